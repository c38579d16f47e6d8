"""Stiffness factors of parameter groups from FRFs (cappe.monitor._estimation): the analytic Jacobian against
finite differences, noise-free recovery, honest uncertainties under seeded noise, the direction of a fault
parameter against a finite change, and errors."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.stats import chi2

from cappe.exceptions import ConvergenceWarning, DataError
from cappe.model import NumericModel, load_model
from cappe.monitor import FactorEstimator, default_components
from cappe.systems.frf import FRFData

SPINDLE_BAND = (148.5, 1213.3)  # default_config's band of the spindle: 0.7 x the first, 1.1 x the last mode


@pytest.fixture(scope="module")
def spindle_groups(spindle) -> dict[str, list[str]]:
    return {c.name: list(c.parameters) for c in default_components(spindle.structure)}


def component_estimator(spindle, groups, **kwargs) -> FactorEstimator:
    return FactorEstimator(spindle, groups, inputs=spindle.input_names, outputs=spindle.output_names,
                           band=SPINDLE_BAND, **kwargs)


def simulate(model, groups, factors, freq, inputs, outputs, base=None):
    """FRFs of ``model`` with every parameter of group g scaled by factors[g] (from ``base`` overrides)."""
    base = dict(base or {})
    ref = model.vector(base)
    params = dict(base)
    for members, f in zip(groups.values(), factors, strict=True):
        for p in members:
            params[p] = ref[model.parameter_names.index(p)] * f
    return model.system(params).frf(freq, list(inputs), list(outputs))


def central_jacobian(est, s, freq, h=1e-5):
    """dH/ds by central differences of the estimator's own frf()."""
    out = []
    for g in range(s.size):
        e = np.zeros(s.size)
        e[g] = h
        out.append((est.frf(s + e, freq) - est.frf(s - e, freq)) / (2 * h))
    return np.array(out)


def assert_jacobian_matches(est, s, freq):
    p = est.parameters(s)
    x, lt = est._dynamic(p, freq)
    analytic = est._jacobian(p, freq, x, lt)
    numeric = central_jacobian(est, s, freq)
    for g, name in enumerate(est.names):
        scale = np.max(np.abs(analytic[g]))
        assert scale > 0, name
        # central differences with h = 1e-5: truncation h^2/6 |H'''| ~ 1e-10 |H'| times up to ~1e3 near lightly
        # damped resonances, rounding eps |H| / h ~ 1e-11; 1e-6 of the group's largest entry bounds both
        np.testing.assert_allclose(analytic[g], numeric[g], rtol=0, atol=1e-6 * scale, err_msg=name)


# -- Jacobian --------------------------------------------------------------------------------------------------
def test_analytic_jacobian_matches_central_differences_on_the_spindle(spindle):
    # groups touching K (stiffness, and preload through the bearing law), C (damping), M and G (the shaft mass
    # enters both), G alone (the spin speed, nonzero in the reference)
    groups = {"front": ["kfx", "kfy", "kfz"], "screws": ["kh1x", "kh2y", "kh3z"], "damping": ["cfx", "cry"],
              "mass": ["ms"], "spin": ["Omega"], "preload": ["preload"]}
    est = FactorEstimator(spindle, groups, reference={"Omega": 300.0}, inputs=["Fx", "Fy"],
                          outputs=["sx", "hax", "hray"], band=(100, 1200))
    s = np.random.default_rng(0).uniform(-0.2, 0.2, len(groups))
    assert_jacobian_matches(est, s, np.linspace(150, 1150, 37))


def test_analytic_jacobian_matches_central_differences_with_hysteretic_damping():
    # the machine tool has structural (loss-factor) damping: groups moving H alone and K with H together
    tool = NumericModel(load_model("builtin:uniaxial-machine-tool"))
    groups = {"joint": ["kj_x", "kj_y"], "loss": ["eta_j1_x", "eta_j2_y"], "guide": ["lgs1_cx"], "table": ["m_t"]}
    est = FactorEstimator(tool, groups, position={"z": 0.3}, inputs=["Ftx", "Fbx"], outputs=["atx", "abx", "aty"],
                          band=(10, 500))
    assert_jacobian_matches(est, np.random.default_rng(1).uniform(-0.2, 0.2, len(groups)), np.linspace(20, 480, 23))


