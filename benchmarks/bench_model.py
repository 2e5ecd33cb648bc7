"""Speed of the breast model: primitive sampling, the five global deformations, database S + datasets.

Measures (docs/model.md §2–§5), each as the median wall time over repeats after one warm-up call:

1. `Primitive.sample` on 100×100 and 1000×1000 grids, for P00 and a non-unit-eps primitive;
2. each of the five deformations, and all five together (`Deformation.apply`), on 10 000 and
   1 000 000 points of P00 (target: all five on 1 M points ≤ 150 ms);
3. `build_database("S")` and `build_dataset(db, name, 8)` for the eight conditions
   (target: both together ≤ 20 s); the reference-extent cache is cleared before each repeat.

Every row has a baseline measured in the same run (see the footnote of the table) and the
ratio measured / baseline, so runs on a noisy shared machine can be compared. Nothing is
asserted: the script prints a table, then one line of JSON with all figures.

Run:  .venv/bin/python benchmarks/bench_model.py [--repeats N] [--db-repeats M] [--quick]
      (defaults 7 and 3 repeats; --quick uses 3 and 1)
"""
from __future__ import annotations

import argparse
import json
import statistics

import numpy as np
from rich.console import Console
from rich.table import Table

from breastplan import Primitive
from breastplan.deform import degree
from breastplan.deform.conditions import CONDITIONS
from breastplan.deform.global_deformations import (Deformation, flatten_side, ptosis, top_shape,
                                                   turn, turn_top)
from breastplan.learn.databases import build_database
from breastplan.learn.datasets import build_dataset

from timing import fmt, median_time, timed

P00 = Primitive()
P_EPS = Primitive(9, 11, 10, 8, 12, 0.8, 1.2)
GRIDS = {10_000: (100, 100), 1_000_000: (1000, 1000)}
ALL_FIVE = Deformation(top_shape=(1, -0.5, 0.5, -0.5), flatten_side=(0.1, 0.05), turn_top=(0.41, 0.1),
                       ptosis=(1.125, 0.25), turn=(1.1, 0.5))
DEFORMATIONS = {  # case name → f(points), parameters as in ALL_FIVE
    "ptosis": lambda p: ptosis(p, *ALL_FIVE.ptosis),
    "turn": lambda p: turn(p, *ALL_FIVE.turn),
    "top-shape": lambda p: top_shape(p, *ALL_FIVE.top_shape, primitive=P00),
    "flatten-side": lambda p: flatten_side(p, *ALL_FIVE.flatten_side, primitive=P00),
    "turn-top": lambda p: turn_top(p, *ALL_FIVE.turn_top, primitive=P00),
    "all five (Deformation.apply)": lambda p: ALL_FIVE.apply(p, P00),
}
TARGET_ALL_FIVE_1M_S = 0.150
TARGET_DB_DATASETS_S = 20.0
DD = 8
BASELINE_NOTE = (
    "Baselines, measured in the same run: per-point rows — np.linalg.norm(points, axis=1) on the "
    "same (N, 3) float64 points; database/dataset rows (points = per breast) — 'minimum numpy work': P00.sample(100, 100) "
    "60 times (database S) and/or one such norm of a 10 000×3 array per deformed breast "
    "(60 for database S, 60·8·8 = 3840 for the datasets; the total row is 60 samples + 3840 norms).")


def row(case: str, points: int, median_s: float, baseline_s: float, target_s: float | None = None) -> dict:
    return {"case": case, "points": points, "median_s": median_s, "baseline_s": baseline_s,
            "ratio": median_s / baseline_s, "target_s": target_s,
            "met": None if target_s is None else bool(median_s <= target_s)}


def per_point_rows(repeats: int) -> list[dict]:
    """Sampling and deformation rows, each against a norm of the same points."""
    rows = []
    for n, grid in GRIDS.items():
        points = P00.sample(*grid)
        baseline = median_time(lambda: np.linalg.norm(points, axis=1), repeats)
        for name, prim in (("sample P00", P00), ("sample eps (0.8, 1.2)", P_EPS)):
            rows.append(row(name, n, median_time(lambda: prim.sample(*grid), repeats), baseline))
        for name, fn in DEFORMATIONS.items():
            target = TARGET_ALL_FIVE_1M_S if name.startswith("all five") and n == 1_000_000 else None
            rows.append(row(name, n, median_time(lambda: fn(points), repeats), baseline, target))
    return rows


def database_rows(repeats: int) -> list[dict]:
    """Database S, its 8 condition datasets (#dd = 8), and both, timed per repeat (plus a warm-up)."""
    db_times, ds_times = [], []
    for _ in range(repeats + 1):
        degree._reference_extents.cache_clear()
        db = None

        def build():
            nonlocal db
            db = build_database("S")
        db_times.append(timed(build))
        ds_times.append(timed(lambda: [build_dataset(db, name, DD) for name in CONDITIONS]))
    n_breasts, n_points = db.points.shape[:2]
    n_deformed = n_breasts * len(CONDITIONS) * DD

    samples = lambda: [P00.sample(*db.grid) for _ in range(n_breasts)]
    sampled = samples()
    norms = lambda k: [np.linalg.norm(sampled[i % n_breasts], axis=1) for i in range(k)]
    base_sample = median_time(samples, repeats)
    base_norm = median_time(lambda: norms(n_deformed), repeats)
    base_db = base_sample + base_norm * n_breasts / n_deformed

    med = lambda ts: statistics.median(ts[1:])
    totals = [a + b for a, b in zip(db_times, ds_times)]
    return [row(f"database S ({n_breasts} breasts)", n_points, med(db_times), base_db),
            row(f"datasets {len(CONDITIONS)} conditions × {DD} degrees", n_points, med(ds_times), base_norm),
            row("database S + datasets", n_points, med(totals), base_sample + base_norm,
                TARGET_DB_DATASETS_S)]


def print_table(rows: list[dict], repeats: int, db_repeats: int) -> None:
    table = Table(title=f"bench_model — medians of {repeats} (per-point) / {db_repeats} (database) repeats",
                  caption=BASELINE_NOTE, caption_justify="left")
    for col in ("case", "points", "median", "baseline median", "ratio", "target", "met"):
        table.add_column(col, justify="left" if col == "case" else "right")
    for r in rows:
        met = "" if r["met"] is None else ("yes" if r["met"] else "no")
        target = "" if r["target_s"] is None else f"≤ {fmt(r['target_s'], 2)}"
        table.add_row(r["case"], f"{r['points']:,}", fmt(r["median_s"], 2), fmt(r["baseline_s"], 2),
                      f"{r['ratio']:.1f}", target, met)
    Console(width=140).print(table)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, help="repeats of the per-point timings (default 7)")
    parser.add_argument("--db-repeats", type=int, help="repeats of the database timings (default 3)")
    parser.add_argument("--quick", action="store_true", help="3 and 1 repeats")
    args = parser.parse_args()
    repeats = args.repeats or (3 if args.quick else 7)
    db_repeats = args.db_repeats or (1 if args.quick else 3)
    rows = per_point_rows(repeats) + database_rows(db_repeats)
    print_table(rows, repeats, db_repeats)
    print(json.dumps({"benchmark": "bench_model", "repeats": repeats, "db_repeats": db_repeats, "rows": rows}))


if __name__ == "__main__":
    main()
