"""NPZ artefacts (docs/artefacts.md): schema-tagged, pickle-free, validated, atomic.

Every artefact holds `schema` ("breastplan.<name>/<version>"), `units`, `frame`,
`version` (of the producing breastplan), `meta` (a JSON string) and plain numeric or
string arrays. `load_npz` checks the schema, that `meta` is a JSON object and, given specs, each
array's dtype kind and shape and the JSON type of each metadata entry present; any defect raises
ArtefactError naming the file.
"""
from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Mapping

import numpy as np

from .atomic import atomic_open
from .errors import ArtefactError, NewerArtefactError, require_file
from .json_text import from_json

RESERVED = ("schema", "units", "frame", "version", "meta")
MAX_BYTES = 256 << 20
"""Bytes of arrays an artefact may declare: breastplan's largest, a database, holds tens of MB; more
(a small file that inflates to gigabytes) is refused before anything is unpacked."""

Spec = Mapping[str, tuple[str, tuple]]
"""name → (dtype kinds, shape); shape entries are ints, or names bound to one size across arrays."""
MetaSpec = Mapping[str, object]
"""metadata key → the JSON type of its value: `str`, `int`, `float` (an int too), `bool`, `list`,
`dict`, a tuple of these, `[T]` for a list of T, or a MetaSpec for an object (key "*": every value
of it). Absent keys pass."""
_JSON_NAMES = {str: "a string", int: "an integer", float: "a number", bool: "a boolean",
               list: "a list", dict: "an object", type(None): "null"}


def save_npz(path: str | Path, schema: str, arrays: Mapping[str, np.ndarray], *,
             units: str = "mm", frame: str = "breast", meta: Mapping | None = None,
             compress: bool = False) -> Path:
    """Write an artefact atomically; `schema` like "breastplan.database/1"; deflated if `compress`."""
    from . import __version__

    clash = set(arrays) & set(RESERVED)
    if clash:
        raise ValueError(f"array names {sorted(clash)} are reserved")
    payload = {k: np.asarray(v) for k, v in arrays.items()}
    for k, v in payload.items():
        if v.dtype.kind == "O":
            raise ValueError(f"array '{k}' has dtype object, which would need pickle")
    payload.update(schema=np.str_(schema), units=np.str_(units), frame=np.str_(frame),
                   version=np.str_(__version__), meta=np.str_(json.dumps(dict(meta or {}))))
    path = Path(path)
    with atomic_open(path) as fh:
        (np.savez_compressed if compress else np.savez)(fh, **payload)
    return path


class Artefact(dict):
    """Loaded arrays by name, plus `schema`, `units`, `frame`, `version`, `meta` attributes."""

    schema: str
    units: str
    frame: str
    version: str
    meta: dict


def load_npz(path: str | Path, schema: str, spec: Spec | None = None, meta_spec: MetaSpec | None = None) -> Artefact:
    """Load and validate an artefact of `schema` ("breastplan.<name>/<version>")."""
    path = require_file(path, f"{schema} artefact", ArtefactError)
    if not zipfile.is_zipfile(path):
        raise ArtefactError(path, f"is not an NPZ file (expected a {schema} artefact)")
    try:
        _check_sizes(path)
        with np.load(path, allow_pickle=False) as npz:
            raw = {k: npz[k] for k in npz.files}
    except (zipfile.BadZipFile, OSError, EOFError, ValueError, KeyError) as exc:
        problem = "holds arrays that would need pickle" if "pickle" in str(exc) else "is a corrupt NPZ file"
        raise ArtefactError(path, problem) from None
    if "schema" not in raw:
        raise ArtefactError(path, f"is not a breastplan artefact (it has no schema; expected {schema})")
    found = str(raw["schema"])
    want_name, want_ver = _split_schema(schema)
    name, ver = _split_schema(found)
    if name != want_name:
        raise ArtefactError(path, f"has schema {found}, expected {schema}")
    if ver is None or ver > want_ver:
        raise NewerArtefactError(path, f"has schema {found}, newer than this breastplan reads ({schema})")
    art = Artefact({k: v for k, v in raw.items() if k not in RESERVED})
    art.schema, art.units = found, str(raw.get("units", ""))
    art.frame, art.version = str(raw.get("frame", "")), str(raw.get("version", ""))
    try:
        art.meta = from_json(str(raw.get("meta", "{}")))
    except ValueError:
        raise ArtefactError(path, "has metadata that is not valid JSON") from None
    if not isinstance(art.meta, dict):
        raise ArtefactError(path, f"has metadata that is {_json_name(art.meta)}, not a JSON object")
    if spec:
        check_arrays(path, art, spec)
    if meta_spec:
        _check_meta(path, art.meta, meta_spec)
    return art


