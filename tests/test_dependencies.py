"""The packages' imports point one way, as docs/design.md draws them: a module imports from its own package and
from packages to its right, never to its left nor beside it, so that no two packages import each other."""
import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _order() -> list[list[str]]:
    """The packages left to right, each step's packages together, from docs/design.md's drawing."""
    line = next(l for l in (ROOT / "docs" / "design.md").read_text().splitlines() if l.startswith("cli → "))
    return [[p.strip() for p in step.split(",")] for step in line.split("→")]


def _imported(path: Path) -> list[tuple[int, str]]:
    """(line, the breastplan package) of every import of breastplan's in `path` (the core for `breastplan` itself)."""
    packages = {p for step in _order() for p in step}
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        names = []
        if isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").startswith("breastplan"):
            names = [node.module]
        elif isinstance(node, ast.ImportFrom) and node.level == 2:
            names = ["breastplan." + (node.module or "")]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names if a.name.startswith("breastplan")]
        for name in names:
            parts = name.split(".")
            found.append((node.lineno, parts[1] if len(parts) > 1 and parts[1] in packages else "core"))
    return found


def test_every_import_points_to_the_right_of_its_package_in_the_design():
    order = _order()
    assert [p for step in order for p in step][-1] == "core" and len(order) > 5
    rank = {p: i for i, step in enumerate(order) for p in step}
    wrong = [f"{path.relative_to(ROOT)}:{line} imports breastplan.{target}"
             for package in rank for path in sorted((ROOT / package).glob("*.py"))
             for line, target in _imported(path)
             if target != package and rank[target] <= rank[package]]
    assert wrong == []
