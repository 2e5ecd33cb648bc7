"""Anthropometric breast measures, on a breast before surgery and on a planned (deformed) one.

Everything is in one frame, the input frame of the scan (a recording's camera: x right, y down,
z forward; a scan file's own frame), in mm. Two steps:

* `find_landmarks` finds, once per scan, what stays fixed through surgery: the mid-sagittal
  plane, the body's up axis and the sternal notch (`BodyLandmarks`);
* `breast_measures` measures one side's breast — a closed, outward-oriented triangle mesh (the
  fitted surface, fit.ply, or the planned one: same faces, moved vertices) and its nipple — against
  them; `asymmetry` compares the sides.

Distances are straight chords between two points, where a surgeon lays a tape over the skin:
notch to nipple and nipple to fold come out shorter than a tape on a projecting breast.

How the landmarks are found (the torso: the background-free body points, `Scan.torso_camera`;
head, neck and arms may be in it):

1. **Mid-sagittal plane** by mirror ICP: reflect the torso (8 mm voxels) in the current plane,
   pair each point with the nearest of the torso's 4 mm voxels, and take the plane bisecting the
   closest 80 % of the pairs (the rest have no mirror image: a flank seen at a grazing angle, an
   arm posed unlike the other); the plane is kept upright (its normal ⟂ the current up axis). It
   starts through the nipples' midpoint, normal along the nipple-to-nipple direction (one
   nipple: through the torso's middle, normal along the viewing frame's x).
2. **Up axis** in that plane. The camera may look up or down but is taken as not rolled: the up
   axis lies in the viewing frame's y–z plane (a scan file's viewing frame has its y opposite the
   declared up axis). With a wall seen behind her (`ingest.background.plumb_wall`), the wall is
   plumb, and the up axis is the vertical it gives: ⟂ to its normal and to the viewing frame's x
   (unless that leans over PLUMB_DEG from the viewing frame's up: a slanted backdrop, not a wall).
   Without one, it starts at the viewing frame's −y, and the camera's pitch is corrected by making
   the anterior midline profile of the sternum and the upper abdomen (130–400 mm below the notch)
   vertical, as it is on an upright body of average weight (a heavy body's belly leans it); plane,
   up axis and notch are then refined together (`ROUNDS` rounds).
3. **Sternal (jugular) notch**: on the midline profile (the most anterior torso point in 5 mm
   height bins of the strip within 10 mm of the plane), the deepest (most posterior) point
   between 60 and 400 mm above the nipples — the hollow where the sloping upper chest meets the
   neck — refined by a parabola over ±30 mm of height. A torso cut below the neck gives the top
   of its midline instead.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from breastplan import BadInputError
from breastplan.meshes import corners_positive_part_mean
from breastplan.voxels import voxel_centroids

MEASURES = ("volume_cc", "upper_pole_cc", "lower_pole_cc", "pole_ratio", "notch_to_nipple_mm",
            "nipple_below_notch_mm", "nipple_to_midline_mm", "nipple_to_fold_mm", "width_mm", "projection_mm")
"""The names `breast_measures` gives, in order."""

VOXEL_MM = (4.0, 8.0)
"""Voxels evening out the torso's sampling: fine (the profile; the mirror images' partners) and
coarse (the points the mirror ICP reflects)."""
MIRROR_KEEP = 0.8
"""Share of the mirror pairs (the closest) that place the plane."""
STRIP_MM = 10.0
"""Half-width of the midline strip the profile is taken in."""
BIN_MM = 5.0
"""Height bins of the midline profile."""
NOTCH_ABOVE_NIPPLES_MM = (60.0, 400.0)
"""The notch is searched this far above the nipples' mean height."""
NOTCH_FIT_MM = 30.0
"""Half-height of the parabola fitted around the profile's deepest bin."""
STERNUM_BELOW_NOTCH_MM = (130.0, 400.0)
"""The profile made vertical to correct the camera's pitch: sternum and upper abdomen."""
MIN_STERNUM_BINS = 20
"""Fewer profile bins than this there (100 mm): the pitch is not corrected."""
ROUNDS = 4
"""Rounds of plane → notch → pitch."""
UP_FROM = ("midline profile", "wall")
"""What may set the up axis (`BodyLandmarks.up_from`)."""
PLUMB_DEG = 30.0
"""A wall's vertical farther than this from the viewing frame's up is not taken (degrees)."""
MIRROR_ITERATIONS = 40
"""Mirror ICP iterations at most, each time it runs."""


