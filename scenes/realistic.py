"""The realistic synthetic scanner: a MakeHuman body (head, neck, arms) seen by an OAK-like camera.

The camera looks at the midpoint of the nipples from `distance_mm`, pitched (positive: from
above, looking down) and turned about the body's vertical axis (yaw, positive: from the
patient's left); a wall may stand behind her. The truth it writes: both nipples, the breast
regions and the exact volume of each half of the closed body, with the body mesh, all in
camera mm. It can also write what the camera sees as a scan file (`write_scan_file`): the
noise-free depth pixels back-projected (PLY) or the body's visible triangles (OBJ), in the
body frame turned so that the body's up lies on a chosen axis, in mm or m.

open3d (and the renderer) are imported by the functions that render, so that a command can
check its camera options without that cost.
"""
from __future__ import annotations

import tempfile
from dataclasses import asdict, dataclass, field, replace
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from breastplan import load_npz, save_npz, transform_points, write_ply
from breastplan.atomic import Stage, atomic_set
from breastplan.options import SIDES, UP_AXES, OptionError

from .makehuman import Body, BodyOptions, breast_region, make_body

if TYPE_CHECKING:
    import open3d as o3d

TRUTH_SCHEMA = "breastplan.body-truth/1"
RESOLUTIONS = {"640x400": (640, 400), "800x600": (800, 600), "1280x800": (1280, 800)}
HFOV_DEG = 72.0
"""Horizontal field of view of the depth camera (an OAK-D's stereo pair)."""
WALL_MM = (0.0, 3000.0)
"""Range of the gap between the back and the wall."""
SCAN_SUFFIXES = (".ply", ".obj", ".glb")
SCAN_UNITS = {"mm": 1.0, "m": 1000.0}
"""Units of a scan file → millimetres per unit."""
VISIBLE_TOLERANCE_MM = 1.0
"""A vertex is visible when the camera's ray towards it hits nothing nearer than this before it."""
CORE_MM = 50.0
"""`crop_against_truth`: the breast's core is the skin the camera sees within this of the true nipple."""
HELD_MM = 4.0
"""`crop_against_truth`: a pixel of the core is held when a cropped point lies within this of it."""


