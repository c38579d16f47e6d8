"""Prognosis: when a degrading component will reach a grade, from the trend of its change.

A component that degrades steadily (a screw loosening, a bearing wearing) changes about linearly in time. The
relative changes ``y_k`` recorded since the fault began, at times ``t_k``, are fitted by least squares with a line
``y = a + b t``; the forecast is the time the line reaches the grade's threshold ``c``, ``t* = (c - a) / b``.

Its interval is Fieller's: the times ``t`` at which the line's value is not significantly different from ``c``,

    (a + b t - c)^2 <= q^2 s^2 (1 / n + (t - t_mean)^2 / S_tt),

with ``s^2`` the residual variance (``n - 2`` degrees of freedom) and ``q`` Student's quantile. For independent
Gaussian scatter about a straight line it covers the true crossing time at exactly the stated rate, also where the
delta method (a symmetric interval from the slope's standard error) does not: the crossing time is a ratio and its
distribution is skewed. Where the slope is not significant at that level the set is unbounded: the data cannot
tell when, and the forecast says so instead of giving a number.

The monitor's change sizes also carry a systematic error proportional to the change (the fit's nonlinearity and
the model's error: up to about 1 % of the change on the exact spindle model, 1 to 10 % with its damping 30 % off,
depending on the component), which the scatter about the line cannot show and which shifts the whole line; the
monitor passes the baseline's estimate of it for the component (:meth:`cappe.monitor.Baseline.component_scale_std`,
read back on the machine's twin).
A true change ``(1 + e)`` times the estimated one crosses ``c`` when the estimate crosses ``c / (1 + e)``, a time
shift of about ``-e c / b``; with ``scale_std`` the standard deviation of ``e``, each side of Fieller's interval is
widened in quadrature by ``z scale_std |c / b|`` (``z`` the normal quantile of the level): the scatter and the scale
error are independent.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy import stats

from cappe.exceptions import DataError

__all__ = ["CrossingForecast", "forecast_crossing"]


@dataclass(frozen=True)
class CrossingForecast:
    """When a linear trend reaches a threshold, with its interval.

    Attributes
    ----------
    threshold : float
        The relative change the trend is extrapolated to (e.g. -0.25 for the intolerable grade of a loss).
    time : float or None
        Forecast crossing time in the unit of the given times (None: the trend does not head there).
    lower, upper : float
        The interval's ends (``-inf``/``inf`` where unbounded).
    level : float
        Its coverage probability.
    slope, slope_std : float
        Trend per time unit and its standard error.
    n : int
        Points fitted.
    determined : bool
        Whether the interval is bounded (the trend is significant at ``level``).
    reason : str
        Why the time cannot be told, where that is not the trend's significance (empty otherwise).
    """

    threshold: float
    time: float | None
    lower: float
    upper: float
    level: float
    slope: float
    slope_std: float
    n: int
    determined: bool
    reason: str = ""

    def covers(self, value: float) -> bool:
        """Whether ``value`` lies in the interval.

        Parameters
        ----------
        value : float
            A time in the unit of the forecast.

        Returns
        -------
        bool
        """
        return bool(self.lower <= value <= self.upper)

    def to_dict(self) -> dict[str, Any]:
        def finite(v: float | None) -> float | None:
            return None if v is None or not np.isfinite(v) else float(v)

        return {"threshold": self.threshold, "time": finite(self.time), "lower": finite(self.lower),
                "upper": finite(self.upper), "level": self.level, "slope": self.slope, "slope_std": self.slope_std,
                "n": self.n, "determined": self.determined, "reason": self.reason}

    def text(self, unit: str = "h", now: float = 0.0) -> str:
        """The forecast in words, times counted from ``now``.

        Parameters
        ----------
        unit : str
            Unit of the times.
        now : float
            The time the forecast is told at (its times are shown relative to it).

        Returns
        -------
        str
        """
        grade = f"{100 * self.threshold:+.0f} %"
        if self.reason:
            return f"reaches {grade}: cannot be told ({self.reason})"
        if not self.determined or self.time is None:
            return (f"reaches {grade}: cannot be told from {self.n} measurements (the trend "
                    f"{100 * self.slope:+.2g} %/{unit} +- {100 * self.slope_std:.2g} is not significant at "
                    f"{100 * self.level:.0f} %)")
        return (f"reaches {grade} in about {self.time - now:.3g} {unit} ({100 * self.level:.0f} % interval "
                f"{self.lower - now:.3g} to {self.upper - now:.3g} {unit}; trend {100 * self.slope:+.2g} %/{unit} "
                f"from {self.n} measurements)")


def forecast_crossing(
    times: ArrayLike,
    change: ArrayLike,
    threshold: float,
    *,
    level: float = 0.95,
    scale_std: float = 0.0,
) -> CrossingForecast:
    """Fieller forecast of when the linear trend of ``change`` reaches ``threshold`` (see the module notes).

    Parameters
    ----------
    times : array_like, shape (n,)
        Times of the measurements (any unit, e.g. hours).
    change : array_like, shape (n,)
        Relative change of the component at each (e.g. -0.08 for 8 % lost).
    threshold : float
        The relative change to reach.
    level : float
        Coverage probability of the interval.
    scale_std : float
        Relative standard uncertainty of the changes' scale (a systematic error common to all of them).

    Returns
    -------
    CrossingForecast

    Raises
    ------
    DataError
        Fewer than 3 points, lengths differ, values not finite, all times equal, or ``level`` outside (0, 1).

    Examples
    --------
    >>> t = np.arange(10.0)
    >>> f = forecast_crossing(t, -0.02 * t + 0.001 * np.cos(7 * t), -0.25)
    >>> round(f.time, 1), bool(f.lower < f.time < f.upper)
    (12.5, True)
    """
    t = np.asarray(times, dtype=float)
    y = np.asarray(change, dtype=float)
    if t.shape != y.shape or t.ndim != 1 or t.size < 3 or not (np.all(np.isfinite(t)) and np.all(np.isfinite(y))):
        msg = f"a forecast needs at least 3 finite (time, change) pairs of equal length; got {t.size} and {y.size}"
        raise DataError(msg)
    if not 0 < level < 1:
        msg = f"forecast level must be in (0, 1); got {level!r}"
        raise DataError(msg)
    if not 0 <= scale_std < 0.2:
        msg = f"forecast scale_std must be in [0, 0.2); got {scale_std!r}"
        raise DataError(msg)
    if scale_std > 0:
        z = float(stats.norm.ppf(0.5 + level / 2))
        nominal = forecast_crossing(t, y, threshold, level=level)
        if not nominal.determined or nominal.time is None:
            return replace(nominal, lower=-np.inf, upper=np.inf, determined=False)
        # a scale error e moves the crossing by -e c / b: its z-quantile added in quadrature to each side of the
        # scatter's interval (the two errors are independent; adding the quantiles over-covered: 80/80 at 95 %)
        shift = abs(z * scale_std * threshold / nominal.slope)
        return replace(nominal, lower=nominal.time - float(np.hypot(nominal.time - nominal.lower, shift)),
                       upper=nominal.time + float(np.hypot(nominal.upper - nominal.time, shift)))
    n = t.size
    t_mean = float(t.mean())
    s_tt = float(np.sum((t - t_mean) ** 2))
    if s_tt <= 0:
        msg = "a forecast needs measurements at different times"
        raise DataError(msg)
    b = float(np.sum((t - t_mean) * (y - y.mean())) / s_tt)
    a_mean = float(y.mean())  # the line's value at t_mean
    resid = y - (a_mean + b * (t - t_mean))
    s2 = float(resid @ resid) / (n - 2)
    q = float(stats.t.ppf(0.5 + level / 2, n - 2))
    slope_std = float(np.sqrt(s2 / s_tt))
    # (a_mean - c + b u)^2 <= q^2 s^2 (1/n + u^2 / S_tt), u = t - t_mean: A u^2 + B u + C <= 0
    d = a_mean - threshold
    big_a = b * b - q * q * s2 / s_tt
    big_b = 2 * d * b
    big_c = d * d - q * q * s2 / n
    time = t_mean - d / b if b != 0 else None
    disc = big_b * big_b - 4 * big_a * big_c
    if big_a > 0 and disc >= 0:
        root = np.sqrt(disc)
        lo, hi = sorted(((-big_b - root) / (2 * big_a), (-big_b + root) / (2 * big_a)))
        return CrossingForecast(float(threshold), time, t_mean + lo, t_mean + hi, float(level), b, slope_std, n,
                                time is not None)
    return CrossingForecast(float(threshold), time, -np.inf, np.inf, float(level), b, slope_std, n, False)
