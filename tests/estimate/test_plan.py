"""Test planning (cappe.estimate._plan): the Fisher matrix against finite differences of an independent eigen
solve, the chosen plan against random plans of the same size, and undetermined unknowns named.

The independent reference: M, C, K, H of ``NumericModel.matrices`` (what ``cappe model matrices`` prints) at
perturbed parameters, solved with ``scipy.linalg.eigh``, modes followed by MAC, energy damping ratios
``phi^T C phi / 2 omega + phi^T H phi / 2 omega^2`` and unit sensor shapes written out here from the noise model of
``cappe simulate`` -- no cappe modal or derivative code.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from cappe.estimate._plan import PlanCandidates, plan_test
from cappe.model import NumericModel, load_model

UNKNOWNS = ["me1_kx", "me2_kz", "lgs_kx", "lgs_krx", "cpl_krz", "me1_dy", "bsd_drz"]
SENSORS = ["table_fl:x", "table_fl:y", "nut:x", "rotor:y", "bed1_l:x", "me1_node:z", "journal:y"]
NOISE = (0.005, 0.05, 0.02)


@pytest.fixture(scope="module")
def machine() -> NumericModel:
    return NumericModel(load_model("builtin:uniaxial-machine-tool"))


def _modes(nm: NumericModel, values: dict[str, float], position: dict[str, float], rows: np.ndarray, m: int):
    mats = nm.matrices(values, position)
    lam, phi = scipy.linalg.eigh(mats["K"], mats["M"])  # mass-normalized
    omega = np.sqrt(lam[:m])
    phi = phi[:, :m]
    zeta = (np.einsum("ir,ij,jr->r", phi, mats["C"], phi) / (2 * omega)
            + np.einsum("ir,ij,jr->r", phi, mats["H"], phi) / (2 * omega**2))
    return omega / (2 * np.pi), zeta, phi, rows @ phi


def _observations(freq, zeta, shapes, ref_shapes):
    """Noise-normalized observations: log f / s_f, log zeta / s_z, unit shapes (signed like the reference) / noise."""
    x = shapes / np.linalg.norm(shapes, axis=0)
    ref = ref_shapes / np.linalg.norm(ref_shapes, axis=0)
    x = x * np.sign(np.sum(x * ref, axis=0))
    noise_x = NOISE[2] * np.max(np.abs(ref), axis=0) / np.sqrt(2)
    return np.concatenate([np.log(freq) / NOISE[0], np.log(zeta) / NOISE[1], (x / noise_x).T.ravel()])


def test_fisher_matches_finite_differences_of_scipy_eigh(machine):
    position = {"z": 0.135}
    m = 8
    cands = PlanCandidates.from_model(machine, unknowns=UNKNOWNS, positions=[position], sensors=SENSORS, n_modes=m,
                                      noise=NOISE, visibility=0.0)
    rows = np.array(machine.sensor_matrix(position=position)[1])
    labels = machine.sensor_matrix(position=position)[0]
    rows = rows[[labels.index(s) for s in cands.sensors]]
    nominal = {p.name: p.value for p in machine.structure.parameters}
    f0, z0, phi0, s0 = _modes(machine, nominal, position, rows, m)
    assert np.allclose(f0, cands.frequency[0], rtol=1e-9)
    mass = machine.matrices(nominal, position)["M"]
    columns = []
    h = 1e-5
    for name in UNKNOWNS:
        obs = []
        for sign in (+1, -1):
            values = dict(nominal, **{name: nominal[name] * np.exp(sign * h)})
            f, z, phi, s = _modes(machine, values, position, rows, m)
            order = np.argmax(np.abs(phi0.T @ mass @ phi), axis=1)  # follow each nominal mode by MAC
            obs.append(_observations(f[order], z[order], s[:, order], s0))
        columns.append((obs[0] - obs[1]) / (2 * h))
    jac_fd = np.column_stack(columns)
    fisher_fd = jac_fd.T @ jac_fd
    fisher = cands.fisher([0], list(range(len(cands.sensors))))
    scale = np.sqrt(np.outer(np.diag(fisher_fd), np.diag(fisher_fd)))
    assert np.max(np.abs(fisher - fisher_fd) / scale) < 1e-4
    # each block on its own: the frequency rows alone, the damping rows alone
    jac = cands.jacobian([0], list(range(len(cands.sensors))))
    np.testing.assert_allclose(jac[:m], jac_fd[:m], rtol=1e-5, atol=1e-4 * np.abs(jac_fd[:m]).max())
    np.testing.assert_allclose(jac[m:2 * m], jac_fd[m:2 * m], rtol=1e-5, atol=1e-4 * np.abs(jac_fd[m:2 * m]).max())


def test_chosen_plan_beats_random_plans_of_the_same_size(machine):
    nodes = ["bed1_l", "bed4_r", "me1_node", "me2_node", "table_fl", "table_rr", "nut", "screw_fb", "rotor", "journal"]
    cands = PlanCandidates.from_model(machine, n_modes=12, sensors=nodes, noise=NOISE)
    assert len(cands.sensors) == 30
    assert len(cands.positions) == 4
    plan = plan_test(candidates=cands, n_positions=2, n_sensors=6, n_random=10, rng=3)
    random = plan.random
    assert len(random["criterion"]) == 10
    assert plan.criterion > max(random["criterion"])
    # D-optimality is the geometric mean of the std over the determined directions: smaller than every random plan's
    rng = np.random.default_rng(3)
    for _ in range(10):
        rp = sorted(rng.choice(len(cands.positions), 2, replace=False).tolist())
        rs = sorted(rng.choice(len(cands.sensors), 6, replace=False).tolist())
        fisher = cands.fisher(rp, rs)
        assert np.linalg.slogdet(fisher + 1e-6 * np.eye(fisher.shape[0]))[1] < plan.criterion
    # and the expected std: its median over the unknowns is below the median of the random plans' medians
    assert np.median(plan.relative_std) < np.median(random["median_relative_std"])


def test_cached_blocks_equal_the_jacobian_form(machine):
    # the search's per-position blocks (sufficient statistics per channel) against the Fisher matrix built from the
    # plan's Jacobian rows (checked above against scipy's eigh); sets of one channel (no shape information), a set
    # that leaves some modes unseen, and large sets
    from cappe.estimate._plan import _FisherCache

    cands = PlanCandidates.from_model(machine, n_modes=12, noise=NOISE, visibility=0.3)
    cache = _FisherCache(cands)
    rng = np.random.default_rng(5)
    n_ch = len(cands.sensors)
    for size in (1, 2, 3, 7, 40, n_ch):
        positions = sorted(rng.choice(len(cands.positions), 2, replace=False).tolist())
        sensors = sorted(rng.choice(n_ch, size, replace=False).tolist())
        reference = cands.fisher(positions, sensors)
        cached = sum(cache.block(j, sensors) for j in positions)
        # rounding only: the two forms sum the same products in another order
        np.testing.assert_allclose(cached, reference, rtol=0, atol=1e-11 * np.abs(reference).max())
        base = sensors[:-1]
        rest = sorted(set(range(n_ch)) - set(base))
        adds = rng.choice(rest, min(5, len(rest)), replace=False).tolist()
        batch = cache.added(positions[0], base, adds)
        for i, block in zip(adds, batch, strict=True):
            ref = cands.fisher(positions[:1], sorted({*base, i}))
            np.testing.assert_allclose(block, ref, rtol=0, atol=1e-11 * max(np.abs(ref).max(), 1.0))


def test_search_adds_cached_blocks_and_leaves_no_improving_swap(machine, monkeypatch):
    # the search builds no Jacobian per trial plan (it did: ~3 000 for this plan, 9 min on the three-axis machine);
    # its plan is still a local optimum of the reference criterion: no single swap of a position or channel helps
    cands = PlanCandidates.from_model(machine, n_modes=12, noise=NOISE)
    calls = []
    jacobian = PlanCandidates.jacobian

    def counted(self, positions, sensors):
        calls.append(1)
        return jacobian(self, positions, sensors)

    monkeypatch.setattr(PlanCandidates, "jacobian", counted)
    plan = plan_test(candidates=cands, n_positions=2, n_sensors=8, n_random=0)
    assert len(calls) <= 3  # the plan's uncertainty, every candidate's, and the plan's criterion
    monkeypatch.undo()
    pos, sens = list(plan.position_index), list(plan.sensor_index)
    best = cands.criterion(pos, sens)
    assert np.isclose(plan.criterion, best, rtol=1e-12)
    tol = 1e-9 * abs(best)
    for k in range(len(pos)):
        for j in set(range(len(cands.positions))) - set(pos):
            assert cands.criterion([*pos[:k], j, *pos[k + 1:]], sens) <= best + tol
    for k in range(len(sens)):
        for i in set(range(len(cands.sensors))) - set(sens):
            assert cands.criterion(pos, [*sens[:k], i, *sens[k + 1:]]) <= best + tol


def test_undetermined_scale_is_named():
    # two-mass rig: scaling every mass, stiffness and damping together changes no frequency, damping ratio or unit
    # shape -- no plan determines any of them, and the combination says so
    nm = NumericModel(load_model("builtin:two-mass-rig"))
    names = ["m1", "m2", "k11", "k12", "k22", "c11", "c22"]
    cands = PlanCandidates.from_model(nm, unknowns=names, n_modes=2)
    plan = plan_test(candidates=cands, n_positions=1, n_sensors=2, n_random=0)
    assert plan.uncertainty.rank == len(names) - 1
    assert set(plan.undetermined) == set(names)
    assert set(plan.undetermined_with_all) == set(names)
    assert len(plan.uncertainty.combinations) == 1
    # with the masses known, all five are determined
    known = plan_test(candidates=PlanCandidates.from_model(nm, unknowns=names[2:], n_modes=2), n_positions=1,
                      n_sensors=2, n_random=0)
    assert known.undetermined == []
    assert np.all(known.relative_std < 0.1)


def test_plan_file_contract(machine):
    cands = PlanCandidates.from_model(machine, unknowns=UNKNOWNS, sensors=SENSORS, n_modes=8)
    doc = plan_test(candidates=cands, n_positions=2, n_sensors=3, n_random=2).to_dict()
    assert doc["format"] == "cappe.plan/1"
    assert len(doc["positions"]) == 2
    assert set(doc["positions"][0]) == {"z"}
    assert len(doc["sensors"]) == 3
    assert all(s in SENSORS for s in doc["sensors"])
    assert set(doc["unknowns"]) == set(UNKNOWNS)
    assert doc["noise"] == {"frequency": 0.005, "damping": 0.05, "shape": 0.02}
