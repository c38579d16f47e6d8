"""The FRF of a matrix model from its dynamic stiffness, with or without its parameter derivatives: the one kernel
behind :meth:`MechanicalSystem.frf`, the validation's receptances, the one-step FRF estimator and the monitor's
stiffness-factor fit.

``Z(omega) = K + iH + i omega (C + G) - omega^2 M`` is assembled for a batch of frequency lines and solved only for
the wanted input columns, ``X = Z^-1 B`` (one batched LAPACK call over the lines); the FRF is ``H = S X`` times
``(i omega)^order`` for velocity and acceleration outputs. The derivative with respect to a parameter is
``dH/dp = -L (dZ/dp) X`` with ``L = S Z^-1``: the same factorization serves both sides (one batched inverse where
the wanted rows and columns are a large share of the DOFs, two batched solves otherwise), and a stiffness
derivative, a sum of a few element terms ``k h h^T``, is applied through its low-rank factor ``U E U^T``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["FRFLines", "dynamic_stiffness", "frf_lines", "response_derivatives"]

Array = NDArray[np.float64]
CArray = NDArray[np.complex128]


def dynamic_stiffness(matrices: Mapping[str, NDArray[Any]], omega: Array) -> CArray:
    """``Z = K + iH + i omega (C + G) - omega^2 M`` of every line, real and imaginary parts written in place.

    Parameters
    ----------
    matrices : mapping of str to ndarray, shape (n, n)
        ``"M"``, ``"C"``, ``"K"``, ``"G"``, ``"H"`` (real).
    omega : ndarray, shape (n_lines,)
        Angular frequencies in rad/s.

    Returns
    -------
    ndarray of complex, shape (n_lines, n, n)

    Examples
    --------
    >>> one = {name: np.array([[v]]) for name, v in zip("MCKGH", (2.0, 3.0, 5.0, 0.0, 1.0), strict=True)}
    >>> dynamic_stiffness(one, np.array([1.0]))[0, 0, 0]
    np.complex128(3+4j)
    """
    w = np.asarray(omega, dtype=float)
    k = matrices["K"]
    z = np.empty((w.size, *k.shape), dtype=complex)
    np.multiply(-(w**2)[:, None, None], matrices["M"], out=z.real)
    z.real += k
    np.multiply(w[:, None, None], matrices["C"] + matrices["G"], out=z.imag)
    z.imag += matrices["H"]
    return z


@dataclass(frozen=True)
class FRFLines:
    """What :func:`frf_lines` computes, line-major.

    Attributes
    ----------
    H : ndarray of complex, shape (n_lines, n_out, n_in)
        The FRFs, in the outputs' units per input unit.
    X : ndarray of complex, shape (n_lines, n, n_in)
        ``Z^-1 B``: the displacements of every DOF under each input.
    L : ndarray of complex, shape (n_lines, n_out, n) or None
        ``S Z^-1`` (displacement level): computed only with derivatives.
    dH : ndarray of complex, shape (n_derivatives, n_lines, n_out, n_in)
        ``dH/dp`` of each derivative given (empty without).
    singular : ndarray of bool, shape (n_lines,)
        Lines where ``Z`` is singular (``X`` and ``H`` are inf there); only with ``singular="inf"``.
    """

    H: CArray
    X: CArray
    L: CArray | None
    dH: CArray
    singular: NDArray[np.bool_]


def _solve(z: CArray, rhs: CArray, singular: str) -> tuple[CArray, NDArray[np.bool_]]:
    """``z^-1 rhs`` line by line in one batched call; a singular line raises, or (``singular="inf"``) is inf."""
    bad = np.zeros(z.shape[0], dtype=bool)
    try:
        return np.asarray(np.linalg.solve(z, np.broadcast_to(rhs, (z.shape[0], *rhs.shape))), dtype=complex), bad
    except np.linalg.LinAlgError:
        if singular != "inf":
            raise
    x = np.empty((z.shape[0], *rhs.shape), dtype=complex)
    for k in range(z.shape[0]):
        try:
            x[k] = np.linalg.solve(z[k], rhs)
        except np.linalg.LinAlgError:
            x[k] = np.inf
            bad[k] = True
    return x, bad


def frf_lines(
    matrices: Mapping[str, NDArray[Any]],
    omega: Array,
    inputs: NDArray[Any],
    outputs: NDArray[Any],
    *,
    orders: Sequence[int] | NDArray[np.integer[Any]] | None = None,
    derivatives: Mapping[str, NDArray[Any]] | None = None,
    left: bool = False,
    singular: str = "raise",
) -> FRFLines:
    """FRFs ``H[line, out, in] = (i omega)^order S Z^-1 B`` and, optionally, their derivatives ``-L (dZ/dp) X``.

    Parameters
    ----------
    matrices : mapping of str to ndarray, shape (n, n)
        ``"M"``, ``"C"``, ``"K"``, ``"G"``, ``"H"`` (real).
    omega : ndarray, shape (n_lines,)
        Angular frequencies in rad/s.
    inputs : ndarray, shape (n, n_in)
        The wanted input columns of ``B`` (only these are solved for).
    outputs : ndarray, shape (n_out, n)
        The wanted output rows of ``S`` (displacement level).
    orders : sequence of int, shape (n_out,), optional
        Time-derivative order of each output (0 displacement, 1 velocity, 2 acceleration); default 0.
    derivatives : mapping of str to ndarray, shape (n_derivatives, n, n), optional
        ``dM``, ``dC``, ``dK``, ``dG``, ``dH`` under the keys ``"M"``, ``"C"``, ``"K"``, ``"G"``, ``"H"`` (a missing
        key is zero), one slice per parameter (or combination of parameters) to differentiate by.
    left : bool
        Also compute ``L = S Z^-1`` (always computed with ``derivatives``), e.g. for :func:`response_derivatives`
        at the same point later.
    singular : {"raise", "inf"}
        At a line where ``Z`` is singular: raise ``numpy.linalg.LinAlgError``, or set ``X`` and ``H`` to inf there.

    Returns
    -------
    FRFLines

    Examples
    --------
    One mass on a spring (m = 2 kg, k = 5 N/m, c = 3 N s/m): ``H = 1 / (k - omega^2 m + i omega c)``.

    >>> one = {name: np.array([[v]]) for name, v in zip("MCKGH", (2.0, 3.0, 5.0, 0.0, 0.0), strict=True)}
    >>> out = frf_lines(one, np.array([1.0]), np.eye(1), np.eye(1), derivatives={"K": np.ones((1, 1, 1))})
    >>> bool(np.isclose(out.H[0, 0, 0], 1 / (3 + 3j))), bool(np.isclose(out.dH[0, 0, 0, 0], -1 / (3 + 3j) ** 2))
    (True, True)
    """
    w = np.asarray(omega, dtype=float)
    z = dynamic_stiffness(matrices, w)
    b = np.ascontiguousarray(inputs, dtype=complex)  # a transposed B in Fortran order slows the solve by half
    s = np.asarray(outputs)
    n = z.shape[-1]
    if derivatives is None and not left:
        x, bad = _solve(z, b, singular)
        lt = None
    elif s.shape[0] + b.shape[1] >= n / 3:
        # one batched inverse serves both sides: cheaper than two solves where the wanted rows and columns are many
        # (11-DOF spindle, 5 of them: 7.5 ms against 10.7 ms for 400 lines; 30 DOFs, 8 of them: 37 against 26 ms)
        z_inv = np.linalg.inv(z)
        x, bad = z_inv @ b, np.zeros(w.size, dtype=bool)
        lt = s.astype(complex) @ z_inv
    else:
        x, bad = _solve(z, b, singular)
        lt = np.swapaxes(_solve(np.swapaxes(z, 1, 2), s.T.astype(complex), "raise")[0], 1, 2)
    h = _project(s, x)
    scale = None
    if orders is not None and np.any(np.asarray(orders)):
        scale = (1j * w)[:, None] ** np.asarray(orders)[None, :]  # (n_lines, n_out)
        h = h * scale[:, :, None]
    dh = np.zeros((0, *h.shape), dtype=complex)
    if derivatives is not None and lt is not None:
        dh = response_derivatives(derivatives, w, x, lt, orders=orders)
    return FRFLines(h, x, lt, dh, bad)


def _project(s: NDArray[Any], x: CArray) -> CArray:
    """``S X`` of every line; a real ``S`` multiplies the interleaved real and imaginary parts of ``X`` (a real @
    complex matmul takes numpy's slow non-BLAS loop)."""
    if np.iscomplexobj(s):
        return np.asarray(s @ x, dtype=complex)
    out = np.empty((x.shape[0], s.shape[0], x.shape[2]), dtype=complex)
    np.matmul(np.ascontiguousarray(s, dtype=float), np.ascontiguousarray(x).view(np.float64),
              out=out.view(np.float64))
    return out


def response_derivatives(
    derivatives: Mapping[str, NDArray[Any]],
    omega: Array,
    x: CArray,
    lt: CArray,
    *,
    orders: Sequence[int] | NDArray[np.integer[Any]] | None = None,
) -> CArray:
    """``dH/dp = -(i omega)^order L (dZ/dp) X`` of every derivative slice, from ``X`` and ``L`` of :func:`frf_lines`.

    Parameters
    ----------
    derivatives : mapping of str to ndarray, shape (n_derivatives, n, n)
        ``dM``, ``dC``, ``dK``, ``dG``, ``dH`` under ``"M"``, ``"C"``, ``"K"``, ``"G"``, ``"H"`` (missing: zero).
    omega : ndarray, shape (n_lines,)
        Angular frequencies in rad/s.
    x : ndarray of complex, shape (n_lines, n, n_in)
        ``Z^-1 B`` (:attr:`FRFLines.X`).
    lt : ndarray of complex, shape (n_lines, n_out, n)
        ``S Z^-1`` (:attr:`FRFLines.L`).
    orders : sequence of int, shape (n_out,), optional
        Time-derivative order of each output; default 0.

    Returns
    -------
    ndarray of complex, shape (n_derivatives, n_lines, n_out, n_in)

    Examples
    --------
    >>> one = {name: np.array([[v]]) for name, v in zip("MCKGH", (2.0, 3.0, 5.0, 0.0, 0.0), strict=True)}
    >>> at = frf_lines(one, np.array([1.0]), np.eye(1), np.eye(1), left=True)
    >>> bool(np.isclose(response_derivatives({"M": np.ones((1, 1, 1))}, np.array([1.0]), at.X, at.L)[0, 0, 0, 0],
    ...                 1 / (3 + 3j) ** 2))  # dH/dm = omega^2 H^2
    True
    """
    w = np.asarray(omega, dtype=float)
    n_d = max((np.asarray(v).shape[0] for v in derivatives.values()), default=0)
    out = np.empty((n_d, w.size, lt.shape[1], x.shape[2]), dtype=complex)
    for d in range(n_d):
        term = np.zeros((w.size, lt.shape[1], x.shape[2]), dtype=complex)
        for name, factor in (("K", 1.0 + 0j), ("H", 1j)):
            if name not in derivatives:
                continue
            dmat = derivatives[name][d]
            if np.any(dmat) and not np.array_equal(dmat, dmat.T):
                term += factor * (lt @ dmat @ x)
            elif np.any(dmat):
                # a stiffness derivative is a few element terms k h h^T: its low-rank factor U E U^T makes
                # L dK X two thin products instead of two n x n ones per line (5x faster on the 11-DOF spindle)
                e, u = np.linalg.eigh(dmat)
                keep = np.abs(e) > 1e-12 * np.max(np.abs(e))
                lu, ux = lt @ u[:, keep], u[:, keep].T @ x
                term += factor * ((lu * e[keep]) @ ux)
        for name, factor_w in (("C", 1j * w), ("G", 1j * w), ("M", -(w**2) + 0j)):
            if name not in derivatives:
                continue
            dmat = derivatives[name][d]
            if np.any(dmat):
                term += factor_w[:, None, None] * (lt @ dmat @ x)
        out[d] = -term
    if orders is not None and np.any(np.asarray(orders)):
        out = out * ((1j * w)[:, None] ** np.asarray(orders)[None, :])[None, :, :, None]
    return out
