"""A plan computed from her fitted breasts: every state it shows, her volumes, her torso as planned and
the measures (`plan.result.Plan`). Writes nothing: `plan.record` writes what this computes.
"""
from __future__ import annotations

from dataclasses import replace
from importlib import metadata
from pathlib import Path

import numpy as np

from breastplan import transform_points
from breastplan.body import Body, shared_body
from breastplan.case import sha256
from breastplan.clock import Clock
from breastplan.options import PlanOptions

from .breast_volume import BreastVolumes, change_on_earlier_wall, measure_breasts
from .changes import Change, Method, change_name, combine, solve_change
from .measures import asymmetry, breast_measures
from .result import COMBINED, Measures, Plan, PlanState, SidePlan, SkinChange, planned_states
from .surface import PlannedChange
from .symmetry import bcct_measures, ptosis_from_cells


def slider_degrees(requested: float) -> list[float]:
    """The degrees a kind's slider offers: 1..8 and the requested one."""
    return sorted({*map(float, range(1, 9)), float(requested)})


def compute_plan(source: Path, fitted: dict[str, SidePlan], options: PlanOptions, method: Method,
                 earlier: BreastVolumes | None, clock: Clock) -> Plan:
    """The plan of `options` on her fitted breasts (`fitted`: each side's scan and fit, no changes yet),
    by `method`; `earlier`: a follow-up's earlier visit measured on her skin then."""
    sides = {}
    for side, sp in fitted.items():
        with clock(f"changes {side}"):
            sides[side] = replace(sp, changes=solve_changes(sp, options, method))
    with clock("states"):
        states = tuple(_states(sides, options, method))
    body = shared_body({s: sp.scan.body for s, sp in sides.items()}, source)
    with clock("volumes on her skin"):
        volumes = measure_breasts(body, {s: sp.scan.nipple_camera_mm for s, sp in sides.items()})
    with clock("measures"):
        requested = planned_states(states, next(iter(sides.values())))
        torsos = tuple(planned_torso(body, sides, st) for st in requested)
        measures = plan_measures(sides, volumes, requested[-1], torsos[-1])
        skin = {} if earlier is None else skin_changes(body, sides, volumes, earlier)
        sliders = slider_states(sides, states, options)
        shown = shown_measures(sides, volumes, {st.key: st for st in sliders}.values())
    return Plan(source, options, body, sides, volumes, states, torsos, measures, earlier, skin,
                None if source.is_dir() else sha256(source), versions(), clock.ms, slider_states=sliders,
                shown_measures=shown)


def versions() -> dict[str, str]:
    """The versions of breastplan and the packages a plan rests on."""
    out = {}
    for name in ("breastplan", "numpy", "scipy", "open3d", "plotly", "depthai"):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def solve_changes(side: SidePlan, options: PlanOptions, method: Method) -> tuple[Change, ...]:
    """Each requested change of one side, then (for more than one) their combination."""
    singles = [solve_change(side.local_surface, kind, degree, side.primitive, method)
               for kind, degree in options.changes]
    return tuple(singles + ([combine(singles)] if len(singles) > 1 else []))


def _states(sides: dict[str, SidePlan], options: PlanOptions, method: Method):
    """Every state the plan shows: each requested kind at each of its slider's degrees (the requested
    degree being the change solved for the plan), then the combination as planned."""
    for kind, requested in options.changes:
        for degree in slider_degrees(requested):
            name = change_name(kind, degree)
            changes = {s: next((c for c in sp.changes if c.name == name), None)
                       or solve_change(sp.local_surface, kind, degree, sp.primitive, method)
                       for s, sp in sides.items()}
            yield _state(sides, name, kind, degree, changes)
    if len(options.changes) > 1:
        yield _state(sides, COMBINED, None, None, {s: sp.changes[-1] for s, sp in sides.items()})


def slider_states(sides: dict[str, SidePlan], states: tuple[PlanState, ...],
                  options: PlanOptions) -> tuple[PlanState, ...]:
    """What each kind's slider shows at each of its degrees, in the order of `states`: with one requested
    change, that change at the degree; with several, their combination with this kind at the degree and every
    other at its requested degree (the combination as planned at the requested degree)."""
    if len(options.changes) == 1:
        return states
    requested, by_key = dict(options.changes), {st.key: st for st in states}
    out = []
    for st in (st for st in states if st.kind is not None):
        if st.degree == requested[st.kind]:
            out.append(by_key[COMBINED])
            continue
        parts = {k: by_key[change_name(k, d)] for k, d in requested.items()} | {st.kind: st}
        changes = {s: replace(combine([parts[k].changes[s] for k in requested]), name=f"{COMBINED}-{st.key}")
                   for s in sides}
        out.append(_state(sides, f"{COMBINED}-{st.key}", st.kind, st.degree, changes))
    return tuple(out)


