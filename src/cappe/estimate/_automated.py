"""Automated identification guided by global sensitivity analysis (Ellinger & Zaeh 2022, sections 2.2-2.3).

The pipeline (paper Fig. 1), for reference modes at several axis positions, one of which may be held out:

1. **GSA** (:func:`cappe.sensitivity.model_sobol`): one shared Sobol' sample design over all unknowns within
   their bounds, one batched modal evaluation per sample per identification position, and the total Sobol'
   indices ``ST`` of MACXP (eq. 4) and NDD^2 (eq. 5) of every reference mode at every position. The
   significant parameters of a mode-position pair are those with ``ST >= threshold`` (paper: 1 %).
2. **Stiffness** (section 2.3.2, Fig. 2). Unknowns of kind ``damping`` and ``loss`` are damping unknowns; every
   other unknown (stiffness, and mass, inertia, length or other if any) is a *modal* unknown, found in this stage.
   For every mode-position subproblem whose MACXP has significant modal unknowns, ``n_opt`` local searches run
   over those unknowns only, from random starts in the bounds, with every other unknown drawn at random in its
   bounds for each run (the paper's brute force). The objective of subproblem (r, j) is the agreement of the
   model mode paired with reference mode r at position j (largest MACXP):
   ``J = w_f NFD^2 + w_s (1 - MAC)``, ``NFD = (f_m - f_r) / f_r``: the two things the MACXP measures (pole
   proximity and shape similarity) in a smooth least-squares form (``1 - MAC`` is the squared norm of the
   reference shape's residual off the model shape, as in :class:`~cappe.estimate.ModalUpdatingEstimator`).
   The ``n_opt`` runs are one batch: a projected Levenberg-Marquardt iteration in log coordinates with analytic
   eigenvalue and eigenvector derivatives (modal expansion, exact since all modes are known), every iteration
   one batched eigen solution for all runs. For each modal unknown, the subproblem with the least spread of its
   optimum over the runs (relative standard deviation, paper section 2.3.2; subproblems where half the runs or
   more ended at a bound are passed over) gives its value, the median of the runs (the paper takes the mean;
   the median ignores the runs trapped in other minima; both are reported). Then all modal unknowns are refined
   jointly over all modes and positions (:class:`~cappe.estimate.ModalUpdatingEstimator`, frequency and shape
   residuals, damping fixed), started at that selection and at a few alternatives (the consensus of all
   subproblems, and the selections by the second, third ... least spread; a single local refinement can be
   trapped where modes cross), the lowest cost winning; the diagnostics report the cost at the selection and
   after, and the parameter changes.
3. **Damping** (section 2.3.3). At the identified stiffness, the first-order damping ratio of every mode is
   ``zeta_r = zeta_known,r + sum_n q_rn p_n`` with ``q_rn = d zeta_r / d p_n`` at fixed modes
   (:attr:`cappe.modal.ModalBatch.damping_gradient`; exact for coefficients linear in the damping unknowns, as
   ``c`` and ``eta * k`` are). Rows are the mode-position pairs: the paper's selection keeps those with the
   least influence of the non-search (modal) unknowns on their NDD^2 (sum of their ST) whose residual damping
   ``zeta_ref - zeta_known`` is at least ``residual_damping_threshold`` (paper: 0.5 %), enough of them for
   ``2 n_damping`` rows (a third of all rows if more) and full column rank. Each row is divided by
   ``zeta_ref`` (the residual is then the NDD) and solved by bounded linear least squares
   (:func:`scipy.optimize.lsq_linear`).
4. **Joint refinement** of all unknowns over all modes and positions (frequency, damping and shape residuals,
   weights ``weights``), started at stages 2-3, on the model's exact complex modes (:class:`ExactModalProblem`;
   ``exact=False``: first-order modes, :class:`~cappe.estimate.ModalUpdatingEstimator`); its Jacobian gives the
   uncertainty and identifiability. Stages 1-3 use the first-order modes (light damping, assumption A1), whose
   difference from exact complex modes (mode complexity from non-proportional damping) would otherwise bias
   the estimates by up to about 1 % on closely spaced modes.
5. **Validation** (:func:`validate_identification`) at the held-out position and at the identification positions:
   FRAC, CSF, MACXP, NDD statistics (paper Tables 2-5); and the permuted-damping comparison (Fig. 7): the
   identified damping unknowns' factors from their start (preliminary) values, reassigned to other damping
   unknowns at random, give models whose validation criteria show what the damping identification is worth.
"""

