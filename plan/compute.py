"""A plan computed from her fitted breasts: every state it shows, her volumes, her torso as planned and
the measures (`plan.result.Plan`). Writes nothing: `plan.record` writes what this computes.
"""
from __future__ import annotations

import itertools
from dataclasses import replace
from importlib import metadata
from pathlib import Path

import numpy as np

from breastplan import BadInputError, transform_points
from breastplan.body import Body, shared_body
from breastplan.case import sha256
from breastplan.clock import Clock
from breastplan.options import PlanOptions

from .base_width import base_width_mm
from .breast_volume import BreastVolumes, change_on_earlier_wall, measure_breasts
from .camera_distance import camera_distance_mm, distance_notes
from .changes import UNCHANGED, Change, Method, change_name, combine, solve_change
from .learnt_operation import operation_models
from .measures import asymmetry, breast_measures, breast_measures_each
from .operated import Operated, operate
from .operation_spec import OperationSpec
from .result import COMBINED, OFF, OPERATED, Measures, Plan, PlanState, SidePlan, SkinChange, StateGrid, planned_states
from .surface import PlannedChange
from .symmetrising import symmetrising
from .symmetry import bcct_measures, fold_line, ptosis_from_cells


def slider_degrees(requested: float) -> list[float]:
    """The positions a kind's slider offers: off (`OFF`), then the degrees 1..8 and the requested one."""
    return sorted({OFF, *map(float, range(1, 9)), float(requested)})


def compute_plan(source: Path, fitted: dict[str, SidePlan], options: PlanOptions, method: Method,
                 earlier: BreastVolumes | None, clock: Clock) -> Plan:
    """The plan of `options` on her fitted breasts (`fitted`: each side's scan and fit, no changes yet),
    by `method`; `earlier`: a follow-up's earlier visit measured on her skin then."""
    body = shared_body({s: sp.scan.body for s, sp in fitted.items()}, source)
    with clock("volumes on her skin"):
        volumes = measure_breasts(body, {s: sp.scan.nipple_camera_mm for s, sp in fitted.items()})
    with clock("operations"):
        operated = operations(fitted, volumes, options)
    sides = {}
    for side, sp in fitted.items():
        with clock(f"changes {side}"):
            sides[side] = replace(sp, changes=solve_changes(sp, options, method) or (UNCHANGED,))
    with clock("states"):
        states = tuple(_states(sides, options, method, operated))
    folds = {s: her_fold(volumes, sp) for s, sp in sides.items()}
    widths = {s: base_width_mm(volumes.cells, volumes.in_body(sp.scan.nipple_camera_mm), s) for s, sp in sides.items()}
    fitted_measures = {s: _model_measures(volumes, sp, folds[s]) for s, sp in sides.items()}
    with clock("every slider state"):
        grid = state_grid(sides, states, options, volumes, fitted_measures, folds, widths, operated)
    with clock("measures"):
        requested = planned_states(states, next(iter(sides.values())))
        torsos = tuple(planned_torso(body, sides, st) for st in requested)
        measures = plan_measures(sides, volumes, widths, requested[-1], torsos[-1], fitted_measures,
                                 grid.measures_at(grid.planned_index))
        skin = {} if earlier is None else skin_changes(body, sides, volumes, earlier)
    now = camera_distance_mm({s: sp.scan.nipple_from_camera_mm for s, sp in sides.items()})
    then = None if any(sp.follow_up is None for sp in sides.values()) else camera_distance_mm(
        {s: sp.follow_up.earlier_nipple_from_camera_mm for s, sp in sides.items()})
    return Plan(source, options, body, sides, volumes, states, torsos, measures, earlier, skin,
                None if source.is_dir() else sha256(source), versions(), clock.ms, grid=grid, operated=operated,
                camera_mm=now, camera_notes=distance_notes(now, then))


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


