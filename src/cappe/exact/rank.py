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
    "controllability_rank",
    "exact_rank",
    "float_rank",
    "invertibility_matrix",
    "observability_rank",
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
