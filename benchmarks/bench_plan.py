"""The main job: `breastplan plan` on the bundled sample, and its report in Chromium.

Each round, one after the other so that both see the same load of the (shared, noisy) machine:
- `breastplan plan --out CASE` (both sides, the default three changes ptosis:3 turn:3
  top-shape:3, their combination, the measures and the report), whole process; target ≤ 6 s;
- baseline: the same work as separate commands, whole processes: `ingest` of each side, `fit`
  of each side, `deform --degree 3` of each fitted side for each of the three kinds (what a
  user ran before `plan` existed, with no report);
- `plan` with two operations per side (OPERATIONS), alone and under the three changes, whole process; target ≤ 8 s.
Then report.html's size (target ≤ 8 MB) and, by headless Chromium's own clock (Debian's, through
tests/browser.py; seconds from navigation start, medians of at least 5 opens after a warm-up):
- shown: the page's first view painted — the front-view poster of the plan, the title and the
  measures (performance mark `breastplan-shown`); target ≤ 2 s;
- drawn: the interactive 3-D view painted in its place (mark `breastplan-ready`);
- a slider moved: from its input event to the state it names drawn (SLIDES moves, ptosis and turn in turn), and
  the page's states (every combination of the three kinds' degrees), the modes they are stored as and their worst
  drawn error;
- baseline for both: a page of plotly.js alone drawing one 3-D scatter of as many points, drawn
  (the same mark, set the same way: after the frame that follows Plotly.newPlot), opened in turn.

Run:  .venv/bin/python benchmarks/bench_plan.py [--repeats N] [--quick]   (default 3; --quick 1)
"""
from __future__ import annotations

import json
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from rich.console import Console
from rich.table import Table

from timing import fmt, repeats_argument, rounded, timed

from breastplan.options import DEGREE_KINDS

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from browser import chromium, missing_chromium  # noqa: E402

BIN = Path(sys.executable).with_name("breastplan")
TARGETS = {"plan_s": 6.0, "report_mb": 8.0, "shown_s": 2.0, "operations_s": 8.0}
OPERATIONS = ("--left", "augmentation:300:moderate", "--left", "lift:fold=45", "--right", "reduction:60", "--right",
              "lumpectomy:20:10:30")
"""Two operations on each breast of the sample: an implant and a lift, a reduction and an excision."""
CHANGES = tuple(a for kind in DEGREE_KINDS for a in ("--deform", f"{kind}:3"))
OPENS = 5
"""At least this many opens of each page are measured (after one warm-up)."""
BASELINE_POINTS = 12_000
"""The baseline page draws one 3-D scatter of this many points (as many as the report drew of her torso before it
drew her skin as a surface)."""
READY = "window.breastplanReady === true"


