"""The whole fit: superquadric + FFD lattice, fit.npz / fit.ply and the `fit` command.

Truths: the thesis stopping rule on database breasts, the closed-form volume of shear-deformed
primitives (ptosis, turn and turn-top keep it), the synthetic scanner's true breasts.
"""
import functools
import json
import shutil

import numpy as np
import open3d as o3d
import pytest

from breastplan import Primitive, read_ply, to_mm, transform_points, write_ply
from breastplan.deform.global_deformations import Deformation
from breastplan.deform.names import DEFORMATION_PARAMS, PLAUSIBLE, at_bounds
from breastplan.case import Case, Source, sha256
from breastplan.chest_wall import ChestWall
from breastplan.fitting.breast_fit import MESH_GRID, fit_breast
from breastplan.meshes import mesh_volume

from clitools import assert_bad_input, run

STOP_RESIDUAL = 0.0015
"""The thesis's stopping rule: mean normalised residual below 0.0015 (docs/model.md §6)."""


@pytest.fixture(scope="module")
def database():
    from breastplan.learn.databases import build_database
    return build_database("S")


NEAR_RULE = 1.6
"""The strongest rows of database S meet the stopping rule but for a few (benchmarks/README.md, "Fitting"); which
ones miss it, and by how much, depends on the machine: a fit near the rule turns into one local minimum or
another on the last bits of its floating-point sums (on one machine two of the eight below ended at 0.00159 and
0.00224, on another all eight met the rule). Every one ends converged within this multiple of the rule."""


def test_ffd_of_degree_8_database_breasts_meets_the_thesis_stopping_rule_at_the_median(database):
    from breastplan.learn.datasets import build_dataset

    residuals = []
    for condition, breast in [("ptosis b0>b1", 3), ("turn c1>c0", 40), ("ptosis b1>=b0", 57), ("turn c0>c1", 0),
                              ("ptosis b0", 23), ("turn c0>c1", 29), ("top-shape s0->s1+", 20),
                              ("top-shape s1->s0+", 16)]:
        ds = build_dataset(database, condition, 8)
        k = int(np.flatnonzero((ds.row == 7) & (ds.breast == breast))[0])
        fit = fit_breast(ds.deformed_points(k))
        assert fit.ffd.converged and fit.ffd.residual < NEAR_RULE * STOP_RESIDUAL, (condition, breast, fit.ffd.residual)
        assert fit.ffd.lattice.points.shape == (125, 3)
        residuals.append(fit.ffd.residual)
    assert np.median(residuals) < STOP_RESIDUAL, residuals


@pytest.mark.parametrize("deformation", [Deformation(ptosis=(1.2, 0.3)), Deformation(turn=(0.6, 0.2)),
                                         Deformation(turn_top=(0.5, 0.2))])
def test_fitted_volume_is_the_closed_form_volume_of_a_shear_deformed_primitive(deformation):
    P = Primitive(10, 11, 9.5, 10.5, 9, 0.9, 1.0)
    fit = fit_breast(to_mm(deformation.apply(P.sample(100, 100), P)))
    assert abs(fit.volume_cc / P.volume_cc - 1) <= 0.01
    assert fit.residual_stats()["rms"] < 0.3


def _edges_shared_twice(faces):
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    return np.all(np.unique(e, axis=0, return_counts=True)[1] == 2)


def test_fit_of_ingested_synthetic_scans_is_within_1_mm_of_the_true_breast_and_3_percent_in_volume():
    from breastplan.scenes import synthetic
    from breastplan.ingest.pipeline import ingest_frames
    from breastplan.options import IngestOptions
    from breastplan.ingest.recording import DepthFrames

    scene = synthetic.make_scene(2, tilt_deg=10.0)
    frames = DepthFrames(synthetic.depth_frames(scene, 10, 2), scene.K, "synthetic")
    for side in synthetic.SIDES:
        scan = ingest_frames(frames, IngestOptions(side))
        fit = fit_breast(scan.points)
        side_vertices = fit.vertices[MESH_GRID[1]:-1]                     # all but the base cap
        d = scene.surface_distance(side, transform_points(np.linalg.inv(scan.input_to_breast), side_vertices))
        assert np.sqrt(np.mean(d ** 2)) <= 1.0
        assert abs(fit.volume_cc / scene.breasts[side].primitive.volume_cc - 1) <= 0.03  # its deformations are shears
        assert _edges_shared_twice(fit.faces)                             # closed, watertight


