"""A copy of the repository laid out as an installed `breastplan` package: what the mutation check and
bench_plan_against run instead of the editable install.

setuptools' package-dir mapping (pyproject.toml) maps `breastplan` to core/, `breastplan.plan` to plan/
and so on; `lay_out` builds that package from a repository's folders by symbolic links, so that a folder
holding it, put first on PYTHONPATH, is what `import breastplan` finds.
"""
from __future__ import annotations

import tomllib
from pathlib import Path


def lay_out(repo: Path, site: Path) -> Path:
    """`site`, now holding the `breastplan` package of the repository `repo` (symbolic links into it)."""
    mapping = tomllib.loads((repo / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]
    top = site / "breastplan"
    top.mkdir(parents=True)
    for entry in (repo / mapping["breastplan"]).iterdir():
        (top / entry.name).symlink_to(entry)
    for package, source in mapping.items():
        if package != "breastplan":
            (top / package.split(".", 1)[1]).symlink_to(repo / source, target_is_directory=True)
    return site
