"""Black-box polynomial models (thesis 2.1.3, Table 2.2): ARX, ARMAX, output error and Box-Jenkins.

All four are special cases of the general multi-input single-output structure (Ljung 1999, eq. 4.33)

    A(q) y(t) = sum_i B_i(q) / F_i(q) u_i(t) + C(q) / D(q) e(t)

with polynomials in the backward shift q^-1: ``A = [1, a1, ..., a_na]``, ``B_i = [0]*nk_i + [b0, ..., b_(nb_i-1)]``
(the leading zeros are the input delay), ``C``, ``D``, ``F_i`` monic like A. Arrays follow the
``scipy.signal.lfilter`` convention (coefficient of q^-k at index k), the same as MATLAB's ``idpoly``.

ARX is linear in its parameters and is solved by least squares (QR of the column-scaled regressor matrix,
never the normal equations). ARMAX, OE and BJ minimize the one-step prediction errors
``e = D/C (A y - sum B_i/F_i u_i)`` by a Levenberg-Marquardt (damped Gauss-Newton) iteration with the analytic
Jacobian (each column is a filtered, shifted signal). C and F_i are kept stable (every accepted iterate has their
roots reflected into the unit circle) so that the predictor stays stable; initial values come from ARX, a
pseudo-linear regression on high-order ARX residuals (ARMAX, BJ noise model, after Hannan and Rissanen) and
Steiglitz-McBride iterations (OE, BJ). Filters start from zero initial conditions.
"""

from __future__ import annotations

import copy
import inspect
import math
import warnings
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Self

import numpy as np
import scipy.linalg as sla
import scipy.signal as sig
from numpy.typing import NDArray

from cappe._settings import Settings
from cappe.exceptions import ConvergenceWarning, DataError, IllConditionedWarning, ModelError, NotFittedError
from cappe.io.measurements import match_channels
from cappe.systems.statespace import StateSpaceModel
from cappe.systems.timedata import TimeData, check_clipping
from cappe.systems.transfer import TransferFunctionModel, transfer_function
from cappe.systems.zpk import ZeroPoleGainModel, zpk

__all__ = [
    "ARMAX",
    "ARX",
    "OE",
    "BoxJenkins",
    "DiscreteTransferFunction",
    "ModalParameters",
    "PolynomialModel",
    "modal_parameters_from_poles",
]

Array = NDArray[np.float64]
CArray = NDArray[np.complex128]

# A discrete root whose imaginary part is below this (relative to its modulus) is treated as real.
_REAL_TOL = 1e-9
# Discrete poles closer than this to z = 0 are pure delays (log(0) = -inf): no finite continuous equivalent.
_ZERO_TOL = 1e-12


# ---------------------------------------------------------------------------------------------------------------
# results shared by the identification modules


@dataclass(frozen=True)
class ModalParameters:
    """Natural frequencies and damping ratios of the complex pole pairs of a continuous model, ascending.

    Attributes
    ----------
    frequency : ndarray, shape (n_modes,)
        Natural frequencies ``|lambda| / (2 pi)`` in Hz, ascending.
    damping : ndarray, shape (n_modes,)
        Damping ratios ``-Re(lambda) / |lambda|`` (negative for an unstable pair).
    poles : ndarray, shape (n_modes,)
        The poles ``lambda`` in rad/s, upper half plane.

    Examples
    --------
    >>> import numpy as np
    >>> modes = modal_parameters_from_poles(np.array([-1 + 100j, -1 - 100j, -5.0]))
    >>> modes.to_dict()  # doctest: +ELLIPSIS
    {'modes': [{'frequency': 15.916..., 'damping': 0.0099995...}]}
    """

    frequency: Array
    damping: Array
    poles: CArray

    @property
    def n_modes(self) -> int:
        return int(self.frequency.size)

    def to_dict(self) -> dict[str, Any]:
        return {
            "modes": [
                {"frequency": float(f), "damping": float(z)} for f, z in zip(self.frequency, self.damping, strict=True)
            ]
        }


def modal_parameters_from_poles(poles: NDArray[np.complexfloating[Any]]) -> ModalParameters:
    """Modal parameters of the complex pole pairs among continuous poles (rad/s); real poles are skipped.

    Each pair is represented by its member in the upper half plane; pairs are sorted by natural frequency.

    Parameters
    ----------
    poles : ndarray of complex
        Continuous poles in rad/s, any shape; non-finite ones are skipped.

    Returns
    -------
    ModalParameters
        Frequencies in Hz, damping ratios and the upper poles, ascending in frequency.

    Examples
    --------
    >>> import numpy as np
    >>> modal_parameters_from_poles(np.array([-3 + 4j, -3 - 4j])).damping
    array([0.6])
    """
    p = np.asarray(poles, dtype=complex).ravel()
    p = p[np.isfinite(p)]
    upper = p[p.imag > _REAL_TOL * np.maximum(np.abs(p), 1e-300)]
    omega = np.abs(upper)
    order = np.argsort(omega, kind="stable")
    upper, omega = upper[order], omega[order]
    return ModalParameters(omega / (2 * np.pi), -upper.real / omega, np.asarray(upper, dtype=complex))


@dataclass(frozen=True)
class DiscreteTransferFunction:
    """SISO discrete transfer function ``num(q^-1) / den(q^-1)`` with sample time ``dt`` (s).

    ``numerator`` and ``denominator`` have equal length (zero padded), so they read both as coefficients of
    q^-k at index k and as z-polynomials, highest power first. ``denominator[0] == 1``.

    Attributes
    ----------
    numerator, denominator : tuple of float
        Coefficients of q^-0, q^-1, ... (equal length).
    dt : float
        Sample time in s.
    input, output : str
        Channel names.

    Examples
    --------
    >>> tf = DiscreteTransferFunction((0.0, 0.5), (1.0, -0.5), 0.1, "u", "y")
    >>> complex(tf.evaluate([0.0])[0])
    (1+0j)
    """

    numerator: tuple[float, ...]
    denominator: tuple[float, ...]
    dt: float
    input: str
    output: str

    def poles(self) -> CArray:
        """Roots of the denominator in the z-plane (including poles at z = 0 from delays)."""
        return _roots(np.asarray(self.denominator))

    def zeros(self) -> CArray:
        """Roots of the numerator in the z-plane."""
        return _roots(np.asarray(self.numerator))

    def evaluate(self, freq: Sequence[float] | Array) -> CArray:
        """Frequency response at ``freq`` (Hz): the value at ``z = exp(2j pi f dt)``.

        Parameters
        ----------
        freq : array_like, shape (n_freq,)
            Frequencies in Hz.

        Returns
        -------
        ndarray of complex, shape (n_freq,)
            In output units per input unit.
        """
        z = np.exp(2j * np.pi * np.asarray(freq, dtype=float) * self.dt)
        return np.asarray(np.polyval(self.numerator, z) / np.polyval(self.denominator, z), dtype=complex)

    def to_control(self) -> Any:
        """The equivalent python-control ``TransferFunction`` (discrete, same dt)."""
        import control

        return control.tf(list(self.numerator), list(self.denominator), self.dt)

    def to_dict(self) -> dict[str, Any]:
        return {
            "input": self.input,
            "output": self.output,
            "dt": self.dt,
            "numerator": list(self.numerator),
            "denominator": list(self.denominator),
        }


# ---------------------------------------------------------------------------------------------------------------
# structure bookkeeping


@dataclass(frozen=True)
class _Orders:
    na: int
    nb: tuple[int, ...]
    nc: int
    nd: int
    nf: tuple[int, ...]
    nk: tuple[int, ...]

    @property
    def n_inputs(self) -> int:
        return len(self.nb)

    @property
    def n_parameters(self) -> int:
        return self.na + sum(self.nb) + self.nc + self.nd + sum(self.nf)

    @property
    def n_lagged(self) -> int:
        """Samples lost at the start of an ARX regression (largest lag)."""
        lags = [self.na] + [k + b - 1 for k, b in zip(self.nk, self.nb, strict=True)]
        return max(0, *lags)


