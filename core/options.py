"""Frozen option objects of the stages: what a command, a batch or a filter passes around.

Each validates itself on construction (OptionError, a ValueError naming the field) and turns into plain
JSON values (`as_dict`) for an artefact's provenance.
"""
from __future__ import annotations

import os
import re
from dataclasses import asdict, dataclass

SIDES = ("left", "right")
SHOWN_SIDES = ("right", "left")
"""The order her sides are shown in, in every table and sentence: her right first, as she stands facing
whoever reads them (and as her picture shows her)."""
UNITS = ("auto", "mm", "m")
UP_AXES = ("+x", "-x", "+y", "-y", "+z", "-z")
UP_CHOICES = ("auto", *UP_AXES)
"""A scan file's superior axis: found from her body (auto) or one of its six signed axes."""
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
    up: str = "auto"                                 # superior axis of a scan file (UP_CHOICES)
    device_id: str | None = None                     # the live OAK to capture from (None: the first)

    def __post_init__(self):
        if self.side not in SIDES:
            raise OptionError("side", f"'{self.side}' is not a side; choose left or right")
        if not 0.5 <= self.voxel_mm <= 20.0:
            raise OptionError("voxel_mm", f"the voxel size must be 0.5..20 mm, got {self.voxel_mm}")
        if self.frames is not None and self.frames < 1:
            raise OptionError("frames", f"the number of frames must be at least 1, got {self.frames}")
        _check_scan_file(self.units, self.up)
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
        twice = sorted({k for k in self.deformations if self.deformations.count(k) > 1})
        if twice:
            raise OptionError("deformations",
                              f"{', '.join(twice)} named more than once: each deformation is fitted once")

    def as_dict(self) -> dict:
        return {**asdict(self), "deformations": list(self.deformations)}


DEGREE_KINDS = ("ptosis", "turn", "top-shape")
"""The deformations a surgeon plans by degree (those with deformation conditions, docs/model.md §4)."""
PLAN_DEGREES = (1.0, 8.0)
"""The degrees a plan takes (thesis: 8 degrees)."""
DEFAULT_PLAN = (("ptosis", 3.0), ("turn", 3.0), ("top-shape", 3.0))


def _check_scan_file(units: str, up: str) -> None:
    """OptionError unless `units` and `up` say how to read a scan file (UNITS, UP_CHOICES)."""
    if units not in UNITS:
        raise OptionError("units", f"the units are auto, mm or m, not '{units}'")
    if up not in UP_CHOICES:
        raise OptionError("up", f"the up axis is one of {' '.join(UP_CHOICES)}, not '{up}'")


