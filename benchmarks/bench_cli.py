"""Start-up time of the `breastplan` command: whole processes, as a user (or a test) pays it.

Measures the wall time of whole processes, each as the median over repeats after one warm-up
round; a round runs every case once, one after the other, so that all cases and the baseline
see the same load of the (shared, noisy) machine:

- baseline: `python -c pass` with the virtualenv's interpreter (what any Python command costs);
- `breastplan --help` and `breastplan --version` (targets ≤ 0.4 s each);
- for information: `breastplan fit --help` and `breastplan deform --help`.

Every case must exit 0 (the benchmark stops otherwise). Nothing is asserted: the script prints
a table, then one line of JSON with all figures, the targets and the baseline of the same run.

Run:  .venv/bin/python benchmarks/bench_cli.py [--repeats N] [--quick]
      (default 15 repeats; --quick uses 5)
"""
from __future__ import annotations

import json
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

from timing import fmt, repeats_argument, timed

PYTHON = sys.executable
BREASTPLAN = str(Path(PYTHON).with_name("breastplan")) if Path(PYTHON).with_name("breastplan").exists() \
    else shutil.which("breastplan")
BASELINE = "python -c pass"
CASES = {  # case → (argv, target seconds or None)
    BASELINE: ([PYTHON, "-c", "pass"], None),
    "breastplan --help": ([BREASTPLAN, "--help"], 0.4),
    "breastplan --version": ([BREASTPLAN, "--version"], 0.4),
    "breastplan fit --help": ([BREASTPLAN, "fit", "--help"], None),
    "breastplan deform --help": ([BREASTPLAN, "deform", "--help"], None),
}
BASELINE_NOTE = (f"Baseline, measured in the same run, alternating with the cases: `{BASELINE}` with the "
                 "virtualenv's interpreter. Times are whole processes (start-up, imports, output, exit).")


def run(argv: list[str]) -> None:
    subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)


def measure(repeats: int) -> dict[str, list[float]]:
    """Seconds of every case per round, `repeats` rounds after one warm-up round."""
    times: dict[str, list[float]] = {case: [] for case in CASES}
    for _ in range(repeats + 1):
        for case, (argv, _target) in CASES.items():
            times[case].append(timed(lambda: run(argv)))
    return {case: ts[1:] for case, ts in times.items()}


def rows_of(times: dict[str, list[float]]) -> list[dict]:
    baseline = statistics.median(times[BASELINE])
    rows = []
    for case, (_argv, target) in CASES.items():
        median = statistics.median(times[case])
        rows.append({"case": case, "median_s": median, "min_s": min(times[case]), "max_s": max(times[case]),
                     "baseline_s": baseline, "ratio": median / baseline, "target_s": target,
                     "met": None if target is None else bool(median <= target)})
    return rows


def print_table(rows: list[dict], repeats: int) -> None:
    table = Table(title=f"bench_cli — whole-process wall time, medians of {repeats} alternating rounds",
                  caption=BASELINE_NOTE, caption_justify="left")
    for col in ("case", "median", "min", "max", "baseline median", "ratio", "target", "met"):
        table.add_column(col, justify="left" if col == "case" else "right")
    for r in rows:
        met = "" if r["met"] is None else ("yes" if r["met"] else "no")
        target = "" if r["target_s"] is None else f"≤ {fmt(r['target_s'])}"
        table.add_row(r["case"], fmt(r["median_s"]), fmt(r["min_s"]), fmt(r["max_s"]), fmt(r["baseline_s"]),
                      f"{r['ratio']:.1f}", target, met)
    Console(width=140).print(table)


def main() -> None:
    repeats = repeats_argument(__doc__.splitlines()[0], 15, 5)
    if BREASTPLAN is None:
        sys.exit("bench_cli: the breastplan command is not installed (make test installs it)")
    start, load_start = time.perf_counter(), os.getloadavg()
    rows = rows_of(measure(repeats))
    print_table(rows, repeats)
    targeted = [r for r in rows if r["met"] is not None]
    print(json.dumps({"benchmark": "bench_cli", "repeats": repeats, "baseline": BASELINE,
                      "targets": {r["case"]: r["target_s"] for r in targeted}, "rows": rows,
                      "met": all(r["met"] for r in targeted), "loadavg_start": load_start,
                      "loadavg_end": os.getloadavg(), "wall_s": time.perf_counter() - start}))


if __name__ == "__main__":
    main()
