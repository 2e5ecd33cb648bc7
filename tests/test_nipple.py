"""The nipple finder on surfaces with a known raised disc (the nipple-areola complex) or none."""
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from breastplan.ingest.breast import BreastFrame
from breastplan.ingest.nipple import find_disc, find_apex, find_nipple

IDENTITY = BreastFrame(np.zeros(3), np.eye(3))


def dome(spacing: float, rng: np.random.Generator, noise: float, curvature: float = 80.0) -> np.ndarray:
    """A breast-like dome z = 60 − r²/curvature (mm) sampled on a jittered grid, with depth noise."""
    g = np.arange(-45.0, 45.0 + 1e-9, spacing)
    xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2) + rng.uniform(-0.3, 0.3, (g.size ** 2, 2)) * spacing
    z = 60.0 - np.sum(xy ** 2, axis=1) / curvature + rng.normal(0.0, noise, len(xy))
    return np.column_stack([xy, z])


def with_disc(points: np.ndarray, centre, height: float, radius: float) -> np.ndarray:
    """The surface with a disc raised `height` mm of `radius` mm (soft edge) at (x, y) `centre`."""
    r = np.linalg.norm(points[:, :2] - centre, axis=1)
    out = points.copy()
    out[:, 2] += height / (1.0 + np.exp((r - radius) / 0.8))
    return out


@settings(max_examples=60, deadline=None)
@given(offset=st.tuples(st.floats(-6, 6), st.floats(-6, 6)), height=st.floats(2.0, 5.0),
       radius=st.floats(4.0, 8.0), spacing=st.sampled_from([0.7, 1.1, 1.7]), seed=st.integers(0, 2 ** 16))
def test_the_nipple_is_the_centre_of_the_raised_disc(offset, height, radius, spacing, seed):
    rng = np.random.default_rng(seed)
    points = with_disc(dome(spacing, rng, noise=0.3), np.array(offset), height, radius)
    nipple, found = find_nipple(points, IDENTITY)
    assert found == "areola"
    # within 1 mm of the disc's centre, on the skin over it (the disc's soft edge leaves its
    # centre within 0.01 height of the full rise): a third of the 3 mm target, over 3 σ of the
    # centroid of points sampled up to 1.7 mm apart with 0.3 mm noise
    assert np.linalg.norm(nipple[:2] - offset) < 1.0
    top = 60.0 - np.sum(np.square(offset)) / 80.0 + height
    assert abs(nipple[2] - top) < 1.0


@settings(max_examples=40, deadline=None)
@given(spacing=st.sampled_from([0.7, 1.1, 1.7]), curvature=st.floats(40.0, 160.0), seed=st.integers(0, 2 ** 16))
def test_without_a_raised_disc_the_nipple_is_the_apex(spacing, curvature, seed):
    rng = np.random.default_rng(seed)
    points = dome(spacing, rng, noise=0.3, curvature=curvature)
    apex = find_apex(points)
    assert find_disc(points, apex[:2]) is None
    nipple, found = find_nipple(points, IDENTITY)
    assert found == "apex" and np.allclose(nipple, apex)
    assert abs(apex[2] - 60.0) < 1.0


def test_a_disc_too_wide_for_a_nipple_is_not_taken():
    rng = np.random.default_rng(0)
    points = with_disc(dome(1.0, rng, noise=0.3), np.array([3.0, 0.0]), 4.0, 18.0)
    assert find_disc(points, find_apex(points)[:2]) is None


def test_too_few_points_keep_the_apex():
    rng = np.random.default_rng(1)
    points = with_disc(dome(8.0, rng, noise=0.0), np.zeros(2), 3.0, 6.0)
    assert find_disc(points, np.zeros(2)) is None
