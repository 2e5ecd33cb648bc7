"""What a plan is, as values: her body, each breast with its fit and frames, every planned state, the
measures. Computed once (`plan.compute`), then written (`plan.record`), drawn (`plan.report`,
`plan.summary`, `plan.views`) and printed (`cli.plan`); nothing downstream computes any of it again.

Frames (4 × 4, mm), named `a_to_b`: *input* (a recording's camera, x right, y down, z forward; a scan
file's own frame), *view* (the scan's viewing frame), *breast* (the scan's breast frame: x the
patient's left, y up, z out of the chest), *primitive* (the fitted primitive's frame, made anatomical:
a left breast mirrored in x so that both sides are planned as the model's right breast) and *body*
(x her left, y up, z anterior, origin the sternal notch: `BreastVolumes.body_from_input`).

This module imports nothing else from `plan/`: it is the vocabulary the others share.
"""
from __future__ import annotations

import datetime
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from breastplan import Primitive, transform_points
from breastplan.body import Body
from breastplan.case import Case, Fit, Scan
from breastplan.deform.names import DEFORMATION_PARAMS, at_bounds
from breastplan.options import SHOWN_SIDES, PlanOptions

if TYPE_CHECKING:
    from breastplan.ingest.follow_up import Registration

    from .breast_volume import BreastVolumes
    from .changes import Change
    from .operated import Operated
    from .surface import PlannedChange

COMBINED = "combined"
"""The key of the state that applies every requested change together."""
OPERATED = "operated"
"""The key of the one state of a plan of operations alone (no change by degree), and of the slider state with
every kind off."""
OFF = 0.0
"""A slider's first position: its kind switched off (that change left out of the state)."""


@dataclass(frozen=True, eq=False)
class BreastFrames:
    """One breast's frames: the transforms between the input, view, breast and primitive frames."""

    input_to_breast: np.ndarray
    input_to_view: np.ndarray
    breast_to_primitive: np.ndarray

    @classmethod
    def of(cls, scan: Scan, fit: Fit, side: str) -> "BreastFrames":
        """From a scan's frames and its fit's pose (primitive → breast); a left breast is mirrored in x
        (the model's breast is a right one, its −x lateral, docs/model.md §1, §3), so both sides plan
        the same change, medial and lateral alike."""
        mirror = np.diag([-1.0, 1.0, 1.0, 1.0]) if side == "left" else np.eye(4)
        return cls(np.asarray(scan.input_to_breast, float), np.asarray(scan.input_to_view, float),
                   mirror @ np.linalg.inv(fit.pose))

    @cached_property
    def breast_to_input(self) -> np.ndarray:
        return np.linalg.inv(self.input_to_breast)

    @cached_property
    def input_to_primitive(self) -> np.ndarray:
        return self.breast_to_primitive @ self.input_to_breast


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
    earlier_nipple_from_camera_mm: np.ndarray | None = None   # (3,) the earlier nipple from its camera; None: a file


@dataclass(frozen=True, eq=False)
class SidePlan:
    """One breast: its case, scan and fit, its frames, and its planned changes (each as solved on the
    fitted surface: one per requested change, then their combination)."""

    side: str
    case: Case | None                        # None: in memory only (the filters)
    scan: Scan
    fit: Fit
    changes: tuple[Change, ...]
    reused: tuple[str, ...] = ()             # stages taken from the case folder as they were
    follow_up: FollowUp | None = None        # with `wall_from`: the earlier case it is measured against

    @cached_property
    def frames(self) -> BreastFrames:
        return BreastFrames.of(self.scan, self.fit, self.side)

    @property
    def primitive(self) -> Primitive:
        """The fitted primitive in the anatomical frame (a left breast's a1, a2 swapped)."""
        p = self.fit.primitive
        return replace(p, a1=p.a2, a2=p.a1) if self.side == "left" else p

    @cached_property
    def surface_input(self) -> np.ndarray:
        """The fitted surface's vertices (fit.ply) in the input frame, mm."""
        return transform_points(self.frames.breast_to_input, self.fit.vertices)

    @cached_property
    def local_surface(self) -> np.ndarray:
        """The fitted surface in the anatomical primitive frame, mm: what degrees are measured on."""
        return transform_points(self.frames.breast_to_primitive, self.fit.vertices)

    @property
    def at_bounds(self) -> list[str]:
        """The fitted deformation parameters at an end of their plausible range."""
        return at_bounds(dict(zip(DEFORMATION_PARAMS, map(float, self.fit.deformation))))

    @property
    def model_change(self) -> tuple[float, float] | None:
        """A follow-up's change of the fitted model's volume since the earlier visit, each fitted down to
        its chest wall (now: the earlier one carried over): cc, and % of then; None without a follow-up."""
        if self.follow_up is None:
            return None
        then = self.follow_up.earlier_volume_cc
        return self.fit.volume_cc - then, 100.0 * (self.fit.volume_cc - then) / then

    @property
    def ptosis_params(self) -> tuple[float, float]:
        """The fitted ptosis parameters b0, b1 (model units)."""
        d = self.fit.deformation
        return float(d[DEFORMATION_PARAMS.index("b0")]), float(d[DEFORMATION_PARAMS.index("b1")])


