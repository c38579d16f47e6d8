"""Parameter spaces, local uncertainty, the least-squares workhorse and the cappe.estimate/1 result."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cappe.estimate import (
    Estimator,
    ParameterEstimate,
    ParameterSpace,
    fit_least_squares,
    jacobian_uncertainty,
    read_estimate,
    write_estimate,
)
from cappe.exceptions import DataError, ModelError, NotFittedError
from cappe.model import NumericModel


def test_space_defaults_transform_and_full_vector(two_mass):
    space = ParameterSpace.from_model(two_mass, values={"c12": 0.5})
    assert space.names == ("m1", "m2", "k11", "k12", "k22", "c11", "c22")  # the model's unknowns
    assert space.log.all()  # all positive and bounded
    u = space.to_internal(space.start)
    np.testing.assert_allclose(u, np.log(space.start), rtol=1e-15)
    np.testing.assert_allclose(space.from_internal(u), space.start, rtol=1e-15)
    nm = NumericModel(two_mass)
    full = space.full(space.start * 2)
    assert full[nm.parameter_names.index("c12")] == 0.5  # a known parameter keeps the given value
    assert full[nm.parameter_names.index("k11")] == 2 * 1.38e6
    # chain rule factor dp/du of the log transform is p itself
    np.testing.assert_allclose(space.value_jacobian(u), space.start, rtol=1e-15)


def test_space_linear_transform_for_parameters_that_may_be_zero(two_mass):
    space = ParameterSpace.from_model(two_mass, ["c12", "k12"], bounds={"c12": (0.0, 5.0)})
    assert space.log.tolist() == [False, True]
    assert space.scale[0] == 5.0
    np.testing.assert_allclose(space.from_internal(space.to_internal([2.5, 1e5])), [2.5, 1e5])


def test_space_errors(two_mass):
    with pytest.raises(ModelError, match=r"unknowns \['k99'\] are not parameters of model 'two-mass-rig'"):
        ParameterSpace.from_model(two_mass, ["k11", "k99"])
    with pytest.raises(ModelError, match=r"unknowns must be listed once each; repeated: \['k11'\]"):
        ParameterSpace.from_model(two_mass, ["k11", "k11"])
    with pytest.raises(ModelError, match=r"bounds of 'k11' must satisfy lower < upper; got \[2e\+06, 1e\+06\]"):
        ParameterSpace.from_model(two_mass, ["k11"], bounds={"k11": (2e6, 1e6)})
    with pytest.raises(ModelError, match=r"start of 'k11' = 5e\+06 lies outside its bounds \[600000, 4e\+06\]"):
        ParameterSpace.from_model(two_mass, ["k11"], start={"k11": 5e6})
    with pytest.raises(ModelError, match=r"bounds or start given for \['k22'\], which are not among the unknowns"):
        ParameterSpace.from_model(two_mass, ["k11"], bounds={"k22": (1.0, 2.0)})
    space = ParameterSpace.from_model(two_mass, ["k11", "k22"])
    with pytest.raises(ModelError, match=r"values must give every unknown; missing \['k22'\]"):
        space.vector({"k11": 1.0})


def test_uncertainty_of_a_linear_model_matches_the_closed_form():
    rng = np.random.default_rng(0)
    x = np.linspace(0.0, 2.0, 40)
    design = np.column_stack([np.ones_like(x), x])
    truth = np.array([1.5, -0.7])
    y = design @ truth + 0.05 * rng.standard_normal(x.size)
    beta, *_ = np.linalg.lstsq(design, y, rcond=None)
    r = design @ beta - y
    unc = jacobian_uncertainty(names=["a", "b"], values=beta, jacobian=design, residuals=r)
    # textbook OLS: cov = s^2 (X^T X)^-1, s^2 = RSS / (n - p); t quantile for 38 dof is 2.0244
    s2 = r @ r / (x.size - 2)
    cov = s2 * np.linalg.inv(design.T @ design)
    np.testing.assert_allclose(unc.covariance, cov, rtol=1e-10)
    np.testing.assert_allclose(unc.std, np.sqrt(np.diag(cov)), rtol=1e-10)
    np.testing.assert_allclose(unc.ci95[:, 1] - beta, 2.024394164 * np.sqrt(np.diag(cov)), rtol=1e-8)
    np.testing.assert_allclose(unc.correlation[0, 1], cov[0, 1] / np.sqrt(cov[0, 0] * cov[1, 1]), rtol=1e-10)
    assert unc.identifiable.all()
    assert unc.rank == 2


def test_only_the_sum_of_two_masses_is_determined():
    # a rigid pair under a known force: the acceleration fixes m1 + m2 only
    f = np.linspace(1.0, 10.0, 30)
    m = np.array([1.2, 0.8])
    acc = f / m.sum()
    jac = np.column_stack([-acc / m.sum(), -acc / m.sum()])  # d(a_model)/dm_i, identical columns
    unc = jacobian_uncertainty(names=["m1", "m2", "k"], values=[*m, 5.0],
                               jacobian=np.column_stack([jac, np.sin(f)]), residuals=1e-3 * np.cos(3 * f))
    assert unc.identifiable.tolist() == [False, False, True]
    assert np.isnan(unc.std[:2]).all()
    assert np.isfinite(unc.std[2])
    # relative coordinates, largest weight positive: dm1/m1 : dm2/m2 = -0.8 : 1.2 keeps m1 + m2 (normalized)
    assert unc.combinations == ("+0.83 m2 -0.55 m1",)


def test_column_scale_keeps_a_determined_parameter_near_zero_determined():
    """An offset that happens to lie near 0 is determined as well as any other: relative scaling (the default,
    for physical parameters) shrinks its column to a false null direction; ``scale`` (unit-norm columns, as step 1
    of the two-step method gives) does not, and the covariance is then the textbook one."""
    x = np.linspace(0.0, 1.0, 40)
    design = np.column_stack([x, np.ones_like(x)])
    values = np.array([2.0, 1e-9])
    r = 0.01 * np.cos(7 * x)
    relative = jacobian_uncertainty(names=["a", "offset"], values=values, jacobian=design, residuals=r)
    assert relative.identifiable.tolist() == [True, False]
    unit = jacobian_uncertainty(names=["a", "offset"], values=values, jacobian=design, residuals=r,
                                scale=1.0 / np.sqrt(np.sum(design**2, axis=0)))
    assert unit.identifiable.all()
    np.testing.assert_allclose(unit.covariance, r @ r / 38 * np.linalg.inv(design.T @ design), rtol=1e-10)
    with pytest.raises(ValueError, match="scale must hold 2 finite positive"):
        jacobian_uncertainty(names=["a", "offset"], values=values, jacobian=design, residuals=r, scale=[1.0, 0.0])


def test_least_squares_recovers_stiffnesses_from_frequencies(two_mass):
    nm = NumericModel(two_mass)
    truth = {"k11": 1.1e6, "k22": 0.3e6}
    target = nm.system(truth).undamped_modes()[0]
    space = ParameterSpace.from_model(nm, ["k11", "k22"], start={"k11": 2.5e6, "k22": 0.1e6})

    def residuals(p):
        return nm.system(space.mapping(p)).undamped_modes()[0] / target - 1

    est = fit_least_squares("test", space, residuals)
    assert est.success
    np.testing.assert_allclose(est.values, [1.1e6, 0.3e6], rtol=1e-7)  # exact data: solver tolerance
    assert est.diagnostics["at_bound"] == []
    assert est.identifiable.all()


def test_result_round_trip_and_nulls(tmp_path):
    est = ParameterEstimate(
        "one-step", ("m1", "k11"), np.array([1.3, 1.4e6]), np.array([np.nan, 2e3]),
        np.array([[np.nan, np.nan], [1.396e6, 1.404e6]]), np.array([[1.0, np.nan], [np.nan, 1.0]]),
        np.array([False, True]), ("+1.00 m1",), 0.25, False, "max evaluations", {"iterations": 12, "h": np.ones(2)},
    )
    path = write_estimate(tmp_path / "e.json", est)
    data = json.loads(path.read_text())
    assert data["format"] == "cappe.estimate/1"
    assert data["parameters"] == {"m1": 1.3, "k11": 1.4e6}
    assert data["uncertainty"]["std"]["m1"] is None
    assert data["identifiable"] == {"m1": False, "k11": True, "combinations": ["+1.00 m1"]}
    assert data["diagnostics"] == {"message": "max evaluations", "iterations": 12, "h": [1.0, 1.0]}
    back = read_estimate(path)
    np.testing.assert_array_equal(back.values, est.values)
    np.testing.assert_array_equal(back.ci95, est.ci95)
    assert back.message == "max evaluations"
    assert back.success is False
    assert list(back.to_dataframe().index) == ["m1", "k11"]
    (tmp_path / "bad.json").write_text('{"format": "cappe.modal/1"}')
    with pytest.raises(DataError, match=r"bad.json: format must be 'cappe.estimate/1'; got 'cappe.modal/1'"):
        read_estimate(tmp_path / "bad.json")
    with pytest.raises(DataError, match=r"cannot read estimate file .*none\.json: no such file"):
        read_estimate(tmp_path / "none.json")
    (tmp_path / "bad.json").write_text("[1]")
    with pytest.raises(DataError, match=r"bad\.json: an estimate file must hold a JSON object; got list"):
        read_estimate(tmp_path / "bad.json")
    (tmp_path / "bad.json").write_text("[" * 100_000)
    with pytest.raises(DataError, match=r"estimate file .*bad\.json nests arrays or objects too deeply to be read"):
        read_estimate(tmp_path / "bad.json")


class _Minimal(Estimator):
    method = "minimal"

    def _fit(self, model, space, data, rng):
        return fit_least_squares(self.method, space, lambda p: p / space.start - 1)


def test_estimator_is_abstract_and_unfitted_use_is_an_error(two_mass):
    with pytest.raises(TypeError, match="abstract"):
        Estimator(two_mass)
    with pytest.raises(NotFittedError, match=r"_Minimal is not fitted yet; call fit\(data\) first"):
        _ = _Minimal(two_mass).estimate_


@pytest.mark.parametrize("strategy", ["multistart", "differential-evolution"])
def test_global_search_escapes_a_local_minimum(two_mass, strategy):
    # frequencies of the rig are symmetric-ish in (k11, k22): from a start in the wrong basin a local fit alone
    # stays there; the global stage finds the basin of the truth (then the local fit polishes it)
    nm = NumericModel(two_mass)
    truth = {"k11": 1.1e6, "k22": 0.3e6}
    target = nm.system(truth).undamped_modes()[0]
    space = ParameterSpace.from_model(nm, ["k11", "k22"], start={"k11": 0.61e6, "k22": 0.59e6})

    def residuals(p):
        return nm.system(space.mapping(p)).undamped_modes()[0] / target - 1

    stuck = fit_least_squares("test", space, residuals)  # local only: ends on the bounds, far from the truth
    assert stuck.cost > 0.1
    est = fit_least_squares("test", space, residuals, strategy=strategy, rng=1)
    np.testing.assert_allclose(est.values, [1.1e6, 0.3e6], rtol=1e-6)
    assert est.diagnostics["global_search"]["strategy"] == strategy


def test_the_package_loads_each_public_name_from_its_module_on_first_use():
    """cappe.estimate imports its modules lazily (SPEC 1, from the imports of __init__.pyi): its names are the stub's
    __all__ (which type checkers read), each resolves, an unknown name is an AttributeError naming it, and a fresh
    interpreter importing the package and the CLI's method registry loads none of the estimators' modules."""
    import ast
    import subprocess
    import sys
    from pathlib import Path

    import cappe.estimate as package

    stub = ast.parse(Path(package.__file__).with_suffix(".pyi").read_text())
    listed = next(node.value for node in stub.body if isinstance(node, ast.Assign)
                  and any(isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets))
    assert sorted(package.__all__) == sorted(ast.literal_eval(listed))
    for name in package.__all__:
        assert getattr(package, name) is not None, name
    assert package.AutomatedIdentification.__module__ == "cappe.estimate._automated"
    assert set(package.__all__) <= set(dir(package))
    with pytest.raises(AttributeError, match="DirectEstimatr"):
        _ = package.DirectEstimatr
    code = ("import sys, cappe.estimate, cappe.estimate._registry; "
            "print(sorted(m for m in sys.modules if m.startswith('cappe.estimate.')), 'sympy' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "['cappe.estimate._registry'] False"
