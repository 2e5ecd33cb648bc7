"""The filter registry (filters/), its built-in filters on a realistic scan, the `filters` and `filter`
commands, and third-party filters installed as a real distribution with an entry point.

The scan is a MakeHuman body as `scan-synth --scan-file` writes it (mm, up +y: the body frame, X her
left, Y up, Z anterior); its truths — MakeHuman's nipple rings and the exact volume of each half of
the closed body — are computed from the body, never from the filters' output.
"""
import inspect
import json
import os
import subprocess
import re
import sys
import textwrap
from typing import Literal

import numpy as np
import pytest

from breastplan import BadInputError, read_ply, write_ply
from breastplan.filters import (Filter, Mesh, ParameterError, UnknownFilterError, filter, filters, get,
                                registry)
from breastplan.scenes.makehuman import BodyOptions, make_body
from breastplan.scenes.realistic import CameraOptions, make_body_scene, write_scan_file
from breastplan.plan.job import sample_recording

from clitools import assert_bad_input, run

BUILTINS = ("apply_breast_ptosis", "apply_breast_top_shape", "apply_breast_turn", "compute_breast_fit",
            "compute_breast_isolation", "get_breast_measures")
NIPPLE_MM = 8.0
"""The nipple tolerance of the isolation tests (tests/test_realistic.py)."""
VOLUME_FACTOR = 1.5
"""How far the fitted volume may lie from what the cup adds to her half body, as a factor either way: the
cup target also thickens the chest around the breast, which the fit's base (on the chest wall ingest
finds) leaves out, and a cup of 0 keeps a small mound of its own; the two measure the breast only
roughly alike."""


@pytest.fixture(scope="module")
def scan(tmp_path_factory):
    """A realistic scan file (the depth pixels of a MakeHuman body of average build in A-pose, a wall
    400 mm behind her; mm, up +y) and her body (its frame is the file's)."""
    folder = tmp_path_factory.mktemp("scan")
    scene = make_body_scene(BodyOptions(), CameraOptions())
    path = folder / "body.ply"
    write_scan_file(path, scene, units="mm", up="+y")
    return path, scene.body


@pytest.fixture
def sandbox(monkeypatch):
    """A copy of the registry that the test may add filters to, restored afterwards."""
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))


# --- 1. the registry ---------------------------------------------------------------------------------

def test_the_builtin_filters_take_the_parameters_of_their_signatures():
    assert [f.name for f in filters(plugins=False)] == sorted(BUILTINS)
    for f in filters(plugins=False):
        signature = inspect.signature(f.function)
        names = list(signature.parameters)[1:]
        assert [p.name for p in f.parameters] == names
        for p in f.parameters:
            assert p.default == signature.parameters[p.name].default
            assert isinstance(p.default, p.type)
        assert f.description and f.description == inspect.getdoc(f.function).splitlines()[0]
    ptosis = {p.name: p for p in get("apply_breast_ptosis").parameters}
    assert (ptosis["degree"].type, ptosis["degree"].default, ptosis["degree"].choices) == (float, 3.0, None)
    assert ptosis["method"].choices == ("exact", "learnt") and ptosis["method"].default == "exact"
    assert ptosis["up"].choices == ("auto", "+x", "-x", "+y", "-y", "+z", "-z") and ptosis["up"].default == "auto"
    fit = {p.name: p for p in get("compute_breast_fit").parameters}
    assert (fit["lattice"].type, fit["lattice"].default) == (int, 5)


