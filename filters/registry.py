"""The filter registry: stage operations as plain functions with typed keyword parameters, by name.

A filter is a function whose first positional parameter is the input geometry (a `Mesh`) and whose
other parameters are keyword-only, each annotated int, float, str, bool or `Literal[...]` (its
choices) and given a default; it returns a new `Mesh` (never changing its input) or a dict of
measures. `@filter("name")` registers one: its description is its docstring's first line, its
parameters come from its signature, and the `Filter` object it returns is called as the function
was, its parameters checked and converted first.

Third-party filters come through the entry-point group `breastplan.filters`: an entry point names a
decorated function, a plain function (registered under the entry point's name) or a module whose
import registers filters. Plugins are loaded on the first look-up, once; one that fails to load is
left out with a `PluginWarning` naming it and its error (docs/filters.md).
"""
from __future__ import annotations

import difflib
import functools
import importlib
import inspect
import keyword
import math
import numbers
import threading
import types
import typing
import warnings
from dataclasses import dataclass
from typing import Any, Callable, Literal, Mapping

import numpy as np

from breastplan.errors import BadInputError, BreastplanError

from .mesh import Mesh

GROUP = "breastplan.filters"
"""The entry-point group of third-party filters."""
BUILTIN = "breastplan"
"""The source of the built-in filters."""
BUILTINS_MODULE = "breastplan.filters.stages"
TYPES = (int, float, str, bool)
"""The types a filter's parameters may have (or choices of one of them, `Literal[...]`)."""
_TRUE, _FALSE = ("true", "yes", "on", "1"), ("false", "no", "off", "0")


BRIDGE_NAMES = frozenset({"run"})
"""The names of `breastplan.meshlab`'s own functions, which no filter may take (its filters are its attributes)."""


class FilterError(ValueError):
    """A filter asked for that does not exist, or parameters it does not take."""


class UnknownFilterError(FilterError):
    """No filter of that name is registered."""


class ParameterError(FilterError):
    """A parameter a filter does not take, or a value it cannot take; `parameter` names it."""

    def __init__(self, parameter: str, message: str):
        super().__init__(message)
        self.parameter = parameter


class PluginWarning(UserWarning):
    """A plugin that could not be loaded, or a filter of one that was left out."""


@dataclass(frozen=True)
class Parameter:
    """A filter's keyword parameter: its name, type (int, float, str or bool), default and, for a
    `Literal[...]` annotation, its choices."""

    name: str
    type: type
    default: Any
    choices: tuple | None = None

    def convert(self, value: Any) -> Any:
        """`value` (of the type, or a string as a command line gives it) as the parameter's type;
        ParameterError, one sentence, if it is not one."""
        converted = _CONVERT[self.type](value)
        if converted is None:
            what = {int: "a whole number", float: "a finite number", str: "a string", bool: "true or false"}[self.type]
            raise ParameterError(self.name, f"{self.name}={value!r} is not {what}")
        if self.choices is not None and converted not in self.choices:
            raise ParameterError(self.name, f"{self.name}={value!r} is not one of {', '.join(map(str, self.choices))}")
        return converted

    def as_dict(self) -> dict:
        return {"name": self.name, "type": self.type.__name__, "default": self.default,
                "choices": None if self.choices is None else list(self.choices)}

    def __str__(self) -> str:
        kind = "|".join(map(str, self.choices)) if self.choices is not None else self.type.__name__
        return f"{self.name}: {kind} = {self.default}"


def _to_int(value):
    if isinstance(value, bool):
        return None
    if isinstance(value, str):
        try:
            return int(value.strip())
        except ValueError:
            return None
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, numbers.Real) and float(value).is_integer():
        return int(value)
    return None


def _to_float(value):
    if isinstance(value, bool):
        return None
    try:
        out = float(value.strip()) if isinstance(value, str) else float(value)
    except (TypeError, ValueError):
        return None
    return out if math.isfinite(out) else None


def _to_bool(value):
    if isinstance(value, bool) or type(value).__name__ == "bool_":      # numpy's bool too
        return bool(value)
    if isinstance(value, str) and value.strip().lower() in _TRUE + _FALSE:
        return value.strip().lower() in _TRUE
    return None


_CONVERT = {int: _to_int, float: _to_float, str: lambda v: v if isinstance(v, str) else None, bool: _to_bool}


