"""Mutation check: plant plausible bugs one at a time and see whether the tests catch each one.

Copies the repository's files (`git ls-files`, untracked ones included, so new tests count) into a
temporary folder, lays the package out there as setuptools' package-dir mapping does (`breastplan` =
core/, `breastplan.deform` = deform/, … from pyproject.toml, by symbolic links) and puts that first on
PYTHONPATH: the copy, not the editable install of this working tree, is what the tests and the
`breastplan` command they run import (checked before anything runs). The unmutated copy must pass
every test file the mutants name (the baseline). Then, for each mutant, one exact source-text
replacement (a bug at two sites, such as a swap in a deformation and its inverse, is one mutant; each
original text must occur exactly once, so the script breaks loudly when the code moves) is applied,
the mutated module must still import, and the mutant's relevant test files run with
`python -m pytest -x -q -p no:cacheprovider` (serial, stopping at the first failure; the baseline runs
on two xdist workers); the file is restored afterwards. A mutant is killed when the tests fail, and
survives when they pass. Nothing in the working tree is touched.

Prints a table (mutant, where, change, verdict, the first failing test, seconds) and one JSON line:
{"figure": "mutants survived", "value": N, "target": 0, "mutants": M, ...}.

Run by hand (a few minutes; the baseline runs the slow fit and learn tests once):
    .venv/bin/python benchmarks/mutation_check.py [--only NAME ...] [--list] [--skip-baseline] [--keep] [--markdown]
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

from rich.console import Console
from rich.markup import escape
from rich.table import Table

ROOT = Path(__file__).resolve().parents[1]
PYTEST = ["-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", "-p", "no:xdist", "-p", "no:dash",
          "-o", "addopts=-ra"]
"""Serial runs that stop at the first failure (the project's addopts would start two xdist workers)."""
BASELINE = ["-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:dash", "-o", "addopts=-ra -n 2"]
TIMEOUT_S = 45 * 60
"""A run that hangs this long counts as killed (by the hang), and says so."""

DEFORM = ("tests/test_reference.py", "tests/test_deformations.py", "tests/test_degree.py",
          "tests/test_inverse.py", "tests/test_databases.py", "tests/test_primitive.py")
"""The files the issue names for the deformation bugs: deformation, degree, inverse, database, primitive."""
LATTICE = ("tests/test_reference.py", "tests/test_lattice.py", "tests/test_ffd.py")
FIT = ("tests/test_reference.py", "tests/test_ffd.py", "tests/test_fit.py")
LEARN = ("tests/test_reference.py", "tests/test_learn.py", "tests/test_databases.py", "tests/test_metrics.py")
INGEST = ("tests/test_ingest.py", "tests/test_ingest_files.py")


@dataclass(frozen=True)
class Mutant:
    name: str
    why: str                                   # the plausible mistake it stands for
    edits: tuple[tuple[str, str, str], ...]    # (file, original text, mutated text), one bug
    tests: tuple[str, ...]                     # relevant test files, fastest-failing first

    @property
    def module(self) -> str:
        """The importable name of the first edited file (checked to import after the mutation)."""
        path = Path(self.edits[0][0]).with_suffix("")
        top = {"core": "breastplan"}.get(path.parts[0], f"breastplan.{path.parts[0]}")
        return ".".join([top, *path.parts[1:]])


def one(name, why, file, old, new, tests) -> Mutant:
    return Mutant(name, why, ((file, old, new),), tests)


MUTANTS = [
    # --- the five the issue found surviving --------------------------------------------------------
    Mutant("top-shape-t0-t1-swapped", "β″(0) and β″(1) exchanged in top-shape and its inverse",
           (("deform/global_deformations.py", "beta(w, s0, s1, t0, t1), 1.0)", "beta(w, s0, s1, t1, t0), 1.0)"),
            ("deform/global_deformations.py", "(2 / np.pi), s0, s1, t0, t1)", "(2 / np.pi), s0, s1, t1, t0)")),
           DEFORM),
    one("ffd-stop-residual-loosened", "the FFD stopping rule 0.0015 typed as 0.005",
        "fitting/ffd.py", "STOP_RESIDUAL = 0.0015", "STOP_RESIDUAL = 0.005", FIT),
    one("generic-turn-top-0.14", "Table 4.1's generic turn-top g0 = 0.41 typed as 0.14",
        "deform/degree.py", "turn=(0.38, 0.0), turn_top=(0.41, 0.0))", "turn=(0.38, 0.0), turn_top=(0.14, 0.0))",
        ("tests/test_reference.py", "tests/test_databases.py", "tests/test_degree.py", "tests/test_inverse.py")),
    one("dataset-position-row-over-dd", "a dataset's position t = row/#dd instead of row/(#dd − 1)",
        "learn/datasets.py", "return self.row / (self.dd - 1)", "return self.row / self.dd", LEARN),
    one("learnt-position-shifted", "the learnt position off by 0.03 on the condition's line",
        "deform/by_degree.py", "model.predict(features[None, :])[0], 0.0, 1.0)",
        "model.predict(features[None, :])[0] + 0.03, 0.0, 1.0)", ("tests/test_reference.py", "tests/test_learn.py")),
    # --- deform ----------------------------------------------------------------------------------------
    one("bernstein-sign", "(s − 1) for (1 − s) in the Bernstein basis",
        "deform/lattice.py", "t = 1.0 - s", "t = s - 1.0", LATTICE),
    one("lattice-xy-order", "control points in meshgrid's default xy order, the basis in ij order",
        "deform/lattice.py", 'np.meshgrid(*axes, indexing="ij")', 'np.meshgrid(*axes, indexing="xy")', LATTICE),
    one("signed-extent-includes-y0", "top-shape's signed extent over y ≥ 0 instead of the upper half y > 0",
        "deform/degree.py", "upper = o[..., 1] > 0", "upper = o[..., 1] >= 0", DEFORM),
    one("turn-feature-moved-axis", "turn's moved axis copied from ptosis (y): FS5's m0 the mean y",
        "deform/descriptors.py", '"turn": (0, 2)', '"turn": (1, 2)', ("tests/test_reference.py", "tests/test_learn.py")),
    # --- core ------------------------------------------------------------------------------------------
    one("volume-a1-twice", "the closed-form volume with (a1 + a1) for (a1 + a2)",
        "core/primitive.py", "(self.a3 + self.a4) * (self.a1 + self.a2))", "(self.a3 + self.a4) * (self.a1 + self.a1))",
        ("tests/test_reference.py", "tests/test_primitive.py", "tests/test_databases.py")),
    # --- fitting ---------------------------------------------------------------------------------------
    one("ffd-residual-ratio-of-means", "the normalised residual as mean distance over mean ‖d‖",
        "fitting/ffd.py", "final = float(np.mean(dist / data_norm))", "final = float(np.mean(dist) / np.mean(data_norm))",
        FIT),
    one("ffd-smoothness-swapped", "the FFD's λ for seen and partly seen breasts exchanged",
        "fitting/breast_fit.py", "SMOOTHNESS[1] if unseen.mean() > UNSEEN_SHARE else SMOOTHNESS[0]",
        "SMOOTHNESS[0] if unseen.mean() > UNSEEN_SHARE else SMOOTHNESS[1]", ("tests/test_fit.py",)),
    # --- ingest ----------------------------------------------------------------------------------------
    one("ingest-metres-factor-100", "a scan file detected in metres scaled by 100 instead of 1000",
        "ingest/files.py", 'return 1000.0, f"units m (detected', 'return 100.0, f"units m (detected', INGEST),
    one("ingest-left-right-swapped", "a mound right of the midline (patient's left) called the right breast",
        "ingest/breast.py", '"left" if centre[0] > midline_x else "right"', '"left" if centre[0] < midline_x else "right"',
        INGEST),
    one("chest-wall-front-band-40mm", "the chest wall keeps points 40 mm in front of it (the breasts) as inliers",
        "ingest/chest_wall.py", "front_mm: float = 4.0", "front_mm: float = 40.0", INGEST),
    # --- learn -----------------------------------------------------------------------------------------
    one("indirect-metric-modelled-norm", "modelled ⇒ original distances divided by ‖m‖ instead of ‖o*‖",
        "learn/metrics.py", "mo = d_mo / o_norm[nearest_o] * 100.0", "mo = d_mo / np.linalg.norm(m, axis=1) * 100.0",
        ("tests/test_metrics.py", "tests/test_reference.py")),
    one("database-volume-square-root", "the semi-axes scaled by the square root of the volume ratio",
        "learn/databases.py", "volume_cc()) ** (1 / 3)))", "volume_cc()) ** (1 / 2)))",
        ("tests/test_reference.py", "tests/test_databases.py")),
]


# --- the copy -------------------------------------------------------------------------------------
def tracked_files() -> list[str]:
    out = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                         check=True, capture_output=True).stdout.decode()
    return sorted({f for f in out.split("\0") if f and (ROOT / f).is_file()})


