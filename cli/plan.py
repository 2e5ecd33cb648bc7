"""The `plan` command: the main job, from a patient's scan to report.html (docs/cli.md)."""
from __future__ import annotations

import math
from pathlib import Path
from typing import List, Optional

import typer

from breastplan.clock import Clock
from breastplan.errors import require_file
from breastplan.options import DEFAULT_PLAN, DEGREE_KINDS, OptionError, PlanOptions

from .app import JSON, UNITS_HELP, UP_HELP, command, scan_file_options
from .output import inside, not_one_side_of_a_plan, read_only, real, report, stderr, usage_error, writable

FLAGS = {"changes": "--deform", "sides": "--side", "method": "--method", "units": "--units", "up": "--up",
         "operations": "--left/--right", "symmetrise": "--symmetrise", "operation_models": "--operation-model"}
OPERATION_HELP = ("repeatable, in the order made: augmentation:VOLUME[:PROFILE][:round|anatomical][:subglandular|"
                  "submuscular] or augmentation:WIDTHxPROJECTION[...], lift:notch=MM|fold=MM|other, "
                  "reduction:VOLUME|to=VOLUME[:fold=MM|other|none], lumpectomy:VOLUME:CLOCK:DISTANCE[:DEPTH] (cc, mm; "
                  "the clock as the surgeon faces her). With operations and no --deform, no change by degree is "
                  "planned.")


