"""Scan files (PLY, OBJ, STL, PCD, XYZ, glTF/GLB) → a point cloud in millimetres, in the file's own frame.

Meshes are sampled uniformly by area (about 1 point per mm², seeded, so reads are
deterministic) with the triangle normals; point files keep their points and normals. Colour is kept:
a PLY's or PCD's per-point colour, an OBJ's or glTF's vertex colours, the texture image an OBJ's material
names (OBJ + MTL + image, as clinics' scanners export) or a glTF's one embedded texture (phone scanning
apps), read at each vertex; an STL holds none. Units
are detected from the extent (largest side of the axis-aligned bounding box) or declared.
Every defect raises BadInputError naming the file: open3d reports corrupt or foreign files
only as console warnings and hands back an empty geometry, so this module checks for that.
What no body scan holds is refused before a reader loads it: each file's header (STL, PCD, glTF) or
its lines, scanned in chunks (OBJ, XYZ), are checked against MAX_POINTS and the file's size.
open3d is imported when a reader needs it.
"""
from __future__ import annotations

import base64
import binascii
import json
import os
import re
import struct
import tempfile
import warnings
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, NamedTuple

import numpy as np

from breastplan import BadInputError, read_ply, require_file
from breastplan.point_order import canonical_faces
from breastplan.errors import counted
from breastplan.case import CAMERA_FRAME
from breastplan.ply import MAX_ELEMENTS as MAX_POINTS, FaceLayoutError, faces_problem
from breastplan.units import FAR_EXTENT_MM as FAR_EXTENT
from breastplan.units import SCAN_EXTENT_MM
from breastplan.units import extent as extent_of

from .crash_probe import crash_of

SUPPORTED = (".ply", ".obj", ".stl", ".pcd", ".xyz", ".glb", ".gltf")
POINTS_PER_MM2 = 1.0
SAMPLE_RANGE = (20_000, 400_000)
"""Bounds on the number of points sampled from a mesh surface."""
SAMPLE_SEED = 0
METRE_EXTENT = (0.05, SCAN_EXTENT_MM / 1000.0)
MM_EXTENT = (50.0, SCAN_EXTENT_MM)
"""Plausible extents of a scan in metres and in millimetres: from a breast alone to a patient with
the room around her."""
MIN_CLOUD_POINTS = 500
"""A point cloud with fewer points cannot hold a breast (ingest keeps at least as many of one)."""
GLTF_TEXT_BYTES = 1 << 28
"""The largest .gltf text read whole (its JSON is parsed at once): a scan of some 3 M vertices with normals and
colours, embedded in base64; a larger one comes as GLB, whose binary chunk is not parsed as text."""
_CHUNK = 1 << 24
_MAX_LINE = 1 << 16
"""Bytes scanned at a time, and the longest line a text scan file may hold."""
_MAGIC = {b"\x89PNG": "a PNG image", b"\xff\xd8\xff": "a JPEG image", b"\x89MCAP": "an MCAP recording",
          b"PK\x03\x04": "a ZIP or NPZ archive", b"\x93NUMPY": "a NumPy array", b"ply": "a PLY file",
          b"%PDF": "a PDF document"}


@dataclass(frozen=True, eq=False)
class ScanCloud:
    """A scan as points (N, 3) in mm, in the file's own frame, with optional unit normals (N, 3) and colours
    ((N, 3) uint8 RGB)."""

    points: np.ndarray
    normals: np.ndarray | None
    frame_hint: str | None
    """"camera-opencv" if a PLY comment says "frame camera-opencv", else None."""
    description: str
    colours: np.ndarray | None = None


class ScanArrays(NamedTuple):
    """A scan file's own arrays, in its units."""

    points: np.ndarray                  # (N, 3)
    faces: np.ndarray | None            # (M, 3) triangles; None: a point cloud
    normals: np.ndarray | None          # (N, 3)
    comments: list                      # its header comments (PLY)
    colours: np.ndarray | None = None   # (N, 3) uint8 RGB of its points (vertices)
    note: str = ""                      # what of the file was not used, for the scan's description: ", …"


def read_scan_file(path: str | Path, units: str = "auto") -> ScanCloud:
    """Read a PLY/OBJ/STL/PCD/XYZ/glTF/GLB scan as mm points; units "auto" (from the extent), "mm" or "m"."""
    path = Path(path)
    if units not in ("auto", "mm", "m"):
        raise BadInputError(None, f"units must be auto, mm or m, not '{units}'")
    a = read_scan_arrays(path)
    return scan_cloud(a.points, a.faces, a.normals, units, comments=a.comments, path=path, colours=a.colours,
                      note=a.note)


