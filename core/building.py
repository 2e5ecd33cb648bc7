"""Folders built beside their target and renamed into place when whole, and the locks that keep two
processes from one folder.

A folder `out` is built in a hidden sibling `.<out>.<kind>-XXXXXXXX` (`kind`: plan, batch, stale…),
locked while it is built; the system releases a lock when its process dies, even by kill -9, so a
sibling whose lock no living process holds was left by a killed one and is removed by the next build.
"""
from __future__ import annotations

import contextlib
import fcntl
import glob
import os
import re
import secrets
import shutil
from pathlib import Path
from typing import Iterator

from .atomic import short_name

LEFTOVER = re.compile(r"^\..+\.(plan|batch|stale)-[0-9a-f]{8}$")
"""The hidden siblings a killed build may leave: a plan's build folder, a batch's re-plan copy, a swapped-out case."""


def sibling(out: Path, kind: str) -> Path:
    """A new hidden sibling of `out` to build it in (`kind`: one of LEFTOVER's kinds)."""
    return out.parent / f".{short_name(out.name)}.{kind}-{secrets.token_hex(4)}"


@contextlib.contextmanager
def building(out: Path, kind: str, replace: bool = False) -> Iterator[Path]:
    """The folder to build `out` in: `out` itself if it exists (and not `replace`), else a locked hidden
    sibling put in its place once the block ends without error (`swap_in`; removed if it fails, and by a
    later build if this one is killed). A failed build leaves none of the parent folders it made.
    OSErrors name `out`, not the sibling."""
    if out.exists() and not replace:
        yield out
        return
    work = sibling(out, kind)
    made = [p for p in (out.parent, *out.parent.parents) if not p.exists()]
    done = False
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        with _locked_folder(work, work.name[:-8]):
            yield work
            swap_in(work, out)
            done = True
    except OSError as exc:
        where = str(exc.filename or out)
        raise OSError(exc.errno, exc.strerror, str(out) + where[len(str(work)):] if where.startswith(str(work))
                      else where) from None
    finally:
        shutil.rmtree(work, ignore_errors=True)
        for folder in made if not done else ():
            with contextlib.suppress(OSError):        # only if still empty: another process may have filled it
                folder.rmdir()


def swap_in(work: Path, out: Path) -> None:
    """Put the folder `work` in the place of `out`, whole: an `out` there is first moved aside to a
    hidden sibling, then removed (and by a later build if this process is killed in between)."""
    if not out.exists():
        os.rename(work, out)
        return
    old = sibling(out, "stale")
    os.rename(out, old)
    os.rename(work, out)
    shutil.rmtree(old, ignore_errors=True)


@contextlib.contextmanager
def _locked_folder(work: Path, stem: str) -> Iterator[None]:
    """Create `work` and hold a lock on it, first removing the folders `stem`XXXXXXXX beside it whose lock
    no living process holds. Both under a lock on their parent, so that no folder is removed between
    its creation and its lock."""
    parent = lock(work.parent)
    try:
        for folder in work.parent.glob(glob.escape(stem) + "[0-9a-f]" * 8):
            abandoned = lock(folder, wait=False) if folder.is_dir() else None
            if abandoned is not None:
                shutil.rmtree(folder, ignore_errors=True)
                os.close(abandoned)
        work.mkdir()
        held = lock(work)
    finally:
        os.close(parent)
    try:
        yield
    finally:
        os.close(held)


def lock(path: Path, wait: bool = True) -> int | None:
    """A descriptor of `path` (a folder or a file) holding its exclusive lock; None when another process
    holds it and not `wait`."""
    fd = os.open(path, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
    except BlockingIOError:
        os.close(fd)
        return None
    return fd
