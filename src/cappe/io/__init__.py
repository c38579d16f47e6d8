"""File contracts: JSON parameter files and atomic writes."""

from cappe.io.files import read_parameters, write_json, write_text

__all__ = ["read_parameters", "write_json", "write_text"]
