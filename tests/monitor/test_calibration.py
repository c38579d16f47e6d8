"""Calibration of the monitoring chain against an independent generator (issue 25): the learned range, size intervals
that follow the baseline's own scatter and the model's offset, a 2 % front-bearing loss, false alarms.

The data come from :class:`benchmarks._spindle_generator.ShopFloor` (numpy physics of its own: cold starts, warm-up, a
lagging temperature sensor, log-normal FRF errors), never from cappe's scenario path. The full figures (140 fault
trials per case, 1000 healthy measurements) are ``benchmarks/bench_calibration.py`` and
``benchmarks/bench_small_change.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
from benchmarks._spindle_generator import ShopFloor
from benchmarks.bench_small_change import detect, small_change_trials

from cappe.model import NumericModel
from cappe.monitor import Monitor, MonitorConfig, diagnose
from cappe.monitor._baseline import MODEL_OFFSET_FACTOR, SIZE_SCALE_FLOOR, learn_baseline
from cappe.monitor._chain import detectable_change
from cappe.monitor._diagnosis import FaultHypothesis


@pytest.fixture(scope="module")
def chain(spindle: NumericModel, spindle_config: MonitorConfig):
    """The chain, the generator (exact model) and a baseline from one healthy day of it."""
    config = spindle_config
    monitor = Monitor(config, spindle)
    floor = ShopFloor(config, spindle, rng=np.random.default_rng(5), sensor_lag=0.5)
    day = floor.run(96)
    baseline = monitor.learn_baseline([monitor.analyse(m.frf, modal=False) for m in day],
                                      conditions=[m.conditions for m in day])
    return monitor, floor, baseline


def test_the_learned_range_is_the_range_of_the_data() -> None:
    # a machine that runs warm most of the day: 80 measurements at 26-27 degC, 16 during the cold start at 18-19;
    # the range the baseline says it learned must be 18 to 27, not centred on the mean (old: 19.6 to 28.6, so a
    # cold machine at 18.5 degC, inside the healthy data, was refused as outside the learned range)
    rng = np.random.default_rng(3)
    temps = np.concatenate([rng.uniform(26.0, 27.0, 80), rng.uniform(18.0, 19.0, 16)])
    logs = 0.004 * (temps[:, None] - 22.0) + 1e-4 * rng.standard_normal((96, 1))
    b = learn_baseline(logs, names=["front"], conditions=[{"temperature": t} for t in temps])
    assert b.judge({"temperature": 18.5}) == ([], [])
    assert b.judge({"temperature": float(temps.min())}) == ([], [])
    assert b.judge({"temperature": 30.0})[0]  # beyond 27 + a quarter of the half-range


def test_size_uncertainty_follows_the_scatter_and_the_models_offset() -> None:
    # no fixed 0.5 % floor: a small change is sized with the healthy scatter (0.01 %), a large one with a relative
    # part that grows with the model's offset from the machine (old: +-0.5 % whatever the scatter and the model)
    rng = np.random.default_rng(0)
    hyps = [FaultHypothesis(n, n, np.eye(3)[k]) for k, n in enumerate("abc")]
    for offset in (0.0, -0.03):
        b = learn_baseline(offset + 1e-4 * rng.standard_normal((60, 3)), names=list("abc"))
        assert b.model_offset == pytest.approx(abs(offset), abs=1e-4)
        kappa = np.hypot(SIZE_SCALE_FLOOR, MODEL_OFFSET_FACTOR * abs(offset))
        assert b.size_scale_std == pytest.approx(kappa, rel=1e-3)
        small = np.array([np.log(0.999), 0.0, 0.0])
        d = diagnose(small, b.size_covariance(small), hyps)
        assert d.hypothesis == "a"
        assert d.change_std < 1.5e-4  # the scatter (1e-4) and 0.1 % of kappa
        large = np.array([np.log(0.7), 0.0, 0.0])
        d = diagnose(large, b.size_covariance(large), hyps)
        assert d.change_std == pytest.approx(0.7 * kappa * abs(np.log(0.7)), rel=0.05)


def test_a_2_percent_front_bearing_loss_is_found_and_sized(chain) -> None:
    # issue 25's smaller change on the independent generator: within 5 measurements, located, its 95 % interval
    # covering the truth and far narrower than the old fixed +-0.5 %; and healthy measurements raise no alarm
    monitor, floor, baseline = chain
    rows = small_change_trials(monitor, floor, baseline, 4)
    for r in rows:
        assert r["false_alarms_before"] == 0, r
        assert r["detected_after"] is not None, r
        assert r["detected_after"] <= 5, r
        assert r["diagnosis"] == "front", r
        assert abs(r["change"] + 0.02) <= 1.96 * r["change_std"], r
        assert r["change_std"] < 0.001, r  # 0.5 % before
    _, raised, skipped = detect(monitor, baseline, floor.run(48))
    assert not raised, [a.message for _, a in raised]
    assert skipped < 12


def test_status_says_how_uncertain_sizes_are(chain) -> None:
    monitor, _, baseline = chain
    det = detectable_change(monitor.config, baseline)
    assert det["size_scale_std"] == pytest.approx(baseline.size_scale_std)
    assert det["model_offset"] < 0.01  # the exact model: only the preload's thermal offset at the learned centre
    assert max(det["change"].values()) < 0.002  # 2 % is far above what the charts find


@pytest.mark.slow
@pytest.mark.extended(reason="1000 healthy measurements and 20 trials; the contract on 4 trials and 48 healthy: "
                             "test_a_2_percent_front_bearing_loss_is_found_and_sized")
def test_2_percent_loss_and_1000_healthy_measurements(chain) -> None:
    # issue 25's done-means: a 2 % front-bearing loss detected within 5 measurements at <= 0.1 % false alarms per
    # measurement over >= 1000 healthy measurements with drift (cold starts, warm-up, a lagging sensor)
    monitor, floor, baseline = chain
    rows = small_change_trials(monitor, floor, baseline, 20)
    assert all(r["detected_after"] is not None and r["detected_after"] <= 5 for r in rows), rows
    assert sum(r["diagnosis"] == "front" for r in rows) >= 19
    healthy = floor.run(1000)
    _, raised, skipped = detect(monitor, baseline, healthy)
    assert len(raised) <= 0.001 * (len(healthy) - skipped), [a.message for _, a in raised]
    assert skipped < 100


def test_the_forecasts_scale_term_adds_in_quadrature() -> None:
    # the scatter and the scale error of the sizes are independent: each side of Fieller's interval is widened in
    # quadrature by z scale_std |c / b| (old: the hull of the intervals at shifted thresholds, the two quantiles
    # added: 80 of 80 at a stated 95 % on the exact model)
    from scipy.stats import norm

    from cappe.monitor import forecast_crossing

    t = np.arange(13) * 0.25
    y = -0.02 * t + 0.0005 * np.cos(5 * t)
    plain = forecast_crossing(t, y, -0.25)
    wide = forecast_crossing(t, y, -0.25, scale_std=0.01)
    shift = norm.ppf(0.975) * 0.01 * 0.25 / abs(plain.slope)
    assert wide.time == pytest.approx(plain.time)
    assert wide.time - wide.lower == pytest.approx(np.hypot(plain.time - plain.lower, shift), rel=1e-9)
    assert wide.upper - wide.time == pytest.approx(np.hypot(plain.upper - plain.time, shift), rel=1e-9)


_TWIN_CASES: dict[tuple[object, ...], tuple[Monitor, ShopFloor, object]] = {}


def _twin_case(spindle: NumericModel, spindle_config: MonitorConfig, **mismatch: float):
    """A chain and a baseline (with FRFs: the twin) from 24 healthy measurements of a mismatched generator; made
    once per mismatch (the twin is most of a test's time; the baseline is only read)."""
    key = (id(spindle), id(spindle_config), *sorted(mismatch.items()))
    if key not in _TWIN_CASES:
        _TWIN_CASES[key] = _new_twin_case(spindle, spindle_config, **mismatch)
    return _TWIN_CASES[key]


def _new_twin_case(spindle: NumericModel, spindle_config: MonitorConfig, **mismatch: float):
    """:func:`_twin_case` without the memory."""
    config = spindle_config
    monitor = Monitor(config, spindle)
    floor = ShopFloor(config, spindle, rng=np.random.default_rng(11), sensor_lag=0.5, **mismatch)
    day = floor.run(24)
    baseline = monitor.learn_baseline([monitor.analyse(m.frf, modal=False) for m in day],
                                      conditions=[m.conditions for m in day], frfs=[m.frf for m in day])
    return monitor, floor, baseline


def _sized(monitor: Monitor, floor: ShopFloor, baseline, fault: str, loss: float):
    """The diagnosis of one measurement of ``fault`` at ``loss``, sized along the true fault."""
    m = floor.run(1, fault=fault, loss=loss)[0]
    deviation = baseline.deviation(monitor.analyse(m.frf, baseline=baseline, modal=False).estimate.log_factor,
                                   m.conditions)
    hyp = next(h for h in monitor.hypotheses() if h.name == fault)
    return diagnose(deviation, baseline.size_covariance(deviation), [hyp])


def test_size_intervals_follow_what_is_off_not_the_offset(spindle: NumericModel, spindle_config: MonitorConfig) -> None:
    # damping 30 % off barely moves the factors (offset about 0.5 %), yet a screw-1 loss is read about 8 % too small
    # on the independent generator: the offset rule gave +-0.9 % of the change and its 95 % interval missed the
    # truth; the twin (the model with one damping factor fitted to the healthy FRFs) measures the error per component
    monitor, floor, baseline = _twin_case(spindle, spindle_config, damping_factor=1.3)
    assert baseline.model_offset < 0.01
    d = _sized(monitor, floor, baseline, "screw1", 0.25)
    assert abs(d.change + 0.25) > 0.005  # the error is real (about 3 % of the loss)
    assert abs(d.change + 0.25) <= 1.96 * d.change_std, (d.change, d.change_std)
    # the prognosis' scale of each component: the twin's error; screw 1's far above the front bearing's
    scale = dict(zip(baseline.names, baseline.component_scale_std(), strict=True))
    assert scale["screw1"] > 0.05
    assert scale["front"] < 0.02


def test_a_mass_error_does_not_widen_the_size_intervals(spindle: NumericModel, spindle_config: MonitorConfig) -> None:
    # masses 3 % off shift every factor by -3 % (a uniform mass error is a uniform stiffness-and-damping one) and
    # change the read sizes by less than 1 %: the offset rule widened every interval by 4.4 % of the change
    monitor, floor, baseline = _twin_case(spindle, spindle_config, mass_error=0.03)
    assert baseline.model_offset > 0.02
    for fault in ("front", "screw3"):
        d = _sized(monitor, floor, baseline, fault, 0.25)
        assert abs(d.change + 0.25) <= 1.96 * d.change_std, (fault, d.change, d.change_std)
        assert d.change_std < 0.02 * 0.25, (fault, d.change_std)  # offset rule: 0.044 * 0.29 = 0.013
    assert baseline.size_scale_std < 0.02


def test_the_twins_errors_round_trip(spindle: NumericModel, spindle_config: MonitorConfig) -> None:
    from cappe.monitor import Baseline

    _, _, baseline = _twin_case(spindle, spindle_config, damping_factor=1.3)
    again = Baseline.from_dict(baseline.to_dict())
    assert baseline.size_error is not None
    np.testing.assert_array_equal(again.size_error, baseline.size_error)
    np.testing.assert_array_equal(again.component_scale_std(), baseline.component_scale_std())
