"""BCCT.core's asymmetry measures, taken in 3-D on her skin, against what the bodies truly are.

`plan.symmetry.symmetry_measures` gives each scan pBRA, pUNR, pLBC, pBCE, BCD and the mirrored overlap
(docs/symmetry.md). This script scans the bodies and views of bench_volume_repeat (`shots()`: 4 bodies
re-scanned 5 times each and once in another room, 2 symmetric bodies in 6 views, 5 asymmetric bodies in
2 views; MakeHuman, 8 noisy depth frames at 800×600, both sides ingested, `measure_breasts`) and compares:

1. **Nipple measures against the truth.** BRA, UNR and their shares from MakeHuman's own nipples and
   sternal notch (x her left, y up in MakeHuman's frame), against those measured from the nipples and
   notch the scan found: error in percentage points. Baseline, in the same run: the same measures from a
   frontal photograph with perfect marks — the true nipples and notch projected through the camera (its
   K) onto the image, as BCCT.core measures them; the camera's yaw and pitch then shorten or tilt them.
2. **Mirror-symmetric bodies** (the re-scan bodies R1–R3 and S1–S2: the mesh is mirror-symmetric, every
   measure's truth is 0 and the overlap's 100 %): the largest value of each measure, and the lowest
   overlap, over all their scans — the measures' floor.
3. **Re-scans**: each measure's spread (max − min) over a body's 5 re-scans, worst body.
4. **A breast moved by a known amount**: on each mirror-symmetric body's scans, the left breast's points
   (within 100 mm of its nipple, tapering to nothing at 150 mm) and its nipple moved MOVE_MM down her up
   axis, and measured again: UNR, BRA and LBC against what the scan's own left − right differences
   become with the left nipple and lowest point MOVE_MM lower (`expected_after_move`; the measures are
   unsigned, and a scan's own small difference adds to the move or takes from it), BCE against its
   value before: error of each; and LBC's worst where the measures say a lowest point lay on a hidden
   cell (`lower_contours_hidden`) and where they do not.

A scene whose ingest or measure raises is counted and listed. Nothing is asserted; the last line is the
JSON of the figures.

Run:  .venv/bin/python benchmarks/bench_symmetry.py     (46 scenes, about 1 minute on 2 cores)
"""
from __future__ import annotations

import json
import statistics
import time

import numpy as np
from rich.console import Console

from breastplan import BadInputError, transform_points
from breastplan.body import Body
from breastplan.options import SIDES
from breastplan.plan.breast_volume import measure_breasts
from breastplan.plan.symmetry import lower_edge, own_region, symmetry_measures
from breastplan.scenes.realistic import BodyScene, camera_pose

from bench_realistic import new_table
from bench_volume_repeat import build_body, scanned_and_measured, shots
from timing import rounded

MOVE_MM = 10.0
MIRROR_BODIES = ("R1 cup .8 firm .3", "R2 cup .3 firm .8 wt .8", "R3 cup .6 wt .3 mus .7", "S1 wt .85 cup .2",
                 "S2 wt .5 cup .7")
"""Bodies whose mesh is its own mirror image: every asymmetry measure's truth is 0, the overlap's 100 %."""
MEASURES = ("pBRA_pct", "pUNR_pct", "pLBC_pct", "pBCE_pct", "BCD_mm")


def nipple_measures(notch, left, right) -> dict:
    """BRA and UNR (in the points' units) and their shares (%) from the notch and nipples (x her left or
    right, y up, either sign; 2-D or 3-D), as `plan.symmetry.bcct_measures` defines them."""
    rel = {s: np.asarray(p, float) - np.asarray(notch, float) for s, p in (("left", left), ("right", right))}
    folded = {s: np.concatenate([[abs(v[0])], v[1:]]) for s, v in rel.items()}
    drop = {s: abs(v[1]) for s, v in rel.items()}
    bra, unr = float(np.linalg.norm(folded["left"] - folded["right"])), abs(drop["left"] - drop["right"])
    return {"BRA": bra, "UNR": unr, "pBRA_pct": 100 * bra / np.mean([np.linalg.norm(v) for v in rel.values()]),
            "pUNR_pct": 100 * unr / np.mean(list(drop.values()))}


def photographed(scene: BodyScene, point_body: np.ndarray) -> np.ndarray:
    """(2,) where a point of MakeHuman's frame falls on the camera's image (pixels, y down)."""
    p = transform_points(scene.camera_from_body, np.asarray(point_body, float)[None])[0]
    uvw = scene.camera.K @ p
    return uvw[:2] / uvw[2]


