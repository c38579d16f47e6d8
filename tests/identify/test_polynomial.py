"""Polynomial black-box models (ARX, ARMAX, OE, BJ) and order selection against independent references.

References: data generated here with scipy.signal.lfilter from known polynomials (noise-free: exact recovery;
noisy, seeded: estimates within a few standard deviations of the truth), numpy.linalg.lstsq on a regression
matrix built here with plain loops, python-control's ZOH sampling (control.sample_system) for the continuous
conversion, the two-mass rig's exact modes, and the textbook formulas of the information criteria.
"""

from __future__ import annotations

import math

import control
import numpy as np
import pytest
import scipy.signal as sig

from cappe.exceptions import (
    ConvergenceWarning,
    DataError,
    DataWarning,
    IllConditionedWarning,
    ModelError,
    NotFittedError,
)
from cappe.identify._order import information_criteria, select_order
from cappe.identify._polynomial import ARMAX, ARX, OE, BoxJenkins, DiscreteTransferFunction
from cappe.io.timedata import TimeData
from cappe.model import NumericModel

# true systems (polynomials in q^-1, lfilter convention)
A = [1.0, -1.5, 0.7]
B1 = [0.0, 1.0, 0.5]  # nk = 1, nb = 2
B2 = [0.0, 0.0, -0.4, 0.2]  # nk = 2, nb = 2
C = [1.0, -0.6, 0.2]
F1 = [1.0, -1.2, 0.5]
F2 = [1.0, -0.6]

# A z-score bound of 4.5 for the largest of up to 8 parameters fails with probability < 8 * 7e-6 for a correct
# estimator whose standard deviations are right; the seeds are fixed, so the test is deterministic.
Z_MAX = 4.5


def _inputs(n, seed):
    rng = np.random.default_rng(seed)
    return rng.standard_normal(n), rng.standard_normal(n), rng


def _arx_data(n=2000, seed=0, noise=0.0):
    u1, u2, rng = _inputs(n, seed)
    e = noise * rng.standard_normal(n)
    y = sig.lfilter(B1, A, u1) + sig.lfilter(B2, A, u2) + sig.lfilter([1.0], A, e)
    return TimeData.from_rate(10.0, {"u1": u1, "u2": u2, "y": y})


def _true_arx_theta():
    return np.array([A[1], A[2], B1[1], B1[2], B2[2], B2[3]])


# ---------------------------------------------------------------------------------------------------------------
# ARX


def test_arx_noise_free_recovers_the_polynomials_exactly():
    model = ARX(na=2, nb=[2, 2], nk=[1, 2]).fit(_arx_data(), inputs=["u1", "u2"], output="y")
    # exact data and exact structure: only float round-off remains (the regressor is well conditioned)
    np.testing.assert_allclose(model.A_, A, atol=1e-12)
    np.testing.assert_allclose(model.B_[0], B1, atol=1e-12)
    np.testing.assert_allclose(model.B_[1], B2, atol=1e-12)
    assert model.loss_ < 1e-24
    assert model.success_
    assert model.n_parameters_ == 6
    assert model.parameter_names_ == ("a1", "a2", "b1[u1]", "b2[u1]", "b2[u2]", "b3[u2]")
    assert model.fit_percent(_arx_data(seed=5)) == pytest.approx(100.0, abs=1e-8)


def _independent_regression(data, na, nbs, nks, inputs, output):
    """Regression matrix built sample by sample (no shared code with cappe)."""
    y = data.channel(output)
    us = [data.channel(n) for n in inputs]
    start = max([na] + [nk + nb - 1 for nb, nk in zip(nbs, nks, strict=True)])
    rows = []
    for t in range(start, y.size):
        row = [-y[t - k] for k in range(1, na + 1)]
        for u, nb, nk in zip(us, nbs, nks, strict=True):
            row += [u[t - nk - j] for j in range(nb)]
        rows.append(row)
    return np.array(rows), y[start:]


