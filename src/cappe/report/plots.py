"""Plots (matplotlib, written to files): Bode diagrams, pole-zero maps, cost landscapes, sensitivity bars."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from cappe._plotting import figure as _figure
from cappe._plotting import log_frequency_axis as _log_frequency_axis
from cappe._plotting import save as _save
from cappe.sensitivity import landscape_plot, sobol_plot
from cappe.systems.frf import FRFData
from cappe.systems.zpk import ZeroPoleGainModel

__all__ = [
    "bode_plot",
    "correlation_plot",
    "frf_plot",
    "landscape_plot",
    "pole_zero_plot",
    "preload_map_plot",
    "pruning_plot",
    "response_plot",
    "sobol_plot",
    "stabilization_plot",
    "trajectory_plot",
]


def bode_plot(frf: FRFData, path: str | Path, title: str = "") -> Path:
    """Bode magnitude (dB re 1 unit) and phase (deg) of every output/input pair, written to ``path``.

    Parameters
    ----------
    frf : FRFData
        The FRFs.
    path : str or Path
        Image file to write (format from the extension: .png, .svg, .pdf ...).
    title : str
        Figure title (none when empty).

    Returns
    -------
    Path
        ``path``.
    """
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
    _log_frequency_axis(ax_phase, float(np.min(frf.freq[frf.freq > 0], initial=np.inf)), float(np.max(frf.freq)))
    ax_mag.legend(loc="best", fontsize=8)
    ax_mag.grid(True, which="both", alpha=0.3)
    ax_phase.grid(True, which="both", alpha=0.3)
    if title:
        ax_mag.set_title(title)
    return _save(fig, path)


def frf_plot(frf: FRFData, path: str | Path, title: str = "", *, coherence_threshold: float = 0.8) -> Path:
    """Measured FRFs: magnitude, phase and (when estimated) coherence of every output/input pair.

    The coherence panel marks ``coherence_threshold``; frequency axis linear in Hz, magnitude on a log scale.

    Parameters
    ----------
    frf : FRFData
        The FRFs (with coherence for the third panel).
    path : str or Path
        Image file to write (format from the extension: .png, .svg, .pdf ...).
    title : str
        Figure title (none when empty).
    coherence_threshold : float
        Coherence level marked in the coherence panel (0..1).

    Returns
    -------
    Path
        ``path``.
    """
    rows = 3 if frf.coherence is not None else 2
    fig, axes = _figure(rows)
    for o, out in enumerate(frf.output_names):
        for i, inp in enumerate(frf.input_names):
            h = frf.H[o, i]
            (line,) = axes[0].semilogy(frf.freq, np.abs(h) + 1e-300, lw=1, label=f"{out}/{inp}")
            axes[1].plot(frf.freq, np.degrees(np.angle(h)), lw=0.8, color=line.get_color())
            if frf.coherence is not None:
                axes[2].plot(frf.freq, frf.coherence[o, i], lw=0.8, color=line.get_color())
    axes[0].set_ylabel("|H|")
    axes[1].set_ylabel("phase (deg)")
    axes[1].set_yticks([-180, -90, 0, 90, 180])
    if frf.coherence is not None:
        axes[2].axhline(coherence_threshold, color="0.4", ls="--", lw=0.8)
        axes[2].set_ylim(0, 1.05)
        axes[2].set_ylabel("coherence")
    axes[-1].set_xlabel("frequency (Hz)")
    axes[0].legend(loc="best", fontsize=8)
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
    if title:
        axes[0].set_title(title)
    return _save(fig, path)


_FLAG_STYLE = {
    "s": ("o", "tab:green", "stable (frequency, damping, vector)"),
    "v": ("^", "tab:blue", "stable frequency and vector"),
    "d": ("s", "tab:orange", "stable frequency and damping"),
    "f": ("d", "tab:purple", "stable frequency"),
    "o": ("+", "0.5", "new / unstable"),
}


def stabilization_plot(
    diagram: Any, path: str | Path, *, frf: FRFData | None = None, selected: Any = None, title: str = ""
) -> Path:
    """Stabilization diagram: poles per model order over frequency, marked by stability, over the FRF magnitude.

    ``diagram`` is a :class:`cappe.identify.StabilizationDiagram`; ``frf`` adds the sum of |H| over all pairs
    (right axis, log) and ``selected`` (a :class:`cappe.identify.PoleSelection` or anything with ``frequency``)
    draws the chosen physical poles as vertical lines. Excluded poles are not drawn.

    Parameters
    ----------
    diagram : StabilizationDiagram
        The poles per order with their flags.
    path : str or Path
        Image file to write (format from the extension: .png, .svg, .pdf ...).
    frf : FRFData, optional
        FRFs drawn behind the poles.
    selected : PoleSelection, optional
        The chosen poles (frequencies in Hz).
    title : str
        Figure title (none when empty).

    Returns
    -------
    Path
        ``path``.
    """
    fig, axes = _figure(1)
    ax = axes
    for flag, (marker, color, label) in _FLAG_STYLE.items():
        idx = np.flatnonzero(np.asarray(diagram.flags) == flag)
        if idx.size:
            filled = marker != "+"
            style = {"c": color, "edgecolors": "k", "linewidths": 0.3} if filled else {"c": color, "linewidths": 0.8}
            ax.scatter(diagram.frequency[idx], diagram.order[idx], marker=marker, s=18, label=label, **style)
    if selected is not None:
        for k, f in enumerate(np.atleast_1d(selected.frequency)):
            ax.axvline(float(f), color="tab:red", lw=0.8, ls=":", label="selected" if k == 0 else None)
    ax.set_xlim(*diagram.band)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("model order")
    if frf is not None:
        twin = ax.twinx()
        inside = (frf.freq >= diagram.band[0]) & (frf.freq <= diagram.band[1])
        total = np.abs(frf.H).sum(axis=(0, 1))
        twin.semilogy(frf.freq[inside], total[inside] + 1e-300, color="0.3", lw=0.8)
        twin.set_ylabel("sum |H|")
        ax.set_zorder(twin.get_zorder() + 1)  # poles above the FRF curve
        ax.patch.set_visible(False)
    ax.legend(loc="upper left", fontsize=7)
    ax.grid(True, alpha=0.3)
    ax.set_title(title or f"stabilization diagram ({diagram.reference} LSCF)")
    return _save(fig, path)


def pole_zero_plot(model: ZeroPoleGainModel, path: str | Path, title: str = "") -> Path:
    """Pole-zero map in the s-plane (rad/s), written to ``path``.

    Parameters
    ----------
    model : ZeroPoleGainModel
        Poles and zeros in rad/s.
    path : str or Path
        Image file to write (format from the extension: .png, .svg, .pdf ...).
    title : str
        Figure title (none when empty).

    Returns
    -------
    Path
        ``path``.
    """
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


_RULE_MARKERS = {
    "cutoff": "v", "cancellation": "D", "damping": "s", "real": ">", "min_peak": "^", "n_modes": "^",
    "with_pole": "d", "properness": "<", "unstable": "*",
}


def pruning_plot(pruned: Any, path: str | Path, title: str = "") -> Path:
    """Pole-zero map of a pruned high-order model: kept roots bold, removed roots faint and marked by rule.

    ``pruned`` is a :class:`cappe.identify.PrunedModel`; coordinates are continuous-time (rad/s). The unpruned
    model is the union of kept and removed roots.

    Parameters
    ----------
    pruned : PrunedModel
        The pruned model.
    path : str or Path
        Image file to write (format from the extension: .png, .svg, .pdf ...).
    title : str
        Figure title (none when empty).

    Returns
    -------
    Path
        ``path``.
    """
    fig, ax = _figure(1)
    removed = list(pruned.removed_poles) + list(pruned.removed_zeros)
    rules = sorted({r.rule for r in removed})
    for rule in rules:
        for kind, face in (("pole", "0.55"), ("zero", "none")):
            roots = np.array([r.value for r in removed if r.rule == rule and r.kind == kind], dtype=complex)
            roots = roots[np.isfinite(roots)]  # a root at z = 0 maps to -inf in the s-plane
            if roots.size:
                ax.scatter(roots.real, roots.imag, marker=_RULE_MARKERS.get(rule, "."), s=22, facecolors=face,
                           edgecolors="0.55", linewidths=0.7, label=f"removed {kind}s: {rule}")
    kept_p = np.array([r.value for r in pruned.poles], dtype=complex)
    kept_z = np.array([r.value for r in pruned.zeros], dtype=complex)
    ax.plot(kept_p.real, kept_p.imag, "x", color="tab:red", markersize=10, mew=2, label="kept poles")
    if kept_z.size:
        ax.plot(kept_z.real, kept_z.imag, "o", mfc="none", color="tab:blue", markersize=9, mew=2, label="kept zeros")
    ax.axvline(0, color="0.6", lw=0.8)
    ax.axhline(0, color="0.6", lw=0.8)
    ax.set_xlabel("real (rad/s)")
    ax.set_ylabel("imaginary (rad/s)")
    ax.legend(loc="best", fontsize=7)
    ax.grid(True, alpha=0.3)
    ax.set_title(title or f"pruned model: {kept_p.size} of {kept_p.size + len(pruned.removed_poles)} poles kept")
    return _save(fig, path)


def correlation_plot(estimate: Any, path: str | Path, title: str = "") -> Path:
    """The correlation matrix of a :class:`cappe.estimate.ParameterEstimate` (non-identifiable entries blank).

    Parameters
    ----------
    estimate : ParameterEstimate
        The estimate (its ``names`` and ``correlation``).
    path : str or Path
        Image file to write (format from the extension: .png, .svg, .pdf ...).
    title : str
        Figure title (none when empty).

    Returns
    -------
    Path
        ``path``.
    """
    fig, ax = _figure(1)
    corr = np.asarray(estimate.correlation, dtype=float)
    image = ax.imshow(np.ma.masked_invalid(corr), cmap="RdBu_r", vmin=-1, vmax=1)
    fig.colorbar(image, ax=ax, label="correlation")
    names = list(estimate.names)
    ax.set_xticks(range(len(names)), names, rotation=45, ha="right", fontsize=8)
    ax.set_yticks(range(len(names)), names, fontsize=8)
    for i in range(len(names)):
        for j in range(len(names)):
            if np.isfinite(corr[i, j]) and i != j:
                ax.text(j, i, f"{corr[i, j]:.2f}", ha="center", va="center", fontsize=7)
    ax.set_title(title or f"{estimate.method}: parameter correlation")
    return _save(fig, path)


def trajectory_plot(
    time: Any, trajectories: Any, names: Any, path: str | Path, *, truth: Any = None, title: str = ""
) -> Path:
    """Parameter estimates over time (e.g. an EKF's), each relative to its final value or to ``truth``.

    Parameters
    ----------
    time : array_like, shape (n_t,)
        Time in s.
    trajectories : array_like, shape (n_t, n)
        Estimates over time (SI).
    names : sequence of str
        The n parameters.
    path : str or Path
        Image file to write (format from the extension: .png, .svg, .pdf ...).
    truth : array_like, shape (n,), optional
        Reference values (SI; default the final estimates).
    title : str
        Figure title (none when empty).

    Returns
    -------
    Path
        ``path``.
    """
    fig, ax = _figure(1)
    values = np.asarray(trajectories, dtype=float)
    ref = np.asarray(truth, dtype=float) if truth is not None else values[-1]
    for k, name in enumerate(names):
        ax.plot(time, values[:, k] / ref[k], lw=1, label=name)
    ax.axhline(1.0, color="0.4", lw=0.8, ls="--")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("estimate / truth" if truth is not None else "estimate / final value")
    ax.legend(loc="best", fontsize=7, ncol=2)
    ax.grid(True, alpha=0.3)
    ax.set_title(title or "parameter trajectories")
    return _save(fig, path)


def response_plot(
    x: Any, measured: Any, before: Any, after: Any, path: str | Path, *, labels: Any, xlabel: str = "time (s)",
    log: bool = False, title: str = "",
) -> Path:
    """Measured response against the model's before and after estimation, one panel per channel.

    ``measured``, ``before`` and ``after`` are (n_channels, n_points) real arrays (magnitudes for FRFs, ``log=True``).

    Parameters
    ----------
    x : array_like, shape (n_points,)
        Abscissa (time in s, or frequency in Hz).
    measured, before, after : array_like, shape (n_channels, n_points)
        Measured response and the model's before and after estimation (channel units).
    path : str or Path
        Image file to write (format from the extension: .png, .svg, .pdf ...).
    labels : sequence of str
        Channel names, one panel each.
    xlabel : str
        Abscissa label.
    log : bool
        Logarithmic ordinate.
    title : str
        Figure title (none when empty).

    Returns
    -------
    Path
        ``path``.
    """
    rows = len(labels)
    fig, axes = _figure(rows)
    axes = np.atleast_1d(axes)
    for ax, label, m, b, a in zip(axes, labels, measured, before, after, strict=True):
        plot = ax.semilogy if log else ax.plot
        plot(x, m, color="0.3", lw=1.2, label="measured")
        plot(x, b, color="tab:orange", lw=0.9, ls="--", label="model before")
        plot(x, a, color="tab:blue", lw=0.9, label="model after")
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="best", fontsize=7)
    axes[-1].set_xlabel(xlabel)
    if title:
        axes[0].set_title(title)
    return _save(fig, path)


def preload_map_plot(preload_map: Any, path: str | Path, title: str = "") -> Path:
    """Frequency-damping map over preload (thesis Fig. 5.30): one trace per mode, preloads labelled in %.

    Parameters
    ----------
    preload_map : PreloadMap
        Frequencies (Hz) and damping ratios of the modes over the preloads.
    path : str or Path
        Image file to write (format from the extension: .png, .svg, .pdf ...).
    title : str
        Figure title (none when empty).

    Returns
    -------
    Path
        ``path``.
    """
    fig, axes = _figure(1)
    ax = axes
    for j, mode in enumerate(preload_map.modes):
        f, z = preload_map.frequency[:, j], 100 * preload_map.damping[:, j]
        ax.plot(f, z, "o-", ms=4, label=f"mode {mode}")
        for k in (0, len(f) // 2, len(f) - 1):
            ax.annotate(f"{100 * preload_map.preload[k]:.0f} %", (f[k], z[k]), fontsize=7, xytext=(3, 3),
                        textcoords="offset points")
    ax.set_xlabel("natural frequency (Hz)")
    ax.set_ylabel("damping ratio (%)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax.set_title(title or "frequency-damping map over preload")
    return _save(fig, path)