def test_groups_sharing_a_parameter_are_rejected_or_differentiated_consistently(rig):
    # parameters() lets the last group that names a parameter set it, while the Jacobian differentiates it in
    # every group: either the constructor refuses overlapping groups or the two agree
    try:
        est = FactorEstimator(rig, {"a": ["k11", "k12"], "b": ["k12"]}, inputs=["F1"], outputs=["d1", "d2"],
                              band=(50, 250))
        error = None
    except DataError as exc:
        est, error = None, str(exc)
    if error is not None:
        assert "k12" in error
    else:
        assert_jacobian_matches(est, np.array([0.1, -0.05]), np.linspace(60, 240, 19))


# -- noise-free recovery ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_noise_free_recovery_of_random_component_factors(spindle, spindle_groups, seed):
    factors = np.random.default_rng(seed).uniform(0.7, 1.3, len(spindle_groups))
    freq = np.arange(140.0, 1220.0, 2.0)
    data = simulate(spindle, spindle_groups, factors, freq, spindle.input_names, spindle.output_names)
    est = component_estimator(spindle, spindle_groups)
    result = est.estimate(data)
    assert result.success
    assert result.message == "converged"
    assert result.names == tuple(spindle_groups)
    # the fit stops when a step is below 1e-9 or the cost stops improving at 1e-12 relative: on exact data
    # the log-factors are right to far better than 1e-8
    np.testing.assert_allclose(result.log_factor, np.log(factors), rtol=0, atol=1e-8)
    np.testing.assert_allclose(result.factor, factors, rtol=1e-8)
    assert np.all(result.std < 1e-8)  # no residual, no uncertainty


def test_reference_overrides_define_factor_one(spindle, spindle_groups):
    base = {"kfx": 72e6, "kh2y": 110e6}
    freq = np.arange(140.0, 1220.0, 4.0)
    data = simulate(spindle, spindle_groups, np.ones(len(spindle_groups)), freq, ["Fx", "Fy"], ["sx", "hax", "hay"],
                    base=base)
    est = FactorEstimator(spindle, spindle_groups, reference=base, inputs=["Fx", "Fy"], outputs=["sx", "hax", "hay"],
                          band=SPINDLE_BAND)
    p = est.parameters(np.log(np.full(len(spindle_groups), 0.9)))
    names = spindle.parameter_names
    assert p[names.index("kfx")] == pytest.approx(0.9 * 72e6, rel=1e-14)
    assert p[names.index("kh2y")] == pytest.approx(0.9 * 110e6, rel=1e-14)
    assert p[names.index("ms")] == 10.67  # outside every group: untouched
    np.testing.assert_allclose(est.estimate(data).log_factor, 0.0, atol=1e-8)  # same stopping rule as above


