"""The estimator pattern shared by every method, and the bounded least-squares fit most of them end in.

Every estimator follows scikit-learn's rules (STYLE.md): ``__init__`` stores the model and settings only,
``fit(data)`` validates and returns ``self``, learned values end in ``_`` (``estimate_``, ``params_``) and reading
them before ``fit`` raises :class:`~cappe.exceptions.NotFittedError`. The result is a :class:`ParameterEstimate`.
"""

from __future__ import annotations

import warnings
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from cappe._rng import RandomLike, as_generator
from cappe._settings import Settings
from cappe.estimate._result import ParameterEstimate
from cappe.estimate._space import ParameterSpace
from cappe.estimate._uncertainty import LocalUncertainty, jacobian_uncertainty, null_direction_text
from cappe.exceptions import ConvergenceWarning, ModelError, NotFittedError
from cappe.model import NumericModel, Structure

__all__ = ["CostFunction", "Estimator", "Fitted", "fit_least_squares", "honest_intervals",
           "least_squares_fit", "with_noise_variance", "with_residual_tests"]

#: Relative standard error above which an unknown is practically non-identifiable (its 95 % interval spans more
#: than about +-60 % of its value).
PRACTICAL_RELATIVE_STD = 0.3
#: Residuals below this RMS (relative to the data's, which the estimators scale to 1) are an exact fit: rounding,
#: not noise, so there is nothing for a residual test to judge.
_EXACT_FIT_RMS = 1e-8

Array = NDArray[np.float64]
Residuals = Callable[[Array], Array]


@dataclass(frozen=True)
class CostFunction:
    """The cost ``|residuals(p)|^2`` a least-squares method minimized, and where (:meth:`Estimator.cost_slice`).

    Attributes
    ----------
    space : ParameterSpace
        The unknowns the residuals take (SI vectors, ``space.n``); may hold nuisance unknowns after the physical ones.
    residuals : callable
        ``residuals(p)`` -> ndarray (n_obs,).
    centre : ndarray, shape (space.n,)
        The optimum found (SI).
    jacobian : ndarray, shape (n_obs, space.n), optional
        ``d r / d p`` (SI) at the optimum, as the search last evaluated it.
    """

    space: ParameterSpace
    residuals: Residuals
    centre: Array
    jacobian: Array | None = None


@dataclass(frozen=True)
class Fitted:
    """What an estimator's ``_fit`` may return instead of a bare estimate: the estimate and the cost it minimized
    (:func:`least_squares_fit` makes one), kept by :meth:`Estimator.fit` as ``cost_function_``.

    Attributes
    ----------
    estimate : ParameterEstimate
        The result.
    cost : CostFunction or None
        The cost minimized (None where every start failed).
    """

    estimate: ParameterEstimate
    cost: CostFunction | None = None

    def with_estimate(self, estimate: ParameterEstimate) -> Fitted:
        """The same cost with a post-processed estimate (more diagnostics, physical unknowns only ...).

        Parameters
        ----------
        estimate : ParameterEstimate
            The post-processed estimate.

        Returns
        -------
        Fitted
        """
        return replace(self, estimate=estimate)