from __future__ import annotations

import contextlib
import copy
import time
import warnings
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import replace
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from cappe._rng import RandomLike
from cappe.estimate._base import CostFunction, Estimator, Fitted, least_squares_fit
from cappe.estimate._damping_least_squares import DampingLeastSquares, damping_least_squares
from cappe.estimate._exact_modal import ExactModalProblem
from cappe.estimate._modal_updating import ModalUpdatingEstimator
from cappe.estimate._result import ParameterEstimate
from cappe.estimate._space import ParameterSpace
from cappe.estimate._subproblems import SubproblemResult, _alternative_starts, select_stiffness, solve_subproblem
from cappe.estimate._validation import (
    ValidationResult,
    _truth_receptance,
    find_set,
    summarize,
    validate_identification,
)
from cappe.exceptions import DataError, ModelError
from cappe.io.modal import ModalData
from cappe.modal import ModalEngine
from cappe.model import NumericModel, Structure
from cappe.parallel import Executor, chunk_slices, single_threaded_blas

__all__ = [
    "DAMPING_KINDS",
    "AutomatedIdentification",
    "DampingLeastSquares",
    "SubproblemResult",
    "damping_least_squares",
    "select_stiffness",
    "solve_subproblem",
]

Array = NDArray[np.float64]
CArray = NDArray[np.complex128]
#: Parameter kinds identified by the damping stage; every other unknown is found from frequencies and shapes.
DAMPING_KINDS = ("damping", "loss")


# -------------------------------------------------------------------------------------------------------------
# the estimator
# -------------------------------------------------------------------------------------------------------------


