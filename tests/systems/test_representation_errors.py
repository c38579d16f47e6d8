"""Masses and stiffnesses beyond what double precision resolves: a ModelError naming the model file and the body,
or the correct answer, never NaN, inf or a wrong rigid-body mode (issue 18)."""

from __future__ import annotations

import numpy as np
import pytest

from cappe.exceptions import ModelError
from cappe.model import NumericModel, StructureBuilder, load_model
from cappe.systems import MechanicalSystem, transfer_function


def chain(masses, stiffnesses, damping=(0.0, 0.0)):
    """Two masses in a chain: ground -k1- m1 -k2- m2 (no k1 if it is None: free-free), dampers beside the springs."""
    b = StructureBuilder("chain", source="chain.yaml")
    b.parameter("m1", masses[0], kind="mass")
    b.parameter("m2", masses[1], kind="mass")
    b.parameter("k2", stiffnesses[1], kind="stiffness")
    b.parameter("c1", damping[0], kind="damping")
    b.parameter("c2", damping[1], kind="damping")
    b.body("a", mass="m1", dofs=["x"])
    b.body("b", mass="m2", dofs=["x"])
    if stiffnesses[0] is None:
        b.element("e1", bodies=("ground", "a"), damping={"x": "c1"})
    else:
        b.parameter("k1", stiffnesses[0], kind="stiffness")
        b.element("e1", bodies=("ground", "a"), stiffness={"x": "k1"}, damping={"x": "c1"})
    b.element("e2", bodies=("a", "b"), stiffness={"x": "k2"}, damping={"x": "c2"})
    b.input("F", body="a", direction="x")
    b.output("d", body="a", direction="x")
    return NumericModel(b.build()).system()


def closed_form(m, k):
    """Natural frequencies (Hz) of the undamped chain with equal masses and springs: w^2 = (k / m) (3 -+ sqrt 5) / 2."""
    return np.sqrt(k / m * (3 + np.array([-1.0, 1.0]) * np.sqrt(5)) / 2) / (2 * np.pi)


def test_masses_far_apart_lose_a_mode_and_say_so_instead_of_calling_it_rigid():
    # 1e-200 and 1e200 kg: the squared frequencies differ by 1e400; the lower one is below round-off of the higher,
    # and no rigid-body mode exists (both masses are held by springs)
    system = chain((1e-200, 1e200), (2e6, 2e6))
    match = (r"^chain\.yaml, bodies\[1\] \(b\.x\): a mode is taken for a rigid-body mode because its natural frequency "
             r"is below 1e-6 of the highest .* but it is not one: the model's masses, stiffnesses, damping or spin span "
             r"too many orders of magnitude for double precision \(mass matrix diagonal 1e-200 to 1e\+200")
    for damping in ("undamped", "first-order", "exact"):
        with pytest.raises(ModelError, match=match):
            system.modes(damping)
    # masses 1e11 apart: the lower squared frequency, 2.5e-12 of the higher, is taken for a rigid-body mode at
    # first; it is not one, and double precision still resolves it (to about eps / 2.5e-12 = 1e-4)
    m, k = 1e11, 2e6
    system = chain((1.0, m), (k, k))
    a, b, c = m, -(k + 2 * k * m), k * k  # m1 m2 w^4 - (m1 k2 + m2 (k1 + k2)) w^2 + k1 k2, m1 = 1
    low = 2 * c / (-b + np.sqrt(b * b - 4 * a * c))  # the smaller root, without cancellation
    modes = system.modes("undamped")
    assert not modes.rigid.any()
    np.testing.assert_allclose(modes.omega[0] ** 2, low, rtol=1e-3)  # 1e-4 expected; 1e-3 leaves room
    # a free-free pair (no spring to ground), masses 3e6 apart: its zero mode is a rigid-body mode and passes
    system = chain((3.0, 1.0e-6), (None, 2.0e6))
    modes = system.modes("undamped")
    assert modes.rigid.tolist() == [True, False]
    np.testing.assert_allclose(modes.frequency[1], np.sqrt(2e6 * (1 / 3 + 1e6)) / (2 * np.pi), rtol=1e-9)


