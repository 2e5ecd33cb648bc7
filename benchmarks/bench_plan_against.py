"""`breastplan plan` on the bundled sample, whole process, against another revision of the code in the
same run: is a change no slower?

Each revision (REV, and the working tree's HEAD unless --head-rev says otherwise) is laid out from
`git archive` in a temporary folder as setuptools' package-dir mapping lays it out (`breastplan` =
core/, `breastplan.plan` = plan/, …, by symbolic links) and put first on PYTHONPATH, so the command
run imports that revision, not the editable install; both run with this venv's Python and packages.
The two alternate, one plan each per round, after a warm-up of each (which also compiles each
revision's bytecode), so both see the same load of the (shared, noisy) machine. Prints the median seconds of each and their ratio (HEAD / REV; target ≤ 1.05:
no slower, within the machine's noise) and one JSON line.

Run:  .venv/bin/python benchmarks/bench_plan_against.py REV [--head-rev REV] [--repeats N]   (default 5)
"""
from __future__ import annotations

import argparse
import io
import json
import os
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

from package_layout import lay_out

ROOT = Path(__file__).resolve().parents[1]
TARGET = 1.05
CLI = "import sys; from breastplan.cli.main import main; sys.argv[0] = 'breastplan'; main()"


def revision(rev: str, folder: Path) -> Path:
    """The site folder holding `rev`'s `breastplan` package (symbolic links into its extracted tree)."""
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev], capture_output=True, check=True).stdout
    with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
        tar.extractall(folder / "repo", filter="data")
    return lay_out(folder / "repo", folder / "site")


def plan_seconds(site: Path, out: Path) -> float:
    """Wall seconds of one whole `breastplan plan --out out` process importing from `site`."""
    env = {**os.environ, "PYTHONPATH": str(site)}
    start = time.perf_counter()
    subprocess.run([sys.executable, "-c", CLI, "plan", "--out", str(out)], env=env, check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rev", help="the revision to measure against (a commit, tag or branch)")
    parser.add_argument("--head-rev", default="HEAD", help="the revision measured (default HEAD)")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        sites = {name: revision(rev, Path(tmp) / name) for name, rev in (("head", args.head_rev), ("rev", args.rev))}
        times: dict[str, list[float]] = {name: [] for name in sites}
        for round_ in range(args.repeats + 1):
            for name, site in sites.items():
                seconds = plan_seconds(site, Path(tmp) / f"{name}-{round_}")
                if round_:                                       # the first round warms up
                    times[name].append(seconds)
    head, rev = (statistics.median(times[n]) for n in ("head", "rev"))
    print(f"plan on the sample, median of {args.repeats}: {args.head_rev} {head:.2f} s, {args.rev} {rev:.2f} s, "
          f"ratio {head / rev:.3f} (target ≤ {TARGET})")
    print(json.dumps({"figure": "plan seconds against another revision", "value": round(head, 2),
                      "baseline": round(rev, 2), "ratio": round(head / rev, 3), "target_ratio": TARGET,
                      "revisions": [args.head_rev, args.rev], "runs": times}))


if __name__ == "__main__":
    main()
