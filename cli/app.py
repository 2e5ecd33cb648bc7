"""The typer application and option parsing shared by the command modules.

Each command lives in its own module (cli/synth.py, cli/deform.py, …) and registers itself with
`@command()`; `cli/main.py` imports them. At its top a command module imports only the standard
library, typer, rich and plain-data modules (option defaults and help come from modules such as
`breastplan.deform.names`); numpy, the stage it runs and the heavy libraries behind it (open3d,
scipy, scikit-learn, matplotlib, depthai, pymeshlab, igl) are imported inside the command
function, so that `breastplan --help` and every command's start-up stay fast
(tests/test_cli_startup.py, benchmarks/bench_cli.py).
"""
from __future__ import annotations

import inspect
import math
from typing import TYPE_CHECKING, List

import typer
from typer.core import TyperCommand, TyperGroup

from .output import usage_error

if TYPE_CHECKING:
    from pathlib import Path

    import numpy as np


class _Flags:
    """Typer's rich help prints a type after every option, flags included (`--json <bool>`), as if a
    flag took a value; an empty metavar shows a flag as a flag (`--json`)."""

    def get_params(self, ctx):
        params = super().get_params(ctx)
        for param in params:
            if getattr(param, "is_flag", False) and param.metavar is None:
                param.metavar = ""
        return params


class Group(_Flags, TyperGroup):
    pass


class Command(_Flags, TyperCommand):
    pass


app = typer.Typer(cls=Group, add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="Plan the aesthetic result of breast surgery from a 3-D scan.")


def command(name: str | None = None):
    """Register the decorated function as the command `name` (default: the function's name).

    typer refuses an existing path it cannot read as a usage error (exit 2); the commands refuse it
    themselves, as bad input naming the file (exit 3), so typer's check is turned off."""
    def register(function):
        for param in inspect.signature(function).parameters.values():
            if isinstance(param.default, typer.models.ParameterInfo):
                param.default.readable = False
        return app.command(name, cls=Command)(function)

    return register


def _print_version(value: bool) -> None:
    if value:
        from breastplan import __version__

        print(f"breastplan {__version__}")
        raise typer.Exit()


@app.callback()
def _options(
    version: bool = typer.Option(False, "--version", is_eager=True, callback=_print_version,
                                 help="Print the version and exit."),
):
    pass


JSON = typer.Option(False, "--json", help="Print one JSON object on stdout (logs go to stderr).")
UNITS_HELP = "Units of a scan file: auto (from its extent), mm or m."
UP_HELP = ("Superior axis of a scan file: auto (found from her body: the axis along which her head stands above "
           "her chest), +x, -x, +y, -y, +z or -z.")


def parse_pairs(items: List[str], what: str, option: str) -> dict[str, float]:
    """NAME=VALUE items (repeated or comma-separated) → {name: finite float}; usage error otherwise."""
    pairs = {}
    for item in (p for chunk in items for p in chunk.split(",") if p.strip()):
        name, sep, value = item.partition("=")
        name = name.strip()
        if name in pairs:
            raise usage_error(f"{name} is given twice ({what})", option)
        try:
            if not sep or not name:
                raise ValueError
            pairs[name] = float(value)
        except ValueError:
            raise usage_error(f"'{item}' is not NAME=VALUE with a number VALUE ({what})", option) from None
        if not math.isfinite(pairs[name]):
            raise usage_error(f"'{item}' is not a finite number ({what})", option)
    return pairs


def scan_file_options(input: Path | None, units: str, up: str) -> None:
    """Usage error for --units or --up (given other than their defaults) with an input that is no scan
    file: they describe a scan file's own units and axes, and a recording, a camera or a case has its own."""
    from breastplan.ingest.scan import is_recording

    if input is not None and not input.is_dir() and not is_recording(input):
        return
    given = [name for name, value, default in (("--units", units, "auto"), ("--up", up, "auto")) if value != default]
    if given:
        what = ("a case folder, ingested already" if input is not None and input.is_dir() else
                "a depth recording, whose frame is its camera's (mm)")
        verb = "describes" if len(given) == 1 else "describe"
        raise usage_error(f"{' and '.join(given)} {verb} a scan file; {input or 'the input'} is {what}", given[0])


def parse_numbers(text: str | None, count: int, option: str) -> np.ndarray | None:
    """'a,b,c' → an array of `count` finite floats; usage error otherwise."""
    if text is None:
        return None
    import numpy as np

    try:
        values = np.array([float(v) for v in text.split(",")])
    except ValueError:
        values = np.array([])
    if len(values) != count or not np.isfinite(values).all():
        raise usage_error(f"'{text}' is not {count} comma-separated finite numbers", option)
    return values
