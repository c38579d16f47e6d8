"""Validation of the arrays handed to the correlation criteria (private)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cappe.exceptions import DataError


def first_index(mask: NDArray[np.bool_]) -> tuple[int, ...] | None:
    """Index of the first True entry of ``mask`` (``()`` for a true 0-d mask), or None."""
    if not mask.any():
        return None
    return tuple(int(i) for i in np.unravel_index(int(np.argmax(mask)), mask.shape))


def as_finite_array(value: ArrayLike, name: str, *, allow_complex: bool = True) -> NDArray[Any]:
    """``value`` as a float64 or complex128 array with only finite entries, or a `DataError` naming ``name``."""
    try:
        arr = np.asarray(value)
    except (ValueError, TypeError) as exc:
        msg = f"{name} must be a numeric array; numpy cannot convert the {type(value).__name__} given ({exc})"
        raise DataError(msg) from exc
    kinds = "iufc" if allow_complex else "iuf"
    if arr.dtype.kind not in kinds:
        what = "real or complex" if allow_complex else "real"
        msg = f"{name} must be a {what} numeric array; got dtype {arr.dtype}"
        raise DataError(msg)
    arr = arr.astype(np.complex128 if arr.dtype.kind == "c" else np.float64)
    index = first_index(~np.isfinite(arr))
    if index is not None:
        msg = f"{name} must be finite (no NaN or inf); got {arr[index]} at index {index}"
        raise DataError(msg)
    return arr


def as_shapes(phi: ArrayLike, name: str) -> NDArray[Any]:
    """Mode shapes as a 2-D array (n_sensors, n_modes), each column scaled to a largest magnitude of 1.

    A 1-D array is one shape (one column). The scaling changes no scale-invariant criterion and keeps
    ``|phi|**2`` away from underflow and overflow.
    """
    arr = as_finite_array(phi, name)
    if arr.ndim == 1:
        arr = arr[:, np.newaxis]
    elif arr.ndim != 2:
        msg = f"{name} must be 1-D (one shape) or 2-D (n_sensors, n_modes); got shape {arr.shape}"
        raise DataError(msg)
    if arr.shape[0] == 0 or arr.shape[1] == 0:
        msg = f"{name} must hold at least one sensor and one mode; got shape {arr.shape}"
        raise DataError(msg)
    peak = np.max(np.abs(arr), axis=0)
    zero = np.flatnonzero(peak == 0)
    if zero.size:
        msg = f"{name} column {int(zero[0])} is all zeros; the criterion is undefined for a zero shape"
        raise DataError(msg)
    return np.asarray(arr / peak)


def check_same_sensors(phi_a: NDArray[Any], phi_x: NDArray[Any]) -> None:
    """Raise a `DataError` unless both shape sets have the same number of rows (sensors)."""
    if phi_a.shape[0] != phi_x.shape[0]:
        msg = (
            "phi_a and phi_x must have the same number of sensors (rows); "
            f"got {phi_a.shape[0]} and {phi_x.shape[0]}"
        )
        raise DataError(msg)


def as_poles(lam: ArrayLike, name: str, n_modes: int, shapes_name: str) -> NDArray[np.complex128]:
    """Poles as a 1-D complex array with one nonzero pole per mode-shape column."""
    arr = np.atleast_1d(as_finite_array(lam, name))
    if arr.ndim != 1:
        msg = f"{name} must be 1-D (n_modes,); got shape {arr.shape}"
        raise DataError(msg)
    if arr.shape[0] != n_modes:
        msg = f"{name} must hold one pole per column of {shapes_name} ({n_modes}); got {arr.shape[0]}"
        raise DataError(msg)
    zero = np.flatnonzero(arr == 0)
    if zero.size:
        msg = f"{name}[{int(zero[0])}] is 0; MACXP needs nonzero poles (a zero pole is a rigid-body mode)"
        raise DataError(msg)
    return arr.astype(np.complex128)
