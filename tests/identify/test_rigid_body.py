"""Rigid-body motion from accelerometers, model-based motion and confidence (thesis 4.6).

References used: closed-form rigid-body kinematics written out here with ``np.cross`` (independent of the
module's row formula), the sympy point Jacobian of :mod:`cappe.model.geometry`, the least-squares covariance
``(A^T W A)^-1`` for seeded noise, scipy's Butterworth response and ``cont2discrete``/``dlsim`` for the model
simulation.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal as sig
import sympy as sp
from scipy.integrate import cumulative_trapezoid

from cappe.exceptions import DataError, DataWarning, IllConditionedWarning
from cappe.identify._rigid_body import (
    NINE_ACCELEROMETER_LABELS,
    RIGID_BODY_DOFS,
    RigidBodyMotion,
    accelerometer_matrix,
    body_geometry,
    integrate_acceleration,
    model_rigid_body_motion,
    motion_confidence,
    nine_accelerometer_layout,
    reconstruct_rigid_body_motion,
    solve_nine_accelerometers,
)
from cappe.io.timedata import TimeData
from cappe.model import NumericModel
from cappe.model.geometry import point_jacobian


def _readings(points, directions, reference, acc, omega=None):
    """Accelerometer readings d . (a0 + alpha x rho [+ w x (w x rho)]) for body accelerations acc (n_t, 6)."""
    rho = np.asarray(points) - np.asarray(reference)
    a0, alpha = acc[:, None, :3], acc[:, None, 3:]
    point_acc = a0 + np.cross(alpha, rho[None])
    if omega is not None:
        w = omega[:, None, :]
        point_acc = point_acc + np.cross(w, np.cross(w, rho[None]))
    return np.einsum("tkj,kj->kt", point_acc, np.asarray(directions))


# -- kinematics ---------------------------------------------------------------------------------------------------
def test_accelerometer_matrix_matches_cross_product_and_point_jacobian():
    rng = np.random.default_rng(1)
    points = rng.uniform(-0.3, 0.3, (7, 3))
    directions = rng.normal(size=(7, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    reference = np.array([0.05, -0.02, 0.1])
    q = rng.normal(size=(1, 6))
    rows = accelerometer_matrix(points, 2.5 * directions, reference)  # directions are normalized
    # closed form d . (a0 + alpha x (r - r0)); round-off level agreement (1e-12 absolute, values are O(1))
    np.testing.assert_allclose(rows @ q[0], _readings(points, directions, reference, q)[:, 0], atol=1e-12)
    # the model's symbolic point Jacobian [I, -[r]x] maps q to the point motion: same rows
    for k in range(7):
        jac = np.array(point_jacobian([sp.Float(v) for v in points[k] - reference]), dtype=float)
        np.testing.assert_allclose(rows[k], directions[k] @ jac, atol=1e-12)


def test_nine_accelerometer_layout_is_the_3_2_2_2_arrangement():
    lay = nine_accelerometer_layout(rx=0.1, ry=0.2, rz=-0.3, origin=(1.0, 2.0, 3.0))
    assert lay.labels == NINE_ACCELEROMETER_LABELS
    where = {lab: (p - lay.reference).round(12).tolist() for lab, p in zip(lay.labels, lay.points, strict=True)}
    axis = {lab: "xyz"[int(np.argmax(d))] for lab, d in zip(lay.labels, lay.directions, strict=True)}
    # thesis Fig. 4.7: triax at the origin, pairs perpendicular to their arms
    assert where["a_x"] == where["a_y"] == where["a_z"] == [0.0, 0.0, 0.0]
    assert where["a_x1"] == where["a_z1"] == [0.0, 0.2, 0.0]
    assert where["a_y2"] == where["a_z2"] == [0.1, 0.0, 0.0]
    assert where["a_x3"] == where["a_y3"] == [0.0, 0.0, -0.3]
    assert [axis[lab] for lab in NINE_ACCELEROMETER_LABELS] == ["x", "y", "z", "x", "z", "y", "z", "x", "y"]
    assert lay.to_dict()["labels"] == list(NINE_ACCELEROMETER_LABELS)


def test_nine_accelerometer_solution_is_exact_with_centripetal_terms():
    rng = np.random.default_rng(2)
    rx, ry, rz = 0.12, 0.08, 0.15
    lay = nine_accelerometer_layout(rx=rx, ry=ry, rz=rz, origin=(0.3, -0.1, 0.2))
    acc = rng.normal(size=(50, 6))
    omega = rng.normal(scale=3.0, size=(50, 3))  # finite angular velocity, rad/s
    readings = _readings(lay.points, lay.directions, lay.reference, acc, omega).T
    # Padgaonkar's averaging cancels w x (w x r) exactly: round-off agreement (values O(1), 1e-12 absolute)
    np.testing.assert_allclose(solve_nine_accelerometers(readings, rx=rx, ry=ry, rz=rz), acc, atol=1e-12)
    # the linearized least-squares fit of the same readings is biased by the centripetal terms (not exact)
    data = TimeData.from_rate(100.0, dict(zip(lay.labels, readings.T, strict=True)))
    motion = reconstruct_rigid_body_motion(data, sensors={"b": lay.sensors()}, reference={"b": lay.reference})
    assert np.abs(motion.get("b", "acceleration") - acc).max() > 1e-2


# -- drift-suppressed integration ---------------------------------------------------------------------------------
def test_integration_suppresses_offset_and_drift_and_keeps_the_passband():
    fs, f_min, amp = 1000.0, 2.0, 1e-3
    t = np.arange(4000) / fs
    w0 = 2 * np.pi * 23.7
    d_true = amp * np.sin(w0 * t + 0.3)
    v_true = amp * w0 * np.cos(w0 * t + 0.3)
    inner = (t > 2 / f_min) & (t < t[-1] - 2 / f_min)
    # a small offset (0.2 % of the peak acceleration) and a linear drift
    acc = -(w0**2) * d_true + 0.05 + 0.02 * t
    naive = cumulative_trapezoid(cumulative_trapezoid(acc, dx=1 / fs, initial=0), dx=1 / fs, initial=0)
    assert np.abs(naive).max() > 100 * amp  # what drift does to plain double integration
    vel, disp = integrate_acceleration(acc, fs=fs, f_min=f_min)
    assert np.abs(disp).max() < 1.3 * amp  # bounded over the whole record, edges included
    # interior error measured 1.5e-4 of the amplitude (high-pass roll-off at 11.9 f_min plus edge tails): 1e-3
    np.testing.assert_allclose(disp[inner], d_true[inner], rtol=0, atol=1e-3 * amp)
    np.testing.assert_allclose(vel[inner], v_true[inner], rtol=0, atol=1e-3 * amp * w0)
    # a slow thermal-like wave at f_min / 5, 4.7 times the signal at displacement level, is removed to within
    # 1 % of the signal amplitude in the interior (measured 0.77 %) and stays bounded at the edges (measured 2.0)
    wave = 0.03 * np.sin(2 * np.pi * 0.4 * t)
    assert 0.03 / (2 * np.pi * 0.4) ** 2 > 4.5 * amp
    _, disp = integrate_acceleration(acc + wave, fs=fs, f_min=f_min)
    assert np.abs(disp).max() < 2.5 * amp
    np.testing.assert_allclose(disp[inner], d_true[inner], rtol=0, atol=1e-2 * amp)


def test_integration_pass_band_is_the_zero_phase_butterworth_response():
    fs, f_min, order = 500.0, 4.0, 4
    t = np.arange(5000) / fs
    for f0 in (1.5 * f_min, 3.0 * f_min, 40.0):
        w0 = 2 * np.pi * f0
        acc = -(w0**2) * np.sin(w0 * t)
        _, disp = integrate_acceleration(acc, fs=fs, f_min=f_min, f_max=60.0, filter_order=order)
        inner = (t > 2 / f_min) & (t < t[-1] - 2 / f_min)
        basis = np.column_stack([np.sin(w0 * t[inner]), np.cos(w0 * t[inner])])
        coef, *_ = np.linalg.lstsq(basis, disp[inner], rcond=None)
        # documented gain: squared magnitudes of analog Butterworth high- and low-pass filters (scipy)
        w = [2 * np.pi * f0]
        _, h_hp = sig.freqs(*sig.butter(order, 2 * np.pi * f_min, "highpass", analog=True), worN=w)
        _, h_lp = sig.freqs(*sig.butter(order, 2 * np.pi * 60.0, analog=True), worN=w)
        gain = abs(h_hp[0]) ** 2 * abs(h_lp[0]) ** 2
        # interior amplitude measured within 3e-6 of the gain (edge tails); 1e-4 leaves margin
        assert np.hypot(*coef) == pytest.approx(gain, rel=1e-4)
        assert abs(coef[1]) < 1e-4 * abs(coef[0])  # zero phase


def test_integration_argument_errors():
    acc = np.zeros(100)
    with pytest.raises(DataError, match="'f_min' must be below the Nyquist frequency 50 Hz; got 60"):
        integrate_acceleration(acc, fs=100.0, f_min=60.0)
    with pytest.raises(DataError, match=r"'f_max' must satisfy f_min \(5 Hz\) < f_max"):
        integrate_acceleration(acc, fs=100.0, f_min=5.0, f_max=4.0)
    with pytest.raises(DataError, match="'f_min' must be > 0 Hz; got -1"):
        integrate_acceleration(acc, fs=100.0, f_min=-1.0)
    with pytest.raises(DataError, match="'filter_order' must be an integer from 1 to 16; got 2.5"):
        integrate_acceleration(acc, fs=100.0, f_min=5.0, filter_order=2.5)  # type: ignore[arg-type]
    with pytest.raises(DataError, match="at least 8 samples along the time axis; got 4"):
        integrate_acceleration(np.zeros(4), fs=100.0, f_min=5.0)
    with pytest.raises(DataError, match="acceleration contains NaN or Inf"):
        integrate_acceleration(np.full(10, np.nan), fs=100.0, f_min=5.0)
    with pytest.warns(DataWarning, match="shorter than 2 / f_min"):
        integrate_acceleration(acc, fs=100.0, f_min=1.0)


# -- signal-based motion from explicit sensors --------------------------------------------------------------------
def _analytic_motion(t):
    """Sinusoidal translations (m) and rotations (rad) with distinct frequencies, and their derivatives."""
    freq = np.array([17.0, 23.0, 31.0, 41.0, 53.0, 61.0])
    amp = np.array([1e-4, 2e-4, 1.5e-4, 1e-3, 2e-3, 1.5e-3])
    phase = np.linspace(0.1, 1.1, 6)
    w = 2 * np.pi * freq
    arg = w[None, :] * t[:, None] + phase
    return amp * np.sin(arg), amp * w * np.cos(arg), -amp * w**2 * np.sin(arg)


def test_nine_accelerometers_recover_analytic_motion_exactly():
    fs = 1000.0
    t = np.arange(3000) / fs
    disp, vel, acc = _analytic_motion(t)
    lay = nine_accelerometer_layout(rx=0.1, ry=0.15, rz=0.2, origin=(0.02, 0.03, -0.01))
    readings = _readings(lay.points, lay.directions, lay.reference, acc)
    data = TimeData.from_channels(t, dict(zip(lay.labels, readings, strict=True)))
    scale = np.abs(acc).max(axis=0)
    # closed form and least squares: noise-free data, round-off only (1e-10 of each DOF's peak)
    closed = solve_nine_accelerometers(readings.T, rx=0.1, ry=0.15, rz=0.2)
    np.testing.assert_allclose(closed / scale, acc / scale, atol=1e-10)
    motion = reconstruct_rigid_body_motion(
        data, sensors={"plate": lay.sensors()}, reference={"plate": lay.reference}, f_min=5.0
    )
    np.testing.assert_allclose(motion.get("plate", "acceleration") / scale, acc / scale, atol=1e-10)
    assert motion.redundancy.tolist() == [3]
    assert np.nanmax(motion.residual_ratio) < 1e-10  # a rigid motion leaves no residual
    assert motion.condition[0] < 10
    inner = (t > 0.4) & (t < t[-1] - 0.4)  # 2 / f_min from the ends
    amp = np.abs(disp).max(axis=0)
    # lowest component at 3.4 f_min loses 2.4e-4 to the high-pass; interior edge tails add ~1e-4: 1e-3
    np.testing.assert_allclose(motion.get("plate")[inner] / amp, disp[inner] / amp, atol=1e-3)
    np.testing.assert_allclose(
        motion.get("plate", "velocity")[inner] / np.abs(vel).max(axis=0),
        vel[inner] / np.abs(vel).max(axis=0),
        atol=1e-3,
    )
    # point motion u + theta x (r - r0) of a sensor point equals the closed form
    pm = motion.point_motion("plate", lay.points[:1], "acceleration")[:, 0]
    expected = acc[:, :3] + np.cross(acc[:, 3:], lay.points[0] - lay.reference)
    np.testing.assert_allclose(pm, expected, atol=1e-10 * np.abs(expected).max())
    assert motion.to_dict()["bodies"]["plate"]["redundancy"] == 3


def test_weighted_least_squares_with_redundant_noisy_sensors_matches_its_covariance():
    rng = np.random.default_rng(7)
    n_s, n_t = 16, 4000
    points = rng.uniform(-0.2, 0.2, (n_s, 3))
    directions = rng.normal(size=(n_s, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    sigma = rng.uniform(0.01, 0.1, n_s)  # channel noise, m/s^2
    acc = rng.normal(size=(n_t, 6))
    clean = _readings(points, directions, np.zeros(3), acc)
    noisy = clean + sigma[:, None] * rng.normal(size=(n_s, n_t))
    names = [f"s{k}" for k in range(n_s)]
    data = TimeData.from_rate(1000.0, dict(zip(names, noisy, strict=True)))
    sensors = {"frame": {c: (p, d) for c, p, d in zip(names, points, directions, strict=True)}}
    weights = {c: 1 / s**2 for c, s in zip(names, sigma, strict=True)}
    motion = reconstruct_rigid_body_motion(data, sensors=sensors, weights=weights, f_min=5.0)
    err = motion.get("frame", "acceleration") - acc
    a = np.hstack([directions, np.cross(points, directions)])
    cov = np.linalg.inv(a.T @ (a / sigma[:, None] ** 2))
    z = np.linalg.solve(np.linalg.cholesky(cov), err.T)  # whitened errors: standard normal if the fit is GLS
    # mean of 24000 chi-square(1) draws: std 0.009, so +-0.05 is > 5 sigma
    assert np.mean(z**2) == pytest.approx(1.0, abs=0.05)
    # weighted residual sum of squares per sample has expectation n_s - 6 (std of the mean 0.07)
    wrss = np.mean(np.sum(motion.residual**2 / sigma[:, None] ** 2, axis=0))
    assert wrss == pytest.approx(n_s - 6, abs=0.5)
    # ordinary (unweighted) LS has the larger, sandwich covariance: its errors are worse on average
    plain = reconstruct_rigid_body_motion(data, sensors=sensors, f_min=5.0)
    assert np.mean((plain.get("frame", "acceleration") - acc) ** 2) > np.mean(err**2)


def test_residual_points_at_a_non_rigid_channel():
    rng = np.random.default_rng(3)
    t = np.arange(2000) / 1000.0
    _, _, acc = _analytic_motion(t)
    points = rng.uniform(-0.2, 0.2, (10, 3))
    directions = np.eye(3)[np.arange(10) % 3]
    readings = _readings(points, directions, np.zeros(3), acc)
    flexible = 0.3 * np.abs(readings[4]).max() * np.sin(2 * np.pi * 120 * t)  # local, non-rigid motion
    readings[4] += flexible
    names = [f"a{k}" for k in range(10)]
    data = TimeData.from_channels(t, dict(zip(names, readings, strict=True)))
    motion = reconstruct_rigid_body_motion(
        data, sensors={"b": {c: (p, d) for c, p, d in zip(names, points, directions, strict=True)}}
    )
    # closed form: the residual is (I - H) applied to the non-rigid part, H = A A^+ the hat matrix
    a = np.hstack([directions, np.cross(points, directions)])
    expected = (np.eye(10) - a @ np.linalg.pinv(a))[:, 4:5] * flexible[None, :]
    np.testing.assert_allclose(motion.residual, expected, atol=1e-10 * np.abs(flexible).max())
    assert motion.residual_ratio[4] > 0.05
    assert motion.to_dict()["channels"]["a4"]["body"] == "b"


def test_rank_deficient_sensor_sets_name_body_and_missing_motion():
    t = np.arange(1000) / 1000.0
    sig_ = np.sin(2 * np.pi * 50 * t)
    on_axis = {
        f"p{k}{d}": ((0.0, 0.0, z), np.eye(3)["xyz".index(d)]) for k, z in enumerate((-0.1, 0.0, 0.1)) for d in "xyz"
    }
    data = TimeData.from_channels(t, dict.fromkeys(on_axis, sig_))
    # points on the z axis cannot see a rotation about z
    with pytest.raises(
        DataError,
        match=r"body 'shaft': the 9 weighted sensor channel\(s\) determine only 5 of its 6 "
        r"motions \(x, y, z, rx, ry, rz\); not determined: rz",
    ):
        reconstruct_rigid_body_motion(data, sensors={"shaft": on_axis})
    # ... unless rz is not estimated
    motion = reconstruct_rigid_body_motion(
        data, sensors={"shaft": on_axis}, dofs={"shaft": ["x", "y", "z", "rx", "ry"]}
    )
    assert motion.active.tolist() == [[True] * 5 + [False]]
    assert np.all(motion.get("shaft", "acceleration")[:, 5] == 0)
    # one triaxial point: the three rotations about it are missing (combinations with translations)
    one = {k: v for k, v in on_axis.items() if k.startswith("p2")}
    # (a rotation about the point: translation of the origin by -theta x p, p = (0, 0, 0.1))
    with pytest.raises(
        DataError,
        match=r"determine only 3 of its 6 motions .*; not determined: x - 10\*ry; "
        r"y \+ 10\*rx; rz\.",
    ):
        reconstruct_rigid_body_motion(data, sensors={"shaft": one})
    # zero weights take channels out of the fit
    with pytest.raises(DataError, match=r"the 3 weighted sensor channel\(s\) determine only 3"):
        reconstruct_rigid_body_motion(
            data, sensors={"shaft": on_axis}, weights={k: 0.0 for k in on_axis if not k.startswith("p2")}
        )


def test_nearly_degenerate_layout_warns():
    t = np.arange(1000) / 1000.0
    on_axis = {
        f"p{k}{d}": ((1e-8 * (k == 0), 0.0, z), np.eye(3)["xyz".index(d)])
        for k, z in enumerate((-0.1, 0.0, 0.1))
        for d in "xyz"
    }
    data = TimeData.from_channels(t, dict.fromkeys(on_axis, np.sin(2 * np.pi * 50 * t)))
    with pytest.warns(IllConditionedWarning, match="body 'shaft': sensor matrix condition number"):
        reconstruct_rigid_body_motion(data, sensors={"shaft": on_axis})


def test_reconstruction_argument_errors():
    t = np.arange(200) / 1000.0
    data = TimeData.from_channels(t, {"a": np.sin(t), "b": np.cos(t)})
    good = {"a": ((0, 0, 0), (1, 0, 0))}
    with pytest.raises(DataError, match="give exactly one of 'sensors'"):
        reconstruct_rigid_body_motion(data)
    with pytest.raises(DataError, match="unknown channel 'c'"):
        reconstruct_rigid_body_motion(data, sensors={"b1": {"c": ((0, 0, 0), (1, 0, 0))}})
    with pytest.raises(DataError, match="channel 'a' is listed for two bodies"):
        reconstruct_rigid_body_motion(data, sensors={"b1": good, "b2": good})
    with pytest.raises(DataError, match=r"direction of 'a' must be a non-zero 3-vector"):
        reconstruct_rigid_body_motion(data, sensors={"b1": {"a": ((0, 0, 0), (0, 0, 0))}})
    with pytest.raises(DataError, match=r"sensors\['b1'\]\['a'\] point must be a finite 3-vector"):
        reconstruct_rigid_body_motion(data, sensors={"b1": {"a": ((0, 0), (1, 0, 0))}})
    with pytest.raises(DataError, match=r"dofs\['b1'\] must list names from x, y, z"):
        reconstruct_rigid_body_motion(data, sensors={"b1": good}, dofs={"b1": ["q"]})
    with pytest.raises(DataError, match="reference: unknown body 'b9'"):
        reconstruct_rigid_body_motion(data, sensors={"b1": good}, reference={"b9": (0, 0, 0)})
    with pytest.raises(DataError, match="unknown body 'b9'"):
        reconstruct_rigid_body_motion(data, sensors={"b1": good}, bodies=["b9"])
    with pytest.raises(DataError, match="weights: channel 'b' is not a sensor channel of the fit"):
        reconstruct_rigid_body_motion(data, sensors={"b1": good}, weights={"b": 1.0}, dofs={"b1": ["x"]})
    with pytest.raises(DataError, match="weights: weight of channel 'a' must be a finite number >= 0; got -1"):
        reconstruct_rigid_body_motion(data, sensors={"b1": good}, weights={"a": -1.0}, dofs={"b1": ["x"]})
    with pytest.raises(DataError, match="'labels' applies to model sensor nodes"):
        reconstruct_rigid_body_motion(data, sensors={"b1": good}, labels={"a": "n:x"})
    with pytest.raises(DataError, match=r"argument 'points' must have shape \(n, 3\)"):
        accelerometer_matrix([[0.0, 1.0]], [[1.0, 0.0]])
    with pytest.raises(DataError, match=r"accelerations must have shape \(\.\.\., 9\)"):
        solve_nine_accelerometers(np.zeros(8), rx=1, ry=1, rz=1)
    with pytest.raises(DataError, match="arm length 'ry' must be a non-zero finite number in m; got 0"):
        nine_accelerometer_layout(rx=0.1, ry=0.0, rz=0.1)


# -- model-based motion and confidence ----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def spindle_nm(spindle):
    return NumericModel(spindle)


@pytest.fixture(scope="module")
def spindle_test(spindle_nm):
    """Random forces on the spindle nose and the sensor accelerations they cause (nominal model)."""
    fs, n_t = 5000.0, 2000
    rng = np.random.default_rng(11)
    forces = {"Fx": rng.normal(scale=50.0, size=n_t), "Fy": rng.normal(scale=50.0, size=n_t)}
    data = TimeData.from_rate(fs, forces)
    truth = model_rigid_body_motion(spindle_nm, data, inputs={"Fx": "Fx", "Fy": "Fy"})
    geo = body_geometry(spindle_nm)
    channels = dict(forces)
    structure = spindle_nm.structure
    for s in structure.sensors:
        body_acc = truth.get(s.body, "acceleration")
        point = geo[s.body].points[geo[s.body].labels.index(f"sensor:{s.name}")]
        rho = point - geo[s.body].reference
        point_acc = body_acc[:, :3] + np.cross(body_acc[:, 3:], rho)
        for a, axis in enumerate("xyz"):
            channels[f"{s.name}:{axis}"] = point_acc[:, a]
    return TimeData.from_rate(fs, channels), truth


def test_model_motion_matches_an_independent_simulation(spindle_nm, spindle_test):
    data, truth = spindle_test
    system = spindle_nm.system()
    n = system.n_dof
    minv = np.linalg.inv(system.M)
    a = np.block([[np.zeros((n, n)), np.eye(n)], [-minv @ system.K, -minv @ system.C]])
    cols = [spindle_nm.input_names.index(k) for k in ("Fx", "Fy")]
    b = np.vstack([np.zeros((n, 2)), minv @ system.B[:, cols]])
    c = np.vstack([np.hstack([np.eye(n), np.zeros((n, n))]), a[n:]])  # displacements and accelerations
    d = np.vstack([np.zeros((n, 2)), b[n:]])
    ad, bd, cd, dd, _ = sig.cont2discrete((a, b, c, d), data.dt, method="zoh")
    u = np.column_stack([data.channel("Fx"), data.channel("Fy")])
    _, y, _ = sig.dlsim((ad, bd, cd, dd, data.dt), u)
    for j, label in enumerate(spindle_nm.dofs):
        body, dof = label.split(".")
        k = RIGID_BODY_DOFS.index(dof)
        # two ZOH discretizations of the same system: agreement to round-off of the matrix exponential (1e-9)
        for got, ref in ((truth.get(body)[:, k], y[:, j]), (truth.get(body, "acceleration")[:, k], y[:, n + j])):
            np.testing.assert_allclose(got, ref, rtol=0, atol=1e-9 * np.abs(ref).max())
    assert truth.active[truth.index("spindle")].tolist() == [True] * 5 + [False]
    assert np.all(truth.get("spindle")[:, 5] == 0)


def test_signal_and_model_motion_agree_for_the_true_model(spindle_nm, spindle_test):
    data, truth = spindle_test
    # the model's own sensor rows give the same channels as the closed-form point kinematics used to make them
    labels, rows = spindle_nm.sensor_matrix()
    qdd = np.hstack([truth.get(b, "acceleration")[:, truth.active[truth.index(b)]] for b in ("spindle", "housing")])
    for lab, row in zip(labels, rows, strict=True):
        np.testing.assert_allclose(row @ qdd.T, data.channel(lab), atol=1e-10 * np.abs(data.channel(lab)).max())
    motion = reconstruct_rigid_body_motion(data, model=spindle_nm, f_min=20.0)
    assert motion.bodies == ("spindle", "housing")
    assert motion.redundancy.tolist() == [4, 3]
    for body in motion.bodies:
        ref = truth.get(body, "acceleration")
        # noise-free, exactly rigid data: round-off (1e-9 of the peak)
        np.testing.assert_allclose(motion.get(body, "acceleration"), ref, atol=1e-9 * np.abs(ref).max())
    conf = motion_confidence(motion, truth)
    assert conf.confidence > 1 - 1e-9
    assert np.isnan(conf.ratio[0, 5])  # spindle rz is not a DOF
    # displacement: the model path integrated with the same band limits agrees as closely
    banded = model_rigid_body_motion(spindle_nm, data, inputs={"Fx": "Fx", "Fy": "Fy"}, f_min=20.0)
    assert motion_confidence(motion, banded, quantity="displacement").confidence > 1 - 1e-8
    # renamed channels through labels give the same motion
    renamed = TimeData(data.time, data.values, tuple(f"ch{k}" for k in range(data.n_channels)))
    mapping = {f"ch{k}": c for k, c in enumerate(data.channels) if ":" in c}
    again = reconstruct_rigid_body_motion(renamed, model=spindle_nm, labels=mapping, f_min=20.0, bodies=["housing"])
    np.testing.assert_allclose(again.get("housing", "acceleration"), motion.get("housing", "acceleration"), atol=0)


def test_confidence_degrades_monotonically_with_a_model_error(spindle_nm, spindle_test):
    data, _ = spindle_test
    motion = reconstruct_rigid_body_motion(data, model=spindle_nm, f_min=20.0)
    values = []
    for factor in (1.0, 1.05, 1.2, 1.6):
        params = {"kfx": 60.0e6 * factor, "krx": 60.0e6 * factor}
        sim = model_rigid_body_motion(spindle_nm, data, inputs={"Fx": "Fx", "Fy": "Fy"}, params=params)
        values.append(motion_confidence(motion, sim).confidence)
    assert values[0] > 1 - 1e-9
    assert all(b < a - 1e-3 for a, b in zip(values, values[1:], strict=False))


def test_model_geometry_and_too_few_sensors_on_the_slide(slide):
    nm = NumericModel(slide)
    geo = body_geometry(nm, position={"z": 0.25})
    assert geo["slide"].reference.tolist() == pytest.approx([0.0, 0.05, 0.25])
    tool = geo["slide"].points[geo["slide"].labels.index("sensor:tool")]
    assert tool.tolist() == pytest.approx([0.0, 0.15, 0.25])
    t = np.arange(100) / 1000.0
    data = TimeData.from_channels(t, {f"top:{a}": np.sin(50 * t + k) for k, a in enumerate("xyz")})
    # one triaxial node on the 6-DOF base cannot give its rotations
    with pytest.raises(DataError, match=r"body 'base': the 3 weighted sensor channel\(s\) determine only 3 of its 6"):
        reconstruct_rigid_body_motion(data, model=nm, position={"z": 0.25})
    with pytest.raises(DataError, match="body 'slide' has no sensor channel in the data"):
        reconstruct_rigid_body_motion(data, model=nm, bodies=["slide"])
    with pytest.raises(DataError, match="'reference' and 'dofs' apply to explicit sensors"):
        reconstruct_rigid_body_motion(data, model=nm, dofs={"base": ["x"]})
    with pytest.raises(DataError, match=r"labels: channel 'top:x' maps to 'tip:x', which is not a sensor channel"):
        reconstruct_rigid_body_motion(data, model=nm, labels={"top:x": "tip:x"})
    bad = TimeData.from_channels(t, {"top:q": np.sin(t)})
    with pytest.raises(DataError, match="channel 'top:q': sensor direction must be x, y or z"):
        reconstruct_rigid_body_motion(bad, model=nm)
    none = TimeData.from_channels(t, {"F": np.sin(t)})
    with pytest.raises(DataError, match="no data channel names a sensor of model 'slide'"):
        reconstruct_rigid_body_motion(none, model=nm)
    with pytest.raises(DataError, match="inputs: channel 'F' maps to unknown model input 'G'"):
        model_rigid_body_motion(nm, none, inputs={"F": "G"})
    with pytest.raises(DataError, match="unknown body 'table' for model 'slide'"):
        model_rigid_body_motion(nm, none, inputs={"F": "F"}, bodies=["table"])
    with pytest.raises(DataError, match="f_max needs f_min"):
        model_rigid_body_motion(nm, none, inputs={"F": "F"}, f_max=100.0)


def _motion(t, values, active=None, body="b"):
    acc = np.zeros((1, t.size, 6))
    for k, v in values.items():
        acc[0, :, RIGID_BODY_DOFS.index(k)] = v
    act = np.ones((1, 6), bool) if active is None else np.array([active])
    return RigidBodyMotion(t, (body,), acc, acc, acc, act, np.zeros((1, 3)), (np.zeros((1, 3)),), "signal")


def test_confidence_definition_weights_and_window():
    t = np.arange(1000) / 1000.0
    s = np.sin(2 * np.pi * 10 * t)
    c = np.cos(2 * np.pi * 10 * t)
    measured = _motion(t, {"x": s, "rx": 1e-3 * s})
    model = _motion(t, {"x": 0.9 * s, "rx": 1e-3 * (s + 0.5 * c)})
    conf = motion_confidence(
        measured, model, weights={"b.x": 3.0, "b.rx": 1.0, "b.y": 0.0, "b.z": 0.0, "b.ry": 0.0, "b.rz": 0.0}
    )
    # closed forms over whole periods: RMS(0.1 s)/RMS(s) = 0.1, RMS(0.5 c)/RMS(s) = 0.5
    assert conf.ratio[0, 0] == pytest.approx(0.1, rel=1e-12)
    assert conf.ratio[0, 3] == pytest.approx(0.5, rel=1e-12)
    r = np.sqrt((3 * 0.1**2 + 0.5**2) / 4)
    assert conf.residual == pytest.approx(r, rel=1e-12)
    assert conf.confidence == pytest.approx(1 - r, rel=1e-12)
    # y, z, ry, rz: zero in both and active -> ratio 0, but weight 0 leaves them out
    assert conf.to_dict()["ratio"]["b"]["x"] == pytest.approx(0.1)
    equal = motion_confidence(measured, model, weights={"b": 1.0})
    assert equal.residual == pytest.approx(np.sqrt((0.1**2 + 0.5**2) / 6), rel=1e-12)
    # a large error clips at zero confidence
    assert motion_confidence(measured, _motion(t, {"x": -3 * s})).confidence == 0.0
    # a window that holds only the second half of the record
    half = motion_confidence(measured, model, window=(0.5, 1.0))
    assert half.window == (0.5, 1.0)
    assert half.ratio[0, 0] == pytest.approx(0.1, rel=1e-12)


def test_confidence_errors():
    t = np.arange(100) / 100.0
    a = _motion(t, {"x": np.sin(t)})
    with pytest.raises(DataError, match="must share the time grid; got 100 and 50 samples"):
        motion_confidence(a, _motion(t[:50], {"x": np.sin(t[:50])}))
    with pytest.raises(DataError, match="have none in common"):
        motion_confidence(a, _motion(t, {"x": np.sin(t)}, body="c"))
    with pytest.raises(DataError, match="weights: key 'b.q' must be a compared body or 'body.dof'"):
        motion_confidence(a, a, weights={"b.q": 1.0})
    with pytest.raises(DataError, match="weights: weight 'b' must be a finite number >= 0; got -2"):
        motion_confidence(a, a, weights={"b": -2.0})
    with pytest.raises(DataError, match="quantity must be one of acceleration, velocity, displacement; got 'jerk'"):
        motion_confidence(a, a, quantity="jerk")  # type: ignore[arg-type]
    with pytest.raises(DataError, match=r"window \(5, 6\) s holds fewer than 2 samples"):
        motion_confidence(a, a, window=(5.0, 6.0))
    with pytest.raises(DataError, match="no body DOF is active in both motions"):
        motion_confidence(a, _motion(t, {}, active=[False] * 6))
    with pytest.raises(DataError, match="unknown body 'q'; the motion has"):
        a.get("q")
