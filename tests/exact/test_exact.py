"""Exact algebra in ``cappe.exact`` checked against hand-derived closed forms and known ranks.

References: thesis eqs. 5.8-5.9 and 5.12 (two-mass rig) written out here as sympy expressions, the
dynamometer-plate finding of thesis Table 4.1 / Example 1, systems built to be uncontrollable, and
rational matrices whose rank is known by construction.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
import sympy as sp

from cappe.exact import (
    controllability_rank,
    exact_rank,
    exact_state_space,
    exact_transfer_function,
    float_rank,
    invertibility_matrix,
    observability_rank,
    sain_massey,
    symbolic_transfer_function,
    to_rational,
)
from cappe.exact.transfer import S
from cappe.model import NumericModel, StructureBuilder, derive, load_model
from cappe.model._expressions import symbol
from cappe.systems import transfer_function


@cache
def rig_symbolic():
    return derive(load_model("builtin:two-mass-rig"))


@cache
def plate_symbolic():
    return derive(load_model("builtin:dynamometer-plate"))


m1, m2, k11, k12, k22, c11, c12, c22 = (symbol(n) for n in ("m1", "m2", "k11", "k12", "k22", "c11", "c12", "c22"))

# thesis eq. 5.9: common monic denominator s^4 + a3 s^3 + a2 s^2 + a1 s + a0 of G11 and G21
THESIS_DEN = (
    sp.Integer(1),
    (c12 * m1 + c22 * m1 + c11 * m2 + c12 * m2) / (m1 * m2),
    (c11 * c12 + c11 * c22 + c12 * c22 + k12 * m1 + k22 * m1 + k11 * m2 + k12 * m2) / (m1 * m2),
    (c12 * k11 + c22 * k11 + c11 * k12 + c22 * k12 + c11 * k22 + c12 * k22) / (m1 * m2),
    (k11 * k12 + k11 * k22 + k12 * k22) / (m1 * m2),
)
# thesis eq. 5.8, G11 = d1/F1: b2 s^2 + b1 s + b0. The thesis prints b2 = 1/m2; the leading coefficient of
# c^T adj(Z) b / det Z is m2 / (m1 m2) = 1/m1 (drive-point mass line), so the test uses the corrected value.
THESIS_G11_NUM = (1 / m1, (c12 + c22) / (m1 * m2), (k12 + k22) / (m1 * m2))
# G21 = d2/F1: b1* s + b0*
THESIS_G21_NUM = (c12 / (m1 * m2), k12 / (m1 * m2))


def assert_expressions_equal(actual, expected) -> None:
    assert len(actual) == len(expected), f"{len(actual)} coefficients, expected {len(expected)}"
    for a, e in zip(actual, expected, strict=True):
        assert sp.simplify(sp.sympify(a) - e) == 0, f"{a} != {e}"


# ---------------------------------------------------------------------------------------------------
# thesis two-mass rig: symbolic transfer functions


def test_symbolic_g11_matches_thesis_eqs_5_8_and_5_9():
    tf = symbolic_transfer_function(rig_symbolic(), "F1", "d1")
    assert tf.kind == "symbolic"
    assert tf.cancelled == ()
    assert_expressions_equal(tf.denominator, THESIS_DEN)
    assert_expressions_equal(tf.numerator, THESIS_G11_NUM)
    # the misprinted value is really different (so the test can tell them apart)
    assert sp.simplify(tf.numerator[0] - 1 / m2) != 0


def test_symbolic_g21_matches_thesis():
    tf = symbolic_transfer_function(rig_symbolic(), "F1", "d2")
    assert_expressions_equal(tf.denominator, THESIS_DEN)
    assert_expressions_equal(tf.numerator, THESIS_G21_NUM)


def test_symbolic_g12_equals_g21_reciprocity():
    g12 = symbolic_transfer_function(rig_symbolic(), "F2", "d1")
    assert_expressions_equal(g12.numerator, THESIS_G21_NUM)
    assert_expressions_equal(g12.denominator, THESIS_DEN)


def test_symbolic_dc_gains_match_thesis_eq_5_12():
    delta = k11 * k12 + k11 * k22 + k12 * k22
    expected = {"d1": (k12 + k22) / delta, "d2": k12 / delta}
    for out, gain in expected.items():
        tf = symbolic_transfer_function(rig_symbolic(), "F1", out)
        assert sp.simplify(tf.numerator[-1] / tf.denominator[-1] - gain) == 0
        # numeric DC gain at the nominal values, float and exact paths
        nominal = {symbol(k): to_rational(v) for k, v in rig_symbolic().structure.nominal.items()}
        value = gain.xreplace(nominal)
        exact = exact_transfer_function(rig_symbolic(), "F1", out)
        assert sp.Rational(exact.numerator[-1]) / sp.Rational(exact.denominator[-1]) == value  # exact equality
        system = NumericModel(rig_symbolic()).system()
        # float K^-1 vs a rational evaluated in float: round-off only
        np.testing.assert_allclose(system.dc_gain("F1", out)[0, 0], float(value), rtol=1e-13)


@pytest.mark.parametrize(
    ("values", "out"),
    [
        (None, "d1"),
        (None, "d2"),
        ({"c12": 0.5, "m2": 1.2, "k22": 2.5e5}, "d1"),
        ({"c12": 0.5, "m2": 1.2, "k22": 2.5e5}, "d2"),
    ],
)
def test_exact_tf_equals_thesis_formulas_at_rational_values(values, out):
    structure = rig_symbolic().structure
    resolved = structure.resolve_parameters(values)
    subs = {symbol(k): to_rational(v) for k, v in resolved.items()}
    # decimals are read exactly: 1.39 -> 139/100, not the binary float
    assert subs[m1] == sp.Rational(139, 100)
    tf = exact_transfer_function(rig_symbolic(), "F1", out, values=values)
    assert tf.kind == "exact"
    num = THESIS_G11_NUM if out == "d1" else THESIS_G21_NUM
    expected_num = [sp.nsimplify(c.xreplace(subs)) for c in num]
    while expected_num and expected_num[0] == 0:  # c12 = 0 removes the s term of G21
        expected_num.pop(0)
    assert tuple(tf.numerator) == tuple(expected_num)
    assert tuple(tf.denominator) == tuple(c.xreplace(subs) for c in THESIS_DEN)
    assert all(isinstance(c, sp.Rational) for c in tf.numerator + tf.denominator)


def test_symbolic_tf_with_fixed_values_matches_partial_substitution():
    tf = symbolic_transfer_function(rig_symbolic(), "F1", "d1", values={"c12": 0, "m1": 2})
    subs = {c12: 0, m1: 2}
    assert_expressions_equal(tf.numerator, [c.xreplace(subs) for c in THESIS_G11_NUM])
    assert_expressions_equal(tf.denominator, [c.xreplace(subs) for c in THESIS_DEN])
    assert not tf.numerator[0].free_symbols


# ---------------------------------------------------------------------------------------------------
# dynamometer plate (thesis section 4.2, Table 4.1, Example 1)


def test_dynamometer_sain_massey_exact_vs_float():
    ss = exact_state_space(plate_symbolic())
    assert ss.A.shape == (12, 12)
    result = sain_massey(ss)
    assert result.matrix_shape == (78, 78)
    # exact: rank(M_{n-1}) = 60, rank(M_n) = 66, difference = m = 6 inputs -> invertible
    assert result.exact_ranks == (60, 66)
    assert result.invertible_exact
    # double precision: the entries span ~1e-3..1e14, the SVD rank collapses and says "not invertible"
    assert result.float_ranks != result.exact_ranks
    assert not result.invertible_float
    # the Sain-Massey matrix holds the Markov parameters D, C B, C A B: with displacement outputs of all six
    # coordinates and loads at the reference point, D = C B = 0 and C A B = M^-1 (hand-derived)
    mk = invertibility_matrix(ss, 2)
    nominal = {symbol(k): to_rational(v) for k, v in plate_symbolic().structure.nominal.items()}
    minv = plate_symbolic().M.xreplace(nominal).inv()
    assert mk[0:6, 0:6] == sp.zeros(6, 6)
    assert mk[6:12, 0:6] == sp.zeros(6, 6)
    assert mk[12:18, 0:6] == minv
    assert mk[12:18, 6:12] == sp.zeros(6, 6)  # block Toeplitz: (2, 1) = C B
    assert mk[0:6, 6:12] == sp.zeros(6, 6)  # lower triangular


def test_sain_massey_simple_cases():
    # SISO G11 (relative degree 2, non-zero): invertible, the rank grows by exactly m = 1
    siso = sain_massey(exact_state_space(rig_symbolic(), inputs=["F1"], outputs=["d1"]))
    assert siso.invertible_exact
    assert siso.exact_ranks[1] - siso.exact_ranks[0] == 1
    # d1 = 0 u, C B = 0, C A B = 1/m1, ...: the first Markov parameters give the ranks by hand: M_4 is
    # lower-triangular Toeplitz of (0, 0, 1/m1, x, y) so rank = 5 - 2 = 3, M_3 has rank 4 - 2 = 2
    assert siso.exact_ranks == (2, 3)
    # identically zero transfer function (force across the measured direction): never invertible
    zero = sain_massey(exact_state_space(twin_oscillators(), inputs=["F"], outputs=["dp"]))
    assert zero.exact_ranks == (0, 0)
    assert not zero.invertible_exact
    # more inputs than outputs: not left-invertible whatever the ranks
    wide = sain_massey(exact_state_space(rig_symbolic(), inputs=["F1", "F2"], outputs=["d1"]))
    assert not wide.invertible_exact
    assert not wide.invertible_float


def test_dynamometer_exact_tf_cancels_the_bounce_mode():
    sym = plate_symbolic()
    tf = exact_transfer_function(sym, "Fx", "x")
    assert (len(tf.numerator) - 1, len(tf.denominator) - 1) == (8, 10)
    assert len(tf.cancelled) == 1
    factor = sp.Poly(sp.sympify(tf.cancelled[0]), S)
    assert factor.degree() == 2
    # the vertical bounce mode (4 sensors in z): m s^2 + 4 cs s + 4 kn, hand-derived, up to a constant
    nominal = {k: to_rational(v) for k, v in sym.structure.nominal.items()}
    bounce = sp.Poly(nominal["m"] * S**2 + 4 * nominal["cs"] * S + 4 * nominal["kn"], S)
    assert sp.simplify(factor.as_expr() / bounce.as_expr()).is_number
    assert sp.rem(factor, bounce, S).is_zero

    # the float transfer function keeps the pole and the zero: orders (10, 12)
    system = NumericModel(sym).system()
    ftf = transfer_function(system.state_space("Fx", "x"), "Fx", "x")
    assert (len(ftf.numerator) - 1, len(ftf.denominator) - 1) == (10, 12)
    # ... at the bounce roots (float zero and pole both within 1e-6 relative of the exact root)
    bounce_roots = np.roots([float(c) for c in bounce.all_coeffs()])
    for root in bounce_roots:
        assert np.min(np.abs(ftf.poles() - root)) < 1e-6 * abs(root)
        assert np.min(np.abs(ftf.zeros() - root)) < 1e-6 * abs(root)
    # the reduced exact TF is the same function as cappe's second-order FRF solve: exact coefficients
    # rounded to float and evaluated by Horner (coefficients spanning ~45 decades) agree to ~1e-12 (observed)
    freq = np.array([50.0, 400.0, 1500.0, 2500.0, 3000.0, 6000.0])
    s = 2j * np.pi * freq
    num, den = tf.float_coefficients()
    np.testing.assert_allclose(np.polyval(num, s) / np.polyval(den, s), system.frf(freq, "Fx", "x").H[0, 0], rtol=1e-7)


@pytest.mark.parametrize("name", ["plate", "rig"])
def test_exact_state_space_equals_float_state_space(name):
    # the rig has velocity and acceleration outputs (C rows from A, a non-zero D)
    sym = plate_symbolic() if name == "plate" else rig_symbolic()
    ess = exact_state_space(sym)
    fss = NumericModel(sym).system().state_space()
    assert ess.output_names == fss.output_names
    assert ess.input_names == fss.input_names
    # exact rationals rounded once vs float assembly and Cholesky solves: 1e-12 relative of each matrix
    for exact, flt in ((ess.A, fss.A), (ess.B, fss.B), (ess.C, fss.C), (ess.D, fss.D)):
        arr = np.array(exact, dtype=float)
        np.testing.assert_allclose(flt, arr, rtol=1e-10, atol=1e-12 * max(np.abs(arr).max(), 1e-300))


def test_symbolic_state_space_substitutes_to_exact():
    sym = rig_symbolic()
    symbolic = exact_state_space(sym, symbolic=True)
    exact = exact_state_space(sym)
    nominal = {symbol(k): to_rational(v) for k, v in sym.structure.nominal.items()}
    for s_mat, e_mat in ((symbolic.A, exact.A), (symbolic.B, exact.B), (symbolic.C, exact.C), (symbolic.D, exact.D)):
        assert (s_mat.xreplace(nominal) - e_mat).applyfunc(sp.simplify) == sp.zeros(*e_mat.shape)
    # hand-written: acceleration a1 = (F1 - (k11 + k12) d1 + k12 d2 - (c11 + c12) v1 + c12 v2) / m1
    a1 = symbolic.output_names.index("a1")
    expected_row = sp.Matrix([[-(k11 + k12) / m1, k12 / m1, -(c11 + c12) / m1, c12 / m1]])
    assert (symbolic.C[a1, :] - expected_row).applyfunc(sp.simplify) == sp.zeros(1, 4)
    assert sp.simplify(symbolic.D[a1, symbolic.input_names.index("F1")] - 1 / m1) == 0
    assert symbolic.D[a1, symbolic.input_names.index("F2")] == 0


# ---------------------------------------------------------------------------------------------------
# controllability, observability and exact pole-zero cancellation


@cache
def twin_oscillators():
    """One body with x and y DOFs, identical springs and dampers: two uncoupled identical oscillators.

    The force acts along (3, 4, 0)/5 (rational direction cosines), so both oscillators are driven by the
    same signal: only the combination 3 x + 4 y is excited and the pair x, y is not controllable.
    """
    b = StructureBuilder("twin")
    b.parameter("m", 2.0, kind="mass")
    b.parameter("k", 8.0e3, kind="stiffness")
    b.parameter("c", 3.0, kind="damping")
    b.body("body", mass="m", dofs=["x", "y"])
    b.element("mount", bodies=("ground", "body"), stiffness={"x": "k", "y": "k"}, damping={"x": "c", "y": "c"})
    b.input("F", body="body", direction=[3, 4, 0])
    b.output("dx", quantity="displacement", body="body", direction="x")
    b.output("dy", quantity="displacement", body="body", direction="y")
    b.output("dq", quantity="displacement", body="body", direction=[3, 4, 0])  # along the force
    b.output("dp", quantity="displacement", body="body", direction=[4, -3, 0])  # across the force
    return derive(b.build())


def test_controllability_rank_of_uncontrollable_twin():
    sym = twin_oscillators()
    full = exact_state_space(sym, outputs=["dx", "dy"])
    n = full.A.rows
    assert n == 4
    # known: A = diag(A1, A1) with identical blocks and b = (3 b1, 4 b1)/5 -> rank [b, Ab, ...] = 2
    assert controllability_rank(full) == n - 2
    assert controllability_rank(full, exact=False) == n - 2  # well scaled, so float agrees here
    assert observability_rank(full) == n  # x and y both measured
    along = exact_state_space(sym, outputs=["dq"])
    assert observability_rank(along) == n - 2  # one direction measured, the other mode unobservable
    # an independent check of the known answer: the same ranks from sympy's own rank on the Kalman matrix
    kalman = sp.Matrix.hstack(full.B, full.A * full.B, full.A**2 * full.B, full.A**3 * full.B)
    assert kalman.rank() == n - 2


def test_controllability_full_for_two_mass_rig():
    ss = exact_state_space(rig_symbolic(), inputs=["F1"], outputs=["d2"])
    assert controllability_rank(ss) == 4
    assert observability_rank(ss) == 4


def test_exact_pole_zero_cancellation_twin():
    sym = twin_oscillators()
    mass, k, c = sp.Integer(2), sp.Integer(8000), sp.Integer(3)
    oscillator = mass * S**2 + c * S + k
    # x / F = (3/5) / (m s^2 + c s + k): the y oscillator cancels exactly from det Z = oscillator^2
    for out, gain in (("dx", sp.Rational(3, 5)), ("dy", sp.Rational(4, 5)), ("dq", sp.Integer(1))):
        tf = exact_transfer_function(sym, "F", out)
        assert len(tf.cancelled) == 1
        assert sp.simplify(sp.sympify(tf.cancelled[0]) / oscillator).is_number
        assert tuple(tf.numerator) == (gain / mass,)
        assert tuple(tf.denominator) == (1, c / mass, k / mass)
    # across the force nothing moves: the transfer function is identically 0
    zero = exact_transfer_function(sym, "F", "dp")
    assert tuple(zero.numerator) == (0,)
    # the float route keeps both oscillators (order 4) and cannot cancel: but it is the same function
    system = NumericModel(sym).system()
    ftf = transfer_function(system.state_space("F", "dx"), "F", "dx")
    assert len(ftf.denominator) - 1 == 4
    s = 2j * np.pi * np.array([1.0, 10.0, 30.0, 100.0])
    # round-off of the pole/zero/gain route with a double pole pair: ~1e-12 relative observed
    np.testing.assert_allclose(ftf.evaluate(s), 0.6 / (2 * s**2 + 3 * s + 8000), rtol=1e-9)


def test_symbolic_cancellation_twin():
    tf = symbolic_transfer_function(twin_oscillators(), "F", "dx")
    m, k, c = symbol("m"), symbol("k"), symbol("c")
    assert len(tf.cancelled) == 1
    # the printed factor uses the parameter names: parse it with cappe's (real) symbols
    factor = sp.sympify(tf.cancelled[0], locals={"m": m, "k": k, "c": c, "s": S})
    assert sp.simplify(factor / (m * S**2 + c * S + k)).is_number
    assert_expressions_equal(tf.numerator, (sp.Rational(3, 5) / m,))
    assert_expressions_equal(tf.denominator, (1, c / m, k / m))


def test_no_cancellation_reported_when_none_exists():
    tf = exact_transfer_function(rig_symbolic(), "F1", "d1", values={"c12": 0.5})
    assert tf.cancelled == ()
    assert len(tf.denominator) == 5


# ---------------------------------------------------------------------------------------------------
# exact vs float rank on wide-range rational matrices

E = sp.Integer(10) ** 12
e = sp.Rational(1, 10**12)

WIDE_RANGE = [
    # rows (E, 1, 0) and (1, e, 0) are proportional (E e = 1): rank 2 with the e diagonal; the float SVD
    # tolerance 3 eps 1e12 ~ 7e-4 swallows the singular value 1e-12
    pytest.param(sp.Matrix([[E, 1, 0], [1, e, 0], [0, 0, e]]), 2, id="proportional-rows"),
    # det [[E, E], [E, E + e]] = E e = 1 != 0: rank 2, but E + e == E in double precision
    pytest.param(sp.Matrix([[E, E, 0], [E, E + e, 0], [0, 0, 0]]), 2, id="cancelling-det"),
    # outer products u1 v1^T + u2 v2^T, entries 1e-24..1e24: rank 2 by construction
    pytest.param(
        sp.Matrix([E, 1, e, 1]) * sp.Matrix([[1, e, E, 1]]) + sp.Matrix([1, E, 1, e]) * sp.Matrix([[e, 1, 1, E]]),
        2,
        id="two-outer-products",
    ),
]


@pytest.mark.parametrize(("matrix", "rank"), WIDE_RANGE)
def test_exact_rank_of_wide_range_matrix(matrix, rank):
    assert exact_rank(matrix) == rank
    assert matrix.rank() == rank  # sympy's own exact rank agrees with the construction
    # scaling every entry by an exact rational does not change the exact rank
    assert exact_rank(matrix * sp.Rational(7, 3)) == rank


@pytest.mark.parametrize(("matrix", "rank"), WIDE_RANGE[:2])
def test_float_rank_gets_wide_range_matrix_wrong(matrix, rank):
    assert float_rank(matrix) != rank
    assert float_rank(np.array(matrix, dtype=float)) == float_rank(matrix)


def test_exact_rank_edge_cases():
    assert exact_rank(sp.zeros(0, 3)) == 0
    assert exact_rank(sp.zeros(3, 3)) == 0
    assert exact_rank(sp.eye(5) * e) == 5  # tiny but exactly non-zero
    assert float_rank(sp.eye(5) * e) == 5  # uniform scale: float SVD is scale-invariant here


def test_exact_tf_warns_and_drops_hysteretic_damping():
    b = StructureBuilder("lossy")
    b.parameter("m", 2.0, kind="mass")
    b.parameter("k", 8.0e3, kind="stiffness")
    b.parameter("eta", 0.05, kind="loss")
    b.body("body", mass="m", dofs=["x"])
    b.element("mount", bodies=("ground", "body"), stiffness={"x": "k"}, loss={"x": "eta"})
    b.input("F", body="body", direction="x")
    b.output("d", quantity="displacement", body="body", direction="x")
    sym = derive(b.build())
    # documented: hysteretic damping has no rational form; cappe warns and leaves it out
    with pytest.warns(UserWarning, match="hysteretic"):
        tf = exact_transfer_function(sym, "F", "d")
    assert tuple(tf.numerator) == (sp.Rational(1, 2),)
    assert tuple(tf.denominator) == (1, 0, 4000)