# -- uncertainty under seeded noise ----------------------------------------------------------------------------
def test_reported_uncertainty_is_honest_under_relative_noise(spindle, spindle_groups):
    # 30 realizations of 1 % complex relative noise on every line and channel. If the reported covariance C is
    # honest, e' C^-1 e ~ chi2(6) for each fit, so their sum over 30 independent fits is chi2(180); and each
    # component's normalized error e_g / sqrt(C_gg) has unit variance, its mean square over 30 fits chi2(30)/30.
    # Bands: the two-sided 99.9 % quantiles (Bonferroni over the 6 components for the second).
    truth = np.array([0.9, 1.0, 1.05, 1.0, 0.95, 1.0])
    freq = np.arange(140.0, 1220.0, 3.0)
    clean = simulate(spindle, spindle_groups, truth, freq, spindle.input_names, spindle.output_names)
    est = component_estimator(spindle, spindle_groups)
    rng = np.random.default_rng(2024)
    n_real = 30
    mahalanobis, normalized = [], []
    for _ in range(n_real):
        noise = 0.01 * (rng.standard_normal(clean.H.shape) + 1j * rng.standard_normal(clean.H.shape)) / np.sqrt(2)
        result = est.estimate(FRFData(clean.freq, clean.H * (1 + noise), clean.input_names, clean.output_names))
        assert result.success
        err = result.log_factor - np.log(truth)
        mahalanobis.append(err @ np.linalg.solve(result.covariance, err))
        normalized.append(err / np.sqrt(np.diag(result.covariance)))
        # the delta-method std of the factor is the log-factor std times the factor
        np.testing.assert_allclose(result.std, result.factor * np.sqrt(np.diag(result.covariance)), rtol=1e-12)
    total = float(np.sum(mahalanobis))
    lo, hi = chi2.ppf([0.0005, 0.9995], 6 * n_real)
    assert lo < total < hi, total / (6 * n_real)
    mean_square = np.mean(np.array(normalized) ** 2, axis=0)
    lo, hi = chi2.ppf([0.0005 / 6, 1 - 0.0005 / 6], n_real) / n_real
    assert np.all((lo < mean_square) & (mean_square < hi)), mean_square
    # the relative uncertainty is small against the 5-10 % changes monitored, so the linearization holds
    assert np.all(np.sqrt(np.diag(result.covariance)) < 0.01)


# -- direction of a fault parameter ----------------------------------------------------------------------------
def test_preload_direction_is_the_fit_of_a_small_preload_change(spindle, spindle_groups):
    est = component_estimator(spindle, spindle_groups)
    freq = np.arange(140.0, 1220.0, 2.0)
    lines = freq[(freq >= SPINDLE_BAND[0]) & (freq <= SPINDLE_BAND[1])]
    direction = est.direction("preload", lines)  # on the fit's own lines, so that both use the same weights
    h = 0.02
    fits = {}
    for preload in (1 + h, 1 - h):
        data = spindle.system({"preload": preload}).frf(freq, list(spindle.input_names), list(spindle.output_names))
        # exact data that the factors describe only to first order (the preload moves radial and axial stiffness
        # by different laws): the misfit check would rightly call that a model mismatch, so it is off here
        fits[preload] = est.estimate(data, misfit_ratio=None).log_factor
    size = np.max(np.abs(direction))
    assert size > 0.1  # the bearings move noticeably: the comparison below is not between zeros
    # first order: s(1.02) = ln(1.02) d + O(ln(1.02)^2), a remainder of order h relative to d
    np.testing.assert_allclose(fits[1 + h] / np.log(1 + h), direction, rtol=0, atol=h * size)
    # central difference: the remainder is of order h^2
    central = (fits[1 + h] - fits[1 - h]) / (np.log(1 + h) - np.log(1 - h))
    np.testing.assert_allclose(central, direction, rtol=0, atol=h**2 * size)
    # the bearing groups carry it: front and rear dominate the screws
    assert min(abs(direction[0]), abs(direction[1])) > 5 * np.max(np.abs(direction[2:]))
    # the default 400-line grid over the band gives the same signature to the same first order
    np.testing.assert_allclose(est.direction("preload"), direction, rtol=0, atol=h * size)


def test_direction_of_a_group_parameter_is_its_unit_vector(rig):
    est = FactorEstimator(rig, {"coupling": ["k12"], "base": ["k11"]}, inputs=["F1"], outputs=["d1", "d2"],
                          band=(50, 250))
    # the parameter's FRF change is the group's own Jacobian column: its projection is exact
    np.testing.assert_allclose(est.direction("k12"), [1.0, 0.0], atol=1e-10)
    np.testing.assert_allclose(est.direction("k11", np.linspace(60, 240, 50)), [0.0, 1.0], atol=1e-10)
    np.testing.assert_array_equal(est.direction("c12"), [0.0, 0.0])  # c12 = 0: a relative change is no change


