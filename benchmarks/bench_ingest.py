"""Accuracy and speed of the ingest stage: depthai recordings of the synthetic scanner → breast clouds.

Measures:

1. accuracy: for seeds 0, 1, 2 × tilt 0° and 10° × both sides, 10 depth frames of the synthetic
   scanner are recorded with `write_recording`, replayed with `read_recording`, ingested
   (`ingest_frames`) and compared with the truth (`scan_errors`). Targets: RMS ≤ 0.8 mm,
   nipple ≤ 2 mm, z axis ≤ 3°, coverage ≥ 95 %. Baseline, same run: the RMS of the same
   pipeline on the first frame alone (`max_frames=1`), to show what temporal fusion buys;
2. speed, as medians over repeats after one warm-up call:
   (a) one 640×400 frame → the cropped, downsampled breast cloud (`ingest_frames` on 1 frame;
       target ≤ 60 ms); baseline: open3d `PointCloud.create_from_depth_image` +
       `voxel_down_sample(2.0)` of the same whole frame (the least any open3d pipeline does);
   (b) a 30-frame recording through the whole pipeline, replay included
       (`breastplan.ingest.scan.ingest(path, IngestOptions("left"))`; target ≤ 1.5 s); baseline: the depthai
       replay alone (`read_recording(path)`);
   (c) the median time of every step the pipeline times (`Ingested.timings_ms`), for (a) and (b).

Each timed call alternates with its baseline call, so that both see the same load; ratios are
measured / baseline, so runs on a noisy shared machine can be compared. Nothing is
asserted: the script prints tables, then one line of JSON with all figures.

Run:  .venv/bin/python benchmarks/bench_ingest.py [--frame-repeats N] [--scan-repeats M] [--quick]
      (defaults 31 and 15 repeats, seeds 0 1 2; --quick uses seed 0, 5 and 3 repeats)
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import open3d as o3d
from rich.console import Console
from rich.table import Table
from threadpoolctl import threadpool_limits

from breastplan.scenes import synthetic
from breastplan.ingest.pipeline import ingest_frames
from breastplan.ingest.recording import DepthFrames, read_recording, write_recording
from breastplan.ingest.scan import ingest
from breastplan.options import IngestOptions

from timing import fmt, median_times, timed

SEEDS = (0, 1, 2)
TILTS_DEG = (0.0, 10.0)
ACCURACY_FRAMES = 10
SPEED_FRAMES = 30
VOXEL_MM = 2.0
TARGETS = {"rms_mm": 0.8, "nipple_mm": 2.0, "z_axis_deg": 3.0, "coverage": 0.95,
           "one_frame_s": 0.060, "recording_30_s": 1.5}
BASELINE_NOTE = (
    "Baselines, measured in the same run: accuracy — the RMS of the same pipeline on the first frame "
    "of the same recording alone (read_recording(max_frames=1)); one frame — open3d "
    "create_from_depth_image + voxel_down_sample(2 mm) of the same whole 640×400 frame; 30 frames — "
    "read_recording(path) alone (the depthai replay).")


def to_camera(result) -> tuple[np.ndarray, np.ndarray]:
    """The ingested points (breast frame) and the breast z axis, in the camera frame."""
    inv = np.linalg.inv(result.input_to_breast)
    return result.points @ inv[:3, :3].T + inv[:3, 3], inv[:3, 2]


def errors(frames: DepthFrames, truth, side: str) -> dict:
    result = ingest_frames(frames, IngestOptions(side, VOXEL_MM))
    points, z_axis = to_camera(result)
    return synthetic.scan_errors(points, result.nipple_camera, z_axis, truth, side)


def met_accuracy(e: dict) -> bool:
    return bool(e["rms_mm"] <= TARGETS["rms_mm"] and e["nipple_mm"] <= TARGETS["nipple_mm"]
                and e["z_axis_deg"] <= TARGETS["z_axis_deg"] and e["coverage"] >= TARGETS["coverage"])


# --- 1. accuracy ---------------------------------------------------------------------------
def accuracy_cases(seeds, workdir: Path) -> list[dict]:
    """One row per seed × tilt × side: fused (10 frames) and single-frame errors against the truth."""
    cases = []
    for seed in seeds:
        for tilt in TILTS_DEG:
            scene = synthetic.make_scene(seed, tilt_deg=tilt)
            stem = f"seed{seed}_tilt{tilt:g}"
            path = write_recording(workdir / f"{stem}.mcap",
                                   synthetic.depth_frames(scene, ACCURACY_FRAMES, seed), scene.K)
            truth = synthetic.load_truth(synthetic.save_truth(workdir / f"{stem}_truth.npz", scene, ACCURACY_FRAMES))
            fused, single = read_recording(path), read_recording(path, max_frames=1)
            for side in synthetic.SIDES:
                e, e1 = errors(fused, truth, side), errors(single, truth, side)
                cases.append({"seed": seed, "tilt_deg": tilt, "side": side,
                              "distance_mm": float(scene.meta["distance_mm"]), "frames_recorded": ACCURACY_FRAMES,
                              "frames": int(fused.depth.shape[0]),
                              **e, "single_frame": e1, "rms_1frame_mm": e1["rms_mm"],
                              "fusion_ratio": e1["rms_mm"] / e["rms_mm"], "met": met_accuracy(e)})
    return cases


def worst(cases: list[dict]) -> dict:
    w = {"rms_mm": max(c["rms_mm"] for c in cases), "rms_1frame_mm": max(c["rms_1frame_mm"] for c in cases),
         "nipple_mm": max(c["nipple_mm"] for c in cases), "z_axis_deg": max(c["z_axis_deg"] for c in cases),
         "coverage": min(c["coverage"] for c in cases), "points": min(c["points"] for c in cases),
         "frames": min(c["frames"] for c in cases),
         "fusion_ratio": min(c["fusion_ratio"] for c in cases)}
    w["met"] = {k: bool(w[k] >= TARGETS[k]) if k == "coverage" else bool(w[k] <= TARGETS[k])
                for k in ("rms_mm", "nipple_mm", "z_axis_deg", "coverage")}
    return w


def print_accuracy(cases: list[dict], w: dict, console: Console) -> None:
    table = Table(title=f"bench_ingest — accuracy ({ACCURACY_FRAMES} fused frames vs 1 frame, voxel {VOXEL_MM:g} mm)")
    cols = ("seed", "tilt", "side", "distance", "frames", "points", "RMS", "RMS 1 frame", "1 frame / fused", "nipple",
            "z axis", "coverage", "met")
    for col in cols:
        table.add_column(col, justify="left" if col == "side" else "right")
    for c in cases:
        table.add_row(str(c["seed"]), f"{c['tilt_deg']:g}°", c["side"], f"{c['distance_mm']:.0f} mm",
                      f"{c['frames']}/{c['frames_recorded']}", f"{c['points']:,}", f"{c['rms_mm']:.3f} mm", f"{c['rms_1frame_mm']:.3f} mm",
                      f"{c['fusion_ratio']:.2f}", f"{c['nipple_mm']:.2f} mm", f"{c['z_axis_deg']:.2f}°",
                      f"{100 * c['coverage']:.1f} %", "yes" if c["met"] else "no")
    table.add_section()
    yn = lambda k: "yes" if w["met"][k] else "no"  # noqa: E731
    table.add_row("worst", "", "", "", f"{w['frames']}", f"{w['points']:,}", f"{w['rms_mm']:.3f} mm", f"{w['rms_1frame_mm']:.3f} mm",
                  f"{w['fusion_ratio']:.2f}", f"{w['nipple_mm']:.2f} mm", f"{w['z_axis_deg']:.2f}°",
                  f"{100 * w['coverage']:.1f} %", "yes" if all(w["met"].values()) else "no")
    table.add_row("target", "", "", "", "", "", f"≤ {TARGETS['rms_mm']} mm", "", "", f"≤ {TARGETS['nipple_mm']:g} mm",
                  f"≤ {TARGETS['z_axis_deg']:g}°", f"≥ {100 * TARGETS['coverage']:g} %", "")
    table.add_row("met", "", "", "", "", "", yn("rms_mm"), "", "", yn("nipple_mm"), yn("z_axis_deg"), yn("coverage"), "")
    console.print(table)


# --- 2. speed ------------------------------------------------------------------------------
def step_medians(runs: list[dict]) -> dict:
    """Median ms of each step over the runs (steps in pipeline order)."""
    return {step: statistics.median(r.get(step, 0.0) for r in runs) for step in runs[0]}


def speed_one_frame(frame: DepthFrames, repeats: int) -> dict:
    """(a) ingest_frames on one frame vs open3d back-projection + voxel downsampling of that frame."""
    timings = []

    def run():
        timings.append(ingest_frames(frame, IngestOptions("left", VOXEL_MM)).timings_ms)
    K, (w, h) = frame.K, frame.size
    intrinsic = o3d.camera.PinholeCameraIntrinsic(w, h, K[0, 0], K[1, 1], K[0, 2], K[1, 2])
    depth = np.ascontiguousarray(frame.depth[0])

    parts = []

    def baseline_fn():
        t0 = time.perf_counter()
        cloud = o3d.geometry.PointCloud.create_from_depth_image(o3d.geometry.Image(depth), intrinsic,
                                                                depth_scale=1.0, depth_trunc=1e9)
        t1 = time.perf_counter()
        cloud.voxel_down_sample(VOXEL_MM)
        parts.append((t1 - t0, time.perf_counter() - t1, len(cloud.points)))
    median, baseline = median_times(run, baseline_fn, repeats)
    return {"case": f"1 frame {w}×{h} → breast cloud (ingest_frames)", "repeats": repeats, "median_s": median,
            "baseline_s": baseline, "ratio": median / baseline, "target_s": TARGETS["one_frame_s"],
            "met": bool(median <= TARGETS["one_frame_s"]), "steps_ms": step_medians(timings[1:]),
            "frames": [1] * repeats, "baseline_points": parts[-1][2],
            "baseline_parts_s": {"create_from_depth_image": statistics.median(p[0] for p in parts[1:]),
                                 "voxel_down_sample": statistics.median(p[1] for p in parts[1:])}}


def speed_recording(path: Path, repeats: int) -> dict:
    """(b) scan.ingest of a 30-frame recording (replay included) vs the depthai replay alone."""
    timings, frames, replayed = [], [], []

    def run():
        scan = ingest(path, IngestOptions("left", VOXEL_MM))
        timings.append(scan.timings_ms)
        frames.append(scan.source.frames)
    median, baseline = median_times(run, lambda: replayed.append(read_recording(path).depth.shape[0]), repeats)
    return {"case": f"{SPEED_FRAMES}-frame recording → breast cloud (scan.ingest)", "repeats": repeats,
            "median_s": median, "baseline_s": baseline, "ratio": median / baseline,
            "target_s": TARGETS["recording_30_s"], "met": bool(median <= TARGETS["recording_30_s"]),
            "steps_ms": step_medians(timings[1:]), "frames": frames[1:], "baseline_frames": replayed[1:]}


def print_speed(rows: list[dict], console: Console) -> None:
    parts = rows[0]["baseline_parts_s"]
    caption = (f"{BASELINE_NOTE} The one-frame baseline splits into create_from_depth_image "
               f"{fmt(parts['create_from_depth_image'])} + voxel_down_sample {fmt(parts['voxel_down_sample'])} "
               f"(whole frame, {rows[0]['baseline_points']:,} points after downsampling).")
    table = Table(title="bench_ingest — speed (medians after one warm-up; each call alternates with its baseline)",
                  caption=caption, caption_justify="left")
    for col in ("case", "repeats", "frames fused (min–max)", "median", "baseline median", "ratio", "target", "met"):
        table.add_column(col, justify="left" if col == "case" else "right")
    for r in rows:
        table.add_row(r["case"], str(r["repeats"]), f"{min(r['frames'])}–{max(r['frames'])}", fmt(r["median_s"]), fmt(r["baseline_s"]), f"{r['ratio']:.1f}",
                      f"≤ {fmt(r['target_s'])}", "yes" if r["met"] else "no")
    console.print(table)

    one, rec = rows
    steps = list(dict.fromkeys([*rec["steps_ms"], *one["steps_ms"]]))
    table = Table(title="bench_ingest — median time of each pipeline step (Ingested.timings_ms)")
    table.add_column("step")
    for r, label in ((one, "1 frame"), (rec, f"{SPEED_FRAMES} frames, replay included")):
        table.add_column(f"{label}", justify="right")
        table.add_column("share", justify="right")
    cells = lambda r, s: ((f"{r['steps_ms'][s]:.2f} ms", f"{100 * r['steps_ms'][s] / sum(r['steps_ms'].values()):.0f} %")  # noqa: E731
                          if s in r["steps_ms"] else ("", ""))
    for s in steps:
        table.add_row(s, *cells(one, s), *cells(rec, s))
    table.add_section()
    table.add_row("sum of step medians", f"{sum(one['steps_ms'].values()):.2f} ms", "",
                  f"{sum(rec['steps_ms'].values()):.2f} ms", "")
    table.add_row("median of the whole call", f"{1e3 * one['median_s']:.2f} ms", "",
                  f"{1e3 * rec['median_s']:.2f} ms", "")
    console.print(table)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frame-repeats", type=int, help="repeats of the one-frame timings (default 31)")
    parser.add_argument("--scan-repeats", type=int, help="repeats of the 30-frame timings (default 15)")
    parser.add_argument("--quick", action="store_true", help="seed 0 only, 5 and 3 repeats")
    args = parser.parse_args()
    seeds = SEEDS[:1] if args.quick else SEEDS
    frame_repeats = args.frame_repeats or (5 if args.quick else 31)
    scan_repeats = args.scan_repeats or (3 if args.quick else 15)
    console = Console(width=150)
    start, load_start = time.perf_counter(), os.getloadavg()

    with tempfile.TemporaryDirectory(prefix="bench_ingest_") as tmp, threadpool_limits(1, "blas"):  # as `ingest` runs
        workdir = Path(tmp)
        cases = accuracy_cases(seeds, workdir)
        w = worst(cases)
        print_accuracy(cases, w, console)

        scene = synthetic.make_scene(0)
        path = write_recording(workdir / "speed_30.mcap", synthetic.depth_frames(scene, SPEED_FRAMES, 0), scene.K)
        single = read_recording(path, max_frames=1)
        rows = [speed_one_frame(single, frame_repeats), speed_recording(path, scan_repeats)]
        print_speed(rows, console)

    lost = [f"seed {c['seed']} tilt {c['tilt_deg']:g}° {c['side']}: {c['frames']}/{c['frames_recorded']}"
            for c in cases if c["frames"] < c["frames_recorded"]]
    lost += [f"{r['case']}: {min(r[k])}/{SPEED_FRAMES} ({k})" for r in rows[1:]
             for k in ("frames", "baseline_frames") if min(r[k]) < SPEED_FRAMES]
    if lost:
        console.print("[bold]Warning:[/] read_recording returned fewer frames than were recorded — "
                      + "; ".join(lost))
    accuracy_met = all(w["met"].values())
    speed_met = all(r["met"] for r in rows)
    print(json.dumps({
        "benchmark": "bench_ingest", "quick": bool(args.quick), "seeds": list(seeds), "tilts_deg": list(TILTS_DEG),
        "accuracy_frames": ACCURACY_FRAMES, "speed_frames": SPEED_FRAMES, "voxel_mm": VOXEL_MM,
        "frame_repeats": frame_repeats, "scan_repeats": scan_repeats, "targets": TARGETS,
        "accuracy": {"cases": cases, "worst": w, "met": accuracy_met},
        "speed": {"one_frame": rows[0], "recording_30": rows[1], "met": speed_met},
        "frames_lost": lost, "loadavg_start": load_start, "loadavg_end": os.getloadavg(), "met": bool(accuracy_met and speed_met), "wall_s": time.perf_counter() - start}))


if __name__ == "__main__":
    main()
