"""What a plan says of how far the depth camera stood (plan.camera_distance): the distance to the nipples'
midpoint, and a sentence outside the distances her volume was measured well from, or between two visits
scanned from distances apart."""
import numpy as np
import pytest

from breastplan.plan.camera_distance import APART_MM, FARTHEST_MM, NEAREST_MM, camera_distance_mm, distance_notes


def test_the_distance_is_the_cameras_to_the_nipples_midpoint_and_none_without_a_camera():
    left, right = np.array([100.0, 0.0, 600.0]), np.array([-100.0, 30.0, 640.0])
    assert camera_distance_mm({"left": left, "right": right}) == pytest.approx(np.sqrt(15 ** 2 + 620 ** 2))
    assert camera_distance_mm({"left": left}) == pytest.approx(np.sqrt(100 ** 2 + 600 ** 2))
    assert camera_distance_mm({"left": left, "right": None}) is None
    assert camera_distance_mm({}) is None


@pytest.mark.parametrize("mm", [NEAREST_MM, 650.0, FARTHEST_MM])
def test_a_camera_where_her_volume_was_measured_well_is_not_remarked(mm):
    assert distance_notes(mm) == ()
    assert distance_notes(None) == ()


def test_a_camera_too_far_or_too_near_is_said_in_metres():
    (far,) = distance_notes(1000.0)
    assert far.startswith("The camera stood 1.00 m from her nipples") and "0.5–0.8 m" in far
    (near,) = distance_notes(400.0)
    assert near.startswith("The camera stood 0.40 m from her nipples, nearer than") and "0.5–0.8 m" in near


def test_two_visits_scanned_from_distances_apart_are_said_to_be():
    assert distance_notes(650.0, 650.0 + APART_MM) == ()
    assert distance_notes(650.0, None) == ()
    (apart,) = distance_notes(760.0, 640.0)
    assert apart.startswith("Her earlier visit was scanned from 0.64 m, this one from 0.76 m")
    (apart,) = distance_notes(640.0, 760.0)
    assert apart.startswith("Her earlier visit was scanned from 0.76 m, this one from 0.64 m")
    far, apart = distance_notes(1000.0, 650.0)
    assert far.startswith("The camera stood 1.00 m") and apart.startswith("Her earlier visit was scanned from 0.65 m")
