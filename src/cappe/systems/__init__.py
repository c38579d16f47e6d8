"""Representations of linear mechanical systems: matrices, state space, transfer functions, ZPK, modes, FRFs."""

from cappe.systems.frf import FRFData
from cappe.systems.mechanical import MechanicalSystem
from cappe.systems.modal import ModalSet
from cappe.systems.statespace import StateSpaceModel, simulate
from cappe.systems.timeresponse import OUTPUT_UNITS, time_response
from cappe.systems.transfer import TransferFunctionModel, transfer_function
from cappe.systems.zpk import ZeroPoleGainModel, zpk

__all__ = [
    "FRFData",
    "OUTPUT_UNITS",
    "MechanicalSystem",
    "ModalSet",
    "StateSpaceModel",
    "TransferFunctionModel",
    "ZeroPoleGainModel",
    "simulate",
    "time_response",
    "transfer_function",
    "zpk",
]
