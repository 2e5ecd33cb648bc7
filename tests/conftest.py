"""Shared fixtures: the databases are pure functions of their seed, so build them once."""
import sys
from pathlib import Path

import pytest

from breastplan.learn.databases import build_database


@pytest.fixture(scope="session")
def db_v():
    return build_database("V", seed=0)


@pytest.fixture(scope="session")
def db_s():
    return build_database("S", seed=0)


@pytest.fixture(scope="session")
def cli():
    """Path of the installed `breastplan` console script (next to this Python)."""
    exe = Path(sys.executable).with_name("breastplan")
    assert exe.exists(), f"the breastplan command is not installed next to {sys.executable}"
    return str(exe)


def pytest_collection_modifyitems(items):
    """The long tests first (stable order otherwise): handed out first, they do not leave one worker busy
    while the other has finished."""
    items.sort(key=lambda item: item.get_closest_marker("long") is None)
