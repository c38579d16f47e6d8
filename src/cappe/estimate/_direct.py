"""The "direct" method (thesis 2.2, 3.6.1): the equations of motion as a regression on measured motion and forces.

With the displacements ``q``, velocities ``q'`` and accelerations ``q''`` of every degree of freedom and the forces
``u`` measured, the equations of motion ``M q'' + (C + G) q' + K q = B u`` hold at every sample and are linear in
the matrices. cappe models are affine in their coefficients (``K = K0 + sum_j p_j dK/dp_j``, DESIGN §3), so for
unknowns that enter linearly the equations stack into one linear least-squares problem::

    sum_j p_j (dM_j q'' + dD_j q' + dK_j q) = B u - (M0 q'' + D0 q' + K0 q)       (one row per DOF and sample)

where ``D = C + G`` and ``M0, D0, K0`` hold the known parameters' share. Unknowns that enter non-linearly (e.g. a
bearing stiffness ``k0 * preload**(1/3)``) are found by Gauss-Newton on the same equation errors
(a bounded trust-region search with the exact Jacobian from :meth:`NumericModel.matrix_derivatives`).

**Weighting.** The equations of different DOFs carry different forces and noise: a first solve weights each DOF's
rows by the inverse RMS of its forces at the start values, the final solve by the inverse RMS of its residuals
(feasible generalized least squares).

**Instrumental variables.** Noise in the measured motion sits inside the regressors, so plain least squares is
biased (errors in variables; with 1 % noise on lightly damped structures, about 1 % low on masses and stiffnesses,
because inertia and stiffness forces nearly cancel near resonance and the noise does not). Instruments are
regressors correlated with the true motion but not with the noise; the estimate is the two-stage least-squares
solution ``(A^T P A)^-1 A^T P b`` with ``P`` the projection on the instruments:

* ``instruments="model"`` (the default): the regressors rebuilt from the model's noise-free simulated response to
  the measured forces at the previous estimate (zero-order hold, start at rest), iterated ``n_iter`` times from the
  least-squares estimate (the bootstrap IV of Young / Fritzen, thesis Fig. 2.4). Works for any excitation.
  For unknowns that enter non-linearly the instruments are the Jacobian of the equation errors on that simulated
  response, and each iteration solves the instrumental-variable equations by Gauss-Newton steps from the
  Gauss-Newton estimate (an unknown they put outside its bounds is held at the bound).
* ``instruments="delayed"`` (linear unknowns only): the measured regressors ``delay`` samples earlier. Cheap,
  consistent for white measurement noise, but only as good as the correlation of the signals over the delay: with
  excitation up to the Nyquist frequency the accelerations are nearly white and the instruments are weak (large
  errors).

**The fit's verdict.** Where the equations of motion hold at the samples, the equation errors of a consistent
estimate are the measurement noise, independent of the forces; where they do not (a delay between the force and the
response channels, a wrong known parameter, the error of a derived quantity), they follow the forces. Their
cross-correlation with the forces is tested as one-step's output errors are (MATLAB ``resid``,
:func:`cappe.estimate._base.with_residual_tests`): a failed test makes the fit FAILED (``success`` False, exit
status 1), one WARNING line per failed pair. The errors tested are the model-instrument ones: with
``instruments="model"``, those of the estimate reported; with plain least squares, whose own errors correlate with
the forces through the errors-in-variables bias on every noisy record, and with the (weak) delayed instruments,
those of the model-instrument estimate, iterated from least squares (``diagnostics["residuals_tested"]``).
Unknowns that enter non-linearly are tested on the errors of the model-instrument estimate iterated from the
Gauss-Newton one (the Jacobian of the equation errors on the simulated response as instruments). Plain least
squares (linear unknowns) and Gauss-Newton are compared with that model-instrument estimate: where an unknown differs
by more than the Bonferroni normal quantile at 1 % of its standard errors, a warning says that the noise biases the
estimate beyond its intervals (``diagnostics["noise_bias"]``). The verdict is that
of the estimate reported: unknowns held at a bound keep their bound values in the tested solution (a bound that
excludes the truth fails the fit), have no interval and are practically non-identifiable.
Noise on the force channel enters the equation errors and the tested force alike, at lag 0 only and far below the
bound: with 1, 5 and 10 % white force noise (and 1 % on the motion, model instruments) 1 of the same 10 ``lsim``
records failed at each level, as without it.

**Missing quantities.** The method needs all three quantities of every DOF. Channels are matched to the model's
outputs by name and mapped to DOFs through their output rows ``S`` (least squares when sensors are redundant).
Missing quantities raise :class:`DataError` naming the channels to add, unless ``derive_missing=True``: then a
missing quantity is differentiated from the next lower one (4th-order central differences; the two samples at each
end are dropped) or integrated from the next higher one (cumulative Simpson rule, then a straight line is removed
by least squares because the initial displacement / velocity and sensor offsets are unknown). Differentiation
assumes smooth signals: under zero-order-hold (stepped) forces the acceleration jumps at every sample and a
difference quotient of the velocity misses it by about ``omega dt`` of the force change. Derived channels have
correlated errors, so their standard errors are optimistic.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import scipy.linalg as sla
from numpy.typing import NDArray
from scipy import signal
from scipy.integrate import cumulative_simpson
from scipy.optimize import least_squares, lsq_linear

from cappe._rng import RandomLike
from cappe.estimate._base import Estimator, honest_intervals, with_residual_tests
from cappe.estimate._one_step import channel_names
from cappe.estimate._result import ParameterEstimate
from cappe.estimate._space import ParameterSpace
from cappe.estimate._uncertainty import (
    LocalUncertainty,
    correlated_uncertainty,
    jacobian_uncertainty,
    newey_west_bandwidth,
)
from cappe.exceptions import ConvergenceWarning, DataError, DataWarning, ModelError
from cappe.model import NumericModel, Structure
from cappe.systems.mechanical import DERIVATIVE_ORDER
from cappe.systems.statespace import StateSpaceModel
from cappe.systems.timedata import TimeData

__all__ = ["DirectEstimator"]

Array = NDArray[np.float64]

_QUANTITY = {0: "displacement", 1: "velocity", 2: "acceleration"}
_INSTRUMENTS = (None, "delayed", "model")
#: Relative agreement of the matrix derivatives at two parameter vectors below which the unknowns enter linearly.
_AFFINE_RTOL = 1e-9


class DirectEstimator(Estimator):
    """Physical parameters from measured forces, displacements, velocities and accelerations (thesis 3.6.1).

    Parameters
    ----------
    model, unknowns, bounds, start, values, rng
        As for :class:`Estimator`. Bounds constrain the estimate: where the least-squares solution of linear
        unknowns lies outside them, the estimate is the optimum within them (bounded-variable least squares), its
        unknowns at a bound are flagged without an interval and the unbounded values are said in a warning; they
        bound the Gauss-Newton search of non-linear unknowns.
    inputs : sequence of str or str, optional
        Model inputs that act during the measurement; each needs a force channel of that name (a text is one name
        or several separated by commas). Default: every model input. Inputs left out are taken as zero.
    position : mapping, optional
        Axis positions of the model (default: the model's nominal ones).
    instruments : {"model", "delayed", None}
        Instrumental variables against the noise bias (see the module notes). ``"model"`` (default): consistent
        with noise on every measured quantity. None (or ``"none"``) for plain least squares (or Gauss-Newton), which
        the noise in the measured motion biases by many standard errors on noisy records (a warning says by how
        much); right for noise-free data only. ``"delayed"`` needs unknowns that enter the equations linearly.
    delay : int
        Delay in samples of the ``"delayed"`` instruments.
    n_iter : int
        Iterations of the ``"model"`` instruments.
    derive_missing : bool
        Derive missing quantities by differentiation or integration instead of raising :class:`DataError`.
    covariance : {"auto", "gauss-newton", "sandwich"}
        Linear unknowns: ``"gauss-newton"``, ``s^2 (J^T J)^-1`` of the weighted equation errors (right for white
        errors); ``"sandwich"``, the Newey-West covariance of errors correlated in time (one-step's); ``"auto"``
        (default): the sandwich where an equation error fails the whiteness test (a warning says so).

    Attributes
    ----------
    estimate_ : ParameterEstimate
        The result; ``diagnostics`` holds the channels used per quantity, derived quantities, the weights, the
        instrument iterations and whether the unknowns entered linearly.

    Examples
    --------
    >>> from cappe.model import load_model
    >>> from cappe.systems import time_response
    >>> from cappe.identify import random_noise
    >>> nm = NumericModel(load_model("builtin:two-mass-rig"))
    >>> f1, f2 = (random_noise(fs=2000.0, duration=0.2, rms=5.0, rng=k, name=n) for k, n in ((1, "F1"), (2, "F2")))
    >>> force = TimeData(f1.time, np.vstack([f1.values, f2.values]), ("F1", "F2"))
    >>> data = time_response(nm.system(), force)           # noise-free d, v, a of both masses
    >>> est = DirectEstimator(nm, ["m1", "k11", "c11"]).fit(data)
    >>> {k: round(v, 6) for k, v in est.params_.items()}
    {'m1': 1.39, 'k11': 1380000.0, 'c11': 13.42}
    """

    method = "direct"

    def __init__(
        self,
        model: NumericModel | Structure,
        unknowns: Sequence[str] | None = None,
        *,
        bounds: Mapping[str, Sequence[float]] | None = None,
        start: Mapping[str, float] | None = None,
        values: Mapping[str, float] | None = None,
        rng: RandomLike = None,
        inputs: Sequence[str] | str | None = None,
        position: Mapping[str, float] | None = None,
        instruments: str | None = "model",
        delay: int = 1,
        n_iter: int = 3,
        derive_missing: bool = False,
        covariance: str = "auto",
    ) -> None:
        super().__init__(model, unknowns, bounds=bounds, start=start, values=values, rng=rng)
        self.inputs = inputs
        self.position = position
        self.instruments = None if isinstance(instruments, str) and instruments.lower() == "none" else instruments
        self.delay = delay
        self.n_iter = n_iter
        self.derive_missing = derive_missing
        self.covariance = covariance

    # ------------------------------------------------------------------------------------------------------------
    def _check_settings(self) -> None:
        if self.covariance not in ("auto", "gauss-newton", "sandwich"):
            msg = f"covariance must be 'auto', 'gauss-newton' or 'sandwich'; got {self.covariance!r}"
            raise DataError(msg)
        if self.instruments not in _INSTRUMENTS:
            msg = f"instruments must be None, 'model' or 'delayed'; got {self.instruments!r}"
            raise DataError(msg)
        for name, value in (("delay", self.delay), ("n_iter", self.n_iter)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                msg = f"{name} must be an integer >= 1; got {value!r}"
                raise DataError(msg)

    def _fit(
        self, model: NumericModel, space: ParameterSpace, data: Any, rng: np.random.Generator
    ) -> ParameterEstimate:
        self._check_settings()
        if not isinstance(data, TimeData):
            msg = f"the direct method needs TimeData with force and motion channels; got {type(data).__name__}"
            raise DataError(msg)
        p0 = space.full(space.start)
        system = model.system(p0, self.position)
        if np.any(system.H):
            msg = (
                f"model '{system.name}' has hysteretic damping (H != 0), which has no time-domain form; the direct "
                f"method needs viscous damping (use a frequency-domain method)"
            )
            raise ModelError(msg)
        forces, used_inputs = _forces(system, data, self.inputs)
        motion, valid, info = _motion(system, data, derive_missing=self.derive_missing)
        equations = _Equations(model, space, self.position, motion, forces, used_inputs, valid)
        diagnostics: dict[str, Any] = {
            "inputs": list(used_inputs),
            "channels": info["channels"],
            "derived": info["derived"],
            "samples": int(valid.sum()),
            "linear": equations.linear,
            "instruments": self.instruments,
        }
        if equations.linear:
            return self._fit_linear(space, equations, data, diagnostics)
        if self.instruments == "delayed":
            msg = (
                f"instruments='delayed' need unknowns that enter the equations linearly; {list(space.names)} do not "
                f"(use instruments='model' or None)"
            )
            raise DataError(msg)
        return self._fit_nonlinear(space, equations, data, diagnostics)

    # -- linear unknowns -------------------------------------------------------------------------------------------
    def _fit_linear(
        self, space: ParameterSpace, eq: _Equations, data: TimeData, diagnostics: dict[str, Any]
    ) -> ParameterEstimate:
        a, b = eq.regression(eq.motion)  # (n_dof, n_s, n_u), (n_dof, n_s)
        weights = 1.0 / eq.force_scale(a, b, space.start)
        theta = _weighted_lstsq(a, b, weights, space.start)
        weights = _residual_weights(a, b, theta, weights)
        theta = _weighted_lstsq(a, b, weights, space.start)
        jac = (a * weights[:, None, None]).reshape(-1, space.n)
        history: list[dict[str, float]] = [space.mapping(theta)]
        ls_fit = (theta, weights)
        every_sample = (a, b)  # the delayed instruments drop the first samples; the tested errors take them all
        if self.instruments == "delayed":
            delay = int(self.delay)
            if delay >= b.shape[1] - space.n:
                msg = f"delay = {delay} samples leaves too few of the {b.shape[1]} samples for the instruments"
                raise DataError(msg)
            inst = eq.regression(eq.delayed(delay))[0][:, delay:]
            a, b = a[:, delay:], b[:, delay:]
            for k in range(2):  # the second pass re-weights the DOFs by their IV residuals
                if k:
                    weights = _residual_weights(a, b, theta, weights)
                theta, jac = _iv_solve(a, b, inst, weights, space.start)
                history.append(space.mapping(theta))
        elif self.instruments == "model":
            theta, iv_jac, weights, stopped = self._model_instruments(space, eq, data, a, b, theta, weights, history)
            jac = jac if iv_jac is None else iv_jac
            if stopped is not None:
                warnings.warn(
                    f"model instruments stopped: the model cannot be simulated at {space.mapping(theta)} "
                    f"({stopped}); the last estimate is kept",
                    ConvergenceWarning,
                    stacklevel=4,
                )
        message = "linear least squares" if self.instruments is None else f"instrumental variables ({self.instruments})"
        outside = [
            n for n, v, lo, hi in zip(space.names, theta, space.lower, space.upper, strict=True) if not lo <= v <= hi
        ]
        at_bound: list[str] = []
        if outside and np.all(np.isfinite(theta)):
            free = theta
            theta = _bounded(jac, theta, space.lower, space.upper)
            if self.instruments is None:  # weight the DOFs by their residuals at the bounded optimum, as above
                weights = _residual_weights(a, b, theta, weights)
                jac = (a * weights[:, None, None]).reshape(-1, space.n)
                theta = _bounded(jac, _weighted_lstsq(a, b, weights, space.start), space.lower, space.upper)
            at_bound = [n for n, v, lo, hi in zip(space.names, theta, space.lower, space.upper, strict=True)
                        if v <= lo or v >= hi]
            said = ", ".join(f"{n} at {free[space.names.index(n)]:.6g} (bounds [{space.lower[space.names.index(n)]:g}"
                             f", {space.upper[space.names.index(n)]:g}])" for n in outside)
            line = (f"the data alone put {said}: the estimate is the least-squares optimum within the bounds, "
                    f"at a bound for {at_bound}; widen the bounds if they exclude the truth")
            diagnostics["outside_bounds"] = outside
            diagnostics["unbounded"] = {n: float(free[space.names.index(n)]) for n in outside}
            diagnostics["at_bound"] = at_bound
            diagnostics["warnings"] = [*diagnostics.get("warnings", []), line]
            message += f"; estimate at a bound for {at_bound}"
            warnings.warn(f"direct estimate outside the bounds for {outside}; {line}", DataWarning, stacklevel=4)
        # the verdict is that of the estimate reported: with the unknowns a bound holds kept there
        held = np.isin(np.array(space.names), at_bound)
        start = (theta, weights) if self.instruments == "model" else (np.where(held, theta, ls_fit[0]), ls_fit[1])
        tested, tested_weights, diagnostics["residuals_tested"], iv = self._tested_errors(
            space, eq, data, *every_sample, start, held)
        if self.instruments is None and iv is not None and tested is not None:
            _noise_bias(space.names, theta, *iv, tested, held, diagnostics, "least-squares")
        errors = (b - a @ theta) * weights[:, None]  # (n_dof, n_s): weighted equation errors
        residuals = errors.ravel()
        unc = jacobian_uncertainty(names=space.names, values=theta, jacobian=jac, residuals=residuals)
        raw = b - a @ theta  # unweighted (N): an exact fit leaves round-off of the forces' size times 1e-16
        exact = bool(np.sqrt(np.mean(raw**2)) <= 1e-8 * np.sqrt(np.mean(b**2)))
        unc = self._covariance(unc, eq, jac, errors, diagnostics, exact=exact)
        if at_bound:  # an estimate held by its bound has no Gauss-Newton interval
            unc = _held_without_interval(unc, at_bound)
            diagnostics["practically_non_identifiable"] = dict.fromkeys(at_bound, "at a bound")
        diagnostics["weights"] = dict(zip(eq.dofs, (float(w) for w in weights), strict=True))
        diagnostics["iterations"] = len(history)
        if len(history) > 1:
            diagnostics["history"] = history
        success = bool(np.all(np.isfinite(theta)))
        if not success:
            message += "; the solution is not finite"
        estimate = ParameterEstimate.from_uncertainty(
            self.method, unc, cost=float(residuals @ residuals), success=success, message=message,
            diagnostics=diagnostics,
        )
        return _with_verdict(estimate, eq, tested, tested_weights, float(np.sqrt(np.mean(b**2))))

    def _model_instruments(self, space: ParameterSpace, eq: _Equations, data: TimeData, a: Array | None,
                           b: Array | None, theta: Array, weights: Array, history: list[dict[str, float]] | None = None,
                           held: NDArray[np.bool_] | None = None
                           ) -> tuple[Array, Array | None, Array, Exception | None]:
        """``n_iter`` model-instrument iterations from ``theta``: the instruments are the regressors of the model's
        response simulated at the last estimate, the DOFs re-weighted by their residuals before each solve.

        Unknowns that enter linearly solve the regression ``a``, ``b`` of every sample. For unknowns that enter
        non-linearly (``a``, ``b`` None) the instruments are the Jacobian of the equation errors on the simulated
        response, ``Z``, and each iteration solves ``Z^T W e(theta) = 0`` by Gauss-Newton steps from ``theta``
        (:meth:`_nonlinear_iv`). Unknowns flagged in ``held`` keep their values (an estimate held by its bound).

        Returns the estimate, the last solve's Jacobian (None if none ran), the weights, and the error that stopped
        the iterations where the model could not be simulated (None when all ran). Each estimate is appended to
        ``history`` when given.
        """
        jac = None
        held = np.zeros(space.n, dtype=bool) if held is None else held
        for _ in range(int(self.n_iter)):
            try:
                simulated = eq.simulate(theta, data.time)
            except (ModelError, np.linalg.LinAlgError, ValueError) as exc:
                return theta, jac, weights, exc
            if a is None or b is None:
                theta, jac, weights, stopped = _nonlinear_iv(space, eq, simulated, theta, weights, held)
                if stopped is not None:
                    return theta, jac, weights, stopped
            else:
                weights = _residual_weights(a, b, theta, weights)
                theta, jac = _held_iv_solve(a, b, eq.regression(simulated)[0], weights, space.start, theta, held)
            if history is not None:
                history.append(space.mapping(theta))
        return theta, jac, weights, None

    def _tested_errors(self, space: ParameterSpace, eq: _Equations, data: TimeData, a: Array | None,
                       b: Array | None, fit: tuple[Array, Array], held: NDArray[np.bool_]
                       ) -> tuple[Array | None, Array, str, tuple[Array, Array] | None]:
        """The weighted equation errors (n_dof, n_s) whose correlation with the forces tests the equations, their
        DOF weights, what they are (``diagnostics["residuals_tested"]``) and, where this ran the model-instrument
        iterations, their estimate and its Jacobian ``P A`` (else None).

        Noise on the measured motion sits in the regressors: the least-squares estimate is biased (errors in
        variables) and its equation errors correlate with the forces through that bias on every noisy record, so
        they cannot test whether the equations hold. The model-instrument estimate is consistent and its
        instruments are strong: its equation errors are the noise (independent of the forces) where the equations of
        motion hold at the samples, and follow the forces where they do not (a delay between the force and the
        response channels, a wrong known parameter). The delayed instruments are consistent but weak: their
        estimate's error enters the equation errors through the regressors, which correlate with the forces at lag 0
        (13 of 20 ``lsim`` records at 5 % noise whose equations hold failed on them). So the errors tested are those
        of the model-instrument estimate: the one reported (``fit``) with ``instruments="model"``, else ``n_iter``
        iterations from the least-squares (linear unknowns) or Gauss-Newton (non-linear unknowns) ``fit``, as
        ``instruments="model"`` runs them. Unknowns flagged in ``held`` (the reported estimate's, held by a bound)
        keep their values: the verdict is that of the model within the bounds. ``a``, ``b``: the regression of every
        sample (linear unknowns; None for non-linear ones). None where the model cannot be simulated there.
        """
        theta, weights = fit
        names = [n for n, h in zip(space.names, held, strict=True) if h]
        kept = f"; {names} held at their bounds" if names else ""
        if a is not None and b is not None and self.instruments == "model":
            return (np.asarray((b - a @ theta) * weights[:, None], dtype=float), weights,
                    f"the equation errors of the estimate (instrumental variables, model{kept})", None)
        iv_jac = None
        try:
            theta, iv_jac, weights, stopped = self._model_instruments(space, eq, data, a, b, theta, weights,
                                                                      held=held)
        except (np.linalg.LinAlgError, ValueError) as exc:
            stopped = exc
        if stopped is not None:
            return None, weights, (f"none: the model-instrument iterations stopped at {space.mapping(theta)} "
                                   f"({stopped})"), None
        if not np.all(np.isfinite(theta)) or iv_jac is None:
            return None, weights, "none: the model-instrument solution is not finite", None
        names = [n for n, h in zip(space.names, held, strict=True) if h]  # with those the iterations held
        kept = f"; {names} held at their bounds" if names else ""
        if a is None or b is None:
            errors = -eq.residuals(theta)
            what, source = "Gauss-Newton", "Gauss-Newton (least-squares) estimate"
        else:
            errors = b - a @ theta
            what = "least-squares" if self.instruments is None else "delayed-instrument"
            source = "least squares"
        return (np.asarray(errors * weights[:, None], dtype=float), weights,
                f"the equation errors of the model-instrument estimate ({self.n_iter} iterations from {source}"
                f"{kept}; the {what} estimate's own errors correlate with the forces through "
                f"{'its larger error' if self.instruments == 'delayed' else 'the noise bias'})", (theta, iv_jac))

    def _covariance(self, unc: LocalUncertainty, eq: _Equations, jac: Array, errors: Array,
                    diagnostics: dict[str, Any], *, exact: bool) -> LocalUncertainty:
        """``unc``, or its Newey-West sandwich where the equation errors are coloured (``covariance``).

        The equation errors of each DOF are tested for whiteness (:func:`residual_analysis`); their independence of
        the forces is the fit's verdict, tested on the errors :meth:`_tested_errors` picks. Where one
        is not white and ``covariance="auto"``, or with ``covariance="sandwich"``, the covariance is the one-step's
        sandwich (:func:`correlated_uncertainty`, bandwidth :func:`newey_west_bandwidth`) over the time steps, all
        DOFs of a step in one block; for instruments the Jacobian is the projected regressors ``P A``.
        """
        from cappe.identify._residual_analysis import residual_analysis

        n_dof, n_s = errors.shape
        forces = eq.forces[:, eq.forces.shape[1] - n_s:]  # the delayed instruments drop the first samples
        if exact and self.covariance != "sandwich":
            return unc  # an exact fit (noise-free data): round-off is not tested
        tests = residual_analysis(residuals=errors.T, inputs=forces.T, output_names=list(eq.dofs),
                                  input_names=[eq.model.input_names[c] for c in eq.columns])
        analysis = tests.to_dict()
        coloured = [d for d, white in analysis["white"].items() if not white]
        diagnostics["equation_errors_white"] = analysis["white"]
        if not (self.covariance == "sandwich" or (self.covariance == "auto" and coloured)):
            return unc
        lag = newey_west_bandwidth([n_s], analysis)
        jac_t = jac.reshape(n_dof, n_s, -1).transpose(1, 0, 2).reshape(n_dof * n_s, -1)
        hac = correlated_uncertainty(unc, jacobian=jac_t, residuals=errors.T.ravel(), block=n_dof, records=[n_s],
                                     max_lag=lag)
        diagnostics["covariance"] = {"kind": "sandwich (Newey-West)", "lags": lag,
                                     "gauss_newton_std": dict(zip(unc.names, unc.std.tolist(), strict=True))}
        return hac

    # -- non-linear unknowns ---------------------------------------------------------------------------------------
    def _fit_nonlinear(self, space: ParameterSpace, eq: _Equations, data: TimeData,
                       diagnostics: dict[str, Any]) -> ParameterEstimate:
        """Gauss-Newton (bounded trust-region) on the weighted equation errors, in the space's internal coordinates.

        The first pass weights each DOF by the RMS of its equation error at the start, the second by that at the
        first estimate, continuing from it. With ``instruments="model"`` the estimate is the model-instrument one
        iterated from there (:meth:`_model_instruments`); an unknown it puts outside its bounds is held at the bound.
        The intervals are those of the search's coordinates (:func:`honest_intervals`); an unknown held by its bound
        has none and is practically non-identifiable. The verdict tests the equation errors of the model-instrument
        estimate (:meth:`_tested_errors`): the Gauss-Newton estimate's own errors correlate with the forces through
        the noise bias.
        """
        lo, hi = space.internal_bounds()
        first = 1.0 / eq.scale_from_residual(eq.residuals(space.start))
        u = np.clip(space.to_internal(space.start), lo, hi)
        weights = first
        sol: Any = None
        for k in range(2):
            if k:
                weights = 1.0 / eq.scale_from_residual(eq.residuals(space.from_internal(sol.x)), floor=1.0 / first)
            fun = _flat(eq.residuals, weights)
            jac = _flat_jac(eq.jacobian, weights)
            sol = least_squares(
                lambda x, f=fun: f(space.from_internal(x)),
                sol.x if sol is not None else u,
                jac=lambda x, j=jac: j(space.from_internal(x)) * space.value_jacobian(x),
                bounds=(lo, hi),
                x_scale="jac",
                method="trf",
            )
        theta = space.from_internal(sol.x)
        held = np.array([np.isclose(x, a) or np.isclose(x, b) for a, b, x in zip(lo, hi, sol.x, strict=True)],
                        dtype=bool)
        message = f"Gauss-Newton on the equation errors: {sol.message}"
        diagnostics = {**diagnostics, "iterations": int(sol.nfev), "start": space.mapping(space.start)}
        if self.instruments == "model":
            # from the Gauss-Newton estimate, all unknowns free: its bias may have put one at a bound
            theta, weights, held, iv_jac = self._nonlinear_model_instruments(
                space, eq, data, theta, weights, np.zeros(space.n, dtype=bool), diagnostics)
            errors = -eq.residuals(theta) * weights[:, None]
            unc = jacobian_uncertainty(names=space.names, values=theta, jacobian=iv_jac, residuals=errors.ravel())
            message = f"instrumental variables (model) from the {message}"
        else:
            errors = -eq.residuals(theta) * weights[:, None]
            unc = jacobian_uncertainty(names=space.names, values=theta, jacobian=_flat_jac(eq.jacobian, weights)(theta),
                                       residuals=errors.ravel())
        at_bound = [n for n, h in zip(space.names, held, strict=True) if h]
        unc, practical = honest_intervals(space, unc, at_bound)
        unc = _held_without_interval(unc, at_bound)
        if at_bound:
            message += f"; estimate at a bound for {at_bound}"
        diagnostics["weights"] = dict(zip(eq.dofs, weights.tolist(), strict=True))
        diagnostics["at_bound"] = at_bound
        if practical:
            diagnostics["practically_non_identifiable"] = practical
        if at_bound:
            said = ", ".join(f"{n} at {theta[j]:.6g} (bounds [{space.lower[j]:g}, {space.upper[j]:g}])"
                             for j, n in enumerate(space.names) if n in at_bound)
            diagnostics["warnings"] = [*diagnostics.get("warnings", []),
                                       f"the {'estimate' if self.instruments else 'Gauss-Newton search'} stopped at "
                                       f"a bound: {said}; such an estimate has no interval and the verdict is that "
                                       f"of the model with it there; widen the bounds if they exclude the truth"]
        if self.instruments == "model":
            tested: Array | None = errors
            tested_weights = weights
            diagnostics["residuals_tested"] = "the equation errors of the estimate (instrumental variables, model" + (
                f"; {at_bound} held at their bounds)" if at_bound else ")")
        else:
            tested, tested_weights, diagnostics["residuals_tested"], iv = self._tested_errors(
                space, eq, data, None, None, (theta, weights), held.copy())
            if iv is not None and tested is not None:
                _noise_bias(space.names, theta, *iv, tested, held, diagnostics, "Gauss-Newton")
        estimate = ParameterEstimate.from_uncertainty(
            self.method, unc, cost=float(np.sum(errors**2)), success=bool(sol.success) and sol.status > 0,
            message=message, diagnostics=diagnostics,
        )
        return _with_verdict(estimate, eq, tested, tested_weights, eq.term_scale(theta))

    def _nonlinear_model_instruments(self, space: ParameterSpace, eq: _Equations, data: TimeData, theta: Array,
                                     weights: Array, held: NDArray[np.bool_], diagnostics: dict[str, Any]
                                     ) -> tuple[Array, Array, NDArray[np.bool_], Array]:
        """The model-instrument estimate of non-linear unknowns from the Gauss-Newton ``theta``: its values, DOF
        weights, the unknowns held at a bound (those in ``held`` and those the iterations put outside their bounds)
        and its Jacobian ``P A`` (SI)."""
        held = held.copy()
        history = [space.mapping(theta)]
        new, jac, new_weights, stopped = self._model_instruments(space, eq, data, None, None, theta, weights, history,
                                                                 held)
        diagnostics["history"] = history
        if stopped is not None or jac is None:
            warnings.warn(f"model instruments stopped at {space.mapping(new)} ({stopped}); the Gauss-Newton estimate "
                          f"is kept", ConvergenceWarning, stacklevel=5)
            return theta, weights, held, _flat_jac(eq.jacobian, weights)(theta)
        return new, new_weights, held, jac


#: Level of the noise-bias check of least-squares estimates (Bonferroni over the unknowns, as the residual tests').
_BIAS_LEVEL = 0.01


def _noise_bias(names: Sequence[str], values: Array, iv_values: Array, iv_jac: Array, iv_errors: Array,
                held: NDArray[np.bool_], diagnostics: dict[str, Any], what: str) -> None:
    """Compare a least-squares estimate with the model-instrument one its verdict computed; warn where they differ.

    Noise in the measured motion biases least squares (errors in variables) by far more than its standard errors
    on lightly damped structures (seen: 6-13 standard errors with 1 % noise and both forces, up to 59 with one); its
    intervals do not include the bias. The model-instrument estimate is consistent: where an unknown differs from
    it by more than the two-sided normal quantile at :data:`_BIAS_LEVEL` (Bonferroni over the unknowns) of the
    model-instrument standard error (from its Jacobian ``P A`` and equation errors; unknowns held by a bound are
    not compared), a warning says so. ``diagnostics["noise_bias"]`` holds the differences in those standard errors.
    """
    from scipy import stats

    if not (np.all(np.isfinite(iv_jac)) and np.all(np.isfinite(iv_errors))):
        return
    unc = jacobian_uncertainty(names=names, values=iv_values, jacobian=iv_jac, residuals=iv_errors.ravel())
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (values - iv_values) / unc.std
    compared = ~held & np.isfinite(z)
    if not compared.any():
        return
    critical = float(stats.norm.ppf(1.0 - _BIAS_LEVEL / (2 * int(compared.sum()))))
    diagnostics["noise_bias"] = {
        "standard_errors": {n: float(v) for n, v, c in zip(names, z, compared, strict=True) if c},
        "model_instruments": dict(zip(names, (float(v) for v in iv_values), strict=True)),
        "critical": critical,
    }
    biased = [k for k in np.argsort(-np.abs(np.where(compared, z, 0.0))) if compared[k] and abs(z[k]) > critical]
    if not biased:
        return
    said = ", ".join(f"{names[k]} {values[k]:.6g} against {iv_values[k]:.6g} ({z[k]:+.3g})" for k in biased[:4])
    diagnostics["warnings"] = [
        *diagnostics.get("warnings", []),
        f"the {what} estimate differs from the model-instrument estimate by more than {critical:.3g} of its standard "
        f"errors for {[names[k] for k in biased]} ({said}{', ...' if len(biased) > 4 else ''}): the noise in the "
        f"measured motion biases least squares (errors in variables) and its intervals do not include that bias; "
        f"use instruments=model",
    ]


def _with_verdict(estimate: ParameterEstimate, eq: _Equations, tested: Array | None, weights: Array,
                  scale: float) -> ParameterEstimate:
    """``estimate`` with the force-independence test of the equation errors ``tested`` (n_dof, n_s; DOF
    ``weights``) as its verdict (:func:`with_residual_tests`); a warning line where none could be tested. Errors
    whose RMS is below 1e-8 of ``scale`` (N: the size of the equations' terms) are an exact fit, not tested."""
    if tested is None:
        line = f"the equations of motion were not tested against the forces: {estimate.diagnostics['residuals_tested']}"
        return replace(estimate, diagnostics={**estimate.diagnostics,
                                              "warnings": [*estimate.diagnostics.get("warnings", []), line]})
    tested_rms = np.sqrt(np.mean((tested / weights[:, None]) ** 2))
    if tested_rms <= 1e-8 * scale:
        return estimate  # the tested solution fits exactly (noise-free data): round-off is not tested
    return with_residual_tests(estimate, [tested.T], [eq.forces[:, eq.forces.shape[1] - tested.shape[1]:].T],
                               list(eq.dofs), [eq.model.input_names[c] for c in eq.columns])


def _held_without_interval(unc: LocalUncertainty, at_bound: Sequence[str]) -> LocalUncertainty:
    """``unc`` without intervals for the unknowns held by a bound, which are not identifiable."""
    held = np.isin(np.array(unc.names), list(at_bound))
    if not held.any():
        return unc
    ci = unc.ci95.copy()
    ci[held] = np.nan
    return replace(unc, ci95=ci, identifiable=unc.identifiable & ~held)


# ---------------------------------------------------------------------------------------------------------------
# data


def _forces(system: Any, data: TimeData, inputs: Sequence[str] | str | None) -> tuple[Array, tuple[str, ...]]:
    """Force channels (n_inputs_used, n_samples) of the acting model inputs."""
    names = tuple(system.input_names) if inputs is None else tuple(channel_names(inputs))
    unknown = [n for n in names if n not in system.input_names]
    if unknown:
        msg = f"inputs {unknown} are not inputs of model '{system.name}'; its inputs are {list(system.input_names)}"
        raise DataError(msg)
    missing = [n for n in names if n not in data.channels]
    if missing:
        msg = (
            f"data lack the force channel(s) {missing} of model input(s) {missing}; channels present: "
            f"{list(data.channels)} (pass inputs=[...] to name only the inputs that act)"
        )
        raise DataError(msg)
    return np.array([data.channel(n) for n in names], dtype=float), names


def _motion(system: Any, data: TimeData, *, derive_missing: bool) -> tuple[Array, NDArray[np.bool_], dict[str, Any]]:
    """Displacement, velocity and acceleration of every DOF (3, n_dof, n_samples) from the output channels."""
    n = system.n_dof
    dofs = list(system.dofs)
    present: dict[int, list[int]] = {0: [], 1: [], 2: []}
    for k, (name, quantity) in enumerate(zip(system.output_names, system.output_quantities, strict=True)):
        order = DERIVATIVE_ORDER.get(quantity)
        if order is not None and name in data.channels:
            present[order].append(k)
    out = np.zeros((3, n, data.n_samples))
    have: dict[int, bool] = {}
    channels: dict[str, list[str]] = {}
    problems: list[str] = []
    for order in (0, 1, 2):
        rows = system.S[present[order]] if present[order] else np.zeros((0, n))
        names = [system.output_names[k] for k in present[order]]
        channels[_QUANTITY[order]] = names
        rank = int(np.linalg.matrix_rank(rows)) if rows.size else 0
        if rank == n:
            y = np.array([data.channel(c) for c in names])
            out[order] = np.linalg.lstsq(rows, y, rcond=None)[0]
            have[order] = True
            continue
        have[order] = False
        if rows.size:
            null = np.linalg.svd(rows)[2][rank:]
        else:
            null = np.eye(n)
        lost = [dofs[j] for j in range(n) if np.linalg.norm(null[:, j]) > 1e-8]
        helpers = [
            system.output_names[k]
            for k, q in enumerate(system.output_quantities)
            if DERIVATIVE_ORDER.get(q) == order
            and k not in present[order]
            and np.any(np.abs(system.S[k][[dofs.index(d) for d in lost]]) > 0)
        ]
        problems.append(
            f"the {_QUANTITY[order]} of DOF(s) {lost} (channels present: {names}; add model output channel(s) "
            f"{helpers})"
        )
    derived: dict[str, str] = {}
    valid = {order: np.ones(data.n_samples, dtype=bool) for order in (0, 1, 2)}
    if problems and not derive_missing:
        msg = (
            "the direct method needs the displacement, velocity and acceleration of every DOF; data lack "
            + "; ".join(problems)
            + " - or pass derive_missing=True to differentiate / integrate the quantities present"
        )
        raise DataError(msg)
    if problems:
        if not any(have.values()):
            msg = (
                "cannot derive missing quantities: no quantity (displacement, velocity or acceleration) is "
                "measured for every DOF; data lack " + "; ".join(problems)
            )
            raise DataError(msg)
        dt = data.dt
        changed = True
        while changed:
            changed = False
            for order in (0, 1, 2):
                if have[order]:
                    continue
                if order > 0 and have[order - 1]:
                    out[order], valid[order] = _differentiate(out[order - 1], dt, valid[order - 1])
                    derived[_QUANTITY[order]] = f"differentiated from {_QUANTITY[order - 1]}"
                elif order < 2 and have[order + 1]:
                    out[order] = _integrate(out[order + 1], dt)
                    valid[order] = valid[order + 1].copy()
                    derived[_QUANTITY[order]] = f"integrated from {_QUANTITY[order + 1]} (straight line removed)"
                else:
                    continue
                have[order] = True
                changed = True
    mask = valid[0] & valid[1] & valid[2]
    return out, mask, {"channels": channels, "derived": derived}


def _differentiate(x: Array, dt: float, valid: NDArray[np.bool_]) -> tuple[Array, NDArray[np.bool_]]:
    """4th-order central difference along the last axis; a sample is valid when its five-point stencil is."""
    out = np.zeros_like(x)
    out[..., 2:-2] = (x[..., :-4] - 8.0 * x[..., 1:-3] + 8.0 * x[..., 3:-1] - x[..., 4:]) / (12.0 * dt)
    ok = np.zeros_like(valid)
    ok[2:-2] = valid[:-4] & valid[1:-3] & valid[2:-2] & valid[3:-1] & valid[4:]
    return out, ok


def _integrate(x: Array, dt: float) -> Array:
    """Cumulative Simpson integral along the last axis with a least-squares straight line removed."""
    return np.asarray(signal.detrend(cumulative_simpson(x, dx=dt, axis=-1, initial=0.0), axis=-1, type="linear"))


# ---------------------------------------------------------------------------------------------------------------
# the equations of motion


class _Equations:
    """``M q'' + D q' + K q - B u`` for the unknowns of a space, with its exact derivatives."""

    def __init__(
        self,
        model: NumericModel,
        space: ParameterSpace,
        position: Mapping[str, float] | None,
        motion: Array,
        forces: Array,
        inputs: tuple[str, ...],
        valid: NDArray[np.bool_],
    ) -> None:
        self.model = model
        self.space = space
        self.position = position
        self.columns = [model.input_names.index(i) for i in inputs]
        self.dofs = tuple(model.dofs)
        self.full_motion = motion
        self.full_forces = forces
        self.valid = valid
        self.motion = motion[..., valid]
        self.forces = forces[:, valid]
        self.linear = self._is_linear()

    # matrices at SI unknowns --------------------------------------------------------------------------------------
    def _matrices(self, p: Array) -> tuple[Array, Array, Array, Array]:
        full = self.space.full(p)
        mats = self.model.matrices(full, self.position, names=("M", "C", "G", "K"))
        b_mat = self.model.io_matrices(full, self.position)[0][:, self.columns]
        return mats["M"], mats["C"] + mats["G"], mats["K"], b_mat

    def _derivatives(self, p: Array) -> tuple[Array, Array, Array, Array]:
        full = self.space.full(p)
        der = self.model.matrix_derivatives(full, self.position, names=("M", "C", "G", "K"))
        cols = self.space.columns
        d_b = np.zeros((self.space.n, self.model.n_dof, len(self.columns)))
        if self._b_varies:
            for j in range(self.space.n):
                h = 1e-6 * max(abs(p[j]), 1e-12)
                hi, lo = p.copy(), p.copy()
                hi[j] += h
                lo[j] -= h
                d_b[j] = (self._matrices(hi)[3] - self._matrices(lo)[3]) / (2 * h)
        return der["M"][cols], der["C"][cols] + der["G"][cols], der["K"][cols], d_b

    def _is_linear(self) -> bool:
        s = self.space
        p1 = s.start
        # a second, generic point inside the bounds: golden-ratio fractions of each internal interval
        lo, hi = s.internal_bounds()
        frac = np.mod(0.5 + 0.618034 * np.arange(1, s.n + 1), 1.0)
        u1 = s.to_internal(p1)
        u2 = np.where(np.isfinite(lo) & np.isfinite(hi), lo + frac * (hi - lo), u1 + 0.1 * frac)
        p2 = s.from_internal(u2)
        self._b_varies = not np.allclose(self._matrices(p1)[3], self._matrices(p2)[3], rtol=_AFFINE_RTOL, atol=0)
        if self._b_varies:
            return False
        d1, d2 = self._derivatives(p1), self._derivatives(p2)
        for x, y in zip(d1[:3], d2[:3], strict=True):
            scale = max(float(np.abs(x).max()), float(np.abs(y).max()), 1e-300)
            if not np.allclose(x, y, rtol=_AFFINE_RTOL, atol=_AFFINE_RTOL * scale):
                return False
        return True

    # linear regression --------------------------------------------------------------------------------------------
    def regression(self, motion: Array) -> tuple[Array, Array]:
        """``A`` (n_dof, n_samples, n_unknowns) and ``b`` (n_dof, n_samples) of ``A theta = b`` (linear case)."""
        p = self.space.start
        m, d, k, b_mat = self._matrices(p)
        dm, dd, dk, _ = self._derivatives(p)
        q, qd, qdd = motion
        a = (
            np.einsum("jab,bs->asj", dm, qdd)
            + np.einsum("jab,bs->asj", dd, qd)
            + np.einsum("jab,bs->asj", dk, q)
        )
        known_m = m - np.einsum("j,jab->ab", p, dm)
        known_d = d - np.einsum("j,jab->ab", p, dd)
        known_k = k - np.einsum("j,jab->ab", p, dk)
        rhs = b_mat @ self.forces - known_m @ qdd - known_d @ qd - known_k @ q
        return a, rhs

    def delayed(self, delay: int) -> Array:
        """The measured motion ``delay`` samples earlier (the first ``delay`` samples repeat the first one)."""
        out = np.empty_like(self.motion)
        out[..., delay:] = self.motion[..., :-delay]
        out[..., :delay] = self.motion[..., :1]
        return out

    def simulate(self, theta: Array, time: Array) -> Array:
        """Noise-free displacement, velocity and acceleration of the model at ``theta`` driven by the forces."""
        system = self.model.system(self.space.full(theta), self.position)
        n = system.n_dof
        a_mat = system.state_matrix()
        minv_b = np.linalg.solve(system.M, system.B[:, self.columns])
        b_ss = np.vstack([np.zeros((n, len(self.columns))), minv_b])
        c_ss = np.vstack([np.eye(2 * n), a_mat[n:]])
        d_ss = np.vstack([np.zeros((2 * n, len(self.columns))), minv_b])
        ss = StateSpaceModel(a_mat, b_ss, c_ss, d_ss)
        y, _ = ss.simulate(self.full_forces.T, time)
        out = np.stack([y[:, :n].T, y[:, n : 2 * n].T, y[:, 2 * n :].T])
        return np.asarray(out[..., self.valid], dtype=float)

    def force_scale(self, a: Array, b: Array, p: Array) -> Array:
        """RMS of each DOF's forces at ``p`` (a weight scale that does not need a fit)."""
        forces = np.abs(a * p).sum(axis=2) + np.abs(b)
        scale = np.sqrt(np.mean(forces**2, axis=1))
        top = float(scale.max()) if scale.size else 0.0
        if top <= 0:
            msg = "the measured forces and motion are all zero; nothing to estimate"
            raise DataError(msg)
        return np.asarray(np.maximum(scale, 1e-12 * top), dtype=float)

    # general (non-linear) residuals -------------------------------------------------------------------------------
    def residuals(self, p: Array, motion: Array | None = None) -> Array:
        """Equation errors ``M q'' + D q' + K q - B u`` (n_dof, n_samples) at ``p`` of the measured motion (or of
        ``motion``)."""
        m, d, k, b_mat = self._matrices(np.asarray(p, dtype=float))
        q, qd, qdd = self.motion if motion is None else motion
        return np.asarray(m @ qdd + d @ qd + k @ q - b_mat @ self.forces, dtype=float)

    def jacobian(self, p: Array, motion: Array | None = None) -> Array:
        """Derivatives (n_dof, n_samples, n_unknowns) of :meth:`residuals` at ``p``."""
        dm, dd, dk, d_b = self._derivatives(np.asarray(p, dtype=float))
        q, qd, qdd = self.motion if motion is None else motion
        return np.asarray(
            np.einsum("jab,bs->asj", dm, qdd)
            + np.einsum("jab,bs->asj", dd, qd)
            + np.einsum("jab,bs->asj", dk, q)
            - np.einsum("jab,bs->asj", d_b, self.forces),
            dtype=float,
        )

    def term_scale(self, p: Array) -> float:
        """The largest RMS (N) of the equations' terms ``M q''``, ``D q'``, ``K q`` and ``B u`` at ``p``."""
        m, d, k, b_mat = self._matrices(np.asarray(p, dtype=float))
        q, qd, qdd = self.motion
        return max(float(np.sqrt(np.mean(t**2))) for t in (m @ qdd, d @ qd, k @ q, b_mat @ self.forces))

    def scale_from_residual(self, r: Array, floor: Array | None = None) -> Array:
        scale = np.sqrt(np.mean(r**2, axis=1))
        ref = floor if floor is not None else np.full_like(scale, float(scale.max()) or 1.0)
        return np.maximum(scale, 1e-12 * ref)


def _flat(func: Callable[[Array], Array], weights: Array) -> Callable[[Array], Array]:
    def wrapped(p: Array) -> Array:
        return np.asarray((func(p) * weights[:, None]).ravel(), dtype=float)

    return wrapped


def _flat_jac(func: Callable[[Array], Array], weights: Array) -> Callable[[Array], Array]:
    def wrapped(p: Array) -> Array:
        jac = func(p) * weights[:, None, None]
        return np.asarray(jac.reshape(-1, jac.shape[-1]), dtype=float)

    return wrapped


def _weighted_lstsq(a: Array, b: Array, weights: Array, p0: Array) -> Array:
    """Least squares of the DOF-weighted, column-scaled regression, as the smallest change from ``p0``.

    For a full-rank regression this is the least-squares solution; directions the data do not determine keep
    their start values (instead of the arbitrary minimum-norm values).
    """
    aw = (a * weights[:, None, None]).reshape(-1, a.shape[-1])
    bw = (b * weights[:, None]).ravel() - aw @ p0
    scale = np.linalg.norm(aw, axis=0)
    scale[scale == 0] = 1.0
    sol = np.linalg.lstsq(aw / scale, bw, rcond=None)[0]
    return np.asarray(p0 + sol / scale, dtype=float)


def _bounded(jac: Array, theta: Array, lower: Array, upper: Array) -> Array:
    """The least-squares optimum within the bounds: ``theta`` minimizes ``|J p - y|`` without them, so the bounded
    optimum minimizes ``|J (p - theta)|`` (bounded-variable least squares on the column-scaled Jacobian)."""
    scale = np.linalg.norm(jac, axis=0)
    scale[scale == 0] = 1.0
    js = jac / scale
    sol = lsq_linear(js, js @ (theta * scale), bounds=(lower * scale, upper * scale), method="bvls")
    return np.asarray(np.clip(sol.x / scale, lower, upper), dtype=float)


def _residual_weights(a: Array, b: Array, theta: Array, weights: Array) -> Array:
    """Inverse RMS residual per DOF (floored at 1e-12 of the current weighted scale)."""
    r = b - a @ theta
    sigma = np.sqrt(np.mean(r**2, axis=1))
    floor = 1e-12 / weights
    return np.asarray(1.0 / np.maximum(sigma, floor), dtype=float)


def _iv_solve(a: Array, b: Array, inst: Array, weights: Array, p0: Array) -> tuple[Array, Array]:
    """Two-stage least squares ``(A^T P A)^-1 A^T P b`` (smallest change from ``p0``); also ``P A``, the Jacobian
    for the covariance."""
    n_u = a.shape[-1]
    aw = (a * weights[:, None, None]).reshape(-1, n_u)
    zw = (inst * weights[:, None, None]).reshape(-1, n_u)
    bw = (b * weights[:, None]).ravel() - aw @ p0
    scale = np.linalg.norm(zw, axis=0)
    scale[scale == 0] = 1.0
    q, _ = sla.qr(zw / scale, mode="economic")
    projected = q @ (q.T @ aw)
    cols = np.linalg.norm(projected, axis=0)
    cols[cols == 0] = 1.0
    theta = p0 + np.linalg.lstsq(projected / cols, q @ (q.T @ bw), rcond=None)[0] / cols
    return np.asarray(theta, dtype=float), np.asarray(projected, dtype=float)


def _held_iv_solve(a: Array, b: Array, inst: Array, weights: Array, p0: Array, theta: Array,
                   held: NDArray[np.bool_]) -> tuple[Array, Array]:
    """:func:`_iv_solve` with the unknowns flagged in ``held`` kept at their values in ``theta`` (the Jacobian's
    columns of the held unknowns are zero)."""
    if not held.any():
        return _iv_solve(a, b, inst, weights, p0)
    free = ~held
    sub, sub_jac = _iv_solve(a[..., free], b - a[..., held] @ theta[held], inst[..., free], weights, p0[free])
    out = theta.copy()
    out[free] = sub
    jac = np.zeros((sub_jac.shape[0], theta.size))
    jac[:, free] = sub_jac
    return out, jac


#: Gauss-Newton steps of one non-linear instrumental-variable solve, and the relative step that ends it.
_IV_STEPS = 20
_IV_STEP_TOL = 1e-10


def _nonlinear_iv(space: ParameterSpace, eq: _Equations, simulated: Array, theta: Array, weights: Array,
                  held: NDArray[np.bool_]) -> tuple[Array, Array | None, Array, Exception | None]:
    """One model-instrument iteration for unknowns that enter the equations non-linearly.

    The instruments are the Jacobian ``Z`` of the equation errors evaluated on the model's noise-free response
    ``simulated`` at ``theta`` (what the regressors are for linear unknowns); the DOFs are weighted by the
    residuals at ``theta``; ``Z^T W e(p) = 0`` is solved by Gauss-Newton steps on the equation errors linearized
    at each step, in SI units (affine unknowns then take one step, as the linear path; a logarithm would overshoot
    from a Gauss-Newton estimate far off), from ``theta``. Unknowns flagged in ``held`` keep their values; a step
    that puts an unknown outside its bounds holds it at the bound, flagged in ``held`` (in place). Returns the
    estimate, the projected Jacobian ``P A`` of the last step, the weights and the error that stopped the steps (a
    non-finite estimate; else None).
    """
    inst = eq.jacobian(theta, simulated)
    a = eq.jacobian(theta)
    b = a @ theta - eq.residuals(theta)
    weights = _residual_weights(a, b, theta, weights)
    jac = None
    scale = np.where(theta != 0, np.abs(theta), 1.0)
    for _ in range(_IV_STEPS):
        new, jac = _held_iv_solve(a, b, inst, weights, theta, theta, held)
        outside = ~held & ((new < space.lower) | (new > space.upper))
        if outside.any():  # held at the bound from here on (and for the caller)
            held |= outside
            new = np.clip(new, space.lower, space.upper)
        step = float(np.max(np.abs(new - theta) / scale))
        theta = new
        if not np.all(np.isfinite(theta)):
            return theta, None, weights, FloatingPointError("the instrumental-variable step is not finite")
        a = eq.jacobian(theta)
        b = a @ theta - eq.residuals(theta)
        if step <= _IV_STEP_TOL:
            break
    return theta, jac, weights, None