def test_arx_equals_numpy_lstsq_on_an_independent_regression():
    data = _arx_data(n=1500, seed=1, noise=0.5)
    model = ARX(na=3, nb=[2, 3], nk=[1, 2]).fit(data, inputs=["u1", "u2"], output="y")
    phi, rhs = _independent_regression(data, 3, [2, 3], [1, 2], ["u1", "u2"], "y")
    theta, *_ = np.linalg.lstsq(phi, rhs, rcond=None)
    # two least-squares solvers on a regressor of condition ~1e2: agreement to ~1e-12 relative
    np.testing.assert_allclose(model.parameters_, theta, rtol=1e-10, atol=1e-12)
    resid = rhs - phi @ theta
    lam = resid @ resid / (rhs.size - theta.size)
    std = np.sqrt(lam * np.diag(np.linalg.inv(phi.T @ phi)))
    np.testing.assert_allclose(model.noise_variance_, lam, rtol=1e-10)
    np.testing.assert_allclose(model.loss_, resid @ resid / rhs.size, rtol=1e-10)
    np.testing.assert_allclose(model.parameter_std_, std, rtol=1e-8)


def test_arx_noisy_estimate_is_within_a_few_std_of_the_truth():
    data = _arx_data(n=3000, seed=2, noise=0.3)
    model = ARX(na=2, nb=[2, 2], nk=[1, 2]).fit(data, inputs=["u1", "u2"], output="y")
    z = (model.parameters_ - _true_arx_theta()) / model.parameter_std_
    assert np.abs(z).max() < Z_MAX
    # the noise variance estimate of 3000 samples is within 10 % (5 std of a chi-square estimate) of 0.09
    assert model.noise_variance_ == pytest.approx(0.09, rel=0.1)


def test_arx_40th_order_two_inputs_is_a_single_least_squares_solve():
    rng = np.random.default_rng(7)
    n = 10_000
    u1, u2 = rng.standard_normal(n), rng.standard_normal(n)
    y = sig.lfilter(B1, A, u1) + sig.lfilter(B2, A, u2) + 0.1 * rng.standard_normal(n)
    data = TimeData.from_rate(1000.0, {"u1": u1, "u2": u2, "y": y})
    model = ARX(40, 40).fit(data, inputs=["u1", "u2"], output="y")
    assert model.n_parameters_ == 120
    assert model.n_samples_ == n - 40
    # the true poles are among the 40 (the extra ones model the coloured equation error)
    true_poles = np.roots(A)
    assert min(abs(model.poles() - true_poles[0])) < 1e-2


# ---------------------------------------------------------------------------------------------------------------
# ARMAX, OE, BJ


def test_armax_noisy_estimate_is_within_a_few_std_of_the_truth():
    u1, u2, rng = _inputs(3000, 3)
    e = 0.3 * rng.standard_normal(3000)
    y = sig.lfilter(B1, A, u1) + sig.lfilter(B2, A, u2) + sig.lfilter(C, A, e)
    data = TimeData.from_rate(10.0, {"u1": u1, "u2": u2, "y": y})
    model = ARMAX(na=2, nb=2, nc=2, nk=[1, 2]).fit(data, inputs=["u1", "u2"], output="y")
    assert model.success_
    truth = np.concatenate([_true_arx_theta(), C[1:]])
    z = (model.parameters_ - truth) / model.parameter_std_
    assert np.abs(z).max() < Z_MAX
    # the residuals of the true model are the white noise e: their variance estimates 0.09
    assert model.noise_variance_ == pytest.approx(0.09, rel=0.1)


def test_oe_noise_free_recovers_two_inputs_with_different_orders():
    u1, u2, _ = _inputs(1500, 4)
    y = sig.lfilter(B1, F1, u1) + sig.lfilter([0.0, 0.5], F2, u2)
    data = TimeData.from_rate(10.0, {"u1": u1, "u2": u2, "y": y})
    model = OE(nb=[2, 1], nf=[2, 1]).fit(data, inputs=["u1", "u2"], output="y")
    assert model.success_
    # the iteration stops at the round-off floor of an exact fit
    np.testing.assert_allclose(model.F_[0], F1, atol=1e-9)
    np.testing.assert_allclose(model.F_[1], F2, atol=1e-9)
    np.testing.assert_allclose(model.B_[0], B1, atol=1e-9)
    np.testing.assert_allclose(model.B_[1], [0.0, 0.5], atol=1e-9)
    np.testing.assert_allclose(model.A_, [1.0])


