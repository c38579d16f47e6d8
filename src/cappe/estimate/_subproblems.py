"""Stage 2 of the automated identification: the stiffness subproblems (Ellinger & Zaeh 2022, section 2.3.2).

For every mode-position pair whose MACXP has significant modal unknowns, ``n_opt`` local searches run over those
unknowns, the others drawn at random in their bounds. The objective of subproblem (r, j) is the agreement of the
model mode paired with reference mode r at position j (largest MACXP): ``J = w_f NFD^2 + w_s (1 - MAC)``,
``NFD = (f_m - f_r) / f_r``. The runs are one batch: projected Levenberg-Marquardt in log coordinates with analytic
eigenvalue and eigenvector derivatives (modal expansion), every iteration one batched eigen solution for all runs.
:func:`select_stiffness` then takes each unknown from the subproblem where its optimum spreads least over the runs.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cappe.correlate import macxp_batch
from cappe.estimate._space import ParameterSpace
from cappe.exceptions import ModelError
from cappe.io.modal import ModalData, ModalDataSet
from cappe.modal import ModalEngine, mode_derivative_terms
from cappe.model import NumericModel

__all__ = ["StiffnessChoice", "SubproblemResult", "select_stiffness", "solve_subproblem"]

Array = NDArray[np.float64]
_STEP = 1e-6  # relative step of the central differences of M and K (exact for matrices affine in a parameter)


@dataclass(frozen=True)
class SubproblemResult:
    """The ``n_opt`` local searches of one mode-position subproblem.

    Attributes
    ----------
    mode : int
        Reference mode (1-based, as in the paper).
    position : dict
        Axis position.
    parameters : tuple of str
        Searched (significant modal) unknowns.
    values : ndarray, shape (n_opt, n_search)
        Optimum of every run (SI).
    cost : ndarray, shape (n_opt,)
        Final objective ``w_f NFD^2 + w_s (1 - MAC)`` of every run.
    iterations : int
        Batched Levenberg-Marquardt iterations (every one a batched eigen solution of all active runs).
    seconds : float
        Wall time.
    lower, upper : ndarray, shape (n_search,), optional
        Bounds of the searched unknowns (to tell runs that ended at a bound).
    """

    mode: int
    position: dict[str, float]
    parameters: tuple[str, ...]
    values: Array
    cost: Array
    iterations: int
    seconds: float
    lower: Array | None = None
    upper: Array | None = None

    @property
    def median(self) -> Array:
        return np.asarray(np.median(self.values, axis=0), dtype=float)

    @property
    def at_bound(self) -> Array:
        """Fraction of the runs whose optimum lies at a bound (relative 1e-6), per searched unknown."""
        if self.lower is None or self.upper is None:
            return np.zeros(len(self.parameters))
        hit = (self.values <= self.lower * (1 + 1e-6)) | (self.values >= self.upper * (1 - 1e-6))
        return np.asarray(np.mean(hit, axis=0), dtype=float)

    @property
    def spread(self) -> Array:
        """Relative standard deviation of each searched unknown's optimum over the runs; ``inf`` where half the
        runs or more ended at a bound (the bound, not the data, held them: no evidence of a determined optimum)."""
        spread = np.std(self.values, axis=0) / np.abs(self.median)
        return np.asarray(np.where(self.at_bound >= 0.5, np.inf, spread), dtype=float)

    def to_dict(self) -> dict[str, Any]:
        return {
            "mode": self.mode,
            "position": dict(self.position),
            "parameters": list(self.parameters),
            "median": dict(zip(self.parameters, self.median.tolist(), strict=True)),
            "mean": dict(zip(self.parameters, np.mean(self.values, axis=0).tolist(), strict=True)),
            "spread": dict(zip(self.parameters, self.spread.tolist(), strict=True)),
            "at_bound": dict(zip(self.parameters, self.at_bound.tolist(), strict=True)),
            "cost_median": float(np.median(self.cost)),
            "cost_min": float(np.min(self.cost)),
            "runs": int(self.cost.size),
            "iterations": self.iterations,
            "seconds": self.seconds,
        }


def _constant_derivatives(model: NumericModel, position: Mapping[str, float],
                          columns: NDArray[np.intp]) -> tuple[Array, Array] | None:
    """``(dK/dp, dM/dp)`` (n_search, n, n) when K and M are linear in the searched parameters, else None.

    Linear (the usual case: stiffnesses and masses enter as coefficients of constant patterns) means the exact
    derivatives of :meth:`NumericModel.matrix_derivatives` are the same at two different parameter vectors; the
    subproblem's Jacobian then needs no matrix assembly per sample (else it differentiates the batch centrally).
    """
    base = model.nominal
    searched = [model.parameter_names[c] for c in columns]
    first = model.matrix_derivatives(base, position, names=("K", "M"), parameters=searched)
    second = model.matrix_derivatives(base * 1.37, position, names=("K", "M"), parameters=searched)
    out = []
    for name in ("K", "M"):
        a, b = first[name], second[name]
        if not np.allclose(a, b, rtol=1e-12, atol=1e-12 * max(float(np.abs(a).max()), 1e-300)):
            return None
        out.append(a)
    return out[0], out[1]


def _mode_problem(
    engine: ModalEngine,
    position: Mapping[str, float],
    data_set: ModalDataSet,
    mode: int,
    columns: NDArray[np.intp],
    weights: tuple[float, float],
) -> Callable[[Array], tuple[Array, Array]]:
    """Residuals (B, 1 + 2 n_s) and their Jacobian (B, 1 + 2 n_s, n_search) in SI units, for a batch of vectors."""
    model = engine.model
    x = data_set.shapes[:, mode] / np.linalg.norm(data_set.shapes[:, mode])
    f_ref = float(data_set.frequency[mode])
    pole_ref = data_set.poles[mode]
    sw_f, sw_s = np.sqrt(weights[0]), np.sqrt(weights[1])
    constant = _constant_derivatives(model, position, columns)
    stacked: tuple[Array, Array] | None = None
    if constant is not None:
        # (n, n_search * n): row j, column (i, l) holds dK_i[l, j], so phi_k @ stacked = (dK_i phi_k)_l for every i
        n_dof = model.n_dof
        stacked = (np.ascontiguousarray(constant[0].transpose(2, 0, 1).reshape(n_dof, -1)),
                   np.ascontiguousarray(constant[1].transpose(2, 0, 1).reshape(n_dof, -1)))

    def derivative_products(p: Array, phi_k: Array, lam: Array) -> tuple[Array, Array]:
        """``(dK_i - lam dM_i) phi_k`` and ``dM_i phi_k`` for every searched parameter i: (B, n_search, n) each."""
        b, n = phi_k.shape
        if stacked is not None:  # K and M linear in the searched parameters: constant derivatives, one product
            dm_phi = (phi_k @ stacked[1]).reshape(b, columns.size, n)
            g = (phi_k @ stacked[0]).reshape(b, columns.size, n) - lam[:, None, None] * dm_phi
            return g, dm_phi
        g, dm_phi = np.empty((b, columns.size, n)), np.empty((b, columns.size, n))
        for i, col in enumerate(columns):  # central differences of the batch's matrices
            h = _STEP * np.maximum(np.abs(p[:, col]), 1e-300)
            hi, lo = p.copy(), p.copy()
            hi[:, col] += h
            lo[:, col] -= h
            m_hi = model.matrices(hi, position, names=("M", "K"))
            m_lo = model.matrices(lo, position, names=("M", "K"))
            dk = (m_hi["K"] - m_lo["K"]) / (2 * h)[:, None, None]
            dm = (m_hi["M"] - m_lo["M"]) / (2 * h)[:, None, None]
            dm_phi[:, i] = (dm @ phi_k[:, :, None])[:, :, 0]
            g[:, i] = (dk @ phi_k[:, :, None])[:, :, 0] - lam[:, None] * dm_phi[:, i]
        return g, dm_phi

    def evaluate(p: Array) -> tuple[Array, Array]:
        b = p.shape[0]
        batch = engine.evaluate(p, position, full_shapes=True)
        freq, phi, a_all = batch.frequency, batch.full_shapes, batch.shapes
        assert phi is not None  # full_shapes=True
        valid = freq > 0
        poles = np.where(valid, batch.first_order_poles, 1j)
        crit = macxp_batch(a_all, poles, x[:, None], np.asarray(pole_ref)[None])[:, 0, :]
        k = np.argmax(np.where(valid, crit, -1.0), axis=1)
        rows = np.arange(b)
        lam_all = (2 * np.pi * freq) ** 2
        lam = lam_all[rows, k]
        phi_k = phi[rows, :, k]  # (B, n)
        a = a_all[rows, :, k]  # (B, n_s)
        f = freq[rows, k]
        c = a @ x  # (B,) complex
        aa = np.sum(a * a, axis=1)
        e = a * (c / aa)[:, None] - x[None, :]
        res = np.concatenate([(sw_f * (f - f_ref) / f_ref)[:, None], sw_s * e.real, sw_s * e.imag], axis=1)
        # modal expansion of the derivatives, all searched parameters at once (axis 1 of the (B, n_search, .) arrays)
        omega = np.sqrt(lam)
        g, dm_phi = derivative_products(p, phi_k, lam)
        proj = g @ phi  # (B, n_search, m): phi_s^T (dK_i - lam dM_i) phi_k
        d_lam, coef = mode_derivative_terms(lam_all, k, proj, (dm_phi @ phi_k[:, :, None])[:, :, 0])
        da = coef @ np.swapaxes(a_all, 1, 2)  # (B, n_search, n_s)
        d_f = d_lam / (2 * omega[:, None]) / (2 * np.pi)
        dc = da @ x  # (B, n_search)
        daa = 2 * (da @ a[:, :, None])[:, :, 0]
        de = (da * (c / aa)[:, None, None] + a[:, None, :] * (dc / aa[:, None])[:, :, None]
              - a[:, None, :] * (c[:, None] * daa / aa[:, None] ** 2)[:, :, None])  # (B, n_search, n_s)
        jac = np.empty((b, res.shape[1], columns.size))
        jac[:, 0, :] = sw_f * d_f / f_ref
        n_s = x.size
        jac[:, 1:1 + n_s, :] = sw_s * np.swapaxes(de.real, 1, 2)
        jac[:, 1 + n_s:, :] = sw_s * np.swapaxes(de.imag, 1, 2)
        return res, jac

    return evaluate


def solve_subproblem(
    *,
    model: NumericModel,
    reference: ModalData,
    set_index: int,
    mode: int,
    parameters: Sequence[str],
    start: Array,
    lower: ArrayLike,
    upper: ArrayLike,
    weights: tuple[float, float] = (1.0, 1.0),
    max_iterations: int = 50,
    engine: ModalEngine | None = None,
) -> tuple[Array, Array, int]:
    """Batched local searches of one mode-position subproblem (projected Levenberg-Marquardt, log coordinates).

    Minimizes ``w_f NFD^2 + w_s (1 - MAC)`` of reference mode ``mode`` (0-based) of set ``set_index`` over
    ``parameters`` for every row of ``start`` at once (see the module notes).

    Parameters
    ----------
    model : NumericModel
    reference : ModalData
    set_index, mode : int
        The reference set (position) and mode (0-based).
    parameters : sequence of str
        Searched parameters (positive, with ``0 < lower < upper``).
    start : ndarray, shape (B, n_params)
        Full parameter vectors of the runs: the searched entries are the starts, the others stay fixed.
    lower, upper : sequence of float
        Bounds of the searched parameters.
    weights : (float, float)
        ``(w_f, w_s)``.
    max_iterations : int
        Iteration limit.
    engine : ModalEngine, optional
        An engine at the reference's sensors (made if not given).

    Returns
    -------
    values : ndarray, shape (B, n_search)
        Optima (SI).
    cost : ndarray, shape (B,)
        Objective at the optima.
    iterations : int
        Iterations run.

    Examples
    --------
    >>> from cappe.model import load_model
    >>> nm = NumericModel(load_model("builtin:two-mass-rig"))
    >>> ref = ModalEngine(nm).modal_data(params={"k11": 1.5e6}, exact=False)
    >>> starts = np.tile(nm.nominal, (3, 1))
    >>> starts[:, nm.parameter_names.index("k11")] = [1.0e6, 1.3e6, 1.8e6]
    >>> values, cost, _ = solve_subproblem(model=nm, reference=ref, set_index=0, mode=1, parameters=["k11"],
    ...                                    start=starts, lower=[0.8e6], upper=[2.0e6])
    >>> np.allclose(values[:, 0], 1.5e6, rtol=1e-8)
    True
    """
    data_set = reference.sets[set_index]
    eng = engine if engine is not None else ModalEngine(model, sensors=list(reference.sensors))
    position = model.structure.resolve_position(data_set.position)
    columns = np.array([model.parameter_names.index(n) for n in parameters], dtype=np.intp)
    lo_p, hi_p = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    if not np.all((lo_p > 0) & (hi_p > lo_p)):
        msg = f"subproblem parameters {list(parameters)} need bounds 0 < lower < upper; got {lo_p}, {hi_p}"
        raise ModelError(msg)
    problem = _mode_problem(eng, position, data_set, mode, columns, weights)
    return _levenberg_marquardt(problem, np.array(start, dtype=float, copy=True), columns, np.log(lo_p),
                                np.log(hi_p), max_iterations)


def _levenberg_marquardt(problem: Callable[[Array], tuple[Array, Array]], p: Array, columns: NDArray[np.intp],
                         lo: Array, hi: Array, max_iterations: int) -> tuple[Array, Array, int]:
    """Projected Levenberg-Marquardt in ``u = log p`` for every row of ``p`` (B, n_params) at once.

    ``problem(p)`` gives the residuals (B, n_r) and their Jacobian (B, n_r, n_search) of a batch; the searched
    columns move within ``[lo, hi]`` (log bounds), the others stay. Every iteration is one batched evaluation of
    the runs still active (each run has its own damping ``mu`` and stops on its own).

    Kept rather than :func:`cappe.estimate.fit_least_squares` (scipy's trust-region reflective method, one run at
    a time) because it measurably wins for this batched use: the runs share one batched eigen solution per
    iteration. ``python -m benchmarks.bench_subproblem`` (one machine-tool subproblem, 7 stiffness unknowns, the
    same residuals and Jacobian, 2-core machine, one run): 20 runs 0.17 s against 0.94 s (5.6x), 100 runs 0.51 s
    against 4.0 s (7.9x), at the same median final cost (6.05e-3 / 6.04e-3).
    """
    u = np.clip(np.log(p[:, columns]), lo, hi)
    p[:, columns] = np.exp(u)
    r, j = problem(p)
    cost = np.sum(r**2, axis=1)
    b, s = u.shape
    mu = np.full(b, 1e-2)
    active = np.ones(b, dtype=bool)
    iterations = 0
    eye = np.eye(s)
    for _ in range(max_iterations):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        iterations += 1
        ju = j[idx] * p[idx][:, columns][:, None, :]  # dr/du = dr/dp * p
        jut = np.swapaxes(ju, 1, 2)
        g = (jut @ r[idx][:, :, None])[:, :, 0]
        hess = jut @ ju
        ui = u[idx]
        blocked = ((ui <= lo + 1e-12) & (g > 0)) | ((ui >= hi - 1e-12) & (g < 0))
        diag = np.diagonal(hess, axis1=1, axis2=2)
        damp = mu[idx, None] * np.maximum(diag, 1e-12 * np.maximum(diag.max(axis=1, keepdims=True), 1e-300))
        mat = hess + damp[:, :, None] * eye[None]
        free = ~blocked
        mat = np.where(free[:, :, None] & free[:, None, :], mat, eye[None] * 1.0)
        rhs = np.where(free, -g, 0.0)
        step = np.linalg.solve(mat, rhs[:, :, None])[:, :, 0]
        u_try = np.clip(ui + step, lo, hi)
        p_try = p[idx].copy()
        p_try[:, columns] = np.exp(u_try)
        r_try, j_try = problem(p_try)
        cost_try = np.sum(r_try**2, axis=1)
        better = cost_try < cost[idx]
        moved = np.max(np.abs(u_try - ui), axis=1)
        gain = cost[idx] - cost_try
        acc = idx[better]
        u[acc], p[acc], r[acc], j[acc], cost[acc] = u_try[better], p_try[better], r_try[better], j_try[better], \
            cost_try[better]
        mu[idx] = np.where(better, np.maximum(mu[idx] / 3, 1e-10), mu[idx] * 4)
        done = (better & ((gain <= 1e-8 * np.maximum(cost[idx] + gain, 1e-300)) | (moved < 1e-7))) \
            | (mu[idx] > 1e8) | (cost[idx] < 1e-24)
        active[idx[done]] = False
    return np.asarray(p[:, columns], dtype=float), cost, iterations




@dataclass(frozen=True)
class StiffnessChoice:
    """The value of one modal unknown taken from the subproblem where its optimum spreads least (paper 2.3.2).

    Attributes
    ----------
    name : str
    value, mean : float
        Median and mean of the runs of the chosen subproblem (SI).
    spread : float
        Their relative standard deviation.
    subproblem : int
        Index of the chosen subproblem.
    mode : int
        Its reference mode (1-based).
    position : dict
        Its axis position.
    searched_in : int
        Subproblems that searched the unknown.
    """

    name: str
    value: float
    mean: float
    spread: float
    subproblem: int
    mode: int
    position: dict[str, float]
    searched_in: int

    def to_dict(self) -> dict[str, Any]:
        return {"value": self.value, "mean": self.mean, "spread": self.spread, "subproblem": self.subproblem,
                "mode": self.mode, "position": dict(self.position), "searched_in": self.searched_in}



def select_stiffness(
    subproblems: Sequence[SubproblemResult], names: Sequence[str]
) -> dict[str, dict[str, Any]]:
    """The paper's selection: for each name, the subproblem with the least relative spread; its median.

    Returns ``{name: {"value", "mean", "spread", "subproblem", "mode", "position", "searched_in"}}`` for the
    names searched in at least one subproblem where fewer than half of the runs ended at a bound
    (:meth:`StiffnessChoice.to_dict`).

    Parameters
    ----------
    subproblems : sequence of SubproblemResult
        The mode-position subproblems with their runs' final values (SI).
    names : sequence of str
        The modal unknowns to select.

    Returns
    -------
    dict
        As above; values in SI units.

    Examples
    --------
    >>> a = SubproblemResult(1, {"z": 0.0}, ("k",), np.array([[1.0], [1.2], [0.8]]), np.zeros(3), 1, 0.0)
    >>> b = SubproblemResult(2, {"z": 0.0}, ("k",), np.array([[2.0], [2.01], [1.99]]), np.zeros(3), 1, 0.0)
    >>> select_stiffness([a, b], ["k"])["k"]["value"]
    2.0
    """
    return {name: choice.to_dict() for name, choice in choose_stiffness(subproblems, names).items()}


def choose_stiffness(subproblems: Sequence[SubproblemResult], names: Sequence[str]) -> dict[str, StiffnessChoice]:
    """:func:`select_stiffness` as typed records."""
    out: dict[str, StiffnessChoice] = {}
    for name in names:
        best: tuple[float, int, int] | None = None
        count = 0
        for s, sub in enumerate(subproblems):
            if name not in sub.parameters:
                continue
            count += 1
            i = sub.parameters.index(name)
            spread = float(sub.spread[i])
            if not np.isfinite(spread):
                continue
            if best is None or spread < best[0]:
                best = (spread, s, i)
        if best is None:
            continue
        spread, s, i = best
        sub = subproblems[s]
        out[name] = StiffnessChoice(name, float(sub.median[i]), float(np.mean(sub.values[:, i])), spread, s,
                                    sub.mode, dict(sub.position), count)
    return out


def _alternative_starts(
    subproblems: Sequence[SubproblemResult],
    space: ParameterSpace,
    selected: Array,
    names: Sequence[str],
    n_starts: int,
) -> list[tuple[str, Array]]:
    """Starts of the stiffness refinement: the paper's selection, then the consensus (each unknown's median over
    the medians of all subproblems that determine it) and the rank-k selections (k-th least spread), distinct."""
    per_name: dict[str, list[tuple[float, float]]] = {}
    for sub in subproblems:
        for i, n in enumerate(sub.parameters):
            if n in names and np.isfinite(sub.spread[i]):
                per_name.setdefault(n, []).append((float(sub.spread[i]), float(sub.median[i])))
    for n in per_name:
        per_name[n].sort()
    out = [("selection", selected.copy())]
    consensus = selected.copy()
    for n, found in per_name.items():
        consensus[space.names.index(n)] = float(np.median([v for _, v in found]))
    out.append(("consensus", consensus))
    k = 1
    while len(out) < n_starts and any(len(v) > k for v in per_name.values()):
        vector = selected.copy()
        for n, found in per_name.items():
            vector[space.names.index(n)] = found[min(k, len(found) - 1)][1]
        out.append((f"rank {k}", vector))
        k += 1
    unique: list[tuple[str, Array]] = []
    for label, vector in out[:max(n_starts, 1)]:
        vector = np.clip(vector, space.lower, space.upper)
        if not any(np.allclose(vector, v, rtol=1e-12, atol=0) for _, v in unique):
            unique.append((label, vector))
    return unique
