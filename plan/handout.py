"""report.pdf: the handout she takes home — two A4 pages (landscape) made on this machine, no service: her
torso before and as planned from her obliques and the front (`plan.pictures.PICTURED`), then the main measures in plain
words, each page with her name, the surgeon, the date and the reminder that it is a simulation."""
from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from .pictures import PICTURED, SHOT_PX, font
from .result import OFF, Plan, StateGrid

PAGE_PX = (1754, 1240)
"""An A4 page, landscape, at DPI."""
DPI = 150
MARGIN_PX = 60
WRAP_CHARS = 130
"""What is planned is written in lines of at most this many characters (22 px type fills a line at about 140)."""
DISCLAIMER = ("A simulation of a planned change on her scanned body: a guide for discussion, not a promise of "
              "the result.")
OUTER_SAID_CC = 5.0
"""Her words say what her breast may hold beyond its outer edge, unseen, from this much (cc, a teaspoon); the
surgeon's tables give every figure."""
UNSEEN_WORDS = ("The pictures show her front as the camera in front of her saw it; beneath each breast, which it did "
                "not see, her skin is drawn straight back to her chest.")
"""Said under her pictures: a camera in front of her does not see beneath a breast that hangs."""
PLAIN = {"volume_cc": ("breast volume", "cc"),
         "notch_to_nipple_mm": ("nipple to the notch at the base of the neck", "mm"),
         "nipple_to_midline_mm": ("nipple to the middle of the chest", "mm"),
         "nipple_to_fold_mm": ("nipple to the fold beneath the breast", "mm"),
         "pole_ratio": ("fullness above the nipple to fullness below it", "")}
"""The measures the summary and the handout give, in plain words, and their units."""


def state_words(grid: StateGrid, i: int) -> str:
    """What state i of the plan's slider states shows, in words: each kind's degree (or off), or their combination
    as planned."""
    degrees = grid.combination(i)
    if not grid.kinds:
        return "the operations planned"
    if all(d == OFF for d in degrees):
        return "every change off"
    if len(grid.kinds) == 1:
        return f"{grid.kinds[0]}, degree {degrees[0]:g}"
    if degrees == grid.requested:
        return "all planned changes combined"
    return ", ".join(f"{k} off" if d == OFF else f"{k} degree {d:g}" + (" (planned)" if d == r else "")
                     for k, d, r in zip(grid.kinds, degrees, grid.requested))


def shown_words(plan: Plan) -> str:
    """What the pictures as planned show, in words, the operations and changes named."""
    words = state_words(plan.grid, plan.grid.planned_index)
    if len(plan.grid.kinds) > 1:
        words += " (" + ", ".join(f"{k} {d:g}" for k, d in plan.options.changes) + ")"
    operations = "; ".join(f"her {s} breast, {op.words or 'nothing'}" for s, op in plan.operated_shown)
    return words if not operations else operations if not plan.grid.kinds else f"{operations}; then {words}"


def measure_rows(plan: Plan) -> list[tuple[str, ...]]:
    """Rows of text: a head, then each measure of PLAIN and (a follow-up) the change since the earlier visit;
    columns: the measure, then her right and her left breast (those planned), before → as planned."""
    m, sides = plan.measures, plan.shown_sides
    rows = [("measure", *(f"her {s} breast: before → as planned" for s in sides))]
    for name, (words, unit) in PLAIN.items():
        cells = []
        for s in sides:
            text = f"{plain_value(m.before[s].get(name))} → {plain_value(m.after[s].get(name))} {unit}".rstrip()
            if name == "volume_cc":
                text += f"  (± {plan.volumes.sides[s].uncertainty_cc:.0f})"
            cells.append(text)
        rows.append((words, *cells))
    if plan.skin_changes:
        rows.append(("since the earlier visit", *(
            f"{c.on_wall_cc:+.0f} cc ({c.on_wall_pct:+.1f} %)" if (c := plan.skin_changes.get(s)) else "—"
            for s in sides)))
    return rows


def outer_words(plan: Plan) -> list[str]:
    """A line for the handout (and the report's words for her) when her scan, seen from in front of her, leaves at
    least OUTER_SAID_CC of a breast's outer side unseen (none else); a number and its unit are not split across
    lines."""
    more = {s: v for s in plan.shown_sides
            if (v := plan.volumes.sides[s].unseen_outer_cc) >= OUTER_SAID_CC}
    if not more:
        return []
    said = ", and her left about ".join(f"{v:.0f}\u00a0cc more" for v in more.values())
    if len(more) == 2:
        return ["The volumes above are measured on her skin as seen from the front, which does not reach all the way "
                f"round each breast: as scanned, her right breast may hold about {said}."]
    (side,) = more
    return [f"The volume of her {side} breast above is measured on her skin as seen from the front, which does not "
            f"reach all the way round it: as scanned, it may hold about {said}."]


SAID_CC = 5.0
"""A state says how much its changes by degree change a breast's volume from this much on (cc)."""


