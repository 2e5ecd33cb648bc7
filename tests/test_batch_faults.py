"""`breastplan batch` (and a training set's pairs.csv) against the faults users found trying bad inputs:
symbolic-link loops, a --jobs no machine runs, a scheduler address where an HTTP server answers, and the
folders a failed batch made. Cheap inputs (empty files): each case fails at once."""
import csv
import http.server
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from clitools import assert_bad_input, child_processes, run

from breastplan.options import MAX_JOBS, BatchOptions, OptionError


def _rows(out: Path) -> dict[str, dict]:
    with open(out / "manifest.csv", newline="") as fh:
        return {r["input"]: r for r in csv.DictReader(fh)}


def _one_line(stderr: str) -> str:
    """stderr as one line (a usage error's box and line breaks dropped)."""
    return " ".join(stderr.replace("│", " ").split())


def test_symbolic_link_loops_are_skipped_with_their_reason_and_the_batch_goes_on(cli, tmp_path):
    folder, out = tmp_path / "scans", tmp_path / "cases"
    (folder / "ward").mkdir(parents=True)
    (folder / "empty.ply").touch()
    (folder / "self.ply").symlink_to("self.ply")                  # a link to itself
    (folder / "a.ply").symlink_to("b.ply")                        # a → b → a
    (folder / "b.ply").symlink_to("a.ply")
    (folder / "ward" / "loop").symlink_to("loop/")                # a folder's name, no suffix
    (folder / "through.ply").symlink_to("ward/loop/x.ply")        # a path through a loop
    res = run(cli, "batch", folder, "--out", out)
    assert res.returncode == 3 and "Traceback" not in res.stderr, res.stderr[-2000:]
    assert res.stderr.strip().splitlines()[-1] == (f"error: {folder}: no input was planned (1 failed, 5 skipped; "
                                                   f"see {out / 'manifest.csv'}).")
    rows = _rows(out)
    loops = ("self.ply", "a.ply", "b.ply", "ward/loop", "through.ply")
    assert set(rows) == {"empty.ply", *loops}
    for name in loops:
        assert rows[name]["status"] == "skipped"
        assert rows[name]["error"] == f"{folder / name}: skipped: a symbolic link loop."
        assert f"warning: {folder / name}: skipped: a symbolic link loop." in res.stderr
    assert rows["empty.ply"]["status"] == "failed" and "is empty (0 bytes)" in rows["empty.ply"]["error"]


@pytest.mark.parametrize("where", ["row", "folder"])
def test_a_symbolic_link_loop_in_a_training_set_is_bad_input(cli, tmp_path, where):
    pairs = tmp_path / "pairs"
    pairs.mkdir()
    (pairs / "pairs.csv").write_text("before,after,type,degree\nb.ply,loop.ply,ptosis,3\n")
    (pairs / "b.ply").touch()
    (pairs / "loop.ply").symlink_to("loop.ply")
    if where == "folder":
        pairs = tmp_path / "looped"
        pairs.symlink_to("looped")
    res = run(cli, "train-statistical", "--pairs", pairs, "--out", tmp_path / "out.npz")
    named = pairs / "pairs.csv" if where == "row" else pairs
    assert_bad_input(res, named, tmp_path)
    assert res.stderr.strip() == (f"error: {named}: line 2: after path 'loop.ply' is a symbolic link loop."
                                  if where == "row" else f"error: {named}: is a symbolic link loop, not a pairs folder.")


@pytest.mark.parametrize("executor", ["local", "dask"])
def test_more_jobs_than_a_batch_runs_is_a_usage_error_naming_the_bound(cli, tmp_path, executor):
    (tmp_path / "scans").mkdir()
    (tmp_path / "scans" / "empty.ply").touch()
    res = run(cli, "batch", tmp_path / "scans", "--out", tmp_path / "cases", "--executor", executor,
              "--jobs", MAX_JOBS + 1)
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
    assert f"a batch runs at most {MAX_JOBS} cases at once" in _one_line(res.stderr) and "--jobs" in res.stderr
    assert not (tmp_path / "cases").exists()


def test_the_bound_on_jobs_is_64_or_twice_the_cpus():
    assert MAX_JOBS == max(64, 2 * os.cpu_count())
    assert BatchOptions(jobs=MAX_JOBS).jobs == MAX_JOBS
    with pytest.raises(OptionError, match=f"at most {MAX_JOBS}"):
        BatchOptions(jobs=MAX_JOBS + 1, executor="dask")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="counts child processes in /proc")
