"""Batched modal engine against the per-sample reference (MechanicalSystem), determinism, errors."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse as sps

from cappe.exceptions import ModelError
from cappe.modal import ModalEngine, modal_batch
from cappe.model import NumericModel, StructureBuilder, load_model


def random_params(model: NumericModel, n: int, seed: int, spread: float = 0.3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return model.nominal * rng.uniform(1 - spread, 1 + spread, size=(n, model.nominal.size))


def align_signs(shapes: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Flip each column of ``shapes`` (n, m) to point the same way as ``reference``."""
    sign = np.sign(np.sum(shapes * reference, axis=0))
    return shapes * np.where(sign == 0, 1.0, sign)


@pytest.mark.parametrize("fixture", ["spindle", "slide"])
def test_batch_matches_per_sample_first_order_modes(fixture, request):
    structure = request.getfixturevalue(fixture)
    model = NumericModel(structure)
    engine = ModalEngine(model, sensors="dofs", n_workers=1)
    params = random_params(model, 6, seed=1)
    position = {"z": 0.25} if model.axis_names else None
    batch = engine.evaluate(params, position)
    for b, p in enumerate(params):
        ref = model.system(p, position).modes("first-order")
        # both solve the same symmetric-definite problem in double precision: agreement to round-off
        np.testing.assert_allclose(batch.frequency[b], ref.frequency, rtol=1e-10)
        np.testing.assert_allclose(batch.damping[b], ref.damping, rtol=1e-8, atol=1e-14)
        np.testing.assert_allclose(align_signs(batch.shapes[b], ref.shapes), ref.shapes, atol=1e-8 * np.abs(ref.shapes).max())


def test_exact_poles_match_the_state_space_eigenvalues(slide):
    model = NumericModel(slide)
    engine = ModalEngine(model, sensors="dofs")
    params = random_params(model, 4, seed=2)
    batch = engine.evaluate(params, {"z": 0.4}, exact=True)
    for b, p in enumerate(params):
        ref = model.system(p, {"z": 0.4}).modes("exact")
        # the pairing may order near-equal modes differently; compare the sets of poles
        np.testing.assert_allclose(np.sort_complex(batch.poles[b]), np.sort_complex(ref.poles), rtol=1e-9)
        # complex shapes are scaled so that phi^T M psi = 1 with their real mode
        mass = model.matrices(p, {"z": 0.4}, names=("M",))["M"]
        full = engine.evaluate(p, {"z": 0.4}, full_shapes=True).full_shapes[0]
        np.testing.assert_allclose(np.einsum("ir,ij,jr->r", full, mass, batch.complex_shapes[b]), 1.0, rtol=1e-9)


def test_light_damping_exact_and_first_order_agree(spindle):
    """DESIGN 3: the first-order damping ratios approximate the exact ones for light damping."""
    batch = modal_batch(spindle, exact=True)
    exact_zeta = -batch.poles.real / np.abs(batch.poles)
    # spindle damping ratios are 1-5 %; first-order error is O(zeta^2) relative, plus modal coupling
    np.testing.assert_allclose(batch.damping, exact_zeta, rtol=0.1)
    np.testing.assert_allclose(batch.frequency, np.abs(batch.poles) / (2 * np.pi), rtol=2e-3)


def test_results_do_not_depend_on_batch_size_chunking_or_threads(slide):
    model = NumericModel(slide)
    params = random_params(model, 37, seed=3)
    kwargs = {"exact": True, "contributions": True, "track": True}
    position = {"z": 0.1}
    one = ModalEngine(model, chunk_size=256, n_workers=1).evaluate(params, position, **kwargs)
    many = ModalEngine(model, chunk_size=5, n_workers=2).evaluate(params, position, **kwargs)
    single = [ModalEngine(model, chunk_size=1, n_workers=1).evaluate(p, position, **kwargs) for p in params[:7]]
    for name in ("frequency", "damping", "shapes", "poles", "complex_shapes", "contributions", "damping_gradient",
                 "mode_index", "tracking_mac"):
        np.testing.assert_array_equal(getattr(one, name), getattr(many, name), err_msg=name)
        np.testing.assert_array_equal(getattr(one, name)[:7], np.concatenate([getattr(s, name) for s in single]),
                                      err_msg=name)


def test_constant_and_varying_mass_give_identical_bits(spindle):
    """Samples that share M and samples whose M varies, mixed in one chunk or split over chunks of their own,
    come out bit for bit the same (the mass reduction must not depend on what else is in the chunk)."""
    model = NumericModel(spindle)
    params = random_params(model, 8, seed=4)
    mass_names = [p.name for p in spindle.parameters if p.kind in ("mass", "inertia")]
    fixed = params.copy()
    for name in mass_names:
        fixed[:, model.parameter_names.index(name)] = model.nominal[model.parameter_names.index(name)]
    mixed = np.vstack([fixed, params])
    engine = ModalEngine(model, chunk_size=64, n_workers=1)
    a = engine.evaluate(mixed)
    b = ModalEngine(model, chunk_size=8, n_workers=1).evaluate(mixed)
    np.testing.assert_array_equal(a.frequency, b.frequency)
    np.testing.assert_array_equal(a.shapes, b.shapes)


