"""What the report draws: the torso, each side's scan and fitted breast (and a follow-up's earlier
breast), and every planned state.

All in the display frame (x to the image's right, y away from the viewer, z up; mm), from the
scan's viewing frame (x right, y down, z away). Her torso is drawn as one triangle surface through the
centroids of its points in TORSO_MM cubes: one camera's view (a recording) triangulated as its pixels lie
(`skin_triangles`), a scan file's points, which need not be one view's, reconstructed in 3-D
(`surface_triangles`); its points near the breasts
(the patch) move with the plan. Every state the report's sliders reach (`Plan.grid`) is drawn: the planned
breast meshes and the moved patch, as arrays over the states (`Views.moved`, `Views.planned_meshes`), from which
`Views.state` gives one.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import Delaunay

from breastplan import transform_points
from breastplan.ingest.cloud import voxel_colours, voxel_downsample
from breastplan.point_order import in_caller_order

from .measures import midline_profile
from .result import Plan
from .surface import PlannedChange
from .symmetry import fold_line

TORSO_MM = 5.0
"""Her torso is drawn through the centroids of its points in cubes of this side (mm)."""
GAP_MM = 20.0
"""A triangle of her drawn skin with an edge longer than this would span a gap the camera did not see
across (an occluding edge, the side of her body): it is left out, except beneath a breast (BENEATH_MM)."""
BENEATH_MM, HIDDEN_MM, ACROSS = 60.0, 150.0, 0.15
"""Beneath a breast — across her footprint's span less the ACROSS share of its outline's points at each side (a
triangle there, from the breast's outer edge to her flank, showed as a fin once the breast moved), from its
middle height down to this far below its lowest point (her body frame) — a triangle spanning up to HIDDEN_MM is
kept: it runs from the breast's lower edge back to her chest along the camera's line of sight, over skin the
camera did not see, so that her body is not drawn torn in two under a breast that hangs."""
VIEW_TO_DISPLAY = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0], [0, -1.0, 0, 0], [0, 0, 0, 1.0]])
"""Viewing frame (y down, z away) → display frame (y away, z up)."""
MIDLINE_MM = (60.0, -350.0)
"""The midline drawn: the measures' anterior midline profile (her skin on the mid-sagittal plane),
from this far above the sternal notch to this far below it (along the up axis), mm."""


@dataclass(frozen=True)
class State:
    """One drawn plan state: its label, its index in `Plan.grid` (None: her skin as scanned)."""

    key: str
    index: int | None
    mesh: dict[str, np.ndarray]       # side → (V, 3) planned breast vertices, display frame
    torso: np.ndarray                  # (P, 3) the moved torso patch, display frame


FOOTPRINT_LIFT_MM = 4.0
"""Each footprint is drawn this far in front of her skin (along her anterior axis), over the points on it."""


@dataclass(frozen=True)
class Views:
    torso: np.ndarray                   # (T, 3) torso points drawn still
    patch: np.ndarray                   # (P, 3) torso points near the breasts (they move)
    skin: np.ndarray                    # (F, 3) her skin's triangles over the torso points then the patch's
    scans: dict[str, np.ndarray]        # side → (N, 3) scan points
    meshes: dict[str, tuple[np.ndarray, np.ndarray]]   # side → fitted (V, 3), (F, 3)
    earlier: dict[str, tuple[np.ndarray, np.ndarray]]  # side → a follow-up's earlier fitted breast (V, 3), (F, 3)
    landmarks: dict[str, np.ndarray]    # what the measures start from: "sternal notch" (1, 3), "midline" (K, 3)
                                        # her skin on the mid-sagittal plane, "nipples" (sides, 3) as found
    footprints: dict[str, np.ndarray]   # side → (K, 3) the closed outline her volume is measured inside
    side_labels: dict[str, np.ndarray]  # side → (3,) where her side is named: SIDE_LABEL_MM from its nipple
    folds: dict[str, np.ndarray]        # side → (K, 3) her inframammary fold under the breast, as measured
    keys: tuple[str, ...] = ()          # per state of `Plan.grid`: its name
    moved: np.ndarray | None = None     # (S, P, 3) float32 the patch in each state
    planned_meshes: dict[str, np.ndarray] | None = None   # side → (S, V, 3) float32 the planned breast in each state
    skin_rgb: np.ndarray | None = None  # (T + P, 3) uint8 her skin's recorded colour at the torso then the patch's
                                        # points (the mean over each TORSO_MM cube); None: none was recorded
    marks_moved: np.ndarray | None = None   # (S, M, 3) float32 the nipples and footprints in each state of
                                            # `Plan.grid` (her operations and changes applied), `mark_layout`
    mark_layout: tuple = ()             # (name, side or None, start, stop) of each mark's rows in `marks_moved`
    operated_labels: dict | None = None  # side → (3,) where her side is named on her operated skin; None: no
                                         # operation

    def marks(self, state: State) -> dict:
        """What is drawn on her in `state`: "footprints", "folds", "side_labels" and "landmarks" (with the nipples),
        as found on her skin as scanned, or moved as `state` moves her skin (her folds stay where they were found:
        on her chest, where no change or operation moves them)."""
        found = {"footprints": self.footprints, "folds": self.folds, "side_labels": self.side_labels,
                 "landmarks": self.landmarks}
        if state.index is None:
            return found
        moved = {"footprints": {}, "folds": self.folds, "side_labels": self.operated_labels or self.side_labels}
        for name, side, a, b in self.mark_layout:
            points = self.marks_moved[state.index, a:b].astype(float)
            if side is None:
                moved["landmarks"] = {**self.landmarks, name: points}
            else:
                moved[name][side] = points
        return moved

    def state(self, key: str) -> State:
        """The drawn state named `key` ("original": her skin as scanned)."""
        if key == "original":
            return State(key, None, {s: m[0] for s, m in self.meshes.items()}, self.patch)
        i = self.keys.index(key)
        return State(key, i, {s: m[i] for s, m in self.planned_meshes.items()}, self.moved[i])


def build_views(plan: Plan) -> Views:
    """Every state of the plan in the display frame."""
    to_display = VIEW_TO_DISPLAY @ plan.body.input_to_view                  # input frame → display frame
    torso, rgb = _trunk(plan)
    torso_in, rgb = (voxel_downsample(torso, TORSO_MM), None) if rgb is None else voxel_colours(torso, TORSO_MM, rgb)
    near = np.zeros(len(torso_in), bool)
    for planned in plan.changes[0].planned.values():
        near |= planned.weights(torso_in) > 0
    still_in, patch_in = torso_in[~near], torso_in[near]
    show = lambda p: transform_points(to_display, p)  # noqa: E731
    meshes = {s: (show(sp.surface_input), sp.fit.faces) for s, sp in plan.sides.items()}
    drawn_order = np.concatenate([np.flatnonzero(~near), np.flatnonzero(near)])   # still, then patch
    at = in_caller_order(drawn_order, np.arange(len(torso_in)))                   # each torso point among the drawn
    nipples = np.array([sp.scan.nipple_camera_mm for sp in plan.sides.values()])
    ahead = FOOTPRINT_LIFT_MM * plan.volumes.landmarks.anterior_axis
    footprints = {s: v.footprint_input_mm + ahead for s, v in plan.volumes.sides.items()}
    folds = _folds(plan)
    one_view = all(sp.scan.source.kind != "file" for sp in plan.sides.values())
    torso_view = transform_points(plan.body.input_to_view, torso_in)
    # her skin's surface is made over her points in one order, whatever the plan's changes split off as the patch:
    # ball pivoting's result depends on the order of its points
    skin = skin_triangles(torso_view, _beneath_breasts(plan)) if one_view else surface_triangles(torso_view)
    return Views(torso=show(still_in), patch=show(patch_in), skin=at[skin],
                 scans={s: show(transform_points(sp.frames.breast_to_input, sp.scan.points))
                        for s, sp in plan.sides.items()},
                 meshes=meshes, keys=plan.grid.keys, moved=_moved(plan, patch_in, to_display),
                 planned_meshes={s: _shown32(to_display, m) for s, m in plan.grid.models.items()},
                 earlier={s: (show(sp.follow_up.earlier_surface_input), sp.follow_up.earlier_faces)
                          for s, sp in plan.sides.items() if sp.follow_up is not None},
                 landmarks=_landmarks(plan, show), footprints={s: show(f) for s, f in footprints.items()},
                 side_labels={s: show(p[None])[0] for s, p in _side_labels(plan, plan.body.torso_input,
                                                                           nipples).items()},
                 folds={s: show(f) for s, f in folds.items()},
                 skin_rgb=None if rgb is None else np.concatenate([rgb[~near], rgb[near]]),
                 **_marks_in_states(plan, to_display, nipples, footprints),
                 operated_labels=_operated_labels(plan, show, nipples) if plan.operated else None)


def _marks_in_states(plan: Plan, to_display: np.ndarray, nipples: np.ndarray, footprints: dict) -> dict:
    """`Views.marks_moved` and `mark_layout`: her nipples ((sides, 3)) and footprints (side → (K, 3)), input frame,
    moved as her skin is in each state of `Plan.grid`."""
    parts = [("nipples", None, nipples), *(("footprints", s, f) for s, f in footprints.items())]
    ends = np.cumsum([len(p) for *_, p in parts])
    layout = tuple((name, side, int(b - len(p)), int(b)) for (name, side, p), b in zip(parts, ends))
    return {"marks_moved": _moved(plan, np.concatenate([p for *_, p in parts]), to_display), "mark_layout": layout}


def _operated_labels(plan: Plan, show, nipples: np.ndarray) -> dict:
    """`Views.operated_labels`: her side labels placed on her skin and nipples ((sides, 3), input frame) as her
    operations move them, display frame."""
    def operated(points: np.ndarray) -> np.ndarray:
        return points + sum(op.displacement(points) for op in plan.operated.values())

    return {s: show(p[None])[0] for s, p in _side_labels(
        plan, operated(np.asarray(plan.body.torso_input, float)), operated(nipples)).items()}


def _moved(plan: Plan, patch_in: np.ndarray, to_display: np.ndarray) -> np.ndarray:
    """(S, P, 3) float32 the patch (input frame) moved by both sides in each state of `Plan.grid`, display frame."""
    moved = None
    for s in plan.sides:
        shift = PlannedChange.displacements(plan.grid.planned[s], patch_in)
        moved = shift if moved is None else np.add(moved, shift, out=moved)
    return _shown32(to_display, np.add(moved, patch_in, out=moved))


def _shown32(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Points (..., 3) mapped by the rigid T in float32 (the page draws in float32): many states at once."""
    out = np.asarray(points, dtype=np.float32).reshape(-1, 3) @ T[:3, :3].T.astype(np.float32)
    out += T[:3, 3].astype(np.float32)
    return out.reshape(np.shape(points))


DRAWN_MM = (80.0, -650.0)
"""Her torso is drawn from this far above her sternal notch to this far below it (along her up axis), mm: her
trunk, not the head and legs a whole-body scan holds."""


def _trunk(plan: Plan) -> tuple[np.ndarray, np.ndarray | None]:
    """Her torso's points (input frame, mm) within DRAWN_MM of her sternal notch, and their colours (or None)."""
    marks = plan.volumes.landmarks
    torso = np.asarray(plan.body.torso_input, float)
    height = (torso - marks.sternal_notch) @ marks.up_axis
    keep = (height <= DRAWN_MM[0]) & (height >= DRAWN_MM[1])
    return torso[keep], None if plan.body.torso_rgb is None else np.asarray(plan.body.torso_rgb)[keep]


def skin_triangles(points_view: np.ndarray, beneath=None) -> np.ndarray:
    """(F, 3) vertex indices of a triangle surface over points one camera saw (its viewing frame: z away
    from it, mm): the Delaunay triangulation of their directions from the camera (x/z, y/z), each
    triangle wound so that its normal (right-handed) faces the camera, without those with an edge over
    GAP_MM, but for those with none over HIDDEN_MM whose centroid `beneath` ((n, 3) viewing frame → (n,) bool)
    places beneath a breast."""
    uv = points_view[:, :2] / points_view[:, 2:]
    faces = Delaunay(uv).simplices
    a, b, c = (uv[faces[:, k]] for k in range(3))
    away = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]) > 0
    faces[away] = faces[away][:, ::-1]
    longest = _longest_edges(points_view, faces)
    keep = longest <= GAP_MM
    if beneath is not None:
        hidden = ~keep & (longest <= HIDDEN_MM)
        keep[hidden] = beneath(points_view[faces[hidden]].mean(axis=1))
    return faces[keep].astype(np.int64)


