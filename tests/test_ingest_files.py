"""Scan files → mm point clouds (ingest/files.py): formats, surface sampling, units, bad input."""
import json

import numpy as np
import open3d as o3d
import pytest

from breastplan import BadInputError, write_ply
from breastplan.ingest.files import read_scan_arrays, read_scan_file

from gltf import write_glb

SPHERE_AREA_MM2 = 4 * np.pi * 100.0**2


def sphere_m():
    """A tessellated sphere of radius 0.1 m (100 mm) centred on the origin."""
    return o3d.geometry.TriangleMesh.create_sphere(radius=0.1)


def save_mesh(path, mesh):
    if path.suffix == ".ply":
        write_ply(path, np.asarray(mesh.vertices), faces=np.asarray(mesh.triangles))
    else:
        mesh.compute_triangle_normals()  # open3d's STL writer refuses a mesh without them
        assert o3d.io.write_triangle_mesh(str(path), mesh)
    return path


def write_stl(path, triangles):
    """Binary STL of (M, 3, 3) triangles, by hand (to put NaN in it)."""
    rec = np.zeros(len(triangles), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    rec["v"] = triangles
    path.write_bytes(b"\0" * 80 + np.uint32(len(triangles)).tobytes() + rec.tobytes())
    return path


def write_pcd(path, points, normals=None):
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, float)))
    if normals is not None:
        cloud.normals = o3d.utility.Vector3dVector(np.asarray(normals, float))
    assert o3d.io.write_point_cloud(str(path), cloud)
    return path


def grid_points_mm(n=8):
    """n³ points on a 0..200 mm grid (extent 200: millimetres)."""
    g = np.linspace(0.0, 200.0, n)
    return np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)


# --- meshes: sampled by area, in mm -------------------------------------------------------

@pytest.mark.parametrize("ext", [".stl", ".obj", ".ply", ".glb"])
def test_sphere_in_metres_comes_back_in_mm_on_its_surface(tmp_path, ext):
    scan = read_scan_file(save_mesh(tmp_path / f"sphere{ext}", sphere_m()))
    r = np.linalg.norm(scan.points, axis=1)
    assert r.max() <= 100.0 + 1e-6 and r.min() > 98.0          # inscribed polyhedron of a 100 mm sphere
    assert abs(len(scan.points) - SPHERE_AREA_MM2) < 0.01 * SPHERE_AREA_MM2   # ~1 point per mm²
    assert np.allclose(np.linalg.norm(scan.normals, axis=1), 1.0)
    assert (np.einsum("ij,ij->i", scan.normals, scan.points / r[:, None]) > 0.95).all()  # outward
    assert scan.points.dtype == np.float64 and scan.points.shape[1] == 3
    assert scan.frame_hint is None
    assert f"sphere{ext}" in scan.description and "units m" in scan.description


def test_a_gltf_of_several_nodes_is_read_as_one_mesh_each_node_in_its_place(tmp_path):
    """A phone app's glTF may hold a scan in pieces, one node each with its own translation."""
    square = np.array([[0, 0, 0], [100, 0, 0], [0, 100, 0], [100, 100, 0]], float)
    write_glb(tmp_path / "two.glb", square, [[0, 1, 2], [1, 3, 2]], places=((0, 0, 0), (300, 0, 0)))
    read = read_scan_arrays(tmp_path / "two.glb")
    assert len(read.points) == 8 and len(read.faces) == 4
    assert sorted(map(tuple, read.points.round(3))) == sorted(map(tuple, np.vstack([square, square + [300, 0, 0]])))


