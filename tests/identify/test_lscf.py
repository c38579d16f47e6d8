"""Modal parameter extraction: (poly-reference) LSCF poles, stabilization diagrams, pole selection and LSFD.

References used here, all independent of the estimators:
* a 3-DOF proportionally damped structure whose modes come from ``scipy.linalg.eigh(K, M)``; its FRFs are the
  closed-form pole-residue sum ``phi phi^T / (2j omega_d) / (s - lambda) + conj`` (checked against a direct
  solve of the dynamic stiffness);
* the two-mass rig's exact complex modes (``MechanicalSystem.modes()``) and its exact residues
  ``psi psi^T / (psi^T (2 lambda M + C) psi)`` from the state-space eigenvectors;
* sdypy-EMA's LSCF run on the same data.
"""

from __future__ import annotations

import contextlib
import io
import warnings
from functools import cache

import numpy as np
import pytest
import scipy.linalg as sla

from cappe.correlate import mac
from cappe.exceptions import DataError
from cappe.identify._lscf import lscf_poles, select_poles, stabilization_diagram
from cappe.identify._lsfd import extract_modes, lsfd
from cappe.model.loader import load_model
from cappe.model.numeric import NumericModel
from cappe.systems.frf import FRFData

# -- reference structures ----------------------------------------------------------------------------------------
INPUTS = [0, 2]  # forces at DOF 1 and 3 (driving points x1 and x3)