def test_damping_contributions_sum_and_reproduce_eq12(slide):
    model = NumericModel(slide)
    params = random_params(model, 5, seed=5)
    batch = ModalEngine(model).evaluate(params, {"z": 0.25}, contributions=True)
    np.testing.assert_allclose(batch.contributions.sum(axis=2), batch.damping, rtol=1e-12)
    names, per_element = batch.element_contributions()
    assert names == ("mount0", "mount1", "mount2", "shoe0", "shoe1", "drive")
    np.testing.assert_allclose(per_element.sum(axis=2), batch.damping, rtol=1e-12)
    # eq. 12/13: zeta = Q p over the damping parameters cm, cg and the loss factor eta (zeta is linear in each,
    # with no other damping in the model), so Q @ p reproduces zeta exactly
    idx = [model.parameter_names.index(n) for n in ("cm", "cg", "eta")]
    q = batch.damping_gradient[:, :, idx]
    np.testing.assert_allclose(np.einsum("bmp,bp->bm", q, params[:, idx]), batch.damping, rtol=1e-10)
    # at fixed shapes only the parameters in the damping coefficients (c, eta * k) enter Q: masses and inertias
    # do not, while the hysteretic coefficients eta * kmr and eta * kg also move with the stiffnesses
    masses = [model.parameter_names.index(n) for n in ("mb", "ms", "Jb", "Js")]
    assert np.all(batch.damping_gradient[:, :, masses] == 0)
    assert np.all(batch.damping_gradient[:, :, [model.parameter_names.index(n) for n in ("kmr", "kg0", "Fp")]]
                  .any(axis=(0, 1)))


def test_damping_gradient_of_a_damping_parameter_is_the_exact_derivative(slide):
    """zeta is linear in c at fixed mass and stiffness: a finite difference of any size is exact."""
    model = NumericModel(slide)
    p = model.nominal.copy()
    i = model.parameter_names.index("cg")
    engine = ModalEngine(model)
    base = engine.evaluate(p, contributions=True)
    p2 = p.copy()
    p2[i] *= 3.0
    moved = engine.evaluate(p2)
    np.testing.assert_allclose((moved.damping - base.damping) / (p2[i] - p[i]), base.damping_gradient[:, :, i],
                               rtol=1e-9, atol=1e-18)


def test_tracking_follows_a_mode_through_a_frequency_crossing():
    b = StructureBuilder("crossing")
    b.parameter("kx", 1.0e6, kind="stiffness")
    b.parameter("ky", 0.5e6, kind="stiffness")
    b.parameter("kc", 1.0e3, kind="stiffness")
    b.body("m", mass=1.0, inertia={"xx": 1, "yy": 1, "zz": 1}, dofs=["x", "y"])
    b.element("sx", bodies=("ground", "m"), stiffness={"x": "kx"})
    b.element("sy", bodies=("ground", "m"), stiffness={"y": "ky"})
    b.element("diag", bodies=("ground", "m"), axes={"x": [1, 1, 0]}, stiffness={"x": "kc"})
    model = NumericModel(b.build())
    engine = ModalEngine(model, sensors="dofs")
    ky = np.array([0.5e6, 0.9e6, 1.1e6, 2.0e6])
    params = np.column_stack([np.full(4, 1.0e6), ky, np.full(4, 1.0e3)])
    untracked = engine.evaluate(params)
    tracked = engine.evaluate(params, track=True)
    # untracked: mode 0 is the y mode below the crossing and the x mode above it
    assert abs(untracked.shapes[0, 1, 0]) > abs(untracked.shapes[0, 0, 0])
    assert abs(untracked.shapes[3, 0, 0]) > abs(untracked.shapes[3, 1, 0])
    # tracked: mode 0 stays the y mode, its frequency follows sqrt(ky)
    assert np.all(np.abs(tracked.shapes[:, 1, 0]) > np.abs(tracked.shapes[:, 0, 0]))
    np.testing.assert_allclose(tracked.frequency[:, 0], np.sqrt(ky) / (2 * np.pi), rtol=1e-2)
    np.testing.assert_array_equal(tracked.mode_index[:, 0], [0, 0, 1, 1])
    assert np.all(tracked.tracking_mac > 0.99)


def test_references_are_tracked_across_axis_positions(slide):
    engine = ModalEngine(slide, n_modes=9)
    positions = [{"z": z} for z in (0.1, 0.25, 0.4)]
    refs = engine.references(positions)
    assert [r.n_modes for r in refs] == [9, 9, 9]
    # neighbouring references describe the same physical modes: high mass-weighted MAC on the diagonal
    for a, b in zip(refs, refs[1:], strict=False):
        cross = (a.shapes.T @ a.mass @ b.shapes) ** 2
        assert np.all(np.diag(cross) > 0.5)
        assert np.all(np.argmax(cross, axis=1) == np.arange(9))


def test_map_streams_chunks(slide):
    model = NumericModel(slide)
    params = random_params(model, 20, seed=6)
    engine = ModalEngine(model, chunk_size=6)
    parts = engine.map(lambda batch: batch.frequency[:, 0], params, {"z": 0.1})
    assert [p.shape for p in parts] == [(6,), (6,), (6,), (2,)]
    np.testing.assert_array_equal(np.concatenate(parts), engine.evaluate(params, {"z": 0.1}).frequency[:, 0])


def test_sensor_selection(slide):
    engine = ModalEngine(slide, sensors=["tool:x", "top"])
    assert engine.sensors == ("tool:x", "top:x", "top:y", "top:z")
    batch = engine.evaluate()
    full = ModalEngine(slide).evaluate()
    np.testing.assert_array_equal(batch.shapes[0, 0], full.shapes[0, full.sensors.index("tool:x")])


