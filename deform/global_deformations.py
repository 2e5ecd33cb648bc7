"""The five global deformations of Chen et al. 2000 (docs/model.md §3), vectorised over points.

Every function takes an (N, 3) array (or (..., 3)) in the breast frame, model units, and
returns a new array; the input is never modified and the point order is kept. Inverses
are provided for each (top-shape and flatten-side from tables of their 1-D maps, refined by
scipy's bracketed root finder).
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Callable, Mapping, Sequence

import numpy as np

from breastplan import Primitive
from breastplan.frames import points_copy

from .names import KIND_PARAMS, NEEDS_PRIMITIVE

REFERENCE_AXIS = 10.0
"""ζ = z / 10: polynomial arguments normalised by P00's semi-axis (docs/model.md §3)."""
TABLE_SIZE = 512
"""Nodes of the tables of the 1-D maps that top-shape and flatten-side invert."""


def _need(primitive: Primitive | None, kind: str) -> Primitive:
    if primitive is None:
        raise ValueError(f"the {kind} deformation needs the breast primitive")
    return primitive


def beta(w, s0, s1, t0, t1):
    """Top-shape quintic Hermite β(w) (docs/model.md §3): β(0)=β(1)=1, β'=(s0,s1), β''=(t0,t1)."""
    a = -t0 / 2 - 3 * s0 - 3 * s1 + t1 / 2
    b = 3 * t0 / 2 + 8 * s0 + 7 * s1 - t1
    c = -3 * t0 / 2 - 6 * s0 - 4 * s1 + t1 / 2
    return ((((a * w + b) * w + c) * w + t0 / 2) * w + s0) * w + 1.0


def gamma(w, h0, h1):
    """Flatten-side cubic Hermite γ(w) (docs/model.md §3): γ(0)=1, γ'(0)=0, γ(1)=1−h0, γ'(1)=h1."""
    g = 1.0 - h0
    return ((h1 + 2 - 2 * g) * w + (3 * g - 3 - h1)) * w * w + 1.0


# --- ptosis, turn: shears along y, x driven by z ------------------------------------
def _shear_by_z(points, axis: int, k0: float, k1: float) -> np.ndarray:
    """coordinate `axis` ← itself − (k0·ζ + k1·ζ²), ζ = z/10, all points."""
    p = points_copy(points)
    zeta = p[..., 2] / REFERENCE_AXIS
    p[..., axis] -= zeta * (k0 + k1 * zeta)
    return p


def ptosis(points, b0: float, b1: float) -> np.ndarray:
    """y ← y − (b0·ζ + b1·ζ²), ζ = z/10, all points (docs/model.md §3)."""
    return _shear_by_z(points, 1, b0, b1)


def ptosis_inverse(points, b0: float, b1: float) -> np.ndarray:
    return ptosis(points, -b0, -b1)


def turn(points, c0: float, c1: float) -> np.ndarray:
    """x ← x − (c0·ζ + c1·ζ²), ζ = z/10, all points (docs/model.md §3)."""
    return _shear_by_z(points, 0, c0, c1)


def turn_inverse(points, c0: float, c1: float) -> np.ndarray:
    return turn(points, -c0, -c1)


# --- turn-top: shear along x driven by y, upper half ---------------------------------
def turn_top(points, g0: float, g1: float, *, primitive: Primitive) -> np.ndarray:
    """x ← x − (g0·w + g1·w²), w = y/a3, where y > 0 (docs/model.md §3)."""
    a3 = _need(primitive, "turn-top").a3
    p = points_copy(points)
    w = p[..., 1] / a3
    p[..., 0] -= np.where(w > 0, w * (g0 + g1 * w), 0.0)
    return p


def turn_top_inverse(points, g0: float, g1: float, *, primitive: Primitive) -> np.ndarray:
    return turn_top(points, -g0, -g1, primitive=primitive)


