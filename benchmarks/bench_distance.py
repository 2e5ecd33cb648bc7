"""How far from her the camera may stand: her volume, nipples and refusals against the camera's distance.

Four MakeHuman bodies (bench_volume_repeat's: cup 0.8 soft, arms down; cup 0.3 firm and heavy, hands on
hips; cup 0.6 slim and muscular, A-pose; weight 0.5, cup 0.7, A-pose), each scanned from DISTANCES_MM in
front of her nipples (pitched 5°, 8 noisy depth frames at 800×600, the depth noise growing with the
square of the distance, `scenes.realistic`), with a wall WALL_MM behind her and without, both sides
ingested and measured (`measure_breasts`). Per distance: the scenes refused (BadInputError), the worst
nipple error against the truth, and each breast's volume against the same body's at REFERENCE_MM, with
its stated ±; each scene's volumes, footprint areas and plateau (`plateau_pct`) are in the JSON. Then what
moves the small breasts of the heavy body (`why_far`): its 650 mm scan thinned to the points a scan from
FAR_MM holds, and scanned again at 650 mm with the depth noise of FAR_MM, against its scan from FAR_MM; and,
for each body at 650 mm with a wall, how much of her skin next to the footprint stands within 1 mm of FOOT_MM
above the wall (a plateau whose cells a small shift of the wall carries into the footprint or out of it).
Nothing is asserted; the last line is the JSON of the figures.

Run:  .venv/bin/python benchmarks/bench_distance.py     (48 scenes and 3 more, about 1 minute on 2 cores)
"""
from __future__ import annotations

import json
import time

import numpy as np
from rich.console import Console
from scipy import ndimage

from breastplan import BadInputError
from breastplan.body import Body
from breastplan.options import SIDES
from breastplan.plan.breast_volume import FOOT_MM, measure_breasts
from breastplan.scenes.realistic import CameraOptions, make_body_scene

from bench_realistic import new_table
from bench_volume_repeat import BODIES, RESOLUTION, scanned_and_measured
from timing import rounded

NAMES = ("R1 cup .8 firm .3", "R2 cup .3 firm .8 wt .8", "R3 cup .6 wt .3 mus .7", "S2 wt .5 cup .7")
DISTANCES_MM = (500.0, 650.0, 800.0, 900.0, 1000.0, 1200.0)
REFERENCE_MM = 650.0
WALL_MM = 400.0
SEED = 7
FAR_MM = 1000.0
HEAVY = "R2 cup .3 firm .8 wt .8"


def scene(name: str, distance: float, wall: float | None) -> dict:
    """One body scanned from `distance` (mm), with a wall `wall` mm behind her or none: what was refused, the worst
    nipple error (mm), each breast's volume and its ± (cc)."""
    bench_scene = make_body_scene(BODIES[name], CameraOptions(distance, 5.0, 0.0, RESOLUTION, wall_mm=wall))
    out = {"body": name, "distance_mm": distance, "wall": wall is not None, "errors": [], "nipple_mm": None,
           "volume_cc": {}, "uncertainty_cc": {}, "area_cm2": {}, "plateau_pct": None}
    try:
        _, nipples, m = scanned_and_measured(bench_scene, SEED, name)
    except BadInputError as exc:
        out["errors"].append(str(exc))
        return out
    truth = bench_scene.nipples_camera()
    out["nipple_mm"] = max(float(np.linalg.norm(nipples[s] - truth[s])) for s in SIDES)
    out["volume_cc"] = {s: b.volume_cc for s, b in m.sides.items()}
    out["uncertainty_cc"] = {s: b.uncertainty_cc for s, b in m.sides.items()}
    out["area_cm2"] = {s: b.area_cm2 for s, b in m.sides.items()}
    out["plateau_pct"] = plateau_pct(m)
    return out


def left_breast(m) -> dict:
    """One measure's left breast: volume (cc), footprint area (cm²)."""
    return {"volume_cc": m.sides["left"].volume_cc, "area_cm2": m.sides["left"].area_cm2}


def plateau_pct(m) -> float:
    """The area of her skin within 1 mm of FOOT_MM above the wall, seen, within 3 cells outside either footprint
    or on its outer 3 cells, as a share of the footprints' area (%)."""
    c = m.cells
    near = ndimage.binary_dilation(c.footprint, iterations=3) & ~ndimage.binary_erosion(c.footprint, iterations=3)
    return 100.0 * float((near & c.seen & (np.abs(c.height_mm - FOOT_MM) <= 1.0)).sum() / c.footprint.sum())


