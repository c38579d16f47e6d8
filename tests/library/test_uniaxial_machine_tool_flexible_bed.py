"""``builtin:uniaxial-machine-tool-flexible-bed``: the machine tool with its bed a reduced FE model (issue 23).

References from outside the reduced model: the rigid variant's file (the same unknowns, bounds, sensors, inputs and
outputs), a rigid translation of the reduced bed (its mass, numpy), the same machine with the full, unreduced
frame of the bed (Craig-Bampton against the full FE model), and the truth of a simulated reference that
``cappe identify`` never sees.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg

from cappe.cli import main
from cappe.correlate import mac
from cappe.estimate import AutomatedIdentification, ParameterSpace
from cappe.library import builtin_path
from cappe.modal import modal_batch, reference_modes, sensor_coordinates
from cappe.model import NumericModel, load_model
from cappe.model.loader import structure_from_yaml

MODEL = "builtin:uniaxial-machine-tool-flexible-bed"


@pytest.fixture(scope="module")
def machine() -> NumericModel:
    return NumericModel(load_model(MODEL))


def test_same_unknowns_bounds_sensors_inputs_and_outputs_as_the_rigid_variant(machine):
    rigid = load_model("builtin:uniaxial-machine-tool")
    flexible = machine.structure
    unknown = {p.name: p.bounds for p in rigid.parameters if p.unknown}
    assert len(unknown) == 27
    assert {p.name: p.bounds for p in flexible.parameters if p.unknown} == unknown
    assert [s.name for s in flexible.sensors] == [s.name for s in rigid.sensors]
    assert [i.name for i in flexible.inputs] == [i.name for i in rigid.inputs]
    assert [o.name for o in flexible.outputs] == [o.name for o in rigid.outputs]
    assert [a.positions for a in flexible.axes] == [a.positions for a in rigid.axes]
    # the bed's sensors sit where the rigid variant's do (global coordinates)
    for z in (-0.294, 0.33):
        ours, theirs = sensor_coordinates(flexible, position={"z": z}), sensor_coordinates(rigid, position={"z": z})
        assert ours.keys() == theirs.keys()
        for name, point in ours.items():
            np.testing.assert_allclose(point, theirs[name], atol=1e-12, err_msg=name)


def test_bed_is_a_craig_bampton_frame_of_2000_kg(machine):
    bed = machine.structure.flexible_body("bed")
    assert bed.n_dof == 100
    # a rigid translation of the bed: every interface node's translation 1 along x, no fixed-interface modal
    # amplitude (Craig-Bampton's constraint modes carry rigid motions exactly); its kinetic mass is the bed's
    u = np.zeros(bed.n_dof)
    for node in bed.nodes:
        u[node.row("x")] = 1.0
    assert u @ bed.mass @ u == pytest.approx(2000.0, rel=0.01)  # about 1910 kg of spine and 90 kg of ribs
    np.testing.assert_allclose(bed.stiffness @ u, 0.0, atol=1e-6 * abs(bed.stiffness).max())


def _full_frame_machine() -> NumericModel:
    """The same machine with the bed's full frame (318 DOFs, no reduction): every recovered node an interface
    node."""
    text = builtin_path(MODEL[len("builtin:"):]).read_text()
    head, rest = text.split("    recovery:\n      nodes:\n")
    recovered, tail = rest.split("    lines:\n")
    assert "reduction: {band: 400, multiple: 3}\n" in tail
    tail = tail.replace("    reduction: {band: 400, multiple: 3}\n", "")
    recovered = "".join(line[2:] + "\n" for line in recovered.splitlines())  # into the interface nodes' list
    return NumericModel(structure_from_yaml(head + recovered + "    lines:\n" + tail, "full-frame"))


@pytest.mark.slow
def test_reduced_bed_matches_the_full_frame_in_the_machine(machine):
    full = _full_frame_machine()
    assert full.n_dof == 121 - 100 + 318
    for z in (-0.294, 0.33):
        reduced = modal_batch(machine, position={"z": z}, n_modes=20)
        exact = modal_batch(full, position={"z": z}, n_modes=20)
        # the criterion for a Craig-Bampton model against its full FE model: 0.5 %, MAC 0.99
        np.testing.assert_allclose(reduced.frequency, exact.frequency, rtol=5e-3)
        shapes = np.abs(np.diagonal(mac(reduced.shapes[0], exact.shapes[0])))
        assert shapes.min() >= 0.99, shapes


def test_moving_shoes_are_continuous_over_the_travel(machine):
    # the shoes slide from rail station to rail station: no jump where a shoe passes a station (z +- 0.13 = -0.145)
    z0 = -0.145 + 0.13
    lo = modal_batch(machine, position={"z": z0 - 1e-6}, n_modes=20).frequency[0]
    hi = modal_batch(machine, position={"z": z0 + 1e-6}, n_modes=20).frequency[0]
    far = modal_batch(machine, position={"z": z0 + 1e-2}, n_modes=20).frequency[0]
    np.testing.assert_allclose(lo, hi, rtol=1e-5)
    assert np.abs(far - lo).max() > 1e3 * np.abs(hi - lo).max()


def _undamped_hz(model: NumericModel, z: float) -> np.ndarray:
    system = model.system(None, {"z": z})
    lam = scipy.linalg.eigh(system.K, system.M, eigvals_only=True)
    return np.sqrt(np.clip(lam, 0.0, None)) / (2 * np.pi)


@pytest.mark.parametrize("z", [-0.294, -0.060, 0.135, 0.330])
def test_twenty_modes_from_15_hz_to_about_400_hz(machine, z):
    freq = _undamped_hz(machine, z)  # scipy on the assembled (K, M), not the modal engine
    assert freq[0] > 15.0
    assert 350.0 < freq[19] < 420.0  # 357-405 Hz over the four positions


def _random_truth(space: ParameterSpace, seed: int) -> dict[str, float]:
    rng = np.random.default_rng(seed)
    return space.mapping(space.lower * (space.upper / space.lower) ** rng.uniform(size=space.n))


def test_ideal_case_stiffness_within_1_percent_on_a_subset(machine):
    """The contract of the extended test below, on five unknowns (three stiffnesses the bed's flexibility
    couples with: the shoes' and the front mount's, and two damping ones), three positions, small designs."""
    unknowns = ["lgs_kx", "lgs_ky", "me1_ky", "me1_dy", "cpl_drz"]
    space = ParameterSpace.from_model(machine, unknowns)
    truth = _random_truth(space, 5)
    params = machine.structure.resolve_parameters(truth)
    reference = reference_modes(machine, params=params, positions=[{"z": -0.294}, {"z": 0.135}, {"z": 0.33}],
                                n_modes=12)
    est = AutomatedIdentification(machine, unknowns=unknowns, n_gsa=32, n_opt=4, validation={"z": -0.294},
                                  rng=5, n_permutations=0).fit(reference, truth=truth)
    errors = est.estimate_.relative_error(truth)
    assert max(abs(errors[n]) for n in ("lgs_kx", "lgs_ky", "me1_ky")) < 0.01, errors
    assert max(abs(errors[n]) for n in ("me1_dy", "cpl_drz")) < 0.05, errors


@pytest.mark.slow
@pytest.mark.extended(reason=(
    "one full identification of the 121-DOF machine (about 2 CPU-minutes); its contract is covered by "
    "test_ideal_case_stiffness_within_1_percent_on_a_subset"))
def test_cappe_identify_ideal_case_all_stiffness_within_1_percent(machine, tmp_path: Path, capsys):
    truth = _random_truth(ParameterSpace.from_model(machine), 1)
    (tmp_path / "truth.json").write_text(json.dumps(truth))
    assert main(["simulate", MODEL, "--params", str(tmp_path / "truth.json"), "--positions", "all", "--modes", "20",
                 "-o", str(tmp_path / "ref.json")]) == 0
    assert main(["identify", MODEL, "--reference", str(tmp_path / "ref.json"), "--truth",
                 str(tmp_path / "truth.json"), "--n-gsa", "256", "--n-opt", "20", "--permutations", "0",
                 "-o", str(tmp_path / "result.json")]) == 0
    capsys.readouterr()
    result = json.loads((tmp_path / "result.json").read_text())
    kinds = {p.name: p.kind for p in machine.structure.parameters}
    stiffness = {n: result["parameters"][n] / truth[n] - 1 for n in truth if kinds[n] == "stiffness"}
    damping = {n: result["parameters"][n] / truth[n] - 1 for n in truth if kinds[n] != "stiffness"}
    assert len(stiffness) == 16
    assert max(abs(e) for e in stiffness.values()) < 0.01, stiffness
    assert max(abs(e) for e in damping.values()) < 0.05, damping