class Estimator(Settings, ABC):
    """Base class: ``Estimator(model, unknowns, bounds=..., start=..., values=..., rng=...).fit(data)``.

    Parameters
    ----------
    model : NumericModel or Structure
        The physical model whose parameters are estimated.
    unknowns : sequence of str, optional
        Parameters to estimate (default: those marked ``unknown`` in the model file).
    bounds : mapping name -> (lower, upper), optional
        Overrides of the model file's bounds (SI).
    start : mapping name -> value, optional
        Start values (default: the model's values).
    values : mapping name -> value, optional
        Values of the known parameters, when they differ from the model file.
    rng : int, Generator or None
        Seed for every random choice (multi-start points, bootstrap, filters).

    Notes
    -----
    ``get_params()`` returns every ``__init__`` argument by name and ``set_params(**settings)`` changes them for the
    next fit, so ``type(est)(**est.get_params())`` is an unfitted copy. A subclass's ``__init__`` stores its arguments
    unchanged under their own names and nothing else; it validates them in ``fit``.
    """

    #: Name written to ``cappe.estimate/1`` files.
    method: ClassVar[str] = ""

    def __init__(
        self,
        model: NumericModel | Structure,
        unknowns: Sequence[str] | None = None,
        *,
        bounds: Mapping[str, Sequence[float]] | None = None,
        start: Mapping[str, float] | None = None,
        values: Mapping[str, float] | None = None,
        rng: RandomLike = None,
    ) -> None:
        self.model = model
        self.unknowns = unknowns
        self.bounds = bounds
        self.start = start
        self.values = values
        self.rng = rng

    # -- the pattern ------------------------------------------------------------------------------------------
    def fit(self, data: Any) -> Estimator:
        """Estimate the unknowns from ``data``; the result is ``self.estimate_``.

        Parameters
        ----------
        data : TimeData, FRFData, ModalData or as the method documents
            The measurements of the kind the method takes (``cappe.estimate.METHODS[method][2]``: time records,
            FRFs or reference modes), in SI units.

        Returns
        -------
        self

        Raises
        ------
        DataError
            The data are not of the method's kind or do not fit the model (channels, positions, NaN ...).
        ModelError
            The unknowns, bounds or settings break a rule of the model or the method.
        """
        numeric = self.model if isinstance(self.model, NumericModel) else NumericModel(self.model)
        space = ParameterSpace.from_model(
            numeric, self.unknowns, bounds=self.bounds, start=self.start, values=self.values
        )
        self.numeric_ = numeric
        self.space_ = space
        outcome = self._fit(numeric, space, data, as_generator(self.rng))
        fitted = outcome if isinstance(outcome, Fitted) else Fitted(outcome)
        self._cost = fitted.cost
        result = fitted.estimate
        if not result.success:
            verb = "failed its residual tests" if result.diagnostics.get("fit_test") == "failed" else "did not converge"
            warnings.warn(f"{self.method} estimation {verb}: {result.message}", ConvergenceWarning, stacklevel=2)
        self._estimate = result
        return self

    @abstractmethod
    def _fit(
        self, model: NumericModel, space: ParameterSpace, data: Any, rng: np.random.Generator
    ) -> ParameterEstimate | Fitted:
        """The method itself: validate ``data`` and estimate the unknowns of ``space``; methods that end in a
        least-squares search return :class:`Fitted` (from :func:`least_squares_fit`) so that their cost can be
        sliced."""

    @property
    def estimate_(self) -> ParameterEstimate:
        try:
            return self._estimate
        except AttributeError:
            msg = f"{type(self).__name__} is not fitted yet; call fit(data) first"
            raise NotFittedError(msg) from None

    @property
    def params_(self) -> dict[str, float]:
        """``{name: estimate}``."""
        return self.estimate_.parameters

    @property
    def cost_function_(self) -> CostFunction | None:
        """The cost the method minimized (None for methods that do not end in a nonlinear least-squares search)."""
        _ = self.estimate_  # NotFittedError before fit
        return self._cost

    def cost_slice(self, names: Sequence[str], *, n: int = 31, span: float | None = None) -> Any:
        """The method's cost ``|r|^2`` on a grid of two unknowns around the optimum, the others held there.

        Each axis spans ``estimate * (1 +- span)`` clipped to the bounds (log-spaced for log-searched unknowns);
        by default 6 standard errors either side (20 % where the error is undefined), where the cost has risen by
        about 36 noise variances.
        Returns a :class:`cappe.sensitivity.CostLandscape` (``.plot(path)``). Available for the methods that end in a
        nonlinear least-squares fit (two-step, one-step, modal, feature-map, hybrid of those).

        Parameters
        ----------
        names : sequence of two str
            The unknowns on the x and y axes.
        n : int
            Grid points per axis (the cost is evaluated ``n**2`` times).
        span : float, optional
            Relative half-width of each axis (0.1: +-10 % of the estimate); default 6 standard errors.

        Returns
        -------
        CostLandscape
            The cost on the ``(n, n)`` grid (rows along ``names[1]``), in the method's residual units squared.

        Raises
        ------
        NotFittedError
            Before ``fit``.
        ModelError
            The method has no nonlinear cost, or ``names`` are not two of the unknowns.
        """
        from cappe.sensitivity import CostLandscape

        estimate = self.estimate_
        captured = self.cost_function_
        if captured is None:
            msg = f"{self.method}: no nonlinear cost to slice (the method does not end in a least-squares search)"
            raise ModelError(msg)
        space, residuals, centre = captured.space, captured.residuals, captured.centre
        if len(names) != 2 or any(name not in estimate.names for name in names):
            msg = f"cost_slice needs two of the unknowns {list(estimate.names)}; got {list(names)}"
            raise ModelError(msg)
        axes = []
        for name in names:
            k = space.names.index(name)
            std = estimate.std[estimate.names.index(name)]
            half = span if span is not None else (6 * std / abs(centre[k]) if np.isfinite(std) and centre[k] else 0.2)
            lo = max(centre[k] * (1 - half), space.lower[k])
            hi = min(centre[k] * (1 + half), space.upper[k])
            axes.append(np.geomspace(lo, hi, n) if space.log[k] and lo > 0 else np.linspace(lo, hi, n))
        ix, iy = (space.names.index(name) for name in names)
        values = np.empty((n, n))
        for i, yv in enumerate(axes[1]):
            for j, xv in enumerate(axes[0]):
                p = centre.copy()
                p[ix], p[iy] = xv, yv
                r = np.asarray(residuals(p), dtype=float)
                values[i, j] = float(r @ r)
        return CostLandscape((names[0], names[1]), axes[0], axes[1], values, space.full(centre))


