"""Exact closest points on a triangle mesh, in numpy, with no loop over the points.

Units and frame are the caller's, one for mesh and data (in breastplan: mm, the breast frame).

Search. The mesh is cut into *pieces*: its triangles, except that a triangle much larger than the
mesh's typical one (the base cap's fan of a model mesh) is cut into cells, so that no box covers
half the mesh. An upper bound U of each point's distance comes from the triangle of the piece
whose box centre is nearest (a scipy k-d tree). A bounding-volume hierarchy over the piece boxes
(Morton order, LEAF pieces to a leaf, a binary tree above) is then opened, level by level and for
all points at once, at every node whose box is within U of the point: a triangle as near as U has
a piece whose box is, so the triangles left at the leaves include every nearest one. Each
(point, triangle) pair is solved exactly (Ericson, *Real-Time Collision Detection* §5.1.5,
"closest point on triangle", vectorised) and the nearest kept: the exact answer (up to rounding),
not an approximation.

Determinism: a point's answer depends on that point and the mesh alone, never on the other data
points or their order: the triangle with the smallest computed squared distance, ties going to
the smaller triangle index (every triangle tied at the minimum is among the candidates).

Vectors are held component-major here, (3, ...) arrays, so that every product is elementwise on
contiguous rows (numpy is slow at sums over a short last axis, and at broadcasts along it).
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

LEAF = 8
"""Pieces per leaf of the hierarchy."""
SPLIT = 2.0
"""Triangles with a radius (centre to farthest corner) above SPLIT × the median radius, and above
1/32 of the largest, are cut into cells about that size."""
DEGENERATE = 1e-12
"""A triangle whose doubled area is at most this share of its longest edge squared (zero area: a
repeated corner, collinear corners) is solved as its three edges."""
PAIRS = 4096
"""(point, triangle) pairs solved at once: small arrays stay in cache."""


def closest_points(vertices: np.ndarray, faces: np.ndarray, data: np.ndarray):
    """Closest points of data (N, 3) on the triangle mesh (vertices (V, 3); faces (T, 3) of any
    integer type), mesh and data in one frame and unit (mm).

    Returns (tri, dist, points, bary): tri (N,) int64 the nearest triangle (ties: the smaller
    index), dist (N,) float64 = |points − data|, points (N, 3) float64 the closest points on the
    mesh, bary (N, 3) float64 their weights of the corners faces[tri, 0], faces[tri, 1],
    faces[tri, 2] (rows sum to 1).
    """
    faces = np.asarray(faces).astype(np.int64).reshape(-1, 3)
    coords = np.ascontiguousarray(np.asarray(vertices, np.float64).T)           # (3, V)
    p = np.ascontiguousarray(np.asarray(data, np.float64).reshape(-1, 3).T)    # (3, N)
    if not len(faces):
        raise ValueError("closest_points: the mesh has no triangles")
    if not (np.isfinite(coords).all() and np.isfinite(p).all()):
        raise ValueError("closest_points: vertices and data must be finite")
    a, b, c = (np.take(coords, faces[:, i], axis=1) for i in range(3))        # (3, T) each
    triangles = _Triangles(a, b, c)
    lo, hi, owner = _pieces(a, b, c)
    bvh = _Hierarchy(lo, hi, owner)
    margin = 1e-9 * max(np.abs(coords).max(), np.abs(p).max(initial=0.0))    # rounding of boxes and distances
    n = p.shape[1]
    if not n:
        return np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3))
    first = cKDTree(((lo + hi) / 2).T, balanced_tree=False, compact_nodes=False).query(p.T)[1]
    reach = np.sqrt(_nearest(triangles, p, np.arange(n), owner[first])[1][1])   # to the nearest piece's triangle
    met, (tri, _, v, w) = _nearest(triangles, p, *bvh.within(p, (reach + margin) ** 2))   # every triangle as near
    assert len(met) == n                                   # that triangle at least, for every point
    u = 1 - v - w
    points = u * a[:, tri] + v * b[:, tri] + w * c[:, tri]   # a vertex's weights (1, 0, 0) give it exactly
    d = points - p
    return tri, np.sqrt(_dot(d, d)), np.ascontiguousarray(points.T), np.column_stack([u, v, w])


def _nearest(triangles, p, pt, tri):
    """Over (point, triangle) pairs grouped by point (pt ascending): the points met (their columns of
    p) and each one's nearest triangle (ties: the smaller index), squared distance and weights (v, w)."""
    e2, v, w = np.empty(len(pt)), np.empty(len(pt)), np.empty(len(pt))
    for s in range(0, len(pt), PAIRS):
        e2[s:s + PAIRS], v[s:s + PAIRS], w[s:s + PAIRS] = triangles.solve(np.take(p, pt[s:s + PAIRS], axis=1),
                                                                         tri[s:s + PAIRS])
    starts = np.flatnonzero(np.r_[True, pt[1:] != pt[:-1]]) if len(pt) else np.zeros(0, np.int64)
    if not len(starts):
        return starts, (starts, np.zeros(0), np.zeros(0), np.zeros(0))
    group = np.cumsum(np.r_[False, pt[1:] != pt[:-1]])     # each pair's group
    ties = np.where(e2 == np.minimum.reduceat(e2, starts)[group], tri, np.iinfo(np.int64).max)
    pick = np.flatnonzero(ties == np.minimum.reduceat(ties, starts)[group])
    pick = pick[np.r_[True, pt[pick[1:]] != pt[pick[:-1]]]]  # the first such pair of each point
    return pt[pick], (tri[pick], e2[pick], v[pick], w[pick])


