"""The point-cloud operations ingest runs (breastplan.ingest.cloud, ingest.depth.to_points) against open3d's,
a second implementation of each, on a MakeHuman body's depth image; and each is independent of the points' order."""
from __future__ import annotations

import numpy as np
import pytest

from breastplan.ingest.cloud import dbscan, normals_towards, radius_inliers, voxel_downsample
from breastplan.ingest.depth import depth_range, fuse, to_points
from breastplan.scenes.makehuman import BodyOptions
from breastplan.scenes.realistic import CameraOptions, make_body_scene
from breastplan.voxels import voxel_centroids

o3d = pytest.importorskip("open3d")


@pytest.fixture(scope="module")
def body():
    """A fused depth image of a heavy, arms-down MakeHuman body (640×400, a wall behind her), its intrinsics
    and its points within the patient's slab (camera frame, mm)."""
    scene = make_body_scene(BodyOptions(pose="arms-down", cup=0.8, weight=0.8),
                            CameraOptions(resolution="640x400", pitch_deg=6.0, wall_mm=400.0))
    image = fuse(scene.frames(3, seed=4))
    near, far = depth_range(image)
    return image, scene.camera.K, to_points(image, scene.camera.K, near, far)


def _cloud(points):
    return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))


def test_back_projection_is_open3ds(body):
    image, K, _ = body
    near, far = depth_range(image)
    masked = np.where((image >= near) & (image <= far), image, 0).astype(np.float32)
    h, w = image.shape
    theirs = np.asarray(o3d.geometry.PointCloud.create_from_depth_image(
        o3d.geometry.Image(masked), o3d.camera.PinholeCameraIntrinsic(w, h, K[0, 0], K[1, 1], K[0, 2], K[1, 2]),
        depth_scale=1.0, depth_trunc=1e9).points)
    ours = to_points(image, K, near, far)
    assert ours.shape == theirs.shape and len(ours) > 10_000
    assert np.abs(ours - theirs).max() < 1e-3


def _partition(labels):
    """Clusters as sets of point indices (noise left out), whatever their numbering."""
    return {frozenset(np.flatnonzero(labels == k)) for k in np.unique(labels[labels >= 0])}


def test_dbscan_finds_open3ds_clusters_and_keeps_them_when_the_points_are_reordered(body):
    coarse = voxel_centroids(body[2], 10.0)[0]
    ours = dbscan(coarse, 25.0, 4)
    theirs = np.asarray(_cloud(coarse).cluster_dbscan(25.0, 4))
    assert len(np.unique(ours[ours >= 0])) >= 1
    np.testing.assert_array_equal(ours < 0, theirs < 0)
    assert _partition(ours) == _partition(theirs)
    order = np.random.default_rng(0).permutation(len(coarse))
    moved = np.empty_like(ours)
    moved[order] = dbscan(coarse[order], 25.0, 4)
    assert _partition(moved) == _partition(ours)


def test_a_point_without_enough_neighbours_is_dropped_as_open3d_drops_it_in_any_order(body):
    points = body[2][::3]
    rng = np.random.default_rng(1)
    strays = points[rng.choice(len(points), 200, replace=False)] + rng.normal(0.0, 30.0, (200, 3))
    cloud = np.vstack([points, strays])
    kept = radius_inliers(cloud, 5.0, 4)
    _, theirs = _cloud(cloud).remove_radius_outlier(nb_points=4, radius=5.0)
    np.testing.assert_array_equal(np.flatnonzero(kept), np.sort(theirs))
    assert (~kept[len(points):]).mean() > 0.9                  # the strays go
    order = np.random.default_rng(3).permutation(len(cloud))
    np.testing.assert_array_equal(radius_inliers(cloud[order], 5.0, 4), kept[order])


def test_normals_are_open3ds_and_face_the_camera(body):
    points = voxel_centroids(body[2], 2.0)[0]
    ours = normals_towards(points, np.zeros(3), 6.0, 16)
    cloud = _cloud(points)
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=6.0, max_nn=16))
    cloud.orient_normals_towards_camera_location(np.zeros(3))
    theirs = np.asarray(cloud.normals)
    np.testing.assert_allclose(np.linalg.norm(ours, axis=1), 1.0, atol=1e-9)
    agree = np.einsum("ij,ij->i", ours, theirs)
    facing = np.einsum("ij,ij->i", ours, -points / np.linalg.norm(points, axis=1, keepdims=True))
    edge_on = np.abs(facing) < 1e-6                          # seen edge-on: either way faces the camera
    assert np.quantile(np.abs(agree), 0.001) > 0.999         # the same line (open3d's solver is approximate)
    assert (agree[~edge_on] > 0.999).mean() > 0.999 and (facing > -1e-6).all()


def test_voxel_downsampling_keeps_open3ds_voxels_in_any_order(body):
    points = body[2]
    ours = voxel_downsample(points, 2.0)
    theirs = np.asarray(_cloud(points).voxel_down_sample(2.0).points)
    assert ours.shape == theirs.shape and len(ours) > 1000
    from scipy.spatial import cKDTree

    gap, match = cKDTree(theirs).query(ours)
    assert gap.max() < 1e-6 and len(np.unique(match)) == len(ours)      # the same centroids, one for one
    order = np.random.default_rng(4).permutation(len(points))
    np.testing.assert_allclose(voxel_downsample(points[order], 2.0), ours, atol=1e-9)
