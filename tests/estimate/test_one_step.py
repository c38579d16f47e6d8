"""One-step output error in the time domain (thesis eq. 3.108) and on FRFs.

Data are simulated with cappe.systems.time_response (zero-order hold, seeded noise), independently of the
estimator's modal-form simulation; delayed data come from a simulation on a finer grid with the held input
shifted by whole fine samples, so they do not share the estimator's delay formula either.

Truth of the two-mass rig (thesis Table 5.1 ranges, the issue lets us pick): the nominal masses and stiffnesses
with c11 = 30 N s/m and c22 = 3 N s/m, so that the modes have 1.0 % and 0.24 % damping (the nominal c22 gives
0.04 %).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.signal as sig

from cappe.estimate._one_step import (
    OneStepEstimator,
    OneStepFRFEstimator,
    _TimeModel,
    frf_derivatives,
    random_starts,
)
from cappe.estimate._space import ParameterSpace
from cappe.exceptions import ConvergenceWarning, DataError, DataWarning
from cappe.identify import estimate_frf, random_noise
from cappe.io.timedata import TimeData
from cappe.model import NumericModel
from cappe.systems import time_response
from cappe.systems.frf import FRFData

NAMES = ("m1", "m2", "k11", "k12", "k22", "c11", "c22")
TRUTH = {"m1": 1.39, "m2": 1.09, "k11": 1.38e6, "k12": 0.12e6, "k22": 0.24e6, "c11": 30.0, "c22": 3.0}
P_TRUE = np.array([TRUTH[n] for n in NAMES])
FS = 1000.0  # Hz: modes at 90 and 166 Hz
#: mixed 50 % patterns: masses and stiffnesses moved in opposite directions, so both natural frequencies start
#: far off (a uniform x1.5 or x0.5 leaves them unchanged and is easy)
PATTERN_A = (1.5, 0.5, 0.5, 1.5, 1.5, 0.5, 1.5)
PATTERN_B = (0.5, 1.5, 1.5, 0.5, 0.5, 1.5, 0.5)


def _start(pattern):
    return {n: TRUTH[n] * f for n, f in zip(NAMES, pattern, strict=True)}


@pytest.fixture(scope="module")
def rig(two_mass):
    return NumericModel(two_mass)


@pytest.fixture(scope="module")
def excitation():
    return random_noise(fs=FS, duration=2.0, rms=10.0, rng=11, name="F1")


@pytest.fixture(scope="module")
def clean(rig, excitation):
    return time_response(rig.system(TRUTH), excitation, outputs=["d1", "d2"])


@pytest.fixture(scope="module")
def noisy(rig, excitation):
    # separate seeds for the excitation (11) and the noise (12)
    return time_response(rig.system(TRUTH), excitation, outputs=["d1", "d2"], noise=0.01, rng=12)


def _delayed_record(rig, excitation, *, fine_shift, factor=2, offsets=(0.0, 0.0), noise=0.0, rng=None):
    """Outputs to the held input delayed by ``fine_shift / factor`` samples: simulated on a grid ``factor`` times
    finer with the held input shifted by whole fine samples, then sampled at the original rate."""
    u = excitation.values[0]
    u_fine = np.repeat(u, factor)
    delayed = np.concatenate([np.zeros(fine_shift), u_fine[: u_fine.size - fine_shift]])
    fine = time_response(rig.system(TRUTH), TimeData.from_rate(FS * factor, {"F1": delayed}), outputs=["d1", "d2"])
    y = fine.values[1:, ::factor]
    if noise:
        gen = np.random.default_rng(rng)
        y = y + noise * np.sqrt(np.mean(y**2, axis=1, keepdims=True)) * gen.standard_normal(y.shape)
    return TimeData.from_rate(FS, {"F1": u, "d1": y[0] + offsets[0], "d2": y[1] + offsets[1]})


# -- the simulation --------------------------------------------------------------------------------------------
def test_modal_simulation_matches_scipy_dlsim_and_shifts_by_whole_samples(rig, excitation):
    system = rig.system(TRUTH)
    ss = system.state_space(["F1"], ["d1", "d2", "a1"])
    u = excitation.values[0][:, None]
    # peer: scipy's discrete simulation of the ZOH model (state-space recursion, no modal form)
    _, y_ref, _ = sig.dlsim(sig.cont2discrete((ss.A, ss.B, ss.C, ss.D), 1 / FS, method="zoh"), u)
    sim = _TimeModel(rig, None, ["F1"], ["d1", "d2", "a1"], 1 / FS)
    modes = sim.modes(rig.vector(TRUTH), np.ones(3))
    y = sim.simulate(modes, u, 0.0)
    # rounding of two different recursions over 2000 steps: 1e-10 of the peak
    peak = np.abs(y_ref).max(axis=0)
    np.testing.assert_allclose(y / peak, y_ref / peak, rtol=0, atol=1e-10)
    # a delay of exactly 3 samples is the same response shifted by 3 samples (zeros before)
    y3 = sim.simulate(modes, u, 3.0)
    np.testing.assert_allclose(y3[3:] / peak, y[:-3] / peak, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(y3[:3], 0.0)


def test_random_starts_are_reproducible_and_inside_the_bounds(two_mass):
    space = ParameterSpace.from_model(two_mass, ["m1", "k11"])
    a = random_starts(space, 5, np.random.default_rng(3))
    b = random_starts(space, 5, np.random.default_rng(3))
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a[0], space.start)  # the start comes first
    assert np.all((a >= space.lower) & (a <= space.upper))
    with pytest.raises(DataError, match=r"starts must be an integer >= 1 .*; got 0"):
        random_starts(space, 0, np.random.default_rng(0))


# -- time domain: accuracy and convergence ---------------------------------------------------------------------
def test_noise_free_data_give_the_truth_from_a_start_50_percent_off(two_mass, clean):
    est = OneStepEstimator(two_mass, NAMES, start=_start(PATTERN_A)).fit(clean).estimate_
    assert est.success
    # noise-free: the optimum is the truth to the optimizer's tolerance (1e-6 relative is far below any noise)
    np.testing.assert_allclose(est.values, P_TRUE, rtol=1e-6)
    assert abs(est.diagnostics["delay"]["samples"]) < 1e-6
    assert est.method == "one-step"
    doc = est.to_dict()
    assert list(doc["parameters"]) == list(NAMES)  # nuisance parameters stay out of the parameters
    assert doc["diagnostics"]["offsets"]["value"]["d1"][0] == pytest.approx(0.0, abs=1e-12)
    # the continuation ran three weighted stages before the exact fit
    assert [s["zeta"] for s in est.diagnostics["stages"]] == [0.3, 0.1, 0.03]


@pytest.mark.parametrize("pattern", [PATTERN_A, PATTERN_B])
def test_one_percent_noise_within_two_percent_from_50_percent_off(two_mass, noisy, pattern):
    est = OneStepEstimator(two_mass, NAMES, start=_start(pattern), rng=0).fit(noisy).estimate_
    assert est.success
    err = est.values / P_TRUE - 1
    # the target: every parameter within 2 % (the thesis's one-step needed manual guidance)
    assert np.all(np.abs(err) < 0.02), dict(zip(NAMES, err, strict=True))
    # honest uncertainty: the truth lies within 4 standard errors of every estimate (about 1 in 15 000 to miss)
    assert est.identifiable.all()
    assert np.all(np.abs(est.values - P_TRUE) < 4 * est.std), (est.values - P_TRUE) / est.std


def test_plain_output_error_without_continuation_is_trapped(two_mass, clean):
    # measured motivation for the continuation: on the same (noise-free, 0.5 s) record and start, plain output
    # error ends in a wrong valley while the continuation finds the truth
    short = TimeData.from_rate(FS, {c: clean.values[i, :500] for i, c in enumerate(clean.channels)})
    with pytest.warns(ConvergenceWarning, match="failed its residual tests: the residuals correlate with the inputs"):
        plain = OneStepEstimator(two_mass, NAMES, start=_start(PATTERN_A), continuation=(), delay=False).fit(short)
    assert np.max(np.abs(plain.estimate_.values / P_TRUE - 1)) > 0.1
    assert not plain.estimate_.success  # the wrong valley says so (issue 21)
    guided = OneStepEstimator(two_mass, NAMES, start=_start(PATTERN_A), delay=False).fit(short)
    np.testing.assert_allclose(guided.estimate_.values, P_TRUE, rtol=1e-6)


def test_delay_of_one_and_a_half_samples_and_offsets_are_recovered(two_mass, rig, excitation):
    offsets = (2e-6, -1e-6)  # m, about 10 % of each channel's RMS
    data = _delayed_record(rig, excitation, fine_shift=3, offsets=offsets)
    unknowns = ["k11", "k22", "c11", "c22"]
    start = {"k11": 1.0e6, "k22": 0.3e6, "c11": 20.0, "c22": 2.0}
    est = OneStepEstimator(two_mass, unknowns, values=TRUTH, start=start).fit(data).estimate_
    # noise-free data from an independent delay construction: exact up to the optimizer's tolerance
    np.testing.assert_allclose(est.values, [TRUTH[n] for n in unknowns], rtol=1e-6)
    assert est.diagnostics["delay"]["samples"] == pytest.approx(1.5, abs=1e-6)
    assert est.diagnostics["delay"]["value"] == pytest.approx(1.5 / FS, rel=1e-6)
    np.testing.assert_allclose([est.diagnostics["offsets"]["value"][c][0] for c in ("d1", "d2")], offsets,
                               rtol=1e-6)
    # ignoring the delay biases the estimates (the data are not those of the undelayed model)
    with pytest.warns(ConvergenceWarning, match="failed its residual tests"):
        plain = OneStepEstimator(two_mass, unknowns, values=TRUTH, start=start, delay=False).fit(data).estimate_
    assert np.max(np.abs(plain.values / est.values - 1)) > 1e-3
    assert plain.diagnostics["fit_test"] == "failed"  # and the residual test says so


def test_delay_with_noise_is_within_its_uncertainty(two_mass, rig, excitation):
    data = _delayed_record(rig, excitation, fine_shift=3, noise=0.01, rng=5)
    est = OneStepEstimator(two_mass, ["k11", "k22"], values=TRUTH, start={"k11": 1.2e6, "k22": 0.3e6}).fit(data)
    est = est.estimate_
    delay = est.diagnostics["delay"]
    # 4 standard errors (the delay is determined to a few thousandths of a sample)
    assert abs(delay["value"] - 1.5 / FS) < 4 * delay["std"]
    assert delay["std"] < 0.01 / FS


def test_acceleration_outputs_keep_the_delay_smooth(two_mass, rig, excitation):
    # accelerations feed the input straight through; with the delay estimated near zero the cost must stay
    # smooth there, or the finite-difference Jacobian sees a jump and the uncertainty analysis breaks down
    data = time_response(rig.system(TRUTH), excitation, outputs=["d1", "a1", "a2"], noise=0.01, rng=13)
    est = OneStepEstimator(two_mass, ["k11", "k22", "c11"], values=TRUTH).fit(data).estimate_
    truth = np.array([TRUTH["k11"], TRUTH["k22"], TRUTH["c11"]])
    assert est.identifiable.all()
    assert np.all(np.abs(est.values - truth) < 4 * est.std)  # 4 standard errors
    assert abs(est.diagnostics["delay"]["samples"]) < 4 * est.diagnostics["delay"]["std"] * FS


def test_record_not_starting_at_rest_needs_the_initial_state(two_mass, clean):
    cut = TimeData.from_rate(FS, {c: clean.values[i, 700:] for i, c in enumerate(clean.channels)})
    unknowns = ["k11", "k22"]
    start = {"k11": 1.3e6, "k22": 0.25e6}
    with_state = OneStepEstimator(two_mass, unknowns, values=TRUTH, start=start, initial_state=True).fit(cut)
    with_state = with_state.estimate_
    np.testing.assert_allclose(with_state.values, [TRUTH[n] for n in unknowns], rtol=1e-6)  # noise-free: exact
    with pytest.warns(ConvergenceWarning, match="failed its residual tests"):
        at_rest = OneStepEstimator(two_mass, unknowns, values=TRUTH, start=start).fit(cut).estimate_
    assert np.max(np.abs(at_rest.values / with_state.values - 1)) > 1e-4  # the start-up transient is misfitted
    assert not at_rest.success


def test_several_records_are_fitted_together(two_mass, rig):
    # F1 drives mass 1 in one record, F2 drives mass 2 in the other; m2 and c22 are unknown
    f1 = random_noise(fs=FS, duration=0.5, rms=10.0, rng=21, name="F1")
    f2 = random_noise(fs=FS, duration=0.5, rms=10.0, rng=22, name="F2")
    records = [time_response(rig.system(TRUTH), f, outputs=["d1", "d2"]) for f in (f1, f2)]
    est = OneStepEstimator(two_mass, ["m2", "c22"], values=TRUTH, delay=False, start={"m2": 1.3, "c22": 2.0})
    est.fit(records)
    np.testing.assert_allclose(est.estimate_.values, [TRUTH["m2"], TRUTH["c22"]], rtol=1e-6)  # noise-free
    assert est.estimate_.diagnostics["inputs"] == ["F1", "F2"]


def test_one_step_errors_name_what_is_wrong(two_mass, clean):
    with pytest.raises(DataError, match=r"time data lacks the output channels \['v1'\] needed"):
        OneStepEstimator(two_mass, ["k11"], outputs=["d1", "v1"]).fit(clean)
    with pytest.raises(DataError, match=r"time data has none of the model's inputs \['F1', 'F2'\]"):
        OneStepEstimator(two_mass, ["k11"]).fit(clean.select(["d1", "d2"]))
    with pytest.raises(DataError, match=r"outputs \['x9'\] are not outputs of the model"):
        OneStepEstimator(two_mass, ["k11"], outputs=["x9"]).fit(clean)
    with pytest.raises(DataError, match=r"needs TimeData \(or a list of TimeData records\); got dict"):
        OneStepEstimator(two_mass, ["k11"]).fit({"F1": [1.0]})
    flat = TimeData.from_rate(FS, {"F1": clean.channel("F1"), "d1": np.full(clean.n_samples, 1e-6)})
    with pytest.raises(DataError, match=r"output channels \['d1'\] are constant"):
        OneStepEstimator(two_mass, ["k11"]).fit(flat)
    with pytest.raises(DataError, match=r"continuation must list artificial damping ratios > 0; got \[0.3, -1.0\]"):
        OneStepEstimator(two_mass, ["k11"], continuation=(0.3, -1.0)).fit(clean)
    with pytest.raises(DataError, match=r"argument 'max_delay' must be > 0 s; got -2"):
        OneStepEstimator(two_mass, ["k11"], max_delay=-2).fit(clean)
    slow = TimeData.from_rate(FS / 2, {c: clean.values[i] for i, c in enumerate(clean.channels)})
    with pytest.raises(DataError, match=r"time data record 1 has sample time 0.002 s; every record must share 0.001"):
        OneStepEstimator(two_mass, ["k11"]).fit([clean, slow])
    short = TimeData.from_rate(FS, {c: clean.values[i, :4] for i, c in enumerate(clean.channels)})
    with pytest.raises(DataError, match=r"time data have 4 samples of 2 outputs; too few for 7 unknowns"):
        OneStepEstimator(two_mass, NAMES).fit(short)


# -- frequency domain --------------------------------------------------------------------------------------------
def test_frf_derivatives_match_central_differences_with_hysteresis_and_rates(slide):
    nm = NumericModel(slide)
    freq = np.linspace(5.0, 400.0, 60)
    names = ["km", "kg0", "Fp", "cm", "eta", "ms"]  # Fp enters non-linearly (preload law), eta through H
    position = {"z": 0.25}
    d = frf_derivatives(model=nm, freq=freq, position=position, parameters=names)
    p0 = nm.vector()
    for k, name in enumerate(names):
        j = nm.parameter_names.index(name)
        # the loss factor moves the FRF so little that a 1e-5 step's difference sits at the FRF's rounding level
        # (relative errors ~1e-6 there, falling with the step): it takes 1e-3, where truncation is still ~1e-8
        h = (1e-3 if name == "eta" else 1e-5) * p0[j]
        plus, minus = p0.copy(), p0.copy()
        plus[j] += h
        minus[j] -= h
        fd = (nm.system(plus, position).frf(freq).H - nm.system(minus, position).frf(freq).H) / (2 * h)
        # central differences with a 1e-5 relative step: truncation ~1e-10, rounding ~1e-11 relative
        np.testing.assert_allclose(d.dH[k], fd, rtol=0, atol=1e-6 * np.abs(fd).max(), err_msg=name)
    np.testing.assert_allclose(d.H, nm.system(p0, position).frf(freq).H, rtol=1e-12)


def test_frf_derivatives_of_velocity_and_acceleration_outputs(rig):
    freq = np.array([50.0, 120.0, 200.0])
    d = frf_derivatives(model=rig, freq=freq, params=TRUTH, inputs=["F2"], outputs=["d1", "v1", "a1"],
                        parameters=["k12"])
    w = 2 * np.pi * freq
    # closed form: velocity = j w displacement, acceleration = -w^2 displacement, also for the derivatives
    np.testing.assert_allclose(d.dH[0, 1, 0], 1j * w * d.dH[0, 0, 0], rtol=1e-12)
    np.testing.assert_allclose(d.dH[0, 2, 0], -(w**2) * d.dH[0, 0, 0], rtol=1e-12)
    # static closed form: H11(0) = (k12 + k22) / det K, so dH11/dk11 = -H11^2 at 0 Hz
    s = frf_derivatives(model=rig, freq=[0.0], params=TRUTH, inputs=["F1"], outputs=["d1"], parameters=["k11"])
    assert s.dH[0, 0, 0, 0] == pytest.approx(-s.H[0, 0, 0] ** 2, rel=1e-12)


@pytest.mark.parametrize("residual", ["log", "relative"])
def test_frf_estimator_jacobian_matches_finite_differences(two_mass, rig, residual):
    frf = rig.system(TRUTH).frf(np.arange(20.0, 300.0, 2.0), ["F1"], ["d1", "d2"])
    coherence = np.clip(0.5 + 0.5 * np.cos(frf.freq / 40.0), 0.05, 0.99) * np.ones(frf.H.shape)
    data = FRFData(frf.freq, frf.H, frf.input_names, frf.output_names, frf.output_quantities, coherence)
    est = OneStepFRFEstimator(two_mass, NAMES, residual=residual, delay=True)
    space = ParameterSpace.from_model(two_mass, NAMES)
    problem = est._problem(rig, space, data)
    theta = np.append(P_TRUE * np.array(PATTERN_A) ** 0.2, problem.shift + 2e-4)  # off the optimum, with delay
    jac = problem.jacobian(theta)
    for j in range(theta.size):
        h = 1e-6 * abs(theta[j])
        plus, minus = theta.copy(), theta.copy()
        plus[j] += h
        minus[j] -= h
        fd = (problem.residuals(plus) - problem.residuals(minus)) / (2 * h)
        # central differences, 1e-6 relative step: agreement to 1e-6 of the column's size
        np.testing.assert_allclose(jac[:, j], fd, rtol=0, atol=1e-6 * np.abs(fd).max(), err_msg=str(j))


def test_frf_noise_free_exact_recovery_and_delay(two_mass, rig):
    freq = np.arange(10.0, 400.0, 0.5)  # resolves the 0.4 Hz half-power band of the 90 Hz mode
    frf = rig.system(TRUTH).frf(freq, ["F1"], ["d1", "d2"])
    start = {n: TRUTH[n] * f**0.5 for n, f in zip(NAMES, PATTERN_A, strict=True)}  # 20 to 30 % off
    est = OneStepFRFEstimator(two_mass, NAMES, start=start).fit(frf).estimate_
    np.testing.assert_allclose(est.values, P_TRUE, rtol=1e-6)  # noise-free: exact
    tau = 3e-4
    delayed = FRFData(freq, frf.H * np.exp(-2j * np.pi * freq * tau), frf.input_names, frf.output_names,
                      frf.output_quantities)
    est = OneStepFRFEstimator(two_mass, ["k11", "k22"], values=TRUTH, delay=True, residual="relative").fit(delayed)
    est = est.estimate_
    np.testing.assert_allclose(est.values, [TRUTH["k11"], TRUTH["k22"]], rtol=1e-6)
    assert est.diagnostics["delay"]["value"] == pytest.approx(tau, rel=1e-6)


def test_frf_from_measured_time_data_within_two_percent(two_mass, rig):
    # a measurement of a continuous input: periodic random band-limited to 450 Hz simulated on an 8x finer grid
    # (its hold changes the magnitude by sinc(f / 8 kHz), < 0.08 % below 170 Hz) and sampled at 1 kHz, 1 % output
    # noise; leakage-free FRF from the last 4 of 5 periods
    factor, period, n_periods = 8, 2000, 5
    force = random_noise(fs=FS * factor, duration=2.0 * n_periods, rms=10.0, band=(5.0, 450.0), periodic=True,
                         n_periods=n_periods, rng=31)
    fine = time_response(rig.system(TRUTH), TimeData.from_rate(FS * factor, {"F1": force.values[0]}),
                         outputs=["d1", "d2"])
    sampled = fine.values[:, ::factor][:, period:]
    gen = np.random.default_rng(32)
    y = sampled[1:] + 0.01 * np.sqrt(np.mean(sampled[1:] ** 2, axis=1, keepdims=True)) * gen.standard_normal(
        sampled[1:].shape)
    data = TimeData.from_rate(FS, {"F1": sampled[0], "d1": y[0], "d2": y[1]})
    with pytest.warns(DataWarning, match="low coherence"):
        frf = estimate_frf(data, inputs="F1", outputs=["d1", "d2"], nperseg=period, noverlap=0, window="boxcar",
                           detrend=None)
    # the fine grid's hold lags by half a fine sample: the delay nuisance takes it
    est = OneStepFRFEstimator(two_mass, NAMES, band=(20.0, 400.0), delay=True, start=_start(PATTERN_A), starts=4,
                              rng=1).fit(frf).estimate_
    err = est.values / P_TRUE - 1
    assert np.all(np.abs(err) < 0.02), dict(zip(NAMES, err, strict=True))
    assert np.all(np.abs(est.values - P_TRUE) < 4 * est.std)  # honest: within 4 standard errors
    assert est.diagnostics["delay"]["value"] == pytest.approx(0.5 / (FS * factor), rel=0.05)


def test_frf_errors_name_what_is_wrong(two_mass, rig):
    frf = rig.system(TRUTH).frf(np.linspace(10, 300, 50), ["F1"], ["d1"])
    with pytest.raises(DataError, match=r"FRF data lacks the output channels \['d2'\] needed"):
        OneStepFRFEstimator(two_mass, ["k11"], outputs=["d1", "d2"]).fit(frf)
    with pytest.raises(DataError, match=r"needs FRFData; got TimeData"):
        OneStepFRFEstimator(two_mass, ["k11"]).fit(TimeData.from_rate(FS, {"F1": [0.0, 1.0]}))
    with pytest.raises(DataError, match=r"no line above 0 Hz inside band \(400.0, 500.0\)"):
        OneStepFRFEstimator(two_mass, ["k11"], band=(400.0, 500.0)).fit(frf)
    with pytest.raises(DataError, match=r"band must satisfy 0 <= f_lo < f_hi \(Hz\); got \(50.0, 20.0\)"):
        OneStepFRFEstimator(two_mass, ["k11"], band=(50.0, 20.0)).fit(frf)
    with pytest.raises(DataError, match=r"weighting must be 'coherence' or 'uniform'; got 'snr'"):
        OneStepFRFEstimator(two_mass, ["k11"], weighting="snr").fit(frf)
    with pytest.raises(DataError, match=r"residual must be 'relative' or 'log'; got 'abs'"):
        OneStepFRFEstimator(two_mass, ["k11"], residual="abs").fit(frf)
    # c12 = 0 and k12 = 0 leave mass 2 without a path from F1
    measured = FRFData(frf.freq, np.ones((1, 1, frf.freq.size), complex), ("F1",), ("d2",))
    with pytest.raises(DataError, match=r"the model has no response for the FRF pairs \['d2 / F1'\]"):
        OneStepFRFEstimator(two_mass, ["k11"], values={"k12": 0.0}, bounds={"k11": (1e5, 1e7)}).fit(measured)


# -- time domain: calibration of the stated uncertainty ----------------------------------------------------------
def _scipy_rig(p):
    """State space x = [d1, d2, v1, v2] of the rig from its equations of motion (numpy), F1 in, d1 and d2 out."""
    m = np.diag([p["m1"], p["m2"]])
    k = np.array([[p["k11"] + p["k12"], -p["k12"]], [-p["k12"], p["k12"] + p["k22"]]])
    c = np.array([[p["c11"], 0.0], [0.0, p["c22"]]])  # c12 = 0, the model file's value
    mi = np.linalg.inv(m)
    a = np.block([[np.zeros((2, 2)), np.eye(2)], [-mi @ k, -mi @ c]])
    b = np.vstack([np.zeros((2, 1)), mi[:, :1]])
    return a, b, np.eye(4)[:2], np.zeros((2, 1))


def _independent_response(intersample, n, rng):
    """F1 and the noise-free d1, d2 (n samples at FS) from scipy alone: the exact zero-order-hold recursion
    (``cont2discrete`` + ``dlsim``), or a DAQ record: a smooth force simulated by ``lsim`` at 32x the rate, force and
    responses through the same FIR anti-alias filter (0.45 FS) and decimated (what ``bl`` describes; the linear
    interpolation between the fine samples leaves ~3e-5 of the response, a tenth of the standard errors here)."""
    system = _scipy_rig(TRUTH)
    if intersample == "zoh":
        f = rng.standard_normal(n)
        _, y, _ = sig.dlsim(sig.cont2discrete(system, 1 / FS, method="zoh"), f)
        return f, y
    over = 32
    bb, aa = sig.butter(8, 0.35 * 2 / over)  # 0.35 FS
    fine = sig.lfilter(bb, aa, rng.standard_normal(n * over + 2000))[2000:]
    fine[: n * over // 50] *= np.linspace(0.0, 1.0, n * over // 50)  # starts with the record, at rest
    _, y, _ = sig.lsim(system, fine, np.arange(n * over) / (FS * over))
    h = sig.firwin(32 * over + 1, 0.45 * 2 / over)
    return sig.lfilter(h, 1.0, fine)[::over], sig.lfilter(h, 1.0, y, axis=0)[::over]


@pytest.mark.slow  # 40 fits: 7-10 CPU-s per case
@pytest.mark.parametrize("intersample", ["zoh", "bl"])
def test_stated_standard_errors_match_the_scatter_over_noise_draws(two_mass, intersample):
    """Issue 21: on ten DAQ records one-step's errors were 0.43-0.48 of its stated standard errors (m2, k12, k22,
    c22). Here the stated std of every parameter is compared with the Monte-Carlo scatter of the estimates over 40
    noise draws (1 %) on one record of scipy's making, F1 only, the seven unknowns, with the covariance
    ``covariance="auto"`` picks (Gauss-Newton; the Newey-West sandwich on the one draw in 40 whose whiteness test
    fails). A std twice or half the right one fails (checked by scaling the stated std)."""
    f, y = _independent_response(intersample, 2000, np.random.default_rng(40))
    gen = np.random.default_rng(41)
    z, covered = [], 0
    for _ in range(40):
        noisy = y + 0.01 * np.sqrt(np.mean(y**2, axis=0)) * gen.standard_normal(y.shape)
        data = TimeData.from_rate(FS, {"F1": f, "d1": noisy[:, 0], "d2": noisy[:, 1]})
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)  # a whiteness test fails about once in a hundred
            est = OneStepEstimator(two_mass, NAMES, values={"c12": 0.0}, start=TRUTH, continuation=(),
                                   intersample=intersample).fit(data).estimate_
        z.append((est.values - P_TRUE) / est.std)
        covered += int(np.sum((est.ci95[:, 0] <= P_TRUE) & (P_TRUE <= est.ci95[:, 1])))
    rms = np.sqrt(np.mean(np.square(z), axis=0))
    # 40 draws: rms^2 ~ chi2(40) / 40, so 0.7 and 1.4 lie 2.9 and 3.4 sigma out (one-sided p 0.2 % and 0.03 %)
    assert np.all((rms > 0.7) & (rms < 1.4)), dict(zip(NAMES, rms.round(2), strict=True))
    assert covered >= 0.9 * 40 * len(NAMES)  # the issue's >= 90 % of parameter x draw pairs
