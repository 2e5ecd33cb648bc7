"""The synthetic scanner: a patient with breasts of known parameters seen by an OAK-like camera.

Body frame (mm): origin on the sternum at the height of the breast-base centres, X towards
the patient's left, Y superior, Z anterior. Camera frame: OpenCV (x right in the image, y
down, z forward), mm. Each breast is the primitive of docs/model.md §2 with the deformations of
docs/model.md §3 in its breast frame (docs/model.md §1), whose base plane is the tangent plane of the
chest wall at the base centre; the base ring is extruded into the body so that the breast
meets the curved chest. Depth is rendered with open3d ray casting; the noise grows with the
square of the distance, grazing surfaces and random holes give no depth (0), as on an OAK.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree

from breastplan import PARAM_NAMES, Primitive, load_npz, save_npz, transform_points
from breastplan.chest_wall import ChestWall
from breastplan.deform.breast_model import BreastModel
from breastplan.deform.global_deformations import Deformation
from breastplan.deform.names import DEFORMATION_PARAMS, PLAUSIBLE
from breastplan.meshes import volume_below_base
from breastplan.options import SIDES

from .rendering import GRAZING_DEG, cast_depth, noisy_frames

TRUTH_SCHEMA = "breastplan.scan-truth/1"
WIDTH, HEIGHT = 640, 400
CHEST_RX, CHEST_RY = 420.0, 900.0
"""Radii of curvature (mm) of the chest wall across (X) and along (Y) the body."""
BASE_X = 90.0
"""|X| of the breast-base centres, mm."""
NIPPLE_SIGMA_MM = 3.0
"""Width (σ) of the nipple bump."""
SURFACE_GRID = (90, 144)
"""(n_u, n_v) of the true breast surface meshes."""


@dataclass(frozen=True)
class Breast:
    """A breast: primitive (model units) and deformation in its breast frame, and a nipple.

    The nipple is a Gaussian bump (height `nipple_height_mm`, σ NIPPLE_SIGMA_MM) along z on
    the deformed apex, so that the nipple is a landmark as on a patient, not the flat top of
    a dome. Away from it (beyond ~3σ) the surface is exactly the deformed primitive.
    """

    primitive: Primitive
    deformation: Deformation
    nipple_height_mm: float = 4.0

    def surface(self) -> tuple[np.ndarray, np.ndarray]:
        """Outer surface mesh (V mm breast frame, F), without the base cap."""
        V, F = BreastModel(self.primitive, self.deformation).mesh(*SURFACE_GRID, closed=False)
        apex = self.apex_mm
        d2 = np.sum(np.square(V[:, :2] - apex[:2]), axis=1)
        V[:, 2] += self.nipple_height_mm * np.exp(-d2 / (2 * NIPPLE_SIGMA_MM**2)) * (V[:, 2] > apex[2] / 2)
        return V, F

    @property
    def apex_mm(self) -> np.ndarray:
        """The deformed apex (0, 0, a5) of the primitive, mm, breast frame."""
        return BreastModel(self.primitive, self.deformation).place([[0.0, 0.0, self.primitive.a5]])[0]

    @property
    def nipple_mm(self) -> np.ndarray:
        """The tip of the nipple, mm, breast frame (the deformations keep the apex normal along z)."""
        return self.apex_mm + [0.0, 0.0, self.nipple_height_mm]

    def volume_on_chest_cc(self, side: str) -> float:
        """Volume down to the curved chest (cc): the primitive's, and that of its base extruded into
        the body to the chest (`breastplan.meshes.volume_below_base`)."""
        V, F = BreastModel(self.primitive, self.deformation).mesh(*SURFACE_GRID)
        reversed_z = np.diag([1.0, 1.0, -1.0, 1.0])         # the body frame, z away from the viewer
        floor = partial(CHEST.beneath, np.linalg.inv(body_from_breast(side)) @ reversed_z)
        return self.primitive.volume_cc + volume_below_base(V, F, floor) / 1000.0


@dataclass(frozen=True)
class Scene:
    """Everything the scanner renders, plus the truth it records."""

    breasts: dict[str, Breast]
    K: np.ndarray                   # (3, 3) pixels
    camera_from_body: np.ndarray    # (4, 4) mm
    noise_mm: float = 1.0           # depth σ at NOISE_REF_MM
    meta: dict = field(default_factory=dict)

    def camera_from_breast(self, side: str) -> np.ndarray:
        return self.camera_from_body @ body_from_breast(side)

    def surface_distance(self, side: str, points_camera: np.ndarray) -> np.ndarray:
        """Distance (mm) of points (camera frame, mm) to the true outer surface of the `side` breast."""
        V, F = self.breasts[side].surface()
        surface = o3d.t.geometry.RaycastingScene()
        surface.add_triangles(o3d.core.Tensor(transform_points(self.camera_from_breast(side), V).astype(np.float32)),
                              o3d.core.Tensor(F.astype(np.uint32)))
        return surface.compute_distance(o3d.core.Tensor(np.asarray(points_camera, np.float32))).numpy()


CHEST = ChestWall(np.array([0.0, 0.0, 0.0, 1e4 / (2 * CHEST_RX), 0.0, 1e4 / (2 * CHEST_RY)]), 2, np.zeros(2), 0.0)
"""The chest wall, x²/(2 CHEST_RX) + y²/(2 CHEST_RY), as a height field of the body frame with z
reversed (as a viewing frame's: z away from the viewer)."""


def chest_z(x, y):
    """Z of the chest wall (body frame, mm): a quadric, 0 at the sternum."""
    return -CHEST.z(np.stack(np.broadcast_arrays(x, y), -1))


def body_from_breast(side: str) -> np.ndarray:
    """(4, 4) breast frame → body frame: origin at the base centre, z the chest normal there."""
    x0 = BASE_X if side == "left" else -BASE_X
    origin = np.array([x0, 0.0, chest_z(x0, 0.0)])
    z = np.array([x0 / CHEST_RX, 0.0, 1.0])
    z /= np.linalg.norm(z)
    y = np.array([0.0, 1.0, 0.0]) - z[1] * z
    y /= np.linalg.norm(y)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([np.cross(y, z), y, z])
    T[:3, 3] = origin
    return T


def default_breast(rng: np.random.Generator, overrides: dict[str, float] | None = None) -> Breast:
    """A plausible breast drawn from `rng` (≈ 300–650 cc, mild ptosis), with named overrides."""
    values = dict(zip(PARAM_NAMES, [*rng.uniform(9.0, 11.5, 5), rng.uniform(0.8, 1.1), rng.uniform(0.85, 1.1)]))
    values["a5"] = rng.uniform(8.5, 10.5)
    deform = dict.fromkeys(DEFORMATION_PARAMS, 0.0)
    deform.update(b0=rng.uniform(0.0, 1.5), b1=rng.uniform(0.0, 0.8), c0=rng.uniform(-0.4, 0.4),
                  g0=rng.uniform(0.0, 0.3))
    for name, value in (overrides or {}).items():
        (values if name in PARAM_NAMES else deform)[name] = float(value)
    primitive = Primitive(**{k: float(v) for k, v in values.items()})
    problem = primitive.breast_problem()
    if problem:
        raise ValueError(f"the breast {problem}")
    outside = {n: v for n, v in deform.items() if not PLAUSIBLE[n][0] <= v <= PLAUSIBLE[n][1]}
    if outside:
        raise ValueError("deformation parameters outside what a breast shows: " + ", ".join(
            f"{n} = {v:g} (range {PLAUSIBLE[n][0]:g}..{PLAUSIBLE[n][1]:g})" for n, v in outside.items()))
    return Breast(primitive, Deformation.from_vector([deform[n] for n in DEFORMATION_PARAMS]))


def make_scene(seed: int = 0, tilt_deg: float = 0.0, distance_mm: float | None = None, noise_mm: float = 1.0,
               overrides: dict[str, dict[str, float]] | None = None) -> Scene:
    """The patient and the camera for `seed`; the camera looks at the chest from `distance_mm`, pitched by `tilt_deg`."""
    rng = np.random.default_rng(seed)
    breasts = {side: default_breast(rng, (overrides or {}).get(side)) for side in SIDES}
    distance = float(rng.uniform(550.0, 750.0) if distance_mm is None else distance_mm)
    f = rng.uniform(445.0, 455.0)
    K = np.array([[f, 0.0, WIDTH / 2 + rng.uniform(-3, 3)], [0.0, f * rng.uniform(0.998, 1.002),
                  HEIGHT / 2 + rng.uniform(-3, 3)], [0.0, 0.0, 1.0]])
    meta = {"seed": seed, "tilt_deg": tilt_deg, "distance_mm": distance, "noise_mm": noise_mm}
    return Scene(breasts, K, camera_pose(distance, tilt_deg), noise_mm, meta)


def camera_pose(distance_mm: float, tilt_deg: float) -> np.ndarray:
    """camera_from_body (4, 4): looking at the chest from the front, pitched down by `tilt_deg`."""
    t = np.radians(tilt_deg)
    target = np.array([0.0, -20.0, -20.0])
    centre = target + distance_mm * np.array([0.0, np.sin(t), np.cos(t)])
    z = (target - centre) / distance_mm
    x = np.array([1.0, 0.0, 0.0])  # the patient's left is the image's right
    R = np.vstack([x, np.cross(z, x), z])
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, -R @ centre
    return T


# --- geometry of the scene -------------------------------------------------------------
def torso_mesh() -> tuple[np.ndarray, np.ndarray]:
    """Torso front (chest wall, abdomen, shoulders) as a height-field mesh, body frame mm."""
    y = np.arange(-420.0, 266.0, 5.0)
    s = np.linspace(-1.0, 1.0, 121)
    Y, S = np.meshgrid(y, s, indexing="ij")
    half_width = 200.0 + 35.0 * _smoothstep((Y - 80.0) / 120.0) - 14.0 * np.exp(-np.square((Y + 300.0) / 90.0))
    X = S * half_width
    Z = (chest_z(X, Y) + 12.0 * np.exp(-np.square((Y + 300.0) / 90.0))        # abdomen
         - 120.0 * np.square(np.clip((np.abs(S) - 0.84) / 0.16, 0.0, 1.0))     # flanks
         - 160.0 * np.square(np.clip((Y - 185.0) / 80.0, 0.0, 1.0)))           # shoulders
    return np.stack([X, Y, Z], -1).reshape(-1, 3), _grid_triangles(*Y.shape)


def _smoothstep(t):
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3 - 2 * t)


