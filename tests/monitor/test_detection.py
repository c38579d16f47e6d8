"""Sequential change detection (cappe.monitor._detection): Brook-Evans ARLs against published tables and an
independent integral-equation solution, limit design, and SequentialDetector by Monte Carlo and closed forms."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest
from scipy.stats import norm

from cappe.exceptions import DataError
from cappe.monitor import SequentialDetector, cusum_arl, cusum_limit, ewma_arl, ewma_limit

# The module promises ARLs "to about 0.1 %" (301 Markov-chain states); every comparison with a converged
# reference (the Nystrom solutions below, a peer library) uses that promise as its tolerance.
CHAIN_RTOL = 1e-3


# -- independent references ------------------------------------------------------------------------------------
def page_integral_arl(k: float, h: float, shift: float = 0.0, n: int = 80) -> float:
    """Zero-state ARL of a one-sided CUSUM by Page's integral equation (Goel & Wu 1971), Gauss-Legendre Nystrom:
    L(x) = 1 + L(0) Phi(k - x - mu) + int_0^h L(y) phi(y + k - x - mu) dy. Converged to ~1e-12 at n = 80."""
    t, w = np.polynomial.legendre.leggauss(n)
    y, w = (t + 1) * h / 2, w * h / 2
    points = np.concatenate([y, [0.0]])
    a = np.eye(n + 1)
    a[:, :n] -= w[None, :] * norm.pdf(y[None, :] + k - points[:, None] - shift)
    a[:, n] -= norm.cdf(k - points - shift)
    return float(np.linalg.solve(a, np.ones(n + 1))[n])


def crowder_integral_arl(lam: float, limit: float, shift: float = 0.0, n: int = 200) -> float:
    """Zero-state ARL of a two-sided EWMA by Crowder's (1987) integral equation, Gauss-Legendre Nystrom:
    L(z) = 1 + int_{-c}^{c} L(y) phi((y - (1 - lam) z) / lam - mu) / lam dy. Reproduces SAS's EWMAARL."""
    c = limit * np.sqrt(lam / (2 - lam))
    t, w = np.polynomial.legendre.leggauss(n)
    y, w = t * c, w * c
    points = np.concatenate([y, [0.0]])
    a = np.eye(n + 1)
    a[:, :n] -= w[None, :] * norm.pdf((y[None, :] - (1 - lam) * points[:, None]) / lam - shift) / lam
    return float(np.linalg.solve(a, np.ones(n + 1))[n])


def siegmund_arl(k: float, h: float, shift: float = 0.0) -> float:
    """Siegmund's (1985) approximation of the one-sided CUSUM ARL (Montgomery, eq. 9.20)."""
    delta, b = shift - k, h + 1.166
    if delta == 0:
        return b * b
    return float((np.exp(-2 * delta * b) + 2 * delta * b - 1) / (2 * delta**2))


def two_sided(k: float, h: float, shift: float) -> float:
    """Two-sided CUSUM ARL from its one-sided halves: 1/ARL = 1/ARL+ + 1/ARL- (Montgomery, eq. 9.21)."""
    return 1.0 / (1.0 / cusum_arl(k, h, shift) + 1.0 / cusum_arl(k, h, -shift))


# -- CUSUM ARL -------------------------------------------------------------------------------------------------
# Montgomery, Introduction to Statistical Quality Control, Table 9.3: two-sided tabular CUSUM, k = 0.5
MONTGOMERY_CUSUM = {
    4.0: {0.0: 168, 0.25: 74.2, 0.5: 26.6, 0.75: 13.3, 1.0: 8.38, 1.5: 4.75, 2.0: 3.34, 2.5: 2.62, 3.0: 2.19,
          4.0: 1.71},
    5.0: {0.0: 465, 0.25: 139, 0.5: 38.0, 0.75: 17.0, 1.0: 10.4, 1.5: 5.75, 2.0: 4.01, 2.5: 3.11, 3.0: 2.57,
          4.0: 2.01},
}


