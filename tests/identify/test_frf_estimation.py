"""FRF estimation: H1 / H2 / Hv, coherence, multiple inputs, impact tests, stepped sine, window correction.

References: the exact FRF of the simulated system (ZOH-discretized two-mass rig: C (zI - A)^-1 B + D, and
``MechanicalSystem.frf`` with the ZOH hold factor), pyFRF on the same data, closed-form noise biases, a
Levy rational fit written here, and the rig's exact modes.
"""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest
from pyFRF import FRF
from scipy.signal import lfilter

from cappe.exceptions import DataError, DataWarning, IllConditionedWarning
from cappe.identify._frf import (
    ForceWindow,
    coherence_summary,
    detect_hits,
    estimate_frf,
    exponential_window_correction,
    stepped_sine_frf,
)
from cappe.identify._signals import impact, random_noise, stepped_sine, stepped_sine_schedule
from cappe.io.timedata import TimeData
from cappe.model.numeric import NumericModel
from cappe.systems.frf import FRFData

FS = 1024.0
N = 1024  # one period / segment: 1 Hz lines
DAMPED = {"c11": 150.0, "c22": 40.0}  # modal damping 3.4 % and 5.1 %: short transients, wide peaks
# stiffer coupling: modes 113.7 and 206.6 Hz (1.8 %, 2.0 %) and a clear anti-resonance of d1/F1 at 140 Hz
SEPARATED = {"k12": 0.6e6, "c11": 60.0, "c22": 20.0, "c12": 10.0}
NOISE_BAND = (5.0, 300.0)


@pytest.fixture(scope="module")
def rig(two_mass):
    return NumericModel(two_mass)


def _discrete_frf(ss_d, freq, fs, shift=0.0):
    """Exact FRF of a discrete state space at z = exp((j omega + shift) / fs), shape (n_out, n_in, n_f)."""
    z = np.exp((2j * np.pi * np.asarray(freq) + shift) / fs)
    n = ss_d.A.shape[0]
    x = np.linalg.solve(z[:, None, None] * np.eye(n) - ss_d.A, np.broadcast_to(ss_d.B, (z.size, *ss_d.B.shape)))
    return (ss_d.C @ x + ss_d.D).transpose(1, 2, 0)


def _steady_periodic(ss, u, period):
    """Response of a continuous state space (ZOH) to a periodic input, started on its periodic steady state."""
    fs = FS
    ss_d = ss.discretize(1 / fs)
    one = np.vstack([u[:period], np.zeros((1, u.shape[1]))])
    _, x = ss.simulate(one, np.arange(period + 1) / fs)
    x0 = np.linalg.solve(np.eye(ss.A.shape[0]) - np.linalg.matrix_power(ss_d.A, period), x[-1])
    y, _ = ss.simulate(u, np.arange(u.shape[0]) / fs, x0=x0)
    return y


def _periodic_force(seed, n_periods, rms=10.0, band=(5.0, 400.0)):
    return random_noise(
        fs=FS, duration=n_periods * N / FS, rms=rms, band=band, periodic=True, n_periods=n_periods, rng=seed
    ).values[0]


# -- (a) noise-free periodic random: leakage-free, exact ------------------------------------------------------
def test_h1_periodic_random_matches_exact_frf(rig):
    system = rig.system()  # default (lightly damped) rig: the steady-state start removes the long transient
    ss = system.state_space(["F1"], ["d1", "d2"])
    u = _periodic_force(1, 3)
    y = _steady_periodic(ss, u[:, None], N)
    data = TimeData.from_rate(FS, {"F1": u, "d1": y[:, 0], "d2": y[:, 1]})
    frf = estimate_frf(
        data, inputs="F1", outputs=["d1", "d2"], nperseg=N, noverlap=0, window="boxcar", band=(5.0, 400.0)
    )
    exact = _discrete_frf(ss.discretize(1 / FS), frf.freq, FS)
    scale = np.abs(exact).max(axis=-1, keepdims=True)
    # noise-free, periodic, steady state: only rounding separates the estimate from the exact discrete FRF
    np.testing.assert_allclose(frf.H / scale, exact / scale, rtol=0, atol=1e-9)
    # the continuous FRF times the zero-order-hold factor sinc(f/fs) exp(-j pi f/fs); what is left is the
    # held input's images at fs - f aliased through the rig, largest near 400 Hz (measured 3.7e-4 of the peak)
    continuous = system.frf(frf.freq, ["F1"], ["d1", "d2"]).H
    hold = np.sinc(frf.freq / FS) * np.exp(-1j * np.pi * frf.freq / FS)
    np.testing.assert_allclose(frf.H / scale, continuous * hold / scale, rtol=0, atol=1e-3)
    assert frf.coherence.min() > 1 - 1e-9  # noise-free: coherence 1 up to rounding
    assert frf.output_quantities == ()
    assert frf.window_decay is None


def test_welch_random_noise_default_settings(rig):
    ss = rig.system(params=DAMPED).state_space(["F1"], ["d1"])
    n = 2**16
    u = random_noise(fs=FS, duration=n / FS, rms=10.0, rng=3).values[0]
    y, _ = ss.simulate(u[:, None], np.arange(n) / FS)
    data = TimeData.from_channels(np.arange(n) / FS, {"F1": u, "d1": y[:, 0]}, units={"F1": "N", "d1": "m"})
    frf = estimate_frf(data, inputs=["F1"], outputs=["d1"], nperseg=1024, band=(10.0, 400.0))
    exact = _discrete_frf(ss.discretize(1 / FS), frf.freq, FS)
    # Hann window, 127 averages, 1 Hz lines against half-power bandwidths of 6 and 17 Hz: leakage bias and
    # random error stay below 2 % of the peak (measured 0.9 %)
    err = np.abs(frf.H - exact).max() / np.abs(exact).max()
    assert err < 0.02
    assert frf.output_quantities == ("displacement",)


