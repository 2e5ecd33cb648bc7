"""Pairs folders (learn/pair_folder.py, docs/artefacts.md): before/after breasts labelled by type and degree,
exported from deformation datasets by `write_pairs` / `synth --pairs` and read back by `read_pairs`."""
import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from breastplan import ArtefactError, BadInputError, Primitive, read_ply, write_ply
from breastplan.atomic import atomic_set
from breastplan.case import Case, Provenance, Scan, Source
from breastplan.chest_wall import ChestWall
from breastplan.deform.conditions import CONDITIONS
from breastplan.learn.databases import Database, build_database
from breastplan.learn.datasets import build_dataset
from breastplan.learn.pair_folder import PAIRS_CSV, PairRow, breast_cloud, count_files, read_pairs, write_pairs

from clitools import run

HEADER = "before,after,type,degree,split,condition\n"
CONDITION_NAMES = ("ptosis b0>b1", "top-shape s1->s0+")


def hemisphere(n=300, radius=60.0, seed=0):
    """A breast-sized point cloud in millimetres, base on z = 0."""
    v = np.random.default_rng(seed).normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2])
    return radius * v / np.linalg.norm(v, axis=1, keepdims=True)


def pairs_folder(root: Path, csv_text: str | bytes) -> Path:
    """A folder with two breast PLYs (a.ply, b.ply) and pairs.csv holding `csv_text`."""
    root.mkdir(parents=True, exist_ok=True)
    write_ply(root / "a.ply", hemisphere(seed=1))
    write_ply(root / "b.ply", hemisphere(seed=2))
    (root / PAIRS_CSV).write_bytes(csv_text.encode() if isinstance(csv_text, str) else csv_text)
    return root


def a_scan(points):
    normals = points / np.linalg.norm(points, axis=1, keepdims=True)
    return Scan(points=points, normals=normals, torso_camera=hemisphere(500, 300.0, seed=9),
                input_to_breast=np.diag([1.0, -1.0, -1.0, 1.0]), input_to_view=np.eye(4), side="left",
                nipple_camera_mm=np.array([0.0, 0.0, -60.0]),             # 60 mm in front of the wall at z = 0
                chest_wall=ChestWall.from_array(np.r_[2.0, 0.0, 0.0, 1.0, np.zeros(6)]),
                mound_centre_view_mm=np.zeros(2), mound_radius_mm=80.0, crop_height_mm=2.0,
                roi_camera_mm=None, voxel_mm=2.0, source=Source("file", "test hemisphere"),
                provenance=Provenance())


# --- export and read back ---------------------------------------------------------------

@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    db = build_database("S", n_points=400)
    datasets = [build_dataset(db, name, 8) for name in CONDITION_NAMES]
    folder = tmp_path_factory.mktemp("pairs") / "out"
    with atomic_set() as stage:
        csv_path = write_pairs(folder, datasets, stage)
    return folder, csv_path, db, datasets, read_pairs(folder)


def test_export_writes_a_folder_read_pairs_accepts_with_one_row_per_example(exported):
    folder, csv_path, db, datasets, rows = exported
    assert csv_path == folder / PAIRS_CSV and csv_path.is_file()
    assert len(rows) == 2 * 60 * 8 == sum(len(ds) for ds in datasets) == count_files(datasets) - 60
    assert all(isinstance(r, PairRow) and r.before.is_absolute() and r.after.is_absolute() for r in rows)
    assert len(list((folder / "before").glob("*.ply"))) == len(db)            # each breast once
    assert len({r.after for r in rows}) == len(rows)                          # one after file per example
    assert not [p for p in folder.rglob("*") if p.name.endswith((".part", ".commit"))]