def read_scan_arrays(path: str | Path) -> ScanArrays:
    """A scan file's own arrays (`ScanArrays`); BadInputError naming the file for any defect."""
    path = Path(path)
    _check_file(path)
    return _READERS[path.suffix.lower()](path)


def scan_cloud(points, faces=None, normals=None, units: str = "auto", *, name: str = "mesh",
               comments=(), path: str | Path | None = None, colours=None, note: str = "") -> ScanCloud:
    """A scan's arrays (file units) → a `ScanCloud` in mm, as `read_scan_file` makes it from a file.

    points (N, 3); faces (M, 3) triangles or None (a point cloud; its normals (N, 3) kept, if any);
    a triangle mesh is sampled uniformly by area, its vertices' colours (N, 3) uint8, if any, interpolated.
    `path` is named in the errors (None: none is named) and its file name in the description, else `name`;
    `note` (", …") is added to the description."""
    path = None if path is None else Path(path)
    if units not in ("auto", "mm", "m"):
        raise BadInputError(None, f"units must be auto, mm or m, not '{units}'")
    points = as_rows(path, points, 3, np.float64, "points")
    faces = None if faces is None else as_rows(path, faces, 3, np.int64, "faces")
    normals = None if normals is None else as_rows(path, normals, 3, np.float64, "normals")
    _check_points(path, points)
    if faces is None and len(points) < MIN_CLOUD_POINTS:
        raise BadInputError(path, f"has only {counted(len(points), 'point')}; a point cloud of a body needs at least "
                                  f"{MIN_CLOUD_POINTS}")
    if faces is not None and len(faces) and (faces.min() < 0 or faces.max() >= len(points)):
        raise BadInputError(path, f"has faces that refer to missing vertices (it has {counted(len(points), 'point')})")
    if normals is not None and len(normals) != len(points):
        raise BadInputError(path, f"has {len(normals)} normals for {counted(len(points), 'point')}")
    if colours is not None and len(colours) != len(points):
        raise BadInputError(path, f"has {len(colours)} colours for {counted(len(points), 'point')}")
    extent = extent_of(points)
    mm_per_unit, units_text = _mm_per_unit(path, extent, units)
    points = points * mm_per_unit
    if faces is not None:
        n_faces = len(faces)
        points, normals, colours = _sample_surface(path, points, faces, colours)
        what = f"triangle mesh, {counted(n_faces, 'face')}, sampled to {counted(len(points), 'point')}"
    else:
        normals = _unit_normals(path, normals)
        with_normals = " with normals" if normals is not None else ""
        what = f"point cloud, {counted(len(points), 'point')}{with_normals}"
    hint = "camera-opencv" if any(CAMERA_FRAME in c for c in comments) else None
    coloured = ", in colour" if colours is not None else ""
    return ScanCloud(points=_frozen(points), normals=None if normals is None else _frozen(normals),
                     frame_hint=hint, colours=None if colours is None else np.asarray(colours, np.uint8),
                     description=f"{path.name if path is not None else name}: {what}{coloured}{note}, {units_text}")


def as_rows(path: Path | None, values, columns: int, dtype, what: str) -> np.ndarray:
    """`values` as an (N, columns) array of `dtype`; BadInputError (naming `path`, if any) for another
    shape, for values that are not numbers, or for `what` that are not whole when `dtype` is."""
    try:
        a = np.asarray(values)
    except ValueError:                            # rows of unequal length
        raise BadInputError(path, f"has {what} in rows of unequal length, not (N, {columns})") from None
    except TypeError as exc:
        raise BadInputError(path, f"has {what} that are no array of numbers ({exc})") from None
    if a.size == 0:
        a = a.reshape(0, columns)
    if a.size and (a.dtype == bool or not np.issubdtype(a.dtype, np.number) or np.iscomplexobj(a)):
        raise BadInputError(path, f"has {what} of type {a.dtype}, not real numbers")
    if a.ndim != 2 or a.shape[1] != columns:
        raise BadInputError(path, f"has {what} of shape {a.shape}, not (N, {columns})")
    if np.issubdtype(dtype, np.integer) and a.size and not np.issubdtype(a.dtype, np.integer):
        if not np.isfinite(a).all() or not np.array_equal(a, np.round(a)):
            raise BadInputError(path, f"has {what} that are not whole vertex indices")
    return a.astype(dtype, copy=False)


