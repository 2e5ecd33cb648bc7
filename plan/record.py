"""A finished plan written out: each side's planned changes, the changed torso, plan.json, report.html,
summary.png and the handout report.pdf; the files of changes an earlier plan of the folder made and this
one does not, removed.

Each side's changes go to its case (`Case.save_change`); the plan's own files form one set written
all or nothing, plan.json last, so that a plan.json always describes the report beside it.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from breastplan import __version__, transform_points, write_ply
from breastplan.code_digest import code_digest
from breastplan.atomic import Stage, atomic_set
from breastplan.case import Case, Provenance, sha256
from breastplan.json_text import measure_values, to_json, utf8
from breastplan.fitting.ffd import STOP_RESIDUAL
from breastplan.options import SIDES

from .plan_file import PLAN_SCHEMA
from .result import Plan, PlanState, SidePlan, SkinChange

SUMMARY = "summary.png"
HANDOUT = "report.pdf"


def write_plan(plan: Plan, folder: Path, parallel: bool = False) -> dict:
    """Write every artefact of `plan` into `folder` (its case folder, or the one being built); the
    plan.json record. With `parallel`, some of her pictures (for summary.png and report.pdf) are drawn in a
    forked child while this process writes the report (`_shots`)."""
    from .handout import handout_pdf
    from .report import first_state, render
    from .summary import summary_png
    from .views import build_views

    with atomic_set() as stage:             # the changes, the torso, the report and plan.json: all or nothing
        sides = {}
        for side, sp in plan.sides.items():
            sides[side] = {"nipple_input_mm": [round(float(v), 2) for v in sp.scan.nipple_camera_mm],
                           "nipple_found": sp.scan.nipple_found,
                           "volume": volume_record(plan, side), "fit": fit_record(sp), "reused": list(sp.reused),
                           "changes": [_save_change(sp, st, folder, stage) for st in plan.changes]}
            if sp.follow_up is not None:
                sides[side]["wall_from"] = {**follow_up_record(sp),
                                            **skin_change_record(plan.skin_changes.get(side))}
            if side in plan.operated:
                sides[side]["operations"] = plan.operated[side].as_dict()
        torso_files = {}
        record = {"schema": PLAN_SCHEMA, "version": __version__, "code": code_digest(), "input": input_record(plan),
                  "options": plan.options.as_dict(), "stopping_rule": STOP_RESIDUAL, "sides": sides,
                  "measures": measures_record(plan), "versions": plan.versions,
                  "patient": plan.patient.as_dict(),
                  "files": {"report": Case.REPORT, "summary": SUMMARY, "handout": HANDOUT, "torso": torso_files},
                  "timings_ms": {k: round(v, 1) for k, v in plan.timings_ms.items()}}
        for state, moved in zip(plan.changes, plan.planned_torsos):
            name = f"{Case.PLAN}/{state.key}-torso.ply"
            write_ply(stage(folder / name), moved, comments=[
                f"breastplan plan: {state.key}, the torso with the planned change, input frame, mm"])
            torso_files[state.key] = name
        views = build_views(plan)
        shots = _shots(views, first_state(plan, views), parallel, stage(folder / Case.REPORT),
                       lambda: utf8(render(plan, views)))
        summary_png(plan, shots, stage(folder / SUMMARY))
        handout_pdf(plan, shots, stage(folder / HANDOUT))
        Path(stage(folder / Case.PLAN_JSON)).write_text(to_json(record, indent=1), encoding="utf-8")
    _remove_earlier_plans(folder, record)
    return record


SHOTS_BESIDE = 2
"""Of her pictured views (`plan.pictures.PICTURED`), the pictures of this many are drawn by a forked child while
the plan writes the report and draws the others: about as long."""


def _shots(views, state, parallel: bool, report: Path, page) -> dict:
    """`plan.pictures.before_after` of every pictured view for `state`, the report `page()` written to `report`
    meanwhile: with `parallel`, the first SHOTS_BESIDE views drawn beside (`breastplan.forked`), else here."""
    from PIL import Image

    from breastplan.forked import beside, shared

    from .pictures import PICTURED, SHOT_PX, before_after

    theirs, mine = PICTURED[:SHOTS_BESIDE], PICTURED[SHOTS_BESIDE:]
    drawn = shared((len(theirs), 2, SHOT_PX[1], SHOT_PX[0], 3), np.uint8)

    def draw() -> None:
        for i, pair in enumerate(before_after(views, state, theirs).values()):
            drawn[i] = [np.asarray(p) for p in pair]

    with beside(draw if parallel else None) as finished:
        Path(report).write_bytes(page())
        shots = before_after(views, state, mine)
        shots |= ({n: tuple(Image.fromarray(p) for p in drawn[i]) for i, n in enumerate(theirs)} if finished()
                  else before_after(views, state, theirs))
    return {n: shots[n] for n in PICTURED}


def input_record(plan: Plan) -> dict:
    """The plan's input as plan.json records it: path, kind and content hash, how far the depth camera stood from
    her nipples (mm; None for a scan file) and what the plan says of it."""
    return {"path": str(plan.input), "kind": plan.input_kind,
            **({} if plan.input_sha256 is None else {"sha256": plan.input_sha256}),
            "camera_mm": None if plan.camera_mm is None else round(plan.camera_mm, 1),
            "camera_notes": list(plan.camera_notes)}


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


def follow_up_record(sp: SidePlan) -> dict:
    """plan.json's `wall_from` of a follow-up's side: the earlier case, the registration, the fitted model's change."""
    (cc, pct), f = sp.model_change, sp.follow_up
    return {"case": str(f.case), **f.registration.as_dict(), "earlier_volume_cc": round(f.earlier_volume_cc, 2),
            "volume_change_cc": round(cc, 2), "volume_change_pct": round(pct, 2)}


