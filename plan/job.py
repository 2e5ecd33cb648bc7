"""The main job: a patient's scan → ingest → fit → the planned changes → measures → report.

A plan's case folder holds one case per side (`left/`, `right/`: scan, fit and `plan/<change>.*`)
and, at its top, `report.html`, `summary.png` and `plan.json` (docs/artefacts.md). Its input is
a recording, a scan file, a case folder (a plan's, or one side's from `ingest`), or nothing (the
bundled sample recording). Stages whose inputs and options hash as before are reused. A new case
folder is built beside its target and renamed into place when whole, so a failed plan leaves none;
an existing one is updated one artefact set at a time, each all or nothing.
"""
from __future__ import annotations

import contextlib
import fcntl
import glob
import os
import secrets
import shutil
from dataclasses import dataclass, field, replace
from functools import cached_property
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterator

import numpy as np

from breastplan import BadInputError, Primitive, transform_points
from breastplan.atomic import short_name
from breastplan.case import Case, Fit, Provenance, Scan, sha256
from breastplan.clock import Clock
from breastplan.errors import about
from breastplan.json_text import from_json
from breastplan.options import FitOptions, IngestOptions, PlanOptions

from .breast_volume import BreastVolumes, measure_breasts
from .changes import Change, combine, solve_change
from .surface import PlannedChange

if TYPE_CHECKING:
    from breastplan.ingest.follow_up import Registration

PLAN_SCHEMA = "breastplan.plan/1"


def sample_recording() -> Path:
    """The bundled sample recording (a synthetic patient, 10 depth frames), inside the package."""
    return Path(str(resources.files("breastplan.plan") / "data" / "sample.mcap"))


@dataclass(frozen=True, eq=False)
class FollowUp:
    """A side measured down to an earlier case's chest wall: that case, the registration that carried
    its wall over, and the earlier breast's fit down to its own wall (its surface carried into this
    scan's input frame by the registration, mm)."""

    case: Path
    registration: Registration
    earlier_volume_cc: float
    earlier_surface_input: np.ndarray       # (V, 3)
    earlier_faces: np.ndarray               # (F, 3)

    def record(self, volume_cc: float) -> dict:
        """plan.json's `wall_from` of a side whose breast now measures `volume_cc` on the earlier wall."""
        change = volume_cc - self.earlier_volume_cc
        return {"case": str(self.case), **self.registration.as_dict(),
                "earlier_volume_cc": round(self.earlier_volume_cc, 2), "volume_change_cc": round(change, 2),
                "volume_change_pct": round(100.0 * change / self.earlier_volume_cc, 2)}


@dataclass(frozen=True, eq=False)
class SidePlan:
    """One side's case, scan, fit and planned changes (each as solved on the fitted surface)."""

    side: str
    case: Case
    scan: Scan
    fit: Fit
    changes: tuple[Change, ...]              # one per requested change, then the combination
    reused: tuple[str, ...] = ()             # stages taken from the case folder as they were
    follow_up: FollowUp | None = None        # with `wall_from`: the earlier case it is measured against

    @property
    def anatomical(self) -> np.ndarray:
        """(4, 4) primitive frame → the side's anatomical frame: the model's breast is a right one
        (its −x lateral, docs/model.md §1, §3), so a left breast is mirrored in x and both sides
        plan the same change, medial and lateral alike (a turn turns both breasts outwards)."""
        return np.diag([-1.0, 1.0, 1.0, 1.0]) if self.side == "left" else np.eye(4)

    @property
    def primitive(self) -> Primitive:
        """The fitted primitive in the anatomical frame (a left breast's a1, a2 swapped)."""
        p = self.fit.primitive
        return replace(p, a1=p.a2, a2=p.a1) if self.side == "left" else p

    @property
    def to_primitive(self) -> np.ndarray:
        """(4, 4) input frame → anatomical primitive frame, mm."""
        return self.anatomical @ np.linalg.inv(self.fit.pose) @ self.scan.camera_to_breast

    @property
    def to_input(self) -> np.ndarray:
        """(4, 4) breast frame → input frame, mm."""
        return np.linalg.inv(self.scan.camera_to_breast)

    def planned(self, change: Change) -> PlannedChange:
        return PlannedChange(change.deformation, self.primitive, self.to_primitive, fields=change.fields)

    @cached_property
    def surface_input(self) -> np.ndarray:
        """The fitted surface's vertices (fit.ply) in the input frame, mm."""
        return transform_points(self.to_input, self.fit.vertices)

    def local_surface(self) -> np.ndarray:
        """The fitted surface in the anatomical primitive frame, mm: what degrees are measured on."""
        return transform_points(self.anatomical @ np.linalg.inv(self.fit.pose), self.fit.vertices)


