"""The `train-statistical` command: a statistical deformation model learnt from a clinic's before/after pairs."""
from __future__ import annotations

from pathlib import Path

import typer

from breastplan import BadInputError
from breastplan.clock import Clock
from breastplan.errors import about

from .app import JSON, command
from .output import cache_folder, progress, report, usage_error, writable

REGRESSORS = ("ridge", "kernel-ridge", "mlp")
"""The regressors a model file holds (learn.statistical.EXPORTABLE; listed here so that --help stays light)."""


@command("train-statistical")
def train_statistical(
    pairs: Path = typer.Option(..., "--pairs", help="Folder with pairs.csv (before,after,type,degree[,split]) and "
                                                    "the before/after scans it names (breast PLYs or case folders); "
                                                    "or, for an operation's model, pairs.csv (before,after,operation,"
                                                    "side[,split]) and the case folders `plan` wrote of her before "
                                                    "and after it."),
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
    """Learn a statistical deformation model (FFD displacement fields) from before/after pairs, or a model of one
    operation (augmentation or reduction) from scans of the women it was made on, for plan --operation-model."""
    clock = Clock()
    if regressor not in REGRESSORS:
        raise usage_error(f"'{regressor}' is not a regressor; choose one of {', '.join(REGRESSORS)}", "--regressor")
    if not 3 <= lattice <= 7:
        raise usage_error(f"--lattice must be 3..7 control points per axis, got {lattice}", "--lattice")
    if out.suffix != ".npz":
        raise usage_error(f"the model file must end in .npz, got {out.name}", "--out")
    writable(out)
    from breastplan.plan.operation_pairs import is_operation_table

    if is_operation_table(pairs):
        if corresponding or lattice != 5:
            raise usage_error("--corresponding and --lattice are a deformation model's; an operation's pairs are "
                              "her scans before and after it", "--corresponding" if corresponding else "--lattice")
        return _operation_model(pairs, out, regressor, as_json, clock)
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


def _operation_model(pairs: Path, out: Path, regressor: str, as_json: bool, clock: Clock) -> None:
    """An operation's model learnt from its pairs folder (`plan.operation_pairs`), written to `out`."""
    from breastplan.plan.operation_pairs import learnt_pairs, read_operation_pairs

    with about(pairs / "pairs.csv"):
        rows = read_operation_pairs(pairs)
    from threadpoolctl import threadpool_limits

    from breastplan.plan.learnt_operation import save, train

    folders = len({f for r in rows if r.split == "train" for f in (r.before, r.after)})
    with progress("measuring her scans", folders) as advance, threadpool_limits(1, "blas"):
        learnt = learnt_pairs(rows, advance)
    if len(learnt) < 2:
        raise BadInputError(pairs / "pairs.csv", "holds one breast operated: a model learns from two at least")
    trained = train(learnt, regressor)
    save(out, trained)
    meta = trained[-1]
    report({"model": str(out), "operation": meta["kind"], "pairs": meta["training"]["pairs"],
            "women": meta["training"]["women"], "regressor": regressor, "hyper": meta["hyper"],
            "cv_rmse": meta["cv_rmse"], "seconds": clock.seconds}, as_json, f"model → {out}")
