"""The built-in filters (filters/stages.py) held to truths they do not compute themselves, in process (no
command line), each test a few seconds on fits shared through the filters' own memory.

The body is MakeHuman's (average build, A-pose, a wall 400 mm behind her), written as
`scan-synth --scan-file` writes it twice: in mm with her up on +y (the body frame) and in metres with
her up on +x (`scenes.realistic.file_from_body`, a rotation the test inverts exactly). Truths:

* her nipples: MakeHuman's nipple rings, in her body frame;
* a frame's invariance: the same body in another frame and units gives the same breast in her body
  frame (nipple within 1 mm, width and volume alike);
* the width's definition (docs/filters.md): the base outline's extent from side to side, along the
  breast frame's left axis — her up axis (known from the file's making) made perpendicular to the base
  plane, oriented to her left — computed here from the fitted mesh's outline alone;
* tests/reference_model.py: ptosis and turn shear y and x by functions of z alone, which neither
  changes, so together they displace every point by the sum of what each does alone;
* a remembered surface's parameters: what the same chain gives from the scan with those parameters,
  computed afresh with the memory emptied (`forget`).
"""
import warnings

import numpy as np
import pytest

import reference_model as ref
from breastplan import BadInputError, read_ply, transform_points
from breastplan.filters import (Mesh, ShortOfDegree, apply_breast_ptosis, apply_breast_top_shape,
                                apply_breast_turn, compute_breast_fit, compute_breast_isolation, forget,
                                get_breast_measures)
from breastplan.scenes.makehuman import BodyOptions
from breastplan.scenes.realistic import CameraOptions, file_from_body, make_body_scene, write_scan_file

NIPPLE_MM = 2.0
"""How far the nipple found may lie from MakeHuman's nipple ring's centroid (it lies within 1 mm)."""
SAME_MM = 1.0
"""How far the same body's breast may move between two frames of its scan (voxels fall differently)."""
WIDTH_MM = 2.5
"""How far `width_mm` may lie from the outline's extent computed here (the breast frame's normal is the
chest wall's at the breast, this test's the outline's plane's: they differ by a few degrees, 2.0 mm of the
default body's 138 mm; along her body's left axis instead, the same outline spans 119 mm)."""
MODEL_REL, MODEL_MM = 0.05, 3.0
"""How far the fitted model's width and volume, and its surface's centre, may move between two frames of one
scan: its fit is not continuous in her points (points moved by 1e-5 mm move the width by up to 8 mm, 4 %,
and the surface's centre by 2.3 mm); the nipple, found on her points, stays within SAME_MM."""
FRAMES = {"mm +y": ("mm", "+y"), "m +x": ("m", "+x")}


@pytest.fixture(scope="module")
def body(tmp_path_factory):
    """(the scans by frame name, as Mesh; her body). Everything the filters remembered is forgotten
    first and last, so that nothing here leans on another test module's surfaces."""
    forget()
    scene = make_body_scene(BodyOptions(), CameraOptions())
    folder = tmp_path_factory.mktemp("frames")
    scans = {}
    for name, (units, up) in FRAMES.items():
        path = folder / f"body-{units}-{up[1]}.ply"
        write_scan_file(path, scene, units=units, up=up)
        scans[name] = Mesh(read_ply(path).points)
    yield scans, scene.body
    forget()


def to_body(points_mm, up: str) -> np.ndarray:
    """A filter's output (file frame, mm) in her body frame (mm)."""
    return transform_points(np.linalg.inv(file_from_body(up, "mm")), np.atleast_2d(points_mm))


def fitted(body, name: str = "mm +y", side: str = "left") -> Mesh:
    """The fitted surface of a scan (computed once; again only after a test forgot it)."""
    units, up = FRAMES[name]
    return compute_breast_fit(body[0][name], side=side, units=units, up=up)


def outline(fit: Mesh) -> np.ndarray:
    """The base outline of a fitted surface, from the mesh alone: the model's mesh closes its base with a
    fan of triangles round its last vertex, the outline is the ring of vertices that fan touches."""
    centre = len(fit.vertices) - 1
    ring = np.unique(fit.faces[(fit.faces == centre).any(axis=1)])
    return fit.vertices[ring[ring != centre]]


def true_width(fit: Mesh, up: str) -> float:
    """The base outline's extent along the breast frame's left axis: her up (in the file's frame)
    crossed with the outline plane's normal (out of the chest), oriented towards her left."""
    ring = outline(fit)
    R = file_from_body(up, "mm")[:3, :3]
    her_up, her_left = R @ [0.0, 1.0, 0.0], R @ [1.0, 0.0, 0.0]
    normal = np.linalg.svd(ring - ring.mean(axis=0))[2][-1]
    left = np.cross(her_up, normal)
    left *= np.sign(left @ her_left) / np.linalg.norm(left)
    return float(np.ptp(ring @ left))


