"""Kalman-filter estimators: the unknown parameters as augmented states (thesis 3.6.4, 5.3.4.3).

The augmented state is ``z = [theta, q, q']``: ``theta`` are the unknowns in the parameter space's internal
coordinates (``log p`` for bounded positive parameters, so masses and stiffnesses stay positive and the random walk
is relative), ``q, q'`` the displacements and velocities of the model's DOFs. Between samples the inputs are held
(zero-order hold, ``intersample="zoh"``) or linear (first-order hold, ``"foh"``: what :func:`scipy.signal.lsim`
simulates, and the nearer of the two to a band-limited DAQ record) and the parameters follow a random walk, so the
transition is

    x[k+1] = Ad(theta) x[k] + B0(theta) w[k] + B1(theta) w[k+1],        theta[k+1] = theta[k] + random walk,

with ``Ad = expm(A dt)`` and ``B0, B1`` the exact hold weights of the continuous model at ``theta``
(:func:`cappe.systems.statespace.hold_matrices`; ``B1 = 0`` for a held input). The next input ``w[k+1]`` is a
recorded sample, so the linear input needs no extra state. A band-limited input (``"bl"``) is refused: between two
samples it depends on every sample of the record (its interpolation is non-causal and unbounded), so no transition
from one sample to the next exists for a filter to step with. The measurements are the
model's named outputs (displacement ``S q``, velocity ``S q'``, acceleration ``S M^-1 (B w - C q' - K q)``).

**EKF.** The transition and its Jacobian with respect to theta are exact at a linearization point ``theta0``:
``Ad, B0, B1`` and their derivatives come from one matrix exponential of a block-triangular matrix (Van Loan 1978:
the upper blocks of ``expm([[Z, E_j], [0, Z]])`` are the Frechet derivatives of ``expm`` at ``Z`` in direction
``E_j``), with ``dA/dtheta`` from the exact affine matrix derivatives of M, C and K. Between re-linearizations
the filter uses the first-order expansion ``Ad(theta0) + sum_j dAd_j (theta - theta0)_j``; a new exact
linearization is made whenever theta has moved by more than 0.01 in internal coordinates (1 % for log
parameters), so the error of the expansion stays below ~1e-4 relative, far below the measurement noise. The
covariance update uses the Joseph form ``(I - KH) P (I - KH)^T + K R K^T``, which keeps P symmetric positive
definite where the short form ``(I - KH) P`` loses it by round-off (the state mixes displacements of 1e-6 m with
log parameters of order 1; the states are also scaled to unit RMS for the same reason).

**UKF.** Sigma points (scaled unscented transform, Wan & van der Merwe 2000) of the augmented state; each sigma
point is propagated through the exact transition (ZOH or FOH) of the model at its own theta. With the state
ordered ``[theta, x]`` and an upper Cholesky factor, only ``2 n_theta + 1`` distinct parameter vectors occur per
step; their matrix exponentials are computed as one batch (:func:`expm_batch`). The process noise is added before
the propagation, so that the sigma points the measurement update sees carry the parameters' random walk.

**Convergence.** One forward pass of an EKF from a poor start over a record of a lightly damped system is known
to stall or diverge (the thesis's seven-parameter case, 5.3.4.3). Here: internal coordinates; states, inputs and
outputs scaled to unit RMS; an initial covariance from the bounds (each bound interval taken as +-2 standard
deviations); exact discretization; and several forward passes over the record. Each later pass re-starts at the
previous estimate with the previous pass's (output-error) covariance inflated by ``inflation`` (capped at the
bounds' covariance) and at the least-squares initial state; the passes stop when no determined parameter moved
by more than ``tol`` or a quarter of its standard error. The prior of a pass is centred on the previous
estimate, so its pull vanishes at the fixed point.
The passes approach their fixed point slowly along weakly determined directions (F1 only, 5 % noise: the rig's
(m2, k12, k22, c22) moved by ~1 % a pass for 12 passes, 4 of 10 records unconverged after 6 and one 7 standard
errors off; issue 21). With constant parameters the filter's estimate is therefore the start of Gauss-Newton steps
of the output-error fit (``refine``, default on): the same exact sensitivities as the uncertainty below, the
initial state a nuisance, a step halved until it lowers the cost, stopped when every determined parameter's next
step is below ``tol`` or a tenth of its standard error. The estimate is then the output-error optimum, the point
the reported covariance belongs to; the filter's own estimate stays in the diagnostics.

**Initial state.** The filter evaluates the sensitivity to theta along its own state estimate. Where that estimate
has absorbed measurement noise (unknown initial state, wide parameter prior at the start of a pass), a spurious
free vibration reads as information about the masses and stiffnesses that set its frequency: a weakly excited
parameter then looks determined and is biased. The least-squares initial state (taken as rest when it is
indistinguishable from rest) and the modest inflation keep the later passes clear of this.

**Uncertainty and identifiability.** Constant parameters with a trusted model (no process noise, no random walk):
the covariance is the inverse of the output-error Fisher information at the estimate (exact sensitivities of the
simulated outputs, the initial state as a nuisance parameter) plus the bounds prior, which is what the data
support, not the filter's own covariance (reported as ``filter_std``), which the mechanism above can make far too
small. Tracking: the filter's covariance, with ``inv(P_end) - inv(P_start + N Q_theta)`` as the data's
information. Either information, whitened by the bounds prior, has eigenvalues that say how many times more the
data know along a direction than the bounds do: below 1 the direction is undetermined, the parameters with weight
above 0.1 in it are flagged non-identifiable (``std`` nan) and the direction is reported as a combination.

**Residual tests.** Constant parameters: the output errors of the simulation at the estimate (from the fitted
initial state) are tested as one-step's (MATLAB ``resid``, :func:`cappe.estimate._base.with_residual_tests`):
errors that correlate with an input fail the fit (the model of the structure or of the inputs between samples is
wrong), coloured errors warn and, with ``covariance="auto"``, switch the covariance to the Newey-West sandwich
around the same information (the one-step's, :func:`cappe.estimate._uncertainty.newey_west_meat`).

filterpy (``ExtendedKalmanFilter``, ``UnscentedKalmanFilter``) was judged and not used on the hot path: it calls
the user's transition once per sigma point in a Python loop and copies its state several times per step, which
costs more than the whole vectorized step here, and it offers neither the lazy exact linearization nor the state
scaling. The tests use it as the independent reference for the filter equations.
"""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from cappe._rng import RandomLike
from cappe.estimate._base import Estimator, with_residual_tests
from cappe.estimate._intersample import forced_responses, intersample_sensitivity, sensitivity_warning
from cappe.estimate._one_step import _select as _select_channels
from cappe.estimate._result import ParameterEstimate
from cappe.estimate._space import ParameterSpace
from cappe.estimate._uncertainty import _NULL_WEIGHT, newey_west_bandwidth, newey_west_meat, null_direction_text
from cappe.exceptions import DataError
from cappe.model import NumericModel, Structure
from cappe.systems.mechanical import DERIVATIVE_ORDER
from cappe.systems.statespace import check_intersample
from cappe.systems.timedata import TimeData

__all__ = ["ExtendedKalmanEstimator", "UnscentedKalmanEstimator"]

Array = NDArray[np.float64]

#: Internal-coordinate change after which the EKF makes a new exact linearization (1 % for log parameters).
_RELINEARIZE = 0.01
#: Rows kept of the parameter trajectory in the diagnostics.
_MAX_ROWS = 2000
#: A direction whose data information is below this multiple of the bounds prior's is undetermined.
_INFO_RATIO = 1.0
#: Variance (scaled states) of an initial state known to be at rest.
_REST_VAR = 1e-12
#: Samples used for the least-squares initial state.
_X0_SAMPLES = 2000
#: Most Gauss-Newton steps of the output-error refinement after the filter's passes (a UKF record at 5 % noise
#: needed 10, with 23 halvings, from a filter estimate 7 % off; 8 left it 3.8 std off and unconverged).
_REFINE_STEPS = 20
#: Most filter passes where nothing refines their estimate (tracking, ``refine=False``).
_PASSES = 6
#: The UKF's passes before the output-error refinement, which reaches the same optimum from a rougher start: on the
#: two-mass rig (F1, lsim, 10 seeds) 2 passes and the refinement gave the 6 passes' coverage and accuracy at 5.6
#: instead of 15.7 CPU-s (1 % noise) and 12.1 instead of 17.1 (5 %; benchmarks/results/coverage_ukf_passes.json).
_REFINED_PASSES = 2
#: Measurement noise (fraction of each output's RMS) of the first pass when none is given.
_FIRST_NOISE = 0.05
#: Why the filters refuse a band-limited input (module notes).
BAND_LIMITED_REFUSAL = (
    "a Kalman filter steps from one sample to the next, and a band-limited input between two samples depends on "
    "every sample of the record (its interpolation is non-causal and unbounded), so no such step exists; fit "
    "band-limited data with one-step, or use intersample 'foh' here (its gain error is about (omega h)^2 / 12 "
    "at omega, h the sample time)"
)


# ---------------------------------------------------------------------------------------------------------------
# data and the augmented model
# ---------------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Record:
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    w: Array  # (N, n_in) forces
    y: Array  # (N, m) measurements
    dt: float


