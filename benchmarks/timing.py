"""Helpers shared by the benchmarks: wall-clock seconds, medians after a warm-up, rounded JSON.

The clock is breastplan's own (`breastplan.clock.Clock`), the one the commands and the ingest
pipeline use.
"""
from __future__ import annotations

import argparse
import statistics

from breastplan.clock import Clock


def fmt(seconds: float, ms_digits: int = 1) -> str:
    """Seconds as 'x.x ms' below one second, else 'x.xx s'."""
    return f"{seconds * 1e3:.{ms_digits}f} ms" if seconds < 1 else f"{seconds:.2f} s"


def timed(fn) -> float:
    """Seconds one call of fn() takes."""
    clock = Clock()
    with clock("call"):
        fn()
    return clock.ms["call"] / 1e3


def median_time(fn, repeats: int, before=None) -> float:
    """Median seconds of fn() over `repeats` calls after one warm-up; `before()` runs untimed first."""
    times = []
    for _ in range(repeats + 1):
        if before:
            before()
        times.append(timed(fn))
    return statistics.median(times[1:])


def median_times(fn, baseline, repeats: int) -> tuple[float, float]:
    """Median seconds of fn() and of baseline() over `repeats` calls each after one warm-up of each;
    the calls alternate, so that both see the same load of the (shared, noisy) machine."""
    times = [(timed(fn), timed(baseline)) for _ in range(repeats + 1)][1:]
    return statistics.median(t[0] for t in times), statistics.median(t[1] for t in times)


def repeats_argument(description: str, default: int, quick: int) -> int:
    """Rounds of measurements from the command line: --repeats N, or --quick for `quick` rounds."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--repeats", type=int, help=f"rounds of measurements (default {default})")
    parser.add_argument("--quick", action="store_true", help=f"{quick} rounds")
    args = parser.parse_args()
    return args.repeats or (quick if args.quick else default)


def rounded(x, digits: int = 5):
    """x (nested dicts/lists) with floats to `digits` significant figures, for a JSON line of sane length."""
    if isinstance(x, float):
        return float(f"{x:.{digits}g}")
    if isinstance(x, dict):
        return {k: rounded(v, digits) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [rounded(v, digits) for v in x]
    return x