def test_errors_name_the_problem(slide):
    model = NumericModel(slide)
    with pytest.raises(ModelError, match=r"sensor 'nowhere' does not exist in model 'slide'"):
        ModalEngine(model, sensors=["nowhere"])
    with pytest.raises(ModelError, match=r"n_modes must be an integer from 1 to n_dof = 12; got 13"):
        ModalEngine(model, n_modes=13)
    with pytest.raises(ModelError, match=r"sensors must be a list of channel labels"):
        ModalEngine(model, sensors="tool")
    params = np.tile(model.nominal, (5, 1))
    params[3, model.parameter_names.index("ms")] = -1.0
    with pytest.raises(ModelError, match=r"mass matrix is not positive definite for samples \[3\] \(1 in all\)"):
        ModalEngine(model, n_workers=1).evaluate(params)
    params = np.tile(model.nominal, (5, 1))
    params[[1, 4], model.parameter_names.index("km")] = -1.0e7
    with pytest.raises(ModelError, match=r"stiffness matrix is not positive semi-definite for samples \[1, 4\]"):
        ModalEngine(model, n_workers=1).evaluate(params)
    with pytest.raises(ModelError, match=r"parameter array must have shape"):
        ModalEngine(model).evaluate(np.ones((2, 3)))


@pytest.mark.parametrize("com", [(0, 0, 0), (0.01, 0.005, 0.02)])
def test_block_and_diagonal_mass_reductions_match_the_reference(com):
    """Chains of 6-DOF bodies: diagonal M (no offsets) and full 6 x 6 blocks at n_dof >= 48 take the fast
    reductions; both must agree with the dense generalized eigen-solution."""
    b = StructureBuilder("chain")
    b.parameter("m", 5.0, kind="mass")
    b.parameter("J", 0.05, kind="inertia")
    b.parameter("k", 1.0e7, kind="stiffness")
    b.parameter("c", 100.0, kind="damping")
    for i in range(9):
        b.body(f"b{i}", mass="m", inertia={"xx": "J", "yy": "1.1*J", "zz": "1.2*J"}, position=[0, 0, 0.2 * i],
               com=list(com))
    six = ("x", "y", "z", "rx", "ry", "rz")
    for i in range(10):
        a = "ground" if i == 0 else f"b{i - 1}"
        c = "ground" if i == 9 else f"b{i}"
        b.element(f"e{i}", bodies=(a, c), at=[0.05, 0.02, 0.2 * i - 0.1],
                  stiffness={d: f"{1 + 0.1 * i}*k" if d in "xyz" else "k/100" for d in six}, damping={"x": "c"})
    model = NumericModel(b.build())
    assert model.n_dof == 54
    params = random_params(model, 3, seed=8)
    batch = ModalEngine(model, sensors="dofs").evaluate(params)
    for k, p in enumerate(params):
        ref = model.system(p).modes("first-order")
        np.testing.assert_allclose(batch.frequency[k], ref.frequency, rtol=1e-9)  # round-off of n = 54 solves
        np.testing.assert_allclose(batch.damping[k], ref.damping, rtol=1e-7)


def test_mass_errors_name_the_samples_beside_nominal_ones(slide):
    # samples 0, 2 and 3 keep the nominal masses (the shared reduction); 1 and 4 have their own, 4 a negative one
    model = NumericModel(slide)
    params = np.tile(model.nominal, (5, 1))
    ms = model.parameter_names.index("ms")
    params[1, ms] *= 1.1
    params[4, ms] = -1.0
    with pytest.raises(ModelError, match=r"mass matrix is not positive definite for samples \[4\] \(1 in all\)"):
        ModalEngine(model, n_workers=1).evaluate(params)
    bad = copy.copy(model)
    bad.nominal = model.nominal.copy()
    bad.nominal[ms] = -1.0
    with pytest.raises(ModelError, match=r"nominal mass matrix of model 'slide' at position .* not positive definite"):
        ModalEngine(bad, n_workers=1).evaluate(np.tile(bad.nominal, (3, 1)))


@pytest.mark.parametrize("kwargs", [{"n_modes": 3}, {"n_modes": 1}, {"n_modes": 3, "exact": True},
                                    {"n_modes": 3, "track": True}])
def test_fewer_modes_than_dofs_give_the_same_bits_in_any_chunk(spindle, kwargs):
    # first-order damping without contributions, shapes and poles with n_modes < n_dof: the per-sample products see
    # arrays whose strides depend on the chunk size unless the engine lays them out contiguously
    model = NumericModel(spindle)
    params = random_params(model, 9, seed=8)
    kwargs = dict(kwargs)  # the parametrized dict is shared: leave it as given
    n_modes = kwargs.pop("n_modes")
    whole = ModalEngine(model, chunk_size=64, n_workers=1, n_modes=n_modes).evaluate(params, **kwargs)
    for chunk in (1, 2, 4):
        parts = ModalEngine(model, chunk_size=chunk, n_workers=1, n_modes=n_modes).evaluate(params, **kwargs)
        for name in ("frequency", "damping", "shapes", "poles", "complex_shapes"):
            if getattr(whole, name) is not None:
                np.testing.assert_array_equal(getattr(parts, name), getattr(whole, name), err_msg=f"{name} {chunk}")


def test_nominal_reduction_is_made_at_the_position_it_was_asked_for(slide):
    # the reduction is cached per position and factored on first use: a caller's mapping changed in between
    # must not move it
    model = NumericModel(slide)
    engine = ModalEngine(model, n_workers=1)
    pos = {"z": 0.1}
    varied = np.tile(model.nominal, (2, 1))
    varied[:, model.parameter_names.index("ms")] *= 1.2
    engine.evaluate(varied, pos)  # creates the cache entry, the factor not yet
    pos["z"] = 0.3
    got = engine.evaluate(np.tile(model.nominal, (2, 1)), {"z": 0.1})
    fresh = ModalEngine(model, n_workers=1).evaluate(np.tile(model.nominal, (2, 1)), {"z": 0.1})
    np.testing.assert_array_equal(got.frequency, fresh.frequency)


