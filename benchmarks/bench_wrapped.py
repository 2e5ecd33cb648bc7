"""Scanners' wrapped meshes read as well as a frontal view of her, with a frontal export of the same body as the
baseline in the same run.

1. Closed bodies: seven MakeHuman bodies (`scenes.makehuman`) of varied cup, firmness, weight and pose, each written as
   its whole closed mesh (front, sides and back, as Artec and 3dMD export) in a file format (OBJ, PLY, GLB), in
   units (mm, m), with her up on one of the file's six signed axes and her turned about her vertical axis, and
   read with no --up (`ingest_sides`, her up found from her body). Per body: was the up found right; both
   nipples' distance from MakeHuman's (target: median ≤ 3 mm, worst ≤ 8 mm); her volume on her skin
   (`measure_scans`) against that of a camera's frontal export of the same body (`write_scan_file`, an OBJ of the
   triangles a camera at 680 mm sees): within the frontal volume's stated range (target): its ±, and above it
   what the frontal scan says may lie on her outer side, unseen (`unseen_outer_cc`); the ± alone as the baseline.
2. One breast a cup larger: bench_volume_repeat's one-sided cup bodies (the left half of one MakeHuman body, the
   right of another a cup apart, blended across her midline), in the three poses, each written as its closed mesh
   (turned 0° and 30°) and as a camera's frontal export (680 mm, pitched 5°): her measured left − right volume
   against the true one (the difference of the blended mesh's exact half volumes). A camera's depth frames get
   no depth from skin seen beyond rendering.GRAZING_DEG, and so miss the larger breast's outer side (docs/volume.md);
   the wrapped scan shows it. Also: whether the true difference lies within the frontal export's stated ranges
   (each breast's ±, and the larger one's unseen outer side).
3. Speed: a closed body subdivided to over 1 M vertices, as a binary PLY in metres with Z up, read and both
   breasts isolated (`ingest_sides`, no --up), median of REPEATS after a warm-up (target ≤ 3 s); the baseline is
   the frontal OBJ export of the same body, read and isolated alternately in the same run.

    .venv/bin/python benchmarks/bench_wrapped.py [--quick]
"""
from __future__ import annotations

import json
import statistics
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import open3d as o3d

from breastplan import transform_points, write_ply
from breastplan.ingest.scan import ingest_sides
from breastplan.options import IngestOptions
from breastplan.plan.compute import measure_scans
from breastplan.scenes.makehuman import BodyOptions, blended, make_body
from breastplan.scenes.realistic import (BodyScene, CameraOptions, camera_pose, file_from_body, make_body_scene,
                                        turned, write_closed_scan, write_scan_file)

sys.path.insert(0, str(Path(__file__).parent))
from bench_volume_repeat import BLEND_MM, HYBRIDS, range_holds  # noqa: E402
from timing import median_times, repeats_argument  # noqa: E402

BODIES = [  # (name, body, her turn about her vertical axis (°), up in the file, units, format)
    ("cup 0.8, her back to the viewer", BodyOptions(cup=0.8), 180.0, "+y", "mm", ".obj"),
    ("heavy, arms down", BodyOptions(cup=0.6, weight=0.8, pose="arms-down"), 35.0, "+z", "m", ".ply"),
    ("cup 0.9, soft", BodyOptions(cup=0.9, firmness=0.2), -40.0, "-x", "m", ".glb"),
    ("small, firm, hands on hips", BodyOptions(cup=0.3, firmness=0.8, pose="hands-on-hips"), 20.0, "-y", "mm",
     ".obj"),
    ("slim, muscular", BodyOptions(cup=0.6, weight=0.3, muscle=0.7), -15.0, "-z", "mm", ".ply"),
    ("asymmetric, arms down", BodyOptions(cup=0.7, modifiers={"asymmetry": 0.5}, pose="arms-down"), 45.0, "+x",
     "m", ".glb"),
    ("cup 0.7, hands on hips", BodyOptions(cup=0.7, pose="hands-on-hips"), 0.0, "-y", "m", ".ply"),
]
MILLION = 1_000_000


def both(path: Path) -> dict:
    return dict(zip(("left", "right"), ingest_sides(path, [IngestOptions(s) for s in ("left", "right")])))


