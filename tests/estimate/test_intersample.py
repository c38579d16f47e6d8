"""Intersample behaviour (zoh / foh / bl) on data that cappe did not simulate (issue 21).

The references are written here from the physics of the two-mass rig with numpy and scipy only:

* ``_lsim``: :func:`scipy.signal.lsim`, whose default interpolates the input linearly between samples (a FOH);
* ``_daq``: a continuous simulation at 16x the sample rate of a smooth force, both channels passed through the same
  FIR anti-alias filter and decimated, as a data-acquisition system records them; optionally the force channel is
  advanced by a fraction of a sample (the response lags it).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.signal as sig

from cappe.estimate import estimator_class
from cappe.estimate._one_step import OneStepEstimator
from cappe.exceptions import DataError
from cappe.model import NumericModel
from cappe.systems import TimeData, time_response
from cappe.systems.statespace import band_limited_modal_response, hold_matrices, hold_weights

FS = 2000.0
N = 6000
#: hidden truth of the issue's repro (c12 = 0 is known); modes at 119 Hz (1.4 %) and 85 Hz (0.25 %)
TRUTH = {"m1": 1.25, "m2": 1.0, "k11": 1.5e6, "k12": 0.1e6, "k22": 0.3e6, "c11": 15.0, "c12": 0.0, "c22": 2.0}
UNKNOWNS = ["m1", "m2", "k11", "k12", "k22", "c11", "c22"]


def _rig(p):
    """Continuous state space (x = [d1, d2, v1, v2]) of the two-mass rig from its equations of motion."""
    m = np.diag([p["m1"], p["m2"]])
    k = np.array([[p["k11"] + p["k12"], -p["k12"]], [-p["k12"], p["k12"] + p["k22"]]])
    c = np.array([[p["c11"] + p["c12"], -p["c12"]], [-p["c12"], p["c12"] + p["c22"]]])
    mi = np.linalg.inv(m)
    a = np.block([[np.zeros((2, 2)), np.eye(2)], [-mi @ k, -mi @ c]])
    b = np.vstack([np.zeros((2, 2)), mi])
    return a, b, np.hstack([np.eye(2), np.zeros((2, 2))]), np.zeros((2, 2))


def _force(n, rate, band, rng, inputs=1):
    b, a = sig.butter(8, band / (rate / 2))
    f = sig.lfilter(b, a, rng.standard_normal((n + 2000, inputs)), axis=0)[2000:]
    f[: n // 100] *= np.linspace(0.0, 1.0, n // 100)[:, None]  # the shaker starts with the record, at rest
    return 10.0 * f / np.sqrt(np.mean(f**2, axis=0))


def _lsim(p, f):
    a, b, c, d = _rig(p)
    _, y, _ = sig.lsim((a, b[:, : f.shape[1]], c, d[:, : f.shape[1]]), f, np.arange(f.shape[0]) / FS)
    return y


def _daq(p, rng, *, over=16, delay=0.0, inputs=1):
    a, b, c, d = _rig(p)
    fine = _force(N * over, FS * over, 700.0, rng, inputs)
    _, y, _ = sig.lsim((a, b[:, :inputs], c, d[:, :inputs]), fine, np.arange(fine.shape[0]) / (FS * over))
    h = sig.firwin(32 * over + 1, 0.45 * FS / (over * FS / 2))  # anti-alias filter at 0.45 fs, both channels
    f_rec, y_rec = sig.lfilter(h, 1.0, fine, axis=0), sig.lfilter(h, 1.0, y, axis=0)
    f_rec = np.roll(f_rec, -round(delay * over), axis=0)
    return f_rec[::over], y_rec[::over]


def _record(f, y, noise, rng):
    y = y + noise * np.sqrt(np.mean(y**2, axis=0)) * rng.standard_normal(y.shape)
    channels = {f"F{j + 1}": f[:, j] for j in range(f.shape[1])}
    return TimeData.from_rate(FS, {**channels, "d1": y[:, 0], "d2": y[:, 1]})


def _z_scores(est):
    return {n: (v - TRUTH[n]) / s for n, v, s in zip(est.names, est.values, est.std, strict=True)}


# -- the discretization -------------------------------------------------------------------------------------------
def test_first_order_hold_equals_scipy_lsim_and_cont2discrete(two_mass):
    ss = NumericModel(two_mass).system(TRUTH).state_space(["F1", "F2"], ["d1", "d2", "a2"])
    f = _force(4000, FS, 700.0, np.random.default_rng(3), inputs=2)
    t = np.arange(f.shape[0]) / FS
    _, ref, _ = sig.lsim((ss.A, ss.B, ss.C, ss.D), f, t)  # linear interpolation between samples
    got, _ = ss.simulate(f, t, intersample="foh")
    # both exact for a linear input; the difference is round-off of 4000 steps
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-10 * np.abs(ref).max(axis=0).max())
    held, _ = ss.simulate(f, t)
    assert np.abs(held - ref).max() > 0.05 * np.abs(ref).max()  # a held input is another signal
    disc = ss.discretize(1 / FS, "foh")
    ad, bd, cd, dd, _ = sig.cont2discrete((ss.A, ss.B, ss.C, ss.D), 1 / FS, method="foh")
    for mine, theirs in ((disc.A, ad), (disc.B, bd), (disc.C, cd), (disc.D, dd)):
        np.testing.assert_allclose(mine, theirs, rtol=1e-12, atol=1e-12 * np.abs(theirs).max())


def test_modal_hold_weights_are_the_diagonal_of_the_hold_matrices():
    lam = np.array([-3.0 + 700.0j, -0.2 + 40.0j, -1e-6 + 1e-3j, -5.0])
    for intersample in ("zoh", "foh"):
        ad, b0, b1 = hold_matrices(np.diag(lam.real), np.eye(4), 1e-3, intersample)  # real parts: a real check
        w0, w1 = hold_weights(lam.real, 1e-3, intersample)
        np.testing.assert_allclose(np.diag(b0), w0.real, rtol=1e-13)
        np.testing.assert_allclose(np.diag(b1), w1.real, rtol=1e-13, atol=1e-20)
        # complex eigenvalues through a 2x2 real block [[s, w], [-w, s]] with eigenvalues s -+ jw
        for mode in lam[:3]:
            block = np.array([[mode.real, mode.imag], [-mode.imag, mode.real]])
            _, m0, m1 = hold_matrices(block, np.eye(2), 1e-3, intersample)
            v0, v1 = hold_weights([mode], 1e-3, intersample)
            np.testing.assert_allclose(m0[0, 0] + 1j * m0[0, 1], v0[0], rtol=1e-12)
            np.testing.assert_allclose(m1[0, 0] + 1j * m1[0, 1], v1[0], rtol=1e-12, atol=1e-22)


def test_band_limited_simulation_matches_a_daq_record(two_mass):
    f, y = _daq(TRUTH, np.random.default_rng(5))
    data = time_response(NumericModel(two_mass).system(TRUTH), TimeData.from_rate(FS, {"F1": f[:, 0]}),
                         outputs=["d1", "d2"], intersample="bl")
    err = {m: np.abs(time_response(NumericModel(two_mass).system(TRUTH), TimeData.from_rate(FS, {"F1": f[:, 0]}),
                                   outputs=["d1", "d2"], intersample=m).values[1:].T - y).max() / np.abs(y).max()
           for m in ("zoh", "foh")}
    bl = np.abs(data.values[1:].T - y).max() / np.abs(y).max()
    # the 16x oversampled reference carries its own (omega h / 16)^2 / 12 interpolation error, ~1e-4 here
    assert bl < 5e-4
    assert err["foh"] > 20 * bl
    assert err["zoh"] > 100 * bl


@pytest.mark.parametrize("delay", [0.0, 0.3, -2.7])
def test_modal_band_limited_kernel_removes_the_wrapped_free_decay(delay):
    """A lightly damped rig (decay 0.03 1/s: 70 s to exp(-28), the record is 3 s): the modal kernel pads by one record
    and subtracts the free decay that wraps around (without it: errors of the response's size); the reference pads
    2^21 samples (the slowest mode decays by exp(-31)), written here from the state space."""
    p = {**TRUTH, "c22": 0.05}
    a, b, c, d = _rig(p)
    u = _force(N, FS, 700.0, np.random.default_rng(7), inputs=2)
    total = 1 << 21
    omega = 2 * np.pi * np.fft.rfftfreq(total, 1 / FS)
    h = c @ np.linalg.solve(1j * omega[:, None, None] * np.eye(4) - a, b)  # (n_f, 2, 2)
    h *= np.exp(-1j * omega * delay / FS)[:, None, None]
    h[-1] = h[-1].real
    ref = np.fft.irfft(np.einsum("foi,fi->fo", h, np.fft.rfft(u, total, axis=0)), total, axis=0)[:N]
    lam, vec = np.linalg.eig(a)
    got = band_limited_modal_response(lam, np.linalg.solve(vec, b.astype(complex)), c @ vec, d, u, 1 / FS,
                                      delay=delay)
    # what remains is the band-limited ringing of the record's end over the one-record padding, ~1e-5 of the peak
    # (the 16x oversampled DAQ reference itself is 1e-4 off)
    np.testing.assert_allclose(got, ref, rtol=0, atol=2e-5 * np.abs(ref).max())


def test_band_limited_simulation_matches_a_64x_daq_record_to_its_own_accuracy(two_mass):
    """At 16x the reference's linear interpolation of the fine force is ~1e-4 off (one standard error of a 1 % noise
    fit); at 64x it is 16 times smaller (its (omega h / 64)^2 / 12), and the modal bl kernel follows it (1.1e-5 seen)."""
    f, y = _daq(TRUTH, np.random.default_rng(0), over=64)
    sim = time_response(NumericModel(two_mass).system(TRUTH), TimeData.from_rate(FS, {"F1": f[:, 0]}),
                        outputs=["d1", "d2"], intersample="bl").values[1:].T
    assert np.abs(sim - y).max() / np.abs(y).max() < 3e-5


def test_unknown_intersample_is_refused(two_mass):
    force = TimeData.from_rate(FS, {"F1": np.ones(10)})
    with pytest.raises(DataError, match="intersample must be one of zoh, foh, bl.*got 'linear'"):
        time_response(NumericModel(two_mass).system(), force, intersample="linear")
    with pytest.raises(DataError, match="intersample must be one of"):
        OneStepEstimator(two_mass, ["k11"], intersample="cubic").fit(
            time_response(NumericModel(two_mass).system(), TimeData.from_rate(FS, {"F1": np.sin(np.arange(500.0))}),
                          outputs=["d1"]))


# -- the estimators ------------------------------------------------------------------------------------------------
def _fit(model, method, data, **settings):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # non-convergence is asserted on the numbers here, not on the warning
        return estimator_class(method)(model, UNKNOWNS, values={"c12": 0.0}, rng=0, **settings).fit(data).estimate_


@pytest.mark.slow
def test_one_step_on_lsim_data_is_honest_with_a_linear_input(two_mass):
    """The issue's repro: lsim data, F1 only, 1 % noise, 7 unknowns. Held: m1 about 80 std off; linear: covered."""
    rng = np.random.default_rng(1)
    f = _force(N, FS, 700.0, rng)
    data = _record(f, _lsim(TRUTH, f), 0.01, rng)
    held = _z_scores(_fit(two_mass, "one-step", data, intersample="zoh"))
    assert abs(held["m1"]) > 20  # the old silent bias, kept as the reason for the option
    linear = _z_scores(_fit(two_mass, "one-step", data, intersample="foh"))
    assert max(abs(z) for z in linear.values()) < 3.0, linear  # 3 std: 7 parameters at 95 % would miss one in 3


