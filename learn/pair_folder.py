"""Pairs folders: before/after breast scans labelled by deformation type and degree (docs/artefacts.md).

A clinic hands the statistical-model trainer (`breastplan train-statistical --pairs DIR`) a folder

    DIR/pairs.csv     header: before,after,type,degree[,split][,condition]
    DIR/<the files and case folders pairs.csv names, by paths relative to DIR>

Each row is one pair: the breast before and after a change of one deformation kind that has
degrees (ptosis, turn, top-shape) at a degree in [1, 8]. `before` and `after` name a PLY of breast
points (mm, breast frame, as `synth` and `deform` write) or a case folder (its ingested breast).
`read_pairs` checks the table and the paths it names; `breast_cloud` reads one breast and checks it;
`training_pairs` checks the pairs a model learns from; `write_pairs` exports deformation datasets
(`learn.datasets`) as such a folder.
"""
from __future__ import annotations

import csv
import hashlib
import io
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from breastplan import BadInputError, read_ply, write_ply
from breastplan.atomic import atomic_open, recover
from breastplan.deform.by_degree import slug
from breastplan.deform.conditions import CONDITIONS, find_condition
from breastplan.deform.names import DD
from breastplan.errors import counted, loops, require_file
from breastplan.options import DEGREE_KINDS
from breastplan.units import breast_points_problem

PAIRS_CSV = "pairs.csv"
COLUMNS = ("before", "after", "type", "degree", "split", "condition")
REQUIRED = COLUMNS[:4]
DEGREES = (1.0, float(DD))
SPLITS = ("train", "test")
MAX_PAIRS = 100_000
"""Pairs pairs.csv may hold: more than any study of before/after scans has (each pair is fitted)."""
MAX_CSV_BYTES = 64 << 20
"""Bytes pairs.csv may hold: MAX_PAIRS rows of long paths."""
MIN_POINTS = 100
"""Points a breast needs at least to be learnt from."""
BEFORE, AFTER = "before", "after"
"""Folders `write_pairs` puts the before and after PLYs in."""


@dataclass(frozen=True)
class PairRow:
    """One row of pairs.csv: absolute, resolved paths of a before and an after breast (PLY file or
    case folder), the kind changed, its degree, the split and the condition's canonical name (or None)."""

    before: Path
    after: Path
    kind: str
    degree: float
    split: str
    condition: str | None


def read_pairs(folder: str | Path) -> list[PairRow]:
    """The pairs of `folder`/pairs.csv, in file order; BadInputError naming pairs.csv (and the line)
    for any defect of the table or of the paths it names. The breasts themselves are read by
    `breast_cloud`."""
    table, root, (line, header), lines = read_table(folder)
    index = columns(table, line, header, COLUMNS, REQUIRED)
    resolved: dict[str, Path] = {}           # a path named on many rows is looked up once
    rows = [_row(table, n, (root, resolved), cells, index, len(header)) for n, cells in lines]
    if not any(r.split == "train" for r in rows):
        raise BadInputError(table, f"holds no training pair: {'all ' * (len(rows) > 1)}{counted(len(rows), 'pair')} "
                                     f"{'is' if len(rows) == 1 else 'are'} in the test split")
    return rows


