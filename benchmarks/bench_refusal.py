"""Refusal of bad input: peak memory and time of whole `breastplan` processes that must refuse.

Each case of `CASES` builds its input in a temporary folder (large files as sparse files, which cost
no disk), runs the command under `/usr/bin/time -v` and reads its peak resident set size and wall
time. A case is as promised when it exits with its code (3 bad input, 2 usage), says one first line
on stderr naming the file (bad input), and leaves nothing named out* behind. Targets, for every
refused input: peak RSS ≤ 1024 MB, refusal within 5 s. Baseline, measured in the same run:
`breastplan --help`. Nothing is asserted: the script prints a table and two JSON lines (worst peak
RSS, worst seconds), each with its target and baseline.

Another engineer adds a case by appending a `Case` to `CASES` (e.g. MCAP recordings for `ingest`).

Run:  .venv/bin/python benchmarks/bench_refusal.py
"""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
from rich.console import Console
from rich.table import Table

from breastplan import write_ply

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from bad_inputs import breast_mm, forged_npz, four_numbers_ply, inflating_npz, ply_header, sparse  # noqa: E402
from faulty_recordings import RECORDINGS  # noqa: E402  (damaged and forged MCAP recordings)

BREASTPLAN = str(Path(sys.executable).with_name("breastplan"))
TIME = "/usr/bin/time"
TARGET_MB, TARGET_S = 1024, 5.0
GB2 = 2 << 30


@dataclass(frozen=True)
class Case:
    """A refused input: `build(folder)` writes it and returns the arguments after `breastplan`
    (outputs named out*); `code` is the promised exit code; `prefix` runs the command under
    another (e.g. setpriv)."""

    name: str
    build: Callable[[Path], list]
    code: int = 3
    prefix: tuple[str, ...] = ()


def points(name: str, pts) -> Callable[[Path], Path]:
    return lambda d: write_ply(d / name, pts)


def many_lines(d: Path) -> Path:
    """An XYZ file of one point more than any body scan holds."""
    (d / "many.xyz").write_bytes(b"0 0 0\n" * 20_000_001)
    return d / "many.xyz"


def fan_obj(d: Path) -> Path:
    """An OBJ of one triangle's 3 vertices and 10 million faces over them (80 MB)."""
    (d / "fan.obj").write_bytes(b"v 0 0 0\nv 300 0 0\nv 0 300 10\n" + b"f 1 2 3\n" * 10_000_000)
    return d / "fan.obj"


def locked(d: Path) -> Path:
    path = write_ply(d / "locked.ply", breast_mm())
    path.chmod(0)
    return path


def deform(make, *options: str) -> Callable[[Path], list]:
    return lambda d: ["deform", make(d), "--kind", "ptosis", "--param", "b0=1", *options, "--out", d / "out.ply"]


def ingest(make, *options: str) -> Callable[[Path], list]:
    return lambda d: ["ingest", make(d), "--side", "left", *options, "--out", d / "out"]


def fit(make) -> Callable[[Path], list]:
    return lambda d: ["fit", make(d), "--out", d / "out"]


def dataset(make, dd: int = 8) -> Callable[[Path], list]:
    return lambda d: ["dataset", "--db", make(d), "--condition", "ptosis b0", "--dd", dd, "--out", d / "out.npz"]


def file(name: str, header: bytes = b"", size: int = GB2) -> Callable[[Path], Path]:
    return lambda d: sparse(d / name, header, size)


def placed_glb(d: Path) -> Path:
    """A GLB whose JSON declares a mesh of 100,000 vertices placed by 300 nodes (30 M vertices), no data behind."""
    text = json.dumps({"asset": {"version": "2.0"}, "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
                       "accessors": [{"count": 100_000, "type": "VEC3"}], "nodes": [{"mesh": 0}] * 300}).encode()
    text += b" " * (-len(text) % 4)
    path = d / "placed.glb"
    path.write_bytes(b"glTF" + (2).to_bytes(4, "little") + (28 + len(text)).to_bytes(4, "little")
                     + len(text).to_bytes(4, "little") + b"JSON" + text + bytes(8))
    return path