@functools.cache
@functools.lru_cache(maxsize=None)
def realistic_breast(side: str, **body):
    """One breast of a MakeHuman body (`BodyOptions`; modifiers as (name, value) pairs), as
    `ingest_frames` gives it (points and chest wall), seen from the front (a-pose, 650 mm, 800×600, wall at 400 mm, 8 frames)."""
    from breastplan.scenes.makehuman import BodyOptions
    from breastplan.ingest.pipeline import ingest_frames
    from breastplan.scenes.realistic import CameraOptions, make_body_scene
    from breastplan.ingest.recording import DepthFrames
    from breastplan.options import IngestOptions

    scene = make_body_scene(BodyOptions(**{**body, "modifiers": dict(body.get("modifiers", ()))}), CameraOptions(650.0, 0.0, 0.0, "800x600", wall_mm=400.0))
    return ingest_frames(DepthFrames(scene.frames(8, 0), scene.camera.K, "synthetic"), IngestOptions(side))


@pytest.mark.parametrize("wall_mm, words", [(-2000.0, "more than any breast holds"), (500.0, "a negative volume")])
def test_a_fitted_breast_on_a_chest_wall_that_is_not_hers_is_refused(wall_mm, words):
    """A chest wall 2 m behind her breast's base adds its 150-odd cm² times 2 m (some 30 litres) beneath it; one
    half a metre in front of it takes more than the breast holds: neither is a breast's volume, and it is said."""
    from breastplan import BadInputError

    with pytest.raises(BadInputError, match=words):
        fit_breast(realistic_breast("left", cup=0.7).points, chest=lambda xy: np.full(np.shape(xy)[:-1], wall_mm))


def test_fit_of_a_realistic_breast_ends_below_the_plain_primitive_whatever_the_order_of_its_points():
    """Truths: zero deformations give the plain primitive, so a fit with deformations that ends farther
    from the points than the plain primitive has stopped in a local minimum; and the order of the
    points says nothing about the breast. The breast: a heavy, soft MakeHuman breast seen from the
    front (the right one of a body whose top-shape start stopped at 10 mm from its points)."""
    from breastplan.fitting.superquadric import fit_superquadric
    from breastplan.options import FitOptions

    points = realistic_breast("right", cup=0.9, firmness=0.0, weight=0.9, muscle=0.3,
                              modifiers=(("asymmetry", -0.6), ("torso_width", 0.5))).points
    plain = np.mean(np.abs(fit_superquadric(points).residuals_mm))
    deformed = fit_superquadric(points, deformations=FitOptions().deformations)
    assert np.mean(np.abs(deformed.residuals_mm)) < plain
    volumes = [round(fit_breast(p).volume_cc, 2) for p in (points, points[::-1].copy())]
    assert volumes[1] == volumes[0]


@pytest.mark.parametrize("side", ["left", "right"])
def test_the_softer_of_two_realistic_breasts_is_fitted_with_the_larger_ptosis(side):
    """Truth: MakeHuman's firmness 0 sags the breast, firmness 1 lifts it; all else equal, the ptosis
    the fit gives the softer breast (b0 and b1 together, as the sag of its apex) is the larger."""
    body = dict(cup=0.7, weight=0.2, muscle=0.7, modifiers=(("breast_trans", -0.5),))
    soft, firm = (fit_breast(realistic_breast(side, firmness=f, **body).points) for f in (0.0, 1.0))
    assert soft.ptosis_sag_mm > firm.ptosis_sag_mm + 1.0


