"""The steps of the automated identification, each a function from the setup (and the previous steps' results)
to its typed result (:mod:`cappe.estimate._automated_result`); :func:`run_pipeline` runs them in order and times
them. The maths of steps 2 and 4 is in :mod:`~cappe.estimate._subproblems` and
:mod:`~cappe.estimate._damping_least_squares`, that of the exact-mode refinement in
:mod:`~cappe.estimate._exact_modal`; see :class:`~cappe.estimate.AutomatedIdentification` for the pipeline.
"""

from __future__ import annotations

import contextlib
import time
import warnings
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, replace
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from cappe.estimate._automated_result import (
    AutomatedResult,
    AutomatedSettings,
    GSAStage,
    IdentificationValidation,
    JointRefinement,
    RefinementRun,
    SensitivityOutput,
    StiffnessRefinement,
    StiffnessSearch,
)
from cappe.estimate._base import CostFunction, least_squares_fit
from cappe.estimate._damping_least_squares import DampingLeastSquares, damping_least_squares
from cappe.estimate._exact_modal import ExactModalProblem
from cappe.estimate._frf_refinement import FRFRefinement, MeasuredFRF, refine_against_frf
from cappe.estimate._modal_updating import MODAL_VARIANCE_FLOOR, ModalUpdatingEstimator
from cappe.estimate._result import ParameterEstimate
from cappe.estimate._space import ParameterSpace
from cappe.estimate._subproblems import SubproblemResult, _alternative_starts, choose_stiffness, solve_subproblem
from cappe.estimate._validation import ValidationResult, _truth_receptance, validate_identification
from cappe.modal import ModalEngine
from cappe.model import NumericModel
from cappe.parallel import Executor, chunk_slices
from cappe.systems.modal import ModalData

__all__ = ["Setup", "run_pipeline"]

Array = NDArray[np.float64]
_T = TypeVar("_T")
#: Parameter kinds identified by the damping step; every other unknown is found from frequencies and shapes.
DAMPING_KINDS = ("damping", "loss")


@dataclass(frozen=True)
class Setup:
    """What every step reads: the model, the unknowns, the reference and its split, the settings, where to run.

    ``base_model`` is ``model`` with the known parameters' values as its nominal vector: the GSA evaluates the
    model there, and the subproblems' engine reduces the nominal mass matrix once per position.
    """

    method: str
    model: NumericModel
    base_model: NumericModel
    space: ParameterSpace
    data: ModalData
    ident: tuple[int, ...]
    held: int | None
    settings: AutomatedSettings
    runner: Executor
    n_workers: int | None
    progress: bool
    frf: tuple[MeasuredFRF, ...] = ()  # measured FRFs, at most one per reference set (matched by position)

    def measured_at(self, k: int) -> MeasuredFRF | None:
        """The measured FRFs at the position of reference set ``k`` (None without)."""
        position = self.model.structure.resolve_position(self.data.sets[k].position)
        want = self.model.position_vector(position)
        for item in self.frf:
            have = self.model.position_vector(self.model.structure.resolve_position(item.position))
            if np.allclose(have, want, rtol=0, atol=1e-9):
                return item
        return None

    @property
    def ident_ref(self) -> ModalData:
        """The identification sets only."""
        return ModalData(self.data.sensors, tuple(self.data.sets[k] for k in self.ident), self.data.source)

    @property
    def damping_unknowns(self) -> list[str]:
        structure = self.model.structure
        return [n for n in self.space.names if structure.parameter(n).kind in DAMPING_KINDS]

    @property
    def modal_unknowns(self) -> list[str]:
        structure = self.model.structure
        return [n for n in self.space.names if structure.parameter(n).kind not in DAMPING_KINDS]

    def bar(self, total: int, desc: str, unit: str) -> Any:
        """A progress bar (tqdm on stderr), silent unless ``progress``."""
        from tqdm.auto import tqdm

        return tqdm(total=total, desc=desc, unit=unit, disable=not self.progress)


