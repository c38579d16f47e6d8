"""Stiffness factors of parameter groups from measured FRFs: the estimation step of the monitoring chain.

A :class:`FactorEstimator` fits log-factors ``s`` (``p_i = p_ref,i exp(s_g)`` for every parameter ``i`` of group
``g``) to FRFs by Levenberg-Marquardt on the weighted complex residual

    r = (H_model(s) - H_measured) / (|H_ref| + floor * rms_o)

over every line of the band and every measured input/output pair, where ``H_ref`` is the reference model's FRF
(fixed weights: a relative error with a floor at a fraction of each output's RMS level, so anti-resonances and
near-zero cross FRFs do not dominate). The Jacobian is analytic: ``dH/ds_g = -S Z^-1 (dZ/ds_g) Z^-1 B`` with the
exact matrix derivatives of the model (``Z = K + iH + i omega (C + G) - omega^2 M``), so a fit of a few groups on
an 11-DOF model takes milliseconds.

The monitoring chain uses it twice: with one group per component (the fast path, every measurement) and with
one group per parameter (the slow path, the full estimation of every stiffness). Log-factors make a loss and a
gain of the same ratio equally far, keep every stiffness positive and make the factor's relative uncertainty the
log-factor's standard deviation.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cappe.exceptions import ConvergenceWarning, DataError
from cappe.model import NumericModel
from cappe.systems.dynamic_stiffness import FRFLines, frf_lines, response_derivatives
from cappe.systems.frf import FRFData
from cappe.systems.mechanical import DERIVATIVE_ORDER

__all__ = ["FactorEstimate", "FactorEstimator"]

Array = NDArray[np.float64]
CArray = NDArray[np.complex128]


@dataclass(frozen=True)
class FactorEstimate:
    """Estimated log-factors of parameter groups.

    Attributes
    ----------
    names : tuple of str
        Group names.
    log_factor : ndarray, shape (n,)
        ``ln`` of each group's factor (0 = the reference model).
    covariance : ndarray, shape (n, n)
        Gauss-Newton covariance of ``log_factor``, scaled by the fit's residual variance.
    cost : float
        Half the sum of squared weighted residuals at the estimate.
    sigma : float
        Residual standard deviation (the relative noise level the data showed).
    iterations : int
        Levenberg-Marquardt iterations.
    success : bool
        Converged with a full-rank Jacobian.
    message : str
        Why it stopped.
    """

    names: tuple[str, ...]
    log_factor: Array
    covariance: Array
    cost: float
    sigma: float
    iterations: int
    success: bool
    message: str

    @property
    def factor(self) -> Array:
        """Each group's stiffness factor (1 = reference)."""
        return np.exp(self.log_factor)

    @property
    def std(self) -> Array:
        """Standard uncertainty of each factor (delta method)."""
        return self.factor * np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    def to_dict(self) -> dict[str, Any]:
        return {
            "names": list(self.names),
            "factor": self.factor.tolist(),
            "std": self.std.tolist(),
            "log_factor": self.log_factor.tolist(),
            "covariance": self.covariance.tolist(),
            "cost": self.cost,
            "sigma": self.sigma,
            "iterations": self.iterations,
            "success": self.success,
            "message": self.message,
        }


def _roughness(log_h: CArray, weights: Array) -> float:
    """Noise level of ``ln H`` seen in the data alone: the robust spread of second differences along frequency.

    For white noise of standard deviation ``sigma`` per real component, ``L[k+1] - 2 L[k] + L[k-1]`` has
    ``sqrt(6) sigma``; the median absolute deviation ignores the few lines where a resonance curves ``ln H``.
    Only runs of three lines well above the weighting floor count.
    """
    good = weights > 0.9
    ok = good[..., 2:] & good[..., 1:-1] & good[..., :-2]
    d2 = (log_h[..., 2:] - 2 * log_h[..., 1:-1] + log_h[..., :-2])[ok]
    if d2.size < 10:
        return 0.0
    parts = np.concatenate([d2.real, d2.imag])
    return float(1.4826 * np.median(np.abs(parts - np.median(parts))) / np.sqrt(6.0))


