"""Exact closest points on a mesh (breastplan.fitting.closest), against a brute-force reference that
solves every point against every triangle by another method: projection onto the plane (a 2×2
least-squares system for the weights) when it falls inside, else the nearest of the three clamped
edges. Units mm."""
import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from breastplan import Primitive, to_mm
from breastplan.fitting.closest import closest_points


def brute_force(vertices, faces, data, chunk=32):
    """(N, T) distances of every point to every triangle, and each point's nearest point on the
    mesh (the first triangle at the minimum)."""
    T = vertices[np.asarray(faces, np.int64)]
    a, ab, ac = T[:, 0], T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]
    gram = np.stack([np.stack([(ab * ab).sum(1), (ab * ac).sum(1)], -1),
                     np.stack([(ab * ac).sum(1), (ac * ac).sum(1)], -1)], -2)            # (T, 2, 2)
    flat = np.linalg.norm(np.cross(ab, ac), axis=1) == 0                                 # zero area
    gram[flat] = np.eye(2)
    edges = [(T[:, 0], T[:, 1]), (T[:, 0], T[:, 2]), (T[:, 1], T[:, 2])]
    dist, nearest = [], []
    for s in range(0, len(data), chunk):
        p = data[s:s + chunk, None, :]                                                   # (m, 1, 3)
        rhs = np.stack([((p - a) * ab).sum(-1), ((p - a) * ac).sum(-1)], -1)[..., None]
        vw = np.linalg.solve(np.broadcast_to(gram, rhs.shape[:2] + (2, 2)), rhs)[..., 0]
        inside = ~flat & (vw[..., 0] >= 0) & (vw[..., 1] >= 0) & (vw.sum(-1) <= 1)
        on = [np.where(inside[..., None], a + vw[..., :1] * ab + vw[..., 1:] * ac, np.inf)]
        for e0, e1 in edges:
            e = e1 - e0
            t = np.clip(((p - e0) * e).sum(-1) / np.maximum((e * e).sum(-1), 1e-300), 0, 1)
            on.append(e0 + t[..., None] * e)
        on = np.stack(on)                                                                # (4, m, T, 3)
        d = np.linalg.norm(on - p, axis=-1)
        d[np.isnan(d)] = np.inf
        which = d.argmin(0)
        d = d.min(0)
        best = d.argmin(1)
        dist.append(d)
        nearest.append(np.take_along_axis(on, which[None, ..., None], 0)[0][np.arange(len(best)), best])
    return np.concatenate(dist), np.concatenate(nearest)


