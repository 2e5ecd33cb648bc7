"""Her volume measured on her skin (plan.breast_volume), on MakeHuman bodies whose truth is known: the
exact half-body volumes, a bump of closed-form volume added to one breast, her mirror symmetry."""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest
from matplotlib.path import Path as Polygon
from scipy.spatial import cKDTree
from threadpoolctl import threadpool_limits

from breastplan import transform_points
from breastplan.scenes.makehuman import BodyOptions, make_body
from breastplan.ingest.pipeline import ingest_frames
from breastplan.scenes.realistic import BodyScene, CameraOptions, camera_pose
from breastplan.ingest.recording import DepthFrames
from breastplan.options import IngestOptions
from breastplan.plan.breast_volume import measure_breasts

BODIES = {"symmetric": BodyOptions(cup=0.7, firmness=0.4, weight=0.6, pose="hands-on-hips"),
          "asymmetric": BodyOptions(cup=0.85, firmness=0.2, modifiers={"asymmetry": 0.5}, pose="arms-down")}
SYMMETRIC, ASYMMETRIC = BODIES


@lru_cache(maxsize=None)
def scanned(body: str, distance=650.0, pitch=5.0, yaw=0.0, height=0.0, wall=400.0, seed=0):
    """(torso, nipples, view, plumb, half-body volumes) of one of BODIES ingested as `plan` ingests it (input
    frame); the camera `height` mm above the nipples' midpoint it looks at."""
    made = make_body(BODIES[body])
    camera = CameraOptions(distance, pitch, yaw, "800x600", wall_mm=wall)
    target = 0.5 * (made.nipples["left"] + made.nipples["right"]) + [0.0, height, 0.0]
    scene = BodyScene(made, camera, camera_pose(target, camera))
    frames = DepthFrames(scene.frames(8, seed), camera.K, "test")
    sides = {side: ingest_frames(frames, IngestOptions(side)) for side in ("left", "right")}
    first = sides["left"]
    return (first.torso_camera, {s: i.nipple_camera for s, i in sides.items()}, first.input_to_view,
            first.plumb_camera, made.half_volumes_cc())


def measured(body: str, **view):
    torso, nipples, view_from, plumb, _ = scanned(body, **view)
    return measure_breasts(torso, nipples, view_from, plumb)


@pytest.mark.parametrize("view", [dict(yaw=10.0, wall=None), dict(yaw=-8.0, pitch=8.0)])
def test_a_symmetric_womans_breasts_measure_alike(view):
    m = measured(SYMMETRIC, **view)
    left, right = m.sides["left"].volume_cc, m.sides["right"].volume_cc
    assert abs(left - right) <= 0.03 * 0.5 * (left + right)
    assert 150 < left < 1500


def test_one_breast_larger_measures_as_the_half_bodies_differ():
    """MakeHuman's asymmetry target changes one breast: the measured left − right volume is the exact
    half-body difference within 20 cc."""
    truth = scanned(ASYMMETRIC)[-1]
    m = measured(ASYMMETRIC)
    diff = m.sides["left"].volume_cc - m.sides["right"].volume_cc
    assert diff == pytest.approx(truth["left"] - truth["right"], abs=20.0)


def test_tissue_added_to_one_breast_is_measured_there_and_not_on_the_other():
    """A raised-cosine bump of closed-form volume, π r² h (1/2 − 2/π²), pushed onto the left breast's skin
    along her anterior axis, is measured on the left and not on the right."""
    torso, nipples, view_from, plumb, _ = scanned(SYMMETRIC)
    before = measure_breasts(torso, nipples, view_from, plumb)
    T = before.body_from_input
    body = transform_points(T, torso)
    centre = transform_points(T, nipples["left"][None])[0]
    r, h = 45.0, 10.0
    d = np.linalg.norm(body[:, :2] - centre[:2], axis=1)
    bump = np.where(d < r, 0.5 * h * (1.0 + np.cos(np.pi * d / r)), 0.0)
    body[:, 2] += bump
    after = measure_breasts(transform_points(np.linalg.inv(T), body), nipples, view_from, plumb)
    added_cc = np.pi * r * r * h * (0.5 - 2.0 / np.pi ** 2) / 1000.0      # ∫ 2π ρ ½h(1 + cos πρ/r) dρ
    gain = after.sides["left"].volume_cc - before.sides["left"].volume_cc
    assert gain == pytest.approx(added_cc, rel=0.15)
    assert after.sides["right"].volume_cc == pytest.approx(before.sides["right"].volume_cc, rel=0.02)