def moved_left(m, body: Body, nipples: dict):
    """(the scan's body with the left breast moved MOVE_MM down her up axis, the moved nipples); `m` its
    `measure_breasts`, whose body frame the move is made in."""
    T = m.body_from_input
    points = transform_points(T, body.torso_input)
    nipple = transform_points(T, nipples["left"][None])[0]
    d = np.linalg.norm(points[:, :2] - nipple[:2], axis=1)
    shift = MOVE_MM * np.where(d < 100.0, 1.0, np.where(d < 150.0, 0.5 * (1 + np.cos(np.pi * (d - 100.0) / 50.0)), 0.0))
    points[:, 1] -= np.where(points[:, 0] > 0, shift, 0.0)
    back = np.linalg.inv(T)
    moved = dict(nipples, left=transform_points(back, (nipple - [0.0, MOVE_MM, 0.0])[None])[0])
    return Body(transform_points(back, points), body.input_to_view, body.plumb_input), moved


def signed(m, nipples: dict) -> dict:
    """Left less right, in her body frame (mm): the nipples (3,), their heights, and the breasts' lowest
    points' heights, as `plan.symmetry.bcct_measures` takes them."""
    n = {s: m.in_body(nipples[s]) for s in SIDES}
    lowest = {s: float(np.nanmin(lower_edge(m.cells, own_region(m.cells, s, n[s])))) for s in SIDES}
    return {"nipple": n["left"] * [-1.0, 1.0, 1.0] - n["right"], "height": n["left"][1] - n["right"][1],
            "lowest": lowest["left"] - lowest["right"]}


def expected_after_move(before: dict, measured: dict) -> dict:
    """UNR, BRA, LBC and BCE (mm) once the left nipple and lowest point are MOVE_MM lower than in a scan
    whose signed differences are `before` (`signed`) and whose measures are `measured`."""
    return {"UNR_mm": abs(before["height"] - MOVE_MM),
            "BRA_mm": float(np.linalg.norm(before["nipple"] - [0.0, MOVE_MM, 0.0])),
            "LBC_mm": abs(before["lowest"] - MOVE_MM), "BCE_mm": measured["BCE_mm"]}


def run(shot) -> dict:
    made = build_body(shot.body, shot.pose)
    target = 0.5 * (made.nipples["left"] + made.nipples["right"]) + [0.0, shot.dh_mm, 0.0]
    scene = BodyScene(made, shot.camera, camera_pose(target, shot.camera))
    row = {"set": shot.set, "body": shot.body, "view": shot.label,
           "true": nipple_measures(made.sternal_notch, made.nipples["left"], made.nipples["right"]),
           "photo": nipple_measures(*(photographed(scene, p) for p in (made.sternal_notch, made.nipples["left"],
                                                                        made.nipples["right"])))}
    try:
        body, nipples, m = scanned_and_measured(scene, shot.seed, shot.body)
    except BadInputError as exc:
        return {**row, "error": str(exc)}
    row["measured"] = symmetry_measures(m, nipples)
    if shot.body in MIRROR_BODIES:
        moved_body, moved_nipples = moved_left(m, body, nipples)
        row["moved"] = symmetry_measures(measure_breasts(moved_body, moved_nipples), moved_nipples)
        row["expected"] = expected_after_move(signed(m, nipples), row["measured"])
    return row


def figures(rows: list[dict]) -> dict:
    ok = [r for r in rows if "measured" in r]
    err = {k: [r["measured"][k] - r["true"][k] for r in ok] for k in ("pBRA_pct", "pUNR_pct")}
    photo = {k: [r["photo"][k] - r["true"][k] for r in ok] for k in ("pBRA_pct", "pUNR_pct")}
    mirror = [r for r in ok if r["body"] in MIRROR_BODIES]
    rescans = {}
    for r in ok:
        if r["set"] == "rescan":
            rescans.setdefault(r["body"], []).append(r["measured"])
    by_body = {body: {k: max(s[k] for s in scans) - min(s[k] for s in scans) for k in (*MEASURES, "overlap_pct")}
               for body, scans in rescans.items()}
    spread = {k: max(b[k] for b in by_body.values()) for k in (*MEASURES, "overlap_pct")}
    moved = [r for r in mirror if "moved" in r]
    shift = {k: [r["moved"][k] - r["expected"][k] for r in moved] for k in ("UNR_mm", "BRA_mm", "LBC_mm", "BCE_mm")}
    said = [r["moved"]["lower_contours_hidden"] > 0 for r in moved]
    lbc = [abs(e) for e in shift["LBC_mm"]]
    absolute = lambda v: [abs(x) for x in v]  # noqa: E731
    return {
        "scenes": len(rows), "failed": [f"{r['body']} {r['view']}: {r['error']}" for r in rows if "error" in r],
        "nipple_error_pp": {k: {"median": statistics.median(absolute(v)), "worst": max(absolute(v))}
                            for k, v in err.items()},
        "photograph_error_pp": {k: {"median": statistics.median(absolute(v)), "worst": max(absolute(v))}
                                for k, v in photo.items()},
        "mirror_scans": len(mirror),
        "mirror_worst": {k: max(r["measured"][k] for r in mirror) for k in MEASURES},
        "mirror_overlap_lowest_pct": min(r["measured"]["overlap_pct"] for r in mirror),
        "rescan_spread_worst": spread, "rescan_spread_by_body": by_body,
        "moved_scans": len(moved),
        "moved_error_mm": {k: {"median": statistics.median(absolute(v)), "worst": max(absolute(v))}
                           for k, v in shift.items()},
        "contour_hidden_scans": sum(r["measured"]["lower_contours_hidden"] > 0 for r in ok),
        "moved_lbc_worst_mm_said_hidden": max((e for e, h in zip(lbc, said) if h), default=None),
        "moved_lbc_worst_mm_said_seen": max((e for e, h in zip(lbc, said) if not h), default=None),
        "moved_said_hidden": sum(said),
    }


