"""The learned healthy state (cappe.monitor._baseline): exact recovery of a quadratic dependence on operating
conditions, the residual covariance against seeded noise, serialization and errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cappe.exceptions import DataError
from cappe.monitor import BASELINE_FORMAT, Baseline, learn_baseline
from cappe.systems.frf import FRFData

NAMES = ["front", "rear"]


def truth(temperature: np.ndarray, speed: np.ndarray | None = None) -> np.ndarray:
    """Log-factors with a quadratic dependence on temperature (and speed), as the preload law gives."""
    dt = temperature - 22.0
    front = 0.01 + 0.004 * dt - 5e-4 * dt**2
    rear = -0.02 + 0.002 * dt + 2e-4 * dt**2
    if speed is not None:
        ds = (speed - 6000.0) / 1000.0
        front = front - 0.003 * ds + 0.001 * ds**2
        rear = rear + 0.001 * ds
    return np.column_stack([front, rear])


def test_recovers_a_quadratic_temperature_dependence_exactly_without_noise():
    rng = np.random.default_rng(0)
    t = rng.uniform(18.0, 26.0, 40)
    b = learn_baseline(truth(t), names=NAMES, conditions=[{"temperature": v} for v in t])
    assert b.conditions == ("temperature",)
    assert b.center[0] == pytest.approx((t.max() + t.min()) / 2, rel=1e-14)  # the middle of the learned range
    assert b.spread[0] == pytest.approx((t.max() - t.min()) / 2, rel=1e-14)
    for value in (17.0, 20.5, 22.0, 27.5):  # inside and a little outside the learned range
        # least squares on an exactly representable quadratic: rounding only (~1e-16 of terms of order 0.1)
        np.testing.assert_allclose(b.expected({"temperature": value}), truth(np.array([value]))[0], rtol=0,
                                   atol=1e-13)
    np.testing.assert_allclose(b.covariance, 0.0, atol=1e-28)
    np.testing.assert_allclose(b.deviation([0.05, -0.01], {"temperature": 24.0}),
                               np.array([0.05, -0.01]) - truth(np.array([24.0]))[0], atol=1e-13)
    assert b.n_measurements == 40


def test_recovers_two_additive_quadratic_conditions():
    rng = np.random.default_rng(1)
    t, v = rng.uniform(18.0, 26.0, 50), rng.uniform(3000.0, 9000.0, 50)
    conditions = [{"temperature": a, "speed": c} for a, c in zip(t, v, strict=True)]
    b = learn_baseline(truth(t, v), names=NAMES, conditions=conditions)
    assert set(b.conditions) == {"temperature", "speed"}
    assert b.coefficients.shape == (5, 2)  # constant, two linear, two quadratic terms
    point = {"temperature": 23.0, "speed": 8000.0}
    np.testing.assert_allclose(b.expected(point), truth(np.array([23.0]), np.array([8000.0]))[0], rtol=0, atol=1e-12)


def test_residual_covariance_matches_the_seeded_noise():
    rng = np.random.default_rng(2)
    n = 4000
    cov = np.array([[1.0e-6, 6.0e-7], [6.0e-7, 4.0e-6]])
    t = rng.uniform(18.0, 26.0, n)
    s = truth(t) + rng.multivariate_normal(np.zeros(2), cov, n)
    b = learn_baseline(s, names=NAMES, conditions=[{"temperature": v} for v in t])
    # sampling standard error of a covariance entry: sqrt((S_ij^2 + S_ii S_jj) / N); 4.5 of them
    se = np.sqrt((cov**2 + np.outer(np.diag(cov), np.diag(cov))) / n)
    np.testing.assert_array_less(np.abs(b.covariance - cov), 4.5 * se)
    np.testing.assert_allclose(b.std, np.sqrt(np.diag(b.covariance)), rtol=1e-15)
    # the expectation is still the quadratic: the prediction's standard error at x0 is
    # sigma sqrt(x0' (X'X)^-1 x0) (ordinary least squares); 4.5 of them
    x = (t - b.center[0]) / b.spread[0]
    design = np.column_stack([np.ones(n), x, x**2])
    x0 = np.array([1.0, (22.0 - b.center[0]) / b.spread[0], ((22.0 - b.center[0]) / b.spread[0]) ** 2])
    se_pred = np.sqrt(np.diag(cov) * (x0 @ np.linalg.solve(design.T @ design, x0)))
    np.testing.assert_array_less(np.abs(b.expected({"temperature": 22.0}) - truth(np.array([22.0]))[0]),
                                 4.5 * se_pred)


def test_covariance_is_unbiased_for_a_small_baseline():
    # 9 measurements, 3 fitted terms per component: dividing the residual sum of squares by N - 3 makes the
    # covariance unbiased (dividing by N would be 1/3 low). Mean over 3000 independent baselines: each diagonal
    # estimate has a relative standard deviation sqrt(2 / 6), so the mean's is 0.0105; 4.5 of those.
    rng = np.random.default_rng(3)
    sigma = np.array([1e-3, 3e-3])
    estimates = []
    for _ in range(3000):
        t = rng.uniform(18.0, 26.0, 9)
        s = truth(t) + sigma * rng.standard_normal((9, 2))
        estimates.append(np.diag(learn_baseline(s, names=NAMES, conditions=[{"temperature": v} for v in t])
                                 .covariance))
    np.testing.assert_allclose(np.mean(estimates, axis=0) / sigma**2, 1.0, atol=4.5 * np.sqrt(2 / 6 / 3000))


def test_without_conditions_the_baseline_is_the_mean_and_sample_covariance():
    rng = np.random.default_rng(4)
    s = rng.normal([0.01, -0.02], [1e-3, 2e-3], size=(12, 2))
    b = learn_baseline(s, names=NAMES)
    assert b.conditions == ()
    assert b.coefficients.shape == (1, 2)
    np.testing.assert_allclose(b.expected(), s.mean(axis=0), rtol=1e-13)
    np.testing.assert_allclose(b.expected({"temperature": 40.0}), s.mean(axis=0), rtol=1e-13)  # extra ignored
    np.testing.assert_allclose(b.covariance, np.cov(s.T, ddof=1), rtol=1e-12)


def test_constant_and_partial_conditions_are_dropped():
    rng = np.random.default_rng(5)
    t = rng.uniform(18.0, 26.0, 20)
    conditions = [{"temperature": v, "speed": 3000.0} for v in t]  # speed never varies
    conditions[3]["humidity"] = 0.4  # given by one measurement only
    b = learn_baseline(truth(t), names=NAMES, conditions=conditions)
    assert b.conditions == ("temperature",)
    np.testing.assert_allclose(b.expected({"temperature": 21.0}), truth(np.array([21.0]))[0], atol=1e-13)
    # with the constant speed gone, 9 measurements (not 15) suffice
    learn_baseline(truth(t[:9]), names=NAMES, conditions=conditions[:9])


def test_chart_scale_adds_the_resolution():
    rng = np.random.default_rng(6)
    s = rng.normal(0.0, [1e-3, 1e-2], size=(30, 2))
    b = learn_baseline(s, names=NAMES, resolution=0.004)
    np.testing.assert_allclose(b.scale, np.sqrt(np.diag(b.covariance) + 0.004**2), rtol=1e-15)
    np.testing.assert_allclose(b.chart_covariance, b.covariance + 0.004**2 * np.eye(2), rtol=1e-15)
    assert b.resolution == 0.004


def test_feature_statistics_ignore_missing_values():
    s = np.zeros((4, 2)) + np.arange(4)[:, None] * 1e-3
    features = [{"f1": 1.0, "f2": np.nan, "f3": np.nan}, {"f1": 3.0, "f2": 5.0}, {"f1": 2.0, "f3": np.nan},
                {"f1": np.nan, "f2": np.inf}]
    b = learn_baseline(s, names=NAMES, features=features)
    assert b.features["f1"] == pytest.approx((2.0, 1.0), rel=1e-15)  # mean, sample std of 1, 3, 2
    assert b.features["f2"] == (5.0, 0.0)  # a single finite value: no spread
    assert "f3" not in b.features  # never finite


def test_mean_frf_of_the_healthy_measurements():
    freq = np.array([10.0, 20.0, 30.0])
    h1 = np.array([[[1 + 1j, 2.0, 3j]]])
    h2 = np.array([[[3 - 1j, 4.0, 1j]]])
    frfs = [FRFData(freq, h1, ("F",), ("a",)), FRFData(freq, h2, ("F",), ("a",))]
    b = learn_baseline(np.zeros((3, 2)) + [[0.0, 0.0], [1e-3, 0.0], [0.0, 1e-3]], names=NAMES, frfs=[*frfs, frfs[0]])
    mean = b.frf_data()
    np.testing.assert_allclose(mean.H, (2 * h1 + h2) / 3, rtol=1e-15)
    np.testing.assert_array_equal(mean.freq, freq)
    assert mean.input_names == ("F",)
    assert mean.output_names == ("a",)
    other_lines = FRFData(freq + 1.0, h1, ("F",), ("a",))
    assert learn_baseline(np.zeros((3, 2)), names=NAMES, frfs=[frfs[0], other_lines, frfs[1]]).frf_data() is None


def test_dict_round_trip_through_json():
    rng = np.random.default_rng(7)
    t = rng.uniform(18.0, 26.0, 30)
    s = truth(t) + 1e-4 * rng.standard_normal((30, 2))
    freq = np.array([10.0, 20.0])
    frf = FRFData(freq, np.array([[[1 + 1j, 2.0]]]), ("F",), ("a",))
    b = learn_baseline(s, names=NAMES, conditions=[{"temperature": v} for v in t], frfs=[frf] * 30,
                       features=[{"f1": float(v)} for v in t], resolution=0.003, measurement_ids=range(1, 31),
                       preload_map={"parameter": "preload", "values": [1.0, 2.0]})
    d = json.loads(json.dumps(b.to_dict()))
    assert d["format"] == BASELINE_FORMAT
    c = Baseline.from_dict(d)
    assert (c.names, c.conditions, c.n_measurements, c.measurement_ids, c.created, c.resolution) == (
        b.names, b.conditions, b.n_measurements, b.measurement_ids, b.created, b.resolution)
    for field in ("center", "spread", "coefficients", "covariance"):
        np.testing.assert_array_equal(getattr(c, field), getattr(b, field))  # JSON floats round-trip exactly
    assert c.features == b.features
    assert c.map == b.map
    np.testing.assert_array_equal(c.frf_data().H, b.frf_data().H)
    np.testing.assert_array_equal(c.expected({"temperature": 25.0}), b.expected({"temperature": 25.0}))
    # the people's view: factors at the centre of the conditions, delta-method std, 3-sigma chart limits
    mean = np.exp(b.coefficients[0])
    assert d["mean"] == {"front": pytest.approx(mean[0], rel=1e-15), "rear": pytest.approx(mean[1], rel=1e-15)}
    assert d["std"]["rear"] == pytest.approx(mean[1] * b.std[1], rel=1e-15)
    assert d["limits"]["front"] == pytest.approx([mean[0] * np.exp(-3 * b.scale[0]), mean[0] * np.exp(3 * b.scale[0])],
                                                 rel=1e-15)


def test_errors():
    rng = np.random.default_rng(8)
    t = rng.uniform(18.0, 26.0, 8)
    with pytest.raises(DataError, match=r"a baseline with 1 operating condition\(s\) \['temperature'\] needs at "
                                        r"least 9 healthy measurements; got 8"):
        learn_baseline(truth(t), names=NAMES, conditions=[{"temperature": v} for v in t])
    with pytest.raises(DataError, match=r"a baseline with 0 operating condition\(s\) \[\] needs at least 3 healthy "
                                        r"measurements; got 2"):
        learn_baseline(np.zeros((2, 2)), names=NAMES)
    with pytest.raises(DataError, match=r"baseline log-factors must be a finite \(N, 2\) array; got shape \(5, 3\)"):
        learn_baseline(np.zeros((5, 3)), names=NAMES)
    with pytest.raises(DataError, match=r"baseline log-factors must be a finite \(N, 2\) array; got shape \(4,\)"):
        learn_baseline(np.zeros(4), names=NAMES)
    bad = np.zeros((5, 2))
    bad[2, 1] = np.nan
    with pytest.raises(DataError, match=r"baseline log-factors must be a finite \(N, 2\) array; got shape \(5, 2\)"):
        learn_baseline(bad, names=NAMES)
    with pytest.raises(DataError, match=r"baseline: 5 measurements but 4 condition records"):
        learn_baseline(np.zeros((5, 2)), names=NAMES, conditions=[{}] * 4)
    t = rng.uniform(18.0, 26.0, 12)
    b = learn_baseline(truth(t), names=NAMES, conditions=[{"temperature": v} for v in t])
    with pytest.raises(DataError, match=r"the baseline depends on the operating condition 'temperature', which the "
                                        r"measurement does not give \(conditions \{'speed': 1.0\}\)"):
        b.expected({"speed": 1.0})
    with pytest.raises(DataError, match=r"operating condition 'temperature', which the measurement does not give "
                                        r"\(conditions \{\}\)"):
        b.deviation([0.0, 0.0])
    d = b.to_dict()
    with pytest.raises(DataError, match=r"baseline format must be 'cappe.monitor-baseline/1'; got 'other/1'"):
        Baseline.from_dict({**d, "format": "other/1"})
    del d["covariance"]
    with pytest.raises(DataError, match=r"baseline is malformed: KeyError 'covariance'"):
        Baseline.from_dict(d)
    with pytest.raises(DataError, match=r"baseline is malformed: ValueError"):
        Baseline.from_dict({**b.to_dict(), "coefficients": [[0.1, 0.2, 0.3]]})


def test_a_nan_condition_is_not_silently_dropped():
    # one measurement without a valid temperature: the regression on temperature must not vanish unnoticed
    # (np.ptp of a column with a NaN is NaN, and "NaN > 0" is False). Either the measurement is left out of
    # the regression, or the call says what is wrong.
    rng = np.random.default_rng(9)
    t = rng.uniform(18.0, 26.0, 20)
    conditions = [{"temperature": v} for v in t]
    conditions[5] = {"temperature": float("nan")}
    try:
        b, error = learn_baseline(truth(t), names=NAMES, conditions=conditions), None
    except DataError as exc:
        b, error = None, str(exc)
    if error is not None:
        assert "temperature" in error
    else:
        assert b.conditions == ("temperature",)