@pytest.mark.slow
def test_one_step_band_limited_recovers_a_daq_record_with_a_fractional_delay(two_mass):
    rng = np.random.default_rng(2)
    f, y = _daq(TRUTH, rng, delay=0.3)
    est = _fit(two_mass, "one-step", _record(f, y, 0.01, rng), intersample="bl")
    z = _z_scores(est)
    assert max(abs(v) for v in z.values()) < 3.0, z
    # the force was advanced by 5 / 16 sample on the 16x grid: the response lags it by that much
    assert est.diagnostics["delay"]["samples"] == pytest.approx(5 / 16, abs=3 * est.diagnostics["delay"]["std"] * FS)
    assert est.diagnostics["intersample"] == "bl"


def test_ekf_on_lsim_data_is_biased_held_and_honest_linear(two_mass):
    """lsim data (linear input), F1 only, 1 % noise, 7 unknowns, 3000 samples. Held input: m1 +8.7 % at 13 std, not
    converged; linear (FOH transition): every parameter within 1.2 std, converged (seen)."""
    rng = np.random.default_rng(1)
    f = _force(3000, FS, 700.0, rng)
    data = _record(f, _lsim(TRUTH, f), 0.01, rng)
    held = _fit(two_mass, "ekf", data, intersample="zoh")
    assert max(abs(v / TRUTH[n] - 1) for n, v in held.parameters.items()) > 0.05
    linear = _fit(two_mass, "ekf", data, intersample="foh")
    z = _z_scores(linear)
    assert max(abs(v) for v in z.values()) < 3.0, z  # 3 std: 7 parameters at 95 % would miss one in 3
    assert linear.success
    assert linear.diagnostics["intersample"] == "foh"