@dataclass(frozen=True)
class PlanOptions:
    """What `plan` plans: (kind, degree) changes, each side's, and how degrees become parameters.

    `method` is exact (the inverse solver), learnt (the shipped regressions) or the path of a
    `breastplan.model/1` file of one condition; `units` and `up` say how to read a scan file, as
    for `IngestOptions`; `wall_from`, an earlier case folder of the patient (a plan's, or one
    side's from `ingest`), makes the plan a follow-up: each breast measured down to that case's
    chest wall, and its volume change since then. `operations`: (side, operation as written) in the order
    made (`plan.operation_spec`: the words are checked there); `symmetrise`: the side whose operations are
    proposed to match the other; `operation_models`: paths of a clinic's models of operations, each making its
    operation in place of the built-in one (`plan.learnt_operation`)."""

    changes: tuple[tuple[str, float], ...] = DEFAULT_PLAN
    sides: tuple[str, ...] = SIDES
    method: str = "exact"
    units: str = "auto"
    up: str = "auto"
    wall_from: str | None = None
    operations: tuple[tuple[str, str], ...] = ()
    symmetrise: str | None = None
    operation_models: tuple[str, ...] = ()

    def __post_init__(self):
        changes = tuple((str(k), float(d)) for k, d in self.changes)
        operations = tuple((str(s), str(text)) for s, text in self.operations)
        if not changes and not operations and self.symmetrise is None:
            raise OptionError("changes", "a plan needs at least one change (--deform KIND:DEGREE) or operation "
                                         "(--left/--right, --symmetrise)")
        for kind, degree in changes:
            if kind not in DEGREE_KINDS:
                raise OptionError("changes", f"'{kind}' has no degrees to plan; choose {', '.join(DEGREE_KINDS)}")
            if not PLAN_DEGREES[0] <= degree <= PLAN_DEGREES[1]:   # NaN fails too
                raise OptionError("changes", f"the degree of {kind} must lie in {PLAN_DEGREES[0]:g}..{PLAN_DEGREES[1]:g}, "
                                             f"got {float(degree)!r}")
        kinds = [k for k, _ in changes]
        if len(set(kinds)) != len(kinds):
            raise OptionError("changes", "each kind is planned once; give one --deform per kind")
        sides = tuple(self.sides)
        if not sides or any(s not in SIDES for s in sides) or len(set(sides)) != len(sides):
            raise OptionError("sides", f"the sides are left, right or both, not {'/'.join(sides) or 'none'}")
        _check_scan_file(self.units, self.up)
        for side, _ in operations:
            if side not in sides:
                raise OptionError("operations", f"an operation on her {side} breast, which is not planned (--side)")
        if self.symmetrise is not None:
            if self.symmetrise not in SIDES or sides != SIDES:
                raise OptionError("symmetrise", "--symmetrise takes left or right, and a plan of both sides")
            if any(side == self.symmetrise for side, _ in operations):
                raise OptionError("symmetrise", f"--symmetrise {self.symmetrise} proposes the operations on that "
                                                "side: give them, or ask for them, not both")
        object.__setattr__(self, "changes", changes)
        object.__setattr__(self, "sides", sides)
        object.__setattr__(self, "operations", operations)
        object.__setattr__(self, "operation_models", tuple(map(str, self.operation_models)))

    @property
    def deform_items(self) -> tuple[str, ...]:
        """The changes by degree as the command line writes them (KIND:DEGREE): `parse`'s items."""
        return tuple(f"{kind}:{degree:g}" for kind, degree in self.changes)

    @property
    def written(self) -> str:
        """What is planned, in a line: each operation as written with its side, the breast symmetrised, then the
        changes by degree (`ptosis:3; turn:3; top-shape:3`)."""
        parts = [f"{side} {text}" for side, text in self.operations]
        parts += [f"symmetrise {self.symmetrise}"] if self.symmetrise else []
        return "; ".join([*parts, *self.deform_items])

    def operations_of(self, side: str) -> tuple[str, ...]:
        """The operations on one side, as written, in order."""
        return tuple(text for s, text in self.operations if s == side)

    @classmethod
    def parse(cls, deform: list[str], side: str = "both", method: str = "exact", units: str = "auto",
              up: str = "auto", wall_from: str | None = None, operations: tuple[tuple[str, str], ...] = (),
              symmetrise: str | None = None, operation_models: tuple[str, ...] = ()) -> "PlanOptions":
        """From the command line's KIND:DEGREE items, side (left, right or both) and the rest as given; without
        KIND:DEGREE items, the default changes unless operations are planned."""
        changes = []
        for item in deform:
            kind, sep, degree = item.partition(":")
            try:
                if not sep:
                    raise ValueError
                changes.append((kind.strip(), float(degree)))
            except ValueError:
                raise OptionError("changes", f"'{item}' is not KIND:DEGREE (e.g. ptosis:3)") from None
        if side not in (*SIDES, "both"):
            raise OptionError("sides", f"'{side}' is not a side; choose left, right or both")
        operated = bool(operations) or symmetrise is not None
        return cls(tuple(changes) or (() if operated else DEFAULT_PLAN), SIDES if side == "both" else (side,), method,
                   units, up, wall_from, tuple(operations), symmetrise, tuple(operation_models))

    def as_dict(self) -> dict:
        return {"changes": [list(c) for c in self.changes], "sides": list(self.sides), "method": self.method,
                "units": self.units, "up": self.up, "wall_from": self.wall_from,
                "operations": [list(o) for o in self.operations], "symmetrise": self.symmetrise,
                "operation_models": list(self.operation_models)}

    @classmethod
    def from_dict(cls, d: dict) -> "PlanOptions":
        """The options `as_dict` gave."""
        return cls(tuple(map(tuple, d["changes"])), tuple(d["sides"]), d["method"], d["units"], d["up"],
                   d.get("wall_from"), tuple(map(tuple, d.get("operations", ()))), d.get("symmetrise"),
                   tuple(d.get("operation_models", ())))


EXECUTORS = ("local", "dask")
"""Where a batch's cases run: local worker processes, or the workers of a Dask cluster."""
MAX_JOBS = max(64, 2 * (os.cpu_count() or 1))
"""Cases a batch runs at once at most: each is a process (a Dask worker, two), with its open files."""
_SCHEDULER = re.compile(r"((tcp|tls|ws|wss|ucx)://)?(\[[0-9A-Fa-f:.]+\]|[^\s/:\[\]]+):([1-9][0-9]{0,4})")
"""A Dask scheduler's address: an optional protocol, a host (an IPv6 one in brackets) and a port."""


@dataclass(frozen=True)
class BatchOptions:
    """How `batch` plans a folder: the plan of every case, how many cases at once (one BLAS thread
    each), and where (local processes, or Dask: a local cluster of `jobs` workers, or the scheduler at
    `scheduler`, e.g. tcp://host:8786); `wall_from`, an earlier batch's output folder, makes each
    case a follow-up of the case of the same name there."""

    plan: PlanOptions = PlanOptions()
    jobs: int = 1
    executor: str = "local"
    scheduler: str | None = None
    wall_from: str | None = None

    def __post_init__(self):
        if self.jobs < 1:
            raise OptionError("jobs", f"a batch runs at least 1 case at once, got {self.jobs}")
        if self.jobs > MAX_JOBS:
            raise OptionError("jobs", f"a batch runs at most {MAX_JOBS} cases at once (the larger of 64 and "
                                      f"twice this machine's {os.cpu_count()} CPUs), got {self.jobs}")
        if self.executor not in EXECUTORS:
            raise OptionError("executor", f"'{self.executor}' is not an executor; choose {' or '.join(EXECUTORS)}")
        if self.scheduler is not None and self.executor != "dask":
            raise OptionError("scheduler", "a scheduler address needs --executor dask")
        address = None if self.scheduler is None else _SCHEDULER.fullmatch(self.scheduler)
        if self.scheduler is not None and (address is None or int(address[4]) > 65535):
            raise OptionError("scheduler", f"'{self.scheduler}' is not a scheduler address; give "
                                           "[PROTOCOL://]HOST:PORT, e.g. tcp://host:8786")

    def as_dict(self) -> dict:
        return {"plan": self.plan.as_dict(), "jobs": self.jobs, "executor": self.executor, "scheduler": self.scheduler,
                "wall_from": self.wall_from}