def read_table(folder: str | Path) -> tuple[Path, Path, tuple[int, list[str]], list[tuple[int, list[str]]]]:
    """`folder`/pairs.csv read and split: (its path, the folder resolved, (line, cells) of its header, (line,
    cells) of each row that is not blank); BadInputError naming the folder or the table for what makes it no
    table of pairs (no such folder, too large, not UTF-8, not CSV, no header, no rows, too many)."""
    folder = Path(folder)
    if loops(folder):
        raise BadInputError(folder, "is a symbolic link loop, not a pairs folder")
    if not folder.exists():
        raise BadInputError(folder, f"no such folder (a pairs folder holds {PAIRS_CSV})")
    if not folder.is_dir():
        raise BadInputError(folder, f"is a file, not a pairs folder (a folder holding {PAIRS_CSV})")
    if not os.access(folder, os.R_OK | os.X_OK):
        raise BadInputError(folder, "cannot be read (Permission denied)")
    try:
        recover(folder)                      # a `synth --pairs` write killed after its commit point
    except OSError as exc:
        raise BadInputError(folder, f"holds an interrupted write that cannot be completed here "
                                    f"({exc.strerror or exc}); write the folder again") from None
    table = require_file(folder / PAIRS_CSV, "CSV file")
    if table.stat().st_size > MAX_CSV_BYTES:
        raise BadInputError(table, f"holds {table.stat().st_size:,} bytes, more than a table of pairs "
                                   f"needs ({MAX_CSV_BYTES:,} at most)")
    try:
        data = table.read_bytes()
    except OSError as exc:
        raise BadInputError(table, f"cannot be read ({exc.strerror or exc})") from None
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise BadInputError(table, f"line {line}: is not UTF-8 text") from None
    reader = csv.reader(io.StringIO(text, newline=""), strict=True)
    lines: list[tuple[int, list[str]]] = []
    try:
        header = next((r for r in reader if any(c.strip() for c in r)), None)
        if header is None:
            raise BadInputError(table, "is empty: it has no header line")
        top = reader.line_num
        for cells in reader:
            if any(c.strip() for c in cells):    # blank lines (and all-empty ones a spreadsheet adds) skipped
                if len(lines) == MAX_PAIRS:
                    raise BadInputError(table, f"holds more than {MAX_PAIRS:,} pairs, more than breastplan "
                                               "trains on")
                lines.append((reader.line_num, cells))
    except csv.Error as exc:
        raise BadInputError(table, f"line {reader.line_num}: is not valid CSV ({exc})") from None
    if not lines:
        raise BadInputError(table, "holds no pairs: only a header")
    return table, folder.resolve(), (top, header), lines


def columns(table: Path, line: int, header: list[str], known: tuple[str, ...],
            required: tuple[str, ...]) -> dict[str, int]:
    """Each `known` column's index in `header` (line `line` of `table`); BadInputError for one named twice or a
    `required` one missing."""
    names = [h.strip().lower() for h in header]
    for name in known:
        if names.count(name) > 1:
            raise BadInputError(table, f"line {line}: the header names column '{name}' twice")
    missing = [name for name in required if name not in names]
    if missing:
        optional = "".join(f"[,{name}]" for name in known if name not in required)
        raise BadInputError(table, f"line {line}: the header lacks column{'s' * (len(missing) > 1)} "
                                   f"{', '.join(missing)} (it needs {','.join(required)}{optional})")
    return {name: names.index(name) for name in known if name in names}


def _row(table: Path, line: int, paths: tuple[Path, dict[str, Path]], cells: list[str], index: dict[str, int],
         width: int) -> PairRow:
    """The pair of one line; `paths`: the folder and the paths resolved so far, by the text naming them."""
    def bad(problem: str) -> BadInputError:
        return BadInputError(table, f"line {line}: {problem}")

    if len(cells) > width and any(c.strip() for c in cells[width:]):
        raise bad(f"has {len(cells)} fields, more than the header's {width}")
    value = {name: (cells[i].strip() if i < len(cells) else "") for name, i in index.items()}
    kind = value["type"].lower().replace("_", "-")
    if kind not in DEGREE_KINDS:
        raise bad(f"type '{value['type']}' is not a deformation kind with degrees; choose {', '.join(DEGREE_KINDS)}"
                  if value["type"] else f"has no type; choose {', '.join(DEGREE_KINDS)}")
    try:
        degree = float(value["degree"])
    except ValueError:
        raise bad(f"degree '{value['degree']}' is not a number" if value["degree"] else "has no degree") from None
    if not math.isfinite(degree):
        raise bad(f"degree '{value['degree']}' is not a finite number")
    if not DEGREES[0] <= degree <= DEGREES[1]:
        raise bad(f"degree {degree:g} lies outside [{DEGREES[0]:g}, {DEGREES[1]:g}]")
    split = value.get("split", "").lower() or "train"
    if split not in SPLITS:
        raise bad(f"split '{value['split']}' is neither train nor test (empty means train)")
    condition = value.get("condition") or None
    if condition is not None:
        try:
            cond = find_condition(condition, kind)
        except ValueError:
            raise bad(f"condition '{condition}' is not a known condition; choose one of: "
                      f"{', '.join(c.name for c in CONDITIONS.values() if c.kind == kind)}") from None
        if cond.kind != kind:
            raise bad(f"condition '{cond.name}' changes {cond.kind}, not the row's type {kind}")
        condition = cond.name
    root, resolved = paths
    for col in (BEFORE, AFTER):
        if value[col] not in resolved:
            resolved[value[col]] = member(bad, root, value[col], col)
    before, after = resolved[value[BEFORE]], resolved[value[AFTER]]
    return PairRow(before=before, after=after, kind=kind, degree=degree, split=split, condition=condition)


