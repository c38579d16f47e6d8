"""``cappe estimate`` through main(argv): the cappe.estimate/1 contract, methods on simulated rig data, errors."""

from __future__ import annotations

import json

import pytest

from cappe.cli import main
from cappe.estimate import read_estimate

TRUTH = {"m1": 1.39, "m2": 1.09, "k11": 1.38e6, "k12": 0.12e6, "k22": 0.24e6, "c11": 20.0, "c22": 4.0}


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture(scope="module")
def rig_data(tmp_path_factory):
    path = tmp_path_factory.mktemp("estimate") / "rig.npz"
    code = main(["simulate", "builtin:two-mass-rig", "--set", "c11=20", "--set", "c22=4", "--excite", "F1=random",
                 "--excite", "F2=random", "--fs", "2000", "--duration", "4", "--noise", "0.01", "--seed", "1",
                 "-o", str(path)])
    assert code == 0
    return path


def test_direct_estimate_json_contract(capsys, tmp_path, rig_data):
    out_file = tmp_path / "est.json"
    code, out, err = run(capsys, "estimate", "builtin:two-mass-rig", "--data", rig_data, "--method", "direct",
                         "--json", "-o", out_file)
    assert code == 0, err
    doc = json.loads(out)
    assert doc["format"] == "cappe.estimate/1"
    assert doc["method"] == "direct"
    assert set(doc["parameters"]) == set(TRUTH)
    assert set(doc["uncertainty"]) >= {"std", "ci95", "correlation"}
    assert doc["success"] is True
    # the bar for the direct method with velocities and accelerations measured: within 2 % (the dampers,
    # whose std are 1-3 %: within their 95 % intervals, as every parameter)
    for name, value in TRUTH.items():
        if name[0] != "c":
            assert doc["parameters"][name] == pytest.approx(value, rel=0.02), name
        low, high = doc["uncertainty"]["ci95"][name]
        assert low <= value <= high, name
    assert read_estimate(out_file).parameters == doc["parameters"]


@pytest.fixture(scope="module")
def rig_zoh_data(tmp_path_factory):
    """The same record with the force held between samples: what the EKF models by default (a band-limited record
    fails its residual test: the filter cannot model that input)."""
    path = tmp_path_factory.mktemp("estimate") / "rig-zoh.npz"
    code = main(["simulate", "builtin:two-mass-rig", "--set", "c11=20", "--set", "c22=4", "--excite", "F1=random",
                 "--excite", "F2=random", "--fs", "2000", "--duration", "4", "--noise", "0.01", "--seed", "1",
                 "--intersample", "zoh", "-o", str(path)])
    assert code == 0
    return path


def test_ekf_subset_text_and_trajectory_plot(capsys, tmp_path, rig_zoh_data):
    plot = tmp_path / "traj.png"
    code, out, err = run(capsys, "estimate", "builtin:two-mass-rig", "--data", rig_zoh_data, "--method", "ekf",
                         "--unknowns", "k11,k22", "--set", "c11=20", "--set", "c22=4", "--plot", plot)
    assert code == 0, err
    assert "ekf: converged" in out
    assert "k11" in out
    assert "m1 " not in out
    assert plot.stat().st_size > 5000


def test_errors(capsys, tmp_path, rig_data):
    code, _, err = run(capsys, "estimate", "builtin:two-mass-rig", "--data", rig_data, "--method", "modal")
    assert code == 2
    assert "method 'modal' takes modal data" in err
    code, _, err = run(capsys, "estimate", "builtin:two-mass-rig", "--data", rig_data, "--method", "direct",
                       "--unknowns", "k11,kx")
    assert code == 1
    assert "unknowns ['kx'] are not parameters of model 'two-mass-rig'" in err
    code, _, err = run(capsys, "estimate", "builtin:two-mass-rig", "--data", rig_data, "--method", "direct",
                       "--bounds", "k11=1e6")
    assert code == 2
    assert "--bounds must look like NAME=LO:HI" in err
    code, _, err = run(capsys, "estimate", "builtin:two-mass-rig", "--data", rig_data, "--method", "direct",
                       "--unknowns", "k11", "--bounds", "k11=2e6:3e6")
    assert code == 1
    assert "start of 'k11' = 1.38e+06 lies outside its bounds [2e+06, 3e+06]" in err
    frf_only = tmp_path / "few.csv"
    frf_only.write_text("time,F1,d1\n0,1,0\n0.001,0,1e-6\n0.002,0,2e-6\n")
    code, _, err = run(capsys, "estimate", "builtin:two-mass-rig", "--data", frf_only, "--method", "direct")
    assert code == 1
    assert "F2" in err or "v1" in err or "a1" in err  # the missing channels are named


