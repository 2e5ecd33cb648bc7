"""A plan file: what a surgeon plans, written down once (YAML or JSON), given to `plan --plan-file` or put beside
her scan in a batch's folder (`anna.plan.yaml` beside `anna.mcap`).

    left: [augmentation:300:moderate, lift:fold=20]     # each side's operations, in the order made
    right: augmentation:250:moderate                   # one operation, or a list
    deform: [ptosis:2]                                  # changes by degree, shown after the operations
    symmetrise: right                                   # or: propose the operations on this side

Every key may be left out; no other key is taken. The words are the command line's (`plan --help`).
"""
from __future__ import annotations

import stat
from dataclasses import dataclass
from pathlib import Path

KEYS = ("left", "right", "deform", "symmetrise")
MAX_BYTES = 1 << 20
"""A plan file longer than this is no plan file."""


@dataclass(frozen=True)
class WrittenPlan:
    """A plan file's contents: the command line's --left, --right, --deform and --symmetrise."""

    left: tuple[str, ...] = ()
    right: tuple[str, ...] = ()
    deform: tuple[str, ...] = ()
    symmetrise: str | None = None


def read_written_plan(path: Path) -> WrittenPlan:
    """The plan file at `path`; ValueError in one sentence naming it when it cannot be read or says anything
    but the keys above, each a word or a list of words."""
    import yaml

    try:
        info = Path(path).stat()
        if not stat.S_ISREG(info.st_mode):            # a named pipe or a device: reading it may never end
            raise ValueError("is not a regular file")
        if info.st_size > MAX_BYTES:
            raise ValueError(f"is over {MAX_BYTES >> 20} MB")
        text = Path(path).read_text(encoding="utf-8")
        data = yaml.safe_load(text)        # JSON is YAML; safe_load builds no Python objects
    except OSError as exc:
        raise ValueError(f"the plan file {path} cannot be read ({exc.strerror or type(exc).__name__})") from None
    except (UnicodeDecodeError, yaml.YAMLError, RecursionError) as exc:   # Recursion: nested deeper than any plan
        raise ValueError(f"the plan file {path} cannot be read as YAML or JSON ({type(exc).__name__})") from None
    except ValueError as exc:
        raise ValueError(f"the plan file {path} {exc}") from None
    if data is None:
        data = {}
    if not isinstance(data, dict) or not set(map(str, data)) <= set(KEYS):
        raise ValueError(f"the plan file {path} must hold only the keys {', '.join(KEYS)}")
    words = {}
    for key, value in data.items():
        items = value if isinstance(value, list) else [value]
        if not all(isinstance(v, (str, int, float)) and not isinstance(v, bool) for v in items):
            raise ValueError(f"the plan file {path}: '{key}' takes a word or a list of words")
        words[key] = tuple(str(v) for v in items)
    symmetrise = words.pop("symmetrise", ())
    if len(symmetrise) > 1:
        raise ValueError(f"the plan file {path}: 'symmetrise' takes one side")
    return WrittenPlan(**words, symmetrise=symmetrise[0] if symmetrise else None)