# --- top-shape: z scaled by β of the latitude, upper half ----------------------------
def top_shape(points, s0: float, s1: float, t0: float, t1: float, *, primitive: Primitive) -> np.ndarray:
    """z ← z·β(w), w = 2u/π with u the point's latitude, where y > 0 (docs/model.md §3)."""
    prim = _need(primitive, "top-shape")
    p = points_copy(points)
    w = prim.latitude(p) * (2 / np.pi)
    p[..., 2] *= np.where(p[..., 1] > 0, beta(w, s0, s1, t0, t1), 1.0)
    return p


def top_shape_inverse(points, s0: float, s1: float, t0: float, t1: float, *,
                      primitive: Primitive, fast: bool = False) -> np.ndarray:
    """Inverse of top_shape on the upper half, from a table of its 1-D map refined by root bracketing.

    On the upper half top-shape maps z ↦ f(z) = z·β(w(z)), monotone only piecewise: with s1 < 0
    (every Table 4.1 shape) f rises to a maximum and folds back to a5 just below the nipple, because
    dw/dz is unbounded there (docs/model.md §3), and some rows of the conditions, on a primitive with
    eps1 < 1, make it rise, fall and rise again; a height may then have several preimages. A point
    takes the one on the piece of the map nearest the primitive's own surface height above its (x, y),
    which is where a surface point comes from (a point inside the breast, in a band of several
    preimages, may come from another). Exact (default): among the pieces whose images hold its height,
    solved to rounding by scipy's bracketed root finder inside the table's bracket; heights that are
    no image are left as they are. `fast`, for surface points, as a fit needs hundreds of times: the
    table's linear interpolation on the piece holding that surface height, clipped to its images.
    """
    prim = _need(primitive, "top-shape")

    def forward(z):
        return z * beta(prim.latitude_at(z) * (2 / np.pi), s0, s1, t0, t1)

    z, image, bounds = top_shape_table(prim.a5, prim.eps1, s0, s1, t0, t1)
    p = points_copy(points)
    sel = (p[..., 1] > 0) & (p[..., 2] > 0)
    h, surface = p[..., 2][sel], prim.height(p[sel])
    if fast:
        piece = np.searchsorted(z[bounds[1:-1]], surface, side="left")
    else:
        z, image, bounds = _true_turns(forward, z, image, bounds)
        piece = _nearest_piece(h, surface, z, image, bounds)
        found = piece >= 0                                    # heights that are some height's image
        sel[sel] = found
        h, piece = h[found], piece[found]
    p[..., 2][sel] = _piece_inverse(h, piece, z, image, bounds, forward if not fast else None)
    return p


def _monotone_pieces(image: np.ndarray) -> np.ndarray:
    """Nodes splitting a tabulated map into its monotone pieces: piece i runs from node bounds[i] to node
    bounds[i + 1] (a flat step counts as falling)."""
    rising = np.diff(image) > 0
    turns = np.flatnonzero(rising[1:] != rising[:-1]) + 1
    return np.r_[0, turns, len(image) - 1]


