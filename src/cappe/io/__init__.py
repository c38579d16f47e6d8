"""File contracts: JSON parameter files, modal data (cappe.modal/1), time data and FRFs (UFF 58, CSV, npz), UFF 55
modes and UFF 15/2411 nodes, all written atomically; sensor maps (``channel,sensor`` CSV)."""

from cappe.io.files import read_parameters, write_json, write_text
from cappe.io.lvm import read_lvm_time_data
from cappe.io.measurements import (
    FRF_NPZ_FORMAT,
    MEASUREMENT_FORMATS,
    TIME_NPZ_FORMAT,
    match_channels,
    read_frf,
    read_measurements,
    read_time_data,
    write_frf,
    write_time_data,
)
from cappe.io.modal import (
    MODAL_FORMAT,
    ModalData,
    ModalDataSet,
    modal_data_from_mapping,
    read_modal_data,
    write_modal_data,
)
from cappe.io.sensor_map import apply_sensor_map, channel_sign, map_channels, map_modal_data, read_sensor_map
from cappe.io.uff import (
    UFF_FORMAT,
    read_uff_frf,
    read_uff_modal,
    read_uff_nodes,
    read_uff_time_data,
    write_uff_frf,
    write_uff_modal,
    write_uff_nodes,
    write_uff_time_data,
)
from cappe.systems.timedata import TimeData, check_clipping

__all__ = [
    "FRF_NPZ_FORMAT",
    "MEASUREMENT_FORMATS",
    "MODAL_FORMAT",
    "TIME_NPZ_FORMAT",
    "UFF_FORMAT",
    "ModalData",
    "ModalDataSet",
    "TimeData",
    "apply_sensor_map",
    "channel_sign",
    "check_clipping",
    "map_channels",
    "map_modal_data",
    "match_channels",
    "modal_data_from_mapping",
    "read_frf",
    "read_lvm_time_data",
    "read_measurements",
    "read_modal_data",
    "read_parameters",
    "read_sensor_map",
    "read_time_data",
    "read_uff_frf",
    "read_uff_modal",
    "read_uff_nodes",
    "read_uff_time_data",
    "write_frf",
    "write_json",
    "write_modal_data",
    "write_text",
    "write_time_data",
    "write_uff_frf",
    "write_uff_modal",
    "write_uff_nodes",
    "write_uff_time_data",
]
