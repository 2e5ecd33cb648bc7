"""The `fit` command: the breast model (superquadric + FFD lattice) fitted to an ingested breast."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np
import typer

from breastplan import BadInputError, read_ply
from breastplan.deform.global_deformations import KIND_PARAMS
from breastplan.fitting.breast_fit import DEFORMATIONS, fit_breast
from breastplan.ingest.scan import load_scan

from .app import JSON, app
from .output import Timer, report, usage_error


@app.command()
def fit(
    input: Path = typer.Argument(..., help="A case folder from `ingest` (scan.ply, scan.npz) or a breast-frame PLY (mm)."),
    out: Optional[Path] = typer.Option(None, "--out", help="Folder for fit.npz and fit.ply (default: the case folder, "
                                       "or the PLY's folder)."),
    lattice: int = typer.Option(5, "--lattice", help="Control points per lattice axis, 3..7 (5 = 125 CP)."),
    deformations: str = typer.Option(",".join(DEFORMATIONS), "--deformations", help="Global deformations fitted with the "
                                     f"primitive, comma-separated from {', '.join(KIND_PARAMS)}; 'none' for the "
                                     "plain primitive."),
    max_iterations: int = typer.Option(1000, "--max-iterations", help="FFD iterations before giving up (thesis: 1000)."),
    max_seconds: float = typer.Option(20.0, "--max-seconds", help="Time guard of the FFD fit, seconds."),
    as_json: bool = JSON,
):
    """Fit the breast primitive, its pose and an FFD lattice to a breast in the breast frame."""
    timer = Timer()
    if not 3 <= lattice <= 7:
        raise usage_error(f"--lattice must be 3..7, got {lattice}", "--lattice")
    kinds = tuple(k.strip() for k in deformations.split(",") if k.strip() not in ("", "none"))
    unknown = sorted(set(kinds) - set(KIND_PARAMS))
    if unknown:
        raise usage_error(f"unknown deformations {unknown}; choose from {', '.join(KIND_PARAMS)}", "--deformations")
    if max_iterations < 1 or not max_seconds > 0:
        raise usage_error("--max-iterations must be at least 1 and --max-seconds positive", "--max-iterations")
    points, source, folder = _breast_points(input)
    result = fit_breast(points, lattice, kinds, path=source, max_iterations=max_iterations,
                        max_seconds=max_seconds)
    paths = result.save(out or folder)
    stats = result.residual_stats()
    report({"fit": str(paths["fit_npz"]), "mesh": str(paths["fit_ply"]), "points": len(points),
            "volume_cc": round(result.volume_cc, 2),
            "volume_cc_primitive": round(result.superquadric.primitive.volume_cc, 2),
            "rms_mm": round(stats["rms"], 4), "residuals_mm": {k: round(v, 4) for k, v in stats.items()},
            "normalised_residual": round(result.ffd.residual, 6),
            "iterations": {"superquadric": result.superquadric.iterations, "ffd": result.ffd.iterations},
            "params": {k: round(v, 5) for k, v in result.params().items()},
            "seconds": timer.seconds}, as_json, f"fit → {paths['fit_ply']}")


def _breast_points(input: Path) -> tuple[np.ndarray, Path, Path]:
    """(points mm, the file they came from, the default output folder) of a case folder or a PLY."""
    if input.is_dir():
        load_scan(input / "scan.npz")       # a case folder must hold a valid ingest artefact
        source = input / "scan.ply"
        folder = input
    elif input.suffix.lower() == ".ply" or not input.exists():
        source, folder = input, input.parent
    else:
        raise BadInputError(input, "is neither a PLY file nor a case folder from `breastplan ingest`")
    points = read_ply(source).points
    extent = np.ptp(points, axis=0).max() if len(points) else 0.0
    if 0 < extent < 5.0:
        raise BadInputError(source, f"spans only {extent:.3g} units: fit takes millimetres (is it in metres?)")
    return points, source, folder
