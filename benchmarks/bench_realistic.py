"""Breast isolation and fitting on realistic bodies (MakeHuman), with the Chen torso as the baseline.

Realistic scenes: 4 pairs of MakeHuman bodies (`scenes.makehuman.BodyOptions`), each pair differing
in one thing only — two in cup (0.3 vs 0.8, 0.2 vs 1.0), two in firmness (0 vs 1) — with weights
0.2–0.9, muscle 0.3–0.7 and modifiers (asymmetry ±, breast_trans, torso_width). Each pair is seen
from 3 of the 8 views of VIEWS (pose a-pose / arms-down / hands-on-hips; camera 500–900 mm, pitch
−15..15°, yaw −10..10°, 640×400 / 800×600 / 1280×800, wall at 400 mm or none): 8 bodies × 3 views =
24 scenes, 8 noisy depth frames each (`scenes.realistic.make_body_scene(...).frames(8, view)`; both
bodies of a pair share the view and its noise seed). Each scene goes through `ingest_frames` for the
left and the right side (automatic isolation, no nipple given); a side that returns is fitted with
`fit_scan(ingested)` (`fit_breast` on the chest wall ingest found: volumes down to that wall).
Baseline scenes, in the same run and interleaved with the realistic ones (so that both see the
same load): 6 Chen torsos (`scenes.synthetic.make_scene`), seeds 0, 1, 2 as drawn and with all five semi-axes × CHEN_SCALE (a known volume change), 8 frames
(640×400), through the same calls.

Figures (a side is *isolated* when ingest returns and its nipple lies within ISOLATED_MM of the truth;
a BadInputError counts as not isolated; a fit is made whenever ingest returns, and used for the
volume and ptosis figures only when its side is isolated):

1. both breasts isolated: share of scenes with both sides isolated (target 100 %);
2. nipple error, 3-D, over the isolated sides: median (≤ 3 mm) and worst (≤ 8 mm). Truth: the
   centroid of MakeHuman's nipple ring (`scene.nipples_camera()`); Chen: the tip of the nipple bump;
3. nipple asymmetry: per scene with both sides isolated, (left − right) nipple offsets in the body
   frame (found nipples taken there by the inverse of `scene.camera_from_body`), horizontal (X) and
   vertical (Y), minus the true offsets: worst |error| ≤ 4 mm;
3b. (no target) the breast's boundary, per isolated realistic side (`scenes.realistic.crop_against_truth`):
   the share of the crop's points whose nearest body vertex is one of MakeHuman's breast (`breast_region`:
   the vertices its breast targets move), worst; and the share of the body pixels the camera sees within
   CORE_MM of the true nipple that the crop holds, median and worst;
3c. (no target) the plan's landmarks (`plan.measures.find_landmarks` on the torso ingest found and the
   nipples found), per scene with both sides isolated, against the body's frame: the up axis's and the
   mid-sagittal plane normal's angles from the body's Y and X axes, and the nipple-to-midline measure
   minus the true one (|X| of the true nipple), median and worst; baseline: the same on the Chen torsos;
   and the found sternal notch against MakeHuman's (`Body.sternal_notch`), with the two measures taken
   from it, notch-to-nipple and the nipple's drop below the notch, minus the true ones (no baseline:
   the Chen torso has no neck);
4. cup change: per cup pair × view × side, fitted volume change vs the true change (difference of
   `body.half_volumes_cc()` of that side); worst relative error ≤ 10 %. Baseline: the same on the
   Chen pairs (truth: `synthetic.Breast.volume_on_chest_cc`, the primitive and its base extruded to the
   curved chest);
5. firmness pairs (same cup, firmness 0 vs 1), per view × side: (a) the fitted ptosis parameters
   (b0, b1; docs/model.md §3, `BreastFit.superquadric.deformation.params("ptosis")`), taken together as
   the sag they give the fitted primitive's apex (`BreastFit.ptosis_sag_mm`), are larger for firmness 0 by over
   SAG_TIE_MM (target: every case; closer sags are a tie and count as not ordered; b0 alone is reported
   too: it ties at its plausible bound, 3, in about half the cases); baseline: on the Chen torsos, the
   share of scenes whose fitted left/right sag order matches the true order, where the true sags differ
   by ≥ CHEN_SAG_GAP_MM; (b) the fitted volumes differ by ≤ 5 % of their mean
   (baseline: the true difference, in % of the same mean); reported beside it, with no target: the
   fitted volume change against the true one, |fitted − true| in % of the same mean;
5c. (no target) repeatability: per body and side fitted from several views, the spread of its fitted
   volumes, (max − min) / mean, median and worst;
6. fit seconds per breast (the whole `fit_scan` call, one call per breast): median over the realistic
   breasts ≤ 1 s; baseline: the median over the Chen breasts;
7. ingest time of 8 frames at 800×600 (`ingest_frames`, frames already in memory): median ≤ 1 s, over
   the 800×600 scenes (up to TIMING_CASES scene × side cases), each a median of `repeats` calls after
   one warm-up, alternating with the baseline: the Chen scene's ingest (640×400, 8 frames, same side).
   A call that raises BadInputError is timed as it is (until it raises) and counted.

Every fit runs under `threadpool_limits(1, "blas")`, as `breastplan fit` runs it. Nothing is asserted:
the script prints tables, then one line of JSON per figure ({"figure", "value", "target", "baseline",
"unit", "met", ...}) and a last line with everything.

Run:  .venv/bin/python benchmarks/bench_realistic.py [--repeats N] [--quick]
      (default 5 repeats for 7., 24 scenes + 6 Chen scenes, about 3–4 minutes on 2 cores; --quick:
      2 repeats, one cup pair and one firmness pair seen from 2 views (8 scenes) + 2 Chen scenes)
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from dataclasses import dataclass, field, replace

import numpy as np
from rich.console import Console
from rich.markup import escape
from rich.table import Table
from threadpoolctl import threadpool_limits

from breastplan import BadInputError, transform_points
from breastplan.fitting.breast_fit import fit_scan, ptosis_sag_mm
from breastplan.scenes import synthetic
from breastplan.scenes.makehuman import BodyOptions
from breastplan.ingest.pipeline import ingest_frames
from breastplan.scenes.realistic import CORE_MM, BodyScene, CameraOptions, crop_against_truth, make_body_scene
from breastplan.ingest.recording import DepthFrames
from breastplan.options import SIDES, IngestOptions
from breastplan.plan.measures import find_landmarks

from timing import fmt, median_times, rounded

FRAMES = 8
ISOLATED_MM = 30.0
CHEN_SEEDS, CHEN_TILTS_DEG = (0, 1, 2), (0.0, 10.0, 5.0)
CHEN_SCALE = 1.12
"""The Chen pairs' second member: all five semi-axes × 1.12 (volume × 1.40)."""
CHEN_SAG_GAP_MM = 1.0
"""Chen scenes whose true left/right ptosis sags differ by less than this are left out of 5a's baseline."""
SAG_TIE_MM, B0_TIE = 0.1, 0.01
"""Fitted sags (b0 values) of a firmness pair closer than this are a tie (b0: most often both at the bound 3)."""
TIMING_RESOLUTION, TIMING_CASES = "800x600", 4
TARGETS = {"both_isolated_pct": 100.0, "nipple_median_mm": 3.0, "nipple_worst_mm": 8.0, "asymmetry_worst_mm": 4.0,
           "cup_change_worst_pct": 10.0, "firmness_order_pct": 100.0, "firmness_volume_pct": 5.0,
           "fit_s": 1.0, "ingest_800x600_s": 1.0}