@dataclass(frozen=True, eq=False)
class Plan:
    """A finished plan: its folder, input, options and sides."""

    folder: Path
    input: Path
    options: PlanOptions
    sides: dict[str, SidePlan]
    volumes: BreastVolumes
    timings_ms: dict = field(default_factory=dict)
    earlier_volumes: BreastVolumes | None = None     # a follow-up: the earlier visit's, measured on its own skin


Progress = Callable[[str], None]


def run_plan(input: Path | None, out: Path, options: PlanOptions, progress: Progress = lambda _: None) -> Plan:
    """Plan `options` on `input` (None: the bundled sample) into the case folder `out`."""
    from .record import write_plan

    source = sample_recording() if input is None else Path(input)
    clock = Clock()
    with _building(out) as folder:
        sides = _sides(source, folder, options, clock, progress)
        with clock("volumes on her skin"):
            progress("volumes")
            volumes = measure_sides(sides)
            earlier = None if options.wall_from is None else _earlier_volumes(Path(options.wall_from))
        with clock("report"):
            progress("report")
            write_plan(Plan(out, source, options, sides, volumes, clock.ms, earlier), folder)
    moved = {s: replace(sp, case=Case(out / sp.case.folder.relative_to(folder))) for s, sp in sides.items()}
    return Plan(out, source, options, moved, volumes, clock.ms, earlier)


def measure_sides(sides: dict[str, SidePlan]) -> BreastVolumes:
    """Both breasts measured on her skin (`plan.breast_volume`), from the torso the sides share."""
    return _measured({s: sp.scan for s, sp in sides.items()})


def _measured(scans: dict[str, Scan]) -> BreastVolumes:
    first = next(iter(scans.values()))
    return measure_breasts(first.torso_camera, {s: scan.nipple_camera_mm for s, scan in scans.items()},
                           first.view_from_camera, first.plumb_camera)


def _earlier_volumes(folder: Path) -> BreastVolumes:
    """An earlier visit's breasts measured on her skin then, each visit on its own chest wall."""
    from breastplan.ingest.follow_up import earlier_cases

    with about(folder):
        return _measured({side: case.load_scan() for side, case in earlier_cases(folder).items()})


@contextlib.contextmanager
def _building(out: Path) -> Iterator[Path]:
    """The folder to build the case in: `out` itself if it exists, else a hidden sibling renamed to
    `out` once the plan is whole (removed if it fails, and by a later plan if this one is killed)."""
    if out.exists():
        yield out
        return
    stem = f".{short_name(out.name)}.plan-"
    work = out.parent / f"{stem}{secrets.token_hex(4)}"
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        with _locked_folder(work, stem):
            yield work
            os.rename(work, out)
    except OSError as exc:                   # name the folder the user asked for, not the one being built
        where = str(exc.filename or out)
        raise OSError(exc.errno, exc.strerror, str(out) + where[len(str(work)):] if where.startswith(str(work))
                      else where) from None
    finally:
        shutil.rmtree(work, ignore_errors=True)


