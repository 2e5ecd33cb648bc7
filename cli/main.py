"""The `breastplan` command (docs/cli.md): `main()` runs the typer app of cli/app.py.

Each command is one module of this package; importing it registers the command (in the order
below, the order of `breastplan --help`). A command imports its stage only when it runs.
"""
from __future__ import annotations

import os
import signal
import sys
import warnings
from typing import NoReturn

from breastplan import BadInputError
from breastplan.errors import Interrupted

from . import plan, batch, synth, deform, dataset, scan_synth, ingest, fit, evaluate, train, train_statistical, filters  # noqa: F401,E501  (register the commands)
from .app import app
from .output import stderr


REFUSED = (2, 3, 130)    # usage error, bad input, interrupted: the exit codes that end in one sentence


def main() -> None:
    """Entry point: run the app, mapping deliberate errors to exit codes (docs/cli.md).

    Warnings the libraries raise on the way (numpy's on data about to be refused) are held back:
    a refusal is its one sentence; any other ending shows them after the fact."""
    for stream in (sys.stdout, sys.stderr):      # a terminal that is not UTF-8, a file name that is not
        stream.reconfigure(errors="backslashreplace")           # UTF-8: shown escaped, never a crash
    sys.stdout = _Stdout(sys.stdout)
    held: list[warnings.WarningMessage] = []
    try:
        with warnings.catch_warnings(record=True) as held:     # shown after it, where showing is no recording
            _run()
    except SystemExit as exc:
        if exc.code not in REFUSED:
            _show(held)
        raise
    except BaseException:
        _show(held)
        raise
    _show(held)


class _Stdout:
    """stdout, whose reader going away (`breastplan filters | head -1`) ends the process by SIGPIPE, as it
    ends any tool. Only stdout's: a broken pipe to a worker process stays the exception it is."""

    def __init__(self, stream):
        self._stream = stream

    def __getattr__(self, name):
        return getattr(self._stream, name)

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            _end_by_sigpipe()

    def flush(self) -> None:
        try:
            self._stream.flush()
        except BrokenPipeError:
            _end_by_sigpipe()


def _end_by_sigpipe() -> NoReturn:
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)
    os.kill(os.getpid(), signal.SIGPIPE)
    raise SystemExit(141)                       # not reached: the signal ends the process


def _run() -> None:
    empty = _empty_argument(sys.argv[1:])
    if empty:
        _refuse(f"error: {empty} is empty: give it a value or leave it out (see `breastplan --help`).", 2)
    try:
        app()
    except BadInputError as exc:
        _refuse(f"error: {exc}", 3)
    except OSError as exc:  # an output we cannot write, a disk that is full
        where = f"{exc.filename}: " if exc.filename else ""
        _refuse(f"error: {where}{exc.strerror or exc}.", 3)
    except Interrupted as exc:
        _refuse(f"interrupted: {exc}", 130)


def _refuse(sentence: str, code: int) -> NoReturn:
    stderr.print(sentence, markup=False, soft_wrap=True)
    sys.exit(code)


def _show(held: list[warnings.WarningMessage]) -> None:
    for w in held:
        warnings.showwarning(w.message, w.category, w.filename, w.lineno)


def _empty_argument(args: list[str]) -> str | None:
    """What an empty (or blank) argument was given for: `--out ""` or `--out=` would otherwise name the
    current folder, `--deformations ""` no deformation. None when every argument has a value."""
    for i, arg in enumerate(args):
        option, equals, value = arg.partition("=")
        if arg.startswith("--") and equals and not value.strip():
            return f"the value of {option}"
        if not arg.strip():
            return f"the value of {args[i - 1]}" if i and args[i - 1].startswith("-") else f"argument {i + 1}"
    return None


if __name__ == "__main__":
    main()