def closed_body(folder: Path, name, options, deg, up, units, suffix) -> dict:
    body = make_body(options)
    to_file = file_from_body(up, units) @ turned(deg)
    write_closed_scan(folder / f"closed{suffix}", body, units, up, turn_deg=deg)
    scans = both(folder / f"closed{suffix}")
    mm = 1000.0 if units == "m" else 1.0
    errors = [float(np.linalg.norm(s.nipple_camera_mm - mm * transform_points(to_file, body.nipples[side][None])[0]))
              for side, s in scans.items()]
    found = all(f"up {up} (found" in s.source.description for s in scans.values())
    frontal = make_body_scene(options, CameraOptions(680.0, 5.0, 0.0, wall_mm=None))
    write_scan_file(folder / "front.obj", frontal, "mm", "+y")
    wrapped, front = measure_scans(scans).sides, measure_scans(both(folder / "front.obj")).sides
    volumes = {side: (wrapped[side].volume_cc, front[side].volume_cc, front[side].uncertainty_cc,
                      front[side].unseen_outer_cc) for side in wrapped}
    return {"name": f"{name}; turned {deg:g}°, {up} up, {units}, {suffix[1:].upper()}", "up_found": found,
            "nipple_mm": errors, "volumes": volumes}


ONE_SIDED_POSES = ("a-pose", "arms-down", "hands-on-hips")
ONE_SIDED_TURNS = (0.0, 30.0)


def one_sided(folder: Path) -> list[dict]:
    """Per one-sided cup body and pose: the true left − right half-body volume (cc) and the measured one's error
    (cc) on her closed mesh (each turn of ONE_SIDED_TURNS) and on a camera's frontal export."""
    rows = []
    for name, (lo, ro) in HYBRIDS.items():
        for pose in ONE_SIDED_POSES:
            body = blended(make_body(replace(lo, pose=pose)), make_body(replace(ro, pose=pose)), BLEND_MM)
            truth = body.half_volumes_cc()
            true = truth["left"] - truth["right"]

            def measured(path: Path) -> dict:
                return measure_scans(both(path)).sides

            def error(path: Path) -> float:
                sides = measured(path)
                return sides["left"].volume_cc - sides["right"].volume_cc - true

            wrapped = []
            for deg in ONE_SIDED_TURNS:
                write_closed_scan(folder / "one-sided.ply", body, "mm", "+y", turn_deg=deg)
                wrapped.append(error(folder / "one-sided.ply"))
            camera = CameraOptions(680.0, 5.0, 0.0, wall_mm=None)
            target = 0.5 * (body.nipples["left"] + body.nipples["right"])
            write_scan_file(folder / "one-sided-front.obj", BodyScene(body, camera, camera_pose(target, camera)),
                            "mm", "+y")
            front = measured(folder / "one-sided-front.obj")
            lr = front["left"].volume_cc - front["right"].volume_cc
            rows.append({"name": f"{name}, {pose}", "true_cc": true, "wrapped_error_cc": wrapped,
                         "frontal_error_cc": lr - true,
                         "frontal_range_holds": range_holds(vars(front["left"]), vars(front["right"]), true)})
            print(f"{rows[-1]['name']}: true left − right {true:.0f} cc; error, closed mesh "
                  + " / ".join(f"{e:+.0f}" for e in wrapped)
                  + f" cc, frontal export {rows[-1]['frontal_error_cc']:+.0f} cc (within its stated ranges: "
                  f"{rows[-1]['frontal_range_holds']})", flush=True)
    return rows