@dataclass(frozen=True, eq=False)
class PlanState:
    """The plan at one (kind, degree) on every side — a requested change or a degree the report's
    slider offers — or the combination as planned (kind and degree None)."""

    key: str                                  # "ptosis-3", "turn-2.5" or COMBINED
    kind: str | None
    degree: float | None
    changes: dict[str, Change]                # side → the change as solved on that breast
    planned: dict[str, PlannedChange]         # side → that change placed in the input frame


@dataclass(frozen=True, eq=False)
class StateGrid:
    """Every state the report's sliders reach: each requested kind off (`OFF`) or at each of its slider's degrees, in
    every combination (the kinds' changes as each was solved alone, applied together). State i takes the kinds'
    degrees at the digits of i in mixed radix, the last kind's digit the fastest (`combination`)."""

    kinds: tuple[str, ...]
    degrees: tuple[tuple[float, ...], ...]        # per kind: its slider's positions, ascending: OFF, then degrees
    requested: tuple[float, ...]                  # per kind: the degree planned
    keys: tuple[str, ...]                         # per state: its name (COMBINED: every kind as planned)
    changes: dict[str, tuple[Change, ...]]        # side → per state: the change as combined
    planned: dict[str, tuple[PlannedChange, ...]]  # side → per state: that change placed in the input frame
    models: dict[str, np.ndarray]                 # side → (S, V, 3) float32 the fitted model as planned, input
                                                  # frame, mm
    measures: dict[str, dict[str, np.ndarray]]    # side → measure → (S,) her breast as planned (her volume on
                                                  # her skin, changed by as much as the fitted model's)

    def __len__(self) -> int:
        return len(self.keys)

    def index(self, degrees) -> int:
        """The state of these degrees (one per kind, each one of its slider's)."""
        i = 0
        for offered, d in zip(self.degrees, degrees):
            i = i * len(offered) + offered.index(float(d))
        return i

    def combination(self, i: int) -> tuple[float, ...]:
        """The kinds' degrees in state i."""
        out = []
        for offered in reversed(self.degrees):
            i, digit = divmod(i, len(offered))
            out.append(offered[digit])
        return tuple(reversed(out))

    @property
    def planned_index(self) -> int:
        """The state of the degrees planned."""
        return self.index(self.requested)

    def measures_at(self, i: int) -> dict[str, dict[str, float]]:
        """Side → measure → value in state i."""
        return {s: {k: float(v[i]) for k, v in m.items()} for s, m in self.measures.items()}


@dataclass(frozen=True)
class SkinChange:
    """A follow-up's change of one breast's volume on her skin (cc, %): on the earlier visit's wall and
    footprint (`on_wall`, from `earlier_cc`), and from each visit's own scan and wall alone (`alone`)."""

    earlier_cc: float
    on_wall_cc: float
    on_wall_pct: float
    alone_cc: float
    alone_pct: float


