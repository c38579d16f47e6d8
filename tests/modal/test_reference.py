"""Reference data simulated from a model (cappe.modal._reference): exact modes, tracking, noise, UFF, FRFs.

References: the exact complex modes of ``MechanicalSystem.modes()`` (an independent state-space eigen solve),
a fine-step continuation of the undamped modes along the axis, closed-form sensor coordinates and frequencies,
python-control's frequency response of a state-space model built here, and the sample statistics of seeded noise.
"""

from __future__ import annotations

import control
import numpy as np
import pytest
import scipy.linalg as sla
from scipy.optimize import linear_sum_assignment

from cappe.exceptions import DataError, ModelError
from cappe.io import read_frf, read_uff_modal, read_uff_nodes, write_frf, write_uff_modal
from cappe.modal._reference import axis_positions, reference_frf, reference_modes, sensor_coordinates
from cappe.model import NumericModel, StructureBuilder, load_model
from conftest import build_slide


@pytest.fixture(scope="module")
def spindle():
    return NumericModel(load_model("builtin:spindle-bearing"))


@pytest.fixture(scope="module")
def slide_model():
    return NumericModel(build_slide())


@pytest.fixture(scope="module")
def rig():
    return NumericModel(load_model("builtin:two-mass-rig"))


def crossing_model():
    """Two weakly coupled oscillators; the stiffness of 'a' grows with z so that the two modes cross in order.

    Uncoupled: f_a = sqrt(k (1 + 3 z) / m) / 2 pi, f_b = sqrt(2 k / m) / 2 pi, so mode a is the lower one at z = 0
    and the higher one at z = 1 (they cross at z = 1/3).
    """
    b = StructureBuilder("crossing")
    b.parameter("m", 1.0, unit="kg", kind="mass")
    b.parameter("k", 1.0e6, unit="N/m", kind="stiffness")
    b.parameter("c", 20.0, unit="N s/m", kind="damping")
    b.axis("z", [0.0, 1.0])
    b.body("a", mass="m", dofs=["x"])
    b.body("b", mass="m", dofs=["x"], position=[0, 1, 0])
    b.element("ka", bodies=("ground", "a"), stiffness={"x": "k*(1 + 3*z)"}, damping={"x": "c"})
    b.element("kb", bodies=("ground", "b"), at=[0, 1, 0], stiffness={"x": "2*k"}, damping={"x": "c"})
    b.element("kab", bodies=("a", "b"), points=[[0, 0, 0], [0, 0, 0]], stiffness={"x": "0.01*k"})
    b.sensor("pa", body="a")
    b.sensor("pb", body="b")
    b.input("F", body="a", direction="x")
    b.output("d", body="a", direction="x")
    return NumericModel(b.build())


def mac(a, b):
    """Complex MAC of two vectors."""
    return abs(np.vdot(a, b)) ** 2 / (np.vdot(a, a).real * np.vdot(b, b).real)


def assert_matches_system_modes(model, data_set, params, position):
    """Frequencies, damping ratios and sensor shapes equal the exact modes of MechanicalSystem.modes()."""
    modes = model.system(params, position).modes()  # independent: eig of the full state matrix
    _, rows = model.sensor_matrix(params, position)
    # pair by frequency: exact poles of distinct modes differ by far more than the 1e-9 tolerance below
    pairs = [int(np.argmin(abs(modes.frequency - f))) for f in data_set.frequency]
    assert len(set(pairs)) == len(pairs)
    # both sides solve the same state-space eigenproblem with LAPACK: agreement to rounding (1e-9 relative)
    np.testing.assert_allclose(data_set.frequency, modes.frequency[pairs], rtol=1e-9)
    np.testing.assert_allclose(data_set.damping, modes.damping[pairs], rtol=1e-7, atol=1e-12)
    for r, j in enumerate(pairs):
        assert mac(data_set.shapes[:, r], rows @ modes.shapes[:, j]) == pytest.approx(1.0, abs=1e-9)


# ---------------------------------------------------------------------------------------------- exact modes


def test_noise_free_reference_equals_the_exact_modes_of_the_spindle(spindle):
    params = {"Omega": 200.0, "kfx": 1.1 * spindle.structure.nominal["kfx"], "chx": 2500.0}  # gyroscopic, changed
    ref = reference_modes(spindle, params=params)
    assert ref.sensors == tuple(f"{s.name}:{d}" for s in spindle.structure.sensors for d in "xyz")
    assert len(ref.sets) == 1
    assert ref.sets[0].n_modes == spindle.n_dof  # 11 oscillatory modes, no rigid-body mode
    assert_matches_system_modes(spindle, ref.sets[0], params, None)
    assert ref.source == "spindle-bearing"