# --- scenes -----------------------------------------------------------------------------------
VIEWS = (
    ("a-pose", CameraOptions(650.0, 0.0, 0.0, "800x600", wall_mm=400.0)),
    ("arms-down", CameraOptions(800.0, 10.0, -5.0, "640x400", wall_mm=None)),
    ("hands-on-hips", CameraOptions(550.0, -10.0, 8.0, "1280x800", wall_mm=400.0)),
    ("a-pose", CameraOptions(900.0, 15.0, 10.0, "800x600", wall_mm=None)),
    ("arms-down", CameraOptions(500.0, -15.0, -10.0, "1280x800", wall_mm=400.0)),
    ("hands-on-hips", CameraOptions(700.0, 5.0, -8.0, "640x400", wall_mm=400.0)),
    ("a-pose", CameraOptions(750.0, -5.0, 5.0, "1280x800", wall_mm=None)),
    ("hands-on-hips", CameraOptions(600.0, 12.0, 0.0, "800x600", wall_mm=None)),
)
"""(pose, camera) of each view; noise 1 mm (the CameraOptions default)."""


@dataclass(frozen=True)
class Pair:
    """Two bodies differing only in `varies` (cup or firmness): values (lo, hi)."""

    name: str
    varies: str
    values: tuple[float, float]
    base: BodyOptions
    views: tuple[int, ...]
    quick_views: tuple[int, ...] = ()

    def body(self, member: int, pose: str) -> BodyOptions:
        return replace(self.base, **{self.varies: self.values[member], "pose": pose})


PAIRS = (
    Pair("cup-1", "cup", (0.3, 0.8), BodyOptions(firmness=0.5, weight=0.5, muscle=0.5), (0, 1, 2), (0, 2)),
    Pair("cup-2", "cup", (0.2, 1.0), BodyOptions(firmness=0.7, weight=0.8, muscle=0.4, modifiers={"asymmetry": 0.8}),
         (2, 3, 4)),
    Pair("firm-1", "firmness", (0.0, 1.0), BodyOptions(cup=0.7, weight=0.2, muscle=0.7,
                                                       modifiers={"breast_trans": -0.5}), (4, 5, 6), (0, 2)),
    Pair("firm-2", "firmness", (0.0, 1.0), BodyOptions(cup=0.9, weight=0.9, muscle=0.3,
                                                       modifiers={"asymmetry": -0.6, "torso_width": 0.5}), (6, 7, 0)),
)
MEMBERS = ("lo", "hi")


@dataclass
class Side:
    """One side of one scene: what ingest and fit gave, and the errors against the truth."""

    status: str = "raised"             # "isolated", "far" (nipple > ISOLATED_MM off), "raised"
    error: str | None = None
    ingest_s: float = 0.0
    nipple_mm: float | None = None
    nipple_camera: np.ndarray | None = None
    points: int = 0
    on_breast: float | None = None     # share of its points on MakeHuman's breast (realistic only)
    core_held: float | None = None     # share of the seen skin within CORE_MM of the true nipple it holds
    fit_status: str | None = None      # None (no fit), "fitted", "rejected"
    fit_error: str | None = None
    fit_s: float | None = None
    volume_cc: float | None = None
    b0: float | None = None
    b1: float | None = None
    sag_mm: float | None = None        # how far the fitted ptosis lowers the primitive's apex (BreastFit.ptosis_sag_mm)
    residual: float | None = None      # FFD mean normalised residual
    iterations: tuple | None = None    # (superquadric nfev, FFD iterations)
    stage_s: tuple | None = None       # (superquadric, FFD) seconds as the fit reports them
    converged: bool | None = None      # FFD met the stopping rule or stopped improving (not cut at max_iterations)

    @property
    def isolated(self) -> bool:
        return self.status == "isolated"

    def as_dict(self) -> dict:
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in self.__dict__.items()}


@dataclass
class SceneResult:
    kind: str                          # "realistic" or "chen"
    label: str
    meta: dict
    sides: dict = field(default_factory=dict)
    asymmetry_mm: dict | None = None   # {"horizontal": err, "vertical": err} when both sides are isolated
    truth: dict = field(default_factory=dict)
    landmarks: dict | None = None      # `landmark_errors` when both sides are isolated
    wall_s: float = 0.0

    @property
    def both_isolated(self) -> bool:
        return all(self.sides[s].isolated for s in SIDES)

    def as_dict(self) -> dict:
        return {"kind": self.kind, "label": self.label, "meta": self.meta, "truth": self.truth,
                "sides": {s: v.as_dict() for s, v in self.sides.items()}, "asymmetry_mm": self.asymmetry_mm,
                "landmarks": self.landmarks,
                "both_isolated": self.both_isolated, "wall_s": self.wall_s}


def realistic_specs(quick: bool) -> list[dict]:
    """One spec per realistic scene: pair, member, view."""
    specs = []
    for pair in PAIRS:
        views = pair.quick_views if quick else pair.views
        for view in views:
            for member in (0, 1):
                specs.append({"pair": pair, "member": member, "view": view})
    return specs


