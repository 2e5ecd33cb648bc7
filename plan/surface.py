"""A planned change carried onto the patient's own surface, blended into the chest around the breast.

The change is a global deformation of the fitted breast (docs/model.md §3) in its primitive frame,
followed by the FFD lattices of a statistical model, if any.
Points of the breast's footprint (the base superellipse of semi-axes a1..a4) move as the model
moves; beyond it the displacement fades to zero over a band of BAND footprint radii, with a C²
quintic step, so that the changed breast meets the unchanged chest without a step.

Top-shape, as the model states it, scales heights on the upper half only and so tears a surface
along y = 0 (docs/model.md §3). On the patient's surface its displacement is faded in over the
first SEAM·a3 above y = 0 with the same step, so her skin does not split; the planned model
itself keeps the model's formula, on which degrees are defined.

After operations (`plan.operated`), the change starts from her skin (and the fitted model) as they leave it: the
operations move the points first, and the change moves them on from there.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence

import numpy as np

from breastplan import Primitive, to_mm, to_model_units, transform_points
from breastplan.units import MM_PER_MU
from breastplan.deform.global_deformations import Deformation
from breastplan.deform.lattice import Lattice

if TYPE_CHECKING:
    from .operated import Operated

BAND = 0.5
"""Width of the blending band outside the footprint, in footprint radii."""
SEAM = 0.25
"""Height above y = 0, in units of the upper semi-axis a3, over which top-shape is faded in on a surface."""


def smoothstep(s) -> np.ndarray:
    """C² step from 1 (s ≤ 0) to 0 (s ≥ 1): 1 − (6s⁵ − 15s⁴ + 10s³)."""
    s = np.clip(np.asarray(s, dtype=float), 0.0, 1.0)
    return 1.0 - s * s * s * (s * (6.0 * s - 15.0) + 10.0)


@dataclass(frozen=True, eq=False)
class PlannedChange:
    """A deformation of a fitted breast, placed in an input frame.

    `to_primitive` maps input-frame points (mm) to the primitive's frame (mm): the scan's input →
    breast frame transform, then the fit's pose inverted (and, for a left breast, a mirror in x:
    any orthogonal transform)."""

    deformation: Deformation
    primitive: Primitive
    to_primitive: np.ndarray          # (4, 4)
    band: float = BAND
    fields: tuple[Lattice, ...] = ()  # FFD lattices applied after the deformation (mm, primitive frame)
    operated: Operated | None = None  # operations made on her breast before the change (`plan.operated`)

    @classmethod
    def of(cls, side, change, operated: Operated | None = None) -> "PlannedChange":
        """A change (`plan.changes.Change`) of one breast (`plan.result.SidePlan`), placed in its input frame, after
        the `operated` breast's operations, if any."""
        return cls(change.deformation, side.primitive, side.frames.input_to_primitive, fields=change.fields,
                   operated=operated)

    def _before(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) input-frame points where the operations, if any, move them: where the change starts."""
        return points if self.operated is None else self.operated(points)

    def footprint_radius(self, local_mm: np.ndarray) -> np.ndarray:
        """Normalised radius of primitive-frame points over the base superellipse (1 on its rim)."""
        p = self.primitive
        ax = np.where(local_mm[:, 0] >= 0, p.a1, p.a2) * MM_PER_MU
        ay = np.where(local_mm[:, 1] >= 0, p.a3, p.a4) * MM_PER_MU
        return np.hypot(local_mm[:, 0] / ax, local_mm[:, 1] / ay)

    def weights(self, points_mm) -> np.ndarray:
        """(N,) blending weight of input-frame points: 1 on the footprint, 0 past the band; 1 where the operations
        move them."""
        points = np.asarray(points_mm, dtype=float).reshape(-1, 3)
        start = self._before(points)
        moved = np.any(start != points, axis=1)
        return np.maximum(self._weights(transform_points(self.to_primitive, start)), moved)

    def _weights(self, local_mm: np.ndarray) -> np.ndarray:
        return smoothstep((self.footprint_radius(local_mm) - 1.0) / self.band)

    def displacement(self, points_mm) -> np.ndarray:
        """(N, 3) blended displacement of input-frame points, mm, input frame."""
        return PlannedChange.displacements([self], points_mm)[0]

    @staticmethod
    def displacements(changes: Sequence["PlannedChange"], points_mm) -> np.ndarray:
        """(S, N, 3) `displacement` of input-frame points by each of `changes`, all of one breast (one primitive,
        frame and band): the points placed and weighed once, each top-shape applied once."""
        first = _one_breast(changes)
        pts = np.asarray(points_mm, dtype=float).reshape(-1, 3)
        start = first._before(pts)
        local = transform_points(first.to_primitive, start)
        w = first._weights(local)
        moving = w > 0
        out = np.broadcast_to(start - pts, (len(changes), len(pts), 3)).copy()
        near, lifted = local[moving], {}
        near_mu = to_model_units(near)
        for i, change in enumerate(changes):
            moved = change._lattices(to_mm(change._seamless(near_mu, lifted)))
            out[i, moving] += (moved - near) * w[moving, None] @ first.to_primitive[:3, :3]   # back by Rᵀ
        return out

    def __call__(self, points_mm) -> np.ndarray:
        """Input-frame points (mm) with the change applied, blended into the chest."""
        pts = np.asarray(points_mm, dtype=float)
        return pts + self.displacement(pts).reshape(pts.shape)

    def _seamless(self, p_mu: np.ndarray, lifted: dict) -> np.ndarray:
        """The deformation of primitive-frame points (model units), top-shape faded in above y = 0; `lifted` keeps
        the faded top-shape of these points by its parameters, for the next change of the same breast."""
        top, rest = self.deformation.split("flatten-side")
        key = top.params("top-shape")
        if key not in lifted:
            moved = top.apply(p_mu, self.primitive)
            fade = 1.0 - smoothstep(p_mu[:, 1] / (SEAM * self.primitive.a3))
            lifted[key] = p_mu + (moved - p_mu) * fade[:, None]
        return rest.apply(lifted[key], self.primitive)

    def _lattices(self, local_mm: np.ndarray) -> np.ndarray:
        for lattice in self.fields:
            local_mm = lattice(local_mm)
        return local_mm

    def model(self, vertices_mm) -> np.ndarray:
        """Input-frame vertices of the fitted model moved by the operations, then the full change (no blending)."""
        return PlannedChange.models([self], vertices_mm)[0]

    @staticmethod
    def models(changes: Sequence["PlannedChange"], vertices_mm) -> np.ndarray:
        """(S, V, 3) `model` of input-frame vertices by each of `changes`, all of one breast (one primitive and
        frame, after its operations): each top-shape applied once."""
        first = _one_breast(changes)
        start = first._before(np.asarray(vertices_mm, dtype=float).reshape(-1, 3))
        local = to_model_units(transform_points(first.to_primitive, start))
        out, topped = np.empty((len(changes), len(local), 3)), {}
        back = np.linalg.inv(first.to_primitive)
        for i, change in enumerate(changes):
            top, rest = change.deformation.split("flatten-side")
            key = top.params("top-shape")
            if key not in topped:
                topped[key] = top.apply(local, first.primitive)
            out[i] = transform_points(back, change._lattices(to_mm(rest.apply(topped[key], first.primitive))))
        return out


def _one_breast(changes: Sequence[PlannedChange]) -> PlannedChange:
    """The first of `changes`; ValueError unless all are of one breast (primitive, frame, band and operations)."""
    first = changes[0]
    if any(c.primitive != first.primitive or c.band != first.band or c.operated is not first.operated
           or not np.array_equal(c.to_primitive, first.to_primitive) for c in changes[1:]):
        raise ValueError("the changes are not all of one breast (its primitive, frame, band and operations)")
    return first
