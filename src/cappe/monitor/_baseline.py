"""The learned healthy state of a machine: what its component factors should be, and how much they scatter.

A healthy machine's stiffness factors are not constant: the bearing preload, and with it the bearing stiffness,
follows the spindle temperature. :func:`learn_baseline` therefore fits each component's log-factor over the
healthy measurements as a quadratic polynomial in the recorded operating conditions (temperature, speed; none:
a constant), and keeps the covariance of what is left. A new measurement is then judged by its *deviation*
from the expectation at its own conditions, so that a warm machine is not taken for a faulty one.

The charts standardize the deviations by ``sqrt(std^2 + resolution^2)``. The ``resolution`` is what the
scatter ``std`` of single measurements does not show (:func:`derived_resolution`, unless one is given): the
uncertainty of the learned expectation itself (the regression's largest leverage over the healthy data times the
scatter), and variation slower than one measurement that the regression did not explain (the excess variance of
means of :data:`BLOCK` consecutive residuals over ``std^2 / BLOCK``; model error that follows the unrecorded
part of the temperature, say), which a sequential chart would otherwise add up into false alarms. Both come from
the baseline's own data, so the smallest detectable change follows the machine's real scatter instead of a fixed
fraction.

The quadratic is known only over the conditions it was learned from. :meth:`Baseline.judge` tells whether a
measurement's conditions let it be judged at all: a condition the baseline depends on that the measurement does
not give, or one outside the learned range by more than :data:`LEARNED_MARGIN` of its half-range (an
extrapolation), leaves the measurement recorded but not judged; one more than :data:`IMPLAUSIBLE` half-ranges
away is called implausible (a unit or sensor error). :meth:`Baseline.gradient` gives the change of the expected
log-factors per unit of each condition: the signature of a condition sensor that reads off by a constant.

A condition sensor that lags what it stands for (a housing sensor behind the bearing) reads low while the machine
warms up and high while it cools: the error is the lag times the condition's rate of change. The baseline can
therefore also depend on the *rate of change* of each condition, per minute, taken from the previous measurement
of the same machine (:func:`condition_rates`; the derived condition ``rate:<name>``). :func:`learn_baseline`
adds a linear term in a condition's rate to a component's expectation only where it lowers the Bayesian information
criterion (BIC) of that component's fit (a lagging temperature sensor moves the bearings' expectation, not the
screws'). The rate is unknown for a machine's first measurement, one after a gap longer than
:data:`RATE_GAP` (the first one of a day, after the night) or one whose rate is implausible: such a measurement is
still judged, at the learned mean rate, with the rate term's healthy scatter added to its own uncertainty
(:meth:`Baseline.rate_std`), and :meth:`Baseline.judge` says so. Measurements without a rate do not drop the term
while learning: it is fitted on those that have one.

A change is read through the model's sensitivities, so a model that does not describe the machine reads it too large
or too small by a fraction of itself that the healthy scatter cannot show. How large that fraction is depends on
*what* is off and on the component, not on the size of the offset: on the spindle, masses 3 % off shift every
log-factor by about -0.03 and change the read sizes by less than 1 %, because a uniform mass error is a uniform
stiffness-and-damping error the factors absorb; damping 30 % off barely shows in the factors but reads a screw's
loss up to 8 % too small and a front-bearing loss within 0.2 %. :func:`twin_size_errors` therefore measures the
error on a *twin* of the machine: the model with its component factors and one common damping factor fitted to
healthy FRFs (the mismatch the data show), from which losses of each component are read back through the monitor's
own estimator. Its per-component errors give :attr:`Baseline.component_scale_std` (the prognosis of a component)
and the size term of :meth:`Baseline.size_covariance`; a baseline without FRFs falls back on the offset rule
(:data:`MODEL_OFFSET_FACTOR`).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cappe.exceptions import DataError
from cappe.systems.frf import FRFData

if TYPE_CHECKING:
    from cappe.monitor._estimation import FactorEstimator

__all__ = ["BASELINE_FORMAT", "BLOCK", "IMPLAUSIBLE", "LEARNED_MARGIN", "RATE_GAP", "RATE_PREFIX", "SIZE_SCALE_FLOOR",
           "TWIN_LOSSES", "Baseline", "condition_rates", "derived_resolution", "learn_baseline", "rate_name",
           "twin_size_errors", "with_rates"]

BASELINE_FORMAT = "cappe.monitor-baseline/1"

Array = NDArray[np.float64]

#: How far (in half-ranges of the healthy data, beyond the learned range) a condition may lie and still be judged.
LEARNED_MARGIN = 0.25

#: Conditions further than this many half-ranges from the learned centre are implausible for the machine.
IMPLAUSIBLE = 5.0

#: Relative standard uncertainty of a change's size on an exact model: what the fit's nonlinearity and noise
#: weighting add in proportion to the size (calibrated by simulation on an independent generator with the exact
#: model, ``benchmarks/bench_calibration.py``: relative size errors of 0.1-1 %, RMS 0.5 %). A model that is off adds
#: its own part (:attr:`Baseline.size_scale_std`).
SIZE_SCALE_FLOOR = 0.005

#: Multiple of the model's offset (:attr:`Baseline.model_offset`, an RMS over the components) taken as the relative
#: size error it causes: with the masses 3 % off, the sizes of single components were off by 1 to 8 % of themselves
#: (about 2.5 times the offset for the worst component); 1.5 brought the 95 % intervals to 66 of 67 in the
#: calibration run (1.0: 60 of 67), checked on fresh seeds in ``benchmarks/results/calibration_mismatch.json``.
MODEL_OFFSET_FACTOR = 1.5

#: Losses of each component read back on the twin (:func:`twin_size_errors`; the largest error is kept): the range a
#: trend crosses on its way to the intolerable grade. The error changes with the size, and not monotonically (screw 3
#: of the spindle with damping 30 % off: 0.4 % at a 3 % loss, 3 % at 5 %, 1.3 % at 10 %, 4.5 % at 30 %).
TWIN_LOSSES = (0.02, 0.05, 0.1, 0.2, 0.3)

#: Healthy FRFs (evenly spread over the learned day) the twin's damping and factors are fitted to.
TWIN_FITS = 8

#: Consecutive healthy measurements whose mean residual shows variation slower than one measurement.
BLOCK = 8

#: Name prefix of the derived rate-of-change conditions (``rate:temperature``, per minute): cappe's, not a sensor's.
RATE_PREFIX = "rate:"

#: Longest time from the previous measurement of the same machine over which a condition's rate of change is taken
#: (a longer gap, such as the night before a day's first measurement, leaves the rate unknown): four times the
#: usual 15-minute interval, so a missed measurement or two still give a rate.
RATE_GAP = timedelta(minutes=60)


def rate_name(condition: str) -> str:
    """The name of a condition's rate of change (``rate:<condition>``, per minute).

    Parameters
    ----------
    condition : str
        The operating condition.

    Returns
    -------
    str

    Examples
    --------
    >>> rate_name("temperature")
    'rate:temperature'
    """
    return f"{RATE_PREFIX}{condition}"


def condition_rates(
    conditions: Mapping[str, float] | None,
    timestamp: datetime,
    previous: tuple[datetime, Mapping[str, float] | None] | None,
    *,
    gap: timedelta = RATE_GAP,
) -> dict[str, float]:
    """Rate of change per minute of each condition since the previous measurement of the same machine.

    Parameters
    ----------
    conditions : mapping name -> float or None
        This measurement's operating conditions.
    timestamp : datetime
        When it was taken.
    previous : (datetime, mapping) or None
        Time and conditions of the machine's previous measurement (None: it has none).
    gap : timedelta
        Longest time from the previous measurement over which a rate is taken (:data:`RATE_GAP`).

    Returns
    -------
    dict
        ``rate:<name>`` -> change per minute, for each finite condition (not itself a rate) that the previous
        measurement also gives; empty when there is no previous measurement, it is not earlier, or it is more than
        ``gap`` earlier (the rate is unknown).

    Examples
    --------
    >>> t = datetime(2026, 3, 2, 6, 15, tzinfo=UTC)
    >>> condition_rates({"temperature": 21.0}, t, (t - timedelta(minutes=15), {"temperature": 19.5}))
    {'rate:temperature': 0.1}
    >>> condition_rates({"temperature": 21.0}, t, (t - timedelta(hours=8), {"temperature": 18.0}))
    {}
    """
    if previous is None or not conditions or not previous[1]:
        return {}
    minutes = (timestamp - previous[0]).total_seconds() / 60.0
    if not 0.0 < minutes <= gap.total_seconds() / 60.0:
        return {}
    before = previous[1]
    rates = {}
    for name, value in conditions.items():
        if name.startswith(RATE_PREFIX) or name not in before:
            continue
        rate = (float(value) - float(before[name])) / minutes
        if np.isfinite(rate):
            rates[rate_name(name)] = rate
    return rates


def with_rates(
    conditions: Sequence[Mapping[str, float] | None],
    timestamps: Sequence[datetime],
    previous: tuple[datetime, Mapping[str, float] | None] | None = None,
    *,
    gap: timedelta = RATE_GAP,
) -> list[dict[str, float]]:
    """Measurements' conditions with their rates of change (:func:`condition_rates`) added.

    Parameters
    ----------
    conditions : sequence of mapping
        Each measurement's operating conditions.
    timestamps : sequence of datetime
        When each was taken (any order: each one's previous is the one before it in time).
    previous : (datetime, mapping), optional
        The measurement before the earliest of them.
    gap : timedelta
        See :func:`condition_rates`.

    Returns
    -------
    list of dict
        In the order given.

    Raises
    ------
    DataError
        ``conditions`` and ``timestamps`` differ in length.
    """
    if len(conditions) != len(timestamps):
        msg = f"rates of change: {len(conditions)} condition records but {len(timestamps)} timestamps"
        raise DataError(msg)
    out: list[dict[str, float]] = [{} for _ in conditions]
    before = previous
    for k in sorted(range(len(timestamps)), key=lambda i: timestamps[i]):
        given = {name: float(v) for name, v in (conditions[k] or {}).items() if not name.startswith(RATE_PREFIX)}
        out[k] = {**given, **condition_rates(given, timestamps[k], before, gap=gap)}
        before = (timestamps[k], given)
    return out


@dataclass(frozen=True)
class Baseline:
    """Healthy expectation and scatter of the component log-factors.

    Attributes
    ----------
    names : tuple of str
        Components.
    conditions : tuple of str
        Operating conditions the expectation depends on (may be empty).
    center, spread : ndarray, shape (n_cond,)
        Centre and half-range of each condition over the healthy data (the polynomial's variable is
        ``(c - center) / spread``).
    coefficients : ndarray, shape (1 + 2 n_cond + n_rate, n)
        Constant, linear and quadratic terms of each component's expected log-factor, then its linear terms in the
        rates of change (0 where a component has no such term).
    covariance : ndarray, shape (n, n)
        Covariance of the healthy deviations.
    resolution : float
        Smallest relative change treated as real (adds to the charts' standard deviation; derived from the
        healthy data unless one was given).
    n_measurements : int
        Healthy measurements learned from.
    measurement_ids : tuple of int
        Their ids in the history store (empty when learned outside one).
    frf : dict, optional
        Mean complex FRF of the healthy measurements on their common lines.
    features : dict
        Mean and standard deviation of every scalar feature.
    map : dict, optional
        Frequency-damping map over the preload (thesis Fig. 5.30) for the dashboard.
    created : str
        ISO time of learning.
    sigma : float, optional
        Median residual of the healthy fits: how well the model describes this machine (model error included);
        later fits are judged against it.
    left_out : tuple of str
        Measurements of the chosen range that were left out, and why.
    size_error : ndarray, shape (n, n), optional
        Largest relative error of component ``i``'s read change, as a fraction of a loss of component ``j``
        (column), on the machine's twin (:func:`twin_size_errors`); None: not measured (no FRFs).
    rates : tuple of str
        Conditions whose rate of change (``rate:<name>``, per minute) the expectation may depend on (see the module
        notes); which components use each is :attr:`rate_terms`.
    rate_center, rate_spread : ndarray, shape (n_rate,)
        Centre and half-range of each rate over the healthy data (the variable is ``(rate - center) / spread``).
    rate_mean, rate_scatter : ndarray, shape (n_rate,)
        Mean and standard deviation of each rate over the healthy data: where a measurement's rate is unknown it
        is judged at the mean, with the term's scatter added to its uncertainty.
    """

    names: tuple[str, ...]
    conditions: tuple[str, ...]
    center: Array
    spread: Array
    coefficients: Array
    covariance: Array
    resolution: float = 0.005
    n_measurements: int = 0
    measurement_ids: tuple[int, ...] = ()
    frf: dict[str, Any] | None = None
    features: dict[str, tuple[float, float]] = field(default_factory=dict)
    map: dict[str, Any] | None = None
    created: str = ""
    sigma: float | None = None
    left_out: tuple[str, ...] = ()
    size_error: Array | None = None
    rates: tuple[str, ...] = ()
    rate_center: Array = field(default_factory=lambda: np.zeros(0))
    rate_spread: Array = field(default_factory=lambda: np.ones(0))
    rate_mean: Array = field(default_factory=lambda: np.zeros(0))
    rate_scatter: Array = field(default_factory=lambda: np.zeros(0))

    def _design(self, conditions: Mapping[str, float] | None) -> Array:
        values = []
        for name in self.conditions:
            if conditions is None or name not in conditions:
                msg = (f"the baseline depends on the operating condition '{name}', which the measurement does not "
                       f"give (conditions {dict(conditions or {})})")
                raise DataError(msg)
            values.append(float(conditions[name]))
        x = (np.asarray(values, dtype=float) - self.center) / self.spread
        known = self._known_rates(conditions)
        rate = np.array([known.get(name, self.rate_mean[k]) for k, name in enumerate(self.rates)], dtype=float)
        return np.concatenate([[1.0], x, x**2, (rate - self.rate_center) / self.rate_spread])

    def _known_rates(self, conditions: Mapping[str, float] | None) -> dict[str, float]:
        """The rates of ``conditions`` this baseline can use: finite, and not beyond :data:`IMPLAUSIBLE`
        half-ranges of the learned ones (a sensor's jump, not a warm-up)."""
        known = {}
        for k, name in enumerate(self.rates):
            value = float((conditions or {}).get(rate_name(name), np.nan))
            if np.isfinite(value) and abs(value - self.rate_center[k]) <= IMPLAUSIBLE * self.rate_spread[k]:
                known[name] = value
        return known

    @property
    def rate_terms(self) -> dict[str, tuple[str, ...]]:
        """Component -> the conditions whose rate of change its expectation uses (components without one left out)."""
        rows = self.coefficients[1 + 2 * len(self.conditions):]
        return {n: tuple(c for c, row in zip(self.rates, rows, strict=True) if row[j] != 0.0)
                for j, n in enumerate(self.names) if np.any(rows[:, j] != 0.0)}

    def rate_std(self, conditions: Mapping[str, float] | None) -> Array:
        """Standard uncertainty of each expectation from rates of change these conditions do not give.

        A measurement whose rate is unknown (see the module notes) is judged at the learned mean rate; what the
        rate term spreads over the healthy data is then part of its deviation's uncertainty.

        Parameters
        ----------
        conditions : mapping name -> float or None
            The measurement's conditions, rates (``rate:<name>``) included where known.

        Returns
        -------
        ndarray, shape (n,)
            0 for every component when every rate the baseline uses is known.
        """
        known = self._known_rates(conditions)
        rows = self.coefficients[1 + 2 * len(self.conditions):]
        variance = np.zeros(len(self.names))
        for k, name in enumerate(self.rates):
            if name not in known:
                variance += (rows[k] / self.rate_spread[k] * self.rate_scatter[k]) ** 2
        return np.sqrt(variance)

    def judge(self, conditions: Mapping[str, float] | None) -> tuple[list[str], list[str]]:
        """Whether a measurement at these conditions can be judged against this baseline.

        Parameters
        ----------
        conditions : mapping name -> float or None
            The measurement's operating conditions.

        Returns
        -------
        reasons : list of str
            Why it cannot be judged (empty: it can): a condition missing, not finite, outside the learned range
            by more than :data:`LEARNED_MARGIN` of its half-range, or implausible.
        notes : list of str
            What to know about a measurement that is judged (a condition slightly outside the learned range).

        Examples
        --------
        >>> b = learn_baseline(np.zeros((9, 1)) + np.arange(9)[:, None] * 1e-4, names=["front"],
        ...                    conditions=[{"temperature": 18.0 + t} for t in range(9)])
        >>> b.judge({"temperature": 22.0})
        ([], [])
        >>> b.judge({"temp": 22.0})[0]
        ["the baseline depends on the condition 'temperature', which the measurement does not give (it gives temp)"]
        >>> b.judge({"temperature": 77.0})[0]  # doctest: +NORMALIZE_WHITESPACE
        ['temperature 77 is implausible for this machine: 13 half-ranges from the learned range 18 to 26 (a unit
          or sensor error?)']
        """
        given = dict(conditions or {})
        reasons: list[str] = []
        notes: list[str] = []
        for k, name in enumerate(self.conditions):
            if name not in given:
                others = ", ".join(sorted(given)) or "none"
                reasons.append(f"the baseline depends on the condition '{name}', which the measurement does not "
                               f"give (it gives {others})")
                continue
            value = float(given[name])
            if not np.isfinite(value):
                reasons.append(f"{name} is not a number ({value})")
                continue
            lo, hi = self.center[k] - self.spread[k], self.center[k] + self.spread[k]
            # as many digits as tell the value from the range's ends ("18.087 ... outside the learned range 18.09 to
            # 26.14", not "18.09 ... outside the learned range 18.09 to 26.14")
            digits = next((d for d in range(4, 10) if f"{value:.{d}g}" not in (f"{lo:.{d}g}", f"{hi:.{d}g}")), 4)
            learned = f"the learned range {lo:.{digits}g} to {hi:.{digits}g}"
            x = abs(value - self.center[k]) / self.spread[k]
            if x > IMPLAUSIBLE:
                reasons.append(f"{name} {value:.{digits}g} is implausible for this machine: {x - 1:.2g} half-ranges "
                               f"from {learned} (a unit or sensor error?)")
            elif x > 1 + LEARNED_MARGIN:
                reasons.append(f"{name} {value:.{digits}g} is outside {learned} ({x - 1:.2g} half-ranges beyond it): "
                               f"the healthy expectation there is unknown")
            elif x > 1 + 1e-12:  # the learned extremes themselves (rounding) are inside
                notes.append(f"{name} {value:.{digits}g} is slightly outside {learned} (judged on the extrapolated "
                             f"expectation)")
        known = self._known_rates(given)
        for k, name in enumerate(self.rates):
            users = [n for n, used in self.rate_terms.items() if name in used]
            if not users:
                continue
            value = float(given.get(rate_name(name), np.nan))
            if name not in known:
                why = (f"{value:.3g} per minute is implausible (a sensor's jump?)" if np.isfinite(value) else
                       f"unknown (no earlier measurement of this machine within {RATE_GAP.total_seconds() / 60:g} "
                       "min)")
                extra = float(np.max(self.rate_std(given)))
                notes.append(f"the rate of change of {name} is {why}: judged at the learned mean rate "
                             f"{self.rate_mean[k]:+.3g} per minute, the rate term of {', '.join(users)} adding "
                             f"{100 * extra:.2g} % to its uncertainty")
            elif abs(value - self.rate_center[k]) > (1 + LEARNED_MARGIN) * self.rate_spread[k]:
                lo, hi = self.rate_center[k] - self.rate_spread[k], self.rate_center[k] + self.rate_spread[k]
                notes.append(f"the rate of change of {name}, {value:+.3g} per minute, is outside the learned "
                             f"{lo:+.3g} to {hi:+.3g} (judged on the extrapolated rate term)")
        return reasons, notes

    def gradient(self, conditions: Mapping[str, float] | None = None) -> Array:
        """Change of the expected log-factors per unit of each condition, at these conditions.

        Parameters
        ----------
        conditions : mapping name -> float, optional
            The measurement's operating conditions (every one the baseline depends on).

        Returns
        -------
        ndarray, shape (n_cond, n)
            Row ``k``: ``d expected / d condition_k`` (per recorded unit).

        Raises
        ------
        DataError
            A condition the baseline depends on is missing.
        """
        x = self._design(conditions)[1:1 + len(self.conditions)]
        m = len(self.conditions)
        linear, quadratic = self.coefficients[1:1 + m], self.coefficients[1 + m:1 + 2 * m]
        return np.asarray((linear + 2 * x[:, None] * quadratic) / self.spread[:, None], dtype=float)

    def expected(self, conditions: Mapping[str, float] | None = None) -> Array:
        """Expected healthy log-factors at these operating conditions.

        Parameters
        ----------
        conditions : mapping name -> float, optional
            The measurement's operating conditions (every one the baseline depends on, in its recorded unit).

        Returns
        -------
        ndarray, shape (n,)
            ``ln`` of each component's expected factor.

        Raises
        ------
        DataError
            A condition the baseline depends on is missing.
        """
        return np.asarray(self._design(conditions) @ self.coefficients, dtype=float)

    def deviation(self, log_factor: ArrayLike, conditions: Mapping[str, float] | None = None) -> Array:
        """Log-factors minus their healthy expectation.

        Parameters
        ----------
        log_factor : array_like, shape (n,)
            ``ln`` of the measured component factors.
        conditions : mapping name -> float, optional
            The measurement's operating conditions (every one the baseline depends on, in its recorded unit).

        Returns
        -------
        ndarray, shape (n,)
            Deviations in ``ln`` units (0.01: about 1 % above the expectation).
        """
        return np.asarray(log_factor, dtype=float) - self.expected(conditions)

    @property
    def std(self) -> Array:
        """Healthy standard deviation of each log-factor."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    @property
    def scale(self) -> Array:
        """The charts' standard deviation: ``sqrt(std^2 + resolution^2)``."""
        return np.sqrt(self.std**2 + self.resolution**2)

    @property
    def model_offset(self) -> float:
        """How far the healthy machine is from its model: the RMS over the components of the expected log-factors
        at the centre of the learned conditions (0 for a model that describes the machine; a model 3 % off in mass
        gives about 0.03)."""
        centre = np.asarray(self.coefficients[0], dtype=float)
        return float(np.sqrt(np.mean(centre**2))) if centre.size else 0.0

    @property
    def size_scale_std(self) -> float:
        """Relative standard uncertainty of a change's size, the largest over the components.

        With the twin's errors (:attr:`size_error`) the largest of :meth:`component_scale_std` over the
        components; without, ``hypot(SIZE_SCALE_FLOOR, MODEL_OFFSET_FACTOR model_offset)``: a model a fraction ``e``
        away from the machine is taken to read sizes about ``e`` of themselves off. Checked by simulation on an
        independent generator (exact model and a machine 3 % heavier and 30 % more damped than its model,
        ``benchmarks/bench_calibration.py``)."""
        if self.size_error is not None:
            return float(np.max(self.component_scale_std(leaked=True), initial=SIZE_SCALE_FLOOR))
        return float(np.hypot(SIZE_SCALE_FLOOR, MODEL_OFFSET_FACTOR * self.model_offset))

    def component_scale_std(self, leaked: bool = False) -> Array:
        """Relative standard uncertainty of each component's read change beyond the scatter.

        ``hypot(SIZE_SCALE_FLOOR, error)`` with ``error`` the twin's (:attr:`size_error`): the component's own
        error for a loss of itself, or with ``leaked`` the largest for a loss of any component (what a change
        elsewhere leaks into it). Without the twin every component gets the offset rule of :attr:`size_scale_std`.

        Parameters
        ----------
        leaked : bool
            Include what losses of the other components leak into each component's reading.

        Returns
        -------
        ndarray, shape (n,)
        """
        if self.size_error is None:
            return np.full(len(self.names), self.size_scale_std)
        error = np.max(self.size_error, axis=1) if leaked else np.diag(self.size_error)
        return np.asarray(np.hypot(SIZE_SCALE_FLOOR, error), dtype=float)

    def size_covariance(self, change: ArrayLike, weight: float = 1.0) -> Array:
        """Covariance the diagnosis sizes a change with and compares the hypotheses by.

        The charts' covariance (the healthy scatter and the resolution, both from the baseline's own data) divided by
        ``weight``, plus the systematic part that grows with the change, on component ``i``: with the twin's errors
        ``E`` (:attr:`size_error`) ``(SIZE_SCALE_FLOOR max|change|)^2 + sum_j (E_ij change_j)^2``, the error its
        reading takes from the change of each component (its own, and what a wrong sensitivity leaks into it from
        the others); without them ``(size_scale_std max|change|)^2`` on every component.

        Parameters
        ----------
        change : array_like, shape (n,)
            The change of the log-factors being diagnosed.
        weight : float
            How many measurements the change is the mean of.

        Returns
        -------
        ndarray, shape (n, n)
        """
        delta = np.asarray(change, dtype=float)
        largest = float(np.max(np.abs(delta), initial=0.0))
        if self.size_error is None:
            variance = np.full(len(self.names), (self.size_scale_std * largest) ** 2)
        else:
            variance = (SIZE_SCALE_FLOOR * largest) ** 2 + (self.size_error**2) @ (delta**2)
        return np.asarray(self.chart_covariance / weight + np.diag(variance), dtype=float)

    @property
    def diagnosis_covariance(self) -> Array:
        """Covariance of a single measurement's deviation for the diagnosis at no change (the charts' covariance);
        :meth:`size_covariance` adds the part that grows with a change."""
        return self.chart_covariance

    @property
    def chart_covariance(self) -> Array:
        """Covariance of the deviations as the charts and the diagnosis see it (resolution added)."""
        return np.asarray(self.covariance + self.resolution**2 * np.eye(len(self.names)), dtype=float)

    def to_dict(self) -> dict[str, Any]:
        mean = np.exp(self.coefficients[0])
        return {
            "format": BASELINE_FORMAT,
            "created": self.created,
            "n_measurements": self.n_measurements,
            "measurement_ids": list(self.measurement_ids),
            "names": list(self.names),
            "conditions": list(self.conditions),
            "center": self.center.tolist(),
            "spread": self.spread.tolist(),
            "coefficients": self.coefficients.tolist(),
            "covariance": self.covariance.tolist(),
            "resolution": self.resolution,
            "sigma": self.sigma,
            "left_out": list(self.left_out),
            "size_error": None if self.size_error is None else self.size_error.tolist(),
            "rates": list(self.rates),
            "rate_center": self.rate_center.tolist(),
            "rate_spread": self.rate_spread.tolist(),
            "rate_mean": self.rate_mean.tolist(),
            "rate_scatter": self.rate_scatter.tolist(),
            "rate_terms": {n: list(v) for n, v in self.rate_terms.items()},
            # the view for people and the dashboard: factors at the centre of the conditions
            "mean": {n: float(v) for n, v in zip(self.names, mean, strict=True)},
            "std": {n: float(m * s) for n, m, s in zip(self.names, mean, self.std, strict=True)},
            "limits": {n: [float(m * np.exp(-3 * s)), float(m * np.exp(3 * s))]
                       for n, m, s in zip(self.names, mean, self.scale, strict=True)},
            "features": {k: list(v) for k, v in self.features.items()},
            "frf": self.frf,
            "map": self.map,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Baseline:
        """The baseline of a ``cappe.monitor-baseline/1`` document (the inverse of :meth:`to_dict`).

        Parameters
        ----------
        data : mapping
            The document.

        Returns
        -------
        Baseline

        Raises
        ------
        DataError
            The format is not ``cappe.monitor-baseline/1`` or an entry is missing or malformed.
        """
        if data.get("format") != BASELINE_FORMAT:
            msg = f"baseline format must be {BASELINE_FORMAT!r}; got {data.get('format')!r}"
            raise DataError(msg)
        try:
            baseline = cls(
                names=tuple(data["names"]),
                conditions=tuple(data["conditions"]),
                center=np.asarray(data["center"], dtype=float),
                spread=np.asarray(data["spread"], dtype=float),
                coefficients=np.asarray(data["coefficients"], dtype=float).reshape(-1, len(data["names"])),
                covariance=np.asarray(data["covariance"], dtype=float),
                resolution=float(data["resolution"]),
                n_measurements=int(data["n_measurements"]),
                measurement_ids=tuple(int(i) for i in data.get("measurement_ids", [])),
                frf=data.get("frf"),
                features={k: (float(v[0]), float(v[1])) for k, v in data.get("features", {}).items()},
                map=data.get("map"),
                created=str(data.get("created", "")),
                sigma=None if data.get("sigma") is None else float(data["sigma"]),
                left_out=tuple(str(v) for v in data.get("left_out", [])),
                size_error=None if data.get("size_error") is None
                else np.asarray(data["size_error"], dtype=float).reshape(len(data["names"]), len(data["names"])),
                rates=tuple(str(v) for v in data.get("rates", [])),
                rate_center=np.asarray(data.get("rate_center", []), dtype=float),
                rate_spread=np.asarray(data.get("rate_spread", []), dtype=float),
                rate_mean=np.asarray(data.get("rate_mean", []), dtype=float),
                rate_scatter=np.asarray(data.get("rate_scatter", []), dtype=float),
            )
        except (KeyError, TypeError, ValueError) as exc:
            msg = f"baseline is malformed: {type(exc).__name__} {exc}"
            raise DataError(msg) from exc
        rows = 1 + 2 * len(baseline.conditions) + len(baseline.rates)
        sizes = {a.size for a in (baseline.rate_center, baseline.rate_spread, baseline.rate_mean,
                                  baseline.rate_scatter)}
        if baseline.coefficients.shape[0] != rows or sizes != {len(baseline.rates)}:
            msg = (f"baseline is malformed: {len(baseline.conditions)} condition(s) and the rates "
                   f"{list(baseline.rates)} need {rows} coefficient rows and {len(baseline.rates)} rate centres, "
                   f"spreads, means and scatters; got {baseline.coefficients.shape[0]} rows and sizes {sorted(sizes)}")
            raise DataError(msg)
        return baseline

    def frf_data(self) -> FRFData | None:
        """The mean healthy FRF."""
        if not self.frf:
            return None
        H = np.asarray(self.frf["re"]) + 1j * np.asarray(self.frf["im"])
        return FRFData(np.asarray(self.frf["freq"], dtype=float), H, tuple(self.frf["input_names"]),
                       tuple(self.frf["output_names"]))


def _mean_frf(frfs: Sequence[FRFData]) -> dict[str, Any] | None:
    first = frfs[0]
    same = all(f.freq.shape == first.freq.shape and np.allclose(f.freq, first.freq)
               and f.input_names == first.input_names and f.output_names == first.output_names for f in frfs)
    if not same:
        return None
    H = np.mean([np.asarray(f.H) for f in frfs], axis=0)
    return {"freq": first.freq.tolist(), "input_names": list(first.input_names),
            "output_names": list(first.output_names), "re": H.real.tolist(), "im": H.imag.tolist(),
            "magnitude": np.abs(H).tolist()}


def derived_resolution(residual: ArrayLike, design: ArrayLike) -> float:
    """The resolution a baseline's own data support (see the module notes).

    Parameters
    ----------
    residual : array_like, shape (N, n)
        Healthy log-factors minus the regression's fit, in time order.
    design : array_like, shape (N, p)
        The regression's design matrix.

    Returns
    -------
    float
        The largest over the components of ``sqrt(leverage std^2 + excess)`` (``ln`` units).

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> white = 1e-3 * rng.standard_normal((400, 1))
    >>> round(derived_resolution(white, np.ones((400, 1))) / 1e-3, 2)  # white scatter: only 1 / sqrt(400)
    0.05
    >>> slow = white + 2e-3 * np.repeat(rng.standard_normal(50), 8)[:, None]  # a level that wanders
    >>> 1.5 < derived_resolution(slow, np.ones((400, 1))) / 1e-3 < 2.5
    True
    """
    r = np.asarray(residual, dtype=float)
    x = np.asarray(design, dtype=float)
    n_meas, p = x.shape
    var = np.sum(r**2, axis=0) / max(n_meas - p, 1)
    leverage = float(np.max(np.sum(x * np.linalg.pinv(x).T, axis=1)))
    blocks = n_meas // BLOCK
    excess = np.zeros(r.shape[1])
    if blocks >= 3:
        means = r[:blocks * BLOCK].reshape(blocks, BLOCK, -1).mean(axis=1)
        excess = np.clip(means.var(axis=0, ddof=1) - var / BLOCK, 0.0, None)
    return float(np.sqrt(np.max(leverage * var + excess)))


def learn_baseline(
    log_factors: Array,
    *,
    names: Sequence[str],
    conditions: Sequence[Mapping[str, float]] | None = None,
    frfs: Sequence[FRFData] | None = None,
    features: Sequence[Mapping[str, float]] | None = None,
    resolution: float | None = None,
    measurement_ids: Sequence[int] = (),
    preload_map: Mapping[str, Any] | None = None,
    sigma: float | None = None,
    size_error: ArrayLike | None = None,
) -> Baseline:
    """Learn a :class:`Baseline` from healthy measurements.

    Parameters
    ----------
    log_factors : ndarray, shape (N, n)
        Estimated log-factors of the healthy measurements.
    names : sequence of str
        Component names (n).
    conditions : sequence of mapping, optional
        Operating conditions of each measurement; those every measurement gives, and that vary, become
        regressors (a quadratic in each). Their rates of change (``rate:<name>``, :func:`with_rates`) are
        candidate linear terms, taken per component where they lower its BIC and fitted on the measurements that
        give them (a measurement without one keeps the other terms; see the module notes).
    frfs : sequence of FRFData, optional
        The healthy FRFs (their mean is kept when they share their lines).
    features : sequence of mapping, optional
        Scalar features of each measurement (NaN = missing).
    resolution : float, optional
        Smallest relative change treated as real (0.005 = 0.5 %); default: :func:`derived_resolution` of the
        healthy data (see the module notes).
    measurement_ids : sequence of int
    preload_map : mapping, optional
    sigma : float, optional
        Median residual of the healthy fits (see :attr:`Baseline.sigma`).
    size_error : array_like, shape (n, n), optional
        The twin's relative size errors (:func:`twin_size_errors`; see :attr:`Baseline.size_error`).

    Raises
    ------
    DataError
        With fewer measurements than ``3 (1 + 2 n_cond)``, or non-finite log-factors.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> t = rng.uniform(18, 26, 60)
    >>> s = np.column_stack([0.01 * (t - 22) + 1e-4 * rng.standard_normal(60), 1e-4 * rng.standard_normal(60)])
    >>> b = learn_baseline(s, names=["front", "rear"], conditions=[{"temperature": v} for v in t])
    >>> [round(float(v), 3) + 0.0 for v in b.expected({"temperature": 25.0})]
    [0.03, 0.0]
    """
    s = np.asarray(log_factors, dtype=float)
    n_meas = s.shape[0] if s.ndim == 2 else 0
    if s.ndim != 2 or s.shape[1] != len(names) or not np.all(np.isfinite(s)):
        msg = f"baseline log-factors must be a finite (N, {len(names)}) array; got shape {s.shape}"
        raise DataError(msg)
    conds = list(conditions) if conditions is not None else [{}] * n_meas
    if len(conds) != n_meas:
        msg = f"baseline: {n_meas} measurements but {len(conds)} condition records"
        raise DataError(msg)
    # rates of change are learned apart: a measurement without one (a day's first) must not drop the term
    common = sorted(set.intersection(*({k for k in c if not k.startswith(RATE_PREFIX)} for c in conds))) if conds \
        else []
    values = np.array([[float(c[k]) for k in common] for c in conds], dtype=float).reshape(n_meas, len(common))
    bad = np.argwhere(~np.isfinite(values))
    if bad.size:
        i, j = bad[0]
        msg = f"baseline: operating condition '{common[j]}' of measurement {i} is not finite ({values[i, j]})"
        raise DataError(msg)
    varying = [j for j in range(len(common)) if np.ptp(values[:, j]) > 0]
    names_c = tuple(common[j] for j in varying)
    values = values[:, varying]
    needed = 3 * (1 + 2 * len(names_c))
    if n_meas < needed:
        msg = (f"a baseline with {len(names_c)} operating condition(s) {list(names_c)} needs at least {needed} "
               f"healthy measurements; got {n_meas}")
        raise DataError(msg)
    # the middle of the learned range, not the mean: a machine that runs warm most of the day has its mean near the
    # top of the range, and center +- spread must be the range the data cover (what judge() calls learned)
    center = (values.min(axis=0) + values.max(axis=0)) / 2 if names_c else np.zeros(0)
    spread = np.ptp(values, axis=0) / 2 if names_c else np.zeros(0)
    x = (values - center) / spread if names_c else values
    design = np.column_stack([np.ones(n_meas), x, x**2])
    coefficients, *_ = np.linalg.lstsq(design, s, rcond=None)
    rates, rate_values, known = _rate_candidates(conds, names_c, needed)
    rate_center = (rate_values.min(axis=0) + rate_values.max(axis=0)) / 2 if rates else np.zeros(0)
    rate_spread = np.ptp(rate_values, axis=0) / 2 if rates else np.ones(0)
    rate_x = (rate_values - rate_center) / rate_spread
    chosen = _bic_rate_terms(s[known], design[known], rate_x)
    rows = known if chosen.any() else np.ones(n_meas, dtype=bool)
    full = np.column_stack([design, np.zeros((n_meas, len(rates)))])
    full[known, design.shape[1]:] = rate_x
    coefficients = np.vstack([coefficients, np.zeros((len(rates), len(names)))])
    for j in np.flatnonzero(chosen.any(axis=0)):
        columns = np.concatenate([np.arange(design.shape[1]), design.shape[1] + np.flatnonzero(chosen[:, j])])
        fitted, *_ = np.linalg.lstsq(full[np.ix_(known, columns)], s[known, j], rcond=None)
        coefficients[:, j] = 0.0
        coefficients[columns, j] = fitted
    # the scatter of the measurements the expectation is judged with (those with their rates where a term uses one)
    used = np.concatenate([np.arange(design.shape[1]), design.shape[1] + np.flatnonzero(chosen.any(axis=1))])
    residual = s[rows] - full[rows] @ coefficients
    dof = max(int(rows.sum()) - design.shape[1] - int(chosen.sum(axis=0).max(initial=0)), 1)
    covariance = residual.T @ residual / dof
    if resolution is None:
        resolution = derived_resolution(residual, full[np.ix_(rows, used)])
    feature_stats: dict[str, tuple[float, float]] = {}
    if features:
        for key in sorted({k for f in features for k in f}):
            column = np.array([float(f.get(key, np.nan)) for f in features])
            column = column[np.isfinite(column)]
            if column.size:
                feature_stats[key] = (float(column.mean()), float(column.std(ddof=1)) if column.size > 1 else 0.0)
    return Baseline(
        names=tuple(names),
        conditions=names_c,
        center=center,
        spread=spread,
        coefficients=coefficients,
        covariance=covariance,
        resolution=float(resolution),
        n_measurements=n_meas,
        measurement_ids=tuple(int(i) for i in measurement_ids),
        frf=_mean_frf(frfs) if frfs else None,
        features=feature_stats,
        map=dict(preload_map) if preload_map else None,
        created=datetime.now(UTC).isoformat(),
        sigma=sigma,
        size_error=None if size_error is None else np.asarray(size_error, dtype=float),
        rates=rates,
        rate_center=rate_center,
        rate_spread=rate_spread,
        rate_mean=rate_values.mean(axis=0) if rates else np.zeros(0),
        rate_scatter=rate_values.std(axis=0, ddof=1) if rates else np.zeros(0),
    )


def _rate_candidates(
    conds: Sequence[Mapping[str, float]], names_c: tuple[str, ...], needed: int,
) -> tuple[tuple[str, ...], Array, NDArray[np.bool_]]:
    """The conditions whose rate of change may enter the baseline, their rates on the measurements that give every
    one of them, and which measurements those are.

    A condition's rate is a candidate when the condition is one of the regression's (``names_c``), at least
    ``needed + 3`` measurements give it finite and it varies; the rates are taken on the measurements that give all
    the candidates (the others keep the terms that do not need a rate)."""
    rates = []
    for name in names_c:
        column = np.array([float(c.get(rate_name(name), np.nan)) for c in conds], dtype=float)
        finite = column[np.isfinite(column)]
        if finite.size >= needed + 3 and np.ptp(finite) > 0:
            rates.append(name)
    table = np.array([[float(c.get(rate_name(name), np.nan)) for name in rates] for c in conds],
                     dtype=float).reshape(len(conds), len(rates))
    known = np.all(np.isfinite(table), axis=1)
    if rates and (known.sum() < needed + 3 or np.any(np.ptp(table[known], axis=0) == 0)):
        return (), np.zeros((len(conds), 0)), np.ones(len(conds), dtype=bool)
    return tuple(rates), table[known], known


def _bic_rate_terms(s: Array, design: Array, rate_x: Array) -> NDArray[np.bool_]:
    """Which rate terms each component's expectation takes: forward selection by the Bayesian information
    criterion ``N ln(RSS / N) + p ln N`` over the rows that have their rates.

    Parameters
    ----------
    s : ndarray, shape (N, n)
        Log-factors.
    design : ndarray, shape (N, p)
        The terms every component has (constant, linear and quadratic in the conditions).
    rate_x : ndarray, shape (N, n_rate)
        The candidate rate terms.

    Returns
    -------
    ndarray of bool, shape (n_rate, n)
    """
    n_rows, n_comp = s.shape
    chosen = np.zeros((rate_x.shape[1], n_comp), dtype=bool)

    def bic(j: int, extra: NDArray[np.bool_]) -> float:
        x = np.column_stack([design, rate_x[:, extra]])
        coefficients, _, rank, _ = np.linalg.lstsq(x, s[:, j], rcond=None)
        rss = float(np.sum((s[:, j] - x @ coefficients) ** 2))
        return float(n_rows * np.log(max(rss, 1e-300) / n_rows) + int(rank) * np.log(n_rows))

    for j in range(n_comp):
        current = bic(j, chosen[:, j])
        while not chosen[:, j].all():
            trials = {k: bic(j, chosen[:, j] | (np.arange(len(chosen)) == k)) for k in np.flatnonzero(~chosen[:, j])}
            best = min(trials, key=lambda k: trials[k])
            if trials[best] >= current:
                break
            chosen[best, j], current = True, trials[best]
    return chosen


def twin_size_errors(
    read: FactorEstimator,
    twin: FactorEstimator,
    frfs: Sequence[FRFData],
    *,
    losses: Sequence[float] = TWIN_LOSSES,
    fits: int = TWIN_FITS,
) -> Array:
    """How wrong the monitor reads each component's loss on a twin of the machine (see the module notes).

    ``twin`` has the groups of ``read`` and more (one factor of all the model's dampings, say): it is fitted to up to
    ``fits`` of the healthy FRFs, evenly spread over them, and the median of its factors is the twin. Losses of each
    component of the twin (``losses``, fractions) are then read back through ``read`` against its reading of the
    healthy twin; the errors are noise-free, so they are the model's mismatch alone.

    Parameters
    ----------
    read : FactorEstimator
        The monitor's estimator (one group per component).
    twin : FactorEstimator
        An estimator whose first groups are those of ``read``, followed by the groups that describe the mismatch.
    frfs : sequence of FRFData
        Healthy FRFs holding the configured channels.
    losses : sequence of float
        Relative losses read back (0.1 = 10 % lost).
    fits : int
        Largest number of FRFs the twin is fitted to.

    Returns
    -------
    ndarray, shape (n, n)
        ``[i, j]``: the largest over ``losses`` of ``|read change of i - true change of i| / loss`` for a loss of
        component ``j``.

    Raises
    ------
    DataError
        No FRFs, or ``twin``'s first groups are not ``read``'s.
    """
    n = len(read.names)
    if twin.names[:n] != read.names or not frfs:
        msg = (f"a twin needs healthy FRFs and the groups {list(read.names)} first; got {len(frfs)} FRFs and "
               f"groups {list(twin.names)}")
        raise DataError(msg)
    chosen = [frfs[int(k)] for k in np.unique(np.linspace(0, len(frfs) - 1, min(fits, len(frfs))).round())]
    with warnings.catch_warnings():
        # a probe of the model, not a result: a misfit is what the twin is for, and the errors below are its answer
        warnings.simplefilter("ignore")
        factors = np.median([twin.estimate(f, misfit_ratio=None).log_factor for f in chosen], axis=0)
        freq, _ = read.select(chosen[0])

        def reading(log_factor: Array) -> Array:
            h = twin.frf(log_factor, freq)
            data = FRFData(freq, h, read.inputs, read.outputs)
            return read.estimate(data, factors[:n], misfit_ratio=None).log_factor

        healthy = reading(factors)
        errors = np.zeros((n, n))
        for j in range(n):
            for loss in losses:
                shifted = factors.copy()
                shifted[j] += np.log1p(-loss)
                change = np.expm1(reading(shifted) - healthy)
                truth = np.where(np.arange(n) == j, -loss, 0.0)
                errors[:, j] = np.maximum(errors[:, j], np.abs(change - truth) / loss)
    return errors
