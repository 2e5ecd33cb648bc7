"""The ingest pipeline: depth frames or a scan file → the breast of one side in the breast frame.

The body, once for every side (`BodyScan`): fusion → depth to points → background removal
(depth range, the nearest large DBSCAN cluster of coarse voxels) → trunk (head, neck and arms cut
off) → a wall behind her, if one stands there (`ingest.background`: the plumb the plan's up axis
takes) → chest wall (robust height field, mounds excluded) → mounds. Then each side (`isolate_side`):
the breasts among the mounds (a pair placed as breasts are), the requested side's → its chest wall
→ breast crop → breast frame and nipple → outlier removal → voxel downsampling → outward normals
→ breast frame. Every step is timed.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial import cKDTree
from breastplan import BadInputError, transform_points
from breastplan.body import Body
from breastplan.chest_wall import ChestWall
from breastplan.clock import Clock
from breastplan.options import IngestOptions
from breastplan.point_order import canonical_order
from breastplan.voxels import voxel_centroids

from . import breast as B
from .background import plumb_wall
from .chest_wall import fit_chest_wall
from .cloud import dbscan, normals_towards, radius_inliers, seen_from, voxel_downsample
from .depth import colours_at, depth_range, fuse, to_points
from .files import ScanCloud
from .recording import DepthFrames
from .trunk import Trunk, find_trunk

WRAPPED_HIDDEN = 0.08
"""A scan file of which more than this share of the points is hidden from a viewer in front of her wraps round
her body (a 180° scan hides 12–14 % of its points, a closed one about half; a camera's view, 1–4 %: what lies
behind her)."""
VIEWER_MM = 2000.0
"""A scan file's viewer stands this far in front of its points' mean (`_viewer`), along the viewing axis."""
UP_TRIED = ("+y", "+z", "+x")
"""The axes tried in turn as a scan file's up when it is not given (its sense from her head; +y first, the
convention of most scanners' files)."""
UP_SEARCH_MM = 5.0
"""Voxel size of the cloud the up axes are tried on."""
RELIEF_MM = 130.0
"""Her breasts lie within this far of her midline; her trunk's sides, which curve away, lie farther."""
BEHIND_STRIDE = 4
"""Every this-many-th pixel row and column beyond the depth slab is looked at for a wall behind her
(a wall's 20 mm voxels, 1–2 m away, span more pixels than that)."""
COARSE_MM = 10.0
"""Voxel size of the coarse cloud used for background removal, chest wall and mounds."""
MIN_BREAST_POINTS = 500
REFINE_VIEW, REFINED_DEG = 4, 0.1
"""A scan file's viewing axis is refined at most this many times on the trunk it shows, until it turns
by under this angle (degrees)."""
BODY_VOXELS = 1000
"""Clusters of this many coarse voxels (0.1 m² of surface) or more may be the body."""


@dataclass
class Ingested:
    """The breast of one side, and how it was found."""

    points: np.ndarray               # (N, 3) mm, breast frame
    normals: np.ndarray              # (N, 3) outward unit normals, breast frame
    input_to_breast: np.ndarray      # (4, 4) input (camera) frame → breast frame, mm
    side: str
    nipple_camera: np.ndarray        # (3,) mm, input frame
    nipple_found: str                # how: "areola" (centre of the raised disc), "apex" or "given"
    chest_wall: ChestWall            # in the viewing frame
    input_to_view: np.ndarray        # (4, 4) input frame → viewing frame
    crop: dict                       # mound centre, radius, roi, thresholds
    torso_camera: np.ndarray         # (M, 3) the background-free torso, input frame
    plumb_camera: np.ndarray | None = None   # (3,) a wall's normal behind her, input frame (ingest.background)
    timings_ms: dict = field(default_factory=dict)
    torso_rgb: np.ndarray | None = None      # (M, 3) uint8 her skin's colour at each torso point; None: not recorded

    @property
    def body(self) -> Body:
        return Body(self.torso_camera, self.input_to_view, self.plumb_camera, self.torso_rgb)