def _select(
    nm: NumericModel, data: Any, inputs: Sequence[str] | str | None, outputs: Sequence[str] | str | None
) -> _Record:
    """Input and output channels of a TimeData, matched to the model's inputs and outputs by name (as for the
    one-step method: by default every model input and output the data have)."""
    if not isinstance(data, TimeData):
        msg = f"Kalman-filter estimation needs TimeData (forces and responses); got {type(data).__name__}"
        raise DataError(msg)
    chosen_in = _select_channels(inputs, nm.input_names, data.channels, "input", "time data")
    chosen_out = _select_channels(outputs, nm.output_names, data.channels, "output", "time data")
    if data.n_samples < 10:
        msg = f"Kalman-filter estimation needs at least 10 samples; got {data.n_samples}"
        raise DataError(msg)
    w = np.ascontiguousarray(data.values[[data.index(c) for c in chosen_in]].T)
    y = np.ascontiguousarray(data.values[[data.index(c) for c in chosen_out]].T)
    return _Record(tuple(chosen_in), tuple(chosen_out), w, y, float(data.dt))


def _rms(values: Array) -> Array:
    return np.asarray(np.sqrt(np.mean(values**2, axis=0)), dtype=float)


def _equivalent_viscous(mass: Array, stiff: Array, hyst: Array) -> Array:
    """Batched viscous matrices giving each undamped mode the first-order damping of H (B, n, n)."""
    low = np.linalg.cholesky(mass)
    inv_low = np.linalg.inv(low)
    lam, psi = np.linalg.eigh(inv_low @ stiff @ np.swapaxes(inv_low, -1, -2))
    phi = np.swapaxes(inv_low, -1, -2) @ psi
    omega = np.sqrt(np.clip(lam, 0.0, None))
    hv = np.einsum("bir,bij,bjr->br", phi, hyst, phi)
    coef = np.where(omega > 0, hv / np.where(omega > 0, omega, 1.0), 0.0)
    mphi = mass @ phi
    return np.asarray((mphi * coef[:, None, :]) @ np.swapaxes(mphi, -1, -2), dtype=float)


#: Pade coefficients of degree 7 and the norm up to which they give double precision (Higham 2005, Table 2.3).
_PADE7 = (17297280.0, 8648640.0, 1995840.0, 277200.0, 25200.0, 1512.0, 56.0, 1.0)
_THETA7 = 0.9504178996162932
_MATRICES = ("M", "C", "K", "G", "H")


def expm_batch(z: Array) -> Array:
    """Matrix exponentials of a stack (B, s, s): scaling and squaring with the degree-7 Pade approximant.

    ``scipy.linalg.expm`` treats a stack one matrix at a time (about 10 us each); the filters need tens of small
    exponentials per sample, so this applies Higham's (2005) algorithm at a fixed degree to the whole stack: the
    stack is scaled by ``2^-s`` until its largest 1-norm is below 0.95, where degree 7 is accurate to double
    precision, and the result squared ``s`` times.

    Examples
    --------
    >>> import scipy.linalg
    >>> z = np.array([[[0.0, 1.0], [-4.0, -0.1]], [[-1.0, 0.0], [0.0, -2.0]]])
    >>> bool(np.allclose(expm_batch(z), [scipy.linalg.expm(m) for m in z], rtol=1e-13, atol=1e-15))
    True
    """
    mats = np.asarray(z, dtype=float)
    norm = float(np.max(np.sum(np.abs(mats), axis=-2))) if mats.size else 0.0
    squarings = max(0, int(np.ceil(np.log2(norm / _THETA7)))) if norm > _THETA7 else 0
    x = mats / 2.0**squarings
    eye = np.eye(mats.shape[-1])
    b = _PADE7
    x2 = x @ x
    x4 = x2 @ x2
    x6 = x4 @ x2
    u = x @ (b[7] * x6 + b[5] * x4 + b[3] * x2 + b[1] * eye)
    v = b[6] * x6 + b[4] * x4 + b[2] * x2 + b[0] * eye
    r = np.linalg.solve(v - u, v + u)
    for _ in range(squarings):
        r = r @ r
    return np.asarray(r, dtype=float)


