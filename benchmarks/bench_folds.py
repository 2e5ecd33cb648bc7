"""How well the inframammary fold, and so the ptosis grade, is found on MakeHuman bodies whose fold is known.

`plan.symmetry.ptosis_grade` puts each breast's fold where the skin under the nipple is seen to reach the
skin below the breast ("seen"), or, where the lower pole ends in a cliff, HANG_SLOPE × the gland's depth
above its lowest point ("estimated"), and reports the nipple's height above it (`nipple_to_fold_mm`).
This script scans 11 MakeHuman bodies (`scenes.makehuman`: cup 0.2–1, firmness 0–1, some weight, muscle
and pose variety), 4 of them twice: 15 scans from DISTANCE_MM in front, pitched 0–10°, yaw 0, a wall
WALL_MM behind her or none, FRAMES noisy depth frames at RESOLUTION (`scenes.realistic.BodyScene`), both
sides ingested (`ingest_frames`), measured (`measure_breasts`) and graded — 30 breasts.

The truth: each breast's fold on the mesh's sagittal section through its nipple (the plane x = nipple x
of MakeHuman's frame; the triangles cut by it, chained into a closed loop). Going down the front of the
section from the nipple: a breast that hangs descends to its lowest point and its underside turns back
up to the chest — the fold is the top of that crease (the first peak after the lowest point); a breast
that does not hang meets the chest in a concave corner — the fold is the point where the profile turns
most sharply inwards (over TURN_MM either side), 10–BELOW_MM below the nipple. (Under the widest-set
nipples, cup ≥ 0.9, the plane leaves the torso some 80 mm below the nipple: the crease is then the one
the underside makes with the side of her chest.) The true fold is
carried to the camera (`camera_from_body`), then into her body frame as the measure found it
(`body_from_input`); error = measured nipple_to_fold_mm − (found nipple's y − true fold's y), along her
found up axis — the found nipple's own error cancels. Baseline: the fold put at the breast's lowest
point itself (`nipple_to_lowest_mm` as the nipple-to-fold), over the estimated folds.

Beside it: `nipple_to_lowest_mm` against the profile's lowest point above the fold, and the grade against
the one `ptosis_grade`'s bands give the true fold and lowest point.

Per breast, and per fold_from: breasts, mean error, RMS, worst |error|. A scene whose ingest or measure
raises BadInputError is counted and listed. Nothing is asserted; the last line is the JSON of the figures.

Run:  .venv/bin/python benchmarks/bench_folds.py     (15 scenes, about 15 seconds on 2 cores)
"""
from __future__ import annotations

import json
import time

import numpy as np
from rich.console import Console
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import depth_first_order
from threadpoolctl import threadpool_limits

from breastplan import BadInputError, transform_points
from breastplan.ingest.pipeline import ingest_frames
from breastplan.ingest.recording import DepthFrames
from breastplan.options import SIDES, IngestOptions
from breastplan.plan import breast_volume
from breastplan.plan.symmetry import ptosis_grade, regnault_grade
from breastplan.scenes.makehuman import Body, BodyOptions, make_body
from breastplan.scenes.realistic import BodyScene, CameraOptions, camera_pose

from bench_realistic import new_table
from timing import rounded

FRAMES = 8
RESOLUTION = "800x600"
DISTANCE_MM = 650.0
WALL_MM = 400.0
ARC_MM, STEP_MM = 350.0, 1.0
"""The front of the section is followed this far down from the nipple, resampled every STEP_MM."""
RISE_MM = 2.0
"""A profile rising back this much above its lowest point hangs; its crease ends where it falls this much."""
TURN_MM, BELOW_MM = 10.0, 100.0
"""A fold that does not hang: the sharpest inward turn over ±TURN_MM of profile, 10–BELOW_MM below the nipple."""