ROOT_READS = os.geteuid() == 0 and shutil.which("setpriv") is not None
UNPRIVILEGED = ("setpriv", "--bounding-set=-dac_override,-dac_read_search") if ROOT_READS else ()
"""Root reads a chmod-000 file; without these capabilities it cannot."""
FAR = np.r_[breast_mm(), [[1e30, 0, 0]]]
CASES = [
    Case("ascii PLY, a line of 4 numbers (deform)", deform(lambda d: four_numbers_ply(d / "four.ply"))),
    Case("ascii PLY, a line of 4 numbers (ingest)", ingest(lambda d: four_numbers_ply(d / "four.ply"))),
    Case("all points identical (fit)", fit(points("same.ply", np.full((500, 3), 10.0)))),
    Case("breast in micrometres (fit)", fit(points("um.ply", breast_mm() * 1000))),
    Case("breast in metres (deform)", deform(points("m.ply", breast_mm() / 1000))),
    Case("one coordinate 1e30, --units mm (ingest)", ingest(points("far.ply", FAR), "--units", "mm")),
    Case("coordinates ±1.7e308 (fit)", fit(points("inf.ply", np.r_[breast_mm(), [[1.7e308] * 3, [-1.7e308] * 3]]))),
    Case("NPZ member declaring 10^12 × 3 values (dataset)", dataset(lambda d: forged_npz(d / "db.npz"))),
    Case("NPZ of 3 MB unpacking to 3 GiB (dataset)", dataset(lambda d: inflating_npz(d / "db.npz", 3072))),
    Case("synth --points 10^8", lambda d: ["synth", "--db", "S", "--points", 10**8, "--out", d / "out"], 2),
    Case("synth --seed -1", lambda d: ["synth", "--db", "S", "--seed", -1, "--out", d / "out"], 2),
    Case("dataset --dd 100000", dataset(lambda d: forged_npz(d / "db.npz"), 100_000), 2),
    Case("unreadable file, chmod 000 (deform)", deform(locked), prefix=UNPRIVILEGED),
    Case("deform --param b0=1e308", lambda d: ["deform", points("b.ply", breast_mm())(d), "--kind", "ptosis",
                                               "--param", "b0=1e308", "--out", d / "out.ply"]),
    Case("--out name of 256 characters (deform)", lambda d: ["deform", points("b.ply", breast_mm())(d), "--kind",
                                                             "ptosis", "--out", d / ("out" + "d" * 253)]),
    Case("2 GB of zeros as .ply (deform)", deform(file("zero.ply"))),
    Case("2 GB of zeros as .xyz (ingest)", ingest(file("zero.xyz"))),
    Case("2 GB of zeros as .obj (ingest)", ingest(file("zero.obj"))),
    Case("2 GB of zeros as .stl (ingest)", ingest(file("zero.stl"))),
    Case("2 GB of zeros as .pcd (ingest)", ingest(file("zero.pcd"))),
    Case("2 GB of zeros as .glb (ingest)", ingest(file("zero.glb"))),
    Case("2 GB of zeros as .gltf (ingest)", ingest(file("zero.gltf"))),
    Case("GLB whose JSON places a mesh of 100 000 vertices 300 times (ingest)", ingest(placed_glb)),
    Case("2 GB of zeros as .npz (dataset)", dataset(file("zero.npz"))),
    Case("PLY of 100 vertices and 2 GB more (fit)", fit(file("tail.ply", ply_header(100)))),
    Case("ascii PLY of 100 vertices and 2 GB more (ingest)", ingest(file("tail.ply", ply_header(100, "ascii")))),
    Case("XYZ of 20 000 001 lines, 120 MB (ingest)", ingest(many_lines)),
    Case("OBJ of 3 vertices and 10 M faces, 80 MB (ingest)", ingest(fan_obj)),
    Case("binary STL declaring 2^32 - 1 triangles (ingest)", ingest(file("big.stl", bytes(80) + b"\xff" * 4, 134))),
    Case("PCD declaring 100 M points (ingest)", ingest(file("big.pcd", b"VERSION .7\nFIELDS x y z\nSIZE 4 4 4\n"
                                                        b"TYPE F F F\nCOUNT 1 1 1\nWIDTH 100000000\nHEIGHT 1\n"
                                                        b"POINTS 100000000\nDATA binary\n", 4096))),
    Case("PLY declaring 89 M vertices, 1.07 GB (fit)", fit(file("huge.ply", ply_header(89_000_000),
                                                                89_000_000 * 12 + 200))),
    Case("PLY declaring 19 M vertices in 1 kB (fit)", fit(file("short.ply", ply_header(19_000_000), 1000))),
    Case("ascii PLY declaring 19 M vertices in 1 kB (ingest)", ingest(file("short.ply", ply_header(19_000_000, "ascii"),
                                                                          1000))),
]
CASES += [Case(f"{name} (ingest)", ingest(build)) for name, build in RECORDINGS]


