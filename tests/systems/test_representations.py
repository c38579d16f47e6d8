"""Representations in ``cappe.systems`` checked against independent references.

References: python-control and scipy.signal on a first-order realization built here from M, C, K (never
from cappe's own state space), closed forms for a 1-DOF oscillator and the thesis two-mass rig, and
physical invariances (reciprocity, ordering and scaling) on random chains.
"""

from __future__ import annotations

from functools import cache

import control
import numpy as np
import pytest
import scipy.signal as sig
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import linear_sum_assignment

from cappe.exact import exact_transfer_function
from cappe.model import NumericModel, StructureBuilder, derive, load_model
from cappe.systems import MechanicalSystem, transfer_function, zpk

# ---------------------------------------------------------------------------------------------------
# independent references and helpers


def reference_matrices(system: MechanicalSystem, inputs: list[str], outputs: list[str]):
    """First-order realization x = [q, q'] of ``M q'' + (C + G) q' + K q = B u`` built from the matrices.

    Written out here (np.linalg.solve, no Cholesky) so that it shares no code with cappe's state_space.
    """
    assert not np.any(system.H), "reference realization is for viscous models only"
    n = system.M.shape[0]
    minv_k = np.linalg.solve(system.M, system.K)
    minv_c = np.linalg.solve(system.M, system.C + system.G)
    cols = [system.input_names.index(i) for i in inputs]
    minv_b = np.linalg.solve(system.M, system.B[:, cols])
    a = np.block([[np.zeros((n, n)), np.eye(n)], [-minv_k, -minv_c]])
    b = np.vstack([np.zeros((n, len(cols))), minv_b])
    c_rows, d_rows = [], []
    for name in outputs:
        k = system.output_names.index(name)
        s = system.S[k]
        quantity = system.output_quantities[k]
        if quantity in ("displacement", "elongation"):
            c_rows.append(np.concatenate([s, np.zeros(n)]))
            d_rows.append(np.zeros(len(cols)))
        elif quantity == "velocity":
            c_rows.append(np.concatenate([np.zeros(n), s]))
            d_rows.append(np.zeros(len(cols)))
        else:  # acceleration: q'' = -M^-1 K q - M^-1 C q' + M^-1 B u
            c_rows.append(np.concatenate([-s @ minv_k, -s @ minv_c]))
            d_rows.append(s @ minv_b)
    return a, b, np.array(c_rows), np.array(d_rows)


def reference_ss(system: MechanicalSystem, inputs: list[str], outputs: list[str]) -> control.StateSpace:
    return control.ss(*reference_matrices(system, inputs, outputs))


def assert_same_roots(actual, expected, *, rtol: float, atol: float = 0.0) -> None:
    """Equal multisets of complex numbers: optimal one-to-one matching, then |a - e| <= atol + rtol |e|."""
    actual = np.asarray(actual, dtype=complex).ravel()
    expected = np.asarray(expected, dtype=complex).ravel()
    assert actual.shape == expected.shape, f"{actual.size} roots, expected {expected.size}"
    if not expected.size:
        return
    cost = np.abs(actual[:, None] - expected[None, :])
    rows, cols = linear_sum_assignment(cost)
    err = cost[rows, cols]
    bound = atol + rtol * np.abs(expected[cols])
    assert np.all(err <= bound), f"root mismatch: max excess {np.max(err - bound):.3g}\n{actual}\n{expected}"


def scaled_coefficients(num, den):
    """Coefficients of num/den in the frequency-normalized variable s / w0, w0 = |den[-1]|^(1/order).

    Raw coefficients of a structural TF span ~12 decades (s^4 ... 3e11), so a comparison with one atol is
    meaningless; after scaling the denominator coefficients are O(1e-3..1) and one relative-to-max
    tolerance is fair.
    """
    den = np.asarray(den, float) / den[0]
    num = np.asarray(num, float)
    order = den.size - 1
    w0 = abs(den[-1]) ** (1.0 / order)
    den_s = den * w0 ** (-np.arange(den.size, dtype=float))
    num_pow = np.arange(num.size - 1, -1, -1, dtype=float)  # powers of s, highest first
    num_s = num * w0 ** (num_pow - order)
    return num_s, den_s


def padded(coefficients, size: int):
    c = np.asarray(coefficients, float)
    return np.concatenate([np.zeros(size - c.size), c])


@cache
def rig_model() -> NumericModel:
    return NumericModel(load_model("builtin:two-mass-rig"))


@cache
def spindle_model() -> NumericModel:
    return NumericModel(load_model("builtin:spindle-bearing"))


RIG_OUTPUTS = ["d1", "d2", "v1", "v2", "a1", "a2"]
RIG_INPUTS = ["F1", "F2"]
# nominal set (c12 = 0, a structurally special case: G21 has no s term) and one with every damper active
RIG_PARAMS = [None, {"c11": 40.0, "c12": 2.5, "c22": 3.0}]


@pytest.fixture(params=RIG_PARAMS, ids=["nominal", "all-dampers"])
def rig(request) -> MechanicalSystem:
    return rig_model().system(request.param)


# ---------------------------------------------------------------------------------------------------
# poles, zeros, transfer functions, FRFs, DC gain vs python-control


