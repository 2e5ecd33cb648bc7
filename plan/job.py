"""The main job: a patient's scan → her fitted breasts (`plan.stages`) → the plan computed
(`plan.compute`) → written (`plan.record`: plan.json, the report, the summary, the changed surfaces).

A plan's case folder holds one case per side (`left/`, `right/`: scan, fit and `plan/<change>.*`)
and, at its top, `report.html`, `summary.png` and `plan.json` (docs/artefacts.md). Its input is
a recording, a scan file, a case folder (a plan's, or one side's from `ingest`), or nothing (the
bundled sample recording). Stages whose inputs and options hash as before are reused. A new case
folder is built beside its target and renamed into place when whole, so a failed plan leaves none;
an existing one (of the same input) is updated one artefact set at a time, each all or nothing.
"""
from __future__ import annotations

from dataclasses import replace
from importlib import resources
from pathlib import Path

from breastplan.building import building
from breastplan.case import Case
from breastplan.clock import Clock
from breastplan.errors import about
from breastplan.options import PlanOptions

from .changes import Method
from .result import Patient, Plan
from .stages import Progress, check_own_case, check_same_patient, earlier_volumes, fitted_sides


def sample_recording() -> Path:
    """The bundled sample recording (a synthetic patient, 10 depth frames), inside the package."""
    return Path(str(resources.files("breastplan.plan") / "data" / "sample.mcap"))


def run_plan(input: Path | None, out: Path, options: PlanOptions, progress: Progress = lambda _: None,
             method: Method | None = None, force: bool = False, patient: Patient | None = None,
             parallel: bool = False) -> Plan:
    """Plan `options` on `input` (None: the bundled sample) into the case folder `out`, by `method`
    (`options.method` resolved; resolved here when not given), for `patient` (named in the report and
    handout; default anonymous, today). A folder `out` holding the case of another input is refused, or
    with `force` planned afresh and put in its place whole. `parallel`: fit both sides, and draw her pictures
    beside the report, at once when two CPUs allow (`breastplan.forked`); a batch, which plans several cases
    at once, leaves it off."""
    from threadpoolctl import threadpool_limits

    from .compute import compute_plan
    from .record import write_plan

    source = sample_recording() if input is None else Path(input)
    method = method or _resolved(options.method)
    if not force:
        check_own_case(source, out)
    if options.wall_from is not None and patient is not None:
        check_same_patient(Path(options.wall_from), patient.patient_id)
    clock = Clock()
    with threadpool_limits(1, "blas"), building(out, "plan", force) as folder:   # small dense solves: threads only add overhead
        fitted = fitted_sides(source, folder, options, clock, progress, parallel)
        progress("changes and measures")
        earlier = None if options.wall_from is None else earlier_volumes(Path(options.wall_from))
        with about(source):
            plan = replace(compute_plan(source, fitted, options, method, earlier, clock), patient=patient or Patient())
        with clock("report"):
            progress("report")
            write_plan(plan, folder, parallel)
    moved = {s: replace(sp, case=Case(out / sp.case.folder.relative_to(folder))) for s, sp in plan.sides.items()}
    return replace(plan, sides=moved)


def _resolved(name: str) -> Method:
    with about(Path(name)):
        return Method.resolve(name)