def make_copy(folder: Path) -> tuple[Path, Path]:
    """(repository copy, site folder holding the `breastplan` package laid out from the copy)."""
    repo, site = folder / "repo", folder / "site"
    for f in tracked_files():
        (repo / f).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / f, repo / f)
    mapping = tomllib.loads((repo / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]
    top = site / "breastplan"
    top.mkdir(parents=True)
    for entry in (repo / mapping["breastplan"]).iterdir():
        (top / entry.name).symlink_to(entry)
    for package, source in mapping.items():
        if package != "breastplan":
            (top / package.split(".", 1)[1]).symlink_to(repo / source, target_is_directory=True)
    return repo, site


def environment(site: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site), *filter(None, [env.get("PYTHONPATH")])])
    env["PYTHONDONTWRITEBYTECODE"] = "1"     # a same-size mutation within one second must not reuse a .pyc
    return env


def check_imports_from_copy(repo: Path, site: Path, env: dict) -> str:
    """The interpreter and the `breastplan` command the tests run both import the copy; returns its path."""
    code = ("import breastplan, breastplan.deform.global_deformations as g, breastplan.cli.main as m;"
            "print(breastplan.__file__); print(g.__file__); print(m.__file__)")
    out = subprocess.run([sys.executable, "-c", code], cwd=repo, env=env, capture_output=True, text=True, check=True)
    paths = out.stdout.split()
    if not all(Path(p).is_relative_to(site) for p in paths):
        raise SystemExit(f"the package does not import from the copy: {paths}")
    script = Path(sys.executable).with_name("breastplan")        # what the tests' `cli` fixture runs
    first = script.read_text().splitlines()[0] if script.exists() else ""
    if not first.startswith("#!") or Path(first[2:].strip()).resolve() != Path(sys.executable).resolve():
        raise SystemExit(f"{script} does not run {sys.executable}, so it may not import the copy")
    return paths[0]