def run_pipeline(setup: Setup, rng: np.random.Generator) -> AutomatedResult:
    """GSA, stiffness subproblems, stiffness refinement, damping least squares, joint refinement, validation."""
    t_total, cpu_total = time.perf_counter(), time.process_time()
    timings: dict[str, float] = {}
    cpu: dict[str, float] = {}
    caught: list[str] = []
    ident_ref = setup.ident_ref
    seeds = rng.integers(1, 2**31, size=4)

    def timed(name: str, step: Callable[[], _T]) -> _T:
        t, c = time.perf_counter(), time.process_time()
        out = step()
        timings[name] = time.perf_counter() - t
        cpu[name] = time.process_time() - c
        return out

    gsa = timed("gsa", lambda: sensitivity_step(setup, ident_ref, int(seeds[0])))
    search = timed("stiffness_subproblems", lambda: subproblem_step(setup, ident_ref, gsa, int(seeds[1])))
    refinement = timed("stiffness_refinement", lambda: stiffness_refinement_step(setup, ident_ref, search, caught))
    current = (search.values if refinement is None else refinement.values).copy()
    damping = timed("damping_least_squares", lambda: damping_step(setup, gsa, current))
    if damping is not None:
        current[[setup.space.names.index(n) for n in damping.names]] = damping.values
    joint = timed("joint_refinement", lambda: joint_refinement_step(setup, ident_ref, current, caught))
    frf = None
    if any(setup.measured_at(k) is not None for k in setup.ident):
        frf = timed("frf_refinement", lambda: frf_refinement_step(setup, joint.values))
    final = joint.values if frf is None else frf.values
    validation = timed("validation", lambda: validation_step(setup, final, int(seeds[2])))
    timings["total"] = time.perf_counter() - t_total
    cpu["total"] = time.process_time() - cpu_total
    caught.extend(f"IdentificationWarning: {line}"
                  for line in identification_warnings(setup, joint, validation, frf))
    data = setup.data
    return AutomatedResult(
        method=setup.method, names=setup.space.names, stiffness_unknowns=tuple(setup.modal_unknowns),
        damping_unknowns=tuple(setup.damping_unknowns),
        identification_positions=tuple(dict(data.sets[k].position) for k in setup.ident),
        validation_position=None if setup.held is None else dict(data.sets[setup.held].position),
        settings=setup.settings, gsa=gsa, stiffness=search, refinement=refinement, damping=damping,
        after_damping=current, joint=joint, validation=validation, timings=timings, warnings=tuple(caught), frf=frf,
        cpu_timings=cpu)


# -- step 1 -----------------------------------------------------------------------------------------------------


def sensitivity_step(setup: Setup, ident_ref: ModalData, seed: int) -> GSAStage:
    """One Sobol' design over all unknowns within their bounds; ``ST`` of every criterion of every mode and
    identification position, and the unknowns significant for it."""
    from cappe.sensitivity import model_sobol

    space, settings = setup.space, setup.settings
    bounds = np.column_stack([space.lower, space.upper])
    sobol = model_sobol(setup.base_model, ident_ref, parameters=list(space.names), bounds=bounds, n=settings.n_gsa,
                        rng=seed, criteria=settings.criteria, n_workers=setup.n_workers, executor=setup.runner,
                        progress=setup.progress)
    st = sobol.sobol.ST
    outputs: list[SensitivityOutput] = []
    for j, data_set in enumerate(ident_ref.sets):
        for r in range(data_set.n_modes):
            for c in settings.criteria:
                row = st[len(outputs)]
                outputs.append(SensitivityOutput(
                    j, r + 1, dict(data_set.position), c, float(data_set.frequency[r]), row,
                    tuple(n for n, v in zip(space.names, row, strict=True) if v >= settings.threshold), space.names))
    return GSAStage(sobol, settings.n_gsa, settings.n_gsa * (space.n + 2) * len(setup.ident), settings.threshold,
                    tuple(outputs))


# -- step 2 -----------------------------------------------------------------------------------------------------


