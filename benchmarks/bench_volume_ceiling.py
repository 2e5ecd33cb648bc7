"""How much of a MakeHuman cup or firmness change a breast measured on its own chest can hold at best.

bench_realistic's cup and firmness pairs compare the fitted volume change of a breast with the change
of the half-body volume: everything MakeHuman's target moves, the chest around the breast included.
This script measures, on the same pairs and views, what the exact body surfaces give when each
breast is measured as breastplan measures it — over the chest wall ingest found under it, within
the region ingest cropped — so that the fit's shortfall can be told from the truth's reach.

Per pair × view × side, both bodies are rendered and ingested (`ingest_frames`, automatic
isolation), and fitted (`fit_scan`, on the chest wall ingest found). On a 2 mm grid of the first body's
viewing frame, each body's exact front surface (open3d ray casting of its mesh: the skin a camera in
front sees at best, an overhang's underside hidden) and each body's ingested chest wall
(`ChestWall.beneath`, along that frame's view axis) give:

* own walls: Σ over the body's own crop (grid cells within 3 mm of its ingested points) of the
  surface's height over its own wall; the change hi − lo;
* one wall: the same over the second body's crop (cup; for firmness: over both crops, as the
  softer breast hangs lower), both bodies over the first one's wall (the smaller or softer breast:
  the chest as it was before the change);
* wall lift: how much higher the second breast's wall lies, mean over its crop, mm;
* fitted: the fitted volume change (bench_realistic's figures 4 and 5);
* fitted, one wall: the same, the second breast fitted down to the first one's wall (taken into
  its viewing frame through the true body poses by `ingest.follow_up.carry_wall`): what the fit
  holds when the wall does not move;
* follow-up: the same with the first breast's wall carried over as `fit --wall-from` carries it
  (`ingest.follow_up.carried_wall`: the two chests registered, no truth used), and the
  registration's error: the largest distance, over the second body's chest around the breast,
  between where the registration and the true poses put its points (mm);
* follow-up, another view: the same, the second body seen from the pair's next view (another
  pose and camera, as a second visit is), against the first body in this view.

Cup changes are given in % of the true change; firmness changes, small against the volume, by
their error |change − true change| in % of the mean fitted volume (bench_realistic's scale).

Nothing is asserted; one JSON line per case, and lines for two figures: the follow-up's worst
cup error (≤ 10 % of the true change, as for bench_realistic's cup pairs; baseline: the fitted
change with each breast on its own wall), and how far the exact surfaces on one wall make the
firmness pairs' volumes differ (against bench_realistic's ≤ 5 %; baseline: the true difference),
then a summary line.

Run:  .venv/bin/python benchmarks/bench_volume_ceiling.py     (about three minutes)
"""
from __future__ import annotations

import json
import statistics
from dataclasses import replace

import numpy as np
import open3d as o3d
from rich.console import Console
from scipy.spatial import cKDTree
from threadpoolctl import threadpool_limits

from breastplan import transform_points
from breastplan.case import Provenance
from breastplan.fitting.breast_fit import fit_scan
from breastplan.ingest.follow_up import carried_wall, carry_wall, chest_around_breast
from breastplan.ingest.pipeline import ingest_frames
from breastplan.scenes.realistic import make_body_scene
from breastplan.ingest.recording import DepthFrames
from breastplan.ingest.scan import depth_source, scan_record
from breastplan.options import IngestOptions

from bench_realistic import FRAMES, PAIRS, VIEWS, new_table

CELL_MM, CROP_MM, HALF_WIDTH_MM = 2.0, 3.0, 220.0


