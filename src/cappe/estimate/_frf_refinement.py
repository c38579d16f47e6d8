"""Refinement of all unknowns against measured FRFs, after the modal stages of the automated identification.

The modal stages (GSA, stiffness subproblems, damping least squares, exact-mode refinement) find the global basin
from extracted modes. Extracted modes carry the systematic errors of the rational fit that produced them (mode
complexity an LSCF/LSFD fit of hysteretically damped FRFs cannot reproduce, overlapping modes, residual terms), and
a damping unknown that barely moves any extracted damping ratio stays undetermined (issue 20: damping worst 40-64 %
with modes alone). The measured FRFs hold all of it, so the last step fits the model's FRFs to them directly, at
the sensor channels and references the test measured, at every identification position.

**Residual.** The complex logarithm of model over measured FRF, ``log(H_model / H_meas)``: its real part is the
log-magnitude error, its imaginary part the phase error in rad. An expert's choice for FRFs spanning decades: a
linear (complex difference) residual is dominated by the few lines at the resonance peaks of the most flexible
channel, while the logarithm weighs every line by its *relative* error, so weak channels, anti-resonances and the
flanks of the peaks (where the damping shows) count; the magnitude and phase of a measured FRF are what its noise
disturbs alike (for relative noise ``H (1 + e)``, ``log(1 + e) ~ e``). It is the residual of
:class:`~cappe.estimate.OneStepFRFEstimator` as well.

**Weights: the data's own noise.** Each residual is divided by its noise standard deviation. Per FRF, the noise of
``log H`` at line l is ``s^2 u_l`` (complex variance, half in each part):

- ``u_l = (1 - gamma_l^2) / gamma_l^2`` where the data have a coherence (for an H1 estimate the variance of the log
  is ``(1 - gamma^2) / (2 n_avg gamma^2)`` per part, Bendat & Piersol; the number of averages is not in the file);
- ``u_l = 1`` otherwise (relative noise of one level along the FRF);

and the level ``s^2`` comes from the FRF itself: the second difference along frequency
``d_l = log H_{l+1} - 2 log H_l + log H_{l-1}`` of a smooth FRF is its noise, with variance
``(u_{l-1} + 4 u_l + u_{l+1}) s^2``; the median of ``|d_l|^2 / (u_{l-1} + 4 u_l + u_{l+1})`` is ``ln 2 s^2``
(an exponential variable's median). The median ignores the few lines where a sharp resonance curves ``log H``
more than the noise does. This estimate does not use the model, so the fit's residual can be compared with it:
``chi2 / dof`` is reported and a ratio far above one is a warning (a misfit above the noise).

**Lines.** A measured FRF has many more lines than the unknowns need (1400 lines x 180 FRFs x 3 positions on the
benchmark: 1.5 million complex residuals). The fit keeps, in the band of the reference modes widened by a fifth,
the lines where the FRFs change: the line spacing grows with the distance to the nearest reference pole,
``(zeta_r f_r + |f - f_r|) / LINES_PER_SCALE`` (never below the measured spacing), so each resonance is sampled
within its half-power band and the flanks and the stretches between modes more sparsely.

**Covariance.** The model-based ``s^2 (J^T J)^-1`` assumes independent residuals. Those of neighbouring lines and of
the channels of one line are correlated in practice (spectral leakage and windows, the common force signal of an
H1 estimate, model error around one mode), so the reported standard error is the larger of the model-based one and
a cluster-robust sandwich over blocks of consecutive lines at one position, all channels together
(:func:`~cappe.estimate._automated_steps.robust_uncertainty`), with 95 % intervals on a log scale. Known parameters
given a tolerance (``--known-tolerance``) add their consider covariance there, from the same residuals' derivatives
by those parameters (:meth:`FRFRefinementProblem.jacobian` with ``parameters``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cappe.estimate._result import ParameterEstimate
from cappe.estimate._space import ParameterSpace
from cappe.exceptions import DataError, ModelError
from cappe.model import NumericModel
from cappe.systems.dynamic_stiffness import frf_lines
from cappe.systems.frf import FRFData
from cappe.systems.mechanical import DERIVATIVE_ORDER
from cappe.systems.modal import ModalDataSet

__all__ = ["FRFRefinement", "FRFRefinementProblem", "MeasuredFRF", "frf_noise", "model_frf", "refine_against_frf",
           "resonance_lines"]

Array = NDArray[np.float64]
CArray = NDArray[np.complex128]

#: Lines kept per local scale ``zeta_r f_r + |f - f_r|`` of the FRF near pole r (see the module notes).
LINES_PER_SCALE = 3.0
#: The fitted band: the reference modes' span widened by this factor on both sides.
BAND_MARGIN = 1.2
#: Consecutive fitted lines of one position that form one cluster of the sandwich covariance.
CLUSTER_LINES = 5
#: Coherence is clipped to this range before it forms the noise shape (1 would give an infinite weight).
_COHERENCE_RANGE = (1e-3, 0.999)


@dataclass(frozen=True)
class MeasuredFRF:
    """Measured FRFs at one axis position, at model sensor channels (after a sensor map).

    Attributes
    ----------
    position : dict
        Axis position ``{axis: value}`` (m or rad).
    data : FRFData
        The FRFs; outputs and inputs are model sensor channels ``"node:dir"`` (a force at the sensor point along
        the channel's direction), output quantities as measured (displacement, velocity or acceleration).
    source : str
        The file it came from (for messages).
    """

    position: dict[str, float]
    data: FRFData
    source: str = ""

    def where(self) -> str:
        """The file name (or "measured FRFs") for messages."""
        return self.source or "measured FRFs"


def model_frf(model: NumericModel, params: Array, position: Mapping[str, float], freq: Array,
              outputs: Sequence[str], inputs: Sequence[str], orders: Sequence[int],
              columns: Sequence[int] | None = None) -> tuple[CArray, CArray]:
    """The model's FRFs between sensor channels, line-major ``H[line, out, in]``, and with ``columns`` (indices of
    model parameters) their exact derivatives ``dH[k, line, out, in]`` (:func:`cappe.systems.dynamic_stiffness.
    frf_lines`: the one FRF kernel).

    Parameters
    ----------
    model : NumericModel
        The model.
    params : ndarray, shape (n_params,)
        Full parameter vector (SI).
    position : mapping
        Axis position.
    freq : ndarray, shape (n_lines,)
        Frequencies in Hz.
    outputs, inputs : sequence of str
        Sensor channels ``"node:dir"`` of the responses and of the forces.
    orders : sequence of int
        Time-derivative order of each output (0 displacement, 1 velocity, 2 acceleration).
    columns : sequence of int, optional
        Parameters to differentiate by.

    Returns
    -------
    H : ndarray of complex, shape (n_lines, n_out, n_in)
    dH : ndarray of complex, shape (len(columns), n_lines, n_out, n_in)
        Empty without ``columns``. Sensor points that move with a parameter are not differentiated (the pipeline
        refuses such unknowns, :class:`FRFRefinementProblem`).
    """
    labels, rows = model.sensor_matrix(params, position)
    index = {lab: i for i, lab in enumerate(labels)}
    s_out = rows[[index[c] for c in outputs]]
    b_in = rows[[index[c] for c in inputs]].T
    mats = model.matrices(params, position)
    derivs = None
    if columns is not None:
        names = [model.parameter_names[c] for c in columns]
        derivs = model.matrix_derivatives(params, position, parameters=names)
    lines = frf_lines(mats, 2 * np.pi * np.asarray(freq, dtype=float), b_in, s_out, orders=orders,
                      derivatives=derivs)
    return lines.H, lines.dH


def frf_noise(H: CArray, coherence: Array | None = None) -> tuple[Array, str]:
    """Noise variance of ``log H`` at every line, from the FRF itself (see the module notes).

    Parameters
    ----------
    H : ndarray of complex, shape (n_out, n_in, n_lines)
        Measured FRFs on equally spaced lines (any unit).
    coherence : ndarray, shape (n_out, n_in, n_lines), optional
        Coherence of each line; it shapes the noise along the FRF, the second differences set its level.

    Returns
    -------
    variance : ndarray, shape (n_out, n_in, n_lines)
        Complex variance of ``log H`` per line (half of it in the log-magnitude, half in the phase); NaN where ``H``
        is zero or not finite, and for an FRF with fewer than five usable lines.
    how : str
        What the weights were made of, for the output.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> n = rng.standard_normal((1, 1, 4000)) + 1j * rng.standard_normal((1, 1, 4000))
    >>> H = np.exp(1j * np.linspace(0, 3, 4000))[None, None, :] * (1 + 0.02 * n / np.sqrt(2))
    >>> var, _ = frf_noise(H)
    >>> bool(abs(np.sqrt(np.nanmedian(var)) / 0.02 - 1) < 0.05)
    True
    """
    h = np.asarray(H, dtype=complex)
    valid = np.isfinite(h) & (np.abs(h) > 0)
    ell = np.log(np.where(valid, h, 1.0))
    if coherence is not None:
        gamma2 = np.clip(np.asarray(coherence, dtype=float), *_COHERENCE_RANGE)
        shape = (1.0 - gamma2) / gamma2
        how = "coherence (its shape along frequency) times the FRF's own second-difference scatter (its level)"
    else:
        shape = np.ones(h.shape)
        how = "each FRF's own scatter (second differences of log H along frequency, robust median)"
    # log H_{l+1} - 2 log H_l + log H_{l-1}: magnitudes as logs, phases as wrapped angle differences
    d = ell[..., 2:] - 2 * ell[..., 1:-1] + ell[..., :-2]
    d = d.real + 1j * np.angle(np.exp(1j * d.imag))
    denom = shape[..., :-2] + 4 * shape[..., 1:-1] + shape[..., 2:]
    ok = valid[..., 2:] & valid[..., 1:-1] & valid[..., :-2]
    ratio = np.where(ok, np.abs(d) ** 2 / denom, np.nan)
    enough = np.sum(ok, axis=-1) >= 3
    level = np.full(h.shape[:-1], np.nan)
    if np.any(enough):
        level[enough] = np.nanmedian(ratio[enough], axis=-1) / math.log(2.0)
    variance = np.where(valid, level[..., None] * shape, np.nan)
    return variance, how


def resonance_lines(freq: Array, band: tuple[float, float], frequency: Array, damping: Array,
                    per_scale: float = LINES_PER_SCALE) -> NDArray[np.intp]:
    """Indices of the lines to fit: dense near the poles, sparse between them (see the module notes).

    Parameters
    ----------
    freq : ndarray, shape (n_lines,)
        Measured lines in Hz (ascending).
    band : (float, float)
        Band in Hz.
    frequency, damping : ndarray, shape (m,)
        Natural frequencies (Hz) and damping ratios of the poles that shape the FRFs.
    per_scale : float
        Lines per local scale ``zeta_r f_r + |f - f_r|``.

    Returns
    -------
    ndarray of int
        Ascending indices into ``freq``.

    Examples
    --------
    >>> f = np.arange(1, 2001) * 0.25
    >>> keep = resonance_lines(f, (50.0, 450.0), np.array([100.0, 300.0]), np.array([0.01, 0.02]))
    >>> gap = np.min(np.abs(f[keep][:, None] - np.array([100.0, 300.0])), axis=0)  # nearest kept line to each pole
    >>> bool(np.all(gap < np.array([0.01, 0.02]) * [100.0, 300.0])), len(keep) < 400
    (True, True)
    """
    f = np.asarray(freq, dtype=float)
    inside = np.flatnonzero((f >= band[0]) & (f <= band[1]))
    if inside.size == 0:
        return inside
    fr = np.asarray(frequency, dtype=float)
    half = np.abs(np.asarray(damping, dtype=float)) * fr
    scale = np.min(half[None, :] + np.abs(f[inside, None] - fr[None, :]), axis=1)
    # lines wanted per measured line: per_scale / scale times the spacing; one line is kept each time their running
    # sum passes a whole number (every line where more than one is wanted)
    step = np.gradient(f[inside]) if inside.size > 1 else np.ones(1)
    wanted = np.cumsum(per_scale * step / np.maximum(scale, 1e-12 * float(f[inside].max())))
    count = np.floor(wanted)
    first = np.concatenate([[True], count[1:] > count[:-1]])
    return np.asarray(inside[first], dtype=np.intp)


@dataclass(frozen=True)
class _Position:
    """One position's fitted data: channels, lines, log of the measurement, residual weights, the kept mask."""

    position: dict[str, float]
    source: str
    outputs: tuple[str, ...]
    inputs: tuple[str, ...]
    orders: NDArray[np.intp]
    freq: Array
    log_meas: CArray  # (n_lines, n_out, n_in)
    sqrt_w: Array  # (n_lines, n_out, n_in), 0 where left out
    mask: NDArray[np.bool_]


