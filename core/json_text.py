"""The text breastplan writes. JSON: strict (a NaN or an infinity, which JSON has not, is null), numpy
arrays and scalars as plain lists and numbers, anything else unknown as its string. Any text file:
UTF-8, whatever file names it holds."""
from __future__ import annotations

import json
import math


def to_json(value, **kwargs) -> str:
    """`value` as strict JSON text; `kwargs` go to json.dumps (indent, separators)."""
    return json.dumps(_strict(value), allow_nan=False, default=str, **kwargs)


def from_json(text: str | bytes):
    """The value of JSON `text`; ValueError for text that is not JSON, nested too deep included (Python's
    parser recurses: a file of 100 000 '[' would otherwise end it with a RecursionError)."""
    try:
        return json.loads(text)
    except RecursionError:
        raise ValueError("JSON nested deeper than Python's parser reaches") from None


def measure_values(x):
    """Measures as plain JSON values: floats to 4 decimals below 10, else 2 (None where not finite);
    arrays to lists; dicts item by item."""
    import numpy as np                      # not at import: the command starts without numpy

    if isinstance(x, dict):
        return {k: measure_values(v) for k, v in x.items()}
    if isinstance(x, np.ndarray):
        return [measure_values(float(v)) for v in x]
    if isinstance(x, (float, np.floating)):
        x = float(x)
        return round(x, 4 if abs(x) < 10 else 2) if math.isfinite(x) else None
    return x


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


def utf8(text: str) -> bytes:
    """`text` as UTF-8 bytes, a file name's bytes that are not UTF-8 (which Python holds as surrogates,
    e.g. a Latin-1 `M\\xfcller.ply`) written as `\\xfc`."""
    try:
        raw = text.encode("utf-8", "surrogateescape")
    except UnicodeEncodeError:                               # a surrogate no file name holds
        return text.encode("utf-8", "backslashreplace")
    return raw.decode("utf-8", "backslashreplace").encode("utf-8")
