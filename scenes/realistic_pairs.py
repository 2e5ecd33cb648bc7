"""Pairs folders of realistic ptosis: MakeHuman bodies, firm then sagging, seen by the depth camera.

`write_realistic_pairs(folder, bodies, firmness_levels, side)` writes a pairs folder
(`learn.pair_folder`, docs/artefacts.md) for `breastplan train-statistical`: for each body
(a `BodyOptions`; its own firmness is ignored) the *before* is that body at firmness 1 (MakeHuman's
max: a firm breast) and each *after* the same body, pose and camera at a lower firmness — in
MakeHuman a real sagging of the breast (ptosis). Every scan is rendered by the simulated depth camera
(`scenes.realistic`: noisy frames, fused) and written as a breast PLY (mm, the before's breast frame:
base on the chest wall at z = 0, y superior, z anterior; docs/model.md §1), named
`before/body<i>.ply` and `after/body<i>-f<firmness>.ply`; pairs.csv holds one row per after:
type `ptosis`, its degree in [1, 8] and its split.

**One frame for both scans.** A clinic registers the two scans of a patient on her chest wall,
which ptosis does not move; so must we. Ingesting the after on its own does not: the breast frame's
origin is the foot of the *nipple* on the chest wall and its axes follow the chest wall fitted
under the breast's mound (`ingest.breast.breast_frame`), and sagging moves both. Measured on
640×400 scans of the right breast: the separately ingested after's frame lay 5 mm (cup 0.5,
firmness 0.5) to 61 mm (cup 0.9, firmness 0) lower and turned 1.5° to 12°, and on the most ptotic
breast the after's automatic crop lost its upper pole. Hence:

* the camera stays where it stood for the before (`make_body_scene` aims at the nipples, which
  sag; the after's scene reuses the before's `camera_from_body`): same camera, same body pose;
* only the before is ingested (`ingest_frames`, automatic isolation): its breast points and its
  camera→breast transform, which the after's camera points are taken through;
* the after keeps the *same piece of the body* as the before's crop. MakeHuman's bodies share
  their mesh, so each after point's material point is known: its closest point on the after
  mesh (triangle and barycentric coordinates), carried to the same triangle of the before mesh.
  An after point is kept when that material point lies within `2 × voxel_mm` of the before's
  crop (and the point within SURFACE_MM of its body's surface: wall and strays go), then thinned
  as ingest thins a breast (radius outliers, `voxel_mm` voxels) and, like the before, kept in
  front of the base plane (z > 0). No other threshold of the before's crop (mound footprint,
  chest-wall height) is re-applied to the after: the sagging breast leaves the firm one's mound.

A caveat of the test world: MakeHuman's firmness targets move all of a large breast's crop, its
base ring included (cup 0.9 at firmness 0: a median 34 mm along the chest), so only the crops of
small and moderate breasts hold skin that stays in place; the body around them does not move,
which is what the shared frame rests on.

**Degree.** Degrees are defined on the *extent* of a change (docs/model.md §5: the mean distance
of corresponding points), and MakeHuman blends its firmness targets piecewise linearly (anchors
min / average / max), so the sagging is not linear in firmness: firmness 0.5 moves a breast only
21–35 % as far as firmness 0 (cups 0.2–0.9). The degree is therefore linear in the true extent: with E(f) the mean
displacement (mm) of the side's MakeHuman breast-region vertices (`makehuman.breast_region`) from
the firm body to the body at firmness f, degree = 1 + 7 · E(f) / E(0): the firm breast would be
1 and each body's full sagging (firmness 0) is 8, as a condition's rows run from its first to its
last for every breast. `PairsOptions(degree="firmness")` gives the plain linear map
1 + 7 · (1 − f) instead.

Each PLY records, in a comment (`frame_from_comments`), the body → breast transform of its pair's
frame, so that the MakeHuman meshes (the truth) can be laid over both scans. Everything is
vectorised and seeded: scan k of body i (k = 0 the before) uses noise seed `seed + 1000 i + k`.
"""
from __future__ import annotations

import csv
import io
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Sequence

import numpy as np

from breastplan import transform_points, write_ply
from breastplan.atomic import atomic_open
from breastplan.options import SIDES, IngestOptions, OptionError

from .makehuman import Body, BodyOptions, breast_region, make_body
from .realistic import BodyScene, CameraOptions, make_body_scene

FIRM = 1.0
"""Firmness of every before (MakeHuman's max)."""
SAGGED = 0.0
"""Firmness whose sagging is degree 8 (MakeHuman's min)."""
DEGREES = (1.0, 8.0)
DEGREE_MAPS = ("extent", "firmness")
SURFACE_MM = 6.0
"""An after point further than this from its body's surface is not the body (the wall, a stray)."""
OUTLIER_POINTS, OUTLIER_RADIUS_MM = 4, 5.0
"""Radius-outlier removal as ingest's (ingest/pipeline.py)."""
FRAME_COMMENT = "breastplan realistic pairs: body_to_breast (MakeHuman body frame to this breast frame, mm, row-major)"
PAIRS_CSV = "pairs.csv"
HEADER = ("before", "after", "type", "degree", "split")


