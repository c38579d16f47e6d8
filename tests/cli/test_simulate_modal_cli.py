"""``cappe simulate`` without ``--excite``: reference modal data (cappe.modal/1, UFF 55) and FRFs (UFF 58).

The CLI only parses and calls cappe.modal._reference (whose numbers tests/modal/test_reference.py checks against
independent references); here its files must equal what the library returns for the same arguments, and the
parameter / position handling and the errors must be right.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from cappe.cli import main
from cappe.io import read_frf, read_modal_data, read_uff_modal, read_uff_nodes
from cappe.modal._reference import reference_frf, reference_modes
from cappe.model import NumericModel, load_model

CARRIAGE = """\
format: cappe.model/1
name: carriage
parameters:
  - {name: mb, value: 20.0, kind: mass, disturbable: true}
  - {name: mt, value: 5.0, kind: mass, disturbable: true}
  - {name: kb, value: 4.0e6, kind: stiffness}
  - {name: kt, value: 2.0e6, kind: stiffness}
  - {name: cb, value: 200.0, kind: damping}
  - {name: ct, value: 40.0, kind: damping, disturbable: true}
axes:
  - {name: z, positions: [-0.2, 0.0, 0.3]}
bodies:
  - {name: base, mass: mb, inertia: {xx: 0.5, yy: 0.5, zz: 0.5}, dofs: [x, ry]}
  - {name: table, mass: mt, inertia: {xx: 0.02, yy: 0.02, zz: 0.02}, position: [0, 0, z], dofs: [x, ry]}
elements:
  - {name: m1, bodies: [ground, base], at: [0, 0, -0.5], stiffness: {x: kb}, damping: {x: cb}}
  - {name: m2, bodies: [ground, base], at: [0, 0, 0.5], stiffness: {x: kb}, damping: {x: cb}}
  - {name: g1, bodies: [base, table], at: [0, 0, z - 0.1], stiffness: {x: kt}, damping: {x: ct}}
  - {name: g2, bodies: [base, table], at: [0, 0, z + 0.1], stiffness: {x: kt}, damping: {x: ct}}
sensors:
  - {name: tip, body: table, point: [0, 0, 0.1]}
  - {name: foot, body: base, point: [0, 0, -0.4]}
inputs:
  - {name: F, body: table, point: [0, 0, 0.1], direction: x}
outputs:
  - {name: d, body: table, point: [0, 0, 0.1], direction: x}
