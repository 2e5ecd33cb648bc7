"""The inputs of a batch: every scan and recording under a folder, each with the case it becomes.

A folder is walked recursively (hidden entries and the batch's own output folder left out, symbolic
links to folders not followed). Each file becomes an `Input`: one to plan, or one skipped with the
reason — not a scan or recording, not a regular file (a named pipe, a device), a symbolic link
leading outside the folder or into a loop of links, a case name already taken by another input
(`a.ply` and `a.mcap` both become case `a`; the first in sorted order is planned), or a case inside
another's (`a/left.ply` beside `a.ply`). A plan file beside a scan (`a.plan.yaml`, `.plan.yml` or
`.plan.json` beside `a.ply`: `plan.written_plan`) goes with it, and is no input of its own; one with no
scan of its name beside it is skipped, saying so. An OBJ's material and texture of its own name beside it
(`a.mtl`, `a.png` beside `a.obj`, as scanners export them) are read with it, and are no inputs either.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from breastplan.errors import loops
from breastplan.ingest.files import SUPPORTED

SCAN_SUFFIXES = (".mcap", *SUPPORTED)
"""A recording (.mcap) or a scan file of a format ingest reads."""
PLAN_SUFFIXES = (".plan.yaml", ".plan.yml", ".plan.json")
"""A scan's own plan file: its name, then one of these."""
OBJ_COMPANIONS = (".mtl", ".png", ".jpg", ".jpeg", ".bmp", ".tga", ".tif", ".tiff")
"""What a scanner writes beside its OBJ, of the OBJ's name: its material and its texture."""


@dataclass(frozen=True)
class Input:
    """One file of the input folder: its path, its name relative to the folder (POSIX), the case folder
    it becomes (relative to the output folder), when it is not planned, why, and its plan file if any."""

    path: Path
    name: str
    case: str
    skipped: str | None = None
    plan_file: Path | None = None      # her plan, beside her scan


def find_inputs(folder: Path, out: Path | None = None) -> list[Input]:
    """Every file under `folder` (sorted by relative name), as an Input; `out` (the batch's output
    folder, if inside `folder`) is not searched."""
    folder = Path(folder)
    root = folder.resolve()
    skip_dir = out.resolve() if out is not None else None
    found: list[Input] = []
    unreadable = lambda e: found.append(_input(folder, Path(e.filename), f"a folder that cannot be read ({e.strerror})"))  # noqa: E731
    for here, dirs, files in os.walk(folder, onerror=unreadable):
        base = Path(here)
        kept = []
        for d in sorted(dirs):
            path = base / d
            if d.startswith(".") or path.resolve() == skip_dir:
                continue
            if path.is_symlink():
                found.append(_input(folder, path, "a symbolic link to a folder, not followed"))
                continue
            kept.append(d)
        dirs[:] = kept
        for f in files:
            if not f.startswith("."):
                found.append(_classify(folder, root, base / f))
    found.sort(key=lambda i: i.name)
    return _mark_duplicates(_with_plan_files(_without_obj_companions(found)))


def _without_obj_companions(found: list[Input]) -> list[Input]:
    """The inputs less each OBJ's material and texture of its own name beside it (OBJ_COMPANIONS)."""
    objs = {i.case for i in found if i.skipped is None and i.name.lower().endswith(".obj")}
    return [i for i in found if not (Path(i.name).suffix.lower() in OBJ_COMPANIONS and i.case in objs)]


def _with_plan_files(found: list[Input]) -> list[Input]:
    """The inputs with each scan's plan file (PLAN_SUFFIXES) given to it; a plan file with no scan or recording
    of its name beside it, or a second one of a scan, skipped, saying so."""
    plans: dict[str, list[Input]] = {}
    out = []
    for i in found:
        suffix = next((p for p in PLAN_SUFFIXES if i.name.lower().endswith(p)), None)
        if suffix is not None and i.skipped is None:
            plans.setdefault(i.name[:-len(suffix)], []).append(i)
        else:
            out.append(i)
    scans: dict[str, Input] = {}
    for i in out:
        if i.skipped is None:
            scans.setdefault(i.case, i)                    # the first of a case name is planned
    for stem, files in plans.items():
        scan = scans.get(stem)
        if scan is None:
            out += [Input(f.path, f.name, f.case, "a plan file with no scan or recording of its name beside it")
                    for f in files]
            continue
        out[out.index(scan)] = Input(scan.path, scan.name, scan.case, None, files[0].path)
        out += [Input(f.path, f.name, f.case, f"a second plan file of {scan.name} (its plan is {files[0].name})")
                for f in files[1:]]
    return sorted(out, key=lambda i: i.name)


def _classify(folder: Path, root: Path, path: Path) -> Input:
    if path.is_symlink():
        if loops(path):
            return _input(folder, path, "a symbolic link loop")
        target = path.resolve()
        if not target.is_relative_to(root):
            return _input(folder, path, f"a symbolic link leading outside the input folder (to {target})")
    if path.suffix.lower() not in SCAN_SUFFIXES and not path.name.lower().endswith(PLAN_SUFFIXES):
        return _input(folder, path, f"not a scan or recording (the planned kinds end in {', '.join(SCAN_SUFFIXES)})")
    if path.exists() and not path.is_file():  # a named pipe or a device: reading it may never end
        return _input(folder, path, "not a regular file")
    return _input(folder, path)


def _input(folder: Path, path: Path, skipped: str | None = None) -> Input:
    name = path.relative_to(folder).as_posix()
    return Input(path, name, str(Path(name).with_suffix("").as_posix()), skipped)


def _mark_duplicates(inputs: list[Input]) -> list[Input]:
    """The second and later inputs of one case name skipped, naming the first; and an input whose case
    folder would lie inside another's (`anna/left.ply` beside `anna.ply`, whose case holds `left/`),
    naming the input whose case holds it."""
    owner: dict[str, str] = {}
    for i in inputs:
        if i.skipped is None:
            owner.setdefault(i.case, i.name)
    marked = []
    for i in inputs:
        reason = None if i.skipped is not None else _clash(i, owner)
        marked.append(i if reason is None else Input(i.path, i.name, i.case, reason))
    return marked


def _clash(i: Input, owner: dict[str, str]) -> str | None:
    """Why a planned input must be skipped after all: its case taken by another input, or lying inside one."""
    if owner[i.case] != i.name:
        return f"a duplicate name: case '{i.case}' is planned from {owner[i.case]}"
    outer = next((p.as_posix() for p in Path(i.case).parents if p.as_posix() in owner), None)
    if outer is not None:
        return f"its case '{i.case}' would lie inside case '{outer}', planned from {owner[outer]}"
    return None
