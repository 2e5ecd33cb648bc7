"""summary.png: a page of the plan for the patient's file — her torso before and as the report first shows it,
from her right oblique, the front and her left oblique (`plan.pictures`), the main measures in words below."""
from __future__ import annotations

import textwrap
from pathlib import Path

from PIL import Image, ImageDraw

from .handout import DISCLAIMER, draw_rows, measure_rows, shown_words, vertical_text
from .pictures import PICTURED, SHOT_PX, font
from .result import Plan

HEAD_PX, LABEL_PX, FOOT_PX = 90, 28, 290
"""Heights of the title band, of the row labels' column (its width) and of the measures and words below, px."""
WRAP_CHARS, WORDS_LINES = 125, 3
"""What the bottom row shows is written in at most WORDS_LINES lines of at most WRAP_CHARS characters."""


def summary_png(plan: Plan, shots: dict, path: Path) -> Path:
    """Write summary.png from `shots` (`plan.pictures.before_after`): her torso before (top row) and as first
    shown (bottom row) from each of PICTURED; the main measures of each side, a follow-up's change, the state shown
    and the disclaimer in words."""
    w, h = SHOT_PX
    page = Image.new("RGB", (LABEL_PX + w * len(PICTURED), HEAD_PX + 2 * h + FOOT_PX), "white")
    pen = ImageDraw.Draw(page)
    small = font(15)
    pen.text((12, 10), "breastplan — plan summary", fill="black", font=font(22))
    pen.text((12, 40), plan.patient.header, fill="#333333", font=small)
    for col, name in enumerate(PICTURED):
        x = LABEL_PX + col * w
        for row, shot in enumerate(shots[name]):
            page.paste(shot, (x, HEAD_PX + row * h))
        pen.text((x + w // 2, HEAD_PX - 6), name, fill="#333333", font=small, anchor="mb")
    for row, label in enumerate(("before", "as planned")):
        vertical_text(page, label, (4, HEAD_PX + row * h + h // 2), small)
    rows = measure_rows(plan)
    draw_rows(pen, rows, (12, HEAD_PX + 2 * h + 12), small, 22)
    words = textwrap.wrap(f"Bottom row: {shown_words(plan)}.", WRAP_CHARS)
    if len(words) > WORDS_LINES:
        words = words[:WORDS_LINES - 1] + [textwrap.shorten(" ".join(words[WORDS_LINES - 1:]), WRAP_CHARS)]
    pen.multiline_text((12, HEAD_PX + 2 * h + 20 + 22 * len(rows)), "\n".join(words), fill="#333333", font=small,
                       spacing=4)
    pen.text((12, page.height - 26), DISCLAIMER, fill="#555555", font=small)
    page.save(path, format="PNG", compress_level=3)
    return Path(path)