class _Augmented:
    """The model's continuous state space over theta (internal coordinates), scaled to unit RMS signals.

    States, inputs and outputs are divided by their RMS values (states: from a simulation at the start
    parameters), so that every block of the filter's covariance is of order one. The transition takes the rows of
    :meth:`inputs`: ``w[k]``, and ``w[k + 1]`` too for a linear input.
    """

    def __init__(
        self,
        nm: NumericModel,
        space: ParameterSpace,
        record: _Record,
        position: Mapping[str, float] | None,
        intersample: str = "zoh",
    ) -> None:
        self.nm, self.space, self.position = nm, space, position
        self.intersample = intersample
        n = self.n = nm.n_dof
        self.n_theta = space.n
        self.dt = record.dt
        full = space.full(space.start)
        b_in, s_out = nm.io_matrices(full, position)
        self.b_in = b_in[:, [nm.input_names.index(c) for c in record.inputs]]
        rows = [nm.output_names.index(c) for c in record.outputs]
        self.s_out = s_out[rows]
        orders = np.array([DERIVATIVE_ORDER[nm.output_quantities[r]] for r in rows])
        self.rows = [np.flatnonzero(orders == k) for k in range(3)]
        self.m = len(rows)
        self.n_in = self.b_in.shape[1]
        self.s = 2 * n + self.n_in
        #: columns of the transition [Ad, B0(, B1)]: the state, the input at k (and at k + 1 for a linear input)
        self.s_t = self.s + (self.n_in if intersample == "foh" else 0)
        mats = nm.matrices(full, position, names=_MATRICES)
        self._base = np.stack([mats[k] for k in _MATRICES])
        deriv = nm.matrix_derivatives(full, position, names=_MATRICES)
        self._slope = np.stack([deriv[k][space.columns] for k in _MATRICES], axis=1)  # (n_theta, 5, n, n)
        self.affine = self._is_affine()
        self.hysteretic = bool(np.any(self._base[4]))
        self.w_scale = np.where(_rms(record.w) > 0, _rms(record.w), 1.0)
        y_rms = _rms(record.y)
        self.y_scale = np.where(y_rms > 0, y_rms, 1.0)
        self.x_scale = np.ones(2 * n)
        self.x_scale = self._state_scale(record)
        self._templates()

    def _is_affine(self) -> bool:
        """Whether M, C, K, G, H are affine in the unknowns (then one tensor product evaluates them)."""
        u0 = self.space.to_internal(self.space.start)
        lo, hi = self.space.internal_bounds()
        probe = np.clip(u0 + 0.3 * np.where(np.arange(self.n_theta) % 2 == 0, 1.0, -1.0), lo, hi)
        exact = self._general(probe[None, :])[0]
        linear = self._base + np.tensordot(self.space.from_internal(probe) - self.space.start, self._slope, axes=1)
        return bool(np.allclose(exact, linear, rtol=1e-12, atol=1e-12 * float(np.max(np.abs(self._base)))))

    def _general(self, theta: Array) -> Array:
        mats = self.nm.matrices(self.space.full(self.space.from_internal(theta)), self.position, names=_MATRICES)
        return np.stack([mats[k] for k in _MATRICES], axis=1)

    def matrices(self, theta: Array) -> Array:
        """M, C, K, G, H at theta rows: (B, 5, n, n)."""
        if self.affine:
            step = self.space.from_internal(theta) - self.space.start
            flat = step @ self._slope.reshape(self.n_theta, -1)
            return np.asarray(self._base + flat.reshape(-1, *self._base.shape), dtype=float)
        return self._general(theta)

    def _templates(self) -> None:
        """Constant parts of the scaled ``Z = [[A, B], [0, 0]] dt`` and ``[C, D]`` for :meth:`discrete`."""
        n, s = self.n, self.s
        qs, vs = self.x_scale[:n], self.x_scale[n:]
        self._z_template = np.zeros((s, s))
        self._z_template[:n, n: 2 * n] = np.diag(vs / qs) * self.dt
        # columns [q, q', w] of the row block M^-1 [-K, -C, B] in the scaled variables, rows divided by vs
        self._block_scale = np.concatenate([qs, vs, self.w_scale])[None, :] / vs[:, None]
        self._y_template = np.zeros((self.m, s))
        r0, r1, r2 = self.rows
        self._y_template[r0, :n] = self.s_out[r0] * (qs[None, :] / self.y_scale[r0, None])
        self._y_template[r1, n: 2 * n] = self.s_out[r1] * (vs[None, :] / self.y_scale[r1, None])
        self._acc = self.s_out[r2] * (vs[None, :] / self.y_scale[r2, None])

    def inputs(self, w: Array) -> Array:
        """The transition's input rows (N, s_t - 2n) from the scaled inputs (N, n_in): ``w[k]``, and for a linear
        input ``[w[k], w[k + 1]]`` (the last sample's next input repeats it; no step is taken from there)."""
        if self.intersample != "foh":
            return w
        return np.hstack([w, np.vstack([w[1:], w[-1:]])])

    def _hold(self, z: Array) -> Array:
        """``[Ad, B0(, B1)]`` (B, 2n, s_t) from the scaled ``Z = [[A, B], [0, 0]] dt`` (B, s, s)."""
        n2, s = 2 * self.n, self.s
        if self.intersample != "foh":
            return expm_batch(z)[:, :n2]
        # the linear input: expm([[A dt, B dt, 0], [0, 0, I], [0, 0, 0]]) = [Ad, G1, G2] in its first block row,
        # B0 = G1 - G2, B1 = G2 (hold_matrices)
        big = np.zeros((z.shape[0], self.s_t, self.s_t))
        big[:, :s, :s] = z
        big[:, n2:s, s:] = np.eye(self.n_in)
        e = expm_batch(big)[:, :n2]
        e[:, :, n2:s] -= e[:, :, s:]
        return e

    def discrete(self, theta: Array) -> tuple[Array, Array]:
        """``[Ad, B0(, B1)]`` (B, 2n, s_t) and ``[C, D(, 0)]`` (B, m, s_t), scaled, at theta rows (B, n_theta).

        The same matrices as :meth:`linearize` gives (without derivatives), with the fewest array operations:
        one batched solve for ``M^-1 [-K, -C, B]`` and one batched matrix exponential.
        """
        n, s = self.n, self.s
        mats = self.matrices(theta)
        batch = mats.shape[0]
        damp = mats[:, 1] + mats[:, 3]
        if self.hysteretic:
            damp = damp + _equivalent_viscous(mats[:, 0], mats[:, 2], mats[:, 4])
        rhs = np.concatenate([-mats[:, 2], -damp, np.broadcast_to(self.b_in, (batch, n, self.n_in))], axis=2)
        block = np.linalg.solve(mats[:, 0], rhs) * self._block_scale
        z = np.broadcast_to(self._z_template, (batch, s, s)).copy()
        z[:, n: 2 * n] = block * self.dt
        out = np.zeros((batch, self.m, self.s_t))
        out[:, :, :s] = self._y_template
        if self._acc.size:
            out[:, self.rows[2], :s] = self._acc @ block
        return self._hold(z), out

    # -- continuous matrices ------------------------------------------------------------------------------------
    def _physical(self, theta: Array) -> tuple[Array, Array, Array, Array, Array]:
        """Minv, A21 = -Minv K, A22 = -Minv (C + G + C_eq), Minv B and M, C, K, G, H, batched over theta rows."""
        mats = self.matrices(theta)
        damp = mats[:, 1] + mats[:, 3]
        if self.hysteretic:
            damp = damp + _equivalent_viscous(mats[:, 0], mats[:, 2], mats[:, 4])
        minv = np.asarray(np.linalg.inv(mats[:, 0]), dtype=float)
        return minv, -minv @ mats[:, 2], -minv @ damp, minv @ self.b_in, mats

    def continuous(self, theta: Array) -> tuple[Array, Array, Array, Array]:
        """Scaled A (B, 2n, 2n), B (B, 2n, n_in), C (B, m, 2n), D (B, m, n_in) at theta rows (B, n_theta)."""
        _, a21, a22, minv_b, _ = self._physical(theta)
        return self._assemble(a21, a22, minv_b)

    def _assemble(self, a21: Array, a22: Array, minv_b: Array, derivative: bool = False) -> tuple[
            Array, Array, Array, Array]:
        """Scaled state-space matrices from the second-order blocks (or their derivatives)."""
        batch, n = a21.shape[0], self.n
        xs, ws, ys = self.x_scale, self.w_scale, self.y_scale
        qs, vs = xs[:n], xs[n:]
        a = np.zeros((batch, 2 * n, 2 * n))
        if not derivative:
            a[:, :n, n:] = np.diag(vs / qs)
        a[:, n:, :n] = a21 * (qs[None, :] / vs[:, None])
        a[:, n:, n:] = a22 * (vs[None, :] / vs[:, None])
        b = np.zeros((batch, 2 * n, self.n_in))
        b[:, n:] = minv_b * (ws[None, :] / vs[:, None])
        c = np.zeros((batch, self.m, 2 * n))
        d = np.zeros((batch, self.m, self.n_in))
        r0, r1, r2 = self.rows
        if not derivative:
            c[:, r0, :n] = self.s_out[r0] * (qs[None, :] / ys[r0, None])
            c[:, r1, n:] = self.s_out[r1] * (vs[None, :] / ys[r1, None])
        if r2.size:
            # accelerations S q'' = S [A21 A22] x + S Minv B w, in the scaled states: rows of the scaled A over vs
            acc = self.s_out[r2] * (vs[None, :] / ys[r2, None])
            c[:, r2] = acc @ a[:, n:, :]
            d[:, r2] = acc @ b[:, n:, :]
        return a, b, c, d

    def _state_scale(self, record: _Record) -> Array:
        """RMS of each state in a simulation at the start parameters (floored), for unit-scale states."""
        a, b, _, _ = self.continuous(self.space.to_internal(self.space.start)[None, :])
        hold = self.transition(a, b)[0]
        ad, bd = hold[:, : 2 * self.n], hold[:, 2 * self.n:]
        forcing = self.inputs(record.w / self.w_scale) @ bd.T
        x = np.zeros(2 * self.n)
        acc = np.zeros(2 * self.n)
        for f in forcing:
            x = ad @ x + f
            acc += x**2
        rms = np.sqrt(acc / forcing.shape[0])
        floor = np.concatenate([np.full(self.n, rms[: self.n].max()), np.full(self.n, rms[self.n:].max())]) * 1e-3
        scale = np.maximum(rms, floor)
        return np.where(scale > 0, scale, 1.0)

    def zoh(self, a: Array, b: Array) -> Array:
        """Exact zero-order-hold ``[Ad, Bd]`` (B, 2n, 2n + n_in) of scaled continuous matrices (B, ...)."""
        z = np.zeros((a.shape[0], self.s, self.s))
        z[:, : 2 * self.n, : 2 * self.n] = a * self.dt
        z[:, : 2 * self.n, 2 * self.n:] = b * self.dt
        return expm_batch(z)[:, : 2 * self.n]

    def transition(self, a: Array, b: Array) -> Array:
        """Exact ``[Ad, B0(, B1)]`` (B, 2n, s_t) of scaled continuous matrices for the record's input."""
        z = np.zeros((a.shape[0], self.s, self.s))
        z[:, : 2 * self.n, : 2 * self.n] = a * self.dt
        z[:, : 2 * self.n, 2 * self.n:] = b * self.dt
        return self._hold(z)

    # -- exact linearization (EKF) -------------------------------------------------------------------------------
    def linearize(self, theta: Array) -> tuple[Array, Array]:
        """``W = [[Ad, B0(, B1)], [C, D(, 0)]]`` (2n + m, s_t) at theta and ``dW/dtheta`` (n_theta, 2n + m, s_t).

        ``d expm(Z)`` in direction ``E_j = dZ/dtheta_j`` is the upper right block of ``expm([[Z, E_j], [0, Z]])``
        (Van Loan 1978), all directions in one batch; for a linear input ``Z`` carries the identity block of
        :meth:`_hold`, which does not depend on theta.
        """
        n, nt, s = self.n, self.n_theta, self.s_t
        minv, a21, a22, minv_b, _ = self._physical(theta[None, :])
        a, b, c, d = self._assemble(a21, a22, minv_b)
        if self.affine:
            slope = self._slope
        else:
            full = self.space.full(self.space.from_internal(theta))
            deriv = self.nm.matrix_derivatives(full, self.position, names=_MATRICES)
            slope = np.stack([deriv[k][self.space.columns] for k in _MATRICES], axis=1)
        slope = slope * self.space.value_jacobian(theta)[:, None, None, None]
        dm, dk = slope[:, 0], slope[:, 2]
        dc = slope[:, 1] + slope[:, 3]
        if self.hysteretic:
            dc = dc + self._hysteretic_derivative(theta)
        da21 = -minv @ (dk + dm @ a21)
        da22 = -minv @ (dc + dm @ a22)
        dminv_b = -minv @ dm @ minv_b
        da, db, dcc, dd = self._assemble(da21, da22, dminv_b, derivative=True)
        big = np.zeros((nt, 2 * s, 2 * s))
        big[:, : 2 * n, : 2 * n] = a[0] * self.dt
        big[:, : 2 * n, 2 * n: self.s] = b[0] * self.dt
        big[:, s: s + 2 * n, s: s + 2 * n] = a[0] * self.dt
        big[:, s: s + 2 * n, s + 2 * n: s + self.s] = b[0] * self.dt
        big[:, : 2 * n, s: s + 2 * n] = da * self.dt
        big[:, : 2 * n, s + 2 * n: s + self.s] = db * self.dt
        if s > self.s:  # the linear input's identity block, in both diagonal copies
            big[:, 2 * n: self.s, self.s: s] = np.eye(self.n_in)
            big[:, s + 2 * n: s + self.s, s + self.s:] = np.eye(self.n_in)
        e = expm_batch(big)
        w0 = np.zeros((2 * n + self.m, s))
        w0[: 2 * n] = e[0, : 2 * n, :s]
        w0[2 * n:, : 2 * n] = c[0]
        w0[2 * n:, 2 * n: self.s] = d[0]
        dw = np.zeros((nt, 2 * n + self.m, s))
        dw[:, : 2 * n] = e[:, : 2 * n, s:]
        dw[:, 2 * n:, : 2 * n] = dcc
        dw[:, 2 * n:, 2 * n: self.s] = dd
        if s > self.s:  # [G1, G2] -> [B0, B1] = [G1 - G2, G2]
            w0[: 2 * n, 2 * n: self.s] -= w0[: 2 * n, self.s:]
            dw[:, : 2 * n, 2 * n: self.s] -= dw[:, : 2 * n, self.s:]
        return w0, dw

    def _hysteretic_derivative(self, theta: Array) -> Array:
        """d C_eq / d theta by central differences (the equivalent viscous matrix has no simple derivative)."""
        h = 1e-6
        steps = np.vstack([theta + h * np.eye(self.n_theta), theta - h * np.eye(self.n_theta)])
        mats = self.matrices(steps)
        ceq = _equivalent_viscous(mats[:, 0], mats[:, 2], mats[:, 4])
        return np.asarray((ceq[: self.n_theta] - ceq[self.n_theta:]) / (2 * h), dtype=float)


