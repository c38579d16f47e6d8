"""Simulation studies at an axis position: the data are simulated, and estimated, where the user asked.

The independent reference is a carriage written here from the physics with numpy: a table (z, rx) on a fixed
spring at y = -0.3 m and a shoe spring k that moves with the axis y; a point at y moves z + y rx.
"""

from __future__ import annotations

import numpy as np
import pytest

from cappe.estimate._study import StudyResult, simulate_data, simulation_study
from cappe.exceptions import ConvergenceWarning, ModelError
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


def test_coverage_counts_the_runs_claiming_success_and_all_runs():
    # three runs at 1 % noise, the second FAILED: hand-made intervals, counts written out by hand
    truth = np.array([2.0, 5.0])
    ci95 = np.array([[[[1.9, 2.1], [4.0, 4.5]],           # success: covers a, not b
                      [[1.5, 2.5], [4.8, 5.2]],           # FAILED: covers both
                      [[np.nan, np.nan], [4.9, 5.1]]]])   # success: a without an interval (not covered), covers b
    result = StudyResult("direct", ("a", "b"), truth, np.array([0.01]), (0, 1, 2),
                         np.array([[[2.0, 4.2], [np.nan, np.nan], [2.2, 5.0]]]), np.array([[True, False, True]]),
                         ci95=ci95)
    rows = {r["parameter"]: r for r in result.summary()}
    assert (rows["a"]["covered"], rows["a"]["runs"], rows["a"]["covered_all"], rows["a"]["runs_all"]) == (1, 2, 2, 3)
    assert (rows["b"]["covered"], rows["b"]["runs"], rows["b"]["covered_all"], rows["b"]["runs_all"]) == (1, 2, 2, 3)
    text = result.to_text()
    assert "1 of 3 runs were not a success (did not converge or failed a residual test; 1 of 3 at 1 %)" in text
    assert "95 % intervals covering the truth: of the runs claiming success | of all runs" in text
    assert [line.split()[-3:] for line in text.splitlines()[-2:]] == [["1/2", "|", "2/3"], ["1/2", "|", "2/3"]]
    assert result.to_dict()["rows"][0]["covered_all"] == 2


def test_failed_runs_keep_their_intervals_in_the_coverage_of_all_runs():
    # the data are simulated with c11 = 20 while the estimator knows the rig file's 13.42: a wrong known parameter,
    # so the noise-free runs are FAILED (their equation errors follow the forces). Their estimates are left out of
    # the mean, but their intervals count in the coverage of all runs (before: no coverage at all)
    from cappe.estimate._direct import DirectEstimator

    rig = NumericModel(load_model("builtin:two-mass-rig"))
    unknowns = ["m1", "m2", "k11", "k12", "k22"]
    result = simulation_study(model=rig, method="direct", truth={"c11": 20.0}, unknowns=unknowns, noise_levels=[0.0],
                              seeds=[0, 1], duration=0.5)
    assert not result.success.any()
    assert np.isnan(result.estimates).all()
    rows = result.summary()
    assert {(r["runs"], r["covered"], r["runs_all"]) for r in rows} == {(0, 0, 2)}
    # independent bookkeeping: the same runs again, outside the study
    covered = np.zeros(len(unknowns), dtype=int)
    for seed in (0, 1):
        data = simulate_data(rig, "time", rig.structure.resolve_parameters({"c11": 20.0}), noise=0.0,
                             rng=np.random.default_rng([seed, 0]), fs=1000.0, duration=0.5)
        with pytest.warns(ConvergenceWarning, match="direct estimation failed its residual tests"):
            again = DirectEstimator(rig, unknowns, rng=seed).fit(data).estimate_
        np.testing.assert_array_equal(result.ci95[0, seed], again.ci95)
        covered += (again.ci95[:, 0] <= result.truth) & (result.truth <= again.ci95[:, 1])
    assert [r["covered_all"] for r in rows] == covered.tolist()
