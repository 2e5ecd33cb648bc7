"""How well the breast volume measured on her skin repeats, with the fitted model's volume as the baseline.

`plan.breast_volume.measure_breasts` measures each breast as the tissue in front of one chest wall
inside the breast's footprint, from the torso ingest found, the nipples found and the landmarks'
body frame. This script scans MakeHuman bodies (`scenes.makehuman`, rendered by
`scenes.realistic.BodyScene`, 8 noisy depth frames at 800×600, `ingest_frames` for both sides,
automatic isolation) and gives each scene to `measure_breasts` (the torso, the nipples found, the
viewing frame and the wall's plumb of the left side's ingest) and, in the same run, to the fitted
model (`fit_scan(ingested).volume_cc` per side, BLAS on one thread as `breastplan fit` runs it):

1. re-scans: 4 bodies (cup 0.8 / firmness 0.3, arms down; cup 0.3 / firmness 0.8 / weight 0.8,
   hands on hips; cup 0.6 / weight 0.3 / muscle 0.7, a-pose; asymmetry +0.5), each scanned
   RESCANS times from a camera drawn per scan (seeded): distance 600–720 mm, pitch 2–10°, yaw
   −7..7°, aimed ±25 mm above or below the nipples' midpoint, a new noise seed, in the same room (a
   wall 400 mm behind bodies 1 and 3, none behind 2 and 4). Per breast:
   * the volume's coefficient of variation (stdev / mean) — target: median over the breasts ≤ 2 %;
   * its spread (max − min) / median — target: worst ≤ 6 %;
   * the nipple spread: the largest distance of a scan's nipple (found by ingest) from the scans'
     mean, in the body frame `measure_breasts` found (`body_from_input`) — target: worst ≤ 2 mm;
     reported beside it: the same nipples in the true body frame (ingest's own spread) and the
     true nipple in the found frames (the frame's own spread);
   * the footprint spread: per scan, the distance between its footprint curve and that of the
     scan whose volume is the median, in the found body frame, in x–y (both curves resampled every
     CURVE_STEP_MM, the mean distance from each point of one to the nearest of the other, both ways
     averaged), averaged over the other scans — target: worst ≤ 4 mm; the same in the true frame
     beside it;
   * honesty: the share of the scans' volumes within their stated ± (`uncertainty_cc`) of their
     breast's median volume — target ≥ 90 % over all re-scans (the fitted model states no ±);
   * her width (`plan.base_width`): its max − min over the re-scans, beside the fitted model's base
     outline's width (`breast_measures`), no target; and on the symmetric bodies (2.), |left − right|.
2. symmetric bodies: 2 bodies (weight 0.85 / cup 0.2; weight 0.5 / cup 0.7) in 6 views each (each
   pose twice, with a wall and without, yaw −10..10°): |left − right| / mean volume — target ≤ 3 %
   in every view (the bodies' true half-body volumes differ by under 3 cc). Beside it, with no target:
   each body × pose is seen from 2 of these views; the spread of each breast's volume over them.
3. asymmetry: measured left − right volume against the true one (the difference of the exact
   half-body volumes, `Body.half_volumes_cc`), |error| in cc — target: worst ≤ 20 cc. Bodies:
   MakeHuman's asymmetry target (`asym/asymm-breast-1-l/-r`, modifier "asymmetry" ±0.5; it lowers
   one breast by up to 10 mm and raises the other by up to 5 mm, and changes the half-body volumes
   by only 10–20 cc, so that measuring no difference at all would meet the target) on 3 bodies in
   2 views each, and the re-scans of body 4 of set 1. Beside it: one-sided cup changes, bodies whose
   left half has one cup and right half another (two MakeHuman bodies blended across the midline over
   ±BLEND_MM by a smooth step; the truth is the blended mesh's own half volumes, 135 and 390 cc apart;
   the vertices the cup targets move all lie within 145 mm of the nipple), 2 bodies in 2 views each:
   |error| in % of the true difference — target ≤ 10 % (bench_realistic's for a cup change). To
   explain it, what a perfect front view holds of the true difference: the body's true surface seen along
   her found anterior axis (every cell seen, no perspective, `true_front_mm`), its left less its mirror
   image on the right, summed over the whole grid (no wall, no outline) and, clipped at the measured wall,
   over the footprint the measure drew; and the measure's own left − right over the cells it saw against
   that perfect view's on the same cells.

4. the other room: each re-scan body scanned once more with a wall where its re-scans had none (or
   none where they had one), whose up axis then comes from the other source: its nipple and volume
   against the re-scans' (no target).
5. two visits: two women whose cup changed between visits (bench_realistic's cup pairs), one scan
   each: her change measured on her skin from each scan alone, on each visit's own wall, as a share of
   the true half-body change, beside the fitted model's (no target: a follow-up is measured on one
   wall, `--wall-from`, which bench_realistic measures).

A scene whose ingest, measure or fit raises is counted and listed; its breasts are left out of the
figures they would enter. Nothing is asserted. The script prints tables, then one JSON line per figure
({"benchmark", "figure", "value", "target", "baseline", "unit", "met", ...}) and a last line with
everything.

Run:  .venv/bin/python benchmarks/bench_volume_repeat.py     (50 scenes, about 3 minutes on 2 cores)
"""
from __future__ import annotations

import json
import os
import statistics
import time
from dataclasses import dataclass, field, replace

import numpy as np
from rich.console import Console
from scipy.spatial import cKDTree
from threadpoolctl import threadpool_limits

from breastplan import BadInputError, transform_points
from breastplan.fitting.breast_fit import fit_scan
from breastplan.scenes.makehuman import Body, BodyOptions, blended, make_body
from breastplan.ingest.pipeline import ingest_frames
from breastplan.scenes.realistic import BodyScene, CameraOptions, camera_pose
from breastplan.ingest.recording import DepthFrames
from breastplan.options import SIDES, IngestOptions
from breastplan.plan.base_width import base_width_mm
from breastplan.plan.breast_volume import CELL_MM, measure_breasts
from breastplan.plan.measures import breast_measures