@pytest.mark.parametrize("h", [4.0, 5.0])
def test_cusum_arl_reproduces_montgomerys_table(h):
    for shift, published in MONTGOMERY_CUSUM[h].items():
        # the table is printed to 3 significant figures: half a unit of its last digit
        last_digit = 10.0 ** (np.floor(np.log10(published)) - 2)
        assert two_sided(0.5, h, shift) == pytest.approx(published, abs=0.5 * last_digit + CHAIN_RTOL * published)


def test_one_sided_in_control_arl_is_twice_the_two_sided():
    # with no shift the two halves are mirror images, so 1/ARL = 2/ARL+: the one-sided chart that the detector
    # designs has twice Montgomery's two-sided in-control ARL (the table's 3 figures: 0.3 %)
    for h in (4.0, 5.0):
        assert cusum_arl(0.5, h) == pytest.approx(2 * MONTGOMERY_CUSUM[h][0.0], rel=3e-3)
    # the negative side of the chart is the positive side of the mirrored data
    assert cusum_arl(0.5, 4.0, -0.5) == pytest.approx(page_integral_arl(0.5, 4.0, -0.5), rel=CHAIN_RTOL)


@pytest.mark.parametrize(("k", "h", "shift"), [(0.5, 4.0, 0.0), (0.5, 5.0, 0.0), (0.5, 5.0, 1.0), (1.0, 3.0, 0.0),
                                              (1.0, 3.0, 2.0), (0.25, 8.0, 0.0), (0.5, 5.0, -1.0), (0.0, 2.0, 0.0)])
def test_cusum_arl_matches_pages_integral_equation(k, h, shift):
    assert cusum_arl(k, h, shift) == pytest.approx(page_integral_arl(k, h, shift), rel=CHAIN_RTOL)


@pytest.mark.parametrize(("h", "shift"), [(4.0, 0.0), (5.0, 0.0), (4.0, 1.0), (5.0, 1.0)])
def test_cusum_arl_agrees_with_siegmunds_approximation(h, shift):
    # Montgomery (9.1.4) quotes Siegmund's 938.2 for h = 5, k = 0.5 against the exact 930.8: the
    # approximation is good to about 1 % for k = 0.5, h = 4-5 and ARLs above ~8 (it degrades to a few % for
    # the short run lengths of large shifts, so those are left to the integral equation), 2 % bounds it
    assert cusum_arl(0.5, h, shift) == pytest.approx(siegmund_arl(0.5, h, shift), rel=0.02)


def test_siegmund_reference_value_as_quoted_by_montgomery():
    # guards the helper: Montgomery prints 938.2 for the one-sided h = 5, k = 0.5 chart
    assert siegmund_arl(0.5, 5.0) == pytest.approx(938.2, abs=0.05)


def test_cusum_arl_falls_with_the_shift_and_rises_with_h():
    shifts = np.linspace(0.0, 3.0, 7)
    arls = [cusum_arl(0.5, 5.0, s) for s in shifts]
    assert np.all(np.diff(arls) < 0)
    assert cusum_arl(0.5, 4.0) < cusum_arl(0.5, 4.5) < cusum_arl(0.5, 5.0)


# -- EWMA ARL --------------------------------------------------------------------------------------------------
# Lucas & Saccucci (1990), as Montgomery's Table 9.11: (lambda, L) -> {shift: ARL}
LUCAS_SACCUCCI = {
    (0.40, 3.054): {0.0: 500, 0.25: 224, 0.5: 71.2, 1.0: 14.3, 2.0: 3.5, 3.0: 2.0},
    (0.25, 2.998): {0.0: 500, 0.25: 170, 0.5: 48.2, 1.0: 11.1, 2.0: 3.6, 3.0: 2.3},
    (0.20, 2.962): {0.0: 500, 0.25: 150, 0.5: 41.8, 1.0: 10.5, 2.0: 3.7, 3.0: 2.4},
    (0.10, 2.814): {0.0: 500, 0.25: 106, 0.5: 31.3, 1.0: 10.3, 2.0: 4.4, 3.0: 2.9},
    (0.05, 2.615): {0.0: 500, 0.25: 84.1, 0.5: 28.8, 1.0: 11.4, 2.0: 5.2, 3.0: 3.5},
}


