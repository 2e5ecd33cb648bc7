"""A batch's manifest: one row per file of the input folder, as CSV and JSON, and beside it the measures of
every breast planned (`measures.csv`), rewritten all or nothing after every case (cases that finished while
they were being written: together) so that a killed batch leaves true ones.

Statuses: `done` (planned by this run), `reused` (a whole plan of the same input content and options was
already there), `failed` (the error says why), `skipped` (not planned: the error says why), `pending`
(not finished when the manifest was written).
"""
from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

from breastplan.atomic import atomic_set
from breastplan.json_text import to_json, utf8
from breastplan.plan.plan_file import MEASURE_COLUMNS, read_measures

MANIFEST_SCHEMA = "breastplan.batch/1"
CSV_NAME, JSON_NAME, MEASURES_NAME = "manifest.csv", "manifest.json", "measures.csv"
STATUSES = ("done", "reused", "failed", "skipped", "pending")
SUCCEEDED = ("done", "reused")


@dataclass
class Row:
    """One input: its name relative to the input folder, its case relative to the output folder, status,
    seconds spent planning it (0 when not planned), the error sentence and the input's SHA-256."""

    input: str
    case: str
    status: str = "pending"
    seconds: float = 0.0
    error: str = ""
    sha256: str = ""


class Manifest:
    """The rows of a batch (in input order) and what the batch was; `write()` puts both files in `out`."""

    def __init__(self, out: Path, about: dict, rows: list[Row]):
        self.out, self.about, self.rows = Path(out), about, rows
        self._measures: dict[str, list[dict]] = {}          # case → its breasts' rows, read once when it succeeds

    def summary(self) -> dict[str, int]:
        counts = {s: 0 for s in STATUSES}
        for row in self.rows:
            counts[row.status] += 1
        return {"inputs": len(self.rows), **counts}

    def succeeded(self) -> bool:
        return any(r.status in SUCCEEDED for r in self.rows)

    def as_dict(self) -> dict:
        return {"schema": MANIFEST_SCHEMA, **self.about, "summary": self.summary(),
                "cases": [dict(vars(r)) for r in self.rows]}    # plain values: `asdict`'s deep copy is slow

    def measures(self) -> list[dict]:
        """Each breast of every case planned or reused, in input order: the input, its case and
        `plan.plan_file.MEASURE_COLUMNS`."""
        for r in self.rows:
            if r.status in SUCCEEDED and r.case not in self._measures:
                self._measures[r.case] = read_measures(self.out / r.case)
        return [{"input": r.input, "case": r.case, **m} for r in self.rows if r.status in SUCCEEDED
                for m in self._measures[r.case]]

    def write(self) -> None:
        doc = self.as_dict()
        with atomic_set() as stage:
            Path(stage(self.out / CSV_NAME)).write_bytes(_csv(list(Row.__dataclass_fields__), doc["cases"]))
            Path(stage(self.out / JSON_NAME)).write_text(to_json(doc, indent=1), encoding="utf-8")
            Path(stage(self.out / MEASURES_NAME)).write_bytes(_csv(["input", "case", *MEASURE_COLUMNS],
                                                                   self.measures()))


def _csv(columns: list[str], rows: list[dict]) -> bytes:
    """UTF-8 CSV of `rows` under a header of `columns`; None is an empty cell."""
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return utf8(text.getvalue())
