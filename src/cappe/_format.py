"""Numbers as the text outputs and the HTML report print them."""

from __future__ import annotations

import numpy as np

__all__ = ["interval_text"]


def interval_text(lo: float, hi: float, value: float) -> str:
    """``[lo, hi]`` with enough significant digits that the two ends differ where they do (the width shows).

    Parameters
    ----------
    lo, hi : float
        The ends of the interval; a non-finite end gives ``"not determined"``.
    value : float
        The estimate inside it (sets the scale with the ends).

    Returns
    -------
    str
        The interval as printed.

    Examples
    --------
    >>> interval_text(2.594975e7, 2.595025e7, 2.595e7)
    '[2.594975e+07, 2.595025e+07]'
    >>> interval_text(0.9, 1.1, 1.0)
    '[0.9, 1.1]'
    """
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return "not determined"
    width = abs(hi - lo)
    scale = max(abs(lo), abs(hi), abs(value))
    digits = 4 if width == 0 or scale == 0 else int(np.clip(np.ceil(np.log10(scale / width)) + 2, 4, 17))
    return f"[{lo:.{digits}g}, {hi:.{digits}g}]"
