"""Feature sets of the deformation-parameter regressions (thesis Table 4.3).

Each kind moves one coordinate as a function of another ("moved" and "driver" axes): ptosis
moves y by z, turn moves x by z (the thesis: "use x where ptosis uses y"), top-shape moves z on
the upper pole, so its driver is y. With M the moved axis and D the driver:

    REF = DD, v0, M0, Mdisplacement     FS1 = DD, v0, D0     FS2 = DD, v0, D0, M0
    FS3 = DD, v0, M0                    FS4 = DD, v0         FS5 = DD, v0, d0, m0

capitals are the vectors of every point's coordinate, lower case the mean point's. Top-shape's
FS5 adds the upper-pole profile (`deform.descriptors.upper_profile`). DD is the discrete degree
(thesis) or the continuous one (docs/model.md §5). Vector blocks are scaled to [0, 1] and reduced by
PCA fitted on the training split only (`VectorReducer`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sklearn.decomposition import PCA

from breastplan.deform.descriptors import AXES, breast_scalars, scalar_names

from .datasets import Dataset
from .studies import FEATURE_SETS

VECTOR_BLOCKS = ("M0", "D0", "Mdisplacement")
MAX_COMPONENTS = 10


@dataclass
class ExampleFeatures:
    """Scalar columns (n, s) and raw vector blocks (n, V) of a dataset's examples."""

    scalars: np.ndarray
    vectors: np.ndarray | None
    names: list[str]


def breast_table(database, kind: str) -> np.ndarray:
    """FS5's per-breast scalars (v0, d0, m0[, profile]) of every breast of a database."""
    return np.array([breast_scalars(p, kind, "FS5") for p in database.points])


def example_features(ds: Dataset, feature_set: str, degree: str = "discrete",
                     table: np.ndarray | None = None) -> ExampleFeatures:
    """Features of every example of `ds`; `degree` "discrete" (thesis) or "continuous";
    `table` is `breast_table(ds.database, kind)` when the caller has it already."""
    kind = ds.condition.kind
    moved, driver = AXES[kind]
    table = breast_table(ds.database, kind) if table is None else table
    names = scalar_names(feature_set, kind)
    dd = ds.degree if degree == "discrete" else ds.degree_continuous
    scalars = np.column_stack([dd, table[ds.breast, : len(names) - 1]])
    blocks = []
    for block in FEATURE_SETS[feature_set]:
        if block == "M0":
            blocks.append(ds.database.points[ds.breast, :, moved])
        elif block == "D0":
            blocks.append(ds.database.points[ds.breast, :, driver])
        elif block == "Mdisplacement":
            blocks.append(np.array([ds.deformed_points(k)[:, moved] for k in range(len(ds))])
                          - ds.database.points[ds.breast, :, moved])
    vectors = np.concatenate(blocks, axis=1) if blocks else None
    return ExampleFeatures(scalars, vectors, names)


class VectorReducer:
    """[0, 1] scaling and PCA of vector blocks, fitted on training rows only."""

    def __init__(self, n_components: int = MAX_COMPONENTS):
        self.n_components = n_components

    def fit(self, vectors: np.ndarray) -> "VectorReducer":
        self.low = vectors.min(axis=0)
        self.span = np.where(np.ptp(vectors, axis=0) > 0, np.ptp(vectors, axis=0), 1.0)
        k = min(self.n_components, len(vectors) - 1)
        self.pca = PCA(n_components=k, svd_solver="randomized", random_state=0).fit(self._scaled(vectors))
        return self

    def _scaled(self, vectors: np.ndarray) -> np.ndarray:
        return (vectors - self.low) / self.span

    def transform(self, vectors: np.ndarray, k: int) -> np.ndarray:
        """The first k principal scores."""
        return self.pca.transform(self._scaled(vectors))[:, :k]

    def explained(self, k: int) -> float:
        """Share (%) of the training variance the first k components explain."""
        return float(100 * self.pca.explained_variance_ratio_[:k].sum())
