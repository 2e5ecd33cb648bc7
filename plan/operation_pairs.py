"""Pairs folders of one operation: her scans before and after it, from which a clinic's own model of that operation
is learnt (`breastplan train-statistical --pairs DIR`; `plan.learnt_operation`).

    DIR/pairs.csv     header: before,after,operation,side[,split]
    DIR/<the case folders pairs.csv names, by paths relative to DIR>

Each row is one woman's operation: `before` and `after` name the case folders `breastplan plan` (or `batch`) wrote
of her scans before and after it; `operation` is the operation as a surgeon writes it (`augmentation:300:moderate`,
`reduction:250`; one kind of operation in a folder); `side` the breast it was made on (left, right or both); `split`
train (the default) or test. `read_operation_pairs` checks the table and the paths it names; `learnt_pairs`
measures each woman's breasts on her skin before and after.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from breastplan import BadInputError
from breastplan.case import Case
from breastplan.learn.pair_folder import SPLITS, columns, member, read_table
from breastplan.options import OptionError

from .compute import measure_scans
from .learnt_operation import LEARNT, Pair
from .operation_spec import OperationSpec

COLUMNS = ("before", "after", "operation", "side", "split")
REQUIRED = COLUMNS[:4]
SIDES = {"left": ("left",), "right": ("right",), "both": ("left", "right")}


@dataclass(frozen=True)
class OperationRow:
    """One row of an operation's pairs.csv: the case folders before and after (absolute, resolved), the operation
    as written, the breasts it was made on, and the split."""

    before: Path
    after: Path
    operation: str
    sides: tuple[str, ...]
    split: str


def is_operation_table(folder: str | Path) -> bool:
    """Whether `folder`/pairs.csv is an operation's (its header names an `operation` column); False for any other
    or none (`read_operation_pairs` or `pair_folder.read_pairs` then says what is wrong)."""
    try:
        _, _, (_, header), _ = read_table(folder)
    except BadInputError:
        return False
    return "operation" in [h.strip().lower() for h in header]


def read_operation_pairs(folder: str | Path) -> list[OperationRow]:
    """The rows of `folder`/pairs.csv, in file order; BadInputError naming pairs.csv (and the line) for any defect
    of the table or the case folders it names, and for pairs of more than one kind of operation or of one the
    models do not learn."""
    table, root, (line, header), lines = read_table(folder)
    index = columns(table, line, header, COLUMNS, REQUIRED)
    rows, kinds = [], set()
    for n, cells in lines:
        def bad(problem: str, n=n) -> BadInputError:
            return BadInputError(table, f"line {n}: {problem}")

        value = {name: (cells[i].strip() if i < len(cells) else "") for name, i in index.items()}
        try:
            spec = OperationSpec.parse(value["operation"])
        except OptionError as exc:
            raise bad(str(exc)) from None
        if spec.kind not in LEARNT:
            raise bad(f"a model learns {' or '.join(LEARNT)}, not {spec.kind}")
        kinds.add(spec.kind)
        if len(kinds) > 1:
            raise bad(f"is a {spec.kind} where the rows above are {(kinds - {spec.kind}).pop()}s: a model learns one "
                      "operation")
        side = value["side"].lower()
        if side not in SIDES:
            raise bad(f"side '{value['side']}' is none of left, right or both")
        split = value.get("split", "").lower() or "train"
        if split not in SPLITS:
            raise bad(f"split '{value['split']}' is neither train nor test (empty means train)")
        paths = [member(bad, root, value[col], col, plans=True) for col in ("before", "after")]
        if paths[0] == paths[1]:
            raise bad("names one case folder before and after: a pair shows her before and after the operation")
        rows.append(OperationRow(*paths, spec.text, SIDES[side], split))
    if not any(r.split == "train" for r in rows):
        raise BadInputError(table, "holds no training pair: every row is in the test split")
    return rows


def learnt_pairs(rows: list[OperationRow], advance=lambda: None) -> list:
    """The training rows' pairs (`learnt_operation.Pair`, one per breast operated), each woman measured on her
    skin before and after (each case folder once); BadInputError naming a case folder that does not hold the
    breast its row names."""
    measured = {}

    def of(folder: Path, sides: tuple[str, ...]):
        if folder not in measured:
            scans = {side: case.load_scan() for side, case in Case.of_sides(folder).items()}
            measured[folder] = (measure_scans(scans, folder), {s: scan.nipple_camera_mm for s, scan in scans.items()})
            advance()
        volumes, nipples = measured[folder]
        missing = [s for s in sides if s not in volumes.sides]
        if missing:
            raise BadInputError(folder, f"holds no case of her {' and '.join(missing)} breast, which its pair names")
        return volumes, nipples

    pairs = []
    for r in (r for r in rows if r.split == "train"):
        (before, nb), (after, na) = of(r.before, r.sides), of(r.after, r.sides)
        pairs += [Pair(before, after, nb[s], na[s], s, OperationSpec.parse(r.operation), str(r.before))
                  for s in r.sides]
    return pairs
