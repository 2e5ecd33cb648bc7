"""breastplan: plan the aesthetic result of breast surgery from a 3-D scan.

The core package holds artefact I/O, units and frames, the breast primitive and errors.
Stages live in the subpackages ingest, fitting, deform, learn and cli (docs/design.md).
"""
from importlib.metadata import PackageNotFoundError, version as _version

try:
    __version__ = _version("breastplan")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

from .artefacts import load_npz, save_npz
from .errors import ArtefactError, BadInputError, BreastplanError, require_file
from .frames import transform_points
from .ply import Geometry, read_ply, write_ply
from .primitive import PARAM_NAMES, Primitive, spow, uv_grid
from .units import MM_PER_MU, mu3_to_cc, to_mm, to_model_units

__all__ = [
    "__version__", "ArtefactError", "BadInputError", "BreastplanError", "Geometry", "MM_PER_MU",
    "PARAM_NAMES", "Primitive", "load_npz", "mu3_to_cc", "read_ply", "require_file", "save_npz", "spow",
    "to_mm", "to_model_units", "transform_points", "uv_grid", "write_ply",
]