BODIES = {
    "cup .2": BodyOptions(cup=0.2),
    "cup .3 firm .8 wt .8": BodyOptions(cup=0.3, firmness=0.8, weight=0.8, pose="hands-on-hips"),
    "cup .4 firm 1 wt .3": BodyOptions(cup=0.4, firmness=1.0, weight=0.3, pose="arms-down"),
    "cup .5": BodyOptions(),
    "cup .6 firm 0 wt .7": BodyOptions(cup=0.6, firmness=0.0, weight=0.7, pose="hands-on-hips"),
    "cup .7 mus .7": BodyOptions(cup=0.7, muscle=0.7, pose="arms-down"),
    "cup .8 firm .3": BodyOptions(cup=0.8, firmness=0.3, pose="arms-down"),
    "cup .8 firm 1 wt .6": BodyOptions(cup=0.8, firmness=1.0, weight=0.6),
    "cup .9 firm .6 wt .2": BodyOptions(cup=0.9, firmness=0.6, weight=0.2, pose="hands-on-hips"),
    "cup 1": BodyOptions(cup=1.0),
    "cup 1 firm 0 low": BodyOptions(cup=1.0, firmness=0.0, modifiers={"breast_volume_vert": -1.0}, pose="arms-down"),
}
VIEWS = (   # body, pitch °, wall behind her
    ("cup .2", 0.0, WALL_MM), ("cup .2", 8.0, None), ("cup .3 firm .8 wt .8", 3.0, None),
    ("cup .4 firm 1 wt .3", 6.0, WALL_MM), ("cup .5", 10.0, None), ("cup .6 firm 0 wt .7", 2.0, WALL_MM),
    ("cup .6 firm 0 wt .7", 9.0, None), ("cup .7 mus .7", 5.0, WALL_MM), ("cup .8 firm .3", 4.0, None),
    ("cup .8 firm .3", 10.0, WALL_MM), ("cup .8 firm 1 wt .6", 7.0, None), ("cup .9 firm .6 wt .2", 1.0, WALL_MM),
    ("cup 1", 5.0, None), ("cup 1 firm 0 low", 3.0, WALL_MM), ("cup 1 firm 0 low", 8.0, None),
)


# --- the truth: the fold on the mesh's section through the nipple ---------------------------------
def section_loop(body: Body, nipple: np.ndarray) -> np.ndarray:
    """(K, 3) the closed curve where the plane x = nipple x cuts the mesh, in order round it from the point
    nearest the nipple (the loop that holds it): each cut edge gives a point, each cut triangle joins two."""
    V, d = body.vertices, body.vertices[:, 0] - nipple[0]
    d = np.where(d == 0.0, 1e-9, d)
    edges = np.sort(body.faces[:, [[0, 1], [1, 2], [2, 0]]], axis=2)           # (T, 3, 2)
    cut = d[edges[..., 0]] * d[edges[..., 1]] < 0
    tri = cut.sum(1) == 2
    keys, node = np.unique(edges[tri][cut[tri]] @ [len(V), 1], return_inverse=True)
    a, b = np.divmod(keys, len(V))
    points = V[a] + (d[a] / (d[a] - d[b]))[:, None] * (V[b] - V[a])
    ends = node.reshape(-1, 2).T
    graph = coo_matrix((np.ones(ends.shape[1]), (ends[0], ends[1])), shape=(len(points),) * 2)
    start = int(np.argmin(np.linalg.norm(points - nipple, axis=1)))
    return points[depth_first_order(graph.tocsr(), start, directed=False, return_predecessors=False)]


def front_down(loop: np.ndarray) -> np.ndarray:
    """(n, 3) the loop followed downwards from its first point (the nipple) for ARC_MM, every STEP_MM."""
    if loop[1:6, 1].mean() > loop[0, 1]:
        loop = np.vstack([loop[:1], loop[:0:-1]])
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(loop, axis=0), axis=1))])
    t = np.arange(0.0, min(ARC_MM, s[-1]), STEP_MM)
    return np.column_stack([np.interp(t, s, loop[:, k]) for k in range(3)])


