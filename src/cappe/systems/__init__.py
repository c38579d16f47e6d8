"""Representations of linear mechanical systems (matrices, state space, transfer functions, ZPK, modes, FRFs) and the
data types measured or simulated responses are handed around in (FRFs, time data, modes)."""

from cappe.systems.frf import FRFData
from cappe.systems.mechanical import MechanicalSystem
from cappe.systems.modal import ModalData, ModalDataSet, ModalSet, dominant_dofs
from cappe.systems.statespace import StateSpaceModel, simulate
from cappe.systems.timedata import TimeData, check_clipping
from cappe.systems.timeresponse import OUTPUT_UNITS, time_response
from cappe.systems.transfer import TransferFunctionModel, transfer_function
from cappe.systems.zpk import ZeroPoleGainModel, zpk

__all__ = [
    "FRFData",
    "OUTPUT_UNITS",
    "MechanicalSystem",
    "ModalData",
    "ModalDataSet",
    "ModalSet",
    "StateSpaceModel",
    "TimeData",
    "TransferFunctionModel",
    "ZeroPoleGainModel",
    "check_clipping",
    "dominant_dofs",
    "simulate",
    "time_response",
    "transfer_function",
    "zpk",
]