# ---------------------------------------------------------------------------------------------------------------
# settings shared by both filters
# ---------------------------------------------------------------------------------------------------------------
def _per_unknown(value: float | Mapping[str, float], space: ParameterSpace, what: str) -> Array:
    if isinstance(value, Mapping):
        extra = sorted(set(value) - set(space.names))
        if extra:
            msg = f"{what} given for {extra}, which are not among the unknowns {list(space.names)}"
            raise DataError(msg)
        arr = np.array([float(value.get(n, 0.0)) for n in space.names])
    else:
        arr = np.full(space.n, float(value))
    if not np.all(np.isfinite(arr) & (arr >= 0)):
        msg = f"{what} must be finite and >= 0; got {value!r}"
        raise DataError(msg)
    return arr


def _per_output(value: float | Mapping[str, float] | None, outputs: Sequence[str], what: str) -> Array | None:
    if value is None:
        return None
    if isinstance(value, Mapping):
        missing = [o for o in outputs if o not in value]
        if missing:
            msg = f"{what} must give every output channel used; missing {missing}"
            raise DataError(msg)
        arr = np.array([float(value[o]) for o in outputs])
    else:
        arr = np.full(len(outputs), float(value))
    if not np.all(np.isfinite(arr) & (arr > 0)):
        msg = f"{what} must be finite and > 0 (fraction of each output's RMS); got {value!r}"
        raise DataError(msg)
    return arr


def _prior_std(space: ParameterSpace) -> Array:
    """Standard deviation in internal coordinates: each bound interval is +-2 std; 0.5 where unbounded."""
    lo, hi = space.internal_bounds()
    width = hi - lo
    return np.where(np.isfinite(width), width / 4.0, 0.5)


@dataclass
class _Pass:
    theta: Array  # final estimate (internal)
    cov: Array  # final full covariance ([theta, x] order)
    start_cov: Array  # theta block at the start
    trajectory: Array  # (N, n_theta) filtered theta
    std: Array  # (N, n_theta) filtered std
    nis: Array  # (N,)
    innovations: Array  # (N, m) scaled innovations
    predicted_var: Array  # (N, m) diagonal of the predicted output covariance (without R)
    relinearizations: int = 0