@pytest.mark.parametrize("mass", [1e300, 1e-300])
def test_extreme_masses_give_the_right_undamped_frequencies_or_a_named_error(mass):
    system = chain((mass, mass), (2e6, 2e6), damping=(30.0, 30.0))
    want = closed_form(mass, 2e6)
    # the undamped problem is well scaled (K / M); 1e-12: LAPACK's eigh on a 2 x 2 generalized problem
    np.testing.assert_allclose(system.modes("undamped").frequency, want, rtol=1e-12)
    # the exact complex modes see the unit block of the state matrix next to K / M (or, at 1e-300 kg, damping
    # ratios of 1e148 spreading the poles over 1e297): they cannot resolve the modes and say so
    with pytest.raises(ModelError, match=r"^chain\.yaml, bodies\[\d\] \([ab]\.x\): the exact complex modes cannot "
                                         r"resolve 2 elastic mode\(s\) from .* Hz \(undamped\)"):
        system.modes("exact")


def test_a_stiffness_near_the_largest_double_overflows_the_state_matrix_with_a_named_error():
    system = chain((1e-3, 1e-3), (1e306, 1e306))
    with pytest.raises(ModelError, match=r"^chain\.yaml, bodies\[\d\] \([ab]\.x\): the state matrix \(M\^-1 K, M\^-1 C\) "
                                         r"overflows"):
        system.state_space()


def test_a_frequency_response_that_overflows_names_the_frequency():
    system = chain((1.0, 1.0), (2e6, 2e6))
    h = system.frf([10.0, 1e150]).H  # w^2 m = 4e300: finite
    assert np.isfinite(h).all()
    with pytest.raises(ModelError, match=r"^chain\.yaml: the frequency response is not finite at 1e\+160 Hz"):
        system.frf([10.0, 1e160])  # w^2 m = 4e320: beyond double precision


def test_a_system_built_with_nan_says_which_matrix():
    good = chain((1.0, 1.0), (2e6, 2e6))
    k = good.K.copy()
    k[1, 0] = np.nan
    bad = MechanicalSystem(**{**good.__dict__, "K": k})
    for compute in (bad.undamped_modes, bad.modes, bad.state_space, lambda: bad.frf([10.0])):
        with pytest.raises(ModelError, match=r"^chain\.yaml: matrix K has the non-finite entry nan at \[1, 0\]$"):
            compute()


def test_transfer_function_that_cannot_be_computed_is_an_error_not_nan():
    system = chain((1e-300, 1e-300), (2e6, 2e6), damping=(30.0, 30.0))
    with pytest.raises(ModelError, match=r"^transfer function d/F: its coefficients cannot be computed in double "
                                         r"precision \(4 poles of magnitude up to .* rad/s"):
        transfer_function(system.state_space("F", "d"), "F", "d")


@pytest.mark.slow
def test_transfer_function_of_90_states_is_finite_and_matches_the_state_space():
    # the gain used to be a product of 90 factors of ~1e4 rad/s (inf / inf = NaN numerator); as a sum of logarithms
    # it is finite, and the coefficients give the state-space response
    ss = NumericModel(load_model("builtin:uniaxial-machine-tool")).system().state_space("Ftx", "atx")
    tf = transfer_function(ss, "Ftx", "atx")
    num, den = tf.float_coefficients()
    assert np.isfinite(num).all()
    assert np.isfinite(den).all()
    s = 2j * np.pi * np.array([1.0, 10.0, 50.0])
    want = [(ss.C @ np.linalg.solve(x * np.eye(ss.n_states) - ss.A, ss.B) + ss.D)[0, 0] for x in s]
    # 1e-6: an order-90 polynomial evaluated in double precision below 100 Hz (measured 2e-8)
    np.testing.assert_allclose(tf.evaluate(s), want, rtol=1e-6)
