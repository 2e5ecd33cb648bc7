"""The statistical study's report, in the parametric study's format: `report.json` (meta, one row per
method and direction, the best per condition, t-tests) and `report.md` (thesis Table 5.8 beside ours)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from breastplan.json_text import to_json

from .metrics import summary, ttest
from .report import DIRECTIONS, _f, _plain, _write_text, hyper_text, ttest_cells
from .statistical_study import CONTINUOUS_ROW, SPIKE, THESIS_CONDITION, THESIS_HAUSDORFF, StatResult

FIELD_ROW, UNCHANGED_ROW = "FFD fit", "no change"
THESIS_ROW = "MLP (thesis)"


def _key(r: StatResult) -> tuple[str, int, str]:
    return r.condition, r.lattice, r.fit


def best_of(results: list[StatResult]) -> StatResult:
    """The learnt row with the lowest cross-validated field RMSE (chosen without the test split)."""
    return min((r for r in results if np.isfinite(r.cv_rmse_pct)), key=lambda r: r.cv_rmse_pct)


def json_rows(results: list[StatResult]) -> list[dict]:
    rows = []
    for r in results:
        for direction in DIRECTIONS:
            row = {"condition": r.condition, "control_points": r.control_points, "fit": r.fit, "method": r.method,
                   "direction": direction, "hyper": {k: _plain(v) for k, v in r.hyper.items()},
                   "cv_rmse_pct": _plain(r.cv_rmse_pct), "rmse_pct": r.rmse_pct, "n_test": len(r.spikes),
                   "spike_free_pct": r.spike_free_pct, "spike_ratio_median": float(np.median(r.spikes)),
                   "vertex_spike_free_pct": r.vertex_spike_free_pct}
            for metric in ("euclidean", "hausdorff"):
                row.update({f"{metric}_{k}_pct": v for k, v in summary(r.distances[f"{direction}_{metric}"]).items()})
            if r.condition == THESIS_CONDITION and r.method == THESIS_ROW and direction == DIRECTIONS[0]:
                row["thesis_hausdorff_mean_pct"] = THESIS_HAUSDORFF.get(r.lattice)
            rows.append(row)
    return rows


def _mean(r: StatResult, metric: str) -> float:
    return float(np.mean(r.distances[f"modelled_to_original_{metric}"]))


def write_report(out: Path, results: list[StatResult], meta: dict) -> dict:
    """Write report.json and report.md into `out`; returns the JSON object."""
    out.mkdir(parents=True, exist_ok=True)
    groups = {}
    for r in results:
        groups.setdefault(_key(r), []).append(r)
    best, tests = [], {}
    key = "modelled_to_original_euclidean"
    for (cond, n, fit), rows in groups.items():
        b = best_of(rows)
        pick = {r.method: r for r in rows}
        best.append({"condition": cond, "control_points": n ** 3, "fit": fit, "best": b.method,
                     "euclidean": _mean(b, "euclidean"), "hausdorff": _mean(b, "hausdorff"),
                     "hausdorff_max": float(np.max(b.distances["modelled_to_original_hausdorff"])),
                     "spike_free_pct": b.spike_free_pct, "vertex_spike_free_pct": b.vertex_spike_free_pct,
                     "field": {**{m: _mean(pick[FIELD_ROW], m) for m in ("euclidean", "hausdorff")},
                               "spike_free_pct": pick[FIELD_ROW].spike_free_pct},
                     "unchanged": {m: _mean(pick[UNCHANGED_ROW], m) for m in ("euclidean", "hausdorff")},
                     "thesis_model": ({m: _mean(pick[THESIS_ROW], m) for m in ("euclidean", "hausdorff")}
                                      if THESIS_ROW in pick else None),
                     "thesis_hausdorff": THESIS_HAUSDORFF.get(n) if cond == THESIS_CONDITION else None})
        if THESIS_ROW in pick:
            tests[f"{cond} {n ** 3} CP {fit}: {b.method} vs {THESIS_ROW}"] = ttest(b.distances[key], pick[THESIS_ROW].distances[key])
        continuous = [r for r in rows if r.method.endswith(CONTINUOUS_ROW)]
        discrete = [r for r in rows if r.method.startswith("PCA") and not r.method.endswith(CONTINUOUS_ROW)]
        if continuous and discrete:
            c, d = best_of(continuous), best_of(discrete)
            tests[f"{cond} {n ** 3} CP {fit}: {c.method} vs {d.method}"] = ttest(c.distances[key], d.distances[key])
    by_lattice = {r.lattice: r for r in results if r.method == THESIS_ROW and r.fit == results[0].fit}
    if len(by_lattice) == 2:
        (a, ra), (b, rb) = sorted(by_lattice.items())
        tests[f"{THESIS_ROW}: {a ** 3} vs {b ** 3} CP"] = ttest(ra.distances[key], rb.distances[key])
    report = {"meta": meta, "rows": json_rows(results), "best": best, "t_tests": tests, "figures": {}}
    _write_text(out / "report.json", to_json(report, indent=1))
    _write_text(out / "report.md", markdown(report, results))
    return report


def markdown(report: dict, results: list[StatResult]) -> str:
    lines = ["# breastplan statistical study report", "", f"Run: {json.dumps(report['meta'])}", "",
             "Database S, test split, modelled ⇒ original, % of ‖o‖ (docs/model.md §7). Each pair is an FFD",
             "displacement field, fitted from corresponding points or by closest points; *FFD fit* applies each",
             "test pair's own fitted field (the floor of every model), *no change* the original breast (the ceiling). *Best*: the learnt row with the lowest",
             "cross-validated field RMSE. *Spike-free*: share of test breasts whose largest modelled ⇒ original",
             f"distance is at most {SPIKE:g}× their median; *vertex spike-free*: the same on vertex errors, the",
             "distance of each moved point to its true position (stricter: it also counts points sliding",
             "along the surface).", "",
             "## Headline (thesis Table 5.8 beside ours)", "",
             "| condition | CP | fit | thesis Hausd. µ | thesis MLP (ours) Eucl. µ | Hausd. µ | best | best Eucl. µ | "
             "best Hausd. µ | best Hausd. max | spike-free % | vertex spike-free % | FFD fit Eucl. µ | "
             "FFD fit Hausd. µ | no change Eucl. µ | no change Hausd. µ |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for h in report["best"]:
        t = h["thesis_model"] or {}
        lines.append(f"| {h['condition']} | {h['control_points']} | {h['fit']} | {_f(h['thesis_hausdorff'])} | "
                     f"{_f(t.get('euclidean'))} | {_f(t.get('hausdorff'))} | {h['best']} | {_f(h['euclidean'])} | "
                     f"{_f(h['hausdorff'])} | {_f(h['hausdorff_max'])} | {_f(h['spike_free_pct'])} | "
                     f"{_f(h['vertex_spike_free_pct'])} | "
                     f"{_f(h['field']['euclidean'])} | {_f(h['field']['hausdorff'])} | "
                     f"{_f(h['unchanged']['euclidean'])} | {_f(h['unchanged']['hausdorff'])} |")
    lines += ["", "## Every method", "",
              "| condition | CP | fit | method | CV field RMSE | field RMSE | M⇒O Eucl. µ | M⇒O Hausd. µ | Hausd. max | "
              "O⇒M Eucl. µ | O⇒M Hausd. µ | spike-free % | vertex spike-free % | hyper-parameters |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        d = r.distances
        lines.append(f"| {r.condition} | {r.control_points} | {r.fit} | {r.method} | {_f(r.cv_rmse_pct)} | {_f(r.rmse_pct)} | "
                     f"{_f(float(np.mean(d['modelled_to_original_euclidean'])))} | "
                     f"{_f(float(np.mean(d['modelled_to_original_hausdorff'])))} | "
                     f"{_f(float(np.max(d['modelled_to_original_hausdorff'])))} | "
                     f"{_f(float(np.mean(d['original_to_modelled_euclidean'])))} | "
                     f"{_f(float(np.mean(d['original_to_modelled_hausdorff'])))} | {_f(r.spike_free_pct)} | "
                     f"{_f(r.vertex_spike_free_pct)} | {hyper_text(r.hyper)} |")
    lines += ["", "## t-tests (modelled ⇒ original Euclidean per test example, pooled, α = 0.05)", "",
              "| comparison | t | p | significant |", "|---|---|---|---|"]
    for name, t in report["t_tests"].items():
        lines.append(f"| {name} | {ttest_cells(t)} |")
    return "\n".join(lines) + "\n"
