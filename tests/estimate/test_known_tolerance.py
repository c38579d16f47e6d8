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


def test_correlation_is_that_of_the_widened_covariance():
    """The correlation stored with the widened intervals is that of the covariance they come from: it matches the
    correlation of the Monte Carlo estimates (dominated by the known parameters' common error), and with it and
    the standard errors the covariance's diagonal is std^2. The input's correlation (identity here) is not kept.
    The known parameters' effect lies (nearly) in the unknowns' span, as a mass error is absorbed by stiffnesses:
    the residuals stay at the noise, so the scatter part is small and the Monte Carlo is the reference."""
    x_u, _ = _design()
    mix = np.array([[0.5, -0.3], [0.2, 0.8], [-0.4, 0.1]])
    x_k = x_u @ mix + 0.02 * np.random.default_rng(11).standard_normal((x_u.shape[0], KNOWN.size))
    groups = np.repeat(np.arange(N_CLUSTERS), PER_CLUSTER)
    rng = np.random.default_rng(5)
    tolerance = dict(zip(("ka", "kb"), TOLERANCE, strict=True))
    estimates, out = [], None
    for _ in range(400):
        est, ju, r = _disturbed_fit(x_u, x_k, rng)
        out = robust_uncertainty(est, ju, r, groups, known_tolerance=tolerance, known_jacobian=x_k / NOISE,
                                 known_values=KNOWN)
        estimates.append(est.values)
    assert out is not None
    sampled = np.corrcoef(np.array(estimates).T)
    assert np.max(np.abs(sampled - np.eye(3))) > 0.5  # the known parameters correlate the unknowns strongly
    # 400 draws: a correlation's sampling error is below (1 - rho^2) / sqrt(400) = 0.05
    np.testing.assert_allclose(out.correlation, sampled, atol=0.1)
    np.testing.assert_allclose(np.diag(out.correlation), 1.0)
    np.testing.assert_allclose(out.correlation, out.correlation.T)
    assert np.all(np.linalg.eigvalsh(out.correlation) > -1e-12)  # a correlation matrix: positive semi-definite
    gain = np.array(list(out.diagnostics["uncertainty"]["known"]["gain"].values())).T  # (n, n_k)
    np.testing.assert_allclose(np.sqrt((gain**2) @ TOLERANCE**2) * np.abs(out.values),
                               out.diagnostics["uncertainty"]["known"]["std_from_known"], rtol=1e-12)


def test_correlation_without_known_parameters_is_the_sandwich_one_at_the_larger_std():
    """Without known parameters the correlation still belongs to the covariance of the reported std (the
    sandwich's, with clustered residuals); an undetermined parameter's row stays nan."""
    x_u, _ = _design()
    groups = np.repeat(np.arange(N_CLUSTERS), PER_CLUSTER)
    rng = np.random.default_rng(2)
    y = x_u @ THETA + np.repeat(rng.standard_normal(N_CLUSTERS), PER_CLUSTER) * NOISE  # clustered errors
    theta, *_ = np.linalg.lstsq(x_u, y, rcond=None)
    r = (x_u @ theta - y) / NOISE
    ju = x_u / NOISE
    std = np.array([1e-6, 1e-6, np.nan])  # tiny model-based std: the sandwich's is the larger one
    corr = np.array([[1.0, 0.0, np.nan], [0.0, 1.0, np.nan], [np.nan, np.nan, 1.0]])
    est = ParameterEstimate("t", ("a", "b", "c"), theta, std, np.full((3, 2), np.nan), corr,
                            np.array([True, True, False]))
    out = robust_uncertainty(est, ju, r, groups)
    jr = ju * theta[None, :]
    bread = np.linalg.inv(jr.T @ jr)
    scores = np.stack([jr[groups == c].T @ r[groups == c] for c in range(N_CLUSTERS)])
    cov = bread @ scores.T @ scores @ bread
    expected = cov[0, 1] / np.sqrt(cov[0, 0] * cov[1, 1])
    assert abs(expected) > 0.05
    np.testing.assert_allclose(out.correlation[0, 1], expected, rtol=1e-9)
    assert np.isnan(out.correlation[0, 2])
    assert np.isnan(out.correlation[2, 1])


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