def test_oe_noisy_estimate_is_within_a_few_std_and_beats_arx_in_simulation():
    u1, _, rng = _inputs(3000, 5)
    y0 = sig.lfilter(B1, F1, u1)
    data = TimeData.from_rate(10.0, {"u": u1, "y": y0 + 0.3 * rng.standard_normal(3000)})
    model = OE(nb=2, nf=2).fit(data, inputs="u", output="y")
    truth = np.array([B1[1], B1[2], F1[1], F1[2]])
    z = (model.parameters_ - truth) / model.parameter_std_
    assert np.abs(z).max() < Z_MAX
    # simulation against the noise-free output: the OE estimate is consistent, the ARX one biased by the
    # coloured equation error, so OE fits the true output better
    clean = TimeData.from_rate(10.0, {"u": u1, "y": y0})
    arx = ARX(2, 2).fit(data, inputs="u", output="y")
    assert model.fit_percent(clean) > arx.fit_percent(clean)
    assert model.fit_percent(clean) > 97.0


def test_box_jenkins_noisy_estimate_is_within_a_few_std_of_the_truth():
    u, _, rng = _inputs(3000, 6)
    e = 0.3 * rng.standard_normal(3000)
    d_poly = [1.0, -0.85]
    c_poly = [1.0, 0.5]
    y = sig.lfilter(B1, F1, u) + sig.lfilter(c_poly, d_poly, e)
    data = TimeData.from_rate(10.0, {"u": u, "y": y})
    model = BoxJenkins(nb=2, nc=1, nd=1, nf=2).fit(data, inputs="u", output="y")
    assert model.success_
    truth = np.array([B1[1], B1[2], c_poly[1], d_poly[1], F1[1], F1[2]])
    z = (model.parameters_ - truth) / model.parameter_std_
    assert np.abs(z).max() < Z_MAX
    assert model.parameter_names_ == ("b1[u]", "b2[u]", "c1", "d1", "f1[u]", "f2[u]")


def test_unstable_noise_model_start_is_reflected_into_a_stable_predictor():
    # a minimum-phase equivalent exists for any C: data generated with C having a root outside the unit circle
    # has the same spectrum as with the reflected root; the estimate must return the stable (reflected) C
    u, _, rng = _inputs(4000, 8)
    e = 0.3 * rng.standard_normal(4000)
    c_out = [1.0, -2.0]  # root at z = 2; reflected: [1, -0.5] with twice the noise gain
    y = sig.lfilter(B1, A, u) + sig.lfilter(c_out, A, e)
    model = ARMAX(2, 2, 1).fit(TimeData.from_rate(1.0, {"u": u, "y": y}), inputs="u", output="y")
    assert np.all(np.abs(np.roots(model.C_)) < 1)
    # 4 std of a c1 estimate from 4000 samples is about 0.06
    assert model.C_[1] == pytest.approx(-0.5, abs=0.06)
    # noise variance of the innovations: (2 * 0.3)^2
    assert model.noise_variance_ == pytest.approx(0.36, rel=0.1)


def test_non_convergence_warns_and_sets_success_false():
    u1, u2, rng = _inputs(2000, 9)
    y = sig.lfilter(B1, A, u1) + sig.lfilter(C, A, 0.3 * rng.standard_normal(2000))
    data = TimeData.from_rate(1.0, {"u": u1, "y": y})
    # the model's name shows the iteration limit that stopped it (a default one is left out)
    with pytest.warns(ConvergenceWarning, match=r"ARMAX\(na=2, nb=2, nc=2, nk=1, max_iter=1\) did not converge"):
        model = ARMAX(2, 2, 2, max_iter=1).fit(data, inputs="u", output="y")
    assert model.success_ is False
    assert "no convergence in 1 iterations" in model.message_


