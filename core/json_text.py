"""The JSON text breastplan writes: strict JSON (a NaN or an infinity, which JSON has not, is null),
numpy arrays and scalars as plain lists and numbers, anything else unknown as its string."""
from __future__ import annotations

import json
import math


def to_json(value, **kwargs) -> str:
    """`value` as strict JSON text; `kwargs` go to json.dumps (indent, separators)."""
    return json.dumps(_strict(value), allow_nan=False, default=str, **kwargs)


def _strict(value):
    if isinstance(value, dict):
        return {k: _strict(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_strict(v) for v in value]
    if hasattr(value, "tolist"):
        return _strict(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
