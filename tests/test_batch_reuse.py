"""`batch`'s two promises that a wrong case would break silently, held to what the batch is asked and what
happens to its workers, in seconds each (one case of the sample recording is planned once):

* a case is reused only when it is a whole plan of the same input content with the same options — the
  method, the sides and the earlier case of a follow-up (`--wall-from`) included — made by the same code; any
  other is planned again (the cases sent to the executor are recorded, not planned, by a stand-in executor);
* a case whose worker process dies (killed, out of memory) is failed, never done, and a batch whose every
  case failed has not succeeded — with the real local executor, its workers killed as they start.
"""
import json
import os
import shutil
import signal
import threading
import time
from pathlib import Path

import pytest
from clitools import run

from breastplan.batch import run as batch_run
from breastplan.batch.executors import ATTEMPTS
from breastplan.batch.run import run_batch
from breastplan.options import BatchOptions, PlanOptions
from breastplan.plan.job import sample_recording

SAMPLE = sample_recording()
CHANGES = (("ptosis", 2.0),)
"""The one change the case is planned with (a plan of one change is the quickest whole plan)."""


@pytest.fixture(scope="module")
def planned(cli, tmp_path_factory):
    """(input folder, output folder): the sample recording as anna.mcap, planned by `batch` with the
    defaults but one change: exact, both sides, no follow-up."""
    root = tmp_path_factory.mktemp("reuse")
    folder, out = root / "scans", root / "cases"
    folder.mkdir()
    shutil.copy(SAMPLE, folder / "anna.mcap")
    res = run(cli, "batch", folder, "--out", out, "--deform", "ptosis:2")
    assert res.returncode == 0, res.stderr[-2000:]
    return folder, out


@pytest.fixture
def sent(monkeypatch):
    """The tasks the batch sends to its executor (a stand-in that plans nothing: each case fails)."""
    tasks = []

    def executor(given, jobs):
        for task in given:
            tasks.append(task)
            yield [(task, {"status": "failed", "seconds": 0.0, "error": f"{task.input}: not planned by this test."})]

    monkeypatch.setattr(batch_run, "run_local", executor)
    return tasks


def statuses(batch) -> dict[str, str]:
    return {row.input: row.status for row in batch.manifest.rows}


def test_a_case_planned_with_the_same_options_is_reused_and_sent_to_no_worker(planned, sent):
    folder, out = planned
    batch = run_batch(folder, out, BatchOptions(plan=PlanOptions(changes=CHANGES)))
    assert statuses(batch) == {"anna.mcap": "reused"} and sent == []


@pytest.mark.parametrize("options, planned_with", [
    (BatchOptions(plan=PlanOptions(changes=CHANGES, method="learnt")), ("method", "learnt")),
    (BatchOptions(plan=PlanOptions(changes=CHANGES, sides=("left",))), ("sides", ["left"])),
    (BatchOptions(plan=PlanOptions(changes=CHANGES, sides=("right",))), ("sides", ["right"])),
    (BatchOptions(plan=PlanOptions(changes=CHANGES, method="exact", units="m")), ("units", "m")),
    (BatchOptions(plan=PlanOptions(changes=(("ptosis", 3.0),))), ("changes", [["ptosis", 3.0]])),
], ids=["method", "left-side", "right-side", "units", "degree"])
def test_a_case_planned_with_other_options_is_planned_again(planned, sent, options, planned_with):
    """Truth: the case's plan.json says exact, both sides, mm/auto, ptosis 2; the batch asks otherwise."""
    folder, out = planned
    batch = run_batch(folder, out, options)
    assert statuses(batch) == {"anna.mcap": "failed"}                 # sent to the executor, which failed it
    assert len(sent) == 1 and Path(sent[0].case) == (out / "anna").resolve()
    key, value = planned_with
    assert sent[0].options[key] == value
    assert (out / "anna" / "plan.json").is_file()                     # the earlier plan is left as it was


def test_a_case_planned_alone_is_planned_again_as_a_follow_up(planned, sent, tmp_path):
    """`--wall-from` an earlier batch's output: each case becomes a follow-up of the case of its name
    there, which the case planned alone is not."""
    folder, out = planned
    earlier = tmp_path / "last-year"
    (earlier / "anna").mkdir(parents=True)
    batch = run_batch(folder, out, BatchOptions(plan=PlanOptions(changes=CHANGES), wall_from=str(earlier)))
    assert statuses(batch) == {"anna.mcap": "failed"}
    assert [t.options["wall_from"] for t in sent] == [str(earlier.resolve() / "anna")]


