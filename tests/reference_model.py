"""A second, independent implementation of the breast model, written from docs/model.md alone.

The tests compare the package against it (tests/test_reference.py), so that a formula bug in the
package is not hidden by test truths that the same code computed. Nothing here imports breastplan
or was copied from it; where the docs define something as the solution of conditions (the β and γ
profiles are Hermite polynomials), it is built from the conditions, not from the coefficients the
docs print.

Frames and units (docs/model.md §1): points are (..., 3) arrays in the breast frame, x lateral on
the left breast, y superior, z anterior (chest wall z = 0 → nipple); the model formulas work in
model units (mu, 1 mu = 6 mm); volumes in cc (1 cc = 1000 mm³). A primitive is the sequence
(a1, a2, a3, a4, a5, eps1, eps2) (semi-axes in mu). A deformation is the 12-vector
(s0 s1 t0 t1 h0 h1 g0 g1 b0 b1 c0 c1) of docs/model.md §3, model units.
"""
from __future__ import annotations

from math import comb

import numpy as np
from scipy.special import beta as euler_beta
from scipy.spatial import cKDTree

MM_PER_MU = 6.0
"""docs/model.md §1: 1 mu = 6 mm."""
P00 = (10.0, 10.0, 10.0, 10.0, 10.0, 1.0, 1.0)
"""The thesis's reference breast: five semi-axes of 10 mu, eps = (1, 1)."""
ORDER = ("top-shape", "flatten-side", "turn-top", "ptosis", "turn")
"""The fixed order in which the deformations apply and are stored (docs/model.md §3)."""
SLICES = {"top-shape": slice(0, 4), "flatten-side": slice(4, 6), "turn-top": slice(6, 8),
          "ptosis": slice(8, 10), "turn": slice(10, 12)}
"""Where each kind's parameters sit in the 12-vector."""

TABLE_4_1 = {  # docs/model.md §4, typed from the table: s0 s1 t0 t1 | h0 h1 | g0 g1 | b0 b1 | c0 c1
    "generic": (0, 0, 0, 0, 0, 0, 0.41, 0, 0, 0, 0.38, 0),
    "shape1": (0.5, -1, 0, -1, 0, 0.01, 0, 0.2, -0.2, 0, 0.25, 0),
    "shape2": (1.5, -7, 0, -5, 0, 0.05, 0.05, 0.05, -0.1, 0, 0, 0.05),
    "shape3": (1, -0.5, 0.5, -0.5, 0.1, 0, 0, 0.3, 0, -0.05, 0.3, 0.05),
    "shape4": (1, -0.5, 0.5, -0.5, 0, 0, 0.41, 0, -0.1, -0.05, 0.38, 0),
}
"""Thesis Table 4.1 as docs/model.md §4 reads it (N/A → 0), as 12-vectors."""

TABLE_4_2 = {  # docs/model.md §4: condition → (kind, first row, last row)
    "ptosis b0": ("ptosis", (0.45, 0), (2.25, 0)),
    "ptosis b1": ("ptosis", (0, 0.1), (0, 0.5)),
    "ptosis b0>b1": ("ptosis", (0.225, 0.05), (1.125, 0.25)),
    "ptosis b1>=b0": ("ptosis", (0.05, 0.1), (0.5, 0.5)),
    "turn c0>c1": ("turn", (0.3, 0.05), (1.1, 0.5)),
    "turn c1>c0": ("turn", (0.05, 0.125), (0.5, 0.625)),
    "top-shape s0->s1+": ("top-shape", (-0.5, 0.25, 0, 0), (-2.5, 2, 0, 0)),
    "top-shape s1->s0+": ("top-shape", (0.25, -0.5, 0, 0), (1.75, -2, 0, 0)),
}
"""Thesis Table 4.2 (repaired) as docs/model.md §4 prints it."""


# --- §1 units ------------------------------------------------------------------------------------
def mu(mm):
    """mm → model units."""
    return np.asarray(mm, float) / MM_PER_MU


def mm(mu_):
    """model units → mm."""
    return np.asarray(mu_, float) * MM_PER_MU


# --- §2 the primitive ----------------------------------------------------------------------------
def spow(t, e):
    """Signed power sign(t)·|t|^e."""
    return np.sign(t) * np.abs(t) ** e


def surface(prim, u, v) -> np.ndarray:
    """Surface points (..., 3) mu at latitude u ∈ [0, π/2] and longitude v ∈ [−π, π) (broadcast)."""
    a1, a2, a3, a4, a5, e1, e2 = prim
    u, v = np.broadcast_arrays(np.asarray(u, float), np.asarray(v, float))
    ax = np.where(np.cos(v) >= 0, a1, a2)
    ay = np.where(np.sin(v) >= 0, a3, a4)
    return np.stack([ax * spow(np.cos(u), e1) * spow(np.cos(v), e2),
                     ay * spow(np.cos(u), e1) * spow(np.sin(v), e2),
                     a5 * spow(np.sin(u), e1)], axis=-1)


