"""How far an estimate depends on what the inputs did between their samples (issue 21).

A time-domain fit assumes one intersample behaviour of the recorded inputs: held (``zoh``), linear (``foh``, what
:func:`scipy.signal.lsim` does) or band-limited (``bl``, what a DAQ's anti-alias filter records). The residual tests
cannot always tell them apart (a 3000-sample DAQ record at 5 % noise fitted with ``foh`` passed them with m1 17
standard errors off). The answer then depends on the assumption, and the estimate says by how much: at the
estimate, the model's forced response to the recorded inputs under each other behaviour differs from the one
fitted by ``dy = y_other - y_used``. Fitted to the same data under the other behaviour, the output errors at the
estimate change by ``-dy`` (the free response of the initial state is the same for every behaviour), and the
least-squares estimate moves by a Gauss-Newton step from the estimate (``R`` the regularized information the fit's
covariance comes from, ``J`` its noise-weighted output Jacobian, taken for the other behaviour:
:func:`intersample_sensitivity`). The shift is reported per parameter, relative and in standard errors.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cappe.exceptions import DataError
from cappe.systems.statespace import INTERSAMPLE, StateSpaceModel, simulate

__all__ = ["forced_responses", "intersample_sensitivity", "sensitivity_text", "sensitivity_warning"]

Array = NDArray[np.float64]

#: How each behaviour reads in the text output.
_WERE = {"zoh": "held between samples (zoh)", "foh": "linear between samples (foh, as scipy's lsim)",
         "bl": "band-limited (a DAQ's anti-alias filter, bl)"}
#: A parameter whose estimate would move by more than this many standard errors under another behaviour depends
#: on the assumption: its interval does not hold without it.
DEPENDS_LEVEL = 1.0


def forced_responses(
    a: Array, b: Array, c: Array, d: Array, u: Array, dt: float, holds: Sequence[str] = tuple(INTERSAMPLE)
) -> dict[str, Array]:
    """Forced responses (from rest) of a continuous model to sampled inputs under each intersample behaviour.

    Parameters
    ----------
    a, b, c, d : ndarray
        Continuous state-space matrices ``(n, n)``, ``(n, n_in)``, ``(n_out, n)``, ``(n_out, n_in)``.
    u : ndarray, shape (n_samples, n_in)
        The inputs at the samples.
    dt : float
        Sample time in s.
    holds : sequence of str
        The behaviours to simulate (:func:`cappe.systems.statespace.simulate`'s ``intersample``).

    Returns
    -------
    dict of str to ndarray, shape (n_samples, n_out)
        The outputs per behaviour; a behaviour the model cannot be simulated with (``bl`` on an unstable or
        undamped model) is left out.
    """
    model = StateSpaceModel(np.asarray(a, dtype=float), np.asarray(b, dtype=float), np.asarray(c, dtype=float),
                            np.asarray(d, dtype=float))
    t = np.arange(u.shape[0]) * dt
    out: dict[str, Array] = {}
    for hold in holds:
        try:
            out[hold] = np.asarray(simulate(model, u, t, intersample=hold)[0], dtype=float)
        except DataError:
            continue
    return out


def intersample_sensitivity(
    respond: Callable[[Array, Sequence[str]], Mapping[str, Array]],
    used: str,
    jac: Array,
    residual: Array,
    regular: Array,
    sigma: Array,
    theta: Array,
    space: Any,
    std: Array,
    step: float = 1e-5,
    iterations: int = 3,
) -> tuple[dict[str, dict[str, dict[str, float]]], dict[str, Array]]:
    """The Gauss-Newton shift of an estimate fitted to the same data under another intersample behaviour.

    A few Gauss-Newton steps of the refit under the other behaviour from the estimate: its forced response
    evaluated exactly at ``theta + delta`` (the initial state's free response, the same for every behaviour,
    linearized), its Jacobian ``J_o = J + (d y_o/dtheta - d y_used/dtheta) / sigma`` by central differences, the
    prior of ``R - J^T J`` kept, and the estimate's own gradient (zero at its optimum) left out. One step with ``J``
    for ``J_o`` (``delta = -R^-1 J^T dy / sigma``) missed m1 and k11 of a FOH fit's refit with a held input by a
    factor 4 (their sensitivities are nearly orthogonal to the half-sample shift between the two); these steps
    matched that refit within 5 % of each shift (lsim record, 1500 samples, m1, k11, c11: +4.9/+4.8 %,
    +5.6/+5.5 %, -15.5/-16.2 %).

    Parameters
    ----------
    respond : callable
        ``respond(theta, holds)``: forced responses for the behaviours ``holds`` at internal parameters ``theta``
        (:func:`forced_responses`), in the fit's output units, each (n_samples, n_out).
    used : str
        The behaviour the fit assumed (a key of ``respond``'s result).
    jac : ndarray, shape (n_samples * n_out, n)
        Noise-weighted output Jacobian, time-major rows; its first ``space.n`` columns are the parameters (internal
        coordinates), the rest nuisance parameters (an initial state).
    residual : ndarray, shape (n_samples * n_out,)
        Noise-weighted output errors at the estimate (data minus model), time-major.
    regular : ndarray, shape (n, n)
        The regularized information ``J^T J + prior`` of the fit.
    sigma : ndarray, shape (n_out,)
        Noise standard deviation per output (the fit's output units).
    theta : ndarray, shape (space.n,)
        The estimate in internal coordinates.
    space : ParameterSpace
        The unknowns (names, ``from_internal``).
    std : ndarray, shape (space.n,)
        The reported standard errors (value units; nan where not determined).
    step : float
        Central-difference step in internal coordinates.
    iterations : int
        Gauss-Newton steps (the fitted behaviour's response linearized about the estimate, the difference of the
        behaviours and its derivative evaluated anew at each).

    Returns
    -------
    shifts : dict
        ``{behaviour: {parameter: {"shift": relative change, "shift_std": change / std}}}`` for every behaviour
        other than ``used``.
    errors : dict of str to ndarray, shape (n_samples, n_out)
        The output errors of each such refit (data minus model, the fit's output units), to test whether the data
        rule that behaviour out.
    """
    nt = space.n
    values = space.from_internal(theta)
    at = respond(theta, tuple(INTERSAMPLE))
    if used not in at:
        return {}, {}

    def slopes(point: Array, hold: str) -> Array:
        """d y_hold / dtheta at point (central differences), noise-weighted, time-major rows."""
        out = np.zeros((jac.shape[0], nt))
        for j in range(nt):
            shift = np.zeros(nt)
            shift[j] = step
            diff = respond(point + shift, (hold,))[hold] - respond(point - shift, (hold,))[hold]
            out[:, j] = (diff / (2 * step * sigma[None, :])).ravel()
        return out

    fitted = slopes(theta, used)
    prior = regular - jac.T @ jac
    out: dict[str, dict[str, dict[str, float]]] = {}
    refit_errors: dict[str, Array] = {}
    for hold in (h for h in at if h != used):
        delta = np.zeros(jac.shape[1])  # the parameters' and the nuisance parameters' change
        for _ in range(iterations):
            here = respond(theta + delta[:nt], (hold,))
            if hold not in here:
                break
            # the output errors were the other behaviour fitted at theta + delta: its forced response exact, the
            # initial state's free response linearized
            errors = residual + ((at[used] - here[hold]) / sigma[None, :]).ravel() - jac[:, nt:] @ delta[nt:]
            j_other = jac.copy()
            j_other[:, :nt] += slopes(theta + delta[:nt], hold) - fitted
            # the estimate's own gradient (zero at its optimum) is left out
            gradient = j_other.T @ errors - jac.T @ residual - prior @ delta
            change = np.linalg.solve(prior + j_other.T @ j_other, gradient)
            delta = delta + change
            # the output errors at the refit, to first order from the last evaluation
            refit_errors[hold] = (errors - j_other @ change).reshape(-1, sigma.size) * sigma[None, :]
        moved = space.from_internal(theta + delta[:nt]) - values
        with np.errstate(invalid="ignore", divide="ignore"):
            rel = np.where(values != 0, moved / np.abs(values), np.nan)
            in_std = np.where(np.isfinite(std) & (std > 0), moved / std, np.nan)
        out[hold] = {n: {"shift": float(r), "shift_std": float(z)}
                     for n, r, z in zip(space.names, rel, in_std, strict=True)}
    return out, refit_errors


def _largest(shifts: Mapping[str, Mapping[str, float]], count: int) -> list[tuple[str, float, float]]:
    rows = [(n, s["shift"], s["shift_std"]) for n, s in shifts.items()]
    return sorted(rows, key=lambda r: -abs(r[2]) if np.isfinite(r[2]) else -abs(r[1]) * 1e-9)[:count]


def sensitivity_text(
    sensitivity: Mapping[str, Mapping[str, Mapping[str, float]]], count: int = 3,
    ruled_out: Mapping[str, bool] | None = None,
) -> str:
    """One line naming the largest shifts per behaviour.

    Parameters
    ----------
    sensitivity : mapping
        :func:`intersample_sensitivity`'s result.
    count : int
        Parameters named per behaviour.
    ruled_out : mapping of str to bool, optional
        Per behaviour, whether the residual tests reject its refit (said after its shifts).

    Returns
    -------
    str
        E.g. ``"were the inputs bl: m1 +2.6 % (17 std), ...; zoh: ..."``.
    """
    parts = []
    for hold, shifts in sensitivity.items():
        named = ", ".join(f"{n} {100 * r:+.3g} %" + (f" ({z:+.2g} std)" if np.isfinite(z) else "")
                          for n, r, z in _largest(shifts, count))
        said = " (its refit fails the residual tests)" if ruled_out and ruled_out.get(hold, False) else ""
        parts.append(f"{hold}: {named}{said}")
    return "; ".join(parts)


def sensitivity_warning(
    sensitivity: Mapping[str, Mapping[str, Mapping[str, float]]], rejected: bool,
    ruled_out: Mapping[str, bool] | None = None,
) -> tuple[str | None, list[str]]:
    """The warning where a parameter would move by more than :data:`DEPENDS_LEVEL` standard errors, and which.

    Parameters
    ----------
    sensitivity : mapping
        :func:`intersample_sensitivity`'s result.
    rejected : bool
        Whether the residual tests reject the fit (then the data speak against the assumed behaviour).
    ruled_out : mapping of str to bool, optional
        Per behaviour, whether the residual tests reject its refit (the data then tell it apart from the assumed
        one, and it is not warned of).

    Returns
    -------
    line : str or None
        The warning (None where no parameter depends on the assumption).
    dependent : list of str
        The parameters that do.
    """
    dependent: list[str] = []
    clauses = []
    for hold, shifts in sensitivity.items():
        if ruled_out and ruled_out.get(hold, False):
            continue
        moved = [(n, r, z) for n, r, z in _largest(shifts, len(shifts)) if np.isfinite(z) and abs(z) > DEPENDS_LEVEL]
        if not moved:
            continue
        dependent += [n for n, _, _ in moved if n not in dependent]
        named = ", ".join(f"{n} would be {100 * abs(r):.2g} % {'higher' if r > 0 else 'lower'} ({abs(z):.2g} std)"
                          for n, r, z in moved[:3])
        more = f" and {len(moved) - 3} more" if len(moved) > 3 else ""
        clauses.append(f"were they {_WERE.get(hold, hold)}, {named}{more}")
    if not clauses:
        return None, []
    verdict = ("the residual tests reject the assumed behaviour and not this one: state the right --intersample, "
               "or fit with one-step --intersample bl" if rejected else
               "the residual tests do not tell the behaviours apart: state --intersample as the inputs were "
               "recorded, or fit with one-step --intersample bl")
    return ("the estimate depends on the inputs' intersample behaviour: " + "; ".join(clauses) + "; " + verdict,
            dependent)