def test_a_larger_cup_is_fitted_with_most_of_its_true_volume_change():
    """Truth: two MakeHuman bodies differing only in cup differ in volume by exactly the change of
    their half-body volumes; the fitted breasts (left, seen from the front, each down to its chest
    wall) differ by at least 80 % of it (the target is 90 %: the chest under a breast is inferred
    from a frontal scan, about 4 mm higher under the larger one, and 6 % of the change lies over
    90 mm from the nipple; a breast's flat base alone, its chest wall ignored, kept 81 %; the old
    ring-fitted wall, 58 %) and by no more than 120 %."""
    from breastplan.fitting.breast_fit import fit_scan
    from breastplan.scenes.makehuman import BodyOptions, make_body

    body = dict(firmness=0.5, weight=0.5, muscle=0.5)
    small, large = (fit_scan(b).volume_cc
                    for b in (realistic_breast("left", cup=c, **body) for c in (0.3, 0.8)))
    truth = (make_body(BodyOptions(cup=0.8, **body)).half_volumes_cc()["left"]
             - make_body(BodyOptions(cup=0.3, **body)).half_volumes_cc()["left"])
    assert 0.8 * truth < large - small < 1.2 * truth


def test_a_symmetric_womans_two_breasts_planned_alike_grow_alike(cli, tmp_path):
    """Truth: a MakeHuman body with no asymmetry is her own mirror image, so one change planned on both breasts
    changes them alike. Her soft cup-0.8 breasts (arms down, camera straight in front): the right one's fit had
    stopped in a worse minimum (2.7 mm from its points, the left's 1.5 mm), below the plain primitive's cost, and
    top-shape 3 then added 114 cc to it and 57 cc to the left. Each fit is now the better of two starts."""
    res = run(cli, "scan-synth", "--body", "makehuman", "--cup", "0.8", "--firmness", "0.2", "--pose", "arms-down",
              "--frames", "8", "--out", tmp_path / "her.mcap", "--truth", tmp_path / "truth.npz")
    assert res.returncode == 0, res.stderr
    truth = np.load(tmp_path / "truth.npz")
    assert abs(float(truth["left_half_volume_cc"]) - float(truth["right_half_volume_cc"])) < 5.0     # of 24 litres
    res = run(cli, "plan", tmp_path / "her.mcap", "--deform", "top-shape:3", "--out", tmp_path / "case")
    assert res.returncode == 0, res.stderr
    m = json.loads((tmp_path / "case" / "plan.json").read_text())["measures"]
    added = {s: m["after"][s]["volume_cc"] - m["before"][s]["volume_cc"] for s in ("left", "right")}
    assert min(added.values()) > 20.0 and max(added.values()) < 1.15 * min(added.values()), added


REORDERED_BODIES = {"cup 0.8, firmness 0.3, arms down": ("left", dict(cup=0.8, firmness=0.3, pose="arms-down")),
                    "cup 0.3, weight 0.8, hands on hips": ("right", dict(cup=0.3, weight=0.8, pose="hands-on-hips"))}


def _fitted_figures(fit) -> tuple:
    """What a fit prints: its volume (cc, 0.01) and its primitive and deformation parameters (model units)."""
    return round(fit.volume_cc, 2), {k: round(v, 6) for k, v in fit.params().items()}


@pytest.mark.parametrize("body", REORDERED_BODIES)
def test_the_fit_of_a_realistic_breast_is_the_same_whatever_the_order_of_its_points(body):
    """Truth: the order of a scan's points says nothing about her breast. The same ingested breast,
    its points (and normals) as ingested, reversed and shuffled, is fitted (`fit_scan`, on its chest
    wall) to the same volume and the same primitive and deformations, and its per-point residuals
    (superquadric and FFD, the artefact's `residual_map_mm`) come out in the caller's order."""
    import dataclasses

    from breastplan.fitting.breast_fit import fit_scan

    side, options = REORDERED_BODIES[body]
    scan = realistic_breast(side, **options)
    n = len(scan.points)
    orders = (np.arange(n), np.arange(n)[::-1], np.random.default_rng(3).permutation(n))
    fits = [fit_scan(dataclasses.replace(scan, points=np.ascontiguousarray(scan.points[o]),
                                         normals=np.ascontiguousarray(scan.normals[o]))) for o in orders]
    assert all(_fitted_figures(f) == _fitted_figures(fits[0]) for f in fits[1:])
    for order, fit in zip(orders[1:], fits[1:]):
        assert np.array_equal(fit.ffd.residuals_mm, fits[0].ffd.residuals_mm[order])
        assert np.array_equal(fit.superquadric.residuals_mm, fits[0].superquadric.residuals_mm[order])
        assert fit.residual_stats() == fits[0].residual_stats()