def chen_specs(quick: bool) -> list[dict]:
    seeds = CHEN_SEEDS[:1] if quick else CHEN_SEEDS
    return [{"seed": s, "tilt_deg": CHEN_TILTS_DEG[k], "scaled": scaled}
            for k, s in enumerate(seeds) for scaled in (False, True)]


def chen_scene(spec: dict) -> synthetic.Scene:
    scene = synthetic.make_scene(spec["seed"], tilt_deg=spec["tilt_deg"])
    if not spec["scaled"]:
        return scene
    overrides = {side: {a: CHEN_SCALE * getattr(scene.breasts[side].primitive, a) for a in ("a1", "a2", "a3", "a4", "a5")}
                 for side in SIDES}
    return synthetic.make_scene(spec["seed"], tilt_deg=spec["tilt_deg"], overrides=overrides)


def chen_nipples_body(scene: synthetic.Scene) -> dict[str, np.ndarray]:
    return {s: transform_points(synthetic.body_from_breast(s), scene.breasts[s].nipple_mm[None])[0] for s in SIDES}


# --- one scene through ingest and fit ---------------------------------------------------------
def run_side(frames: DepthFrames, side: str, truth_camera: np.ndarray, scene: BodyScene | None = None):
    """One side through ingest and fit; with a realistic `scene`, its crop against the body's breast.
    (Side, what ingest returned or None)."""
    out, ingested = Side(), None
    t0 = time.perf_counter()
    try:
        ingested = ingest_frames(frames, IngestOptions(side=side))
    except BadInputError as exc:
        out.ingest_s, out.error = time.perf_counter() - t0, str(exc)
        return out, ingested
    out.ingest_s = time.perf_counter() - t0
    out.nipple_camera = np.asarray(ingested.nipple_camera, float)
    out.nipple_mm = float(np.linalg.norm(out.nipple_camera - truth_camera))
    out.status = "isolated" if out.nipple_mm <= ISOLATED_MM else "far"
    out.points = int(len(ingested.points))
    if scene is not None:
        crop = transform_points(np.linalg.inv(ingested.input_to_breast), ingested.points)
        shares = crop_against_truth(scene, side, crop)
        out.on_breast, out.core_held = shares["on_breast"], shares["core_held"]
    t0 = time.perf_counter()
    try:
        fit = fit_scan(ingested)
    except BadInputError as exc:
        out.fit_s, out.fit_status, out.fit_error = time.perf_counter() - t0, "rejected", str(exc)
        return out, ingested
    out.fit_s, out.fit_status = time.perf_counter() - t0, "fitted"
    out.volume_cc, out.residual = float(fit.volume_cc), float(fit.ffd.residual)
    out.b0, out.b1 = (float(v) for v in fit.superquadric.deformation.params("ptosis"))
    out.sag_mm = fit.ptosis_sag_mm
    out.iterations = (int(fit.superquadric.iterations), int(fit.ffd.iterations))
    out.stage_s = (float(fit.superquadric.seconds), float(fit.ffd.seconds))
    out.converged = bool(fit.ffd.converged)
    return out, ingested


def asymmetry(sides: dict[str, Side], body_from_camera: np.ndarray, truth_body: dict) -> dict | None:
    """(left − right) found nipple offset minus the true one, body frame: X horizontal, Y vertical (mm)."""
    if not all(sides[s].isolated for s in SIDES):
        return None
    found = {s: transform_points(body_from_camera, sides[s].nipple_camera[None])[0] for s in SIDES}
    d = (found["left"] - found["right"]) - (truth_body["left"] - truth_body["right"])
    return {"horizontal": float(d[0]), "vertical": float(d[1])}


def landmark_errors(runs: dict, camera_from_body: np.ndarray, truth_body: dict, notch_body=None) -> dict | None:
    """The plan's landmarks (`plan.measures.find_landmarks` on the torso ingest found, with both
    nipples found) against the body's frame (X its left, Y up): the up axis's and the mid-sagittal
    plane's normal's angles from Y and X (degrees), and each nipple's distance from the plane minus
    the true one (|X| of the true nipple, mm). With the true sternal notch (`notch_body`, body frame):
    the found notch's distance from it, and per side the notch-to-nipple chord and the nipple's drop
    below the notch (along the found up axis) minus the true ones (true notch and nipple, along Y),
    mm. None unless both sides are isolated."""
    if not all(side.isolated for side, _ in runs.values()):
        return None
    ingested = runs["left"][1]
    nipples = {s: side.nipple_camera for s, (side, _) in runs.items()}
    try:
        found = find_landmarks(ingested.torso_camera, nipples, ingested.input_to_view, ingested.plumb_camera)
    except BadInputError as exc:
        return {"error": str(exc)}
    angle = lambda a, b: float(np.degrees(np.arccos(np.clip(a @ b, -1.0, 1.0))))  # noqa: E731
    R = camera_from_body[:3, :3]
    midline = {s: abs((nipples[s] - found.midline_point) @ found.left_axis) - abs(truth_body[s][0]) for s in SIDES}
    out = {"up_deg": angle(found.up_axis, R[:, 1]), "up_from": found.up_from,
           "normal_deg": angle(found.left_axis, R[:, 0]), "nipple_to_midline_mm": midline}
    if notch_body is not None:
        notch = transform_points(camera_from_body, np.asarray(notch_body, float)[None])[0]
        out["notch_mm"] = float(np.linalg.norm(found.sternal_notch - notch))
        out["notch_to_nipple_mm"] = {s: float(np.linalg.norm(nipples[s] - found.sternal_notch)
                                              - np.linalg.norm(truth_body[s] - notch_body)) for s in SIDES}
        out["nipple_below_notch_mm"] = {s: float((found.sternal_notch - nipples[s]) @ found.up_axis
                                                 - (notch_body[1] - truth_body[s][1])) for s in SIDES}
    return out


