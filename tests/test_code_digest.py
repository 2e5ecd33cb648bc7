"""The digest of breastplan's source that decides whether a stage or a plan made earlier is reused: it covers
every package the project installs, and depends on the source alone."""
import tomllib
from pathlib import Path

from breastplan.code_digest import PACKAGES, source_digest

ROOT = Path(__file__).resolve().parents[1]


def test_every_installed_package_is_in_the_digest():
    """Truth: pyproject.toml's list of the packages it installs."""
    installed = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]
    assert sorted(PACKAGES) == sorted(installed)


def _package(folder: Path, files: dict[str, bytes]) -> Path:
    folder.mkdir(parents=True)
    for name, text in files.items():
        (folder / name).write_bytes(text)
    return folder


def test_the_digest_is_the_sources_wherever_and_in_whatever_order_they_were_written(tmp_path):
    files = {"a.py": b"x = 1\n", "b.py": b"y = 2\n", "notes.md": b"not code"}
    one = _package(tmp_path / "one" / "pkg", files)
    two = _package(tmp_path / "two" / "pkg", dict(reversed(list(files.items()))))
    assert source_digest({"p": one}) == source_digest({"p": two})
    (two / "notes.md").write_bytes(b"other notes")                          # not source: the same digest
    assert source_digest({"p": one}) == source_digest({"p": two})
    (two / "b.py").write_bytes(b"y = 3\n")                                  # one byte of source: another
    assert source_digest({"p": one}) != source_digest({"p": two})
    (two / "b.py").write_bytes(b"y = 2\n")
    (two / "c.py").write_bytes(b"")                                         # a module added: another
    assert source_digest({"p": one}) != source_digest({"p": two})


def test_a_module_moved_to_another_package_changes_the_digest(tmp_path):
    here = _package(tmp_path / "a", {"m.py": b"z = 0\n"})
    empty = _package(tmp_path / "b", {})
    assert source_digest({"p": here, "q": empty}) != source_digest({"p": empty, "q": here})
