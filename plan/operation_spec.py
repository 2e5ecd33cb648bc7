"""An operation as a surgeon writes it on the command line or in a plan file, and the operation it makes.

    augmentation:VOLUME[:PROFILE][:SHAPE][:POCKET]    augmentation:300:moderate, augmentation:250:high:anatomical
    augmentation:WIDTHxPROJECTION[:SHAPE][:POCKET]    augmentation:115x37:submuscular (mm)
    lift:notch=MM | lift:fold=MM | lift:other         the nipple this far from the sternal notch, this far above
                                                      her fold, or at her other nipple's height
    reduction:VOLUME[:LIFT] | reduction:to=VOLUME[:LIFT]   cc resected, or the volume left; LIFT fold=MM or other
                                                      as for lift, none, or (not given) the lift it needs: a nipple
                                                      below her fold raised to its height
    lumpectomy:VOLUME:CLOCK:DISTANCE[:DEPTH]          cc excised at a clock position (1–12, as the surgeon faces
                                                      her) and a distance from the nipple (mm), its centre DEPTH
                                                      mm beneath her skin

`OperationSpec.parse` checks the words and numbers (an OptionError naming what is wrong: a usage error);
`OperationSpec.operate` makes the operation on her breast (a BadInputError where her scan rules it out).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from breastplan import BadInputError
from breastplan.options import OptionError

from .augmentation import POCKETS, augmentation
from .breast_volume import BreastVolumes
from .implants import PROFILES, SHAPES, Implant
from .lumpectomy import lumpectomy
from .mastopexy import mastopexy, nipple_height, to_notch_distance
from .reduction import reduction
from .skin_lift import SkinLift

KINDS = ("augmentation", "lift", "reduction", "lumpectomy")


@dataclass(frozen=True)
class OperationSpec:
    """One operation as written (`text`): its kind and its settings."""

    kind: str
    settings: dict = field(default_factory=dict)
    text: str = ""

    @classmethod
    def parse(cls, text: str) -> "OperationSpec":
        """The operation `text` names (module docstring); OptionError in one sentence if it names none."""
        kind, *words = [w.strip() for w in str(text).split(":")]
        if kind not in KINDS:
            raise OptionError("operation", f"'{text}' is no operation: write one of {', '.join(KINDS)} (e.g. "
                                           "augmentation:300:moderate)")
        return cls(kind, getattr(cls, f"_{kind}")(text, words), ":".join([kind, *words]))

    @staticmethod
    def _augmentation(text: str, words: list[str]) -> dict:
        if not words:
            raise OptionError("operation", f"'{text}': an augmentation needs the implant's volume (cc) or its width "
                                           "and projection (e.g. augmentation:300 or augmentation:115x37)")
        size, rest = words[0], words[1:]
        out = {"profile": "moderate", "shape": "round", "pocket": "subglandular"}
        if "x" in size:
            out |= {"width_mm": _number(text, size.split("x")[0]), "projection_mm": _number(text, size.split("x")[1])}
        else:
            out["volume_cc"] = _number(text, size)
        kinds = {**dict.fromkeys(PROFILES, "profile"), **dict.fromkeys(SHAPES, "shape"),
                 **dict.fromkeys(POCKETS, "pocket")}
        for word in rest:
            key = kinds.get(word)
            if key is None:
                raise OptionError("operation", f"'{text}': '{word}' is no profile ({', '.join(PROFILES)}), shape "
                                               f"({', '.join(SHAPES)}) or pocket ({', '.join(POCKETS)})")
            out[key] = word
        implant = implant_of(out)                                       # its own checks: volume range, sizes
        return out | {"volume_cc": implant.volume_cc}

    @staticmethod
    def _lift(text: str, words: list[str]) -> dict:
        if len(words) != 1:
            raise OptionError("operation", f"'{text}': a lift takes one target: notch=MM, fold=MM or other")
        return _lift_target(text, words[0])

    @staticmethod
    def _reduction(text: str, words: list[str]) -> dict:
        if not words or len(words) > 2:
            raise OptionError("operation", f"'{text}': a reduction takes the cc resected (or to=CC) and an optional "
                                           "lift target")
        out = ({"to_volume_cc": _number(text, words[0][3:])} if words[0].startswith("to=")
               else {"volume_cc": _number(text, words[0])})
        lift = ({"lift": "needed"} if len(words) == 1 else {"lift": "none"} if words[1] == "none"
                else _lift_target(text, words[1]))
        if lift.get("lift") == "notch":
            raise OptionError("operation", f"'{text}': a reduction's lift is fold=MM or other (for a distance from "
                                           "the notch, plan the lift on its own)")
        return out | lift

    @staticmethod
    def _lumpectomy(text: str, words: list[str]) -> dict:
        if len(words) not in (3, 4):
            raise OptionError("operation", f"'{text}': a lumpectomy takes VOLUME:CLOCK:DISTANCE[:DEPTH] (e.g. "
                                           "lumpectomy:40:10:30, or lumpectomy:40:10:30:15)")
        volume, clock, distance, *depth = (_number(text, w) for w in words)
        if not 0.0 < clock <= 12.0:
            raise OptionError("operation", f"'{text}': the clock position lies in 1–12, as the surgeon faces her")
        return {"volume_cc": volume, "clock": clock, "distance_mm": distance} | (
            {"depth_mm": depth[0]} if depth else {})

    @property
    def words(self) -> str:
        """The operation in a surgeon's words."""
        s = self.settings
        if self.kind == "augmentation":
            implant = implant_of(s)
            return (f"an implant of {implant.volume_cc:.0f} cc ({implant.width_mm:.0f} × {implant.projection_mm:.0f} "
                    f"mm), {s['shape']}, {'behind the muscle' if s['pocket'] == 'submuscular' else 'behind the gland'}")
        if self.kind == "lumpectomy":
            return (f"an excision of {s['volume_cc']:g} cc at {s['clock']:g} o'clock, {s['distance_mm']:g} mm from the "
                    "nipple" + (f", {s['depth_mm']:g} mm deep" if "depth_mm" in s else ""))
        lift = _lift_words(s)
        if self.kind == "lift":
            return f"a lift: {lift}"
        cut = f"to {s['to_volume_cc']:g} cc" if "to_volume_cc" in s else f"of {s['volume_cc']:g} cc"
        return f"a reduction {cut}" + ("" if lift is None else f", with {lift}" if s["lift"] == "needed"
                                       else f", with a lift: {lift}")

    def operate(self, volumes: BreastVolumes, nipples: dict, side: str, fold_below_nipple_mm: float) -> SkinLift:
        """This operation on her `side` breast (`nipples` side → (3,) input frame; her fold `fold_below_nipple_mm`
        below that nipple)."""
        s, nipple = self.settings, nipples[side]
        if self.kind == "augmentation":
            return augmentation(volumes, side, nipple, fold_below_nipple_mm, implant_of(s), s["pocket"])
        if self.kind == "lumpectomy":
            return lumpectomy(volumes, side, nipple, s["volume_cc"], s["clock"], s["distance_mm"], s.get("depth_mm"))
        if self.kind == "reduction":
            height = (_height(volumes, nipples, side, fold_below_nipple_mm, s) if s["lift"] in ("fold", "other")
                      else _needed(volumes, nipple, fold_below_nipple_mm) if s["lift"] == "needed" else None)
            cut = {"volume_cc": s.get("volume_cc"), "to_volume_cc": s.get("to_volume_cc")}
            if s["lift"] != "needed" or height is None:
                return reduction(volumes, side, nipple, **cut, nipple_height_mm=height)
            reduction(volumes, side, nipple, **cut)                  # the resection alone: its own refusals first
            try:
                return reduction(volumes, side, nipple, **cut, nipple_height_mm=height)
            except BadInputError as exc:
                raise BadInputError(None, f"{exc.problem}: the lift this reduction needs (her {side} nipple to her "
                                          f"fold's height) is out of reach; give it a lift (fold=MM) or none "
                                          f"({self.text}:none)") from None
        if s["lift"] == "notch":
            return to_notch_distance(volumes, side, nipple, s["mm"])
        return mastopexy(volumes, side, nipple, _height(volumes, nipples, side, fold_below_nipple_mm, s))


