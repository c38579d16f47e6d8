"""One-step output-error estimation (thesis 3.6.3, eq. 3.108) in the time domain, and its counterpart on FRFs.

**Time domain** (:class:`OneStepEstimator`). The model's outputs are simulated to the measured inputs and the sum
of squared output errors is minimized over the unknowns (eq. 3.108). The simulation is the zero-order-hold
discretization at the data's sample rate, evaluated in modal coordinates: the continuous state matrix is
diagonalized once per parameter vector, each complex mode is one first-order recursion run by
:func:`scipy.signal.lfilter`, and conjugate pairs are computed once. It equals
:meth:`cappe.systems.StateSpaceModel.simulate` (and :func:`cappe.systems.time_response` without noise) to
rounding. Each output channel's error is divided by the channel's RMS value (about its mean when offsets are
estimated), so displacement, velocity and acceleration channels count alike.

*Nuisance parameters* (thesis 5.3.4.2 had "level" and "phase shift"):

- per-output offsets, eliminated by variable projection: for any parameter vector the best offsets are the
  least-squares constants of the output error, so the error is projected onto the complement of the constants;
  their values are reported in ``diagnostics["offsets"]``;
- an input-output delay ``tau`` (seconds, any fraction of a sample, either sign) estimated with the unknowns. It
  enters the discretization exactly (the modified z-transform of a delayed zero-order hold): with
  ``tau = (n + f) dt``, ``0 <= f < 1``, the held input acts through two input matrices,
  ``x[k+1] = Ad x[k] + G0 u[k-n] + G1 u[k-n-1]`` with ``G0 = int_0^{(1-f)dt} e^{A s} ds B`` and
  ``G1 = e^{A(1-f)dt} int_0^{f dt} e^{A s} ds B``. The direct feedthrough of acceleration outputs sees the
  input interpolated linearly between samples (the held input jumps at the sampling instants, which would make
  the cost jump at whole-sample delays). It is reported in ``diagnostics["delay"]``.

*Global convergence* by continuation in artificial damping. Lightly damped modes make the output error
multimodal: a model resonance more than about one half-power bandwidth away from the true one sits in another
valley. Weighting a record segment's inputs and outputs by ``exp(-sigma t)`` (t from the segment start) maps the
exact input-output relation onto the same system with every pole moved left by ``sigma``; the free response of
the segment's unknown initial state is projected out with the offsets. Fits with ``sigma`` equal to
``continuation`` times the lowest natural frequency of the current model (default 0.3, 0.1, 0.03), each started
from the previous result, widen every valley to the added damping and end in the exact output error. From starts
with every unknown 50 % off (any pattern of x1.5 and x0.5) the two-mass rig converges without guidance, where
plain output error does not (``continuation=()``).

**Frequency domain** (:class:`OneStepFRFEstimator`). Residuals are the complex logarithm of model over measured
FRF, ``log(H_model / H_meas)`` (real part: log-magnitude error, imaginary part: phase error in rad), weighted by
``gamma^2 / (1 - gamma^2)`` from the coherence where the data have one: for the H1 estimate the variance of both
log-magnitude and phase is ``(1 - gamma^2) / (2 n_avg gamma^2)`` (Bendat & Piersol), so this is the
inverse-variance weight. Logarithms treat resonances and anti-resonances alike and keep the cost smooth far from
the optimum (``residual="relative"`` uses ``(H_model - H_meas) / |H_meas|`` instead). Single local fits from
starts 50 % off converge only part of the time (the peaks of lightly damped modes are as narrow as in the time
domain); ``starts`` adds random starts. The Jacobian is analytic: ``dH/dp = -S Z^-1 (dZ/dp) Z^-1 B`` with the
dynamic stiffness ``Z = K + jH + j omega (C + G) - omega^2 M`` and its exact parameter derivatives
(:func:`frf_derivatives`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np
import scipy.linalg as sla
import scipy.signal as sig
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares

from cappe._arguments import positive_number
from cappe._rng import RandomLike
from cappe.estimate._base import Estimator, Fitted, honest_intervals, least_squares_fit, with_residual_tests
from cappe.estimate._result import ParameterEstimate
from cappe.estimate._space import ParameterSpace
from cappe.estimate._uncertainty import (
    correlated_uncertainty,
    jacobian_uncertainty,
    newey_west_bandwidth,
    null_direction_text,
)
from cappe.exceptions import DataError, ModelError
from cappe.model import NumericModel, Structure
from cappe.model.numeric import ParamsLike
from cappe.systems.dynamic_stiffness import frf_lines
from cappe.systems.frf import FRFData
from cappe.systems.mechanical import DERIVATIVE_ORDER
from cappe.systems.statespace import band_limited_modal_response, check_intersample, hold_weights
from cappe.systems.timedata import TimeData

__all__ = ["FRFDerivatives", "OneStepEstimator", "OneStepFRFEstimator", "frf_derivatives"]

Array = NDArray[np.float64]
CArray = NDArray[np.complex128]

#: Default artificial damping ratios of the continuation stages (relative to the lowest natural frequency).
CONTINUATION = (0.3, 0.1, 0.03)
#: A weighted segment spans this many decay times ``1 / sigma`` (exp(-5) = 0.7 % weight left at its end).
_SEGMENT_DECAYS = 5.0
#: Lines the runs test judges: coherence at least this (at lower coherence the log of a noisy FRF is biased, a
#: systematic error of the residual itself, not of the model).
_TRUSTED_COHERENCE = 0.9
#: Largest accepted coherence in the weights gamma^2 / (1 - gamma^2) (caps a weight at 999).
_MAX_COHERENCE = 0.999


# -- shared helpers -----------------------------------------------------------------------------------------
def random_starts(space: ParameterSpace, n: int, rng: np.random.Generator) -> Array:
    """The space's start followed by ``n - 1`` random points in its bounds (SI), shape (n, n_unknowns).

    Log-uniform for parameters searched in ``log p``, uniform otherwise; unbounded coordinates are drawn within
    a factor of 10 of the start (or +-1 scale unit).
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        msg = f"starts must be an integer >= 1 (the start plus random starts in the bounds); got {n!r}"
        raise DataError(msg)
    lo, hi = space.internal_bounds()
    u0 = space.to_internal(space.start)
    lo = np.where(np.isfinite(lo), lo, u0 - np.where(space.log, np.log(10.0), 1.0))
    hi = np.where(np.isfinite(hi), hi, u0 + np.where(space.log, np.log(10.0), 1.0))
    draws = rng.uniform(lo, hi, size=(int(n) - 1, space.n))
    return np.vstack([space.start[None, :], space.from_internal(draws)])