@pytest.mark.parametrize("design", list(LUCAS_SACCUCCI))
def test_ewma_arl_reproduces_lucas_and_saccucci(design):
    lam, limit = design
    for shift, published in LUCAS_SACCUCCI[design].items():
        # L is printed to 3 decimals, which moves ARL0 = 500 by up to ~0.1 %; the ARLs to 3 figures or 1 decimal
        last_digit = 0.1 if published < 100 else 1.0
        tol = 0.5 * last_digit + 2e-3 * published
        assert ewma_arl(lam, limit, shift) == pytest.approx(published, abs=tol), (lam, shift)


def test_ewma_arl_matches_sas_ewmaarl():
    # SAS/QC documentation, EWMAARL function: EWMAARL(1.00, 0.25, 3.0) = 11.154267016 (Crowder's method)
    assert ewma_arl(0.25, 3.0, 1.0) == pytest.approx(11.154267016, rel=CHAIN_RTOL)
    assert crowder_integral_arl(0.25, 3.0, 1.0) == pytest.approx(11.154267016, rel=1e-9)  # guards the helper


@pytest.mark.parametrize(("lam", "limit", "shift"), [(0.1, 2.814, 0.0), (0.2, 2.962, 0.0), (0.1, 2.814, 1.0),
                                                    (0.05, 2.615, 0.5), (0.4, 3.054, 0.0), (0.3, 2.5, -1.5)])
def test_ewma_arl_matches_crowders_integral_equation(lam, limit, shift):
    assert ewma_arl(lam, limit, shift) == pytest.approx(crowder_integral_arl(lam, limit, shift), rel=CHAIN_RTOL)


def test_ewma_with_lambda_one_is_a_shewhart_chart():
    # lambda = 1: alarm when |z| > L, a geometric run length with ARL = 1 / P(|z + mu| > L)
    for limit, shift in ((3.0, 0.0), (2.5, 1.0)):
        exact = 1.0 / (norm.sf(limit - shift) + norm.cdf(-limit - shift))
        assert ewma_arl(1.0, limit, shift) == pytest.approx(exact, rel=CHAIN_RTOL)


# -- limit design ----------------------------------------------------------------------------------------------
def test_cusum_limit_inverts_cusum_arl():
    # brentq's xtol = 1e-6 on h moves ln ARL by less than 1e-5
    assert cusum_limit(cusum_arl(0.5, 5.0), 0.5) == pytest.approx(5.0, abs=1e-5)
    assert cusum_limit(cusum_arl(0.5, 4.0), 0.5) == pytest.approx(4.0, abs=1e-5)
    for arl0, k in ((200.0, 1.0), (5000.0, 0.25), (1e4, 1.5)):
        assert cusum_arl(k, cusum_limit(arl0, k)) == pytest.approx(arl0, rel=1e-5)


def test_ewma_limit_inverts_ewma_arl_and_finds_the_published_limits():
    for lam, limit in LUCAS_SACCUCCI:
        # the published L are rounded to 3 decimals and the chain is good to 0.1 % in ARL (~5e-4 in L)
        assert ewma_limit(500.0, lam) == pytest.approx(limit, abs=2e-3)
    for arl0, lam in ((100.0, 0.3), (2000.0, 0.1)):
        assert ewma_arl(lam, ewma_limit(arl0, lam)) == pytest.approx(arl0, rel=1e-5)


def outcome(call):
    """(value, None) or (None, message of the DataError it raised)."""
    try:
        return call(), None
    except DataError as exc:
        return None, str(exc)


def test_cusum_design_for_a_large_shift_gives_a_chart_or_a_clear_error():
    # k = 3: even h -> 0 gives ARL0 = 1 / P(z > 3) = 741 > 500, so the root is outside the search bracket.
    # Either the design returns a chart at least as quiet as asked, or it says why it cannot; a bare scipy
    # "f(a) and f(b) must have different signs" is neither.
    h, error = outcome(lambda: cusum_limit(500.0, 3.0))
    if error is not None:
        assert "CUSUM design" in error
    else:
        assert cusum_arl(3.0, h) >= 500.0 * (1 - CHAIN_RTOL)


