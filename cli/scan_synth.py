"""The `scan-synth` command: a synthetic patient's depth frames, recorded through depthai."""
from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from breastplan.clock import Clock

from .app import JSON, command, parse_pairs
from .output import report, usage_error


@command("scan-synth")
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
    clock = Clock()
    if not 1 <= frames <= 300:
        raise usage_error(f"--frames must be 1..300, got {frames}", "--frames")
    if not (distance is None or 400.0 <= distance <= 1200.0):
        raise usage_error(f"--distance must be 400..1200 mm, got {distance}", "--distance")
    if not (0.0 <= noise <= 10.0 and -30.0 <= tilt <= 30.0):
        raise usage_error("--noise must be 0..10 mm and --tilt −30..30 degrees", "--noise/--tilt")

    import numpy as np

    from breastplan import PARAM_NAMES
    from breastplan.ingest import synthetic
    from breastplan.ingest.recording import write_recording

    overrides = _side_overrides(side_params, set(PARAM_NAMES) | set(synthetic.DEFORMATION_NAMES))
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
            "seconds": clock.seconds}, as_json, f"synthetic scan → {out}")


def _side_overrides(items: List[str], names: set[str]) -> dict[str, dict[str, float]]:
    """SIDE:NAME=VALUE,… items → {side: {name: value}}, NAME one of `names`; usage error otherwise."""
    from breastplan.options import SIDES

    overrides: dict[str, dict[str, float]] = {}
    for item in items:
        side, sep, rest = item.partition(":")
        if not sep or side not in SIDES:
            raise usage_error(f"'{item}' is not SIDE:NAME=VALUE,… with SIDE left or right", "--side-params")
        values = parse_pairs([rest], f"{side} breast", "--side-params")
        unknown = sorted(set(values) - names)
        if unknown:
            raise usage_error(f"unknown breast parameters {unknown}; use {sorted(names)}", "--side-params")
        overrides.setdefault(side, {}).update(values)
    return overrides
