"""The ways to start the command: the ``cappe`` script and ``python -m cappe`` / ``cappe.cli``."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest


@pytest.mark.parametrize("module", ["cappe", "cappe.cli"])
def test_module_entry_points_run_the_command(module):
    result = subprocess.run([sys.executable, "-m", module, "--version"], capture_output=True, text=True,
                            check=False, timeout=300)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("cappe ")


def test_console_script_runs_the_command():
    # the script pip writes beside the interpreter (the README's commands run through its function in
    # tests/cli/test_model_cli.py::test_readme_command_runs)
    result = subprocess.run([str(Path(sys.executable).with_name("cappe")), "--version"], capture_output=True,
                            text=True, check=False, timeout=300)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("cappe ")