def fold_on(path: np.ndarray) -> tuple[int, str]:
    """The fold's index on a profile down from the nipple (`front_down`), and whether the breast "hangs"
    (the fold the top of the crease its underside rises to) or "tapers" (the sharpest inward turn)."""
    y = path[:, 1]
    rise = y - np.minimum.accumulate(y)
    if rise.max() > RISE_MM:
        j = int(np.argmax(rise > RISE_MM))                     # on the underside, rising from the lowest point
        fall = np.maximum.accumulate(y[j:]) - y[j:]
        end = j + (int(np.argmax(fall > RISE_MM)) if (fall > RISE_MM).any() else len(fall))
        return j + int(np.argmax(y[j:end])), "hangs"
    w = int(TURN_MM / STEP_MM)
    t1, t2 = path[w:-w, 1:] - path[:-2 * w, 1:], path[2 * w:, 1:] - path[w:-w, 1:]       # (y, z)
    inward = np.arctan2(t1[:, 1] * t2[:, 0] - t1[:, 0] * t2[:, 1], (t1 * t2).sum(1))
    below = y[0] - y[w:-w]
    return w + int(np.argmax(np.where((below > 10.0) & (below < BELOW_MM), inward, -np.inf))), "tapers"


def true_fold(body: Body, side: str) -> tuple[np.ndarray, int, str]:
    """The profile down from the `side` nipple ((n, 3) MakeHuman's frame, mm), the fold's index on it, and
    "hangs" / "tapers"."""
    path = front_down(section_loop(body, body.nipples[side]))
    return path, *fold_on(path)


# --- one scan -------------------------------------------------------------------------------------
def run_scene(name: str, pitch: float, wall: float | None, seed: int) -> tuple[list[dict], list[str]]:
    """Per breast measured: its row; and the BadInputErrors raised."""
    made = make_body(BODIES[name])
    camera = CameraOptions(DISTANCE_MM, pitch, 0.0, RESOLUTION, wall_mm=wall)
    scene = BodyScene(made, camera, camera_pose(0.5 * (made.nipples["left"] + made.nipples["right"]), camera))
    frames = DepthFrames(scene.frames(FRAMES, seed), camera.K, name)
    view = f"{made.options.pose} p{pitch:.0f} {'wall' if wall else 'open'}"
    ingested, errors = {}, []
    for side in SIDES:
        try:
            ingested[side] = ingest_frames(frames, IngestOptions(side))
        except BadInputError as exc:
            errors.append(f"{name} {view}: ingest {side}: {exc}")
    nipples = {side: np.asarray(i.nipple_camera, float) for side, i in ingested.items()}
    try:
        m = breast_volume.measure_breasts(next(iter(ingested.values())).body, nipples) if nipples else None
    except BadInputError as exc:
        return [], errors + [f"{name} {view}: measure: {exc}"]
    rows = []
    for side in m.sides if m else ():
        path, k, how = true_fold(made, side)
        y = transform_points(m.body_from_input @ scene.camera_from_body, path[:k + 1])[:, 1]   # her found up axis
        nipple_y = m.in_body(nipples[side])[1]
        true, true_lowest = float(nipple_y - y[k]), float(nipple_y - y.min())
        p = ptosis_grade(m, nipples, side)
        to_fold, to_lowest = p["nipple_to_fold_mm"], p["nipple_to_lowest_mm"]
        rows.append({"body": name, "view": view, "side": side, "truth": how, "fold_from": p["fold_from"],
                     "grade": p["grade"], "true_grade": regnault_grade(true, true_lowest), "measured_mm": to_fold,
                     "true_mm": true, "error_mm": None if to_fold is None else to_fold - true,
                     "lowest_error_mm": None if to_lowest is None else to_lowest - true_lowest,
                     "lowest_as_fold_error_mm": None if to_lowest is None else to_lowest - true})
    return rows, errors


# --- figures --------------------------------------------------------------------------------------
def stats(errors: list[float]) -> dict:
    e = np.asarray(errors, float)
    if not len(e):
        return {"breasts": 0, "mean_mm": None, "rms_mm": None, "worst_mm": None}
    return {"breasts": len(e), "mean_mm": float(e.mean()), "rms_mm": float(np.sqrt((e ** 2).mean())),
            "worst_mm": float(np.abs(e).max())}


