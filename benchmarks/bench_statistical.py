"""Speed and accuracy of the statistical deformation models (database S, 8 degrees, test split).

1. FFD fitting of every example of one condition (60 breasts fitted before, and 480 pairs after)
   from a cold cache, against the 3-minute target: by closest points with 125 and 216 control
   points (the thesis's way, no correspondence); the baseline, measured in the same run, is the
   fit of the same pairs from corresponding points (least squares: the befores' fits and little
   else).
2. The study (`evaluate --study statistical`, in process, on the warm cache): per condition, the
   best model's indirect metrics against the targets (ptosis b0>b1: Hausdorff µ ≤ 5 %, Euclidean
   µ ≤ 1 %; 95 % of test breasts spike-free, their largest modelled ⇒ original distance at most 3× the
   median; the same on vertex errors is shown beside, no target) beside the thesis's MLP as we reproduce it, the
   thesis's own figure (Table 5.8) and the unchanged breast (the baseline).

Nothing is asserted: tables, then one line of JSON.

Run:  .venv/bin/python benchmarks/bench_statistical.py [--quick] [--out DIR]
"""
from __future__ import annotations

import argparse
import json
import tempfile
import time
import warnings
from pathlib import Path

from rich.console import Console
from rich.table import Table
from threadpoolctl import threadpool_limits

from breastplan.learn.displacements import FitCache, PairOptions
from breastplan.learn.statistical_report import write_report
from breastplan.learn.statistical_study import THESIS_CONDITION, StudyPlan, fit_condition, run_study, study_database

from timing import fmt

TARGET_FIT_S = 180.0
TARGETS = {"hausdorff": 5.0, "euclidean": 1.0, "spike_free_pct": 95.0}


def fitting(cache: Path, quick: bool) -> dict[str, float]:
    """Seconds to fit one condition's pairs from a cold cache, per way of fitting, and the baseline."""
    db = study_database(quick)
    ways = {"closest 125 CP": PairOptions(lattice=5), "closest 216 CP": PairOptions(lattice=6),
            "baseline: corresponding 125 CP": PairOptions(lattice=5, corresponding=True)}
    seconds = {}
    for name, options in ways.items():
        folder = cache / name.replace(" ", "-").replace(":", "").replace(",", "")
        start = time.perf_counter()
        fit_condition(db, THESIS_CONDITION, options, FitCache(folder))
        seconds[name] = time.perf_counter() - start
    return seconds


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="4 breasts per shape and split, 2 500 points, small grids")
    ap.add_argument("--out", type=Path, default=None, help="keep the study's report in this folder")
    args = ap.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="bench-statistical-"))
    cache = Path(tempfile.mkdtemp(prefix="bench-statistical-cache-"))
    warnings.filterwarnings("ignore")
    console = Console()
    with threadpool_limits(1, "blas"):
        fit_seconds = fitting(cache, args.quick)
        table = Table(title=f"FFD fitting of {THESIS_CONDITION}, every example, cold cache", title_justify="left")
        for col in ("fit", "wall time", f"✓ ≤ {fmt(TARGET_FIT_S)}"):
            table.add_column(col)
        for name, s in fit_seconds.items():
            table.add_row(name, fmt(s), "" if name.startswith("baseline") else "✔" if s <= TARGET_FIT_S else "✘")
        console.print(table)

        plan = StudyPlan.quick_plan() if args.quick else StudyPlan()
        start = time.perf_counter()
        results, _ = run_study(plan, FitCache(cache / "study"))
        study_seconds = time.perf_counter() - start
    report = write_report(out, results, {"study": "statistical", "quick": args.quick, "seconds": study_seconds})

    table = Table(title="statistical models: test split, modelled ⇒ original (%)", title_justify="left")
    for col in ("condition", "CP", "fit", "best", "Eucl. µ", "Hausd. µ", "spike-free %", "vertex spike-free %",
                "FFD fit spike-free %", "✓ targets",
                "thesis MLP (ours) Hausd. µ", "thesis Table 5.8", "no change Eucl. / Hausd. µ"):
        table.add_column(col)
    rows = []
    for h in report["best"]:
        ok = (h["hausdorff"] <= TARGETS["hausdorff"] and h["euclidean"] <= TARGETS["euclidean"]
              and h["spike_free_pct"] >= TARGETS["spike_free_pct"])
        t = h["thesis_model"]
        table.add_row(h["condition"], str(h["control_points"]), h["fit"], h["best"], f"{h['euclidean']:.3f}",
                      f"{h['hausdorff']:.3f}", f"{h['spike_free_pct']:.0f}", f"{h['vertex_spike_free_pct']:.0f}",
                      f"{h['field']['spike_free_pct']:.0f}",
                      "✔" if ok else "✘",
                      f"{t['hausdorff']:.2f}" if t else "—", str(h["thesis_hausdorff"] or "—"),
                      f"{h['unchanged']['euclidean']:.2f} / {h['unchanged']['hausdorff']:.2f}")
        rows.append({**h, "targets_met": ok})
    console.print(table)
    console.print(f"study wall time {fmt(study_seconds)}; report: {out / 'report.md'}")
    print(json.dumps({"quick": args.quick, "fit_seconds": fit_seconds, "fit_target_seconds": TARGET_FIT_S,
                      "targets": TARGETS, "study_seconds": study_seconds, "conditions": rows}))


if __name__ == "__main__":
    main()
