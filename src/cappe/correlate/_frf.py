"""FRF correlation criteria: FRAC, CSAC and CSF."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cappe.correlate._validate import as_finite_array, first_index
from cappe.exceptions import DataError

__all__ = ["csac", "csf", "frac"]


def _frf_pair(
    H_a: ArrayLike, H_x: ArrayLike, ndims: tuple[int, ...] | None, layout: str
) -> tuple[NDArray[Any], NDArray[Any]]:
    """Both FRF arrays validated; ``ndims=None`` accepts any dimension >= 1."""
    a = as_finite_array(H_a, "H_a")
    x = as_finite_array(H_x, "H_x")
    for name, arr in (("H_a", a), ("H_x", x)):
        bad_ndim = arr.ndim == 0 if ndims is None else arr.ndim not in ndims
        if bad_ndim or arr.size == 0:
            msg = f"{name} must be a non-empty array of shape {layout}; got shape {arr.shape}"
            raise DataError(msg)
    if a.shape != x.shape:
        msg = f"H_a and H_x must have the same shape; got {a.shape} and {x.shape}"
        raise DataError(msg)
    return a, x


def _first_zero(power: NDArray[np.float64], what: str, criterion: str) -> None:
    """Raise a `DataError` naming the first result index where ``power`` is zero."""
    index = first_index(power == 0)
    if index is not None:
        msg = f"{what} for result index {index}; {criterion} is undefined there"
        raise DataError(msg)


def frac(H_a: ArrayLike, H_x: ArrayLike) -> NDArray[np.float64]:
    """Frequency response assurance criterion of every FRF over frequency (Heylen & Lammens).

    ``FRAC = |sum_f conj(H_x) H_a|^2 / (sum_f |H_a|^2 sum_f |H_x|^2)`` over the frequency lines, per
    output/input pair. It ignores a complex scale factor between the two FRFs.

    Parameters
    ----------
    H_a : array_like, shape (n_out, n_in, n_freq) or (n_freq,)
        FRFs, e.g. of a model, on the same frequency lines as ``H_x`` (any unit, the same as ``H_x``).
        Frequency is the last axis; any leading axes are kept.
    H_x : array_like, same shape as ``H_a``
        Reference FRFs, e.g. measured.

    Returns
    -------
    ndarray, shape (n_out, n_in), or shape () for 1-D input
        FRAC values in [0, 1] (dimensionless).

    Raises
    ------
    DataError
        If an input is not numeric and finite, is empty, the shapes differ, or an FRF is zero at all
        frequency lines.

    Examples
    --------
    >>> import numpy as np
    >>> from cappe.correlate import frac
    >>> H = np.array([1.0 + 1.0j, 2.0, -1.0j])
    >>> frac(H, (2.0 - 3.0j) * H)
    array(1.)
    >>> frac([1.0, 0.0], [1.0, 1.0])
    array(0.5)
    """
    a, x = _frf_pair(H_a, H_x, None, "(..., n_freq), e.g. (n_out, n_in, n_freq) or (n_freq,)")
    power_a = np.sum(np.abs(a) ** 2, axis=-1)
    power_x = np.sum(np.abs(x) ** 2, axis=-1)
    _first_zero(power_a, "H_a is zero at all frequency lines", "FRAC")
    _first_zero(power_x, "H_x is zero at all frequency lines", "FRAC")
    cross = np.abs(np.sum(x.conj() * a, axis=-1)) ** 2
    return np.asarray(cross / (power_a * power_x), dtype=np.float64)


def csac(H_a: ArrayLike, H_x: ArrayLike) -> NDArray[np.float64]:
    """Cross-signature assurance criterion of the operating shapes, per input and frequency line.

    ``CSAC = |H_x^H H_a|^2 / ((H_x^H H_x) (H_a^H H_a))``, the inner products running over the outputs
    (Dascotte; Zang, Grafe & Imregun). It is the MAC of the two deflection shapes at each frequency line.

    Parameters
    ----------
    H_a : array_like, shape (n_out, n_in, n_freq) or (n_out, n_freq)
        FRFs, e.g. of a model, on the same outputs and frequency lines as ``H_x``.
    H_x : array_like, same shape as ``H_a``
        Reference FRFs, e.g. measured.

    Returns
    -------
    ndarray, shape (n_in, n_freq), or (n_freq,) for 2-D input
        CSAC values in [0, 1] (dimensionless).

    Raises
    ------
    DataError
        If an input is not numeric and finite, is empty, not 2-D or 3-D, the shapes differ, or an FRF set is
        zero at all outputs for some input and frequency line (e.g. an accelerance at 0 Hz: drop that line).

    Examples
    --------
    >>> import numpy as np
    >>> from cappe.correlate import csac
    >>> H = np.array([[1.0, 1.0j], [2.0, 1.0]])  # (n_out=2, n_freq=2)
    >>> csac(H, 3.0j * H)
    array([1., 1.])
    """
    a, x = _frf_pair(H_a, H_x, (2, 3), "(n_out, n_in, n_freq) or (n_out, n_freq)")
    power_a = np.sum(np.abs(a) ** 2, axis=0)
    power_x = np.sum(np.abs(x) ** 2, axis=0)
    _first_zero(power_a, "H_a is zero at all outputs", "CSAC")
    _first_zero(power_x, "H_x is zero at all outputs", "CSAC")
    cross = np.abs(np.sum(x.conj() * a, axis=0)) ** 2
    return np.asarray(cross / (power_a * power_x), dtype=np.float64)


def csf(H_a: ArrayLike, H_x: ArrayLike) -> NDArray[np.float64]:
    """Cross-signature scale factor of the operating shapes, per input and frequency line.

    ``CSF = 2 |H_x^H H_a| / (H_x^H H_x + H_a^H H_a)``, the inner products running over the outputs
    (Dascotte; Zang, Grafe & Imregun). Unlike the CSAC it penalizes amplitude differences: it is 1 only
    for equal shapes up to a phase factor ``e^{i t}``, and ``2 c / (1 + c^2)`` for ``H_x = c H_a``.

    Parameters
    ----------
    H_a : array_like, shape (n_out, n_in, n_freq) or (n_out, n_freq)
        FRFs, e.g. of a model, in the same unit and on the same outputs and frequency lines as ``H_x``.
    H_x : array_like, same shape as ``H_a``
        Reference FRFs, e.g. measured.

    Returns
    -------
    ndarray, shape (n_in, n_freq), or (n_freq,) for 2-D input
        CSF values in [0, 1] (dimensionless).

    Raises
    ------
    DataError
        If an input is not numeric and finite, is empty, not 2-D or 3-D, the shapes differ, or both FRF sets
        are zero at all outputs for some input and frequency line.

    Examples
    --------
    >>> import numpy as np
    >>> from cappe.correlate import csf
    >>> H = np.array([[1.0, 1.0j], [2.0, 1.0]])  # (n_out=2, n_freq=2)
    >>> csf(H, H)
    array([1., 1.])
    >>> csf(H, 2.0 * H)
    array([0.8, 0.8])
    """
    a, x = _frf_pair(H_a, H_x, (2, 3), "(n_out, n_in, n_freq) or (n_out, n_freq)")
    power = np.sum(np.abs(a) ** 2, axis=0) + np.sum(np.abs(x) ** 2, axis=0)
    _first_zero(power, "H_a and H_x are both zero at all outputs", "CSF")
    cross = np.abs(np.sum(x.conj() * a, axis=0))
    return np.asarray(2.0 * cross / power, dtype=np.float64)
