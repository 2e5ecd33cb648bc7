"""How far the depth camera stood from her, and what a plan says of it.

Her volume on her skin (`plan.breast_volume`) moves with the camera's distance: from further away her skin holds
fewer points and more noise, and the chest wall inferred beneath her breasts moves with them
(`benchmarks/bench_distance.py`, docs/volume.md). Distances are taken from the camera to the midpoint of the
nipples planned (one nipple, for one side), in a recording's input frame (the camera's); a scan file holds no
camera, and nothing is said of it.
"""
from __future__ import annotations

import numpy as np

NEAREST_MM, FARTHEST_MM = 450.0, 850.0
"""Outside these distances (mm), a plan says how far the camera stood: just outside the span the benchmarks found
her volume steady over, and beyond the nearest they tried (`benchmarks/bench_distance.py`, docs/volume.md)."""
APART_MM = 100.0
"""A follow-up whose two visits were scanned further apart than this (mm) says so: her volume moves more across such
a change of distance than between re-scans from alike ones (docs/volume.md)."""


def camera_distance_mm(nipples_from_camera: dict) -> float | None:
    """The camera's distance from the midpoint of the nipples (side → (3,) from the camera, mm, or None), mm (of a
    plan of one side, from its nipple); None where any side's scan holds no camera."""
    if not nipples_from_camera or any(n is None for n in nipples_from_camera.values()):
        return None
    return float(np.linalg.norm(np.mean([np.asarray(n, float) for n in nipples_from_camera.values()], axis=0)))


def distance_notes(now_mm: float | None, then_mm: float | None = None) -> tuple[str, ...]:
    """What a plan says of the camera's distance `now_mm` (None: no camera), and of an earlier visit's `then_mm`
    (a follow-up; None: none, or no camera then): a sentence each, none when the distances are as they should be."""
    notes = []
    if now_mm is not None and now_mm > FARTHEST_MM:
        notes.append(f"The camera stood {now_mm / 1000:.2f} m from her nipples. From that far her volume can read "
                     "high: in the benchmarks a small breast read up to 12 % more than from 0.65 m. Scan her from "
                     "0.5–0.8 m.")
    elif now_mm is not None and now_mm < NEAREST_MM:
        notes.append(f"The camera stood {now_mm / 1000:.2f} m from her nipples, nearer than the benchmarks tried "
                     "(0.5 m): close up it hides more of her breasts' outer sides. Scan her from 0.5–0.8 m.")
    if now_mm is not None and then_mm is not None and abs(now_mm - then_mm) > APART_MM:
        notes.append(f"Her earlier visit was scanned from {then_mm / 1000:.2f} m, this one from {now_mm / 1000:.2f} m: "
                     "her volume moves with the camera's distance, so part of the change may be the camera's. Scan "
                     "her from the same distance at each visit.")
    return tuple(notes)
