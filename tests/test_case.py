"""The case folder: typed round trips, all-or-nothing artefact sets, provenance, file modes; the
breast model in one place; options; errors named at the boundary."""
import dataclasses
import hashlib
import json
import os
import stat

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from breastplan import BadInputError, Primitive, read_ply, to_mm, write_ply
from breastplan.atomic import atomic_set
from breastplan.case import Case, Fit, Provenance, Scan, Source, sha256
from breastplan.chest_wall import ChestWall
from breastplan.deform.breast_model import BreastModel
from breastplan.deform.global_deformations import Deformation
from breastplan.meshes import mesh_volume
from breastplan.errors import ArtefactError, about
from breastplan.options import FitOptions, IngestOptions


def a_scan(n=60, provenance=Provenance()):
    rng = np.random.default_rng(0)
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix()
    T[:3, 3] = [10.0, -20.0, -600.0]
    normals = rng.normal(size=(n, 3))
    return Scan(points=rng.normal(size=(n, 3)) * 30, normals=normals / np.linalg.norm(normals, axis=1, keepdims=True),
                torso_camera=rng.normal(size=(5 * n, 3)) * 200, input_to_breast=T, input_to_view=np.eye(4),
                side="right", nipple_camera_mm=np.array([-100.0, 0.0, 650.0]),
                chest_wall=ChestWall.from_array(np.r_[2.0, 0.0, 0.0, 1.0, 700.0, np.arange(1.0, 6.0)]),  # 52 mm behind
                mound_centre_view_mm=np.array([-90.0, 5.0]), mound_radius_mm=80.0, crop_height_mm=2.0,
                roi_camera_mm=None, voxel_mm=2.0,
                source=Source("recording", "rec.mcap: 3 frames", 3, np.diag([450.0, 450.0, 1.0]), np.array([640, 400])),
                nipple_found="areola", timings_ms={"fuse": 1.5}, provenance=provenance)


def a_fit(model=BreastModel(Primitive(10, 11, 9, 10, 8, 0.9, 1.1), Deformation(ptosis=(1.0, 0.2))), **changes):
    V, F = model.mesh(20, 24)
    lattice = np.stack(np.meshgrid(*[np.linspace(-90, 90, 3)] * 3, indexing="ij"), -1).reshape(-1, 3)
    fields = dict(vertices=V, faces=F, primitive=model.primitive, pose=model.pose,
                  deformation=model.deformation.as_vector(), lattice_shape=np.array([3, 3, 3]),
                  lattice_box_mm=np.array([[-90.0] * 3, [90.0] * 3]), control_rest_mm=lattice,
                  control_fitted_mm=lattice + 1.0, residuals_mm={"mean": 0.1, "rms": 0.2, "p95": 0.3, "max": 0.9},
                  normalised_residual=0.001, volume_cc_primitive=model.primitive.volume_cc,
                  volume_cc_mesh=mesh_volume(V, F) / 1000.0, volume_cc_below_base=12.5, iterations=(40, 3),
                  seconds=(0.2, 0.05), points=3000,
                  residual_map_mm=np.linspace(0.0, 0.9, 3000),
                  converged=True, stopping_rule_met=True, provenance=Provenance({"scan.ply": "ab" * 32}, {"lattice": 3}))
    fields.update(changes)
    return Fit(**fields)


def test_scan_round_trip(tmp_path):
    case = Case(tmp_path / "case")
    scan = a_scan(provenance=Provenance({"rec.mcap": "0" * 64}, IngestOptions("right").as_dict()))
    written = case.save_scan(scan)
    assert set(written) == {"scan.ply", "camera.ply", "scan.npz"} and Case.holds(case.folder)
    back = case.load_scan()
    for name in ("points", "normals", "torso_camera", "input_to_breast", "nipple_camera_mm"):
        assert np.array_equal(getattr(back, name), getattr(scan, name)), name
    assert np.array_equal(back.chest_wall.as_array(), scan.chest_wall.as_array())
    assert back.side == "right" and back.roi_camera_mm is None and back.source.frames == 3
    assert back.nipple_found == "areola"
    assert back.source.description == scan.source.description and np.array_equal(back.source.K, scan.source.K)
    assert back.provenance == scan.provenance
    T = scan.input_to_breast                        # the nipple in the breast frame, by hand
    assert np.allclose(back.nipple_breast_mm, T[:3, :3] @ scan.nipple_camera_mm + T[:3, 3])
    assert back.plumb_camera is None                 # no wall was seen behind her