def sample(prim, n_u: int = 100, n_v: int = 100) -> np.ndarray:
    """(n_u·n_v, 3) mu on the (u, v) grid: u uniform on [0, π/2] with both ends, v uniform on
    [−π, π) without π, u-major (point k ↔ latitude k // n_v, longitude k % n_v)."""
    u = np.linspace(0.0, np.pi / 2, n_u)
    v = np.array([-np.pi + 2 * np.pi * k / n_v for k in range(n_v)])
    return surface(prim, u[:, None], v[None, :]).reshape(-1, 3)


def inside_outside(prim, p) -> np.ndarray:
    """F(p): < 1 inside, 1 on the surface, > 1 outside; the half's semi-axes by the signs of x, y."""
    a1, a2, a3, a4, a5, e1, e2 = prim
    p = np.asarray(p, float)
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    ax = np.where(x >= 0, a1, a2)
    ay = np.where(y >= 0, a3, a4)
    g = (np.abs(x / ax) ** (2 / e2) + np.abs(y / ay) ** (2 / e2)) ** (e2 / e1)
    return g + np.abs(z / a5) ** (2 / e1)


def radial_distance(prim, p) -> np.ndarray:
    """Gross & Boult radial distance |p|·|1 − F^(−eps1/2)|, mu."""
    p = np.asarray(p, float)
    return np.linalg.norm(p, axis=-1) * np.abs(1 - inside_outside(prim, p) ** (-prim[5] / 2))


def height(prim, p) -> np.ndarray:
    """Height of the surface above the (x, y) of p, mu: F = 1 solved for z; 0 outside the base."""
    p = np.array(p, float)
    p[..., 2] = 0.0
    return prim[4] * np.maximum(1 - inside_outside(prim, p), 0.0) ** (prim[5] / 2)


def latitude(prim, z) -> np.ndarray:
    """Latitude u of a point at height z: sin u = clip(z/a5, 0, 1)^(1/eps1)."""
    return np.arcsin(np.clip(np.asarray(z, float) / prim[4], 0.0, 1.0) ** (1 / prim[5]))


def volume_mu3(prim) -> float:
    """Closed-form volume of the closed half superellipsoid, mu³."""
    a1, a2, a3, a4, a5, e1, e2 = prim
    return e1 * e2 / 4 * euler_beta(e1 / 2 + 1, e1) * euler_beta(e2 / 2, e2 / 2) * a5 * (a3 + a4) * (a1 + a2)


def volume_cc(prim) -> float:
    """Closed-form volume, cc."""
    return volume_mu3(prim) * MM_PER_MU**3 / 1000.0


# --- §3 the five global deformations --------------------------------------------------------------
def beta_profile(w, s0, s1, t0, t1):
    """Top-shape's β: the quintic Hermite polynomial with β(0) = β(1) = 1, β′ = (s0, s1), β″ = (t0, t1),
    as 1 + s0·H1 + t0·H2 + s1·H4 + t1·H5 in the quintic Hermite basis (the value basis H0 + H3 = 1)."""
    w = np.asarray(w, float)
    h1 = w - 6 * w**3 + 8 * w**4 - 3 * w**5            # H1: H1′(0) = 1, every other end condition 0
    h2 = (w**2 - 3 * w**3 + 3 * w**4 - w**5) / 2       # H2: H2″(0) = 1
    h4 = -4 * w**3 + 7 * w**4 - 3 * w**5               # H4: H4′(1) = 1
    h5 = (w**3 - 2 * w**4 + w**5) / 2                  # H5: H5″(1) = 1
    return 1 + s0 * h1 + t0 * h2 + s1 * h4 + t1 * h5


def gamma_profile(w, h0, h1):
    """Flatten-side's γ: the cubic Hermite polynomial with γ(0) = 1, γ′(0) = 0, γ(1) = 1 − h0, γ′(1) = h1."""
    w = np.asarray(w, float)
    value0 = 2 * w**3 - 3 * w**2 + 1                   # Hermite h00
    value1 = -2 * w**3 + 3 * w**2                      # h01
    slope1 = w**3 - w**2                               # h11
    return value0 + (1 - h0) * value1 + h1 * slope1


def ptosis(p, b0, b1) -> np.ndarray:
    """y ← y − (b0·ζ + b1·ζ²), ζ = z/10, every point."""
    p = np.array(p, float)
    zeta = p[..., 2] / 10
    p[..., 1] = p[..., 1] - (b0 * zeta + b1 * zeta**2)
    return p