@command()
def plan(
    input: Optional[Path] = typer.Argument(None, help="A depthai recording (.mcap), a scan file (PLY, OBJ, STL, PCD, "
                                           "XYZ, glTF/GLB) or a case folder; omitted: the bundled sample recording."),
    side: str = typer.Option("both", "--side", help="The breasts to plan: left, right or both."),
    deform: List[str] = typer.Option([], "--deform", help="KIND:DEGREE, repeatable: a change to plan, KIND one of "
                                     f"{', '.join(DEGREE_KINDS)}, DEGREE in 1..8 (decimals allowed). Default: "
                                     + " ".join(f"{k}:{d:g}" for k, d in DEFAULT_PLAN) + "."),
    left: List[str] = typer.Option([], "--left", help="An operation on her left breast, " + OPERATION_HELP),
    right: List[str] = typer.Option([], "--right", help="An operation on her right breast, " + OPERATION_HELP),
    symmetrise: Optional[str] = typer.Option(None, "--symmetrise", help="left or right: propose the operations on "
                                             "that breast that bring it to her other breast's volume and nipple "
                                             "height."),
    plan_file: Optional[Path] = typer.Option(None, "--plan-file", help="A plan file (YAML or JSON) with the keys "
                                             "left, right, deform and symmetrise, each as its option takes it; "
                                             "instead of those options."),
    operation_model: List[Path] = typer.Option([], "--operation-model", help="A clinic's model of one operation "
                                               "(augmentation or reduction), learnt by train-statistical from "
                                               "before/after scans of the clinic's patients: it makes that "
                                               "operation in place of the built-in model. Repeatable, one per "
                                               "operation."),
    method: str = typer.Option("exact", "--method", help="How a degree becomes parameters: exact (the inverse "
                               "solver), learnt (the shipped regressions) or MODEL.npz (a trained model of one "
                               "condition, for its kind)."),
    out: Optional[Path] = typer.Option(None, "--out", help="Case folder to write (default: INPUT if it is a case "
                                       "folder, else ./<input name>-plan)."),
    units: str = typer.Option("auto", "--units", help=UNITS_HELP),
    up: str = typer.Option("auto", "--up", help=UP_HELP),
    wall_from: Optional[Path] = typer.Option(None, "--wall-from", help="An earlier case folder of the same patient "
                                             "(a plan's, or one side's from `ingest`): each breast is measured "
                                             "down to that case's chest wall, and its volume change since then "
                                             "reported (a follow-up scan)."),
    force: bool = typer.Option(False, "--force", help="Replace a case folder that holds another recording's "
                               "case: it is planned afresh and nothing of the old case is kept."),
    patient: Optional[str] = typer.Option(None, "--patient", help="Her name, for the report's and the handout's "
                                          "header (default: anonymous)."),
    patient_id: Optional[str] = typer.Option(None, "--patient-id", help="Her ID in the clinic's records, for the "
                                             "header."),
    surgeon: Optional[str] = typer.Option(None, "--surgeon", help="The surgeon's name, for the header."),
    date: Optional[str] = typer.Option(None, "--date", help="The date the header gives, YYYY-MM-DD (default: "
                                       "today)."),
    as_json: bool = JSON,
):
    """Plan operations and changes on a patient's scan: ingest, fit, each side's operations, each change by degree
    and their combination, measures, an interactive report (report.html) and a handout for her (report.pdf)."""
    clock = Clock()
    deform, operations, symmetrise = _written(plan_file, deform, left, right, symmetrise)
    try:
        options = PlanOptions.parse(deform, side, method, units, up, None if wall_from is None else str(wall_from),
                                    operations, symmetrise, tuple(str(p.absolute()) for p in operation_model))
    except OptionError as exc:
        raise usage_error(str(exc), FLAGS[exc.option]) from None
    who = _patient(patient, patient_id, surgeon, date)
    resolved = check_method(method)
    check_operation_models(options)
    if input is not None and not input.is_dir():
        require_file(input, "recording or scan file")
    scan_file_options(input, units, up)
    if out is None:
        out = input if input is not None and input.is_dir() else Path(f"{(input or Path('sample')).stem}-plan")
    if wall_from is not None:
        read_only(wall_from, out)
    not_one_side_of_a_plan(out, "planned")
    if force and input is not None and inside(real(input), real(out)):
        raise usage_error(f"--force would replace {out}, which holds the input {input}; give --out a new folder",
                          "--out")
    writable(out, folder=True)

    from breastplan.plan.breast_volume import model_differs_much
    from breastplan.plan.changes import short_of
    from breastplan.plan.job import run_plan

    with _progress() as step:
        planned = run_plan(input, out, options, step, resolved, force, who, parallel=True)
    if as_json:
        report(_json(planned, out, clock.seconds), True, "")
    else:
        _print_plan(planned, out / "report.html", clock.seconds)
    for note in planned.camera_notes:
        stderr.print(f"note: {note[0].lower()}{note[1:]} The report says so.", markup=False, soft_wrap=True)
    for s in planned.shown_sides:
        sp = planned.sides[s]
        differs = planned.volumes.sides[s].model_differs_pct(sp.fit.volume_cc)
        if model_differs_much(differs):
            stderr.print(f"note: the {s} breast's fitted model holds {differs:+.0f} % of the volume measured on her "
                         "skin; the report says so.", markup=False, soft_wrap=True)
        if not sp.fit.stopping_rule_met:
            stderr.print(f"note: the {s} breast's fit ends above the stopping rule (normalised residual "
                         f"{sp.fit.normalised_residual:.4f}); the report says so.", markup=False, soft_wrap=True)
    for s in planned.shown_sides:
        for d in (d for st in planned.changes if st.kind is not None for d in st.changes[s].details):
            short = short_of(d, options.method)
            if short:
                stderr.print(f"note: on the {s} breast, {d['kind']} {d['degree']:g} reaches {short}; the report says "
                             "so.", markup=False, soft_wrap=True)


def _written(plan_file: Path | None, deform: list[str], left: list[str], right: list[str], symmetrise: str | None):
    """The changes, the operations ((side, as written), each checked: `written_operations`) and the side to
    symmetrise, from the command line or the plan file (`plan.written_plan`); a usage error naming what is wrong."""
    from breastplan.plan.operation_spec import written_operations
    from breastplan.plan.written_plan import read_written_plan

    if plan_file is not None:
        if deform or left or right or symmetrise:
            raise usage_error("--plan-file is instead of --deform, --left, --right and --symmetrise: give one or the "
                              "other", "--plan-file")
        try:
            written = read_written_plan(plan_file)
        except ValueError as exc:
            raise usage_error(str(exc), "--plan-file") from None
        deform, left, right, symmetrise = list(written.deform), written.left, written.right, written.symmetrise
    try:
        operations = written_operations(left, right)
    except OptionError as exc:
        raise usage_error(str(exc), "--plan-file" if plan_file else f"--{exc.option}") from None
    return deform, operations, symmetrise


NAME_CHARS = 120
"""The longest name, ID or surgeon the header takes."""


