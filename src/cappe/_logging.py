"""Library logging: cappe logs to the 'cappe' logger and never configures handlers itself."""

from __future__ import annotations

import logging

__all__ = ["get_logger"]


def get_logger(name: str) -> logging.Logger:
    """Return the logger for a cappe module (``name`` is the module's ``__name__``)."""
    return logging.getLogger(name if name.startswith("cappe") else f"cappe.{name}")