def _true_turns(f, z: np.ndarray, image: np.ndarray, bounds: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The table with each interior turn node moved to the map's true extremum between its neighbours
    (scipy's bounded scalar minimiser), so that the heights beyond a turn node, up to the true extremum,
    have their preimages."""
    if len(bounds) == 2:
        return z, image, bounds
    from scipy.optimize import minimize_scalar

    z, image = z.copy(), image.copy()
    for k in bounds[1:-1]:
        sign = 1.0 if image[k] >= image[k - 1] else -1.0          # a maximum, or a minimum
        best = minimize_scalar(lambda v: -sign * f(v), bounds=(z[k - 1], z[k + 1]), method="bounded",
                               options={"xatol": 1e-12 * max(z[-1], 1.0)})
        if sign * f(best.x) > sign * image[k]:
            z[k], image[k] = best.x, f(best.x)
    return z, image, bounds


def _nearest_piece(h: np.ndarray, guide: np.ndarray, z: np.ndarray, image: np.ndarray, bounds: np.ndarray
                   ) -> np.ndarray:
    """For each height h, of the monotone pieces whose images hold it, the one whose heights z lie nearest
    its guide height; −1 for none."""
    piece, best = np.full(len(h), -1), np.full(len(h), np.inf)
    for i in range(len(bounds) - 1):
        ends = image[[bounds[i], bounds[i + 1]]]
        off = np.maximum(z[bounds[i]] - guide, 0.0) + np.maximum(guide - z[bounds[i + 1]], 0.0)
        better = (ends.min() <= h) & (h <= ends.max()) & (off < best)
        piece[better], best[better] = i, off[better]
    return piece


def _piece_inverse(h: np.ndarray, piece: np.ndarray, z: np.ndarray, image: np.ndarray, bounds: np.ndarray,
                  forward=None) -> np.ndarray:
    """Preimages of heights h, each on its monotone piece of the tabulated map (z, image) (`_monotone_pieces`),
    clipped to that piece's images: the table's interpolation, refined to rounding if `forward` (the map) is
    given."""
    out = np.empty_like(h)
    for i in np.unique(piece):
        on = piece == i
        zs, fs = z[bounds[i]:bounds[i + 1] + 1], image[bounds[i]:bounds[i + 1] + 1]
        if fs[-1] < fs[0]:
            zs, fs = zs[::-1], fs[::-1]
        out[on] = _monotone_inverse(forward, h[on], zs, fs, exact=forward is not None)
    return out


_TABLE_SINES = np.sin(np.linspace(0.0, np.pi / 2, TABLE_SIZE))
"""sin u at the TABLE_SIZE latitudes of top-shape's table, u uniform on [0, π/2]."""
_TABLE_LATITUDES: dict = {}
"""(a5, eps1) ↦ (table heights z, their latitudes w = 2u/π): a fit's table changes with s0…t1 far more
often than with the primitive (each column of its finite-difference Jacobian steps one of them)."""


def top_shape_table(a5, eps1, s0, s1, t0, t1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Top-shape's map z ↦ z·β(w(z)) on the upper half, tabulated (`top_shape_inverse`): the heights
    z = a5·sin(u)^eps1 at TABLE_SIZE latitudes u uniform on [0, π/2], their images, and the nodes
    bounding the map's monotone pieces (`_monotone_pieces`; [0, last node] if it rises throughout)."""
    key = (float(a5), float(eps1))
    cached = _TABLE_LATITUDES.get(key)
    if cached is None:
        z = a5 * _TABLE_SINES ** eps1
        w = np.arcsin(np.clip(z / a5, 0.0, 1.0) ** (1.0 / eps1)) * (2 / np.pi)   # Primitive.latitude_at(z)·2/π
        z.flags.writeable = w.flags.writeable = False             # shared by every table of (a5, eps1)
        if len(_TABLE_LATITUDES) >= 64:
            _TABLE_LATITUDES.clear()
        _TABLE_LATITUDES[key] = cached = (z, w)
    z, w = cached
    image = z * beta(w, s0, s1, t0, t1)
    return z, image, _monotone_pieces(image)


# --- flatten-side: x scaled by γ(|x|/a2), lateral half ---------------------------------
def flatten_side(points, h0: float, h1: float, *, primitive: Primitive) -> np.ndarray:
    """x ← x·γ(|x|/a2) where x < 0 (lateral half, docs/model.md §3)."""
    a2 = _need(primitive, "flatten-side").a2
    p = points_copy(points)
    x = p[..., 0]
    p[..., 0] = np.where(x < 0, x * gamma(-x / a2, h0, h1), x)
    return p


def flatten_side_inverse(points, h0: float, h1: float, *, primitive: Primitive, fast: bool = False) -> np.ndarray:
    """Inverse of flatten_side where w ↦ w·γ(w) is increasing (true for Table 4.1 values): a table of
    that map over [0, w_max] (widened until it holds every point), refined by root bracketing
    unless `fast` (see `top_shape_inverse`)."""
    a2 = _need(primitive, "flatten-side").a2
    p = points_copy(points)
    x = p[..., 0]
    sel = x < 0
    target = -x[sel] / a2

    def forward(w):
        return w * gamma(w, h0, h1)

    reach = target.max(initial=0.0)
    w_max = max(1.0, 1.5 * reach)
    while forward(w_max) < reach and w_max < 2.0**64:
        w_max *= 2
    w = np.linspace(0.0, w_max, TABLE_SIZE)
    x[sel] = -a2 * _monotone_inverse(forward, target, w, forward(w), exact=not fast)
    return p


def _monotone_inverse(f, target: np.ndarray, xs: np.ndarray, fs: np.ndarray, exact: bool) -> np.ndarray:
    """x with f(x) = target for f increasing on the table (xs, fs = f(xs)); targets beyond the table
    clip to its ends. Linear interpolation of the table, then (exact) scipy's bracketed root finder
    (Chandrupatla) between the two table nodes around each target."""
    x = np.interp(target, fs, xs)
    if not exact or not target.size:
        return x
    k = np.clip(np.searchsorted(fs, target), 1, len(fs) - 1)
    inside = (fs[k - 1] < target) & (target < fs[k])          # on a node or beyond the table: done
    if inside.any():
        from scipy.optimize import elementwise     # only the exact inverses need it

        a, b = xs[k - 1][inside], xs[k][inside]                  # a falling piece's table is read backwards
        res = elementwise.find_root(lambda v, t: f(v) - t, (np.minimum(a, b), np.maximum(a, b)),
                                    args=(target[inside],))
        x[inside] = res.x
    return x


_FORWARD = {"top-shape": top_shape, "flatten-side": flatten_side, "turn-top": turn_top,
            "ptosis": ptosis, "turn": turn}
_INVERSE = {"top-shape": top_shape_inverse, "flatten-side": flatten_side_inverse,
            "turn-top": turn_top_inverse, "ptosis": ptosis_inverse, "turn": turn_inverse}
TABULATED = frozenset({"top-shape", "flatten-side"})
"""The kinds whose inverse interpolates a table of their 1-D map."""


def kind_params(kind: str, params: Mapping[str, float] | Sequence[float]) -> tuple[float, ...]:
    """A kind's parameters as a tuple in docs/model.md order, from a mapping (missing → 0) or a sequence."""
    if kind not in KIND_PARAMS:
        raise ValueError(f"unknown deformation kind '{kind}'; choose one of {', '.join(KIND_PARAMS)}")
    names = KIND_PARAMS[kind]
    if isinstance(params, Mapping):
        unknown = set(params) - set(names)
        if unknown:
            raise ValueError(f"{kind} takes parameters {', '.join(names)}, not {', '.join(sorted(unknown))}")
        return tuple(float(params.get(n, 0.0)) for n in names)
    values = tuple(float(v) for v in params)
    if len(values) != len(names):
        raise ValueError(f"{kind} takes {len(names)} parameters ({', '.join(names)}), got {len(values)}")
    return values


def apply_kind(points, kind: str, params, primitive: Primitive | None = None, *, inverse: bool = False,
               fast: bool = False):
    """Apply (or undo) one deformation kind with parameters given as a mapping or a sequence;
    `fast` inverts top-shape and flatten-side for surface points from their tables (`top_shape_inverse`)."""
    values = kind_params(kind, params)
    fn = (_INVERSE if inverse else _FORWARD)[kind]
    options = {"fast": fast} if inverse and kind in TABULATED else {}
    if kind in NEEDS_PRIMITIVE:
        return fn(points, *values, primitive=_need(primitive, kind), **options)
    return fn(points, *values)


@dataclass(frozen=True)
class Deformation:
    """Parameters of all five deformations; `apply` composes them in docs/model.md §3 order."""

    top_shape: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    flatten_side: tuple[float, float] = (0.0, 0.0)
    turn_top: tuple[float, float] = (0.0, 0.0)
    ptosis: tuple[float, float] = (0.0, 0.0)
    turn: tuple[float, float] = (0.0, 0.0)

    def params(self, kind: str) -> tuple[float, ...]:
        return tuple(getattr(self, kind.replace("-", "_")))

    def active(self) -> list[str]:
        """Kinds with a non-zero parameter, in application order."""
        return [k for k in KIND_PARAMS if any(self.params(k))]

    def apply(self, points, primitive: Primitive | None = None) -> np.ndarray:
        """Deform points (model units); zero-parameter kinds are skipped (they are the identity)."""
        p = points_copy(points)
        for kind in self.active():
            p = apply_kind(p, kind, self.params(kind), primitive)
        return p

    def inverse(self, points, primitive: Primitive | None = None, *, fast: bool = False) -> np.ndarray:
        """Undo `apply`: the inverses in reverse order (`fast`: see `apply_kind`)."""
        p = points_copy(points)
        for kind in reversed(self.active()):
            p = apply_kind(p, kind, self.params(kind), primitive, inverse=True, fast=fast)
        return p

    def as_vector(self) -> np.ndarray:
        """The 12 parameters in docs/model.md order (s0 s1 t0 t1 h0 h1 g0 g1 b0 b1 c0 c1)."""
        return np.concatenate([self.params(k) for k in KIND_PARAMS]).astype(float)

    @classmethod
    def from_vector(cls, values) -> "Deformation":
        values = [float(v) for v in np.asarray(values, dtype=float).ravel()]
        out, i = {}, 0
        for f, names in zip(fields(cls), KIND_PARAMS.values()):
            out[f.name] = tuple(values[i: i + len(names)])
            i += len(names)
        if i != len(values):
            raise ValueError(f"a deformation vector has {i} values, got {len(values)}")
        return cls(**out)

    def split(self, kind: str) -> tuple["Deformation", "Deformation"]:
        """(the stages before `kind`, `kind`'s stage and the later ones), docs/model.md §3 order."""
        names = [f.name for f in fields(self)]   # docs/model.md §3 order
        i = names.index(kind.replace("-", "_"))
        zero = Deformation()
        return (replace(self, **{n: getattr(zero, n) for n in names[i:]}),
                replace(self, **{n: getattr(zero, n) for n in names[:i]}))

    def plus(self, kind: str, params) -> "Deformation":
        """This record with `params` added to `kind`'s parameters."""
        added = np.add(self.params(kind), kind_params(kind, params))
        return replace(self, **{kind.replace("-", "_"): tuple(float(v) for v in added)})

    @classmethod
    def single(cls, kind: str, params) -> "Deformation":
        """A record with only `kind` set."""
        return cls(**{kind.replace("-", "_"): kind_params(kind, params)})


def changing(kind: str, sample, own: Deformation, primitive: Primitive | None = None
             ) -> Callable[[object], np.ndarray]:
    """params ↦ the breast `own.apply(sample)` with `kind`'s parameters changed by `params`.

    A condition changes the breast's own parameters: its kind's stage and the later ones are
    redone from the primitive `sample` (model units), so the chain keeps docs/model.md §3 order. For
    ptosis and turn (shears of the last stages) this equals applying the change on top; for
    top-shape it keeps one top-shape (β of summed parameters) where stacking would give two
    β profiles and two tears at y = 0. Works from the sample because top-shape folds just below
    the nipple and has no inverse there.
    """
    before, rest = own.split(kind)
    base = before.apply(sample, primitive)
    return lambda params: rest.plus(kind, params).apply(base, primitive)
