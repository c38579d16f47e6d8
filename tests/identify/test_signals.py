"""Excitation signals against closed forms: RMS, Fourier coefficients, chirp phase, flat PRBS spectrum,
half-sine pulse transform, band limits, reproducible seeds, and every error message."""

from __future__ import annotations

import numpy as np
import pytest

from cappe.exceptions import DataError
from cappe.identify._signals import (
    chirp,
    impact,
    prbs,
    random_noise,
    sine,
    square,
    stepped_sine,
    stepped_sine_schedule,
)


def test_sine_rms_amplitude_and_phase():
    fs, f, amp, phase = 1000.0, 12.5, 4.0, 0.7
    x = sine(freq=f, amplitude=amp, fs=fs, duration=2.0, phase=phase)  # 25 whole periods
    assert x.channels == ("F",)
    assert x.units == ("N",)
    assert x.fs == fs
    assert x.n_samples == 2000
    values = x.values[0]
    np.testing.assert_allclose(np.sqrt(np.mean(values**2)), amp / np.sqrt(2), rtol=1e-12)  # RMS of a sine
    # the only DFT line is 12.5 Hz, with amplitude * N / 2 and phase (phase - pi/2) of a sine
    spectrum = np.fft.rfft(values)
    k = int(f * 2.0)
    np.testing.assert_allclose(spectrum[k], amp * values.size / 2 * np.exp(1j * (phase - np.pi / 2)), rtol=1e-10)
    others = np.delete(np.abs(spectrum), k)
    assert others.max() < 1e-9 * abs(spectrum[k])
    named = sine(freq=f, amplitude=amp, fs=fs, duration=0.1, name="shaker", unit="kN")
    assert named.channels == ("shaker",)
    assert named.unit("shaker") == "kN"


@pytest.mark.parametrize("duty", [0.5, 0.25])
def test_square_levels_duty_and_fundamental(duty):
    fs, f, amp = 10000.0, 10.0, 3.0
    values = square(freq=f, amplitude=amp, fs=fs, duration=1.0, duty=duty).values[0]
    assert set(np.unique(values)) == {-amp, amp}
    # 1000 samples a period: the share of +A samples is the duty to within one sample a period (the edge sample
    # falls either side by rounding of the phase)
    np.testing.assert_allclose(np.mean(values > 0), duty, atol=1e-3)
    # Fourier series of a +-A pulse train with duty D: fundamental amplitude (4A / pi) sin(pi D); one sample
    # moved per period changes it by at most ~2 pi / 1000 relative
    fundamental = 2 * np.abs(np.fft.rfft(values)[int(f)]) / values.size
    np.testing.assert_allclose(fundamental, 4 * amp / np.pi * np.sin(np.pi * duty), rtol=5e-3)


def test_chirp_matches_closed_form_phase():
    fs, f0, f1, dur, amp = 2000.0, 5.0, 300.0, 2.0, 1.5
    t = np.arange(int(fs * dur)) / fs
    linear = chirp(f0=f0, f1=f1, fs=fs, duration=dur, amplitude=amp).values[0]
    # phase of a linear sweep: 2 pi (f0 t + (f1 - f0) t^2 / (2 T))
    np.testing.assert_allclose(linear, amp * np.sin(2 * np.pi * (f0 * t + (f1 - f0) * t**2 / (2 * dur))), atol=1e-9)
    log = chirp(f0=f0, f1=f1, fs=fs, duration=dur, amplitude=amp, method="logarithmic").values[0]
    # logarithmic: f(t) = f0 k^(t/T), k = f1 / f0, phase 2 pi T f0 (k^(t/T) - 1) / ln k
    k = f1 / f0
    np.testing.assert_allclose(log, amp * np.sin(2 * np.pi * dur * f0 * (k ** (t / dur) - 1) / np.log(k)), atol=1e-9)
    # instantaneous frequency from the zero crossings (linearly interpolated) of a finely sampled sweep: half a
    # period between two crossings, assigned to their midpoint
    fine = chirp(f0=f0, f1=f1, fs=40 * fs, duration=dur).values[0]
    s = np.signbit(fine)
    idx = np.flatnonzero(s[1:] != s[:-1])
    crossings = (idx + fine[idx] / (fine[idx] - fine[idx + 1])) / (40 * fs)
    inst = 0.5 / np.diff(crossings)
    expected = f0 + (f1 - f0) * (crossings[:-1] + crossings[1:]) / 2 / dur
    np.testing.assert_allclose(inst, expected, rtol=1e-3)  # crossing interpolation error ~(2 pi f dt)^2 / 6
    constant = chirp(f0=50.0, f1=50.0, fs=fs, duration=0.1, method="logarithmic").values[0]
    np.testing.assert_allclose(constant, np.sin(2 * np.pi * 50.0 * t[:200]), atol=1e-12)


