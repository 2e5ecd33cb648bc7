"""What `breastplan` shows before any command runs: version, command list, flags, and the light start-up.

The start-up is a property of what gets imported, tested here; its time is measured by
benchmarks/bench_cli.py (no wall-clock limit in a test).
"""
import json
import os
import subprocess
import sys
from importlib.metadata import version

import pytest

from clitools import run

COMMANDS = ("synth", "deform", "dataset", "scan-synth", "ingest", "fit", "evaluate", "train")
HEAVY = ("open3d", "scipy", "sklearn", "matplotlib", "depthai", "pymeshlab", "igl", "numpy")
"""Not loaded before a command runs; numpy too: its import alone is half of the start-up budget."""


def wide_help(cli, *args):
    """`breastplan ARGS --help` on a wide terminal (one line per option)."""
    res = subprocess.run([cli, *args, "--help"], capture_output=True, text=True, timeout=600,
                         env={**os.environ, "COLUMNS": "200"})
    assert res.returncode == 0, res.stderr
    return res.stdout


def test_version_prints_the_package_version_and_exits_0(cli):
    res = run(cli, "--version")
    assert res.returncode == 0, res.stderr
    assert res.stdout == f"breastplan {version('breastplan')}\n"


def test_help_lists_every_command(cli):
    listed = [line.split()[1] for line in wide_help(cli).splitlines()
              if len(line.split()) > 1 and line.split()[1] in COMMANDS]
    assert listed == list(COMMANDS)


@pytest.mark.parametrize("command", [(), *((c,) for c in COMMANDS)])
def test_flags_show_as_flags(cli, command):
    text = wide_help(cli, *command)
    assert "<bool>" not in text
    flags = ["--version", "--help"] if not command else ["--json", "--help"]
    for flag in flags:
        line = next(line for line in text.splitlines() if f" {flag} " in line)
        assert line.split(flag, 1)[1].split()[0][0].isupper()       # the help text follows, no value


@pytest.mark.parametrize("module", ["breastplan", "breastplan.cli.main"])
def test_importing_the_package_or_the_command_loads_no_heavy_library(module):
    code = f"import sys, json, {module}; print(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout) == []