# --- running --------------------------------------------------------------------------------------
def first_failure(output: str) -> str:
    for line in output.splitlines():
        if line.startswith(("FAILED ", "ERROR ")):
            return line.split(" ", 1)[1].split(" - ")[0].removeprefix("tests/")
    return ""


def run_tests(args: list[str], files, repo: Path, env: dict) -> tuple[int, str, float]:
    start = time.perf_counter()
    try:
        res = subprocess.run([sys.executable, *args, *files], cwd=repo, env=env, capture_output=True,
                             text=True, timeout=TIMEOUT_S)
        code, output = res.returncode, res.stdout + res.stderr
    except subprocess.TimeoutExpired:
        code, output = -1, "timed out"
    return code, output, time.perf_counter() - start


def mutate(repo: Path, mutant: Mutant) -> dict[Path, str]:
    """Apply the mutant's edits; returns the original texts to restore. Each original text must
    occur exactly once in its file."""
    originals = {}
    for file, old, new in mutant.edits:
        path = repo / file
        text = originals.get(path) or path.read_text()
        originals.setdefault(path, text)
        current = path.read_text()
        if current.count(old) != 1:
            raise SystemExit(f"{mutant.name}: '{old}' occurs {current.count(old)} times in {file}, "
                             "not once: the code moved; update the mutant")
        path.write_text(current.replace(old, new))
    return originals


def line_of(repo: Path, file: str, old: str) -> int:
    text = (repo / file).read_text()
    return text[: text.index(old)].count("\n") + 1