def fit_least_squares(
    method: str,
    space: ParameterSpace,
    residuals: Residuals,
    jacobian: Callable[[Array], Array] | None = None,
    *,
    starts: Array | None = None,
    noise_variance: float | None = None,
    diagnostics: Mapping[str, Any] | None = None,
    max_nfev: int | None = None,
    x_scale: Array | str = "jac",
    strategy: str | None = None,
    rng: RandomLike = None,
) -> ParameterEstimate:
    """Bounded nonlinear least squares in the space's internal coordinates, with local uncertainty.

    ``residuals(p)`` and ``jacobian(p)`` (``d r / d p``, shape (n_obs, n)) take SI parameter vectors (n,); the
    search runs in ``u`` (log or scaled, see :class:`ParameterSpace`) with the box bounds handled by the
    trust-region reflective method, from every row of ``starts`` (SI, default the space's start); the lowest
    cost wins. The uncertainty comes from the Jacobian at the optimum (:func:`jacobian_uncertainty`).

    ``strategy`` (``"multistart"``, ``"direct"``, ``"differential-evolution"``, ``"dual-annealing"``) first runs
    that global search of :func:`cappe.optimize.minimize` over the whole box (seeded by ``rng``); its result joins
    the starts of the local fit.

    Parameters
    ----------
    method : str
        Method name written to the estimate (``"one-step"``, ``"modal"`` ...).
    space : ParameterSpace
        The unknowns, their bounds, start and transformation.
    residuals : callable
        ``residuals(p)`` -> ndarray, shape (n_obs,), for an SI parameter vector ``p``, shape (space.n,).
    jacobian : callable, optional
        ``jacobian(p)`` -> ndarray, shape (n_obs, space.n): ``d r / d p`` in SI; default 2-point differences.
    starts : ndarray, shape (n_starts, space.n), optional
        Start vectors (SI); default the space's start.
    noise_variance : float, optional
        Variance of the residuals' noise (residual units squared) for the uncertainty; default estimated from the
        residuals at the optimum.
    diagnostics : mapping, optional
        Extra entries for the estimate's ``diagnostics``.
    max_nfev : int, optional
        Limit of residual evaluations per local search (scipy's default otherwise).
    x_scale : ndarray, shape (space.n,), or "jac"
        Scale of the internal coordinates, as :func:`scipy.optimize.least_squares` takes it.
    strategy : str, optional
        Global search run first over the whole box (see above); default none.
    rng : int, Generator or None
        Seed of the global search.

    Returns
    -------
    ParameterEstimate
        The best start's optimum with its local uncertainty; ``success=False`` with the message where every start
        failed.

    Raises
    ------
    ModelError
        A global search is asked for and an unknown has an infinite bound.
    """
    return least_squares_fit(method, space, residuals, jacobian, starts=starts, noise_variance=noise_variance,
                             diagnostics=diagnostics, max_nfev=max_nfev, x_scale=x_scale, strategy=strategy,
                             rng=rng).estimate