def run(*args) -> None:
    subprocess.run([str(BIN), *map(str, args)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)


def separate_commands(sample: Path, work: Path) -> None:
    for side in ("left", "right"):
        run("ingest", sample, "--side", side, "--out", work / side)
        run("fit", work / side)
        for kind in DEGREE_KINDS:
            run("deform", work / side, "--kind", kind, "--degree", 3, "--out", work / f"{side}-{kind}.ply")


def baseline_page(path: Path, points: int) -> Path:
    """A plotly.js page drawing one 3-D scatter of `points`; marks `breastplan-ready` as the report does."""
    import numpy as np
    import plotly.graph_objects as go

    p = np.random.default_rng(0).normal(size=(points, 3))
    fig = go.Figure([go.Scatter3d(x=p[:, 0], y=p[:, 1], z=p[:, 2], mode="markers", marker={"size": 1.4})])
    fig.write_html(path, include_plotlyjs=True, post_script="requestAnimationFrame(() => setTimeout(() => {"
                   "window.breastplanReady = true; performance.mark('breastplan-ready'); }, 0));")
    return path


def open_times(report: Path, baseline: Path, opens: int) -> tuple[dict[str, float], dict[str, float]]:
    """Median seconds from navigation start (the browser's clock) of each timing of the report and of
    the baseline page (first-contentful-paint, the marks breastplan-shown and breastplan-ready), over
    `opens` opens of each, in turn, after a warm-up of each."""
    runs: dict[Path, dict[str, list[float]]] = {report: {}, baseline: {}}
    with chromium() as b:
        for i in range(opens + 1):
            for page, times in runs.items():
                b.open(page, wait_for_js=READY)
                if i:
                    for name, seconds in b.timings().items():
                        times.setdefault(name, []).append(seconds)
    return tuple({name: statistics.median(v) for name, v in times.items()} for times in runs.values())


SLIDES = 12
"""Slider moves timed in the report (after one), alternating ptosis and turn between two degrees each."""
SLIDE = """const [kind, to, done] = arguments; const s = document.getElementById('slider-' + kind);
const before = window.breastplanDrawn, t0 = performance.now();
s.value = to; s.dispatchEvent(new Event('input'));
(function wait() { if (window.breastplanDrawn !== before) requestAnimationFrame(() => done(performance.now() - t0));
                   else requestAnimationFrame(wait); })();"""
"""Move a slider and call back with the milliseconds until the state it names is drawn and the next frame painted."""


def slide_times(report: Path) -> tuple[list[float], dict]:
    """Seconds from a slider moved (as a hand moves it: an input event) to the state it names drawn, over SLIDES
    moves after one; and the page's states: their number, the modes they are stored as, the worst drawn error."""
    with chromium() as b:
        b.open(report, wait_for_js=READY)
        b.driver.set_script_timeout(60)
        moves = [("ptosis", 7)] + [(("ptosis", "turn")[i % 2], (i // 2) % 2 * 7) for i in range(SLIDES)]
        times = [b.driver.execute_async_script(SLIDE, kind, to) / 1000.0 for kind, to in moves]
        grid = b.js("JSON.parse(document.getElementById('plan-data').textContent).grid")
    return times[1:], {"states": len(grid["keys"]), "modes": len(grid["scales"]), "worst_mm": grid["worst_mm"]}


def main() -> None:
    repeats = repeats_argument(__doc__.splitlines()[0], 3, 1)
    from breastplan.plan.job import sample_recording

    sample = sample_recording()
    root = Path(tempfile.mkdtemp(prefix="bench-plan-"))
    plan_times, base_times, operated_times, both_times = [], [], [], []
    opens = max(OPENS, repeats)
    page, base_page = {}, {}
    try:
        for i in range(repeats):
            plan_times.append(timed(lambda: run("plan", "--out", root / f"case{i}")))
            base_times.append(timed(lambda: separate_commands(sample, root / f"separate{i}")))
            operated_times.append(timed(lambda: run("plan", *OPERATIONS, "--out", root / f"operated{i}")))
            both_times.append(timed(lambda: run("plan", *OPERATIONS, *CHANGES, "--out", root / f"both{i}")))
        report = root / "case0" / "report.html"
        size_mb = report.stat().st_size / 2**20
        slides, grid = [], {}
        if missing_chromium() is None:
            page, base_page = open_times(report, baseline_page(root / "baseline.html", BASELINE_POINTS), opens)
            slides, grid = slide_times(report)
    finally:
        shutil.rmtree(root, ignore_errors=True)
    plan_s, base_s = statistics.median(plan_times), statistics.median(base_times)
    shown_s, drawn_s = page.get("breastplan-shown"), page.get("breastplan-ready")
    base_drawn_s = base_page.get("breastplan-ready")
    operated_s, both_s = statistics.median(operated_times), statistics.median(both_times)
    rows = [("plan on the sample (whole process)", plan_s, base_s, "separate commands", TARGETS["plan_s"]),
            ("plan, two operations per side (whole process)", operated_s, plan_s, "plan on the sample",
             TARGETS["operations_s"]),
            ("plan, two operations per side under the three changes", both_s, plan_s, "plan on the sample",
             TARGETS["operations_s"]),
            ("report.html opens in Chromium: shown (poster, measures)", shown_s, base_drawn_s,
             "plotly.js + one scatter, drawn", TARGETS["shown_s"]),
            ("report.html opens in Chromium: 3-D view drawn", drawn_s, base_drawn_s, "plotly.js + one scatter, drawn",
             None)]
    table = Table(title=f"bench_plan — medians of {repeats} rounds (opens: {opens if page else 0}, browser clock)")
    for col in ("case", "median", "baseline", "baseline is", "ratio", "target", "met"):
        table.add_column(col)
    for name, value, base, what, target in rows:
        if value is None:
            table.add_row(name, "no chromium", "", what, "", "", "")
            continue
        table.add_row(name, fmt(value), fmt(base), what, f"{value / base:.2f}", "" if target is None else
                      f"≤ {fmt(target)}", "" if target is None else "yes" if value <= target else "no")
    table.add_row("report.html size", f"{size_mb:.2f} MB", "", "", "", f"≤ {TARGETS['report_mb']:g} MB",
                  "yes" if size_mb <= TARGETS["report_mb"] else "no")
    slide_s = statistics.median(slides) if slides else None
    if slides:
        table.add_row(f"a slider moved: its state drawn ({grid['states']} states as {grid['modes']} modes, "
                      f"worst {grid['worst_mm']:.3f} mm)", fmt(slide_s), "", "", "", "", "")
    Console().print(table)
    print(json.dumps(rounded({"benchmark": "plan", "repeats": repeats, "opens": opens if page else 0,
                              "plan_s": plan_s, "baseline_separate_commands_s": base_s, "ratio": plan_s / base_s,
                              "operations_s": operated_s, "operations_and_changes_s": both_s,
                              "report_mb": size_mb, "shown_s": shown_s, "drawn_s": drawn_s,
                              "first_contentful_paint_s": page.get("first-contentful-paint"),
                              "baseline_plotly_page_drawn_s": base_drawn_s, "slider_drawn_s": slide_s,
                              "slider_drawn_max_s": max(slides) if slides else None, **grid, "targets": TARGETS})))


if __name__ == "__main__":
    main()