def test_noise_free_reference_equals_the_exact_modes_of_the_slide_at_every_position(slide_model):
    params = {"kg0": 2.5e7, "cm": 1500.0, "eta": 0.05}
    ref = reference_modes(slide_model, params=params, positions="all", n_modes=8)
    assert [s.position for s in ref.sets] == [{"z": 0.1}, {"z": 0.25}, {"z": 0.4}]
    for data_set in ref.sets:
        assert data_set.n_modes == 8
        assert_matches_system_modes(slide_model, data_set, params, data_set.position)


def test_positions_argument_forms(slide_model):
    default = reference_modes(slide_model, n_modes=2)
    assert [s.position for s in default.sets] == [{"z": 0.1}]
    one = reference_modes(slide_model, n_modes=2, positions={"z": 0.3})
    assert [s.position for s in one.sets] == [{"z": 0.3}]
    assert axis_positions(slide_model) == [{"z": 0.1}, {"z": 0.25}, {"z": 0.4}]


def test_tracking_follows_the_same_physical_mode_through_a_crossing():
    model = crossing_model()
    ref = reference_modes(model, positions="all")
    low, high = ref.sets
    k, m = 1.0e6, 1.0
    # column 0 is mode a (the lower at z = 0, the higher at z = 1); the weak coupling (1 % of k) shifts the
    # uncoupled frequencies by about 0.5 %, damping (zeta ~ 1e-3) far less: 1 % tolerance
    np.testing.assert_allclose(low.frequency, np.sqrt([k / m, 2 * k / m]) / (2 * np.pi), rtol=0.01)
    np.testing.assert_allclose(high.frequency, np.sqrt([4 * k / m, 2 * k / m]) / (2 * np.pi), rtol=0.01)
    for s in ref.sets:  # mode a moves sensor pa (channel 0), mode b sensor pb (channel 3)
        assert abs(s.shapes[0, 0]) > 10 * abs(s.shapes[3, 0])
        assert abs(s.shapes[3, 1]) > 10 * abs(s.shapes[0, 1])
    # the lowest mode at the first position, followed to the second (where it is not the lowest)
    first = reference_modes(model, positions="all", n_modes=1)
    np.testing.assert_allclose(first.sets[1].frequency, high.frequency[:1], rtol=1e-12)


def test_tracking_agrees_with_a_fine_continuation_along_the_axis(slide_model):
    ref = reference_modes(slide_model, positions="all")
    # independent pairing: undamped modes followed in 300 steps of 1 mm, matched by mass-weighted MAC at each step
    order = np.arange(slide_model.n_dof)
    previous = None
    follow = {}
    for z in np.round(np.linspace(0.1, 0.4, 301), 6):
        system = slide_model.system(None, {"z": z})
        _, phi = sla.eigh(system.K, system.M)
        if previous is not None:
            overlap = (previous.T @ system.M @ phi) ** 2
            _, order = linear_sum_assignment(overlap, maximize=True)
            phi = phi[:, order]
        previous = phi
        if z in (0.1, 0.25, 0.4):
            follow[z] = phi
    for s in ref.sets:
        _, rows = slide_model.sensor_matrix(None, s.position)
        tracked = rows @ follow[s.position["z"]]
        macs = np.array([[mac(s.shapes[:, r], tracked[:, j]) for j in range(tracked.shape[1])]
                         for r in range(s.n_modes)])
        # each reference column is the continued mode of the same index (MAC near 1 there, clearly best)
        np.testing.assert_array_equal(np.argmax(macs, axis=1), np.arange(s.n_modes))


# ---------------------------------------------------------------------------------------------------- noise


