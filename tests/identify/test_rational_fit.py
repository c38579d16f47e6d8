"""Frequency-domain rational fits (Levy, Sanathanan-Koerner) against exact rational models.

References: the two-mass rig's transfer functions written out here in closed form from M, C and K (the
characteristic polynomial det(M s^2 + C s + K) and its adjugate), exact FRFs of a 3-DOF chain and of a random
8-mode model built from chosen poles, the exact complex modes (``MechanicalSystem.modes()``), python-control's
evaluation of the fitted transfer functions, and seeded noisy FRFs with stated tolerances.
"""

from __future__ import annotations

import control
import numpy as np
import pytest

from cappe.exceptions import ConvergenceWarning, DataError
from cappe.identify._rational import fit_rational
from cappe.model import NumericModel
from cappe.systems.frf import FRFData
from cappe.systems.mechanical import MechanicalSystem


@pytest.fixture(scope="module")
def rig(two_mass):
    return NumericModel(two_mass).system()


def _rig_polynomials(rig):
    """Closed-form d1/F1 and d2/F1 of the two-mass rig: adj(Z) / det(Z), Z = M s^2 + C s + K."""
    m1, m2 = rig.M[0, 0], rig.M[1, 1]
    (c_a, c_b), (_, c_d) = rig.C
    (k_a, k_b), (_, k_d) = rig.K
    z11 = [m1, c_a, k_a]
    z22 = [m2, c_d, k_d]
    z12 = [c_b, k_b]
    det = np.polysub(np.polymul(z11, z22), np.polymul(z12, z12))
    return np.array(z22) / det[0], -np.array(z12) / det[0], det / det[0]


def _noisy(frf, seed, level=0.01):
    """FRF with complex Gaussian noise of ``level`` times |H| at each line (constant SNR per line)."""
    rng = np.random.default_rng(seed)
    noise = (rng.standard_normal(frf.H.shape) + 1j * rng.standard_normal(frf.H.shape)) / np.sqrt(2)
    return FRFData(frf.freq, frf.H * (1 + level * noise), frf.input_names, frf.output_names)


@pytest.fixture(scope="module")
def chain():
    m = np.diag([2.0, 1.5, 1.0])
    k1, k2, k3 = 4e5, 3e5, 2e5
    k = np.array([[k1 + k2, -k2, 0.0], [-k2, k2 + k3, -k3], [0.0, -k3, k3]])
    zero = np.zeros((3, 3))
    return MechanicalSystem(
        m, 2e-5 * k + 5.0 * m, k, zero, zero, np.eye(3)[:, [0, 2]], np.eye(3), ("x1", "x2", "x3"), ("F1", "F3"),
        ("d1", "d2", "d3"), ("displacement",) * 3, "chain",
    )  # fmt: skip


# -- exact recovery ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["sk", "levy"])
def test_exact_rig_transfer_functions_are_recovered(rig, method):
    freq = np.linspace(1.0, 400.0, 800)
    frf = rig.frf(freq, ["F1"], ["d1", "d2"])
    fit = fit_rational(frf, order=(2, 4), method=method)
    g11, g21, den = _rig_polynomials(rig)
    # noise-free data of an exactly representable model: the brief asks for ~1e-8 relative; measured ~1e-14
    np.testing.assert_allclose(fit.transfer_function("d1", "F1").denominator, den, rtol=1e-8)
    np.testing.assert_allclose(fit.transfer_function("d1", "F1").numerator, g11, rtol=1e-8)
    num21 = np.asarray(fit.transfer_function("d2", "F1").numerator)
    # c12 = 0: the s^2 and s coefficients of d2/F1 vanish; compare against the largest coefficient's scale
    np.testing.assert_allclose(num21, np.concatenate([[0.0], g21]), rtol=1e-8, atol=1e-8 * abs(g21).max() / 400**2)
    truth = rig.modes()
    np.testing.assert_allclose(fit.modes.frequency, truth.frequency, rtol=1e-8)
    np.testing.assert_allclose(fit.modes.damping, truth.damping, rtol=1e-6)
    assert fit.rms_error < 1e-10
    assert fit.converged
    assert fit.order == (2, 4)
    assert fit.method == method


def test_exact_chain_with_two_inputs_and_three_outputs(chain):
    freq = np.linspace(1.0, 250.0, 1000)
    fit = fit_rational(chain.frf(freq), n_poles=6)
    assert len(fit.transfer_functions) == 6
    assert fit.order == (5, 6)
    truth = chain.modes()
    np.testing.assert_allclose(fit.modes.frequency, truth.frequency, rtol=1e-8)
    np.testing.assert_allclose(fit.modes.damping, truth.damping, rtol=1e-8)
    # reciprocity of the fitted model: d3/F1 equals d1/F3 (the data are reciprocal, the fit is exact)
    s = 2j * np.pi * np.array([30.0, 90.0])
    a, b = fit.transfer_function("d3", "F1").evaluate(s), fit.transfer_function("d1", "F3").evaluate(s)
    np.testing.assert_allclose(a, b, rtol=1e-8)


