"""The `breastplan` command end to end through files, as a user runs it (docs/cli.md exit codes)."""
import contextlib
import json
import os
import subprocess

import numpy as np
import pytest

from breastplan import Primitive, read_ply, to_mm, to_model_units, write_ply

from clitools import assert_bad_input, run


@pytest.fixture(scope="module")
def synth_s(cli, tmp_path_factory):
    out = tmp_path_factory.mktemp("synth") / "S"
    res = run(cli, "synth", "--db", "S", "--points", 2500, "--out", out, "--ply", "--json")
    assert res.returncode == 0, res.stderr
    return out, json.loads(res.stdout)


def test_synth_writes_database_and_plys(synth_s):
    out, info = synth_s
    assert (info["breasts"], info["train"], info["test"], info["points_per_breast"]) == (60, 48, 12, 2500)
    assert (out / "database.npz").is_file()
    assert len(list(out.glob("S-shape*.ply"))) == 60


def test_deform_round_trip_matches_the_formula(cli, synth_s, tmp_path):
    out, _ = synth_s
    src = out / "S-shape3-04.ply"
    res = run(cli, "deform", src, "--kind", "ptosis", "--param", "b0=1.125", "--param", "b1=0.25",
              "--out", tmp_path / "d.ply", "--json")
    assert res.returncode == 0, res.stderr
    before, after = read_ply(src).points, read_ply(tmp_path / "d.ply").points
    zeta = before[:, 2] / 60.0                         # ζ = z/10 in model units, z_mm/6 = z_mu
    assert np.allclose(after[:, 1], before[:, 1] - 6 * (1.125 * zeta + 0.25 * zeta**2))
    assert np.array_equal(after[:, [0, 2]], before[:, [0, 2]])
    info = json.loads(res.stdout)
    assert info["points"] == 2500 and info["params"] == {"b0": 1.125, "b1": 0.25}


def test_deform_with_primitive(cli, synth_s, tmp_path):
    out, _ = synth_s
    res = run(cli, "deform", out / "S-shape1-00.ply", "--kind", "flatten-side", "--param", "h0=0.1",
              "--primitive", "a1=10,a2=10,a3=10,a4=10,a5=10", "--out", tmp_path / "f.ply")
    assert res.returncode == 0, res.stderr
    before, after = read_ply(out / "S-shape1-00.ply").points, read_ply(tmp_path / "f.ply").points
    medial = before[:, 0] >= 0
    assert np.array_equal(after[medial], before[medial])
    assert np.array_equal(after[:, 1:], before[:, 1:])
    # closed form (docs/model.md §3): h = (0.1, 0), g = 0.9, γ(w) = (0 + 2 − 1.8)w³ + (2.7 − 3 − 0)w² + 1
    # = 0.2w³ − 0.3w² + 1 with w = |x|/a2, a2 = 10 mu = 60 mm; x ← x·γ(w) on the lateral half x < 0
    w = -before[~medial, 0] / 60.0
    assert np.allclose(after[~medial, 0], before[~medial, 0] * (0.2 * w**3 - 0.3 * w**2 + 1), rtol=0, atol=1e-5)


def test_deform_reads_the_primitive_a_synth_ply_carries(cli, synth_s, tmp_path):
    """Truth: top-shape of the database breast's own primitive (docs/model.md §3), applied by hand."""
    from breastplan.deform.global_deformations import top_shape
    from breastplan.learn.databases import build_database
    out, _ = synth_s
    db_s = build_database("S", n_points=2500)
    res = run(cli, "deform", out / "S-shape1-00.ply", "--kind", "top-shape", "--param", "s0=-2.5,s1=2",
              "--out", tmp_path / "t.ply", "--json")
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["primitive"] == "carried by the input"
    i = db_s.index("S-shape1-00")
    expected = to_mm(top_shape(to_model_units(db_s.points[i]), -2.5, 2, 0, 0, primitive=db_s.primitive(i)))
    written = read_ply(tmp_path / "t.ply")
    assert np.allclose(written.points, expected, atol=1e-9)
    assert Primitive.from_comments(written.comments) == db_s.primitive(i)      # carried on, for the next deform