@pytest.mark.parametrize("kwargs", [{}, {"full_shapes": True, "contributions": True}, {"exact": True},
                                    {"track": True}])
def test_samples_sharing_a_stiffness_share_one_eigen_solve_and_keep_their_bits(slide, kwargs, monkeypatch):
    # a Saltelli design repeats each base sample's stiffness in the columns of the damping unknowns: those
    # samples take one eigen-solve between them, and every result is what the sample alone gives
    model = NumericModel(slide)
    damping = [i for i, p in enumerate(slide.parameters) if p.kind in ("damping", "loss")]
    masses = [i for i, p in enumerate(slide.parameters) if p.kind in ("mass", "inertia")]
    assert damping
    base = random_params(model, 3, seed=11)
    base[:, masses] = model.nominal[masses]  # the nominal M: the shared-mass path, where solves are shared
    rows = []
    rng = np.random.default_rng(12)
    for b in base:  # each base sample, then copies with other damping
        rows.append(b)
        for i in damping:
            other = b.copy()
            other[i] *= rng.uniform(0.5, 1.5)
            rows.append(other)
    params = np.array(rows)
    solves = []
    original = np.linalg.eigh

    def counted(a, *args, **kw):
        solves.append(np.asarray(a).shape[0])
        return original(a, *args, **kw)

    monkeypatch.setattr(np.linalg, "eigh", counted)
    batch = ModalEngine(model, n_workers=1, chunk_size=64).evaluate(params, {"z": 0.2}, **kwargs)
    assert solves[-1] == 3  # three distinct stiffnesses (with track, the nominal reference was solved before)
    assert len(np.unique(batch.damping, axis=0)) == len(params)  # the damping still differs
    for k in range(len(params)):
        alone = ModalEngine(model, n_workers=1).evaluate(params[k:k + 1], {"z": 0.2}, **kwargs)
        for name in ("frequency", "damping", "shapes", "full_shapes", "mode_index", "tracking_mac", "contributions",
                     "damping_gradient", "poles", "complex_shapes"):
            got = getattr(batch, name)
            if got is not None:
                np.testing.assert_array_equal(got[k:k + 1], getattr(alone, name), err_msg=f"{name} of sample {k}")


def test_empty_sensor_list_is_a_model_error():
    # `--sensors ""` reached the engine as [] and ended in a reshape ValueError traceback
    with pytest.raises(ModelError, match=r"list of sensor channels for model 'two-mass-rig' is empty"):
        ModalEngine(load_model("builtin:two-mass-rig"), sensors=[])


def _flexible_with_dense_rows(n: int = 7, *, varying_mass: bool = False, lumped: bool = False) -> NumericModel:
    """A 30 kg block on a free-free steel beam (``n`` nodes) on two mounts: the beam's loss factor gives dense rank-one
    damping rows and a sensor between two nodes reads a dense recovery row (the engine's BLAS path). The beam's
    mass falls into blocks of 2 n DOFs (axial, torsion, two bending planes): with 13 nodes their L^-T is dense too.
    With ``varying_mass`` the beam's mass scale ``s_m`` and the block's mass ``mb`` are parameters; ``lumped`` keeps
    the diagonal of the beam's mass matrix (1 x 1 blocks)."""
    from cappe.model.fe import BeamSection, frame_model

    nodes = np.c_[np.linspace(0, 1.2, n), np.zeros(n), np.zeros(n)]
    fm = frame_model(nodes, [[i, i + 1] for i in range(n - 1)], BeamSection.rectangle(0.08, 0.12, E=210e9, nu=0.3,
                                                                                       rho=7850.0))
    rec = np.zeros((3, 6 * n))
    rec[:, 18:21] = rec[:, 24:27] = 0.5 * np.eye(3)
    b = StructureBuilder("beam-block")
    b.parameter("k", 2.0e7, kind="stiffness")
    b.parameter("s_k", 1.0, kind="other")
    b.parameter("eta", 0.01, kind="loss")
    if varying_mass:
        b.parameter("s_m", 1.0, kind="other")
        b.parameter("mb", 30.0, kind="mass")
    mass = sps.diags(fm.mass.diagonal()) if lumped else fm.mass
    b.flexible_body("beam", mass=mass, stiffness=fm.stiffness, stiffness_scale="s_k", damping={"loss": "eta"},
                    mass_scale="s_m" if varying_mass else 1,
                    nodes=[{"name": f"n{i}", "at": [float(x), 0.0, 0.0]} for i, x in enumerate(nodes[:, 0])],
                    recovery={"matrix": rec, "nodes": [{"name": "mid", "at": [0.55, 0.0, 0.0], "dofs": ["x", "y", "z"]}]})
    for name, x in (("left", 0.0), ("right", 1.2)):
        b.element(name, bodies=["ground", "beam"], at=[x, 0, 0],
                  stiffness={d: "k" for d in ("x", "y", "z", "rx", "ry", "rz")}, damping={"y": 300.0})
    b.body("block", mass="mb" if varying_mass else 30.0, inertia={"xx": 0.2, "yy": 0.2, "zz": 0.2},
           position=[0.6, 0.0, 0.1], com=[0.01, 0.02, 0.03])
    b.element("mount", bodies=["beam", "block"], at=[0.6, 0, 0],
              stiffness={d: "k" for d in ("x", "y", "z", "rx", "ry", "rz")})
    b.sensor("mid", body="beam", point="mid")
    b.sensor("block", body="block")
    return NumericModel(b.build())