def test_every_pair_holds_the_database_breast_and_its_deformation(exported):
    folder, _, db, datasets, rows = exported
    by_name = {ds.condition.name: ds for ds in datasets}
    seen = set()
    for r in rows:
        ds = by_name[r.condition]
        i = db.index(r.before.stem)
        breast, _, d = r.after.stem.rpartition("-d")
        assert breast == r.before.stem
        k = int(np.flatnonzero((ds.breast == i) & (ds.row == int(d) - 1))[0])
        seen.add((r.condition, k))
        before, after = read_ply(r.before), read_ply(r.after)
        np.testing.assert_array_equal(before.points, db.points[i])         # float64 PLYs: exact
        np.testing.assert_array_equal(after.points, ds.deformed_points(k))
        assert r.kind == ds.condition.kind and r.degree == ds.degree[k] and r.split == db.split[i]
        assert Primitive.from_comments(after.comments) == db.primitive(i)
    assert seen == {(c, k) for c, ds in by_name.items() for k in range(len(ds))}


def test_breast_cloud_reads_exported_plys_and_the_plys_say_what_they_are(exported):
    folder, _, db, datasets, rows = exported
    r = rows[-1]
    np.testing.assert_array_equal(breast_cloud(r.before), db.points[db.index(r.before.stem)])
    before, after = read_ply(r.before), read_ply(r.after)
    assert any("before" in c and r.before.stem in c for c in before.comments)
    assert any("after" in c and r.condition in c and f"degree {int(r.degree)}" in c for c in after.comments)
    assert Primitive.from_comments(before.comments) == db.primitive(db.index(r.before.stem))


def test_splits_and_degrees_follow_the_database_and_dataset(exported):
    _, _, db, datasets, rows = exported
    train_breasts = int((db.split == "train").sum())
    assert sum(r.split == "train" for r in rows) == 2 * 8 * train_breasts
    for ds in datasets:
        degrees = [r.degree for r in rows if r.condition == ds.condition.name]
        assert sorted(degrees) == sorted(ds.degree.astype(float).tolist())


def test_a_failed_export_in_an_atomic_set_leaves_nothing(tmp_path):
    db = build_database("S", n_points=100)
    ds = build_dataset(db, "turn c0>c1", 8)
    with pytest.raises(RuntimeError), atomic_set() as stage:
        write_pairs(tmp_path / "out", ds, stage)            # one Dataset, not a list
        raise RuntimeError("killed before the commit point")
    assert list(tmp_path.rglob("*")) == []                  # the folders the set made too


def test_datasets_that_cannot_make_one_pairs_folder_are_refused_before_writing(tmp_path):
    db = build_database("S", n_points=100)
    ds = build_dataset(db, "turn c0>c1", 8)
    other = build_dataset(build_database("S", seed=1, n_points=100), "ptosis b0", 8)   # same names, other breasts
    for datasets in ([ds, ds], [build_dataset(db, "ptosis b0", 4)], [ds, other]):
        with pytest.raises(ValueError), atomic_set() as stage:
            write_pairs(tmp_path / "out", datasets, stage)
    assert [p for p in tmp_path.rglob("*") if not p.is_dir()] == []


# --- the command ----------------------------------------------------------------------------

def test_synth_pairs_writes_a_pairs_folder(cli, tmp_path):
    out = tmp_path / "S"
    res = run(cli, "synth", "--pairs", "ptosis b0>b1", "--db", "S", "--points", 400, "--out", out, "--json")
    assert res.returncode == 0, res.stderr
    info = json.loads(res.stdout)
    assert info["pairs"] == str(out / PAIRS_CSV) and info["pair_count"] == 60 * 8
    rows = read_pairs(out)
    assert len(rows) == 60 * 8
    assert {r.kind for r in rows} == {"ptosis"} and {r.condition for r in rows} == {"ptosis b0>b1"}
    assert sum(r.split == "test" for r in rows) == 12 * 8
    assert {r.degree for r in rows} <= set(map(float, range(1, 9)))
    db = Database.load(out / "database.npz")                 # written in the same set
    for r in rows[::37]:
        np.testing.assert_array_equal(breast_cloud(r.before), db.points[db.index(r.before.stem)])


def test_synth_without_pairs_reports_none(cli, tmp_path):
    res = run(cli, "synth", "--db", "S", "--points", 9, "--out", tmp_path / "S", "--json")
    assert res.returncode == 0, res.stderr
    info = json.loads(res.stdout)
    assert info["pairs"] is None and info["pair_count"] == 0
    assert not (tmp_path / "S" / PAIRS_CSV).exists()


