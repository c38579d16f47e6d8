"""Measured (or simulated) time signals: uniformly sampled, named channels.

``TimeData`` is what every identification routine takes as input: the FRF estimators, the black-box fits and
the rigid-body reconstruction. Channels are matched to model inputs and outputs by name.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cappe._arguments import positive_number
from cappe.exceptions import DataError, DataWarning

__all__ = ["TimeData", "check_clipping"]

# A sampling grid is uniform when every time stamp lies on the grid t0 + k dt within its own decimal rounding (a
# recorder writing 7 significant digits rounds t = 9.999512 s to 1e-6 s, 2 % of a 51.2 kHz step) plus this
# fraction of the step, which covers the rounding of binary floats.
_UNIFORM_RTOL = 1e-6
# Steps further than this fraction from the typical step are missing or irregular samples (an error); smaller
# departures from the grid beyond the rounding are timing jitter (a warning).
_JITTER_LIMIT = 0.1


@dataclass(frozen=True)
class TimeData:
    """Uniformly sampled, multi-channel time data.

    Attributes
    ----------
    time : ndarray, shape (n_samples,)
        Sample times in s, strictly increasing with a constant step.
    values : ndarray, shape (n_channels, n_samples)
        One row per channel, in SI units.
    channels : tuple of str
        Channel names (unique), e.g. ``("F1", "d1", "d2")``.
    units : tuple of str
        One unit per channel (``"N"``, ``"m/s^2"`` ...) or empty when unknown.

    Examples
    --------
    >>> import numpy as np
    >>> data = TimeData.from_channels(np.arange(4) * 0.01, {"F": [0.0, 1.0, 0.0, 0.0], "a": [0.0, 0.1, 0.2, 0.1]})
    >>> data.fs, data.channels, data.n_samples
    (100.0, ('F', 'a'), 4)
    """

    time: NDArray[np.float64]
    values: NDArray[np.float64]
    channels: tuple[str, ...]
    units: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        time = np.asarray(self.time, dtype=float)
        values = np.atleast_2d(np.asarray(self.values, dtype=float))
        channels = tuple(str(c) for c in self.channels)
        units = tuple(str(u) for u in self.units)
        if time.ndim != 1 or time.size < 2:
            msg = f"time must be a 1-D array of at least 2 samples; got shape {time.shape}"
            raise DataError(msg)
        if values.shape != (len(channels), time.size):
            msg = (
                f"values must have shape (n_channels, n_samples) = ({len(channels)}, {time.size}); "
                f"got {values.shape}"
            )
            raise DataError(msg)
        unnamed = [i for i, c in enumerate(channels) if not c]
        if unnamed:
            msg = f"channel names must not be empty; channel {unnamed[0]} has none"
            raise DataError(msg)
        duplicates = sorted({c for c in channels if channels.count(c) > 1})
        if duplicates:
            msg = f"channel names must be unique; repeated: {duplicates}"
            raise DataError(msg)
        if units and len(units) != len(channels):
            msg = f"units must list one unit per channel ({len(channels)}); got {len(units)}"
            raise DataError(msg)
        _check_time(time)
        for name, row in zip(channels, values, strict=True):
            bad = np.flatnonzero(~np.isfinite(row))
            if bad.size:
                msg = (
                    f"channel {name!r} has {bad.size} non-finite value(s) (NaN or Inf), first at sample {bad[0]} "
                    f"(t = {time[bad[0]]:.6g} s)"
                )
                raise DataError(msg)
        object.__setattr__(self, "time", time)
        object.__setattr__(self, "values", values)
        object.__setattr__(self, "channels", channels)
        object.__setattr__(self, "units", units)

    @classmethod
    def from_channels(
        cls,
        time: ArrayLike,
        channels: Mapping[str, ArrayLike],
        units: Mapping[str, str] | None = None,
    ) -> TimeData:
        """Build from a time vector and a mapping ``name -> samples``; lengths are checked per channel.

        Parameters
        ----------
        time : array_like, shape (n_samples,)
            Uniform, increasing sample times in s.
        channels : mapping name -> array_like, shape (n_samples,)
            The samples of each channel (SI units).
        units : mapping name -> str, optional
            Unit of some or all channels (``"N"``, ``"m/s^2"`` ...).

        Returns
        -------
        TimeData

        Raises
        ------
        DataError
            A channel's length differs from ``time``'s, or a rule of TimeData is broken.
        """
        t = np.asarray(time, dtype=float)
        rows = []
        for name, samples in channels.items():
            row = np.asarray(samples, dtype=float)
            if row.ndim != 1 or row.size != t.size:
                msg = f"channel {name!r} has {row.size} samples but the time vector has {t.size}"
                raise DataError(msg)
            rows.append(row)
        names = tuple(channels)
        unit_list = tuple((units or {}).get(n, "") for n in names) if units else ()
        return cls(time=t, values=np.array(rows).reshape(len(names), t.size), channels=names, units=unit_list)

    @classmethod
    def from_rate(cls, fs: float, channels: Mapping[str, ArrayLike], t0: float = 0.0) -> TimeData:
        """Build from a sampling rate ``fs`` (Hz) and a mapping ``name -> samples``.

        Parameters
        ----------
        fs : float
            Sampling rate in Hz, > 0.
        channels : mapping name -> array_like, shape (n_samples,)
            The samples of each channel (all of the same length).
        t0 : float
            Time of the first sample in s.

        Returns
        -------
        TimeData

        Raises
        ------
        DataError
            ``fs`` is not positive or the channels differ in length.
        """
        rate = positive_number("fs", fs, "Hz")
        lengths = {name: np.asarray(v).size for name, v in channels.items()}
        n = max(lengths.values(), default=0)
        short = {name: size for name, size in lengths.items() if size != n}
        if short:
            msg = f"channels must all have the same length ({n} samples); different: {short}"
            raise DataError(msg)
        return cls.from_channels(t0 + np.arange(n) / rate, channels)

    @property
    def n_samples(self) -> int:
        return int(self.time.size)

    @property
    def n_channels(self) -> int:
        return len(self.channels)

    @property
    def dt(self) -> float:
        """Sampling interval in s."""
        return float((self.time[-1] - self.time[0]) / (self.time.size - 1))

    @property
    def fs(self) -> float:
        """Sampling rate in Hz."""
        return float(np.round(1.0 / self.dt, 9))

    @property
    def duration(self) -> float:
        return float(self.time[-1] - self.time[0] + self.dt)

    def index(self, channel: str) -> int:
        """Row of a channel; unknown names raise a DataError listing the available ones.

        Parameters
        ----------
        channel : str
            Channel name.

        Returns
        -------
        int
            Index into ``channels`` and the rows of ``values``.
        """
        try:
            return self.channels.index(channel)
        except ValueError:
            msg = f"unknown channel {channel!r}; the data has {list(self.channels)}"
            raise DataError(msg) from None

    def channel(self, name: str) -> NDArray[np.float64]:
        """Samples of one channel, shape (n_samples,).

        Parameters
        ----------
        name : str
            Channel name.

        Returns
        -------
        ndarray, shape (n_samples,)

        Raises
        ------
        DataError
            No channel has that name.
        """
        return np.asarray(self.values[self.index(name)])

    def select(self, names: Sequence[str]) -> TimeData:
        """A new TimeData holding only the given channels, in the given order.

        Parameters
        ----------
        names : sequence of str
            Channel names.

        Returns
        -------
        TimeData

        Raises
        ------
        DataError
            A name is not a channel.
        """
        rows = [self.index(n) for n in names]
        units = tuple(self.units[r] for r in rows) if self.units else ()
        return TimeData(self.time, self.values[rows], tuple(names), units)

    def unit(self, name: str) -> str:
        """The unit of one channel (empty when unknown).

        Parameters
        ----------
        name : str
            Channel name.

        Returns
        -------
        str

        Raises
        ------
        DataError
            No channel has that name.
        """
        return self.units[self.index(name)] if self.units else ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "time": self.time.tolist(),
            "channels": {c: row.tolist() for c, row in zip(self.channels, self.values, strict=True)},
            "units": dict(zip(self.channels, self.units, strict=True)) if self.units else {},
        }


def _check_time(time: NDArray[np.float64]) -> None:
    step = np.diff(time)
    if not np.all(np.isfinite(time)):
        first = int(np.flatnonzero(~np.isfinite(time))[0])
        msg = f"time stamps must be finite; sample {first} is {time[first]!r}"
        raise DataError(msg)
    if np.any(step <= 0):
        first = int(np.flatnonzero(step <= 0)[0])
        msg = (
            f"time stamps must increase strictly; sample {first + 1} (t = {time[first + 1]:.9g} s) does not follow "
            f"sample {first} (t = {time[first]:.9g} s)"
        )
        raise DataError(msg)
    typical = float(np.median(step))
    off = np.abs(step - typical) > _JITTER_LIMIT * typical
    if np.any(off):
        first = int(np.flatnonzero(off)[0])
        msg = (
            f"time stamps must be uniformly spaced (missing or irregular samples); the step after sample {first} "
            f"is {step[first]:.9g} s, the typical (median) step is {typical:.9g} s"
        )
        raise DataError(msg)
    if np.all(np.abs(step - typical) <= _UNIFORM_RTOL * typical):
        return  # uniform to the rounding of binary floats: computed time vectors stop here
    k = np.arange(time.size, dtype=float)
    dt = float((time[-1] - time[0]) / (time.size - 1))
    # the grid through the stamps (least squares): the end points alone would carry their own rounding into it
    k_mean, t_mean = float(k.mean()), float(time.mean())
    dt = float(np.dot(k - k_mean, time - t_mean) / np.dot(k - k_mean, k - k_mean)) if time.size > 2 else dt
    off_grid = np.abs(time - (t_mean + (k - k_mean) * dt))
    # half a unit of its last digit is a stamp's rounding; the grid fitted through all the rounded stamps errs by up
    # to half a unit of the coarsest of them
    quantum = _decimal_quantum(time)
    allowed = 0.5 * (quantum + quantum.max()) + _UNIFORM_RTOL * dt
    worst = int(np.argmax(off_grid - allowed))
    if off_grid[worst] > allowed[worst]:
        warnings.warn(
            f"time stamps jitter: sample {worst} (t = {time[worst]:.10g} s) lies {off_grid[worst]:.3g} s "
            f"({100 * off_grid[worst] / dt:.2g} % of the {dt:.6g} s step) from the uniform grid, more than the "
            f"rounding of its {_significant_digits(time)} significant digits; the data are used as uniformly sampled "
            f"at {1 / dt:.6g} Hz",
            DataWarning,
            stacklevel=4,
        )


def _significant_digits(time: NDArray[np.float64]) -> int:
    """The fewest significant decimal digits that write every time stamp exactly (17 for computed floats)."""
    nonzero = time[time != 0]
    if nonzero.size == 0:
        return 17
    magnitude = np.abs(nonzero)
    exponent = np.floor(np.log10(magnitude))
    slack = 4 * np.spacing(magnitude)

    def exact(digits: int) -> bool:
        unit = 10.0 ** (exponent - digits + 1)
        return bool(np.all(np.abs(np.round(nonzero / unit) * unit - nonzero) <= slack))

    lo, hi = 1, 17  # exact at hi (by convention); exact at d implies exact at d + 1: bisect
    while lo < hi:
        mid = (lo + hi) // 2
        if exact(mid):
            hi = mid
        else:
            lo = mid + 1
    return hi


def _decimal_quantum(time: NDArray[np.float64]) -> NDArray[np.float64]:
    """The last written decimal unit of each time stamp (s): ``10**(e - d + 1)`` for a stamp ``m * 10**e`` written
    with the file's ``d`` significant digits; the float spacing for computed time vectors."""
    digits = _significant_digits(time)
    magnitude = np.abs(time)
    exponent = np.floor(np.log10(np.where(magnitude > 0, magnitude, 1.0)))
    if digits >= 17:
        return np.asarray(4 * np.spacing(magnitude), dtype=float)
    return np.asarray(10.0 ** (exponent - digits + 1), dtype=float)


