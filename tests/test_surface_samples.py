"""A mesh read as points (`ingest.surface_samples`): each triangle takes its share by area, the points lie on
it, evenly, and no random draw chooses them."""
import numpy as np

from breastplan.ingest.surface_samples import surface_samples
from breastplan.scenes.makehuman import BodyOptions, make_body


def test_each_triangle_of_a_body_takes_its_share_of_the_points_by_area_and_they_lie_on_it():
    body = make_body(BodyOptions(cup=0.6, pose="a-pose"))
    v, f = body.vertices, body.faces
    n = 200_000
    points, normals, corners, weights = surface_samples(v, f, n)
    assert len(points) == n and (weights >= -1e-12).all() and np.allclose(weights.sum(1), 1.0)
    assert np.allclose(np.einsum("nk,nkc->nc", weights, v[corners]), points)
    area = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    ids = np.unique(np.vstack([np.sort(f, 1), np.sort(corners, 1)]), axis=0, return_inverse=True)[1].ravel()
    counts = np.bincount(ids[len(f):], minlength=ids.max() + 1)[ids[:len(f)]]   # each triangle's points
    assert np.abs(counts - area / area.sum() * n).max() < 1.0 + 1e-9      # the running sum's rounding
    tri_normals = np.cross(v[corners[:, 1]] - v[corners[:, 0]], v[corners[:, 2]] - v[corners[:, 0]])
    assert (np.einsum("nc,nc->n", tri_normals, normals) > 0).all()          # each triangle's own side


def test_the_points_cover_a_square_evenly():
    """A 40 × 40 mm square of two triangles, 16,000 points: each 2 × 2 mm cell holds its 40 within a few (a random
    draw leaves some cells a quarter short or over)."""
    v = np.array([[0.0, 0.0, 0.0], [40.0, 0.0, 0.0], [40.0, 40.0, 0.0], [0.0, 40.0, 0.0]])
    points = surface_samples(v, np.array([[0, 1, 2], [0, 2, 3]]), 16_000)[0]
    cells = np.histogram2d(points[:, 0], points[:, 1], bins=20, range=[[0, 40], [0, 40]])[0]
    assert np.abs(cells - 40).max() <= 6
