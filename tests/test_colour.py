"""Her own colour: recorded beside depth or in a scan file, kept by ingest on her torso, drawn by the plan."""
import json
import tempfile
from pathlib import Path

import numpy as np
import open3d as o3d
import pytest

from breastplan import read_ply, transform_points, write_ply
from breastplan.ingest.files import read_scan_arrays, read_scan_file, scan_cloud
from breastplan.ingest.recording import read_recording, write_recording
from breastplan.scenes.makehuman import BodyOptions
from breastplan.scenes.realistic import CameraOptions, file_from_body, make_body_scene, write_scan_file
from breastplan.scenes.rendering import AREOLA_RGB, SKIN_RGB

from clitools import run
from gltf import write_glb

K = np.array([[500.0, 0.0, 32.0], [0.0, 500.0, 24.0], [0.0, 0.0, 1.0]])


def test_a_ply_keeps_its_colours_as_open3d_reads_them(tmp_path):
    rng = np.random.default_rng(0)
    points, colours = rng.normal(size=(50, 3)), rng.integers(0, 256, (50, 3)).astype(np.uint8)
    write_ply(tmp_path / "c.ply", points, colours=colours)
    assert np.array_equal(read_ply(tmp_path / "c.ply").colours, colours)
    theirs = o3d.io.read_point_cloud(str(tmp_path / "c.ply"))              # a second reader
    assert np.allclose(np.asarray(theirs.colors) * 255, colours)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))   # a second writer: colours as 0..1
    cloud.colors = o3d.utility.Vector3dVector(colours / 255.0)
    o3d.io.write_point_cloud(str(tmp_path / "o3d.ply"), cloud)
    assert np.array_equal(read_ply(tmp_path / "o3d.ply").colours, colours)
    assert read_ply(write_ply(tmp_path / "plain.ply", points)).colours is None


def test_a_recording_keeps_the_colour_aligned_to_its_depth(tmp_path):
    depth = np.full((3, 48, 64), 700, np.uint16)
    colour = np.zeros((48, 64, 3), np.uint8)
    colour[..., 0], colour[10:20, 30:40] = 200, (90, 50, 40)
    frames = read_recording(write_recording(tmp_path / "c.mcap", depth, K, colour=colour))
    assert np.array_equal(frames.colour, colour) and "1 colour frame" in frames.source
    noisy = np.stack([colour, colour, colour]).astype(int) + [[[[0]]], [[[6]]], [[[-6]]]]   # one per depth frame
    frames = read_recording(write_recording(tmp_path / "n.mcap", depth, K, colour=noisy.clip(0, 255)))
    assert np.array_equal(frames.colour, colour)                            # their median
    assert read_recording(write_recording(tmp_path / "d.mcap", depth, K)).colour is None
    other = read_recording(write_recording(tmp_path / "o.mcap", depth, K, colour=np.zeros((24, 32, 3), np.uint8)))
    assert other.colour is None and "colour frames not aligned to depth or damaged (not used)" in other.source


@pytest.fixture(scope="module")
def patient(cli, tmp_path_factory):
    """A MakeHuman patient recorded with colour (`scan-synth`), and her plan."""
    folder = tmp_path_factory.mktemp("colour")
    res = run(cli, "scan-synth", "--body", "makehuman", "--cup", "0.8", "--pose", "arms-down", "--yaw", "-5",
              "--frames", "4", "--out", folder / "her.mcap", "--truth", folder / "truth.npz", "--json")
    assert res.returncode == 0, res.stderr
    nipples = {s: np.array(p) for s, p in json.loads(res.stdout)["nipples_camera_mm"].items()}
    res = run(cli, "plan", folder / "her.mcap", "--out", folder / "case")
    assert res.returncode == 0, res.stderr
    return folder, nipples


def _dark(rgb) -> bool:
    """Of the areola's hue rather than the skin's (green over red: light and shade scale both alike)."""
    rgb = np.asarray(rgb, float)
    areola, skin = (np.asarray(c, float) for c in (AREOLA_RGB, SKIN_RGB))
    return rgb[1] / rgb[0] < 0.5 * (areola[1] / areola[0] + skin[1] / skin[0])