@dataclass(frozen=True)
class PairsOptions:
    """How the pairs are scanned: the camera, depth frames fused per scan, the noise seed, the
    indices of the bodies whose pairs form the test split, the degree map ("extent" or
    "firmness", module docstring) and ingest's voxel size (mm)."""

    camera: CameraOptions = field(default_factory=lambda: CameraOptions(resolution="640x400"))
    frames: int = 3
    seed: int = 0
    test: tuple[int, ...] = ()
    degree: str = "extent"
    voxel_mm: float = 2.0

    def __post_init__(self):
        if self.frames < 1:
            raise OptionError("frames", f"a scan fuses at least 1 frame, got {self.frames}")
        if self.degree not in DEGREE_MAPS:
            raise OptionError("degree", f"the degree map is {' or '.join(DEGREE_MAPS)}, not {self.degree!r}")
        object.__setattr__(self, "test", tuple(int(i) for i in self.test))


@dataclass(frozen=True)
class Scanned:
    """One body's pairs: the before's points and, per firmness level, the after's points and degree
    (mm, the before's breast frame)."""

    before: np.ndarray
    afters: dict[float, np.ndarray]
    degrees: dict[float, float]
    body_to_breast: np.ndarray          # (4, 4) MakeHuman body frame → the before's breast frame, mm


def write_realistic_pairs(folder: str | Path, bodies: Sequence[BodyOptions], firmness_levels: Sequence[float],
                          side: str = "right", options: PairsOptions = PairsOptions()) -> Path:
    """Write a pairs folder of realistic ptosis (module docstring); the path of its pairs.csv.

    `bodies`: the bodies (their firmness ignored); `firmness_levels`: the afters' firmness, each in
    [0, 1). OptionError (a ValueError) for bad arguments; BadInputError if ingest finds no breast on
    a before scan."""
    folder = Path(folder)
    levels = _levels(firmness_levels)
    if side not in SIDES:
        raise OptionError("side", f"'{side}' is not a side; choose left or right")
    if not bodies:
        raise OptionError("bodies", "no bodies to scan")
    if any(not 0 <= i < len(bodies) for i in options.test) or len(set(options.test)) >= len(bodies):
        raise OptionError("test", f"test bodies {list(options.test)}: give indices of some (not all) of the "
                                  f"{len(bodies)} bodies")
    lines = [list(HEADER)]
    for i, body in enumerate(bodies):
        scanned = scan_pairs(body, levels, side, options, seed=options.seed + 1000 * i)
        name = f"body{i:02d}"
        described = _describe(body)
        frame = frame_comment(scanned.body_to_breast)
        before = Path("before") / f"{name}.ply"
        write_ply(folder / before, scanned.before, comments=[
            f"breastplan realistic pairs: before, MakeHuman {described}, firmness {FIRM:g}, {side} breast",
            "mm, breast frame of this before scan (ingest_frames); its afters share it", frame])
        for f in levels:
            after = Path("after") / f"{name}-f{f:.3f}.ply"
            degree = scanned.degrees[f]
            write_ply(folder / after, scanned.afters[f], comments=[
                f"breastplan realistic pairs: after, MakeHuman {described}, firmness {f:g}, {side} breast, "
                f"ptosis degree {degree:.4f} ({options.degree})",
                f"mm, breast frame of {before.as_posix()} (same camera and pose; the before's crop, by mesh correspondence)",
                frame])
            lines.append([before.as_posix(), after.as_posix(), "ptosis", f"{degree:.4f}",
                          "test" if i in options.test else "train"])
    text = io.StringIO()
    csv.writer(text, lineterminator="\n").writerows(lines)
    path = folder / PAIRS_CSV
    with atomic_open(path) as fh:                 # written last: a folder with a table is complete
        fh.write(text.getvalue().encode())
    return path