@dataclass(frozen=True, eq=False)
class BodyLandmarks:
    """Landmarks that surgery leaves in place, input frame, mm.

    `midline_point` and `left_axis` give the mid-sagittal plane (`left_axis` its unit normal,
    towards the patient's left); `up_axis` is unit, superior, in that plane; `sternal_notch` lies
    on the plane."""

    sternal_notch: np.ndarray   # (3,)
    midline_point: np.ndarray   # (3,)
    left_axis: np.ndarray       # (3,)
    up_axis: np.ndarray         # (3,)
    up_from: str = "midline profile"   # or "wall": what set the up axis (module docstring, step 2)

    def __post_init__(self):
        if self.up_from not in UP_FROM:
            raise ValueError(f"up_from must be one of {', '.join(UP_FROM)}, got {self.up_from!r}")
        for name in ("sternal_notch", "midline_point", "left_axis", "up_axis"):
            value = np.array(getattr(self, name), dtype=float).reshape(-1)
            if value.shape != (3,) or not np.isfinite(value).all():
                raise ValueError(f"{name} must be 3 finite numbers, got {getattr(self, name)!r}")
            value.flags.writeable = False
            object.__setattr__(self, name, value)
        L, U = self.left_axis, self.up_axis
        if abs(np.linalg.norm(L) - 1) > 1e-6 or abs(np.linalg.norm(U) - 1) > 1e-6 or abs(L @ U) > 1e-6:
            raise ValueError("left_axis and up_axis must be orthogonal unit vectors")

    @property
    def anterior_axis(self) -> np.ndarray:
        """Unit, towards the front of the body: left × up."""
        return np.cross(self.left_axis, self.up_axis)

    def transformed(self, T) -> "BodyLandmarks":
        """The landmarks in another frame: T (4, 4) a rigid transform from this frame to it."""
        T = np.asarray(T, dtype=float)
        R, t = T[:3, :3], T[:3, 3]
        return BodyLandmarks(R @ self.sternal_notch + t, R @ self.midline_point + t, R @ self.left_axis,
                             R @ self.up_axis, self.up_from)


# --- landmarks ---------------------------------------------------------------------------------
def find_landmarks(torso_mm, nipples: dict, view_from_input=None, plumb=None) -> BodyLandmarks:
    """The mid-sagittal plane, up axis and sternal notch of a frontal scan (module docstring).

    torso_mm: (M, 3) the body's points without background, input frame, mm; nipples: side →
    (3,) the nipples found on it (one or both); view_from_input: (4, 4) input → viewing frame
    (`Scan.input_to_view`; None: the input frame is the viewing frame, as for a recording);
    plumb: (3,) unit normal of a wall behind her, input frame (`Scan.plumb_camera`), or None.
    BadInputError when the torso shows no midline above the nipples."""
    P = _finite_points(torso_mm, "the torso")
    nips = {s: np.asarray(p, float).reshape(3) for s, p in nipples.items()}
    if not nips or not set(nips) <= {"left", "right"}:
        raise ValueError(f"nipples must map left and/or right to points, got sides {sorted(nipples)}")
    R = np.eye(3) if view_from_input is None else np.asarray(view_from_input, float)[:3, :3]
    level, up = R.T @ [1.0, 0.0, 0.0], R.T @ [0.0, -1.0, 0.0]    # viewing frame: x level, y down
    walled = None if plumb is None else _plumb_up(plumb, level, up)
    up = up if walled is None else walled
    fine, coarse = (voxel_centroids(P, s)[0] for s in VOXEL_MM)
    tree = cKDTree(fine)                          # mirror images are looked up among the fine voxels
    centre = np.mean(list(nips.values()), axis=0)
    if len(nips) == 2:
        left = _unit(_perp(nips["left"] - nips["right"], up))
        offset = float(left @ centre)
    else:
        left = _unit(_perp(level, up))
        offset = float(np.median(coarse @ left))
    for _ in range(ROUNDS if walled is None else 0):          # a wall's up axis needs no refining
        left, offset = _mirror_plane(coarse, tree, left, offset, up)
        notch_h = _notch(fine, left, offset, up, float(centre @ up))[1]
        slope = _sternum_slope(fine, left, offset, up, notch_h)
        up = _unit(_perp(up + slope * np.cross(left, up), level))          # pitch only: no roll
        left = _unit(_perp(left, up))
    left, offset = _mirror_plane(coarse, tree, left, offset, up)
    notch = _notch(fine, left, offset, up, float(centre @ up))[0]
    return BodyLandmarks(notch, centre - (centre @ left - offset) * left, left, up,
                         "midline profile" if walled is None else "wall")


