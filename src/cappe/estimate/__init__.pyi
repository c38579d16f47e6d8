"""Names and types of :mod:`cappe.estimate`: its ``__init__.py`` loads each name on first use from the module
imported here (lazy_loader reads these imports); type checkers read the imports and ``__all__``."""

from ._automated import DAMPING_KINDS, AutomatedIdentification
from ._automated_result import (
    AutomatedResult,
    AutomatedSettings,
    GSAStage,
    IdentificationValidation,
    JointRefinement,
    RefinementRun,
    SensitivityOutput,
    StiffnessRefinement,
    StiffnessSearch,
)
from ._base import CostFunction, Estimator, Fitted, fit_least_squares, least_squares_fit
from ._damping_least_squares import DampingLeastSquares, damping_least_squares
from ._direct import DirectEstimator
from ._exact_modal import ExactModalProblem
from ._feature_map import FeatureMapEstimator
from ._frf_refinement import FRFRefinement, FRFRefinementProblem, MeasuredFRF, refine_against_frf
from ._hybrid import HybridEstimator
from ._kalman import ExtendedKalmanEstimator, UnscentedKalmanEstimator
from ._modal_updating import ModalUpdatingEstimator
from ._one_step import FRFDerivatives, OneStepEstimator, OneStepFRFEstimator, frf_derivatives
from ._plan import PLAN_FORMAT, MeasurementPlan, PlanCandidates, plan_fisher, plan_test
from ._registry import METHODS, estimator_class
from ._resampling import (
    BootstrapResult,
    PosteriorSample,
    Profile,
    mcmc_posterior,
    parametric_bootstrap,
    profile_likelihood,
)
from ._result import ESTIMATE_FORMAT, ParameterEstimate, read_estimate, write_estimate
from ._space import ParameterSpace
from ._study import StudyResult, simulate_data, simulation_study
from ._subproblems import StiffnessChoice, SubproblemResult, select_stiffness, solve_subproblem
from ._two_step import TwoStepTFEstimator, TwoStepZPKEstimator, model_transfer_functions
from ._uncertainty import LocalUncertainty, jacobian_uncertainty
from ._validation import ValidationResult, find_set, model_receptance, summarize, validate_identification

__all__ = [
    "DAMPING_KINDS",
    "AutomatedIdentification",
    "AutomatedResult",
    "AutomatedSettings",
    "GSAStage",
    "IdentificationValidation",
    "JointRefinement",
    "RefinementRun",
    "SensitivityOutput",
    "StiffnessChoice",
    "StiffnessRefinement",
    "StiffnessSearch",
    "DampingLeastSquares",
    "ExactModalProblem",
    "FRFRefinement",
    "FRFRefinementProblem",
    "MeasuredFRF",
    "refine_against_frf",
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
    "CostFunction",
    "Estimator",
    "LocalUncertainty",
    "ParameterEstimate",
    "ParameterSpace",
    "StudyResult",
    "simulate_data",
    "simulation_study",
    "fit_least_squares",
    "Fitted",
    "least_squares_fit",
    "jacobian_uncertainty",
    "read_estimate",
    "write_estimate",
    "PLAN_FORMAT",
    "MeasurementPlan",
    "PlanCandidates",
    "plan_fisher",
    "plan_test",
]
