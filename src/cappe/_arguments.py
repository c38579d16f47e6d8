"""Validation of scalar arguments at public boundaries, with messages that name the argument."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cappe.exceptions import DataError

__all__ = ["is_numeric", "positive_number", "real_number"]


def real_number(name: str, value: Any) -> float:
    """``value`` as a finite float, or a DataError naming ``name``.

    Examples
    --------
    >>> real_number("fs", "1e3")
    1000.0
    """
    try:
        out = float(value)
    except OverflowError:
        msg = f"argument {name!r} must be finite; got an integer beyond the floating-point range"
        raise DataError(msg) from None
    except (TypeError, ValueError):
        msg = f"argument {name!r} must be a real number; got {value!r}"
        raise DataError(msg) from None
    if not math.isfinite(out):
        msg = f"argument {name!r} must be finite; got {value!r}"
        raise DataError(msg)
    return out


def positive_number(name: str, value: Any, unit: str = "") -> float:
    """``value`` as a finite float > 0 (``unit`` only shapes the message).

    Examples
    --------
    >>> positive_number("duration", 2, "s")
    2.0
    """
    out = real_number(name, value)
    if out <= 0:
        msg = f"argument {name!r} must be > 0{' ' + unit if unit else ''}; got {value!r}"
        raise DataError(msg)
    return out


def is_numeric(value: Any) -> bool:
    """Whether numpy can read ``value`` as an array of floats."""
    try:
        np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return False
    return True
