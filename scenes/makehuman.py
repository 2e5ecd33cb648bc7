"""Realistic female bodies from MakeHuman's CC0 base mesh and targets (assets/makehuman.npz).

Body frame (mm): MakeHuman's own, X towards the body's left, Y up, Z anterior, the feet
near Y = −820 mm. A body is the base mesh plus MakeHuman's macro targets, blended as
MakeHuman blends them (products of linear weights over the anchors min 0 / average 0.5 /
max 1), plus breast, asymmetry and torso modifiers, then posed: each arm chain of the
default rig turned about its shoulder (and the forearm about its elbow) by linear blend
skinning. The truth it gives: both nipples (centroid of MakeHuman's nipple ring), the sternal
notch, and the exact volume of each half of the closed body.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from breastplan.meshes import positive_part_mean
from breastplan.options import SIDES, OptionError

ASSET = Path(__file__).with_name("assets") / "makehuman.npz"
LEVELS = ("min", "average", "max")
POSES = {"a-pose": (0.0, 0.0), "arms-down": (-28.0, 0.0), "hands-on-hips": (0.0, -85.0)}
"""Pose → (shoulder, elbow) turns in degrees, positive away from the body in the frontal plane."""
MODIFIERS = {
    "breast_trans": ("breast/breast-trans-down", "breast/breast-trans-up"),
    "breast_volume_vert": ("breast/breast-volume-vert-down", "breast/breast-volume-vert-up"),
    "breast_dist": ("breast/breast-dist-decr", "breast/breast-dist-incr"),
    "breast_point": ("breast/breast-point-decr", "breast/breast-point-incr"),
    "asymmetry": ("asym/asymm-breast-1-r", "asym/asymm-breast-1-l"),
    "torso_width": ("torso/torso-scale-horiz-decr", "torso/torso-scale-horiz-incr"),
    "torso_depth": ("torso/torso-scale-depth-decr", "torso/torso-scale-depth-incr"),
    "torso_vshape": ("torso/torso-vshape-decr", "torso/torso-vshape-incr"),
    "underbust": ("torso/measure-underbust-circ-decr", "torso/measure-underbust-circ-incr"),
}
"""Modifier name → (target at −1, target at +1); 0 is MakeHuman's default."""
NOTCH_VERTICES = (1522, 815)
"""The jugular notch on the base mesh, chosen by looking at the mesh: the anterior profile of its
midline (vertices with X = 0) slopes back from the sternum, is deepest (most posterior) between the
chest and the chin at vertex 815 (Y ≈ 513 mm on the default body), and rises along the throat above
it; 1522 is the next midline vertex below (Y ≈ 502 mm), where the sternum's slope ends. The notch,
the top of the manubrium between the clavicles' heads, lies between them."""


@dataclass(frozen=True)
class BodyOptions:
    """A body: macro values in 0..1 (0.5 = MakeHuman's average), modifiers in −1..1, a pose.
    A value out of range raises OptionError (a ValueError) naming the field."""

    cup: float = 0.5
    firmness: float = 0.5
    weight: float = 0.5
    muscle: float = 0.5
    modifiers: dict = field(default_factory=dict)
    pose: str = "a-pose"

    def __post_init__(self):
        for name in ("cup", "firmness", "weight", "muscle"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise OptionError(name, f"{name} must be 0..1, got {getattr(self, name)}")
        for name, value in self.modifiers.items():
            if name not in MODIFIERS or not -1.0 <= value <= 1.0:
                raise OptionError("modifiers", f"modifier {name}={value}: use one of {', '.join(sorted(MODIFIERS))} "
                                               f"with a value −1..1")
        if self.pose not in POSES:
            raise OptionError("pose", f"pose must be one of {', '.join(POSES)}, got {self.pose!r}")


@lru_cache(maxsize=1)
def _asset() -> dict:
    with np.load(ASSET, allow_pickle=False) as data:
        asset = {k: data[k] for k in data.files}
    names = [str(n) for n in asset["target_names"]]
    off = asset["target_offsets"]
    asset["targets"] = {n: (asset["target_index"][a:b], asset["target_delta"][a:b].astype(float))
                        for n, a, b in zip(names, off[:-1], off[1:])}
    asset["n_body"] = len(asset["vertices"]) - len(asset["joint_names"])   # the joint centres follow the body
    asset["joints"] = {str(n): asset["n_body"] + k for k, n in enumerate(asset["joint_names"])}
    return asset


def anchor_weights(value: float) -> dict[str, float]:
    """MakeHuman's linear weights of the anchors min / average / max for a macro value in 0..1."""
    if value < 0.5:
        return {"min": 1.0 - 2.0 * value, "average": 2.0 * value, "max": 0.0}
    return {"min": 0.0, "average": 2.0 - 2.0 * value, "max": 2.0 * value - 1.0}


def target_weights(options: BodyOptions) -> dict[str, float]:
    """Target name → weight for a body."""
    m, w = anchor_weights(options.muscle), anchor_weights(options.weight)
    c, f = anchor_weights(options.cup), anchor_weights(options.firmness)
    weights = {f"macrodetails/{race}-female-young": 1.0 / 3.0 for race in ("african", "asian", "caucasian")}
    for mk in LEVELS:
        for wk in LEVELS:
            weights[f"macrodetails/universal-female-young-{mk}muscle-{wk}weight"] = m[mk] * w[wk]
            for ck in LEVELS:
                for fk in LEVELS:
                    if (ck, fk) != ("average", "average"):
                        weights[f"breast/female-young-{mk}muscle-{wk}weight-{ck}cup-{fk}firmness"] = \
                            m[mk] * w[wk] * c[ck] * f[fk]
    for name, value in options.modifiers.items():
        weights[MODIFIERS[name][value > 0]] = abs(value)
    return {k: v for k, v in weights.items() if v > 0.0}


@dataclass(frozen=True)
class Body:
    """A posed body: the closed surface (mm, body frame) and its truth."""

    vertices: np.ndarray       # (N, 3) mm
    faces: np.ndarray          # (F, 3)
    joints: dict               # name → (3,) mm
    options: BodyOptions

    @property
    def nipples(self) -> dict[str, np.ndarray]:
        """Side → the centroid of MakeHuman's nipple ring (mm, body frame)."""
        rings = _asset()["nipple_rings"]
        return {side: self.vertices[ring].mean(0) for side, ring in zip(SIDES, rings)}

    @property
    def sternal_notch(self) -> np.ndarray:
        """The jugular notch: the midpoint of NOTCH_VERTICES (mm, body frame)."""
        return self.vertices[list(NOTCH_VERTICES)].mean(0)

    def half_volumes_cc(self) -> dict[str, float]:
        """Side → exact volume (cc) of the closed body on that side of the mid-sagittal plane X = 0."""
        tri = self.vertices[self.faces]
        area_x = 0.5 * np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])[:, 0]
        x = tri[:, :, 0]
        return {"left": float(area_x @ positive_part_mean(x)) / 1000.0,
                "right": float(-(area_x @ positive_part_mean(-x))) / 1000.0}