@dataclass(frozen=True)
class _Polys:
    A: Array
    B: tuple[Array, ...]
    C: Array
    D: Array
    F: tuple[Array, ...]


def _unpack(theta: Array, o: _Orders) -> _Polys:
    pos = 0

    def take(n: int) -> Array:
        nonlocal pos
        out = theta[pos : pos + n]
        pos += n
        return np.asarray(out, dtype=float)

    a = np.concatenate(([1.0], take(o.na)))
    b = tuple(np.concatenate((np.zeros(k), take(n))) for n, k in zip(o.nb, o.nk, strict=True))
    c = np.concatenate(([1.0], take(o.nc)))
    d = np.concatenate(([1.0], take(o.nd)))
    f = tuple(np.concatenate(([1.0], take(n))) for n in o.nf)
    return _Polys(a, b, c, d, f)


def _pack(p: _Polys, o: _Orders) -> Array:
    parts = [p.A[1:]]
    parts += [b[k:] for b, k in zip(p.B, o.nk, strict=True)]
    parts += [p.C[1:], p.D[1:]]
    parts += [f[1:] for f in p.F]
    return np.concatenate(parts).astype(float)


def _parameter_names(o: _Orders, inputs: Sequence[str]) -> tuple[str, ...]:
    names = [f"a{k}" for k in range(1, o.na + 1)]
    for name, n, k in zip(inputs, o.nb, o.nk, strict=True):
        names += [f"b{j}[{name}]" for j in range(k, k + n)]
    names += [f"c{k}" for k in range(1, o.nc + 1)]
    names += [f"d{k}" for k in range(1, o.nd + 1)]
    for name, n in zip(inputs, o.nf, strict=True):
        names += [f"f{k}[{name}]" for k in range(1, n + 1)]
    return tuple(names)


def _roots(poly: Array) -> CArray:
    p = np.asarray(poly, dtype=float)
    p = np.trim_zeros(p, "f")
    if p.size <= 1:
        return np.zeros(0, dtype=complex)
    return np.asarray(np.roots(p), dtype=complex)


def _reflect(poly: Array) -> tuple[Array, bool]:
    """Monic polynomial in q^-1 with every root outside the unit circle reflected to ``1 / conj(root)``."""
    if poly.size <= 1:
        return poly, False
    r = np.roots(poly)
    out = np.abs(r) > 1.0
    if not out.any():
        return poly, False
    r[out] = 1.0 / np.conj(r[out])
    return np.real(np.poly(r)).astype(float), True


def _shift(x: Array, k: int) -> Array:
    """``x(t - k)`` with zeros before the start."""
    if k == 0:
        return x
    out = np.zeros_like(x)
    out[k:] = x[:-k]
    return out


def _lagged(x: Array, lags: Sequence[int] | NDArray[np.int_], start: int) -> Array:
    """Matrix with columns ``x(t - lag)`` for rows ``t = start .. n - 1``."""
    t = np.arange(start, x.size)[:, None]
    return np.asarray(x[t - np.asarray(lags, dtype=int)[None, :]], dtype=float)


def _lfilter(b: Array, a: Array, x: Array) -> Array:
    return np.asarray(sig.lfilter(b, a, x), dtype=float)


# ---------------------------------------------------------------------------------------------------------------
# linear least squares (ARX) and its helpers


def _arx_regressor(y: Array, u: Array, o: _Orders, start: int) -> Array:
    cols = [-_lagged(y, np.arange(1, o.na + 1), start)]
    for i in range(o.n_inputs):
        cols.append(_lagged(u[i], np.arange(o.nk[i], o.nk[i] + o.nb[i]), start))
    return np.hstack(cols) if cols else np.zeros((y.size - start, 0))


@dataclass(frozen=True)
class _LinearSolution:
    theta: Array
    residuals: Array
    cov_unscaled: Array  # (Phi^T Phi)^-1
    rank_deficient: bool


def _solve_ls(phi: Array, rhs: Array) -> _LinearSolution:
    """Least squares by QR of the column-scaled regressor; pseudo-inverse through the SVD of R if rank deficient."""
    n_par = phi.shape[1]
    if n_par == 0:
        return _LinearSolution(np.zeros(0), rhs.copy(), np.zeros((0, 0)), False)
    scale = np.sqrt(np.einsum("ij,ij->j", phi, phi))
    scale[scale == 0] = 1.0
    # R of the augmented matrix [Phi | rhs] holds R and Q^T rhs without forming Q
    aug = np.empty((phi.shape[0], n_par + 1))
    np.divide(phi, scale, out=aug[:, :n_par])
    aug[:, n_par] = rhs
    r_aug = sla.qr(aug, mode="r", overwrite_a=True, check_finite=False)[0]
    r = r_aug[:n_par, :n_par]
    qty = r_aug[:n_par, n_par]
    # SVD of the small triangular factor gives both the (pseudo-)solution and the covariance
    uu, s, vt = np.linalg.svd(r)
    tol = s[0] * max(phi.shape) * np.finfo(float).eps
    keep = s > tol
    inv_s = np.where(keep, 1.0 / np.where(keep, s, 1.0), 0.0)
    theta_s = vt.T @ (inv_s * (uu.T @ qty))
    theta = theta_s / scale
    cov = (vt.T * inv_s**2) @ vt / np.outer(scale, scale)
    return _LinearSolution(theta, rhs - phi @ theta, cov, bool(not keep.all()))


def _arx_fit(y: Array, u: Array, o: _Orders) -> tuple[_Polys, _LinearSolution, int]:
    start = o.n_lagged
    phi = _arx_regressor(y, u, o, start)
    sol = _solve_ls(phi, y[start:])
    theta = np.concatenate([sol.theta, np.zeros(o.nc + o.nd + sum(o.nf))])
    return _unpack(theta, o), sol, start


def _arx_orders(na: int, nb: Sequence[int], nk: Sequence[int]) -> _Orders:
    return _Orders(na, tuple(nb), 0, 0, (0,) * len(nb), tuple(nk))


def _high_order_residuals(y: Array, u: Array, nk: Sequence[int], order: int) -> Array:
    """One-step residuals of a high-order ARX model (zero for the first ``order`` samples)."""
    o = _arx_orders(order, [order] * u.shape[0], nk)
    _, sol, start = _arx_fit(y, u, o)
    e = np.zeros_like(y)
    e[start:] = sol.residuals
    return e


def _ar_residuals(v: Array, order: int) -> Array:
    """One-step residuals of a high-order AR model of ``v`` (zero for the first ``order`` samples)."""
    start = order
    phi = -_lagged(v, np.arange(1, order + 1), start)
    sol = _solve_ls(phi, v[start:])
    e = np.zeros_like(v)
    e[start:] = sol.residuals
    return e


# ---------------------------------------------------------------------------------------------------------------
# prediction errors, Jacobian and the Levenberg-Marquardt iteration


def _errors(p: _Polys, y: Array, u: Array) -> tuple[Array, Array, list[Array]]:
    """One-step prediction errors ``e``, equation errors ``v = A y - sum w_i`` and ``w_i = B_i/F_i u_i``."""
    w = [_lfilter(b, f, ui) for b, f, ui in zip(p.B, p.F, u, strict=True)]
    v = _lfilter(p.A, np.ones(1), y) - (np.sum(w, axis=0) if w else 0.0)
    e = _lfilter(p.D, p.C, v)
    return e, v, w