class _Triangles:
    """Per-triangle constants of the closest-point test, one (T,) row per quantity, so that
    gathering them for the candidates gives contiguous arrays."""

    def __init__(self, a, b, c):
        ab, ac = b - a, c - a
        n = _cross(ab, ac)
        nn, aa, bb, cc, bc = _dot(n, n), _dot(ab, ab), _dot(ab, ac), _dot(ac, ac), _dot(c - b, c - b)
        self.degenerate = ~(np.sqrt(nn) > DEGENERATE * np.maximum(np.maximum(aa, cc), bc))
        scale = np.where(self.degenerate, 0.0, 1 / np.where(self.degenerate, 1.0, nn))
        gb, gc = _cross(ac, n) * scale, _cross(n, ab) * scale   # (p − a)·gb, (p − a)·gc: p's plane weights of b, c
        inverse = [np.where(x > 0, 1 / np.where(x > 0, x, 1.0), 0.0) for x in (aa, cc, bc)]   # zero length: 0
        self.rows = [*a, *ab, *ac, *gb, *gc, aa, bb, cc, *inverse]              # 21 rows (T,)

    def solve(self, p: np.ndarray, tri: np.ndarray):
        """Squared distance from p (3, m) to the nearest point of triangle tri (m,) and that point's
        weights (v, w) of corners b, c (Ericson's regions; a zero-area triangle: its three edges)."""
        ax, ay, az, abx, aby, abz, acx, acy, acz, gbx, gby, gbz, gcx, gcy, gcz, aa, bb, cc, iaa, icc, ibc = \
            (np.take(row, tri) for row in self.rows)
        px, py, pz = p[0] - ax, p[1] - ay, p[2] - az       # p − a
        d1, d2 = px * abx + py * aby + pz * abz, px * acx + py * acy + pz * acz
        v, w = px * gbx + py * gby + pz * gbz, px * gcx + py * gcy + pz * gcz   # p's plane weights of b, c
        d3, d4, d5, d6 = d1 - aa, d2 - bb, d1 - bb, d2 - cc  # Ericson's d3..d6 from d1, d2 and the edges
        t_ab, t_ac, t_bc = d1 * iaa, d2 * icc, (d4 - d3) * ibc
        regions = [((d1 <= 0) & (d2 <= 0), 0.0, 0.0),                     # vertex a
                   ((d3 >= 0) & (d4 <= d3), 1.0, 0.0),                    # vertex b
                   ((w <= 0) & (d1 >= 0) & (d3 <= 0), t_ab, 0.0),         # edge ab
                   ((d6 >= 0) & (d5 <= d6), 0.0, 1.0),                    # vertex c
                   ((v <= 0) & (d2 >= 0) & (d6 <= 0), 0.0, t_ac),         # edge ac
                   ((v + w >= 1) & (d4 >= d3) & (d5 >= d6), 1 - t_bc, t_bc)]   # edge bc; else the face
        for region, rv, rw in reversed(regions):          # the first region that holds wins
            v, w = np.where(region, rv, v), np.where(region, rw, w)
        flat = np.take(self.degenerate, tri)
        if flat.any():                                     # zero area: the nearest of its three edges
            v[flat], w[flat] = _edges(*(x[flat] for x in (px, py, pz, abx, aby, abz, acx, acy, acz, t_ab, t_ac, t_bc)))
        ex, ey, ez = px - v * abx - w * acx, py - v * aby - w * acy, pz - v * abz - w * acz
        return ex * ex + ey * ey + ez * ez, v, w


