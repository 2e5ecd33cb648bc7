"""PLY and NPZ artefacts: round trips, validation, atomic writes (docs/artefacts.md)."""
import io
import json
import os
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from breastplan import ArtefactError, load_npz, read_ply, save_npz, write_ply
from breastplan.atomic import NAME_KEPT, atomic_open, atomic_set, short_name
from breastplan.json_text import to_json, utf8

SPEC = {"points": ("f", ("n", 3)), "label": ("U", ("n",))}


def sample_mesh():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.5]], float)
    F = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    return V, F


def test_ply_round_trip_mesh_with_normals(tmp_path):
    V, F = sample_mesh()
    N = V / np.maximum(np.linalg.norm(V, axis=1, keepdims=True), 1)
    g = read_ply(write_ply(tmp_path / "m.ply", V, faces=F, normals=N, comments=["hello"]))
    assert np.array_equal(g.points, V) and np.array_equal(g.faces, F) and np.array_equal(g.normals, N)
    assert "hello" in g.comments
    assert (tmp_path / "m.ply").read_bytes().startswith(b"ply\nformat binary_little_endian 1.0\n")


def test_ply_ascii_big_endian_and_quads(tmp_path):
    ascii_ply = ("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                 "property float z\nproperty uchar red\nelement face 1\nproperty list uchar int vertex_indices\n"
                 "end_header\n0 0 0 255\n1 0 0 0\n1 1 0 0\n0 1 0 9\n4 0 1 2 3\n")
    (tmp_path / "a.ply").write_text(ascii_ply)
    g = read_ply(tmp_path / "a.ply")
    assert np.allclose(g.points[2], [1, 1, 0])
    assert np.array_equal(g.faces, [[0, 1, 2], [0, 2, 3]])      # quad fan-triangulated
    header = b"ply\nformat binary_big_endian 1.0\nelement vertex 2\nproperty double x\nproperty double y\nproperty double z\nend_header\n"
    (tmp_path / "b.ply").write_bytes(header + np.array([[1, 2, 3], [4, 5, 6]], ">f8").tobytes())
    assert np.array_equal(read_ply(tmp_path / "b.ply").points, [[1, 2, 3], [4, 5, 6]])


