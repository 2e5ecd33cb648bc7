"""The `synth` command: synthetic database V or S (docs/model.md §4)."""
from __future__ import annotations

from pathlib import Path

import typer

from breastplan.clock import Clock

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
    as_json: bool = JSON,
):
    """Write synthetic database V or S (docs/model.md §4) as DIR/database.npz."""
    clock = Clock()
    if db not in ("V", "S"):
        raise usage_error(f"'{db}' is not a database; choose V or S", "--db")
    if seed < 0:
        raise usage_error(f"--seed must be 0 or more, got {seed}", "--seed")
    if not 9 <= points <= MAX_POINTS:
        raise usage_error(f"--points must be a square number from 9 to {MAX_POINTS:,} per breast, got {points:,}",
                          "--points")

    from breastplan.learn.databases import build_database, grid_for

    try:
        grid_for(points)
    except ValueError as exc:
        raise usage_error(str(exc), "--points") from None
    writable(out, folder=True)
    database = build_database(db, seed=seed, n_points=points)
    from breastplan.atomic import atomic_set

    path = out / "database.npz"
    with atomic_set() as stage:                        # the database and its PLYs, all or nothing
        if ply:
            with progress(f"writing {len(database)} PLYs", len(database)) as advance:
                database.write_plys(out, advance, stage)
        database.save(stage(path))
    train = database.split == "train"
    report({"database": str(path), "breasts": len(database), "train": int(train.sum()),
            "test": int((~train).sum()), "points_per_breast": int(database.points.shape[1]),
            "volume_mean_cc": float(database.volume_cc.mean()),
            "volume_sd_cc": float(database.volume_cc.std(ddof=1)),
            "ply_folder": str(out) if ply else None, "seconds": clock.seconds},
           as_json, f"database {db}")