# ---------------------------------------------------------------------------------------------------------------
# the estimators
# ---------------------------------------------------------------------------------------------------------------
class _KalmanEstimator(Estimator):
    """Shared settings, passes and result assembly of the EKF and the UKF."""

    _kind: ClassVar[str] = ""
    #: The command line's intersample when none is given (a held input, as before FOH was added), and the
    #: intersample behaviours the filters refuse, with the reason.
    intersample_default: ClassVar[str] = "zoh"
    intersample_refused: ClassVar[Mapping[str, str]] = {"bl": BAND_LIMITED_REFUSAL}

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
        noise: float | Mapping[str, float] | None = None,
        process_noise: float = 0.0,
        random_walk: float | Mapping[str, float] = 0.0,
        passes: int | None = 6,
        tol: float = 1e-4,
        initial_state: str = "estimate",
        inflation: float = 4.0,
        intersample: str = "zoh",
        covariance: str = "auto",
        refine: bool = True,
    ) -> None:
        super().__init__(model, unknowns, bounds=bounds, start=start, values=values, rng=rng)
        self.inputs = inputs
        self.outputs = outputs
        self.position = position
        self.noise = noise
        self.process_noise = process_noise
        self.random_walk = random_walk
        self.passes = passes
        self.tol = tol
        self.initial_state = initial_state
        self.inflation = inflation
        self.intersample = intersample
        self.covariance = covariance
        self.refine = refine

    def _check_settings(self) -> None:
        if self.covariance not in ("auto", "gauss-newton", "sandwich"):
            msg = f"covariance must be 'auto', 'gauss-newton' or 'sandwich'; got {self.covariance!r}"
            raise DataError(msg)
        if check_intersample(self.intersample) == "bl":
            msg = f"intersample 'bl' does not apply to the {self._kind} Kalman filter: {BAND_LIMITED_REFUSAL}"
            raise DataError(msg)
        if self.passes is not None and (isinstance(self.passes, bool) or not isinstance(self.passes, int)
                                        or self.passes < 1):
            msg = f"passes must be an integer >= 1; got {self.passes!r}"
            raise DataError(msg)
        for what, value in (("process_noise", self.process_noise), ("tol", self.tol)):
            if not (np.isfinite(value) and value >= 0):
                msg = f"{what} must be finite and >= 0; got {value!r}"
                raise DataError(msg)
        if not (np.isfinite(self.inflation) and self.inflation >= 1):
            msg = f"inflation must be finite and >= 1; got {self.inflation!r}"
            raise DataError(msg)
        if not isinstance(self.refine, (bool, np.bool_)):
            msg = f"refine must be true or false; got {self.refine!r}"
            raise DataError(msg)
        if self.initial_state not in ("estimate", "rest"):
            msg = f"initial_state must be 'estimate' or 'rest'; got {self.initial_state!r}"
            raise DataError(msg)

    def _fit(
        self, model: NumericModel, space: ParameterSpace, data: Any, rng: np.random.Generator
    ) -> ParameterEstimate:
        self._check_settings()
        record = _select(model, data, self.inputs, self.outputs)
        given = _per_output(self.noise, record.outputs, "noise")
        walk = _per_unknown(self.random_walk, space, "random_walk")
        aug = _Augmented(model, space, record, self.position, self.intersample)
        w = aug.inputs(record.w / aug.w_scale)  # the transition's input rows
        y = record.y / aug.y_scale
        n_x = 2 * aug.n
        nt = space.n
        prior_var = _prior_std(space) ** 2
        q_theta = walk**2 * record.dt
        # process noise: white force noise of `process_noise` x the input RMS on every used input (scaled units)
        a_start, b_start, _, _ = aug.continuous(space.to_internal(space.start)[None, :])
        bd = aug.zoh(a_start, b_start)[0, :, n_x:]
        # (plus 1e-12 of the states' variance per step, which keeps P positive definite and is far below any noise)
        q_x = self.process_noise**2 * (bd @ bd.T) + 1e-12 * np.eye(n_x)
        q = np.zeros((nt + n_x, nt + n_x))
        q[:nt, :nt] = np.diag(q_theta)
        q[nt:, nt:] = q_x
        r_std = given if given is not None else np.full(aug.m, _FIRST_NOISE)
        theta = space.to_internal(space.start)
        x0 = np.zeros(n_x)
        p_x = np.eye(n_x) if self.initial_state == "estimate" else _REST_VAR * np.eye(n_x)
        p_first = p_x
        constant = not (self.process_noise > 0 or np.any(walk > 0))
        n_passes = self._passes(constant)
        passes: list[_Pass] = []
        history: list[dict[str, float]] = []
        change = np.full(nt, np.inf)
        converged = False
        cov_u = np.diag(prior_var)
        p_theta = cov_u
        info = np.zeros((nt, nt))
        newton = np.full(nt, np.nan)
        errors: tuple[Array, Array, Array] | None = None
        for k in range(n_passes):
            p0 = np.zeros((nt + n_x, nt + n_x))
            p0[:nt, :nt] = p_theta
            p0[nt:, nt:] = p_x
            result = self._run(aug, np.concatenate([theta, x0]), p0, q, np.diag(r_std**2), w, y)
            passes.append(result)
            history.append(space.mapping(space.from_internal(result.theta)))
            if not (np.all(np.isfinite(result.theta)) and np.all(np.isfinite(result.cov))):
                break
            change = np.abs(result.theta - theta)
            theta = result.theta
            if given is None:
                half = y.shape[0] // 2
                e2 = np.mean(result.innovations[half:] ** 2, axis=0)
                r_std = np.sqrt(np.maximum(e2 - np.mean(result.predicted_var[half:], axis=0), 0.01 * e2))
            if self.initial_state == "estimate":
                x0, p_x = _initial_state(aug, theta, w, y, r_std)
            # the initial state is a nuisance parameter with the prior of the first pass
            cov_u, info, newton, errors = self._uncertainty(aug, result, theta, x0, p_first, w, y, r_std, prior_var,
                                                            q_theta, constant)
            sigma = np.sqrt(np.maximum(np.diagonal(cov_u), 0.0))
            determined = _identifiability(info, prior_var, space.names)[0]
            # converged: every determined parameter moved by less than tol or a quarter of its standard error
            if k > 0 and bool(np.all((change <= np.maximum(self.tol, 0.25 * sigma)) | ~determined)):
                converged = True
                break
            # the next pass starts at this estimate with the covariance inflated, capped at the bounds prior
            p_theta = self.inflation * cov_u if constant else np.diag(prior_var)
            cap = np.sqrt(np.minimum(1.0, prior_var / np.maximum(np.diagonal(p_theta), 1e-300)))
            p_theta = p_theta * np.outer(cap, cap)
        refinement: dict[str, Any] | None = None
        if self.refine and errors is not None and np.all(np.isfinite(passes[-1].theta)):
            theta, cov_u, info, newton, errors, refinement = self._refine(
                aug, passes[-1], theta, x0, p_first, w, y, r_std, prior_var, q_theta)
        estimate = self._result(space, record, aug, passes, history, change, converged, given, r_std, q_theta,
                                prior_var, cov_u, info, newton, constant, theta=theta, refinement=refinement)
        if errors is None or not np.all(np.isfinite(estimate.values)):
            return estimate
        # the output errors at the estimate, tested as one-step's (MATLAB resid): a filter whose model of the
        # inputs between samples (or of the structure) is wrong fails here instead of returning a confident number
        jac, residual, regular = errors
        n_samples = y.shape[0]
        output_errors = residual.reshape(n_samples, aug.m) * r_std[None, :]
        tested = with_residual_tests(estimate, [output_errors], [record.w], record.outputs, record.inputs)
        analysis = tested.diagnostics.get("residual_analysis", {})
        coloured = "white" in analysis and not all(analysis["white"].values())
        if not (self.covariance == "sandwich" or (self.covariance == "auto" and coloured)):
            return _with_intersample_sensitivity(tested, aug, record, theta, jac, residual, regular, r_std)
        # the Newey-West sandwich around the regularized output-error information (its bread)
        lag = newey_west_bandwidth([n_samples], analysis)
        bread = np.linalg.inv(regular)
        meat = newey_west_meat(jacobian=jac, residuals=residual, block=aug.m, records=[n_samples], max_lag=lag)
        sandwich = _symmetric(bread @ meat @ bread)[: space.n, : space.n]
        estimate = self._result(space, record, aug, passes, history, change, converged, given, r_std, q_theta,
                                prior_var, sandwich, info, newton, constant, theta=theta, refinement=refinement)
        diagnostics = dict(estimate.diagnostics)
        diagnostics["covariance"] = {"kind": "sandwich (Newey-West)", "lags": lag,
                                     "gauss_newton_std": dict(zip(space.names, tested.std.tolist(), strict=True))}
        tested = with_residual_tests(replace(estimate, diagnostics=diagnostics), [output_errors], [record.w],
                                     record.outputs, record.inputs)
        return _with_intersample_sensitivity(tested, aug, record, theta, jac, residual, regular, r_std)

    def _passes(self, constant: bool) -> int:
        """The most filter passes: ``passes``, or where it is None (the UKF's default) :data:`_REFINED_PASSES` when
        the output-error refinement finishes the job (constant parameters, ``refine``) and :data:`_PASSES` else."""
        if self.passes is not None:
            return int(self.passes)
        return _REFINED_PASSES if constant and self.refine else _PASSES

    @staticmethod
    def _uncertainty(
        aug: _Augmented,
        result: _Pass,
        theta: Array,
        x0: Array,
        p_x: Array,
        w: Array,
        y: Array,
        r_std: Array,
        prior_var: Array,
        q_theta: Array,
        constant: bool,
    ) -> tuple[Array, Array, Array, tuple[Array, Array, Array] | None]:
        """Covariance of theta (internal), the information the data carry about it, a Gauss-Newton step, and (for
        constant parameters) the output errors' ``J``, ``r`` and the regularized information (for the sandwich).

        Constant parameters and a trusted model (no process noise): the output-error Fisher information at the
        estimate, with the initial state as a nuisance parameter (its prior as in the filter). This is what the
        data say; the filter's own covariance can be far too small where its state estimate has absorbed
        measurement noise (a weakly excited parameter then looks determined). The Gauss-Newton step of the
        output-error fit from the estimate says how far the filter's fixed point lies from the output-error
        optimum (nan when tracking). Tracking (random walk or process noise): the filter's covariance, and as
        data information ``inv(P_end) - inv(P_start + N Q_theta)``.
        """
        nt = aug.n_theta
        if not constant:
            prior_end = result.start_cov + np.diag(q_theta) * w.shape[0]
            info = _symmetric(np.linalg.inv(result.cov[:nt, :nt]) - np.linalg.inv(_symmetric(prior_end)))
            return result.cov[:nt, :nt], info, np.full(nt, np.nan), None
        full, gradient, jac, residual = _output_error_information(aug, theta, x0, w, y, r_std)
        a, b, d = full[:nt, :nt], full[:nt, nt:], full[nt:, nt:] + np.linalg.inv(p_x)
        info = _symmetric(a - b @ np.linalg.solve(d, b.T))
        regular = full.copy()
        regular[:nt, :nt] += np.diag(1.0 / prior_var)
        regular[nt:, nt:] += np.linalg.inv(p_x)
        newton = np.asarray(np.linalg.solve(_symmetric(regular), gradient)[:nt], dtype=float)
        return (_symmetric(np.linalg.inv(info + np.diag(1.0 / prior_var))), info, newton,
                (jac, residual, _symmetric(regular)))

    def _refine(
        self,
        aug: _Augmented,
        result: _Pass,
        theta: Array,
        x0: Array,
        p_x: Array,
        w: Array,
        y: Array,
        r_std: Array,
        prior_var: Array,
        q_theta: Array,
    ) -> tuple[Array, Array, Array, Array, tuple[Array, Array, Array] | None, dict[str, Any]]:
        """Gauss-Newton steps of the output-error fit from the filter's estimate (constant parameters).

        The covariance is the output-error information at the estimate (:meth:`_uncertainty`), so the estimate it
        belongs to is the output-error optimum. The filter's passes reach it slowly along weakly determined
        directions: with F1 only and 5 % noise the combination (m2, k12, k22, c22) of the two-mass rig moved by
        ~1 % per pass for 12 passes, 7 standard errors from the truth after 6 (issue 21). From the filter's
        estimate the Newton steps that :meth:`_uncertainty` already computes (the initial state a nuisance, the
        bounds prior as damping) reach it in a few steps; a step that does not lower the output-error cost is
        halved. Converged: every determined parameter's next step is below ``tol`` or a tenth of its standard
        error.
        """
        space = aug.space
        nt = space.n
        lo, hi = space.internal_bounds()
        p_inv = np.linalg.inv(p_x)

        def evaluate(at: Array, x_at: Array) -> tuple[Any, float, Array]:
            found = self._uncertainty(aug, result, at, x_at, p_x, w, y, r_std, prior_var, q_theta, True)
            assert found[3] is not None  # constant parameters: the output errors are there
            jac, residual, regular = found[3]
            # the joint step of [theta, x0]: the initial state's prior pulls it to rest, the bounds prior is damping
            step = np.linalg.solve(regular, jac.T @ residual - np.concatenate([np.zeros(nt), p_inv @ x_at]))
            return found, float(residual @ residual + x_at @ p_inv @ x_at), step

        found, cost, step = evaluate(theta, x0)
        cov_u, info, newton, errors = found
        start_cost, start_theta = cost, theta.copy()
        steps, converged, halvings = 0, False, 0
        for _ in range(_REFINE_STEPS + 1):
            sigma = np.sqrt(np.maximum(np.diagonal(cov_u), 0.0))
            determined = _identifiability(info, prior_var, space.names)[0]
            if bool(np.all((np.abs(step[:nt]) <= np.maximum(self.tol, 0.1 * sigma)) | ~determined)):
                converged = True
                break
            if steps == _REFINE_STEPS:
                break
            scale, accepted = 1.0, False
            while scale >= 1.0 / 16.0:
                trial = np.clip(theta + scale * step[:nt], lo, hi)
                x_trial = x0 + scale * step[nt:]
                trial_found, trial_cost, trial_step = evaluate(trial, x_trial)
                if trial_cost < cost:
                    theta, x0, cost, step, accepted = trial, x_trial, trial_cost, trial_step, True
                    cov_u, info, newton, errors = trial_found
                    break
                scale /= 2.0
                halvings += 1
            if not accepted:
                break
            steps += 1
        record = {"steps": steps, "halvings": halvings, "converged": converged,
                  "cost_before": start_cost, "cost_after": cost,
                  "moved": space.mapping(space.from_internal(theta) - space.from_internal(start_theta)),
                  "filter_estimate": space.mapping(space.from_internal(start_theta))}
        return theta, cov_u, info, step[:nt], errors, record  # the step left, with the initial state's prior

    @abstractmethod
    def _run(self, aug: _Augmented, z0: Array, p0: Array, q: Array, r: Array, w: Array, y: Array) -> _Pass:
        """One forward pass of the filter over the record."""

    def _result(
        self,
        space: ParameterSpace,
        record: _Record,
        aug: _Augmented,
        passes: list[_Pass],
        history: list[dict[str, float]],
        change: Array,
        converged: bool,
        given: Array | None,
        r_std: Array,
        q_theta: Array,
        prior_var: Array,
        cov_u: Array,
        info: Array,
        newton: Array,
        constant: bool,
        *,
        theta: Array | None = None,
        refinement: Mapping[str, Any] | None = None,
    ) -> ParameterEstimate:
        nt = space.n
        last = passes[-1]
        n_samples = record.y.shape[0]
        finite = bool(np.all(np.isfinite(last.theta)) and np.all(np.isfinite(last.cov)))
        if theta is None:
            theta = last.theta
        theta = theta if finite else np.full(nt, np.nan)
        values = space.from_internal(theta)
        if not finite:
            cov_u = np.full((nt, nt), np.nan)
        jac = space.value_jacobian(theta)
        cov = cov_u * np.outer(jac, jac)
        filter_std = np.sqrt(np.maximum(np.diagonal(last.cov)[:nt], 0.0)) * jac
        identifiable = np.zeros(nt, dtype=bool)
        combos: tuple[str, ...] = ()
        ratio = np.zeros(nt)
        if finite:
            identifiable, ratio, combos = _identifiability(info, prior_var, space.names)
        std = np.sqrt(np.maximum(np.diag(cov), 0.0))
        std = np.where(identifiable, std, np.nan)
        z = float(stats.norm.ppf(0.975))
        ci95 = np.column_stack([values - z * std, values + z * std])
        with np.errstate(invalid="ignore", divide="ignore"):
            corr = cov / np.outer(np.sqrt(np.diag(cov)), np.sqrt(np.diag(cov)))
        corr = np.where(np.outer(identifiable, identifiable), corr, np.nan)
        np.fill_diagonal(corr, 1.0)
        # innovation consistency over the last pass, after the first tenth (the states' start-up)
        skip = n_samples // 10
        nis = last.nis[skip:]
        m = aug.m
        n_used = nis.size
        nis_mean = float(np.mean(nis)) if n_used else float("nan")
        band = [float(stats.chi2.ppf(0.025, n_used * m) / n_used), float(stats.chi2.ppf(0.975, n_used * m) / n_used)]
        per_channel = np.mean(last.innovations[skip:] ** 2 / (last.predicted_var[skip:] + r_std**2), axis=0)
        largest = float(np.max(change)) if change.size else 0.0
        single = len(passes) == 1 and self._passes(constant) == 1 and refinement is None
        refined = refinement is not None and bool(refinement["converged"])
        success = finite and (converged or single or refined)
        if not finite:
            message = f"the filter diverged in pass {len(passes)} (non-finite state or covariance)"
        elif single:
            message = "one forward pass (tracking); no pass-to-pass convergence check"
        elif converged:
            message = (f"converged after {len(passes)} passes: the last changed the estimate by at most {largest:.2g} "
                       f"(internal coordinates), below tol = {self.tol:g} or a quarter of its standard error")
        else:
            message = (f"{'the passes did not settle' if refined else 'not converged'} after {len(passes)} passes: "
                       f"the last changed the estimate by {largest:.2g} (internal coordinates), more than "
                       f"tol = {self.tol:g} and a quarter of its standard error")
        if finite and refinement is not None:
            steps = int(refinement["steps"])
            if refined and steps == 0:
                message += "; the output-error optimum lies within a tenth of a standard error (no Gauss-Newton step)"
            else:
                message += (f"; {'then ' if refined else ''}{steps} output-error Gauss-Newton step"
                            f"{'' if steps == 1 else 's'}{' converged' if refined else ' did not converge'}")
        lo, hi = space.internal_bounds()
        at_bound = [n for n, t, a, b in zip(space.names, theta, lo, hi, strict=True)
                    if finite and (np.isclose(t, a) or np.isclose(t, b))]
        if at_bound:
            message += f"; estimate at a bound for {at_bound}"
        if finite and not identifiable.all():
            undetermined = [n for n, f in zip(space.names, identifiable, strict=True) if not f]
            message += f"; the data do not determine {undetermined}"
        with np.errstate(invalid="ignore", divide="ignore"):
            offset = np.where(identifiable, newton / np.sqrt(np.diagonal(cov_u)), np.nan)
        far = [n for n, v in zip(space.names, offset, strict=True) if np.isfinite(v) and abs(v) > 1]
        if far:
            message += (f"; the output-error optimum lies up to {np.nanmax(np.abs(offset)):.1f} standard errors from "
                        f"the filter's estimate for {far} (a filter bias in weakly determined directions)")
        rows = np.concatenate([p.trajectory for p in passes])
        stds = np.concatenate([p.std for p in passes])
        times = np.tile(np.arange(n_samples) * record.dt, len(passes))
        pass_index = np.repeat(np.arange(1, len(passes) + 1), n_samples)
        step = max(1, int(np.ceil(rows.shape[0] / _MAX_ROWS)))
        keep = np.arange(0, rows.shape[0], step)
        keep[-1] = rows.shape[0] - 1  # the final estimate is always shown
        traj_values = space.from_internal(rows[keep])
        traj_std = stds[keep] * space.value_jacobian(rows[keep])
        diagnostics: dict[str, Any] = {
            "filter": self._kind,
            "intersample": self.intersample,
            "passes": len(passes),
            "pass_estimates": history,
            "converged": bool(converged),
            "last_change": {n: float(v) for n, v in zip(space.names, change, strict=True)},
            "samples": int(n_samples),
            "inputs": list(record.inputs),
            "outputs": list(record.outputs),
            "noise": {o: float(s) for o, s in zip(record.outputs, r_std, strict=True)},
            "noise_source": "given" if given is not None else "estimated from the innovations",
            "noise_std": {o: float(s * ys) for o, s, ys in zip(record.outputs, r_std, aug.y_scale, strict=True)},
            "process_noise": float(self.process_noise),
            "random_walk": {n: float(v) for n, v in zip(space.names, np.sqrt(q_theta / record.dt), strict=True)},
            "start": space.mapping(space.start),
            "bounds": {n: [float(a), float(b)] for n, a, b in zip(space.names, space.lower, space.upper, strict=True)},
            "at_bound": at_bound,
            "information_ratio": [float(v) for v in ratio],
            "uncertainty_source": ("output-error information at the estimate" if constant
                                   else "filter covariance (tracking)"),
            "filter_std": {n: float(v) for n, v in zip(space.names, filter_std, strict=True)},
            "output_error_step": {n: float(v) for n, v in zip(space.names, offset, strict=True)},
            "nis": {"mean": nis_mean, "dof": m, "band95": band, "consistent": bool(band[0] <= nis_mean <= band[1]),
                    "per_channel": {o: float(v) for o, v in zip(record.outputs, per_channel, strict=True)}},
            "relinearizations": int(sum(p.relinearizations for p in passes)),
            "trajectory": {"names": list(space.names), "time": times[keep], "pass": pass_index[keep],
                           "values": traj_values, "std": traj_std, "decimation": step},
            "iterations": len(passes),
        }
        if refinement is not None:
            diagnostics["output_error_refinement"] = dict(refinement)
        cost = float(np.sum(last.nis)) if finite else float("nan")
        return ParameterEstimate(self.method, space.names, values, std, ci95, corr, identifiable, combos, cost,
                                 bool(success), message, diagnostics)


