"""PLY point clouds and triangle meshes (docs/artefacts.md: binary little-endian, millimetres).

Read: ascii and binary PLY, vertices with optional normals, faces of one polygon size
(fan-triangulated). Every defect (not PLY, truncated, NaN, bad indices) raises
ArtefactError naming the file. Write: binary little-endian, float64 vertices, atomically.
open3d's reader reports such defects only as console warnings, hence this module.
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

import numpy as np

from .atomic import atomic_open
from .errors import ArtefactError, counted, require_file

_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}
_MAX_HEADER = 1 << 16
_CHUNK = 1 << 24
"""Bytes of ASCII data parsed at a time."""
_TRAILING = 64
"""Bytes of whitespace a binary PLY may hold after its data (a final newline)."""
_MAX_POLYGON = 1 << 16
"""Vertices a face may have."""
MAX_ELEMENTS = 20_000_000
"""Vertices (or faces) a PLY may declare: no body scan holds more."""
FACES_PER_VERTEX = 4
"""Faces a mesh may have per vertex: a triangulated surface has about 2, a closed one 2 exactly (Euler)."""


@dataclass
class Geometry:
    """A point cloud (faces None) or triangle mesh; coordinates in mm unless stated."""

    points: np.ndarray
    faces: np.ndarray | None = None
    normals: np.ndarray | None = None
    comments: list[str] = field(default_factory=list)
    colours: np.ndarray | None = None      # (N, 3) uint8 RGB per vertex


@dataclass
class _Element:
    name: str
    count: int
    props: list[tuple[str, str, str | None]] = field(default_factory=list)  # (name, type, list count type)


def read_ply(path: str | Path) -> Geometry:
    """Read a PLY file; raise ArtefactError naming the file and the defect.

    The header is read and checked first, then the sizes it declares against the file's size, so
    that a foreign, forged or oversized file is refused before its body is read; the body is read
    as declared (binary) or parsed in chunks (ASCII), never more than it should hold.
    """
    path = require_file(path, "PLY file", ArtefactError)
    try:
        with open(path, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            fmt, elements, comments, start = _parse_header(path, fh.read(_MAX_HEADER))
            _check_declared(path, elements, fmt, size - start)
            fh.seek(start)
            if fmt is None:
                arrays = _read_ascii(path, elements, _Numbers(path, fh))
            else:
                arrays = _read_binary(path, elements, fh, fmt, size)
    except OSError as exc:
        raise ArtefactError(path, f"cannot be read ({exc.strerror})") from None
    return _to_geometry(path, elements, arrays, comments)


# words on a header line, by (keyword, second word is "list"); other keywords are refused
_WORDS = {("format", False): 3, ("element", False): 3, ("property", False): 3, ("property", True): 5}
_END_HEADER = re.compile(rb"^end_header[ \t\r]*$", re.MULTILINE)


def _parse_header(path: Path, data: bytes):
    """(byte order or None for ASCII, elements, comments, offset of the body) of a PLY header."""
    if not data.startswith(b"ply"):
        raise ArtefactError(path, "is not a PLY file (it does not start with 'ply')")
    last = _END_HEADER.search(data, 0, _MAX_HEADER)          # the line itself, not those words in a comment
    if last is None:
        raise ArtefactError(path, "is not a valid PLY file: its header has no 'end_header' line")
    end = last.start()
    nl = data.find(b"\n", end)
    start = nl + 1 if nl >= 0 else len(data)
    try:
        lines = data[:end].decode("ascii").splitlines()[1:]
    except UnicodeDecodeError:
        raise ArtefactError(path, "is not a valid PLY file: its header is not ASCII text") from None
    fmt, elements, comments = "missing", [], []
    for line in lines:
        words = line.split()
        if not words:
            continue
        if words[0] in ("comment", "obj_info"):
            comments.append(line.split(None, 1)[1] if len(words) > 1 else "")
            continue
        try:
            if len(words) != _WORDS[words[0], words[1] == "list"]:
                raise ValueError
            if words[0] == "format":
                if words[1] not in _FORMATS:
                    raise ArtefactError(path, f"has an unsupported PLY format '{words[1]}'")
                if words[2] != "1.0":
                    raise ArtefactError(path, f"has PLY version {words[2]}; only version 1.0 exists")
                fmt = _FORMATS[words[1]]
            elif words[0] == "element":
                elements.append(_Element(words[1], int(words[2])))
            elif words[1] == "list":
                elements[-1].props.append((words[4], _TYPES[words[3]], _TYPES[words[2]]))
            else:
                elements[-1].props.append((words[2], _TYPES[words[1]], None))
        except (IndexError, KeyError, ValueError):
            raise ArtefactError(path, f"is not a valid PLY file: bad header line '{line.strip()}'") from None
    if fmt == "missing":
        raise ArtefactError(path, "is not a valid PLY file: its header has no 'format' line")
    if any(e.count < 0 for e in elements):
        raise ArtefactError(path, "is not a valid PLY file: an element has a negative count")
    for e in elements:
        if e.name == "face" and any("f" in (t[0], count_t[0]) for _, t, count_t in e.props if count_t is not None):
            raise ArtefactError(path, "is not a valid PLY file: its faces' vertex counts or indices are declared as "
                                      "floats, not integers")
        names = [p[0] for p in e.props]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ArtefactError(path, f"is not a valid PLY file: its element '{e.name}' declares the property "
                                      f"'{twice[0]}' more than once")
    return fmt, elements, comments, start


def faces_problem(vertices: int, faces: int) -> str | None:
    """What is wrong with a mesh of these counts that no surface has (more faces than FACES_PER_VERTEX
    per vertex, where a reader would build them all before finding out), or None."""
    if faces > FACES_PER_VERTEX * vertices + 100:
        return (f"{counted(faces, 'face')} over {counted(vertices, 'vertex', 'vertices')}: a scanned surface has "
                f"about 2 faces per vertex, and breastplan reads meshes of {FACES_PER_VERTEX} at most")
    return None


def _check_declared(path: Path, elements: list[_Element], fmt: str | None, body_size: int) -> None:
    """ArtefactError if the header declares more than any body scan holds, or more than the file's
    `body_size` bytes can hold (each face counted as a triangle; in ASCII, 2 bytes per number)."""
    for el in elements:
        if el.count > MAX_ELEMENTS:
            raise ArtefactError(path, f"declares {el.count:,} '{el.name}' elements, more than any body scan "
                                      f"holds ({MAX_ELEMENTS:,})")
    counts = {el.name: el.count for el in elements}
    problem = faces_problem(counts.get("vertex", 0), counts.get("face", 0))
    if problem:
        raise ArtefactError(path, f"declares {problem}")
    need = 0
    for el in elements:
        if fmt is None:
            need += 2 * el.count * sum(1 if count_t is None else 4 for _, _, count_t in el.props)
        else:
            need += el.count * sum(np.dtype(t).itemsize * (1 if count_t is None else 3)
                                   + (0 if count_t is None else np.dtype(count_t).itemsize)
                                   for _, t, count_t in el.props)
        if need - (fmt is None) > body_size:
            raise _truncated(path, el)


class FaceLayoutError(ArtefactError):
    """Face data that does not fit faces of the first face's vertex count: a truncated file, or faces of
    several vertex counts (triangles and quads), which this reader does not read but a polygon reader may."""


def _truncated(path: Path, el: _Element) -> ArtefactError:
    error = FaceLayoutError if _has_faces([el]) else ArtefactError
    return error(path, f"is truncated: its header declares {counted(el.count, repr(el.name) + ' element')} "
                       f"but the file ends before their data does")


def _has_faces(elements: list[_Element]) -> bool:
    return any(el.name == "face" and any(p[2] is not None for p in el.props) for el in elements)


def _read_binary(path: Path, elements: list[_Element], fh: BinaryIO, order: str, size: int) -> dict:
    """Each element's records, read as declared; trailing data other than whitespace is refused."""
    arrays = {}
    for el in elements:
        lists = [p for p in el.props if p[2] is not None]
        if not lists:
            dtype = np.dtype([(n, order + t) for n, t, _ in el.props])
        elif el.name == "face" and len(lists) == 1:
            dtype = _face_dtype(path, el, fh, order, size)
        else:
            raise ArtefactError(path, f"has a PLY element '{el.name}' with list properties breastplan cannot read")
        if fh.tell() + dtype.itemsize * el.count > size:        # checked before anything is allocated
            raise _truncated(path, el)
        arrays[el.name] = np.frombuffer(fh.read(dtype.itemsize * el.count), dtype=dtype, count=el.count)
    extra = size - fh.tell()
    if extra > _TRAILING or fh.read(extra).strip():
        raise (FaceLayoutError if _has_faces(elements) else ArtefactError)(
            path, f"is not a valid PLY file: it holds {counted(extra, 'byte')} after the data its header declares "
                  "(a wrong element count or property type?)")
    return arrays


