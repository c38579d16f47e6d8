"""Physical parameter estimation: the common estimator API, parameter spaces with bounded transformations,
the ``cappe.estimate/1`` result, and local uncertainty / identifiability."""

# SPEC 1 lazy loading: the estimators' modules import scipy.stats, scipy.signal, scipy.interpolate and sympy (about
# 1.3 s); they load on first use of a name, so that e.g. the CLI's method registry and its commands without
# estimation start at once. The imports below are for type checkers only; _MODULE maps each public name to them.
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from cappe.estimate._automated import (
        DAMPING_KINDS,
        AutomatedIdentification,
        DampingLeastSquares,
        ExactModalProblem,
        SubproblemResult,
        damping_least_squares,
        select_stiffness,
        solve_subproblem,
    )
    from cappe.estimate._base import Estimator, fit_least_squares
    from cappe.estimate._direct import DirectEstimator
    from cappe.estimate._feature_map import FeatureMapEstimator
    from cappe.estimate._hybrid import HybridEstimator
    from cappe.estimate._kalman import ExtendedKalmanEstimator, UnscentedKalmanEstimator
    from cappe.estimate._modal_updating import ModalUpdatingEstimator
    from cappe.estimate._one_step import FRFDerivatives, OneStepEstimator, OneStepFRFEstimator, frf_derivatives
    from cappe.estimate._registry import METHODS, estimator_class
    from cappe.estimate._resampling import (
        BootstrapResult,
        PosteriorSample,
        Profile,
        mcmc_posterior,
        parametric_bootstrap,
        profile_likelihood,
    )
    from cappe.estimate._result import ESTIMATE_FORMAT, ParameterEstimate, read_estimate, write_estimate
    from cappe.estimate._space import ParameterSpace
    from cappe.estimate._study import StudyResult, simulate_data, simulation_study
    from cappe.estimate._two_step import TwoStepTFEstimator, TwoStepZPKEstimator, model_transfer_functions
    from cappe.estimate._uncertainty import LocalUncertainty, jacobian_uncertainty
    from cappe.estimate._validation import (
        ValidationResult,
        find_set,
        model_receptance,
        summarize,
        validate_identification,
    )

__all__ = [
    "DAMPING_KINDS",
    "AutomatedIdentification",
    "DampingLeastSquares",
    "ExactModalProblem",
    "SubproblemResult",
    "ValidationResult",
    "damping_least_squares",
    "find_set",
    "model_receptance",
    "select_stiffness",
    "solve_subproblem",
    "summarize",
    "validate_identification",
    "ESTIMATE_FORMAT",
    "METHODS",
    "DirectEstimator",
    "ExtendedKalmanEstimator",
    "FeatureMapEstimator",
    "FRFDerivatives",
    "HybridEstimator",
    "ModalUpdatingEstimator",
    "OneStepEstimator",
    "OneStepFRFEstimator",
    "frf_derivatives",
    "UnscentedKalmanEstimator",
    "TwoStepTFEstimator",
    "TwoStepZPKEstimator",
    "model_transfer_functions",
    "estimator_class",
    "BootstrapResult",
    "PosteriorSample",
    "Profile",
    "mcmc_posterior",
    "parametric_bootstrap",
    "profile_likelihood",
    "Estimator",
    "LocalUncertainty",
    "ParameterEstimate",
    "ParameterSpace",
    "StudyResult",
    "simulate_data",
    "simulation_study",
    "fit_least_squares",
    "jacobian_uncertainty",
    "read_estimate",
    "write_estimate",
]

#: the private module (in this package) of each public name
_MODULE = {
    name: f"cappe.estimate.{module}"
    for module, names in {
        "_automated": "DAMPING_KINDS AutomatedIdentification DampingLeastSquares ExactModalProblem SubproblemResult"
        " damping_least_squares select_stiffness solve_subproblem",
        "_validation": "ValidationResult find_set model_receptance summarize validate_identification",
        "_result": "ESTIMATE_FORMAT ParameterEstimate read_estimate write_estimate",
        "_registry": "METHODS estimator_class",
        "_direct": "DirectEstimator",
        "_kalman": "ExtendedKalmanEstimator UnscentedKalmanEstimator",
        "_feature_map": "FeatureMapEstimator",
        "_one_step": "FRFDerivatives OneStepEstimator OneStepFRFEstimator frf_derivatives",
        "_hybrid": "HybridEstimator",
        "_modal_updating": "ModalUpdatingEstimator",
        "_two_step": "TwoStepTFEstimator TwoStepZPKEstimator model_transfer_functions",
        "_resampling": "BootstrapResult PosteriorSample Profile mcmc_posterior parametric_bootstrap profile_likelihood",
        "_base": "Estimator fit_least_squares",
        "_uncertainty": "LocalUncertainty jacobian_uncertainty",
        "_space": "ParameterSpace",
        "_study": "StudyResult simulate_data simulation_study",
    }.items()
    for name in names.split()
}


def __getattr__(name: str) -> Any:
    import importlib

    if name not in _MODULE:
        msg = f"module 'cappe.estimate' has no attribute {name!r}"
        raise AttributeError(msg)
    value = getattr(importlib.import_module(_MODULE[name]), name)
    globals()[name] = value  # once loaded, a plain module attribute
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
