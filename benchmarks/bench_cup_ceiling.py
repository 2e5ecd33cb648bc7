"""How much of a MakeHuman cup change a breast measured on its own chest can hold at best.

bench_realistic's cup pairs compare the fitted volume change of a breast with the change of the
half-body volume: everything MakeHuman's cup target moves, the chest around the breast included.
This script measures, on the same pairs and views, what the exact body surfaces give when each
breast is measured as breastplan measures it — over the chest wall ingest found under it, within
the region ingest cropped — so that the fit's shortfall can be told from the truth's reach.

Per cup pair × view × side, both bodies are rendered and ingested (`ingest_frames`, automatic
isolation), and fitted (`fit_scan`, on the chest wall ingest found). On a 2 mm grid of the first body's
viewing frame, each body's exact front surface (open3d ray casting of its mesh) and each body's
ingested chest wall (`ChestWall.beneath`, along that frame's view axis) give:

* own wall: Σ over the body's own crop (grid cells within 3 mm of its ingested points) of the
  surface's height over its own wall; the change hi − lo, in % of the true change;
* one wall: the same over the larger breast's crop, both bodies over the smaller one's wall (the
  chest as it was before the cup grew);
* wall lift: how much higher the larger breast's wall lies, mean over its crop, mm;
* fitted: the fitted volume change (bench_realistic's figure 4), in % of the true change;
* fitted, one wall: the same, the larger breast fitted down to the smaller one's wall (taken into
  the larger body's viewing frame through the true body poses by `ingest.follow_up.carry_wall`):
  what the fit holds when the wall does not move;
* follow-up: the same with the smaller breast's wall carried over as `fit --wall-from` carries it
  (`ingest.follow_up.carried_wall`: the two chests registered, no truth used), and the
  registration's error: the largest distance, over the larger body's chest around the breast,
  between where the registration and the true poses put its points (mm).

Nothing is asserted; one JSON line per case, one for the figure with a target (the follow-up's
worst error, ≤ 10 % of the true change as for bench_realistic's cup pairs; baseline: the fitted
change with each breast on its own wall) and a last summary line.

Run:  .venv/bin/python benchmarks/bench_cup_ceiling.py     (about a minute)
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
from breastplan.case import Provenance, Source
from breastplan.fitting.breast_fit import fit_scan
from breastplan.ingest.follow_up import carried_wall, carry_wall, chest_around_breast
from breastplan.ingest.pipeline import ingest_frames
from breastplan.ingest.realistic import make_body_scene
from breastplan.ingest.recording import DepthFrames
from breastplan.ingest.scan import scan_record
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
    ingested = ingest_frames(DepthFrames(scene.frames(FRAMES, view), scene.camera.K, "synthetic"), options)
    with threadpool_limits(1, "blas"):
        fit = fit_scan(ingested)
    view_from_body = ingested.view_from_camera @ scene.camera_from_body
    view_from_breast = ingested.view_from_camera @ np.linalg.inv(ingested.camera_to_breast)
    return {"scene": scene, "ingested": ingested, "fit": fit, "view_from_body": view_from_body,
            "scan": scan_record(ingested, Source("recording", "synthetic"), options, Provenance()),
            "crop_view": transform_points(view_from_breast, ingested.points), "half_cc": scene.body.half_volumes_cc()[side]}


def case(pair, view: int, side: str) -> dict:
    lo, hi = (member(pair, view, m, side) for m in (0, 1))
    frame = lo["view_from_body"]                                  # the common frame: the smaller breast's viewing frame
    centre = lo["crop_view"][:, :2].mean(0)
    grid = np.mgrid[-HALF_WIDTH_MM:HALF_WIDTH_MM:CELL_MM, -HALF_WIDTH_MM:HALF_WIDTH_MM:CELL_MM].reshape(2, -1).T + centre
    for b in (lo, hi):
        to_frame = frame @ np.linalg.inv(b["view_from_body"])      # its viewing frame → the common one
        b["surface"] = front_depth(transform_points(frame, b["scene"].body.vertices), b["scene"].body.faces, grid)
        b["wall"] = b["ingested"].chest_wall.beneath(to_frame, grid)          # its wall, along the common view axis
        b["crop"] = cKDTree(transform_points(to_frame, b["crop_view"])[:, :2]).query(grid)[0] < CROP_MM

    def held(surface, wall, where) -> float:                      # cc of surface over wall (z away from the viewer)
        return float(np.nansum(np.clip(wall - surface, 0.0, None)[where]) * CELL_MM ** 2 / 1000.0)
    true = hi["half_cc"] - lo["half_cc"]
    own = held(hi["surface"], hi["wall"], hi["crop"]) - held(lo["surface"], lo["wall"], lo["crop"])
    one = held(hi["surface"], lo["wall"], hi["crop"]) - held(lo["surface"], lo["wall"], hi["crop"])
    fitted = hi["fit"].volume_cc - lo["fit"].volume_cc
    on_lo = carry_wall(lo["ingested"].chest_wall, hi["view_from_body"] @ np.linalg.inv(frame), centre)
    follow_wall, registration = carried_wall(lo["scan"], hi["scan"])
    chest = chest_around_breast(hi["scan"])
    truth = lo["scene"].camera_from_body @ np.linalg.inv(hi["scene"].camera_from_body)   # hi's camera → lo's
    registration_error = np.linalg.norm(transform_points(registration.earlier_from_later, chest)
                                        - transform_points(truth, chest), axis=1).max()
    with threadpool_limits(1, "blas"):
        hi_on_lo = fit_scan(replace(hi["ingested"], chest_wall=on_lo))
        follow_up = fit_scan(replace(hi["ingested"], chest_wall=follow_wall))
    return {"pair": pair.name, "view": view, "side": side, "true_change_cc": true, "fitted_pct": 100.0 * fitted / true,
            "fitted_one_wall_pct": 100.0 * (hi_on_lo.volume_cc - lo["fit"].volume_cc) / true,
            "follow_up_pct": 100.0 * (follow_up.volume_cc - lo["fit"].volume_cc) / true,
            "registration_error_mm": float(registration_error),
            "own_wall_pct": 100.0 * own / true, "one_wall_pct": 100.0 * one / true,
            "wall_lift_mm": float(np.nanmean((lo["wall"] - hi["wall"])[hi["crop"]]))}


def main() -> None:
    console = Console(width=150)
    cases = [case(pair, view, side) for pair in PAIRS if pair.varies == "cup" for view in pair.views
             for side in ("left", "right")]
    table = new_table("bench_cup_ceiling — a cup change measured on the breast's own chest, in % of the true change",
                      ("pair", "view", "side", "true change", "fitted", "fitted, one wall", "follow-up",
                       "registration error", "exact surfaces, own walls", "exact surfaces, one wall", "wall lift"),
                      "own walls: each body's exact surface over the chest wall ingest found under it, within its "
                      "crop; one wall: both over the smaller breast's wall, within the larger one's crop (fitted, "
                      "one wall: the larger breast fitted down to it; follow-up: down to it as registered).")
    for c in cases:
        table.add_row(c["pair"], str(c["view"]), c["side"], f"{c['true_change_cc']:+.0f} cc", f"{c['fitted_pct']:.0f} %",
                      f"{c['fitted_one_wall_pct']:.0f} %", f"{c['follow_up_pct']:.0f} %",
                      f"{c['registration_error_mm']:.1f} mm",
                      f"{c['own_wall_pct']:.0f} %", f"{c['one_wall_pct']:.0f} %", f"{c['wall_lift_mm']:+.1f} mm")
    console.print(table)
    for c in cases:
        print(json.dumps({k: round(v, 2) if isinstance(v, float) else v for k, v in c.items()}))
    summary = {}
    for name in ("cup-1", "cup-2"):
        mine = [c for c in cases if c["pair"] == name]
        summary[name] = {k: round(statistics.median(c[k] for c in mine), 1)
                         for k in ("fitted_pct", "fitted_one_wall_pct", "follow_up_pct", "own_wall_pct", "one_wall_pct",
                                   "wall_lift_mm")}
    worst = {k: max(abs(c[k] - 100.0) for c in cases) for k in ("follow_up_pct", "fitted_pct")}
    print(json.dumps({"figure": "follow_up_cup_change_error_worst", "value": round(worst["follow_up_pct"], 2),
                      "target": 10.0, "baseline": round(worst["fitted_pct"], 2), "unit": "%",
                      "met": worst["follow_up_pct"] <= 10.0, "baseline_is": "each breast on its own wall",
                      "registration_error_worst_mm": round(max(c["registration_error_mm"] for c in cases), 2)}))
    print(json.dumps({"benchmark": "bench_cup_ceiling", "medians": summary, "cases": len(cases)}))


if __name__ == "__main__":
    main()
