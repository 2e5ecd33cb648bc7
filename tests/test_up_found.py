"""A scan file's up axis found from her body when it is not given: the axis along which her head stands above her
chest, whichever of the file's six signed axes it lies on and however she is turned about it; with her head out of
view, the file's +y taken and said."""
import numpy as np
import pytest

from breastplan import transform_points
from breastplan.ingest.files import scan_cloud
from breastplan.ingest.pipeline import upright_frame
from breastplan.options import UP_AXES
from breastplan.point_order import canonical_order
from breastplan.scenes.makehuman import BodyOptions, make_body
from breastplan.scenes.realistic import file_from_body, turned

TURN_DEG = -30.0
"""Her turn about her vertical axis in the files (her right side forward)."""


@pytest.fixture(scope="module")
def surface():
    """Her closed body's surface sampled as a scan file's mesh is (body frame, mm: Y up, Z her front), and the same
    cut 150 mm above her nipples (no neck, no head)."""
    body = make_body(BodyOptions(cup=0.7, weight=0.6, pose="arms-down"))
    points = np.asarray(scan_cloud(body.vertices, body.faces, units="mm").points)
    cut = points[points[:, 1] < body.nipples["left"][1] + 150.0]
    return points, cut


def _found(points: np.ndarray, up: str):
    """upright_frame of `points` (body frame) written with the body's up on the file's `up`, turned TURN_DEG."""
    to_file = file_from_body(up, "mm") @ turned(TURN_DEG)
    inside = transform_points(to_file, points)
    return upright_frame(inside[canonical_order(inside)]), to_file


@pytest.mark.parametrize("up", UP_AXES)
def test_her_up_axis_and_facing_are_found_on_any_of_the_files_axes(surface, up):
    (frame, _, found, how), to_file = _found(surface[0], up)
    assert (found, how) == (up, "her head")
    her_up, her_front = to_file[:3, :3] @ [0.0, 1.0, 0.0], to_file[:3, :3] @ [0.0, 0.0, 1.0]
    assert np.allclose(her_up, (1.0 if up[0] == "+" else -1.0) * np.eye(3)["xyz".index(up[1])])   # as written
    assert frame[1, :3] @ her_up < -0.99                                      # viewing y runs down her body
    assert np.degrees(np.arccos(-frame[2, :3] @ her_front)) < 10.0            # the viewer stands in front of her


def test_with_her_head_out_of_view_the_files_y_is_taken_and_said(surface):
    (frame, _, found, how), to_file = _found(surface[1], "+y")
    assert (found, how) == ("+y", "taken")
    assert frame[1, :3] @ (to_file[:3, :3] @ [0.0, 1.0, 0.0]) < -0.99