def _beneath_breasts(plan: Plan):
    """Whether points (viewing frame, mm; (n, 3) → (n,) bool) lie beneath one of her breasts (BENEATH_MM)."""
    v = plan.volumes
    to_body = v.body_from_input @ np.linalg.inv(plan.body.input_to_view)
    spans = []
    for side in v.sides.values():
        f = transform_points(v.body_from_input, side.footprint_input_mm)
        if len(f):
            low, high = f[:, 1].min(), f[:, 1].max()
            inner, outer = np.quantile(f[:, 0], [ACROSS, 1.0 - ACROSS])
            spans.append((inner, outer, low - BENEATH_MM, 0.5 * (low + high)))

    def beneath(points_view: np.ndarray) -> np.ndarray:
        x, y = transform_points(to_body, points_view)[:, :2].T
        return np.any([(x >= x0) & (x <= x1) & (y >= y0) & (y <= y1) for x0, x1, y0, y1 in spans], axis=0) \
            if spans else np.zeros(len(points_view), bool)
    return beneath


BALL_RADII_MM = (1.6 * TORSO_MM, 2.4 * TORSO_MM)
"""The radii of the balls `surface_triangles` rolls over her points, in turn (the larger closes what the smaller
cannot cross), mm."""


CRACK_EDGES = 60
"""Holes of that surface bounded by at most this many edges are closed (pymeshlab's hole filling): the cracks a
wrapped scan's front leaves where her chest just below a breast was hidden from the viewer behind it."""