def _face_dtype(path: Path, el: _Element, fh: BinaryIO, order: str, size: int) -> np.dtype:
    """Structured dtype of a face element, assuming every face has the first face's vertex count."""
    fields = []
    for name, t, count_t in el.props:
        if count_t is None:
            fields.append((name, order + t))
            continue
        k = 3
        if el.count:                                            # the first face's vertex count
            at = fh.tell() + np.dtype(fields).itemsize
            if at + np.dtype(count_t).itemsize > size:
                raise _truncated(path, el)
            fh.seek(at)
            k = int(np.frombuffer(fh.read(np.dtype(count_t).itemsize), order + count_t)[0])
            fh.seek(at - np.dtype(fields).itemsize)
        if k < 3:
            raise ArtefactError(path, f"has a face with {counted(k, 'vertex', 'vertices')}; faces need at least 3")
        if fh.tell() + el.count * (np.dtype(fields).itemsize + np.dtype(count_t).itemsize
                                   + k * np.dtype(t).itemsize) > size:
            raise _truncated(path, el)
        if k > _MAX_POLYGON:
            raise ArtefactError(path, f"has a face with {k:,} vertices; breastplan reads at most {_MAX_POLYGON:,}")
        fields += [("_n", order + count_t), ("_idx", order + t, (k,))]
    return np.dtype(fields)