def _check_file(path: Path) -> None:
    """Raise BadInputError unless path is a readable, non-empty file of a supported type."""
    if path.suffix.lower() not in SUPPORTED and path.is_file():
        kind = f"has the extension '{path.suffix}'" if path.suffix else "has no file extension"
        raise BadInputError(path, f"{kind}; supported scan files are {', '.join(SUPPORTED)} (depthai recordings: "
                                  f".mcap)")
    require_file(path, "scan file")


def _check_points(path: Path | None, points: np.ndarray) -> None:
    """Raise BadInputError for NaN/Inf coordinates or fewer than 3 points."""
    bad = int((~np.isfinite(points).all(axis=1)).sum())
    if bad:
        raise BadInputError(path, f"has {counted(bad, 'point')} with NaN or infinite coordinates")
    if len(points) < 3:
        raise BadInputError(path, f"has only {counted(len(points), 'point')}; a scan needs at least 3")


def _mm_per_unit(path: Path | None, extent: float, units: str) -> tuple[float, str]:
    """Millimetres per file unit and a phrase saying how the units were chosen."""
    e = np.format_float_positional(extent, precision=3, fractional=False, trim="-") if extent < 1e6 else f"{extent:.3g}"
    if extent == 0.0:
        raise BadInputError(path, "has all its points at one place: no surface")
    if units != "auto" and extent > MM_EXTENT[1]:       # more than a body in either unit
        raise BadInputError(path, f"has an extent of {extent:.3g} {units}, more than any body scan spans "
                                  f"(a point lies far from the others?)")
    if extent > FAR_EXTENT:
        raise BadInputError(path, f"has an extent of {e}, more than any body scan spans in metres, millimetres or "
                                  f"micrometres (a point lies far from the others?)")
    if units == "mm" and extent <= METRE_EXTENT[1]:
        raise BadInputError(path, f"is declared mm but its extent of {e} says metres")
    if units == "m" and extent >= MM_EXTENT[0]:
        raise BadInputError(path, f"is declared m but its extent of {e} says millimetres")
    if units != "auto":
        return (1000.0 if units == "m" else 1.0), f"units {units} (declared, extent {e})"
    if METRE_EXTENT[0] <= extent <= METRE_EXTENT[1]:
        return 1000.0, f"units m (detected from extent {e})"
    if MM_EXTENT[0] <= extent <= MM_EXTENT[1]:
        return 1.0, f"units mm (detected from extent {e})"
    how = "pass --units mm or --units m" if path is not None else "give the units, mm or m"
    raise BadInputError(path, f"has an ambiguous extent of {e} (a body scan spans {METRE_EXTENT[0]:g}–"
                              f"{METRE_EXTENT[1]:g} in metres or {MM_EXTENT[0]:g}–{MM_EXTENT[1]:g} in "
                              f"millimetres); {how}")


def _sample_surface(path: Path, points_mm: np.ndarray, faces: np.ndarray, colours=None) -> tuple:
    """Sample a mesh (mm) uniformly by area, ~1 point per mm², seeded: (points, normals from the triangles,
    colours interpolated from the vertices' (N, 3) uint8, or None)."""
    faces = canonical_faces(points_mm, faces)          # the sampling is the surface's, whatever the files' order
    with _open3d() as o3d:
        mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(points_mm),
                                         o3d.utility.Vector3iVector(np.ascontiguousarray(faces, dtype=np.int32)))
        if colours is not None:
            mesh.vertex_colors = o3d.utility.Vector3dVector(np.asarray(colours, float) / 255.0)
        area = mesh.get_surface_area()
        if not area > 0:
            raise BadInputError(path, "is a mesh whose triangles have no area")
        n = int(np.clip(round(area * POINTS_PER_MM2), *SAMPLE_RANGE))
        o3d.utility.random.seed(SAMPLE_SEED)
        cloud = mesh.sample_points_uniformly(n, use_triangle_normal=True)
        sampled = _rgb8(cloud.colors) if colours is not None else None
    return np.asarray(cloud.points), np.asarray(cloud.normals), sampled


def _rgb8(colors) -> np.ndarray:
    """(N, 3) uint8 RGB of open3d's colours (0..1)."""
    return np.rint(np.asarray(colors) * 255).clip(0, 255).astype(np.uint8)


