"""Intervals that stay honest (issue 21): coloured residuals, positive parameters, practical identifiability.

References: a linear regression with AR(1) errors whose true slope is known (Monte Carlo coverage), and the
issue's two-step repro on data from scipy.signal.lsim (tests/estimate/test_intersample.py writes them from the
physics of the rig).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal as sig
from test_intersample import FS, TRUTH, _fit, _force, _lsim, _record  # the rig written from physics

from cappe.estimate._base import honest_intervals
from cappe.estimate._space import ParameterSpace
from cappe.estimate._uncertainty import correlated_uncertainty, jacobian_uncertainty
from cappe.model import load_model
from cappe.systems import TimeData


def test_sandwich_covers_with_ar1_residuals_where_gauss_newton_does_not():
    """y = a x + e with AR(1) errors (rho 0.8) and a smooth regressor: 400 draws, nominal 95 %."""
    rng = np.random.default_rng(0)
    n = 500
    x = np.sin(np.linspace(0, 6, n))[:, None]
    covered = {"gn": 0, "hac": 0}
    for _ in range(400):
        e = sig.lfilter([1.0], [1.0, -0.8], rng.standard_normal(n + 100))[100:]
        y = 2.0 * x[:, 0] + e
        a = float(np.linalg.lstsq(x, y, rcond=None)[0][0])
        r = a * x[:, 0] - y
        gn = jacobian_uncertainty(names=["a"], values=[a], jacobian=x, residuals=r)
        hac = correlated_uncertainty(gn, jacobian=x, residuals=r, block=1, records=[n], max_lag=40)
        covered["gn"] += abs(a - 2.0) <= 1.96 * gn.std[0]
        covered["hac"] += abs(a - 2.0) <= 1.96 * hac.std[0]
    assert covered["gn"] < 0.6 * 400  # white-noise theory: far too narrow
    assert covered["hac"] > 0.85 * 400  # Newey-West: near nominal (measured 87.8 %; Bartlett bias at rho 0.8)


def test_ekf_switches_to_the_sandwich_on_coloured_output_errors(two_mass):
    """EKF (FOH) on lsim data with 2 % low-pass (150 Hz) output noise, F1 only, 7 unknowns: the output errors fail the
    whiteness test, "auto" reports the Newey-West sandwich, 1.2-2.5x wider than the inverse information (seen);
    measured over 10 such records: see the README's coverage notes."""
    rng = np.random.default_rng(100)
    f = _force(6000, FS, 700.0, rng)
    y = _lsim(TRUTH, f)
    b, a = sig.butter(4, 150.0 / (FS / 2))
    e = sig.lfilter(b, a, rng.standard_normal(y.shape), axis=0)
    y = y + 0.02 * np.sqrt(np.mean(y**2, axis=0)) * e / e.std(axis=0)
    data = TimeData.from_rate(FS, {"F1": f[:, 0], "d1": y[:, 0], "d2": y[:, 1]})
    est = _fit(two_mass, "ekf", data, intersample="foh")
    assert est.diagnostics["covariance"]["kind"] == "sandwich (Newey-West)"
    gn = np.array([est.diagnostics["covariance"]["gauss_newton_std"][n] for n in est.names])
    assert np.all(est.std > 1.1 * gn)
    assert est.success  # coloured but independent of the input: a warning, not a failure
    plain = _fit(two_mass, "ekf", data, intersample="foh", covariance="gauss-newton")
    np.testing.assert_allclose(plain.std, gn, rtol=1e-9)  # the same information, without the sandwich


def test_ekf_sandwich_is_centred_on_the_output_error_optimum(two_mass):
    """The record of the 10 (seeds 100-109, 2 % low-pass noise) whose sandwich intervals missed most: the filter's
    estimate sat 2.1-2.2 sandwich std from the truth in m2, k11, k12, k22, c22 (5 of 7 missed; 60 / 70 over the 10
    records) because the sandwich was centred where the filter stopped, not at the output-error optimum it is
    computed for. With the Gauss-Newton refinement: within 1.3 std, 7 / 7 (65 / 70 over the 10)."""
    rng = np.random.default_rng(106)
    f = _force(6000, FS, 700.0, rng)
    y = _lsim(TRUTH, f)
    b, a = sig.butter(4, 150.0 / (FS / 2))
    e = sig.lfilter(b, a, rng.standard_normal(y.shape), axis=0)
    y = y + 0.02 * np.sqrt(np.mean(y**2, axis=0)) * e / e.std(axis=0)
    data = TimeData.from_rate(FS, {"F1": f[:, 0], "d1": y[:, 0], "d2": y[:, 1]})
    est = _fit(two_mass, "ekf", data, intersample="foh")
    assert est.diagnostics["covariance"]["kind"] == "sandwich (Newey-West)"
    z = {n: (v - TRUTH[n]) / s for n, v, s in zip(est.names, est.values, est.std, strict=True)}
    assert max(abs(v) for v in z.values()) < 1.96, z
    assert est.success


