"""Free-form deformation lattice (docs/model.md §6), a deformation object after mathLab PyGeM's `pygem/ffd.py`.

A `Lattice` owns its axis-aligned box (`lo`, `hi`: mm, breast frame), its shape (l, m, n control
points per axis, Bernstein degrees l − 1, m − 1, n − 1) and its control points; calling it
deforms points. Control points are (K, 3) arrays, K = l·m·n, in `np.meshgrid(..., indexing="ij")`
order: control point (i, j, k) is row (i·m + j)·n + k.

With s = (p − lo)/(hi − lo) ∈ [0, 1]³ the lattice coordinates of p and B_ijk(s) = B_i^{l−1}(s_x)
B_j^{m−1}(s_y) B_k^{n−1}(s_z) the trivariate Bernstein basis, a point inside the box moves to

    X(p) = p + Σ_ijk B_ijk(s) (P_ijk − R_ijk)   (R the rest lattice, a regular grid on the box),

which equals Σ_ijk B_ijk(s) P_ijk since Σ B_ijk R_ijk = p (linear precision). Points outside
the box are returned unchanged, as PyGeM does.

`save`/`load` write and read a standalone `breastplan.lattice/1` NPZ (docs/artefacts.md).
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np
from scipy import sparse
from scipy.special import comb

from breastplan import ArtefactError, load_npz, save_npz
from breastplan.frames import points_copy

SCHEMA = "breastplan.lattice/1"
CHUNK = 1 << 14
"""Points per block of `Lattice.apply`: its temporaries stay a few MB (5³); of 2¹², 2¹⁴ and 2¹⁶,
2¹⁴ was the fastest on 1 M points."""
_SPEC = {"shape": ("iu", (3,)), "box": ("f", (2, 3)), "rest": ("f", ("cp", 3)), "points": ("f", ("cp", 3))}


def bernstein(n: int, s) -> np.ndarray:
    """(..., n+1) Bernstein polynomials B_i^n(s) = C(n, i) sᶦ (1 − s)ⁿ⁻ᶦ, s ∈ [0, 1] (docs/model.md §6),
    by repeated products (several times faster than powers)."""
    s = np.asarray(s, float)
    t = 1.0 - s
    up, down = [np.ones_like(s)], [np.ones_like(s)]
    for _ in range(n):
        up.append(up[-1] * s)
        down.append(down[-1] * t)
    return np.stack([comb(n, i) * up[i] * down[n - i] for i in range(n + 1)], axis=-1)


def _shape3(shape: int | Sequence[int]) -> tuple[int, int, int]:
    dims = (shape,) * 3 if np.ndim(shape) == 0 else tuple(shape)
    if len(dims) != 3 or any(int(d) != d or d < 2 for d in dims):
        raise ValueError(f"lattice shape {dims!r} must be three whole numbers of control points ≥ 2")
    return tuple(int(d) for d in dims)


def _frozen(array: np.ndarray) -> np.ndarray:
    """`array`, made read-only: a lattice's box, grid and control points change only through its setters."""
    array.setflags(write=False)
    return array


def grid(lo: np.ndarray, hi: np.ndarray, shape: tuple[int, int, int]) -> np.ndarray:
    """(K, 3) regular control points on the box [lo, hi] (mm), "ij" order."""
    axes = [np.linspace(lo[k], hi[k], shape[k]) for k in range(3)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)


