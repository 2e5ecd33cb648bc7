"""Bad input through the `breastplan` command (docs/cli.md): each case ends as promised.

Bad input: exit 3, one sentence naming the file, nothing written. Usage: exit 2, the option named,
nothing written. Large inputs are sparse files: they cost no disk and are refused from their header.
"""
import os
import shutil
import subprocess

import numpy as np
import pytest

from breastplan import read_ply, write_ply

from bad_inputs import PLY_XYZ, breast_mm, forged_npz, four_numbers_ply, inflating_npz, ply_header, sparse
from clitools import assert_bad_input, run


def unprivileged(path):
    """The command prefix under which `path` (chmod 000 by the caller) cannot be read: none, or for root,
    setpriv dropping the capabilities that let root read anything."""
    if not os.access(path, os.R_OK):
        return []
    if os.geteuid() == 0 and shutil.which("setpriv"):
        return ["setpriv", "--bounding-set=-dac_override,-dac_read_search"]
    pytest.skip("running as root without setpriv: chmod 000 does not stop root reading")


GB2 = 2 << 30
PCD_100M = ("VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 100000000\nHEIGHT 1\n"
            "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 100000000\nDATA binary\n")
DEFORM = ["deform", "--kind", "ptosis", "--param", "b0=1"]
INGEST = ["ingest", "--side", "left"]
WHOLE_SCAN = "far too large for one breast: if it is a whole scan, `breastplan ingest`"
FIT = ["fit"]
CASES = {  # name → (file name, builder(path) → path, command, extra options, words of the sentence)
    "ascii ply, a line of 4 numbers (deform)": ("four.ply", four_numbers_ply, DEFORM, [], "1 value more than its"),
    "ascii ply, a line of 4 numbers (ingest)": ("four.ply", four_numbers_ply, INGEST, [], "1 value more than its"),
    "all points identical (fit)": ("same.ply", lambda p: write_ply(p, np.full((500, 3), 10.0)), FIT, [],
                                   "all its points at one place"),
    "all points identical (ingest)": ("same.ply", lambda p: write_ply(p, np.full((500, 3), 10.0)), INGEST, [],
                                      "all its points at one place"),
    "breast in micrometres (fit)": ("um.ply", lambda p: write_ply(p, breast_mm() * 1000), FIT, [], "micrometres"),
    "breast in metres (deform)": ("m.ply", lambda p: write_ply(p, breast_mm() / 1000), DEFORM, [], "is it in metres"),
    "whole body 1.9 m tall in mm (fit)": ("body.ply", lambda p: write_ply(p, breast_mm() * 16), FIT, [], WHOLE_SCAN),
    "whole body 1.9 m tall in mm (deform)": ("body.ply", lambda p: write_ply(p, breast_mm() * 16), DEFORM, [],
                                             WHOLE_SCAN),
    "a body in micrometres (fit)": ("um.ply", lambda p: write_ply(p, breast_mm() * 16000), FIT, [],
                                    "more than a breast or a whole body in millimetres (is it in micrometres?)"),
    "one vertex with NaN (fit)": ("nan.ply", lambda p: write_ply(p, np.r_[breast_mm(), [[np.nan, 0, 0]]]), FIT, [],
                                  "has 1 vertex with NaN or infinite coordinates"),
    "two vertices with NaN (deform)": ("nan.ply", lambda p: write_ply(p, np.r_[breast_mm(), [[np.nan, 0, 0]] * 2]),
                                       DEFORM, [], "has 2 vertices with NaN or infinite coordinates"),
    "ascii ply, a face of 1 vertex (deform)": (
        "face1.ply", lambda p: p.write_bytes(ply_header(3, "ascii").replace(
            b"end_header", b"element face 1\nproperty list uchar int vertex_indices\nend_header")
            + b"0 0 0\n1 0 0\n0 1 0\n1 0" + b" " * 8 + b"\n"), DEFORM, [],
        "has a face with 1 vertex; faces need at least 3"),
    "ascii ply of 1 vertex and no data (fit)": ("short1.ply", lambda p: p.write_bytes(ply_header(1, "ascii")), FIT, [],
                                                "its header declares 1 'vertex' element but the file ends"),
    "ply declaring x twice (deform)": ("twice.ply", lambda p: p.write_bytes(ply_header(3).replace(
        b"property float z", b"property float z\nproperty float x") + bytes(48)), DEFORM, [],
        "its element 'vertex' declares the property 'x' more than once"),
    "ply whose face indices are floats (deform)": ("floatfaces.ply", lambda p: p.write_bytes(ply_header(3, "ascii").replace(
        b"end_header", b"element face 1\nproperty list uchar float vertex_indices\nend_header")
        + b"0 0 0\n1 0 0\n0 1 0\n3 0.5 1.5 2.5\n"), DEFORM, [], "vertex counts or indices are declared as floats"),
    "text file named .npz (deform)": ("text.npz", lambda p: p.write_text("not an archive\n"), DEFORM, [],
                                      "is neither a PLY file nor a fit.npz or case folder holding a fit, which deform"),
    "folder without a fit (deform)": ("case", lambda p: p.mkdir(), DEFORM, [],
                                      "holds no fit.npz: deform takes a case folder once `breastplan fit` has fitted"),
    "one coordinate 1e30, --units mm (ingest)": ("far.ply", lambda p: write_ply(p, np.r_[breast_mm(), [[1e30, 0, 0]]]),
                                                 INGEST, ["--units", "mm"], "more than any body scan spans"),
    "one coordinate 1e30 (fit)": ("far.ply", lambda p: write_ply(p, np.r_[breast_mm(), [[1e30, 0, 0]]]), FIT, [],
                                  "a point lies far from the others"),
    "coordinates ±1.7e308, overflowing (fit)": ("inf.ply", lambda p: write_ply(p, np.r_[breast_mm(), [[1.7e308] * 3,
                                                [-1.7e308] * 3]]), FIT, [], "a point lies far from the others"),
    "npz member declaring 10^12 × 3 values (dataset)": ("db.npz", forged_npz, ["dataset", "--condition", "ptosis b0",
                                                        "--db"], [], "declares 1000000000000×3 values"),
    "npz of 300 kB unpacking to 300 MiB (dataset)": ("bomb.npz", inflating_npz, ["dataset", "--condition", "ptosis b0",
                                                     "--db"], [], "more than any breastplan artefact holds (256 MiB)"),
    "2 GB of zeros as .ply (deform)": ("zero.ply", lambda p: sparse(p, b"", GB2), DEFORM, [], "is not a PLY file"),
    "2 GB of zeros as .xyz (ingest)": ("zero.xyz", lambda p: sparse(p, b"", GB2), INGEST, [], "it is not text"),
    "2 GB of zeros as .obj (ingest)": ("zero.obj", lambda p: sparse(p, b"", GB2), INGEST, [], "it is not text"),
    "2 GB of zeros as .stl (ingest)": ("zero.stl", lambda p: sparse(p, b"", GB2), INGEST, [], "no triangles"),
    "2 GB of zeros as .glb (ingest)": ("zero.glb", lambda p: sparse(p, b"", GB2), INGEST, [],
                                       "does not start as a binary glTF does"),
    "2 GB of zeros as .gltf (ingest)": ("zero.gltf", lambda p: sparse(p, b"", GB2), INGEST, [], "export it as GLB"),
    "2 GB of zeros as .pcd (ingest)": ("zero.pcd", lambda p: sparse(p, b"", GB2), INGEST, [], "no DATA line"),
    "2 GB of zeros as .npz (dataset)": ("zero.npz", lambda p: sparse(p, b"", GB2),
                                        ["dataset", "--condition", "ptosis b0", "--db"], [], "is not an NPZ file"),
    "ply of 100 vertices and 2 GB more (fit)": (
        "tail.ply", lambda p: sparse(p, ply_header(100), GB2), FIT, [], "bytes after the data its header"),
    "ascii ply of 100 vertices and 2 GB more (ingest)": (
        "tail.ply", lambda p: sparse(p, ply_header(100, "ascii"),
                                     GB2), INGEST, [], "not a number"),
    "ply declaring 89 M vertices (fit)": (
        "huge.ply", lambda p: sparse(p, ply_header(89000000), 89_000_000 * 12 + 200), FIT, [],
        "declares 89,000,000 'vertex' elements, more than any body scan holds"),
    "ply declaring 19 M vertices in 1 kB (fit)": (
        "short.ply", lambda p: sparse(p, ply_header(19000000), 1000), FIT, [], "truncated"),
    "ascii ply declaring 19 M vertices in 1 kB (ingest)": (
        "short.ply", lambda p: sparse(p, ply_header(19000000, "ascii"), 1000), INGEST, [], "truncated"),
    "binary stl declaring 2^32 - 1 triangles (ingest)": ("big.stl", lambda p: p.write_bytes(bytes(80) + b"\xff" * 4
                                                          + bytes(50)), INGEST, [], "declares 4,294,967,295 triangles"),
    "pcd declaring 100 M points (ingest)": ("big.pcd", lambda p: p.write_text(PCD_100M), INGEST, [],
                                            "declares 100,000,000 points, more than any body scan"),
    "ply whose first face declares 2^31 vertices (deform)": (
        "faces.ply", lambda p: p.write_bytes(f"ply\nformat binary_little_endian 1.0\nelement vertex 3\n{PLY_XYZ}"
                                             "element face 1\nproperty list int int vertex_indices\nend_header\n"
                                             .encode() + bytes(36) + (2**31 - 1).to_bytes(4, "little") + bytes(12)),
        DEFORM, [], "truncated"),
    "obj of 3 vertices and 1000 faces (ingest)": (
        "fan.obj", lambda p: p.write_text("v 0 0 0\nv 300 0 0\nv 0 300 10\n" + "f 1 2 3\n" * 1000), INGEST, [],
        "holds 1,000 faces over 3 vertices: a scanned surface has about 2 faces per vertex"),
    "ply declaring 3 vertices and 19 M faces (fit)": (
        "fan.ply", lambda p: sparse(p, ply_header(3).replace(b"end_header", b"element face 19000000\n"
                                    b"property list uchar int vertex_indices\nend_header"), 19_000_000 * 13 + 300),
        FIT, [], "declares 19,000,000 faces over 3 vertices"),
}