@pytest.mark.parametrize("name", ["sideways", "ptosis", "b2", ""])
def test_synth_pairs_of_an_unknown_condition_is_a_usage_error(cli, tmp_path, name):
    res = subprocess.run([cli, "synth", "--db", "S", "--points", "400", "--out", "o", "--pairs", name],
                         capture_output=True, text=True, cwd=tmp_path, timeout=600)
    assert res.returncode == 2, res.stderr
    assert "--pairs" in res.stderr
    assert list(tmp_path.iterdir()) == []


def test_pairs_all_is_the_six_deployed_conditions_once():
    from breastplan.cli.synth import _pair_conditions

    deployed = ["ptosis b0>b1", "ptosis b1>=b0", "turn c0>c1", "turn c1>c0", "top-shape s0->s1+",
                "top-shape s1->s0+"]
    assert [c.name for c in _pair_conditions(["all"])] == deployed
    assert [c.name for c in _pair_conditions(["b1>=b0", "ALL", "ptosis b0"])] == [
        "ptosis b1>=b0", *[d for d in deployed if d != "ptosis b1>=b0"], "ptosis b0"]


# --- reading: what is accepted ---------------------------------------------------------------

def test_variants_a_spreadsheet_writes_are_accepted(tmp_path):
    folder = tmp_path / "DIR"
    text = ("\ufeff Before , AFTER,Type,degree,notes,Split\r\n"             # BOM, spaces, case, extra column
            "a.ply,b.ply,ptosis,5.5,left side,\r\n"                         # empty split: train
            "\r\n"
            ",,,,,\r\n"                                                       # an all-empty row
            f"{folder.resolve() / 'b.ply'},a.ply,top_shape,1,,TEST\r\n")   # absolute inside, top_shape
    rows = read_pairs(pairs_folder(folder, text))
    assert rows == [
        PairRow(folder.resolve() / "a.ply", folder.resolve() / "b.ply", "ptosis", 5.5, "train", None),
        PairRow(folder.resolve() / "b.ply", folder.resolve() / "a.ply", "top-shape", 1.0, "test", None)]


def test_a_short_condition_name_is_made_canonical(tmp_path):
    rows = read_pairs(pairs_folder(tmp_path, HEADER + "a.ply,b.ply,ptosis,3,train,b0>b1\n"
                                             "a.ply,./sub/../b.ply,turn,8,,turn c1>c0\n"))
    assert [r.condition for r in rows] == ["ptosis b0>b1", "turn c1>c0"]
    assert rows[1].after == tmp_path.resolve() / "b.ply"


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(degree=st.floats(allow_nan=True, allow_infinity=True) | st.floats(0.5, 8.5))
def test_a_degree_is_accepted_exactly_when_it_is_a_number_from_1_to_8(tmp_path, degree):
    folder = pairs_folder(tmp_path / "d", HEADER + f"a.ply,b.ply,turn,{degree!r},train,\n")
    if 1.0 <= degree <= 8.0:
        assert read_pairs(folder)[0].degree == degree
    else:
        with pytest.raises(BadInputError, match=r"pairs\.csv: line 2: degree"):
            read_pairs(folder)


def test_a_case_folder_can_be_a_before_or_after(tmp_path):
    points = hemisphere(400, seed=5)
    Case(tmp_path / "DIR" / "patient-1").save_scan(a_scan(points))
    folder = pairs_folder(tmp_path / "DIR", HEADER + "patient-1,a.ply,ptosis,2,,\n")
    (row,) = read_pairs(folder)
    assert row.before == (tmp_path / "DIR" / "patient-1").resolve()
    np.testing.assert_array_equal(breast_cloud(row.before), points)


# --- reading: what is refused -------------------------------------------------------------------

LINE2 = "a.ply,b.ply,ptosis,3,train,\n"