def test_a_decorated_function_is_registered_with_typed_parameters_and_converts_strings(sandbox):
    @filter("test_shift")
    def shift(mesh, *, by: float = 1.5, times: int = 2, axis: Literal["x", "y", "z"] = "x", back: bool = False) -> Mesh:
        """Shift a mesh along an axis.

        More words that are not the description."""
        step = np.eye(3)["xyz".index(axis)] * by * times * (-1 if back else 1)
        return Mesh(mesh.vertices + step, mesh.faces)

    assert isinstance(shift, Filter) and get("test_shift") is shift and shift in filters()
    assert shift.description == "Shift a mesh along an axis."
    assert [(p.name, p.type, p.default, p.choices) for p in shift.parameters] == [
        ("by", float, 1.5, None), ("times", int, 2, None), ("axis", str, "x", ("x", "y", "z")), ("back", bool, False, None)]
    assert shift.bind({"by": "2.5", "times": "3", "axis": "z", "back": "yes"}) == \
        {"by": 2.5, "times": 3, "axis": "z", "back": True}
    assert shift.bind({}) == {"by": 1.5, "times": 2, "axis": "x", "back": False}

    square = Mesh([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], [[0, 1, 2]])
    moved = shift(square, by="1", axis="y", back="false")
    assert np.array_equal(moved.vertices, square.vertices + [0.0, 2.0, 0.0])
    assert np.array_equal(square.vertices[1], [1.0, 0.0, 0.0])            # the input is unchanged ...
    with pytest.raises(ValueError):
        square.vertices[0, 0] = 5.0                                       # ... and cannot be changed

    for values, words in [({"by": "two"}, "by='two' is not a finite number"), ({"times": "2.5"}, "not a whole number"),
                          ({"axis": "w"}, "axis='w' is not one of x, y, z"), ({"back": "maybe"}, "not true or false"),
                          ({"by": "nan"}, "not a finite number"), ({"bye": "1"}, "did you mean by?")]:
        with pytest.raises(ParameterError, match=words) as caught:
            shift.bind(values)
        assert str(caught.value).count(".") <= 1 and "\n" not in str(caught.value)    # one sentence
    with pytest.raises(UnknownFilterError, match="did you mean test_shift"):
        get("test_shfit")


def test_a_plain_function_registered_by_the_decorator_takes_its_own_name(sandbox):
    @filter
    def test_count(mesh) -> dict:
        """Count the points."""
        return {"points": len(mesh.vertices)}

    assert get("test_count") is test_count and test_count.parameters == ()
    assert test_count(np.zeros((4, 3))) == {"points": 4}                  # (N, 3) points are a point cloud
    with pytest.raises(ParameterError, match="has no parameter 'x'; it takes none"):
        test_count(np.zeros((4, 3)), x=1)


@pytest.mark.parametrize("source, words", [
    ("def f(mesh, by: float = 1.0): pass", "keyword-only"),
    ("def f(*, by: float = 1.0): pass", "first positional parameter"),
    ("def f(mesh, *, by=1.0): pass", "annotated none"),
    ("def f(mesh, *, by: list = []): pass", "annotated list"),
    ("def f(mesh, *, by: float): pass", "needs a default"),
    ("def f(mesh, *, by: int = 1.5): pass", "is not of its type"),
    ("def f(mesh, *, by: Literal['a', 1] = 'a'): pass", "Literal"),
])
def test_a_function_that_is_no_filter_is_refused(sandbox, source, words):
    scope = {"Literal": Literal}
    exec(source, scope)
    with pytest.raises(TypeError, match=words):
        filter("test_bad")(scope["f"])
    with pytest.raises(UnknownFilterError):
        get("test_bad")


def test_a_fortran_ordered_array_as_pymeshlab_gives_is_fitted_exactly_as_its_c_ordered_copy(scan):
    points = read_ply(scan[0]).points
    fortran = np.asfortranarray(points)
    assert fortran.flags.f_contiguous and not fortran.flags.c_contiguous
    from breastplan.filters import forget

    c_result = get("compute_breast_fit")(Mesh(points), side="left").vertices
    forget()                                               # not the remembered fit of the same values
    assert np.array_equal(get("compute_breast_fit")(Mesh(fortran), side="left").vertices, c_result)


def test_a_filter_cannot_take_the_name_of_the_meshlab_bridges_own_function(sandbox):
    with pytest.raises(ValueError, match="cannot be named 'run'"):
        filter("run")(lambda mesh: {})


