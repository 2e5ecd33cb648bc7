"""Accuracy and speed of the deformation-parameter study.

Runs `breastplan evaluate --study all` in process (database S test split, 8 degrees,
modelled ⇒ original) and prints, per condition, the best learnt model's and the exact solver's
indirect metrics against the targets (learnt: Euclidean µ ≤ 0.5 %, Hausdorff µ ≤ 2.0 %; exact:
≤ 0.05 % and ≤ 0.2 %) beside the thesis's figures; then the study's wall time against its
15-minute target, with a baseline measured in the same run: building every dataset the study
uses. Nothing is asserted: a table, then one line of JSON.

Run:  .venv/bin/python benchmarks/bench_learn.py [--study all|ptosis-S|...] [--quick] [--out DIR]
"""
from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

from breastplan.learn.report import write_report
from breastplan.learn.study import run_studies, study_datasets
from breastplan.learn.studies import STUDIES

from timing import fmt

TARGETS = {"learnt": (0.5, 2.0), "exact": (0.05, 0.2)}
TARGET_STUDY_S = 15 * 60


def run(names: list[str], quick: bool, out: Path) -> tuple[dict, float, float]:
    """(report, study seconds, dataset-building seconds)."""
    start = time.perf_counter()
    datasets = study_datasets(names, 8, quick)
    baseline = time.perf_counter() - start
    results = run_studies(datasets, quick)
    seconds = time.perf_counter() - start
    return write_report(out, results, {"study": names, "quick": quick, "seconds": seconds}), seconds, baseline


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--study", default="all", choices=[*STUDIES, "all"])
    ap.add_argument("--quick", action="store_true", help="the small grid and few breasts of --quick")
    ap.add_argument("--out", type=Path, default=None, help="keep the report in this folder")
    args = ap.parse_args()
    names = list(STUDIES) if args.study == "all" else [args.study]
    out = args.out or Path(tempfile.mkdtemp(prefix="bench-learn-"))
    report, seconds, baseline = run(names, args.quick, out)

    table = Table(title="deformation models: test split, modelled ⇒ original (%)", title_justify="left")
    for col in ("study", "condition", "best learnt", "Eucl. µ", "Hausd. µ", "✓ ≤ 0.5 / 2.0",
                "exact Eucl. µ", "exact Hausd. µ", "✓ ≤ 0.05 / 0.2", "thesis Eucl. / Hausd. µ"):
        table.add_column(col)
    rows = []
    for h in report["best"]:
        b, e, t = h["best_learnt"], h["exact_continuous"], h.get("thesis")
        ok_b = b["euclidean"] <= TARGETS["learnt"][0] and b["hausdorff"] <= TARGETS["learnt"][1]
        ok_e = e["euclidean"] <= TARGETS["exact"][0] and e["hausdorff"] <= TARGETS["exact"][1]
        table.add_row(h["study"], h["condition"], h["best"], f"{b['euclidean']:.3f}", f"{b['hausdorff']:.3f}",
                      "✔" if ok_b else "✘", f"{e['euclidean']:.4f}", f"{e['hausdorff']:.4f}", "✔" if ok_e else "✘",
                      f"{t['euclidean']} / {t['hausdorff']}" if t else "—")
        rows.append({**h, "learnt_ok": ok_b, "exact_ok": ok_e})
    console = Console()
    console.print(table)
    console.print(f"study wall time {fmt(seconds)} (target ≤ {fmt(TARGET_STUDY_S)}; "
                  f"baseline, building its datasets: {fmt(baseline)}, ratio {seconds / baseline:.0f}); report: {out}")
    print(json.dumps({"study": names, "quick": args.quick, "seconds": seconds, "baseline_seconds": baseline,
                      "target_seconds": TARGET_STUDY_S, "conditions": rows}))


if __name__ == "__main__":
    main()