@pytest.mark.parametrize("body", REORDERED_BODIES)
def test_the_fit_of_a_realistic_breast_is_the_same_on_one_or_two_blas_threads(body):
    """Truth: the machine's thread count says nothing about her breast: `fit_scan` under one and two
    BLAS threads gives the same volume and parameters (OpenBLAS sums a product in another order on
    two threads, which moved a fit's volume by 2.7 % before the fit ran on one)."""
    from threadpoolctl import threadpool_limits

    from breastplan.fitting.breast_fit import fit_scan

    side, options = REORDERED_BODIES[body]
    scan = realistic_breast(side, **options)
    figures = []
    for threads in (1, 2):
        with threadpool_limits(threads, "blas"):
            figures.append(_fitted_figures(fit_scan(scan)))
    assert figures[1] == figures[0]


def _nudged(points: np.ndarray, seed: int) -> np.ndarray:
    """The points with each coordinate moved in its last bits (relative 1e-12): another machine's rounding."""
    return points * (1.0 + 1e-12 * np.random.default_rng(seed).standard_normal(points.shape))


def test_the_points_a_fit_solves_on_are_chosen_by_position_whatever_their_order_or_last_bits():
    """Truth: which of a breast's points a fit solves on says nothing of her breast, so it must not move
    with their order or with a last-bit change upstream (another machine's rounding): `position_subset`
    of the points reversed, shuffled or nudged by 1e-12 picks the same points, in the same order; the
    first 600 of its 3000 are its 600; and it is an unbiased sample: each half of the breast on either
    side of its median x, y or z holds half the subset within four binomial standard deviations."""
    from breastplan.fitting.sampling import position_subset

    points = realistic_breast("left", cup=0.8, firmness=0.3, pose="arms-down").points
    n = len(points)
    chosen = position_subset(points, 3000)
    index = {p.tobytes(): i for i, p in enumerate(points)}
    picked = np.array([index[p.tobytes()] for p in chosen])
    assert len(np.unique(picked)) == 3000
    for order in (np.arange(n)[::-1], np.random.default_rng(5).permutation(n)):
        assert np.array_equal(position_subset(points[order], 3000), chosen)
    for seed in (1, 2, 3):
        moved = _nudged(points, seed)
        assert not np.array_equal(moved, points)
        assert np.array_equal(position_subset(moved, 3000), moved[picked])
    assert np.array_equal(position_subset(chosen, 600), position_subset(points, 600))
    for axis in range(3):
        below = np.sum(chosen[:, axis] < np.median(points[:, axis]))
        assert abs(below - 1500) < 4 * np.sqrt(3000 * 0.25), (axis, below)


def test_the_plain_primitive_fitted_to_a_realistic_breast_does_not_move_with_its_points_last_bits():
    """Truth: a last-bit change of her points (another machine's rounding upstream) is no change of her
    breast. The plain primitive (analytic Jacobian, no deformations) fitted to the same breast with its
    coordinates nudged by 1e-12 ends where the unnudged fit ends, to 1e-6 of every parameter. When its
    3000 points were a seeded subset drawn by index in the points' sorted order, a nudge reordered points of
    nearly equal x, drew another subset, and moved a parameter by 0.009 here."""
    from breastplan.fitting.superquadric import fit_superquadric

    points = realistic_breast("right", cup=0.3, weight=0.8, pose="hands-on-hips").points
    fits = [fit_superquadric(p) for p in (points, _nudged(points, 1), _nudged(points, 2))]
    for fit in fits[1:]:
        assert np.allclose(fit.x, fits[0].x, rtol=0, atol=1e-6), np.abs(fit.x - fits[0].x).max()


@pytest.fixture(scope="module")
def case(tmp_path_factory, cli):
    folder = tmp_path_factory.mktemp("case")
    res = run(cli, "ingest", "examples/sample.mcap", "--side", "left", "--out", folder)
    assert res.returncode == 0, res.stderr
    return folder