from bench_realistic import figure, new_table, print_figures
from timing import rounded

FRAMES = 8
RESOLUTION = "800x600"
WALL_MM = 400.0
RESCANS = 5
RESCAN_SEED = 20240
CURVE_STEP_MM = 1.0
BLEND_MM = 30.0
TARGETS = {"cv_median_pct": 2.0, "spread_worst_pct": 6.0, "nipple_spread_mm": 2.0, "footprint_spread_mm": 4.0,
           "honesty_pct": 90.0, "symmetric_worst_pct": 3.0, "asymmetry_worst_cc": 20.0, "one_sided_cup_worst_pct": 10.0}

# --- bodies and views -------------------------------------------------------------------------
BODIES = {
    "R1 cup .8 firm .3": BodyOptions(cup=0.8, firmness=0.3, pose="arms-down"),
    "R2 cup .3 firm .8 wt .8": BodyOptions(cup=0.3, firmness=0.8, weight=0.8, pose="hands-on-hips"),
    "R3 cup .6 wt .3 mus .7": BodyOptions(cup=0.6, weight=0.3, muscle=0.7, pose="a-pose"),
    "R4 asym +.5": BodyOptions(modifiers={"asymmetry": 0.5}),
    "S1 wt .85 cup .2": BodyOptions(weight=0.85, cup=0.2),
    "S2 wt .5 cup .7": BodyOptions(weight=0.5, cup=0.7),
    "A1 asym +.5 cup .3 wt .7": BodyOptions(cup=0.3, weight=0.7, modifiers={"asymmetry": 0.5}),
    "A2 asym -.5 cup .8 firm .3": BodyOptions(cup=0.8, firmness=0.3, modifiers={"asymmetry": -0.5}),
    "A3 asym -.5 trans +.5 cup .6": BodyOptions(cup=0.6, weight=0.6, modifiers={"asymmetry": -0.5, "breast_trans": 0.5}),
    "V1 cup .3": BodyOptions(cup=0.3, pose="arms-down"), "V1 cup .8": BodyOptions(cup=0.8, pose="arms-down"),
    "V2 cup .2": BodyOptions(cup=0.2, firmness=0.7, weight=0.8, muscle=0.4, pose="hands-on-hips"),
    "V2 cup 1": BodyOptions(cup=1.0, firmness=0.7, weight=0.8, muscle=0.4, pose="hands-on-hips"),
}
HYBRIDS = {
    "C1 cup L .8 / R .4": (BodyOptions(cup=0.8), BodyOptions(cup=0.4)),
    "C2 cup L .3 / R .6 firm .3": (BodyOptions(cup=0.3, firmness=0.3, weight=0.6),
                                   BodyOptions(cup=0.6, firmness=0.3, weight=0.6)),
}
"""One-sided cup bodies: (left half's body, right half's body)."""
VISITS = {"V1": ("V1 cup .3", "V1 cup .8"), "V2": ("V2 cup .2", "V2 cup 1")}
"""Two visits of one woman whose cup changed between them (bench_realistic's cup pairs): (before, after)."""
RESCAN_BODIES = ("R1 cup .8 firm .3", "R2 cup .3 firm .8 wt .8", "R3 cup .6 wt .3 mus .7", "R4 asym +.5")
SYMMETRIC_VIEWS = (   # pose, distance mm, pitch °, yaw °, wall
    ("a-pose", 650.0, 4.0, 0.0, WALL_MM), ("arms-down", 700.0, 8.0, -10.0, None),
    ("hands-on-hips", 620.0, 6.0, 10.0, WALL_MM), ("a-pose", 680.0, 2.0, 7.0, None),
    ("hands-on-hips", 640.0, 10.0, -5.0, None), ("arms-down", 660.0, 5.0, 4.0, WALL_MM),
)
ASYMMETRY_VIEWS = {
    "A1 asym +.5 cup .3 wt .7": (("hands-on-hips", 660.0, 5.0, 4.0, WALL_MM), ("a-pose", 700.0, 8.0, -6.0, None)),
    "A2 asym -.5 cup .8 firm .3": (("arms-down", 640.0, 3.0, -4.0, None), ("a-pose", 690.0, 7.0, 7.0, WALL_MM)),
    "A3 asym -.5 trans +.5 cup .6": (("a-pose", 620.0, 6.0, 0.0, WALL_MM), ("hands-on-hips", 710.0, 9.0, -8.0, None)),
    "C1 cup L .8 / R .4": (("a-pose", 650.0, 5.0, 3.0, WALL_MM), ("arms-down", 690.0, 8.0, -7.0, None)),
    "C2 cup L .3 / R .6 firm .3": (("hands-on-hips", 630.0, 4.0, -3.0, None), ("a-pose", 700.0, 9.0, 8.0, WALL_MM)),
}


@dataclass(frozen=True)
class Shot:
    """One scene to scan: which set, which body in which pose, the camera, its aim and its noise seed."""

    set: str            # "rescan", "room" (a re-scan body in the other room), "symmetric", "asymmetry", "visit"
    body: str
    pose: str
    camera: CameraOptions
    dh_mm: float
    seed: int

    @property
    def label(self) -> str:
        c = self.camera
        return (f"{self.pose} d{c.distance_mm:.0f} p{c.pitch_deg:.0f} y{c.yaw_deg:+.0f} dh{self.dh_mm:+.0f} "
                f"{'wall' if c.wall_mm else 'open'}")