def _extended(space: ParameterSpace, names: Sequence[str], lower: Sequence[float], upper: Sequence[float],
              start: Sequence[float]) -> ParameterSpace:
    """The space with nuisance coordinates appended (linear, scaled by their bound). Only the optimizer uses it;
    model vectors are always built from the physical space."""
    if not names:
        return space
    lo, hi = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    return ParameterSpace(
        space.names + tuple(names),
        np.concatenate([space.lower, lo]),
        np.concatenate([space.upper, hi]),
        np.concatenate([space.start, np.asarray(start, dtype=float)]),
        np.concatenate([space.log, np.zeros(len(names), dtype=bool)]),
        np.concatenate([space.scale, np.maximum(np.abs(lo), np.abs(hi))]),
        np.concatenate([space.columns, np.full(len(names), -1, dtype=np.intp)]),
        space.base,
    )


def _delay_space(space: ParameterSpace, max_delay: float | None) -> tuple[ParameterSpace, float]:
    """The space with a delay coordinate in ``[-max_delay, max_delay]`` appended (none for ``None``), and the
    shift of that coordinate. The optimizer sees ``delay + 2 max_delay``, which is never zero: the relative
    scaling of the identifiability analysis (columns times |value|) would flag a parameter that sits at zero."""
    if max_delay is None:
        return space, 0.0
    shift = 2.0 * max_delay
    return _extended(space, ["delay"], [shift - max_delay], [shift + max_delay], [shift]), shift


def _stage(space: ParameterSpace, residuals: Callable[[Array], Array], starts: Array) -> tuple[Array, float, int]:
    """One continuation stage: bounded least squares in internal coordinates from every start (SI rows), without
    the uncertainty analysis (only the final, exact stage needs it). Returns the best SI vector, its cost
    (sum of squares) and the number of evaluations."""
    lo, hi = space.internal_bounds()
    best: Any = None
    evaluations = 0
    for p0 in np.atleast_2d(starts):
        sol = least_squares(lambda u: residuals(space.from_internal(u)), np.clip(space.to_internal(p0), lo, hi),
                            bounds=(lo, hi), x_scale="jac", method="trf")
        evaluations += int(sol.nfev)
        if best is None or sol.cost < best.cost:
            best = sol
    return space.from_internal(best.x), float(2 * best.cost), evaluations


def _sum_squares(residuals: Callable[[Array], Array], theta: Array) -> float:
    r = residuals(theta)
    return float(r @ r)


def _physical(estimate: ParameterEstimate, n: int, nuisance: Mapping[str, Any]) -> ParameterEstimate:
    """The estimate restricted to the first ``n`` (physical) unknowns; the marginal uncertainty of a block of a
    covariance is the block itself, so std, intervals and correlations stay valid."""
    diagnostics = dict(estimate.diagnostics)
    diagnostics.update(nuisance)
    for key in ("start", "bounds"):
        if isinstance(diagnostics.get(key), Mapping):
            diagnostics[key] = {k: v for k, v in diagnostics[key].items() if k in estimate.names[:n]}
    return replace(
        estimate,
        names=estimate.names[:n],
        values=estimate.values[:n],
        std=estimate.std[:n],
        ci95=estimate.ci95[:n],
        correlation=estimate.correlation[:n, :n],
        identifiable=estimate.identifiable[:n],
        diagnostics=diagnostics,
    )


def channel_names(requested: Sequence[str] | str) -> list[str]:
    """Channel names given as a sequence, or as one text: ``"F1"`` or ``"F1,F2"`` (what ``--setting inputs=F1``
    passes; iterated as a sequence it would be its characters)."""
    if isinstance(requested, str):
        return [name.strip() for name in requested.split(",")]
    return list(requested)


def _select(requested: Sequence[str] | str | None, model_names: tuple[str, ...], available: Sequence[str],
            what: str, source: str) -> list[str]:
    """Model inputs or outputs to use: the requested ones (each must be in the model and the data) or, by
    default, every model name the data has."""
    if requested is None:
        chosen = [n for n in model_names if n in available]
        if not chosen:
            msg = (
                f"{source} has none of the model's {what}s {list(model_names)}; it has channels {list(available)}"
            )
            raise DataError(msg)
        return chosen
    names = channel_names(requested)
    foreign = [n for n in names if n not in model_names]
    if foreign:
        msg = f"{what}s {foreign} are not {what}s of the model; its {what}s are {list(model_names)}"
        raise DataError(msg)
    missing = [n for n in names if n not in available]
    if missing:
        msg = f"{source} lacks the {what} channels {missing} needed; it has channels {list(available)}"
        raise DataError(msg)
    if not names:
        msg = f"{what}s must name at least one channel; got an empty list"
        raise DataError(msg)
    return names


def _orthonormal(basis: Array) -> Array:
    """Orthonormal columns spanning ``basis`` (rank-revealing: dependent columns are dropped)."""
    if basis.shape[1] == 0:
        return basis
    q, r, _ = sla.qr(basis, mode="economic", pivoting=True)
    diag = np.abs(np.diag(r))
    keep = diag > 1e-10 * (diag[0] if diag.size and diag[0] > 0 else 1.0)
    return np.asarray(q[:, keep])


# -- time domain ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Record:
    """One time record prepared for the fit: inputs (N, n_in) in SI, outputs (N, n_out) divided by ``scale``."""

    u: Array
    y: Array
    scale: Array


@dataclass(frozen=True)
class _Modes:
    """Modal form of the continuous model: ``x' = A x + B u``, ``y = C x + D u`` with ``A = V diag(lam) V^-1``.

    Only one member of each conjugate pair is kept (``weight`` 2, real eigenvalues weight 1), so
    ``y = Re(sum_i weight_i Cm_i z_i) + D u`` with ``z_i' = lam_i z_i + Bm_i u``.
    """

    lam: CArray  # (m,)
    bm: CArray  # (m, n_in)
    cm: CArray  # (n_out, m), weights and output scaling included
    d: Array  # (n_out, n_in), output scaling included


