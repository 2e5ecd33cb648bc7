"""Measures of a plan, before and after (the combination as planned), each side and their asymmetry."""
from __future__ import annotations

from breastplan import transform_points
from breastplan.meshes import mesh_volume

from .job import Plan


def plan_measures(plan: Plan) -> dict:
    before, after = {}, {}
    for side, sp in plan.sides.items():
        verts = transform_points(sp.to_input, sp.fit.vertices)
        planned = sp.planned(sp.changes[-1]).model(verts)
        before[side] = {"volume_cc": round(mesh_volume(verts, sp.fit.faces) / 1e3, 1)}
        after[side] = {"volume_cc": round(mesh_volume(planned, sp.fit.faces) / 1e3, 1)}
    asym = {}
    if len(before) == 2:
        asym = {w: {k: round(m["left"][k] - m["right"][k], 2) for k in m["left"]} for w, m in
                (("before", before), ("after", after))}
    return {"before": before, "after": after, "asymmetry": asym}