def _patient(name: str | None, patient_id: str | None, surgeon: str | None, date: str | None):
    """The plan's `Patient` from the header's options; a usage error for a name that is empty, too long or
    holds a control character, or a date that is not a real YYYY-MM-DD."""
    import datetime
    import re

    from breastplan.plan.result import Patient

    given = {"--patient": name, "--patient-id": patient_id, "--surgeon": surgeon}
    for flag, text in given.items():
        if text is not None and (not text.strip() or len(text) > NAME_CHARS or not text.isprintable()):
            raise usage_error(f"{flag} takes a name of 1 to {NAME_CHARS} printable characters, got {text!r}", flag)
    if date is not None:
        try:
            if not re.fullmatch(r"\d{4}-\d{2}-\d{2}", date):
                raise ValueError
            datetime.date.fromisoformat(date)
        except ValueError:
            raise usage_error(f"--date takes a date as YYYY-MM-DD, got {date!r}", "--date") from None
    return Patient(*(None if t is None else t.strip() for t in given.values()),
                   **({} if date is None else {"date": date}))


def _json(plan, out: Path, seconds: float) -> dict:
    """`plan --json`: where the case and its report are, each side's volume, fit and changes, the measures."""
    from breastplan.plan.record import (follow_up_record, input_record, measures_record, skin_change_record,
                                        volume_record)

    sides = {}
    for s, sp in plan.sides.items():
        volume = volume_record(plan, s)
        sides[s] = {**{k: v for k, v in volume.items() if k != "footprint_input_mm"},
                    "stopping_rule_met": sp.fit.stopping_rule_met,
                    "changes": [st.key for st in plan.changes], "reused": list(sp.reused)}
        if s in plan.operated:
            sides[s]["operations"] = plan.operated[s].as_dict()
        if sp.follow_up is not None:
            sides[s]["wall_from"] = {**follow_up_record(sp),
                                     **skin_change_record(plan.skin_changes.get(s))}
    return {"case": str(out), "report": str(out / "report.html"), "handout": str(out / "report.pdf"),
            "plan": str(out / "plan.json"),
            "input": str(plan.input), **{k: v for k, v in input_record(plan).items() if k.startswith("camera_")},
            "sides": sides, "measures": measures_record(plan), "seconds": seconds}


def _print_plan(plan, report_path: Path, seconds: float) -> None:
    """The plan for a person: what was planned, the measures before and after, where the report is."""
    from rich.table import Table

    from breastplan.plan.measures import measure_label
    from breastplan.plan.operated import said
    from breastplan.plan.report import figure
    from breastplan.plan.result import OPERATED

    from .output import stdout

    m, sides = plan.measures, plan.shown_sides
    planned = [f"{s} {spec.text}" for s, op in plan.operated_shown for spec in op.written]
    planned += [st.key for st in plan.changes if st.key != OPERATED]
    table = Table(title=f"plan: {', '.join(planned) or 'nothing to operate'} — after: {plan.shown.key}",
                  title_justify="left")
    table.add_column("measure")
    for s in sides:
        table.add_column(f"{s} before", justify="right")
        table.add_column(f"{s} after", justify="right")
    if m.asymmetry:
        table.add_column("left − right before", justify="right")
        table.add_column("after", justify="right")
    for name in m.before[sides[0]]:
        row = [measure_label(name)]
        for s in sides:
            row += [figure(m.before[s][name]), figure(m.after[s][name])]
        if m.asymmetry:
            row += [figure(m.asymmetry["before"][name]), figure(m.asymmetry["after"][name])]
        table.add_row(*row)
    stdout.print(table)
    for s in sides:
        sp = plan.sides[s]
        fit, volume = sp.fit, plan.volumes.sides[s]
        stdout.print(f"{s} volume: {volume.volume_cc:.1f} ± {volume.uncertainty_cc:.1f} cc on her skin "
                     f"(footprint {volume.area_cm2:.0f} cm²"
                     + (f", {volume.unseen_pct:.0f} % filled in from her other side" if volume.unseen_pct >= 0.5
                        else "") + ")"
                     + (f"; perhaps {volume.unseen_outer_cc:.0f} cc more beyond its outer edge, unseen"
                        if volume.unseen_outer_cc >= 0.5 else ""))
        grade = m.ptosis["before"][s]
        stdout.print(f"{s} ptosis: grade {grade['grade']} → {m.ptosis['after'][s]['grade']} as planned"
                     + (f" (nipple {abs(grade['nipple_to_fold_mm']):.0f} mm "
                        f"{'above' if grade['nipple_to_fold_mm'] >= 0 else 'below'} the fold, the fold "
                        f"{grade['fold_from']})" if grade["nipple_to_fold_mm"] is not None else ""))
        stdout.print(f"{s} fit: the model's volume {fit.volume_cc:.1f} cc down to the chest wall, "
                     f"rms {fit.residuals_mm['rms']:.2f} mm, normalised residual "
                     f"{fit.normalised_residual:.4f}" + (f"; reused: {', '.join(sp.reused)}" if sp.reused else ""))
        if sp.follow_up is not None:
            f, skin = sp.follow_up, plan.skin_changes.get(s)
            cc, pct = sp.model_change
            stdout.print(f"{s} since {f.case}: the model {cc:+.1f} cc "
                         f"({pct:+.1f} %; then {f.earlier_volume_cc:.1f} cc, measured "
                         f"down to its chest wall, registered at rms {f.registration.rms_mm:.2f} mm)"
                         + (f"; on her skin, on the earlier wall: {skin.on_wall_cc:+.1f} cc" if skin else ""))
    for s, op in plan.operated_shown:
        stdout.print(f"{s} operated: {', '.join(op.texts) or 'nothing proposed'}; her volume "
                     f"{op.volume_before_cc:.1f} → {op.volume_cc:.1f} cc on her skin, her nipple moved "
                     f"{op.nipple_moved_mm:.0f} mm ({op.nipple_move_words})", markup=False, soft_wrap=True)
        for words in said(op, m):
            stdout.print(f"{s}: {words}", markup=False, soft_wrap=True)
    if m.symmetry["before"]:
        sym = m.symmetry
        stdout.print("symmetry: " + ", ".join(f"{k.replace('_pct', '')} {sym['before'][k]:.1f} → {sym['after'][k]:.1f} %"
                                             for k in ("pBRA_pct", "pUNR_pct", "pLBC_pct", "overlap_pct")
                                             if _finite(sym["before"].get(k)) and _finite(sym["after"].get(k)))
                     + ("; a breast's lowest point was hidden and is estimated from her other side"
                        if m.contour_hidden else ""))
    stdout.print(f"report → {report_path}  ({seconds:.1f} s)")
    stdout.print(f"handout → {report_path.with_suffix('.pdf')}")