def test_input_without_excitation_warns_instead_of_failing():
    # a zero input leaves the output-error predictor independent of B and F: the search must stop and say so
    y = np.random.default_rng(15).standard_normal(400)
    data = TimeData.from_rate(1.0, {"u": np.zeros(400), "y": y})
    with (
        pytest.warns(
            ConvergenceWarning, match=r"OE\(nb=1, nf=1, nk=1\) did not converge: the prediction errors do not"
        ),
        pytest.warns(IllConditionedWarning, match="the parameters are not all identifiable"),
    ):
        model = OE(1, 1).fit(data, inputs="u", output="y")
    assert model.success_ is False
    assert np.all(np.isinf(model.parameter_std_))


def test_rank_deficient_regression_warns():
    n = 500
    data = TimeData.from_rate(1.0, {"u": np.zeros(n), "y": np.random.default_rng(0).standard_normal(n)})
    with pytest.warns(IllConditionedWarning, match="rank deficient"):
        ARX(1, 2).fit(data, inputs="u", output="y")


# ---------------------------------------------------------------------------------------------------------------
# prediction


def test_predictions_match_independent_filters():
    u1, u2, rng = _inputs(1000, 10)
    e = 0.3 * rng.standard_normal(1000)
    y = sig.lfilter(B1, A, u1) + sig.lfilter(C, A, e)
    data = TimeData.from_rate(1.0, {"u": u1, "y": y})
    model = ARMAX(2, 2, 2).fit(data, inputs="u", output="y")
    a, b, c = model.A_, model.B_[0], model.C_
    # one step: C yhat = (C - A) y + B u (Ljung eq. 4.18), zero initial conditions
    ref1 = sig.lfilter([1.0], c, sig.lfilter(c - a, [1.0], y) + sig.lfilter(b, [1.0], u1))
    np.testing.assert_allclose(model.predict(data, horizon=1), ref1, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(model.residuals(data), y - ref1, rtol=1e-10, atol=1e-10)
    # simulation: B / A u
    np.testing.assert_allclose(model.predict(data, horizon=math.inf), sig.lfilter(b, a, u1), rtol=1e-10, atol=1e-10)


def test_k_step_prediction_uses_outputs_up_to_t_minus_k_only():
    data = _arx_data(n=400, seed=11, noise=0.3)
    model = ARMAX(2, [2, 2], 2, [1, 2]).fit(data, inputs=["u1", "u2"], output="y")
    k, t = 5, 300
    y_hat = model.predict(data, horizon=k)
    values = data.values.copy()
    values[2, t - k + 1 :] += 10.0  # change outputs after t - k: the prediction at t must not move
    changed = TimeData(data.time, values, data.channels)
    assert model.predict(changed, horizon=k)[t] == pytest.approx(y_hat[t], rel=1e-12)
    values[2, t - k] += 1.0  # but the output at t - k is used
    assert model.predict(TimeData(data.time, values, data.channels), horizon=k)[t] != pytest.approx(y_hat[t])
    # far horizons tend to the simulation (the noise model's impulse response has decayed, |poles| < 0.85)
    far = model.predict(data, horizon=200)
    np.testing.assert_allclose(far[250:], model.predict(data, horizon=math.inf)[250:], atol=1e-8)


def test_fit_percent_is_the_nrmse_fit():
    data = _arx_data(n=800, seed=12, noise=0.3)
    model = ARX(2, [2, 2], [1, 2]).fit(data, inputs=["u1", "u2"], output="y")
    y = data.channel("y")
    y_sim = sig.lfilter(model.B_[0], model.A_, data.channel("u1")) + sig.lfilter(
        model.B_[1], model.A_, data.channel("u2")
    )
    ref = 100 * (1 - np.linalg.norm(y - y_sim) / np.linalg.norm(y - y.mean()))
    assert model.fit_percent(data) == pytest.approx(ref, rel=1e-10)


# ---------------------------------------------------------------------------------------------------------------
# discrete and continuous representations


@pytest.fixture(scope="module")
def rig(two_mass):
    return NumericModel(two_mass).system()


def _zoh_arx(rig, fs, seed=0):
    """ARX(4, 4) fitted to noise-free data from python-control's ZOH sampling of G11 = d1 / F1."""
    ss = rig.state_space(["F1"], ["d1"])
    csys = control.ss(ss.A, ss.B, ss.C, ss.D)
    dtf = control.tf(control.sample_system(csys, 1.0 / fs, "zoh"))
    num, den = np.ravel(dtf.num[0][0]), np.ravel(dtf.den[0][0])
    num = np.concatenate([np.zeros(den.size - num.size), num])  # z-polynomials -> q^-1 arrays of equal length
    u = np.random.default_rng(seed).standard_normal(3000)
    data = TimeData.from_rate(fs, {"F1": u, "d1": sig.lfilter(num, den, u)})
    return ARX(4, 4).fit(data, inputs="F1", output="d1"), csys, num, den


def test_continuous_conversion_inverts_python_control_zoh_sampling(rig):
    model, csys, num, den = _zoh_arx(rig, fs=1000.0)
    dtf = model.to_discrete_tf()
    # the noise-free ARX fit reproduces python-control's discrete coefficients (round-off of an exact fit)
    np.testing.assert_allclose(dtf.denominator, den, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(dtf.numerator, num, rtol=1e-6, atol=1e-12 * np.abs(num).max())
    tf = model.to_transfer_function()
    ctf = control.tf(csys)
    ref_den = np.ravel(ctf.den[0][0])
    # d2c by the matrix logarithm: the denominator (poles) is recovered to ~1e-12; the s^0..s^4 coefficients
    # span 12 decades, hence the relative tolerance per coefficient
    np.testing.assert_allclose(tf.denominator, ref_den, rtol=1e-9)
    omega = 2 * np.pi * np.linspace(1.0, 400.0, 200)
    ref = np.array([ctf(1j * w) for w in omega])
    # the numerator inherits the conditioning of ARX coefficients of poles near z = 1 (about 1e-7 here)
    np.testing.assert_allclose(tf.evaluate(1j * omega), ref, rtol=1e-5)
    zpk = model.to_zpk()
    np.testing.assert_allclose(np.sort_complex(zpk.poles), np.sort_complex(control.poles(ctf)), rtol=1e-10)
    # python-control's own conversion leaves a round-off zero near 7e12 rad/s (relative degree 2 computed as 1);
    # cappe drops zeros beyond 1e6 x Nyquist, so compare the finite, physical pair (sqrt((k12 + k22) / m2))
    ref_zeros = control.zeros(ctf)
    ref_zeros = ref_zeros[np.abs(ref_zeros) < 1e6]
    assert zpk.zeros.size == 2
    np.testing.assert_allclose(np.sort_complex(zpk.zeros), np.sort_complex(ref_zeros), rtol=1e-5)
    # the discrete TF evaluates as python-control's discrete TF does
    freq = np.array([10.0, 90.0, 300.0])
    z = np.exp(2j * np.pi * freq / 1000.0)
    np.testing.assert_allclose(dtf.evaluate(freq), dtf.to_control()(z), rtol=1e-12)


def test_modal_parameters_are_the_exact_modes(rig):
    model, *_ = _zoh_arx(rig, fs=2000.0)
    modes = rig.modes()
    mp = model.modal_parameters()
    # ZOH maps poles exactly (z = exp(lambda dt)); an exact fit gives them to round-off
    np.testing.assert_allclose(mp.frequency, modes.frequency, rtol=1e-9)
    np.testing.assert_allclose(mp.damping, modes.damping, rtol=1e-6)
    assert mp.to_dict()["modes"][0] == {"frequency": mp.frequency[0], "damping": mp.damping[0]}
    np.testing.assert_allclose(np.exp(model.continuous_poles() / 2000.0), model.poles(), rtol=1e-12)


def test_negative_real_discrete_pole_errors_or_is_reflected():
    u = np.random.default_rng(13).standard_normal(800)
    y = sig.lfilter([0.0, 1.0, 0.3], [1.0, -0.2, -0.48], u)  # poles at z = 0.8 and z = -0.6
    model = ARX(2, 2).fit(TimeData.from_rate(100.0, {"u": u, "y": y}), inputs="u", output="y")
    with pytest.raises(ModelError, match=r"negative real axis \(z = -0\.6\)"):
        model.to_transfer_function()
    with pytest.warns(IllConditionedWarning, match=r"z = -0\.6 of the model from 'u' moved to \|z\|"):
        tf = model.to_transfer_function(negative_real="reflect")
    # poles log(0.8)/dt and log(0.6)/dt, static gain kept
    np.testing.assert_allclose(np.sort(tf.poles().real), np.sort(100 * np.log([0.6, 0.8])), rtol=1e-8)
    assert tf.dc_gain() == pytest.approx(1.3 / (1 - 0.2 - 0.48), rel=1e-8)


def test_pure_delay_has_no_continuous_equivalent():
    u = np.random.default_rng(14).standard_normal(500)
    y = sig.lfilter([0.0, 0.0, 1.0], [1.0, -0.5], u)
    model = ARX(1, 1, nk=2).fit(TimeData.from_rate(1.0, {"u": u, "y": y}), inputs="u", output="y")
    with pytest.raises(ModelError, match=r"pole at z = 0 \(a pure delay"):
        model.to_transfer_function()
    assert model.zeros().size == 0
    assert model.poles() == pytest.approx([0.5])


def test_discrete_tf_round_trip_and_dict():
    tf = DiscreteTransferFunction((0.0, 0.5), (1.0, -0.5), 0.1, "u", "y")
    assert tf.to_dict() == {"input": "u", "output": "y", "dt": 0.1, "numerator": [0.0, 0.5], "denominator": [1.0, -0.5]}
    np.testing.assert_allclose(tf.poles(), [0.5])


# ---------------------------------------------------------------------------------------------------------------
# order selection


def _order_data(seed, n=2000):
    u, _, rng = _inputs(n, seed)
    y = sig.lfilter(B1, A, u) + sig.lfilter([1.0], A, 0.2 * rng.standard_normal(n))
    return TimeData.from_rate(1.0, {"u": u, "y": y})


def test_criteria_pick_the_true_arx_order_and_follow_their_definitions():
    data = _order_data(20)
    grid = [(na, nb) for na in range(1, 5) for nb in range(1, 5)]
    for criterion in ("aic", "bic", "fpe"):
        sel = select_order(data, inputs="u", output="y", orders=grid, criterion=criterion)
        assert sel.best_orders == {"na": 2, "nb": 2}, criterion
    # textbook definitions recomputed from the table's loss (Ljung 1999, eqs 16.33, 16.36, 16.38)
    n, d, v = sel.n_samples, sel.n_parameters, sel.loss
    np.testing.assert_allclose(sel.fpe, v * (1 + d / n) / (1 - d / n), rtol=1e-12)
    np.testing.assert_allclose(sel.aic, n * np.log(v) + 2 * d, rtol=1e-12)
    np.testing.assert_allclose(sel.bic, n * np.log(v) + d * np.log(n), rtol=1e-12)
    # the loss is the mean squared one-step error over the common samples t >= 4 (the largest lag)
    e = sel.model.residuals(data)[4:]
    assert sel.loss[sel.best] == pytest.approx(e @ e / e.size, rel=1e-12)
    assert sel.n_samples == 2000 - 4
    table = sel.to_dict()["table"]
    assert len(table) == 16
    assert set(table[0]) == {"na", "nb", "n_parameters", "loss", "aic", "bic", "fpe"}
    assert information_criteria(0.5, 4, 1000)["bic"] == pytest.approx(1000 * math.log(0.5) + 4 * math.log(1000))


def test_validation_data_choose_the_true_order():
    sel = select_order(_order_data(21), inputs="u", output="y", orders=range(1, 7), validation=_order_data(22))
    assert sel.criterion == "validation"
    assert sel.best_orders == {"na": 2, "nb": 2}
    assert sel.validation_loss is not None
    assert sel.validation_loss.argmin() == sel.best


def test_order_selection_for_output_error_models():
    u, _, rng = _inputs(1500, 23)
    y = sig.lfilter(B1, F1, u) + 0.1 * rng.standard_normal(1500)
    data = TimeData.from_rate(1.0, {"u": u, "y": y})
    sel = select_order(data, inputs="u", output="y", structure="oe", orders=[1, 2, 3], criterion="bic")
    assert sel.best_orders == {"nb": 2, "nf": 2}
    assert isinstance(sel.model, OE)


# ---------------------------------------------------------------------------------------------------------------
# errors


def test_missing_channels_and_bad_roles():
    data = _arx_data(n=100)
    with pytest.raises(
        DataError, match=r"input channel\(s\) \['F9'\] not found in the data; available channels: \['u1', 'u2', 'y'\]"
    ):
        ARX(1, 1).fit(data, inputs=["F9"], output="y")
    with pytest.raises(DataError, match=r"output channel\(s\) \['d1'\] not found in the data; available channels"):
        ARX(1, 1).fit(data, inputs="u1", output="d1")
    with pytest.raises(DataError, match=r"output channel 'y' is also listed as an input"):
        ARX(1, 1).fit(data, inputs=["u1", "y"], output="y")
    with pytest.raises(DataError, match=r"inputs must name at least one input channel; got \[\]"):
        ARX(1, 1).fit(data, inputs=[], output="y")
    with pytest.raises(DataError, match=r"inputs must be distinct channels"):
        ARX(1, 1).fit(data, inputs=["u1", "u1"], output="y")
    with pytest.raises(DataError, match=r"output must be one channel name; got \['y'\]"):
        ARX(1, 1).fit(data, inputs=["u1"], output=["y"])  # type: ignore[arg-type]


def test_invalid_orders():
    data = _arx_data(n=100)
    with pytest.raises(DataError, match=r"ARX order na must be an integer >= 0; got -1"):
        ARX(-1, 1).fit(data, inputs="u1", output="y")
    with pytest.raises(DataError, match=r"ARX order nb must be an integer >= 1; got 0"):
        ARX(1, 0).fit(data, inputs="u1", output="y")
    with pytest.raises(DataError, match=r"ARX order nk must have one entry per input \(2\); got 3"):
        ARX(1, 1, nk=[1, 1, 1]).fit(data, inputs=["u1", "u2"], output="y")
    with pytest.raises(DataError, match=r"ARMAX order nc must be an integer >= 1; got 0"):
        ARMAX(1, 1, 0).fit(data, inputs="u1", output="y")
    with pytest.raises(DataError, match=r"OE order nf must be an integer or one integer per input; got '2'"):
        OE(1, "2").fit(data, inputs="u1", output="y")  # type: ignore[arg-type]
    with pytest.raises(DataError, match=r"BoxJenkins order nd must be an integer >= 0; got 1.5"):
        BoxJenkins(1, 1, 1.5, 1).fit(data, inputs="u1", output="y")  # type: ignore[arg-type]
    with pytest.raises(DataError, match=r"OE max_iter must be an integer >= 1; got 0"):
        OE(1, 1, max_iter=0).fit(data, inputs="u1", output="y")
    with pytest.raises(DataError, match=r"ARMAX tol must be a number in \(0, 1\); got 2"):
        ARMAX(1, 1, 1, tol=2).fit(data, inputs="u1", output="y")


def test_data_too_short_for_the_order():
    data = _arx_data(n=60)
    with pytest.raises(
        DataError,
        match=r"data too short for ARX\(na=30, nb=20, nk=1\): 60 samples \(30 usable after the first 30 lagged ones\) "
        r"for 50 parameters",
    ):
        ARX(30, 20).fit(data, inputs="u1", output="y")
    with pytest.raises(DataError, match=r"data too short for OE\(nb=40, nf=30, nk=1\): 60 samples"):
        OE(40, 30).fit(data, inputs="u1", output="y")


def test_use_before_fit_and_bad_use_after_fit():
    with pytest.raises(NotFittedError, match=r"this ARX is not fitted yet; call fit\(data, inputs=..., output=...\)"):
        ARX(1, 1).predict(_arx_data(n=50))
    model = ARX(2, [2, 2], [1, 2]).fit(_arx_data(n=300), inputs=["u1", "u2"], output="y")
    other_rate = TimeData.from_rate(20.0, {"u1": np.ones(10), "u2": np.ones(10), "y": np.ones(10)})
    with pytest.raises(DataError, match=r"data sampled at dt = 0.05 s but the model was fitted at dt = 0.1 s"):
        model.predict(other_rate)
    with pytest.raises(DataError, match=r"horizon must be a positive integer or inf; got 0"):
        model.predict(_arx_data(n=50), horizon=0)
    with pytest.raises(DataError, match=r"the model has 2 inputs \['u1', 'u2'\]; name one with input=..."):
        model.to_discrete_tf()
    with pytest.raises(DataError, match=r"input 'F1' is not an input of the model; inputs: \['u1', 'u2'\]"):
        model.zeros("F1")
    with pytest.raises(DataError, match=r"negative_real must be 'error' or 'reflect'; got 'drop'"):
        model.to_transfer_function("u1", negative_real="drop")
    flat = TimeData.from_rate(10.0, {"u1": np.ones(50), "u2": np.ones(50), "y": np.full(50, 2.0)})
    with pytest.raises(DataError, match=r"output channel 'y' is constant; the fit in % is undefined"):
        model.fit_percent(flat)
    # the simulation needs no output channel; the one-step prediction does
    inputs_only = TimeData.from_rate(10.0, {"u1": np.ones(50), "u2": np.ones(50)})
    assert model.predict(inputs_only, horizon=math.inf).shape == (50,)
    with pytest.raises(DataError, match=r"output channel\(s\) \['y'\] not found in the data"):
        model.predict(inputs_only, horizon=1)


def test_order_selection_errors():
    data = _order_data(24, n=300)
    with pytest.raises(DataError, match=r"structure must be one of \['armax', 'arx', 'bj', 'oe'\]; got 'fir'"):
        select_order(data, inputs="u", output="y", structure="fir")
    with pytest.raises(DataError, match=r"criterion must be 'aic', 'bic', 'fpe' or 'validation'; got 'mdl'"):
        select_order(data, inputs="u", output="y", criterion="mdl")
    with pytest.raises(DataError, match=r"criterion 'validation' needs validation data"):
        select_order(data, inputs="u", output="y", criterion="validation")
    with pytest.raises(
        DataError, match=r"each arx candidate order must be an integer n .* \('na', 'nb'\) of integers; got \(1, 2, 3\)"
    ):
        select_order(data, inputs="u", output="y", orders=[(1, 2, 3)])
    with pytest.raises(DataError, match=r"orders must list at least one candidate"):
        select_order(data, inputs="u", output="y", orders=[])


def test_clipped_output_warns_by_name():
    rng = np.random.default_rng(6)
    u = rng.standard_normal(3000)
    y = sig.lfilter([0, 1.0, 0.5], [1, -1.5, 0.7], u)
    limit = 0.5 * np.abs(y).max()
    data = TimeData.from_rate(100.0, {"u": u, "y": np.clip(y, -limit, limit)})
    with pytest.warns(DataWarning, match=r"look clipped .*'y'"):
        ARX(2, 2).fit(data, inputs=["u"], output="y")


def test_with_parameters_copies_the_model_with_other_polynomials():
    """The copy used to propagate the OE covariance (two-step weighting): same orders, new polynomials, original
    unchanged; a vector of the wrong length or with NaN is refused."""
    t = np.arange(400.0)
    data = TimeData.from_rate(100.0, {"u": np.sin(0.3 * t), "y": np.cos(0.2 * t)})
    oe = OE(nb=2, nf=1).fit(data, inputs="u", output="y")
    theta = oe.parameters_ + np.array([0.1, -0.2, 0.05])
    other = oe.with_parameters(theta)
    np.testing.assert_array_equal(other.parameters_, theta)
    np.testing.assert_array_equal(other.F_[0][1:], theta[2:])  # names: b1[u], b2[u], f1[u]
    np.testing.assert_array_equal(other.B_[0][1:], theta[:2])
    assert not np.array_equal(oe.parameters_, theta)
    with pytest.raises(DataError, match=r"with_parameters: need 3 finite parameters .*; got shape \(2,\)"):
        oe.with_parameters(theta[:2])
    with pytest.raises(DataError, match="with_parameters: need 3 finite parameters"):
        oe.with_parameters([np.nan, 0.0, 0.0])
