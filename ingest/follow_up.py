"""A follow-up scan measured on the chest of an earlier one: the two torsos are registered on the
chest around the breast (open3d's point-to-plane ICP with a robust loss), and the earlier scan's
chest wall is carried into the later scan's viewing frame.

A breast measured on the chest around it stands on a wall inferred from that skin, and a breast
that grew lifts it: measured on one wall, before and after, a change is measured as it is.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree

from breastplan import BadInputError, transform_points
from breastplan.case import Case
from breastplan.chest_wall import ChestWall
from breastplan.errors import require_folder

from .chest_wall import fit_chest_wall

CHEST_MM = (110.0, 260.0)
"""The chest the torsos are registered on: this (x, y) distance from the nipple (viewing frame,
mm), beyond the breasts and their skirts."""
LEVEL_MM = 30.0
"""The torso's middle is that of its points within this height of the nipple."""
NEAR_MM = 20.0
"""Later chest points within this of the earlier chest once registered are seen in both."""
VOXEL_MM = 4.0
"""The chests are thinned to one point per voxel of this size before they are registered."""
MIN_POINTS = 200
"""Fewer thinned chest points than this are too little chest to register."""
PASSES_MM = (40.0, 20.0, 10.0, 5.0)
"""ICP's correspondence distance, pass by pass."""
MIN_AGREEMENT = 0.7
"""A registration is refused when less than this share of the chest seen in both scans (later
points within NEAR_MM of the earlier chest) lies within the last pass's distance of it."""
WALL_HALF_MM = 160.0
"""The earlier wall is sampled this far around its nipple to be carried across."""


@dataclass(frozen=True)
class Registration:
    """earlier_from_later (4, 4): the later scan's input frame → the earlier one's, mm; at the last
    pass, the RMS of the matched points (mm), the share of the later chest matched (overlap), and
    the share of the chest seen in both that is matched (agreement)."""

    earlier_from_later: np.ndarray
    rms_mm: float
    overlap: float
    agreement: float

    def as_dict(self) -> dict:
        return {"rms_mm": round(self.rms_mm, 3), "overlap": round(self.overlap, 3),
                "agreement": round(self.agreement, 3)}

    def provenance(self, earlier_case: Path) -> tuple[dict[str, Path], dict]:
        """What a fit down to `earlier_case`'s wall adds to its provenance: that case's scan.npz
        among the inputs, and `wall_from` (the case and this registration) among the options."""
        return ({f"earlier {Case.SCAN_NPZ}": Path(earlier_case) / Case.SCAN_NPZ},
                {"wall_from": {"case": str(earlier_case), **self.as_dict()}})


def earlier_cases(folder: Path) -> dict[str, Case]:
    """The cases an earlier case folder holds, by side (`Case.of_sides`); BadInputError naming the
    folder when it is none."""
    return Case.of_sides(require_folder(folder, "case folder of an earlier scan to measure the follow-up against"))


def earlier_case(folder: Path, side: str) -> Case:
    """The case of `side` in an earlier case folder; one of the other side as it is, when that is all
    the folder holds (the registration refuses it, saying which side it holds)."""
    cases = earlier_cases(folder)
    return cases.get(side) or next(iter(cases.values()))


def chest_around_breast(scan) -> np.ndarray:
    """The torso points of a scan (input frame, mm) within CHEST_MM of its nipple in (x, y) of its
    viewing frame, and beyond CHEST_MM[0] of the other breast's nipple, taken as the mirror image
    of this one across the torso's middle at the nipple's height."""
    view = transform_points(scan.input_to_view, scan.torso_camera)
    nipple = _nipple_view(scan)
    level = view[np.abs(view[:, 1] - nipple[1]) < LEVEL_MM, 0]
    other = np.array([np.sum(np.percentile(level, [2, 98])) - nipple[0], nipple[1]]) if len(level) else nipple[:2]
    r = np.linalg.norm(view[:, :2] - nipple[:2], axis=1)
    keep = (r > CHEST_MM[0]) & (r < CHEST_MM[1]) & (np.linalg.norm(view[:, :2] - other, axis=1) > CHEST_MM[0])
    return scan.torso_camera[keep]