class FactorEstimator:
    """Fit group stiffness factors of a model to measured FRFs (see the module notes).

    Not a scikit-learn-style estimator: it is built once per machine (the model's input and output matrices,
    the weights of the last line grid and the start point's Jacobian are kept) and :meth:`estimate` returns a
    :class:`FactorEstimate` per measurement, so one instance serves a stream of measurements.

    Parameters
    ----------
    model : NumericModel
    groups : mapping of str to sequence of str
        Group name -> model parameters it scales.
    reference : mapping, optional
        Parameter overrides of the reference model (default: the model's values).
    position : mapping, optional
        Axis position.
    inputs, outputs : sequence of str
        FRF channels the data must have.
    band : (float, float)
        Lines of the data used, in Hz.
    noise_floor : float
        Weighting floor as a fraction of each output's RMS FRF level.

    Examples
    --------
    >>> from cappe.model import load_model
    >>> rig = NumericModel(load_model("builtin:two-mass-rig"))
    >>> data = rig.system({"k12": 0.9 * 120e3}).frf(np.arange(50.0, 250.0), ["F1"], ["d1", "d2"])
    >>> est = FactorEstimator(rig, {"coupling": ["k12"], "base": ["k11"]}, inputs=["F1"],
    ...                       outputs=["d1", "d2"], band=(50, 250)).estimate(data)
    >>> np.round(est.factor, 6).tolist()
    [0.9, 1.0]
    """

    def __init__(
        self,
        model: NumericModel,
        groups: Mapping[str, Sequence[str]],
        *,
        reference: Mapping[str, float] | None = None,
        position: Mapping[str, float] | None = None,
        inputs: Sequence[str],
        outputs: Sequence[str],
        band: tuple[float, float],
        noise_floor: float = 0.01,
    ) -> None:
        self.model = model
        self.names = tuple(groups)
        if not self.names:
            msg = "FactorEstimator needs at least one group"
            raise DataError(msg)
        self._members = []
        owner: dict[str, str] = {}
        for name, params in groups.items():
            for p in params:
                if p in owner:
                    msg = f"parameter '{p}' is in groups '{owner[p]}' and '{name}'; each parameter belongs to one group"
                    raise DataError(msg)
                owner[p] = name
            unknown = [p for p in params if p not in model.parameter_names]
            if unknown or not params:
                msg = f"group '{name}': parameters {list(params)} must be non-empty model parameters; unknown {unknown}"
                raise DataError(msg)
            self._members.append(np.array([model.parameter_names.index(p) for p in params], dtype=np.intp))
        self.reference = model.vector(dict(reference or {}))
        self.position = dict(position or {})
        self.inputs = tuple(inputs)
        self.outputs = tuple(outputs)
        self.band = (float(band[0]), float(band[1]))
        self.noise_floor = float(noise_floor)
        b_mat, s_mat = model.io_matrices(self.reference, self.position)
        self._B = b_mat[:, [model.input_names.index(i) for i in self.inputs]].astype(complex)
        out_index = [model.output_names.index(o) for o in self.outputs]
        self._S = s_mat[out_index].astype(complex)
        self._order = np.array([DERIVATIVE_ORDER[model.output_quantities[k]] for k in out_index])
        self._grid: tuple[bytes, Array, CArray] | None = None  # lines -> weights cache
        self._start: tuple[tuple[bytes, bytes], CArray, Array] | None = None  # start point -> model, Jacobian

    @property
    def members(self) -> tuple[NDArray[np.intp], ...]:
        """Each group's parameters, as indices into the model's parameters (one array per group)."""
        return tuple(self._members)

    # -- model side -----------------------------------------------------------------------------------------

    def parameters(self, log_factor: Array) -> Array:
        """The model parameter vector at group log-factors ``log_factor``.

        Parameters
        ----------
        log_factor : ndarray, shape (n,)
            ``ln`` of each group's factor (0: the reference model).

        Returns
        -------
        ndarray, shape (n_params,)
            The reference parameters (SI) with each group's members scaled by its factor.
        """
        p = self.reference.copy()
        for members, s in zip(self._members, np.asarray(log_factor, dtype=float), strict=True):
            p[members] = self.reference[members] * np.exp(s)
        return p

    def _lines(self, p: Array, freq: Array) -> FRFLines:
        """The dynamic-stiffness kernel at ``p``: H (F, n_out, n_in), X = Z^-1 B and L = S Z^-1."""
        m = self.model.matrices(p, self.position)
        return frf_lines(m, 2 * np.pi * freq, self._B, self._S, orders=self._order, left=True)

    def _dynamic(self, p: Array, freq: Array) -> tuple[CArray, CArray]:
        """X = Z^-1 B (F, n, n_in) and L = S Z^-1 (F, n_out, n) of the dynamic stiffness
        ``Z = K + iH + i omega (C + G) - omega^2 M``."""
        lines = self._lines(p, freq)
        return lines.X, cast(CArray, lines.L)  # computed: left=True

    def frf(self, log_factor: Array, freq: Array) -> CArray:
        """Model FRFs H[out, in, freq] at ``log_factor``.

        Parameters
        ----------
        log_factor : ndarray, shape (n,)
            ``ln`` of each group's factor (0: the reference model).
        freq : ndarray, shape (n_freq,)
            Frequencies in Hz.

        Returns
        -------
        ndarray of complex, shape (n_out, n_in, n_freq)
            In the outputs' units per input unit (m/N, m/s/N or m/s^2/N).
        """
        return np.moveaxis(self._lines(self.parameters(log_factor), np.asarray(freq, dtype=float)).H, 0, -1)

    def _jacobian(self, p: Array, freq: Array, x: CArray, lt: CArray,
                  groups: Sequence[NDArray[np.intp]] | None = None) -> CArray:
        """dH/ds_g = -L (dZ/ds_g) X for every group (default: the estimator's): (n_groups, n_out, n_in, F)."""
        groups = self._members if groups is None else groups
        deriv = self.model.matrix_derivatives(p, self.position)
        # d/ds_g = sum_i p_i d/dp_i over the group's members
        by_group = {name: np.stack([np.tensordot(p[members], deriv[name][members], axes=1) for members in groups])
                    for name in ("K", "H", "C", "G", "M")}
        dh = response_derivatives(by_group, 2 * np.pi * freq, x, lt, orders=self._order)
        return np.moveaxis(dh, 1, -1)

    def _weights(self, freq: Array) -> tuple[Array, CArray]:
        """Weights of the log residual and the reference FRF on these lines (cached for the last grid).

        The weight ``|H_ref| / (|H_ref| + floor rms_o)`` is 1 well above the floor and falls below it; lines below
        half of it (anti-resonances, cross FRFs that vanish by symmetry) are left out, because the logarithm of
        a value that is mostly noise is biased and undefined at zero.
        """
        key = freq.tobytes()
        if self._grid is None or self._grid[0] != key:
            h_ref = self.frf(np.zeros(len(self.names)), freq)
            rms = np.sqrt(np.mean(np.abs(h_ref) ** 2, axis=(1, 2)))
            level = np.abs(h_ref) / (np.abs(h_ref) + self.noise_floor * rms[:, None, None])
            self._grid = (key, np.where(level > 0.5, level, 0.0), h_ref)
        return self._grid[1], self._grid[2]

    # -- data side ------------------------------------------------------------------------------------------
    def select(self, data: FRFData) -> tuple[Array, CArray]:
        """The lines in the band and the configured channels of ``data``: (freq, H[out, in, freq]).

        Parameters
        ----------
        data : FRFData
            Measured FRFs holding the configured channels.

        Returns
        -------
        freq : ndarray, shape (n_lines,)
            The lines in the band, in Hz.
        H : ndarray of complex, shape (n_out, n_in, n_lines)

        Raises
        ------
        DataError
            A channel is missing, or the band holds too few lines for the groups.
        """
        missing = [n for n in self.outputs if n not in data.output_names]
        missing += [n for n in self.inputs if n not in data.input_names]
        if missing:
            msg = (f"FRF data lack channels {missing}; they have outputs {list(data.output_names)} and inputs "
                   f"{list(data.input_names)}")
            raise DataError(msg)
        freq = np.asarray(data.freq, dtype=float)
        keep = (freq >= self.band[0]) & (freq <= self.band[1]) & (freq > 0)
        if keep.sum() < 2 * len(self.names):
            msg = (f"FRF data have {int(keep.sum())} lines in the band {self.band[0]:g}-{self.band[1]:g} Hz; "
                   f"at least {2 * len(self.names)} are needed")
            raise DataError(msg)
        oo = np.array([data.output_names.index(n) for n in self.outputs], dtype=np.intp)
        ii = np.array([data.input_names.index(n) for n in self.inputs], dtype=np.intp)
        h = np.asarray(data.H)[np.ix_(oo, ii, np.flatnonzero(keep))]
        if not np.all(np.isfinite(h)):
            msg = "FRF data contain non-finite values in the band"
            raise DataError(msg)
        return freq[keep], h

    def estimate(
        self,
        data: FRFData,
        start: ArrayLike | None = None,
        *,
        max_iter: int = 50,
        misfit_ratio: float | None = 5.0,
        misfit_level: float | None = None,
    ) -> FactorEstimate:
        """Levenberg-Marquardt fit of the log-factors to ``data`` (from ``start``, default 0 = the reference).

        The residual is the weighted complex logarithm ``w ln(H_model / H_measured)`` (log magnitude and phase):
        it is the relative error near the optimum, where its least squares are the maximum-likelihood fit of
        FRFs with relative noise, and far from it a peak shifted by more than its bandwidth costs its log
        height, not its height, so on the spindle the fit converges from the reference model to losses of 50 %
        (a plain complex residual stalls at such a start: the local minima of FRF fitting, thesis 4.3).

        Local minima remain possible on very lightly damped models. So the fit compares its residual with the
        noise the data show on their own (the spread of second differences of ``ln H`` along frequency, a
        model-free estimate): beyond ``misfit_ratio`` times that, it restarts from points around the first
        result (each group 20 % and 40 % lower and 25 % higher) and keeps the best; if even that misfits, the
        result has ``success=False`` (a local minimum, or a model that does not describe the data). A model of a
        real machine never fits to the noise; ``misfit_level``, the residual of good fits (a monitor's healthy
        baseline), replaces the noise as the reference when it is larger. ``misfit_ratio=None`` turns the check
        off. A
        rank-deficient Jacobian or no convergence also gives ``success=False``; every failure warns
        (`ConvergenceWarning`).

        Parameters
        ----------
        data : FRFData
            Measured FRFs holding the configured channels.
        start : array_like, shape (n,), optional
            Start log-factors (default 0: the reference model).
        max_iter : int
            Levenberg-Marquardt iterations per start.
        misfit_ratio : float or None
            Residual over the data's own noise beyond which the fit restarts and then fails; None: no check.
        misfit_level : float, optional
            Residual of good fits (relative, like the noise), used instead of the noise when larger.

        Returns
        -------
        FactorEstimate

        Raises
        ------
        DataError
            A channel is missing, the band holds too few lines, or the data are zero where the model responds.
        """
        freq, h_meas = self.select(data)
        weights, _ = self._weights(freq)
        used = weights > 0
        h_meas = np.where(used, h_meas, 1.0)
        if np.any(h_meas == 0):
            msg = "FRF data are exactly zero on lines where the model responds; cannot take their logarithm"
            raise DataError(msg)
        n = len(self.names)
        s0 = np.zeros(n) if start is None else np.asarray(start, dtype=float).copy()
        if s0.shape != (n,) or not np.all(np.isfinite(s0)):
            msg = f"start must be {n} finite log-factors ({list(self.names)}); got {s0.tolist()}"
            raise DataError(msg)
        best = self._solve(freq, h_meas, weights, s0, max_iter)
        dof = max(2 * int(used.sum()) - n, 1)
        noise = max(_roughness(np.log(h_meas), weights), misfit_level or 0.0)
        limit = np.inf if misfit_ratio is None else misfit_ratio * noise
        if np.sqrt(2.0 * best[1] / dof) > limit:
            for g in range(n):
                for delta in (np.log(0.8), np.log(0.6), np.log(1.25)):
                    trial = best[0].copy()
                    trial[g] += delta
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        candidate = self._solve(freq, h_meas, weights, trial, max_iter)
                    if candidate[1] < best[1]:
                        best = candidate
        s, cost, jac, iterations, converged, message = best
        sigma2 = 2.0 * cost / dof
        jtj = jac.T @ jac
        rank = int(np.linalg.matrix_rank(jtj))
        covariance = sigma2 * np.linalg.pinv(jtj)
        success = converged and rank == n
        if rank < n:
            message = f"{message}; Jacobian rank {rank} < {n} groups (not all identifiable from these channels)"
        if np.sqrt(sigma2) > limit:
            success = False
            message = (f"{message}; residual {np.sqrt(sigma2):.3g} is {np.sqrt(sigma2) / noise:.3g} times the "
                       f"reference misfit {noise:.3g} (the noise the data show, or the healthy fits' residual): a "
                       f"local minimum or a model that does not describe the data")
        if not success:
            warnings.warn(f"stiffness-factor fit: {message}", ConvergenceWarning, stacklevel=2)
        return FactorEstimate(self.names, s, np.asarray(covariance, dtype=float), cost, float(np.sqrt(sigma2)),
                              iterations, success, message)

    def _solve(
        self, freq: Array, h_meas: CArray, weights: Array, start: Array, max_iter: int
    ) -> tuple[Array, float, Array, int, bool, str]:
        """Levenberg-Marquardt from ``start``: (log-factors, cost, Jacobian, iterations, converged, message).

        A loop of its own rather than the shared least squares (:func:`cappe.optimize.minimize`,
        ``strategy="least-squares"``, scipy's trust-region reflective method): it keeps the start point's model and
        Jacobian for the next measurement, limits a step to a factor e^0.5 and stops once the step is 1 % of the
        estimate's own standard deviation. On its real use (benchmarks/bench_lm.py: spindle, 2 groups, 400 lines, a
        stream of 20 noisy measurements, both in one run) it takes 0.74-0.88 s against 2.37-2.47 s (2.7-3.3x) for
        the same costs.
        """
        used = weights > 0
        n = len(self.names)
        max_step = 0.5  # a trust region in log-factor: at most a factor e^0.5 per iteration
        s = start.copy()

        def model(s_vec: Array) -> tuple[CArray, CArray, CArray]:
            lines = self._lines(self.parameters(s_vec), freq)
            h = np.where(used, np.moveaxis(lines.H, 0, -1), 1.0)
            return h, lines.X, cast(CArray, lines.L)

        def residual(h: CArray) -> Array:
            r = (weights * np.log(h / h_meas)).ravel()
            return np.concatenate([r.real, r.imag])

        def jacobian(s_vec: Array, h: CArray, x: CArray, lt: CArray) -> Array:
            jac = (weights[None] * self._jacobian(self.parameters(s_vec), freq, x, lt) / h[None]).reshape(n, -1)
            return np.concatenate([jac.real, jac.imag], axis=1).T

        # the model and its Jacobian at the start do not depend on the data: a monitor starts every healthy
        # measurement from the same point, so they are kept for the next fit on the same lines
        key = (s.tobytes(), freq.tobytes())
        if self._start is not None and self._start[0] == key:
            h, jac = self._start[1], self._start[2]
        else:
            h, x, lt = model(s)
            jac = jacobian(s, h, x, lt)
            self._start = (key, h, jac)
        r = residual(h)
        cost = 0.5 * float(r @ r)
        lam = 1e-3
        message = "maximum number of iterations reached"
        converged = False
        iterations = 0
        for iterations in range(1, max_iter + 1):  # noqa: B007 (reported after the loop)
            jtj = jac.T @ jac
            grad = jac.T @ r
            diag = np.diag(jtj).copy()
            diag[diag <= 0] = 1.0
            while True:
                try:
                    step = -np.linalg.solve(jtj + lam * np.diag(diag), grad)
                except np.linalg.LinAlgError:
                    step = -np.linalg.lstsq(jtj + lam * np.diag(diag), grad, rcond=None)[0]
                largest = float(np.max(np.abs(step)))
                if largest > max_step:
                    step *= max_step / largest
                with np.errstate(all="ignore"):
                    h_new, x_new, lt_new = model(s + step)
                    r_new = residual(h_new)
                cost_new = 0.5 * float(r_new @ r_new)
                if np.isfinite(cost_new) and (cost_new <= cost or lam > 1e12):
                    break
                lam *= 10.0
                if lam > 1e14:
                    cost_new = np.inf
                    break
            if not cost_new <= cost:
                message = "no step reduces the cost"
                converged = bool(np.linalg.norm(grad) < 1e-8 * max(1.0, cost))
                break
            s = s + step
            improvement = cost - cost_new
            # the step in units of the estimate's own standard deviation (its Mahalanobis length): once it is
            # below 1 % of one, further iterations cannot change the result in any way that matters, and the
            # Jacobian of the last point serves the covariance
            variance = 2.0 * cost_new / max(r_new.size - n, 1)
            decrement = float(step @ jtj @ step) / max(variance, 1e-300)
            r, cost = r_new, cost_new
            lam = max(lam / 10.0, 1e-12)
            if decrement < 1e-4 or np.max(np.abs(step)) < 1e-9 or improvement <= 1e-12 * max(cost, 1e-300):
                message = "converged"
                converged = True
                break
            jac = jacobian(s, h_new, x_new, lt_new)
        return s, cost, jac, iterations, converged, message

    def direction(self, parameter: str, data_freq: Sequence[float] | None = None) -> Array:
        """How a change of any model parameter shows in the group log-factors: ``d s / d ln parameter``.

        The least-squares projection (with the fit's own weights) of the FRF change a small relative change of
        ``parameter`` causes onto the group Jacobian at the reference: the signature of, e.g., a preload change
        in the bearing factors, used by the diagnosis.

        Parameters
        ----------
        parameter : str
            A model parameter.
        data_freq : sequence of float, optional
            Frequency lines in Hz (default 400 lines over the band).

        Returns
        -------
        ndarray, shape (n,)
            Change of each group's log-factor per unit change of ``ln parameter``.

        Raises
        ------
        DataError
            ``parameter`` is not in the model.
        """
        if parameter not in self.model.parameter_names:
            msg = f"unknown parameter '{parameter}'; the model has {list(self.model.parameter_names)}"
            raise DataError(msg)
        lo, hi = self.band
        freq = np.asarray(data_freq, dtype=float) if data_freq is not None else np.linspace(max(lo, 1e-3), hi, 400)
        weights, h_ref = self._weights(freq)
        h_ref = np.where(weights > 0, h_ref, 1.0)
        p = self.reference
        x, lt = self._dynamic(p, freq)
        k = np.array([self.model.parameter_names.index(parameter)], dtype=np.intp)
        jac = self._jacobian(p, freq, x, lt, [*self._members, k]) * (weights / h_ref)[None]
        flat = jac.reshape(len(self._members) + 1, -1)
        a = np.concatenate([flat[:-1].real, flat[:-1].imag], axis=1).T
        b = np.concatenate([flat[-1].real, flat[-1].imag]) * float(p[k[0]] != 0)
        return np.asarray(np.linalg.lstsq(a, b, rcond=None)[0], dtype=float)


