"""Shared fixtures."""

from __future__ import annotations

import pytest

from cappe.model import load_model


@pytest.fixture(scope="session")
def two_mass():
    return load_model("builtin:two-mass-rig")


@pytest.fixture(scope="session")
def spindle():
    return load_model("builtin:spindle-bearing")