def _unit_normals(path: Path, normals: np.ndarray | None) -> np.ndarray | None:
    """Normals scaled to unit length (zero vectors stay zero); NaN/Inf normals are bad input."""
    if normals is None:
        return None
    if not np.isfinite(normals).all():
        raise BadInputError(path, "has normals with NaN or infinite components")
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=np.float64)
    a.flags.writeable = False
    return a


# --- format readers: path → ScanArrays, in the file's units ---

def _read_ply(path: Path):
    """PLY through breastplan's strict reader (ArtefactError, a BadInputError, on defects); a mesh whose
    faces it cannot read as faces of one vertex count (triangles and quads mixed, as scanners export),
    triangulated by pymeshlab, whose reader says the file's own error if it is truncated."""
    try:
        g = read_ply(path)
    except FaceLayoutError:
        polygons = _read_polygons(path)
        if polygons is None:
            raise
        return polygons
    return ScanArrays(g.points, g.faces, g.normals, g.comments, g.colours)


def _read_mesh(path: Path) -> ScanArrays:
    """OBJ/STL through open3d, with an OBJ's vertex colours or its texture's colour at each vertex (`_texture_rgb`);
    polygon OBJs, whose non-triangles open3d drops, through pymeshlab; an OBJ of indented lines (legal, but
    neither reads them) from a copy without the indentation."""
    obj = path.suffix.lower() == ".obj"
    polygons, n_vertices, n_faces, indented, materials = _check_obj(path) if obj else (_check_stl(path), 0, 0,
                                                                                        False, False)
    with _dedented(path) if indented else nullcontext(path) as readable:
        if polygons:
            read = _read_polygons(readable, materials)
            if read is None:
                raise _not_valid(path, "")
        else:
            with _open3d() as o3d:
                mesh = o3d.io.read_triangle_mesh(str(readable))
            faces = np.asarray(mesh.triangles, dtype=np.int64)
            if obj and len(faces) < n_faces:
                _check_face_references(path, n_vertices)
            colours = _rgb8(mesh.vertex_colors) if mesh.has_vertex_colors() else None
            if materials:
                colours = _texture_rgb(mesh)
            read = ScanArrays(np.asarray(mesh.vertices, dtype=np.float64), faces, None, [], colours,
                              UNREAD_TEXTURE if materials and colours is None else "")
    if len(read.faces) == 0:
        raise _not_valid(path, "or holds no triangles")
    return read


UNREAD_TEXTURE = ", its texture image not readable beside it (not used)"


def _texture_rgb(mesh) -> np.ndarray | None:
    """(V, 3) uint8: the colour of an open3d mesh's texture images at each vertex, the mean over the corners of its
    triangles of the texel each corner's coordinate falls in (coordinates outside 0..1 clamped; open3d holds an
    OBJ's image flipped, its rows running with v as OBJ's v runs up the image); None when it holds no readable
    texture. A vertex of no textured corner takes the mean colour of those of one."""
    uv, material = np.asarray(mesh.triangle_uvs), np.asarray(mesh.triangle_material_ids)
    images = [np.asarray(t) if not t.is_empty() else None for t in mesh.textures]
    vertex = np.asarray(mesh.triangles).ravel()
    if len(uv) != len(vertex) or all(im is None for im in images):
        return None
    corner = np.repeat(material, 3) if len(material) == len(vertex) // 3 else np.zeros(len(vertex), int)
    return _corner_rgb(len(mesh.vertices), vertex, uv, corner, images)


def _corner_rgb(n_vertices: int, vertex: np.ndarray, uv: np.ndarray, corner: np.ndarray,
                images: list) -> np.ndarray | None:
    """(V, 3) uint8 at each of `n_vertices`: the mean over the triangle corners on it (`vertex`, (3M,)) of the texel
    each corner's `uv` (3M, 2) falls in, of the image `corner` (3M,) indexes in `images` (arrays whose rows run
    with v; None: unreadable); None when no corner falls in a readable image."""
    total, count = np.zeros((n_vertices, 3)), np.zeros(n_vertices)
    for m in np.unique(corner):
        image = images[m] if 0 <= m < len(images) else None
        if image is None:
            continue
        rgb = _image_rgb(image)
        h, w = rgb.shape[:2]
        on = corner == m
        col = np.clip(np.floor(uv[on, 0] * w), 0, w - 1).astype(int)
        row = np.clip(np.floor(uv[on, 1] * h), 0, h - 1).astype(int)
        np.add.at(total, vertex[on], rgb[row, col])
        count += np.bincount(vertex[on], minlength=len(count))
    if not count.any():
        return None
    rgb = total / np.maximum(count, 1)[:, None]
    rgb[count == 0] = rgb[count > 0].mean(axis=0)
    return np.rint(rgb).clip(0, 255).astype(np.uint8)