def subproblem_step(setup: Setup, ident_ref: ModalData, gsa: GSAStage, seed: int) -> StiffnessSearch:
    """For every mode-position pair with significant modal unknowns (MACXP), ``n_opt`` batched local searches over
    them from random points in the bounds; each unknown taken from the subproblem where it spreads least."""
    space, settings, model = setup.space, setup.settings, setup.model
    structure = model.structure
    modal_names = setup.modal_unknowns
    engine = ModalEngine(setup.base_model, sensors=list(setup.data.sensors))  # known masses at their nominal
    jobs: list[tuple[int, int, tuple[str, ...]]] = []
    for j, data_set in enumerate(ident_ref.sets):
        position = structure.resolve_position(data_set.position)
        engine.evaluate(space.full(space.start), position)  # warm the per-position caches before threading
        for r in range(data_set.n_modes):
            search = tuple(n for n in gsa.output(j, r + 1, "macxp").significant if n in modal_names)
            if search:
                jobs.append((j, r, search))
    job_seeds = np.random.default_rng(seed).integers(1, 2**31, size=max(len(jobs), 1))
    lo_u, hi_u = space.internal_bounds()
    w_f, _, w_s = settings.weights

    def run(s: slice) -> list[SubproblemResult]:
        results = []
        for q in range(s.start, s.stop):
            j, r, search = jobs[q]
            sub_rng = np.random.default_rng(int(job_seeds[q]))
            u = sub_rng.uniform(lo_u, hi_u, size=(settings.n_opt, space.n))  # random unknowns, starts included
            starts = space.full(space.from_internal(u))
            idx = [space.names.index(n) for n in search]
            t0 = time.perf_counter()
            values, cost, iters = solve_subproblem(
                model=model, reference=ident_ref, set_index=j, mode=r, parameters=search, start=starts,
                lower=space.lower[idx], upper=space.upper[idx], weights=(w_f, w_s),
                max_iterations=settings.max_iterations, engine=engine)
            position = structure.resolve_position(ident_ref.sets[j].position)
            results.append(SubproblemResult(r + 1, dict(position), search, values, cost, iters,
                                            time.perf_counter() - t0, space.lower[idx], space.upper[idx]))
        return results

    bar = setup.bar(len(jobs), "stiffness subproblems", "subproblem")
    try:
        parts = setup.runner.map(run, chunk_slices(len(jobs), 1), done=lambda s: bar.update(s.stop - s.start))
    finally:
        bar.close()
    subproblems = tuple(sub for part in parts for sub in part)
    selection = choose_stiffness(subproblems, modal_names)
    values = space.start.copy()
    for n, choice in selection.items():
        i = space.names.index(n)
        values[i] = np.clip(choice.value, space.lower[i], space.upper[i])
    return StiffnessSearch(subproblems, selection, tuple(n for n in modal_names if n not in selection), values)


# -- step 3 -----------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _LocalRefinement:
    """One modal-updating refinement from a start: the values reached and the fit's record."""

    values: Array
    estimate: ParameterEstimate
    cost_before: float
    evaluations: int | None
    relative_change: dict[str, float]
    cost_function: CostFunction | None


def stiffness_refinement_step(setup: Setup, ident_ref: ModalData, search: StiffnessSearch,
                              caught: list[str]) -> StiffnessRefinement | None:
    """The modal unknowns refined jointly over all modes and positions (first-order modes, damping fixed) from the
    selection and the alternative starts; the lowest final cost wins. None without modal unknowns."""
    space, settings = setup.space, setup.settings
    modal_names = setup.modal_unknowns
    if not modal_names:
        return None
    selected = search.values
    candidates = _alternative_starts(list(search.subproblems), space, selected, modal_names, settings.refine_starts)
    w_f, _, w_s = settings.weights
    # independent local refinements: side by side on the executor (threads: numpy's solves release the GIL; worker
    # processes and Dask workers hand back their warnings); the warnings are recorded here, around all of them
    # (catch_warnings is process-wide state). A remote start's cost function stays where it ran (unused here)
    remote = setup.runner.kind not in ("serial", "threads")

    def refine(candidate: tuple[str, Array]) -> _LocalRefinement:
        found = _modal_refinement(setup, ident_ref, candidate[1], modal_names, (w_f, 0.0, w_s))
        return replace(found, cost_function=None) if remote else found

    bar = setup.bar(len(candidates), "stiffness refinement", "start")
    with _recorded_warnings(caught, sort=True):  # the starts' threads interleave their warnings
        try:
            refined = setup.runner.map(refine, candidates, done=lambda _: bar.update(1))
        finally:
            bar.close()
    runs = tuple(RefinementRun(label, found.cost_before, float(found.estimate.cost))
                 for (label, _), found in zip(candidates, refined, strict=True))
    best = 0
    for k, run in enumerate(runs):
        if run.cost_after < runs[best].cost_after * (1 - 1e-9):
            best = k
    found, est = refined[best], refined[best].estimate
    idx = [space.names.index(n) for n in modal_names]
    return StiffnessRefinement(
        start=runs[best].start, runs=runs, cost_before=runs[0].cost_before, cost_after=runs[best].cost_after,
        success=bool(est.success), message=est.message, evaluations=found.evaluations,
        relative_change={n: float(found.values[i] / selected[i] - 1.0) for n, i in zip(modal_names, idx, strict=True)},
        selection={n: float(selected[i]) for n, i in zip(modal_names, idx, strict=True)}, values=found.values)