def _jacobian(p: _Polys, o: _Orders, y: Array, u: Array, e: Array, v: Array, w: list[Array]) -> Array:
    """Jacobian ``d e / d theta`` (n_samples, n_parameters); each column is a filtered signal shifted in time."""
    cols: list[Array] = []
    if o.na:
        ya = _lfilter(p.D, p.C, y)
        cols += [_shift(ya, k) for k in range(1, o.na + 1)]
    for i in range(o.n_inputs):
        ub = -_lfilter(p.D, np.convolve(p.C, p.F[i]), u[i])
        cols += [_shift(ub, o.nk[i] + k) for k in range(o.nb[i])]
    if o.nc:
        ec = -_lfilter(np.ones(1), p.C, e)
        cols += [_shift(ec, k) for k in range(1, o.nc + 1)]
    if o.nd:
        vc = _lfilter(np.ones(1), p.C, v)
        cols += [_shift(vc, k) for k in range(1, o.nd + 1)]
    for i in range(o.n_inputs):
        if o.nf[i]:
            wf = _lfilter(p.D, np.convolve(p.C, p.F[i]), w[i])
            cols += [_shift(wf, k) for k in range(1, o.nf[i] + 1)]
    return np.column_stack(cols) if cols else np.zeros((y.size, 0))


def _stabilize(p: _Polys) -> _Polys:
    c, _ = _reflect(p.C)
    d, _ = _reflect(p.D)
    f = tuple(_reflect(fi)[0] for fi in p.F)
    return _Polys(p.A, p.B, c, d, f)


@dataclass(frozen=True)
class _PemResult:
    theta: Array
    errors: Array
    jacobian: Array
    success: bool
    message: str
    n_iter: int


def _pem(theta0: Array, o: _Orders, y: Array, u: Array, *, max_iter: int, tol: float) -> _PemResult:
    """Levenberg-Marquardt minimization of ``sum e(theta)^2`` with stable C, D and F_i.

    A loop of its own rather than the shared least squares (:func:`cappe.optimize.minimize`,
    ``strategy="least-squares"``, which cannot project a trial step): every trial is stabilized (roots of C, D and
    F_i reflected into the unit circle) before its errors are filtered. benchmarks/bench_lm.py (4000 samples of a
    seeded ARMAX process, both in one run, two runs): the same losses for ARMAX(2, 2, 2), ARMAX(4, 4, 4) and
    OE(2, 2) at times within the machine's noise (shared / own 0.5-1.6x), but OE(4, 4) ends at loss 0.341 with the
    shared solver against 0.0886 with this one (unstable F in between).
    """
    theta = _pack(_stabilize(_unpack(theta0, o)), o)
    p = _unpack(theta, o)
    e, v, w = _errors(p, y, u)
    cost = float(e @ e)
    floor = (1e3 * np.finfo(float).eps) ** 2 * float(y @ y)  # an exact fit cannot be improved below this
    jac = _jacobian(p, o, y, u, e, v, w)
    mu_rel = 1e-6
    message = f"no convergence in {max_iter} iterations"
    success = False
    it = 0
    while it < max_iter:
        it += 1
        if cost <= floor:
            success, message = True, "exact fit"
            break
        scale = np.sqrt(np.einsum("ij,ij->j", jac, jac))
        scale[scale == 0] = 1.0
        uu, s, vt = np.linalg.svd(jac / scale, full_matrices=False)
        if not s[0] > 0:  # e.g. an input that is zero throughout: the errors do not depend on the parameters
            message = "the prediction errors do not depend on the parameters (zero Jacobian)"
            break
        g = uu.T @ e
        gradient = float(np.linalg.norm(s * g)) / max(float(s[0]) * math.sqrt(cost), 1e-300)
        accepted = False
        while mu_rel < 1e12:
            mu = mu_rel * float(s[0]) ** 2
            step = -(vt.T @ (s / (s**2 + mu) * g)) / scale
            trial_p = _stabilize(_unpack(theta + step, o))
            trial = _pack(trial_p, o)
            e_t, v_t, w_t = _errors(trial_p, y, u)
            cost_t = float(e_t @ e_t)
            if np.isfinite(cost_t) and cost_t < cost:
                accepted = True
                break
            mu_rel *= 10.0
        if not accepted:
            # no descent direction left: converged if the gradient vanishes (to round-off) or the errors are at the
            # rounding level of their own filtering (relative rms below 1e6 eps: the recursive filters of a lightly
            # damped F or C lose digits, and there the gradient is rounding noise), failed otherwise
            if gradient < 1e-6:
                success, message = True, "converged (no further decrease)"
            elif cost <= 1e6 * floor:
                success, message = True, "exact fit (to the rounding of the filtered errors)"
            else:
                message = f"stalled with relative gradient {gradient:.2g}"
            break
        decrease = (cost - cost_t) / cost
        rel_step = float(np.linalg.norm(trial - theta)) / (float(np.linalg.norm(theta)) + math.sqrt(tol))
        theta, p, e, v, w, cost = trial, trial_p, e_t, v_t, w_t, cost_t
        jac = _jacobian(p, o, y, u, e, v, w)
        mu_rel = max(mu_rel / 10.0, 1e-12)
        if decrease < tol and rel_step < math.sqrt(tol):
            success, message = True, "converged"
            break
    return _PemResult(theta, e, jac, success, message, it)


def _steiglitz_mcbride(y: Array, u: Array, nf: int, nb: Sequence[int], nk: Sequence[int], n_iter: int = 6) -> _Polys:
    """Common-denominator output-error initial values: ARX, then ARX on data prefiltered by 1/F (repeated)."""
    o = _arx_orders(nf, nb, nk)
    p, _, _ = _arx_fit(y, u, o)
    f = _reflect(p.A)[0]
    for _ in range(n_iter):
        yf = _lfilter(np.ones(1), f, y)
        uf = np.array([_lfilter(np.ones(1), f, ui) for ui in u])
        p, _, _ = _arx_fit(yf, uf, o)
        f = _reflect(p.A)[0]
    return _Polys(np.ones(1), p.B, np.ones(1), np.ones(1), tuple(f for _ in nb))


def _refit_b(y: Array, u: Array, f: Sequence[Array], nb: Sequence[int], nk: Sequence[int]) -> tuple[Array, ...]:
    """Numerators B_i by least squares with the denominators F_i fixed (the model is linear in B then)."""
    cols = []
    for i in range(u.shape[0]):
        uf = _lfilter(np.ones(1), np.asarray(f[i]), u[i])
        cols.append(_lagged(uf, np.arange(nk[i], nk[i] + nb[i]), 0) if nb[i] else np.zeros((y.size, 0)))
    sol = _solve_ls(np.hstack(cols), y)
    out, pos = [], 0
    for i in range(u.shape[0]):
        out.append(np.concatenate((np.zeros(nk[i]), sol.theta[pos : pos + nb[i]])))
        pos += nb[i]
    return tuple(out)


def _output_error_start(y: Array, u: Array, o: _Orders) -> _Polys:
    """Initial B_i and F_i: Steiglitz-McBride with the largest F order, per-input root selection, B refitted."""
    n = max(o.nf)
    if n == 0:
        b0 = _refit_b(y, u, [np.ones(1)] * o.n_inputs, o.nb, o.nk)
        return _Polys(np.ones(1), b0, np.ones(1), np.ones(1), _ones_per_input(o))
    common = _steiglitz_mcbride(y, u, n, o.nb, o.nk)
    f_all = common.F[0]
    roots = np.asarray(np.roots(f_all), dtype=complex)
    fs: list[Array] = []
    for i in range(o.n_inputs):
        if o.nf[i] == n:
            fs.append(f_all)
            continue
        if o.nf[i] == 0:
            fs.append(np.ones(1))
            continue
        # keep the nf_i roots that matter most to input i: largest |residue| / (1 - |root|) of B_i / F
        b = common.B[i]
        den = np.concatenate((f_all, np.zeros(max(0, b.size - f_all.size))))
        num = np.concatenate((b, np.zeros(max(0, den.size - b.size))))
        weight = np.array(
            [
                abs(np.polyval(num, r) / np.prod(r - np.delete(roots, j))) / max(1.0 - abs(r), 1e-6)
                for j, r in enumerate(roots)
            ]
        )
        chosen = _conjugate_closed_top(roots, weight, o.nf[i])
        fs.append(np.real(np.poly(chosen)).astype(float))
    b_new = _refit_b(y, u, fs, o.nb, o.nk)
    return _Polys(np.ones(1), b_new, np.ones(1), np.ones(1), tuple(fs))