def written_operations(left, right) -> tuple[tuple[str, str], ...]:
    """(side, operation as `OperationSpec.parse` reads it) for each of `left`, then of `right`, in order; an
    OptionError whose option is the side, naming the first that is no operation."""
    out = []
    for side, texts in (("left", left), ("right", right)):
        for text in texts:
            try:
                out.append((side, OperationSpec.parse(text).text))
            except OptionError as exc:
                raise OptionError(side, str(exc)) from None
    return tuple(out)


def _number(text: str, word: str) -> float:
    try:
        value = float(word)
    except ValueError:
        raise OptionError("operation", f"'{text}': '{word}' is not a number") from None
    if not (np.isfinite(value) and value > 0):
        raise OptionError("operation", f"'{text}': {word} must be a positive number")
    return value


def _lift_target(text: str, word: str) -> dict:
    if word == "other":
        return {"lift": "other"}
    key, _, value = word.partition("=")
    if key not in ("notch", "fold"):
        raise OptionError("operation", f"'{text}': a lift's target is notch=MM, fold=MM or other, not '{word}'")
    return {"lift": key, "mm": _number(text, value)}


def _needed(volumes: BreastVolumes, nipple_mm, fold_below_nipple_mm: float) -> float | None:
    """The nipple height (body frame y, mm) a reduction's lift needs: her fold's, where her nipple lies below it (the
    projection of her fold on her breast, where a reduction places the nipple); None where it lies above."""
    if fold_below_nipple_mm >= 0.0:
        return None
    nipple = volumes.in_body(nipple_mm)
    return nipple_height(nipple, above_fold_mm=0.0, fold_below_nipple_mm=fold_below_nipple_mm)


def _lift_words(settings: dict) -> str | None:
    if settings["lift"] == "none":
        return None
    if settings["lift"] == "needed":
        return "the lift it needs (her nipple to her fold's height, where it lies below it)"
    if settings["lift"] == "other":
        return "the nipple to her other nipple's height"
    where = "from the sternal notch" if settings["lift"] == "notch" else "above her fold"
    return f"the nipple {settings['mm']:g} mm {where}"


def implant_of(settings: dict) -> Implant:
    """The implant an augmentation's settings name (`OperationSpec.settings`)."""
    if "width_mm" in settings:
        return Implant.sized(settings["width_mm"], settings["projection_mm"], settings["shape"])
    return Implant.of(settings["volume_cc"], settings["profile"], settings["shape"])


def _height(volumes: BreastVolumes, nipples: dict, side: str, fold_below_nipple_mm: float, settings: dict) -> float:
    """The nipple height (body frame y, mm) a lift target asks for."""
    body = {s: volumes.in_body(n) for s, n in nipples.items()}
    if settings["lift"] == "fold":
        return nipple_height(body[side], above_fold_mm=settings["mm"], fold_below_nipple_mm=fold_below_nipple_mm)
    return nipple_height(body[side], as_nipple_body=body["right" if side == "left" else "left"])