def test_a_second_function_cannot_take_a_registered_name(sandbox):
    with pytest.warns(registry.PluginWarning, match="apply_breast_ptosis .* registered a filter of that name first"):
        filter("apply_breast_ptosis")(lambda mesh: {})
    assert get("apply_breast_ptosis").function.__module__ == "breastplan.filters.stages"


def test_meshes_with_bad_arrays_are_bad_input():
    with pytest.raises(BadInputError, match="faces that refer to missing vertices"):
        Mesh(np.zeros((3, 3)), [[0, 1, 3]])
    with pytest.raises(BadInputError, match=r"vertices of shape \(4, 2\)"):
        Mesh(np.zeros((4, 2)))
    assert Mesh(np.zeros((3, 3)), np.zeros((0, 3), int)).faces is None    # no faces: a point cloud
    with pytest.raises(BadInputError, match=r"vertices in rows of unequal length, not \(N, 3\)"):
        Mesh([[1, 2, 3], [1, 2]])
    for values in (np.ones((4, 3), bool), np.ones((4, 3), complex), np.ones((4, 3), object), np.full((4, 3), "1")):
        with pytest.raises(BadInputError, match=f"vertices of type {values.dtype}, not real numbers"):
            Mesh(values)


@pytest.mark.parametrize("points, words", [
    (np.zeros((0, 3)), "has only 0 points"),
    (np.full((50, 3), np.nan), "NaN or infinite"),
    (np.random.default_rng(0).uniform(0, 1, (2, 3)), "has only 2 points"),
])
def test_bad_geometry_is_refused_with_one_sentence(points, words):
    with pytest.raises(BadInputError, match=words) as caught:
        get("compute_breast_fit")(Mesh(points))
    assert str(caught.value).endswith(".") and "\n" not in str(caught.value)


def test_a_degree_out_of_range_is_refused_before_any_work():
    with pytest.raises(ParameterError, match="degree=9 lies outside 1..8"):
        get("apply_breast_ptosis").bind({"degree": 9})


# --- 2. the commands on a realistic scan ---------------------------------------------------------------

def test_filters_json_lists_every_filter_with_typed_parameters(cli):
    res = run(cli, "filters", "--json")
    assert res.returncode == 0, res.stderr
    listed = {f["name"]: f for f in json.loads(res.stdout)["filters"]}
    assert set(BUILTINS) <= set(listed)
    for name in BUILTINS:
        signature = inspect.signature(get(name).function)
        params = {p["name"]: p for p in listed[name]["parameters"]}
        assert list(params) == list(signature.parameters)[1:]
        for pname, p in params.items():
            assert p["default"] == signature.parameters[pname].default
    assert params["side"]["choices"] == ["auto", "left", "right"]            # get_breast_measures's
    degree = listed["apply_breast_ptosis"]["parameters"][0]
    assert degree == {"name": "degree", "type": "float", "default": 3.0, "choices": None}
    assert listed["get_breast_measures"]["returns"] == "measures" and listed["compute_breast_fit"]["returns"] == "mesh"


@pytest.mark.parametrize("columns", ["20", "200"])
def test_filters_lists_every_name_and_parameter_whole_at_any_width(cli, columns):
    res = subprocess.run([cli, "filters"], capture_output=True, text=True, timeout=600,
                         env={**os.environ, "COLUMNS": columns})
    assert res.returncode == 0, res.stderr
    words = set(re.findall(r"[\w.]+", res.stdout))
    for name in BUILTINS:
        assert name in words
        assert set(list(inspect.signature(get(name).function).parameters)[1:]) <= words


def test_isolation_keeps_the_breast_around_the_true_nipple(cli, scan, tmp_path):
    path, body = scan
    out = tmp_path / "breast.ply"
    res = run(cli, "filter", "compute_breast_isolation", path, "--param", "side=right", "--out", out, "--json")
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["faces"] == 0
    breast = read_ply(out)
    assert breast.faces is None and len(breast.points) > 500
    nipple = body.nipples["right"]
    assert np.linalg.norm(breast.points - nipple, axis=1).min() <= 3.0    # on the skin at the nipple (2 mm voxels)
    assert (breast.points[:, 0] < 0).all()                                # her right: X < 0
    assert np.linalg.norm(breast.points - nipple, axis=1).max() < 150.0  # one breast, not the chest


