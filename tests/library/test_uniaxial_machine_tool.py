"""The benchmark model ``builtin:uniaxial-machine-tool`` (issue 6, after Ellinger and Zaeh 2022, section 3.1).

Checks the file's promises: the paper's 27 unknowns with eq. 14 bounds, enough disturbable known parameters,
the four axis positions, at least 20 stable modes in 15-400 Hz at each of them, modes that move with the
axis, sensor nodes, the damping convention, the ball-screw kinematics, and that every unknown is visible to
the global sensitivity analysis. Reference numbers come from outside cappe's modal engine wherever possible:
scipy.linalg.eigh on (K, M), numpy eigenvalues of a state matrix built here, and closed forms of the nut,
screw-shaft and guide elements.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from cappe.io.modal import ModalData, ModalDataSet
from cappe.modal import ModalEngine
from cappe.model.loader import load_model
from cappe.model.numeric import NumericModel
from cappe.sensitivity import model_sobol

MODEL = "builtin:uniaxial-machine-tool"
POSITIONS = (-0.294, -0.060, 0.135, 0.330)
BAND_HZ = (15.0, 400.0)
UNKNOWNS = (
    *(f"me{i}_{s}" for i in (1, 2, 3) for s in ("kx", "ky", "kz", "bx", "bz", "dy")),
    "fb_kz", "cpl_krz", "cpl_drz", "bsd_kz", "bsd_drz", "lgs_kx", "lgs_ky", "lgs_krx", "lgs_kry",
)
LEAD = 0.020  # m, ball-screw lead written into the nut elements
FB_Z = 0.55  # m, fixed-bearing position; the screw's free length is FB_Z - z


@pytest.fixture(scope="module")
def model() -> NumericModel:
    return NumericModel(load_model(MODEL))


def _dof(model: NumericModel, label: str) -> int:
    return model.dofs.index(label)


def _undamped_hz(model: NumericModel, z: float, params: dict[str, float] | None = None) -> np.ndarray:
    system = model.system(params, {"z": z})
    lam = scipy.linalg.eigh(system.K, system.M, eigvals_only=True)
    return np.sqrt(np.clip(lam, 0.0, None)) / (2 * np.pi)


def test_the_file_declares_exactly_the_papers_27_unknowns(model):
    structure = model.structure
    unknown = [p for p in structure.parameters if p.unknown]
    assert sorted(p.name for p in unknown) == sorted(UNKNOWNS)
    assert len(unknown) == 27
    # k: stiffness, b: viscous damping, d: hysteretic damping as a loss factor
    kinds = {"k": "stiffness", "b": "damping", "d": "loss"}
    for p in unknown:
        assert p.kind == kinds[p.name.split("_")[1][0]], p.name


def test_bounds_follow_paper_eq14(model):
    for name in UNKNOWNS:
        p = model.structure.parameter(name)
        assert p.bounds is not None
        lo, hi = p.bounds
        expected = (0.7, 1.3) if p.kind == "stiffness" else (1 / 3, 3.0)
        # the file writes the bounds as decimals; 1e-12 allows only the division's round-off
        assert lo / p.value == pytest.approx(expected[0], rel=1e-12), name
        assert hi / p.value == pytest.approx(expected[1], rel=1e-12), name


def test_at_least_40_known_parameters_are_disturbable(model):
    params = model.structure.parameters
    assert sum(p.disturbable for p in params if not p.unknown) >= 40
    assert not any(p.disturbable for p in params if p.unknown)


def test_disturbable_inertias_and_stiffnesses_barely_move_the_modes(model):
    # the file's rule, checked with scipy's eigh on (K, M): a +10 % change of a disturbable mass, inertia or
    # stiffness shifts no undamped frequency below 400 Hz by more than 0.1 %, while every mass, inertia and
    # stiffness left out (the sensitive known parameters) shifts some mode by more than 0.05 %
    base = {z: _undamped_hz(model, z) for z in POSITIONS[1:]}
    shifts = {}
    for p in model.structure.parameters:
        if p.unknown or p.kind not in ("mass", "inertia", "stiffness"):
            continue
        worst = 0.0
        for z, f0 in base.items():
            band = f0 < BAND_HZ[1]
            f1 = _undamped_hz(model, z, {p.name: 1.1 * p.value})
            worst = max(worst, float(np.max(np.abs(f1[band] / f0[band] - 1))))
        shifts[p.name] = (worst, p.disturbable)
    assert {n for n, (_, d) in shifts.items() if d} >= {"J_s_xx", "m_j", "fb_kt"}
    loud = {n: s for n, (s, d) in shifts.items() if d and s > 1e-3}
    assert not loud
    quiet = {n: s for n, (s, d) in shifts.items() if not d and s < 5e-4}
    assert not quiet


def test_disturbable_damping_is_damping_of_distinct_parts(model):
    # the loss factors and viscous coefficients tagged disturbable are each used by one bed joint direction,
    # one guide shoe or one bearing/nut/bracket group, and none is a damping unknown
    params = {p.name: p for p in model.structure.parameters}
    damping = [n for n, p in params.items() if p.disturbable and p.kind in ("loss", "damping")]
    assert len(damping) >= 30
    joints = [n for n in damping if n.startswith("eta_j")]
    assert len(joints) == 17
    assert {n for n in damping if n.startswith("lgs")} == {f"lgs{s}_{d}" for s in range(1, 5) for d in ("cx", "cy")}


def test_axis_positions_and_sensor_nodes(model):
    structure = model.structure
    assert structure.axis_names == ("z",)
    assert structure.axes[0].positions == POSITIONS
    nodes = {s.name: s.body for s in structure.sensors}
    assert len(nodes) >= 20
    # spread over the bed segments, the table, the screw and the drive
    for body in ("bed1", "bed2", "bed3", "bed4", "table", "screw", "journal", "rotor", "motor"):
        assert body in nodes.values(), body
    labels, rows = model.sensor_matrix(position={"z": 0.135})
    assert len(labels) == 3 * len(nodes)
    assert {lab.split(":")[1] for lab in labels} == {"x", "y", "z"}
    # every node sees some motion of the structure
    assert np.all(np.abs(rows).reshape(len(nodes), -1).max(axis=1) > 0)


@pytest.mark.parametrize("z", POSITIONS)
def test_at_least_20_modes_between_15_and_400_hz(model, z):
    freq = _undamped_hz(model, z)
    assert freq.min() >= BAND_HZ[0]  # no free rigid-body motion, nothing below the band
    assert np.count_nonzero((freq >= BAND_HZ[0]) & (freq <= BAND_HZ[1])) >= 20
    # the batched engine finds the same frequencies as scipy's generalized eigensolver (float round-off)
    engine = ModalEngine(model, sensors="dofs")
    np.testing.assert_allclose(engine.evaluate(None, {"z": z}).frequency[0], freq, rtol=1e-8)


@pytest.mark.parametrize("z", POSITIONS)
def test_modes_are_stable_and_lightly_damped(model, z):
    system = model.system(None, {"z": z})
    n = system.M.shape[0]
    minv = np.linalg.inv(system.M)
    # state matrix with the complex (hysteretic) stiffness K + iH, built here from the model's matrices
    a = np.block([[np.zeros((n, n)), np.eye(n)], [-minv @ (system.K + 1j * system.H), -minv @ system.C]])
    lam = np.linalg.eigvals(a)
    # hysteretic damping is non-causal: only the positive-frequency branch is physical (Im > 0)
    poles = lam[lam.imag > 0]
    assert poles.size == n
    zeta = -poles.real / np.abs(poles)
    assert np.all(zeta > 0)
    freq = np.abs(poles) / (2 * np.pi)
    in_band = (freq >= BAND_HZ[0]) & (freq <= BAND_HZ[1])
    # machine-tool modes: a few tenths of a per cent to a few per cent
    assert np.all((zeta[in_band] > 0.005) & (zeta[in_band] < 0.07))
    # light damping (paper assumption A1): in the band, first-order damping ratios from the undamped shapes
    # agree with the exact ones; the nominal design keeps close mode pairs apart (worst found: 1.7 % at
    # z = 0.33, 248/252 Hz), 3 % leaves room for round-off but fails on a real damping-coupled pair
    order = np.argsort(freq)
    batch = ModalEngine(model, sensors="dofs").evaluate(None, {"z": z})
    first, band = batch.damping[0], batch.frequency[0] <= BAND_HZ[1]
    np.testing.assert_allclose(zeta[order][: first.size][band], first[band], rtol=0.03)


def test_at_least_five_modes_shift_more_than_two_percent(model):
    engine = ModalEngine(model, sensors="dofs")
    positions = [{"z": z} for z in POSITIONS]
    refs = engine.references(positions)
    tracked = np.array([engine.evaluate(None, p, track=ref).frequency[0] for p, ref in zip(positions, refs,
                                                                                               strict=True)])
    first20 = tracked[:, :20]
    shift = (first20.max(axis=0) - first20.min(axis=0)) / first20.min(axis=0)
    assert np.count_nonzero(shift > 0.02) >= 5
    # independent of the tracking: the k-th lowest frequency itself moves by more than 2 % for >= 5 ranks
    ranked = np.array([_undamped_hz(model, z)[:20] for z in POSITIONS])
    ranked_shift = (ranked.max(axis=0) - ranked.min(axis=0)) / ranked.min(axis=0)
    assert np.count_nonzero(ranked_shift > 0.02) >= 5


def test_hysteretic_damping_is_a_loss_factor_times_the_stiffness(model):
    z = {"z": 0.135}
    p = model.structure.nominal
    h_nominal = model.matrices(model.vector(None), z)["H"]
    h_without = model.matrices(model.vector({"cpl_drz": 0.0}), z)["H"]
    rotor, journal = _dof(model, "rotor.rz"), _dof(model, "journal.rz")
    row = np.zeros(model.n_dof)
    row[rotor], row[journal] = 1.0, -1.0  # coupling twist: rotor rotation minus journal rotation
    expected = p["cpl_drz"] * p["cpl_krz"] * np.outer(row, row)
    np.testing.assert_allclose(h_nominal - h_without, expected, rtol=1e-12, atol=1e-9)
    # b parameters feed viscous sources, d parameters hysteretic ones
    sources = model.damping_sources(None, z)
    for name in UNKNOWNS:
        if name.split("_")[1][0] == "k":
            continue
        column = model.parameter_names.index(name)
        fed = np.flatnonzero(sources.jacobian[0, :, column])
        assert fed.size > 0, name
        want = "viscous" if name.split("_")[1][0] == "b" else "hysteretic"
        assert {sources.kinds[j] for j in fed} == {want}, name


def test_modal_damping_is_linear_in_the_damping_unknowns(model):
    # paper eq. 12: zeta = sum q p; first-order damping ratios are exactly affine in each b and d
    engine = ModalEngine(model, sensors="dofs")
    p = model.structure.nominal
    for name in ("me2_bz", "me1_dy", "cpl_drz", "bsd_drz"):
        batch = model.vector(None)[None, :].repeat(3, axis=0)
        batch[:, model.parameter_names.index(name)] = [0.0, p[name], 2 * p[name]]
        zeta = engine.evaluate(batch, {"z": -0.06}).damping
        np.testing.assert_allclose(zeta[2] - zeta[1], zeta[1] - zeta[0], rtol=1e-8, atol=1e-12)
        assert np.max(zeta[1] - zeta[0]) > 1e-4, name  # and each one damps some mode noticeably


@pytest.mark.parametrize("z", POSITIONS)
def test_ball_screw_nut_and_shaft_follow_the_closed_forms(model, z):
    p = model.structure.nominal
    k = model.matrices(model.vector(None), {"z": z})["K"]
    tz, ty, sz, srz, jz = (_dof(model, d) for d in ("table.z", "table.y", "screw.z", "screw.rz", "journal.z"))
    ratio = LEAD / (2 * np.pi)  # axial travel per radian
    # the two helix elements make the nut one axial spring knut on (table z - screw z + lead/(2 pi) screw rz)
    assert k[tz, tz] == pytest.approx(p["knut"], rel=1e-12)
    assert abs(k[tz, srz]) == pytest.approx(p["knut"] * ratio, rel=1e-12)
    assert k[ty, srz] == pytest.approx(0.0, abs=1e-6 * p["knut"] * ratio)  # lateral terms cancel
    # screw rotation: nut through the lead plus the shaft torsion over the free length 0.55 - z
    free = FB_Z - z
    torsion = p["bsd_ktz"] * FB_Z / free
    assert k[srz, srz] == pytest.approx(p["knut"] * ratio**2 + torsion, rel=1e-12)
    # shaft axial stiffness between journal (fixed bearing) and screw: bsd_kz L0 / L
    assert -k[jz, sz] == pytest.approx(p["bsd_kz"] * FB_Z / free, rel=1e-12)


@pytest.mark.parametrize("z", POSITIONS)
def test_guide_shoe_weights_are_a_partition_of_unity(model, z):
    # vertical stiffness on the table: four shoes, each split over the three segments it can reach with hat
    # weights that sum to 1 (plus a 1e-6 floor per element), the nut's radial spring and the helix tilt
    # tan(alpha)^2 knut; a weight missing or counted twice would be off by tens of per cent
    p = model.structure.nominal
    k = model.matrices(model.vector(None), {"z": z})["K"]
    ty = _dof(model, "table.y")
    assert sum(e.body_b == "table" and e.name.startswith("shoe") for e in model.structure.elements) == 12
    tilt = (LEAD / (2 * np.pi * 0.02)) ** 2 * p["knut"]
    expected = 4 * p["lgs_ky"] * (1 + 3e-6) + p["knut_r"] + tilt
    assert k[ty, ty] == pytest.approx(expected, rel=1e-12)


@pytest.fixture(scope="module")
def reference(model) -> ModalData:
    """The model's own lowest 20 modes (tracked) at the four positions, simulated at nominal values."""
    data = ModalEngine(model, sensors=None).modal_data([{"z": z} for z in POSITIONS])
    sets = tuple(ModalDataSet(s.position, s.frequency[:20], s.damping[:20], s.shapes[:, :20]) for s in data.sets)
    return ModalData(data.sensors, sets)


@pytest.mark.slow
def test_every_unknown_is_visible_to_the_sensitivity_analysis(model, reference):
    # paper section 3.2: one GSA per mode x position x criterion; a parameter with no total index >= 1 %
    # anywhere could not be identified. n = 64 keeps this short; at n = 2048 the weakest unknown still reaches
    # about 0.15 (see the map in the model's source text), far above the sampling noise at this n.
    assert len(reference.sensors) >= 60
    res = model_sobol(model, reference, n=64, rng=11, criteria=("macxp", "ndd2"))
    assert set(res.names) == set(UNKNOWNS)
    best = np.nanmax(res.sobol.ST, axis=0)
    weak = [name for name, value in zip(res.names, best, strict=True) if not value >= 0.01]
    assert not weak
    # stiffness shows in the mode shapes (MACXP), the damping unknowns in the damping (NDD^2)
    crit = np.array(res.criteria)
    for j, name in enumerate(res.names):
        strongest = crit[np.nanargmax(res.sobol.ST[:, j])]
        if name.split("_")[1][0] in "bd":
            assert strongest == "ndd2", name
