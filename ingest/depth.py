"""Depth frames → one fused depth image → points (camera frame, mm).

Temporal fusion is a per-pixel robust average: the median of the valid (non-zero) depths,
then the mean of those within the noise band around it. Back-projection uses the recorded
pinhole intrinsics.
"""
from __future__ import annotations

import numpy as np

NOISE_MM_AT_600 = 1.0
"""Depth σ (mm) of an OAK-class stereo camera at 0.6 m; it grows with the square of the depth."""
RANGE_MM = 450.0
"""Half-depth of the slab kept around the patient (background removal by depth range)."""


def depth_sigma(depth_mm):
    """Expected depth noise σ (mm) at a depth (mm)."""
    return NOISE_MM_AT_600 * np.square(np.asarray(depth_mm, float) / 600.0)


def fuse(depth: np.ndarray) -> np.ndarray:
    """(N, H, W) uint16 mm → (H, W) float32 mm, 0 where fewer than max(1, N // 3) frames measured."""
    n = depth.shape[0]
    if n == 1:
        return depth[0].astype(np.float32)
    ordered = np.sort(depth, axis=0)  # zeros (no depth) first
    valid = np.count_nonzero(depth, axis=0)
    median = np.take_along_axis(ordered, np.minimum(n - valid + valid // 2, n - 1)[None], axis=0)[0].astype(np.float32)
    band = np.maximum(3.0 * depth_sigma(median), 2.0)
    keep = (depth > 0) & (np.abs(depth - median) <= band)
    count = keep.sum(axis=0)
    fused = (np.where(keep, depth, 0).sum(axis=0, dtype=np.float32) / np.maximum(count, 1)).astype(np.float32)
    fused[(count == 0) | (valid < max(1, n // 3))] = 0.0
    return fused


def depth_range(image: np.ndarray) -> tuple[float, float]:
    """Depth slab (mm) around the patient: the median depth of the central third of the image ± RANGE_MM."""
    h, w = image.shape
    centre = image[h // 3: 2 * h // 3, w // 3: 2 * w // 3]
    ref = float(np.median(centre[centre > 0])) if (centre > 0).any() else float(np.median(image[image > 0]))
    return ref - RANGE_MM, ref + RANGE_MM


def colours_at(points: np.ndarray, K: np.ndarray, image: np.ndarray) -> np.ndarray:
    """(N, 3) uint8: the colour `image` ((H, W, 3), aligned to depth) holds at the pixel each camera-frame point
    (mm) projects to (u = fx·x/z + cx, the inverse of `to_points`), the nearest pixel on the image's edge for a
    point off it."""
    z = np.maximum(points[:, 2], 1e-9)
    u = np.rint(K[0, 0] * points[:, 0] / z + K[0, 2]).clip(0, image.shape[1] - 1).astype(np.int64)
    v = np.rint(K[1, 1] * points[:, 1] / z + K[1, 2]).clip(0, image.shape[0] - 1).astype(np.int64)
    return image[v, u]


def to_points(image: np.ndarray, K: np.ndarray, near: float = 0.0, far: float = np.inf) -> np.ndarray:
    """Back-project a depth image (mm) within [near, far] to (N, 3) camera-frame points (mm), row by
    row: x = (u − cx)·z/fx, y = (v − cy)·z/fy."""
    v, u = np.nonzero((image > 0) & (image >= near) & (image <= far))
    z = image[v, u].astype(float)
    return np.column_stack([(u - K[0, 2]) * z / K[0, 0], (v - K[1, 2]) * z / K[1, 1], z])
