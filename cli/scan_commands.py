"""Commands of the scanning stage: `scan-synth` (the synthetic scanner) and `ingest`."""
from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import numpy as np
import typer

from breastplan import PARAM_NAMES
from breastplan.ingest import synthetic
from breastplan.ingest.recording import write_recording
from breastplan.ingest.scan import SIDES, ingest as run_ingest, save_case

from .app import JSON, app, parse_numbers, parse_pairs
from .output import Timer, report, usage_error

SIDE_NAMES = set(PARAM_NAMES) | set(synthetic.DEFORMATION_NAMES)


@app.command("scan-synth")
def scan_synth(
    out: Path = typer.Option(..., "--out", help="The depthai recording to write (.mcap)."),
    truth: Path = typer.Option(..., "--truth", help="Truth NPZ: breast parameters, camera pose, true surfaces."),
    frames: int = typer.Option(10, "--frames", help="Depth frames to record."),
    seed: int = typer.Option(0, "--seed", help="Seed of the patient, the camera and the noise."),
    tilt: float = typer.Option(0.0, "--tilt", help="Camera pitch, degrees (looking down at the chest)."),
    distance: Optional[float] = typer.Option(None, "--distance", help="Camera distance, mm (default: 550–750 by seed)."),
    noise: float = typer.Option(1.0, "--noise", help="Depth noise σ at 0.6 m, mm; grows with distance²."),
    side_params: List[str] = typer.Option([], "--side-params", help="SIDE:NAME=VALUE,… with SIDE left|right and NAME "
                                          "a primitive parameter (a1..a5 in model units, eps1, eps2) or a deformation "
                                          "parameter (b0, c0, s0, …); repeatable. Others are drawn from the seed."),
    as_json: bool = JSON,
):
    """Render depth frames of a synthetic patient and record them through depthai (RecordMessage)."""
    timer = Timer()
    if not 1 <= frames <= 300:
        raise usage_error(f"--frames must be 1..300, got {frames}", "--frames")
    if not (distance is None or 400.0 <= distance <= 1200.0):
        raise usage_error(f"--distance must be 400..1200 mm, got {distance}", "--distance")
    if not (0.0 <= noise <= 10.0 and -30.0 <= tilt <= 30.0):
        raise usage_error("--noise must be 0..10 mm and --tilt −30..30 degrees", "--noise/--tilt")
    overrides = _side_overrides(side_params)
    try:
        scene = synthetic.make_scene(seed, tilt, distance, noise, overrides)
    except ValueError as exc:
        raise usage_error(str(exc), "--side-params") from None
    depth = synthetic.depth_frames(scene, frames, seed)
    write_recording(out, depth, scene.K)
    synthetic.save_truth(truth, scene, frames)
    report({"recording": str(out), "truth": str(truth), "frames": frames, "size": [synthetic.WIDTH, synthetic.HEIGHT],
            "distance_mm": round(scene.meta["distance_mm"], 1), "tilt_deg": tilt,
            "valid_pixels": round(float(np.mean(depth > 0)), 4), "megabytes": round(out.stat().st_size / 1e6, 2),
            "seconds": timer.seconds}, as_json, f"synthetic scan → {out}")


def _side_overrides(items: List[str]) -> dict[str, dict[str, float]]:
    overrides: dict[str, dict[str, float]] = {}
    for item in items:
        side, sep, rest = item.partition(":")
        if not sep or side not in SIDES:
            raise usage_error(f"'{item}' is not SIDE:NAME=VALUE,… with SIDE left or right", "--side-params")
        values = parse_pairs([rest], f"{side} breast", "--side-params")
        unknown = sorted(set(values) - SIDE_NAMES)
        if unknown:
            raise usage_error(f"unknown breast parameters {unknown}; use {sorted(SIDE_NAMES)}", "--side-params")
        overrides.setdefault(side, {}).update(values)
    return overrides


@app.command()
def ingest(
    input: Optional[Path] = typer.Argument(None, help="depthai recording (.mcap) or scan file (PLY, OBJ, STL, PCD, "
                                           "XYZ); omit with --device."),
    side: str = typer.Option(..., "--side", help="The patient's breast to isolate: left or right."),
    out: Path = typer.Option(..., "--out", help="Case folder for scan.ply, scan.npz and camera.ply."),
    voxel: float = typer.Option(2.0, "--voxel", help="Voxel size of the downsampling, mm."),
    frames: Optional[int] = typer.Option(None, "--frames", help="Fuse at most N depth frames (default: all; 10 live)."),
    roi: Optional[str] = typer.Option(None, "--roi", help="X0,Y0,Z0,X1,Y1,Z1: box (camera mm) holding the breast."),
    nipple: Optional[str] = typer.Option(None, "--nipple", help="X,Y,Z: the nipple (camera mm), overriding the apex."),
    units: str = typer.Option("auto", "--units", help="Units of a scan file: auto (from its extent), mm or m."),
    up: str = typer.Option("+y", "--up", help="Superior axis of a scan file: +x, -x, +y, -y, +z or -z."),
    device: bool = typer.Option(False, "--device", help="Capture from a live OAK device instead of INPUT."),
    device_id: Optional[str] = typer.Option(None, "--device-id", help="With --device: the OAK's ID (default: the first)."),
    as_json: bool = JSON,
):
    """Turn a depth recording or scan into the clean breast of one side, in the breast frame."""
    timer = Timer()
    if side not in SIDES:
        raise usage_error(f"'{side}' is not a side; choose left or right", "--side")
    if (input is None) != device:
        raise usage_error("give either INPUT or --device", "INPUT/--device")
    if not 0.5 <= voxel <= 20.0:
        raise usage_error(f"--voxel must be 0.5..20 mm, got {voxel}", "--voxel")
    if frames is not None and frames < 1:
        raise usage_error(f"--frames must be at least 1, got {frames}", "--frames")
    if units not in ("auto", "mm", "m") or up not in ("+x", "-x", "+y", "-y", "+z", "-z"):
        raise usage_error("--units is auto, mm or m; --up is one of +x -x +y -y +z -z", "--units/--up")
    box = parse_numbers(roi, 6, "--roi")
    if box is not None and not (box[:3] < box[3:]).all():
        raise usage_error("--roi needs X0<X1, Y0<Y1, Z0<Z1", "--roi")
    result, source = run_ingest(input, side, voxel, frames, box, parse_numbers(nipple, 3, "--nipple"), units, up, device_id)
    paths = save_case(out, result, source, voxel)
    report({"scan": str(paths["scan_ply"]), "points": len(result.points), "side": result.side,
            "nipple_camera_mm": result.nipple_camera.round(2), "frames": source.frames, "source": source.description,
            "timings_ms": {k: round(v, 1) for k, v in result.timings_ms.items()}, "seconds": timer.seconds},
           as_json, f"ingest {result.side} breast → {out}")