def _plumb_up(plumb, level, view_up) -> np.ndarray | None:
    """The up axis a plumb wall (unit normal) gives a camera that is not rolled (its `level` x axis
    horizontal): the vertical, ⟂ to both; None when it leans over PLUMB_DEG from `view_up`."""
    along = np.cross(np.asarray(plumb, float), level)
    if np.linalg.norm(along) < 1e-6:
        return None
    up = _unit(along) * np.sign(along @ view_up)
    return up if up @ view_up >= np.cos(np.radians(PLUMB_DEG)) else None


def _mirror_plane(P, tree, n, d, up) -> tuple[np.ndarray, float]:
    """The plane n·p = d (n ⟂ up) about which the points P are most nearly symmetric (mirror ICP)."""
    for _ in range(MIRROR_ITERATIONS):
        dist, j = tree.query(P - 2.0 * (P @ n - d)[:, None] * n)
        keep = dist <= max(np.quantile(dist, MIRROR_KEEP), 1e-9)
        Q = tree.data[j[keep]]
        D = _perp(P[keep] - Q, up)             # pairs point across the plane
        vec = np.linalg.eigh(D.T @ D)[1][:, -1]
        new = vec * np.sign(vec @ n)
        d = float(np.mean(0.5 * (P[keep] + Q) @ new))
        moved = np.linalg.norm(new - n)
        n = new
        if moved < 1e-7:
            break
    return n, d


def midline_profile(P, n, d, up, origin_h) -> tuple[np.ndarray, np.ndarray]:
    """The anterior midline profile: (heights, anterior coordinates) of the most anterior point
    per BIN_MM height bin of the strip within STRIP_MM of the plane (bins counted from origin_h)."""
    strip = P[np.abs(P @ n - d) < STRIP_MM]
    if len(strip) == 0:
        return np.zeros(0), np.zeros(0)
    k = np.floor((strip @ up - origin_h) / BIN_MM).astype(np.int64)
    k0 = k.min()
    front = np.full(k.max() - k0 + 1, -np.inf)
    np.maximum.at(front, k - k0, strip @ np.cross(n, up))
    seen = np.isfinite(front)
    return origin_h + (np.flatnonzero(seen) + k0 + 0.5) * BIN_MM, front[seen]


def _notch(P, n, d, up, nipple_h) -> tuple[np.ndarray, float]:
    """(the notch (3,), its height): the deepest point of the midline profile above the nipples."""
    h, a = midline_profile(P, n, d, up, nipple_h)
    lo, hi = NOTCH_ABOVE_NIPPLES_MM
    inside = (h > nipple_h + lo) & (h < nipple_h + hi)
    if inside.sum() < 3:
        raise BadInputError(None, "shows no midline above the nipples to find the sternal notch on")
    i = np.argmin(np.where(inside, a, np.inf))
    near = inside & (np.abs(h - h[i]) <= NOTCH_FIT_MM)
    hv, av = h[i], a[i]
    if near.sum() >= 3:
        c = np.polyfit(h[near] - h[i], a[near], 2)
        if c[0] > 0:
            x = float(np.clip(-c[1] / (2 * c[0]), h[near].min() - h[i], h[near].max() - h[i]))
            hv, av = h[i] + x, float(np.polyval(c, x))
    return d * n + hv * up + av * np.cross(n, up), float(hv)


