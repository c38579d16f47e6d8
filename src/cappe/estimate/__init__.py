"""Physical parameter estimation: the common estimator API, parameter spaces with bounded transformations,
the ``cappe.estimate/1`` result, and local uncertainty / identifiability."""

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
from cappe.estimate._validation import ValidationResult, find_set, model_receptance, summarize, validate_identification

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