def skin_change_record(change: SkinChange | None) -> dict:
    """A follow-up's change of her volume on her skin (`plan.compute.skin_changes`); {} when there is none."""
    if change is None:
        return {}
    return {"skin_earlier_volume_cc": round(change.earlier_cc, 1), "skin_volume_change_cc": round(change.on_wall_cc, 1),
            "skin_volume_change_pct": round(change.on_wall_pct, 1),
            "skin_own_walls_change_cc": round(change.alone_cc, 1),
            "skin_own_walls_change_pct": round(change.alone_pct, 1)}


def fit_record(sp: SidePlan) -> dict:
    f = sp.fit
    return {"model_volume_cc": round(f.volume_cc, 2), "model_volume_cc_below_base": round(f.volume_cc_below_base, 2),
            "rms_mm": round(f.residuals_mm["rms"], 4),
            "normalised_residual": round(f.normalised_residual, 6), "stopping_rule_met": f.stopping_rule_met,
            "converged": f.converged, "at_bounds": sp.at_bounds,
            "ptosis_params": [round(v, 4) for v in sp.ptosis_params],
            "points": f.points, "iterations": list(f.iterations)}


def _save_change(sp: SidePlan, state: PlanState, folder: Path, stage: Stage) -> dict:
    """Write one change of one side (model and scan points in the breast frame); its plan.json entry."""
    change, planned = state.changes[sp.side], state.planned[sp.side]
    to_breast = sp.frames.input_to_breast
    model = transform_points(to_breast, planned.model(sp.surface_input))
    shift = planned.displacement(transform_points(sp.frames.breast_to_input, sp.scan.points)) @ to_breast[:3, :3].T
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


def measures_record(plan: Plan) -> dict:
    """plan.json's `measures`: `Plan.measures` and the landmarks they start from."""
    m, landmarks = plan.measures, plan.volumes.landmarks
    return measure_values({"before": m.before, "after": m.after, "asymmetry": m.asymmetry, "symmetry": m.symmetry,
                    "ptosis": m.ptosis,
                    "landmarks": {"sternal_notch_mm": landmarks.sternal_notch, "up_axis": landmarks.up_axis,
                                  "left_axis": landmarks.left_axis, "up_from": landmarks.up_from}})