def test_measures_find_the_nipple_and_a_breast_of_the_volume_the_cup_adds(cli, scan):
    path, body = scan
    res = run(cli, "filter", "get_breast_measures", path, "--json")
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    measures = out["result"]
    assert out["params"]["side"] == "auto" and measures["side"] == "left"    # auto: the left breast of a scan
    assert np.linalg.norm(np.array(measures["nipple_mm"]) - body.nipples["left"]) <= NIPPLE_MM
    flat = make_body(BodyOptions(cup=0.0)).half_volumes_cc()["left"]
    added = body.half_volumes_cc()["left"] - flat
    assert added > 50.0                                                    # the cup adds a breast indeed
    assert added / VOLUME_FACTOR <= measures["volume_cc"] <= added * VOLUME_FACTOR
    assert measures["fit_volume_cc"] > measures["volume_cc"]   # the fit reaches down to her convex chest, the mesh its base
    assert measures["upper_pole_cc"] + measures["lower_pole_cc"] == pytest.approx(measures["volume_cc"], rel=1e-6)
    # the fitted base's width: on this body the model's base reaches beyond the skin the camera saw (a nearby
    # minimum, docs/realistic.md), up to about 210 mm; half her chest is wider than that
    assert measures["rms_mm"] < 2.0 and 50.0 < measures["width_mm"] < 250.0 and 10.0 < measures["projection_mm"] < 100.0
    assert measures["changes"] == []


def test_a_ptosis_of_degree_5_lowers_the_nipple_along_her_up_axis_and_keeps_the_volume(cli, scan, tmp_path):
    path, body = scan
    fit, sagged = tmp_path / "fit.ply", tmp_path / "ptosis.ply"
    res = run(cli, "filter", "compute_breast_fit", path, "--out", fit)
    assert res.returncode == 0, res.stderr
    res = run(cli, "filter", "apply_breast_ptosis", path, "--param", "degree=5", "--out", sagged, "--json")
    assert res.returncode == 0, res.stderr
    before, after = read_ply(fit), read_ply(sagged)
    assert np.array_equal(before.faces, after.faces)                      # the fitted surface, its vertices moved
    tip = np.argmin(np.linalg.norm(before.points - body.nipples["left"], axis=1))
    assert np.linalg.norm(before.points[tip] - body.nipples["left"]) <= NIPPLE_MM
    drop = before.points[tip, 1] - after.points[tip, 1]                   # Y: her up axis
    assert drop > 1.0
    from breastplan.meshes import mesh_volume

    # a ptosis is a shear (Jacobian determinant 1): the breast keeps its volume
    assert mesh_volume(after.points, after.faces) == pytest.approx(mesh_volume(before.points, before.faces), rel=0.01)
    assert any("mm, the input's frame" in c for c in after.comments)


def test_a_change_short_of_its_degree_warns_and_its_measures_say_so(scan):
    import warnings

    from breastplan.filters import ShortOfDegree, apply_breast_ptosis, get_breast_measures
    fitted = get("compute_breast_fit")(Mesh(read_ply(scan[0]).points), side="left")
    for degree in (1.0, 8.0):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            change = get_breast_measures(apply_breast_ptosis(fitted, degree=degree))["changes"][0]
        short = [w for w in caught if issubclass(w.category, ShortOfDegree)]
        assert change["reached"] == (abs(change["degree_reached"] - degree) < 0.5)   # rounds to the degree
        assert len(short) == (not change["reached"])
        if short:
            assert f"degree {change['degree_reached']:.2f}, not {degree:g}" in str(short[0].message)