def test_noise_statistics_match_the_settings(slide_model):
    clean = reference_modes(slide_model, positions="all")
    levels = {"noise_frequency": 0.01, "noise_damping": 0.08, "noise_shape": 0.03}
    rel_f, rel_d, rel_s = [], [], []
    for seed in range(40):
        noisy = reference_modes(slide_model, positions="all", rng=seed, **levels)
        for c, n in zip(clean.sets, noisy.sets, strict=True):
            rel_f.append(n.frequency / c.frequency - 1)
            rel_d.append(n.damping / c.damping - 1)
            rel_s.append(((n.shapes - c.shapes) / abs(c.shapes).max(axis=0)).ravel())
    rel_f, rel_d, rel_s = np.concatenate(rel_f), np.concatenate(rel_d), np.concatenate(rel_s)
    assert rel_f.size == rel_d.size == 40 * 3 * 12  # 1440 draws each; 8640 shape components
    # the standard error of a sample std is std / sqrt(2 N) (2 % for N = 1440): 10 % is five standard errors
    assert np.std(rel_f) == pytest.approx(0.01, rel=0.10)
    assert np.std(rel_d) == pytest.approx(0.08, rel=0.10)
    # shapes: RMS modulus of the complex noise, split evenly between real and imaginary parts (N = 8640)
    assert np.sqrt(np.mean(abs(rel_s) ** 2)) == pytest.approx(0.03, rel=0.05)
    assert np.std(rel_s.real) == pytest.approx(0.03 / np.sqrt(2), rel=0.05)
    assert np.std(rel_s.imag) == pytest.approx(0.03 / np.sqrt(2), rel=0.05)
    # unbiased: means within 5 standard errors of 0
    assert abs(np.mean(rel_f)) < 5 * 0.01 / np.sqrt(rel_f.size)
    assert abs(np.mean(rel_d)) < 5 * 0.08 / np.sqrt(rel_d.size)
    # independent streams: the frequency and damping noise are uncorrelated (|r| < 5 / sqrt(N))
    assert abs(np.corrcoef(rel_f, rel_d)[0, 1]) < 5 / np.sqrt(rel_f.size)


def test_same_seed_same_data_and_streams_are_independent(rig):
    kwargs = {"noise_frequency": 0.005, "noise_damping": 0.05, "noise_shape": 0.02}
    a = reference_modes(rig, rng=7, **kwargs)
    b = reference_modes(rig, rng=7, **kwargs)
    c = reference_modes(rig, rng=8, **kwargs)
    assert a.to_dict() == b.to_dict()
    assert not np.array_equal(a.sets[0].frequency, c.sets[0].frequency)
    # changing one level leaves the other quantities' noise as it was
    d = reference_modes(rig, rng=7, noise_frequency=0.005, noise_damping=0.0, noise_shape=0.02)
    np.testing.assert_array_equal(d.sets[0].frequency, a.sets[0].frequency)
    np.testing.assert_array_equal(d.sets[0].shapes, a.sets[0].shapes)
    assert not np.array_equal(d.sets[0].damping, a.sets[0].damping)
    # a generator works as well as a seed
    e = reference_modes(rig, rng=np.random.default_rng(7), **kwargs)
    assert e.to_dict() == a.to_dict()


def test_large_damping_noise_keeps_ratios_in_range(slide_model):
    # at these levels about 10 % (damping) and 2 % (frequency) of the first draws are inadmissible and redrawn
    noisy = reference_modes(slide_model, positions="all", noise_damping=0.8, noise_frequency=0.5, rng=3)
    for s in noisy.sets:
        assert np.all(s.damping > 0)
        assert np.all(s.damping < 1)
        assert np.all(s.frequency > 0)


# --------------------------------------------------------------------------------------------- files


def test_sensor_coordinates_closed_form(slide_model):
    # tool: slide origin (0, 0.05, z) + (0, 0.1, 0); top: base origin (0, 0, 0) + (0.2, 0.2, 0.1)
    coords = sensor_coordinates(slide_model, position={"z": 0.25})
    np.testing.assert_allclose(coords["tool"], (0.0, 0.15, 0.25), atol=1e-15)
    np.testing.assert_allclose(coords["top"], (0.2, 0.2, 0.1), atol=1e-15)


def test_uff55_round_trip_of_a_multi_position_reference(tmp_path, slide_model):
    ref = reference_modes(slide_model, positions="all", n_modes=6, noise_frequency=0.005, noise_damping=0.05,
                          noise_shape=0.02, rng=1)
    coords = sensor_coordinates(slide_model, position=ref.sets[0].position)
    path = write_uff_modal(tmp_path / "modes.uff", ref, coordinates=coords)
    back = read_uff_modal(path)
    assert back.sensors == ref.sensors
    assert [s.position for s in back.sets] == [s.position for s in ref.sets]
    for b, r in zip(back.sets, ref.sets, strict=True):
        # frequency and damping come back exactly (cappe's ID line 5); shapes keep UFF 55's 6 digits (E13.5)
        np.testing.assert_array_equal(b.frequency, r.frequency)
        np.testing.assert_array_equal(b.damping, r.damping)
        np.testing.assert_allclose(b.shapes, r.shapes, rtol=0, atol=1e-5 * abs(r.shapes).max())
    assert read_uff_nodes(path) == coords  # UFF 2411 holds double precision: exact