@pytest.mark.parametrize("content,message", [
    (b"", "is empty"),
    (b"solid stl\nfacet normal 0 0 1\n", "not a PLY file"),
    (b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n", "end_header"),
    (b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
     "no vertices"),
    (b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
     b"0 0 0\nnan 1 1\n", "NaN"),
    (b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
     b"0 0 0\n1 1 inf\n", "NaN or infinite"),
    (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
     b"element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n",
     "outside 0..2"),
    (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
     b"0 0 0\n1 0 0\n", "truncated"),
    (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
     b"0 zero 0\n", "not a number"),
    (b"ply\nformat binary_middle_endian 1.0\nend_header\n", "unsupported PLY format"),
    (b"ply\nformat ascii 2.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
     b"0 0 0\n", "version 2.0"),
    (b"ply\nformat ascii 1.0\nelement vertex 1 extra\nproperty float x\nproperty float y\nproperty float z\n"
     b"end_header\n0 0 0\n", "bad header line 'element vertex 1 extra'"),
    (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x y\nproperty float z\nend_header\n0 0 0\n",
     "bad header line 'property float x y'"),
    (b"ply\nformat ascii 1.0\nelement vertex 1\nproprety float x\nproperty float y\nproperty float z\n"
     b"end_header\n0 0 0\n", "bad header line 'proprety float x'"),
    (b"ply\nformat ascii 1.0\nproperty float x\nend_header\n", "bad header line 'property float x'"),
    (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float u\nend_header\n1\n", "x, y and z"),
])
def test_bad_ply_is_refused_with_the_file_name(tmp_path, content, message):
    path = tmp_path / "scan.ply"
    path.write_bytes(content)
    with pytest.raises(ArtefactError, match=message) as err:
        read_ply(path)
    assert str(path) in str(err.value)


def test_truncated_binary_ply(tmp_path):
    V, F = sample_mesh()
    data = write_ply(tmp_path / "m.ply", V, faces=F).read_bytes()
    for cut in (len(data) - 5, len(data) - 40):
        (tmp_path / "t.ply").write_bytes(data[:cut])
        with pytest.raises(ArtefactError, match="truncated"):
            read_ply(tmp_path / "t.ply")


def test_missing_file_and_folder(tmp_path):
    with pytest.raises(ArtefactError, match="no such file"):
        read_ply(tmp_path / "nope.ply")
    with pytest.raises(ArtefactError, match="folder"):
        read_ply(tmp_path)


def test_npz_round_trip_and_header(tmp_path):
    pts = np.arange(12.0).reshape(4, 3)
    path = save_npz(tmp_path / "a.npz", "breastplan.test/2", {"points": pts, "label": np.array(list("abcd"))},
                    units="mm", frame="camera", meta={"k": 1})
    art = load_npz(path, "breastplan.test/2", SPEC)
    assert np.array_equal(art["points"], pts)
    assert (art.schema, art.units, art.frame, art.meta) == ("breastplan.test/2", "mm", "camera", {"k": 1})
    assert load_npz(path, "breastplan.test/3", SPEC)["points"].shape == (4, 3)  # older versions load


def test_npz_validation(tmp_path):
    good = {"points": np.zeros((4, 3)), "label": np.array(list("abcd"))}
    path = save_npz(tmp_path / "a.npz", "breastplan.test/2", good)
    with pytest.raises(ArtefactError, match="expected breastplan.other/1"):
        load_npz(path, "breastplan.other/1")
    with pytest.raises(ArtefactError, match="newer"):
        load_npz(path, "breastplan.test/1")
    bad_shape = save_npz(tmp_path / "b.npz", "breastplan.test/2", {"points": np.zeros((4, 2)), "label": good["label"]})
    with pytest.raises(ArtefactError, match="shape"):
        load_npz(bad_shape, "breastplan.test/2", SPEC)
    mismatch = save_npz(tmp_path / "c.npz", "breastplan.test/2", {"points": np.zeros((4, 3)), "label": np.array(["a"])})
    with pytest.raises(ArtefactError, match="inconsistent"):
        load_npz(mismatch, "breastplan.test/2", SPEC)
    nan = save_npz(tmp_path / "d.npz", "breastplan.test/2", {"points": np.full((4, 3), np.nan), "label": good["label"]})
    with pytest.raises(ArtefactError, match="NaN"):
        load_npz(nan, "breastplan.test/2", SPEC)
    with pytest.raises(ArtefactError, match="lacks the array 'label'"):
        load_npz(save_npz(tmp_path / "e.npz", "breastplan.test/2", {"points": good["points"]}), "breastplan.test/2", SPEC)


def test_npz_without_schema_pickles_and_corruption(tmp_path):
    np.savez(tmp_path / "plain.npz", x=np.zeros(3))
    with pytest.raises(ArtefactError, match="no schema"):
        load_npz(tmp_path / "plain.npz", "breastplan.test/1")
    np.savez(tmp_path / "pickle.npz", schema=np.str_("breastplan.test/1"), x=np.array([{"a": 1}], dtype=object))
    with pytest.raises(ArtefactError, match="pickle"):
        load_npz(tmp_path / "pickle.npz", "breastplan.test/1")
    data = (tmp_path / "plain.npz").read_bytes()
    (tmp_path / "cut.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(ArtefactError, match="not an NPZ file|corrupt"):
        load_npz(tmp_path / "cut.npz", "breastplan.test/1")
    with pytest.raises(ValueError, match="pickle"):
        save_npz(tmp_path / "o.npz", "breastplan.test/1", {"x": np.array([None], dtype=object)})


def test_atomic_write_leaves_nothing_on_failure(tmp_path):
    target = tmp_path / "sub" / "out.bin"
    with pytest.raises(RuntimeError):
        with atomic_open(target) as fh:
            fh.write(b"half")
            raise RuntimeError("crash")
    assert os.listdir(tmp_path / "sub") == []
    target.write_bytes(b"old")
    with pytest.raises(RuntimeError):
        with atomic_open(target) as fh:
            fh.write(b"new")
            raise RuntimeError("crash")
    assert target.read_bytes() == b"old" and os.listdir(tmp_path / "sub") == ["out.bin"]
    assert zipfile.is_zipfile(save_npz(tmp_path / "z.npz", "breastplan.test/1", {"x": np.zeros(1)}))


def test_binary_faces_with_extra_properties(tmp_path):
    header = (b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
              b"property float z\nelement face 2\nproperty uchar flags\nproperty list uchar int vertex_indices\n"
              b"end_header\n")
    face = np.zeros(2, dtype=[("flags", "u1"), ("n", "u1"), ("idx", "<i4", (3,))])
    face["flags"], face["n"], face["idx"] = 7, 3, [[0, 1, 2], [2, 1, 0]]
    (tmp_path / "f.ply").write_bytes(header + np.eye(3, dtype="<f4").tobytes() + face.tobytes())
    assert np.array_equal(read_ply(tmp_path / "f.ply").faces, [[0, 1, 2], [2, 1, 0]])


@settings(max_examples=25, deadline=None)
@given(st.integers(1, 300), st.integers(0, 2**32 - 1), st.booleans())
def test_ply_round_trip_is_exact(tmp_path_factory, n, seed, with_faces):
    rng = np.random.default_rng(seed)
    V = rng.normal(scale=100.0, size=(n, 3))
    F = rng.integers(0, n, size=(2 * n, 3)) if with_faces else None
    g = read_ply(write_ply(tmp_path_factory.mktemp("ply") / "r.ply", V, faces=F))
    assert np.array_equal(g.points, V)
    assert (g.faces is None) if not with_faces else np.array_equal(g.faces, F)


@settings(max_examples=50, deadline=None)
@given(st.text(st.characters(exclude_categories=()), max_size=40) | st.just("x\nend_header\ny"))
def test_a_comment_of_any_text_is_one_header_line(tmp_path_factory, text):
    """A file name carried into a comment may hold a newline, a control character or bytes that are
    not UTF-8 (a surrogate): the header stays one ASCII line per comment and the points read back;
    printable ASCII is kept as it is."""
    points = np.arange(9.0).reshape(3, 3)
    g = read_ply(write_ply(tmp_path_factory.mktemp("ply") / "c.ply", points, comments=[f"source {text}", "last"]))
    assert np.array_equal(g.points, points)
    assert len(g.comments) == 2 and g.comments[1] == "last" and g.comments[0].isascii()
    if all(" " <= c <= "~" for c in text):
        assert g.comments[0].rstrip() == f"source {text}".rstrip()


@settings(max_examples=100, deadline=None)
@given(st.binary(max_size=300).filter(lambda b: b"/" not in b and b"\0" not in b))
def test_any_file_name_is_written_as_utf8_text_and_cut_to_whole_characters(raw):
    """A POSIX name is any bytes but '/' and NUL; Python holds those that are not UTF-8 as surrogates."""
    name = os.fsdecode(raw)
    text = utf8(f"input {name}").decode("utf-8")                            # valid UTF-8 whatever the name
    assert text == f"input {raw.decode('utf-8', 'backslashreplace')}"
    cut = short_name(name)
    assert name.startswith(cut) and len(os.fsencode(cut)) <= NAME_KEPT
    assert len(os.fsencode(name[:len(cut) + 1])) > NAME_KEPT or cut == name  # as long as it may be


def test_a_long_legal_name_is_written(tmp_path):
    """A 250-byte name is legal (NAME_MAX 255); the temporary name beside it must fit too."""
    path = tmp_path / ("b" * 246 + ".ply")
    write_ply(path, np.zeros((3, 3)))
    assert read_ply(path).points.shape == (3, 3)


def test_a_full_disk_names_the_file_and_leaves_nothing(tmp_path, monkeypatch):
    import errno
    import os

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(OSError) as caught:
        write_ply(tmp_path / "scan.ply", np.zeros((3, 3)))
    assert caught.value.filename == str(tmp_path / "scan.ply") and caught.value.errno == errno.ENOSPC
    assert list(tmp_path.iterdir()) == []


def test_an_array_header_declaring_more_than_the_file_holds_is_refused(tmp_path):
    """A member whose header declares 10¹² × 3 float64 values (24 TB) while the file holds 24 bytes."""
    path = tmp_path / "forged.npz"
    save_npz(path, "breastplan.dataset/1", {"points": np.zeros((1, 3))})
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": (10**12, 3)})
    with zipfile.ZipFile(path, "a") as archive:
        archive.writestr("huge.npy", header.getvalue() + b"\0" * 24)   # the header writes its own magic
    with pytest.raises(ArtefactError, match=r"forged\.npz: has an array 'huge' whose header declares 1000000000000×3"):
        load_npz(path, "breastplan.dataset/1")


def test_a_ply_declaring_more_vertices_than_any_scan_is_refused_before_its_body_is_read(tmp_path):
    path = tmp_path / "huge.ply"
    path.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 89000000\nproperty float x\n"
                     b"property float y\nproperty float z\nend_header\n" + b"\0" * 1200)
    with pytest.raises(ArtefactError, match=r"huge\.ply: declares 89,000,000 'vertex' elements, more than any body scan"):
        read_ply(path)


def test_a_foreign_file_is_refused_from_its_first_bytes(tmp_path):
    path = tmp_path / "photo.ply"
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + b"\0" * (1 << 20))
    with pytest.raises(ArtefactError, match="is not a PLY file"):
        read_ply(path)


def test_npz_metadata_types(tmp_path):
    """Truth: metadata is one JSON object; an entry of another JSON type than the spec names is
    refused by its dotted name, an absent one passes, and an integer is a number."""
    meta_spec = {"n": int, "x": float, "tags": [str], "who": {"name": str, "*": (str, int)}}
    good = {"n": 3, "x": 2, "tags": ["a"], "who": {"name": "b", "age": 4}}
    path = save_npz(tmp_path / "a.npz", "breastplan.test/1", {"v": np.zeros(2)}, meta=good)
    assert load_npz(path, "breastplan.test/1", meta_spec=meta_spec).meta == good
    assert load_npz(save_npz(tmp_path / "b.npz", "breastplan.test/1", {"v": np.zeros(2)}), "breastplan.test/1",
                    meta_spec=meta_spec).meta == {}
    for meta, problem in [({"n": True}, "'n' that is a boolean, not an integer"),
                          ({"n": 1.5}, "'n' that is a number, not an integer"),
                          ({"x": "1"}, "'x' that is a string, not a number"),
                          ({"tags": "a"}, "'tags' that is a string, not a list"),
                          ({"tags": ["a", 2]}, "'tags.1' that is an integer, not a string"),
                          ({"who": {"name": None}}, "'who.name' that is null, not a string"),
                          ({"who": {"age": [4]}}, "'who.age' that is a list, not a string or an integer")]:
        bad = save_npz(tmp_path / "c.npz", "breastplan.test/1", {"v": np.zeros(2)}, meta=meta)
        with pytest.raises(ArtefactError, match=problem):
            load_npz(bad, "breastplan.test/1", meta_spec=meta_spec)
    np.savez(tmp_path / "d.npz", schema=np.str_("breastplan.test/1"), meta=np.str_("[1, 2]"))
    with pytest.raises(ArtefactError, match="metadata that is a list, not a JSON object"):
        load_npz(tmp_path / "d.npz", "breastplan.test/1")
    np.savez(tmp_path / "e.npz", schema=np.str_("breastplan.test/1"), meta=np.str_("[" * 100_000 + "]" * 100_000))
    with pytest.raises(ArtefactError, match="metadata that is not valid JSON"):          # deeper than json recurses
        load_npz(tmp_path / "e.npz", "breastplan.test/1")


def test_a_journal_nested_deeper_than_json_recurses_is_no_journal(tmp_path):
    """A leftover `.x.commit` that is not a journal is ignored by the next write into its folder."""
    (tmp_path / ".a.txt.commit").write_text('{"schema":' * 100_000 + "1" + "}" * 100_000)
    with atomic_set() as stage:
        Path(stage(tmp_path / "a.txt")).write_text("new a")
    assert (tmp_path / "a.txt").read_text() == "new a"


def test_json_text_is_strict_json():
    """Truth: JSON has no NaN or Infinity (RFC 8259), so a strict parser reads all breastplan writes."""
    text = to_json({"v": float("nan"), "w": [np.float64("inf"), np.int64(3)], "a": np.array([1.5, -np.inf]),
                    "t": (1, "x"), "p": Path("/x")})
    assert json.loads(text, parse_constant=lambda name: pytest.fail(f"{name} in {text}")) == \
        {"v": None, "w": [None, 3], "a": [1.5, None], "t": [1, "x"], "p": "/x"}


def test_a_set_with_a_folder_where_a_file_goes_is_refused_before_its_commit(tmp_path):
    """Truth: all or nothing — a set that could not rename every file is not begun: no file of it
    replaced, no journal left for every later write to trip on, the target named."""
    (tmp_path / "a.txt").write_text("old a")
    (tmp_path / "b.txt").mkdir()
    with pytest.raises(IsADirectoryError) as err:
        with atomic_set() as stage:
            Path(stage(tmp_path / "a.txt")).write_text("new a")
            Path(stage(tmp_path / "b.txt")).write_text("new b")
    assert err.value.filename == str(tmp_path / "b.txt")
    assert (tmp_path / "a.txt").read_text() == "old a" and sorted(os.listdir(tmp_path)) == ["a.txt", "b.txt"]
    (tmp_path / "sub").write_text("a file")
    with pytest.raises(NotADirectoryError) as err:
        with atomic_set() as stage:
            Path(stage(tmp_path / "sub" / "c.txt")).write_text("c")
    assert err.value.filename == str(tmp_path / "sub")
    assert sorted(os.listdir(tmp_path)) == ["a.txt", "b.txt", "sub"]
