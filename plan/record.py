"""A finished plan written out: each side's planned changes, the changed torso, plan.json, report.html
and summary.png; the files of changes an earlier plan of the folder made and this one does not, removed.

Each side's changes go to its case (`Case.save_change`); the plan's own files form one set written
all or nothing, plan.json last, so that a plan.json always describes the report beside it.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from breastplan import __version__, transform_points, write_ply
from breastplan.atomic import Stage, atomic_set
from breastplan.case import Case, Provenance, sha256
from breastplan.json_text import to_json, utf8
from breastplan.deform.names import PARAM_NAMES, at_bounds
from breastplan.fitting.ffd import STOP_RESIDUAL
from breastplan.options import SIDES

from .job import PLAN_SCHEMA, Plan, SidePlan, input_record
from .breast_volume import change_on_earlier_wall
from .measures import asymmetry, breast_measures
from .symmetry import bcct_measures, ptosis_from_cells

SUMMARY = "summary.png"


def write_plan(plan: Plan, folder: Path) -> dict:
    """Write every artefact of `plan` into `folder` (its case folder, or the one being built); the
    plan.json record."""
    from .report import render, versions
    from .summary import summary_png

    with atomic_set() as stage:             # the changes, the torso, the report and plan.json: all or nothing
        sides = {}
        for side, sp in plan.sides.items():
            sides[side] = {"nipple_input_mm": [round(float(v), 2) for v in sp.scan.nipple_camera_mm],
                           "nipple_found": sp.scan.nipple_found,
                           "volume": volume_record(plan, side), "fit": fit_record(sp), "reused": list(sp.reused),
                           "changes": [_save_change(sp, c, folder, stage) for c in sp.changes]}
            if sp.follow_up is not None:
                sides[side]["wall_from"] = {**sp.follow_up.record(sp.fit.volume_cc), **_skin_change(plan, side)}
        torso_files, torsos = {}, planned_torsos(plan)
        record = {"schema": PLAN_SCHEMA, "version": __version__, "input": input_record(plan),
                  "options": plan.options.as_dict(), "stopping_rule": STOP_RESIDUAL, "sides": sides,
                  "measures": plan_measures(plan, torsos[-1]), "versions": versions(),
                  "files": {"report": Case.REPORT, "summary": SUMMARY, "torso": torso_files},
                  "timings_ms": {k: round(v, 1) for k, v in plan.timings_ms.items()}}
        for change, moved in zip(next(iter(plan.sides.values())).changes, torsos):
            name = f"{Case.PLAN}/{change.name}-torso.ply"
            write_ply(stage(folder / name), moved, comments=[
                f"breastplan plan: {change.name}, the torso with the planned change, input frame, mm"])
            torso_files[change.name] = name
        Path(stage(folder / Case.REPORT)).write_bytes(utf8(render(plan, record)))
        summary_png(plan, record, stage(folder / SUMMARY))
        Path(stage(folder / Case.PLAN_JSON)).write_text(to_json(record, indent=1), encoding="utf-8")
    _remove_earlier_plans(folder, record)
    return record


def planned_torsos(plan: Plan) -> list[np.ndarray]:
    """Her torso (`Scan.torso_camera`, input frame, mm) with each change of the plan, both sides moved."""
    torso = next(iter(plan.sides.values())).scan.torso_camera
    torsos = []
    for i in range(len(next(iter(plan.sides.values())).changes)):
        moved = torso.copy()
        for sp in plan.sides.values():
            moved += sp.planned(sp.changes[i]).displacement(torso)
        torsos.append(moved)
    return torsos


def _remove_earlier_plans(folder: Path, record: dict) -> None:
    """Remove what an earlier plan of the case folder left in its plan/ folders (changes no longer
    planned) once the new plan.json, which does not name them, is in place."""
    kept = {folder / f for f in record["files"]["torso"].values()}
    kept |= {folder / f for side in record["sides"].values() for c in side["changes"] for f in c["files"].values()}
    for plans in [folder / Case.PLAN, *(folder / side / Case.PLAN for side in SIDES)]:
        for path in plans.glob("*") if plans.is_dir() else ():
            if path.is_file() and path.suffix in (".ply", ".npz") and path not in kept:
                path.unlink()


def volume_record(plan: Plan, side: str) -> dict:
    """plan.json's `volume` of a side: measured on her skin (`plan.breast_volume`), its footprint (input
    frame, mm), and how far the fitted model's volume lies from it."""
    measured, model = plan.volumes.sides[side], plan.sides[side].fit.volume_cc
    return {**measured.as_dict(), "model_volume_cc": round(model, 1), "model_differs_pct": measured.model_differs_pct(model),
            "footprint_input_mm": np.round(measured.footprint_input_mm, 1).tolist()}


def _skin_change(plan: Plan, side: str) -> dict:
    """A follow-up's change of her volume on her skin: on the earlier visit's wall and footprint (this
    torso carried there by the side's registration), and from each visit's own scan and wall alone."""
    then = plan.earlier_volumes.sides.get(side) if plan.earlier_volumes is not None else None
    if then is None or not then.volume_cc > 0:
        return {}
    sp = plan.sides[side]
    before, after = change_on_earlier_wall(plan.earlier_volumes, sp.scan.torso_camera,
                                           sp.follow_up.registration.earlier_from_later, side)
    on_wall, alone = after - before, plan.volumes.sides[side].volume_cc - then.volume_cc
    return {"skin_earlier_volume_cc": round(before, 1), "skin_volume_change_cc": round(on_wall, 1),
            "skin_volume_change_pct": round(100.0 * on_wall / before, 1),
            "skin_own_walls_change_cc": round(alone, 1),
            "skin_own_walls_change_pct": round(100.0 * alone / then.volume_cc, 1)}