@dataclass(frozen=True, eq=False)
class Measures:
    """The plan's measures (lengths mm, volumes cc, input frame): each side's before and as planned (the
    last change), the asymmetry (left − right) of each, BCCT.core's symmetry measures and each side's
    Regnault ptosis grade, before and as planned. `before`/`after`: side → measure name → value."""

    before: dict[str, dict[str, float]]
    after: dict[str, dict[str, float]]
    asymmetry: dict[str, dict[str, float]]    # "before"/"after" → measure → left − right ({} for one side)
    symmetry: dict[str, dict[str, float]]     # "before"/"after" → measure ({} for one side)
    ptosis: dict[str, dict[str, dict]]        # "before"/"after" → side → grade and what it rests on

    @property
    def contour_hidden(self) -> bool:
        """Whether, before or as planned, a breast's lowest point lies on skin the camera did not see (its
        height her other side's, mirrored: `plan.symmetry.bcct_measures`' `lower_contours_hidden`)."""
        return any(self.symmetry.get(when, {}).get("lower_contours_hidden") for when in ("before", "after"))


def planned_states(states, side: SidePlan) -> tuple[PlanState, ...]:
    """Of `states`, those of `side`'s planned changes, in their order (the combination last)."""
    by_key = {st.key: st for st in states}
    return tuple(by_key[c.name] for c in side.changes)


@dataclass(frozen=True)
class Patient:
    """Whom and when a plan is for, as its report and handout name them; nothing is computed from it.
    `date`: ISO (YYYY-MM-DD), the day planned unless given."""

    name: str | None = None
    patient_id: str | None = None
    surgeon: str | None = None
    date: str = field(default_factory=lambda: datetime.date.today().isoformat())

    @property
    def header(self) -> str:
        """One line: her name and ID (or "anonymous"), the surgeon, the date."""
        who = " ".join(filter(None, [self.name, f"(ID {self.patient_id})" if self.patient_id else None]))
        parts = [f"Patient: {who or 'anonymous'}", f"Surgeon: {self.surgeon}" if self.surgeon else None,
                 f"Date: {self.date}"]
        return " · ".join(filter(None, parts))

    def as_dict(self) -> dict:
        return {"name": self.name, "patient_id": self.patient_id, "surgeon": self.surgeon, "date": self.date}


@dataclass(frozen=True, eq=False)
class Plan:
    """A computed plan: its input and options, her body, each breast, her volumes measured on her skin, the
    states (the requested changes, their combination, each kind alone at its slider's degrees), every state the
    sliders reach (`grid`), her torso as planned, the measures, for a follow-up the earlier visit's volumes
    and each side's change since, and each operated side's operations (made first, under every state)."""

    input: Path
    options: PlanOptions
    body: Body                                # her torso as scanned, shared by the sides
    sides: dict[str, SidePlan]
    volumes: BreastVolumes
    states: tuple[PlanState, ...]
    planned_torsos: tuple[np.ndarray, ...]    # her torso (input frame, mm) with each of `changes`
    measures: Measures
    earlier_volumes: BreastVolumes | None = None
    skin_changes: dict[str, SkinChange] = field(default_factory=dict)
    input_sha256: str | None = None           # None: a case folder
    versions: dict[str, str] = field(default_factory=dict)   # package → version, as planned
    timings_ms: dict = field(default_factory=dict)
    patient: Patient = field(default_factory=Patient)
    grid: StateGrid | None = None             # every state the report's sliders reach
    operated: dict[str, Operated] = field(default_factory=dict)   # side → its operations, under every state
    camera_mm: float | None = None            # the depth camera's distance from her nipples; None: a scan file
    camera_notes: tuple[str, ...] = ()        # what the plan says of that distance (`plan.camera_distance`)

    @property
    def input_kind(self) -> str:
        if self.input.is_dir():
            return "case folder"
        return "recording" if self.input.suffix.lower() == ".mcap" else "scan file"

    @property
    def shown_sides(self) -> list[str]:
        """The sides planned, in the order tables and sentences show them (`SHOWN_SIDES`)."""
        return [s for s in SHOWN_SIDES if s in self.sides]

    @property
    def operated_shown(self) -> list[tuple[str, Operated]]:
        """(side, its operations) of each operated side, in `shown_sides` order."""
        return [(s, self.operated[s]) for s in self.shown_sides if s in self.operated]

    @property
    def first(self) -> SidePlan:
        """The first side planned."""
        return next(iter(self.sides.values()))

    @property
    def changes(self) -> tuple[PlanState, ...]:
        """The planned states in order: each requested change, then (for more than one) the combination."""
        return planned_states(self.states, self.first)

    @property
    def shown(self) -> PlanState:
        """The state the plan leads with: the combination as planned, the one planned change, or the operations
        alone."""
        return self.changes[-1]