class FRFRefinementProblem:
    """Weighted complex-log FRF residuals over all unknowns at the identification positions, with their analytic
    Jacobian (see the module notes).

    Parameters
    ----------
    model : NumericModel
        The model.
    space : ParameterSpace
        The unknowns.
    measured : sequence of MeasuredFRF
        FRFs at identification positions, at model sensor channels.
    reference : sequence of ModalDataSet
        The reference modes at the same positions (same order): their poles choose the band and the lines.

    Raises
    ------
    DataError
        An FRF file has no output or input at a model sensor channel, lines that are not equally spaced, no line
        in the band, or an exponential window.
    ModelError
        A sensor point moves with an unknown (the FRF Jacobian would miss that term).
    """

    def __init__(self, model: NumericModel, space: ParameterSpace, measured: Sequence[MeasuredFRF],
                 reference: Sequence[ModalDataSet]) -> None:
        self.model = model
        self.space = space
        self.positions: list[_Position] = []
        self.noise = ""
        labels = model.sensor_matrix(space.full(space.start))[0]
        self.refuse_moving_sensors(space.names, "unknowns")
        for item, data_set in zip(measured, reference, strict=True):
            self.positions.append(self._prepare(item, data_set, set(labels)))
        self.evaluations = 0

    def refuse_moving_sensors(self, names: Sequence[str], what: str) -> None:
        """Raise if a sensor point moves with one of the model parameters ``names``: the FRF derivatives leave the
        sensor rows' change out.

        Parameters
        ----------
        names : sequence of str
            Model parameters (unknowns, or known ones whose uncertainty the intervals consider).
        what : str
            What they are, for the message.

        Raises
        ------
        ModelError
            Naming the parameters that move a sensor point.
        """
        base = self.space.full(self.space.start)
        rows0 = self.model.sensor_matrix(base)[1]
        moved = []
        for name in names:
            p = base.copy()
            p[self.model.parameter_names.index(name)] *= 1.5
            if not np.array_equal(self.model.sensor_matrix(p)[1], rows0):
                moved.append(name)
        if moved:
            msg = f"sensor points of model '{self.model.structure.name}' move with the {what} {moved}; the FRF " \
                  "refinement needs them fixed"
            raise ModelError(msg)

    def _prepare(self, item: MeasuredFRF, data_set: ModalDataSet, labels: set[str]) -> _Position:
        frf, where = item.data, item.where()
        if frf.window_decay is not None:
            msg = (f"{where}: FRFs of an exponentially windowed response (tau {frf.window_decay:g} s) carry the "
                   "window's damping; the FRF refinement needs unwindowed FRFs")
            raise DataError(msg)
        outs = [k for k, n in enumerate(frf.output_names) if n in labels]
        ins = [k for k, n in enumerate(frf.input_names) if n in labels]
        if not outs:
            msg = (f"{where}: no FRF output is a sensor channel of model '{self.model.structure.name}' (outputs "
                   f"{list(frf.output_names)[:6]}); map them with --sensor-map")
            raise DataError(msg)
        if not ins:
            msg = (f"{where}: no FRF input (reference) is a sensor channel of model '{self.model.structure.name}' "
                   f"(inputs {list(frf.input_names)}); map them with --sensor-map")
            raise DataError(msg)
        freq = np.asarray(frf.freq, dtype=float)
        steps = np.diff(freq)
        if freq.size < 5 or np.any(steps <= 0) or np.ptp(steps) > 1e-6 * float(np.mean(steps)):
            msg = f"{where}: the FRF refinement needs at least 5 equally spaced, increasing frequency lines"
            raise DataError(msg)
        band = (float(data_set.frequency.min()) / BAND_MARGIN, float(data_set.frequency.max()) * BAND_MARGIN)
        quantities = frf.output_quantities or ("displacement",) * len(frf.output_names)
        orders = np.array([DERIVATIVE_ORDER[quantities[k]] for k in outs], dtype=np.intp)
        h = np.asarray(frf.H, dtype=complex)[np.ix_(outs, ins)]
        coherence = None if frf.coherence is None else np.asarray(frf.coherence)[np.ix_(outs, ins)]
        inside = (freq >= band[0]) & (freq <= band[1])
        if np.count_nonzero(inside) < 5:
            msg = (f"{where}: fewer than 5 lines in the band of the reference modes {band[0]:.4g}-{band[1]:.4g} Hz; "
                   f"its lines span {freq.min():g}-{freq.max():g} Hz")
            raise DataError(msg)
        variance, self.noise = frf_noise(h[..., inside], None if coherence is None else coherence[..., inside])
        lines = resonance_lines(freq, band, data_set.frequency, data_set.damping)
        local = np.searchsorted(np.flatnonzero(inside), lines)
        var = np.moveaxis(variance[..., local], -1, 0)
        meas = np.moveaxis(h[..., lines], -1, 0)
        mask = np.isfinite(var) & (var > 0)
        if not np.any(mask):
            msg = f"{where}: no FRF line with a finite, non-zero value and an estimable noise in the band"
            raise DataError(msg)
        sqrt_w = np.where(mask, 1.0 / np.sqrt(np.where(mask, var, 1.0) / 2.0), 0.0)  # per part: variance / 2
        return _Position(dict(item.position), where, tuple(frf.output_names[k] for k in outs),
                         tuple(frf.input_names[k] for k in ins), orders, freq[lines],
                         np.log(np.where(mask, meas, 1.0)), sqrt_w, mask)

    @property
    def n_residuals(self) -> int:
        """Number of real residuals."""
        return int(sum(2 * np.count_nonzero(p.mask) for p in self.positions))

    def _at(self, p: Array, pos: _Position, columns: Sequence[int] | None) -> tuple[CArray, CArray]:
        full = self.space.full(p)
        try:
            return model_frf(self.model, full, pos.position, pos.freq, pos.outputs, pos.inputs, pos.orders.tolist(),
                             columns)
        except np.linalg.LinAlgError as exc:
            msg = f"dynamic stiffness is singular at a fitted line of {pos.source}"
            raise ModelError(msg) from exc

    def residuals(self, p: Array) -> Array:
        """Weighted residuals ``[Re, Im] sqrt(w) log(H_model / H_meas)`` of every position, line-major.

        Parameters
        ----------
        p : ndarray, shape (space.n,)
            The unknowns in SI units.

        Returns
        -------
        ndarray, shape (n_residuals,)
        """
        self.evaluations += 1
        out = []
        for pos in self.positions:
            h = self._at(np.asarray(p, dtype=float), pos, None)[0]
            with np.errstate(divide="ignore", invalid="ignore"):
                ell = np.log(h[pos.mask]) - pos.log_meas[pos.mask]
            err = ell.real + 1j * np.angle(np.exp(1j * ell.imag))  # phase error wrapped to (-pi, pi]
            w = pos.sqrt_w[pos.mask]
            out.append(np.concatenate([w * err.real, w * err.imag]))
        return np.concatenate(out)

    def jacobian(self, p: Array, parameters: Sequence[str] | None = None) -> Array:
        """``d residuals / d p`` (SI), from the analytic FRF derivatives ``dH/dp / H``.

        Parameters
        ----------
        p : ndarray, shape (space.n,)
            The unknowns in SI units.
        parameters : sequence of str, optional
            Model parameters to differentiate by instead of the unknowns, e.g. known ones whose uncertainty the
            intervals consider (:func:`~cappe.estimate._automated_steps.robust_uncertainty`); default the unknowns.
            Sensor points must not move with them (:meth:`refuse_moving_sensors`).

        Returns
        -------
        ndarray, shape (n_residuals, space.n) or (n_residuals, len(parameters))
            Derivatives of the residuals by the SI parameters (1 / unit of each parameter).
        """
        columns = (self.space.columns.tolist() if parameters is None
                   else [self.model.parameter_names.index(n) for n in parameters])
        blocks = []
        for pos in self.positions:
            h, dh = self._at(np.asarray(p, dtype=float), pos, columns)
            d = dh[:, pos.mask] / h[pos.mask][None, :]  # (n, n_res)
            w = pos.sqrt_w[pos.mask][None, :]
            blocks.append(np.concatenate([w * d.real, w * d.imag], axis=1).T)
        return np.vstack(blocks)

    def groups(self) -> NDArray[np.intp]:
        """Cluster of every residual for the sandwich covariance: blocks of ``CLUSTER_LINES`` consecutive fitted
        lines of one position, all its channels and both parts together (see the module notes).

        Returns
        -------
        ndarray of int, shape (n_residuals,)
        """
        out, offset = [], 0
        for pos in self.positions:
            line = np.broadcast_to(np.arange(pos.freq.size)[:, None, None], pos.mask.shape)[pos.mask]
            block = offset + line // CLUSTER_LINES
            out.append(np.concatenate([block, block]))
            offset = int(block.max()) + 1
        return np.concatenate(out).astype(np.intp)

    def summary(self) -> list[dict[str, Any]]:
        """Per position: its file, channels and lines fitted."""
        return [{"position": p.position, "source": p.source, "outputs": len(p.outputs), "inputs": list(p.inputs),
                 "lines": int(p.freq.size), "band": [float(p.freq[0]), float(p.freq[-1])],
                 "residuals": int(2 * np.count_nonzero(p.mask))} for p in self.positions]


