"""Her body as one scan saw it: the background-free torso, the scan's viewing frame and the plumb line of
a wall behind her. Both breasts of one recording share it; each side's `Scan` carries it (`Scan.body`).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import BadInputError


@dataclass(frozen=True, eq=False)
class Body:
    """The torso she was scanned as (input frame, mm), the transform to the scan's viewing frame (None:
    not known, her up and facing are then taken from the torso alone), the unit normal of a wall
    behind her (input frame; None: no wall) and her skin's colour at each torso point (None: not recorded)."""

    torso_input: np.ndarray                 # (M, 3)
    input_to_view: np.ndarray | None = None  # (4, 4)
    plumb_input: np.ndarray | None = None    # (3,)
    torso_rgb: np.ndarray | None = None      # (M, 3) uint8 RGB

    def same(self, other: "Body") -> bool:
        """Whether `other` is this body as the same scan saw it (the same torso, in the same frame)."""
        return np.array_equal(self.torso_input, other.torso_input) and \
            np.array_equal(self.input_to_view, other.input_to_view)


def shared_body(bodies: dict[str, Body], where: str | Path | None) -> Body:
    """The one body `bodies` (side → body) share; a case whose sides were scanned from different bodies
    (or recordings) is refused, naming `where`."""
    first, *others = bodies.values()
    if not all(first.same(b) for b in others):
        raise BadInputError(where, "holds sides scanned from different recordings "
                            f"({', '.join(bodies)} do not share one torso): plan each recording in a case of its own")
    return first