def test_ekf_at_5_percent_noise_reaches_the_output_error_optimum(two_mass):
    """lsim data, F1 only, 5 % noise, 7 unknowns (seed 7). The filter's passes creep along (m2, k12, k22, c22) by
    ~1 % a pass: before, not converged after 6 passes and 8.4 std off (seen); the output-error Gauss-Newton steps
    from the filter's estimate reach the optimum where the reported covariance belongs: within 1.9 std, success."""
    rng = np.random.default_rng(7)
    f = _force(N, FS, 700.0, rng)
    data = _record(f, _lsim(TRUTH, f), 0.05, rng)
    est = _fit(two_mass, "ekf", data, intersample="foh")
    z = _z_scores(est)
    assert max(abs(v) for v in z.values()) < 3.0, z
    assert est.success, est.message
    refinement = est.diagnostics["output_error_refinement"]
    assert refinement["converged"]
    assert refinement["steps"] >= 1
    assert refinement["cost_after"] < refinement["cost_before"]
    # the filter's own estimate stays in the diagnostics, and the unrefined filter is still there on request
    assert set(refinement["filter_estimate"]) == set(UNKNOWNS)
    plain = _fit(two_mass, "ekf", data, intersample="foh", refine=False)
    assert "output_error_refinement" not in plain.diagnostics
    assert plain.parameters == pytest.approx(refinement["filter_estimate"], rel=1e-12)


def test_ukf_with_a_linear_input_on_lsim_data(two_mass):
    """The UKF's sigma points through the FOH transition: m1, k11, c11 from 1500 lsim samples, 1 % noise. Held:
    about 4 std off and failed; linear: within 0.7 std (seen)."""
    rng = np.random.default_rng(1)
    f = _force(1500, FS, 700.0, rng)
    data = _record(f, _lsim(TRUTH, f), 0.01, rng)
    known = {k: v for k, v in TRUTH.items() if k not in ("m1", "k11", "c11")}
    settings = {"values": known}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        held = estimator_class("ukf")(two_mass, ["m1", "k11", "c11"], intersample="zoh", **settings).fit(data)
        linear = estimator_class("ukf")(two_mass, ["m1", "k11", "c11"], intersample="foh", **settings).fit(data)
    assert max(abs(v) for v in _z_scores(held.estimate_).values()) > 3.0
    assert max(abs(v) for v in _z_scores(linear.estimate_).values()) < 2.0
    assert linear.estimate_.success


