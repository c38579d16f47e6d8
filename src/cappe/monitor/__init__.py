"""Monitoring: preload studies (frequency-damping maps, FRFs over preload, sensor visibility) and the
quasi-static bearing stiffness test."""

from cappe.monitor._preload import THESIS_PRELOADS, PreloadMap, preload_frfs, preload_map, sensor_visibility
from cappe.monitor._static import StaticBearingTest, static_bearing_stiffness

__all__ = [
    "THESIS_PRELOADS",
    "PreloadMap",
    "StaticBearingTest",
    "preload_frfs",
    "preload_map",
    "sensor_visibility",
    "static_bearing_stiffness",
]
