"""pbh_ranks against python-control's Krylov ranks, hand-built uncontrollable systems and the exact ranks."""

from __future__ import annotations

from types import SimpleNamespace

import control
import numpy as np
import pytest

from cappe.exact import PBHRanks, controllability_rank, exact_state_space, observability_rank, pbh_ranks
from cappe.model import NumericModel, derive, load_model


def oscillators(omegas, zeta=0.02):
    """Uncoupled unit-mass oscillators, x = [q, q']."""
    n = len(omegas)
    w = np.diag(np.asarray(omegas, dtype=float))
    return np.block([[np.zeros((n, n)), np.eye(n)], [-(w**2), -2 * zeta * w]])


def control_ranks(a, b, c):
    """Ranks of python-control's controllability and observability matrices (exact enough for 6 states of O(1))."""
    return int(np.linalg.matrix_rank(control.ctrb(a, b))), int(np.linalg.matrix_rank(control.obsv(a, c)))


@pytest.mark.parametrize(
    ("omegas", "b", "c", "expected"),
    [
        # force on oscillators 1 and 2, displacement of 3: each sees two oscillators' worth of states
        ([1.0, 2.0, 3.0], [[0, 0, 0, 1, 1, 0]], [[0, 0, 1, 0, 0, 0]], (4, 2)),
        # every oscillator driven and seen: complete
        ([1.0, 2.0, 3.0], [[0, 0, 0, 1, 1, 1]], [[1, 1, 1, 0, 0, 0]], (6, 6)),
        # two identical oscillators and one force: a repeated pole pair, one direction of it reachable
        ([2.0, 2.0], [[0, 0, 1, 1]], [[1, 0, 0, 0], [0, 1, 0, 0]], (2, 4)),
        # a velocity sensor on an undriven oscillator
        ([1.0, 3.0], [[0, 0, 1, 0]], [[0, 0, 0, 1]], (2, 2)),
    ],
)
def test_pbh_ranks_equal_python_control_krylov_ranks(omegas, b, c, expected):
    a = oscillators(omegas)
    b = np.array(b, dtype=float).T
    c = np.array(c, dtype=float)
    assert control_ranks(a, b, c) == expected
    ranks = pbh_ranks(SimpleNamespace(A=a, B=b, C=c))
    assert ranks == PBHRanks(*expected)
    assert ranks.to_dict() == {"controllability_rank": expected[0], "observability_rank": expected[1]}


def test_pbh_ranks_are_invariant_to_a_change_of_state_coordinates():
    rng = np.random.default_rng(3)
    a = oscillators([1.0, 2.0, 3.0])
    b = np.array([[0, 0, 0, 1, 1, 0]], dtype=float).T
    c = np.array([[0, 0, 1, 0, 0, 0]], dtype=float)
    t = rng.normal(size=(6, 6)) + 6 * np.eye(6)  # well conditioned
    ti = np.linalg.inv(t)
    assert pbh_ranks(SimpleNamespace(A=ti @ a @ t, B=ti @ b, C=c @ t)) == PBHRanks(4, 2)


@pytest.mark.parametrize("name", ["two-mass-rig", "spindle-bearing"])
def test_pbh_ranks_equal_the_exact_ranks_of_builtin_models(name):
    structure = load_model(f"builtin:{name}")
    numeric = NumericModel(structure)
    ss = numeric.system().state_space()
    exact = exact_state_space(derive(structure), structure.nominal)
    assert pbh_ranks(ss) == PBHRanks(controllability_rank(exact), observability_rank(exact))
