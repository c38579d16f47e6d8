"""Feature maps: parameters from measured modal features through precomputed functional relationships.

Thesis 3.6.5 and 5.4.4: where a feature of the measured signals (a natural frequency, a damping ratio) depends on
a physical parameter in a known way, the parameter can be read off a map of the feature against the parameter.
The map is computed from the model: the modal engine evaluates the features on a grid (one or two unknowns) or
a scrambled Sobol sample (more unknowns) of the parameter box, in one batched call with the modes tracked
against those at the start parameters (so that "mode 2" is the same physical mode across the map, through
veering and crossings). The map is inverted by weighted least squares on a smooth surrogate of it:

* one or two unknowns: cubic interpolation on the grid (``scipy.interpolate.RegularGridInterpolator``);
* more: a thin-plate-spline radial basis function interpolant (``scipy.interpolate.RBFInterpolator``) of the
  sample, or a quadratic response surface (``surrogate="quadratic"``).

The search starts from the map points nearest to the measurement (in noise-weighted feature distance) and runs
bounded trust-region least squares in the space's internal coordinates (:func:`fit_least_squares`). The
surrogate's own error is measured by exact model evaluations at and around the estimate (half a map spacing) and
added to the feature noise, and the fit repeated, so the standard errors (from the surrogate Jacobian) are honest
about a coarse map as well as about noisy features; its error over the whole box is recorded as well. Finally the
model itself is evaluated at the estimate: features it misses by more than the noise allows (chi-square,
p = 1e-3) are reported as out of reach within the bounds (``success`` false); a single feature outside the
map's whole range is a :class:`~cappe.exceptions.DataError`.

The diagnostics keep the map (``samples`` in SI, ``features``, ``feature_names``, the ``grid`` axes) so that the
thesis's frequency/damping-against-parameter plots (Fig. 5.30) can be drawn from a result file.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray
from scipy import stats
from scipy.interpolate import RBFInterpolator, RegularGridInterpolator
from scipy.stats import qmc

from cappe._rng import RandomLike
from cappe.estimate._base import Estimator, Fitted, least_squares_fit
from cappe.estimate._modal_updating import check_finite_modes
from cappe.estimate._space import ParameterSpace
from cappe.exceptions import DataError, ModelError
from cappe.modal import ModalEngine
from cappe.model import NumericModel, Structure
from cappe.systems.modal import ModalData, ModalDataSet

__all__ = ["FeatureMapEstimator"]

Array = NDArray[np.float64]

_FEATURES = ("frequency", "damping")
#: Grid points per unknown (one / two unknowns) and Sobol points per unknown (more) by default.
_GRID = {1: 41, 2: 21}
_SOBOL_PER_UNKNOWN = 128
#: Extra model evaluations at random points of the box that measure the surrogate's error.
_VALIDATION = 64
#: Map points tried as starts of the least-squares search.
_STARTS = 4
#: Tail probability of the misfit below which the measurement is taken as outside the map.
_MISFIT_ALPHA = 1e-3


@dataclass(frozen=True)
class _Measured:
    names: tuple[str, ...]  # feature labels
    values: Array  # (n_feat,)
    sigma: Array  # (n_feat,) noise standard deviation
    kind: tuple[str, ...]  # "frequency" | "damping" per feature
    units: tuple[str, ...]


class FeatureMapEstimator(Estimator):
    """Parameters from measured natural frequencies and damping ratios via a precomputed feature map.

    ``FeatureMapEstimator(model, unknowns, ...).fit(data)`` with ``data`` a :class:`~cappe.systems.ModalData`
    (``cappe.modal/1``: frequencies and damping ratios at one or more axis positions) or a mapping
    ``{"frequency": [...], "damping": [...], "position": {...}}`` for one position.

    Parameters
    ----------
    model, unknowns, bounds, start, values, rng
        See :class:`~cappe.estimate.Estimator`. The bounds span the map and must be finite; ``rng`` seeds the
        Sobol sample and the validation points.
    features : sequence of {"frequency", "damping"}, optional
        Features used. Default: frequencies, plus damping ratios where every measured ratio is > 0.
    modes : sequence of int, optional
        Model mode (0-based, ascending at the start parameters, tracked over the map) of each measured mode.
        Default: the measured modes are the lowest ones, in order.
    resolution : int, optional
        Grid points per unknown for one or two unknowns (default 41 / 21).
    samples : int, optional
        Sobol sample size for three or more unknowns (default 128 per unknown, rounded up to a power of 2).
    surrogate : {"auto", "grid", "rbf", "quadratic"}
        Map interpolant; ``"auto"``: the grid for one or two unknowns, the RBF otherwise.
    frequency_noise, damping_noise : float
        Standard deviations of the measured frequencies and damping ratios as fractions of their values
        (defaults 0.5 % and 10 %, typical of experimental modal analysis).

    Examples
    --------
    >>> from cappe.model import NumericModel, load_model
    >>> nm = NumericModel(load_model("builtin:two-mass-rig"))
    >>> truth = nm.system({"k11": 1.6e6, "k22": 0.3e6}).modes("first-order")
    >>> data = {"frequency": truth.frequency}
    >>> est = FeatureMapEstimator(nm, ["k11", "k22"], resolution=15).fit(data)
    >>> {k: round(v / 1e6, 3) for k, v in est.params_.items()}
    {'k11': 1.6, 'k22': 0.3}
    """

    method: ClassVar[str] = "feature-map"

    def __init__(
        self,
        model: NumericModel | Structure,
        unknowns: Sequence[str] | None = None,
        *,
        bounds: Mapping[str, Sequence[float]] | None = None,
        start: Mapping[str, float] | None = None,
        values: Mapping[str, float] | None = None,
        rng: RandomLike = None,
        features: Sequence[str] | None = None,
        modes: Sequence[int] | None = None,
        resolution: int | None = None,
        samples: int | None = None,
        surrogate: str = "auto",
        frequency_noise: float = 0.005,
        damping_noise: float = 0.1,
    ) -> None:
        super().__init__(model, unknowns, bounds=bounds, start=start, values=values, rng=rng)
        self.features = features
        self.modes = modes
        self.resolution = resolution
        self.samples = samples
        self.surrogate = surrogate
        self.frequency_noise = frequency_noise
        self.damping_noise = damping_noise

    # -- validation ---------------------------------------------------------------------------------------------
    def _check(self, space: ParameterSpace) -> str:
        if self.surrogate not in ("auto", "grid", "rbf", "quadratic"):
            msg = f"surrogate must be 'auto', 'grid', 'rbf' or 'quadratic'; got {self.surrogate!r}"
            raise DataError(msg)
        kind = self.surrogate if self.surrogate != "auto" else ("grid" if space.n <= 2 else "rbf")
        if kind == "grid" and space.n > 2:
            msg = f"a grid map takes one or two unknowns; got {space.n} ({list(space.names)}): use 'rbf'"
            raise DataError(msg)
        unbounded = [n for n, lo, hi in zip(space.names, space.lower, space.upper, strict=True)
                     if not (np.isfinite(lo) and np.isfinite(hi))]
        if unbounded:
            msg = f"a feature map needs finite bounds; {unbounded} have none (give bounds=...)"
            raise ModelError(msg)
        for what, value in (("frequency_noise", self.frequency_noise), ("damping_noise", self.damping_noise)):
            if not (np.isfinite(value) and value > 0):
                msg = f"{what} must be a fraction > 0; got {value!r}"
                raise DataError(msg)
        sizes: tuple[tuple[str, int | None, int], ...] = (("resolution", self.resolution, 4),
                                                           ("samples", self.samples, 2 * space.n + 2))
        for what, size, least in sizes:
            if size is not None and (isinstance(size, bool) or not isinstance(size, int) or size < least):
                msg = f"{what} must be an integer >= {least}; got {size!r}"
                raise DataError(msg)
        return kind

    def _data(self, data: Any) -> ModalData:
        if isinstance(data, ModalData):
            return data
        if isinstance(data, Mapping):
            if "frequency" not in data:
                msg = f"feature data must give 'frequency' (Hz); got keys {sorted(data)}"
                raise DataError(msg)
            freq = np.atleast_1d(np.asarray(data["frequency"], dtype=float))
            damping = np.atleast_1d(np.asarray(data.get("damping", np.zeros(freq.size)), dtype=float))
            if freq.ndim != 1 or damping.shape != freq.shape:
                msg = (f"feature data 'frequency' and 'damping' must be flat lists of equal length; got shapes "
                       f"{freq.shape} and {damping.shape}")
                raise DataError(msg)
            bad = ~np.isfinite(freq) | (freq <= 0) | ~np.isfinite(damping) | (damping < 0)
            if np.any(bad):
                msg = (f"feature data need finite frequencies > 0 Hz and damping ratios >= 0; got frequency "
                       f"{freq.tolist()}, damping {damping.tolist()}")
                raise DataError(msg)
            position = {str(k): float(v) for k, v in dict(data.get("position", {})).items()}
            return ModalData((), (ModalDataSet(position, freq, damping, np.zeros((0, freq.size), complex)),))
        msg = f"feature-map estimation needs ModalData or a mapping of features; got {type(data).__name__}"
        raise DataError(msg)

    def _measured(self, modal: ModalData, n_dof: int) -> tuple[_Measured, list[Any]]:
        if not modal.sets:
            msg = "modal data hold no sets"
            raise DataError(msg)
        for k, data_set in enumerate(modal.sets):
            check_finite_modes(f"modal data set {k} (position {data_set.position})", data_set, shapes=False)
        features = list(self.features) if self.features is not None else None
        if features is not None:
            bad = [f for f in features if f not in _FEATURES]
            if bad or not features:
                msg = f"features must be a non-empty selection of {list(_FEATURES)}; got {list(self.features or [])}"
                raise DataError(msg)
        else:
            features = ["frequency"]
            if all(np.all(s.damping > 0) for s in modal.sets):
                features.append("damping")
        if "damping" in features and not all(np.all(s.damping > 0) for s in modal.sets):
            msg = "damping features need measured damping ratios > 0 in every set; some are 0"
            raise DataError(msg)
        names, values, sigma, kinds, units, plan = [], [], [], [], [], []
        single = len(modal.sets) == 1
        for k, data_set in enumerate(modal.sets):
            m = data_set.n_modes
            modes = list(self.modes) if self.modes is not None else list(range(m))
            if len(modes) != m:
                msg = f"modes must name one model mode per measured mode; set {k} has {m} modes, modes has {len(modes)}"
                raise DataError(msg)
            if any(isinstance(r, bool) or not isinstance(r, (int, np.integer)) or not 0 <= r < n_dof for r in modes) \
                    or len(set(modes)) != len(modes):
                msg = f"modes must be distinct integers from 0 to {n_dof - 1} (model modes); got {modes}"
                raise DataError(msg)
            suffix = "" if single else f"[set {k}]"
            for feature in features:
                for r, mode in enumerate(modes):
                    value = float(data_set.frequency[r] if feature == "frequency" else data_set.damping[r])
                    label = "f" if feature == "frequency" else "zeta"
                    names.append(f"{label}{mode + 1}{suffix}")
                    values.append(value)
                    noise = self.frequency_noise if feature == "frequency" else self.damping_noise
                    sigma.append(noise * value)
                    kinds.append(feature)
                    units.append("Hz" if feature == "frequency" else "")
            plan.append((data_set.position, modes, features))
        return _Measured(tuple(names), np.array(values), np.array(sigma), tuple(kinds), tuple(units)), plan

    # -- the map ---------------------------------------------------------------------------------------------------
    def _evaluate(self, engine: ModalEngine, space: ParameterSpace, u: Array, plan: list[Any],
                  references: list[Any]) -> Array:
        """Features (B, n_feat) at internal points u (B, n)."""
        full = space.full(space.from_internal(u))
        parts = []
        for (position, modes, features), ref in zip(plan, references, strict=True):
            batch = engine.evaluate(full, position or None, track=ref)
            for feature in features:
                parts.append((batch.frequency if feature == "frequency" else batch.damping)[:, modes])
        return np.concatenate(parts, axis=1)

    def _fit(
        self, model: NumericModel, space: ParameterSpace, data: Any, rng: np.random.Generator
    ) -> Fitted:
        kind = self._check(space)
        modal = self._data(data)
        measured, plan = self._measured(modal, model.n_dof)
        engine = ModalEngine(model, sensors="dofs")
        try:
            references = [engine.reference(space.full(space.start), position or None) for position, _, _ in plan]
        except ModelError as exc:
            msg = f"modal data positions do not fit model '{model.structure.name}': {exc}"
            raise DataError(msg) from exc
        lo, hi = space.internal_bounds()
        n = space.n

        def evaluate(u: Array) -> Array:
            return self._evaluate(engine, space, np.atleast_2d(u), plan, references)

        # the map: a grid for one or two unknowns, a scrambled Sobol sample otherwise
        grid_axes: list[Array] = []
        if kind == "grid":
            size = self.resolution or _GRID[n]
            grid_axes = [np.linspace(a, b, size) for a, b in zip(lo, hi, strict=True)]
            mesh = np.meshgrid(*grid_axes, indexing="ij")
            points = np.column_stack([g.ravel() for g in mesh])
        else:
            count = self.samples or _SOBOL_PER_UNKNOWN * n
            unit = qmc.Sobol(d=n, scramble=True, rng=rng).random_base2(int(np.ceil(np.log2(count))))
            points = lo + unit * (hi - lo)
        features = evaluate(points)
        surrogate = _surrogate(kind, points, features, grid_axes, lo, hi)
        # the surrogate's error over the box (for the record) and, below, near the estimate (joins the noise)
        check = lo + rng.random((_VALIDATION, n)) * (hi - lo)
        box_error = np.sqrt(np.mean((surrogate(check) - evaluate(check)) ** 2, axis=0))
        sigma = measured.sigma
        # a feature outside the range the map reaches cannot be matched by any parameters within the bounds
        low, high = features.min(axis=0), features.max(axis=0)
        slack = 3 * np.sqrt(sigma**2 + box_error**2)
        outside = np.flatnonzero((measured.values < low - slack) | (measured.values > high + slack))
        if outside.size:
            j = int(outside[0])
            unit_txt = f" {measured.units[j]}" if measured.units[j] else ""
            msg = (
                f"measured {measured.kind[j]} {measured.names[j]} = {measured.values[j]:.6g}{unit_txt} lies outside "
                f"the feature map's range [{low[j]:.6g}, {high[j]:.6g}]{unit_txt} for {list(space.names)} within "
                f"their bounds; widen the bounds, choose other unknowns or check the mode pairing (modes=...)"
            )
            raise DataError(msg)

        def weighted(scale: Array) -> Callable[[Array], Array]:
            def residuals(p: Array) -> Array:
                return np.asarray((surrogate(space.to_internal(p)[None, :])[0] - measured.values) / scale, dtype=float)

            return residuals

        distance = np.sum(((features - measured.values) / sigma) ** 2, axis=1)
        starts = space.from_internal(points[np.argsort(distance)[: _STARTS]])
        first = least_squares_fit(self.method, space, weighted(sigma), None, starts=starts, noise_variance=1.0)
        estimate = first.estimate
        if not np.all(np.isfinite(estimate.values)):
            return first
        # the surrogate's error near the estimate (at it and half a map spacing around it, from exact model
        # evaluations) joins the feature noise; the fit is repeated with these weights from the estimate
        spacing = (hi - lo) / (np.array([ax.size - 1 for ax in grid_axes]) if grid_axes else
                               points.shape[0] ** (1.0 / n))
        u_hat = space.to_internal(estimate.values)
        near = np.clip(np.vstack([u_hat, u_hat + 0.5 * np.diag(spacing), u_hat - 0.5 * np.diag(spacing)]), lo, hi)
        error = np.sqrt(np.mean((surrogate(near) - evaluate(near)) ** 2, axis=0))
        sigma = np.sqrt(measured.sigma**2 + error**2)
        diagnostics: dict[str, Any] = {
            "map": {
                "kind": "grid" if kind == "grid" else "sobol",
                "names": list(space.names),
                "samples": space.from_internal(points),
                "features": features,
                "feature_names": list(measured.names),
                "grid": [np.where(space.log[i], np.exp(ax), ax * space.scale[i]) for i, ax in enumerate(grid_axes)],
                "positions": [dict(position) for position, _, _ in plan],
            },
            "surrogate": {"kind": {"grid": "cubic grid interpolation", "rbf": "thin-plate-spline RBF",
                                   "quadratic": "quadratic response surface"}[kind],
                          "points": int(points.shape[0]),
                          "error": {f: float(e) for f, e in zip(measured.names, error, strict=True)},
                          "error_box": {f: float(e) for f, e in zip(measured.names, box_error, strict=True)}},
            "measured": {f: float(v) for f, v in zip(measured.names, measured.values, strict=True)},
            "sigma": {f: float(v) for f, v in zip(measured.names, sigma, strict=True)},
            "model_evaluations": int(points.shape[0] + _VALIDATION + near.shape[0]),
        }
        refit = least_squares_fit(self.method, space, weighted(sigma), None, starts=estimate.values[None, :],
                                  noise_variance=1.0, diagnostics=diagnostics)
        estimate = refit.estimate
        # the check: the model itself (not the surrogate) at the estimate must reproduce the measured features
        # within their noise; otherwise they are out of reach within the bounds (or the surrogate misled the search)
        u_hat = space.to_internal(estimate.values)
        fitted = surrogate(u_hat[None, :])[0]
        exact = evaluate(u_hat)[0]
        misfit = float(np.sum(((exact - measured.values) / measured.sigma) ** 2))
        dof = max(measured.values.size - n, 1)
        limit = float(stats.chi2.isf(_MISFIT_ALPHA, dof))
        diagnostics = {**estimate.diagnostics,
                       "fitted": {f: float(v) for f, v in zip(measured.names, exact, strict=True)},
                       "surrogate_fitted": {f: float(v) for f, v in zip(measured.names, fitted, strict=True)},
                       "misfit": misfit, "misfit_limit": limit}
        # the noise is known (given fractions and the measured surrogate error): normal, not Student t, intervals
        z = float(stats.norm.ppf(0.975))
        ci95 = np.column_stack([estimate.values - z * estimate.std, estimate.values + z * estimate.std])
        success, message = estimate.success, estimate.message
        if misfit > limit:
            worst = int(np.argmax(np.abs(exact - measured.values) / measured.sigma))
            success = False
            message = (
                f"the measured features are not reached within the bounds: at the estimate the model misses them by "
                f"a weighted misfit of {misfit:.3g} > {limit:.3g} (chi-square, {dof} dof, p = {_MISFIT_ALPHA:g}), "
                f"worst {measured.names[worst]} = {exact[worst]:.6g} against {measured.values[worst]:.6g} measured; "
                f"{message}"
            )
        return refit.with_estimate(dataclasses.replace(estimate, ci95=ci95, success=success, message=message,
                                                       diagnostics=diagnostics))


def _surrogate(kind: str, points: Array, features: Array, axes: list[Array], lo: Array,
               hi: Array) -> Callable[[Array], Array]:
    """An interpolant of the map in internal coordinates: (B, n) -> (B, n_feat)."""
    if kind == "grid":
        shape = tuple(ax.size for ax in axes)
        table = features.reshape(*shape, features.shape[1])
        interp = RegularGridInterpolator(tuple(axes), table, method="cubic", bounds_error=False, fill_value=None)

        def on_grid(u: Array) -> Array:
            return np.asarray(interp(np.clip(u, lo, hi)), dtype=float)

        return on_grid
    unit = (points - lo) / (hi - lo)
    if kind == "rbf":
        rbf = RBFInterpolator(unit, features, kernel="thin_plate_spline", degree=1)

        def radial(u: Array) -> Array:
            return np.asarray(rbf((np.asarray(u) - lo) / (hi - lo)), dtype=float)

        return radial
    coef, *_ = np.linalg.lstsq(_quadratic_terms(unit), features, rcond=None)

    def quadratic(u: Array) -> Array:
        return np.asarray(_quadratic_terms((np.asarray(u) - lo) / (hi - lo)) @ coef, dtype=float)

    return quadratic


def _quadratic_terms(x: Array) -> Array:
    """1, x_i, x_i x_j (i <= j) for rows of x (B, n)."""
    n = x.shape[1]
    cols = [np.ones(x.shape[0])] + [x[:, i] for i in range(n)]
    cols += [x[:, i] * x[:, j] for i in range(n) for j in range(i, n)]
    return np.column_stack(cols)