def _assert_numpy_modes(result, i, model, params):
    """Sample ``i`` of an engine result equals numpy's undamped modes of the assembled matrices: frequencies,
    phi^T C phi / 2 omega + phi^T H phi / 2 omega^2, and the sensor shapes up to sign; returns the mass-normalized
    modes phi."""
    system = model.system(params)
    lam, phi = scipy.linalg.eigh(system.K, system.M)
    omega = np.sqrt(lam)
    zeta = (np.einsum("ij,ik,kj->j", phi, system.C, phi) / (2 * omega)
            + np.einsum("ij,ik,kj->j", phi, system.H, phi) / (2 * omega**2))
    np.testing.assert_allclose(result.frequency[i], omega / (2 * np.pi), rtol=1e-9)
    np.testing.assert_allclose(result.damping[i], zeta, rtol=1e-8, atol=1e-12)
    shapes = model.sensor_matrix()[1] @ phi
    np.testing.assert_allclose(np.abs(result.shapes[i]), np.abs(shapes), rtol=1e-7, atol=1e-9 * np.abs(shapes).max())
    return phi


def test_dense_rows_of_flexible_bodies_give_the_same_bits_in_any_chunk_and_the_numpy_damping():
    model = _flexible_with_dense_rows()
    engine = ModalEngine(model, n_workers=1, chunk_size=64)
    assert engine._stacked_rows(None, engine._sensor_rows(None)[1],
                                model.damping_sources().rows).dense_index.size > 30  # the dense path is taken
    params = random_params(model, 9, seed=4)
    params[:, model.parameter_names.index("eta")] = 0.01  # masses stay nominal: the nominal reduction's path too
    kwargs = {"contributions": True}
    whole = engine.evaluate(params, **kwargs)
    for chunk in (1, 4):
        parts = ModalEngine(model, chunk_size=chunk, n_workers=1).evaluate(params, **kwargs)
        for name in ("frequency", "damping", "shapes", "contributions", "damping_gradient"):
            np.testing.assert_array_equal(getattr(parts, name), getattr(whole, name), err_msg=f"{name} {chunk}")
    # independent of the rank-one sources and of the projection: numpy on the assembled matrices
    for i in (0, 5):
        system = model.system(params[i])
        lam, phi = scipy.linalg.eigh(system.K, system.M)
        omega = np.sqrt(lam)
        zeta = np.einsum("ij,ik,kj->j", phi, system.C, phi) / (2 * omega) + np.einsum(
            "ij,ik,kj->j", phi, system.H, phi) / (2 * omega**2)
        np.testing.assert_allclose(whole.frequency[i], omega / (2 * np.pi), rtol=1e-9)
        np.testing.assert_allclose(whole.damping[i], zeta, rtol=1e-8, atol=1e-12)
        labels, rows = model.sensor_matrix()
        shapes = rows @ phi
        np.testing.assert_allclose(np.abs(whole.shapes[i]), np.abs(shapes), rtol=1e-7, atol=1e-9 * np.abs(shapes).max())


def test_a_flexible_body_is_projected_without_forming_its_shapes_and_gives_the_numpy_modes(monkeypatch):
    # the hot path on a flexible body (known masses): the sensor and source rows times the nominal L^-T are applied
    # to the eigenvectors; L^-T v (four dense 26 x 26 blocks per mode here) is formed only for full shapes or exact modes
    from cappe.modal._engine import _NominalReduction

    model = _flexible_with_dense_rows(13)
    params = random_params(model, 6, seed=7)
    params[:, model.parameter_names.index("eta")] = 0.01
    engine = ModalEngine(model, n_workers=1, chunk_size=4)
    full = engine.evaluate(params, full_shapes=True, contributions=True)  # L^-T v, then the rows

    def refused(self, vectors):  # noqa: ARG001 (the signature of the method it replaces)
        msg = "the shapes at all DOFs were formed"
        raise AssertionError(msg)

    monkeypatch.setattr(_NominalReduction, "flat_shapes", refused)
    fused = engine.evaluate(params, contributions=True)
    for chunk in (1, 6):  # the same bits in any chunk
        parts = ModalEngine(model, chunk_size=chunk, n_workers=1).evaluate(params, contributions=True)
        for name in ("frequency", "damping", "shapes", "contributions", "damping_gradient"):
            np.testing.assert_array_equal(getattr(parts, name), getattr(fused, name), err_msg=f"{name} {chunk}")
    # the lowest five modes (the eigenvectors a strided view): the same bits in any chunk too
    few = [ModalEngine(model, n_modes=5, chunk_size=chunk, n_workers=1).evaluate(params) for chunk in (1, 6)]
    for name in ("frequency", "damping", "shapes"):
        np.testing.assert_array_equal(getattr(few[0], name), getattr(few[1], name), err_msg=name)
        np.testing.assert_allclose(np.abs(getattr(few[1], name)), np.abs(getattr(fused, name)[..., :5]), rtol=1e-9,
                                   atol=1e-12 * np.abs(getattr(fused, name)).max(), err_msg=name)
    # the same numbers by either order of the products (rtol: rounding of 42-term sums, measured 1e-13)
    for name in ("frequency", "damping", "contributions"):
        np.testing.assert_allclose(getattr(fused, name), getattr(full, name), rtol=1e-10, atol=1e-14, err_msg=name)
    np.testing.assert_allclose(fused.shapes, full.shapes, rtol=1e-9, atol=1e-12 * np.abs(full.shapes).max())
    # and numpy's phi^T C phi / 2 omega + phi^T H phi / 2 omega^2 on the assembled matrices
    for i in range(len(params)):
        _assert_numpy_modes(fused, i, model, params[i])