def test_ekf_with_a_linear_input_on_a_daq_record_fails_its_residual_test(two_mass):
    """A DAQ record (band-limited), F1 only, 1 % noise: the FOH is the filter's nearest model and is ~2.5 % off on m1,
    k11 and c11 at 70 std (seen); before the output errors were tested it reported success. Now: FAILED, why."""
    rng = np.random.default_rng(1)
    f, y = _daq(TRUTH, rng)
    data = _record(f[:3000], y[:3000], 0.01, rng)
    est = _fit(two_mass, "ekf", data, intersample="foh")
    assert abs(est.parameters["m1"] / TRUTH["m1"] - 1) > 0.01  # the bias the FOH leaves
    assert not est.success
    assert "the residuals correlate with the inputs" in est.message
    assert any("residuals of d1 correlate with input F1" in w for w in est.diagnostics["warnings"])



@pytest.mark.slow
def test_ekf_on_a_daq_record_with_two_forces_at_5_percent_fails_on_its_lag_zero_correlation(two_mass):
    """F1 + F2, 5 % noise, 3000 samples: the FOH leaves m1, k11 and c11 about 17 std off, and its output error takes a
    share of the force at lag 0 (issue 21). The largest correlation over all 51 lags passed it (p = 0.019 over the 4
    pairs, level 0.01; 9 of 20 such records passed, seeds 0-19); with half the level on lags -1..1: p = 0.0022,
    FAILED (6 of 20 still pass: the residual test cannot see every biased FOH fit at this length and noise)."""
    rng = np.random.default_rng(7)
    f, y = _daq(TRUTH, rng, inputs=2)
    data = _record(f[:3000], y[:3000], 0.05, rng)
    est = _fit(two_mass, "ekf", data, intersample="foh")
    assert min(_z_scores(est).values()) < -10.0  # the bias the FOH leaves
    assert not est.success
    analysis = est.diagnostics["residual_analysis"]
    lag0 = analysis["cross_lags"].index(0)
    worst = np.abs(np.asarray(analysis["cross_correlation"])[0, 0])
    assert int(np.argmax(worst)) == lag0  # d1 and F1 correlate most at lag 0
    assert any("residuals of d1 correlate with input F1" in w for w in est.diagnostics["warnings"])


@pytest.mark.slow
def test_ekf_on_a_daq_record_that_passes_its_residual_test_says_the_estimate_depends_on_the_hold(two_mass):
    """F1 + F2, 5 % noise, 3000 samples, seed 1: the FOH leaves m1, k11, c11 about 3 % low (19 std) and the residual
    test passes (one of 6 in 20 such records). Before, success with every parameter a plain "yes"; now the
    intersample sensitivity says that band-limited inputs would move m1 up by about the bias, in a WARNING, and the
    text does not call m1 a plain "yes"."""
    from cappe.cli.estimate import _text

    rng = np.random.default_rng(1)
    f, y = _daq(TRUTH, rng, inputs=2)
    data = _record(f[:3000], y[:3000], 0.05, rng)
    est = _fit(two_mass, "ekf", data, intersample="foh")
    assert min(_z_scores(est).values()) < -10.0  # the bias the FOH leaves
    assert est.diagnostics["fit_test"] == "passed"  # which the residual test does not see on this record
    band_limited = est.diagnostics["intersample_sensitivity"]["bl"]
    for name in ("m1", "k11", "c11"):
        # the refit with a band-limited input would be the truth: the predicted shift is the FOH's bias
        assert band_limited[name]["shift"] == pytest.approx(TRUTH[name] / est.parameters[name] - 1, rel=0.3)
        assert band_limited[name]["shift_std"] > 5.0
        assert name in est.diagnostics["intersample_dependent"]
    text = _text(est, "ekf")
    warning = next(line for line in text.splitlines() if line.startswith("WARNING: the estimate depends on the inputs"))
    assert "were they band-limited" in warning
    assert "m1 would be 2." in warning or "m1 would be 3." in warning
    assert "% higher" in warning
    assert "the residual tests do not tell the behaviours apart" in warning
    assert not est.diagnostics["intersample_ruled_out"]["bl"]  # the band-limited refit passes them
    row = next(line for line in text.splitlines() if line.split()[:1] == ["m1"])
    assert row.rstrip().endswith("depends on intersample")
    assert "were the inputs between samples not foh" in text


def test_intersample_shift_predicts_the_refit_with_the_other_hold(two_mass):
    """lsim record (linear input), F1 only, 1 % noise, 1500 samples, m1, k11, c11. The shift each fit predicts for
    the other hold against the actual refit with it (seen: within 5 %; the one-step prediction with the fitted
    hold's Jacobian missed m1 and k11 from the FOH side by a factor 4). The UKF shares the code path."""
    rng = np.random.default_rng(1)
    f = _force(1500, FS, 700.0, rng)
    data = _record(f, _lsim(TRUTH, f), 0.01, rng)
    known = {k: v for k, v in TRUTH.items() if k not in ("m1", "k11", "c11")}
    fits = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for kind, hold in (("ekf", "foh"), ("ekf", "zoh"), ("ukf", "foh")):
            fits[kind, hold] = estimator_class(kind)(two_mass, ["m1", "k11", "c11"], values=known, rng=0,
                                                    intersample=hold).fit(data).estimate_
    for (kind, hold), other in ((("ekf", "foh"), "zoh"), (("ekf", "zoh"), "foh"), (("ukf", "foh"), "zoh")):
        est = fits[kind, hold]
        refit = fits["ekf", other]
        shifts = est.diagnostics["intersample_sensitivity"][other]
        for name in ("m1", "k11", "c11"):
            actual = refit.parameters[name] / est.parameters[name] - 1
            assert abs(actual) > 0.03  # the holds differ by a half sample: 5-20 % here
            assert shifts[name]["shift"] == pytest.approx(actual, rel=0.3), (kind, hold, name)
    # the held input would move the right hold's fit by many standard errors, but the data rule it out: no warning
    # of it (the held fit, the wrong one, is told that a linear input is not ruled out)
    assert fits["ekf", "foh"].diagnostics["intersample_ruled_out"]["zoh"]
    assert not any("were they held between samples" in w for w in fits["ekf", "foh"].diagnostics["warnings"])
    assert not fits["ekf", "zoh"].diagnostics["intersample_ruled_out"]["foh"]


