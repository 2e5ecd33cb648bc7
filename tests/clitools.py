"""Running the `breastplan` command in tests, checking its bad-input contract, and the processes it starts."""
import subprocess
from pathlib import Path


def run(cli, *args):
    """Run `breastplan ARGS`; CompletedProcess with text stdout/stderr."""
    return subprocess.run([cli, *map(str, args)], capture_output=True, text=True, timeout=600)


def assert_bad_input(res, path, folder):
    """Exit 3, one stderr line naming `path`, no stdout, nothing half-written in `folder`."""
    assert res.returncode == 3, (res.returncode, res.stderr)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and str(path) in lines[0] and "Traceback" not in res.stderr
    assert res.stdout == ""
    assert not any(p.name.endswith(".part") or p.name.startswith("out") for p in folder.iterdir())


def child_processes(pid: int) -> set[int]:
    """The live processes whose parent is `pid` (from /proc)."""
    kids = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid and fields[0] != "Z":
            kids.add(int(stat.parent.name))
    return kids
