"""A folder made once per test session and shared by every xdist worker (an expensive fixture's output)."""
import fcntl
import os
from pathlib import Path


def made_once(tmp_path_factory, name: str, make) -> Path:
    """The folder `make(folder)` fills once per session: the first worker to ask makes it under a lock while
    the others wait, then all read it. Without xdist it is this session's own."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent                          # the session's folder, above each worker's popen-gwN
    folder, done = root / f"shared-{name}", root / f"shared-{name}.done"
    with open(root / f"shared-{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not done.exists():
            folder.mkdir(exist_ok=True)
            make(folder)
            done.touch()
    return folder