def test_poles_match_python_control_two_mass_rig(rig):
    expected = control.poles(reference_ss(rig, RIG_INPUTS, RIG_OUTPUTS))
    # eigenvalues of the same 4x4 matrix formed two ways: agree to ~1e-13 relative; 1e-9 is generous
    assert_same_roots(rig.state_space().poles(), expected, rtol=1e-9)
    tf = transfer_function(rig.state_space("F1", "d1"), "F1", "d1")
    assert_same_roots(tf.poles(), expected, rtol=1e-9)
    modes = rig.modes("exact")
    upper = expected[expected.imag > 0]
    assert_same_roots(modes.poles, upper, rtol=1e-9)
    np.testing.assert_allclose(np.sort(modes.frequency), np.sort(np.abs(upper)) / (2 * np.pi), rtol=1e-9)
    np.testing.assert_allclose(
        modes.damping[np.argsort(modes.frequency)], (-upper.real / np.abs(upper))[np.argsort(np.abs(upper))], rtol=1e-7
    )


@pytest.mark.parametrize("omega", [0.0, 150.0], ids=["standstill", "spinning"])
def test_poles_match_python_control_spindle(omega):
    system = spindle_model().system({"Omega": omega})
    if omega:
        assert np.any(system.G), "spinning spindle must have a gyroscopic matrix"
    expected = control.poles(reference_ss(system, ["Fx"], ["sx"]))
    assert expected.size == 22
    # 22x22 eigenproblem with |p| up to ~7e3 rad/s: backward-stable solvers agree to ~1e-12 relative
    assert_same_roots(system.state_space().poles(), expected, rtol=1e-8)
    assert_same_roots(system.modes("exact").poles, expected[expected.imag > 0], rtol=1e-8)


@pytest.mark.parametrize(
    ("inp", "out"), [("F1", "d1"), ("F1", "d2"), ("F2", "d2"), ("F1", "v1"), ("F1", "a1"), ("F2", "a1")]
)
def test_zeros_match_python_control(rig, inp, out):
    ref = reference_ss(rig, [inp], [out])
    expected = control.zeros(ref)
    tf = transfer_function(rig.state_space(inp, out), inp, out)
    # zeros of a 4-state SISO pencil agree to ~1e-12 relative; zeros at s = 0 (velocity: single,
    # acceleration: double) need an absolute floor, a double root splits by ~sqrt(eps) |p| ~ 1e-5 rad/s;
    # 1e-3 rad/s is still far below any structural frequency here (> 500 rad/s)
    assert_same_roots(tf.zeros(), expected, rtol=1e-8, atol=1e-3)


def test_zeros_closed_form_drive_point(rig):
    # G11 numerator: m2 s^2 + (c12 + c22) s + (k12 + k22) (thesis eq. 5.8)
    p = rig.parameters
    expected = np.roots([p["m2"], p["c12"] + p["c22"], p["k12"] + p["k22"]])
    tf = transfer_function(rig.state_space("F1", "d1"), "F1", "d1")
    assert_same_roots(tf.zeros(), expected, rtol=1e-9)
    assert_same_roots(control.zeros(reference_ss(rig, ["F1"], ["d1"])), expected, rtol=1e-9)


@pytest.mark.parametrize("inp", RIG_INPUTS)
@pytest.mark.parametrize("out", RIG_OUTPUTS)
def test_tf_coefficients_match_python_control(rig, inp, out):
    ref = control.ss2tf(reference_ss(rig, [inp], [out]))
    ref_num = np.asarray(ref.num[0][0], float)
    ref_den = np.asarray(ref.den[0][0], float)
    ref_num_s, ref_den_s = scaled_coefficients(ref_num, ref_den)
    # scipy's ss2tf forms the numerator as poly(A - B C) - poly(A) (plus D): cancellation leaves round-off
    # of ~1e-8 of the largest scaled numerator term where the true coefficient is 0 (observed 1e-8)
    tol = 1e-7 * np.abs(ref_num_s).max()

    cappe_tf = transfer_function(rig.state_space(inp, out), inp, out)
    exact_tf = exact_transfer_function(derive(rig_model().structure), inp, out, values=dict(rig.parameters))
    for tf in (cappe_tf, exact_tf):
        num, den = tf.float_coefficients()
        assert den[0] == 1.0, "cappe denominators are monic"
        assert den.size == ref_den.size
        num_s, den_s = scaled_coefficients(num, den)
        np.testing.assert_allclose(den_s, ref_den_s, rtol=1e-9, atol=1e-12)
        assert num_s.size <= ref_num_s.size
        np.testing.assert_allclose(padded(num_s, ref_num_s.size), ref_num_s, rtol=0, atol=tol)
    # float vs exact coefficients, tighter: cappe's pole/zero/gain route is accurate to ~1e-12 relative
    # per scaled coefficient; a zero at s = 0 (velocity, acceleration) leaves a constant term of ~1e-16
    num_f, den_f = scaled_coefficients(*cappe_tf.float_coefficients())
    num_e, den_e = scaled_coefficients(*exact_tf.float_coefficients())
    np.testing.assert_allclose(den_f, den_e, rtol=1e-9)
    np.testing.assert_allclose(padded(num_f, num_e.size), num_e, rtol=1e-9, atol=1e-11 * np.abs(num_e).max())


