"""Modal updating: physical parameters from reference modes (cappe.modal/1) at one or several axis positions.

For every reference set (axis position) and reference mode r, paired with model mode m(r), the residuals are

- ``sqrt(w_f) (f_m - f_r) / f_r``: relative frequency error (the natural frequency difference, NFD);
- ``sqrt(w_z) (zeta_m - zeta_r) / zeta_r``: relative damping error, whose square is the paper's NDD^2 (eq. 5);
- ``sqrt(w_s) (a (a^T x) / (a^T a) - x)`` (real and imaginary parts): the reference shape ``x`` (unit norm,
  complex) minus its projection on the model shape ``a`` (real, at the reference's sensors). Its squared norm is
  ``1 - MAC(a, x)``, so the cost equals :class:`cappe.sensitivity.ModalCost` (``w_f NFD^2 + w_z NDD^2 +
  w_s (1 - MAC)`` summed over positions and modes) while staying smooth at a perfect match, where
  ``sqrt(1 - MAC)`` is not.

Model modes are, by default (``modes="exact"``), the exact complex modes of the state-space model (all viscous,
hysteretic and gyroscopic terms: what a measurement or ``cappe simulate`` gives), compared by
:class:`~cappe.estimate.ExactModalProblem` with a shape residual ``a (a^H x) / (a^H a) - x`` and an analytic
Jacobian from the perturbation of the state matrix's eigen-decomposition. With ``modes="first-order"`` they are
the undamped modes with first-order (energy) damping ratios of :class:`cappe.modal.ModalEngine` (light damping,
assumption A1 of the 2022 paper), the Jacobian analytic from :meth:`~cappe.modal.ModalEngine.derivatives`
(frequency, damping and shape derivatives). Against exact modes this approximation biases the estimate (about 1 %
on a stiffness of the uniaxial machine tool, several standard errors): the fit then estimates that bias to first
order (the first-order minus the exact model's residuals at the estimate, through the pseudo-inverse of the
Jacobian), reports it in ``diagnostics["modes"]`` and warns where it exceeds a tenth of a standard error.
Modes are paired afresh
at every evaluation by an optimal one-to-one assignment (:func:`cappe.correlate.pair_modes`), so a pairing
survives large parameter changes and modes that trade places. The criterion is MACXP by default (eq. 4 of the
paper: shape similarity weighted by pole proximity), which keeps nearly repeated modes (x and y bending of a
round spindle) apart where shapes alone are ambiguous. Far from the optimum its pole weighting dominates: a model
mode 50 % off in frequency pairs with whichever reference mode is nearest in frequency; ``pairing="mac"`` pairs
by shape alone instead. Sets whose reference or model damping is zero use the MAC (MACXP degenerates for
undamped poles). Local least squares cannot carry two modes through a crossing (the shapes mix there and the
shape residual rises between the valleys); ``starts`` adds random starts for such cases.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from cappe._rng import RandomLike
from cappe.correlate import mac, macxp, pair_modes
from cappe.estimate._base import Estimator, Fitted, least_squares_fit
from cappe.estimate._exact_modal import ExactModalProblem
from cappe.estimate._one_step import random_starts
from cappe.estimate._space import ParameterSpace
from cappe.exceptions import DataError, ModelError
from cappe.modal import ModalEngine
from cappe.model import NumericModel, Structure
from cappe.systems.modal import ModalData, ModalDataSet

__all__ = ["ModalUpdatingEstimator"]

Array = NDArray[np.float64]
CArray = NDArray[np.complex128]
_PAIRINGS = ("macxp", "mac")
_MODES = ("exact", "first-order")
# the residuals are relative errors computed in double precision: the minimum of their squared sum is located only
# to about sqrt(eps) (a cost known to eps), so the uncertainty assumes at least that residual level; without it a
# noise-free fit (residuals ~1e-11 where round-off, not noise, is left) claims intervals of ~1e-13 around an estimate
# 1e-10 off (measured on the uniaxial machine tool: 21 of 27 intervals missed the truth)
MODAL_VARIANCE_FLOOR = float(np.finfo(float).eps)
# a first-order bias above this fraction of a standard error is warned about (the 95 % interval then under-covers)
_BIAS_WARNING = 0.1


@dataclass(frozen=True)
class _Pairing:
    """Model mode of every reference mode of one set, and the pairing criterion used."""

    model: NDArray[np.intp]
    values: Array
    criterion: str


@dataclass(frozen=True)
class _ModalProblem:
    """Residuals (n_obs,), Jacobian (n_obs, n) and the pairings of an SI parameter vector (n,)."""

    engine: ModalEngine
    weights: tuple[float, float, float]
    residuals: Callable[[Array], Array]
    jacobian: Callable[[Array], Array]
    pairings: Callable[[Array], list[_Pairing]]


def check_finite_modes(where: str, data_set: ModalDataSet, *, shapes: bool = True) -> None:
    """Reference modes built in memory are not checked on construction (files are, by :mod:`cappe.io`): refuse a
    NaN or infinite frequency, damping ratio or (with ``shapes``) shape entry before it reaches a search, naming the
    set and the modes (1-based)."""
    checked: list[tuple[str, NDArray[Any]]] = [("frequencies", data_set.frequency),
                                               ("damping ratios", data_set.damping)]
    if shapes:
        checked.append(("shapes", data_set.shapes))
    for what, values in checked:
        values = np.asarray(values)
        bad = ~np.isfinite(values) if values.ndim == 1 else ~np.all(np.isfinite(values), axis=0)
        if np.any(bad):
            msg = f"{where}: modes {(np.flatnonzero(bad) + 1).tolist()} have non-finite {what} (NaN or inf)"
            raise DataError(msg)


def _poles(freq: Array, zeta: Array) -> CArray:
    w = 2 * np.pi * freq
    return np.asarray(-zeta * w + 1j * w * np.sqrt(np.clip(1 - zeta**2, 0, None)), dtype=complex)


class ModalUpdatingEstimator(Estimator):
    """Estimate physical parameters from reference modal data (frequencies, damping ratios, shapes).

    Parameters
    ----------
    model, unknowns, bounds, start, values, rng
        See :class:`Estimator`.
    weights : (float, float, float)
        ``(w_f, w_z, w_s)``: weights of the frequency, damping and shape residuals (see the module notes);
        ``(1, 0, 0)`` fits frequencies only.
    pairing : {"macxp", "mac"}
        Criterion of the mode pairing, repeated at every evaluation (see the module notes).
    n_modes : int, optional
        Number of (lowest) model modes that may be paired (default all).
    starts : int
        Number of starts (the start, plus random points in the bounds drawn with ``rng``).
    modes : {"exact", "first-order"}
        Model modes compared with the reference (see the module notes): the exact complex modes (default; like
        measured modes) or first-order ones (undamped modes with energy damping ratios), whose bias against exact
        modes is then estimated, reported and warned about.
    bias_check : bool
        With first-order modes: estimate their bias against exact ones by a local refit on exact modes from the
        first-order estimate (default). The automated identification turns it off: its own final refinement is
        on exact modes.

    Attributes
    ----------
    estimate_ : ParameterEstimate
        ``diagnostics["pairing"]`` lists, per set, the model mode paired with each reference mode, the criterion
        value and the MAC at the estimate; ``diagnostics["modes"]`` names the model modes compared and, for
        first-order ones, their estimated bias against exact modes.

    Examples
    --------
    >>> from cappe.model import load_model
    >>> model = load_model("builtin:two-mass-rig")
    >>> reference = ModalEngine(model).modal_data(params={"k11": 1.6e6, "c22": 0.9})  # exact complex modes
    >>> est = ModalUpdatingEstimator(model, ["k11", "c22"]).fit(reference)
    >>> {k: round(v, 6) for k, v in est.params_.items()}
    {'k11': 1600000.0, 'c22': 0.9}
    """

    method: ClassVar[str] = "modal"

    def __init__(
        self,
        model: NumericModel | Structure,
        unknowns: Sequence[str] | None = None,
        *,
        bounds: Mapping[str, Sequence[float]] | None = None,
        start: Mapping[str, float] | None = None,
        values: Mapping[str, float] | None = None,
        rng: RandomLike = None,
        weights: tuple[float, float, float] = (1.0, 1.0, 1.0),
        pairing: str = "macxp",
        n_modes: int | None = None,
        starts: int = 1,
        modes: str = "exact",
        bias_check: bool = True,
    ) -> None:
        super().__init__(model, unknowns, bounds=bounds, start=start, values=values, rng=rng)
        self.weights = weights
        self.pairing = pairing
        self.n_modes = n_modes
        self.starts = starts
        self.modes = modes
        self.bias_check = bias_check

    # -- validation ----------------------------------------------------------------------------------------
    def _check(self, model: NumericModel, data: Any) -> tuple[float, float, float]:
        if not isinstance(data, ModalData):
            msg = f"modal updating needs ModalData (cappe.modal/1); got {type(data).__name__}"
            raise DataError(msg)
        if not data.sets:
            msg = "modal data have no sets; modal updating needs at least one set of reference modes"
            raise DataError(msg)
        try:
            w_f, w_z, w_s = (float(w) for w in self.weights)
        except (TypeError, ValueError) as exc:
            msg = f"weights must be three numbers (w_f, w_z, w_s); got {self.weights!r}"
            raise DataError(msg) from exc
        if not all(np.isfinite(w) and w >= 0 for w in (w_f, w_z, w_s)) or w_f + w_z + w_s == 0:
            msg = f"weights (w_f, w_z, w_s) must be finite, >= 0 and not all zero; got {self.weights!r}"
            raise DataError(msg)
        if self.pairing not in _PAIRINGS:
            msg = f"pairing must be one of {_PAIRINGS}; got {self.pairing!r}"
            raise DataError(msg)
        if self.modes not in _MODES:
            msg = f"modes must be one of {_MODES}; got {self.modes!r}"
            raise DataError(msg)
        labels, _ = model.sensor_matrix()
        missing = [s for s in data.sensors if s not in labels]
        if missing:
            msg = (
                f"modal data sensors {missing} are not sensor channels of model '{model.structure.name}'; "
                f"its channels are {labels}"
            )
            raise DataError(msg)
        n_model = model.n_dof if self.n_modes is None else int(self.n_modes)
        for k, data_set in enumerate(data.sets):
            where = f"modal data set {k} (position {data_set.position})"
            if data_set.n_modes == 0:
                msg = f"{where} has no modes"
                raise DataError(msg)
            if data_set.n_modes > n_model:
                msg = f"{where} has {data_set.n_modes} modes; the model offers only {n_model}"
                raise DataError(msg)
            check_finite_modes(where, data_set)
            if np.any(data_set.frequency <= 0):
                msg = f"{where}: reference frequencies must be > 0 Hz; got {data_set.frequency.tolist()}"
                raise DataError(msg)
            if w_z > 0 and np.any(data_set.damping <= 0):
                bad = np.flatnonzero(data_set.damping <= 0).tolist()
                msg = (
                    f"{where}: modes {bad} have damping ratio <= 0; the relative damping residual needs damping "
                    "> 0 (set the damping weight to 0 to fit frequencies and shapes only)"
                )
                raise DataError(msg)
            if w_s > 0 and np.any(np.sum(np.abs(data_set.shapes) ** 2, axis=0) == 0):
                bad = np.flatnonzero(np.sum(np.abs(data_set.shapes) ** 2, axis=0) == 0).tolist()
                msg = f"{where}: modes {bad} have all-zero shapes; the shape residual needs a shape"
                raise DataError(msg)
            try:
                model.position_vector(data_set.position)
            except ModelError as exc:
                msg = f"{where}: {exc}"
                raise DataError(msg) from exc
        return w_f, w_z, w_s

    # -- pairing -------------------------------------------------------------------------------------------
    def _pair(self, freq: Array, zeta: Array, shapes: Array, data_set: ModalDataSet) -> _Pairing:
        """Optimal one-to-one pairing of every reference mode with a visible, elastic model mode."""
        visible = np.flatnonzero((freq > 0) & (np.sum(shapes**2, axis=0) > 0))
        criterion = self.pairing
        if criterion == "macxp" and (np.any(zeta[visible] <= 0) or np.any(data_set.damping <= 0)):
            criterion = "mac"
        if visible.size < data_set.n_modes:
            msg = (
                f"only {visible.size} model modes are visible at the sensors at position {data_set.position}; "
                f"the reference has {data_set.n_modes}"
            )
            raise DataError(msg)
        a = shapes[:, visible]
        if criterion == "macxp":
            values = macxp(a, _poles(freq[visible], zeta[visible]), data_set.shapes, data_set.poles)
        else:
            values = mac(a, data_set.shapes)
        pairs = pair_modes(matrix=values, threshold=0.0)
        model_of = np.empty(data_set.n_modes, dtype=np.intp)
        model_of[pairs.index_x] = visible[pairs.index_a]
        crit = np.empty(data_set.n_modes)
        crit[pairs.index_x] = pairs.values
        return _Pairing(model_of, crit, criterion)

    # -- the fit -------------------------------------------------------------------------------------------
    def residuals(self, data: Any, values: Mapping[str, float] | None = None) -> Array:
        """The residual vector (see the module notes) for ``data`` at ``values`` of the unknowns (default: the
        start), without fitting: ``|r|^2`` is the cost :meth:`fit` minimizes.

        Parameters
        ----------
        data : ModalData
            Reference modes.
        values : mapping name -> float, optional
            Every unknown's value (SI).

        Returns
        -------
        ndarray, shape (n_residuals,)

        Examples
        --------
        >>> from cappe.model import load_model
        >>> model = load_model("builtin:two-mass-rig")
        >>> reference = ModalEngine(model).modal_data(params={"k11": 1.6e6})
        >>> r = ModalUpdatingEstimator(model, ["k11"]).residuals(reference, {"k11": 1.6e6})
        >>> bool(r @ r < 1e-20)
        True
        """
        numeric = self.model if isinstance(self.model, NumericModel) else NumericModel(self.model)
        space = ParameterSpace.from_model(numeric, self.unknowns, bounds=self.bounds, start=self.start,
                                          values=self.values)
        p = space.start if values is None else space.vector(values)
        if self.modes == "exact":
            return self._exact_problem(numeric, space, data).residuals(p)
        return self._problem(numeric, space, data).residuals(p)

    def _exact_problem(self, model: NumericModel, space: ParameterSpace, data: Any) -> ExactModalProblem:
        """Residuals and analytic Jacobian of the exact complex modes (the same residual layout as
        :meth:`_problem`), re-paired at every point."""
        weights = self._check(model, data)
        return ExactModalProblem(model, space, data, weights, pairing=self.pairing, n_modes=self.n_modes)

    def _problem(self, model: NumericModel, space: ParameterSpace, data: Any) -> _ModalProblem:
        """Residuals, analytic Jacobian and pairings over the unknowns (SI vectors), re-paired at every point."""
        w_f, w_z, w_s = self._check(model, data)
        engine = ModalEngine(model, sensors=list(data.sensors), n_modes=self.n_modes)
        sets: tuple[ModalDataSet, ...] = data.sets
        targets = []
        for data_set in sets:
            x = data_set.shapes / np.linalg.norm(data_set.shapes, axis=0, keepdims=True) if w_s > 0 else None
            targets.append(x)
        cols = np.arange(space.n)  # derivatives come for the unknowns only, in their order
        cache: dict[bytes, tuple[Array, Array, list[_Pairing]]] = {}

        def evaluate(p: Array) -> tuple[Array, Array, list[_Pairing]]:
            key = p.tobytes()
            if key in cache:
                return cache[key]
            params = space.full(p)
            res: list[Array] = []
            jac: list[Array] = []
            pairings = []
            for data_set, x in zip(sets, targets, strict=True):
                # pair on the modes alone, then differentiate only the paired ones (the expansion still runs over
                # every mode, so the derivatives are the same): on the three-axis machine 25 of 162 modes
                modes = engine.derivatives(params, data_set.position, parameters=[])
                pairing = self._pair(modes.frequency, modes.damping, modes.shapes, data_set)
                pairings.append(pairing)
                d = engine.derivatives(params, data_set.position, parameters=space.names, modes=pairing.model)
                idx = np.arange(pairing.model.size)
                if w_f > 0:
                    f_ref = data_set.frequency
                    res.append(np.sqrt(w_f) * (d.frequency[idx] - f_ref) / f_ref)
                    jac.append(np.sqrt(w_f) * d.d_frequency[idx][:, cols] / f_ref[:, None])
                if w_z > 0:
                    z_ref = data_set.damping
                    res.append(np.sqrt(w_z) * (d.damping[idx] - z_ref) / z_ref)
                    jac.append(np.sqrt(w_z) * d.d_damping[idx][:, cols] / z_ref[:, None])
                if x is not None:
                    e, de = _shape_residual(d.shapes[:, idx], d.d_shapes[:, idx][:, :, cols], x)
                    res.extend([np.sqrt(w_s) * e.real.ravel(), np.sqrt(w_s) * e.imag.ravel()])
                    jac.extend([np.sqrt(w_s) * de.real.reshape(-1, cols.size),
                                np.sqrt(w_s) * de.imag.reshape(-1, cols.size)])
            out = (np.concatenate(res), np.vstack(jac), pairings)
            cache.clear()
            cache[key] = out
            return out

        return _ModalProblem(engine, (w_f, w_z, w_s), lambda p: evaluate(p)[0], lambda p: evaluate(p)[1],
                             lambda p: evaluate(p)[2])

    def _fit(self, model: NumericModel, space: ParameterSpace, data: Any,
             rng: np.random.Generator) -> Fitted:
        if self.modes == "exact":
            return self._fit_exact(model, space, data, rng)
        problem = self._problem(model, space, data)
        engine, (w_f, w_z, w_s) = problem.engine, problem.weights
        sets: tuple[ModalDataSet, ...] = data.sets
        starts = random_starts(space, self.starts, rng)
        fitted = least_squares_fit(self.method, space, problem.residuals, problem.jacobian, starts=starts,
                                   variance_floor=MODAL_VARIANCE_FLOOR)
        result = fitted.estimate
        if not np.all(np.isfinite(result.values)):  # every start failed: nothing to pair or compare
            return fitted
        pairings = problem.pairings(np.asarray(result.values, dtype=float))
        report = []
        for data_set, pairing in zip(sets, pairings, strict=True):
            d = engine.derivatives(space.full(result.values), data_set.position)
            macs = [float(mac(d.shapes[:, m], data_set.shapes[:, r])[0, 0]) if np.any(d.shapes[:, m]) else 0.0
                    for r, m in enumerate(pairing.model)]
            report.append({
                "position": dict(data_set.position),
                "criterion": pairing.criterion,
                "model_mode": pairing.model.tolist(),
                "value": pairing.values.tolist(),
                "mac": macs,
                "frequency_error": ((d.frequency[pairing.model] - data_set.frequency) / data_set.frequency).tolist(),
            })
        diagnostics = dict(result.diagnostics)
        diagnostics.update({"pairing": report, "weights": [w_f, w_z, w_s], "sensors": list(data.sensors)})
        if not self.bias_check:
            diagnostics["modes"] = {"modes": "first-order", "bias": None}
            return fitted.with_estimate(replace(result, diagnostics=diagnostics))
        p = np.asarray(result.values, dtype=float)
        bias = _first_order_bias(fitted, self._exact_problem(model, space, data), space)
        diagnostics["modes"] = bias
        shift = np.array([bias["bias"].get(n, np.nan) for n in space.names]) * np.abs(p)
        known = np.isfinite(shift) & np.isfinite(result.std) & (result.std > 0)
        in_std = np.full(space.n, np.nan)
        in_std[known] = np.abs(shift[known]) / result.std[known]
        if not bias["bias"] or np.any(in_std[known] > _BIAS_WARNING):
            if bias["bias"]:
                worst = int(np.nanargmax(in_std))
                size = (f"up to {100 * bias['bias'][space.names[worst]]:+.3g} % on {space.names[worst]} "
                        f"({in_std[worst]:.3g} standard errors)")
            else:
                size = f"not known ({bias['note']})"
            text = (
                f"modal: the model modes are first-order (undamped modes with energy damping ratios); against exact "
                f"complex (measured) modes their bias is {size}, and the 95 % intervals do not include it; "
                "modes='exact' compares like with like"
            )
            diagnostics.setdefault("warnings", []).append(text)
            warnings.warn(text, UserWarning, stacklevel=3)
        return fitted.with_estimate(replace(result, diagnostics=diagnostics))

    def _fit_exact(self, model: NumericModel, space: ParameterSpace, data: Any,
                   rng: np.random.Generator) -> Fitted:
        problem = self._exact_problem(model, space, data)
        starts = random_starts(space, self.starts, rng)
        fitted = least_squares_fit(self.method, space, problem.residuals, problem.jacobian, starts=starts,
                                   variance_floor=MODAL_VARIANCE_FLOOR)
        result = fitted.estimate
        if not np.all(np.isfinite(result.values)):  # every start failed: nothing to pair
            return fitted
        p = np.asarray(result.values, dtype=float)
        full = space.full(p)[None, :]
        report = []
        for k, (data_set, pairing) in enumerate(zip(data.sets, problem.pairing_report(p), strict=True)):
            batch = problem.engine.evaluate(full, problem.positions[k], exact=True)
            assert batch.poles is not None  # exact=True
            assert batch.complex_shapes is not None
            idx = np.asarray(pairing["model_mode"], dtype=np.intp)
            lam = batch.poles[0, idx]
            shapes = batch.complex_shapes[0][:, idx]
            macs = [float(mac(shapes[:, r], data_set.shapes[:, r])[0, 0]) for r in range(idx.size)]
            pairing.update({
                "mac": macs,
                "frequency_error": (np.abs(lam) / (2 * np.pi) / data_set.frequency - 1).tolist(),
                "damping_error": (-lam.real / np.abs(lam) / data_set.damping - 1).tolist()
                if np.all(data_set.damping > 0) else None,
            })
            report.append(pairing)
        diagnostics = dict(result.diagnostics)
        diagnostics.update({"pairing": report, "weights": [float(w) ** 2 for w in problem.sqrt_w],
                            "sensors": list(data.sensors), "modes": {"modes": "exact"}})
        return fitted.with_estimate(replace(result, diagnostics=diagnostics))


def _shape_residual(a: Array, da: Array, x: CArray) -> tuple[CArray, CArray]:
    """Residual ``a (a^T x) / (a^T a) - x`` per mode and its derivative.

    Parameters: model shapes ``a`` (n_s, m) real, their derivatives ``da`` (n_s, m, n_p), unit reference shapes
    ``x`` (n_s, m) complex. Returns e (n_s, m) and de (n_s, m, n_p).
    """
    c = np.sum(a * x, axis=0)  # a^T x (m,)
    aa = np.sum(a * a, axis=0)
    e = a * (c / aa)[None, :] - x
    dc = np.einsum("smp,sm->mp", da, x)  # da^T x
    daa = 2 * np.einsum("sm,smp->mp", a, da)  # d(a^T a)
    de = (da * (c / aa)[None, :, None] + a[:, :, None] * (dc / aa[:, None])[None]
          - a[:, :, None] * (c[:, None] * daa / aa[:, None] ** 2)[None])
    return np.asarray(e, dtype=complex), np.asarray(de, dtype=complex)


def _first_order_bias(fitted: Fitted, exact: ExactModalProblem, space: ParameterSpace) -> dict[str, Any]:
    """The first-order modes' bias against exact ones: the first-order estimate minus the estimate of the same fit
    on exact complex modes started there (a local search), relative to the exact estimate, per unknown."""
    p = np.asarray(fitted.estimate.values, dtype=float)
    refit = least_squares_fit("modal", space, exact.residuals, exact.jacobian, starts=p[None, :],
                              noise_variance=None).estimate
    out: dict[str, Any] = {"modes": "first-order", "exact_estimate": refit.parameters if refit.success else None}
    if not refit.success:
        out["bias"] = {}
        out["note"] = f"the fit on exact modes from the first-order estimate failed: {refit.message}"
        return out
    q = np.asarray(refit.values, dtype=float)
    out["bias"] = {n: float(a / b - 1) if b != 0 else float("nan") for n, a, b in zip(space.names, p, q, strict=True)}
    return out
