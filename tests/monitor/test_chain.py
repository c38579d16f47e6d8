"""The monitoring chain end to end on simulated spindle data with 1 % FRF noise (the issue's done-means).

Truth comes from the scenario simulator (an exact model with temperature-driven preload drift and seeded noise),
never from the chain itself.
"""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import numpy as np
import pytest

from cappe.exceptions import DataError
from cappe.model import NumericModel
from cappe.monitor import Monitor, default_config, simulate_scenario

#: The monitoring set-up of the tests: hammer at the spindle nose in x, y, z; the two shaft probes of the
#: thesis rig and four housing accelerometers (front x/y/z, top x) -- a sensor set a shop floor can afford.
OUTPUTS = ["sx", "sy", "hax", "hay", "haz", "htax"]
BAND = (150.0, 1000.0)


@pytest.fixture(scope="module")
def monitor(spindle: NumericModel) -> Monitor:
    config = default_config(spindle, machine="spindle-01", source="builtin:spindle-bearing", outputs=OUTPUTS,
                            band=BAND)
    return Monitor(config, spindle)


@pytest.fixture(scope="module")
def healthy(monitor: Monitor) -> list:
    """One day of healthy measurements every 15 minutes: the baseline covers a full temperature cycle."""
    return simulate_scenario(monitor.config, "healthy", n=96, model=monitor.model, rng=100)


@pytest.fixture(scope="module")
def baseline(monitor: Monitor, healthy: list):
    analyses = [monitor.analyse(m.frf, modal=False) for m in healthy]
    return monitor.learn_baseline(analyses, conditions=[m.conditions for m in healthy],
                                  frfs=[m.frf for m in healthy[:8]])


def _after(healthy: list, days: float = 1.0) -> datetime:
    return healthy[-1].timestamp + timedelta(days=days)


def _first_alarm(monitor: Monitor, baseline, data: list) -> tuple[int | None, str | None]:
    """Index (within ``data``) and diagnosed hypothesis of the first alarm."""
    state = None
    for k, m in enumerate(data):
        analysis = monitor.analyse(m.frf, baseline=baseline, modal=False)
        state, _, alarms = monitor.step(state, analysis, m.conditions, baseline)
        if alarms:
            return k, alarms[0].diagnosis.hypothesis
    return None, None


def test_baseline_follows_the_temperature(monitor: Monitor, baseline, healthy: list) -> None:
    # the bearing factors depend on the temperature through the preload (1 %/K, Hertzian law ~ preload^0.36):
    # the baseline must have learned that slope, else the daily cycle (+-4 K) would look like a +-1.4 % fault
    assert baseline.conditions == ("temperature",)
    slope = baseline.coefficients[1] / baseline.spread[0]  # d log-factor / dK at the centre
    direction = monitor.estimator.direction("preload")
    # expected slope: d ln k / d ln P x d ln P / dT, with d ln P / dT = 0.01 at the nominal preload
    np.testing.assert_allclose(slope[:2], 0.01 * direction[:2], rtol=0.05)  # 5 %: quadratic terms of the law
    assert np.all(baseline.std < 1e-3)  # healthy scatter after compensation: far below the 0.5 % resolution


@pytest.mark.slow
@pytest.mark.extended(reason="the 95 % rate over 20 trials; one 10 % front-bearing loss detected at once and "
                             "diagnosed as the front bearing: tests/cli/test_monitor_cli.py::"
                             "test_chain_records_and_reports_the_fault")
def test_front_bearing_loss_is_detected_fast_and_diagnosed(monitor: Monitor, baseline, healthy: list) -> None:
    # done-means: a 10 % drop of the front bearing stiffness is detected within 5 measurements and diagnosed as
    # the front bearing (not the rear bearing or a screw) in at least 95 % of trials
    trials = 20
    delays, verdicts = [], []
    for seed in range(trials):
        data = simulate_scenario(monitor.config, "bearing-loss", n=5, fault_at=0, component="front",
                                 severity=0.10, model=monitor.model, rng=200 + seed,
                                 start=_after(healthy, 1 + seed / 7))
        k, hyp = _first_alarm(monitor, baseline, data)
        delays.append(k)
        verdicts.append(hyp)
    assert all(d is not None and d < 5 for d in delays), delays
    assert sum(v == "front" for v in verdicts) >= 0.95 * trials, verdicts