def test_box_points_lie_on_its_faces_with_face_normals(tmp_path):
    size = np.array([100.0, 200.0, 300.0])  # mm; area 220 000 mm²
    box = o3d.geometry.TriangleMesh.create_box(*(size / 1000))
    scan = read_scan_file(save_mesh(tmp_path / "box.stl", box))
    assert len(scan.points) == 2 * (100 * 200 + 200 * 300 + 300 * 100)
    p, n = scan.points, scan.normals
    tol = 1e-4  # STL stores float32: 0.3 m comes back as 300.00001 mm
    assert (p >= -tol).all() and (p <= size + tol).all()
    gap = np.minimum(np.abs(p), np.abs(size - p))                # distance to each pair of face planes
    assert np.allclose(gap.min(axis=1), 0.0, atol=tol)
    axis = gap.argmin(axis=1)                                     # the face each point is on
    side = np.where(np.abs(p[np.arange(len(p)), axis]) < tol, -1.0, 1.0)
    expected = np.zeros_like(n)
    expected[np.arange(len(p)), axis] = side
    assert np.allclose(n, expected, atol=1e-6)


@pytest.mark.parametrize("side_m, expected", [(0.05, 20_000), (0.1, 60_000), (1.0, 400_000)])
def test_sample_count_is_area_in_mm2_clamped(tmp_path, side_m, expected):
    cube = o3d.geometry.TriangleMesh.create_box(side_m, side_m, side_m)
    scan = read_scan_file(save_mesh(tmp_path / "cube.obj", cube))
    assert len(scan.points) == expected  # 6 side² mm², within [20 000, 400 000]


def test_sampling_is_deterministic(tmp_path):
    path = save_mesh(tmp_path / "sphere.stl", sphere_m())
    assert np.array_equal(read_scan_file(path).points, read_scan_file(path).points)


