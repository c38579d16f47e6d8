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
from cappe.parallel import ship_once

# a Dask executor sends an engine to each worker once, not with every map (its per-position caches stay here)
ship_once(ModalEngine, caches=("_sensor_cache", "_group_cache", "_nominal_cache", "_stacked_cache", "_fused_cache",
                               "_state_cache"))

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
