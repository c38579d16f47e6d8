"""Plots and reports."""

from cappe.report.plots import bode_plot, landscape_plot, pole_zero_plot, sobol_plot

__all__ = ["bode_plot", "landscape_plot", "pole_zero_plot", "sobol_plot"]