@dataclass(frozen=True)
class CameraOptions:
    """Where the camera stands and what it is: mm, degrees, pixels. A value out of range raises
    OptionError (a ValueError) naming the field."""

    distance_mm: float = 650.0
    pitch_deg: float = 0.0
    yaw_deg: float = 0.0
    resolution: str = "800x600"
    noise_mm: float = 1.0
    wall_mm: float | None = 400.0       # gap between the back and a wall behind; None: no wall

    def __post_init__(self):
        if not 400.0 <= self.distance_mm <= 1500.0:
            raise OptionError("distance_mm", f"the distance must be 400..1500 mm, got {self.distance_mm}")
        for name in ("pitch_deg", "yaw_deg"):
            if not -30.0 <= getattr(self, name) <= 30.0:
                raise OptionError(name, f"the {name[:-4]} must be −30..30 degrees, got {getattr(self, name)}")
        if self.resolution not in RESOLUTIONS:
            raise OptionError("resolution", f"the resolution must be one of {', '.join(RESOLUTIONS)}, "
                                            f"got {self.resolution!r}")
        if not 0.0 <= self.noise_mm <= 10.0:
            raise OptionError("noise_mm", f"the noise must be 0..10 mm, got {self.noise_mm}")
        if self.wall_mm is not None and not WALL_MM[0] <= self.wall_mm <= WALL_MM[1]:
            raise OptionError("wall_mm", f"the wall must stand 0..3000 mm behind the back, got {self.wall_mm}")

    @property
    def size(self) -> tuple[int, int]:
        return RESOLUTIONS[self.resolution]

    @property
    def K(self) -> np.ndarray:
        w, h = self.size
        f = 0.5 * w / np.tan(np.radians(HFOV_DEG / 2))
        return np.array([[f, 0.0, w / 2], [0.0, f, h / 2], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class BodyScene:
    """A posed body, its camera and its surroundings."""

    body: Body
    camera: CameraOptions
    camera_from_body: np.ndarray       # (4, 4) mm
    meta: dict = field(default_factory=dict)

    def meshes(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Camera-frame meshes: the body, then the wall if any."""
        out = [(transform_points(self.camera_from_body, self.body.vertices), self.body.faces)]
        if self.camera.wall_mm is not None:
            z = float(self.body.vertices[:, 2].min()) - self.camera.wall_mm
            wall = np.array([[-4000, -4000, z], [4000, -4000, z], [4000, 4000, z], [-4000, 4000, z]])
            out.append((transform_points(self.camera_from_body, wall), np.array([[0, 1, 2], [0, 2, 3]])))
        return out

    def raycasting(self) -> o3d.t.geometry.RaycastingScene:
        """The camera-frame meshes in a ray-casting scene; geometry ids 0 body, 1 wall."""
        import open3d as o3d

        rc = o3d.t.geometry.RaycastingScene()
        for V, F in self.meshes():
            rc.add_triangles(o3d.core.Tensor(V.astype(np.float32)), o3d.core.Tensor(F.astype(np.uint32)))
        return rc

    def render(self) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free depth (H, W) mm, NaN where nothing is measured, and geometry ids (0 body, 1 wall)."""
        from .rendering import cast_depth

        return cast_depth(self.raycasting(), self.camera.K, *self.camera.size)

    @cached_property
    def colour(self) -> np.ndarray:
        """(H, W, 3) uint8 RGB of the colour camera aligned to depth: her skin shaded, her areolae darker (cast
        once: a recording and a scan file of the scene share it)."""
        from .rendering import cast_colour

        return cast_colour(self.raycasting(), self.meshes(), self.camera.K, *self.camera.size,
                           np.stack(list(self.nipples_camera().values())))

    def frames(self, n_frames: int, seed: int = 0) -> np.ndarray:
        """(N, H, W) uint16 noisy depth frames, mm."""
        from .rendering import noisy_frames

        return noisy_frames(self.render()[0], self.camera.noise_mm, n_frames, seed)

    def nipples_camera(self) -> dict[str, np.ndarray]:
        return {s: transform_points(self.camera_from_body, p[None])[0] for s, p in self.body.nipples.items()}


def make_body_scene(body: BodyOptions = BodyOptions(), camera: CameraOptions = CameraOptions()) -> BodyScene:
    """The body of `body`, seen by `camera`."""
    made = make_body(body)
    target = 0.5 * (made.nipples["left"] + made.nipples["right"])
    return BodyScene(made, camera, camera_pose(target, camera))


def make_back_scene(body: BodyOptions = BodyOptions(), camera: CameraOptions = CameraOptions()) -> BodyScene:
    """The body of `body` turned 180° about her vertical axis (Y), in front of the camera that would
    see her front: a scene with no breast in view. Her body frame turns with her (X to her right,
    Z posterior); a rotation, so the faces stay outward."""
    front = make_body_scene(body, camera)
    return BodyScene(replace(front.body, vertices=front.body.vertices * [-1.0, 1.0, -1.0]), camera,
                     front.camera_from_body)


def camera_pose(target: np.ndarray, camera: CameraOptions) -> np.ndarray:
    """camera_from_body (4, 4): at `distance_mm` from `target`, pitched down by `pitch_deg`,
    turned by `yaw_deg` about the body's vertical axis (Y)."""
    p, y = np.radians(camera.pitch_deg), np.radians(camera.yaw_deg)
    direction = np.array([np.cos(p) * np.sin(y), np.sin(p), np.cos(p) * np.cos(y)])  # target → camera
    centre = target + camera.distance_mm * direction
    z = -direction
    x = np.cross(z, [0.0, 1.0, 0.0])          # the patient's left appears on the image's right
    x /= np.linalg.norm(x)
    R = np.vstack([x, np.cross(z, x), z])
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, -R @ centre
    return T


# --- what the camera sees, as a scan file ------------------------------------------------
UP_ROTATIONS = {
    "+y": ((1, 0, 0), (0, 1, 0), (0, 0, 1)),
    "-y": ((-1, 0, 0), (0, -1, 0), (0, 0, 1)),      # half a turn about Z
    "+z": ((1, 0, 0), (0, 0, -1), (0, 1, 0)),       # a quarter turn about X: Y → +Z, Z → −Y
    "-z": ((1, 0, 0), (0, 0, 1), (0, -1, 0)),       # Y → −Z, Z → +Y
    "+x": ((0, 1, 0), (-1, 0, 0), (0, 0, 1)),       # a quarter turn about Z: Y → +X, X → −Y
    "-x": ((0, -1, 0), (1, 0, 0), (0, 0, 1)),       # Y → −X, X → +Y
}
"""Up axis of a scan file → the rotation (rows: file axes in body coordinates) that puts the body's up there."""
assert set(UP_ROTATIONS) == set(UP_AXES)
_BODY_DIRECTIONS = {(0, 1): "left", (0, -1): "right", (1, 1): "up", (1, -1): "down", (2, 1): "front", (2, -1): "back"}


def turned(deg: float) -> np.ndarray:
    """(4, 4) the body frame turned `deg` about her vertical axis (Y; positive: her left side forward)."""
    a = np.radians(deg)
    T = np.eye(4)
    T[0, 0] = T[2, 2] = np.cos(a)
    T[0, 2], T[2, 0] = np.sin(a), -np.sin(a)
    return T


def file_from_body(up: str, units: str) -> np.ndarray:
    """(4, 4) body frame (mm) → a scan file's frame: turned so that the body's up (Y) lies on `up`
    (one of options.UP_AXES), scaled to `units` (mm or m)."""
    T = np.eye(4)
    T[:3, :3] = np.array(UP_ROTATIONS[up], float) / SCAN_UNITS[units]
    return T


def file_axes(up: str) -> str:
    """Where a scan file's axes point on the body, e.g. 'x left, y back, z up' for up +z."""
    rows = np.array(UP_ROTATIONS[up])
    body_axis = np.abs(rows).argmax(1)                 # each file axis is ± one body axis
    sign = rows[np.arange(3), body_axis]
    return ", ".join(f"{axis} {_BODY_DIRECTIONS[int(k), int(s)]}" for axis, k, s in zip("xyz", body_axis, sign))


def visible_points(scene: BodyScene) -> tuple[np.ndarray, np.ndarray]:
    """The noise-free depth pixels back-projected: (N, 3) camera mm, row by row, and their
    geometry ids (0 body, 1 wall)."""
    depth, ids = scene.render()
    K = scene.camera.K
    v, u = np.nonzero(np.isfinite(depth))
    z = depth[v, u]
    return np.column_stack([(u - K[0, 2]) * z / K[0, 0], (v - K[1, 2]) * z / K[1, 1], z]), ids[v, u]


def crop_against_truth(scene: BodyScene, side: str, points_camera) -> dict[str, float]:
    """How an isolated breast's points ((N, 3) camera mm) compare with the body's own breast:
    `on_breast`, the share of them whose nearest body vertex is one of the breast's (`breast_region`),
    and `core_held`, the share of the body pixels the camera sees within CORE_MM of the true
    nipple that lie within HELD_MM of one of them."""
    from scipy.spatial import cKDTree

    points = np.asarray(points_camera, float)
    body = transform_points(scene.camera_from_body, scene.body.vertices)
    region = np.zeros(len(body), bool)
    region[breast_region(side)] = True
    seen, ids = visible_points(scene)
    core = seen[(ids == 0) & (np.linalg.norm(seen - scene.nipples_camera()[side], axis=1) <= CORE_MM)]
    return {"on_breast": float(region[cKDTree(body).query(points)[1]].mean()),
            "core_held": float(np.mean(cKDTree(points).query(core)[0] <= HELD_MM))}


def visible_faces(scene: BodyScene) -> np.ndarray:
    """Indices (into body.faces) of the body triangles the camera sees whole: facing it at an
    incidence under rendering.GRAZING_DEG, their three vertices inside the image and hidden by nothing."""
    import open3d as o3d

    from .rendering import GRAZING_DEG

    V, F = scene.meshes()[0]
    dist = np.linalg.norm(V, axis=1)
    dirs = V / dist[:, None]
    rays = np.hstack([np.zeros_like(dirs), dirs]).astype(np.float32)
    first = scene.raycasting().cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()   # inf: nothing hit
    w, h = scene.camera.size
    uvw = V @ scene.camera.K.T
    front = uvw[:, 2] > 0
    u, v = (uvw[:, :2] / np.where(front, uvw[:, 2], 1.0)[:, None]).T
    seen = front & (u >= -0.5) & (u <= w - 0.5) & (v >= -0.5) & (v <= h - 0.5) & (first >= dist - VISIBLE_TOLERANCE_MM)
    tri = V[F]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])     # outward: the body mesh is oriented
    centre = tri.mean(1)
    with np.errstate(invalid="ignore", divide="ignore"):               # degenerate triangles: NaN, not seen
        cos_inc = -np.sum(normal * centre, 1) / (np.linalg.norm(normal, axis=1) * np.linalg.norm(centre, axis=1))
    return np.flatnonzero(seen[F].all(1) & (cos_inc >= np.cos(np.radians(GRAZING_DEG))))


def write_scan_file(path: str | Path, scene: BodyScene, units: str = "mm", up: str = "+y",
                    stage: Stage | None = None) -> dict:
    """Write what the camera sees as a scan file: a `.ply` holds the noise-free depth pixels (body and wall)
    back-projected, each with the colour seen there (`BodyScene.colour`); an `.obj` the body's visible
    triangles (`visible_faces`), textured as a scanner textures its mesh: the colour camera's image as
    `NAME.png`, its material `NAME.mtl` beside it, each vertex's texture coordinate where the camera sees it;
    a `.glb` the same triangles, each vertex with the colour seen there (open3d's glTF writer).
    All or nothing: each file is written to `stage(file)` (an `atomic_set`'s), or in a set of its own.
    Coordinates: the body frame turned by `file_from_body(up, units)`. Returns the counts written
    (points or vertices, faces)."""
    path = Path(path)
    if stage is None:
        with atomic_set() as own:
            return write_scan_file(path, scene, units, up, own)
    suffix = _checked_suffix(path, units, up)
    frame = f"units {units}; body frame turned so that its up lies on {up}: {file_axes(up)}"
    if suffix == ".ply":
        from breastplan.ingest.depth import colours_at

        points, ids = visible_points(scene)
        to_file = file_from_body(up, units) @ np.linalg.inv(scene.camera_from_body)
        what = "body and wall" if (ids == 1).any() else "body"
        write_ply(stage(path), transform_points(to_file, points), colours=colours_at(points, scene.camera.K,
                                                                                    scene.colour),
                  comments=[f"breastplan scan-synth: realistic {what}, noise-free depth pixels back-projected, with "
                            "the colour seen at each", frame])
        return {"points": len(points), "faces": 0}
    from PIL import Image

    used, faces = np.unique(scene.body.faces[visible_faces(scene)], return_inverse=True)
    V = transform_points(file_from_body(up, units), scene.body.vertices[used])
    if suffix == ".glb":
        from breastplan.ingest.depth import colours_at

        seen_at = transform_points(scene.camera_from_body, scene.body.vertices[used])
        _write_glb(stage(path), V, faces.reshape(-1, 3), colours_at(seen_at, scene.camera.K, scene.colour))
        return {"points": len(V), "faces": faces.size // 3}
    seen = transform_points(scene.camera_from_body, scene.body.vertices[used]) @ scene.camera.K.T
    w, h = scene.camera.size
    texture = (seen[:, :2] / seen[:, 2:] + 0.5) / [w, h]                # pixel centres at (i + ½) / size
    texture[:, 1] = 1.0 - texture[:, 1]                                  # OBJ's v runs up the image
    Image.fromarray(scene.colour).save(stage(path.with_suffix(".png")), format="PNG")
    stage(path.with_suffix(".mtl")).write_text(f"newmtl skin\nKd 1 1 1\nmap_Kd {path.stem}.png\n")
    text = (f"# breastplan scan-synth: realistic body, the triangles the camera sees, textured by its colour "
            f"camera\n# {frame}\nmtllib {path.stem}.mtl\n"
            + ("v {:.6f} {:.6f} {:.6f}\n" * len(V)).format(*V.ravel())
            + ("vt {:.6f} {:.6f}\n" * len(V)).format(*texture.ravel()) + "usemtl skin\n"
            + ("f {}/{} {}/{} {}/{}\n" * (faces.size // 3)).format(*np.repeat(faces.ravel() + 1, 2)))
    stage(path).write_bytes(text.encode("ascii"))
    return {"points": len(V), "faces": faces.size // 3}


def write_closed_scan(path: str | Path, body: Body, units: str = "mm", up: str = "+y",
                      stage: Stage | None = None, turn_deg: float = 0.0) -> dict:
    """Write her whole closed body mesh — front, sides and back, as a 360° scanner exports it — as PLY (binary),
    OBJ (text) or GLB (open3d's writer), to `stage(path)` or in a set of its own. Coordinates: the body frame
    turned `turn_deg` about her vertical axis (`turned`), then by `file_from_body(up, units)`, as `write_scan_file`'s
    for no turn. Returns the counts written (vertices, faces)."""
    path = Path(path)
    if stage is None:
        with atomic_set() as own:
            return write_closed_scan(path, body, units, up, own, turn_deg)
    suffix = _checked_suffix(path, units, up)
    V, F = transform_points(file_from_body(up, units) @ turned(turn_deg), body.vertices), body.faces
    if suffix == ".ply":
        write_ply(stage(path), V, faces=F, comments=["breastplan scan-synth: realistic body, its whole closed mesh",
                                                     f"units {units}; body frame turned {turn_deg:g}° about her "
                                                     f"vertical, then so that its up lies on {up}"])
    elif suffix == ".glb":
        _write_glb(stage(path), V, F)
    else:
        stage(path).write_text(("v {:.6f} {:.6f} {:.6f}\n" * len(V)).format(*V.ravel())
                               + ("f {} {} {}\n" * len(F)).format(*(F.ravel() + 1)))
    return {"points": len(V), "faces": len(F)}


def _checked_suffix(path: Path, units: str, up: str) -> str:
    """A scan file's suffix (SCAN_SUFFIXES), OptionError naming what is not one of a scan file's suffix, units
    (SCAN_UNITS) or up axis (UP_AXES)."""
    suffix = path.suffix.lower()
    if suffix not in SCAN_SUFFIXES:
        raise OptionError("path", f"a scan file ends in {' or '.join(SCAN_SUFFIXES)}, not '{suffix}'")
    if units not in SCAN_UNITS:
        raise OptionError("units", f"the units of a scan file are {' or '.join(SCAN_UNITS)}, not '{units}'")
    if up not in UP_ROTATIONS:
        raise OptionError("up", f"the up axis is one of {' '.join(UP_AXES)}, not '{up}'")
    return suffix


def _write_glb(path: Path, vertices: np.ndarray, faces: np.ndarray, rgb: np.ndarray | None = None) -> None:
    """A binary glTF (open3d's writer) of the triangles `faces` over `vertices`, each vertex of colour `rgb`
    ((V, 3) uint8) if given, at `path` whatever its name ends in (open3d goes by the extension)."""
    import open3d as o3d

    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(vertices), o3d.utility.Vector3iVector(faces))
    if rgb is not None:
        mesh.vertex_colors = o3d.utility.Vector3dVector(np.asarray(rgb) / 255.0)
    with tempfile.TemporaryDirectory(prefix="breastplan-glb-") as folder:
        glb = Path(folder) / "scan.glb"
        if not o3d.io.write_triangle_mesh(str(glb), mesh):
            raise OSError(f"{path}: open3d could not write it")
        Path(path).write_bytes(glb.read_bytes())


def save_body_truth(path: str | Path, scene: BodyScene, frames: int) -> Path:
    """truth.npz (breastplan.body-truth/1): camera, nipples, breast regions, half volumes, body mesh (camera mm)."""
    V = transform_points(scene.camera_from_body, scene.body.vertices)
    nipples = scene.nipples_camera()
    volumes = scene.body.half_volumes_cc()
    w, h = scene.camera.size
    arrays = {"K": scene.camera.K, "image_size": np.array([w, h]), "camera_from_body": scene.camera_from_body,
              "vertices": V.astype(np.float32), "faces": scene.body.faces.astype(np.int32)}
    for side in SIDES:
        arrays[f"{side}_nipple_camera_mm"] = nipples[side]
        arrays[f"{side}_half_volume_cc"] = np.array(volumes[side])
        arrays[f"{side}_breast_vertices"] = breast_region(side).astype(np.int32)
    meta = dict(scene.meta, frames=frames, body=asdict(scene.body.options), camera=asdict(scene.camera),
                body_frame="MakeHuman: X the body's left, Y up, Z anterior")
    return save_npz(path, TRUTH_SCHEMA, arrays, units="mm", frame="camera", meta=meta, compress=True)


_TRUTH_SPEC = {"K": ("f", (3, 3)), "image_size": ("iu", (2,)), "camera_from_body": ("f", (4, 4)),
               "vertices": ("f", ("nv", 3)), "faces": ("iu", ("nf", 3)),
               **{f"{s}_{k}": spec for s in SIDES for k, spec in {
                   "nipple_camera_mm": ("f", (3,)), "half_volume_cc": ("f", ()),
                   "breast_vertices": ("iu", (f"{s}_nb",))}.items()}}


def load_body_truth(path: str | Path) -> dict:
    """Load and validate a realistic scene's truth.npz."""
    return load_npz(path, TRUTH_SCHEMA, _TRUTH_SPEC)