def check_clipping(data: TimeData, *, min_run: int = 3, rtol: float = 1e-9) -> dict[str, float]:
    """Warn about channels that look clipped (saturated) and return them with their clipped fraction.

    A channel is flagged when it stays at its maximum or minimum value for ``min_run`` or more consecutive samples
    (a saturated amplifier or ADC holds the rail) while at least 10 % of its samples lie strictly between the two
    extremes; a smooth signal touches its extremes at isolated samples only. Signals that live on their extremes by
    design - two-level PRBS or square waves, an impact force resting at zero between hits - are not flagged.

    Parameters
    ----------
    data : TimeData
        The channels to check.
    min_run : int
        Consecutive samples at an extreme that count as clipping.
    rtol : float
        Relative tolerance (of the channel's range) for a sample to be at an extreme.

    Returns
    -------
    dict
        ``{channel: fraction of samples at an extreme}`` of the flagged channels; one
        :class:`~cappe.exceptions.DataWarning` names them.

    Examples
    --------
    >>> import numpy as np, warnings
    >>> t = np.arange(200) / 100.0
    >>> data = TimeData.from_channels(t, {"ok": np.sin(7 * t), "cut": np.clip(np.sin(7 * t), -0.5, 0.5)})
    >>> with warnings.catch_warnings(record=True):
    ...     warnings.simplefilter("always")
    ...     sorted(check_clipping(data))
    ['cut']
    """
    clipped: dict[str, float] = {}
    for name, row in zip(data.channels, data.values, strict=True):
        span = float(np.ptp(row))
        if span == 0.0:
            continue
        at_rails = [np.abs(row - rail) <= rtol * span for rail in (row.max(), row.min())]
        if np.mean(~(at_rails[0] | at_rails[1])) < 0.1:
            continue  # a two-level or baseline-dominated signal (PRBS, square, resting hammer), not a saturated one
        flagged = np.zeros(row.size, dtype=bool)
        for at in at_rails:
            flagged |= at & _runs_at_least(at, min_run)
        if flagged.any():
            clipped[name] = float(flagged.mean())
    if clipped:
        detail = ", ".join(f"{name!r} ({100 * frac:.1f} % of samples)" for name, frac in clipped.items())
        warnings.warn(f"channel(s) look clipped (saturated at a rail): {detail}", DataWarning, stacklevel=2)
    return clipped


def _runs_at_least(mask: NDArray[np.bool_], length: int) -> NDArray[np.bool_]:
    """Elements of ``mask`` that belong to a run of True of at least ``length`` samples."""
    padded = np.concatenate(([False], mask, [False])).astype(np.int8)
    edges = np.diff(padded)
    starts = np.flatnonzero(edges == 1)
    stops = np.flatnonzero(edges == -1)
    out = np.zeros(mask.size, dtype=bool)
    for start, stop in zip(starts, stops, strict=True):
        if stop - start >= length:
            out[start:stop] = True
    return out