def why_far(rows: list[dict]) -> dict:
    """The heavy body's left breast from 650 mm (REFERENCE_MM), from FAR_MM, from 650 mm with its points thinned
    to FAR_MM's density (each kept with probability (650 / FAR_MM)², a fixed seed) and from 650 mm with FAR_MM's
    depth noise (noise_mm scaled by (FAR_MM / 650)², as the noise grows); the thinned scan's wall moved against her
    skin (mean over the footprint, mm: > 0 the wall further back); and each body's plateau at 650 mm with a wall,
    from `rows` (`scene`'s)."""
    near_scene = make_body_scene(BODIES[HEAVY], CameraOptions(REFERENCE_MM, 5.0, 0.0, RESOLUTION, wall_mm=WALL_MM))
    body, nipples, near = scanned_and_measured(near_scene, SEED, HEAVY)
    keep = np.random.default_rng(0).random(len(body.torso_input)) < (REFERENCE_MM / FAR_MM) ** 2
    thinned = measure_breasts(Body(body.torso_input[keep], body.input_to_view, body.plumb_input), nipples)
    far = scanned_and_measured(make_body_scene(BODIES[HEAVY], CameraOptions(FAR_MM, 5.0, 0.0, RESOLUTION,
                                                                             wall_mm=WALL_MM)), SEED, HEAVY)[2]
    noisy = scanned_and_measured(make_body_scene(BODIES[HEAVY], CameraOptions(
        REFERENCE_MM, 5.0, 0.0, RESOLUTION, noise_mm=(FAR_MM / REFERENCE_MM) ** 2, wall_mm=WALL_MM)), SEED, HEAVY)[2]
    a, b = near.cells, thinned.cells                    # the same nipples: the same cells
    both = a.footprint & b.footprint & a.seen & b.seen
    moved = float(np.mean((b.height_mm - a.height_mm)[both]))      # her skin higher above the wall: the wall back
    plateau = {r["body"]: r["plateau_pct"] for r in rows if r["distance_mm"] == REFERENCE_MM and r["wall"]}
    return {"body": HEAVY, "near": left_breast(near), "far": left_breast(far), "thinned": left_breast(thinned),
            "noisier": left_breast(noisy), "thinned_wall_back_mm": moved, "plateau_pct_at_650": plateau}


def main() -> None:
    console = Console(width=160)
    t0 = time.perf_counter()
    rows = []
    for name in NAMES:
        for wall in (WALL_MM, None):
            for d in DISTANCES_MM:
                rows.append(scene(name, d, wall))
                r = rows[-1]
                said = (f"refused: {r['errors'][0]}" if r["errors"] else f"nipple {r['nipple_mm']:.1f} mm, volume "
                        + ", ".join(f"{s} {v:.0f} ± {r['uncertainty_cc'][s]:.0f} cc over {r['area_cm2'][s]:.0f} cm²"
                                    for s, v in r["volume_cc"].items()))
                console.log(f"{name}, {'wall' if wall else 'open'}, {d:.0f} mm: {said}")
    reference = {(r["body"], r["wall"]): r for r in rows if r["distance_mm"] == REFERENCE_MM}
    table = new_table("bench_distance — her volume and nipples against the camera's distance",
                      ("distance mm", "scenes refused", "nipple error, worst", "volume against 650 mm: least, most",
                       "beyond its ±"), f"volume: each breast against the same body and wall at {REFERENCE_MM:g} mm")
    figures = []
    for d in DISTANCES_MM:
        at = [r for r in rows if r["distance_mm"] == d]
        done = [r for r in at if not r["errors"] and len(r["volume_cc"]) == 2]
        ratio, beyond = [], 0
        for r in done:
            ref = reference[(r["body"], r["wall"])]
            for s, v in r["volume_cc"].items():
                if s in ref["volume_cc"]:
                    ratio.append(100.0 * (v / ref["volume_cc"][s] - 1.0))
                    beyond += abs(v - ref["volume_cc"][s]) > r["uncertainty_cc"][s]
        nipple = max((r["nipple_mm"] for r in done), default=None)
        refused = [f"{r['body']}, wall {r['wall']}: {r['errors'][0]}" for r in at if r["errors"]]
        figures.append({"distance_mm": d, "scenes": len(at), "refused": refused,
                        "nipple_worst_mm": nipple, "volume_pct": [min(ratio), max(ratio)] if ratio else None,
                        "beyond_uncertainty": f"{beyond}/{len(ratio)}"})
        f = figures[-1]
        table.add_row(f"{d:.0f}", f"{len(f['refused'])} of {len(at)}", "–" if nipple is None else f"{nipple:.1f} mm",
                      "–" if not ratio else f"{min(ratio):+.1f} %, {max(ratio):+.1f} %", f["beyond_uncertainty"])
    console.print(table)
    for f in figures:
        for refusal in f["refused"]:
            print(f"refused at {f['distance_mm']:.0f} mm: {refusal}")
    why = why_far(rows)
    said = {k: f"{why[k]['volume_cc']:.1f} cc over {why[k]['area_cm2']:.0f} cm²" for k in ("near", "far", "thinned",
                                                                                        "noisier")}
    print(f"{HEAVY}, left breast: {said['near']} from {REFERENCE_MM:g} mm, {said['far']} from {FAR_MM:g} mm; "
          f"from {REFERENCE_MM:g} mm thinned to {FAR_MM:g} mm's points {said['thinned']} (its wall "
          f"{why['thinned_wall_back_mm']:+.2f} mm further back against her skin), with {FAR_MM:g} mm's noise "
          f"{said['noisier']}")
    print("skin within 1 mm of FOOT_MM next to the footprint's edge, share of the footprint at 650 mm: "
          + ", ".join(f"{k} {v:.0f} %" for k, v in why["plateau_pct_at_650"].items()))
    print(f"{len(rows)} scenes, {time.perf_counter() - t0:.0f} s")
    print(json.dumps({"benchmark": "bench_distance", "reference_mm": REFERENCE_MM, "figures": rounded(figures, 4),
                      "why_far": rounded(why, 4), "scenes": rounded(rows, 4)}))


if __name__ == "__main__":
    main()