def test_a_wall_behind_her_round_trips_and_a_damaged_one_is_refused(tmp_path):
    """Truth: the wall's normal is a unit vector; anything else in scan.npz is damage."""
    plumb = np.array([0.0, 0.6, -0.8])
    case = Case(tmp_path / "case")
    case.save_scan(dataclasses.replace(a_scan(), plumb_camera=plumb))
    assert np.array_equal(case.load_scan().plumb_camera, plumb)
    damaged = Case(tmp_path / "damaged")
    damaged.save_scan(dataclasses.replace(a_scan(), plumb_camera=np.array([0.0, 1.0, 1.0])))
    with pytest.raises(ArtefactError, match="'plumb_camera' that is not a unit vector"):
        damaged.load_scan()


def test_fit_round_trip_and_the_primitive_and_pose_in_the_ply_header(tmp_path):
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_rotvec([0.0, 0.0, 0.2]).as_matrix()
    pose[:3, 3] = [1.0, -2.0, 0.0]
    model = BreastModel(Primitive(10, 11, 9, 10, 8, 0.9, 1.1), Deformation(turn=(0.4, 0.1)), pose)
    fit = a_fit(model, converged=False, stopping_rule_met=False)
    case = Case(tmp_path)
    case.save_fit(fit)
    back = case.load_fit()
    assert back.primitive == fit.primitive and np.array_equal(back.pose, pose)
    assert np.array_equal(back.vertices, fit.vertices) and np.array_equal(back.faces, fit.faces)
    assert back.residuals_mm == fit.residuals_mm and back.iterations == (40, 3)
    assert back.volume_cc_below_base == 12.5 and back.volume_cc == fit.volume_cc_mesh + 12.5
    assert back.converged is False and back.stopping_rule_met is False and back.provenance == fit.provenance
    assert np.allclose(back.residual_map_mm, fit.residual_map_mm, atol=1e-6)   # stored as float32
    assert Primitive.from_comments(read_ply(tmp_path / "fit.ply").comments) == fit.primitive


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(0.05, 50.0, allow_nan=False), min_size=7, max_size=7))
def test_the_primitive_comment_round_trips_exactly(values):
    p = Primitive(*values)
    assert Primitive.from_comments(["some other comment", p.comment()]) == p
    assert Primitive.from_comments(["nothing here"]) is None
    with pytest.raises(ValueError, match="malformed"):
        Primitive.from_comments([p.comment().replace("a3=", "a3=x")])


def test_a_set_whose_files_do_not_belong_together_is_refused(tmp_path):
    case = Case(tmp_path)
    case.save_fit(a_fit())
    mesh = read_ply(tmp_path / "fit.ply")
    write_ply(tmp_path / "fit.ply", mesh.points + 1.0, faces=mesh.faces)   # a refit killed before its NPZ
    with pytest.raises(ArtefactError, match="fit.ply: is not the file fit.npz was written with"):
        case.load_fit()
    os.unlink(tmp_path / "fit.ply")
    with pytest.raises(ArtefactError, match="fit.ply: is missing"):
        case.load_fit()


def test_a_failed_write_leaves_the_previous_set_whole_and_no_part_file(tmp_path, monkeypatch):
    case = Case(tmp_path)
    case.save_fit(a_fit())
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    import breastplan.case as case_module

    def full_disk(*args, **kwargs):
        raise OSError(28, "No space left on device", str(args[0]))
    monkeypatch.setattr(case_module, "save_npz", full_disk)          # the NPZ is written last
    with pytest.raises(OSError) as caught:
        case.save_fit(a_fit(normalised_residual=0.002))
    assert caught.value.filename == str(tmp_path / "fit.npz")         # the file asked for, not a .part
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    monkeypatch.undo()
    assert case.load_fit().normalised_residual == 0.001


def test_a_folder_where_the_journal_goes_fails_the_write_and_leaves_no_part_file(tmp_path):
    case = Case(tmp_path)
    case.save_fit(a_fit())
    (tmp_path / ".fit.npz.commit").mkdir()                            # not a journal: nothing to recover
    before = {p.name: p.is_dir() or p.read_bytes() for p in tmp_path.iterdir()}
    with pytest.raises(OSError):
        case.save_fit(a_fit(normalised_residual=0.002))
    assert {p.name: p.is_dir() or p.read_bytes() for p in tmp_path.iterdir()} == before


def test_atomic_set_renames_in_staging_order_only_on_success(tmp_path):
    with atomic_set() as stage:
        first, second = stage(tmp_path / "a.txt"), stage(tmp_path / "sub" / "b.txt")
        first.write_text("a")
        second.write_text("b")
        assert not (tmp_path / "a.txt").exists()                       # nothing visible before the end
    assert (tmp_path / "a.txt").read_text() == "a" and (tmp_path / "sub" / "b.txt").read_text() == "b"
    with pytest.raises(RuntimeError):
        with atomic_set() as stage:
            stage(tmp_path / "c.txt").write_text("c")
            raise RuntimeError
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "sub"]