# -- the two-mass rig ------------------------------------------------------------------------------------------
def test_two_mass_rig_example(rig):
    groups = {"coupling": ["k12"], "base": ["k11"]}
    freq = np.arange(50.0, 250.0)
    data = rig.system({"k12": 0.9 * 120e3, "k11": 1.1 * 1380e3}).frf(freq, ["F1"], ["d1", "d2"])
    est = FactorEstimator(rig, groups, inputs=["F1"], outputs=["d1", "d2"], band=(50, 250))
    result = est.estimate(data)
    np.testing.assert_allclose(result.factor, [0.9, 1.1], rtol=1e-8)  # exact data: the stopping rule's 1e-8
    again = est.estimate(data, start=np.log([0.92, 1.08]))  # from a nearby start: the same optimum
    np.testing.assert_allclose(again.factor, [0.9, 1.1], rtol=1e-8)
    d = result.to_dict()
    assert d["names"] == ["coupling", "base"]
    assert d["success"] is True
    assert d["message"] == "converged"
    np.testing.assert_allclose(d["factor"], [0.9, 1.1], rtol=1e-8)
    np.testing.assert_allclose(d["log_factor"], np.log([0.9, 1.1]), atol=1e-8)
    assert len(d["covariance"]) == 2
    assert d["iterations"] == result.iterations >= 1
    # lines outside the band are not used: adding nonsense there changes nothing
    outside = FRFData(np.concatenate([[10.0, 20.0], freq, [300.0]]),
                      np.concatenate([np.ones((2, 1, 2)), data.H, np.ones((2, 1, 1))], axis=-1),
                      data.input_names, data.output_names)
    np.testing.assert_allclose(est.estimate(outside).factor, [0.9, 1.1], rtol=1e-8)


@pytest.mark.parametrize("component", ["front", "screw2"])
def test_a_fifty_percent_loss_converges_from_the_reference(spindle, spindle_groups, component):
    # the fit's docstring: the log residual converges from the reference model to losses of 50 %
    factors = np.ones(len(spindle_groups))
    factors[list(spindle_groups).index(component)] = 0.5
    freq = np.arange(140.0, 1220.0, 4.0)
    data = simulate(spindle, spindle_groups, factors, freq, spindle.input_names, spindle.output_names)
    result = component_estimator(spindle, spindle_groups).estimate(data)
    assert result.success
    np.testing.assert_allclose(result.factor, factors, rtol=1e-8)  # exact data: the stopping rule's 1e-8


def test_a_thirty_percent_coupling_loss_on_the_rig_is_found_or_flagged(rig):
    # the same claim on the lightly damped rig (zeta 0.05 % and 0.45 %): from the reference a 30 % loss of the
    # coupling spring ends in a local minimum of the wrapped-phase log residual (factor 0.955, a residual
    # sigma of 0.39 on exact data). A fit may miss a far optimum, but then it must say so (success=False and a
    # ConvergenceWarning, STYLE "Errors"), not report success at a 39 % misfit.
    est = FactorEstimator(rig, {"coupling": ["k12"]}, inputs=["F1"], outputs=["d1", "d2"], band=(50, 250))
    data = rig.system({"k12": 0.7 * 120e3}).frf(np.arange(50.0, 250.0), ["F1"], ["d1", "d2"])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = est.estimate(data)
    if result.success:
        np.testing.assert_allclose(result.factor, [0.7], rtol=1e-8)
    else:
        assert any(issubclass(w.category, ConvergenceWarning) for w in caught)