def _grid_triangles(rows: int, cols: int) -> np.ndarray:
    i, j = np.meshgrid(np.arange(rows - 1), np.arange(cols - 1), indexing="ij")
    a = (i * cols + j).ravel()
    return np.concatenate([np.stack([a, a + 1, a + cols], 1), np.stack([a + 1, a + cols + 1, a + cols], 1)])


def breast_render_mesh(breast: Breast) -> tuple[np.ndarray, np.ndarray]:
    """The breast surface plus its base ring extruded 40 mm into the body, breast frame mm."""
    V, F = breast.surface()
    n_v = SURFACE_GRID[1]
    ring = V[:n_v].copy()
    ring[:, 2] -= 40.0
    j = np.arange(n_v)
    k = len(V)
    band = np.concatenate([np.stack([k + j, j, (j + 1) % n_v], 1), np.stack([k + j, (j + 1) % n_v, k + (j + 1) % n_v], 1)])
    return np.vstack([V, ring]), np.vstack([F, band])


def background_meshes() -> list[tuple[np.ndarray, np.ndarray]]:
    """A wall behind the patient and a box beside her (clutter for background removal), body frame mm."""
    wall = np.array([[-4000, -4000, -650], [4000, -4000, -650], [4000, 4000, -650], [-4000, 4000, -650.0]])
    box = o3d.geometry.TriangleMesh.create_box(80.0, 160.0, 80.0).translate((300.0, -360.0, -160.0))
    return [(wall, np.array([[0, 1, 2], [0, 2, 3]])), (np.asarray(box.vertices), np.asarray(box.triangles))]