def test_fit_command_refuses_a_volume_no_breast_holds_and_writes_nothing(cli, case, tmp_path):
    """Her scan's chest wall moved 60 mm nearer the camera, in front of her breast's base (scan.npz edited): the
    model's volume down to it is negative, which no breast holds; `fit` exits 3 with one sentence naming the
    case, and writes no fit."""
    copy = tmp_path / "moved"
    shutil.copytree(case, copy)
    with np.load(copy / "scan.npz", allow_pickle=False) as npz:
        arrays = dict(npz)
    arrays["chest_wall"] = arrays["chest_wall"].copy()
    arrays["chest_wall"][4] -= 60.0                        # [degree, x0, y0, σ, constant term, …]: z 60 mm nearer
    np.savez(copy / "scan.npz", **arrays)
    res = run(cli, "fit", copy)
    assert_bad_input(res, copy, copy)
    assert "a negative volume" in res.stderr, res.stderr
    assert not (copy / "fit.npz").exists() and not (copy / "fit.ply").exists()


def test_fit_command_writes_the_artefacts_it_reports(cli, case):
    res = run(cli, "fit", case, "--json")
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert {"volume_cc", "rms_mm", "params", "seconds"} <= set(out)
    mesh = read_ply(case / "fit.ply")
    assert _edges_shared_twice(mesh.faces)
    assert mesh_volume(mesh.points, mesh.faces) / 1000 == pytest.approx(out["model_volume_cc_mesh"], abs=0.01)
    assert out["model_volume_cc"] == pytest.approx(out["model_volume_cc_mesh"] + out["model_volume_cc_below_base"],
                                                   abs=0.02)
    assert out["model_volume_cc_below_base"] > 0     # the sample's chest is convex: it falls away from the base
    assert out["volume_from"] == "skin, one side" and out["uncertainty_cc"] > 0
    fit = Case(case).load_fit()
    assert fit.control_fitted_mm.shape == fit.control_rest_mm.shape == (125, 3)
    assert fit.residuals_mm["rms"] == pytest.approx(out["rms_mm"], abs=1e-4)
    assert fit.volume_cc == pytest.approx(out["model_volume_cc"], abs=0.01)
    assert fit.primitive.a1 == pytest.approx(out["params"]["a1"], abs=1e-5)
    assert fit.provenance.inputs == {"scan.ply": sha256(case / "scan.ply")}
    points = read_ply(case / "scan.ply").points
    assert np.sqrt(np.mean(np.square(_distances(mesh, points)))) == pytest.approx(out["rms_mm"], rel=0.02)


@pytest.mark.parametrize("field, value, words", [
    ("chest_wall", ChestWall(np.zeros(6), 3, np.zeros(2), 1.0),
     "'chest_wall' whose coefficients do not match its degree"),
    ("input_to_view", np.diag([1.0, 1.0, 0.0, 1.0]), "'view_from_camera' that is not a rigid transform"),
    ("source", Source("hologram", "examples/sample.mcap", 8, np.eye(3), np.array([640, 400])),
     "names its source 'hologram', not one of recording, device, file"),
    ("source", Source("recording", "examples/sample.mcap", 8, np.diag([-500.0, 500.0, 1.0]), np.array([640, 400])),
     "holds no usable camera: 8 frames, focal lengths -500 and 500 px"),
    ("source", Source("recording", "examples/sample.mcap", 0, np.diag([500.0, 500.0, 1.0]), np.array([640, 400])),
     "holds no usable camera: 0 frames"),
])
def test_fit_of_a_case_whose_chest_wall_or_frames_are_damaged_is_bad_input(cli, case, tmp_path, field, value, words):
    """Truth: the fit evaluates the case's chest wall and inverts its transforms, and a plan draws her skin and says
    how far the camera stood from what scan.npz says of its source; a scan.npz that cannot give them (or names a
    source no scan comes from, or a depth camera without a camera) is named in one sentence, exit 3, and no fit is
    written."""
    import dataclasses
    import shutil

    damaged = tmp_path / "damaged"
    shutil.copytree(case, damaged, ignore=shutil.ignore_patterns("fit.*"))
    Case(damaged).save_scan(dataclasses.replace(Case(damaged).load_scan(), **{field: value}))
    res = run(cli, "fit", damaged)
    assert_bad_input(res, damaged / "scan.npz", damaged)
    assert words in res.stderr, res.stderr
    assert not list(damaged.glob("fit.*"))


