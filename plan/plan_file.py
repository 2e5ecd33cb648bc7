"""plan.json read back: what a case folder's plan says it planned, and the files it names.

`plan.record` writes plan.json; this is its one reader, for what decides whether a case folder can be
reused (`plan`, `batch`): its schema, its input's content hash, its options, the code that planned it and its
files; and for each breast's lead figures, which `batch` tabulates (`read_measures`).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from breastplan.case import Case
from breastplan.json_text import from_json
from breastplan.options import PlanOptions

PLAN_SCHEMA = "breastplan.plan/1"


@dataclass(frozen=True)
class PlanFile:
    """A case folder's plan.json: its schema, its input's SHA-256 (None: a case folder's plan, or none
    recorded), its options (`PlanOptions.as_dict`; {} if not recorded) and every file it names, relative
    to the folder (None when the record is not whole: of another schema, or damaged)."""

    schema: str
    input_sha256: str | None
    options: dict
    files: tuple[str, ...] | None
    patient_id: str | None = None      # her ID in the clinic's records, when the plan was given one
    code: str | None = None            # the digest of the code that planned it (`code_digest`); None: not recorded

    @property
    def current(self) -> bool:
        """Whether this breastplan writes plans of its schema."""
        return self.schema == PLAN_SCHEMA


def read_plan_file(folder: Path) -> PlanFile | None:
    """The plan.json of `folder`; None when it has none. ValueError when it is not a JSON object."""
    path = Path(folder) / Case.PLAN_JSON
    try:
        text = path.read_text()
    except FileNotFoundError:
        return None
    record = from_json(text)
    if not isinstance(record, dict):
        raise ValueError(f"{path} is not a JSON object")
    schema, given = str(record.get("schema", "")), record.get("input")
    sha = given.get("sha256") if isinstance(given, dict) else None
    options = record.get("options") if isinstance(record.get("options"), dict) else {}
    patient_id, code = _at(record, "patient", "patient_id"), record.get("code")
    return PlanFile(schema, sha if isinstance(sha, str) else None, options,
                    _files(record) if schema == PLAN_SCHEMA else None,
                    patient_id if isinstance(patient_id, str) else None, code if isinstance(code, str) else None)


MEASURE_COLUMNS = ("side", "planned", "volume_cc", "uncertainty_cc", "unseen_outer_cc", "footprint_area_cm2",
                   "unseen_pct", "model_volume_cc", "model_differs_pct", "volume_planned_cc",
                   "volume_left_minus_right_cc", "ptosis_grade", "notch_to_nipple_mm", "nipple_to_midline_mm",
                   "nipple_to_fold_mm", "change_since_earlier_cc", "change_since_earlier_pct", "camera_mm")
"""`read_measures`' columns: what was planned (operations as written, then changes by degree), her volume on her skin
and what goes with it (cc, cm², %), the fitted model's and how far it lies from hers, her volume as planned, her
left − right before, her ptosis grade and nipple distances before (mm), at a follow-up her change on the earlier wall
(cc, %), and how far the camera stood from her nipples (mm; None for a scan file)."""
_VOLUME_COLUMNS = ("volume_cc", "uncertainty_cc", "unseen_outer_cc", "footprint_area_cm2", "unseen_pct",
                   "model_volume_cc", "model_differs_pct")
_BEFORE_COLUMNS = ("notch_to_nipple_mm", "nipple_to_midline_mm", "nipple_to_fold_mm")


def read_measures(folder: Path) -> list[dict]:
    """One row per breast of the plan in `folder` (MEASURE_COLUMNS, as plan.json gives them; None where it has no
    such figure, as a plan of an earlier version may not); [] when it holds no plan.json of this schema."""
    try:
        record = from_json((Path(folder) / Case.PLAN_JSON).read_text())
    except (OSError, ValueError):
        return []
    if not isinstance(record, dict) or record.get("schema") != PLAN_SCHEMA or not isinstance(record.get("sides"), dict):
        return []
    rows = []
    for side, planned in record["sides"].items():
        volume, since = _at(planned, "volume") or {}, _at(planned, "wall_from") or {}
        before = _at(record, "measures", "before", side) or {}
        rows.append({"side": side, "planned": _planned(record.get("options")),
                     **{k: _at(volume, k) for k in _VOLUME_COLUMNS},
                     "volume_planned_cc": _at(record, "measures", "after", side, "volume_cc"),
                     "volume_left_minus_right_cc": _at(record, "measures", "asymmetry", "before", "volume_cc"),
                     "ptosis_grade": _at(record, "measures", "ptosis", "before", side, "grade"),
                     **{k: _at(before, k) for k in _BEFORE_COLUMNS},
                     "change_since_earlier_cc": _at(since, "skin_volume_change_cc"),
                     "change_since_earlier_pct": _at(since, "skin_volume_change_pct"),
                     "camera_mm": _at(record, "input", "camera_mm")})
    return [{k: v + 0.0 if isinstance(v, float) else v for k, v in row.items()} for row in rows]   # no −0.0


def _at(record, *keys):
    """record[k0][k1]…, or None where a key or a mapping is missing."""
    for key in keys:
        if not isinstance(record, dict):
            return None
        record = record.get(key)
    return record


def _planned(options) -> str | None:
    """What a plan's recorded options planned, in a line (`PlanOptions.written`); None where they are not whole."""
    try:
        return PlanOptions.from_dict(options).written
    except (KeyError, TypeError, ValueError, AttributeError):
        return None


def _files(record: dict) -> tuple[str, ...] | None:
    """Every file a plan record names (its report, summary and torsos; each side's scan, fit and
    changes); None when it does not name them as a whole plan does."""
    try:
        named = record["files"]
        files = [named["report"], named["summary"], *named["torso"].values()]
        files += [named["handout"]] if "handout" in named else []
        for side, planned in record["sides"].items():
            files += [f"{side}/{Case.SCAN_NPZ}", f"{side}/{Case.FIT_NPZ}"]
            files += [f for change in planned["changes"] for f in change["files"].values()]
    except (KeyError, TypeError, AttributeError):
        return None
    return tuple(files) if all(isinstance(f, str) for f in files) else None
