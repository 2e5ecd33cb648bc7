"""One case of a batch, as a worker runs it, and how the batch tells a finished case.

A case folder appears whole or not at all: a new case is built in a hidden sibling and renamed into
place by `run_plan`; a case planned before is planned again in a hidden sibling — from a copy of it
when its input is unchanged (its unchanged stages reused), afresh when the file's content changed — and
swapped in (`swap_in`). A batch killed at any moment leaves
finished cases intact and only hidden folders (`LEFTOVER`), which the next batch removes.
"""
from __future__ import annotations

import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

from breastplan.building import LEFTOVER, sibling, swap_in
from breastplan.code_digest import code_digest




@dataclass(frozen=True)
class Task:
    """A case to plan: the input file, the case folder (absolute paths), the plan's options as plain
    JSON values (`PlanOptions.as_dict`) and the input's SHA-256."""

    input: str
    case: str
    options: dict
    sha256: str


def plan_case(task: Task) -> dict:
    """Plan one case (in a worker); {"status": "done" | "failed", "seconds", "error"}. Never raises for
    a bad input: a failing case is a row of the manifest, not the end of the batch."""
    from threadpoolctl import threadpool_limits

    from breastplan import BadInputError

    start = time.perf_counter()
    try:
        with threadpool_limits(1):
            _plan(task)
        status, error = "done", ""
    except BadInputError as exc:
        status, error = "failed", str(exc)
    except OSError as exc:
        status, error = "failed", f"{exc.filename or task.input}: {exc.strerror or exc}."
    except Exception as exc:  # a bug or a library's failure on this input: reported, the batch goes on
        status, error = "failed", f"{task.input}: unexpected error ({type(exc).__name__}: {exc})."
    if status == "failed" and _planned_input(Path(task.case)) not in (None, task.sha256):
        error += f" Its case folder {task.case} still holds the plan of this file's earlier content."
    return {"status": status, "seconds": round(time.perf_counter() - start, 3), "error": error}


def _plan(task: Task) -> None:
    from breastplan.options import PlanOptions
    from breastplan.plan.job import run_plan

    options = PlanOptions.from_dict(task.options)
    case = Path(task.case)
    if not case.exists():
        run_plan(Path(task.input), case, options)
        return
    work = sibling(case, "batch")
    try:
        planned = _plan_file(case)
        if planned is not None and planned.current and planned.input_sha256 == task.sha256:
            shutil.copytree(case, work, symlinks=True)  # the same input: reuse its stages; else plan afresh
        run_plan(Path(task.input), work, options)
        swap_in(work, case)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def finished(case: Path, sha256: str, options: dict) -> bool:
    """Whether `case` holds a whole plan of the input of this SHA-256 with these options, made by this code:
    its plan.json says so, and every file it names is there, with each side's scan and fit."""
    planned = _plan_file(case)
    return (planned is not None and planned.current and planned.input_sha256 == sha256
            and planned.options == options and planned.code == code_digest() and planned.files is not None
            and all((case / f).is_file() for f in planned.files))


def _planned_input(case: Path) -> str | None:
    """The SHA-256 of the input `case` holds a plan of; None if it holds none."""
    planned = _plan_file(case)
    return None if planned is None else planned.input_sha256


def _plan_file(case: Path):
    """The case's plan.json (`plan.plan_file.PlanFile`); None if it has none or it is not a JSON object."""
    from breastplan.plan.plan_file import read_plan_file

    try:
        return read_plan_file(case)
    except (OSError, ValueError):
        return None


def remove_leftovers(out: Path) -> list[Path]:
    """Remove the hidden folders a killed batch left under `out`; the removed paths."""
    removed = []
    for here, dirs, _ in os.walk(out):
        for d in list(dirs):
            if LEFTOVER.match(d):
                shutil.rmtree(Path(here) / d, ignore_errors=True)
                removed.append(Path(here) / d)
                dirs.remove(d)
    return removed
