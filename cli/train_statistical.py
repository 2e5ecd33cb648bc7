"""The `train-statistical` command: a statistical deformation model learnt from a clinic's before/after pairs."""
from __future__ import annotations

from pathlib import Path

import typer

from breastplan.clock import Clock
from breastplan.errors import about

from .app import JSON, command
from .output import cache_folder, progress, report, usage_error, writable

REGRESSORS = ("ridge", "kernel-ridge", "mlp")
"""The regressors a model file holds (learn.statistical.EXPORTABLE; listed here so that --help stays light)."""


@command("train-statistical")
def train_statistical(
    pairs: Path = typer.Option(..., "--pairs", help="Folder with pairs.csv (before,after,type,degree[,split]) and "
                                                    "the before/after scans it names (breast PLYs or case folders)."),
    out: Path = typer.Option(..., "--out", help="The model file to write (breastplan.model/1, .npz)."),
    lattice: int = typer.Option(5, "--lattice", help="Control points per lattice axis (5 = 125, 6 = 216)."),
    regressor: str = typer.Option("kernel-ridge", "--regressor", help=f"{' | '.join(REGRESSORS)}: what predicts "
                                                                       "the weights of the field's PCA modes."),
    corresponding: bool = typer.Option(False, "--corresponding", help="The before and after clouds correspond point "
                                                                      "for point (synthetic pairs): fit by least squares."),
    cache: Path = typer.Option(None, "--cache", help="Folder of cached FFD fits (default: $BREASTPLAN_CACHE or "
                                                     "~/.cache/breastplan/ffd)."),
    as_json: bool = JSON,
):
    """Learn a statistical deformation model (FFD displacement fields) from before/after pairs."""
    clock = Clock()
    if regressor not in REGRESSORS:
        raise usage_error(f"'{regressor}' is not a regressor; choose one of {', '.join(REGRESSORS)}", "--regressor")
    if not 3 <= lattice <= 7:
        raise usage_error(f"--lattice must be 3..7 control points per axis, got {lattice}", "--lattice")
    if out.suffix != ".npz":
        raise usage_error(f"the model file must end in .npz, got {out.name}", "--out")
    writable(out)
    cache = cache_folder(cache)
    from breastplan.learn.pair_folder import read_pairs, training_pairs

    with about(pairs / "pairs.csv"):               # bad pairs refused at once, before the fits' code is loaded
        train, clouds = training_pairs(read_pairs(pairs), corresponding)
    from threadpoolctl import threadpool_limits

    from breastplan.learn.displacements import FitCache, PairOptions
    from breastplan.learn.field_file import save_field_model, train_from_pairs

    options = PairOptions(lattice=lattice, corresponding=corresponding)
    with progress("fitting before scans", len(train)) as advance, threadpool_limits(1, "blas"):
        with about(pairs / "pairs.csv"):
            estimator, meta = train_from_pairs(train, clouds, options, FitCache(cache), regressor, advance)
    save_field_model(out, estimator, meta)
    report({"model": str(out), "kinds": meta["kinds"], "pairs": meta["training"]["pairs"],
            "befores": meta["training"]["befores"], "regressor": regressor, "hyper": meta["hyper"],
            "cv_field_rmse_pct": meta["cv_field_rmse_pct"], "seconds": clock.seconds}, as_json, f"model → {out}")