def least_squares_fit(
    method: str,
    space: ParameterSpace,
    residuals: Residuals,
    jacobian: Callable[[Array], Array] | None = None,
    *,
    starts: Array | None = None,
    noise_variance: float | None = None,
    diagnostics: Mapping[str, Any] | None = None,
    max_nfev: int | None = None,
    x_scale: Array | str = "jac",
    strategy: str | None = None,
    rng: RandomLike = None,
    variance_floor: float = 0.0,
) -> Fitted:
    """:func:`fit_least_squares` with the cost it minimized: what an estimator's ``_fit`` returns so that
    :meth:`Estimator.cost_slice` can slice that cost (``cost`` is None where every start failed).

    Parameters
    ----------
    method, space, residuals, jacobian, starts, noise_variance, diagnostics, max_nfev, x_scale, strategy, rng
        As for :func:`fit_least_squares`.
    variance_floor : float
        Least residual variance the uncertainty uses where ``noise_variance`` is not given (residual units
        squared): the precision to which the residuals are computed, so that a fit to noise-free data does not
        claim intervals narrower than the arithmetic that found its optimum.

    Returns
    -------
    Fitted
        The estimate and its :class:`CostFunction`.

    Examples
    --------
    >>> from cappe.model import load_model
    >>> space = ParameterSpace.from_model(load_model("builtin:two-mass-rig"), ["k11", "k22"])
    >>> fitted = least_squares_fit("demo", space, lambda p: np.array([p[0] / 1.38e6 - 1, p[1] / 0.24e6 - 1]))
    >>> fitted.estimate.parameters == fitted.cost.space.mapping(fitted.cost.centre)
    True
    """
    lo, hi = space.internal_bounds()
    candidates = np.atleast_2d(space.start if starts is None else np.asarray(starts, dtype=float))
    global_diag: dict[str, Any] = {}
    if strategy is not None:
        from cappe.optimize import minimize

        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            msg = f"a global search ({strategy}) needs finite bounds for every unknown; got {space.to_dict()}"
            raise ModelError(msg)

        def squares(u: Array) -> Array:
            return np.asarray(residuals(space.from_internal(u)), dtype=float)

        u0 = np.clip(space.to_internal(space.start), lo, hi)
        found = minimize(None, (lo, hi), strategy=strategy, residuals=squares, x0=u0, rng=rng)
        candidates = np.vstack([space.from_internal(found.x)[None, :], candidates])
        global_diag = {"global_search": {"strategy": strategy, "cost": float(found.fun),
                                         "evaluations": int(found.n_evaluations), "success": bool(found.success)}}

    def fun(u: Array) -> Array:
        return np.asarray(residuals(space.from_internal(u)), dtype=float)

    jac: Any = "2-point"
    if jacobian is not None:

        def jac(u: Array) -> Array:  # chain rule: dr/du = dr/dp * dp/du
            return np.asarray(jacobian(space.from_internal(u)), dtype=float) * space.value_jacobian(u)

    best: Any = None
    runs: list[dict[str, Any]] = []
    for p0 in candidates:
        u0 = np.clip(space.to_internal(p0), lo, hi)
        try:
            sol = least_squares(fun, u0, jac=jac, bounds=(lo, hi), x_scale=x_scale, max_nfev=max_nfev,
                                method="trf")
        except (ValueError, np.linalg.LinAlgError) as exc:
            runs.append({"start": space.mapping(p0), "success": False, "message": str(exc)})
            continue
        runs.append({"start": space.mapping(p0), "cost": float(2 * sol.cost), "success": bool(sol.success),
                     "evaluations": int(sol.nfev)})
        if best is None or sol.cost < best.cost:
            best = sol
    if best is None:
        return Fitted(ParameterEstimate.failed(method, space.names, "every start failed: " + str(runs[-1]["message"]),
                                               {"runs": runs, **(diagnostics or {})}))
    p = space.from_internal(best.x)
    jac_p = best.jac / space.value_jacobian(best.x)  # back to d r / d p in SI
    if noise_variance is None and variance_floor > 0:
        dof = max(best.fun.size - space.n, 1)
        noise_variance = max(float(best.fun @ best.fun) / dof, variance_floor)
    unc = jacobian_uncertainty(names=space.names, values=p, jacobian=jac_p, residuals=best.fun,
                               noise_variance=noise_variance)
    at_bound = [
        n for n, a, b, u in zip(space.names, lo, hi, best.x, strict=True) if np.isclose(u, a) or np.isclose(u, b)
    ]
    diag: dict[str, Any] = {
        "iterations": int(best.nfev),
        "evaluations": sum(int(r.get("evaluations", 0)) for r in runs),
        "starts": len(candidates),
        "start": space.mapping(candidates[0]),
        "bounds": {n: [float(a), float(b)] for n, a, b in zip(space.names, space.lower, space.upper, strict=True)},
        "at_bound": at_bound,
        **global_diag,
        **(diagnostics or {}),
    }
    if len(runs) > 1:
        diag["runs"] = runs
    success = bool(best.success) and best.status > 0
    message = str(best.message)
    if at_bound:
        message += f"; estimate at a bound for {at_bound}"
    unc, practical = honest_intervals(space, unc, at_bound)
    if practical:
        diag["practically_non_identifiable"] = practical
        diag["weakest_direction"] = _weakest_direction(space, unc)
    estimate = ParameterEstimate.from_uncertainty(
        method, unc, cost=float(2 * best.cost), success=success, message=message, diagnostics=diag
    )
    return Fitted(estimate, CostFunction(space, residuals, p, np.asarray(jac_p, dtype=float)))


