"""The pymeshlab bridge (meshlab/): breastplan's filters on a pymeshlab MeshSet, pymeshlab-style, and the
example that runs them after a screened Poisson reconstruction (examples/meshlab_pipeline.py).

Truths: MakeHuman's nipple rings and the half-body volumes of the scanned body, and pymeshlab's own
measures of the meshes the filters add (their volume, their closedness)."""
import inspect
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pymeshlab
import pytest

from breastplan import BadInputError, write_ply
from breastplan import meshlab
from breastplan.filters import ParameterError, filters
from breastplan.scenes.makehuman import BodyOptions, make_body
from breastplan.scenes.realistic import CameraOptions, make_body_scene, write_scan_file

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "meshlab_pipeline.py"
NIPPLE_MM = 8.0
"""The nipple tolerance of the isolation tests (tests/test_realistic.py)."""
VOLUME_FACTOR = 1.6
"""As in tests/test_filters.py (1.5 there): the fitted volume and the volume the cup adds to her half body
measure the breast only roughly alike (the cup target also thickens the chest around the breast, and a cup of
0 keeps a small mound). Here the breast is fitted on points drawn from a Poisson surface, and the fitted
model moves with the draw: four seeds of the same surface's draw fitted it at 164–187 cc, 1.36–1.56 times
what the cup adds."""


@pytest.fixture(scope="module")
def scan(tmp_path_factory):
    """A realistic scan file (MakeHuman body of average build, A-pose, no wall; mm, up +y: her body
    frame) and her body."""
    scene = make_body_scene(BodyOptions(), CameraOptions(wall_mm=None))
    path = tmp_path_factory.mktemp("scan") / "body.ply"
    write_scan_file(path, scene, units="mm", up="+y")
    return path, scene.body


def edges_shared_twice(faces) -> bool:
    """Whether every edge of a triangle mesh borders exactly two triangles (a closed surface)."""
    f = np.asarray(faces)
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return bool((counts == 2).all())


def test_every_builtin_filter_is_a_function_of_the_module_with_its_parameters():
    for f in filters(plugins=False):
        bridged = meshlab.__dict__[f.name]                         # a real attribute, not __getattr__'s
        params = inspect.signature(bridged).parameters
        assert list(params) == ["ms"] + [p.name for p in f.parameters]
        assert all(params[p.name].default == p.default for p in f.parameters)
        assert f.name in dir(meshlab)
    with pytest.raises(AttributeError, match="no filter of that name"):
        meshlab.compute_breast_fitt


def test_the_names_no_filter_may_take_are_the_modules_own_functions():
    from breastplan.filters.registry import BRIDGE_NAMES

    names = {f.name for f in filters(plugins=False)}
    own = {n for n, v in vars(meshlab).items() if not n.startswith("_") and callable(v) and n not in names}
    assert own == BRIDGE_NAMES


def test_the_filters_add_meshes_to_the_meshset_and_measures_come_back_as_a_dict(scan):
    path, body = scan
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(path))
    scan_points = ms.current_mesh().vertex_matrix().copy()

    assert meshlab.compute_breast_isolation(ms, side="right") is None
    assert ms.mesh_number() == 2 and ms.current_mesh().label() == "compute_breast_isolation"
    breast = ms.current_mesh()
    assert breast.is_point_cloud() and breast.vertex_number() > 500
    assert np.linalg.norm(breast.vertex_matrix() - body.nipples["right"], axis=1).min() <= 3.0

    assert meshlab.compute_breast_fit(ms) is None                  # on the isolated breast: its side, right
    fit_id = ms.current_mesh_id()
    assert ms.mesh_number() == 3 and ms.current_mesh().label() == "compute_breast_fit"
    fit = ms.current_mesh()
    assert fit.face_number() > 1000 and edges_shared_twice(fit.face_matrix())
    fit_volume_mm3 = ms.get_geometric_measures()["mesh_volume"]    # pymeshlab's own measure

    measures = meshlab.get_breast_measures(ms)
    assert isinstance(measures, dict) and ms.mesh_number() == 3     # a dict, no mesh added
    assert measures["side"] == "right"
    assert measures["volume_cc"] == pytest.approx(fit_volume_mm3 / 1000.0, rel=1e-3)
    assert np.linalg.norm(measures["nipple_mm"] - body.nipples["right"]) <= NIPPLE_MM
    added = body.half_volumes_cc()["right"] - make_body(BodyOptions(cup=0.0)).half_volumes_cc()["right"]
    assert added / VOLUME_FACTOR <= measures["volume_cc"] <= added * VOLUME_FACTOR

    meshlab.apply_breast_ptosis(ms, degree=5)
    assert ms.mesh_number() == 4 and ms.current_mesh().label() == "apply_breast_ptosis"
    assert np.array_equal(ms.current_mesh().face_matrix(), ms.mesh(fit_id).face_matrix())
    after = meshlab.get_breast_measures(ms)
    assert [(c["kind"], c["degree"]) for c in after["changes"]] == [("ptosis", 5.0)]
    assert after["nipple_mm"][1] < measures["nipple_mm"][1] - 1.0   # lower along her up axis, Y
    assert after["volume_cc"] == pytest.approx(measures["volume_cc"], rel=0.01)   # a shear keeps the volume

    assert np.array_equal(ms.mesh(0).vertex_matrix(), scan_points)   # the scan itself is untouched


