"""Pairing of two mode sets by optimal assignment on a correlation criterion."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linear_sum_assignment

from cappe.correlate._modal import mac, macx, macxp
from cappe.correlate._validate import as_finite_array
from cappe.exceptions import DataError

__all__ = ["ModePairing", "pair_modes"]

Criterion = Literal["mac", "macx", "macxp"]
_CRITERIA = ("mac", "macx", "macxp")


def _frozen(values: ArrayLike, dtype: type[np.generic]) -> NDArray[Any]:
    arr = np.array(values, dtype=dtype)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class ModePairing:
    """Pairs of modes of two sets, found by `pair_modes`.

    Attributes
    ----------
    index_a : ndarray of int, shape (n_pairs,)
        Column of each pair in set ``a``, ascending.
    index_x : ndarray of int, shape (n_pairs,)
        Column of each pair in set ``x``.
    values : ndarray of float, shape (n_pairs,)
        Criterion value of each pair (dimensionless).
    unpaired_a : ndarray of int
        Columns of set ``a`` without a partner, ascending.
    unpaired_x : ndarray of int
        Columns of set ``x`` without a partner, ascending.
    matrix : ndarray of float, shape (n_a, n_x)
        The full criterion matrix the pairing was made on.
    criterion : str
        ``"mac"``, ``"macx"``, ``"macxp"``, or ``"matrix"`` for a matrix given by the caller.
    threshold : float
        Smallest criterion value a pair may have.
    """

    index_a: NDArray[np.intp]
    index_x: NDArray[np.intp]
    values: NDArray[np.float64]
    unpaired_a: NDArray[np.intp]
    unpaired_x: NDArray[np.intp]
    matrix: NDArray[np.float64]
    criterion: str
    threshold: float

    @property
    def n_pairs(self) -> int:
        """Number of pairs."""
        return int(self.index_a.shape[0])

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python form (lists, floats, ints) for JSON output."""
        return {
            "criterion": self.criterion,
            "threshold": self.threshold,
            "pairs": [
                {"index_a": int(i), "index_x": int(j), "value": float(v)}
                for i, j, v in zip(self.index_a, self.index_x, self.values, strict=True)
            ],
            "unpaired_a": [int(i) for i in self.unpaired_a],
            "unpaired_x": [int(j) for j in self.unpaired_x],
            "matrix": self.matrix.tolist(),
        }


