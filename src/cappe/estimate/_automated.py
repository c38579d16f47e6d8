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

   **With measured FRFs** (``frf``) at identification positions, all unknowns are then fitted to them
   (:mod:`cappe.estimate._frf_refinement`: complex-log residuals weighted by the data's own noise, started at the
   joint refinement, which found the basin): the FRFs settle what extracted modes cannot (mode complexity, damping
   that barely moves an extracted damping ratio). Its estimate and uncertainty are the final ones.
5. **Validation** (:func:`validate_identification`) at the held-out position and at the identification positions:
   FRAC, CSF, MACXP, NDD statistics (paper Tables 2-5; FRAC and CSF against the measured FRFs where ``frf`` has
   them and ``truth`` is not given); and the permuted-damping comparison (Fig. 7): the
   identified damping unknowns' factors from their start (preliminary) values, reassigned to other damping
   unknowns at random, give models whose validation criteria show what the damping identification is worth.

Where the code is: this module holds the estimator (its settings, their checks and the reference's);
``_automated_steps`` the steps, each a function that returns a typed result of ``_automated_result``
(:class:`GSAStage`, :class:`StiffnessSearch`, :class:`StiffnessRefinement`, :class:`DampingLeastSquares`,
:class:`JointRefinement`, :class:`IdentificationValidation`, together :class:`AutomatedResult`); the maths of
stages 2 and 3 is in ``_subproblems`` and ``_damping_least_squares``, the exact-mode residuals in ``_exact_modal``.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any, ClassVar, Self

import numpy as np

from cappe._rng import RandomLike
from cappe.estimate._automated_result import AutomatedResult, AutomatedSettings
from cappe.estimate._automated_steps import DAMPING_KINDS, Setup, run_pipeline
from cappe.estimate._base import Estimator, Fitted
from cappe.estimate._damping_least_squares import DampingLeastSquares
from cappe.estimate._frf_refinement import MeasuredFRF
from cappe.estimate._modal_updating import check_finite_modes
from cappe.estimate._space import ParameterSpace
from cappe.estimate._subproblems import SubproblemResult
from cappe.estimate._validation import find_set
from cappe.exceptions import DataError, ModelError, NotFittedError
from cappe.model import NumericModel, Structure
from cappe.parallel import Executor, single_threaded_blas
from cappe.systems.modal import ModalData, ModalDataSet

__all__ = ["DAMPING_KINDS", "AutomatedIdentification"]

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
    n_permutations : int
        Random reassignments of the damping factors in the validation step's permuted-damping comparison (0: none).
    exact : bool
        Final joint refinement on the model's exact complex modes (default; right for measured modes and for
        references simulated with exact modes) rather than first-order ones (right for first-order references).
    noise : (float, float, float), optional
        Relative noise of the reference's frequencies, damping ratios and shape components (e.g.
        ``(0.005, 0.05, 0.02)``): the final refinement then weights its residuals by their noise (see
        :class:`ExactModalProblem`), which makes its 95 % intervals meaningful. Needs ``exact``.
    shapes : {"real", "complex"}
        Shapes the exact-mode refinement compares. ``"real"`` (default): model and reference shapes are each
        realized (turned to their principal phase, real part kept; :func:`~cappe.estimate._exact_modal.realized`),
        which removes the mode complexity that a rational (LSCF/LSFD) fit of FRFs with hysteretic damping
        ``K + iH`` cannot reproduce (its mirrored poles are not complex conjugates): 1 - MAC between extracted and
        exact modes at the truth halves (0.005 -> 0.0025). Frequencies and damping ratios still come from the
        exact complex poles; exact at the truth for simulated references too. ``"complex"``: complex shapes as
        they are, which keep the phase of non-proportional damping. Measured on the chain of
        ``benchmarks/bench_real_chain.py`` (3 truths, same extracted modes and start): worst stiffness error
        2.2 / 3.6 / 2.1 % realized against 2.2 / 2.2 / 20.7 % complex, worst damping error 43 / 40 / 64 % against
        30 / 6 / 27 % (issue 20).
    n_workers : int, optional
        Threads for the GSA and the subproblems (default one per core).
    executor : Executor, str or None
        Where the GSA's model evaluations and the subproblems run instead: ``"serial"``, ``"threads"``,
        ``"processes"`` or a Dask scheduler address (see :class:`cappe.parallel.Executor`). The result is the
        same for every choice.
    frf : sequence of MeasuredFRF, optional
        Measured FRFs at reference positions (at model sensor channels). At identification positions, all unknowns
        are refined against them after the modal stages (:mod:`cappe.estimate._frf_refinement`); at the held-out
        position, the validation's FRAC and CSF compare the model with them (without ``truth``).
    known_tolerance : mapping name -> float, optional
        Relative standard deviation (0.1: 10 %) of known parameters whose error the 95 % intervals should include
        (consider covariance, :func:`~cappe.estimate._automated_steps.robust_uncertainty`; exact-mode refinement
        only, and the refinement against measured FRFs after it). An error bounded by +-REL (uniform, or +-REL
        with a random sign as in the disturbed case) has a standard deviation of at most REL, so REL itself is a
        safe value. Without it the intervals assume the known parameters exact.
    **deprecated
        ``truth``, ``overlay`` and ``progress``: arguments of :meth:`fit` since cappe 0.1 (they do not shape the
        estimate; they say what one run validates against, which FRF it keeps and whether it shows progress).
        Given here they still work until cappe 0.2, with a :class:`DeprecationWarning`, as defaults of :meth:`fit`.

    Attributes
    ----------
    result_ : AutomatedResult
        Every step's typed result (``gsa``, ``stiffness``, ``refinement``, ``damping``, ``joint``, ``validation``),
        the timings and the warnings; ``result_.to_dict()`` is the ``cappe.estimate/1`` document.
    estimate_ : ParameterEstimate
        All unknowns with the joint refinement's uncertainty; ``diagnostics`` holds ``gsa``, ``subproblems``,
        ``selection``, ``stiffness_refinement``, ``damping``, ``costs``, ``timings`` (s) and ``validation``
        (:meth:`AutomatedResult.diagnostics`).
    gsa_ : ModelSobolResult
        ``result_.gsa.sobol``.
    subproblems_ : list of SubproblemResult
    selection_ : dict
        ``{name: StiffnessChoice.to_dict()}`` of the selected modal unknowns.
    damping_ : DampingLeastSquares or None
    validation_ : dict
        ``"validation"``: ValidationResult at the held-out position (or None), ``"identification"``: list at the
        identification positions, ``"permuted"``: list of ValidationResult at the held-out (else first) position
        (``result_.validation``).
    timings_ : dict
        Seconds per stage.

    Examples
    --------
    >>> from cappe.modal import ModalEngine
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
        n_permutations: int = 10,
        exact: bool = True,
        noise: Sequence[float] | None = None,
        shapes: str = "real",
        n_workers: int | None = None,
        executor: Executor | str | None = None,
        frf: Sequence[MeasuredFRF] | None = None,
        known_tolerance: Mapping[str, float] | None = None,
        **deprecated: Any,
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
        self.n_permutations = n_permutations
        self.exact = exact
        self.noise = noise
        self.shapes = shapes
        self.n_workers = n_workers
        self.executor = executor
        self.frf = frf
        self.known_tolerance = known_tolerance
        if deprecated:  # the run options that were settings (one release with a warning): defaults of fit
            self._deprecated_run = _deprecated_run_options(deprecated, "AutomatedIdentification(...)")

    # -- checks -------------------------------------------------------------------------------------------------
    def _settings(self, run: _RunOptions) -> AutomatedSettings:
        """The validated settings, with the run's ``truth`` and ``overlay``."""
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
        if self.shapes not in ("real", "complex"):
            msg = f"shapes must be 'real' or 'complex'; got {self.shapes!r}"
            raise DataError(msg)
        w_f, w_z, w_s = (float(v) for v in self.weights)
        return AutomatedSettings(
            n_gsa=int(self.n_gsa), n_opt=int(self.n_opt), threshold=float(self.threshold),
            criteria=tuple(self.criteria), weights=(w_f, w_z, w_s),
            residual_damping_threshold=float(self.residual_damping_threshold), damping_rows=self.damping_rows,
            max_iterations=int(self.max_iterations), refine_starts=int(self.refine_starts), exact=bool(self.exact),
            noise=None if self.noise is None else tuple(self.noise), n_permutations=int(self.n_permutations),
            truth=run.truth, overlay=run.overlay, shapes=self.shapes,
            known_tolerance=None if not self.known_tolerance else dict(self.known_tolerance))

    def _check(self, model: NumericModel, space: ParameterSpace, data: Any) -> tuple[list[int], int | None]:
        """Validated data: (identification set indices, validation set index or None)."""
        name = model.structure.name
        for known, rel in dict(self.known_tolerance or {}).items():
            if known not in model.parameter_names:
                msg = f"known_tolerance: {known!r} is not a parameter of {name}"
                raise DataError(msg)
            if known in space.names:
                msg = f"known_tolerance: {known!r} is an unknown of this identification, not a known parameter"
                raise DataError(msg)
            if isinstance(rel, bool) or not isinstance(rel, (int, float)) or not (np.isfinite(rel) and rel >= 0):
                msg = f"known_tolerance: {known}={rel!r} must be a relative standard deviation >= 0 (0.1: 10 %)"
                raise DataError(msg)
        if self.known_tolerance and not self.exact:
            msg = "known_tolerance needs the exact-mode refinement (exact=True)"
            raise DataError(msg)
        bad = [n for n, lo, hi in zip(space.names, space.lower, space.upper, strict=True)
               if not (np.isfinite(lo) and np.isfinite(hi) and lo > 0)]
        if bad:
            msg = f"unknowns {bad} of model '{name}' need finite bounds 0 < lower < upper for the GSA and searches"
            raise ModelError(msg)
        labels, _ = model.sensor_matrix()
        missing = [s for s in data.sensors if s not in labels]
        if missing and not labels:
            from cappe.modal._reference import no_sensors_message

            shown = f"{missing[:6]}{' ...' if len(missing) > 6 else ''}"
            msg = f"reference sensors {shown}: {no_sensors_message(model.structure)}"
            raise DataError(msg)
        if missing:
            msg = f"reference sensors {missing} are not sensor channels of model '{name}'; its channels: {labels}"
            raise DataError(msg)
        for k, data_set in enumerate(data.sets):
            _check_set(model, f"reference set {k} (position {data_set.position})", data_set)
        held: int | None = None
        if self.validation is not None:
            held = find_set(data, self.validation, model)
        ident = [k for k in range(len(data.sets)) if k != held]
        if not ident:
            msg = "every reference set is held out for validation; at least one position must identify"
            raise DataError(msg)
        return ident, held

    # -- the pipeline -------------------------------------------------------------------------------------------
    def fit(self, data: Any, *, truth: Mapping[str, float] | None = None, overlay: tuple[str, str] | None = None,
            progress: bool | None = None) -> AutomatedIdentification:
        """Identify the unknowns from reference modes; the result is ``self.result_`` (and ``self.estimate_``).

        Parameters
        ----------
        data : ModalData
            Reference modes (``cappe.modal/1``) at one or more axis positions, at the model's sensor channels.
        truth : mapping name -> value, optional
            True parameters (SI) of a simulated reference: the validation step's reference FRFs then come from the
            model at the truth (else by modal synthesis of the reference modes). Does not change the estimate.
        overlay : (str, str), optional
            Output and input channel (reference sensor channels) of the FRF the validation step keeps for the
            report's overlay plot (default: the driving point with the largest peak). It is chosen here, where the
            FRFs are computed: keeping all of them would take ``n_sensors^2 n_freq`` complex numbers per model
            (126 MB for the machine tool's 81 channels).
        progress : bool, optional
            Progress bars (tqdm, stderr) per stage (default: off).

        Returns
        -------
        self

        Raises
        ------
        DataError
            The data are not reference modes that fit the model, or ``overlay`` does not name two of its channels.
        ModelError
            The settings, unknowns, bounds or ``truth`` break a rule of the model or the method.
        """
        given = _RunOptions(truth=truth, overlay=overlay, progress=progress)
        self._run = given.over(getattr(self, "_deprecated_run", None))
        try:
            super().fit(data)
        finally:
            del self._run
        return self

    def set_params(self, **params: Any) -> Self:
        """Change settings for the next fit (see :meth:`Estimator.set_params`); ``truth``, ``overlay`` and
        ``progress`` are accepted until cappe 0.2 with a :class:`DeprecationWarning` (pass them to :meth:`fit`).

        Parameters
        ----------
        **params
            ``name=value`` for any of the ``__init__`` arguments.

        Returns
        -------
        self
        """
        moved = {name: params.pop(name) for name in _RunOptions.names() if name in params}
        if moved:
            earlier = getattr(self, "_deprecated_run", _RunOptions())
            self._deprecated_run = _deprecated_run_options(moved, "set_params(...)").over(earlier)
        return super().set_params(**params)

    def _fit(self, model: NumericModel, space: ParameterSpace, data: Any,
             rng: np.random.Generator) -> Fitted:
        if not isinstance(data, ModalData):
            msg = f"automated identification needs reference ModalData (cappe.modal/1); got {type(data).__name__}"
            raise DataError(msg)
        if not data.sets:
            msg = "reference modal data have no sets; the identification needs modes at one or more positions"
            raise DataError(msg)
        run = self._run
        settings = self._settings(run.checked(model, data))
        ident, held = self._check(model, space, data)
        runner = Executor.coerce(self.executor, self.n_workers)
        # the known parameters' values: the GSA evaluates the model at its nominal vector, so hand it (and the
        # subproblems' engine, whose shared-mass reduction is that of the nominal M) the model with them as nominal
        base_model = model if np.array_equal(space.base, model.nominal) else model.with_nominal(space.base)
        setup = Setup(self.method, model, base_model, space, data, tuple(ident), held, settings, runner,
                      self.n_workers, bool(run.progress), _check_frf(model, data, self.frf))
        try:
            # BLAS on one thread in the calling thread too: the refinements' least squares take an SVD of a Jacobian
            # of about 10 000 x 27 per step, measured 51 ms on two OpenBLAS threads against 6 ms on one (the
            # stiffness refinement 1.9 -> 0.6 s in benchmarks/bench_pipeline.py); the parallelism is over samples
            with single_threaded_blas():
                result = run_pipeline(setup, rng)
        finally:
            if runner is not self.executor:  # made here (e.g. a Dask client from an address): release it
                runner.close()
        self._result = result
        return Fitted(result.estimate, result.joint.cost_function if result.frf is None else result.frf.cost_function)

    # -- learned attributes -------------------------------------------------------------------------------------
    @property
    def result_(self) -> AutomatedResult:
        """Every step's typed result (see :class:`AutomatedResult`)."""
        _ = self.estimate_  # NotFittedError before fit
        try:
            return self._result
        except AttributeError:  # pragma: no cover - estimate_ and _result are set together
            msg = f"{type(self).__name__} is not fitted yet; call fit(data) first"
            raise NotFittedError(msg) from None

    @property
    def gsa_(self) -> Any:
        """The GSA's Sobol' indices (:class:`cappe.sensitivity.ModelSobolResult`)."""
        return self.result_.gsa.sobol

    @property
    def subproblems_(self) -> list[SubproblemResult]:
        return list(self.result_.stiffness.subproblems)

    @property
    def selection_(self) -> dict[str, dict[str, Any]]:
        return {n: c.to_dict() for n, c in self.result_.stiffness.selection.items()}

    @property
    def damping_(self) -> DampingLeastSquares | None:
        return self.result_.damping

    @property
    def validation_(self) -> dict[str, Any]:
        return self.result_.validation.as_mapping()

    @property
    def timings_(self) -> dict[str, float]:
        return dict(self.result_.timings)