class _Numbers:
    """The numbers of an ASCII PLY body, parsed a chunk at a time as they are taken."""

    def __init__(self, path: Path, fh: BinaryIO):
        self.path, self.fh = path, fh
        self.left = os.fstat(fh.fileno()).st_size - fh.tell()   # bytes not yet read
        self.buf, self.pos, self.carry = np.empty(0), 0, b""

    def _fill(self) -> bool:
        """Parse the next chunk (up to its last whitespace); False at the end of the file."""
        block = self.fh.read(_CHUNK)
        self.left = self.left - len(block) if block else 0       # 0 also if the file shrank meanwhile
        data, self.carry = self.carry + block, b""
        if block:
            cut = max(data.rfind(c) for c in b" \t\r\n") + 1       # a number may go on in the next chunk
            if cut == 0 and len(data) > _CHUNK:
                raise _not_a_number(self.path)
            data, self.carry = data[:cut], data[cut:]
        try:
            self.buf, self.pos = np.array(data.split(), dtype=float), 0
        except ValueError:
            raise _not_a_number(self.path) from None
        return bool(block) or self.buf.size > 0

    def most(self) -> int:
        """The most numbers the rest of the file can hold (2 bytes each)."""
        return self.buf.size - self.pos + (self.left + len(self.carry) + 1) // 2

    def peek(self) -> float | None:
        """The next number without taking it; None at the end of the file."""
        while self.pos == self.buf.size:
            if not self._fill():
                return None
        return float(self.buf[self.pos])

    def take(self, n: int) -> np.ndarray:
        """The next `n` numbers (fewer at the end of the file)."""
        out, got = np.empty(min(n, self.most())), 0
        while got < out.size and self.peek() is not None:
            part = self.buf[self.pos: self.pos + out.size - got]
            out[got: got + part.size] = part
            got, self.pos = got + part.size, self.pos + part.size
        return out[:got]

    def rest(self) -> int | None:
        """How many numbers remain: exact if the file holds no more chunks, else None (many)."""
        count = self.buf.size - self.pos
        while self.left or self.carry:
            if count and self.left:
                return None
            self._fill()
            count += self.buf.size
        return count


def _not_a_number(path: Path) -> ArtefactError:
    return ArtefactError(path, "is not a valid ASCII PLY file: its data holds a value that is not a number")