def shown_measures(sides: dict[str, SidePlan], volumes: BreastVolumes, states) -> dict[str, dict]:
    """State key → side → her breast's measures in that state (`breast_measures` of the planned breast; her
    volume on her skin changed by as much as the fitted model's)."""
    before = {s: _model_measures(volumes, sp) for s, sp in sides.items()}
    return {state.key: {s: _as_planned(volumes, sp, state.planned[s], before[s]) for s, sp in sides.items()}
            for state in states}


def _model_measures(volumes: BreastVolumes, sp: SidePlan) -> dict[str, float]:
    """A side's measures on its fitted breast as scanned (the volume the fitted model's)."""
    return breast_measures(volumes.landmarks, sp.scan.nipple_camera_mm, sp.surface_input, sp.fit.faces)


def _as_planned(volumes: BreastVolumes, sp: SidePlan, planned: PlannedChange, before: dict[str, float]) -> dict:
    """A side's measures on its breast as `planned` moves it; the volume hers, measured on her skin, changed by
    as much as the fitted model's (`before`: `_model_measures`)."""
    after = breast_measures(volumes.landmarks, planned.model(sp.scan.nipple_camera_mm[None])[0],
                            planned.model(sp.surface_input), sp.fit.faces)
    after["volume_cc"] = volumes.sides[sp.side].volume_cc + after["volume_cc"] - before["volume_cc"]
    return after


def _state(sides: dict[str, SidePlan], key: str, kind, degree, changes: dict[str, Change]) -> PlanState:
    return PlanState(key, kind, degree, changes, {s: PlannedChange.of(sp, changes[s]) for s, sp in sides.items()})


def measure_scans(scans: dict, where: Path | None = None) -> BreastVolumes:
    """The breasts of these scans (side → `Scan`, of one body; `where` is named if they are not)
    measured on her skin (`plan.breast_volume`)."""
    body = shared_body({s: scan.body for s, scan in scans.items()}, where)
    return measure_breasts(body, {s: scan.nipple_camera_mm for s, scan in scans.items()})


def planned_torso(body: Body, sides: dict[str, SidePlan], state: PlanState) -> np.ndarray:
    """Her torso (input frame, mm) in `state`, both sides moved."""
    moved = body.torso_input.copy()
    for side in sides:
        moved += state.planned[side].displacement(body.torso_input)
    return moved


def plan_measures(sides: dict[str, SidePlan], volumes: BreastVolumes, shown: PlanState,
                  torso: np.ndarray) -> Measures:
    """Each side's measures before and as planned (`shown`, her torso so: `torso`, input frame, mm), and
    their asymmetry (left − right). The volume is hers, measured on her skin; as planned, it changes by
    as much as the fitted model's does."""
    before, after, nipples = {}, {}, {"before": {}, "after": {}}
    for side, sp in sides.items():
        nipple, planned = sp.scan.nipple_camera_mm, shown.planned[side]
        nipples["before"][side], nipples["after"][side] = nipple, planned.model(nipple[None])[0]
        before[side] = _model_measures(volumes, sp)
        after[side] = _as_planned(volumes, sp, planned, before[side])
        before[side]["volume_cc"] = volumes.sides[side].volume_cc
    asym = {when: {k: v["left_minus_right"] for k, v in asymmetry(m).items()} for when, m in
            (("before", before), ("after", after))}
    symmetry, ptosis = _symmetry(volumes, nipples, torso)
    return Measures(before, after, asym if len(before) == 2 else {}, symmetry, ptosis)


def _symmetry(volumes: BreastVolumes, nipples_input: dict, torso: np.ndarray):
    """BCCT.core's measures (both sides) and each side's ptosis grade, before and as planned, from her
    skin's cells (`plan.symmetry`); `nipples_input`: "before"/"after" → side → (3,), input frame, mm."""
    T, cells = volumes.body_from_input, volumes.cells
    nipples = {when: {s: transform_points(T, n[None])[0] for s, n in by_side.items()}
               for when, by_side in nipples_input.items()}
    sides = list(nipples["before"])
    states = {"before": cells, "after": cells.moved(transform_points(T, torso))}
    symmetry = {when: bcct_measures(nipples[when], states[when]) if len(sides) == 2 else {} for when in states}
    ptosis = {when: {s: ptosis_from_cells(nipples[when][s], states[when], s) for s in sides} for when in states}
    return symmetry, ptosis


def skin_changes(body: Body, sides: dict[str, SidePlan], volumes: BreastVolumes,
                 earlier: BreastVolumes) -> dict[str, SkinChange]:
    """A follow-up's change of each breast's volume on her skin: on the earlier visit's wall and
    footprint (this torso carried there by the side's registration), and from each visit's own scan
    and wall alone. Sides the earlier visit has no volume for are left out."""
    out = {}
    for side, sp in sides.items():
        then = earlier.sides.get(side)
        if then is None or not then.volume_cc > 0 or sp.follow_up is None:
            continue
        before, after = change_on_earlier_wall(earlier, body.torso_input,
                                               sp.follow_up.registration.earlier_from_later, side)
        alone = volumes.sides[side].volume_cc - then.volume_cc
        out[side] = SkinChange(before, after - before, 100.0 * (after - before) / before, alone,
                               100.0 * alone / then.volume_cc)
    return out