class _TimeModel:
    """Zero-order-hold simulation of a model's outputs to recorded inputs, in modal coordinates."""

    def __init__(self, model: NumericModel, position: Mapping[str, float] | None, inputs: Sequence[str],
                 outputs: Sequence[str], dt: float, intersample: str = "zoh") -> None:
        self.model = model
        self.position = position
        self.inputs = list(inputs)
        self.outputs = list(outputs)
        self.dt = dt
        self.intersample = intersample

    def modes(self, params: Array, scale: Array) -> _Modes:
        system = self.model.system(params, self.position)
        ss = system.state_space(self.inputs, self.outputs)
        lam, vec = np.linalg.eig(ss.A)
        if np.linalg.cond(vec) > 1e10:
            msg = (
                f"state matrix of model '{self.model.structure.name}' is not diagonalizable at these parameters "
                "(repeated or rigid-body poles); the one-step simulation needs distinct poles"
            )
            raise ModelError(msg)
        keep = lam.imag >= 0
        weight = np.where(lam.imag > 0, 2.0, 1.0)[keep]
        bm = np.linalg.solve(vec, ss.B.astype(complex))[keep]
        cm = (ss.C / scale[:, None]) @ vec[:, keep] * weight[None, :]
        return _Modes(lam[keep], bm, cm, ss.D / scale[:, None])

    def drive(self, modes: _Modes, u: Array, delay: float) -> tuple[CArray, Array]:
        """Modal drive ``g`` (N, m) with ``z[k+1] = mu z[k] + g[k]`` for an input delayed by ``delay`` samples
        (exact for a held input; for a linear one with ``intersample`` "foh" and "bl", the band-limited case's
        stand-in in the continuation stages), and the input seen by the direct feedthrough at the samples (N, n_in).
        """
        n = int(np.floor(delay))
        f = float(delay - n)
        lam, dt = modes.lam, self.dt
        ub = u @ modes.bm.T  # (N, m)
        held = _shift(u, n)
        if f > 0:
            # the delayed input at the samples lies between two of the record's samples: linear interpolation
            # (for a held input it keeps the direct feedthrough continuous in the delay, exact at whole samples)
            held = (1.0 - f) * held + f * _shift(u, n + 1)
        mu_rest = np.exp(lam * (1.0 - f) * dt)
        if self.intersample == "zoh":
            # held u[k-n-1] for f dt, then u[k-n] for (1 - f) dt
            g = _shift(ub, n) * hold_weights(lam, (1.0 - f) * dt, "zoh")[0]
            if f > 0:
                g = g + _shift(ub, n + 1) * (mu_rest * hold_weights(lam, f * dt, "zoh")[0])
            return g, held
        # linear input, delayed: over [k dt, (k + f) dt] from e_k to u[k-n], then to e_{k+1}, where
        # e_k = f u[k-n-1] + (1 - f) u[k-n] is the delayed input at the sample
        a0, a1 = hold_weights(lam, f * dt, "foh")
        b0, b1 = hold_weights(lam, (1.0 - f) * dt, "foh")
        e_now = (1.0 - f) * _shift(ub, n) + f * _shift(ub, n + 1)
        e_next = (1.0 - f) * _shift(ub, n - 1) + f * _shift(ub, n)
        g = e_now * (mu_rest * a0) + _shift(ub, n) * (mu_rest * a1 + b0) + e_next * b1
        return g, held

    def simulate(self, modes: _Modes, u: Array, delay: float) -> Array:
        """Outputs (N, n_out), divided by the record's scale, from rest."""
        if self.intersample == "bl":
            return self._band_limited(modes, u, delay)
        g, held = self.drive(modes, u, delay)
        mu = np.exp(modes.lam * self.dt)
        z = np.empty_like(g)
        for i, m in enumerate(mu):
            z[:, i] = sig.lfilter([0.0, 1.0], [1.0, -m], g[:, i])
        return np.asarray((z @ modes.cm.T).real + held @ modes.d.T)

    def _band_limited(self, modes: _Modes, u: Array, delay: float) -> Array:
        """Outputs for a band-limited input delayed by ``delay`` samples (exact: the delay is a linear phase)."""
        if modes.lam.size and np.any(modes.lam.real >= 0):
            msg = "the model has an undamped or unstable mode; a band-limited simulation needs every mode to decay"
            raise ModelError(msg)
        # each kept mode stands for itself and its conjugate (weight 2 in cm) or is real (weight 1)
        return band_limited_modal_response(modes.lam, modes.bm, modes.cm, modes.d, u, self.dt, delay=delay)

    def segments(self, modes: _Modes, u: Array, delay: float, sigma: float, length: int) -> tuple[Array, Array]:
        """Exponentially weighted zero-state responses of consecutive segments (n_seg, length, n_out), and the
        weighted free responses of the modes over one segment (length, n_out, 2 m) (real and imaginary parts)."""
        g, held = self.drive(modes, u, delay)
        n_seg = u.shape[0] // length
        w = np.exp(-sigma * self.dt)
        wj = w ** np.arange(length)
        wmu = w * np.exp(modes.lam * self.dt)
        drive = g[: n_seg * length].reshape(n_seg, length, -1) * (w * wj)[None, :, None]
        z = np.empty_like(drive)
        for i, m in enumerate(wmu):
            z[:, :, i] = sig.lfilter([0.0, 1.0], [1.0, -m], drive[:, :, i], axis=1)
        yh = np.einsum("sjm,om->sjo", z, modes.cm).real
        yh += np.einsum("sji,oi->sjo", held[: n_seg * length].reshape(n_seg, length, -1), modes.d) * wj[None, :, None]
        return np.asarray(yh), _free_response(wmu, modes.cm, length)


def _shift(x: NDArray[Any], n: int) -> NDArray[Any]:
    """``x[k - n]`` along axis 0 with zeros outside the record (n may be negative)."""
    if n == 0:
        return x
    out = np.zeros_like(x)
    if abs(n) >= x.shape[0]:
        return out
    if n > 0:
        out[n:] = x[:-n]
    else:
        out[:n] = x[-n:]
    return out


def _free_response(mu: CArray, cm: CArray, length: int) -> Array:
    """Outputs (length, n_out, 2 m) of the modes' free responses ``mu^k`` from unit initial states (real and
    imaginary parts): the columns that project out an unknown initial state."""
    free = (mu[None, :] ** np.arange(length)[:, None])[:, None, :] * cm[None, :, :]
    return np.concatenate([free.real, -free.imag], axis=2)


def _sandwich(result: ParameterEstimate, space: ParameterSpace, jacobian: Array, residuals: Array, n_out: int,
              records: Sequence[int], analysis: Mapping[str, Any]) -> ParameterEstimate:
    """The estimate with the Newey-West covariance of time-correlated residuals (:func:`correlated_uncertainty`).

    The bandwidth is twice the lag beyond which every output's residual autocorrelation stays inside its 99 %
    bound (at least the Newey-West rule ``4 (N / 100)^(2/9)``, at most N / 10 or 500 samples)."""
    lag = newey_west_bandwidth(records, analysis)
    base = jacobian_uncertainty(names=space.names, values=result.values, jacobian=jacobian, residuals=residuals)
    hac = correlated_uncertainty(base, jacobian=jacobian, residuals=residuals, block=n_out, records=records,
                                 max_lag=lag)
    at_bound = list(result.diagnostics.get("at_bound", []))
    hac, practical = honest_intervals(space, hac, at_bound)
    diagnostics = {k: v for k, v in result.diagnostics.items()
                   if k not in ("practically_non_identifiable", "weakest_direction")}
    diagnostics["covariance"] = {"kind": "sandwich (Newey-West)", "lags": lag,
                                 "gauss_newton_std": dict(zip(space.names, result.std.tolist(), strict=True))}
    if practical:
        diagnostics["practically_non_identifiable"] = practical
        scale = np.where(hac.values != 0, np.abs(hac.values), 1.0)
        eigval, eigvec = np.linalg.eigh(np.nan_to_num(hac.covariance / np.outer(scale, scale)))
        diagnostics["weakest_direction"] = {"combination": null_direction_text(space.names, eigvec[:, -1]),
                                            "relative_std": float(np.sqrt(max(eigval[-1], 0.0)))}
    return replace(result, std=hac.std, ci95=hac.ci95, correlation=hac.correlation, identifiable=hac.identifiable,
                   diagnostics=diagnostics)


