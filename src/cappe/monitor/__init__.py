"""Monitoring: preload studies (frequency-damping maps, FRFs over preload, sensor visibility)."""

from cappe.monitor._preload import THESIS_PRELOADS, PreloadMap, preload_frfs, preload_map, sensor_visibility

__all__ = ["THESIS_PRELOADS", "PreloadMap", "preload_frfs", "preload_map", "sensor_visibility"]