def test_a_dask_batch_of_the_most_jobs_on_one_input_starts_one_worker(cli, tmp_path):
    """The fault: --jobs 10000 on one input started 10000 Dask workers, which ran out of files."""
    (tmp_path / "scans").mkdir()
    (tmp_path / "scans" / "empty.ply").touch()
    out = tmp_path / "cases"
    batch = subprocess.Popen([cli, "batch", tmp_path / "scans", "--out", out, "--executor", "dask",
                              "--jobs", str(MAX_JOBS)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    most = set()
    while batch.poll() is None:
        kids = {k for k in child_processes(batch.pid) if _of_multiprocessing(k)}   # not a `uname -p` distributed
        most = max(most, kids, key=len)                                            # runs to report its versions
        time.sleep(0.05)
    _, err = batch.communicate()
    assert batch.returncode == 3 and "Traceback" not in err and "Too many open files" not in err, err[-2000:]
    assert _rows(out)["empty.ply"]["status"] == "failed"
    assert len(most) <= 2, most             # one worker's process (and multiprocessing's resource tracker)


def _of_multiprocessing(pid: int) -> bool:
    """Whether process `pid` is one multiprocessing started (a worker, or its resource tracker): its command line."""
    try:
        return b"multiprocessing" in Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return False


class _Http(http.server.BaseHTTPRequestHandler):
    def log_message(self, *args):
        pass


def _answering(server: socket.socket) -> None:
    """Answer each connection's first bytes with an HTTP error, as a web server does to a stranger."""
    while True:
        conn, _ = server.accept()
        with conn:
            conn.recv(65536)
            conn.sendall(b"HTTP/1.0 400 Bad request\r\nContent-Type: text/html\r\n\r\n<html>bad</html>\n")


@pytest.fixture(params=["http.server", "answering"])
def http_address(request):
    """The tcp:// address of a local HTTP server on a free port: Python's http.server (it waits for a whole
    request line), or one answering the first bytes it reads."""
    if request.param == "http.server":
        server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Http)
        threading.Thread(target=server.serve_forever, daemon=True).start()
        yield f"tcp://127.0.0.1:{server.server_address[1]}"
        server.shutdown()
        server.server_close()
    else:
        with socket.create_server(("127.0.0.1", 0)) as server:
            threading.Thread(target=_answering, args=(server,), daemon=True).start()
            yield f"tcp://127.0.0.1:{server.getsockname()[1]}"


def test_an_address_answering_http_is_no_scheduler_exit_3(cli, tmp_path, http_address):
    (tmp_path / "scans").mkdir()
    (tmp_path / "scans" / "empty.ply").touch()
    res = run(cli, "batch", tmp_path / "scans", "--out", tmp_path / "cases", "--executor", "dask",
              "--scheduler", http_address)
    assert res.returncode == 3 and "Traceback" not in res.stderr, res.stderr[-2000:]
    assert len(res.stderr.strip().splitlines()) == 1
    assert f"{http_address} does not answer as a Dask scheduler" in res.stderr
    assert not (tmp_path / "cases").exists()                 # nothing written


def test_a_failed_batch_leaves_none_of_the_folders_it_made_for_its_cases(cli, tmp_path):
    folder, out = tmp_path / "scans", tmp_path / "cases"
    (folder / "sub" / "deeper").mkdir(parents=True)
    names = [f"sub/a{i}.ply" for i in range(200)] + ["sub/deeper/b.ply", "kept/c.ply"]
    (folder / "kept").mkdir()
    for name in names:
        (folder / name).touch()
    (out / "kept").mkdir(parents=True)                          # there before the batch: not the batch's to remove
    res = run(cli, "batch", folder, "--out", out, "--jobs", "2")
    assert res.returncode == 3 and "Traceback" not in res.stderr, res.stderr[-2000:]
    rows = _rows(out)
    assert set(rows) == set(names) and {r["status"] for r in rows.values()} == {"failed"}
    assert sorted(p.name for p in out.iterdir()) == [".batch.lock", "kept", "manifest.csv", "manifest.json",
                                                     "measures.csv"]
    assert not any((out / "kept").iterdir())
