"""The `deform` command: one deformation of a breast PLY, by explicit parameters or by degree."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, List, Optional

import typer

from breastplan import BadInputError
from breastplan.errors import require_folder
from breastplan.clock import Clock
from breastplan.deform.names import DD, DEFAULT_CONDITION, KIND_PARAMS, METHODS, NEEDS_PRIMITIVE

from .app import JSON, command, parse_pairs
from .output import apart, report, usage_error, writable

if TYPE_CHECKING:
    from breastplan import Primitive


@command()
def deform(
    input: Path = typer.Argument(..., help="Breast PLY (points or mesh; mm, breast frame), a fit.npz, or a case "
                                 "folder with a fit. A fit, or a PLY written by synth, fit or deform, carries its "
                                 "primitive."),
    kind: str = typer.Option(..., "--kind", help=f"Deformation: {', '.join(KIND_PARAMS)}."),
    param: List[str] = typer.Option([], "--param", help="NAME=VALUE, model units (docs/model.md §3); "
                                    "repeat or comma-separate; unnamed parameters are 0."),
    degree: Optional[float] = typer.Option(None, "--degree", help=f"Degree of deformation in [1, {DD}] "
                                           "(instead of --param): ptosis, turn or top-shape."),
    condition: Optional[str] = typer.Option(None, "--condition", help="Condition of --degree, e.g. \"b0>b1\" "
                                            f"(defaults: {', '.join(DEFAULT_CONDITION.values())})."),
    method: Optional[str] = typer.Option(None, "--method", help="How --degree finds the parameters: exact (the "
                                         "inverse solver, the default) or learnt (the shipped regression models)."),
    model: Optional[Path] = typer.Option(None, "--model", help="A statistical model (train-statistical's .npz) that "
                                         "deforms by --degree instead: it moves the points by its learnt FFD field; "
                                         "it sets no parameters and takes no --condition."),
    primitive: Optional[str] = typer.Option(None, "--primitive", help="a1=..,a2=..,a3=..,a4=..,a5=..[,eps1=..,eps2=..] "
                                            "in model units (1 mu = 6 mm); needed by top-shape, flatten-side, turn-top "
                                            "when INPUT carries none; overrides the one it carries."),
    out: Path = typer.Option(..., "--out", help="Output PLY, mm, breast frame, same point order."),
    as_json: bool = JSON,
):
    """Apply one deformation to a breast (PLY or fit), by explicit parameters or by degree."""
    clock = Clock()
    if kind not in KIND_PARAMS:
        raise usage_error(f"'{kind}' is not a deformation; choose one of {', '.join(KIND_PARAMS)}", "--kind")
    if degree is not None and param:
        raise usage_error("give either --param or --degree, not both", "--degree")
    import numpy as np

    from breastplan import to_mm, to_model_units, transform_points, write_ply
    from breastplan.case import pose_comment
    from breastplan.units import breast_points_problem, displacement_problem

    given = _parse_primitive(primitive)
    params = parse_pairs(param, f"parameters of {kind}", "--param")
    unknown = sorted(set(params) - set(KIND_PARAMS[kind]))
    if unknown:
        raise usage_error(f"{kind} takes {', '.join(KIND_PARAMS[kind])}, not {', '.join(unknown)}", "--param")
    if model is not None and degree is None:
        raise usage_error("--model deforms by degree: give --degree too", "--model")
    for option, value in (("--condition", condition), ("--method", method)):
        if value is not None and degree is None:
            raise usage_error(f"{option} goes with --degree; --param gives the parameters themselves", option)
        if value is not None and model is not None:
            raise usage_error(f"give either {option} or --model: a statistical model has no condition and no "
                              "method, it moves the points by the FFD field it learnt", option)
    method = method or "exact"
    if method not in METHODS:
        raise usage_error(f"'{method}' is not a method; choose one of {', '.join(METHODS)}", "--method")
    if degree is not None:
        from breastplan.deform.by_degree import pick_condition

        try:
            pick_condition(kind, condition)
        except ValueError as exc:
            raise usage_error(str(exc), "--condition" if kind in DEFAULT_CONDITION else "--kind") from None
    fields = None if model is None else _statistical_model(model, kind)
    geometry, carried, pose = _breast(input)
    problem = breast_points_problem(geometry.points)
    if problem:
        raise BadInputError(input, problem)
    apart(writable(out), input)
    prim = given or carried
    if prim is None and kind in NEEDS_PRIMITIVE:
        raise usage_error(f"{kind} needs the breast primitive, and {input} carries none: "
                          "--primitive a1=..,a2=..,a3=..,a4=..,a5=..", "--primitive")
    local = transform_points(np.linalg.inv(pose), geometry.points)      # the primitive's own frame, mm
    if degree is None:
        from breastplan.deform.global_deformations import apply_kind

        with np.errstate(over="ignore", invalid="ignore"):     # an overflow is reported below, once
            moved = to_mm(apply_kind(to_model_units(local), kind, params, prim))
        extra = {"params": {n: params.get(n, 0.0) for n in KIND_PARAMS[kind]}}
    else:
        from breastplan.deform.by_degree import deform_by_degree
        from breastplan.learn.field_file import by_degree

        if model is not None:                                   # a statistical model works in the breast frame
            method = str(fields.path)
        try:
            if model is None:
                result = deform_by_degree(local, kind, degree, condition=condition, method=method, primitive=prim)
            else:
                result = by_degree(geometry.points, kind, degree, method=method, primitive=prim)
        except ValueError as exc:
            raise usage_error(str(exc), "--degree") from None
        moved, params = result.points_mm, dict(zip(KIND_PARAMS[kind], result.params))
        if model is not None:
            moved = transform_points(np.linalg.inv(pose), moved)
        extra = {"condition": result.condition.name, "method": method, "degree": degree,
                 "degree_reached": round(result.degree_reached, 4)}
        if model is None:                                       # a statistical model has no parameters
            extra.update(t=round(result.t, 6), params={k: round(float(v), 6) for k, v in params.items()})
    shift, problem = displacement_problem(local, moved)      # the pose is rigid: the same in the breast frame
    if problem:
        raise BadInputError(input, f"{kind} with these parameters {problem}")
    after = transform_points(pose, moved)
    carry = [] if prim is None else [prim.comment(), pose_comment(pose)]
    how = " ".join([kind, *(f"{k}={v:g}" for k, v in params.items())])
    if degree is not None:
        how += (f" (degree {degree:g}, " + (f"{result.condition.name}, {method})" if model is None else
                                            f"the FFD field of the statistical model {model.name})"))
    write_ply(out, after, faces=geometry.faces, comments=[f"breastplan deform {how}", *carry])
    report({"output": str(out), "points": len(after), "kind": kind, **extra,
            "primitive": "given" if given else "carried by the input" if carried else None,
            "mean_displacement_mm": float(shift.mean()), "max_displacement_mm": float(shift.max()),
            "seconds": clock.seconds}, as_json, f"{kind} → {out}")


def _statistical_model(path: Path, kind: str):
    """The statistical model file `path` of `--model`, checked to make `kind`; BadInputError naming it
    and saying what it is otherwise (a parametric model, another artefact, another type)."""
    from breastplan import ArtefactError, require_file
    from breastplan.learn.field_file import field_file, is_field_model
    from breastplan.model_file import load_model

    require_file(path, "statistical model file")
    try:
        loaded = load_model(path)
    except ArtefactError as exc:
        raise ArtefactError(path, f"{exc.problem}, and --model takes a statistical model "
                                  "(train-statistical writes those)") from None
    if not is_field_model(loaded):
        what = f"of the condition '{loaded.meta['condition']}' " if loaded.meta.get("condition") else ""
        raise ArtefactError(path, f"is a parametric model {what}(a position on the condition's line, for "
                                  "`plan --method`), not the statistical model --model takes (an FFD field, "
                                  "written by train-statistical)")
    fields = field_file(loaded, path)
    if kind not in fields.kinds:
        raise ArtefactError(path, f"is a statistical model that models {', '.join(fields.kinds)}, not {kind} (--kind)")
    return fields


def _breast(input: Path):
    """(geometry mm breast frame, the primitive it carries or None, the pose it carries or identity) of a
    PLY, a fit.npz or a case folder holding a fit."""
    import numpy as np

    from breastplan import Geometry, Primitive, read_ply
    from breastplan.case import Case, pose_from_comments, sha256
    from breastplan.frames import is_rigid

    if input.is_dir() and not (require_folder(input, "case folder") / Case.FIT_NPZ).exists():
        raise BadInputError(input, f"holds no {Case.FIT_NPZ}: deform takes a case folder once `breastplan fit` "
                                   "has fitted it, a PLY file or a fit.npz")
    if input.is_dir() or input.name == Case.FIT_NPZ:
        case = Case(require_folder(input if input.is_dir() else input.parent, "case folder"))
        fit, scan_ply = case.load_fit(), case.path(Case.SCAN_PLY)
        fitted_to = fit.provenance.inputs.get(Case.SCAN_PLY)
        if fitted_to is not None and scan_ply.is_file() and fitted_to != sha256(scan_ply):
            raise BadInputError(case.path(Case.FIT_NPZ), f"was fitted to another scan than the {Case.SCAN_PLY} beside "
                                                         "it (ingested since): `breastplan fit` the case again")
        return Geometry(fit.vertices, fit.faces), fit.primitive, fit.pose
    if input.suffix.lower() != ".ply" and not _starts_with(input, b"ply"):
        raise BadInputError(input, f"is neither a PLY file nor a {Case.FIT_NPZ} or case folder holding a fit, "
                                   "which deform takes")
    geometry = read_ply(input)
    try:
        carried, pose = Primitive.from_comments(geometry.comments), pose_from_comments(geometry.comments)
    except ValueError as exc:
        raise BadInputError(input, str(exc)) from None
    problem = carried and carried.breast_problem()
    if problem:
        raise BadInputError(input, f"carries a primitive that {problem}")
    if pose is not None and not is_rigid(pose):
        raise BadInputError(input, "carries a pose that is not a rigid transform")
    return geometry, carried, np.eye(4) if pose is None or carried is None else pose


def _starts_with(path: Path, magic: bytes) -> bool:
    """Whether `path` starts with `magic`; True when it is empty, cannot be read or is no regular file (a
    named pipe, which reading would block on): the reader then says why."""
    from breastplan.errors import file_head

    return file_head(path, len(magic)) in (magic, b"", None)


def _parse_primitive(text: Optional[str]) -> Optional[Primitive]:
    from breastplan import PARAM_NAMES, Primitive

    if text is None:
        return None
    values = parse_pairs([text], "primitive", "--primitive")
    missing = [n for n in PARAM_NAMES[:5] if n not in values]
    unknown = sorted(set(values) - set(PARAM_NAMES))
    if missing or unknown:
        raise usage_error(f"the primitive needs a1..a5 (and optionally eps1, eps2); "
                          f"missing {missing}, unknown {unknown}", "--primitive")
    try:
        prim = Primitive(**values)
    except ValueError as exc:
        raise usage_error(str(exc), "--primitive") from None
    problem = prim.breast_problem()
    if problem:
        raise usage_error(f"the primitive {problem}", "--primitive")
    return prim
