"""The typer application and option parsing shared by the command modules."""
from __future__ import annotations

from typing import List

import numpy as np
import typer

from .output import usage_error

app = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="Plan the aesthetic result of breast surgery from a 3-D scan.")

JSON = typer.Option(False, "--json", help="Print one JSON object on stdout (logs go to stderr).")


def parse_pairs(items: List[str], what: str, option: str) -> dict[str, float]:
    """NAME=VALUE items (repeated or comma-separated) → {name: finite float}; usage error otherwise."""
    pairs = {}
    for item in (p for chunk in items for p in chunk.split(",") if p.strip()):
        name, sep, value = item.partition("=")
        try:
            if not sep:
                raise ValueError
            pairs[name.strip()] = float(value)
        except ValueError:
            raise usage_error(f"'{item}' is not NAME=VALUE with a number VALUE ({what})", option) from None
        if not np.isfinite(pairs[name.strip()]):
            raise usage_error(f"'{item}' is not a finite number ({what})", option)
    return pairs


def parse_numbers(text: str | None, count: int, option: str) -> np.ndarray | None:
    """'a,b,c' → an array of `count` finite floats; usage error otherwise."""
    if text is None:
        return None
    try:
        values = np.array([float(v) for v in text.split(",")])
    except ValueError:
        values = np.array([])
    if len(values) != count or not np.isfinite(values).all():
        raise usage_error(f"'{text}' is not {count} comma-separated finite numbers", option)
    return values