def _offset_basis(weights: Array, n_out: int) -> Array:
    """Per-output constants (length, n_out, n_out), each sample weighted by ``weights`` (length,)."""
    basis = np.zeros((weights.size, n_out, n_out))
    basis[:, np.arange(n_out), np.arange(n_out)] = weights[:, None]
    return basis


class OneStepEstimator(Estimator):
    """Time-domain output-error estimation of physical parameters (thesis 3.6.3, eq. 3.108).

    Minimizes ``sum_c sum_k ((y_model,c[k] - y_c[k]) / rms_c)^2`` over the unknowns, with per-output offsets and
    an input-output delay as nuisance parameters, by bounded trust-region least squares (finite-difference
    Jacobian in the log / scaled coordinates of :class:`ParameterSpace`) after a continuation in artificial
    damping (see the module notes).

    Parameters
    ----------
    model, unknowns, bounds, start, values, rng
        See :class:`Estimator`.
    inputs, outputs : sequence of str, optional
        Model inputs and outputs to use; each must be a channel of the data. Default: every model input any
        record has (a record without one of them had it at zero, e.g. an unexcited shaker) and every model output
        of the first record (all records must have them). Model inputs that are not used are taken as zero.
    position : mapping, optional
        Axis position of the model.
    offsets : bool
        Estimate a constant offset per output channel.
    delay : bool
        Estimate an input-output delay.
    max_delay : float, optional
        Bound of the delay search in s (the delay lies in ``[-max_delay, max_delay]``); default five samples.
    initial_state : bool
        Also fit the record's initial state (free response) in the final exact stage; by default the record
        starts at rest (as simulated measurements do).
    continuation : sequence of float
        Artificial damping ratios of the stages before the exact fit (``()``: plain output error).
    starts : int
        Number of starts: the start, plus random points in the bounds (drawn with ``rng``); all enter the first
        stage and the lowest cost continues.
    intersample : {"zoh", "foh", "bl"}
        The inputs between samples (:mod:`cappe.systems.statespace`): held (default, as
        :func:`cappe.systems.time_response` simulates by default), linear, or band-limited (what a DAQ with an
        anti-alias filter records; the final fit is then exact in the frequency domain, the continuation stages
        use the linear input).
    covariance : {"auto", "gauss-newton", "sandwich"}
        ``"gauss-newton"``: ``s^2 (J^T J)^-1``, right for white residuals; ``"sandwich"``: the Newey-West covariance
        of residuals correlated in time (:func:`cappe.estimate._uncertainty.correlated_uncertainty`); ``"auto"``
        (default): the sandwich where the residuals fail the whiteness test.

    Attributes
    ----------
    estimate_ : ParameterEstimate
        ``diagnostics`` hold ``offsets`` (SI, per output), ``delay`` (s and samples, with its standard error),
        the ``stages`` of the continuation and ``rms`` (the output scaling).

    Examples
    --------
    >>> from cappe.model import load_model
    >>> from cappe.identify import random_noise
    >>> from cappe.systems import time_response
    >>> model = load_model("builtin:two-mass-rig")
    >>> force = random_noise(fs=2000.0, duration=0.5, rms=10.0, rng=1, name="F1")
    >>> data = time_response(NumericModel(model).system({"k11": 1.5e6}), force, outputs=["d1", "d2"])
    >>> est = OneStepEstimator(model, ["k11"], delay=False).fit(data)
    >>> round(est.params_["k11"] / 1.5e6, 6)
    1.0
    """

    method: ClassVar[str] = "one-step"

    def __init__(
        self,
        model: NumericModel | Structure,
        unknowns: Sequence[str] | None = None,
        *,
        bounds: Mapping[str, Sequence[float]] | None = None,
        start: Mapping[str, float] | None = None,
        values: Mapping[str, float] | None = None,
        rng: RandomLike = None,
        inputs: Sequence[str] | None = None,
        outputs: Sequence[str] | None = None,
        position: Mapping[str, float] | None = None,
        offsets: bool = True,
        delay: bool = True,
        max_delay: float | None = None,
        initial_state: bool = False,
        continuation: Sequence[float] = CONTINUATION,
        starts: int = 1,
        intersample: str = "zoh",
        covariance: str = "auto",
    ) -> None:
        super().__init__(model, unknowns, bounds=bounds, start=start, values=values, rng=rng)
        self.inputs = inputs
        self.outputs = outputs
        self.position = position
        self.offsets = offsets
        self.delay = delay
        self.max_delay = max_delay
        self.initial_state = initial_state
        self.continuation = continuation
        self.starts = starts
        self.intersample = intersample
        self.covariance = covariance

    # -- data --------------------------------------------------------------------------------------------------
    def _records(self, model: NumericModel, data: Any) -> tuple[list[str], list[str], float, list[_Record]]:
        items = [data] if isinstance(data, TimeData) else list(data) if isinstance(data, Sequence) else None
        if not items or not all(isinstance(d, TimeData) for d in items):
            msg = f"one-step estimation needs TimeData (or a list of TimeData records); got {type(data).__name__}"
            raise DataError(msg)
        first = items[0]
        union = sorted({c for d in items for c in d.channels}, key=lambda c: (c not in first.channels, c))
        inputs = _select(self.inputs, model.input_names, union, "input", "time data")
        outputs = _select(self.outputs, model.output_names, first.channels, "output", "time data")
        dt = first.dt
        records = []
        for k, record in enumerate(items):
            source = "time data" if len(items) == 1 else f"time data record {k}"
            if self.inputs is not None:
                _select(inputs, model.input_names, record.channels, "input", source)
            _select(outputs, model.output_names, record.channels, "output", source)
            if not np.isclose(record.dt, dt, rtol=1e-9):
                msg = f"{source} has sample time {record.dt:g} s; every record must share {dt:g} s"
                raise DataError(msg)
            u = np.column_stack([record.channel(n) if n in record.channels else np.zeros(record.n_samples)
                                 for n in inputs])
            y = np.column_stack([record.channel(n) for n in outputs])
            centred = y - y.mean(axis=0) if self.offsets else y
            scale = np.sqrt(np.mean(centred**2, axis=0))
            peak = np.max(np.abs(y), axis=0)
            flat = [n for n, s, m in zip(outputs, scale, peak, strict=True) if not s > 1e-12 * m]
            if flat:
                msg = f"{source}: output channels {flat} are constant; they carry no response to fit"
                raise DataError(msg)
            records.append(_Record(u, y / scale, scale))
        return inputs, outputs, dt, records

    # -- the fit -----------------------------------------------------------------------------------------------
    def _fit(self, model: NumericModel, space: ParameterSpace, data: Any,
             rng: np.random.Generator) -> Fitted:
        inputs, outputs, dt, records = self._records(model, data)
        n_samples = sum(r.u.shape[0] for r in records)
        max_delay = 0.0  # in samples
        if self.delay:
            max_delay = 5.0 if self.max_delay is None else positive_number("max_delay", self.max_delay, "s") / dt
        n_extra = 1 if self.delay else 0
        if n_samples * len(outputs) <= 2 * (space.n + n_extra + len(outputs)):
            msg = (
                f"time data have {n_samples} samples of {len(outputs)} outputs; too few for {space.n} unknowns "
                "and the nuisance parameters"
            )
            raise DataError(msg)
        stages_zeta = [float(z) for z in self.continuation]
        if any(not (np.isfinite(z) and z > 0) for z in stages_zeta):
            msg = f"continuation must list artificial damping ratios > 0; got {list(self.continuation)!r}"
            raise DataError(msg)
        if self.covariance not in ("auto", "gauss-newton", "sandwich"):
            msg = f"covariance must be 'auto', 'gauss-newton' or 'sandwich'; got {self.covariance!r}"
            raise DataError(msg)
        sim = _TimeModel(model, self.position, inputs, outputs, dt, check_intersample(self.intersample))
        full, shift = _delay_space(space, max_delay if self.delay else None)

        def split(theta: Array) -> tuple[Array, float]:
            return space.full(theta[: space.n]), float(theta[space.n] - shift) if self.delay else 0.0

        def exact_residuals(theta: Array) -> Array:
            params, delay = split(theta)
            out = []
            for rec in records:
                modes = sim.modes(params, rec.scale)
                r = sim.simulate(modes, rec.u, delay) - rec.y
                out.append(self._project(r, modes, sim, free=self.initial_state))
            return np.concatenate(out)

        def weighted_residuals(sigma: float, length: int) -> Callable[[Array], Array]:
            def residuals(theta: Array) -> Array:
                params, delay = split(theta)
                out = []
                for rec in records:
                    n_seg = rec.u.shape[0] // length
                    if n_seg == 0:
                        continue
                    modes = sim.modes(params, rec.scale)
                    yh, free = sim.segments(modes, rec.u, delay, sigma, length)
                    wj = np.exp(-sigma * dt * np.arange(length))
                    yd = rec.y[: n_seg * length].reshape(n_seg, length, -1) * wj[None, :, None]
                    cols = [free]
                    if self.offsets:
                        cols.append(_offset_basis(wj, len(outputs)))
                    q = _orthonormal(np.concatenate(cols, axis=2).reshape(length * len(outputs), -1))
                    r = (yh - yd).reshape(n_seg, -1)
                    out.append((r - (r @ q) @ q.T).ravel())
                return np.concatenate(out)

            return residuals

        starts = random_starts(space, self.starts, rng)
        current = np.column_stack([starts, np.full((starts.shape[0], n_extra), shift)])
        stages: list[dict[str, Any]] = []
        shortest = min(r.u.shape[0] for r in records)
        for zeta in stages_zeta:
            lowest = self._lowest_frequency(sim, current[0], split, records[0].scale)
            sigma = zeta * lowest
            length = int(np.ceil(_SEGMENT_DECAYS / (sigma * dt)))
            if 2 * length > shortest:
                stages.append({"zeta": zeta, "skipped": "record shorter than two weighted segments"})
                continue
            values, cost, evaluations = _stage(full, weighted_residuals(sigma, length), current)
            current = values[None, :]
            reached = space.mapping(values[: space.n])
            if self.delay:
                reached["delay_samples"] = float(values[space.n] - shift)
            stages.append({"zeta": zeta, "sigma": sigma, "segment_samples": length, "cost": cost,
                           "evaluations": evaluations, "values": reached})
        if stages_zeta and self.starts == 1:
            # safety: should the continuation have led away, the exact fit starts from the better point
            first = np.append(space.start, [shift] * n_extra)
            if _sum_squares(exact_residuals, first) < _sum_squares(exact_residuals, current[0]):
                current = first[None, :]
                stages.append({"note": "the start fits the exact output error better; the final fit starts there"})
        fitted = least_squares_fit(self.method, full, exact_residuals, starts=current,
                                   diagnostics={"stages": stages})
        result = fitted.estimate
        theta = result.values
        params, delay = split(theta)
        nuisance: dict[str, Any] = {
            "inputs": inputs,
            "outputs": outputs,
            "rms": {n: [float(r.scale[c]) for r in records] for c, n in enumerate(outputs)},
            "samples": n_samples,
            "dt": dt,
            "intersample": self.intersample,
        }
        if self.delay:
            std = float(result.std[space.n]) * dt
            nuisance["delay"] = {"value": delay * dt, "samples": delay, "std": std}
        if self.offsets:
            nuisance["offsets"] = self._offsets(sim, records, params, delay, outputs, len(theta), result.cost)
        if np.all(np.isfinite(theta)):
            flat = exact_residuals(theta)
            parts, at = [], 0
            for rec in records:
                parts.append(flat[at: at + rec.y.size].reshape(rec.y.shape))
                at += rec.y.size
            result = with_residual_tests(result, parts, [rec.u for rec in records], outputs, inputs)
            analysis = result.diagnostics.get("residual_analysis", {})
            coloured = "white" in analysis and not all(analysis["white"].values())
            if fitted.cost is not None and fitted.cost.jacobian is not None and (
                    self.covariance == "sandwich" or (self.covariance == "auto" and coloured)):
                result = _sandwich(result, full, fitted.cost.jacobian, flat, len(outputs),
                                   [rec.u.shape[0] for rec in records], analysis)
        return fitted.with_estimate(_physical(result, space.n, nuisance))

    def _project(self, r: Array, modes: _Modes, sim: _TimeModel, *, free: bool) -> Array:
        """Output error (N, n_out) with the offsets (and the free response) projected out, flattened."""
        if not self.offsets and not free:
            return r.ravel()
        if not free:
            return np.asarray((r - r.mean(axis=0)).ravel())
        n, n_out = r.shape
        cols = [_free_response(np.exp(modes.lam * sim.dt), modes.cm, n)]
        if self.offsets:
            cols.append(_offset_basis(np.ones(n), n_out))
        q = _orthonormal(np.concatenate(cols, axis=2).reshape(n * n_out, -1))
        flat = r.ravel()
        return np.asarray(flat - q @ (q.T @ flat))

    @staticmethod
    def _lowest_frequency(sim: _TimeModel, theta: Array, split: Callable[[Array], tuple[Array, float]],
                          scale: Array) -> float:
        lam = np.abs(sim.modes(split(theta)[0], scale).lam)
        lam = lam[lam > 0]
        return float(lam.min()) if lam.size else 1.0 / sim.dt

    def _offsets(self, sim: _TimeModel, records: list[_Record], params: Array, delay: float,
                 outputs: Sequence[str], n_theta: int, cost: float) -> dict[str, dict[str, list[float]]]:
        """Offsets (SI) per output and record at the estimate: the mean output error (or, with a fitted initial
        state, its least-squares constant), with the standard error of a mean of the residual noise."""
        values: dict[str, list[float]] = {n: [] for n in outputs}
        stds: dict[str, list[float]] = {n: [] for n in outputs}
        n_obs = sum(r.y.size for r in records)
        s2 = cost / max(n_obs - n_theta - len(outputs) * len(records), 1)
        for rec in records:
            modes = sim.modes(params, rec.scale)
            err = rec.y - sim.simulate(modes, rec.u, delay)
            n = err.shape[0]
            if self.initial_state:
                basis = np.concatenate([_free_response(np.exp(modes.lam * sim.dt), modes.cm, n),
                                        _offset_basis(np.ones(n), err.shape[1])], axis=2).reshape(err.size, -1)
                coef, *_ = np.linalg.lstsq(basis, err.ravel(), rcond=None)
                level = coef[-err.shape[1]:]
            else:
                level = err.mean(axis=0)
            for c, name in enumerate(outputs):
                values[name].append(float(level[c] * rec.scale[c]))
                stds[name].append(float(np.sqrt(s2 / n) * rec.scale[c]))
        return {"value": values, "std": stds}


