"""Command-line plumbing shared by all commands: consoles, JSON results, progress, exit codes.

Exit codes (docs/cli.md): 0 ok, 2 usage error, 3 bad input (one sentence, no traceback),
1 internal error. The `seconds` a command reports come from `breastplan.clock.Clock`. rich's
progress bar and table are imported when used: every command's start-up imports this module.
"""
from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Any, Iterator

import typer
from rich.console import Console

from breastplan.json_text import to_json

stdout = Console(highlight=False, emoji=False)   # "lumpectomy:100:10:30" is no emoji
stderr = Console(stderr=True, highlight=False, emoji=False)


def usage_error(message: str, param: str | None = None) -> typer.BadParameter:
    """A usage error (exit 2) to raise from a command."""
    return typer.BadParameter(message, param_hint=param)


def writable(path: Path, folder: bool = False, option: str = "--out") -> Path:
    """`path` if an output file (or `folder`) can be written there; else BadInputError naming it (exit 3),
    raised before any work: a name longer than the file system holds, a file where a folder is needed
    (or a folder where `option` needs a file), a symbolic link leading nowhere, a folder the user may
    not write in."""
    from breastplan import BadInputError

    path = Path(path)
    existing = next((p for p in (path, *path.parents) if _exists(p)), Path(path.anchor or "."))
    limit = os.pathconf(existing if existing.is_dir() else existing.parent, "PC_NAME_MAX")
    long = [p for p in path.relative_to(existing).parts if len(os.fsencode(p)) > limit]
    if long:
        raise BadInputError(path, f"cannot be written: its name has {len(os.fsencode(long[0]))} bytes, more "
                                  f"than the {limit} a file name may have")
    dangling = next((p for p in (path, *path.parents) if p.is_symlink() and not _exists(p)), None)
    if dangling is not None:
        raise BadInputError(path, f"cannot be written: {dangling} is a symbolic link to {os.readlink(dangling)}, "
                                  "which does not exist")
    if existing == path and path.is_dir() != folder:
        raise BadInputError(path, "is a file, not a folder" if folder else f"is a folder; {option} needs a file name")
    where = existing if existing != path else path if folder else path.parent    # the folder written in
    if not where.is_dir():
        raise BadInputError(path, f"cannot be written: {where} is a file, not a folder")
    if not os.access(where, os.W_OK | os.X_OK):
        raise BadInputError(path, f"cannot be written: no permission to write in {where}")
    return path


def cache_folder(cache: Path | None) -> Path | None:
    """The folder of cached FFD fits: `--cache`, checked as an output is (exit 3); else the default
    ($BREASTPLAN_CACHE or the user's cache folder) if it can be written, else none (fits kept in memory
    only), said in a note: a cache is never needed."""
    from breastplan import BadInputError

    if cache is not None:
        return writable(cache, folder=True, option="--cache")
    from breastplan.learn.displacements import default_cache

    try:
        return writable(default_cache(), folder=True)
    except BadInputError as exc:
        stderr.print(f"note: FFD fits are not cached on disk: {exc}", markup=False, soft_wrap=True)
        return None


def real(path: Path) -> Path:
    """`path`, absolute, with its links followed as far as they lead (where `Path.resolve` raises on a
    looping link, this leaves it as it is)."""
    return Path(os.path.realpath(path))


def inside(path: Path, folder: Path) -> bool:
    """Whether `path` is `folder` or lies in it (both as `real` gives them)."""
    return path == folder or folder in path.parents


def read_only(earlier: Path, out: Path) -> None:
    """A usage error (exit 2) when writing the folder `out` could write into the earlier case folder
    given to --wall-from (`out` is it, lies in it or holds it): an earlier visit is only read."""
    a, b = real(out), real(earlier)
    how = "that very folder" if a == b else "a folder inside it" if inside(a, b) else "a folder that holds it" \
        if inside(b, a) else None
    if how:
        raise usage_error(f"{earlier} is the earlier visit, which is only read, and this command writes "
                          f"{out}, {how}; write the new visit into a folder of its own", "--wall-from")


def holds_plan(folder: Path) -> bool:
    """Whether `folder` holds a plan.json (a plan's case folder), however damaged."""
    return (Path(folder) / "plan.json").is_file()


def not_one_side_of_a_plan(out: Path, command: str) -> None:
    """A usage error (exit 2) when `out` is one side's folder of a plan's case folder: `command` writing there
    alone would leave the plan naming files it no longer has, or another scan's."""
    from breastplan.options import SIDES

    if real(out).name in SIDES and holds_plan(real(out).parent):
        raise usage_error(f"{out} is one side of the plan in {out.parent}: {command} alone there would leave that "
                          f"plan naming files it no longer has; plan {out.parent} (both sides), or give --out a new "
                          "folder", "--out")


def apart(out: Path, input: Path, option: str = "--out") -> Path:
    """`out` unless writing it would replace what the command reads: `input` itself (by whatever path or
    link), or one of the files of the case folder it is in; a usage error (exit 2) then."""
    from breastplan.case import Case

    try:
        same = real(out) == real(input) or (_exists(out) and _exists(input) and os.path.samefile(out, input))
        owned = Case.owns(out)
    except OSError:                          # a name too long to be either: `writable` says so
        return out
    if same:
        raise usage_error(f"it names {input}, which is read: writing there would replace it", option)
    if owned:
        raise usage_error(f"it names the {out.name} of the case folder {out.parent}: writing there would leave "
                          "that case's files disagreeing", option)
    return out


def _exists(path: Path) -> bool:
    try:                         # Path.exists raises on a name too long
        path.stat()
    except OSError:
        return False
    return True


@contextlib.contextmanager
def progress(label: str, total: int) -> Iterator[Any]:
    """A progress bar on stderr (only on a terminal); yields a function that advances it by one."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    bar = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                   console=stderr, transient=True, disable=not stderr.is_terminal)
    with bar:
        task = bar.add_task(label, total=total)
        yield lambda: bar.advance(task)


def report(result: dict, as_json: bool, title: str) -> None:
    """Print the result: one JSON object on stdout, or a two-column table (without the rows whose
    value is None, which JSON keeps as null)."""
    if as_json:
        print(to_json(result))
        return
    from rich.table import Table

    table = Table(title=title, show_header=False, title_justify="left")
    for key, value in result.items():
        if value is not None:
            table.add_row(key, _human(value))
    stdout.print(table)


def _human(value) -> str:
    value = value.tolist() if hasattr(value, "tolist") else value
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, (list, tuple)):
        return ", ".join(_human(v) for v in value)
    if isinstance(value, dict):
        return ", ".join(f"{k}={_human(v)}" for k, v in value.items())
    return str(value)
