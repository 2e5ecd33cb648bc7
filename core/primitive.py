"""The breast primitive: a half superellipsoid closed by the chest wall (docs/model.md §2).

All lengths are model units (docs/model.md §1) in the breast frame: z anterior (chest wall
z = 0 → nipple), y superior, x lateral–medial. Latitude u ∈ [0, π/2] (0 = base ring,
π/2 = nipple), longitude v ∈ [−π, π).
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from .units import BREAST_EXTENT_MM, MM_PER_MU, mu3_to_cc

PARAM_NAMES = ("a1", "a2", "a3", "a4", "a5", "eps1", "eps2")
EPS_BOUNDS = (0.3, 2.0)
"""A breast's shape exponents eps1, eps2: from a boxy (0.3) to a pinched (2.0) superellipsoid."""
COMMENT = "primitive (model units)"
"""Start of the PLY header comment that carries a primitive."""


def euler_beta(a: float, b: float) -> float:
    """Euler's beta function B(a, b) = Γ(a)Γ(b)/Γ(a + b) of positive scalars. The ratio of gammas
    agrees with scipy.special.beta to ~2e-15 relative; Γ overflows past 171, so larger arguments go
    through log-gamma (~1e-13 relative there, where lgamma's cancellation grows)."""
    if a + b < 170.0:
        return math.gamma(a) * math.gamma(b) / math.gamma(a + b)
    return math.exp(math.lgamma(a) + math.lgamma(b) - math.lgamma(a + b))


def spow(t, e):
    """Signed power sign(t)·|t|^e (docs/model.md §2)."""
    return np.sign(t) * np.abs(t) ** e


