"""Synthetic breast databases V and S (docs/model.md §4, thesis §4.1, Table 4.1).

A database is a pure function of (name, seed, n_points). Each breast is a primitive
(eps = (1, 1)) deformed by its shape's Table 4.1 parameters, sampled on the (u, v) grid
so that all breasts correspond point to point. Stored as one `breastplan.database/1` NPZ
with points in mm; semi-axes and deformation parameters in model units.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
from scipy.special import ndtr, ndtri

from breastplan import ArtefactError, Primitive, load_npz, save_npz, to_model_units, write_ply
from breastplan.atomic import recover
from breastplan.units import breast_points_problem
from breastplan.deform.degree import GENERIC_SHAPE
from breastplan.deform.breast_model import BreastModel
from breastplan.deform.global_deformations import Deformation, changing

SCHEMA = "breastplan.database/1"
SHAPES: dict[str, Deformation] = {
    "generic": GENERIC_SHAPE,
    "shape1": Deformation(ptosis=(-0.2, 0.0), turn=(0.25, 0.0), top_shape=(0.5, -1.0, 0.0, -1.0),
                          flatten_side=(0.0, 0.01), turn_top=(0.0, 0.2)),
    "shape2": Deformation(ptosis=(-0.1, 0.0), turn=(0.0, 0.05), top_shape=(1.5, -7.0, 0.0, -5.0),
                          flatten_side=(0.0, 0.05), turn_top=(0.05, 0.05)),
    "shape3": Deformation(ptosis=(0.0, -0.05), turn=(0.3, 0.05), top_shape=(1.0, -0.5, 0.5, -0.5),
                          flatten_side=(0.1, 0.0), turn_top=(0.0, 0.3)),
    "shape4": Deformation(ptosis=(-0.1, -0.05), turn=(0.38, 0.0), top_shape=(1.0, -0.5, 0.5, -0.5),
                          turn_top=(0.41, 0.0)),
}
"""Table 4.1 as docs/model.md §4 reads it (N/A → 0)."""

LAYOUT = {  # name → (shapes, breasts per shape, test breasts per shape, semi-axis jitter)
    "V": (("generic",), 65, 15, 0.0),
    "S": (("shape1", "shape2", "shape3", "shape4"), 15, 3, 0.10),
}
VOLUME_MEAN_CC, VOLUME_SD_CC, VOLUME_RANGE_CC = 452.0, 120.0, (150.0, 1200.0)

_SPEC = {
    "names": ("U", ("n",)), "shape": ("U", ("n",)), "split": ("U", ("n",)),
    "semi_axes": ("f", ("n", 5)), "eps": ("f", ("n", 2)), "deformation": ("f", ("n", 12)),
    "volume_cc": ("f", ("n",)), "primitive_volume_cc": ("f", ("n",)),
    "points": ("f", ("n", "points", 3)), "grid": ("iu", (2,)),
}


@dataclass
class Database:
    """Breasts with corresponding points; per-breast arrays share the first axis."""

    name: str
    seed: int
    grid: tuple[int, int]          # (n_u, n_v) of the sampling grid
    names: np.ndarray              # (n,) str
    shape: np.ndarray              # (n,) str, a key of SHAPES
    split: np.ndarray              # (n,) "train" | "test"
    semi_axes: np.ndarray          # (n, 5) a1..a5, model units
    eps: np.ndarray                # (n, 2)
    deformation: np.ndarray        # (n, 12) Deformation.as_vector(), model units
    volume_cc: np.ndarray          # (n,) volume of the (shape-deformed) breast, closed mesh
    primitive_volume_cc: np.ndarray  # (n,) closed-form volume of its primitive
    points: np.ndarray             # (n, n_u·n_v, 3) mm, breast frame

    def __len__(self) -> int:
        return len(self.names)

    def primitive(self, i: int) -> Primitive:
        return Primitive.from_array(np.concatenate([self.semi_axes[i], self.eps[i]]))

    def points_mu(self, i: int) -> np.ndarray:
        return to_model_units(self.points[i])

    def changer(self, i: int, kind: str) -> Callable[[object], np.ndarray]:
        """params ↦ breast i (model units) with its `kind` parameters changed by params
        (`global_deformations.changing`: the change acts at the kind's place in the chain)."""
        prim = self.primitive(i)
        return changing(kind, prim.sample(*self.grid), Deformation.from_vector(self.deformation[i]), prim)

    def index(self, name: str) -> int:
        hits = np.flatnonzero(self.names == name)
        if not len(hits):
            raise KeyError(f"no breast named '{name}' in database {self.name}")
        return int(hits[0])

    def arrays(self) -> dict[str, np.ndarray]:
        return {k: np.asarray(getattr(self, k)) for k in _SPEC}

    def subset(self, indices) -> "Database":
        """The breasts at `indices`, in that order."""
        arrays = {k: (v if k == "grid" else v[indices]) for k, v in self.arrays().items()}
        return Database.from_arrays(arrays, {"name": self.name, "seed": self.seed})

    def save(self, path: str | Path) -> Path:
        meta = {"name": self.name, "seed": self.seed}
        return save_npz(path, SCHEMA, self.arrays(), meta=meta)

    @classmethod
    def from_arrays(cls, arrays, meta: dict) -> "Database":
        return cls(name=str(meta.get("name", "?")), seed=int(meta.get("seed", -1)),
                   grid=tuple(int(g) for g in arrays["grid"]),
                   **{k: arrays[k] for k in _SPEC if k != "grid"})

    @classmethod
    def load(cls, path: str | Path) -> "Database":
        try:
            recover(Path(path).parent)                # a `synth --ply` write killed after its commit point
        except OSError as exc:
            raise ArtefactError(path, f"was left by an interrupted write that cannot be completed here "
                                      f"({exc.strerror or exc}); run synth again") from None
        art = load_npz(path, SCHEMA, _SPEC, {"name": str, "seed": int})
        problem = _problem(art)
        if problem:
            raise ArtefactError(path, problem)
        return cls.from_arrays(art, art.meta)

    def write_plys(self, folder: str | Path, progress=None, stage=Path) -> list[Path]:
        """One PLY per breast (points in mm, breast frame) named after the breast; `stage(path)`
        gives the path to write each to (an `atomic_set`'s, to write them with others all or nothing)."""
        out = []
        for i, name in enumerate(self.names):
            out.append(Path(folder) / f"{name}.ply")
            write_ply(stage(out[-1]), self.points[i], comments=[f"breastplan database {self.name} breast {name}",
                                                                self.primitive(i).comment()])
            if progress:
                progress()
        return out


def grid_for(n_points: int) -> tuple[int, int]:
    """The square (u, v) grid of n_points (a square number ≥ 9)."""
    side = int(round(np.sqrt(n_points)))
    if side * side != n_points or side < 3:
        raise ValueError(f"the number of points must be a square number of at least 9 "
                         f"(a √n × √n (u, v) grid, e.g. 10000), got {n_points}")
    return side, side


def draw_volumes(rng: np.random.Generator, n: int) -> np.ndarray:
    """n volumes (cc) from the truncated normal of docs/model.md §4, stratified (one per n-quantile bin).

    Stratification keeps each database's mean and sd close to the law for any seed.
    """
    lo, hi = (ndtr((v - VOLUME_MEAN_CC) / VOLUME_SD_CC) for v in VOLUME_RANGE_CC)
    q = (rng.permutation(n) + rng.uniform(size=n)) / n
    return VOLUME_MEAN_CC + VOLUME_SD_CC * ndtri(lo + q * (hi - lo))  # truncated-normal quantiles


def _problem(art) -> str | None:
    """Why a database's arrays cannot be breasts sampled on their grid, or None."""
    if not len(art["names"]):
        return "holds no breasts"
    if art["grid"][0] < 2 or art["grid"][1] < 3 or art["points"].shape[1] != int(np.prod(art["grid"])):
        return "has a point count that does not match its sampling grid"
    for i, name in enumerate(art["names"]):
        try:
            problem = Primitive.from_array(np.r_[art["semi_axes"][i], art["eps"][i]]).breast_problem()
        except ValueError as exc:
            return f"has a breast {name} whose {exc}"
        if problem:
            return f"has a breast {name} whose primitive {problem}"
        problem = breast_points_problem(art["points"][i])
        if problem:
            return f"has a breast {name} that {problem}"
        if not art["volume_cc"][i] > 0:
            return f"has a breast {name} whose volume is not positive"
    return None


def build_database(name: str, seed: int = 0, n_points: int = 10_000) -> Database:
    """Database "V" (65 breasts, 50/15) or "S" (4 shapes × 15, 48/12), docs/model.md §4."""
    if name not in LAYOUT:
        raise ValueError(f"unknown database '{name}'; choose V or S")
    shapes, per_shape, test_per_shape, jitter = LAYOUT[name]
    n_u, n_v = grid_for(n_points)
    rng = np.random.default_rng([seed, ord(name)])
    labels, shape_of, split, prims, points, volumes = [], [], [], [], [], []
    for shape in shapes:
        drawn = draw_volumes(rng, per_shape)
        test = set(rng.choice(per_shape, size=test_per_shape, replace=False).tolist())
        deformation = SHAPES[shape]
        for k, vol in enumerate(drawn):
            prim = Primitive(*(10.0 * rng.uniform(1 - jitter, 1 + jitter, size=5)))
            # Top-shape and flatten-side are scale-invariant and the rest are shears, so scaling
            # all semi-axes by s scales the breast volume by s³: scale to the drawn volume.
            prim = Primitive(*(prim.as_array()[:5] * (vol / BreastModel(prim, deformation).volume_cc()) ** (1 / 3)))
            model = BreastModel(prim, deformation)
            labels.append(f"{name}-{k:03d}" if len(shapes) == 1 else f"{name}-{shape}-{k:02d}")
            shape_of.append(shape)
            split.append("test" if k in test else "train")
            prims.append(prim)
            points.append(model.sample(n_u, n_v))
            volumes.append(model.volume_cc())
    return Database(
        name=name, seed=seed, grid=(n_u, n_v), names=np.array(labels), shape=np.array(shape_of),
        split=np.array(split), semi_axes=np.array([p.as_array()[:5] for p in prims]),
        eps=np.array([[p.eps1, p.eps2] for p in prims]),
        deformation=np.array([SHAPES[s].as_vector() for s in shape_of]),
        volume_cc=np.array(volumes), primitive_volume_cc=np.array([p.volume_cc for p in prims]),
        points=np.stack(points),
    )