@pytest.mark.parametrize("name", CASES)
def test_bad_input_exits_3_with_one_sentence_naming_the_file(cli, tmp_path, name):
    filename, build, command, options, words = CASES[name]
    path = tmp_path / filename
    build(path)
    out = tmp_path / ("out.ply" if command == DEFORM else "out.npz" if "dataset" in command else "out")
    res = run(cli, *command, path, *options, "--out", out)
    assert_bad_input(res, path, tmp_path)
    assert words in res.stderr, res.stderr


@pytest.mark.parametrize("command", [DEFORM, FIT, INGEST, ["dataset", "--condition", "ptosis b0", "--db"]])
def test_an_unreadable_file_is_bad_input_not_a_usage_error(cli, tmp_path, command):
    path = tmp_path / ("locked.npz" if "dataset" in command else "locked.ply")
    write_ply(path, breast_mm()) if path.suffix == ".ply" else forged_npz(path)
    path.chmod(0)
    prefix = unprivileged(path)
    res = run(*prefix, cli, *command, path, "--out", tmp_path / "out")
    assert_bad_input(res, path, tmp_path)
    assert "cannot be read (Permission denied)" in res.stderr


@pytest.mark.parametrize("command", [DEFORM, FIT, INGEST, ["plan"], ["dataset", "--condition", "ptosis b0", "--db"],
                                     ["batch"]])
