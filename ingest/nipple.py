"""The nipple on an isolated breast: the apex, then the centre of the raised nipple-areola disc.

Points and results are in the viewing frame (mm); the search works in a breast frame
(`ingest.breast.BreastFrame`: z anterior along the chest normal). The apex (the highest point
above the base) is where a firm breast's nipple is, but a heavy or soft breast's apex lies
several millimetres from it. The nipple and areola stand a few millimetres proud of the breast's
smooth surface, so the nipple is refined to the centre of that disc: the residual of the points
over a robust cubic fitted around the apex is smoothed, and the disc is its region above half of
its peak. Where no such disc stands out (too low, too small or too large, not round, or not
clear of the skin around it), the apex is kept.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy import ndimage

APEX_RADIUS_MM = 5.0
"""Radius of the patch fitted around the apex (and the disc's centre) for its height."""
CAP_MM = 2.0
"""The top cap (points this close to the highest) gives the apex's first estimate."""
SURFACE_RADIUS_MM = 28.0
"""The smooth breast surface is fitted on points this far from the apex, in x, y."""
SEARCH_MM = 10.0
"""The disc's peak lies this close to the apex."""
CELL_MM = 0.5
"""Cells of the residual map."""
SMOOTH_MM = 2.0
"""Gaussian σ of the residual map's smoothing."""
DISC_MM = (1.0, (2.0, 12.0))
"""The disc rises at least this far, and its half-height region's equivalent radius lies in this range …"""
ROUND = 1.6
"""… and no point of that region lies further than this many radii from its centre (a disc, not an
arc), and the skin around it …"""
SURROUND = 0.25
"""… (1.5–2.5 radii from its centre) lies below this share of its rise."""
TOP = (0.8, 3.5)
"""The disc's top, for the skin's height over its centre: a round paraboloid fitted to the residuals
within this share of its radius, or this many mm if more (clear of its falling edge)."""


def find_apex(local: np.ndarray) -> np.ndarray:
    """The apex of points in a breast frame (N, 3): centre of the top cap, refined by quadratic patches."""
    cap = local[local[:, 2] > local[:, 2].max() - CAP_MM]
    apex = np.array([*cap[:, :2].mean(0), cap[:, 2].max()])
    for _ in range(4):
        c = _quadratic(local[np.linalg.norm(local[:, :2] - apex[:2], axis=1) < APEX_RADIUS_MM], apex[:2])
        if c is None:
            break
        refined = _quadratic_peak(c, apex[:2])
        if refined is None:                       # too flat for a peak: the fitted height, not the noisiest point's
            apex[2] = c[0]
            break
        moved = np.linalg.norm(refined[:2] - apex[:2])
        apex = refined
        if moved < 0.05:
            break
    return apex


def find_nipple(points: np.ndarray, frame, min_rise: float = DISC_MM[0]) -> tuple[np.ndarray, str]:
    """The nipple (viewing frame) of breast points (viewing frame) seen in `frame`, and how it was
    found: "areola", the centre of the nipple-areola disc near the apex, or "apex" where no disc
    stands out (module docstring) by at least `min_rise` mm."""
    local = frame.to_breast(points)
    apex = find_apex(local)
    disc = find_disc(local, apex[:2], min_rise)
    if disc is None:
        return frame.origin + frame.axes @ apex, "apex"
    return frame.origin + frame.axes @ np.array([*disc.centre, disc.top]), "areola"


class Disc(NamedTuple):
    """The raised nipple-areola disc in a breast frame (mm)."""
    centre: np.ndarray
    """(x, y) of its centroid."""
    top: float
    """Height of the skin over its centre."""


def find_disc(local: np.ndarray, apex_xy: np.ndarray, min_rise: float = DISC_MM[0]) -> Disc | None:
    """The raised disc near `apex_xy` in breast-frame points (N, 3), rising at least `min_rise` mm
    over the breast's smooth surface, or None (module docstring)."""
    near = local[np.linalg.norm(local[:, :2] - apex_xy, axis=1) < SURFACE_RADIUS_MM]
    if len(near) < 50:
        return None
    coef = _robust_cubic(near[:, :2] - apex_xy, near[:, 2])
    residual = near[:, 2] - _cubic_terms(near[:, :2] - apex_xy) @ coef
    n = int(np.ceil((SEARCH_MM + DISC_MM[1][1]) / CELL_MM))                 # the map reaches past any disc
    ij = np.round((near[:, :2] - apex_xy) / CELL_MM).astype(int) + n
    inside = np.all((ij >= 0) & (ij <= 2 * n), axis=1)
    sums, counts = np.zeros((2, 2 * n + 1, 2 * n + 1))
    np.add.at(sums, tuple(ij[inside].T), residual[inside])
    np.add.at(counts, tuple(ij[inside].T), 1.0)
    weight = ndimage.gaussian_filter(counts, SMOOTH_MM / CELL_MM, mode="constant")
    grid = (np.indices(weight.shape) - n) * CELL_MM
    seen = weight > 0.25 * np.median(weight[np.hypot(*grid) <= SEARCH_MM])   # sampled, at any resolution
    smooth = np.where(seen, ndimage.gaussian_filter(sums, SMOOTH_MM / CELL_MM, mode="constant") / np.maximum(weight, 1e-9), 0.0)
    searched = seen & (np.hypot(*grid) <= SEARCH_MM)
    if not searched.any():
        return None
    peak = np.unravel_index(np.argmax(np.where(searched, smooth, -np.inf)), smooth.shape)
    rise = smooth[peak]
    labels, _ = ndimage.label(seen & (smooth >= 0.5 * rise))
    disc = labels == labels[peak]
    radius = np.sqrt(disc.sum() * CELL_MM ** 2 / np.pi)
    border = disc[[0, -1], :].any() or disc[:, [0, -1]].any()
    if rise < min_rise or not DISC_MM[1][0] <= radius <= DISC_MM[1][1] or border:
        return None
    centre = grid[:, disc].mean(1)
    if np.hypot(*(grid[:, disc] - centre[:, None])).max() > ROUND * radius:       # an arc, not a disc
        return None
    apart = np.hypot(*(grid - centre[:, None, None]))
    around = seen & (apart >= 1.5 * radius) & (apart <= 2.5 * radius)
    if not around.any() or np.mean(smooth[around]) > SURROUND * rise:
        return None
    centre = apex_xy + centre
    d = near[:, :2] - centre
    inner = np.hypot(*d.T) < max(TOP[0] * radius, TOP[1])
    if inner.sum() < 6:
        return None
    A = np.column_stack([np.ones(inner.sum()), d[inner], np.sum(d[inner] ** 2, axis=1)])
    paraboloid, *_ = np.linalg.lstsq(A, residual[inner], rcond=None)
    return Disc(centre, float(_cubic_terms(centre[None] - apex_xy)[0] @ coef + paraboloid[0]))


def _robust_cubic(xy: np.ndarray, z: np.ndarray, iterations: int = 6) -> np.ndarray:
    """Coefficients (of `_cubic_terms`) of a cubic z(x, y) fitted to the points below the raised
    disc: points far above the fit (the disc) are left out iteratively."""
    A = _cubic_terms(xy)
    keep = np.ones(len(z), bool)
    for _ in range(iterations):
        coef, *_ = np.linalg.lstsq(A[keep], z[keep], rcond=None)
        r = z - A @ coef
        sigma = max(1.4826 * float(np.median(np.abs(r[keep]))), 0.2)
        keep = (r < max(2.0 * sigma, 0.6)) & (r > -4.0 * sigma)
    return coef


def _cubic_terms(xy: np.ndarray) -> np.ndarray:
    """The ten monomials of degree ≤ 3 in (x, y) / SURFACE_RADIUS_MM, (N, 10)."""
    u, v = (xy / SURFACE_RADIUS_MM).T
    return np.column_stack([u ** i * v ** (d - i) for d in range(4) for i in range(d, -1, -1)])


def _quadratic_peak(c: np.ndarray, centre: np.ndarray) -> np.ndarray | None:
    """Peak of the quadratic with coefficients `c` (of `_quadratic`) about `centre`, if it is a
    maximum within APEX_RADIUS_MM."""
    H = np.array([[2 * c[3], c[4]], [c[4], 2 * c[5]]])
    if not np.all(np.linalg.eigvalsh(H) < 0):
        return None
    d = np.linalg.solve(H, -c[1:3])
    if np.linalg.norm(d) > APEX_RADIUS_MM:
        return None
    return np.array([*(centre + d), c[0] + c[1:3] @ d + 0.5 * d @ H @ d])


def _quadratic(patch: np.ndarray, centre: np.ndarray) -> np.ndarray | None:
    """Coefficients (1, x, y, x², xy, y²) of z fitted to the patch about `centre`; None under 12 points."""
    if len(patch) < 12:
        return None
    x, y = (patch[:, :2] - centre).T
    c, *_ = np.linalg.lstsq(np.column_stack([np.ones_like(x), x, y, x * x, x * y, y * y]), patch[:, 2], rcond=None)
    return c
