"""Frozen option objects of the stages: what a command, a batch or a filter passes around.

Each validates itself on construction (OptionError, a ValueError naming the field) and turns into plain
JSON values (`as_dict`) for an artefact's provenance.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

SIDES = ("left", "right")
UNITS = ("auto", "mm", "m")
UP_AXES = ("+x", "-x", "+y", "-y", "+z", "-z")
DEFORMATIONS = ("top-shape", "ptosis", "turn")
"""Global deformations fitted with the primitive by default (docs/model.md §3, §6): ptosis and turn
are shears by z with closed-form inverses, top-shape gives the upper half its own profile; a
sagging, turned or top-heavy breast is no superellipsoid, and the lattice alone cannot make up
the difference."""


class OptionError(ValueError):
    """An option value no stage takes; `option` names the field."""

    def __init__(self, option: str, message: str):
        super().__init__(message)
        self.option = option


def _finite(values, count: int, option: str, name: str) -> tuple[float, ...] | None:
    if values is None:
        return None
    import numpy as np  # here, not at the top: the commands import this module for their help (cli/app.py)

    out = tuple(float(v) for v in np.asarray(values, dtype=float).ravel())
    if len(out) != count or not np.isfinite(out).all():
        raise OptionError(option, f"{name} must be {count} finite numbers, got {values!r}")
    return out


@dataclass(frozen=True)
class IngestOptions:
    """How `ingest` isolates the breast of one side; points and boxes in camera mm."""

    side: str
    voxel_mm: float = 2.0                            # voxel size of the downsampling
    frames: int | None = None                        # fuse at most this many depth frames (None: all; 10 live)
    roi_camera_mm: tuple[float, ...] | None = None   # (x0, y0, z0, x1, y1, z1): box holding the breast
    nipple_camera_mm: tuple[float, ...] | None = None  # the nipple, overriding the apex
    units: str = "auto"                              # of a scan file: auto (from its extent), mm or m
    up: str = "+y"                                   # superior axis of a scan file
    device_id: str | None = None                     # the live OAK to capture from (None: the first)

    def __post_init__(self):
        if self.side not in SIDES:
            raise OptionError("side", f"'{self.side}' is not a side; choose left or right")
        if not 0.5 <= self.voxel_mm <= 20.0:
            raise OptionError("voxel_mm", f"the voxel size must be 0.5..20 mm, got {self.voxel_mm}")
        if self.frames is not None and self.frames < 1:
            raise OptionError("frames", f"the number of frames must be at least 1, got {self.frames}")
        if self.units not in UNITS:
            raise OptionError("units", f"the units are auto, mm or m, not '{self.units}'")
        if self.up not in UP_AXES:
            raise OptionError("up", f"the up axis is one of {' '.join(UP_AXES)}, not '{self.up}'")
        roi = _finite(self.roi_camera_mm, 6, "roi_camera_mm", "the region of interest")
        if roi is not None and not all(a < b for a, b in zip(roi[:3], roi[3:])):
            raise OptionError("roi_camera_mm", "the region of interest needs X0<X1, Y0<Y1, Z0<Z1")
        object.__setattr__(self, "roi_camera_mm", roi)
        object.__setattr__(self, "nipple_camera_mm", _finite(self.nipple_camera_mm, 3, "nipple_camera_mm", "the nipple"))

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class FitOptions:
    """How `fit` fits the breast model: lattice size, deformations fitted with the primitive, and
    the FFD's budget, counted in iterations so that a result never depends on the machine's load."""

    lattice: int = 5                                 # control points per lattice axis (5 = 125 CP)
    deformations: tuple[str, ...] = DEFORMATIONS     # global deformations fitted with the primitive
    max_iterations: int = 1000                       # FFD iterations before stopping (thesis: 1000)

    def __post_init__(self):
        if not 3 <= self.lattice <= 7:
            raise OptionError("lattice", f"the lattice must have 3..7 control points per axis, got {self.lattice}")
        if self.max_iterations < 1:
            raise OptionError("max_iterations", f"the FFD needs at least 1 iteration, got {self.max_iterations}")
        object.__setattr__(self, "deformations", tuple(self.deformations))

    def as_dict(self) -> dict:
        return {**asdict(self), "deformations": list(self.deformations)}
