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

A hypothesis may also be a condition sensor that reads off by a constant (``unit`` set): its direction is the
baseline's change of the expected log-factors per unit of the condition, its magnitude the offset in that unit
(not a relative change), bounded by ``bounds`` (an offset that would put the true condition outside what the
baseline learned is not a sensor offset it can explain: the fit is held at the bound). Every hypothesis that
keeps at least :data:`ALTERNATIVE` of the probability is named in the text, so that a change the data cannot
attribute (a preload loss or a temperature sensor reading high) reads as such.
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

__all__ = ["ALTERNATIVE", "Diagnosis", "FaultHypothesis", "diagnose"]

Array = NDArray[np.float64]

#: Posterior probability from which a hypothesis other than the best is named as an alternative.
ALTERNATIVE = 0.05

#: The grade of a condition-sensor hypothesis: the machine may run, but its monitoring is blind until the sensor
#: is checked.
SENSOR_GRADE = "conditionally tolerable"


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
    unit : str or None
        None for a component or model parameter (magnitude: a relative change); the unit of a condition for a
        condition sensor's offset (magnitude: the offset, in that unit; ``""`` for a unit not known).
    bounds : (float, float) or None
        The magnitudes the hypothesis can take (a condition sensor: offsets that keep the true condition inside
        the learned range); None: any.
    """

    name: str
    label: str
    direction: Array
    thresholds: SeverityThresholds = field(default_factory=SeverityThresholds)
    components: tuple[str, ...] = ()
    unit: str | None = None
    bounds: tuple[float, float] | None = None


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
    unit : str or None
        The best hypothesis's unit (None: ``change`` is relative; else an offset in this unit).
    alternatives : tuple of dict
        The other hypotheses with at least :data:`ALTERNATIVE` of the probability, most probable first:
        ``hypothesis, label, probability, change, change_std, severity, unit``.
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
    unit: str | None = None
    alternatives: tuple[dict[str, Any], ...] = ()

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
            "unit": self.unit,
            "alternatives": [dict(a) for a in self.alternatives],
        }

    def text(self) -> str:
        """One line for people."""
        note = "" if self.consistent else " (no single fault explains the change well)"
        first = _words(self.label, self.change, self.change_std, self.severity, self.unit, self.probability)
        others = [_words(a["label"], a["change"], a["change_std"], a["severity"], a["unit"], a["probability"])
                  for a in self.alternatives]
        if not others:
            return first + note
        return (first + "; or " + "; or ".join(others) + note
                + "; the data cannot tell these apart")


def _words(label: str, change: float, std: float, severity: str, unit: str | None, probability: float) -> str:
    if unit is None:
        size = f"{100 * change:+.1f} % (+- {100 * std:.2g} %), {severity}"
    else:
        size = f"{change:+.2g}{' ' + unit if unit else ''} (+- {std:.1g}{' ' + unit if unit else ''})"
    return f"{label}: {size}, probability {100 * probability:.0f} %"


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
        if hyp.bounds is not None:  # the misfit at the nearest magnitude the hypothesis can take
            a = float(np.clip(a, *hyp.bounds))
            left = dvec - a * d
            fits.append((max(float(left @ info @ left), 0.0), a, 1.0 / np.sqrt(weight)))
            continue
        fits.append((max(total - a * a * weight, 0.0), a, 1.0 / np.sqrt(weight)))
    misfits = np.array([f[0] for f in fits])
    log_post = -0.5 * (misfits - misfits.min())
    post = np.exp(log_post) / np.exp(log_post).sum()
    best = int(np.argmin(misfits))
    hyp = hypotheses[best]
    misfit, a, a_std = fits[best]
    limit = float(chi2_dist.ppf(0.999, max(n - 1, 1)))
    sizes = [_size(h, f[1], f[2]) for h, f in zip(hypotheses, fits, strict=True)]
    alternatives = tuple(
        {"hypothesis": hypotheses[j].name, "label": hypotheses[j].label, "probability": float(post[j]),
         "change": sizes[j][0], "change_std": sizes[j][1], "severity": sizes[j][2], "unit": hypotheses[j].unit}
        for j in np.argsort(-post) if j != best and post[j] >= ALTERNATIVE)
    return Diagnosis(
        hypothesis=hyp.name,
        label=hyp.label,
        probability=float(post[best]),
        change=sizes[best][0],
        change_std=sizes[best][1],
        severity=sizes[best][2],
        candidates={h.name: float(p) for h, p in zip(hypotheses, post, strict=True)},
        misfit=float(misfit),
        consistent=bool(misfit <= limit),
        unit=hyp.unit,
        alternatives=alternatives,
    )


def _size(hyp: FaultHypothesis, a: float, a_std: float) -> tuple[float, float, str]:
    """Magnitude, its standard uncertainty and grade of a hypothesis fitted at log-magnitude (or offset) ``a``."""
    if hyp.unit is not None:
        return float(a), float(a_std), SENSOR_GRADE
    rel = float(np.expm1(a))
    return rel, float(np.exp(a) * a_std), hyp.thresholds.grade(rel)