def test_a_scan_without_a_breast_exits_3_naming_the_file(cli, tmp_path):
    """A flat board 600 × 400 mm, 2 mm apart, 0.5 mm noise (as tests/test_realistic.py)."""
    x, y = np.meshgrid(np.arange(-300.0, 300.0, 2.0), np.arange(-200.0, 200.0, 2.0))
    z = np.random.default_rng(0).normal(0.0, 0.5, x.shape)
    board = write_ply(tmp_path / "board.ply", np.column_stack([x.ravel(), y.ravel(), z.ravel()]))
    res = run(cli, "filter", "compute_breast_fit", board, "--out", tmp_path / "out.ply")
    assert_bad_input(res, board, tmp_path)


@pytest.mark.parametrize("name, content, words", [
    ("scan.ply", b"ply\nformat ascii 1.0\nelement vertex 3\n", "no 'end_header'"),
    ("scan.ply", None, "no such file"),
    ("sample.mcap", sample_recording().read_bytes(), "is a depthai recording; filters take a scan or mesh file")])
def test_a_bad_file_exits_3_naming_it(cli, tmp_path, name, content, words):
    path = tmp_path / name
    if content is not None:
        path.write_bytes(content)
    res = run(cli, "filter", "get_breast_measures", path)
    assert_bad_input(res, path, tmp_path)
    assert words in res.stderr


@pytest.mark.parametrize("args, words", [
    (["no_such_filter"], "there is no filter 'no_such_filter'"),
    (["apply_breast_ptosiss"], "did you mean apply_breast_ptosis"),
    (["apply_breast_ptosis", "--param", "degre=5"], "did you mean degree"),
    (["apply_breast_ptosis", "--param", "degree=five"], "not a finite number"),
    (["apply_breast_ptosis", "--param", "degree=9"], "outside 1..8"),
    (["apply_breast_ptosis", "--param", "method=guess"], "not one of exact, learnt"),
    (["apply_breast_ptosis", "--param", "degree"], "not NAME=VALUE"),
    (["compute_breast_fit", "--param", "lattice=9"], "lattice"),
    (["compute_breast_fit", "--param", "lattice=5.5"], "not a whole number"),
    (["get_breast_measures", "--param", "side=middle"], "not one of auto, left, right"),
])
def test_a_bad_filter_or_parameter_is_a_usage_error(cli, scan, tmp_path, args, words):
    path, _ = scan
    name, rest = args[0], args[1:]
    out = [] if name == "get_breast_measures" else ["--out", tmp_path / "out.ply"]
    res = run(cli, "filter", name, path, *rest, *out)
    assert res.returncode == 2, (res.returncode, res.stderr)
    assert " ".join(words.split()) in " ".join(res.stderr.replace("│", " ").split())
    assert res.stdout == "" and not (tmp_path / "out.ply").exists()


def test_a_mesh_filter_needs_an_output_and_a_measures_filter_takes_none(cli, scan, tmp_path):
    path, _ = scan
    res = run(cli, "filter", "compute_breast_fit", path)
    assert res.returncode == 2 and "--out" in res.stderr
    res = run(cli, "filter", "get_breast_measures", path, "--out", tmp_path / "x.ply")
    assert res.returncode == 2 and "--out" in res.stderr


# --- 3. plugins, installed for real ----------------------------------------------------------------------

def pyproject(name: str, version: str, entry_points: dict[str, str]) -> str:
    """The pyproject.toml of a plugin distribution: its modules are those its entry points name."""
    modules = list(dict.fromkeys(target.split(":")[0] for target in entry_points.values()))
    points = "\n".join(f'{key} = "{target}"' for key, target in entry_points.items())
    return f"""
[build-system]
requires = ["setuptools>=61"]
build-backend = "setuptools.build_meta"

[project]
name = "{name}"
version = "{version}"

[project.entry-points."breastplan.filters"]
{points}

[tool.setuptools]
py-modules = {json.dumps(modules)}
"""