def run_mutant(repo: Path, env: dict, mutant: Mutant) -> dict:
    where = ", ".join(f"{f}:{line_of(repo, f, old)}" for f, old, _ in mutant.edits)
    originals = mutate(repo, mutant)
    try:
        imp = subprocess.run([sys.executable, "-c", f"import {mutant.module}"], cwd=repo, env=env,
                             capture_output=True, text=True)
        if imp.returncode != 0:
            raise SystemExit(f"{mutant.name} breaks the import of {mutant.module}; a mutant must be a "
                             f"plausible bug, not a crash:\n{imp.stderr[-2000:]}")
        code, output, seconds = run_tests(PYTEST, mutant.tests, repo, env)
    finally:
        for path, text in originals.items():
            path.write_text(text)
    if code == 5:
        raise SystemExit(f"{mutant.name}: no tests collected from {mutant.tests}")
    verdict = "killed" if code in (1, 2) else ("killed (hang)" if code == -1 else
                                               "survived" if code == 0 else f"error {code}")
    return {"name": mutant.name, "why": mutant.why, "where": where, "change": mutant.edits[0][1:],
            "verdict": verdict, "killed_by": first_failure(output) if code else "", "seconds": round(seconds, 1),
            "tests": list(mutant.tests), "tail": output.strip().splitlines()[-3:] if code in (0, 2) else []}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", metavar="NAME", help="run only these mutants")
    ap.add_argument("--list", action="store_true", help="list the mutants and exit")
    ap.add_argument("--skip-baseline", action="store_true", help="do not first run the tests on the unmutated copy")
    ap.add_argument("--keep", action="store_true", help="keep the temporary copy")
    ap.add_argument("--markdown", action="store_true", help="also print the table as Markdown (for the README)")
    args = ap.parse_args()
    console = Console(width=None if sys.stdout.isatty() else 200)
    mutants = MUTANTS
    if args.only:
        unknown = set(args.only) - {m.name for m in MUTANTS}
        if unknown:
            raise SystemExit(f"unknown mutants {sorted(unknown)}; --list shows them")
        mutants = [m for m in MUTANTS if m.name in args.only]
    if args.list:
        for m in MUTANTS:
            console.print(f"{m.name:32s} {m.edits[0][0]:30s} {m.why}")
        return

    start = time.perf_counter()
    folder = Path(tempfile.mkdtemp(prefix="breastplan-mutants-"))
    try:
        repo, site = make_copy(folder)
        env = environment(site)
        imported = check_imports_from_copy(repo, site, env)
        console.print(f"copy: {repo} (breastplan imports from {imported})")
        for m in mutants:                              # every original text once, before spending time
            for file, old, _ in m.edits:
                if (repo / file).read_text().count(old) != 1:
                    raise SystemExit(f"{m.name}: '{old}' does not occur exactly once in {file}")
        baseline_s = None
        if not args.skip_baseline:
            files = list(dict.fromkeys(f for m in mutants for f in m.tests))
            console.print(f"baseline: {len(files)} test files on the unmutated copy …")
            code, output, baseline_s = run_tests(BASELINE, files, repo, env)
            if code != 0:
                console.print(escape(output[-4000:]))
                raise SystemExit(f"the unmutated copy fails its tests (exit {code}): fix them first")
            console.print(f"baseline passed in {baseline_s:.0f} s: {output.strip().splitlines()[-1]}")
        results = []
        for m in mutants:
            r = run_mutant(repo, env, m)
            results.append(r)
            style = "green" if r["verdict"].startswith("killed") else "red"
            console.print(f"[{style}]{r['verdict']:>8}[/] {m.name} ({r['seconds']} s) {escape(r['killed_by'])}")
    finally:
        if args.keep:
            console.print(f"kept {folder}")
        else:
            shutil.rmtree(folder, ignore_errors=True)
    total = time.perf_counter() - start

    table = Table(title="mutation check: one planted bug at a time, its relevant tests (pytest -x)",
                  title_justify="left")
    for col in ("mutant", "the bug", "where", "change", "verdict", "first failing test", "s"):
        table.add_column(col, overflow="fold")
    for r in results:
        old, new = r["change"]
        table.add_row(escape(r["name"]), escape(r["why"]), escape(r["where"]), escape(f"{old} → {new}"),
                      f"[green]{r['verdict']}[/]" if r["verdict"].startswith("killed") else f"[red]{r['verdict']}[/]",
                      escape(r["killed_by"]), f"{r['seconds']:.1f}")
    console.print(table)
    if args.markdown:
        print("| mutant | the bug | where | verdict | first failing test | s |\n|---|---|---|---|---|---:|")
        for r in results:
            print(f"| `{r['name']}` | {r['why']} | `{r['where']}` | {r['verdict']} | `{r['killed_by']}` | {r['seconds']:.1f} |")
    survivors = [r["name"] for r in results if not r["verdict"].startswith("killed")]
    for r in results:
        if r["tail"]:
            console.print(escape(f"{r['name']}: {' | '.join(r['tail'])}"))
    print(json.dumps({"figure": "mutants survived", "value": len(survivors), "target": 0, "mutants": len(results),
                      "killed": len(results) - len(survivors), "survivors": survivors,
                      "seconds": round(total, 1), "baseline_seconds": None if baseline_s is None else round(baseline_s, 1),
                      "mutant_seconds": {r["name"]: r["seconds"] for r in results}}))


if __name__ == "__main__":
    main()
