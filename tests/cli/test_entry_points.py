"""The ways to start the command: the ``cappe`` script (README tests) and ``python -m cappe`` / ``cappe.cli``."""

from __future__ import annotations

import subprocess
import sys

import pytest


@pytest.mark.parametrize("module", ["cappe", "cappe.cli"])
def test_module_entry_points_run_the_command(module):
    result = subprocess.run([sys.executable, "-m", module, "--version"], capture_output=True, text=True,
                            check=False, timeout=300)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("cappe ")