@pytest.mark.parametrize("periodic", [False, True])
def test_random_noise_band_rms_and_seed(periodic):
    fs, dur, band = 1000.0, 4.0, (50.0, 150.0)
    kw = {"fs": fs, "duration": dur, "rms": 2.5, "band": band, "periodic": periodic, "rng": 42}
    x = random_noise(**kw).values[0]
    np.testing.assert_allclose(np.sqrt(np.mean(x**2)), 2.5, rtol=1e-12)
    power = np.abs(np.fft.rfft(x)) ** 2
    freq = np.fft.rfftfreq(x.size, 1 / fs)
    inside = (freq >= band[0]) & (freq <= band[1])
    assert power[~inside].max() < 1e-24 * power[inside].max()  # nothing outside the band but rounding
    np.testing.assert_array_equal(random_noise(**kw).values, x[None])  # the same seed, the same signal
    assert not np.allclose(random_noise(**{**kw, "rng": 43}).values[0], x)
    if periodic:
        # a random-phase multisine: every in-band line has the same amplitude
        np.testing.assert_allclose(power[inside], power[inside].mean(), rtol=1e-9)


def test_periodic_random_repeats_and_full_band():
    x = random_noise(fs=1000.0, duration=2.0, rms=1.0, periodic=True, n_periods=4, rng=np.random.default_rng(1))
    values = x.values[0].reshape(4, 500)
    np.testing.assert_array_equal(values, np.broadcast_to(values[0], values.shape))
    power = np.abs(np.fft.rfft(values[0])) ** 2
    # default band: every line from the first above 0 Hz to the Nyquist line, the mean removed
    np.testing.assert_allclose(power[1:-1], power[1:-1].mean(), rtol=1e-9)
    assert power[0] < 1e-20 * power[1]


def test_prbs_period_levels_and_flat_spectrum():
    order, amp = 7, 2.0
    x = prbs(fs=1000.0, order=order, amplitude=amp).values[0]
    n = 2**order - 1
    assert x.size == n
    assert set(np.unique(x)) == {-amp, amp}
    spectrum = np.fft.fft(x)
    # maximum-length sequence: periodic autocorrelation n A^2 at lag 0 and -A^2 elsewhere, hence
    # |X_k|^2 = (n + 1) A^2 on every line but 0, and X_0 = A (one more +1 than -1)
    np.testing.assert_allclose(np.abs(spectrum[1:]) ** 2, (n + 1) * amp**2, rtol=1e-10)
    np.testing.assert_allclose(spectrum[0], amp, atol=1e-10)
    # longer records repeat the period
    long = prbs(fs=1000.0, order=order, amplitude=amp, n_samples=3 * n + 5).values[0]
    np.testing.assert_array_equal(long[: 3 * n].reshape(3, n), np.broadcast_to(x, (3, n)))
    np.testing.assert_array_equal(long[3 * n :], x[:5])


def test_prbs_clock_divider_and_start_state():
    order, p = 5, 4
    bits = prbs(fs=1000.0, order=order).values[0]
    held = prbs(fs=1000.0, order=order, clock_divider=p).values[0]
    n = bits.size
    np.testing.assert_array_equal(held, np.repeat(bits, p))
    # holding each bit p samples shapes the flat spectrum: |X_k| = |B_(k mod n)| |sin(pi k / n) / sin(pi k / (n p))|
    k = np.arange(1, n * p)
    k = k[k % n != 0]
    shaped = np.abs(np.fft.fft(bits))[k % n] * np.abs(np.sin(np.pi * k / n) / np.sin(np.pi * k / (n * p)))
    np.testing.assert_allclose(np.abs(np.fft.fft(held))[k], shaped, rtol=1e-9, atol=1e-9)
    # a seeded start state gives a circular shift of the same sequence, reproducibly
    shifted = prbs(fs=1000.0, order=order, rng=3).values[0]
    np.testing.assert_array_equal(shifted, prbs(fs=1000.0, order=order, rng=3).values[0])
    matches = [s for s in range(n) if np.array_equal(np.roll(bits, -s), shifted)]
    assert len(matches) == 1
    # order from the length: the smallest register whose period (2^order - 1) covers 100 bits is 7
    assert prbs(fs=1000.0, n_samples=100).n_samples == 100
    np.testing.assert_array_equal(prbs(fs=1000.0, n_samples=100).values[0], prbs(fs=1000.0, order=7).values[0, :100])


