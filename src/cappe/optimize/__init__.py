"""Search strategies for bounded minimization: multi-start local search (SLSQP or trust-region least squares),
DIRECT, differential evolution and dual annealing, with test functions of known minima (the six-hump camelback of
thesis Fig. 4.3 among them)."""

from cappe.optimize._minimize import STRATEGIES, LocalMinimum, OptimizationResult, SearchRecord, minimize
from cappe.optimize._test_functions import TEST_FUNCTIONS, BenchmarkFunction

__all__ = [
    "STRATEGIES",
    "TEST_FUNCTIONS",
    "BenchmarkFunction",
    "LocalMinimum",
    "OptimizationResult",
    "SearchRecord",
    "minimize",
]
