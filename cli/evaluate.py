"""The `evaluate` command: the thesis study of deformation-parameter regressions, and its report."""
from __future__ import annotations

from pathlib import Path

import typer

from breastplan.clock import Clock
from breastplan.learn.studies import STUDIES

from .app import JSON, command
from .output import progress, report, usage_error


@command()
def evaluate(
    study: str = typer.Option(..., "--study", help=f"{' | '.join(STUDIES)} | all."),
    dd: int = typer.Option(8, "--dd", help="Number of degrees of deformation: 4 or 8 (thesis)."),
    quick: bool = typer.Option(False, "--quick", help="Small grid, FS5 only, 4 breasts per shape and split, 2500 points (CI)."),
    out: Path = typer.Option(..., "--out", help="Folder for report.md, report.json and figures/."),
    as_json: bool = JSON,
):
    """Run the thesis study of deformation-parameter regressions; write its report."""
    clock = Clock()
    names = list(STUDIES) if study == "all" else [study]
    if any(n not in STUDIES for n in names):
        raise usage_error(f"'{study}' is not a study; choose one of {', '.join(STUDIES)} or all", "--study")
    if dd not in (4, 8):
        raise usage_error(f"--dd must be 4 or 8 (thesis), got {dd}", "--dd")

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