def _embedded_rgb(mesh) -> np.ndarray | None:
    """(V, 3) uint8: the colour of a pymeshlab mesh's one texture held in memory (a glTF's embedded image) at each
    vertex (`_corner_rgb`; MeshLab's v runs up the image); None without exactly one texture and its coordinates."""
    from PIL import Image

    if not mesh.has_wedge_tex_coord() or mesh.texture_number() != 1:
        return None
    with tempfile.TemporaryDirectory(prefix="breastplan-texture-") as folder:
        png = Path(folder) / "texture.png"
        next(iter(mesh.textures().values())).save(str(png))
        image = np.asarray(Image.open(png))[::-1]
    vertex = mesh.face_matrix().ravel()
    return _corner_rgb(mesh.vertex_number(), vertex, mesh.wedge_tex_coord_matrix(), np.zeros(len(vertex), int),
                       [image])


def _image_rgb(image: np.ndarray) -> np.ndarray:
    """(H, W, 3) float 0..255 of an image's pixels: grey (with alpha or not) or RGB(A), 8 or 16 bits, or floats
    0..1."""
    grey = image if image.ndim == 2 else image[..., 0] if image.shape[2] < 3 else None
    rgb = np.repeat(grey[..., None], 3, axis=2) if grey is not None else image[..., :3]
    if rgb.dtype == np.uint16:
        return rgb / 257.0
    return rgb * 255.0 if rgb.dtype.kind == "f" else rgb.astype(float)


def _read_pcd(path: Path):
    """PCD through open3d, NaN points kept so that they are reported."""
    _check_pcd(path)
    with _open3d() as o3d:
        cloud = o3d.io.read_point_cloud(str(path), format="pcd")
    if len(cloud.points) == 0:
        raise _not_valid(path, "or holds no points")
    normals = np.asarray(cloud.normals, dtype=np.float64) if cloud.has_normals() else None
    colours = _rgb8(cloud.colors) if cloud.has_colors() else None
    return ScanArrays(np.asarray(cloud.points, dtype=np.float64), None, normals, [], colours)


def _read_xyz(path: Path):
    """Plain text 'x y z' or 'x y z nx ny nz' per line ('#' comments), parsed strictly by numpy."""
    lines = sum(chunk.count(b"\n") for chunk in _text_chunks(path))
    if lines > MAX_POINTS:
        raise BadInputError(path, f"holds {lines:,} lines, more points than any body scan holds ({MAX_POINTS:,})")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "input contained no data"
            table = np.loadtxt(path, dtype=np.float64, ndmin=2, encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise _not_valid(path, "(it is not text)") from None
    except ValueError as exc:
        detail = re.sub(r"'([^']{40})[^']+'", r"'\1…'", str(exc).split(";")[0].rstrip("."))  # a long word, cut
        raise _not_valid(path, f"({detail})") from None
    if table.size == 0:
        raise BadInputError(path, "holds no points")
    if table.shape[1] not in (3, 6):
        raise _not_valid(path, f"(its lines hold {table.shape[1]} numbers; expected x y z or x y z nx ny nz)")
    normals = table[:, 3:] if table.shape[1] == 6 else None
    if normals is not None and np.isfinite(normals).all():
        if not np.allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-2):
            raise BadInputError(path, "has columns 4–6 that are not unit normals; an .xyz file must hold "
                                      "x y z or x y z nx ny nz per line")
    return ScanArrays(table[:, :3], None, normals, [])


def _read_gltf(path: Path) -> ScanArrays:
    """glTF or GLB (phone scanning apps' export) through pymeshlab, all its meshes as one, with their vertex colours
    or the colour of their one embedded texture at each vertex."""
    _check_gltf(path)
    read = _read_polygons(path)
    if read is None:
        raise _not_valid(path, "")
    if len(read.faces) == 0:
        raise _not_valid(path, "or holds no triangles")
    return read


_READERS = {".ply": _read_ply, ".obj": _read_mesh, ".stl": _read_mesh, ".pcd": _read_pcd, ".xyz": _read_xyz,
            ".glb": _read_gltf, ".gltf": _read_gltf}


