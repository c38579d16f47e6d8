"""Figures written to files: matplotlib on the Agg canvas (no display needed), saved atomically.

The drawing helpers every layer that writes a figure shares (the sensitivity results' ``plot`` methods and
:mod:`cappe.report`); matplotlib is imported on first use only.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = ["figure", "log_frequency_axis", "save"]


def figure(rows: int) -> tuple[Any, Any]:
    """A figure with ``rows`` stacked axes (sharing x when more than one), on the Agg canvas."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt.subplots(rows, 1, figsize=(7, 3 + 2 * rows), sharex=rows > 1)


def save(fig: Any, path: str | Path, *, rect: tuple[float, float, float, float] | None = None) -> Path:
    """Lay out (the axes within ``rect``, figure fractions, when given: room for a figure legend), write ``fig`` to
    ``path`` (format by extension) through a temporary file, close it; returns the path."""
    import matplotlib.pyplot as plt

    out = Path(path)
    tmp = out.with_name(f".{out.name}.tmp{out.suffix}")
    fig.tight_layout(rect=rect)
    fig.savefig(tmp, dpi=120)
    plt.close(fig)
    tmp.replace(out)
    return out


def log_frequency_axis(ax: Any, lo: float, hi: float) -> None:
    """Label a log frequency axis from ``lo`` to ``hi`` (Hz) with plain numbers that never overlap.

    matplotlib labels the minor ticks of a log axis spanning less than about two decades as ``2x10^1 3x10^1 ...``,
    which run into each other at a figure's width; here the labels are 10, 20, 50, 100 ... (1, 2 and 5 per decade
    up to three decades, the decades alone beyond) and the minor ticks stay unlabelled.
    """
    import math

    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    decades = math.log10(hi / lo) if 0 < lo < hi else math.inf
    ax.xaxis.set_major_locator(LogLocator(base=10.0, subs=(1.0, 2.0, 5.0) if decades <= 3 else (1.0,)))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
    ax.xaxis.set_minor_formatter(NullFormatter())
