"""What the report draws: the torso, each side's scan and fitted breast (and a follow-up's earlier
breast), and every planned state.

All in the display frame (x to the image's right, y away from the viewer, z up; mm), from the
scan's viewing frame (x right, y down, z away). A state is the plan at one (kind, degree) — the
degrees 1..8 of every requested kind and the requested degrees — or the combination as planned:
the planned breast meshes and the moved torso points near the breasts, each stored as a
displacement from the original, quantised to int8 with its own scale (at most 1/254 of the
largest displacement: well under a millimetre), so a report of some thirty states stays small.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from breastplan import transform_points

from .changes import Change, change_name, solve_change
from .job import Plan, SidePlan, method_for
from .measures import midline_profile

TORSO_POINTS = 12_000
"""At most this many torso points are drawn (a seeded subsample)."""
VIEW_TO_DISPLAY = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0], [0, -1.0, 0, 0], [0, 0, 0, 1.0]])
"""Viewing frame (y down, z away) → display frame (y away, z up)."""
MIDLINE_MM = (60.0, -350.0)
"""The midline drawn: the measures' anterior midline profile (her skin on the mid-sagittal plane),
from this far above the sternal notch to this far below it (along the up axis), mm."""


@dataclass(frozen=True)
class State:
    """One drawn plan state: its label, the kind whose slider shows it (None: combined), its degree."""

    key: str
    kind: str | None
    degree: float | None
    mesh: dict[str, np.ndarray]       # side → (V, 3) planned breast vertices, display frame
    torso: np.ndarray                  # (P, 3) the moved torso patch, display frame


FOOTPRINT_LIFT_MM = 4.0
"""Each footprint is drawn this far in front of her skin (along her anterior axis), over the points on it."""


@dataclass(frozen=True)
class Views:
    torso: np.ndarray                   # (T, 3) torso points drawn still
    patch: np.ndarray                   # (P, 3) torso points near the breasts (they move)
    scans: dict[str, np.ndarray]        # side → (N, 3) scan points
    meshes: dict[str, tuple[np.ndarray, np.ndarray]]   # side → fitted (V, 3), (F, 3)
    states: list[State]
    earlier: dict[str, tuple[np.ndarray, np.ndarray]]  # side → a follow-up's earlier fitted breast (V, 3), (F, 3)
    landmarks: dict[str, np.ndarray]    # what the measures start from: "sternal notch" (1, 3), "midline" (K, 3)
                                        # her skin on the mid-sagittal plane, "nipples" (sides, 3) as found
    footprints: dict[str, np.ndarray]   # side → (K, 3) the closed outline her volume is measured inside


def slider_degrees(requested: float) -> list[float]:
    """The degrees a kind's slider offers: 1..8 and the requested one."""
    return sorted({*map(float, range(1, 9)), float(requested)})


def build_views(plan: Plan, landmarks: dict) -> Views:
    """Every state of the plan in the display frame; `landmarks`: plan.json's measures.landmarks
    (the sternal notch and the up axis, input frame, mm)."""
    first = next(iter(plan.sides.values()))
    to_display = VIEW_TO_DISPLAY @ first.scan.view_from_camera        # input frame → display frame
    torso_in = first.scan.torso_camera
    keep = np.random.default_rng(0).permutation(len(torso_in))[:TORSO_POINTS]
    torso_in = torso_in[np.sort(keep)]
    near = np.zeros(len(torso_in), bool)
    for side in plan.sides.values():
        near |= side.planned(side.changes[0]).weights(torso_in) > 0
    patch_in = torso_in[near]
    show = lambda p: transform_points(to_display, p)  # noqa: E731
    meshes = {s: (show(sp.surface_input), sp.fit.faces) for s, sp in plan.sides.items()}
    states = []
    for kind, degree in plan.options.changes:
        for d in slider_degrees(degree):
            changes = {s: _single(sp, plan, kind, d) for s, sp in plan.sides.items()}
            states.append(_state(plan, changes, patch_in, show, change_name(kind, d), kind, d))
    if len(plan.options.changes) > 1:
        states.append(_state(plan, {s: sp.changes[-1] for s, sp in plan.sides.items()}, patch_in, show,
                             "combined", None, None))
    return Views(torso=show(torso_in[~near]), patch=show(patch_in),
                 scans={s: show(transform_points(sp.to_input, sp.scan.points)) for s, sp in plan.sides.items()},
                 meshes=meshes, states=states,
                 earlier={s: (show(sp.follow_up.earlier_surface_input), sp.follow_up.earlier_faces)
                          for s, sp in plan.sides.items() if sp.follow_up is not None},
                 landmarks=_landmarks(plan, landmarks, show),
                 footprints={s: show(v.footprint_input_mm + FOOTPRINT_LIFT_MM * plan.volumes.landmarks.anterior_axis)
                             for s, v in plan.volumes.sides.items()})


def _landmarks(plan: Plan, landmarks: dict, show) -> dict[str, np.ndarray]:
    notch = np.asarray(landmarks["sternal_notch_mm"], float)
    up, left = (np.asarray(landmarks[k], float) for k in ("up_axis", "left_axis"))
    offset, top = float(left @ notch), float(up @ notch)
    height, front = midline_profile(next(iter(plan.sides.values())).scan.torso_camera, left, offset, up, top)
    keep = (height <= top + MIDLINE_MM[0]) & (height >= top + MIDLINE_MM[1])
    profile = offset * left + np.outer(height[keep], up) + np.outer(front[keep], np.cross(left, up))
    return {"sternal notch": show(notch[None]), "midline": show(profile[::-1]),
            "nipples": show(np.array([sp.scan.nipple_camera_mm for sp in plan.sides.values()]))}


def _single(side: SidePlan, plan: Plan, kind: str, degree: float) -> Change:
    """The side's change (kind, degree): the one solved for the plan, or solved now for the slider."""
    name = change_name(kind, degree)
    for change in side.changes:
        if change.name == name:
            return change
    return solve_change(side.local_surface(), kind, degree, side.primitive, method_for(plan.options.method, kind))


def _state(plan: Plan, changes: dict[str, Change], patch_in: np.ndarray, show, key: str, kind, degree) -> State:
    moved = patch_in.copy()
    mesh = {}
    for s, sp in plan.sides.items():
        planned = sp.planned(changes[s])
        moved += planned.displacement(patch_in)
        mesh[s] = show(planned.model(sp.surface_input))
    return State(key, kind, degree, mesh, show(moved))


def quantise(displacement: np.ndarray) -> tuple[np.ndarray, float]:
    """(int8 values, scale mm): displacement ≈ values · scale."""
    largest = float(np.abs(displacement).max()) if displacement.size else 0.0
    scale = largest / 127.0 if largest > 0 else 1.0
    return np.round(displacement / scale).astype(np.int8), scale