@pytest.mark.parametrize("text, line, words", [
    ("before,after,type\n" + "a.ply,b.ply,ptosis\n", 1, "degree"),
    ("before,after,kind,degree\n" + "a.ply,b.ply,ptosis,3\n", 1, "type"),
    ("before,after,type,degree,split,split\n" + LINE2, 1, "twice"),
    (HEADER + "a.ply,b.ply,sag,3,,\n", 2, "type 'sag'"),
    (HEADER + "a.ply,b.ply,flatten-side,3,,\n", 2, "type 'flatten-side'"),
    (HEADER + "a.ply,b.ply,,3,,\n", 2, "no type"),
    (HEADER + LINE2 + "a.ply,b.ply,ptosis,three,,\n", 3, "degree 'three' is not a number"),
    (HEADER + "a.ply,b.ply,ptosis,,,\n", 2, "no degree"),
    (HEADER + "a.ply,b.ply,ptosis,nan,,\n", 2, "finite"),
    (HEADER + "a.ply,b.ply,ptosis,inf,,\n", 2, "finite"),
    (HEADER + "a.ply,b.ply,ptosis,0,,\n", 2, "outside [1, 8]"),
    (HEADER + "a.ply,b.ply,ptosis,8.01,,\n", 2, "outside [1, 8]"),
    (HEADER + "a.ply,b.ply,ptosis,3,validation,\n", 2, "split 'validation'"),
    (HEADER + LINE2 + "\n" + "a.ply,c.ply,ptosis,3,,\n", 4, "'c.ply' does not exist"),   # blank line 3 counted
    (HEADER + "a.ply,,ptosis,3,,\n", 2, "no after path"),
    (HEADER + "../outside.ply,b.ply,ptosis,3,,\n", 2, "outside the pairs folder"),
    (HEADER + "a.ply,sub/../../outside.ply,ptosis,3,,\n", 2, "outside the pairs folder"),
    (HEADER + "a.ply,{outside},ptosis,3,,\n", 2, "outside the pairs folder"),             # absolute
    (HEADER + "a.ply,link.ply,ptosis,3,,\n", 2, "outside the pairs folder"),              # a link out
    (HEADER + "a.ply,.,ptosis,3,,\n", 2, "outside the pairs folder"),                     # the folder itself
    (HEADER + "a.ply,sub,ptosis,3,,\n", 2, "not a case folder"),
    (HEADER + "a.ply,b.ply,ptosis,3,,b1>=b0,surplus\n", 2, "more than the header's 6"),
    (HEADER + "a.ply,b.ply,ptosis,3,,sideways\n", 2, "condition 'sideways'"),
    (HEADER + "a.ply,b.ply,turn,3,,ptosis b0>b1\n", 2, "changes ptosis, not the row's type turn"),
    (HEADER + 'a.ply,b.ply,ptosis,3,,"b0\n', 2, "not valid CSV"),
    (HEADER + LINE2 + "a.ply,b.ply,ptosis,3,,\xff\n", 3, "not UTF-8"),
    (HEADER, None, "no pairs"),
    ("\n \n", None, "no header"),
    (HEADER + "a.ply,b.ply,ptosis,3,test,\n" + "b.ply,a.ply,turn,2,test,\n", None,
     "no training pair: all 2 pairs are in the test split"),
    (HEADER + "a.ply,b.ply,ptosis,3,test,\n", None, "no training pair: 1 pair is in the test split"),
])
def test_a_defective_table_is_bad_input_naming_pairs_csv_and_the_line(tmp_path, text, line, words):
    outside = tmp_path / "outside.ply"
    write_ply(outside, hemisphere())
    if "\xff" in text:
        text = text.encode().replace("\xff".encode(), b"\xff")
    folder = pairs_folder(tmp_path / "DIR", text.replace("{outside}", str(outside)) if isinstance(text, str) else text)
    (folder / "sub").mkdir()
    (folder / "link.ply").symlink_to(outside)
    with pytest.raises(BadInputError) as err:
        read_pairs(folder)
    message = str(err.value)
    assert message.startswith(f"{folder / PAIRS_CSV}: ")
    assert words in message
    if line is not None:
        assert f"line {line}:" in message
    assert "\n" not in message


def test_a_table_of_more_pairs_than_breastplan_trains_on_is_refused_and_repeated_rows_are_read(tmp_path):
    from breastplan.learn.pair_folder import MAX_PAIRS

    folder = pairs_folder(tmp_path / "DIR", HEADER + LINE2 * MAX_PAIRS)
    rows = read_pairs(folder)
    assert len(rows) == MAX_PAIRS and rows[0] == rows[-1]
    (folder / PAIRS_CSV).write_text(HEADER + LINE2 * (MAX_PAIRS + 1))
    with pytest.raises(BadInputError, match=f"holds more than {MAX_PAIRS:,} pairs"):
        read_pairs(folder)


