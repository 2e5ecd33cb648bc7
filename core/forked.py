"""Work done beside this process in a forked child, on a second CPU, while this process does its own.

The child shares this process's memory as it was at the fork and reports only its exit code: its work
writes files, or into an array `shared` with this process. A child that failed, or is stuck (a lock
another thread held at the fork is never released in the child), leaves its work to this process,
which does it as it would have alone: the same result either way, only later.
"""
from __future__ import annotations

import contextlib
import mmap
import multiprocessing
import os
import time
from collections.abc import Callable, Iterator

import numpy as np

STUCK = (60.0, 10.0)
"""A child still working after the larger of this many seconds and this many times the time this process
took for its own share is taken for stuck and stopped."""


@contextlib.contextmanager
def beside(work: Callable[[], None] | None) -> Iterator[Callable[[], bool]]:
    """Start `work()` in a forked child, when there is work, two CPUs to share, and this process may start
    one (a daemonic worker, as in a batch, may not); yields `finished()`: whether the child did its work,
    waited for (see STUCK) — False when no child was started. A child still running when the block raises
    is stopped."""
    child = None
    if work is not None and len(os.sched_getaffinity(0)) >= 2 and not multiprocessing.current_process().daemon:
        child = multiprocessing.get_context("fork").Process(target=_do, args=(work,))
        child.start()
    started = time.monotonic()

    def finished() -> bool:
        if child is None:
            return False
        child.join(max(STUCK[0], STUCK[1] * (time.monotonic() - started)))
        return _stopped(child) == 0

    try:
        yield finished
    finally:
        if child is not None:
            _stopped(child)


def shared(shape: tuple[int, ...], dtype) -> np.ndarray:
    """A zeroed array in memory this process shares with the children it forks afterwards: what a child
    writes there, this process reads."""
    dtype = np.dtype(dtype)
    count = int(np.prod(shape))
    return np.frombuffer(mmap.mmap(-1, max(count * dtype.itemsize, 1)), dtype, count).reshape(shape)


def _stopped(child) -> int:
    """The child's exit code, once it has ended (stopped now if still running)."""
    if child.exitcode is None:
        child.kill()
        child.join()
    return child.exitcode


def _do(work: Callable[[], None]) -> None:
    """The child: its work, then an exit code (no clean-up of the parent's state it inherited)."""
    try:
        work()
    except BaseException:                                      # noqa: BLE001 — the parent does the work again
        os._exit(1)
    os._exit(0)