def test_scan_synth_records_her_skin_and_darker_areolae(patient):
    folder, nipples = patient
    frames = read_recording(folder / "her.mcap")
    for nipple in nipples.values():
        for offset, dark in (((0, 0, 0), True), ((0, 60, 0), False), ((0, -60, 0), False)):   # y: down
            p = nipple + offset
            u, v = np.rint(frames.K[:2, :2] @ (p[:2] / p[2]) + frames.K[:2, 2]).astype(int)
            assert _dark(frames.colour[v, u]) == dark, (nipple, offset, frames.colour[v, u])


def test_ingest_keeps_her_colour_on_the_torso_and_the_report_draws_it(patient):
    folder, nipples = patient
    for side in ("left", "right"):
        torso = read_ply(folder / "case" / side / "camera.ply")
        assert torso.colours is not None and len(torso.colours) == len(torso.points)
        for offset, dark in (((0, 0, 0), True), ((0, 60, 0), False), ((40, -40, 0), False)):
            near = np.linalg.norm(torso.points - (nipples[side] + offset), axis=1).argsort()[:5]
            assert all(_dark(c) == dark for c in torso.colours[near]), (side, offset, torso.colours[near])
    page = (folder / "case" / "report.html").read_text()
    assert '"skin_vertex_rgb"' in page and '"skin_rgb"' not in page


def test_a_mesh_samples_its_vertices_colours():
    square = np.array([[0, 0, 0], [100, 0, 0], [100, 100, 0], [0, 100, 0]], float)
    points = np.vstack([square, square + [300.0, 0, 0]])
    faces = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    colours = np.repeat(np.array([[200, 30, 30], [30, 30, 200]], np.uint8), 4, axis=0)   # a red, a blue square
    cloud = scan_cloud(points, faces, units="mm", colours=colours)
    red = cloud.points[:, 0] < 200
    assert red.any() and (~red).any() and "in colour" in cloud.description
    assert (cloud.colours[red] == [200, 30, 30]).all() and (cloud.colours[~red] == [30, 30, 200]).all()


def _atlas_obj(folder, colours: np.ndarray) -> tuple:
    """An OBJ of a grid of vertices, each textured by a pixel of its own in a PNG holding its colour (an
    atlas: every vertex's texture coordinate at its pixel's centre), and its material file."""
    from PIL import Image

    n = len(colours)
    side = int(np.ceil(np.sqrt(n)))
    row, col = np.divmod(np.arange(n), side)
    image = np.zeros((side, side, 3), np.uint8)
    image[row, col] = colours
    Image.fromarray(image).save(folder / "atlas.png")
    (folder / "atlas.mtl").write_text("newmtl skin\nmap_Kd atlas.png\n")
    grid = np.column_stack([col * 10.0, row * 10.0, np.zeros(n)])
    uv = np.column_stack([(col + 0.5) / side, 1.0 - (row + 0.5) / side])
    quads = [(r * side + c, r * side + c + 1, (r + 1) * side + c + 1, (r + 1) * side + c)
             for r in range(side - 1) for c in range(side - 1) if (r + 1) * side + c + 1 < n]
    faces = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    lines = (["mtllib atlas.mtl"] + [f"v {x:g} {y:g} {z:g}" for x, y, z in grid]
             + [f"vt {u:.8f} {v:.8f}" for u, v in uv] + ["usemtl skin"]
             + [f"f {a}/{a} {b}/{b} {c}/{c}" for a, b, c in faces + 1])
    (folder / "atlas.obj").write_text("\n".join(lines) + "\n")
    return folder / "atlas.obj", grid, faces


def test_an_obj_takes_its_colours_from_its_texture_image(tmp_path):
    """Each vertex's colour is the texture's pixel at its texture coordinate (its own pixel in an atlas)."""
    colours = np.random.default_rng(1).integers(0, 256, (60, 3)).astype(np.uint8)
    obj, grid, faces = _atlas_obj(tmp_path, colours)
    read = read_scan_arrays(obj)
    which = {tuple(p): i for i, p in enumerate(grid)}
    order = [which[tuple(p)] for p in read.points]                # its reader may order the vertices its own way
    assert sorted(order) == list(range(len(grid))) and len(read.faces) == len(faces) and read.note == ""
    assert np.array_equal(read.colours, colours[order])
    (tmp_path / "atlas.png").unlink()                              # the image not copied with it
    cloud = read_scan_file(obj, units="mm")
    assert cloud.colours is None and "its texture image not readable beside it (not used)" in cloud.description


