"""Which code made an artefact: a digest of breastplan's own Python source.

A case folder's stages (ingest, fit) and a batch's finished plans are reused only when this very code
made them: after an upgrade, or any edit of the source, they are made again, so that one table never
mixes the figures of two versions. Standard library only.
"""
from __future__ import annotations

import hashlib
from functools import cache
from importlib.util import find_spec
from pathlib import Path

PACKAGES = ("breastplan", "breastplan.ingest", "breastplan.scenes", "breastplan.fitting", "breastplan.deform",
            "breastplan.learn", "breastplan.plan", "breastplan.batch", "breastplan.filters", "breastplan.meshlab",
            "breastplan.cli")
"""Every package of breastplan, as installed."""


def source_digest(folders: dict[str, Path]) -> str:
    """SHA-256 (hex) of the `*.py` files directly in each folder (package name → its folder), by package name and
    file name: the same for the same source wherever it lies and whatever order its files were written in."""
    digest = hashlib.sha256()
    for name in sorted(folders):
        for path in sorted(Path(folders[name]).glob("*.py"), key=lambda p: p.name):
            digest.update(f"{name}/{path.name}\0".encode())
            digest.update(path.read_bytes())
            digest.update(b"\0")
    return digest.hexdigest()


@cache
def code_digest() -> str:
    """`source_digest` of every package of this breastplan (`PACKAGES`), computed once per process."""
    return source_digest({name: Path(find_spec(name).submodule_search_locations[0]) for name in PACKAGES})