def test_direct_bounds_hold_the_estimate(capsys, rig_data):
    # --bounds with --method direct were not applied: k11 came back outside them, "identifiable yes", with an interval
    free = json.loads(run(capsys, "estimate", "builtin:two-mass-rig", "--data", rig_data, "--method", "direct",
                          "--json")[1])
    k11 = free["parameters"]["k11"]
    assert k11 < 1.38e6
    lo = (k11 + 1.38e6) / 2  # bounds that contain the model's value (1.38e6, the start) but not this data's estimate
    code, out, err = run(capsys, "estimate", "builtin:two-mass-rig", "--data", rig_data, "--method", "direct",
                         "--bounds", f"k11={lo!r}:2e6")
    assert code == 0, err
    row = next(line for line in out.splitlines() if line.split()[:1] == ["k11"])
    assert float(row.split()[1]) == pytest.approx(lo, rel=1e-5)  # printed with 6 digits
    assert row.rstrip().endswith("NO (at a bound)")
    assert "not determined" in row
    assert f"WARNING: the data alone put k11 at {k11:.6g}" in out
    assert err == ""  # said once, in the text


def test_study_tabulates_mean_and_std_per_noise_level(capsys):
    code, out, err = run(capsys, "study", "builtin:two-mass-rig", "--method", "direct", "--unknowns", "k11,k22",
                         "--set", "k11=1.2e6", "--noise", "0,0.01", "--seeds", 2, "--duration", 1, "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["format"] == "cappe.study/1"
    assert doc["truth"] == {"k11": 1.2e6, "k22": 0.24e6}
    rows = {(r["noise"], r["parameter"]): r for r in doc["rows"]}
    assert rows[(0.0, "k11")]["mean"] == pytest.approx(1.2e6, rel=1e-8)  # noise-free: exact
    assert rows[(0.01, "k11")]["runs"] == 2
    assert rows[(0.01, "k11")]["mean"] == pytest.approx(1.2e6, rel=0.02)
    code, _, err = run(capsys, "study", "builtin:two-mass-rig", "--method", "direct", "--noise", "a,b")
    assert code == 2
    assert "--noise must be comma-separated fractions" in err


def test_settings_reach_the_estimator(capsys, rig_data):
    code, out, err = run(capsys, "estimate", "builtin:two-mass-rig", "--data", rig_data, "--method", "direct",
                         "--setting", "instruments=model", "--json")
    assert code == 0, err
    assert json.loads(out)["diagnostics"]["instruments"] == "model"
    code, _, err = run(capsys, "estimate", "builtin:two-mass-rig", "--data", rig_data, "--method", "direct",
                       "--setting", "bogus=1")
    assert code == 2
    assert "unexpected keyword argument 'bogus'" in err
    code, _, err = run(capsys, "estimate", "builtin:two-mass-rig", "--data", rig_data, "--method", "direct",
                       "--setting", "=1")
    assert code == 2
    assert "--setting must look like NAME=VALUE" in err


def test_response_plot_before_and_after(capsys, tmp_path, rig_data):
    plot = tmp_path / "resp.png"
    # the known dampings as simulated: with the model file's (c22 8.5x too small) the equations of motion do not hold
    # and direct FAILS its force-independence test (exit 1)
    code, out, err = run(capsys, "estimate", "builtin:two-mass-rig", "--data", rig_data, "--method", "direct",
                         "--unknowns", "k11,k22", "--set", "c11=20", "--set", "c22=4", "--plot-response", plot, "--json")
    assert code == 0, err
    assert json.loads(out)["diagnostics"]["plot_response"] == str(plot)
    assert plot.stat().st_size > 20000  # six panels of curves
    ref = tmp_path / "ref.json"
    assert run(capsys, "model", "modes", "builtin:two-mass-rig", "--modal-out", ref, "--sensors", "n1:x,n2:x")[0] == 0
    code, _, err = run(capsys, "estimate", "builtin:two-mass-rig", "--data", ref, "--method", "modal",
                       "--unknowns", "k11", "--plot-response", tmp_path / "x.png")
    assert code == 2
    assert "--plot-response needs time data or FRFs" in err


def test_response_plot_of_frfs(capsys, tmp_path):
    """The FRF branch of --plot-response: one panel per (output, input) pair of the measured FRFs."""
    import numpy as np

    from cappe.io import write_frf
    from cappe.model import NumericModel, load_model

    data = tmp_path / "h.npz"
    system = NumericModel(load_model("builtin:two-mass-rig")).system()
    write_frf(data, system.frf(np.linspace(5.0, 300.0, 120), outputs=["d1", "d2"]))
    plot = tmp_path / "frf.png"
    code, out, err = run(capsys, "estimate", "builtin:two-mass-rig", "--data", data, "--method", "one-step-frf",
                         "--unknowns", "k11", "--plot-response", plot, "--json")
    assert code == 0, err
    assert json.loads(out)["diagnostics"]["plot_response"] == str(plot)
    assert plot.stat().st_size > 20000  # four panels of curves


def test_landscape_plot(capsys, tmp_path, rig_data):
    plot = tmp_path / "land.png"
    # a held-input record fitted as such: the landscape's hundreds of one-step costs on the band-limited default
    # take minutes (each a zero-padded FFT simulation; issue 21's note)
    held = tmp_path / "held.npz"
    assert main(["simulate", "builtin:two-mass-rig", "--set", "c11=20", "--set", "c22=4", "--excite", "F1=random",
                 "--excite", "F2=random", "--fs", "2000", "--duration", "4", "--noise", "0.01", "--seed", "1",
                 "--intersample", "zoh", "-o", str(held)]) == 0
    code, _, err = run(capsys, "estimate", "builtin:two-mass-rig", "--data", held, "--method", "one-step",
                       "--unknowns", "k11,k22", "--set", "c11=20", "--set", "c22=4", "--intersample", "zoh",
                       "--plot-landscape", f"k11,k22:{plot}")
    assert code == 0, err
    assert plot.stat().st_size > 10000
    code, _, err = run(capsys, "estimate", "builtin:two-mass-rig", "--data", rig_data, "--method", "direct",
                       "--unknowns", "k11,k22", "--plot-landscape", f"k11,k22:{plot}")
    assert code == 1
    assert "direct: no nonlinear cost to slice" in err
    code, _, err = run(capsys, "estimate", "builtin:two-mass-rig", "--data", rig_data, "--method", "one-step",
                       "--unknowns", "k11,k22", "--plot-landscape", "k11:x.png")
    assert code == 2
    assert "--plot-landscape must look like A,B:FILE.png" in err


CARRIAGE = """\
format: cappe.model/1
name: carriage
parameters:
  - {name: m, value: 5.0, kind: mass}
  - {name: k, value: 1.0e6, kind: stiffness, bounds: [1.0e5, 1.0e7], unknown: true}
  - {name: c, value: 20.0, kind: damping}
axes:
  - {name: y, positions: [-0.1, 0.0, 0.2]}
bodies:
  - {name: table, mass: m, inertia: {xx: 0.05, yy: 0.05, zz: 0.05}, dofs: [z, rx]}
elements:
  - {name: a, bodies: [ground, table], at: [0, -0.3, 0], stiffness: {z: 2.0e6}, damping: {z: c}}
  - {name: b, bodies: [ground, table], at: [0, y, 0], stiffness: {z: k}, damping: {z: c}}
inputs:
  - {name: F, body: table, point: [0, 0.1, 0], direction: z}
outputs:
  - {name: d, quantity: displacement, body: table, point: [0, 0.1, 0], direction: z}
"""


def test_position_reaches_the_estimator(capsys, tmp_path):
    # `--position` was parsed and dropped: the fit used the first listed position and returned k at 68 % of the
    # truth with a 4 % std. Independent data: the table's (z, rx) receptance written from the physics with numpy
    # (a point at y moves z + y rx; springs k_i [1, y_i] [1, y_i]^T, dampers likewise), the moving shoe at y = 0.2.
    import numpy as np

    m, ixx, c, k_true, y = 5.0, 0.05, 20.0, 2.0e6, 0.2
    h = {name: np.array([1.0, at]) for name, at in (("a", -0.3), ("b", y), ("io", 0.1))}
    stiffness = 2.0e6 * np.outer(h["a"], h["a"]) + k_true * np.outer(h["b"], h["b"])
    damping = c * (np.outer(h["a"], h["a"]) + np.outer(h["b"], h["b"]))
    freq = np.linspace(20.0, 400.0, 200)
    rows = []
    for f in freq:
        w = 2 * np.pi * f
        value = h["io"] @ np.linalg.solve(stiffness - w**2 * np.diag([m, ixx]) + 1j * w * damping, h["io"])
        rows.append(f"{f:.17g},{value.real:.17g},{value.imag:.17g}")
    data = tmp_path / "frf.csv"
    data.write_text('# output_quantities: ["displacement"]\nfrequency,d/F re,d/F im\n' + "\n".join(rows) + "\n")
    model = tmp_path / "carriage.yaml"
    model.write_text(CARRIAGE)
    argv = ["estimate", str(model), "--data", str(data), "--method", "one-step-frf", "--unknowns", "k", "--json"]
    code, out, err = run(capsys, *argv, "--position", "y=0.2")
    assert code == 0, err
    assert json.loads(out)["parameters"]["k"] == pytest.approx(k_true, rel=1e-8)  # exact data, exact model
    # methods whose reference data carry their positions refuse the option instead of ignoring it
    reference = tmp_path / "ref.json"
    assert run(capsys, "model", "modes", str(model), "--modal-out", str(reference))[0] == 0
    code, _, err = run(capsys, "estimate", str(model), "--data", str(reference), "--method", "modal", "--position",
                       "y=0.2")
    assert code == 2
    assert "--position does not apply to method 'modal'" in err