def _distances(mesh, points):
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(mesh.points.astype(np.float32)), o3d.core.Tensor(mesh.faces.astype(np.uint32)))
    return scene.compute_distance(o3d.core.Tensor(points.astype(np.float32))).numpy()


def test_fit_command_on_a_ply_writes_next_to_it_and_fits_deformations(cli, tmp_path):
    P = Primitive(10, 11, 9.5, 10.5, 9, 0.9, 1.0)
    write_ply(tmp_path / "breast.ply", to_mm(Deformation(ptosis=(1.0, 0.3)).apply(P.sample(80, 80), P)))
    res = run(cli, "fit", tmp_path / "breast.ply", "--deformations", "ptosis", "--lattice", "4", "--json")
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert out["params"]["b0"] == pytest.approx(1.0, abs=0.03) and out["params"]["b1"] == pytest.approx(0.3, abs=0.03)
    assert out["model_volume_cc_below_base"] == 0 and out["model_volume_cc"] == out["model_volume_cc_mesh"]  # no chest
    assert (out["volume_cc"], out["volume_from"]) == (round(out["model_volume_cc"], 2), "model")   # nor skin round it
    assert Case(tmp_path).load_fit().control_rest_mm.shape == (64, 3)


def test_fit_command_fits_top_shape_ptosis_and_turn_by_default_and_none_fits_the_plain_primitive(cli, tmp_path):
    P = Primitive(10, 11, 9.5, 10.5, 9, 0.9, 1.0)
    truth = Deformation(top_shape=(1.0, -1.5, 0.0, 0.0), ptosis=(0.8, 0.2), turn=(0.5, 0.1))
    write_ply(tmp_path / "breast.ply", to_mm(truth.apply(P.sample(80, 80), P)))
    res = run(cli, "fit", tmp_path / "breast.ply", "--json")
    assert res.returncode == 0, res.stderr
    params = json.loads(res.stdout)["params"]
    for name, value in (("s0", 1.0), ("s1", -1.5), ("b0", 0.8), ("b1", 0.2), ("c0", 0.5), ("c1", 0.1)):
        assert params[name] == pytest.approx(value, abs=0.1 if name[0] == "s" else 0.03), name
    plain = json.loads(run(cli, "fit", tmp_path / "breast.ply", "--deformations", "none", "--json").stdout)["params"]
    assert not {"s0", "s1", "b0", "b1", "c0", "c1"} & set(plain)
    for empty in ("", ",", "ptosis,", "none,ptosis", "ptosis,turn,ptosis"):   # no list: not a silent 'none'
        res = run(cli, "fit", tmp_path / "breast.ply", "--deformations", empty)
        assert res.returncode == 2 and "--deformations" in res.stderr, (empty, res.stderr)


def test_a_ptosis_beyond_its_plausible_range_is_fitted_at_its_end_and_said(cli, tmp_path):
    """b0 = 4.5 asks for more than the plausible −1…3: the fit stops b0 at 3 and names it, on stderr and
    in its JSON; b0 = 1 is inside and named nowhere."""
    P = Primitive(10, 11, 9.5, 10.5, 9, 0.9, 1.0)
    out = {}
    for b0 in (4.5, 1.0):
        write_ply(tmp_path / f"b0-{b0}.ply", to_mm(Deformation(ptosis=(b0, 0.3)).apply(P.sample(80, 80), P)))
        res = run(cli, "fit", tmp_path / f"b0-{b0}.ply", "--deformations", "ptosis", "--lattice", "4", "--json")
        assert res.returncode == 0, res.stderr
        out[b0] = (json.loads(res.stdout), " ".join(res.stderr.split()))
    beyond, inside = out[4.5][0], out[1.0][0]
    assert beyond["params"]["b0"] == pytest.approx(PLAUSIBLE["b0"][1]) and "b0" in beyond["at_bounds"]
    assert "the fitted b0" in out[4.5][1] and "reached the end of their plausible range" in out[4.5][1]
    assert inside["at_bounds"] == [] and "plausible range" not in out[1.0][1]