class AutomatedIdentification(Estimator):
    """GSA-guided identification of all unknowns from reference modes at several axis positions (see the module).

    Parameters
    ----------
    model, unknowns, bounds, start, values, rng
        See :class:`Estimator`. ``start`` is the preliminary model (default: the model's values); every unknown
        needs finite bounds (the GSA samples within them).
    n_gsa : int
        Base sample size of the Sobol' design (power of two); the model runs ``n_gsa (D + 2)`` times per position.
    n_opt : int
        Local searches per mode-position subproblem.
    threshold : float
        Total Sobol' index from which a parameter is significant (paper: 0.01).
    validation : mapping, optional
        Axis position of the reference set held out for validation (e.g. ``{"z": -0.294}``); the others identify.
    criteria : sequence of str
        GSA outputs per mode and position, among ``("macxp", "ndd2", "frequency", "damping")``; ``macxp``
        is needed for the stiffness subproblems, ``ndd2`` for the damping row selection.
    weights : (float, float, float)
        ``(w_f, w_z, w_s)`` of the frequency, damping and shape residuals of the subproblems (``w_f``, ``w_s``) and
        of the refinements (see :class:`ModalUpdatingEstimator`). The default gives relative damping residuals
        the weight 0.01, the inverse variance ratio of typical modal-test scatter (damping ratios about ten times
        less certain than frequencies): errors in the known damping of an imperfect model then do not pull the
        stiffnesses (disturbed benchmark case, paper 3.3: worst stiffness error 5.6 % with weight 1, 2.6 % with
        0.01). ``noise`` replaces these weights in the final refinement.
    residual_damping_threshold : float
        Smallest residual damping ratio of a damping row (paper: 0.005).
    damping_rows : int, optional
        Rows of the damping least squares (default ``max(2 n_d, rows // 3)``).
    max_iterations : int
        Iteration limit of the batched subproblem searches.
    refine_starts : int
        Starts of the joint stiffness refinement: the paper's selection, the consensus of all subproblems
        (each unknown's median over the subproblems that determine it) and the selections by 2nd, 3rd ... least
        spread; the lowest final cost wins. A single start can be trapped where modes cross between positions.
    truth : mapping, optional
        True parameters of a simulated reference: validation FRFs then come from the model at the truth.
    n_permutations : int
        Random reassignments of the damping factors in the permuted-damping comparison (0: none).
    exact : bool
        Final joint refinement on the model's exact complex modes (default; right for measured modes and for
        references simulated with exact modes) rather than first-order ones (right for first-order references).
    noise : (float, float, float), optional
        Relative noise of the reference's frequencies, damping ratios and shape components (e.g.
        ``(0.005, 0.05, 0.02)``): the final refinement then weights its residuals by their noise (see
        :class:`ExactModalProblem`), which makes its 95 % intervals meaningful. Needs ``exact``.
    overlay : (str, str), optional
        Output and input channel of the FRF kept for overlays (default: the driving point with the largest peak).
    n_workers : int, optional
        Threads for the GSA and the subproblems (default one per core).
    executor : Executor, str or None
        Where the GSA's model evaluations and the subproblems run instead: ``"serial"``, ``"threads"``,
        ``"processes"`` or a Dask scheduler address (see :class:`cappe.parallel.Executor`). The result is the
        same for every choice.
    progress : bool
        Progress bars (tqdm, stderr) per stage.

    Attributes
    ----------
    estimate_ : ParameterEstimate
        All unknowns with the joint refinement's uncertainty; ``diagnostics`` holds ``gsa``, ``subproblems``,
        ``selection``, ``stiffness_refinement``, ``damping``, ``costs``, ``timings`` (s) and ``validation``.
    gsa_ : ModelSobolResult
    subproblems_ : list of SubproblemResult
    damping_ : DampingLeastSquares or None
    validation_ : dict
        ``"validation"``: ValidationResult at the held-out position (or None), ``"identification"``: list at the
        identification positions, ``"permuted"``: list of ValidationResult at the held-out (else first) position.
    timings_ : dict
        Seconds per stage.

    Examples
    --------
    >>> from cappe.model import load_model
    >>> rig = load_model("builtin:two-mass-rig")
    >>> truth = {"k11": 1.5e6, "k22": 0.25e6, "c11": 15.0, "c22": 1.0}
    >>> ref = ModalEngine(rig).modal_data(params=truth)
    >>> est = AutomatedIdentification(rig, ["k11", "k22", "c11", "c22"], n_gsa=64, n_opt=4, rng=0,
    ...                               bounds={"k11": (1e6, 2e6), "k22": (0.2e6, 0.3e6), "c11": (5, 30),
    ...                                       "c22": (0.2, 3)}, n_permutations=0, n_workers=1).fit(ref)
    >>> {k: round(v / truth[k], 6) for k, v in est.params_.items()}
    {'k11': 1.0, 'k22': 1.0, 'c11': 1.0, 'c22': 1.0}
    """

    method: ClassVar[str] = "automated-gsa"

    def __init__(
        self,
        model: NumericModel | Structure,
        unknowns: Sequence[str] | None = None,
        *,
        bounds: Mapping[str, Sequence[float]] | None = None,
        start: Mapping[str, float] | None = None,
        values: Mapping[str, float] | None = None,
        rng: RandomLike = None,
        n_gsa: int = 1024,
        n_opt: int = 100,
        threshold: float = 0.01,
        validation: Mapping[str, float] | None = None,
        criteria: Sequence[str] = ("macxp", "ndd2"),
        weights: tuple[float, float, float] = (1.0, 0.01, 1.0),
        residual_damping_threshold: float = 0.005,
        damping_rows: int | None = None,
        max_iterations: int = 50,
        refine_starts: int = 3,
        truth: Mapping[str, float] | None = None,
        n_permutations: int = 10,
        exact: bool = True,
        noise: Sequence[float] | None = None,
        overlay: tuple[str, str] | None = None,
        n_workers: int | None = None,
        executor: Executor | str | None = None,
        progress: bool = False,
    ) -> None:
        super().__init__(model, unknowns, bounds=bounds, start=start, values=values, rng=rng)
        self.n_gsa = n_gsa
        self.n_opt = n_opt
        self.threshold = threshold
        self.validation = validation
        self.criteria = criteria
        self.weights = weights
        self.residual_damping_threshold = residual_damping_threshold
        self.damping_rows = damping_rows
        self.max_iterations = max_iterations
        self.refine_starts = refine_starts
        self.truth = truth
        self.n_permutations = n_permutations
        self.exact = exact
        self.noise = noise
        self.overlay = overlay
        self.n_workers = n_workers
        self.executor = executor
        self.progress = progress

    # -- checks -------------------------------------------------------------------------------------------------
    def _check(self, model: NumericModel, space: ParameterSpace, data: Any) -> tuple[list[int], int | None]:
        """Validated settings and data: (identification set indices, validation set index or None)."""
        if not isinstance(data, ModalData):
            msg = f"automated identification needs reference ModalData (cappe.modal/1); got {type(data).__name__}"
            raise DataError(msg)
        name = model.structure.name
        if not data.sets:
            msg = "reference modal data have no sets; the identification needs modes at one or more positions"
            raise DataError(msg)
        for setting, value, low in (("n_gsa", self.n_gsa, 2), ("n_opt", self.n_opt, 1),
                                    ("max_iterations", self.max_iterations, 1),
                                    ("refine_starts", self.refine_starts, 1),
                                    ("n_permutations", self.n_permutations, 0)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
                msg = f"{setting} must be an integer >= {low}; got {value!r}"
                raise DataError(msg)
        if not (isinstance(self.threshold, (int, float)) and 0 <= self.threshold < 1):
            msg = f"threshold must be a number in [0, 1); got {self.threshold!r}"
            raise DataError(msg)
        if "macxp" not in tuple(self.criteria):
            msg = f"criteria must include 'macxp' (the stiffness subproblems use it); got {list(self.criteria)}"
            raise DataError(msg)
        w = np.asarray(self.weights, dtype=float)
        if w.shape != (3,) or not np.all(np.isfinite(w) & (w >= 0)) or w[0] + w[2] == 0:
            msg = f"weights (w_f, w_z, w_s) must be three finite numbers >= 0 with w_f + w_s > 0; got {self.weights!r}"
            raise DataError(msg)
        if self.noise is not None:
            levels = np.asarray(self.noise, dtype=float)
            if levels.shape != (3,) or not np.all(np.isfinite(levels) & (levels > 0)):
                msg = f"noise must be three numbers > 0 (frequency, damping, shape); got {self.noise!r}"
                raise DataError(msg)
            if not self.exact:
                msg = "noise weighting needs the exact-mode refinement (exact=True)"
                raise DataError(msg)
        bad = [n for n, lo, hi in zip(space.names, space.lower, space.upper, strict=True)
               if not (np.isfinite(lo) and np.isfinite(hi) and lo > 0)]
        if bad:
            msg = f"unknowns {bad} of model '{name}' need finite bounds 0 < lower < upper for the GSA and searches"
            raise ModelError(msg)
        labels, _ = model.sensor_matrix()
        missing = [s for s in data.sensors if s not in labels]
        if missing:
            msg = f"reference sensors {missing} are not sensor channels of model '{name}'; its channels: {labels}"
            raise DataError(msg)
        for k, data_set in enumerate(data.sets):
            where = f"reference set {k} (position {data_set.position})"
            unknown_axes = sorted(set(data_set.position) - set(model.axis_names))
            if unknown_axes:
                msg = (f"{where}: axes {unknown_axes} are not axes of model '{name}' "
                       f"(its axes: {list(model.axis_names)})")
                raise DataError(msg)
            missing_axes = sorted(set(model.axis_names) - set(data_set.position))
            if missing_axes:
                msg = f"{where}: no value for the model's axes {missing_axes}"
                raise DataError(msg)
            if data_set.n_modes == 0:
                msg = f"{where} has no modes"
                raise DataError(msg)
            if data_set.n_modes > model.n_dof:
                msg = f"{where} has {data_set.n_modes} modes; model '{name}' has only {model.n_dof}"
                raise DataError(msg)
            if np.any(data_set.frequency <= 0):
                bad_modes = (np.flatnonzero(data_set.frequency <= 0) + 1).tolist()
                msg = f"{where}: modes {bad_modes} have frequencies <= 0 Hz"
                raise DataError(msg)
            if np.any(data_set.damping <= 0):
                bad_modes = (np.flatnonzero(data_set.damping <= 0) + 1).tolist()
                msg = f"{where}: modes {bad_modes} have damping ratios <= 0; NDD and the damping stage need > 0"
                raise DataError(msg)
            zero = np.flatnonzero(np.sum(np.abs(data_set.shapes) ** 2, axis=0) == 0)
            if zero.size:
                msg = f"{where}: modes {(zero + 1).tolist()} have all-zero shapes"
                raise DataError(msg)
        held: int | None = None
        if self.validation is not None:
            held = find_set(data, self.validation, model)
        ident = [k for k in range(len(data.sets)) if k != held]
        if not ident:
            msg = "every reference set is held out for validation; at least one position must identify"
            raise DataError(msg)
        return ident, held

    # -- the pipeline -------------------------------------------------------------------------------------------
    def _fit(self, model: NumericModel, space: ParameterSpace, data: Any,
             rng: np.random.Generator) -> Fitted:
        runner = Executor.coerce(self.executor, self.n_workers)
        try:
            # BLAS on one thread in the calling thread too: the refinements' least squares take an SVD of a Jacobian
            # of about 10 000 x 27 per step, measured 51 ms on two OpenBLAS threads against 6 ms on one (the
            # stiffness refinement 1.9 -> 0.6 s in benchmarks/bench_pipeline.py); the parallelism is over samples
            with single_threaded_blas():
                return self._stages(model, space, data, rng, runner)
        finally:
            if runner is not self.executor:  # made here (e.g. a Dask client from an address): release it
                runner.close()

    def _stages(self, model: NumericModel, space: ParameterSpace, data: Any, rng: np.random.Generator,
                runner: Executor) -> Fitted:
        """GSA, stiffness subproblems and refinement, damping, joint refinement and validation (see the class)."""
        from tqdm.auto import tqdm

        from cappe.sensitivity import model_sobol

        ident, held = self._check(model, space, data)
        t_total = time.perf_counter()
        timings: dict[str, float] = {}
        caught: list[str] = []
        structure = model.structure
        kinds = {n: structure.parameter(n).kind for n in space.names}
        damp_names = [n for n in space.names if kinds[n] in DAMPING_KINDS]
        modal_names = [n for n in space.names if kinds[n] not in DAMPING_KINDS]
        ident_ref = ModalData(data.sensors, tuple(data.sets[k] for k in ident), data.source)
        seeds = rng.integers(1, 2**31, size=4)
        w_f, w_z, w_s = (float(v) for v in self.weights)
        # the known parameters' values: the GSA evaluates the model at its nominal vector, so hand it (and the
        # subproblems' engine, whose shared-mass reduction is that of the nominal M) a view whose nominal holds them
        base_model = model
        if not np.array_equal(space.base, model.nominal):
            base_model = copy.copy(model)
            base_model.nominal = space.base.copy()
        bounds_arr = np.column_stack([space.lower, space.upper])

        # 1. GSA ------------------------------------------------------------------------------------------------
        t = time.perf_counter()
        gsa = model_sobol(base_model, ident_ref, parameters=list(space.names), bounds=bounds_arr, n=int(self.n_gsa),
                          rng=int(seeds[0]), criteria=tuple(self.criteria), n_workers=self.n_workers,
                          executor=runner,
                          progress=self.progress)
        timings["gsa"] = time.perf_counter() - t
        st = gsa.sobol.ST
        table: dict[tuple[int, int, str], Array] = {}
        out_index = 0
        for j in range(len(ident)):
            for r in range(ident_ref.sets[j].n_modes):
                for c in self.criteria:
                    table[(j, r, c)] = st[out_index]
                    out_index += 1
        significant = {key: tuple(n for n, v in zip(space.names, row, strict=True) if v >= self.threshold)
                       for key, row in table.items()}

        # 2. stiffness subproblems --------------------------------------------------------------------------------
        t = time.perf_counter()
        engine = ModalEngine(base_model, sensors=list(data.sensors))  # known masses at their nominal: shared M
        jobs: list[tuple[int, int, tuple[str, ...]]] = []
        for j in range(len(ident)):
            position = structure.resolve_position(ident_ref.sets[j].position)
            engine.evaluate(space.full(space.start), position)  # warm the per-position caches before threading
            for r in range(ident_ref.sets[j].n_modes):
                search = tuple(n for n in significant[(j, r, "macxp")] if n in modal_names)
                if search:
                    jobs.append((j, r, search))
        job_seeds = np.random.default_rng(int(seeds[1])).integers(1, 2**31, size=max(len(jobs), 1))
        lo_u, hi_u = space.internal_bounds()
        n_opt = int(self.n_opt)
        bar: Any = tqdm(total=len(jobs), desc="stiffness subproblems", unit="subproblem", disable=not self.progress)

        def run(s: slice) -> list[SubproblemResult]:
            results = []
            for q in range(s.start, s.stop):
                j, r, search = jobs[q]
                sub_rng = np.random.default_rng(int(job_seeds[q]))
                u = sub_rng.uniform(lo_u, hi_u, size=(n_opt, space.n))  # random unknowns, starts included
                starts = space.full(space.from_internal(u))
                idx = [space.names.index(n) for n in search]
                t0 = time.perf_counter()
                values, cost, iters = solve_subproblem(
                    model=model, reference=ident_ref, set_index=j, mode=r, parameters=search, start=starts,
                    lower=space.lower[idx], upper=space.upper[idx], weights=(w_f, w_s),
                    max_iterations=int(self.max_iterations), engine=engine)
                position = structure.resolve_position(ident_ref.sets[j].position)
                results.append(SubproblemResult(r + 1, dict(position), search, values, cost, iters,
                                                time.perf_counter() - t0, space.lower[idx], space.upper[idx]))
            return results

        try:
            parts = runner.map(
                run, chunk_slices(len(jobs), 1), done=lambda s: bar.update(s.stop - s.start))
        finally:
            bar.close()
        subproblems = [sub for part in parts for sub in part]
        selection = select_stiffness(subproblems, modal_names)
        timings["stiffness_subproblems"] = time.perf_counter() - t
        current = space.start.copy()
        for n, sel in selection.items():
            i = space.names.index(n)
            current[i] = np.clip(sel["value"], space.lower[i], space.upper[i])
        selected = current.copy()

        # 2b. joint stiffness refinement ---------------------------------------------------------------------------
        t = time.perf_counter()
        refinement: dict[str, Any] = {}
        if modal_names:
            candidates = _alternative_starts(subproblems, space, selected, modal_names, int(self.refine_starts))
            best: tuple[Array, dict[str, Any]] | None = None
            runs = []
            # independent local refinements: side by side on a thread executor (numpy's solves release the GIL);
            # their warnings are recorded here, around all of them (catch_warnings is process-wide state)
            local = runner if runner.kind == "threads" else Executor("serial")
            refine_bar: Any = tqdm(total=len(candidates), desc="stiffness refinement", unit="start",
                                   disable=not self.progress)
            with _recorded_warnings(caught, sort=True):  # the starts' threads interleave their warnings
                try:
                    refined = local.map(
                        lambda c: self._refine(model, space, ident_ref, c[1], modal_names, (w_f, 0.0, w_s)),
                        candidates, done=lambda _: refine_bar.update(1))
                finally:
                    refine_bar.close()
            for (label, _), (found, info) in zip(candidates, refined, strict=True):
                runs.append({"start": label, "cost_before": info["cost_before"], "cost_after": info["cost_after"]})
                if best is None or info["cost_after"] < best[1]["cost_after"] * (1 - 1e-9):
                    best = (found, {**info, "start": label})
            assert best is not None  # candidates always hold the selection
            current, refinement = best
            refinement["runs"] = runs
            refinement["cost_before"] = runs[0]["cost_before"]  # the paper's selection
            refinement["selection"] = {n: float(selected[space.names.index(n)]) for n in modal_names}
            refinement["relative_change"] = {n: float(current[space.names.index(n)] / selected[space.names.index(n)]
                                                      - 1.0) for n in modal_names}
        timings["stiffness_refinement"] = time.perf_counter() - t

        # 3. damping least squares -------------------------------------------------------------------------------
        t = time.perf_counter()
        damping_result: DampingLeastSquares | None = None
        if damp_names:
            interaction: dict[tuple[int, int], float] | None = None
            if "ndd2" in tuple(self.criteria):
                others = np.array([n not in damp_names for n in space.names])
                interaction = {(k, r): float(np.sum(np.clip(table[(j, r, "ndd2")][others], 0, None)))
                               for j, k in enumerate(ident) for r in range(data.sets[k].n_modes)}
            didx = [space.names.index(n) for n in damp_names]
            damping_result = damping_least_squares(
                model=model, reference=data, params=space.full(current), damping=damp_names,
                lower=space.lower[didx], upper=space.upper[didx], sets=ident, interaction=interaction,
                n_rows=self.damping_rows, residual_threshold=float(self.residual_damping_threshold))
            current[didx] = damping_result.values
        after_stages = current.copy()
        timings["damping_least_squares"] = time.perf_counter() - t

        # 4. joint refinement of everything ----------------------------------------------------------------------
        t = time.perf_counter()
        if self.exact:
            final, joint = self._refine_exact(model, space, ident_ref, current, (w_f, w_z, w_s), runner)
        else:
            with _recorded_warnings(caught):
                final, joint = self._refine(model, space, ident_ref, current, list(space.names), (w_f, w_z, w_s),
                                            keep=True)
        timings["joint_refinement"] = time.perf_counter() - t
        estimate: ParameterEstimate = joint.pop("estimate")
        cost: CostFunction | None = joint.pop("cost_function")

        # 5. validation ------------------------------------------------------------------------------------------
        t = time.perf_counter()
        truth_vec = None if self.truth is None else model.vector(structure.resolve_parameters(
            {**{n: float(v) for n, v in zip(model.parameter_names, space.base, strict=True)}, **dict(self.truth)}))
        p_final = space.full(final)
        n_perm = int(self.n_permutations) if len(damp_names) > 1 else 0
        val_bar: Any = tqdm(total=len(data.sets) + n_perm, desc="validation", unit="model",
                            disable=not self.progress)

        def check(job: tuple[Array, int]) -> ValidationResult:
            params, k = job
            return validate_identification(model=model, params=params, reference=data,
                                           position=data.sets[k].position, truth=truth_vec, overlay=self.overlay)

        models: list[tuple[Array, int]] = [(p_final, k) for k in ([] if held is None else [held]) + list(ident)]
        perm_info: list[dict[str, Any]] = []
        if n_perm:
            perm_rng = np.random.default_rng(int(seeds[2]))
            didx = [space.names.index(n) for n in damp_names]
            factors = final[didx] / space.start[didx]
            target = held if held is not None else ident[0]
            for _ in range(n_perm):
                order = _derangement(len(didx), perm_rng)
                p_perm = final.copy()
                p_perm[didx] = space.start[didx] * factors[order]
                models.append((space.full(p_perm), target))
                perm_info.append({"assignment": {damp_names[i]: damp_names[o] for i, o in enumerate(order)}})
        # independent FRF validations: on the executor (numpy's solves release the GIL)
        try:
            checked = runner.map(check, models, done=lambda _: val_bar.update(1))
        finally:
            _truth_receptance.cache_clear()  # the reference FRFs (tens of MB per position) are not kept
        held_result = None if held is None else checked.pop(0)
        ident_results = checked[: len(ident)]
        permuted = checked[len(ident):]
        for info, result in zip(perm_info, permuted, strict=True):
            info["statistics"] = result.statistics()
        val_bar.close()
        timings["validation"] = time.perf_counter() - t
        timings["total"] = time.perf_counter() - t_total

        # result ---------------------------------------------------------------------------------------------------
        self.gsa_ = gsa
        self.subproblems_ = subproblems
        self.damping_ = damping_result
        self.validation_ = {"validation": held_result, "identification": ident_results, "permuted": permuted}
        self.timings_ = timings
        self.selection_ = selection
        gsa_rows = []
        for (j, r, c), row in table.items():
            gsa_rows.append({"mode": r + 1, "position": dict(ident_ref.sets[j].position), "criterion": c,
                             "reference_frequency": float(ident_ref.sets[j].frequency[r]),
                             "significant": list(significant[(j, r, c)]),
                             "ST": {n: float(v) for n, v in zip(space.names, row, strict=True)}})
        costs = {"selection": refinement.get("cost_before"), "stiffness_refined": refinement.get("cost_after"),
                 "after_damping_least_squares": joint.get("cost_before"), "final": joint.get("cost_after")}
        diagnostics: dict[str, Any] = dict(estimate.diagnostics)
        diagnostics.update({
            "stiffness_unknowns": modal_names,
            "damping_unknowns": damp_names,
            "identification_positions": [dict(data.sets[k].position) for k in ident],
            "validation_position": None if held is None else dict(data.sets[held].position),
            "settings": {"n_gsa": int(self.n_gsa), "n_opt": n_opt, "threshold": float(self.threshold),
                         "criteria": list(self.criteria), "weights": [w_f, w_z, w_s],
                         "residual_damping_threshold": float(self.residual_damping_threshold),
                         "exact": bool(self.exact), "noise": None if self.noise is None else list(self.noise),
                         "objective": "subproblems: w_f NFD^2 + w_s (1 - MAC) of the MACXP-paired mode"},
            "gsa": {"n": int(self.n_gsa), "model_runs": int(self.n_gsa) * (space.n + 2) * len(ident),
                    "threshold": float(self.threshold), "outputs": gsa_rows},
            "subproblems": [s.to_dict() for s in subproblems],
            "selection": selection,
            "not_searched": [n for n in modal_names if n not in selection],
            "stiffness_refinement": refinement,
            "damping": None if damping_result is None else damping_result.to_dict(),
            "joint_refinement": joint,
            "stages": {"selection": space.mapping(selected),
                       "after_damping_least_squares": space.mapping(after_stages)},
            "costs": costs,
            "timings": timings,
            "validation": {
                "validation": None if held_result is None else held_result.to_dict(),
                "identification": [v.to_dict() for v in ident_results],
                "identification_statistics": _pooled(ident_results),
                "permuted": perm_info,
            },
            "warnings": caught,
        })
        return Fitted(replace(estimate, method=self.method, diagnostics=diagnostics), cost)

    def _refine(
        self,
        model: NumericModel,
        space: ParameterSpace,
        reference: ModalData,
        current: Array,
        names: list[str],
        weights: tuple[float, float, float],
        *,
        keep: bool = False,
    ) -> tuple[Array, dict[str, Any]]:
        """Modal updating over ``names`` from ``current`` (other unknowns fixed); cost before/after, changes.

        The caller records the fit's warnings."""
        fixed = {n: float(v) for n, v in zip(space.names, current, strict=True) if n not in names}
        known = {n: float(v) for n, v in zip(model.parameter_names, space.base, strict=True)}
        known.update(fixed)
        idx = [space.names.index(n) for n in names]
        bounds = {n: (float(space.lower[i]), float(space.upper[i])) for n, i in zip(names, idx, strict=True)}
        start = {n: float(np.clip(current[i], space.lower[i], space.upper[i])) for n, i in zip(names, idx, strict=True)}
        updater = ModalUpdatingEstimator(model, names, bounds=bounds, start=start, values=known, weights=weights)
        sub_space = ParameterSpace.from_model(model, names, bounds=bounds, start=start, values=known)
        problem = updater._problem(model, sub_space, reference)
        r0 = problem.residuals(sub_space.start)
        updater.fit(reference)
        est = updater.estimate_
        out = current.copy()
        out[idx] = est.values
        info: dict[str, Any] = {
            "cost_before": float(r0 @ r0),
            "cost_after": float(est.cost),
            "success": bool(est.success),
            "message": est.message,
            "evaluations": est.diagnostics.get("evaluations"),
            "relative_change": {n: float(est.values[k] / current[i] - 1.0) for k, (n, i) in
                                enumerate(zip(names, idx, strict=True))},
        }
        if keep:
            info["estimate"] = est
            info["cost_function"] = CostFunction(sub_space, problem.residuals, np.asarray(est.values, dtype=float))
        return out, info


    def _refine_exact(
        self,
        model: NumericModel,
        space: ParameterSpace,
        reference: ModalData,
        current: Array,
        weights: tuple[float, float, float],
        runner: Executor,
    ) -> tuple[Array, dict[str, Any]]:
        """Joint refinement of all unknowns on the model's exact complex modes (analytic Jacobian)."""
        problem = ExactModalProblem(model, space, reference, weights, self.noise, executor=runner)
        r0 = problem.residuals(current)
        diagnostics = {"modes": "exact", "jacobian": "analytic (eigen-decomposition perturbation)"}
        start = np.clip(current, space.lower, space.upper)
        fitted = least_squares_fit(self.method, space, problem.residuals, problem.jacobian,
                                   starts=start[None, :], diagnostics=diagnostics)
        est = fitted.estimate
        info: dict[str, Any] = {
            "cost_before": float(r0 @ r0),
            "cost_after": float(est.cost),
            "success": bool(est.success),
            "message": est.message,
            "evaluations": problem.evaluations,
            "relative_change": {n: float(v / c - 1.0) for n, v, c in zip(space.names, est.values, current,
                                                                          strict=True)},
            "pairing": problem.pairing_report(np.asarray(est.values, dtype=float)),
            "estimate": est,
            "cost_function": fitted.cost,
        }
        return np.asarray(est.values, dtype=float), info


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


def _pooled(results: Sequence[ValidationResult]) -> dict[str, dict[str, float]]:
    """Statistics over several positions at once (paper Tables 2 and 4)."""
    if not results:
        return {}
    out = {}
    for c in ("frac", "csf", "macxp", "ndd"):
        out[c] = summarize(np.concatenate([r.values(c) for r in results]), larger_is_better=c != "ndd")
    return out
