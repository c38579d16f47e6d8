"""The two-step methods (thesis 3.6.2): experimental transfer function, then coefficient or zero-pole matching.

References: the closed-form coefficients of thesis eqs 5.7-5.11 (with the known defect fixed: b2 = 1/m1);
``scipy.signal.ss2tf`` of the model's state space; the direct frequency-response solve of ``MechanicalSystem.frf``
for the 11-DOF spindle; central finite differences for the analytic Jacobians; exact recovery from exact transfer
functions and from noise-free time data (the OE model of the physical order and the exact ZOH inverse reproduce the
continuous transfer function); seeded 1 % noise round trips.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal as sig

from cappe.estimate._space import ParameterSpace
from cappe.estimate._two_step import (
    TwoStepTFEstimator,
    TwoStepZPKEstimator,
    _ModelTF,
    _pairs,
    model_transfer_functions,
)
from cappe.exceptions import DataError, ModelError
from cappe.identify import random_noise
from cappe.io.timedata import TimeData
from cappe.model import NumericModel, load_model
from cappe.systems import time_response
from cappe.systems.transfer import TransferFunctionModel
from cappe.systems.zpk import zpk

# Test truth of our choice inside the model's bounds (Table 5.1 widened): nominal masses and stiffnesses, damping
# 20 / 4 N s/m (zeta 0.68 % / 0.34 %) instead of the thesis's 13.42 / 0.47. The estimators start from the model's
# nominal values (c22 = 0.47, 8.5 times too small) and from Sobol points inside the bounds.
TRUTH = {"m1": 1.39, "m2": 1.09, "k11": 1.38e6, "k12": 0.12e6, "k22": 0.24e6, "c11": 20.0, "c12": 0.0, "c22": 4.0}
SEVEN = ("m1", "m2", "k11", "k12", "k22", "c11", "c22")
THREE_PAIRS = [("F1", "d1"), ("F1", "d2"), ("F2", "d2")]


@pytest.fixture(scope="module")
def rig():
    return NumericModel(load_model("builtin:two-mass-rig"))


def _errors(estimate):
    return np.array([estimate.relative_error(TRUTH)[n] for n in SEVEN])


def _excitation(fs, duration, seed):
    f1 = random_noise(fs=fs, duration=duration, rms=10.0, rng=seed, name="F1")
    f2 = random_noise(fs=fs, duration=duration, rms=10.0, rng=seed + 1, name="F2")
    return TimeData(f1.time, np.vstack([f1.values, f2.values]), ("F1", "F2"), ("N", "N"))


# -- model transfer functions ---------------------------------------------------------------------------------------


def test_model_coefficients_match_thesis_closed_form(rig):
    p = dict(TRUTH, c12=0.7)
    m1, m2, k11, k12, k22, c11, c12, c22 = (p[n] for n in ("m1", "m2", "k11", "k12", "k22", "c11", "c12", "c22"))
    g11, g21 = model_transfer_functions(rig, [("F1", "d1"), ("F1", "d2")], p, unknowns=[*SEVEN, "c12"])
    mm = m1 * m2
    den = [
        1.0,
        (c12 * m1 + c22 * m1 + c11 * m2 + c12 * m2) / mm,  # a3, eq. 5.9d
        (c11 * c12 + c11 * c22 + c12 * c22 + k12 * m1 + k22 * m1 + k11 * m2 + k12 * m2) / mm,  # a2, 5.9c
        (c12 * k11 + c22 * k11 + c11 * k12 + c22 * k12 + c11 * k22 + c12 * k22) / mm,  # a1, 5.9b
        (k11 * k12 + k11 * k22 + k12 * k22) / mm,  # a0, 5.9a
    ]
    # eq. 5.8 with b2 = 1/m1 (the thesis prints 1/m2, a known defect)
    np.testing.assert_allclose(g11.numerator, [1 / m1, (c12 + c22) / mm, (k12 + k22) / mm], rtol=1e-12)
    np.testing.assert_allclose(g21.numerator, [c12 / mm, k12 / mm], rtol=1e-12)  # eq. 5.11
    np.testing.assert_allclose(g11.denominator, den, rtol=1e-12)
    np.testing.assert_allclose(g21.denominator, den, rtol=1e-12)
    # with c12 = 0 known the s term of G21 is a structural zero and the numerator is k12 / (m1 m2) alone
    (g21_0,) = model_transfer_functions(rig, [("F1", "d2")], TRUTH)
    np.testing.assert_allclose(g21_0.numerator, [k12 / mm], rtol=1e-12)


def test_model_coefficients_match_scipy_for_velocity_and_acceleration(rig):
    system = rig.system(TRUTH)
    pairs = [("F2", "v1"), ("F1", "a2"), ("F2", "a2")]
    tfs = model_transfer_functions(rig, pairs, TRUTH, unknowns=[*SEVEN, "c12"])
    for (inp, out), tf in zip(pairs, tfs, strict=True):
        ss = system.state_space(inp, out)
        num, den = sig.ss2tf(ss.A, ss.B, ss.C, ss.D)
        ref = np.trim_zeros(num[0], "f")
        scale = np.abs(ref).max()
        got = np.asarray(tf.numerator)
        # ss2tf goes through the characteristic polynomial of A: its structural zeros come out as ~1e-8 of the
        # largest coefficient (ours are exact zeros)
        np.testing.assert_allclose(got, ref[-got.size :], rtol=1e-7, atol=1e-7 * scale)
        np.testing.assert_allclose(np.abs(ref[: -got.size]), 0.0, atol=1e-7 * scale)
        np.testing.assert_allclose(tf.denominator, den, rtol=1e-9)


def test_model_response_of_the_spindle_matches_the_direct_frf_solve():
    nm = NumericModel(load_model("builtin:spindle-bearing"))
    tfs = model_transfer_functions(nm, [("Fx", "sx"), ("Fx", "hax")])
    assert [len(tf.denominator) for tf in tfs] == [23, 23]  # 11 DOF
    f = np.array([50.0, 300.0, 900.0, 1500.0])
    h = nm.system().frf(f, inputs=["Fx"], outputs=["sx", "hax"]).H[:, 0]
    for k, tf in enumerate(tfs):
        # monomial coefficients over 22 orders of magnitude: evaluation round-off ~1e-8 relative
        np.testing.assert_allclose(tf.evaluate(2j * np.pi * f), h[k], rtol=1e-6)


@pytest.mark.parametrize("cls", [TwoStepTFEstimator, TwoStepZPKEstimator])
def test_analytic_jacobian_matches_finite_differences(rig, cls):
    space = ParameterSpace.from_model(rig)
    pairs = _pairs(rig, [("F1", "d1"), ("F1", "d2"), ("F2", "a2")])
    engine = _ModelTF(rig, space, pairs, None)
    given = model_transfer_functions(rig, [(p.input, p.output) for p in pairs], TRUTH)
    residuals, jacobian, _ = cls(rig)._residuals(engine, given, np.ones(3))
    p = space.vector(TRUTH) * np.array([1.1, 0.9, 1.05, 0.95, 1.2, 0.8, 1.3])
    jac = jacobian(p)
    for j in range(space.n):
        h = 1e-6 * p[j]
        up, down = p.copy(), p.copy()
        up[j] += h
        down[j] -= h
        fd = (residuals(up) - residuals(down)) / (2 * h)
        # central differences of relative residuals: truncation ~h^2, round-off ~1e-16 / 1e-6 relative
        np.testing.assert_allclose(jac[:, j] * p[j], fd * p[j], atol=1e-6 * max(1.0, np.abs(fd * p[j]).max()))


# -- exact recovery -------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("cls", [TwoStepTFEstimator, TwoStepZPKEstimator])
def test_exact_transfer_functions_recover_the_truth(rig, cls):
    exact = model_transfer_functions(rig, THREE_PAIRS, TRUTH)
    est = cls(rig, n_starts=8, rng=1).fit(exact)
    np.testing.assert_allclose(_errors(est.estimate_), 0.0, atol=1e-8)
    assert est.estimate_.identifiable.all()
    assert est.estimate_.cost < 1e-20
    # the same transfer functions in zero-pole-gain form
    est_zpk = cls(rig, n_starts=8, rng=1).fit([zpk(tf) for tf in exact])
    np.testing.assert_allclose(_errors(est_zpk.estimate_), 0.0, atol=1e-8)
    assert est.estimate_.method == cls.method


@pytest.mark.parametrize("cls", [TwoStepTFEstimator, TwoStepZPKEstimator])
def test_undamped_model_structural_zeros_and_undamped_roots(rig, cls):
    # all damping known to be zero: the odd denominator powers are structural zeros (not compared) and the poles
    # and zeros lie on the imaginary axis (damping compared in absolute, not relative, terms)
    undamped = dict(TRUTH, c11=0.0, c22=0.0)
    unknowns = ["m1", "m2", "k11", "k12", "k22"]
    exact = model_transfer_functions(rig, THREE_PAIRS, undamped, unknowns=unknowns)
    assert exact[0].denominator[1] == 0.0
    assert exact[0].denominator[3] == 0.0
    est = cls(rig, unknowns, values={"c11": 0.0, "c22": 0.0}, n_starts=4, rng=9).fit(exact)
    np.testing.assert_allclose(est.estimate_.values, [undamped[n] for n in unknowns], rtol=1e-8)


def test_noise_free_time_data_recovers_the_truth(rig):
    data = time_response(rig.system(TRUTH), _excitation(2000.0, 0.5, 21), outputs=["d1", "d2"])
    est = TwoStepTFEstimator(rig, n_starts=4, rng=2).fit(data)
    # OE of the physical order fits the ZOH-sampled system exactly and the ZOH inverse is exact
    np.testing.assert_allclose(_errors(est.estimate_), 0.0, atol=1e-8)
    assert [f"{tf.input}->{tf.output}" for tf in est.transfer_functions_] == ["F1->d1", "F2->d1", "F1->d2", "F2->d2"]
    zp = TwoStepZPKEstimator(rig, n_starts=4, rng=2).fit(est.transfer_functions_)
    np.testing.assert_allclose(_errors(zp.estimate_), 0.0, atol=1e-8)


def test_thesis_route_high_order_arx_and_pruning(rig):
    data = time_response(rig.system(TRUTH), _excitation(2000.0, 1.0, 23), outputs=["d1", "d2"])
    est = TwoStepTFEstimator(rig, identification="arx", arx_order=4, n_starts=2, rng=2).fit(data)
    assert est.estimate_.diagnostics["identification"] == "arx (time data)"
    # noise-free ARX of the physical order is the exact ZOH model; pruning maps its zeros by matched-z, which at
    # 2 kHz (modes at 90 and 166 Hz) moves them by ~1e-6 relative
    np.testing.assert_allclose(_errors(est.estimate_), 0.0, atol=1e-4)


def test_exact_frfs_through_the_rational_fit(rig):
    frf = rig.system(TRUTH).frf(np.linspace(2.0, 400.0, 400), inputs=["F1", "F2"], outputs=["d1", "d2"])
    est = TwoStepZPKEstimator(rig, n_starts=4, rng=3).fit(frf)
    assert est.estimate_.diagnostics["identification"] == "fit_rational (FRF data)"
    # the Sanathanan-Koerner fit of exact FRFs converges to the exact rational function (to ~1e-9)
    np.testing.assert_allclose(_errors(est.estimate_), 0.0, atol=1e-6)


# -- noisy data: beat the thesis ------------------------------------------------------------------------------------


@pytest.mark.slow  # two OE fits of 20000 samples: a few seconds
def test_one_percent_noise_both_variants_within_five_percent(rig):
    data = time_response(rig.system(TRUTH), _excitation(2000.0, 10.0, 31), outputs=["d1", "d2"], noise=0.01, rng=33)
    tf = TwoStepTFEstimator(rig, rng=4).fit(data)
    zp = TwoStepZPKEstimator(rig, rng=4).fit(tf.transfer_functions_)  # the same step 1
    err_tf, err_zp = _errors(tf.estimate_), _errors(zp.estimate_)
    # issue 5 target: all seven within 5 % (thesis Table 5.5: m2 off by 131 %, k22 by 1700 %). Over 8 seeds of
    # this set-up the largest errors were ~4 % (TF, c22) and ~2.5 % (ZP, c11); masses and stiffnesses within ~1 %.
    assert np.all(np.abs(err_tf) < 0.05), err_tf
    assert np.all(np.abs(err_zp) < 0.05), err_zp
    assert np.all(np.abs(err_zp[:5]) < 0.015), err_zp
    for est in (tf, zp):
        assert est.estimate_.success
        assert est.estimate_.identifiable.all()
        assert np.all(np.isfinite(est.estimate_.std))
        assert est.estimate_.diagnostics["starts"] == 16
    # time data: step 1's covariance weights step 2 (minimum distance); every identified coefficient is compared,
    # those of the structural zeros of G12 / G21 (c12 = 0 known: s .. s^4) against 0
    assert tf.estimate_.diagnostics["second_step_weighting"].startswith("covariance of step 1")
    assert tf.estimate_.diagnostics["compared"]["F1->d2"]["structural_zeros"] == [1, 2, 3, 4]
    assert tf.estimate_.diagnostics["compared"]["F1->d1"]["structural_zeros"] == [3, 4]
    # transfer functions given without a covariance: the normalized-square index, whose structural zeros are noise
    # and not compared
    assert zp.estimate_.diagnostics["second_step_weighting"].startswith("none (normalized-square index)")
    plain = TwoStepTFEstimator(rig, rng=4, weighting="none").fit(data).estimate_
    assert plain.diagnostics["ignored_numerator_powers"]["F1->d2"] == [1, 2, 3]
    assert plain.diagnostics["compared"]["F1->d1"]["numerator_powers"] == [0, 1, 2]


# -- identifiability ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("cls", [TwoStepTFEstimator, TwoStepZPKEstimator])
def test_one_transfer_function_cannot_determine_m2(rig, cls):
    # G11 alone: b2 = 1/m1 fixes m1 and a3 fixes c11, but m2 only appears in ratios (k12^2/m2, (k12 + k22)/m2,
    # c22/m2): a one-parameter family fits exactly
    (g11,) = model_transfer_functions(rig, [("F1", "d1")], TRUTH)
    e = cls(rig, n_starts=4, rng=5).fit([g11]).estimate_
    flags = dict(zip(e.names, e.identifiable.tolist(), strict=True))
    assert flags == {"m1": True, "m2": False, "k11": True, "k12": False, "k22": False, "c11": True, "c22": False}
    assert np.isnan(e.std[~e.identifiable]).all()
    assert np.isfinite(e.std[e.identifiable]).all()
    assert len(e.combinations) == 1
    assert {"m2", "k22", "c22", "k12"} <= set(e.combinations[0].split()[1::2])
    np.testing.assert_allclose([e.parameters["m1"], e.parameters["c11"]], [TRUTH["m1"], TRUTH["c11"]], rtol=1e-8)
    assert e.to_dict()["uncertainty"]["std"]["m2"] is None


def test_exciting_both_inputs_improves_the_conditioning(rig):
    # with F1 only (G11, G21) all seven are determined, but k12 enters a0 only through k12^2 / (m1 m2), a few per
    # cent of it; G22 (F2 excited) gives 1/m2 directly
    one = TwoStepTFEstimator(rig, n_starts=2, rng=6).fit(model_transfer_functions(rig, THREE_PAIRS[:2], TRUTH))
    two = TwoStepTFEstimator(rig, n_starts=2, rng=6).fit(model_transfer_functions(rig, THREE_PAIRS, TRUTH))
    assert one.estimate_.identifiable.all()
    assert two.estimate_.identifiable.all()
    assert one.estimate_.diagnostics["condition_number"] > 20 * two.estimate_.diagnostics["condition_number"]


# -- settings and errors --------------------------------------------------------------------------------------------


def test_pair_weights_and_pair_selection(rig):
    exact = model_transfer_functions(rig, THREE_PAIRS, TRUTH)
    est = TwoStepTFEstimator(rig, pairs=[("F1", "d1"), ("F2", "d2")], weights={"F2->d2": 3.0}, n_starts=2,
                             rng=7).fit(exact)
    assert est.estimate_.diagnostics["pairs"] == ["F1->d1", "F2->d2"]
    assert est.estimate_.diagnostics["weights"] == {"F1->d1": 1.0, "F2->d2": 3.0}
    np.testing.assert_allclose(_errors(est.estimate_), 0.0, atol=1e-8)


def test_errors(rig):
    exact = model_transfer_functions(rig, THREE_PAIRS, TRUTH)
    short = time_response(rig.system(TRUTH), _excitation(1000.0, 0.2, 41), outputs=["d1", "d2"])
    with pytest.raises(DataError, match=r"two-step estimation takes TimeData, FRFData or transfer functions .*; got dict"):
        TwoStepTFEstimator(rig).fit({"F1": 1.0})
    with pytest.raises(DataError, match=r"the time data has no channel named after a model input \['F1', 'F2'\]"):
        TwoStepTFEstimator(rig).fit(short.select(["d1", "d2"]))
    with pytest.raises(DataError, match=r"the time data has no channel named after a model output"):
        TwoStepTFEstimator(rig).fit(short.select(["F1", "F2"]))
    with pytest.raises(DataError, match=r"pair F1->v1 needs channel\(s\) \['v1'\], which the time data lacks"):
        TwoStepTFEstimator(rig, pairs=[("F1", "v1")]).fit(short)
    with pytest.raises(DataError, match=r"pair F9->d1: 'F9' is not an input of model 'two-mass-rig'"):
        TwoStepTFEstimator(rig, pairs=[("F9", "d1")]).fit(exact)
    with pytest.raises(DataError, match=r"no experimental transfer function given for pair\(s\) \['F2->d1'\]"):
        TwoStepTFEstimator(rig, pairs=[("F2", "d1")]).fit(exact)
    low = TransferFunctionModel((1.0,), (1.0, 2.0, 3.0), "F1", "d1")
    with pytest.raises(DataError, match=r"experimental transfer function F1->d1 has 2 poles but the model has 4; identify \(or prune\) to the physical order 4"):
        TwoStepTFEstimator(rig).fit(low)
    thin = TransferFunctionModel((1.0, 2.0), exact[0].denominator, "F1", "d1")
    with pytest.raises(DataError, match=r"F1->d1 has a numerator of degree 1 but the model's has degree 2"):
        TwoStepTFEstimator(rig).fit(thin)
    with pytest.raises(DataError, match=r"F1->d1 has 1 finite non-zero zeros but the model has 2"):
        TwoStepZPKEstimator(rig).fit(thin)
    hole = TransferFunctionModel((1.0, 0.0, 2.0), exact[0].denominator, "F1", "d1")
    with pytest.raises(DataError, match=r"F1->d1 has an exactly zero coefficient where the model's is not"):
        TwoStepTFEstimator(rig).fit(hole)
    with pytest.raises(DataError, match=r"weights given for \['F2->d1'\], which are not among the compared pairs"):
        TwoStepTFEstimator(rig, weights={"F2->d1": 1.0}).fit(exact)
    with pytest.raises(DataError, match=r"weights must be finite and > 0; got \[-1.0\] for \['F1->d1'\]"):
        TwoStepTFEstimator(rig, weights={"F1->d1": -1.0}).fit(exact)
    with pytest.raises(DataError, match=r"identification must be 'oe' or 'arx'; got 'n4sid'"):
        TwoStepTFEstimator(rig, identification="n4sid").fit(exact)
    with pytest.raises(DataError, match=r"n_starts must be an integer >= 1; got 0"):
        TwoStepTFEstimator(rig, n_starts=0).fit(exact)
    with pytest.raises(DataError, match=r"roots must be 'frequency-damping' or 'complex'; got 'polar'"):
        TwoStepZPKEstimator(rig, roots="polar").fit(exact)
    with pytest.raises(ModelError, match=r"unknowns \['k99'\] are not parameters of model 'two-mass-rig'"):
        TwoStepTFEstimator(rig, ["k99"]).fit(exact)


def test_complex_root_form_and_result_document(rig, tmp_path):
    from cappe.estimate import read_estimate, write_estimate

    exact = model_transfer_functions(rig, THREE_PAIRS, TRUTH)
    est = TwoStepZPKEstimator(rig, roots="complex", n_starts=4, rng=8).fit(exact)
    # in this form a damping error shows only as ~zeta times a relative error (Re(l) / |l|), so the optimizer's
    # stopping tolerances leave the damping at ~1e-7 instead of ~1e-12
    np.testing.assert_allclose(_errors(est.estimate_), 0.0, atol=1e-6)
    doc = est.estimate_.to_dict()
    assert doc["format"] == "cappe.estimate/1"
    assert doc["method"] == "two-step-zp"
    assert doc["diagnostics"]["roots"] == "complex"
    assert doc["diagnostics"]["compared"]["F1->d1"] == {"poles": 4, "zeros": 2, "gain": "s^0 / s^0"}
    assert doc["diagnostics"]["compared"]["F1->d2"]["poles"] == 0  # the same denominator is compared once
    back = read_estimate(write_estimate(tmp_path / "zp.json", est.estimate_))
    np.testing.assert_allclose(back.values, est.estimate_.values, rtol=1e-15)
