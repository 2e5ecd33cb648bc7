"""Command-line plumbing shared by all commands: consoles, JSON results, progress, exit codes.

Exit codes (docs/cli.md): 0 ok, 2 usage error, 3 bad input (one sentence, no traceback),
1 internal error. The `seconds` a command reports come from `breastplan.clock.Clock`. rich's
progress bar and table are imported when used: every command's start-up imports this module.
"""
from __future__ import annotations

import contextlib
import json
from typing import Any, Iterator

import typer
from rich.console import Console

stdout = Console(highlight=False)
stderr = Console(stderr=True, highlight=False)


def usage_error(message: str, param: str | None = None) -> typer.BadParameter:
    """A usage error (exit 2) to raise from a command."""
    return typer.BadParameter(message, param_hint=param)


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
    """Print the result: one JSON object on stdout, or a two-column table."""
    if as_json:
        print(json.dumps(result, default=_plain))
        return
    from rich.table import Table

    table = Table(title=title, show_header=False, title_justify="left")
    for key, value in result.items():
        table.add_row(key, _human(value))
    stdout.print(table)


def _plain(value):
    if hasattr(value, "tolist"):
        return value.tolist()
    return str(value)


def _human(value) -> str:
    value = _plain(value) if hasattr(value, "tolist") else value
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, (list, tuple)):
        return ", ".join(_human(v) for v in value)
    if isinstance(value, dict):
        return ", ".join(f"{k}={_human(v)}" for k, v in value.items())
    return str(value)
