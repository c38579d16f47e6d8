"""Sequential change detection on standardized parameters: CUSUM and EWMA charts with a chosen false-alarm rate.

Each monitored quantity ``z`` (a component's log stiffness factor minus its healthy expectation, divided by its
healthy standard deviation) feeds a two-sided chart:

- **CUSUM** (Page): ``S+ = max(0, S+ + z - k)``, ``S- = max(0, S- - z - k)``, alarm when either exceeds ``h``.
  ``k = shift / 2`` makes it the fastest chart for a step of ``shift`` standard deviations.
- **EWMA** (Roberts): ``Z = lam z + (1 - lam) Z``, alarm when ``|Z| > L sqrt(lam / (2 - lam))``.

The limits ``h`` and ``L`` follow from the in-control average run length (ARL) the false-alarm rate asks for,
computed by the Markov-chain method of Brook & Evans (1972) for both charts (:func:`cusum_arl`, :func:`ewma_arl`):
with ``n`` components and a rate ``alpha`` of false alarms per healthy measurement, every one-sided CUSUM gets
``ARL0 = 2 n / alpha`` and every two-sided EWMA ``n / alpha`` (a union bound: a run length is close to
geometric, so a chart alarms with probability about 1 / ARL0 per in-control measurement).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import brentq
from scipy.stats import norm

from cappe.exceptions import DataError

__all__ = ["ChartSignal", "SequentialDetector", "cusum_arl", "cusum_limit", "ewma_arl", "ewma_limit"]

Array = NDArray[np.float64]

_STATES = 301  # Markov-chain states: ARLs to about 0.1 % (checked against the published tables in the tests)


def _absorbing_arl(transition: Array, start: int) -> float:
    """Average steps to absorption of a chain with transient-state transition matrix ``transition``."""
    n = transition.shape[0]
    steps = np.linalg.solve(np.eye(n) - transition, np.ones(n))
    return float(steps[start])


@lru_cache(maxsize=256)
def cusum_arl(k: float, h: float, shift: float = 0.0) -> float:
    """Average run length of a one-sided upper CUSUM on N(shift, 1) observations, started at 0.

    Brook & Evans' chain: state 0 is the statistic at zero, states ``i = 1 .. m-1`` the intervals of width
    ``w = 2 h / (2 m - 1)`` centred on ``i w``.

    Examples
    --------
    >>> round(cusum_arl(0.5, 5.0))  # Montgomery, Table 9.3: 465 for the two-sided chart, so 930 one-sided
    931
    """
    if not (h > 0 and k >= 0):
        msg = f"CUSUM needs h > 0 and k >= 0; got h={h!r}, k={k!r}"
        raise DataError(msg)
    m = _STATES
    w = 2 * h / (2 * m - 1)
    centres = np.arange(m) * w
    upper_edges = (np.arange(m) + 0.5) * w  # upper edge of each state's interval
    # next value c_i + z - k falls in state j when it lies in [edge_{j-1}, edge_j); state 0 takes everything <= w/2
    cdf = norm.cdf(upper_edges[None, :] - centres[:, None] + k - shift)
    transition = np.diff(np.concatenate([np.zeros((m, 1)), cdf], axis=1), axis=1)
    return _absorbing_arl(transition, 0)


@lru_cache(maxsize=256)
def ewma_arl(lam: float, limit: float, shift: float = 0.0) -> float:
    """Average run length of a two-sided EWMA chart on N(shift, 1) observations, started at 0.

    ``limit`` is ``L``: the chart alarms when ``|Z| > L sqrt(lam / (2 - lam))`` (asymptotic limits).

    Examples
    --------
    >>> round(ewma_arl(0.1, 2.814), -1)  # Lucas & Saccucci (1990): 500
    500.0
    """
    if not (0 < lam <= 1 and limit > 0):
        msg = f"EWMA needs 0 < lambda <= 1 and L > 0; got lambda={lam!r}, L={limit!r}"
        raise DataError(msg)
    m = _STATES  # odd, so that a state is centred on 0
    c = limit * np.sqrt(lam / (2 - lam))
    width = 2 * c / m
    centres = -c + (np.arange(m) + 0.5) * width
    mean_next = (1 - lam) * centres[:, None]
    hi = norm.cdf((centres[None, :] + width / 2 - mean_next) / lam - shift)
    lo = norm.cdf((centres[None, :] - width / 2 - mean_next) / lam - shift)
    return _absorbing_arl(hi - lo, m // 2)


def _solve_limit(arl: Any, target: float, lo: float, hi: float, what: str) -> float:
    if not (target > 1 and np.isfinite(target)):
        msg = f"{what}: the in-control ARL must be a finite number > 1; got {target!r}"
        raise DataError(msg)
    if arl(lo) >= target:
        # even the narrowest limit is quieter than asked (a large reference k): use it; the chart then has fewer
        # false alarms than asked, never more
        return lo
    while arl(hi) < target:
        hi *= 1.5
        if hi > 1e3:
            msg = f"{what}: no limit reaches an in-control ARL of {target:g}"
            raise DataError(msg)
    return float(brentq(lambda x: np.log(arl(x)) - np.log(target), lo, hi, xtol=1e-6))


def cusum_limit(arl0: float, k: float) -> float:
    """The decision interval ``h`` of a one-sided CUSUM with reference ``k`` and in-control ARL ``arl0``.

    Parameters
    ----------
    arl0 : float
        In-control average run length (measurements between false alarms).
    k : float
        Reference value in standard deviations (half the shift to detect).

    Returns
    -------
    float
        ``h`` in standard deviations.

    Examples
    --------
    >>> round(cusum_limit(930.8, 0.5), 2)
    5.0
    """
    return _solve_limit(lambda h: cusum_arl(k, h), arl0, 1e-3, 10.0, "CUSUM design")


def ewma_limit(arl0: float, lam: float) -> float:
    """The limit ``L`` of a two-sided EWMA chart with smoothing ``lam`` and in-control ARL ``arl0``.

    Parameters
    ----------
    arl0 : float
        In-control average run length (measurements between false alarms).
    lam : float
        Smoothing constant, 0 < lam <= 1.

    Returns
    -------
    float
        ``L`` in asymptotic standard deviations of the EWMA statistic.

    Examples
    --------
    >>> round(ewma_limit(500.0, 0.1), 2)
    2.81
    """
    return _solve_limit(lambda limit: ewma_arl(lam, limit), arl0, 0.1, 5.0, "EWMA design")


@dataclass(frozen=True)
class ChartSignal:
    """A chart beyond its limit after an update.

    Attributes
    ----------
    name : str
        The monitored quantity.
    side : {"+", "-"}
        Direction of the change.
    statistic : float
        The chart's value (CUSUM sum or EWMA in standard deviations of z).
    limit : float
        The limit it crossed.
    run : int
        Measurements since the chart last left zero (CUSUM: the change-point estimate) or 0 for EWMA.
    change : ndarray, shape (n,)
        Estimate of the change of every quantity (in the units fed to the detector, before standardization):
        the mean since the change point (CUSUM) or the EWMA of the deviations.
    change_weight : float
        How many measurements that estimate is worth (its covariance is the healthy one divided by this).
    """

    name: str
    side: str
    statistic: float
    limit: float
    run: int
    change: Array
    change_weight: float


class SequentialDetector:
    """Two-sided CUSUM or EWMA charts on several quantities, designed for a false-alarm rate.

    The detector is stateless: :meth:`update` takes and returns a plain state dict (JSON-ready), so that the
    history store keeps it with every measurement and concurrent ingests continue each other's charts.

    Parameters
    ----------
    names : sequence of str
        The monitored quantities.
    scale : sequence of float
        Healthy standard deviation of each quantity (z = deviation / scale).
    method : {"cusum", "ewma"}
    false_alarm_rate : float
        Expected false alarms per in-control measurement, all charts together.
    shift : float
        Step size in standard deviations the CUSUM is tuned to (k = shift / 2).
    lam : float
        EWMA smoothing constant.

    Examples
    --------
    >>> det = SequentialDetector(["a"], [1.0], false_alarm_rate=0.001, shift=2.0)
    >>> state, signals = det.update(None, [0.3])
    >>> signals
    []
    >>> for _ in range(4):
    ...     state, signals = det.update(state, [-3.0])
    >>> [(s.name, s.side) for s in signals]
    [('a', '-')]
    """

    def __init__(
        self,
        names: Sequence[str],
        scale: ArrayLike,
        *,
        method: str = "cusum",
        false_alarm_rate: float = 1e-3,
        shift: float = 2.0,
        lam: float = 0.2,
    ) -> None:
        self.names = tuple(names)
        self.scale = np.asarray(scale, dtype=float)
        if self.scale.shape != (len(self.names),) or not np.all(self.scale > 0):
            msg = f"detector scales must be {len(self.names)} positive numbers; got {self.scale.tolist()}"
            raise DataError(msg)
        if method not in ("cusum", "ewma"):
            msg = f"detection method must be 'cusum' or 'ewma'; got {method!r}"
            raise DataError(msg)
        if not 0 < false_alarm_rate < 1:
            msg = f"false_alarm_rate must be in (0, 1); got {false_alarm_rate!r}"
            raise DataError(msg)
        self.method = method
        self.false_alarm_rate = float(false_alarm_rate)
        self.shift = float(shift)
        self.lam = float(lam)
        n = len(self.names)
        if method == "cusum":
            self.k = self.shift / 2
            self.arl0 = 2 * n / self.false_alarm_rate
            self.limit = cusum_limit(self.arl0, self.k)
        else:
            self.k = 0.0
            self.arl0 = n / self.false_alarm_rate
            self.limit = ewma_limit(self.arl0, self.lam)

    def design(self) -> dict[str, Any]:
        """The chart parameters and their in-control and out-of-control ARLs."""
        if self.method == "cusum":
            arl1 = cusum_arl(self.k, self.limit, self.shift)
        else:
            arl1 = ewma_arl(self.lam, self.limit, self.shift)
        return {"method": self.method, "limit": self.limit, "k": self.k, "lambda": self.lam,
                "arl0_per_chart": self.arl0, "arl_at_shift": arl1, "shift": self.shift,
                "false_alarm_rate": self.false_alarm_rate}

    def initial_state(self) -> dict[str, Any]:
        n = len(self.names)
        zeros = [0.0] * n
        return {"method": self.method, "names": list(self.names), "upper": zeros, "lower": list(zeros),
                "run_upper": [0] * n, "run_lower": [0] * n, "sum_upper": [zeros] * n, "sum_lower": [zeros] * n,
                "ewma": list(zeros), "ewma_change": list(zeros), "count": 0}

    def update(
        self, state: Mapping[str, Any] | None, deviation: ArrayLike, std: ArrayLike | None = None
    ) -> tuple[dict[str, Any], list[ChartSignal]]:
        """Feed one measurement's deviations (same units as ``scale``); return the new state and the signals.

        ``std``, the measurement's own standard uncertainty of each deviation, widens its standardization to
        ``sqrt(scale^2 + std^2)``: a poorly determined estimate moves the charts less.

        Parameters
        ----------
        state : mapping or None
            The state after the previous measurement (None: in control, at the start).
        deviation : array_like, shape (n,)
            Deviation of each quantity from its healthy expectation.
        std : array_like, shape (n,), optional
            Standard uncertainty of each deviation (same units).

        Returns
        -------
        state : dict
            The new state (JSON-ready).
        signals : list of ChartSignal
            The charts beyond their limits.

        Raises
        ------
        DataError
            ``deviation`` or ``std`` has the wrong length or non-finite (``std``: negative) values.
        """
        d = np.asarray(deviation, dtype=float)
        if d.shape != (len(self.names),) or not np.all(np.isfinite(d)):
            msg = f"detector needs {len(self.names)} finite deviations ({list(self.names)}); got {d.tolist()}"
            raise DataError(msg)
        own = np.zeros_like(d) if std is None else np.asarray(std, dtype=float)
        if own.shape != d.shape or not np.all(np.isfinite(own) & (own >= 0)):
            msg = f"detector needs {len(self.names)} finite standard uncertainties >= 0; got {own.tolist()}"
            raise DataError(msg)
        st = dict(self.initial_state() if state is None else state)
        if list(st.get("names", [])) != list(self.names) or st.get("method") != self.method:
            msg = (f"detector state is for {st.get('method')} charts on {st.get('names')}, not {self.method} on "
                   f"{list(self.names)}; learn a new baseline to reset it")
            raise DataError(msg)
        z = d / np.sqrt(self.scale**2 + own**2)
        signals: list[ChartSignal] = []
        st["count"] = int(st["count"]) + 1
        if self.method == "cusum":
            for side, sign in (("upper", 1.0), ("lower", -1.0)):
                value = np.maximum(0.0, np.asarray(st[side]) + sign * z - self.k)
                run = np.where(value > 0, np.asarray(st[f"run_{side}"]) + 1, 0)
                sums = np.where((value > 0)[:, None], np.asarray(st[f"sum_{side}"]) + d[None, :], 0.0)
                st[side], st[f"run_{side}"], st[f"sum_{side}"] = value.tolist(), run.tolist(), sums.tolist()
                for i in np.flatnonzero(value > self.limit):
                    signals.append(ChartSignal(self.names[i], "+" if sign > 0 else "-", float(value[i]),
                                               self.limit, int(run[i]), sums[i] / run[i], float(run[i])))
        else:
            ewma = self.lam * d + (1 - self.lam) * np.asarray(st["ewma_change"])
            zz = self.lam * z + (1 - self.lam) * np.asarray(st["ewma"])
            st["ewma"], st["ewma_change"] = zz.tolist(), ewma.tolist()
            sigma = np.sqrt(self.lam / (2 - self.lam))
            for i in np.flatnonzero(np.abs(zz) > self.limit * sigma):
                signals.append(ChartSignal(self.names[i], "+" if zz[i] > 0 else "-", float(zz[i] / sigma),
                                           self.limit, 0, ewma, (2 - self.lam) / self.lam))
        return st, signals

    def in_control(self, state: Mapping[str, Any], name: str) -> bool:
        """Whether a quantity's chart has come back: CUSUM sums at zero, or EWMA inside half its limit.

        Parameters
        ----------
        state : mapping
            A state returned by :meth:`update`.
        name : str
            One of ``names``.

        Returns
        -------
        bool
        """
        i = self.names.index(name)
        if self.method == "cusum":
            return float(state["upper"][i]) == 0.0 and float(state["lower"][i]) == 0.0
        sigma = np.sqrt(self.lam / (2 - self.lam))
        return bool(abs(float(state["ewma"][i])) < 0.5 * self.limit * sigma)