def test_sixteen_poles_stay_well_conditioned():
    rng = np.random.default_rng(1)
    omega = np.sort(rng.uniform(50.0, 500.0, 8)) * 2 * np.pi
    zeta = rng.uniform(0.005, 0.05, 8)
    upper = -zeta * omega + 1j * omega * np.sqrt(1 - zeta**2)
    poles = np.concatenate([upper, upper.conj()])
    zeros = np.concatenate([upper[:7] * 1.03, upper[:7].conj() * 1.03])
    freq = np.linspace(1.0, 700.0, 2000)
    s = 2j * np.pi * freq
    h = np.prod(s[:, None] - zeros, axis=1) / np.prod(s[:, None] - poles, axis=1)
    fit = fit_rational((freq, h), order=(14, 16))
    # a monomial basis would be hopeless here (Vandermonde condition ~1e20); the orthogonal basis gives 2e-11
    got = np.sort_complex(fit.poles)
    np.testing.assert_allclose(got, np.sort_complex(poles), rtol=1e-8)
    np.testing.assert_allclose(fit.modes.damping, zeta, rtol=1e-6)


def test_fitted_model_evaluates_as_python_control_does(rig):
    freq = np.linspace(1.0, 400.0, 400)
    frf = _noisy(rig.frf(freq, ["F1"], ["d1", "d2"]), seed=3)
    fit = fit_rational(frf, n_poles=4)
    omega = 2 * np.pi * np.array([10.0, 89.0, 120.0, 166.0, 350.0])
    got = fit.evaluate(omega / (2 * np.pi))
    for k, tf in enumerate(fit.transfer_functions):
        ref = control.tf(list(tf.numerator), list(tf.denominator))(1j * omega)
        np.testing.assert_allclose(got[k, 0], ref, rtol=1e-10)
    np.testing.assert_allclose(
        np.sort_complex(fit.poles), np.sort_complex(control.poles(fit.transfer_functions[0].to_control())), rtol=1e-6
    )


# -- noisy data ---------------------------------------------------------------------------------------------------
# 1 % complex noise per line. Over 20 seeds (measured): rig frequencies within 3.4e-5, damping within 2 % (the
# 90 Hz mode has zeta = 5e-4, a half-power band of 0.09 Hz sampled every 0.2 Hz); chain within 7e-5 and 0.4 %.
# Tolerances: 10x the frequency spread, 2.5x the damping spread.


def test_noisy_rig_modes_within_tolerance(rig):
    freq = np.linspace(5.0, 300.0, 1500)
    frf = _noisy(rig.frf(freq, ["F1"], ["d1", "d2"]), seed=7)
    truth = rig.modes()
    sk = fit_rational(frf, n_poles=4)
    np.testing.assert_allclose(sk.modes.frequency, truth.frequency, rtol=3e-4)
    np.testing.assert_allclose(sk.modes.damping, truth.damping, rtol=5e-2)
    # the residual is the noise (1 % of |H| per line), a little less where the model absorbs some of it
    assert 0.005 < sk.rms_error < 0.012
    # SK weights toward the output error, which Levy's linearization over-weights at high |D|: lower error
    levy = fit_rational(frf, n_poles=4, method="levy")
    assert sk.rms_error < levy.rms_error
    assert sk.iterations > levy.iterations == 1


def test_noisy_chain_modes_within_tolerance(chain):
    freq = np.linspace(1.0, 250.0, 1000)
    fit = fit_rational(_noisy(chain.frf(freq), seed=8), n_poles=6)
    truth = chain.modes()
    np.testing.assert_allclose(fit.modes.frequency, truth.frequency, rtol=7e-4)
    np.testing.assert_allclose(fit.modes.damping, truth.damping, rtol=1e-2)


def test_zero_weights_ignore_corrupted_lines(rig):
    freq = np.linspace(1.0, 400.0, 800)
    frf = rig.frf(freq, ["F1"], ["d1"])
    h = frf.H.copy()
    h[..., 100:130] *= 5.0  # a corrupted band (e.g. a shaker resonance)
    weights = np.ones(freq.size)
    weights[100:130] = 0.0
    fit = fit_rational((freq, h[0, 0]), n_poles=4, weights=weights)
    np.testing.assert_allclose(fit.modes.frequency, rig.modes().frequency, rtol=1e-8)
    bad = fit_rational((freq, h[0, 0]), n_poles=4)
    assert np.abs(bad.modes.frequency / rig.modes().frequency - 1).max() > 1e-4


