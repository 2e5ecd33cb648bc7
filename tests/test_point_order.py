"""A surface's triangles in one order whatever order a file lists them in: what makes sampling a scanner's mesh
the surface's alone."""
import numpy as np

from breastplan.point_order import canonical_faces
from breastplan.scenes.makehuman import BodyOptions, make_body


def _corners(vertices, faces):
    return np.asarray(vertices)[canonical_faces(vertices, faces)]


def test_the_same_surface_gives_the_same_triangles_in_the_same_order():
    """A MakeHuman body's mesh with a texture seam (vertices split into coinciding copies), then listed in another
    order: vertices permuted, triangles shuffled, each triangle's corners turned (its orientation kept)."""
    body = make_body(BodyOptions(cup=0.5, pose="arms-down"))
    v, f = body.vertices, body.faces.copy()
    seam = np.arange(0, len(f), 7)                                     # every 7th triangle's first corner split
    v = np.vstack([v, v[f[seam, 0]]])
    f[seam, 0] = len(body.vertices) + np.arange(len(seam))
    rng = np.random.default_rng(11)
    moved = rng.permutation(len(v))
    where = np.empty_like(moved)
    where[moved] = np.arange(len(moved))
    g = where[f][rng.permutation(len(f))]
    g = np.take_along_axis(g, (rng.integers(0, 3, len(g))[:, None] + np.arange(3)) % 3, 1)
    assert np.array_equal(_corners(v, f), _corners(v[moved], g))

    def normals(corners):                                            # each triangle's, in lexicographic order
        n = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        return n[np.lexsort(np.round(n, 6).T[::-1])]

    assert np.allclose(normals(_corners(v, f)), normals(v[f]))      # each triangle faces as it did
