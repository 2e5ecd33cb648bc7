"""summary.png: a page of the plan for the patient's file — her torso before and as the report first shows it,
from her right oblique, the front and her left oblique (`plan.pictures`), the main measures in words below."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from .measures import measure_label
from .pictures import camera, font, picture
from .result import Plan
from .views import State, Views

VIEWS = {"her right oblique": -45.0, "front": 0.0, "her left oblique": 45.0}
"""The summary's columns and their azimuths (degrees; `plan.pictures.VIEWS`)."""
PICTURE_PX = (400, 440)
"""Each picture's width and height, px."""
MEASURES = ("volume_cc", "notch_to_nipple_mm", "nipple_to_midline_mm", "nipple_to_fold_mm", "pole_ratio")
"""The measures the summary lists, before → as planned, for each side."""
DISCLAIMER = "A simulation of a planned change on her scanned body: a guide for discussion, not a promise of the result."
HEAD_PX, LABEL_PX, FOOT_PX = 90, 28, 220
"""Heights of the title band, of the row labels' column (its width) and of the measures below, px."""


def original(views: Views) -> State:
    """Her body as scanned: the state with nothing moved."""
    return State("original", None, None, {s: m[0] for s, m in views.meshes.items()}, views.patch)


def summary_png(plan: Plan, views: Views, path: Path) -> Path:
    """Write summary.png: her torso before (top row) and as first shown (bottom row) from each of VIEWS,
    framed alike; the state shown, the main measures of each side and the disclaimer in words."""
    shown = next(st for st in views.states if st.key == plan.shown.key)
    w, h = PICTURE_PX
    page = Image.new("RGB", (LABEL_PX + w * len(VIEWS), HEAD_PX + 2 * h + FOOT_PX), "white")
    pen = ImageDraw.Draw(page)
    big, small = font(22), font(15)
    pen.text((12, 10), "breastplan — plan summary", fill="black", font=big)
    pen.text((12, 40), f"Bottom row: {_shown_words(plan)}.", fill="#333333", font=small)
    for col, (name, azimuth) in enumerate(VIEWS.items()):
        cam = camera(views, [shown], azimuth, PICTURE_PX)
        x = LABEL_PX + col * w
        for row, state in enumerate((original(views), shown)):
            page.paste(picture(views, state, cam, marks=False), (x, HEAD_PX + row * h))
        pen.text((x + w // 2, HEAD_PX - 6), name, fill="#333333", font=small, anchor="mb")
    for row, label in enumerate(("before", "as planned")):
        _vertical(page, label, (4, HEAD_PX + row * h + h // 2), small)
    _measures(pen, plan, HEAD_PX + 2 * h + 12, small)
    page.save(path, format="PNG", compress_level=3)
    return Path(path)


def _shown_words(plan: Plan) -> str:
    if plan.shown.kind is None:
        return "all planned changes combined (" + ", ".join(f"{k} {d:g}" for k, d in plan.options.changes) + ")"
    return f"{plan.shown.kind}, degree {plan.shown.degree:g}"


def _vertical(page: Image.Image, text: str, centre: tuple[int, int], font) -> None:
    """`text` turned a quarter to read upwards, centred on `centre` at the page's left."""
    box = font.getbbox(text)
    label = Image.new("RGB", (box[2] + 4, box[3] + 4), "white")
    ImageDraw.Draw(label).text((2, 2), text, fill="#333333", font=font)
    label = label.rotate(90, expand=True)
    page.paste(label, (centre[0], centre[1] - label.height // 2))


def _measures(pen: ImageDraw.ImageDraw, plan: Plan, top: int, font) -> None:
    """The main measures of each side, before → as planned, her right first as the pictures show her; a
    follow-up's change of her volume since the earlier visit (on its chest wall)."""
    m, sides = plan.measures, [s for s in ("right", "left") if s in plan.sides]
    columns = [12, 260, 560]
    pen.text((columns[0], top), "measure", fill="#555555", font=font)
    for c, side in zip(columns[1:], sides):
        pen.text((c, top), f"her {side}: before → as planned", fill="#555555", font=font)
    for i, name in enumerate(MEASURES, start=1):
        y = top + 22 * i
        pen.text((columns[0], y), measure_label(name), fill="black", font=font)
        for c, side in zip(columns[1:], sides):
            text = f"{_value(m.before[side].get(name, np.nan))} → {_value(m.after[side].get(name, np.nan))}"
            if name == "volume_cc":
                text += f"   (± {plan.volumes.sides[side].uncertainty_cc:.0f})"
            pen.text((c, y), text, fill="black", font=font)
    rows = len(MEASURES) + 1
    if plan.skin_changes:                                      # a follow-up: her change since the earlier visit
        pen.text((columns[0], top + 22 * rows), "since the earlier visit", fill="black", font=font)
        for c, side in zip(columns[1:], sides):
            if (change := plan.skin_changes.get(side)) is not None:
                pen.text((c, top + 22 * rows), f"{change.on_wall_cc:+.0f} cc ({change.on_wall_pct:+.1f} %)",
                         fill="black", font=font)
        rows += 1
    pen.text((columns[0], top + 22 * rows + 8), DISCLAIMER, fill="#555555", font=font)


def _value(v: float) -> str:
    return "—" if not np.isfinite(v) else (f"{v:.0f}" if abs(v) >= 10 else f"{v:.2f}")