def _modal_refinement(setup: Setup, reference: ModalData, current: Array, names: list[str],
                      weights: tuple[float, float, float]) -> _LocalRefinement:
    """Modal updating over ``names`` from ``current`` (other unknowns fixed). The caller records the warnings."""
    model, space = setup.model, setup.space
    fixed = {n: float(v) for n, v in zip(space.names, current, strict=True) if n not in names}
    known = {n: float(v) for n, v in zip(model.parameter_names, space.base, strict=True)}
    known.update(fixed)
    idx = [space.names.index(n) for n in names]
    bounds = {n: (float(space.lower[i]), float(space.upper[i])) for n, i in zip(names, idx, strict=True)}
    start = {n: float(np.clip(current[i], space.lower[i], space.upper[i])) for n, i in zip(names, idx, strict=True)}
    # first-order modes (fast); the final joint refinement compares exact ones
    updater = ModalUpdatingEstimator(model, names, bounds=bounds, start=start, values=known, weights=weights,
                                     modes="first-order", bias_check=False)
    r0 = updater.residuals(reference)
    est = updater.fit(reference).estimate_
    out = current.copy()
    out[idx] = est.values
    return _LocalRefinement(
        values=out, estimate=est, cost_before=float(r0 @ r0), evaluations=est.diagnostics.get("evaluations"),
        relative_change={n: float(est.values[k] / current[i] - 1.0) for k, (n, i) in
                         enumerate(zip(names, idx, strict=True))},
        cost_function=updater.cost_function_)


# -- step 4 -----------------------------------------------------------------------------------------------------


def damping_step(setup: Setup, gsa: GSAStage, current: Array) -> DampingLeastSquares | None:
    """The damping unknowns by bounded linear least squares at the identified stiffness, rows chosen by their
    GSA interaction (sum of the other unknowns' ``ST`` of NDD^2). None without damping unknowns."""
    space, settings, data = setup.space, setup.settings, setup.data
    damp_names = setup.damping_unknowns
    if not damp_names:
        return None
    interaction: dict[tuple[int, int], float] | None = None
    if "ndd2" in settings.criteria:
        others = np.array([n not in damp_names for n in space.names])
        interaction = {(k, r): float(np.sum(np.clip(gsa.output(j, r + 1, "ndd2").st[others], 0, None)))
                       for j, k in enumerate(setup.ident) for r in range(data.sets[k].n_modes)}
    didx = [space.names.index(n) for n in damp_names]
    return damping_least_squares(
        model=setup.model, reference=data, params=space.full(current), damping=damp_names,
        lower=space.lower[didx], upper=space.upper[didx], sets=list(setup.ident), interaction=interaction,
        n_rows=settings.damping_rows, residual_threshold=settings.residual_damping_threshold)


# -- step 5 -----------------------------------------------------------------------------------------------------