def test_impact_half_sine_spectrum_matches_fourier_transform():
    fs, amp, contact, at = 100_000.0, 250.0, 1.1e-3, 2.03e-3  # 1/(2T) = 454.5 Hz, off the 50 Hz lines
    hit = impact(fs=fs, duration=0.02, amplitude=amp, contact_time=contact, at=at)
    x = hit.values[0]
    assert x.max() == pytest.approx(amp, rel=1e-3)  # 110 samples a pulse: the sampled peak is within 0.05 %
    freq = np.fft.rfftfreq(x.size, 1 / fs)[:80]  # to 4 kHz, beyond the first zero at 1.5 / T = 1.36 kHz
    w = 2 * np.pi * freq
    a = np.pi / contact
    closed = amp * a * (1 + np.exp(-1j * w * contact)) / (a**2 - w**2) * np.exp(-1j * w * at)
    sampled = np.fft.rfft(x)[:80] / fs  # Riemann sum of the transform; error O((dt / T)^2) of F(0)
    np.testing.assert_allclose(sampled, closed, rtol=0, atol=1e-3 * 2 * amp * contact / np.pi)


def test_impact_haversine_and_double_hit():
    fs, amp, contact = 50_000.0, 100.0, 2e-3
    x = impact(fs=fs, duration=0.05, amplitude=amp, contact_time=contact, at=0.01, shape="haversine").values[0]
    np.testing.assert_allclose(x.sum() / fs, amp * contact / 2, rtol=1e-9)  # area of (1 - cos) / 2: A T / 2
    assert x.argmax() == int(0.011 * fs)
    two = impact(fs=fs, duration=0.05, amplitude=amp, contact_time=contact, at=0.01, double_hit=(5e-3, 0.3)).values[0]
    first, second = two[: int(0.014 * fs)], two[int(0.014 * fs) :]
    np.testing.assert_allclose([first.max(), second.max()], [amp, 0.3 * amp], rtol=1e-9)
    assert second.argmax() + int(0.014 * fs) == int(0.0160 * fs)  # peak of the second pulse at 10 + 5 + 1 ms


