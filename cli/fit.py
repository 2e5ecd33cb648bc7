"""The `fit` command: the breast model (superquadric + FFD lattice) fitted to an ingested breast."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Optional

import typer

from breastplan import BadInputError
from breastplan.clock import Clock
from breastplan.deform.names import KIND_PARAMS
from breastplan.errors import about, require_folder
from breastplan.options import DEFORMATIONS, FitOptions, OptionError

from .app import JSON, command
from .output import read_only, report, stderr, usage_error, writable

if TYPE_CHECKING:
    import numpy as np

    from breastplan.case import Scan


@command()
def fit(
    input: Path = typer.Argument(..., help="A case folder from `ingest` (scan.ply, scan.npz; the "
                                "breast's volume reaches down to its chest wall) or a breast-frame PLY (mm; its base "
                                "is the plane z = 0)."),
    out: Optional[Path] = typer.Option(None, "--out", help="Folder for fit.npz and fit.ply (default: the case folder, "
                                       "or the PLY's folder)."),
    lattice: int = typer.Option(5, "--lattice", help="Control points per lattice axis, 3..7 (5 = 125 CP)."),
    deformations: str = typer.Option(",".join(DEFORMATIONS), "--deformations", help="Global deformations fitted with the "
                                     f"primitive, comma-separated from {', '.join(KIND_PARAMS)}; 'none' for the "
                                     "plain primitive."),
    max_iterations: int = typer.Option(1000, "--max-iterations", help="FFD iterations before stopping (thesis: "
                                       "1000); a fit that stops above the stopping rule is written and says so."),
    wall_from: Optional[Path] = typer.Option(None, "--wall-from", help="An earlier case folder of the same patient "
                                             "and side (or a plan's, holding that side): the breast is measured "
                                             "down to that case's chest wall, carried over by registering the two "
                                             "chests around the breast (a follow-up scan: a change measured on one "
                                             "wall)."),
    as_json: bool = JSON,
):
    """Fit the breast primitive, its pose and an FFD lattice to a breast in the breast frame."""
    clock = Clock()
    names = [k.strip() for k in deformations.split(",")]
    if "" in names or ("none" in names and len(names) > 1):
        raise usage_error(f"'{deformations}' is no list of deformations: name them, comma-separated, or 'none'",
                          "--deformations")
    kinds = tuple(k for k in names if k != "none")
    unknown = sorted(set(kinds) - set(KIND_PARAMS))
    if unknown:
        raise usage_error(f"unknown deformations {unknown}; choose from {', '.join(KIND_PARAMS)}", "--deformations")
    try:
        options = FitOptions(lattice, kinds, max_iterations)
    except OptionError as exc:
        raise usage_error(str(exc), {"lattice": "--lattice", "max_iterations": "--max-iterations",
                                       "deformations": "--deformations"}[exc.option]) from None

    points, scan, source, folder = _breast_points(input)     # bad input is refused before the stage loads
    if wall_from is not None and scan is None:
        raise usage_error("--wall-from measures a case folder from `breastplan ingest` on an earlier case's chest "
                          f"wall; {input} is a breast-frame PLY, whose chest is not known", "--wall-from")
    earlier = None
    if wall_from is not None:
        from breastplan.ingest.follow_up import earlier_case

        read_only(wall_from, out or folder)

        earlier = earlier_case(wall_from, scan.side)           # in a plan's folder, the case of this side
        earlier_scan = earlier.load_scan()
    writable(out or folder, folder=True)

    from breastplan.case import Case, Provenance
    from breastplan.fitting.ffd import STOP_RESIDUAL
    from breastplan.plan.stages import fit_one_thread, on_earlier_wall

    if scan is not None:                                      # refused before anything is written
        with about(folder):
            measured, both = measured_volume(scan, folder)
    inputs, carried = {source.name: source}, {}
    if earlier is not None:
        scan, _, earlier_inputs, carried = on_earlier_wall(scan, earlier, earlier_scan)
        inputs.update(earlier_inputs)
    result = fit_one_thread(points if scan is None else scan, options, source)
    fit = result.artefact(Provenance.of(inputs, {**options.as_dict(), **carried}))
    paths = Case(out or folder).save_fit(fit)
    if not fit.stopping_rule_met:
        how = ("stopped improving" if fit.converged else
               f"stopped after its {max_iterations} FFD iteration{'s' * (max_iterations != 1)} (--max-iterations)")
        floor = " (noise in the scan can set such a floor)" if fit.converged else ""
        stderr.print(f"warning: {source}: the fit {how} at mean normalised residual {fit.normalised_residual:.4f}, "
                     f"above the stopping rule {STOP_RESIDUAL}{floor}; its artefacts are written, and fit.npz maps "
                     f"each point's residual (residual_map_mm).", markup=False,
                     soft_wrap=True)
    at_bounds = result.at_bounds()
    if at_bounds:
        stderr.print(f"warning: {source}: the fitted {', '.join(at_bounds)} reached the end of their plausible range: "
                     f"the breast model holds this breast only roughly.", markup=False, soft_wrap=True)
    stats = fit.residuals_mm
    if scan is None:
        volume = {"volume_cc": round(fit.volume_cc, 2), "volume_from": "model"}
    else:
        if not both:
            stderr.print(f"note: {folder}: her volume is measured from this side's scan alone; a plan of both sides "
                         "measures both breasts on one chest wall, inside one mirrored outline, and its figure is the "
                         "one to compare.", markup=False, soft_wrap=True)
        volume = {**measured.as_dict(), "volume_from": "skin" if both else "skin, one side",
                  "model_differs_pct": measured.model_differs_pct(fit.volume_cc)}
    from breastplan.plan.breast_volume import model_differs_much

    if model_differs_much(volume.get("model_differs_pct")):
        stderr.print(f"warning: {source}: the fitted model holds {volume['model_differs_pct']:+.0f} % of the volume "
                     "measured on her skin: the model describes this breast only roughly.", markup=False, soft_wrap=True)
    report({"fit": str(paths[Case.FIT_NPZ]), "mesh": str(paths[Case.FIT_PLY]), "points": len(points),
            **volume, "model_volume_cc": round(fit.volume_cc, 2), "model_volume_cc_mesh": round(fit.volume_cc_mesh, 2),
            "model_volume_cc_below_base": round(fit.volume_cc_below_base, 2),
            "model_volume_cc_primitive": round(fit.volume_cc_primitive, 2),
            "rms_mm": round(stats["rms"], 4), "residuals_mm": {k: round(v, 4) for k, v in stats.items()},
            "normalised_residual": round(fit.normalised_residual, 6), "stopping_rule": STOP_RESIDUAL,
            "stopping_rule_met": fit.stopping_rule_met, "converged": fit.converged, "at_bounds": at_bounds,
            "iterations": {"superquadric": fit.iterations[0], "ffd": fit.iterations[1]},
            "params": {k: round(v, 5) for k, v in result.params().items()}, **carried,
            "seconds": clock.seconds}, as_json, f"fit → {paths[Case.FIT_PLY]}")


def measured_volume(scan: Scan, folder: Path):
    """The breast's `BreastVolume` measured on her skin, and whether both sides were: with the other
    side's nipple when a case of it made from the same torso stands beside this one (a plan's case folder)."""
    from breastplan.case import Case
    from breastplan.options import SIDES
    from breastplan.plan.breast_volume import measure_breasts

    nipples = {scan.side: scan.nipple_camera_mm}
    other = Path(folder).resolve().parent / next(s for s in SIDES if s != scan.side)
    if Path(folder).resolve().name == scan.side and Case.holds(other):
        twin = Case(other).load_scan()
        if twin.side != scan.side and twin.body.same(scan.body):
            nipples[twin.side] = twin.nipple_camera_mm
    measured = measure_breasts(scan.body, nipples)
    return measured.sides[scan.side], len(nipples) == 2


def _breast_points(input: Path) -> tuple[np.ndarray, Scan | None, Path, Path]:
    """(points mm, the case's scan (None for a PLY), the file they came from, the default output
    folder) of a case folder or a PLY. A case's breast sits on its chest wall; a PLY's on z = 0."""
    from breastplan import read_ply
    from breastplan.case import Case
    from breastplan.units import breast_points_problem

    if input.is_dir():
        scan = Case(require_folder(input, "case folder")).load_scan()
        points, source, folder = scan.points, input / Case.SCAN_PLY, input
    elif input.suffix.lower() == ".ply" or not input.exists():
        scan, points, source, folder = None, read_ply(input).points, input, input.parent
    else:
        raise BadInputError(input, "is neither a PLY file nor a case folder from `breastplan ingest`")
    problem = breast_points_problem(points)
    if problem:
        raise BadInputError(source, problem)
    return points, scan, source, folder
