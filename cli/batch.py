"""The `batch` command: every scan and recording of a folder planned, locally or on Dask (docs/cli.md)."""
from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from breastplan.errors import counted
from breastplan.options import DEFAULT_PLAN, DEGREE_KINDS, BatchOptions, OptionError, PlanOptions

from .app import JSON, UNITS_HELP, UP_HELP, command
from .output import read_only, real, report, stderr, stdout, usage_error, writable
from .plan import FLAGS as PLAN_FLAGS
from .plan import check_method, check_operation_models

FLAGS = {**PLAN_FLAGS, "jobs": "--jobs", "executor": "--executor", "scheduler": "--scheduler"}


@command()
def batch(
    input: Path = typer.Argument(..., help="The folder of scans and recordings (searched recursively)."),
    out: Path = typer.Option(..., "--out", help="The output folder: one case folder per input, the manifest "
                             "(manifest.csv, manifest.json) and each breast's measures (measures.csv)."),
    jobs: int = typer.Option(1, "--jobs", help="Cases planned at once (one BLAS thread each); with Dask and no "
                             "--scheduler, the local cluster's workers."),
    side: str = typer.Option("both", "--side", help="The breasts to plan: left, right or both."),
    deform: List[str] = typer.Option([], "--deform", help="KIND:DEGREE, repeatable, KIND one of "
                                     f"{', '.join(DEGREE_KINDS)}. Default: "
                                     + " ".join(f"{k}:{d:g}" for k, d in DEFAULT_PLAN) + "."),
    method: str = typer.Option("exact", "--method", help="exact, learnt or MODEL.npz, as for plan."),
    operation_model: List[Path] = typer.Option([], "--operation-model", help="A clinic's model of one operation, "
                                               "as for plan: it makes that operation wherever a patient's plan "
                                               "file names it. Repeatable, one per operation."),
    units: str = typer.Option("auto", "--units", help=UNITS_HELP + " The same for every scan file."),
    up: str = typer.Option("auto", "--up", help=UP_HELP + " The same for every scan file."),
    executor: str = typer.Option("local", "--executor", help="local (worker processes) or dask (a Dask "
                                 "distributed cluster)."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", help="With --executor dask: the address of a "
                                            "running scheduler (e.g. tcp://host:8786); default: a local cluster."),
    wall_from: Optional[Path] = typer.Option(None, "--wall-from", help="An earlier batch's output folder: each "
                                             "input is planned as a follow-up (plan --wall-from) of the case of "
                                             "the same name there."),
    as_json: bool = JSON,
):
    """Plan every scan and recording of a folder, one case folder each, with a manifest; resumable.
    Exit 0 when any input was planned, 3 when none was."""
    from breastplan import BadInputError
    from breastplan.errors import require_folder

    try:
        models = tuple(str(p.absolute()) for p in operation_model)
        options = BatchOptions(PlanOptions.parse(deform, side, method, units, up, operation_models=models), jobs,
                               executor, scheduler, None if wall_from is None else str(wall_from))
    except OptionError as exc:
        raise usage_error(str(exc), FLAGS[exc.option]) from None
    check_method(method)
    check_operation_models(options.plan, planned=False)
    if wall_from is not None:
        read_only(wall_from, out)
    if real(out) == real(input):
        raise usage_error(f"it names IN_DIR itself ({input}), whose case folders the next batch would take for "
                          "scans; give another folder (one inside IN_DIR is left out of the search)", "--out")
    require_folder(input, "folder of scans and recordings")
    if wall_from is not None:
        require_folder(wall_from, "folder of earlier cases")
    writable(out, folder=True)

    from breastplan.batch.run import run_batch

    with _Progress() as progress:
        result = run_batch(input, out, options, progress)
    manifest = result.manifest
    for row in manifest.rows:
        if row.status == "skipped":
            stderr.print(f"warning: {row.error}", markup=False, soft_wrap=True)
    summary = manifest.summary()
    if as_json:
        report({"out": str(out), "manifest": str(out / "manifest.csv"), "measures": str(out / "measures.csv"),
                "summary": summary,
                "failed": {r.input: r.error for r in manifest.rows if r.status == "failed"}}, True, "")
    else:
        _print_summary(out, manifest)
    if not manifest.succeeded():
        raise BadInputError(input, f"no input was planned ({summary['failed']} failed, {summary['skipped']} "
                                   f"skipped; see {out / 'manifest.csv'})")


def _print_summary(out: Path, manifest) -> None:
    s = manifest.summary()
    stdout.print(f"batch: {counted(s['inputs'], 'input')} — {s['done']} planned, {s['reused']} reused, "
                 f"{s['failed']} failed, {s['skipped']} skipped; manifest → {out / 'manifest.csv'}, "
                 f"each breast's measures → {out / 'measures.csv'}", markup=False, soft_wrap=True)
    for row in manifest.rows:
        if row.status == "failed":
            stdout.print(f"  failed: {row.error}", markup=False, soft_wrap=True)


class _Progress:
    """A progress bar of the cases settled, on a terminal's stderr; nothing otherwise."""

    def __enter__(self):
        from rich.progress import Progress

        self.bar = Progress(console=stderr, transient=True) if stderr.is_terminal else None
        self.task = None
        if self.bar:
            self.bar.start()
        return self.advance

    def advance(self, row, total: int) -> None:
        if not self.bar or row.status in ("skipped", "reused"):
            return
        if self.task is None:
            self.task = self.bar.add_task("batch", total=total)
        self.bar.update(self.task, advance=1, description=f"batch: {row.input} {row.status}")

    def __exit__(self, *exc):
        if self.bar:
            self.bar.stop()