def _daq_motion(delay):
    """d, v, a of both masses and F1 from the 16x DAQ simulation (force advanced by ``delay`` samples)."""
    over = 16
    a, b, _, _ = _rig(TRUTH)
    rng = np.random.default_rng(6)
    fine = _force(N * over, FS * over, 700.0, rng)
    _, _, x = sig.lsim((a, b[:, :1], np.eye(4), np.zeros((4, 1))), fine, np.arange(N * over) / (FS * over))
    y = np.hstack([x, x @ a[2:].T + fine @ b[2:, :1].T])
    h = sig.firwin(32 * over + 1, 0.45 * FS / (over * FS / 2))
    f_rec = np.roll(sig.lfilter(h, 1.0, fine, axis=0), -round(delay * over), axis=0)[::over]
    y_rec = sig.lfilter(h, 1.0, y, axis=0)[::over]
    y_rec = y_rec + 0.01 * np.sqrt(np.mean(y_rec**2, axis=0)) * rng.standard_normal(y_rec.shape)
    names = ["d1", "d2", "v1", "v2", "a1", "a2"]
    return TimeData.from_rate(FS, {"F1": f_rec[:, 0], **{n: y_rec[:, k] for k, n in enumerate(names)}})


def test_direct_fails_where_force_and_response_are_not_simultaneous(two_mass):
    """direct on a DAQ record whose force leads the responses by 0.3 sample: up to ~45 % off (bench_coverage: 9 of 70
    intervals covered). Its instrumental-variable equation errors correlate with F1: the fit is FAILED, as one-step's
    residual test fails a fit (before: success with a WARNING line). Plain least squares is tested on the equation
    errors of an instrumental-variable solution and FAILS as well. The same record without the delay succeeds."""
    delayed = _daq_motion(0.3)
    for instruments in ("model", None, "delayed"):
        est = _fit(two_mass, "direct", delayed, instruments=instruments, inputs=["F1"])
        assert any("correlate with input F1" in w for w in est.diagnostics["warnings"]), est.diagnostics["warnings"]
        assert est.diagnostics["residual_analysis"]["independent"] is False
        assert not est.success, instruments
        assert est.diagnostics["fit_test"] == "failed"
        assert est.message.startswith("the residuals correlate with the inputs")
    simultaneous = _fit(two_mass, "direct", _daq_motion(0.0), instruments="model", inputs=["F1"])
    assert simultaneous.diagnostics["residual_analysis"]["independent"] is True
    assert simultaneous.success


def test_direct_cli_exits_1_with_failed_on_a_delayed_record(two_mass, tmp_path, capsys):
    """The verdict reaches the user as the two-step's chi-square failure does: FAILED in the text, exit status 1."""
    from cappe.cli import main
    from cappe.io import write_time_data

    path = tmp_path / "delayed.npz"
    write_time_data(path, _daq_motion(0.3))
    code = main(["estimate", "builtin:two-mass-rig", "--data", str(path), "--method", "direct", "--set", "c12=0",
                 "--unknowns", ",".join(UNKNOWNS), "--setting", "instruments=model", "--setting", 'inputs=["F1"]'])
    out = capsys.readouterr().out
    assert code == 1
    assert "direct: FAILED (the fit does not explain the data)" in out
    assert "residuals tested: the equation errors of the estimate (instrumental variables, model)" in out
    assert "WARNING: residuals of mass1.x correlate with input F1" in out


def test_plain_least_squares_is_tested_on_instrumental_variable_errors(two_mass):
    """Plain least squares on an lsim record with 5 % noise: its estimate is biased by the noise in the regressors
    (errors in variables) and its own equation errors correlate with the force through that bias, so testing them
    failed every such record (seen: p ~ 1e-30). The errors tested are those of an instrumental-variable solution,
    which hold the noise only: the record passes and the estimate is a success."""
    est = _fit(two_mass, "direct", _lsim_motion(8, 0.05, N), instruments=None, inputs=["F1"])
    # the least-squares estimate puts m2 at 0.002 kg, its bound holds it at 0.4: the tested solution keeps it there
    assert "model-instrument estimate (3 iterations from least squares; ['m2'] held at their bounds; the " \
           "least-squares estimate's" in est.diagnostics["residuals_tested"]
    assert est.diagnostics["residual_analysis"]["independent"] is True
    assert not any("correlate with input" in w for w in est.diagnostics.get("warnings", []))
    assert est.success


def _lsim_motion(seed, noise, n):
    """d, v, a of both masses and F1 from scipy lsim, white noise drawn independently of the force."""
    rng = np.random.default_rng(seed)
    a, b, _, _ = _rig(TRUTH)
    f = _force(n, FS, 700.0, rng)
    _, _, x = sig.lsim((a, b[:, :1], np.eye(4), np.zeros((4, 1))), f, np.arange(n) / FS)
    y = np.hstack([x, x @ a[2:].T + f @ b[2:, :1].T])  # the equations of motion hold at every sample
    y = y + noise * np.sqrt(np.mean(y**2, axis=0)) * rng.standard_normal(y.shape)
    names = ["d1", "d2", "v1", "v2", "a1", "a2"]
    return TimeData.from_rate(FS, {"F1": f[:, 0], **{n: y[:, k] for k, n in enumerate(names)}})


