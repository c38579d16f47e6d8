"""Known parameters that are not exactly known: the consider covariance of the automated identification's
intervals (``robust_uncertainty(known_tolerance=...)``, ``cappe identify --known-tolerance``)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from cappe.estimate._automated_steps import robust_uncertainty
from cappe.estimate._result import ParameterEstimate
from cappe.exceptions import DataError

N_CLUSTERS, PER_CLUSTER = 60, 4
THETA = np.array([3.0, 0.5, 8.0])  # unknowns
KNOWN = np.array([2.0, 4.0])  # known parameters, nominal
TOLERANCE = np.array([0.1, 0.05])  # their relative standard deviations
NOISE = 0.01


def _design() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(7)
    n_r = N_CLUSTERS * PER_CLUSTER
    x_u = rng.standard_normal((n_r, THETA.size)) + 0.3 * rng.standard_normal((n_r, 1))  # correlated columns
    x_k = rng.standard_normal((n_r, KNOWN.size)) + 0.5 * x_u[:, :2]
    return x_u, x_k


def _disturbed_fit(x_u: np.ndarray, x_k: np.ndarray, rng: np.random.Generator) -> tuple[ParameterEstimate,
                                                                                       np.ndarray, np.ndarray]:
    """Data from disturbed known parameters and noise; the unknowns fitted with the known ones at their nominal
    values (numpy least squares), model-based std; and the weighted residuals."""
    k_true = KNOWN * (1 + TOLERANCE * rng.standard_normal(KNOWN.size))
    y = x_u @ THETA + x_k @ k_true + NOISE * rng.standard_normal(x_u.shape[0])
    ju = x_u / NOISE  # weighted residual r = (model - y) / NOISE
    theta, *_ = np.linalg.lstsq(x_u, y - x_k @ KNOWN, rcond=None)
    r = (x_u @ theta + x_k @ KNOWN - y) / NOISE
    s2 = float(r @ r) / (r.size - theta.size)
    std = np.sqrt(s2 * np.diag(np.linalg.inv(ju.T @ ju)))
    est = ParameterEstimate("t", ("a", "b", "c"), theta, std, np.full((3, 2), np.nan), np.eye(3),
                            np.ones(3, dtype=bool))
    return est, ju, r


def test_consider_covariance_matches_a_monte_carlo_of_disturbed_fits():
    """The unknowns' spread over fits with disturbed known parameters (Monte Carlo, numpy least squares) is the
    consider covariance G diag(tol^2) G^T, and the 95 % intervals that include it cover the truth at their rate;
    those without it (the scatter of one fit's residuals) cover far less."""
    x_u, x_k = _design()
    groups = np.repeat(np.arange(N_CLUSTERS), PER_CLUSTER)
    rng = np.random.default_rng(1)
    tolerance = dict(zip(("ka", "kb"), TOLERANCE, strict=True))
    estimates, covered, covered_without = [], [], []
    predicted = None
    for _ in range(600):
        est, ju, r = _disturbed_fit(x_u, x_k, rng)
        out = robust_uncertainty(est, ju, r, groups, known_tolerance=tolerance, known_jacobian=x_k / NOISE,
                                 known_values=KNOWN)
        plain = robust_uncertainty(est, ju, r, groups)
        estimates.append(est.values)
        covered.append((out.ci95[:, 0] <= THETA) & (THETA <= out.ci95[:, 1]))
        covered_without.append((plain.ci95[:, 0] <= THETA) & (THETA <= plain.ci95[:, 1]))
        predicted = np.asarray(out.diagnostics["uncertainty"]["known"]["std_from_known"])
    spread = np.std(np.array(estimates), axis=0)  # noise-driven spread is << the known parameters' part
    assert predicted is not None
    np.testing.assert_allclose(predicted, spread, rtol=0.1)
    rate = np.mean(covered, axis=0)
    assert np.all(rate >= 0.92), rate
    assert np.mean(covered_without) < 0.5  # the bug: intervals blind to the known parameters' error
    known = out.diagnostics["uncertainty"]["known"]
    assert known["largest_widening"] > 2
    assert known["parameters"] == tolerance
    assert "consider" in out.diagnostics["uncertainty"]["std"]


def test_zero_tolerance_leaves_the_intervals_as_they_were():
    x_u, x_k = _design()
    groups = np.repeat(np.arange(N_CLUSTERS), PER_CLUSTER)
    est, ju, r = _disturbed_fit(x_u, x_k, np.random.default_rng(3))
    plain = robust_uncertainty(est, ju, r, groups)
    zero = robust_uncertainty(est, ju, r, groups, known_tolerance={"ka": 0.0, "kb": 0.0},
                              known_jacobian=x_k / NOISE, known_values=KNOWN)
    np.testing.assert_allclose(zero.ci95, plain.ci95)
    assert zero.diagnostics["uncertainty"]["known"]["largest_widening"] == 1.0


@pytest.mark.parametrize(("tolerance", "said"), [
    ({"nope": 0.1}, "'nope' is not a parameter of two-mass-rig"),
    ({"k11": 0.1}, "'k11' is an unknown of this identification"),
    ({"m1": -0.1}, "m1=-0.1 must be a relative standard deviation >= 0"),
    ({"m1": float("nan")}, "must be a relative standard deviation >= 0"),
])
def test_automated_identification_refuses_bad_tolerances(tolerance, said):
    from cappe.estimate import AutomatedIdentification
    from cappe.modal import ModalEngine
    from cappe.model import load_model

    rig = load_model("builtin:two-mass-rig")
    ref = ModalEngine(rig).modal_data()
    est = AutomatedIdentification(rig, ["k11", "k22"], n_gsa=8, n_opt=1, n_permutations=0, n_workers=1,
                                  known_tolerance=tolerance)
    with pytest.raises(DataError, match=re.escape(said)):
        est.fit(ref)
