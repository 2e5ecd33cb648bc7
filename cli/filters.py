"""The `filters` and `filter` commands: the registered filters listed, and one run on a scan or mesh file."""
from __future__ import annotations

import contextlib
from pathlib import Path
from typing import Iterator, List, Optional

import typer

from breastplan.clock import Clock
from breastplan.errors import about

from .app import JSON, command
from .output import apart, report, stderr, stdout, usage_error, writable


NARROW = 60
"""Below this many columns the filters are listed one block each, not as a table."""


@command("filters")
def list_filters(as_json: bool = JSON):
    """List the filters, built-in and from plugins, with their typed parameters and defaults."""
    clock = Clock()
    with plugin_warnings():
        from breastplan.filters import filters

        found = filters()
    if as_json:
        report({"filters": [f.as_dict() for f in found], "seconds": clock.seconds}, True, "")
        return
    from rich.markup import escape
    from rich.table import Table

    def about_filter(f) -> str:
        origin = "" if f.source == "breastplan" else f"\n[dim]from {escape(f.source)}[/dim]"
        return f"[bold]{f.name}[/bold]\n{escape(f.description)}{origin}"

    if stdout.width < NARROW:   # a table would drop a column: one block per filter
        stdout.print(f"{len(found)} filters")
        for f in found:
            params = "".join(f"\n  {escape(str(p))}" for p in f.parameters)
            stdout.print(f"\n{about_filter(f)}{params}", soft_wrap=True)
        return
    table = Table(title=f"{len(found)} filters", title_justify="left", show_lines=True)
    table.add_column("filter", ratio=1)
    table.add_column("parameters", no_wrap=True)
    for f in found:
        table.add_row(about_filter(f), escape("\n".join(str(p) for p in f.parameters)) or "—")
    stdout.print(table)


@command("filter")
def run_filter(
    name: str = typer.Argument(..., help="The filter to run (`breastplan filters` lists them)."),
    input: Path = typer.Argument(..., help="A scan or mesh file: PLY, OBJ, STL, PCD, XYZ or glTF/GLB."),
    param: List[str] = typer.Option([], "--param", help="NAME=VALUE: a parameter of the filter (repeatable)."),
    out: Optional[Path] = typer.Option(None, "--out", help="Output PLY of a filter that gives a mesh (mm, the "
                                       "input's frame); written atomically."),
    as_json: bool = JSON,
):
    """Run one filter on a scan or mesh file: a mesh result is written to --out, measures are printed."""
    clock = Clock()
    with plugin_warnings():
        from breastplan.filters import FilterError, get

        try:
            chosen = get(name)
        except FilterError as exc:
            raise usage_error(str(exc), "NAME") from None
    values = {}
    for item in param:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise usage_error(f"'{item}' is not NAME=VALUE", "--param")
        if key.strip() in values:
            raise usage_error(f"{key.strip()} is given twice", "--param")
        values[key.strip()] = value.strip()
    try:
        bound = chosen.bind(values)
    except FilterError as exc:
        raise usage_error(str(exc), "--param") from None
    if chosen.returns == "mesh" and out is None:
        raise usage_error(f"filter {name} gives a mesh: name its output PLY", "--out")
    if chosen.returns == "measures" and out is not None:
        raise usage_error(f"filter {name} gives measures, which are printed, not a mesh", "--out")
    if out is not None:
        if out.suffix.lower() != ".ply":
            raise usage_error(f"'{out}' does not end in .ply; a filter writes its mesh as a PLY", "--out")
        apart(writable(out), input)

    from breastplan.filters import Mesh, ParameterError, read_mesh, write_mesh

    mesh = read_mesh(input)                      # bad files are refused naming themselves
    with about(input):
        try:
            result = chosen(mesh, **bound)
        except ParameterError as exc:            # a value the filter refuses only when it runs (a degree)
            raise usage_error(str(exc), "--param") from None
    head = {"filter": name, "input": str(input), "params": bound}
    if isinstance(result, Mesh):
        if out is None:
            raise usage_error(f"filter {name} gave a mesh: name its output PLY", "--out")
        write_mesh(out, result, comments=[f"breastplan filter {name}: {chosen.description}",
                                          "mm, the input's frame",
                                          "params " + " ".join(f"{k}={v}" for k, v in bound.items())])
        faces = 0 if result.faces is None else len(result.faces)
        report({**head, "output": str(out), "vertices": len(result.vertices), "faces": faces,
                "seconds": clock.seconds}, as_json, f"{name} → {out}")
    elif as_json:
        report({**head, "result": result, "seconds": clock.seconds}, True, "")
    else:
        report({"filter": name, "input": str(input), **result, "seconds": clock.seconds}, False, f"{name}: {input}")


@contextlib.contextmanager
def plugin_warnings() -> Iterator[None]:
    """Warnings raised inside (a plugin that failed to load) as `warning: …` lines on stderr."""
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield
    for w in caught:
        stderr.print(f"warning: {w.message}", markup=False, soft_wrap=True)