def _check_sizes(path: Path) -> None:
    """ArtefactError for an array whose header declares more data than its member holds: read
    before loading, so that a forged header cannot make numpy allocate what the file never held."""
    with zipfile.ZipFile(path) as archive:
        total = sum(info.file_size for info in archive.infolist())
        if total > MAX_BYTES:
            raise ArtefactError(path, f"unpacks to {total:,} bytes, more than any breastplan artefact holds "
                                      f"({MAX_BYTES >> 20} MiB)")
        for info in archive.infolist():
            if not info.filename.endswith(".npy"):
                continue
            with archive.open(info) as fh:
                major, _ = np.lib.format.read_magic(fh)
                read = np.lib.format.read_array_header_1_0 if major == 1 else np.lib.format.read_array_header_2_0
                shape, _, dtype = read(fh)
                declared = int(np.prod(shape, dtype=object)) * dtype.itemsize
                if not dtype.hasobject and declared > info.file_size - fh.tell():
                    raise ArtefactError(path, f"has an array '{info.filename[:-4]}' whose header declares "
                                              f"{'×'.join(map(str, shape))} values, more than the file holds")


def _split_schema(schema: str) -> tuple[str, int | None]:
    name, _, ver = schema.partition("/")
    return name, int(ver) if ver.isdigit() else None


def check_arrays(path: Path, arrays: dict, spec: Spec) -> dict[str, int]:
    """ArtefactError naming `path` unless each array of `spec` is present with its dtype kind and shape
    (named sizes consistent across arrays, floats finite); the named sizes. Floats become float64 and
    integers int64 in `arrays`, so that no reader meets float16 or an unsigned wrap-around."""
    sizes: dict[str, int] = {}
    for key, (kinds, shape) in spec.items():
        if key not in arrays:
            raise ArtefactError(path, f"lacks the array '{key}'")
        a = arrays[key]
        if a.dtype.kind not in kinds:
            raise ArtefactError(path, f"has array '{key}' of dtype {a.dtype}, expected kind '{kinds}'")
        if a.ndim != len(shape):
            raise ArtefactError(path, f"has array '{key}' of shape {a.shape}, expected {len(shape)} dimensions")
        for dim, want in zip(a.shape, shape):
            size = sizes.setdefault(want, dim) if isinstance(want, str) else want
            if dim != size:
                named = f" ({want} = {size})" if isinstance(want, str) else ""
                raise ArtefactError(path, f"has array '{key}' of shape {a.shape}, inconsistent with the rest{named}")
        if a.dtype.kind == "f":
            a = arrays[key] = a.astype(np.float64)
            if not np.isfinite(a).all():
                raise ArtefactError(path, f"has NaN or infinite values in '{key}'")
        elif a.dtype.kind in "iu":
            if a.size and a.dtype.kind == "u" and a.max() > np.iinfo(np.int64).max:
                raise ArtefactError(path, f"has values in '{key}' beyond the range of integers it may hold")
            arrays[key] = a.astype(np.int64)
    return sizes


def _check_meta(path: Path, meta: dict, spec: MetaSpec, where: str = "") -> None:
    """ArtefactError naming `where`+key for the first entry of `meta` that is not of its MetaSpec type."""
    for key, want in spec.items():
        items = meta.items() if key == "*" else [(key, meta[key])] if key in meta else []
        for name, value in items:
            if isinstance(want, Mapping):
                if not isinstance(value, dict):
                    raise ArtefactError(path, f"has metadata '{where}{name}' that is {_json_name(value)}, "
                                              f"not an object")
                _check_meta(path, value, want, f"{where}{name}.")
            elif isinstance(want, list):
                if not isinstance(value, list):
                    raise ArtefactError(path, f"has metadata '{where}{name}' that is {_json_name(value)}, not a list")
                _check_meta(path, dict(enumerate(value)), {"*": want[0]}, f"{where}{name}.")
            elif not _is_json(value, want if isinstance(want, tuple) else (want,)):
                kinds = " or ".join(_JSON_NAMES[t] for t in (want if isinstance(want, tuple) else (want,)))
                raise ArtefactError(path, f"has metadata '{where}{name}' that is {_json_name(value)}, not {kinds}")


def _is_json(value, types: tuple) -> bool:
    if isinstance(value, bool):
        return bool in types
    return isinstance(value, types) or (float in types and isinstance(value, int))


def _json_name(value) -> str:
    return _JSON_NAMES.get(type(value), type(value).__name__)