@contextlib.contextmanager
def _locked_folder(work: Path, stem: str) -> Iterator[None]:
    """Create `work` and hold a lock on it (the system releases it when the process dies, even by
    kill -9), first removing the folders `stem`XXXXXXXX beside it whose lock no living plan holds:
    those a killed plan left. Both under a lock on their parent, so that no folder is removed between
    its creation and its lock."""
    parent = _lock(work.parent)
    try:
        for folder in work.parent.glob(glob.escape(stem) + "[0-9a-f]" * 8):
            abandoned = _lock(folder, wait=False) if folder.is_dir() else None
            if abandoned is not None:
                shutil.rmtree(folder, ignore_errors=True)
                os.close(abandoned)
        work.mkdir()
        held = _lock(work)
    finally:
        os.close(parent)
    try:
        yield
    finally:
        os.close(held)


def _lock(folder: Path, wait: bool = True) -> int | None:
    """A descriptor of `folder` holding its exclusive lock; None when another process holds it and not `wait`."""
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
    except BlockingIOError:
        os.close(fd)
        return None
    return fd


def _sides(source: Path, folder: Path, options: PlanOptions, clock: Clock, progress: Progress) -> dict[str, SidePlan]:
    """Scan and fit each side (reusing what the case folder holds; down to the earlier case's wall
    with `wall_from`), then solve its changes."""
    earlier = {} if options.wall_from is None else _earlier_cases(Path(options.wall_from), options.sides)
    if source.is_dir():
        cases = _cases_of(source, folder, options)
        scans, reused = {}, {}
        for side, case in cases.items():
            scans[side], reused[side] = case.load_scan(), ["ingest"]
    else:
        cases = {side: Case(folder / side) for side in options.sides}
        scans, reused = _ingest(source, cases, options, clock, progress)
    sides = {}
    for side, case in cases.items():
        with clock(f"fit {side}"):
            progress(f"fit {side}")
            fit, fit_reused, follow_up = _fit(case, scans[side], earlier.get(side))
        unsolved = SidePlan(side, case, scans[side], fit, (), tuple(reused[side] + fit_reused), follow_up)
        with clock(f"changes {side}"):
            progress(f"changes {side}")
            sides[side] = replace(unsolved, changes=solve_changes(unsolved, options))
    return sides


def solve_changes(side: SidePlan, options: PlanOptions) -> tuple[Change, ...]:
    """Each requested change of one side, then (for more than one) their combination."""
    local = side.local_surface()
    singles = [solve_change(local, kind, degree, side.primitive, method_for(options.method, kind))
               for kind, degree in options.changes]
    return tuple(singles + ([combine(singles)] if len(singles) > 1 else []))


def method_for(method: str, kind: str) -> str:
    """A model file plans its own kind; the other kinds are solved exactly."""
    if method in ("exact", "learnt"):
        return method
    from breastplan.model_file import load_model

    return method if kind in load_model(Path(method)).kinds else "exact"


def _cases_of(source: Path, folder: Path, options: PlanOptions) -> dict[str, Case]:
    """The side cases a case folder holds for the requested sides, copied into `folder` unless the
    plan is made in place. A one-side case from `ingest` plans its own side."""
    _check_schema(source)
    held = Case.of_sides(source)
    found = {s: case.folder for s, case in held.items() if s in options.sides}
    missing = [] if found and Case.holds(source) else [s for s in options.sides if s not in held]
    if missing:
        raise BadInputError(source, f"holds no scan of the {' and '.join(missing)} breast; plan it from the "
                                    "recording or scan file")
    in_place = folder.resolve() == source.resolve()
    cases = {}
    for side, path in found.items():
        target = path if in_place else folder / side
        if not in_place:
            shutil.copytree(path, target, dirs_exist_ok=True)
        cases[side] = Case(target)
    return cases