@dataclass(frozen=True)
class BodyInView:
    """The nearest body in view (viewing frame, mm): its points, coarse voxels' centroids, each
    point's voxel, and its trunk."""

    points: np.ndarray
    voxels: np.ndarray
    which: np.ndarray
    trunk: Trunk


def find_body(points: np.ndarray) -> BodyInView:
    """The nearest body among viewing-frame points (`body_cluster`) and its trunk (`find_trunk`)."""
    body, voxels, which = body_cluster(points)
    return BodyInView(body, voxels, which, find_trunk(body))


@dataclass(frozen=True)
class BodyScan:
    """What every side's breast is isolated from: the body in view and its chest (viewing frame, mm)."""

    input_to_view: np.ndarray        # (4, 4) input frame → viewing frame
    viewer: np.ndarray               # (3,) where the camera is
    trunk: Trunk
    torso: np.ndarray                # (M, 3) the trunk's points
    coarse: np.ndarray               # (K, 3) the chest's coarse voxels' centroids
    wall: ChestWall                  # the chest wall fitted on them, mounds excluded
    mounds: tuple[B.Mound, ...]      # largest volume first
    plumb: np.ndarray | None         # (3,) a wall's normal behind her, or None
    timings_ms: dict                 # the steps timed until now (the source's read included)
    torso_rgb: np.ndarray | None = None   # (M, 3) uint8 the colour seen at each torso point; None: not recorded
    up: str | None = None            # a scan file's superior axis as read (UP_AXES); None: a camera's view
    up_found: str = "given"          # how that axis was known: "given", "her head" (seen above her chest) or
                                     # "taken" (her head seen along no axis: UP_TRIED's first that shows a trunk)


def ingest_frames(frames: DepthFrames, options: IngestOptions, clock: Clock | None = None) -> Ingested:
    """Depth frames (camera = viewing frame) → the breast of `options.side`."""
    clock = clock or Clock()
    return isolate_side(frames_body(frames, clock), options, clock)


def frames_body(frames: DepthFrames, clock: Clock) -> BodyScan:
    """Depth frames (camera = viewing frame) → the body in view."""
    with clock("fuse"):
        image = fuse(frames.depth)
    with clock("depth to points"):
        near, far = depth_range(image)
        points = to_points(image, frames.K, near, far)
        S = BEHIND_STRIDE                                      # beyond the slab: what stands behind her
        beyond = to_points(image[::S, ::S], np.diag([1.0 / S, 1.0 / S, 1.0]) @ frames.K, far, np.inf)
    body = isolate_body(points, np.eye(4), clock, viewer=np.zeros(3), beyond=beyond)
    if frames.colour is None:
        return body
    return replace(body, torso_rgb=colours_at(body.torso, frames.K, frames.colour))   # viewing frame = camera


def ingest_cloud(cloud: ScanCloud, options: IngestOptions, clock: Clock | None = None) -> Ingested:
    """A scan file's points → the breast of `options.side`; the viewing direction comes from the torso's shape."""
    clock = clock or Clock()
    return isolate_side(cloud_body(cloud, options.up, clock), options, clock)


def cloud_body(cloud: ScanCloud, up: str, clock: Clock) -> BodyScan:
    """A scan file's points, `up` its superior axis → the body in view: of a scan that wraps round her (more than
    WRAPPED_HIDDEN of its points hidden from a viewer in front of her), the points that viewer sees (`seen_from`);
    of a frontal scan, all (the wall behind her, which gives her vertical, stays whole). The points
    are put in a canonical order first (sorted by their coordinates): what is found depends on her surface, not
    on the order a file lists its points in."""
    with clock("viewing frame"):
        order = canonical_order(cloud.points)
        ordered = cloud.points[order]
        how = "given"
        if cloud.frame_hint == "camera-opencv":
            view, found, up = np.eye(4), None, None
        elif up == "auto":
            view, found, up, how = upright_frame(ordered)
        else:
            view, found = viewing_frame(ordered, up)
        points = transform_points(view, ordered)
        viewer = _viewer(points)
    with clock("seen from the front"):
        seen = seen_from(points, viewer)
        if 1.0 - seen.mean() > WRAPPED_HIDDEN:        # a scan that wraps round her: its front, as a camera sees it
            points, found = points[seen], None
    body = replace(isolate_body(points, view, clock, viewer=viewer, found=found, up=up), up=up, up_found=how)
    if cloud.colours is None:
        return body
    torso = transform_points(np.linalg.inv(body.input_to_view), body.torso)   # the file's own points, its frame
    return replace(body, torso_rgb=cloud.colours[order][cKDTree(ordered).query(torso)[1]])


