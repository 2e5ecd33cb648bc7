"""breastplan: plan the aesthetic result of breast surgery from a 3-D scan.

The core package holds artefact I/O, units and frames, the breast primitive and errors.
Stages live in the subpackages ingest, fitting, deform, learn and cli (docs/design.md).
Importing it is light (the standard library only): the `breastplan` command imports it on every
run, so the names below that need numpy are imported on first use (PEP 562), as is `__version__`.
"""
from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from .errors import ArtefactError, BadInputError, BreastplanError, require_file

_LAZY = {  # name → the submodule that defines it (numpy-based)
    "load_npz": "artefacts", "save_npz": "artefacts",
    "transform_points": "frames",
    "Geometry": "ply", "read_ply": "ply", "write_ply": "ply",
    "PARAM_NAMES": "primitive", "Primitive": "primitive", "spow": "primitive", "uv_grid": "primitive",
    "MM_PER_MU": "units", "mu3_to_cc": "units", "to_mm": "units", "to_model_units": "units",
}

__all__ = [
    "__version__", "ArtefactError", "BadInputError", "BreastplanError", "Geometry", "MM_PER_MU",
    "PARAM_NAMES", "Primitive", "load_npz", "mu3_to_cc", "read_ply", "require_file", "save_npz", "spow",
    "to_mm", "to_model_units", "transform_points", "uv_grid", "write_ply",
]

if TYPE_CHECKING:
    from .artefacts import load_npz, save_npz
    from .frames import transform_points
    from .ply import Geometry, read_ply, write_ply
    from .primitive import PARAM_NAMES, Primitive, spow, uv_grid
    from .units import MM_PER_MU, mu3_to_cc, to_mm, to_model_units

    __version__: str


def __getattr__(name: str):
    """The numpy-based names, from their submodule on first use; `__version__` from the installed
    metadata (importlib.metadata alone takes tens of milliseconds to import)."""
    if name == "__version__":
        from importlib.metadata import PackageNotFoundError, version

        try:
            value = version("breastplan")
        except PackageNotFoundError:  # running from a source tree that is not installed
            value = "0+unknown"
    elif name in _LAZY:
        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