def _read_ascii(path: Path, elements: list[_Element], numbers: _Numbers) -> dict:
    arrays = {}
    for el in elements:
        n_scalar = sum(1 for p in el.props if p[2] is None)
        if any(p[2] is not None for p in el.props):
            if el.name != "face" or el.props[0][2] is None or len(el.props) != 1:
                raise ArtefactError(path, f"has a PLY element '{el.name}' with list properties breastplan cannot read")
            first = numbers.peek() if el.count else 3.0          # the first face's vertex count
            if first is not None and first < 3:
                raise ArtefactError(path, f"has a face with {first:g} vert{'ex' if first == 1 else 'ices'}; "
                                          "faces need at least 3")
            k = int(first) if first is not None and first <= _MAX_POLYGON else 3
            width = 1 + k
        else:
            width = n_scalar
        if width * el.count > numbers.most():                  # checked before anything is allocated
            raise _truncated(path, el)
        chunk = numbers.take(width * el.count)
        if chunk.size < width * el.count:
            raise _truncated(path, el)
        table = chunk.reshape(el.count, width)
        if width != n_scalar:
            arrays[el.name] = {"_n": table[:, 0], "_idx": table[:, 1:]}
        else:
            arrays[el.name] = {name: table[:, i] for i, (name, _, _) in enumerate(el.props)}
    extra = numbers.rest()
    if extra != 0:
        many = f"{extra} value{'s' * (extra != 1)}" if extra is not None else "values"
        raise (FaceLayoutError if _has_faces(elements) else ArtefactError)(
            path, f"is not a valid ASCII PLY file: its data holds {many} more than its header declares (a line with "
                  "too many numbers?)")
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
        raise ArtefactError(path, f"has {counted(bad, 'vertex', 'vertices')} with NaN or infinite coordinates")
    normals = None
    if {"nx", "ny", "nz"} <= set(names):
        normals = np.column_stack([np.asarray(v[c], dtype=np.float64) for c in ("nx", "ny", "nz")])
    colours = next((_colours(v, c) for c in (("red", "green", "blue"), ("diffuse_red", "diffuse_green", "diffuse_blue"))
                    if set(c) <= set(names)), None)
    faces = None
    if "face" in arrays and len(arrays["face"]["_n"]):
        f = arrays["face"]
        if not np.all(f["_n"] == f["_idx"].shape[1]):
            raise FaceLayoutError(path, "mixes faces of different vertex counts; triangulate it first")
        idx = np.asarray(f["_idx"], dtype=np.int64)
        if idx.min() < 0 or idx.max() >= n:
            raise ArtefactError(path, f"has faces whose vertex indices lie outside 0..{n - 1}")
        k = idx.shape[1]  # fan triangulation of k-gons, vectorised over faces
        fan = np.stack([np.zeros(k - 2, int), np.arange(1, k - 1), np.arange(2, k)], axis=1)
        faces = idx[:, fan].reshape(-1, 3)
    return Geometry(points=points, faces=faces, normals=normals, comments=comments, colours=colours)


def _colours(v, names: tuple[str, str, str]) -> np.ndarray:
    """(N, 3) uint8 RGB of vertex colour properties: integers as they are, floats as 0..1."""
    rgb = np.column_stack([np.asarray(v[c], dtype=np.float64) for c in names])
    if np.asarray(v[names[0]]).dtype.kind == "f":
        rgb = rgb * 255.0
    return np.clip(np.nan_to_num(np.rint(rgb)), 0, 255).astype(np.uint8)


def write_ply(path: str | Path, points, faces=None, normals=None, comments=(), colours=None) -> Path:
    """Write points (N,3) [and triangles (M,3), normals (N,3), colours (N,3) uint8 RGB] as binary little-endian
    PLY, atomically."""
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must be (N, 3), got {points.shape}")
    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    if normals is not None:
        fields += [("nx", "<f8"), ("ny", "<f8"), ("nz", "<f8")]
    if colours is not None:
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    vert = np.empty(len(points), dtype=fields)
    vert["x"], vert["y"], vert["z"] = points.T
    if normals is not None:
        vert["nx"], vert["ny"], vert["nz"] = np.asarray(normals, dtype=np.float64).T
    if colours is not None:
        vert["red"], vert["green"], vert["blue"] = np.asarray(colours, dtype=np.uint8).T
    header = ["ply", "format binary_little_endian 1.0"]
    header += [f"comment {_header_text(c)}" for c in comments]
    header.append(f"element vertex {len(points)}")
    header += [f"property {'uchar' if kind == 'u1' else 'double'} {name}" for name, kind in fields]
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
        fh.write(("\n".join(header) + "\n").encode("ascii"))
        fh.write(vert.tobytes())
        fh.write(face_bytes)
    return path


def _header_text(text: str) -> str:
    """`text` as one line of printable ASCII, which a PLY header is: other characters (a newline or
    an accent in a file name) escaped as Python writes them (`\\n`, `\\xfc`, `\\udcfc`)."""
    return re.sub(r"[^\x20-\x7e]", lambda m: m.group().encode("unicode_escape", "backslashreplace").decode("ascii"),
                  text)
