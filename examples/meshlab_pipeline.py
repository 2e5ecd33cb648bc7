"""A scan through pymeshlab and breastplan's filters: Poisson surface, breast fit, measures, a ptosis.

    python examples/meshlab_pipeline.py                      # a MakeHuman body it scans first
    python examples/meshlab_pipeline.py SCAN.ply --side right --up +z --units m --out meshes/

1. The scan goes into a pymeshlab MeshSet (metres are scaled to mm). A point cloud — the default
   scan is one, the depth pixels of a realistic MakeHuman body seen from the front, as
   `breastplan scan-synth --body makehuman --no-wall --scan-file` writes it — is reconstructed:
   normals (`compute_normal_for_point_clouds`, oriented towards the viewer, whom
   `breastplan.ingest.pipeline.viewing_frame` places in front of the trunk), screened Poisson
   (`generate_surface_reconstruction_screened_poisson`, one thread), then the Poisson surface trimmed
   to within about a cell of the scan's points (Poisson closes the surface behind the body too).
2. breastplan's filters on the MeshSet (`breastplan.meshlab`): `compute_breast_isolation` on the
   surface, `compute_breast_fit` on the isolated breast, `get_breast_measures` on the fit,
   `apply_breast_ptosis(degree=3)` on it. Each mesh a filter gives becomes the current mesh.
3. `get_hausdorff_distance` compares the breast's scan points with the fit, the fit with the scan
   (its base cap, on the chest wall behind the breast, lies off the scan: hence its larger maximum)
   and the ptosis with the fit.

It prints a short table (`--json`: one JSON object); `--out DIR` also saves the meshes as PLY.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

DEFAULT_SCAN = Path(tempfile.gettempdir()) / "breastplan-example" / "makehuman-scan.ply"
"""Where the default scan is written, and found again by later runs."""
POISSON_DEPTH, POISSON_SCALE = 8, 1.1
"""Octree depth of the Poisson reconstruction and the scale of its cube over the scan's largest side:
its cells are POISSON_SCALE × the largest side / 2**POISSON_DEPTH across (about 4 mm on a body)."""
TRIM_CELLS = 1.25
"""Poisson vertices farther from the scan than this many cells are cut off: Poisson closes the surface
behind the body, and a wider margin leaves a flange round the body's outline that changes where the
trunk and the breasts are found."""


def default_scan() -> tuple[Path, dict]:
    """The default scan (a MakeHuman body of average build, arms in A-pose, seen from 650 mm, no
    wall; mm, up +y), made if missing, and its true nipples (mm, the scan's frame)."""
    from breastplan.scenes.makehuman import BodyOptions, make_body
    from breastplan.scenes.realistic import CameraOptions, make_body_scene, write_scan_file

    if not DEFAULT_SCAN.is_file():
        scene = make_body_scene(BodyOptions(), CameraOptions(wall_mm=None))
        write_scan_file(DEFAULT_SCAN, scene, units="mm", up="+y")
    return DEFAULT_SCAN, make_body(BodyOptions()).nipples       # body frame = the file's frame (mm, up +y)


def load(ms, path: Path, units: str) -> float:
    """Load the scan into `ms`, scaled to mm; the mm per unit of the file."""
    from breastplan.units import extent

    ms.load_new_mesh(str(path))
    size = extent(ms.current_mesh().vertex_matrix())
    scale = {"mm": 1.0, "m": 1000.0}.get(units, 1000.0 if size <= 3.0 else 1.0)
    if scale != 1.0:
        ms.compute_matrix_from_scaling_or_normalization(axisx=scale, axisy=scale, axisz=scale, freeze=True)
    return scale


def reconstruct(ms, up: str) -> dict:
    """The current point cloud → a screened Poisson surface trimmed to the scan (the new current mesh)."""
    from breastplan import transform_points
    from breastplan.ingest.pipeline import viewing_frame

    scan_id = ms.current_mesh_id()
    points = ms.current_mesh().vertex_matrix()
    view, _ = viewing_frame(points, up)                         # z away from the viewer
    viewer = transform_points(np.linalg.inv(view), transform_points(view, points).mean(0) - [0.0, 0.0, 2000.0])
    ms.compute_normal_for_point_clouds(k=10, flipflag=True, viewpos=viewer)
    ms.generate_surface_reconstruction_screened_poisson(depth=POISSON_DEPTH, scale=POISSON_SCALE, preclean=True,
                                                        threads=1)    # its threads fight other work badly
    poisson_id = ms.current_mesh_id()
    trim = TRIM_CELLS * POISSON_SCALE * float(np.ptp(points, axis=0).max()) / 2**POISSON_DEPTH
    ms.compute_scalar_by_distance_from_another_mesh_per_vertex(measuremesh=poisson_id, refmesh=scan_id,
                                                               signeddist=False)
    ms.compute_selection_by_condition_per_vertex(condselect=f"q > {trim}")
    ms.meshing_remove_selected_vertices()
    mesh = ms.current_mesh()
    return {"vertices": mesh.vertex_number(), "faces": mesh.face_number(), "trim_mm": trim}


def hausdorff(ms, sampled: int, target: int) -> dict:
    """Distances (mm) from every vertex of mesh `sampled` to the surface of mesh `target`."""
    r = ms.get_hausdorff_distance(sampledmesh=sampled, targetmesh=target,
                                  samplenum=ms.mesh(sampled).vertex_number())
    return {"mean_mm": float(r["mean"]), "rms_mm": float(r["RMS"]), "max_mm": float(r["max"])}


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scan", nargs="?", type=Path, help="A scan file (PLY, OBJ, STL, …); default: a MakeHuman "
                        f"body it scans into {DEFAULT_SCAN} (or finds there).")
    parser.add_argument("--side", choices=("left", "right"), default="left", help="The breast (default left).")
    parser.add_argument("--units", choices=("auto", "mm", "m"), default="auto", help="The scan's units.")
    parser.add_argument("--up", default="+y", choices=("+x", "-x", "+y", "-y", "+z", "-z"),
                        help="The scan's axis towards the head (default +y).")
    parser.add_argument("--degree", type=float, default=3.0, help="The ptosis's degree, 1..8 (default 3).")
    parser.add_argument("--out", type=Path, help="Also save the meshes here as PLY files.")
    parser.add_argument("--json", action="store_true", help="Print one JSON object instead of the table.")
    args = parser.parse_args(argv)

    import pymeshlab

    from breastplan import meshlab

    start = time.perf_counter()
    truth = None
    path = args.scan
    if path is None:
        path, nipples = default_scan()
        truth = nipples[args.side]
    ms = pymeshlab.MeshSet()
    scale = load(ms, path, args.units)
    scan = ms.current_mesh()
    out = {"scan": str(path), "points": scan.vertex_number(), "faces": scan.face_number(), "mm_per_unit": scale}
    if scan.is_point_cloud():
        out["poisson"] = reconstruct(ms, args.up)
    surface_id = ms.current_mesh_id()
    where = {"side": args.side, "units": "mm", "up": args.up}
    meshlab.compute_breast_isolation(ms, **where)
    breast_id = ms.current_mesh_id()
    meshlab.compute_breast_fit(ms, **where)
    fit_id = ms.current_mesh_id()
    measures = meshlab.get_breast_measures(ms, **where)
    meshlab.apply_breast_ptosis(ms, degree=args.degree, **where)
    ptosis_id = ms.current_mesh_id()
    after = meshlab.get_breast_measures(ms, **where)
    out.update({
        "side": args.side, "breast_points": ms.mesh(breast_id).vertex_number(),
        "measures": {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in measures.items()},
        "ptosis": {"degree": args.degree, "nipple_mm": after["nipple_mm"].tolist(),
                   "nipple_drop_mm": None},
        "hausdorff": {"breast points → fit": hausdorff(ms, breast_id, fit_id),
                      "fit → scan": hausdorff(ms, fit_id, surface_id),
                      f"ptosis-{args.degree:g} → fit": hausdorff(ms, ptosis_id, fit_id)},
    })
    if truth is not None:
        out["true_nipple_mm"] = truth.tolist()
        out["nipple_error_mm"] = float(np.linalg.norm(measures["nipple_mm"] - truth))
    if args.up[1] in "xyz":                                  # the ptosis's drop along the scan's up axis
        axis = np.zeros(3)
        axis["xyz".index(args.up[1])] = 1.0 if args.up[0] == "+" else -1.0
        out["ptosis"]["nipple_drop_mm"] = float((measures["nipple_mm"] - after["nipple_mm"]) @ axis)
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        for name, i in (("surface", surface_id), ("breast", breast_id), ("fit", fit_id), ("ptosis", ptosis_id)):
            ms.set_current_mesh(i)
            ms.save_current_mesh(str(args.out / f"{name}.ply"))
        out["saved"] = str(args.out)
    out["seconds"] = round(time.perf_counter() - start, 2)
    if args.json:
        print(json.dumps(out))
    else:
        print_table(out)
    return out