class Filter:
    """A registered filter: call it as its function, `filter(geometry, **parameters)`.

    `name`, `description` (its docstring's first line), `parameters` (from its signature), `source`
    (`breastplan` for the built-ins, else the plugin that brought it) and `function` (the function)."""

    def __init__(self, name: str, function: Callable, source: str = BUILTIN,
                 check: Callable[[dict], None] | None = None):
        if not isinstance(name, str) or not name.isidentifier() or keyword.iskeyword(name):
            raise ValueError(f"a filter's name is a Python identifier (letters, digits, _), not {name!r}")
        if name in BRIDGE_NAMES:
            raise ValueError(f"a filter cannot be named {name!r}: breastplan.meshlab keeps that name for itself")
        self.name = name
        self.function = function
        self.source = source
        self.check = check
        self.parameters = _parameters(name, function)
        self.returns = _returns(function)
        doc = inspect.getdoc(function) or ""
        self.description = next((line.strip() for line in doc.splitlines() if line.strip()), "")
        functools.update_wrapper(self, function)

    def parameter(self, name: str) -> Parameter:
        """The parameter `name`; ParameterError (naming close names) if the filter has none of that name."""
        for p in self.parameters:
            if p.name == name:
                return p
        names = [p.name for p in self.parameters]
        close = difflib.get_close_matches(name, names, n=3, cutoff=0.6)
        hint = f"; did you mean {_either(close)}?" if close else \
            f"; it takes {', '.join(names)}" if names else "; it takes none"
        raise ParameterError(name, f"filter {self.name} has no parameter '{name}'{hint}")

    def bind(self, values: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """Every parameter's value: those given (converted, e.g. from strings) and the others' defaults,
        checked together by the filter's `check` if it has one (ParameterError)."""
        values = dict(values or {})
        for name in values:
            self.parameter(name)
        bound = {p.name: p.convert(values[p.name]) if p.name in values else p.default for p in self.parameters}
        if self.check is not None:
            self.check(bound)
        return bound

    def __call__(self, geometry, /, **parameters):
        """Run the filter on `geometry` (a Mesh, or (N, 3) points); a new Mesh or a dict. A plugin's filter
        that fails, or returns anything else than it declares or a mesh with NaN or infinite vertices, raises
        BadInputError saying so (a built-in's failure is a bug, and raises as it is)."""
        mesh = geometry if isinstance(geometry, Mesh) else Mesh(geometry)
        bound = self.bind(parameters)
        try:
            result = self.function(mesh, **bound)
        except (BreastplanError, ParameterError):
            raise
        except Exception as exc:
            if self.source == BUILTIN:
                raise
            raise BadInputError(None, f"{self._who()} failed ({type(exc).__name__}: {exc})") from None
        wanted = {"mesh": Mesh, "measures": dict}.get(self.returns, (Mesh, dict))
        if not isinstance(result, wanted):
            raise BadInputError(None, f"{self._who()} returned {type(result).__name__}, not the "
                                      f"{'Mesh or dict' if isinstance(wanted, tuple) else wanted.__name__} it declares")
        if isinstance(result, Mesh) and not np.isfinite(result.vertices).all():
            raise BadInputError(None, f"{self._who()} returned a mesh with NaN or infinite vertices")
        return result

    def _who(self) -> str:
        return f"filter {self.name}" + ("" if self.source == BUILTIN else f" (from {self.source})")

    def as_dict(self) -> dict:
        return {"name": self.name, "description": self.description, "source": self.source,
                "returns": self.returns, "parameters": [p.as_dict() for p in self.parameters]}

    def __repr__(self) -> str:
        params = "".join(f", {p}" for p in self.parameters)
        return f"<Filter {self.name}(geometry, *{params}) from {self.source}>"


def _returns(function: Callable) -> str | None:
    """"mesh" or "measures" by a function's return annotation (Mesh or dict), else None."""
    try:
        hint = typing.get_type_hints(function).get("return")
    except (TypeError, ValueError, NameError):
        return None
    hint = typing.get_origin(hint) or hint
    return "mesh" if hint is Mesh else "measures" if hint is dict else None


def _either(names: list[str]) -> str:
    """'a', 'a or b', 'a, b or c'."""
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} or {names[-1]}"


def _parameters(name: str, function: Callable) -> tuple[Parameter, ...]:
    """The keyword parameters of a filter function, from its signature; TypeError for a function that
    is no filter."""
    if not callable(function):
        raise TypeError(f"filter {name} is a {type(function).__name__}, not a function")
    try:
        params = list(inspect.signature(function).parameters.values())
        hints = typing.get_type_hints(function)
    except (TypeError, ValueError, NameError) as exc:
        raise TypeError(f"filter {name}: its signature cannot be read ({exc})") from None
    positional = (inspect.Parameter.POSITIONAL_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)
    if not params or params[0].kind not in positional:
        raise TypeError(f"filter {name} must take the input geometry as its first positional parameter")
    out = []
    for p in params[1:]:
        if p.kind is not inspect.Parameter.KEYWORD_ONLY:
            raise TypeError(f"filter {name}: parameter '{p.name}' must be keyword-only (after a bare *)")
        kind, choices = _annotation(name, p.name, hints.get(p.name, inspect.Parameter.empty))
        if p.default is inspect.Parameter.empty:
            raise TypeError(f"filter {name}: parameter '{p.name}' needs a default")
        param = Parameter(p.name, kind, None, choices)
        try:
            default = param.convert(p.default)
        except ParameterError:
            raise TypeError(f"filter {name}: the default of '{p.name}', {p.default!r}, is not of its type") from None
        out.append(Parameter(p.name, kind, default, choices))
    return tuple(out)