def test_frf_equals_the_system_frf_and_python_control(spindle):
    freq = np.linspace(0.0, 1500.0, 301)
    frf = reference_frf(spindle, freq=freq, inputs=["Fx", "nose:x", "nose:y"], outputs=["sx", "hax", "nose", "hx"])
    assert frf.input_names == ("Fx", "nose:x", "nose:y")
    assert frf.output_names == ("sx", "hax", "nose:x", "nose:y", "nose:z", "hx")
    assert frf.output_quantities == ("displacement", "acceleration", "displacement", "displacement", "displacement",
                                     "displacement")
    system = spindle.system()
    direct = system.frf(freq, ["Fx"], ["sx", "hax", "hx"])
    # the same dynamic-stiffness solve for the model outputs: rounding-level agreement
    np.testing.assert_allclose(frf.H[[0, 1, 5], 0], direct.H[:, 0], rtol=1e-10, atol=0)
    # Fx acts at the nose in x: a unit force at sensor channel nose:x is the same driving point
    np.testing.assert_allclose(frf.H[:, 1], frf.H[:, 0], rtol=1e-10, atol=0)
    # Maxwell reciprocity (no gyroscopic terms at Omega = 0): H[nose:x, nose:y] = H[nose:y, nose:x]
    np.testing.assert_allclose(frf.H[2, 2], frf.H[3, 1], rtol=1e-9, atol=0)

    # independent: python-control's frequency response of the first-order state-space form (no hysteretic terms)
    assert not np.any(system.H)
    n = system.n_dof
    labels, rows = spindle.sensor_matrix()
    minv = np.linalg.inv(system.M)
    a = np.block([[np.zeros((n, n)), np.eye(n)], [-minv @ system.K, -minv @ (system.C + system.G)]])
    b = np.vstack([np.zeros((n, 1)), minv @ system.B[:, :1]])
    c = np.hstack([rows[[labels.index(f"nose:{d}") for d in "xyz"]], np.zeros((3, n))])
    response = control.frequency_response(control.ss(a, b, c, np.zeros((3, 1))), 2 * np.pi * freq)
    expected = np.asarray(response.complex).reshape(3, freq.size)
    # state-space inversion vs dynamic-stiffness solve: agreement to 1e-8 of the largest response
    np.testing.assert_allclose(frf.H[2:5, 0], expected, rtol=0, atol=1e-8 * abs(expected).max())


def test_frf_of_a_position_dependent_model_with_hysteretic_damping(slide_model):
    freq = np.array([0.0, 50.0, 97.0, 400.0])
    position = {"z": 0.4}
    frf = reference_frf(slide_model, freq=freq, position=position)  # default: model inputs to every sensor channel
    assert frf.input_names == ("F",)
    assert frf.output_names == ("tool:x", "tool:y", "tool:z", "top:x", "top:y", "top:z")
    system = slide_model.system(None, position)
    _, rows = slide_model.sensor_matrix(None, position)
    # direct solve of (K + 1j H + 1j w C - w^2 M) x = b, one frequency at a time
    for k, f in enumerate(freq):
        w = 2 * np.pi * f
        x = np.linalg.solve(system.K + 1j * system.H + 1j * w * (system.C + system.G) - w**2 * system.M, system.B)
        np.testing.assert_allclose(frf.H[:, :, k], rows @ x, rtol=1e-10, atol=1e-22)


def test_frf_uff58_round_trip(tmp_path, spindle):
    frf = reference_frf(spindle, freq=np.linspace(0.0, 1200.0, 121), inputs=["Fx", "nose:y"])
    back = read_frf(write_frf(tmp_path / "frf.uff", frf))
    assert back.input_names == frf.input_names
    assert back.output_names == frf.output_names
    np.testing.assert_array_equal(back.freq, frf.freq)
    # ASCII UFF 58 keeps 12 significant digits (E20.12)
    np.testing.assert_allclose(back.H, frf.H, rtol=1e-11, atol=0)


# -------------------------------------------------------------------------------------------- errors


def test_mode_count_errors(slide_model):
    with pytest.raises(DataError, match=r"n_modes = 13 exceeds the 12 oscillatory modes that model 'slide' has"):
        reference_modes(slide_model, n_modes=13)
    with pytest.raises(DataError, match=r"n_modes must be a positive integer or None \(all modes\); got 0"):
        reference_modes(slide_model, n_modes=0)


