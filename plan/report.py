"""report.html: a self-contained, offline page of the plan (plotly.js embedded; no request leaves it).

The page is headed with whom and when it is for (`Plan.patient`). It draws her skin (her torso as one
shaded surface in her recorded colour, or a skin tone where none was recorded, moved near the breasts as
the state shown plans it, or coloured by the millimetres each point moves, the value under the pointer),
on demand each breast's scanned points and
fitted model as planned (from the legend), for a follow-up the breast as fitted at the earlier visit (a
translucent blue mesh), the landmarks the measures start from (the sternal notch, the midline and the
nipples found, red), each breast's footprint (blue), the fold beneath each breast (purple) and her sides
named on her. A degree slider per planned kind, off at its left end, each keeping its degree while another moves
(every combination they reach, `Plan.grid`, computed by the plan: the page looks a state up, it computes none), the
combination as planned, her skin before beside the state shown (one camera for both), the five standard views (her
right side, her right oblique, front, her left oblique, her left side) and a top view; on a phone, the legend below
her.
Below: the main measures in plain words for her, with the disclaimer and a link to her handout; the measures
before and after with the asymmetry between sides, her volume, symmetry and a follow-up's change; and,
folded away for the surgeon, the fits' quality, the changes' parameters, the inputs, options and versions.
Geometry travels as base64 typed arrays (`views`), the states' displacements as shared modes (`plan.modes`); a
small script decodes them and redraws the plot when a control changes.

The page opens on a poster, a front view of the first state drawn here (a PNG), above its tables:
plain HTML, painted before any heavy script runs. plotly.js and the data wait in inert blocks
(`<script type="text/plain">`, `application/json`) until the poster is painted
(`window.breastplanShown`, performance mark `breastplan-shown`); then plotly.js runs, builds the 3-D
scene under the poster and hides it once drawn (`window.breastplanReady`, mark `breastplan-ready`); printed, the
page shows the poster and the text for her, not the controls, the 3-D view or the surgeon's part.
`window.breastplanState` names the state shown, `window.breastplanDrawn` the state last drawn.
"""
from __future__ import annotations

import base64
import html
import io
import json
import re

import numpy as np

from breastplan.fitting.ffd import STOP_RESIDUAL

from .breast_volume import model_differs_much
from .changes import short_of
from .handout import DISCLAIMER, PLAIN, outer_words, plain_value, state_words, volume_said
from .measures import asymmetry, measure_label
from .pictures import FOLD, FOOTPRINT, LANDMARK, LIGHT, VIEWS, camera, picture, skin_colour
from .result import OFF, OPERATED, Plan
from .modes import modes_of
from .operated import said
from .views import State, Views

SCAN = "#2b2b2b"
"""Colour of a breast's scanned points (before the plan)."""
MODEL = "#8fa8c8"
"""Colour of a breast's fitted model as planned (shown on demand, translucent, over her skin)."""
UP_FROM_TEXT = {
    "wall": "Up (which divides the poles and gives the drop below the notch) is the vertical of the wall "
            "seen behind her.",
    "midline profile": "Up (which divides the poles and gives the drop below the notch) is read off her midline "
                       "profile: no wall was seen behind her. A full abdomen leans it, by up to 10° on a heavy "
                       "patient; scanned in front of a wall, its vertical is taken instead.",
}
"""What the report says of where the up axis came from (`BodyLandmarks.up_from`)."""
TITLE = "breastplan — surgical plan"
POSTER_PX = (760, 640)
"""The poster's width and height, px: those of the plot it stands in for."""
NIPPLE_FOUND = {"areola": "centre of the raised areola", "apex": "apex (no raised areola found)",
                "given": "given (--nipple)"}
"""How the nipple was found, in the report's words."""
AT_BOUNDS_TEXT = ('<p id="at-bounds">A fitted parameter at an end of its plausible range (what the breasts the model '
                  'was built on span) means the breast asked for more: the model holds it only roughly, and its '
                  'lattice carries the rest.</p>')
"""Said under the fit's table when a parameter of either side is at an end of its plausible range."""
VOLUME_TEXT = ('<p id="volume-how">Her volume is the tissue between her skin and the chest wall beneath it, inside '
               'the footprint drawn on her (the outline where her skin rises from her chest). One chest wall, the '
               'same on both sides, is inferred from her chest around both breasts, and both breasts are measured '
               'inside one outline, mirrored, so that a difference between them is a difference of tissue. The ± '
               'holds nine re-scans in ten. Where her skin was not seen, the other side\'s mirror image fills it in, '
               'and the ± grows by what it adds. Her skin is measured as seen from in front of her (a camera\'s '
               'view, or the front of a scan that wraps round her), which stops short of the outer side of a breast '
               'that turns away: her breast may go on beyond the footprint\'s outer edge. The column "perhaps more '
               'beyond its outer edge" estimates what it could hold there, had her skin fallen to the wall at the '
               'steepest slope a depth camera still sees; it can only add. The fitted model, which plans the change, '
               'has a volume of its own; it is shown as a cross-check.</p>')
DIFFERS_TEXT = ('<p class="differs">The fitted model of her {side} breast holds {pct:+.0f} % of the volume measured '
                'on her skin: the model describes her breast only roughly, and its planned change is best read as '
                'a shape, not a volume.</p>')


def _b64(array: np.ndarray, dtype: str) -> str:
    return base64.b64encode(np.ascontiguousarray(array, dtype=dtype).tobytes()).decode("ascii")


def _points(p: np.ndarray) -> dict:
    return {"n": int(len(p)), "xyz": _b64(p, "<f4")}


def _mesh(vertices: np.ndarray, faces: np.ndarray) -> dict:
    return {**_points(vertices), **_faces(faces, len(vertices))}


def _faces(faces: np.ndarray, n: int) -> dict:
    """(M, 3) faces of n vertices for the page: 16-bit indices where they fit (`wide` says when not)."""
    wide = n > 1 << 16
    return {"faces": _b64(faces, "<i4" if wide else "<u2"), "m": int(len(faces)), "wide": wide}


