"""Plots are written, non-trivial, and leave no temporary files."""

from __future__ import annotations

import numpy as np

from cappe.estimate import ParameterEstimate
from cappe.report import correlation_plot, response_plot, trajectory_plot


def _estimate():
    corr = np.array([[1.0, -0.8, np.nan], [-0.8, 1.0, np.nan], [np.nan, np.nan, 1.0]])
    return ParameterEstimate("one-step", ("m1", "k11", "c11"), np.ones(3), np.ones(3), np.ones((3, 2)), corr,
                             np.array([True, True, False]))


def test_estimation_plots_are_written(tmp_path):
    files = [
        correlation_plot(_estimate(), tmp_path / "corr.png"),
        trajectory_plot(np.arange(50) * 0.01, np.linspace(0.5, 1.0, 50)[:, None] * [1.0, 2.0], ["k11", "k22"],
                        tmp_path / "traj.png", truth=[1.0, 2.0]),
        response_plot(np.arange(20), np.ones((2, 20)), 2 * np.ones((2, 20)), np.ones((2, 20)), tmp_path / "r.png",
                      labels=["d1", "d2"], log=True),
    ]
    for path in files:
        assert path.stat().st_size > 5000  # a rendered figure, not an empty canvas
    assert sorted(p.name for p in tmp_path.iterdir()) == ["corr.png", "r.png", "traj.png"]


def test_sobol_bars_say_what_st_is_and_when_n_is_too_small(tmp_path, monkeypatch):
    # the bars were labelled "S1" and "ST" alone, and ST up to 2.7 was drawn without comment
    import cappe.sensitivity._plots as plots
    from cappe.sensitivity import SobolResult

    drawn = {}

    def keep(fig, path, **kwargs):
        drawn["texts"] = [t.get_text() for t in fig.texts]
        drawn["legend"] = [t.get_text() for lg in fig.legends for t in lg.get_texts()]
        drawn["title"] = [lg.get_title().get_text() for lg in fig.legends]
        return path

    monkeypatch.setattr(plots, "_save", keep)
    st = np.array([[2.7, 0.1, 0.0], [0.4, 0.5, 0.02]])
    noisy = SobolResult(0.8 * st, np.full(st.shape, 0.3), st, np.full(st.shape, 0.3), ("a", "b", "c"),
                        ("f1", "f2"), 16, 100, 0.95)
    plots.sobol_plot(noisy, tmp_path / "s.png")
    assert "ST, total index: alone and in interactions" in drawn["legend"]
    assert "S1, first-order index: the parameter alone" in drawn["legend"]
    assert drawn["title"] == ["Sobol indices, N = 16; whiskers: 95 % bootstrap intervals"]
    assert any(t.startswith("Too noisy to read at N = 16: 1 of 6 ST estimates lie outside [0, 1]")
               for t in drawn["texts"])
    quiet = SobolResult(0.8 * st / 3, np.full(st.shape, 0.02), st / 3, np.full(st.shape, 0.02), ("a", "b", "c"),
                        ("f1", "f2"), 4096, 100, 0.95)
    plots.sobol_plot(quiet, tmp_path / "s.png")
    assert not any("noisy" in t for t in drawn["texts"])
