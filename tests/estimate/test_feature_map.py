"""Feature maps (thesis 3.6.5, 5.4.4): parameters from modal features through a precomputed map.

The measured features come from ``MechanicalSystem.modes("first-order")`` (a dense eigen solve per parameter
vector), independent of the batched modal engine that builds the maps; standard errors are checked against
linear propagation of the feature noise through the modal engine's analytic derivatives.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from cappe.estimate import read_estimate, write_estimate
from cappe.estimate._feature_map import FeatureMapEstimator
from cappe.exceptions import ConvergenceWarning, DataError, ModelError
from cappe.io.modal import ModalData, ModalDataSet
from cappe.modal import ModalEngine
from cappe.model import NumericModel

RIG_TRUTH = {"k11": 1.6e6, "k22": 0.3e6}


@pytest.fixture(scope="module")
def rig(two_mass):
    return NumericModel(two_mass)


def _modes(nm, params, position=None):
    return nm.system(params, position).modes("first-order")


def _propagated_std(nm, params, names, relative_noise, position=None):
    """Standard errors of a least-squares inversion of frequencies with the given relative noise."""
    der = ModalEngine(nm, sensors="dofs").derivatives(params, position)
    cols = [nm.parameter_names.index(n) for n in names]
    jac = der.d_frequency[:, cols] / (relative_noise * der.frequency[:, None])
    return np.sqrt(np.diag(np.linalg.inv(jac.T @ jac)))


def test_preload_from_the_spindle_frequencies_and_damping(spindle):
    nm = NumericModel(spindle)
    truth = _modes(nm, {"preload": 0.7})
    data = {"frequency": truth.frequency[:5], "damping": truth.damping[:5]}
    est = FeatureMapEstimator(nm, ["preload"], rng=0).fit(data).estimate_
    assert est.success, est.message
    # noise-free features, a 41-point cubic map over log(preload) in [0.05, 1.5]: measured 1e-6 relative
    assert abs(est.parameters["preload"] / 0.7 - 1) < 1e-4
    # the uncertainty: 0.5 % frequency and 10 % damping noise propagated through the analytic derivatives
    der = ModalEngine(nm, sensors="dofs").derivatives({"preload": 0.7})
    col = nm.parameter_names.index("preload")
    jac = np.concatenate([der.d_frequency[:5, col] / (0.005 * der.frequency[:5]),
                          der.d_damping[:5, col] / (0.1 * der.damping[:5])])
    # the surrogate's slope and its (tiny) error add to the analytic linearization: 1 % agreement
    np.testing.assert_allclose(est.std[0], 1 / np.sqrt(jac @ jac), rtol=0.01)
    diag = est.diagnostics
    assert diag["map"]["kind"] == "grid"
    assert len(diag["map"]["grid"][0]) == 41
    assert np.asarray(diag["map"]["features"]).shape == (41, 10)  # 5 frequencies, 5 damping ratios
    # the map is monotonic in preload for the first mode: stiffer bearings, higher frequency (thesis Fig. 5.30)
    assert np.all(np.diff(np.asarray(diag["map"]["features"])[:, 0]) > 0)


@pytest.mark.parametrize(("resolution", "tolerance"), [(7, 2e-4), (21, 2e-5)])
def test_two_stiffnesses_from_two_frequencies_accuracy_vs_resolution(rig, resolution, tolerance):
    truth = _modes(rig, RIG_TRUTH)
    est = FeatureMapEstimator(rig, ["k11", "k22"], resolution=resolution, rng=0).fit(
        {"frequency": truth.frequency}).estimate_
    assert est.success, est.message
    # noise-free: the error is the cubic interpolation error of the map; measured 4e-5 with 7 points per axis
    # (spacing 0.32 in log k11) and 3e-6 with 21 points
    error = np.abs(list(est.relative_error(RIG_TRUTH).values()))
    assert error.max() < tolerance
    expected = _propagated_std(rig, RIG_TRUTH, ["k11", "k22"], 0.005)
    np.testing.assert_allclose(est.std, expected, rtol=0.01)
    assert est.ci95[0, 1] - est.values[0] == pytest.approx(1.959964 * est.std[0], rel=1e-6)  # normal quantile


def test_noisy_frequencies_land_within_their_uncertainty(rig):
    truth = _modes(rig, RIG_TRUTH)
    rng = np.random.default_rng(3)
    freq = truth.frequency * (1 + 0.005 * rng.standard_normal(2))
    est = FeatureMapEstimator(rig, ["k11", "k22"], rng=0).fit({"frequency": freq}).estimate_
    z = (est.values - np.array(list(RIG_TRUTH.values()))) / est.std
    assert np.all(np.abs(z) < 3)  # seeded 0.5 % noise, standard errors from the same 0.5 %
    assert np.abs(z).max() > 0.05  # and the noise did move the estimate


def test_three_unknowns_on_a_sobol_map_with_rbf_and_quadratic_surrogates(rig):
    truth_params = {"k11": 1.6e6, "k22": 0.3e6, "c11": 30.0}
    truth = _modes(rig, truth_params)
    data = {"frequency": truth.frequency, "damping": truth.damping}
    rbf = FeatureMapEstimator(rig, list(truth_params), samples=256, rng=0).fit(data).estimate_
    assert rbf.success, rbf.message
    assert rbf.diagnostics["map"]["kind"] == "sobol"
    assert np.asarray(rbf.diagnostics["map"]["samples"]).shape == (256, 3)
    error = rbf.relative_error(truth_params)
    # thin-plate RBF on 256 Sobol points: measured 7e-5, 4e-4 and 1e-2 (the damping map is the roughest)
    assert abs(error["k11"]) < 1e-3
    assert abs(error["k22"]) < 2e-3
    assert abs(error["c11"]) < 0.03
    quad = FeatureMapEstimator(rig, list(truth_params), samples=256, surrogate="quadratic", rng=0).fit(
        data).estimate_
    # a quadratic surface cannot follow the map across the box: measured errors up to 16 % for c11, which its
    # own error estimate (added to the feature noise) covers
    assert quad.diagnostics["surrogate"]["kind"] == "quadratic response surface"
    assert np.all(np.abs(quad.values - rbf.values) < 3 * quad.std)
    assert np.all(quad.std > rbf.std)


def test_two_positions_of_a_slide_from_a_modal_data_file(slide, tmp_path):
    nm = NumericModel(slide)
    truth = {"kg0": 3.6e7, "km": 7.0e6}
    sets = []
    for z in (0.1, 0.4):
        modes = _modes(nm, truth, {"z": z})
        pick = [0, 3, 4]  # distinct modes (2 and 3 lie 0.4 % apart and swap with the parameters)
        sets.append(ModalDataSet({"z": z}, modes.frequency[pick], modes.damping[pick], np.zeros((1, 3), complex)))
    data = ModalData(("slide:x",), tuple(sets))
    est = FeatureMapEstimator(nm, ["kg0", "km"], bounds={"kg0": (1e7, 1e8), "km": (2e6, 2e7)}, modes=[0, 3, 4],
                              rng=0).fit(data).estimate_
    assert est.success, est.message
    # noise-free features at two axis positions, 21 x 21 cubic map: measured 5e-5
    np.testing.assert_allclose(est.values, list(truth.values()), rtol=5e-4)
    assert est.diagnostics["map"]["positions"] == [{"z": 0.1}, {"z": 0.4}]
    assert "f4[set 1]" in est.diagnostics["measured"]
    write_estimate(tmp_path / "map.json", est)
    doc = json.loads((tmp_path / "map.json").read_text())
    assert doc["method"] == "feature-map"
    assert len(doc["diagnostics"]["map"]["features"]) == 441
    np.testing.assert_allclose(read_estimate(tmp_path / "map.json").values, est.values, rtol=1e-15)


def test_a_frequency_outside_the_map_is_a_data_error(rig):
    with pytest.raises(DataError, match=r"measured frequency f2 = 500 Hz lies outside the feature map's range "
                                        r"\[\d+\.\d+, 274\.\d+\] Hz for \['k11', 'k22'\] within their bounds"):
        FeatureMapEstimator(rig, ["k11", "k22"], resolution=9).fit({"frequency": [90.0, 500.0]})


def test_features_no_parameters_within_the_bounds_reach_fail_with_the_reason(rig):
    # each frequency lies inside the map's range, the pair does not (32 standard deviations from every map point)
    with pytest.warns(ConvergenceWarning, match="the measured features are not reached within the bounds"):
        est = FeatureMapEstimator(rig, ["k11", "k22"], rng=0).fit({"frequency": [120.0, 120.0]})
    assert not est.estimate_.success
    assert est.estimate_.diagnostics["misfit"] > 10.8  # chi-square with 1 dof at p = 1e-3


def test_errors_name_the_argument_and_the_rule(rig):
    data = {"frequency": [90.0, 170.0]}
    with pytest.raises(DataError, match="feature-map estimation needs ModalData or a mapping of features; got list"):
        FeatureMapEstimator(rig, ["k11"]).fit([90.0])
    with pytest.raises(DataError, match=r"feature data must give 'frequency' \(Hz\); got keys \['damping'\]"):
        FeatureMapEstimator(rig, ["k11"]).fit({"damping": [0.01]})
    with pytest.raises(DataError, match="feature data need finite frequencies > 0 Hz"):
        FeatureMapEstimator(rig, ["k11"]).fit({"frequency": [-1.0]})
    with pytest.raises(DataError, match=r"surrogate must be 'auto', 'grid', 'rbf' or 'quadratic'; got 'spline'"):
        FeatureMapEstimator(rig, ["k11"], surrogate="spline").fit(data)
    with pytest.raises(DataError, match=r"a grid map takes one or two unknowns; got 3"):
        FeatureMapEstimator(rig, ["k11", "k12", "k22"], surrogate="grid").fit(data)
    with pytest.raises(ModelError, match=r"a feature map needs finite bounds; \['c12'\] have none"):
        FeatureMapEstimator(rig, ["c12"], bounds={"c12": (0.0, np.inf)}).fit(data)
    with pytest.raises(DataError, match="frequency_noise must be a fraction > 0; got 0.0"):
        FeatureMapEstimator(rig, ["k11"], frequency_noise=0.0).fit(data)
    with pytest.raises(DataError, match="resolution must be an integer >= 4; got 3"):
        FeatureMapEstimator(rig, ["k11"], resolution=3).fit(data)
    with pytest.raises(DataError, match=r"features must be a non-empty selection of \['frequency', 'damping'\]"):
        FeatureMapEstimator(rig, ["k11"], features=["shape"]).fit(data)
    with pytest.raises(DataError, match="damping features need measured damping ratios > 0 in every set"):
        FeatureMapEstimator(rig, ["k11"], features=["damping"]).fit(data)
    with pytest.raises(DataError, match="modes must name one model mode per measured mode; set 0 has 2 modes"):
        FeatureMapEstimator(rig, ["k11"], modes=[0]).fit(data)
    with pytest.raises(DataError, match=r"modes must be distinct integers from 0 to 1 \(model modes\); got \[0, 5\]"):
        FeatureMapEstimator(rig, ["k11"], modes=[0, 5]).fit(data)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        FeatureMapEstimator(rig, ["k11"], resolution=9).fit({"frequency": [90.0]})  # one mode, no warning
