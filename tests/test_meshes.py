"""A closed mesh's volume: a closed form, and libigl's as a second implementation."""
import igl
import numpy as np
import pytest

from breastplan.deform.breast_model import BreastModel
from breastplan.deform.global_deformations import Deformation
from breastplan.meshes import mesh_volume


def test_a_box_anywhere_holds_its_volume():
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float) * [2.0, 3.0, 5.0]
    faces = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                      [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    assert mesh_volume(corners + [100.0, -40.0, 7.0], faces) == pytest.approx(30.0, rel=1e-12)


def test_a_breasts_volume_is_libigls(db_s):
    for k in (0, 7, 19):
        V, F = BreastModel(db_s.primitive(k), Deformation.from_vector(db_s.deformation[k])).mesh(40, 96, closed=True)
        assert mesh_volume(V, F) == pytest.approx(igl.centroid(V.astype(float), F.astype(np.int64))[1], rel=1e-12)