def million(folder: Path, repeats: int) -> dict:
    """Seconds to read and isolate both breasts of a closed body of over 1 M vertices, and of its frontal OBJ."""
    options = BodyOptions(cup=0.8)
    body = make_body(options)
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(body.vertices), o3d.utility.Vector3iVector(body.faces))
    mesh = mesh.subdivide_loop(1).simplify_quadric_decimation(MILLION // 32 + 1000).subdivide_midpoint(3)
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    big = folder / "million.ply"
    write_ply(big, transform_points(file_from_body("+z", "m"), V), faces=F)
    write_scan_file(folder / "front.obj", make_body_scene(options, CameraOptions(680.0, 5.0, 0.0, wall_mm=None)),
                    "mm", "+y")
    wrapped, frontal = median_times(lambda: both(big), lambda: both(folder / "front.obj"), repeats)
    return {"vertices": len(V), "faces": len(F), "seconds": wrapped, "frontal_seconds": frontal}


def main() -> None:
    repeats = repeats_argument(__doc__.splitlines()[0], 3, 1)
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-wrapped-") as tmp:
        folder = Path(tmp)
        for args in BODIES:
            rows.append(closed_body(folder, *args))
            r = rows[-1]
            nipples = " / ".join(f"{e:.1f}" for e in r["nipple_mm"])
            print(f"{r['name']}: up found {r['up_found']}, nipples {nipples} mm,"
                  " volumes " + ", ".join(f"{s} {w:.0f} vs {f:.0f} ± {u:.0f} (+{e:.0f} unseen) cc"
                                           for s, (w, f, u, e) in r["volumes"].items()), flush=True)
        cups = one_sided(folder)
        speed = million(folder, repeats)
    errors = [e for r in rows for e in r["nipple_mm"]]
    more = [(w - f) / f for r in rows for w, f, _, _ in r["volumes"].values()]
    within = [-u <= w - f <= u + e for r in rows for w, f, u, e in r["volumes"].values()]
    within_pm = [abs(w - f) <= u for r in rows for w, f, u, _ in r["volumes"].values()]
    figures = {
        "up_found": f"{sum(r['up_found'] for r in rows)}/{len(rows)}",
        "nipple_median_mm": statistics.median(errors), "nipple_worst_mm": max(errors),
        "volume_within_frontal_range": f"{sum(within)}/{len(within)}",
        "volume_within_frontal_uncertainty": f"{sum(within_pm)}/{len(within_pm)}",
        "volume_more_than_frontal": [min(more), statistics.median(more), max(more)],
        "one_sided_cup_wrapped_worst_cc": max(abs(e) for r in cups for e in r["wrapped_error_cc"]),
        "one_sided_cup_frontal_worst_cc": max(abs(r["frontal_error_cc"]) for r in cups),
        "one_sided_cup_frontal_range_holds": f"{sum(r['frontal_range_holds'] for r in cups)}/{len(cups)}",
        **{f"million_{k}": v for k, v in speed.items()},
    }
    print(f"\n| closed bodies ({len(rows)}, no --up) | measured | target | met |\n|---|---:|---:|:-:|")
    print(f"| up axis found | {figures['up_found']} | all | {'✔' if all(r['up_found'] for r in rows) else '✗'} |")
    print(f"| nipple error, median (worst) | {figures['nipple_median_mm']:.1f} mm ({max(errors):.1f} mm) | ≤ 3 mm "
          f"(≤ 8 mm) | {'✔' if figures['nipple_median_mm'] <= 3 and max(errors) <= 8 else '✗'} |")
    print(f"| volume within the frontal export's stated range (± alone, same run) | "
          f"{figures['volume_within_frontal_range']} ({figures['volume_within_frontal_uncertainty']}) | all | "
          f"{'✔' if all(within) else '✗'} |")
    spread = ", ".join(f"{m:+.1%}" for m in figures["volume_more_than_frontal"])
    print(f"| volume against the frontal export's: least, median, most | {spread} | — | |")
    print(f"| one breast a cup larger: left − right against the truth, worst (frontal export, same run) | "
          f"{figures['one_sided_cup_wrapped_worst_cc']:.0f} cc ({figures['one_sided_cup_frontal_worst_cc']:.0f} cc) | "
          f"≤ 20 cc | {'✔' if figures['one_sided_cup_wrapped_worst_cc'] <= 20 else '✗'} |")
    print(f"| one breast a cup larger: the true left − right within the frontal export's stated ranges | "
          f"{figures['one_sided_cup_frontal_range_holds']} | — | |")
    print(f"| read + both breasts, {speed['vertices']:,} vertices (frontal OBJ in the same run) | "
          f"{speed['seconds']:.2f} s ({speed['frontal_seconds']:.2f} s) | ≤ 3 s | "
          f"{'✔' if speed['seconds'] <= 3 else '✗'} |")
    print(json.dumps({k: (round(v, 3) if isinstance(v, float) else v) for k, v in figures.items()}))


if __name__ == "__main__":
    main()