def _finite(v) -> bool:
    return v is not None and math.isfinite(v)


def check_method(method: str):
    """--method resolved (`plan.changes.Method`): exact, learnt, or a model file (.npz) that plans one of
    the plannable kinds; a usage error otherwise, bad input (exit 3) for a model file that is missing,
    unreadable or inconsistent, said before any work."""
    from breastplan.plan.changes import Method

    if method not in ("exact", "learnt"):
        path = Path(method)
        if path.suffix.lower() != ".npz":
            raise usage_error(f"'{method}' is not a method; choose exact, learnt or a model file (.npz)", "--method")
        require_file(path, "model file")
    resolved = Method.resolve(method)
    if resolved.model is not None and not set(resolved.kinds) & set(DEGREE_KINDS):
        raise usage_error(f"{method} models {', '.join(map(str, resolved.kinds))}, which has no degrees to plan",
                          "--method")
    return resolved


def check_operation_models(options: PlanOptions, planned: bool = True) -> None:
    """--operation-model's files loaded before any work: bad input (exit 3) for a file that is missing or no
    operation's model, or a second model of one operation; with `planned`, a usage error for a model of an
    operation the options do not plan (a batch's patients plan theirs in their own files)."""
    from breastplan.plan.learnt_operation import operation_models
    from breastplan.plan.operation_spec import OperationSpec

    for path in options.operation_models:
        require_file(Path(path), "model file")
    kinds = {OperationSpec.parse(text).kind for _, text in options.operations}
    for kind, model in operation_models(options.operation_models).items():
        if planned and kind not in kinds and options.symmetrise is None:
            raise usage_error(f"{model.path} makes {kind}s, and no {kind} is planned", "--operation-model")


class _progress:
    """A spinner with the current stage on a terminal's stderr; nothing otherwise."""

    def __enter__(self):
        from rich.status import Status

        self.status = Status("plan", console=stderr) if stderr.is_terminal else None
        if self.status:
            self.status.start()
        return self.step

    def step(self, stage: str) -> None:
        if self.status:
            self.status.update(f"plan: {stage}")

    def __exit__(self, *exc):
        if self.status:
            self.status.stop()