def page_data(plan: Plan, views: Views) -> dict:
    """The JSON the page's script reads: geometry, every slider state and the state it opens on (her sides in
    `Plan.shown_sides` order, so the legend lists her right first)."""
    sides = plan.shown_sides
    return {"sides": sides, "torso": _points(views.torso), "patch": _points(views.patch),
            "skin_faces": _faces(views.skin, len(views.torso) + len(views.patch)),
            "scans": {s: _points(views.scans[s]) for s in sides},
            "meshes": {s: _mesh(*views.meshes[s]) for s in sides},
            "earlier": {s: _mesh(*views.earlier[s]) for s in views.earlier},
            "landmarks": {k: v.round(2).tolist() for k, v in views.landmarks.items()},
            "side_labels": {s: v.round(1).tolist() for s, v in views.side_labels.items()},
            "folds": {s: {"xyz": views.folds[s].round(1).tolist(),
                          "from": plan.measures.ptosis["before"][s]["fold_from"]} for s in sides if s in views.folds},
            "before": {s: _written(plan.measures.before[s]) for s in sides},
            "asymmetry_before": {k: figure(v) for k, v in plan.measures.asymmetry.get("before", {}).items()},
            "bounds": _bounds(views), "footprints": {s: views.footprints[s].round(2).tolist() for s in sides},
            "grid": _grid(plan, views), **_skin_colour(views), "light": list(LIGHT),
            "mark_layout": [list(m) for m in views.mark_layout],
            "operated_labels": None if views.operated_labels is None else {
                s: v.round(1).tolist() for s, v in views.operated_labels.items()},
            "scan": SCAN, "model": MODEL, "landmark": LANDMARK, "footprint": FOOTPRINT, "fold": FOLD}


def _written(measures: dict) -> dict:
    """One side's measures (scalars, or per state) as the page writes them: each as the surgeon's tables and the
    terminal write it (`figure`), and those of her table (PLAIN) also as hers (`plain_value`, under "plain:"), so
    that a figure is rounded once, here, and reads alike on the page and the terminal."""
    return {**{k: _each(figure, v) for k, v in measures.items()},
            **{f"plain:{k}": _each(plain_value, measures[k]) for k in PLAIN if k in measures}}


def _each(write, values):
    """`write` (`figure`, `plain_value`) of one value, or of each of a state's values (a list)."""
    one = lambda x: write(None if x is None else float(x))  # noqa: E731
    return one(values) if np.ndim(values) == 0 else [one(x) for x in values]


def _grid(plan: Plan, views: Views) -> dict:
    """Every slider state (`Plan.grid`): its name, words and measures, and its displacements of the patch then of
    each side's breast mesh as shared modes (`plan.modes`), and the state planned."""
    grid, sides = plan.grid, plan.shown_sides
    moved = np.concatenate([views.moved - views.patch.astype(np.float32)] + [
        views.planned_meshes[s] - views.meshes[s][0].astype(np.float32) for s in sides]
        + [views.marks_moved - _found_marks(views).astype(np.float32)], axis=1)
    stored = modes_of(moved)
    asym = asymmetry(grid.measures)
    return {"kinds": list(grid.kinds), "degrees": [list(d) for d in grid.degrees], "requested": list(grid.requested),
            "keys": list(grid.keys), "words": [_state_said(plan, i) for i in range(len(grid))],
            "planned": grid.planned_index, **_short(plan),
            "measures": {s: _written(grid.measures[s]) for s in sides},
            "asymmetry": {k: _each(figure, v["left_minus_right"]) for k, v in asym.items()},
            "coefficients": _b64(stored.coefficients, "<f4"), "modes": _b64(stored.modes, "<i2"),
            "scales": stored.scales.astype(float).tolist(), "worst_mm": stored.worst_mm}


def _short(plan: Plan) -> dict:
    """Per kind and slider position (`StateGrid.degrees`), where her breasts stop short of the slider's degree
    (`changes.short_of`; a kind's change is solved alone, so it stops short alike in every state): `reached`, the
    degrees they reach ("5.29 and 5.25", her right and left; None where both reach it), and `notes`, a sentence
    for each breast that stops short, which the page adds to the words of every state at that position."""
    sides = plan.shown_sides
    alone = {(st.kind, st.degree): st for st in plan.states if st.kind is not None}
    reached, notes = [], []
    for kind, degrees in zip(plan.grid.kinds, plan.grid.degrees):
        details = [None if d == OFF else [alone[kind, d].changes[s].details[0] for s in sides] for d in degrees]
        said = [[] if each is None else [f"on her {s} breast, {kind} reaches {why}" for s, d in zip(sides, each)
                                         if (why := short_of(d, plan.options.method))] for each in details]
        notes.append(said)
        reached.append([" and ".join(f"{d['degree_reached']:.2f}" for d in each) if words else None
                        for each, words in zip(details, said)])
    return {"reached": reached, "notes": notes}


def _state_said(plan: Plan, i: int) -> str:
    """What slider state i shows, in words, with the volume its changes by degree add to a breast or take from it
    (the page adds where a breast stops short of a slider's degree, `_short`)."""
    grid = plan.grid
    return (state_words(grid, i) + (" (after the operations)" if plan.operated and grid.kinds else "")
            + "".join(f"; {words}" for words in volume_said(plan, i)))


def _found_marks(views: Views) -> np.ndarray:
    """(M, 3) the marks as found on her skin as scanned, in `Views.mark_layout`'s order (display frame)."""
    found = views.marks(views.state("original"))
    return np.concatenate([found["landmarks"][name] if side is None else found[name][side]
                           for name, side, _, _ in views.mark_layout])


def _skin_colour(views: Views) -> dict:
    """How the page colours her skin: one tone (`skin_rgb`) or her recorded colour per vertex (`skin_vertex_rgb`,
    uint8 RGB of the torso then the patch), and its shade (`plan.pictures.skin_colour`)."""
    rgb, shade = skin_colour(views)
    return {"shade": list(shade), **({"skin_rgb": rgb.tolist()} if rgb.ndim == 1 else
                                     {"skin_vertex_rgb": _b64(views.skin_rgb, "u1")})}


def _bounds(views: Views) -> list[list[float]]:
    """[[lo, hi]] of x, y, z (display frame, mm) holding her skin in every state and everything drawn on her (a
    point outside is not drawn): one box for every scene, so that before and as planned side by side share a
    scale."""
    marks = [*views.landmarks.values(), *views.footprints.values(), *views.folds.values(),
             *(p[None] for p in views.side_labels.values())]
    if views.operated_labels is not None:
        marks += [p[None] for p in views.operated_labels.values()]
    every = np.concatenate([views.torso, views.patch, views.moved.reshape(-1, 3), views.marks_moved.reshape(-1, 3),
                            *marks])
    lo, hi = every.min(axis=0), every.max(axis=0)
    pad = 0.03 * (hi - lo).max()
    return [[round(float(a - pad), 1), round(float(b + pad), 1)] for a, b in zip(lo, hi)]


def first_state(plan: Plan, views: Views) -> State:
    """The state the page opens on: the combination as planned, or the one planned change."""
    return views.state(plan.shown.key)