def test_delayed_instruments_are_tested_on_model_instrument_errors(two_mass):
    """The delayed instruments are consistent but weak: their estimate's error enters the equation errors through the
    regressors, which correlate with the force at lag 0, and testing those errors failed 13 of 20 lsim records at 5 %
    noise (3 of 20 with F1 + F2 at 1 %) whose equations hold. The errors tested are those of the model-instrument
    estimate (its iterations from least squares)."""
    est = _fit(two_mass, "direct", _lsim_motion(202, 0.05, N), instruments="delayed", inputs=["F1"])
    assert "the delayed-instrument estimate's own errors" in est.diagnostics["residuals_tested"]
    assert est.diagnostics["residual_analysis"]["independent"] is True
    assert est.success


def test_direct_force_independence_fails_at_its_stated_level(two_mass):
    """direct's force-independence test where force and noise are independent (every failure a false alarm): its
    stated level is 1 % (Bonferroni over lags and DOF x force pairs). Measured (bench_coverage --false-alarm 100,
    four settings): 5 of 400 records, 1.25 %. Here 50 lsim records at 1 % noise: 0.5 expected at the level; more
    than 3 has probability 0.2 % at 1 %, and 75 % at a 10 % rate."""
    warned = 0
    for seed in range(50):
        est = _fit(two_mass, "direct", _lsim_motion(500 + seed, 0.01, 3000), instruments="model", inputs=["F1"])
        assert est.diagnostics["residual_analysis"]["level"] == 0.01
        failed = any("correlate with input F1" in w for w in est.diagnostics.get("warnings", []))
        assert est.success is not failed  # the test's verdict is the fit's
        warned += failed
    assert warned <= 3, warned


#: The rig with k11 = kb * preload**(1/3) (kb known, the truth's k11 at preload = 1): the unknowns enter the equations
#: non-linearly and direct takes its Gauss-Newton path. Bounds a decade each side of the truth (none is reached here).
PRELOADED_RIG = f"""
format: cappe.model/1
name: preloaded-rig
parameters:
  - {{name: m1, value: 1.39, unit: kg, kind: mass, bounds: [0.1, 14.0]}}
  - {{name: m2, value: 1.09, unit: kg, kind: mass, bounds: [0.1, 11.0]}}
  - {{name: kb, value: {TRUTH["k11"]}, unit: N/m, kind: stiffness}}
  - {{name: preload, value: 0.7, unit: '1', kind: other, bounds: [0.05, 3.0]}}
  - {{name: k12, value: 0.12e6, unit: N/m, kind: stiffness, bounds: [0.012e6, 1.2e6]}}
  - {{name: k22, value: 0.24e6, unit: N/m, kind: stiffness, bounds: [0.024e6, 2.4e6]}}
  - {{name: c11, value: 13.42, unit: N s/m, kind: damping, bounds: [1.342, 134.2]}}
  - {{name: c22, value: 0.47, unit: N s/m, kind: damping, bounds: [0.047, 47.0]}}
bodies:
  - {{name: mass1, mass: m1, dofs: [x]}}
  - {{name: mass2, mass: m2, dofs: [x]}}
elements:
  - {{name: beam1, bodies: [ground, mass1], stiffness: {{x: kb*preload**(1/3)}}, damping: {{x: c11}}}}
  - {{name: spring12, bodies: [mass1, mass2], stiffness: {{x: k12}}}}
  - {{name: beam2, bodies: [ground, mass2], stiffness: {{x: k22}}, damping: {{x: c22}}}}
inputs:
  - {{name: F1, body: mass1, direction: x}}
outputs:
""" + "".join(f"  - {{name: {q[0]}{j}, quantity: {q}, body: mass{j}, direction: x}}\n"
              for q in ("displacement", "velocity", "acceleration") for j in (1, 2))
PRELOADED_UNKNOWNS = ["preload", "m1", "m2", "k12", "k22", "c11", "c22"]


def _fit_preloaded(data, unknowns=tuple(PRELOADED_UNKNOWNS), **settings):
    from cappe.estimate._direct import DirectEstimator
    from cappe.model.loader import structure_from_yaml

    model = NumericModel(structure_from_yaml(PRELOADED_RIG))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        settings.setdefault("instruments", None)  # Gauss-Newton, the path these tests are about
        est = DirectEstimator(model, list(unknowns), inputs=["F1"], **settings).fit(data).estimate_
    assert est.diagnostics["linear"] is False  # the Gauss-Newton path
    return est


