"""Excitation signals for vibration tests: sine, stepped sine, square wave, chirp, random noise, PRBS and impacts.

Every generator is a keyword-only function that returns a single-channel :class:`~cappe.systems.TimeData`
(channel ``name``, default ``"F"``, in ``unit``, default ``"N"``), sampled at ``fs`` Hz from t = 0. The stepped
sine also has a :class:`SteppedSineSchedule` (frequency, start and settling time of each step) that
:func:`cappe.identify._frf.stepped_sine_frf` uses to estimate the FRF line by line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import scipy.signal as sig
from numpy.typing import ArrayLike, NDArray

from cappe._arguments import is_numeric, positive_number, real_number
from cappe._rng import RandomLike, as_generator
from cappe.exceptions import DataError
from cappe.systems.timedata import TimeData

__all__ = [
    "SteppedSineSchedule",
    "chirp",
    "impact",
    "prbs",
    "random_noise",
    "sine",
    "square",
    "stepped_sine",
    "stepped_sine_schedule",
]

Array = NDArray[np.float64]


# -- validation helpers ------------------------------------------------------------------------------------------
def _below_nyquist(name: str, value: Any, fs: float, *, allow_zero: bool = False) -> float:
    """A frequency in [0, fs/2) (Hz); ``allow_zero=False`` requires > 0."""
    out = real_number(name, value)
    if out < 0 or (out == 0 and not allow_zero):
        rule = ">= 0" if allow_zero else "> 0"
        msg = f"argument {name!r} must be {rule} Hz; got {value!r}"
        raise DataError(msg)
    if out >= fs / 2:
        msg = f"argument {name!r} must be below the Nyquist frequency fs/2 = {fs / 2:g} Hz; got {out:g} Hz"
        raise DataError(msg)
    return out


def _integer(name: str, value: Any, low: int) -> int:
    """An int (not a bool) >= ``low``."""
    if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < low:
        msg = f"argument {name!r} must be an integer >= {low}; got {value!r}"
        raise DataError(msg)
    return int(value)


def _n_samples(fs: float, duration: Any) -> int:
    dur = positive_number("duration", duration, "s")
    n = int(round(dur * fs))
    if n < 2:
        msg = f"argument 'duration' must span at least 2 samples at fs = {fs:g} Hz; got {dur:g} s"
        raise DataError(msg)
    return n


def _signal(x: Array, fs: float, name: str, unit: str) -> TimeData:
    return TimeData.from_channels(np.arange(x.size) / fs, {name: x}, units={name: unit})


# -- periodic signals --------------------------------------------------------------------------------------------
def sine(
    *,
    freq: float,
    amplitude: float,
    fs: float,
    duration: float,
    phase: float = 0.0,
    name: str = "F",
    unit: str = "N",
) -> TimeData:
    """Sine wave ``amplitude * sin(2 pi freq t + phase)``.

    Parameters
    ----------
    freq : float
        Frequency in Hz, 0 < freq < fs/2.
    amplitude : float
        Peak value in ``unit`` (RMS = amplitude / sqrt(2) over whole periods).
    fs : float
        Sampling rate in Hz.
    duration : float
        Record length in s (``round(duration * fs)`` samples).
    phase : float
        Phase at t = 0 in rad.
    name, unit : str
        Channel name and unit.

    Raises
    ------
    DataError
        If a number is not finite, ``fs``/``duration`` are not positive or ``freq`` is not in (0, fs/2).

    Examples
    --------
    >>> force = sine(freq=5.0, amplitude=10.0, fs=1000.0, duration=1.0)
    >>> round(float(force.values[0].std()), 4)
    7.0711
    """
    fs = positive_number("fs", fs, "Hz")
    f = _below_nyquist("freq", freq, fs)
    amp = real_number("amplitude", amplitude)
    ph = real_number("phase", phase)
    n = _n_samples(fs, duration)
    t = np.arange(n) / fs
    return _signal(amp * np.sin(2 * np.pi * f * t + ph), fs, name, unit)


def square(
    *,
    freq: float,
    amplitude: float,
    fs: float,
    duration: float,
    duty: float = 0.5,
    name: str = "F",
    unit: str = "N",
) -> TimeData:
    """Square wave switching between ``+amplitude`` and ``-amplitude`` (:func:`scipy.signal.square`).

    ``duty`` is the fraction of each period at ``+amplitude``. Its harmonics above fs/2 alias; keep ``freq`` well
    below the Nyquist frequency.

    Parameters
    ----------
    freq : float
        Frequency in Hz, 0 < freq < fs/2.
    amplitude : float
        Level in ``unit``.
    fs : float
        Sampling rate in Hz.
    duration : float
        Record length in s (``round(duration * fs)`` samples).
    duty : float
        Fraction of each period at ``+amplitude``, in [0, 1].
    name, unit : str
        Channel name and unit.

    Returns
    -------
    TimeData

    Raises
    ------
    DataError
        If a number is not finite, ``fs``/``duration`` are not positive, ``freq`` is not in (0, fs/2) or ``duty``
        not in [0, 1].

    Examples
    --------
    >>> force = square(freq=10.0, amplitude=2.0, fs=1000.0, duration=0.1, duty=0.25)
    >>> float((force.values[0] > 0).mean())
    0.25
    """
    fs = positive_number("fs", fs, "Hz")
    f = _below_nyquist("freq", freq, fs)
    amp = real_number("amplitude", amplitude)
    d = real_number("duty", duty)
    if not 0.0 <= d <= 1.0:
        msg = f"argument 'duty' must be in [0, 1] (fraction of the period at +amplitude); got {duty!r}"
        raise DataError(msg)
    n = _n_samples(fs, duration)
    t = np.arange(n) / fs
    return _signal(amp * np.asarray(sig.square(2 * np.pi * f * t, duty=d), dtype=float), fs, name, unit)


def chirp(
    *,
    f0: float,
    f1: float,
    fs: float,
    duration: float,
    amplitude: float = 1.0,
    method: Literal["linear", "logarithmic"] = "linear",
    name: str = "F",
    unit: str = "N",
) -> TimeData:
    """Swept sine from ``f0`` to ``f1`` Hz over ``duration`` s, starting at zero (``amplitude * sin(phase(t))``).

    The instantaneous frequency is ``f0 + (f1 - f0) t / T`` (``"linear"``) or ``f0 (f1 / f0)**(t / T)``
    (``"logarithmic"``, equal time per octave; needs f0, f1 > 0), T = ``duration``. Built on :func:`scipy.signal.chirp`.

    Parameters
    ----------
    f0, f1 : float
        Start and end frequency in Hz, in [0, fs/2) (> 0 for ``"logarithmic"``).
    fs : float
        Sampling rate in Hz.
    duration : float
        Record length in s.
    amplitude : float
        Peak value in ``unit``.
    method : {"linear", "logarithmic"}
        The sweep law.
    name, unit : str
        Channel name and unit.

    Returns
    -------
    TimeData

    Examples
    --------
    >>> sweep = chirp(f0=10.0, f1=200.0, fs=1000.0, duration=2.0, method="logarithmic")
    >>> sweep.n_samples, abs(float(sweep.values[0, 0])) < 1e-12
    (2000, True)
    """
    fs = positive_number("fs", fs, "Hz")
    if method not in ("linear", "logarithmic"):
        msg = f"argument 'method' must be 'linear' or 'logarithmic'; got {method!r}"
        raise DataError(msg)
    log = method == "logarithmic"
    start = _below_nyquist("f0", f0, fs, allow_zero=not log)
    stop = _below_nyquist("f1", f1, fs, allow_zero=not log)
    amp = real_number("amplitude", amplitude)
    n = _n_samples(fs, duration)
    t = np.arange(n) / fs
    t_end = n / fs
    if log and start == stop:
        # scipy's logarithmic sweep divides by log(f1 / f0); a constant frequency is a plain sine
        x = np.sin(2 * np.pi * start * t)
    else:
        x = sig.chirp(t, f0=start, t1=t_end, f1=stop, method=method, phi=-90.0)
    return _signal(amp * np.asarray(x, dtype=float), fs, name, unit)


# -- stepped sine ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SteppedSineSchedule:
    """The steps of a stepped-sine test: one frequency per step, held for ``dwell`` s.

    The first ``settle`` s of each step are left for the transient to die out; the FRF is estimated from the
    rest of the step (the measurement window).

    Attributes
    ----------
    freq : ndarray, shape (n_steps,)
        Step frequencies in Hz.
    fs : float
        Sampling rate in Hz.
    n_dwell : int
        Samples per step.
    n_settle : int
        Samples at the start of each step that the FRF estimate skips.
    """

    freq: Array
    fs: float
    n_dwell: int
    n_settle: int

    @property
    def n_steps(self) -> int:
        return int(self.freq.size)

    @property
    def dwell(self) -> float:
        """Step length in s."""
        return self.n_dwell / self.fs

    @property
    def settle(self) -> float:
        """Settling time in s."""
        return self.n_settle / self.fs

    @property
    def start(self) -> Array:
        """Start time of each step in s, shape (n_steps,)."""
        return np.arange(self.n_steps, dtype=float) * self.dwell

    @property
    def n_samples(self) -> int:
        """Samples of the whole test."""
        return self.n_steps * self.n_dwell

    def to_dict(self) -> dict[str, Any]:
        return {
            "freq": self.freq.tolist(),
            "fs": self.fs,
            "dwell": self.dwell,
            "settle": self.settle,
            "start": self.start.tolist(),
        }


def stepped_sine_schedule(
    *, freqs: ArrayLike, fs: float, dwell: float, settle: float | None = None
) -> SteppedSineSchedule:
    """Schedule of a stepped-sine test (see :func:`stepped_sine`).

    Parameters
    ----------
    freqs : array_like, shape (n_steps,)
        Step frequencies in Hz, each in (0, fs/2).
    fs : float
        Sampling rate in Hz.
    dwell : float
        Time per step in s.
    settle : float, optional
        Settling time at the start of each step in s, 0 <= settle < dwell; default dwell / 2. Choose a few time
        constants ``1 / (zeta omega_n)`` of the least damped mode. The rest of the step must hold at least one
        period of its frequency.

    Examples
    --------
    >>> plan = stepped_sine_schedule(freqs=[10.0, 20.0], fs=1000.0, dwell=0.5, settle=0.2)
    >>> plan.start.tolist(), plan.n_settle
    ([0.0, 0.5], 200)
    """
    fs = positive_number("fs", fs, "Hz")
    f = np.atleast_1d(np.asarray(freqs, dtype=float)) if is_numeric(freqs) else None
    if f is None or f.ndim != 1 or f.size == 0 or not np.all(np.isfinite(f)):
        msg = f"argument 'freqs' must be a non-empty 1-D sequence of finite frequencies in Hz; got {freqs!r}"
        raise DataError(msg)
    for value in f:
        _below_nyquist("freqs", value, fs)
    dw = positive_number("dwell", dwell, "s")
    st = dw / 2 if settle is None else real_number("settle", settle)
    if not 0 <= st < dw:
        msg = f"argument 'settle' must be in [0, dwell) = [0, {dw:g}) s; got {st:g} s"
        raise DataError(msg)
    n_dwell = int(round(dw * fs))
    n_settle = int(round(st * fs))
    window = (n_dwell - n_settle) / fs
    shortest = 1.0 / float(f.min())
    if window < shortest:
        msg = (
            f"the measurement window dwell - settle = {window:g} s must hold at least one period of the lowest "
            f"frequency ({f.min():g} Hz, {shortest:g} s); increase 'dwell' or reduce 'settle'"
        )
        raise DataError(msg)
    return SteppedSineSchedule(freq=f, fs=fs, n_dwell=n_dwell, n_settle=n_settle)


def stepped_sine(
    *,
    freqs: ArrayLike,
    amplitude: float,
    fs: float,
    dwell: float,
    settle: float | None = None,
    name: str = "F",
    unit: str = "N",
) -> TimeData:
    """Stepped sine: ``amplitude * sin(2 pi f_k tau)`` for ``dwell`` s at each frequency ``f_k``.

    ``tau`` restarts at 0 with every step, so every step starts at zero force. The same arguments give the
    :func:`stepped_sine_schedule` that :func:`~cappe.identify._frf.stepped_sine_frf` needs.

    Parameters
    ----------
    freqs : array_like, shape (n_steps,)
        Step frequencies in Hz, each in (0, fs/2).
    amplitude : float
        Peak value in ``unit``.
    fs : float
        Sampling rate in Hz.
    dwell : float
        Time per step in s.
    settle : float, optional
        Settling time at the start of each step in s (see :func:`stepped_sine_schedule`).
    name, unit : str
        Channel name and unit.

    Returns
    -------
    TimeData

    Examples
    --------
    >>> force = stepped_sine(freqs=[10.0, 20.0, 40.0], amplitude=5.0, fs=1000.0, dwell=0.5)
    >>> force.duration
    1.5
    """
    plan = stepped_sine_schedule(freqs=freqs, fs=fs, dwell=dwell, settle=settle)
    amp = real_number("amplitude", amplitude)
    tau = np.tile(np.arange(plan.n_dwell) / plan.fs, plan.n_steps)
    f = np.repeat(plan.freq, plan.n_dwell)
    return _signal(amp * np.sin(2 * np.pi * f * tau), plan.fs, name, unit)


# -- random signals ----------------------------------------------------------------------------------------------
def random_noise(
    *,
    fs: float,
    duration: float,
    rms: float,
    band: tuple[float, float] | None = None,
    periodic: bool = False,
    n_periods: int = 1,
    rng: RandomLike = None,
    name: str = "F",
    unit: str = "N",
) -> TimeData:
    """Band-limited random excitation, scaled to an exact RMS value.

    The spectrum is shaped in the FFT domain: every FFT line outside ``band`` is zero.

    * ``periodic=False``: Gaussian white noise with its out-of-band lines removed (a random amplitude on every
      line). Use Welch averaging with a taper window (``estimate_frf(window="hann")``).
    * ``periodic=True``: periodic random (random-phase multisine) - every in-band line of one period has the
      same amplitude and a uniformly random phase; the period is repeated ``n_periods`` times. With segments of
      exactly one period and a rectangular window (``estimate_frf(nperseg=period, noverlap=0,
      window="boxcar")``) the FRF has no leakage once the transient has died out (skip the first period).

    Parameters
    ----------
    fs : float
        Sampling rate in Hz.
    duration : float
        Total length in s; with ``periodic=True`` it must split into ``n_periods`` periods of whole samples.
    rms : float
        RMS value of the signal in ``unit`` (> 0).
    band : (float, float), optional
        Pass band ``(f_lo, f_hi)`` in Hz, 0 <= f_lo < f_hi <= fs/2; default: every line from the first above 0 Hz
        to fs/2. The mean (0 Hz line) is always zero.
    periodic : bool
        Periodic random instead of random noise.
    n_periods : int
        Number of identical periods (``periodic=True`` only).
    rng : int, numpy.random.Generator or None
        Seed or generator; the same seed gives the same signal.
    name, unit : str
        Channel name and unit.

    Raises
    ------
    DataError
        For a band outside [0, fs/2], a band without any FFT line, or a duration that does not split into
        ``n_periods`` periods.

    Examples
    --------
    >>> force = random_noise(fs=1000.0, duration=2.0, rms=3.0, band=(20.0, 200.0), rng=0)
    >>> round(float(np.sqrt(np.mean(force.values[0] ** 2))), 6)
    3.0
    """
    fs = positive_number("fs", fs, "Hz")
    n = _n_samples(fs, duration)
    level = positive_number("rms", rms, unit)
    n_periods = _integer("n_periods", n_periods, 1)
    if n_periods > 1 and not periodic:
        msg = f"argument 'n_periods' = {n_periods} needs periodic=True"
        raise DataError(msg)
    if n % n_periods:
        msg = f"argument 'duration' ({n} samples) must split into n_periods = {n_periods} periods of whole samples"
        raise DataError(msg)
    n_period = n // n_periods
    gen = as_generator(rng)
    freq = np.fft.rfftfreq(n_period, 1.0 / fs)
    f_lo, f_hi = _band(band, fs)
    keep = (freq >= f_lo) & (freq <= f_hi) & (freq > 0)
    if not keep.any():
        msg = (
            f"argument 'band' = {band!r} contains no FFT line of a {n_period}-sample period (line spacing "
            f"{fs / n_period:g} Hz); widen the band or lengthen the record"
        )
        raise DataError(msg)
    if periodic:
        spectrum = np.exp(2j * np.pi * gen.random(freq.size))
    else:
        spectrum = np.fft.rfft(gen.standard_normal(n_period))
    spectrum[~keep] = 0.0
    if n_period % 2 == 0 and keep[-1]:
        spectrum[-1] = spectrum[-1].real  # the Nyquist line of a real signal is real
    x = np.asarray(np.fft.irfft(spectrum, n=n_period), dtype=float)
    x *= level / np.sqrt(np.mean(x**2))
    return _signal(np.tile(x, n_periods), fs, name, unit)


def _band(band: tuple[float, float] | None, fs: float) -> tuple[float, float]:
    if band is None:
        return 0.0, fs / 2
    try:
        lo, hi = (float(v) for v in band)
    except (TypeError, ValueError):
        msg = f"argument 'band' must be a pair (f_lo, f_hi) in Hz; got {band!r}"
        raise DataError(msg) from None
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo < hi <= fs / 2):
        msg = f"argument 'band' must satisfy 0 <= f_lo < f_hi <= fs/2 (Nyquist {fs / 2:g} Hz); got ({lo:g}, {hi:g}) Hz"
        raise DataError(msg)
    return lo, hi


def prbs(
    *,
    fs: float,
    order: int | None = None,
    n_samples: int | None = None,
    amplitude: float = 1.0,
    clock_divider: int = 1,
    rng: RandomLike = None,
    name: str = "F",
    unit: str = "N",
) -> TimeData:
    """Pseudo-random binary sequence (maximum-length sequence) switching between ``+amplitude`` and ``-amplitude``.

    Built from :func:`scipy.signal.max_len_seq`. One period has ``2**order - 1`` bits; each bit is held for
    ``clock_divider`` samples, so a period is ``(2**order - 1) * clock_divider`` samples. Over one period the
    spectrum is flat: ``|DFT|**2 = 2**order * amplitude**2`` on every non-zero line (``clock_divider=1``); a divider
    p shapes it by ``sinc(f p / fs)**2`` and concentrates the power below fs / p.

    Parameters
    ----------
    fs : float
        Sampling rate in Hz.
    order : int, optional
        Register length, 2 <= order <= 32. Default: the smallest order whose period covers ``n_samples``.
    n_samples : int, optional
        Signal length in samples; default one period. Longer signals repeat the sequence periodically.
    amplitude : float
        Level in ``unit``.
    clock_divider : int
        Samples per bit (>= 1).
    rng : int, numpy.random.Generator or None
        None starts the register at all ones (scipy's default, a fixed sequence); a seed or generator draws a
        random non-zero start state, i.e. a random circular shift of the same sequence.
    name, unit : str
        Channel name and unit.

    Examples
    --------
    >>> x = prbs(fs=1000.0, order=5, amplitude=2.0).values[0]
    >>> x.size, float(x.sum())
    (31, 2.0)
    """
    fs = positive_number("fs", fs, "Hz")
    amp = real_number("amplitude", amplitude)
    divider = _integer("clock_divider", clock_divider, 1)
    if n_samples is not None:
        n_samples = _integer("n_samples", n_samples, 2)
    if order is None:
        if n_samples is None:
            msg = "prbs needs 'order' or 'n_samples'"
            raise DataError(msg)
        bits_needed = -(-n_samples // divider)
        order = max(2, int(math.ceil(math.log2(bits_needed + 1))))
    if not isinstance(order, (int, np.integer)) or isinstance(order, bool) or not 2 <= order <= 32:
        msg = f"argument 'order' must be an integer in [2, 32]; got {order!r}"
        raise DataError(msg)
    period_bits = 2 ** int(order) - 1
    n = period_bits * divider if n_samples is None else n_samples
    state = None
    if rng is not None:
        gen = as_generator(rng)
        state = gen.integers(0, 2, size=int(order))
        if not state.any():
            state[gen.integers(int(order))] = 1  # the all-zero register is the one forbidden state
    bits_needed = -(-n // divider)
    seq, _ = sig.max_len_seq(int(order), state=state, length=min(bits_needed, period_bits))
    if bits_needed > period_bits:
        seq = np.resize(seq, bits_needed)
    levels = np.repeat(2.0 * seq.astype(float) - 1.0, divider)[:n]
    return _signal(amp * levels, fs, name, unit)


# -- impact ------------------------------------------------------------------------------------------------------
def impact(
    *,
    fs: float,
    duration: float,
    amplitude: float,
    contact_time: float,
    at: float = 0.0,
    shape: Literal["half-sine", "haversine"] = "half-sine",
    double_hit: tuple[float, float] | None = None,
    name: str = "F",
    unit: str = "N",
) -> TimeData:
    """Force of an impact hammer: one pulse of peak ``amplitude`` lasting ``contact_time`` s, starting at ``at`` s.

    Shapes (``u = (t - at) / contact_time`` in [0, 1], zero elsewhere):

    * ``"half-sine"``: ``amplitude * sin(pi u)``; its Fourier transform is
      ``amplitude (pi / T) (1 + exp(-j w T)) / ((pi / T)**2 - w**2)`` times ``exp(-j w at)`` (T = contact_time),
      flat to about 1 / (2 T) and first zero at 1.5 / T.
    * ``"haversine"``: ``amplitude * (1 - cos(2 pi u)) / 2``, smoother, first zero at 2 / T.

    ``double_hit=(delay, ratio)`` adds a second pulse ``delay`` s after the first with ``ratio * amplitude`` peak,
    as when the hammer bounces.

    Parameters
    ----------
    fs : float
        Sampling rate in Hz.
    duration : float
        Record length in s.
    amplitude : float
        Peak force in ``unit``.
    contact_time : float
        Pulse length in s (at least 2 samples).
    at : float
        Start of the pulse in s.
    shape : {"half-sine", "haversine"}
        Pulse shape.
    double_hit : (float, float), optional
        ``(delay in s >= contact_time, amplitude ratio > 0)`` of a second pulse.
    name, unit : str
        Channel name and unit.

    Returns
    -------
    TimeData

    Raises
    ------
    DataError
        If the pulse is shorter than 2 samples or does not end inside the record.

    Examples
    --------
    >>> hit = impact(fs=10000.0, duration=0.1, amplitude=200.0, contact_time=1e-3, at=0.01)
    >>> float(hit.values[0].max()), int((hit.values[0] > 0).sum())
    (200.0, 9)
    """
    fs = positive_number("fs", fs, "Hz")
    n = _n_samples(fs, duration)
    amp = real_number("amplitude", amplitude)
    contact = positive_number("contact_time", contact_time, "s")
    if contact * fs < 2:
        msg = (
            f"argument 'contact_time' must span at least 2 samples at fs = {fs:g} Hz (>= {2 / fs:g} s); "
            f"got {contact:g} s"
        )
        raise DataError(msg)
    start = real_number("at", at)
    if shape not in ("half-sine", "haversine"):
        msg = f"argument 'shape' must be 'half-sine' or 'haversine'; got {shape!r}"
        raise DataError(msg)
    pulses = [(start, amp)]
    if double_hit is not None:
        try:
            delay, ratio = (float(v) for v in double_hit)
        except (TypeError, ValueError):
            msg = f"argument 'double_hit' must be a pair (delay in s, amplitude ratio); got {double_hit!r}"
            raise DataError(msg) from None
        if not (math.isfinite(delay) and math.isfinite(ratio) and delay >= contact and ratio > 0):
            msg = (
                f"argument 'double_hit' must have delay >= contact_time ({contact:g} s) and ratio > 0; "
                f"got {double_hit!r}"
            )
            raise DataError(msg)
        pulses.append((start + delay, ratio * amp))
    t = np.arange(n) / fs
    end = max(p[0] for p in pulses) + contact
    if start < 0 or end > t[-1]:
        msg = f"the pulse(s) must lie inside the record [0, {t[-1]:g}] s; they span [{start:g}, {end:g}] s"
        raise DataError(msg)
    x = np.zeros(n)
    for t0, peak in pulses:
        u = np.round((t - t0) / contact, 9)  # a sample that falls on the pulse end in exact arithmetic is 0
        inside = (u > 0) & (u < 1)  # both shapes are zero at the ends
        pulse = np.sin(np.pi * u) if shape == "half-sine" else 0.5 * (1 - np.cos(2 * np.pi * u))
        x += np.where(inside, peak * pulse, 0.0)
    return _signal(x, fs, name, unit)