def _sternum_slope(P, n, d, up, notch_h) -> float:
    """d(anterior)/d(height) of the midline profile over the sternum and upper abdomen (a line fit
    trimmed at 2.5σ), 0 where too little of it is seen."""
    h, a = midline_profile(P, n, d, up, notch_h)
    lo, hi = STERNUM_BELOW_NOTCH_MM
    inside = (h > notch_h - hi) & (h < notch_h - lo)
    if inside.sum() < MIN_STERNUM_BINS:
        return 0.0
    x, y = h[inside] - notch_h, a[inside]
    keep = np.ones(len(x), bool)
    for _ in range(3):
        c = np.polyfit(x[keep], y[keep], 1)
        r = y - np.polyval(c, x)
        keep = np.abs(r) <= max(2.5 * 1.4826 * np.median(np.abs(r[keep])), 2.0)
    return float(c[0])


def _perp(v, axis) -> np.ndarray:
    """v (..., 3) without its component along the unit `axis`."""
    v = np.asarray(v, float)
    return v - (v @ axis)[..., None] * axis


def _unit(v) -> np.ndarray:
    return v / np.linalg.norm(v)


def _finite_points(points, what) -> np.ndarray:
    P = np.asarray(points, dtype=float)
    if P.ndim != 2 or P.shape[1] != 3 or len(P) == 0 or not np.isfinite(P).all():
        raise ValueError(f"{what} must be (N, 3) finite points, got shape {P.shape}")
    return P


# --- measures ----------------------------------------------------------------------------------
def base_ring(faces, centre: int | None = None) -> np.ndarray:
    """Indices of the base outline of a closed breast mesh: the vertices sharing a triangle with
    the base centre, `centre` (default: the last vertex, as `Primitive.mesh` and fit.ply lay the
    mesh out: rings, apex, base centre)."""
    F = np.asarray(faces, dtype=np.int64)
    c = int(F.max()) if centre is None else int(centre)
    ring = np.unique(F[(F == c).any(1)])
    return ring[ring != c]


def breast_measures(landmarks: BodyLandmarks, nipple_mm, vertices_mm, faces, base=None,
                    fold_mm=None) -> dict[str, float]:
    """One breast's measures (MEASURES), input frame: lengths in mm, volumes in cc.

    nipple_mm (3,); vertices_mm (V, 3), faces (F, 3): the closed, outward-oriented breast mesh,
    its base cap on the chest wall; base: indices of its base outline (default `base_ring(faces)`); fold_mm (3,):
    her inframammary fold as found on her skin (`plan.symmetry.fold_line`; default: the base outline's lowest vertex).

    * volume_cc: volume the mesh encloses;
    * upper_pole_cc, lower_pole_cc: of it, above and below the horizontal plane (normal: up)
      through the nipple (exact on the triangles); pole_ratio = upper / lower (1 for a breast
      symmetric about that plane, inf if nothing lies below);
    * notch_to_nipple_mm: chord from the sternal notch; nipple_below_notch_mm: the nipple's
      height below the notch along up;
    * nipple_to_midline_mm: distance from the mid-sagittal plane;
    * nipple_to_fold_mm: chord to the inframammary fold (`fold_mm`, else the lowest base vertex along up);
    * width_mm: extent of the base outline along the left–right axis;
    * projection_mm: height of the nipple above the base plane (least squares through the base
      outline)."""
    V = _finite_points(vertices_mm, "the breast mesh")
    out = breast_measures_each(landmarks, np.asarray(nipple_mm, dtype=float).reshape(1, 3), V[None], faces, base,
                               fold_mm)
    return {k: float(v[0]) for k, v in out.items()}


EACH_MESHES = 32
"""`breast_measures_each` measures this many meshes at a time (their triangles held at once)."""


