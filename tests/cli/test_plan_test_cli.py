"""``cappe plan-test``: the plan file, the text report (expected std, undetermined unknowns, a ready command line),
and the chain it feeds: ``cappe simulate --sensors`` writes the plan's channels at the plan's positions."""

from __future__ import annotations

import json
import shlex

import pytest

from cappe.cli import main
from cappe.io import read_modal_data


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def _simulated(capsys, line, out):
    """Run a printed cappe simulate line at the model's values (its --params file left out), writing ``out``."""
    argv = shlex.split(line)[1:]
    i = argv.index("--params")
    del argv[i:i + 2]
    argv[argv.index("-o") + 1] = str(out)
    code, _, err = run(capsys, *argv)
    assert code == 0, err
    return read_modal_data(out)


def test_plan_test_writes_a_plan_the_simulate_chain_takes(tmp_path, capsys):
    out = tmp_path / "plan.json"
    code, text, err = run(capsys, "plan-test", "builtin:uniaxial-machine-tool", "--n-positions", 2, "--n-sensors", 4,
                          "--candidate-sensors", "table_fl,nut,rotor,me1_node", "--modes", 8,
                          "--unknowns", "me1_kx,lgs_kx,cpl_krz,bsd_drz", "--random", 3, "-o", out)
    assert code == 0, err
    doc = json.loads(out.read_text())
    assert doc["format"] == "cappe.plan/1"
    assert len(doc["positions"]) == 2
    assert len(doc["sensors"]) == 4
    assert "std % plan" in text
    assert "bsd_drz" in text
    # the damping of the ball-screw drive is not determined by 4 channels (the text says so, naming it)
    assert doc["unknowns"]["bsd_drz"]["determined"] is False
    assert any(line.startswith("not determined by this plan") and "bsd_drz" in line for line in text.splitlines())
    assert "3 random plans of the same size" in text
    # plans are compared by the median std over the unknowns every candidate together determines (the median over
    # all also counts those no plan determines), and the text says which is which
    keep = [n for n, u in doc["unknowns"].items() if n not in doc["undetermined_with_all_candidates"]]
    median = sorted(doc["unknowns"][n]["relative_std"] for n in keep)
    assert doc["median_relative_std_determinable"] == pytest.approx(
        (median[(len(median) - 1) // 2] + median[len(median) // 2]) / 2, rel=1e-12)
    assert len(doc["random_plans"]["median_relative_std_determinable"]) == 3
    assert f"median std over the {len(keep)} unknowns every candidate together determines" in text
    # the ready command line runs and gives modes at exactly the plan's positions and channels
    ref = _simulated(capsys, doc["commands"]["simulate"], tmp_path / "ref.json")
    assert list(ref.sensors) == doc["sensors"]
    assert [dict(s.position) for s in ref.sets] == doc["positions"]


def test_simulate_sensors_option_restricts_channels(tmp_path, capsys):
    code, _, err = run(capsys, "simulate", "builtin:two-mass-rig", "--sensors", "n1:x,n2:x", "-o", tmp_path / "r.json")
    assert code == 0, err
    assert list(read_modal_data(tmp_path / "r.json").sensors) == ["n1:x", "n2:x"]


def test_plan_test_bad_input(capsys):
    code, _, err = run(capsys, "plan-test", "builtin:uniaxial-machine-tool", "--n-positions", 9, "--n-sensors", 2)
    assert code == 2
    assert "only 4 candidate positions" in err
    code, _, err = run(capsys, "plan-test", "builtin:uniaxial-machine-tool", "--n-positions", 1, "--n-sensors", 2,
                       "--candidate-positions", "x=0.1")
    assert code == 2
    assert "--candidate-positions" in err
    code, _, err = run(capsys, "plan-test", "builtin:uniaxial-machine-tool", "--n-positions", 1, "--n-sensors", 2,
                       "--noise-shape", "0")
    assert code == 2
    assert "noise levels must be > 0" in err
    # --position on an axis the plan chooses was dropped without a word (the option audit found it)
    code, _, err = run(capsys, "plan-test", "builtin:uniaxial-machine-tool", "--n-positions", 1, "--n-sensors", 2,
                       "--position", "z=0.1")
    assert code == 2
    assert "--position fixes z, which the plan chooses" in err


def test_grid_candidates_span_the_listed_range(capsys):
    code, out, err = run(capsys, "plan-test", "builtin:uniaxial-machine-tool", "--grid", 3, "--n-positions", 1,
                         "--n-sensors", 2, "--candidate-sensors", "nut", "--modes", 4, "--unknowns", "lgs_kx",
                         "--random", 0, "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert [p["z"] for p in doc["candidates"]["positions"]] == pytest.approx([-0.294, 0.018, 0.33])
    assert doc["candidates"]["sensors"] == ["nut:x", "nut:y", "nut:z"]


def test_the_rehearsal_commands_of_a_plan_off_the_grid_run_one_position_each(tmp_path, capsys):
    # a new user on the three-axis machine (issue 24): the plan's four positions do not form a grid, and the printed
    # command was one `cappe simulate --positions x=-0.6,y=0.8,z=0`, which simulate refuses ('y=0.8' is not a number)
    # and which named only the first position. Now one simulate line per position, and the identify line reads them
    from argparse import Namespace
    from types import SimpleNamespace

    from cappe.cli.plan_test import _commands

    # the second position off the model's listed ones, with more digits than %g prints: simulated where planned
    positions = [{"x": -0.6, "y": 0.4, "z": -0.2}, {"x": 0.6, "y": 1.2345678, "z": 0.2}]
    plan = SimpleNamespace(positions=positions, sensors=["head_rt:x", "spindle_nose:y"])
    args = Namespace(model="builtin:three-axis-machine-tool", modes=3, noise_frequency=0.001, noise_damping=0.05,
                     noise_shape=0.01)
    commands = _commands(args, plan, ("x", "y", "z"))
    lines = commands["simulate"].splitlines()
    assert len(lines) == 2
    assert "--reference ref1.json ref2.json " in commands["identify"]
    ref = _simulated(capsys, lines[1], tmp_path / "ref2.json")
    assert [dict(s.position) for s in ref.sets] == [positions[1]]
    assert list(ref.sensors) == plan.sensors
