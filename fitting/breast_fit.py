"""The breast model fitted to a breast-frame cloud: superquadric (+ global deformations), then FFD.

`fit_breast` runs the two stages of docs/model.md §2–§3 and §6; `BreastFit.artefact` gives the
case's `Fit` (`breastplan.case`), which the case writes as fit.npz and fit.ply (the fitted closed
surface: mm, breast frame, its base cap held near the chest wall's tangent plane z = 0; the
breast's volume adds the gap between that cap and the chest wall beneath, `BreastFit.below_base_cc`).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property, partial

import numpy as np
from scipy.spatial import cKDTree

from breastplan import BadInputError, Primitive, to_mm
from breastplan.case import Fit, Provenance
from breastplan.deform.global_deformations import ptosis
from breastplan.deform.names import DEFORMATION_PARAMS, at_bounds
from breastplan.meshes import mesh_volume, volume_below_base
from breastplan.options import FitOptions
from breastplan.point_order import canonical_order
from breastplan.units import volume_problem

from .ffd import STOP_RESIDUAL, FFDFit, fit_ffd
from .sampling import one_blas_thread
from .superquadric import SuperquadricFit, distance_stats, fit_superquadric

MESH_GRID = (40, 96)
"""(n_u, n_v) of the model mesh: 3 746 vertices, about 2 mm apart on a 450 cc breast."""
BASE_WEIGHT = 0.1
"""Weight holding the base cap on z = 0 (the chest wall's tangent plane), as a share of the data's weight."""
SMOOTHNESS = (1e-9, 1e-6)
"""λ of the FFD for a fully seen breast and for a partly seen one: the smaller lets the lattice
follow a database breast closely, the larger carries the seen shape of a frontal scan smoothly over
its unseen side (benchmarks/bench_fit.py measures both)."""
UNSEEN_MM, UNSEEN_SHARE = 6.0, 0.02
"""A model vertex is unseen with no data point within 6 mm; a breast is partly seen above 2 %."""
MAX_RESIDUAL = 0.03
"""A fit whose mean normalised residual stays above 3 % describes no breast surface."""


@dataclass
class BreastFit:
    """A fitted breast model: the superquadric stage, the FFD stage and the closed mesh (mm)."""

    superquadric: SuperquadricFit
    ffd: FFDFit
    faces: np.ndarray              # (F, 3) of the closed mesh; vertices are ffd.vertices
    below_base_cc: float = 0.0     # between the base cap and the curved chest wall beneath it

    @property
    def vertices(self) -> np.ndarray:
        return self.ffd.vertices

    @property
    def stopping_rule_met(self) -> bool:
        """Whether the mean normalised residual is below the thesis's stopping rule (docs/model.md §6)."""
        return bool(self.ffd.residual < STOP_RESIDUAL)

    def residual_stats(self) -> dict[str, float]:
        """Data ↔ fitted-surface distances, mm: mean, rms, p95, max."""
        return distance_stats(self.ffd.residuals_mm)

    @cached_property
    def mesh_volume_cc(self) -> float:
        """Volume enclosed by the fitted closed surface (cc): the model above its base cap."""
        return mesh_volume(self.vertices, self.faces) / 1000.0

    @property
    def volume_cc(self) -> float:
        """The breast's volume on the chest wall (cc): the closed surface's and the gap between its
        base and the chest wall beneath (`below_base_cc`)."""
        return self.mesh_volume_cc + self.below_base_cc

    @property
    def seconds(self) -> float:
        return self.superquadric.seconds + self.ffd.seconds

    def params(self) -> dict[str, float]:
        """Primitive parameters (model units) and the fitted deformation parameters."""
        out = self.superquadric.primitive.as_dict()
        out.update({n: float(v) for n, v in zip(DEFORMATION_PARAMS, self.superquadric.deformation.as_vector()) if v != 0.0})
        return out

    @property
    def ptosis_sag_mm(self) -> float:
        """`ptosis_sag_mm` of the fitted primitive and ptosis."""
        return ptosis_sag_mm(self.superquadric.primitive, self.superquadric.deformation.params("ptosis"))

    def at_bounds(self) -> list[str]:
        """Fitted deformation parameters at an end of their plausible range (deform.names.at_bounds)."""
        return at_bounds(self.params())

    def artefact(self, provenance: Provenance = Provenance()) -> Fit:
        """The case's record of this fit (`Case.save_fit` writes it)."""
        sq, lattice = self.superquadric, self.ffd.lattice
        return Fit(vertices=self.vertices, faces=self.faces, primitive=sq.primitive, pose=sq.pose,
                   deformation=sq.deformation.as_vector(), lattice_shape=np.full(3, lattice.n, dtype=np.int64),
                   lattice_box_mm=np.stack([lattice.lo, lattice.hi]), control_rest_mm=lattice.rest,
                   control_fitted_mm=lattice.points, residuals_mm=self.residual_stats(),
                   normalised_residual=float(self.ffd.residual), volume_cc_primitive=sq.primitive.volume_cc,
                   volume_cc_mesh=self.mesh_volume_cc, volume_cc_below_base=self.below_base_cc,
                   iterations=(sq.iterations, self.ffd.iterations),
                   seconds=(sq.seconds, self.ffd.seconds), points=len(self.ffd.residuals_mm),
                   residual_map_mm=self.ffd.residuals_mm,
                   converged=bool(self.ffd.converged), stopping_rule_met=self.stopping_rule_met,
                   provenance=provenance)


ChestBeneath = Callable[[np.ndarray], np.ndarray]
"""The chest wall under a breast: breast-frame (..., 2) x, y → (...,) z of the wall, mm."""


def fit_breast(points_mm: np.ndarray, options: FitOptions = FitOptions(),
               chest: ChestBeneath | None = None) -> BreastFit:
    """Fit the breast model to (N, 3) points (mm, breast frame, base on z = 0), on the chest wall
    `chest` (None: the plane z = 0, as on a database breast; an ingested breast: `fit_scan`).

    A fit that runs out of iterations before the stopping rule is returned as it is (its
    `ffd.converged` and `stopping_rule_met` say so; `ffd.residuals_mm` maps where it misses);
    BadInputError for unusable points or a fit that finds no breast surface (mean normalised
    residual above MAX_RESIDUAL, or no enclosed volume).

    The fit is a function of the point set alone: any order of the same points gives the same fit,
    bit for bit (its stages work on the points in canonical order, `breastplan.point_order`, and
    report the per-point residuals in the caller's order), and so does any BLAS thread count (it
    runs on one).
    """
    with one_blas_thread():
        return _fit_breast(points_mm, options, chest)


def _fit_breast(points_mm, options: FitOptions, chest: ChestBeneath | None) -> BreastFit:
    sq = fit_superquadric(points_mm, deformations=options.deformations)
    vertices, faces = model_mesh(sq)
    points = np.asarray(points_mm, float)
    lam = smoothness(vertices, points[canonical_order(points)])
    ffd = fit_ffd(points, vertices, faces, n=options.lattice, smoothness=lam, held=held_weights(vertices),
                  max_iterations=options.max_iterations)
    if not ffd.residual < MAX_RESIDUAL:
        raise BadInputError(None, f"gives a fit that found no breast surface: mean normalised residual "
                                  f"{ffd.residual:.4f} after {ffd.iterations} FFD iterations "
                                  f"(stopping rule {STOP_RESIDUAL})")
    below = 0.0 if chest is None else volume_below_base(ffd.vertices, faces, chest) / 1000.0
    fit = BreastFit(sq, ffd, faces, below)
    if not fit.mesh_volume_cc > 0.0:
        raise BadInputError(None, f"gives a fitted surface that encloses no volume ({fit.mesh_volume_cc:.0f} cc): "
                                  "its points do not hold a breast")
    problem = volume_problem(fit.volume_cc)
    if problem:
        raise BadInputError(None, f"gives a fitted breast of {fit.volume_cc:,.0f} cc down to the chest wall, "
                                  f"{problem}: the chest wall found beneath it is not hers")
    return fit


def fit_scan(scan, options: FitOptions = FitOptions()) -> BreastFit:
    """`fit_breast` of an ingested breast (a case's `Scan`, or `ingest_frames`' result) on the chest
    wall ingest found beneath it."""
    view_to_breast = np.asarray(scan.input_to_breast, float) @ np.linalg.inv(scan.input_to_view)
    return fit_breast(scan.points, options, partial(scan.chest_wall.beneath, view_to_breast))


def ptosis_sag_mm(primitive: Primitive, params) -> float:
    """How far ptosis (b0, b1 together; model units) lowers the apex (0, 0, a5) of `primitive`, mm."""
    apex = np.array([[0.0, 0.0, primitive.a5]])
    return float(to_mm(apex[0, 1] - ptosis(apex, *params)[0, 1]))


def held_weights(vertices: np.ndarray) -> np.ndarray:
    """(V, 3) weights holding the base cap (rim ring and centre) at its height, z = 0."""
    held = np.zeros_like(vertices)
    base = np.r_[np.arange(MESH_GRID[1]), len(vertices) - 1]
    held[base, 2] = BASE_WEIGHT / len(base)
    return held


def smoothness(vertices: np.ndarray, points: np.ndarray) -> float:
    """Laplacian weight λ of the FFD: tiny when data surround the whole model (a database breast),
    larger when the scanner missed part of it (model vertices with no point within UNSEEN_MM) so
    that the lattice carries the seen shape smoothly over the unseen part."""
    unseen = cKDTree(points).query(vertices[MESH_GRID[1]:-1], distance_upper_bound=UNSEEN_MM)[0] == np.inf
    return SMOOTHNESS[1] if unseen.mean() > UNSEEN_SHARE else SMOOTHNESS[0]


def model_mesh(sq: SuperquadricFit, grid: tuple[int, int] = MESH_GRID) -> tuple[np.ndarray, np.ndarray]:
    """Closed mesh (mm, breast frame) of the fitted primitive, deformed and posed."""
    return sq.model.mesh(*grid, closed=True)