def figures_of(rows: list[dict]) -> dict:
    out = {f: stats([r["error_mm"] for r in rows if r["fold_from"] == f]) for f in ("seen", "estimated")}
    out["none"] = {"breasts": sum(r["fold_from"] == "none" for r in rows)}
    out["lowest_as_fold"] = stats([r["lowest_as_fold_error_mm"] for r in rows if r["fold_from"] == "estimated"])
    out["nipple_to_lowest"] = stats([r["lowest_error_mm"] for r in rows if r["lowest_error_mm"] is not None])
    out["grades_agree"] = sum(r["grade"] == r["true_grade"] for r in rows)
    return out


def mm(v: float | None) -> str:
    return "–" if v is None else f"{v:+.1f}"


def main() -> None:
    console = Console(width=200)
    start = time.perf_counter()
    rows, errors, raised = [], [], 0
    with threadpool_limits(1, "blas"):      # as bench_volume_repeat runs
        for seed, (name, pitch, wall) in enumerate(VIEWS):
            r, e = run_scene(name, pitch, wall, seed)
            rows += r
            errors += e
            raised += bool(e)
            console.log(f"{name} p{pitch:.0f}: " + "; ".join(f"{x['side']} {x['fold_from']} {mm(x['error_mm'])} mm"
                                                              for x in r) + (f"; {len(e)} raised" if e else ""))
    table = new_table("bench_folds — nipple-to-fold per breast (mm, along her found up axis)",
                      ("body", "view", "side", "truth", "fold_from", "grade", "true grade", "measured", "true",
                       "error", "lowest as fold", "to lowest error"),
                      "truth: the breast hangs or tapers on the mesh's section through its nipple (true grade: from "
                      "its fold and lowest point, `ptosis_grade`'s bands); error: measured − true nipple-to-fold; "
                      "lowest as fold: nipple_to_lowest_mm − true nipple-to-fold; to lowest error: "
                      "nipple_to_lowest_mm − the true nipple-to-lowest.")
    for r in rows:
        table.add_row(r["body"], r["view"], r["side"], r["truth"], r["fold_from"], r["grade"], r["true_grade"],
                      *(mm(r[k]) for k in ("measured_mm", "true_mm", "error_mm", "lowest_as_fold_error_mm",
                                           "lowest_error_mm")))
    console.print(table)
    figures = figures_of(rows)
    summary = new_table(f"bench_folds — nipple-to-fold error by fold_from (MIN_POINTS {breast_volume.MIN_POINTS})",
                        ("fold", "breasts", "mean", "RMS", "worst |error|"))
    for key, label in (("seen", "seen"), ("estimated", "estimated"),
                       ("lowest_as_fold", "estimated: the fold put at the lowest point itself"),
                       ("nipple_to_lowest", "(nipple_to_lowest_mm against the mesh's lowest point)")):
        f = figures[key]
        summary.add_row(label, str(f["breasts"]), *("–" if f[k] is None else f"{f[k]:.1f} mm"
                                                    for k in ("mean_mm", "rms_mm", "worst_mm")))
    summary.add_row("none", str(figures["none"]["breasts"]), "", "", "")
    console.print(summary)
    wall_s = time.perf_counter() - start
    console.print(f"{len(VIEWS)} scenes ({raised} raised BadInputError), {len(rows)} breasts; grade as the truth's: "
                  f"{figures['grades_agree']} of {len(rows)}; {wall_s:.0f} s")
    for e in errors:
        console.print(f"  raised: {e}")
    print(json.dumps(rounded({"benchmark": "bench_folds", "min_points": breast_volume.MIN_POINTS,
                              "scenes": len(VIEWS), "scenes_raised": raised, "raised": errors, "breasts": len(rows),
                              "error_is": "measured − true nipple-to-fold, mm", **figures,
                              "wall_s": wall_s})))


if __name__ == "__main__":
    main()
