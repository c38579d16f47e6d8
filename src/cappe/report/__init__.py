"""Plots, animations and reports."""

from cappe.report.animation import animate_mode_shape, animate_motion
from cappe.report.html import write_html_report
from cappe.report.plots import (
    bode_plot,
    correlation_plot,
    frf_plot,
    landscape_plot,
    pole_zero_plot,
    preload_map_plot,
    pruning_plot,
    response_plot,
    sobol_plot,
    stabilization_plot,
    trajectory_plot,
)

__all__ = [
    "animate_mode_shape",
    "animate_motion",
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
    "write_html_report",
]