def test_tf_g21_nominal_minreal_agrees():
    # nominal rig: c12 = 0 so G21 = k12 / (m1 m2 den): numerator is a constant; ss2tf leaves round-off
    # s^3..s^1 terms, minreal (python-control) must not remove any pole because none cancels
    rig = rig_model().system()
    ref = control.minreal(control.ss2tf(reference_ss(rig, ["F1"], ["d2"])), tol=1e-6, verbose=False)
    tf = transfer_function(rig.state_space("F1", "d2"), "F1", "d2")
    num, den = tf.float_coefficients()
    assert num.size == 1
    assert den.size == 5
    assert np.asarray(ref.den[0][0]).size == 5
    p = rig.parameters
    np.testing.assert_allclose(num[0], p["k12"] / (p["m1"] * p["m2"]), rtol=1e-9)  # closed form, round-off
    # minreal + ss2tf round-off (see the coefficient test): ~1e-8 relative observed
    np.testing.assert_allclose(control.dcgain(ref), tf.dc_gain(), rtol=1e-7)


def test_frf_matches_python_control_two_mass_rig(rig):
    freq = np.linspace(0.0, 400.0, 1601)  # Hz: both modes (~90 and ~166 Hz) and the antiresonance
    omega = 2 * np.pi * freq
    ref = control.frequency_response(reference_ss(rig, RIG_INPUTS, RIG_OUTPUTS), omega)
    np.testing.assert_array_equal(ref.omega, omega)
    expected = ref.complex  # (outputs, inputs, freq)
    actual = rig.frf(freq, RIG_INPUTS, RIG_OUTPUTS).H
    assert actual.shape == expected.shape
    for o in range(len(RIG_OUTPUTS)):
        for i in range(len(RIG_INPUTS)):
            # two linear solves of a matrix with condition ~1/zeta ~ 2e3 at resonance: ~1e-12 relative
            np.testing.assert_allclose(
                actual[o, i], expected[o, i], rtol=1e-8, atol=1e-11 * np.abs(expected[o, i]).max()
            )
    # the derivative outputs are i w and -w^2 times the displacement, exactly
    np.testing.assert_allclose(actual[2:4], actual[0:2] * (1j * omega), rtol=1e-12, atol=0)
    np.testing.assert_allclose(actual[4:6], actual[0:2] * -(omega**2), rtol=1e-12, atol=0)


@pytest.mark.parametrize("omega", [0.0, 150.0], ids=["standstill", "spinning"])
def test_frf_matches_python_control_spindle(omega):
    system = spindle_model().system({"Omega": omega})
    freq = np.linspace(0.0, 1500.0, 751)
    w = 2 * np.pi * freq
    ref = control.frequency_response(reference_ss(system, ["Fx"], ["sx", "hax"]), w).complex
    actual = system.frf(freq, "Fx", ["sx", "hax"]).H
    for o in range(2):
        # 11-DOF solve vs 22-state resolvent: agreement ~1e-11 of the peak; atol 1e-9 of the peak leaves margin
        np.testing.assert_allclose(actual[o, 0], ref[o, 0], rtol=1e-7, atol=1e-9 * np.abs(ref[o, 0]).max())


def _continuous_response(model, w):
    """C (j w I - A)^-1 B + D of a continuous StateSpaceModel: (outputs, inputs, frequencies)."""
    eye = np.eye(model.A.shape[0])
    return np.stack([model.C @ np.linalg.solve(1j * wk * eye - model.A, model.B) + model.D for wk in w], axis=-1)


def test_state_space_frequency_response_spindle_spinning():
    # cappe's own first-order realization (not only its FRF solver) against the reference, with the
    # gyroscopic matrix active; G's sign only shows in cross terms (poles of +G and -G coincide)
    system = spindle_model().system({"Omega": 200.0})
    ins, outs = ["Fx", "Fy"], ["sx", "sy", "hax", "sax"]
    freq = np.linspace(5.0, 1500.0, 300)
    w = 2 * np.pi * freq
    actual = _continuous_response(system.state_space(ins, outs), w)
    expected = control.frequency_response(reference_ss(system, ins, outs), w).complex
    second_order = system.frf(freq, ins, outs).H
    for o in range(len(outs)):
        for i in range(len(ins)):
            # two resolvent solves of the same 22x22 matrix: ~1e-12 of the peak; 1e-9 leaves margin
            atol = 1e-9 * np.abs(expected[o, i]).max()
            np.testing.assert_allclose(actual[o, i], expected[o, i], rtol=1e-7, atol=atol)
            np.testing.assert_allclose(second_order[o, i], expected[o, i], rtol=1e-7, atol=atol)
    # the cross FRF sy/Fx is far from zero, so the check above sees the gyroscopic coupling
    cross = expected[outs.index("sy"), ins.index("Fx")]
    assert np.abs(cross).max() > 1e-3 * np.abs(expected[outs.index("sx"), ins.index("Fx")]).max()


