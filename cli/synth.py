"""The `synth` command: synthetic database V or S (docs/model.md §4)."""
from __future__ import annotations

from pathlib import Path
from typing import List

import typer

from breastplan.clock import Clock
from breastplan.deform.conditions import CONDITIONS, find_condition

from .app import JSON, command
from .output import progress, report, usage_error, writable


MAX_POINTS = 250_000
"""Points per breast at most: database V then holds 65 × 250 000 points, about 400 MB."""


@command()
def synth(
    db: str = typer.Option(..., "--db", help="Database to generate: V (65 breasts) or S (60)."),
    out: Path = typer.Option(..., "--out", help="Folder for database.npz (and the PLYs)."),
    seed: int = typer.Option(0, "--seed", help="Random seed; the database is a pure function of it."),
    points: int = typer.Option(10_000, "--points", help="Points per breast (a square number)."),
    ply: bool = typer.Option(False, "--ply", help="Also write one PLY per breast (mm, breast frame)."),
    pairs: List[str] = typer.Option([], "--pairs", metavar="CONDITION",
                                    help="Also write DIR/pairs.csv and the before/after PLYs of the condition's "
                                         "dataset (every breast × 8 degrees), a pairs folder for "
                                         "train-statistical; repeatable; 'all' for the six conditions of the "
                                         f"shipped models. Conditions: {'; '.join(CONDITIONS)}."),
    as_json: bool = JSON,
):
    """Write synthetic database V or S (docs/model.md §4) as DIR/database.npz (with --pairs, a pairs folder too)."""
    clock = Clock()
    if db not in ("V", "S"):
        raise usage_error(f"'{db}' is not a database; choose V or S", "--db")
    if seed < 0:
        raise usage_error(f"--seed must be 0 or more, got {seed}", "--seed")
    if not 9 <= points <= MAX_POINTS:
        raise usage_error(f"--points must be a square number from 9 to {MAX_POINTS:,} per breast, got {points:,}",
                          "--points")

    conditions = _pair_conditions(pairs)

    from breastplan.learn.databases import build_database, grid_for

    try:
        grid_for(points)
    except ValueError as exc:
        raise usage_error(str(exc), "--points") from None
    writable(out, folder=True)
    database = build_database(db, seed=seed, n_points=points)
    datasets = []
    if conditions:
        from breastplan.deform.names import DD
        from breastplan.learn.datasets import build_dataset

        with progress(f"deforming {len(database)} breasts by {len(conditions)} condition"
                      f"{'s' * (len(conditions) > 1)}", len(database) * len(conditions)) as advance:
            datasets = [build_dataset(database, cond, DD, advance) for cond in conditions]
    from breastplan.atomic import atomic_set

    path, pairs_csv = out / "database.npz", None
    with atomic_set() as stage:                        # the database, its PLYs and pairs, all or nothing
        if ply:
            with progress(f"writing {len(database)} PLYs", len(database)) as advance:
                database.write_plys(out, advance, stage)
        if datasets:
            from breastplan.learn.pair_folder import count_files, write_pairs

            total = count_files(datasets)
            with progress(f"writing {total} pair PLYs", total) as advance:
                pairs_csv = write_pairs(out, datasets, stage, advance)
        database.save(stage(path))
    train = database.split == "train"
    report({"database": str(path), "breasts": len(database), "train": int(train.sum()),
            "test": int((~train).sum()), "points_per_breast": int(database.points.shape[1]),
            "volume_mean_cc": float(database.volume_cc.mean()),
            "volume_sd_cc": float(database.volume_cc.std(ddof=1)),
            "ply_folder": str(out) if ply else None, "pairs": str(pairs_csv) if pairs_csv else None,
            "pair_count": sum(len(d) for d in datasets), "seconds": clock.seconds},
           as_json, f"database {db}")


def _pair_conditions(names: List[str]) -> list:
    """The conditions `--pairs` names, each once, in the order given ('all': the shipped models' six);
    a usage error for a name that is none."""
    chosen = {}
    for name in names:
        if name.strip().lower() == "all":
            from breastplan.learn.train import DEPLOYED

            found = [find_condition(n) for n in DEPLOYED]
        else:
            try:
                found = [find_condition(name)]
            except ValueError:
                raise usage_error(f"'{name}' is not a condition; choose all or one of: {'; '.join(CONDITIONS)}",
                                  "--pairs") from None
        chosen.update((c.name, c) for c in found)
    return list(chosen.values())
