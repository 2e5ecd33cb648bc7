"""`scan-synth`'s outputs: checked before any work, written all or nothing, and holding every frame reported."""
import json
import os
import resource
import shutil
import signal
import subprocess

import numpy as np
import pytest
from mcap.reader import make_reader

from breastplan.ingest import recording
from breastplan.scenes import synthetic
from breastplan.ingest.recording import read_recording, write_recording

from clitools import assert_bad_input, run

CHEN = ("scan-synth", "--frames", 1)
MAKEHUMAN = ("scan-synth", "--body", "makehuman", "--resolution", "640x400", "--frames", 1)


def leftovers(folder):
    """Every file and folder under `folder`, as paths relative to it."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def run_in(cli, folder, *args, **kwargs):
    """Run `breastplan ARGS` in `folder`, so that relative paths are the user's own."""
    return subprocess.run([cli, *map(str, args)], capture_output=True, text=True, cwd=folder, **kwargs)


def message_count(path):
    return make_reader(open(path, "rb")).get_summary().statistics.message_count


@pytest.fixture(scope="module")
def scene():
    return synthetic.make_scene(0, 0.0, None, 1.0, {})


# --- every frame recorded ---------------------------------------------------------------
@pytest.mark.parametrize("n", range(1, 9))
def test_the_recording_holds_every_frame(scene, tmp_path, n):
    depth = synthetic.depth_frames(scene, n, 0)                 # 640×400: few frames once lost the last ones
    path = write_recording(tmp_path / "r.mcap", depth, scene.K)
    assert message_count(path) == n + 1                         # the frames and the end marker
    back = read_recording(path)
    assert len(back.depth) == n and np.array_equal(back.depth, depth)
    assert leftovers(tmp_path) == ["r.mcap"]


def test_a_recorder_that_loses_messages_fails_naming_the_file(monkeypatch, tmp_path):
    record = recording._record
    monkeypatch.setattr(recording, "_record", lambda part, messages: record(part, messages[:-1]))
    with pytest.raises(OSError, match="depthai's recorder wrote 2 of the 3 messages") as caught:
        write_recording(tmp_path / "r.mcap", np.full((2, 40, 64), 700, np.uint16), np.diag([45.0, 45.0, 1.0]))
    assert caught.value.filename == str(tmp_path / "r.mcap")
    assert leftovers(tmp_path) == []


def test_a_recorder_that_fails_fails_naming_the_file(tmp_path):
    dai = recording.depthai()
    with pytest.raises(OSError, match="depthai's recorder stopped before it had written every message") as caught:
        recording.record_messages(tmp_path / "r.mcap", [dai.Buffer() for _ in range(3)])   # no type it records
    assert caught.value.filename == str(tmp_path / "r.mcap")
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("n", [3, 4])
def test_scan_synth_reports_the_frames_its_recording_holds(cli, tmp_path, n):
    res = run(cli, "scan-synth", "--out", tmp_path / "r.mcap", "--truth", tmp_path / "t.npz", "--frames", n, "--json")
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["frames"] == n
    assert synthetic.load_truth(tmp_path / "t.npz").meta["frames"] == n
    assert message_count(tmp_path / "r.mcap") == n + 1
    assert len(read_recording(tmp_path / "r.mcap").depth) == n
    assert leftovers(tmp_path) == ["r.mcap", "t.npz"]


# --- outputs checked before any work ----------------------------------------------------
@pytest.mark.parametrize("args, option", [
    ((*CHEN, "--out", "d.mcap", "--truth", "d.mcap"), "--out/--truth"),
    ((*CHEN, "--out", "d.mcap", "--truth", "sub/../d.mcap"), "--out/--truth"),
    ((*MAKEHUMAN, "--out", "e.ply", "--scan-file", "e.ply", "--truth", "t.npz"), "--out/--scan-file"),
    ((*MAKEHUMAN, "--scan-file", "e.ply", "--truth", "e.ply"), "--truth/--scan-file"),
    ((*CHEN, "--out", "x.txt", "--truth", "t.npz"), "--out"),
    ((*CHEN, "--out", "folder", "--truth", "t.npz"), "--out"),
    ((*CHEN, "--out", "x.mcap", "--truth", "t.txt"), "--truth"),
    ((*MAKEHUMAN, "--scan-file", "s.xyz", "--truth", "t.npz"), "--scan-file"),
])
def test_outputs_of_the_wrong_kind_or_clashing_are_usage_errors(cli, tmp_path, args, option):
    res = run_in(cli, tmp_path, *args)
    assert res.returncode == 2, (res.returncode, res.stderr)
    assert option in res.stderr and "Traceback" not in res.stderr
    assert leftovers(tmp_path) == []