def test_parameter_and_position_errors(slide_model):
    with pytest.raises(ModelError, match="unknown parameter 'kx' for model 'slide'"):
        reference_modes(slide_model, params={"kx": 1.0})
    with pytest.raises(ModelError, match="unknown axis 'x' for model 'slide'; known axes: z"):
        reference_modes(slide_model, positions=[{"x": 0.1}])
    with pytest.raises(DataError, match="positions must be 'all', a list of axis positions or None; got 'every'"):
        reference_modes(slide_model, positions="every")
    with pytest.raises(DataError, match="positions must list at least one axis position; got an empty list"):
        reference_modes(slide_model, positions=[])


@pytest.mark.parametrize("name", ["noise_frequency", "noise_damping", "noise_shape"])
def test_noise_level_errors(rig, name):
    with pytest.raises(DataError, match=rf"{name} must be a finite number >= 0 \(relative standard deviation\); "
                                        r"got -0.1"):
        reference_modes(rig, **{name: -0.1})
    with pytest.raises(DataError, match=rf"{name} must be a number >= 0 \(relative standard deviation\); got 'x'"):
        reference_modes(rig, **{name: "x"})


def test_runaway_noise_is_an_error(rig):
    with pytest.raises(DataError, match="noise_damping noise level 1e\\+06 keeps drawing non-physical values"):
        reference_modes(rig, noise_damping=1e6, rng=0)


def test_model_without_sensors_is_an_error():
    b = StructureBuilder("bare")
    b.parameter("m", 1.0, kind="mass")
    b.body("a", mass="m", dofs=["x"])
    b.element("k", bodies=("ground", "a"), stiffness={"x": 1.0e4})
    model = NumericModel(b.build())
    with pytest.raises(DataError, match="model 'bare' has no sensor nodes"):
        reference_modes(model)
    dofs = reference_modes(model, sensors="dofs")  # closed form: sqrt(k / m) / 2 pi
    assert dofs.sensors == ("a.x",)
    np.testing.assert_allclose(dofs.sets[0].frequency, [100.0 / (2 * np.pi)], rtol=1e-12)
    with pytest.raises(DataError, match="model must be a NumericModel or a Structure; got str"):
        reference_modes("builtin:two-mass-rig")


def test_frf_errors(rig):
    with pytest.raises(DataError, match=r"driving point 'F9' is neither an input of model 'two-mass-rig' \(F1, F2\)"):
        reference_frf(rig, freq=[1.0], inputs=["F9"])
    with pytest.raises(DataError, match="output 'n3:x' is neither an output of model 'two-mass-rig'"):
        reference_frf(rig, freq=[1.0], outputs=["n3:x"])
    with pytest.raises(DataError, match="inputs name 'F1' twice"):
        reference_frf(rig, freq=[1.0], inputs=["F1", "F1"])
    with pytest.raises(DataError, match="inputs must name at least one channel; got an empty list"):
        reference_frf(rig, freq=[1.0], inputs=[])
    with pytest.raises(DataError, match=r"outputs name the same channel twice: \['n1:x', 'n1:x', 'n1:y', 'n1:z'\]"):
        reference_frf(rig, freq=[1.0], outputs=["n1:x", "n1"])
    with pytest.raises(DataError, match=r"freq must be a non-empty 1-D array of finite frequencies >= 0 Hz; "
                                        r"got shape \(2,\)"):
        reference_frf(rig, freq=[-1.0, 2.0])


def test_frf_of_a_model_without_inputs_needs_sensor_driving_points():
    b = StructureBuilder("quiet")
    b.parameter("m", 2.0, kind="mass")
    b.body("a", mass="m", dofs=["x"])
    b.element("k", bodies=("ground", "a"), stiffness={"x": 8.0e4})
    b.sensor("p", body="a")
    model = NumericModel(b.build())
    with pytest.raises(DataError, match="model 'quiet' has no inputs; name the driving points as sensor channels"):
        reference_frf(model, freq=[1.0])
    frf = reference_frf(model, freq=[0.0, 10.0], inputs=["p:x"], outputs=["p:x"])
    w = 2 * np.pi * 10.0
    np.testing.assert_allclose(frf.H[0, 0], [1 / 8.0e4, 1 / (8.0e4 - 2.0 * w**2)], rtol=1e-12)  # 1 / (k - m w^2)
