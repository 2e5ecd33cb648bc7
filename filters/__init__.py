"""The filter registry: each stage operation a plain function with typed keyword parameters, by name.

    from breastplan.filters import Mesh, filters, get
    fit = get("compute_breast_fit")(Mesh(points_mm), side="right")

The built-in filters are also attributes of this package (`breastplan.filters.apply_breast_ptosis`);
plugins come through the entry-point group `breastplan.filters` (docs/filters.md).
"""
from .mesh import Mesh, read_mesh, write_mesh
from .registry import (GROUP, Filter, FilterError, Parameter, ParameterError, PluginWarning, UnknownFilterError,
                       filter, filters, get, load_plugins)
from .stages import (ShortOfDegree, apply_breast_ptosis, apply_breast_top_shape, apply_breast_turn,
                     compute_breast_fit, compute_breast_isolation, forget, get_breast_measures)

__all__ = [
    "GROUP", "Filter", "FilterError", "Mesh", "Parameter", "ParameterError", "PluginWarning", "ShortOfDegree",
    "UnknownFilterError", "apply_breast_ptosis", "apply_breast_top_shape", "apply_breast_turn", "compute_breast_fit",
    "compute_breast_isolation", "filter", "filters", "forget", "get", "get_breast_measures", "load_plugins",
    "read_mesh", "write_mesh",
]
