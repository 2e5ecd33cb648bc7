"""The chest wall: a polynomial height field z = f(x, y) in a viewing frame (camera convention:
z away from the viewer, y down, mm). Ingest fits it to the torso around the breasts
(`breastplan.ingest.chest_wall`); the case stores it; the fit measures the breast down to it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SCALE_MM = 100.0
"""Coordinates are divided by this before the polynomial, for conditioning."""
MAX_DEGREE = 5
"""The highest degree a stored wall may have."""


def exponents(degree: int) -> np.ndarray:
    """(K, 2) exponents (i, j) of the polynomial's terms x^i y^j, by total degree."""
    return np.array([(i, d - i) for d in range(degree + 1) for i in range(d, -1, -1)])


@dataclass(frozen=True)
class ChestWall:
    """z = Σ c_k ((x − x0)/100)^i ((y − y0)/100)^j in the viewing frame (mm)."""

    coefficients: np.ndarray   # (K,)
    degree: int
    centre: np.ndarray         # (2,) x0, y0 mm
    scale_mm: float            # robust σ of the inlier residuals

    def basis(self, xy: np.ndarray) -> np.ndarray:
        """(…, K) the polynomial's terms at (x, y), mm: the design matrix of a fit."""
        uv = (np.asarray(xy, float)[..., :2] - self.centre) / SCALE_MM
        px = np.cumprod(np.concatenate([np.ones_like(uv[..., :1]), np.repeat(uv[..., :1], self.degree, -1)], -1), -1)
        py = np.cumprod(np.concatenate([np.ones_like(uv[..., 1:]), np.repeat(uv[..., 1:], self.degree, -1)], -1), -1)
        e = exponents(self.degree)
        return px[..., e[:, 0]] * py[..., e[:, 1]]

    def z(self, xy) -> np.ndarray:
        """Chest depth under (x, y), mm."""
        return self.basis(xy) @ self.coefficients

    def height(self, points) -> np.ndarray:
        """Height of points in front of the chest along the view axis (towards the viewer), mm."""
        p = np.asarray(points, float)
        return self.z(p) - p[..., 2]

    def normal(self, xy) -> np.ndarray:
        """Unit normal towards the viewer (anterior) at (x, y)."""
        xy = np.asarray(xy, float)
        h = 1e-3
        gx = (self.z(xy + [h, 0]) - self.z(xy - [h, 0])) / (2 * h)
        gy = (self.z(xy + [0, h]) - self.z(xy - [0, h])) / (2 * h)
        n = np.stack([gx, gy, -np.ones_like(gx)], -1)
        return n / np.linalg.norm(n, axis=-1, keepdims=True)

    def point(self, xy) -> np.ndarray:
        """The chest point under (x, y)."""
        xy = np.asarray(xy, float)[..., :2]
        return np.concatenate([xy, self.z(xy)[..., None]], -1)

    def beneath(self, frame_from_view: np.ndarray, xy, iterations: int = 6) -> np.ndarray:
        """z of the chest wall under (x, y) of another frame (`frame_from_view`: (4, 4), viewing
        frame → that frame, e.g. the breast frame), along that frame's z axis, mm: Newton steps on
        the height along the line (x, y, t)."""
        xy = np.asarray(xy, float)[..., :2]
        view_from_frame = np.linalg.inv(frame_from_view)
        R, o = view_from_frame[:3, :3], view_from_frame[:3, 3]
        base = xy @ R[:, :2].T + o

        def height(t):
            return self.height(base + t[..., None] * R[:, 2])
        t = np.zeros(xy.shape[:-1])
        for _ in range(iterations):
            h = height(t)
            t = t - h / (height(t + 1.0) - h)
        return t

    def as_array(self) -> np.ndarray:
        """[degree, x0, y0, scale, c_0 … c_K−1] for artefacts."""
        return np.concatenate([[self.degree, *self.centre, self.scale_mm], self.coefficients])

    @classmethod
    def from_array(cls, values) -> "ChestWall":
        """The wall `as_array` wrote; ValueError saying what is wrong with a damaged one."""
        v = np.asarray(values, float).ravel()
        degree = int(v[0]) if len(v) and v[0] in range(1, MAX_DEGREE + 1) else 0
        if not degree or len(v) != 4 + len(exponents(degree)):
            raise ValueError("whose coefficients do not match its degree")
        return cls(v[4:], degree, v[1:3], float(v[3]))