def test_a_scan_with_no_earlier_visit_of_its_name_fails_saying_so_and_is_sent_to_no_worker(planned, sent, tmp_path):
    folder, out = planned
    earlier = tmp_path / "last-year"
    earlier.mkdir()
    plan_json = (out / "anna" / "plan.json").read_bytes()
    batch = run_batch(folder, out, BatchOptions(plan=PlanOptions(changes=CHANGES), wall_from=str(earlier)))
    row = batch.manifest.rows[0]
    assert row.status == "failed" and sent == []
    assert row.error.startswith(f"{folder / 'anna.mcap'}: has no earlier visit") and str(earlier / "anna") in row.error
    assert not batch.manifest.succeeded()                              # the command's exit 3: none was planned
    assert (out / "anna" / "plan.json").read_bytes() == plan_json      # her earlier plan left as it was
    assert list(earlier.iterdir()) == []                               # nothing written where it looked


def test_a_case_of_an_input_whose_content_changed_is_planned_again(planned, sent, tmp_path):
    folder, out = planned
    changed = tmp_path / "scans"
    changed.mkdir()
    (changed / "anna.mcap").write_bytes(SAMPLE.read_bytes() + b"\0")      # the same name, other content
    batch = run_batch(changed, out, BatchOptions(plan=PlanOptions(changes=CHANGES)))
    assert statuses(batch) == {"anna.mcap": "failed"} and len(sent) == 1


def test_a_case_planned_by_another_breastplan_is_planned_again(planned, sent, tmp_path):
    """Truth: the case's plan.json says other code planned it (an upgrade since, or an edit of the source): its
    figures are that code's, so the batch plans it again rather than tabulate them beside this code's."""
    folder, out = planned
    older = tmp_path / "cases"
    shutil.copytree(out, older, symlinks=True)
    record = json.loads((older / "anna" / "plan.json").read_text())
    record["code"] = "0" * 64
    (older / "anna" / "plan.json").write_text(json.dumps(record))
    batch = run_batch(folder, older, BatchOptions(plan=PlanOptions(changes=CHANGES)))
    assert statuses(batch) == {"anna.mcap": "failed"} and len(sent) == 1


def _workers(parent: int) -> list[int]:
    """The live multiprocessing workers (`spawn_main`) whose parent is `parent`, from /proc."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
            command = (stat.parent / "cmdline").read_bytes()
        except OSError:
            continue
        if int(fields[1]) == parent and fields[0] != "Z" and b"spawn_main" in command:
            found.append(int(stat.parent.name))
    return found


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="finds the workers in /proc")
def test_a_case_whose_worker_dies_every_time_is_failed_and_the_batch_has_not_succeeded(tmp_path):
    """Each worker the batch starts is killed (SIGKILL) as soon as it appears, as the system's
    out-of-memory killer would: after ATTEMPTS tries the case is failed, saying its worker died, the
    manifest on disk says so, no case folder is left, and the batch has not succeeded."""
    folder, out = tmp_path / "scans", tmp_path / "cases"
    folder.mkdir()
    shutil.copy(SAMPLE, folder / "anna.mcap")
    stop, killed = threading.Event(), set()

    def killer():
        while not stop.is_set():
            for pid in _workers(os.getpid()):
                try:
                    os.kill(pid, signal.SIGKILL)
                    killed.add(pid)
                except ProcessLookupError:
                    pass
            time.sleep(0.01)

    thread = threading.Thread(target=killer, daemon=True)
    thread.start()
    try:
        batch = run_batch(folder, out, BatchOptions(plan=PlanOptions(changes=CHANGES), jobs=1))
    finally:
        stop.set()
        thread.join()
    assert len(killed) >= ATTEMPTS
    row = batch.manifest.rows[0]
    assert row.status == "failed" and f"died ({ATTEMPTS}×" in row.error and str(folder / "anna.mcap") in row.error
    assert batch.manifest.summary() == {"inputs": 1, "done": 0, "reused": 0, "failed": 1, "skipped": 0, "pending": 0}
    assert not batch.manifest.succeeded()
    assert [c["status"] for c in json.loads((out / "manifest.json").read_text())["cases"]] == ["failed"]
    assert not (out / "anna").exists()
