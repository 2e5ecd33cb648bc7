"""The built-in filters: thin wrappers over the stages (ingest, fit, plan) on a `Mesh`.

**Frames and units.** A filter reads its input in the input's own frame and units — `units` says
which (auto: from the extent; mm; m) and `up` which input axis points to the patient's head — and
gives its result in that same frame, in millimetres: the input's coordinates times 1000 for an input
in metres, unchanged for one in mm.

**Memory.** The surfaces these filters return (the isolated points, the fitted surface, a deformed
surface) are remembered, in memory, by a content hash of their vertices (the MEMORY most recent
ones), with the isolation, fit and changes behind them; a later filter given one of them reuses
those (its `units`, `up` and fit parameters then play no part). Any other geometry is taken as a
scan of the patient: its breast is isolated (and fitted) first. A remembered surface keeps its side:
`side` must be that side or `auto`.

**Changes.** A deformed surface is the fitted breast with its changes solved by degree on the
fitted model (`plan.changes.solve_change`) and applied to the whole model (`plan.surface`), in the
anatomical frame `plan.result.SidePlan` gives (a left breast is planned in its mirror image). Applying
another change to a deformed surface adds it (a change of the same kind replaces the one before: a
degree is always measured on the fitted breast), as `plan` combines its changes.
"""
from __future__ import annotations

import hashlib
import json
import threading
import warnings
from collections import OrderedDict
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Literal

import numpy as np

from breastplan import BadInputError, transform_points
from breastplan.deform.names import KIND_PARAMS, METHODS
from breastplan.options import PLAN_DEGREES, SIDES, UNITS, UP_AXES, FitOptions, IngestOptions, OptionError

from .mesh import Mesh
from .registry import ParameterError, filter

if TYPE_CHECKING:
    from breastplan.case import Scan
    from breastplan.plan.changes import Change
    from breastplan.plan.result import SidePlan

SideOrAuto = Literal[("auto", *SIDES)]
Units = Literal[UNITS]
Up = Literal[UP_AXES]
Method = Literal[METHODS]

MEMORY = 16
"""Surfaces (and scans) remembered; the least recently used is forgotten first."""


class ShortOfDegree(UserWarning):
    """A change's surface does not round to the degree asked: exact stops at the end of its condition's line
    for this breast, learnt has the model's prediction (the measures' `changes` give the degree reached)."""


MEASURES = ("volume_cc", "upper_pole_cc", "lower_pole_cc", "pole_ratio", "width_mm", "projection_mm")
"""The measures of `plan.measures.breast_measures` that need no torso."""


# --- the built-in filters -----------------------------------------------------------------------

def _isolation_options(values: dict) -> IngestOptions:
    side = SIDES[0] if values["side"] == "auto" else values["side"]
    return _option(IngestOptions, side=side, voxel_mm=values["voxel_mm"], units=values["units"], up=values["up"])


def _fit_options(values: dict) -> FitOptions:
    return _option(FitOptions, lattice=values["lattice"], max_iterations=values["max_iterations"])


def _check_degree(values: dict) -> None:
    degree = values["degree"]
    if not PLAN_DEGREES[0] <= degree <= PLAN_DEGREES[1]:
        raise ParameterError("degree", f"degree={degree:g} lies outside {PLAN_DEGREES[0]:g}..{PLAN_DEGREES[1]:g}, "
                                       f"the degrees of deformation")


@filter("compute_breast_isolation", check=_isolation_options)
def compute_breast_isolation(mesh: Mesh, *, side: SideOrAuto = "auto", units: Units = "auto", up: Up = "+y",
                             voxel_mm: float = 2.0) -> Mesh:
    """Isolate one breast of a scan: its points (no faces), input frame, mm.

    `mesh`: a scan of the patient's upper body (points, or a triangle mesh whose surface is sampled);
    `side`: the patient's breast (auto: a remembered surface's side, else left); `units`, `up`: the
    input's units and superior axis; `voxel_mm`: the spacing of the points kept (as `ingest --voxel`)."""
    record = _isolated(mesh, side, units, up, voxel_mm)
    return _remember(Mesh(transform_points(np.linalg.inv(record.scan.camera_to_breast), record.scan.points)),
                     record)


@filter("compute_breast_fit", check=_fit_options)
def compute_breast_fit(mesh: Mesh, *, side: SideOrAuto = "auto", units: Units = "auto", up: Up = "+y",
                       lattice: int = 5, max_iterations: int = 1000) -> Mesh:
    """Fit the breast model to one breast: the closed fitted surface, input frame, mm.

    `mesh`: a scan (isolated first) or a remembered isolated breast; `lattice`, `max_iterations`: the
    FFD lattice's control points per axis and iteration budget (as `fit`). Given a remembered fitted
    or deformed surface, the fitted surface of that breast."""
    record = _fitted(mesh, side, units, up, _option(FitOptions, lattice=lattice, max_iterations=max_iterations))
    record = replace(record, changes=(), change=None)
    plan = record.fitted
    return _remember(Mesh(plan.surface_input, plan.fit.faces), record)