def scan_pairs(body: BodyOptions, firmness_levels: Sequence[float], side: str = "right",
               options: PairsOptions = PairsOptions(), seed: int | None = None) -> Scanned:
    """One body firm (the before, ingested) and at each firmness level (afters in the before's frame
    and crop); `seed` defaults to options.seed."""
    from scipy.spatial import cKDTree

    from breastplan.ingest.pipeline import ingest_frames
    from breastplan.ingest.recording import DepthFrames

    levels = _levels(firmness_levels)
    seed = options.seed if seed is None else seed
    camera = options.camera
    firm = make_body_scene(replace(body, firmness=FIRM), camera)
    ingested = ingest_frames(DepthFrames(firm.frames(options.frames, seed=seed), camera.K, "synthetic"),
                             IngestOptions(side=side, voxel_mm=options.voxel_mm))
    to_breast = ingested.input_to_breast
    body_to_breast = to_breast @ firm.camera_from_body
    crop = transform_points(np.linalg.inv(body_to_breast), ingested.points)       # the before's crop, body frame
    crop_tree = cKDTree(crop)
    region = breast_region(side)
    sagged = make_body(replace(body, firmness=SAGGED)).vertices[region]
    full = _extent(firm.body.vertices[region], sagged)
    afters, degrees = {}, {}
    for k, f in enumerate(levels, start=1):
        made = make_body(replace(body, firmness=f))
        scene = BodyScene(made, camera, firm.camera_from_body)                  # the before's camera pose
        points = _camera_points(scene.frames(options.frames, seed=seed + k), camera.K)
        at_body = transform_points(np.linalg.inv(firm.camera_from_body), points)
        material, gap = _material_points(made, firm.body, at_body)
        near, _ = crop_tree.query(material, distance_upper_bound=2.0 * options.voxel_mm)
        kept = points[(gap <= SURFACE_MM) & np.isfinite(near)]
        after = transform_points(to_breast, _thin(kept, options.voxel_mm))
        afters[f] = after[after[:, 2] > 0.0]                                   # in front of the base, as ingest crops
        degrees[f] = _degree(f, _extent(firm.body.vertices[region], made.vertices[region]), full, options.degree)
    return Scanned(ingested.points, afters, degrees, body_to_breast)


def frame_comment(body_to_breast: np.ndarray) -> str:
    """The PLY comment that records where the breast frame sits on the MakeHuman body (`frame_from_comments`)."""
    return f"{FRAME_COMMENT} " + " ".join(f"{v:.17g}" for v in np.ravel(body_to_breast))


def frame_from_comments(comments) -> np.ndarray | None:
    """The (4, 4) body → breast transform a realistic pair's PLY records, or None."""
    for line in comments:
        if line.startswith(FRAME_COMMENT):
            return np.array([float(v) for v in line[len(FRAME_COMMENT):].split()]).reshape(4, 4)
    return None


def _levels(firmness_levels: Sequence[float]) -> tuple[float, ...]:
    levels = tuple(float(f) for f in firmness_levels)
    if not levels:
        raise OptionError("firmness_levels", "no firmness levels for the afters")
    if any(not SAGGED <= f < FIRM for f in levels) or len(set(levels)) < len(levels):
        raise OptionError("firmness_levels", f"firmness levels {list(levels)}: each after's firmness lies in "
                                             f"[{SAGGED:g}, {FIRM:g}) (the before is {FIRM:g}), none twice")
    return levels


def _extent(before: np.ndarray, after: np.ndarray) -> float:
    """Mean distance (mm) of corresponding vertices."""
    return float(np.linalg.norm(after - before, axis=1).mean())


def _degree(firmness: float, extent: float, full: float, how: str) -> float:
    if how == "firmness":
        value = DEGREES[0] + (DEGREES[1] - DEGREES[0]) * (FIRM - firmness) / (FIRM - SAGGED)
    else:
        if not full > 0:
            raise OptionError("bodies", "a body whose breast firmness changes nothing has no ptosis degrees")
        value = DEGREES[0] + (DEGREES[1] - DEGREES[0]) * extent / full
    return float(np.clip(value, *DEGREES))


def _camera_points(depth: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Fused depth frames → camera points (mm), as ingest fuses and back-projects them."""
    from breastplan.ingest.depth import depth_range, fuse, to_points

    image = fuse(depth)
    return to_points(image, K, *depth_range(image))


def _material_points(made: Body, firm: Body, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For points (body frame) near the surface of `made`: the same material points on `firm` (the
    closest point of `made`'s mesh, carried by its triangle and barycentric coordinates to `firm`'s
    mesh, which shares its faces), and each point's distance to `made`'s surface (mm)."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(made.vertices.astype(np.float32)),
                        o3d.core.Tensor(made.faces.astype(np.uint32)))
    hit = scene.compute_closest_points(o3d.core.Tensor(points.astype(np.float32)))
    closest = hit["points"].numpy().astype(float)
    triangle = made.faces[hit["primitive_ids"].numpy().astype(np.int64)]
    u, v = hit["primitive_uvs"].numpy().astype(float).T
    weights = np.column_stack([1.0 - u - v, u, v])                         # open3d: p = (1-u-v) a + u b + v c
    material = np.einsum("nk,nkd->nd", weights, firm.vertices[triangle])
    return material, np.linalg.norm(points - closest, axis=1)


def _thin(points: np.ndarray, voxel_mm: float) -> np.ndarray:
    """Radius outliers removed and voxel-downsampled, as ingest thins a breast crop."""
    import open3d as o3d

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    cloud, _ = cloud.remove_radius_outlier(nb_points=OUTLIER_POINTS, radius=OUTLIER_RADIUS_MM)
    return np.asarray(cloud.voxel_down_sample(voxel_mm).points)


def _describe(body: BodyOptions) -> str:
    values = {k: v for k, v in asdict(body).items() if k != "firmness"}
    return ", ".join(f"{k} {v}" for k, v in values.items() if v not in ({}, None))