def test_pair_input_shapes_and_names(rig):
    freq = np.linspace(1.0, 400.0, 300)
    h = rig.frf(freq, ["F1"], ["d1", "d2"]).H
    one = fit_rational((freq, h[0, 0]), n_poles=4)
    assert one.input_names == ("u1",)
    assert one.output_names == ("y1",)
    two = fit_rational((freq, h[:, 0, :]), n_poles=4)
    assert two.output_names == ("y1", "y2")
    assert two.evaluate(freq).shape == (2, 1, 300)
    out = two.to_dict()
    assert out["order"] == [3, 4]
    assert len(out["modes"]) == 2
    assert len(out["transfer_functions"]) == 2


def test_sk_without_settling_warns(rig):
    frf = _noisy(rig.frf(np.linspace(5.0, 300.0, 600), ["F1"], ["d1"]), seed=9)
    with pytest.warns(ConvergenceWarning, match=r"Sanathanan-Koerner iterations did not settle in 1 solves"):
        fit = fit_rational(frf, n_poles=4, iterations=1)
    assert fit.converged is False


# -- errors -------------------------------------------------------------------------------------------------------


def test_fit_rational_errors(rig):
    freq = np.linspace(1.0, 400.0, 50)
    h = rig.frf(freq, ["F1"], ["d1"]).H[0, 0]
    with pytest.raises(
        DataError,
        match=r"give exactly one of n_poles and order=\(num_degree, den_degree\); got n_poles=4, order=\(2, 4\)",
    ):
        fit_rational((freq, h), n_poles=4, order=(2, 4))
    with pytest.raises(DataError, match=r"give exactly one of n_poles and order"):
        fit_rational((freq, h))
    with pytest.raises(DataError, match=r"n_poles must be an integer >= 1; got 0"):
        fit_rational((freq, h), n_poles=0)
    with pytest.raises(
        DataError, match=r"order must satisfy 0 <= num_degree <= den_degree and den_degree >= 1; got \(5, 4\)"
    ):
        fit_rational((freq, h), order=(5, 4))
    with pytest.raises(DataError, match=r"order must be a pair \(num_degree, den_degree\) of integers; got 4"):
        fit_rational((freq, h), order=4)  # type: ignore[arg-type]
    with pytest.raises(DataError, match=r"method must be 'sk' or 'levy'; got 'vf'"):
        fit_rational((freq, h), n_poles=4, method="vf")
    with pytest.raises(DataError, match=r"iterations must be an integer >= 1; got 0"):
        fit_rational((freq, h), n_poles=4, iterations=0)
    with pytest.raises(DataError, match=r"tol must be a number in \(0, 1\); got 0"):
        fit_rational((freq, h), n_poles=4, tol=0)
    with pytest.raises(
        DataError,
        match=r"too few frequencies: 5 complex FRF samples in 1 column\(s\) give 10 real equations for 18 unknowns",
    ):
        fit_rational((freq[:5], h[:5]), n_poles=9)
    with pytest.raises(DataError, match=r"freq must be 1-D with one entry per FRF sample \(50\); got shape \(49,\)"):
        fit_rational((freq[1:], h), n_poles=4)
    with pytest.raises(DataError, match=r"freq must hold finite frequencies >= 0 Hz"):
        fit_rational((-freq, h), n_poles=4)
    with pytest.raises(DataError, match=r"freq must not repeat a frequency"):
        fit_rational((np.ones(50), h), n_poles=4)
    bad = h.copy()
    bad[3] = np.nan
    with pytest.raises(DataError, match=r"H has non-finite values, first at output 'y1', input 'u1', 25.4\d* Hz"):
        fit_rational((freq, bad), n_poles=4)
    with pytest.raises(
        DataError,
        match=r"H must have shape \(n_freq,\), \(n_columns, n_freq\) or \(n_out, n_in, n_freq\); got \(1, 1, 1, 50\)",
    ):
        fit_rational((freq, h[None, None, None]), n_poles=4)
    with pytest.raises(DataError, match=r"frf must be FRFData or a pair \(freq, H\); got int"):
        fit_rational(3, n_poles=4)  # type: ignore[arg-type]
    with pytest.raises(DataError, match=r"weights of shape \(3,\) do not broadcast to the FRF shape \(1, 1, 50\)"):
        fit_rational((freq, h), n_poles=4, weights=np.ones(3))
    with pytest.raises(DataError, match=r"weights must be finite, >= 0 and not all zero"):
        fit_rational((freq, h), n_poles=4, weights=-np.ones(50))
    fit = fit_rational((freq, h), n_poles=4)
    with pytest.raises(
        DataError,
        match=r"no fitted transfer function from input 'F1' to output 'd1'; inputs \['u1'\], outputs \['y1'\]",
    ):
        fit.transfer_function("d1", "F1")