def test_ewma_design_below_the_search_bracket_gives_a_chart_or_a_clear_error():
    # the same bracket problem for EWMA: lambda = 1 and L = 0.1 (the lower end) already give
    # ARL0 = 1 / P(|z| > 0.1) = 1.087 > 1.05
    limit, error = outcome(lambda: ewma_limit(1.05, 1.0))
    if error is not None:
        assert "EWMA design" in error
    else:
        assert ewma_arl(1.0, limit) >= 1.05 * (1 - CHAIN_RTOL)


def test_detector_for_a_large_shift_that_the_config_accepts():
    # MonitorConfig accepts shift in (0, 50]; shift = 10 (k = 5) makes ARL0 >= 1 / P(z > 5) = 3.5e6 for any h
    det, error = outcome(lambda: SequentialDetector(["a", "b"], [1.0, 1.0], shift=10.0, false_alarm_rate=1e-3))
    if error is not None:
        assert "CUSUM design" in error
    else:
        assert det.design()["arl0_per_chart"] == pytest.approx(4000.0)
        assert cusum_arl(5.0, det.limit) >= 4000.0 * (1 - CHAIN_RTOL)


def test_design_errors():
    with pytest.raises(DataError, match=r"CUSUM needs h > 0 and k >= 0; got h=0.0, k=0.5"):
        cusum_arl(0.5, 0.0)
    with pytest.raises(DataError, match=r"CUSUM needs h > 0 and k >= 0; got h=4.0, k=-0.1"):
        cusum_arl(-0.1, 4.0)
    with pytest.raises(DataError, match=r"EWMA needs 0 < lambda <= 1 and L > 0; got lambda=0.0, L=3.0"):
        ewma_arl(0.0, 3.0)
    with pytest.raises(DataError, match=r"EWMA needs 0 < lambda <= 1 and L > 0; got lambda=1.5, L=3.0"):
        ewma_arl(1.5, 3.0)
    with pytest.raises(DataError, match=r"EWMA needs 0 < lambda <= 1 and L > 0; got lambda=0.2, L=-1.0"):
        ewma_arl(0.2, -1.0)
    with pytest.raises(DataError, match=r"CUSUM design: the in-control ARL must be a finite number > 1; got 1.0"):
        cusum_limit(1.0, 0.5)
    with pytest.raises(DataError, match=r"EWMA design: the in-control ARL must be a finite number > 1; got inf"):
        ewma_limit(float("inf"), 0.2)
    # k = 0: ARL ~ (h + 1.166)^2 stays near 1e6 at the search's cap of h = 1000
    with pytest.raises(DataError, match=r"CUSUM design: no limit reaches an in-control ARL of 1e\+07"):
        cusum_limit(1e7, 0.0)
    with pytest.raises(DataError, match=r"EWMA design: no limit reaches an in-control ARL of 1e\+30"):
        ewma_limit(1e30, 0.1)


# -- SequentialDetector: design --------------------------------------------------------------------------------
def test_detector_design_splits_the_false_alarm_rate_over_the_charts():
    names = ["a", "b", "c"]
    cusum = SequentialDetector(names, [1.0, 2.0, 3.0], false_alarm_rate=0.002, shift=1.0)
    d = cusum.design()
    assert d["k"] == 0.5
    assert d["arl0_per_chart"] == pytest.approx(2 * 3 / 0.002)  # 2 one-sided charts per quantity
    assert cusum_arl(0.5, d["limit"]) == pytest.approx(3000.0, rel=1e-5)
    assert d["arl_at_shift"] == pytest.approx(cusum_arl(0.5, d["limit"], 1.0), rel=1e-12)
    ewma = SequentialDetector(names, [1.0, 2.0, 3.0], method="ewma", false_alarm_rate=0.006, lam=0.1)
    d = ewma.design()
    assert d["arl0_per_chart"] == pytest.approx(3 / 0.006)  # one two-sided chart per quantity
    assert d["limit"] == pytest.approx(2.814, abs=2e-3)  # Lucas & Saccucci's L for ARL0 = 500, lambda = 0.1
    assert d["arl_at_shift"] == pytest.approx(ewma_arl(0.1, d["limit"], 2.0), rel=1e-12)


