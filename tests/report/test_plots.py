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