def joint_refinement_step(setup: Setup, ident_ref: ModalData, current: Array, caught: list[str]) -> JointRefinement:
    """All unknowns refined jointly over all modes and positions from ``current``, on exact complex modes
    (:class:`ExactModalProblem`) or, with ``exact=False``, first-order ones (modal updating)."""
    settings, space = setup.settings, setup.space
    if not settings.exact:
        with _recorded_warnings(caught):
            found = _modal_refinement(setup, ident_ref, current, list(space.names), settings.weights)
        est = found.estimate
        return JointRefinement(est, found.cost_function, found.cost_before, float(est.cost), bool(est.success),
                               est.message, found.evaluations, found.relative_change, None, found.values)
    candidates = pairing_candidates(setup.model, ident_ref, space.full(current))
    problem = ExactModalProblem(setup.model, space, ident_ref, settings.weights, settings.noise,
                                executor=setup.runner, shapes=settings.shapes, n_modes=candidates)
    r0 = problem.residuals(current)
    diagnostics: dict[str, Any] = {"modes": "exact", "jacobian": "analytic (eigen-decomposition perturbation)",
                                   "pairing_candidates": candidates}
    start = np.clip(current, space.lower, space.upper)
    fitted = least_squares_fit(setup.method, space, problem.residuals, problem.jacobian, starts=start[None, :],
                               diagnostics=diagnostics, variance_floor=MODAL_VARIANCE_FLOOR)
    est = fitted.estimate
    values = np.asarray(est.values, dtype=float)
    weighting = problem.weighting
    # neither stated noise nor the reference's standard deviations: weight every residual by its own scatter
    # at the fit (per mode; ExactModalProblem.reweight) and fit again, twice (the levels settle). Fixed weights
    # let the shapes' extraction errors, which differ between modes by two orders of magnitude on measured
    # data and exceed the frequencies' by as much, pull the stiffnesses (issue 20: worst stiffness error 10 %
    # with fixed weights, 2-3 % reweighted on the same extracted modes)
    for _ in range(2 if weighting == "weights" and np.all(np.isfinite(values)) else 0):
        levels = problem.reweight(values)
        if levels is None:
            break
        diagnostics["scatter"] = levels
        fitted = least_squares_fit(setup.method, space, problem.residuals, problem.jacobian,
                                   starts=np.clip(values, space.lower, space.upper)[None, :],
                                   diagnostics=diagnostics)
        est = fitted.estimate
        values = np.asarray(est.values, dtype=float)
        weighting = "the residuals' own scatter per mode"
    problem.weighting = weighting
    how = None
    if np.all(np.isfinite(values)):
        tolerance = dict(settings.known_tolerance or {})
        kv = np.array([setup.base_model.nominal[setup.model.parameter_names.index(n)] for n in tolerance])
        est = robust_uncertainty(
            est, problem.jacobian(values), problem.residuals(values), problem.groups(), known_tolerance=tolerance,
            known_jacobian=problem.jacobian(values, list(tolerance)) if tolerance else None, known_values=kv)
        how = str(est.diagnostics["uncertainty"]["std"])
        r = problem.residuals(values)
        est = replace(est, diagnostics={**est.diagnostics, "weighting": problem.weighting,
                                        "shapes": problem.shapes, "residuals": int(r.size),
                                        "exact_solves": problem.engine.exact_solves})
    return JointRefinement(
        est, fitted.cost, float(r0 @ r0), float(est.cost), bool(est.success), est.message, problem.evaluations,
        {n: float(v / c - 1.0) for n, v, c in zip(space.names, est.values, current, strict=True)},
        problem.pairing_report(values), values, uncertainty=how, weighting=problem.weighting, shapes=problem.shapes)


#: The exact joint refinement pairs the reference modes of a set with the model modes up to this factor above the
#: set's highest reference frequency (at the refinement's start), and at least with as many as the reference has plus
#: PAIRING_MARGIN: the exact modes are then solved for those only (quadratic eigenproblem, mode by mode) instead of
#: all n_dof (one eig of the 2 n_dof state matrix).
PAIRING_BAND = 1.25
PAIRING_MARGIN = 5


def pairing_candidates(model: NumericModel, reference: ModalData, full: NDArray[np.float64]) -> int:
    """How many of the lowest model modes may pair with the reference in the exact joint refinement: per set, those
    up to :data:`PAIRING_BAND` times its highest reference frequency at the vector ``full`` (undamped modes), at
    least the set's mode count plus :data:`PAIRING_MARGIN`; the largest over the sets, at most ``n_dof``.

    Parameters
    ----------
    model : NumericModel
        The model.
    reference : ModalData
        The reference modes (Hz) at their positions.
    full : ndarray, shape (n_params,)
        The model's parameter vector (SI).

    Returns
    -------
    int
        The number of candidate modes.
    """
    engine = ModalEngine(model, sensors="dofs")
    count = 0
    for data_set in reference.sets:
        freq = engine.evaluate(full, model.structure.resolve_position(data_set.position)).frequency[0]
        band = int(np.count_nonzero(freq <= PAIRING_BAND * float(np.max(data_set.frequency))))
        count = max(count, band, data_set.n_modes + PAIRING_MARGIN)
    return min(model.n_dof, count)