@pytest.mark.slow
@pytest.mark.extended(reason="the 90 % rate over 20 trials; one loosening screw located (and graded): "
                             "test_loosening_screw_escalates")
def test_loose_screw_is_located(monitor: Monitor, baseline, healthy: list) -> None:
    # done-means: one housing screw losing 50 % of its stiffness is located in at least 90 % of trials; the
    # screws come in mirror pairs (x = +-0.048 m), which only the cross responses tell apart
    trials = 20
    rng = np.random.default_rng(7)
    correct = 0
    for seed in range(trials):
        screw = f"screw{rng.integers(1, 5)}"
        data = simulate_scenario(monitor.config, "bearing-loss", n=5, fault_at=0, component=screw, severity=0.5,
                                 model=monitor.model, rng=300 + seed, start=_after(healthy, 1 + seed / 5))
        k, hyp = _first_alarm(monitor, baseline, data)
        correct += k is not None and hyp == screw
    assert correct >= 0.9 * trials


def _false_alarms(monitor: Monitor, baseline, data: list) -> int:
    """Alarms the chain raises over ``data`` (one chart state carried through)."""
    state, alarms = None, 0
    for m in data:
        analysis = monitor.analyse(m.frf, baseline=baseline, modal=False)
        state, _, raised = monitor.step(state, analysis, m.conditions, baseline)
        alarms += len(raised)
    return alarms


@pytest.mark.slow
def test_false_alarms_over_ten_healthy_days(monitor: Monitor, baseline, healthy: list) -> None:
    # the done-means' ten days of daily temperature cycles (+-4 K) and wandering temperature, new noise, sampled
    # every 75 min instead of 15 (1000 healthy measurements at <= 0.1 % false alarms, against an independent
    # generator with cold starts and a lagging sensor: tests/monitor/test_calibration.py, extended): the same span of conditions the baseline must compensate, in 200 chart steps.
    # The mark is the done-means' 1 %: at most 2 of 200 (the charts are designed for 0.1 %: 0.2 expected)
    data = simulate_scenario(monitor.config, "healthy", n=200, model=monitor.model, rng=401,
                             interval=timedelta(minutes=75), start=_after(healthy))
    temperatures = [m.conditions["temperature"] for m in data]
    assert data[-1].timestamp - data[0].timestamp > timedelta(days=10)
    assert min(temperatures) < 18.5  # the daily cycle's extremes (22 +- 4 degC) are reached
    assert max(temperatures) > 25.5
    assert _false_alarms(monitor, baseline, data) <= 2


def test_preload_loss_is_told_from_a_bearing_loss(monitor: Monitor, baseline, healthy: list) -> None:
    # a preload loss softens both bearings in the ratio the Hertzian law sets; the diagnosis must name the
    # preload, and its size must be the simulated one
    data = simulate_scenario(monitor.config, "preload-loss", n=3, fault_at=0, severity=0.4, model=monitor.model,
                             rng=5, start=_after(healthy))
    state = None
    for m in data:
        analysis = monitor.analyse(m.frf, baseline=baseline, modal=False)
        state, _, alarms = monitor.step(state, analysis, m.conditions, baseline)
        if alarms:
            break
    assert alarms[0].diagnosis.hypothesis == "preload"
    # the truth: the preload relative to its healthy value at this temperature
    expected = m.truth["preload"] / (1 + 0.01 * (m.conditions["temperature"] - 22.0)) - 1
    assert alarms[0].diagnosis.change == pytest.approx(expected, abs=0.02)  # first-order signature of a 40 % change
    assert alarms[0].severity == "intolerable"


