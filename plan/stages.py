"""The stages a plan rests on, each side's: its scan (ingested, or taken from a case folder) and its fit
(down to an earlier case's chest wall for a follow-up), each reused from the case folder when its
inputs and options hash as before, else made and saved there.
"""
from __future__ import annotations

import contextlib
import os
import shutil
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterator

import numpy as np

from breastplan import BadInputError, transform_points
from breastplan.body import shared_body
from breastplan.case import Case, Fit, Provenance, Scan, sha256
from breastplan.clock import Clock
from breastplan.errors import ArtefactError, NewerArtefactError, about
from breastplan.options import SIDES, FitOptions, IngestOptions, PlanOptions

from .breast_volume import BreastVolumes
from .compute import measure_scans
from .plan_file import PLAN_SCHEMA, read_plan_file
from .result import FollowUp, SidePlan

if TYPE_CHECKING:
    from breastplan.ingest.follow_up import Registration

Progress = Callable[[str], None]


def fitted_sides(source: Path, folder: Path, options: PlanOptions, clock: Clock, progress: Progress,
                 parallel: bool = False) -> dict[str, SidePlan]:
    """Scan and fit each side (reusing what the case folder holds; down to the earlier case's wall
    with `wall_from`); no changes solved yet. With `parallel`, two sides to fit are fitted at once (`_fitted`)."""
    earlier = {} if options.wall_from is None else _earlier_cases(Path(options.wall_from), options.sides)
    if source.is_dir():
        held = _cases_of(source, options)
        scans = {side: _held_scan(case, side) for side, case in held.items()}
        shared_body({s: scan.body for s, scan in scans.items()}, source)    # one patient, before any fit
        cases = _copied(held, source, folder)
        reused = {side: ["ingest"] for side in cases}
    else:
        cases = {side: Case(folder / side) for side in options.sides}
        scans, reused = _ingest(source, cases, options, clock, progress)
    with clock("fit"), _named_in(source, folder):
        progress("fit " + " and ".join(cases))
        todo = {side: _to_fit(case, scans[side], earlier.get(side)) for side, case in cases.items()}
        fits = _fitted({side: t for side, t in todo.items() if t.fit is None}, cases, parallel)
    return {side: SidePlan(side, case, scans[side], fits.get(side) or todo[side].fit, (),
                           tuple(reused[side] + ([] if side in fits else ["fit"])), todo[side].follow_up)
            for side, case in cases.items()}


def check_own_case(source: Path, out: Path) -> None:
    """BadInputError when the folder `out` holds the case of another input than the file `source` (by
    content): a case is one patient's, of one recording."""
    if source.is_dir() or not out.is_dir():
        return
    try:
        planned = read_plan_file(out)
    except (OSError, ValueError):
        planned = None
    held = {planned.input_sha256} if planned is not None and planned.input_sha256 else \
        {sha for case in _side_cases(out) for sha in case.provenance(Case.SCAN_NPZ).inputs.values()}
    if held and sha256(source) not in held:
        raise BadInputError(out, f"holds the case of another input than {source} (another content): a case "
                                 "is one recording's; plan into a new folder, or give --force to replace it")


def check_same_patient(earlier: Path, patient_id: str | None) -> None:
    """BadInputError when the earlier visit's case folder `earlier` was planned for another patient ID than
    `patient_id` (None: none given, nothing to compare): a follow-up is measured on her own earlier scan, and the
    registration of two chests cannot tell every two women apart (docs/cli.md)."""
    if not patient_id:
        return
    try:
        then = read_plan_file(earlier)
    except (OSError, ValueError):
        return                                        # a damaged earlier plan is refused where it is read
    if then is not None and then.patient_id and then.patient_id != patient_id:
        raise BadInputError(earlier, f"is the plan of patient ID {then.patient_id}, not {patient_id}: a follow-up is "
                                     "measured on her own earlier scan")


def _side_cases(folder: Path) -> list[Case]:
    """The cases in `folder`: itself (one side's, from `ingest`) or its sides'."""
    return [c for c in (Case(folder), *(Case(folder / s) for s in SIDES)) if Case.holds(c.folder)]


def _cases_of(source: Path, options: PlanOptions) -> dict[str, Case]:
    """The side cases a case folder holds for the requested sides. A one-side case from `ingest`
    plans its own side."""
    _check_schema(source)
    _check_own_files(source)
    held = Case.of_sides(source)
    found = {s: case for s, case in held.items() if s in options.sides}
    missing = [] if found and Case.holds(source) else [s for s in options.sides if s not in held]
    if missing:
        raise BadInputError(source, f"holds no scan of the {' and '.join(missing)} breast; plan it from the "
                                    "recording or scan file")
    return found


