"""Representations of linear mechanical systems: matrices, state space, transfer functions, ZPK, modes, FRFs."""

from cappe.systems.frf import FRFData
from cappe.systems.mechanical import MechanicalSystem
from cappe.systems.modal import ModalSet
from cappe.systems.statespace import StateSpaceModel, simulate
from cappe.systems.transfer import TransferFunctionModel, transfer_function
from cappe.systems.zpk import ZeroPoleGainModel, zpk

__all__ = [
    "FRFData",
    "MechanicalSystem",
    "ModalSet",
    "StateSpaceModel",
    "TransferFunctionModel",
    "ZeroPoleGainModel",
    "simulate",
    "transfer_function",
    "zpk",
]