def surface_triangles(points_view: np.ndarray) -> np.ndarray:
    """(F, 3) vertex indices of a triangle surface over points of her skin (viewing frame, mm) that need not be one
    camera's view (a scan file's): pymeshlab's ball pivoting (BALL_RADII_MM) over their normals (turned towards
    the viewer), cracks closed (CRACK_EDGES; the pivoted surface as it is where pymeshlab cannot close them), each
    triangle wound so that its normal faces the viewer, without those with an edge over GAP_MM."""
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=np.ascontiguousarray(points_view, float)))
    ms.compute_normal_for_point_clouds(k=10, viewpos=np.zeros(3))
    for radius in BALL_RADII_MM:
        ms.generate_surface_reconstruction_ball_pivoting(ballradius=pymeshlab.PureValue(radius))
    pivoted = ms.current_mesh().face_matrix().astype(np.int64)
    try:                                                   # faces only: her points stay the mesh's vertices
        ms.meshing_repair_non_manifold_edges()
        ms.meshing_close_holes(maxholesize=CRACK_EDGES)
        faces = ms.current_mesh().face_matrix().astype(np.int64)
    except pymeshlab.PyMeshLabException:
        faces = pivoted
    if ms.current_mesh().vertex_number() != len(points_view):
        faces = pivoted
    tri = points_view[faces]
    away = np.einsum("ij,ij->i", np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), tri.mean(axis=1)) > 0
    faces[away] = faces[away][:, ::-1]
    return faces[_longest_edges(points_view, faces) <= GAP_MM].astype(np.int64)