def member(bad: Callable[[str], BadInputError], root: Path, text: str, column: str, plans: bool = False) -> Path:
    """The resolved path `text` names relative to the folder `root`, which must lie inside it and exist: a file
    or a case folder (`plans`: a folder of a plan's cases, left/ and right/, or one side's case only)."""
    if not text:
        raise bad(f"has no {column} path")
    try:
        if loops(root / text):
            raise bad(f"{column} path '{text}' is a symbolic link loop")
        path = (root / text).resolve()        # .., absolute paths and symbolic links all followed
        if root not in path.parents:
            raise bad(f"{column} path '{text}' lies outside the pairs folder")
        if not path.exists():
            raise bad(f"{column} path '{text}' does not exist")
    except (OSError, ValueError) as exc:      # a name too long, a NUL byte
        raise bad(f"{column} path '{text}' cannot be a file name here ({getattr(exc, 'strerror', None) or exc})") \
            from None
    from breastplan.case import Case

    if plans and not (path.is_dir() and (Case.holds(path) or any(Case.holds(path / s) for s in ("left", "right")))):
        raise bad(f"{column} path '{text}' is no case folder of `breastplan plan` (it holds no left/ or right/ "
                  f"case, nor {Case.SCAN_NPZ})")
    if path.is_dir() and not plans and not Case.holds(path):
        raise bad(f"{column} path '{text}' is a folder but not a case folder (it holds no "
                  f"{Case.SCAN_NPZ} from `breastplan ingest`)")
    return path


def breast_cloud(path: str | Path) -> np.ndarray:
    """The (N, 3) float64 points, mm, breast frame, of a breast PLY or of a case folder's ingested breast;
    BadInputError (ArtefactError for a defective file) naming the file if it cannot be a breast: not
    a PLY or case, unreadable or corrupt, NaN or infinite coordinates, fewer than MIN_POINTS points,
    or an extent no breast in millimetres has (in metres, say). Nothing is cached."""
    path = Path(path)
    if path.is_dir():
        from breastplan.case import Case

        if not Case.holds(path):
            raise BadInputError(path, f"is a folder but not a case folder (it holds no {Case.SCAN_NPZ} from "
                                      f"`breastplan ingest`)")
        points = Case(path).load_scan().points
    else:
        points = read_ply(path).points          # ArtefactError naming the file for a missing or bad PLY
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise BadInputError(path, f"holds points of shape {points.shape}, not (N, 3)")
    finite = np.isfinite(points).all(axis=1)
    if not finite.all():
        raise BadInputError(path, f"has {counted(int((~finite).sum()), 'point')} with NaN or infinite coordinates")
    if len(points) < MIN_POINTS:
        raise BadInputError(path, f"has {counted(len(points), 'point')}, fewer than the {MIN_POINTS} a breast needs")
    problem = breast_points_problem(points)
    if problem is not None:
        raise BadInputError(path, problem)
    return points


def training_pairs(rows: list[PairRow], corresponding: bool = False) -> tuple[list[PairRow], dict[Path, np.ndarray]]:
    """The training rows of `rows` and their before breasts' points (by path), every pair read and
    checked, so that bad input is refused before any fit. BadInputError naming no file for a type whose
    training pairs are all of one degree; naming the after scan of a pair whose point count differs from
    its before's (when `corresponding`), that holds its before breast, or that is one change given two degrees."""
    train = [r for r in rows if r.split != "test"]
    for kind in {r.kind for r in train}:
        degrees = {r.degree for r in train if r.kind == kind}
        if len(degrees) < 2:
            raise BadInputError(None, f"holds training pairs of {kind} at one degree only ({min(degrees):g}): a model "
                                      "of degrees learns from pairs at two degrees at least")
    clouds: dict[Path, np.ndarray] = {}
    for r in train:
        if r.before not in clouds:
            clouds[r.before] = breast_cloud(r.before)
    changes: dict[tuple, PairRow] = {}             # the rows checked so far, by the change they show
    for r in train:
        cloud, before = breast_cloud(r.after), clouds[r.before]
        if corresponding and cloud.shape != before.shape:
            raise BadInputError(r.after, f"holds {len(cloud):,} points where its before scan holds "
                                         f"{len(before):,}; --corresponding pairs correspond point for point")
        if cloud.shape == before.shape and np.array_equal(cloud, before):
            raise BadInputError(r.after, f"holds the very breast of its before scan {r.before.name}: a pair of "
                                         f"{r.kind} at degree {r.degree:g} shows a change")
        same = changes.setdefault((r.before, r.kind, cloud.shape, hashlib.sha256(cloud.tobytes()).digest()), r)
        if same.degree != r.degree:
            raise BadInputError(r.after, f"holds the same breast as {same.after.name}, both after {r.before.name} "
                                         f"by {r.kind}: one change cannot be of degree {same.degree:g} and "
                                         f"{r.degree:g}")
    return train, clouds


