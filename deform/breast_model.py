"""The breast model: a primitive, its global deformations and a pose (docs/model.md §2, §3).

The primitive and the deformations work in model units in the primitive's own frame; the pose
(4×4, mm) places that frame in the breast frame. Everything the model gives out is in mm,
breast frame: the fitted model, the synthetic scanner's breasts and the databases' breasts are
all this one composition.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from breastplan import Primitive, mu3_to_cc, to_mm, to_model_units, transform_points
from breastplan.frames import is_rigid
from breastplan.meshes import mesh_volume

from .global_deformations import Deformation


@dataclass(frozen=True, eq=False)
class BreastModel:
    """Primitive (model units), deformations in docs/model.md §3 order, pose (primitive frame → breast frame, mm)."""

    primitive: Primitive
    deformation: Deformation = Deformation()
    pose: np.ndarray = field(default_factory=lambda: np.eye(4))

    def __post_init__(self):
        if not is_rigid(self.pose):
            raise ValueError(f"a breast model's pose is a rigid 4×4 transform (rotation and translation), "
                             f"got {np.asarray(self.pose).tolist()}")

    def place(self, points_mu) -> np.ndarray:
        """Primitive-frame points (model units) deformed and posed: breast frame, mm."""
        deformed = to_mm(self.deformation.apply(points_mu, self.primitive))
        return deformed if np.array_equal(self.pose, np.eye(4)) else transform_points(self.pose, deformed)

    def inverse(self, points_mm, *, fast: bool = False) -> np.ndarray:
        """Breast-frame points (mm) taken back through the pose and the deformations: primitive
        frame, model units (`fast`: see `global_deformations.apply_kind`)."""
        local = transform_points(np.linalg.inv(self.pose), points_mm)
        return self.deformation.inverse(to_model_units(local), self.primitive, fast=fast)

    def sample(self, n_u: int = 100, n_v: int = 100) -> np.ndarray:
        """Points on the (u, v) grid (`Primitive.sample`), mm, breast frame: corresponding points
        for any two models sampled on the same grid."""
        return self.place(self.primitive.sample(n_u, n_v))

    def mesh(self, n_u: int = 100, n_v: int = 100, closed: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Triangle mesh (V mm breast frame, F) on the grid (`Primitive.mesh`), base cap if `closed`."""
        V, F = self.primitive.mesh(n_u, n_v, closed=closed)
        return self.place(V), F

    def volume_cc(self, n: int = 100) -> float:
        """Volume (cc) of the closed n × n grid mesh (the pose is rigid: it keeps the volume)."""
        V, F = self.primitive.mesh(n, n, closed=True)
        return float(mu3_to_cc(mesh_volume(self.deformation.apply(V, self.primitive), F)))
