"""The cup and firmness figures of bench_realistic, each over shifted copies of the same scans.

`bench_realistic.py` measures each pair case once, and `bench_repeatability.py` shows that a shift
of a few millimetres moves a small breast's fitted volume by up to a third: one run's worst case is
partly luck. This script ingests (`isolate`, automatic isolation) and fits (`fit_scan`) both members
of every cup and firmness case of bench_realistic (4 pairs × 3 views × 2 sides) with the fused depth
points shifted by each of SHIFTS_MM (the viewing frame shifted with them), and reports how the
figures are distributed over the 12 cases × 4 shifts: the cup change's error (median, 90th
percentile, worst, share within the 10 % target), the firmness pairs' sag order (share right) and
their volume difference (share within 5 %). Baseline: the Chen pairs of bench_realistic (semi-axes
× 1.12) under the same shifts.

Run:  .venv/bin/python benchmarks/bench_shifted_pairs.py     (about 3 minutes)
"""
from __future__ import annotations

import json
import statistics

import numpy as np
from rich.console import Console

from breastplan.scenes import synthetic
from breastplan.scenes.realistic import make_body_scene
from breastplan.options import SIDES

from bench_realistic import FRAMES, PAIRS, SAG_TIE_MM, TARGETS, VIEWS, chen_scene, chen_specs, new_table
from bench_repeatability import camera_points, fits_under_shifts

SHIFTS_MM = ((0, 0, 0), (3, 0, 0), (0, 3, 0), (-4, 2, 6))


def shifted(points: np.ndarray, side: str) -> list[tuple[float, float]]:
    """(volume cc, ptosis sag mm) of the breast on `side` for each shift of the camera points."""
    return [(fit.volume_cc, fit.ptosis_sag_mm) for _, _, fit in fits_under_shifts(points, side, SHIFTS_MM)]


def realistic_cases(console: Console) -> list[dict]:
    cases = []
    for pair in PAIRS:
        for view in pair.views:
            pose, camera = VIEWS[view]
            members = []
            for member in (0, 1):
                scene = make_body_scene(pair.body(member, pose), camera)
                points = camera_points(scene.frames(FRAMES, view), scene.camera.K)
                members.append((scene.body.half_volumes_cc(), {s: shifted(points, s) for s in SIDES}))
            for side in SIDES:
                (t0, fits0), (t1, fits1) = ((truth[side], fits[side]) for truth, fits in members)
                cases.append({"pair": pair.name, "varies": pair.varies, "view": view, "side": side,
                              "true_change_cc": t1 - t0, "fits": [fits0, fits1]})
            console.log(f"{pair.name} v{view}")
    return cases


def chen_cases(console: Console) -> list[dict]:
    cases = []
    specs = chen_specs(False)
    for plain, scaled in zip(specs[::2], specs[1::2]):
        members = []
        for spec in (plain, scaled):
            scene = chen_scene(spec)
            points = camera_points(synthetic.depth_frames(scene, FRAMES, spec["seed"]), scene.K)
            members.append(({s: scene.breasts[s].volume_on_chest_cc(s) for s in SIDES},
                            {s: shifted(points, s) for s in SIDES}))
        for side in SIDES:
            (t0, fits0), (t1, fits1) = ((truth[side], fits[side]) for truth, fits in members)
            cases.append({"pair": f"chen s{plain['seed']}", "varies": "cup", "view": None, "side": side,
                          "true_change_cc": t1 - t0, "fits": [fits0, fits1]})
        console.log(f"chen s{plain['seed']}")
    return cases


def cup_errors(cases: list[dict]) -> list[float]:
    """|fitted change / true change − 1| in %, one per case × shift."""
    return [100.0 * abs((b[0] - a[0]) / c["true_change_cc"] - 1.0)
            for c in cases if c["varies"] == "cup" for a, b in zip(*c["fits"])]


def firmness(cases: list[dict]) -> tuple[list[bool], list[float]]:
    """Per case × shift: firmness 0 sags more (by over SAG_TIE_MM); |volume difference| in % of the mean."""
    pairs = [(a, b) for c in cases if c["varies"] == "firmness" for a, b in zip(*c["fits"])]
    return ([a[1] > b[1] + SAG_TIE_MM for a, b in pairs],
            [200.0 * abs(b[0] - a[0]) / (a[0] + b[0]) for a, b in pairs])


def summary(errors: list[float], target: float) -> dict:
    e = np.asarray(errors)
    return {"median": round(float(np.median(e)), 2), "p90": round(float(np.percentile(e, 90)), 2),
            "worst": round(float(e.max()), 2), "within_target_pct": round(100.0 * float(np.mean(e <= target)), 1),
            "n": len(e)}


def main() -> None:
    console = Console(width=160)
    real, chen = realistic_cases(console), chen_cases(console)
    table = new_table("bench_shifted_pairs — pair figures over shifted copies of each scan",
                      ("pair", "view", "side", "true change", "fitted change per shift", "sag 0 → 1 per shift (mm)"),
                      f"shifts (mm): {', '.join(str(s) for s in SHIFTS_MM)}; sag only for the firmness pairs.")
    for c in real + chen:
        changes = " ".join(f"{b[0] - a[0]:+.0f}" for a, b in zip(*c["fits"]))
        sags = " ".join(f"{a[1]:.0f}→{b[1]:.0f}" for a, b in zip(*c["fits"])) if c["varies"] == "firmness" else ""
        table.add_row(c["pair"], "" if c["view"] is None else str(c["view"]), c["side"],
                      f"{c['true_change_cc']:+.0f} cc", changes, sags)
    console.print(table)
    order, difference = firmness(real)
    figures = {"cup_change_error": {**summary(cup_errors(real), TARGETS["cup_change_worst_pct"]), "unit": "%",
                                    "target": TARGETS["cup_change_worst_pct"],
                                    "baseline": summary(cup_errors(chen), TARGETS["cup_change_worst_pct"])},
               "firmness_order_right_pct": {"value": round(100.0 * statistics.mean(order), 1), "n": len(order),
                                            "target": TARGETS["firmness_order_pct"]},
               "firmness_volume_difference": {**summary(difference, TARGETS["firmness_volume_pct"]), "unit": "%",
                                              "target": TARGETS["firmness_volume_pct"]}}
    columns = ("figure", "median", "90th pct.", "worst", "within target", "target", "Chen baseline")
    summary_table = new_table("bench_shifted_pairs — figures over 12 cases × shifts", columns, "")
    cup, base = figures["cup_change_error"], figures["cup_change_error"]["baseline"]
    summary_table.add_row("cup change error", f"{cup['median']:.1f} %", f"{cup['p90']:.1f} %", f"{cup['worst']:.1f} %",
                          f"{cup['within_target_pct']:.0f} % of {cup['n']}", "≤ 10 %",
                          f"{base['median']:.1f} / {base['worst']:.1f} % (median / worst)")
    diff = figures["firmness_volume_difference"]
    summary_table.add_row("firmness volumes differ", f"{diff['median']:.1f} %", f"{diff['p90']:.1f} %",
                          f"{diff['worst']:.1f} %", f"{diff['within_target_pct']:.0f} % of {diff['n']}", "≤ 5 %",
                          "–")
    summary_table.add_row("firmness sag order right", "", "", "",
                          f"{figures['firmness_order_right_pct']['value']:.0f} % of {len(order)}", "100 %", "–")
    console.print(summary_table)
    print(json.dumps({"benchmark": "bench_shifted_pairs", "shifts_mm": SHIFTS_MM, "figures": figures}))


if __name__ == "__main__":
    main()
