"""`breastplan batch` of 20 realistic patients' recordings: throughput with 1 and 2 local workers, and on
a Dask LocalCluster of 2 workers.

The folder: 20 MakeHuman patients (`scenes.makehuman.BodyOptions`: cup 0.3–0.9, firmness 0.2–0.8,
weight 0.3–0.7, asymmetry −0.4..0.4, poses a-pose / arms-down / hands-on-hips), each recorded through
depthai as `scan-synth` does (8 depth frames, 640×400, camera 600–750 mm, pitch −8..8°, yaw −6..6°,
wall 400 mm), drawn from a fixed seed. Each round, one after the other so that all three see the same
load of the (shared, noisy) machine, a whole `breastplan batch` process into a fresh output folder:
- `--jobs 1` (the baseline);
- `--jobs 2`: throughput (cases per minute) at least 1.7 × the baseline's (target);
- `--executor dask --jobs 2` (a LocalCluster of 2 single-threaded worker processes, started and closed
  by the batch): within 15 % of `--jobs 2`'s time (target: dask time / local time ≤ 1.15).
Every figure is the median over the rounds; the ratios are those of the medians. Also the mean time of one
case as the manifest records it, alone (`--jobs 1`) and beside another (`--jobs 2`): their ratio bounds the
throughput two workers can reach on this machine (2 / that ratio).

Run:  .venv/bin/python benchmarks/bench_batch.py [--repeats N] [--quick]   (default 2; --quick 1)
"""
from __future__ import annotations

import json
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from timing import fmt, repeats_argument, rounded, timed

BIN = Path(sys.executable).with_name("breastplan")
PATIENTS = 20
POSES = ("a-pose", "arms-down", "hands-on-hips")
TARGETS = {"jobs2_speedup": 1.7, "dask_over_local": 1.15}
RUNS = {"--jobs 1": ["--jobs", "1"], "--jobs 2": ["--jobs", "2"],
        "--executor dask --jobs 2": ["--executor", "dask", "--jobs", "2"]}


def write_patients(folder: Path, seed: int = 0) -> None:
    """20 realistic recordings in `folder`."""
    from breastplan.scenes.makehuman import BodyOptions
    from breastplan.scenes.realistic import CameraOptions, make_body_scene
    from breastplan.ingest.recording import write_recording

    rng = np.random.default_rng(seed)
    for i in range(PATIENTS):
        body = BodyOptions(cup=float(rng.uniform(0.3, 0.9)), firmness=float(rng.uniform(0.2, 0.8)),
                           weight=float(rng.uniform(0.3, 0.7)), pose=POSES[i % len(POSES)],
                           modifiers={"asymmetry": float(rng.uniform(-0.4, 0.4))})
        camera = CameraOptions(distance_mm=float(rng.uniform(600, 750)), pitch_deg=float(rng.uniform(-8, 8)),
                               yaw_deg=float(rng.uniform(-6, 6)), resolution="640x400")
        scene = make_body_scene(body, camera)
        write_recording(folder / f"patient{i:02d}.mcap", scene.frames(8, i), camera.K)


def batch(folder: Path, out: Path, args: list[str]) -> dict:
    """Run one batch; its manifest's summary and the mean seconds of a case (the manifest's)."""
    shutil.rmtree(out, ignore_errors=True)
    subprocess.run([str(BIN), "batch", str(folder), "--out", str(out), *args],
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
    manifest = json.loads((out / "manifest.json").read_text())
    return {**manifest["summary"], "case_s": statistics.mean(c["seconds"] for c in manifest["cases"])}


def main() -> None:
    repeats = repeats_argument(__doc__.splitlines()[0], 2, 1)
    work = Path(tempfile.mkdtemp(prefix="bench-batch-"))
    try:
        folder = work / "patients"
        folder.mkdir()
        write_patients(folder)
        seconds = {name: [] for name in RUNS}
        case_s = {name: [] for name in RUNS}
        summaries = {}
        for _ in range(repeats):
            for name, args in RUNS.items():
                result = {}
                seconds[name].append(timed(lambda: result.update(batch(folder, work / "out", args))))
                case_s[name].append(result.pop("case_s"))
                summaries[name] = result
        median = {name: statistics.median(s) for name, s in seconds.items()}
        case = {name: statistics.median(s) for name, s in case_s.items()}
    finally:
        shutil.rmtree(work, ignore_errors=True)

    per_minute = {name: 60.0 * PATIENTS / s for name, s in median.items()}
    speedup = per_minute["--jobs 2"] / per_minute["--jobs 1"]
    dask_ratio = median["--executor dask --jobs 2"] / median["--jobs 2"]
    ceiling = 2 * case["--jobs 1"] / case["--jobs 2"]   # if two cases at once took no longer each than one alone
    table = Table(title=f"bench_batch — {PATIENTS} realistic recordings, medians of {repeats} rounds")
    for column in ("run", "median", "cases / min", "a case (mean)", "planned", "failed", "vs baseline", "target", "met"):
        table.add_column(column)
    targets = {"--jobs 1": ("baseline", "", ""),
               "--jobs 2": (f"{speedup:.2f}× throughput", f"≥ {TARGETS['jobs2_speedup']}×",
                            "yes" if speedup >= TARGETS["jobs2_speedup"] else "no"),
               "--executor dask --jobs 2": (f"{dask_ratio:.3f} × --jobs 2's time", f"≤ {TARGETS['dask_over_local']}",
                                            "yes" if dask_ratio <= TARGETS["dask_over_local"] else "no")}
    for name in RUNS:
        s = summaries[name]
        table.add_row(name, fmt(median[name]), f"{per_minute[name]:.1f}", fmt(case[name]), str(s["done"]),
                      str(s["failed"]), *targets[name])
    Console().print(table)
    print(f"A case planned beside another takes {case['--jobs 2'] / case['--jobs 1']:.2f}× as long as alone: two "
          f"workers can give at most {ceiling:.2f}× the throughput of one on this machine.")
    print(json.dumps(rounded({"benchmark": "batch", "cases": PATIENTS, "repeats": repeats, "seconds": median,
                              "cases_per_minute": per_minute, "case_seconds": case, "jobs2_speedup": speedup,
                              "jobs2_ceiling": ceiling, "dask_over_local": dask_ratio,
                              "baseline": "--jobs 1", "summaries": summaries, "targets": TARGETS})))


if __name__ == "__main__":
    main()
