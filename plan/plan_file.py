"""plan.json read back: what a case folder's plan says it planned, and the files it names.

`plan.record` writes plan.json; this is its one reader, for what decides whether a case folder can be
reused (`plan`, `batch`): its schema, its input's content hash, its options and its files; and for each
breast's lead figures, which `batch` tabulates (`read_measures`).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from breastplan.case import Case
from breastplan.json_text import from_json

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
    return PlanFile(schema, sha if isinstance(sha, str) else None, options,
                    _files(record) if schema == PLAN_SCHEMA else None)


MEASURE_COLUMNS = ("side", "volume_cc", "uncertainty_cc", "unseen_outer_cc", "footprint_area_cm2", "model_volume_cc",
                   "volume_planned_cc", "volume_left_minus_right_cc", "ptosis_grade", "notch_to_nipple_mm",
                   "nipple_to_midline_mm", "nipple_to_fold_mm", "change_since_earlier_cc", "change_since_earlier_pct",
                   "camera_mm")
"""`read_measures`' columns: her volume on her skin and what goes with it (cc, cm²), the fitted model's, her volume as
planned, her left − right before, her ptosis grade and nipple distances before (mm), at a follow-up her change on the
earlier wall (cc, %), and how far the camera stood from her nipples (mm; None for a scan file)."""


def read_measures(folder: Path) -> list[dict]:
    """One row per breast of the plan in `folder` (MEASURE_COLUMNS, to 0.1; None where the plan has no such figure);
    [] when it holds no plan.json of this breastplan's schema, or one that is not whole."""
    try:
        record = from_json((Path(folder) / Case.PLAN_JSON).read_text())
        if record.get("schema") != PLAN_SCHEMA:
            return []
        m = record["measures"]
        rows = []
        for side, planned in record["sides"].items():
            volume, before, since = planned["volume"], m["before"][side], planned.get("wall_from") or {}
            rows.append({"side": side, **{k: volume.get(k) for k in MEASURE_COLUMNS[1:6]},
                         "volume_planned_cc": m["after"][side].get("volume_cc"),
                         "volume_left_minus_right_cc": (m.get("asymmetry") or {}).get("before", {}).get("volume_cc"),
                         "ptosis_grade": m["ptosis"]["before"][side].get("grade"),
                         **{k: before.get(k) for k in MEASURE_COLUMNS[9:12]},
                         "change_since_earlier_cc": since.get("skin_volume_change_cc"),
                         "change_since_earlier_pct": since.get("skin_volume_change_pct"),
                         "camera_mm": record["input"].get("camera_mm")})
        return [{k: round(v, 1) if isinstance(v, float) else v for k, v in row.items()} for row in rows]
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return []


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