def test_direct_nonlinear_path_fails_where_force_and_response_are_not_simultaneous():
    """Unknowns that enter non-linearly (Gauss-Newton on the equation errors) on the DAQ record whose force leads
    the responses by 0.3 sample: every parameter off (bench_direct_verdict: 0 of 70 intervals covered) and, before,
    a success. The errors tested are those of the non-linear model-instrument estimate from the Gauss-Newton one
    (whose own errors correlate with the force through the noise bias); they follow F1 and the fit is FAILED. The
    same record without the delay passes."""
    est = _fit_preloaded(_daq_motion(0.3))
    assert "model-instrument estimate (3 iterations from Gauss-Newton (least-squares) estimate" in (
        est.diagnostics["residuals_tested"])
    assert est.diagnostics["residual_analysis"]["independent"] is False
    assert any("residuals of mass1.x correlate with input F1" in w for w in est.diagnostics["warnings"])
    assert not est.success
    assert est.diagnostics["fit_test"] == "failed"
    simultaneous = _fit_preloaded(_daq_motion(0.0))
    assert simultaneous.diagnostics["residual_analysis"]["independent"] is True
    assert simultaneous.success


def test_direct_nonlinear_path_fails_a_wrong_known_mass():
    """m1 known 12 % high (1.4 kg, truth 1.25) on an lsim record: the equations of mass 1 cannot hold and their
    errors follow F1 (p ~ 1e-16); before, a success. With m1 estimated the record passes. (A wrong k22 or m2 is not
    seen with F1 only, and rightly: the unforced second equation determines m2, k12, k22, c22 up to a common scale,
    which the free three absorb.)"""
    data = _lsim_motion(8, 0.01, N)
    wrong = _fit_preloaded(data, [n for n in PRELOADED_UNKNOWNS if n != "m1"], values={"m1": 1.4})
    assert wrong.diagnostics["residual_analysis"]["independence_p"]["mass1.x"]["F1"] < 1e-6
    assert not wrong.success
    right = _fit_preloaded(data)
    assert right.diagnostics["residual_analysis"]["independent"] is True
    assert right.success


def test_direct_nonlinear_path_fails_at_its_stated_level():
    """The non-linear path's test where force and noise are independent (every failure a false alarm; stated level
    1 %): 30 lsim records at 1 % noise, 0.3 expected; more than 3 has probability 3e-4 at 1 % and 35 % at a 10 % rate.
    (bench_direct_verdict: 200 records, four settings.)"""
    failed = 0
    for seed in range(30):
        est = _fit_preloaded(_lsim_motion(700 + seed, 0.01, 3000))
        assert est.diagnostics["residual_analysis"]["level"] == 0.01
        failed += not est.success
    assert failed <= 3, failed


def test_direct_nonlinear_model_instruments_equal_the_linear_ones_and_least_squares_says_it_is_biased(two_mass):
    """An lsim record, F1 only, 1 % noise. Plain Gauss-Newton on the non-linear unknowns (and plain least squares on
    the linear ones) is biased by the noise in the measured motion: m2, k12, k22 about 40 % low, 1 of 7 intervals
    covering, and a success without a word (before). It now warns with the model-instrument estimate it differs
    from (by up to 65 of its standard errors). instruments="model" on the non-linear unknowns (refused before) is
    the same estimate as on the linear rig (independent path: the linear regression's two-stage least squares),
    k11 = kb preload**(1/3), and its intervals cover the truth."""
    data = _lsim_motion(3, 0.01, N)
    plain = _fit_preloaded(data)
    assert plain.success
    bias = plain.diagnostics["noise_bias"]["standard_errors"]
    assert abs(bias["m2"]) > 20
    assert any(w.startswith("the Gauss-Newton estimate differs from the model-instrument estimate by more than")
               and w.endswith("use instruments=model") for w in plain.diagnostics["warnings"])
    linear_plain = _fit(two_mass, "direct", data, instruments=None, inputs=["F1"])
    assert any(w.startswith("the least-squares estimate differs from the model-instrument estimate")
               for w in linear_plain.diagnostics["warnings"])
    iv = _fit_preloaded(data, instruments="model")
    linear = _fit(two_mass, "direct", data, instruments="model", inputs=["F1"])
    assert iv.success
    assert linear.success
    assert "noise_bias" not in iv.diagnostics
    assert iv.diagnostics["residuals_tested"] == "the equation errors of the estimate (instrumental variables, model)"
    # both run 3 iterations, from different starts (Gauss-Newton, least squares): equal within 1e-3 of a standard
    # error (seen: 5e-4 of c22's, 1e-7 relative for k11)
    std = dict(zip(linear.names, linear.std, strict=True))
    k11 = TRUTH["k11"] * iv.parameters["preload"] ** (1 / 3)
    np.testing.assert_allclose(k11, linear.parameters["k11"], atol=1e-3 * std["k11"], rtol=0)
    for name in ("m1", "m2", "k12", "k22", "c11", "c22"):
        np.testing.assert_allclose(iv.parameters[name], linear.parameters[name], atol=1e-3 * std[name], rtol=0)
    truth = {"preload": 1.0, **TRUTH}
    assert all(lo <= truth[n] <= hi for n, (lo, hi) in zip(iv.names, iv.ci95, strict=True))


def test_direct_nonlinear_model_instruments_leave_the_gauss_newton_bound():
    """5 % noise, F1 only: the noise bias puts Gauss-Newton's k12 at its lower bound (0.012e6 for 0.1e6). The
    model-instrument estimate starts there with every unknown free and takes its steps in SI units (in log
    coordinates the first step from that far overshot by orders of magnitude and held five unknowns at bounds; with
    Gauss-Newton's bound kept, k12 stayed at it): no bound, each parameter within 1.5 standard errors of the truth
    (seen: 0.7)."""
    data = _lsim_motion(100, 0.05, 3000)
    assert _fit_preloaded(data).diagnostics["at_bound"] == ["k12"]
    iv = _fit_preloaded(data, instruments="model")
    assert iv.diagnostics["at_bound"] == []
    assert iv.success
    truth = {"preload": 1.0, **TRUTH}
    z = [(v - truth[n]) / sd for n, v, sd in zip(iv.names, iv.values, iv.std, strict=True)]
    assert np.all(np.abs(z) < 1.5), z


