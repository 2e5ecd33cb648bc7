"""A batch: every scan and recording of a folder planned as `plan` does, one case folder each.

The output folder holds one case per input (its path relative to the input folder, suffix dropped)
and the manifest; the folders the batch makes for cases are removed again if none of their cases was
planned. One batch writes a folder at a time (a lock); a batch resumes what an earlier one
left: cases whose input content and options are unchanged are reused, the rest planned, and the
hidden folders of a killed batch removed.
"""
from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

from breastplan import BadInputError, __version__
from breastplan.building import lock
from breastplan.case import sha256
from breastplan.errors import Interrupted, require_folder
from breastplan.options import SIDES, BatchOptions, OptionError, PlanOptions

from .executors import require_scheduler, run_dask, run_local
from .inputs import Input, find_inputs
from .manifest import Manifest, Row
from .task import Task, finished, remove_leftovers

LOCK = ".batch.lock"

Progress = Callable[[Row, int], None]
"""Called with each row as it is settled and the number of inputs to plan."""


@dataclass(frozen=True)
class Batch:
    """A finished batch: its manifest (rows, summary) and the leftovers of a killed batch it removed."""

    manifest: Manifest
    removed: tuple[Path, ...]


def run_batch(folder: Path, out: Path, options: BatchOptions, progress: Progress = lambda row, total: None) -> Batch:
    """Plan every scan and recording under `folder` into `out` (docs/cli.md, `batch`)."""
    folder, out = Path(folder), Path(out)
    require_folder(folder, "folder")
    inputs = find_inputs(folder, out)
    if not inputs:
        raise BadInputError(folder, "holds no file to plan (no scan or recording)")
    if options.executor == "dask" and options.scheduler is not None:
        require_scheduler(options.scheduler)      # unreachable, or no scheduler: said before anything is written
    out.mkdir(parents=True, exist_ok=True)
    with _locked(out):
        removed = remove_leftovers(out)
        rows, tasks = _rows_and_tasks(inputs, out, options)
        about = {"version": __version__, "input_folder": str(folder), "options": options.as_dict()}
        manifest = Manifest(out, about, rows)
        manifest.write()
        by_case = {r.case: r for r in rows if r.status == "pending"}   # case names unique among the planned

        def row_of(task: Task) -> Row:
            return by_case[Path(task.case).relative_to(out.resolve()).as_posix()]

        for row in rows:
            if row.status != "pending":
                progress(row, len(tasks))
        made = _make_parents(tasks, out)
        results = run_local(tasks, options.jobs) if options.executor == "local" else \
            run_dask(tasks, options.jobs, options.scheduler)
        try:
            for settled in results:             # the cases finished while the manifest was last written
                for task, result in settled:
                    row = row_of(task)
                    error = result["error"].replace(task.input, str(folder / row.input))
                    error = error.replace(task.case, str(out / row.case))
                    if options.wall_from is not None:
                        error = error.replace(task.options["wall_from"], str(Path(options.wall_from) / row.case))
                    row.status, row.seconds, row.error = result["status"], result["seconds"], error   # paths as given
                manifest.write()
                for task, _ in settled:
                    progress(row_of(task), len(tasks))
        except KeyboardInterrupt:
            results.close()                       # its workers killed: the cases they were planning left unfinished
            remove_leftovers(out)
            for task in tasks:                    # finished on disk before its result reached the batch
                row = row_of(task)
                if row.status == "pending" and finished(Path(task.case), task.sha256, task.options):
                    row.status = "done"
            manifest.write()
            summary = manifest.summary()
            raise Interrupted(f"{len(tasks) - summary['pending']} of the {len(tasks)} inputs to plan were settled "
                              f"and {summary['pending']} left pending in {out / 'manifest.csv'}; the same command "
                              f"resumes the batch") from None
        finally:
            for parent in made[::-1]:           # deepest first
                with contextlib.suppress(OSError):      # only if empty: none of its cases planned
                    parent.rmdir()
    return Batch(manifest, tuple(removed))


def _rows_and_tasks(inputs: list[Input], out: Path, options: BatchOptions) -> tuple[list[Row], list[Task]]:
    """A row for every input (settled for the skipped, unreadable and reused) and a task for the rest
    (with `wall_from`, a follow-up of the earlier batch's case of the same name)."""
    rows, tasks = [], []
    for i in inputs:
        row = Row(i.name, i.case)
        rows.append(row)
        if i.skipped:
            row.status, row.error = "skipped", f"{i.path}: skipped: {i.skipped}."
            continue
        try:
            row.sha256 = sha256(i.path)
        except OSError as exc:
            row.status, row.error = "failed", f"{i.path}: cannot be read ({exc.strerror})."
            continue
        case = out.resolve() / i.case
        earlier = None if options.wall_from is None else str(Path(options.wall_from).resolve() / i.case)
        if earlier is not None and not Path(earlier).is_dir():
            row.status = "failed"
            row.error = (f"{i.path}: has no earlier visit to follow up: {Path(options.wall_from) / i.case} does not "
                         f"exist (the earlier batch planned no scan named {i.case}).")
            continue
        try:
            plan = {**_her_plan(options.plan, i.plan_file).as_dict(), "wall_from": earlier}
        except ValueError as exc:
            row.status, row.error = "failed", f"{exc}."
            continue
        if finished(case, row.sha256, plan):
            row.status = "reused"
        else:
            tasks.append(Task(str(i.path.absolute()), str(case), plan, row.sha256))
    return rows, tasks


def _her_plan(plan: PlanOptions, plan_file: Path | None) -> PlanOptions:
    """The batch's plan of every case, or the one her plan file (`plan.written_plan`) writes for her scan: its
    operations and its changes (without `deform`, none when it names operations, else the batch's). ValueError
    in one sentence naming the file when it cannot be read or planned."""
    if plan_file is None:
        return plan
    from breastplan.plan.operation_spec import written_operations
    from breastplan.plan.written_plan import read_written_plan

    written = read_written_plan(plan_file)
    try:
        operations = written_operations(written.left, written.right)
        changes = list(plan.deform_items) if not (operations or written.symmetrise) else []
        return PlanOptions.parse(list(written.deform) or changes, "both" if plan.sides == SIDES else plan.sides[0],
                                 plan.method, plan.units, plan.up, plan.wall_from, operations, written.symmetrise,
                                 plan.operation_models)
    except OptionError as exc:
        raise ValueError(f"{plan_file}: {exc}") from None


def _make_parents(tasks: list[Task], out: Path) -> list[Path]:
    """Make the missing folders the tasks' cases lie in, once, before the workers (which would race to make
    and remove them); those that were missing, parents first."""
    root = out.resolve()
    needed = {root / p for t in tasks for p in Path(t.case).relative_to(root).parents[:-1]}
    made = sorted((p for p in needed if not p.exists()), key=lambda p: len(p.parts))
    for parent in made:
        with contextlib.suppress(OSError):      # one that cannot be made fails its cases, each with its sentence
            parent.mkdir(exist_ok=True)
    return made


@contextlib.contextmanager
def _locked(out: Path) -> Iterator[None]:
    """Hold `out`'s batch lock (released by the system if the batch is killed)."""
    (out / LOCK).touch()
    fd = lock(out / LOCK, wait=False)
    if fd is None:
        raise BadInputError(out, "is being written by another batch (its lock is held); wait for it to finish")
    try:
        yield
    finally:
        os.close(fd)
