"""cappe: computer-aided physical parameter estimation for machine structures."""

from cappe._version import __version__

__all__ = ["__version__"]
