"""Compare the plan.json of two case folders, timings and the folders' own paths aside: what a change of
the code that should not change any plan is checked with (plan the same inputs with the code before and
after, into two folders).

Run:  .venv/bin/python benchmarks/compare_plans.py BEFORE AFTER [CASE ...]
      (BEFORE, AFTER: folders of case folders; CASE: their names, default every case folder in BEFORE)
Prints each case's verdict and every differing entry; exits 1 when any differs.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path


def record(case: Path, root: Path) -> dict:
    """The case's plan.json, its timings removed and its root folder's path written ROOT."""
    text = (case / "plan.json").read_text().replace(str(root), "ROOT")
    doc = json.loads(text)
    doc.pop("timings_ms", None)
    return doc


def differences(a, b, where: str = "") -> list[str]:
    if type(a) is not type(b):
        return [f"{where}: {a!r} → {b!r}"]
    if isinstance(a, dict):
        out = [] if list(a) == list(b) else [f"{where}: keys {list(a)} → {list(b)}"]
        return out + [d for k in a if k in b for d in differences(a[k], b[k], f"{where}.{k}")]
    if isinstance(a, list):
        if len(a) != len(b):
            return [f"{where}: {len(a)} items → {len(b)}"]
        return [d for i, (u, v) in enumerate(zip(a, b)) for d in differences(u, v, f"{where}[{i}]")]
    return [] if a == b else [f"{where}: {a!r} → {b!r}"]


def main() -> int:
    if len(sys.argv) < 3:
        print(__doc__.strip().splitlines()[-3], file=sys.stderr)
        return 2
    before, after = Path(sys.argv[1]).resolve(), Path(sys.argv[2]).resolve()
    cases = sys.argv[3:] or sorted(p.name for p in before.iterdir() if (p / "plan.json").is_file())
    differ = 0
    for name in cases:
        found = differences(record(before / name, before), record(after / name, after))
        print(f"{name}: {'identical' if not found else f'{len(found)} entries differ'}")
        for line in found[:20]:
            print("   ", line)
        differ += bool(found)
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
