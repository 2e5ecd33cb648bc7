"""The realistic synthetic scanner: a MakeHuman body (head, neck, arms) seen by an OAK-like camera.

The camera looks at the midpoint of the nipples from `distance_mm`, pitched (positive: from
above, looking down) and turned about the body's vertical axis (yaw, positive: from the
patient's left); a wall may stand behind her. The truth it writes: both nipples, the breast
regions and the exact volume of each half of the closed body, with the body mesh, all in
camera mm.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import open3d as o3d

from breastplan import load_npz, save_npz, transform_points
from breastplan.options import SIDES

from .makehuman import Body, BodyOptions, breast_region, make_body
from .rendering import cast_depth, noisy_frames

TRUTH_SCHEMA = "breastplan.body-truth/1"
RESOLUTIONS = {"640x400": (640, 400), "800x600": (800, 600), "1280x800": (1280, 800)}
HFOV_DEG = 72.0
"""Horizontal field of view of the depth camera (an OAK-D's stereo pair)."""


@dataclass(frozen=True)
class CameraOptions:
    """Where the camera stands and what it is: mm, degrees, pixels."""

    distance_mm: float = 650.0
    pitch_deg: float = 0.0
    yaw_deg: float = 0.0
    resolution: str = "800x600"
    noise_mm: float = 1.0
    wall_mm: float | None = 400.0       # gap between the back and a wall behind; None: no wall

    def __post_init__(self):
        if not 400.0 <= self.distance_mm <= 1500.0:
            raise ValueError(f"distance must be 400..1500 mm, got {self.distance_mm}")
        if not (-30.0 <= self.pitch_deg <= 30.0 and -30.0 <= self.yaw_deg <= 30.0):
            raise ValueError("pitch and yaw must be −30..30 degrees")
        if self.resolution not in RESOLUTIONS:
            raise ValueError(f"resolution must be one of {sorted(RESOLUTIONS)}, got {self.resolution!r}")
        if not 0.0 <= self.noise_mm <= 10.0:
            raise ValueError(f"noise must be 0..10 mm, got {self.noise_mm}")

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

    def render(self) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free depth (H, W) mm, NaN where nothing is measured, and geometry ids (0 body, 1 wall)."""
        rc = o3d.t.geometry.RaycastingScene()
        for V, F in self.meshes():
            rc.add_triangles(o3d.core.Tensor(V.astype(np.float32)), o3d.core.Tensor(F.astype(np.uint32)))
        return cast_depth(rc, self.camera.K, *self.camera.size)

    def frames(self, n_frames: int, seed: int = 0) -> np.ndarray:
        """(N, H, W) uint16 noisy depth frames, mm."""
        return noisy_frames(self.render()[0], self.camera.noise_mm, n_frames, seed)

    def nipples_camera(self) -> dict[str, np.ndarray]:
        return {s: transform_points(self.camera_from_body, p[None])[0] for s, p in self.body.nipples.items()}


def make_body_scene(body: BodyOptions = BodyOptions(), camera: CameraOptions = CameraOptions()) -> BodyScene:
    """The body of `body`, seen by `camera`."""
    made = make_body(body)
    target = 0.5 * (made.nipples["left"] + made.nipples["right"])
    return BodyScene(made, camera, camera_pose(target, camera))


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
    options = scene.body.options
    meta = dict(scene.meta, frames=frames, body={"cup": options.cup, "firmness": options.firmness,
                "weight": options.weight, "muscle": options.muscle, "modifiers": dict(options.modifiers),
                "pose": options.pose},
                camera={"distance_mm": scene.camera.distance_mm, "pitch_deg": scene.camera.pitch_deg,
                        "yaw_deg": scene.camera.yaw_deg, "resolution": scene.camera.resolution,
                        "noise_mm": scene.camera.noise_mm, "wall_mm": scene.camera.wall_mm},
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
