"""The `breastplan` command (docs/cli.md)."""
from __future__ import annotations

import sys
from pathlib import Path
from typing import List, Optional

import numpy as np
import typer

from breastplan import PARAM_NAMES, BadInputError, Primitive, read_ply, to_mm, to_model_units, write_ply
from breastplan.deform.by_degree import DD, DEFAULT_CONDITION, METHODS, deform_by_degree
from breastplan.deform.conditions import CONDITIONS, find_condition
from breastplan.deform.global_deformations import KIND_PARAMS, NEEDS_PRIMITIVE, apply_kind
from breastplan.learn.databases import Database, build_database, grid_for
from breastplan.learn.datasets import build_dataset

from . import fit_command, learn_commands, scan_commands  # noqa: F401  (register fit, evaluate, train, scan-synth, ingest)
from .app import JSON, app, parse_pairs
from .output import Timer, progress, report, stderr, usage_error


@app.command()
def synth(
    db: str = typer.Option(..., "--db", help="Database to generate: V (65 breasts) or S (60)."),
    out: Path = typer.Option(..., "--out", help="Folder for database.npz (and the PLYs)."),
    seed: int = typer.Option(0, "--seed", help="Random seed; the database is a pure function of it."),
    points: int = typer.Option(10_000, "--points", help="Points per breast (a square number)."),
    ply: bool = typer.Option(False, "--ply", help="Also write one PLY per breast (mm, breast frame)."),
    as_json: bool = JSON,
):
    """Write synthetic database V or S (docs/model.md §4) as DIR/database.npz."""
    timer = Timer()
    if db not in ("V", "S"):
        raise usage_error(f"'{db}' is not a database; choose V or S", "--db")
    try:
        grid_for(points)
    except ValueError as exc:
        raise usage_error(str(exc), "--points") from None
    database = build_database(db, seed=seed, n_points=points)
    path = database.save(out / "database.npz")
    if ply:
        with progress(f"writing {len(database)} PLYs", len(database)) as advance:
            database.write_plys(out, advance)
    train = database.split == "train"
    report({"database": str(path), "breasts": len(database), "train": int(train.sum()),
            "test": int((~train).sum()), "points_per_breast": int(database.points.shape[1]),
            "volume_mean_cc": float(database.volume_cc.mean()),
            "volume_sd_cc": float(database.volume_cc.std(ddof=1)),
            "ply_folder": str(out) if ply else None, "seconds": timer.seconds},
           as_json, f"database {db}")


@app.command()
def deform(
    input: Path = typer.Argument(..., help="Breast PLY (points or mesh), mm, breast frame."),
    kind: str = typer.Option(..., "--kind", help=f"Deformation: {', '.join(KIND_PARAMS)}."),
    param: List[str] = typer.Option([], "--param", help="NAME=VALUE, model units (docs/model.md §3); "
                                    "repeat or comma-separate; unnamed parameters are 0."),
    degree: Optional[float] = typer.Option(None, "--degree", help=f"Degree of deformation in [1, {DD}] "
                                           "(instead of --param): ptosis, turn or top-shape."),
    condition: Optional[str] = typer.Option(None, "--condition", help="Condition of --degree, e.g. \"b0>b1\" "
                                            f"(defaults: {', '.join(DEFAULT_CONDITION.values())})."),
    method: str = typer.Option("exact", "--method", help="How --degree finds the parameters: exact (the inverse "
                               "solver) or learnt (the shipped regression models)."),
    primitive: Optional[str] = typer.Option(None, "--primitive", help="a1=..,a2=..,a3=..,a4=..,a5=..[,eps1=..,eps2=..] "
                                            "in model units (1 mu = 6 mm); needed by top-shape, flatten-side, turn-top."),
    out: Path = typer.Option(..., "--out", help="Output PLY, mm, breast frame, same point order."),
    as_json: bool = JSON,
):
    """Apply one deformation to a breast PLY, by explicit parameters or by degree."""
    timer = Timer()
    if kind not in KIND_PARAMS:
        raise usage_error(f"'{kind}' is not a deformation; choose one of {', '.join(KIND_PARAMS)}", "--kind")
    if degree is not None and param:
        raise usage_error("give either --param or --degree, not both", "--degree")
    prim = _parse_primitive(primitive, kind)
    params = parse_pairs(param, f"parameters of {kind}", "--param")
    unknown = sorted(set(params) - set(KIND_PARAMS[kind]))
    if unknown:
        raise usage_error(f"{kind} takes {', '.join(KIND_PARAMS[kind])}, not {', '.join(unknown)}", "--param")
    if degree is not None and method not in METHODS:
        raise usage_error(f"'{method}' is not a method; choose one of {', '.join(METHODS)}", "--method")
    geometry = read_ply(input)
    if degree is None:
        after = to_mm(apply_kind(to_model_units(geometry.points), kind, params, prim))
        extra = {"params": {n: params.get(n, 0.0) for n in KIND_PARAMS[kind]}}
    else:
        try:
            result = deform_by_degree(geometry.points, kind, degree, condition=condition, method=method, primitive=prim)
        except ValueError as exc:
            raise usage_error(str(exc), "--degree") from None
        after, params = result.points_mm, dict(zip(KIND_PARAMS[kind], result.params))
        extra = {"condition": result.condition.name, "method": method, "degree": degree,
                 "degree_reached": round(result.degree_reached, 4), "t": round(result.t, 6),
                 "params": {k: round(float(v), 6) for k, v in params.items()}}
    if not np.isfinite(after).all():
        raise BadInputError(input, f"{kind} with these parameters sends points to infinity")
    write_ply(out, after, faces=geometry.faces,
              comments=[f"breastplan deform {kind} " + " ".join(f"{k}={v:g}" for k, v in params.items())])
    moved = np.linalg.norm(after - geometry.points, axis=1)
    report({"output": str(out), "points": len(after), "kind": kind, **extra,
            "mean_displacement_mm": float(moved.mean()), "max_displacement_mm": float(moved.max()),
            "seconds": timer.seconds}, as_json, f"{kind} → {out}")


