"""Issue-level acceptance: synthetic measurements -> FRFs -> modes, compared with the model's exact modes.

Truth is the exact complex eigen-solution of the simulating model (``MechanicalSystem.modes()``); the data are
made by ``time_response`` (ZOH simulation) with seeded 1 % output noise. Tolerances are the issue's: frequencies
within 0.5 %, damping ratios within 5 %.
"""

from __future__ import annotations

import numpy as np
import pytest

from cappe.identify import estimate_frf, extract_modes, impact, random_noise
from cappe.model import NumericModel, load_model
from cappe.model.loader import structure_from_yaml
from cappe.systems import time_response

THREE_DOF = """
format: cappe.model/1
name: three-dof-chain
parameters:
  - {name: m, value: 2.0, unit: kg, kind: mass}
  - {name: k, value: 4.0e5, unit: N/m, kind: stiffness}
  - {name: c, value: 40.0, unit: N s/m, kind: damping}
bodies:
  - {name: b1, mass: m, dofs: [x]}
  - {name: b2, mass: 0.8*m, dofs: [x]}
  - {name: b3, mass: 0.6*m, dofs: [x]}
elements:
  - {name: e1, bodies: [ground, b1], stiffness: {x: k}, damping: {x: c}}
  - {name: e2, bodies: [b1, b2], stiffness: {x: 0.7*k}, damping: {x: 0.5*c}}
  - {name: e3, bodies: [b2, b3], stiffness: {x: 0.5*k}, damping: {x: 0.5*c}}
inputs:
  - {name: F, body: b1, direction: x}
outputs:
  - {name: a1, quantity: acceleration, body: b1, direction: x}
  - {name: a2, quantity: acceleration, body: b2, direction: x}
  - {name: a3, quantity: acceleration, body: b3, direction: x}
"""

FREQ_RTOL = 0.005  # issue 4: frequencies within 0.5 %
DAMPING_RTOL = 0.05  # issue 4: damping within 5 %


@pytest.fixture(scope="module")
def three_dof():
    return NumericModel(structure_from_yaml(THREE_DOF)).system()


@pytest.fixture(scope="module")
def rig():
    return NumericModel(load_model("builtin:two-mass-rig")).system()


def _check(found, system):
    truth = system.modes()
    assert found.frequency.size == truth.frequency.size
    np.testing.assert_allclose(found.frequency, truth.frequency, rtol=FREQ_RTOL)
    np.testing.assert_allclose(found.damping, truth.damping, rtol=DAMPING_RTOL)


def test_three_dof_random_excitation_one_percent_noise(three_dof):
    force = random_noise(fs=1024.0, duration=128.0, rms=10.0, band=(0.0, 400.0), rng=1)
    data = time_response(three_dof, force, noise=0.01, rng=2)
    # the band is where the responses stand above the 1 % noise floor; coherence stays high there
    frf = estimate_frf(data, inputs=["F"], outputs=["a1", "a2", "a3"], nperseg=16384, band=(10.0, 200.0))
    _check(extract_modes(frf, band=(10.0, 200.0)), three_dof)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_simulated_impact_test_on_the_rig(rig, seed):
    # the rig's first mode has zeta = 0.05 %: a 4 s record has not decayed, so the estimator applies an exponential
    # window and extract_modes removes the damping it adds (FRFData.window_decay)
    hit = impact(fs=2048.0, duration=4.0, amplitude=200.0, contact_time=1e-3, at=0.02, name="F1")
    data = time_response(rig, hit, outputs=["a1", "a2"], noise=0.01, rng=seed)
    frf = estimate_frf(data, inputs=["F1"], outputs=["a1", "a2"], impact=True)
    assert frf.window_decay is not None
    _check(extract_modes(frf, band=(20.0, 400.0)), rig)


def test_simulated_impact_test_three_dof(three_dof):
    hit = impact(fs=1024.0, duration=2.0, amplitude=500.0, contact_time=2.5e-3, at=0.02)
    data = time_response(three_dof, hit, noise=0.01, rng=3)
    frf = estimate_frf(data, inputs=["F"], outputs=["a1", "a2", "a3"], impact=True)
    _check(extract_modes(frf, band=(10.0, 200.0)), three_dof)