def breast_measures_each(landmarks: BodyLandmarks, nipples_mm, vertices_mm, faces, base=None,
                         fold_mm=None) -> dict[str, np.ndarray]:
    """`breast_measures` of S meshes sharing `faces` (one breast as several plans move it): nipples_mm (S, 3),
    vertices_mm (S, V, 3); measure name → (S,). A fold given (`fold_mm`, (3,)) is hers in every one: no change
    moves it."""
    nipples, V = np.asarray(nipples_mm, dtype=float), np.asarray(vertices_mm, dtype=float)
    F = np.asarray(faces, dtype=np.int64)
    ring = V[:, base_ring(F) if base is None else np.asarray(base, dtype=np.int64)]          # (S, R, 3)
    L, U, notch = landmarks.left_axis, landmarks.up_axis, landmarks.sternal_notch
    across = np.linalg.svd(U[None], full_matrices=True)[2][1:]                       # two axes ⟂ up
    across[1] *= np.sign(np.linalg.det(np.vstack([across, U])))                       # (across, up) right-handed
    volume, upper = np.empty(len(V)), np.empty(len(V))
    for at in range(0, len(V), EACH_MESHES):
        chunk = slice(at, at + EACH_MESHES)
        a, b = np.ascontiguousarray((V[chunk] @ across.T).transpose(2, 1, 0))             # (V, s) each
        h = np.ascontiguousarray(((V[chunk] - nipples[chunk, None]) @ U).T)              # above the nipple's plane
        a, b, h = ([x[F[:, k]] for k in range(3)] for x in (a, b, h))                    # (F, s) per corner
        area_up = 0.5 * ((a[1] - a[0]) * (b[2] - b[0]) - (b[1] - b[0]) * (a[2] - a[0]))
        # Σ (area along up) · (mean of a linear field) over a closed mesh is the field's gradient along up times the
        # volume (divergence theorem): the height's is 1
        volume[chunk] = np.einsum("fs,fs->s", area_up, (h[0] + h[1] + h[2]) / 3.0)
        upper[chunk] = np.einsum("fs,fs->s", area_up, corners_positive_part_mean(*h))
    if not (volume > 0).all():
        raise BadInputError(None, "gives a breast mesh that encloses no volume (not closed and outward-oriented)")
    lower = volume - upper
    centroid = ring.mean(axis=1)
    normal = np.linalg.svd(ring - centroid[:, None], full_matrices=False)[2][:, -1]
    fold = (np.take_along_axis(ring, np.argmin(ring @ U, axis=1)[:, None, None], axis=1)[:, 0] if fold_mm is None
            else np.asarray(fold_mm, dtype=float).reshape(1, 3))
    out = {
        "volume_cc": volume / 1000.0,
        "upper_pole_cc": upper / 1000.0,
        "lower_pole_cc": lower / 1000.0,
        "pole_ratio": np.divide(upper, lower, out=np.full_like(upper, np.inf), where=lower > 0),
        "notch_to_nipple_mm": np.linalg.norm(nipples - notch, axis=1),
        "nipple_below_notch_mm": (notch - nipples) @ U,
        "nipple_to_midline_mm": np.abs((nipples - landmarks.midline_point) @ L),
        "nipple_to_fold_mm": np.linalg.norm(nipples - fold, axis=1),
        "width_mm": np.ptp(ring @ L, axis=1),
        "projection_mm": np.abs(np.einsum("si,si->s", nipples - centroid, normal)),
    }
    return {k: out[k] for k in MEASURES}


def measure_label(name: str) -> str:
    """A measure's name as the terminal, the report and the summary show it: its words (volume_cc, in a
    plan, is her volume measured on her skin, `plan.breast_volume`)."""
    return name.replace("_", " ")


def asymmetry(measures_by_side: dict) -> dict[str, dict[str, float]]:
    """Measure → {"left_minus_right", "abs_difference"} for the measures both sides have
    (`breast_measures` of each, or `breast_measures_each`: arrays); empty unless both sides are given."""
    if not {"left", "right"} <= set(measures_by_side):
        return {}
    left, right = measures_by_side["left"], measures_by_side["right"]
    out = {}
    for name in (k for k in left if k in right):
        diff = np.asarray(left[name], dtype=float) - np.asarray(right[name], dtype=float)
        diff = diff if diff.ndim else float(diff)                  # per state, for `StateGrid.measures`
        out[name] = {"left_minus_right": diff, "abs_difference": abs(diff)}
    return out
