"""plan.json read back: what a case folder's plan says it planned, and the files it names.

`plan.record` writes plan.json; this is its one reader, for what decides whether a case folder can be
reused (`plan`, `batch`): its schema, its input's content hash, its options and its files.
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