# -- (b) noise: bias of H1, H2, Hv; coherence ---------------------------------------------------------------------
@pytest.fixture(scope="module")
def noisy_case(rig):
    ss = rig.system(params=SEPARATED).state_space(["F1"], ["d1"])
    periods = 64
    u = _periodic_force(5, periods, band=NOISE_BAND)
    y = _steady_periodic(ss, u[:, None], N)[:, 0]
    exact = _discrete_frf(ss.discretize(1 / FS), np.arange(N // 2 + 1.0), FS)[0, 0]
    return u, y, exact, periods


def _line_power(rms, band=NOISE_BAND):
    """|X_k|^2 of one period of the periodic random force on each in-band line (Parseval)."""
    lines = np.count_nonzero((np.arange(N // 2 + 1) >= band[0]) & (np.arange(N // 2 + 1) <= band[1]))
    return N**2 * rms**2 / (2 * lines)


def test_output_noise_bias(noisy_case):
    u, y, exact, periods = noisy_case
    rng = np.random.default_rng(11)
    x_line = _line_power(10.0)
    # noise per line N sigma^2 equal to the response power at the anti-resonance of d1/F1 (140 Hz)
    anti = 140
    sigma = np.sqrt(np.abs(exact[anti]) ** 2 * x_line / N)
    data = TimeData.from_rate(FS, {"F1": u, "d1": y + sigma * rng.standard_normal(y.size)})
    kw = {"inputs": "F1", "outputs": "d1", "nperseg": N, "noverlap": 0, "window": "boxcar", "band": NOISE_BAND}
    h1, h2, hv = (estimate_frf(data, estimator=e, **kw) for e in ("H1", "H2", "Hv"))
    truth = exact[5:301]
    near = np.abs(h1.freq - anti) <= 1  # the 3 lines at the anti-resonance
    # H1 is unbiased: mean complex ratio over the band, random error ~ 1/sqrt(64 averages x 396 lines)
    ratio1 = h1.H[0, 0] / truth
    assert abs(np.mean(ratio1) - 1) < 0.01
    # H2 = H (1 + noise / |Y|^2): biased up where the response is small; expected factor 1 + SNR^-1 there
    snr = np.abs(truth) ** 2 * x_line / (N * sigma**2)
    expected = 1 + 1 / snr
    ratio2 = np.abs(h2.H[0, 0] / truth)
    assert np.all(ratio2[near] > 1.4)  # SNR <= 1.1 on these lines: bias >= 1.9, random error ~ 0.2
    np.testing.assert_allclose(np.median(ratio2 / expected), 1.0, atol=0.02)
    # Hv lies between H1 and H2 in magnitude on every line (algebraic for one input)
    mags = np.abs([h1.H[0, 0], hv.H[0, 0], h2.H[0, 0]])
    assert np.all(mags[0] <= mags[1] * (1 + 1e-12))
    assert np.all(mags[1] <= mags[2] * (1 + 1e-12))
    # coherence = SNR / (1 + SNR) for a periodic input: low at the anti-resonance, ~1 at the resonances
    predicted = snr / (1 + snr)
    np.testing.assert_allclose(h1.coherence[0, 0], predicted, atol=0.12)  # 64 averages: ~1/sqrt(64) spread
    assert h1.coherence[0, 0, near].max() < 0.75
    assert h1.coherence[0, 0, np.abs(h1.freq - anti) > 10].min() > 0.9
    # narrow anti-resonance dip only: no DataWarning (pytest turns warnings into errors)
    assert coherence_summary(h1, threshold=0.8).fraction_below[0, 0] < 0.1


def test_input_noise_bias(noisy_case):
    u, y, exact, _ = noisy_case
    rng = np.random.default_rng(12)
    x_line = _line_power(10.0)
    noise_to_signal = 0.5  # input-noise power per line / force power per line
    sigma = np.sqrt(noise_to_signal * x_line / N)
    data = TimeData.from_rate(FS, {"F1": u + sigma * rng.standard_normal(u.size), "d1": y})
    kw = {"inputs": "F1", "outputs": "d1", "nperseg": N, "noverlap": 0, "window": "boxcar", "band": NOISE_BAND}
    with pytest.warns(DataWarning, match=r"low coherence for output 'd1' / input 'F1': 100 % of the 296 lines"):
        h1, h2, hv = (estimate_frf(data, estimator=e, **kw) for e in ("H1", "H2", "Hv"))
    truth = exact[5:301]
    # H1 = H |X|^2 / (|X|^2 + noise): biased low by 1 / (1 + 0.5) on every line; H2 unbiased
    np.testing.assert_allclose(np.mean(np.abs(h1.H[0, 0] / truth)), 1 / 1.5, rtol=0.02)
    np.testing.assert_allclose(np.mean(h2.H[0, 0] / truth), 1.0, atol=0.02)
    mags = np.abs([h1.H[0, 0], hv.H[0, 0], h2.H[0, 0]])
    assert np.all(mags[0] <= mags[1] * (1 + 1e-12))
    assert np.all(mags[1] <= mags[2] * (1 + 1e-12))
    # coherence = 1 / (1 + 0.5) everywhere (the input noise is white); 64 averages
    np.testing.assert_allclose(np.mean(h1.coherence), 1 / 1.5, atol=0.02)


def test_hv_equal_noise_is_consistent(noisy_case):
    """With equal noise on input and output (in their units) Hv is the consistent estimator; H1, H2 are not."""
    u, y, exact, _ = noisy_case
    rng = np.random.default_rng(13)
    scale = 1e6  # response in micrometres: |H| ~ 1, so equal noise in both channels is a fair TLS case
    x_line = _line_power(10.0)
    sigma = np.sqrt(0.3 * x_line / N)
    data = TimeData.from_rate(
        FS, {"F1": u + sigma * rng.standard_normal(u.size), "d1": scale * y + sigma * rng.standard_normal(y.size)}
    )
    kw = {"inputs": "F1", "outputs": "d1", "nperseg": N, "noverlap": 0, "window": "boxcar", "band": NOISE_BAND}
    estimates = {}
    for est in ("H1", "H2", "Hv"):
        with pytest.warns(DataWarning, match="low coherence for output 'd1' / input 'F1'"):
            estimates[est] = estimate_frf(data, estimator=est, **kw).H[0, 0] / (scale * exact[5:301])
    # mean complex ratio over 296 lines: Hv within 1 % (measured 0.3 %), H1 low and H2 high by far more
    assert abs(np.mean(estimates["Hv"]) - 1) < 0.01
    assert np.mean(estimates["H1"]).real < 0.85
    assert np.mean(estimates["H2"]).real > 1.5


# -- (c) MIMO -------------------------------------------------------------------------------------------------
def test_mimo_two_uncorrelated_inputs_recover_matrix(rig):
    ss = rig.system().state_space(["F1", "F2"], ["d1", "d2"])
    blocks = []
    for r in range(6):  # six independent realizations of two periodic random forces, each in steady state
        u = np.stack([_periodic_force(100 + r, 1), _periodic_force(200 + r, 1)], axis=1)
        y = _steady_periodic(ss, u, N)
        blocks.append(np.hstack([u, y]))
    rec = np.vstack(blocks)
    data = TimeData.from_rate(FS, dict(zip(["F1", "F2", "d1", "d2"], rec.T, strict=True)))
    exact = _discrete_frf(ss.discretize(1 / FS), np.arange(5.0, 401.0), FS)
    scale = np.abs(exact).max(axis=-1, keepdims=True)
    kw = {
        "inputs": ["F1", "F2"],
        "outputs": ["d1", "d2"],
        "nperseg": N,
        "noverlap": 0,
        "window": "boxcar",
        "band": (5.0, 400.0),
    }
    for est in ("H1", "H2", "Hv"):  # noise-free: all three are exact
        frf = estimate_frf(data, estimator=est, **kw)
        assert frf.H.shape == (2, 2, 396)
        np.testing.assert_allclose(frf.H / scale, exact / scale, rtol=0, atol=1e-8, err_msg=est)
    assert frf.coherence.min() > 1 - 1e-9  # multiple coherence of a noise-free linear system
    # reciprocity of the rig is recovered
    np.testing.assert_allclose(frf.H[0, 1] / scale[0, 1], frf.H[1, 0] / scale[0, 1], atol=1e-8)


def test_correlated_inputs_warn_ill_conditioned():
    rng = np.random.default_rng(4)
    f1 = rng.standard_normal(8192)
    y = np.convolve(f1, [1.0, 0.5])[:8192]
    data = TimeData.from_rate(FS, {"F1": f1, "F2": 0.5 * f1, "y": y})
    with pytest.warns(IllConditionedWarning, match=r"Gxx of inputs \['F1', 'F2'\] is ill-conditioned on 100 %"):
        estimate_frf(data, inputs=["F1", "F2"], outputs=["y"], nperseg=512)


def test_h2_needs_square_problem():
    rng = np.random.default_rng(5)
    data = TimeData.from_rate(
        FS, {"F1": rng.standard_normal(4096), "F2": rng.standard_normal(4096), "y": rng.standard_normal(4096)}
    )
    with pytest.raises(DataError, match=r"'H2' needs one input or as many outputs as inputs.*2 inputs.*1 outputs"):
        estimate_frf(data, inputs=["F1", "F2"], outputs=["y"], estimator="H2", nperseg=512, coherence_fraction=1.0)


# -- (d) pyFRF cross-check ------------------------------------------------------------------------------------
def test_agrees_with_pyfrf(rig):
    ss = rig.system(params=DAMPED).state_space(["F1"], ["d1", "d2"])
    n = 2**15
    rng = np.random.default_rng(21)
    u = random_noise(fs=FS, duration=n / FS, rms=10.0, band=(5.0, 400.0), rng=6).values[0]
    y, _ = ss.simulate(u[:, None], np.arange(n) / FS)
    # micrometres keep |H| ~ 1: pyFRF's closed-form Hv cancels catastrophically when Gxx >> Gyy (m/N units)
    y = 1e6 * y + 0.05 * rng.standard_normal(y.shape)
    u = u + 0.5 * rng.standard_normal(n)
    data = TimeData.from_rate(FS, {"F1": u, "d1": y[:, 0], "d2": y[:, 1]})
    nper = 1024
    ref = FRF(
        int(FS),
        exc=u,
        resp=y.T[None],
        exc_type="f",
        resp_type="d",
        window="hann",
        nperseg=nper,
        noverlap=nper // 2,
        fft_len=nper,
    )
    lines = slice(1, None)  # pyFRF leaves the 0 Hz line to 0/0
    for est in ("H1", "H2", "Hv"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DataWarning)  # the noise floor above 400 Hz has low coherence
            mine = estimate_frf(
                data,
                inputs="F1",
                outputs=["d1", "d2"],
                estimator=est,
                nperseg=nper,
                noverlap=nper // 2,
                window=np.hanning(nper),
            )
        theirs = ref.get_FRF(frf_estimator=est)
        # same segments, window and detrending: H1, H2 agree to rounding; pyFRF's Hv formula subtracts
        # nearly equal numbers (relative error ~1e-16 Gxx / |Gyx| ~ 1e-10 here), the eigenvector does not
        rtol = 1e-6 if est == "Hv" else 1e-10
        np.testing.assert_allclose(mine.H[:, :, lines], theirs[:, :, lines], rtol=rtol, err_msg=est)
    np.testing.assert_allclose(mine.coherence[:, 0, lines], ref.get_coherence()[:, lines], rtol=0, atol=1e-10)


def test_agrees_with_pyfrf_mimo():
    rng = np.random.default_rng(22)
    n = 2**14
    u = rng.standard_normal((2, n))
    u[1] += 0.3 * u[0]  # partially correlated inputs
    y1 = lfilter([0.5, 0.2, -0.1], [1, -0.5], u[0]) + lfilter([0.1, -0.4], [1], u[1]) + 0.1 * rng.standard_normal(n)
    y2 = lfilter([0.3, 0.3], [1], u[0]) + lfilter([1.0, 0.0, 0.2], [1, 0.3], u[1]) + 0.1 * rng.standard_normal(n)
    data = TimeData.from_rate(FS, {"F1": u[0], "F2": u[1], "y1": y1, "y2": y2})
    ref = FRF(
        int(FS),
        exc=u[None],
        resp=np.stack([y1, y2])[None],
        exc_type="f",
        resp_type="d",
        window="hann",
        nperseg=256,
        noverlap=128,
        fft_len=256,
    )
    for est in ("H1", "H2"):
        mine = estimate_frf(
            data, inputs=["F1", "F2"], outputs=["y1", "y2"], estimator=est, nperseg=256, window=np.hanning(256)
        )
        np.testing.assert_allclose(mine.H, ref.get_FRF(frf_estimator=est), rtol=1e-10, err_msg=est)
    np.testing.assert_allclose(mine.coherence[:, 0], np.real(ref.get_coherence()), atol=1e-10)


# -- (e) impact test ------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def impact_case(rig):
    fs = 4096.0
    system = rig.system()  # the lightly damped rig: the response does not decay in a 1 s record
    ss = system.state_space(["F1"], ["d1", "d2"])
    force = impact(fs=fs, duration=1.0, amplitude=100.0, contact_time=2e-3, at=0.01).values[0]
    y, _ = ss.simulate(force[:, None], np.arange(force.size) / fs)
    return fs, system, ss, force, y


def _levy_poles(freq, h, fs, order):
    """Poles (rad/s) of a discrete rational fit B(z^-1) / A(z^-1) of degree ``order`` by linear least squares."""
    zi = np.exp(-2j * np.pi * freq / fs)
    powers = zi[:, None] ** np.arange(order + 1)[None, :]
    # h (1 + sum a_k z^-k) = sum b_k z^-k  ->  [-h z^-k, z^-k] [a; b] = h
    lhs = np.hstack([-h[:, None] * powers[:, 1:], powers])
    sol, *_ = np.linalg.lstsq(np.vstack([lhs.real, lhs.imag]), np.concatenate([h.real, h.imag]), rcond=None)
    z = np.roots(np.concatenate([[1.0], sol[:order]]))
    s = np.log(z.astype(complex)) * fs
    s = s[s.imag > 0]
    return s[np.argsort(s.imag)]


def test_impact_exponential_window_and_correction(impact_case):
    fs, system, ss, force, y = impact_case
    data = TimeData.from_rate(fs, {"F1": force, "d1": y[:, 0], "d2": y[:, 1]})
    # no window: the 1 s record truncates a response that decays over ~3 s; "auto" notices and windows
    auto = estimate_frf(data, inputs="F1", outputs=["d1", "d2"], impact=True)
    record = fs / (auto.freq[1] - auto.freq[0])  # samples from the pretrigger to the end
    assert auto.window_decay == pytest.approx(record / fs / np.log(100.0), rel=1e-12)  # 1 % at the record end
    tau = 0.1
    frf = estimate_frf(data, inputs="F1", outputs=["d1", "d2"], impact=True, exponential_window=tau, band=(20, 400))
    assert frf.window_decay == tau
    # the window on force and response makes the estimate H_d(z) at z = exp((j omega + 1/tau) / fs) exactly,
    # up to the response left at the record end (exp(-(0.29 + 10) * 1 s) ~ 3e-5 of the start; measured 3.8e-5)
    shifted = _discrete_frf(ss.discretize(1 / fs), frf.freq, fs, shift=1.0 / tau)
    scale = np.abs(shifted).max(axis=-1, keepdims=True)
    np.testing.assert_allclose(frf.H / scale, shifted / scale, rtol=0, atol=2e-4)
    # identify the poles (2 modes) from the windowed FRF, then correct them for the window
    measured = _levy_poles(frf.freq, frf.H[0, 0], fs, order=4)
    modes = system.modes()
    true_poles = modes.poles[np.argsort(modes.poles.imag)]
    np.testing.assert_allclose(measured.real, true_poles.real - 1 / tau, rtol=1e-4)  # shifted by -1/tau (2e-5)
    corrected = exponential_window_correction(tau=tau, poles=measured)
    # damping 0.05 % and 0.45 %: after removing 1/tau = 10 1/s the decay rates 0.29 and 4.75 1/s come back
    # within 0.5 % (Levy fit of a 1 Hz-resolution FRF with ~3e-5 truncation; measured 0.06 % and 6e-6)
    np.testing.assert_allclose(corrected.zeta, modes.damping, rtol=5e-3)
    np.testing.assert_allclose(corrected.freq, modes.frequency, rtol=1e-5)
    # the opposite sign (subtracting 1/tau again) or no correction leaves the damping tens of times too high
    for wrong in (measured - 1 / tau, measured):
        assert np.all(-wrong.real / np.abs(wrong) > 2.5 * modes.damping)


def test_exponential_window_correction_closed_form():
    # a pole p = -sigma + j omega_d measured through exp(-t/tau) reads -sigma - 1/tau + j omega_d
    sigma, omega_d, tau = 3.0, 2 * np.pi * 50.0, 0.05
    measured = complex(-sigma - 1 / tau, omega_d)
    out = exponential_window_correction(tau=tau, poles=[measured])
    np.testing.assert_allclose(out.poles, [complex(-sigma, omega_d)], rtol=1e-14)
    np.testing.assert_allclose(out.zeta, [sigma / np.hypot(sigma, omega_d)], rtol=1e-14)
    # the same through (freq, zeta) of the measured pole
    wn = abs(measured)
    again = exponential_window_correction(tau=tau, freq=[wn / (2 * np.pi)], zeta=[-measured.real / wn])
    np.testing.assert_allclose(again.poles, out.poles, rtol=1e-13)
    assert out.to_dict()["tau"] == tau


def test_impact_several_hits_are_averaged(impact_case):
    fs, _, _, force, y = impact_case
    n = force.size
    single = TimeData.from_rate(fs, {"F1": force, "d1": y[:, 0]})
    ref = estimate_frf(single, inputs="F1", outputs="d1", exponential_window=0.1, nperseg=n - 20)
    # three hits of different strength, each response from rest (as after a long wait), one record each
    gains = (1.0, 0.6, 1.4)
    data = TimeData.from_rate(
        fs, {"F1": np.concatenate([g * force for g in gains]), "d1": np.concatenate([g * y[:, 0] for g in gains])}
    )
    hits = detect_hits(data, channel="F1")
    np.testing.assert_allclose(hits.time, [0.0101 + k * n / fs for k in range(3)], atol=1 / fs)
    np.testing.assert_allclose(hits.peak, 100.0 * np.array(gains), rtol=1e-3)
    frf = estimate_frf(data, inputs="F1", outputs="d1", exponential_window=0.1, nperseg=n - 20)
    # linear and noise-free: every record gives the same FRF, so their average equals the single-hit estimate
    ok = np.isfinite(ref.H)
    np.testing.assert_allclose(frf.H[ok], ref.H[ok], rtol=1e-9)
    assert frf.coherence[0, 0, 1:400].min() > 1 - 1e-9


def test_force_window_removes_force_noise(rig):
    fs = 4096.0
    ss = rig.system(params=DAMPED).state_space(["F1"], ["d1"])  # decays within the 1 s record: no exp. window
    force = impact(fs=fs, duration=1.0, amplitude=100.0, contact_time=2e-3, at=0.01).values[0]
    y, _ = ss.simulate(force[:, None], np.arange(force.size) / fs)
    noisy = force + 0.5 * np.random.default_rng(31).standard_normal(force.size)  # 0.5 N noise, 100 N hit
    data = TimeData.from_rate(fs, {"F1": noisy, "d1": y[:, 0]})
    kw = {"inputs": "F1", "outputs": "d1", "impact": True, "exponential_window": None, "band": (20, 400)}
    with_fw = estimate_frf(data, **kw)
    without = estimate_frf(data, **kw, force_window=ForceWindow(width=0.98))  # keeps the whole record
    exact = _discrete_frf(ss.discretize(1 / fs), with_fw.freq, fs)[0, 0]
    err_with = np.median(np.abs(with_fw.H[0, 0] / exact - 1))
    err_without = np.median(np.abs(without.H[0, 0] / exact - 1))
    # noise summed over ~16 kept samples instead of ~4000 against a pulse area of ~570 N samples:
    # about sqrt(4000 / 16) = 16 times less force error (measured 0.7 % against 6.7 %)
    assert err_with < 0.015
    assert err_without > 5 * err_with


def test_double_hit_warns(rig):
    fs = 4096.0
    ss = rig.system(params=DAMPED).state_space(["F1"], ["d1"])
    force = impact(fs=fs, duration=0.5, amplitude=100.0, contact_time=2e-3, at=0.01, double_hit=(5e-3, 0.4))
    y, _ = ss.simulate(force.values[0][:, None], force.time)
    data = TimeData.from_rate(fs, {"F1": force.values[0], "d1": y[:, 0]})
    with pytest.warns(DataWarning, match=r"double hit\(s\) on input 'F1' at 0.0102\d* s"):
        frf = estimate_frf(data, inputs="F1", outputs="d1", impact=True, band=(20, 120))
    exact = _discrete_frf(ss.discretize(1 / fs), frf.freq, fs)[0, 0]
    # both pulses sit inside the force window, so H1 = Y / F is still right where F has no notch (< 120 Hz)
    np.testing.assert_allclose(frf.H[0, 0], exact, rtol=1e-3)
    assert frf.window_decay is None  # the damped rig has decayed by the record end: no exponential window


def test_detect_hits_hysteresis_and_spacing():
    fs = 1000.0
    x = np.zeros(2000)
    x[100:103] = [5.0, 10.0, 4.0]
    x[103:106] = [5.5, 9.0, 1.0]  # chatter on the falling edge: stays above half the threshold level (0.5)
    x[1100:1103] = [3.0, 8.0, 2.0]
    data = TimeData.from_rate(fs, {"F": x})
    hits = detect_hits(data, channel="F", threshold=0.1, min_spacing=0.5)
    assert hits.index.tolist() == [100, 1100]
    assert hits.n_crossings.tolist() == [1, 1]
    assert hits.to_dict()["double"] == [False, False]
    x[103] = 0.0  # falls below half the level, then rises again: a second crossing of the same hit
    hits = detect_hits(TimeData.from_rate(fs, {"F": x}), channel="F", threshold=0.1, min_spacing=0.5)
    assert hits.double.tolist() == [True, False]


# -- stepped sine ---------------------------------------------------------------------------------------------
def test_stepped_sine_frf_matches_exact(rig):
    ss = rig.system(params=DAMPED).state_space(["F1"], ["d1", "d2"])
    freqs = [30.0, 60.0, 89.5, 91.7, 120.0, 166.0, 250.0]
    plan = stepped_sine_schedule(freqs=freqs, fs=FS, dwell=0.75, settle=0.5)
    force = stepped_sine(freqs=freqs, amplitude=20.0, fs=FS, dwell=0.75, settle=0.5)
    y, _ = ss.simulate(force.values[0][:, None], force.time)
    data = TimeData.from_rate(FS, {"F1": force.values[0], "d1": y[:, 0], "d2": y[:, 1]})
    frf = stepped_sine_frf(data, schedule=plan, inputs="F1", outputs=["d1", "d2"])
    exact = _discrete_frf(ss.discretize(1 / FS), np.array(freqs), FS)
    scale = np.abs(exact).max(axis=-1, keepdims=True)
    # the transient of each step decays as exp(-18.9 t) (mode 1): after 0.5 s settling ~1e-4 of the step
    np.testing.assert_allclose(frf.H / scale, exact / scale, rtol=0, atol=2e-4)
    assert frf.coherence.min() > 0.999
    # with too short a settling time the left-over transient shows in the fit quality
    short = stepped_sine_schedule(freqs=freqs, fs=FS, dwell=0.75, settle=0.0)
    rough = stepped_sine_frf(data, schedule=short, inputs="F1", outputs=["d1", "d2"])
    assert rough.coherence.min() < frf.coherence.min()


def test_stepped_sine_frf_errors():
    plan = stepped_sine_schedule(freqs=[10.0, 20.0], fs=100.0, dwell=1.0)
    data = TimeData.from_rate(100.0, {"F": np.ones(150), "y": np.ones(150)})
    with pytest.raises(DataError, match=r"holds 150 samples but the schedule needs 200 \(2 steps of 100\)"):
        stepped_sine_frf(data, schedule=plan, inputs="F", outputs="y")
    other = TimeData.from_rate(200.0, {"F": np.ones(400), "y": np.ones(400)})
    with pytest.raises(DataError, match=r"sampled at 200 Hz but the schedule at 100 Hz"):
        stepped_sine_frf(other, schedule=plan, inputs="F", outputs="y")
    with pytest.raises(DataError, match=r"exactly one input channel; got \['F', 'y'\]"):
        stepped_sine_frf(other, schedule=plan, inputs=["F", "y"], outputs="y")
    with pytest.raises(DataError, match="'schedule' must be a SteppedSineSchedule; got dict"):
        stepped_sine_frf(other, schedule={}, inputs="F", outputs="y")


# -- (f) errors and warnings ----------------------------------------------------------------------------------
@pytest.fixture
def small():
    rng = np.random.default_rng(7)
    f = rng.standard_normal(2048)
    return TimeData.from_rate(FS, {"F": f, "y": np.convolve(f, [1.0, 0.3])[:2048], "z": rng.standard_normal(2048)})


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"inputs": "Q"}, r"input channel\(s\) \['Q'\] not found in the data; available channels: \['F', 'y', 'z'\]"),
        ({"outputs": ["y", "w"]}, r"output channel\(s\) \['w'\] not found in the data; available channels"),
        ({"outputs": ["F"]}, r"channel\(s\) \['F'\] are listed as both inputs and outputs"),
        ({"outputs": ["y", "y"]}, r"argument 'outputs' repeats channel\(s\) \['y'\]"),
        ({"outputs": []}, "argument 'outputs' must name at least one channel"),
        ({"inputs": 3}, "argument 'inputs' must be a channel name or a sequence of channel names; got 3"),
        ({"estimator": "H3"}, "argument 'estimator' must be 'H1', 'H2' or 'Hv'; got 'H3'"),
        (
            {"band": (10.0, 600.0)},
            r"argument 'band' must satisfy 0 <= f_lo < f_hi <= fs/2 \(Nyquist 512 Hz\); got \(10, 600\) Hz",
        ),
        ({"band": (100.0, 50.0)}, r"argument 'band' must satisfy 0 <= f_lo < f_hi .*; got \(100, 50\) Hz"),
        ({"band": 5.0}, r"argument 'band' must be a pair \(f_lo, f_hi\) in Hz; got 5.0"),
        (
            {"band": (100.2, 100.4), "nperseg": 256},
            r"band \(100.2, 100.4\) Hz holds no frequency line \(line spacing 4 Hz\)",
        ),
        ({"nperseg": 1}, "argument 'nperseg' must be an integer >= 2; got 1"),
        ({"nperseg": 4096}, "argument 'nperseg' = 4096 exceeds the 2048 samples of the data"),
        (
            {"nperseg": 256, "noverlap": 256},
            r"argument 'noverlap' must be an integer in \[0, nperseg\) = \[0, 256\); got 256",
        ),
        ({"noverlap": 10}, "argument 'noverlap' needs 'nperseg'"),
        ({"nperseg": 256, "n_averages": 4}, "give either 'nperseg' or 'n_averages', not both"),
        ({"n_averages": 0}, "argument 'n_averages' must be an integer >= 1; got 0"),
        (
            {"window": "nowindow", "nperseg": 256},
            "argument 'window' = 'nowindow' is not a window scipy.signal.get_window knows",
        ),
        (
            {"window": np.ones(10), "nperseg": 256},
            r"argument 'window' as an array must be 256 finite values, not all zero; got shape \(10,\)",
        ),
        ({"detrend": "quadratic"}, "argument 'detrend' must be 'constant', 'linear', 'auto' or None; got 'quadratic'"),
        ({"coherence_threshold": 1.5}, r"argument 'coherence_threshold' must be in \(0, 1\); got 1.5"),
        ({"coherence_fraction": -0.1}, r"argument 'coherence_fraction' must be in \[0, 1\]; got -0.1"),
        ({"hit_threshold": 0.0}, r"argument 'hit_threshold' must be in \(0, 1\); got 0.0"),
        ({"exponential_window": -1.0}, "argument 'exponential_window' must be > 0 s; got -1.0"),
        (
            {"exponential_window": "fast"},
            "argument 'exponential_window' must be a time constant in s, 'auto' or None; got 'fast'",
        ),
        ({"force_window": 0.1}, "argument 'force_window' must be a ForceWindow or None; got float"),
        (
            {"impact": True, "inputs": ["F", "z"]},
            r"impact mode takes exactly one input \(the hammer force\); got \['F', 'z'\]",
        ),
        ({"impact": True, "n_averages": 3}, "arguments 'n_averages' and 'noverlap' do not apply in impact mode"),
        (
            {"impact": True, "window": "hann"},
            r"argument 'window' must be 'boxcar' \(rectangular\) in impact mode; got 'hann'",
        ),
        ({"impact": True, "pretrigger": -0.1}, "argument 'pretrigger' must be >= 0 s; got -0.1"),
    ],
)
def test_estimate_frf_errors(small, kwargs, match):
    args = {"inputs": "F", "outputs": "y", **kwargs}
    with pytest.raises(DataError, match=match):
        estimate_frf(small, **args)


def test_estimate_frf_data_errors():
    with pytest.raises(DataError, match="data must be a cappe.io.TimeData; got dict"):
        estimate_frf({}, inputs="F", outputs="y")
    zero = TimeData.from_rate(FS, {"F": np.zeros(1024), "y": np.ones(1024)})
    with pytest.raises(DataError, match="force channel 'F' is zero everywhere; no hit to find"):
        estimate_frf(zero, inputs="F", outputs="y", impact=True)
    hit = np.zeros(1024)
    hit[1000:1003] = [1.0, 2.0, 1.0]
    late = TimeData.from_rate(FS, {"F": hit, "y": np.ones(1024)})
    with pytest.raises(
        DataError, match=r"no complete record of nperseg = 512 samples after any hit on input 'F' \(hits at 0.976"
    ):
        estimate_frf(late, inputs="F", outputs="y", impact=True, nperseg=512)
    with pytest.raises(DataError, match="ForceWindow width must be a positive time in s or None; got -1"):
        ForceWindow(width=-1)


def test_dropped_hit_warns():
    x = np.zeros(3000)
    x[10:13] = [1.0, 2.0, 1.0]
    x[2800:2803] = [1.0, 2.0, 1.0]
    data = TimeData.from_rate(FS, {"F": x, "y": np.convolve(x, [0.5, 0.2])[:3000]})
    with pytest.warns(
        DataWarning, match=r"hit\(s\) at 2.73.* s on input 'F' dropped: fewer than nperseg = 1024 samples follow"
    ):
        frf = estimate_frf(data, inputs="F", outputs="y", impact=True, nperseg=1024)
    np.testing.assert_allclose(frf.H[0, 0, :100], 0.5 + 0.2 * np.exp(-2j * np.pi * frf.freq[:100] / FS), rtol=1e-9)


def test_low_coherence_warning_names_pair_and_band():
    rng = np.random.default_rng(8)
    f = rng.standard_normal(8192)
    y = np.convolve(f, [1.0, 0.3])[:8192]
    data = TimeData.from_rate(FS, {"F": f, "good": y, "bad": y + 2.0 * rng.standard_normal(8192)})
    with pytest.warns(DataWarning) as record:
        frf = estimate_frf(data, inputs="F", outputs=["good", "bad"], nperseg=256, band=(50.0, 300.0))
    assert len(record) == 1  # only the noisy output
    message = str(record[0].message)
    assert re.search(
        r"low coherence for output 'bad' / input 'F': 100 % of the 63 lines in 50-300 Hz are below 0.8", message
    )
    summary = coherence_summary(frf, threshold=0.8)
    assert summary.low() == [("bad", "F")]
    assert summary.to_dict()["pairs"][0]["fraction_below"] == 0.0
    # the expected coherence of y + noise is |H|^2 / (|H|^2 + 4): below 0.32 on every line
    assert frf.coherence[1, 0].max() < 0.45


def test_low_multiple_coherence_warning():
    rng = np.random.default_rng(9)
    f1, f2 = rng.standard_normal((2, 8192))
    y = f1 + 0.5 * f2 + 3.0 * rng.standard_normal(8192)
    data = TimeData.from_rate(FS, {"F1": f1, "F2": f2, "y": y})
    with pytest.warns(DataWarning, match=r"output 'y' \(multiple coherence with inputs \['F1', 'F2'\]\)"):
        estimate_frf(data, inputs=["F1", "F2"], outputs="y", nperseg=256)


def test_coherence_summary_errors():
    model = FRFData(np.arange(3.0), np.ones((1, 1, 3), complex), ("F",), ("y",))
    with pytest.raises(DataError, match=r"needs measured FRFs \(FRFData with coherence\)"):
        coherence_summary(model)
    measured = FRFData(np.arange(3.0), np.ones((1, 1, 3), complex), ("F",), ("y",), coherence=np.ones((1, 1, 3)))
    with pytest.raises(DataError, match=r"band \(5.0, 6.0\) Hz holds no frequency line with a finite FRF"):
        coherence_summary(measured, band=(5.0, 6.0))
    with pytest.raises(DataError, match=r"argument 'threshold' must be in \(0, 1\); got 2"):
        coherence_summary(measured, threshold=2)
    with pytest.raises(DataError, match=r"argument 'band' must be a pair \(f_lo, f_hi\) in Hz; got 'all'"):
        coherence_summary(measured, band="all")


def test_detect_hits_errors():
    data = TimeData.from_rate(FS, {"F": np.r_[np.zeros(10), 1.0, np.zeros(10)]})
    with pytest.raises(DataError, match="argument 'min_spacing' must be > 0 s; got -1"):
        detect_hits(data, channel="F", min_spacing=-1)
    with pytest.raises(DataError, match=r"argument 'threshold' must be in \(0, 1\); got 1.0"):
        detect_hits(data, channel="F", threshold=1.0)
    with pytest.raises(DataError, match=r"unknown channel 'G'; the data has \['F'\]"):
        detect_hits(data, channel="G")


def test_window_correction_errors_and_warning():
    with pytest.raises(DataError, match="argument 'tau' must be > 0 s; got 0"):
        exponential_window_correction(tau=0, poles=[-1 + 10j])
    with pytest.raises(DataError, match="needs 'poles' or both 'freq' and 'zeta'"):
        exponential_window_correction(tau=1.0, freq=[10.0])
    with pytest.raises(DataError, match="give either 'poles' or 'freq' and 'zeta', not both"):
        exponential_window_correction(tau=1.0, poles=[-1 + 10j], freq=[10.0])
    with pytest.raises(DataError, match=r"argument 'zeta' must hold damping ratios in \[0, 1\); got \[1.5\]"):
        exponential_window_correction(tau=1.0, freq=[10.0], zeta=[1.5])
    with pytest.raises(DataError, match=r"argument 'freq' must hold finite natural frequencies > 0 Hz; got \[-1.0\]"):
        exponential_window_correction(tau=1.0, freq=[-1.0], zeta=[0.1])
    with pytest.raises(
        DataError, match=r"'freq' and 'zeta' must be 1-D of the same length; got shapes \(2,\) and \(1,\)"
    ):
        exponential_window_correction(tau=1.0, freq=[1.0, 2.0], zeta=[0.1])
    with pytest.raises(DataError, match="argument 'poles' must be a 1-D array of finite complex values"):
        exponential_window_correction(tau=1.0, poles=[np.nan])
    with pytest.warns(DataWarning, match=r"corrected damping is negative for mode\(s\) \[0\]"):
        out = exponential_window_correction(tau=0.1, poles=[-5.0 + 100j])  # decays slower than the window
    assert out.zeta[0] < 0


def test_clipped_channel_warns_by_name():
    rng = np.random.default_rng(5)
    force = rng.standard_normal(8192)
    response = np.convolve(force, np.exp(-np.arange(50) / 10.0), mode="same")
    limit = 0.6 * np.abs(response).max()
    data = TimeData.from_rate(1000.0, {"F": force, "acc": np.clip(response, -limit, limit)})
    with pytest.warns(DataWarning, match=r"look clipped .*'acc'"):
        estimate_frf(data, inputs=["F"], outputs=["acc"], nperseg=1024)