def volume_said(plan: Plan, i: int) -> list[str]:
    """How much slider state i's changes by degree change each breast's volume, against every slider off (after the
    operations, if any), and what that asks for: a change of shape that makes a breast larger asks for volume (an
    implant, a graft) that the shape alone does not give, one that makes it smaller for a resection. Nothing where no
    breast changes by SAID_CC."""
    grid = plan.grid
    off = grid.index((OFF,) * len(grid.kinds))
    by = {s: float(grid.measures[s]["volume_cc"][i] - grid.measures[s]["volume_cc"][off])
          for s in plan.shown_sides}
    if all(abs(v) < SAID_CC for v in by.values()):
        return []
    adds, takes = any(v >= SAID_CC for v in by.values()), any(v <= -SAID_CC for v in by.values())
    alone = ("neither adds nor takes volume: that takes an implant or a fat graft, or a resection" if adds and takes
             else "adds no volume: that takes an implant or a fat graft" if adds
             else "takes no volume away: that takes a resection")
    return ["these changes make " + " and ".join(f"her {s} breast {abs(v):.0f} cc {'larger' if v > 0 else 'smaller'}"
                                                for s, v in by.items())
            + f" (a change of shape alone {alone})"]


def draw_rows(pen: ImageDraw.ImageDraw, rows: list[tuple[str, ...]], at: tuple[int, int], face, step: int) -> None:
    """Draw `rows` of text as a table from `at` (px), `step` px apart: each column as wide as its widest cell
    and a gap; the first row (the head) grey."""
    widths = [max(pen.textlength(row[k], font=face) for row in rows if k < len(row)) for k in range(len(rows[0]))]
    starts = at[0] + np.concatenate([[0], np.cumsum(np.array(widths[:-1]) + 2 * face.size)])
    for i, row in enumerate(rows):
        for x, text in zip(starts, row):
            pen.text((float(x), at[1] + step * i), text, fill="#555555" if i == 0 else "black", font=face)


def plain_value(v) -> str:
    """A measure as the plain-words tables write it: whole above 10, two decimals below; — if not finite."""
    if v is None or not np.isfinite(v):
        return "—"
    return f"{v:.0f}" if abs(v) >= 10 else f"{v:.2f}"


def vertical_text(page: Image.Image, text: str, centre: tuple[int, int], size) -> None:
    """`text` turned a quarter to read upwards, its middle at `centre`'s height, from `centre`'s x."""
    box = size.getbbox(text)
    label = Image.new("RGB", (box[2] + 4, box[3] + 4), "white")
    ImageDraw.Draw(label).text((2, 2), text, fill="#333333", font=size)
    label = label.rotate(90, expand=True)
    page.paste(label, (centre[0], centre[1] - label.height // 2))


def handout_pdf(plan: Plan, shots: dict, path: Path) -> Path:
    """Write report.pdf from `shots` (`plan.pictures.before_after` of every view): page 1 the pictures, page 2
    the measures."""
    pages = [_pictures_page(plan, shots), _measures_page(plan)]
    pages[0].save(path, format="PDF", save_all=True, append_images=pages[1:], resolution=DPI, quality=88,
                  title="breastplan — a planned change, for her", producer="breastplan")
    return Path(path)


def _page(plan: Plan, title: str) -> tuple[Image.Image, ImageDraw.ImageDraw]:
    page = Image.new("RGB", PAGE_PX, "white")
    pen = ImageDraw.Draw(page)
    pen.text((MARGIN_PX, MARGIN_PX), title, fill="black", font=font(40))
    pen.text((MARGIN_PX, MARGIN_PX + 58), plan.patient.header, fill="#333333", font=font(24))
    pen.text((MARGIN_PX, PAGE_PX[1] - MARGIN_PX), DISCLAIMER, fill="#555555", font=font(22), anchor="lb")
    return page, pen


def _pictures_page(plan: Plan, shots: dict) -> Image.Image:
    page, pen = _page(plan, "Before, and as planned")
    w, h = SHOT_PX
    left, top = (PAGE_PX[0] - w * len(PICTURED)) // 2 + 20, MARGIN_PX + 150
    for col, name in enumerate(PICTURED):
        x = left + col * w
        pen.text((x + w // 2, top - 10), name, fill="#333333", font=font(22), anchor="mb")
        for row, shot in enumerate(shots[name]):
            page.paste(shot, (x, top + row * h))
    for row, label in enumerate(("before", "as planned")):
        vertical_text(page, label, (left - 40, top + row * h + h // 2), font(24))
    words = textwrap.wrap(f"As planned: {shown_words(plan)}. {UNSEEN_WORDS}", WRAP_CHARS)
    pen.multiline_text((MARGIN_PX, top + 2 * h + 20), "\n".join(words), fill="#333333", font=font(22), spacing=8)
    return page


def measure_notes(plan: Plan) -> tuple[str, ...]:
    """The notes under the handout's measures: how volumes and lengths are measured, which side is which, what her
    scan leaves unseen (`outer_words`) and what volume the changes as planned ask for (`volume_said`)."""
    return ("Volumes are measured on the scan of her skin, down to the chest wall beneath each breast; the ± is how "
            "far a new scan may read.",
            "Lengths are straight lines between points of her skin, in millimetres.",
            "Her right breast is on the left of a picture from the front, as someone facing her sees it.",
            *outer_words(plan),
            *([f"As planned, {words}." for words in volume_said(plan, plan.grid.planned_index)] if plan.grid.kinds
              else []))


def _measures_page(plan: Plan) -> Image.Image:
    page, pen = _page(plan, "The measures, before and as planned")
    top, rows = MARGIN_PX + 160, measure_rows(plan)
    draw_rows(pen, rows, (MARGIN_PX, top), font(26), 48)
    notes = measure_notes(plan)
    lines = [line for note in notes for line in textwrap.wrap(note, WRAP_CHARS)]
    for i, line in enumerate(lines):
        pen.text((MARGIN_PX, top + 48 * (len(rows) + 1) + 36 * i), line, fill="#333333", font=font(22))
    return page
