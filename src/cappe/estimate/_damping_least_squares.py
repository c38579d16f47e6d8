"""Stage 3 of the automated identification: damping by bounded linear least squares (Ellinger & Zaeh 2022,
section 2.3.3, eqs 11-13).

At the identified stiffness, the first-order damping ratio of every mode is ``zeta_r = zeta_known,r + sum_n q_rn
p_n`` with ``q_rn = d zeta_r / d p_n`` at fixed modes (:attr:`cappe.modal.ModalBatch.damping_gradient`; exact for
coefficients linear in the damping unknowns, as ``c`` and ``eta * k`` are). Rows are the mode-position pairs; the
paper's selection keeps those with the least influence of the other unknowns on their NDD^2 whose residual damping
``zeta_ref - zeta_known`` reaches a threshold, enough of them for full column rank. Each row is divided by
``zeta_ref`` (the residual is then the NDD).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import lsq_linear

from cappe.estimate._validation import _pair
from cappe.exceptions import DataError
from cappe.modal import ModalEngine
from cappe.model import NumericModel
from cappe.systems.modal import ModalData

__all__ = ["DampingLeastSquares", "damping_least_squares"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class DampingLeastSquares:
    """Result of the linear least-squares damping stage (paper eqs 11-13).

    Attributes
    ----------
    names : tuple of str
        Damping unknowns.
    values : ndarray, shape (n_d,)
        Estimates (SI).
    rows : list of dict
        Every mode-position row: ``set``, ``mode`` (1-based), ``position``, ``zeta_reference``, ``zeta_known``,
        ``zeta_residual``, ``interaction`` (non-search influence on NDD^2, NaN if unknown) and ``selected``.
    q : ndarray, shape (n_rows, n_d)
        ``d zeta / d p`` of every row (paper eq. 13, Q).
    residual : ndarray, shape (n_selected,)
        NDD residuals of the selected rows at the estimate.
    rank : int
        Column rank of the selected rows.
    condition_number : float
        Of the scaled least-squares matrix.
    active_bounds : tuple of str
        Unknowns that ended at a bound.
    """

    names: tuple[str, ...]
    values: Array
    rows: list[dict[str, Any]]
    q: Array
    residual: Array
    rank: int
    condition_number: float
    active_bounds: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        return {
            "values": dict(zip(self.names, self.values.tolist(), strict=True)),
            "rows": self.rows,
            "selected": int(sum(1 for r in self.rows if r["selected"])),
            "rank": self.rank,
            "condition_number": self.condition_number,
            "residual_rms": float(np.sqrt(np.mean(self.residual**2))) if self.residual.size else 0.0,
            "active_bounds": list(self.active_bounds),
        }


def damping_least_squares(
    *,
    model: NumericModel,
    reference: ModalData,
    params: Array,
    damping: Sequence[str],
    lower: ArrayLike,
    upper: ArrayLike,
    sets: Sequence[int] | None = None,
    interaction: Mapping[tuple[int, int], float] | None = None,
    n_rows: int | None = None,
    residual_threshold: float = 0.005,
) -> DampingLeastSquares:
    """Damping unknowns from modal damping ratios at fixed modes: bounded linear least squares (paper eqs 11-13).

    Parameters
    ----------
    model : NumericModel
    reference : ModalData
        Reference modes (damping ratios > 0).
    params : ndarray, shape (n_params,)
        Full parameter vector: identified stiffness; the damping unknowns' entries only linearize (exact when
        the damping coefficients are linear in them).
    damping : sequence of str
        Damping unknowns.
    lower, upper : sequence of float
        Their bounds.
    sets : sequence of int, optional
        Reference sets used (default all).
    interaction : mapping (set, mode) -> float, optional
        Influence of the non-search unknowns on each row's NDD^2 (from the GSA; lower is better).
        Without it every row passing the residual threshold is used.
    n_rows : int, optional
        Rows to select (default ``max(2 n_d, n_candidates // 3)``, more if needed for full column rank).
    residual_threshold : float
        Smallest residual damping ratio ``zeta_ref - zeta_known`` of a used row (paper: 0.005). Rows below it are
        used only when the others do not determine every unknown.

    Returns
    -------
    DampingLeastSquares

    Examples
    --------
    >>> from cappe.model import load_model
    >>> nm = NumericModel(load_model("builtin:two-mass-rig"))
    >>> truth = nm.vector({"c11": 20.0, "c22": 1.5})
    >>> ref = ModalEngine(nm).modal_data(params=truth, exact=False)
    >>> res = damping_least_squares(model=nm, reference=ref, params=nm.nominal, damping=["c11", "c22"],
    ...                             lower=[1.0, 0.1], upper=[50.0, 5.0], residual_threshold=0.0)
    >>> res.values.round(6)
    array([20. ,  1.5])
    """
    names = tuple(damping)
    cols = np.array([model.parameter_names.index(n) for n in names], dtype=np.intp)
    lo, hi = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    used_sets = list(range(len(reference.sets))) if sets is None else list(sets)
    p = np.asarray(params, dtype=float)
    rows, q = _damping_rows(model, reference, p, cols, used_sets, interaction)
    zeta_ref = np.array([r["zeta_reference"] for r in rows])
    zeta_res = np.array([r["zeta_residual"] for r in rows])
    scale = np.where(np.isfinite(hi), np.abs(hi), np.maximum(np.abs(p[cols]), 1.0))
    a_all = q / zeta_ref[:, None] * scale[None, :]
    inter_all = np.array([r["interaction"] for r in rows])
    order = np.argsort(np.where(np.isfinite(inter_all), inter_all, np.inf), kind="stable")
    passing = [i for i in order if zeta_res[i] >= residual_threshold]
    failing = [i for i in order if zeta_res[i] < residual_threshold]
    target = n_rows if n_rows is not None else (max(2 * cols.size, len(passing) // 3) if interaction else len(passing))
    chosen = _chosen_rows(a_all, passing, failing, target)
    for i in chosen:
        rows[i]["selected"] = True
    a = a_all[chosen]
    b = zeta_res[chosen] / zeta_ref[chosen]
    if not chosen:
        msg = "no mode-position rows for the damping least squares"
        raise DataError(msg)
    sol = lsq_linear(a, b, bounds=(lo / scale, hi / scale), method="bvls")
    values = np.asarray(sol.x * scale, dtype=float)
    sv = np.linalg.svd(a, compute_uv=False)
    cond = float(sv[0] / sv[-1]) if sv.size and sv[-1] > 0 else float("inf")
    at_bound = tuple(n for n, v, lo_i, hi_i in zip(names, values, lo, hi, strict=True)
                     if np.isclose(v, lo_i, rtol=1e-9) or np.isclose(v, hi_i, rtol=1e-9))
    return DampingLeastSquares(names, values, rows, q, np.asarray(a @ sol.x - b, dtype=float), _rank(a_all, chosen),
                               cond, at_bound)


def _damping_rows(
    model: NumericModel,
    reference: ModalData,
    p: Array,
    cols: NDArray[np.intp],
    sets: Sequence[int],
    interaction: Mapping[tuple[int, int], float] | None,
) -> tuple[list[dict[str, Any]], Array]:
    """One row per mode of every used set: its record (see :class:`DampingLeastSquares`) and ``d zeta / d p``
    (n_rows, n_d) of the damping unknowns ``cols`` at ``p``, model modes paired with the reference by MACXP."""
    engine = ModalEngine(model, sensors=list(reference.sensors))
    rows: list[dict[str, Any]] = []
    q_rows: list[Array] = []
    for j in sets:
        data_set = reference.sets[j]
        if np.any(data_set.damping <= 0):
            msg = (f"reference set {j} (position {data_set.position}) has damping ratios <= 0; the damping stage "
                   "needs > 0")
            raise DataError(msg)
        position = model.structure.resolve_position(data_set.position)
        batch = engine.evaluate(p, position, contributions=True)
        assert batch.damping_gradient is not None  # contributions=True
        model_of, _ = _pair(batch.shapes[0].astype(complex), batch.first_order_poles[0], data_set)
        grad = batch.damping_gradient[0][model_of][:, cols]  # (m, n_d)
        known = batch.damping[0][model_of] - grad @ p[cols]
        for r in range(data_set.n_modes):
            inter = float("nan") if interaction is None else float(interaction.get((j, r), np.nan))
            rows.append({"set": j, "mode": r + 1, "position": dict(data_set.position),
                         "zeta_reference": float(data_set.damping[r]), "zeta_known": float(known[r]),
                         "zeta_residual": float(data_set.damping[r] - known[r]), "interaction": inter,
                         "selected": False})
            q_rows.append(grad[r])
    return rows, np.array(q_rows).reshape(len(rows), cols.size)


def _rank(a_all: Array, idx: list[int]) -> int:
    return int(np.linalg.matrix_rank(a_all[idx])) if idx else 0


def _chosen_rows(a_all: Array, passing: list[int], failing: list[int], target: int) -> list[int]:
    """The paper's row selection: rows in order (``passing`` the residual threshold first) until ``target`` rows
    with full column rank; a failing row only where it raises the rank."""
    n_d = a_all.shape[1]
    chosen: list[int] = []
    for i in passing + failing:
        if len(chosen) >= target and _rank(a_all, chosen) == n_d:
            break
        if i in failing and _rank(a_all, chosen) == n_d:
            break
        if i in failing and _rank(a_all, [*chosen, i]) == _rank(a_all, chosen):
            continue
        chosen.append(i)
    return chosen