def _check_schema(folder: Path) -> None:
    """BadInputError naming a plan.json of another schema (an older or newer breastplan's case)."""
    doc = folder / Case.PLAN_JSON
    if not doc.is_file():
        return
    try:
        schema = from_json(doc.read_text()).get("schema", "")
    except (OSError, ValueError, AttributeError):
        raise BadInputError(doc, "is not a plan record (not JSON)") from None
    if schema != PLAN_SCHEMA:
        name, _, version = str(schema).partition("/")
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
        if case.is_fresh(Case.SCAN_NPZ, Provenance.of({source.name: source}, wanted[side].as_dict())):
            scans[side], reused[side] = case.load_scan(), ["ingest"]
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


def _fit(case: Case, scan: Scan, earlier: Case | None) -> tuple[Fit, list[str], FollowUp | None]:
    """The side's fit (reused when the case holds one of this scan, and of the earlier scan it is
    measured against, with the default options), the stages reused, and the follow-up."""
    from breastplan.ingest.follow_up import carried_wall

    scan_ply = case.path(Case.SCAN_PLY)
    inputs, options, follow_up = {scan_ply.name: scan_ply}, FitOptions().as_dict(), None
    if earlier is not None:
        with about(earlier.folder):
            earlier_scan = earlier.load_scan()
            wall, registration = carried_wall(earlier_scan, scan)
        scan = replace(scan, chest_wall=wall)
        more_inputs, more_options = registration.provenance(earlier.folder)
        inputs, options = {**inputs, **more_inputs}, {**options, **more_options}
        then = _own_wall_fit(earlier, earlier_scan)
        later_from_earlier = np.linalg.inv(earlier_scan.camera_to_breast @ registration.earlier_from_later)
        follow_up = FollowUp(earlier.folder, registration, then.volume_cc,
                             transform_points(later_from_earlier, then.vertices), then.faces)
    wanted = Provenance.of(inputs, options)
    if case.is_fresh(Case.FIT_NPZ, wanted):
        return case.load_fit(), ["fit"], follow_up
    fit = _fitted(scan, scan_ply).artefact(wanted)
    case.save_fit(fit)
    return fit, [], follow_up


def _own_wall_fit(case: Case, scan: Scan) -> Fit:
    """An earlier breast's fit down to its own chest wall: its case's fit.npz when that was made with
    the default options, else fitted now (and not written: the earlier case is only read)."""
    scan_ply = case.path(Case.SCAN_PLY)
    wanted = Provenance.of({scan_ply.name: scan_ply}, FitOptions().as_dict())
    if case.is_fresh(Case.FIT_NPZ, wanted):
        return case.load_fit()
    return _fitted(scan, scan_ply).artefact(wanted)


def _fitted(scan: Scan, scan_ply: Path):
    """`fit_scan` with the default options, one BLAS thread, bad input naming `scan_ply`."""
    from threadpoolctl import threadpool_limits

    from breastplan.fitting.breast_fit import fit_scan

    with about(scan_ply), threadpool_limits(1, "blas"):
        return fit_scan(scan, FitOptions())


def _earlier_cases(folder: Path, sides: tuple[str, ...]) -> dict[str, Case]:
    """Each planned side's case in an earlier case folder (`ingest.follow_up.earlier_cases`)."""
    from breastplan.ingest.follow_up import earlier_cases

    cases = earlier_cases(folder)
    if set(sides) - set(cases):                          # only a one-side case lacks a side
        held = next(iter(cases))
        raise BadInputError(folder, f"holds a scan of the {held} breast only; plan --side {held} against it")
    return {side: cases[side] for side in sides}


def input_record(plan: Plan) -> dict:
    """The plan's input as plan.json records it: path, kind and content hash."""
    path = plan.input
    if path.is_dir():
        return {"path": str(path), "kind": "case folder"}
    return {"path": str(path), "kind": "recording" if path.suffix.lower() == ".mcap" else "scan file",
            "sha256": sha256(path)}