# -- frequency domain -----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FRFDerivatives:
    """Model FRFs and their exact derivatives with respect to parameters.

    Attributes
    ----------
    freq : ndarray, shape (n_freq,)
        Frequencies in Hz.
    H : ndarray of complex, shape (n_out, n_in, n_freq)
        FRFs (m/N, m/s/N or m/s^2/N by output quantity).
    dH : ndarray of complex, shape (n_params, n_out, n_in, n_freq)
        ``dH / dp`` per parameter unit.
    parameter_names, input_names, output_names : tuple of str
        Names along the first axis of ``dH`` and the input and output axes of ``H``.
    position : dict
        Axis position of the model, ``{axis: value}`` (m or rad); empty for a model without axes.
    """

    freq: Array
    H: CArray
    dH: CArray
    parameter_names: tuple[str, ...]
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    position: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            "freq": self.freq.tolist(),
            "parameter_names": list(self.parameter_names),
            "input_names": list(self.input_names),
            "output_names": list(self.output_names),
            "position": dict(self.position),
            "H_re": self.H.real.tolist(),
            "H_im": self.H.imag.tolist(),
            "dH_re": self.dH.real.tolist(),
            "dH_im": self.dH.imag.tolist(),
        }


def _frf_core(model: NumericModel, params: Array, position: Mapping[str, float] | None, freq: Array,
              inputs: Sequence[int], outputs: Sequence[int], columns: Sequence[int] | None) -> tuple[CArray, CArray]:
    """H (n_out, n_in, n_f) and, for ``columns`` (parameter indices), dH (n_c, n_out, n_in, n_f): the dynamic
    stiffness kernel (:func:`cappe.systems.dynamic_stiffness.frf_lines`) plus the terms of input and output
    matrices that depend on parameters."""
    mats = model.matrices(params, position)
    b_mat, s_mat = model.io_matrices(params, position)
    w = 2 * np.pi * freq
    cols = None if columns is None else list(columns)
    derivs = None
    if cols is not None:
        d = model.matrix_derivatives(params, position)
        derivs = {name: d[name][cols] for name in ("M", "C", "K", "G", "H")}
    lines = frf_lines(mats, w, b_mat[:, list(inputs)], s_mat[list(outputs)], derivatives=derivs)
    order = np.array([DERIVATIVE_ORDER[model.output_quantities[o]] for o in outputs])
    factor = (1j * w)[None, :] ** order[:, None]  # (n_out, n_f)
    h = np.moveaxis(lines.H, 0, -1) * factor[:, None, :]
    if cols is None or lines.L is None:
        return h, np.zeros((0, *h.shape), dtype=complex)
    x, lt = lines.X, lines.L
    dh = np.moveaxis(lines.dH, 1, -1)
    # input and output matrices may depend on parameters (lengths): central differences, exact for affine terms
    for k, col in enumerate(cols):
        step = 1e-6 * max(abs(params[col]), 1e-6)
        plus, minus = params.copy(), params.copy()
        plus[col] += step
        minus[col] -= step
        bp, sp_ = model.io_matrices(plus, position)
        bm_, sm = model.io_matrices(minus, position)
        db = (bp - bm_)[:, list(inputs)] / (2 * step)
        ds = (sp_ - sm)[list(outputs)] / (2 * step)
        if np.any(db):
            dh[k] += np.einsum("fon,ni->oif", lt, db)
        if np.any(ds):
            dh[k] += np.einsum("on,fni->oif", ds, x)
    return h, dh * factor[None, :, None, :]


