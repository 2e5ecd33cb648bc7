"""PLY point clouds and triangle meshes (docs/artefacts.md: binary little-endian, millimetres).

Read: ascii and binary PLY, vertices with optional normals, faces of one polygon size
(fan-triangulated). Every defect (not PLY, truncated, NaN, bad indices) raises
ArtefactError naming the file. Write: binary little-endian, float64 vertices, atomically.
open3d's reader reports such defects only as console warnings, hence this module.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .atomic import atomic_open
from .errors import ArtefactError, require_file

_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}
_MAX_HEADER = 1 << 16
MAX_ELEMENTS = 20_000_000
"""Vertices (or faces) a PLY may declare: no body scan holds more."""


@dataclass
class Geometry:
    """A point cloud (faces None) or triangle mesh; coordinates in mm unless stated."""

    points: np.ndarray
    faces: np.ndarray | None = None
    normals: np.ndarray | None = None
    comments: list[str] = field(default_factory=list)


@dataclass
class _Element:
    name: str
    count: int
    props: list[tuple[str, str, str | None]] = field(default_factory=list)  # (name, type, list count type)


def read_ply(path: str | Path) -> Geometry:
    """Read a PLY file; raise ArtefactError naming the file and the defect."""
    path = require_file(path, "PLY file", ArtefactError)
    try:
        with open(path, "rb") as fh:                  # the header first: a foreign or forged file is
            head = fh.read(_MAX_HEADER)               # refused before its body is read
            fmt, elements, comments, body = _parse_header(path, head)
            too_many = [e for e in elements if e.count > MAX_ELEMENTS]
            if too_many:
                raise ArtefactError(path, f"declares {too_many[0].count:,} '{too_many[0].name}' elements, more than "
                                          f"any body scan holds ({MAX_ELEMENTS:,})")
            body += fh.read()
    except OSError as exc:
        raise ArtefactError(path, f"cannot be read ({exc.strerror})") from None
    if fmt is None:
        arrays = _read_ascii(path, elements, body)
    else:
        arrays = _read_binary(path, elements, body, fmt)
    return _to_geometry(path, elements, arrays, comments)


def _parse_header(path: Path, data: bytes):
    if not data.startswith(b"ply"):
        raise ArtefactError(path, "is not a PLY file (it does not start with 'ply')")
    end = data.find(b"end_header", 0, _MAX_HEADER)
    if end < 0:
        raise ArtefactError(path, "is not a valid PLY file: its header has no 'end_header' line")
    nl = data.find(b"\n", end)
    body = data[nl + 1:] if nl >= 0 else b""
    try:
        lines = data[:end].decode("ascii").splitlines()[1:]
    except UnicodeDecodeError:
        raise ArtefactError(path, "is not a valid PLY file: its header is not ASCII text") from None
    fmt, elements, comments = "missing", [], []
    for line in lines:
        words = line.split()
        if not words:
            continue
        try:
            if words[0] == "format":
                if words[1] not in _FORMATS:
                    raise ArtefactError(path, f"has an unsupported PLY format '{words[1]}'")
                fmt = _FORMATS[words[1]]
            elif words[0] == "element":
                elements.append(_Element(words[1], int(words[2])))
            elif words[0] == "property":
                if words[1] == "list":
                    elements[-1].props.append((words[4], _TYPES[words[3]], _TYPES[words[2]]))
                else:
                    elements[-1].props.append((words[2], _TYPES[words[1]], None))
            elif words[0] in ("comment", "obj_info"):
                comments.append(line.split(None, 1)[1] if len(words) > 1 else "")
        except (IndexError, KeyError, ValueError):
            raise ArtefactError(path, f"is not a valid PLY file: bad header line '{line.strip()}'") from None
    if fmt == "missing":
        raise ArtefactError(path, "is not a valid PLY file: its header has no 'format' line")
    if any(e.count < 0 for e in elements):
        raise ArtefactError(path, "is not a valid PLY file: an element has a negative count")
    return fmt, elements, comments, body


def _read_binary(path: Path, elements: list[_Element], body: bytes, order: str) -> dict:
    arrays, offset = {}, 0
    for el in elements:
        lists = [p for p in el.props if p[2] is not None]
        if not lists:
            dtype = np.dtype([(n, order + t) for n, t, _ in el.props])
        elif el.name == "face" and len(lists) == 1:
            dtype = _face_dtype(path, el, body, offset, order)
        else:
            raise ArtefactError(path, f"has a PLY element '{el.name}' with list properties breastplan cannot read")
        size = dtype.itemsize * el.count
        if offset + size > len(body):
            raise ArtefactError(path, f"is truncated: its header declares {el.count} '{el.name}' "
                                      f"elements but the file ends before their data does")
        arrays[el.name] = np.frombuffer(body, dtype=dtype, count=el.count, offset=offset)
        offset += size
    return arrays


def _face_dtype(path: Path, el: _Element, body: bytes, offset: int, order: str) -> np.dtype:
    """Structured dtype of a face element, assuming every face has the first face's vertex count."""
    fields = []
    for name, t, count_t in el.props:
        if count_t is None:
            fields.append((name, order + t))
            continue
        at = offset + np.dtype(fields).itemsize  # the first face's vertex count
        if el.count and at + np.dtype(count_t).itemsize > len(body):
            raise ArtefactError(path, "is truncated: the file ends before its face data")
        k = int(np.frombuffer(body, order + count_t, 1, at)[0]) if el.count else 3
        if k < 3:
            raise ArtefactError(path, f"has a face with {k} vertices; faces need at least 3")
        fields += [("_n", order + count_t), ("_idx", order + t, (k,))]
    return np.dtype(fields)


