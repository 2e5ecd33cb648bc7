"""Atomic file writes: a temporary file in the target folder, then os.replace (docs/design.md).

Files are created with the mode the umask gives (0644 under umask 022), as `open` would.
`atomic_set` writes several files all or nothing, whatever the point at which the process dies:
each file is staged whole beside its target and synced; then a journal naming every rename is
written atomically (the commit point); then the renames are made and the journal removed. A
process killed before the commit point leaves the previous set; one killed after it leaves a
journal that `recover` — called by every reader and writer of the folder — completes, so the
folder then holds the new set. Temporaries a killed write left are removed by the next write of
the same file, and the folders a failed set created are removed with its temporaries.
"""
from __future__ import annotations

import bisect
import contextlib
import errno
import itertools
import json
import os
import re
import secrets
import tempfile
from pathlib import Path
from typing import BinaryIO, Callable, Iterator

from .json_text import from_json


Stage = Callable[[str | Path], Path]
"""An `atomic_set`'s `stage`: the path to write a target's content to."""
NAME_KEPT = 200
"""Bytes of the target's name kept in a temporary name, which must fit in 255 bytes."""
JOURNAL = ".commit"
"""Suffix of a set's journal, `.<last file's name>.commit` beside the set's last file."""
JOURNAL_SCHEMA = "breastplan.commit/1"


def short_name(name: str) -> str:
    """`name` cut to NAME_KEPT bytes (whole characters), to fit in a temporary's name; a name's bytes that
    are not UTF-8 (held as surrogates) count one byte each, as the file system stores them."""
    ends = list(itertools.accumulate(len(os.fsencode(c)) for c in name))
    return name[:bisect.bisect_right(ends, NAME_KEPT)]