def _ones_per_input(o: _Orders) -> tuple[Array, ...]:
    return tuple(np.ones(1) for _ in range(o.n_inputs))


def _conjugate_closed_top(roots: CArray, weight: Array, n: int) -> CArray:
    """The ``n`` highest-weight roots, taking complex pairs together (a pair that does not fit is skipped)."""
    chosen: list[complex] = []
    used = np.zeros(roots.size, dtype=bool)
    for j in np.argsort(-weight, kind="stable"):
        if used[j] or len(chosen) >= n:
            continue
        r = roots[j]
        if abs(r.imag) > _REAL_TOL * max(abs(r), 1e-300):
            partner = int(np.argmin(np.abs(roots - np.conj(r)) + used * 1e300 + (np.arange(roots.size) == j) * 1e300))
            if len(chosen) + 2 > n:
                continue
            chosen += [r, np.conj(r)]
            used[[j, partner]] = True
        else:
            chosen.append(complex(r.real))
            used[j] = True
    # a complex pair that did not fit the remaining slot: stand in a real root of the same modulus
    for j in np.argsort(-weight, kind="stable"):
        if len(chosen) >= n:
            break
        if not used[j]:
            chosen.append(complex(np.copysign(abs(roots[j]), roots[j].real)))
            used[j] = True
    return np.asarray(chosen, dtype=complex)