def upright_frame(points: np.ndarray) -> tuple[np.ndarray, BodyInView, str, str]:
    """`viewing_frame` of a scan file whose up axis is not given, that axis, and how it was found: the first of
    UP_TRIED along which her head is seen above her chest, or the opposite of one along which it is seen below
    ("her head"); where her head is seen along none (a torso cut below her neck), the first along which a trunk
    is seen ("taken"). The first axis is tried on all the points (its frame kept when her head stands above
    along it), the others on the centroids of UP_SEARCH_MM voxels."""
    sparse, _ = voxel_centroids(points, UP_SEARCH_MM)
    taken = None
    for up in UP_TRIED:
        try:
            frame, found = viewing_frame(points if up == UP_TRIED[0] else sparse, up)
        except BadInputError:
            continue
        head = found.trunk.head
        if head == "above" and up == UP_TRIED[0]:
            return frame, found, up, "her head"
        if head is not None:
            up = up if head == "above" else "-" + up[1]
            return *viewing_frame(points, up), up, "her head"
        taken = taken or up
    if taken is None:
        raise BadInputError(None, "shows no trunk along any of its axes: nothing in view is as wide as a chest and "
                                  "curved as one (a wall or a board is flat)")
    return *viewing_frame(points, taken), taken, "taken"


def viewing_frame(points: np.ndarray, up: str) -> tuple[np.ndarray, BodyInView]:
    """(4, 4) input → viewing frame for a frontal scan, and the body found in it: z away from the viewer
    along the thinnest axis of the body's trunk, y opposite to the input's `up` axis.

    The body is first found looking along the cloud's principal axes, thinnest first (a wall or floor
    in the file can make the depth its longest); of the two senses of an axis, the viewer's is the one
    from which the nearest body's trunk bulges towards it (a chest is convex across). The axis is then
    refined on that trunk alone, so that whatever else the file holds does not tilt the frame."""
    along_up = None
    for axis in _principal_axes(points):
        try:
            facing = _facing(points, axis, up)
        except BadInputError as exc:    # the axis lies along `up`: the viewer cannot look along it
            along_up = exc
            continue
        if facing is not None:
            return _refined(points, *facing, up)
    raise along_up or BadInputError(None, "shows no trunk: nothing in view is as wide as a chest and curved as one (a "
                                          "wall or a board is flat)")


def _refined(points: np.ndarray, frame: np.ndarray, found: BodyInView, up: str) -> tuple[np.ndarray, BodyInView]:
    """The viewing frame turned, up to REFINE_VIEW times, to look along the thinnest axis of the trunk
    it shows (the same sense), until that axis moves by under REFINED_DEG."""
    for _ in range(REFINE_VIEW):
        trunk = transform_points(np.linalg.inv(frame), found.points[found.trunk.mask])
        axis = _principal_axes(trunk)[0]
        axis *= -np.sign(np.dot(axis, frame[2, :3]))        # anterior: opposite the frame's z
        if np.degrees(np.arccos(min(1.0, -np.dot(axis, frame[2, :3])))) < REFINED_DEG:
            break
        turned = _frame(axis, up)
        body = _body_or_none(transform_points(turned, points))
        if body is None:
            break
        frame, found = turned, body
    return frame, found


def _principal_axes(points: np.ndarray) -> np.ndarray:
    """(3, 3) unit principal axes of a cloud as rows, thinnest first."""
    return np.linalg.eigh(np.cov((points - points.mean(0)).T))[1].T


