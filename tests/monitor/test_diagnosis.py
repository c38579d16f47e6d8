"""GLR diagnosis over single-fault hypotheses (cappe.monitor._diagnosis): closed-form GLS fits, the chi-square
law of the misfit and the selection probabilities by Monte Carlo, severity grades and errors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate
from scipy.stats import chi2, kstest, norm

from cappe.exceptions import DataError
from cappe.monitor import SEVERITY_GRADES, Diagnosis, FaultHypothesis, SeverityThresholds, diagnose, severity_rank

# a covariance with correlations, as the component factors of one FRF fit have (4 components)
SIGMA = np.array([0.004, 0.006, 0.005, 0.008])
CORR = np.array([[1.0, 0.3, -0.2, 0.1],
                 [0.3, 1.0, 0.25, 0.0],
                 [-0.2, 0.25, 1.0, -0.3],
                 [0.1, 0.0, -0.3, 1.0]])
COV = CORR * np.outer(SIGMA, SIGMA)
NAMES = ("front", "rear", "screw1", "screw2")
# a preload-like hypothesis: moves both bearings and a little of the screws (the spindle's direction('preload'))
PRELOAD = np.array([0.36, 0.29, -0.017, 0.018])


def unit_hypotheses(n: int = 4) -> list[FaultHypothesis]:
    return [FaultHypothesis(NAMES[j], f"part {NAMES[j]}", np.eye(n)[j]) for j in range(n)]


def gls_fit(change: np.ndarray, cov: np.ndarray, direction: np.ndarray) -> tuple[float, float]:
    """Independent route to the GLS fit: whiten with the Cholesky factor and solve by least squares."""
    chol = np.linalg.cholesky(cov)
    y = np.linalg.solve(chol, change)
    x = np.linalg.solve(chol, direction)
    a, *_ = np.linalg.lstsq(x[:, None], y, rcond=None)
    misfit = float(np.sum((y - a[0] * x) ** 2))
    return float(a[0]), misfit


def test_magnitude_misfit_and_probabilities_follow_the_gls_closed_form():
    rng = np.random.default_rng(11)
    hyps = [*unit_hypotheses(), FaultHypothesis("preload", "bearing preload", PRELOAD)]
    for _ in range(5):
        change = rng.normal(0.0, 0.02, 4)
        result = diagnose(change, COV, hyps)
        fits = [gls_fit(change, COV, h.direction) for h in hyps]
        misfits = np.array([m for _, m in fits])
        best = int(np.argmin(misfits))
        a, misfit = fits[best]
        # both routes are exact linear algebra on a 4 x 4 system: agreement to rounding
        assert result.hypothesis == hyps[best].name
        assert result.label == hyps[best].label
        assert result.change == pytest.approx(np.expm1(a), rel=1e-9)
        assert result.misfit == pytest.approx(misfit, rel=1e-9)
        weight = direction_weight(hyps[best].direction)
        assert result.change_std == pytest.approx(np.exp(a) / np.sqrt(weight), rel=1e-9)  # delta method
        post = np.exp(-0.5 * (misfits - misfits.min()))
        post /= post.sum()
        np.testing.assert_allclose([result.candidates[h.name] for h in hyps], post, rtol=1e-9, atol=1e-300)
        assert result.probability == pytest.approx(post[best], rel=1e-12)
        assert sum(result.candidates.values()) == pytest.approx(1.0, abs=1e-12)


def direction_weight(d: np.ndarray) -> float:
    return float(d @ np.linalg.solve(COV, d))


def test_unit_hypotheses_with_diagonal_covariance_pick_the_largest_standardized_change():
    # misfit_j = sum D^2/s^2 - D_j^2/s_j^2, so the posterior is a softmax of D_j^2 / (2 s_j^2)
    s = np.array([0.01, 0.02, 0.005])
    change = np.array([0.015, -0.05, 0.004])
    result = diagnose(change, np.diag(s**2), unit_hypotheses(3))
    score = (change / s) ** 2 / 2
    expected = np.exp(score - score.max()) / np.exp(score - score.max()).sum()
    np.testing.assert_allclose(list(result.candidates.values()), expected, rtol=1e-12)
    assert result.hypothesis == "rear"
    assert result.change == pytest.approx(np.expm1(-0.05), rel=1e-12)


def test_a_clear_single_fault_is_diagnosed_with_certainty_and_its_size():
    rng = np.random.default_rng(3)
    chol = np.linalg.cholesky(COV)
    hyps = [*unit_hypotheses(), FaultHypothesis("preload", "bearing preload", PRELOAD)]
    for j, hyp in enumerate(hyps):
        a = np.log(0.85)  # a 15 % loss: 15 to 45 standard deviations of its GLS estimate for these hypotheses
        result = diagnose(a * hyp.direction + chol @ rng.standard_normal(4), COV, hyps)
        assert result.hypothesis == hyp.name, j
        assert result.probability > 0.999
        assert result.consistent
        # the estimate is within 5 of its own standard deviations of the truth (z-bound, p < 1e-6)
        assert abs(result.change - (-0.15)) < 5 * result.change_std
        assert result.severity == "conditionally tolerable"


def test_probability_of_a_correct_diagnosis_matches_the_gaussian_law():
    # two unit hypotheses, equal variances, a change of mu standard deviations along the first: the diagnosis
    # is right exactly when |mu + e1| > |e2|, whose probability is an integral of normal laws
    mu, s, n = 1.5, 0.01, 4000
    exact = integrate.quad(lambda y: norm.pdf(y) * (1 - (norm.cdf(abs(y) - mu) - norm.cdf(-abs(y) - mu))),
                           -np.inf, np.inf)[0]
    rng = np.random.default_rng(5)
    hyps = unit_hypotheses(2)
    noise = s * rng.standard_normal((n, 2))
    right = sum(diagnose(np.array([mu * s, 0.0]) + e, np.eye(2) * s**2, hyps).hypothesis == "front"
                for e in noise)
    # binomial standard error of the frequency; 4.5 of them (p ~ 7e-6)
    se = np.sqrt(exact * (1 - exact) / n)
    assert right / n == pytest.approx(exact, abs=4.5 * se)
    assert 0.7 < exact < 0.95  # the test sits where mistakes are common, so it can see a wrong rule


def test_misfit_of_the_true_hypothesis_is_chi_square_with_n_minus_1_degrees_of_freedom():
    rng = np.random.default_rng(17)
    chol = np.linalg.cholesky(COV)
    hyps = unit_hypotheses()
    n_draws = 1500
    misfits, magnitudes = [], []
    for _ in range(n_draws):
        change = np.log(0.8) * np.eye(4)[1] + chol @ rng.standard_normal(4)  # 40 sigma: always the true one
        result = diagnose(change, COV, hyps)
        assert result.hypothesis == "rear"
        misfits.append(result.misfit)
        magnitudes.append(np.log1p(result.change))
    misfits = np.array(misfits)
    # mean of chi2(3) is 3 with standard error sqrt(6 / N) = 0.063; 4.5 standard errors
    assert misfits.mean() == pytest.approx(3.0, abs=4.5 * np.sqrt(6 / n_draws))
    assert kstest(misfits, chi2(3).cdf).pvalue > 1e-4
    # the GLS magnitude is unbiased with variance 1 / (d' S^-1 d): sample variance in its chi2(N-1) band
    var = np.var(magnitudes, ddof=1) * direction_weight(np.eye(4)[1])
    lo, hi = chi2.ppf([5e-5, 1 - 5e-5], n_draws - 1) / (n_draws - 1)
    assert lo < var < hi
    assert np.mean(magnitudes) == pytest.approx(np.log(0.8), abs=4.5 / np.sqrt(direction_weight(np.eye(4)[1])
                                                                          * n_draws))


def test_consistency_limit_is_the_999_quantile_of_chi_square():
    # S = I, change (10, x, 0): the first hypothesis fits with a = 10 and leaves misfit x^2
    hyps = unit_hypotheses(3)
    limit = chi2.ppf(0.999, 2)
    inside = diagnose([10.0, np.sqrt(limit) * (1 - 1e-6), 0.0], np.eye(3), hyps)
    outside = diagnose([10.0, np.sqrt(limit) * (1 + 1e-6), 0.0], np.eye(3), hyps)
    assert inside.hypothesis == outside.hypothesis == "front"
    assert inside.misfit == pytest.approx(limit, rel=3e-6)
    assert inside.consistent
    assert not outside.consistent


def test_a_change_along_two_hypotheses_at_once_is_not_consistent():
    rng = np.random.default_rng(23)
    change = np.log(0.9) * (np.eye(4)[0] + np.eye(4)[2]) + np.linalg.cholesky(COV) @ rng.standard_normal(4)
    result = diagnose(change, COV, unit_hypotheses())
    assert not result.consistent
    assert result.misfit > chi2.ppf(0.999, 3)
    assert result.text().endswith("(no single fault explains the change well)")


def test_severity_grades_at_the_thresholds():
    t = SeverityThresholds()
    assert (t.tolerable, t.intolerable) == (0.05, 0.25)
    assert t.grade(0.0) == t.grade(-0.0499) == t.grade(0.0499) == "tolerable"
    # a change equal to a threshold takes the higher grade (below 'tolerable' is tolerable)
    assert t.grade(0.05) == t.grade(-0.05) == "conditionally tolerable"
    assert t.grade(-0.2499) == "conditionally tolerable"
    assert t.grade(0.25) == t.grade(-0.25) == t.grade(-0.9) == "intolerable"
    custom = SeverityThresholds(tolerable=0.02, intolerable=0.1)
    hyps = [FaultHypothesis("a", "part a", np.array([1.0, 0.0]), custom),
            FaultHypothesis("b", "part b", np.array([0.0, 1.0]))]
    cov = np.eye(2) * 1e-8
    for rel, grade in ((-0.015, "tolerable"), (-0.03, "conditionally tolerable"), (-0.12, "intolerable"),
                       (0.12, "intolerable")):
        result = diagnose([np.log1p(rel), 0.0], cov, hyps)
        assert result.change == pytest.approx(rel, rel=1e-12)
        assert result.severity == grade
    # the second hypothesis has the default thresholds: 3 % is tolerable there
    assert diagnose([0.0, np.log1p(-0.03)], cov, hyps).severity == "tolerable"
    assert [severity_rank(g) for g in (None, *SEVERITY_GRADES)] == [0, 1, 2, 3]


def test_diagnosis_text_and_dict():
    hyps = [FaultHypothesis("a", "part a", np.array([1.0, 0.0])), FaultHypothesis("b", "part b", np.array([0.0, 1.0]))]
    result = diagnose([np.log(0.9), 0.001], np.eye(2) * 1e-4, hyps)
    assert isinstance(result, Diagnosis)
    # std = 0.9 * 0.01 (delta method), probability exp(50 - 0.005)-weighted: 100 %
    assert result.text() == "part a: -10.0 % (+- 0.9 %), conditionally tolerable, probability 100 %"
    d = result.to_dict()
    assert set(d) == {"hypothesis", "label", "probability", "change", "change_std", "severity", "candidates",
                      "misfit", "consistent", "unit", "alternatives"}
    assert d["candidates"] == result.candidates
    assert d["change"] == result.change
    assert d["misfit"] == pytest.approx(0.001**2 / 1e-4, rel=1e-9)


def test_errors():
    hyps = unit_hypotheses(2)
    with pytest.raises(DataError, match=r"diagnose needs a covariance of shape \(2, 2\) and hypotheses; got \(3, 3\), 2"):
        diagnose([0.1, 0.0], np.eye(3), hyps)
    with pytest.raises(DataError, match=r"diagnose needs a covariance of shape \(2, 2\) and hypotheses; got \(2, 2\), 0"):
        diagnose([0.1, 0.0], np.eye(2), [])
    with pytest.raises(DataError, match=r"fault hypothesis 'z' needs a non-zero direction of length 2"):
        diagnose([0.1, 0.0], np.eye(2), [*hyps, FaultHypothesis("z", "zero", np.zeros(2))])
    with pytest.raises(DataError, match=r"fault hypothesis 'w' needs a non-zero direction of length 2"):
        diagnose([0.1, 0.0], np.eye(2), [FaultHypothesis("w", "wrong", np.ones(3))])
    with pytest.raises(DataError, match=r"severity thresholds must satisfy 0 < tolerable < intolerable; got "
                                        r"tolerable 0.3, intolerable 0.2"):
        SeverityThresholds(0.3, 0.2)