def poster_png(views: Views, state: State) -> bytes:
    """PNG (POSTER_PX) of `state` seen from the front: her skin moved as `state` plans, the landmarks red,
    each breast's footprint blue, her sides named (`plan.pictures`)."""
    image = picture(views, state, camera(views, [state], VIEWS["front"], POSTER_PX))
    out = io.BytesIO()
    image.save(out, format="PNG", compress_level=3)
    return out.getvalue()


def _table(head: list[str], rows: list[list], cls: str = "") -> str:
    th = "".join(f"<th>{html.escape(str(h))}</th>" for h in head)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(figure(c))}</td>" for c in row) + "</tr>" for row in rows)
    return f'<table class="{cls}"><thead><tr>{th}</tr></thead><tbody>{body}</tbody></table>'


def figure(v) -> str:
    """A figure as the surgeon's tables give it, here, on the page and on the terminal alike: one decimal from 10
    on, else three significant digits; "—" for none (or none finite)."""
    if isinstance(v, float):
        return "—" if not np.isfinite(v) else f"{v:.1f}" if abs(v) >= 10 else f"{v:.3g}"
    return "—" if v is None else str(v)


def render(plan: Plan, views: Views) -> str:
    """The page's HTML for a plan drawn as `views` (`plan.views.build_views`)."""
    from plotly.offline import get_plotlyjs

    data = page_data(plan, views)
    poster = poster_png(views, first_state(plan, views))
    parts = {"TITLE": TITLE, "WHO": html.escape(plan.patient.header),
             "POSTER": base64.b64encode(poster).decode("ascii"), "TABLES": tables(plan), "SCRIPT": _SCRIPT,
             "PLOTLY": get_plotlyjs(), "PLANNED": "As operated" if not plan.grid.kinds else "Combined, as planned",
             "DATA": json.dumps(data, separators=(",", ":")).replace("</", "<\\/")}
    return re.sub(r"%([A-Z]+)%", lambda m: parts[m[1]], _TEMPLATE)


def _how(detail: dict) -> str:
    """A change's condition and parameters, or the statistical model's lattice it came from."""
    if detail.get("model") == "statistical":
        return "statistical model"
    return f"{detail['condition']}, {' '.join(f'{p:.3g}' for p in detail['params'])}"


def _reached(detail: dict, method: str) -> str:
    """The degree a change gives the breast, and the degree asked where it does not round to it."""
    return short_of(detail, method) or f"{detail['degree_reached']:.2f}"


def tables(plan: Plan) -> str:
    """The report's text: for her (the main measures in plain words, the disclaimer, her handout), then the
    measures, volume, symmetry and follow-up tables, and for the surgeon, collapsed, the fit quality,
    the changes' parameters, the inputs, options and versions."""
    sides = plan.shown_sides
    parts = [_operations_table(plan), for_her(plan), _measures_table(plan)]
    volumes = {s: plan.volumes.sides[s] for s in sides}
    differs = {s: v.model_differs_pct(plan.sides[s].fit.volume_cc) for s, v in volumes.items()}
    rows = [[s, f"{v.volume_cc:.1f} ± {v.uncertainty_cc:.1f}", f"+{v.unseen_outer_cc:.0f}", v.area_cm2,
             f"{v.unseen_pct:.1f}", plan.sides[s].fit.volume_cc, differs[s]] for s, v in volumes.items()]
    parts.append("<h2>Volume, measured on her skin</h2>" + _table(
        ["side", "volume cc", "perhaps more beyond its outer edge, unseen cc", "footprint cm²",
         "filled in from her other side %", "the model's volume cc", "the model differs by %"], rows, "volume")
        + VOLUME_TEXT
        + "".join(DIFFERS_TEXT.format(side=s, pct=pct) for s, pct in differs.items() if model_differs_much(pct))
        + "".join(f'<p class="camera-distance">{html.escape(note)}</p>' for note in plan.camera_notes))
    parts.append(_symmetry_tables(plan))
    surgeon, shown = [], {s: plan.sides[s] for s in sides}
    rows = [[s, sp.fit.volume_cc, sp.fit.volume_cc_below_base, sp.fit.residuals_mm["rms"], sp.fit.normalised_residual,
             "met" if sp.fit.stopping_rule_met else "not met", sp.fit.points, NIPPLE_FOUND[sp.scan.nipple_found],
             ", ".join(sp.at_bounds) or "none"] for s, sp in shown.items()]
    surgeon.append("<h2>Fit quality</h2>" + _table(
        ["side", "model volume cc down to the chest wall", "of it below the base cc", "rms mm", "normalised residual",
         f"stopping rule {STOP_RESIDUAL}", "points", "nipple found", "at an end of its plausible range"],
        rows, "fit") + AT_BOUNDS_TEXT * any(sp.at_bounds for sp in plan.sides.values()))
    since = {s: sp for s, sp in shown.items() if sp.follow_up is not None}
    if since:
        rows = []
        for s, sp in since.items():
            f, skin = sp.follow_up, plan.skin_changes.get(s)
            cc, pct = sp.model_change
            rows.append([s, str(f.case), f.earlier_volume_cc, sp.fit.volume_cc, f"{cc:+.1f}", f"{pct:+.1f}",
                         f"{skin.on_wall_cc:+.1f} ({skin.on_wall_pct:+.1f} %)" if skin else "—",
                         f.registration.rms_mm, f"{100 * f.registration.agreement:.0f} %"])
        parts.append("<h2>Since the earlier scan (the model, measured down to its chest wall)</h2>" + _table(
            ["side", "earlier case", "volume then cc", "volume now cc", "change cc", "change %",
             "on her skin, on the earlier wall: change cc", "chests registered, rms mm", "chest agreeing"],
            rows, "since"))
    method = plan.options.method
    rows = [[s, st.key, ", ".join(f"{d['kind']} {d['degree']:g} ({_how(d)})" for d in st.changes[s].details),
             ", ".join(_reached(d, method) for d in st.changes[s].details)]
            for s in sides for st in plan.changes if st.changes[s].details]
    surgeon.append("<h2>Planned changes</h2>" + _table(["side", "change", "how (parameters in model units)",
                                                       "degree reached"], rows))
    rows = [["input", str(plan.input)], ["input kind", plan.input_kind], ["input sha256", plan.input_sha256 or "—"],
            ["the camera from her nipples", "—" if plan.camera_mm is None else f"{plan.camera_mm:.0f} mm"],
            ["options", json.dumps(plan.options.as_dict())]] + [[k, v] for k, v in plan.versions.items()]
    surgeon.append("<h2>Inputs, options and versions</h2>" + _table(["", ""], rows, "about"))
    parts.append('<details id="for-surgeon"><summary>For the surgeon: the fits\' quality, the changes\' parameters, '
                 'inputs and versions</summary>' + "\n".join(surgeon) + "</details>")
    return "\n".join(parts)