def _check_frf(model: NumericModel, data: ModalData, frf: Sequence[MeasuredFRF] | None) -> tuple[MeasuredFRF, ...]:
    """Measured FRFs each at a position of the reference, at most one per position."""
    items = tuple(frf or ())
    seen: dict[int, str] = {}
    for item in items:
        if not isinstance(item, MeasuredFRF):
            msg = f"frf must be a sequence of MeasuredFRF (FRFs with their position); got {type(item).__name__}"
            raise DataError(msg)
        try:
            k = find_set(data, item.position, model)
        except DataError as exc:
            msg = f"{item.where()}: {exc}"
            raise DataError(msg) from exc
        if k in seen:
            msg = f"{item.where()}: position {item.position} already has measured FRFs ({seen[k]})"
            raise DataError(msg)
        seen[k] = item.where()
    return items


@dataclass(frozen=True)
class _RunOptions:
    """What one :meth:`AutomatedIdentification.fit` validates against and shows (not settings of the estimate).

    Attributes
    ----------
    truth : mapping name -> value or None
        True parameters of a simulated reference.
    overlay : (str, str) or None
        Output and input channel of the FRF the validation keeps.
    progress : bool or None
        Progress bars (None: not given).
    """

    truth: Mapping[str, float] | None = None
    overlay: tuple[str, str] | None = None
    progress: bool | None = None

    @staticmethod
    def names() -> tuple[str, ...]:
        return tuple(f.name for f in fields(_RunOptions))

    def over(self, defaults: _RunOptions | None) -> _RunOptions:
        """These options, each one not given (None) taken from ``defaults``."""
        if defaults is None:
            return self
        return _RunOptions(**{n: getattr(defaults, n) if getattr(self, n) is None else getattr(self, n)
                             for n in self.names()})

    def checked(self, model: NumericModel, data: ModalData) -> _RunOptions:
        """The options checked against the model and the reference before the pipeline runs (an unknown truth
        name or overlay channel was found only by the validation step, after the whole identification)."""
        if self.truth is not None:
            model.structure.resolve_parameters(dict(self.truth))  # unknown names and bad values: ModelError
        if self.overlay is not None:
            pair = tuple(self.overlay)
            if len(pair) != 2 or any(c not in data.sensors for c in pair):
                msg = (f"overlay {self.overlay!r} must be (output, input): two reference sensor channels, e.g. "
                       f"{tuple(data.sensors[:2])}")
                raise DataError(msg)
        return self


def _deprecated_run_options(given: Mapping[str, Any], where: str) -> _RunOptions:
    """The run options given as settings (deprecated), with one warning naming them; others are a TypeError."""
    unknown = sorted(set(given) - set(_RunOptions.names()))
    if unknown:
        msg = f"AutomatedIdentification got unexpected keyword argument(s) {unknown}"
        raise TypeError(msg)
    named = ", ".join(f"{n}=" for n in given)
    warnings.warn(f"{where} with {named} is deprecated and stops working in cappe 0.2: pass "
                  f"{named.replace('=', '=...')} to fit(reference, ...) instead", DeprecationWarning, stacklevel=3)
    return _RunOptions(**given)


def _check_set(model: NumericModel, where: str, data_set: ModalDataSet) -> None:
    """A reference set fits the model: its axes, mode count, frequencies, damping ratios and shapes."""
    name = model.structure.name
    unknown_axes = sorted(set(data_set.position) - set(model.axis_names))
    if unknown_axes:
        msg = f"{where}: axes {unknown_axes} are not axes of model '{name}' (its axes: {list(model.axis_names)})"
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
    check_finite_modes(where, data_set)
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