@filter("apply_breast_ptosis", check=_check_degree)
def apply_breast_ptosis(mesh: Mesh, *, degree: float = 3.0, method: Method = "exact", side: SideOrAuto = "auto",
                        units: Units = "auto", up: Up = "+y") -> Mesh:
    """Give the fitted breast a ptosis (sagging) of a degree 1..8: its surface, input frame, mm.

    `mesh`: a remembered fitted or deformed surface, else a scan (isolated and fitted first);
    `method`: exact (the inverse solver) or learnt (the shipped regressions); `side`, `units`, `up`:
    as compute_breast_isolation's."""
    return _apply("ptosis", mesh, degree, method, side, units, up)


@filter("apply_breast_turn", check=_check_degree)
def apply_breast_turn(mesh: Mesh, *, degree: float = 3.0, method: Method = "exact", side: SideOrAuto = "auto",
                      units: Units = "auto", up: Up = "+y") -> Mesh:
    """Turn the fitted breast outwards by a degree 1..8: its surface, input frame, mm.

    Parameters as apply_breast_ptosis's."""
    return _apply("turn", mesh, degree, method, side, units, up)


@filter("apply_breast_top_shape", check=_check_degree)
def apply_breast_top_shape(mesh: Mesh, *, degree: float = 3.0, method: Method = "exact", side: SideOrAuto = "auto",
                           units: Units = "auto", up: Up = "+y") -> Mesh:
    """Fill the fitted breast's upper pole (top-shape) by a degree 1..8: its surface, input frame, mm.

    Parameters as apply_breast_ptosis's."""
    return _apply("top-shape", mesh, degree, method, side, units, up)


@filter("get_breast_measures")
def get_breast_measures(mesh: Mesh, *, side: SideOrAuto = "auto", units: Units = "auto", up: Up = "+y") -> dict:
    """Measure the fitted (or deformed) breast: volume, poles, width, projection, nipple, fit quality.

    Lengths in mm, volumes in cc, `nipple_mm` in the input frame (mm). Up and left–right are the
    breast frame's axes (the chest wall's tangent plane at the breast, up from the scan's `up`), so
    no torso is needed: `width_mm` is the base outline's extent left to right, `projection_mm` the
    nipple's height above the base plane, the poles the volume above and below the nipple's level
    (`plan.measures.breast_measures`). `fit_volume_cc`, `rms_mm`, `normalised_residual`,
    `stopping_rule_met`, `converged` describe the fit; `changes` the changes applied."""
    from breastplan.plan.measures import BodyLandmarks, breast_measures
    from breastplan.plan.surface import PlannedChange

    record = _fitted(mesh, side, units, up, FitOptions())
    plan, fit = record.fitted, record.fitted.fit
    nipple, vertices = plan.scan.nipple_camera_mm, plan.surface_input
    if record.change is not None:
        planned = PlannedChange.of(plan, record.change)
        nipple, vertices = planned.model(nipple[None])[0], planned.model(vertices)
    axes = plan.frames.breast_to_input[:3, :3]                      # breast frame → input frame: x the patient's left, y up
    landmarks = BodyLandmarks(nipple, nipple, axes[:, 0], axes[:, 1])
    measures = breast_measures(landmarks, nipple, vertices, fit.faces)
    details = [d for change in ([record.change] if record.change is not None else []) for d in change.details]
    return {"side": plan.side, **{k: measures[k] for k in MEASURES}, "nipple_mm": np.asarray(nipple, float),
            "fit_volume_cc": float(fit.volume_cc), "rms_mm": float(fit.residuals_mm["rms"]),
            "normalised_residual": float(fit.normalised_residual), "stopping_rule_met": bool(fit.stopping_rule_met),
            "converged": bool(fit.converged), "points": int(fit.points),
            "changes": [{"kind": d["kind"], "degree": float(d["degree"]), "degree_reached": float(d["degree_reached"]),
                         "reached": bool(d["reached"]), "method": method}
                        for d, (_, _, method) in zip(details, record.changes)]}


# --- what the filters share -------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class _Record:
    """A breast behind a surface: its scan (isolated), its fit (if fitted) and its changes (if any)."""

    key: str                                            # the scan's: its content and isolation options
    scan: Scan
    fitted: SidePlan | None = None                      # the scan and fit, in memory (no case folder)
    changes: tuple[tuple[str, float, str], ...] = ()    # (kind, degree, method), in the model's order
    change: Change | None = None                        # the changes solved together


class _Memory:
    """A bounded map, least recently used out, shared by the threads of a process."""

    def __init__(self, size: int):
        self.size, self.items, self.lock = size, OrderedDict(), threading.Lock()

    def get(self, key: str):
        with self.lock:
            if key in self.items:
                self.items.move_to_end(key)
                return self.items[key]
        return None

    def put(self, key: str, value) -> None:
        with self.lock:
            self.items[key] = value
            self.items.move_to_end(key)
            while len(self.items) > self.size:
                self.items.popitem(last=False)

    def clear(self) -> None:
        with self.lock:
            self.items.clear()


_MEMORY = _Memory(MEMORY)