def run_realistic(spec: dict) -> tuple[SceneResult, DepthFrames]:
    start = time.perf_counter()
    pair, member, view = spec["pair"], spec["member"], spec["view"]
    pose, camera = VIEWS[view]
    scene = make_body_scene(pair.body(member, pose), camera)
    frames = DepthFrames(scene.frames(FRAMES, view), scene.camera.K, "synthetic")
    truth_camera = scene.nipples_camera()
    runs = {s: run_side(frames, s, truth_camera[s], scene) for s in SIDES}
    sides = {s: run[0] for s, run in runs.items()}
    volumes = scene.body.half_volumes_cc()
    result = SceneResult("realistic", f"{pair.name}/{MEMBERS[member]} v{view}",
                         {"pair": pair.name, "varies": pair.varies, "member": MEMBERS[member],
                          "value": pair.values[member], "view": view, "pose": pose, "resolution": camera.resolution,
                          "distance_mm": camera.distance_mm, "pitch_deg": camera.pitch_deg, "yaw_deg": camera.yaw_deg,
                          "wall_mm": camera.wall_mm, "body": {**pair.body(member, pose).__dict__}},
                         sides, asymmetry(sides, np.linalg.inv(scene.camera_from_body), scene.body.nipples),
                         {"half_volume_cc": volumes})
    result.landmarks = landmark_errors(runs, scene.camera_from_body, scene.body.nipples,
                                   scene.body.sternal_notch)
    result.wall_s = time.perf_counter() - start
    return result, frames


def run_chen(spec: dict) -> tuple[SceneResult, DepthFrames]:
    start = time.perf_counter()
    scene = chen_scene(spec)
    frames = DepthFrames(synthetic.depth_frames(scene, FRAMES, spec["seed"]), scene.K, "synthetic")
    truth_body = chen_nipples_body(scene)
    truth_camera = {s: transform_points(scene.camera_from_body, truth_body[s][None])[0] for s in SIDES}
    runs = {s: run_side(frames, s, truth_camera[s]) for s in SIDES}
    sides = {s: run[0] for s, run in runs.items()}
    truth = {"volume_cc": {s: scene.breasts[s].volume_on_chest_cc(s) for s in SIDES},
             "b0": {s: float(scene.breasts[s].deformation.params("ptosis")[0]) for s in SIDES},
             "sag_mm": {s: ptosis_sag_mm(scene.breasts[s].primitive, scene.breasts[s].deformation.params("ptosis"))
                        for s in SIDES}}
    result = SceneResult("chen", f"chen s{spec['seed']}{' ×' + format(CHEN_SCALE, 'g') if spec['scaled'] else ''}",
                         {**spec, "distance_mm": float(scene.meta["distance_mm"]), "resolution": "640x400"},
                         sides, asymmetry(sides, np.linalg.inv(scene.camera_from_body), truth_body), truth)
    result.landmarks = landmark_errors(runs, scene.camera_from_body, truth_body)
    result.wall_s = time.perf_counter() - start
    return result, frames