def test_a_symbolic_link_that_loops_is_named_as_such(cli, tmp_path, command):
    path = tmp_path / "loop.ply"
    path.symlink_to(path.name)
    res = run(cli, *command, path, "--out", tmp_path / "out")
    assert_bad_input(res, path, tmp_path)
    assert ("is a symbolic link to no file (it loops" if command[0] != "batch" else "is not a folder") in res.stderr


@pytest.mark.parametrize("command", [DEFORM, FIT, INGEST, ["plan"], ["filter", "get_breast_measures"]])
@pytest.mark.parametrize("name", ["scan.ply", "scan.mcap"])
def test_a_named_pipe_is_refused_not_waited_on(cli, tmp_path, command, name):
    """Reading a named pipe blocks until something writes to it: no command may open one to sniff it."""
    path = tmp_path / name
    os.mkfifo(path)
    res = run(cli, *command, path, *(["--out", tmp_path / "out"] if command[0] != "filter" else []))
    assert_bad_input(res, path, tmp_path)


def test_a_file_name_that_is_not_utf8_and_a_terminal_that_is_not_are_no_faults(cli, tmp_path):
    """A Latin-1 name copied from another machine (b'M\\xfcller.ply') is a legal POSIX name; a Latin-1
    terminal cannot show '→'. Both are shown escaped, and the breast is deformed."""
    before = os.fsdecode(os.path.join(os.fsencode(tmp_path), b"M\xfcller.ply"))
    after = os.fsdecode(os.path.join(os.fsencode(tmp_path), b"M\xfcller-b0.ply"))
    write_ply(before, breast_mm())
    res = subprocess.run([cli, *DEFORM, before, "--out", after], capture_output=True,
                         env={**os.environ, "PYTHONIOENCODING": "latin-1"})
    assert res.returncode == 0, res.stderr
    assert b"M\\udcfcller" in res.stdout and b"ptosis \\u2192" in res.stdout and b"Traceback" not in res.stderr
    assert read_ply(after).points.shape == read_ply(before).points.shape