def pair_modes(
    *,
    phi_a: ArrayLike | None = None,
    phi_x: ArrayLike | None = None,
    lam_a: ArrayLike | None = None,
    lam_x: ArrayLike | None = None,
    criterion: Criterion | None = None,
    matrix: ArrayLike | None = None,
    threshold: float = 0.5,
) -> ModePairing:
    """Pair the modes of two sets so that the sum of the criterion over the kept pairs is largest.

    Give either the shapes (and, for MACXP, the poles) or a precomputed criterion ``matrix``. Entries
    below ``threshold`` are set to zero before the assignment (`scipy.optimize.linear_sum_assignment`,
    maximizing), and pairs whose value is below ``threshold`` are dropped, so the assignment maximizes the
    total criterion of the pairs actually kept. The sets may differ in size; every mode not kept in a pair
    is listed as unpaired.

    Parameters
    ----------
    phi_a : array_like, shape (n_sensors, n_a) or (n_sensors,), optional
        Shapes of set ``a`` (e.g. model), one mode per column.
    phi_x : array_like, shape (n_sensors, n_x) or (n_sensors,), optional
        Shapes of set ``x`` (e.g. measured) at the same sensors.
    lam_a, lam_x : array_like, shape (n_a,) and (n_x,), optional
        Complex poles in rad/s; required for ``criterion="macxp"``.
    criterion : {"mac", "macx", "macxp"}, optional
        Criterion computed from the shapes. Default: ``"macxp"`` when both pole arrays are given, else ``"mac"``.
    matrix : array_like, shape (n_a, n_x), optional
        A precomputed criterion (larger is better), instead of shapes.
    threshold : float, default 0.5
        Smallest criterion value a pair may have (dimensionless).

    Returns
    -------
    ModePairing
        Pairs, their values, the unpaired modes of both sets and the criterion matrix.

    Raises
    ------
    DataError
        If both or neither of shapes and ``matrix`` are given, only one shape set is given, poles are given
        with ``matrix`` or missing for MACXP, the criterion name is unknown, ``threshold`` is not finite,
        ``matrix`` is not a finite real 2-D array, or the shape and pole arrays are invalid (see `macxp`).

    Examples
    --------
    >>> import numpy as np
    >>> from cappe.correlate import pair_modes
    >>> phi_x = np.array([[1.0, 1.0, 0.0], [1.0, -1.0, 1.0], [0.0, 1.0, 1.0]])
    >>> pairing = pair_modes(phi_a=phi_x[:, [2, 0]], phi_x=phi_x)
    >>> pairing.index_a, pairing.index_x, pairing.unpaired_x
    (array([0, 1]), array([2, 0]), array([1]))
    """
    msg = f"threshold must be a finite real number; got {threshold!r}"
    try:
        threshold = float(threshold)
    except (TypeError, ValueError) as exc:
        raise DataError(msg) from exc
    if not np.isfinite(threshold):
        raise DataError(msg)
    has_shapes = phi_a is not None or phi_x is not None
    if matrix is not None:
        if has_shapes or lam_a is not None or lam_x is not None or criterion is not None:
            msg = "matrix must be given alone: not with phi_a, phi_x, lam_a, lam_x or criterion"
            raise DataError(msg)
        values = as_finite_array(matrix, "matrix", allow_complex=False)
        if values.ndim != 2 or values.size == 0:
            msg = f"matrix must be a non-empty 2-D array (n_a, n_x); got shape {values.shape}"
            raise DataError(msg)
        name = "matrix"
    else:
        if phi_a is None or phi_x is None:
            msg = "pair_modes needs either matrix or both phi_a and phi_x; got " + (
                "only one of phi_a and phi_x" if has_shapes else "neither"
            )
            raise DataError(msg)
        has_poles = lam_a is not None and lam_x is not None
        if criterion is None:
            criterion = "macxp" if has_poles else "mac"
        if criterion not in _CRITERIA:
            msg = f"criterion must be one of {_CRITERIA}; got {criterion!r}"
            raise DataError(msg)
        if criterion == "macxp":
            if lam_a is None or lam_x is None:
                msg = "criterion 'macxp' needs both lam_a and lam_x; got " + (
                    "only one" if lam_a is not None or lam_x is not None else "neither"
                )
                raise DataError(msg)
            values = macxp(phi_a, lam_a, phi_x, lam_x)
        elif lam_a is not None or lam_x is not None:
            msg = f"lam_a and lam_x are only used by criterion 'macxp'; got criterion {criterion!r}"
            raise DataError(msg)
        else:
            values = mac(phi_a, phi_x) if criterion == "mac" else macx(phi_a, phi_x)
        name = criterion

    gain = np.where(values >= threshold, values, 0.0)
    rows, cols = linear_sum_assignment(gain, maximize=True)
    keep = values[rows, cols] >= threshold
    rows, cols = rows[keep], cols[keep]
    return ModePairing(
        index_a=_frozen(rows, np.intp),
        index_x=_frozen(cols, np.intp),
        values=_frozen(values[rows, cols], np.float64),
        unpaired_a=_frozen(np.setdiff1d(np.arange(values.shape[0]), rows), np.intp),
        unpaired_x=_frozen(np.setdiff1d(np.arange(values.shape[1]), cols), np.intp),
        matrix=_frozen(values, np.float64),
        criterion=name,
        threshold=threshold,
    )