def frf_refinement_step(setup: Setup, start: Array) -> FRFRefinement:
    """All unknowns fitted to the measured FRFs at the identification positions, from the modal stages' estimate
    (:mod:`cappe.estimate._frf_refinement`): the modal stages find the basin, the FRFs settle what extracted modes
    cannot (issue 20)."""
    pairs = [(item, setup.data.sets[k]) for k in setup.ident if (item := setup.measured_at(k)) is not None]
    return refine_against_frf(method=setup.method, model=setup.model, space=setup.space,
                              measured=[m for m, _ in pairs], reference=[s for _, s in pairs], start=start)


def robust_uncertainty(estimate: ParameterEstimate, jacobian: Array, residuals: Array,
                       groups: NDArray[np.intp], clusters: str = "mode-position pairs", *,
                       known_tolerance: Mapping[str, float] | None = None, known_jacobian: Array | None = None,
                       known_values: Array | None = None) -> ParameterEstimate:
    """The estimate with an honest uncertainty: per unknown the larger of the model-based standard error and a
    cluster-robust (sandwich) one, and 95 % intervals on a log scale, which never include zero or negative values.

    The model-based covariance ``s^2 (J^T J)^+`` assumes independent residuals of one variance. Those of one mode
    at one position (its frequency, damping and shape components) share their causes, the mode's extraction errors
    and the model's own error, so they are not independent; the sandwich
    ``(J^T J)^+ (sum_g J_g^T r_g r_g^T J_g) (J^T J)^+ G / (G - n)`` over the G mode-position clusters ``g`` holds
    whatever their correlation and variance within a cluster (G / (G - n): the clusters' residuals are shrunk by
    the fit of n unknowns). Intervals ``value * exp(+-t sigma / value)`` with Student's t at ``G - 1`` degrees of
    freedom (the model-based ones where G <= n + 1: too few clusters for a sandwich).

    Both reflect the residuals' scatter only. An error of a known parameter shifts every cluster alike, so it
    does not show there; with ``known_tolerance`` the known parameters are "consider parameters"
    (Schmidt-Kalman): a relative error ``dk`` of them moves the least-squares estimate by
    ``G dk``, ``G = -(J_u^T J_u)^+ J_u^T J_k`` (both Jacobians by relative changes, weighted like the residuals),
    so the unknowns' relative covariance gains ``G diag(tol^2) G^T``, added to the larger of the two above.

    Parameters
    ----------
    estimate : ParameterEstimate
        The joint refinement's estimate (positive values, SI).
    jacobian : ndarray, shape (n_r, n)
        ``d r / d p`` at the estimate (SI).
    residuals : ndarray, shape (n_r,)
        Weighted residuals at the estimate.
    groups : ndarray of int, shape (n_r,)
        Cluster (mode-position pair) of every residual.
    clusters : str
        What a cluster is, for ``diagnostics["uncertainty"]``.
    known_tolerance : mapping name -> float, optional
        Relative standard deviation of each considered known parameter (0.1: 10 %).
    known_jacobian : ndarray, shape (n_r, len(known_tolerance)), optional
        ``d r / d k`` of the considered known parameters at the estimate (SI), in the order of ``known_tolerance``.
    known_values : ndarray, shape (len(known_tolerance),), optional
        The considered known parameters' values (SI).

    Returns
    -------
    ParameterEstimate
        ``std`` and ``ci95`` replaced; ``diagnostics["uncertainty"]`` says how they were formed.
    """
    from scipy import stats

    p = np.asarray(estimate.values, dtype=float)
    n = p.size
    jr = np.asarray(jacobian, dtype=float) * p[None, :]  # d r / d (relative change)
    labels = np.unique(groups)
    g = labels.size
    std_rel = np.asarray(estimate.std, dtype=float) / np.abs(p)
    how = "model-based s^2 (J^T J)^-1"
    dof = max(int(residuals.size) - n, 1)
    if g > n + 1:
        bread = np.linalg.pinv(jr.T @ jr, rcond=1e-12, hermitian=True)
        scores = np.stack([jr[groups == c].T @ residuals[groups == c] for c in labels])  # (G, n)
        cov = bread @ (scores.T @ scores) @ bread * (g / (g - n))
        sandwich = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        std_rel = np.where(np.isfinite(std_rel), np.maximum(std_rel, sandwich), std_rel)
        how = f"larger of model-based and cluster-robust sandwich over {g} {clusters}"
        dof = g - 1
    considered: dict[str, Any] | None = None
    if known_tolerance:
        tol = np.array([float(v) for v in known_tolerance.values()])
        jk = np.asarray(known_jacobian, dtype=float) * np.asarray(known_values, dtype=float)[None, :]
        gain = -np.linalg.pinv(jr.T @ jr, rcond=1e-12, hermitian=True) @ (jr.T @ jk)  # (n, n_k)
        consider = np.sqrt(np.einsum("ik,k,ik->i", gain, tol**2, gain))
        before = std_rel
        std_rel = np.sqrt(std_rel**2 + consider**2)
        factor = np.where(before > 0, std_rel / before, np.inf)
        worst = int(np.nanargmax(np.where(np.isfinite(factor), factor, -np.inf))) if np.any(np.isfinite(factor)) \
            else 0
        how += " + consider covariance of the known parameters"
        considered = {"parameters": dict(known_tolerance.items()), "tolerance": "relative standard deviation",
                      "std_without": (before * np.abs(p)).tolist(), "std_from_known": (consider * np.abs(p)).tolist(),
                      "widening": factor.tolist(), "largest_widening": float(factor[worst]),
                      "largest_widening_parameter": estimate.names[worst]}
    t = float(stats.t.ppf(0.975, dof))
    std = std_rel * np.abs(p)
    positive = p > 0
    half = t * std_rel
    lo = np.where(positive, p * np.exp(-half), p - t * std)
    hi = np.where(positive, p * np.exp(half), p + t * std)
    ci = np.column_stack([lo, hi])
    ci[~np.isfinite(std)] = np.nan
    diag = {**estimate.diagnostics,
            "uncertainty": {"std": how, "ci95": f"log scale, Student t with {dof} degrees of freedom",
                            "clusters": int(g), **({"known": considered} if considered else {})}}
    return replace(estimate, std=std, ci95=ci, diagnostics=diag)


