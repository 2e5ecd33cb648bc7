"""Errors breastplan raises on purpose; the CLI maps them to exit codes (docs/design.md)."""
from __future__ import annotations

import contextlib
import errno
import os
from pathlib import Path
from typing import Iterator


class BreastplanError(Exception):
    """Base class of the errors breastplan raises deliberately."""


class BadInputError(BreastplanError):
    """Bad user input (file or value): CLI exit code 3, one sentence, no traceback."""

    def __init__(self, path: str | Path | None, problem: str):
        self.path = None if path is None else Path(path)
        self.problem = problem.rstrip(".")
        where = f"{self.path}: " if self.path is not None else ""
        super().__init__(f"{where}{self.problem}{'' if self.problem.endswith('?') else '.'}")


class ArtefactError(BadInputError):
    """An artefact file (PLY or NPZ) that is missing, corrupt or of the wrong schema."""


class NewerArtefactError(ArtefactError):
    """An artefact written by a newer breastplan: refused, never overwritten."""


class Interrupted(BreastplanError):
    """Work stopped by the user (Ctrl-C) after writing what was finished: CLI exit code 130, one sentence."""


def counted(n: int, noun: str, plural: str | None = None) -> str:
    """A count and its noun for an error sentence: '1 vertex', '2 vertices', '12,034 points'."""
    return f"{n:,} {noun if n == 1 else plural or noun + 's'}"


def require_file(path: str | Path, kind: str, error: type[BadInputError] = BadInputError) -> Path:
    """`path` as a Path if it is an existing, non-empty regular file; else `error` saying why."""
    path = Path(path)
    if not path.exists():
        raise error(path, "is a symbolic link to no file (it loops, or its target is gone)" if path.is_symlink()
                    else "no such file")
    if path.is_dir():
        raise error(path, f"is a folder, not a {kind}")
    if not path.is_file():
        raise error(path, "is not a regular file")
    if path.stat().st_size == 0:
        raise error(path, "is empty (0 bytes)")
    try:
        open(path, "rb").close()
    except OSError as exc:
        raise error(path, f"cannot be read ({exc.strerror})") from None
    return path


def loops(path: str | Path) -> bool:
    """Whether `path` leads into a loop of symbolic links (`Path.resolve` raises RuntimeError for one
    on Python < 3.13, and later versions resolve it to a path that does not exist)."""
    try:
        os.stat(path)
    except OSError as exc:
        return exc.errno == errno.ELOOP
    return False


def file_head(path: Path, size: int) -> bytes | None:
    """The first `size` bytes of the regular file `path` (fewer if it is shorter); None if it is no
    regular file (a named pipe, which reading would block on) or cannot be read."""
    if not path.is_file():
        return None
    try:
        with open(path, "rb") as fh:
            return fh.read(size)
    except OSError:
        return None


def require_folder(path: str | Path, kind: str, error: type[BadInputError] = BadInputError) -> Path:
    """`path` as a Path if it is a folder whose files can be listed and read; else `error` saying why."""
    path = Path(path)
    if not path.is_dir():
        raise error(path, f"is not a {kind}")
    if not os.access(path, os.R_OK | os.X_OK):
        raise error(path, "cannot be read (Permission denied)")
    return path


@contextlib.contextmanager
def about(path: str | Path | None) -> Iterator[None]:
    """Name `path` in the BadInputErrors raised inside that name no file (stages raise them without
    paths; the command that read the file knows which it was)."""
    try:
        yield
    except BadInputError as exc:
        if exc.path is not None or path is None:
            raise
        raise type(exc)(path, exc.problem) from None