def test_stepped_sine_samples_and_schedule():
    freqs, amp, fs = [5.0, 12.0, 40.0], 3.0, 500.0
    x = stepped_sine(freqs=freqs, amplitude=amp, fs=fs, dwell=0.4, settle=0.1).values[0]
    plan = stepped_sine_schedule(freqs=freqs, fs=fs, dwell=0.4, settle=0.1)
    assert x.size == plan.n_samples == 600
    assert plan.n_steps == 3
    assert plan.n_settle == 50
    tau = np.arange(200) / fs
    for k, f in enumerate(freqs):
        np.testing.assert_allclose(x[200 * k : 200 * (k + 1)], amp * np.sin(2 * np.pi * f * tau), atol=1e-12)
    assert plan.to_dict()["start"] == [0.0, 0.4, 0.8]
    assert plan.settle == pytest.approx(0.1)
    assert plan.dwell == pytest.approx(0.4)
    assert stepped_sine_schedule(freqs=freqs, fs=fs, dwell=0.4).n_settle == 100  # default: half the dwell


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (
            lambda: sine(freq=600.0, amplitude=1.0, fs=1000.0, duration=1.0),
            r"argument 'freq' must be below the Nyquist frequency fs/2 = 500 Hz; got 600 Hz",
        ),
        (lambda: sine(freq=0.0, amplitude=1.0, fs=1000.0, duration=1.0), "argument 'freq' must be > 0 Hz; got 0.0"),
        (
            lambda: sine(freq=10.0, amplitude=np.nan, fs=1000.0, duration=1.0),
            "argument 'amplitude' must be finite; got nan",
        ),
        (
            lambda: sine(freq=10.0, amplitude="big", fs=1000.0, duration=1.0),
            "argument 'amplitude' must be a real number; got 'big'",
        ),
        (lambda: sine(freq=10.0, amplitude=1.0, fs=-5.0, duration=1.0), "argument 'fs' must be > 0 Hz; got -5.0"),
        (
            lambda: sine(freq=10.0, amplitude=1.0, fs=1000.0, duration=0.001),
            "argument 'duration' must span at least 2 samples at fs = 1000 Hz; got 0.001 s",
        ),
        (
            lambda: square(freq=10.0, amplitude=1.0, fs=1000.0, duration=1.0, duty=1.2),
            r"argument 'duty' must be in \[0, 1\] \(fraction of the period at \+amplitude\); got 1.2",
        ),
        (
            lambda: chirp(f0=10.0, f1=900.0, fs=1000.0, duration=1.0),
            "argument 'f1' must be below the Nyquist frequency fs/2 = 500 Hz; got 900 Hz",
        ),
        (lambda: chirp(f0=-1.0, f1=100.0, fs=1000.0, duration=1.0), "argument 'f0' must be >= 0 Hz; got -1.0"),
        (
            lambda: chirp(f0=0.0, f1=100.0, fs=1000.0, duration=1.0, method="logarithmic"),
            "argument 'f0' must be > 0 Hz; got 0.0",
        ),
        (
            lambda: chirp(f0=1.0, f1=100.0, fs=1000.0, duration=1.0, method="cubic"),
            "argument 'method' must be 'linear' or 'logarithmic'; got 'cubic'",
        ),
        (
            lambda: random_noise(fs=1000.0, duration=1.0, rms=1.0, band=(10.0, 700.0)),
            r"argument 'band' must satisfy 0 <= f_lo < f_hi <= fs/2 \(Nyquist 500 Hz\); got \(10, 700\) Hz",
        ),
        (
            lambda: random_noise(fs=1000.0, duration=1.0, rms=1.0, band=10.0),
            r"argument 'band' must be a pair \(f_lo, f_hi\) in Hz; got 10.0",
        ),
        (
            lambda: random_noise(fs=1000.0, duration=0.1, rms=1.0, band=(20.1, 20.2)),
            r"argument 'band' = \(20.1, 20.2\) contains no FFT line of a 100-sample period \(line spacing 10 Hz\)",
        ),
        (lambda: random_noise(fs=1000.0, duration=1.0, rms=0.0), "argument 'rms' must be > 0 N; got 0.0"),
        (
            lambda: random_noise(fs=1000.0, duration=1.0, rms=1.0, periodic=True, n_periods=3),
            r"argument 'duration' \(1000 samples\) must split into n_periods = 3 periods of whole samples",
        ),
        (
            lambda: random_noise(fs=1000.0, duration=1.0, rms=1.0, n_periods=2),
            "argument 'n_periods' = 2 needs periodic=True",
        ),
        (
            lambda: random_noise(fs=1000.0, duration=1.0, rms=1.0, periodic=True, n_periods=0),
            "argument 'n_periods' must be an integer >= 1; got 0",
        ),
        (lambda: prbs(fs=1000.0), "prbs needs 'order' or 'n_samples'"),
        (lambda: prbs(fs=1000.0, order=40), r"argument 'order' must be an integer in \[2, 32\]; got 40"),
        (lambda: prbs(fs=1000.0, order=5, clock_divider=0), "argument 'clock_divider' must be an integer >= 1; got 0"),
        (lambda: prbs(fs=1000.0, n_samples=1), "argument 'n_samples' must be an integer >= 2; got 1"),
        (
            lambda: impact(fs=1000.0, duration=1.0, amplitude=10.0, contact_time=1e-3),
            r"argument 'contact_time' must span at least 2 samples at fs = 1000 Hz \(>= 0.002 s\); got 0.001 s",
        ),
        (
            lambda: impact(fs=1000.0, duration=1.0, amplitude=10.0, contact_time=0.01, at=0.995),
            r"the pulse\(s\) must lie inside the record \[0, 0.999\] s; they span \[0.995, 1.005\] s",
        ),
        (
            lambda: impact(fs=1000.0, duration=1.0, amplitude=10.0, contact_time=0.01, shape="square"),
            "argument 'shape' must be 'half-sine' or 'haversine'; got 'square'",
        ),
        (
            lambda: impact(fs=1000.0, duration=1.0, amplitude=10.0, contact_time=0.01, double_hit=(0.001, 0.5)),
            r"argument 'double_hit' must have delay >= contact_time \(0.01 s\) and ratio > 0; got \(0.001, 0.5\)",
        ),
        (
            lambda: impact(fs=1000.0, duration=1.0, amplitude=10.0, contact_time=0.01, double_hit=0.5),
            r"argument 'double_hit' must be a pair \(delay in s, amplitude ratio\); got 0.5",
        ),
        (
            lambda: stepped_sine(freqs=[], amplitude=1.0, fs=1000.0, dwell=1.0),
            r"argument 'freqs' must be a non-empty 1-D sequence of finite frequencies in Hz; got \[\]",
        ),
        (
            lambda: stepped_sine(freqs=[10.0, 800.0], amplitude=1.0, fs=1000.0, dwell=1.0),
            "argument 'freqs' must be below the Nyquist frequency fs/2 = 500 Hz; got 800 Hz",
        ),
        (
            lambda: stepped_sine(freqs=[10.0], amplitude=1.0, fs=1000.0, dwell=1.0, settle=1.0),
            r"argument 'settle' must be in \[0, dwell\) = \[0, 1\) s; got 1 s",
        ),
        (
            lambda: stepped_sine(freqs=[2.0], amplitude=1.0, fs=1000.0, dwell=1.0, settle=0.8),
            r"the measurement window dwell - settle = 0.2 s must hold at least one period of the lowest frequency \(2 Hz, 0.5 s\)",
        ),
    ],
)
def test_signal_errors(make, match):
    with pytest.raises(DataError, match=match):
        make()