def test_an_unreadable_case_folder_is_bad_input(cli, tmp_path):
    case = tmp_path / "case"
    case.mkdir()
    case.chmod(0)
    prefix = unprivileged(case)
    res = run(*prefix, cli, "fit", case, "--out", tmp_path / "out")
    case.chmod(0o755)
    assert_bad_input(res, case, tmp_path)
    assert "cannot be read" in res.stderr


def test_an_output_folder_without_write_permission_is_bad_input(cli, tmp_path):
    write_ply(tmp_path / "breast.ply", breast_mm())
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    prefix = unprivileged(locked) if os.access(locked, os.W_OK) else []
    res = run(*prefix, cli, *DEFORM, tmp_path / "breast.ply", "--out", locked / "out.ply")
    assert res.returncode == 3 and res.stderr.strip().splitlines() == [
        f"error: {locked / 'out.ply'}: cannot be written: no permission to write in {locked}."], res.stderr
    assert list(locked.iterdir()) == []


@pytest.mark.parametrize("command,out", [(INGEST, "gone"), (DEFORM, "gone/out.ply"), (DEFORM, "gone")])
def test_an_output_through_a_link_leading_nowhere_is_refused_before_any_work(cli, tmp_path, command, out):
    write_ply(tmp_path / "breast.ply", breast_mm())
    (tmp_path / "gone").symlink_to(tmp_path / "deleted")
    res = run(cli, *command, tmp_path / "breast.ply", "--out", tmp_path / out)
    assert res.returncode == 3 and res.stderr.strip().splitlines() == [
        f"error: {tmp_path / out}: cannot be written: {tmp_path / 'gone'} is a symbolic link to "
        f"{tmp_path / 'deleted'}, which does not exist."], res.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["breast.ply", "gone"]


def test_a_legal_250_character_out_name_is_written(cli, tmp_path):
    write_ply(tmp_path / "breast.ply", breast_mm())
    out = tmp_path / ("d" * 246 + ".ply")
    res = run(cli, *DEFORM, tmp_path / "breast.ply", "--out", out)
    assert res.returncode == 0, res.stderr
    assert read_ply(out).points.shape == (2000, 3)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["breast.ply", out.name]


def test_an_out_name_longer_than_the_file_system_allows_is_bad_input(cli, tmp_path):
    write_ply(tmp_path / "breast.ply", breast_mm())
    out = tmp_path / ("out" + "d" * 253 + ".ply")
    res = run(cli, *DEFORM, tmp_path / "breast.ply", "--out", out)
    assert_bad_input(res, out, tmp_path)
    assert "more than the 255 a file name may have" in res.stderr


@pytest.mark.parametrize("param,words", [("b0=1e308", "sends points to infinity"),
                                         ("b0=400", "moves points by 2.4e+03 mm, more than any breast spans")])
def test_parameters_beyond_any_breast_give_one_sentence(cli, tmp_path, param, words):
    write_ply(tmp_path / "breast.ply", breast_mm())
    res = run(cli, "deform", tmp_path / "breast.ply", "--kind", "ptosis", "--param", param,
              "--out", tmp_path / "out.ply")
    assert_bad_input(res, tmp_path / "breast.ply", tmp_path)
    assert words in res.stderr, res.stderr


@pytest.mark.parametrize("args,option", [
    (["synth", "--db", "S", "--points", str(10**8)], "--points"),
    (["synth", "--db", "S", "--points", "-4"], "--points"),
    (["synth", "--db", "S", "--seed", "-1"], "--seed"),
    (["dataset", "--db", "db.npz", "--condition", "ptosis b0", "--dd", "100000"], "--dd"),
])
def test_usage_errors_exit_2_naming_the_option_and_write_nothing(cli, tmp_path, args, option):
    res = subprocess.run([cli, *args, "--out", "out"], capture_output=True, text=True, cwd=tmp_path, timeout=600)
    assert res.returncode == 2, res.stderr
    assert option in res.stderr and "Traceback" not in res.stderr and "NaN" not in res.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("primitive, problem", [
    ("a1=1e308,a2=10,a3=10,a4=10,a5=10", "no breast's size"),              # wider than any breast
    ("a1=1e-300,a2=1e-300,a3=1e-300,a4=1e-300,a5=1e-300", "no breast's size"),   # a point
    ("a1=10,a2=10,a3=10,a4=10,a5=10,eps1=1e9", "shape exponents"),        # no superellipsoid a breast has
])
def test_a_primitive_no_breast_has_is_a_usage_error(cli, tmp_path, primitive, problem):
    write_ply(tmp_path / "breast.ply", breast_mm())
    res = run(cli, "deform", tmp_path / "breast.ply", "--kind", "ptosis", "--param", "b0=1",
              "--primitive", primitive, "--out", tmp_path / "out.ply")
    assert res.returncode == 2, res.stderr
    assert "--primitive" in res.stderr and problem in " ".join(res.stderr.replace("│", " ").split())
    assert "Traceback" not in res.stderr and "Warning" not in res.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["breast.ply"]