def honest_intervals(space: ParameterSpace, unc: LocalUncertainty, at_bound: Sequence[str]) -> tuple[
        LocalUncertainty, dict[str, str]]:
    """Intervals in the search's coordinates, clipped to the bounds, and practical identifiability.

    For an unknown searched in ``log p`` the 95 % interval is ``p exp(+-t std / p)`` (the Gauss-Newton interval
    of ``log p``, whose std is ``std / p`` to first order): it never includes zero or a negative value. Every
    interval is clipped to the unknown's bounds (the truth lies inside them). An unknown whose relative standard
    error exceeds :data:`PRACTICAL_RELATIVE_STD` or that sits at a bound is *practically* non-identifiable: the
    data leave it free over a range comparable to its value. It is flagged (``identifiable`` False) with its reason.

    Parameters
    ----------
    space : ParameterSpace
        The unknowns (their bounds and which are searched in log).
    unc : LocalUncertainty
        The Gauss-Newton uncertainty at the optimum.
    at_bound : sequence of str
        Unknowns at a bound.

    Returns
    -------
    LocalUncertainty
        With the new intervals and flags.
    dict
        ``{name: reason}`` of the practically non-identifiable unknowns.
    """
    from scipy import stats

    p, std = unc.values, unc.std
    t = float(stats.t.ppf(0.975, unc.dof))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        rel = np.where(p != 0, std / np.abs(p), np.inf)
        lo = np.where(space.log, p * np.exp(-t * rel), p - t * std)
        hi = np.where(space.log, p * np.exp(t * rel), p + t * std)
    finite = np.isfinite(std)
    lo = np.where(finite, np.maximum(lo, space.lower), np.nan)
    hi = np.where(finite, np.minimum(hi, space.upper), np.nan)
    practical: dict[str, str] = {}
    for k, name in enumerate(space.names):
        if not unc.identifiable[k]:
            continue
        if name in at_bound:
            practical[name] = "at a bound"
        elif finite[k] and rel[k] > PRACTICAL_RELATIVE_STD:
            practical[name] = f"relative std {100 * rel[k]:.3g} % > {100 * PRACTICAL_RELATIVE_STD:g} %"
    flags = np.array([bool(f) and n not in practical for n, f in zip(space.names, unc.identifiable, strict=True)])
    return replace(unc, ci95=np.column_stack([lo, hi]), identifiable=flags), practical


