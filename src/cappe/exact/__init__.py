"""Exact rational and symbolic algebra: transfer-function coefficients, ranks, invertibility, cancellations."""

from cappe.exact.check import EXACT_STATE_LIMIT, ModelCheck, check_model
from cappe.exact.rank import (
    InvertibilityResult,
    PBHRanks,
    controllability_rank,
    exact_rank,
    float_rank,
    invertibility_matrix,
    observability_rank,
    pbh_ranks,
    sain_massey,
)
from cappe.exact.rational import ExactStateSpace, exact_state_space, to_rational
from cappe.exact.transfer import exact_transfer_function, symbolic_transfer_function

__all__ = [
    "EXACT_STATE_LIMIT",
    "ExactStateSpace",
    "InvertibilityResult",
    "ModelCheck",
    "PBHRanks",
    "check_model",
    "controllability_rank",
    "exact_rank",
    "exact_state_space",
    "exact_transfer_function",
    "float_rank",
    "invertibility_matrix",
    "observability_rank",
    "pbh_ranks",
    "sain_massey",
    "symbolic_transfer_function",
    "to_rational",
]
