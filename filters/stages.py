"""The built-in filters: thin wrappers over the stages (ingest, fit, plan) on a `Mesh`.

**Frames and units.** A filter reads its input in the input's own frame and units — `units` says
which (auto: from the extent; mm; m) and `up` which input axis points to the patient's head — and
gives its result in that same frame, in millimetres: the input's coordinates times 1000 for an input
in metres, unchanged for one in mm.

**Memory.** The surfaces these filters return (the isolated points, the fitted surface, a deformed
surface) are remembered, in memory, by a content hash of their vertices (the MEMORY most recent
ones), each with its recipe: the scan of the patient its chain began with, the side and voxel size
isolated, the fit's options and the changes applied. A later filter given one of them starts from
that scan with the recipe, its own parameters replacing the recipe's: `units` and `up` (they
describe that scan, in whose frame every surface of the chain lies), `voxel_mm` (isolation),
`lattice` and `max_iterations` (fit), and an `apply_*` filter's change (replacing one of its kind);
so its result is what the same chain gives from the scan with those parameters (as computed afresh
after `forget()`). Any other geometry is taken as a scan of the patient: its breast is isolated (and
fitted) first. A remembered surface keeps its side: `side` must be that side or `auto`. The
isolations, fits and changes computed are kept too (the RESULTS most recent), each keyed on every
option it depends on (the scan's content, side, voxel size, units, up; the fit's options; the
change), so that nothing is computed twice and nothing is reused for other parameters.

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
from breastplan.options import PLAN_DEGREES, SIDES, UNITS, UP_CHOICES, FitOptions, IngestOptions, OptionError

from .mesh import Mesh
from .registry import ParameterError, filter

if TYPE_CHECKING:
    from breastplan.case import Scan
    from breastplan.plan.changes import Change
    from breastplan.plan.result import SidePlan

SideOrAuto = Literal[("auto", *SIDES)]
Units = Literal[UNITS]
Up = Literal[UP_CHOICES]
Method = Literal[METHODS]

MEMORY = 16
"""Surfaces remembered (with their recipes); the least recently used is forgotten first."""
RESULTS = 32
"""Isolations, fits and changes kept; the least recently used is forgotten first."""


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
def compute_breast_isolation(mesh: Mesh, *, side: SideOrAuto = "auto", units: Units = "auto", up: Up = "auto",
                             voxel_mm: float = 2.0) -> Mesh:
    """Isolate one breast of a scan: its points (no faces), input frame, mm.

    `mesh`: a scan of the patient's upper body (points, or a triangle mesh whose surface is sampled),
    or a remembered surface (its chain's scan isolated with these parameters); `side`: the patient's
    breast (auto: a remembered surface's side, else left); `units`, `up`: the input's units and
    superior axis (a remembered surface's: its chain's scan's); `voxel_mm`: the spacing of the points
    kept (as `ingest --voxel`)."""
    recipe = replace(_recipe(mesh, side, voxel_mm), fit=None, changes=())
    _, scan = _isolated(recipe, units, up)
    return _remember(Mesh(transform_points(np.linalg.inv(scan.input_to_breast), scan.points)), recipe)


@filter("compute_breast_fit", check=_fit_options)
def compute_breast_fit(mesh: Mesh, *, side: SideOrAuto = "auto", units: Units = "auto", up: Up = "auto",
                       lattice: int = 5, max_iterations: int = 1000) -> Mesh:
    """Fit the breast model to one breast: the closed fitted surface, input frame, mm.

    `mesh`: a scan (isolated first) or a remembered isolated breast; `lattice`, `max_iterations`: the
    FFD lattice's control points per axis and iteration budget (as `fit`). Given a remembered fitted
    or deformed surface, that breast fitted with these parameters (its changes left out)."""
    fit = _option(FitOptions, lattice=lattice, max_iterations=max_iterations)
    recipe = replace(_recipe(mesh, side), fit=fit, changes=())
    _, plan = _fitted(recipe, units, up)
    return _remember(Mesh(plan.surface_input, plan.fit.faces), recipe)


@filter("apply_breast_ptosis", check=_check_degree)
def apply_breast_ptosis(mesh: Mesh, *, degree: float = 3.0, method: Method = "exact", side: SideOrAuto = "auto",
                        units: Units = "auto", up: Up = "auto") -> Mesh:
    """Give the fitted breast a ptosis (sagging) of a degree 1..8: its surface, input frame, mm.

    `mesh`: a remembered fitted or deformed surface, else a scan (isolated and fitted first);
    `method`: exact (the inverse solver) or learnt (the shipped regressions); `side`, `units`, `up`:
    as compute_breast_isolation's."""
    return _apply("ptosis", mesh, degree, method, side, units, up)


@filter("apply_breast_turn", check=_check_degree)
def apply_breast_turn(mesh: Mesh, *, degree: float = 3.0, method: Method = "exact", side: SideOrAuto = "auto",
                      units: Units = "auto", up: Up = "auto") -> Mesh:
    """Turn the fitted breast outwards by a degree 1..8: its surface, input frame, mm.

    Parameters as apply_breast_ptosis's."""
    return _apply("turn", mesh, degree, method, side, units, up)


@filter("apply_breast_top_shape", check=_check_degree)
def apply_breast_top_shape(mesh: Mesh, *, degree: float = 3.0, method: Method = "exact", side: SideOrAuto = "auto",
                           units: Units = "auto", up: Up = "auto") -> Mesh:
    """Fill the fitted breast's upper pole (top-shape) by a degree 1..8: its surface, input frame, mm.

    Parameters as apply_breast_ptosis's."""
    return _apply("top-shape", mesh, degree, method, side, units, up)


@filter("get_breast_measures")
def get_breast_measures(mesh: Mesh, *, side: SideOrAuto = "auto", units: Units = "auto", up: Up = "auto") -> dict:
    """Measure the fitted (or deformed) breast: volume, poles, width, projection, nipple, fit quality.

    Lengths in mm, volumes in cc, `nipple_mm` in the input frame (mm). Up and left–right are the
    breast frame's axes (the chest wall's tangent plane at the breast, up from the scan's `up`), so
    no torso is needed: `width_mm` is the base outline's extent left to right, `projection_mm` the
    nipple's height above the base plane, the poles the volume above and below the nipple's level
    (`plan.measures.breast_measures`). `fit_volume_cc`, `rms_mm`, `normalised_residual`,
    `stopping_rule_met`, `converged` describe the fit; `changes` the changes applied."""
    from breastplan.plan.measures import BodyLandmarks, breast_measures

    recipe = _recipe(mesh, side)
    recipe = replace(recipe, fit=recipe.fit or FitOptions())
    plan, _, change = _changed(recipe, units, up)
    fit = plan.fit
    nipple = _moved(plan, change, np.asarray(plan.scan.nipple_camera_mm, float)[None])[0]
    vertices = _moved(plan, change, plan.surface_input)
    axes = plan.frames.breast_to_input[:3, :3]        # breast frame → input frame: x the patient's left, y up
    landmarks = BodyLandmarks(nipple, nipple, axes[:, 0], axes[:, 1])
    measures = breast_measures(landmarks, nipple, vertices, fit.faces)
    details = [] if change is None else list(change.details)
    return {"side": plan.side, **{k: measures[k] for k in MEASURES}, "nipple_mm": np.asarray(nipple, float),
            "fit_volume_cc": float(fit.volume_cc), "rms_mm": float(fit.residuals_mm["rms"]),
            "normalised_residual": float(fit.normalised_residual), "stopping_rule_met": bool(fit.stopping_rule_met),
            "converged": bool(fit.converged), "points": int(fit.points),
            "changes": [{"kind": d["kind"], "degree": float(d["degree"]), "degree_reached": float(d["degree_reached"]),
                         "reached": bool(d["reached"]), "method": method}
                        for d, (_, _, method) in zip(details, recipe.changes)]}


# --- what the filters share -------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class _Recipe:
    """How a surface was made: the scan of the patient its chain began with (`origin`; `origin_key`, a
    hash of its content), the breast isolated from it and the voxel size, the fit's options (None:
    isolated only) and the changes applied. `units` and `up` are no part of it: every filter is given
    its own (they describe `origin`, in whose frame every surface of the chain lies)."""

    origin: Mesh
    origin_key: str
    side: str
    voxel_mm: float
    fit: FitOptions | None = None
    changes: tuple[tuple[str, float, str], ...] = ()    # (kind, degree, method), in the model's order


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


_SURFACES = _Memory(MEMORY)
"""surface_key → the _Recipe of a surface a filter gave."""
_RESULTS = _Memory(RESULTS)
"""The isolations, fits and changes computed, each keyed on every option it depends on."""


def forget() -> None:
    """Forget every remembered surface, isolation, fit and change."""
    _SURFACES.clear()
    _RESULTS.clear()


def surface_key(vertices) -> str:
    """The content hash a surface is remembered by: its vertices as float32 (so that a copy through
    float32, e.g. a PLY of floats, is still recognised)."""
    v = np.ascontiguousarray(vertices, dtype=np.float32)
    return "surface:" + hashlib.sha256(repr(v.shape).encode() + v.tobytes()).hexdigest()


def _content_key(mesh: Mesh) -> str:
    """A scan's content, exactly: its vertices (float64) and faces."""
    digest = hashlib.sha256(repr(mesh.vertices.shape).encode() + np.ascontiguousarray(mesh.vertices).tobytes())
    if mesh.faces is not None:
        digest.update(np.ascontiguousarray(mesh.faces).tobytes())
    return digest.hexdigest()


def _options_key(options) -> str:
    return json.dumps(options.as_dict(), sort_keys=True)


def _remember(mesh: Mesh, recipe: _Recipe) -> Mesh:
    _SURFACES.put(surface_key(mesh.vertices), recipe)
    return mesh


def _recipe(mesh: Mesh, side: str, voxel_mm: float | None = None) -> _Recipe:
    """The recipe of a filter's input: a remembered surface's (BadInputError if it is of the other side
    than `side`; `voxel_mm`, if given, replaces its own), else that of `mesh` taken as a scan of the
    patient (`side` auto: the left breast)."""
    recipe = _SURFACES.get(surface_key(mesh.vertices))
    if recipe is None:
        return _Recipe(mesh, _content_key(mesh), SIDES[0] if side == "auto" else side,
                       2.0 if voxel_mm is None else voxel_mm)
    if side not in ("auto", recipe.side):
        raise BadInputError(None, f"is a surface of the {recipe.side} breast, not the {side} one; "
                                  f"give side={recipe.side}")
    return recipe if voxel_mm is None else replace(recipe, voxel_mm=voxel_mm)


def _option(kind, **values):
    """A stage's option object; ParameterError naming the parameter for a value it refuses."""
    try:
        return kind(**values)
    except OptionError as exc:
        raise ParameterError(exc.option, f"{exc.option}: {exc}") from None


def _isolated(recipe: _Recipe, units: str, up: str) -> tuple[str, Scan]:
    """(key, scan) of the recipe's breast isolated from its origin read with `units` and `up`."""
    options = _option(IngestOptions, side=recipe.side, voxel_mm=recipe.voxel_mm, units=units, up=up)
    key = f"scan:{recipe.origin_key}:{_options_key(options)}"
    scan = _RESULTS.get(key)
    if scan is None:
        from threadpoolctl import threadpool_limits

        from breastplan.case import Provenance, Source
        from breastplan.ingest.files import scan_cloud
        from breastplan.ingest.pipeline import ingest_cloud
        from breastplan.ingest.scan import scan_record

        origin = recipe.origin
        cloud = scan_cloud(origin.vertices, origin.faces, None, units, name="the input")
        with threadpool_limits(1, "blas"):               # small dense solves: threads only add overhead
            found = ingest_cloud(cloud, options)
        scan = scan_record(found, Source("file", cloud.description), options, Provenance())
        _RESULTS.put(key, scan)
    return key, scan


def _fitted(recipe: _Recipe, units: str, up: str) -> tuple[str, SidePlan]:
    """(key, side plan without changes) of the recipe's breast isolated and fitted with its fit options."""
    scan_key, scan = _isolated(recipe, units, up)
    key = f"{scan_key}:fit:{_options_key(recipe.fit)}"
    plan = _RESULTS.get(key)
    if plan is None:
        from threadpoolctl import threadpool_limits

        from breastplan.fitting.breast_fit import fit_scan
        from breastplan.plan.result import SidePlan

        with threadpool_limits(1, "blas"):
            fit = fit_scan(scan, recipe.fit).artefact()
        plan = SidePlan(scan.side, None, scan, fit, ())
        _RESULTS.put(key, plan)
    return key, plan


def _changed(recipe: _Recipe, units: str, up: str) -> tuple[SidePlan, list[Change], Change | None]:
    """The recipe's fitted breast, each of its changes solved alone on it, and their combination (None
    without changes)."""
    from threadpoolctl import threadpool_limits

    from breastplan.plan.changes import Method, combine, solve_change

    fit_key, plan = _fitted(recipe, units, up)
    singles = []
    for kind, degree, method in recipe.changes:
        key = f"{fit_key}:change:{json.dumps([kind, degree, method])}"
        single = _RESULTS.get(key)
        if single is None:
            with threadpool_limits(1, "blas"):
                single = solve_change(plan.local_surface, kind, degree, plan.primitive, Method(method))
            _RESULTS.put(key, single)
        singles.append(single)
    change = None if not singles else singles[0] if len(singles) == 1 else combine(singles)
    return plan, singles, change


def _moved(plan: SidePlan, change: Change | None, points: np.ndarray) -> np.ndarray:
    """Input-frame points of the fitted model moved by `change` (None: as they are)."""
    if change is None:
        return points
    from breastplan.plan.surface import PlannedChange

    return PlannedChange.of(plan, change).model(points)


def _apply(kind: str, mesh: Mesh, degree: float, method: str, side: str, units: str, up: str) -> Mesh:
    """The fitted breast behind `mesh` with `kind` at `degree` (and the changes it carries), input frame."""
    _check_degree({"degree": degree})
    from breastplan.plan.changes import short_of

    recipe = _recipe(mesh, side)
    order = list(KIND_PARAMS)
    changes = tuple(sorted([c for c in recipe.changes if c[0] != kind] + [(kind, float(degree), method)],
                           key=lambda c: order.index(c[0])))
    recipe = replace(recipe, fit=recipe.fit or FitOptions(), changes=changes)
    plan, singles, change = _changed(recipe, units, up)
    asked = next(single for single, (k, _, _) in zip(singles, changes) if k == kind)
    short = short_of(asked.details[0], method)
    if short is not None:
        warnings.warn(f"{kind} reaches {short}", ShortOfDegree, stacklevel=4)   # the caller of the filter
    return _remember(Mesh(_moved(plan, change, plan.surface_input), plan.fit.faces), recipe)