def run_all(quick: bool, console: Console) -> tuple[list[SceneResult], list[SceneResult], list, DepthFrames]:
    """Realistic scenes with the Chen scenes interleaved (one every len(real)/len(chen) scenes).
    Returns both lists of results, the 800×600 cases kept for the ingest timing (7.) and the frames
    of the first Chen scene (its baseline)."""
    real_specs, chen_list = realistic_specs(quick), chen_specs(quick)
    every = max(1, len(real_specs) // len(chen_list))
    real, chen, timing_frames, chen_frames = [], [], [], None
    ci = 0
    for k, spec in enumerate(real_specs):
        if k % every == 0 and ci < len(chen_list):
            r, frames = run_chen(chen_list[ci])
            chen.append(r)
            if ci == 0:
                chen_frames = frames
            ci += 1
            console.log(f"{r.label}: {r.wall_s:.1f} s")
        r, frames = run_realistic(spec)
        real.append(r)
        if r.meta["resolution"] == TIMING_RESOLUTION and len(timing_frames) < TIMING_CASES:
            timing_frames.append((r.label, SIDES[len(timing_frames) % 2], frames))
        console.log(f"{r.label}: {r.wall_s:.1f} s")
    for spec in chen_list[ci:]:
        r, _ = run_chen(spec)
        chen.append(r)
        console.log(f"{r.label}: {r.wall_s:.1f} s")
    return real, chen, timing_frames, chen_frames


# --- figures ----------------------------------------------------------------------------------
def median_or_none(values):
    values = list(values)
    return statistics.median(values) if values else None


def max_or_none(values):
    values = list(values)
    return max(values) if values else None


def notch_figures(marks: list[dict]) -> dict:
    """Median and worst |error| of the found notch and of the two measures taken from it (mm)."""
    errors = {"notch": [m["notch_mm"] for m in marks],
              **{key: [abs(m[f"{key}_mm"][side]) for m in marks for side in SIDES]
                 for key in ("notch_to_nipple", "nipple_below_notch")}}
    return {f"{key}_{name}_mm": stat(values) for key, values in errors.items()
            for name, stat in (("median", median_or_none), ("worst", max_or_none))}


def isolation_figures(scenes: list[SceneResult]) -> dict:
    nipples = [s.sides[side].nipple_mm for s in scenes for side in SIDES if s.sides[side].isolated]
    asym = [max(abs(s.asymmetry_mm["horizontal"]), abs(s.asymmetry_mm["vertical"])) for s in scenes if s.asymmetry_mm]
    crops = [s.sides[side] for s in scenes for side in SIDES
             if s.sides[side].isolated and s.sides[side].on_breast is not None]
    marks = [s.landmarks for s in scenes if s.landmarks and "error" not in s.landmarks]
    midline = [abs(m["nipple_to_midline_mm"][side]) for m in marks for side in SIDES]
    return {"landmark_scenes": len(marks), "landmark_errors": sum(bool(s.landmarks and "error" in s.landmarks)
                                                                 for s in scenes),
            "up_worst_deg": max_or_none(m["up_deg"] for m in marks),
            "up_median_deg": median_or_none(m["up_deg"] for m in marks),
            **{f"up_{key}_worst_deg": max_or_none(m["up_deg"] for m in marks if m["up_from"] == source)
               for key, source in (("wall", "wall"), ("profile", "midline profile"))},
            "up_from_wall": sum(m["up_from"] == "wall" for m in marks),
            "normal_worst_deg": max_or_none(m["normal_deg"] for m in marks),
            "midline_median_mm": median_or_none(midline), "midline_worst_mm": max_or_none(midline),
            **notch_figures([m for m in marks if "notch_mm" in m]),
            "on_breast_worst_pct": min((100 * c.on_breast for c in crops), default=None),
            "core_held_worst_pct": min((100 * c.core_held for c in crops), default=None),
            "core_held_median_pct": median_or_none(100 * c.core_held for c in crops), "crops": len(crops),
            "scenes": len(scenes), "both_isolated": sum(s.both_isolated for s in scenes),
            "both_isolated_pct": 100.0 * sum(s.both_isolated for s in scenes) / len(scenes),
            "sides_isolated": len(nipples), "sides": 2 * len(scenes),
            "sides_raised": sum(s.sides[side].status == "raised" for s in scenes for side in SIDES),
            "sides_far": sum(s.sides[side].status == "far" for s in scenes for side in SIDES),
            "nipple_median_mm": median_or_none(nipples), "nipple_worst_mm": max_or_none(nipples),
            "asymmetry_scenes": len(asym), "asymmetry_worst_mm": max_or_none(asym)}


def usable(side: Side) -> bool:
    return side.isolated and side.fit_status == "fitted"


def order(soft: float, firm: float, tie: float) -> str:
    """'right' when the softer breast's value is larger by over `tie`, 'tie' within it, else 'wrong'."""
    return "right" if soft > firm + tie else "tie" if abs(soft - firm) <= tie else "wrong"


def realistic_pairs(scenes: list[SceneResult], varies: str) -> list[dict]:
    """One case per pair × view × side of the pairs varying `varies` (both members present)."""
    index = {(s.meta["pair"], s.meta["view"], s.meta["member"]): s for s in scenes}
    cases = []
    for pair in PAIRS:
        if pair.varies != varies:
            continue
        for view in sorted({s.meta["view"] for s in scenes if s.meta["pair"] == pair.name}):
            lo, hi = index.get((pair.name, view, "lo")), index.get((pair.name, view, "hi"))
            if lo is None or hi is None:
                continue
            for side in SIDES:
                a, b = lo.sides[side], hi.sides[side]
                case = {"pair": pair.name, "view": view, "side": side, "values": list(pair.values),
                        "true_change_cc": hi.truth["half_volume_cc"][side] - lo.truth["half_volume_cc"][side],
                        "fitted": usable(a) and usable(b), "volume_cc": [a.volume_cc, b.volume_cc],
                        "b0": [a.b0, b.b0], "b1": [a.b1, b.b1], "sag_mm": [a.sag_mm, b.sag_mm]}
                if case["fitted"]:
                    case["fitted_change_cc"] = b.volume_cc - a.volume_cc
                    mean = 0.5 * (a.volume_cc + b.volume_cc)
                    if varies == "cup":
                        case["relative_error_pct"] = 100.0 * (case["fitted_change_cc"] / case["true_change_cc"] - 1.0)
                    else:
                        case["order"] = order(a.sag_mm, b.sag_mm, SAG_TIE_MM)    # firmness 0 sags more
                        case["order_ok"] = case["order"] == "right"
                        case["b0_order"] = order(a.b0, b.b0, B0_TIE)
                        case["volume_difference_pct"] = 100.0 * abs(case["fitted_change_cc"]) / mean
                        case["true_difference_pct"] = 100.0 * abs(case["true_change_cc"]) / mean
                        case["change_error_pct"] = 100.0 * abs(case["fitted_change_cc"] - case["true_change_cc"]) / mean
                cases.append(case)
    return cases


def view_spreads(scenes: list[SceneResult]) -> list[dict]:
    """Per body (pair × member) and side fitted from at least two views: the spread of the fitted
    volumes over the views, (max − min) / mean in %."""
    groups: dict = {}
    for s in scenes:
        for side in SIDES:
            if usable(s.sides[side]):
                groups.setdefault((s.meta["pair"], s.meta["member"], side), []).append(s.sides[side].volume_cc)
    return [{"pair": pair, "member": member, "side": side, "volume_cc": v,
             "spread_pct": 100.0 * (max(v) - min(v)) / statistics.mean(v)}
            for (pair, member, side), v in sorted(groups.items()) if len(v) >= 2]


def chen_pairs(chen: list[SceneResult]) -> list[dict]:
    """Cup-change baseline: each Chen seed as drawn vs scaled, per side."""
    index = {(s.meta["seed"], s.meta["scaled"]): s for s in chen}
    cases = []
    for seed in sorted({s.meta["seed"] for s in chen}):
        lo, hi = index.get((seed, False)), index.get((seed, True))
        if lo is None or hi is None:
            continue
        for side in SIDES:
            a, b = lo.sides[side], hi.sides[side]
            case = {"seed": seed, "side": side, "true_change_cc": hi.truth["volume_cc"][side] - lo.truth["volume_cc"][side],
                    "fitted": usable(a) and usable(b), "volume_cc": [a.volume_cc, b.volume_cc]}
            if case["fitted"]:
                case["fitted_change_cc"] = b.volume_cc - a.volume_cc
                case["relative_error_pct"] = 100.0 * (case["fitted_change_cc"] / case["true_change_cc"] - 1.0)
            cases.append(case)
    return cases


def chen_ptosis_order(chen: list[SceneResult]) -> dict:
    """Baseline of 5a: Chen scenes whose fitted left/right ptosis sag order matches the true order."""
    cases = []
    for s in chen:
        t = s.truth["sag_mm"]
        if abs(t["left"] - t["right"]) < CHEN_SAG_GAP_MM or not all(usable(s.sides[x]) for x in SIDES):
            continue
        fitted = {x: s.sides[x].sag_mm for x in SIDES}
        cases.append({"scene": s.label, "true_sag_mm": t, "fitted_sag_mm": fitted,
                      "order_ok": bool((t["left"] > t["right"]) == (fitted["left"] > fitted["right"]))})
    return {"cases": cases, "order_ok_pct": 100.0 * sum(c["order_ok"] for c in cases) / len(cases) if cases else None}


def ingest_timing(timing_frames: list, chen_frames: DepthFrames, repeats: int) -> list[dict]:
    """7. Each 800×600 case alternating with the Chen scene's ingest of the same side."""
    rows = []
    for label, side, frames in timing_frames:
        raised = {"realistic": 0, "chen": 0}

        def call(which, frames, side=side, raised=raised):
            def run():
                try:
                    ingest_frames(frames, IngestOptions(side=side))
                except BadInputError:
                    raised[which] += 1
            return run
        median, baseline = median_times(call("realistic", frames), call("chen", chen_frames), repeats)
        rows.append({"scene": label, "side": side, "size": list(frames.size), "frames": int(frames.depth.shape[0]),
                     "repeats": repeats, "median_s": median, "baseline_s": baseline, "ratio": median / baseline,
                     "raised": raised["realistic"], "baseline_raised": raised["chen"], "calls": repeats + 1})
    return rows


def fit_times(scenes: list[SceneResult]) -> list[float]:
    return [s.sides[x].fit_s for s in scenes for x in SIDES if s.sides[x].fit_status is not None]


# --- tables -----------------------------------------------------------------------------------
def new_table(title: str, columns: tuple[str, ...], caption: str | None = None) -> Table:
    table = Table(title=title, caption=caption and escape(caption), caption_justify="left")
    for i, col in enumerate(columns):
        table.add_column(col, justify="left" if i == 0 else "right")
    return table


def side_cell(side: Side) -> str:
    if side.status == "raised":
        return "raised"
    text = f"{side.nipple_mm:.1f} mm" + ("" if side.isolated else " (far)")
    return text


def fit_cell(side: Side) -> str:
    if side.fit_status is None:
        return "–"
    if side.fit_status == "rejected":
        return f"rejected {side.fit_s:.2f} s"
    cut = "" if side.converged else " cut"
    return f"{side.volume_cc:.0f} cc b0 {side.b0:+.2f} {side.fit_s:.2f} s {side.iterations[1]} it{cut}"


def print_scenes(real: list[SceneResult], chen: list[SceneResult], console: Console) -> None:
    caption = (f"Nipple: 3-D distance of the found nipple from the truth (camera mm); 'raised' = ingest raised "
               f"BadInputError, '(far)' = farther than {ISOLATED_MM:g} mm (not isolated). Asymmetry: (left − right) "
               f"found offset minus the true offset in the body frame, X horizontal / Y vertical. Fit: fitted volume, "
               f"ptosis b0, seconds of fit_scan (made whenever ingest returned) and FFD iterations ('cut': stopped at max_iterations). Chen rows are the baseline scenes "
               f"(640×400), run interleaved with the realistic ones.")
    table = new_table(f"bench_realistic — scenes ({FRAMES} frames each)",
                      ("scene", "pose", "camera", "ingest L / R", "nipple L", "nipple R", "asymmetry X / Y",
                       "fit L", "fit R", "wall"), caption=caption)
    for s in [*real, *chen]:
        m = s.meta
        if s.kind == "realistic":
            wall = "wall" if m["wall_mm"] is not None else "no wall"
            camera = f"{m['distance_mm']:.0f} mm {m['pitch_deg']:+.0f}°/{m['yaw_deg']:+.0f}° {m['resolution']} {wall}"
            pose = m["pose"]
        else:
            camera, pose = f"{m['distance_mm']:.0f} mm tilt {m['tilt_deg']:g}° 640x400", "Chen torso"
        asym = (f"{s.asymmetry_mm['horizontal']:+.1f} / {s.asymmetry_mm['vertical']:+.1f} mm" if s.asymmetry_mm else "–")
        table.add_row(s.label, pose, camera, f"{s.sides['left'].ingest_s:.2f} / {s.sides['right'].ingest_s:.2f} s",
                      side_cell(s.sides["left"]), side_cell(s.sides["right"]), asym, fit_cell(s.sides["left"]),
                      fit_cell(s.sides["right"]), f"{s.wall_s:.1f} s")
        if s is real[-1]:
            table.add_section()
    console.print(table)
    errors = {}
    for s in [*real, *chen]:
        for x in SIDES:
            for msg in (s.sides[x].error, s.sides[x].fit_error):
                if msg:
                    errors.setdefault(msg, []).append(f"{s.label} {x}")
    if errors:
        table = new_table("bench_realistic — errors raised (BadInputError)", ("message", "count", "where"))
        for msg, where in sorted(errors.items(), key=lambda kv: -len(kv[1])):
            table.add_row(escape(msg), str(len(where)), escape(", ".join(where[:4]) + (" …" if len(where) > 4 else "")))
        console.print(table)


def print_pairs(cup: list[dict], firm: list[dict], chen_cup: list[dict], console: Console) -> None:
    table = new_table("bench_realistic 4 — cup change: fitted volume change vs the true change",
                      ("pair", "view", "side", "volume lo → hi", "fitted change", "true change", "relative error"),
                      caption=f"True change: difference of the half-body volumes (body.half_volumes_cc) of that side; "
                              f"Chen: semi-axes × {CHEN_SCALE:g}, truth the primitive's volume down to the curved "
                              f"chest. '–': a side not isolated or its fit rejected in either member.")
    for c in cup:
        vol = f"{c['volume_cc'][0]:.0f} → {c['volume_cc'][1]:.0f} cc" if c["fitted"] else "–"
        table.add_row(f"{c['pair']} ({c['values'][0]:g} → {c['values'][1]:g})", str(c["view"]), c["side"], vol,
                      f"{c['fitted_change_cc']:+.0f} cc" if c["fitted"] else "–", f"{c['true_change_cc']:+.0f} cc",
                      f"{c['relative_error_pct']:+.1f} %" if c["fitted"] else "–")
    table.add_section()
    for c in chen_cup:
        vol = f"{c['volume_cc'][0]:.0f} → {c['volume_cc'][1]:.0f} cc" if c["fitted"] else "–"
        table.add_row(f"chen s{c['seed']} (×{CHEN_SCALE:g})", "", c["side"], vol,
                      f"{c['fitted_change_cc']:+.0f} cc" if c["fitted"] else "–", f"{c['true_change_cc']:+.0f} cc",
                      f"{c['relative_error_pct']:+.1f} %" if c["fitted"] else "–")
    console.print(table)
    table = new_table("bench_realistic 5 — firmness pairs (firmness 0 → 1): fitted ptosis and volumes",
                      ("pair", "view", "side", "b0 (0 → 1)", "b1 (0 → 1)", "sag (0 → 1)", "sag order", "b0 order",
                       "volume (0 → 1)", "fitted |Δ|", "true |Δ|"),
                      caption=f"sag: how far the fitted ptosis lowers the primitive's apex (mm); order: 'right' when "
                              f"firmness 0 has the larger sag by over {SAG_TIE_MM} mm (b0: by over {B0_TIE}), 'tie' "
                              "within it. |Δ|: volume difference in % "
                              "of the mean fitted volume; true: the half-body volume difference in % of the same mean.")
    for c in firm:
        if not c["fitted"]:
            table.add_row(c["pair"], str(c["view"]), c["side"], "–", "–", "–", "–", "–", "–", "–",
                          f"{abs(c['true_change_cc']):.0f} cc")
            continue
        table.add_row(c["pair"], str(c["view"]), c["side"], f"{c['b0'][0]:+.2f} → {c['b0'][1]:+.2f}",
                      f"{c['b1'][0]:+.2f} → {c['b1'][1]:+.2f}", f"{c['sag_mm'][0]:.1f} → {c['sag_mm'][1]:.1f}",
                      c["order"], c["b0_order"],
                      f"{c['volume_cc'][0]:.0f} → {c['volume_cc'][1]:.0f} cc", f"{c['volume_difference_pct']:.1f} %",
                      f"{c['true_difference_pct']:.1f} %")
    console.print(table)


def print_timing(rows: list[dict], console: Console) -> None:
    table = new_table(f"bench_realistic 7 — ingest of {FRAMES} frames (medians after one warm-up; alternating with "
                      f"the baseline)", ("scene", "side", "size", "median", "Chen 640×400 (baseline)", "ratio",
                                         "calls raising"),
                      caption="A call raising BadInputError is timed until it raises; 'calls raising' counts them "
                              "(realistic / Chen) among all calls, warm-up included.")
    for r in rows:
        table.add_row(r["scene"], r["side"], f"{r['size'][0]}×{r['size'][1]}", fmt(r["median_s"]), fmt(r["baseline_s"]),
                      f"{r['ratio']:.1f}", f"{r['raised']} / {r['baseline_raised']} of {r['calls']}")
    console.print(table)


def figure(name, value, target, baseline, unit, at_most=True, **extra) -> dict:
    """One figure; a `target` of None reports it without one."""
    met = None if value is None or target is None else bool(value <= target if at_most else value >= target)
    return {"figure": name, "value": value, "target": target, "target_is": "max" if at_most else "min",
            "baseline": baseline, "unit": unit, "met": met, **extra}


def print_figures(figures: list[dict], console: Console,
                  title: str = "bench_realistic — figures (realistic bodies; baseline: the Chen torso, same run)") -> None:
    table = new_table(title, ("figure", "value", "target", "baseline", "met", "over"))
    for f in figures:
        unit = f["unit"]
        show = lambda v: "–" if v is None else f"{v:.3g} {unit}"  # noqa: E731
        target = "–" if f["target"] is None else f"{'≤' if f['target_is'] == 'max' else '≥'} {f['target']:g} {unit}"
        table.add_row(f["figure"], show(f["value"]), target,
                      show(f["baseline"]), "–" if f["met"] is None else ("yes" if f["met"] else "no"), f.get("over", ""))
    console.print(table)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, help="rounds of the ingest timing (default 5)")
    parser.add_argument("--quick", action="store_true", help="8 realistic + 2 Chen scenes, 2 rounds")
    args = parser.parse_args()
    repeats = args.repeats or (2 if args.quick else 5)
    console = Console(width=200)
    start, load_start = time.perf_counter(), os.getloadavg()

    with threadpool_limits(1, "blas"):      # as `breastplan fit` runs
        real, chen, timing_frames, chen_frames = run_all(args.quick, console)
        scenes_s = time.perf_counter() - start
        timing_start = time.perf_counter()
        timing = ingest_timing(timing_frames, chen_frames, repeats)
        timing_s = time.perf_counter() - timing_start

    print_scenes(real, chen, console)
    cup, firm, chen_cup = realistic_pairs(real, "cup"), realistic_pairs(real, "firmness"), chen_pairs(chen)
    chen_order = chen_ptosis_order(chen)
    print_pairs(cup, firm, chen_cup, console)
    print_timing(timing, console)

    iso, iso_chen = isolation_figures(real), isolation_figures(chen)
    cup_errors = [abs(c["relative_error_pct"]) for c in cup if c["fitted"]]
    chen_cup_errors = [abs(c["relative_error_pct"]) for c in chen_cup if c["fitted"]]
    firm_fitted = [c for c in firm if c["fitted"]]
    fits, chen_fits = fit_times(real), fit_times(chen)
    spreads = view_spreads(real)
    b0_alone = {k: sum(c["b0_order"] == k for c in firm_fitted) for k in ("right", "tie", "wrong")}
    T = TARGETS
    figures = [
        figure("both_isolated", iso["both_isolated_pct"], T["both_isolated_pct"], iso_chen["both_isolated_pct"], "%",
               at_most=False, over=f"{iso['both_isolated']}/{iso['scenes']} scenes (Chen {iso_chen['both_isolated']}/"
               f"{iso_chen['scenes']}); sides raised {iso['sides_raised']}, far {iso['sides_far']}"),
        figure("nipple_error_median", iso["nipple_median_mm"], T["nipple_median_mm"], iso_chen["nipple_median_mm"], "mm",
               over=f"{iso['sides_isolated']}/{iso['sides']} isolated sides (Chen {iso_chen['sides_isolated']})"),
        figure("nipple_error_worst", iso["nipple_worst_mm"], T["nipple_worst_mm"], iso_chen["nipple_worst_mm"], "mm",
               over=f"{iso['sides_isolated']}/{iso['sides']} isolated sides"),
        figure("nipple_asymmetry_worst", iso["asymmetry_worst_mm"], T["asymmetry_worst_mm"],
               iso_chen["asymmetry_worst_mm"], "mm",
               over=f"{iso['asymmetry_scenes']} scenes with both sides isolated (Chen {iso_chen['asymmetry_scenes']})"),
        figure("crop_on_breast_worst", iso["on_breast_worst_pct"], None, None, "%", at_most=False,
               core_held_worst=iso["core_held_worst_pct"], core_held_median=iso["core_held_median_pct"],
               over=f"{iso['crops']} isolated sides: the least share of a crop's points on MakeHuman's breast; "
               f"core_held: the share of the skin seen within {CORE_MM:g} mm of the true nipple the crop holds; "
               "no target"),
        figure("nipple_to_midline_error_worst", iso["midline_worst_mm"], None, iso_chen["midline_worst_mm"], "mm",
               median=iso["midline_median_mm"], up_axis_worst_deg=iso["up_worst_deg"],
               up_axis_median_deg=iso["up_median_deg"], up_axis_from_wall=iso["up_from_wall"],
               up_axis_wall_worst_deg=iso["up_wall_worst_deg"], up_axis_profile_worst_deg=iso["up_profile_worst_deg"],
               plane_normal_worst_deg=iso["normal_worst_deg"], baseline_up_axis_worst_deg=iso_chen["up_worst_deg"],
               over=f"{iso['landmark_scenes']} scenes with both sides isolated ({iso['landmark_errors']} without "
               f"landmarks; Chen {iso_chen['landmark_scenes']}): the plan's nipple-to-midline measure minus the "
               "true one, and its up axis and mid-sagittal plane against the body's; no target"),
        figure("notch_to_nipple_error_worst", iso["notch_to_nipple_worst_mm"], None, None, "mm",
               median=iso["notch_to_nipple_median_mm"], notch_median_mm=iso["notch_median_mm"],
               notch_worst_mm=iso["notch_worst_mm"], nipple_below_notch_median_mm=iso["nipple_below_notch_median_mm"],
               nipple_below_notch_worst_mm=iso["nipple_below_notch_worst_mm"],
               over=f"{iso['landmark_scenes']} scenes: the plan's notch-to-nipple chord minus the one between "
               "MakeHuman's notch and nipple; notch: the found sternal notch's distance from MakeHuman's; "
               "nipple_below_notch: the nipple's drop below the notch minus the true one; no target, no "
               "baseline (the Chen torso has no neck)"),
        figure("cup_change_relative_error_worst", max_or_none(cup_errors), T["cup_change_worst_pct"],
               max_or_none(chen_cup_errors), "%", median=median_or_none(cup_errors),
               over=f"{len(cup_errors)}/{len(cup)} pair × view × side cases (Chen {len(chen_cup_errors)}/{len(chen_cup)})"),
        figure("firmness_ptosis_order", 100.0 * sum(c["order_ok"] for c in firm_fitted) / len(firm_fitted)
               if firm_fitted else None, T["firmness_order_pct"], chen_order["order_ok_pct"], "%", at_most=False,
               ties=sum(c["order"] == "tie" for c in firm_fitted), wrong=sum(c["order"] == "wrong" for c in firm_fitted),
               b0_alone=b0_alone,
               over=f"{len(firm_fitted)}/{len(firm)} cases, ptosis sag at the apex (b0 alone: {b0_alone['right']} right, "
               f"{b0_alone['tie']} ties); Chen: {len(chen_order['cases'])} scenes, left/right sag order"),
        figure("firmness_volume_difference_worst", max_or_none(c["volume_difference_pct"] for c in firm_fitted),
               T["firmness_volume_pct"], max_or_none(c["true_difference_pct"] for c in firm_fitted), "%",
               baseline_is="the true difference (half-body volumes) in % of the same mean",
               over=f"{len(firm_fitted)}/{len(firm)} cases"),
        figure("firmness_volume_change_error_worst", max_or_none(c["change_error_pct"] for c in firm_fitted), None,
               None, "%", median=median_or_none(c["change_error_pct"] for c in firm_fitted),
               over=f"{len(firm_fitted)}/{len(firm)} cases: |fitted − true volume change| in % of the mean fitted "
               f"volume; no target"),
        figure("volume_spread_over_views_worst", max_or_none(c["spread_pct"] for c in spreads), None, None, "%",
               median=median_or_none(c["spread_pct"] for c in spreads),
               over=f"{len(spreads)} body × side cases, fitted from {min((len(c['volume_cc']) for c in spreads), default=0)}"
               f"–{max((len(c['volume_cc']) for c in spreads), default=0)} views; no target (repeatability)"),
        figure("fit_seconds_median", median_or_none(fits), T["fit_s"], median_or_none(chen_fits), "s",
               over=f"{len(fits)} realistic fits, {len(chen_fits)} Chen fits, one call each"),
        figure("ingest_800x600_seconds_median", median_or_none(r["median_s"] for r in timing), T["ingest_800x600_s"],
               median_or_none(r["baseline_s"] for r in timing), "s",
               ratio=(statistics.median(r["median_s"] for r in timing) / statistics.median(r["baseline_s"] for r in timing)
                      if timing else None),
               over=f"{len(timing)} cases × {repeats} repeats; baseline Chen 640×400"),
    ]
    print_figures(figures, console)
    wall = time.perf_counter() - start
    per_scene = statistics.mean(s.wall_s for s in real)
    console.print(f"Wall time {wall:.0f} s: scenes {scenes_s:.0f} s ({len(real)} realistic, mean {per_scene:.1f} s; "
                  f"{len(chen)} Chen, mean {statistics.mean(s.wall_s for s in chen):.1f} s), ingest timing "
                  f"{timing_s:.0f} s; load average {load_start[0]:.1f} → {os.getloadavg()[0]:.1f}.")
    for f in figures:
        print(json.dumps(rounded(f)))
    print(json.dumps(rounded({
        "benchmark": "bench_realistic", "quick": bool(args.quick), "repeats": repeats, "frames": FRAMES,
        "isolated_mm": ISOLATED_MM, "targets": TARGETS, "figures": {f["figure"]: f for f in figures},
        "isolation": iso, "isolation_chen": iso_chen, "cup_pairs": cup, "firmness_pairs": firm, "chen_cup_pairs": chen_cup,
        "chen_ptosis_order": chen_order, "view_spreads": spreads, "ingest_timing": timing,
        "scenes": [s.as_dict() for s in real], "chen_scenes": [s.as_dict() for s in chen],
        "met": all(f["met"] for f in figures if f["target"] is not None), "loadavg_start": load_start, "loadavg_end": os.getloadavg(),
        "wall_s": wall})))


if __name__ == "__main__":
    main()
