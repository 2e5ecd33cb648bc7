"""`breastplan batch`: a folder of realistic patients' scans and recordings planned case by case, locally
and on Dask (a LocalCluster, and a scheduler with two workers as separate processes); the manifest;
resuming, also after `kill -9`; bad inputs reported, never stopping the batch."""
import csv
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from clitools import child_processes, run

from breastplan.batch.inputs import find_inputs
from breastplan.case import sha256
from breastplan.scenes.makehuman import BodyOptions
from breastplan.scenes.realistic import CameraOptions, make_body_scene, write_scan_file
from breastplan.options import DEFAULT_PLAN, BatchOptions, OptionError
from breastplan.plan.job import sample_recording

SAMPLE = sample_recording()


def _manifest(out: Path) -> dict:
    """manifest.json's rows by input, checked against manifest.csv (the same rows)."""
    doc = json.loads((out / "manifest.json").read_text())
    with open(out / "manifest.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["input"] for r in rows] == [c["input"] for c in doc["cases"]]
    assert [r["status"] for r in rows] == [c["status"] for c in doc["cases"]]
    return {c["input"]: c for c in doc["cases"]}


def _whole(case: Path) -> bool:
    """A case folder holding a whole plan: plan.json (written last) and what it vouches for."""
    try:
        record = json.loads((case / "plan.json").read_text())
    except (OSError, ValueError):
        return False
    return (case / "report.html").is_file() and all((case / s / "fit.npz").is_file() for s in record["sides"])


def _hidden(out: Path) -> list[Path]:
    return [p for p in out.rglob(".*") if p.is_dir()]


@pytest.fixture(scope="module")
def patients(tmp_path_factory):
    """A clinic's folder: the sample patient's recording, another patient (fuller, sagging, heavier,
    arms down) as a PLY scan in a ward subfolder, and the faults a real folder holds."""
    folder = tmp_path_factory.mktemp("batch") / "scans"
    (folder / "ward").mkdir(parents=True)
    shutil.copy(SAMPLE, folder / "anna.mcap")
    scene = make_body_scene(BodyOptions(cup=0.9, firmness=0.2, weight=0.65, pose="arms-down"),
                            CameraOptions(distance_mm=700.0, pitch_deg=5.0))
    write_scan_file(folder / "ward" / "berta.ply", scene)
    (folder / "notes.txt").write_text("consultation notes, not a scan")
    (folder / "corrupt.mcap").write_bytes(SAMPLE.read_bytes()[:200_000])
    (folder / "anna.ply").write_bytes((folder / "ward" / "berta.ply").read_bytes())   # the name of anna.mcap's case
    (folder / "outside.ply").symlink_to(SAMPLE)                                      # leads out of the folder
    (folder / "gone.ply").symlink_to(folder / "ward" / "deleted.ply")               # unreadable: dangling
    return folder


EXPECTED = {"anna.mcap": "done", "ward/berta.ply": "done", "corrupt.mcap": "failed", "gone.ply": "failed",
            "anna.ply": "skipped", "notes.txt": "skipped", "outside.ply": "skipped"}


@pytest.fixture(scope="module")
def batched(cli, patients, tmp_path_factory):
    out = tmp_path_factory.mktemp("batch-out") / "cases"
    res = run(cli, "batch", patients, "--out", out, "--jobs", "2", "--json")
    return out, res


def test_find_inputs_names_each_file_and_why_it_is_skipped(patients, tmp_path):
    found = {i.name: i for i in find_inputs(patients)}
    assert set(found) == set(EXPECTED)
    assert found["ward/berta.ply"].case == "ward/berta" and found["ward/berta.ply"].skipped is None
    assert "outside the input folder" in found["outside.ply"].skipped
    assert "not a scan or recording" in found["notes.txt"].skipped
    assert "duplicate name" in found["anna.ply"].skipped and "anna.mcap" in found["anna.ply"].skipped
    assert found["gone.ply"].skipped is None          # found; it fails when read


def test_an_objs_material_and_texture_beside_it_are_no_inputs(tmp_path):
    """A scanner's export: eva.obj with eva.mtl and eva.png beside it; a texture of no OBJ's name is still listed."""
    for name in ("eva.obj", "eva.mtl", "eva.png", "ward/eva.png", "logo.png"):
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_bytes(b"")
    found = {i.name: i.skipped for i in find_inputs(tmp_path)}
    assert set(found) == {"eva.obj", "ward/eva.png", "logo.png"} and found["eva.obj"] is None
    assert found["logo.png"].startswith("not a scan or recording") and found["ward/eva.png"] is not None


def test_find_inputs_skips_a_named_pipe_which_reading_would_block_on(tmp_path):
    os.mkfifo(tmp_path / "pipe.ply")
    (tmp_path / "gone.ply").symlink_to(tmp_path / "deleted.ply")
    found = {i.name: i.skipped for i in find_inputs(tmp_path)}
    assert found == {"pipe.ply": "not a regular file", "gone.ply": None}     # a dangling link fails when read


def test_find_inputs_skips_a_case_that_would_lie_inside_another(tmp_path):
    """Case `anna` holds left/, right/ and plan.json: inputs whose cases would be those are not planned."""
    (tmp_path / "anna").mkdir()
    for name in ("anna.ply", "anna/left.ply", "anna/plan.json.ply", "annabel.ply"):
        (tmp_path / name).write_text("ply")
    found = {i.name: i.skipped for i in find_inputs(tmp_path)}
    assert found["anna.ply"] is None and found["annabel.ply"] is None
    assert found["anna/left.ply"] == "its case 'anna/left' would lie inside case 'anna', planned from anna.ply"
    assert "inside case 'anna'" in found["anna/plan.json.ply"]


def test_find_inputs_leaves_out_hidden_files_and_the_output_folder(tmp_path):
    (tmp_path / ".cache").mkdir()
    (tmp_path / ".cache" / "x.ply").write_text("ply")
    (tmp_path / ".hidden.ply").write_text("ply")
    (tmp_path / "out" / "case").mkdir(parents=True)
    (tmp_path / "out" / "case" / "scan.ply").write_text("ply")
    (tmp_path / "a.PLY").write_text("ply")
    assert [i.name for i in find_inputs(tmp_path, tmp_path / "out")] == ["a.PLY"]


def test_batch_plans_every_patient_and_reports_every_fault(batched, patients):
    out, res = batched
    assert res.returncode == 0, res.stderr[-3000:]
    rows = _manifest(out)
    assert {k: r["status"] for k, r in rows.items()} == EXPECTED
    summary = json.loads(res.stdout)["summary"]
    assert (summary["done"], summary["failed"], summary["skipped"], summary["pending"]) == (2, 2, 3, 0)
    for name in ("anna.mcap", "ward/berta.ply"):
        case = out / rows[name]["case"]
        record = json.loads((case / "plan.json").read_text())
        assert _whole(case) and record["input"]["sha256"] == rows[name]["sha256"] == sha256(patients / name)
        assert set(record["sides"]) == {"left", "right"} and rows[name]["seconds"] > 0
    assert "corrupt.mcap" in rows["corrupt.mcap"]["error"] and "gone.ply" in rows["gone.ply"]["error"]
    assert "No such file" in rows["gone.ply"]["error"]
    assert "outside.ply" in res.stderr and "warning" in res.stderr      # the skipped link, warned about
    assert sorted(p.name for p in out.iterdir()) == [".batch.lock", "anna", "manifest.csv", "manifest.json",
                                                     "measures.csv", "ward"]
    assert not _hidden(out)


def _measures(out: Path) -> list[dict]:
    with open(out / "measures.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def test_measures_csv_gives_each_planned_breast_its_plans_figures_and_nothing_of_the_rest(batched, patients):
    """One row per breast of the two planned cases, in input order, none for a failed or skipped input; each the
    figures of its case's plan.json: what was planned, her volume, its ± and unseen outer side, her left − right
    (left less right, the same on both rows), her ptosis grade and her nipple's distance from the notch; the
    recording's camera distance, none for the scan file; no follow-up, no change since."""
    out, res = batched
    rows = _measures(out)
    assert json.loads(res.stdout)["measures"] == str(out / "measures.csv")
    assert [(r["input"], r["side"]) for r in rows] == [("anna.mcap", "left"), ("anna.mcap", "right"),
                                                       ("ward/berta.ply", "left"), ("ward/berta.ply", "right")]
    for name in ("anna.mcap", "ward/berta.ply"):
        record = json.loads((out / _manifest(out)[name]["case"] / "plan.json").read_text())
        mine = {r["side"]: r for r in rows if r["input"] == name}
        for side, row in mine.items():
            volume = record["sides"][side]["volume"]
            assert [float(row[k]) for k in ("volume_cc", "uncertainty_cc", "unseen_outer_cc")] == \
                [volume["volume_cc"], volume["uncertainty_cc"], volume["unseen_outer_cc"]]
            assert row["ptosis_grade"] == record["measures"]["ptosis"]["before"][side]["grade"]
            assert row["planned"] == "; ".join(f"{k}:{d:g}" for k, d in DEFAULT_PLAN)      # the batch's changes
            assert float(row["notch_to_nipple_mm"]) == pytest.approx(
                record["measures"]["before"][side]["notch_to_nipple_mm"], abs=0.051)
            assert row["change_since_earlier_cc"] == row["change_since_earlier_pct"] == ""
            assert (row["camera_mm"] == "") == name.endswith(".ply")
        left_minus_right = float(mine["left"]["volume_left_minus_right_cc"])
        assert mine["right"]["volume_left_minus_right_cc"] == mine["left"]["volume_left_minus_right_cc"]
        assert left_minus_right == pytest.approx(
            record["measures"]["before"]["left"]["volume_cc"] - record["measures"]["before"]["right"]["volume_cc"],
            abs=0.06)
    assert 500 < float(rows[0]["camera_mm"]) < 800                         # the sample, recorded from about 0.65 m


def test_a_batch_case_is_the_plan_of_its_input(batched, cli, tmp_path):
    """The same input planned alone by `plan`: the same nipples, fits and measures."""
    out, _ = batched
    res = run(cli, "plan", SAMPLE, "--out", tmp_path / "alone")
    assert res.returncode == 0, res.stderr[-2000:]
    alone = json.loads((tmp_path / "alone" / "plan.json").read_text())
    batch = json.loads((out / "anna" / "plan.json").read_text())
    assert batch["measures"] == alone["measures"]
    for side in ("left", "right"):
        assert batch["sides"][side]["nipple_input_mm"] == alone["sides"][side]["nipple_input_mm"]
        assert batch["sides"][side]["volume"] == alone["sides"][side]["volume"]
        assert batch["sides"][side]["fit"]["model_volume_cc"] == alone["sides"][side]["fit"]["model_volume_cc"]


def test_a_plan_lacking_a_figure_keeps_its_rows_with_that_cell_empty(batched, tmp_path):
    """A case planned by an earlier version (no unseen outer side, no ptosis measures) keeps both breasts' rows, the
    figures it lacks left empty, the rest as its plan.json gives them."""
    from breastplan.plan.plan_file import read_measures

    out, _ = batched
    record = json.loads((out / "anna" / "plan.json").read_text())
    for side in record["sides"].values():
        del side["volume"]["unseen_outer_cc"]
    del record["measures"]["ptosis"]
    (tmp_path / "plan.json").write_text(json.dumps(record))
    rows = read_measures(tmp_path)
    assert [r["side"] for r in rows] == ["left", "right"]
    assert all(r["unseen_outer_cc"] is None and r["ptosis_grade"] is None for r in rows)
    assert [r["volume_cc"] for r in rows] == [record["sides"][s]["volume"]["volume_cc"] for s in ("left", "right")]


def test_a_batch_again_reuses_every_finished_case_and_retries_the_failed(batched, cli, patients):
    out, _ = batched
    stamps = {p: p.stat().st_mtime_ns for p in out.rglob("plan.json")}
    res = run(cli, "batch", patients, "--out", out, "--json")
    assert res.returncode == 0, res.stderr[-2000:]
    rows = _manifest(out)
    assert rows["anna.mcap"]["status"] == rows["ward/berta.ply"]["status"] == "reused"
    assert rows["corrupt.mcap"]["status"] == "failed"
    assert {p: p.stat().st_mtime_ns for p in out.rglob("plan.json")} == stamps     # untouched
    assert [(r["input"], r["side"]) for r in _measures(out)] == [(i, s) for i in ("anna.mcap", "ward/berta.ply")
                                                                for s in ("left", "right")]     # reused: still there


def test_a_case_missing_a_file_its_plan_names_is_planned_again(cli, tmp_path):
    """Truth: reused means whole — a case whose report or side folder was deleted is no finished plan."""
    folder = tmp_path / "one"
    folder.mkdir()
    shutil.copy(SAMPLE, folder / "anna.mcap")
    out = tmp_path / "cases"
    assert run(cli, "batch", folder, "--out", out, "--deform", "ptosis:2").returncode == 0
    (out / "anna" / "report.html").unlink()
    shutil.rmtree(out / "anna" / "left")
    res = run(cli, "batch", folder, "--out", out, "--deform", "ptosis:2")
    assert res.returncode == 0, res.stderr[-2000:]
    assert _manifest(out)["anna.mcap"]["status"] == "done"
    record = json.loads((out / "anna" / "plan.json").read_text())
    assert (out / "anna" / "report.html").is_file()
    assert all((out / "anna" / f).is_file() for c in record["sides"]["left"]["changes"] for f in c["files"].values())


def test_other_options_replan_a_case_in_place(patients, cli, tmp_path):
    """A case planned before with other changes is planned again, its ingest and fit reused, and
    swapped in whole."""
    folder = tmp_path / "one"
    folder.mkdir()
    shutil.copy(SAMPLE, folder / "anna.mcap")
    out = tmp_path / "cases"
    assert run(cli, "batch", folder, "--out", out, "--deform", "ptosis:2").returncode == 0
    res = run(cli, "batch", folder, "--out", out, "--deform", "ptosis:5", "--deform", "turn:2")
    assert res.returncode == 0, res.stderr[-2000:]
    record = json.loads((out / "anna" / "plan.json").read_text())
    assert _manifest(out)["anna.mcap"]["status"] == "done"
    assert record["options"]["changes"] == [["ptosis", 5.0], ["turn", 2.0]]
    assert record["sides"]["left"]["reused"] == ["ingest", "fit"]
    assert not _hidden(out)


def test_a_scan_replaced_by_a_corrupt_file_fails_and_says_its_case_holds_the_earlier_plan(cli, tmp_path):
    """The earlier plan is the clinic's record and is kept untouched, but the failed row must not let
    it pass for a plan of the file now in the folder."""
    folder, out = tmp_path / "one", tmp_path / "cases"
    folder.mkdir()
    shutil.copy(SAMPLE, folder / "anna.mcap")
    assert run(cli, "batch", folder, "--out", out).returncode == 0
    before = (out / "anna" / "plan.json").read_bytes()
    (folder / "anna.mcap").write_bytes(SAMPLE.read_bytes()[:200_000])
    res = run(cli, "batch", folder, "--out", out)
    assert res.returncode == 3, res.stderr[-2000:]
    row = _manifest(out)["anna.mcap"]
    assert row["status"] == "failed" and "is a truncated MCAP recording" in row["error"]
    assert "still holds the plan of this file's earlier content" in row["error"] and str(out / "anna") in row["error"]
    assert (out / "anna" / "plan.json").read_bytes() == before and not _hidden(out)


def test_a_batch_where_every_input_fails_exits_3(cli, tmp_path):
    folder = tmp_path / "bad"
    folder.mkdir()
    (folder / "a.mcap").write_bytes(SAMPLE.read_bytes()[:100_000])
    (folder / "b.ply").write_text("not a ply at all")
    res = run(cli, "batch", folder, "--out", tmp_path / "cases")
    assert res.returncode == 3, res.stderr
    assert "no input was planned" in res.stderr and str(folder) in res.stderr and "Traceback" not in res.stderr
    assert {r["status"] for r in _manifest(tmp_path / "cases").values()} == {"failed"}
    assert sorted(p.name for p in (tmp_path / "cases").iterdir()) == [".batch.lock", "manifest.csv", "manifest.json",
                                                                       "measures.csv"]
    assert _measures(tmp_path / "cases") == []                              # its header alone: no breast planned


def test_an_empty_folder_exits_3_and_writes_nothing(cli, tmp_path):
    (tmp_path / "empty" / ".hidden").mkdir(parents=True)
    res = run(cli, "batch", tmp_path / "empty", "--out", tmp_path / "cases")
    assert res.returncode == 3 and f"{tmp_path / 'empty'}: holds no file to plan" in res.stderr
    assert not (tmp_path / "cases").exists()


def test_a_missing_folder_exits_3_naming_it(cli, tmp_path):
    res = run(cli, "batch", tmp_path / "nowhere", "--out", tmp_path / "cases")
    assert res.returncode == 3 and str(tmp_path / "nowhere") in res.stderr
    assert not (tmp_path / "cases").exists()


@pytest.mark.parametrize("args, message", [
    (["--jobs", "0"], "at least 1"),
    (["--executor", "spark"], "not an executor"),
    (["--scheduler", "tcp://127.0.0.1:8786"], "needs --executor dask"),
    (["--executor", "dask", "--scheduler", "not a url"], "is not a scheduler address"),
    (["--executor", "dask", "--scheduler", "tcp://host"], "is not a scheduler address"),
    (["--executor", "dask", "--scheduler", "host:65536"], "is not a scheduler address"),
    (["--deform", "ptosis"], "KIND:DEGREE"),
    (["--deform", "ptosis:9"], "1..8"),
    (["--method", "fast"], "not a method"),
])
def test_batch_usage_errors_exit_2_before_any_work(cli, tmp_path, args, message):
    res = run(cli, "batch", tmp_path, "--out", tmp_path / "cases", *args)
    assert res.returncode == 2 and message in res.stderr
    assert not (tmp_path / "cases").exists()


def test_batch_options_check_themselves():
    with pytest.raises(OptionError):
        BatchOptions(jobs=0)
    assert BatchOptions(jobs=2, executor="dask").as_dict()["executor"] == "dask"
    for address in ("tcp://10.0.0.7:8786", "clinic-dask:8786", "tls://[::1]:8786"):
        assert BatchOptions(executor="dask", scheduler=address).scheduler == address


def test_what_a_plan_planned_reads_in_a_line_as_it_was_written():
    """measures.csv's `planned`: each operation as written with its side, the breast symmetrised, then the changes
    by degree as --deform takes them, which read back to the same changes."""
    from breastplan.options import PlanOptions

    operated = PlanOptions.parse(["turn:2.5"], operations=(("left", "augmentation:250:moderate"),), symmetrise="right")
    assert operated.written == "left augmentation:250:moderate; symmetrise right; turn:2.5"
    assert PlanOptions.parse(list(PlanOptions().deform_items)).changes == PlanOptions().changes


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _three_patients_batched_until_one_is_finished(cli, tmp_path, executor=(), **popen):
    """(input folder, output folder, names, the running batch) once one of three cases is whole."""
    folder = tmp_path / "scans"
    folder.mkdir()
    names = [f"patient{i}" for i in range(3)]
    for name in names:
        shutil.copy(SAMPLE, folder / f"{name}.mcap")
    out = tmp_path / "cases"
    batch = subprocess.Popen([cli, "batch", folder, "--out", out, "--jobs", "2", *executor], **popen)
    while not any(_whole(out / n) for n in names):
        assert batch.poll() is None, "the batch ended before it could be stopped"
        time.sleep(0.1)
    return folder, out, names, batch


@pytest.mark.long
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the workers' parent-death signal is Linux's")
def test_kill_9_at_a_random_moment_loses_no_finished_case_and_leaves_none_half_written(cli, tmp_path):
    folder, out, names, batch = _three_patients_batched_until_one_is_finished(
        cli, tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    delay = random.uniform(0.0, 4.0)
    time.sleep(delay)
    workers = child_processes(batch.pid)
    batch.send_signal(signal.SIGKILL)
    batch.wait()
    while any(_alive(w) for w in workers):               # the workers die with the batch
        time.sleep(0.1)
    finished = {n: (out / n / "plan.json").stat().st_mtime_ns for n in names if _whole(out / n)}
    assert finished, f"killed after {delay:.2f} s"
    for n in names:                                      # a case is whole or absent
        assert _whole(out / n) or not (out / n).exists(), (n, delay)
    rows = _manifest(out)                                # the manifest is whole too
    assert all(rows[f"{n}.mcap"]["status"] in ("done", "pending") for n in names)

    res = run(cli, "batch", folder, "--out", out, "--jobs", "2", "--json")
    assert res.returncode == 0, res.stderr[-2000:]
    rows = _manifest(out)
    for n in names:
        assert _whole(out / n)
        assert rows[f"{n}.mcap"]["status"] == ("reused" if n in finished else "done"), (n, delay)
    assert {n: (out / n / "plan.json").stat().st_mtime_ns for n in finished} == finished   # intact
    assert sorted(p.name for p in out.iterdir() if p.is_dir()) == names                   # none duplicated
    assert not _hidden(out)


@pytest.mark.long
@pytest.mark.parametrize("executor", [(), ("--executor", "dask")], ids=["local", "dask"])
def test_ctrl_c_stops_the_batch_at_once_with_its_manifest_true_to_the_disk(cli, tmp_path, executor):
    """SIGINT to the batch and its workers (a terminal's Ctrl-C) once a case is finished: the cases being
    planned are dropped, not finished behind the manifest's back; the sentence says what is left, with no
    worker's traceback, and the same command finishes it."""
    folder, out, names, batch = _three_patients_batched_until_one_is_finished(   # SIGINT heard, as at a terminal,
        cli, tmp_path, executor, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,  # even when the tests
        start_new_session=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))   # run in the back
    os.killpg(batch.pid, signal.SIGINT)
    _, err = batch.communicate()
    assert batch.returncode == 130, err[-2000:]
    assert "Traceback" not in err, err[-3000:]
    rows = _manifest(out)
    settled = [n for n in names if rows[f"{n}.mcap"]["status"] == "done"]
    assert settled and all(_whole(out / n) for n in settled)
    for n in set(names) - set(settled):                   # pending: nothing of it on disk
        assert rows[f"{n}.mcap"]["status"] == "pending" and not (out / n).exists()
    assert not _hidden(out)
    assert (f"interrupted: {len(settled)} of the 3 inputs to plan were settled and {3 - len(settled)} left pending "
            f"in {out / 'manifest.csv'}") in " ".join(err.split())
    res = run(cli, "batch", folder, "--out", out, "--jobs", "2")
    assert res.returncode == 0, res.stderr[-2000:]
    assert {n: r["status"] for n, r in _manifest(out).items()} == {
        f"{n}.mcap": "reused" if n in settled else "done" for n in names}


def test_dask_local_cluster_plans_the_folder(cli, patients, tmp_path):
    out = tmp_path / "cases"
    res = run(cli, "batch", patients, "--out", out, "--executor", "dask", "--jobs", "2")
    assert res.returncode == 0, res.stderr[-3000:]
    rows = _manifest(out)
    assert {k: r["status"] for k, r in rows.items()} == EXPECTED
    assert _whole(out / "anna") and _whole(out / "ward" / "berta")


@pytest.fixture
def dask_cluster(tmp_path):
    """A Dask scheduler and two single-threaded workers, each its own process; the scheduler's address."""
    dask = str(Path(sys.executable).with_name("dask"))
    file = tmp_path / "scheduler.json"
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    procs = [subprocess.Popen([dask, "scheduler", "--scheduler-file", file, "--port", "0", "--no-dashboard"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)]
    try:
        while not file.exists():
            assert procs[0].poll() is None, "the Dask scheduler did not start"
            time.sleep(0.2)
        procs += [subprocess.Popen([dask, "worker", "--scheduler-file", file, "--nthreads", "1", "--no-dashboard",
                                    "--no-nanny"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
                  for _ in range(2)]
        yield json.loads(file.read_text())["address"]
    finally:
        for p in procs[::-1]:
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:    # a worker still closing its connections
                p.kill()
                p.wait()


@pytest.mark.long
def test_dask_scheduler_with_two_worker_processes_plans_the_folder(cli, dask_cluster, tmp_path):
    folder = tmp_path / "scans"
    folder.mkdir()
    for name in ("anna", "carla"):
        shutil.copy(SAMPLE, folder / f"{name}.mcap")
    (folder / "corrupt.mcap").write_bytes(SAMPLE.read_bytes()[:200_000])
    out = tmp_path / "cases"
    res = run(cli, "batch", folder, "--out", out, "--executor", "dask", "--scheduler", dask_cluster, "--json")
    assert res.returncode == 0, res.stderr[-3000:]
    rows = _manifest(out)
    assert {k: r["status"] for k, r in rows.items()} == {"anna.mcap": "done", "carla.mcap": "done",
                                                          "corrupt.mcap": "failed"}
    assert _whole(out / "anna") and _whole(out / "carla")


def test_an_unreachable_scheduler_exits_3(cli, tmp_path):
    (tmp_path / "scans").mkdir()
    shutil.copy(SAMPLE, tmp_path / "scans" / "anna.mcap")
    res = run(cli, "batch", tmp_path / "scans", "--out", tmp_path / "cases", "--executor", "dask",
              "--scheduler", "tcp://127.0.0.1:9")
    assert res.returncode == 3 and "cannot reach the Dask scheduler" in res.stderr and "Traceback" not in res.stderr
    assert not (tmp_path / "cases").exists()                 # nothing written
