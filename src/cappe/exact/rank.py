"""Exact and floating-point ranks; Sain-Massey invertibility; controllability and observability."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import sympy as sp
from sympy.polys.matrices import DomainMatrix

from cappe.exact.rational import ExactStateSpace

__all__ = [
    "InvertibilityResult",
    "PBHRanks",
    "controllability_rank",
    "exact_rank",
    "float_rank",
    "invertibility_matrix",
    "observability_rank",
    "pbh_ranks",
    "sain_massey",
]


def exact_rank(matrix: sp.Matrix) -> int:
    """Rank over the rationals (exact), by fraction-free elimination.

    Parameters
    ----------
    matrix : sympy.Matrix
        A matrix of rational (or integer) entries.

    Returns
    -------
    int
    """
    if matrix.rows == 0 or matrix.cols == 0:
        return 0
    return int(DomainMatrix.from_Matrix(sp.Matrix(matrix)).convert_to(sp.QQ).rank())


def float_rank(matrix: sp.Matrix | np.ndarray[Any, Any], tol: float | None = None) -> int:
    """Rank in double precision by SVD with numpy's default tolerance ``S.max() * max(shape) * eps``.

    Parameters
    ----------
    matrix : sympy.Matrix or ndarray, shape (rows, cols)
        A numeric matrix (sympy entries are converted to floats).
    tol : float, optional
        Singular values at or below it count as zero (same units as the entries).

    Returns
    -------
    int
    """
    arr = np.array(matrix, dtype=float) if isinstance(matrix, sp.MatrixBase) else np.asarray(matrix, float)
    if arr.size == 0:
        return 0
    return int(np.linalg.matrix_rank(arr, tol=tol))


def invertibility_matrix(ss: ExactStateSpace, k: int) -> sp.Matrix:
    """Sain-Massey matrix M_k: block lower-triangular Toeplitz of D, CB, CAB, ..., C A^(k-1) B.

    Block (i, j) for i, j = 0..k is D when i == j, C A^(i-j-1) B when i > j, zero otherwise; its size is
    ((k+1) r) x ((k+1) m) for r outputs and m inputs.

    Parameters
    ----------
    ss : ExactStateSpace
        The realization.
    k : int
        Highest Markov parameter index (``k >= 0``).

    Returns
    -------
    sympy.Matrix, shape ((k+1) r, (k+1) m)
    """
    r, m = ss.D.shape
    markov = [ss.D]
    power_b = ss.B
    for _ in range(k):
        markov.append(ss.C * power_b)
        power_b = ss.A * power_b
    out = sp.zeros((k + 1) * r, (k + 1) * m)
    for i in range(k + 1):
        for j in range(i + 1):
            out[i * r : (i + 1) * r, j * m : (j + 1) * m] = markov[i - j]
    return out


@dataclass(frozen=True)
class InvertibilityResult:
    """Sain-Massey test: invertible iff m <= r and rank(M_n) - rank(M_{n-1}) == m.

    Attributes
    ----------
    n_states : int
        n, the order of the realization.
    n_inputs, n_outputs : int
        m and r.
    exact_ranks : (int, int)
        Exact ranks of M_{n-1} and M_n.
    float_ranks : (int, int)
        Their double-precision ranks (SVD).
    matrix_shape : (int, int)
        Shape of M_n.
    """

    n_states: int
    n_inputs: int
    n_outputs: int
    exact_ranks: tuple[int, int]
    float_ranks: tuple[int, int]
    matrix_shape: tuple[int, int]

    @property
    def invertible_exact(self) -> bool:
        return self.n_inputs <= self.n_outputs and self.exact_ranks[1] - self.exact_ranks[0] == self.n_inputs

    @property
    def invertible_float(self) -> bool:
        return self.n_inputs <= self.n_outputs and self.float_ranks[1] - self.float_ranks[0] == self.n_inputs

    def to_dict(self) -> dict[str, Any]:
        return {
            "n_states": self.n_states,
            "n_inputs": self.n_inputs,
            "n_outputs": self.n_outputs,
            "matrix_shape": list(self.matrix_shape),
            "exact": {
                "rank_M_n_minus_1": self.exact_ranks[0],
                "rank_M_n": self.exact_ranks[1],
                "invertible": self.invertible_exact,
            },
            "float": {
                "rank_M_n_minus_1": self.float_ranks[0],
                "rank_M_n": self.float_ranks[1],
                "invertible": self.invertible_float,
            },
        }


def sain_massey(ss: ExactStateSpace) -> InvertibilityResult:
    """Invertibility test of Sain & Massey (1969), exactly and in double precision side by side.

    Parameters
    ----------
    ss : ExactStateSpace
        The realization (rational entries for the exact ranks).

    Returns
    -------
    InvertibilityResult
    """
    n = ss.A.rows
    m_n = invertibility_matrix(ss, n)
    r, m = ss.D.shape
    m_prev = m_n[: n * r, : n * m]
    return InvertibilityResult(
        n_states=n,
        n_inputs=m,
        n_outputs=r,
        exact_ranks=(exact_rank(m_prev), exact_rank(m_n)),
        float_ranks=(float_rank(m_prev), float_rank(m_n)),
        matrix_shape=(m_n.rows, m_n.cols),
    )


def controllability_rank(ss: ExactStateSpace, *, exact: bool = True) -> int:
    """Rank of [B, AB, ..., A^(n-1) B].

    Parameters
    ----------
    ss : ExactStateSpace
        The realization.
    exact : bool
        Rank over the rationals (True) or in double precision (False).

    Returns
    -------
    int
        n for a controllable realization.
    """
    blocks = [ss.B]
    for _ in range(ss.A.rows - 1):
        blocks.append(ss.A * blocks[-1])
    mat = sp.Matrix.hstack(*blocks)
    return exact_rank(mat) if exact else float_rank(mat)


def observability_rank(ss: ExactStateSpace, *, exact: bool = True) -> int:
    """Rank of [C; CA; ...; C A^(n-1)].

    Parameters
    ----------
    ss : ExactStateSpace
        The realization.
    exact : bool
        Rank over the rationals (True) or in double precision (False).

    Returns
    -------
    int
        n for an observable realization.
    """
    blocks = [ss.C]
    for _ in range(ss.A.rows - 1):
        blocks.append(blocks[-1] * ss.A)
    mat = sp.Matrix.vstack(*blocks)
    return exact_rank(mat) if exact else float_rank(mat)


@dataclass(frozen=True)
class PBHRanks:
    """Controllability and observability ranks by the Popov-Belevitch-Hautus test (:func:`pbh_ranks`).

    Attributes
    ----------
    controllability_rank : int
        Number of controllable modes (states); n for a controllable realization.
    observability_rank : int
        Number of observable modes (states); n for an observable realization.
    """

    controllability_rank: int
    observability_rank: int

    def to_dict(self) -> dict[str, int]:
        return {"controllability_rank": self.controllability_rank, "observability_rank": self.observability_rank}


def pbh_ranks(ss: Any, *, tol: float = 1e-8) -> PBHRanks:
    """Controllability and observability ranks by the Popov-Belevitch-Hautus eigenvector test, mode by mode.

    Mode r (right eigenvector v, left eigenvector w of A) is uncontrollable when w^H B = 0 and unobservable when
    C v = 0; here "0" is below ``tol`` relative to |w| |B| (|C| |v|), after balancing A (a similarity transform,
    which leaves both ranks unchanged) so that the stiffness and identity blocks of a mechanical state matrix
    do not differ by ten orders of magnitude, and with every input column and output row scaled to unit norm.
    A repeated eigenvalue (symmetric rotors, mirror-image structures) counts the rank of W^H B (C V) over its
    whole eigenspace. Unlike the rank of the Krylov matrix [B, AB, ...] (:func:`controllability_rank` with
    ``exact=False``) this stays meaningful in double precision for many states; the exact ranks of an
    :class:`~cappe.exact.ExactStateSpace` are the reference for small models.

    Parameters
    ----------
    ss : StateSpaceModel or any object with ``A``, ``B`` and ``C``
        A continuous realization: ``A`` of shape (n, n) in 1/s, ``B`` of shape (n, m), ``C`` of shape (r, n)
        (any units: every input column and output row is scaled to unit norm).
    tol : float
        Relative threshold below which a projection counts as zero.

    Returns
    -------
    PBHRanks

    Examples
    --------
    Two uncoupled unit oscillators, x = [q1, q2, q1', q2'], a force on the first and a sensor on the second:
    neither realization is complete, each sees one oscillator (two states).

    >>> import numpy as np
    >>> from types import SimpleNamespace
    >>> from cappe.exact import pbh_ranks
    >>> k = np.diag([1.0, 4.0])                                 # stiffness / mass, 1/s^2
    >>> a = np.block([[np.zeros((2, 2)), np.eye(2)], [-k, -0.02 * np.eye(2)]])
    >>> b = np.array([[0.0], [0.0], [1.0], [0.0]])
    >>> c = np.array([[0.0, 1.0, 0.0, 0.0]])
    >>> pbh_ranks(SimpleNamespace(A=a, B=b, C=c))
    PBHRanks(controllability_rank=2, observability_rank=2)
    """
    import scipy.linalg as sla

    a, b, c = np.asarray(ss.A, dtype=float), np.asarray(ss.B, dtype=float), np.asarray(ss.C, dtype=float)
    # unit inputs and outputs (displacement and acceleration rows differ by omega^2): ranks unchanged
    b = b / np.where(np.linalg.norm(b, axis=0) > 0, np.linalg.norm(b, axis=0), 1.0)[None, :]
    c = c / np.where(np.linalg.norm(c, axis=1) > 0, np.linalg.norm(c, axis=1), 1.0)[:, None]
    a_bal, (scale, perm) = sla.matrix_balance(a, separate=True)
    t = np.eye(a.shape[0])[:, perm] * scale[None, :]  # a_bal = inv(t) @ a @ t
    b_bal = np.linalg.solve(t, b)
    c_bal = c @ t
    lam, w, v = sla.eig(a_bal, left=True, right=True)
    w = w / np.linalg.norm(w, axis=0)
    v = v / np.linalg.norm(v, axis=0)
    nb = max(float(np.linalg.norm(b_bal)), 1e-300)
    nc = max(float(np.linalg.norm(c_bal)), 1e-300)
    # repeated eigenvalues (symmetric rotors, mirror-image structures): the test is on the whole eigenspace
    order = np.argsort(lam.real + 1e-3 * lam.imag)
    clusters: list[list[int]] = []
    for k in order:
        if clusters and abs(lam[k] - lam[clusters[-1][-1]]) <= 1e-7 * max(abs(lam[k]), 1.0):
            clusters[-1].append(k)
        else:
            clusters.append([k])

    def rank(matrix: Any, norm: float) -> int:
        sv = np.linalg.svd(matrix, compute_uv=False)
        return int(np.sum(sv > tol * norm))

    ctrb = sum(rank(w[:, idx].conj().T @ b_bal, nb) for idx in clusters)
    obsv = sum(rank(c_bal @ v[:, idx], nc) for idx in clusters)
    return PBHRanks(controllability_rank=ctrb, observability_rank=obsv)
