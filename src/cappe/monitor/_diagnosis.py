"""Which fault explains a detected change, how sure that is, and how severe the fault is (thesis 1.1, blocks 5-6).

Every fault hypothesis is a direction ``d`` in the space of the component log-factors: a component losing
stiffness moves its own factor (``d = e_c``); a change of another model parameter, such as the bearing preload,
moves several factors at once, as the estimator sees it (``d = ds / d ln p``, :meth:`FactorEstimator.direction`).
Given the estimated change ``D`` of the log-factors with covariance ``S``, the magnitude of hypothesis ``j`` is
the generalized-least-squares fit ``a_j = d'S^-1 D / d'S^-1 d`` and its misfit ``chi2_j = D'S^-1 D - a_j^2 d'S^-1 d``
(the generalized likelihood ratio of the single-fault hypotheses). With equal prior probabilities the posterior
probability of hypothesis ``j`` is ``exp(-chi2_j / 2)`` normalized over the hypotheses. When even the best
hypothesis leaves a misfit beyond the 99.9 % quantile of chi-square with ``n - 1`` degrees of freedom, the
diagnosis says so: several faults at once, or one the hypotheses do not describe.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.stats import chi2 as chi2_dist

from cappe.exceptions import DataError
from cappe.monitor._config import SeverityThresholds

__all__ = ["Diagnosis", "FaultHypothesis", "diagnose"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class FaultHypothesis:
    """One single-fault explanation of a change in the component log-factors.

    Attributes
    ----------
    name : str
        A component (``front``) or a fault parameter (``preload``).
    label : str
        Words for reports.
    direction : ndarray, shape (n,)
        Change of the log-factors per unit change of the hypothesis's log-magnitude.
    thresholds : SeverityThresholds
        Grades of the hypothesis's relative change.
    components : tuple of str
        The components the hypothesis moves noticeably (for clearing a latched alarm).
    """

    name: str
    label: str
    direction: Array
    thresholds: SeverityThresholds = field(default_factory=SeverityThresholds)
    components: tuple[str, ...] = ()


@dataclass(frozen=True)
class Diagnosis:
    """The outcome of :func:`diagnose`.

    Attributes
    ----------
    hypothesis, label : str
        The most probable hypothesis.
    probability : float
        Its posterior probability.
    change : float
        Its relative change (``exp(a) - 1``: -0.1 is a 10 % loss).
    change_std : float
        Standard uncertainty of ``change``.
    severity : str
        Grade of ``change`` by the hypothesis's thresholds.
    candidates : dict
        Posterior probability of every hypothesis.
    misfit : float
        ``chi2`` of the best hypothesis.
    consistent : bool
        False when the best hypothesis does not explain the change (see the module notes).
    """

    hypothesis: str
    label: str
    probability: float
    change: float
    change_std: float
    severity: str
    candidates: dict[str, float]
    misfit: float
    consistent: bool

    def to_dict(self) -> dict[str, Any]:
        return {
            "hypothesis": self.hypothesis,
            "label": self.label,
            "probability": self.probability,
            "change": self.change,
            "change_std": self.change_std,
            "severity": self.severity,
            "candidates": dict(self.candidates),
            "misfit": self.misfit,
            "consistent": self.consistent,
        }

    def text(self) -> str:
        """One line for people."""
        note = "" if self.consistent else " (no single fault explains the change well)"
        return (f"{self.label}: {100 * self.change:+.1f} % (+- {100 * self.change_std:.1f} %), "
                f"{self.severity}, probability {100 * self.probability:.0f} %{note}")


def diagnose(change: ArrayLike, covariance: Array, hypotheses: Sequence[FaultHypothesis]) -> Diagnosis:
    """Pick the single-fault hypothesis that best explains a change of the component log-factors.

    Parameters
    ----------
    change : array_like, shape (n,)
        Estimated change of the log-factors.
    covariance : ndarray, shape (n, n)
        Its covariance.
    hypotheses : sequence of FaultHypothesis

    Returns
    -------
    Diagnosis

    Examples
    --------
    >>> hyps = [FaultHypothesis("a", "part a", np.array([1.0, 0.0])),
    ...         FaultHypothesis("b", "part b", np.array([0.0, 1.0]))]
    >>> d = diagnose([np.log(0.9), 0.001], np.eye(2) * 1e-4, hyps)
    >>> d.hypothesis, round(d.change, 3), d.severity
    ('a', -0.1, 'conditionally tolerable')
    """
    dvec = np.asarray(change, dtype=float)
    n = dvec.size
    cov = np.asarray(covariance, dtype=float)
    if cov.shape != (n, n) or not hypotheses:
        msg = f"diagnose needs a covariance of shape ({n}, {n}) and hypotheses; got {cov.shape}, {len(hypotheses)}"
        raise DataError(msg)
    info = np.linalg.pinv(cov)
    total = float(dvec @ info @ dvec)
    fits = []
    for hyp in hypotheses:
        d = np.asarray(hyp.direction, dtype=float)
        if d.shape != (n,) or not np.any(d):
            msg = f"fault hypothesis '{hyp.name}' needs a non-zero direction of length {n}"
            raise DataError(msg)
        weight = float(d @ info @ d)
        if weight <= 0:  # the hypothesis moves only what the covariance calls unobservable: it explains nothing
            fits.append((total, 0.0, np.inf))
            continue
        a = float(d @ info @ dvec) / weight
        fits.append((max(total - a * a * weight, 0.0), a, 1.0 / np.sqrt(weight)))
    misfits = np.array([f[0] for f in fits])
    log_post = -0.5 * (misfits - misfits.min())
    post = np.exp(log_post) / np.exp(log_post).sum()
    best = int(np.argmin(misfits))
    hyp = hypotheses[best]
    misfit, a, a_std = fits[best]
    rel = float(np.expm1(a))
    limit = float(chi2_dist.ppf(0.999, max(n - 1, 1)))
    return Diagnosis(
        hypothesis=hyp.name,
        label=hyp.label,
        probability=float(post[best]),
        change=rel,
        change_std=float(np.exp(a) * a_std),
        severity=hyp.thresholds.grade(rel),
        candidates={h.name: float(p) for h, p in zip(hypotheses, post, strict=True)},
        misfit=float(misfit),
        consistent=bool(misfit <= limit),
    )