@pytest.mark.parametrize("umask,mode", [(0o022, 0o644), (0o027, 0o640), (0o077, 0o600)])
def test_files_are_readable_as_the_umask_says(tmp_path, umask, mode):
    old = os.umask(umask)
    try:
        Case(tmp_path).save_fit(a_fit())
    finally:
        os.umask(old)
    for name in ("fit.ply", "fit.npz"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == mode, name


def test_provenance_says_whether_a_stage_can_be_reused(tmp_path):
    (tmp_path / "scan.ply").write_bytes(b"a scan")
    made = Provenance.of({"scan.ply": tmp_path / "scan.ply"}, FitOptions().as_dict())
    assert made.inputs == {"scan.ply": hashlib.sha256(b"a scan").hexdigest()}
    case = Case(tmp_path / "case")
    case.save_fit(a_fit(provenance=made))
    assert case.is_fresh(Case.FIT_NPZ, made)
    assert not case.is_fresh(Case.FIT_NPZ, Provenance(made.inputs, FitOptions(lattice=4).as_dict()))
    assert not case.is_fresh(Case.FIT_NPZ, Provenance({"scan.ply": "0" * 64}, made.options))
    assert not case.is_fresh(Case.FIT_NPZ, dataclasses.replace(made, code="0" * 64))    # made by other code
    assert not Case(tmp_path / "empty").is_fresh(Case.FIT_NPZ, made)


def test_sha256_is_the_standard_digest(tmp_path):
    (tmp_path / "abc").write_bytes(b"abc")                             # FIPS 180-2 test vector
    assert sha256(tmp_path / "abc") == "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"


# --- the breast model ---------------------------------------------------------------------
def test_breast_model_composes_primitive_deformations_and_pose():
    P = Primitive(10, 11, 9, 10, 8, 0.9, 1.1)
    D = Deformation(top_shape=(0.5, -0.5, 0, 0), ptosis=(1.0, 0.2), turn=(0.3, 0.1))
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_rotvec([0.05, -0.1, 0.2]).as_matrix()
    pose[:3, 3] = [3.0, -4.0, 1.0]
    model = BreastModel(P, D, pose)
    by_hand = to_mm(D.apply(P.sample(30, 40), P)) @ pose[:3, :3].T + pose[:3, 3]
    assert np.allclose(model.sample(30, 40), by_hand, atol=1e-12)
    V, F = model.mesh(30, 40, closed=False)
    assert np.allclose(V[:30 * 40 - 40], by_hand[:-40], atol=1e-12) and F.max() == len(V) - 1


def test_breast_model_volume_is_the_closed_form_volume_under_shears_and_pose():
    P = Primitive(10, 11, 9.5, 10.5, 9, 1.0, 1.0)
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_rotvec([0.3, 0.2, -0.1]).as_matrix()
    model = BreastModel(P, Deformation(ptosis=(1.5, 0.3), turn=(0.4, 0.0)), pose)   # shears keep the volume
    assert model.volume_cc(200) == pytest.approx(P.volume_cc, rel=1e-3)


@settings(max_examples=25, deadline=None)
@given(b0=st.floats(-1.0, 2.0), c0=st.floats(-1.0, 1.0), h0=st.floats(0.0, 0.2), angle=st.floats(-0.4, 0.4))
def test_breast_model_inverse_takes_surface_points_back_to_the_primitive(b0, c0, h0, angle):
    P = Primitive(10, 11, 9.5, 10.5, 9, 0.9, 1.0)
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_rotvec([0.0, 0.0, angle]).as_matrix()
    model = BreastModel(P, Deformation(flatten_side=(h0, 0.0), ptosis=(b0, 0.1), turn=(c0, 0.0)), pose)
    samples = P.sample(20, 24)
    assert np.allclose(model.inverse(model.place(samples)), samples, atol=1e-9)
    assert np.allclose(model.inverse(model.place(samples), fast=True), samples, atol=1e-3)


# --- options and errors ---------------------------------------------------------------------
@pytest.mark.parametrize("bad", [dict(side="middle"), dict(side="left", voxel_mm=0.1), dict(side="left", frames=0),
                                 dict(side="left", units="inch"), dict(side="left", up="up"),
                                 dict(side="left", roi_camera_mm=(0, 0, 0, -1, 1, 1)),
                                 dict(side="left", nipple_camera_mm=(0, float("nan"), 1))])
def test_ingest_options_refuse_what_no_scan_takes(bad):
    with pytest.raises(ValueError):
        IngestOptions(**bad)


def test_options_are_frozen_and_plain():
    opts = IngestOptions("left", roi_camera_mm=np.arange(6.0) * [1, 1, 1, 2, 2, 2] + [0, 0, 0, 1, 1, 1])
    assert isinstance(opts.roi_camera_mm, tuple)
    with pytest.raises(AttributeError):
        opts.side = "right"
    assert FitOptions().as_dict() == {"lattice": 5, "deformations": ["top-shape", "ptosis", "turn"],
                                      "max_iterations": 1000}
    with pytest.raises(ValueError):
        FitOptions(lattice=9)


def test_errors_raised_without_a_path_get_the_command_s_file():
    with pytest.raises(BadInputError) as caught:
        with about("scan.ply"):
            raise BadInputError(None, "has only 3 points")
    assert str(caught.value) == "scan.ply: has only 3 points."
    with pytest.raises(ArtefactError) as caught:                 # one that names its own file keeps it
        with about("scan.ply"):
            raise ArtefactError("fit.npz", "is corrupt")
    assert str(caught.value) == "fit.npz: is corrupt."


MISMATCHED_WALL = "'chest_wall' whose coefficients do not match its degree"


@pytest.mark.parametrize("field, value, problem", [
    ("input_to_breast", np.zeros((4, 4)), "'transform_camera_to_breast' that is not a rigid transform"),
    ("input_to_view", np.diag([2.0, 1.0, 1.0, 1.0]), "'view_from_camera' that is not a rigid transform"),
    ("chest_wall", ChestWall(np.arange(6.0), 3, np.zeros(2), 1.0), MISMATCHED_WALL),
    ("chest_wall", ChestWall(np.arange(6.0), 2.5, np.zeros(2), 1.0), MISMATCHED_WALL),
    ("chest_wall", ChestWall(np.r_[np.nan, np.zeros(5)], 2, np.zeros(2), 1.0), "NaN or infinite values in 'chest_wall'"),
    ("chest_wall", ChestWall(np.r_[700.0, np.zeros(5)], 2, np.array([1e300, 0.0]), 1.0), "does not lie behind its nipple"),
    ("chest_wall", ChestWall(np.r_[600.0, np.zeros(5)], 2, np.zeros(2), 1.0), "the nipple stands -50 mm in front"),
    ("chest_wall", ChestWall(np.r_[700.0, np.zeros(5)], 2, np.zeros(2), -1.0), "negative spread of its chest wall"),
    ("mound_radius_mm", -5.0, "'crop_mound_radius_mm' of -5, not a positive length"),
    ("voxel_mm", 0.0, "'voxel_mm' of 0, not a positive length"),
])
def test_a_scan_whose_frames_or_chest_wall_cannot_be_used_is_refused_by_name(tmp_path, field, value, problem):
    """Truth: the fit inverts the scan's transforms and evaluates its chest wall; a scan.npz whose
    transforms are not rigid, whose wall's coefficients do not match its degree, whose wall does
    not lie behind the nipple (at 650 mm, 600 mm is in front of it), or whose lengths are not
    positive is damaged."""
    case = Case(tmp_path / "case")
    case.save_scan(dataclasses.replace(a_scan(), **{field: value}))
    with pytest.raises(ArtefactError, match=problem) as err:
        case.load_scan()
    assert err.value.path == case.path(Case.SCAN_NPZ)


def test_a_scan_written_by_another_tool_in_other_number_types_is_read_as_float64_and_int64(tmp_path):
    """Truth: an identity stored in float16 is still the identity, and an 800×600 image in uint16 still
    800×600; readers get float64 and int64, which linear algebra and arithmetic take without wrapping."""
    case = Case(tmp_path / "case")
    case.save_scan(dataclasses.replace(a_scan(), input_to_view=np.eye(4)))
    _rewrite_npz(case.path(Case.SCAN_NPZ), input_to_view=np.eye(4, dtype=np.float16),
                 image_size=np.array([800, 600], np.uint16))
    scan = case.load_scan()
    assert scan.input_to_view.dtype == np.float64 and np.array_equal(scan.input_to_view, np.eye(4))
    assert scan.source.image_size.dtype == np.int64 and (scan.source.image_size - 1000).tolist() == [-200, -400]


def test_a_scan_saying_its_nipple_was_found_some_other_way_is_refused_by_name(tmp_path):
    case = Case(tmp_path / "case")
    case.save_scan(a_scan())
    npz = case.path(Case.SCAN_NPZ)
    with np.load(npz) as z:
        meta = json.loads(str(z["meta"]))
    _rewrite_npz(npz, meta=json.dumps({**meta, "nipple_found": "elbow"}))
    with pytest.raises(ArtefactError, match="says its nipple was found by 'elbow', not one of areola, apex, given"):
        case.load_scan()


def _rewrite_npz(path, **changes):
    """The NPZ at `path` with some entries replaced (`meta` as JSON text), as a foreign tool would."""
    with np.load(path, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays.update({k: np.str_(v) if isinstance(v, str) else v for k, v in changes.items()})
    np.savez(path, **arrays)


@pytest.mark.parametrize("change, problem", [
    ({"volume_cc_mesh": np.float64(-5000.0)}, "records a volume of -5000 cc where fit.ply encloses"),
    ({"volume_cc_mesh": np.float64(1e308)}, "records a volume of 1e\\+308 cc"),
    ({"volume_cc_below_base": np.float64(-1e6)}, "down to the chest wall that is not positive"),
    ({"pose": np.diag([1000.0, 1000.0, 1000.0, 1.0])}, "'pose' that is not a rigid transform"),
    ({"pose": np.zeros((4, 4))}, "'pose' that is not a rigid transform"),
    ({"primitive": np.array([1e7, 1e7, 1e7, 1e7, 1e7, 1.0, 1.0])}, "a primitive that spans 1.2e\\+08 mm"),
    ({"primitive": np.array([10.0, 10, 10, 10, 10, 9.0, 1.0])}, "shape exponents eps1 = 9"),
    ({"normalised_residual": np.float64(-1.0)}, "negative residuals"),
    ({"meta": "[]"}, "metadata that is a list, not a JSON object"),
    ({"meta": '{"points": "abc"}'}, "metadata 'points' that is a string, not an integer"),
    ({"meta": '{"provenance": "x"}'}, "metadata 'provenance' that is a string, not an object"),
    ({"meta": '{"set": ["fit.ply"]}'}, "metadata 'set' that is a list, not an object"),
    ({"meta": '{"provenance": {"inputs": {"scan.ply": 5}}}'}, "'provenance.inputs.scan.ply' that is an integer"),
])
def test_a_fit_npz_whose_numbers_cannot_be_its_surface_s_is_refused_by_name(tmp_path, change, problem):
    """Truth: a fit's recorded volume is the volume its own fit.ply encloses (divergence theorem),
    its pose is rigid, a breast's primitive spans 20–600 mm with eps in 0.3–2, residuals are
    distances and metadata has the types the fit writes; an edited fit.npz that breaks one is
    damaged, named, and never read as a breast."""
    case = Case(tmp_path / "case")
    case.save_fit(a_fit())
    _rewrite_npz(case.path(Case.FIT_NPZ), **change)
    with pytest.raises(ArtefactError, match=problem) as err:
        case.load_fit()
    assert err.value.path == case.path(Case.FIT_NPZ)


def test_a_fit_from_a_newer_breastplan_is_refused_not_refitted_over(tmp_path):
    """Truth: a stage that is merely stale is redone, but an artefact this breastplan cannot read
    because a newer one wrote it must not be overwritten by an older tool."""
    (tmp_path / "scan.ply").write_bytes(b"a scan")
    made = Provenance.of({"scan.ply": tmp_path / "scan.ply"}, FitOptions().as_dict())
    case = Case(tmp_path / "case")
    case.save_fit(a_fit(provenance=made))
    _rewrite_npz(case.path(Case.FIT_NPZ), schema="breastplan.fit/99")
    with pytest.raises(ArtefactError, match="newer than this breastplan reads"):
        case.is_fresh(Case.FIT_NPZ, made)
    _rewrite_npz(case.path(Case.FIT_NPZ), schema="breastplan.fit/2", meta="[]")
    assert not case.is_fresh(Case.FIT_NPZ, made)                # damaged: redone


@pytest.mark.parametrize("pose", [np.eye(3), 2 * np.eye(4), np.full((4, 4), np.nan)])
def test_a_breast_model_refuses_a_pose_that_is_no_rigid_transform(pose):
    with pytest.raises(ValueError, match="rigid 4×4 transform"):
        BreastModel(Primitive(), pose=pose)


def test_the_report_words_every_way_a_nipple_is_found():
    from breastplan.case import NIPPLE_FOUND
    from breastplan.plan.report import NIPPLE_FOUND as WORDS

    assert set(WORDS) == set(NIPPLE_FOUND)
