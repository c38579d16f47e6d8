"""From measurements to experimental models: excitation signals, FRF estimation, black-box models (ARX, ARMAX,
OE, BJ) with order selection and pruning, frequency-domain rational fits, modal extraction (LSCF / LSFD with
stabilization diagrams) and rigid-body motion reconstruction."""

from cappe.identify._lscf import PoleSelection, StabilizationDiagram, lscf_poles, select_poles, stabilization_diagram
from cappe.identify._lsfd import ModalExtraction, ModalFit, extract_modes, lsfd

__all__ = [
    "ModalExtraction",
    "ModalFit",
    "PoleSelection",
    "StabilizationDiagram",
    "extract_modes",
    "lscf_poles",
    "lsfd",
    "select_poles",
    "stabilization_diagram",
]