def fit_record(sp: SidePlan) -> dict:
    f = sp.fit
    return {"model_volume_cc": round(f.volume_cc, 2), "model_volume_cc_below_base": round(f.volume_cc_below_base, 2),
            "rms_mm": round(f.residuals_mm["rms"], 4),
            "normalised_residual": round(f.normalised_residual, 6), "stopping_rule_met": f.stopping_rule_met,
            "converged": f.converged, "at_bounds": at_bounds(dict(zip(PARAM_NAMES, map(float, f.deformation)))),
            "ptosis_params": [round(float(f.deformation[PARAM_NAMES.index(k)]), 4) for k in ("b0", "b1")],
            "points": f.points, "iterations": list(f.iterations)}


def _save_change(sp: SidePlan, change, folder: Path, stage: Stage) -> dict:
    """Write one change of one side (model and scan points in the breast frame); its plan.json entry."""
    planned = sp.planned(change)
    to_breast = sp.scan.camera_to_breast
    model = transform_points(to_breast, planned.model(sp.surface_input))
    shift = planned.displacement(transform_points(sp.to_input, sp.scan.points)) @ to_breast[:3, :3].T
    details = [dict(d) for d in change.details]
    record = {"name": change.name, "requested": [list(r) for r in change.requested], "details": details,
              "displacement_mm": shift}
    fit_npz = sp.case.path(Case.FIT_NPZ)
    provenance = Provenance({Case.FIT_NPZ: sha256(fit_npz)}, {"requested": record["requested"]})
    paths = sp.case.save_change(change.name, (model, sp.fit.faces), sp.scan.points + shift, record, provenance, stage)
    moved = np.linalg.norm(shift, axis=1)
    return {"name": change.name, "requested": record["requested"], "details": details,
            "scan_displacement_mm": {"mean": round(float(moved.mean()), 3), "max": round(float(moved.max()), 3)},
            "files": {k: os.path.relpath(p, folder) for k, p in paths.items()}}


def plan_measures(plan: Plan, planned_torso: np.ndarray) -> dict:
    """Each side's measures before and after (the last change: the combination as planned, or the
    single change), and their asymmetry (left − right); lengths mm, volumes cc, input frame. The volume
    is hers, measured on her skin; after, it changes by as much as the fitted model's does.
    `planned_torso`: her torso as planned (`planned_torsos`' last), input frame, mm."""
    landmarks = plan.volumes.landmarks
    before, after = {}, {}
    for side, sp in plan.sides.items():
        verts, nipple = sp.surface_input, sp.scan.nipple_camera_mm
        planned = sp.planned(sp.changes[-1])
        before[side] = breast_measures(landmarks, nipple, verts, sp.fit.faces)
        after[side] = breast_measures(landmarks, planned.model(nipple[None])[0], planned.model(verts), sp.fit.faces)
        measured = plan.volumes.sides[side].volume_cc              # her volume, and after: changed as the model is
        after[side]["volume_cc"] = measured + after[side]["volume_cc"] - before[side]["volume_cc"]
        before[side]["volume_cc"] = measured
    asym = {when: {k: v["left_minus_right"] for k, v in asymmetry(m).items()} for when, m in
            (("before", before), ("after", after))}
    return _finite({"before": before, "after": after, "asymmetry": asym if len(before) == 2 else {},
                    **symmetry_record(plan, planned_torso),
                    "landmarks": {"sternal_notch_mm": landmarks.sternal_notch, "up_axis": landmarks.up_axis,
                                  "left_axis": landmarks.left_axis, "up_from": landmarks.up_from}})


def symmetry_record(plan: Plan, planned_torso: np.ndarray) -> dict:
    """plan.json's `symmetry` (BCCT.core's measures, both sides) and `ptosis` (each side's grade), before
    and as planned (the last change; `planned_torso`: her torso so, input frame, mm), from her skin's
    cells (`plan.symmetry`)."""
    volumes = plan.volumes
    T, cells = volumes.body_from_input, volumes.cells
    nipples = {"before": {}, "after": {}}
    for side, sp in plan.sides.items():
        planned = sp.planned(sp.changes[-1])
        nipples["before"][side] = transform_points(T, sp.scan.nipple_camera_mm[None])[0]
        nipples["after"][side] = transform_points(T, planned.model(sp.scan.nipple_camera_mm[None]))[0]
    states = {"before": cells, "after": cells.moved(transform_points(T, planned_torso))}
    return {"symmetry": {when: bcct_measures(nipples[when], states[when]) if len(plan.sides) == 2 else {}
                         for when in states},
            "ptosis": {when: {s: ptosis_from_cells(nipples[when][s], states[when], s) for s in plan.sides}
                       for when in states}}


def _finite(x):
    """Plain values for JSON: floats to 4 decimals below 10, else 2 (None where not finite); arrays to lists."""
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, np.ndarray):
        return [_finite(float(v)) for v in x]
    if isinstance(x, (float, np.floating)):
        x = float(x)
        return round(x, 4 if abs(x) < 10 else 2) if np.isfinite(x) else None
    return x
