"""Uncertainty beyond the local Jacobian: profile likelihood, parametric bootstrap and an MCMC posterior.

* :func:`profile_likelihood` fixes one unknown on a grid and re-optimizes the others; the 95 % interval is where
  the cost rises by ``chi2(1, 0.95) = 3.84`` noise variances above the optimum. A flat profile means the data do not
  determine the parameter (practical non-identifiability) even where the local Jacobian looked fine.
* :func:`parametric_bootstrap` re-estimates from data simulated at the estimate with new noise.
* :func:`mcmc_posterior` samples ``exp(-cost / (2 s^2))`` inside the bounds with emcee's affine-invariant ensemble.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from cappe._rng import RandomLike, as_generator
from cappe.estimate._base import Estimator, fit_least_squares
from cappe.estimate._result import ParameterEstimate
from cappe.estimate._space import ParameterSpace
from cappe.exceptions import ConvergenceWarning, DataError

__all__ = [
    "BootstrapResult",
    "PosteriorSample",
    "Profile",
    "mcmc_posterior",
    "parametric_bootstrap",
    "profile_likelihood",
]

Array = NDArray[np.float64]
Residuals = Callable[[Array], Array]
_CHI2_95 = float(stats.chi2.ppf(0.95, 1))


def _noise_variance(estimate: ParameterEstimate, n_obs: int) -> float:
    dof = estimate.diagnostics.get("degrees_of_freedom", max(n_obs - estimate.values.size, 1))
    return float(estimate.cost) / float(dof)


@dataclass(frozen=True)
class Profile:
    """Profile of the cost over one unknown.

    ``values`` (SI) on the grid, ``cost`` the re-optimized cost there, ``ci95`` where ``cost - min`` crosses
    ``3.84 s^2`` (``nan`` on a side where it never does inside the bounds: the interval is open there), and
    ``identifiable`` False when it stays open on both sides.

    Attributes
    ----------
    name : str
        The profiled unknown.
    values : ndarray, shape (n_points,)
        Grid of the unknown (SI).
    cost : ndarray, shape (n_points,)
        ``|r|^2`` with the other unknowns re-optimized (residual units squared).
    threshold : float
        ``min cost + 3.84 s^2``, the cost at the bounds of the 95 % interval.
    ci95 : (float, float)
        Lower and upper bound of the 95 % interval (SI; ``nan`` where open).
    identifiable : bool
        False when the interval is open on both sides.
    """

    name: str
    values: Array
    cost: Array
    threshold: float
    ci95: tuple[float, float]
    identifiable: bool

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "values": self.values.tolist(),
            "cost": self.cost.tolist(),
            "threshold": self.threshold,
            "ci95": [None if np.isnan(v) else v for v in self.ci95],
            "identifiable": self.identifiable,
        }


def profile_likelihood(
    *,
    space: ParameterSpace,
    residuals: Residuals,
    estimate: ParameterEstimate,
    name: str,
    n_points: int = 21,
    span: float = 4.0,
    noise_variance: float | None = None,
) -> Profile:
    """Profile of ``|residuals|^2`` over unknown ``name``, the others re-optimized at each grid value.

    The grid covers ``span`` local standard errors either side of the estimate (the whole bound range when the
    local error is undefined), clipped to the bounds, in the unknown's internal coordinate. ``residuals(p)`` takes the
    full unknown vector of ``space`` (SI), as for :func:`fit_least_squares`.

    Parameters
    ----------
    space : ParameterSpace
        The unknowns, their bounds and transformation.
    residuals : callable
        ``residuals(p)`` -> ndarray, shape (n_obs,), for an SI vector ``p``, shape (space.n,).
    estimate : ParameterEstimate
        The optimum (its values and standard errors set the grid).
    name : str
        The unknown to profile.
    n_points : int
        Grid points (each a least-squares fit of the others).
    span : float
        Half-width of the grid in local standard errors.
    noise_variance : float, optional
        Variance of the residuals' noise (residual units squared); default estimated from the estimate's cost and
        degrees of freedom.

    Returns
    -------
    Profile

    Raises
    ------
    DataError
        ``name`` is not an unknown, or it has neither finite bounds nor a local standard error.

    Examples
    --------
    >>> from cappe.model import load_model
    >>> space = ParameterSpace.from_model(load_model("builtin:two-mass-rig"), ["k11", "k22"])
    >>> def res(p):
    ...     return np.array([p[0] / 1.38e6 - 1, p[1] / 0.24e6 - 1, 0.01])
    >>> est = fit_least_squares("demo", space, res)
    >>> prof = profile_likelihood(space=space, residuals=res, estimate=est, name="k11", n_points=5)
    >>> prof.identifiable
    True
    """
    if name not in space.names:
        msg = f"{name!r} is not among the unknowns {list(space.names)}"
        raise DataError(msg)
    k = space.names.index(name)
    r0 = np.asarray(residuals(estimate.values), dtype=float)
    s2 = noise_variance if noise_variance is not None else _noise_variance(estimate, r0.size)
    lo, hi = space.internal_bounds()
    u_hat = space.to_internal(estimate.values)[k]
    std = estimate.std[k]
    if np.isfinite(std) and std > 0:
        du = span * std / float(space.value_jacobian(space.to_internal(estimate.values))[k])
        grid_u = np.linspace(max(u_hat - du, lo[k]), min(u_hat + du, hi[k]), n_points)
    elif np.isfinite(lo[k]) and np.isfinite(hi[k]):
        grid_u = np.linspace(lo[k], hi[k], n_points)
    else:
        msg = f"{name!r} has no finite bounds and no local standard error: give bounds to profile it"
        raise DataError(msg)
    u_grid = np.tile(space.to_internal(estimate.values), (n_points, 1))
    u_grid[:, k] = grid_u
    grid = space.from_internal(u_grid)[:, k]
    costs = np.empty(n_points)
    others = [j for j in range(space.n) if j != k]
    for i, value in enumerate(grid):
        if not others:
            costs[i] = float(np.sum(np.asarray(residuals(np.array([value]))) ** 2))
            continue
        sub = space.fixing(name, value)
        sub = replace(sub, start=np.clip(estimate.values[others], sub.lower, sub.upper))

        def sub_residuals(p: Array, value: float = float(value)) -> Array:
            full = np.insert(p, k, value)
            return np.asarray(residuals(full), dtype=float)

        costs[i] = fit_least_squares("profile", sub, sub_residuals).cost
    threshold = float(estimate.cost + _CHI2_95 * s2)
    ci = (_crossing(grid, costs, threshold, k_side=-1, centre=estimate.values[k]),
          _crossing(grid, costs, threshold, k_side=1, centre=estimate.values[k]))
    return Profile(name, grid, costs, threshold, ci, not (np.isnan(ci[0]) and np.isnan(ci[1])))


def _crossing(x: Array, cost: Array, threshold: float, *, k_side: int, centre: float) -> float:
    """Where the profile first exceeds the threshold going from the centre outwards (linear interpolation)."""
    order = np.argsort(x)
    x, cost = x[order], cost[order]
    side = np.flatnonzero(x >= centre) if k_side > 0 else np.flatnonzero(x <= centre)[::-1]
    for a, b in zip(side[:-1], side[1:], strict=True):
        if cost[a] <= threshold < cost[b]:
            t = (threshold - cost[a]) / (cost[b] - cost[a])
            return float(x[a] + t * (x[b] - x[a]))
    return float("nan")


@dataclass(frozen=True)
class BootstrapResult:
    """Re-estimates from simulated data: ``samples`` (n_ok, n) in SI, their std and percentile 95 % intervals.

    Attributes
    ----------
    names : tuple of str
        The unknowns, in the order of the columns.
    samples : ndarray, shape (n_ok, n)
        The converged re-estimates (SI).
    std : ndarray, shape (n,)
        Their standard deviations (SI).
    ci95 : ndarray, shape (n, 2)
        2.5 and 97.5 percentiles (SI).
    n_failed : int
        Re-fits that did not converge (left out).
    """

    names: tuple[str, ...]
    samples: Array
    std: Array
    ci95: Array
    n_failed: int

    def to_dict(self) -> dict[str, Any]:
        return {
            "names": list(self.names),
            "std": dict(zip(self.names, self.std.tolist(), strict=True)),
            "ci95": {n: row.tolist() for n, row in zip(self.names, self.ci95, strict=True)},
            "n_samples": int(self.samples.shape[0]),
            "n_failed": self.n_failed,
        }


def parametric_bootstrap(
    *,
    estimator: Estimator,
    simulate: Callable[[Mapping[str, float], np.random.Generator], Any],
    n: int = 50,
    rng: RandomLike = None,
) -> BootstrapResult:
    """Fit ``estimator`` (already fitted once) again to ``n`` data sets ``simulate(estimate, rng)``.

    ``simulate`` returns data in the form the estimator's ``fit`` takes, made at the parameter values given (the
    current estimate) with fresh noise. Re-fits that do not converge are counted, not used.

    Parameters
    ----------
    estimator : Estimator
        A fitted estimator; each re-fit is a copy with its settings (``get_params``).
    simulate : callable
        ``simulate(parameters, rng)`` -> data, with ``parameters`` ``{name: value}`` (SI) and a numpy Generator.
    n : int
        Number of simulated data sets.
    rng : int, Generator or None
        Seed of the simulations.

    Returns
    -------
    BootstrapResult

    Raises
    ------
    NotFittedError
        ``estimator`` is not fitted.
    """
    first = estimator.estimate_
    gen = as_generator(rng)
    rows, failed = [], 0
    for _ in range(n):
        data = simulate(first.parameters, gen)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            est = type(estimator)(**estimator.get_params()).fit(data).estimate_
        if est.success:
            rows.append(est.values)
        else:
            failed += 1
    samples = np.array(rows).reshape(len(rows), first.values.size)
    if samples.shape[0] < 2:
        msg = f"parametric bootstrap: only {samples.shape[0]} of {n} re-estimates converged"
        raise DataError(msg)
    return BootstrapResult(
        first.names, samples, samples.std(axis=0, ddof=1),
        np.percentile(samples, [2.5, 97.5], axis=0).T, failed,
    )


@dataclass(frozen=True)
class PosteriorSample:
    """MCMC draws (n_draws, n) in SI with posterior mean, std, 95 % credible intervals and acceptance fraction.

    Attributes
    ----------
    names : tuple of str
        The unknowns, in the order of the columns.
    samples : ndarray, shape (n_draws, n)
        The draws after burn-in, all walkers (SI).
    mean, std : ndarray, shape (n,)
        Posterior mean and standard deviation (SI).
    ci95 : ndarray, shape (n, 2)
        2.5 and 97.5 percentiles (SI).
    acceptance : float
        Mean acceptance fraction of the walkers (0..1).
    """

    names: tuple[str, ...]
    samples: Array
    mean: Array
    std: Array
    ci95: Array
    acceptance: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "names": list(self.names),
            "mean": dict(zip(self.names, self.mean.tolist(), strict=True)),
            "std": dict(zip(self.names, self.std.tolist(), strict=True)),
            "ci95": {n: row.tolist() for n, row in zip(self.names, self.ci95, strict=True)},
            "acceptance": self.acceptance,
            "n_draws": int(self.samples.shape[0]),
        }


def mcmc_posterior(
    *,
    space: ParameterSpace,
    residuals: Residuals,
    estimate: ParameterEstimate,
    noise_variance: float | None = None,
    n_walkers: int | None = None,
    n_steps: int = 500,
    burn: int = 100,
    rng: RandomLike = None,
) -> PosteriorSample:
    """Posterior ``exp(-|r(p)|^2 / (2 s^2))`` with a flat prior on the internal coordinates inside the bounds
    (log-uniform for log-searched parameters), sampled with emcee from a ball around the estimate.

    Parameters
    ----------
    space : ParameterSpace
        The unknowns, their bounds and transformation.
    residuals : callable
        ``residuals(p)`` -> ndarray, shape (n_obs,), for an SI vector ``p``, shape (space.n,).
    estimate : ParameterEstimate
        The optimum: the walkers start around it.
    noise_variance : float, optional
        ``s^2``, the variance of the residuals' noise (residual units squared); default estimated from the
        estimate's cost and degrees of freedom.
    n_walkers : int, optional
        Ensemble size (default ``max(4 n, 8)``).
    n_steps : int
        Steps per walker.
    burn : int
        Steps per walker discarded at the start.
    rng : int, Generator or None
        Seed of the start ball and of emcee's moves.

    Returns
    -------
    PosteriorSample
    """
    import emcee

    r0 = np.asarray(residuals(estimate.values), dtype=float)
    s2 = noise_variance if noise_variance is not None else _noise_variance(estimate, r0.size)
    lo, hi = space.internal_bounds()
    u_hat = space.to_internal(estimate.values)
    walkers = n_walkers if n_walkers is not None else max(4 * space.n, 8)
    gen = as_generator(rng)
    spread = np.where(np.isfinite(estimate.std), estimate.std, 0.01 * np.abs(estimate.values))
    spread_u = np.maximum(spread / space.value_jacobian(u_hat), 1e-8)
    p0 = np.clip(u_hat + 0.1 * spread_u * gen.standard_normal((walkers, space.n)), lo, hi)

    def log_prob(u: Array) -> float:
        if np.any(u < lo) or np.any(u > hi):
            return -np.inf
        r = np.asarray(residuals(space.from_internal(u)), dtype=float)
        return float(-0.5 * (r @ r) / s2)

    sampler = emcee.EnsembleSampler(walkers, space.n, log_prob)
    # emcee draws from its own legacy RandomState: seed it from our generator so a seed reproduces the chain
    sampler.random_state = np.random.RandomState(int(gen.integers(2**31))).get_state()
    sampler.run_mcmc(p0, n_steps, progress=False)
    chain = sampler.get_chain(discard=burn, flat=True)
    samples = space.from_internal(chain)
    return PosteriorSample(
        space.names, samples, samples.mean(axis=0), samples.std(axis=0, ddof=1),
        np.percentile(samples, [2.5, 97.5], axis=0).T, float(np.mean(sampler.acceptance_fraction)),
    )
