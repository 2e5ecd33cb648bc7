"""The `dataset` command: every breast of a database deformed by every row of a condition."""
from __future__ import annotations

from pathlib import Path

import typer

from breastplan.clock import Clock
from breastplan.deform.conditions import CONDITIONS, find_condition

from .app import JSON, command
from .output import apart, progress, report, usage_error, writable


MAX_DD = 64
"""Degrees of deformation at most (the thesis uses 4 or 8); the dataset grows with #dd."""


@command()
def dataset(
    db: Path = typer.Option(..., "--db", help="database.npz written by `breastplan synth`."),
    condition: str = typer.Option(..., "--condition", help=f"One of: {'; '.join(CONDITIONS)}."),
    dd: int = typer.Option(8, "--dd", help="Number of degrees of deformation (4 or 8 in the thesis)."),
    out: Path = typer.Option(..., "--out", help="Output dataset NPZ."),
    as_json: bool = JSON,
):
    """Deform every breast of a database by every row of a condition; extents and degrees."""
    clock = Clock()
    try:
        cond = find_condition(condition)
    except ValueError as exc:
        raise usage_error(str(exc), "--condition") from None
    if not 2 <= dd <= MAX_DD:
        raise usage_error(f"--dd must be 2..{MAX_DD}, got {dd}", "--dd")
    apart(out, db)

    import numpy as np

    from breastplan.learn.databases import Database
    from breastplan.learn.datasets import build_dataset

    database = Database.load(db)
    writable(out)
    with progress(f"{cond.name} × {dd} degrees", len(database)) as advance:
        data = build_dataset(database, cond, dd, advance)
    path = data.save(out)
    report({"dataset": str(path), "condition": cond.name, "dd": dd, "examples": len(data),
            "reference_extents": data.reference_extents.round(5),
            "examples_per_degree": np.bincount(data.degree, minlength=dd + 1)[1:],
            "seconds": clock.seconds}, as_json, f"dataset {cond.name}")