def _read_polygons(path: Path, materials: bool = False) -> ScanArrays | None:
    """A mesh read by pymeshlab, its quads and larger polygons triangulated, with its vertex colours, or (with
    `materials`) the colour of its texture at each vertex (MeshLab's texture-to-vertex filter), or that of the one
    texture it holds in memory (a glTF's); None if pymeshlab cannot read it. A texture that cannot be read leaves
    the mesh without colour, and its `note` says so."""
    import pymeshlab

    ms = pymeshlab.MeshSet()
    gltf = {"load_in_a_single_layer": True} if path.suffix.lower() in (".glb", ".gltf") else {}
    crash = crash_of(lambda: pymeshlab.MeshSet().load_new_mesh(str(path), **gltf))
    if crash:
        raise _not_valid(path, f"(MeshLab's reader crashes on it, {crash})")
    try:
        ms.load_new_mesh(str(path), **gltf)                   # a glTF's nodes as one mesh, each placed
    except pymeshlab.PyMeshLabException:
        return None
    colours, note = None, ""
    if materials:
        try:
            ms.compute_color_from_texture_per_vertex()
            colours = _rgb8(ms.current_mesh().vertex_color_matrix()[:, :3])
        except pymeshlab.PyMeshLabException:
            note = UNREAD_TEXTURE
    elif ms.current_mesh().has_vertex_color():
        colours = _rgb8(ms.current_mesh().vertex_color_matrix()[:, :3])
    mesh = ms.current_mesh()
    if not materials and colours is None and mesh.texture_number():
        colours = _embedded_rgb(mesh)
        note = "" if colours is not None else ", its textures (several) not used"
    return ScanArrays(mesh.vertex_matrix().astype(np.float64), mesh.face_matrix().astype(np.int64), None, [],
                      colours, note)


# --- checks before a reader loads a file: what no body scan holds, refused from headers and lines ---

def _text_chunks(path: Path) -> Iterator[bytes]:
    """A text scan file in chunks of whole lines; BadInputError if it is binary or has an endless line."""
    with path.open("rb") as fh:
        carry = b""
        while block := fh.read(_CHUNK):
            if b"\0" in block:
                raise _not_valid(path, "(it is not text)")
            data = carry + block
            cut = data.rfind(b"\n") + 1
            if len(data) - cut > _MAX_LINE:
                raise _not_valid(path, f"(it has a line longer than {_MAX_LINE:,} bytes)")
            carry = data[cut:]
            yield data[:cut]
        yield carry


def _check_obj(path: Path) -> tuple[bool, int, int, bool, bool]:
    """Refuse an OBJ that is not text or holds more vertices or faces than any body scan; whether it
    has a face ('f' line) of 4 or more vertices, its numbers of vertices and faces, whether any of
    its lines is indented, and whether it names a material library ('mtllib' line) and texture coordinates."""
    vertices = faces = 0
    polygons = indented = library = coordinates = False
    for chunk in _text_chunks(path):
        chunk = b"\n" + chunk                                          # every line starts after a newline
        inner = re.findall(rb"\n[ \t]+([vf])[ \t]", chunk)                  # OBJ lines may be indented
        indented = indented or re.search(rb"\n[ \t]+[^ \t\r\n]", chunk) is not None
        vertices += chunk.count(b"\nv ") + chunk.count(b"\nv\t") + inner.count(b"v")
        faces += chunk.count(b"\nf ") + chunk.count(b"\nf\t") + inner.count(b"f")
        polygons = polygons or re.search(rb"(?m)^[ \t]*f(?:[ \t]+[^ \t\r\n]+){4,}", chunk) is not None
        library = library or re.search(rb"\n[ \t]*mtllib[ \t]", chunk) is not None
        coordinates = coordinates or re.search(rb"\n[ \t]*vt[ \t]", chunk) is not None
        for count, what in ((vertices, "vertices"), (faces, "faces")):
            if count > MAX_POINTS:
                raise BadInputError(path, f"holds more than {MAX_POINTS:,} {what}, more than any body scan")
    problem = faces_problem(vertices, faces)
    if problem:
        raise BadInputError(path, f"holds {problem}")
    return polygons, vertices, faces, indented, library and coordinates


@contextmanager
def _dedented(path: Path) -> Iterator[Path]:
    """A temporary copy of the text file `path` with the blanks that start its lines removed."""
    with tempfile.TemporaryDirectory(prefix="breastplan-obj-") as folder:
        plain = Path(folder) / path.name
        with plain.open("wb") as fh:
            for chunk in _text_chunks(path):
                fh.write(re.sub(rb"(?m)^[ \t]+", b"", chunk))
        yield plain