def _longest_edges(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) each face's longest edge, mm."""
    tri = points[faces]
    return np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max(axis=1)


FOLD_HALF_MM = 30.0
"""Each breast's inframammary fold is drawn this far to either side of the point under its nipple, mm."""


def _folds(plan: Plan) -> dict[str, np.ndarray]:
    """Side → (K, 3) a short line along the fold under the breast as the plan's ptosis measure places it
    (`symmetry.fold_line`), input frame; none where it found no fold."""
    across = np.linspace(-FOLD_HALF_MM, FOLD_HALF_MM, 13)
    lines = {s: fold_line(plan.volumes, sp.scan.nipple_camera_mm, plan.measures.ptosis["before"][s], across)
             for s, sp in plan.sides.items()}
    return {s: line for s, line in lines.items() if line is not None}


SIDE_LABEL_MM = (30.0, 120.0, 30.0)
"""Her sides are named this far outside each nipple (along her left–right axis), below it (along her up axis)
and in front of her (of the nipple, or of her skin there where that stands further forward), mm: on her skin
under the breast, inside any view of her, and not hidden behind her."""
LABEL_REACH_MM = 25.0
"""Her skin within this distance of a side's label, across her front, is what the label stands in front of."""


def _side_labels(plan: Plan, torso: np.ndarray, nipples: np.ndarray) -> dict[str, np.ndarray]:
    """Side → (3,) where her side is named (SIDE_LABEL_MM) from her `nipples` ((sides, 3)) and her `torso`, input
    frame."""
    marks = plan.volumes.landmarks
    torso, ahead = np.asarray(torso, float), marks.anterior_axis
    out = {}
    for s, nipple in zip(plan.sides, nipples):
        outward = marks.left_axis if s == "left" else -marks.left_axis
        place = nipple + SIDE_LABEL_MM[0] * outward - SIDE_LABEL_MM[1] * marks.up_axis
        depth = (torso - place) @ ahead
        near = np.linalg.norm(torso - place - np.outer(depth, ahead), axis=1) < LABEL_REACH_MM
        skin = max(float(depth[near].max()), 0.0) if near.any() else 0.0
        out[s] = place + (skin + SIDE_LABEL_MM[2]) * ahead
    return out


def _landmarks(plan: Plan, show) -> dict[str, np.ndarray]:
    marks = plan.volumes.landmarks
    notch, up, left = marks.sternal_notch, marks.up_axis, marks.left_axis
    offset, top = float(left @ notch), float(up @ notch)
    height, front = midline_profile(plan.body.torso_input, left, offset, up, top)
    keep = (height <= top + MIDLINE_MM[0]) & (height >= top + MIDLINE_MM[1])
    profile = offset * left + np.outer(height[keep], up) + np.outer(front[keep], np.cross(left, up))
    return {"sternal notch": show(notch[None]), "midline": show(profile[::-1]),
            "nipples": show(np.array([sp.scan.nipple_camera_mm for sp in plan.sides.values()]))}
