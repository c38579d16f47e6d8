"""Method names of ``cappe.estimate/1`` files and the CLI, mapped to estimator classes, with the data each takes."""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["METHODS", "estimator_class"]

#: method name -> (module, class name, kind of data its ``fit`` takes)
METHODS: dict[str, tuple[str, str, str]] = {
    "direct": ("cappe.estimate._direct", "DirectEstimator", "time"),
    "two-step-tf": ("cappe.estimate._two_step", "TwoStepTFEstimator", "time"),
    "two-step-zp": ("cappe.estimate._two_step", "TwoStepZPKEstimator", "time"),
    "one-step": ("cappe.estimate._one_step", "OneStepEstimator", "time"),
    "one-step-frf": ("cappe.estimate._one_step", "OneStepFRFEstimator", "frf"),
    "ekf": ("cappe.estimate._kalman", "ExtendedKalmanEstimator", "time"),
    "ukf": ("cappe.estimate._kalman", "UnscentedKalmanEstimator", "time"),
    "feature-map": ("cappe.estimate._feature_map", "FeatureMapEstimator", "modal"),
    "modal": ("cappe.estimate._modal_updating", "ModalUpdatingEstimator", "modal"),
    "hybrid": ("cappe.estimate._hybrid", "HybridEstimator", "time"),
    "automated-gsa": ("cappe.estimate._automated", "AutomatedIdentification", "modal"),
}


def estimator_class(method: str) -> Any:
    """The estimator class of a method name; unknown names list the known ones.

    Parameters
    ----------
    method : str
        A key of :data:`METHODS` (``"direct"``, ``"one-step"``, ``"modal"`` ...).

    Returns
    -------
    type
        The :class:`~cappe.estimate.Estimator` subclass (its module is imported on first use).

    Raises
    ------
    ModelError
        ``method`` is not registered.

    Examples
    --------
    >>> estimator_class("modal").__name__
    'ModalUpdatingEstimator'
    """
    from cappe.exceptions import ModelError

    try:
        module, name, _ = METHODS[method]
    except KeyError:
        msg = f"unknown estimation method {method!r}; choose from {', '.join(METHODS)}"
        raise ModelError(msg) from None
    return getattr(importlib.import_module(module), name)