"""
TRUTH = {"kt": 2.4e6, "cb": 150.0}  # the other parameters keep their nominal values
NOISE = {"noise_frequency": 0.005, "noise_damping": 0.05, "noise_shape": 0.02}


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    root = tmp_path_factory.mktemp("carriage")
    (root / "carriage.yaml").write_text(CARRIAGE)
    (root / "truth.json").write_text(json.dumps(TRUTH))
    return root


@pytest.fixture(scope="module")
def model(files):
    return NumericModel(load_model(str(files / "carriage.yaml")))


def simulate(capsys, files, *argv):
    return run(capsys, "simulate", files / "carriage.yaml", "--params", files / "truth.json", *argv)


def test_files_equal_the_library_reference(capsys, files, model, tmp_path):
    ref_file, uff, frf_file = tmp_path / "ref.json", tmp_path / "modes.uff", tmp_path / "frf.uff"
    code, out, err = simulate(capsys, files, "--positions", "all", "--modes", 3, "--noise-frequency", 0.005,
                              "--noise-damping", 0.05, "--noise-shape", 0.02, "--seed", 4, "-o", ref_file,
                              "--uff", uff, "--frf", frf_file, "--driving-points", "F,tip:x", "--band", "0:400",
                              "--lines", 81, "--json")
    assert code == 0, err
    expected = reference_modes(model, params=TRUTH, positions="all", n_modes=3, rng=4, **NOISE)
    got = read_modal_data(ref_file)
    # JSON keeps every float exactly (shortest repr round trip)
    assert got.to_dict() == expected.to_dict()
    assert got.sensors == ("tip:x", "tip:y", "tip:z", "foot:x", "foot:y", "foot:z")
    # the truth differs from the nominal model (missing parameters nominal, given ones used)
    nominal = reference_modes(model, positions="all", n_modes=3, rng=4, **NOISE)
    assert not np.allclose(got.sets[0].frequency, nominal.sets[0].frequency, rtol=1e-3)

    back = read_uff_modal(uff)
    assert back.sensors == got.sensors
    assert [s.position for s in back.sets] == [{"z": -0.2}, {"z": 0.0}, {"z": 0.3}]
    for b, r in zip(back.sets, got.sets, strict=True):
        np.testing.assert_array_equal(b.frequency, r.frequency)  # exact through cappe's ID line 5
        np.testing.assert_allclose(b.shapes, r.shapes, atol=1e-5 * abs(r.shapes).max())  # UFF 55: 6 digits
    # sensor nodes at the first position (z = -0.2): tip = table origin (0, 0, z) + (0, 0, 0.1); foot fixed
    assert read_uff_nodes(uff) == {"tip": (0.0, 0.0, -0.2 + 0.1), "foot": (0.0, 0.0, -0.4)}

    summary = json.loads(out)
    assert summary["n_sets"] == 3
    assert summary["n_modes"] == 3
    assert summary["n_sensors"] == 6
    assert summary["parameters"] == TRUTH
    assert summary["noise"] == {"frequency": 0.005, "damping": 0.05, "shape": 0.02}
    assert summary["seed"] == 4
    assert summary["sets"][2]["frequency_range"] == [got.sets[2].frequency.min(), got.sets[2].frequency.max()]
    assert summary["files"]["modal"] == str(ref_file)
    assert summary["files"]["uff"] == str(uff)
    paths = [item["path"] for item in summary["files"]["frf"]]
    assert paths == [str(tmp_path / f"frf_z={z}.uff") for z in ("-0.2", "0", "0.3")]
    for path, z in zip(paths, (-0.2, 0.0, 0.3), strict=True):
        frf = read_frf(path)
        exact = reference_frf(model, freq=np.linspace(0, 400, 81), params=TRUTH, position={"z": z},
                              inputs=["F", "tip:x"])
        assert frf.input_names == ("F", "tip:x")
        assert frf.output_names == got.sensors
        np.testing.assert_allclose(frf.freq, exact.freq, rtol=1e-12)
        np.testing.assert_allclose(frf.H, exact.H, rtol=1e-11, atol=0)  # ASCII UFF 58: 12 digits


def test_text_summary_and_default_position(capsys, files, tmp_path):
    ref_file = tmp_path / "ref.json"
    code, out, err = simulate(capsys, files, "-o", ref_file)
    assert code == 0, err
    assert "carriage: 4 modes at 1 position(s), 6 sensor channels (2 nodes)" in out
    assert "z=-0.2" in out  # the default position: the first listed
    assert "noise: frequency 0, damping 0, shape 0 (relative std; seed 0)" in out
    assert f"wrote {ref_file} (cappe.modal/1)" in out
    assert [s.position for s in read_modal_data(ref_file).sets] == [{"z": -0.2}]


def test_position_forms(capsys, files, tmp_path):
    def positions(*argv):
        path = tmp_path / "p.json"
        code, _, err = simulate(capsys, files, *argv, "-o", path)
        assert code == 0, err
        return [s.position for s in read_modal_data(path).sets]

    assert positions("--positions", "z=-0.2,0.3") == [{"z": -0.2}, {"z": 0.3}]
    assert positions("--positions", "z=-0.2", "--positions", "z=0.3") == [{"z": -0.2}, {"z": 0.3}]
    assert positions("--position", "z=0.1") == [{"z": 0.1}]


def test_frf_band_defaults_and_model_outputs(capsys, files, tmp_path):
    frf_file = tmp_path / "frf.npz"
    code, out, err = simulate(capsys, files, "--frf", frf_file, "--frf-outputs", "d,tip", "--json")
    assert code == 0, err
    summary = json.loads(out)
    assert summary["files"]["frf"] == [{"path": str(frf_file), "position": {"z": -0.2}, "noise": 0.0}]  # as named
    frf = read_frf(frf_file)
    assert frf.input_names == ("F",)  # default: every model input
    assert frf.output_names == ("d", "tip:x", "tip:y", "tip:z")
    assert frf.freq.size == 801
    assert frf.freq[0] == 0.0
    # default band: 0 to 1.25 x the highest mode, 3 significant digits
    assert frf.freq[-1] == float(f"{1.25 * summary['sets'][0]['frequency_range'][1]:.3g}")
    # model output d and sensor channel tip:x are the same point and direction
    np.testing.assert_allclose(frf.H[0], frf.H[1], rtol=1e-12)


def test_frf_noise_rehearses_a_modal_test(capsys, files, tmp_path):
    """--noise-frf: H (1 + REL e), e complex standard normal per line and channel, on sensor channels that are not
    model outputs; the modes and the exact FRFs of the same seed do not change."""
    common = ("--frf-outputs", "tip,foot:x", "--driving-points", "tip:x", "--lines", "2001", "--seed", "7")
    exact_file, noisy_file = tmp_path / "exact.npz", tmp_path / "noisy.npz"
    assert simulate(capsys, files, "--frf", exact_file, *common, "-o", tmp_path / "a.json")[0] == 0
    code, out, err = simulate(capsys, files, "--frf", noisy_file, *common, "--noise-frf", "0.02",
                              "-o", tmp_path / "b.json")
    assert code == 0, err
    assert "relative complex noise 0.02)" in out
    exact, noisy = read_frf(exact_file), read_frf(noisy_file)
    assert noisy.output_names == ("tip:x", "tip:y", "tip:z", "foot:x")
    live = np.abs(exact.H) > 0  # a channel the driving point cannot move has H = 0 exactly
    relative = (noisy.H[live] / exact.H[live] - 1.0) * np.sqrt(2.0)
    assert relative.size > 4000
    # real and imaginary parts each N(0, 0.02^2), independent: std within 5 % of 0.02 at n > 4000, no mean
    for part in (relative.real, relative.imag):
        assert abs(np.std(part) / 0.02 - 1.0) < 0.05
        assert abs(np.mean(part)) < 4 * 0.02 / np.sqrt(part.size)
    assert abs(np.corrcoef(relative.real, relative.imag)[0, 1]) < 0.05
    assert read_modal_data(tmp_path / "a.json").sets[0].frequency.tolist() == \
        read_modal_data(tmp_path / "b.json").sets[0].frequency.tolist()


@pytest.mark.parametrize(
    ("argv", "code", "message"),
    [
        (["--positions", "x=0.1"], 2, "--positions 'x=0.1': model 'carriage' has no axis 'x'; its axes: "
                                      "z (positions -0.2, 0, 0.3)"),
        (["--positions", "z=abc"], 2, "--positions 'z=abc': 'abc' is not a finite number"),
        (["--positions", "z"], 2, "--positions must be 'all' or AXIS=VALUE[,VALUE...] (e.g. z=-0.294,0.135); "
                                  "got 'z'"),
        (["--positions", "all", "--positions", "z=0.1"], 2, "--positions all cannot be combined"),
        (["--positions", "z=0.1,0.1"], 2, "--positions names z=0.1 twice"),
        (["--modes", "5"], 1, "n_modes = 5 exceeds the 4 oscillatory modes that model 'carriage' has"),
        (["--modes", "0"], 1, "n_modes must be a positive integer or None (all modes); got 0"),
        (["--noise-damping", "-0.1"], 1, "noise_damping must be a finite number >= 0"),
        (["--driving-points", "F"], 2, "--driving-points sets up the simulated FRFs; give --frf FILE as well"),
        (["--noise-frf", "0.02"], 2, "--noise-frf sets up the simulated FRFs; give --frf FILE as well"),
        (["--frf", "x.npz", "--noise-frf", "2"], 2, "--noise-frf must be a relative level in [0, 1] (0.02 = 2 %); "
                                                   "got 2"),
        (["--band", "0:100"], 2, "--band sets up the simulated FRFs; give --frf FILE as well"),
        (["--frf", "f.uff", "--lines", "1"], 2, "--lines must be an integer >= 2; got 1"),
        (["--frf", "f.uff", "--band", "5"], 2, "--band must look like LO:HI"),
        (["--frf", "f.uff", "--driving-points", "Q"], 1, "driving point 'Q' is neither an input of model 'carriage'"),
        (["--noise", "0.01"], 2, "--noise belongs to time simulation (--excite INPUT=SIGNAL)"),
        (["--fs", "100", "--duration", "2"], 2, "--fs, --duration belong to time simulation"),
        (["--excite", "F=random", "--modes", "3"], 2, "--modes belongs to reference modal data (without --excite)"),
        (["--disturb", "1.5"], 2, "--disturb must be a fraction in [0, 1), e.g. 0.1; got 1.5"),
        (["--disturb", "nan"], 2, "--disturb must be a fraction in [0, 1)"),
    ],
)
def test_errors(capsys, files, tmp_path, argv, code, message):
    ref_file = tmp_path / ("ref.npz" if "--excite" in argv else "ref.json")  # -o of what the command writes
    got, _, err = simulate(capsys, files, *argv, "-o", ref_file)
    assert got == code, err
    assert message in err
    assert not ref_file.exists()  # nothing is written when the command fails


def test_unknown_parameter_in_truth_file(capsys, files, tmp_path):
    truth = tmp_path / "bad.json"
    truth.write_text(json.dumps({"kt": 2.0e6, "k_guide": 1.0}))
    code, _, err = run(capsys, "simulate", files / "carriage.yaml", "--params", truth, "-o", tmp_path / "r.json")
    assert code == 1
    assert "unknown parameter 'k_guide' for model 'carriage'" in err


def test_model_without_axes_and_builtin(capsys, tmp_path):
    ref_file = tmp_path / "ref.json"
    code, out, err = run(capsys, "simulate", "builtin:two-mass-rig", "--positions", "all", "--set", "k12=2e5",
                         "-o", ref_file)
    assert code == 0, err
    data = read_modal_data(ref_file)
    assert [s.position for s in data.sets] == [{}]
    rig = NumericModel(load_model("builtin:two-mass-rig"))
    assert data.to_dict() == reference_modes(rig, params={"k12": 2e5}).to_dict()
    assert "(no axes)" in out
    code, _, err = run(capsys, "simulate", "builtin:two-mass-rig", "--positions", "z=0")
    assert code == 2
    assert "model 'two-mass-rig' has no axis 'z'; its axes: none (this model has no axes)" in err


def test_disturbed_model(capsys, files, model, tmp_path):
    # paper 3.3: every disturbable parameter (mb, mt, ct here) off by +-10 %, except those given explicitly
    ref_file = tmp_path / "ref.json"
    code, out, err = simulate(capsys, files, "--disturb", 0.1, "--set", "mt=6", "--seed", 3, "--modes", 3,
                              "-o", ref_file, "--json")
    assert code == 0, err
    params = json.loads(out)["parameters"]
    assert params["kt"] == TRUTH["kt"]  # not disturbable: as given
    assert params["mt"] == 6.0  # given explicitly: not disturbed
    assert params["mb"] in (pytest.approx(18.0, rel=1e-15), pytest.approx(22.0, rel=1e-15))
    assert params["ct"] in (pytest.approx(36.0, rel=1e-15), pytest.approx(44.0, rel=1e-15))
    assert read_modal_data(ref_file).to_dict() == reference_modes(model, params=params, n_modes=3, rng=3).to_dict()
    # the signs come from the seed: some seed among a few flips mb
    signs = set()
    for seed in range(6):
        code, out, _ = simulate(capsys, files, "--disturb", 0.1, "--seed", seed, "--json")
        assert code == 0
        signs.add(json.loads(out)["parameters"]["mb"] > 20.0)
    assert signs == {True, False}
    code, _, err = run(capsys, "simulate", "builtin:two-mass-rig", "--disturb", "0.1")
    assert code == 2
    assert "model 'two-mass-rig' tags no parameter as disturbable" in err
