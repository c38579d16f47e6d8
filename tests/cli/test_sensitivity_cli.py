"""``cappe sensitivity`` through main(argv)."""

from __future__ import annotations

import json

import pytest

from cappe.cli import main


def run(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_local_json_contract(capsys):
    code, out, _ = run(capsys, "sensitivity", "builtin:two-mass-rig", "--local", "--percent", "10", "--json")
    assert code == 0
    data = json.loads(out)
    assert [m["frequency"] for m in data["modes"]] == sorted(m["frequency"] for m in data["modes"])
    assert len(data["rows"]) == 2 * 8  # one row per parameter and sign
    row = data["rows"][0]
    assert row["parameter"] == "m1"
    assert row["change_percent"] == 10
    assert len(row["frequency_change_percent"]) == len(row["damping_change_percent"]) == 2
    assert data["rows"][1]["change_percent"] == -10
    assert len(data["normalized"]["frequency"]) == 2


def test_local_text_and_parameter_subset(capsys):
    code, out, _ = run(capsys, "sensitivity", "builtin:two-mass-rig", "--local", "--parameters", "c11")
    assert code == 0
    assert "c11" in out
    assert "m1 " not in out.split("\n", 2)[2]


def test_sobol_with_a_reference_written_by_model_modes(capsys, tmp_path):
    ref = tmp_path / "ref.json"
    code, out, _ = run(capsys, "model", "modes", "builtin:two-mass-rig", "--modal-out", str(ref), "--sensors", "n1:x,n2:x")
    assert code == 0
    assert "wrote 1 modal set(s) at 2 channels" in out
    assert json.loads(ref.read_text())["format"] == "cappe.modal/1"
    plot = tmp_path / "sobol.png"
    code, out, _ = run(capsys, "sensitivity", "builtin:two-mass-rig", "--sobol", "--reference", str(ref), "--n-gsa", "64",
                       "--criteria", "frequency,macxp", "--json", "--plot", str(plot))
    assert code == 0
    data = json.loads(out)
    assert data["format"] == "cappe.sensitivity/1"
    assert [o["name"] for o in data["outputs"]][:2] == ["frequency:mode1@-", "macxp:mode1@-"]
    assert "m2" in data["significant"]["frequency:mode1@-"]
    assert plot.stat().st_size > 1000


def test_all_positions_writes_one_set_per_axis_position(capsys, tmp_path):
    model = tmp_path / "sled.yaml"
    model.write_text(SLED)
    ref = tmp_path / "ref.json"
    code, out, err = run(capsys, "model", "modes", str(model), "--modal-out", str(ref), "--all-positions")
    assert code == 0, err
    data = json.loads(ref.read_text())
    assert [s["position"] for s in data["sets"]] == [{"z": -0.2}, {"z": 0.0}, {"z": 0.3}]


SLED = """\
format: cappe.model/1
name: sled
parameters:
  - {name: m, value: 3.0, kind: mass}
  - {name: k, value: 2.0e6, kind: stiffness}
  - {name: c, value: 30.0, kind: damping}
axes:
  - {name: z, positions: [-0.2, 0.0, 0.3]}
bodies:
  - {name: table, mass: m, inertia: {xx: 0.02, yy: 0.02, zz: 0.02}, position: [0, 0, z], dofs: [x, ry]}
elements:
  - {name: a, bodies: [ground, table], at: [0, 0, -0.5], stiffness: {x: k}, damping: {x: c}}
  - {name: b, bodies: [ground, table], at: [0, 0, 0.5], stiffness: {x: k}, damping: {x: c}}
sensors:
  - {name: tip, body: table, point: [0, 0, 0.1]}
"""


@pytest.mark.parametrize(
    ("argv", "code", "message"),
    [
        (["--sobol"], 2, "--sobol needs --reference FILE.json"),
        (["--sobol", "--reference", "missing.json"], 1, "cannot read modal data file missing.json: no such file"),
        (["--local", "--percent", "200"], 1, r"percent must lie in (0, 100); got 200"),
        (["--local", "--parameters", "k99"], 1, "unknown parameter 'k99'"),
    ],
)
def test_errors(capsys, argv, code, message):
    got, _, err = run(capsys, "sensitivity", "builtin:two-mass-rig", *argv)
    assert got == code
    assert message in err


def test_reference_with_unknown_sensors_is_an_error(capsys, tmp_path):
    ref = tmp_path / "ref.json"
    ref.write_text(json.dumps({"format": "cappe.modal/1", "sensors": ["tool:x"],
                               "sets": [{"frequency": [90.0], "damping": [0.01], "shape_re": [[1.0]]}]}))
    code, _, err = run(capsys, "sensitivity", "builtin:two-mass-rig", "--sobol", "--reference", str(ref), "--n-gsa", "8")
    assert code == 1
    assert "sensor 'tool:x' does not exist in model 'two-mass-rig'" in err
    ref.write_text(json.dumps({"format": "cappe.modal/1", "sensors": ["n1:x"],
                               "sets": [{"frequency": [90.0, 100.0], "damping": [0.01], "shape_re": [[1.0]]}]}))
    code, _, err = run(capsys, "sensitivity", "builtin:two-mass-rig", "--sobol", "--reference", str(ref), "--n-gsa", "8")
    assert code == 1
    assert "sets[0].damping must list 2 number(s); got 1" in err


SYMMETRIC = """\
format: cappe.model/1
name: symmetric
parameters:
  - {name: m, value: 2.0, kind: mass}
  - {name: k, value: 1.0e6, kind: stiffness}
bodies:
  - {name: table, mass: m, inertia: {xx: 0.02, yy: 0.02, zz: 0.02}, dofs: [x, y]}
elements:
  - {name: a, bodies: [ground, table], at: [0, 0, 0], stiffness: {x: k, y: k}}
"""


def test_local_on_repeated_modes_warns_in_words(capsys, tmp_path):
    # a raw "IllConditionedWarning: modes [(1, 0), (0, 1)] ..." with a source line came out before
    model = tmp_path / "symmetric.yaml"
    model.write_text(SYMMETRIC)
    code, out, err = run(capsys, "sensitivity", str(model), "--local")
    assert code == 0
    # sqrt(k / m) / 2 pi = 112.54 Hz for both x and y
    assert err.startswith("cappe: warning: model 'symmetric' has (nearly) equal frequencies (modes 1 and 2 at "
                          "112.54 Hz)")
    assert "The table re-solves the modes and is not affected" in err
    assert "IllConditionedWarning" not in err
    assert len(err.strip().splitlines()) == 1


def test_sobol_says_when_n_is_too_small(capsys, tmp_path):
    ref = tmp_path / "ref.json"
    run(capsys, "model", "modes", "builtin:two-mass-rig", "--modal-out", str(ref), "--sensors", "n1:x,n2:x")
    code, out, _ = run(capsys, "sensitivity", "builtin:two-mass-rig", "--sobol", "--reference", str(ref), "--n-gsa", "8",
                       "--criteria", "frequency")
    assert code == 0
    assert "WARNING: the ST values are too noisy to read at N = 8:" in out
    code, out, _ = run(capsys, "sensitivity", "builtin:two-mass-rig", "--sobol", "--reference", str(ref), "--n-gsa",
                       "8", "--criteria", "frequency", "--json")
    assert json.loads(out)["noise"]["too_noisy"] is True
