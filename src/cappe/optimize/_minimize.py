"""Bounded minimization with a choice of global search strategies.

The box is handled natively by every strategy (SLSQP and the trust-region reflective least-squares method keep
their iterates inside it; DIRECT, differential evolution and dual annealing sample only inside it), and the
objective is never evaluated outside it. There are no penalty functions: thesis section 4.3 shows how a penalty
wall trapped its minimizer. Transform bounded positive quantities before calling (``cappe.estimate.ParameterSpace``
searches in ``log p``); the bounds here are in those optimizer coordinates.

Strategies
----------
``"multistart"``
    Local searches from ``x0`` (if given) and ``n_starts`` scrambled-Sobol' (or Latin-hypercube) points in the box:
    SLSQP on ``fun``, or the trust-region reflective least-squares method when ``residuals`` are given. The end
    points are clustered into distinct local minima (:attr:`OptimizationResult.minima`), and the neighbourhood of
    each is searched once more so that saddle points where a gradient method stopped are not reported as minima.
``"least-squares"``
    The same machinery with the least-squares solver only, from ``x0`` (default the box centre) plus ``n_starts``
    sampled points (default none): the plain local fit.
``"direct"``
    DIRECT (Jones et al. 1993; ``scipy.optimize.direct``), the modern, deterministic form of the adaptive grid
    refinement the thesis used (section 4.3), then a local polish. ``x0`` and ``rng`` are not used. The original,
    globally balanced DIRECT is the default (``options={"locally_biased": True}`` gives the faster DIRECT-L, meant
    for few local minima), without scipy's volume stopping rule (``vol_tol=0``; it ends searches in many
    variables early), so it stops on ``len_tol`` or ``maxfun`` (default 1000 n).
``"differential-evolution"``
    ``scipy.optimize.differential_evolution`` (seeded) with ``x0`` in the first population, then a local polish.
    With ``vectorized=True`` a generation is evaluated in one call.
``"dual-annealing"``
    ``scipy.optimize.dual_annealing`` (seeded; L-BFGS-B local steps that use ``jac``), then a local polish.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import optimize as sopt
from scipy.stats import qmc

from cappe._rng import RandomLike, as_generator
from cappe.exceptions import ConvergenceWarning, DataError

__all__ = ["STRATEGIES", "LocalMinimum", "OptimizationResult", "SearchRecord", "minimize"]

Array = NDArray[np.float64]
Objective = Callable[[Array], Any]

STRATEGIES = ("multistart", "direct", "differential-evolution", "dual-annealing", "least-squares")
"""Names accepted by ``minimize(strategy=...)``."""

_GLOBAL_OPTIONS: dict[str, tuple[str, ...]] = {
    "direct": ("eps", "maxfun", "maxiter", "locally_biased", "f_min", "f_min_rtol", "vol_tol", "len_tol"),
    "differential-evolution": ("strategy", "maxiter", "popsize", "tol", "mutation", "recombination", "init", "atol",
                               "updating"),
    "dual-annealing": ("maxiter", "initial_temp", "restart_temp_ratio", "visit", "accept", "maxfun",
                       "no_local_search"),
}
_LOCAL_OPTIONS = ("local_maxiter",)
_POLISH_SHARE = 0.8  # share of max_evaluations the global phase may use when a polish follows


def _finite_or_none(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


@dataclass(frozen=True)
class SearchRecord:
    """One stage of a search: a local search from a start, or the global phase of a global strategy.

    Attributes
    ----------
    stage : str
        ``"local"`` (a multi-start local search), ``"check"`` (a search of the neighbourhood of a local end point,
        see ``check_minima``), ``"restart"`` (a local search from a lower point a check found), ``"global"``
        (DIRECT, differential evolution or dual annealing) or ``"polish"`` (the local search from the global
        phase's best point).
    method : str
        ``"SLSQP"``, ``"TRF"`` (trust-region reflective least squares) or the global strategy's name.
    start : ndarray, shape (n,) or None
        Start point (None for a global phase without ``x0``).
    x : ndarray, shape (n,)
        End point.
    fun : float
        Objective at ``x`` (``inf`` when the search failed before producing a point).
    success : bool
        The method's own convergence verdict.
    n_evaluations, n_iterations : int
        Objective (or residual) evaluations, finite-difference ones included, and iterations of this stage.
    message : str
        The method's termination message.

    Examples
    --------
    >>> r = SearchRecord("local", "SLSQP", np.zeros(1), np.ones(1), 0.5, True, 12, 4, "ok")
    >>> r.to_dict()["x"]
    [1.0]
    """

    stage: str
    method: str
    start: Array | None
    x: Array
    fun: float
    success: bool
    n_evaluations: int
    n_iterations: int
    message: str

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (non-finite values become None)."""
        return {
            "stage": self.stage,
            "method": self.method,
            "start": None if self.start is None else [float(v) for v in self.start],
            "x": [float(v) for v in self.x],
            "fun": _finite_or_none(self.fun),
            "success": self.success,
            "n_evaluations": self.n_evaluations,
            "n_iterations": self.n_iterations,
            "message": self.message,
        }


@dataclass(frozen=True)
class LocalMinimum:
    """A distinct local minimum: converged end points closer than ``cluster_tol`` (as a fraction of the box
    width in every coordinate) count as one.

    Attributes
    ----------
    x : ndarray, shape (n,)
        The lowest end point of the cluster.
    fun : float
        Objective at ``x``.
    hits : int
        How many local searches ended there (a rough measure of the basin's share of the starts).

    Examples
    --------
    >>> LocalMinimum(np.array([0.5]), -1.0, 3).to_dict()
    {'x': [0.5], 'fun': -1.0, 'hits': 3}
    """

    x: Array
    fun: float
    hits: int

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return {"x": [float(v) for v in self.x], "fun": _finite_or_none(self.fun), "hits": self.hits}


@dataclass(frozen=True)
class OptimizationResult:
    """Outcome of :func:`minimize`.

    Attributes
    ----------
    x : ndarray, shape (n,)
        Best point found (inside the box).
    fun : float
        Objective at ``x``; with ``residuals`` and no ``fun`` it is ``sum(r**2)``.
    success : bool
        For multi-start and least squares: the local search that produced ``x`` converged and the evaluation
        budget was not exhausted. For the global strategies: the polish converged (the global phase stopping at
        its own iteration or evaluation limit is normal and only reported in ``message``); without polish, the
        global method's verdict. No strategy can certify that a minimum is global.
    message : str
        What happened, including why a search failed.
    strategy : str
        The strategy used.
    n_evaluations : int
        Objective or residual evaluations in total, finite-difference ones included (a batch of S points counts S).
    n_jacobian_evaluations : int
        Calls of ``jac`` or ``residual_jacobian``.
    n_iterations : int
        Iterations summed over all stages.
    history : tuple of SearchRecord
        Every stage in the order run: one record per local search for multi-start, the global phase and its
        polish for the global strategies.
    minima : tuple of LocalMinimum
        Distinct local minima from the converged local searches (polish included), lowest first.

    Examples
    --------
    >>> res = minimize(lambda x: float((x[0] - 0.3) ** 2), ([-1.0], [1.0]), strategy="multistart", n_starts=2, rng=0)
    >>> bool(res.success), round(float(res.x[0]), 6), res.to_dict()["strategy"]
    (True, 0.3, 'multistart')
    """

    x: Array
    fun: float
    success: bool
    message: str
    strategy: str
    n_evaluations: int
    n_jacobian_evaluations: int
    n_iterations: int
    history: tuple[SearchRecord, ...]
    minima: tuple[LocalMinimum, ...]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (``"format": "cappe.optimize/1"``)."""
        return {
            "format": "cappe.optimize/1",
            "strategy": self.strategy,
            "x": [float(v) for v in self.x],
            "fun": _finite_or_none(self.fun),
            "success": self.success,
            "message": self.message,
            "n_evaluations": self.n_evaluations,
            "n_jacobian_evaluations": self.n_jacobian_evaluations,
            "n_iterations": self.n_iterations,
            "minima": [m.to_dict() for m in self.minima],
            "history": [r.to_dict() for r in self.history],
        }


class _BudgetExhausted(Exception):
    """Raised inside the objective wrapper when max_evaluations is reached."""


class _UserFailure(Exception):  # noqa: N818 - internal carrier, never seen by users
    """Carries an exception raised by (or about) the user's callables past the solvers' own error handling."""

    def __init__(self, exc: BaseException) -> None:
        super().__init__(str(exc))
        self.exc = exc


class _Problem:
    """The user's callables with evaluation counting, the budget, box clipping and the best point seen."""

    def __init__(self, fun: Objective | None, jac: Objective | None, residuals: Objective | None,
                 residual_jacobian: Objective | None, lower: Array, upper: Array, vectorized: bool,
                 budget: int | None) -> None:
        self.fun, self.jac, self.res, self.res_jac = fun, jac, residuals, residual_jacobian
        self.lower, self.upper = lower, upper
        self.vectorized, self.budget = vectorized, budget
        self.n_fun = 0
        self.n_jac = 0
        self.best_x: Array | None = None
        self.best_f = np.inf

    @property
    def has_gradient(self) -> bool:
        return self.jac is not None or (self.fun is None and self.res_jac is not None)

    @property
    def has_residual_jacobian(self) -> bool:
        return self.res_jac is not None

    def _charge(self, k: int) -> None:
        if self.budget is not None and self.n_fun + k > self.budget:
            raise _BudgetExhausted
        self.n_fun += k

    def _inside(self, x: ArrayLike) -> Array:
        return np.asarray(np.clip(np.asarray(x, dtype=float).reshape(self.lower.shape), self.lower, self.upper))

    def _note(self, x: Array, f: float) -> None:
        if f < self.best_f:
            self.best_f, self.best_x = f, x.copy()

    @staticmethod
    def _call(func: Objective, arg: Array) -> Any:
        try:
            return func(arg)
        except Exception as exc:
            raise _UserFailure(exc) from exc

    def value(self, x: ArrayLike) -> float:
        u = self._inside(x)
        if self.fun is None:
            r = self.residual(u)
            return float(r @ r) if np.all(np.isfinite(r)) else np.inf
        self._charge(1)
        out = np.asarray(self._call(self.fun, u[:, None] if self.vectorized else u), dtype=float)
        if out.size != 1:
            kind = "one value per column of its (n, 1) batch" if self.vectorized else "a scalar"
            raise _UserFailure(DataError(f"fun must return {kind}; got an array of shape {out.shape}"))
        f = float(out.reshape(()))
        f = f if not np.isnan(f) else np.inf
        self._note(u, f)
        return f

    def values(self, batch: ArrayLike) -> Array:
        """Vectorized objective: batch (n, S) -> (S,)."""
        xs = np.clip(np.asarray(batch, dtype=float), self.lower[:, None], self.upper[:, None])
        s = xs.shape[1]
        if self.fun is None or not self.vectorized:
            return np.array([self.value(xs[:, j]) for j in range(s)])
        self._charge(s)
        out = np.asarray(self._call(self.fun, xs), dtype=float)
        if out.shape != (s,):
            raise _UserFailure(DataError(f"vectorized fun must map a batch (n, S) = {xs.shape} to shape ({s},); "
                                         f"got {out.shape}"))
        out = np.where(np.isnan(out), np.inf, out)
        j = int(np.argmin(out))
        self._note(xs[:, j], float(out[j]))
        return out

    def gradient(self, x: ArrayLike) -> Array:
        u = self._inside(x)
        if self.jac is not None:
            self.n_jac += 1
            g = np.asarray(self._call(self.jac, u), dtype=float)
            if g.shape != u.shape:
                raise _UserFailure(DataError(f"jac must return the gradient, shape {u.shape}; got {g.shape}"))
            return g
        r = self.residual(u)  # fun is sum(r**2): gradient 2 J^T r
        return 2.0 * self.residual_jac(u).T @ r

    def residual(self, x: ArrayLike) -> Array:
        u = self._inside(x)
        if self.res is None:  # pragma: no cover - guarded by the validation
            raise _UserFailure(DataError("residuals are needed for a least-squares search"))
        self._charge(1)
        r = np.asarray(self._call(self.res, u), dtype=float)
        if r.ndim != 1:
            raise _UserFailure(DataError(f"residuals must return a 1-D array; got shape {r.shape}"))
        if np.all(np.isfinite(r)):
            self._note(u, float(r @ r))
        return r

    def residual_jac(self, x: ArrayLike) -> Array:
        u = self._inside(x)
        if self.res_jac is None:  # pragma: no cover - guarded by has_residual_jacobian
            raise _UserFailure(DataError("residual_jacobian is not given"))
        self.n_jac += 1
        jac = np.asarray(self._call(self.res_jac, u), dtype=float)
        if jac.ndim != 2 or jac.shape[1] != u.size:
            raise _UserFailure(DataError(f"residual_jacobian must return shape (n_residuals, {u.size}); "
                                         f"got {jac.shape}"))
        return jac


def _local_search(problem: _Problem, start: Array, *, stage: str, use_lsq: bool, tol: float,
                  maxiter: int | None, box: tuple[Array, Array] | None = None) -> SearchRecord:
    """SLSQP on the objective or trust-region reflective least squares on the residuals, from ``start``, in the
    problem's box or a smaller one inside it."""
    lower, upper = box if box is not None else (problem.lower, problem.upper)
    n0 = problem.n_fun
    method = "TRF" if use_lsq else "SLSQP"
    x_end, fun_end, ok, nit, message = start.copy(), np.inf, False, 0, ""
    try:
        if use_lsq:
            jac: Any = problem.residual_jac if problem.has_residual_jacobian else "2-point"
            lsq = sopt.least_squares(problem.residual, start, jac=jac, bounds=(lower, upper),
                                     method="trf", ftol=tol, xtol=tol, gtol=tol, max_nfev=maxiter)
            x_end, fun_end, ok = np.asarray(lsq.x, dtype=float), float(2.0 * lsq.cost), bool(lsq.status > 0)
            nit, message = int(lsq.njev or lsq.nfev), str(lsq.message)
            if problem.fun is not None and np.all(np.isfinite(x_end)):  # report the objective the user gave
                fun_end = problem.value(x_end)
        else:
            grad = problem.gradient if problem.has_gradient else None
            sol = sopt.minimize(problem.value, start, method="SLSQP", jac=grad,
                                bounds=sopt.Bounds(lower, upper),
                                options={"ftol": tol, "maxiter": 200 if maxiter is None else maxiter})
            x_end, fun_end, ok = np.asarray(sol.x, dtype=float), float(sol.fun), bool(sol.success)
            nit, message = int(sol.get("nit", 0)), str(sol.message)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
        message = f"{method} failed: {exc}"
    if not (np.all(np.isfinite(x_end)) and np.isfinite(fun_end)):
        if not message.startswith(method):
            message = f"{method} ended at a non-finite point or value: {message}"
        x_end, fun_end, ok = start.copy(), np.inf, False
    x_end = np.clip(x_end, lower, upper)
    return SearchRecord(stage, method, start.copy(), x_end, fun_end, ok, problem.n_fun - n0, nit, message)


def _sample_starts(n_starts: int, lower: Array, upper: Array, sampling: str, gen: np.random.Generator) -> Array:
    if n_starts == 0:
        return np.empty((0, lower.size))
    if sampling == "sobol":
        m = int(np.ceil(np.log2(n_starts)))
        unit = qmc.Sobol(lower.size, scramble=True, rng=gen).random_base2(m)[:n_starts]
    else:
        unit = qmc.LatinHypercube(lower.size, rng=gen).random(n_starts)
    return np.asarray(qmc.scale(unit, lower, upper), dtype=float)


def _groups(records: list[SearchRecord], rejected: set[int], lower: Array, upper: Array,
            cluster_tol: float) -> list[list[int]]:
    """Indices of the converged local end points grouped into distinct minima, each group lowest first."""
    ends = [i for i, r in enumerate(records) if r.stage in ("local", "restart", "polish")]
    pool = ends if ends else [i for i, r in enumerate(records) if r.stage == "global"]
    found = sorted((i for i in pool if i not in rejected and records[i].success and np.isfinite(records[i].fun)),
                   key=lambda i: records[i].fun)
    width = upper - lower
    groups: list[list[int]] = []
    for i in found:
        for g in groups:
            if np.max(np.abs(records[i].x - records[g[0]].x) / width) <= cluster_tol:
                g.append(i)
                break
        else:
            groups.append([i])
    return groups


def _check_minima(problem: _Problem, records: list[SearchRecord], gen: np.random.Generator, *, use_lsq: bool,
                  tol: float, maxiter: int | None, cluster_tol: float) -> set[int]:
    """Search the neighbourhood of every distinct end point for a lower point.

    A gradient method can stop on a saddle point (the camelback's origin). Around each distinct end point a
    local search confined to a small box (``10 cluster_tol`` of the box width either side) starts from a random
    kick; if it finds a clearly lower value, the end point is not a local minimum: its group is dropped and a full
    local search (stage ``"restart"``) continues from the lower point. Returns the indices of the dropped records.
    """
    lower, upper = problem.lower, problem.upper
    radius = 10.0 * cluster_tol * (upper - lower)
    rejected: set[int] = set()
    checked: set[int] = set()
    for _ in range(2 * len(records) + 1):
        todo = [g for g in _groups(records, rejected, lower, upper, cluster_tol) if not checked.intersection(g)]
        if not todo:
            break
        group = todo[0]
        head = records[group[0]]
        near = (np.maximum(head.x - radius, lower), np.minimum(head.x + radius, upper))
        start = np.clip(head.x + 0.5 * radius * gen.uniform(-1.0, 1.0, lower.size), *near)
        probe = _local_search(problem, start, stage="check", use_lsq=use_lsq, tol=tol, maxiter=maxiter, box=near)
        records.append(probe)
        checked.update(group)
        if probe.success and probe.fun < head.fun - 10.0 * tol * (1.0 + abs(head.fun)):
            rejected.update(group)
            records.append(_local_search(problem, probe.x, stage="restart", use_lsq=use_lsq, tol=tol,
                                         maxiter=maxiter))
    return rejected


def _global_phase(problem: _Problem, strategy: str, starts: Array, gen: np.random.Generator,
                  options: dict[str, Any], budget: int | None, polish: bool) -> SearchRecord:
    n0 = problem.n_fun
    box = list(zip(problem.lower, problem.upper, strict=True))
    share = None if budget is None else max(1, int(_POLISH_SHARE * budget) if polish else budget)
    x0 = starts[0] if len(starts) else None
    if strategy == "direct":
        # the original (globally balanced) DIRECT; no volume rule, which in n variables stops after about
        # 33 / n trisections of each side (1e-16 = 3**-33) and so ends a 20-variable search almost at once
        kw = {"maxfun": share, "locally_biased": False, "vol_tol": 0.0, **options}
        res = sopt.direct(problem.value, box, **kw)
    elif strategy == "differential-evolution":
        kw = dict(options)
        if share is not None and "maxiter" not in kw:  # stop by generations within the budget share
            popsize = int(kw.get("popsize", 15)) * problem.lower.size
            kw["maxiter"] = max(0, share // max(popsize, 1) - 1)
        if problem.vectorized:
            kw["updating"] = "deferred"
        res = sopt.differential_evolution(problem.values if problem.vectorized else problem.value, box, rng=gen,
                                          polish=False, x0=x0, vectorized=problem.vectorized, **kw)
    else:
        kw = {"maxfun": share if share is not None else 10_000_000, **options}
        minimizer: dict[str, Any] = {"method": "L-BFGS-B"}
        if problem.has_gradient:
            minimizer["jac"] = problem.gradient
        res = sopt.dual_annealing(problem.value, box, rng=gen, x0=x0, minimizer_kwargs=minimizer, **kw)
    msg = res.message if isinstance(res.message, str) else "; ".join(str(m) for m in res.message)
    x = np.clip(np.asarray(res.x, dtype=float), problem.lower, problem.upper)
    return SearchRecord("global", strategy, None if x0 is None else x0.copy(), x, float(res.fun),
                        bool(res.success), problem.n_fun - n0, int(res.get("nit", 0)), msg or "finished")


def _validate_box(bounds: Any) -> tuple[Array, Array]:
    if isinstance(bounds, sopt.Bounds):
        lo_raw, hi_raw = bounds.lb, bounds.ub
    else:
        try:
            lo_raw, hi_raw = bounds
        except (TypeError, ValueError) as exc:
            shape = np.shape(bounds) if not isinstance(bounds, (str, bytes)) else type(bounds).__name__
            msg = (f"bounds must be (lower, upper), two arrays of shape (n,); got {shape} "
                   "(for a list of (low, high) pairs use numpy.transpose)")
            raise DataError(msg) from exc
    try:
        lower = np.atleast_1d(np.asarray(lo_raw, dtype=float))
        upper = np.atleast_1d(np.asarray(hi_raw, dtype=float))
    except (TypeError, ValueError) as exc:
        msg = f"bounds must hold numbers; got {bounds!r}"
        raise DataError(msg) from exc
    if lower.ndim != 1 or lower.shape != upper.shape or lower.size == 0:
        msg = (f"bounds must be (lower, upper), two arrays of shape (n,); got shapes {lower.shape} and "
               f"{upper.shape} (for a list of (low, high) pairs use numpy.transpose)")
        raise DataError(msg)
    if not (np.all(np.isfinite(lower)) and np.all(np.isfinite(upper))):
        msg = f"bounds must be finite (transform unbounded parameters first); got lower={lower}, upper={upper}"
        raise DataError(msg)
    bad = np.flatnonzero(~(lower < upper))
    if bad.size:
        i = int(bad[0])
        msg = f"bounds must satisfy lower < upper; got lower[{i}]={lower[i]:g} >= upper[{i}]={upper[i]:g}"
        raise DataError(msg)
    return lower, upper


def _validate_starts(x0: ArrayLike | None, lower: Array, upper: Array) -> Array:
    n = lower.size
    if x0 is None:
        return np.empty((0, n))
    starts = np.asarray(x0, dtype=float)
    if starts.ndim == 1:
        starts = starts[None, :]
    if starts.ndim != 2 or starts.shape[1] != n:
        msg = f"x0 must have shape ({n},) or (k, {n}) to match the bounds; got {np.shape(x0)}"
        raise DataError(msg)
    if not np.all(np.isfinite(starts)):
        msg = f"x0 must be finite; got {starts.tolist()}"
        raise DataError(msg)
    outside = np.argwhere((starts < lower) | (starts > upper))
    if outside.size:
        k, i = (int(v) for v in outside[0])
        msg = (f"x0 must lie inside the bounds; got x0[{k}][{i}]={starts[k, i]:g} outside "
               f"[{lower[i]:g}, {upper[i]:g}]")
        raise DataError(msg)
    return starts


def _validate_options(strategy: str, options: Mapping[str, Any] | None) -> tuple[dict[str, Any], int | None]:
    given = dict(options or {})
    allowed = (*_GLOBAL_OPTIONS.get(strategy, ()), *_LOCAL_OPTIONS)
    unknown = sorted(set(given) - set(allowed))
    if unknown:
        msg = f"options for strategy {strategy!r} may be {sorted(allowed)}; got unknown {unknown}"
        raise DataError(msg)
    local_maxiter = given.pop("local_maxiter", None)
    return given, None if local_maxiter is None else _positive_int("options['local_maxiter']", local_maxiter, 1)


def _positive_int(name: str, value: Any, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        msg = f"{name} must be an integer >= {minimum}; got {value!r}"
        raise DataError(msg)
    return int(value)


def minimize(
    fun: Objective | None,
    bounds: Any,
    *,
    strategy: str = "multistart",
    x0: ArrayLike | None = None,
    jac: Objective | None = None,
    residuals: Objective | None = None,
    residual_jacobian: Objective | None = None,
    n_starts: int | None = None,
    rng: RandomLike = None,
    max_evaluations: int | None = None,
    tol: float = 1e-8,
    polish: bool = True,
    vectorized: bool = False,
    sampling: str = "sobol",
    cluster_tol: float = 1e-3,
    check_minima: bool = True,
    options: Mapping[str, Any] | None = None,
) -> OptimizationResult:
    """Minimize ``fun`` over a box with one of the search strategies (see the module docstring).

    Parameters
    ----------
    fun : callable or None
        Objective ``fun(x (n,)) -> float``. With ``vectorized=True`` it takes a batch of points as COLUMNS,
        ``fun(X (n, S)) -> (S,)`` (scipy's convention; a function written for rows ``(S, n)`` is passed as
        ``lambda X: f(X.T)``). None when ``residuals`` are given: the objective is then ``sum(residuals(x)**2)``.
        When both are given, ``fun`` is the objective that is reported and compared while the residuals drive the
        local searches, so the two must share their minimizers (``fun = sum(r**2)`` or a multiple of it).
        NaN values count as ``+inf``; exceptions raised by ``fun`` propagate unchanged.
    bounds : (lower, upper) or scipy.optimize.Bounds
        The box, two finite arrays of shape (n,) with lower < upper, in the optimizer's coordinates.
    strategy : {"multistart", "direct", "differential-evolution", "dual-annealing", "least-squares"}
        Search strategy.
    x0 : array_like, shape (n,) or (k, n), optional
        Start point(s) inside the box: local starts for multi-start and least squares, the first population
        member of differential evolution, the start of dual annealing (first row only). DIRECT ignores it.
    jac : callable, optional
        Gradient of ``fun``, ``jac(x (n,)) -> (n,)``, used by SLSQP and the annealing's local steps.
    residuals : callable, optional
        ``residuals(x (n,)) -> r (m,)``. When given, every local search (multi-start, least squares, polish)
        is the trust-region reflective least-squares method on ``r``.
    residual_jacobian : callable, optional
        ``residual_jacobian(x (n,)) -> dr/dx (m, n)``; without it the Jacobian is a 2-point finite difference.
    n_starts : int, optional
        Sampled start points in addition to ``x0``. Default ``8 n`` for multi-start, 0 for least squares;
        ignored by the global strategies.
    rng : int, numpy.random.Generator or None
        Seed of the start points, the evolution and the annealing. The same seed gives bit-identical results.
    max_evaluations : int, optional
        Hard cap on evaluations of ``fun``/``residuals`` (finite differences included). The global phase gets 80 %
        of it when a polish follows (its own limit, a normal end); reaching the cap itself stops the run with
        ``success=False``.
    tol : float
        Tolerance of the local searches (SLSQP ``ftol``; least-squares ``ftol``, ``xtol`` and ``gtol``).
    polish : bool
        Follow a global strategy with a local search from its best point.
    vectorized : bool
        ``fun`` accepts column batches (used by differential evolution to evaluate a generation in one call).
    sampling : {"sobol", "lhs"}
        Design of the multi-start points: scrambled Sobol' (the first ``n_starts`` of a power-of-two set) or Latin
        hypercube.
    cluster_tol : float
        End points closer than this fraction of the box width (in every coordinate) are one local minimum.
    check_minima : bool
        Multi-start only: search a small box (``10 cluster_tol`` of the box width either side) around each distinct
        end point from a random kick, and drop end points it finds a clearly lower value next to (saddle points
        where a gradient method stopped); a full local search (stage ``"restart"``) continues from there. Costs one
        small local search per distinct end point (stage ``"check"`` in ``history``).
    options : mapping, optional
        Settings passed to the scipy routine of a global strategy (DIRECT: eps, maxfun, maxiter, locally_biased,
        f_min, f_min_rtol, vol_tol, len_tol; differential evolution: strategy, maxiter, popsize, tol, mutation,
        recombination, init, atol, updating; dual annealing: maxiter, initial_temp, restart_temp_ratio, visit,
        accept, maxfun, no_local_search), plus ``local_maxiter`` for every strategy (SLSQP iterations, or
        residual evaluations of the least-squares method).

    Returns
    -------
    OptimizationResult
        A failed search does not raise: it returns ``success=False`` with the reason and warns
        :class:`~cappe.exceptions.ConvergenceWarning`.

    Raises
    ------
    DataError
        Invalid arguments; the message names the argument, the rule and the value received.

    Examples
    --------
    >>> from cappe.optimize import TEST_FUNCTIONS
    >>> camel = TEST_FUNCTIONS["camelback"]
    >>> res = minimize(camel, camel.bounds, strategy="direct", jac=camel.gradient)
    >>> round(res.fun, 4), bool(res.success)
    (-1.0316, True)
    """
    if strategy not in STRATEGIES:
        msg = f"strategy must be one of {list(STRATEGIES)}; got {strategy!r}"
        raise DataError(msg)
    for name, func in (("fun", fun), ("jac", jac), ("residuals", residuals), ("residual_jacobian", residual_jacobian)):
        if func is not None and not callable(func):
            msg = f"{name} must be callable or None; got {type(func).__name__}"
            raise DataError(msg)
    if fun is None and residuals is None:
        msg = "fun is None and no residuals are given; pass an objective, residuals, or both"
        raise DataError(msg)
    if strategy == "least-squares" and residuals is None:
        msg = "strategy 'least-squares' needs residuals (a callable x -> r); got residuals=None"
        raise DataError(msg)
    if residual_jacobian is not None and residuals is None:
        msg = "residual_jacobian is given without residuals"
        raise DataError(msg)
    if vectorized and fun is None:
        msg = "vectorized=True applies to fun, but fun is None"
        raise DataError(msg)
    lower, upper = _validate_box(bounds)
    starts = _validate_starts(x0, lower, upper)
    n = lower.size
    local = strategy in ("multistart", "least-squares")
    if n_starts is None:
        n_starts = 8 * n if strategy == "multistart" else 0
    n_starts = _positive_int("n_starts", n_starts, 0)
    if strategy == "multistart" and n_starts == 0 and len(starts) == 0:
        msg = "multistart needs at least one start: give x0 or n_starts >= 1; got neither"
        raise DataError(msg)
    if max_evaluations is not None:
        max_evaluations = _positive_int("max_evaluations", max_evaluations, 1)
    if not (isinstance(tol, (int, float, np.floating)) and np.isfinite(tol) and tol > 0):
        msg = f"tol must be a finite number > 0; got {tol!r}"
        raise DataError(msg)
    if sampling not in ("sobol", "lhs"):
        msg = f"sampling must be 'sobol' or 'lhs'; got {sampling!r}"
        raise DataError(msg)
    if not (np.isfinite(cluster_tol) and 0 < cluster_tol < 1):
        msg = f"cluster_tol must lie in (0, 1) (a fraction of the box width); got {cluster_tol!r}"
        raise DataError(msg)
    global_options, local_maxiter = _validate_options(strategy, options)
    gen = as_generator(rng)

    problem = _Problem(fun, jac, residuals, residual_jacobian, lower, upper, vectorized, max_evaluations)
    use_lsq = residuals is not None
    records: list[SearchRecord] = []
    rejected: set[int] = set()
    stopped = False
    planned = 0
    try:
        try:
            if local:
                sampled = _sample_starts(n_starts, lower, upper, sampling, gen)
                all_starts = np.vstack([starts, sampled])
                if len(all_starts) == 0:
                    all_starts = ((lower + upper) / 2.0)[None, :]
                planned = len(all_starts)
                for start in all_starts:
                    records.append(_local_search(problem, start, stage="local", use_lsq=use_lsq, tol=tol,
                                                 maxiter=local_maxiter))
                if strategy == "multistart" and check_minima:
                    rejected = _check_minima(problem, records, gen, use_lsq=use_lsq, tol=tol, maxiter=local_maxiter,
                                             cluster_tol=cluster_tol)
            else:
                first = _global_phase(problem, strategy, starts, gen, global_options, max_evaluations, polish)
                records.append(first)
                if polish:
                    records.append(_local_search(problem, first.x, stage="polish", use_lsq=use_lsq, tol=tol,
                                                 maxiter=local_maxiter))
        except _BudgetExhausted:
            stopped = True
    except _UserFailure as failure:
        raise failure.exc from None

    minima = tuple(LocalMinimum(records[g[0]].x.copy(), records[g[0]].fun, len(g))
                   for g in _groups(records, rejected, lower, upper, cluster_tol))
    finite = [r for r in records if np.isfinite(r.fun)]
    best = min(finite, key=lambda r: r.fun) if finite else None
    if stopped:
        x = problem.best_x if problem.best_x is not None else (best.x if best else (lower + upper) / 2.0)
        f = problem.best_f if problem.best_x is not None else (best.fun if best else np.nan)
        success = False
        n_done = sum(r.stage == "local" for r in records)
        done = f"{n_done} of {planned} local searches" if local else f"{len(records)} stage(s)"
        message = (f"stopped at max_evaluations={max_evaluations} after completing {done}; returning the best point "
                   "evaluated")
    elif best is None:
        x, f, success = (records[0].x if records else (lower + upper) / 2.0), np.nan, False
        message = "every search failed: " + "; ".join(r.message for r in records)
    elif local:
        x, f, success = best.x, best.fun, best.success
        starts_run = [r for r in records if r.stage == "local"]
        n_ok = sum(r.success for r in starts_run)
        message = (f"{n_ok} of {len(starts_run)} local searches ({best.method}) converged; {len(minima)} distinct "
                   f"minima")
        if rejected:
            message += f"; {len(rejected)} end point(s) were stationary points but not minima"
        message += f"; best: {best.message}"
    else:
        x, f = best.x, best.fun
        glob = records[0]
        if polish:
            last = records[-1]
            success = last.success
            message = f"{strategy}: {glob.message}; polish ({last.method}): {last.message}"
        else:
            success = glob.success
            message = f"{strategy}: {glob.message}"
    if not success:
        warnings.warn(f"minimize ({strategy}) did not converge: {message}", ConvergenceWarning, stacklevel=2)
    return OptimizationResult(
        x=np.asarray(x, dtype=float).copy(), fun=float(f), success=bool(success), message=message,
        strategy=strategy, n_evaluations=problem.n_fun, n_jacobian_evaluations=problem.n_jac,
        n_iterations=sum(r.n_iterations for r in records), history=tuple(records), minima=minima,
    )