class ModalFactorEstimator:
    """Fit group stiffness factors to output-only modes: natural frequencies and unscaled mode shapes.

    Without a measured force the FRFs are unknown; what operational responses give (:func:`cappe.identify.ssi_cov`)
    are the poles and the mode shapes at the output channels up to a complex scale each. The residuals are those of
    :class:`cappe.estimate.ExactModalProblem` on the model's exact complex modes (one home of modal residuals and
    their analytic Jacobian): the relative frequency error over ``freq_noise`` and the shape residual
    ``a (a^H x) / (a^H a) - x`` (squared norm ``1 - MAC``, blind to the shape's scale) over ``shape_noise``;
    damping ratios are not fitted (operational damping estimates scatter by 10 % and depend on the load).
    Shapes at velocity and acceleration outputs are brought to displacement level by dividing by the identified
    pole (``s`` per derivative), so channels of mixed quantities compare with the model's displacement shapes.
    The Jacobian in the group log-factors is the chain rule ``dr/ds_g = sum_(i in g) p_i dr/dp_i``.

    What the data cannot give: the modal masses (no force, no scale), hence no mass change and no change of all
    stiffnesses together against all masses; the factors are relative to the model's masses.

    Parameters
    ----------
    factors : FactorEstimator
        The machine's FRF factor estimator: its groups, reference parameters, position and outputs.
    freq_noise : float
        Relative scatter of an identified natural frequency (weights the frequency residuals).
    shape_noise : float
        Scatter of a shape component relative to the shape's largest (weights the shape residuals).

    Raises
    ------
    DataError
        An output has no sensor channel of the model (the shapes are compared at sensor channels).
    """

    def __init__(self, factors: FactorEstimator, *, freq_noise: float = 1e-3, shape_noise: float = 1e-2) -> None:
        from cappe.estimate._space import ParameterSpace

        self.factors = factors
        self.names = factors.names
        self.freq_noise = float(freq_noise)
        self.shape_noise = float(shape_noise)
        model = factors.model
        labels, rows = model.sensor_matrix(factors.reference, factors.position)
        _, s_mat = model.io_matrices(factors.reference, factors.position)
        self.sensors: list[str] = []
        for o in factors.outputs:
            row = s_mat[model.output_names.index(o)]
            hits = [lab for lab, r in zip(labels, rows, strict=True) if np.allclose(r, row, rtol=1e-9, atol=1e-12)]
            if not hits:
                msg = (f"output '{o}' is not a sensor channel of model '{model.structure.name}' (its row matches none "
                       f"of {labels}); output-only monitoring compares mode shapes at sensor channels")
                raise DataError(msg)
            self.sensors.append(hits[0])
        self._order = np.array([DERIVATIVE_ORDER[model.output_quantities[model.output_names.index(o)]]
                                for o in factors.outputs])
        self._unknowns = [model.parameter_names[i] for members in factors.members for i in members]
        self._columns = np.concatenate(factors.members)
        self._group_of = np.concatenate([np.full(m.size, g) for g, m in enumerate(factors.members)])
        values = dict(zip(model.parameter_names, factors.reference.tolist(), strict=True))
        self._space = ParameterSpace.from_model(model, self._unknowns, values=values, log=False)

    def reference_modes(self, frequency: ArrayLike, damping: ArrayLike, shapes: ArrayLike) -> Any:
        """Identified modes as the :class:`~cappe.systems.modal.ModalData` the fit compares with.

        Parameters
        ----------
        frequency, damping : array_like, shape (m,)
            Natural frequencies (Hz) and damping ratios.
        shapes : array_like of complex, shape (n_out, m)
            Shapes at the estimator's outputs, in each output's quantity.

        Returns
        -------
        ModalData
            Displacement-level shapes at the outputs' sensor channels.
        """
        from cappe.systems.modal import ModalData, ModalDataSet

        f = np.asarray(frequency, dtype=float)
        z = np.asarray(damping, dtype=float)
        wn = 2 * np.pi * f
        pole = -z * wn + 1j * wn * np.sqrt(np.clip(1 - z**2, 0.0, None))
        x = np.asarray(shapes, dtype=complex) / pole[None, :] ** self._order[:, None]
        data_set = ModalDataSet(dict(self.factors.position), f, z, x)
        return ModalData(tuple(self.sensors), (data_set,), self.factors.model.structure.name)

    def estimate(
        self,
        frequency: ArrayLike,
        damping: ArrayLike,
        shapes: ArrayLike,
        start: ArrayLike | None = None,
        *,
        max_iter: int = 30,
        misfit_ratio: float | None = 3.0,
    ) -> FactorEstimate:
        """Trust-region least squares of the log-factors against identified modes (from ``start``, default 0).

        The residuals are scaled by the expected frequency and shape noise, so a good fit has an RMS residual
        near 1. Beyond ``misfit_ratio`` the fit restarts from points around its result (each group 20 % and 40 %
        lower and 25 % higher, as :meth:`FactorEstimator.estimate` does) and keeps the best.

        Parameters
        ----------
        frequency, damping : array_like, shape (m,)
            Natural frequencies (Hz) and damping ratios of the identified modes.
        shapes : array_like of complex, shape (n_out, m)
            Their shapes at the outputs (any scale).
        start : array_like, shape (n,), optional
            Start log-factors.
        max_iter : int
            Largest number of Jacobian evaluations.
        misfit_ratio : float or None
            RMS scaled residual beyond which the fit restarts; None: no restarts.

        Returns
        -------
        FactorEstimate
            Covariance scaled by the residual variance; ``success=False`` (with a warning) where the Jacobian
            is rank deficient (fewer modes than the groups need) or the fit did not converge.

        Raises
        ------
        DataError
            No mode given, or ``start`` of the wrong size.
        """
        from scipy.optimize import least_squares

        from cappe.estimate._exact_modal import ExactModalProblem

        n = len(self.names)
        f = np.asarray(frequency, dtype=float)
        if f.size == 0:
            msg = "no identified mode to fit the stiffness factors to"
            raise DataError(msg)
        s0 = np.zeros(n) if start is None else np.asarray(start, dtype=float).copy()
        if s0.shape != (n,) or not np.all(np.isfinite(s0)):
            msg = f"start must be {n} finite log-factors ({list(self.names)}); got {s0.tolist()}"
            raise DataError(msg)
        problem = ExactModalProblem(self.factors.model, self._space, self.reference_modes(f, damping, shapes),
                                    (1.0, 0.0, 1.0), noise=(self.freq_noise, 0.0, self.shape_noise),
                                    pairing="mac")

        def unknowns(s_vec: Array) -> Array:
            return self.factors.parameters(s_vec)[self._columns]

        def fun(s_vec: Array) -> Array:
            return problem.residuals(unknowns(s_vec))

        def jac(s_vec: Array) -> Array:
            p = unknowns(s_vec)
            j_p = problem.jacobian(p) * p[None, :]
            out = np.zeros((j_p.shape[0], n))
            np.add.at(out.T, self._group_of, j_p.T)
            return out

        def solve(start_vec: Array) -> Any:
            with np.errstate(all="ignore"):
                return least_squares(fun, start_vec, jac=jac, method="trf", max_nfev=max_iter, x_scale=1.0,
                                     xtol=1e-10, ftol=1e-10)

        result = solve(s0)
        dof_fit = max(np.asarray(result.fun).size - n, 1)
        if misfit_ratio is not None and np.sqrt(2.0 * result.cost / dof_fit) > misfit_ratio:
            # a local minimum (a large change shifts modes past each other): restart around it, as the FRF fit does
            for g in range(n):
                for delta in (np.log(0.8), np.log(0.6), np.log(1.25)):
                    trial = np.asarray(result.x, dtype=float).copy()
                    trial[g] += delta
                    candidate = solve(trial)
                    if candidate.cost < result.cost:
                        result = candidate
        r = np.asarray(result.fun, dtype=float)
        j = np.asarray(result.jac, dtype=float)
        dof = max(r.size - n, 1)
        sigma2 = float(r @ r) / dof
        jtj = j.T @ j
        rank = int(np.linalg.matrix_rank(jtj))
        success = bool(result.success) and rank == n
        message = str(result.message)
        if rank < n:
            message = (f"{message}; Jacobian rank {rank} < {n} groups ({f.size} modes do not determine every "
                       f"component)")
        if not success:
            warnings.warn(f"modal stiffness-factor fit: {message}", ConvergenceWarning, stacklevel=2)
        return FactorEstimate(self.names, np.asarray(result.x, dtype=float), sigma2 * np.linalg.pinv(jtj),
                              0.5 * float(r @ r), float(np.sqrt(sigma2)), int(result.nfev), success, message)