# -- SequentialDetector: closed forms without noise ------------------------------------------------------------
def test_cusum_signal_time_run_and_change_estimate_for_a_noise_free_step():
    det = SequentialDetector(["a", "b"], [0.01, 0.02], false_alarm_rate=0.01, shift=2.0)
    h, k = det.limit, det.k
    step = np.array([-0.025, 0.004])  # a: -2.5 sigma, b: +0.2 sigma (below k, its chart stays at zero)
    z = abs(step[0]) / 0.01
    expected_time = int(np.floor(h / (z - k))) + 1  # S- = t (z - k) first exceeds h
    state, signals = None, []
    for _ in range(3):
        state, signals = det.update(state, [0.0, 0.0])
        assert signals == []
    for t in range(1, expected_time + 1):
        state, signals = det.update(state, step)
        assert (signals != []) == (t == expected_time)
    (sig,) = signals
    assert (sig.name, sig.side, sig.run) == ("a", "-", expected_time)
    assert sig.statistic == pytest.approx(expected_time * (z - k), rel=1e-12)
    assert sig.limit == h
    np.testing.assert_allclose(sig.change, step, rtol=1e-12)  # the mean since the change point
    assert sig.change_weight == expected_time
    assert state["count"] == 3 + expected_time
    assert state["upper"] == [0.0, 0.0]
    assert state["run_lower"] == [expected_time, 0]
    assert not det.in_control(state, "a")
    assert det.in_control(state, "b")


def test_ewma_signal_statistic_and_change_for_a_noise_free_step():
    lam = 0.2
    det = SequentialDetector(["a", "b"], [0.01, 0.01], method="ewma", false_alarm_rate=0.01, lam=lam)
    sigma = np.sqrt(lam / (2 - lam))
    step = np.array([0.03, -0.005])
    # Z_t = z (1 - (1 - lam)^t) for a step z from a zero start
    zt = [3.0 * (1 - (1 - lam) ** t) for t in range(1, 60)]
    expected_time = 1 + int(np.argmax(np.array(zt) > det.limit * sigma))
    state = None
    for t in range(1, expected_time + 1):
        state, signals = det.update(state, step)
        assert (signals != []) == (t == expected_time)
    (sig,) = signals
    assert (sig.name, sig.side, sig.run) == ("a", "+", 0)
    assert sig.statistic == pytest.approx(zt[expected_time - 1] / sigma, rel=1e-12)
    np.testing.assert_allclose(sig.change, step * (1 - (1 - lam) ** expected_time), rtol=1e-12)
    assert sig.change_weight == pytest.approx((2 - lam) / lam, rel=1e-12)  # 1 / asymptotic EWMA variance
    assert not det.in_control(state, "a")
    assert det.in_control(state, "b")
    # back inside half the limit after enough zero deviations
    for _ in range(30):
        state, _ = det.update(state, [0.0, 0.0])
    assert det.in_control(state, "a")


def test_docstring_example_and_lower_side():
    det = SequentialDetector(["a"], [1.0], false_alarm_rate=0.001, shift=2.0)
    state, signals = det.update(None, [0.3])
    assert signals == []
    for _ in range(4):
        state, signals = det.update(state, [-3.0])
    assert [(s.name, s.side) for s in signals] == [("a", "-")]


# -- SequentialDetector: Monte Carlo ---------------------------------------------------------------------------
def _restart(state, det, index, side):
    """Restart one chart (the renewal that makes its alarms a renewal process with mean gap ARL0)."""
    n = len(det.names)
    if det.method == "cusum":
        key = "upper" if side == "+" else "lower"
        state[key][index] = 0.0
        state[f"run_{key}"][index] = 0
        state[f"sum_{key}"][index] = [0.0] * n
    else:
        state["ewma"][index] = 0.0
        state["ewma_change"][index] = 0.0


