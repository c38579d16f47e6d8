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
from datetime import UTC, datetime
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cappe.exceptions import DataError
from cappe.systems.frf import FRFData

if TYPE_CHECKING:
    from cappe.monitor._estimation import FactorEstimator

__all__ = ["BASELINE_FORMAT", "BLOCK", "IMPLAUSIBLE", "LEARNED_MARGIN", "SIZE_SCALE_FLOOR", "TWIN_LOSSES",
           "Baseline", "derived_resolution", "learn_baseline", "twin_size_errors"]

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
    coefficients : ndarray, shape (1 + 2 n_cond, n)
        Constant, linear and quadratic terms of each component's expected log-factor.
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

    def _design(self, conditions: Mapping[str, float] | None) -> Array:
        values = []
        for name in self.conditions:
            if conditions is None or name not in conditions:
                msg = (f"the baseline depends on the operating condition '{name}', which the measurement does not "
                       f"give (conditions {dict(conditions or {})})")
                raise DataError(msg)
            values.append(float(conditions[name]))
        x = (np.asarray(values, dtype=float) - self.center) / self.spread
        return np.concatenate([[1.0], x, x**2])

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
        linear, quadratic = self.coefficients[1:1 + m], self.coefficients[1 + m:]
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
            return cls(
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
            )
        except (KeyError, TypeError, ValueError) as exc:
            msg = f"baseline is malformed: {type(exc).__name__} {exc}"
            raise DataError(msg) from exc

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
        regressors (a quadratic in each).
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
    common = sorted(set.intersection(*(set(c) for c in conds))) if conds else []
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
    residual = s - design @ coefficients
    dof = max(n_meas - design.shape[1], 1)
    covariance = residual.T @ residual / dof
    if resolution is None:
        resolution = derived_resolution(residual, design)
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
    )


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