# -- warnings and errors ---------------------------------------------------------------------------------------
def test_unidentifiable_group_warns_and_reports_failure(rig):
    # c12 is zero in the reference: its log-factor moves nothing, a zero Jacobian column
    est = FactorEstimator(rig, {"coupling": ["k12"], "c12": ["c12"]}, inputs=["F1"], outputs=["d1", "d2"],
                          band=(50, 250))
    data = rig.system({"k12": 0.9 * 120e3}).frf(np.arange(50.0, 250.0), ["F1"], ["d1", "d2"])
    with pytest.warns(ConvergenceWarning, match=r"stiffness-factor fit: .*Jacobian rank 1 < 2 groups \(not all "
                                                 r"identifiable from these channels\)"):
        result = est.estimate(data)
    assert not result.success
    assert result.factor[0] == pytest.approx(0.9, rel=1e-8)  # the identifiable group is still right


def test_iteration_limit_warns(rig):
    est = FactorEstimator(rig, {"coupling": ["k12"], "base": ["k11"]}, inputs=["F1"], outputs=["d1", "d2"],
                          band=(50, 250))
    data = rig.system({"k12": 0.6 * 120e3, "k11": 0.7 * 1380e3}).frf(np.arange(50.0, 250.0), ["F1"], ["d1", "d2"])
    with pytest.warns(ConvergenceWarning, match=r"stiffness-factor fit: maximum number of iterations reached"):
        result = est.estimate(data, max_iter=1)
    assert not result.success
    assert result.iterations == 1


def test_errors(rig):
    kwargs = {"inputs": ["F1"], "outputs": ["d1", "d2"], "band": (50, 250)}
    with pytest.raises(DataError, match=r"FactorEstimator needs at least one group"):
        FactorEstimator(rig, {}, **kwargs)
    with pytest.raises(DataError, match=r"group 'x': parameters \['k12', 'bogus'\] must be non-empty model "
                                        r"parameters; unknown \['bogus'\]"):
        FactorEstimator(rig, {"x": ["k12", "bogus"]}, **kwargs)
    with pytest.raises(DataError, match=r"group 'x': parameters \[\] must be non-empty model parameters; unknown \[\]"):
        FactorEstimator(rig, {"x": []}, **kwargs)
    est = FactorEstimator(rig, {"coupling": ["k12"], "base": ["k11"]}, **kwargs)
    with pytest.raises(DataError, match=r"unknown parameter 'bolt'; the model has \['m1', 'm2', 'k11'"):
        est.direction("bolt")
    freq = np.arange(50.0, 250.0)
    only_d1 = rig.system({}).frf(freq, ["F1"], ["d1"])
    with pytest.raises(DataError, match=r"FRF data lack channels \['d2'\]; they have outputs \['d1'\] and inputs "
                                        r"\['F1'\]"):
        est.estimate(only_d1)
    other_input = rig.system({}).frf(freq, ["F2"], ["d1", "d2"])
    with pytest.raises(DataError, match=r"FRF data lack channels \['F1'\]"):
        est.estimate(other_input)
    few = rig.system({}).frf(np.array([10.0, 60.0, 70.0, 80.0, 300.0]), ["F1"], ["d1", "d2"])
    with pytest.raises(DataError, match=r"FRF data have 3 lines in the band 50-250 Hz; at least 4 are needed"):
        est.estimate(few)
    good = rig.system({}).frf(freq, ["F1"], ["d1", "d2"])
    h = good.H.copy()
    h[0, 0, 40] = np.nan
    with pytest.raises(DataError, match=r"FRF data contain non-finite values in the band"):
        est.estimate(FRFData(freq, h, good.input_names, good.output_names))
    h = good.H.copy()
    h[0, 0, 40] = 0.0  # d1 at 90 Hz, near the first mode: a line the fit uses
    with pytest.raises(DataError, match=r"FRF data are exactly zero on lines where the model responds"):
        est.estimate(FRFData(freq, h, good.input_names, good.output_names))


def test_no_warning_on_a_clean_fit(rig):
    est = FactorEstimator(rig, {"coupling": ["k12"]}, inputs=["F1"], outputs=["d1", "d2"], band=(50, 250))
    data = rig.system({"k12": 0.95 * 120e3}).frf(np.arange(50.0, 250.0), ["F1"], ["d1", "d2"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert est.estimate(data).success