def quietly(function, *args, **kwargs):
    """A change whose surface does not round to its degree warns (ShortOfDegree): not what is tested here."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ShortOfDegree)
        return function(*args, **kwargs)


# --- frames and units ------------------------------------------------------------------------------

def test_the_same_body_in_another_frame_and_units_gives_the_same_breast_and_its_true_width(body):
    """Truth: her nipple (MakeHuman's ring), frame invariance, and the width's definition. A filter that
    ignored `up` or `units`, or measured the width along another axis or in the input's own frame, fails."""
    scans, her = body
    found = {}
    for name, (units, up) in FRAMES.items():
        fit = fitted(body, name)
        measures = get_breast_measures(fit, units=units, up=up)
        nipple = to_body(measures["nipple_mm"], up)[0]
        assert np.linalg.norm(nipple - her.nipples["left"]) <= NIPPLE_MM, name
        assert abs(measures["width_mm"] - true_width(fit, up)) <= WIDTH_MM, (name, measures["width_mm"])
        found[name] = (nipple, measures, to_body(fit.vertices, up))
    (n1, m1, v1), (n2, m2, v2) = found.values()
    assert np.linalg.norm(n1 - n2) <= SAME_MM
    # the fitted model's width and volume: its fit moves by millimetres when her points move by 1e-5 mm
    assert m2["width_mm"] == pytest.approx(m1["width_mm"], rel=MODEL_REL)
    assert m2["volume_cc"] == pytest.approx(m1["volume_cc"], rel=MODEL_REL)
    assert np.linalg.norm(v1.mean(axis=0) - v2.mean(axis=0)) <= MODEL_MM     # the same surface, in her frame


def test_a_woman_wider_from_left_to_right_has_a_wider_breast_base_not_a_taller_one(body):
    """Truth: the width is measured left to right. Her scan stretched by 30 % along her left axis (a wider woman,
    the same height) is fitted with a base wider than it is tall by 30 mm: a filter that measured the width from top
    to bottom fails. (Her own breasts' bases are about as wide as they are tall.)"""
    scans, _ = body
    units, up = FRAMES["mm +y"]
    wide = to_body(scans["mm +y"].vertices, up) * [1.3, 1.0, 1.0]
    fit = compute_breast_fit(Mesh(transform_points(file_from_body(up, units), wide)), side="left", units=units, up=up)
    measures = get_breast_measures(fit, units=units, up=up)
    ring = to_body(outline(fit), up)
    assert measures["width_mm"] > np.ptp(ring[:, 1]) + 30.0, (measures["width_mm"], np.ptp(ring[:, 1]))


def test_a_scan_in_metres_said_to_be_in_mm_is_refused_as_ingest_refuses_it(body):
    scans, _ = body
    with pytest.raises(BadInputError, match="declared mm but its extent of 1.88 says metres"):
        compute_breast_isolation(scans["m +x"], units="mm", up="+x")
    with pytest.raises(BadInputError, match="declared m but"):
        compute_breast_isolation(scans["mm +y"], units="m")


# --- sides -----------------------------------------------------------------------------------------

def test_each_side_of_one_scan_is_that_breast_and_a_surface_keeps_its_side(body):
    _, her = body
    fits = {side: fitted(body, side=side) for side in ("left", "right")}
    for side, fit in fits.items():
        nipple = get_breast_measures(fit)["nipple_mm"]
        assert np.linalg.norm(nipple - her.nipples[side]) <= NIPPLE_MM, side
        assert np.sign(fit.vertices[:, 0].mean()) == (1 if side == "left" else -1)    # X: her left
    with pytest.raises(BadInputError, match="is a surface of the right breast, not the left one; give side=right"):
        apply_breast_ptosis(fits["right"], side="left")
    assert get_breast_measures(fits["right"], side="right")["side"] == "right"


# --- chains ----------------------------------------------------------------------------------------

def test_ptosis_and_turn_shear_along_z_alone_so_chained_they_displace_by_the_sum(body):
    """Closed form (tests/reference_model.py): ptosis moves y, turn moves x, each by a function of z,
    which neither changes; together they move every point by the sum of their moves alone, in either
    order of the calls. A chain that lost its first change, or applied it twice, fails."""
    p = np.random.default_rng(0).uniform(-12.0, 12.0, (50, 3))
    both = ref.ptosis(ref.turn(p, 0.4, 0.1), 0.7, 0.2)
    assert np.allclose(both - p, (ref.ptosis(p, 0.7, 0.2) - p) + (ref.turn(p, 0.4, 0.1) - p), atol=1e-12)

    fit = fitted(body)
    ptosis, turn = apply_breast_ptosis(fit, degree=4), apply_breast_turn(fit, degree=3)
    chained = apply_breast_turn(ptosis, degree=3)
    other_way = apply_breast_ptosis(turn, degree=4)
    moved_p, moved_t = ptosis.vertices - fit.vertices, turn.vertices - fit.vertices
    assert np.linalg.norm(moved_p, axis=1).max() > 2.0 and np.linalg.norm(moved_t, axis=1).max() > 2.0
    assert np.abs(chained.vertices - fit.vertices - (moved_p + moved_t)).max() < 1e-6
    assert np.abs(other_way.vertices - chained.vertices).max() < 1e-6
    changes = get_breast_measures(chained)["changes"]
    assert [(c["kind"], c["degree"], round(c["degree_reached"], 6)) for c in changes] == [
        ("ptosis", 4.0, 4.0), ("turn", 3.0, 3.0)]                 # both within reach on this breast
    # a change of a kind the surface has replaces it: a degree is measured on the fitted breast
    again = apply_breast_ptosis(chained, degree=2)
    directly = apply_breast_turn(apply_breast_ptosis(fit, degree=2), degree=3)
    assert np.abs(again.vertices - directly.vertices).max() < 1e-6
    assert [(c["kind"], round(c["degree_reached"], 6)) for c in get_breast_measures(again)["changes"]] == [
        ("ptosis", 2.0), ("turn", 3.0)]


def test_a_chain_is_applied_in_the_models_order_whatever_the_order_of_the_calls(body):
    fit = fitted(body)
    a = quietly(apply_breast_ptosis, quietly(apply_breast_top_shape, fit, degree=3), degree=5)
    b = quietly(apply_breast_top_shape, quietly(apply_breast_ptosis, fit, degree=5), degree=3)
    assert np.abs(a.vertices - b.vertices).max() < 1e-6
    assert np.abs(a.vertices - quietly(apply_breast_ptosis, fit, degree=5).vertices).max() > 1.0


# --- the memory: a remembered surface takes the parameters it is given ---------------------------------

def test_a_remembered_surface_fitted_again_with_another_lattice_is_that_fit_not_the_remembered_one(body):
    """Truth: the same chain from the scan with that lattice, computed afresh with the memory emptied."""
    scans, _ = body
    five = fitted(body)
    deformed = quietly(apply_breast_ptosis, five, degree=5)
    three = compute_breast_fit(deformed, lattice=3)
    three_of_fit = compute_breast_fit(five, lattice=3)
    assert np.linalg.norm(three.vertices - five.vertices, axis=1).max() > 5.0     # not the remembered fit
    measures = get_breast_measures(quietly(apply_breast_turn, three, degree=2))
    forget()
    fresh = compute_breast_fit(scans["mm +y"], side="left", lattice=3)
    assert np.array_equal(three.vertices, fresh.vertices) and np.array_equal(three_of_fit.vertices, fresh.vertices)
    assert np.array_equal(three.faces, fresh.faces)
    fresh_measures = get_breast_measures(quietly(apply_breast_turn, fresh, degree=2))
    assert measures["width_mm"] == fresh_measures["width_mm"]
    assert measures["volume_cc"] == fresh_measures["volume_cc"]
    assert np.array_equal(measures["nipple_mm"], fresh_measures["nipple_mm"])


def test_a_remembered_surface_given_its_scans_up_is_read_with_it_not_with_the_one_it_was_made_with(body):
    """A chain begun with the wrong `up` (the file's up is +x) and continued with the right one: the result
    is that of the right one, computed afresh from the scan, and its width is true again."""
    scans, _ = body
    wrong = compute_breast_isolation(scans["m +x"], units="m", up="+y")
    measures = get_breast_measures(wrong, units="m", up="+x")
    fit = compute_breast_fit(wrong, units="m", up="+x")
    assert abs(measures["width_mm"] - true_width(fit, "+x")) <= WIDTH_MM
    forget()
    fresh = get_breast_measures(scans["m +x"], side="left", units="m", up="+x")
    assert measures["width_mm"] == fresh["width_mm"] and np.array_equal(measures["nipple_mm"], fresh["nipple_mm"])


def test_a_remembered_surface_isolated_again_takes_the_voxel_size_asked_for(body):
    scans, _ = body
    fit = fitted(body)
    coarse = compute_breast_isolation(fit, voxel_mm=4.0)
    fine = compute_breast_isolation(scans["mm +y"], side="left")
    assert len(coarse.vertices) < 0.5 * len(fine.vertices)                  # 4 mm voxels: about a quarter
    forget()
    assert np.array_equal(coarse.vertices, compute_breast_isolation(scans["mm +y"], side="left", voxel_mm=4.0).vertices)
