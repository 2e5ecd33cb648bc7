"""The five global deformations of Chen et al. 2000 (docs/model.md §3), vectorised over points.

Every function takes an (N, 3) array (or (..., 3)) in the breast frame, model units, and
returns a new array; the input is never modified and the point order is kept. Inverses
are provided for each (top-shape and flatten-side by a vectorised 1-D root solve).
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Callable, Mapping, Sequence

import numpy as np

from breastplan import Primitive

KIND_PARAMS: dict[str, tuple[str, ...]] = {
    "top-shape": ("s0", "s1", "t0", "t1"),
    "flatten-side": ("h0", "h1"),
    "turn-top": ("g0", "g1"),
    "ptosis": ("b0", "b1"),
    "turn": ("c0", "c1"),
}
"""Parameter names of each kind, in the order the kinds are applied (docs/model.md §3)."""

NEEDS_PRIMITIVE = frozenset({"top-shape", "flatten-side", "turn-top"})
REFERENCE_AXIS = 10.0
"""ζ = z / 10: polynomial arguments normalised by P00's semi-axis (docs/model.md §3)."""


def _copy(points) -> np.ndarray:
    p = np.array(points, dtype=np.float64, copy=True)
    if p.shape[-1] != 3:
        raise ValueError(f"points must have shape (..., 3), got {p.shape}")
    return p


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
    p = _copy(points)
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
    p = _copy(points)
    w = p[..., 1] / a3
    p[..., 0] -= np.where(w > 0, w * (g0 + g1 * w), 0.0)
    return p


def turn_top_inverse(points, g0: float, g1: float, *, primitive: Primitive) -> np.ndarray:
    return turn_top(points, -g0, -g1, primitive=primitive)


# --- top-shape: z scaled by β of the latitude, upper half ----------------------------
def top_shape(points, s0: float, s1: float, t0: float, t1: float, *, primitive: Primitive) -> np.ndarray:
    """z ← z·β(w), w = 2u/π with u the point's latitude, where y > 0 (docs/model.md §3)."""
    prim = _need(primitive, "top-shape")
    p = _copy(points)
    w = prim.latitude(p) * (2 / np.pi)
    p[..., 2] *= np.where(p[..., 1] > 0, beta(w, s0, s1, t0, t1), 1.0)
    return p


def top_shape_inverse(points, s0: float, s1: float, t0: float, t1: float, *,
                      primitive: Primitive) -> np.ndarray:
    """Inverse of top_shape on its first increasing branch.

    On the upper half top-shape maps z ↦ f(z) = z·β(w(z)). Where f is increasing on
    [0, a5] this is the exact inverse. With s1 < 0 (every Table 4.1 shape) f folds back
    just below the nipple, because dw/dz is unbounded there, so no inverse exists for
    points from that band; heights in f([0, z*]) are mapped back to the branch [0, z*] before
    f's first maximum, and higher points (untouched by top-shape) are left as they are.
    """
    prim = _need(primitive, "top-shape")

    def forward(zz):
        return zz * beta(prim.latitude_at(zz) * (2 / np.pi), s0, s1, t0, t1)

    grid = np.linspace(0.0, prim.a5, 4097)
    rising = np.diff(forward(grid)) > 0
    z_star = prim.a5 if rising.all() else grid[np.argmin(rising)]
    p = _copy(points)
    z = p[..., 2]
    sel = (p[..., 1] > 0) & (z > 0) & (z < forward(z_star))  # the branch's image; above it β = 1
    target = z[sel]
    z[sel] = _solve_increasing(forward, target, np.zeros_like(target), np.full_like(target, z_star))
    return p


# --- flatten-side: x scaled by γ(|x|/a2), lateral half ---------------------------------
def flatten_side(points, h0: float, h1: float, *, primitive: Primitive) -> np.ndarray:
    """x ← x·γ(|x|/a2) where x < 0 (lateral half, docs/model.md §3)."""
    a2 = _need(primitive, "flatten-side").a2
    p = _copy(points)
    x = p[..., 0]
    p[..., 0] = np.where(x < 0, x * gamma(-x / a2, h0, h1), x)
    return p


def flatten_side_inverse(points, h0: float, h1: float, *, primitive: Primitive) -> np.ndarray:
    """Inverse of flatten_side where w ↦ w·γ(w) is increasing (true for Table 4.1 values)."""
    a2 = _need(primitive, "flatten-side").a2
    p = _copy(points)
    x = p[..., 0]
    sel = x < 0
    target = -x[sel] / a2
    def forward(w):
        return w * gamma(w, h0, h1)

    hi = np.ones_like(target)
    for _ in range(64):  # widen the bracket until it holds every target (vectorised)
        short = forward(hi) < target
        if not short.any():
            break
        hi[short] *= 2
    x[sel] = -a2 * _solve_increasing(forward, target, np.zeros_like(target), hi)
    return p


def _solve_increasing(f, target: np.ndarray, lo: np.ndarray, hi: np.ndarray, iters: int = 64) -> np.ndarray:
    """Vectorised bisection for f(x) = target with f increasing on [lo, hi] per element."""
    lo, hi = lo.copy(), hi.copy()
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        below = f(mid) < target
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    return 0.5 * (lo + hi)


_FORWARD = {"top-shape": top_shape, "flatten-side": flatten_side, "turn-top": turn_top,
            "ptosis": ptosis, "turn": turn}
_INVERSE = {"top-shape": top_shape_inverse, "flatten-side": flatten_side_inverse,
            "turn-top": turn_top_inverse, "ptosis": ptosis_inverse, "turn": turn_inverse}


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


def apply_kind(points, kind: str, params, primitive: Primitive | None = None, *, inverse: bool = False):
    """Apply (or undo) one deformation kind with parameters given as a mapping or a sequence."""
    values = kind_params(kind, params)
    fn = (_INVERSE if inverse else _FORWARD)[kind]
    if kind in NEEDS_PRIMITIVE:
        return fn(points, *values, primitive=_need(primitive, kind))
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
        p = _copy(points)
        for kind in self.active():
            p = apply_kind(p, kind, self.params(kind), primitive)
        return p

    def inverse(self, points, primitive: Primitive | None = None) -> np.ndarray:
        """Undo `apply`: the inverses in reverse order."""
        p = _copy(points)
        for kind in reversed(self.active()):
            p = apply_kind(p, kind, self.params(kind), primitive, inverse=True)
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