def test_quad_obj_is_triangulated_not_dropped(tmp_path):
    """open3d drops non-triangle OBJ faces; a 100 mm cube of quads must keep all 6 faces."""
    v = np.array([[x, y, z] for x in (0, 100) for y in (0, 100) for z in (0, 100)], float)
    quads = [[1, 2, 4, 3], [5, 7, 8, 6], [1, 5, 6, 2], [3, 4, 8, 7], [1, 3, 7, 5], [2, 6, 8, 4]]
    text = "".join(f"v {a} {b} {c}\n" for a, b, c in v)
    text += "".join(f"f {' '.join(map(str, q))}\n" for q in quads)
    (tmp_path / "cube.obj").write_text(text)
    scan = read_scan_file(tmp_path / "cube.obj")
    assert len(scan.points) == 60_000 and "units mm" in scan.description
    gap = np.minimum(np.abs(scan.points), np.abs(100.0 - scan.points)).min(axis=1)
    assert np.allclose(gap, 0.0, atol=1e-6)
    assert (np.abs(scan.points - 50.0).max(axis=0) > 49.9).all()  # points reach every face


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
def test_a_ply_of_triangles_and_quads_is_read_whole_and_a_truncated_one_refused(tmp_path, fmt):
    """Scanners export PLY meshes of mixed triangles and quads: a 100 mm cube of 3 quads and 6 triangles
    (the other 3 quads split) keeps all 6 of its faces; cut short, it is refused as truncated."""
    v = np.array([[x, y, z] for x in (0, 100) for y in (0, 100) for z in (0, 100)], float)
    quads = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1]]
    triangles = [[2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    header = (f"ply\nformat {fmt} 1.0\nelement vertex 8\nproperty double x\nproperty double y\nproperty double z\n"
              "element face 9\nproperty list uchar int vertex_indices\nend_header\n").encode()
    if fmt == "ascii":
        body = "".join(f"{a} {b} {c}\n" for a, b, c in v) + "".join(f"{len(f)} {' '.join(map(str, f))}\n"
                                                                   for f in quads + triangles)
        body = body.encode()
    else:
        body = v.astype("<f8").tobytes() + b"".join(np.uint8(len(f)).tobytes() + np.array(f, "<i4").tobytes()
                                                    for f in quads + triangles)
    (tmp_path / "cube.ply").write_bytes(header + body)
    scan = read_scan_file(tmp_path / "cube.ply")
    gap = np.minimum(np.abs(scan.points), np.abs(100.0 - scan.points)).min(axis=1)
    assert np.allclose(gap, 0.0, atol=1e-6)
    assert (np.abs(scan.points - 50.0).max(axis=0) > 49.9).all()          # points reach every face
    for axis in range(3):                                                   # and cover each face alike
        low = np.isclose(scan.points[:, axis], 0.0).mean()
        assert 1 / 6 - 0.02 < low < 1 / 6 + 0.02
    (tmp_path / "cut.ply").write_bytes(header + body[:-9])
    with pytest.raises(BadInputError, match="cut.ply: is truncated"):
        read_scan_file(tmp_path / "cut.ply")


# --- point files: points and normals kept ----------------------------------------------------

def test_pcd_round_trip_with_and_without_normals(tmp_path):
    pts = grid_points_mm()
    nrm = pts - 100.0
    nrm[np.all(nrm == 0, axis=1)] = [0, 0, 1]
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    plain = read_scan_file(write_pcd(tmp_path / "plain.pcd", pts))
    assert np.allclose(plain.points, pts, atol=1e-4) and plain.normals is None
    with_n = read_scan_file(write_pcd(tmp_path / "normals.pcd", pts, nrm))
    assert np.allclose(with_n.points, pts, atol=1e-4) and np.allclose(with_n.normals, nrm, atol=1e-6)
    assert "512 points with normals" in with_n.description


def test_xyz_round_trip_and_metres(tmp_path):
    pts = grid_points_mm()
    np.savetxt(tmp_path / "mm.xyz", pts)
    assert np.array_equal(read_scan_file(tmp_path / "mm.xyz").points, pts)
    np.savetxt(tmp_path / "m.xyz", pts / 1000.0, header="x y z in metres")
    scan = read_scan_file(tmp_path / "m.xyz")
    assert np.allclose(scan.points, pts, atol=1e-9) and scan.normals is None
    nrm = np.tile([0.0, 0.6, 0.8], (len(pts), 1))
    np.savetxt(tmp_path / "n.xyz", np.hstack([pts, nrm]))
    scan = read_scan_file(tmp_path / "n.xyz")
    assert np.array_equal(scan.points, pts) and np.allclose(scan.normals, nrm)
    (tmp_path / "bom.xyz").write_bytes(b"\xef\xbb\xbf" + (tmp_path / "mm.xyz").read_bytes())   # Windows' UTF-8
    assert np.array_equal(read_scan_file(tmp_path / "bom.xyz").points, pts)


def test_an_obj_of_indented_lines_is_read_as_the_same_mesh(tmp_path):
    """OBJ lines may start with blanks; open3d drops such faces, which must not drop the surface."""
    save_mesh(tmp_path / "plain.obj", sphere_m())
    text = (tmp_path / "plain.obj").read_text()
    (tmp_path / "indented.obj").write_text("".join("  " + line for line in text.splitlines(keepends=True)))
    plain, indented = (read_scan_file(tmp_path / name) for name in ("plain.obj", "indented.obj"))
    assert np.array_equal(indented.points, plain.points)                  # the same surface, sampled alike


def test_ply_points_normals_and_camera_frame_hint(tmp_path):
    pts = grid_points_mm()
    nrm = np.tile([1.0, 0.0, 0.0], (len(pts), 1))
    comments = ["breastplan scan", "frame camera-opencv"]
    path = write_ply(tmp_path / "cam.ply", pts, normals=nrm, comments=comments)
    scan = read_scan_file(path)
    assert scan.frame_hint == "camera-opencv"
    assert np.array_equal(scan.points, pts) and np.array_equal(scan.normals, nrm)
    assert read_scan_file(write_ply(tmp_path / "plain.ply", pts)).frame_hint is None


def test_results_are_read_only(tmp_path):
    np.savetxt(tmp_path / "a.xyz", grid_points_mm())
    with pytest.raises(ValueError):
        read_scan_file(tmp_path / "a.xyz").points[0, 0] = 1.0


# --- units ------------------------------------------------------------------------------------

def test_declared_units_override_and_contradictions(tmp_path):
    pts = grid_points_mm() / 20.0                       # extent 10: ambiguous
    np.savetxt(tmp_path / "small.xyz", pts)
    with pytest.raises(BadInputError, match=r"small\.xyz.*ambiguous.*--units"):
        read_scan_file(tmp_path / "small.xyz")
    assert np.array_equal(read_scan_file(tmp_path / "small.xyz", units="mm").points, pts)
    assert np.allclose(read_scan_file(tmp_path / "small.xyz", units="m").points, pts * 1000.0)
    np.savetxt(tmp_path / "metres.xyz", grid_points_mm() / 1000.0)   # extent 0.2
    with pytest.raises(BadInputError, match=r"metres\.xyz: is declared mm but its extent of 0\.2 says metr"):
        read_scan_file(tmp_path / "metres.xyz", units="mm")
    np.savetxt(tmp_path / "mm.xyz", grid_points_mm())                # extent 200
    with pytest.raises(BadInputError, match=r"mm\.xyz: is declared m but its extent of 200 says millimetres"):
        read_scan_file(tmp_path / "mm.xyz", units="m")
    np.savetxt(tmp_path / "between.xyz", grid_points_mm() / 10.0)    # extent 20: 20 m or 20 mm, neither a body
    with pytest.raises(BadInputError, match=r"ambiguous extent of 20 \(a body scan spans 0\.05–8 in metres or 50–8000"):
        read_scan_file(tmp_path / "between.xyz")
    np.savetxt(tmp_path / "huge.xyz", grid_points_mm() * 50.0)       # extent 10 000 in the declared mm
    with pytest.raises(BadInputError, match=r"huge\.xyz: has an extent of 1e\+04 mm, more than any body scan spans"):
        read_scan_file(tmp_path / "huge.xyz", units="mm")
    with pytest.raises(BadInputError, match="units must be"):
        read_scan_file(tmp_path / "mm.xyz", units="cm")


def test_units_auto_detection(tmp_path):
    sphere_mm = sphere_m().scale(1000.0, center=(0, 0, 0))
    scan = read_scan_file(save_mesh(tmp_path / "mm.ply", sphere_mm))
    assert "units mm (detected from extent 200)" in scan.description
    r = np.linalg.norm(scan.points, axis=1)
    assert 98.0 < r.min() and r.max() < 100.0 + 1e-6
    scan = read_scan_file(save_mesh(tmp_path / "m.ply", sphere_m()))
    assert "units m (detected from extent 0.2)" in scan.description
    r = np.linalg.norm(scan.points, axis=1)
    assert 98.0 < r.min() and r.max() < 100.0 + 1e-6


# --- bad input: one sentence naming the file ----------------------------------------------------

def _bad_files(tmp_path):
    """name → (path, expected words); each file is wrong in one way."""
    d = tmp_path
    (d / "folder.stl").mkdir()
    (d / "empty.pcd").write_bytes(b"")
    (d / "image.png").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(64))
    (d / "noext").write_text("1 2 3\n")
    (d / "image.stl").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(256)))
    (d / "recording.pcd").write_bytes(b"\x89MCAP0\r\n" + bytes(range(256)) * 4)
    (d / "recording.obj").write_bytes(b"\x89MCAP0\r\n" + bytes(range(256)) * 4)
    (d / "text.stl").write_text("this is not a mesh\n")
    write_stl(d / "sphere.stl", np.asarray(sphere_m().vertices)[np.asarray(sphere_m().triangles)])
    (d / "truncated.stl").write_bytes((d / "sphere.stl").read_bytes()[:1000])
    tri = np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]])
    write_stl(d / "nan.stl", np.stack([tri, np.where([[True, False, False], [0] * 3, [0] * 3], np.nan, tri)]))
    write_stl(d / "flat.stl", np.stack([tri * [1, 0, 0], tri * [0, 1, 0]]))   # collinear: no area
    (d / "vertices.obj").write_text("v 0 0 0\nv 100 0 0\nv 0 100 0\n")
    (d / "bad_index.obj").write_text("v 0 0 0\nv 100 0 0\nv 0 100 0\nf 1/1 2/2 9/3\n")
    (d / "index_zero.obj").write_text("v 0 0 0\nv 100 0 0\nv 0 100 0\nf 0 1 2\n")
    write_pcd(d / "inf.pcd", np.array([[0, 0, 0], [100, 0, 0], [np.inf, 0, 0]]))
    write_pcd(d / "two.pcd", np.array([[0, 0, 0], [100, 0, 0]]))
    (d / "truncated.pcd").write_bytes(write_pcd(d / "whole.pcd", grid_points_mm()).read_bytes()[:-50])
    assert o3d.io.write_point_cloud(str(d / "text.pcd"), o3d.geometry.PointCloud(o3d.utility.Vector3dVector(
        grid_points_mm(20))), write_ascii=True)
    text = (d / "text.pcd").read_bytes()
    (d / "half.pcd").write_bytes(text[:len(text) // 2 + len(text) // 4])     # its header passes for whole
    (d / "nan.xyz").write_text("0 0 0\n100 0 0\nnan 0 0\n")
    (d / "garbage.xyz").write_text("0 0 0\nhello world 3\n")
    (d / "ragged.xyz").write_text("0 0 0\n100 0 0 0 0 1\n")
    (d / "four.xyz").write_text("0 0 0 1\n100 0 0 1\n0 100 0 1\n")
    (d / "colours.xyz").write_text("0 0 0 255 0 0\n100 0 0 0 255 0\n0 100 0 0 0 255\n")
    (d / "two.xyz").write_text("0 0 0\n100 0 0\n")
    (d / "comments.xyz").write_text("# nothing here\n")
    (d / "binary.xyz").write_bytes(bytes(range(128, 256)))
    write_ply(d / "nan.ply", np.array([[0, 0, 0], [100, 0, 0], [np.nan, 0, 0]]))
    write_glb(d / "whole.glb", grid_points_mm(), [[0, 1, 2], [1, 2, 3]])
    write_glb(d / "nan.glb", np.vstack([grid_points_mm(), [[np.nan, 0, 0]]]), [[0, 1, 2], [1, 2, 512]])
    (d / "truncated.glb").write_bytes((d / "whole.glb").read_bytes()[:-40])
    (d / "zip.glb").write_bytes(b"PK\x03\x04" + bytes(64))
    (d / "text.gltf").write_text('{"asset": {"version": "2.0"}, "meshes": [{"primitives": [{}]}]}')
    (d / "placed.gltf").write_text('{"asset": {"version": "2.0"}, "meshes": [{"primitives": [{"attributes": '
                                   '{"POSITION": 0}}]}], "accessors": [{"count": 100000, "type": "VEC3"}], '
                                   '"nodes": ' + json.dumps([{"mesh": 0}] * 300) + '}')
    (d / "huge.gltf").write_text('{"asset": {"version": "2.0"}, "meshes": [{"primitives": [{"attributes": '
                                 '{"POSITION": 0}}]}], "accessors": [{"count": 300000000, "type": "VEC3"}]}')
    (d / "truncated.ply").write_bytes(write_ply(d / "whole.ply", grid_points_mm()).read_bytes()[:-10])
    return {
        "missing": (d / "missing.stl", "no such file"),
        "folder": (d / "folder.stl", "is a folder"),
        "empty": (d / "empty.pcd", "is empty (0 bytes)"),
        "extension": (d / "image.png", "extension '.png'; supported scan files are .ply, .obj, .stl, .pcd"),
        "no extension": (d / "noext", "has no file extension"),
        "png as stl": (d / "image.stl", "is not a valid STL file: it is a PNG image"),
        "mcap as pcd": (d / "recording.pcd", "is not a valid PCD file: it is an MCAP recording"),
        "mcap as obj": (d / "recording.obj", "is not a valid OBJ file: it is an MCAP recording"),
        "text stl": (d / "text.stl", "is not a valid STL file"),
        "truncated stl": (d / "truncated.stl", "is not a valid STL file"),
        "nan stl": (d / "nan.stl", "has 1 point with NaN or infinite coordinates"),
        "flat stl": (d / "flat.stl", "triangles have no area"),
        "vertex-only obj": (d / "vertices.obj", "is not a valid OBJ file or holds no triangles"),
        "bad index obj": (d / "bad_index.obj", "has a face that refers to vertex 9 of 3 vertices"),
        "index 0 obj": (d / "index_zero.obj", "refers to vertex 0 (OBJ counts vertices from 1)"),
        "inf pcd": (d / "inf.pcd", "NaN or infinite"),
        "two-point pcd": (d / "two.pcd", "has only 2 points; a scan needs at least 3"),
        "truncated pcd": (d / "truncated.pcd", "is not a valid PCD file"),
        "truncated text pcd": (d / "half.pcd", "ends before their data does"),
        "nan glb": (d / "nan.glb", "has 1 point with NaN or infinite coordinates"),    # its reader drops them
        "nan xyz": (d / "nan.xyz", "NaN or infinite"),
        "garbage xyz": (d / "garbage.xyz", "is not a valid XYZ file (could not convert string 'hello'"),
        "ragged xyz": (d / "ragged.xyz", "is not a valid XYZ file"),
        "four-column xyz": (d / "four.xyz", "its lines hold 4 numbers"),
        "colour xyz": (d / "colours.xyz", "not unit normals"),
        "two-point xyz": (d / "two.xyz", "has only 2 points"),
        "comment-only xyz": (d / "comments.xyz", "holds no points"),
        "binary xyz": (d / "binary.xyz", "is not a valid XYZ file (it is not text)"),
        "nan ply": (d / "nan.ply", "NaN or infinite"),
        "truncated ply": (d / "truncated.ply", "truncated"),
        "truncated glb": (d / "truncated.glb", "is not a valid GLB file (it declares"),
        "zip as glb": (d / "zip.glb", "is not a valid GLB file: it is a ZIP or NPZ archive"),
        "gltf without positions": (d / "text.gltf", "is not a valid GLTF file (its JSON is not a glTF's meshes"),
        "gltf of 300 M vertices": (d / "huge.gltf", "holds 300,000,000 vertices, more than any body scan"),
        "gltf placing a mesh 300 times": (d / "placed.gltf", "holds 30,000,000 vertices, more than any body scan"),
    }


def test_bad_files_raise_one_sentence_naming_the_file(tmp_path, capfd):
    for name, (path, words) in _bad_files(tmp_path).items():
        with pytest.raises(BadInputError) as info:
            read_scan_file(path)
        message = str(info.value)
        assert message.startswith(f"{path}: ") and words in message, (name, message)
        assert message.endswith(".") and "\n" not in message, (name, message)
    out, err = capfd.readouterr()
    assert "Open3D" not in out + err  # open3d's warnings are silenced


@pytest.mark.parametrize("units", ["mm", "m"])
def test_one_far_point_under_declared_units_is_bad_input(tmp_path, units):
    pts = grid_points_mm() / (1000.0 if units == "m" else 1.0)
    pts[7] = [1e30, 0.0, 0.0]
    np.savetxt(tmp_path / "far.xyz", pts)
    with pytest.raises(BadInputError, match=r"far\.xyz: has an extent of 1e\+30 " + units + ", more than any body scan"):
        read_scan_file(tmp_path / "far.xyz", units=units)


def test_too_few_points_is_said_before_their_units(tmp_path):
    """Five points cannot hold a breast, whatever their extent: that is the sentence, not a units guess."""
    path = write_ply(tmp_path / "five.ply", grid_points_mm()[:5] / 20.0)     # extent 10: ambiguous units
    with pytest.raises(BadInputError, match=r"five\.ply: has only 5 points; a point cloud of a body needs at least"):
        read_scan_file(path)