def _with_intersample_sensitivity(
    estimate: ParameterEstimate, aug: _Augmented, record: _Record, theta: Array, jac: Array, residual: Array,
    regular: Array, r_std: Array,
) -> ParameterEstimate:
    """The estimate with its intersample sensitivity (:mod:`cappe.estimate._intersample`) in the diagnostics.

    The forced responses of the continuous model at theta (scaled units, as the output errors) to the recorded
    inputs under each behaviour, and the Gauss-Newton shift of the output-error estimate their differences cause.
    Each refit's output errors get the residual tests: a behaviour they reject is one the data rule out
    (``diagnostics["intersample_ruled_out"]``). Where a parameter would move by more than a standard error under a
    behaviour the data do not rule out, a warning says so and
    ``diagnostics["intersample_dependent"]`` names it. The fit stays a success where its tests pass: the estimate
    and its interval are right under the stated behaviour, which the data cannot refute; the warning says that the
    answer is conditional on it.
    """
    from cappe.identify._residual_analysis import residual_analysis

    def respond(at: Array, holds: Sequence[str]) -> dict[str, Array]:
        a, b, c, d = aug.continuous(at[None, :])
        return forced_responses(a[0], b[0], c[0], d[0], record.w / aug.w_scale, record.dt, holds)

    sensitivity, refit_errors = intersample_sensitivity(respond, aug.intersample, jac, residual, regular, r_std,
                                                        theta, aug.space, estimate.std)
    # the residual tests of each refit: a behaviour whose refit fails them is one the data rule out
    ruled_out = {hold: not residual_analysis(residuals=[errors], inputs=[record.w], output_names=record.outputs,
                                             input_names=record.inputs).passed
                 for hold, errors in refit_errors.items()}
    diagnostics = dict(estimate.diagnostics)
    diagnostics["intersample_sensitivity"] = sensitivity
    diagnostics["intersample_ruled_out"] = ruled_out
    line, dependent = sensitivity_warning(sensitivity, rejected=diagnostics.get("fit_test") == "failed",
                                          ruled_out=ruled_out)
    diagnostics["intersample_dependent"] = dependent
    message = estimate.message
    if line is not None:
        diagnostics["warnings"] = [*diagnostics.get("warnings", []), line]
        message += (f"; {dependent} depend on the assumed intersample behaviour ({aug.intersample}) by more than "
                    f"a standard error")
    return replace(estimate, message=message, diagnostics=diagnostics)