def test_deform_without_a_primitive_anywhere_is_a_usage_error(cli, tmp_path):
    write_ply(tmp_path / "bare.ply", np.random.default_rng(0).normal(size=(100, 3)) * 30)
    res = run(cli, "deform", tmp_path / "bare.ply", "--kind", "top-shape", "--param", "s0=1", "--out", tmp_path / "o.ply")
    assert res.returncode == 2 and "carries none" in res.stderr and not (tmp_path / "o.ply").exists()


def test_dataset_command(cli, synth_s, tmp_path):
    out, _ = synth_s
    res = run(cli, "dataset", "--db", out / "database.npz", "--condition", "ptosis b0>b1", "--dd", 8,
              "--out", tmp_path / "ds.npz", "--json")
    assert res.returncode == 0, res.stderr
    info = json.loads(res.stdout)
    assert info["examples"] == 480 and sum(info["examples_per_degree"]) == 480
    assert np.all(np.diff(info["reference_extents"]) > 0)



@pytest.mark.parametrize("content", [b"ply\nformat binary_little_endian 1.0\nelement vertex 100\n"
                                     b"property double x\nproperty double y\nproperty double z\nend_header\n" + b"\0" * 50,
                                     b"\x89PNG\r\n\x1a\n", b""])
def test_corrupt_ply_exits_3_and_writes_nothing(cli, tmp_path, content):
    bad = tmp_path / "corrupt.ply"
    bad.write_bytes(content)
    res = run(cli, "deform", bad, "--kind", "turn", "--param", "c0=1", "--out", tmp_path / "out.ply")
    assert_bad_input(res, bad, tmp_path)


def test_wrong_schema_npz_exits_3_and_writes_nothing(cli, synth_s, tmp_path):
    out, _ = synth_s
    ok = run(cli, "dataset", "--db", out / "database.npz", "--condition", "turn c1>c0", "--dd", 4,
             "--out", tmp_path / "ds.npz")
    assert ok.returncode == 0, ok.stderr
    res = run(cli, "dataset", "--db", tmp_path / "ds.npz", "--condition", "turn c1>c0", "--dd", 4,
              "--out", tmp_path / "out.ply")
    assert_bad_input(res, tmp_path / "ds.npz", tmp_path)
    assert "breastplan.database/1" in res.stderr