def test_outputs_naming_one_file_through_a_link_are_a_usage_error(cli, tmp_path):
    (tmp_path / "t.npz").symlink_to(tmp_path / "r.mcap")
    res = run(cli, *CHEN, "--out", tmp_path / "r.mcap", "--truth", tmp_path / "t.npz")
    assert res.returncode == 2 and "--out/--truth" in res.stderr and "Traceback" not in res.stderr
    assert leftovers(tmp_path) == ["t.npz"]


@pytest.mark.parametrize("made, args, named", [
    ("afile", (*CHEN, "--out", "x.mcap", "--truth", "afile/t.npz"), "afile/t.npz"),
    ("adir.mcap/", (*CHEN, "--out", "adir.mcap", "--truth", "t.npz"), "adir.mcap"),
    ("adir.npz/", (*CHEN, "--out", "x.mcap", "--truth", "adir.npz"), "adir.npz"),
    ("mh/adir.ply/", (*MAKEHUMAN, "--out", "mh/a.mcap", "--truth", "mh/t.npz", "--scan-file", "mh/adir.ply"),
     "mh/adir.ply"),
])
def test_outputs_that_cannot_be_written_are_refused_before_any_work(cli, tmp_path, made, args, named):
    target = tmp_path / made
    target.parent.mkdir(parents=True, exist_ok=True)
    target.mkdir() if made.endswith("/") else target.touch()
    before = leftovers(tmp_path)
    res = run_in(cli, tmp_path, *args)
    assert_bad_input(res, named, tmp_path)
    assert leftovers(tmp_path) == before


def test_a_folder_without_write_permission_is_refused(cli, tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o555)
    prefix = []
    if os.geteuid() == 0:                                       # root writes anywhere unless it drops the capability
        if shutil.which("setpriv") is None:
            pytest.skip("needs setpriv to drop root's CAP_DAC_OVERRIDE")
        prefix = ["setpriv", "--bounding-set=-dac_override,-dac_read_search",
                  "--inh-caps=-dac_override,-dac_read_search"]
    res = subprocess.run([*prefix, cli, *map(str, (*CHEN, "--out", folder / "s.mcap", "--truth", folder / "t.npz"))],
                         capture_output=True, text=True)
    assert_bad_input(res, folder / "s.mcap", folder)
    assert "cannot be written" in res.stderr and leftovers(folder) == []


def test_missing_folders_are_made(cli, tmp_path):
    res = run(cli, *CHEN, "--out", tmp_path / "a" / "s.mcap", "--truth", tmp_path / "b" / "c" / "t.npz")
    assert res.returncode == 0, res.stderr
    assert leftovers(tmp_path) == ["a", "a/s.mcap", "b", "b/c", "b/c/t.npz"]


# --- all or nothing ---------------------------------------------------------------------
def run_limited(cli, fsize, *args):
    """Run `breastplan ARGS` with files limited to `fsize` bytes (a write past it fails with EFBIG)."""
    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))
    return subprocess.run([cli, *map(str, args)], capture_output=True, text=True, preexec_fn=limit)


@pytest.mark.parametrize("fsize", [100_000, 400_000])
def test_a_recording_cut_short_writes_nothing(cli, tmp_path, fsize):
    (tmp_path / "t.npz").write_bytes(b"the previous truth")
    res = run_limited(cli, fsize, *CHEN, "--out", tmp_path / "new" / "s.mcap", "--truth", tmp_path / "t.npz")
    assert_bad_input(res, tmp_path / "new" / "s.mcap", tmp_path)
    assert leftovers(tmp_path) == ["t.npz"] and (tmp_path / "t.npz").read_bytes() == b"the previous truth"


def test_a_scan_file_cut_short_writes_nothing(cli, tmp_path):
    res = run_limited(cli, 2_000_000, *MAKEHUMAN, "--out", tmp_path / "mh" / "a.mcap",
                      "--truth", tmp_path / "mh" / "t.npz", "--scan-file", tmp_path / "mh" / "s.ply")
    assert_bad_input(res, tmp_path / "mh" / "s.ply", tmp_path)
    assert leftovers(tmp_path) == []


def test_makehuman_writes_its_three_files_together(cli, tmp_path):
    res = run(cli, *MAKEHUMAN, "--out", tmp_path / "a.mcap", "--truth", tmp_path / "t.npz",
              "--scan-file", tmp_path / "s.obj", "--json")
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert out["frames"] == 1 and out["megabytes"] == round((tmp_path / "a.mcap").stat().st_size / 1e6, 2)
    assert leftovers(tmp_path) == ["a.mcap", "s.mtl", "s.obj", "s.png", "t.npz"]
    assert len(read_recording(tmp_path / "a.mcap").depth) == 1