def test_at_bounds_names_a_parameter_at_either_end_of_its_range_only():
    lo, hi = PLAUSIBLE["b0"]
    assert at_bounds({"b0": lo}) == ["b0"] and at_bounds({"b0": hi, "c1": PLAUSIBLE["c1"][0]}) == ["b0", "c1"]
    assert at_bounds({"b0": 0.5 * (lo + hi), "b1": PLAUSIBLE["b1"][1] - 1e-3}) == []
    assert at_bounds({"a1": 1e9}) == []                                  # a primitive's parameter has no such range
    assert DEFORMATION_PARAMS == ("s0", "s1", "t0", "t1", "h0", "h1", "g0", "g1", "b0", "b1", "c0", "c1")


def _cloud(tmp_path, points):
    write_ply(tmp_path / "in.ply", points)
    return tmp_path / "in.ply"


SENTENCES = {"missing": "no such file", "not a PLY": "neither a PLY file nor a case folder",
             "few": "at least 50", "collinear": "is flat", "metres": "is it in metres",
             "NaN": "NaN or infinite coordinates", "no surface": "found no breast surface",
             "one point": "all its points at one place", "micrometres": "is it in micrometres",
             "centimetres": "is it in centimetres", "board": "is flat", "reversed": "is its z axis reversed",
             "a torso": "far too large for one breast"}


@pytest.mark.parametrize("problem", list(SENTENCES))
def test_bad_input_exits_3_naming_the_file_and_writes_nothing(cli, tmp_path, problem):
    P = Primitive(10, 11, 9.5, 10.5, 9, 0.9, 1.0)
    args = []
    if problem == "missing":
        path = tmp_path / "absent.ply"
    elif problem == "not a PLY":
        path = tmp_path / "scan.txt"
        path.write_text("1 2 3\n")
    elif problem == "NaN":
        path = tmp_path / "in.ply"
        header = "ply\nformat ascii 1.0\nelement vertex 3\n" + "".join(f"property float {c}\n" for c in "xyz")
        path.write_text(header + "end_header\n0 0 0\nnan 1 2\n1 2 3\n")
    elif problem == "few":
        path = _cloud(tmp_path, to_mm(P.sample(5, 8)))
    elif problem == "collinear":
        path = _cloud(tmp_path, np.column_stack([np.arange(100.0), np.zeros(100), np.zeros(100)]))
    elif problem == "metres":
        path = _cloud(tmp_path, to_mm(P.sample(40, 40)) / 1000)
    elif problem == "micrometres":
        path = _cloud(tmp_path, to_mm(P.sample(40, 40)) * 1000)
    elif problem == "one point":
        path = _cloud(tmp_path, np.full((100, 3), 7.0))
    elif problem == "centimetres":
        path = _cloud(tmp_path, to_mm(P.sample(40, 40)) / 10)
    elif problem == "board":                                  # 300 × 200 mm, 0.5 mm noise
        x, y = np.meshgrid(np.linspace(-150, 150, 60), np.linspace(-100, 100, 40))
        path = _cloud(tmp_path, np.column_stack([x.ravel(), y.ravel(), np.random.default_rng(0).normal(0, 0.5, x.size)]))
    elif problem == "reversed":                               # a breast hollowed into its base: z negated
        path = _cloud(tmp_path, to_mm(P.sample(40, 40)) * [1.0, 1.0, -1.0])
    elif problem == "a torso":                                # a box 650 mm across
        path = _cloud(tmp_path, np.random.default_rng(0).uniform(0, 650, (3000, 3)))
    else:                                                     # a box of scattered points: no breast to fit
        path = _cloud(tmp_path, np.random.default_rng(0).uniform(0, 120, (3000, 3)))
    res = run(cli, "fit", path, *args)
    assert_bad_input(res, path, tmp_path)
    assert SENTENCES[problem] in res.stderr
    assert not (tmp_path / "fit.npz").exists() and not (tmp_path / "fit.ply").exists()