#: Pairs with a MACXP below this are reported.
MACXP_LEVEL = 0.8
#: A weighted residual whose mean square exceeds this many times its stated variance is reported.
RESIDUAL_LEVEL = 4.0


def identification_warnings(setup: Setup, joint: JointRefinement, validation: IdentificationValidation,
                            frf: FRFRefinement | None = None) -> list[str]:
    """What a user must see about the result: poorly paired or unpaired modes, estimates at a bound, residuals
    far above their stated noise, and the validation's notes (shapes not mass-normalized); with a refinement
    against measured FRFs, its own (FRF residual far above the data's noise, estimates at a bound)."""
    out: list[str] = []
    model, space, data = setup.model, setup.space, setup.data
    full = space.full(joint.values if frf is None else frf.values)
    results = ([] if validation.held is None else [validation.held]) + list(validation.identification)
    engine = ModalEngine(model, sensors=list(data.sensors))
    for res in results:
        low = np.flatnonzero(res.macxp < MACXP_LEVEL)
        for r in low:
            out.append(f"reference mode {r + 1} ({res.reference_frequency[r]:.4g} Hz) at {res.position} pairs with "
                       f"model mode {res.model_mode[r] + 1} ({res.model_frequency[r]:.4g} Hz) at MACXP "
                       f"{res.macxp[r]:.2f} < {MACXP_LEVEL}: a wrong shape, a spurious mode or a model error")
        batch = engine.evaluate(full, res.position)
        freq = batch.frequency[0]
        lo, hi = float(res.reference_frequency.min()), float(res.reference_frequency.max())
        lone = [j for j in np.flatnonzero((freq >= lo) & (freq <= hi)) if j not in set(res.model_mode.tolist())]
        if lone:
            out.append(f"model modes {[int(j) + 1 for j in lone]} ({', '.join(f'{freq[j]:.4g}' for j in lone)} Hz) at "
                       f"{res.position} lie in the reference band {lo:.4g}-{hi:.4g} Hz without a reference partner "
                       "(not found in the test, or not excited or observed)")
        out.extend(res.notes)
    at_bound = list(joint.estimate.diagnostics.get("at_bound", []))
    if at_bound and frf is None:  # with FRFs the final estimate is theirs, and so is its warning
        out.append(f"estimates at a bound: {at_bound}; the data or the bounds do not determine them")
    diag = joint.estimate.diagnostics
    n_r = int(diag.get("residuals", 0))
    if diag.get("weighting", "weights") != "weights" and n_r > space.n:
        ratio = joint.cost_after / (n_r - space.n)
        if ratio > RESIDUAL_LEVEL:
            out.append(f"the residuals' mean square is {ratio:.3g} times their stated variance "
                       f"({diag['weighting']}): the noise is understated or the model does not fit the reference")
    if frf is not None:
        out.extend(frf.warnings)
    return out


