"""The package works from a wheel install, not only from the repository's editable install.

Once per module: build the wheel from a copy of the source tree (nothing is written in the
repository), install it with `pip --no-deps --no-index` into a fresh venv, then make the heavy
dependencies of .venv importable there through a `.pth` file holding the path of .venv's
site-packages.  A plain path line in a .pth only adds that folder to sys.path: the .pth files
inside it, among them the editable-install finder of this repository, are not run, so
`breastplan` can only come from the wheel.  Everything then runs with a clean environment (no
PYTHONPATH, no user site) from a folder outside the repository.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
import sysconfig
import tomllib
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text())
SETUPTOOLS = PYPROJECT["tool"]["setuptools"]
DATA = [  # (package, file inside it) that the wheel must carry
    ("breastplan.plan", "data/sample.mcap"),
    ("breastplan.plan", "data/sample_truth.npz"),
    ("breastplan.scenes", "assets/makehuman.npz"),
    *(("breastplan.deform", f"models/{p.name}") for p in sorted((REPO / "deform" / "models").glob("*.npz"))),
]
DEPS = list(dict.fromkeys(sysconfig.get_paths()[k] for k in ("purelib", "platlib")))
"""Site-packages of the venv running the tests (.venv): the dependencies, put on the fresh venv's path."""
COPY_IGNORE = shutil.ignore_patterns(".venv", ".git", "out", "build", "dist", "*.egg-info", "__pycache__",
                                     ".pytest_cache", ".hypothesis", "tests", "benchmarks")


def _version(dist: str) -> tuple[int, ...]:
    try:
        return tuple(int(x) for x in version(dist).split(".")[:2] if x.isdigit())
    except PackageNotFoundError:
        return ()


def _can_build_offline() -> bool:
    """Does this venv hold the build backend pyproject.toml asks for (setuptools>=69, bdist_wheel)?"""
    setuptools = _version("setuptools")
    return setuptools >= (69,) and (setuptools >= (70, 1) or _version("wheel") != ())


def _run(cmd, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=600, **kw)


def _check(res: subprocess.CompletedProcess, what: str) -> None:
    assert res.returncode == 0, f"{what} failed (exit {res.returncode}):\n{res.stdout[-3000:]}\n{res.stderr[-3000:]}"


class Installed:
    """The fresh venv with the wheel installed; `run()` runs its commands cleanly."""

    def __init__(self, root: Path):
        self.venv = root / "fresh"
        self.cwd = root / "elsewhere"   # the current directory of every run: outside the repository
        self.home = root / "home"
        self.python = self.venv / "bin" / "python"
        self.env = {"PATH": f"{self.venv / 'bin'}:/usr/local/bin:/usr/bin:/bin", "HOME": str(self.home),
                    "LANG": "C.UTF-8", "PYTHONNOUSERSITE": "1"}

    def run(self, *cmd) -> subprocess.CompletedProcess:
        return _run(cmd, cwd=self.cwd, env=self.env)

    def python_json(self, code: str):
        """Run `code` (which prints one JSON value) with the fresh venv's python; that value."""
        res = self.run(self.python, "-c", code)
        _check(res, "the fresh venv's python")
        return json.loads(res.stdout)


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Installed:
    root = tmp_path_factory.mktemp("wheel")
    assert not root.resolve().is_relative_to(REPO)
    inst = Installed(root)
    for folder in (inst.cwd, inst.home):
        folder.mkdir()

    src, dist = root / "src", root / "dist"
    shutil.copytree(REPO, src, ignore=COPY_IGNORE)
    # Offline when .venv has the build backend; otherwise pip builds in an isolated environment
    # with setuptools and wheel from the package index, as `make` does for the editable install.
    offline = ["--no-build-isolation", "--no-index"] if _can_build_offline() else []
    _check(_run([sys.executable, "-m", "pip", "wheel", "--no-deps", *offline, "-w", dist, src], cwd=root),
           "pip wheel")
    wheels = list(dist.glob("breastplan-*.whl"))
    assert len(wheels) == 1, wheels

    _check(_run([sys.executable, "-m", "venv", "--without-pip", inst.venv]), "python -m venv")
    # pip of .venv installs into the fresh venv; done before the .pth exists, so pip does not
    # see .venv's own breastplan distribution.
    _check(_run([sys.executable, "-m", "pip", "--python", inst.python, "install", "--no-deps", "--no-index",
                 "--disable-pip-version-check", "--quiet", wheels[0]]), "pip install of the wheel")

    fresh_site = Path(inst.python_json("import json, sysconfig; print(json.dumps(sysconfig.get_paths()['purelib']))"))
    (fresh_site / "zz_breastplan_test_deps.pth").write_text("".join(f"{d}\n" for d in DEPS))
    return inst


