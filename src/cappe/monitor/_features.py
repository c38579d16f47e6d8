"""Features of one measurement: modal frequencies and damping, and FRF correlation with the healthy state.

- :func:`modal_features`: poles from the measured FRFs (poly-reference LSCF at a fixed order, clustered, as
  :func:`cappe.identify.extract_modes` does), each paired to the nearest expected mode. The expected modes come
  from the model at the current estimate, so a mode that moved 5 % keeps its number.
- :func:`frf_features`: the mean FRAC (shape and level of each FRF over frequency) and the mean CSF (operating
  shapes at each line, amplitude-sensitive) against the mean healthy FRF.
"""

from __future__ import annotations

import warnings

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linear_sum_assignment

from cappe.correlate import csf, frac
from cappe.exceptions import DataError
from cappe.identify import extract_modes
from cappe.systems.frf import FRFData

__all__ = ["frf_features", "modal_features"]

Array = NDArray[np.float64]

#: Relative frequency distance beyond which an extracted pole is not the expected mode.
PAIRING_TOLERANCE = 0.08


def modal_features(
    frf: FRFData,
    *,
    band: tuple[float, float],
    expected: ArrayLike,
    max_order: int = 24,
) -> tuple[Array, Array, list[str]]:
    """Natural frequency (Hz) and damping ratio of each expected mode, NaN where none was found.

    Parameters
    ----------
    frf : FRFData
        The measurement.
    band : (float, float)
        Band of the extraction in Hz.
    expected : sequence of float
        Frequencies (Hz) of the modes to report, in their numbering.
    max_order : int
        Highest LSCF order.

    Returns
    -------
    frequency, damping : ndarray, shape (m,)
    notes : list of str
        Why modes are missing (extraction failures and warnings), for the record.
    """
    target = np.asarray(expected, dtype=float)
    freq = np.full(target.size, np.nan)
    zeta = np.full(target.size, np.nan)
    notes: list[str] = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            found = extract_modes(frf, band=band, max_order=max_order, n_bootstrap=0)  # features need no std
        except DataError as exc:
            return freq, zeta, [f"modal extraction failed: {exc}"]
    notes.extend(f"modal extraction: {w.message}" for w in caught)
    f_found = np.asarray(found.frequency, dtype=float)
    if f_found.size and target.size:
        cost = np.abs(np.log(f_found[:, None] / target[None, :]))
        rows, cols = linear_sum_assignment(cost)
        for r, c in zip(rows, cols, strict=True):
            if cost[r, c] <= PAIRING_TOLERANCE:
                freq[c], zeta[c] = f_found[r], float(found.damping[r])
    missing = [k + 1 for k in range(target.size) if not np.isfinite(freq[k])]
    if missing:
        notes.append(f"modes {missing} not found in the measurement")
    return freq, zeta, notes


def frf_features(measured: FRFData, healthy: FRFData) -> tuple[float, float]:
    """Mean FRAC and mean CSF of ``measured`` against the healthy FRF, on the healthy FRF's lines and channels.

    Parameters
    ----------
    measured : FRFData
        The measurement's FRFs.
    healthy : FRFData
        The mean healthy FRF (its lines and channels are compared).

    Returns
    -------
    frac, csf : float
        Mean FRAC over the FRFs and mean CSF over lines and FRFs (dimensionless, 1 = identical).

    Raises
    ------
    DataError
        When the measurement lacks a channel or a line of the healthy FRF.
    """
    oo = [measured.output_names.index(n) if n in measured.output_names else -1 for n in healthy.output_names]
    ii = [measured.input_names.index(n) if n in measured.input_names else -1 for n in healthy.input_names]
    if min(oo + ii) < 0:
        msg = (f"the measurement lacks channels of the healthy FRF (outputs {list(healthy.output_names)}, inputs "
               f"{list(healthy.input_names)})")
        raise DataError(msg)
    lines = np.searchsorted(measured.freq, healthy.freq)
    lines = np.clip(lines, 0, measured.freq.size - 1)
    if not np.allclose(measured.freq[lines], healthy.freq, rtol=1e-9, atol=1e-9):
        msg = "the measurement's frequency lines differ from the healthy FRF's; cannot correlate them"
        raise DataError(msg)
    h_meas = np.asarray(measured.H)[np.ix_(np.array(oo), np.array(ii), lines)]
    h_ref = np.asarray(healthy.H)
    active = np.sum(np.abs(h_ref) ** 2, axis=-1) > 0
    frac_values = frac(h_meas[active], h_ref[active])
    csf_values = csf(h_meas, h_ref)
    return float(np.mean(frac_values)), float(np.mean(csf_values))