def frf_derivatives(
    *,
    model: NumericModel | Structure,
    freq: ArrayLike,
    params: ParamsLike = None,
    position: Mapping[str, float] | None = None,
    inputs: Sequence[str] | None = None,
    outputs: Sequence[str] | None = None,
    parameters: Sequence[str] | None = None,
) -> FRFDerivatives:
    """Model FRFs and their analytic parameter derivatives ``dH/dp = -S Z^-1 (dZ/dp) Z^-1 B``.

    ``Z = K + jH + j omega (C + G) - omega^2 M`` is the dynamic stiffness; its derivatives are exact because the
    matrices are affine in their coefficients (:meth:`NumericModel.matrix_derivatives`). Velocity and
    acceleration outputs carry the factor ``(j omega)^order``.

    Parameters
    ----------
    model : NumericModel or Structure
    freq : array_like, shape (n_freq,)
        Frequencies in Hz.
    params : mapping or array, optional
        Parameter values (default nominal).
    position : mapping, optional
        Axis position.
    inputs, outputs : sequence of str, optional
        Model inputs and outputs (default all).
    parameters : sequence of str, optional
        Parameters to differentiate with respect to (default all).

    Examples
    --------
    >>> from cappe.model import load_model
    >>> d = frf_derivatives(model=load_model("builtin:two-mass-rig"), freq=[0.0], inputs=["F1"], outputs=["d1"],
    ...                     parameters=["k11"])
    >>> bool(np.isclose(d.dH[0, 0, 0, 0], -d.H[0, 0, 0] ** 2))  # static flexibility (k12 + k22) / det K
    True
    """
    nm = model if isinstance(model, NumericModel) else NumericModel(model)
    f = np.atleast_1d(np.asarray(freq, dtype=float))
    if f.ndim != 1 or not np.all(np.isfinite(f)) or np.any(f < 0):
        msg = "freq must be a 1-D array of finite frequencies >= 0 Hz"
        raise DataError(msg)
    p = nm.vector(params)
    ins = _select(inputs, nm.input_names, nm.input_names, "input", "model")
    outs = _select(outputs, nm.output_names, nm.output_names, "output", "model")
    names = list(parameters) if parameters is not None else list(nm.parameter_names)
    bad = [n for n in names if n not in nm.parameter_names]
    if bad:
        msg = f"parameters {bad} are not parameters of model '{nm.structure.name}'"
        raise ModelError(msg)
    h, dh = _frf_core(nm, p, position, f, [nm.input_names.index(n) for n in ins],
                      [nm.output_names.index(n) for n in outs], [nm.parameter_names.index(n) for n in names])
    return FRFDerivatives(f, h, dh, tuple(names), tuple(ins), tuple(outs),
                          dict(zip(nm.axis_names, nm.position_vector(position), strict=True)))


