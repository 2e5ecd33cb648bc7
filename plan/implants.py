"""Breast implants as a surgeon chooses them: a generic catalogue (no manufacturer's data) and each implant's
shape, its thickness over its base.

A round implant of base width W and projection P is modelled as a solid of revolution on a flat base whose
thickness at distance r from its axis is t(r) = P √(1 − (r/R)⁴), R = W / 2: flat on top, steep at the rim, as a
filled shell is. Its volume is (π² / 4) R² P (∫₀¹ 2ρ √(1 − ρ⁴) dρ = π / 4). An anatomical implant has the same
base and volume with its fullness moved down: t(r) (1 − TEARDROP · y / R), y up from the centre (the tilt
integrates to zero over the disc, so the volume is kept). The catalogue gives, for each profile, the projection
as a share of the base width (PROFILES); from a volume, W = (16 V / (π² k))^(1/3) and P = k W.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from breastplan.options import OptionError

PROFILES = {"low": 0.25, "moderate": 0.32, "high": 0.40, "extra-high": 0.47}
"""Projection / base width of a round implant of each profile: those of the round implants clinics use (a
300 cc moderate implant: 115 mm wide, 37 mm of projection)."""
SHAPES = ("round", "anatomical")
TEARDROP = 0.3
"""An anatomical implant is this much thicker at its lower rim than at its centre, and as much thinner at its
upper rim, as a share of the round implant's thickness there."""
VOLUME_CC = (80.0, 1000.0)
"""The implant volumes the catalogue offers (cc)."""
SHAPE_FACTOR = np.pi ** 2 / 4
"""V = SHAPE_FACTOR · R² · P for the thickness profile above."""


@dataclass(frozen=True)
class Implant:
    """One implant: its volume (cc), base width and projection (mm), shape (round or anatomical)."""

    volume_cc: float
    width_mm: float
    projection_mm: float
    shape: str = "round"

    def __post_init__(self):
        if self.shape not in SHAPES:
            raise OptionError("implant", f"the implant's shape is {' or '.join(SHAPES)}, not '{self.shape}'")
        if not VOLUME_CC[0] <= self.volume_cc <= VOLUME_CC[1]:
            raise OptionError("implant", f"an implant holds {VOLUME_CC[0]:g} to {VOLUME_CC[1]:g} cc, not "
                                         f"{self.volume_cc:g}")
        if not (self.width_mm > 0 and self.projection_mm > 0):
            raise OptionError("implant", "an implant's width and projection are positive lengths in mm")

    @classmethod
    def of(cls, volume_cc: float, profile: str = "moderate", shape: str = "round") -> "Implant":
        """The catalogue's implant of `volume_cc` and `profile` (PROFILES)."""
        if profile not in PROFILES:
            raise OptionError("implant", f"the profile is one of {', '.join(PROFILES)}, not '{profile}'")
        k = PROFILES[profile]
        width = (16.0 * 1000.0 * volume_cc / (np.pi ** 2 * k)) ** (1.0 / 3.0)
        return cls(float(volume_cc), float(width), float(k * width), shape)

    @classmethod
    def sized(cls, width_mm: float, projection_mm: float, shape: str = "round") -> "Implant":
        """An implant of the given base width and projection (mm); its volume follows from its shape."""
        volume = SHAPE_FACTOR * (width_mm / 2.0) ** 2 * projection_mm / 1000.0
        return cls(float(volume), float(width_mm), float(projection_mm), shape)

    def thickness(self, x_mm, y_mm) -> np.ndarray:
        """Its thickness (mm) over its base at (x, y) mm from the base's centre, y up (0 off the base)."""
        R = self.width_mm / 2.0
        x, y = np.asarray(x_mm, float), np.asarray(y_mm, float)
        rho4 = ((x * x + y * y) / (R * R)) ** 2
        centre = 1000.0 * self.volume_cc / (SHAPE_FACTOR * R * R)          # the thickness on the axis
        t = centre * np.sqrt(np.clip(1.0 - rho4, 0.0, None))
        return t * (1.0 - TEARDROP * y / R) if self.shape == "anatomical" else t
