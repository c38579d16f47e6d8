"""Analytic modal derivatives against central finite differences and homogeneity identities."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from cappe.exceptions import IllConditionedWarning, ModelError
from cappe.modal import ModalEngine, exact_mode_derivatives, modal_derivatives
from cappe.model import NumericModel, StructureBuilder


def finite_differences(engine: ModalEngine, p: np.ndarray, position, step: float = 1e-6):
    """Central differences of frequency, damping and sensor shapes (sign-aligned) for every parameter."""
    base = engine.evaluate(p, position)
    n_p = p.size
    d_f = np.empty((base.n_modes, n_p))
    d_z = np.empty((base.n_modes, n_p))
    d_s = np.empty((*base.shapes.shape[1:], n_p))
    for i in range(n_p):
        h = step * max(abs(p[i]), 1e-12)
        plus, minus = p.copy(), p.copy()
        plus[i] += h
        minus[i] -= h
        bp, bm = engine.evaluate(plus, position), engine.evaluate(minus, position)
        d_f[:, i] = (bp.frequency[0] - bm.frequency[0]) / (2 * h)
        d_z[:, i] = (bp.damping[0] - bm.damping[0]) / (2 * h)
        sp_, sm = bp.shapes[0], bm.shapes[0]
        ref = base.shapes[0]
        sp_ = sp_ * np.sign(np.sum(sp_ * ref, axis=0))
        sm = sm * np.sign(np.sum(sm * ref, axis=0))
        d_s[:, :, i] = (sp_ - sm) / (2 * h)
    return base, d_f, d_z, d_s


@pytest.mark.parametrize(("fixture", "position"), [("spindle", None), ("slide", {"z": 0.4})])
def test_derivatives_match_finite_differences(fixture, position, request):
    model = NumericModel(request.getfixturevalue(fixture))
    engine = ModalEngine(model, n_workers=1)
    p = model.nominal * np.random.default_rng(7).uniform(0.8, 1.2, model.nominal.size)
    d = engine.derivatives(p, position)
    base, d_f, d_z, d_s = finite_differences(engine, p, position)
    np.testing.assert_allclose(d.frequency, base.frequency[0], rtol=1e-12)
    np.testing.assert_allclose(d.damping, base.damping[0], rtol=1e-10)
    # central differences with relative step 1e-6 have truncation ~1e-12 and round-off ~1e-10 relative to the
    # largest term: compare scaled by p (per cent per per cent) against the largest sensitivity of each mode
    scale_f = np.abs(d.d_frequency * p).max(axis=1, keepdims=True)
    np.testing.assert_allclose(d.d_frequency * p, d_f * p, atol=1e-6 * scale_f.max())
    scale_z = np.abs(d.d_damping * p).max()
    np.testing.assert_allclose(d.d_damping * p, d_z * p, atol=1e-6 * scale_z)
    scale_s = np.abs(d.d_shapes * p).max()
    np.testing.assert_allclose(d.d_shapes * p, d_s * p, atol=1e-5 * scale_s)


def test_euler_homogeneity_of_frequencies_and_damping(slide):
    """f is homogeneous of degree -1/2 in all masses and +1/2 in all stiffnesses; zeta of degree +1 in all
    damping coefficients (c and eta); in the masses its viscous part has degree -1/2 and its hysteretic part
    degree 0 (phi^T H phi and omega^2 both scale with 1/mass). Euler: sum_i p_i dQ/dp_i = degree * Q."""
    model = NumericModel(slide)
    d = modal_derivatives(slide, position={"z": 0.25})
    kinds = {p.name: p.kind for p in slide.parameters}
    names = model.parameter_names
    mass = np.array([kinds[n] in ("mass", "inertia") for n in names])
    # kg0 and km, kmr scale every stiffness; Fp enters only through kg0*(Fp/1000)^(1/3), so it is left out
    stiff = np.array([n in ("km", "kmr", "kg0") for n in names])
    damp = np.array([n in ("cm", "cg", "eta") for n in names])
    p = d.parameters
    # analytic derivatives are exact to round-off: 1e-9 relative
    np.testing.assert_allclose((d.d_frequency[:, mass] * p[mass]).sum(axis=1), -0.5 * d.frequency, rtol=1e-9)
    np.testing.assert_allclose((d.d_frequency[:, stiff] * p[stiff]).sum(axis=1), 0.5 * d.frequency, rtol=1e-9)
    np.testing.assert_allclose((d.d_damping[:, damp] * p[damp]).sum(axis=1), d.damping, rtol=1e-9)
    batch = ModalEngine(slide).evaluate(position={"z": 0.25}, contributions=True)
    viscous = batch.contributions[0][:, [k == "viscous" for k in model.damping_sources().kinds]].sum(axis=1)
    np.testing.assert_allclose((d.d_damping[:, mass] * p[mass]).sum(axis=1), -0.5 * viscous, rtol=1e-9)


def test_two_mass_rig_table_5_3_signs(two_mass):
    """Thesis Table 5.3: +10 % m1 lowers f and zeta of the mass-1 mode; k11 raises f and lowers zeta."""
    d = modal_derivatives(two_mass)
    nf, nz = d.normalized()
    names = d.parameter_names
    mode1 = int(np.argmax(np.abs(d.shapes[0])))  # the mode where mass 1 (channel d1) moves most
    assert nf[mode1, names.index("m1")] < -0.4
    assert nz[mode1, names.index("m1")] < -0.4
    assert nf[mode1, names.index("k11")] > 0.4
    assert nz[mode1, names.index("k11")] < -0.4
    # zeta is proportional to c: normalized sensitivity of the mode's damping to its own damper is close to 1
    assert 0.9 < nz[mode1, names.index("c11")] <= 1.0 + 1e-12


def test_repeated_frequencies_warn():
    b = StructureBuilder("symmetric")
    b.parameter("k", 1.0e6, kind="stiffness")
    b.body("m", mass=1.0, inertia={"xx": 1, "yy": 1, "zz": 1}, dofs=["x", "y"])
    b.element("s", bodies=("ground", "m"), stiffness={"x": "k", "y": "k"})
    with pytest.warns(IllConditionedWarning, match=r"has \(nearly\) equal frequencies \(modes 1 and 2 at "):
        d = modal_derivatives(b.build())
    # eigenvalue derivatives stay defined: both modes scale with sqrt(k)
    np.testing.assert_allclose(d.d_frequency[:, 0] * 1.0e6, 0.5 * d.frequency, rtol=1e-12)


def test_tracked_derivatives_follow_the_reference_order(slide):
    engine = ModalEngine(slide, n_modes=6)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        d = engine.derivatives(position={"z": 0.1}, track=True)
    plain = engine.derivatives(position={"z": 0.1})
    np.testing.assert_allclose(d.frequency, plain.frequency, rtol=1e-12)


def test_derivatives_take_one_vector(slide):
    engine = ModalEngine(slide)
    with pytest.raises(ModelError, match="modal derivatives take a single parameter vector"):
        engine.derivatives(np.tile(engine.model.nominal, (2, 1)))


def test_derivatives_for_chosen_parameters_are_those_columns(slide):
    engine = ModalEngine(slide)
    every = engine.derivatives(None, {"z": 0.2})
    names = [slide.parameter_names[i] for i in (3, 0, 5)]
    some = engine.derivatives(None, {"z": 0.2}, parameters=names)
    cols = [slide.parameter_names.index(n) for n in names]
    assert some.parameter_names == tuple(names)
    np.testing.assert_array_equal(some.parameters, every.parameters[cols])
    np.testing.assert_allclose(some.d_frequency, every.d_frequency[:, cols], rtol=1e-12, atol=0)
    np.testing.assert_allclose(some.d_damping, every.d_damping[:, cols], rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(some.d_shapes, every.d_shapes[:, :, cols], rtol=1e-10,
                               atol=1e-12 * np.abs(every.d_shapes).max())
    with pytest.raises(ModelError, match="unknown parameters \\['nope'\\]"):
        engine.derivatives(None, {"z": 0.2}, parameters=["nope"])


def test_exact_mode_derivatives_match_finite_differences(slide):
    # poles and scale-free shapes of the exact complex modes, against central differences of the engine's own exact
    # modes (a different code path: batched eigen solves and pairing with the real modes)
    model = NumericModel(slide)
    engine = ModalEngine(model, n_workers=1)
    position = {"z": 0.25}
    p = model.nominal * np.random.default_rng(3).uniform(0.8, 1.2, model.nominal.size)
    names = ["km", "cm", "eta", "ms"]  # stiffness, viscous, loss factor and a mass (dA then has M^-1 dM terms)
    assert all(n in model.parameter_names for n in names)
    base = engine.evaluate(p, position, exact=True)
    d = exact_mode_derivatives(engine, p, position, poles=base.poles[0], parameters=names)
    np.testing.assert_allclose(d.poles, base.poles[0], rtol=1e-10)  # the same eigenvalues, picked by nearness
    row = np.argmax(np.abs(d.shapes), axis=0)
    cols = np.arange(d.shapes.shape[1])
    unit = d.shapes / d.shapes[row, cols]

    def normalized(batch):
        a = batch.complex_shapes[0]  # at the sensors
        return a / a[row, cols]

    for i, name in enumerate(names):
        k = model.parameter_names.index(name)
        h = 1e-6 * p[k]
        up, down = p.copy(), p.copy()
        up[k] += h
        down[k] -= h
        bu, bd = engine.evaluate(up, position, exact=True), engine.evaluate(down, position, exact=True)
        fd_poles = (bu.poles[0] - bd.poles[0]) / (2 * h)
        # relative step 1e-6: truncation ~1e-12, round-off ~1e-10 of the largest pole
        np.testing.assert_allclose(d.d_poles[i], fd_poles, atol=1e-6 * np.abs(fd_poles).max() + 1e-12)
        # shapes normalized at their largest sensor component: the derivative of that normalization is
        # (da - a da_max / a_max) / a_max, which removes the arbitrary scale from both sides
        da = d.d_shapes[i]
        analytic = (da - unit * da[row, cols]) / d.shapes[row, cols]
        fd_shapes = (normalized(bu) - normalized(bd)) / (2 * h)
        np.testing.assert_allclose(analytic, fd_shapes, atol=1e-5 * np.abs(fd_shapes).max() + 1e-12)


def _reference_exact_derivatives(model, p, position, poles, names, sensors):
    """The exact-mode derivatives as written before issue 24's speed work, kept here as the reference: numpy's eig of
    the complex state matrix built with ``inv(M)``, every parameter's modal expansion over all 2 n eigenvectors in
    a loop."""
    mats = model.matrices(p, position)
    dmats = model.matrix_derivatives(p, position, parameters=names)
    n = model.n_dof
    minv = np.linalg.inv(mats["M"])
    stiff, visc = mats["K"] + 1j * mats["H"], mats["C"] + mats["G"]
    state = np.zeros((2 * n, 2 * n), dtype=complex)
    state[:n, n:] = np.eye(n)
    state[n:, :n] = -(minv @ stiff)
    state[n:, n:] = -(minv @ visc)
    lam, vec = np.linalg.eig(state)
    inv = np.linalg.inv(vec)
    idx = np.array([int(np.argmin(np.abs(lam - pole))) for pole in poles])
    gap = lam[idx][None, :] - lam[:, None]
    near = np.zeros(gap.shape, dtype=bool)
    near[idx, np.arange(idx.size)] = True
    safe = np.where(near, 1.0, gap)
    w_low = inv[:, n:] @ minv
    v_q, v_v = vec[:n, idx], vec[n:, idx]
    d_poles, d_shapes = [], []
    for i in range(len(names)):
        d_low = (dmats["K"][i] + 1j * dmats["H"][i]) @ v_q + (dmats["C"][i] + dmats["G"][i]) @ v_v
        d_low -= dmats["M"][i] @ (minv @ (stiff @ v_q) + minv @ (visc @ v_v))
        g = -(w_low @ d_low)
        d_poles.append(g[idx, np.arange(idx.size)])
        d_shapes.append(sensors @ (vec[:n] @ np.where(near, 0.0, g / safe)))
    return lam[idx], sensors @ v_q, np.array(d_poles), np.array(d_shapes)


def _gauge_free(shapes, d_shapes):
    """Shapes scaled to 1 at their largest component and the derivatives of those (free of the complex scale)."""
    row = np.argmax(np.abs(shapes), axis=0)
    cols = np.arange(shapes.shape[1])
    pivot = shapes[row, cols]
    d_pivot = d_shapes[:, row, cols]  # (n_p, m)
    return shapes / pivot, (d_shapes - shapes[None] * (d_pivot / pivot)[:, None, :]) / pivot


def _assert_equal_to_the_reference(d, lam, shapes, d_poles, d_shapes) -> None:
    """Poles and their derivatives, and the shapes and theirs free of the gauge, equal the reference to round-off."""
    np.testing.assert_allclose(d.poles, lam, rtol=1e-12)
    np.testing.assert_allclose(d.d_poles, d_poles, rtol=1e-9, atol=1e-11 * np.abs(d_poles).max())
    unit, d_unit = _gauge_free(d.shapes, d.d_shapes)
    unit_ref, d_unit_ref = _gauge_free(shapes, d_shapes)
    np.testing.assert_allclose(unit, unit_ref, rtol=0, atol=1e-11)
    np.testing.assert_allclose(d_unit, d_unit_ref, rtol=0, atol=1e-9 * np.abs(d_unit_ref).max())


@pytest.mark.parametrize("reuse", [True, False])
def test_exact_mode_derivatives_equal_the_full_expansion_to_round_off(slide, reuse):
    # issue 24: the derivatives reuse the engine's eigen-decomposition of the residuals' exact solve and take all
    # parameters in one product; against the former path (own eig, one parameter at a time) to round-off
    model = NumericModel(slide)
    engine = ModalEngine(model, n_workers=1)
    position = {"z": 0.25}
    p = model.nominal * np.random.default_rng(5).uniform(0.8, 1.2, model.nominal.size)
    names = ["km", "cm", "eta", "ms", "kg0"]
    poles = engine.evaluate(p if reuse else p * (1 + 1e-3), position, exact=True).poles[0]
    if not reuse:  # a decomposition kept for another vector is not used
        poles = engine.evaluate(p[None, :].repeat(2, axis=0), position, exact=True).poles[0]
    assert (engine._state_eigensystem(p, position) is not None) == reuse
    d = exact_mode_derivatives(engine, p, position, poles=poles, parameters=names)
    sensors = engine.sensor_rows(position)[1]
    lam, shapes, d_poles, d_shapes = _reference_exact_derivatives(model, p, position, poles, names, sensors)
    _assert_equal_to_the_reference(d, lam, shapes, d_poles, d_shapes)


def test_the_exact_jacobian_reuses_the_residuals_eigen_decomposition(slide, monkeypatch):
    # issue 24: residuals and Jacobian at one vector take one eig of the state matrix per position, not two
    from cappe.estimate import ParameterSpace
    from cappe.estimate._exact_modal import ExactModalProblem

    model = NumericModel(slide)
    positions = [{"z": 0.0}, {"z": 0.25}]
    reference = ModalEngine(model).modal_data(positions)
    space = ParameterSpace.from_model(model, ["km", "cm", "eta", "kg0"])
    problem = ExactModalProblem(model, space, reference, (1.0, 0.01, 1.0))
    calls = []
    original = np.linalg.eig

    def counted(a, *args, **kwargs):
        calls.append(np.shape(a))
        return original(a, *args, **kwargs)

    monkeypatch.setattr(np.linalg, "eig", counted)
    p = space.start * 1.05
    problem.residuals(p)
    problem.jacobian(p)
    assert len(calls) == len(positions)


def test_exact_mode_derivatives_on_the_quadratic_eigenproblem_equal_the_full_expansion(slide, monkeypatch):
    # issue 24: modes solved on the quadratic eigenproblem are differentiated by the bordered (Nelson-type) system,
    # one LU per mode; against the state matrix's eig and modal expansion written in this file, to round-off, in the
    # expansion's own gauge (no component along the mode) and free of it
    import cappe.modal._engine as engine_module

    monkeypatch.setattr(engine_module, "QUADRATIC_FRACTION", 0.5)
    model = NumericModel(slide)
    engine = ModalEngine(model, n_modes=6, n_workers=1)
    position = {"z": 0.25}
    p = model.nominal * np.random.default_rng(5).uniform(0.8, 1.2, model.nominal.size)
    names = ["km", "cm", "eta", "ms", "kg0", "Fp"]
    poles = engine.evaluate(p, position, exact=True).poles[0]
    assert engine._quadratic_modes(p, position) is not None
    assert engine._state_eigensystem(p, position) is None  # no eig of the state matrix was made
    d = exact_mode_derivatives(engine, p, position, poles=poles[[4, 1, 2]], parameters=names)
    sensors = engine.sensor_rows(position)[1]
    lam, shapes, d_poles, d_shapes = _reference_exact_derivatives(model, p, position, poles[[4, 1, 2]], names,
                                                                   sensors)
    _assert_equal_to_the_reference(d, lam, shapes, d_poles, d_shapes)
    # the same gauge as the expansion: the derivatives of the shapes scaled as the reference's are the reference's
    scale = shapes[0] / d.shapes[0]
    np.testing.assert_allclose(d.d_shapes * scale[None, None, :], d_shapes, rtol=0,
                               atol=1e-9 * np.abs(d_shapes).max())