def shots() -> list[Shot]:
    out = []
    for k, name in enumerate(RESCAN_BODIES):
        rng = np.random.default_rng(RESCAN_SEED + k)
        for i in range(RESCANS):
            d, p, y, dh = rng.uniform(600, 720), rng.uniform(2, 10), rng.uniform(-7, 7), rng.uniform(-25, 25)
            cam = CameraOptions(float(d), float(p), float(y), RESOLUTION, wall_mm=WALL_MM if k % 2 == 0 else None)
            out.append(Shot("rescan", name, BODIES[name].pose, cam, float(dh), 100 * k + i))
        other_room = CameraOptions(660.0, 6.0, 0.0, RESOLUTION, wall_mm=None if k % 2 == 0 else WALL_MM)
        out.append(Shot("room", name, BODIES[name].pose, other_room, 0.0, 100 * k + 50))
    for k, name in enumerate(("S1 wt .85 cup .2", "S2 wt .5 cup .7")):
        for i, (pose, d, p, y, wall) in enumerate(SYMMETRIC_VIEWS):
            out.append(Shot("symmetric", name, pose, CameraOptions(d, p, y, RESOLUTION, wall_mm=wall), 0.0,
                            1000 + 100 * k + i))
    for k, (before, after) in enumerate(VISITS.values()):     # a second visit: another camera, the same room
        out.append(Shot("visit", before, BODIES[before].pose, CameraOptions(650.0, 5.0, 0.0, RESOLUTION), 0.0, 3000 + k))
        out.append(Shot("visit", after, BODIES[after].pose, CameraOptions(690.0, 8.0, -5.0, RESOLUTION), 0.0, 3100 + k))
    for k, (name, views) in enumerate(ASYMMETRY_VIEWS.items()):
        for i, (pose, d, p, y, wall) in enumerate(views):
            out.append(Shot("asymmetry", name, pose, CameraOptions(d, p, y, RESOLUTION, wall_mm=wall), 0.0,
                            2000 + 100 * k + i))
    return out


def build_body(name: str, pose: str) -> Body:
    if name in HYBRIDS:
        lo, ro = HYBRIDS[name]
        return blended(make_body(replace(lo, pose=pose)), make_body(replace(ro, pose=pose)), BLEND_MM)
    return make_body(replace(BODIES[name], pose=pose))


# --- one scene -------------------------------------------------------------------------------
@dataclass
class SceneResult:
    shot: Shot
    truth_cc: dict                      # side → exact half-body volume
    seconds: dict = field(default_factory=dict)
    errors: list = field(default_factory=list)          # (stage, message)
    nipple_error_mm: dict = field(default_factory=dict)  # side → found vs true nipple, 3-D
    new: dict = field(default_factory=dict)      # side → {volume_cc, uncertainty_cc, nipple_body, ...}
    fitted: dict = field(default_factory=dict)   # side → volume_cc
    fitted_width: dict = field(default_factory=dict)  # side → the fitted model's width_mm (`breast_measures`)
    frame: dict = field(default_factory=dict)    # the found landmarks in the true body frame: notch, up, left
    front_lr_cc: dict = field(default_factory=dict)  # a perfect front view's left − right: `front_difference_cc`

    def as_dict(self) -> dict:
        s = self.shot
        new = {side: {k: v for k, v in d.items() if not k.startswith("footprint")} for side, d in self.new.items()}
        return {"set": s.set, "body": s.body, "view": s.label, "seed": s.seed, "truth_cc": self.truth_cc,
                "seconds": self.seconds, "errors": self.errors, "nipple_error_mm": self.nipple_error_mm,
                "new": new, "fitted": self.fitted, "fitted_width_mm": self.fitted_width, "frame": self.frame}


def scanned_and_measured(scene: BodyScene, seed: int, label: str):
    """(her body as the left side's ingest found it, side → the nipple found (input frame, mm), both breasts'
    `measure_breasts`): FRAMES depth frames of `scene` (noise seed `seed`) ingested for both sides, as `plan`
    ingests them. BadInputError as ingest or the measure raise it."""
    frames = DepthFrames(scene.frames(FRAMES, seed), scene.camera.K, label)
    ing = {side: ingest_frames(frames, IngestOptions(side)) for side in SIDES}
    nipples = {side: np.asarray(i.nipple_camera, float) for side, i in ing.items()}
    body = ing["left"].body
    return body, nipples, measure_breasts(body, nipples)


def true_body_from_camera(scene: BodyScene) -> np.ndarray:
    """(4, 4) camera → MakeHuman's body frame with its origin at the body's sternal notch (her body frame, truly)."""
    T = np.linalg.inv(scene.camera_from_body)
    T[:3, 3] -= scene.body.sternal_notch
    return T


def run_scene(shot: Shot) -> SceneResult:
    t0 = time.perf_counter()
    made = build_body(shot.body, shot.pose)
    target = 0.5 * (made.nipples["left"] + made.nipples["right"]) + [0.0, shot.dh_mm, 0.0]
    scene = BodyScene(made, shot.camera, camera_pose(target, shot.camera))
    frames = DepthFrames(scene.frames(FRAMES, shot.seed), scene.camera.K, shot.body)
    out = SceneResult(shot, made.half_volumes_cc())
    out.seconds["render"] = time.perf_counter() - t0
    truth = scene.nipples_camera()
    ing = {}
    t0 = time.perf_counter()
    for side in SIDES:
        try:
            ing[side] = ingest_frames(frames, IngestOptions(side))
            out.nipple_error_mm[side] = float(np.linalg.norm(ing[side].nipple_camera - truth[side]))
        except BadInputError as exc:
            out.errors.append((f"ingest {side}", str(exc)))
    out.seconds["ingest"] = time.perf_counter() - t0
    if not ing:
        return out
    first = ing["left"] if "left" in ing else ing["right"]
    nipples = {side: np.asarray(i.nipple_camera, float) for side, i in ing.items()}
    t0 = time.perf_counter()
    try:
        m = measure_breasts(first.body, nipples)
    except Exception as exc:  # noqa: BLE001 — the API is young: a failure is reported, not fatal
        out.errors.append(("measure", f"{type(exc).__name__}: {exc}"))
        m = None
    out.seconds["measure"] = time.perf_counter() - t0
    if m is not None:
        true_T = true_body_from_camera(scene)
        lm = m.landmarks
        out.frame = {"notch": transform_points(true_T, np.asarray(lm.sternal_notch)[None])[0],
                     "up": true_T[:3, :3] @ lm.up_axis, "left": true_T[:3, :3] @ lm.left_axis}
        out.front_lr_cc = front_difference_cc(m, scene) if shot.body in HYBRIDS else {}
        for side, b in m.sides.items():
            out.new[side] = {
                "volume_cc": float(b.volume_cc), "uncertainty_cc": float(b.uncertainty_cc),
                "width_mm": base_width_mm(m.cells, m.in_body(nipples[side]), side),
                "unseen_outer_cc": float(b.unseen_outer_cc),
                "nipple_body": transform_points(m.body_from_input, nipples[side][None])[0],
                "nipple_true_frame": transform_points(true_T, nipples[side][None])[0],
                "true_nipple_found_frame": transform_points(m.body_from_input, truth[side][None])[0],
                "footprint_body": transform_points(m.body_from_input, b.footprint_input_mm),
                "footprint_true_frame": transform_points(true_T, b.footprint_input_mm),
            }
    t0 = time.perf_counter()
    for side, ingested in ing.items():
        try:
            fit = fit_scan(ingested)
            out.fitted[side] = float(fit.volume_cc)
            if m is not None:
                surface = transform_points(np.linalg.inv(ingested.input_to_breast), fit.vertices)
                out.fitted_width[side] = breast_measures(m.landmarks, nipples[side], surface, fit.faces)["width_mm"]
        except BadInputError as exc:
            out.errors.append((f"fit {side}", str(exc)))
    out.seconds["fit"] = time.perf_counter() - t0
    out.seconds["fit_per_breast"] = out.seconds["fit"] / len(ing)
    return out


