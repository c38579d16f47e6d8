"""Frequency-domain rational fits: continuous common-denominator models ``N_c(s) / D(s)`` fitted to FRFs.

``method="levy"`` solves the linearized problem ``min sum |w (N(s_i) - H_i D(s_i))|^2`` once (Levy 1959);
``method="sk"`` repeats it with the weights divided by ``|D(s_i)|`` of the previous iterate (Sanathanan and
Koerner 1963), whose fixed point minimizes the output error ``sum |w (N/D - H)|^2`` far better than Levy's
solution, which over-weights high frequencies.

Conditioning. The polynomials are not expanded in powers of s, whose Vandermonde columns are nearly parallel
already at modest orders; they are expanded in polynomials ``psi_k`` orthonormal on the measured frequencies
(scaled by the largest one) under the current weights, built by an Arnoldi (Stieltjes) process in the style of
Brubeck, Nakatsukasa and Trefethen's "Vandermonde with Arnoldi" and of Richardson and Formenti's orthogonal
rational-fraction polynomials. On the imaginary axis ``psi_k(j x) = j^k phi_k(x)`` with ``phi_k`` real and of
parity k, so every ``psi_k`` has real coefficients and obeys a real recurrence ``s psi_k = sum_j G_jk psi_j``;
the poles are the eigenvalues of the comrade matrix built from G (never the roots of an expanded polynomial).
For each FRF column the numerator unknowns are eliminated by a QR factorization, so the common denominator is
the least-squares solution of the stacked reduced equations.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg as sla
from numpy.typing import ArrayLike, NDArray

from cappe.exceptions import ConvergenceWarning, DataError
from cappe.identify._polynomial import ModalParameters, modal_parameters_from_poles
from cappe.systems.frf import FRFData
from cappe.systems.transfer import TransferFunctionModel

__all__ = ["RationalFit", "fit_rational"]

Array = NDArray[np.float64]
CArray = NDArray[np.complex128]


@dataclass(frozen=True)
class RationalFit:
    """Result of :func:`fit_rational`.

    Attributes
    ----------
    transfer_functions : tuple of TransferFunctionModel
        One per FRF column (outputs major, inputs minor), s in rad/s, monic common denominator.
    input_names, output_names : tuple of str
        Channel names of the columns.
    poles : ndarray, shape (n_poles,)
        Common poles in rad/s (eigenvalues of the comrade matrix).
    modes : ModalParameters
        Frequencies (Hz) and damping ratios of the complex pole pairs.
    order : (int, int)
        Numerator and denominator degrees.
    method : str
        ``"levy"`` or ``"sk"``.
    iterations : int
        Linearized solves done (1 for Levy).
    converged : bool
        Whether the SK weights settled within ``tol`` (always True for Levy).
    rms_error : float
        Weighted relative RMS error ``|w (H - H_fit)| / |w H|`` over all columns and frequencies.

    Examples
    --------
    >>> import numpy as np
    >>> f = np.linspace(1.0, 50.0, 100)
    >>> fit = fit_rational((f, 1.0 / (2j * np.pi * f + 10.0)), n_poles=1)
    >>> fit.transfer_function("y1", "u1").denominator, fit.modes.n_modes
    ((1.0, 10.000000000000...), 0)
    """

    transfer_functions: tuple[TransferFunctionModel, ...]
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    poles: CArray
    modes: ModalParameters
    order: tuple[int, int]
    method: str
    iterations: int
    converged: bool
    rms_error: float

    def transfer_function(self, output: str, input: str) -> TransferFunctionModel:  # noqa: A002
        """The fitted transfer function of one output/input pair.

        Parameters
        ----------
        output, input : str
            Output and input channel names.

        Returns
        -------
        TransferFunctionModel

        Raises
        ------
        DataError
            The pair was not fitted.
        """
        for tf in self.transfer_functions:
            if tf.output == output and tf.input == input:
                return tf
        msg = (
            f"no fitted transfer function from input {input!r} to output {output!r}; inputs {list(self.input_names)}, "
            f"outputs {list(self.output_names)}"
        )
        raise DataError(msg)

    def evaluate(self, freq: ArrayLike) -> CArray:
        """Fitted FRFs ``H[out, in, freq]`` at ``freq`` (Hz).

        Parameters
        ----------
        freq : array_like, shape (n_freq,)
            Frequencies in Hz.

        Returns
        -------
        ndarray of complex, shape (n_out, n_in, n_freq)
            In the units of the fitted FRFs.
        """
        f = np.atleast_1d(np.asarray(freq, dtype=float))
        s = 2j * np.pi * f
        out = np.empty((len(self.output_names), len(self.input_names), f.size), dtype=complex)
        n_in = len(self.input_names)
        for k, tf in enumerate(self.transfer_functions):
            out[k // n_in, k % n_in] = tf.evaluate(s)
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "method": self.method,
            "order": list(self.order),
            "iterations": self.iterations,
            "converged": self.converged,
            "rms_error": self.rms_error,
            "poles": [[float(p.real), float(p.imag)] for p in self.poles],
            "modes": self.modes.to_dict()["modes"],
            "transfer_functions": [tf.to_dict() for tf in self.transfer_functions],
        }


@dataclass(frozen=True)
class _Basis:
    """Polynomials psi_0..psi_K orthonormal on the scaled frequencies x_i under weights v_i."""

    values: CArray  # (n_f, K + 1): psi_k(j x_i)
    g: Array  # (K + 1, K): s psi_k = sum_j g[j, k] psi_j


def _basis(x: Array, v: Array, degree: int) -> _Basis:
    """Parity-preserving Arnoldi on the symmetric point set +-x_i (see the module notes)."""
    n_f = x.size
    phi = np.zeros((n_f, degree + 1))
    h = np.zeros((degree + 1, max(degree, 1)))
    v2 = v**2
    phi[:, 0] = 1.0 / np.sqrt(v2.sum())
    for k in range(degree):
        q = x * phi[:, k]
        same = list(range(k - 1, -1, -2))  # previous polynomials of parity k + 1
        for _ in range(2):  # orthogonalize twice (Kahan's "twice is enough")
            for j in same:
                c = float(np.sum(v2 * q * phi[:, j]))
                h[j, k] += c
                q = q - c * phi[:, j]
        norm = float(np.sqrt(np.sum(v2 * q * q)))
        if norm == 0.0:
            msg = f"too few distinct frequencies for a degree-{degree} polynomial basis"
            raise DataError(msg)
        h[k + 1, k] = norm
        phi[:, k + 1] = q / norm
    kk = np.arange(degree + 1)
    values = phi * (1j**kk)[None, :]
    g = np.zeros_like(h)
    for k in range(degree):
        for j in range(k + 2):
            if (k + 1 - j) % 2 == 0:
                g[j, k] = h[j, k] * (-1.0) ** ((k + 1 - j) // 2)
    return _Basis(np.asarray(values, dtype=complex), g)


def _monomials_from(c0: float, g: Array, degree: int) -> list[Array]:
    out = [np.array([c0])]
    for k in range(degree):
        nxt = np.zeros(k + 2)
        nxt[1:] += out[k]  # s * psi_k
        for j in range(k + 1):
            nxt[: out[j].size] -= g[j, k] * out[j]
        out.append(nxt / g[k + 1, k])
    return out


def _expand(coef: Array, mono: list[Array], degree: int) -> Array:
    """Ascending monomial coefficients of ``sum_k coef[k] psi_k``, padded to ``degree + 1``."""
    out = np.zeros(degree + 1)
    for k, c in enumerate(coef):
        out[: mono[k].size] += c * mono[k]
    return out


def _comrade_roots(coef: Array, g: Array) -> CArray:
    """Roots of ``sum_k coef[k] psi_k`` (degree n = coef.size - 1, coef[n] != 0) as comrade-matrix eigenvalues."""
    n = coef.size - 1
    if n == 0:
        return np.zeros(0, dtype=complex)
    mt = g[:n, :n].T.copy()
    mt[n - 1, :] -= g[n, n - 1] * coef[:n] / coef[n]
    return np.asarray(np.linalg.eigvals(mt), dtype=complex)


def _realify(m: CArray) -> Array:
    return np.concatenate([m.real, m.imag], axis=0)


def _parse(frf: FRFData | tuple[ArrayLike, ArrayLike]) -> tuple[Array, CArray, tuple[str, ...], tuple[str, ...]]:
    if isinstance(frf, FRFData):
        freq = np.asarray(frf.freq, dtype=float)
        h = np.asarray(frf.H, dtype=complex)
        ins, outs = tuple(frf.input_names), tuple(frf.output_names)
    else:
        try:
            f_raw, h_raw = frf
        except (TypeError, ValueError) as exc:
            msg = f"frf must be FRFData or a pair (freq, H); got {type(frf).__name__}"
            raise DataError(msg) from exc
        freq = np.asarray(f_raw, dtype=float)
        h = np.asarray(h_raw, dtype=complex)
        if h.ndim == 1:
            h = h[None, None, :]
        elif h.ndim == 2:
            h = h[:, None, :]
        elif h.ndim != 3:
            msg = f"H must have shape (n_freq,), (n_columns, n_freq) or (n_out, n_in, n_freq); got {h.shape}"
            raise DataError(msg)
        ins = tuple(f"u{i + 1}" for i in range(h.shape[1]))
        outs = tuple(f"y{o + 1}" for o in range(h.shape[0]))
    if freq.ndim != 1 or freq.size != h.shape[-1]:
        msg = f"freq must be 1-D with one entry per FRF sample ({h.shape[-1]}); got shape {freq.shape}"
        raise DataError(msg)
    if not np.all(np.isfinite(freq)) or np.any(freq < 0):
        msg = "freq must hold finite frequencies >= 0 Hz"
        raise DataError(msg)
    if np.unique(freq).size != freq.size:
        msg = "freq must not repeat a frequency"
        raise DataError(msg)
    bad = ~np.isfinite(h)
    if bad.any():
        o, i, k = (int(a[0]) for a in np.nonzero(bad))
        msg = f"H has non-finite values, first at output {outs[o]!r}, input {ins[i]!r}, {freq[k]:g} Hz"
        raise DataError(msg)
    return freq, h, ins, outs


def fit_rational(
    frf: FRFData | tuple[ArrayLike, ArrayLike],
    *,
    n_poles: int | None = None,
    order: tuple[int, int] | None = None,
    method: str = "sk",
    weights: ArrayLike | None = None,
    iterations: int = 30,
    tol: float = 1e-10,
) -> RationalFit:
    """Fit continuous-time rational models with one common denominator to FRFs.

    Parameters
    ----------
    frf : FRFData or (freq, H)
        FRFs ``H[out, in, freq]`` (freq in Hz). A pair may give H as (n_freq,) or (n_columns, n_freq) too;
        its columns are then named ``u1``, ``y1``, ``y2`` ...
    n_poles : int, optional
        Number of poles; the numerators get degree ``n_poles - 1`` (strictly proper, as MATLAB's ``tfest``).
    order : (int, int), optional
        Numerator and denominator degrees instead of ``n_poles`` (numerator degree <= denominator degree).
    method : {"sk", "levy"}
        Sanathanan-Koerner iterations (default) or Levy's single linearized solve.
    weights : array_like, optional
        Non-negative weights broadcastable to H's shape (e.g. coherence); default 1.
    iterations : int
        Maximum linearized solves for ``"sk"``.
    tol : float
        SK stops when the normalized weights ``1/|D(s_i)|`` change by less than ``tol`` (relative RMS).

    Returns
    -------
    RationalFit

    Raises
    ------
    DataError
        Bad shapes, non-finite data, invalid orders or too few frequencies for the unknowns.

    Examples
    --------
    >>> import numpy as np
    >>> f = np.linspace(1.0, 200.0, 400)
    >>> s = 2j * np.pi * f
    >>> h = 1.0 / (s**2 + 2 * 0.02 * 600.0 * s + 600.0**2)
    >>> fit = fit_rational((f, h), order=(0, 2))
    >>> [round(c, 6) for c in fit.transfer_functions[0].denominator]
    [1.0, 24.0, 360000.0]
    """
    freq, h, ins, outs = _parse(frf)
    n_num, n_den = _orders(n_poles, order)
    if method not in ("sk", "levy"):
        msg = f"method must be 'sk' or 'levy'; got {method!r}"
        raise DataError(msg)
    if isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer)) or iterations < 1:
        msg = f"iterations must be an integer >= 1; got {iterations!r}"
        raise DataError(msg)
    if not (isinstance(tol, (int, float)) and 0 < tol < 1):
        msg = f"tol must be a number in (0, 1); got {tol!r}"
        raise DataError(msg)
    w = _weights(weights, h.shape)
    n_out, n_in, n_f = h.shape
    cols = n_out * n_in
    hc = h.reshape(cols, n_f)
    wc = w.reshape(cols, n_f)
    unknowns = cols * (n_num + 1) + n_den
    equations = int(np.sum(np.where(freq > 0, 2, 1)) * cols)
    if equations <= unknowns:
        msg = (
            f"too few frequencies: {n_f} complex FRF samples in {cols} column(s) give {equations} real equations for "
            f"{unknowns} unknowns (orders {n_num}/{n_den}); need more than {unknowns}"
        )
        raise DataError(msg)
    scale = float(2 * np.pi * freq.max()) if freq.max() > 0 else 1.0
    x = 2 * np.pi * freq / scale
    degree = max(n_num, n_den)

    v = np.full(n_f, 1.0 / np.sqrt(n_f))  # weights 1 / |D| of the last iterate, unit norm; Levy: uniform
    converged = method == "levy"
    max_solves = 1 if method == "levy" else iterations
    for n_iter in range(1, max_solves + 1):  # noqa: B007
        basis = _basis(x, v, degree)
        coef = _denominator(basis, hc, wc * v[None, :], n_num, n_den)
        d_val = basis.values[:, : n_den + 1] @ coef
        v_new = 1.0 / np.maximum(np.abs(d_val), 1e-300)
        v_new /= np.linalg.norm(v_new)
        change = float(np.linalg.norm(v_new - v))
        v = v_new
        if method == "sk" and change < tol:
            converged = True
            break
    if method == "sk" and not converged:
        warnings.warn(
            f"Sanathanan-Koerner iterations did not settle in {iterations} solves (last relative change of the "
            f"weights {change:.2g} > tol {tol:g}); the fit may be poor",
            ConvergenceWarning,
            stacklevel=2,
        )
    # final numerators: least squares with the denominator fixed, weights w / |D| for SK (the output error)
    if method == "sk":
        basis = _basis(x, v, degree)
        coef = _denominator(basis, hc, wc * v[None, :], n_num, n_den)
        d_val = basis.values[:, : n_den + 1] @ coef
        row_w = 1.0 / np.abs(d_val)
    else:
        d_val = basis.values[:, : n_den + 1] @ coef
        row_w = np.ones(n_f)
    num_coefs = []
    for c in range(cols):
        a = basis.values[:, : n_num + 1] * (wc[c] * row_w)[:, None]
        rhs = hc[c] * d_val * wc[c] * row_w
        sol, *_ = sla.lstsq(_realify(a), _realify(rhs[:, None])[:, 0])
        num_coefs.append(np.asarray(sol, dtype=float))
    poles = scale * _comrade_roots(coef, basis.g)
    poles = poles[np.argsort(np.abs(poles), kind="stable")]

    mono = _monomials_from(float(basis.values[0, 0].real), basis.g, degree)
    den_asc = _expand(coef, mono, degree)
    powers = scale ** -np.arange(degree + 1, dtype=float)  # coefficient of s^m is that of (s/scale)^m / scale^m
    den_asc = (den_asc * powers)[: n_den + 1]
    lead = den_asc[-1]
    tfs = []
    fitted = np.empty_like(hc)
    for c in range(cols):
        nc = num_coefs[c]
        num_asc = _expand(nc, mono, degree)
        num_asc = (num_asc * powers)[: n_num + 1]
        num = tuple(float(a) for a in (num_asc / lead)[::-1])
        den = tuple(float(a) for a in (den_asc / lead)[::-1])
        tf = TransferFunctionModel(num, den, ins[c % n_in], outs[c // n_in], "float")
        tfs.append(tf)
        fitted[c] = (basis.values[:, : n_num + 1] @ nc) / d_val
    err = float(np.linalg.norm(wc * (hc - fitted)) / max(float(np.linalg.norm(wc * hc)), 1e-300))
    return RationalFit(
        tuple(tfs),
        ins,
        outs,
        np.asarray(poles, dtype=complex),
        modal_parameters_from_poles(poles),
        (n_num, n_den),
        method,
        n_iter + (1 if method == "sk" else 0),
        converged,
        err,
    )


def _denominator(basis: _Basis, hc: CArray, wv: Array, n_num: int, n_den: int) -> Array:
    """Common denominator coefficients (psi basis, last one 1) from the stacked per-column reduced equations."""
    reduced_a = []
    reduced_b = []
    p_vals = basis.values[:, : n_num + 1]
    q_vals = basis.values[:, :n_den]
    last = basis.values[:, n_den]
    for c in range(hc.shape[0]):
        wc = wv[c][:, None]
        a_num = _realify(p_vals * wc)
        a_den = _realify(-hc[c][:, None] * q_vals * wc)
        rhs = _realify((hc[c] * last)[:, None] * wc)
        block = np.hstack([a_num, a_den, rhs])
        r = sla.qr(block, mode="r")[0]
        k = n_num + 1
        rows = r[k : k + n_den + 1]
        reduced_a.append(rows[:, k : k + n_den])
        reduced_b.append(rows[:, -1])
    a = np.vstack(reduced_a)
    b = np.concatenate(reduced_b)
    col = np.sqrt(np.einsum("ij,ij->j", a, a))
    col[col == 0] = 1.0
    sol, *_ = sla.lstsq(a / col, b)
    return np.concatenate([np.asarray(sol, dtype=float) / col, [1.0]])


def _orders(n_poles: int | None, order: tuple[int, int] | Sequence[int] | None) -> tuple[int, int]:
    if (n_poles is None) == (order is None):
        msg = (
            f"give exactly one of n_poles and order=(num_degree, den_degree); got n_poles={n_poles!r}, order={order!r}"
        )
        raise DataError(msg)
    if n_poles is not None:
        if isinstance(n_poles, bool) or not isinstance(n_poles, (int, np.integer)) or n_poles < 1:
            msg = f"n_poles must be an integer >= 1; got {n_poles!r}"
            raise DataError(msg)
        return int(n_poles) - 1, int(n_poles)
    try:
        n_num, n_den = (int(o) for o in order)  # type: ignore[union-attr]
    except (TypeError, ValueError) as exc:
        msg = f"order must be a pair (num_degree, den_degree) of integers; got {order!r}"
        raise DataError(msg) from exc
    if not (n_den >= 1 and 0 <= n_num <= n_den):
        msg = f"order must satisfy 0 <= num_degree <= den_degree and den_degree >= 1; got {order!r}"
        raise DataError(msg)
    return n_num, n_den


def _weights(weights: ArrayLike | None, shape: tuple[int, ...]) -> Array:
    if weights is None:
        return np.ones(shape)
    w = np.asarray(weights, dtype=float)
    try:
        w = np.broadcast_to(w, shape).copy()
    except ValueError as exc:
        msg = f"weights of shape {w.shape} do not broadcast to the FRF shape {shape}"
        raise DataError(msg) from exc
    if not np.all(np.isfinite(w)) or np.any(w < 0) or not np.any(w > 0):
        msg = "weights must be finite, >= 0 and not all zero"
        raise DataError(msg)
    return w