def file_mode() -> int:
    """0o666 less the process's umask: the mode `open` gives a new file."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            umask = next(int(line.split()[1], 8) for line in fh if line.startswith("Umask:"))
    except (OSError, StopIteration, ValueError):   # not Linux: read it by setting it (not thread-safe)
        umask = os.umask(0o022)
        os.umask(umask)
    return 0o666 & ~umask


@contextlib.contextmanager
def atomic_open(path: str | Path) -> Iterator[BinaryIO]:
    """Open `path` for binary writing so that it appears whole or not at all.

    Creates missing parent folders. On any exception the temporary file is removed and `path`
    is left as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    recover(path.parent)                          # a set committed by a killed write lands first
    _remove_stale(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{short_name(path.name)}.", suffix=".part", dir=path.parent)
    except OSError as exc:                        # name the file the user asked for, not our temporary
        raise OSError(exc.errno, exc.strerror, str(path)) from None
    try:
        os.fchmod(fd, file_mode())
        with os.fdopen(fd, "wb") as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and exc.filename is None:   # a full disk names no file: name ours
            raise OSError(exc.errno, exc.strerror, str(path)) from None
        raise


@contextlib.contextmanager
def atomic_set() -> Iterator[Stage]:
    """Write a set of files all or nothing; yields `stage(path)`, the path to write `path`'s content to.

    On leaving without an exception the set is committed (its journal written) and every staged file
    renamed to its target, in staging order (stage last the file that vouches for the others); on an
    exception before the commit all staged files are removed and the targets are left as they were.
    """
    staged: list[tuple[Path, Path]] = []
    made: list[Path] = []
    journal: list[Path] = []

    def stage(path: str | Path) -> Path:
        path = Path(path)
        made.extend(_make_folders(path.parent))
        recover(path.parent)                      # a set committed by a killed write lands first
        _remove_stale(path)
        tmp = path.with_name(f".{short_name(path.name)}.{secrets.token_hex(4)}.part")
        staged.append((tmp, path))
        return tmp

    committed = False
    try:
        yield stage
        for _, path in staged:                    # a rename onto a folder would fail after the commit point
            if path.is_dir():
                raise IsADirectoryError(errno.EISDIR, "is a folder where a file is to be written", str(path))
        if staged:
            journal.append(staged[-1][1].with_name(f".{short_name(staged[-1][1].name)}{JOURNAL}"))
            for tmp, _ in staged:
                _sync(tmp)                        # every staged file whole on disk before the commit point
            _write_journal(journal[0], staged)
            committed = True
            _apply(journal[0], staged)
    except BaseException as exc:
        if committed:                             # the journal stands: `recover` completes the set
            raise
        for tmp in journal + [tmp for tmp, _ in staged]:   # the journal first: it must never outlive a file
            with contextlib.suppress(FileNotFoundError, IsADirectoryError):   # a folder in its place is not ours
                os.unlink(tmp)
        _remove_folders(made)
        names = {str(tmp): path for tmp, path in staged}
        if journal:
            names[str(journal[0])] = staged[-1][1]
        target = names.get(str(getattr(exc, "filename", None)))
        if isinstance(exc, OSError) and target is not None:   # name the file the user asked for
            raise OSError(exc.errno, exc.strerror, str(target)) from None
        raise


def recover(folder: str | Path) -> list[Path]:
    """Complete the set writes whose journals lie in `folder` (left by killed processes); the targets
    renamed. Journals that are not breastplan's, or name other files than staged ones, are left alone."""
    folder, done = Path(folder), []
    try:
        journals = sorted(p for p in folder.iterdir() if p.name.startswith(".") and p.name.endswith(JOURNAL))
    except (FileNotFoundError, NotADirectoryError):
        return done
    for journal in journals:
        renames = _read_journal(journal)
        if renames is not None:
            _apply(journal, renames)
            done.extend(path for _, path in renames)
    return done


def _write_journal(journal: Path, staged: list[tuple[Path, Path]]) -> None:
    folder = journal.parent
    renames = [[os.path.relpath(tmp, folder), os.path.relpath(path, folder)] for tmp, path in staged]
    with atomic_open(journal) as fh:
        fh.write(json.dumps({"schema": JOURNAL_SCHEMA, "renames": renames}).encode())
    _sync(folder)


def _read_journal(journal: Path) -> list[tuple[Path, Path]] | None:
    """The renames of a journal, each a staged file onto its own target; None if it is not such a journal."""
    try:
        doc = from_json(journal.read_bytes())
        pairs = doc["renames"] if doc.get("schema") == JOURNAL_SCHEMA else None
        renames = [(journal.parent / src, journal.parent / dst) for src, dst in pairs]
    except (OSError, ValueError, TypeError, KeyError, AttributeError):
        return None
    for (tmp, path), (src, dst) in zip(renames, pairs):
        parts = Path(src).parts + Path(dst).parts
        if Path(src).is_absolute() or Path(dst).is_absolute() or ".." in parts or tmp.parent != path.parent \
                or not re.fullmatch(rf"\.{re.escape(short_name(path.name))}\.[0-9a-f]{{8}}\.part", tmp.name):
            return None
    return renames


def _apply(journal: Path, renames) -> None:
    """Make a committed set's renames (those a previous attempt left undone), then drop its journal."""
    for tmp, path in renames:
        with contextlib.suppress(FileNotFoundError):     # renamed already, by an interrupted attempt
            os.replace(tmp, path)
    for folder in dict.fromkeys(path.parent for _, path in renames):
        _sync(folder)
    with contextlib.suppress(FileNotFoundError):
        os.unlink(journal)


def _sync(path: Path) -> None:
    """fsync a file or folder (folders: best effort, as some file systems refuse it)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    except OSError:
        if not path.is_dir():
            raise
    finally:
        os.close(fd)


def _remove_stale(path: Path) -> None:
    """Remove the temporaries of `path` a killed write left (call `recover` first): `.NAME.XXXXXXXX.part`
    (its own or a staged copy), `..NAME.<hex8>.part.XXXXXXXX.part` (a staged copy's) and
    `..NAME.commit.XXXXXXXX.part` (a journal's). A concurrent writer of the same file is not supported."""
    name = re.escape(short_name(path.name))
    stale = re.compile(rf"(\.{name}|\.\.{name}\.[0-9a-f]{{8}}\.part|\.\.{name}{re.escape(JOURNAL)})"
                       rf"\.[a-z0-9_]{{8}}\.part")
    with contextlib.suppress(OSError):
        for entry in os.scandir(path.parent):
            if stale.fullmatch(entry.name) and entry.is_file(follow_symlinks=False):
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(entry.path)


def _make_folders(folder: Path) -> list[Path]:
    """Create `folder` and its missing parents; the folders created, deepest first."""
    missing = []
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    if not folder.is_dir():
        raise NotADirectoryError(errno.ENOTDIR, "is a file where a folder is needed", str(folder))
    for made in reversed(missing):
        made.mkdir(exist_ok=True)
    return missing


def _remove_folders(folders: list[Path]) -> None:
    for folder in sorted(folders, key=lambda f: len(f.parts), reverse=True):   # deepest first; a folder not empty stays
        with contextlib.suppress(OSError):
            folder.rmdir()