def _operations_table(plan: Plan) -> str:
    """Each operated side's operations in a surgeon's words, in the order made, her volume on her skin before and
    after them, how far and which way her nipple moves, and what the plan warns of; "" without operations."""
    if not plan.operated:
        return ""
    rows = [[f"her {s}", op.words or "none proposed",
             f"{op.volume_before_cc:.0f} → {op.volume_cc:.0f}", op.nipple_move_words,
             " ".join(said(op, plan.measures)) or "—"] for s, op in plan.operated_shown]
    after = ("Every state shown is after them: the changes by degree start from her breasts as operated."
             if plan.grid.kinds else "")
    return ('<section id="operations"><h2>Operations planned</h2>' + _table(
        ["breast", "operations, in the order made", "her volume cc", "her nipple moves", "warnings and notes"], rows,
        "operations") + (f"<p>{after}</p>" if after else "") + "</section>")


def for_her(plan: Plan) -> str:
    """The main measures in plain words (`plan.handout.PLAIN`), before → as shown (the cells the page's script
    updates as the state shown changes; printed, as planned, as the poster printed above them shows her), what the
    camera did not see of her outer sides, the disclaimer and a link to her handout."""
    m, sides = plan.measures, plan.shown_sides
    head = "".join(f"<th>{h}</th>" for h in ["measure", *(
        f'her {s} breast: before → {_on_screen("as shown", "as planned")}' for s in sides)])
    body = ""
    for name, (words, unit) in PLAIN.items():
        cells = ""
        for s in sides:
            extra = f"  (± {plan.volumes.sides[s].uncertainty_cc:.0f})" if name == "volume_cc" else ""
            cells += (f"<td>{plain_value(m.before[s].get(name))} → "
                      f"{_on_screen(plain_value(m.after[s].get(name)), data_after=f'{s} {name}', data_for_her='')} "
                      f"{unit}{extra}</td>")
        body += f"<tr><td>{html.escape(words)}</td>{cells}</tr>"
    return ('<section id="for-her"><h2>For her</h2><table class="for-her"><thead><tr>' + head + "</tr></thead><tbody>"
            + body + "</tbody></table>"
            + "".join(f'<p class="unseen-outer">{html.escape(w)}</p>' for w in outer_words(plan))
            + f'<p id="disclaimer">{html.escape(DISCLAIMER)}</p><p>To take home: '
            '<a href="report.pdf">report.pdf</a>, two printed pages of these pictures and measures.</p></section>')


def _measures_table(plan: Plan) -> str:
    """Each side's measures before and as shown, and their asymmetry, with where up came from; the page's
    script updates the "as shown" cells as the state shown changes (printed: as planned, as the poster above)."""
    sides, m = plan.shown_sides, plan.measures
    shown = _on_screen("as shown", "as planned")
    head = ["measure"] + [f"{s} {w}" for s in sides for w in ("before", shown)]
    if m.asymmetry:
        head += ["left − right before", f"left − right {shown}"]   # as the terminal heads them
    rows = ""
    for name in m.before[sides[0]]:
        cells = f"<td>{html.escape(measure_label(name))}</td>"
        for s in sides:
            after = _on_screen(figure(m.after[s][name]), data_after=f"{s} {name}")
            cells += f"<td>{figure(m.before[s][name])}</td><td>{after}</td>"
        if m.asymmetry:
            cells += (f'<td>{figure(m.asymmetry["before"][name])}</td>'
                      f'<td>{_on_screen(figure(m.asymmetry["after"][name]), data_asymmetry=name)}</td>')
        rows += f"<tr>{cells}</tr>"
    th = "".join(f"<th>{h}</th>" for h in head)
    title = _on_screen(f"as shown: the state the view shows; as the page opens, the {_opening(plan)}", "as planned")
    return (f'<h2>Measures ({title})</h2>'
            f'<table class="measures"><thead><tr>{th}</tr></thead><tbody>{rows}</tbody></table>'
            f'<p id="up-from">{UP_FROM_TEXT[plan.volumes.landmarks.up_from]}</p>')


def _on_screen(shown: str, printed: str | None = None, **data: str) -> str:
    """HTML of `shown` on screen (the page's script may update it: `data` attributes such as data_after="left
    volume_cc") and of `printed` in print, the page printed being her plan as planned (`printed` None: `shown` as the
    page opens, which is the state planned). Both are HTML-escaped text."""
    attributes = "".join(f' {k.replace("_", "-")}="{html.escape(v)}"' for k, v in data.items())
    return (f'<span class="on-screen"{attributes}>{html.escape(shown)}</span>'
            f'<span class="as-planned">{html.escape(shown if printed is None else printed)}</span>')


def _opening(plan: Plan) -> str:
    if plan.shown.key == OPERATED:
        return "operations as planned"
    return "combination as planned" if plan.shown.kind is None else "planned change"


SYMMETRY_LABELS = {"pBRA_pct": "pBRA: nipples from the notch, one against the other's mirror image %",
                   "pUNR_pct": "pUNR: nipples' heights below the notch %",
                   "pLBC_pct": "pLBC: breasts' lowest points %", "pBCE_pct": "pBCE: nipples above their lowest points %",
                   "BCD_mm": "BCD: outlines, one against the other's mirror image mm",
                   "overlap_pct": "overlap of one breast with the other's mirror image %"}
"""The symmetry measures the report shows (docs/symmetry.md), as it names them."""
SYMMETRY_TEXT = ('<p id="symmetry-how">BCCT.core\'s measures of a frontal photograph, taken in 3-D on her '
                 'skin: 0 % (or 100 % overlap) for a symmetric woman. The fold beneath a breast that hangs '
                 'over it is hidden from a camera in front of her: its place is then estimated, and her '
                 'ptosis grade rests on that estimate; confirm it by examining her.</p>')

CONTOUR_HIDDEN_TEXT = ('<p id="contour-hidden">A breast\'s lowest point lies on skin the camera did not see, '
                       'under the breast: its height there is her other side\'s, mirrored, and pLBC and pBCE may '
                       'read the difference between her breasts short by about 5 mm.</p>')
"""Said under the symmetry table when `Measures.contour_hidden`."""


