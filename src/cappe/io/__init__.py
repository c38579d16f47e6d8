"""File contracts: JSON parameter files, modal data (cappe.modal/1) and atomic writes."""

from cappe.io.files import read_parameters, write_json, write_text
from cappe.io.modal import (
    MODAL_FORMAT,
    ModalData,
    ModalDataSet,
    modal_data_from_mapping,
    read_modal_data,
    write_modal_data,
)
from cappe.io.timedata import TimeData, check_clipping

__all__ = [
    "MODAL_FORMAT",
    "ModalData",
    "ModalDataSet",
    "TimeData",
    "check_clipping",
    "modal_data_from_mapping",
    "read_modal_data",
    "read_parameters",
    "write_json",
    "write_modal_data",
    "write_text",
]