def operations(sides: dict[str, SidePlan], volumes: BreastVolumes, options: PlanOptions) -> dict[str, Operated]:
    """Each side's operations (`options.operations`, or those `options.symmetrise` proposes) made on her skin as
    measured (`volumes`); sides without any are left out. BadInputError where her scan rules one out."""
    nipples = {s: sp.scan.nipple_camera_mm for s, sp in sides.items()}
    models = operation_models(options.operation_models)
    out = {}
    for side in sides:
        written = tuple(map(OperationSpec.parse, options.operations_of(side)))
        if not written and options.symmetrise != side:
            continue
        fold = ptosis_from_cells(volumes.in_body(nipples[side]), volumes.cells, side)["nipple_to_fold_mm"]
        if fold is None or not np.isfinite(fold):
            raise BadInputError(None, f"shows no inframammary fold under her {side} breast, where its operations "
                                      "are placed")
        if options.symmetrise == side:
            proposal = symmetrising(volumes, nipples, side, fold, models)
            out[side] = replace(proposal.operated, note=proposal.note)
        else:
            out[side] = operate(volumes, nipples, side, fold, written, models)
    return out


def _states(sides: dict[str, SidePlan], options: PlanOptions, method: Method, operated: dict[str, Operated]):
    """Each requested kind alone at each of its slider's degrees (the requested degree being the change solved for
    the plan; off is no change), then the combination as planned: the changes `state_grid` combines; with no kind,
    her operations alone (OPERATED). Each after her operations, if any."""
    for kind, requested in options.changes:
        for degree in slider_degrees(requested)[1:]:             # off is no change
            name = change_name(kind, degree)
            changes = {s: next((c for c in sp.changes if c.name == name), None)
                       or solve_change(sp.local_surface, kind, degree, sp.primitive, method)
                       for s, sp in sides.items()}
            yield _state(sides, name, kind, degree, changes, operated)
    if len(options.changes) != 1:
        yield _state(sides, COMBINED if options.changes else OPERATED, None, None,
                     {s: sp.changes[-1] for s, sp in sides.items()}, operated)


def state_grid(sides: dict[str, SidePlan], states: tuple[PlanState, ...], options: PlanOptions,
               volumes: BreastVolumes, fitted: dict[str, dict[str, float]], folds: dict[str, np.ndarray | None],
               widths: dict[str, float], operated: dict[str, Operated] | None = None) -> StateGrid:
    """Every combination of the kinds' slider positions (`states` holds each kind's change at each degree; a kind
    off is left out, every kind off is her operations alone; with no kind, the one state of her operations), after
    her `operated` breasts' operations, each side's fitted model so planned, and her measures on it
    (`breast_measures_each`). Her volume on her skin is changed by the operations' exact
    change, then by as much as the fitted model's volume changes from the operations' state (`fitted`: its measures
    as scanned, `_model_measures`); her width on her skin (side → mm, `base_width_mm`) likewise by as much as the
    model's. Nipple to fold is measured to her fold, side → `her_fold`, in every state."""
    operated = operated or {}
    kinds = tuple(k for k, _ in options.changes)
    requested = tuple(d for _, d in options.changes)
    degrees = tuple(tuple(slider_degrees(d)) for d in requested)
    combos = list(itertools.product(*degrees))
    by_key = {st.key: st for st in states}
    changes, planned, models, measures = {}, {}, {}, {}
    for s, sp in sides.items():
        singles = [[by_key[change_name(k, d)].changes[s] for k, d in zip(kinds, combo) if d != OFF] for combo in combos]
        changes[s] = tuple(one[0] if len(one) == 1 else combine(one) if one else UNCHANGED for one in singles)
        planned[s] = tuple(PlannedChange.of(sp, c, operated.get(s)) for c in changes[s])
        moved = PlannedChange.models(planned[s], np.vstack([sp.surface_input, sp.scan.nipple_camera_mm]))
        measures[s] = breast_measures_each(volumes.landmarks, moved[:, -1], moved[:, :-1], sp.fit.faces,
                                           fold_mm=folds[s])
        models[s] = moved[:, :-1].astype(np.float32)
        base, volume = fitted[s]["volume_cc"], volumes.sides[s].volume_cc
        if s in operated:
            op = operated[s]
            base = breast_measures(volumes.landmarks, op.nipple_mm, op(sp.surface_input), sp.fit.faces)["volume_cc"]
            volume = op.volume_cc
        measures[s]["volume_cc"] += volume - base
        measures[s]["width_mm"] += widths[s] - fitted[s]["width_mm"]
        measures[s] = poles_of_her_volume(measures[s])
    keys = tuple(COMBINED if len(kinds) > 1 and combo == requested else
                 "+".join(change_name(k, d) for k, d in zip(kinds, combo) if d != OFF) or OPERATED for combo in combos)
    return StateGrid(kinds, degrees, requested, keys, changes, planned, models, measures)