def _symmetry_tables(plan: Plan) -> str:
    """The symmetry measures before and as planned, and each side's ptosis grade beside the fitted
    ptosis parameters."""
    sym, ptosis = plan.measures.symmetry, plan.measures.ptosis
    html = ""
    if sym["before"]:
        rows = [[label, sym["before"].get(k), sym["after"].get(k)] for k, label in SYMMETRY_LABELS.items()]
        html += "<h2>Symmetry</h2>" + _table(["measure", "before", "as planned"], rows, "symmetry")
        if plan.measures.contour_hidden:
            html += CONTOUR_HIDDEN_TEXT
    rows = []
    for s in plan.shown_sides:
        before, after, sp = ptosis["before"][s], ptosis["after"][s], plan.sides[s]
        rows.append([s, before["grade"], after["grade"], before["nipple_to_fold_mm"], before["nipple_to_lowest_mm"],
                     before["fold_from"], [round(v, 4) for v in sp.ptosis_params]])
    return html + "<h2>Ptosis (Regnault)</h2>" + _table(
        ["side", "grade before", "grade as planned", "nipple above the fold mm",
         "nipple above the breast's lowest point mm", "fold", "fitted ptosis b0, b1"], rows, "ptosis") + SYMMETRY_TEXT


_TEMPLATE = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><meta name="viewport" content="width=device-width, initial-scale=1">
<meta http-equiv="Content-Security-Policy" content="default-src 'none'; script-src 'unsafe-inline' 'unsafe-eval'; style-src 'unsafe-inline'; img-src data: blob:; worker-src blob:; font-src data:">
<title>%TITLE%</title>
<style>
body{font-family:system-ui,sans-serif;margin:0;color:#222;background:#fafafa}
header{padding:10px 16px;background:#3b3b52;color:#fff}header h1{margin:0;font-size:20px}header p{margin:4px 0 0;font-size:14px}
details{margin:10px 0}summary{cursor:pointer;font-weight:600}
main{display:flex;flex-wrap:wrap;gap:12px;padding:12px}
#plot{position:relative;width:min(760px,calc(100vw - 360px));height:640px;background:#fff;border:1px solid #ddd}
@media (max-width:900px){#plot{width:calc(100vw - 26px);height:min(760px,165vw)}#controls{max-width:none}
 table{display:block;overflow-x:auto;max-width:calc(100vw - 32px)}}
#poster{position:absolute;inset:0;z-index:10;margin:0;background:#fff}#poster[hidden]{display:none}
#poster img{display:block;max-width:100%;height:auto}
.as-planned{display:none}
@media print{header{background:none;color:#000}#controls,#for-surgeon,#plot>div{display:none!important}
 #plot{border:none;width:auto;height:auto}#poster,#poster[hidden]{display:block;position:static}#poster figcaption{display:none}
 #poster::after{content:"From the front, as planned.";display:block;font-size:13px;color:#555}
 .on-screen{display:none}.as-planned{display:inline}
 a[href="report.pdf"]{color:inherit;text-decoration:none}h2{break-after:avoid}
 main{display:block;padding:0}table{break-inside:avoid}}
#poster figcaption{position:absolute;left:8px;top:6px;font-size:13px;color:#555}
#controls{flex:1 1 300px;min-width:300px;max-width:420px}
.slider{margin:8px 0}.slider label{display:block;font-weight:600}.slider label.off{color:#888}.slider input{width:260px}
button{margin:2px;padding:4px 10px}button.on{background:#3b3b52;color:#fff}
table{border-collapse:collapse;margin:6px 0 14px;font-size:13px}td,th{border:1px solid #ccc;padding:3px 6px;text-align:right}
td:first-child,th:first-child{text-align:left}
table.operations :is(td,th):is(:nth-child(2),:nth-child(5)){text-align:left}h2{font-size:16px;margin:14px 0 4px}
#tables{padding:0 16px 16px}
</style><noscript><style>#controls,#poster figcaption .drawing{display:none}#no-scripts{flex:1 1 300px;max-width:420px;margin:0}</style></noscript></head><body>
<header><h1>%TITLE%</h1><p id="who">%WHO%</p></header>
<main><div id="plot"><figure id="poster"><img src="data:image/png;base64,%POSTER%" width="760" height="640" alt="Front view of the plan">
<figcaption>Front view as planned<span class="drawing">; the interactive 3-D view is being drawn…</span></figcaption></figure></div>
<noscript><p id="no-scripts">Her plan from the front, as planned, and its measures below. The interactive 3-D view, its views and its sliders need JavaScript, which is off in this browser.</p></noscript>
<div id="controls">
<div><b>View</b><br><button data-view="right-side">Her right side</button><button data-view="right-oblique">Her right oblique</button><button data-view="front">Front</button><button data-view="left-oblique">Her left oblique</button><button data-view="left-side">Her left side</button><button data-view="top">Top</button></div>
<div id="sliders"></div>
<div><b>Show</b><br><button id="original">Original</button><button id="combined">%PLANNED%</button></div>
<div><b>Colour</b><br><button id="colour-skin" class="on">Her skin</button><button id="colour-moved">Millimetres moved</button></div>
<div><b>Compare</b><br><button id="beside">Before and as planned, side by side</button></div>
<p id="state"></p>
<p>Her skin as scanned, moved as the plan shown would move it (or coloured by how far each point moves). Seen from the side, her skin ends where the camera in front of her stopped seeing it, at her sides; beneath a breast that hangs, which the camera did not see, her skin is drawn straight from the breast's lower edge back to her chest. Red: the sternal notch, the midline and the nipples the measures start from. Blue: each breast's footprint, the outline her volume is measured inside. Purple: the fold beneath each breast, where no change moves it (dotted where the breast hides it and its place is estimated: on her chest behind the breast, seen from below or from her side). The legend shows each breast's scanned points and its fitted model on demand.</p>
</div></main>
<div id="tables">%TABLES%</div>
<script>%SCRIPT%</script>
<script type="text/plain" id="plotly-js">%PLOTLY%</script>
<script type="application/json" id="plan-data">%DATA%</script>
</body></html>
"""

_SCRIPT = r"""
(function(){
function b64(s, T){const b=atob(s);const u=new Uint8Array(b.length);for(let i=0;i<b.length;i++)u[i]=b.charCodeAt(i);return new T(u.buffer);}
function split(f,n,T){T=T||Float32Array;const x=new T(n),y=new T(n),z=new T(n);for(let i=0;i<n;i++){x[i]=f[3*i];y[i]=f[3*i+1];z[i]=f[3*i+2];}return [x,y,z];}
function pts(p){return split(b64(p.xyz,Float32Array),p.n);}
function tri(f){return split(b64(f.faces,f.wide?Int32Array:Uint16Array),f.m,Int32Array);}   // a mesh's faces
function moved(base,d,at,n){const f=new Float32Array(3*n);for(let i=0;i<3*n;i++)f[i]=base[i]+d[at+i];return split(f,n);}
const painted=()=>new Promise(r=>requestAnimationFrame(()=>setTimeout(r,0)));   // after the next frame is painted
const shown=document.querySelector('#poster img').decode().catch(()=>{}).then(painted)
 .then(()=>{window.breastplanShown=true;performance.mark('breastplan-shown');});   // poster and tables painted
const loaded=new Promise(r=>addEventListener('load',()=>setTimeout(r,0)));   // plotly.js and the data read; not in the event
Promise.all([shown,loaded]).then(()=>{
 const js=document.createElement('script');js.textContent=document.getElementById('plotly-js').textContent;
 document.head.appendChild(js);
 draw(JSON.parse(document.getElementById('plan-data').textContent));
});
function draw(P){
const traces=[], idx={};
const still=pts(P.torso), nT=P.torso.n, nP=P.patch.n;
const patchBase=b64(P.patch.xyz,Float32Array);
const sf=tri(P.skin_faces);
idx.skin=traces.length;
traces.push({type:'mesh3d',name:'her skin',i:sf[0],j:sf[1],k:sf[2],showlegend:true,
 lighting:{ambient:1,diffuse:0,specular:0,fresnel:0},hoverinfo:'skip'});   // lit here (shade), the same in every renderer
const LIGHT=P.light, RGB=P.skin_vertex_rgb?b64(P.skin_vertex_rgb,Uint8Array):null;   // her recorded colour, if any
function shade(x,y,z){   // vertex colours: her skin lit from LIGHT (either side of the surface), as the poster is
 const n=x.length,N=new Float32Array(3*n);
 for(let f=0;f<sf[0].length;f++){const a=sf[0][f],b=sf[1][f],c=sf[2][f];
  const ux=x[b]-x[a],uy=y[b]-y[a],uz=z[b]-z[a],vx=x[c]-x[a],vy=y[c]-y[a],vz=z[c]-z[a];
  const nx=uy*vz-uz*vy,ny=uz*vx-ux*vz,nz=ux*vy-uy*vx;
  for(const v of [a,b,c]){N[3*v]+=nx;N[3*v+1]+=ny;N[3*v+2]+=nz;}}
 const out=new Array(n);
 for(let v=0;v<n;v++){const l=Math.hypot(N[3*v],N[3*v+1],N[3*v+2])||1;
  const k=P.shade[0]+P.shade[1]*Math.abs(N[3*v]*LIGHT[0]+N[3*v+1]*LIGHT[1]+N[3*v+2]*LIGHT[2])/l;
  const c=RGB?[RGB[3*v],RGB[3*v+1],RGB[3*v+2]]:P.skin_rgb;
  out[v]='rgb('+c.map(c=>Math.min(255,Math.round(c*k))).join(',')+')';}
 return out;}
const meshBase={};
for(const s of P.sides){
 const sc=pts(P.scans[s]);
 traces.push({type:'scatter3d',mode:'markers',name:s+' breast (scanned)',x:sc[0],y:sc[1],z:sc[2],visible:'legendonly',
  marker:{size:1.6,color:P.scan},hoverinfo:'skip'});
 const m=P.meshes[s]; meshBase[s]=b64(m.xyz,Float32Array);
 const f=tri(m);
 idx[s]=traces.length;
 traces.push({type:'mesh3d',name:s+' breast (model)',i:f[0],j:f[1],k:f[2],color:P.model,opacity:0.6,showlegend:true,
  visible:'legendonly',flatshading:false,lighting:{ambient:0.55,diffuse:0.7,specular:0.15},hoverinfo:'skip'});
}
for(const s of Object.keys(P.earlier)){   // a follow-up: the breast as fitted at the earlier visit
 const m=P.earlier[s];const v=pts(m);const f=tri(m);
 traces.push({type:'mesh3d',name:s+' breast (earlier visit)',x:v[0],y:v[1],z:v[2],i:f[0],j:f[1],k:f[2],
  color:'#6a7fb5',opacity:0.35,showlegend:true,hoverinfo:'skip'});
}
const L=P.landmarks, col=k=>[0,1,2].map(a=>L[k].map(p=>p[a]));   // what the measures start from
const mark={color:P.landmark};
traces.push({type:'scatter3d',mode:'lines',name:'midline',legendgroup:'landmarks',x:col('midline')[0],
 y:col('midline')[1],z:col('midline')[2],line:{...mark,width:3,dash:'dash'},hoverinfo:'skip'});
idx.notch=traces.length;
traces.push({type:'scatter3d',mode:'markers+text',name:'sternal notch',legendgroup:'landmarks',x:col('sternal notch')[0],
 y:col('sternal notch')[1],z:col('sternal notch')[2],text:['\u2002sternal notch'],textposition:'middle right',
 textfont:{...mark,size:11},marker:{...mark,size:4},hoverinfo:'skip'});
idx.nipples=traces.length;
traces.push({type:'scatter3d',mode:'markers',name:'nipples (found)',legendgroup:'landmarks',x:col('nipples')[0],
 y:col('nipples')[1],z:col('nipples')[2],marker:{...mark,size:3.5,symbol:'diamond'},hoverinfo:'skip'});
const sides=Object.keys(P.side_labels);   // her sides named on her body (hers, not the viewer's)
idx.sides=traces.length;
traces.push({type:'scatter3d',mode:'text',name:'her sides',x:sides.map(s=>P.side_labels[s][0]),
 y:sides.map(s=>P.side_labels[s][1]),z:sides.map(s=>P.side_labels[s][2]),text:sides.map(s=>'her '+s),
 textfont:{color:'#333',size:13},hoverinfo:'skip',showlegend:false});
idx.folds={};idx.footprints={};
for(const s of Object.keys(P.folds)){   // the fold under each breast, where "nipple to fold" is measured to
 const F=P.folds[s].xyz;idx.folds[s]=traces.length;
 traces.push({type:'scatter3d',mode:'lines',name:s+' fold ('+P.folds[s].from+')',legendgroup:'folds',x:F.map(p=>p[0]),
  y:F.map(p=>p[1]),z:F.map(p=>p[2]),line:{color:P.fold,width:5,dash:P.folds[s].from==='seen'?'solid':'dot'},
  hovertemplate:'her '+s+' inframammary fold ('+P.folds[s].from+')<extra></extra>'});
}
for(const s of Object.keys(P.footprints)){   // the outline each breast's volume is measured inside
 const F=P.footprints[s];idx.footprints[s]=traces.length;
 traces.push({type:'scatter3d',mode:'lines',name:s+' footprint',legendgroup:'footprints',x:F.map(p=>p[0]),
  y:F.map(p=>p[1]),z:F.map(p=>p[2]),line:{color:P.footprint,width:6},hoverinfo:'skip'});
}
const around=a=>({eye:{x:1.45*Math.sin(a*Math.PI/180),y:-1.45*Math.cos(a*Math.PI/180),z:0.12},up:{x:0,y:0,z:1}});   // a: degrees towards her left
const views={'right-side':around(-90),'right-oblique':around(-45),front:around(0),'left-oblique':around(45),
 'left-side':around(90),top:{eye:{x:0,y:-0.15,z:1.45},up:{x:0,y:1,z:0}}};
const NARROW_PX=600, LEGEND={x:0,y:1};
const layout={margin:{l:0,r:0,t:0,b:0},showlegend:true,legend:LEGEND,hovermode:false,   // the legend beside the body, not over it
 scene:{domain:{x:[0.26,1],y:[0,1]},aspectmode:'data',xaxis:{visible:false},yaxis:{visible:false},zaxis:{visible:false},camera:views.front}};
const gd=document.getElementById('plot');
const G=P.grid, K=G.scales.length, coef=b64(G.coefficients,Float32Array), modes=b64(G.modes,Int16Array);
const M=K?modes.length/K:0;   // every slider state: its displacements of the patch, then each side's mesh, K modes
function displacement(i){const d=new Float64Array(M);
 for(let k=0;k<K;k++){const w=coef[i*K+k]*G.scales[k];if(!w)continue;for(let j=0,o=k*M;j<M;j++)d[j]+=w*modes[o+j];}
 return d;}
function stateAt(i){   // slider state i as the plan computed it: its name, words and measures
 const pick=m=>Object.fromEntries(Object.entries(m).map(([k,v])=>[k,v[i]]));
 const short=digits(i).flatMap((d,k)=>G.notes[k][d]).map(n=>'; '+n).join('');   // where a breast stops short
 return {index:i,key:G.keys[i],words:G.words[i]+short,asymmetry:pick(G.asymmetry),
  measures:Object.fromEntries(P.sides.map(s=>[s,pick(G.measures[s])]))};}
let shownD=null;   // the displacements of the state shown (null: her skin as scanned), for the marks on her too
function arrays(state){   // the moving traces' coordinates in `state`; null: the original
 const upd={x:[],y:[],z:[]};
 const d=state?displacement(state.index):null;shownD=d;
 const pos=d?moved(patchBase,d,0,nP):split(patchBase,nP);
 for(let a=0;a<3;a++){const o=new Float32Array(nT+nP);o.set(still[a]);o.set(pos[a],nT);upd['xyz'[a]].push(o);}
 let at=3*nP;
 for(const s of P.sides){const n=P.meshes[s].n,v=d?moved(meshBase[s],d,at,n):split(meshBase[s],n);at+=3*n;
  upd.x.push(v[0]);upd.y.push(v[1]);upd.z.push(v[2]);}
 return upd;
}
const ids=[idx.skin].concat(P.sides.map(s=>idx[s]));
function digits(i){   // each kind's slider position in state i
 const out=[];for(let k=G.kinds.length-1;k>=0;k--){const n=G.degrees[k].length;out[k]=i%n;i=Math.floor(i/n);}
 return out;}
function label(state){   // what is shown, in words; the sliders and the measures' "as planned" cells follow it
 window.breastplanState=state?state.key:'original';
 document.getElementById('state').textContent='Showing: '+(state?state.words:'the original breasts');
 const at=state?digits(state.index):null;
 G.kinds.forEach((kind,k)=>{const inp=document.getElementById('slider-'+kind);
  if(at)inp.value=at[k];
  const d=G.degrees[k][+inp.value];
  const short=state&&G.reached[k][+inp.value];   // the breasts stop short of the slider's degree
  inp.previousSibling.textContent=kind+(d===0?': off':': degree '+d)+(d===G.requested[k]?' (planned)':'')+(state?'':' (not shown)')
   +(short?' (reaches '+short+(short.includes(' and ')?', her right and left)':')'):'');
  inp.previousSibling.classList.toggle('off',!state);});
 for(const c of document.querySelectorAll('[data-after]')){const [side,name]=c.dataset.after.split(' ');
  const key=(c.dataset.forHer!==undefined?'plain:':'')+name;   // each figure as the plan wrote it
  c.textContent=(state?state.measures:P.before)[side][key];}
 for(const c of document.querySelectorAll('[data-asymmetry]')){const name=c.dataset.asymmetry;
  c.textContent=state?state.asymmetry[name]:P.asymmetry_before[name];}
}
let colourBy='skin';   // her skin shaded, or each point's distance moved by the state shown (mm)
const SCALE_AT=0.88;   // where the scale of millimetres moved stands, her picture to its left
function movedMM(upd){const mm=new Float32Array(nT+nP);let top=0;
 for(let v=0;v<nP;v++){const d=Math.hypot(upd.x[0][nT+v]-patchBase[3*v],upd.y[0][nT+v]-patchBase[3*v+1],upd.z[0][nT+v]-patchBase[3*v+2]);
  mm[nT+v]=d;if(d>top)top=d;}
 return [mm,top];}
function put(upd){ids.forEach((t,n)=>{traces[t]=Object.assign({},traces[t],{x:upd.x[n],y:upd.y[n],z:upd.z[n]});});
 const skin=Object.assign({},traces[idx.skin]);
 if(colourBy==='moved'){const [mm,top]=movedMM(upd);delete skin.vertexcolor;
  Object.assign(skin,{intensity:mm,cmin:0,cmax:Math.max(1,Math.ceil(top)),colorscale:[[0,'#f3ece6'],[0.5,'#f4a582'],[1,'#b2182b']],
   showscale:true,colorbar:{title:{text:'mm moved'},len:0.6,x:SCALE_AT,xanchor:'left'},hovertemplate:'moved %{intensity:.1f} mm<extra></extra>',hoverinfo:undefined});}
 else{for(const k of ['intensity','cmin','cmax','colorscale','colorbar'])delete skin[k];
  Object.assign(skin,{vertexcolor:shade(upd.x[0],upd.y[0],upd.z[0]),showscale:false,hoverinfo:'skip',hovertemplate:undefined});}
 skin.uid='her-skin-'+colourBy;   // a new mesh for each colouring: updated in place, plotly keeps the moved colours
 traces[idx.skin]=skin;}
let current=null;   // the state shown (null: the original)
let beside=false;   // her skin before (left) beside the state shown (right), one camera for both
const still0=arrays(null);
idx.before=traces.length;
traces.push({type:'mesh3d',name:'before',scene:'scene2',x:still0.x[0],y:still0.y[0],z:still0.z[0],i:sf[0],j:sf[1],k:sf[2],
 vertexcolor:shade(still0.x[0],still0.y[0],still0.z[0]),lighting:{ambient:1,diffuse:0,specular:0,fresnel:0},
 hoverinfo:'skip',showlegend:false});
function scenes(layout){   // the layout's scenes for one view or two side by side, the camera kept
 const cam=(gd.layout&&gd.layout.scene&&gd.layout.scene.camera)||views.front;
 const end=colourBy==='moved'?SCALE_AT:1;   // the colour scale beside her, not over her
 const narrow=gd.clientWidth<NARROW_PX;   // a phone: the legend in rows below her, not over her
 const one={domain:narrow?{x:[0,end],y:[0.36,1]}:{x:[0.26,end],y:[0,1]}},two={domain:{x:[0.5,end],y:[0,1]}},left={domain:{x:[0,0.5],y:[0,1]}};
 const B=P.bounds,size=B.map(r=>r[1]-r[0]),most=Math.max(...size);   // one box and scale for every scene
 const axes={aspectmode:'manual',aspectratio:{x:size[0]/most,y:size[1]/most,z:size[2]/most},camera:cam,
  xaxis:{visible:false,range:B[0]},yaxis:{visible:false,range:B[1]},zaxis:{visible:false,range:B[2]}};
 const out=Object.assign({},layout,{scene:Object.assign({},axes,beside?two:one),showlegend:!beside,   // beside: no legend
  legend:narrow?{orientation:'h',x:0,y:0,yanchor:'bottom',font:{size:11}}:LEGEND,
  annotations:beside?[{text:'before',x:0.25,y:0.01,xref:'paper',yref:'paper',showarrow:false,yanchor:'bottom'},
   {text:'as shown',x:0.75,y:0.01,xref:'paper',yref:'paper',showarrow:false,yanchor:'bottom'}]:[]});
 if(beside)out.scene2=Object.assign({},axes,left);else delete out.scene2;
 return out;}
const drawn=()=>beside?traces:traces.filter((_,i)=>i!==idx.before);   // the traces drawn: the scene before only beside
const found={nipples:{null:L.nipples},footprints:P.footprints};   // the marks that move with her skin (`mark_layout`)
const markAt=3*(nP+P.sides.reduce((n,s)=>n+P.meshes[s].n,0));   // the marks' displacements follow the meshes'
function placed(state){   // the marks on her: as found, or moved as the state shown moves her skin
 const at=(t,F)=>{traces[t]=Object.assign({},traces[t],{x:F.map(p=>p[0]),y:F.map(p=>p[1]),z:F.map(p=>p[2])});};
 for(const [name,side,a,b] of P.mark_layout){const F=found[name][side];
  const m=state&&shownD?F.map((p,r)=>p.map((v,c)=>v+shownD[markAt+3*(a+r)+c])):F;
  at(side===null?idx.nipples:idx[name][side],m);}
 at(idx.sides,sides.map(s=>(state&&P.operated_labels?P.operated_labels:P.side_labels)[s]));}
function show(state){current=state;label(state);put(arrays(state));placed(state);const key=window.breastplanState;
 return Plotly.react(gd,drawn(),scenes(Object.assign({},gd.layout,{hovermode:colourBy==='moved'?'closest':false})))
  .then(()=>{window.breastplanDrawn=key;});}
document.getElementById('beside').onclick=()=>{beside=!beside;document.getElementById('beside').classList.toggle('on',beside);
 window.breastplanBeside=beside;return show(current);};
let syncing=false;   // one camera for both scenes: a turn of either turns the other
function linked(ev){const cam=ev['scene.camera']||ev['scene2.camera'];if(!cam||syncing||!beside)return;
 syncing=true;Plotly.relayout(gd,{'scene.camera':cam,'scene2.camera':cam}).then(()=>{syncing=false;});}
for(const [id,by] of [['colour-skin','skin'],['colour-moved','moved']])document.getElementById(id).onclick=()=>{
 colourBy=by;document.getElementById('colour-skin').classList.toggle('on',by==='skin');
 document.getElementById('colour-moved').classList.toggle('on',by==='moved');window.breastplanColour=by;return show(current);};
const box=document.getElementById('sliders');
function chosen(){   // the state every slider's degree names: each keeps its own
 return stateAt(G.kinds.reduce((i,kind,k)=>i*G.degrees[k].length+(+document.getElementById('slider-'+kind).value),0));}
G.kinds.forEach((kind,k)=>{
 const div=document.createElement('div');div.className='slider';
 const lab=document.createElement('label');const inp=document.createElement('input');
 inp.type='range';inp.min=0;inp.max=G.degrees[k].length-1;inp.step=1;inp.id='slider-'+kind;
 inp.value=G.degrees[k].indexOf(G.requested[k]);
 inp.addEventListener('input',()=>show(chosen()));
 div.appendChild(lab);div.appendChild(inp);box.appendChild(div);
});
document.getElementById('original').onclick=()=>show(null);
const comb=document.getElementById('combined');
if(G.kinds.length!==1){comb.onclick=()=>show(stateAt(G.planned));}else{comb.style.display='none';}
const named=v=>sides.map(s=>v.endsWith('-side')&&!v.startsWith(s)?'':'her '+s);   // a side view names its own side only
for(const b of document.querySelectorAll('button[data-view]'))b.onclick=()=>{const v=b.dataset.view;
 traces[idx.sides]=Object.assign({},traces[idx.sides],{text:named(v)});
 traces[idx.notch]=Object.assign({},traces[idx.notch],   // the notch's name reaches in front of her, not into her neck
  {textposition:v.startsWith('left')?'middle left':'middle right',text:[v.startsWith('left')?'sternal notch\u2002':'\u2002sternal notch']});
 const layout=scenes(gd.layout);layout.scene.camera=views[v];if(beside)layout.scene2.camera=views[v];
 return Plotly.react(gd,drawn(),layout);};
const first=stateAt(G.planned);
current=first;
put(arrays(first));
placed(first);
label(first);
Plotly.newPlot(gd,drawn(),scenes(layout),   // a phone: no tool bar over her head (the view buttons turn her)
 {displaylogo:false,responsive:true,displayModeBar:gd.clientWidth<NARROW_PX?false:'hover'}).then(()=>{gd.on('plotly_relayout',linked);
 document.getElementById('poster').hidden=true;   // kept for print
 window.breastplanDrawn=window.breastplanState;return painted();})
 .then(()=>{window.breastplanReady=true;performance.mark('breastplan-ready');});   // the 3-D scene painted
}
})();
"""