def test_a_bad_parameter_is_refused_before_any_work_and_adds_no_mesh(scan):
    path, _ = scan
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(path))
    for call, words in ((lambda: meshlab.apply_breast_ptosis(ms, degree=0), "degree=0 lies outside 1..8"),
                        (lambda: meshlab.compute_breast_fit(ms, lattice=2), "lattice"),
                        (lambda: meshlab.get_breast_measures(ms, sides="left"), "did you mean side")):
        with pytest.raises(ParameterError, match=words):
            call()
    assert ms.mesh_number() == 1
    with pytest.raises(TypeError, match="MeshSet"):
        meshlab.compute_breast_fit(path)


def test_bad_geometry_is_bad_input_naming_the_mesh(tmp_path):
    ms = pymeshlab.MeshSet()
    with pytest.raises(BadInputError, match="holds no mesh"):
        meshlab.get_breast_measures(ms)
    x, y = np.meshgrid(np.arange(-300.0, 300.0, 4.0), np.arange(-200.0, 200.0, 4.0))
    board = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    ms.load_new_mesh(str(write_ply(tmp_path / "board.ply", board)))
    with pytest.raises(BadInputError, match=r"^mesh 'board.ply': .*(trunk|breast)") as caught:
        meshlab.compute_breast_fit(ms)
    assert "\n" not in str(caught.value) and ms.mesh_number() == 1


def test_the_example_reconstructs_fits_measures_and_compares(tmp_path):
    """Run the example as a user would, its default scan made in a private temporary folder."""
    env = {**os.environ, "TMPDIR": str(tmp_path)}
    res = subprocess.run([sys.executable, str(EXAMPLE), "--json"], capture_output=True, text=True, timeout=600,
                         env=env)
    assert res.returncode == 0, res.stderr[-3000:]
    out = json.loads(res.stdout)
    assert Path(out["scan"]).parent.parent == tmp_path
    assert out["poisson"]["faces"] > 10_000 and out["breast_points"] > 500
    assert out["nipple_error_mm"] <= NIPPLE_MM                      # against MakeHuman's nipple ring
    body = make_body(BodyOptions())
    added = body.half_volumes_cc()["left"] - make_body(BodyOptions(cup=0.0)).half_volumes_cc()["left"]
    assert added / VOLUME_FACTOR <= out["measures"]["volume_cc"] <= added * VOLUME_FACTOR
    h = out["hausdorff"]
    assert h["breast points → fit"]["mean_mm"] < 2.0                # the fit holds the breast's points
    assert h["fit → scan"]["mean_mm"] < 5.0
    assert 0.0 < h["ptosis-3 → fit"]["mean_mm"] < h["ptosis-3 → fit"]["max_mm"] < 20.0
    assert out["ptosis"]["nipple_drop_mm"] > 0.5                    # a ptosis lowers the nipple

    sys.path.insert(0, str(EXAMPLE.parent))                        # and its table prints what it found
    try:
        import meshlab_pipeline
    finally:
        sys.path.remove(str(EXAMPLE.parent))
    from io import StringIO
    from contextlib import redirect_stdout

    text = StringIO()
    with redirect_stdout(text):
        meshlab_pipeline.print_table(out)
    lines = text.getvalue().splitlines()
    assert any(line.startswith("volume_cc") and f"{out['measures']['volume_cc']:.4g}" in line for line in lines)
    assert sum(line.startswith(("breast points", "fit → scan", "ptosis-3")) for line in lines) == 3