def test_a_missing_folder_or_table_is_bad_input_naming_it(tmp_path):
    for folder, named in [(tmp_path / "nowhere", tmp_path / "nowhere"), (tmp_path, tmp_path / PAIRS_CSV)]:
        with pytest.raises(BadInputError, match="no such") as err:
            read_pairs(folder)
        assert err.value.path == named
    (tmp_path / "file").write_text("x")
    with pytest.raises(BadInputError, match="not a pairs folder"):
        read_pairs(tmp_path / "file")
    (tmp_path / PAIRS_CSV).write_bytes(b"")
    with pytest.raises(BadInputError, match="empty") as err:
        read_pairs(tmp_path)
    assert err.value.path == tmp_path / PAIRS_CSV
    (tmp_path / PAIRS_CSV).unlink()
    (tmp_path / PAIRS_CSV).mkdir()
    with pytest.raises(BadInputError, match="folder") as err:
        read_pairs(tmp_path)
    assert err.value.path == tmp_path / PAIRS_CSV


# --- breast_cloud --------------------------------------------------------------------------------

def test_breast_cloud_returns_the_points_exactly(tmp_path):
    points = hemisphere(100, seed=3)                   # 100 points: the least a breast may have
    out = breast_cloud(write_ply(tmp_path / "x.ply", points))
    assert out.dtype == np.float64 and out.shape == (100, 3)
    np.testing.assert_array_equal(out, points)


@pytest.mark.parametrize("make, words", [
    (lambda p: write_ply(p, hemisphere(99)), "99 points, fewer than the 100"),
    (lambda p: write_ply(p, hemisphere(1)), "has 1 point, fewer than the 100"),
    (lambda p: write_ply(p, hemisphere() * 15), "far too large for one breast: if it is a whole scan"),
    (lambda p: write_ply(p, hemisphere() / 1000.0), "metres"),
    (lambda p: write_ply(p, hemisphere() * 1000.0), "micrometres"),
    (lambda p: write_ply(p, np.where(np.arange(300)[:, None] == 7, np.nan, hemisphere())), "NaN"),
    (lambda p: p.write_text("x y z\n1 2 3\n"), "not a PLY"),
    (lambda p: p.write_bytes(write_ply(p, hemisphere()).read_bytes()[:-100]), "truncated"),
    (lambda p: p.write_bytes(b""), "empty"),
    (lambda p: None, "no such file"),
    (lambda p: p.mkdir(), "not a case folder"),
])
def test_breast_cloud_refuses_what_no_breast_is_naming_the_file(tmp_path, make, words):
    path = tmp_path / "breast.ply"
    make(path)
    with pytest.raises(BadInputError, match=words) as err:
        breast_cloud(path)
    assert err.value.path == path and str(err.value).startswith(f"{path}: ")


def test_breast_cloud_of_a_damaged_case_names_the_case_file(tmp_path):
    Case(tmp_path / "c").save_scan(a_scan(hemisphere(400)))
    (tmp_path / "c" / "scan.ply").write_bytes(b"ply\n")
    with pytest.raises(ArtefactError) as err:
        breast_cloud(tmp_path / "c")
    assert err.value.path.parent == tmp_path / "c"


def test_breast_cloud_caches_nothing(tmp_path):
    path = write_ply(tmp_path / "x.ply", hemisphere(seed=1))
    first = breast_cloud(path)
    write_ply(path, hemisphere(seed=2))
    np.testing.assert_array_equal(breast_cloud(path), hemisphere(seed=2))
    assert not np.array_equal(first, hemisphere(seed=2))


def test_the_kinds_planned_by_degree_are_those_with_conditions():
    from breastplan.options import DEGREE_KINDS

    assert set(DEGREE_KINDS) == {c.kind for c in CONDITIONS.values()} == {"ptosis", "turn", "top-shape"}