def _edges(px, py, pz, abx, aby, abz, acx, acy, acz, t_ab, t_ac, t_bc):
    """Weights (v, w) of corners b, c of the nearest point to p (p − a given) on the three edges
    ab, ac, bc; ties go to the first."""
    t_ab, t_ac, t_bc = (np.clip(t, 0.0, 1.0) for t in (t_ab, t_ac, t_bc))
    vw = np.array([[t_ab, 0 * t_ab], [0 * t_ac, t_ac], [1 - t_bc, t_bc]])      # (3 edges, 2, m)
    ex, ey, ez = (q - vw[:, 0] * e - vw[:, 1] * f for q, e, f in ((px, abx, acx), (py, aby, acy), (pz, abz, acz)))
    i = (ex * ex + ey * ey + ez * ez).argmin(0)
    m = np.arange(len(i))
    return vw[i, 0, m], vw[i, 1, m]


class _Hierarchy:
    """Tree of boxes over the pieces (boxes lo, hi (3, P); owner (P,) their triangles) in Morton
    order of the box centres: LEAF pieces to a leaf, leaves paired up to the root (empty slots,
    padding, have empty boxes: infinitely far). Each level holds, per parent, the boxes of its
    children: lo, hi (3, children, parents)."""

    def __init__(self, lo, hi, owner):
        order = np.argsort(_morton((lo + hi) / 2), kind="stable")
        leaves = 1 << int(np.ceil(np.log2(max(1, -(-len(owner) // LEAF)))))
        self.owner = np.full(leaves * LEAF, -1)
        self.owner[:len(owner)] = owner[order]
        slo, shi = np.full((3, leaves * LEAF), np.inf), np.full((3, leaves * LEAF), -np.inf)
        slo[:, :len(owner)], shi[:, :len(owner)] = lo[:, order], hi[:, order]
        level = tuple(x.reshape(3, leaves, LEAF).transpose(0, 2, 1).copy() for x in (slo, shi))   # (3, LEAF, leaves)
        self.levels = [level]
        while level[0].shape[2] > 1:                       # up to the root's children
            lo, hi = np.min(level[0], 1), np.max(level[1], 1)   # the parents' boxes, (3, parents)
            level = (np.stack([lo[:, 0::2], lo[:, 1::2]], 1), np.stack([hi[:, 0::2], hi[:, 1::2]], 1))
            self.levels.insert(0, level)

    def within(self, p, bound):
        """(point, triangle) pairs, grouped by point (ascending), of every piece whose box is within
        squared distance bound (N,) of its point p (3, N)."""
        pt, node = np.arange(p.shape[1]), np.zeros(p.shape[1], np.int64)
        for lo, hi in self.levels:                         # (3, children, parents)
            d2 = None
            for i in range(3):                             # in place: few temporaries
                q = np.take(p[i], pt)
                below, above = np.take(lo[i], node, axis=1), np.take(hi[i], node, axis=1)   # (children, F)
                np.subtract(below, q, out=below)
                np.subtract(q, above, out=above)
                np.maximum(below, above, out=below)
                np.maximum(below, 0.0, out=below)
                np.multiply(below, below, out=below)
                d2 = below if d2 is None else np.add(d2, below, out=d2)
            row, child = np.nonzero((d2 <= np.take(bound, pt)).T)   # grouped by point
            pt, node = np.take(pt, row), np.take(node, row) * lo.shape[1] + child
        return pt, np.take(self.owner, node)


def _morton(x):
    """Morton (Z-order) codes of points x (3, P), 10 bits an axis over their bounding box."""
    lo, span = x.min(1, keepdims=True), np.ptp(x, axis=1, keepdims=True)
    q = ((x - lo) / np.where(span > 0, span, 1.0) * 1023).astype(np.int64)
    for shift, mask in ((16, 0x030000FF), (8, 0x0300F00F), (4, 0x030C30C3), (2, 0x09249249)):
        q = (q | (q << shift)) & mask                      # spread each axis' bits two apart
    return (q[0] << 2) | (q[1] << 1) | q[2]


def _pieces(a, b, c):
    """Boxes lo, hi (3, P) of the mesh's pieces and the triangle each belongs to (P,). A piece is
    a triangle, or a cell of an outsize one: seen from its corner A opposite its shortest edge BC,
    a triangle is A + s·((1 − t)(B − A) + t(C − A)), s, t in [0, 1], and a grid over (s, t) cuts it
    into trapezoids about `limit` across (a sliver such as the base cap's fan gives a row of cells)."""
    centre = (a + b + c) / 3
    r = np.sqrt(np.max([_dot(x - centre, x - centre) for x in (a, b, c)], 0))
    limit = max(SPLIT * np.median(r), r.max() / 32)
    big, small = np.flatnonzero(r > limit), np.flatnonzero(~(r > limit))
    lo, hi = np.minimum(np.minimum(a, b), c)[:, small], np.maximum(np.maximum(a, b), c)[:, small]
    if not big.size:
        return lo, hi, small
    corners = np.stack([a[:, big], b[:, big], c[:, big]])                  # (3 corners, 3, B)
    opposite = np.stack([_dot(x - y, x - y) for x, y in ((corners[1], corners[2]), (corners[2], corners[0]),
                                                          (corners[0], corners[1]))])
    apex, at = opposite.argmin(0), np.arange(len(big))
    A, B, C = (corners[(apex + i) % 3, :, at].T for i in range(3))        # A opposite the shortest edge BC
    m = np.ceil(np.sqrt(np.maximum(_dot(B - A, B - A), _dot(C - A, C - A))) / limit).astype(np.int64)
    n = np.ceil(np.sqrt(_dot(C - B, C - B)) / limit).astype(np.int64)
    m, n = np.maximum(m, 1), np.maximum(n, 1)
    count = m * n
    of = np.repeat(at, count)                              # each cell's triangle, among the big ones
    i, j = np.divmod(np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count), n[of])
    A, AB, AC = A[:, of], (B - A)[:, of], (C - A)[:, of]
    cell = [A + s * ((1 - t) * AB + t * AC) for s in (i / m[of], (i + 1) / m[of]) for t in (j / n[of], (j + 1) / n[of])]
    return (np.concatenate([lo, np.min(cell, 0)], 1), np.concatenate([hi, np.max(cell, 0)], 1),
            np.concatenate([small, big[of]]))


def _dot(x, y):
    return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]


def _cross(x, y):
    return np.stack([x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]])
