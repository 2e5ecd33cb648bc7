"""A breast's operations made in turn on her skin: each as written (`plan.operation_spec`), as made (`SkinLift`),
and the breast they leave her (her volume on her skin, her nipple).

Each operation is made on her skin as the ones before it left it: her skin's heights over the cells raised or
lowered by them, her footprint grown over what they raise, her nipple where they moved it, her fold at the height
it was found. Her volume after is hers as measured plus each operation's own change (her skin's volume over the
footprint it is measured in, after less before), so that what her grown footprint takes in of her skin as she
is does not count as operated. A lift to her other nipple ("lift:other", a reduction's
"other") aims at her other nipple as scanned.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .breast_volume import BreastVolumes
from .operation_spec import OperationSpec
from .skin_lift import SkinLift
from .symmetry import ptosis_from_cells


@dataclass(frozen=True, eq=False)
class Operated:
    """One breast's operations, in order, and what they bring it to: her volume on her skin before and after (cc),
    her nipple after (input frame, mm)."""

    side: str
    written: tuple[OperationSpec, ...]
    made: tuple[SkinLift, ...]
    volume_before_cc: float
    volume_cc: float
    nipple_before_mm: np.ndarray          # (3,) input frame
    nipple_mm: np.ndarray                 # (3,) input frame, after
    note: str | None = None               # what a symmetrising proposal leaves unmatched, in words
    ptosis: dict | None = None            # her breast's Regnault grade as scanned (`symmetry.ptosis_from_cells`)

    def __call__(self, points_mm) -> np.ndarray:
        """Input-frame points (mm) as the operations, in turn, move them."""
        points = np.asarray(points_mm, float)
        for operation in self.made:
            points = operation(points)
        return points

    def displacement(self, points_mm) -> np.ndarray:
        """(N, 3) how far the operations move input-frame points, input frame, mm."""
        points = np.asarray(points_mm, float).reshape(-1, 3)
        return self(points) - points

    @property
    def words(self) -> str:
        """The operations in a surgeon's words, in the order made, each made by a clinic's model named ("" for
        none)."""
        return "; then ".join(_as_made(spec, op) for spec, op in zip(self.written, self.made))

    @property
    def texts(self) -> tuple[str, ...]:
        """Each operation as written, in the order made, each made by a clinic's model named."""
        return tuple(spec.text + (f" (by {op.made_by})" if op.made_by else "")
                     for spec, op in zip(self.written, self.made))

    @property
    def warnings(self) -> tuple[str, ...]:
        """What a surgeon is warned of, in a surgeon's words: a lumpectomy's excised share; a lift of a breast that
        shows no ptosis as scanned (Regnault grade 0: a lift is made for a breast that hangs)."""
        made = tuple(w for w in (getattr(op, "warning", None) for op in self.made) if w)
        if self.ptosis is None or self.ptosis["grade"] != "0" or self.ptosis["nipple_to_fold_mm"] is None:
            return made
        unhung = (f"her {self.side} breast shows no ptosis as scanned (Regnault grade 0: its nipple "
                  f"{self.ptosis['nipple_to_fold_mm']:.0f} mm above her fold); this lift raises a nipple that does not "
                  "hang")
        return made + tuple(unhung + (f", by {op.rise_mm:.0f} mm" if hasattr(op, "rise_mm") else "")
                            for spec, op in zip(self.written, self.made) if spec.kind == "lift")

    @property
    def notes(self) -> tuple[str, ...]:
        """What a surgeon is told of how the plan was made: a proposal's unmatched part, a clinic's model's pairs not
        reaching her."""
        return tuple(n for n in (self.note, *(getattr(op, "note", None) for op in self.made)) if n)

    @property
    def nipple_moved_mm(self) -> float:
        """How far the operations move her nipple (mm)."""
        return float(np.linalg.norm(self.nipple_mm - self.nipple_before_mm))

    @property
    def nipple_move(self) -> dict[str, float]:
        """The operations' move of her nipple in her body frame (mm): `up`, `forward` and `outward` (away from her
        midline; < 0: down, back, towards it)."""
        if not self.made:
            return {"up": 0.0, "forward": 0.0, "outward": 0.0}
        x, y, z = self.made[0].body_from_input[:3, :3] @ (self.nipple_mm - self.nipple_before_mm)
        return {"up": float(y), "forward": float(z), "outward": float(x if self.side == "left" else -x)}

    @property
    def nipple_move_words(self) -> str:
        """Her nipple's move in words, each direction of 1 mm or more, largest first ("62 mm up, 3 mm forward");
        "under 1 mm" when it moves less in every direction."""
        names = {"up": ("up", "down"), "forward": ("forward", "back"), "outward": ("outward", "towards her midline")}
        parts = sorted(((abs(v), names[k][v < 0]) for k, v in self.nipple_move.items() if abs(v) >= 1.0),
                       reverse=True)
        return ", ".join(f"{v:.0f} mm {w}" for v, w in parts) or "under 1 mm"

    def as_dict(self) -> dict:
        """plan.json's record of the operations: each as written, her volume and nipple before and after."""
        return {"operations": [{"written": spec.text, "kind": spec.kind, **spec.settings,
                                **({"model": op.made_by} if op.made_by else {})}
                               for spec, op in zip(self.written, self.made)],
                "volume_before_cc": round(self.volume_before_cc, 1), "volume_after_cc": round(self.volume_cc, 1),
                "volume_change_cc": round(self.volume_cc - self.volume_before_cc, 1),
                "nipple_after_input_mm": [round(float(v), 2) for v in self.nipple_mm],
                "nipple_moved_mm": round(self.nipple_moved_mm, 1),
                "nipple_move_mm": {k: round(v, 1) for k, v in self.nipple_move.items()},
                "warnings": list(self.warnings),
                "note": "; ".join(self.notes) or None}


