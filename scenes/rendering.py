"""Depth (and colour) rendering for the synthetic scanners: open3d ray casting, then an OAK-like noise model.

Camera frame: OpenCV (x right in the image, y down, z forward), mm. Noise grows with the
square of the distance; grazing surfaces and random holes give no depth (0), as on an OAK.
"""
from __future__ import annotations

import numpy as np
import open3d as o3d
from scipy import ndimage

from breastplan.meshes import vertex_normals

GRAZING_DEG = 78.0
"""Surfaces seen at a larger angle of incidence give no depth."""
NOISE_REF_MM = 600.0
"""Distance at which the depth noise has its nominal σ; σ grows with distance²."""


def pixel_rays(K: np.ndarray, width: int, height: int) -> np.ndarray:
    """(H·W, 6) rays from the camera centre through each pixel, directions with z = 1."""
    v, u = np.mgrid[0:height, 0:width]
    d = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u, float)], -1).reshape(-1, 3)
    return np.hstack([np.zeros_like(d), d]).astype(np.float32)


def cast_depth(rc: o3d.t.geometry.RaycastingScene, K: np.ndarray, width: int, height: int
               ) -> tuple[np.ndarray, np.ndarray]:
    """Noise-free depth (H, W) mm of a camera-frame ray-casting scene (NaN where nothing is
    measurable) and the hit geometry ids."""
    rays = pixel_rays(K, width, height)
    hit = rc.cast_rays(o3d.core.Tensor(rays))
    depth = hit["t_hit"].numpy().astype(float)  # ray directions have z = 1, so t is the depth
    normals = hit["primitive_normals"].numpy().astype(float)
    dirs = rays[:, 3:] / np.linalg.norm(rays[:, 3:], axis=1, keepdims=True)
    grazing = np.abs(np.sum(normals * dirs, axis=1)) < np.cos(np.radians(GRAZING_DEG))
    depth[~np.isfinite(depth) | grazing] = np.nan
    return depth.reshape(height, width), hit["geometry_ids"].numpy().reshape(height, width)


SKIN_RGB = (222, 176, 152)
"""A light skin tone, RGB."""
AREOLA_RGB = (160, 104, 88)
"""The areola's darker tone, RGB."""
AREOLA_MM = 18.0
"""The areola's radius about the nipple (straight-line distance on her skin), mm."""
WALL_RGB = (206, 206, 200)


def cast_colour(rc: o3d.t.geometry.RaycastingScene, meshes: list[tuple[np.ndarray, np.ndarray]], K: np.ndarray,
                width: int, height: int, nipples: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 RGB the colour camera (aligned to depth: the same pixels) sees of the ray-casting scene
    `rc` of camera-frame `meshes` ((V, 3) mm, (F, 3), geometry ids in order: the body, then the wall): her
    skin, darker within AREOLA_MM of each nipple (`nipples` (2, 3), camera frame, mm), the wall grey;
    smoothly shaded (vertex normals interpolated across each triangle), lit from the camera with some
    ambient light; black where nothing is hit."""
    normals = [(vertex_normals(V, F), F) for V, F in meshes]
    rays = pixel_rays(K, width, height)
    hit = rc.cast_rays(o3d.core.Tensor(rays))
    t, ids = hit["t_hit"].numpy().astype(float), hit["geometry_ids"].numpy()
    found = np.isfinite(t)
    n = np.zeros((len(t), 3))
    uv, prim = hit["primitive_uvs"].numpy().astype(float), hit["primitive_ids"].numpy()
    for g, (N, F) in enumerate(normals):
        on = found & (ids == g)
        corners = N[F[prim[on]]]                                                   # (k, 3 corners, 3)
        w = np.column_stack([1.0 - uv[on].sum(axis=1), uv[on]])
        n[on] = np.einsum("kc,kcd->kd", w, corners)
    dirs = rays[:, 3:] / np.linalg.norm(rays[:, 3:], axis=1, keepdims=True)
    lambert = np.abs(np.sum(n * dirs, axis=1)) / np.maximum(np.linalg.norm(n, axis=1), 1e-12)   # n: interpolated
    points = rays[:, 3:] * np.where(found, t, 0.0)[:, None]
    areola = np.min(np.linalg.norm(points[:, None, :] - np.asarray(nipples)[None], axis=2), axis=1) < AREOLA_MM
    base = np.where((ids == 0)[:, None], np.where(areola[:, None], AREOLA_RGB, SKIN_RGB), WALL_RGB)
    rgb = base * (0.35 + 0.65 * lambert)[:, None]
    rgb[~found] = 0.0
    return np.clip(np.rint(rgb), 0, 255).astype(np.uint8).reshape(height, width, 3)


def noisy_frames(clean: np.ndarray, noise_mm: float, n_frames: int, seed: int = 0) -> np.ndarray:
    """(N, H, W) uint16 depth in mm: clean depth + noise σ·(z/600)², quantised; 0 = no depth."""
    rng = np.random.default_rng(seed)
    sigma = noise_mm * np.square(clean / NOISE_REF_MM)
    noisy = clean + rng.standard_normal((n_frames, *clean.shape)) * sigma
    holes = ndimage.binary_dilation(rng.random(noisy.shape) < 4e-4, structure=_hole_disc())
    noisy[holes | ~np.isfinite(noisy)] = 0.0
    return np.clip(np.rint(noisy), 0, 65535).astype(np.uint16)


def _hole_disc() -> np.ndarray:
    """A disc of radius 3 px in each frame (holes do not spread across frames)."""
    y, x = np.mgrid[-3:4, -3:4]
    return (x * x + y * y <= 9)[None]