def true_front_mm(m, scene: BodyScene) -> np.ndarray:
    """(nx, ny) the body's true surface on the measure's cells as a perfect front view sees it: the first hit
    on the body of a ray along her found anterior axis (−z of her found body frame) through each cell's centre,
    in that frame (mm; NaN: no body there). The scene's own ray casting, in its camera (the input) frame."""
    import open3d as o3d

    to_input = np.linalg.inv(m.body_from_input)
    top = float(transform_points(m.body_from_input @ scene.camera_from_body, scene.body.vertices)[:, 2].max()) + 100.0
    X, Y = np.meshgrid(m.cells.x, m.cells.y, indexing="ij")
    origins = transform_points(to_input, np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, top)]))
    rays = np.column_stack([origins, np.tile(to_input[:3, :3] @ [0.0, 0.0, -1.0], (X.size, 1))])
    hit = scene.raycasting().cast_rays(o3d.core.Tensor(rays.astype(np.float32)))
    t = np.where(hit["geometry_ids"].numpy() == 0, hit["t_hit"].numpy(), np.inf).astype(float)   # 0: the body
    return np.where(np.isfinite(t), top - t, np.nan).reshape(X.shape)


def front_difference_cc(m, scene: BodyScene) -> dict:
    """Left less mirrored right (cc) of a perfect front view (`true_front_mm`): over the whole grid (her skin, no
    wall, no outline: the wall's mirror-symmetric part cancels), over the measured footprint (heights above the
    measured wall, those above 0, as the measure sums them), and over the footprint's cells the camera saw,
    beside the measure's own left − right on those same cells."""
    c = m.cells
    front = true_front_mm(m, scene)
    left = (c.x > 0)[:, None] & np.ones_like(c.footprint)

    def lr(h, mask):
        h = np.clip(np.nan_to_num(h), 0.0, None)
        return float(h[mask & left].sum() - h[mask & ~left].sum()) * CELL_MM ** 2 / 1000.0

    seen = c.footprint & c.seen
    return {"whole_grid": float(np.nansum((front - front[::-1])[c.x > 0])) * CELL_MM ** 2 / 1000.0,
            "footprint": lr(front - c.wall_mm, c.footprint),
            "seen_cells": lr(front - c.wall_mm, seen), "measured_seen_cells": lr(c.height_mm, seen)}


# --- figures ---------------------------------------------------------------------------------
def resampled(curve: np.ndarray) -> np.ndarray:
    """A closed x–y curve resampled every CURVE_STEP_MM along its length."""
    xy = np.asarray(curve, float)[:, :2]
    if not np.allclose(xy[0], xy[-1]):
        xy = np.vstack([xy, xy[:1]])
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    t = np.arange(0.0, s[-1], CURVE_STEP_MM) if s[-1] > 0 else np.zeros(1)
    return np.column_stack([np.interp(t, s, xy[:, 0]), np.interp(t, s, xy[:, 1])])


def curve_distance_mm(a: np.ndarray, b: np.ndarray) -> float:
    """Mean x–y distance from each point of one curve to the nearest point of the other, both ways averaged."""
    if len(a) < 2 or len(b) < 2:
        return float("nan")
    A, B = resampled(a), resampled(b)
    return 0.5 * float(cKDTree(B).query(A)[0].mean() + cKDTree(A).query(B)[0].mean())


def cv_pct(v: list[float]) -> float | None:
    return 100.0 * statistics.stdev(v) / statistics.mean(v) if len(v) >= 2 else None


def spread_pct(v: list[float]) -> float | None:
    return 100.0 * (max(v) - min(v)) / statistics.median(v) if len(v) >= 2 else None


def point_spread_mm(points: list[np.ndarray]) -> float | None:
    if len(points) < 2:
        return None
    P = np.array(points)
    return float(np.linalg.norm(P - P.mean(0), axis=1).max())


def angle_spread_deg(axes: list[np.ndarray]) -> float | None:
    """The largest angle of a unit axis from the axes' mean direction."""
    if len(axes) < 2:
        return None
    A = np.array(axes)
    mean = A.mean(0) / np.linalg.norm(A.mean(0))
    return float(np.degrees(np.arccos(np.clip(A @ mean, -1.0, 1.0))).max())


