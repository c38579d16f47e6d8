"""FRF estimation from measured time data.

* :func:`estimate_frf`: H1, H2 and Hv estimators with Welch averaging (random, periodic random, PRBS, chirp
  excitation) or one record per hit (impact tests, with force and exponential windows); several inputs at once;
  ordinary or multiple coherence.
* :func:`stepped_sine_frf`: one FRF line per step of a stepped-sine test.
* :func:`exponential_window_correction`: poles and damping ratios corrected for an exponential window.
* :func:`coherence_summary`, :func:`detect_hits`: helpers for checks and reports.

Conventions: spectral matrices per frequency line are ``Gxx[a, b] = E[X_a conj(X_b)]`` (inputs x inputs),
``Gyx[o, i] = E[Y_o conj(X_i)]`` and ``Gyy[o, p] = E[Y_o conj(Y_p)]``, averaged over segments (records). Their common
scale factor (PSD density scaling) cancels in every estimator and in the coherence, so it is not applied.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import scipy.signal as sig
from numpy.typing import ArrayLike, NDArray

from cappe._arguments import positive_number, real_number
from cappe.exceptions import DataError, DataWarning, IllConditionedWarning
from cappe.identify._signals import SteppedSineSchedule, _band, _integer
from cappe.io.measurements import match_channels
from cappe.systems.frf import FRFData
from cappe.systems.timedata import TimeData, check_clipping

__all__ = [
    "CoherenceSummary",
    "ForceWindow",
    "Hits",
    "WindowCorrectedModes",
    "coherence_summary",
    "detect_hits",
    "estimate_frf",
    "exponential_window_correction",
    "stepped_sine_frf",
]

Array = NDArray[np.float64]
CArray = NDArray[np.complex128]

# cond(Gxx) above this means inputs with a mutual coherence above ~0.996 (2 inputs): H1 amplifies noise by about cond
_COND_LIMIT = 1e3
# lines whose input power is below this fraction of the peak carry no information (0/0 up to rounding): H = nan
_DEAD_POWER = 1e-20
# with band=None the coherence check looks at the lines within 40 dB of the peak input power (the excited band)
_EXCITED_POWER = 1e-4
# segments are transformed in blocks of about this many samples, so memory stays bounded on long records
_BLOCK_SAMPLES = 2**22
# an impact response whose RMS over the last 5 % of the record exceeds 1 % of its peak has not decayed
_TAIL_FRACTION = 0.05
_TAIL_LEVEL = 0.01
_QUANTITIES = {
    "m": "displacement",
    "m/s": "velocity",
    "m/s^2": "acceleration",
    "m/s2": "acceleration",
    "m/s**2": "acceleration",
}


# -- small result types ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ForceWindow:
    """Force window of an impact test: keep the pulse, zero the rest of the force record.

    The window is 1 from the record start to ``width`` s after the hit's trigger (the threshold crossing),
    falls to 0 with a half-cosine taper of ``taper`` s and stays 0 to the record end, removing the force
    channel's noise between hits.

    Attributes
    ----------
    width : float, optional
        Kept time after the trigger in s. Default: twice the time the force stays above the hit threshold
        (the pulse plus a margin of about one contact time), found from each record.
    taper : float, optional
        Taper length in s. Default: half the time above the threshold, at least 2 samples.

    Examples
    --------
    >>> ForceWindow(width=2e-3).to_dict()
    {'width': 0.002, 'taper': None}
    """

    width: float | None = None
    taper: float | None = None

    def __post_init__(self) -> None:
        for name in ("width", "taper"):
            value = getattr(self, name)
            if value is not None and not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                msg = f"ForceWindow {name} must be a positive time in s or None; got {value!r}"
                raise DataError(msg)

    def to_dict(self) -> dict[str, Any]:
        return {"width": self.width, "taper": self.taper}


@dataclass(frozen=True)
class Hits:
    """Hits found on a force channel (see :func:`detect_hits`).

    Attributes
    ----------
    index : ndarray of int, shape (n_hits,)
        Sample of each hit's trigger (first threshold crossing).
    time : ndarray, shape (n_hits,)
        Trigger times in s.
    peak : ndarray, shape (n_hits,)
        Peak absolute force of each hit (including any double hit) in the channel's unit.
    n_crossings : ndarray of int, shape (n_hits,)
        Threshold crossings that belong to the hit; more than 1 means a double hit.
    end : ndarray of int, shape (n_hits,)
        Last sample above the threshold that belongs to the hit.
    level : float
        Absolute threshold (channel unit).
    """

    index: NDArray[np.intp]
    time: Array
    peak: Array
    n_crossings: NDArray[np.intp]
    end: NDArray[np.intp]
    level: float

    @property
    def n_hits(self) -> int:
        return int(self.index.size)

    @property
    def double(self) -> NDArray[np.bool_]:
        """True for hits with a double hit (a second pulse before the next record)."""
        return np.asarray(self.n_crossings > 1)

    def to_dict(self) -> dict[str, Any]:
        return {
            "time": self.time.tolist(),
            "peak": self.peak.tolist(),
            "double": self.double.tolist(),
            "level": self.level,
        }


@dataclass(frozen=True)
class CoherenceSummary:
    """Share of each FRF's lines whose coherence is below a threshold.

    Attributes
    ----------
    threshold : float
        The coherence threshold (0..1).
    input_names, output_names : tuple of str
        Channels along the second and first axes of the arrays.
    fraction_below : ndarray, shape (n_out, n_in)
        Fraction of the checked lines with coherence below ``threshold``.
    minimum : ndarray, shape (n_out, n_in)
        Lowest coherence over the checked lines.
    freq_of_minimum : ndarray, shape (n_out, n_in)
        Frequency of that minimum in Hz.
    band : (float, float)
        Checked band in Hz.
    n_lines : int
        Number of checked lines.
    """

    threshold: float
    band: tuple[float, float]
    n_lines: int
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    fraction_below: Array
    minimum: Array
    freq_of_minimum: Array

    def low(self, fraction: float = 0.1) -> list[tuple[str, str]]:
        """(output, input) pairs whose fraction of low-coherence lines exceeds ``fraction``.

        Parameters
        ----------
        fraction : float
            Share of the checked lines (0..1) above which a pair is listed.

        Returns
        -------
        list of (str, str)
        """
        rows, cols = np.nonzero(self.fraction_below > fraction)
        return [(self.output_names[r], self.input_names[c]) for r, c in zip(rows, cols, strict=True)]

    def to_dict(self) -> dict[str, Any]:
        pairs = [
            {
                "output": out,
                "input": inp,
                "fraction_below": float(self.fraction_below[o, i]),
                "minimum": float(self.minimum[o, i]),
                "freq_of_minimum": float(self.freq_of_minimum[o, i]),
            }
            for o, out in enumerate(self.output_names)
            for i, inp in enumerate(self.input_names)
        ]
        return {"threshold": self.threshold, "band": list(self.band), "n_lines": self.n_lines, "pairs": pairs}


@dataclass(frozen=True)
class WindowCorrectedModes:
    """Modes corrected for an exponential window (see :func:`exponential_window_correction`).

    Attributes
    ----------
    poles : ndarray, shape (n_modes,)
        Corrected poles in rad/s.
    freq : ndarray, shape (n_modes,)
        Natural frequencies ``|pole| / 2 pi`` in Hz.
    zeta : ndarray, shape (n_modes,)
        Damping ratios ``-Re(pole) / |pole|``.
    tau : float
        Window time constant in s.
    """

    poles: CArray
    freq: Array
    zeta: Array
    tau: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "tau": self.tau,
            "freq": self.freq.tolist(),
            "zeta": self.zeta.tolist(),
            "poles_re": self.poles.real.tolist(),
            "poles_im": self.poles.imag.tolist(),
        }


# -- validation helpers ------------------------------------------------------------------------------------------
def _names(value: Any, what: str) -> tuple[str, ...]:
    names: tuple[Any, ...]
    if isinstance(value, str):
        names = (value,)
    else:
        try:
            names = tuple(value)
        except TypeError:
            msg = f"argument {what!r} must be a channel name or a sequence of channel names; got {value!r}"
            raise DataError(msg) from None
    if not names or not all(isinstance(n, str) for n in names):
        msg = f"argument {what!r} must name at least one channel (strings); got {value!r}"
        raise DataError(msg)
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        msg = f"argument {what!r} repeats channel(s) {repeated}"
        raise DataError(msg)
    return tuple(names)


def _check_data(data: Any) -> TimeData:
    if not isinstance(data, TimeData):
        msg = f"data must be a cappe.io.TimeData; got {type(data).__name__}"
        raise DataError(msg)
    return data


def _fraction_arg(name: str, value: Any, *, open_low: bool = True, open_high: bool = True) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        out = math.nan
    low_ok = out > 0 if open_low else out >= 0
    high_ok = out < 1 if open_high else out <= 1
    if not (math.isfinite(out) and low_ok and high_ok):
        interval = f"{'(' if open_low else '['}0, 1{')' if open_high else ']'}"
        msg = f"argument {name!r} must be in {interval}; got {value!r}"
        raise DataError(msg)
    return out


def _window_arg(window: Any, nperseg: int) -> Array:
    if isinstance(window, (str, tuple)):
        try:
            return np.asarray(sig.get_window(window, nperseg), dtype=float)
        except (ValueError, TypeError) as exc:
            msg = f"argument 'window' = {window!r} is not a window scipy.signal.get_window knows: {exc}"
            raise DataError(msg) from exc
    win = np.asarray(window, dtype=float)
    if win.shape != (nperseg,) or not np.all(np.isfinite(win)) or not np.any(win):
        msg = f"argument 'window' as an array must be {nperseg} finite values, not all zero; got shape {win.shape}"
        raise DataError(msg)
    return win


def _quantities(data: TimeData, outputs: tuple[str, ...]) -> tuple[str, ...]:
    found = tuple(_QUANTITIES.get(data.unit(o).replace(" ", ""), "") for o in outputs)
    return found if all(found) else ()


# -- spectral matrices -------------------------------------------------------------------------------------------
@dataclass
class _Spectra:
    """Averaged spectral matrices with frequency first: gxx (n_f, n_in, n_in), gyx (n_f, n_out, n_in),
    gyy_diag (n_f, n_out) and, when asked for, gyy (n_f, n_out, n_out)."""

    gxx: CArray
    gyx: CArray
    gyy_diag: Array
    gyy: CArray | None
    n_avg: int


def _accumulate(blocks: Iterator[tuple[CArray, CArray]], full_gyy: bool) -> _Spectra:
    """Sum the spectral products of blocks of segment spectra ``X (n_in, n_seg, n_f)``, ``Y (n_out, n_seg, n_f)``."""
    gxx: CArray | None = None
    gyx: CArray | None = None
    gyy: CArray | None = None
    gyy_diag: Array | None = None
    count = 0
    for x, y in blocks:
        xf = x.transpose(2, 0, 1)  # (n_f, n_in, n_seg): frequency is the batch axis of the products
        yf = y.transpose(2, 0, 1)
        xh = xf.conj().transpose(0, 2, 1)
        parts = (xf @ xh, yf @ xh, (yf.real**2 + yf.imag**2).sum(axis=-1))
        full = yf @ yf.conj().transpose(0, 2, 1) if full_gyy else None
        if gxx is None or gyx is None or gyy_diag is None:
            gxx, gyx, gyy_diag, gyy = parts[0], parts[1], parts[2], full
        else:
            gxx += parts[0]
            gyx += parts[1]
            gyy_diag += parts[2]
            if gyy is not None and full is not None:
                gyy += full
        count += x.shape[1]
    if gxx is None or gyx is None or gyy_diag is None:  # pragma: no cover - callers always give a block
        msg = "no segment to average"
        raise DataError(msg)
    return _Spectra(gxx / count, gyx / count, gyy_diag / count, None if gyy is None else gyy / count, count)


def _welch_blocks(
    values: Array, n_in: int, nperseg: int, noverlap: int, win: Array, detrend: str | None
) -> Iterator[tuple[CArray, CArray]]:
    """Segment spectra of all channels, a block of segments at a time.

    Own segmenting rather than :func:`scipy.signal.csd`: csd transforms both signals again for every channel
    pair; here each channel's segments are transformed once and the whole spectral matrix is formed from them.
    """
    step = nperseg - noverlap
    n_seg = (values.shape[1] - nperseg) // step + 1
    view = np.lib.stride_tricks.sliding_window_view(values, nperseg, axis=-1)[:, ::step][:, :n_seg]
    per_block = max(1, _BLOCK_SAMPLES // (nperseg * values.shape[0]))
    for first in range(0, n_seg, per_block):
        seg = view[:, first : first + per_block]
        if detrend is not None:
            seg = sig.detrend(seg, type=detrend, axis=-1)
        spectra = np.fft.rfft(seg * win, axis=-1)
        yield spectra[:n_in], spectra[n_in:]


# -- hits and impact records -------------------------------------------------------------------------------------
def detect_hits(data: TimeData, *, channel: str, threshold: float = 0.1, min_spacing: float | None = None) -> Hits:
    """Find the hits of an impact hammer on a force channel by a threshold.

    A hit starts where ``|force|`` rises through ``threshold * max|force|``. Crossings within ``min_spacing``
    s of a hit's trigger belong to that hit (a double hit); a crossing only counts after the force has fallen
    below half the threshold (hysteresis against noise on the rising edge).

    Parameters
    ----------
    data : TimeData
        Measured data.
    channel : str
        Force channel.
    threshold : float
        Trigger level as a fraction of the largest absolute force, in (0, 1).
    min_spacing : float, optional
        Shortest time between separate hits in s; default 10 % of the record.

    Raises
    ------
    DataError
        If the channel is unknown or identically zero.

    Examples
    --------
    >>> from cappe.identify._signals import impact
    >>> hits = detect_hits(impact(fs=1e4, duration=0.2, amplitude=100.0, contact_time=1e-3, at=0.05,
    ...                           double_hit=(4e-3, 0.3)), channel="F")
    >>> hits.n_hits, hits.time.round(4).tolist(), hits.double.tolist()
    (1, [0.0501], [True])
    """
    data = _check_data(data)
    x = np.abs(data.channel(channel))
    thr = _fraction_arg("threshold", threshold)
    spacing = (
        max(1, int(round(0.1 * data.n_samples)))
        if min_spacing is None
        else max(1, int(round(positive_number("min_spacing", min_spacing, "s") * data.fs)))
    )
    peak = float(x.max())
    if peak == 0.0:
        msg = f"force channel {channel!r} is zero everywhere; no hit to find"
        raise DataError(msg)
    level = thr * peak
    above = x >= level
    rising = np.flatnonzero(above[1:] & ~above[:-1]) + 1
    if above[0]:
        rising = np.concatenate(([0], rising))
    quiet = np.cumsum(x < level / 2)  # number of re-arming samples up to each sample
    starts: list[int] = []
    counts: list[int] = []
    last_counted = -1
    for k in rising:  # a loop over crossings (a handful per record), not over samples
        if last_counted >= 0 and quiet[k] == quiet[last_counted]:
            continue  # chatter on the same edge: the force never fell below half the threshold
        last_counted = int(k)
        if starts and k - starts[-1] < spacing:
            counts[-1] += 1
        else:
            starts.append(int(k))
            counts.append(1)
    index = np.asarray(starts, dtype=np.intp)
    bounds = np.append(index[1:], x.size)
    peaks = np.array([x[a:b].max() for a, b in zip(index, bounds, strict=True)])
    ends = np.array([a + np.flatnonzero(above[a:b])[-1] for a, b in zip(index, bounds, strict=True)], dtype=np.intp)
    return Hits(index, data.time[index], peaks, np.asarray(counts), ends, level)


def _impact_blocks(
    data: TimeData,
    in_row: int,
    out_rows: list[int],
    *,
    input_name: str,
    nperseg: int | None,
    detrend: str | None,
    force_window: ForceWindow,
    exponential_window: float | str | None,
    hit_threshold: float,
    pretrigger: float | None,
) -> tuple[CArray, CArray, int, float | None]:
    """Records around each hit, windowed and transformed: X (1, n_rec, n_f), Y (n_out, n_rec, n_f)."""
    n = data.n_samples
    fs = data.fs
    spacing = None if nperseg is None else nperseg / fs
    hits = detect_hits(data, channel=input_name, threshold=hit_threshold, min_spacing=spacing)
    if hits.double.any():
        times = ", ".join(f"{t:.6g} s" for t in hits.time[hits.double])
        warnings.warn(
            f"double hit(s) on input {input_name!r} at {times}: the force spectrum has notches, expect low "
            f"coherence there; the records are kept",
            DataWarning,
            stacklevel=3,
        )
    idx = hits.index
    span0 = nperseg if nperseg is not None else int(min(np.diff(idx).min(initial=n), n - idx[-1]))
    npre = max(2, span0 // 100) if pretrigger is None else int(round(pretrigger * fs))
    starts = np.maximum(idx - npre, 0)
    length = nperseg if nperseg is not None else int(min(np.diff(starts).min(initial=n), n - starts[-1]))
    fits = starts + length <= n
    if not fits.all():
        dropped = ", ".join(f"{t:.6g} s" for t in hits.time[~fits])
        if not fits.any():
            msg = (
                f"no complete record of nperseg = {length} samples after any hit on input {input_name!r} "
                f"(hits at {dropped}, {n} samples in all); reduce nperseg"
            )
            raise DataError(msg)
        warnings.warn(
            f"hit(s) at {dropped} on input {input_name!r} dropped: fewer than nperseg = {length} samples follow",
            DataWarning,
            stacklevel=3,
        )
    starts, trig, ends = starts[fits], idx[fits], hits.end[fits]
    take = starts[:, None] + np.arange(length)[None, :]
    x = data.values[in_row][take]  # (n_rec, L)
    y = data.values[out_rows][:, take]  # (n_out, n_rec, L)
    if detrend is not None:
        x = sig.detrend(x, type=detrend, axis=-1)
        y = sig.detrend(y, type=detrend, axis=-1)
    # force window, one per record: 1 up to the trigger + width, half-cosine taper, then 0
    above = np.maximum(ends - trig + 1, 1)
    width = 2 * above if force_window.width is None else np.full(trig.shape, int(round(force_window.width * fs)))
    taper = (
        np.maximum(above // 2, 2)
        if force_window.taper is None
        else np.full(trig.shape, max(1, int(round(force_window.taper * fs))))
    )
    keep = (trig - starts) + width
    k = np.arange(length)[None, :]
    u = np.clip((k - keep[:, None]) / taper[:, None], 0.0, 1.0)
    x = x * (0.5 * (1.0 + np.cos(np.pi * u)))
    tau: float | None = None
    if exponential_window == "auto":
        n_tail = max(1, int(round(_TAIL_FRACTION * length)))
        tail = np.sqrt(np.mean(y[:, :, -n_tail:] ** 2, axis=(1, 2)))
        peak = np.abs(y).max(axis=(1, 2))
        if np.any(tail > _TAIL_LEVEL * peak):
            tau = length / fs / math.log(1.0 / _TAIL_LEVEL)  # the window falls to 1 % at the record end
    elif exponential_window is not None:
        tau = float(exponential_window)
    if tau is not None:
        # the same window on force and response: the estimate is H(s) at s = j omega + 1/tau exactly, i.e. every
        # pole moves by -1/tau whatever the pulse shape or where the record starts
        decay = np.exp(-np.arange(length) / (fs * tau))
        x = x * decay
        y = y * decay
    return np.fft.rfft(x, axis=-1)[None], np.fft.rfft(y, axis=-1), length, tau


# -- estimators --------------------------------------------------------------------------------------------------
def _solve_rows(a: CArray, b: CArray) -> CArray:
    """``X`` with ``X @ a = b`` for stacks of square ``a``; pseudo-inverse where ``a`` is exactly singular."""
    try:
        return np.asarray(np.linalg.solve(a.transpose(0, 2, 1), b.transpose(0, 2, 1)).transpose(0, 2, 1), dtype=complex)
    except np.linalg.LinAlgError:
        return np.asarray(b @ np.linalg.pinv(a), dtype=complex)


def _h1(s: _Spectra) -> CArray:
    """``H1 = Gyx Gxx^-1`` per line, shape (n_f, n_out, n_in)."""
    return _solve_rows(s.gxx, s.gyx)


def _h2(s: _Spectra) -> CArray:
    """``H2 = Gyy Gxy^-1`` per line (single input: ``Gyy / Gxy`` for every output); square problems only."""
    if s.gyx.shape[2] == 1:
        return (s.gyy_diag / s.gyx[:, :, 0].conj())[:, :, None]
    if s.gyy is None:  # pragma: no cover - estimate_frf asks for the full Gyy whenever H2 has several inputs
        msg = "H2 with several inputs needs the full output spectral matrix"
        raise DataError(msg)
    return _solve_rows(s.gyx.conj().transpose(0, 2, 1), s.gyy)


def _hv(s: _Spectra) -> CArray:
    """Total least squares per output: the eigenvector of the smallest eigenvalue of [[Gxx, Gxy], [Gyx, Gyy]]."""
    n_f, n_out, n_in = s.gyx.shape
    c = np.empty((n_f, n_out, n_in + 1, n_in + 1), dtype=complex)
    c[:, :, :n_in, :n_in] = s.gxx[:, None]
    c[:, :, n_in, :n_in] = s.gyx
    c[:, :, :n_in, n_in] = s.gyx.conj()
    c[:, :, n_in, n_in] = s.gyy_diag
    _, vectors = np.linalg.eigh(c)
    v = vectors[..., :, 0]  # (n_f, n_out, n_in + 1), ascending eigenvalues
    return np.asarray(-v[..., :n_in].conj() / v[..., n_in:].conj(), dtype=complex)


def _coherence(s: _Spectra, h1: CArray) -> Array:
    """Ordinary (one input) or multiple coherence per output, (n_f, n_out), from H1 and the spectra."""
    explained = np.einsum("foi,foi->fo", h1, s.gyx.conj()).real
    gamma = np.divide(explained, s.gyy_diag, out=np.zeros_like(explained), where=s.gyy_diag > 0)
    return np.asarray(np.clip(np.nan_to_num(gamma, nan=0.0), 0.0, 1.0))


def _summary(
    coherence: Array,
    freq: Array,
    mask: NDArray[np.bool_],
    threshold: float,
    inputs: tuple[str, ...],
    outputs: tuple[str, ...],
    band: tuple[float, float],
) -> CoherenceSummary:
    """Summary over the lines in ``mask`` of ``coherence`` (n_out, n_in, n_f)."""
    n_out, n_in, _ = coherence.shape
    checked = coherence[:, :, mask]
    f = freq[mask]
    if f.size == 0:
        nan = np.full((n_out, n_in), np.nan)
        return CoherenceSummary(threshold, band, 0, inputs, outputs, np.zeros((n_out, n_in)), nan, nan)
    worst = checked.argmin(axis=-1)
    return CoherenceSummary(
        threshold=threshold,
        band=band,
        n_lines=int(f.size),
        input_names=inputs,
        output_names=outputs,
        fraction_below=np.asarray((checked < threshold).mean(axis=-1), dtype=float),
        minimum=np.take_along_axis(checked, worst[..., None], axis=-1)[..., 0],
        freq_of_minimum=f[worst],
    )


def _warn_coherence(
    summary: CoherenceSummary, fraction: float, coherence: Array, freq: Array, mask: NDArray[np.bool_]
) -> None:
    multi = len(summary.input_names) > 1
    for o, out in enumerate(summary.output_names):
        for i, inp in enumerate(summary.input_names):
            if multi and i > 0:
                break  # the multiple coherence is one value per output
            share = float(summary.fraction_below[o, i])
            if share <= fraction:
                continue
            low = freq[mask][coherence[o, i, mask] < summary.threshold]
            pair = (
                f"output {out!r} (multiple coherence with inputs {list(summary.input_names)})"
                if multi
                else f"output {out!r} / input {inp!r}"
            )
            warnings.warn(
                f"low coherence for {pair}: {100 * share:.0f} % of the {summary.n_lines} lines in "
                f"{summary.band[0]:g}-{summary.band[1]:g} Hz are below {summary.threshold:g} (low lines between "
                f"{low.min():g} and {low.max():g} Hz, lowest {summary.minimum[o, i]:.3g} at "
                f"{summary.freq_of_minimum[o, i]:g} Hz); check noise, leakage, nonlinearity or unmeasured inputs",
                DataWarning,
                stacklevel=3,
            )


def _check_conditioning(s: _Spectra, freq: Array, mask: NDArray[np.bool_], inputs: tuple[str, ...]) -> None:
    if len(inputs) < 2 or not mask.any():
        return
    cond = np.linalg.cond(s.gxx[mask])
    bad = ~(cond <= _COND_LIMIT)
    if bad.any():
        worst = int(np.nanargmax(np.where(np.isfinite(cond), cond, np.inf)))
        warnings.warn(
            f"input spectral matrix Gxx of inputs {list(inputs)} is ill-conditioned on {100 * bad.mean():.0f} % of "
            f"the lines (condition number up to {cond[worst]:.3g} at {freq[mask][worst]:g} Hz, limit "
            f"{_COND_LIMIT:g}): the inputs are correlated or there are too few averages ({s.n_avg}); the multi-input "
            f"FRF is unreliable there",
            IllConditionedWarning,
            stacklevel=3,
        )


def estimate_frf(
    data: TimeData,
    *,
    inputs: str | Sequence[str],
    outputs: str | Sequence[str],
    estimator: Literal["H1", "H2", "Hv"] = "H1",
    nperseg: int | None = None,
    noverlap: int | None = None,
    n_averages: int | None = None,
    window: str | tuple[Any, ...] | ArrayLike | None = None,
    detrend: Literal["constant", "linear", "auto"] | None = "auto",
    impact: bool = False,
    force_window: ForceWindow | None = None,
    exponential_window: float | Literal["auto"] | None = "auto",
    hit_threshold: float = 0.1,
    pretrigger: float | None = None,
    band: tuple[float, float] | None = None,
    coherence_threshold: float = 0.8,
    coherence_fraction: float = 0.1,
) -> FRFData:
    """Estimate FRFs ``H[out, in, freq]`` from measured inputs and outputs.

    **Averaging.** Welch's method: the record is cut into segments of ``nperseg`` samples overlapping by
    ``noverlap``; each is detrended, tapered by ``window`` and transformed, and the spectral matrices are averaged
    over the segments. In impact mode there is one record per hit instead (see below).

    **Estimators** (per frequency line, from the averaged matrices ``Gxx``, ``Gyx``, ``Gyy``):

    * ``"H1" = Gyx Gxx^-1`` (solved, not inverted): unbiased by output noise, biased low by input noise. Several
      inputs need partially uncorrelated signals; an ill-conditioned ``Gxx`` (condition number > 1e3 on any line
      checked) warns :class:`~cappe.exceptions.IllConditionedWarning`.
    * ``"H2" = Gyy Gxy^-1``: unbiased by input noise, biased high by output noise (most at anti-resonances).
      One input (each output separately) or as many outputs as inputs.
    * ``"Hv"``: total least squares per output - the eigenvector of the smallest eigenvalue of
      ``[[Gxx, Gxy], [Gyx, Gyy]]``; it weights input and output noise equally in the channels' units and lies
      between H1 and H2 (``|H1| <= |Hv| <= |H2|`` for one input).

    The coherence (ordinary for one input, multiple for several - then the same for every input of an output)
    is always computed from H1. Lines without input power (below 1e-20 of the peak) have ``H = nan`` and
    coherence 0.

    **Impact mode** (``impact=True``, or a ``force_window`` or numeric ``exponential_window`` given): hits on the
    single input are found by :func:`detect_hits` (level ``hit_threshold`` of the peak force); each record
    starts ``pretrigger`` s before a hit's trigger and holds ``nperseg`` samples (default: up to the next hit or
    the end), records are averaged as segments. The force record is multiplied by ``force_window`` (default
    :class:`ForceWindow()`); an exponential window ``exp(-t / tau)`` from the record start multiplies force and
    response alike, which moves every pole by ``-1 / tau`` exactly - ``FRFData.window_decay`` records tau and
    :func:`exponential_window_correction` removes the shift. ``exponential_window="auto"`` applies it only if the
    response has not decayed (RMS of the last 5 % of the record above 1 % of the peak), with ``tau`` such that
    the window falls to 1 % at the record end. No detrending and a rectangular window in this mode.

    Parameters
    ----------
    data : TimeData
        Measured signals, inputs and outputs as channels.
    inputs, outputs : str or sequence of str
        Channel names of the inputs (forces) and outputs (responses).
    estimator : {"H1", "H2", "Hv"}
        FRF estimator.
    nperseg : int, optional
        Samples per segment (record in impact mode); the line spacing is ``fs / nperseg`` Hz. Default from
        ``n_averages``.
    noverlap : int, optional
        Overlap of segments in samples (only with ``nperseg``); default ``nperseg // 2``.
    n_averages : int, optional
        Number of averages when ``nperseg`` is not given (50 % overlap); default 8.
    window : str, tuple or array, optional
        Taper for :func:`scipy.signal.get_window` or the window samples (length ``nperseg``); default ``"hann"``
        (``"boxcar"`` in impact mode, the only one allowed there).
    detrend : {"constant", "linear", None, "auto"}
        Per-segment detrending; ``"auto"``: ``"constant"`` for Welch averaging, none in impact mode.
    impact : bool
        Impact-test mode with default windows.
    force_window : ForceWindow, optional
        Force window (impact mode).
    exponential_window : float, "auto" or None
        Time constant tau of the exponential window in s (impact mode), ``"auto"`` or None for none.
    hit_threshold : float
        Hit trigger level as a fraction of the peak force, in (0, 1).
    pretrigger : float, optional
        Time kept before each hit's trigger in s; default 1 % of the record, at least 2 samples.
    band : (float, float), optional
        Frequency band in Hz: only lines with ``f_lo <= f <= f_hi`` are returned and checked.
    coherence_threshold : float
        Coherence below which a line counts as poor, in (0, 1).
    coherence_fraction : float
        A :class:`~cappe.exceptions.DataWarning` names every output/input pair with more than this fraction of
        poor lines in the checked band (``band``, else the lines within 40 dB of the peak input power).
        Narrow dips at anti-resonances stay below it.

    Returns
    -------
    FRFData
        ``freq`` (Hz), ``H`` (n_out, n_in, n_f), ``coherence`` and ``window_decay`` (tau or None); output
        quantities from the output units (``m``, ``m/s``, ``m/s^2``) when all are known.

    Raises
    ------
    DataError
        Unknown channels (the message lists the available ones), a channel both input and output, a band outside
        [0, Nyquist], bad segment settings, H2 for a non-square problem, impact mode with several inputs or no
        complete record.

    Warns
    -----
    DataWarning
        Low coherence over more than ``coherence_fraction`` of the band; double hits; dropped hits.
    IllConditionedWarning
        Correlated inputs (ill-conditioned ``Gxx``).

    Examples
    --------
    >>> import numpy as np
    >>> from cappe.systems import TimeData
    >>> rng = np.random.default_rng(0)
    >>> f = rng.standard_normal(4096)
    >>> y = np.convolve(f, [0.5, 0.25])[:4096]  # y[k] = 0.5 f[k] + 0.25 f[k-1]
    >>> frf = estimate_frf(TimeData.from_rate(1000.0, {"F": f, "y": y}), inputs="F", outputs="y", nperseg=256)
    >>> np.allclose(frf.H[0, 0, 0], 0.75, rtol=0.02), float(frf.coherence.min()) > 0.99
    (True, True)
    """
    data = _check_data(data)
    ins = _names(inputs, "inputs")
    outs = _names(outputs, "outputs")
    both = sorted(set(ins) & set(outs))
    if both:
        msg = f"channel(s) {both} are listed as both inputs and outputs"
        raise DataError(msg)
    in_rows = match_channels(data, ins, "input")
    out_rows = match_channels(data, outs, "output")
    check_clipping(data.select([*ins, *outs]))
    kinds = {"h1": "H1", "h2": "H2", "hv": "Hv"}
    if not isinstance(estimator, str) or estimator.lower() not in kinds:
        msg = f"argument 'estimator' must be 'H1', 'H2' or 'Hv'; got {estimator!r}"
        raise DataError(msg)
    kind = kinds[estimator.lower()]
    if kind == "H2" and len(ins) > 1 and len(outs) != len(ins):
        msg = (
            f"estimator 'H2' needs one input or as many outputs as inputs (Gxy must be square); got "
            f"{len(ins)} inputs {list(ins)} and {len(outs)} outputs {list(outs)}; use 'H1' or 'Hv'"
        )
        raise DataError(msg)
    if detrend not in ("constant", "linear", "auto", None):
        msg = f"argument 'detrend' must be 'constant', 'linear', 'auto' or None; got {detrend!r}"
        raise DataError(msg)
    if force_window is not None and not isinstance(force_window, ForceWindow):
        msg = f"argument 'force_window' must be a ForceWindow or None; got {type(force_window).__name__}"
        raise DataError(msg)
    if isinstance(exponential_window, str) and exponential_window != "auto":
        msg = f"argument 'exponential_window' must be a time constant in s, 'auto' or None; got {exponential_window!r}"
        raise DataError(msg)
    if exponential_window is not None and exponential_window != "auto":
        positive_number("exponential_window", exponential_window, "s")
    threshold = _fraction_arg("coherence_threshold", coherence_threshold)
    fraction = _fraction_arg("coherence_fraction", coherence_fraction, open_low=False, open_high=False)
    hit_level = _fraction_arg("hit_threshold", hit_threshold)
    fs = data.fs
    lo_hi = None if band is None else _band(band, fs)
    if nperseg is not None:
        nperseg = _integer("nperseg", nperseg, 2)
        if nperseg > data.n_samples:
            msg = f"argument 'nperseg' = {nperseg} exceeds the {data.n_samples} samples of the data"
            raise DataError(msg)
    if n_averages is not None:
        n_averages = _integer("n_averages", n_averages, 1)
    is_impact = (
        bool(impact) or force_window is not None or not (exponential_window is None or exponential_window == "auto")
    )

    if is_impact:
        if len(ins) != 1:
            msg = f"impact mode takes exactly one input (the hammer force); got {list(ins)}"
            raise DataError(msg)
        if n_averages is not None or noverlap is not None:
            msg = "arguments 'n_averages' and 'noverlap' do not apply in impact mode (one record per hit)"
            raise DataError(msg)
        if window is not None and not (isinstance(window, str) and window in ("boxcar", "rectangular")):
            msg = f"argument 'window' must be 'boxcar' (rectangular) in impact mode; got {window!r}"
            raise DataError(msg)
        if pretrigger is not None:
            pretrigger = real_number("pretrigger", pretrigger)
            if pretrigger < 0:
                msg = f"argument 'pretrigger' must be >= 0 s; got {pretrigger!r}"
                raise DataError(msg)
        x, y, length, tau = _impact_blocks(
            data,
            in_rows[0],
            out_rows,
            input_name=ins[0],
            nperseg=nperseg,
            detrend=None if detrend == "auto" else detrend,
            force_window=force_window or ForceWindow(),
            exponential_window=exponential_window,
            hit_threshold=hit_level,
            pretrigger=pretrigger,
        )
        spectra = _accumulate(iter([(x, y)]), full_gyy=kind == "H2" and len(ins) > 1)
    else:
        if nperseg is None:
            if noverlap is not None:
                msg = "argument 'noverlap' needs 'nperseg'"
                raise DataError(msg)
            k = 8 if n_averages is None else n_averages
            nperseg = max(2, (2 * data.n_samples) // (k + 1)) if k > 1 else data.n_samples
        elif n_averages is not None:
            msg = "give either 'nperseg' or 'n_averages', not both"
            raise DataError(msg)
        if noverlap is None:
            noverlap = nperseg // 2
        elif not isinstance(noverlap, (int, np.integer)) or isinstance(noverlap, bool) or not 0 <= noverlap < nperseg:
            msg = f"argument 'noverlap' must be an integer in [0, nperseg) = [0, {nperseg}); got {noverlap!r}"
            raise DataError(msg)
        win = _window_arg("hann" if window is None else window, nperseg)
        values = data.values[in_rows + out_rows]
        mode = "constant" if detrend == "auto" else detrend
        blocks = _welch_blocks(values, len(ins), nperseg, int(noverlap), win, mode)
        spectra = _accumulate(blocks, full_gyy=kind == "H2" and len(ins) > 1)
        length, tau = nperseg, None

    freq = np.asarray(np.fft.rfftfreq(length, 1.0 / fs), dtype=float)
    power = np.einsum("fii->f", spectra.gxx).real
    alive = power > _DEAD_POWER * power.max() if power.max() > 0 else np.zeros(freq.size, dtype=bool)
    eye = np.eye(len(ins))
    spectra.gxx[~alive] = eye  # placeholders; these lines are set to nan below
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        h1 = _h1(spectra)
        h = h1 if kind == "H1" else (_h2(spectra) if kind == "H2" else _hv(spectra))
        gamma = _coherence(spectra, h1)
    h[~alive] = np.nan
    gamma[~alive] = 0.0
    in_band = np.ones(freq.size, dtype=bool) if lo_hi is None else (freq >= lo_hi[0]) & (freq <= lo_hi[1])
    if not in_band.any():
        msg = f"band {lo_hi} Hz holds no frequency line (line spacing {fs / length:g} Hz); widen it or raise nperseg"
        raise DataError(msg)
    checked = in_band & alive
    if lo_hi is None:
        checked &= power >= _EXCITED_POWER * power.max()
    _check_conditioning(spectra, freq, checked, ins)
    H = np.ascontiguousarray(h.transpose(1, 2, 0)[:, :, in_band])
    coherence = np.ascontiguousarray(np.broadcast_to(gamma.T[:, None, in_band], H.shape))
    freq_out = freq[in_band]
    mask = checked[in_band]
    shown = (float(freq_out[mask].min()), float(freq_out[mask].max())) if mask.any() else (0.0, 0.0)
    summary = _summary(coherence, freq_out, mask, threshold, ins, outs, lo_hi or shown)
    _warn_coherence(summary, fraction, coherence, freq_out, mask)
    return FRFData(
        freq=freq_out,
        H=H,
        input_names=ins,
        output_names=outs,
        output_quantities=_quantities(data, outs),
        coherence=coherence,
        window_decay=tau,
    )


def coherence_summary(
    frf: FRFData, *, threshold: float = 0.8, band: tuple[float, float] | None = None
) -> CoherenceSummary:
    """Fraction of lines below a coherence threshold, lowest value and where, per output/input pair.

    Lines with a non-finite FRF are skipped. ``CoherenceSummary.low(fraction)`` lists the pairs to look at.

    Parameters
    ----------
    frf : FRFData
        Measured FRFs with their coherence.
    threshold : float
        Coherence below which a line counts as low (0..1).
    band : (float, float), optional
        Lines checked, in Hz (default all).

    Returns
    -------
    CoherenceSummary

    Raises
    ------
    DataError
        If the FRFs carry no coherence (model FRFs) or the band holds no line.

    Examples
    --------
    >>> import numpy as np
    >>> from cappe.systems.frf import FRFData
    >>> frf = FRFData(np.arange(5.0), np.ones((1, 1, 5), complex), ("F",), ("a",),
    ...               coherence=np.array([[[1.0, 0.9, 0.5, 0.95, 1.0]]]))
    >>> s = coherence_summary(frf, threshold=0.8)
    >>> float(s.fraction_below[0, 0]), float(s.freq_of_minimum[0, 0])
    (0.2, 2.0)
    """
    if not isinstance(frf, FRFData) or frf.coherence is None:
        msg = "coherence_summary needs measured FRFs (FRFData with coherence); got none"
        raise DataError(msg)
    thr = _fraction_arg("threshold", threshold)
    freq = np.asarray(frf.freq, dtype=float)
    if band is None:
        lo_hi = (float(freq.min()), float(freq.max()))
    else:
        try:
            lo, hi = (float(v) for v in band)
        except (TypeError, ValueError):
            msg = f"argument 'band' must be a pair (f_lo, f_hi) in Hz; got {band!r}"
            raise DataError(msg) from None
        lo_hi = (lo, hi)
    mask = (freq >= lo_hi[0]) & (freq <= lo_hi[1]) & np.all(np.isfinite(frf.H), axis=(0, 1))
    if not mask.any():
        msg = f"band {lo_hi} Hz holds no frequency line with a finite FRF (data span {freq.min():g}-{freq.max():g} Hz)"
        raise DataError(msg)
    coh = np.asarray(frf.coherence, dtype=float)
    return _summary(coh, freq, mask, thr, frf.input_names, frf.output_names, lo_hi)


# -- stepped sine ------------------------------------------------------------------------------------------------
def stepped_sine_frf(
    data: TimeData, *, schedule: SteppedSineSchedule, inputs: str | Sequence[str], outputs: str | Sequence[str]
) -> FRFData:
    """One FRF line per step of a stepped-sine test.

    In each step's measurement window (after the settling time) every channel is fitted by least squares with
    ``a cos(w t) + b sin(w t) + c`` at the step's known frequency (exact for any window length, whole periods
    or not); the FRF is the ratio of the output and input phasors ``a - j b``. The coherence slot holds the
    fit quality: the product of the fractions of input and output power (mean removed) explained by the fitted
    sine, 1 for a linear system in steady state without noise; harmonics (nonlinearity), noise or transients
    left over from a too short settling time lower it.

    Parameters
    ----------
    data : TimeData
        The test record, starting at the first step, sampled at ``schedule.fs``.
    schedule : SteppedSineSchedule
        From :func:`~cappe.identify._signals.stepped_sine_schedule` with the arguments the signal was built with.
    inputs : str or sequence of one str
        The force channel.
    outputs : str or sequence of str
        Response channels.

    Raises
    ------
    DataError
        For unknown channels, several inputs, another sampling rate or a record shorter than the schedule.

    Examples
    --------
    >>> import numpy as np
    >>> from cappe.identify._signals import stepped_sine, stepped_sine_schedule
    >>> plan = stepped_sine_schedule(freqs=[5.0, 50.0], fs=1000.0, dwell=0.4, settle=0.1)
    >>> force = stepped_sine(freqs=[5.0, 50.0], amplitude=2.0, fs=1000.0, dwell=0.4, settle=0.1)
    >>> data = TimeData.from_rate(1000.0, {"F": force.values[0], "y": 3.0 * force.values[0]})
    >>> frf = stepped_sine_frf(data, schedule=plan, inputs="F", outputs="y")
    >>> np.round(frf.H[0, 0].real, 9).tolist()
    [3.0, 3.0]
    """
    data = _check_data(data)
    if not isinstance(schedule, SteppedSineSchedule):
        msg = f"argument 'schedule' must be a SteppedSineSchedule; got {type(schedule).__name__}"
        raise DataError(msg)
    ins = _names(inputs, "inputs")
    outs = _names(outputs, "outputs")
    if len(ins) != 1:
        msg = f"a stepped-sine FRF takes exactly one input channel; got {list(ins)}"
        raise DataError(msg)
    rows = match_channels(data, ins, "input") + match_channels(data, outs, "output")
    if abs(data.fs - schedule.fs) > 1e-9 * schedule.fs:
        msg = f"the data is sampled at {data.fs:g} Hz but the schedule at {schedule.fs:g} Hz"
        raise DataError(msg)
    if data.n_samples < schedule.n_samples:
        msg = (
            f"the data holds {data.n_samples} samples but the schedule needs {schedule.n_samples} "
            f"({schedule.n_steps} steps of {schedule.n_dwell})"
        )
        raise DataError(msg)
    n_ch = len(rows)
    values = data.values[rows, : schedule.n_samples].reshape(n_ch, schedule.n_steps, schedule.n_dwell)
    values = values[:, :, schedule.n_settle :]  # (n_ch, n_steps, n_window)
    t = (schedule.n_settle + np.arange(values.shape[-1])) / schedule.fs
    phase = 2 * np.pi * schedule.freq[:, None] * t[None, :]
    basis = np.stack([np.cos(phase), np.sin(phase), np.ones_like(phase)], axis=-1)  # (n_steps, n_window, 3)
    gram = basis.transpose(0, 2, 1) @ basis
    rhs = np.einsum("swk,csw->skc", basis, values)
    coef = np.linalg.solve(gram, rhs)  # (n_steps, 3, n_ch)
    phasor = coef[:, 0, :] - 1j * coef[:, 1, :]  # (n_steps, n_ch)
    residual = values - np.einsum("swk,skc->csw", basis, coef)
    centred = values - values.mean(axis=-1, keepdims=True)
    total = (centred**2).sum(axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        explained = np.clip(1.0 - (residual**2).sum(axis=-1) / total, 0.0, 1.0)
        h = phasor[:, 1:] / phasor[:, :1]
    explained = np.nan_to_num(explained, nan=0.0)
    coherence = explained[0][None, :] * explained[1:]  # (n_out, n_steps)
    return FRFData(
        freq=schedule.freq.copy(),
        H=np.ascontiguousarray(h.T[:, None, :]),
        input_names=ins,
        output_names=outs,
        output_quantities=_quantities(data, outs),
        coherence=np.ascontiguousarray(coherence[:, None, :]),
    )


# -- exponential window correction -------------------------------------------------------------------------------
def exponential_window_correction(
    *,
    tau: float,
    poles: ArrayLike | None = None,
    freq: ArrayLike | None = None,
    zeta: ArrayLike | None = None,
) -> WindowCorrectedModes:
    """Remove the damping that an exponential window ``exp(-t / tau)`` added to identified modes.

    The window multiplies the impulse response ``sum r_k exp(p_k t)`` by ``exp(-t / tau)``, so every pole
    identified from windowed data is ``p_measured = p_true - 1 / tau``: its decay rate ``sigma = -Re p`` is
    ``1 / tau`` too large. The correction is ``p_true = p_measured + 1 / tau``, i.e.
    ``sigma_true = sigma_measured - 1 / tau`` with the damped frequency unchanged; then
    ``freq = |p| / 2 pi`` and ``zeta = sigma / |p|``.

    Parameters
    ----------
    tau : float
        Window time constant in s (``FRFData.window_decay``).
    poles : array_like of complex, shape (n_modes,), optional
        Identified poles in rad/s.
    freq, zeta : array_like, shape (n_modes,), optional
        Identified natural frequencies (Hz) and damping ratios in [0, 1), instead of ``poles``.

    Warns
    -----
    DataWarning
        If a corrected damping ratio is negative (the window decayed faster than the identified mode, i.e. tau is
        not the one used or the identification is poor).

    Examples
    --------
    >>> out = exponential_window_correction(tau=0.1, freq=[100.0], zeta=[0.02])
    >>> round(float(out.zeta[0]), 5)
    0.00409
    """
    t = positive_number("tau", tau, "s")
    if poles is not None:
        if freq is not None or zeta is not None:
            msg = "give either 'poles' or 'freq' and 'zeta', not both"
            raise DataError(msg)
        p = np.atleast_1d(np.asarray(poles, dtype=complex))
        if p.ndim != 1 or not np.all(np.isfinite(p)):
            msg = f"argument 'poles' must be a 1-D array of finite complex values in rad/s; got {poles!r}"
            raise DataError(msg)
    else:
        if freq is None or zeta is None:
            msg = "exponential_window_correction needs 'poles' or both 'freq' and 'zeta'"
            raise DataError(msg)
        f = np.atleast_1d(np.asarray(freq, dtype=float))
        z = np.atleast_1d(np.asarray(zeta, dtype=float))
        if f.shape != z.shape or f.ndim != 1:
            msg = f"arguments 'freq' and 'zeta' must be 1-D of the same length; got shapes {f.shape} and {z.shape}"
            raise DataError(msg)
        if not (np.all(np.isfinite(f)) and np.all(f > 0)):
            msg = f"argument 'freq' must hold finite natural frequencies > 0 Hz; got {f.tolist()}"
            raise DataError(msg)
        if not (np.all(np.isfinite(z)) and np.all((z >= 0) & (z < 1))):
            msg = f"argument 'zeta' must hold damping ratios in [0, 1); got {z.tolist()}"
            raise DataError(msg)
        omega = 2 * np.pi * f
        p = omega * (-z + 1j * np.sqrt(1 - z**2))
    corrected = p + 1.0 / t
    magnitude = np.abs(corrected)
    zeta_true = np.divide(-corrected.real, magnitude, out=np.zeros_like(magnitude), where=magnitude > 0)
    if np.any(zeta_true < 0):
        bad = np.flatnonzero(zeta_true < 0).tolist()
        warnings.warn(
            f"corrected damping is negative for mode(s) {bad} (zeta {zeta_true[bad].round(6).tolist()}): the window "
            f"decay 1/tau = {1 / t:g} 1/s exceeds the identified decay rate; check tau",
            DataWarning,
            stacklevel=2,
        )
    return WindowCorrectedModes(np.asarray(corrected, dtype=complex), magnitude / (2 * np.pi), zeta_true, t)