def poles_of_her_volume(measures: dict) -> dict:
    """`measures` (one side's, scalars or per state) with her volume (`volume_cc`, on her skin) split into its upper
    and lower poles as the fitted model splits its own (`pole_ratio` kept), so that the poles add up to it."""
    upper, lower, volume = (np.asarray(measures[k], float) for k in ("upper_pole_cc", "lower_pole_cc", "volume_cc"))
    share = np.divide(upper, upper + lower, out=np.full_like(upper, 0.5), where=upper + lower > 0)
    up = volume * share
    poles = {"upper_pole_cc": up, "lower_pole_cc": volume - up}
    return {**measures, **{k: v if v.ndim else float(v) for k, v in poles.items()}}


def _model_measures(volumes: BreastVolumes, sp: SidePlan, fold_mm: np.ndarray | None) -> dict[str, float]:
    """A side's measures on its fitted breast as scanned (the volume the fitted model's; nipple to fold to `fold_mm`,
    `her_fold`)."""
    return breast_measures(volumes.landmarks, sp.scan.nipple_camera_mm, sp.surface_input, sp.fit.faces, fold_mm=fold_mm)


def her_fold(volumes: BreastVolumes, sp: SidePlan) -> np.ndarray | None:
    """(3,) her fold under the side's nipple as found on her skin (her ptosis, `symmetry.fold_line`), input frame;
    None: none found (the fitted model's base then stands for it)."""
    nipple = sp.scan.nipple_camera_mm
    line = fold_line(volumes, nipple, ptosis_from_cells(volumes.in_body(nipple), volumes.cells, sp.side))
    return None if line is None else line[0]


def _state(sides: dict[str, SidePlan], key: str, kind, degree, changes: dict[str, Change],
           operated: dict[str, Operated]) -> PlanState:
    return PlanState(key, kind, degree, changes, {s: PlannedChange.of(sp, changes[s], operated.get(s))
                                                  for s, sp in sides.items()})


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


def plan_measures(sides: dict[str, SidePlan], volumes: BreastVolumes, widths: dict[str, float], shown: PlanState,
                  torso: np.ndarray, fitted: dict[str, dict[str, float]],
                  after: dict[str, dict[str, float]]) -> Measures:
    """Each side's measures before (`fitted`: on the fitted breasts as scanned, `_model_measures`) and as planned
    (`shown`, her torso so: `torso`, input frame, mm; `after`: its measures, `StateGrid.measures_at`), and their
    asymmetry (left − right). The volume and the width (side → mm, `base_width_mm`) are hers, measured on her
    skin."""
    before, nipples = {}, {"before": {}, "after": {}}
    for side, sp in sides.items():
        nipple, planned = sp.scan.nipple_camera_mm, shown.planned[side]
        nipples["before"][side], nipples["after"][side] = nipple, planned.model(nipple[None])[0]
        before[side] = poles_of_her_volume({**fitted[side], "volume_cc": volumes.sides[side].volume_cc,
                                            "width_mm": widths[side]})
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
