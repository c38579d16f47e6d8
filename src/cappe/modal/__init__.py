"""Batched modal engine: natural frequencies, damping, shapes, exact complex modes, derivatives, tracking."""

from cappe.modal._batch import ModalBatch
from cappe.modal._derivatives import (
    ExactModeDerivatives,
    ModalDerivatives,
    exact_mode_derivatives,
    modal_derivatives,
    mode_derivative_terms,
)
from cappe.modal._engine import ModalEngine, ModeReference, modal_batch
from cappe.modal._reference import axis_positions, reference_frf, reference_modes, sensor_coordinates

__all__ = [
    "ExactModeDerivatives",
    "ModalBatch",
    "ModalDerivatives",
    "ModalEngine",
    "ModeReference",
    "axis_positions",
    "exact_mode_derivatives",
    "modal_batch",
    "modal_derivatives",
    "mode_derivative_terms",
    "reference_frf",
    "reference_modes",
    "sensor_coordinates",
]
