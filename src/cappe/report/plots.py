"""Plots of representations: Bode diagrams of FRFs and pole-zero maps (matplotlib, written to files)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from cappe.systems.frf import FRFData
from cappe.systems.zpk import ZeroPoleGainModel

__all__ = ["bode_plot", "pole_zero_plot"]


def _figure(rows: int) -> tuple[Any, Any]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt.subplots(rows, 1, figsize=(7, 3 + 2 * rows), sharex=rows > 1)


def _save(fig: Any, path: str | Path) -> Path:
    import matplotlib.pyplot as plt

    out = Path(path)
    tmp = out.with_name(f".{out.name}.tmp{out.suffix}")
    fig.tight_layout()
    fig.savefig(tmp, dpi=120)
    plt.close(fig)
    tmp.replace(out)
    return out


def bode_plot(frf: FRFData, path: str | Path, title: str = "") -> Path:
    """Bode magnitude (dB re 1 unit) and phase (deg) of every output/input pair, written to ``path``."""
    fig, axes = _figure(2)
    ax_mag, ax_phase = axes
    for o, out in enumerate(frf.output_names):
        for i, inp in enumerate(frf.input_names):
            h = frf.H[o, i]
            ax_mag.semilogx(frf.freq, 20 * np.log10(np.abs(h) + 1e-300), label=f"{out}/{inp}")
            ax_phase.semilogx(frf.freq, np.degrees(np.unwrap(np.angle(h))))
    ax_mag.set_ylabel("magnitude (dB)")
    ax_phase.set_ylabel("phase (deg)")
    ax_phase.set_xlabel("frequency (Hz)")
    ax_mag.legend(loc="best", fontsize=8)
    ax_mag.grid(True, which="both", alpha=0.3)
    ax_phase.grid(True, which="both", alpha=0.3)
    if title:
        ax_mag.set_title(title)
    return _save(fig, path)


def pole_zero_plot(model: ZeroPoleGainModel, path: str | Path, title: str = "") -> Path:
    """Pole-zero map in the s-plane (rad/s), written to ``path``."""
    fig, ax = _figure(1)
    ax.plot(model.poles.real, model.poles.imag, "x", markersize=9, label="poles")
    if model.zeros.size:
        ax.plot(model.zeros.real, model.zeros.imag, "o", mfc="none", markersize=8, label="zeros")
    ax.axvline(0, color="0.6", lw=0.8)
    ax.axhline(0, color="0.6", lw=0.8)
    ax.set_xlabel("real (rad/s)")
    ax.set_ylabel("imaginary (rad/s)")
    ax.legend(loc="best")
    ax.grid(True, alpha=0.3)
    ax.set_title(title or f"{model.output}/{model.input}")
    return _save(fig, path)
