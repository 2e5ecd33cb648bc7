"""Named operations on a point cloud (N, 3), mm, any frame: clusters, voxel downsampling, radius outliers,
normals and what a viewer sees (numpy and scipy's k-d tree). Clusters and outliers depend on the points, not on
their order; a normal's neighbours tied at the last place are taken in the points' order, so ingest gives them in
a canonical one (voxel centroids in grid order)."""
from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from breastplan.voxels import voxel_centroids

NO_NORMAL = np.array([0.0, 0.0, 1.0])
"""The normal of a point with fewer than 3 neighbours (before it is turned towards the viewer)."""


def dbscan(points: np.ndarray, eps: float, min_points: int) -> np.ndarray:
    """DBSCAN cluster labels (−1 = noise): a point is a core point with at least `min_points` points
    (itself included) closer than `eps`; clusters are the connected core points, numbered by their
    first point, and a border point joins the cluster of its first core neighbour."""
    n = len(points)
    pairs = _pairs(points, eps)
    core = np.bincount(pairs.ravel(), minlength=n) + 1 >= min_points
    labels = np.full(n, -1, np.int64)
    linked = pairs[core[pairs[:, 0]] & core[pairs[:, 1]]]
    _, comp = connected_components(coo_matrix((np.ones(len(linked)), (linked[:, 0], linked[:, 1])), (n, n)),
                                   directed=False)
    comps, first = np.unique(comp[core], return_index=True)         # each component's first core point
    rank = np.empty(comp.max() + 1, np.int64)
    rank[comps[np.argsort(first)]] = np.arange(len(first))
    labels[core] = rank[comp[core]]
    both = np.vstack([pairs, pairs[:, ::-1]])                           # (border, core neighbour)
    border = both[~core[both[:, 0]] & core[both[:, 1]]]
    border = border[np.lexsort((border[:, 1], border[:, 0]))]
    first = np.unique(border[:, 0], return_index=True)[1]
    labels[border[first, 0]] = labels[border[first, 1]]
    return labels


def voxel_downsample(points: np.ndarray, size: float) -> np.ndarray:
    """(M, 3) the centroids of the occupied voxels of `size` (mm), in grid order, on a grid anchored half a
    voxel below the points' least corner (as open3d's voxel_down_sample anchors it)."""
    return _voxels(points, size)[0]


def voxel_colours(points: np.ndarray, size: float, rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`voxel_downsample`'s centroids, and the mean of each voxel's points' colours `rgb` ((N, 3) uint8)."""
    centres, which = _voxels(points, size)
    counts = np.bincount(which, minlength=len(centres))[:, None]
    means = np.stack([np.bincount(which, rgb[:, k].astype(float), len(centres)) for k in range(3)], 1) / counts
    return centres, np.rint(means).astype(np.uint8)


def _voxels(points: np.ndarray, size: float) -> tuple[np.ndarray, np.ndarray]:
    anchor = points.min(axis=0) - 0.5 * size
    centres, which = voxel_centroids(points - anchor, size)
    return centres + anchor, which


def radius_inliers(points: np.ndarray, radius: float, others: int) -> np.ndarray:
    """(N,) bool: the points with at least `others` other points within `radius`."""
    return cKDTree(points).query_ball_point(points, radius, return_length=True) - 1 >= others


def normals_towards(points: np.ndarray, viewer: np.ndarray, radius: float, most: int) -> np.ndarray:
    """(N, 3) unit normals: the least-spread direction of each point's `most` nearest points within
    `radius` (itself included; NO_NORMAL below 3), turned to face `viewer` (same frame)."""
    dist, idx = cKDTree(points).query(points, k=most, distance_upper_bound=radius)
    near = np.isfinite(dist)
    count = near.sum(axis=1)
    nbrs = points[np.where(near, idx, 0)]                               # (N, most, 3); misses masked below
    w = near[..., None]
    mean = (nbrs * w).sum(axis=1) / count[:, None]
    d = (nbrs - mean[:, None]) * w
    cov = np.einsum("nki,nkj->nij", d, d)
    normals = np.linalg.eigh(cov)[1][:, :, 0]                           # eigenvalues ascending
    normals[count < 3] = NO_NORMAL
    flip = np.einsum("ij,ij->i", normals, viewer - points) < 0
    normals[flip] *= -1
    return normals


SEEN_CELL_MM = 4.0
SEEN_DEPTH_MM = 15.0
"""`seen_from`: the viewer's rays are binned in cells this wide where her body is (mm); a point is seen when it
lies within SEEN_DEPTH_MM of the nearest point of its cell (a surface as steep as 75° stays whole)."""


def seen_from(points: np.ndarray, viewer: np.ndarray) -> np.ndarray:
    """(N,) bool: the points a viewer at `viewer` sees, not hidden behind others, for points in a frame whose z
    runs away from the viewer (a z-buffer over the directions from it, SEEN_CELL_MM cells at the points' median
    distance): the front of a scan that wraps round her body, without its back."""
    d = np.asarray(points, float) - viewer
    depth = d[:, 2]
    cell = np.floor(d[:, :2] / depth[:, None] * (np.median(depth) / SEEN_CELL_MM)).astype(np.int64)
    cell -= cell.min(axis=0)
    key = np.unique(cell[:, 0] * (cell[:, 1].max() + 1) + cell[:, 1], return_inverse=True)[1]
    nearest = np.full(key.max() + 1, np.inf)
    np.minimum.at(nearest, key, depth)
    return depth <= nearest[key] + SEEN_DEPTH_MM


def _pairs(points: np.ndarray, eps: float) -> np.ndarray:
    """(P, 2) index pairs i < j closer than `eps`."""
    pairs = cKDTree(points).query_pairs(eps, output_type="ndarray")
    d = np.linalg.norm(points[pairs[:, 0]] - points[pairs[:, 1]], axis=1)
    return pairs[d < eps].astype(np.int64)
