"""A batch whose worker dies (a native crash, killed, out of memory) while several cases are planned: the case
that kills its worker fails, and the cases planned beside it are planned (each had been charged with the death
and failed beside it)."""
import multiprocessing
import os
import signal
import time

from breastplan.batch import executors
from breastplan.batch.task import Task


def _plan_or_die(task: Task) -> dict:
    """A stand-in for planning a case, of the same signature: the case named "crash" kills its worker process
    (SIGKILL, as the kernel's out-of-memory killer does) at once; the others take a second and are done."""
    if os.path.basename(task.case) == "crash":
        time.sleep(0.2)
        os.kill(os.getpid(), signal.SIGKILL)
    time.sleep(1.0)
    return {"status": "done", "seconds": 1.0, "error": ""}


def test_only_the_case_that_kills_its_worker_fails(monkeypatch):
    fork = multiprocessing.get_context("fork")          # the workers inherit the stand-in
    monkeypatch.setattr(executors.multiprocessing, "get_context", lambda method: fork)
    monkeypatch.setattr(executors, "plan_case", _plan_or_die)
    for names in (("anna", "crash"), ("anna", "crash", "berta", "carla")):
        # two workers: anna and crash start together, and anna is still being planned when crash's worker dies (two
        # cases: on every try, had they been tried together again)
        tasks = [Task(f"/in/{name}", f"/out/{name}", {}, name) for name in names]
        results = {os.path.basename(t.case): r for settled in executors.run_local(tasks, jobs=2) for t, r in settled}
        assert {name: r["status"] for name, r in results.items()} == {
            name: "failed" if name == "crash" else "done" for name in names}
        assert "died" in results["crash"]["error"]
