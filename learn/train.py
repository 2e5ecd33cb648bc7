"""Train the deployable deformation models: one `breastplan.model/1` file per condition.

Each condition's model is the best (lowest cross-validated RMSE) of every regressor family on
FS4 and FS5 with the continuous degree, trained on database S's training split. Only feature
sets of scalar descriptors are deployable: the vector sets need a breast sampled exactly like the
database's (u, v) grid, which a patient's scan is not.
"""
from __future__ import annotations

from pathlib import Path

from breastplan.deform.by_degree import slug
from breastplan.deform.conditions import find_condition
from breastplan.deform.names import DD
from breastplan.model_file import save_model

from .databases import build_database
from .datasets import build_dataset
from .features import breast_table, example_features
from .regressors import FAMILIES, Selected, select

DEPLOYED = ("ptosis b0>b1", "ptosis b1>=b0", "turn c0>c1", "turn c1>c0", "top-shape s0->s1+", "top-shape s1->s0+")
FEATURE_SETS = ("FS4", "FS5")


def train_condition(ds, quick: bool = False, table=None) -> tuple[Selected, str, list[str]]:
    """The best family and feature set of one dataset: (selection, feature set, feature names);
    `table` is `breast_table(ds.database, kind)` when the caller has it already."""
    train = ds.split == "train"
    table = breast_table(ds.database, ds.condition.kind) if table is None else table
    best = None
    for fs in FEATURE_SETS:
        f = example_features(ds, fs, "continuous", table)
        for family in FAMILIES:
            sel = select(family, f.scalars[train], ds.position[train], ds.breast[train], quick)
            if best is None or sel.cv_rmse_pct < best[0].cv_rmse_pct:
                best = (sel, fs, f.names)
    return best


def train_all(out: Path, conditions=DEPLOYED, quick: bool = False, n_points: int = 10_000,
              advance=lambda: None) -> list[dict]:
    """Train and write `out/<slug>.npz` for each condition; returns one summary per file."""
    db = build_database("S", n_points=n_points)
    tables = {kind: breast_table(db, kind) for kind in {find_condition(name).kind for name in conditions}}
    written = []
    for name in conditions:
        cond = find_condition(name)
        ds = build_dataset(db, cond, DD)
        sel, fs, names = train_condition(ds, quick, tables[cond.kind])
        meta = {"condition": cond.name, "kind": cond.kind, "dd": DD, "feature_set": fs, "features": names,
                "degree": "continuous", "target": "position t on the condition's line",
                "family": sel.family, "hyper": {k: str(v) for k, v in sel.params.items()},
                "cv_rmse_pct": sel.cv_rmse_pct, "quick": quick,
                "training": {"database": "S", "seed": db.seed, "points": n_points, "split": "train",
                             "breasts": int((db.split == "train").sum()), "examples": int((ds.split == "train").sum())}}
        path = save_model(out / f"{slug(cond)}.npz", sel.estimator, meta=meta)
        written.append({"condition": cond.name, "file": str(path), "family": sel.family, "feature_set": fs,
                        "cv_rmse_pct": round(sel.cv_rmse_pct, 4)})
        advance()
    return written