def test_deform_refuses_a_parametric_model_saying_what_it_is_and_what_model_takes(cli, tmp_path):
    from breastplan.deform.by_degree import MODELS

    write_ply(tmp_path / "breast.ply", breast_mm())
    model = MODELS / "ptosis-b0-gt-b1.npz"
    res = run(cli, "deform", tmp_path / "breast.ply", "--kind", "ptosis", "--degree", 3, "--model", model,
              "--out", tmp_path / "out.ply")
    assert_bad_input(res, model, tmp_path)
    assert "is a parametric model of the condition 'ptosis b0>b1'" in res.stderr
    assert "not the statistical model --model takes" in res.stderr


def test_deform_refuses_an_npz_that_is_no_model_as_the_model(cli, tmp_path):
    write_ply(tmp_path / "breast.ply", breast_mm())
    np.savez(tmp_path / "arrays.npz", a=np.zeros(3))
    res = run(cli, "deform", tmp_path / "breast.ply", "--kind", "ptosis", "--degree", 3, "--model",
              tmp_path / "arrays.npz", "--out", tmp_path / "out.ply")
    assert_bad_input(res, tmp_path / "arrays.npz", tmp_path)
    assert "is not a breastplan artefact" in res.stderr and "--model takes a statistical model" in res.stderr


PARAMETRIC = "deform/models/ptosis-b0-gt-b1.npz"


@pytest.mark.parametrize("args,option", [
    (["--kind", "ptosis", "--param", "b0=1", "--condition", "b0>b1"], "--condition"),
    (["--kind", "ptosis", "--param", "b0=1", "--method", "learnt"], "--method"),
    (["--kind", "ptosis", "--degree", "3", "--model", PARAMETRIC, "--condition", "ptosis b1>=b0"], "--condition"),
    (["--kind", "ptosis", "--degree", "3", "--model", PARAMETRIC, "--method", "exact"], "--method"),
    (["--kind", "ptosis", "--degree", "3", "--condition", "turn c0>c1"], "--condition"),
    (["--kind", "flatten-side", "--degree", "3", "--condition", "b0>b1"], "--kind"),
])
def test_deform_options_that_do_not_apply_are_usage_errors_never_ignored(cli, tmp_path, args, option):
    from breastplan.deform.by_degree import MODELS

    write_ply(tmp_path / "breast.ply", breast_mm())
    args = [str(MODELS.parent.parent / a) if a == PARAMETRIC else a for a in args]
    res = run(cli, "deform", tmp_path / "breast.ply", *args, "--out", tmp_path / "out.ply")
    assert res.returncode == 2, res.stderr
    assert f"Invalid value for {option}" in res.stderr and "Traceback" not in res.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["breast.ply"]


@pytest.mark.parametrize("comments, problem", [
    (["primitive (model units) a1=10 a2=10 a3=10 a4=10 a5=10 eps1=1 eps2=1",
      "pose (primitive frame to breast frame, mm) " + " ".join(["0"] * 16)], "a pose that is not a rigid transform"),
    (["primitive (model units) a1=1e300 a2=1e300 a3=1e300 a4=1e300 a5=1e300 eps1=1 eps2=1"],
     "a primitive that spans"),
])
def test_a_ply_carrying_a_primitive_or_pose_no_breast_has_is_refused(cli, tmp_path, comments, problem):
    """Truth: a breast's pose is rigid (its inverse takes the points to the primitive's frame) and its
    primitive spans 20–600 mm; a PLY header that says otherwise is a damaged file, not a breast."""
    write_ply(tmp_path / "breast.ply", breast_mm(), comments=comments)
    res = run(cli, "deform", tmp_path / "breast.ply", "--kind", "top-shape", "--degree", "3",
              "--out", tmp_path / "out.ply")
    assert_bad_input(res, tmp_path / "breast.ply", tmp_path)
    assert problem in res.stderr