def footprint_spread_mm(curves: list[np.ndarray], volumes: list[float]) -> float | None:
    """Mean distance of each scan's footprint from that of the scan whose volume is the median."""
    if len(curves) < 2:
        return None
    ref = int(np.argsort(volumes)[len(volumes) // 2])
    return statistics.mean(curve_distance_mm(c, curves[ref]) for k, c in enumerate(curves) if k != ref)


def rescan_rows(results: list[SceneResult]) -> list[dict]:
    rows = []
    for name in RESCAN_BODIES:
        scans = [r for r in results if r.shot.set == "rescan" and r.shot.body == name]
        for side in SIDES:
            new = [r.new[side] for r in scans if side in r.new]
            vol = [n["volume_cc"] for n in new]
            fit = [r.fitted[side] for r in scans if side in r.fitted]
            med = statistics.median(vol) if vol else None
            frames = [r.frame for r in scans if r.frame]
            widths = [n["width_mm"] for n in new]
            fitted_widths = [r.fitted_width[side] for r in scans if side in r.fitted_width]
            rows.append({
                "body": name, "side": side, "scans": len(scans), "new_cc": vol, "fitted_cc": fit,
                "new_width_mm": widths, "fitted_width_mm": fitted_widths,
                "new_width_spread_mm": float(np.ptp(widths)) if len(widths) > 1 else None,
                "fitted_width_spread_mm": float(np.ptp(fitted_widths)) if len(fitted_widths) > 1 else None,
                "uncertainty_cc": [n["uncertainty_cc"] for n in new],
                "new_cv_pct": cv_pct(vol), "new_spread_pct": spread_pct(vol),
                "fitted_cv_pct": cv_pct(fit), "fitted_spread_pct": spread_pct(fit),
                "honest": sum(abs(n["volume_cc"] - med) <= n["uncertainty_cc"] for n in new), "measured": len(new),
                "nipple_spread_mm": point_spread_mm([n["nipple_body"] for n in new]),
                "nipple_spread_true_frame_mm": point_spread_mm([n["nipple_true_frame"] for n in new]),
                "frame_spread_mm": point_spread_mm([n["true_nipple_found_frame"] for n in new]),
                "footprint_spread_mm": footprint_spread_mm([n["footprint_body"] for n in new], vol),
                "footprint_spread_true_frame_mm": footprint_spread_mm([n["footprint_true_frame"] for n in new], vol),
                "notch_spread_mm": point_spread_mm([f["notch"] for f in frames]),
                "up_spread_deg": angle_spread_deg([f["up"] for f in frames]),
                "left_spread_deg": angle_spread_deg([f["left"] for f in frames]),
                **_other_room(results, name, side, new, med),
            })
    return rows


def _other_room(results: list[SceneResult], name: str, side: str, new: list[dict], median: float | None) -> dict:
    """The body scanned once in the other room (a wall behind her where the re-scans had none, or none
    where they had one): its nipple's distance from the re-scans' mean nipple in the found body frame, and
    its volume's difference from the re-scans' median."""
    room = [r.new[side] for r in results if r.shot.set == "room" and r.shot.body == name and side in r.new]
    if not room or not new or not median:
        return {}
    mean = np.mean([n["nipple_body"] for n in new], axis=0)
    return {"other_room_nipple_mm": float(np.linalg.norm(np.asarray(room[0]["nipple_body"]) - mean)),
            "other_room_volume_pct": 100.0 * (room[0]["volume_cc"] - median) / median}


def lr(d: dict) -> float | None:
    return d["left"] - d["right"] if all(s in d for s in SIDES) else None


def sym_pct(d: dict) -> float | None:
    return 100.0 * abs(d["left"] - d["right"]) / (0.5 * (d["left"] + d["right"])) if all(s in d for s in SIDES) else None


def volumes(r: SceneResult, which: str) -> dict:
    return {s: v["volume_cc"] for s, v in r.new.items()} if which == "new" else dict(r.fitted)


def symmetric_rows(results: list[SceneResult]) -> list[dict]:
    return [{"body": r.shot.body, "view": r.shot.label, "true_lr_cc": lr(r.truth_cc),
             "new_cc": volumes(r, "new"), "fitted_cc": volumes(r, "fitted"),
             "new_pct": sym_pct(volumes(r, "new")), "fitted_pct": sym_pct(volumes(r, "fitted")),
             "new_width_lr_mm": lr({s: v["width_mm"] for s, v in r.new.items()}),
             "fitted_width_lr_mm": lr(r.fitted_width)}
            for r in results if r.shot.set == "symmetric"]


def pose_spreads(results: list[SceneResult]) -> list[dict]:
    """Per symmetric body × pose × side: the spread (max − min) / median of its volumes over the views in that pose."""
    rows = []
    for name in dict.fromkeys(r.shot.body for r in results if r.shot.set == "symmetric"):
        for pose in dict.fromkeys(r.shot.pose for r in results if r.shot.set == "symmetric" and r.shot.body == name):
            views = [r for r in results if r.shot.set == "symmetric" and r.shot.body == name and r.shot.pose == pose]
            for side in SIDES:
                new = [r.new[side]["volume_cc"] for r in views if side in r.new]
                fit = [r.fitted[side] for r in views if side in r.fitted]
                rows.append({"body": name, "pose": pose, "side": side, "new_cc": new, "fitted_cc": fit,
                             "new_spread_pct": spread_pct(new), "fitted_spread_pct": spread_pct(fit)})
    return rows


def asymmetry_rows(results: list[SceneResult]) -> list[dict]:
    rows = []
    for r in results:
        if r.shot.set == "asymmetry" or (r.shot.set == "rescan" and r.shot.body == "R4 asym +.5"):
            true = lr(r.truth_cc)
            new, fit = lr(volumes(r, "new")), lr(volumes(r, "fitted"))
            rows.append({"kind": "one-sided cup" if r.shot.body in HYBRIDS else "asymmetry target",
                         "body": r.shot.body, "view": r.shot.label, "true_lr_cc": true,
                         "new_lr_cc": new, "fitted_lr_cc": fit, "front_lr_cc": r.front_lr_cc,
                         "new_error_cc": None if new is None else new - true,
                         "range_holds": None if new is None else range_holds(r.new["left"], r.new["right"], true),
                         "fitted_error_cc": None if fit is None else fit - true})
    return rows


def range_holds(left: dict, right: dict, true_lr: float) -> bool:
    """Whether a true left − right (cc) lies within the measured one's stated range: both breasts' ±, and beyond
    them what each breast's unseen outer side may add (to its own side of the difference). `left`, `right`: each
    breast's `volume_cc`, `uncertainty_cc` and `unseen_outer_cc`."""
    lr, u = left["volume_cc"] - right["volume_cc"], left["uncertainty_cc"] + right["uncertainty_cc"]
    return lr - u - right["unseen_outer_cc"] <= true_lr <= lr + u + left["unseen_outer_cc"]


def visit_rows(results: list[SceneResult]) -> list[dict]:
    """Per woman and side: her change between two visits measured on her skin from each visit's scan alone
    (each on its own chest wall), and the fitted model's likewise, against the true half-body change."""
    by_body = {r.shot.body: r for r in results if r.shot.set == "visit"}
    rows = []
    for woman, (before, after) in VISITS.items():
        if before not in by_body or after not in by_body:
            continue
        then, now = by_body[before], by_body[after]
        for side in SIDES:
            true = now.truth_cc[side] - then.truth_cc[side]
            new = (now.new[side]["volume_cc"] - then.new[side]["volume_cc"]) if side in now.new and side in then.new \
                else None
            fit = (now.fitted[side] - then.fitted[side]) if side in now.fitted and side in then.fitted else None
            rows.append({"woman": woman, "side": side, "true_cc": true, "new_cc": new, "fitted_cc": fit,
                         "new_pct_of_true": None if new is None else 100.0 * new / true,
                         "fitted_pct_of_true": None if fit is None else 100.0 * fit / true})
    return rows


def relative(row: dict, which: str) -> float | None:
    e = row[f"{which}_error_cc"]
    return None if e is None else 100.0 * e / abs(row["true_lr_cc"])


def share(row: dict, key: str) -> float | None:
    """A perfect front view's left − right (`front_difference_cc`, `key`) as % of the row's true difference."""
    return None if not row["front_lr_cc"] else 100.0 * row["front_lr_cc"][key] / row["true_lr_cc"]


def worst_abs(values) -> float | None:
    values = [abs(v) for v in values if v is not None]
    return max(values) if values else None


def median_of(values) -> float | None:
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None


def worst_of(values) -> float | None:
    values = [v for v in values if v is not None]
    return max(values) if values else None


def figures_of(resc: list[dict], sym: list[dict], asym: list[dict], results: list[SceneResult]) -> list[dict]:
    poses = pose_spreads(results)
    visits = visit_rows(results)
    T = TARGETS
    honest, measured = sum(r["honest"] for r in resc), sum(r["measured"] for r in resc)
    breasts = f"{sum(r['measured'] >= 2 for r in resc)} breasts × {RESCANS} re-scans"
    targeted = [a for a in asym if a["kind"] == "asymmetry target"]
    cups = [a for a in asym if a["kind"] == "one-sided cup"]
    measure_s = [r.seconds["measure"] for r in results if "measure" in r.seconds]
    fit_s = [r.seconds["fit_per_breast"] for r in results if "fit_per_breast" in r.seconds]
    figures = [
        figure("rescan_volume_cv_median", median_of(r["new_cv_pct"] for r in resc), T["cv_median_pct"],
               median_of(r["fitted_cv_pct"] for r in resc), "%", worst=worst_of(r["new_cv_pct"] for r in resc),
               baseline_worst=worst_of(r["fitted_cv_pct"] for r in resc), over=breasts),
        figure("rescan_volume_spread_worst", worst_of(r["new_spread_pct"] for r in resc), T["spread_worst_pct"],
               worst_of(r["fitted_spread_pct"] for r in resc), "%", median=median_of(r["new_spread_pct"] for r in resc),
               baseline_median=median_of(r["fitted_spread_pct"] for r in resc),
               over=f"{breasts}: (max − min) / median"),
        figure("rescan_nipple_spread_worst", worst_of(r["nipple_spread_mm"] for r in resc), T["nipple_spread_mm"],
               None, "mm", median=median_of(r["nipple_spread_mm"] for r in resc),
               true_frame_worst=worst_of(r["nipple_spread_true_frame_mm"] for r in resc),
               frame_alone_worst=worst_of(r["frame_spread_mm"] for r in resc),
               notch_worst_mm=worst_of(r["notch_spread_mm"] for r in resc),
               up_axis_worst_deg=worst_of(r["up_spread_deg"] for r in resc),
               left_axis_worst_deg=worst_of(r["left_spread_deg"] for r in resc),
               over=f"{breasts}: the found nipple in the found body frame; true_frame: the same nipples in the "
                    "true body frame (ingest alone); frame_alone: the true nipple in the found frames"),
        figure("rescan_footprint_spread_worst", worst_of(r["footprint_spread_mm"] for r in resc),
               T["footprint_spread_mm"], None, "mm", median=median_of(r["footprint_spread_mm"] for r in resc),
               true_frame_worst=worst_of(r["footprint_spread_true_frame_mm"] for r in resc),
               over=f"{breasts}: x–y distance from the median-volume scan's footprint, found body frame"),
        figure("other_room_nipple_worst", worst_of(r.get("other_room_nipple_mm") for r in resc), None, None, "mm",
               volume_worst_pct=worst_of(abs(r["other_room_volume_pct"]) for r in resc if "other_room_volume_pct" in r),
               over="each re-scan body scanned once more in the other room (a wall where its re-scans had none, or "
                    "none where they had one): the nipple from the re-scans' mean, found body frame; its volume "
                    "from their median (no target: the up axis then comes from the wall on one visit and from her "
                    "midline profile on the other)"),
        figure("rescan_width_spread_worst", worst_of(r["new_width_spread_mm"] for r in resc), None,
               worst_of(r["fitted_width_spread_mm"] for r in resc), "mm",
               median=median_of(r["new_width_spread_mm"] for r in resc),
               baseline_median=median_of(r["fitted_width_spread_mm"] for r in resc),
               over=f"{breasts}: max − min of her width on her skin (`base_width_mm`); baseline: the fitted model's "
                    "base outline's (`breast_measures`' width_mm); no target"),
        figure("symmetric_width_difference_worst", worst_abs(s["new_width_lr_mm"] for s in sym), None,
               worst_abs(s["fitted_width_lr_mm"] for s in sym), "mm",
               median=median_of(abs(s["new_width_lr_mm"]) for s in sym if s["new_width_lr_mm"] is not None),
               over=f"{len(sym)} views of 2 symmetric bodies: |left − right| of her width; baseline: the fitted "
                    "model's; no target"),
        figure("rescan_honesty", 100.0 * honest / measured if measured else None, T["honesty_pct"], None, "%",
               at_most=False, over=f"{honest}/{measured} re-scan volumes within their ± of their breast's median "
                                   "(the fitted model states no ±)"),
        figure("symmetric_difference_worst", worst_of(s["new_pct"] for s in sym), T["symmetric_worst_pct"],
               worst_of(s["fitted_pct"] for s in sym), "%", median=median_of(s["new_pct"] for s in sym),
               baseline_median=median_of(s["fitted_pct"] for s in sym),
               over=f"{sum(s['new_pct'] is not None for s in sym)}/{len(sym)} views of 2 symmetric bodies: "
                    "|left − right| / mean"),
        figure("symmetric_same_pose_spread_worst", worst_of(p["new_spread_pct"] for p in poses), None,
               worst_of(p["fitted_spread_pct"] for p in poses), "%", median=median_of(p["new_spread_pct"] for p in poses),
               baseline_median=median_of(p["fitted_spread_pct"] for p in poses),
               over=f"{len(poses)} symmetric body × pose × side cases, each seen from 2 views (yaw up to ±10°): "
                    "(max − min) / median; no target (repeatability beyond the re-scans' ±7°)"),
        figure("asymmetry_error_worst", worst_abs(a["new_error_cc"] for a in targeted), T["asymmetry_worst_cc"],
               worst_abs(a["fitted_error_cc"] for a in targeted), "cc",
               median=median_of(abs(a["new_error_cc"]) for a in targeted if a["new_error_cc"] is not None),
               baseline_median=median_of(abs(a["fitted_error_cc"]) for a in targeted
                                         if a["fitted_error_cc"] is not None),
               true_lr_cc_range=[min(a["true_lr_cc"] for a in targeted), max(a["true_lr_cc"] for a in targeted)],
               over=f"{sum(a['new_error_cc'] is not None for a in targeted)}/{len(targeted)} scenes with MakeHuman's "
                    "asymmetry target: |measured − true (left − right)|"),
        figure("one_sided_cup_error_worst", worst_abs(relative(a, "new") for a in cups), T["one_sided_cup_worst_pct"],
               worst_abs(relative(a, "fitted") for a in cups), "%",
               worst_cc=worst_abs(a["new_error_cc"] for a in cups),
               range_holds=f"{sum(bool(a['range_holds']) for a in cups)}/{len(cups)}",
               baseline_worst_cc=worst_abs(a["fitted_error_cc"] for a in cups),
               true_lr_cc_range=[min(a["true_lr_cc"] for a in cups), max(a["true_lr_cc"] for a in cups)],
               perfect_front_whole_grid_pct=[share(a, "whole_grid") for a in cups],
               perfect_front_footprint_pct=[share(a, "footprint") for a in cups],
               measured_vs_perfect_on_seen_cells_cc=[
                   None if not a["front_lr_cc"] else
                   a["front_lr_cc"]["measured_seen_cells"] - a["front_lr_cc"]["seen_cells"] for a in cups],
               over=f"{sum(a['new_error_cc'] is not None for a in cups)}/{len(cups)} scenes of one-sided cup "
                    "bodies: |measured − true (left − right)| / |true|; perfect_front: the true surface seen "
                    "along her found anterior axis, left less mirrored right, % of the true difference, over "
                    "the whole grid (no wall) and inside the measured footprint (above the measured wall); "
                    "measured_vs_perfect: the measure's left − right less the perfect view's, on the "
                    "footprint's cells the camera saw; range_holds: scenes whose true difference lies within the "
                    "measured one's stated range (both ±, and each breast's unseen outer side)"),
        figure("single_scan_change_worst_pct", worst_abs(v["new_pct_of_true"] - 100.0 for v in visits
                                                          if v["new_pct_of_true"] is not None), None,
               worst_abs(v["fitted_pct_of_true"] - 100.0 for v in visits if v["fitted_pct_of_true"] is not None), "%",
               shares_of_true_pct=[v["new_pct_of_true"] for v in visits],
               baseline_shares_of_true_pct=[v["fitted_pct_of_true"] for v in visits],
               over=f"{len(visits)} breasts of 2 women whose cup changed between two visits (true change "
                    f"{min(v['true_cc'] for v in visits):.0f}–{max(v['true_cc'] for v in visits):.0f} cc), one "
                    "scan each, each on its own wall: |measured change − true| / true; no target (a follow-up is "
                    "measured on one wall, `--wall-from`: bench_realistic)") if visits else None,
        figure("seconds_per_torso_median", median_of(measure_s), None, median_of(fit_s), "s",
               over="measure_breasts per scene (both breasts) vs fit_scan per breast (baseline); no target"),
    ]
    return [{"benchmark": "bench_volume_repeat", **f} for f in figures if f is not None]


# --- printing --------------------------------------------------------------------------------
def pct(v, digits=1) -> str:
    return "–" if v is None else f"{v:.{digits}f} %"


def mm(v) -> str:
    return "–" if v is None else f"{v:.1f}"


def cc(v, sign=False) -> str:
    return "–" if v is None else (f"{v:+.0f}" if sign else f"{v:.0f}")


def print_tables(console: Console, results, resc, sym, asym, figures) -> None:
    table = new_table("bench_volume_repeat 1 — re-scans: volumes (cc) of each breast, new (skin) vs fitted model",
                      ("body", "side", "new volumes ± median", "CV", "spread", "honest", "fitted volumes", "CV",
                       "spread"),
                      "CV: stdev / mean; spread: (max − min) / median; honest: scans whose volume lies within its "
                      "stated ± of the breast's median volume.")
    for r in resc:
        table.add_row(r["body"], r["side"],
                      " ".join(cc(v) for v in r["new_cc"]) + (f"  ±{statistics.median(r['uncertainty_cc']):.0f}"
                                                             if r["uncertainty_cc"] else ""),
                      pct(r["new_cv_pct"]), pct(r["new_spread_pct"]), f"{r['honest']}/{r['measured']}",
                      " ".join(cc(v) for v in r["fitted_cc"]), pct(r["fitted_cv_pct"]), pct(r["fitted_spread_pct"]))
    console.print(table)
    table = new_table("bench_volume_repeat 1 — re-scans: nipple and footprint spreads (mm)",
                      ("body", "side", "nipple", "nipple, true frame", "frame alone", "notch", "up axis",
                       "left axis", "footprint", "footprint, true frame", "width: skin", "width: model"),
                      "nipple: the largest distance of a scan's nipple from the scans' mean, in the found body frame; "
                      "true frame: the same nipples in MakeHuman's frame (ingest alone); frame alone: the true nipple "
                      "in the found frames; notch: the found sternal notch's spread in MakeHuman's frame; up / left axis: "
                      "the found axes' largest angle from their mean there (°); footprint: mean x–y distance from "
                      "the median-volume scan's curve; width: max − min of her width on her skin, and of the fitted "
                      "model's.")
    for r in resc:
        table.add_row(r["body"], r["side"], mm(r["nipple_spread_mm"]), mm(r["nipple_spread_true_frame_mm"]),
                      mm(r["frame_spread_mm"]), mm(r["notch_spread_mm"]), mm(r["up_spread_deg"]),
                      mm(r["left_spread_deg"]), mm(r["footprint_spread_mm"]), mm(r["footprint_spread_true_frame_mm"]),
                      mm(r["new_width_spread_mm"]), mm(r["fitted_width_spread_mm"]))
    console.print(table)
    table = new_table("bench_volume_repeat 2 — symmetric bodies: |left − right| / mean",
                      ("body", "view", "true L − R", "new L / R (cc)", "new", "fitted L / R (cc)", "fitted"))
    for s in sym:
        n, f = s["new_cc"], s["fitted_cc"]
        table.add_row(s["body"], s["view"], f"{s['true_lr_cc']:+.1f} cc",
                      f"{cc(n.get('left'))} / {cc(n.get('right'))}", pct(s["new_pct"]),
                      f"{cc(f.get('left'))} / {cc(f.get('right'))}", pct(s["fitted_pct"]))
    console.print(table)
    table = new_table("bench_volume_repeat 3 — asymmetry: measured left − right vs the true half-body difference (cc)",
                      ("kind", "body", "view", "true L − R", "new L − R", "error", "fitted L − R", "error"))
    for a in asym:
        table.add_row(a["kind"], a["body"], a["view"], cc(a["true_lr_cc"], True), cc(a["new_lr_cc"], True),
                      cc(a["new_error_cc"], True), cc(a["fitted_lr_cc"], True), cc(a["fitted_error_cc"], True))
    console.print(table)
    failed = [(r.shot.set, r.shot.body, r.shot.label, stage, msg) for r in results for stage, msg in r.errors]
    if failed:
        table = new_table("bench_volume_repeat — errors raised", ("set", "body", "view", "stage", "message"))
        for row in failed:
            table.add_row(*row[:4], row[4][:120])
        console.print(table)
    print_figures(figures, console, "bench_volume_repeat — figures (measure_breasts; baseline: the fitted model, "
                                    "same run)")


def main() -> None:
    console = Console(width=200)
    start, load_start = time.perf_counter(), os.getloadavg()
    results = []
    with threadpool_limits(1, "blas"):      # as `breastplan fit` runs
        for shot in shots():
            r = run_scene(shot)
            results.append(r)
            new = " ".join(f"{s[0].upper()} {r.new[s]['volume_cc']:.0f}±{r.new[s]['uncertainty_cc']:.0f}"
                           for s in SIDES if s in r.new)
            fit = " ".join(f"{s[0].upper()} {r.fitted[s]:.0f}" for s in SIDES if s in r.fitted)
            console.log(f"{shot.set} {shot.body} {shot.label}: new {new or '–'}; fitted {fit or '–'}; "
                        f"nipples {' '.join(f'{v:.1f}' for v in r.nipple_error_mm.values())} mm"
                        + (f"; {len(r.errors)} error(s)" if r.errors else "")
                        + f" ({sum(v for k, v in r.seconds.items() if k != 'fit_per_breast'):.1f} s)")
    resc, sym, asym = rescan_rows(results), symmetric_rows(results), asymmetry_rows(results)
    figures = figures_of(resc, sym, asym, results)
    print_tables(console, results, resc, sym, asym, figures)
    wall = time.perf_counter() - start
    console.print(f"Wall time {wall:.0f} s for {len(results)} scenes; load average {load_start[0]:.1f} → "
                  f"{os.getloadavg()[0]:.1f}.")
    for f in figures:
        print(json.dumps(rounded(f)))
    print(json.dumps(rounded({
        "benchmark": "bench_volume_repeat", "frames": FRAMES, "resolution": RESOLUTION, "rescans": RESCANS,
        "targets": TARGETS, "figures": {f["figure"]: f for f in figures},
        "met": all(f["met"] for f in figures if f["target"] is not None),
        "rescan_breasts": [{k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in r.items()} for r in resc],
        "symmetric": sym, "asymmetry": asym,
        "scenes": [json.loads(json.dumps(r.as_dict(), default=lambda x: x.tolist())) for r in results],
        "loadavg_start": load_start, "loadavg_end": os.getloadavg(), "wall_s": wall})))


if __name__ == "__main__":
    main()