def forget() -> None:
    """Forget every remembered surface and scan."""
    _MEMORY.clear()


def surface_key(vertices) -> str:
    """The content hash a surface is remembered by: its vertices as float32 (so that a copy through
    float32, e.g. a PLY of floats, is still recognised)."""
    v = np.ascontiguousarray(vertices, dtype=np.float32)
    return "surface:" + hashlib.sha256(repr(v.shape).encode() + v.tobytes()).hexdigest()


def _scan_key(mesh: Mesh, options: dict) -> str:
    digest = hashlib.sha256(np.ascontiguousarray(mesh.vertices).tobytes())
    if mesh.faces is not None:
        digest.update(np.ascontiguousarray(mesh.faces).tobytes())
    return f"scan:{digest.hexdigest()}:{json.dumps(options, sort_keys=True)}"


def _remember(mesh: Mesh, record: _Record) -> Mesh:
    _MEMORY.put(surface_key(mesh.vertices), record)
    return mesh


def _remembered(mesh: Mesh, side: str) -> _Record | None:
    """The record of a remembered surface (BadInputError if it is of the other side than `side`), or None."""
    record = _MEMORY.get(surface_key(mesh.vertices))
    if record is not None and side not in ("auto", record.scan.side):
        raise BadInputError(None, f"is a surface of the {record.scan.side} breast, not the {side} one; "
                                  f"give side={record.scan.side}")
    return record


def _option(kind, **values):
    """A stage's option object; ParameterError naming the parameter for a value it refuses."""
    try:
        return kind(**values)
    except OptionError as exc:
        raise ParameterError(exc.option, f"{exc.option}: {exc}") from None


def _isolated(mesh: Mesh, side: str, units: str, up: str, voxel_mm: float = 2.0) -> _Record:
    """The breast behind a remembered surface, or `side`'s breast isolated from `mesh` as a scan."""
    record = _remembered(mesh, side)
    if record is not None:
        return record
    options = _option(IngestOptions, side=SIDES[0] if side == "auto" else side, voxel_mm=voxel_mm, units=units, up=up)
    key = _scan_key(mesh, options.as_dict())
    record = _MEMORY.get(key)
    if record is None:
        from threadpoolctl import threadpool_limits

        from breastplan.case import Provenance, Source
        from breastplan.ingest.files import scan_cloud
        from breastplan.ingest.pipeline import ingest_cloud
        from breastplan.ingest.scan import scan_record

        cloud = scan_cloud(mesh.vertices, mesh.faces, None, units, name="the input")
        with threadpool_limits(1, "blas"):               # small dense solves: threads only add overhead
            found = ingest_cloud(cloud, options)
        record = _Record(key, scan_record(found, Source("file", cloud.description), options, Provenance()))
        _MEMORY.put(key, record)
    return record


def _fitted(mesh: Mesh, side: str, units: str, up: str, options: FitOptions) -> _Record:
    """The fitted breast behind a remembered surface, or the breast of `mesh` isolated and fitted."""
    record = _isolated(mesh, side, units, up)
    if record.fitted is not None:
        return record
    key = f"{record.key}:fit:{json.dumps(options.as_dict(), sort_keys=True)}"
    fitted = _MEMORY.get(key)
    if fitted is None:
        from threadpoolctl import threadpool_limits

        from breastplan.fitting.breast_fit import fit_scan
        from breastplan.plan.result import SidePlan

        with threadpool_limits(1, "blas"):
            fit = fit_scan(record.scan, options).artefact()
        fitted = replace(record, fitted=SidePlan(record.scan.side, None, record.scan, fit, ()))
        _MEMORY.put(key, fitted)
    return fitted


def _apply(kind: str, mesh: Mesh, degree: float, method: str, side: str, units: str, up: str) -> Mesh:
    """The fitted breast behind `mesh` with `kind` at `degree` (and the changes it carries), input frame."""
    _check_degree({"degree": degree})
    from threadpoolctl import threadpool_limits

    from breastplan.plan.changes import Method as Resolved, combine, short_of, solve_change
    from breastplan.plan.surface import PlannedChange

    record = _fitted(mesh, side, units, up, FitOptions())
    order = list(KIND_PARAMS)
    changes = tuple(sorted([c for c in record.changes if c[0] != kind] + [(kind, float(degree), method)],
                           key=lambda c: order.index(c[0])))
    plan = record.fitted
    with threadpool_limits(1, "blas"):
        singles = [solve_change(plan.local_surface, k, d, plan.primitive, Resolved.resolve(m)) for k, d, m in changes]
    asked = next(single for single, (k, _, _) in zip(singles, changes) if k == kind)
    short = short_of(asked.details[0], method)
    if short is not None:
        warnings.warn(f"{kind} reaches {short}", ShortOfDegree, stacklevel=4)   # the caller of the filter
    change = singles[0] if len(singles) == 1 else combine(singles)
    vertices = PlannedChange.of(plan, change).model(plan.surface_input)
    return _remember(Mesh(vertices, plan.fit.faces), replace(record, changes=changes, change=change))