@pytest.mark.parametrize(("n", "lumped"), [(7, False), (13, False), (7, True)])
def test_varying_masses_on_a_flexible_body_scale_the_nominal_factor_and_give_the_numpy_modes(n, lumped, monkeypatch):
    # a flexible body's mass block is s_m M_fe: its Cholesky factor is the nominal one times sqrt(s_m / s_m,nom), and
    # a rigid body's 6 x 6 block takes S_b = L_b^-1 L_b,nom; no sample factors its own M (the dense 121^3 products
    # per sample on the flexible-bed machine tool before)
    from cappe.modal._engine import _MassReduction

    model = _flexible_with_dense_rows(n, varying_mass=True, lumped=lumped)
    params = random_params(model, 7, seed=11)
    params[:, model.parameter_names.index("eta")] = 0.01
    params[2] = model.nominal  # nominal masses beside varying ones in one chunk
    params[4, model.parameter_names.index("s_m")] = 1.0
    params[4, model.parameter_names.index("mb")] = 30.0
    reference = ModalEngine(model, n_workers=1, chunk_size=7).evaluate(params, contributions=True, full_shapes=True)

    def refused(self, *args):  # noqa: ARG001 (the signature of the method it replaces)
        msg = "a sample factored its own mass matrix"
        raise AssertionError(msg)

    monkeypatch.setattr(_MassReduction, "__init__", refused)
    batch = ModalEngine(model, n_workers=1, chunk_size=7).evaluate(params, contributions=True)
    for chunk in (1, 3):  # the same bits in any chunk
        parts = ModalEngine(model, chunk_size=chunk, n_workers=1).evaluate(params, contributions=True)
        for name in ("frequency", "damping", "shapes", "contributions", "damping_gradient"):
            np.testing.assert_array_equal(getattr(parts, name), getattr(batch, name), err_msg=f"{name} {chunk}")
    np.testing.assert_allclose(batch.shapes, reference.shapes, rtol=1e-9, atol=1e-12 * np.abs(batch.shapes).max())
    exact = ModalEngine(model, n_workers=1, chunk_size=7).evaluate(params[:2], exact=True)
    tracked = ModalEngine(model, n_workers=1, chunk_size=7).evaluate(params, track=True)
    # tracking orders the modes as the nominal reference does: the same set
    np.testing.assert_allclose(np.sort(tracked.frequency, axis=1), batch.frequency, rtol=1e-9)
    for i in range(len(params)):
        # the same tolerances as the known-mass path's test above (rounding of the reductions, 1e-13 measured)
        phi = _assert_numpy_modes(batch, i, model, params[i])
        system = model.system(params[i])
        full = reference.full_shapes[i]
        np.testing.assert_allclose(np.abs(full), np.abs(phi), rtol=1e-7, atol=1e-9 * np.abs(phi).max())
        if i < 2:
            ref = system.modes("exact")
            np.testing.assert_allclose(np.sort_complex(exact.poles[i]), np.sort_complex(ref.poles), rtol=1e-9)


