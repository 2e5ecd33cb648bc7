"""Her skin as the report draws it: one surface without holes where her body was seen, from a recording's one view
or from a scan file's points (which need not be one view's)."""
import numpy as np
import pytest
from scipy import ndimage

from breastplan.options import PlanOptions
from breastplan.plan import views as views_module
from breastplan.plan.job import run_plan
from breastplan.plan.pictures import before_after
from breastplan.plan.views import build_views
from breastplan.scenes.makehuman import BodyOptions
from breastplan.scenes.realistic import CameraOptions, make_body_scene, write_scan_file


def holes(picture) -> tuple[float, int]:
    """(share of her drawn pixels, count) of the background seen through her: background pixels (near white) that
    the picture's border does not reach through background."""
    rgb = np.asarray(picture.convert("RGB")).astype(int)
    background = rgb.min(axis=2) > 245
    labels, _ = ndimage.label(background)
    outside = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    inside = background & ~np.isin(labels, outside)
    return float(inside.sum() / max((~background).sum(), 1)), int(inside.sum())


@pytest.fixture(scope="module")
def scan_files(tmp_path_factory):
    """One MakeHuman patient written as a scanner's textured mesh (OBJ) and as a PLY of depth pixels."""
    folder = tmp_path_factory.mktemp("surface")
    scene = make_body_scene(BodyOptions(cup=0.9, firmness=0.3, weight=0.6, pose="a-pose"),
                            CameraOptions(680.0, 6.0, -5.0, wall_mm=None))
    files = {suffix: folder / f"her{suffix}" for suffix in (".obj", ".ply")}
    for path in files.values():
        write_scan_file(path, scene, "mm", "+y")
    return files


@pytest.mark.parametrize("suffix", [".obj", ".ply"])
def test_her_skin_from_a_scan_file_shows_no_background_through_her(scan_files, tmp_path, suffix, monkeypatch):
    plan = run_plan(scan_files[suffix], tmp_path / "case", PlanOptions.parse(["ptosis:3"]))
    views = build_views(plan)
    for name, (before, after) in before_after(views, views.states[0]).items():
        for drawn in (before, after):
            share, pixels = holes(drawn)
            assert share < 0.005, (name, share, pixels)
    if suffix == ".obj":
        assert np.array_equal(build_views(plan).skin, views.skin)          # the same surface every time
        # one view's triangulation would leave holes in a scanner's mesh
        monkeypatch.setattr(views_module, "surface_triangles", views_module.skin_triangles)
        before, _ = before_after(build_views(plan), views.states[0], names=("front",))["front"]
        assert holes(before)[0] > 0.01
