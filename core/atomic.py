"""Atomic file writes: a temporary file in the target folder, then os.replace (docs/design.md).

Files are created with the mode the umask gives (0644 under umask 022), as `open` would.
`atomic_set` writes several files all or nothing: each is staged whole beside its target, then
all are renamed in the order they were staged.
"""
from __future__ import annotations

import contextlib
import os
import secrets
import tempfile
from pathlib import Path
from typing import BinaryIO, Callable, Iterator


NAME_KEPT = 200
"""Bytes of the target's name kept in a temporary name, which must fit in 255 bytes."""


def _short(name: str) -> str:
    return name.encode()[:NAME_KEPT].decode(errors="ignore")


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

    Creates missing parent folders. On any exception the temporary file is removed
    and `path` is left as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{_short(path.name)}.", suffix=".part", dir=path.parent)
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
def atomic_set() -> Iterator[Callable[[str | Path], Path]]:
    """Write a set of files all or nothing; yields `stage(path)`, the path to write `path`'s content to.

    On leaving without an exception every staged file is renamed to its target, in staging order
    (stage last the file that vouches for the others); on an exception all staged files are removed
    and the targets are left as they were.
    """
    staged: list[tuple[Path, Path]] = []

    def stage(path: str | Path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{_short(path.name)}.{secrets.token_hex(4)}.part")
        staged.append((tmp, path))
        return tmp

    try:
        yield stage
        for tmp, path in staged:
            os.replace(tmp, path)
    except BaseException as exc:
        for tmp, _ in staged:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
        target = {str(tmp): path for tmp, path in staged}.get(str(getattr(exc, "filename", None)))
        if isinstance(exc, OSError) and target is not None:   # name the file the user asked for
            raise OSError(exc.errno, exc.strerror, str(target)) from None
        raise