def with_noise_variance(estimate: ParameterEstimate, cost: CostFunction, noise_variance: float) -> ParameterEstimate:
    """The estimate with its Gauss-Newton uncertainty recomputed for another residual variance.

    ``cov = noise_variance (J^T J)^-1`` from the Jacobian the search last evaluated at the optimum, then
    :func:`honest_intervals` (intervals in the search's coordinates, practical identifiability) as
    :func:`least_squares_fit` does it.

    Parameters
    ----------
    estimate : ParameterEstimate
        The estimate of a least-squares fit (values at ``cost.centre``).
    cost : CostFunction
        Its cost, with the Jacobian at the optimum.
    noise_variance : float
        Variance of the residuals (residual units squared).

    Returns
    -------
    ParameterEstimate
        Same values and cost; new std, intervals, correlation, identifiability and practical-identifiability notes.
    """
    if cost.jacobian is None:  # pragma: no cover - least_squares_fit always keeps the Jacobian
        msg = "internal error: no Jacobian at the optimum"
        raise RuntimeError(msg)
    space = cost.space
    r = np.asarray(cost.residuals(cost.centre), dtype=float)
    unc = jacobian_uncertainty(names=space.names, values=cost.centre, jacobian=cost.jacobian, residuals=r,
                               noise_variance=noise_variance)
    unc, practical = honest_intervals(space, unc, list(estimate.diagnostics.get("at_bound", [])))
    diagnostics = {k: v for k, v in estimate.diagnostics.items()
                   if k not in ("practically_non_identifiable", "weakest_direction")}
    if practical:
        diagnostics["practically_non_identifiable"] = practical
        diagnostics["weakest_direction"] = _weakest_direction(space, unc)
    return replace(estimate, std=unc.std, ci95=unc.ci95, correlation=unc.correlation, identifiable=unc.identifiable,
                   combinations=unc.combinations, diagnostics=diagnostics)


def _weakest_direction(space: ParameterSpace, unc: LocalUncertainty) -> dict[str, Any]:
    """The least determined combination of relative changes (largest eigenvalue of the relative covariance)."""
    scale = np.where(unc.values != 0, np.abs(unc.values), 1.0)
    rel_cov = unc.covariance / np.outer(scale, scale)
    rel_cov = np.where(np.isfinite(rel_cov), rel_cov, 0.0)
    eigval, eigvec = np.linalg.eigh(rel_cov)
    return {"combination": null_direction_text(space.names, eigvec[:, -1]),
            "relative_std": float(np.sqrt(max(eigval[-1], 0.0)))}


def with_residual_tests(
    estimate: ParameterEstimate,
    residuals: Sequence[Array],
    inputs: Sequence[Array],
    output_names: Sequence[str],
    input_names: Sequence[str],
) -> ParameterEstimate:
    """The estimate with MATLAB-``resid`` tests of its time-domain output errors (:func:`residual_analysis`).

    ``diagnostics["residual_analysis"]`` holds the correlations, bounds and p-values, ``diagnostics["warnings"]``
    one line per failed test. Residuals that correlate with an input mean the model does not explain the data:
    ``success`` becomes False (``diagnostics["fit_test"] = "failed"``) and the message says why. Coloured but
    input-independent residuals only warn. An exact fit (residual RMS below 1e-8 of the data's) is not tested.

    Parameters
    ----------
    estimate : ParameterEstimate
        The fitted estimate.
    residuals : sequence of ndarray, shape (n_samples, n_out)
        Output errors per record (scaled to the outputs' RMS).
    inputs : sequence of ndarray, shape (n_samples, n_in)
        Inputs per record.
    output_names, input_names : sequence of str
        Channel names.

    Returns
    -------
    ParameterEstimate
    """
    from cappe.identify._residual_analysis import residual_analysis

    diagnostics = dict(estimate.diagnostics)
    warns = list(diagnostics.get("warnings", []))
    rms = float(np.sqrt(np.mean(np.concatenate([np.ravel(r) for r in residuals]) ** 2)))
    if not rms > _EXACT_FIT_RMS:
        diagnostics["residual_analysis"] = {"exact_fit": True, "rms": rms}
        return replace(estimate, diagnostics=diagnostics)
    analysis = residual_analysis(residuals=list(residuals), inputs=list(inputs), output_names=output_names,
                                 input_names=input_names)
    diagnostics["residual_analysis"] = analysis.to_dict()
    warns += analysis.warnings()
    diagnostics["warnings"] = warns
    if analysis.passed:
        diagnostics.setdefault("fit_test", "passed")
        return replace(estimate, diagnostics=diagnostics)
    diagnostics["fit_test"] = "failed"
    message = "the residuals correlate with the inputs: the model does not explain the data"
    if estimate.message:
        message = f"{message} ({estimate.message})"
    return replace(estimate, success=False, message=message, diagnostics=diagnostics)