def hull_mesh():
    """A closed mesh of uneven triangles: the convex hull of a noisy ellipsoid, mm."""
    rng = np.random.default_rng(7)
    u = rng.normal(size=(400, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = u * [60.0, 75.0, 45.0] * rng.uniform(0.97, 1.03, (400, 1))
    return v, ConvexHull(v).simplices


def model_mesh():
    """A closed model mesh as the fit uses (its base cap a fan of long slivers), mm."""
    v, f = Primitive(10, 10, 10, 10, 10, 1.0, 1.0).mesh(20, 48, closed=True)
    return to_mm(v), f


def probes(vertices, faces, rng):
    """Points inside and outside, on and near vertices and edges, and far away."""
    T = vertices[faces]
    centre = vertices.mean(0)
    picks = rng.integers(0, len(faces), 120)
    on_faces = np.einsum("nk,nkc->nc", rng.dirichlet([1, 1, 1], 120), T[picks])
    mids = (T[picks, 0] + T[picks, 1]) / 2
    return np.vstack([
        centre + (on_faces - centre) * rng.uniform(0.3, 0.99, (120, 1)),      # inside
        centre + (on_faces - centre) * rng.uniform(1.01, 1.5, (120, 1)),      # outside
        vertices[rng.integers(0, len(vertices), 40)],                          # on vertices
        vertices[rng.integers(0, len(vertices), 60)] + rng.normal(0, 0.3, (60, 3)),   # near them
        mids[:40], mids[40:100] + rng.normal(0, 0.3, (60, 3)),                 # on and near edges
        on_faces[:40],                                                         # on faces
        centre + rng.normal(0, 1, (20, 3)) * 2000,                             # far away
    ])


def check(vertices, faces, data):
    tri, dist, points, bary = closest_points(vertices, faces, data)
    ref, truth = brute_force(vertices, faces, data)
    scale = np.abs(vertices).max()
    assert tri.dtype == np.int64 and dist.dtype == points.dtype == bary.dtype == np.float64
    assert np.isfinite(dist).all() and np.isfinite(points).all() and np.isfinite(bary).all()
    best = ref.min(1)
    assert dist == pytest.approx(best, rel=1e-9, abs=1e-9 * scale)              # the minimum distance
    assert ref[np.arange(len(data)), tri] == pytest.approx(best, rel=1e-9, abs=1e-9 * scale)   # on its triangle
    assert np.abs(points - truth).max() < 1e-7 * scale                          # the same closest point
    assert np.allclose(dist, np.linalg.norm(points - data, axis=1), rtol=0, atol=1e-12 * scale)
    assert np.allclose(bary.sum(1), 1.0, rtol=0, atol=1e-12) and bary.min() > -1e-12
    corners = vertices[np.asarray(faces, np.int64)[tri]]
    assert np.abs(np.einsum("nk,nkc->nc", bary, corners) - points).max() < 1e-9 * scale   # bary gives the point
    return tri, dist, points, bary


@pytest.mark.parametrize("mesh", [hull_mesh, model_mesh])
def test_closest_points_are_the_brute_force_minimum(mesh):
    vertices, faces = mesh()
    check(vertices, faces, probes(vertices, faces, np.random.default_rng(1)))


def test_degenerate_triangles_give_their_nearest_edge_point_and_no_nan():
    vertices, faces = hull_mesh()
    n = len(vertices)
    extra = np.array([[0.0, 0.0, 80.0], [4.0, 0.0, 80.0], [8.0, 0.0, 80.0],   # collinear, exactly
                      [1.0, 2.0, 90.0],                                     # one point, thrice
                      [0.0, 10.0, 85.0], [3.0, 12.0, 85.0]])               # a repeated corner
    vertices = np.vstack([vertices, extra, vertices[:1]])                  # and a copy of vertex 0
    faces = np.vstack([faces, [[n, n + 2, n + 1], [n + 1, n, n + 2], [n + 3, n + 3, n + 3],
                               [n + 4, n + 4, n + 5], [0, n + 6, faces[0, 1]]]])
    rng = np.random.default_rng(3)
    near = np.vstack([extra + rng.normal(0, 1.5, (6, 3)) for _ in range(20)])
    check(vertices, faces, np.vstack([near, probes(vertices, faces, rng)[::3]]))
    needle = np.array([[0, 1, 2], [1, 2, 0]])                               # a mesh of slivers alone
    check(extra[:3], needle, near)


def test_the_answer_does_not_depend_on_the_order_of_the_points_or_the_index_type():
    vertices, faces = model_mesh()
    data = probes(vertices, faces, np.random.default_rng(5))
    first = closest_points(vertices, faces, data)
    perm = np.random.default_rng(6).permutation(len(data))
    for kind in (np.int64, np.int32, np.uint32):
        again = closest_points(vertices, faces.astype(kind), data[perm])
        for x, y in zip(first, again, strict=True):
            assert np.array_equal(x[perm], y)                                   # bit for bit
    for rows in (slice(0, 1), slice(7, 300)):                                  # alone or among others
        part = closest_points(vertices, faces, data[rows])
        assert all(np.array_equal(x[rows], y) for x, y in zip(first, part, strict=True))


def test_a_tie_goes_to_the_smaller_triangle_index():
    vertices = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    point = np.array([[2.0, -1.0, 0.5]])                   # nearest to vertex 1, a corner of both triangles
    for faces in ([[0, 1, 2], [1, 3, 2]], [[1, 3, 2], [0, 1, 2]]):
        tri, dist, points, _ = closest_points(vertices, np.array(faces), point)
        assert tri[0] == 0 and np.array_equal(points[0], vertices[1]) and dist[0] == np.sqrt(2.25)


def test_no_points_give_empty_answers():
    vertices, faces = hull_mesh()
    tri, dist, points, bary = closest_points(vertices, faces, np.zeros((0, 3)))
    assert tri.shape == dist.shape == (0,) and points.shape == bary.shape == (0, 3)


def test_importing_the_fit_does_not_import_open3d():
    code = "import sys, breastplan.fitting.ffd; print('open3d' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
