"""Simulation studies at an axis position: the data are simulated, and estimated, where the user asked.

The independent reference is a carriage written here from the physics with numpy: a table (z, rx) on a fixed
spring at y = -0.3 m and a shoe spring k that moves with the axis y; a point at y moves z + y rx.
"""

from __future__ import annotations

import numpy as np
import pytest

from cappe.estimate._study import simulate_data, simulation_study
from cappe.exceptions import ModelError
from cappe.model import NumericModel
from cappe.model.loader import load_model

CARRIAGE = """\
format: cappe.model/1
name: carriage
parameters:
  - {name: m, value: 5.0, kind: mass}
  - {name: k, value: 1.0e6, kind: stiffness, bounds: [1.0e5, 1.0e7], unknown: true}
  - {name: c, value: 20.0, kind: damping}
axes:
  - {name: y, positions: [-0.1, 0.0, 0.2]}
bodies:
  - {name: table, mass: m, inertia: {xx: 0.05, yy: 0.05, zz: 0.05}, dofs: [z, rx]}
elements:
  - {name: a, bodies: [ground, table], at: [0, -0.3, 0], stiffness: {z: 2.0e6}, damping: {z: c}}
  - {name: b, bodies: [ground, table], at: [0, y, 0], stiffness: {z: k}, damping: {z: c}}
sensors:
  - {name: tip, body: table, point: [0, 0.1, 0]}
inputs:
  - {name: F, body: table, point: [0, 0.1, 0], direction: z}
outputs:
  - {name: d, quantity: displacement, body: table, point: [0, 0.1, 0], direction: z}
"""


@pytest.fixture(scope="module")
def carriage(tmp_path_factory):
    path = tmp_path_factory.mktemp("carriage") / "carriage.yaml"
    path.write_text(CARRIAGE)
    return NumericModel(load_model(str(path)))


def _natural_frequencies(y, k=1.0e6, m=5.0, ixx=0.05):
    """Undamped natural frequencies (Hz) of the carriage with the shoe at ``y``, from numpy."""
    h_a, h_b = np.array([1.0, -0.3]), np.array([1.0, y])
    stiffness = 2.0e6 * np.outer(h_a, h_a) + k * np.outer(h_b, h_b)
    return np.sqrt(np.linalg.eigvals(np.linalg.solve(np.diag([m, ixx]), stiffness)).real) / (2 * np.pi)


def test_study_data_are_simulated_at_the_position(carriage):
    # the study's FRFs (H1 from simulated random-excitation records, noise-free) peak at the carriage's lower
    # natural frequency with the shoe at y = 0.2 (numpy), not at the default position's (y = -0.1): before,
    # there was no position to give and every study ran at the first listed one
    frf = simulate_data(carriage, "frf", {}, noise=0.0, rng=np.random.default_rng(0), position={"y": 0.2},
                        duration=8.0)
    peak = frf.freq[np.argmax(np.abs(frf.H[0, 0]))]
    at, default = _natural_frequencies(0.2).min(), _natural_frequencies(-0.1).min()
    assert abs(default - at) > 20  # measured 108.6 Hz against 132 Hz: the position matters
    assert peak == pytest.approx(at, abs=2 * (frf.freq[1] - frf.freq[0]))  # within two lines (0.56 Hz each)


def test_study_estimates_at_the_position_it_simulates(carriage):
    # one-step takes a position: data and model both at y = 0.2, noise-free (the FRF-based one-step-frf fails its
    # residual runs test on the study's H1 FRFs of a short random record: their leakage bias is not noise)
    result = simulation_study(model=carriage, method="one-step", truth={"k": 2.0e6}, unknowns=["k"],
                              noise_levels=[0.0], seeds=[0], duration=2.0, position={"y": 0.2})
    assert result.position == {"y": 0.2}
    assert result.to_dict()["position"] == {"y": 0.2}
    assert bool(result.success[0, 0])
    assert result.estimates[0, 0, 0] == pytest.approx(2.0e6, rel=1e-4)


def test_modal_methods_refuse_a_position(carriage):
    with pytest.raises(ModelError, match=r"a position does not apply to method 'modal': its reference data carry"):
        simulation_study(model=carriage, method="modal", truth={}, unknowns=["k"], noise_levels=[0.0], seeds=[0],
                         position={"y": 0.2})