def _parse_primitive(text: Optional[str], kind: str) -> Optional[Primitive]:
    if text is None:
        if kind in NEEDS_PRIMITIVE:
            raise usage_error(f"{kind} needs the breast primitive: --primitive a1=..,a2=..,a3=..,a4=..,a5=..",
                              "--primitive")
        return None
    values = parse_pairs([text], "primitive", "--primitive")
    missing = [n for n in PARAM_NAMES[:5] if n not in values]
    unknown = sorted(set(values) - set(PARAM_NAMES))
    if missing or unknown:
        raise usage_error(f"the primitive needs a1..a5 (and optionally eps1, eps2); "
                          f"missing {missing}, unknown {unknown}", "--primitive")
    try:
        return Primitive(**values)
    except ValueError as exc:
        raise usage_error(str(exc), "--primitive") from None


@app.command()
def dataset(
    db: Path = typer.Option(..., "--db", help="database.npz written by `breastplan synth`."),
    condition: str = typer.Option(..., "--condition", help=f"One of: {'; '.join(CONDITIONS)}."),
    dd: int = typer.Option(8, "--dd", help="Number of degrees of deformation (4 or 8 in the thesis)."),
    out: Path = typer.Option(..., "--out", help="Output dataset NPZ."),
    as_json: bool = JSON,
):
    """Deform every breast of a database by every row of a condition; extents and degrees."""
    timer = Timer()
    try:
        cond = find_condition(condition)
    except ValueError as exc:
        raise usage_error(str(exc), "--condition") from None
    if dd < 2:
        raise usage_error(f"--dd must be at least 2, got {dd}", "--dd")
    database = Database.load(db)
    with progress(f"{cond.name} × {dd} degrees", len(database)) as advance:
        data = build_dataset(database, cond, dd, advance)
    path = data.save(out)
    report({"dataset": str(path), "condition": cond.name, "dd": dd, "examples": len(data),
            "reference_extents": data.reference_extents.round(5),
            "examples_per_degree": np.bincount(data.degree, minlength=dd + 1)[1:],
            "seconds": timer.seconds}, as_json, f"dataset {cond.name}")


def main() -> None:
    """Entry point: run the app, mapping deliberate errors to exit codes (docs/design.md)."""
    try:
        app()
    except BadInputError as exc:
        stderr.print(f"error: {exc}", markup=False, soft_wrap=True)
        sys.exit(3)
    except OSError as exc:  # an output we cannot write, a disk that is full
        where = f"{exc.filename}: " if exc.filename else ""
        stderr.print(f"error: {where}{exc.strerror or exc}.", markup=False, soft_wrap=True)
        sys.exit(3)


if __name__ == "__main__":
    main()