@cache
def three_dof() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Poles (rad/s), damping ratios and mass-normalized shapes of a 3-DOF chain with Rayleigh damping."""
    m = np.diag([2.0, 1.0, 1.5])
    k = 1e5 * np.array([[3.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 1.5]])
    w2, phi = sla.eigh(k, m)
    wn = np.sqrt(w2)
    zeta = 3.0 / (2 * wn) + 4e-5 * wn / 2  # C = 3 M + 4e-5 K: zeta = alpha / (2 wn) + beta wn / 2
    lam = -zeta * wn + 1j * wn * np.sqrt(1 - zeta**2)
    return lam, zeta, phi


def modal_frf(freq: np.ndarray, lam: np.ndarray, residues: np.ndarray) -> np.ndarray:
    """``sum_r R_r / (s - lambda_r) + conj(R_r) / (s - conj(lambda_r))`` with ``R[out, in, mode]``."""
    s = 2j * np.pi * freq
    a = 1.0 / (s[None, :] - lam[:, None])
    b = 1.0 / (s[None, :] - lam.conj()[:, None])
    return np.einsum("oir,rf->oif", residues, a) + np.einsum("oir,rf->oif", residues.conj(), b)


def three_dof_frf(noise: float = 0.0, seed: int = 0, decay: float | None = None) -> FRFData:
    """FRFs x1..x3 / F1, F3 on 0..200 Hz (0.1 Hz lines); proportional complex noise of relative size ``noise``.

    With ``decay`` (s) the FRFs are those of the response seen through the window ``exp(-t / decay)``: every
    pole moves by ``-1 / decay``, the residues stay.
    """
    lam, _, phi = three_dof()
    freq = np.linspace(0.0, 200.0, 2001)
    res = phi[:, None, :] * phi[INPUTS][None, :, :] / (2j * lam.imag)
    H = modal_frf(freq, lam - (1.0 / decay if decay else 0.0), res)
    rng = np.random.default_rng(seed)
    H = H * (1 + noise * (rng.standard_normal(H.shape) + 1j * rng.standard_normal(H.shape)) / np.sqrt(2))
    return FRFData(freq, H, ("F1", "F3"), ("x1", "x2", "x3"), window_decay=decay)


def test_three_dof_closed_form_matches_direct_solve():
    # the reference FRF itself: pole-residue form vs (K + s C + s^2 M)^-1, to rounding (rtol 1e-12)
    m = np.diag([2.0, 1.0, 1.5])
    k = 1e5 * np.array([[3.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 1.5]])
    c = 3.0 * m + 4e-5 * k
    frf = three_dof_frf()
    s = 2j * np.pi * frf.freq
    direct = np.linalg.solve(k + s[:, None, None] * c + s[:, None, None] ** 2 * m, np.eye(3)[:, INPUTS])
    np.testing.assert_allclose(frf.H, direct.transpose(1, 2, 0), rtol=0, atol=1e-12 * np.abs(direct).max())


@cache
def rig():
    return NumericModel(load_model("builtin:two-mass-rig")).system()


def rig_exact_residues() -> tuple[np.ndarray, np.ndarray]:
    """Exact poles and displacement residues of the rig: ``psi psi^T / (psi^T (2 lambda M + C) psi)``."""
    system = rig()
    lam, vec = np.linalg.eig(system.state_matrix("complex"))
    keep = np.flatnonzero(lam.imag > 0)
    keep = keep[np.argsort(lam[keep].imag)]
    lam, psi = lam[keep], vec[: system.n_dof, keep]
    a = 2 * lam * np.einsum("ir,ij,jr->r", psi, system.M, psi) + np.einsum("ir,ij,jr->r", psi, system.C, psi)
    return lam, psi[:, None, :] * psi[None, :, :] / a


# -- (a) known 3-DOF modal model ----------------------------------------------------------------------------------
@pytest.mark.parametrize("method", ["plscf", "lscf"])
def test_three_dof_noise_free_is_exact(method):
    lam, zeta, phi = three_dof()
    res = extract_modes(three_dof_frf(), band=(2.0, 190.0), max_order=30, method=method)
    # noise-free data follow the model exactly up to the z-domain fit: measured errors are ~1e-9 (frequency) and
    # ~1e-7 (damping), so 1e-7 and 1e-5 leave room for BLAS differences and still fail on any real defect
    np.testing.assert_allclose(res.frequency, np.abs(lam) / (2 * np.pi), rtol=1e-7)
    np.testing.assert_allclose(res.damping, zeta, rtol=1e-5)
    assert np.diag(mac(res.shapes, phi)).min() > 1 - 1e-10
    exact = phi[:, None, :] * phi[INPUTS][None, :, :] / (2j * lam.imag)
    np.testing.assert_allclose(res.fit.residues, exact, rtol=0, atol=1e-6 * np.abs(exact).max())
    assert res.fit.fit_error.max() < 1e-6


@pytest.mark.parametrize("method", ["plscf", "lscf"])
def test_three_dof_with_one_percent_noise(method):
    lam, zeta, phi = three_dof()
    res = extract_modes(three_dof_frf(noise=0.01, seed=3), band=(2.0, 190.0), max_order=40, method=method)
    assert res.selection.n_modes == 3
    # acceptance tolerances of the brief: frequency 0.5 %, damping 5 %, MAC 0.99
    # (worst over seeds 0..24, both methods: 1.1e-4, 3.3e-3, 1 - 5e-6)
    np.testing.assert_allclose(res.frequency, np.abs(lam) / (2 * np.pi), rtol=5e-3)
    np.testing.assert_allclose(res.damping, zeta, rtol=0.05)
    assert np.diag(mac(res.shapes, phi)).min() > 0.99


def test_driving_point_scaling_gives_mass_normalized_shapes():
    # proportional damping: R_r = phi_r phi_r^T / (2j omega_d), so driving-point scaling returns the mass-normalized
    # phi of eigh(K, M) (up to sign); noise-free, rtol 1e-6 on the largest component
    _, _, phi = three_dof()
    res = extract_modes(three_dof_frf(), band=(2.0, 190.0), max_order=30, driving_points={"F1": "x1", "F3": "x3"})
    assert res.fit.scaling == "driving point"
    sign = np.sign(phi[np.argmax(np.abs(phi), axis=0), range(3)])
    np.testing.assert_allclose(res.shapes, phi * sign, rtol=0, atol=1e-6 * np.abs(phi).max())
    # participation of input F3 (DOF 3) for mass-normalized shapes: phi_3 / (2j omega_d)
    lam = res.fit.poles
    np.testing.assert_allclose(res.fit.participation[1], res.shapes[2] / (2j * lam.imag), rtol=1e-6)


def test_unit_max_scaling_and_modal_data():
    res = extract_modes(three_dof_frf(), band=(2.0, 190.0), max_order=30)
    assert res.fit.scaling == "unit max"
    np.testing.assert_allclose(np.abs(res.shapes).max(axis=0), 1.0, rtol=1e-12)
    # the rank-one factors reproduce the residues (rank one by construction of the data)
    rebuilt = res.shapes[:, None, :] * res.fit.participation[None, :, :]
    # (the fitted residues deviate from rank one by the fit error, measured 1.3e-8 of the largest)
    np.testing.assert_allclose(rebuilt, res.fit.residues, rtol=0, atol=1e-6 * np.abs(res.fit.residues).max())
    data = res.to_modal_data({"z": 0.1})
    assert data.sensors == ("x1", "x2", "x3")
    assert data.sets[0].position == {"z": 0.1}
    np.testing.assert_array_equal(data.sets[0].frequency, res.frequency)
    out = res.to_dict()
    assert [m["frequency"] for m in out["modes"]] == sorted(m["frequency"] for m in out["modes"])
    assert set(out["modes"][0]) >= {"frequency", "damping"}
    assert out["diagram"]["format"] == "cappe.stabilization/1"


def test_synthesis_reproduces_the_true_frf_outside_the_fitted_lines():
    # fitted on 2..190 Hz, synthesized at off-grid frequencies vs the closed form: rel. error 1e-6 (noise-free)
    frf = three_dof_frf()
    fit = extract_modes(frf, band=(2.0, 190.0), max_order=30).fit
    lam, _, phi = three_dof()
    f_new = np.array([17.33, 32.2, 57.81, 120.05])
    truth = modal_frf(f_new, lam, phi[:, None, :] * phi[INPUTS][None, :, :] / (2j * lam.imag))
    got = fit.synthesize(f_new)
    assert got.output_names == frf.output_names
    np.testing.assert_allclose(got.H, truth, rtol=0, atol=1e-6 * np.abs(truth).max())


def test_manual_selection_by_frequency():
    lam, zeta, _ = three_dof()
    frf = three_dof_frf(noise=0.01, seed=5)
    f_true = np.abs(lam) / (2 * np.pi)
    res = extract_modes(frf, band=(2.0, 190.0), max_order=40, selection=[84.0, 32.0])  # any order
    np.testing.assert_allclose(res.frequency, f_true[[0, 2]], rtol=5e-3)  # the brief's 0.5 %
    sel = select_poles(res.diagram, near=[57.0])
    np.testing.assert_allclose(sel.damping, zeta[1], rtol=0.05)  # the brief's 5 %


def test_n_modes_keeps_the_most_persistent_clusters():
    lam, _, _ = three_dof()
    d = lscf_poles(three_dof_frf(noise=0.01, seed=2), band=(2.0, 190.0), max_order=40)
    sel = select_poles(d, n_modes=2)
    assert sel.n_modes == 2
    f_true = np.abs(lam) / (2 * np.pi)
    # each kept pole is one of the true modes (0.5 % frequency tolerance of the brief)
    assert all(np.min(np.abs(f / f_true - 1)) < 5e-3 for f in sel.frequency)
    assert np.all(np.diff(sel.frequency) > 0)


def test_explicit_orders_and_common_reference_diagram():
    d = lscf_poles(three_dof_frf(), band=(2.0, 190.0), orders=[10, 6, 8], reference="common")
    assert d.orders == (6, 8, 10)
    assert d.input_names == ("common",)
    assert set(np.unique(d.order)) <= {6, 8, 10}
    # a common-denominator model of order n has n poles (n / 2 in the upper half plane, minus real ones)
    assert all(d.at_order(n).size <= n // 2 for n in d.orders)
    np.testing.assert_array_equal(d.participation, 1.0)


# -- (b) two-mass rig ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("outputs", "method"), [(("d1", "d2"), "plscf"), (("v1", "a2"), "plscf"), (("d1", "d2"), "lscf")]
)
def test_two_mass_rig_exact_modes(outputs, method):
    system = rig()
    modes = system.modes()
    # 0.02 Hz lines: mode 1 has a half-power bandwidth of only 2 zeta f = 0.09 Hz
    frf = system.frf(np.arange(0.0, 250.0 + 1e-9, 0.02), inputs=["F1", "F2"], outputs=list(outputs))
    res = extract_modes(frf, band=(20.0, 240.0), max_order=20, method=method)
    # noise-free exact model FRFs: measured errors <= 1.5e-8 (frequency), 2e-6 (damping), 1e-6 (residues)
    np.testing.assert_allclose(res.frequency, modes.frequency, rtol=1e-7)
    np.testing.assert_allclose(res.damping, modes.damping, rtol=2e-5)
    assert np.diag(mac(res.shapes, modes.shapes)).min() > 1 - 1e-10
    lam, residues = rig_exact_residues()
    np.testing.assert_allclose(res.fit.poles, lam, rtol=1e-7)
    np.testing.assert_allclose(res.fit.residues, residues, rtol=0, atol=1e-5 * np.abs(residues).max())


def test_two_mass_rig_driving_point_shapes_are_exact_complex_modes():
    # with driving points, psi = v sqrt(2j omega_d / (v^T (2 lambda M + C) v)) for the exact eigenvector v
    system = rig()
    frf = system.frf(np.arange(0.0, 250.0 + 1e-9, 0.02), inputs=["F1", "F2"], outputs=["d1", "d2"])
    res = extract_modes(frf, band=(20.0, 240.0), max_order=20, driving_points={"F1": "d1", "F2": "d2"})
    lam, residues = rig_exact_residues()
    # R = psi psi^T / (2j omega_d): psi_o^2 = 2j omega_d R_oo, compared up to the sign of each mode
    expected_sq = 2j * lam.imag * np.diagonal(residues).T  # (out, mode)
    np.testing.assert_allclose(res.shapes**2, expected_sq, rtol=1e-5)


@pytest.mark.parametrize(("band", "mode"), [((80.0, 100.0), 0), ((150.0, 180.0), 1)])
def test_two_mass_rig_narrow_band(band, mode):
    # a band holding one mode maps onto a short arc of the unit circle, where the monomial basis is numerically
    # dependent at order 40 (a Cholesky factor of X^H X fails there); the poles must still be the exact ones
    system = rig()
    modes = system.modes()
    frf = system.frf(np.arange(0.0, 250.0 + 1e-9, 0.02), inputs=["F1", "F2"], outputs=["d1", "d2"])
    res = extract_modes(frf, band=band, max_order=40)
    # measured errors 1e-10 (frequency) and 1e-7 (damping) on noise-free data
    np.testing.assert_allclose(res.frequency, modes.frequency[[mode]], rtol=1e-8)
    np.testing.assert_allclose(res.damping, modes.damping[[mode]], rtol=1e-5)


# -- (c) cross-check with sdypy-EMA -------------------------------------------------------------------------------
def test_agrees_with_sdypy_ema():
    ema = pytest.importorskip("sdypy.EMA")
    frf = three_dof_frf(noise=0.01, seed=7)
    single = FRFData(frf.freq, frf.H[:, :1], ("F1",), frf.output_names)
    mine = extract_modes(single, band=(2.0, 190.0), max_order=40, method="lscf")
    model = ema.Model(
        frf=single.H[:, 0], freq=single.freq, lower=2.0, upper=190.0, pol_order_high=20, frf_form="receptance"
    )
    sink = io.StringIO()
    # EMA writes a tqdm progress bar to stderr; it filters its own numpy RuntimeWarnings, and any warning that
    # still escaped would be turned into an error by pytest's filterwarnings = error: record them to show them
    with (
        contextlib.redirect_stdout(sink),
        contextlib.redirect_stderr(sink),
        warnings.catch_warnings(record=True) as caught,
    ):
        warnings.simplefilter("always")
        model.get_poles(method="lscf", show_progress=False)
        model.select_closest_poles(list(mine.frequency))
    assert [str(w.message) for w in caught] == []
    # brief tolerances between the two tools: 0.1 % frequency, 2 % damping (worst over seeds 0..24: 1.3e-5, 2e-3)
    np.testing.assert_allclose(np.asarray(model.nat_freq), mine.frequency, rtol=1e-3)
    np.testing.assert_allclose(np.asarray(model.nat_xi), mine.damping, rtol=0.02)


# -- (d) stabilization flags --------------------------------------------------------------------------------------
def test_flags_with_a_spurious_pole_at_one_order_only():
    true = np.array([-0.5 + 2j * np.pi * 10.0, -2.0 + 2j * np.pi * 40.0])
    spurious = -3.0 + 2j * np.pi * 25.0
    vec = np.array([[1.0, 0.2], [0.3, 1.0]], dtype=complex)  # participation (n_in, n_poles)
    orders = [2, 4, 6, 8, 10]
    poles = [true * (1 + 1e-4 * k) for k in range(5)]
    vectors = [vec.copy() for _ in orders]
    poles[2] = np.append(poles[2], spurious)
    vectors[2] = np.column_stack([vec, [1.0, 1.0]])
    d = stabilization_diagram(orders=orders, poles=poles, participation=vectors, band=(1.0, 60.0))
    spur = int(np.flatnonzero(np.isclose(d.poles, spurious))[0])
    assert d.flags[spur] == "o"
    # the pole after the spurious order is compared with the true one of order 6, not with the spurious pole
    assert d.flags[d.at_order(2)].tolist() == ["o", "o"]
    assert all(d.flags[d.at_order(n)].tolist() == ["s", "s"] for n in (4, 8, 10))
    sel = select_poles(d)
    np.testing.assert_allclose(sel.frequency, np.abs(true) / (2 * np.pi), rtol=1e-3)  # order drift 4e-4
    assert sel.support.tolist() == [4, 4]


def test_flag_levels_and_exclusions():
    base = -1.0 + 2j * np.pi * 20.0
    v = np.array([[1.0], [0.0]], dtype=complex)
    w = np.array([[1.0], [1.0]], dtype=complex)  # MAC with v = 0.5
    more_damped = base.real * 1.2 + 1j * base.imag
    d = stabilization_diagram(
        orders=[1, 2, 3, 4, 5, 6],
        poles=[[base], [base * 1.001], [base * 1.001], [more_damped], [base], [base * 1.02]],
        participation=[v, v, w, w, v, v],
        band=(1.0, 60.0),
    )
    # 2: within 1 % / 5 % / MAC 0.98 -> s; 3: vector changed -> d; 4: damping +20 % -> v;
    # 5: damping back (-17 %) and vector changed -> f; 6: frequency +2 % -> o
    assert d.flags.tolist() == ["o", "s", "d", "v", "f", "o"]
    loose = d.with_tolerances(freq_tol=0.05, damping_tol=0.5, mac_tol=0.4)
    assert loose.flags.tolist() == ["o", "s", "s", "s", "s", "s"]
    assert loose.tolerances["freq_tol"] == 0.05
    d2 = stabilization_diagram(orders=[1, 2], poles=[[base], [base.real * 1.03 + 1j * base.imag]], band=(1.0, 60.0))
    assert d2.flags.tolist() == ["o", "s"]  # no vectors given: the vector test passes; damping +3 % is within 5 %
    ex = stabilization_diagram(
        orders=[2],
        poles=[[0.5 + 60j, -40.0 + 100j, -1 + 2j * np.pi * 80.0, -1 + 2j * np.pi * 30.0, -3.0 + 0j]],
        band=(1.0, 60.0),
        max_damping=0.2,
    )
    assert ex.excluded.tolist() == ["negative damping", "damping above cap", "outside band", ""]
    assert ex.flags.tolist() == ["x", "x", "x", "o"]
    table = d.to_dict()
    assert table["flag"] == d.flags.tolist()
    assert table["tolerances"]["mac_tol"] == 0.98


def test_lscf_diagram_is_stable_at_physical_poles_only():
    lam, _, _ = three_dof()
    d = lscf_poles(three_dof_frf(noise=0.01, seed=11), band=(2.0, 190.0), max_order=40)
    f_true = np.abs(lam) / (2 * np.pi)
    stable = d.stable("s")
    near = np.min(np.abs(d.frequency[stable, None] / f_true[None] - 1), axis=1)
    # every fully stable pole at order >= 10 is a physical one (within 1 %, the frequency tolerance itself)
    assert np.all(near[d.order[stable] >= 10] < 0.01)
    assert d.reference == "poly"
    assert d.input_names == ("F1", "F3")


# -- (e) exponential window -----------------------------------------------------------------------------------
def test_window_decay_correction():
    lam, zeta, phi = three_dof()
    tau = 0.5  # s: shifts every pole by -2 1/s, raising the damping ratios by 28 to 86 %
    frf = three_dof_frf(decay=tau)
    res = extract_modes(frf, band=(2.0, 190.0), max_order=30)
    np.testing.assert_allclose(res.damping, zeta, rtol=1e-5)  # same tolerance as the noise-free case
    np.testing.assert_allclose(res.fit.poles, lam, rtol=1e-8)
    exact = phi[:, None, :] * phi[INPUTS][None, :, :] / (2j * lam.imag)
    np.testing.assert_allclose(res.fit.residues, exact, rtol=0, atol=1e-6 * np.abs(exact).max())
    # the windowed synthesis reproduces the data; the plain one is the structure without the window
    f_new = np.array([32.0, 57.9])
    np.testing.assert_allclose(
        res.fit.synthesize(f_new, windowed=True).H,
        modal_frf(f_new, lam - 1 / tau, exact),
        rtol=0,
        atol=1e-6 * np.abs(exact).max(),
    )
    # without window_decay the estimate is the windowed structure's damping (closed form of the shifted pole)
    plain = FRFData(frf.freq, frf.H, frf.input_names, frf.output_names)
    uncorrected = extract_modes(plain, band=(2.0, 190.0), max_order=30)
    shifted = lam - 1 / tau
    np.testing.assert_allclose(uncorrected.damping, -shifted.real / np.abs(shifted), rtol=1e-5)
    assert np.all(uncorrected.damping > 1.25 * zeta)


# -- (f) errors -----------------------------------------------------------------------------------------------
def _frf(**kw):
    f = kw.pop("freq", np.linspace(0.0, 100.0, 201))
    H = kw.pop("H", np.ones((1, 1, np.size(f)), complex))
    return FRFData(f, H, ("F",), ("x",), **kw)


def test_band_overshooting_by_less_than_one_line_is_clipped_to_the_data():
    # an FRF estimated for band (20, 200) has lines strictly inside it; the same band must work here
    freq = np.linspace(20.2, 199.8, 450)
    s = 2j * np.pi * freq
    pole = 2 * np.pi * (-0.5 + 80j)
    h = (1 / (s - pole) + 1 / (s - np.conj(pole)))[None, None, :]
    clipped = lscf_poles(FRFData(freq, h, ("F",), ("x",)), band=(20.0, 200.0), max_order=4)
    exact = lscf_poles(FRFData(freq, h, ("F",), ("x",)), band=(20.2, 199.8), max_order=4)
    assert clipped.band == exact.band == (20.2, 199.8)
    np.testing.assert_array_equal(clipped.poles, exact.poles)


def _diagram():
    return stabilization_diagram(orders=[2, 4], poles=[[-1 + 60j], [-1 + 60j]], band=(1.0, 60.0))


def _bad_nan():
    H = np.ones((1, 1, 201), complex)
    H[0, 0, 50] = np.nan
    return _frf(H=H)


ERRORS = [
    (lambda: lscf_poles(_frf(freq=np.array([1.0]), H=np.ones((1, 1, 1))), band=(0, 1)), r"1-D with at least 2 lines"),
    (lambda: lscf_poles(_frf(freq=np.array([0.0, 2.0, 1.0])), band=(0, 1)), r"strictly increasing"),
    (lambda: lscf_poles(_frf(H=np.ones((1, 2, 201))), band=(0, 1)), r"shape \(n_out, n_in, n_freq\) = \(1, 1, 201\)"),
    (lambda: lscf_poles(_frf(window_decay=-1.0), band=(1, 50)), r"FRF window_decay must be None or a time constant > 0 in s; got -1.0"),
    (lambda: lscf_poles(_frf(), band=5.0), r"band must be a pair \(f_lo, f_hi\) in Hz; got 5.0"),
    (lambda: lscf_poles(_frf(), band=(10.0, 150.0)), r"band \(10, 150\) Hz .* data's frequency range \[0, 100\] Hz"),
    # overshooting the data by more than one line (0.5 Hz here) is an error; less is clipped (see below)
    (lambda: lscf_poles(_frf(), band=(10.0, 100.6)), r"band \(10, 100.6\) Hz .* data's frequency range"),
    (lambda: lscf_poles(_frf(), band=(60.0, 20.0)), r"band \(60, 20\) Hz must satisfy 0 <= f_lo < f_hi"),
    (lambda: lscf_poles(_bad_nan(), band=(1.0, 90.0)), r"FRF x/F contains NaN or Inf in the band \(first at 25 Hz\)"),
    (lambda: lscf_poles(_frf(), band=(1, 50), reference="left"), r"reference must be 'poly' or 'common'; got 'left'"),
    (lambda: lscf_poles(_frf(), band=(1, 50), orders=[0, 2]), r"model orders must be integers >= 1; got \[0, 2\]"),
    (lambda: lscf_poles(_frf(), band=(1, 50), max_order=1), r"model orders must be integers >= 1; got none"),
    (
        lambda: lscf_poles(_frf(), band=(1, 50), max_order="high"),
        r"model orders must be integers; got orders=None, max_order='high'",
    ),
    (
        lambda: lscf_poles(_frf(), band=(1, 5), max_order=40),
        r"band \(1, 5\) Hz holds 9 frequency lines; model order 40",
    ),
    (lambda: lscf_poles(_frf(H=np.zeros((1, 1, 201))), band=(1, 50)), r"all FRFs are zero in the band"),
    (lambda: lscf_poles(_frf(), band=(1, 50), freq_tol=0.0), r"freq_tol must be > 0; got 0.0"),
    (lambda: lscf_poles(_frf(), band=(1, 50), mac_tol=1.5), r"mac_tol must be in \(0, 1\]; got 1.5"),
    (lambda: stabilization_diagram(orders=[4, 2], poles=[[1j], [1j]]), r"strictly ascending .* got \[4, 2\]"),
    (
        lambda: stabilization_diagram(orders=[2], poles=[[1j], [1j]]),
        r"poles must hold one array per order \(1\); got 2",
    ),
    (
        lambda: stabilization_diagram(orders=[2], poles=[[1j]], participation=[]),
        r"participation must hold one array per order \(1\); got 0",
    ),
    (
        lambda: stabilization_diagram(orders=[2], poles=[[1j]], band=(5, 1)),
        r"band must be \(f_lo, f_hi\) with f_lo < f_hi in Hz; got \(5, 1\)",
    ),
    (lambda: stabilization_diagram(orders=[2], poles=[[np.nan]]), r"poles of order 2 must be a 1-D array of finite"),
    (
        lambda: stabilization_diagram(orders=[2], poles=[[1j]], participation=[np.ones((2, 3))]),
        r"participation of order 2 must have shape \(n_vec, 1\) .* got \(2, 3\)",
    ),
    (lambda: select_poles(_diagram(), near=[]), r"near must be a non-empty list of frequencies > 0 Hz"),
    (lambda: select_poles(_diagram(), near=[30.0]), r"no stable pole within 5 % of 30 Hz .*band 1 .. 60 Hz"),
    (lambda: select_poles(_diagram(), near=[9.5], window=2.0), r"window must be in \(0, 1\]; got 2.0"),
    (lambda: select_poles(_diagram(), n_modes=0), r"n_modes must be a positive integer; got 0"),
    (lambda: select_poles(_diagram(), n_modes=2), r"n_modes=2 requested but the stable poles form only 1 clusters"),
    (lambda: select_poles(_diagram(), min_fraction=0.0), r"min_fraction must be in \(0, 1\]; got 0.0"),
    (lambda: select_poles(stabilization_diagram(orders=[2], poles=[[-1 + 60j]])), r"has no stable poles"),
    (
        lambda: select_poles(
            stabilization_diagram(orders=[1, 2, 3, 4, 5], poles=[[-1 + 60j]] * 2 + [[-1 + 90j]] * 3), min_fraction=0.9
        ),
        r"no pole cluster is stable in at least 90 % of the 5 model orders \(best: 2\)",
    ),
    (
        lambda: lsfd(_frf(output_quantities=("velocity", "velocity")), poles=[-1 + 60j], band=(1, 50)),
        r"FRF output_quantities must list one quantity per output \(1\); got 2",
    ),
    (
        lambda: lsfd(_frf(), poles=[-1 - 60j], band=(1, 50)),
        r"poles must be a non-empty 1-D array of finite poles in the upper half plane",
    ),
    (lambda: lsfd(_frf(), poles=["a"], band=(1, 50)), r"poles must be complex numbers in rad/s"),
    (
        lambda: lsfd(_frf(), poles=[-1 + 60j], band=(1, 50), driving_points={"G": "x"}),
        r"driving_points: unknown input 'G'; FRF inputs: F",
    ),
    (
        lambda: lsfd(_frf(), poles=[-1 + 60j], band=(1, 50), driving_points={"F": "y"}),
        r"driving_points: unknown output 'y' for input 'F'; FRF outputs: x",
    ),
    (
        lambda: lsfd(_frf(), poles=[-1 + 60j, -1 + 70j, -1 + 80j], band=(0, 1)),
        r"band \(0, 1\) Hz holds 2 usable frequency lines; 3 modes",
    ),
    (lambda: extract_modes(_frf(), band=(1, 50), method="polymax"), r"method must be 'plscf' .* got 'polymax'"),
    (
        lambda: extract_modes(_frf(), band=(1, 50), selection="manual"),
        r"selection must be 'auto' or a list .* got 'manual'",
    ),
]


@pytest.mark.parametrize(("call", "match"), ERRORS)
def test_errors(call, match):
    with pytest.raises(DataError, match=match):
        call()


def test_synthesize_rejects_bad_frequencies():
    fit = extract_modes(three_dof_frf(), band=(2.0, 190.0), max_order=20).fit
    with pytest.raises(DataError, match=r"synthesis frequencies must be a 1-D array of finite values > 0 Hz"):
        fit.synthesize([0.0, 10.0])
