"""Batched modal engine: natural frequencies, damping, shapes, exact complex modes, derivatives, tracking."""

from cappe.modal._batch import ModalBatch
from cappe.modal._derivatives import ModalDerivatives, modal_derivatives
from cappe.modal._engine import ModalEngine, ModeReference, modal_batch

__all__ = ["ModalBatch", "ModalDerivatives", "ModalEngine", "ModeReference", "modal_batch", "modal_derivatives"]