def front_depth(vertices: np.ndarray, faces: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """z of the first surface a ray along +z meets above each (x, y) (viewing frame, mm); NaN where none."""
    rays = o3d.t.geometry.RaycastingScene()
    rays.add_triangles(o3d.core.Tensor(vertices.astype(np.float32)), o3d.core.Tensor(faces.astype(np.uint32)))
    origin = np.zeros((len(xy), 6), np.float32)
    origin[:, :2], origin[:, 2], origin[:, 5] = xy, -5000.0, 1.0
    t = rays.cast_rays(o3d.core.Tensor(origin))["t_hit"].numpy().astype(float)
    return np.where(np.isfinite(t), t - 5000.0, np.nan)


def member(pair, view: int, m: int, side: str) -> dict:
    pose, camera = VIEWS[view]
    scene = make_body_scene(pair.body(m, pose), camera)
    options = IngestOptions(side=side)
    frames = DepthFrames(scene.frames(FRAMES, view), scene.camera.K, "synthetic")
    ingested = ingest_frames(frames, options)
    with threadpool_limits(1, "blas"):
        fit = fit_scan(ingested)
    view_from_body = ingested.input_to_view @ scene.camera_from_body
    view_from_breast = ingested.input_to_view @ np.linalg.inv(ingested.input_to_breast)
    return {"scene": scene, "ingested": ingested, "fit": fit, "view_from_body": view_from_body,
            "scan": scan_record(ingested, depth_source(frames), options, Provenance()),
            "crop_view": transform_points(view_from_breast, ingested.points), "half_cc": scene.body.half_volumes_cc()[side]}


def case(pair, view: int, side: str) -> dict:
    """One pair × view × side: the changes hi − lo of every measure (cc), and what they are taken against."""
    lo, hi = (member(pair, view, m, side) for m in (0, 1))
    frame = lo["view_from_body"]                                  # the common frame: the first body's viewing frame
    centre = lo["crop_view"][:, :2].mean(0)
    grid = np.mgrid[-HALF_WIDTH_MM:HALF_WIDTH_MM:CELL_MM, -HALF_WIDTH_MM:HALF_WIDTH_MM:CELL_MM].reshape(2, -1).T + centre
    for b in (lo, hi):
        to_frame = frame @ np.linalg.inv(b["view_from_body"])      # its viewing frame → the common one
        b["surface"] = front_depth(transform_points(frame, b["scene"].body.vertices), b["scene"].body.faces, grid)
        b["wall"] = b["ingested"].chest_wall.beneath(to_frame, grid)          # its wall, along the common view axis
        b["crop"] = cKDTree(transform_points(to_frame, b["crop_view"])[:, :2]).query(grid)[0] < CROP_MM

    def held(surface, wall, where) -> float:                      # cc of surface over wall (z away from the viewer)
        return float(np.nansum(np.clip(wall - surface, 0.0, None)[where]) * CELL_MM ** 2 / 1000.0)
    both = lo["crop"] | hi["crop"]
    on_lo = carry_wall(lo["ingested"].chest_wall, hi["view_from_body"] @ np.linalg.inv(frame), centre)
    follow_wall, registration = carried_wall(lo["scan"], hi["scan"])
    chest = chest_around_breast(hi["scan"])
    truth = lo["scene"].camera_from_body @ np.linalg.inv(hi["scene"].camera_from_body)   # hi's camera → lo's
    registration_error = np.linalg.norm(transform_points(registration.earlier_from_later, chest)
                                        - transform_points(truth, chest), axis=1).max()
    views = pair.views
    elsewhere = member(pair, views[(views.index(view) + 1) % len(views)], 1, side)   # the second body, next view
    across_wall, _ = carried_wall(lo["scan"], elsewhere["scan"])
    with threadpool_limits(1, "blas"):
        hi_on_lo = fit_scan(replace(hi["ingested"], chest_wall=on_lo))
        follow_up = fit_scan(replace(hi["ingested"], chest_wall=follow_wall))
        across = fit_scan(replace(elsewhere["ingested"], chest_wall=across_wall))
    return {"pair": pair.name, "view": view, "side": side, "true_cc": hi["half_cc"] - lo["half_cc"],
            "mean_fitted_cc": 0.5 * (hi["fit"].volume_cc + lo["fit"].volume_cc),
            "fitted_cc": hi["fit"].volume_cc - lo["fit"].volume_cc,
            "fitted_one_wall_cc": hi_on_lo.volume_cc - lo["fit"].volume_cc,
            "follow_up_cc": follow_up.volume_cc - lo["fit"].volume_cc,
            "follow_up_other_view_cc": across.volume_cc - lo["fit"].volume_cc,
            "own_wall_cc": held(hi["surface"], hi["wall"], hi["crop"]) - held(lo["surface"], lo["wall"], lo["crop"]),
            "one_wall_cc": held(hi["surface"], lo["wall"], hi["crop"]) - held(lo["surface"], lo["wall"], hi["crop"]),
            "one_wall_both_crops_cc": held(hi["surface"], lo["wall"], both) - held(lo["surface"], lo["wall"], both),
            "registration_error_mm": float(registration_error),
            "wall_lift_mm": float(np.nanmean((lo["wall"] - hi["wall"])[hi["crop"]]))}


CUP = {"fitted": "fitted_cc", "fitted, one wall": "fitted_one_wall_cc", "follow-up": "follow_up_cc",
       "follow-up, another view": "follow_up_other_view_cc", "exact surfaces, own walls": "own_wall_cc",
       "exact surfaces, one wall": "one_wall_cc"}
"""The cup table's changes, in % of the true change."""
FIRMNESS = {"fitted": "fitted_cc", "fitted, one wall": "fitted_one_wall_cc", "follow-up": "follow_up_cc",
            "follow-up, another view": "follow_up_other_view_cc", "exact surfaces, own walls": "own_wall_cc",
            "exact surfaces, one wall": "one_wall_both_crops_cc"}
"""The firmness table's changes: their error, |change − true change|, in % of the mean fitted volume."""


def pct_of_true(c: dict, key: str) -> float:
    return 100.0 * c[key] / c["true_cc"]


def error_of_mean(c: dict, key: str) -> float:
    return 100.0 * abs(c[key] - c["true_cc"]) / c["mean_fitted_cc"]


def cup_table(cases: list[dict]):
    table = new_table("bench_volume_ceiling — a cup change measured on the breast's own chest, in % of the true change",
                      ("pair", "view", "side", "true change", *CUP, "registration error", "wall lift"),
                      "own walls: each body's exact surface over the chest wall ingest found under it, within its "
                      "crop; one wall: both over the smaller breast's wall, within the larger one's crop (fitted, "
                      "one wall: the larger breast fitted down to it; follow-up: down to it as registered; "
                      "another view: the larger body seen from the pair's next view).")
    for c in cases:
        table.add_row(c["pair"], str(c["view"]), c["side"], f"{c['true_cc']:+.0f} cc",
                      *(f"{pct_of_true(c, k):.0f} %" for k in CUP.values()), f"{c['registration_error_mm']:.1f} mm",
                      f"{c['wall_lift_mm']:+.1f} mm")
    return table


def firmness_table(cases: list[dict]):
    table = new_table("bench_volume_ceiling — a firmness change (0 → 1): |change − true change|, in % of the mean "
                      "fitted volume", ("pair", "view", "side", "true change", "true |Δ|", *FIRMNESS,
                                        "registration error"),
                      "true |Δ|: the true change in % of the same mean (what 'volumes differ by ≤ 5 %' asks of a "
                      "measure that holds the truth). Exact surfaces: the bodies' exact front surfaces (what a camera "
                      "in front can see at best) over the walls ingest found, within their own crops, or over the "
                      "softer breast's wall (firmness 0), within both crops.")
    for c in cases:
        table.add_row(c["pair"], str(c["view"]), c["side"], f"{c['true_cc']:+.0f} cc",
                      f"{100 * abs(c['true_cc']) / c['mean_fitted_cc']:.1f} %",
                      *(f"{error_of_mean(c, k):.1f} %" for k in FIRMNESS.values()), f"{c['registration_error_mm']:.1f} mm")
    return table


def main() -> None:
    console = Console(width=170)
    cases = [case(pair, view, side) for pair in PAIRS for view in pair.views for side in ("left", "right")]
    cups = [c for c in cases if c["pair"].startswith("cup")]
    firms = [c for c in cases if c["pair"].startswith("firm")]
    console.print(cup_table(cups))
    console.print(firmness_table(firms))
    for c in cases:
        print(json.dumps({k: round(v, 2) if isinstance(v, float) else v for k, v in c.items()}))
    summary = {}
    for name in sorted({c["pair"] for c in cases}):
        mine = [c for c in cases if c["pair"] == name]
        if name.startswith("cup"):
            summary[name] = {k: round(statistics.median(pct_of_true(c, k) for c in mine), 1) for k in CUP.values()}
        else:
            summary[name] = {k: round(max(error_of_mean(c, k) for c in mine), 1) for k in FIRMNESS.values()}
        summary[name]["wall_lift_mm"] = round(statistics.median(c["wall_lift_mm"] for c in mine), 1)
    worst = {k: max(abs(pct_of_true(c, k) - 100.0) for c in cups)
             for k in ("follow_up_cc", "follow_up_other_view_cc", "fitted_cc")}
    print(json.dumps({"figure": "follow_up_cup_change_error_worst", "value": round(worst["follow_up_cc"], 2),
                      "target": 10.0, "baseline": round(worst["fitted_cc"], 2), "unit": "%",
                      "met": worst["follow_up_cc"] <= 10.0, "baseline_is": "each breast on its own wall",
                      "another_view_worst": round(worst["follow_up_other_view_cc"], 2),
                      "another_view_median": round(statistics.median(
                          abs(pct_of_true(c, "follow_up_other_view_cc") - 100.0) for c in cups), 2),
                      "registration_error_worst_mm": round(max(c["registration_error_mm"] for c in cups), 2)}))
    exact = max(abs(c["one_wall_both_crops_cc"]) / c["mean_fitted_cc"] * 100.0 for c in firms)
    print(json.dumps({"figure": "firmness_exact_surfaces_volume_difference_worst", "value": round(exact, 2),
                      "target": 5.0, "met": exact <= 5.0, "unit": "%",
                      "baseline": round(max(abs(c["true_cc"]) / c["mean_fitted_cc"] * 100.0 for c in firms), 2),
                      "baseline_is": "the true difference (half-body volumes), in % of the same mean",
                      "change_error_worst": round(max(error_of_mean(c, "one_wall_both_crops_cc") for c in firms), 2)}))
    print(json.dumps({"benchmark": "bench_volume_ceiling", "summary": summary, "cases": len(cases)}))


if __name__ == "__main__":
    main()
