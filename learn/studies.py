"""The thesis's studies and feature sets as plain data (thesis Table 4.3, chapter 5.1). No numpy,
no scikit-learn: the `breastplan evaluate` command builds its options and help from them without
loading the study (`learn.study` runs it, `learn.features` computes the features).
"""
from __future__ import annotations

from dataclasses import dataclass

FEATURE_SETS = {
    "REF": ("M0", "Mdisplacement"), "FS1": ("D0",), "FS2": ("D0", "M0"), "FS3": ("M0",),
    "FS4": (), "FS5": ("d0", "m0"),
}
"""Feature set → its features besides DD and v0 (thesis Table 4.3)."""


@dataclass(frozen=True)
class Study:
    database: str
    conditions: tuple[str, ...]
    feature_sets: tuple[str, ...]   # the thesis configurations run with the discrete degree


STUDIES = {
    "ptosis-V": Study("V", ("ptosis b0", "ptosis b1", "ptosis b0>b1", "ptosis b1>=b0"), tuple(FEATURE_SETS)),
    "ptosis-S": Study("S", ("ptosis b0>b1", "ptosis b1>=b0"), ("REF", "FS4", "FS5")),
    "turn-S": Study("S", ("turn c0>c1", "turn c1>c0"), ("REF", "FS4", "FS5")),
    "top-shape-S": Study("S", ("top-shape s0->s1+", "top-shape s1->s0+"), ("REF", "FS4", "FS5")),
}
"""Database S studies run the thesis's own FS5 (its Tables 5.5–5.7), FS4 and the REF bound."""
