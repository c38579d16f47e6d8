"""Craig-Bampton reduction of full sparse FE matrices.

The reduced coordinates are the interface (boundary) DOFs, kept physical, and the amplitudes of the
fixed-interface normal modes up to ``multiple`` times the frequency band of interest::

    x = T [x_b; q],   T = [[I, 0], [Psi, Phi]]   (rows: boundary, interior),
    Psi = -K_ii^-1 K_ib   (static constraint modes),   K_ii Phi = M_ii Phi diag(omega^2)   (eigsh, shift-invert).

``K_r = T^T K T`` and ``M_r = T^T M T``; ``T`` is the recovery matrix that gives every DOF of the full model,
sensors on interior nodes included.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike, NDArray

from cappe.exceptions import ModelError

__all__ = ["ReducedModel", "craig_bampton"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ReducedModel:
    """A Craig-Bampton model.

    Attributes
    ----------
    mass, stiffness : ndarray, shape (n_b + n_q, n_b + n_q)
        Reduced matrices: boundary DOFs first (in the order given), then the fixed-interface modal amplitudes.
    boundary : ndarray of int, shape (n_b,)
        Rows of the full model kept as boundary DOFs.
    recovery : ndarray, shape (n_full, n_b + n_q)
        ``x_full = recovery @ x_reduced``.
    fixed_interface_freq : ndarray, shape (n_q,)
        Frequencies of the kept fixed-interface modes (Hz).
    """

    mass: Array
    stiffness: Array
    boundary: NDArray[np.intp]
    recovery: Array
    fixed_interface_freq: Array

    @property
    def n_modes(self) -> int:
        return int(self.fixed_interface_freq.size)


def craig_bampton(stiffness: ArrayLike | sps.sparray, mass: ArrayLike | sps.sparray, boundary: ArrayLike, *,
                  band: float | None = None, multiple: float = 1.5, n_modes: int | None = None) -> ReducedModel:
    """Reduce full (sparse) FE matrices by Craig-Bampton.

    Parameters
    ----------
    stiffness, mass : sparse or dense matrix, shape (n, n)
        Full FE matrices (N/m, kg), symmetric; ``K_ii`` must be non-singular (the boundary DOFs hold the body's
        rigid-body motions).
    boundary : array_like of int
        Rows kept as boundary (interface) DOFs, in the order they take in the reduced model.
    band : float, optional
        Upper frequency of interest (Hz): the fixed-interface modes up to ``multiple * band`` are kept.
    multiple : float
        Cut-off as a multiple of ``band`` (1.5 to 2 is the usual rule).
    n_modes : int, optional
        Keep this many fixed-interface modes instead (one of ``band`` and ``n_modes`` is required).

    Returns
    -------
    ReducedModel

    Raises
    ------
    ModelError
        Bad arguments, or ``K_ii`` is singular.

    Examples
    --------
    >>> import numpy as np
    >>> k = np.array([[2.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 1.0]]) * 1e4
    >>> r = craig_bampton(k, np.eye(3), [0], n_modes=1)
    >>> r.stiffness.shape
    (2, 2)
    """
    k = sps.csc_array(stiffness, dtype=float)
    m = sps.csc_array(mass, dtype=float)
    n = k.shape[0]
    if k.shape != (n, n) or m.shape != (n, n):
        msg = f"stiffness and mass must be square and of the same order; got {k.shape} and {m.shape}"
        raise ModelError(msg)
    b = np.asarray(boundary, dtype=np.intp).ravel()
    if b.size == 0 or b.min() < 0 or b.max() >= n or np.unique(b).size != b.size:
        msg = f"boundary must be distinct rows in [0, {n}); got {b.size} rows"
        raise ModelError(msg)
    if (band is None) == (n_modes is None):
        msg = "give either band (Hz) or n_modes"
        raise ModelError(msg)
    if band is not None and not (math.isfinite(band) and band > 0 and multiple >= 1):
        msg = f"band must be > 0 Hz and multiple >= 1; got {band!r} and {multiple!r}"
        raise ModelError(msg)
    interior = np.setdiff1d(np.arange(n), b)
    k_ii, k_ib = k[interior][:, interior], k[interior][:, b]
    m_ii = m[interior][:, interior]
    try:
        lu = spla.splu(sps.csc_matrix(k_ii))
    except RuntimeError as exc:
        msg = "the interior stiffness K_ii is singular: the boundary DOFs must hold the body's rigid-body motions"
        raise ModelError(msg) from exc
    psi = -lu.solve(k_ib.toarray())
    if not np.isfinite(psi).all():
        msg = "the interior stiffness K_ii is singular: the boundary DOFs must hold the body's rigid-body motions"
        raise ModelError(msg)
    lam, phi = _fixed_interface_modes(k_ii, m_ii, lu, band, multiple, n_modes)
    # a rigid-body motion left to the interior shows as a zero fixed-interface eigenvalue (splu may not notice a
    # matrix singular only to round-off); the scale is the largest diagonal ratio, about the largest omega^2
    scale = float((k_ii.diagonal() / np.maximum(m_ii.diagonal(), 1e-300)).max())
    if lam.size and lam[0] <= 1e-9 * scale:
        msg = "the interior stiffness K_ii is singular: the boundary DOFs must hold the body's rigid-body motions"
        raise ModelError(msg)
    t = np.zeros((n, b.size + lam.size))
    t[b, np.arange(b.size)] = 1.0
    t[np.ix_(interior, np.arange(b.size))] = psi
    t[np.ix_(interior, b.size + np.arange(lam.size))] = phi
    k_r = t.T @ (k @ t)
    m_r = t.T @ (m @ t)
    return ReducedModel(0.5 * (m_r + m_r.T), 0.5 * (k_r + k_r.T), b, t, np.sqrt(lam) / (2 * np.pi))


def _fixed_interface_modes(k_ii: sps.csc_array, m_ii: sps.csc_array, lu: spla.SuperLU, band: float | None,
                           multiple: float, n_modes: int | None) -> tuple[Array, Array]:
    """Eigenpairs of ``K_ii phi = lambda M_ii phi`` (mass-normalized), lowest first: ``n_modes`` of them, or all
    up to ``(2 pi multiple band)^2`` (asked for in growing numbers until the last exceeds the cut-off)."""
    size = k_ii.shape[0]
    op = spla.LinearOperator(k_ii.shape, matvec=lu.solve, dtype=float)  # shift-invert at sigma = 0
    cut = None if band is None else (2 * np.pi * multiple * band) ** 2
    want = n_modes if n_modes is not None else 12
    while True:
        want = min(want, size)
        if want == 0:
            return np.zeros(0), np.zeros((size, 0))
        if want >= size - 1 or size <= 200:
            import scipy.linalg

            lam, phi = scipy.linalg.eigh(k_ii.toarray(), m_ii.toarray())
        else:
            # a fixed start vector: ARPACK's own is random, and the reduced matrices of one model then differed
            # from load to load (other signs and mixes of the modal coordinates)
            start = np.random.default_rng(0).standard_normal(size)
            lam, phi = spla.eigsh(k_ii, k=want, M=m_ii, sigma=0.0, which="LM", OPinv=op, v0=start)
        order = np.argsort(lam)
        lam, phi = lam[order], phi[:, order]
        if cut is None:
            lam, phi = lam[:want], phi[:, :want]
            break
        if lam[-1] > cut or lam.size >= size:
            keep = lam <= cut
            lam, phi = lam[keep], phi[:, keep]
            break
        want *= 2
    norms = np.sqrt(np.einsum("ij,ij->j", phi, m_ii @ phi))
    # each mode's sign fixed by its largest entry (positive): the same coordinates from either eigensolver
    largest = phi[np.argmax(np.abs(phi), axis=0), np.arange(phi.shape[1])]
    return lam, phi * (np.where(largest < 0, -1.0, 1.0) / norms)
