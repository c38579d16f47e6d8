"""Plots and reports."""

from cappe.report.plots import bode_plot, pole_zero_plot

__all__ = ["bode_plot", "pole_zero_plot"]
