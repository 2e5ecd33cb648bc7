"""breastplan's filters on a pymeshlab MeshSet, pymeshlab-style.

    import pymeshlab
    from breastplan import meshlab

    ms = pymeshlab.MeshSet()
    ms.load_new_mesh("scan.ply")
    meshlab.compute_breast_fit(ms, side="right")   # the fitted surface: a new mesh, now the current one
    measures = meshlab.get_breast_measures(ms)     # a dict
    meshlab.apply_breast_ptosis(ms, degree=5)      # the deformed surface: another new mesh

Every registered filter is a function of this module taking the MeshSet and the filter's keyword
parameters: it runs the filter on the MeshSet's current mesh (a mesh without faces is a point
cloud), adds a Mesh result to the MeshSet as a new mesh named after the filter, which becomes the
current one (as pymeshlab's own filters do; None is returned), and returns a dict result. The
built-in filters are attributes of the module from its import; a plugin's filters appear on first
use (`__getattr__`, `__dir__`). pymeshlab is imported when a filter runs.
"""
import inspect as _inspect
from typing import Literal as _Literal

from breastplan.errors import about as _about
from breastplan.filters import Filter as _Filter
from breastplan.filters import Mesh as _Mesh
from breastplan.filters import UnknownFilterError as _UnknownFilterError
from breastplan.filters import filters as _filters
from breastplan.filters import get as _get


def run(ms, name: str, /, **parameters) -> dict | None:
    """Run the filter `name` on `ms` (a pymeshlab.MeshSet) as the function of that name does."""
    return _run(_get(name), ms, parameters)


def _run(chosen: _Filter, ms, parameters: dict) -> dict | None:
    import numpy as np
    import pymeshlab

    if not isinstance(ms, pymeshlab.MeshSet):
        raise TypeError(f"{chosen.name} takes a pymeshlab.MeshSet, not a {type(ms).__name__}")
    bound = chosen.bind(parameters)                   # a bad parameter is refused before any work
    if ms.mesh_number() == 0:
        from breastplan import BadInputError

        raise BadInputError(None, "the MeshSet holds no mesh to run a filter on")
    current = ms.current_mesh()
    faces = current.face_matrix()
    with _about(f"mesh '{current.label()}'"):
        result = chosen(_Mesh(current.vertex_matrix(), faces if len(faces) else None), **bound)
    if isinstance(result, _Mesh):
        arrays = {"vertex_matrix": np.ascontiguousarray(result.vertices, dtype=np.float64)}
        if result.faces is not None:
            arrays["face_matrix"] = np.ascontiguousarray(result.faces, dtype=np.int32)
        ms.add_mesh(pymeshlab.Mesh(**arrays), mesh_name=chosen.name, set_as_current=True)
        return None
    return result


def _bridge(chosen: _Filter):
    """The MeshSet function of one filter, with its signature and documentation."""
    def function(ms, /, **parameters):
        return _run(chosen, ms, parameters)

    function.__name__ = function.__qualname__ = chosen.name
    function.__module__ = __name__
    gives = {"mesh": "adds its mesh to the MeshSet (the new current mesh) and returns None",
             "measures": "returns its measures, a dict"}.get(chosen.returns, "adds a mesh result to the MeshSet, "
                                                                            "returns a dict result")
    rest = (_inspect.getdoc(chosen.function) or "").strip().partition("\n")[2].strip()
    function.__doc__ = (f"{chosen.description}\n\nbreastplan filter {chosen.name} on the MeshSet's current mesh: "
                        f"{gives}.\n\n{rest}").strip()
    params = [_inspect.Parameter("ms", _inspect.Parameter.POSITIONAL_ONLY)]
    params += [_inspect.Parameter(p.name, _inspect.Parameter.KEYWORD_ONLY, default=p.default,
                                 annotation=p.type if p.choices is None else _Literal[p.choices])
               for p in chosen.parameters]
    function.__signature__ = _inspect.Signature(params, return_annotation=dict if chosen.returns == "measures"
                                               else None if chosen.returns == "mesh" else _inspect.Signature.empty)
    function.filter = chosen
    return function


for _builtin in _filters(plugins=False):
    globals()[_builtin.name] = _bridge(_builtin)
del _builtin


def __getattr__(name: str):
    """A plugin's filter, as a MeshSet function (loading the plugins on first use)."""
    if name.startswith("__"):
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    try:
        found = _get(name)
    except _UnknownFilterError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r} (no filter of that name)") from None
    bridged = globals()[name] = _bridge(found)
    return bridged


def __dir__() -> list[str]:
    return sorted({n for n in globals() if not n.startswith("_")} | {f.name for f in _filters()})