def _facing(points: np.ndarray, axis: np.ndarray, up: str) -> tuple[np.ndarray, BodyInView] | None:
    """The viewing frame looking along ±`axis` from which the nearest body's trunk, not flat (`_flat`), bulges most
    towards the viewer (a frontal scan's inside is hollow), or, when both senses see a body that wraps round (more than
    WRAPPED_HIDDEN of its points hidden: her front and her back are both convex), from which her chest stands out
    most (`_chest_relief`: breasts, not shoulder blades); and that body. None when neither sense shows a trunk."""
    frames = [_frame(sense * axis, up) for sense in (1.0, -1.0)]
    found = [_body_or_none(transform_points(T, points)) for T in frames]
    found = [None if body is None or _flat(body) else body for body in found]      # a wall seen from behind her
    seen = [None if body is None else seen_from(body.points, _viewer(body.points)) for body in found]
    wraps = all(s is not None and 1.0 - s.mean() > WRAPPED_HIDDEN for s in seen)
    score = ([_chest_relief(body, s) for body, s in zip(found, seen)] if wraps else
             [_trunk_bulge(body) for body in found])
    k = int(np.argmax(score))
    return None if score[k] == -np.inf else (frames[k], found[k])


FLAT_MM = 15.0
"""A trunk whose points lie within this of one plane (95th percentile) is a wall, not her: her chest curves across
by several centimetres. From behind a frontal scan with a wall, the nearest surface as wide as a chest is the wall."""