def _initial_state(aug: _Augmented, theta: Array, w: Array, y: Array, r_std: Array) -> tuple[Array, Array]:
    """Initial state at fixed theta from the first samples (least squares with the unit prior) and its covariance.

    The states' uncertainty at the start matters: the EKF evaluates the sensitivity to theta along its state
    estimate, and a spurious free vibration fitted to the noise of the first samples reads as information about
    the parameters that shape it (masses and stiffnesses) where the data carry none.
    """
    n_x = 2 * aug.n
    a, b, c, d = aug.continuous(theta[None, :])
    hold = aug.transition(a, b)[0]
    ad, bd = hold[:, :n_x], hold[:, n_x:]
    count = min(y.shape[0], _X0_SAMPLES)
    forced = np.empty((count, aug.m))
    free = np.empty((count, aug.m, n_x))
    x = np.zeros(n_x)
    phi = np.eye(n_x)
    for k in range(count):
        forced[k] = c[0] @ x + d[0] @ w[k, : aug.n_in]
        free[k] = c[0] @ phi
        x = ad @ x + bd @ w[k]
        phi = ad @ phi
    design = (free / r_std[None, :, None]).reshape(count * aug.m, n_x)
    rhs = ((y[:count] - forced) / r_std).ravel()
    # posterior of the initial state with the unit prior (scaled states) of the first pass
    cov = _symmetric(np.linalg.inv(design.T @ design + np.eye(n_x)))
    x0 = cov @ (design.T @ rhs)
    # an initial state indistinguishable from rest is taken as rest: a free vibration fitted to noise would
    # otherwise read as information about the masses and stiffnesses that set its frequency
    if float(x0 @ np.linalg.solve(cov, x0)) < stats.chi2.ppf(0.99, n_x):
        x0 = np.zeros(n_x)
    return x0, cov


def _output_error_information(
    aug: _Augmented, theta: Array, x0: Array, w: Array, y: Array, r_std: Array
) -> tuple[Array, Array, Array, Array]:
    """Fisher information about ``[theta, x0]`` of the outputs simulated at theta from x0, ``J^T r``, and ``J``
    (N m, n_theta + 2n, time-major) and ``r`` (N m) themselves.

    Sensitivities by the exact discrete recursion ``S[k+1] = Ad S[k] + dAd/dtheta x[k] + dBd/dtheta w[k]``
    (``w`` the transition's input rows, :meth:`_Augmented.inputs`)
    (derivatives of the ZOH matrices from :meth:`_Augmented.linearize`) and ``dx[k]/dx0 = Ad^k``; ``r`` are the
    noise-weighted output errors ``(y - y_sim) / sigma``, so ``J^T r`` is the Gauss-Newton gradient.
    """
    n_x, nt, m = 2 * aug.n, aug.n_theta, aug.m
    w0, dw = aug.linearize(theta)
    ad, c = w0[:n_x, :n_x], w0[n_x:, :n_x]
    states = np.zeros((n_x, 1 + nt + n_x))  # [x | dx/dtheta | dx/dx0]
    states[:, 0] = x0
    states[:, 1 + nt:] = np.eye(n_x)
    jac = np.empty((w.shape[0], m, nt + n_x))
    simulated = np.empty((w.shape[0], m))
    xi = np.zeros(aug.s_t)
    for k in range(w.shape[0]):
        xi[:n_x] = states[:, 0]
        xi[n_x:] = w[k]
        g = (dw @ xi).T  # (n_x + m, nt): d[x_next; y] / dtheta at fixed state and input
        jac[k] = c @ states[:, 1:]
        jac[k, :, :nt] += g[n_x:]
        simulated[k] = w0[n_x:] @ xi
        rest = ad @ states[:, 1:]
        rest[:, :nt] += g[:n_x]
        states[:, 0] = w0[:n_x] @ xi
        states[:, 1:] = rest
    weighted = (jac / r_std[None, :, None]).reshape(-1, nt + n_x)
    residual = ((y - simulated) / r_std).ravel()
    return (np.asarray(weighted.T @ weighted, dtype=float), np.asarray(weighted.T @ residual, dtype=float),
            np.asarray(weighted, dtype=float), np.asarray(residual, dtype=float))


def _identifiability(
    info: Array, prior_var: Array, names: Sequence[str]
) -> tuple[NDArray[np.bool_], Array, tuple[str, ...]]:
    """Flags, information ratios and undetermined combinations from the data information (internal coordinates).

    The information is whitened by the bounds prior, so each eigenvalue says how many times more the data know
    along its direction than the bounds do; below ``_INFO_RATIO`` the direction is undetermined.
    """
    scale = np.sqrt(prior_var)
    ratio, vec = np.linalg.eigh(_symmetric(info * np.outer(scale, scale)))
    null = vec[:, ratio < _INFO_RATIO].T
    weight = np.sqrt(np.sum(null**2, axis=0))
    return weight <= _NULL_WEIGHT, ratio, tuple(null_direction_text(names, v) for v in null)


def _symmetric(mat: NDArray[np.floating[Any]]) -> Array:
    return np.asarray(0.5 * (mat + mat.T), dtype=float)


class ExtendedKalmanEstimator(_KalmanEstimator):
    """Extended Kalman filter with the unknown parameters as augmented states (thesis 3.6.4).

    ``ExtendedKalmanEstimator(model, unknowns, ...).fit(data)`` with ``data`` a :class:`~cappe.systems.TimeData` whose
    channels are named like the model's inputs (forces) and outputs (displacements, velocities, accelerations).
    Model inputs without a channel are taken as unexcited.

    Parameters
    ----------
    model, unknowns, bounds, start, values, rng
        See :class:`~cappe.estimate.Estimator`. The filter is deterministic; ``rng`` is unused.
    inputs, outputs : sequence of str, optional
        Channels used (default: every data channel named like a model input / output).
    position : mapping, optional
        Axis position of the model.
    noise : float or mapping output -> float, optional
        Standard deviation of the measurement noise as a fraction of each output channel's RMS (0.01 = 1 %).
        Default: 5 % in the first pass, then estimated from the innovations of the previous pass.
    process_noise : float
        Standard deviation of white force noise on every used input, as a fraction of that input's RMS (unmeasured
        excitation, model error). Default 0: the model is trusted.
    random_walk : float or mapping name -> float
        Standard deviation of the parameters' random walk in internal coordinates per square root of a second
        (for log parameters a relative change: 0.1 allows ~10 % drift per second). Default 0 (constant parameters);
        set it to track parameters that change during the record.
    passes : int
        Maximum number of forward passes over the record.
    tol : float
        The passes stop as converged when no determined parameter changed between passes by more than ``tol``
        (internal coordinates: relative for log parameters) or a quarter of its standard error.
    initial_state : {"estimate", "rest"}
        ``"estimate"``: the first pass starts the states at zero with a covariance of their RMS, later passes at
        the least-squares initial state at the previous estimate. ``"rest"``: the record starts at rest (zero
        states, known).
    inflation : float
        Factor on the previous pass's covariance of the parameters for the start of the next (capped at the
        bounds' covariance). Larger values converge faster on informative data and are less robust on weakly
        informative data.
    intersample : {"zoh", "foh"}
        The inputs between samples (:mod:`cappe.systems.statespace`): held (default) or linear (what
        :func:`scipy.signal.lsim` simulates; the nearer of the two to a band-limited DAQ record). ``"bl"`` is
        refused with the reason (module notes): fit band-limited data with ``one-step``.
    covariance : {"auto", "gauss-newton", "sandwich"}
        Constant parameters: ``"gauss-newton"``, the inverse output-error information (right for white output
        errors); ``"sandwich"``, the Newey-West covariance of output errors correlated in time around it
        (:func:`cappe.estimate._uncertainty.newey_west_meat`, as one-step's); ``"auto"`` (default): the sandwich
        where the output errors fail the whiteness test. Tracking: the filter's covariance.
    refine : bool
        Constant parameters: after the passes, Gauss-Newton steps of the output-error fit from the filter's
        estimate to the output-error optimum, where the reported covariance belongs (default True; the filter's
        estimate stays in ``diagnostics["output_error_refinement"]``). ``False``: the filter's estimate as it is.

    Notes
    -----
    The result's ``diagnostics`` hold the parameter ``trajectory`` (every pass, at most 2000 rows: ``time``,
    ``pass``, ``values`` and ``std`` per unknown), the innovation statistics ``nis`` (mean normalized innovation
    squared of the last pass, its 95 % band for white innovations, per channel ratios), the noise used, the
    estimates of every pass, the information ratios, the filter's own standard errors (``filter_std``) and
    ``output_error_step``: the Gauss-Newton step of the output-error fit from the estimate, in standard errors
    (beyond 1 the message says so: the filter's fixed point is biased in a weakly determined direction).

    Examples
    --------
    >>> from cappe.model import NumericModel, load_model
    >>> from cappe.systems import time_response
    >>> nm = NumericModel(load_model("builtin:two-mass-rig"))
    >>> force = TimeData.from_rate(2000.0, {"F1": np.random.default_rng(0).standard_normal(200)})
    >>> data = time_response(nm.system({"k11": 1.5e6}), force, outputs=["d1", "a1"])
    >>> est = ExtendedKalmanEstimator(nm, ["k11"], noise=1e-3).fit(data)
    >>> round(est.params_["k11"] / 1.5e6, 3)
    1.0
    """

    method: ClassVar[str] = "ekf"
    _kind: ClassVar[str] = "extended"

    def _run(self, aug: _Augmented, z0: Array, p0: Array, q: Array, r: Array, w: Array, y: Array) -> _Pass:
        nt, n_x, m = aug.n_theta, 2 * aug.n, aug.m
        n_samples = y.shape[0]
        lo, hi = aug.space.internal_bounds()
        z = z0.copy()
        p = p0.copy()
        start_cov = p0[:nt, :nt].copy()
        center = z0[:nt].copy()
        w0, dw = aug.linearize(center)
        relin = 1
        eye = np.eye(nt + n_x)
        f = np.eye(nt + n_x)
        h = np.zeros((m, nt + n_x))
        xi = np.zeros(aug.s_t)
        traj = np.empty((n_samples, nt))
        std = np.empty((n_samples, nt))
        nis = np.empty(n_samples)
        innov = np.empty((n_samples, m))
        pvar = np.empty((n_samples, m))
        flat = dw.reshape(nt, -1)
        wt = w0 + ((z[:nt] - center) @ flat).reshape(w0.shape)
        for k in range(n_samples):
            # -- measurement update with y[k] (the input w[k] feeds through to accelerations)
            xi[:n_x] = z[nt:]
            xi[n_x:] = w[k]
            yt = wt[n_x:]
            h[:, :nt] = (dw[:, n_x:] @ xi).T
            h[:, nt:] = yt[:, :n_x]
            e = y[k] - yt @ xi
            pht = p @ h.T
            hph = h @ pht
            s_inv = np.linalg.inv(hph + r)
            gain = pht @ s_inv
            z += gain @ e
            ikh = eye - gain @ h
            p = ikh @ p @ ikh.T + gain @ r @ gain.T  # Joseph form: stays symmetric positive definite
            nis[k] = e @ s_inv @ e
            innov[k] = e
            pvar[k] = np.diagonal(hph)
            z[:nt] = np.minimum(np.maximum(z[:nt], lo), hi)
            traj[k] = z[:nt]
            std[k] = np.sqrt(np.diagonal(p)[:nt])
            if k == n_samples - 1:
                break
            # -- time update to k + 1 with the input rows w[k] (held: w[k]; linear: w[k] and w[k + 1])
            delta = z[:nt] - center
            if np.max(np.abs(delta)) > _RELINEARIZE:
                center = z[:nt].copy()
                w0, dw = aug.linearize(center)
                flat = dw.reshape(nt, -1)
                relin += 1
                wt = w0
            else:
                wt = w0 + (delta @ flat).reshape(w0.shape)
            xi[:n_x] = z[nt:]
            zt = wt[:n_x]
            f[nt:, :nt] = (dw[:, :n_x] @ xi).T
            f[nt:, nt:] = zt[:, :n_x]
            z[nt:] = zt @ xi
            p = f @ p @ f.T + q
        return _Pass(z[:nt].copy(), _symmetric(p), start_cov, traj, std, nis, innov, pvar, relin)


