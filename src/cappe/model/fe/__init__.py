"""Finite-element matrices for flexible bodies: a 3-D frame generator, Craig-Bampton reduction, matrix files."""

from cappe.model.fe._files import read_matrix
from cappe.model.fe._frame import BeamSection, FrameModel, beam_element_matrices, frame_from_spec, frame_model
from cappe.model.fe._reduction import ReducedModel, craig_bampton

__all__ = [
    "BeamSection",
    "FrameModel",
    "ReducedModel",
    "beam_element_matrices",
    "craig_bampton",
    "frame_from_spec",
    "frame_model",
    "read_matrix",
]