def test_dc_gain_matches_python_control(rig):
    expected = control.dcgain(reference_ss(rig, RIG_INPUTS, RIG_OUTPUTS))
    actual = rig.dc_gain(RIG_INPUTS, RIG_OUTPUTS)
    # static solve K^-1 vs -C A^-1 B: ~1e-15 relative for the displacement rows
    np.testing.assert_allclose(actual[:2], expected[:2], rtol=1e-10)
    # velocity/acceleration: cappe gives exactly 0; control's D - C A^-1 B cancels to round-off of the
    # a/F scale 1/m ~ 1 kg^-1, so atol 1e-12
    np.testing.assert_array_equal(actual[2:], 0.0)
    np.testing.assert_allclose(expected[2:], 0.0, atol=1e-12)
    np.testing.assert_allclose(actual[:2], np.linalg.inv(rig.K), rtol=1e-12)  # closed form K^-1
    for o, out in enumerate(RIG_OUTPUTS[:2]):
        for i, inp in enumerate(RIG_INPUTS):
            tf = transfer_function(rig.state_space(inp, out), inp, out)
            np.testing.assert_allclose(tf.dc_gain(), expected[o, i], rtol=1e-9)
            # zero-pole-gain form of the same TF: gain prod(-z) / prod(-p), round-off of the roots only
            np.testing.assert_allclose(zpk(tf).dc_gain(), expected[o, i], rtol=1e-8)


# ---------------------------------------------------------------------------------------------------
# discretization


DT = 2e-4  # s: ~30 samples per period of the 166 Hz mode


@pytest.mark.parametrize("method", ["zoh", "tustin"])
def test_discretization_matches_python_control(rig, method):
    cont = rig.state_space(RIG_INPUTS, RIG_OUTPUTS)
    disc = cont.discretize(DT, method)
    assert disc.dt == DT
    assert disc.method == method
    ref = control.sample_system(reference_ss(rig, RIG_INPUTS, RIG_OUTPUTS), DT, method)
    # the same state basis (x = [q, q']), so the matrices themselves must agree (round-off of expm/solve)
    for ours, theirs in ((disc.A, ref.A), (disc.B, ref.B), (disc.C, ref.C), (disc.D, ref.D)):
        np.testing.assert_allclose(ours, theirs, rtol=1e-9, atol=1e-9 * max(np.abs(theirs).max(), 1e-300))
    # closed-form pole maps: z = exp(s T) (ZOH), z = (1 + s T/2) / (1 - s T/2) (Tustin)
    p = control.poles(reference_ss(rig, RIG_INPUTS, RIG_OUTPUTS))
    z = np.exp(p * DT) if method == "zoh" else (1 + p * DT / 2) / (1 - p * DT / 2)
    assert_same_roots(disc.poles(), z, rtol=1e-10)


def _discrete_response(model, z):
    """C (z I - A)^-1 B + D of a discrete StateSpaceModel at points z: (outputs, inputs, points)."""
    eye = np.eye(model.A.shape[0])
    return np.stack([model.C @ np.linalg.solve(zk * eye - model.A, model.B) + model.D for zk in z], axis=-1)


def test_tustin_frequency_response_is_warped_continuous_frf(rig):
    # bilinear map: H_d(exp(j w T)) = H_c(j (2/T) tan(w T / 2)) exactly
    freq = np.linspace(1.0, 400.0, 400)
    w = 2 * np.pi * freq
    disc = rig.state_space(RIG_INPUTS, RIG_OUTPUTS).discretize(DT, "tustin")
    actual = _discrete_response(disc, np.exp(1j * w * DT))
    warped = (2 / DT) * np.tan(w * DT / 2) / (2 * np.pi)
    expected = rig.frf(warped, RIG_INPUTS, RIG_OUTPUTS).H
    for o in range(len(RIG_OUTPUTS)):
        for i in range(len(RIG_INPUTS)):
            np.testing.assert_allclose(
                actual[o, i], expected[o, i], rtol=1e-7, atol=1e-9 * np.abs(expected[o, i]).max()
            )


def test_zoh_preserves_dc_gain(rig):
    disc = rig.state_space(RIG_INPUTS, ["d1", "d2"]).discretize(DT, "zoh")
    static = _discrete_response(disc, np.array([1.0]))[..., 0]
    # (I - e^{AT})^-1 is ill-conditioned by ~1/(zeta w T): error ~1e-10 relative
    np.testing.assert_allclose(static, control.dcgain(reference_ss(rig, RIG_INPUTS, ["d1", "d2"])), rtol=1e-7)


# ---------------------------------------------------------------------------------------------------
# time response


