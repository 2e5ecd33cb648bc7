"""Pictures of her (PIL images, drawn off-screen by `plan.raster`): her skin in one plan state from one of
the standard views, with the landmarks, each breast's footprint and her sides marked on it.

Frames: the display frame of `plan.views` (x to her left, y away from a viewer in front of her, z up; mm).
"""
from __future__ import annotations

import importlib.util
from functools import cache
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from . import raster
from .views import State, Views

SKIN_RGB = (236, 188, 160)
LIGHT = tuple(np.array([-0.35, -0.85, 0.4]) / np.linalg.norm([-0.35, -0.85, 0.4]))
"""Her skin is lit from this direction (display frame, seen from the front: in front of her, above and to
the viewer's left); a picture from another view turns the light with its camera."""
SHADE = (0.45, 0.55)
"""A skin colour's share lit by ambient light, and by LIGHT where the surface faces it squarely."""
RECORDED_SHADE = (0.7, 0.45)
"""The same for her skin's recorded colour, which the room's light already shades: lit more gently (a surface
facing LIGHT squarely is drawn a little brighter than recorded)."""

LANDMARK = "#c0392b"
"""The colour of the landmarks the measures start from: sternal notch, midline, the nipples found."""
FOOTPRINT = "#1f5fbf"
"""The colour of each breast's footprint, the outline her volume is measured inside."""
FOLD = "#7b3294"
"""The colour of each breast's inframammary fold."""
VIEWS = {"her right side": -90.0, "her right oblique": -45.0, "front": 0.0, "her left oblique": 45.0,
         "her left side": 90.0}
"""The standard views a surgeon photographs, in the order they are laid out, and the azimuth of each about her
vertical axis (degrees; +: the camera towards her left)."""
PICTURED = ("her right oblique", "front", "her left oblique")
"""The views of her pictures (her handout, summary.png), of VIEWS: her scan holds her front, which from her side is a
ribbon of skin with the camera's gaps, beneath her breasts and at her sides; the report's 3-D view turns to every
view."""
SHOT_PX = (340, 400)
"""Width and height of each picture of the summary and the handout, px."""
STEP_MM = 1.0
"""Outlines are tested for being hidden every this many mm along them."""


@cache
def font(size: int) -> ImageFont.FreeTypeFont:
    """DejaVu Sans (shipped with matplotlib, found without importing it: it has the arrows and dashes the
    pages write) at `size` px; Pillow's own font where it is missing."""
    spec = importlib.util.find_spec("matplotlib")
    path = Path(spec.origin).parent / "mpl-data" / "fonts" / "ttf" / "DejaVuSans.ttf" if spec and spec.origin else None
    return ImageFont.truetype(str(path), size) if path and path.is_file() else ImageFont.load_default(size=size)


STRAY = 0.002
"""A picture's framing may leave out this share of her drawn points at each end of each axis: a stray piece of
the scan (a hand, a fold of cloth) then does not shrink her."""


def skin_colour(views) -> tuple[np.ndarray, tuple[float, float]]:
    """Her skin's colour ((3,) or (T + P, 3), 0..255) and its shade: as recorded, else SKIN_RGB."""
    if views.skin_rgb is None:
        return np.array(SKIN_RGB, float), SHADE
    return views.skin_rgb.astype(float), RECORDED_SHADE


def camera(views: Views, states: list[State], azimuth_deg: float, size: tuple[int, int]) -> raster.Camera:
    """The camera from `azimuth_deg` that holds her torso (but STRAY) in every one of `states` (so that pictures
    of them line up), `size` = (width, height) px."""
    return raster.framing([views.torso, *(st.torso for st in states)], azimuth_deg, *size, stray=STRAY)


def before_after(views: Views, state: State, names=PICTURED) -> dict[str, tuple[Image.Image, Image.Image]]:
    """View name → (her skin as scanned, as `state` plans it), SHOT_PX each, framed alike, unmarked."""
    before = views.state("original")
    shots = {}
    for name in names:
        cam = camera(views, [state], VIEWS[name], SHOT_PX)
        shots[name] = (picture(views, before, cam, marks=False), picture(views, state, cam, marks=False))
    return shots


def picture(views: Views, state: State, cam: raster.Camera, marks: bool = True) -> Image.Image:
    """Her skin moved as `state` plans, seen by `cam`, lit from LIGHT turned with it; with `marks`, the
    landmarks (red), the footprints (blue) and folds (purple) where not hidden behind her (as `state` places them:
    `Views.marks`), and her sides named."""
    vertices = np.concatenate([views.torso, state.torso])
    rgb, shade = skin_colour(views)
    colours = raster.lit(vertices, views.skin, rgb, cam.light(LIGHT), shade)
    drawn = raster.draw(vertices, views.skin, colours, cam)
    image = Image.fromarray(drawn.rgb)
    if marks:
        pen, on = ImageDraw.Draw(image), views.marks(state)
        px = max(2, round(cam.width / 380))
        for outline in on["footprints"].values():
            _line(pen, drawn, np.vstack([outline, outline[:1]]), FOOTPRINT, px)
        _line(pen, drawn, on["landmarks"]["midline"], LANDMARK, px, dash_px=8 * px)
        for fold in on["folds"].values():
            _line(pen, drawn, fold, FOLD, px, tolerance_mm=12.0)
        for name, radius in (("sternal notch", 2.5 * px), ("nipples", 2 * px)):
            points = on["landmarks"][name]
            for (x, y) in cam.project(points)[0][drawn.visible(points)]:
                pen.ellipse((x - radius, y - radius, x + radius, y + radius), fill=LANDMARK)
        _sides(pen, cam)
    return image


def _line(pen: ImageDraw.ImageDraw, drawn: raster.Picture, polyline: np.ndarray, colour: str, width: int,
          dash_px: float = 0.0, tolerance_mm: float = 3.0) -> None:
    """The polyline (K, 3) drawn where it is not hidden behind the surface (by more than `tolerance_mm`);
    dashed every `dash_px` px if given."""
    steps = np.maximum(np.ceil(np.linalg.norm(np.diff(polyline, axis=0), axis=1) / STEP_MM), 1).astype(int)
    t = np.concatenate([np.arange(n) / n + i for i, n in enumerate(steps)] + [[len(steps)]])
    i = np.minimum(t.astype(int), len(polyline) - 2)
    dense = polyline[i] + (t - i)[:, None] * (polyline[i + 1] - polyline[i])
    xy = drawn.camera.project(dense)[0]
    on = drawn.visible(dense, tolerance_mm)
    if dash_px:
        along = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))]
        on &= (along // dash_px) % 2 == 0
    cuts = np.flatnonzero(np.diff(on.astype(int))) + 1
    for run, shown in zip(np.split(xy, cuts), np.split(on, cuts)):
        if shown[0] and len(run) > 1:
            pen.line(run.ravel().tolist(), fill=colour, width=width, joint="curve")


def _sides(pen: ImageDraw.ImageDraw, cam: raster.Camera) -> None:
    """Her right and her left named at the picture's foot, each on its own side (her left is the picture's
    right from the front and the obliques); a side view, which shows one side only, is left unnamed."""
    if abs(cam.azimuth_deg) >= 90:
        return
    size = font(max(12, cam.width // 40))
    pen.text((8, cam.height - 8), "her right", fill="#555555", font=size, anchor="lb")
    pen.text((cam.width - 8, cam.height - 8), "her left", fill="#555555", font=size, anchor="rb")