def test_missing_and_nan_inputs_exit_3(cli, tmp_path):
    res = run(cli, "deform", tmp_path / "absent.ply", "--kind", "turn", "--out", tmp_path / "out.ply")
    assert_bad_input(res, tmp_path / "absent.ply", tmp_path)
    nan = tmp_path / "nan.ply"
    nan.write_text("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                   "property float z\nend_header\nnan 0 0\n")
    assert_bad_input(run(cli, "deform", nan, "--kind", "turn", "--out", tmp_path / "out.ply"), nan, tmp_path)


@pytest.mark.parametrize("args", [
    ["deform", "x.ply", "--kind", "ptosis", "--param", "b0=1", "--degree", "3", "--out", "o.ply"],  # both
    ["deform", "x.ply", "--kind", "sag", "--out", "o.ply"],                                # unknown kind
    ["deform", "x.ply", "--kind", "ptosis", "--param", "c0=1", "--out", "o.ply"],          # wrong parameter
    ["deform", "x.ply", "--kind", "ptosis", "--param", "b0=lots", "--out", "o.ply"],       # not a number
    ["deform", "x.ply", "--kind", "ptosis", "--param", "b0=1,b0=2", "--out", "o.ply"],     # which b0?
    ["deform", "x.ply", "--kind", "ptosis", "--param", "=1", "--out", "o.ply"],            # no name
    ["synth", "--db", "Q", "--out", "o"],
    ["synth", "--db", "S", "--points", "1000", "--out", "o"],
    ["synth", "--db", "S", "--seed", "-1", "--out", "o"],
    ["synth", "--db", "S", "--points", str(10**8), "--out", "o"],                        # 10⁴ × 10⁴ grid
    ["dataset", "--db", "x.npz", "--condition", "ptosis b0", "--dd", "100000", "--out", "o.npz"],
    ["dataset", "--db", "x.npz", "--condition", "ptosis sideways", "--out", "o.npz"],
    ["dataset", "--db", "x.npz", "--condition", "ptosis b0", "--out", "./x.npz"],          # would replace its input
    ["evaluate", "--study", "statistical", "--dd", "4", "--out", "o"],                    # no degrees to count
    ["evaluate", "--study", "ptosis-V", "--dd", "5", "--out", "o"],
    ["evaluate", "--study", "ptosis-V", "--cache", "c", "--out", "o"],             # no FFD to cache
    ["deform", "x.ply", "--kind", "ptosis", "--param", "b0=1", "--out", ""],            # the current folder
    ["batch", ".", "--out", "."],                                   # its cases would be the next batch's scans
])
def test_usage_errors_exit_2(cli, tmp_path, args):
    res = subprocess.run([cli, *args], capture_output=True, text=True, cwd=tmp_path)
    assert res.returncode == 2, res.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("args", [["train", "--quick"], ["evaluate", "--study", "ptosis-V", "--quick"],
                                  ["evaluate", "--study", "statistical", "--quick"]])
def test_a_report_folder_that_is_a_file_is_refused_before_any_work(cli, tmp_path, args):
    """Truth: an output that cannot be written is said before the work, not after it (minutes)."""
    (tmp_path / "taken").write_text("a file")
    res = run(cli, *args, "--out", tmp_path / "taken")
    assert_bad_input(res, tmp_path / "taken", tmp_path)
    assert "is a file, not a folder" in res.stderr and (tmp_path / "taken").read_text() == "a file"


def test_an_output_that_would_replace_what_is_read_is_a_usage_error(cli, synth_s, tmp_path):
    """deform and filter read their input whole before they write: an --out naming the input (by any path
    or link) would replace the patient's scan, and one naming a case's own file would leave the case
    disagreeing with itself."""
    out, _ = synth_s
    body = tmp_path / "body.ply"
    body.write_bytes((out / "S-shape1-00.ply").read_bytes())
    (tmp_path / "case").mkdir()
    (tmp_path / "case" / "scan.npz").write_bytes(b"a case's scan")
    (tmp_path / "case" / "fit.ply").write_bytes(b"a case's fit")
    os.link(body, tmp_path / "hard.ply")
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    for target in (body, tmp_path / "case" / ".." / "body.ply", tmp_path / "hard.ply", tmp_path / "case" / "fit.ply"):
        for command in (["deform", body, "--kind", "ptosis", "--param", "b0=1"],
                        ["filter", "apply_breast_ptosis", body, "--param", "degree=3"]):
            res = run(cli, *command, "--out", target)
            assert res.returncode == 2 and "--out" in res.stderr, (command, target, res.stderr)
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == before


def test_a_reader_that_went_away_ends_the_command_as_it_ends_any_tool(cli):
    """`breastplan filters | head -1`: head exits, the pipe closes; the command ends by SIGPIPE, as cat or
    ls do, with nothing on stderr (not a traceback, nor exit 1, which says breastplan has a bug)."""
    import signal

    read, write = os.pipe()
    os.close(read)
    res = subprocess.run([cli, "filters"], stdout=write, stderr=subprocess.PIPE, text=True, timeout=600)
    os.close(write)
    assert res.returncode == -signal.SIGPIPE and res.stderr == ""


def test_help_lists_the_commands(cli):
    res = run(cli, "--help")
    assert res.returncode == 0
    for command in ("synth", "deform", "dataset"):
        assert command in res.stdout


def test_parameters_that_overflow_give_one_sentence_and_no_file(cli, synth_s, tmp_path):
    out, _ = synth_s
    res = run(cli, "deform", out / "S-shape1-00.ply", "--kind", "ptosis", "--param", "b0=1e308",
              "--out", tmp_path / "big.ply")
    assert_bad_input(res, out / "S-shape1-00.ply", tmp_path)
    assert "sends points to infinity" in res.stderr


def test_deform_of_a_breast_in_metres_is_bad_input(cli, synth_s, tmp_path):
    out, _ = synth_s
    metres = tmp_path / "metres.ply"
    write_ply(metres, read_ply(out / "S-shape1-00.ply").points / 1000)
    res = run(cli, "deform", metres, "--kind", "ptosis", "--param", "b0=1", "--out", tmp_path / "outm.ply")
    assert_bad_input(res, metres, tmp_path)
    assert "is it in metres" in res.stderr


@pytest.mark.parametrize("command", ["deform", "ingest"])
def test_an_ascii_ply_with_a_line_of_four_numbers_is_bad_input(cli, tmp_path, command):
    rows = np.random.default_rng(0).uniform(0, 100, (60, 3))
    text = "\n".join(" ".join(f"{v:.3f}" for v in row) for row in rows).replace("\n", " 5.0\n", 1)
    bad = tmp_path / "four.ply"
    bad.write_text("ply\nformat ascii 1.0\nelement vertex 60\nproperty float x\nproperty float y\n"
                   "property float z\nend_header\n" + text + "\n")
    args = ["--kind", "ptosis", "--param", "b0=1"] if command == "deform" else ["--side", "left"]
    res = run(cli, command, bad, *args, "--out", tmp_path / "out_four")
    assert_bad_input(res, bad, tmp_path)
    assert "1 value more than its header declares" in res.stderr


def test_a_default_cache_that_cannot_be_written_is_no_cache_and_a_given_one_is_refused(tmp_path, monkeypatch, capsys):
    """A cache is never needed: a read-only home (or $BREASTPLAN_CACHE naming a file) only costs the
    reuse of fits; a --cache that cannot be written is the user's own mistake, said before any work."""
    from breastplan import BadInputError
    from breastplan.cli.output import cache_folder

    (tmp_path / "file").write_text("not a folder")
    monkeypatch.setenv("BREASTPLAN_CACHE", str(tmp_path / "file"))
    assert cache_folder(None) is None
    assert "note: FFD fits are not cached on disk" in capsys.readouterr().err
    monkeypatch.setenv("BREASTPLAN_CACHE", str(tmp_path / "cache"))
    assert cache_folder(None) == tmp_path / "cache"
    with pytest.raises(BadInputError, match="is a file, not a folder"):
        cache_folder(tmp_path / "file")


@pytest.mark.parametrize("ending", [None, SystemExit(0), RuntimeError("a bug")])
def test_a_warning_raised_on_the_way_is_shown_once_after_the_command(monkeypatch, ending):
    """A warning held during a command is shown when it ends (successfully, or not by a refusal), once;
    showing it must not be recorded again (showing while recording appended to the list being shown,
    for ever)."""
    import warnings

    import breastplan.cli.main as cli_main

    def command():
        warnings.warn("numpy said so", RuntimeWarning)
        if ending is not None:
            raise ending
    shown = []
    monkeypatch.setattr(cli_main, "_run", command)
    monkeypatch.setattr(cli_main.sys, "stdout", cli_main.sys.stdout)   # main() wraps stdout; undone after
    monkeypatch.setattr(warnings, "showwarning", lambda message, *rest: shown.append(str(message)))
    with pytest.raises(type(ending)) if ending is not None else contextlib.nullcontext():
        cli_main.main()
    assert shown == ["numpy said so"]