# -- step 6 -----------------------------------------------------------------------------------------------------


def validation_step(setup: Setup, final: Array, seed: int) -> IdentificationValidation:
    """The identified model at the held-out and the identification positions (FRAC, CSF, MACXP, NDD), and the
    permuted-damping models: the identified damping factors (over their start values) reassigned at random."""
    model, space, data, settings = setup.model, setup.space, setup.data, setup.settings
    truth = None if settings.truth is None else model.vector(model.structure.resolve_parameters(
        {**{n: float(v) for n, v in zip(model.parameter_names, space.base, strict=True)}, **dict(settings.truth)}))
    held, ident = setup.held, list(setup.ident)
    damp_names = setup.damping_unknowns
    n_perm = settings.n_permutations if len(damp_names) > 1 else 0

    def check(job: tuple[Array, int]) -> ValidationResult:
        params, k = job
        measured = setup.measured_at(k) if truth is None else None
        return validate_identification(model=model, params=params, reference=data, position=data.sets[k].position,
                                       truth=truth, overlay=settings.overlay,
                                       measured=None if measured is None else measured.data)

    models: list[tuple[Array, int]] = [(space.full(final), k) for k in ([] if held is None else [held]) + ident]
    assignments = []
    if n_perm:
        perm_rng = np.random.default_rng(seed)
        didx = [space.names.index(n) for n in damp_names]
        factors = final[didx] / space.start[didx]
        target = held if held is not None else ident[0]
        for _ in range(n_perm):
            order = _derangement(len(didx), perm_rng)
            p_perm = final.copy()
            p_perm[didx] = space.start[didx] * factors[order]
            models.append((space.full(p_perm), target))
            assignments.append({damp_names[i]: damp_names[o] for i, o in enumerate(order)})
    bar = setup.bar(len(data.sets) + n_perm, "validation", "model")
    # independent FRF validations: on the executor (numpy's solves release the GIL)
    try:
        checked = setup.runner.map(check, models, done=lambda _: bar.update(1))
    finally:
        _truth_receptance.cache_clear()  # the reference FRFs (tens of MB per position) are not kept
        bar.close()
    held_result = None if held is None else checked.pop(0)
    return IdentificationValidation(held_result, tuple(checked[: len(ident)]), tuple(checked[len(ident):]),
                                    tuple(assignments))


# -- helpers ----------------------------------------------------------------------------------------------------


@contextlib.contextmanager
def _recorded_warnings(caught: list[str], *, sort: bool = False) -> Iterator[None]:
    """Append the warnings raised inside the block to ``caught`` as ``"Category: message"``, from any thread
    (``catch_warnings`` is process-wide state, so it wraps a whole parallel map, not each task); ``sort`` where
    threads interleave them, so that the diagnostics do not depend on the scheduling."""
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        yield
    lines = [f"{w.category.__name__}: {w.message}" for w in record]
    caught.extend(sorted(lines) if sort else lines)


def _derangement(n: int, rng: np.random.Generator) -> NDArray[np.intp]:
    """A random permutation with no fixed point (n >= 2)."""
    while True:
        order = rng.permutation(n)
        if not np.any(order == np.arange(n)):
            return order.astype(np.intp)
