"""Typed results of the automated identification's steps, and of the whole pipeline.

Each step of :class:`~cappe.estimate.AutomatedIdentification` hands the next its result as one of these frozen
dataclasses; :class:`AutomatedResult` holds them all. Its :meth:`AutomatedResult.to_dict` is the
``cappe.estimate/1`` document that ``cappe identify -o`` writes: the final estimate, whose ``diagnostics`` hold
each step's ``to_dict()`` under the keys listed in :meth:`AutomatedResult.diagnostics`.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from cappe.estimate._base import CostFunction
from cappe.estimate._damping_least_squares import DampingLeastSquares
from cappe.estimate._frf_refinement import FRFRefinement
from cappe.estimate._result import ParameterEstimate
from cappe.estimate._subproblems import StiffnessChoice, SubproblemResult
from cappe.estimate._validation import ValidationResult, summarize

if TYPE_CHECKING:
    from cappe.sensitivity import ModelSobolResult

__all__ = [
    "AutomatedResult",
    "AutomatedSettings",
    "GSAStage",
    "IdentificationValidation",
    "JointRefinement",
    "RefinementRun",
    "SensitivityOutput",
    "StiffnessRefinement",
    "StiffnessSearch",
]

Array = NDArray[np.float64]
#: The subproblems' objective, as the settings record it.
SUBPROBLEM_OBJECTIVE = "subproblems: w_f NFD^2 + w_s (1 - MAC) of the MACXP-paired mode"


@dataclass(frozen=True)
class AutomatedSettings:
    """The settings of one run of the pipeline (see :class:`~cappe.estimate.AutomatedIdentification`).

    ``to_dict()`` lists those that shape the estimate; ``truth``, ``overlay`` and ``n_permutations`` are the
    validation step's.

    Attributes
    ----------
    n_gsa : int
        Base sample size of the Sobol' design.
    n_opt : int
        Local searches per mode-position subproblem.
    threshold : float
        Total Sobol' index from which an unknown is significant (dimensionless).
    criteria : tuple of str
        GSA outputs per mode and position (``macxp``, ``ndd2``, ``frequency``, ``damping``).
    weights : (float, float, float)
        ``(w_f, w_z, w_s)``: weights of the frequency, damping and shape residuals.
    residual_damping_threshold : float
        Smallest residual damping ratio of a damping row (dimensionless).
    damping_rows : int or None
        Rows of the damping least squares (None: ``max(2 n_d, rows // 3)``).
    max_iterations : int
        Iteration limit of the batched subproblem searches.
    refine_starts : int
        Starts of the joint stiffness refinement.
    exact : bool
        Whether the final joint refinement uses the exact complex modes.
    noise : tuple of float or None
        Relative noise of the reference's frequencies, damping ratios and shape components, or None.
    n_permutations : int
        Random reassignments of the damping factors in the permuted-damping validation.
    truth : mapping name -> value or None
        True parameters (SI) of a simulated reference, for the validation FRFs.
    overlay : (str, str) or None
        Output and input channel of the FRF kept for overlays.
    shapes : str
        ``"real"`` or ``"complex"``: the shapes the exact-mode refinement compares (see
        :class:`~cappe.estimate.AutomatedIdentification`).
    known_tolerance : mapping name -> float or None
        Relative standard deviation of the known parameters whose uncertainty the intervals consider.
    """

    n_gsa: int
    n_opt: int
    threshold: float
    criteria: tuple[str, ...]
    weights: tuple[float, float, float]
    residual_damping_threshold: float
    damping_rows: int | None
    max_iterations: int
    refine_starts: int
    exact: bool
    noise: tuple[float, ...] | None
    n_permutations: int
    truth: Mapping[str, float] | None
    overlay: tuple[str, str] | None
    shapes: str = "real"
    known_tolerance: Mapping[str, float] | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"n_gsa": self.n_gsa, "n_opt": self.n_opt, "threshold": self.threshold,
                "criteria": list(self.criteria), "weights": list(self.weights),
                "residual_damping_threshold": self.residual_damping_threshold, "exact": self.exact,
                "noise": None if self.noise is None else list(self.noise), "objective": SUBPROBLEM_OBJECTIVE,
                "shapes": self.shapes,
                **({"known_tolerance": dict(self.known_tolerance)} if self.known_tolerance else {})}


# -- step 1: global sensitivity -------------------------------------------------------------------------------


@dataclass(frozen=True)
class SensitivityOutput:
    """Total Sobol' indices of one GSA output: a criterion of one reference mode at one identification position.

    Attributes
    ----------
    set_index : int
        Index of the identification set (position) among the identification sets.
    mode : int
        Reference mode (1-based).
    position : dict
        Axis position.
    criterion : str
        ``macxp``, ``ndd2``, ``frequency`` or ``damping``.
    reference_frequency : float
        Hz.
    st : ndarray, shape (n_unknowns,)
        Total Sobol' index of every unknown.
    significant : tuple of str
        Unknowns with ``ST >= threshold``.
    names : tuple of str
        The unknowns, in the order of ``st``.
    """

    set_index: int
    mode: int
    position: dict[str, float]
    criterion: str
    reference_frequency: float
    st: Array
    significant: tuple[str, ...]
    names: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        return {"mode": self.mode, "position": dict(self.position), "criterion": self.criterion,
                "reference_frequency": self.reference_frequency, "significant": list(self.significant),
                "ST": {n: float(v) for n, v in zip(self.names, self.st, strict=True)}}


@dataclass(frozen=True)
class GSAStage:
    """Step 1: one Sobol' design over all unknowns, ``ST`` of every output.

    Attributes
    ----------
    sobol : ModelSobolResult
        The indices (figures and tables of :mod:`cappe.report`).
    n : int
        Base sample size.
    model_runs : int
        Model evaluations, ``n (D + 2)`` per identification position.
    threshold : float
        ``ST`` from which an unknown is significant.
    outputs : tuple of SensitivityOutput
        Per identification position, mode and criterion, in that order.
    """

    sobol: ModelSobolResult
    n: int
    model_runs: int
    threshold: float
    outputs: tuple[SensitivityOutput, ...]

    @functools.cached_property
    def _by_key(self) -> dict[tuple[int, int, str], SensitivityOutput]:
        return {(o.set_index, o.mode, o.criterion): o for o in self.outputs}

    def output(self, set_index: int, mode: int, criterion: str) -> SensitivityOutput:
        """The output of reference ``mode`` (1-based) at identification set ``set_index`` for ``criterion``.

        Parameters
        ----------
        set_index : int
            Index of the identification set among the identification sets (0-based).
        mode : int
            Reference mode (1-based).
        criterion : str
            ``"macxp"``, ``"ndd2"``, ``"frequency"`` or ``"damping"``.

        Returns
        -------
        SensitivityOutput

        Raises
        ------
        KeyError
            No such output was computed.
        """
        return self._by_key[(set_index, mode, criterion)]

    def to_dict(self) -> dict[str, Any]:
        return {"n": self.n, "model_runs": self.model_runs, "threshold": self.threshold,
                "outputs": [o.to_dict() for o in self.outputs]}


# -- step 2: stiffness subproblems ----------------------------------------------------------------------------


@dataclass(frozen=True)
class StiffnessSearch:
    """Step 2: the mode-position subproblems and the selection of every modal unknown.

    Attributes
    ----------
    subproblems : tuple of SubproblemResult
    selection : mapping name -> StiffnessChoice
        The unknowns some subproblem determined.
    not_searched : tuple of str
        Modal unknowns no subproblem determined (they keep their start).
    values : ndarray, shape (n_unknowns,)
        All unknowns after the selection (SI).
    """

    subproblems: tuple[SubproblemResult, ...]
    selection: Mapping[str, StiffnessChoice]
    not_searched: tuple[str, ...]
    values: Array


# -- step 3: joint stiffness refinement -----------------------------------------------------------------------


@dataclass(frozen=True)
class RefinementRun:
    """One start of the joint stiffness refinement: its label and the cost before and after.

    Attributes
    ----------
    start : str
        Label of the start (``selection``, ``consensus``, ``rank k``).
    cost_before, cost_after : float
        Cost (sum of squared residuals, dimensionless) at the start and at the end of the refinement.
    """

    start: str
    cost_before: float
    cost_after: float

    def to_dict(self) -> dict[str, Any]:
        return {"start": self.start, "cost_before": self.cost_before, "cost_after": self.cost_after}


@dataclass(frozen=True)
class StiffnessRefinement:
    """Step 3: the modal unknowns refined jointly over all modes and positions from several starts.

    Attributes
    ----------
    start : str
        Label of the winning start (``selection``, ``consensus``, ``rank k``).
    runs : tuple of RefinementRun
        Every start, the paper's selection first.
    cost_before : float
        Cost at the paper's selection.
    cost_after : float
        Cost of the winning run.
    success : bool
    message : str
    evaluations : int or None
        Of the winning run.
    relative_change : mapping name -> float
        Refined value over the selection, minus one.
    selection : mapping name -> float
        The selection (SI).
    values : ndarray, shape (n_unknowns,)
        All unknowns after the refinement (SI).
    """

    start: str
    runs: tuple[RefinementRun, ...]
    cost_before: float
    cost_after: float
    success: bool
    message: str
    evaluations: int | None
    relative_change: Mapping[str, float]
    selection: Mapping[str, float]
    values: Array

    def to_dict(self) -> dict[str, Any]:
        return {"cost_before": self.cost_before, "cost_after": self.cost_after, "success": self.success,
                "message": self.message, "evaluations": self.evaluations,
                "relative_change": dict(self.relative_change), "start": self.start,
                "runs": [r.to_dict() for r in self.runs], "selection": dict(self.selection)}


# -- step 5: joint refinement of all unknowns -----------------------------------------------------------------


@dataclass(frozen=True)
class JointRefinement:
    """Step 5: all unknowns refined jointly over all modes and positions, on exact or first-order modes.

    Attributes
    ----------
    estimate : ParameterEstimate
        The refinement's estimate (its Jacobian gives the uncertainty).
    cost_function : CostFunction or None
        The cost it minimized.
    cost_before, cost_after : float
    success : bool
    message : str
    evaluations : int or None
    relative_change : mapping name -> float
        Refined value over the start (the result of steps 2-4), minus one.
    pairing : list of dict or None
        Exact modes only: per set, the model mode paired with each reference mode at the estimate.
    values : ndarray, shape (n_unknowns,)
        The estimate (SI).
    uncertainty : str or None
        Exact modes: how the standard errors were formed (model-based or cluster-robust); None otherwise.
    weighting : str or None
        Exact modes: what weighted the residuals (the weights, the stated noise, the reference's standard
        deviations or the residuals' own scatter).
    shapes : str or None
        Exact modes: ``"real"`` or ``"complex"``, the shapes compared.
    """

    estimate: ParameterEstimate
    cost_function: CostFunction | None
    cost_before: float
    cost_after: float
    success: bool
    message: str
    evaluations: int | None
    relative_change: Mapping[str, float]
    pairing: list[dict[str, Any]] | None
    values: Array
    uncertainty: str | None = None
    weighting: str | None = None
    shapes: str | None = None

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"cost_before": self.cost_before, "cost_after": self.cost_after,
                               "success": self.success, "message": self.message, "evaluations": self.evaluations,
                               "relative_change": dict(self.relative_change)}
        if self.pairing is not None:
            out["pairing"] = self.pairing
        return out


# -- step 6: validation ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class IdentificationValidation:
    """Step 6: the identified model against the reference, and the permuted-damping models (paper Fig. 7).

    Attributes
    ----------
    held : ValidationResult or None
        At the held-out position.
    identification : tuple of ValidationResult
        At the identification positions.
    permuted : tuple of ValidationResult
        The permuted-damping models at the held-out (else the first) position.
    assignments : tuple of dict
        Per permuted model, ``{damping unknown: unknown whose factor it took}``.
    """

    held: ValidationResult | None
    identification: tuple[ValidationResult, ...]
    permuted: tuple[ValidationResult, ...]
    assignments: tuple[dict[str, str], ...]

    def identification_statistics(self) -> dict[str, dict[str, float]]:
        """Statistics over all identification positions at once (paper Tables 2 and 4); ``{}`` without any."""
        return _pooled(self.identification)

    def as_mapping(self) -> dict[str, Any]:
        """``{"validation": held, "identification": [...], "permuted": [...]}``, as
        ``AutomatedIdentification.validation_`` gives it."""
        return {"validation": self.held, "identification": list(self.identification),
                "permuted": list(self.permuted)}

    def to_dict(self) -> dict[str, Any]:
        return {
            "validation": None if self.held is None else self.held.to_dict(),
            "identification": [v.to_dict() for v in self.identification],
            "identification_statistics": self.identification_statistics(),
            "permuted": [{"assignment": a, "statistics": r.statistics()}
                         for a, r in zip(self.assignments, self.permuted, strict=True)],
        }


def _pooled(results: Sequence[ValidationResult]) -> dict[str, dict[str, float]]:
    """Statistics over several positions at once (paper Tables 2 and 4)."""
    if not results:
        return {}
    out = {}
    for c in ("frac", "csf", "macxp", "ndd"):
        out[c] = summarize(np.concatenate([r.values(c) for r in results]), larger_is_better=c != "ndd")
    return out


# -- the pipeline ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class AutomatedResult:
    """Everything one run of :class:`~cappe.estimate.AutomatedIdentification` found, step by step.

    Attributes
    ----------
    method : str
        ``"automated-gsa"``.
    names : tuple of str
        All unknowns.
    stiffness_unknowns, damping_unknowns : tuple of str
        Unknowns of steps 2-3 (modal) and 4 (damping).
    identification_positions : tuple of dict
    validation_position : dict or None
    settings : AutomatedSettings
    gsa : GSAStage
    stiffness : StiffnessSearch
    refinement : StiffnessRefinement or None
        None without modal unknowns.
    damping : DampingLeastSquares or None
        None without damping unknowns.
    after_damping : ndarray, shape (n_unknowns,)
        All unknowns after steps 2-4, the start of the joint refinement (SI).
    joint : JointRefinement
    validation : IdentificationValidation
    timings : mapping step -> float
        Seconds per step and ``total``.
    warnings : tuple of str
        ``"Category: message"`` of the warnings the refinements raised.
    frf : FRFRefinement or None
        The refinement against measured FRFs at the identification positions (after the joint refinement), when
        they were given: its estimate is then the final one.
    cpu_timings : mapping step -> float
        CPU seconds of this process per step and ``total`` (every thread of the process counted: with one BLAS
        thread the work a step costs, whatever the load of the machine).
    known_assumed_exact : tuple of str
        Known parameters the model tags ``disturbable`` (they may be off, paper 3.3) that were given no tolerance:
        the intervals take them as exact (every text output says so).
    """

    method: str
    names: tuple[str, ...]
    stiffness_unknowns: tuple[str, ...]
    damping_unknowns: tuple[str, ...]
    identification_positions: tuple[dict[str, float], ...]
    validation_position: dict[str, float] | None
    settings: AutomatedSettings
    gsa: GSAStage
    stiffness: StiffnessSearch
    refinement: StiffnessRefinement | None
    damping: DampingLeastSquares | None
    after_damping: Array
    joint: JointRefinement
    validation: IdentificationValidation
    timings: Mapping[str, float]
    warnings: tuple[str, ...]
    frf: FRFRefinement | None = None
    cpu_timings: Mapping[str, float] = field(default_factory=dict)
    known_assumed_exact: tuple[str, ...] = ()

    @property
    def costs(self) -> dict[str, float | None]:
        """Cost at the selection, after the stiffness refinement, after the damping step and at the end of the
        modal stages; with measured FRFs, the FRF cost at their end and after the FRF refinement."""
        out: dict[str, float | None] = {
            "selection": None if self.refinement is None else self.refinement.cost_before,
            "stiffness_refined": None if self.refinement is None else self.refinement.cost_after,
            "after_damping_least_squares": self.joint.cost_before, "final": self.joint.cost_after}
        if self.frf is not None:
            out.update({"frf_start": self.frf.cost_before, "frf_final": self.frf.cost_after})
        return out

    def diagnostics(self) -> dict[str, Any]:
        """The steps' records, as the estimate's ``diagnostics`` hold them after the joint refinement's own."""
        return {
            "stiffness_unknowns": list(self.stiffness_unknowns),
            "damping_unknowns": list(self.damping_unknowns),
            "identification_positions": [dict(p) for p in self.identification_positions],
            "validation_position": None if self.validation_position is None else dict(self.validation_position),
            "settings": self.settings.to_dict(),
            "gsa": self.gsa.to_dict(),
            "subproblems": [s.to_dict() for s in self.stiffness.subproblems],
            "selection": {n: c.to_dict() for n, c in self.stiffness.selection.items()},
            "not_searched": list(self.stiffness.not_searched),
            "stiffness_refinement": {} if self.refinement is None else self.refinement.to_dict(),
            "damping": None if self.damping is None else self.damping.to_dict(),
            "joint_refinement": self.joint.to_dict(),
            "stages": {"selection": _mapping(self.names, self.stiffness.values),
                       "after_damping_least_squares": _mapping(self.names, self.after_damping),
                       **({} if self.frf is None else {"after_modal_refinement": _mapping(self.names,
                                                                                          self.joint.values)})},
            "frf_refinement": None if self.frf is None else self.frf.to_dict(),
            "costs": self.costs,
            "timings": dict(self.timings),
            "cpu_timings": dict(self.cpu_timings),
            "validation": self.validation.to_dict(),
            "warnings": list(self.warnings),
            "known_assumed_exact": list(self.known_assumed_exact),
        }

    @functools.cached_property
    def estimate(self) -> ParameterEstimate:
        """All unknowns with the last refinement's uncertainty (the FRF refinement's with measured FRFs, else the
        joint refinement's), the steps' records in ``diagnostics``."""
        last = self.joint.estimate if self.frf is None else self.frf.estimate
        return replace(last, method=self.method, diagnostics={**last.diagnostics, **self.diagnostics()})

    def to_dict(self) -> dict[str, Any]:
        """The ``cappe.estimate/1`` document of the estimate (what ``cappe identify -o`` writes)."""
        return self.estimate.to_dict()


def _mapping(names: Sequence[str], values: Array) -> dict[str, float]:
    return {n: float(v) for n, v in zip(names, values, strict=True)}