def _as_made(spec: OperationSpec, op) -> str:
    """One operation in a surgeon's words as made: the clinic's model that made it named; a reduction's lift "it
    needs" said to be none where her nipple lies above her fold."""
    if op.made_by:
        return spec.words + f" (as {op.made_by} makes it, from its volume alone)"
    if spec.kind == "reduction" and spec.settings["lift"] == "needed" and op.lift is None:
        return spec.words + "; none needed: her nipple lies above her fold"
    return spec.words


def said(operated: Operated, measures) -> tuple[str, ...]:
    """What the plan says of one side's operations: its warnings, each with the measures it names as the plan
    finds them before → after (`plan.result.Measures`: pBRA, the volume's left − right), and its notes."""
    sym, asym = measures.symmetry, measures.asymmetry
    figures = []
    if sym.get("before", {}).get("pBRA_pct") is not None and sym.get("after", {}).get("pBRA_pct") is not None:
        figures.append(f"pBRA {sym['before']['pBRA_pct']:.1f} → {sym['after']['pBRA_pct']:.1f} %")
    if asym:
        figures.append(f"volume left − right {asym['before']['volume_cc']:+.0f} → {asym['after']['volume_cc']:+.0f} cc")
    here = f" (this plan: {', '.join(figures)})" if figures else ""
    return tuple(w + here for w in operated.warnings) + operated.notes


def operate(volumes: BreastVolumes, nipples: dict, side: str, fold_below_nipple_mm: float,
            written: tuple[OperationSpec, ...], models: dict | None = None) -> Operated:
    """The operations `written` made in turn on her `side` breast (module docstring): `nipples` side → (3,) input
    frame, as scanned; her fold `fold_below_nipple_mm` below the `side` nipple; `models`: operation kind → a clinic's
    model that makes it (`plan.learnt_operation.OperationModel`) in place of the built-in one."""
    models = models or {}
    start = np.asarray(nipples[side], float)
    fold_mm, nipple, made, now = volumes.in_body(start)[1] - fold_below_nipple_mm, start, [], volumes
    for spec in written:
        done = (models[spec.kind].operate(now, nipple, side, spec) if spec.kind in models
                else spec.operate(now, {**nipples, side: nipple}, side, volumes.in_body(nipple)[1] - fold_mm))
        grown = replace(now.cells, footprint=now.cells.footprint | done.footprint)
        cells = replace(grown, height_mm=done.heights(grown.height_mm))
        volume = now.sides[side].volume_cc + cells.volume_cc(side) - grown.volume_cc(side)   # its own change
        now = replace(now, cells=cells, sides={**now.sides, side: replace(now.sides[side], volume_cc=volume)})
        nipple = done(nipple[None])[0]
        made.append(done)
    return Operated(side, tuple(written), tuple(made), volumes.sides[side].volume_cc, now.sides[side].volume_cc,
                    start, nipple, ptosis=ptosis_from_cells(volumes.in_body(start), volumes.cells, side))
