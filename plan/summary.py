"""summary.png: a static page of the plan for the patient's file (matplotlib, no display needed)."""
from __future__ import annotations

from pathlib import Path

from breastplan import transform_points

from .job import Plan
from .measures import measure_label
from .views import VIEW_TO_DISPLAY

DPI = 110


def summary_png(plan: Plan, record: dict, path: Path) -> Path:
    """Front and side views of each side's breast before (dark) and after the combination as planned
    (skin), with the measures beside them."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    sides = list(plan.sides)
    fig = Figure(figsize=(12, 3.6 * len(sides)), dpi=DPI)
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(sides), 3, squeeze=False)
    for row, side in zip(axes, sides):
        sp = plan.sides[side]
        show = VIEW_TO_DISPLAY @ sp.scan.view_from_camera
        verts = sp.surface_input
        before = transform_points(show, verts)
        after = transform_points(show, sp.planned(sp.changes[-1]).model(verts))
        for ax, (u, v, title) in zip(row[:2], ((0, 2, "front"), (1, 2, "side"))):
            ax.scatter(after[:, u], after[:, v], s=4, linewidths=0, c="#e3a47c", label="planned")
            ax.scatter(before[:, u], before[:, v], s=0.4, linewidths=0, c="#2b2b2b", label="before")
            ax.set_aspect("equal")
            ax.set_title(f"{side} breast, {title} view (mm)")
            ax.legend(loc="upper right", fontsize=7, markerscale=8)
        text = [f"{side}: " + ", ".join(c["name"] for c in record["sides"][side]["changes"][-1:])]
        for name, value in record["measures"]["before"][side].items():
            text.append(f"{measure_label(name)}: {value} → {record['measures']['after'][side][name]}")
        fit = record["sides"][side]["fit"]
        text.append(f"fit: {fit['volume_cc']:.1f} cc down to the chest wall "
                    f"({fit['volume_cc_below_base']:.1f} below the base)")
        text.append(f"fit residual {fit['normalised_residual']:.4f} (rule "
                    f"{'met' if fit['stopping_rule_met'] else 'not met'})")
        if fit["at_bounds"]:
            text.append(f"at an end of the plausible range: {', '.join(fit['at_bounds'])}")
        since = record["sides"][side].get("wall_from")
        if since:
            text.append(f"since the earlier scan: {since['volume_change_cc']:+.1f} cc "
                        f"({since['earlier_volume_cc']:.1f} → {fit['volume_cc']:.1f} cc)")
        row[2].axis("off")
        row[2].text(0, 1, "\n".join(text), va="top", family="monospace", fontsize=8)
    fig.tight_layout()
    with open(path, "wb") as fh:
        fig.savefig(fh, format="png", pil_kwargs={"compress_level": 3})
    return Path(path)
