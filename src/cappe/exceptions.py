"""Exceptions and warnings raised by cappe.

Every error raised at a public boundary is one of these, with a message that names the thing that was
wrong, the rule it broke and the value received.
"""

from __future__ import annotations

__all__ = [
    "ConvergenceWarning",
    "DataError",
    "DataWarning",
    "IllConditionedWarning",
    "ModelError",
    "NotFittedError",
]


class ModelError(ValueError):
    """A model description (file, builder call or parameter set) breaks a rule."""


class DataError(ValueError):
    """Measured or reference data cannot be used as given."""


class NotFittedError(ValueError, AttributeError):
    """An estimator was used before ``fit``."""


class ConvergenceWarning(UserWarning):
    """An iterative method stopped without meeting its convergence criterion."""


class IllConditionedWarning(UserWarning):
    """A numerical problem is so ill-conditioned that float results may be unreliable."""


class DataWarning(UserWarning):
    """Measured data can be used but looks suspect (clipped channel, low coherence, drift)."""