def _flat(body: BodyInView) -> bool:
    """Whether the trunk found is flat (FLAT_MM): a wall or a floor."""
    trunk = body.points[body.trunk.mask]
    centred = trunk - trunk.mean(0)
    normal = np.linalg.svd(centred[::max(1, len(centred) // 20000)], full_matrices=False)[2][2]
    return bool(np.percentile(np.abs(centred @ normal), 95) < FLAT_MM)


def _viewer(points: np.ndarray) -> np.ndarray:
    """(3,) where a scan file's viewer stands, in the viewing frame of its `points` (VIEWER_MM in front of them)."""
    return points.mean(0) - [0.0, 0.0, VIEWER_MM]


def _chest_relief(body: BodyInView, seen: np.ndarray) -> float:
    """How far (mm) the chest a viewer sees of a body's trunk (below her shoulders, within RELIEF_MM of her midline)
    stands out towards it from a smooth surface fitted to it (quartic down her body, quadratic across), at its 99th
    percentile: her breasts on her front, her shoulder blades on her back (viewing frame)."""
    P = body.points
    below_shoulders = (P[:, 1] > body.trunk.top_y) & body.trunk.chest(P)
    chest = P[body.trunk.mask & below_shoulders & seen & (np.abs(P[:, 0] - body.trunk.midline_x) < RELIEF_MM)]
    if len(chest) < 10:
        return -np.inf
    x, y, z = ((chest - chest.mean(0)) / 100.0).T
    A = np.column_stack([np.ones_like(x), x, y, x * x, x * y, y * y, y ** 3, x * x * y, y ** 4])
    coef, *_ = np.linalg.lstsq(A, z, rcond=None)
    return 100.0 * float(np.percentile(A @ coef - z, 99))


def _body_or_none(points: np.ndarray) -> BodyInView | None:
    try:
        return find_body(points)
    except BadInputError:
        return None


def _frame(anterior: np.ndarray, up: str) -> np.ndarray:
    """The viewing frame seen from `anterior` (unit), y opposite to the input's `up` axis."""
    up_vec = np.zeros(3)
    up_vec["xyz".index(up[1])] = -1.0 if up.startswith("-") else 1.0     # up: one of options.UP_AXES
    up_vec -= np.dot(up_vec, anterior) * anterior
    if np.linalg.norm(up_vec) < 0.3:
        raise BadInputError(None, f"its up axis {up} lies nearly along the direction it is seen from (as found from "
                                  "its points): give another up axis (--up, or a filter's up=), unless it is no "
                                  "frontal scan of an upper body at all (a whole closed body, a lone breast)")
    y = -up_vec / np.linalg.norm(up_vec)
    z = -anterior
    T = np.eye(4)
    T[:3, :3] = np.vstack([np.cross(y, z), y, z])
    return T


def _trunk_bulge(body: BodyInView | None) -> float:
    """Curvature across (1/mm) with which a body's trunk bulges towards the viewer (viewing frame),
    −inf without a body."""
    if body is None:
        return -np.inf
    trunk = body.points[body.trunk.mask]
    x, y, z = (trunk - trunk.mean(0)).T
    coef, *_ = np.linalg.lstsq(np.column_stack([np.ones_like(x), x, y, x * x, x * y, y * y]), z, rcond=None)
    return 2.0 * float(coef[3])


def isolate(points: np.ndarray, input_to_view: np.ndarray, options: IngestOptions, clock: Clock,
            viewer: np.ndarray) -> Ingested:
    """The breast of `options.side` among points in the viewing frame (`viewer`: where the camera is)."""
    return isolate_side(isolate_body(points, input_to_view, clock, viewer), options, clock)


def isolate_body(points: np.ndarray, input_to_view: np.ndarray, clock: Clock, viewer: np.ndarray,
                 found: BodyInView | None = None, beyond: np.ndarray | None = None,
                 up: str | None = None) -> BodyScan:
    """The body among points in the viewing frame (`viewer`: where the camera is; `found`: the body
    among them, if already found; `beyond`: more points farther away, where a wall may stand; `up`:
    the input's up axis, when the viewing frame was built on it)."""
    if found is None:
        with clock("background: voxels + DBSCAN"):
            body, voxels, which = body_cluster(points)
        with clock("trunk"):
            found = BodyInView(body, voxels, which, find_trunk(body))
    trunk = found.trunk
    if trunk.head == "below":
        raise BadInputError(None, _upside_down(up))
    with clock("a wall behind her"):
        behind = points[points[:, 2] > found.points[:, 2].max()]
        plumb = plumb_wall(behind if beyond is None else np.vstack([behind, beyond]))
    with clock("chest wall"):
        torso = found.points[trunk.mask]
        in_trunk = np.bincount(found.which[trunk.mask], minlength=len(found.voxels)) > 0
        coarse = found.voxels[in_trunk & trunk.chest(found.voxels)]       # the chest's coarse voxels
        wall = fit_chest_wall(coarse, 2)
    with clock("mounds (height basins) + breasts"):
        mounds = tuple(B.find_mounds(coarse, wall, trunk.midline_x, COARSE_MM))
    return BodyScan(input_to_view, viewer, trunk, torso, coarse, wall, mounds, plumb, dict(clock.ms))


def isolate_side(body: BodyScan, options: IngestOptions, clock: Clock) -> Ingested:
    """The breast of `options.side` on the body; its steps timed on `clock` (which should hold the body's)."""
    roi, nipple, side = options.roi_camera_mm, options.nipple_camera_mm, options.side
    input_to_view, torso = body.input_to_view, body.torso
    to_camera = np.linalg.inv(input_to_view)
    in_roi = _roi_test(roi, to_camera)
    nipple_view = None if nipple is None else transform_points(input_to_view, nipple)
    with clock("mounds (height basins) + breasts"):
        mound = _breast_mound(body.mounds, body.trunk, options, nipple_view, in_roi)
        wall = B.chest_wall_under(body.coarse, mound, body.wall)
    with clock("crop + breast frame"):
        region = B.breast_region(torso, mound, wall, COARSE_MM)
        crop = torso[region & in_roi(torso)] if in_roi is not None else torso[region]
        frame, nipple_view, nipple_found = B.breast_frame(crop, wall, mound, nipple_view)
        crop = crop[frame.to_breast(crop)[:, 2] > 0.0]
    if mound.low and nipple_found == "apex":
        raise BadInputError(None, f"no breast mound found on the {side} side (the mound there rises only "
                                  f"{mound.rise:.2f} of its radius and bears no nipple)")
    _enough(len(crop), "cropping")
    with clock("outliers"):
        crop = crop[radius_inliers(crop, 5.0, 4)]
    with clock("voxel downsampling"):
        points = voxel_downsample(crop, options.voxel_mm) if len(crop) else crop
    _enough(len(points), f"{options.voxel_mm:g} mm voxel downsampling")
    with clock("normals"):
        normals = normals_towards(points, body.viewer, max(3 * options.voxel_mm, 5.0), 16)
    with clock("to breast frame"):
        points, normals = transform_points(frame.matrix, points), normals @ frame.matrix[:3, :3].T
    return Ingested(
        points=points, normals=normals,
        input_to_breast=frame.matrix @ input_to_view,
        side=mound.side if nipple is not None or roi is not None else side,
        nipple_camera=transform_points(to_camera, nipple_view), nipple_found=nipple_found, chest_wall=wall,
        input_to_view=input_to_view,
        crop={"mound_centre_view_mm": mound.centre, "mound_radius_mm": mound.radius, "mound_peak_mm": mound.peak_mm,
              "roi_camera_mm": None if roi is None else np.asarray(roi, float), "crop_height_mm": B.CROP_MM},
        torso_camera=transform_points(to_camera, torso),
        plumb_camera=None if body.plumb is None else input_to_view[:3, :3].T @ body.plumb, timings_ms=clock.ms,
        torso_rgb=body.torso_rgb)


def _upside_down(up: str | None) -> str:
    """Why a view with her head below her chest is refused: read with `up` (a scan file's axis), or
    from a camera (None)."""
    if up is None:
        return "shows her upside down (her neck and head lie below her chest): was the camera upside down?"
    flip = ("+" if up[0] == "-" else "-") + up[1]
    return (f"shows her upside down with {up} up (her neck and head lie below her chest): is her up axis {flip} "
            f"(--up {flip})?")


def body_cluster(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The points of the body, its coarse voxels' centroids and each point's voxel: of the
    connected clusters (DBSCAN on coarse voxels) as large as a trunk's front (BODY_VOXELS, or the
    largest if none is), the nearest to the viewer (a wall behind may be larger)."""
    coarse, which = voxel_centroids(points, COARSE_MM)
    labels = dbscan(coarse, 2.5 * COARSE_MM, 4)
    if (labels < 0).all():
        raise BadInputError(None, "holds no connected surface (only scattered points)")
    counts = np.bincount(labels[labels >= 0])
    big = np.flatnonzero(counts >= min(BODY_VOXELS, counts.max()))
    depth = [np.median(coarse[labels == k, 2]) for k in big]
    voxels = np.flatnonzero(labels == big[int(np.argmin(depth))])
    rank = np.full(len(coarse), -1)
    rank[voxels] = np.arange(len(voxels))
    inside = rank[which] >= 0
    return points[inside], coarse[voxels], rank[which[inside]]


def _roi_test(roi, to_camera: np.ndarray):
    """A test 'inside the camera-frame box' for viewing-frame points, or None without a box."""
    if roi is None:
        return None
    lo, hi = np.asarray(roi, float).reshape(2, 3)

    def inside(points: np.ndarray) -> np.ndarray:
        camera = transform_points(to_camera, points)
        return np.all((camera >= lo) & (camera <= hi), axis=1)
    return inside


def _breast_mound(mounds: tuple[B.Mound, ...], trunk: Trunk, options: IngestOptions, nipple_view, in_roi) -> B.Mound:
    """The requested breast's mound: the one under a given nipple, the largest in a region of
    interest, else the breast of `options.side` (docs/isolation.md §4); BadInputError saying why if none."""
    side = options.side
    if in_roi is not None:
        mounds = [m for m in mounds if in_roi(m.voxels).any()]
    if in_roi is not None or nipple_view is not None:
        return B.choose_mound(mounds, nipple_view, options.nipple_camera_mm)
    breasts = B.find_breasts(mounds, trunk.midline_x, trunk.top_y)
    if side in breasts:
        return breasts[side]
    if breasts:
        why = "; one found on the other side"
    elif mounds:
        why = f" ({len(mounds)} mound{'s' * (len(mounds) > 1)} found, none placed or shaped as a breast is)"
    else:
        why = " (nothing rises from the chest)"
    raise BadInputError(None, f"no breast mound found on the {side} side{why}")


def _enough(n: int, step: str) -> None:
    if n < MIN_BREAST_POINTS:
        raise BadInputError(None, f"only {n} breast points are left after {step}, fewer than {MIN_BREAST_POINTS}")
