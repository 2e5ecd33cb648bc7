"""Work beside the process in a forked child: done there when it can be, else left to the process."""
import os
import time

import pytest

from breastplan import forked

pytestmark = pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="a child is forked only with two CPUs")


def test_a_child_does_its_work_and_says_so(tmp_path):
    with forked.beside(lambda: (tmp_path / "done").write_text(str(os.getpid()))) as finished:
        assert finished()
    assert int((tmp_path / "done").read_text()) != os.getpid()      # written by another process


def test_a_child_that_fails_leaves_its_work_to_the_process():
    def work():
        raise RuntimeError("a fault in the child")

    with forked.beside(work) as finished:
        assert not finished()


def _sleeper(pid_file):
    """Work that never ends, once it has said which process it is (the file appears whole: written aside, then
    renamed, so that a reader never finds it empty)."""
    def work():
        aside = pid_file.with_suffix(".part")
        aside.write_text(str(os.getpid()))
        aside.rename(pid_file)
        time.sleep(3600)
    return work


def _gone(pid_file) -> bool:
    if not pid_file.exists():                       # stopped before it wrote its pid
        return True
    try:
        os.kill(int(pid_file.read_text()), 0)
    except ProcessLookupError:
        return True
    return False


def test_a_stuck_child_is_stopped(monkeypatch, tmp_path):
    monkeypatch.setattr(forked, "STUCK", (0.5, 0.0))
    with forked.beside(_sleeper(tmp_path / "pid")) as finished:
        assert not finished()
    assert _gone(tmp_path / "pid")


def test_a_child_is_stopped_when_the_process_fails(tmp_path):
    with pytest.raises(ValueError), forked.beside(_sleeper(tmp_path / "pid")):
        while not (tmp_path / "pid").exists():
            time.sleep(0.01)
        raise ValueError("the process's own share failed")
    assert _gone(tmp_path / "pid")


def test_no_work_no_child():
    with forked.beside(None) as finished:
        assert not finished()
