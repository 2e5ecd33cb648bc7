"""The `train` command: the shipped regression models, one per condition, trained on database S."""
from __future__ import annotations

from pathlib import Path

import typer

from breastplan.clock import Clock

from .app import JSON, command
from .output import progress, report, writable


@command()
def train(
    out: Path = typer.Option(Path("models"), "--out", help="Folder for one breastplan.model/1 NPZ per condition."),
    quick: bool = typer.Option(False, "--quick", help="Small grid and 2500 points (for tests)."),
    as_json: bool = JSON,
):
    """Train the best model of each condition on database S's training split."""
    clock = Clock()
    writable(out, folder=True)
    from breastplan.learn.train import DEPLOYED, train_all

    with progress("training", len(DEPLOYED)) as advance:
        written = train_all(out, quick=quick, n_points=2500 if quick else 10_000, advance=advance)
    report({"models": {w["condition"]: w for w in written}, "folder": str(out), "seconds": clock.seconds},
           as_json, "trained models")