def test_the_same_woman_scanned_again_measures_the_same_within_its_stated_uncertainty():
    scans = [measured(SYMMETRIC, distance=d, pitch=p, yaw=y, height=z, wall=w, seed=k)
             for k, (d, p, y, z, w) in enumerate([(610.0, 3.0, -6.0, 20.0, 400.0), (700.0, 9.0, 5.0, -20.0, None),
                                                  (660.0, 6.0, 0.0, 0.0, 400.0)])]
    for side in ("left", "right"):
        volumes = np.array([s.sides[side].volume_cc for s in scans])
        assert np.ptp(volumes) <= 0.10 * np.median(volumes)      # the benchmark holds the tighter figures
        assert all(abs(s.sides[side].volume_cc - np.median(volumes)) <= s.sides[side].uncertainty_cc for s in scans)


def test_the_footprint_is_a_closed_curve_on_her_skin_round_her_nipple_and_mirrored():
    torso, nipples, *_ = scanned(SYMMETRIC)
    m = measured(SYMMETRIC)
    T = m.body_from_input
    skin = cKDTree(torso)
    outlines = {}
    for side, v in m.sides.items():
        curve = v.footprint_input_mm
        assert len(curve) > 20 and np.allclose(curve[0], curve[-1])
        assert np.median(skin.query(curve)[0]) < 3.0
        body = transform_points(T, curve)
        assert Polygon(body[:, :2]).contains_point(transform_points(T, nipples[side][None])[0, :2])
        outlines[side] = body[:, :2]
    mirrored = outlines["right"] * [-1.0, 1.0]
    assert np.median(cKDTree(outlines["left"]).query(mirrored)[0]) < 3.0


def test_the_measure_depends_on_her_surface_alone_not_the_points_order_nor_the_blas_threads():
    torso, nipples, view_from, plumb, _ = scanned(ASYMMETRIC)
    order = np.random.default_rng(3).permutation(len(torso))
    runs = []
    for points, threads in ((torso, 1), (torso[order], 1), (torso[::-1], 2)):
        with threadpool_limits(threads, "blas"):
            m = measure_breasts(np.ascontiguousarray(points), nipples, view_from, plumb)
        runs.append({s: (round(v.volume_cc, 1), round(v.uncertainty_cc, 1), v.footprint_input_mm.round(1).tobytes())
                     for s, v in m.sides.items()})
    assert runs[0] == runs[1] == runs[2]


def test_a_torso_that_shows_too_little_chest_around_the_breasts_is_refused_in_a_sentence():
    """Her breasts with hardly any chest around them: no wall can be inferred beneath them, and that is
    said (BadInputError), not guessed."""
    from breastplan import BadInputError

    torso, nipples, view_from, plumb, _ = scanned(SYMMETRIC)
    near = np.min([np.linalg.norm(torso - n, axis=1) for n in nipples.values()], axis=0) < 70.0
    centre = 0.5 * (nipples["left"] + nipples["right"])
    neck = (torso[:, 1] < centre[1] - 150.0) & (np.abs(torso[:, 0] - centre[0]) < 40.0)     # her midline's notch
    with pytest.raises(BadInputError, match="too little of her chest"):
        measure_breasts(torso[near | neck], nipples, view_from, plumb)
