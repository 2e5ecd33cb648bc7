"""A follow-up visit's change of volume, measured three ways, against the truth.

Two women whose cup changed between two visits (bench_realistic's cup pairs: cup 0.3 → 0.8, and 0.2 →
1.0 on a heavy body with asymmetric breasts), the first visit scanned from 650 mm in front of a wall,
the second from the same camera and from another (700 mm, pitch 9°, yaw −6°, no wall). Each visit is
ingested (`ingest_frames`, both sides, as `plan` does), and per breast the change is measured:

* **on her skin, on the earlier wall** (`plan.breast_volume.change_on_earlier_wall`, what `plan
  --wall-from` reports as `skin_volume_change_cc`): the second torso registered onto the first around
  the breast (`ingest.follow_up.carried_wall`), its skin measured on the first visit's chest wall, inside
  the first footprint grown over what now rises;
* **on her skin, each visit on its own wall** (`skin_own_walls_change_cc`): `measure_breasts` of each;
* **the fitted model on the earlier wall** (`volume_change_cc`, the baseline): the second breast fitted
  down to the first visit's wall carried over, minus the first fitted down to its own.

Truth: the exact half-body volumes' change. Target (for the change on the earlier wall): within 7 % of
the true change. The last line is the JSON summary.

A second truth, to explain the first: the true change INSIDE the footprint the follow-up measure uses
(the earlier footprint grown as `change_on_earlier_wall` grows it). The two bodies share their mesh
vertex for vertex, so the change splits exactly over the triangles (`swept_volumes_mm3`); a triangle
counts when its earlier centroid, in the earlier visit's measured body frame, falls on a cell of that
footprint (projected along her anterior axis, the wall's normal there) no more than BEHIND_WALL_MM behind
the earlier wall (the back, under the same cells, is left out; it moves by about 1 cc). The share of the
half-body change outside the footprint is what no breast measure should count: the claim that MakeHuman's
cup target thickens the chest around the breast, measured (it comes to about 1 %, not the 7–8 % the
change on the earlier wall misses by). With BEHIND_WALL_MM = 0 instead (triangles whose earlier centroid
lies in front of the earlier wall only) the truth inside the footprint drops by about 10 %: front-facing
skin of the lower pole, up to 30 mm behind the fitted wall, sweeps that much.

A third, to say what any measure of her front can reach: a perfect front view of both visits' true
surfaces (bench_volume_repeat's `true_front_mm`: every cell seen along her anterior axis, no perspective,
the later body placed as the earlier one stood), measured as the measure does (heights above the earlier
wall, those above 0, summed over the same grown footprint), and the measure's change less that view's on
the cells the later scan saw; and that view's change summed over her whole half grid, unclipped (no wall,
no footprint). A front view counts the air under a hanging breast as tissue, so a breast
that grows down into that air adds less than it grew.

Run:  .venv/bin/python benchmarks/bench_follow_up.py     (about 1 minute)
"""
from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
from rich.console import Console
from threadpoolctl import threadpool_limits

from breastplan import transform_points
from breastplan.case import Provenance
from breastplan.fitting.breast_fit import fit_scan
from breastplan.ingest.follow_up import carried_wall
from breastplan.scenes.makehuman import BodyOptions, make_body
from breastplan.ingest.pipeline import ingest_frames
from breastplan.scenes.realistic import BodyScene, CameraOptions, camera_pose
from breastplan.ingest.recording import DepthFrames
from breastplan.ingest.scan import depth_source, scan_record
from breastplan.options import SIDES, IngestOptions
from breastplan.plan.breast_volume import (CELL_MM, BreastVolumes, change_on_earlier_wall, grown_footprint,
                                          measure_breasts)

from bench_realistic import new_table
from bench_volume_repeat import true_front_mm

TARGET_PCT = 7.0
WOMEN = {"cup 0.3 → 0.8": (dict(pose="arms-down"), 0.3, 0.8),
         "cup 0.2 → 1.0": (dict(firmness=0.7, weight=0.8, muscle=0.4, modifiers={"asymmetry": 0.8},
                                pose="hands-on-hips"), 0.2, 1.0)}
FIRST = CameraOptions(650.0, 5.0, 0.0)
SECOND = {"same camera": FIRST, "another camera": CameraOptions(700.0, 9.0, -6.0, wall_mm=None)}
BEHIND_WALL_MM = 30.0
"""A triangle under the footprint counts for the inside-footprint truth up to this far behind the earlier wall."""


def visit(body: BodyOptions, camera: CameraOptions, seed: int):
    """(side → Scan, the measured volumes, the body made, its scene's camera_from_body (4, 4) mm)."""
    made = make_body(body)
    scene = BodyScene(made, camera, camera_pose(0.5 * (made.nipples["left"] + made.nipples["right"]), camera))
    frames = DepthFrames(scene.frames(8, seed), camera.K, "bench")
    scans = {s: scan_record(ingest_frames(frames, IngestOptions(s)), depth_source(frames), IngestOptions(s),
                            Provenance()) for s in SIDES}
    first = scans["left"]
    measured = measure_breasts(first.body, {s: scans[s].nipple_camera_mm for s in SIDES})
    return scans, measured, made, scene.camera_from_body