def _check_own_files(source: Path) -> None:
    """BadInputError for a case folder holding a symbolic link (a plan writes and removes files in its case, and
    would do so wherever the link leads), or a folder where one of its files goes."""
    for root, dirs, files in os.walk(source):
        link = next((Path(root) / n for n in (*dirs, *files) if (Path(root) / n).is_symlink()), None)
        if link is not None:
            raise BadInputError(link, "is a symbolic link inside a case folder, which holds its own files only (a "
                                      "plan writes there): copy what it leads to in its place")
        folder = next((Path(root) / n for n in sorted(dirs) if n in Case.FILES), None)
        if folder is not None:
            raise BadInputError(folder, "is a folder where the case's file of that name belongs: remove it, or plan "
                                        "her again from her recording")


def _copied(cases: dict[str, Case], source: Path, folder: Path) -> dict[str, Case]:
    """`cases` (of the case folder `source`) copied into `folder`, unless the plan is made in place."""
    if folder.resolve() == source.resolve():
        return cases
    for side, case in cases.items():
        try:
            shutil.copytree(case.folder, folder / side, dirs_exist_ok=True)
        except shutil.Error as exc:                        # the files it could not copy: (from, to, why) each
            copied_from, _, why = exc.args[0][0]
            raise BadInputError(copied_from, f"cannot be read ({why.split('] ')[-1].split(':')[0]})") from None
    return {side: Case(folder / side) for side in cases}


@contextlib.contextmanager
def _named_in(source: Path, folder: Path) -> Iterator[None]:
    """A BadInputError about a file of the case copied from the case folder `source` into `folder` names the
    file of `source` it was copied from (the copy is in a hidden folder, removed when the plan fails)."""
    try:
        yield
    except BadInputError as exc:
        if not source.is_dir() or exc.path is None or not exc.path.is_relative_to(folder) or folder == source:
            raise
        raise BadInputError(source / exc.path.relative_to(folder), exc.problem) from None


def _held_scan(case: Case, side: str) -> Scan:
    """The scan a case folder holds for `side`: it cannot be made again without her recording, so a
    damaged one is refused saying so, and one of the other breast (a folder renamed) is refused."""
    try:
        scan = case.load_scan()
    except NewerArtefactError:
        raise
    except ArtefactError as exc:
        raise ArtefactError(exc.path, f"{exc.problem}; a case folder's scan cannot be made again: plan her "
                                      "recording or scan file again") from None
    if scan.side != side:
        raise BadInputError(case.folder, f"is the {side} side's case but holds a scan of her {scan.side} breast "
                                         "(scan.npz): a case's sides are not renamed; plan her recording again")
    return scan


def _reused(load: Callable, fresh: bool):
    """`load()` of a stage whose artefact is fresh; None (to be made again) when it is not, or is
    damaged or implausible. An artefact a newer breastplan wrote is refused, never made again over."""
    if not fresh:
        return None
    try:
        return load()
    except NewerArtefactError:
        raise
    except ArtefactError:
        return None


def _check_schema(folder: Path) -> None:
    """BadInputError naming a plan.json of another schema (an older or newer breastplan's case)."""
    doc = folder / Case.PLAN_JSON
    try:
        planned = read_plan_file(folder)
    except (OSError, ValueError):
        raise BadInputError(doc, "is not a plan record (not JSON)") from None
    if planned is None or planned.current:
        return
    schema = planned.schema
    name, _, version = schema.partition("/")
    if name != PLAN_SCHEMA.split("/")[0]:
        raise BadInputError(doc, f"is not a plan record (schema '{schema}')")
    age = "an older" if version.isdigit() and int(version) < int(PLAN_SCHEMA.split("/")[1]) else "another"
    raise BadInputError(folder, f"is a case folder of {age} schema ({schema}; this breastplan writes "
                                f"{PLAN_SCHEMA}); plan the patient's scan again into a new folder")


def _ingest(source: Path, cases: dict[str, Case], options: PlanOptions, clock: Clock, progress: Progress):
    """Each side's scan: reused when the case holds one made from this input with the same options."""
    from breastplan.ingest.scan import ingest_sides

    wanted = {side: IngestOptions(side, units=options.units, up=options.up) for side in cases}
    scans, reused = {}, {}
    stale = []
    for side, case in cases.items():
        scan = _reused(case.load_scan, case.is_fresh(Case.SCAN_NPZ, Provenance.of({source.name: source},
                                                                                    wanted[side].as_dict())))
        if scan is not None and scan.side == side:
            scans[side], reused[side] = scan, ["ingest"]
        else:
            stale.append(side)
            reused[side] = []
    if stale:
        with clock("ingest"), about(source):
            progress("ingest " + " and ".join(stale))
            for side, scan in zip(stale, ingest_sides(source, [wanted[s] for s in stale])):
                cases[side].save_scan(scan)
                scans[side] = scan
    return scans, reused


@dataclass(frozen=True)
class _ToFit:
    """A side's fit as the case holds it (None: to be made), the scan to fit (on an earlier case's wall for a
    follow-up), the fit's provenance and source file, and the follow-up."""

    fit: Fit | None
    scan: Scan
    wanted: Provenance
    source: Path
    follow_up: FollowUp | None


