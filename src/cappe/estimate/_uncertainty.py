"""Local uncertainty and identifiability from the residual Jacobian at the optimum.

For weighted least squares ``r(p)`` with ``n_obs`` residuals, the Gauss-Newton covariance is
``cov = s^2 (J^T J)^-1`` with ``s^2 = |r|^2 / (n_obs - n_p)`` (or a known noise variance). Identifiability is read
from the singular values of the Jacobian with its columns scaled by the parameter values (relative
sensitivities): a singular value below ``rtol`` times the largest means a direction in parameter space that the
data do not determine. The parameters with a weight above 10 % in such a direction are flagged non-identifiable
and the direction is reported as a combination, e.g. "+0.71 m1 -0.71 m2" when only m1 + m2 is determined.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import stats

__all__ = ["LocalUncertainty", "correlated_uncertainty", "jacobian_uncertainty", "newey_west_bandwidth",
           "newey_west_meat"]

Array = NDArray[np.float64]

#: A relative singular value below this marks an undetermined direction: sqrt(machine eps) ~ 1.5e-8 is where the
#: normal equations lose every digit; 1e-6 leaves room for the truncation error of finite-difference Jacobians.
_RANK_RTOL = 1e-6
#: Weight of a parameter in an undetermined direction above which the parameter is flagged.
_NULL_WEIGHT = 0.1


@dataclass(frozen=True)
class LocalUncertainty:
    """Standard errors, 95 % intervals, correlations and identifiability at an optimum.

    ``std`` and the intervals are ``nan`` for non-identifiable parameters (a bare number would be a lie).

    Attributes
    ----------
    names : tuple of str
        The parameters, in the order of the arrays.
    values : ndarray, shape (n,)
        Estimates (SI).
    covariance : ndarray, shape (n, n)
        Covariance of the estimates (SI units squared), pseudo-inverse on the determined subspace.
    std : ndarray, shape (n,)
        Standard errors (SI; nan for non-identifiable parameters).
    ci95 : ndarray, shape (n, 2)
        95 % intervals (Student t with ``dof`` degrees of freedom).
    correlation : ndarray, shape (n, n)
        Correlation matrix (nan off the diagonal for non-identifiable parameters).
    identifiable : ndarray of bool, shape (n,)
        False for parameters with weight in an undetermined direction.
    rank : int
        Numerical rank of the relative-sensitivity Jacobian.
    condition_number : float
        Largest over smallest kept singular value (inf at rank 0).
    singular_values : ndarray, shape (n,)
        Singular values of the Jacobian with columns scaled by ``|p|`` (or the ``scale`` given).
    combinations : tuple of str
        Undetermined directions, e.g. ``"+0.71 m1 -0.71 m2"``.
    dof : int
        Degrees of freedom ``max(n_obs - n, 1)``.
    """

    names: tuple[str, ...]
    values: Array
    covariance: Array
    std: Array
    ci95: Array
    correlation: Array
    identifiable: NDArray[np.bool_]
    rank: int
    condition_number: float
    singular_values: Array
    combinations: tuple[str, ...]
    dof: int

    def to_dict(self) -> dict[str, Any]:
        return {
            "std": _named(self.names, self.std),
            "ci95": {n: [_num(lo), _num(hi)] for n, (lo, hi) in zip(self.names, self.ci95, strict=True)},
            "correlation": {"names": list(self.names), "matrix": [[_num(v) for v in row] for row in self.correlation]},
        }


def _num(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def _named(names: Sequence[str], values: Array) -> dict[str, float | None]:
    return {n: _num(v) for n, v in zip(names, values, strict=True)}


def jacobian_uncertainty(
    *,
    names: Sequence[str],
    values: ArrayLike,
    jacobian: ArrayLike,
    residuals: ArrayLike,
    noise_variance: float | None = None,
    rtol: float = _RANK_RTOL,
    scale: ArrayLike | None = None,
) -> LocalUncertainty:
    """Covariance, standard errors, 95 % intervals (Student t), correlation and identifiability.

    Parameters
    ----------
    names : sequence of str
        Parameter names.
    values : array_like, shape (n_p,)
        Estimates (SI).
    jacobian : array_like, shape (n_obs, n_p)
        ``d r / d p`` of the weighted residuals with respect to the parameters in SI units.
    residuals : array_like, shape (n_obs,)
        Weighted residuals at the estimate.
    noise_variance : float, optional
        Known variance of the weighted residuals; default ``|r|^2 / (n_obs - n_p)``.
    rtol : float
        Relative singular-value threshold for an undetermined direction.
    scale : array_like, shape (n_p,), optional
        Scales of the Jacobian's columns for the rank decision and the combinations. Default ``|p|`` (1 where
        ``p = 0``): relative sensitivities, for physical parameters. Give ``1 / |column|`` (unit-norm columns) for
        parameters whose value says nothing about their size: coefficients, offsets and initial states near 0,
        which relative scaling would shrink to a false null direction.

    Examples
    --------
    >>> x = np.linspace(0, 1, 50)
    >>> jac = np.column_stack([x, x])        # only a + b is determined by y = (a + b) x
    >>> u = jacobian_uncertainty(names=["a", "b"], values=[1.0, 2.0], jacobian=jac, residuals=0.01 * np.sin(9 * x))
    >>> u.identifiable.tolist(), u.combinations
    ([False, False], ('+0.89 a -0.45 b',))
    """
    p = np.asarray(values, dtype=float)
    jac = np.atleast_2d(np.asarray(jacobian, dtype=float))
    r = np.asarray(residuals, dtype=float).ravel()
    n_obs, n_p = jac.shape
    dof = max(n_obs - n_p, 1)
    s2 = float(noise_variance) if noise_variance is not None else float(r @ r) / dof
    # relative sensitivities: columns scaled by |p| (by 1 where p = 0; or by `scale`), singular values compare alike
    columns = np.where(p != 0, np.abs(p), 1.0) if scale is None else np.asarray(scale, dtype=float)
    if columns.shape != p.shape or not np.all(np.isfinite(columns) & (columns > 0)):
        msg = f"scale must hold {p.size} finite positive column scales; got {scale!r}"
        raise ValueError(msg)
    # thin SVD (n_p x n_p right factor) when there are enough observations; the full one only when n_obs < n_p,
    # where the extra right singular vectors are the undetermined directions (never allocate n_obs x n_obs)
    _, sv_short, vt = np.linalg.svd(jac * columns, full_matrices=n_obs < n_p)
    sv = np.zeros(n_p)
    sv[: sv_short.size] = sv_short  # fewer observations than parameters: the missing singular values are zero
    top = sv[0] if sv[0] > 0 else 0.0
    keep = sv > rtol * top if top > 0 else np.zeros(n_p, dtype=bool)
    rank = int(keep.sum())
    condition = float(top / sv[keep].min()) if rank else float("inf")
    null = vt[~keep]
    weight = np.sqrt(np.sum(null**2, axis=0))
    identifiable = weight <= _NULL_WEIGHT
    inv_s2 = np.where(keep, 1.0 / np.where(keep, sv, 1.0) ** 2, 0.0)
    cov_rel = (vt.T * inv_s2) @ vt * s2  # pseudo-inverse on the determined subspace
    cov = cov_rel * np.outer(columns, columns)
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    std = np.where(identifiable, std, np.nan)
    t = float(stats.t.ppf(0.975, dof))
    ci95 = np.column_stack([p - t * std, p + t * std])
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(np.sqrt(np.diag(cov)), np.sqrt(np.diag(cov)))
    corr = np.where(np.outer(identifiable, identifiable), corr, np.nan)
    np.fill_diagonal(corr, 1.0)
    combos = tuple(null_direction_text(names, v) for v in null if np.any(v))
    return LocalUncertainty(
        tuple(names), p, cov, std, ci95, corr, identifiable, rank, condition, sv, combos, dof
    )


def null_direction_text(names: Sequence[str], direction: Array) -> str:
    """A null direction (in relative coordinates) as ``"+0.71 m1 -0.71 m2"``, largest weights first."""
    v = direction / (np.max(np.abs(direction)) or 1.0)
    v = v * np.sign(v[np.argmax(np.abs(v))])
    v = v / np.linalg.norm(v)
    order = np.argsort(-np.abs(v))
    return " ".join(f"{v[k]:+.2f} {names[k]}" for k in order if abs(v[k]) >= 0.05)


def correlated_uncertainty(
    unc: LocalUncertainty,
    *,
    jacobian: ArrayLike,
    residuals: ArrayLike,
    block: int,
    records: Sequence[int],
    max_lag: int,
) -> LocalUncertainty:
    """The same estimate with the covariance of residuals correlated in time (Newey-West sandwich).

    ``cov = P S P`` with ``P = (J^T J)^+`` (on the determined subspace, as in :func:`jacobian_uncertainty`) and
    ``S = sum_|l|<=L (1 - |l| / (L + 1)) sum_t g_t g_{t-l}^T``, ``g_t = J_t^T r_t`` the contribution of time step
    ``t`` (``block`` residuals: one per output), summed within each record; scaled by ``n_obs / (n_obs - n_p)``.
    With white residuals it equals the Gauss-Newton covariance up to sampling noise; with coloured residuals
    (coloured noise, slight model error) it is the asymptotic covariance of least squares that the Gauss-Newton
    formula underestimates.

    Parameters
    ----------
    unc : LocalUncertainty
        The Gauss-Newton result at the optimum (:func:`jacobian_uncertainty`).
    jacobian : array_like, shape (n_obs, n_p)
        ``d r / d p`` at the optimum (SI), rows ordered time-major: ``block`` rows per time step.
    residuals : array_like, shape (n_obs,)
        Residuals at the optimum, in the same order.
    block : int
        Residuals per time step (the number of outputs).
    records : sequence of int
        Time steps of each record, in order (correlations are not summed across records).
    max_lag : int
        Bandwidth ``L`` in time steps (>= 0).

    Returns
    -------
    LocalUncertainty
        With the sandwich covariance, its standard errors, Student-t intervals and correlations.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> x = np.linspace(0, 1, 400)[:, None]
    >>> r = np.convolve(rng.standard_normal(420), np.ones(20) / 20, mode="valid")[:400]  # strongly coloured
    >>> base = jacobian_uncertainty(names=["a"], values=[1.0], jacobian=x, residuals=r)
    >>> hac = correlated_uncertainty(base, jacobian=x, residuals=r, block=1, records=[400], max_lag=40)
    >>> bool(hac.std[0] > 2 * base.std[0])
    True
    """
    jac = np.atleast_2d(np.asarray(jacobian, dtype=float))
    r = np.asarray(residuals, dtype=float).ravel()
    n_obs, n_p = jac.shape
    s2 = float(r @ r) / unc.dof
    p_inv = unc.covariance / s2 if s2 > 0 else np.zeros((n_p, n_p))
    meat = newey_west_meat(jacobian=jac, residuals=r, block=block, records=records, max_lag=max_lag)
    meat *= n_obs / max(n_obs - n_p, 1)
    cov = p_inv @ meat @ p_inv
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    std = np.where(unc.identifiable | np.isfinite(unc.std), std, np.nan)
    t = float(stats.t.ppf(0.975, unc.dof))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std)
    corr = np.where(np.isfinite(unc.correlation), corr, np.nan)
    np.fill_diagonal(corr, 1.0)
    ci95 = np.column_stack([unc.values - t * std, unc.values + t * std])
    return LocalUncertainty(unc.names, unc.values, cov, std, ci95, corr, unc.identifiable, unc.rank,
                            unc.condition_number, unc.singular_values, unc.combinations, unc.dof)


def newey_west_meat(
    *, jacobian: ArrayLike, residuals: ArrayLike, block: int, records: Sequence[int], max_lag: int
) -> Array:
    """The Newey-West estimate ``S = sum_|l|<=L (1 - |l| / (L + 1)) sum_t g_t g_{t-l}^T`` of the scores' covariance.

    ``g_t = J_t^T r_t`` is the contribution of time step ``t`` (``block`` residuals) to the gradient; the sums stay
    within each record. The sandwich covariance of a least-squares or likelihood fit is ``B^-1 S B^-1`` with its
    bread ``B`` (``J^T J``, or the regularized information of a filter).

    Parameters
    ----------
    jacobian : array_like, shape (n_obs, n_p)
        ``d r / d p``, rows ordered time-major: ``block`` rows per time step.
    residuals : array_like, shape (n_obs,)
        Residuals in the same order.
    block : int
        Residuals per time step.
    records : sequence of int
        Time steps of each record, in order.
    max_lag : int
        Bandwidth ``L`` in time steps (>= 0).

    Returns
    -------
    ndarray, shape (n_p, n_p)
        ``S``.

    Examples
    --------
    >>> j, r = np.ones((4, 1)), np.array([1.0, -1.0, 1.0, -1.0])
    >>> float(newey_west_meat(jacobian=j, residuals=r, block=1, records=[4], max_lag=0)[0, 0])  # sum of r^2
    4.0
    """
    jac = np.atleast_2d(np.asarray(jacobian, dtype=float))
    r = np.asarray(residuals, dtype=float).ravel()
    n_p = jac.shape[1]
    g_all = np.einsum("tbp,tb->tp", jac.reshape(-1, block, n_p), r.reshape(-1, block))
    meat = np.zeros((n_p, n_p))
    start = 0
    for steps in records:
        g = g_all[start: start + steps]
        start += steps
        meat += g.T @ g
        for lag in range(1, min(int(max_lag), steps - 1) + 1):
            gamma = g[lag:].T @ g[:-lag]
            meat += (1.0 - lag / (max_lag + 1.0)) * (gamma + gamma.T)
    return meat


def newey_west_bandwidth(records: Sequence[int], analysis: Any) -> int:
    """Bandwidth of :func:`newey_west_meat` from a residual analysis (``ResidualAnalysis.to_dict()``).

    Twice the lag beyond which every output's residual autocorrelation stays inside its 99 % bound, at least the
    Newey-West rule ``4 (N / 100)^(2/9)`` and at most N / 10 (N the shortest record) or 500 time steps.

    Parameters
    ----------
    records : sequence of int
        Time steps of each record.
    analysis : mapping
        The residual analysis (its ``autocorrelation`` and ``auto_bound``); without them the rule alone.

    Returns
    -------
    int
        The bandwidth in time steps.

    Examples
    --------
    >>> newey_west_bandwidth([6000], {})  # twice the rule's 9 where no autocorrelation is given
    18
    """
    n = min(records)
    rule = int(np.floor(4 * (sum(records) / 100) ** (2 / 9)))
    inside = rule
    if "autocorrelation" in analysis:
        acf = np.abs(np.asarray(analysis["autocorrelation"], dtype=float))[:, 1:]
        outside = np.flatnonzero(np.any(acf > float(analysis["auto_bound"]), axis=0))
        inside = int(outside.max()) + 2 if outside.size else 0
    return int(min(max(rule, 2 * inside), n // 10, 500))