class UnscentedKalmanEstimator(_KalmanEstimator):
    """Unscented Kalman filter with the unknown parameters as augmented states.

    Same data, settings and result as :class:`ExtendedKalmanEstimator`, plus the sigma-point spread of the scaled
    unscented transform: ``alpha`` (spread, 0 < alpha <= 1), ``beta`` (2 is optimal for Gaussian priors) and
    ``kappa``. Every sigma point is propagated through the exact transition (ZOH or FOH) at its own parameters; no
    Jacobians are used.

    Parameters
    ----------
    model, unknowns, bounds, start, values, rng
        See :class:`Estimator`.
    inputs, outputs, position, noise, process_noise, random_walk, tol, initial_state, inflation
        As for :class:`ExtendedKalmanEstimator`.
    passes : int, optional
        Maximum number of forward passes over the record. Default: 2 where the output-error refinement finishes
        the job (constant parameters, ``refine``; a UKF pass costs ~2 CPU-s on 6000 samples of the two-mass rig,
        and 2 passes gave the same coverage and accuracy as 6), else 6.
    intersample, covariance, refine
        As for :class:`ExtendedKalmanEstimator`.
    alpha : float
        Spread of the sigma points around the mean, 0 < alpha <= 1 (dimensionless).
    beta : float
        Prior-distribution term of the covariance weights (2 is optimal for a Gaussian prior).
    kappa : float
        Secondary scaling of the spread (dimensionless; ``n + kappa > 0``).

    Examples
    --------
    >>> from cappe.model import NumericModel, load_model
    >>> from cappe.systems import time_response
    >>> nm = NumericModel(load_model("builtin:two-mass-rig"))
    >>> force = TimeData.from_rate(2000.0, {"F1": np.random.default_rng(0).standard_normal(200)})
    >>> data = time_response(nm.system({"k11": 1.5e6}), force, outputs=["d1", "a1"])
    >>> est = UnscentedKalmanEstimator(nm, ["k11"], noise=1e-3).fit(data)
    >>> round(est.params_["k11"] / 1.5e6, 3)
    1.0
    """

    method: ClassVar[str] = "ukf"
    _kind: ClassVar[str] = "unscented"

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
        noise: float | Mapping[str, float] | None = None,
        process_noise: float = 0.0,
        random_walk: float | Mapping[str, float] = 0.0,
        passes: int | None = None,
        tol: float = 1e-4,
        initial_state: str = "estimate",
        inflation: float = 4.0,
        intersample: str = "zoh",
        covariance: str = "auto",
        refine: bool = True,
        alpha: float = 1.0,
        beta: float = 2.0,
        kappa: float = 0.0,
    ) -> None:
        super().__init__(model, unknowns, bounds=bounds, start=start, values=values, rng=rng, inputs=inputs,
                         outputs=outputs, position=position, noise=noise, process_noise=process_noise,
                         random_walk=random_walk, passes=passes, tol=tol, initial_state=initial_state,
                         inflation=inflation, intersample=intersample, covariance=covariance,
                         refine=refine)
        self.alpha = alpha
        self.beta = beta
        self.kappa = kappa

    def _check_settings(self) -> None:
        super()._check_settings()
        if not (np.isfinite(self.alpha) and 0 < self.alpha <= 1):
            msg = f"alpha must lie in (0, 1]; got {self.alpha!r}"
            raise DataError(msg)

    def _run(self, aug: _Augmented, z0: Array, p0: Array, q: Array, r: Array, w: Array, y: Array) -> _Pass:
        nt, n_x, m = aug.n_theta, 2 * aug.n, aug.m
        dim = nt + n_x
        n_samples = y.shape[0]
        lo, hi = aug.space.internal_bounds()
        lam = self.alpha**2 * (dim + self.kappa) - dim
        spread = np.sqrt(dim + lam)
        wm = np.full(2 * dim + 1, 0.5 / (dim + lam))
        wc = wm.copy()
        wm[0] = lam / (dim + lam)
        wc[0] = wm[0] + 1.0 - self.alpha**2 + self.beta
        z = z0.copy()
        p = p0.copy()
        start_cov = p0[:nt, :nt].copy()
        # sigma point i uses parameter set owner[i]: 0 the mean, 1 + j / 1 + nt + j the +-j-th theta rows
        owner = np.zeros(2 * dim + 1, dtype=np.intp)
        owner[1: nt + 1] = 1 + np.arange(nt)
        owner[dim + 1: dim + nt + 1] = 1 + nt + np.arange(nt)
        traj = np.empty((n_samples, nt))
        std = np.empty((n_samples, nt))
        nis = np.empty(n_samples)
        innov = np.empty((n_samples, m))
        pvar = np.empty((n_samples, m))
        distinct = np.r_[0, 1: nt + 1, dim + 1: dim + nt + 1]
        # sigma points of the prior at sample 0; later those propagated from the last posterior (with Q added
        # before the propagation, so that the parameters' random walk widens the points the update sees)
        sig = _sigma_points(z, p, spread)
        _, out = aug.discrete(sig[distinct, :nt])
        xi = np.zeros((2 * dim + 1, aug.s_t))
        for k in range(n_samples):
            # -- measurement update with y[k]
            z = wm @ sig
            dz = sig - z
            p = (dz.T * wc) @ dz
            xi[:, :n_x] = sig[:, nt:]
            xi[:, n_x:] = w[k]
            ys = np.einsum("bij,bj->bi", out[owner], xi)
            y_mean = wm @ ys
            dy = ys - y_mean
            s_mat = (dy.T * wc) @ dy
            pvar[k] = np.diagonal(s_mat)
            s_mat = s_mat + r
            s_inv = np.linalg.inv(s_mat)
            gain = ((dz.T * wc) @ dy) @ s_inv
            e = y[k] - y_mean
            z = z + gain @ e
            p = _symmetric(p - gain @ s_mat @ gain.T)
            nis[k] = e @ s_inv @ e
            innov[k] = e
            z[:nt] = np.minimum(np.maximum(z[:nt], lo), hi)
            traj[k] = z[:nt]
            std[k] = np.sqrt(np.maximum(np.diagonal(p)[:nt], 0.0))
            if k == n_samples - 1:
                break
            # -- time update: exact transition of every sigma point at its own parameters
            sig = _sigma_points(z, p + q, spread)
            phi, out = aug.discrete(sig[distinct, :nt])
            xi[:, :n_x] = sig[:, nt:]
            sig[:, nt:] = np.einsum("bij,bj->bi", phi[owner], xi)
        return _Pass(z[:nt].copy(), p, start_cov, traj, std, nis, innov, pvar, 0)


def _sigma_points(mean: Array, cov: Array, spread: float) -> Array:
    """``2 L + 1`` sigma points ``mean``, ``mean +- spread * U[i]`` with ``cov = U^T U`` (U upper triangular)."""
    try:
        upper = np.asarray(np.linalg.cholesky(cov).T, dtype=float)
    except np.linalg.LinAlgError:
        # round-off made the covariance indefinite: the nearest positive semi-definite square root
        val, vec = np.linalg.eigh(_symmetric(np.nan_to_num(cov)))
        upper = np.asarray(np.linalg.qr((vec * np.sqrt(np.clip(val, 0.0, None))).T, mode="r"), dtype=float)
    return np.vstack([mean, mean + spread * upper, mean - spread * upper])