class Lattice:
    """An l×m×n FFD lattice on the box [lo, hi] (mm, breast frame); `lattice(points)` deforms points.

    `rest` (K, 3) is the regular grid of the box, `points` (K, 3) the current control points
    (mm; assign new ones, or `displacements`, to deform; the arrays themselves are read-only).
    Use `Lattice.around` to build one about a cloud.
    """

    def __init__(self, lo, hi, shape: int | Sequence[int], points: np.ndarray | None = None,
                 rest: np.ndarray | None = None):
        self.lo = _frozen(np.array(lo, dtype=float).reshape(3))
        self.hi = _frozen(np.array(hi, dtype=float).reshape(3))
        if not (np.isfinite(self.lo).all() and np.isfinite(self.hi).all() and (self.lo < self.hi).all()):
            raise ValueError(f"lattice box lo {self.lo} must be below hi {self.hi} on every axis")
        self.shape = _shape3(shape)
        regular = grid(self.lo, self.hi, self.shape)
        if rest is None:
            rest = regular
        else:
            rest = np.array(rest, dtype=float)
            tol = 1e-9 * float(np.max(self.hi - self.lo))
            if rest.shape != regular.shape or not np.allclose(rest, regular, rtol=0, atol=tol):
                raise ValueError(f"rest control points of shape {rest.shape} are not the regular "
                                 f"{'×'.join(map(str, self.shape))} grid of the box")
        self.rest = _frozen(rest)
        self.points = rest.copy() if points is None else points

    @property
    def points(self) -> np.ndarray:
        """(K, 3) current control points, mm; read-only: assign new ones (or `displacements`)."""
        return self._points

    @points.setter
    def points(self, value) -> None:
        value = np.array(value, dtype=float)
        if value.shape != self.rest.shape:
            raise ValueError(f"control points of shape {value.shape}, expected {self.rest.shape}")
        if not np.isfinite(value).all():
            raise ValueError("control points must be finite")
        self._points = _frozen(value)

    @property
    def displacements(self) -> np.ndarray:
        """(K, 3) control-point displacements from rest, mm."""
        return self._points - self.rest

    @displacements.setter
    def displacements(self, value) -> None:
        self.points = self.rest + np.asarray(value, float)

    @property
    def size(self) -> int:
        """K = l·m·n, the number of control points."""
        return len(self.rest)

    @property
    def n(self) -> int:
        """Control points per axis of a cubic (n×n×n) lattice, as the fit uses."""
        if len(set(self.shape)) != 1:
            raise ValueError(f"the lattice is {'×'.join(map(str, self.shape))}, not n×n×n")
        return self.shape[0]

    @classmethod
    def around(cls, points: np.ndarray, n: int | Sequence[int], margin: float = 0.1) -> "Lattice":
        """Rest lattice of shape n (or (l, m, n)) on the bounding box of points (mm), padded by
        margin·extent + 1 mm on each side."""
        points = np.asarray(points, float)
        if points.ndim == 0 or points.shape[-1] != 3 or points.size == 0:
            raise ValueError(f"a lattice is built around one or more finite points (..., 3), got shape {points.shape}")
        if not np.isfinite(points).all():
            raise ValueError("a lattice is built around one or more finite points (..., 3), got NaN or infinite ones")
        points = points.reshape(-1, 3)
        lo, hi = points.min(0), points.max(0)
        pad = margin * (hi - lo) + 1.0
        return cls(lo - pad, hi + pad, n)

    def lattice_coordinates(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) s = (p − lo)/(hi − lo) of points (mm); in [0, 1]³ inside the box."""
        return (np.asarray(points, float) - self.lo) / (self.hi - self.lo)

    def basis(self, points: np.ndarray) -> np.ndarray:
        """(N, K) trivariate Bernstein rows B_ijk(s) of points (mm) inside the box (docs/model.md §6).

        Dense: for the fit's few thousand vertices; `apply` never forms it.
        """
        s = self.lattice_coordinates(points)
        l, m, n = self.shape
        bx, by, bz = bernstein(l - 1, s[:, 0]), bernstein(m - 1, s[:, 1]), bernstein(n - 1, s[:, 2])
        return (bx[:, :, None, None] * by[:, None, :, None] * bz[:, None, None, :]).reshape(len(s), -1)

    def apply(self, points: np.ndarray, chunk: int = CHUNK) -> np.ndarray:
        """Deformed copy of points (..., 3), mm: X(p) = p + Σ B_ijk(s)(P_ijk − R_ijk) inside the box,
        p unchanged outside it (docs/model.md §6).

        Evaluated per block of `chunk` points as a tensor product from the per-axis Bernstein
        values — Σ_jk by (B_j B_k) as one small matrix product, then Σ_i — never the (N, K) basis:
        O(N·K) operations, O(chunk·m·n) memory. Its matrix products are thin: whoever runs the
        work does best to limit BLAS to one thread (threadpoolctl), as the commands do.
        """
        moved = points_copy(points)
        flat = moved.reshape(-1, 3)                         # a view: each block is read before it moves
        l, m, n = self.shape
        D = self.displacements.reshape(l, m, n, 3)
        disp = np.ascontiguousarray(D.transpose(1, 2, 0, 3).reshape(m * n, l * 3))   # rows (j, k), columns (i, xyz)
        chunk = max(int(chunk), 1)
        extent = self.hi - self.lo
        for start in range(0, len(flat), chunk):
            block = flat[start:start + chunk]
            s = (block - self.lo) / extent
            inside = ((s >= 0) & (s <= 1)).all(axis=1)
            every = inside.all()
            if not every:
                inside = np.flatnonzero(inside)
                if len(inside) == 0:
                    continue
                s = s[inside]
            bx = bernstein(l - 1, s[:, 0])
            by = bernstein(m - 1, s[:, 1])
            bz = bernstein(n - 1, s[:, 2])
            byz = (by[:, :, None] * bz[:, None, :]).reshape(len(s), m * n)
            t = (byz @ disp).reshape(len(s), l, 3)          # Σ_jk B_j B_k D_ijk: (c, l, 3)
            move = np.einsum("ci,cid->cd", bx, t)                # Σ_i B_i (…): (c, 3)
            if every:
                flat[start:start + len(block)] += move
            else:
                flat[start + inside] += move
        return moved

    __call__ = apply

    def laplacian(self) -> sparse.csr_matrix:
        """(K, K) graph Laplacian of the lattice's 6-neighbourhood (degree − adjacency), sparse."""
        def path(k):                                            # 1-D path-graph Laplacian
            d = np.full(k, 2.0)
            d[[0, -1]] = 1.0
            return sparse.diags([d, -np.ones(k - 1), -np.ones(k - 1)], [0, 1, -1])
        l, m, n = self.shape
        eye = lambda k: sparse.identity(k)
        return sparse.csr_matrix(sparse.kron(sparse.kron(path(l), eye(m)), eye(n))
                                 + sparse.kron(sparse.kron(eye(l), path(m)), eye(n))
                                 + sparse.kron(sparse.kron(eye(l), eye(m)), path(n)))

    def copy(self) -> "Lattice":
        return Lattice(self.lo, self.hi, self.shape, self._points, self.rest)

    def arrays(self) -> dict[str, np.ndarray]:
        """Plain arrays: shape (3,) int64, box (2, 3) [lo; hi] mm, rest (K, 3) mm, points (K, 3) mm."""
        return {"shape": np.array(self.shape, dtype=np.int64), "box": np.stack([self.lo, self.hi]),
                "rest": self.rest.copy(), "points": self._points.copy()}

    @classmethod
    def from_arrays(cls, shape, box, rest, points) -> "Lattice":
        """The lattice of `arrays()`; ValueError if they are inconsistent."""
        shape, box = np.asarray(shape), np.asarray(box, float)
        if shape.shape != (3,) or box.shape != (2, 3):
            raise ValueError(f"lattice shape {shape.shape} and box {box.shape} must be (3,) and (2, 3)")
        dims = _shape3(shape.tolist())
        rest, points = np.asarray(rest, float), np.asarray(points, float)
        K = int(np.prod(dims))
        if rest.shape != (K, 3) or points.shape != (K, 3):
            raise ValueError(f"lattice of shape {dims} needs {K} control points, has rest {rest.shape} "
                             f"and points {points.shape}")
        return cls(box[0], box[1], dims, points, rest)

    def save(self, path: str | Path) -> Path:
        """Write a `breastplan.lattice/1` NPZ (mm, breast frame), atomically."""
        meta = {"order": "ij: control point (i, j, k) is row (i*m + j)*n + k", "box": "row 0 lo, row 1 hi"}
        return save_npz(path, SCHEMA, self.arrays(), meta=meta)

    @classmethod
    def load(cls, path: str | Path) -> "Lattice":
        """Read a `breastplan.lattice/1` NPZ; ArtefactError naming the file if it is corrupt or inconsistent."""
        art = load_npz(path, SCHEMA, _SPEC)
        try:
            return cls.from_arrays(art["shape"], art["box"], art["rest"], art["points"])
        except ValueError as exc:
            raise ArtefactError(path, f"holds an inconsistent lattice: {exc}") from None

    def __repr__(self) -> str:
        moved = float(np.abs(self.displacements).max())
        return (f"Lattice({'×'.join(map(str, self.shape))}, lo={self.lo.round(3).tolist()}, "
                f"hi={self.hi.round(3).tolist()}, max displacement {moved:.3g} mm)")