@dataclass(frozen=True)
class _FRFProblem:
    """Residuals and Jacobian of an FRF fit over the (extended) space; ``shift`` offsets the delay coordinate."""

    space: ParameterSpace
    shift: float
    residuals: Callable[[Array], Array]
    jacobian: Callable[[Array], Array]
    info: dict[str, Any]
    pairs: tuple[tuple[str, int], ...] = ()  # ("output/input", lines used) in the residuals' order
    trusted: NDArray[np.bool_] | None = None  # lines whose residual the runs test judges (coherence >= 0.9)


class OneStepFRFEstimator(Estimator):
    """Frequency-domain output-error estimation on measured FRFs, with an analytic Jacobian.

    Residuals ``sqrt(w) [Re, Im] log(H_model e^{-j omega tau} / H_meas)`` (or the relative complex error) over
    the lines of ``band``; see the module notes for the choice of the logarithm and of the coherence weights
    ``w = gamma^2 / (1 - gamma^2)``.

    Parameters
    ----------
    model, unknowns, bounds, start, values, rng
        See :class:`Estimator`.
    inputs, outputs : sequence of str, optional
        FRF inputs and outputs to use (default: every model input / output the data have).
    position : mapping, optional
        Axis position of the model.
    band : (float, float), optional
        Frequency band in Hz (default: every line above 0 Hz).
    residual : {"log", "relative"}
        ``"log"``: log-magnitude and phase errors (default; smooth far from the optimum). ``"relative"``: complex
        error ``(H_model - H_meas) / |H_meas|``, whose weighted cost is the output-noise likelihood of an H1
        estimate (unbiased also at lines of low coherence, where the logarithm of a noisy value is biased).
    weighting : {"coherence", "uniform"}
        Coherence weights where the data have a coherence, else uniform.
    delay : bool
        Estimate an input-output delay ``tau`` (linear phase), reported in ``diagnostics["delay"]``.
    max_delay : float, optional
        Bound of the delay in s (default 5 / (2 f_max), i.e. five samples of a record sampled at 2 f_max).
    starts : int
        Number of starts (the start, plus random points in the bounds).

    Examples
    --------
    >>> from cappe.model import load_model
    >>> model = load_model("builtin:two-mass-rig")
    >>> frf = NumericModel(model).system({"k22": 0.3e6, "c22": 3.0}).frf(np.arange(10, 300, 0.5), ["F1"], ["d2"])
    >>> est = OneStepFRFEstimator(model, ["k22", "c22"]).fit(frf)
    >>> {k: round(v, 6) for k, v in est.params_.items()}
    {'k22': 300000.0, 'c22': 3.0}
    """

    method: ClassVar[str] = "one-step-frf"

    def __init__(
        self,
        model: NumericModel | Structure,
        unknowns: Sequence[str] | None = None,
        *,
        bounds: Mapping[str, Sequence[float]] | None = None,
        start: Mapping[str, float] | None = None,
        values: Mapping[str, float] | None = None,
        rng: RandomLike = None,
        inputs: Sequence[str] | None = None,
        outputs: Sequence[str] | None = None,
        position: Mapping[str, float] | None = None,
        band: tuple[float, float] | None = None,
        residual: str = "log",
        weighting: str = "coherence",
        delay: bool = False,
        max_delay: float | None = None,
        starts: int = 1,
    ) -> None:
        super().__init__(model, unknowns, bounds=bounds, start=start, values=values, rng=rng)
        self.inputs = inputs
        self.outputs = outputs
        self.position = position
        self.band = band
        self.residual = residual
        self.weighting = weighting
        self.delay = delay
        self.max_delay = max_delay
        self.starts = starts

    def _prepare(self, model: NumericModel, data: Any) -> tuple[list[str], list[str], Array, CArray, Array]:
        """Chosen inputs and outputs, the lines used, measured H (n_out, n_in, n_f) and the weights (same shape,
        zero for lines without a finite non-zero measurement)."""
        if not isinstance(data, FRFData):
            msg = f"one-step FRF estimation needs FRFData; got {type(data).__name__}"
            raise DataError(msg)
        inputs = _select(self.inputs, model.input_names, data.input_names, "input", "FRF data")
        outputs = _select(self.outputs, model.output_names, data.output_names, "output", "FRF data")
        if self.residual not in ("relative", "log"):
            msg = f"residual must be 'relative' or 'log'; got {self.residual!r}"
            raise DataError(msg)
        if self.weighting not in ("coherence", "uniform"):
            msg = f"weighting must be 'coherence' or 'uniform'; got {self.weighting!r}"
            raise DataError(msg)
        freq = np.asarray(data.freq, dtype=float)
        keep = freq > 0
        if self.band is not None:
            try:
                lo, hi = (float(v) for v in self.band)
            except (TypeError, ValueError) as exc:
                msg = f"band must be (f_lo, f_hi) in Hz; got {self.band!r}"
                raise DataError(msg) from exc
            if not (np.isfinite(lo) and np.isfinite(hi) and 0 <= lo < hi):
                msg = f"band must satisfy 0 <= f_lo < f_hi (Hz); got {self.band!r}"
                raise DataError(msg)
            keep &= (freq >= lo) & (freq <= hi)
        if not keep.any():
            msg = (f"FRF data have no line above 0 Hz inside band {self.band!r}; lines span "
                   f"{freq.min():g}..{freq.max():g} Hz")
            raise DataError(msg)
        oi = [data.output_names.index(n) for n in outputs]
        ii = [data.input_names.index(n) for n in inputs]
        h = np.asarray(data.H, dtype=complex)[np.ix_(oi, ii)][:, :, keep]
        if self.weighting == "coherence" and data.coherence is not None:
            gamma2 = np.clip(np.asarray(data.coherence, dtype=float)[np.ix_(oi, ii)][:, :, keep], 0.0, _MAX_COHERENCE)
            weights = gamma2 / (1.0 - gamma2)
        else:
            weights = np.ones(h.shape)
        valid = np.isfinite(h) & (np.abs(h) > 0)
        weights = np.where(valid, weights, 0.0)
        if not np.any(weights > 0):
            msg = "FRF data have no line with a finite, non-zero response and coherence > 0 to fit"
            raise DataError(msg)
        weights = weights / weights[weights > 0].mean()
        h = np.where(valid, h, 1.0)
        self._trusted = (gamma2 >= _TRUSTED_COHERENCE if self.weighting == "coherence" and data.coherence is not None
                         else np.ones(h.shape, dtype=bool))
        return inputs, outputs, freq[keep], h, weights

    def _problem(self, model: NumericModel, space: ParameterSpace, data: Any) -> _FRFProblem:
        """The weighted residuals and their analytic Jacobian over the unknowns (and the delay)."""
        inputs, outputs, freq, measured, weights = self._prepare(model, data)
        mask = weights > 0
        sqrt_w = np.sqrt(weights[mask])
        log_meas = np.log(measured[mask])
        omega = np.broadcast_to(2 * np.pi * freq, measured.shape)[mask]
        in_idx = [model.input_names.index(n) for n in inputs]
        out_idx = [model.output_names.index(n) for n in outputs]
        max_delay = 0.0
        if self.delay:
            max_delay = (positive_number("max_delay", self.max_delay, "s") if self.max_delay is not None
                         else 2.5 / float(freq.max()))
        full, shift = _delay_space(space, max_delay if self.delay else None)
        n_obs = 2 * int(mask.sum())
        if n_obs <= full.n:
            msg = f"FRF data give {n_obs} real residuals; too few for {full.n} unknowns"
            raise DataError(msg)
        cache: dict[bytes, tuple[CArray, CArray]] = {}

        def model_frf(theta: Array) -> tuple[CArray, CArray]:
            key = theta.tobytes()
            if key not in cache:
                cache.clear()
                try:
                    cache[key] = _frf_core(model, space.full(theta[: space.n]), self.position, freq, in_idx,
                                           out_idx, space.columns.tolist())
                except np.linalg.LinAlgError as exc:
                    msg = "dynamic stiffness is singular at a fitted frequency line"
                    raise ModelError(msg) from exc
            return cache[key]

        at_start = model_frf(np.append(space.start, [shift] * (full.n - space.n)))[0]
        silent = [f"{o} / {i}" for a, o in enumerate(outputs) for b, i in enumerate(inputs)
                  if np.any(mask[a, b]) and not np.any(at_start[a, b] != 0)]
        if silent:
            msg = f"the model has no response for the FRF pairs {silent} (output / input); leave them out"
            raise DataError(msg)
        meas = measured[mask]
        inv_abs = 1.0 / np.abs(meas)

        def rotation(theta: Array) -> CArray:  # linear-phase factor of the delay
            if not self.delay:
                return np.ones(omega.shape, dtype=complex)
            return np.asarray(np.exp(-1j * omega * (theta[space.n] - shift)))

        def residuals(theta: Array) -> Array:
            h = model_frf(theta)[0][mask] * rotation(theta)
            if self.residual == "log":
                ell = np.log(h) - log_meas
                err = ell.real + 1j * np.angle(np.exp(1j * ell.imag))  # phase error wrapped to (-pi, pi]
            else:
                err = (h - meas) * inv_abs
            return np.concatenate([sqrt_w * err.real, sqrt_w * err.imag])

        def jacobian(theta: Array) -> Array:
            h_all, dh_all = model_frf(theta)
            rot = rotation(theta)
            h, dh = h_all[mask] * rot, dh_all[:, mask] * rot[None, :]
            scale = 1.0 / h if self.residual == "log" else inv_abs
            d = dh * scale[None, :]  # (n_c, n_lines)
            cols = [np.concatenate([sqrt_w * d.real, sqrt_w * d.imag], axis=1).T]
            if self.delay:
                dd = -1j * omega * h * scale
                cols.append(np.concatenate([sqrt_w * dd.real, sqrt_w * dd.imag])[:, None])
            return np.hstack(cols)

        info: dict[str, Any] = {"inputs": inputs, "outputs": outputs, "lines": int(freq.size),
                                "band": [float(freq.min()), float(freq.max())], "residual": self.residual,
                                "weighting": self.weighting if data.coherence is not None else "uniform"}
        trusted = self._trusted[mask]  # in the residuals' line order
        counts = mask.sum(axis=2)
        pairs = tuple((f"{o}/{i}", int(counts[a, b])) for a, o in enumerate(outputs) for b, i in enumerate(inputs)
                      if counts[a, b])
        return _FRFProblem(full, shift, residuals, jacobian, info, pairs, trusted)

    def _fit(self, model: NumericModel, space: ParameterSpace, data: Any,
             rng: np.random.Generator) -> Fitted:
        problem = self._problem(model, space, data)
        full, shift = problem.space, problem.shift
        starts = random_starts(space, self.starts, rng)
        starts = np.column_stack([starts, np.full((starts.shape[0], full.n - space.n), shift)])
        fitted = least_squares_fit(self.method, full, problem.residuals, problem.jacobian, starts=starts)
        result = fitted.estimate
        nuisance = dict(problem.info)
        if self.delay:
            nuisance["delay"] = {"value": float(result.values[space.n] - shift), "std": float(result.std[space.n])}
        estimate = _physical(result, space.n, nuisance)
        if fitted.cost is not None:
            estimate = self._runs_test(estimate, problem, problem.residuals(fitted.cost.centre))
        return fitted.with_estimate(estimate)

    @staticmethod
    def _runs_test(estimate: ParameterEstimate, problem: _FRFProblem, r: Array) -> ParameterEstimate:
        """The estimate with a runs test of its residuals along frequency (:func:`cappe.identify.runs_test`) at the
        lines of coherence >= 0.9 (all lines without coherence): long runs of one sign are a misfit far above the
        noise, so ``success`` becomes False and the message says so."""
        from cappe.identify._residual_analysis import runs_test

        diagnostics = dict(estimate.diagnostics)
        half = r.size // 2
        if not np.sqrt(np.mean(r**2)) > 1e-8:  # an exact fit: rounding, nothing to test
            diagnostics["residual_analysis"] = {"exact_fit": True}
            return replace(estimate, diagnostics=diagnostics)
        series, names, at = [], [], 0
        trusted = problem.trusted if problem.trusted is not None else np.ones(half, dtype=bool)
        for label, count in problem.pairs:
            for part, offset in (("real", 0), ("imag", half)):
                series.append(r[offset + at: offset + at + count][trusted[at: at + count]])
                names.append(f"{label} {'log-magnitude' if problem.info['residual'] == 'log' else 'real'}"
                             if part == "real" else
                             f"{label} {'phase' if problem.info['residual'] == 'log' else 'imag'}")
            at += count
        test = runs_test(residuals=series, names=names)
        diagnostics["residual_analysis"] = test.to_dict()
        diagnostics["warnings"] = [*diagnostics.get("warnings", []), *test.warnings()]
        if test.passed:
            diagnostics.setdefault("fit_test", "passed")
            return replace(estimate, diagnostics=diagnostics)
        diagnostics["fit_test"] = "failed"
        message = "the residuals are a systematic misfit, not noise: the model does not explain the FRFs"
        if estimate.message:
            message = f"{message} ({estimate.message})"
        return replace(estimate, success=False, message=message, diagnostics=diagnostics)