PLUGIN = {
    "pyproject.toml": pyproject("breastplan-scale-plugin", "0.1.0", {"scale_mesh": "bp_scale_plugin:scale_mesh",
                                                                   "shifted": "bp_scale_plugin:shift",
                                                                   "extra": "bp_scale_extra"}),
    "bp_scale_plugin.py": '''
        from breastplan.filters import Mesh, filter


        @filter("scale_mesh")
        def scale_mesh(mesh, *, factor: float = 2.0) -> Mesh:
            """Scale a mesh about the origin."""
            return Mesh(mesh.vertices * factor, mesh.faces)


        def shift(mesh, *, dx: float = 0.0) -> Mesh:
            """Shift a mesh along x (a plain function: registered under its entry point's name)."""
            return Mesh(mesh.vertices + [dx, 0.0, 0.0], mesh.faces)
        ''',
    "bp_scale_extra.py": '''
        from breastplan.filters import filter


        import numpy as np

        from breastplan.filters import Mesh, filter


        @filter("count_points")
        def count_points(mesh) -> dict:
            """Count the points (a module whose import registers its filters)."""
            return {"points": len(mesh.vertices)}


        @filter("log_depth")
        def log_depth(mesh) -> Mesh:
            """z replaced by its logarithm: numpy warns of a zero z, and its -inf is refused."""
            return Mesh(np.column_stack([mesh.vertices[:, :2], np.log(mesh.vertices[:, 2])]), mesh.faces)
        ''',
}
BROKEN = {
    "pyproject.toml": pyproject("breastplan-broken-plugin", "0.2.0", {"broken": "bp_broken_plugin:smooth"}),
    "bp_broken_plugin.py": '''
        raise RuntimeError("this plugin needs a library that is not installed")
        ''',
}


@pytest.fixture(scope="module")
def plugin_site(tmp_path_factory):
    """Two plugin distributions built and installed with pip into a folder for PYTHONPATH: one with a
    decorated function, a plain function and a module as entry points, one that fails to import."""
    root = tmp_path_factory.mktemp("plugins")
    dists = []
    for name, files in (("scale", PLUGIN), ("broken", BROKEN)):
        folder = root / name
        folder.mkdir()
        for file, text in files.items():
            (folder / file).write_text(textwrap.dedent(text).lstrip())
        dists.append(str(folder))
    site = root / "site"
    res = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation",
                          "--disable-pip-version-check", "--no-input", "--target", str(site), *dists],
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stdout + res.stderr
    assert list(site.glob("breastplan_scale_plugin-*.dist-info"))
    return site


def with_plugins(site):
    """The environment of a process that finds the plugins installed in `site`."""
    paths = [str(site)] + ([os.environ["PYTHONPATH"]] if os.environ.get("PYTHONPATH") else [])
    return {**os.environ, "PYTHONPATH": os.pathsep.join(paths)}


def run_with(env, *args):
    return subprocess.run([str(a) for a in args], capture_output=True, text=True, timeout=600, env=env)


def test_an_installed_plugin_is_listed_and_a_broken_one_only_warns(cli, plugin_site):
    res = run_with(with_plugins(plugin_site), cli, "filters", "--json")
    assert res.returncode == 0, res.stderr
    listed = {f["name"]: f for f in json.loads(res.stdout)["filters"]}
    assert set(BUILTINS) | {"scale_mesh", "shifted", "count_points"} <= set(listed)
    scale = listed["scale_mesh"]
    assert scale["parameters"] == [{"name": "factor", "type": "float", "default": 2.0, "choices": None}]
    assert scale["description"] == "Scale a mesh about the origin."
    assert "breastplan-scale-plugin" in scale["source"]
    assert listed["shifted"]["parameters"][0]["name"] == "dx"             # a plain function: its entry point's name
    assert listed["count_points"]["returns"] == "measures"                 # registered by importing its module
    warning = [line for line in res.stderr.splitlines() if line.startswith("warning:")]
    assert len(warning) == 1, res.stderr
    assert "broken" in warning[0] and "RuntimeError" in warning[0] and "not installed" in warning[0]
    assert "Traceback" not in res.stderr

    res = run_with(with_plugins(plugin_site), cli, "filters")                # the table, too
    assert res.returncode == 0 and "scale_mesh" in res.stdout and "factor: float = 2.0" in res.stdout


