"""An operation as a clinic's own before/after pairs show it: a statistical model of how one operation changes her
skin, learnt from scans of the women it was made on, that makes that operation in a plan in place of the built-in
model (`plan --operation-model MODEL.npz`).

Measured as her volume is (`plan.breast_volume`: her skin over 5 mm cells of her body frame):

1. **What a pair shows**: her skin after less her skin before, along her anterior axis, over a square of GRID_MM
   around her nipple before (each scan in its own body frame, found from her body: the sternal notch its origin),
   the square turned so that u runs from her midline outwards: a left and a right breast share one field. Of an
   augmentation, the rise is learnt (mm: an implant adds its thickness whatever lies over it); of a reduction, the
   share of her tissue taken at each place (the fall over her skin's height above the wall, each summed round the
   place over a Gaussian of σ SHARE_SIGMA_MM: a cell her camera saw at a grazing angle holds a height of a few
   points), which is then laid on her own tissue, as the built-in reduction takes it.
2. **What is learnt** (`learn.statistical.FieldModel`): the PCA modes of these fields and a regressor of their
   weights from her signed volume change (cc: an implant's volume, a resection's less) and her breast's volume on
   her skin before it (cc).
3. **Made on her**: the field predicted for her is laid on her cells round her nipple (a reduction's share times
   her own skin's height above the wall), its part of the operation's sign kept (an implant raises her skin, a
   resection lowers it: the rest is the pairs' scans differing), her footprint grown over the skin it raises, and
   scaled so that her volume on her skin changes by the operation's volume exactly (`plan.skin_lift.scaled`), as
   the built-in operations are; a fall stops at her chest wall (where her volume counts no height below it).
4. **Her nipple**: where the pairs show it move across her body (down and outwards under a larger breast), in
   proportion to the volume change, fitted by least squares. Her skin slides with it, by the nipple's shift
   times a Gaussian of the distance from her nipple (σ SLIDE_MM), and comes forward or back onto the changed
   surface, so that the areola travels with the nipple (as a lift moves her skin, `plan.mastopexy`). Away from the
   nipple the slide fades where her skin turns away from the front (times cos² of its tilt over the cells, but not
   below the square of the Gaussian): a height field holds her front, not the underside of a breast curling back
   beneath it, which, slid whole, tore in oblique views.

The model does not extrapolate: for a woman whose volume or change lies outside the pairs', the skin change is
shaped as at the nearest of their range (and still scaled to her change exactly), and the plan says so (`note`).

Learnt: augmentation and reduction. A lift's change is a sliding of her skin that a height field does not hold, and
a lumpectomy's is tied to a place on her breast.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage

from breastplan import ArtefactError, BadInputError, transform_points
from breastplan.model_file import ModelFile, load_model, save_model

from .breast_volume import CELL_MM, FOOT_MM, BreastVolumes
from .operation_spec import OperationSpec, implant_of
from .skin_lift import SkinLift, facing, scaled

OPERATION = "operation"
"""A model file's `model`: an operation's model (a deformation's statistical model is "statistical")."""
LEARNT = ("augmentation", "reduction")
GRID_MM = 120.0
"""The field is learnt over u, v in [−GRID_MM, GRID_MM] round her nipple (mm)."""
AXIS = np.arange(-GRID_MM, GRID_MM + CELL_MM / 2, CELL_MM)
FEATURES = ("volume change, cc", "her volume before, cc")
SLIDE_MM = 40.0
"""σ of the Gaussian her skin slides with her nipple by (mm)."""
SHARE_SIGMA_MM = CELL_MM
"""σ of the Gaussian a reduction's fall and her tissue's height are summed over round each place (mm): the share
of one cell's, a few points at the side of her breast against a height of a few millimetres, is noise."""


@dataclass(frozen=True, eq=False, kw_only=True)
class LearntOperation(SkinLift):
    """An operation made by a clinic's model (`SkinLift`: her skin's change over the cells, the footprint it is
    measured in), with the operation as written and the model that made it."""

    spec: OperationSpec
    side: str
    model: str                       # the model file's name
    nipple_mm: np.ndarray            # (2,) her nipple before, (x, y) body frame
    shift_mm: np.ndarray             # (2,) how far it moves across her body, (x, y) body frame
    surface_mm: np.ndarray           # (nx, ny) her skin's anterior coordinate before, body frame
    note: str | None = None          # where she lies outside the pairs it learnt from

    @property
    def made_by(self) -> str | None:
        return self.model

    def displacement(self, points_mm) -> np.ndarray:
        """(N, 3) how far input-frame points of her skin move (across her body with her nipple, and forward or back
        onto the changed surface), input frame, mm."""
        T = self.body_from_input
        body = transform_points(T, np.asarray(points_mm, float).reshape(-1, 3))
        near = np.exp(-0.5 * np.sum((body[:, :2] - self.nipple_mm) ** 2, axis=1) / SLIDE_MM ** 2)
        surface = self.sampled(self.surface_mm, body, "nearest")
        ahead = self.sampled(facing(self.surface_mm), body, "nearest")
        slide = near * np.maximum(ahead, near ** 2)                            # the nipple and areola slide whole
        across = np.outer(slide * (np.sign(body[:, 0]) == _outwards(self.side)), self.shift_mm)
        forward = self.sampled(self.surface_mm + self.lift_mm, body[:, :2] + across, "nearest") - surface
        return np.column_stack([across, forward]) @ T[:3, :3]                  # body → input frame


def signed_change_cc(spec: OperationSpec, volume_before_cc: float) -> float:
    """How much an operation changes her breast's volume (cc, < 0 for a reduction), as written."""
    s = spec.settings
    if spec.kind == "augmentation":
        return implant_of(s).volume_cc
    if spec.kind == "reduction":
        return -float(s["volume_cc"] if "volume_cc" in s else volume_before_cc - s["to_volume_cc"])
    raise ValueError(f"no learnt model makes a {spec.kind}")


@dataclass(frozen=True, eq=False)
class Pair:
    """One breast before and after an operation: her torso measured on her skin before and after it, her nipple
    before and after (each in its scan's input frame, mm), the side, the operation as written, and the group it
    belongs to in cross-validation (her scan before, say)."""

    before: BreastVolumes
    after: BreastVolumes
    nipple_mm: np.ndarray
    nipple_after_mm: np.ndarray      # (3,) her nipple after, input frame of the scan after
    side: str
    spec: OperationSpec
    group: str

    @property
    def volume_before_cc(self) -> float:
        return self.before.sides[self.side].volume_cc

    def nipple_shift(self) -> np.ndarray:
        """(2,) how far her nipple moved across her body (u outwards, v up; mm), each scan's in its own body frame."""
        return _across(self.after.in_body(self.nipple_after_mm) - self.before.in_body(self.nipple_mm), self.side)

    def skin_change(self) -> np.ndarray:
        """(len(AXIS), len(AXIS)) her skin after less before along her anterior axis (mm), at u (outwards from her
        midline), v (up) round her nipple before; each scan's skin in its own body frame; 0 off either's cells."""
        centre = self.before.in_body(self.nipple_mm)
        return np.nan_to_num(_skin_at(self.after, centre, self.side) - _skin_at(self.before, centre, self.side))

    def learnt(self) -> np.ndarray:
        """(len(AXIS), len(AXIS)) what a model learns of this pair: an augmentation's rise of her skin (mm); a
        reduction's share of her tissue taken at each place (her skin's fall over its height above the wall, each
        summed round it over a Gaussian of σ SHARE_SIGMA_MM, the height at least FOOT_MM: −1..0)."""
        change = self.skin_change()
        if self.spec.kind == "augmentation":
            return change
        height = np.nan_to_num(_skin_at(self.before, self.before.in_body(self.nipple_mm), self.side, wall=False))
        fall, tissue = (ndimage.gaussian_filter(a, SHARE_SIGMA_MM / CELL_MM, mode="nearest") for a in (change, height))
        return np.clip(fall / np.maximum(tissue, FOOT_MM), -1.0, 0.0)


def features(change_cc: float, volume_before_cc: float) -> np.ndarray:
    """(1, 2) the regressor's inputs (FEATURES)."""
    return np.array([[change_cc, volume_before_cc]], float)


@dataclass(frozen=True)
class OperationModel:
    """A loaded operation model: the operation it makes, and its file."""

    model: ModelFile
    path: Path

    @property
    def kind(self) -> str:
        return str(self.model.meta["kind"])

    @property
    def pairs(self) -> int:
        return int(self.model.meta["training"]["pairs"])

    def field(self, change_cc: float, volume_before_cc: float) -> np.ndarray:
        """(len(AXIS), len(AXIS)) the skin change predicted for her (mm), over u, v round her nipple; inputs outside
        the pairs' range taken at its nearest end."""
        X = np.clip(features(change_cc, volume_before_cc), *self.model.extra["range"])
        weights = self.model.predict(X).reshape(1, -1)
        return (weights @ self.model.extra["components"] + self.model.extra["mean"])[0].reshape(AXIS.size, AXIS.size)

    def nipple_shift(self, change_cc: float) -> np.ndarray:
        """(2,) how far her nipple moves across her body (u outwards, v up; mm) for a volume change (cc)."""
        return change_cc * self.model.extra["nipple"]

    def outside(self, change_cc: float, volume_before_cc: float) -> str | None:
        """Where her change or her volume lies outside the pairs' (a note in words), else None."""
        lo, hi = self.model.extra["range"]
        said = [f"{name} {value:.0f} cc lies outside the pairs' {a:.0f}–{b:.0f} cc"
                for name, value, a, b in zip(("the change", "her volume"), (change_cc, volume_before_cc), lo, hi)
                if not a <= value <= b]
        return (f"{self.path.name} learnt from {self.pairs} breasts: {' and '.join(said)}; shaped as the nearest "
                "of them") if said else None

    def operate(self, volumes: BreastVolumes, nipple_mm, side: str, spec: OperationSpec) -> LearntOperation:
        """`spec` made on her `side` breast by this model (module docstring); `nipple_mm` (3,) input frame.
        BadInputError where her breast rules it out (a resection no smaller than it)."""
        cells, breast = volumes.cells, volumes.sides[side].volume_cc
        change = signed_change_cc(spec, breast)
        if spec.kind == "reduction" and not -breast < change < 0.0:
            raise BadInputError(None, f"gives a resection of {-change:g} cc from her {side} breast of {breast:.0f} cc "
                                      "on her skin: a reduction takes more than nothing and less than the breast")
        nipple = volumes.in_body(nipple_mm)
        U, V = np.meshgrid((cells.x - nipple[0]) * _outwards(side), cells.y - nipple[1], indexing="ij")
        at = np.stack([(U - AXIS[0]) / CELL_MM, (V - AXIS[0]) / CELL_MM])
        shape = ndimage.map_coordinates(self.field(change, breast), at, order=1, mode="constant", cval=0.0)
        half = (cells.x > 0 if side == "left" else cells.x < 0)[:, None]
        shape = np.where(half, np.clip(shape, 0.0, None) if change > 0 else
                         np.clip(shape, -1.0, 0.0) * np.clip(cells.height_mm, 0.0, None), 0.0)
        raised = half & (cells.height_mm + shape > FOOT_MM) & (change > 0)   # a resection raises no skin
        grown = ndimage.binary_propagation(cells.side(side), mask=cells.side(side) | raised)
        lift = scaled(cells, side, np.where(grown, shape, 0.0), grown, change)
        lift = np.maximum(lift, -np.clip(cells.height_mm, 0.0, None))     # to her wall: her volume counts no less
        return LearntOperation(cells.x, cells.y, lift, grown, volumes.body_from_input, spec=spec, side=side,
                               model=self.path.name, nipple_mm=nipple[:2],
                               shift_mm=_across(self.nipple_shift(change), side),
                               surface_mm=cells.wall_mm + cells.height_mm, note=self.outside(change, breast))


def load_operation_model(path: str | Path) -> OperationModel:
    """An operation model file (`train`); ArtefactError naming it if it is not one or is inconsistent."""
    path = Path(path)
    model = load_model(path)
    meta, extra = model.meta, model.extra
    if meta.get("model") != OPERATION:
        raise ArtefactError(path, "is no operation's model (train-statistical writes one from a folder of "
                                  "before/after pairs of one operation)")
    mean, components = extra.get("mean"), extra.get("components")
    nipple, bounds = extra.get("nipple"), extra.get("range")
    if (meta.get("kind") not in LEARNT or mean is None or components is None or mean.shape != (AXIS.size ** 2,)
            or components.shape != (model.n_outputs, mean.size) or model.n_features != len(FEATURES)
            or nipple is None or nipple.shape != (2,) or bounds is None or bounds.shape != (2, len(FEATURES))
            or not (bounds[0] <= bounds[1]).all()
            or not isinstance(meta.get("training", {}).get("pairs"), int)):
        raise ArtefactError(path, "holds an inconsistent operation model (its operation, modes or features)")
    return OperationModel(model, path)


def operation_models(paths) -> dict[str, OperationModel]:
    """The operation models of the files `paths`, by the operation each makes; ArtefactError naming a file that is
    no operation model, BadInputError naming a second model of one operation."""
    out: dict[str, OperationModel] = {}
    for path in paths:
        model = load_operation_model(path)
        if model.kind in out:
            raise BadInputError(model.path, f"makes {model.kind}s, as {out[model.kind].path} does: give one model "
                                            "per operation")
        out[model.kind] = model
    return out


def train(pairs: list[Pair], regressor: str = "kernel-ridge"):
    """One operation learnt from `pairs`: (the FieldModel of what each pair shows, `Pair.learnt`; the nipple's shift
    per cc of change (2,); the features' least and most (2, features); the file's metadata), for `save`. The
    FieldModel's hyper-parameters are chosen by 4-fold cross-validation grouped by the pairs' `group` when there
    are at least 4 groups."""
    from breastplan.learn.statistical import FieldModel
    from breastplan.learn.statistical_study import GRIDS, grid_select

    pairs = sorted(pairs, key=lambda p: (p.group, p.side))        # the folds and the fit, whatever the table's order
    kinds = {p.spec.kind for p in pairs}
    if len(kinds) != 1 or not kinds <= set(LEARNT):
        raise ValueError(f"one operation's pairs are learnt at a time, of {' or '.join(LEARNT)}; got {sorted(kinds)}")
    fields = np.stack([p.learnt().ravel() for p in pairs])
    X = np.concatenate([features(signed_change_cc(p.spec, p.volume_before_cc), p.volume_before_cc) for p in pairs])
    groups = np.array([p.group for p in pairs])
    nipple = np.linalg.lstsq(X[:, :1], np.stack([p.nipple_shift() for p in pairs]), rcond=None)[0][0]
    if len(set(groups)) >= 4:
        est, hyper, cv = grid_select(FieldModel(regressor), GRIDS[regressor], X, fields, groups)
    else:
        est, hyper, cv = FieldModel(regressor).fit(X, fields), {}, float("nan")
    meta = {"model": OPERATION, "kind": kinds.pop(), "regressor": regressor, "features": list(FEATURES),
            "hyper": {k: float(v) for k, v in hyper.items()}, "cv_rmse": cv / 100.0,
            "grid_mm": GRID_MM, "cell_mm": CELL_MM,
            "target": "PCA weights of what a pair shows round her nipple: an augmentation's rise of her skin (mm), a "
                      "reduction's share of her tissue taken (−1..0)",
            "training": {"pairs": len(pairs), "women": len(set(groups))}}
    return est, nipple, np.stack([X.min(axis=0), X.max(axis=0)]), meta


def save(path: str | Path, trained: tuple) -> Path:
    """Write a trained operation model (`train`'s) as a `breastplan.model/1` file, atomically."""
    estimator, nipple, bounds, meta = trained
    return save_model(path, estimator.weights_, meta=meta, extra={
        "mean": estimator.pca_.mean_, "components": estimator.pca_.components_, "nipple": nipple, "range": bounds})


def _outwards(side: str) -> float:
    return 1.0 if side == "left" else -1.0


def _across(shift, side: str) -> np.ndarray:
    """(2,) a shift's (x, y) in her body frame as (u, v) outwards and up, or back: the same map both ways."""
    return np.array([_outwards(side) * shift[0], shift[1]], float)


def _skin_at(volumes: BreastVolumes, centre: np.ndarray, side: str, wall: bool = True) -> np.ndarray:
    """Her skin's anterior coordinate (body frame, mm; or, not `wall`, its height above the wall) at u, v round
    `centre`: bilinear over her cells, the wall's where no skin was seen on either side, NaN off the cells."""
    cells = volumes.cells
    U, V = np.meshgrid(AXIS, AXIS, indexing="ij")
    at = np.stack([(centre[0] + _outwards(side) * U - cells.x[0]) / CELL_MM, (centre[1] + V - cells.y[0]) / CELL_MM])
    skin = ndimage.map_coordinates(cells.height_mm + cells.wall_mm * wall, at, order=1, mode="nearest")
    inside = (at >= 0).all(0) & (at[0] <= cells.x.size - 1) & (at[1] <= cells.y.size - 1)
    return np.where(inside, skin, np.nan)