def raycasting_scene(scene: Scene) -> o3d.t.geometry.RaycastingScene:
    """All surfaces in camera coordinates; geometry ids 0 torso, 1 left, 2 right breast, then background."""
    rc = o3d.t.geometry.RaycastingScene()
    meshes = [(transform_points(scene.camera_from_body, V), F) for V, F in [torso_mesh()]]
    for side in SIDES:
        V, F = breast_render_mesh(scene.breasts[side])
        meshes.append((transform_points(scene.camera_from_breast(side), V), F))
    meshes += [(transform_points(scene.camera_from_body, V), F) for V, F in background_meshes()]
    for V, F in meshes:
        rc.add_triangles(o3d.core.Tensor(V.astype(np.float32)), o3d.core.Tensor(F.astype(np.uint32)))
    return rc


def render_depth(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Noise-free depth (H, W) mm (NaN where nothing is measurable) and the hit geometry ids."""
    return cast_depth(raycasting_scene(scene), scene.K, WIDTH, HEIGHT)


def depth_frames(scene: Scene, n_frames: int, seed: int = 0) -> np.ndarray:
    """(N, H, W) uint16 depth in mm of the scene (see `rendering.noisy_frames`)."""
    return noisy_frames(render_depth(scene)[0], scene.noise_mm, n_frames, seed)


# --- truth ---------------------------------------------------------------------------
def save_truth(path: str | Path, scene: Scene, frames: int) -> Path:
    """truth.npz (breastplan.scan-truth/1): camera, breast parameters and true surfaces in camera mm."""
    arrays = {"K": scene.K, "image_size": np.array([WIDTH, HEIGHT]), "camera_from_body": scene.camera_from_body}
    for side in SIDES:
        breast, T = scene.breasts[side], scene.camera_from_breast(side)
        V, F = breast.surface()
        arrays.update({f"{side}_primitive": breast.primitive.as_array(),
                       f"{side}_deformation": breast.deformation.as_vector(),
                       f"{side}_camera_from_breast": T,
                       f"{side}_nipple_camera_mm": transform_points(T, breast.nipple_mm[None])[0],
                       f"{side}_vertices": transform_points(T, V).astype(np.float32), f"{side}_faces": F.astype(np.int32)})
    meta = dict(scene.meta, frames=frames, deformation_order=list(DEFORMATION_PARAMS), primitive_order=list(PARAM_NAMES),
                body_frame="X patient's left, Y superior, Z anterior; origin sternum at base-centre height")
    return save_npz(path, TRUTH_SCHEMA, arrays, units="mm", frame="camera", meta=meta, compress=True)


_TRUTH_SPEC = {"K": ("f", (3, 3)), "image_size": ("iu", (2,)), "camera_from_body": ("f", (4, 4)),
               **{f"{s}_{k}": spec for s in SIDES for k, spec in {
                   "primitive": ("f", (7,)), "deformation": ("f", (12,)), "camera_from_breast": ("f", (4, 4)),
                   "nipple_camera_mm": ("f", (3,)), "vertices": ("f", (f"{s}_nv", 3)),
                   "faces": ("iu", (f"{s}_nf", 3))}.items()}}


def load_truth(path: str | Path) -> dict:
    """Load and validate truth.npz."""
    return load_npz(path, TRUTH_SCHEMA, _TRUTH_SPEC)


def scene_from_truth(truth) -> Scene:
    """The scene a truth file describes (to ray-cast visibility against it)."""
    breasts = {s: Breast(Primitive.from_array(truth[f"{s}_primitive"]), Deformation.from_vector(truth[f"{s}_deformation"]))
               for s in SIDES}
    return Scene(breasts, truth["K"], truth["camera_from_body"], truth.meta.get("noise_mm", 1.0), truth.meta)


def scan_errors(points_camera: np.ndarray, nipple_camera: np.ndarray, z_axis_camera: np.ndarray,
                truth, side: str, n_samples: int = 20_000) -> dict[str, float]:
    """Accuracy of an ingested breast against the truth, all in camera mm.

    rms_mm: RMS distance of the points to the true breast surface; nipple_mm; z_axis_deg;
    coverage: fraction of the camera-visible true surface with a point within 3 mm.
    """
    V, F = truth[f"{side}_vertices"].astype(np.float32), truth[f"{side}_faces"].astype(np.uint32)
    surface = o3d.t.geometry.RaycastingScene()
    surface.add_triangles(o3d.core.Tensor(V), o3d.core.Tensor(F))
    dist = surface.compute_distance(o3d.core.Tensor(points_camera.astype(np.float32))).numpy()
    T = truth[f"{side}_camera_from_breast"]
    cos_z = float(np.clip(np.dot(z_axis_camera, T[:3, 2]) / np.linalg.norm(z_axis_camera), -1, 1))
    visible = visible_samples(truth, side, n_samples)
    near, _ = cKDTree(points_camera).query(visible, distance_upper_bound=3.0)
    return {"rms_mm": float(np.sqrt(np.mean(np.square(dist)))),
            "nipple_mm": float(np.linalg.norm(nipple_camera - truth[f"{side}_nipple_camera_mm"])),
            "z_axis_deg": float(np.degrees(np.arccos(cos_z))),
            "coverage": float(np.mean(np.isfinite(near))), "points": int(len(points_camera))}


def visible_samples(truth, side: str, n: int) -> np.ndarray:
    """Area-uniform samples of the true breast surface that the camera sees (camera mm)."""
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(truth[f"{side}_vertices"].astype(float)),
                                     o3d.utility.Vector3iVector(truth[f"{side}_faces"].astype(np.int32)))
    o3d.utility.random.seed(0)
    samples = np.asarray(mesh.sample_points_uniformly(n).points)
    dist = np.linalg.norm(samples, axis=1)
    dirs = samples / dist[:, None]
    rays = np.hstack([np.zeros_like(dirs), dirs]).astype(np.float32)
    hit = raycasting_scene(scene_from_truth(truth)).cast_rays(o3d.core.Tensor(rays))
    t = hit["t_hit"].numpy()
    cos_inc = np.abs(np.sum(hit["primitive_normals"].numpy() * dirs, axis=1))
    seen = (np.abs(t - dist) < 0.5) & (cos_inc >= np.cos(np.radians(GRAZING_DEG)))
    return samples[seen]