def uv_grid(n_u: int = 100, n_v: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """Latitudes (n_u,) uniform on [0, π/2] inclusive; longitudes (n_v,) uniform on [−π, π)."""
    if n_u < 2 or n_v < 3:
        raise ValueError(f"the (u, v) grid needs n_u >= 2 and n_v >= 3, got {n_u} x {n_v}")
    return np.linspace(0.0, np.pi / 2, n_u), -np.pi + 2 * np.pi * np.arange(n_v) / n_v


@dataclass(frozen=True)
class Primitive:
    """Semi-axes a1 (+x), a2 (−x), a3 (+y), a4 (−y), a5 (z) in model units; shape exponents eps1, eps2."""

    a1: float = 10.0
    a2: float = 10.0
    a3: float = 10.0
    a4: float = 10.0
    a5: float = 10.0
    eps1: float = 1.0
    eps2: float = 1.0

    def __post_init__(self):
        for name in PARAM_NAMES:
            value = getattr(self, name)
            if not isinstance(value, numbers.Real):
                raise TypeError(f"primitive parameter {name} must be a real number, "
                                f"got {type(value).__name__} {value!r}")
            object.__setattr__(self, name, float(value))
        values = self.as_array()
        if not np.isfinite(values).all() or (values <= 0).any():
            raise ValueError(f"primitive parameters must be finite and positive, got {self.as_dict()}")

    @classmethod
    def from_array(cls, values) -> "Primitive":
        """From (a1, a2, a3, a4, a5, eps1, eps2); ValueError for any other number of values."""
        values = np.asarray(values, dtype=float).ravel()
        if len(values) != len(PARAM_NAMES):
            raise ValueError(f"a primitive has {len(PARAM_NAMES)} parameters ({', '.join(PARAM_NAMES)}), "
                             f"got {len(values)} values")
        return cls(*map(float, values))

    def as_array(self) -> np.ndarray:
        return np.array([getattr(self, n) for n in PARAM_NAMES], dtype=float)

    def as_dict(self) -> dict[str, float]:
        return {n: getattr(self, n) for n in PARAM_NAMES}

    def comment(self) -> str:
        """The PLY header comment that carries this primitive (read back by `from_comments`)."""
        return f"{COMMENT} " + " ".join(f"{k}={v:.17g}" for k, v in self.as_dict().items())

    @classmethod
    def from_comments(cls, comments) -> "Primitive | None":
        """The primitive a PLY header comment carries (`comment`), or None; ValueError if it is malformed."""
        for line in comments:
            if line.startswith(COMMENT):
                try:
                    values = dict(item.split("=", 1) for item in line[len(COMMENT):].split())
                    if sorted(values) != sorted(PARAM_NAMES):
                        raise ValueError(f"it names {', '.join(values) or 'nothing'}, not {', '.join(PARAM_NAMES)}")
                    return cls(**{k: float(v) for k, v in values.items()})
                except (TypeError, ValueError) as exc:
                    raise ValueError(f"its primitive comment '{line}' is malformed ({exc})") from None
        return None

    def breast_problem(self) -> str | None:
        """Why this primitive cannot be a breast's (its largest span outside BREAST_EXTENT_MM, a shape
        exponent outside EPS_BOUNDS), or None."""
        span = max(self.a1 + self.a2, self.a3 + self.a4, self.a5) * MM_PER_MU
        if not BREAST_EXTENT_MM[0] <= span <= BREAST_EXTENT_MM[1]:
            return (f"spans {span:.3g} mm, no breast's size ({BREAST_EXTENT_MM[0]:.0f}–{BREAST_EXTENT_MM[1]:.0f} mm; "
                    f"its semi-axes are in model units of {MM_PER_MU:.0f} mm)")
        if not all(EPS_BOUNDS[0] <= e <= EPS_BOUNDS[1] for e in (self.eps1, self.eps2)):
            return (f"has shape exponents eps1 = {self.eps1:.3g}, eps2 = {self.eps2:.3g}, outside a breast's "
                    f"{EPS_BOUNDS[0]}–{EPS_BOUNDS[1]}")
        return None

    # --- surface -------------------------------------------------------------
    def surface(self, u, v) -> np.ndarray:
        """Surface points (..., 3) at broadcastable latitudes u and longitudes v (docs/model.md §2)."""
        u, v = np.broadcast_arrays(np.asarray(u, float), np.asarray(v, float))
        cu, su, cv, sv = np.cos(u), np.sin(u), np.cos(v), np.sin(v)
        ax = np.where(cv >= 0, self.a1, self.a2)
        ay = np.where(sv >= 0, self.a3, self.a4)
        ring = spow(cu, self.eps1)
        return np.stack([ax * ring * spow(cv, self.eps2),
                         ay * ring * spow(sv, self.eps2),
                         self.a5 * spow(su, self.eps1)], axis=-1)

    def sample(self, n_u: int = 100, n_v: int = 100) -> np.ndarray:
        """n_u·n_v surface points (u-major, v-minor): point k ↔ (u_{k // n_v}, v_{k % n_v}).

        The same grid on any two primitives gives point-to-point correspondence. The last
        latitude row is the nipple, repeated n_v times.
        """
        u, v = uv_grid(n_u, n_v)
        return self.surface(u[:, None], v[None, :]).reshape(-1, 3)

    def mesh(self, n_u: int = 100, n_v: int = 100, closed: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Triangle mesh (V, F) from the (u, v) grid, outward-oriented.

        Vertices: grid rows u_0..u_{n_u−2} (n_v each, as in `sample`), then the nipple apex,
        then (closed only) the base centre (0, 0, 0) that closes the base cap at z = 0.
        """
        u, v = uv_grid(n_u, n_v)
        rings = self.surface(u[:-1, None], v[None, :]).reshape(-1, 3)
        V = [rings, [[0.0, 0.0, self.a5]]] + ([[[0.0, 0.0, 0.0]]] if closed else [])
        V = np.vstack([np.asarray(x, float).reshape(-1, 3) for x in V])
        faces = grid_faces(n_u - 1, n_v, closed)
        return V, faces

    # --- implicit form -------------------------------------------------------
    def inside_outside(self, points) -> np.ndarray:
        """F(p): < 1 inside, 1 on, > 1 outside (docs/model.md §2); |z| is used below the base."""
        p = np.asarray(points, dtype=float)
        x, y, z = p[..., 0], p[..., 1], p[..., 2]
        ax = np.where(x >= 0, self.a1, self.a2)
        ay = np.where(y >= 0, self.a3, self.a4)
        e1, e2 = self.eps1, self.eps2
        xy = (np.abs(x / ax) ** (2 / e2) + np.abs(y / ay) ** (2 / e2)) ** (e2 / e1)
        return xy + np.abs(z / self.a5) ** (2 / e1)

    def radial_projection(self, points) -> np.ndarray:
        """Projection of p onto the surface along the ray from the origin: p·F^(−eps1/2)."""
        p = np.asarray(points, dtype=float)
        f = np.maximum(self.inside_outside(p), 1e-300)
        return p * f[..., None] ** (-self.eps1 / 2)

    def radial_distance(self, points) -> np.ndarray:
        """Radial distance |p|·|1 − F^(−eps1/2)| (Gross & Boult; docs/model.md §2), model units."""
        p = np.asarray(points, dtype=float)
        f = np.maximum(self.inside_outside(p), 1e-300)
        return np.linalg.norm(p, axis=-1) * np.abs(1.0 - f ** (-self.eps1 / 2))

    def height(self, points) -> np.ndarray:
        """Height of the surface above the (x, y) of points (..., 3): F = 1 solved for z (docs/model.md §2), 0 outside."""
        flat = self.inside_outside(np.asarray(points, dtype=float) * [1.0, 1.0, 0.0])
        return self.a5 * np.maximum(1.0 - flat, 0.0) ** (self.eps1 / 2)

    def latitude(self, points) -> np.ndarray:
        """Latitude u of arbitrary points (..., 3) (docs/model.md §2)."""
        return self.latitude_at(np.asarray(points, dtype=float)[..., 2])

    def latitude_at(self, z) -> np.ndarray:
        """Latitude u at heights z: sin u = clip(z/a5, 0, 1)^(1/eps1) (docs/model.md §2)."""
        return np.arcsin(np.clip(np.asarray(z, dtype=float) / self.a5, 0.0, 1.0) ** (1.0 / self.eps1))

    # --- volume ----------------------------------------------------------------
    @property
    def volume_mu3(self) -> float:
        """Closed-form volume of the closed half superellipsoid (docs/model.md §2), mu³."""
        e1, e2 = self.eps1, self.eps2
        return float(e1 * e2 / 4 * euler_beta(e1 / 2 + 1, e1) * euler_beta(e2 / 2, e2 / 2)
                     * self.a5 * (self.a3 + self.a4) * (self.a1 + self.a2))

    @property
    def volume_cc(self) -> float:
        """Closed-form volume in cubic centimetres."""
        return float(mu3_to_cc(self.volume_mu3))


def grid_faces(n_rings: int, n_v: int, closed: bool) -> np.ndarray:
    """Outward triangles over `n_rings` rings of `n_v` vertices, an apex, and (closed) a base centre."""
    i, j = np.meshgrid(np.arange(n_rings - 1), np.arange(n_v), indexing="ij")
    a = i * n_v + j
    b = i * n_v + (j + 1) % n_v
    c, d = a + n_v, b + n_v
    quads = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                            np.stack([b, d, c], -1).reshape(-1, 3)])
    ring = np.arange(n_v)
    last, apex = (n_rings - 1) * n_v, n_rings * n_v
    parts = [quads, np.stack([last + ring, last + (ring + 1) % n_v, np.full(n_v, apex)], -1)]
    if closed:
        parts.append(np.stack([np.full(n_v, apex + 1), (ring + 1) % n_v, ring], -1))
    return np.concatenate(parts).astype(np.int64)
