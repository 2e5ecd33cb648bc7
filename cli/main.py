"""The `breastplan` command (docs/cli.md): `main()` runs the typer app of cli/app.py.

Each command is one module of this package; importing it registers the command (in the order
below, the order of `breastplan --help`). A command imports its stage only when it runs.
"""
from __future__ import annotations

import sys

from breastplan import BadInputError
from breastplan.errors import Interrupted

from . import plan, batch, synth, deform, dataset, scan_synth, ingest, fit, evaluate, train, train_statistical, filters  # noqa: F401,E501  (register the commands)
from .app import app
from .output import stderr


def main() -> None:
    """Entry point: run the app, mapping deliberate errors to exit codes (docs/cli.md)."""
    try:
        app()
    except BadInputError as exc:
        stderr.print(f"error: {exc}", markup=False, soft_wrap=True)
        sys.exit(3)
    except OSError as exc:  # an output we cannot write, a disk that is full
        where = f"{exc.filename}: " if exc.filename else ""
        stderr.print(f"error: {where}{exc.strerror or exc}.", markup=False, soft_wrap=True)
        sys.exit(3)
    except Interrupted as exc:
        stderr.print(f"interrupted: {exc}", markup=False, soft_wrap=True)
        sys.exit(130)


if __name__ == "__main__":
    main()