def test_loosening_screw_escalates(monitor: Monitor, baseline, healthy: list) -> None:
    # a screw loosening from 100 % to 50 % raises one alarm per grade, never two of the same grade
    data = simulate_scenario(monitor.config, "loosening-screw", n=16, fault_at=0, component="screw3",
                             severity=0.5, model=monitor.model, rng=6, start=_after(healthy))
    state, raised = None, []
    for m in data:
        analysis = monitor.analyse(m.frf, baseline=baseline, modal=False)
        state, _, alarms = monitor.step(state, analysis, m.conditions, baseline)
        raised += [(m.index, a) for a in alarms]
    grades = [a.severity for _, a in raised]
    assert grades == ["tolerable", "conditionally tolerable", "intolerable"]
    assert {a.component for _, a in raised} == {"screw3"}
    # each grade is raised when the true loss crosses its threshold (5 %, 25 %), give or take one measurement
    for index, alarm in raised[1:]:
        lost = 1 - data[index].truth["screw3"]
        assert lost >= {"conditionally tolerable": 0.05, "intolerable": 0.25}[alarm.severity] - 0.04


def test_modal_and_frf_features(monitor: Monitor, baseline, healthy: list) -> None:
    data = simulate_scenario(monitor.config, "bearing-loss", n=1, fault_at=0, severity=0.1, model=monitor.model,
                             rng=8, start=_after(healthy))
    analysis = monitor.analyse(data[0].frf, baseline=baseline)
    # reference: the exact modes of the model at the simulated parameters
    p = monitor.model.vector(dict(monitor.config.params))
    k = monitor.model.parameter_names.index("preload")
    p[k] = data[0].truth["preload"]
    for name in monitor.config.component("front").parameters:
        p[monitor.model.parameter_names.index(name)] *= 0.9
    exact = monitor.model.system(p).modes("exact")
    found = np.isfinite(analysis.frequency)
    assert found.sum() >= 8  # the LSCF finds most of the ten modes in the band at order 24
    numbers = np.array(monitor.mode_numbers)[found] - 1
    error_f = np.abs(analysis.frequency[found] / exact.frequency[numbers] - 1)
    error_z = np.abs(analysis.damping[found] / exact.damping[numbers] - 1)
    # 1 % FRF noise at order 24: the well-excited modes within 0.1 %, a weak one near the band edge within 1.5 %
    assert np.median(error_f) < 1e-3
    assert error_f.max() < 0.015
    assert np.median(error_z) < 0.05
    assert error_z.max() < 0.5
    assert analysis.frac is not None
    assert analysis.csf is not None
    assert 0.0 < analysis.frac < 1.0
    assert 0.0 < analysis.csf < 1.0
    healthy_analysis = monitor.analyse(healthy[-1].frf, baseline=baseline, modal=False)
    assert healthy_analysis.csf > analysis.csf  # the fault moved the operating shapes away from the healthy ones


def test_time_data_are_turned_into_frfs(monitor: Monitor, spindle: NumericModel) -> None:
    from cappe.identify import random_noise
    from cappe.io import TimeData
    from cappe.systems import time_response
    from cappe.systems.frf import FRFData

    # 25 kHz: the simulator holds the force constant between samples (zero-order hold), which turns the sampled
    # FRF into H(w) exp(-i w T / 2) sinc(w T / 2); that known hold is divided out below (a real acquisition has
    # the same anti-aliasing filter on force and response, which cancels instead)
    fs, duration = 25000.0, 8.0
    channels = {}
    for k, name in enumerate(monitor.config.inputs):
        signal = random_noise(fs=fs, duration=duration, rms=20.0, band=(0.0, 2000.0), rng=10 + k, name=name)
        channels[name] = signal.channel(name)
    force = TimeData.from_rate(fs, channels)
    p = spindle.vector()
    for name in ("krx", "kry"):
        p[spindle.parameter_names.index(name)] *= 0.8
    data = time_response(spindle.system(p), force, outputs=list(monitor.config.outputs), noise=0.01, rng=11)
    frf = monitor.prepare(data, nperseg=25000)  # the pre-processing step: H1 of three simultaneous inputs
    half = np.pi * frf.freq / fs
    hold = np.exp(-1j * half) * np.sinc(half / np.pi)
    unheld = FRFData(frf.freq, frf.H / hold, frf.input_names, frf.output_names, frf.output_quantities)
    analysis = monitor.analyse(unheld, modal=False)
    factors = dict(zip(monitor.estimator.names, analysis.estimate.factor, strict=True))
    # Welch H1 with 1 Hz lines, 1 % output noise, 8 averages: a few tenths of a percent on modes damped 1-4 %
    assert factors.pop("rear") == pytest.approx(0.8, rel=0.01)
    np.testing.assert_allclose(list(factors.values()), 1.0, atol=0.01)