def described(r: dict) -> str:
    """One scan's measures beside their truths, for the log."""
    if "error" in r:
        return "failed: " + r["error"]
    m, t = r["measured"], r["true"]
    text = (f"pBRA {m['pBRA_pct']:.1f} (true {t['pBRA_pct']:.1f}, photograph {r['photo']['pBRA_pct']:.1f}) %, "
            f"pUNR {m['pUNR_pct']:.1f} (true {t['pUNR_pct']:.1f}) %, pLBC {m.get('pLBC_pct', np.nan):.1f} %, "
            f"pBCE {m.get('pBCE_pct', np.nan):.1f} %, overlap {m.get('overlap_pct', np.nan):.1f} %")
    if "moved" in r:
        text += "; moved, measured (expected): " + ", ".join(
            f"{k[:-3]} {r['moved'][k]:.1f} ({r['expected'][k]:.1f})" for k in ("UNR_mm", "BRA_mm", "LBC_mm", "BCE_mm"))
    return text


def main() -> None:
    console = Console(width=160)
    rows = []
    t0 = time.perf_counter()
    for shot in shots():
        if shot.set == "visit":
            continue
        rows.append(run(shot))
        console.log(f"{shot.body} {shot.label}: {described(rows[-1])}")
    f = figures(rows)
    table = new_table("bench_symmetry — BCCT.core's measures in 3-D against the truth",
                      ("figure", "measured on her skin", "frontal photograph, perfect marks (baseline)"),
                      "pp: percentage points; the photograph's marks are MakeHuman's own nipples and notch")
    for k in ("pBRA_pct", "pUNR_pct"):
        a, b = f["nipple_error_pp"][k], f["photograph_error_pp"][k]
        table.add_row(f"{k[:-4]} against the true nipples: median (worst)",
                      f"{a['median']:.2f} ({a['worst']:.2f}) pp", f"{b['median']:.2f} ({b['worst']:.2f}) pp")
    for k, v in f["mirror_worst"].items():
        table.add_row(f"mirror-symmetric bodies, {k}: largest (truth 0)", f"{v:.2f}", "–")
    table.add_row("mirror-symmetric bodies, overlap: lowest (truth 100 %)",
                  f"{f['mirror_overlap_lowest_pct']:.1f} %", "–")
    for k, v in f["rescan_spread_worst"].items():
        table.add_row(f"re-scans, {k}: spread, worst body", f"{v:.2f}", "–")
    for k, v in f["moved_error_mm"].items():
        table.add_row(f"a breast moved {MOVE_MM:g} mm down, {k} against its expected: error median (worst)",
                      f"{v['median']:.2f} ({v['worst']:.2f}) mm", "–")
    table.add_row("moved: LBC's worst where a lowest point is said hidden (scans) / where not",
                  f"{f['moved_lbc_worst_mm_said_hidden']:.2f} ({f['moved_said_hidden']}) / "
                  f"{f['moved_lbc_worst_mm_said_seen']:.2f} mm", "–")
    table.add_row("scans with a lowest point said hidden, before any move",
                  f"{f['contour_hidden_scans']} of {len(rows)}", "–")
    console.print(table)
    print(f"{len(rows)} scenes, {len(f['failed'])} failed, {time.perf_counter() - t0:.0f} s")
    print(json.dumps({"benchmark": "bench_symmetry", **rounded(f, 4)}))


if __name__ == "__main__":
    main()