def write_pairs(folder: str | Path, dataset, stage: Callable[[Path], Path] = Path,
                progress: Callable[[], object] | None = None) -> Path:
    """Export deformation datasets (one `Dataset` or several) as a pairs folder; the path of pairs.csv.

    Writes `before/<breast>.ply` once per database breast, `after/<condition slug>/<breast>-d<row+1>.ply`
    per example (the breast deformed by the row, `Dataset.deformed_points`), and pairs.csv with one row
    per example: its type (the condition's kind), discrete degree, the breast's split and the condition.
    Each file is written to `stage(path)` (an `atomic_set`'s, to write them with others all or nothing;
    pairs.csv is staged last) and `progress()` is called after each PLY. ValueError for datasets of
    another number of degrees than DD, two of one condition, or two giving one breast name different points.
    """
    folder = Path(folder)
    datasets = _datasets(dataset)
    slugs = [slug(ds.condition) for ds in datasets]
    if len(set(slugs)) < len(slugs):
        raise ValueError("two datasets of one condition would write the same after files")
    if any(ds.dd != DD for ds in datasets):
        raise ValueError(f"a pairs folder holds degrees on the scale of {DD} (datasets of dd = {DD}), "
                         f"not {sorted({ds.dd for ds in datasets if ds.dd != DD})}")
    written: dict[str, np.ndarray] = {}       # breast name → its points, written once
    lines = [list(COLUMNS)]
    for ds, name in zip(datasets, slugs):
        db = ds.database
        for i in np.unique(ds.breast):
            breast = str(db.names[i])
            if breast in written:
                if not np.array_equal(written[breast], db.points[i]):
                    raise ValueError(f"two datasets hold different breasts named {breast}")
                continue
            if Path(breast).name != breast or breast.startswith("."):
                raise ValueError(f"breast name {breast!r} cannot be a file name")
            written[breast] = db.points[i]
            write_ply(stage(folder / BEFORE / f"{breast}.ply"), db.points[i], comments=[
                f"breastplan pairs: before, database {db.name} breast {breast} (mm, breast frame)",
                db.primitive(i).comment()])
            if progress:
                progress()
        params = ", ".join(ds.condition.param_names)
        for k in range(len(ds)):
            i, row, degree = int(ds.breast[k]), int(ds.row[k]), int(ds.degree[k])
            breast = str(db.names[i])
            after = Path(AFTER) / name / f"{breast}-d{row + 1}.ply"
            values = " ".join(f"{p}={v:.17g}" for p, v in zip(ds.condition.param_names, ds.params[k]))
            write_ply(stage(folder / after), ds.deformed_points(k), comments=[
                f"breastplan pairs: after, database {db.name} breast {breast} deformed by {ds.condition.name} "
                f"row {row + 1} of {ds.dd} ({params} replaced by {values}, model units), degree {degree} "
                f"(mm, breast frame)",
                db.primitive(i).comment()])
            lines.append([f"{BEFORE}/{breast}.ply", after.as_posix(), ds.condition.kind, str(degree),
                          str(db.split[i]), ds.condition.name])
            if progress:
                progress()
    text = io.StringIO()
    csv.writer(text, lineterminator="\n").writerows(lines)
    path = folder / PAIRS_CSV
    with atomic_open(stage(path)) as fh:
        fh.write(text.getvalue().encode())
    return path


def _datasets(dataset) -> list:
    """One Dataset or an iterable of them, as a list."""
    return [dataset] if hasattr(dataset, "condition") else list(dataset)


def count_files(datasets) -> int:
    """PLYs `write_pairs` writes for `datasets`: one per breast, one per example (for a progress bar)."""
    datasets = _datasets(datasets)
    names = {str(ds.database.names[i]) for ds in datasets for i in np.unique(ds.breast)}
    return len(names) + sum(len(ds) for ds in datasets)
