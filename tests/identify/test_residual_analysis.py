"""Residual analysis (MATLAB's resid) and the runs test along frequency: calibration by Monte Carlo, power, and the
statistics against direct loops written from their definitions."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal as sig
from scipy import stats

from cappe.exceptions import DataError
from cappe.identify import ResidualAnalysis, residual_analysis, runs_test


def _coloured(n, rng):
    b, a = sig.butter(4, 0.2)
    return sig.lfilter(b, a, rng.standard_normal(n))


def test_statistics_match_their_definitions():
    rng = np.random.default_rng(0)
    n, lag = 600, 7
    e, u = rng.standard_normal(n), _coloured(n, rng)
    res = residual_analysis(residuals=e[:, None], inputs=u[:, None], output_names=["y"], input_names=["u"],
                            max_lag=lag)
    r_e = np.array([np.sum(e[t:] * e[: n - t]) for t in range(lag + 1)]) / np.sum(e * e)
    np.testing.assert_allclose(res.autocorrelation[0], r_e, rtol=1e-10, atol=1e-12)
    q = n * (n + 2) * sum(r_e[t] ** 2 / (n - t) for t in range(1, lag + 1))
    assert res.whiteness_p[0] == pytest.approx(stats.chi2.sf(q, lag), rel=1e-9)
    cross = [np.sum(e[t:] * u[: n - t]) if t >= 0 else np.sum(e[: n + t] * u[-t:]) for t in range(-lag, lag + 1)]
    np.testing.assert_allclose(res.cross_correlation[0, 0], np.array(cross) / np.sqrt(np.sum(e * e) * np.sum(u * u)),
                               rtol=1e-9, atol=1e-12)
    assert res.cross_lags[lag + 1] == 1  # positive lag: the residual after the input


def test_false_alarm_rate_with_a_coloured_input_is_near_the_level():
    """White residuals independent of a low-pass input: the tests fail in about 1 % of 300 draws (binomial: 0-9)."""
    rng = np.random.default_rng(1)
    dependent, coloured = 0, 0
    for _ in range(300):
        u = _coloured(2000, rng)[:, None]
        res = residual_analysis(residuals=rng.standard_normal((2000, 1)), inputs=u, output_names=["y"],
                                input_names=["u"])
        dependent += not res.passed
        coloured += not bool(res.white[0])
    assert dependent <= 9  # Bonferroni over the lags (all, and the near ones): at most the level, ~1 %
    assert coloured <= 9


def _band_limited(n, rng):
    """A DAQ-like force: white noise through an 8th-order low-pass at 0.7 of Nyquist, unit variance."""
    b, a = sig.butter(8, 0.7)
    u = sig.lfilter(b, a, rng.standard_normal(n + 200))[200:]
    return u / u.std()


def test_a_share_of_the_input_at_lag_zero_is_found_at_the_level():
    """A wrong intersample behaviour leaves a share of the input in the residuals at lag 0 (issue 21: the FOH fits
    of band-limited DAQ records, largest correlation at lag 0 in 10 of 10). At 3 standard deviations the largest
    over all 51 lags alone (Bonferroni 3.72 at 1 %, the test before) found it in 57 of these 200 draws; with the
    near-lag part (3.14 with half the level over lags -1..1) 91. Without the share the test keeps its level: 1 of
    200 (2 before; 1 % is 2, binomial 99.9 %: at most 7)."""
    rng = np.random.default_rng(5)
    n, draws = 2000, 200
    found = {0.0: 0, 3.0: 0}
    for share in found:
        for _ in range(draws):
            u = _band_limited(n, rng)
            e = rng.standard_normal(n) + share / np.sqrt(n) * u
            res = residual_analysis(residuals=e[:, None], inputs=u[:, None], output_names=["y"], input_names=["u"])
            found[share] += not res.passed
    assert found[3.0] >= 75  # the max over 51 lags alone: 57 (binomial sd 6.4)
    assert found[0.0] <= 7


def test_input_leaking_into_the_residuals_and_colour_are_found():
    rng = np.random.default_rng(2)
    u = _coloured(4000, rng)
    e = rng.standard_normal(4000) + 0.15 * np.roll(u, 3) / u.std()
    res = residual_analysis(residuals=[e[:2000, None], e[2000:, None]], inputs=[u[:2000, None], u[2000:, None]],
                            output_names=["y"], input_names=["u"])
    assert not res.passed
    assert "residuals of y correlate with input u" in res.warnings()[0]
    assert res.samples == 4000
    again = ResidualAnalysis.from_dict(res.to_dict())
    np.testing.assert_array_equal(again.independence_p, res.independence_p)
    assert again.near_lag == res.near_lag == 1
    ma = rng.standard_normal(4001)
    res = residual_analysis(residuals=(ma[1:] + 0.5 * ma[:-1])[:, None], inputs=rng.standard_normal((4000, 1)),
                            output_names=["y"], input_names=["u"])
    assert res.passed
    assert not res.white[0]
    assert "not white" in res.warnings()[0]


def test_plot_is_written(tmp_path):
    rng = np.random.default_rng(3)
    res = residual_analysis(residuals=rng.standard_normal((500, 2)), inputs=rng.standard_normal((500, 1)),
                            output_names=["d1", "d2"], input_names=["F1"])
    assert res.plot(tmp_path / "resid.png").stat().st_size > 1000


def test_runs_test_calibration_and_power():
    rng = np.random.default_rng(4)
    false = sum(not runs_test(residuals=[rng.standard_normal(300) for _ in range(4)], names=list("abcd")).passed
                for _ in range(300))
    assert false <= 9  # about 1 % of 300
    # Welch H1 errors under a Hann window: neighbouring lines correlate by about +0.44 (the product of the -0.67
    # of the windowed spectra of force and noise); MA(1) with 0.6 has that. Every third line is independent.
    h1 = [np.convolve(rng.standard_normal(601), [1.0, 0.6], mode="valid") for _ in range(40)]
    assert sum(not runs_test(residuals=[x], names=["h1"]).passed for x in h1) <= 2
    assert sum(not runs_test(residuals=[x], names=["h1"], stride=1).passed for x in h1) >= 20
    smooth = np.sin(np.linspace(0, 12, 300)) * 0.3 + rng.standard_normal(300) * 0.2
    test = runs_test(residuals=[rng.standard_normal(300), smooth], names=["white series", "d1/F1 phase"])
    assert not test.passed
    assert "d1/F1 phase" in test.warnings()[0]
    assert "white series" not in test.warnings()[0]


def test_errors_name_what_is_wrong():
    with pytest.raises(DataError, match="got 2 residual and 1 input channels"):
        residual_analysis(residuals=np.zeros((10, 2)), inputs=np.zeros((10, 1)), output_names=["y"],
                          input_names=["u"])
    with pytest.raises(DataError, match="records of equal lengths"):
        residual_analysis(residuals=np.zeros((10, 1)), inputs=np.zeros((9, 1)), output_names=["y"],
                          input_names=["u"])
    with pytest.raises(DataError, match="max_lag must be an integer >= 1; got 0"):
        residual_analysis(residuals=np.ones((10, 1)), inputs=np.ones((10, 1)), output_names=["y"],
                          input_names=["u"], max_lag=0)
    with pytest.raises(DataError, match="got 1 residual series for 2 names"):
        runs_test(residuals=[np.ones(3)], names=["a", "b"])
