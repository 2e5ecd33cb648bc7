"""Scan files that crash a native reader (MeshLab's, a segmentation fault no Python `except` catches) are refused
in one sentence naming the file, as any bad input is: a patient's MakeHuman body as a phone app's GLB, or a
scanner's PLY of triangles and quads, with a lying buffer offset or a face past the vertices."""
import json
import struct

import numpy as np
import pytest
from PIL import Image

from breastplan.scenes.makehuman import BodyOptions, make_body
from clitools import assert_bad_input, run
from gltf import write_glb


@pytest.fixture(scope="module")
def body():
    return make_body(BodyOptions(cup=0.7, pose="a-pose"))


def _glb_parts(path):
    raw = path.read_bytes()
    length = struct.unpack_from("<I", raw, 12)[0]
    return json.loads(raw[20:20 + length]), raw[20 + length + 8:]


def _glb(path, gltf, binary: bytes) -> None:
    text = json.dumps(gltf).encode() if not isinstance(gltf, bytes) else gltf
    text += b" " * (-len(text) % 4)
    body = struct.pack("<I4s", len(text), b"JSON") + text + struct.pack("<I4s", len(binary), b"BIN\0") + binary
    path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)


@pytest.mark.parametrize("fault", ["buffer view past the data", "triangle past the vertices", "JSON not an object"])
def test_a_glb_that_crashes_its_reader_is_refused_naming_it(cli, tmp_path, body, fault):
    write_glb(tmp_path / "good.glb", body.vertices, body.faces)
    gltf, binary = _glb_parts(tmp_path / "good.glb")
    if fault == "buffer view past the data":
        gltf["bufferViews"][0]["byteOffset"] = 10 ** 8
    elif fault == "triangle past the vertices":
        index = gltf["bufferViews"][gltf["accessors"][gltf["meshes"][0]["primitives"][0]["indices"]]["bufferView"]]
        faces = np.frombuffer(binary, "<u4", index["byteLength"] // 4, index["byteOffset"]).copy()
        faces[::7] = 2 ** 32 - 1
        binary = binary[:index["byteOffset"]] + faces.tobytes() + binary[index["byteOffset"] + faces.nbytes:]
    else:
        gltf = b"[1, 2, 3]"
    _glb(tmp_path / "her.glb", gltf, binary)
    res = run(cli, "ingest", tmp_path / "her.glb", "--side", "left", "--out", tmp_path / "out")
    assert_bad_input(res, tmp_path / "her.glb", tmp_path)
    res = run(cli, "ingest", tmp_path / "good.glb", "--side", "left", "--out", tmp_path / "case")   # as made: read
    assert res.returncode == 0, res.stderr


def test_a_ply_of_triangles_and_a_quad_past_the_vertices_is_refused_naming_it(cli, tmp_path, body):
    v, f = body.vertices, body.faces
    header = (f"ply\nformat ascii 1.0\nelement vertex {len(v)}\nproperty float x\nproperty float y\n"
              f"property float z\nelement face {len(f) + 1}\nproperty list uchar int vertex_indices\nend_header\n")
    lines = [" ".join(f"{c:.3f}" for c in p) for p in v] + [f"3 {a} {b} {c}" for a, b, c in f]
    (tmp_path / "her.ply").write_text(header + "\n".join(lines + [f"4 0 1 2 {len(v) + 99}"]) + "\n")
    res = run(cli, "ingest", tmp_path / "her.ply", "--side", "left", "--out", tmp_path / "out")
    assert_bad_input(res, tmp_path / "her.ply", tmp_path)
    assert "is a PLY file" not in res.stderr                  # it is one: the reader fails on it


def test_an_obj_textured_by_a_grey_image_with_alpha_takes_its_grey(cli, tmp_path, body):
    """A texture PNG of grey and alpha (two channels) had ended `ingest` with a traceback."""
    v, f = body.vertices, body.faces
    uv = (v[:, :2] - v[:, :2].min(0)) / np.ptp(v[:, :2], axis=0)
    Image.fromarray(np.dstack([np.full((8, 8), 120, np.uint8), np.full((8, 8), 255, np.uint8)]), "LA").save(
        tmp_path / "grey.png")
    (tmp_path / "her.mtl").write_text("newmtl skin\nmap_Kd grey.png\n")
    (tmp_path / "her.obj").write_text("mtllib her.mtl\nusemtl skin\n"
                                      + "".join(f"v {a:.3f} {b:.3f} {c:.3f}\n" for a, b, c in v)
                                      + "".join(f"vt {a:.4f} {b:.4f}\n" for a, b in uv)
                                      + "".join(f"f {a}/{a} {b}/{b} {c}/{c}\n" for a, b, c in f + 1))
    res = run(cli, "ingest", tmp_path / "her.obj", "--side", "left", "--out", tmp_path / "case")
    assert res.returncode == 0, res.stderr
    header = (tmp_path / "case" / "camera.ply").read_bytes().split(b"end_header")[0]
    assert b"red" in header
