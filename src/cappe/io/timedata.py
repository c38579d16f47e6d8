"""The former home of :class:`~cappe.systems.TimeData`, kept so that ``from cappe.io.timedata import TimeData``
still works: the type and its clipping check live in :mod:`cappe.systems.timedata`; ``cappe.io`` reads and writes
time data (:func:`~cappe.io.read_time_data`, :func:`~cappe.io.write_time_data`, UFF 58)."""

from cappe.systems.timedata import TimeData, check_clipping

__all__ = ["TimeData", "check_clipping"]
