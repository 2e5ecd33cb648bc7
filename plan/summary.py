"""summary.png: a static page of the plan for the patient's file (matplotlib, no display needed)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy import ndimage

from breastplan import transform_points
from breastplan.json_text import measure_values

from .measures import measure_label
from .report import SCAN, SKIN_RGB
from .result import Plan
from .views import VIEW_TO_DISPLAY

DPI = 110
BEFORE = {"colors": SCAN, "linestyles": "dashed", "linewidths": 1.0}
PLANNED = {"colors": "#b5522a", "linestyles": "solid", "linewidths": 1.4}
LAYOUT = {"width_ratios": (1, 1, 1.5), "left": 0.05, "right": 0.99, "bottom": 0.1, "top": 0.94,
          "wspace": 0.25, "hspace": 0.3}
"""Where the views sit on the page (fractions of it): fixed, so that nothing is measured to place them."""
CELL_MM = 2.0
"""Cell of the grid on which a view's outline is drawn; points about 2 mm apart close it."""


def outline(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, y, occupancy) of (N, 2) projected points (mm) on a CELL_MM grid, closed and filled, for
    `contour(..., levels=[0.5])`: the outline of the region they cover."""
    lo = xy.min(axis=0) - 3 * CELL_MM
    cells = np.floor((xy - lo) / CELL_MM).astype(np.int64)
    grid = np.zeros(cells.max(axis=0) + 4, bool)
    grid[cells[:, 0], cells[:, 1]] = True
    grid = ndimage.binary_fill_holes(ndimage.binary_closing(grid, iterations=2))
    x, y = (lo[i] + CELL_MM * (np.arange(grid.shape[i]) + 0.5) for i in (0, 1))
    return x, y, grid.T.astype(float)


def summary_png(plan: Plan, path: Path) -> Path:
    """Front and side views of each side's breast, outlined before (dashed) and after the combination
    as planned (solid, over the planned surface in skin colour), with the measures beside them."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    sides, m = list(plan.sides), plan.measures
    fig = Figure(figsize=(13, 3.6 * len(sides)), dpi=DPI)
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(sides), 3, squeeze=False, gridspec_kw=LAYOUT)
    for row, side in zip(axes, sides):
        sp = plan.sides[side]
        show = VIEW_TO_DISPLAY @ sp.frames.input_to_view
        verts = sp.surface_input
        before = transform_points(show, verts)
        after = transform_points(show, plan.shown.planned[side].model(verts))
        for ax, (u, v, title) in zip(row[:2], ((0, 2, "front"), (1, 2, "side"))):
            ax.scatter(after[:, u], after[:, v], s=4, linewidths=0, c=[np.array(SKIN_RGB) / 255], alpha=0.35)
            for xy, style in ((before[:, [u, v]], BEFORE), (after[:, [u, v]], PLANNED)):
                ax.contour(*outline(xy), levels=[0.5], **style)
            ax.set_aspect("equal")
            ax.set_title(f"{side} breast, {title} view (mm)")
        text = [f"{side}: {plan.shown.key}"]
        for name, value in m.before[side].items():
            text.append(f"{measure_label(name)}: {measure_values(value)} → {measure_values(m.after[side][name])}")
        fit, volume = sp.fit, plan.volumes.sides[side]
        text.append(f"volume on her skin: {volume.volume_cc:.1f} ± {volume.uncertainty_cc:.1f} cc "
                    f"(the model's: {fit.volume_cc:.1f})")
        text.append(f"fit residual {fit.normalised_residual:.4f} (rule "
                    f"{'met' if fit.stopping_rule_met else 'not met'})")
        if sp.at_bounds:
            text.append(f"at an end of the plausible range: {', '.join(sp.at_bounds)}")
        if sp.follow_up is not None:
            text.append(f"since the earlier scan: {sp.model_change[0]:+.1f} cc of the model on the earlier wall "
                        f"({sp.follow_up.earlier_volume_cc:.1f} → {fit.volume_cc:.1f} cc)")
        row[2].axis("off")
        row[2].text(0, 1, "\n".join(text), va="top", family="monospace", fontsize=8)
    fig.legend(handles=[Line2D([], [], color=BEFORE["colors"], linestyle=BEFORE["linestyles"], label="before"),
                        Line2D([], [], color=PLANNED["colors"], label="planned (the combination)")],
               loc="lower center", ncol=2, fontsize=8, frameon=False)
    with open(path, "wb") as fh:
        fig.savefig(fh, format="png", pil_kwargs={"compress_level": 3})
    return Path(path)