def test_a_plugin_filter_runs_on_a_scan_file(cli, scan, plugin_site, tmp_path):
    path, _ = scan
    out = tmp_path / "scaled.ply"
    res = run_with(with_plugins(plugin_site), cli, "filter", "scale_mesh", path, "--param", "factor=3", "--out", out,
                   "--json")
    assert res.returncode == 0, res.stderr
    assert np.allclose(read_ply(out).points, 3.0 * read_ply(path).points)
    res = run_with(with_plugins(plugin_site), cli, "filter", "count_points", path, "--json")
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["result"] == {"points": len(read_ply(path).points)}
    res = run_with(with_plugins(plugin_site), cli, "filter", "scale_mesh", path, "--param", "factor=big", "--out", out)
    assert res.returncode == 2 and "factor='big' is not a finite number" in " ".join(res.stderr.split())


def test_a_refusal_is_one_sentence_though_numpy_warned_on_the_way(cli, scan, plugin_site, tmp_path):
    path, _ = scan
    flat = tmp_path / "flat.ply"
    write_ply(flat, read_ply(path).points * [1.0, 1.0, 0.0])                # every z is 0: log gives -inf
    res = run_with(with_plugins(plugin_site), cli, "filter", "log_depth", flat, "--out", tmp_path / "log.ply")
    said = [line for line in res.stderr.splitlines() if "plugin broken" not in line]     # the broken one is listed
    assert res.returncode == 3 and len(said) == 1 and "log_depth" in said[0], res.stderr
    assert not (tmp_path / "log.ply").exists()


def test_the_meshlab_bridge_offers_plugin_filters(plugin_site):
    code = textwrap.dedent("""
        import json, numpy as np, pymeshlab
        from breastplan import meshlab
        ms = pymeshlab.MeshSet()
        ms.add_mesh(pymeshlab.Mesh(np.eye(3)), mesh_name="three")
        meshlab.scale_mesh(ms, factor=4)
        print(json.dumps({"listed": "scale_mesh" in dir(meshlab), "meshes": ms.mesh_number(),
                          "current": ms.current_mesh().label(), "vertices": ms.current_mesh().vertex_matrix().tolist(),
                          "count": meshlab.count_points(ms)}))
        """)
    res = run_with(with_plugins(plugin_site), sys.executable, "-c", code)
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout.strip().splitlines()[-1])
    assert out == {"listed": True, "meshes": 2, "current": "scale_mesh", "vertices": (4 * np.eye(3)).tolist(),
                   "count": {"points": 3}}


def test_a_plugin_filter_that_fails_or_lies_about_its_result_is_said_not_written():
    """Truth: a filter's result is what it declares (a Mesh or a dict), with finite vertices; a plugin
    that breaks this or raises is named with its source in one sentence — a built-in's bug still raises."""
    def nan_mesh(mesh: Mesh) -> Mesh:
        return Mesh(mesh.vertices * np.nan)

    def liar(mesh: Mesh) -> Mesh:
        return {"points": len(mesh.vertices)}

    def raiser(mesh: Mesh) -> dict:
        raise ValueError("k must be even")

    points = np.random.default_rng(0).normal(size=(50, 3))
    for function, problem in ((nan_mesh, "returned a mesh with NaN or infinite vertices"),
                              (liar, "returned dict, not the Mesh it declares"),
                              (raiser, "failed (ValueError: k must be even)")):
        with pytest.raises(BadInputError, match=f"filter {function.__name__} \\(from clinic 1.0\\) "
                                                + re.escape(problem)):
            Filter(function.__name__, function, source="clinic 1.0")(points)
    with pytest.raises(ValueError, match="k must be even"):
        Filter("raiser", raiser)(points)