def turn(p, c0, c1) -> np.ndarray:
    """x ← x − (c0·ζ + c1·ζ²), ζ = z/10, every point."""
    p = np.array(p, float)
    zeta = p[..., 2] / 10
    p[..., 0] = p[..., 0] - (c0 * zeta + c1 * zeta**2)
    return p


def top_shape(p, prim, s0, s1, t0, t1) -> np.ndarray:
    """z ← z·β(w), w = 2u/π (u the point's latitude), where y > 0."""
    p = np.array(p, float)
    w = 2 * latitude(prim, p[..., 2]) / np.pi
    upper = p[..., 1] > 0
    p[..., 2] = np.where(upper, p[..., 2] * beta_profile(w, s0, s1, t0, t1), p[..., 2])
    return p


def top_shape_preimages(p, prim, s0, s1, t0, t1, n: int = 20_001) -> np.ndarray:
    """For each point p (upper half), how many heights z in (0, a5] top-shape maps to its height (on a
    fine grid of z): a point whose height has one preimage can be taken back whatever it is."""
    z = np.linspace(0.0, prim[4], n)[1:]
    f = top_shape(np.column_stack([0 * z, 1 + 0 * z, z]), prim, s0, s1, t0, t1)[:, 2]
    h = np.asarray(p, float)[:, 2:3]
    return (np.diff(np.sign(f[None, :] - h), axis=1) != 0).sum(axis=1) + (f[0] > h[:, 0])


def flatten_side(p, prim, h0, h1) -> np.ndarray:
    """x ← x·γ(|x|/a2), where x < 0."""
    p = np.array(p, float)
    x = p[..., 0]
    p[..., 0] = np.where(x < 0, x * gamma_profile(np.abs(x) / prim[1], h0, h1), x)
    return p


def turn_top(p, prim, g0, g1) -> np.ndarray:
    """x ← x − (g0·w + g1·w²), w = y/a3, where y > 0."""
    p = np.array(p, float)
    w = p[..., 1] / prim[2]
    p[..., 0] = np.where(p[..., 1] > 0, p[..., 0] - (g0 * w + g1 * w**2), p[..., 0])
    return p


def apply_kind(p, kind: str, params, prim) -> np.ndarray:
    """One deformation kind with its parameters in docs order."""
    if kind == "ptosis":
        return ptosis(p, *params)
    if kind == "turn":
        return turn(p, *params)
    return {"top-shape": top_shape, "flatten-side": flatten_side, "turn-top": turn_top}[kind](p, prim, *params)


def deform(p, prim, vector) -> np.ndarray:
    """All five deformations of a 12-vector, in docs order (mu in, mu out)."""
    vector = np.asarray(vector, float)
    for kind in ORDER:
        p = apply_kind(p, kind, vector[SLICES[kind]], prim)
    return p


def with_kind(vector, kind: str, change) -> np.ndarray:
    """The 12-vector with `change` added to `kind`'s parameters ("Changing one kind", docs §3)."""
    out = np.array(vector, float)
    out[SLICES[kind]] += np.asarray(change, float)
    return out


def breast(prim, vector, n_u: int = 100, n_v: int = 100) -> np.ndarray:
    """A breast: the primitive's (u, v) sample deformed by the 12-vector, mu. A condition's row
    changes the breast's own parameters (`with_kind`) and the chain is redone from the sample."""
    return deform(sample(prim, n_u, n_v), prim, vector)


# --- §4 conditions; §5 extent and degree ----------------------------------------------------------
def condition_at(name: str, t) -> np.ndarray:
    """(..., n_params) point at(t) = first + t·(last − first) of a Table 4.2 line."""
    _, first, last = TABLE_4_2[name]
    t = np.asarray(t, float)[..., None]
    return np.asarray(first, float) + t * (np.asarray(last, float) - np.asarray(first, float))


def condition_rows(name: str, dd: int) -> np.ndarray:
    """(dd, n_params): row j = 1 … dd is the point t = (j − 1)/(dd − 1)."""
    return condition_at(name, [(j - 1) / (dd - 1) for j in range(1, dd + 1)])


def extent(original, deformed) -> float:
    """Mean over corresponding points of ‖o − m‖/‖o‖."""
    o, d = np.asarray(original, float), np.asarray(deformed, float)
    return float(np.mean(np.linalg.norm(o - d, axis=-1) / np.linalg.norm(o, axis=-1)))


def signed_extent(original, deformed, a5) -> float:
    """Top-shape's extent: mean z-change of the original upper half (y > 0), divided by a5."""
    o, d = np.asarray(original, float), np.asarray(deformed, float)
    upper = o[:, 1] > 0
    return float(np.mean(d[upper, 2] - o[upper, 2]) / a5)