def _read_ascii(path: Path, elements: list[_Element], body: bytes) -> dict:
    try:
        tokens = np.array(body.split(), dtype=float)
    except ValueError:
        raise ArtefactError(path, "is not a valid ASCII PLY file: its data holds a value that is not a number") from None
    arrays, pos = {}, 0
    for el in elements:
        n_scalar = sum(1 for p in el.props if p[2] is None)
        if any(p[2] is not None for p in el.props):
            if el.name != "face" or el.props[0][2] is None or len(el.props) != 1:
                raise ArtefactError(path, f"has a PLY element '{el.name}' with list properties breastplan cannot read")
            k = int(tokens[pos]) if el.count and pos < len(tokens) else 3
            width = 1 + k
        else:
            width = n_scalar
        chunk = tokens[pos: pos + width * el.count]
        if chunk.size < width * el.count:
            raise ArtefactError(path, f"is truncated: its header declares {el.count} '{el.name}' "
                                      f"elements but the file ends before their data does")
        table = chunk.reshape(el.count, width)
        if width != n_scalar:
            arrays[el.name] = {"_n": table[:, 0], "_idx": table[:, 1:]}
        else:
            arrays[el.name] = {name: table[:, i] for i, (name, _, _) in enumerate(el.props)}
        pos += width * el.count
    if pos != len(tokens):
        extra = len(tokens) - pos
        raise ArtefactError(path, f"is not a valid ASCII PLY file: its data holds {extra} value{'s' * (extra != 1)} "
                                  f"more than its header declares (a line with too many numbers?)")
    return arrays


def _to_geometry(path: Path, elements: list[_Element], arrays: dict, comments: list[str]) -> Geometry:
    if "vertex" not in arrays:
        raise ArtefactError(path, "has no 'vertex' element")
    v = arrays["vertex"]
    names = v.dtype.names if hasattr(v, "dtype") else tuple(v)
    if not {"x", "y", "z"} <= set(names):
        raise ArtefactError(path, "has vertices without x, y and z coordinates")
    n = len(v["x"])
    if n == 0:
        raise ArtefactError(path, "has no vertices")
    points = np.column_stack([np.asarray(v[c], dtype=np.float64) for c in "xyz"])
    if not np.isfinite(points).all():
        bad = int((~np.isfinite(points).all(axis=1)).sum())
        raise ArtefactError(path, f"has {bad} vertices with NaN or infinite coordinates")
    normals = None
    if {"nx", "ny", "nz"} <= set(names):
        normals = np.column_stack([np.asarray(v[c], dtype=np.float64) for c in ("nx", "ny", "nz")])
    faces = None
    if "face" in arrays and len(arrays["face"]["_n"]):
        f = arrays["face"]
        if not np.all(f["_n"] == f["_idx"].shape[1]):
            raise ArtefactError(path, "mixes faces of different vertex counts; triangulate it first")
        idx = np.asarray(f["_idx"], dtype=np.int64)
        if idx.min() < 0 or idx.max() >= n:
            raise ArtefactError(path, f"has faces whose vertex indices lie outside 0..{n - 1}")
        k = idx.shape[1]  # fan triangulation of k-gons, vectorised over faces
        fan = np.stack([np.zeros(k - 2, int), np.arange(1, k - 1), np.arange(2, k)], axis=1)
        faces = idx[:, fan].reshape(-1, 3)
    return Geometry(points=points, faces=faces, normals=normals, comments=comments)


def write_ply(path: str | Path, points, faces=None, normals=None, comments=()) -> Path:
    """Write points (N,3) [and triangles (M,3), normals (N,3)] as binary little-endian PLY, atomically."""
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must be (N, 3), got {points.shape}")
    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    if normals is not None:
        fields += [("nx", "<f8"), ("ny", "<f8"), ("nz", "<f8")]
    vert = np.empty(len(points), dtype=fields)
    vert["x"], vert["y"], vert["z"] = points.T
    if normals is not None:
        vert["nx"], vert["ny"], vert["nz"] = np.asarray(normals, dtype=np.float64).T
    header = ["ply", "format binary_little_endian 1.0"]
    header += [f"comment {c}" for c in comments]
    header.append(f"element vertex {len(points)}")
    header += [f"property double {name}" for name, _ in fields]
    face_bytes = b""
    if faces is not None:
        faces = np.asarray(faces)
        tri = np.empty(len(faces), dtype=[("n", "u1"), ("idx", "<i4", (3,))])
        tri["n"], tri["idx"] = 3, faces
        header += [f"element face {len(faces)}", "property list uchar int vertex_indices"]
        face_bytes = tri.tobytes()
    header.append("end_header")
    path = Path(path)
    with atomic_open(path) as fh:
        fh.write(("\n".join(header) + "\n").encode("ascii", errors="replace"))  # PLY headers are ASCII
        fh.write(vert.tobytes())
        fh.write(face_bytes)
    return path
