"""``cappe study --position``: reaches the simulation and the estimators that take a position, refused elsewhere."""

from __future__ import annotations

import json

from cappe.cli import main


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


SLIDE = """\
format: cappe.model/1
name: slide
parameters:
  - {name: m, value: 5.0, kind: mass}
  - {name: k, value: 1.0e6, kind: stiffness, bounds: [1.0e5, 1.0e7], unknown: true}
axes:
  - {name: y, positions: [-0.1, 0.2]}
bodies:
  - {name: table, mass: m, inertia: {xx: 0.05, yy: 0.05, zz: 0.05}, dofs: [z, rx]}
elements:
  - {name: a, bodies: [ground, table], at: [0, -0.3, 0], stiffness: {z: 2.0e6}, damping: {z: 20.0}}
  - {name: b, bodies: [ground, table], at: [0, y, 0], stiffness: {z: k}, damping: {z: 20.0}}
sensors:
  - {name: tip, body: table, point: [0, 0.1, 0]}
inputs:
  - {name: F, body: table, point: [0, 0.1, 0], direction: z}
outputs:
  - {name: d, quantity: displacement, body: table, point: [0, 0.1, 0], direction: z}
"""


def test_study_position_is_used_or_refused(capsys, tmp_path):
    model = tmp_path / "slide.yaml"
    model.write_text(SLIDE)
    code, out, err = run(capsys, "study", model, "--method", "one-step-frf", "--noise", "0", "--seeds", 1, "--duration", 2,
                         "--position", "y=0.2", "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["position"] == {"y": 0.2}  # before: parsed and dropped, the study ran at y = -0.1
    code, out, err = run(capsys, "study", model, "--method", "one-step-frf", "--noise", "0", "--seeds", 1, "--duration", 2,
                         "--position", "y=0.2")
    assert code == 0, err
    assert "1 runs per noise level at y=0.2" in out
    code, _, err = run(capsys, "study", model, "--method", "modal", "--position", "y=0.2")
    assert code == 2
    assert "--position does not apply to method 'modal': its reference data carry the axis position" in err