def test_two_step_inverts_the_first_order_hold(two_mass):
    """Noise-free lsim data with both forces: step 1's OE model converted by the inverse FOH gives the truth."""
    rng = np.random.default_rng(4)
    f = _force(3000, FS, 700.0, rng, inputs=2)
    data = _record(f, _lsim(TRUTH, f), 0.0, rng)
    for intersample, limit in (("foh", 1e-8), ("zoh", None)):
        est = _fit(two_mass, "two-step-tf", data, intersample=intersample, n_starts=2)  # exact: ~1e-12 seen
        worst = max(abs(v / TRUTH[n] - 1) for n, v in est.parameters.items())
        if limit is None:
            assert worst > 0.02  # the held-input inverse of linear-input data is off
        else:
            assert worst < limit, est.parameters


@pytest.mark.slow  # three two-step fits of 6000 samples: ~20 s
def test_two_step_with_two_forces_shares_the_poles_across_the_inputs(two_mass):
    """lsim records, F1 + F2, 5 % noise, ``foh``. Step 1 was one discrete OE model per output with a denominator per
    input: on d2 the F2 path, which excites the 181 Hz mode weakly, put that mode elsewhere (a local minimum: the
    restart from F1's denominator had a 0.3 % lower loss; or noise that fits better there), and the second step
    FAILED its chi-square test on 8 of 10 bench records with errors up to 135 % (here: chi2 1549 and 2.1e6, errors 31
    and 150 %). Step 1 is now the continuous model with the poles shared by the inputs, simulated with the linear
    input, as for a band-limited one; its natural frequencies stay below the Nyquist frequency (seed 2 found d2's
    181 Hz mode aliased at 1819 Hz without that bound: chi2 2e8)."""
    for seed, methods in ((1, ("two-step-tf",)), (2, ("two-step-tf", "two-step-zp"))):
        rng = np.random.default_rng(seed)
        f = _force(N, FS, 700.0, rng, inputs=2)
        data = _record(f, _lsim(TRUTH, f), 0.05, rng)
        for method in methods:
            est = _fit(two_mass, method, data, intersample="foh")
            assert est.success, (seed, method, est.message)
            assert est.diagnostics["second_step_test"]["passed"]
            # one-step's worst error on the bench's ten such records is 0.28 %, two-step's now 0.32 %
            worst = max(abs(v / TRUTH[n] - 1) for n, v in est.parameters.items())
            assert worst < 0.01, (seed, method, est.parameters)


@pytest.mark.slow  # two two-step fits of 6000 samples: ~6 s
def test_two_step_with_one_force_fits_step_1_by_the_continuous_model(two_mass):
    """lsim records, F1 only, 5 % noise, ``foh``. Step 1 was the discrete OE model per output, whose search stopped
    in local minima on d1 (its lightly damped 99.5 Hz mode misplaced, a cost 1.2-1.5 x the continuous model's from
    the same poles): the second step FAILED its chi-square test on 4-5 of 10 bench records with errors up to 150 and
    300 % (here, seeds 101 and 103: not a success, chi2 248 on 11 dof for 103). Step 1 is now the continuous model
    for one input too: every fit passes, and every interval covers."""
    for seed in (101, 103):
        rng = np.random.default_rng(seed)
        f = _force(N, FS, 700.0, rng)
        data = _record(f, _lsim(TRUTH, f), 0.05, rng)
        est = _fit(two_mass, "two-step-tf", data, intersample="foh")
        assert est.success, (seed, est.message)
        assert est.diagnostics["second_step_test"]["passed"]
        assert all(lo <= TRUTH[n] <= hi for n, (lo, hi) in zip(est.names, est.ci95, strict=True)), (seed, est.ci95)


def test_two_step_arx_route_refuses_a_non_held_input(two_mass):
    data = TimeData.from_rate(FS, {"F1": np.sin(np.arange(800.0)), "d1": np.cos(np.arange(800.0))})
    with pytest.raises(DataError, match="identification 'arx'.*assumes a held input; got intersample 'foh'"):
        _fit(two_mass, "two-step-tf", data, intersample="foh", identification="arx")


def test_cli_intersample_reaches_the_estimator_or_is_refused(tmp_path, capsys):
    from cappe.cli import main
    from cappe.io import write_time_data

    t = np.arange(400) / FS
    write_time_data(tmp_path / "r.npz", TimeData.from_rate(FS, {"F1": np.sin(300 * t), "d1": 1e-6 * np.sin(300 * t)}))
    code = main(["estimate", "builtin:two-mass-rig", "--data", str(tmp_path / "r.npz"), "--method", "ekf",
                 "--unknowns", "k11", "--intersample", "bl"])
    assert code == 2
    assert ("--intersample bl does not apply to method 'ekf': a Kalman filter steps from one sample to the next, "
            "and a band-limited input") in capsys.readouterr().err
    code = main(["simulate", "builtin:two-mass-rig", "--excite", "F1=random", "--fs", "1000", "--duration", "0.5",
                 "--outputs", "d1", "--intersample", "foh", "--json"])
    assert code == 0
    assert '"intersample": "foh"' in capsys.readouterr().out
