"""The geometry filters take and give: a triangle mesh or a point cloud, in millimetres.

A `Mesh` is immutable (its arrays are read-only copies), so a filter never changes its input: it
returns a new `Mesh`. `read_mesh` reads a scan file with the readers `ingest` uses; `write_mesh`
writes a PLY atomically.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from breastplan import BadInputError


@dataclass(frozen=True, eq=False)
class Mesh:
    """Vertices (N, 3) float and faces (M, 3) int, or faces None for a point cloud.

    Coordinates are in the units and frame of whoever made the mesh; the filters' outputs are in mm
    (docs/filters.md). An empty face array is taken as a point cloud. Malformed arrays (wrong shape,
    faces referring to missing vertices) raise BadInputError; NaN and empty geometry are left to the
    filters, which refuse them with a sentence saying why."""

    vertices: np.ndarray
    faces: np.ndarray | None = None

    def __post_init__(self):
        vertices = _matrix(self.vertices, np.float64, "vertices")
        faces = None if self.faces is None else _matrix(self.faces, np.int64, "faces")
        if faces is not None and len(faces) == 0:
            faces = None
        if faces is not None and (faces.min() < 0 or faces.max() >= len(vertices)):
            raise BadInputError(None, f"has faces that refer to missing vertices (it has {len(vertices)})")
        object.__setattr__(self, "vertices", vertices)
        object.__setattr__(self, "faces", faces)

    @property
    def is_point_cloud(self) -> bool:
        return self.faces is None

    def __repr__(self) -> str:
        faces = "point cloud" if self.faces is None else f"{len(self.faces)} faces"
        return f"Mesh({len(self.vertices)} vertices, {faces})"


def _matrix(values, dtype, what: str) -> np.ndarray:
    """A read-only, C-ordered (N, 3) copy of `values` as `dtype` (`ingest.files.as_rows`): a Fortran-ordered
    array (pymeshlab's) gives the very same results as its C-ordered copy."""
    from breastplan.ingest.files import as_rows

    out = np.array(as_rows(None, values, 3, dtype, what), dtype, order="C")   # one layout: one result
    out.flags.writeable = False
    return out


def read_mesh(path: str | Path) -> Mesh:
    """A scan or mesh file (PLY, OBJ, STL, PCD, XYZ, glTF/GLB) as it is, in its own units and frame, read with the
    readers of `ingest`; BadInputError naming the file for any defect."""
    from breastplan import BadInputError
    from breastplan.errors import about
    from breastplan.ingest.files import SUPPORTED, read_scan_arrays

    if Path(path).suffix.lower() == ".mcap":
        raise BadInputError(path, f"is a depthai recording; filters take a scan or mesh file ({', '.join(SUPPORTED)}), "
                                  "and `breastplan ingest` or `breastplan plan` reads recordings")
    points, faces, *_ = read_scan_arrays(path)
    with about(path):
        return Mesh(points, faces)


def write_mesh(path: str | Path, mesh: Mesh, comments=()) -> Path:
    """`mesh` as a binary PLY (points, or points and triangles), written atomically."""
    from breastplan import write_ply

    return write_ply(path, mesh.vertices, mesh.faces, comments=list(comments))
