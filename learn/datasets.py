"""Deformation datasets: database × condition × #dd (docs/model.md §4–§5, thesis §4.1.1).

Every breast of the database deformed by every row of the condition, with its extent and
its degree (discrete and continuous). A row changes the breast's own parameters of its kind
(`Database.changer`), so a top-shape row does not stack a second top-shape on the breast's.
Deformed points are recomputed on demand from the embedded database (a few ms per breast,
faster than storing and reading them).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from breastplan import ArtefactError, load_npz, save_npz, to_mm
from breastplan.deform.conditions import Condition, find_condition
from breastplan.deform.degree import (condition_extent, continuous_degree, discrete_degree,
                                      reference_extents)

from .databases import _SPEC as _DB_SPEC
from .databases import Database

SCHEMA = "breastplan.dataset/1"
_SPEC = {
    "breast": ("iu", ("examples",)), "row": ("iu", ("examples",)),
    "params": ("f", ("examples", "n_params")), "extent": ("f", ("examples",)),
    "degree": ("iu", ("examples",)), "degree_continuous": ("f", ("examples",)),
    "rows": ("f", ("dd", "n_params")), "reference_extents": ("f", ("dd",)),
    **{f"db_{k}": v for k, v in _DB_SPEC.items()},
}


@dataclass
class Dataset:
    """Examples (breast i, row j) of one condition; `breast` indexes `database`."""

    condition: Condition
    dd: int
    database: Database
    rows: np.ndarray                # (dd, n_params) model units
    reference_extents: np.ndarray   # (dd,) E_0j of P00
    breast: np.ndarray              # (n_examples,) database index
    row: np.ndarray                 # (n_examples,) row index 0..dd-1
    params: np.ndarray              # (n_examples, n_params) = rows[row]
    extent: np.ndarray              # (n_examples,) extent (signed for top-shape)
    degree: np.ndarray              # (n_examples,) discrete degree 1..dd
    degree_continuous: np.ndarray   # (n_examples,) continuous degree, may lie outside [1, dd]

    def __len__(self) -> int:
        return len(self.breast)

    @property
    def position(self) -> np.ndarray:
        """(n_examples,) position t = row / (#dd − 1) of each example on the condition's line."""
        return self.row / (self.dd - 1)

    @property
    def split(self) -> np.ndarray:
        """(n_examples,) "train" | "test", the split of each example's breast."""
        return self.database.split[self.breast]

    def original_points(self, k: int) -> np.ndarray:
        """Example k's breast before deformation, mm."""
        return self.database.points[self.breast[k]]

    @cached_property
    def _changers(self) -> list:
        return [self.database.changer(i, self.condition.kind) for i in range(len(self.database))]

    def changer(self, k: int):
        """params ↦ example k's breast (model units) with the condition's kind changed by params
        (`Database.changer`, built once per breast)."""
        return self._changers[int(self.breast[k])]

    def deformed_points(self, k: int, params=None) -> np.ndarray:
        """Example k's breast, mm, deformed by `params` (default: its row's), recomputed from the
        database; the condition changes the breast's own parameters (`Database.changer`)."""
        return to_mm(self.changer(k)(self.params[k] if params is None else params))

    def save(self, path: str | Path) -> Path:
        arrays = {k: getattr(self, k) for k in ("rows", "reference_extents", "breast", "row", "params",
                                                 "extent", "degree", "degree_continuous")}
        arrays.update({f"db_{k}": v for k, v in self.database.arrays().items()})
        meta = {"condition": self.condition.name, "kind": self.condition.kind, "dd": self.dd,
                "database": self.database.name, "seed": self.database.seed}
        return save_npz(path, SCHEMA, arrays, meta=meta)

    @classmethod
    def load(cls, path: str | Path) -> "Dataset":
        art = load_npz(path, SCHEMA, _SPEC, {"condition": str, "kind": str, "dd": int, "database": str, "seed": int})
        try:
            condition = find_condition(art.meta["condition"])
            dd = int(art.meta["dd"])
        except (KeyError, ValueError, TypeError):
            raise ArtefactError(path, "names no known condition and number of degrees") from None
        if art["rows"].shape != (dd, len(condition.param_names)):
            raise ArtefactError(path, f"has rows of shape {art['rows'].shape}, not {dd} rows of {condition.kind}")
        n_breasts = len(art["db_names"])
        if art["breast"].size and (art["breast"].max() >= n_breasts or art["row"].max() >= dd):
            raise ArtefactError(path, "has examples that point outside its database or rows")
        db = Database.from_arrays({k[3:]: v for k, v in art.items() if k.startswith("db_")},
                                  {"name": art.meta.get("database"), "seed": art.meta.get("seed", -1)})
        return cls(condition=condition, dd=dd, database=db,
                   **{k: art[k] for k in ("rows", "reference_extents", "breast", "row", "params",
                                          "extent", "degree", "degree_continuous")})


def build_dataset(database: Database, condition: Condition | str, dd: int, progress=None) -> Dataset:
    """Deform every breast by every row; extents and degrees per example (docs/model.md §5)."""
    cond = find_condition(condition) if isinstance(condition, str) else condition
    rows = cond.rows(dd)
    ref = reference_extents(cond, dd, *database.grid)
    n = len(database)
    extents = np.empty((n, dd))
    for i in range(n):
        original, prim, change = database.points_mu(i), database.primitive(i), database.changer(i, cond.kind)
        for j, row in enumerate(rows):
            extents[i, j] = condition_extent(cond, original, change(row), prim)
        if progress:
            progress()
    breast, row = (a.ravel() for a in np.meshgrid(np.arange(n), np.arange(dd), indexing="ij"))
    ext = extents.ravel()
    return Dataset(condition=cond, dd=dd, database=database, rows=rows, reference_extents=ref,
                   breast=breast, row=row, params=rows[row], extent=ext,
                   degree=discrete_degree(ext, ref), degree_continuous=continuous_degree(ext, ref))