def _piecewise_input(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform(-1.0, 1.0, size=(n, 2)) * np.array([100.0, 40.0])  # N


def test_simulate_equals_zoh_dlsim(rig):
    n = 1500
    t = np.arange(n) * DT
    u = _piecewise_input(n, 1)
    y, x = rig.state_space(RIG_INPUTS, RIG_OUTPUTS).simulate(u, t)
    a, b, c, d = reference_matrices(rig, RIG_INPUTS, RIG_OUTPUTS)
    ad, bd, cd, dd, _ = sig.cont2discrete((a, b, c, d), DT, method="zoh")
    _, y_ref, x_ref = sig.dlsim((ad, bd, cd, dd, DT), u, t)
    assert y.shape == y_ref.shape == (n, 6)
    for o in range(6):
        # the same recursion, different summation order: round-off growth over 1500 steps, ~1e-12 of peak
        np.testing.assert_allclose(y[:, o], y_ref[:, o], rtol=0, atol=1e-9 * np.abs(y_ref[:, o]).max())
    for s in range(x.shape[1]):
        np.testing.assert_allclose(x[:, s], x_ref[:, s], rtol=0, atol=1e-9 * np.abs(x_ref[:, s]).max())


def test_simulate_approaches_continuous_lsim(rig):
    # the continuous response to the held input, from lsim on a grid r times finer: lsim interpolates
    # linearly between fine samples, so each jump is smeared over DT/r and the error shrinks like 1/r
    n = 600
    t = np.arange(n) * DT
    u = _piecewise_input(n, 2)
    outputs = ["d1", "d2", "v1"]
    y, _ = rig.state_space(RIG_INPUTS, outputs).simulate(u, t)
    ref_sys = reference_matrices(rig, RIG_INPUTS, outputs)
    errors = []
    for r in (4, 32):
        t_fine = np.arange(n * r) * (DT / r)
        _, y_fine, _ = sig.lsim(ref_sys, np.repeat(u, r, axis=0), t_fine)
        y_coarse = y_fine[::r]
        errors.append(np.abs(y - y_coarse).max(axis=0) / np.abs(y).max(axis=0))
    assert np.all(errors[1] < errors[0] / 4), errors  # first-order convergence: 8x finer, >4x smaller
    assert np.all(errors[1] < 0.01), errors  # 1 % of the peak at r = 32 (observed 0.2-0.4 %)


def test_step_response_final_value_is_dc_gain():
    rig = rig_model().system({"c11": 400.0, "c12": 40.0, "c22": 120.0})  # damped enough to settle fast
    ss = rig.state_space(RIG_INPUTS, ["d1", "d2", "v1", "a2"])
    slowest = np.min(-ss.poles().real)
    t_end = 30.0 / slowest  # e^-30 ~ 1e-13 of the transient remains
    t = np.arange(0.0, t_end, DT)
    u = np.zeros((t.size, 2))
    u[:, 0] = 1.0
    y, _ = ss.simulate(u, t)
    final = y[-1]
    np.testing.assert_allclose(final[:2], rig.dc_gain("F1", ["d1", "d2"])[:, 0], rtol=1e-9)
    np.testing.assert_allclose(final[:2], control.dcgain(reference_ss(rig, ["F1"], ["d1", "d2"]))[:, 0], rtol=1e-9)
    # velocity and acceleration settle to 0 (scale: a / F ~ 1/m ~ 1 at t = 0)
    np.testing.assert_allclose(final[2:], 0.0, atol=1e-10)
    # and the step response is not trivially constant: it starts at 0 displacement
    assert y[0, 0] == 0.0


# ---------------------------------------------------------------------------------------------------
# closed forms: single-DOF oscillators


def one_dof(m: float, k: float, c: float = 0.0, eta: float = 0.0) -> MechanicalSystem:
    b = StructureBuilder("sdof")
    b.parameter("m", m, kind="mass")
    b.parameter("k", k, kind="stiffness")
    b.parameter("c", c, kind="damping")
    b.parameter("eta", eta, kind="loss")
    b.body("mass", mass="m", dofs=["x"])
    damping = {"damping": {"x": "c"}} if c else {}
    loss = {"loss": {"x": "eta"}} if eta else {}
    b.element("spring", bodies=("ground", "mass"), stiffness={"x": "k"}, **damping, **loss)
    b.input("F", body="mass", direction="x")
    b.output("d", quantity="displacement", body="mass", direction="x")
    b.output("v", quantity="velocity", body="mass", direction="x")
    b.output("a", quantity="acceleration", body="mass", direction="x")
    return NumericModel(b.build()).system()


SDOF = [(2.0, 8.0e3, 3.0), (1.0e3, 1.0e9, 2.0e3), (0.05, 40.0, 0.9)]


@pytest.mark.parametrize(("m", "k", "c"), SDOF)
def test_sdof_viscous_closed_forms(m, k, c):
    system = one_dof(m, k, c=c)
    wn = np.sqrt(k / m)
    zeta = c / (2 * np.sqrt(k * m))
    for method in ("exact", "first-order"):
        modes = system.modes(method)
        # round-off of a 2x2 eigenproblem / one Rayleigh quotient: 1e-12 relative
        np.testing.assert_allclose(modes.frequency, [wn / (2 * np.pi)], rtol=1e-12)
        np.testing.assert_allclose(modes.damping, [zeta], rtol=1e-10)
    np.testing.assert_allclose(system.modes("exact").poles, [-zeta * wn + 1j * wn * np.sqrt(1 - zeta**2)], rtol=1e-12)
    np.testing.assert_allclose(system.modes("undamped").frequency, [wn / (2 * np.pi)], rtol=1e-12)
    freq = np.linspace(0.0, 3 * wn / (2 * np.pi), 301)
    w = 2 * np.pi * freq
    h = 1.0 / (k - w**2 * m + 1j * w * c)
    frf = system.frf(freq)
    np.testing.assert_allclose(frf.response("d", "F"), h, rtol=1e-12)
    np.testing.assert_allclose(frf.response("v", "F"), 1j * w * h, rtol=1e-12)
    np.testing.assert_allclose(frf.response("a", "F"), -(w**2) * h, rtol=1e-12)
    np.testing.assert_allclose(system.dc_gain("F", "d"), [[1.0 / k]], rtol=1e-14)
    tf = transfer_function(system.state_space("F", "d"), "F", "d")
    num, den = tf.float_coefficients()
    np.testing.assert_allclose(num, [1.0 / m], rtol=1e-10)
    np.testing.assert_allclose(den, [1.0, c / m, k / m], rtol=1e-10)


def test_sdof_overdamped_first_order_closed_forms():
    m, k, c = 1.0, 100.0, 101.0  # s^2 + 101 s + 100 = (s + 1)(s + 100): wn = 10 rad/s, zeta = 5.05
    modes = one_dof(m, k, c=c).modes("first-order")
    np.testing.assert_allclose(modes.omega, [10.0], rtol=1e-12)
    np.testing.assert_allclose(modes.damping, [5.05], rtol=1e-12)
    poles = one_dof(m, k, c=c).state_space("F", "d").poles()
    assert_same_roots(poles, [-1.0, -100.0], rtol=1e-12)


def test_sdof_overdamped_exact_modes():
    modes = one_dof(1.0, 100.0, c=101.0).modes("exact")
    np.testing.assert_allclose(modes.omega, [10.0], rtol=1e-9)
    np.testing.assert_allclose(modes.damping, [5.05], rtol=1e-9)


def test_two_overdamped_modes_exact_pairing():
    # one body, x and y uncoupled: s^2 + 101 s + 100 (poles -1, -100) and s^2 + 25 s + 100 (-5, -20);
    # both modes have wn = 10 rad/s, damping ratios 5.05 and 1.25
    b = StructureBuilder("overdamped-pair")
    b.parameter("m", 1.0, kind="mass")
    b.parameter("k", 100.0, kind="stiffness")
    b.parameter("cx", 101.0, kind="damping")
    b.parameter("cy", 25.0, kind="damping")
    b.body("body", mass="m", dofs=["x", "y"])
    b.element("mount", bodies=("ground", "body"), stiffness={"x": "k", "y": "k"}, damping={"x": "cx", "y": "cy"})
    b.input("F", body="body", direction="x")
    b.output("d", quantity="displacement", body="body", direction="x")
    modes = NumericModel(b.build()).system().modes("exact")
    np.testing.assert_allclose(modes.omega, [10.0, 10.0], rtol=1e-9)
    np.testing.assert_allclose(np.sort(modes.damping), [1.25, 5.05], rtol=1e-9)


@pytest.mark.parametrize(("m", "k", "eta"), [(2.0, 8.0e3, 0.04), (1.0e3, 1.0e9, 0.2), (0.05, 40.0, 0.002)])
def test_sdof_loss_factor_closed_forms(m, k, eta):
    system = one_dof(m, k, eta=eta)
    np.testing.assert_allclose(system.H, [[eta * k]], rtol=1e-14)
    freq = np.linspace(0.0, 3 * np.sqrt(k / m) / (2 * np.pi), 301)
    w = 2 * np.pi * freq
    # hysteretic FRF is exact in the frequency domain: 1 / (k (1 + i eta) - w^2 m), round-off only
    np.testing.assert_allclose(system.frf(freq).response("d", "F"), 1.0 / (k * (1 + 1j * eta) - w**2 * m), rtol=1e-12)
    wn = np.sqrt(k / m)
    first = system.modes("first-order")
    np.testing.assert_allclose(first.damping, [eta / 2], rtol=1e-12)
    np.testing.assert_allclose(first.frequency, [wn / (2 * np.pi)], rtol=1e-12)
    # exact complex-stiffness eigenvalue: lambda^2 = -(k/m)(1 + i eta), upper half plane root
    exact_pole = 1j * wn * np.sqrt(1 + 1j * eta)
    np.testing.assert_allclose(system.modes("exact").poles, [exact_pole], rtol=1e-12)
    # time-domain state space uses the equivalent viscous damping c_eq = eta k / wn: zeta = eta / 2
    poles = system.state_space("F", "d").poles()
    np.testing.assert_allclose(-poles.real / np.abs(poles), [eta / 2, eta / 2], rtol=1e-10)
    np.testing.assert_allclose(np.abs(poles), [wn, wn], rtol=1e-12)


def free_free_chain() -> MechanicalSystem:
    b = StructureBuilder("free-free")
    b.parameter("m1", 2.0, kind="mass")
    b.parameter("m2", 3.0, kind="mass")
    b.parameter("k", 1.0e4, kind="stiffness")
    b.parameter("c", 5.0, kind="damping")
    b.body("a", mass="m1", dofs=["x"])
    b.body("b", mass="m2", dofs=["x"])
    b.element("link", bodies=("a", "b"), stiffness={"x": "k"}, damping={"x": "c"})
    b.input("F", body="a", direction="x")
    b.output("d", quantity="displacement", body="a", direction="x")
    return NumericModel(b.build()).system()


def test_free_free_chain_rigid_mode_undamped_and_first_order():
    system = free_free_chain()
    elastic = np.sqrt(1.0e4 * (1 / 2.0 + 1 / 3.0))  # closed form: k (1/m1 + 1/m2)
    for method in ("undamped", "first-order"):
        modes = system.modes(method)
        assert modes.n_modes == 2
        np.testing.assert_array_equal(modes.rigid, [True, False])
        assert modes.frequency[0] == 0.0
        np.testing.assert_allclose(modes.frequency[1], elastic / (2 * np.pi), rtol=1e-12)
    # static response is unbounded
    assert np.isinf(system.dc_gain()).all()


def test_free_free_chain_rigid_mode_exact():
    system = free_free_chain()
    modes = system.modes("exact")  # must not crash
    assert modes.n_modes == 2
    elastic = np.sqrt(1.0e4 * (1 / 2.0 + 1 / 3.0))
    np.testing.assert_allclose(modes.frequency[1], elastic / (2 * np.pi), rtol=1e-9)
    np.testing.assert_array_equal(modes.rigid, [True, False])
    assert modes.frequency[0] == 0.0


def test_free_free_chain_exact_modes_do_not_crash_and_keep_elastic_mode():
    modes = free_free_chain().modes("exact")
    assert modes.n_modes == 2
    elastic = np.sqrt(1.0e4 * (1 / 2.0 + 1 / 3.0))
    # elastic pole: s^2 + c (1/m1 + 1/m2) s + k (1/m1 + 1/m2) = 0
    zeta = 5.0 * (1 / 2.0 + 1 / 3.0) / (2 * elastic)
    np.testing.assert_allclose(modes.frequency[1], elastic / (2 * np.pi), rtol=1e-9)
    np.testing.assert_allclose(modes.damping[1], zeta, rtol=1e-9)
    # the rigid-body mode is (numerically) at zero frequency: far below the elastic one
    assert modes.frequency[0] < 1e-6 * modes.frequency[1]


# ---------------------------------------------------------------------------------------------------
# thesis two-mass rig: modes vs the hand-written characteristic polynomial

THESIS = {"m1": 1.39, "m2": 1.09, "k11": 1.38e6, "k12": 0.12e6, "k22": 0.24e6, "c11": 13.42, "c12": 0.0, "c22": 0.47}


def test_thesis_rig_modes_vs_characteristic_polynomial():
    p = THESIS
    m1, m2, k11, k12, k22, c11, c12, c22 = (p[n] for n in ("m1", "m2", "k11", "k12", "k22", "c11", "c12", "c22"))
    # det(M s^2 + C s + K) (thesis eq. 5.9 times m1 m2), written out by hand
    char = [
        m1 * m2,
        c12 * m1 + c22 * m1 + c11 * m2 + c12 * m2,
        c11 * c12 + c11 * c22 + c12 * c22 + k12 * m1 + k22 * m1 + k11 * m2 + k12 * m2,
        c12 * k11 + c22 * k11 + c11 * k12 + c22 * k12 + c11 * k22 + c12 * k22,
        k11 * k12 + k11 * k22 + k12 * k22,
    ]
    roots = np.roots(char)
    upper = np.sort_complex(roots[roots.imag > 0])
    modes = rig_model().system(THESIS).modes("exact")
    # quartic roots by companion matrix: ~1e-12 relative for these well-separated modes
    assert_same_roots(modes.poles, upper, rtol=1e-9)
    np.testing.assert_allclose(modes.frequency, np.sort(np.abs(upper)) / (2 * np.pi), rtol=1e-9)
    # undamped frequencies: the 2-DOF closed form
    a11, a22 = (k11 + k12) / m1, (k12 + k22) / m2
    disc = np.sqrt((a11 - a22) ** 2 + 4 * k12**2 / (m1 * m2))
    w2 = np.array([(a11 + a22 - disc) / 2, (a11 + a22 + disc) / 2])
    np.testing.assert_allclose(
        rig_model().system(THESIS).modes("undamped").frequency, np.sqrt(w2) / (2 * np.pi), rtol=1e-12
    )
    # sanity of the reference: the thesis reports modes near 90 and 166 Hz
    np.testing.assert_allclose(modes.frequency, [89.7, 166.3], rtol=2e-3)


# ---------------------------------------------------------------------------------------------------
# property tests on random chains


@cache
def chain_model(order: tuple[int, ...]) -> NumericModel:
    """A chain ground - b0 - b1 - ... with a ground spring at every body, bodies declared in ``order``.

    Inputs ``F<i>`` and displacement outputs ``d<i>`` are collocated at body i.
    """
    n = len(order)
    b = StructureBuilder(f"chain{n}")
    for i in range(n):
        b.parameter(f"m{i}", 1.0, kind="mass")
        b.parameter(f"kg{i}", 1.0, kind="stiffness")
        b.parameter(f"cg{i}", 0.0, kind="damping")
    for i in range(n - 1):
        b.parameter(f"kc{i}", 1.0, kind="stiffness")
        b.parameter(f"cc{i}", 0.0, kind="damping")
    for i in order:
        b.body(f"b{i}", mass=f"m{i}", dofs=["x"])
    for i in range(n):
        b.element(f"g{i}", bodies=("ground", f"b{i}"), stiffness={"x": f"kg{i}"}, damping={"x": f"cg{i}"})
    for i in range(n - 1):
        b.element(f"c{i}", bodies=(f"b{i}", f"b{i + 1}"), stiffness={"x": f"kc{i}"}, damping={"x": f"cc{i}"})
    for i in range(n):
        b.input(f"F{i}", body=f"b{i}", direction="x")
    for i in range(n):
        b.output(f"d{i}", quantity="displacement", body=f"b{i}", direction="x")
    return NumericModel(b.build())


@st.composite
def chains(draw):
    n = draw(st.sampled_from([2, 3]))
    exponent = st.floats(min_value=-1.0, max_value=1.0, allow_nan=False)
    params = {}
    for i in range(n):
        params[f"m{i}"] = 10 ** draw(exponent)
        params[f"kg{i}"] = 1e5 * 10 ** draw(exponent)
        params[f"cg{i}"] = 10 * 10 ** draw(exponent)
    for i in range(n - 1):
        params[f"kc{i}"] = 1e5 * 10 ** draw(exponent)
        params[f"cc{i}"] = 10 * 10 ** draw(exponent)
    perm = tuple(draw(st.permutations(range(n))))
    return n, params, perm


PROPERTY_SETTINGS = settings(max_examples=20, deadline=None, database=None)


def _scaled(params: dict[str, float], mass: float, stiff: float, damp: float) -> dict[str, float]:
    factor = {"m": mass, "k": stiff, "c": damp}
    return {name: v * factor[name[0]] for name, v in params.items()}


@PROPERTY_SETTINGS
@given(chains())
def test_frf_reciprocity(chain):
    n, params, _ = chain
    system = chain_model(tuple(range(n))).system(params)
    wn = np.sqrt(system.modes("undamped").omega)
    freq = np.concatenate([[0.0], np.geomspace(0.05, 5.0, 40) * wn.max() / (2 * np.pi)])
    h = system.frf(freq, [f"F{i}" for i in range(n)], [f"d{i}" for i in range(n)]).H
    # Maxwell-Betti: H_ij = H_ji for collocated force/displacement pairs (symmetric M, C, K); the two
    # entries come from the same factorization, so they differ by round-off only
    scale = np.abs(h).max()
    np.testing.assert_allclose(h, np.swapaxes(h, 0, 1), rtol=1e-10, atol=1e-12 * scale)
    # and the pairs are not trivially zero (coupled chain)
    assert np.all(np.abs(h[0, n - 1, 1:]) > 0)


@PROPERTY_SETTINGS
@given(chains())
def test_modes_invariant_to_dof_ordering(chain):
    n, params, perm = chain
    ref = chain_model(tuple(range(n))).system(params)
    permuted = chain_model(perm).system(params)
    assert permuted.dofs == tuple(f"b{i}.x" for i in perm)
    for method in ("undamped", "exact"):
        a, b = ref.modes(method), permuted.modes(method)
        # the same eigenproblem with rows/columns permuted: round-off only
        np.testing.assert_allclose(b.frequency, a.frequency, rtol=1e-10)
        np.testing.assert_allclose(b.damping, a.damping, rtol=1e-7, atol=1e-12)
    # FRFs are the same functions of the named signals regardless of DOF order
    freq = np.linspace(0.0, 2 * ref.modes("undamped").frequency.max(), 50)
    names = ([f"F{i}" for i in range(n)], [f"d{i}" for i in range(n)])
    np.testing.assert_allclose(
        permuted.frf(freq, *names).H,
        ref.frf(freq, *names).H,
        rtol=1e-9,
        atol=1e-12 * np.abs(ref.frf(freq, *names).H).max(),
    )


@PROPERTY_SETTINGS
@given(chains(), st.floats(min_value=0.1, max_value=10.0, allow_nan=False))
def test_modes_under_unit_scaling(chain, a):
    n, params, _ = chain
    model = chain_model(tuple(range(n)))
    base = model.system(params).modes("exact")
    base_undamped = model.system(params).modes("undamped")
    # M, C, K all times a: det(a (M s^2 + C s + K)) has the same roots
    same = model.system(_scaled(params, a, a, a)).modes("exact")
    np.testing.assert_allclose(same.frequency, base.frequency, rtol=1e-9)
    np.testing.assert_allclose(same.damping, base.damping, rtol=1e-7, atol=1e-12)
    # K times a^2, C times a: s -> a s, so every pole (and natural frequency) scales by a, zeta unchanged
    faster = model.system(_scaled(params, 1.0, a * a, a)).modes("exact")
    np.testing.assert_allclose(faster.frequency, a * base.frequency, rtol=1e-9)
    np.testing.assert_allclose(faster.damping, base.damping, rtol=1e-7, atol=1e-12)
    undamped = model.system(_scaled(params, 1.0, a * a, 1.0)).modes("undamped")
    np.testing.assert_allclose(undamped.frequency, a * base_undamped.frequency, rtol=1e-10)