def _check_face_references(path: Path, vertices: int) -> None:
    """Refuse an OBJ with a face referring to vertex 0 or beyond its `vertices` (read when a reader
    dropped faces, to say why)."""
    highest = 0
    for chunk in _text_chunks(path):
        lines = b"\n".join(re.findall(rb"(?m)^[ \t]*f([ \t][^\r\n]*)", b"\n" + chunk))
        refs = np.array(re.findall(rb"[ \t](\d+)", lines)).astype(np.int64)   # each corner's vertex
        if (refs == 0).any():
            raise BadInputError(path, "has a face that refers to vertex 0 (OBJ counts vertices from 1)")
        highest = max(highest, int(refs.max(initial=0)))
    if highest > vertices:
        raise BadInputError(path, f"has a face that refers to vertex {highest:,} of "
                                  f"{counted(vertices, 'vertex', 'vertices')}")


def _check_stl(path: Path) -> None:
    """Refuse a binary STL whose triangle count is 0, beyond any body scan or beyond the file's size,
    and an ASCII STL ('solid …', not of a binary STL's size) of more triangles than any body scan."""
    size = path.stat().st_size
    with path.open("rb") as fh:
        head = fh.read(84)
    n = int.from_bytes(head[80:84], "little") if len(head) == 84 else -1
    if head.startswith(b"solid") and size != 84 + 50 * n:
        facets = sum(chunk.count(b"endfacet") for chunk in _text_chunks(path))
        if facets > MAX_POINTS:
            raise BadInputError(path, f"holds {facets:,} triangles, more than any body scan ({MAX_POINTS:,})")
        return
    if _real_type(path):
        raise _not_valid(path, "")
    if n > MAX_POINTS:
        raise BadInputError(path, f"declares {n:,} triangles, more than any body scan holds ({MAX_POINTS:,})")
    if n == 0:
        raise BadInputError(path, "is a binary STL file with no triangles")
    if 0 < n and size < 84 + 50 * n:
        raise _not_valid(path, f"(it declares {n:,} triangles but ends before their data does)")


def _check_gltf(path: Path) -> None:
    """Refuse a glTF whose JSON (a .gltf's text, a GLB's first chunk) cannot be read, a GLB whose header does not
    match its size, a .gltf text larger than GLTF_TEXT_BYTES, and one whose meshes, as its nodes place them, hold
    more vertices than any body scan, and one whose positions (`_positions`) are not finite floats within its data."""
    size = path.stat().st_size
    with path.open("rb") as fh:
        if path.suffix.lower() == ".glb":
            head = fh.read(20).ljust(20, b"\0")
            (magic, _, length), (chunk, kind) = struct.unpack_from("<4sII", head), struct.unpack_from("<I4s", head, 12)
            if magic != b"glTF" or kind != b"JSON":
                raise _not_valid(path, "(it does not start as a binary glTF does)")
            if length != size:
                raise _not_valid(path, f"(it declares {length:,} bytes but holds {size:,})")
            if 20 + chunk > size:
                raise _not_valid(path, f"(its JSON chunk declares {chunk:,} bytes, past the file's end)")
            data = fh.read(chunk)
            binary = fh.read()[8:]                           # the BIN chunk after its length and type
        elif size > GLTF_TEXT_BYTES:
            raise BadInputError(path, f"is a glTF text of {size:,} bytes, more than any body scan's "
                                      f"({GLTF_TEXT_BYTES:,}): export it as GLB")
        else:
            data = fh.read()
    try:
        gltf = json.loads(data)
        meshes = [sum(int(gltf["accessors"][p["attributes"]["POSITION"]]["count"]) for p in m["primitives"])
                  for m in gltf.get("meshes", [])]
        placed = [n["mesh"] for n in gltf.get("nodes", []) if "mesh" in n]     # a mesh counts once per node
        vertices = sum(meshes[k] for k in placed) if placed else sum(meshes)
    except (ValueError, KeyError, IndexError, TypeError, AttributeError):   # AttributeError: JSON not an object
        raise _not_valid(path, "(its JSON is not a glTF's meshes and accessors)") from None
    if vertices > MAX_POINTS:
        raise BadInputError(path, f"holds {vertices:,} vertices, more than any body scan ({MAX_POINTS:,})")
    try:
        chunk = binary if path.suffix.lower() == ".glb" else b""
        positions = [_positions(path, gltf, chunk, p["attributes"]["POSITION"])
                     for mesh in gltf.get("meshes", []) for p in mesh["primitives"]]
    except (ValueError, KeyError, IndexError, TypeError, binascii.Error):
        raise _not_valid(path, "(its positions are not where its JSON says)") from None
    for p in positions:
        if p is not None:
            _check_points(path, p)