def test_a_fit_that_misses_the_stopping_rule_is_written_and_says_so(cli, tmp_path):
    """Truth: with 1 mm noise the mean normalised residual cannot fall below 0.0015 (the noise alone,
    ≈ 0.8 mm mean over points ≈ 60 mm from the origin, is ≈ 0.013); one FFD iteration is the budget."""
    P = Primitive(10, 11, 9.5, 10.5, 9, 0.9, 1.0)
    noisy = to_mm(Deformation(ptosis=(2.0, 0.5)).apply(P.sample(60, 60), P))
    path = _cloud(tmp_path, noisy + np.random.default_rng(0).normal(0, 1.0, noisy.shape))
    res = run(cli, "fit", path, "--max-iterations", "1", "--json")
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert out["stopping_rule_met"] is False and out["normalised_residual"] > STOP_RESIDUAL
    assert out["iterations"]["ffd"] <= 1
    rule = [line for line in res.stderr.splitlines() if "stopping rule" in line]
    assert len(rule) == 1 and rule[0].startswith("warning:") and str(path) in rule[0]
    fit = Case(tmp_path).load_fit()
    assert fit.stopping_rule_met is False and fit.iterations[1] == out["iterations"]["ffd"]
    assert fit.residual_map_mm.shape == (len(noisy),)          # where it misses, point by point
    assert np.mean(fit.residual_map_mm) == pytest.approx(out["residuals_mm"]["mean"], abs=1e-3)
    assert 0.5 < np.sqrt(np.mean(np.square(fit.residual_map_mm))) < 3.0   # the 1 mm noise, not a failed fit


def test_deform_refuses_a_case_whose_fit_is_of_an_earlier_scan(cli, case, tmp_path):
    """The case ingested again (the other breast) after its fit: the fit beside the new scan.ply is
    another breast's, so deform says so instead of deforming it; fitted again, it deforms."""
    folder = tmp_path / "case"
    shutil.copytree(case, folder)
    assert run(cli, "fit", folder).returncode == 0
    res = run(cli, "ingest", "examples/sample.mcap", "--side", "right", "--out", folder)
    assert res.returncode == 0, res.stderr
    deform = ("deform", folder, "--kind", "ptosis", "--degree", "2", "--out", tmp_path / "sag.ply")
    res = run(cli, *deform)
    assert_bad_input(res, folder / "fit.npz", tmp_path)
    assert "was fitted to another scan than the scan.ply beside it" in res.stderr
    assert not (tmp_path / "sag.ply").exists()
    assert run(cli, "fit", folder).returncode == 0
    assert run(cli, *deform).returncode == 0


def test_deform_of_a_fit_uses_its_primitive_and_pose(cli, tmp_path):
    """Truth: ptosis moves points along the primitive's own −y (docs/model.md §3), which the fit's pose
    turns into the breast frame: the displacement of each vertex, taken back by the pose's rotation,
    is exactly (0, −(b0·ζ + b1·ζ²), 0) with ζ = z/10 in the primitive frame."""
    P = Primitive(10, 11, 9.5, 10.5, 9, 0.9, 1.0)
    write_ply(tmp_path / "breast.ply", to_mm(Deformation(turn=(0.6, 0.2)).apply(P.sample(60, 60), P)))
    assert run(cli, "fit", tmp_path / "breast.ply").returncode == 0
    res = run(cli, "deform", tmp_path / "fit.npz", "--kind", "ptosis", "--param", "b0=1.5,b1=0.5",
              "--out", tmp_path / "sag.ply", "--json")
    assert res.returncode == 0, res.stderr
    fit = Case(tmp_path).load_fit()
    after = read_ply(tmp_path / "sag.ply")
    assert np.array_equal(after.faces, fit.faces)
    R, t = fit.pose[:3, :3], fit.pose[:3, 3]
    local = (fit.vertices - t) @ R                               # primitive frame, mm
    zeta = local[:, 2] / 6.0 / 10.0
    moved = (after.points - fit.vertices) @ R
    assert np.allclose(moved, np.column_stack([0 * zeta, -6.0 * (1.5 * zeta + 0.5 * zeta ** 2), 0 * zeta]), atol=1e-9)