@dataclass(frozen=True)
class FRFRefinement:
    """The refinement against measured FRFs (after the modal stages).

    Attributes
    ----------
    estimate : ParameterEstimate
        All unknowns, with the larger of the model-based and the cluster-robust uncertainty.
    start : ndarray, shape (n_unknowns,)
        The modal stages' estimate it started from (SI).
    values : ndarray, shape (n_unknowns,)
        The refined estimate (SI).
    cost_before, cost_after : float
        Sum of squared weighted residuals at the start and at the estimate.
    n_residuals : int
        Real residuals fitted.
    noise : str
        What the weights were made of.
    chi2_dof : float
        ``cost_after / (n_residuals - n_unknowns)``: the fit's residual over the data's noise (1 for a fit down to
        the noise).
    positions : list of dict
        Per position: source, channels, lines.
    warnings : tuple of str
        What a user must see (residual far above the noise, estimates at a bound).
    cost_function : CostFunction or None
        The cost it minimized (for :meth:`Estimator.cost_slice`).
    """

    estimate: ParameterEstimate
    start: Array
    values: Array
    cost_before: float
    cost_after: float
    n_residuals: int
    noise: str
    chi2_dof: float
    positions: list[dict[str, Any]] = field(default_factory=list)
    warnings: tuple[str, ...] = ()
    cost_function: Any = None

    @property
    def uncertainty(self) -> str:
        """How the standard deviations were formed (the robust-uncertainty step's words)."""
        return str(self.estimate.diagnostics.get("uncertainty", {}).get("std", "Gauss-Newton"))

    def to_dict(self) -> dict[str, Any]:
        return {"cost_before": self.cost_before, "cost_after": self.cost_after, "residuals": self.n_residuals,
                "noise": self.noise, "chi2_dof": self.chi2_dof, "positions": self.positions,
                "success": bool(self.estimate.success), "message": self.estimate.message,
                "start": {n: float(v) for n, v in zip(self.estimate.names, self.start, strict=True)},
                "relative_change": {n: float(v / s - 1.0) for n, v, s in
                                    zip(self.estimate.names, self.values, self.start, strict=True)}}


