"""Profile likelihood, parametric bootstrap and MCMC against the closed forms of a linear-Gaussian problem."""

from __future__ import annotations

import numpy as np
import pytest

from cappe.estimate import Estimator, ParameterSpace, fit_least_squares
from cappe.estimate._resampling import mcmc_posterior, parametric_bootstrap, profile_likelihood
from cappe.exceptions import DataError

X = np.linspace(0.0, 1.0, 60)
DESIGN = np.column_stack([1.0 + X, 2.0 - X]) * 1e-6  # residuals linear in (k11, k22), scaled to order one
TRUTH = np.array([1.38e6, 0.24e6])
SIGMA = 0.02


def _data(seed):
    return DESIGN @ TRUTH + SIGMA * np.random.default_rng(seed).standard_normal(X.size)


@pytest.fixture(scope="module")
def space(two_mass):
    return ParameterSpace.from_model(two_mass, ["k11", "k22"])


class LinearFit(Estimator):
    method = "linear-test"

    def _fit(self, model, space, data, rng):
        return fit_least_squares(self.method, space, lambda p: DESIGN @ p - data)


def test_profile_interval_equals_the_wald_interval_for_a_linear_model(space):
    y = _data(0)
    est = fit_least_squares("lin", space, lambda p: DESIGN @ p - y, noise_variance=SIGMA**2)
    prof = profile_likelihood(space=space, residuals=lambda p: DESIGN @ p - y, estimate=est, name="k11",
                              n_points=201, noise_variance=SIGMA**2)
    # linear least squares: the profile is an exact parabola, so the chi2(1) crossing is at +-1.96 std
    half = 1.959964 * est.std[0]
    # grid spacing 8 std / 200 and linear interpolation of the parabola: error below 1e-3 std
    np.testing.assert_allclose(prof.ci95, [est.values[0] - half, est.values[0] + half], atol=2e-3 * est.std[0])
    assert prof.identifiable


def test_flat_profile_flags_a_parameter_the_data_cannot_determine(two_mass):
    # bounds wide enough that k22 can compensate every k11 on the grid: the sum is all the data fix
    space = ParameterSpace.from_model(two_mass, ["k11", "k22"], bounds={"k11": (2e5, 1.2e6), "k22": (2e5, 1.5e6)},
                                      start={"k11": 1e6, "k22": 0.5e6})
    y = 1e-6 * (TRUTH.sum()) * np.ones(X.size)

    def residuals(p):  # only k11 + k22 enters
        return 1e-6 * (p[0] + p[1]) * np.ones(X.size) - y + 1e-3 * np.sin(40 * X)

    est = fit_least_squares("sum", space, residuals)
    assert not est.identifiable.any()
    prof = profile_likelihood(space=space, residuals=residuals, estimate=est, name="k11", n_points=7)
    assert not prof.identifiable
    assert np.isnan(prof.ci95).all()
    with pytest.raises(DataError, match=r"'m1' is not among the unknowns \['k11', 'k22'\]"):
        profile_likelihood(space=space, residuals=residuals, estimate=est, name="m1")


def test_bootstrap_spread_matches_the_analytic_standard_error(two_mass):
    fitted = LinearFit(two_mass, ["k11", "k22"]).fit(_data(1))

    def simulate(params, rng):
        p = np.array([params["k11"], params["k22"]])
        return DESIGN @ p + SIGMA * rng.standard_normal(X.size)

    boot = parametric_bootstrap(estimator=fitted, simulate=simulate, n=200, rng=3)
    analytic = SIGMA * np.sqrt(np.diag(np.linalg.inv(DESIGN.T @ DESIGN)))
    # 200 re-fits: the sample std is within ~15 % of the truth at 3 sigma (relative error 1 / sqrt(2 * 199) = 5 %)
    np.testing.assert_allclose(boot.std, analytic, rtol=0.15)
    assert boot.n_failed == 0
    again = parametric_bootstrap(estimator=fitted, simulate=simulate, n=5, rng=3)
    np.testing.assert_array_equal(again.samples, boot.samples[:5])


def test_mcmc_posterior_of_a_linear_gaussian_model(space):
    y = _data(2)
    est = fit_least_squares("lin", space, lambda p: DESIGN @ p - y, noise_variance=SIGMA**2)
    post = mcmc_posterior(space=space, residuals=lambda p: DESIGN @ p - y, estimate=est, noise_variance=SIGMA**2,
                          n_steps=1500, burn=300, rng=4)
    # flat prior in log k over a posterior a few per cent wide: Gaussian to within the prior's tilt; with ~9600
    # correlated draws (autocorrelation ~30 steps) the mean is within 0.15 std and the std within 15 %
    np.testing.assert_allclose(post.mean, est.values, atol=0.15 * est.std.max())
    np.testing.assert_allclose(post.std, est.std, rtol=0.15)
    assert 0.2 < post.acceptance < 0.9
    again = mcmc_posterior(space=space, residuals=lambda p: DESIGN @ p - y, estimate=est, noise_variance=SIGMA**2,
                           n_steps=50, burn=10, rng=4)
    again2 = mcmc_posterior(space=space, residuals=lambda p: DESIGN @ p - y, estimate=est, noise_variance=SIGMA**2,
                            n_steps=50, burn=10, rng=4)
    np.testing.assert_array_equal(again.samples, again2.samples)