def register(earlier, later) -> Registration:
    """The later scan's torso registered onto the earlier one's, on the chest around the breast,
    starting from their breast frames laid on one another."""
    source, target = (_cloud(chest_around_breast(s)) for s in (later, earlier))
    if min(len(source.points), len(target.points)) < MIN_POINTS:
        which = "the follow-up" if len(source.points) < MIN_POINTS else "it"
        raise BadInputError(None, f"cannot be registered with the follow-up: {which} shows too little chest around "
                                  f"the breast ({CHEST_MM[0]:g}–{CHEST_MM[1]:g} mm from the nipple)")
    target.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=15.0, max_nn=30))
    T = np.linalg.inv(earlier.input_to_breast) @ later.input_to_breast
    reg = o3d.pipelines.registration
    for distance in PASSES_MM:
        loss = reg.TukeyLoss(k=distance)
        result = reg.registration_icp(source, target, distance, T, reg.TransformationEstimationPointToPlane(loss),
                                      reg.ICPConvergenceCriteria(max_iteration=30))
        T = result.transformation
    moved = transform_points(T, np.asarray(source.points))
    gap, _ = cKDTree(np.asarray(target.points)).query(moved)
    near = gap < NEAR_MM
    agreement = float(np.mean(gap[near] < PASSES_MM[-1])) if near.any() else 0.0
    return Registration(np.asarray(T), float(result.inlier_rmse), float(result.fitness), agreement)


def carried_wall(earlier, later) -> tuple[ChestWall, Registration]:
    """The earlier scan's chest wall in the later scan's viewing frame, and the registration that
    carried it; BadInputError (naming no file: the earlier case is the culprit) for a scan of the
    other side or of another chest."""
    if earlier.side != later.side:
        raise BadInputError(None, f"holds the {earlier.side} breast, and the follow-up the {later.side} one")
    registration = register(earlier, later)
    if registration.agreement < MIN_AGREEMENT:
        raise BadInputError(None, f"shows another chest around the breast than the follow-up: registered, "
                                  f"{100 * registration.agreement:.0f} % of the chest both show lies within "
                                  f"{PASSES_MM[-1]:g} mm of it (at least {100 * MIN_AGREEMENT:.0f} % for the same "
                                  "patient)")
    later_from_earlier_view = (later.input_to_view @ np.linalg.inv(registration.earlier_from_later)
                               @ np.linalg.inv(earlier.input_to_view))
    return carry_wall(earlier.chest_wall, later_from_earlier_view, _nipple_view(earlier)[:2]), registration


def carry_wall(wall: ChestWall, to_frame: np.ndarray, around_xy: np.ndarray) -> ChestWall:
    """`wall` (a viewing frame's) in another viewing frame (`to_frame`: (4, 4), the wall's frame → the
    other), refitted there as a height field of its degree on its points within WALL_HALF_MM of
    `around_xy` (mm, the wall's frame)."""
    axis = np.linspace(-WALL_HALF_MM, WALL_HALF_MM, 33)
    grid = np.stack(np.meshgrid(axis, axis), -1).reshape(-1, 2) + around_xy
    return fit_chest_wall(transform_points(to_frame, wall.point(grid)), wall.degree)


def _nipple_view(scan) -> np.ndarray:
    """A scan's nipple in its viewing frame (mm)."""
    return transform_points(scan.input_to_view, np.asarray(scan.nipple_camera_mm, float)[None])[0]


def _cloud(points: np.ndarray) -> o3d.geometry.PointCloud:
    """Points (mm) as an open3d cloud thinned to VOXEL_MM."""
    return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, float))).voxel_down_sample(VOXEL_MM)
