"""Sensitivity analysis: local (analytic) sensitivities, percentage tables, cost landscapes, Sobol' indices and
Morris screening of vectorized models, the model GSA per mode, position and criterion, and their plots."""

from cappe.sensitivity._gsa import CRITERIA, ModelSobolResult, model_sobol
from cappe.sensitivity._local import (
    CostLandscape,
    ModalCost,
    PercentageTable,
    cost_landscape,
    modal_sensitivity,
    percentage_table,
)
from cappe.sensitivity._morris import MorrisResult, morris_screening
from cappe.sensitivity._plots import landscape_plot, sobol_plot
from cappe.sensitivity._sobol import SobolResult, sobol_analyze, sobol_indices

__all__ = [
    "CRITERIA",
    "CostLandscape",
    "ModalCost",
    "ModelSobolResult",
    "MorrisResult",
    "PercentageTable",
    "SobolResult",
    "cost_landscape",
    "landscape_plot",
    "modal_sensitivity",
    "model_sobol",
    "morris_screening",
    "percentage_table",
    "sobol_analyze",
    "sobol_indices",
    "sobol_plot",
]
