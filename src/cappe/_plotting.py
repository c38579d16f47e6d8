"""Figures written to files: matplotlib on the Agg canvas (no display needed), saved atomically.

The drawing helpers every layer that writes a figure shares (the sensitivity results' ``plot`` methods and
:mod:`cappe.report`); matplotlib is imported on first use only.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = ["figure", "save"]


def figure(rows: int) -> tuple[Any, Any]:
    """A figure with ``rows`` stacked axes (sharing x when more than one), on the Agg canvas."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt.subplots(rows, 1, figsize=(7, 3 + 2 * rows), sharex=rows > 1)


def save(fig: Any, path: str | Path) -> Path:
    """Lay out, write ``fig`` to ``path`` (format by extension) through a temporary file, close it; returns the path."""
    import matplotlib.pyplot as plt

    out = Path(path)
    tmp = out.with_name(f".{out.name}.tmp{out.suffix}")
    fig.tight_layout()
    fig.savefig(tmp, dpi=120)
    plt.close(fig)
    tmp.replace(out)
    return out