def _arma_start(v: Array, nc: int, nd: int) -> tuple[Array, Array]:
    """Initial C and D of ``D v = C e`` by a pseudo-linear regression on high-order AR residuals."""
    order = min(max(4 * (nc + nd), 20), max(v.size // 10, nc + nd + 1))
    e_hat = _ar_residuals(v, order) if nc else np.zeros_like(v)
    start = max(nc, nd)
    phi = np.hstack([-_lagged(v, np.arange(1, nd + 1), start), _lagged(e_hat, np.arange(1, nc + 1), start)])
    sol = _solve_ls(phi, v[start:])
    d = np.concatenate(([1.0], sol.theta[:nd]))
    c = np.concatenate(([1.0], sol.theta[nd:]))
    return _reflect(c)[0], _reflect(d)[0]


# ---------------------------------------------------------------------------------------------------------------
# argument checks


def _as_int(value: Any, name: str, minimum: int, owner: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or int(value) < minimum:
        msg = f"{owner} order {name} must be an integer >= {minimum}; got {value!r}"
        raise DataError(msg)
    return int(value)


def _per_input(value: Any, name: str, minimum: int, n_inputs: int, owner: str) -> tuple[int, ...]:
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        return (_as_int(value, name, minimum, owner),) * n_inputs
    if isinstance(value, str) or not isinstance(value, Sequence):
        msg = f"{owner} order {name} must be an integer or one integer per input; got {value!r}"
        raise DataError(msg)
    if len(value) != n_inputs:
        msg = f"{owner} order {name} must have one entry per input ({n_inputs}); got {len(value)}: {list(value)!r}"
        raise DataError(msg)
    return tuple(_as_int(v, name, minimum, owner) for v in value)


def _input_names(inputs: Sequence[str] | str) -> tuple[str, ...]:
    names = (inputs,) if isinstance(inputs, str) else tuple(inputs)
    if not names or not all(isinstance(n, str) for n in names):
        msg = f"inputs must name at least one input channel; got {inputs!r}"
        raise DataError(msg)
    if len(set(names)) != len(names):
        msg = f"inputs must be distinct channels; got {list(names)!r}"
        raise DataError(msg)
    return names


def _check_time_data(data: Any, owner: str) -> None:
    if not isinstance(data, TimeData):
        msg = f"{owner} needs TimeData with the input and output channels; got {type(data).__name__}"
        raise DataError(msg)


def _channel(data: TimeData, name: str, role: str) -> Array:
    return np.asarray(data.values[match_channels(data, [name], role)[0]])


# ---------------------------------------------------------------------------------------------------------------
# the estimators


class PolynomialModel(Settings, ABC):
    """Common base of the polynomial black-box estimators (scikit-learn conventions).

    Learned attributes (after :meth:`fit`): ``A_``, ``B_`` (one array per input), ``C_``, ``D_``, ``F_`` (one
    array per input) as polynomials in q^-1; ``inputs_``, ``output_``, ``dt_`` (s); ``parameters_`` and
    ``parameter_names_``; ``covariance_`` and ``parameter_std_`` (from the Jacobian, ``lambda (J^T J)^-1``);
    ``loss_`` (V, the mean squared one-step prediction error over the samples used); ``noise_variance_``
    (``sum e^2 / (N - d)``); ``n_parameters_`` (d); ``n_samples_`` (N); ``success_``; ``message_``; ``n_iter_``.
    ``get_params()`` returns every ``__init__`` argument (orders and iteration settings), ``set_params(**settings)``
    changes them for the next fit.

    Examples
    --------
    >>> isinstance(ARX(2, 2), PolynomialModel), ARX(2, 2).get_params()
    (True, {'na': 2, 'nb': 2, 'nk': 1})
    """

    _iterative: ClassVar[bool] = True

    max_iter: int
    tol: float

    # -- provided by each structure ---------------------------------------------------------------------------
    @abstractmethod
    def _orders(self, n_inputs: int) -> _Orders:
        """Polynomial orders and delays of this structure for ``n_inputs`` inputs."""

    def _start(self, y: Array, u: Array, o: _Orders) -> _Polys:
        """Initial polynomials of the prediction-error search (default: the output-error start; ARX overrides the
        whole fit, ARMAX and BJ add their noise models)."""
        return _output_error_start(y, u, o)

    def __repr__(self) -> str:
        # the orders always; the keyword-only iteration settings where they differ from their defaults
        defaults = {p.name: p.default for p in inspect.signature(type(self).__init__).parameters.values()
                    if p.kind is inspect.Parameter.KEYWORD_ONLY}
        args = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items()
                         if k not in defaults or repr(v) != repr(defaults[k]))
        return f"{type(self).__name__}({args})"

    # -- fitting --------------------------------------------------------------------------------------------------
    def fit(self, data: TimeData, *, inputs: Sequence[str] | str, output: str) -> Self:
        """Estimate the model from time data.

        Parameters
        ----------
        data : TimeData
            Uniformly sampled input and output channels (SI units).
        inputs : sequence of str
            Input channel names (a single name is accepted).
        output : str
            Output channel name.

        Returns
        -------
        self
            With the learned attributes set. Iterative structures that fail to converge warn
            :class:`~cappe.exceptions.ConvergenceWarning` and set ``success_ = False``.

        Raises
        ------
        DataError
            ``data`` is not TimeData, a channel is missing, the orders or iteration settings are invalid or the record
            is too short for them.
        """
        _check_time_data(data, f"{type(self).__name__}.fit")
        names = _input_names(inputs)
        if not isinstance(output, str):
            msg = f"output must be one channel name; got {output!r}"
            raise DataError(msg)
        if output in names:
            msg = f"output channel {output!r} is also listed as an input"
            raise DataError(msg)
        u = data.values[match_channels(data, names, "input")]
        y = _channel(data, output, "output")
        check_clipping(data.select([*names, output]))
        o = self._orders(len(names))
        n = y.size
        usable = n - (o.n_lagged if not self._iterative else 0)
        if usable <= o.n_parameters:
            msg = (
                f"data too short for {self!r}: {n} samples ({usable} usable after the first {n - usable} lagged ones) "
                f"for {o.n_parameters} parameters; need more than {o.n_parameters} usable samples"
            )
            raise DataError(msg)
        self._fit_arrays(y, u, o)
        self.inputs_ = names
        self.output_ = output
        self.dt_ = data.dt
        self.parameter_names_ = _parameter_names(o, names)
        return self

    def _fit_arrays(self, y: Array, u: Array, o: _Orders) -> None:
        p0 = self._start(y, u, o)
        result = _pem(_pack(p0, o), o, y, u, max_iter=self.max_iter, tol=self.tol)
        self._set_result(
            _unpack(result.theta, o),
            o,
            result.errors,
            _unscaled_covariance(result.jacobian, self),
            success=result.success,
            message=result.message,
            n_iter=result.n_iter,
        )
        if not result.success:
            warnings.warn(
                f"{self!r} did not converge: {result.message} (loss {self.loss_:.3g}); the estimate may be poor",
                ConvergenceWarning,
                stacklevel=3,
            )

    def _set_result(
        self, p: _Polys, o: _Orders, e: Array, cov_unscaled: Array, *, success: bool, message: str, n_iter: int
    ) -> None:
        """Learned attributes from the polynomials, the residuals ``e`` and ``(J^T J)^-1``."""
        n_eff = e.size
        d = o.n_parameters
        sse = float(e @ e)
        self._o = o
        self.A_, self.B_, self.C_, self.D_, self.F_ = p.A, list(p.B), p.C, p.D, list(p.F)
        self.parameters_ = _pack(p, o)
        self.n_parameters_ = d
        self.n_samples_ = n_eff
        self.loss_ = sse / n_eff
        self.noise_variance_ = sse / (n_eff - d)
        self.covariance_ = self.noise_variance_ * cov_unscaled
        self.parameter_std_ = np.sqrt(np.clip(np.diag(self.covariance_), 0.0, None))
        self.success_ = success
        self.message_ = message
        self.n_iter_ = n_iter

    def with_parameters(self, parameters: Sequence[float] | Array) -> Self:
        """A copy of the fitted model with another parameter vector: the same orders, inputs, output and ``dt_``.

        For propagating the parameter covariance through a map of the polynomials (continuous coefficients, poles):
        the fit statistics (``covariance_``, ``loss_`` ...) stay those of the original fit.

        Parameters
        ----------
        parameters : array_like, shape (n_parameters_,)
            In the order of ``parameter_names_``.

        Returns
        -------
        PolynomialModel
            A new object; ``self`` is unchanged.

        Raises
        ------
        DataError
            The vector has the wrong length or non-finite entries.

        Examples
        --------
        >>> data = TimeData.from_rate(100.0, {"u": np.sin(np.arange(200.0)), "y": np.cos(np.arange(200.0))})
        >>> arx = ARX(1, 1).fit(data, inputs="u", output="y")
        >>> bool(arx.with_parameters(arx.parameters_ * 2).A_[1] == 2 * arx.A_[1])
        True
        """
        self._check_fitted()
        theta = np.asarray(parameters, dtype=float)
        if theta.shape != self.parameters_.shape or not np.all(np.isfinite(theta)):
            msg = (f"{self!r}.with_parameters: need {self.parameters_.size} finite parameters "
                   f"{list(self.parameter_names_)}; got shape {theta.shape}")
            raise DataError(msg)
        out = copy.copy(self)
        p = _unpack(theta, self._o)
        out.A_, out.B_, out.C_, out.D_, out.F_ = p.A, list(p.B), p.C, p.D, list(p.F)
        out.parameters_ = theta.copy()
        return out

    # -- use ------------------------------------------------------------------------------------------------------
    def _check_fitted(self) -> None:
        if not hasattr(self, "A_"):
            msg = f"this {type(self).__name__} is not fitted yet; call fit(data, inputs=..., output=...) first"
            raise NotFittedError(msg)

    def _polys(self) -> _Polys:
        return _Polys(self.A_, tuple(self.B_), self.C_, self.D_, tuple(self.F_))

    def _input_arrays(self, data: TimeData) -> Array:
        self._check_fitted()
        _check_time_data(data, type(self).__name__)
        if abs(data.dt - self.dt_) > 1e-6 * self.dt_:
            msg = f"data sampled at dt = {data.dt:.9g} s but the model was fitted at dt = {self.dt_:.9g} s"
            raise DataError(msg)
        return np.asarray(data.values[match_channels(data, self.inputs_, "input")])

    def predict(self, data: TimeData, horizon: float = 1) -> Array:
        """Predicted output, shape (n_samples,).

        Parameters
        ----------
        data : TimeData
            Holds the input channels and, for a finite horizon, the output channel.
        horizon : int or inf
            ``1`` for the one-step-ahead prediction, ``k`` for k steps ahead (from outputs up to t - k), ``inf``
            (``math.inf``) for the pure simulation ``sum B_i / (A F_i) u_i``. Zero initial conditions.
        """
        self._check_fitted()
        numeric = isinstance(horizon, (int, float, np.integer, np.floating)) and not isinstance(horizon, bool)
        if not (numeric and (horizon == math.inf or (float(horizon).is_integer() and horizon >= 1))):
            msg = f"horizon must be a positive integer or inf; got {horizon!r}"
            raise DataError(msg)
        p = self._polys()
        u = self._input_arrays(data)
        if horizon == math.inf:
            parts = [_lfilter(b, np.convolve(p.A, f), ui) for b, f, ui in zip(p.B, p.F, u, strict=True)]
            return np.asarray(np.sum(parts, axis=0), dtype=float)
        y = _channel(data, self.output_, "output")
        e, _, _ = _errors(p, y, u)
        k = int(horizon)
        if k == 1:
            return y - e
        # k steps: y - hbar_k(q) e with hbar_k the first k impulse-response terms of H = C / (D A)
        impulse = np.zeros(k)
        impulse[0] = 1.0
        hbar = _lfilter(p.C, np.convolve(p.D, p.A), impulse)
        return y - _lfilter(hbar, np.ones(1), e)

    def residuals(self, data: TimeData) -> Array:
        """One-step prediction errors ``y - y_hat(t | t-1)``, shape (n_samples,).

        Parameters
        ----------
        data : TimeData
            The input and output channels, sampled at the fitted ``dt_``.

        Returns
        -------
        ndarray, shape (n_samples,)
            In the output's unit.
        """
        u = self._input_arrays(data)
        return _errors(self._polys(), _channel(data, self.output_, "output"), u)[0]

    def fit_percent(self, data: TimeData, horizon: float = math.inf) -> float:
        """Normalized RMS fit ``100 (1 - |y - y_hat| / |y - mean(y)|)`` in %, as MATLAB's ``compare``.

        ``horizon`` as in :meth:`predict`; the default compares the simulated output.

        Parameters
        ----------
        data : TimeData
            The input and output channels, sampled at the fitted ``dt_``.
        horizon : int or inf
            Prediction horizon in samples (``inf``: simulation).

        Returns
        -------
        float
            Fit in % (100 for a perfect prediction; negative when worse than the mean).

        Raises
        ------
        DataError
            The output is constant.
        """
        y_hat = self.predict(data, horizon)
        y = _channel(data, self.output_, "output")
        ref = float(np.linalg.norm(y - y.mean()))
        if ref == 0.0:
            msg = f"output channel {self.output_!r} is constant; the fit in % is undefined"
            raise DataError(msg)
        return float(100.0 * (1.0 - np.linalg.norm(y - y_hat) / ref))

    # -- discrete representations ---------------------------------------------------------------------------------
    def _input_index(self, input: str | None) -> int:  # noqa: A002
        self._check_fitted()
        if input is None:
            if len(self.inputs_) != 1:
                msg = f"the model has {len(self.inputs_)} inputs {list(self.inputs_)}; name one with input=..."
                raise DataError(msg)
            return 0
        if input not in self.inputs_:
            msg = f"input {input!r} is not an input of the model; inputs: {list(self.inputs_)}"
            raise DataError(msg)
        return self.inputs_.index(input)

    def to_discrete_tf(self, input: str | None = None) -> DiscreteTransferFunction:  # noqa: A002
        """Discrete transfer function ``B_i / (A F_i)`` from one input to the output.

        Parameters
        ----------
        input : str, optional
            The input channel (may be omitted for a single-input model).

        Returns
        -------
        DiscreteTransferFunction
        """
        i = self._input_index(input)
        num = self.B_[i]
        den = np.convolve(self.A_, self.F_[i])
        n = max(num.size, den.size)
        num = np.concatenate((num, np.zeros(n - num.size)))
        den = np.concatenate((den, np.zeros(n - den.size)))
        return DiscreteTransferFunction(
            tuple(float(x) for x in num), tuple(float(x) for x in den), self.dt_, self.inputs_[i], self.output_
        )

    def poles(self, input: str | None = None) -> CArray:  # noqa: A002
        """Discrete poles (z-plane): roots of ``A F_i``, or of A and every F_i when ``input`` is None.

        Poles at z = 0 that only stand for input delays are not listed.

        Parameters
        ----------
        input : str, optional
            The input channel; None for the poles of A and every F_i.

        Returns
        -------
        ndarray of complex
            Discrete poles (dimensionless z).
        """
        self._check_fitted()
        if input is None:
            den = self.A_
            for f in self.F_:
                den = np.convolve(den, f)
        else:
            den = np.convolve(self.A_, self.F_[self._input_index(input)])
        return _roots(den)

    def zeros(self, input: str | None = None) -> CArray:  # noqa: A002
        """Discrete zeros (z-plane) of ``B_i``: roots of ``[b0, ..., b_(nb-1)]`` (the delay is not a zero).

        Parameters
        ----------
        input : str, optional
            The input channel (may be omitted for a single-input model).

        Returns
        -------
        ndarray of complex
            Discrete zeros (dimensionless z).
        """
        i = self._input_index(input)
        return _roots(np.trim_zeros(self.B_[i], "f"))

    # -- continuous representations -------------------------------------------------------------------------------
    def to_state_space(self, input: str | None = None, *, negative_real: str = "error",  # noqa: A002
                       intersample: str = "zoh") -> StateSpaceModel:
        """Continuous state-space model whose zero-order-hold (or first-order-hold) discretization is the identified
        ``B_i / (A F_i)``.

        The inverse of the ZOH map: with the discrete realization ``(Ad, Bd, Cd, Dd)``,
        ``logm([[Ad, Bd], [0, I]]) / dt = [[A, B], [0, 0]]``, C and D unchanged. The inverse of the FOH map
        (:meth:`StateSpaceModel.discretize` with ``"foh"``): ``A = logm(Ad) / dt``,
        ``B = (B_now + Ad B_next)^-1 Bd`` and ``D = Dd - C B_next B`` with the hold matrices of ``A``
        (:func:`cappe.systems.statespace.hold_matrices`); fit the discrete model with ``nk = 0`` (a linear input
        reaches the output within the sample).

        Parameters
        ----------
        input : str, optional
            The input channel (may be omitted for a single-input model).
        negative_real : {"error", "reflect"}
            A discrete pole on the negative real axis has no real continuous ZOH equivalent of the same order
            (it maps onto the Nyquist frequency). ``"error"`` raises ModelError; ``"reflect"`` moves such poles to
            ``|z|`` (same decay rate, no oscillation), keeps the static gain and warns IllConditionedWarning.
        intersample : {"zoh", "foh"}
            How the input behaved between the samples of the identification data.
        """
        if intersample not in ("zoh", "foh"):
            msg = f"intersample must be 'zoh' or 'foh' for a continuous equivalent; got {intersample!r}"
            raise DataError(msg)
        if negative_real not in ("error", "reflect"):
            msg = f"negative_real must be 'error' or 'reflect'; got {negative_real!r}"
            raise DataError(msg)
        tf = self.to_discrete_tf(input)
        num = np.asarray(tf.numerator)
        den = np.asarray(tf.denominator)
        poles = tf.poles()
        if poles.size == 0:
            msg = f"the model from {tf.input!r} has no poles (a static gain or FIR model); no continuous equivalent"
            raise ModelError(msg)
        if np.any(np.abs(poles) < _ZERO_TOL):
            msg = (
                f"the model from {tf.input!r} has a pole at z = 0 (a pure delay: nk > 1 or nb + nk - 1 > na); "
                f"it has no finite-order continuous ZOH equivalent"
            )
            raise ModelError(msg)
        negative = (np.abs(poles.imag) <= _REAL_TOL * np.abs(poles)) & (poles.real < 0)
        if negative.any():
            listed = ", ".join(f"{p.real:.4g}" for p in poles[negative])
            if negative_real == "error":
                msg = (
                    f"the model from {tf.input!r} has discrete pole(s) on the negative real axis (z = {listed}); "
                    f"they map to the Nyquist frequency and have no real continuous ZOH equivalent "
                    f"(use negative_real='reflect' to move them to |z|)"
                )
                raise ModelError(msg)
            warnings.warn(
                f"discrete pole(s) z = {listed} of the model from {tf.input!r} moved to |z| for the continuous "
                f"conversion (a negative real pole has no real continuous ZOH equivalent)",
                IllConditionedWarning,
                stacklevel=2,
            )
            dc = np.polyval(num, 1.0) / np.polyval(den, 1.0)
            poles = np.where(negative, np.abs(poles), poles)
            den = np.real(np.poly(poles)).astype(float)
            num = num * (dc * np.polyval(den, 1.0) / np.polyval(num, 1.0)) if np.polyval(num, 1.0) != 0 else num
        ad, bd, cd, dd = _observable_realization(num, den)
        n = ad.shape[0]
        if intersample == "foh":
            return self._from_first_order_hold(tf, ad, bd, cd, dd)
        big = np.zeros((n + 1, n + 1))
        big[:n, :n] = ad
        big[:n, n:] = bd
        big[n, n] = 1.0
        log = np.asarray(sla.logm(big), dtype=complex) / self.dt_
        if np.abs(log.imag).max() > 1e-6 * max(float(np.abs(log.real).max()), 1e-300):
            msg = f"the matrix logarithm of the model from {tf.input!r} is not real; no continuous ZOH equivalent"
            raise ModelError(msg)
        return StateSpaceModel(
            log.real[:n, :n].copy(),
            log.real[:n, n:].copy(),
            np.asarray(cd, dtype=float),
            np.asarray(dd, dtype=float),
            None,
            (),
            (tf.input,),
            (tf.output,),
        )

    def _from_first_order_hold(self, tf: DiscreteTransferFunction, ad: NDArray[np.float64], bd: NDArray[np.float64],
                               cd: NDArray[np.float64], dd: NDArray[np.float64]) -> StateSpaceModel:
        """Continuous model whose FOH discretization is ``(ad, bd, cd, dd)`` (see :meth:`to_state_space`)."""
        from cappe.systems.statespace import hold_matrices

        n = ad.shape[0]
        log = np.asarray(sla.logm(ad), dtype=complex) / self.dt_
        if np.abs(log.imag).max() > 1e-6 * max(float(np.abs(log.real).max()), 1e-300):
            msg = f"the matrix logarithm of the model from {tf.input!r} is not real; no continuous FOH equivalent"
            raise ModelError(msg)
        a = log.real
        phi, b_now, b_next = hold_matrices(a, np.eye(n), self.dt_, "foh")
        b = np.linalg.solve(b_now + phi @ b_next, np.asarray(bd, dtype=float))
        c = np.asarray(cd, dtype=float)
        d = np.asarray(dd, dtype=float) - c @ b_next @ b
        return StateSpaceModel(a, b, c, d, None, (), (tf.input,), (tf.output,))

    def to_transfer_function(
        self,
        input: str | None = None,  # noqa: A002
        *,
        negative_real: str = "error",
        intersample: str = "zoh",
    ) -> TransferFunctionModel:
        """Continuous transfer function (s in rad/s, monic denominator) of the ZOH equivalent.

        See :meth:`to_state_space`. Leading numerator coefficients whose term contributes less than 1e-6 of the
        numerator at the Nyquist frequency are dropped: they are round-off (zeros beyond 1e6 x Nyquist) and carry no
        information a model sampled at ``dt`` could hold.

        Parameters
        ----------
        input : str, optional
            The input channel (may be omitted for a single-input model).
        negative_real : {"error", "reflect"}
            As for :meth:`to_state_space`.
        intersample : {"zoh", "foh"}
            As for :meth:`to_state_space`.

        Returns
        -------
        TransferFunctionModel
        """
        tf = transfer_function(self.to_state_space(input, negative_real=negative_real, intersample=intersample))
        num = np.asarray(tf.numerator, dtype=float)
        omega_n = np.pi / self.dt_
        size = np.abs(num) * omega_n ** np.arange(num.size - 1, -1, -1, dtype=float)
        keep = int(np.argmax(size > 1e-6 * size.max())) if size.max() > 0 else num.size - 1
        return TransferFunctionModel(tuple(float(c) for c in num[keep:]), tf.denominator, tf.input, tf.output)

    def to_zpk(self, input: str | None = None, *, negative_real: str = "error") -> ZeroPoleGainModel:  # noqa: A002
        """Continuous zero-pole-gain form of :meth:`to_transfer_function`.

        Parameters
        ----------
        input : str, optional
            The input channel (may be omitted for a single-input model).
        negative_real : {"error", "reflect"}
            As for :meth:`to_state_space`.

        Returns
        -------
        ZeroPoleGainModel
        """
        return zpk(self.to_transfer_function(input, negative_real=negative_real))

    def continuous_poles(self, input: str | None = None) -> CArray:  # noqa: A002
        """Continuous poles ``log(z) / dt`` (rad/s) of :meth:`poles`; exact for the ZOH map of poles.

        Parameters
        ----------
        input : str, optional
            The input channel; None for the poles of A and every F_i.

        Returns
        -------
        ndarray of complex
            Poles in rad/s (``-inf`` for a pole at z = 0).
        """
        z = self.poles(input)
        with np.errstate(divide="ignore"):
            return np.asarray(np.log(z.astype(complex)) / self.dt_, dtype=complex)

    def modal_parameters(self, input: str | None = None) -> ModalParameters:  # noqa: A002
        """Frequencies (Hz) and damping ratios of the complex continuous pole pairs, ascending.

        Discrete poles on the real axis (non-oscillatory, or at the Nyquist frequency) are not modes.

        Parameters
        ----------
        input : str, optional
            The input channel; None for the poles of A and every F_i.

        Returns
        -------
        ModalParameters
        """
        z = self.poles(input)
        pairs = z[np.abs(z.imag) > _REAL_TOL * np.maximum(np.abs(z), 1e-300)]
        return modal_parameters_from_poles(np.asarray(np.log(pairs) / self.dt_, dtype=complex))


def _observable_realization(num: Array, den: Array) -> tuple[Array, Array, Array, Array]:
    """Observer canonical form of ``num(z) / den(z)`` (equal lengths, monic den), balanced for conditioning."""
    n = den.size - 1
    d = float(num[0])
    rest = num[1:] - d * den[1:]
    a = np.zeros((n, n))
    a[:, 0] = -den[1:]
    a[: n - 1, 1:] = np.eye(n - 1)
    b = rest[:, None].astype(float)
    c = np.zeros((1, n))
    c[0, 0] = 1.0
    # diagonal similarity that equalizes row and column norms (LAPACK gebal, no permutation)
    _, (scale, _) = sla.matrix_balance(a, permute=False, separate=True)
    a = a * scale[None, :] / scale[:, None]
    return a, b / scale[:, None], c * scale[None, :], np.array([[d]])


def _unscaled_covariance(jac: Array, model: PolynomialModel) -> Array:
    """``(J^T J)^-1`` through the SVD of the column-scaled Jacobian; warns when J is rank deficient."""
    d = jac.shape[1]
    if d == 0:
        return np.zeros((0, 0))
    scale = np.sqrt(np.einsum("ij,ij->j", jac, jac))
    scale[scale == 0] = 1.0
    _, s, vt = np.linalg.svd(jac / scale, full_matrices=False)
    tol = s[0] * max(jac.shape) * np.finfo(float).eps
    if s[-1] <= tol:
        warnings.warn(
            f"{model!r}: the parameters are not all identifiable from these data (rank-deficient Jacobian, "
            f"condition number > {1 / (np.finfo(float).eps * max(jac.shape)):.1e}); their standard deviations are inf",
            IllConditionedWarning,
            stacklevel=4,
        )
    with np.errstate(divide="ignore", invalid="ignore"):  # inf * 0 and inf - inf: an unidentifiable direction
        inv_s2 = np.where(s > tol, 1.0 / s**2, np.inf)
        cov = (vt.T * inv_s2) @ vt
    cov = np.where(np.isnan(cov), np.inf, cov)
    return np.asarray(cov / np.outer(scale, scale), dtype=float)


class ARX(PolynomialModel):
    """ARX model ``A(q) y = sum_i B_i(q) u_i + e`` estimated by linear least squares.

    Parameters
    ----------
    na : int
        Order of A (number of past outputs), >= 0.
    nb : int or sequence of int
        Number of B coefficients per input, >= 1.
    nk : int or sequence of int
        Input delay in samples per input, >= 0 (1: no direct feed-through).

    Notes
    -----
    The regression uses samples ``t >= max(na, nk_i + nb_i - 1)`` (no assumption about earlier data), so
    ``loss_`` and ``n_samples_`` refer to those. The solution is the QR least-squares solution of the
    column-scaled regressor matrix; ``covariance_ = noise_variance_ (Phi^T Phi)^-1``.

    Examples
    --------
    >>> import numpy as np, scipy.signal as sig
    >>> from cappe.systems import TimeData
    >>> u = np.random.default_rng(0).standard_normal(500)
    >>> y = sig.lfilter([0, 0.5], [1, -0.8], u)
    >>> model = ARX(na=1, nb=1).fit(TimeData.from_rate(100.0, {"u": u, "y": y}), inputs=["u"], output="y")
    >>> np.round(model.A_, 6), np.round(model.B_[0], 6)
    (array([ 1. , -0.8]), array([0. , 0.5]))
    """

    _iterative = False

    def __init__(self, na: int, nb: int | Sequence[int], nk: int | Sequence[int] = 1) -> None:
        self.na = na
        self.nb = nb
        self.nk = nk

    def _orders(self, n_inputs: int) -> _Orders:
        na = _as_int(self.na, "na", 0, "ARX")
        nb = _per_input(self.nb, "nb", 1, n_inputs, "ARX")
        nk = _per_input(self.nk, "nk", 0, n_inputs, "ARX")
        return _arx_orders(na, nb, nk)

    def _fit_arrays(self, y: Array, u: Array, o: _Orders) -> None:
        p, sol, _ = _arx_fit(y, u, o)
        if sol.rank_deficient:
            warnings.warn(
                f"{self!r}: the regressor matrix is rank deficient (input not persistently exciting or orders too "
                f"high); the minimum-norm solution is returned",
                IllConditionedWarning,
                stacklevel=3,
            )
        self._set_result(p, o, sol.residuals, sol.cov_unscaled, success=True, message="least squares", n_iter=0)


class ARMAX(PolynomialModel):
    """ARMAX model ``A(q) y = sum_i B_i(q) u_i + C(q) e`` by prediction-error minimization.

    Parameters
    ----------
    na, nc : int
        Orders of A (>= 0) and C (>= 1).
    nb, nk : int or sequence of int
        B coefficients (>= 1) and delays (>= 0) per input.
    max_iter : int
        Maximum Levenberg-Marquardt iterations.
    tol : float
        Stop when an iteration lowers the loss by less than ``tol`` (relative) and moves the parameters by less
        than ``sqrt(tol)`` (relative).

    Notes
    -----
    Start: ARX for A and B, then a pseudo-linear regression with the residuals of a high-order ARX model standing
    in for e (Hannan-Rissanen). C is kept stable (roots reflected into the unit circle).

    Examples
    --------
    >>> import numpy as np, scipy.signal as sig
    >>> from cappe.systems import TimeData
    >>> rng = np.random.default_rng(1)
    >>> u, e = rng.standard_normal(2000), 0.1 * rng.standard_normal(2000)
    >>> y = sig.lfilter([0, 1.0], [1, -0.7], u) + sig.lfilter([1, 0.5], [1, -0.7], e)
    >>> model = ARMAX(na=1, nb=1, nc=1).fit(TimeData.from_rate(1.0, {"u": u, "y": y}), inputs="u", output="y")
    >>> bool(abs(model.C_[1] - 0.5) < 0.1), model.success_
    (True, True)
    """

    def __init__(
        self,
        na: int,
        nb: int | Sequence[int],
        nc: int,
        nk: int | Sequence[int] = 1,
        *,
        max_iter: int = 100,
        tol: float = 1e-10,
    ) -> None:
        self.na = na
        self.nb = nb
        self.nc = nc
        self.nk = nk
        self.max_iter = max_iter
        self.tol = tol

    def _orders(self, n_inputs: int) -> _Orders:
        na = _as_int(self.na, "na", 0, "ARMAX")
        nb = _per_input(self.nb, "nb", 1, n_inputs, "ARMAX")
        nc = _as_int(self.nc, "nc", 1, "ARMAX")
        nk = _per_input(self.nk, "nk", 0, n_inputs, "ARMAX")
        _check_iteration(self.max_iter, self.tol, "ARMAX")
        return _Orders(na, nb, nc, 0, (0,) * n_inputs, nk)

    def _start(self, y: Array, u: Array, o: _Orders) -> _Polys:
        order = min(max(o.na + o.nc, max(o.nb)) + 10, max(y.size // (10 * (1 + o.n_inputs)), 1))
        e_hat = _high_order_residuals(y, u, o.nk, order)
        start = max(o.n_lagged, o.nc)
        phi = np.hstack([_arx_regressor(y, u, o, start), _lagged(e_hat, np.arange(1, o.nc + 1), start)])
        sol = _solve_ls(phi, y[start:])
        return _unpack(sol.theta, o)


class OE(PolynomialModel):
    """Output-error model ``y = sum_i B_i(q) / F_i(q) u_i + e`` by prediction-error minimization.

    Parameters
    ----------
    nb, nf, nk : int or sequence of int
        B coefficients (>= 1), F order (>= 0) and delay (>= 0) per input.
    max_iter, tol
        As for :class:`ARMAX`.

    Notes
    -----
    Start: Steiglitz-McBride iterations (ARX on data prefiltered by 1/F) with the largest F order, the F roots
    that matter most per input when the orders differ, then B_i by least squares with F_i fixed.
    Each F_i is kept stable.

    Examples
    --------
    >>> import numpy as np, scipy.signal as sig
    >>> from cappe.systems import TimeData
    >>> u = np.random.default_rng(2).standard_normal(1000)
    >>> y = sig.lfilter([0, 0.2, 0.1], [1, -1.2, 0.5], u)
    >>> model = OE(nb=2, nf=2).fit(TimeData.from_rate(1.0, {"u": u, "y": y}), inputs="u", output="y")
    >>> np.round(model.F_[0], 6)
    array([ 1. , -1.2,  0.5])
    """

    def __init__(
        self,
        nb: int | Sequence[int],
        nf: int | Sequence[int],
        nk: int | Sequence[int] = 1,
        *,
        max_iter: int = 100,
        tol: float = 1e-10,
    ) -> None:
        self.nb = nb
        self.nf = nf
        self.nk = nk
        self.max_iter = max_iter
        self.tol = tol

    def _orders(self, n_inputs: int) -> _Orders:
        nb = _per_input(self.nb, "nb", 1, n_inputs, "OE")
        nf = _per_input(self.nf, "nf", 0, n_inputs, "OE")
        nk = _per_input(self.nk, "nk", 0, n_inputs, "OE")
        _check_iteration(self.max_iter, self.tol, "OE")
        return _Orders(0, nb, 0, 0, nf, nk)


class BoxJenkins(PolynomialModel):
    """Box-Jenkins model ``y = sum_i B_i(q) / F_i(q) u_i + C(q) / D(q) e`` by prediction-error minimization.

    Parameters
    ----------
    nb, nf, nk : int or sequence of int
        B coefficients (>= 1), F order (>= 0) and delay (>= 0) per input.
    nc, nd : int
        Orders of the noise numerator C and denominator D (>= 0).
    max_iter, tol
        As for :class:`ARMAX`.

    Notes
    -----
    Start: the output-error start for B_i and F_i, then C and D from a pseudo-linear regression of the
    output-error residuals on their own past and on high-order AR residuals (Hannan-Rissanen).
    C, D and F_i are kept stable.

    Examples
    --------
    >>> import numpy as np, scipy.signal as sig
    >>> from cappe.systems import TimeData
    >>> rng = np.random.default_rng(3)
    >>> u, e = rng.standard_normal(3000), 0.2 * rng.standard_normal(3000)
    >>> y = sig.lfilter([0, 1.0], [1, -0.5], u) + sig.lfilter([1.0], [1, -0.9], e)
    >>> data = TimeData.from_rate(1.0, {"u": u, "y": y})
    >>> model = BoxJenkins(nb=1, nc=0, nd=1, nf=1).fit(data, inputs="u", output="y")
    >>> bool(abs(model.F_[0][1] + 0.5) < 0.02 and abs(model.D_[1] + 0.9) < 0.03)
    True
    """

    def __init__(
        self,
        nb: int | Sequence[int],
        nc: int,
        nd: int,
        nf: int | Sequence[int],
        nk: int | Sequence[int] = 1,
        *,
        max_iter: int = 100,
        tol: float = 1e-10,
    ) -> None:
        self.nb = nb
        self.nc = nc
        self.nd = nd
        self.nf = nf
        self.nk = nk
        self.max_iter = max_iter
        self.tol = tol

    def _orders(self, n_inputs: int) -> _Orders:
        nb = _per_input(self.nb, "nb", 1, n_inputs, "BoxJenkins")
        nc = _as_int(self.nc, "nc", 0, "BoxJenkins")
        nd = _as_int(self.nd, "nd", 0, "BoxJenkins")
        nf = _per_input(self.nf, "nf", 0, n_inputs, "BoxJenkins")
        nk = _per_input(self.nk, "nk", 0, n_inputs, "BoxJenkins")
        _check_iteration(self.max_iter, self.tol, "BoxJenkins")
        return _Orders(0, nb, nc, nd, nf, nk)

    def _start(self, y: Array, u: Array, o: _Orders) -> _Polys:
        g = _output_error_start(y, u, o)
        v = y - np.sum([_lfilter(b, f, ui) for b, f, ui in zip(g.B, g.F, u, strict=True)], axis=0)
        c, d = _arma_start(v, o.nc, o.nd) if (o.nc or o.nd) else (np.ones(1), np.ones(1))
        return _Polys(np.ones(1), g.B, c, d, g.F)


def _check_iteration(max_iter: Any, tol: Any, owner: str) -> None:
    if isinstance(max_iter, bool) or not isinstance(max_iter, (int, np.integer)) or max_iter < 1:
        msg = f"{owner} max_iter must be an integer >= 1; got {max_iter!r}"
        raise DataError(msg)
    if not (isinstance(tol, (int, float)) and 0 < tol < 1):
        msg = f"{owner} tol must be a number in (0, 1); got {tol!r}"
        raise DataError(msg)
