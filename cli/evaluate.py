"""The `evaluate` command: the thesis study of deformation-parameter regressions, and its report."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from breastplan.clock import Clock
from breastplan.learn.studies import STUDIES

from .app import JSON, command
from .output import cache_folder, progress, report, usage_error, writable


@command()
def evaluate(
    study: str = typer.Option(..., "--study", help=f"{' | '.join(STUDIES)} | all | statistical (FFD models "
                                                   "learnt from before/after pairs)."),
    dd: Optional[int] = typer.Option(None, "--dd", help="Number of degrees of deformation of a regression study: "
                                                        "4 or 8 (thesis; default 8)."),
    quick: bool = typer.Option(False, "--quick", help="Small grid, FS5 only, 4 breasts per shape and split, 2500 points (CI)."),
    out: Path = typer.Option(..., "--out", help="Folder for report.md, report.json and figures/."),
    cache: Path = typer.Option(None, "--cache", help="Folder of cached FFD fits (statistical study; default: "
                                                     "$BREASTPLAN_CACHE or ~/.cache/breastplan/ffd)."),
    as_json: bool = JSON,
):
    """Run the thesis study of deformation-parameter regressions, or of statistical models; write its report."""
    clock = Clock()
    names = list(STUDIES) if study == "all" else [study]
    if study == "statistical" and dd is not None:
        raise usage_error("the statistical study learns from pairs of every degree; --dd is for the "
                          "regression studies", "--dd")
    if study != "statistical" and any(n not in STUDIES for n in names):
        raise usage_error(f"'{study}' is not a study; choose one of {', '.join(STUDIES)}, all or statistical",
                          "--study")
    if study != "statistical" and cache is not None:
        raise usage_error("the regression studies fit no FFD; --cache is for the statistical study", "--cache")
    dd = 8 if dd is None else dd
    if dd not in (4, 8):
        raise usage_error(f"--dd must be 4 or 8 (thesis), got {dd}", "--dd")
    writable(out, folder=True)
    if study == "statistical":
        return _statistical(quick, out, cache_folder(cache), as_json, clock)

    from breastplan.learn.report import write_report
    from breastplan.learn.study import configurations, run_studies, study_datasets

    total = sum(len(STUDIES[n].conditions) * configurations(STUDIES[n], quick) for n in names)
    datasets = study_datasets(names, dd, quick)
    with progress(f"study {study}", total) as advance:
        results = run_studies(datasets, quick, advance)
    meta = {"study": study, "dd": dd, "quick": quick, "seconds": clock.seconds}
    written = write_report(out, results, meta)
    best = {f"{h['study']} {h['condition']}": {"best": h["best"],
                                               "euclidean_mean_pct": round(h["best_learnt"]["euclidean"], 4),
                                               "hausdorff_mean_pct": round(h["best_learnt"]["hausdorff"], 4),
                                               "exact_euclidean_mean_pct": round(h["exact_continuous"]["euclidean"], 4)}
            for h in written["best"]}
    report({"report": str(out / "report.md"), "rows": len(written["rows"]), "best": best,
            "seconds": clock.seconds}, as_json, f"study {study}")


def _statistical(quick: bool, out: Path, cache: Path | None, as_json: bool, clock: Clock) -> None:
    from threadpoolctl import threadpool_limits

    from breastplan.learn.displacements import FitCache
    from breastplan.learn.statistical_report import write_report
    from breastplan.learn.statistical_study import StudyPlan, run_study, study_database

    plan = StudyPlan.quick_plan() if quick else StudyPlan()
    db = study_database(quick)
    with progress("statistical study", plan.steps(len(db), len(db) * 8)) as advance, threadpool_limits(1, "blas"):
        results, seconds = run_study(plan, FitCache(cache), advance)
    meta = {"study": "statistical", "quick": quick, "fit_seconds": seconds, "seconds": clock.seconds}
    written = write_report(out, results, meta)
    best = {f"{h['condition']} {h['control_points']} CP {h['fit']}": {
        "best": h["best"], "euclidean_mean_pct": round(h["euclidean"], 4), "hausdorff_mean_pct": round(h["hausdorff"], 4),
        "spike_free_pct": round(h["spike_free_pct"], 1),
        "vertex_spike_free_pct": round(h["vertex_spike_free_pct"], 1)} for h in written["best"]}
    report({"report": str(out / "report.md"), "rows": len(written["rows"]), "best": best,
            "fit_seconds": seconds, "seconds": clock.seconds}, as_json, "statistical study")