def print_table(out: dict) -> None:
    m = out["measures"]
    kind = "point cloud" if not out["faces"] else f"mesh, {out['faces']} faces"
    print(f"scan      {out['scan']} ({kind}, {out['points']} vertices)")
    if "poisson" in out:
        p = out["poisson"]
        print(f"poisson   {p['vertices']} vertices, {p['faces']} faces (depth {POISSON_DEPTH}, trimmed "
              f"{p['trim_mm']:.1f} mm from the scan)")
    print(f"breast    {out['side']}: {out['breast_points']} points; nipple at "
          + ", ".join(f"{v:.1f}" for v in m["nipple_mm"]) + " mm"
          + (f" ({out['nipple_error_mm']:.1f} mm from the true nipple)" if "nipple_error_mm" in out else ""))
    print()
    print(f"{'measure':<24}{'fit':>10}")
    for key in ("volume_cc", "upper_pole_cc", "lower_pole_cc", "width_mm", "projection_mm", "rms_mm",
                "normalised_residual"):
        print(f"{key:<24}{m[key]:>10.4g}")
    drop = out["ptosis"]["nipple_drop_mm"]
    print(f"{'ptosis nipple drop mm':<24}{drop:>10.3g}  (degree {out['ptosis']['degree']:g})")
    print()
    print(f"{'hausdorff (mm)':<24}{'mean':>8}{'rms':>8}{'max':>8}")
    for name, h in out["hausdorff"].items():
        print(f"{name:<24}{h['mean_mm']:>8.2f}{h['rms_mm']:>8.2f}{h['max_mm']:>8.2f}")
    print(f"\n{out['seconds']:.1f} s")


if __name__ == "__main__":
    main(sys.argv[1:])