#: A chi2 / dof above this is reported: the residual is far above the data's own noise.
RESIDUAL_LEVEL = 4.0


def refine_against_frf(*, method: str, model: NumericModel, space: ParameterSpace,
                       measured: Sequence[MeasuredFRF], reference: Sequence[ModalDataSet],
                       start: Array, known_tolerance: Mapping[str, float] | None = None) -> FRFRefinement:
    """All unknowns fitted to measured FRFs from ``start`` (the modal stages' estimate), with an honest uncertainty.

    Parameters
    ----------
    method : str
        The estimator's method name (for the result).
    model : NumericModel
        The model.
    space : ParameterSpace
        The unknowns and their bounds.
    measured : sequence of MeasuredFRF
        FRFs at the identification positions.
    reference : sequence of ModalDataSet
        The reference modes at the same positions (they choose band and lines).
    start : ndarray, shape (space.n,)
        Start (SI).
    known_tolerance : mapping name -> float, optional
        Relative standard deviation of known parameters whose uncertainty the intervals include (consider
        covariance, :func:`~cappe.estimate._automated_steps.robust_uncertainty`; 0.1: 10 %).

    Returns
    -------
    FRFRefinement

    Raises
    ------
    ModelError
        A sensor point moves with an unknown or with a known parameter given a tolerance.
    """
    from cappe.estimate._automated_steps import robust_uncertainty
    from cappe.estimate._base import least_squares_fit

    problem = FRFRefinementProblem(model, space, measured, reference)
    tolerance = dict(known_tolerance or {})
    problem.refuse_moving_sensors(list(tolerance), "known parameters given a tolerance")
    p0 = np.clip(np.asarray(start, dtype=float), space.lower, space.upper)
    r0 = problem.residuals(p0)
    fitted = least_squares_fit(method, space, problem.residuals, problem.jacobian, starts=p0[None, :],
                               diagnostics={"residual": "complex log (log-magnitude and phase)",
                                            "weighting": problem.noise})
    est = fitted.estimate
    values = np.asarray(est.values, dtype=float)
    if not np.all(np.isfinite(values)):
        msg = "the FRF refinement ended at a non-finite estimate"
        raise ModelError(msg)
    r = problem.residuals(values)
    est = robust_uncertainty(
        est, problem.jacobian(values), r, problem.groups(),
        clusters=f"blocks of {CLUSTER_LINES} fitted lines at one position (all channels)", known_tolerance=tolerance,
        known_jacobian=problem.jacobian(values, list(tolerance)) if tolerance else None,
        known_values=space.base[[model.parameter_names.index(n) for n in tolerance]])
    cost = float(r @ r)
    dof = max(r.size - space.n, 1)
    chi2 = cost / dof
    warns: list[str] = []
    if chi2 > RESIDUAL_LEVEL:
        warns.append(f"the FRF residuals' mean square is {chi2:.3g} times the data's own noise ({problem.noise}): "
                     "the model does not explain the measured FRFs down to their noise; intervals are widened by "
                     "the sandwich but the estimates may be biased")
    at_bound = list(est.diagnostics.get("at_bound", []))
    if at_bound:
        warns.append(f"FRF refinement: estimates at a bound: {at_bound}; the FRFs or the bounds do not determine them")
    diag = {**est.diagnostics, "frf_fit": {"chi2_dof": chi2, "residuals": int(r.size)}}
    est = replace(est, diagnostics=diag)
    return FRFRefinement(est, p0, values, float(r0 @ r0), cost, int(r.size), problem.noise, chi2,
                         problem.summary(), tuple(warns), fitted.cost)
