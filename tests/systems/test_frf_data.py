"""FRFData checks its structure on construction; values (inf at an undamped resonance) are the consumers' concern."""

from __future__ import annotations

import numpy as np
import pytest

from cappe.exceptions import DataError
from cappe.systems import FRFData


def test_structure_is_checked_on_construction():
    freq = np.array([1.0, 2.0])
    with pytest.raises(DataError, match=r"FRF H must have shape \(n_out, n_in, n_freq\) = \(2, 1, 2\); got \(1, 1, 2\)"):
        FRFData(freq, np.ones((1, 1, 2), complex), ("F",), ("a", "b"))
    with pytest.raises(DataError, match=r"FRF freq must be a non-empty 1-D array of finite frequencies in Hz"):
        FRFData(np.array([1.0, np.nan]), np.ones((1, 1, 2), complex), ("F",), ("a",))
    with pytest.raises(DataError, match=r"FRF output names must be unique; repeated: \['a'\]"):
        FRFData(freq, np.ones((2, 1, 2), complex), ("F",), ("a", "a"))
    with pytest.raises(DataError, match=r"FRF window_decay must be None or a time constant > 0 in s; got 0.0"):
        FRFData(freq, np.ones((1, 1, 2), complex), ("F",), ("a",), window_decay=0.0)


def test_non_finite_values_are_allowed():
    h = np.array([[[1.0 + 0j, np.inf]]])  # an undamped model FRF at its resonance line
    assert np.isinf(FRFData(np.array([1.0, 2.0]), h, ("F",), ("a",)).H[0, 0, 1])
