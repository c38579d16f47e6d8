"""Frequency axes of the Bode plot: readable tick labels on any span (issue 22: they overlapped on a model of one's
own, matplotlib labelling the minor ticks of a log axis under two decades as 2x10^1 3x10^1 ...)."""

from __future__ import annotations

import numpy as np
import pytest

from cappe.systems.frf import FRFData


def _frf(lo: float, hi: float) -> FRFData:
    freq = np.geomspace(lo, hi, 200)
    # a unit oscillator at the geometric centre of the span (any smooth FRF would do)
    fn = np.sqrt(lo * hi)
    h = 1.0 / (fn**2 - freq**2 + 0.02j * fn * freq)
    return FRFData(freq, h[None, None, :], ("F",), ("d",))


def _labels(monkeypatch: pytest.MonkeyPatch, frf: FRFData) -> list[tuple[str, object]]:
    import cappe.report.plots as plots

    captured = {}

    def keep(fig, path):
        captured["fig"] = fig
        return path

    monkeypatch.setattr(plots, "_save", keep)
    plots.bode_plot(frf, "unused.png", "test")
    fig = captured["fig"]
    fig.set_size_inches(7, 7)  # the size cappe's figures are written at (_plotting.figure(2))
    fig.tight_layout()
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    ax = fig.axes[-1]
    lo, hi = ax.get_xlim()
    shown = []
    for tick in [*ax.xaxis.get_major_ticks(), *ax.xaxis.get_minor_ticks()]:
        label = tick.label1
        if label.get_visible() and label.get_text() and lo <= tick.get_loc() <= hi:
            shown.append((label.get_text(), label.get_window_extent(renderer)))
    import matplotlib.pyplot as plt

    plt.close(fig)
    return shown


@pytest.mark.parametrize(("lo", "hi"), [(12.6, 732.0), (100.0, 150.0), (1.0, 1e5), (0.1, 2000.0), (30.0, 90.0)])
def test_bode_frequency_labels_do_not_overlap(monkeypatch, lo, hi):
    shown = _labels(monkeypatch, _frf(lo, hi))
    assert len(shown) >= 2 or hi / lo < 2  # a readable axis says where it is
    boxes = sorted((box.x0, box.x1, text) for text, box in shown)
    for (_, a1, left), (b0, _, right) in zip(boxes[:-1], boxes[1:], strict=True):
        assert a1 <= b0, f"tick labels {left!r} and {right!r} overlap on {lo:g}-{hi:g} Hz"
    assert all("times" not in text for text, _ in shown)  # plain numbers, not 2x10^1