def test_step_errors(monitor: Monitor, baseline, healthy: list) -> None:
    analysis = monitor.analyse(healthy[0].frf, modal=False)
    with pytest.raises(DataError, match="operating condition 'temperature'"):
        monitor.step(None, analysis, {}, baseline)
    with pytest.raises(DataError, match="FRF data lack channels"):
        monitor.analyse(healthy[0].frf.__class__(healthy[0].frf.freq, healthy[0].frf.H[:1], ("Fx", "Fy", "Fz"),
                                                 ("sx",)))


def test_scenarios_tell_the_truth(monitor: Monitor) -> None:
    start = datetime(2026, 3, 1, tzinfo=UTC)
    data = simulate_scenario(monitor.config, "loosening-screw", n=5, fault_at=1, component="screw2", severity=0.4,
                             model=monitor.model, rng=1, start=start, noise=0.0)
    assert [m.fault for m in data] == [None, "screw2", "screw2", "screw2", "screw2"]
    np.testing.assert_allclose([m.truth["screw2"] for m in data], [1.0, 1.0, 1 - 0.4 / 3, 1 - 0.8 / 3, 0.6])
    assert data[1].timestamp - data[0].timestamp == timedelta(minutes=15)
    # noise-free data are the model's own FRFs at those parameters
    p = monitor.model.vector()
    p[monitor.model.parameter_names.index("preload")] = data[4].truth["preload"]
    for name in monitor.config.component("screw2").parameters:
        p[monitor.model.parameter_names.index(name)] *= 0.6
    exact = monitor.model.system(p).frf(data[4].frf.freq, list(monitor.config.inputs), list(monitor.config.outputs))
    np.testing.assert_allclose(data[4].frf.H, exact.H, rtol=1e-12)
    with pytest.raises(DataError, match="unknown scenario"):
        simulate_scenario(monitor.config, "earthquake", model=monitor.model)
    with pytest.raises(DataError, match="no component 'spindle'"):
        simulate_scenario(monitor.config, "bearing-loss", component="spindle", model=monitor.model)
    with pytest.raises(DataError, match="severity must be a fraction"):
        simulate_scenario(monitor.config, "bearing-loss", severity=1.5, model=monitor.model)


@pytest.mark.slow
def test_a_machine_the_model_describes_only_roughly(monitor: Monitor, healthy: list) -> None:
    # the real machine is not the model: masses 3 % heavier, every damping 30 % higher. The component factors
    # cannot absorb that (a residual ten times the noise), so the baseline learns how well the model fits this
    # machine, and faults are still found, located and sized against it
    from dataclasses import replace

    model = monitor.model
    real = dict(monitor.config.params)
    for name in ("ms", "mh"):
        real[name] = 1.03 * model.structure.parameter(name).value
    for name in ("cfx", "cfy", "cfz", "crx", "cry", "chx", "chy", "chz"):
        real[name] = 1.3 * model.structure.parameter(name).value
    machine = replace(monitor.config, params=real)
    # a day of measurements every 30 minutes (the README's day; every 15 minutes adds nothing the test asks)
    days = simulate_scenario(machine, "healthy", n=48, interval=timedelta(minutes=30), model=model, rng=500)
    analyses = [monitor.analyse(m.frf, modal=False) for m in days]
    baseline = monitor.learn_baseline(analyses, conditions=[m.conditions for m in days])
    assert baseline.sigma > 5 * 0.01 / np.sqrt(2)  # the model error dominates the 1 % noise
    start = _after(days)
    for k, (scenario, component, severity) in enumerate([("bearing-loss", "front", 0.1),
                                                         ("bearing-loss", "screw4", 0.5),
                                                         ("preload-loss", None, 0.4)]):
        data = simulate_scenario(machine, scenario, n=3, fault_at=0, component=component, severity=severity,
                                 model=model, rng=510 + k, start=start + timedelta(days=k))
        index, hypothesis = _first_alarm(monitor, baseline, data)
        assert index == 0
        assert hypothesis == (component or "preload")
    calm = simulate_scenario(machine, "healthy", n=60, model=model, rng=520, start=start + timedelta(days=5))
    assert _first_alarm(monitor, baseline, calm) == (None, None)
