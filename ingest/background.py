"""A wall behind the patient: a plumb reference for her up axis.

Walls stand plumb, so a wall seen behind an upright patient fixes the one direction a frontal scan
cannot tell on its own, how far the camera looks up or down: her up axis lies in the wall's plane.
Works on the points behind the body (viewing frame: x right, y down, z away from the viewer; mm).
"""
from __future__ import annotations

import numpy as np

from breastplan.voxels import voxel_centroids

VOXEL_MM = 20.0
"""The points behind the body are evened out on voxels of this size first."""
HYPOTHESES = 256
"""Planes tried (through three voxels drawn with a fixed seed: the same points give the same wall)."""
JUDGES = 1000
"""The planes are scored on at most this many voxels (drawn with the same seed); the best takes all of its."""
INLIER_MM = 15.0
"""A voxel within this of a plane lies on it."""
WALL_AREA_MM2 = 0.25e6
"""A wall covers at least this much (0.25 m²) of the view behind her."""
FACING_DEG = 45.0
"""A wall faces the viewer within this: a floor or a ceiling seen at a slant does not."""


def plumb_wall(points: np.ndarray) -> np.ndarray | None:
    """The unit normal (towards the viewer) of the largest plane among `points` (N, 3), the points
    behind the body, when it covers WALL_AREA_MM2 and faces the viewer within FACING_DEG; else None."""
    P = np.asarray(points, float)
    if len(P) < 3:
        return None
    Q = voxel_centroids(P, VOXEL_MM)[0]
    min_voxels = int(WALL_AREA_MM2 / VOXEL_MM**2)
    if len(Q) < min_voxels:
        return None
    rng = np.random.default_rng(0)
    draw = rng.integers(0, len(Q), (HYPOTHESES, 3))
    a, b, c = Q[draw[:, 0]], Q[draw[:, 1]], Q[draw[:, 2]]
    normals = np.cross(b - a, c - a)
    length = np.linalg.norm(normals, axis=1)
    ok = length > 1e-6
    normals, offsets = normals[ok] / length[ok, None], np.sum(a[ok] * normals[ok], axis=1) / length[ok]
    judges = Q[rng.choice(len(Q), min(len(Q), JUDGES), replace=False)]
    best = int(np.argmax((np.abs(judges @ normals.T - offsets) < INLIER_MM).sum(axis=0)))
    inliers = Q[np.abs(Q @ normals[best] - offsets[best]) < INLIER_MM]
    if len(inliers) < min_voxels:
        return None
    axes = np.linalg.eigh(np.cov((inliers - inliers.mean(0)).T))[1]      # normal first, then in-plane
    cells = np.floor(inliers @ axes[:, 1:] / VOXEL_MM).astype(np.int64)
    cells -= cells.min(axis=0)
    if len(np.unique(cells[:, 0] * (cells[:, 1].max() + 1) + cells[:, 1])) < min_voxels:
        return None          # its area, counted on the plane (voxels count it twice where it crosses their layers)
    normal = axes[:, 0] if axes[2, 0] < 0 else -axes[:, 0]
    return normal if -normal[2] >= np.cos(np.radians(FACING_DEG)) else None