def test_direct_switches_to_the_sandwich_on_coloured_equation_errors(two_mass):
    """direct (model instruments) on d, v, a of the rig with 2 % low-pass (150 Hz) noise: the equation errors are
    coloured and "auto" reports the Newey-West sandwich; with white noise it keeps s^2 (J^T J)^-1."""
    from cappe.identify import random_noise
    from cappe.model import NumericModel
    from cappe.systems import time_response

    nm = NumericModel(two_mass)
    force = random_noise(fs=FS, duration=2.0, rms=10.0, band=(1.0, 700.0), rng=3, name="F1")
    clean = time_response(nm.system({"c11": 20.0, "c22": 4.0}), force, outputs=["d1", "d2", "v1", "v2", "a1", "a2"])
    rng = np.random.default_rng(4)
    b, a = sig.butter(4, 150.0 / (FS / 2))
    values = clean.values.copy()
    for k in range(1, values.shape[0]):  # row 0 is the force
        e = sig.lfilter(b, a, rng.standard_normal(values.shape[1]))
        values[k] += 0.02 * np.sqrt(np.mean(values[k] ** 2)) * e / e.std()
    data = TimeData(clean.time, values, clean.channels, clean.units)
    est = _fit(two_mass, "direct", data, instruments="model", inputs=["F1"])
    assert est.diagnostics["covariance"]["kind"] == "sandwich (Newey-West)"
    gn = np.array([est.diagnostics["covariance"]["gauss_newton_std"][n] for n in est.names])
    assert np.all(est.std > gn)
    assert any("not white" in w for w in est.diagnostics["warnings"])
    white = clean.values.copy()
    white[1:] += 0.01 * np.sqrt(np.mean(white[1:] ** 2, axis=1, keepdims=True)) * rng.standard_normal(white[1:].shape)
    plain = _fit(two_mass, "direct", TimeData(clean.time, white, clean.channels, clean.units), instruments="model",
                 inputs=["F1"])
    assert all(plain.diagnostics["equation_errors_white"].values())  # white noise passes Ljung-Box (seen)
    assert "covariance" not in plain.diagnostics


def test_positive_intervals_stay_positive_and_inside_the_bounds(two_mass):
    space = ParameterSpace.from_model(two_mass, ["m2", "k11"])
    jac = np.array([[1.0, 0.0], [0.0, 1e-4], [1.0, 1e-4]])  # relative sensitivities 1 (m2) and 140 (k11)
    unc = jacobian_uncertainty(names=space.names, values=[1.0, 1.4e6], jacobian=jac, residuals=[0.5, -0.5, 0.5])
    assert unc.ci95[0, 0] < 0  # the symmetric interval of m2 reaches negative masses
    fixed, practical = honest_intervals(space, unc, [])
    lo, hi = space.lower[0], space.upper[0]
    assert lo <= fixed.ci95[0, 0] < 1.0 < fixed.ci95[0, 1] <= hi
    assert set(practical) == {"m2"}
    assert practical["m2"].startswith("relative std")
    assert not fixed.identifiable[0]
    assert fixed.identifiable[1]


@pytest.mark.slow
def test_two_step_at_a_bound_is_not_called_identifiable(two_mass):
    """The issue: two-step-tf on lsim data, F1 only, held-input inverse: m2 at its bound 0.4 kg, std 15 600 %,
    interval [-159.6, 160.4] kg and 'identifiable: yes'."""
    rng = np.random.default_rng(1)
    f = _force(6000, FS, 700.0, rng)
    est = _fit(two_mass, "two-step-tf", _record(f, _lsim(TRUTH, f), 0.01, rng), intersample="zoh")
    k = est.names.index("m2")
    practical = est.diagnostics["practically_non_identifiable"]
    assert "m2" in practical
    assert not est.identifiable[k]
    bounds = load_model("builtin:two-mass-rig").parameter("m2").bounds
    assert bounds[0] <= est.ci95[k, 0] <= est.ci95[k, 1] <= bounds[1]
    assert "m2" in est.diagnostics["weakest_direction"]["combination"]
    # and step 1 (an OE model of a held input fitted to a linear one) fails its residual tests: not a success
    assert not est.success
    assert est.message.startswith("step 1 (output-error model) the residuals correlate with the inputs")
    assert any("residuals of d1 correlate with input F1" in w for w in est.diagnostics["warnings"])
