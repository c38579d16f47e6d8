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


#: the rigid variant's rule for disturbable known parameters (its file; paper 3.3): +10 % of the parameter alone moves
#: no stiffness unknown by more than 1.2 % in the linearised least-squares fit of the 16 stiffness unknowns to the
#: exact modes at z2..z4, and a mass, inertia or stiffness shifts no undamped frequency below 400 Hz by more than 0.1 %
FIT_LIMIT, SHIFT_LIMIT = 0.012, 1e-3


def _fit_bias(machine: NumericModel) -> dict[str, tuple[float, str]]:
    """Per known parameter, the largest relative change of a stiffness unknown (and which) in the linearised fit:
    exact modes at z2..z4 (20 tracked modes: frequencies relative, complex shapes at the 81 channels divided by
    each nominal shape's largest entry), the unknowns' Jacobian by central differences (+-1e-4 relative)."""
    from cappe.modal import ModalEngine

    names = list(machine.parameter_names)
    stiffness = [p.name for p in machine.structure.parameters if p.unknown and p.kind == "stiffness"]
    known = [p.name for p in machine.structure.parameters if not p.unknown]
    step = 1e-4
    rows = [machine.nominal.copy()]
    for name in stiffness:
        for sign in (1, -1):
            rows.append(machine.nominal.copy())
            rows[-1][names.index(name)] *= 1 + sign * step
    for name in known:
        rows.append(machine.nominal.copy())
        rows[-1][names.index(name)] *= 1.1
    params = np.array(rows)
    engine = ModalEngine(machine, n_modes=20, n_workers=1)
    parts = []
    for z in POSITIONS_FIT:
        batch = engine.evaluate(params, {"z": z}, track=engine.reference(None, {"z": z}), exact=True)
        freq = np.abs(batch.poles) / np.abs(batch.poles[0]) - 1
        shapes = batch.complex_shapes[0]
        largest = shapes[np.argmax(np.abs(shapes), axis=0), np.arange(shapes.shape[1])]
        # each shape turned to the nominal one's phase (a mode's sign is arbitrary: eigh may flip it)
        turn = np.einsum("bsm,sm->bm", batch.complex_shapes.conj(), shapes)
        change = (batch.complex_shapes * (turn / np.abs(turn))[:, None, :] - shapes) / largest
        parts.append(np.hstack([freq, change.real.reshape(len(params), -1), change.imag.reshape(len(params), -1)]))
    features = np.hstack(parts)
    n_s = len(stiffness)
    jacobian = (features[1:1 + 2 * n_s:2] - features[2:2 + 2 * n_s:2]).T / (2 * step)
    bias = -np.linalg.pinv(jacobian) @ features[1 + 2 * n_s:].T  # (n_stiffness, n_known)
    worst = np.argmax(np.abs(bias), axis=0)
    return {name: (float(abs(bias[worst[j], j])), stiffness[worst[j]]) for j, name in enumerate(known)}


POSITIONS_FIT = (-0.060, 0.135, 0.330)


@pytest.mark.slow
def test_disturbable_known_parameters_follow_the_rigid_variants_rule(machine):
    # The rigid variant's tags were copied here unchecked. The same linearisation on the rigid variant gives its
    # file's 40 tags (eta_j1_rz out at 1.20 % where its file says 1.3 %; brake_eta in at 0.91 %, left out there).
    # Here the 23 copied tags pass, and so do eta_bed (0.86 %: the bed's loss factor, in place of the rigid bed's 18
    # joint loss factors) and fb_kr (0.70 %; 5.3 % on the rigid variant): 25 in all.
    bias = _fit_bias(machine)
    params = machine.structure.parameters
    disturbable = {p.name for p in params if p.disturbable}
    assert not any(p.disturbable for p in params if p.unknown)
    assert len(disturbable) == 25
    for p in params:
        if p.unknown:
            continue
        shift = 0.0
        if p.kind in ("mass", "inertia", "stiffness"):  # scipy's eigh on (K, M), not the modal engine
            for z in POSITIONS_FIT:
                f0 = _undamped_hz(machine, z)
                system = machine.system({p.name: 1.1 * p.value}, {"z": z})
                f1 = np.sqrt(np.clip(scipy.linalg.eigh(system.K, system.M, eigvals_only=True), 0, None)) / (2 * np.pi)
                band = f0 < 400.0
                shift = max(shift, float(np.max(np.abs(f1[band] / f0[band] - 1))))
        passes = bias[p.name][0] <= FIT_LIMIT and shift <= SHIFT_LIMIT
        assert passes == p.disturbable, (p.name, bias[p.name], shift)


def test_disturb_perturbs_the_tagged_parameters_only(tmp_path: Path, capsys):
    # `cappe simulate --disturb` on this model (paper 3.3): each disturbable parameter off by +-10 %, the rest nominal
    assert main(["simulate", MODEL, "--disturb", "0.1", "--seed", "3", "--modes", "3", "--json",
                 "-o", str(tmp_path / "ref.json")]) == 0
    values = json.loads(capsys.readouterr().out)["parameters"]  # the values that differ from the file's
    structure = load_model(MODEL)
    assert set(values) == {p.name for p in structure.parameters if p.disturbable}
    for name, value in values.items():
        nominal = structure.parameter(name).value
        assert value in (pytest.approx(0.9 * nominal, rel=1e-15), pytest.approx(1.1 * nominal, rel=1e-15)), name