@pytest.fixture(scope="module")
def run_installed(installed):
    """`run_installed(args)`: CompletedProcess of the wheel's `breastplan ARGS` (clean env, cwd outside the repo)."""
    def run_installed(args) -> subprocess.CompletedProcess:
        return installed.run(installed.venv / "bin" / "breastplan", *args)
    return run_installed


def test_plan_runs_from_the_wheel(run_installed, tmp_path):
    case = tmp_path / "case"
    res = run_installed(["plan", "--out", case, "--json"])
    assert res.returncode == 0, res.stderr[-3000:]
    assert (case / "report.html").is_file()


IMPORT_ALL = """
import importlib, json, sys
modules = {p: importlib.import_module(p).__file__ for p in %r}
finders = [f"{getattr(f, '__module__', '')}.{getattr(f, '__name__', type(f).__name__)}" for f in sys.meta_path]
print(json.dumps({"modules": modules, "loaded": finders + sorted(sys.modules), "path": sys.path}))
"""


def test_breastplan_is_imported_from_the_fresh_venv(installed):
    got = installed.python_json(IMPORT_ALL % (SETUPTOOLS["packages"],))
    fresh = installed.venv.resolve()
    for package, file in got["modules"].items():
        assert Path(file).resolve().is_relative_to(fresh), f"{package} imported from {file}, not the wheel"
    editable = [m for m in got["loaded"] if "editable" in m.lower()]  # setuptools' __editable___*_finder
    assert editable == [], f"the repository's editable install is active in the fresh venv: {editable}"
    entries = [(installed.cwd / p).resolve() for p in got["path"]]  # '' is the current directory
    repo_entries = [p for p in entries if p.is_relative_to(REPO) and not p.is_relative_to(REPO / ".venv")]
    assert repo_entries == [], f"the repository is on the fresh venv's sys.path: {repo_entries}"


def test_every_module_of_the_source_tree_is_installed(installed):
    """Each .py of each package directory (pyproject's package-dir) is in the fresh venv."""
    site = Path(installed.python_json(
        "import json, pathlib, breastplan; print(json.dumps(str(pathlib.Path(breastplan.__file__).parents[1])))"))
    for package in SETUPTOOLS["packages"]:
        source = REPO / SETUPTOOLS["package-dir"][package]
        target = site.joinpath(*package.split("."))
        missing = [p.name for p in source.glob("*.py") if not (target / p.name).is_file()]
        assert missing == [], f"{package}: {missing} not in the wheel"


def test_package_data_is_installed_and_identical(installed):
    got = installed.python_json(
        "import hashlib, json\n"
        "from importlib.resources import files\n"
        f"data = {DATA!r}\n"
        "out = []\n"
        "for package, name in data:\n"
        "    res = files(package).joinpath(*name.split('/'))\n"
        "    out.append([str(res), hashlib.sha256(res.read_bytes()).hexdigest()])\n"
        "print(json.dumps(out))")
    assert len(got) == len(DATA)
    fresh = installed.venv.resolve()
    package_dir = SETUPTOOLS["package-dir"]
    for (package, name), (where, digest) in zip(DATA, got):
        assert Path(where).resolve().is_relative_to(fresh), f"{package}/{name} read from {where}"
        source = REPO / package_dir[package] / name
        assert digest == hashlib.sha256(source.read_bytes()).hexdigest(), f"{where} differs from {source}"
    assert any(package == "breastplan.deform" for package, _ in DATA), "no deform model in the source tree"


def test_package_data_loads_with_the_dependencies(installed):
    """numpy comes from .venv through the .pth; the data files load with it."""
    got = installed.python_json(
        "import json, numpy\n"
        "from importlib.resources import as_file, files\n"
        "out = {'numpy': numpy.__file__}\n"
        "for package, name in [('breastplan.plan', 'data/sample_truth.npz'), ('breastplan.scenes', 'assets/makehuman.npz')]:\n"
        "    with as_file(files(package).joinpath(*name.split('/'))) as f, numpy.load(f) as z:\n"
        "        out[name] = sorted(z.files)\n"
        "print(json.dumps(out))")
    numpy = Path(got.pop("numpy")).resolve()
    assert any(numpy.is_relative_to(Path(d).resolve()) for d in DEPS), f"numpy from {numpy}"
    assert all(keys for keys in got.values()), got


def test_console_script_help_exits_0(installed, run_installed):
    res = run_installed(["--help"])
    assert res.returncode == 0, res.stderr[-3000:]
    assert "Usage" in res.stdout
    assert (installed.venv / "bin" / "breastplan").read_text().splitlines()[0] == f"#!{installed.python}"