def measure(argv: list, prefix=()) -> dict:
    """Exit code, stderr, peak RSS (MB) and wall seconds of one process under /usr/bin/time -v."""
    with tempfile.NamedTemporaryFile("r") as report:
        res = subprocess.run([*prefix, TIME, "-v", "-o", report.name, BREASTPLAN, *map(str, argv)],
                             capture_output=True, text=True)
        text = report.read()
    rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", text).group(1)) / 1024
    clock = re.search(r"Elapsed \(wall clock\) time .*: (?:(\d+):)?(\d+):([\d.]+)", text).groups()
    seconds = 3600 * int(clock[0] or 0) + 60 * int(clock[1]) + float(clock[2])
    return {"code": res.returncode, "stderr": res.stderr, "rss_mb": rss, "seconds": seconds}


def run_case(case: Case) -> dict:
    with tempfile.TemporaryDirectory(prefix="bench_refusal_") as folder:
        folder = Path(folder)
        argv = case.build(folder)
        row = measure(argv, case.prefix)
        left = sorted(p.name for p in folder.iterdir() if p.name.startswith(("out", ".out")))
        for p in folder.iterdir():
            p.chmod(0o700)                                 # a chmod-000 input must go too
    first = row.pop("stderr").strip().splitlines()[:1]
    named = bool(first) and (case.code != 3 or any(str(a) in first[0] for a in argv if isinstance(a, Path)))
    line = re.sub(r"(.)\1{20,}", r"\1…\1", first[0].replace(str(folder), "…")) if first else ""
    return {"case": case.name, **row, "first_line": line, "left_behind": left,
            "as_promised": row["code"] == case.code and named and not left}


def print_table(rows: list[dict], baseline: dict) -> None:
    table = Table(title="bench_refusal — whole processes under /usr/bin/time -v",
                  caption=f"Baseline, same run: `breastplan --help` {baseline['rss_mb']:.0f} MB, "
                          f"{baseline['seconds']:.2f} s. Targets: ≤ {TARGET_MB} MB, ≤ {TARGET_S:g} s.",
                  caption_justify="left")
    for col in ("case", "exit", "first line of stderr", "peak RSS MB", "seconds", "ok"):
        table.add_column(col, justify="right" if col in ("exit", "peak RSS MB", "seconds") else "left",
                         overflow="fold")
    for r in rows:
        table.add_row(r["case"], str(r["code"]), r["first_line"],
                      f"{r['rss_mb']:.0f}", f"{r['seconds']:.2f}", "yes" if r["as_promised"] else "NO")
    Console(width=200).print(table)


def main() -> None:
    if not Path(BREASTPLAN).exists() or not Path(TIME).exists():
        sys.exit(f"bench_refusal: needs {BREASTPLAN} and {TIME}")
    baseline = measure(["--help"])
    rows = [run_case(case) for case in CASES]
    print_table(rows, baseline)
    for figure, key, target, unit in (("worst refusal peak RSS", "rss_mb", TARGET_MB, "MB"),
                                      ("worst refusal seconds", "seconds", TARGET_S, "s")):
        worst = max(rows, key=lambda r: r[key])
        print(json.dumps({"figure": figure, "value": round(worst[key], 2), "target": target,
                          "baseline": round(baseline[key], 2), "unit": unit, "case": worst["case"],
                          "met": worst[key] <= target, "cases": len(rows),
                          "all_as_promised": all(r["as_promised"] for r in rows)}, ensure_ascii=False))


if __name__ == "__main__":
    main()