def swept_volumes_mm3(before: np.ndarray, after: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) the signed volume (mm³, > 0 outward) each triangle sweeps between `before` and `after` ((N, 3) mm,
    one frame, one topology): its prism closed by the before triangle reversed, the after triangle and three
    side quads, each split along the diagonal from its lower-index vertex's before to its higher-index
    vertex's after, so that neighbours' side faces cancel: over a closed, outward mesh they sum to its change."""
    p0, p1 = before[faces], after[faces]
    p0, p1 = p0 - p0[:, :1], p1 - p0[:, :1]                     # each prism about its own corner: no round-off
    det = lambda a, b, c: np.einsum("fi,fi->f", a, np.cross(b, c))
    vol = det(*p1.transpose(1, 0, 2)) - det(*p0.transpose(1, 0, 2))
    for i, j in ((0, 1), (1, 2), (2, 0)):                        # the quad (i0, j0, j1, i1) of edge i → j
        a, b, c, d = p0[:, i], p0[:, j], p1[:, j], p1[:, i]
        vol += np.where(faces[:, i] < faces[:, j], det(a, b, c) + det(a, c, d), det(a, b, d) + det(b, c, d))
    return vol / 6.0


def under_footprint(points_mm: np.ndarray, earlier: BreastVolumes, footprint: np.ndarray) -> np.ndarray:
    """(P,) whether each point (earlier visit's input frame, mm) projects along her anterior axis onto a cell
    of `footprint` ((nx, ny) on the earlier cells) and lies no more than BEHIND_WALL_MM behind its wall."""
    cells, p = earlier.cells, transform_points(earlier.body_from_input, points_mm)
    ij = np.floor((p[:, :2] - [cells.x[0], cells.y[0]]) / CELL_MM + 0.5).astype(int)
    ok = (ij >= 0).all(1) & (ij < footprint.shape).all(1)
    i, j = np.where(ok, ij.T, 0)
    return ok & footprint[i, j] & (p[:, 2] > cells.wall_mm[i, j] - BEHIND_WALL_MM)


def front_cc(height_mm: np.ndarray, mask: np.ndarray) -> float:
    """cc of the heights (mm, NaN: nothing there) above 0 over `mask`'s cells, as the measure sums them."""
    return float(np.clip(np.nan_to_num(height_mm), 0.0, None)[mask].sum()) * CELL_MM ** 2 / 1000.0


def main() -> None:
    console = Console(width=200)
    rows = []
    for woman, (base, lo, hi) in WOMEN.items():
        then, measured_then, made_then, camera_from_body = visit(BodyOptions(cup=lo, **base), FIRST, 1)
        truth_then = made_then.half_volumes_cc()
        centroids_body = made_then.vertices[made_then.faces].mean(1)                   # MakeHuman's body frame, mm
        centroids = transform_points(camera_from_body, centroids_body)                # the earlier input frame, mm
        cells = measured_then.cells
        front_then = true_front_mm(measured_then, BodyScene(made_then, FIRST, camera_from_body)) - cells.wall_mm
        front_now = None
        for how, camera in SECOND.items():
            now, measured_now, made_now, _ = visit(BodyOptions(cup=hi, **base), camera, 2)
            if front_now is None:              # the later body placed as the earlier one stood: the same mesh frame
                front_now = true_front_mm(measured_then, BodyScene(made_now, FIRST, camera_from_body)) - cells.wall_mm
            truth_now = made_now.half_volumes_cc()
            swept = swept_volumes_mm3(made_then.vertices, made_now.vertices, made_then.faces) / 1000.0    # cc
            half = {s: float(swept[np.sign(centroids_body[:, 0]) == sign].sum())
                    for s, sign in zip(SIDES, (1, -1))}
            console.log(f"{woman}: check: the triangles' swept volumes sum to {swept.sum():.3f} cc, the body's change "
                        f"is {sum(truth_now.values()) - sum(truth_then.values()):.3f} cc; by side (centroid's X) "
                        + ", ".join(f"{s} {half[s]:.3f} vs {truth_now[s] - truth_then[s]:.3f}" for s in SIDES))
            for side in SIDES:
                wall, registration = carried_wall(then[side], now[side])
                before, after = change_on_earlier_wall(measured_then, now[side].torso_camera,
                                                       registration.earlier_from_later, side)
                skin_now, grown_cells = grown_footprint(measured_then, now[side].torso_camera,
                                                        registration.earlier_from_later)
                grown = replace(cells, footprint=grown_cells)
                foot = grown.side(side)
                seen = foot & skin_now.seen
                half = ((cells.x > 0) if side == "left" else (cells.x < 0))[:, None] & np.ones_like(foot)
                with threadpool_limits(1, "blas"):
                    model = fit_scan(replace(now[side], chest_wall=wall)).volume_cc - fit_scan(then[side]).volume_cc
                true = truth_now[side] - truth_then[side]
                inside = float(swept[under_footprint(centroids, measured_then, grown.side(side))].sum())
                inside_earlier = float(swept[under_footprint(centroids, measured_then,
                                                             measured_then.cells.side(side))].sum())
                rows.append({"woman": woman, "second": how, "side": side, "true_cc": true,
                             "true_in_footprint_cc": inside, "true_in_earlier_footprint_cc": inside_earlier,
                             "outside_footprint_pct": 100 * (1 - inside / true),
                             "skin_earlier_wall_cc": after - before,
                             "skin_own_walls_cc": measured_now.sides[side].volume_cc - measured_then.sides[side].volume_cc,
                             "model_earlier_wall_cc": model, "registration_rms_mm": registration.rms_mm,
                             "perfect_front_cc": front_cc(front_now, foot) - front_cc(front_then, foot),
                             "perfect_front_half_grid_cc": float(np.nansum((front_now - front_then)[half]))
                             * CELL_MM ** 2 / 1000.0,
                             "measured_less_perfect_on_seen_cc":
                                 front_cc(skin_now.height_mm, seen) - front_cc(cells.height_mm, seen)
                                 - front_cc(front_now, seen) + front_cc(front_then, seen)})
                console.log(f"{woman}, {how}, {side}: true {true:.0f} cc ({inside:.0f} inside the footprint), "
                            f"on her skin {after - before:.0f}")
    table = new_table("bench_follow_up — a change between two visits, as a share of the true change",
                      ("woman", "second visit", "side", "true cc", "skin, earlier wall", "skin, own walls",
                       "model, earlier wall (baseline)", "true in footprint cc", "outside footprint",
                       "skin, earlier wall: error vs half-body", "error vs in footprint",
                       "perfect front view: error vs half-body", "measured less perfect, seen cells"),
                      "true cc: the half-body change; in footprint: the part of it under the earlier footprint "
                      "grown as the measure grows it; perfect front view: both visits' true surfaces seen along "
                      "her anterior axis, on the same wall and footprint")
    for r in rows:
        table.add_row(r["woman"], r["second"], r["side"], f"{r['true_cc']:.0f}",
                      *(f"{100 * r[k] / r['true_cc']:.0f} %" for k in ("skin_earlier_wall_cc", "skin_own_walls_cc",
                                                                      "model_earlier_wall_cc")),
                      f"{r['true_in_footprint_cc']:.0f}", f"{r['outside_footprint_pct']:.1f} %",
                      *(f"{100 * r['skin_earlier_wall_cc'] / r[k] - 100:+.1f} %" for k in ("true_cc",
                                                                                           "true_in_footprint_cc")),
                      f"{100 * r['perfect_front_cc'] / r['true_cc'] - 100:+.1f} %",
                      f"{r['measured_less_perfect_on_seen_cc']:+.1f} cc")
    console.print(table)
    worst = {k: max(abs(100 * r[k] / r["true_cc"] - 100) for r in rows)
             for k in ("skin_earlier_wall_cc", "skin_own_walls_cc", "model_earlier_wall_cc", "perfect_front_cc",
                       "perfect_front_half_grid_cc")}
    worst_inside = max(abs(100 * r["skin_earlier_wall_cc"] / r["true_in_footprint_cc"] - 100) for r in rows)
    print(f"target ({TARGET_PCT:g} %, against the half-body change): worst {worst['skin_earlier_wall_cc']:.1f} %; "
          f"explanatory, against the change inside the footprint: worst {worst_inside:.1f} %; a perfect front view "
          f"on the same wall and footprint: worst {worst['perfect_front_cc']:.1f} %, over her whole half grid "
          f"(no wall, no footprint): worst {worst['perfect_front_half_grid_cc']:.1f} %")
    print(json.dumps({"benchmark": "bench_follow_up", "figure": "follow_up_change_error_worst_pct",
                      "value": round(worst["skin_earlier_wall_cc"], 1), "target": TARGET_PCT,
                      "met": worst["skin_earlier_wall_cc"] <= TARGET_PCT,
                      "in_footprint_worst_pct": round(worst_inside, 1),
                      "in_footprint_is": "against the true change inside the earlier footprint grown as the measure "
                                         "grows it (explanatory; the target is judged against the half-body change)",
                      "perfect_front_worst_pct": round(worst["perfect_front_cc"], 1),
                      "perfect_front_is": "both visits' true surfaces seen along her anterior axis, every cell, "
                                          "measured on the same earlier wall and grown footprint (explanatory)",
                      "perfect_front_half_grid_worst_pct": round(worst["perfect_front_half_grid_cc"], 1),
                      "own_walls_worst_pct": round(worst["skin_own_walls_cc"], 1),
                      "baseline": round(worst["model_earlier_wall_cc"], 1),
                      "baseline_is": "the fitted model on the earlier wall",
                      "rows": [{k: (round(v, 2) if isinstance(v, float) else v) for k, v in r.items()} for r in rows]}))


if __name__ == "__main__":
    main()
