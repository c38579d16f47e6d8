"""The exact-mode refinement's residuals for measured references (issue 20): realized shapes and their Jacobian,
the reference's own standard deviations as weights, weights from the residuals' scatter, and honest intervals."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from cappe.estimate import ParameterSpace
from cappe.estimate._automated_steps import robust_uncertainty
from cappe.estimate._base import least_squares_fit
from cappe.estimate._exact_modal import ExactModalProblem, realized
from cappe.estimate._result import ParameterEstimate
from cappe.modal import ModalEngine
from cappe.model import NumericModel, load_model

BENCH = Path(__file__).parents[1] / "data" / "bench-slide.yaml"
TRUTH = {"me_kx": 7.1e7, "me1_ky": 0.95e8, "me2_ky": 1.2e8, "me3_ky": 1.7e8, "me_kz": 4.1e7, "lgs_kx": 2.3e8,
         "lgs_ky": 3.4e8, "bsd_kz": 0.8e8, "me_by": 1.1e4, "me_dx": 0.025, "lgs_bx": 1.2e3, "lgs_dy": 0.03}
STIFF = ["me_kx", "me1_ky", "me2_ky", "me3_ky", "me_kz", "lgs_kx", "lgs_ky", "bsd_kz"]


@pytest.fixture(scope="module")
def bench():
    nm = NumericModel(load_model(BENCH))
    reference = ModalEngine(nm).modal_data([{"z": z} for z in (-0.2, 0.0, 0.25)], params=TRUTH)
    return nm, reference


def test_realized_is_the_principal_real_shape():
    rng = np.random.default_rng(1)
    real = rng.standard_normal((6, 3))
    turned = real * np.exp(1j * rng.uniform(0, 2 * np.pi, 3))[None, :] * rng.uniform(0.5, 2, 3)[None, :]
    back = realized(turned)
    # the same real shape up to sign and scale (1e-12: rounding)
    for r in range(3):
        ratio = back[:, r] / real[:, r]
        np.testing.assert_allclose(ratio, ratio[0], rtol=1e-12)


@pytest.mark.parametrize("shapes", ["real", "complex"])
def test_jacobian_matches_finite_differences(bench, shapes):
    nm, reference = bench
    space = ParameterSpace.from_model(nm, list(TRUTH))
    problem = ExactModalProblem(nm, space, reference, (1.0, 0.01, 1.0), shapes=shapes)
    p = np.array([TRUTH[n] for n in space.names]) * np.linspace(0.97, 1.03, space.n)
    jac = problem.jacobian(p)
    r0 = problem.residuals(p)
    fd = np.empty_like(jac)
    for i in range(space.n):
        step = 1e-6 * p[i]
        q = p.copy()
        q[i] += step
        fd[:, i] = (problem.residuals(q) - r0) / step
    # forward differences with a relative step 1e-6: agreement to about 1e-4 of the largest entry
    assert np.abs(jac - fd).max() < 1e-3 * np.abs(fd).max()
    # an exact reference: zero residuals at the truth, also with realized shapes
    assert np.abs(problem.residuals(np.array([TRUTH[n] for n in space.names]))).max() < 1e-8


def _biased(reference):
    """The reference with mode 2's frequency 3 % off at every position (a poorly extracted mode)."""
    sets = []
    for s in reference.sets:
        freq = s.frequency.copy()
        freq[1] *= 1.03
        sets.append(replace(s, frequency=freq))
    return replace(reference, sets=tuple(sets))


def _fit(nm, reference, **kwargs):
    space = ParameterSpace.from_model(nm, STIFF, values=TRUTH)
    problem = ExactModalProblem(nm, space, reference, (1.0, 0.0, 0.0), **kwargs)
    start = np.array([TRUTH[n] for n in space.names])
    est = least_squares_fit("t", space, problem.residuals, problem.jacobian, starts=start[None, :]).estimate
    return max(abs(est.parameters[n] / TRUTH[n] - 1) for n in STIFF)


def test_reference_standard_deviations_weight_the_residuals(bench):
    """A mode whose frequency the file says is uncertain (std 3 %, the others 0.01 %) does not pull the estimates;
    weighted alike it does."""
    nm, reference = bench
    biased = _biased(reference)
    with_std = replace(biased, sets=tuple(
        replace(s, frequency_std=np.where(np.arange(s.n_modes) == 1, 0.03, 1e-4) * s.frequency,
                damping_std=0.05 * s.damping, shape_std=np.full(s.shapes.shape, 1e-3)) for s in biased.sets))
    alike = _fit(nm, biased)
    weighted = _fit(nm, with_std)
    assert alike > 0.01  # the biased mode pulls (measured: several %)
    assert weighted < 0.2 * alike


def test_reweight_from_the_residuals_scatter(bench):
    """Per-mode weights from the residuals' own scatter: a mode whose shape is far off (noise 20 % against 0.1 %)
    is down-weighted, so the stiffnesses come closer to the truth than with fixed weights."""
    nm, reference = bench
    rng = np.random.default_rng(3)
    sets = []
    for s in reference.sets:
        level = np.where(np.arange(s.n_modes) == 3, 0.2, 1e-3) * np.abs(s.shapes).max(axis=0)
        noisy = s.shapes + level[None, :] * rng.standard_normal(s.shapes.shape)
        sets.append(replace(s, shapes=noisy, frequency=s.frequency * (1 + 1e-4 * rng.standard_normal(s.n_modes))))
    data = replace(reference, sets=tuple(sets))
    space = ParameterSpace.from_model(nm, STIFF, values=TRUTH)
    problem = ExactModalProblem(nm, space, data, (1.0, 0.0, 1.0))
    start = np.array([TRUTH[n] for n in space.names])

    def fit() -> np.ndarray:
        est = least_squares_fit("t", space, problem.residuals, problem.jacobian, starts=start[None, :]).estimate
        return np.asarray(est.values)

    fixed = fit()
    assert problem.reweight(fixed) is None  # damping weighted zero: no reweighting
    problem = ExactModalProblem(nm, space, data, (1.0, 1e-6, 1.0))
    fixed = fit()
    levels = problem.reweight(fixed)
    assert levels is not None
    assert levels["shape_max"] > 20 * levels["shape_median"]
    reweighted = fit()
    err_fixed = np.abs(fixed / start - 1).max()
    err_reweighted = np.abs(reweighted / start - 1).max()
    assert err_reweighted < 0.5 * err_fixed


def test_intervals_of_positive_parameters_stay_positive():
    """A 70 % relative standard error: the symmetric interval would reach below zero, the log-scale one does not,
    and clustered residuals widen the standard error (sandwich) where the model-based one is too small."""
    names = ("a", "b")
    values = np.array([2.0, 5.0])
    est = ParameterEstimate("t", names, values, np.array([1.4, 0.05]), np.array([[-0.8, 4.8], [4.9, 5.1]]),
                            np.eye(2), np.array([True, True]))
    rng = np.random.default_rng(0)
    groups = np.repeat(np.arange(40), 5)
    jac = rng.standard_normal((200, 2))
    # residuals sharing one error per cluster: correlated within a cluster
    res = np.repeat(rng.standard_normal(40), 5) + 0.1 * rng.standard_normal(200)
    out = robust_uncertainty(est, jac, res, groups)
    assert np.all(out.ci95[:, 0] > 0)
    assert np.all(out.ci95[:, 0] < values)
    assert np.all(out.ci95[:, 1] > values)
    assert out.std[0] >= 1.4
    assert "cluster-robust" in out.diagnostics["uncertainty"]["std"]