def _positions(path: Path, gltf: dict, chunk: bytes, accessor: int) -> np.ndarray | None:
    """(N, 3) a glTF's float positions (`accessor`), from its GLB chunk `chunk` or a buffer it holds as a data
    URI, as its reader would take them (MeshLab's drops the triangles of a NaN vertex, and reads on); None
    from a buffer in another file (read by its reader alone)."""
    acc = gltf["accessors"][accessor]
    view = gltf["bufferViews"][acc["bufferView"]] if "bufferView" in acc else None
    if view is None or acc.get("componentType") != 5126 or acc.get("type") != "VEC3":
        raise _not_valid(path, "(its positions are not three floats a vertex)")
    uri = gltf["buffers"][view.get("buffer", 0)].get("uri")
    if uri is not None and not uri.startswith("data:"):
        return None
    binary = chunk if uri is None else base64.b64decode(uri.split(",", 1)[1], validate=True)
    start, stride, count = view.get("byteOffset", 0) + acc.get("byteOffset", 0), view.get("byteStride", 12), \
        acc["count"]
    if count and (start < 0 or stride < 12 or start + (count - 1) * stride + 12 > len(binary)):
        raise _not_valid(path, "(its positions lie past its binary data)")
    return np.ndarray((count, 3), "<f4", binary, start, (stride, 4)) if count else np.zeros((0, 3))


def _check_pcd(path: Path) -> None:
    """Refuse a PCD whose header is missing, declares more points than any body scan, or more data than
    the file holds (2 bytes a number in ASCII; SIZE × COUNT bytes a point in binary)."""
    with path.open("rb") as fh:
        head = fh.read(_MAX_LINE)
    fields, offset = {}, 0
    for line in head.splitlines(keepends=True):
        offset += len(line)
        words = line.decode("latin-1").split()
        if words and not words[0].startswith("#"):
            fields[words[0].upper()] = words[1:]
        if words[:1] in (["DATA"], ["data"]):
            break
    else:
        raise _not_valid(path, "(its header has no DATA line)")
    try:
        points, data = int(fields["POINTS"][0]), fields["DATA"][0].lower()
        counts = [int(c) for c in fields.get("COUNT", ["1"] * len(fields["SIZE"]))]
        row = sum(int(size) * count for size, count in zip(fields["SIZE"], counts))
    except (KeyError, IndexError, ValueError):
        raise _not_valid(path, "(its header lacks a valid POINTS, SIZE or DATA line)") from None
    if points > MAX_POINTS:
        raise BadInputError(path, f"declares {points:,} points, more than any body scan holds ({MAX_POINTS:,})")
    need = {"ascii": 2 * points * sum(counts) - 1, "binary": points * row}.get(data, 0)
    short = path.stat().st_size - offset < need
    if data == "ascii" and not short:                       # a line a point: the last may lack its end of line
        with path.open("rb") as fh:
            fh.seek(offset)
            ends = sum(chunk.count(b"\n") for chunk in iter(lambda: fh.read(1 << 20), b""))
            fh.seek(-1, os.SEEK_END)
            short = ends + (fh.read(1) != b"\n") < points
    if short:
        raise _not_valid(path, f"(its header declares {points:,} points but the file ends before their data does)")


def _not_valid(path: Path, detail: str) -> BadInputError:
    """'is not a valid STL file …', naming the real type when its first bytes give it away."""
    fmt = path.suffix.lower().lstrip(".").upper()
    real = _real_type(path)
    if real and real != f"a {fmt} file":
        return BadInputError(path, f"is not a valid {fmt} file: it is {real}")
    return BadInputError(path, f"is not a valid {fmt} file {detail}".strip())


def _real_type(path: Path) -> str | None:
    """What a file is by its first bytes ("a PNG image"), if they give it away."""
    with path.open("rb") as fh:
        head = fh.read(16)
    return next((name for magic, name in _MAGIC.items() if head.startswith(magic)), None)


@contextmanager
def _open3d():
    """open3d, with its console warnings (its readers' only report of a bad file) silenced."""
    import open3d as o3d

    previous = o3d.utility.get_verbosity_level()
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    try:
        yield o3d
    finally:
        o3d.utility.set_verbosity_level(previous)