@pytest.mark.parametrize("method", ["cusum", "ewma"])
def test_false_alarm_rate_per_measurement_matches_the_design(method):
    # 6 quantities, 5 % false alarms designed; every chart restarted after its own alarm makes each chart's
    # alarms a renewal process with mean gap equal to its zero-state ARL0, so the expected count over M
    # measurements is M * rate (renewal theorem) with a variance of about M * rate (run lengths close to
    # geometric): 20000 measurements -> 1000 +- 32 alarms; 4.5 standard deviations allowed (p ~ 7e-6).
    n, rate, m = 6, 0.05, 20000
    scale = np.linspace(0.5, 2.0, n)
    det = SequentialDetector([f"q{i}" for i in range(n)], scale, method=method, false_alarm_rate=rate, lam=0.2)
    rng = np.random.default_rng(20240611)
    deviations = scale * rng.standard_normal((m, n))
    state, alarms = None, 0
    for d in deviations:
        state, signals = det.update(state, d)
        for s in signals:
            alarms += 1
            _restart(state, det, det.names.index(s.name), s.side)
    expected = m * rate
    assert abs(alarms - expected) < 4.5 * np.sqrt(expected), alarms


def _first_signal_times(det, shift_sigma, side, max_steps=300, seed=0):
    """Feed every quantity the same step of ``shift_sigma`` standard deviations from the start; return each
    quantity's first signal time on ``side`` ('+' or either side with None)."""
    n = len(det.names)
    rng = np.random.default_rng(seed)
    first = np.zeros(n, dtype=int)
    state = None
    for t in range(1, max_steps + 1):
        state, signals = det.update(state, det.scale * (shift_sigma + rng.standard_normal(n)))
        for s in signals:
            i = det.names.index(s.name)
            if first[i] == 0 and (side is None or s.side == side):
                first[i] = t
        if np.all(first > 0):
            return first
    msg = f"{int(np.sum(first == 0))} charts never signalled"
    raise AssertionError(msg)


def test_cusum_detects_a_one_sigma_step_within_its_design_arl():
    # 400 independent upper charts designed for ARL0 = 930.8 one-sided (h = 5, k = 0.5); each chart's first
    # '+' signal is one draw of the upper chart's run length, whose mean is the chain's ARL at the shift
    # (10.38, Montgomery's two-sided 10.4). Tolerance: 4 Monte Carlo standard errors of the mean.
    n = 400
    det = SequentialDetector([f"q{i}" for i in range(n)], np.full(n, 0.01), false_alarm_rate=2 * n / 930.8247814,
                             shift=1.0)
    assert det.limit == pytest.approx(5.0, abs=1e-4)
    runs = _first_signal_times(det, 1.0, "+", seed=1)
    se = runs.std(ddof=1) / np.sqrt(n)
    assert runs.mean() == pytest.approx(det.design()["arl_at_shift"], abs=4 * se)
    assert det.design()["arl_at_shift"] == pytest.approx(10.4, abs=0.05)


def test_ewma_detects_a_one_sigma_step_within_its_design_arl():
    # 400 charts, lambda = 0.1, ARL0 = 500 per chart (L = 2.814); ARL at 1 sigma is 10.3 (Lucas & Saccucci).
    # A chart's first signal on either side is a draw of the two-sided run length. 4 standard errors.
    n = 400
    det = SequentialDetector([f"q{i}" for i in range(n)], np.full(n, 3.0), method="ewma", false_alarm_rate=n / 500,
                             lam=0.1, shift=1.0)
    runs = _first_signal_times(det, 1.0, None, seed=2)
    se = runs.std(ddof=1) / np.sqrt(n)
    assert runs.mean() == pytest.approx(det.design()["arl_at_shift"], abs=4 * se)
    assert det.design()["arl_at_shift"] == pytest.approx(10.3, abs=0.06)