def _annotation(name: str, param: str, hint) -> tuple[type, tuple | None]:
    """(type, choices) of an annotation: int, float, str or bool, or Literal choices all of one of them."""
    if hint in TYPES:
        return hint, None
    if typing.get_origin(hint) is Literal:
        choices = typing.get_args(hint)
        kinds = {type(c) for c in choices}
        if choices and len(kinds) == 1 and kinds <= set(TYPES):
            return kinds.pop(), tuple(choices)
    shown = "none" if hint is inspect.Parameter.empty else getattr(hint, "__name__", None) or repr(hint)
    raise TypeError(f"filter {name}: parameter '{param}' is annotated {shown}; a filter's parameters are "
                    f"int, float, str, bool or Literal[...] choices of one of them")


# --- the registry --------------------------------------------------------------------------------

_REGISTRY: dict[str, Filter] = {}
_LOCK = threading.RLock()
_plugins_loaded = False
_loading: str | None = None
"""The plugin being imported: the source of the filters its import registers."""


def filter(name: str | Callable | None = None, *, check: Callable[[dict], None] | None = None):  # noqa: A001
    """Register the decorated function as the filter `name` (default: the function's name); returns
    its `Filter`. Usable as `@filter("name")`, `@filter()` or `@filter`. `check`, if given, is called
    with every parameter's value before the filter runs and raises ParameterError for values that
    are of the right type but that the filter does not take (a number out of range)."""
    if callable(name):
        return filter()(name)

    def register(function: Callable) -> Filter:
        module = getattr(function, "__module__", "") or ""
        source = _loading or (BUILTIN if module.startswith("breastplan.") else f"module {module}")
        return _add(Filter(name or function.__name__, function, source, check))

    return register


def _add(new: Filter) -> Filter:
    """Register `new` unless another function holds its name (then a PluginWarning); returns `new`."""
    with _LOCK:
        old = _REGISTRY.get(new.name)
        if old is not None and _origin(old.function) != _origin(new.function):
            warnings.warn(f"filter {new.name} of {new.source} is left out: {old.source} registered a filter of "
                          f"that name first", PluginWarning, stacklevel=3)
            return new
        _REGISTRY[new.name] = new
        return new


def _origin(function: Callable) -> tuple[str, str]:
    return getattr(function, "__module__", ""), getattr(function, "__qualname__", repr(function))


def filters(plugins: bool = True) -> list[Filter]:
    """Every registered filter, by name: the built-ins and (unless `plugins` is False) the plugins'."""
    _load_builtins()
    if plugins:
        load_plugins()
    with _LOCK:
        found = sorted(_REGISTRY.values(), key=lambda f: f.name)
    return [f for f in found if plugins or f.source == BUILTIN]


def get(name: str) -> Filter:
    """The filter `name`; UnknownFilterError naming the close names if there is none."""
    _load_builtins()
    with _LOCK:
        found = _REGISTRY.get(name)
    if found is None:
        load_plugins()
        with _LOCK:
            found = _REGISTRY.get(name)
            names = sorted(_REGISTRY)
    if found is None:
        close = difflib.get_close_matches(str(name), names, n=3, cutoff=0.5)
        hint = f"did you mean {_either(close)}?" if close else f"the filters are {', '.join(names)}"
        raise UnknownFilterError(f"there is no filter '{name}'; {hint}")
    return found


def _load_builtins() -> None:
    importlib.import_module(BUILTINS_MODULE)


def load_plugins() -> None:
    """Load the entry points of group `breastplan.filters`, once (later calls return at once)."""
    global _plugins_loaded
    with _LOCK:
        if _plugins_loaded:
            return
        _plugins_loaded = True
        from importlib.metadata import entry_points

        for ep in sorted(entry_points(group=GROUP), key=lambda e: (e.name, e.value)):
            _load_plugin(ep)


def _load_plugin(ep) -> None:
    """Register what one entry point brings; a PluginWarning, never an exception, if it cannot."""
    global _loading
    dist = getattr(ep, "dist", None)
    label = f"plugin {ep.name} ({dist.name} {dist.version})" if dist is not None else f"plugin {ep.name}"
    before = {f.name for f in _REGISTRY.values() if f.source == label}
    previous, _loading = _loading, label
    try:
        loaded = ep.load()
    except (Exception, SystemExit) as exc:
        warnings.warn(f"the filter {label}, {ep.value}, failed to load and is left out: {type(exc).__name__}: "
                      f"{str(exc).strip() or 'no message'}", PluginWarning, stacklevel=4)
        return
    finally:
        _loading = previous
    if isinstance(loaded, Filter):
        return
    if isinstance(loaded, types.ModuleType):
        if not {f.name for f in _REGISTRY.values() if f.source == label} - before:
            warnings.warn(f"the filter {label}: importing module {loaded.__name__} registered no filter",
                          PluginWarning, stacklevel=4)
        return
    try:
        _add(Filter(ep.name, loaded, label))
    except (TypeError, ValueError) as exc:
        warnings.warn(f"the filter {label}, {ep.value}, is left out: {exc}", PluginWarning, stacklevel=4)