def _state_matrix_poles(model: NumericModel, params: np.ndarray, position) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues and displacement eigenvectors of the state matrix, by scipy's eig (written here, from the
    assembled matrices: no cappe modal code)."""
    mats = model.matrices(params, position)
    n = model.n_dof
    minv = np.linalg.inv(mats["M"])
    state = np.zeros((2 * n, 2 * n), dtype=complex)
    state[:n, n:] = np.eye(n)
    state[n:, :n] = -minv @ (mats["K"] + 1j * mats["H"])
    state[n:, n:] = -minv @ (mats["C"] + mats["G"])
    lam, vec = scipy.linalg.eig(state)
    return lam, vec[:n]


def _assert_equal_to_the_state_matrix(model, params, position, batch):
    lam, vec = _state_matrix_poles(model, params, position)
    for r, pole in enumerate(batch.poles[0]):
        k = int(np.argmin(np.abs(lam - pole)))
        # eig of the 2 n state matrix is accurate to ~1e-16 of its norm: 1e-11 of the pole on these models
        np.testing.assert_allclose(pole, lam[k], rtol=1e-11)
        a = batch.complex_shapes[0][:, r]
        b = vec[:, k]
        mac = abs(np.vdot(a, b)) ** 2 / (np.vdot(a, a).real * np.vdot(b, b).real)
        assert mac == pytest.approx(1.0, abs=1e-11)


@pytest.mark.parametrize("position", [{"z": 0.1}, {"z": 0.4}])
def test_quadratic_exact_modes_equal_scipy_eig_of_the_state_matrix(slide, position, monkeypatch):
    # issue 24: few modes of one vector are solved on the quadratic eigenproblem, mode by mode from the undamped
    # ones; against scipy's eig of the state matrix, and bit-close to the engine's full-eig path
    import cappe.modal._engine as engine_module

    model = NumericModel(slide)
    p = random_params(model, 1, 11)[0]
    full = ModalEngine(model, n_modes=6, sensors="dofs", n_workers=1).evaluate(p, position, exact=True)  # the state eig
    monkeypatch.setattr(engine_module, "QUADRATIC_FRACTION", 0.5)  # 6 of 12 modes
    engine = ModalEngine(model, n_modes=6, sensors="dofs", n_workers=1)
    batch = engine.evaluate(p, position, exact=True)
    assert engine.exact_solves == {"quadratic": 1, "fallback": 0}
    assert engine._quadratic_modes(p, position) is not None
    _assert_equal_to_the_state_matrix(model, p, position, batch)
    # the same pairing and the same shape scaling (phi_r^T M x_r = 1) as the full path
    np.testing.assert_allclose(batch.poles, full.poles, rtol=1e-12)
    np.testing.assert_allclose(batch.complex_shapes, full.complex_shapes, rtol=0,
                               atol=1e-10 * np.abs(full.complex_shapes).max())


@pytest.mark.parametrize("steps", [1, 2])
def test_quadratic_modes_iterate_side_by_side_each_at_its_own_pace(slide, steps, monkeypatch):
    # issue 24 (speed): the modes of one vector run their inverse iterations side by side; with one or two steps per
    # factorization some converge on their first shift while others shift again (counted: more factorizations than
    # modes, fewer than every mode taking every shift), and each ends as if alone: equal to scipy's eig of the state
    # matrix, and to the path with the default steps
    import cappe.modal._engine as engine_module

    model = NumericModel(slide)
    p = random_params(model, 1, 11)[0]
    monkeypatch.setattr(engine_module, "QUADRATIC_FRACTION", 0.5)  # 6 of 12 modes
    default = ModalEngine(model, n_modes=6, sensors="dofs", n_workers=1).evaluate(p, {"z": 0.1}, exact=True)
    monkeypatch.setattr(engine_module, "QUADRATIC_STEPS", steps)
    factored = []
    getrf = scipy.linalg.lapack.zgetrf

    def counted(a, *args, **kwargs):
        factored.append(np.shape(a))
        return getrf(a, *args, **kwargs)

    monkeypatch.setattr(scipy.linalg.lapack, "zgetrf", counted)
    engine = ModalEngine(model, n_modes=6, sensors="dofs", n_workers=1)
    batch = engine.evaluate(p, {"z": 0.1}, exact=True)
    assert engine.exact_solves == {"quadratic": 1, "fallback": 0}
    moving = int(np.count_nonzero(batch.poles[0]))
    assert moving < len(factored) < engine_module.QUADRATIC_SHIFTS * moving
    _assert_equal_to_the_state_matrix(model, p, {"z": 0.1}, batch)
    np.testing.assert_allclose(batch.poles, default.poles, rtol=1e-12)  # both converged to round-off


@pytest.mark.parametrize("n", [1, 7, 162])
def test_the_inverse_iteration_one_column_solve_equals_scipy_lu_solve(n):
    # issue 24 (speed): the inverse-iteration steps solve one column with getrf's factors by two BLAS trsv (no getrs
    # set-up); against scipy's lu_solve of the same factors and numpy's solve, on complex matrices that pivot
    from cappe.modal._engine import _lu_solve, _row_order

    rng = np.random.default_rng(n)
    a = rng.standard_normal((n, n)) + 1j * rng.standard_normal((n, n))
    b = rng.standard_normal(n) + 1j * rng.standard_normal(n)
    lu, piv, info = scipy.linalg.lapack.zgetrf(a)
    assert info == 0
    assert n == 1 or np.any(piv != np.arange(n))  # rows interchanged: the order is exercised
    x = _lu_solve(lu, _row_order(piv), b.copy())
    # both run the same forward and back substitutions: equal to a few ulps of the solution (trsm vs trsv order)
    np.testing.assert_allclose(x, scipy.linalg.lu_solve((lu, piv), b), rtol=0, atol=1e-13 * np.abs(x).max())
    np.testing.assert_allclose(a @ x, b, rtol=0, atol=1e-12 * n * np.abs(a).max() * np.abs(x).max())


@pytest.mark.parametrize("split", [0.0, 1e-7, 1e-3])
def test_quadratic_exact_modes_of_repeated_and_close_frequencies(split, monkeypatch):
    # issue 24: a mass on springs of (nearly) equal x and y stiffness, a damper at 30 degrees coupling x and y: the
    # undamped shapes are any pair of the plane (repeated) or x and y (close), the damped ones are mixed. Either the
    # quadratic solve finds both modes or it misses and falls back to the state eig, counted; the poles and shapes
    # equal scipy's eig of the state matrix either way
    import cappe.modal._engine as engine_module

    b = StructureBuilder("close")
    b.parameter("k", 1.0e6, kind="stiffness")
    b.parameter("c", 40.0, kind="damping")
    b.body("m", mass=1.0, inertia={"xx": 1, "yy": 1, "zz": 1}, dofs=["x", "y"])
    b.element("s", bodies=("ground", "m"), stiffness={"x": "k", "y": f"k*(1 + {split})"})
    b.element("d", bodies=("ground", "m"), axes={"x": [np.cos(np.pi / 6), np.sin(np.pi / 6), 0.0],
                                                 "y": [-np.sin(np.pi / 6), np.cos(np.pi / 6), 0.0]},
              damping={"x": "c"})
    model = NumericModel(b.build())
    monkeypatch.setattr(engine_module, "QUADRATIC_FRACTION", 1.0)
    engine = ModalEngine(model, sensors="dofs", n_workers=1)
    batch = engine.evaluate(None, None, exact=True)
    assert sum(engine.exact_solves.values()) == 1
    assert np.all(np.isfinite(batch.poles))
    _assert_equal_to_the_state_matrix(model, model.nominal, None, batch)
    assert abs(batch.poles[0, 0] - batch.poles[0, 1]) > 1e-6 * abs(batch.poles[0, 0])  # two poles, not one twice


def test_a_quadratic_mode_that_misses_falls_back_to_the_state_eig_and_is_counted(slide, monkeypatch):
    # issue 24: no inverse-iteration step allowed, so every mode misses: the exact modes come from the state eig,
    # the miss is counted, and nothing is kept for the quadratic derivatives
    import cappe.modal._engine as engine_module

    model = NumericModel(slide)
    p = random_params(model, 1, 4)[0]
    full = ModalEngine(model, n_modes=6, n_workers=1).evaluate(p, {"z": 0.1}, exact=True)
    monkeypatch.setattr(engine_module, "QUADRATIC_FRACTION", 0.5)
    monkeypatch.setattr(engine_module, "QUADRATIC_STEPS", 0)
    engine = ModalEngine(model, n_modes=6, n_workers=1)
    batch = engine.evaluate(p, {"z": 0.1}, exact=True)
    assert engine.exact_solves == {"quadratic": 0, "fallback": 1}
    assert engine._quadratic_modes(p, {"z": 0.1}) is None
    assert engine._state_eigensystem(p, {"z": 0.1}) is not None
    np.testing.assert_array_equal(batch.poles, full.poles)


def _counted_steps(monkeypatch) -> list[int]:
    """Count the inverse-iteration steps (one-column LU solves) of the quadratic exact modes."""
    import cappe.modal._engine as engine_module

    steps = [0]
    solve = engine_module._lu_solve

    def counted(*args):
        steps[0] += 1
        return solve(*args)

    monkeypatch.setattr(engine_module, "_lu_solve", counted)
    return steps


def test_warm_started_exact_modes_take_fewer_steps_and_equal_the_state_matrix(slide, monkeypatch):
    # issue 24 (speed): with warm_start, the exact modes of a search's next vector start from the previous vector's
    # poles and shapes at that position, not from the undamped modes: fewer inverse-iteration steps (the error
    # shrinks by |s - sigma| / |s' - sigma| per step, and the previous pole is the nearer shift), the same modes:
    # against scipy's eig of the state matrix and the cold engine
    import cappe.modal._engine as engine_module

    model = NumericModel(slide)
    p = random_params(model, 1, 11)[0]
    q = p * np.exp(1e-4 * np.random.default_rng(3).standard_normal(p.size))  # a trust-region step away
    monkeypatch.setattr(engine_module, "QUADRATIC_FRACTION", 0.5)  # 6 of 12 modes
    steps = _counted_steps(monkeypatch)
    cold = ModalEngine(model, n_modes=6, sensors="dofs", n_workers=1)
    cold.evaluate(p, {"z": 0.1}, exact=True)
    steps[0] = 0
    cold_batch = cold.evaluate(q, {"z": 0.1}, exact=True)
    cold_steps = steps[0]
    warm = ModalEngine(model, n_modes=6, sensors="dofs", n_workers=1, warm_start=True)
    warm.evaluate(p, {"z": 0.1}, exact=True)
    steps[0] = 0
    warm_batch = warm.evaluate(q, {"z": 0.1}, exact=True)
    assert warm.exact_solves == {"quadratic": 2, "fallback": 0}
    assert steps[0] < 0.75 * cold_steps, (steps[0], cold_steps)
    _assert_equal_to_the_state_matrix(model, q, {"z": 0.1}, warm_batch)
    np.testing.assert_allclose(warm_batch.poles, cold_batch.poles, rtol=1e-12)
    np.testing.assert_allclose(warm_batch.complex_shapes, cold_batch.complex_shapes, rtol=0,
                               atol=1e-9 * np.abs(cold_batch.complex_shapes).max())
    assert warm._quadratic_modes(q, {"z": 0.1}) is not None  # kept for the derivatives at the same vector


def test_a_warm_start_that_converges_to_other_modes_is_checked_and_goes_cold(slide, monkeypatch):
    # issue 24: previous modes in another order (two modes swapped, as when their frequencies cross between two
    # vectors of a search) converge to modes that are not the undamped modes' partners: the checks reject them and
    # every mode is solved cold, giving the cold solve's modes bit for bit. The default engine does not warm-start:
    # the same vector gives the same bits whatever came before
    import cappe.modal._engine as engine_module

    model = NumericModel(slide)
    far, p = random_params(model, 2, 4)
    monkeypatch.setattr(engine_module, "QUADRATIC_FRACTION", 0.5)
    engine = ModalEngine(model, n_modes=6, sensors="dofs", n_workers=1)
    first = engine.evaluate(p, {"z": 0.1}, full_shapes=True)
    mats = {k: v[0] for k, v in model.matrices(p[None, :], {"z": 0.1}).items()}
    phi, omega, zeta = first.full_shapes[0], 2 * np.pi * first.frequency[0], first.damping[0]
    steps = _counted_steps(monkeypatch)
    cold = engine_module.QuadraticModes.solve(mats, phi, omega, zeta)
    assert cold is not None
    cold_steps, steps[0] = steps[0], 0
    order = np.array([1, 0, 2, 3, 4, 5])
    swapped = engine_module.QuadraticModes(mats, cold.poles[order], cold.shapes[:, order])
    checked = engine_module.QuadraticModes.solve(mats, phi, omega, zeta, previous=swapped)
    assert checked is not None
    assert steps[0] > cold_steps  # the warm attempt ran, and was rejected
    np.testing.assert_array_equal(checked.poles, cold.poles)
    np.testing.assert_array_equal(checked.shapes, cold.shapes)
    reference = ModalEngine(model, n_modes=6, sensors="dofs", n_workers=1).evaluate(p, {"z": 0.1}, exact=True)
    engine.evaluate(far, {"z": 0.1}, exact=True)
    np.testing.assert_array_equal(engine.evaluate(p, {"z": 0.1}, exact=True).poles, reference.poles)