# -- SequentialDetector: state ---------------------------------------------------------------------------------
@pytest.mark.parametrize("method", ["cusum", "ewma"])
def test_state_survives_json_and_continuing_from_it_is_identical(method):
    det = SequentialDetector(["x", "y", "z"], [0.01, 0.02, 0.03], method=method, false_alarm_rate=0.05)
    rng = np.random.default_rng(7)
    deviations = np.array([0.01, 0.02, 0.03]) * (rng.standard_normal((80, 3)) + np.linspace(0, 2.5, 80)[:, None])
    state = None
    for d in deviations[:40]:
        state, _ = det.update(state, d)
    reloaded = json.loads(json.dumps(state))
    assert reloaded == state
    a, b, total = state, reloaded, 0
    for d in deviations[40:]:
        a, sig_a = det.update(a, d)
        b, sig_b = det.update(b, d)
        assert a == b
        assert len(sig_a) == len(sig_b)
        for s, t in zip(sig_a, sig_b, strict=True):
            assert (s.name, s.side, s.statistic, s.limit, s.run, s.change_weight) == (
                t.name, t.side, t.statistic, t.limit, t.run, t.change_weight)
            np.testing.assert_array_equal(s.change, t.change)
        total += len(sig_a)
    assert total > 0  # the drift makes the charts signal, so signals were compared
    assert a["count"] == 80


def test_update_does_not_modify_the_state_it_is_given():
    det = SequentialDetector(["a", "b"], [1.0, 1.0], false_alarm_rate=0.05)
    state, _ = det.update(None, [2.0, -2.0])
    before = copy.deepcopy(state)
    det.update(state, [3.0, 1.0])
    assert state == before


def test_state_and_input_errors():
    det = SequentialDetector(["a", "b"], [1.0, 1.0])
    # the received values are printed as numpy reprs (np.float64(1.0)) by numpy >= 2; accept both spellings
    with pytest.raises(DataError, match=r"detector needs 2 finite deviations \(\['a', 'b'\]\); got \[(np.float64\()?1.0\)?\]"):
        det.update(None, [1.0])
    with pytest.raises(DataError, match=r"detector needs 2 finite deviations"):
        det.update(None, [1.0, np.nan])
    other_names = SequentialDetector(["a", "c"], [1.0, 1.0]).initial_state()
    with pytest.raises(DataError, match=r"detector state is for cusum charts on \['a', 'c'\], not cusum on "
                                        r"\['a', 'b'\]; learn a new baseline to reset it"):
        det.update(other_names, [0.0, 0.0])
    ewma_state = SequentialDetector(["a", "b"], [1.0, 1.0], method="ewma").initial_state()
    with pytest.raises(DataError, match=r"detector state is for ewma charts on \['a', 'b'\], not cusum on"):
        det.update(ewma_state, [0.0, 0.0])
    with pytest.raises(DataError, match=r"detector state is for None charts on None"):
        det.update({}, [0.0, 0.0])
    with pytest.raises(DataError, match=r"detector scales must be 2 positive numbers; got \[(np.float64\()?1.0\)?\]"):
        SequentialDetector(["a", "b"], [1.0])
    with pytest.raises(DataError, match=r"detector scales must be 2 positive numbers; got \[.*1.0\)?, .*0.0\)?\]"):
        SequentialDetector(["a", "b"], [1.0, 0.0])
    with pytest.raises(DataError, match=r"detection method must be 'cusum' or 'ewma'; got 'shewhart'"):
        SequentialDetector(["a"], [1.0], method="shewhart")
    for bad in (0.0, 1.0):
        with pytest.raises(DataError, match=rf"false_alarm_rate must be in \(0, 1\); got {bad}"):
            SequentialDetector(["a"], [1.0], false_alarm_rate=bad)


def test_an_uncertain_estimate_moves_the_charts_less():
    # z = d / sqrt(scale^2 + std^2): the same deviation with its own std equal to the healthy scale counts
    # 1/sqrt(2) as much (closed form of the first CUSUM step from zero: max(0, z - k))
    det = SequentialDetector(["a"], [0.01], false_alarm_rate=1e-3, shift=2.0)
    sure, _ = det.update(None, [-0.03])
    unsure, _ = det.update(None, [-0.03], [0.01])
    assert sure["lower"][0] == pytest.approx(3.0 - 1.0)
    assert unsure["lower"][0] == pytest.approx(3.0 / np.sqrt(2.0) - 1.0)
    with pytest.raises(DataError, match="finite standard uncertainties >= 0"):
        det.update(None, [0.0], [-1.0])
