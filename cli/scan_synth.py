"""The `scan-synth` command: a synthetic patient's depth frames, recorded through depthai.

Two bodies: `chen`, the parametric torso with primitive breasts of scenes/synthetic.py, and
`makehuman`, a realistic MakeHuman body (scenes/makehuman.py) seen by the camera of
scenes/realistic.py, which can also write what the camera sees as a scan file.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import List, Optional

import typer

from breastplan.clock import Clock
from breastplan.options import UP_AXES

from .app import JSON, command, parse_pairs
from .output import report, usage_error, writable

BODIES = ("chen", "makehuman")
FLAGS = {"cup": "--cup", "firmness": "--firmness", "weight": "--weight", "muscle": "--muscle",
         "modifiers": "--modifier", "pose": "--pose", "distance_mm": "--distance", "pitch_deg": "--pitch",
         "yaw_deg": "--yaw", "resolution": "--resolution", "noise_mm": "--noise", "wall_mm": "--wall"}
"""Field of makehuman.BodyOptions / realistic.CameraOptions → the option that sets it."""
SUFFIXES = {"--out": (".mcap",), "--truth": (".npz",)}
"""How the names of the outputs end, by option (--scan-file: realistic.SCAN_SUFFIXES)."""


@command("scan-synth")
def scan_synth(
    out: Optional[Path] = typer.Option(None, "--out", help="The depthai recording to write (.mcap); required with "
                                       "--body chen."),
    truth: Path = typer.Option(..., "--truth", help="Truth NPZ: breast parameters (chen) or nipples and half-body "
                               "volumes (makehuman), camera pose, true surfaces."),
    body: str = typer.Option("chen", "--body", help="chen: a torso with primitive breasts of known parameters; "
                             "makehuman: a realistic MakeHuman body (head, arms) with known volumes."),
    frames: int = typer.Option(10, "--frames", help="Depth frames to record."),
    seed: int = typer.Option(0, "--seed", help="Seed of the patient, the camera and the noise (makehuman: the noise)."),
    tilt: float = typer.Option(0.0, "--tilt", "--pitch", help="Camera pitch, degrees (positive: from above, looking "
                               "down at the chest)."),
    distance: Optional[float] = typer.Option(None, "--distance", help="Camera distance, mm (chen: 400..1200, default "
                                             "550–750 by seed; makehuman: 400..1500 from the nipples, default 650)."),
    noise: float = typer.Option(1.0, "--noise", help="Depth noise σ at 0.6 m, mm; grows with distance²."),
    side_params: List[str] = typer.Option([], "--side-params", help="chen: SIDE:NAME=VALUE,… with SIDE left|right "
                                          "and NAME a primitive parameter (a1..a5 in model units, eps1, eps2) or a "
                                          "deformation parameter (b0, c0, s0, …); repeatable. Others are drawn from "
                                          "the seed."),
    cup: Optional[float] = typer.Option(None, "--cup", help="makehuman: cup size 0..1 (default 0.5, MakeHuman's "
                                        "average)."),
    firmness: Optional[float] = typer.Option(None, "--firmness", help="makehuman: breast firmness 0..1 (0 sags; "
                                             "default 0.5)."),
    weight: Optional[float] = typer.Option(None, "--weight", help="makehuman: body weight 0..1 (default 0.5)."),
    muscle: Optional[float] = typer.Option(None, "--muscle", help="makehuman: muscle 0..1 (default 0.5)."),
    modifier: List[str] = typer.Option([], "--modifier", help="makehuman: NAME=VALUE, a MakeHuman modifier "
                                       "(breast_trans, breast_volume_vert, breast_dist, breast_point, asymmetry, "
                                       "torso_width, torso_depth, torso_vshape, underbust) at −1..1; repeatable."),
    pose: Optional[str] = typer.Option(None, "--pose", help="makehuman: a-pose (default), arms-down or hands-on-hips."),
    yaw: Optional[float] = typer.Option(None, "--yaw", help="makehuman: camera turn about the body's vertical axis, "
                                        "−30..30 degrees (positive: from the patient's left; default 0)."),
    resolution: Optional[str] = typer.Option(None, "--resolution", help="makehuman: 640x400, 800x600 (default) or "
                                             "1280x800."),
    wall: Optional[float] = typer.Option(None, "--wall", help="makehuman: a wall this far behind the back, 0..3000 mm "
                                         "(default 400)."),
    no_wall: bool = typer.Option(False, "--no-wall", help="makehuman: no wall behind the patient."),
    scan_file: Optional[Path] = typer.Option(None, "--scan-file", help="makehuman: also (or, without --out, instead) "
                                             "write what the camera sees: .ply the depth pixels back-projected, "
                                             ".obj the body's visible triangles textured by the colour camera "
                                             "(with .mtl and .png beside it), .glb those triangles coloured."),
    units: Optional[str] = typer.Option(None, "--units", help="Units of the --scan-file: mm (default) or m."),
    up: Optional[str] = typer.Option(None, "--up", help="The --scan-file axis the body's up lies on: +x, -x, +y "
                                     "(default), -y, +z or -z."),
    closed: bool = typer.Option(False, "--closed", help="makehuman: the --scan-file holds her whole closed body "
                                "(front, sides and back, as a 360° scanner exports it) instead of what the camera "
                                "sees: .ply, .obj or .glb."),
    as_json: bool = JSON,
):
    """Render depth frames of a synthetic patient and record them through depthai (RecordMessage); for a
    MakeHuman body, also or instead write what the camera sees as a scan file."""
    clock = Clock()
    if body not in BODIES:
        raise usage_error(f"--body must be chen or makehuman, got '{body}'", "--body")
    if not 1 <= frames <= 300:
        raise usage_error(f"--frames must be 1..300, got {frames}", "--frames")
    realistic_only = {"--cup": cup, "--firmness": firmness, "--weight": weight, "--muscle": muscle,
                      "--modifier": modifier or None, "--pose": pose, "--yaw": yaw, "--resolution": resolution,
                      "--wall": wall, "--no-wall": no_wall or None, "--scan-file": scan_file, "--units": units,
                      "--up": up, "--closed": closed or None}
    if body == "makehuman":
        return _scan_makehuman(clock, as_json, out=out, truth=truth, frames=frames, seed=seed, pitch=tilt,
                               distance=distance, noise=noise, side_params=side_params, cup=cup, firmness=firmness,
                               weight=weight, muscle=muscle, modifier=modifier, pose=pose, yaw=yaw,
                               resolution=resolution, wall=wall, no_wall=no_wall, scan_file=scan_file, units=units,
                               up=up, closed=closed)
    given = [flag for flag, value in realistic_only.items() if value is not None]
    if given:
        raise usage_error(f"{given[0]} applies to --body makehuman only", given[0])
    if out is None:
        raise usage_error("--body chen needs --out, the recording to write", "--out")
    outputs = _outputs({"--out": out, "--truth": truth})
    if not (distance is None or 400.0 <= distance <= 1200.0):
        raise usage_error(f"--distance must be 400..1200 mm, got {distance}", "--distance")
    if not (0.0 <= noise <= 10.0 and -30.0 <= tilt <= 30.0):
        raise usage_error("--noise must be 0..10 mm and --tilt −30..30 degrees", "--noise/--tilt")

    import numpy as np

    from breastplan import PARAM_NAMES
    from breastplan.deform.names import DEFORMATION_PARAMS
    from breastplan.atomic import atomic_set
    from breastplan.scenes import synthetic
    from breastplan.ingest.recording import write_recording

    overrides = _side_overrides(side_params, set(PARAM_NAMES) | set(DEFORMATION_PARAMS))
    try:
        scene = synthetic.make_scene(seed, tilt, distance, noise, overrides)
    except ValueError as exc:
        raise usage_error(str(exc), "--side-params") from None
    _check_writable(outputs)
    depth = synthetic.depth_frames(scene, frames, seed)
    with atomic_set() as stage:                         # the recording and its truth, all or nothing
        write_recording(stage(out), depth, scene.K)
        synthetic.save_truth(stage(truth), scene, frames)
    report({"recording": str(out), "truth": str(truth), "frames": frames, "size": [synthetic.WIDTH, synthetic.HEIGHT],
            "distance_mm": round(scene.meta["distance_mm"], 1), "tilt_deg": tilt,
            "valid_pixels": round(float(np.mean(depth > 0)), 4), "megabytes": round(out.stat().st_size / 1e6, 2),
            "seconds": clock.seconds}, as_json, f"synthetic scan → {out}")


def _scan_makehuman(clock: Clock, as_json: bool, *, out, truth, frames, seed, pitch, distance, noise, side_params,
                    cup, firmness, weight, muscle, modifier, pose, yaw, resolution, wall, no_wall, scan_file, units,
                    up, closed) -> None:
    """`scan-synth --body makehuman`: check the options, then record, write the scan file and the truth."""
    if side_params:
        raise usage_error("--side-params applies to --body chen only", "--side-params")
    if out is None and scan_file is None:
        raise usage_error("--body makehuman needs --out (a recording), --scan-file (a scan file) or both", "--out")
    if scan_file is None and (units is not None or up is not None or closed):
        raise usage_error("--units, --up and --closed describe a --scan-file, and none is given", "--units/--up")
    if up is not None and up not in UP_AXES:
        raise usage_error(f"--up must be one of {' '.join(UP_AXES)}, not '{up}'", "--up")
    if wall is not None and no_wall:
        raise usage_error("give --wall MM or --no-wall, not both", "--wall/--no-wall")
    modifiers = parse_pairs(modifier, "MakeHuman modifier", "--modifier")

    from breastplan.options import OptionError
    from breastplan.scenes import realistic          # light: it imports open3d only to render
    from breastplan.scenes.makehuman import MODIFIERS, BodyOptions

    outputs = _outputs({"--out": out, "--truth": truth, "--scan-file": scan_file}, realistic.SCAN_SUFFIXES)
    if units is not None and units not in realistic.SCAN_UNITS:
        raise usage_error(f"--units must be {' or '.join(realistic.SCAN_UNITS)}, not '{units}'", "--units")
    unknown = sorted(set(modifiers) - set(MODIFIERS))
    if unknown:
        raise usage_error(f"unknown modifier '{unknown[0]}'; use one of {', '.join(MODIFIERS)}", "--modifier")
    body_values = {"cup": cup, "firmness": firmness, "weight": weight, "muscle": muscle, "pose": pose}
    try:
        body = BodyOptions(modifiers=modifiers, **{k: v for k, v in body_values.items() if v is not None})
    except OptionError as exc:
        raise usage_error(str(exc), FLAGS[exc.option]) from None

    camera_values = {"distance_mm": distance, "pitch_deg": pitch, "yaw_deg": yaw, "resolution": resolution,
                     "noise_mm": noise, "wall_mm": wall}
    try:
        camera = realistic.CameraOptions(**{k: v for k, v in camera_values.items() if v is not None},
                                         **({"wall_mm": None} if no_wall else {}))
    except OptionError as exc:
        raise usage_error(str(exc), FLAGS[exc.option]) from None

    _check_writable(outputs)

    import numpy as np

    from breastplan.atomic import atomic_set
    from breastplan.ingest.recording import write_recording

    scene = realistic.make_body_scene(body, camera)
    result = {"body": "makehuman"}
    with atomic_set() as stage:                         # recording, scan file and truth, all or nothing
        if out is not None:
            depth = scene.frames(frames, seed)
            staged = write_recording(stage(out), depth, camera.K, colour=scene.colour)
            result.update(recording=str(out), frames=frames, valid_pixels=round(float(np.mean(depth > 0)), 4),
                          megabytes=round(staged.stat().st_size / 1e6, 2))
        if scan_file is not None:
            counts = (realistic.write_closed_scan(scan_file, scene.body, units or "mm", up or "+y", stage) if closed
                      else realistic.write_scan_file(scan_file, scene, units or "mm", up or "+y", stage))
            result.update(scan_file=str(scan_file), scan_points=counts["points"], scan_faces=counts["faces"],
                          units=units or "mm", up=up or "+y", closed=closed)
        realistic.save_body_truth(stage(truth), scene, frames if out is not None else 0)
    volumes = scene.body.half_volumes_cc()
    result.update(truth=str(truth), size=list(camera.size), distance_mm=camera.distance_mm, pitch_deg=camera.pitch_deg,
                  yaw_deg=camera.yaw_deg, wall_mm=camera.wall_mm, pose=body.pose,
                  nipples_camera_mm={s: p.round(1) for s, p in scene.nipples_camera().items()},
                  half_volumes_cc={s: round(v, 1) for s, v in volumes.items()}, seconds=clock.seconds)
    report(result, as_json, f"realistic synthetic scan → {out or scan_file}")


def _outputs(given: dict[str, Optional[Path]], scan_suffixes: tuple[str, ...] = ()) -> dict[str, Path]:
    """The output files given, by option; a usage error if one's name ends wrongly or two name the same file."""
    outputs = {option: Path(path) for option, path in given.items() if path is not None}
    seen: dict[str, str] = {}
    for option, path in outputs.items():
        other = seen.setdefault(os.path.normcase(os.path.realpath(path)), option)
        if other != option:
            raise usage_error(f"{other} and {option} both name {path}; give each output its own file",
                              f"{other}/{option}")
    suffixes = dict(SUFFIXES, **{"--scan-file": scan_suffixes})
    for option, path in outputs.items():
        if path.suffix.lower() not in suffixes[option]:
            raise usage_error(f"{option} must end in {' or '.join(suffixes[option])}: '{path}' does not", option)
    return outputs


def _check_writable(outputs: dict[str, Path]) -> None:
    """BadInputError naming the first output that cannot be written (exit 3), before any work."""
    for option, path in outputs.items():
        writable(path, option=option)


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