def make_body(options: BodyOptions = BodyOptions()) -> Body:
    """The body for `options`: base mesh + blended targets, posed."""
    asset = _asset()
    V = asset["vertices"].astype(float)
    for name, weight in target_weights(options).items():
        index, delta = asset["targets"][name]
        V[index] += weight * delta
    V = _pose(V, asset, *POSES[options.pose])
    joints = {name: V[k] for name, k in asset["joints"].items()}
    return Body(V[:asset["n_body"]], asset["faces"], joints, options)


def blended(left: Body, right: Body, across_mm: float = 30.0) -> Body:
    """One body of two made with the same pose: `left`'s left half (X > 0) and `right`'s right half, joined
    by a smooth step over ±`across_mm` of the mid-sagittal plane (a woman one of whose breasts is another
    cup, say). Its truth is its own: `half_volumes_cc` of the blended mesh."""
    t = np.clip((left.vertices[:, 0] + across_mm) / (2 * across_mm), 0.0, 1.0)
    s = (t * t * (3 - 2 * t))[:, None]
    return Body(s * left.vertices + (1 - s) * right.vertices, left.faces, left.joints, left.options)


def _turn(points: np.ndarray, pivot: np.ndarray, degrees: float) -> np.ndarray:
    """Points turned about the axis Z through `pivot` by `degrees` (counter-clockwise seen from the front)."""
    t = np.radians(degrees)
    R = np.array([[np.cos(t), -np.sin(t), 0.0], [np.sin(t), np.cos(t), 0.0], [0.0, 0.0, 1.0]])
    return (points - pivot) @ R.T + pivot


def _pose(V: np.ndarray, asset: dict, shoulder_deg: float, elbow_deg: float) -> np.ndarray:
    """Linear blend skinning of both arm chains (upper arm about the shoulder, forearm about the elbow)."""
    out = V.copy()
    for k, side in enumerate(SIDES):
        sign = 1.0 if side == "left" else -1.0        # away from the body: +Z turn for the left arm
        arm, fore = asset["arm_weight"][k].astype(float), asset["forearm_weight"][k].astype(float)
        shoulder, elbow = V[asset["joints"][f"{side}-shoulder"]], V[asset["joints"][f"{side}-elbow"]]
        upper = _turn(V, shoulder, sign * shoulder_deg)
        lower = _turn(upper, _turn(elbow[None], shoulder, sign * shoulder_deg)[0], sign * elbow_deg)
        out += (arm - fore)[:, None] * (upper - V) + fore[:, None] * (lower - V)
    return out


def breast_region(side: str) -> np.ndarray:
    """Body vertices of the `side` breast: those MakeHuman's cup and firmness targets move by over 1 mm."""
    asset = _asset()
    moved = [index[(np.linalg.norm(delta, axis=1) > 1.0) & (index < asset["n_body"])]
             for name, (index, delta) in asset["targets"].items() if name.startswith("breast/female-young")]
    region = np.unique(np.concatenate(moved))
    x = asset["vertices"][region, 0]
    return region[x > 0] if side == "left" else region[x < 0]