def test_a_glb_takes_its_colours_from_its_embedded_texture_or_its_vertices(tmp_path):
    """A phone app's GLB: each vertex's colour is its embedded image's pixel at its texture coordinate (glTF's
    (0, 0) the image's top left), or its COLOR_0."""
    colours = np.random.default_rng(2).integers(0, 256, (60, 3)).astype(np.uint8)
    _, grid, faces = _atlas_obj(tmp_path, colours)
    side = int(np.ceil(np.sqrt(len(colours))))
    row, col = np.divmod(np.arange(len(colours)), side)
    image = np.zeros((side, side, 3), np.uint8)
    image[row, col] = colours
    uv = np.column_stack([(col + 0.5) / side, (row + 0.5) / side])
    write_glb(tmp_path / "atlas.glb", grid, faces, uv=uv, image=image)
    write_glb(tmp_path / "coloured.glb", grid, faces, colours=colours / 255.0)
    for name in ("atlas.glb", "coloured.glb"):
        read = read_scan_arrays(tmp_path / name)
        which = {tuple(p): i for i, p in enumerate(grid)}
        order = [which[tuple(p)] for p in read.points.astype(np.float32).astype(float)]
        assert sorted(order) == list(range(len(grid))) and len(read.faces) == len(faces) and read.note == "", name
        assert np.array_equal(read.colours, colours[order]), name


def test_an_obj_keeps_its_vertex_colours():
    """OBJ's common extension, `v x y z r g b` (0..1), for triangle and polygon meshes alike."""
    with tempfile.TemporaryDirectory() as folder:
        for face in ("f 1 2 3\nf 1 3 4", "f 1 2 3 4"):
            path = Path(folder) / "c.obj"
            path.write_text("v 0 0 0 1 0 0\nv 100 0 0 0 1 0\nv 100 100 0 0 0 1\nv 0 100 0 0.2 0.2 0.2\n" + face + "\n")
            assert read_scan_arrays(path).colours.tolist() == [[255, 0, 0], [0, 255, 0], [0, 0, 255], [51, 51, 51]]


def test_a_scan_files_colour_is_kept_on_her_torso(cli, tmp_path):
    """A PLY with the colour seen at each point (a textured OBJ's: `test_skin_surface`)."""
    scene = make_body_scene(BodyOptions(cup=0.8, weight=0.6, pose="hands-on-hips"),
                            CameraOptions(680.0, 4.0, 6.0, wall_mm=None))
    write_scan_file(tmp_path / "her.ply", scene, "mm", "+z")
    to_file = file_from_body("+z", "mm") @ np.linalg.inv(scene.camera_from_body)
    write_scan_file(tmp_path / "her.glb", scene, "mm", "+z")                  # her visible triangles, coloured
    glb = read_scan_file(tmp_path / "her.glb", units="mm")
    for side in ("left", "right"):
        nipple = transform_points(to_file, scene.nipples_camera()[side])
        for offset, dark in ((np.zeros(3), True), (to_file[:3, :3] @ [0.0, 60.0, 0.0], False)):
            near = np.linalg.norm(glb.points - (nipple + offset), axis=1).argsort()[:5]
            assert all(_dark(c) == dark for c in glb.colours[near]), (side, offset, glb.colours[near])
    res = run(cli, "ingest", tmp_path / "her.ply", "--side", "right", "--up", "+z", "--out", tmp_path / "right")
    assert res.returncode == 0, res.stderr
    torso = read_ply(tmp_path / "right" / "camera.ply")
    nipple = transform_points(to_file, scene.nipples_camera()["right"])
    down = to_file[:3, :3] @ [0.0, 60.0, 0.0]                                 # 60 mm down her front
    for offset, dark in ((np.zeros(3), True), (down, False)):
        near = np.linalg.norm(torso.points - (nipple + offset), axis=1).argsort()[:5]
        assert all(_dark(c) == dark for c in torso.colours[near]), (offset, torso.colours[near])
