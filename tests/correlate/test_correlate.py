"""Correlation criteria in ``cappe.correlate`` checked against independent references.

References: per-pair loops written out here from the published formulas (MAC; MACX and MACXP of Vacher,
Jacquier & Bucharles, ISMA 2010, in the form of eq. 4 of Ellinger & Zaeh 2022; FRAC of Heylen & Lammens;
CSAC/CSF of Dascotte and Zang et al.), closed forms derived by hand in the comments, and invariances
(swapping the sets, complex scaling of shapes, conjugate representation of a mode, sign convention of the
decay rate) as hypothesis properties.

Two published MACXP implementations are known to be wrong in one of two ways: only same-index pairs are
computed, or ``Re(lam)`` is used for ``|Re(lam)|`` in the denominator. ``test_macxp_matches_loop_reference_off_diagonal``
catches the first; the range, unit-diagonal and decay-sign tests catch the second.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from cappe.correlate import ModePairing, csac, csf, frac, mac, macx, macxp, macxp_paired, ndd, nfd, pair_modes
from cappe.exceptions import DataError

# Round-off: every criterion is a ratio of sums of O(n_sensors) products of O(1) numbers (shapes are
# scaled to a peak of 1 inside), so float64 errors stay within a few hundred ulp; 1e-12 leaves margin.
ROUND = 1e-12

# ---------------------------------------------------------------------------------------------------
# independent references and data


def mac_loop(a, x):
    out = np.empty((a.shape[1], x.shape[1]))
    for i in range(a.shape[1]):
        for j in range(x.shape[1]):
            out[i, j] = abs(np.vdot(a[:, i], x[:, j])) ** 2 / (np.vdot(a[:, i], a[:, i]).real * np.vdot(x[:, j], x[:, j]).real)
    return out


def macx_loop(a, x):
    out = np.empty((a.shape[1], x.shape[1]))
    for i in range(a.shape[1]):
        for j in range(x.shape[1]):
            ai, xj = a[:, i], x[:, j]
            num = (abs(np.vdot(ai, xj)) + abs(ai @ xj)) ** 2
            out[i, j] = num / ((np.vdot(ai, ai).real + abs(ai @ ai)) * (np.vdot(xj, xj).real + abs(xj @ xj)))
    return out


def macxp_loop(a, lam_a, x, lam_x):
    """Eq. (4) of Ellinger & Zaeh (2022), one pair at a time, for damped poles."""
    out = np.empty((a.shape[1], x.shape[1]))
    for i in range(a.shape[1]):
        for j in range(x.shape[1]):
            ai, xj, li, lj = a[:, i], x[:, j], lam_a[i], lam_x[j]
            num = (abs(np.vdot(ai, xj)) / abs(np.conj(li) + lj) + abs(ai @ xj) / abs(li + lj)) ** 2
            den_a = np.vdot(ai, ai).real / (2 * abs(li.real)) + abs(ai @ ai) / (2 * abs(li))
            den_x = np.vdot(xj, xj).real / (2 * abs(lj.real)) + abs(xj @ xj) / (2 * abs(lj))
            out[i, j] = num / (den_a * den_x)
    return out


def complex_shapes(rng, n_sensors, n_modes):
    return rng.standard_normal((n_sensors, n_modes)) + 1j * rng.standard_normal((n_sensors, n_modes))


def stable_poles(omega, zeta):
    omega, zeta = np.asarray(omega, dtype=float), np.asarray(zeta, dtype=float)
    return -zeta * omega + 1j * omega * np.sqrt(1 - zeta**2)


# hypothesis: shapes with entries in [-1, 1] and no near-zero column; poles with 1e-4 <= zeta <= 0.5
_entries = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)


@st.composite
def modal_sets(draw, n_sensors=None):
    n_s = draw(st.integers(1, 6)) if n_sensors is None else n_sensors
    n_m = draw(st.integers(1, 4))
    re = draw(hnp.arrays(float, (n_s, n_m), elements=_entries))
    im = draw(hnp.arrays(float, (n_s, n_m), elements=_entries))
    phi = re + 1j * im
    assume(np.all(np.max(np.abs(phi), axis=0) > 1e-3))
    omega = draw(hnp.arrays(float, n_m, elements=st.floats(1.0, 1e4)))
    zeta = draw(hnp.arrays(float, n_m, elements=st.floats(1e-4, 0.5)))
    return phi, stable_poles(omega, zeta)


@st.composite
def two_modal_sets(draw):
    n_s = draw(st.integers(1, 6))
    return draw(modal_sets(n_s)), draw(modal_sets(n_s))


FAST = settings(max_examples=50, deadline=None)

# ---------------------------------------------------------------------------------------------------
# MAC and MACX


def test_mac_matches_loop_reference():
    rng = np.random.default_rng(1)
    a, x = complex_shapes(rng, 6, 4), complex_shapes(rng, 6, 3)
    np.testing.assert_allclose(mac(a, x), mac_loop(a, x), rtol=ROUND, atol=0)  # ROUND: round-off only


def test_mac_closed_forms_and_1d_promotion():
    phi = np.array([[1.0, 1.0], [1.0, -1.0]])
    np.testing.assert_allclose(mac(phi, phi), np.eye(2), rtol=0, atol=ROUND)  # orthogonal shapes; round-off only
    # [1, 0] vs [1, 1]: 1^2 / (1 * 2) = 0.5; a 1-D array is one column and the result stays 2-D
    result = mac([1.0, 0.0], [1.0, 1.0])
    assert result.shape == (1, 1)
    np.testing.assert_allclose(result, [[0.5]], rtol=ROUND)  # ROUND: round-off only


def test_macx_matches_loop_reference_and_closed_forms():
    rng = np.random.default_rng(2)
    a, x = complex_shapes(rng, 5, 3), complex_shapes(rng, 5, 4)
    np.testing.assert_allclose(macx(a, x), macx_loop(a, x), rtol=ROUND, atol=0)  # ROUND: round-off only
    # [1, i] and [1, -i] describe the same real motion: MAC = |1 + (-i)(-i)|^2 / 4 = 0, MACX = (0 + 2)^2 / (2 * 2) = 1
    circ = np.array([1.0, 1.0j])
    np.testing.assert_allclose(mac(circ, circ.conj()), [[0.0]], atol=ROUND)  # ROUND: round-off only
    np.testing.assert_allclose(macx(circ, circ.conj()), [[1.0]], rtol=ROUND)  # ROUND: round-off only


@FAST
@given(sets=two_modal_sets())
def test_mac_and_macx_lie_in_unit_interval(sets):
    (a, _), (x, _) = sets
    for value in (mac(a, x), macx(a, x)):
        assert np.all(value >= 0)
        assert np.all(value <= 1 + ROUND)


@FAST
@given(sets=two_modal_sets())
def test_macx_equals_mac_for_real_shapes(sets):
    (a, _), (x, _) = sets
    a, x = a.real, x.real
    assume(np.all(np.max(np.abs(a), axis=0) > 1e-3) and np.all(np.max(np.abs(x), axis=0) > 1e-3))
    # real shapes: |a^T x| = |a^H x| and |a^T a| = a^H a, so MACX = (2|a^T x|)^2 / (2 a^T a 2 x^T x) = MAC
    np.testing.assert_allclose(macx(a, x), mac(a, x), rtol=1e-10, atol=ROUND)  # round-off only


# ---------------------------------------------------------------------------------------------------
# MACXP


def test_macxp_matches_loop_reference_off_diagonal():
    """All pairs, not only i == j: sets of different size and every entry against the loop."""
    rng = np.random.default_rng(3)
    a, x = complex_shapes(rng, 6, 4), complex_shapes(rng, 6, 3)
    lam_a = stable_poles([100.0, 104.0, 180.0, 260.0], [0.02, 0.05, 0.01, 0.03])
    lam_x = stable_poles([101.0, 175.0, 250.0], [0.03, 0.02, 0.04])
    result = macxp(a, lam_a, x, lam_x)
    reference = macxp_loop(a, lam_a, x, lam_x)
    assert result.shape == (4, 3)
    off_diagonal = ~np.eye(4, 3, dtype=bool)
    assert np.all(reference[off_diagonal] > 1e-4)  # the off-diagonal entries are not trivially zero
    np.testing.assert_allclose(result, reference, rtol=ROUND, atol=0)  # ROUND: round-off only


def test_macxp_with_itself_has_unit_diagonal_and_range_for_stable_poles():
    rng = np.random.default_rng(4)
    phi = complex_shapes(rng, 5, 4)
    lam = stable_poles([50.0, 51.0, 90.0, 200.0], [0.3, 0.01, 0.1, 0.05])
    result = macxp(phi, lam, phi, lam)
    np.testing.assert_allclose(np.diag(result), 1.0, rtol=ROUND)  # ROUND: round-off only
    assert np.all(result >= 0)
    assert np.all(result <= 1 + ROUND)


def test_macxp_does_not_depend_on_the_sign_convention_of_the_decay_rate():
    """``-s + i w`` and ``s + i w`` are the same mode; a signed ``Re(lam)`` in the denominator breaks this."""
    rng = np.random.default_rng(5)
    a, x = complex_shapes(rng, 4, 3), complex_shapes(rng, 4, 2)
    lam_a = stable_poles([10.0, 12.0, 30.0], [0.2, 0.1, 0.05])
    lam_x = stable_poles([11.0, 29.0], [0.15, 0.08])
    expected = macxp(a, lam_a, x, lam_x)
    for mirrored_a, mirrored_x in [(True, True), (True, False), (False, True)]:
        la = -lam_a.conj() if mirrored_a else lam_a
        lx = -lam_x.conj() if mirrored_x else lam_x
        np.testing.assert_allclose(macxp(a, la, x, lx), expected, rtol=ROUND, atol=0)  # ROUND: round-off only


def test_macxp_closed_form_for_real_shapes():
    """Real shapes: MACXP = MAC (g1 + g2)^2 / ((1 + zeta_a)(1 + zeta_x)), hand-derived from eq. (4).

    With s = zeta |lam|, a^H x = a^T x, a^H a = a^T a: numerator (|a^T x| (1/d1 + 1/d2))^2 and denominator
    a^T a x^T x (1 + zeta_a)(1 + zeta_x) / (4 s_a s_x), g = 2 sqrt(s_a s_x) / d, d1 = |conj(lam_a) + lam_x|,
    d2 = |lam_a + lam_x|.
    """
    a = np.array([1.0, 2.0, -1.0])
    x = np.array([1.0, 1.5, -0.5])
    w_a, z_a, w_x, z_x = 100.0, 0.02, 103.0, 0.05
    lam_a, lam_x = complex(stable_poles(w_a, z_a)), complex(stable_poles(w_x, z_x))
    root = 2 * np.sqrt(z_a * w_a * z_x * w_x)
    g1 = root / abs(np.conj(lam_a) + lam_x)
    g2 = root / abs(lam_a + lam_x)
    mac_value = (a @ x) ** 2 / ((a @ a) * (x @ x))
    expected = mac_value * (g1 + g2) ** 2 / ((1 + z_a) * (1 + z_x))
    np.testing.assert_allclose(macxp(a, lam_a, x, lam_x), [[expected]], rtol=ROUND)  # ROUND: round-off only
    assert 0 < expected < mac_value


def test_macxp_equals_mac_for_real_shapes_at_a_common_pole():
    # closed form above with lam_a = lam_x: g1 = 1, g2 = zeta, so MACXP = MAC (1 + zeta)^2 / (1 + zeta)^2
    rng = np.random.default_rng(6)
    a, x = rng.standard_normal((6, 4)), rng.standard_normal((6, 3))
    lam = complex(stable_poles(120.0, 0.3))
    result = macxp(a, np.full(4, lam), x, np.full(3, lam))
    np.testing.assert_allclose(result, mac(a, x), rtol=1e-10, atol=ROUND)  # round-off only


def test_macxp_of_well_separated_light_modes_vanishes_off_diagonal():
    """Real shapes, separated poles, zeta -> 0: MACXP_ij -> MAC_ij 4 zeta^2 w_i w_j (1/|w_i - w_j| + 1/(w_i + w_j))^2.

    Leading order of the closed form above (d1 -> |w_i - w_j|, d2 -> w_i + w_j); it is not the MAC.
    """
    rng = np.random.default_rng(7)
    phi = rng.standard_normal((6, 3))
    omega = np.array([100.0, 150.0, 300.0])
    zeta = 1e-4
    result = macxp(phi, stable_poles(omega, np.full(3, zeta)), phi, stable_poles(omega, np.full(3, zeta)))
    w_i, w_j = omega[:, None], omega[None, :]
    with np.errstate(divide="ignore"):
        leading = mac(phi, phi) * 4 * zeta**2 * w_i * w_j * (1 / np.abs(w_i - w_j) + 1 / (w_i + w_j)) ** 2
    off = ~np.eye(3, dtype=bool)
    np.testing.assert_allclose(result[off], leading[off], rtol=1e-3)  # next order is O(zeta) = 1e-4; 10x margin
    np.testing.assert_allclose(np.diag(result), 1.0, rtol=ROUND)  # ROUND: round-off only


@FAST
@given(sets=two_modal_sets())
def test_macxp_lies_in_unit_interval(sets):
    (a, lam_a), (x, lam_x) = sets
    result = macxp(a, lam_a, x, lam_x)
    assert np.all(result >= 0)
    assert np.all(result <= 1 + ROUND)


@FAST
@given(modes=modal_sets())
def test_macxp_of_a_set_with_itself_has_unit_diagonal(modes):
    phi, lam = modes
    np.testing.assert_allclose(np.diag(macxp(phi, lam, phi, lam)), 1.0, rtol=ROUND)  # ROUND: round-off only


@FAST
@given(sets=two_modal_sets())
def test_macxp_is_symmetric_under_swapping_the_sets(sets):
    (a, lam_a), (x, lam_x) = sets
    np.testing.assert_allclose(macxp(a, lam_a, x, lam_x), macxp(x, lam_x, a, lam_a).T, rtol=ROUND, atol=ROUND)  # round-off only


@FAST
@given(
    sets=two_modal_sets(),
    magnitude=st.floats(0.1, 10.0),
    phase=st.floats(-np.pi, np.pi),
)
def test_macxp_is_invariant_to_complex_scaling_of_each_shape(sets, magnitude, phase):
    (a, lam_a), (x, lam_x) = sets
    # a different factor per column: magnitude * e^{i phase} times 1, 2, 3, ...
    scale_a = magnitude * np.exp(1j * phase) * np.arange(1, a.shape[1] + 1)
    scale_x = np.exp(-2j * phase) / magnitude * np.arange(1, x.shape[1] + 1)
    # round-off: values near 0 carry absolute, not relative, errors
    np.testing.assert_allclose(
        macxp(a * scale_a, lam_a, x * scale_x, lam_x), macxp(a, lam_a, x, lam_x), rtol=1e-9, atol=ROUND
    )


@FAST
@given(sets=two_modal_sets())
def test_macxp_does_not_depend_on_which_member_of_a_conjugate_pair_is_given(sets):
    (a, lam_a), (x, lam_x) = sets
    expected = macxp(a, lam_a, x, lam_x)
    # (conj(phi), conj(lam)) swaps |a^H x| / |conj(lam_a) + lam_x| with |a^T x| / |lam_a + lam_x|
    np.testing.assert_allclose(macxp(a, lam_a, x.conj(), lam_x.conj()), expected, rtol=1e-10, atol=ROUND)  # round-off only
    np.testing.assert_allclose(macxp(a.conj(), lam_a.conj(), x, lam_x), expected, rtol=1e-10, atol=ROUND)  # round-off only


# undamped poles: the limit as damping -> 0


def test_macxp_undamped_coinciding_poles_give_mac():
    rng = np.random.default_rng(8)
    a, x = complex_shapes(rng, 5, 3), complex_shapes(rng, 5, 3)
    lam = 1j * np.array([10.0, 20.0, 30.0])
    result = macxp(a, lam, x, lam)
    # same pole: |a^H x|^2 / (a^H a x^H x); different undamped poles: 0
    np.testing.assert_allclose(result, np.diag(np.diag(mac(a, x))), rtol=ROUND, atol=0)  # ROUND: round-off only
    np.testing.assert_allclose(np.diag(macxp(a, lam, a, lam)), 1.0, rtol=ROUND)  # ROUND: round-off only
    # the other member of the conjugate pair: lam_x = conj(lam_a) brings |a^T x|^2 / (a^H a x^H x)
    np.testing.assert_allclose(macxp(a, lam, x.conj(), lam.conj()), result, rtol=ROUND, atol=0)  # ROUND: round-off only


def test_macxp_undamped_value_is_the_limit_of_equal_small_damping():
    rng = np.random.default_rng(9)
    a, x = complex_shapes(rng, 5, 3), complex_shapes(rng, 5, 3)
    lam = 1j * np.array([10.0, 20.0, 30.0])
    sigma = 1e-9
    # the difference is O(sigma / |lam|) = 1e-10; 1e-8 leaves two decades
    np.testing.assert_allclose(macxp(a, lam, x, lam), macxp(a, lam - sigma, x, lam - sigma), rtol=0, atol=1e-8)
    # along s_a = r s_x -> 0 the limit is 4 r / (1 + r)^2 times the MAC (r = 3: 0.75); hence the documented choice
    unequal = macxp(a, lam - 3 * sigma, x, lam - sigma)
    np.testing.assert_allclose(np.diag(unequal), 0.75 * np.diag(mac(a, x)), rtol=1e-8)  # O(sigma / |lam|) as above


def test_macxp_undamped_against_damped_is_zero():
    phi = np.array([1.0, 2.0])
    # undamped a: its denominator term a^H a / (2 |Re lam_a|) is infinite, the numerator finite
    assert macxp(phi, 10j, phi, -0.1 + 10j)[0, 0] == 0.0
    assert macxp(phi, -0.1 + 10j, phi, 10j)[0, 0] == 0.0


# ---------------------------------------------------------------------------------------------------
# NFD and NDD


def test_nfd_and_ndd_closed_forms_and_broadcasting():
    np.testing.assert_allclose(nfd([105.0, 190.0], [100.0, 200.0]), [0.05, 0.05], rtol=ROUND)  # ROUND: round-off only
    np.testing.assert_allclose(ndd([0.03, 0.01], 0.02), [0.5, 0.5], rtol=ROUND)  # ROUND: round-off only
    assert nfd([[1.0], [2.0]], [1.0, 4.0]).shape == (2, 2)
    # eq. (5) of Ellinger & Zaeh: NDD^2 = ((xi1 - xi2) / xi2)^2
    np.testing.assert_allclose(ndd(0.012, 0.01) ** 2, ((0.012 - 0.01) / 0.01) ** 2, rtol=ROUND)  # ROUND: round-off only


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: nfd([1.0, 2.0], [1.0, 0.0]), r"f_x \(reference frequency\) must be nonzero; got 0 at index \(1,\)"),
        (lambda: ndd(0.1, 0.0), r"zeta_x \(reference damping ratio\) must be nonzero; got 0 at index \(\)"),
        (lambda: nfd([np.nan], [1.0]), r"f_a must be finite \(no NaN or inf\); got nan at index \(0,\)"),
        (lambda: ndd([0.1], [1j]), r"zeta_x must be a real numeric array; got dtype complex128"),
        (lambda: nfd([1.0, 2.0], [1.0, 2.0, 3.0]), r"f_a with shape \(2,\) and f_x with shape \(3,\) do not broadcast"),
    ],
)
def test_nfd_ndd_errors(call, match):
    with pytest.raises(DataError, match=match):
        call()


# ---------------------------------------------------------------------------------------------------
# errors of the shape criteria


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: mac(np.ones((3, 2)), np.ones((4, 2))), r"phi_a and phi_x must have the same number of sensors \(rows\); got 3 and 4"),
        (lambda: mac(np.ones((2, 2, 2)), np.ones((2, 2))), r"phi_a must be 1-D \(one shape\) or 2-D \(n_sensors, n_modes\); got shape \(2, 2, 2\)"),
        (lambda: mac(np.ones((3, 2)), np.zeros((3, 0))), r"phi_x must hold at least one sensor and one mode; got shape \(3, 0\)"),
        (lambda: macx([[1.0, 0.0], [1.0, 0.0]], np.ones(2)), r"phi_a column 1 is all zeros; the criterion is undefined for a zero shape"),
        (lambda: mac([1.0, np.nan], [1.0, 1.0]), r"phi_a must be finite \(no NaN or inf\); got nan at index \(1,\)"),
        (lambda: mac(["a", "b"], [1.0, 1.0]), r"phi_a must be a real or complex numeric array; got dtype <U1"),
        (lambda: mac([[1.0], [1.0, 2.0]], [1.0, 1.0]), r"phi_a must be a numeric array; numpy cannot convert the list given"),
        (lambda: macxp(np.ones((2, 2)), [-1 + 1j], np.ones((2, 1)), [-1 + 1j]), r"lam_a must hold one pole per column of phi_a \(2\); got 1"),
        (lambda: macxp(np.ones((2, 1)), -1 + 1j, np.ones((2, 1)), [[-1 + 1j]]), r"lam_x must be 1-D \(n_modes,\); got shape \(1, 1\)"),
        (lambda: macxp(np.ones(2), [0.0], np.ones(2), [-1 + 1j]), r"lam_a\[0\] is 0; MACXP needs nonzero poles \(a zero pole is a rigid-body mode\)"),
        (lambda: macxp(np.ones(2), [-1 + 1j], np.ones(2), [complex(np.nan, 1.0)]), r"lam_x must be finite \(no NaN or inf\); got \(?nan\+1j\)? at index \(0,\)"),
    ],
)
def test_shape_criteria_errors(call, match):
    with pytest.raises(DataError, match=match):
        call()


# ---------------------------------------------------------------------------------------------------
# FRAC, CSAC, CSF


def frf_set(rng, n_out=4, n_in=2, n_freq=7):
    shape = (n_out, n_in, n_freq)
    return rng.standard_normal(shape) + 1j * rng.standard_normal(shape)


def test_frac_matches_loop_reference_and_scale_invariance():
    rng = np.random.default_rng(10)
    h_a, h_x = frf_set(rng), frf_set(rng)
    expected = np.empty(h_a.shape[:2])
    for o in range(h_a.shape[0]):
        for i in range(h_a.shape[1]):
            ha, hx = h_a[o, i], h_x[o, i]
            expected[o, i] = abs(np.sum(hx.conj() * ha)) ** 2 / (np.sum(abs(ha) ** 2) * np.sum(abs(hx) ** 2))
    np.testing.assert_allclose(frac(h_a, h_x), expected, rtol=ROUND)  # ROUND: round-off only
    # H_x = c H_a, c complex: |c|^2 S^2 / (S |c|^2 S) = 1
    np.testing.assert_allclose(frac(h_a, (0.3 - 2.0j) * h_a), 1.0, rtol=ROUND)  # ROUND: round-off only
    single = frac(h_a[0, 0], h_x[0, 0])
    assert single.shape == ()
    np.testing.assert_allclose(single, expected[0, 0], rtol=ROUND)  # ROUND: round-off only


@FAST
@given(
    h_a=hnp.arrays(complex, (3, 2, 5), elements=st.complex_numbers(max_magnitude=10.0, allow_nan=False)),
    h_x=hnp.arrays(complex, (3, 2, 5), elements=st.complex_numbers(max_magnitude=10.0, allow_nan=False)),
)
def test_frf_criteria_lie_in_unit_interval(h_a, h_x):
    assume(np.all(np.sum(np.abs(h_a) ** 2, axis=-1) > 1e-6) and np.all(np.sum(np.abs(h_x) ** 2, axis=-1) > 1e-6))
    assume(np.all(np.sum(np.abs(h_a) ** 2, axis=0) > 1e-6) and np.all(np.sum(np.abs(h_x) ** 2, axis=0) > 1e-6))
    for value in (frac(h_a, h_x), csac(h_a, h_x), csf(h_a, h_x)):
        assert np.all(value >= 0)
        assert np.all(value <= 1 + ROUND)


def test_csac_and_csf_match_loop_reference():
    rng = np.random.default_rng(11)
    h_a, h_x = frf_set(rng), frf_set(rng)
    n_in, n_freq = h_a.shape[1:]
    ref_csac, ref_csf = np.empty((n_in, n_freq)), np.empty((n_in, n_freq))
    for i in range(n_in):
        for k in range(n_freq):
            a, x = h_a[:, i, k], h_x[:, i, k]
            ref_csac[i, k] = abs(np.vdot(x, a)) ** 2 / (np.vdot(x, x).real * np.vdot(a, a).real)
            ref_csf[i, k] = 2 * abs(np.vdot(x, a)) / (np.vdot(x, x).real + np.vdot(a, a).real)
    np.testing.assert_allclose(csac(h_a, h_x), ref_csac, rtol=ROUND)  # ROUND: round-off only
    np.testing.assert_allclose(csf(h_a, h_x), ref_csf, rtol=ROUND)  # ROUND: round-off only
    # the CSAC is the MAC of the deflection shapes at each line
    np.testing.assert_allclose(csac(h_a, h_x)[1, 3], mac(h_x[:, 1, 3], h_a[:, 1, 3])[0, 0], rtol=ROUND)  # ROUND: round-off only
    # 2-D input (n_out, n_freq) is one input column
    np.testing.assert_allclose(csf(h_a[:, 1], h_x[:, 1]), ref_csf[1], rtol=ROUND)  # ROUND: round-off only


def test_csf_is_one_only_for_equal_amplitudes_and_csac_ignores_scale():
    rng = np.random.default_rng(12)
    h = frf_set(rng)
    np.testing.assert_allclose(csf(h, h), 1.0, rtol=ROUND)  # ROUND: round-off only
    np.testing.assert_allclose(csf(h, np.exp(0.7j) * h), 1.0, rtol=ROUND)  # a phase factor keeps |H|; round-off only
    np.testing.assert_allclose(csf(h, 2.0 * h), 0.8, rtol=ROUND)  # 2 * 2 / (1 + 4); round-off only
    c = 0.5 - 1.5j
    np.testing.assert_allclose(csf(h, c * h), 2 * abs(c) / (1 + abs(c) ** 2), rtol=ROUND)  # round-off only
    np.testing.assert_allclose(csac(h, c * h), 1.0, rtol=ROUND)  # ROUND: round-off only
    # one set zero at a line: CSF = 0 (defined), CSAC undefined
    zero = h.copy()
    zero[:, 0, 2] = 0.0
    assert csf(zero, h)[0, 2] == 0.0


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: frac(np.ones((2, 3)), np.ones((2, 4))), r"H_a and H_x must have the same shape; got \(2, 3\) and \(2, 4\)"),
        (lambda: frac(1.0, 1.0), r"H_a must be a non-empty array of shape \(\.\.\., n_freq\), e\.g\. \(n_out, n_in, n_freq\) or \(n_freq,\); got shape \(\)"),
        (lambda: frac([1.0, 1.0], [0.0, 0.0]), r"H_x is zero at all frequency lines for result index \(\); FRAC is undefined there"),
        (lambda: csac(np.ones(3), np.ones(3)), r"H_a must be a non-empty array of shape \(n_out, n_in, n_freq\) or \(n_out, n_freq\); got shape \(3,\)"),
        (lambda: csac(np.zeros((2, 2)), np.ones((2, 2))), r"H_a is zero at all outputs for result index \(0,\); CSAC is undefined there"),
        (lambda: csac(np.ones((2, 1, 2)), np.zeros((2, 1, 2))), r"H_x is zero at all outputs for result index \(0, 0\); CSAC is undefined there"),
        (lambda: csf(np.zeros((2, 1, 2)), np.zeros((2, 1, 2))), r"H_a and H_x are both zero at all outputs for result index \(0, 0\); CSF is undefined there"),
        (lambda: csf(np.ones((2, 2)), [[1.0, np.inf], [1.0, 1.0]]), r"H_x must be finite \(no NaN or inf\); got inf at index \(0, 1\)"),
    ],
)
def test_frf_criteria_errors(call, match):
    with pytest.raises(DataError, match=match):
        call()


# ---------------------------------------------------------------------------------------------------
# pairing


def test_pair_modes_recovers_a_permutation_of_a_subset():
    rng = np.random.default_rng(13)
    phi_x = rng.standard_normal((12, 5))
    order = np.array([3, 0, 4])  # set a holds three of the five modes, shuffled
    pairing = pair_modes(phi_a=phi_x[:, order] * [2.0, -1.0, 0.5], phi_x=phi_x)
    assert isinstance(pairing, ModePairing)
    assert pairing.criterion == "mac"
    np.testing.assert_array_equal(pairing.index_a, [0, 1, 2])
    np.testing.assert_array_equal(pairing.index_x, order)
    np.testing.assert_allclose(pairing.values, 1.0, rtol=ROUND)  # ROUND: round-off only
    np.testing.assert_array_equal(pairing.unpaired_a, [])
    np.testing.assert_array_equal(pairing.unpaired_x, [1, 2])
    assert pairing.matrix.shape == (3, 5)


def test_pair_modes_uses_poles_where_shapes_cannot_tell():
    """Two modes with equal shapes at 100 and 150 rad/s: MAC is 1 everywhere, MACXP pairs by pole."""
    shape = np.array([1.0, 0.5, -0.2])
    phi = np.column_stack([shape, shape])
    lam_x = stable_poles([100.0, 150.0], [0.02, 0.02])
    lam_a = stable_poles([151.0, 99.0], [0.02, 0.02])
    pairing = pair_modes(phi_a=phi, phi_x=phi, lam_a=lam_a, lam_x=lam_x)
    assert pairing.criterion == "macxp"
    np.testing.assert_array_equal(pairing.index_x, [1, 0])
    assert pair_modes(phi_a=phi, phi_x=phi, lam_a=lam_a, lam_x=lam_x, criterion="macxp").index_x.tolist() == [1, 0]
    assert pair_modes(phi_a=phi, phi_x=phi, criterion="macx").criterion == "macx"


def test_pair_modes_threshold_drops_pairs_and_maximizes_the_kept_total():
    matrix = np.array([[0.9, 0.8], [0.45, 0.0]])
    # raw optimum (0,1) + (1,0) = 1.25 would keep only 0.8 after dropping 0.45; the kept total is larger with (0,0)
    pairing = pair_modes(matrix=matrix, threshold=0.5)
    assert pairing.criterion == "matrix"
    np.testing.assert_array_equal(pairing.index_a, [0])
    np.testing.assert_array_equal(pairing.index_x, [0])
    np.testing.assert_array_equal(pairing.unpaired_a, [1])
    np.testing.assert_array_equal(pairing.unpaired_x, [1])
    everything = pair_modes(matrix=matrix, threshold=0.0)
    np.testing.assert_array_equal(everything.index_x, [1, 0])
    none = pair_modes(matrix=matrix, threshold=0.95)
    assert none.n_pairs == 0
    np.testing.assert_array_equal(none.unpaired_a, [0, 1])


def test_mode_pairing_to_dict_is_json_and_arrays_are_read_only():
    pairing = pair_modes(matrix=[[0.9, 0.1, 0.2], [0.1, 0.3, 0.7]], threshold=0.5)
    data = json.loads(json.dumps(pairing.to_dict()))
    assert data["pairs"] == [{"index_a": 0, "index_x": 0, "value": 0.9}, {"index_a": 1, "index_x": 2, "value": 0.7}]
    assert data["unpaired_a"] == []
    assert data["unpaired_x"] == [1]
    assert data["threshold"] == 0.5
    assert data["matrix"][1] == [0.1, 0.3, 0.7]
    with pytest.raises(ValueError, match="read-only"):
        pairing.index_a[0] = 1


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({}, r"pair_modes needs either matrix or both phi_a and phi_x; got neither"),
        ({"phi_a": np.eye(2)}, r"pair_modes needs either matrix or both phi_a and phi_x; got only one of phi_a and phi_x"),
        ({"matrix": np.eye(2), "phi_a": np.eye(2)}, r"matrix must be given alone: not with phi_a, phi_x, lam_a, lam_x or criterion"),
        ({"phi_a": np.eye(2), "phi_x": np.eye(2), "criterion": "macxp"}, r"criterion 'macxp' needs both lam_a and lam_x; got neither"),
        ({"phi_a": np.eye(2), "phi_x": np.eye(2), "lam_a": [-1 + 1j, -1 + 2j]}, r"lam_a and lam_x are only used by criterion 'macxp'; got criterion 'mac'"),
        ({"phi_a": np.eye(2), "phi_x": np.eye(2), "criterion": "comac"}, r"criterion must be one of \('mac', 'macx', 'macxp'\); got 'comac'"),
        ({"matrix": np.eye(2), "threshold": float("nan")}, r"threshold must be a finite real number; got nan"),
        ({"matrix": np.eye(2), "threshold": "high"}, r"threshold must be a finite real number; got 'high'"),
        ({"matrix": np.ones(3)}, r"matrix must be a non-empty 2-D array \(n_a, n_x\); got shape \(3,\)"),
        ({"matrix": [[1j]]}, r"matrix must be a real numeric array; got dtype complex128"),
        ({"matrix": [[np.nan]]}, r"matrix must be finite \(no NaN or inf\); got nan at index \(0, 0\)"),
    ],
)
def test_pair_modes_errors(kwargs, match):
    with pytest.raises(DataError, match=match):
        pair_modes(**kwargs)


def test_macxp_paired_is_the_diagonal_of_macxp_over_a_batch():
    rng = np.random.default_rng(11)
    phi_a = rng.normal(size=(4, 6, 3)) + 1j * rng.normal(size=(4, 6, 3))
    phi_x = rng.normal(size=(6, 3)) + 1j * rng.normal(size=(6, 3))
    lam_a = -rng.uniform(0.5, 5, size=(4, 3)) + 1j * rng.uniform(50, 500, size=(4, 3))
    lam_x = -rng.uniform(0.5, 5, size=3) + 1j * rng.uniform(50, 500, size=3)
    paired = macxp_paired(phi_a, lam_a, phi_x, lam_x)
    assert paired.shape == (4, 3)
    for b in range(4):
        # same formula, evaluated as an outer product: equal to round-off
        np.testing.assert_allclose(paired[b], np.diag(macxp(phi_a[b], lam_a[b], phi_x, lam_x)), rtol=1e-13)


@pytest.mark.parametrize("reference", ["complex", "real", "one complex mode"])
def test_macxp_batch_of_real_shapes_matches_macxp_including_undamped_limits(reference):
    # the batch form evaluates real model shapes in squared weights; it must give macxp's values, also where
    # poles are undamped (0 / 0 limits: equal undamped poles give the MAC, different ones 0)
    from cappe.correlate import macxp_batch

    rng = np.random.default_rng(21)
    n_b, n_s, m_a, m_x = 5, 9, 6, 4
    a = rng.standard_normal((n_b, n_s, m_a))
    lam_a = -rng.uniform(0.1, 5.0, (n_b, m_a)) + 1j * rng.uniform(10.0, 100.0, (n_b, m_a))
    x = rng.standard_normal((n_s, m_x)) + 1j * 0.2 * rng.standard_normal((n_s, m_x))
    lam_x = -rng.uniform(0.1, 5.0, m_x) + 1j * rng.uniform(10.0, 100.0, m_x)
    lam_a[0, 2] = 1j * lam_a[0, 2].imag  # undamped, and a reference pole equal to it
    lam_x[1] = lam_a[0, 2]
    lam_a[1, 3] = 1j * 55.0  # undamped against damped references: 0
    a[2, :, 4] = x[:, 0].real  # the same shape and pole: 1
    lam_a[2, 4] = lam_x[0]
    if reference == "real":
        x = x.real.copy()
    elif reference == "one complex mode":
        x, lam_x = x[:, 1:2], lam_x[1:2]
    got = macxp_batch(a, lam_a, x, lam_x)
    want = np.stack([macxp(a[k], lam_a[k], x, lam_x).T for k in range(n_b)])
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-15)
    if reference != "one complex mode":
        assert got[1, :, 3].max() == 0.0
        assert got[0, 1, 2] == pytest.approx(mac(a[0][:, [2]], x[:, [1]])[0, 0], rel=1e-13)
    if reference == "real":
        assert got[2, 0, 4] == pytest.approx(1.0, rel=1e-13)


def test_macxp_batch_takes_integer_shapes():
    from cappe.correlate import macxp_batch

    rng = np.random.default_rng(4)
    shapes = rng.integers(-3, 4, (2, 4, 3))
    lam_a = -rng.uniform(0.1, 1.0, (2, 3)) + 1j * rng.uniform(10.0, 20.0, (2, 3))
    x = rng.standard_normal((4, 2)) + 0.1j
    lam_x = -rng.uniform(0.1, 1.0, 2) + 1j * rng.uniform(10.0, 20.0, 2)
    want = np.stack([macxp(shapes[k].astype(float), lam_a[k], x, lam_x).T for k in range(2)])
    np.testing.assert_allclose(macxp_batch(shapes, lam_a, x, lam_x), want, rtol=1e-13, atol=1e-15)
