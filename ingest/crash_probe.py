"""A native reader tried on a file in a forked child first: a file that makes it crash (a segmentation fault in
C++ code, which no Python `except` catches) is then refused, instead of ending this process — or a batch's
worker, and the patients planned beside it.
"""
from __future__ import annotations

import os
import signal
import time
from collections.abc import Callable

STUCK_S = 120.0
"""A child still reading after this long is stopped and the file read here as it would have been without the
probe (a lock held by another thread at the fork is never released in the child): the result is the same."""


def crash_of(read: Callable[[], object]) -> str | None:
    """The name of the signal that ended a forked child doing `read()` ("SIGSEGV"), or None when it ended
    of itself (whether `read` returned or raised) or was stuck."""
    pid = os.fork()
    if pid == 0:                                               # the child: read, and say nothing but its end
        try:
            read()
        except BaseException:                                  # noqa: BLE001 — raised here, raised again there
            os._exit(1)
        os._exit(0)
    deadline = time.monotonic() + STUCK_S
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        if time.monotonic() > deadline:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            return None
        time.sleep(0.01)
    return signal.Signals(os.WTERMSIG(status)).name if os.WIFSIGNALED(status) else None