def _to_fit(case: Case, scan: Scan, earlier: Case | None) -> _ToFit:
    """The side's fit, reused when the case holds one of this scan (and of the earlier scan it is measured
    against) with the default options, else what to fit; and the follow-up."""
    scan_ply = case.path(Case.SCAN_PLY)
    inputs, options, follow_up = {scan_ply.name: scan_ply}, FitOptions().as_dict(), None
    if earlier is not None:
        with about(earlier.folder):
            earlier_scan = earlier.load_scan()
        scan, registration, more_inputs, more_options = on_earlier_wall(scan, earlier, earlier_scan)
        inputs, options = {**inputs, **more_inputs}, {**options, **more_options}
        then = _own_wall_fit(earlier, earlier_scan)
        later_from_earlier = np.linalg.inv(earlier_scan.input_to_breast @ registration.earlier_from_later)
        follow_up = FollowUp(earlier.folder, registration, then.volume_cc,
                             transform_points(later_from_earlier, then.vertices), then.faces,
                             earlier_scan.nipple_from_camera_mm)
    wanted = Provenance.of(inputs, options)
    return _ToFit(_reused(case.load_fit, case.is_fresh(Case.FIT_NPZ, wanted)), scan, wanted, scan_ply, follow_up)


def _fitted(todo: dict[str, _ToFit], cases: dict[str, Case], parallel: bool) -> dict[str, Fit]:
    """Each side of `todo` fitted and saved in its case. With `parallel` and two sides, the second is fitted
    in a forked child that saves it (`breastplan.forked`), while this process fits the first: the same
    computation, so the same fit. A child that fails or is stuck leaves its side to be fitted here, where
    any error is raised as usual."""
    from functools import partial

    from breastplan.fitting import breast_fit  # noqa: F401 — imported before the fork, not in the child
    from breastplan.forked import beside

    sides = list(todo)
    second = sides[1] if parallel and len(sides) == 2 else None
    fits = {}
    with beside(None if second is None else partial(_fit_and_save, todo[second], cases[second])) as finished:
        for side in sides:
            if side == second and finished() and cases[side].is_fresh(Case.FIT_NPZ, todo[side].wanted):
                fits[side] = cases[side].load_fit()
                continue
            fits[side] = fit_one_thread(todo[side].scan, FitOptions(), todo[side].source).artefact(todo[side].wanted)
            cases[side].save_fit(fits[side])
    return fits


def _fit_and_save(todo: _ToFit, case: Case) -> None:
    """A forked child's work: fit one side and save its fit in its case."""
    case.save_fit(fit_one_thread(todo.scan, FitOptions(), todo.source).artefact(todo.wanted))


def on_earlier_wall(scan: Scan, earlier: Case, earlier_scan: Scan) -> tuple[Scan, Registration, dict, dict]:
    """`scan` with an earlier case's chest wall carried over (`ingest.follow_up.carried_wall`: the two
    chests registered; `earlier_scan`: the earlier case's scan, loaded), the registration, and the inputs
    and options it adds to the fit's provenance. Bad input names the earlier case."""
    from breastplan.ingest.follow_up import carried_wall

    with about(earlier.folder):
        wall, registration = carried_wall(earlier_scan, scan)
    return (replace(scan, chest_wall=wall), registration, *registration.provenance(earlier.folder))


def _own_wall_fit(case: Case, scan: Scan) -> Fit:
    """An earlier breast's fit down to its own chest wall: its case's fit.npz when that was made with
    the default options, else fitted now (and not written: the earlier case is only read)."""
    scan_ply = case.path(Case.SCAN_PLY)
    wanted = Provenance.of({scan_ply.name: scan_ply}, FitOptions().as_dict())
    return _reused(case.load_fit, case.is_fresh(Case.FIT_NPZ, wanted)) or \
        fit_one_thread(scan, FitOptions(), scan_ply).artefact(wanted)


def fit_one_thread(scan: Scan | np.ndarray, options: FitOptions, source: Path):
    """`fit_scan` of a scan (or `fit_breast` of breast-frame points, mm) with `options`, on one BLAS
    thread (small dense solves: threads only add overhead), bad input naming `source`."""
    from threadpoolctl import threadpool_limits

    from breastplan.fitting.breast_fit import fit_breast, fit_scan

    with about(source), threadpool_limits(1, "blas"):
        return fit_breast(scan, options) if isinstance(scan, np.ndarray) else fit_scan(scan, options)


def _earlier_cases(folder: Path, sides: tuple[str, ...]) -> dict[str, Case]:
    """Each planned side's case in an earlier case folder (`ingest.follow_up.earlier_cases`)."""
    from breastplan.ingest.follow_up import earlier_cases

    cases = earlier_cases(folder)
    if set(sides) - set(cases):                          # only a one-side case lacks a side
        held = next(iter(cases))
        raise BadInputError(folder, f"holds a scan of the {held} breast only; plan --side {held} against it")
    return {side: cases[side] for side in sides}


def earlier_volumes(folder: Path) -> BreastVolumes:
    """An earlier visit's breasts measured on her skin then, on its own chest wall."""
    from breastplan.ingest.follow_up import earlier_cases

    with about(folder):
        return measure_scans({side: case.load_scan() for side, case in earlier_cases(folder).items()}, folder)