def condition_extent(name: str, original, deformed, a5) -> float:
    """The extent a condition's degrees use (signed for top-shape)."""
    if TABLE_4_2[name][0] == "top-shape":
        return signed_extent(original, deformed, a5)
    return extent(original, deformed)


def reference_extents(name: str, dd: int, n_u: int = 100, n_v: int = 100) -> np.ndarray:
    """E_0j: P00 with the generic shape, its condition kind changed by each row."""
    kind = TABLE_4_2[name][0]
    generic = TABLE_4_1["generic"]
    p0 = breast(P00, generic, n_u, n_v)
    return np.array([condition_extent(name, p0, breast(P00, with_kind(generic, kind, row), n_u, n_v), P00[4])
                     for row in condition_rows(name, dd)])


def continuous_degree(e, reference) -> np.ndarray:
    """Piecewise-linear degree (degree j at E_0j), continued along the end segments; a decreasing
    reference (signed extents) is handled by flipping signs."""
    ref = np.asarray(reference, float)
    e = np.asarray(e, float)
    if ref[-1] < ref[0]:
        ref, e = -ref, -e
    n = len(ref)
    seg = np.clip(np.searchsorted(ref, e) - 1, 0, n - 2)        # segment [seg, seg + 1], ends extended
    return seg + 1 + (e - ref[seg]) / (ref[seg + 1] - ref[seg])


def discrete_degree(e, reference) -> np.ndarray:
    """Thesis degree: 1 + index of the nearest reference extent."""
    return 1 + np.argmin(np.abs(np.asarray(e, float)[..., None] - np.asarray(reference, float)), axis=-1)


# --- §6 the FFD lattice --------------------------------------------------------------------------
def bernstein(d: int, i: int, s) -> np.ndarray:
    """B_i^d(s) = C(d, i)·s^i·(1 − s)^(d − i)."""
    s = np.asarray(s, float)
    return comb(d, i) * s**i * (1 - s) ** (d - i)


def rest_lattice(lo, hi, shape) -> np.ndarray:
    """(l, m, n, 3) regular control points of the box [lo, hi]: P_ijk = lo + (i/(l−1), j/(m−1), k/(n−1))·(hi − lo)."""
    l, m, n = shape
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    out = np.empty((l, m, n, 3))
    for i in range(l):
        for j in range(m):
            for k in range(n):
                out[i, j, k] = lo + np.array([i / (l - 1), j / (m - 1), k / (n - 1)]) * (hi - lo)
    return out


def ffd(points, lo, hi, control) -> np.ndarray:
    """X(p) = Σ_ijk B_ijk(s)·P_ijk for points inside the box [lo, hi] (s = (p − lo)/(hi − lo)); points
    outside are left where they are. `control` is (l, m, n, 3); row (i·m + j)·n + k of a flat (K, 3)
    array is P_ijk ("ij" order)."""
    p = np.asarray(points, float)
    l, m, n, _ = control.shape
    s = (p - np.asarray(lo, float)) / (np.asarray(hi, float) - np.asarray(lo, float))
    out = np.zeros_like(p)
    for i in range(l):
        for j in range(m):
            for k in range(n):
                weight = bernstein(l - 1, i, s[:, 0]) * bernstein(m - 1, j, s[:, 1]) * bernstein(n - 1, k, s[:, 2])
                out += weight[:, None] * control[i, j, k]
    inside = np.all((s >= 0) & (s <= 1), axis=1)
    return np.where(inside[:, None], out, p)


def normalised_residual(data, closest) -> float:
    """The fit's residual: mean over data points d of ‖d − m‖/‖d‖ (m its closest model point)."""
    d = np.asarray(data, float)
    return float(np.mean(np.linalg.norm(d - np.asarray(closest, float), axis=1) / np.linalg.norm(d, axis=1)))


# --- §7 metrics -----------------------------------------------------------------------------------
def rmse_pct(predicted, target) -> float:
    """sqrt(mean((f − y)²)) / |mean(y)| · 100."""
    f, y = np.asarray(predicted, float), np.asarray(target, float)
    return float(np.sqrt(np.mean((f - y) ** 2)) / abs(np.mean(y)) * 100)


def modelled_to_original(original, modelled) -> tuple[float, float]:
    """(Euclidean, Hausdorff) in % of M ⇒ O: each modelled point's distance to its nearest original
    point o*, divided by ‖o*‖; mean and maximum."""
    o, m = np.asarray(original, float), np.asarray(modelled, float)
    dist, nearest = cKDTree(o, balanced_tree=False).query(m)
    rel = dist / np.linalg.norm(o[nearest], axis=1) * 100
    return float(rel.mean()), float(rel.max())
