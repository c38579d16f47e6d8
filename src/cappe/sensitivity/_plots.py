"""Plots of sensitivity results, written to files: Sobol' index bars and cost landscapes.

They draw ``ModelSobolResult.plot`` (its Sobol' indices) and ``CostLandscape.plot``; :mod:`cappe.report` hands them
on with its other plots.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from cappe._plotting import figure as _figure
from cappe._plotting import save as _save

__all__ = ["landscape_plot", "sobol_plot"]


def landscape_plot(landscape: Any, path: str | Path, title: str = "", *, log: bool = True, levels: int = 30) -> Path:
    """Filled contours of a two-parameter cost landscape (:class:`cappe.sensitivity.CostLandscape`).

    Parameters
    ----------
    landscape : CostLandscape
        The cost on a grid of two unknowns.
    path : str or Path
        Image file to write (format from the extension: .png, .svg, .pdf ...).
    title : str
        Figure title.
    log : bool
        Contour ``log10`` of the cost.
    levels : int
        Number of contour levels.

    Returns
    -------
    Path
        ``path``.
    """
    fig, ax = _figure(1)
    values = np.asarray(landscape.values, dtype=float)
    shown = np.log10(np.maximum(values, np.finfo(float).tiny)) if log else values
    filled = ax.contourf(landscape.x, landscape.y, shown, levels=levels, cmap="viridis")
    fig.colorbar(filled, ax=ax, label="log10 cost" if log else "cost")
    x_min, y_min, _ = landscape.minimum
    ax.plot([x_min], [y_min], "r+", markersize=12, label="grid minimum")
    ax.set_xlabel(landscape.names[0])
    ax.set_ylabel(landscape.names[1])
    ax.legend(loc="best", fontsize=8)
    ax.set_title(title or f"cost over {landscape.names[0]} and {landscape.names[1]}")
    return _save(fig, path)


def sobol_plot(result: Any, path: str | Path, *, outputs: Any = None, top: int = 10, max_panels: int = 6) -> Path:
    """Bars of S1 and ST with confidence whiskers, the ``top`` parameters by ST for each output (paper Fig. 5).

    ``result`` is a :class:`cappe.sensitivity.SobolResult`; ``outputs`` selects output names (default: the
    first ``max_panels``).

    Parameters
    ----------
    result : SobolResult
        The indices with their confidence half-widths.
    path : str or Path
        Image file to write (format from the extension: .png, .svg, .pdf ...).
    outputs : sequence of str, optional
        Output names, one panel each.
    top : int
        Parameters per panel, largest ST first.
    max_panels : int
        Panels drawn when ``outputs`` is not given.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ValueError
        An output name is not in ``result``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(result.output_names)
    chosen = list(outputs) if outputs is not None else names[:max_panels]
    unknown = [o for o in chosen if o not in names]
    if unknown:
        msg = f"unknown outputs {unknown}; known: {', '.join(names[:10])}{' ...' if len(names) > 10 else ''}"
        raise ValueError(msg)
    noisy = result.noise_text() if hasattr(result, "noise_text") else ""
    head = 0.9 + (0.35 if noisy else 0.0)  # inches above the panels: the legend and the noise line
    height = 2.6 * len(chosen) + head
    fig, axes = plt.subplots(len(chosen), 1, figsize=(7, height), squeeze=False)
    width = 0.4
    conf = f"{100 * result.conf_level:g} %" if hasattr(result, "conf_level") else "confidence"
    for ax, output in zip(axes[:, 0], chosen, strict=True):
        o = names.index(output)
        order = np.argsort(-np.nan_to_num(result.ST[o], nan=-np.inf), kind="stable")[:top]
        x = np.arange(order.size)
        ax.axhspan(0.0, 1.0, color="0.93", zorder=0, label="range of an index, 0 to 1")
        ax.bar(x - width / 2, result.S1[o, order], width, yerr=result.S1_conf[o, order], capsize=3,
               label="S1, first-order index: the parameter alone")
        ax.bar(x + width / 2, result.ST[o, order], width, yerr=result.ST_conf[o, order], capsize=3,
               label="ST, total index: alone and in interactions")
        ax.set_xticks(x, [result.names[j] for j in order], rotation=30, ha="right", fontsize=8)
        ax.set_ylabel("share of output variance")
        ax.set_title(output, fontsize=9)
        ax.grid(True, axis="y", alpha=0.3)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper center", ncol=2, fontsize=8, frameon=False,
               title=f"Sobol indices, N = {result.n}; whiskers: {conf} bootstrap intervals", title_fontsize=8)
    if noisy:
        fig.text(0.5, 1 - 0.78 / height, noisy[0].upper() + noisy[1:], ha="center", va="top", fontsize=7,
                 color="#b00020", wrap=True)
    return _save(fig, path, rect=(0, 0, 1, 1 - head / height))
