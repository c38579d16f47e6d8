"""The monitoring chain of thesis Fig. 1.1 for one machine: measurement -> features -> parameters -> detection ->
diagnosis -> severity, and its bookkeeping in the history store.

:class:`Monitor` holds the compiled model and the estimators of a :class:`MonitorConfig`; it is stateless
between measurements (the detector state travels through the store). Per measurement:

1. **Pre-processing.** Time data become H1 FRFs of the configured channels (:func:`cappe.identify.estimate_frf`);
   FRFs are used as they are. A machine with ``excitation="operational"`` takes output-only time data instead:
   SSI-COV modes (:func:`cappe.identify.ssi_cov`) paired with the model's, and in step 3 the factors are fitted
   to their frequencies and unscaled shapes (:class:`ModalFactorEstimator`); its limits are
   :data:`OUTPUT_ONLY_LIMITATIONS`.
2. **Features.** Modal frequency and damping of every mode in the band (:func:`modal_features`), FRAC and CSF
   against the healthy mean FRF (:func:`frf_features`).
3. **Parameters.** Fast path on every measurement: the component stiffness factors by the FRF fit of
   :class:`FactorEstimator` (milliseconds to a few tenths of a second). Slow path every ``slow_every``
   measurements and after every alarm: every stiffness parameter of every component freed on its own, started
   from the fast path (the full estimation).
4. **Detection.** Deviations of the log-factors from the baseline's expectation at the measurement's operating
   conditions, standardized by the healthy scatter and the estimate's own uncertainty, feed the CUSUM or EWMA
   charts (:class:`SequentialDetector`).
5. **Diagnosis.** A chart beyond its limit starts a diagnosis of the change since the chart's change point
   among the single-fault hypotheses: every component, and every fault parameter (``preload``) through its
   signature in the factors (:func:`diagnose`).
6. **Severity.** The diagnosed change is graded. An alarm is raised once per diagnosed fault and again only
   when its grade worsens (a loosening screw goes from conditionally tolerable to intolerable); it clears when
   the charts of the components involved come back to their healthy state. A grade worsens with hysteresis: only
   when the change is beyond the worse grade's threshold by :data:`ESCALATION_Z` standard uncertainties, so a
   constant fault near a threshold does not raise "worse" alarms on noise.
"""

from __future__ import annotations

import hashlib
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linear_sum_assignment

from cappe.exceptions import DataError
from cappe.model import NumericModel, load_model
from cappe.monitor._baseline import (
    LEARNED_MARGIN,
    RATE_PREFIX,
    SIZE_SCALE_FLOOR,
    Baseline,
    condition_rates,
    learn_baseline,
    twin_size_errors,
    with_rates,
)
from cappe.monitor._config import MonitorConfig, severity_rank, worst_severity
from cappe.monitor._detection import ChartSignal, SequentialDetector
from cappe.monitor._diagnosis import Diagnosis, FaultHypothesis, diagnose
from cappe.monitor._estimation import FactorEstimate, FactorEstimator, ModalFactorEstimator
from cappe.monitor._features import PAIRING_TOLERANCE, frf_features, modal_features
from cappe.systems.frf import FRFData
from cappe.systems.timedata import TimeData

__all__ = ["OUTPUT_ONLY_LIMITATIONS", "Alarm", "Analysis", "IngestResult", "Monitor", "RecordedFiles",
           "detectable_change", "file_digest", "forecast_fault",
           "ingest", "learn_store_baseline", "register_machine"]

Array = NDArray[np.float64]

#: Modes of the frequency-damping map kept with the baseline (thesis Fig. 5.30 shows the first ones).
MAP_MODES = (1, 2, 3)

#: Standard uncertainties by which a change must pass a worse grade's threshold before the alarm escalates.
ESCALATION_Z = 3.0

#: What output-only records cannot tell, said wherever such a machine's results are shown.
OUTPUT_ONLY_LIMITATIONS = (
    "output-only (operational) records: the stiffness factors come from natural frequencies and unscaled mode "
    "shapes (SSI-COV), relative to the model's masses; without a measured force the modal masses are unknown, so a "
    "mass change cannot be told from a stiffness change (all stiffnesses rising together looks like all masses "
    "falling); FRF levels, FRAC/CSF and damping are not monitored, and the slow path (every stiffness on its own) "
    "does not run")

#: Units of the operating conditions cappe knows (an offset in degC is one in K); others are shown without one.
_CONDITION_UNITS = {"temperature": "K"}


@dataclass(frozen=True)
class Analysis:
    """Features and parameter estimates of one measurement (steps 1-3).

    Attributes
    ----------
    estimate : FactorEstimate
        Fast path: the component factors.
    frequency, damping : ndarray, shape (m,)
        Modal features of the model's modes in the band (NaN: not found).
    frac, csf : float or None
        FRF correlation with the healthy mean FRF (None before a baseline exists).
    slow : FactorEstimate or None
        Slow path, when it ran.
    notes : tuple of str
        What went wrong on the way, for the record.
    """

    estimate: FactorEstimate
    frequency: Array
    damping: Array
    frac: float | None = None
    csf: float | None = None
    slow: FactorEstimate | None = None
    notes: tuple[str, ...] = ()

    def features(self) -> dict[str, tuple[float, float | None]]:
        """Scalar features as the history store keeps them: name -> (value, std)."""
        out: dict[str, tuple[float, float | None]] = {}
        for k, (f, z) in enumerate(zip(self.frequency, self.damping, strict=True), start=1):
            if np.isfinite(f):
                out[f"freq_{k}"] = (float(f), None)
                out[f"zeta_{k}"] = (float(z), None)
        if self.frac is not None:
            out["frac"] = (self.frac, None)
        if self.csf is not None:
            out["csf"] = (self.csf, None)
        return out

    def feature_values(self) -> dict[str, float]:
        return {k: v for k, (v, _) in self.features().items()}


@dataclass(frozen=True)
class Alarm:
    """A raised alarm (steps 4-6).

    Attributes
    ----------
    component : str
        The diagnosed fault hypothesis (a component or a fault parameter such as ``preload``).
    statistic : str
        The chart that signalled, e.g. ``"cusum+"``.
    value : float
        Its statistic (dimensionless, in the chart's standard deviations).
    severity : str
        Grade of the diagnosed change (:data:`SEVERITY_GRADES`).
    diagnosis : Diagnosis
        The diagnosis behind the alarm.
    message : str
        The alarm text.
    """

    component: str
    statistic: str
    value: float
    severity: str
    diagnosis: Diagnosis
    message: str

    def to_dict(self) -> dict[str, Any]:
        return {"component": self.component, "statistic": self.statistic, "value": self.value,
                "severity": self.severity, "diagnosis": self.diagnosis.to_dict(), "message": self.message}


@dataclass(frozen=True)
class IngestResult:
    """What :func:`ingest` recorded for one measurement.

    Attributes
    ----------
    measurement_id : int
        Id of the measurement in the history store.
    analysis : Analysis
        Its features and estimates.
    deviation : ndarray, shape (n,), or None
        Log-factor deviations from the baseline (None before a baseline exists).
    alarms : tuple of Alarm
        The alarms raised by this measurement.
    active : dict
        ``{fault: severity}`` of the faults active after it.
    not_judged : tuple of str
        Why the measurement was recorded but not judged against the baseline (empty: it was judged, or no
        baseline exists yet).
    notes : tuple of str
        What to know about its judgement (a condition slightly outside the learned range, a rate of change not
        known, a fit that did not succeed).
    """

    measurement_id: int
    analysis: Analysis
    deviation: Array | None
    alarms: tuple[Alarm, ...]
    active: dict[str, str] = field(default_factory=dict)
    not_judged: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        names = self.analysis.estimate.names
        return {
            "measurement_id": self.measurement_id,
            "factors": dict(zip(names, self.analysis.estimate.factor.tolist(), strict=True)),
            "std": dict(zip(names, self.analysis.estimate.std.tolist(), strict=True)),
            "deviation": None if self.deviation is None else dict(zip(names, self.deviation.tolist(), strict=True)),
            "features": self.analysis.feature_values(),
            "alarms": [a.to_dict() for a in self.alarms],
            "active": dict(self.active),
            "notes": [*self.analysis.notes, *self.notes],
            "judged": not self.not_judged,
            "not_judged": list(self.not_judged),
        }


class Monitor:
    """The monitoring chain of one machine (see the module notes).

    Parameters
    ----------
    config : MonitorConfig
    model : NumericModel, optional
        The compiled model of ``config.model`` (compiled here when not given).
    """

    def __init__(self, config: MonitorConfig, model: NumericModel | None = None) -> None:
        self.config = config
        self.model = model if model is not None else NumericModel(load_model(config.model))
        config.check_model(self.model)
        self.estimator = self._estimator({c.name: c.parameters for c in config.components})
        self._slow_groups = [(c.name, p) for c in config.components for p in c.parameters]
        self.slow_estimator = self._estimator({p: [p] for _, p in self._slow_groups})
        modes = self.model.system(self.model.vector(dict(config.params)), config.position).modes("exact")
        inside = (modes.frequency >= config.band[0]) & (modes.frequency <= config.band[1])
        self.mode_numbers = tuple(int(k) + 1 for k in np.flatnonzero(inside))
        self._hypotheses: list[FaultHypothesis] | None = None
        self.operational = config.excitation == "operational"
        self.modal_estimator = ModalFactorEstimator(self.estimator) if self.operational else None

    def limitations(self) -> list[str]:
        """What this machine's measurements cannot tell (said in the text output of the CLI).

        Returns
        -------
        list of str
            One sentence each; empty for measured excitation.
        """
        return [OUTPUT_ONLY_LIMITATIONS] if self.operational else []

    def _estimator(self, groups: Mapping[str, Sequence[str]]) -> FactorEstimator:
        c = self.config
        return FactorEstimator(self.model, groups, reference=c.params, position=c.position, inputs=c.inputs,
                               outputs=c.outputs, band=c.band, noise_floor=c.noise_floor)

    # -- steps 1-3 -----------------------------------------------------------------------------------------
    def prepare(self, data: FRFData | TimeData, *, nperseg: int | None = None) -> FRFData:
        """Pre-processing: time data to H1 FRFs of the configured channels; FRFs pass unchanged.

        Parameters
        ----------
        data : FRFData or TimeData
            One measurement (SI units).
        nperseg : int, optional
            Samples per Welch segment (default: :func:`cappe.identify.estimate_frf`'s).

        Returns
        -------
        FRFData
        """
        if self.operational:
            msg = (f"machine '{self.config.machine}' is monitored output-only (excitation 'operational'): its "
                   f"records are not turned into FRFs")
            raise DataError(msg)
        if isinstance(data, FRFData):
            return data
        missing = [c for c in self.config.inputs if c not in data.channels]
        if missing:
            msg = (f"time data lack the force channel(s) {missing} of machine '{self.config.machine}'; records of "
                   f"operation without a measured force need a machine registered for them "
                   f"(`cappe monitor init ... --excitation operational`)")
            raise DataError(msg)
        from cappe.identify import estimate_frf

        _, hi = self.config.band
        return estimate_frf(data, inputs=list(self.config.inputs), outputs=list(self.config.outputs),
                            nperseg=nperseg, band=(0.0, min(hi * 1.2, data.fs / 2)))

    def expected_modes(self, log_factor: Array) -> Array:
        """Natural frequencies (Hz) of the monitored modes of the model at these component factors.

        Parameters
        ----------
        log_factor : ndarray, shape (n,)
            ``ln`` of each component's stiffness factor.

        Returns
        -------
        ndarray, shape (n_monitored_modes,)
            In Hz.
        """
        p = self.estimator.parameters(log_factor)
        freq = self.model.system(p, self.config.position).modes("exact").frequency
        return np.asarray(freq[[k - 1 for k in self.mode_numbers]], dtype=float)

    def analyse(
        self,
        data: FRFData | TimeData,
        *,
        baseline: Baseline | None = None,
        start: ArrayLike | None = None,
        slow: bool = False,
        modal: bool = True,
    ) -> Analysis:
        """Steps 1-3 for one measurement: features and the component factors (and the slow path if asked).

        Parameters
        ----------
        data : FRFData or TimeData
            One measurement.
        baseline : Baseline, optional
            The healthy baseline: its mean FRF gives FRAC and CSF, its fits' residual the misfit check.
        start : array_like, shape (n,), optional
            Start log-factors of the fit (default the baseline's constant term, else 0).
        slow : bool
            Also run the slow path.
        modal : bool
            Also extract the modal features.

        Returns
        -------
        Analysis
        """
        if start is None and baseline is not None:
            start = baseline.coefficients[0]
        if self.operational:
            return self._analyse_operational(data, start)
        with warnings.catch_warnings(record=True) as caught:  # low coherence etc.: kept with the record
            warnings.simplefilter("always")
            frf = self.prepare(data)
        notes = [f"pre-processing: {w.message}" for w in caught]
        # before a baseline exists the measurements are the healthy reference: no misfit check; afterwards a
        # fit is judged against the healthy fits' residual, which includes the model's error for this machine
        check = {"misfit_ratio": None} if baseline is None else {"misfit_level": baseline.sigma}
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            estimate = self.estimator.estimate(frf, start, **check)
        notes += [f"fast path: {w.message}" for w in caught]
        freq = np.full(len(self.mode_numbers), np.nan)
        damp = np.full(len(self.mode_numbers), np.nan)
        if modal:
            freq, damp, modal_notes = modal_features(frf, band=self.config.band,
                                                     expected=self.expected_modes(estimate.log_factor),
                                                     max_order=self.config.max_order)
            notes.extend(modal_notes)
        frac_value = csf_value = None
        healthy = baseline.frf_data() if baseline is not None else None
        if healthy is not None:
            try:
                frac_value, csf_value = frf_features(frf, healthy)
            except DataError as exc:
                notes.append(f"FRF features: {exc}")
        slow_estimate = self.slow_path(frf, estimate) if slow else None
        return Analysis(estimate, freq, damp, frac_value, csf_value, slow_estimate, tuple(notes))

    def operational_modes(self, data: FRFData | TimeData) -> tuple[Array, Array, NDArray[np.complex128], list[str]]:
        """Output-only modes of a record (SSI-COV), paired with the monitored modes of the model.

        Parameters
        ----------
        data : TimeData
            Responses at the configured outputs, recorded in operation.

        Returns
        -------
        frequency, damping : ndarray, shape (m,)
            Of each monitored mode (NaN: not found).
        shapes : ndarray of complex, shape (n_out, m)
            At the outputs, unit norm (NaN: not found).
        notes : list of str
            Why modes are missing.

        Raises
        ------
        DataError
            The data are FRFs or lack an output channel.
        """
        from cappe.identify import ssi_cov

        if not isinstance(data, TimeData):
            msg = (f"machine '{self.config.machine}' is monitored output-only: its records are time data of the "
                   f"outputs {list(self.config.outputs)}, not FRFs")
            raise DataError(msg)
        missing = [c for c in self.config.outputs if c not in data.channels]
        if missing:
            msg = (f"time data lack the output channel(s) {missing} of machine '{self.config.machine}'; channels: "
                   f"{list(data.channels)}")
            raise DataError(msg)
        target = self.expected_modes(np.zeros(len(self.estimator.names)))
        n_out = len(self.config.outputs)
        freq = np.full(target.size, np.nan)
        zeta = np.full(target.size, np.nan)
        shapes = np.full((n_out, target.size), np.nan, dtype=complex)
        orders, block_rows, capped = self.ssi_settings(target.size, data.fs)
        notes = [f"output-only modal analysis: model orders stop at {orders[-1]}, what {block_rows} block rows x "
                 f"{n_out} outputs allow"] if capped else []
        criteria: dict[str, Any] = dict(self.config.ssi_stability)  # ssi_cov's defaults for the others
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                found = ssi_cov(data, outputs=list(self.config.outputs), band=self.config.band, orders=orders,
                                block_rows=block_rows, **criteria)
            except DataError as exc:
                return freq, zeta, shapes, [*notes, f"output-only modal analysis failed: {exc}"]
        notes += [f"output-only modal analysis: {w.message}" for w in caught]
        if found.n_modes and target.size:
            cost = np.abs(np.log(found.frequency[:, None] / target[None, :]))
            rows, cols = linear_sum_assignment(cost)
            for r, c in zip(rows, cols, strict=True):
                if cost[r, c] <= PAIRING_TOLERANCE:
                    freq[c], zeta[c], shapes[:, c] = found.frequency[r], found.damping[r], found.shapes[:, r]
        missing_modes = [k for k, f in zip(self.mode_numbers, freq, strict=True) if not np.isfinite(f)]
        if missing_modes:
            notes.append(f"modes {missing_modes} not found in the record")
        return freq, zeta, shapes, notes

    def ssi_settings(self, n_modes: int, fs: float) -> tuple[list[int], int, bool]:
        """Model orders and block rows of the SSI-COV of a record: the config's, else derived from the modes.

        Parameters
        ----------
        n_modes : int
            Monitored modes in the band.
        fs : float
            Sampling rate of the record in Hz.

        Returns
        -------
        orders : list of int
            Model orders of the stabilization diagram, ascending.
        block_rows : int
            Block rows of the Toeplitz matrix.
        capped : bool
            Whether automatic orders were cut to what configured block rows allow.
        """
        n_out = len(self.config.outputs)
        if self.config.ssi_orders is not None:
            lo, hi, step = self.config.ssi_orders
            orders = list(range(lo, hi + 1, step))
        else:
            top = 4 * ((2 * n_modes + 8 + 3) // 4)  # twice the modes in the band and room for noise poles
            orders = list(range(4, top + 1, 4))
        if self.config.ssi_block_rows is not None:
            block_rows = self.config.ssi_block_rows
            allowed = [n for n in orders if n <= n_out * block_rows]
            capped = len(allowed) < len(orders)
            return (allowed or [2]), block_rows, capped
        block_rows = max(int(np.ceil(fs / max(self.config.band[0], 1.0))), orders[-1] // n_out + 1)
        return orders, block_rows, False

    def _analyse_operational(self, data: FRFData | TimeData, start: ArrayLike | None) -> Analysis:
        """Steps 1-3 on an output-only record: SSI-COV modes, then the factors from frequencies and shapes."""
        assert self.modal_estimator is not None
        freq, zeta, shapes, notes = self.operational_modes(data)
        ok = np.isfinite(freq)
        if not np.any(ok):
            msg = f"no monitored mode found in the record: {'; '.join(notes)}"
            raise DataError(msg)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            estimate = self.modal_estimator.estimate(freq[ok], zeta[ok], shapes[:, ok], start)
        notes += [f"fast path: {w.message}" for w in caught]
        return Analysis(estimate, freq, zeta, None, None, None, tuple(notes))

    def slow_path(self, frf: FRFData, fast: FactorEstimate) -> FactorEstimate:
        """The full estimation: every stiffness parameter of every component on its own, from the fast path.

        Parameters
        ----------
        frf : FRFData
            The measurement's FRFs.
        fast : FactorEstimate
            The fast path's estimate (the start).

        Returns
        -------
        FactorEstimate
            One log-factor per stiffness parameter.
        """
        index = {name: k for k, name in enumerate(fast.names)}
        start = np.array([fast.log_factor[index[comp]] for comp, _ in self._slow_groups])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a weakly identifiable single parameter is reported, not raised
            return self.slow_estimator.estimate(frf, start)

    # -- baseline ------------------------------------------------------------------------------------------
    def learn_baseline(
        self,
        analyses: Sequence[Analysis],
        *,
        conditions: Sequence[Mapping[str, float]] | None = None,
        frfs: Sequence[FRFData] | None = None,
        resolution: float | None = None,
        measurement_ids: Sequence[int] = (),
        timestamps: Sequence[datetime] | None = None,
    ) -> Baseline:
        """A :class:`Baseline` from healthy analyses, with the mean FRF and the preload map for the dashboard.

        Parameters
        ----------
        analyses : sequence of Analysis
            Analyses of healthy measurements.
        conditions : sequence of mapping, optional
            Operating conditions of each measurement (the expectation is quadratic in them, and may take a linear
            term in their rates of change: see ``timestamps``).
        frfs : sequence of FRFData, optional
            The measurements' FRFs, for the mean healthy FRF.
        resolution : float, optional
            Smallest relative change treated as real (0.005 = 0.5 %; default derived from the healthy data,
            :func:`~cappe.monitor._baseline.derived_resolution`).
        measurement_ids : sequence of int
            Their ids in a history store.
        timestamps : sequence of datetime, optional
            When each was taken: the rates of change of the conditions from one measurement to the next
            (:func:`~cappe.monitor._baseline.with_rates`) become candidate terms of the expectation. Without them
            conditions that already carry their rates (``rate:<name>``) are used as given.

        Returns
        -------
        Baseline

        Raises
        ------
        DataError
            ``analyses`` is empty, or ``timestamps`` is not one per analysis.
        """
        if not analyses:
            msg = f"machine '{self.config.machine}': a baseline needs healthy measurements; got none"
            raise DataError(msg)
        if timestamps is not None:
            if len(timestamps) != len(analyses):
                msg = (f"machine '{self.config.machine}': {len(analyses)} analyses but {len(timestamps)} "
                       "timestamps")
                raise DataError(msg)
            conditions = with_rates(conditions if conditions is not None else [{}] * len(analyses), timestamps)
        return self._learn(np.array([a.estimate.log_factor for a in analyses]),
                           features=[a.feature_values() for a in analyses], conditions=conditions, frfs=frfs,
                           resolution=resolution, measurement_ids=measurement_ids,
                           sigma=float(np.median([a.estimate.sigma for a in analyses])))

    def _learn(
        self,
        log_factors: Array,
        *,
        features: Sequence[Mapping[str, float]],
        conditions: Sequence[Mapping[str, float]] | None,
        frfs: Sequence[FRFData] | None,
        resolution: float | None,
        measurement_ids: Sequence[int],
        sigma: float | None,
    ) -> Baseline:
        """:func:`learn_baseline` with what the machine adds: its component names, the mean FRF on its band and
        channels, the preload map and the size errors of its twin (:meth:`size_errors`)."""
        banded = [self._band(f) for f in frfs] if frfs else None
        return learn_baseline(
            log_factors,
            names=self.estimator.names,
            conditions=conditions,
            frfs=banded,
            features=features,
            resolution=resolution,
            measurement_ids=measurement_ids,
            preload_map=self._preload_map(),
            sigma=sigma,
            size_error=self.size_errors(banded) if banded and not self.operational else None,
        )

    def size_errors(self, frfs: Sequence[FRFData]) -> Array | None:
        """Relative errors of the read component changes on the machine's twin: the model with the component
        factors and one factor of all its other dampings fitted to these healthy FRFs
        (:func:`~cappe.monitor._baseline.twin_size_errors`).

        Parameters
        ----------
        frfs : sequence of FRFData
            Healthy FRFs holding the configured channels.

        Returns
        -------
        ndarray, shape (n, n) or None
            ``[i, j]``: error of component ``i``'s read change as a fraction of a loss of component ``j``; None
            where the model has no damping parameter outside the components (nothing for the twin to fit).
        """
        grouped = {p for c in self.config.components for p in c.parameters}
        damping = [p.name for p in self.model.structure.parameters
                   if p.kind in ("damping", "loss") and p.name not in grouped]
        if not damping:
            return None
        groups = {c.name: list(c.parameters) for c in self.config.components}
        return twin_size_errors(self.estimator, self._estimator({**groups, "damping (twin)": damping}), frfs)

    def _band(self, frf: FRFData) -> FRFData:
        freq, h = self.estimator.select(frf)
        return FRFData(freq, h, self.config.inputs, self.config.outputs)

    def _preload_map(self) -> dict[str, Any] | None:
        if "preload" not in self.config.fault_parameters:
            return None
        from cappe.monitor._preload import THESIS_PRELOADS, preload_map

        modes = tuple(m for m in MAP_MODES if m <= self.model.n_dof)
        result = preload_map(self.model, THESIS_PRELOADS, modes, params=dict(self.config.params),
                             position=self.config.position)
        return {"parameter": "preload", **result.to_dict()}

    # -- steps 4-6 -----------------------------------------------------------------------------------------
    def hypotheses(self) -> list[FaultHypothesis]:
        """One hypothesis per component and per fault parameter (its signature in the factors)."""
        if self._hypotheses is None:
            names = self.estimator.names
            hyps = []
            for k, comp in enumerate(self.config.components):
                direction = np.zeros(len(names))
                direction[k] = 1.0
                hyps.append(FaultHypothesis(comp.name, comp.label, direction, self.config.thresholds(comp.name),
                                            (comp.name,)))
            for name in self.config.fault_parameters:
                direction = self.estimator.direction(name)
                moved = tuple(n for n, d in zip(names, direction, strict=True)
                              if abs(d) >= 0.1 * np.max(np.abs(direction)))
                hyps.append(FaultHypothesis(name, f"bearing {name}" if name == "preload" else name, direction,
                                            self.config.thresholds(name), moved))
            self._hypotheses = hyps
        return self._hypotheses

    def sensor_hypotheses(self, baseline: Baseline, conditions: Mapping[str, float] | None) -> list[FaultHypothesis]:
        """One hypothesis per operating condition the baseline depends on: its sensor reads off by a constant.

        A reading ``a`` too high makes the expectation that of a condition ``a`` higher, so the deviation moves by
        ``-a`` times the baseline's gradient; offsets that would put the true condition outside the learned range
        (with :data:`LEARNED_MARGIN`) are not considered.

        Parameters
        ----------
        baseline : Baseline
            The healthy baseline.
        conditions : mapping name -> float or None
            The measurement's operating conditions (every one the baseline depends on).

        Returns
        -------
        list of FaultHypothesis
            Named ``<condition>_sensor``; empty for a baseline without conditions.
        """
        if not baseline.conditions:
            return []
        gradient = baseline.gradient(conditions)
        names = self.estimator.names
        hyps = []
        for k, cond in enumerate(baseline.conditions):
            direction = -gradient[k]
            if not np.any(direction):
                continue
            reading = float((conditions or {})[cond])
            margin = (1 + LEARNED_MARGIN) * float(baseline.spread[k])
            bounds = (reading - float(baseline.center[k]) - margin, reading - float(baseline.center[k]) + margin)
            moved = tuple(n for n, d in zip(names, direction, strict=True)
                          if abs(d) >= 0.1 * np.max(np.abs(direction)))
            hyps.append(FaultHypothesis(f"{cond}_sensor", f"{cond} sensor reading off", direction,
                                        self.config.thresholds(cond), moved, unit=_CONDITION_UNITS.get(cond, ""),
                                        bounds=bounds))
        return hyps

    def detector(self, baseline: Baseline) -> SequentialDetector:
        """The charts of the configuration, standardized by the baseline's scatter.

        Parameters
        ----------
        baseline : Baseline
            The healthy baseline of this machine's components.

        Returns
        -------
        SequentialDetector

        Raises
        ------
        DataError
            The baseline's components are not the machine's.
        """
        if tuple(baseline.names) != self.estimator.names:
            msg = (f"baseline components {list(baseline.names)} differ from the machine's "
                   f"{list(self.estimator.names)}; learn a new baseline")
            raise DataError(msg)
        return SequentialDetector(self.estimator.names, baseline.scale, method=self.config.detection,
                                  false_alarm_rate=self.config.false_alarm_rate, shift=self.config.shift,
                                  lam=self.config.ewma_lambda)

    def step(
        self,
        state: Mapping[str, Any] | None,
        analysis: Analysis,
        conditions: Mapping[str, float] | None,
        baseline: Baseline,
        *,
        timestamp: datetime | None = None,
    ) -> tuple[dict[str, Any], Array, list[Alarm]]:
        """Steps 4-6: update the charts, diagnose and grade what they signal, apply the alarm policy.

        Returns the new state (JSON-ready), the deviation of the log-factors and the alarms to raise.

        The rates of change of the conditions (for a baseline that uses them) are taken as ``conditions`` give them
        (``rate:<name>``, as :func:`ingest` adds them from the history store) or, with ``timestamp``, from the
        previous measurement the state remembers (:func:`~cappe.monitor._baseline.condition_rates`). A rate that
        is unknown widens the measurement's uncertainty by the rate term's scatter (:meth:`Baseline.rate_std`).

        Parameters
        ----------
        state : mapping or None
            The state after the previous measurement (None, or one of another baseline: start afresh).
        analysis : Analysis
            This measurement's analysis.
        conditions : mapping name -> float or None
            Its operating conditions.
        baseline : Baseline
            The healthy baseline.
        timestamp : datetime, optional
            When the measurement was taken (keeps it in the state for the next one's rates).

        Returns
        -------
        state : dict
            The new state.
        deviation : ndarray, shape (n,)
            Log-factor deviations from the expectation.
        alarms : list of Alarm
        """
        detector = self.detector(baseline)
        previous = None if state is None else state.get("previous")
        if state is None or state.get("baseline") != baseline.created:
            state = {"baseline": baseline.created, "detector": None, "active": {}, "count": 0}
        given = {k: float(v) for k, v in (conditions or {}).items()}
        if timestamp is not None:
            if previous is not None and not any(k.startswith(RATE_PREFIX) for k in given):
                given.update(condition_rates(given, timestamp, (datetime.fromisoformat(previous["timestamp"]),
                                                                previous["conditions"])))
            previous = {"timestamp": timestamp.isoformat(),
                        "conditions": {k: v for k, v in given.items() if not k.startswith(RATE_PREFIX)}}
        conditions = given
        deviation = baseline.deviation(analysis.estimate.log_factor, conditions)
        log_std = np.hypot(np.sqrt(np.clip(np.diag(analysis.estimate.covariance), 0.0, None)),
                           baseline.rate_std(conditions))
        chart_state, signals = detector.update(state["detector"], deviation, log_std)
        active: dict[str, str] = dict(state["active"])
        hyps = {h.name: h for h in [*self.hypotheses(), *self.sensor_hypotheses(baseline, conditions)]}
        # clear faults whose components have all come back
        for name in list(active):
            if all(detector.in_control(chart_state, c) for c in hyps[name].components):
                del active[name]
        best: dict[str, tuple[ChartSignal, Diagnosis]] = {}
        for signal in signals:
            # which fault: from the mean change since the change point (averages the noise of the run); how
            # large: from this measurement's deviation along that fault (a drifting fault has grown since)
            chosen = diagnose(signal.change, baseline.size_covariance(signal.change, signal.change_weight),
                              list(hyps.values()))
            # (a rate this measurement does not know adds the rate term's scatter to its deviation)
            unknown = np.diag(baseline.rate_std(conditions) ** 2)
            now = diagnose(deviation, baseline.size_covariance(deviation) + unknown, [hyps[chosen.hypothesis]])
            diagnosis = replace(chosen, change=now.change, change_std=now.change_std, severity=now.severity)
            held = best.get(diagnosis.hypothesis)
            if held is None or signal.statistic > held[0].statistic:
                best[diagnosis.hypothesis] = (signal, diagnosis)
        alarms = []
        for name, (signal, diagnosis) in best.items():
            # a change the data cannot attribute is graded as its worst explanation (a preload loss or a sensor)
            grade = worst_severity([diagnosis.severity, *(a["severity"] for a in diagnosis.alternatives)])
            assert grade is not None
            escalated = name in active
            if escalated:  # hysteresis: worse only when the change is beyond the threshold, not on noise
                if hyps[name].unit is None:
                    grade = hyps[name].thresholds.grade(
                        _toward_zero(diagnosis.change, ESCALATION_Z * diagnosis.change_std))
            if severity_rank(grade) <= severity_rank(active.get(name)):
                continue
            active[name] = grade
            statistic = f"{detector.method}{signal.side}"
            what = "worse" if escalated else "detected"
            message = (f"{what}: {diagnosis.text()}; {statistic} chart of '{signal.name}' at "
                       f"{signal.statistic:.3g} > {signal.limit:.3g}"
                       + (f" after {signal.run} measurement(s)" if signal.run else ""))
            alarms.append(Alarm(name, statistic, signal.statistic, grade, diagnosis, message))
        new_state = {"baseline": baseline.created, "detector": chart_state, "active": active,
                     "count": int(state["count"]) + 1}
        if previous is not None:
            new_state["previous"] = previous
        return new_state, deviation, alarms


def _toward_zero(value: float, margin: float) -> float:
    """``value`` moved ``margin`` toward zero (not past it)."""
    return float(np.sign(value) * max(abs(value) - margin, 0.0))


# -- the history store ----------------------------------------------------------------------------------------
def register_machine(store: Any, config: MonitorConfig, *, replace: bool = False) -> None:
    """Record a machine's config in a history store (checked against its model first).

    Parameters
    ----------
    store : HistoryStore
        The history store.
    config : MonitorConfig
        The machine's configuration.
    replace : bool
        Replace the config of a machine already registered (else that is an error).

    Raises
    ------
    DataError
        The config does not fit its model, or the machine is registered already and ``replace`` is False.
    """
    Monitor(config)  # compiles the model and checks every name
    store.add_machine(config.machine, config.to_dict(), replace=replace)


def _monitor_for(store: Any, machine: str, monitor: Monitor | None) -> Monitor:
    if monitor is not None:
        if monitor.config.machine != machine:
            msg = f"the monitor is for machine '{monitor.config.machine}', not '{machine}'"
            raise DataError(msg)
        return monitor
    return Monitor(MonitorConfig.from_dict(store.machine_config(machine)))


def ingest(
    store: Any,
    machine: str,
    data: FRFData | TimeData,
    *,
    timestamp: datetime,
    source: str,
    conditions: Mapping[str, float] | None = None,
    monitor: Monitor | None = None,
    keep_frf: bool = True,
    digest: str | None = None,
) -> IngestResult:
    """Run the chain on one measurement and record everything in one transaction.

    Every readable measurement is recorded. One whose operating conditions do not let it be judged against the
    baseline (:meth:`Baseline.judge`: a condition missing or under another name, not a number, outside the
    learned range, implausible) is recorded with its estimates but not judged: the charts skip it, and
    ``IngestResult.not_judged`` and the record's meta say why. Conditions that are not finite numbers are kept
    in the meta, not with the conditions.

    The rates of change of the conditions are taken from the machine's previous recorded measurement (the latest
    one before ``timestamp``; :func:`~cappe.monitor._baseline.condition_rates`) and kept in the meta as
    ``rates``; where there is none within :data:`~cappe.monitor._baseline.RATE_GAP` the measurement is judged
    without them and a note says so (:meth:`Baseline.judge`).

    The heavy steps (features, estimation) run before the transaction; detection, diagnosis and the record run
    inside it, under the store's per-machine lock, so concurrent ingests continue each other's charts. When
    an alarm is raised, or every ``slow_every`` measurements, the slow path runs afterwards and adds its
    estimates to the same measurement.

    Parameters
    ----------
    store : HistoryStore
        The history store.
    machine : str
        A registered machine.
    data : FRFData or TimeData
        The measurement (SI units).
    timestamp : datetime
        When it was taken.
    source : str
        Where it came from (a file name), for the record.
    conditions : mapping name -> float, optional
        Operating conditions (temperature, speed ...).
    monitor : Monitor, optional
        The machine's monitor (built from the stored config when not given).
    keep_frf : bool
        Store the FRF in the band with the measurement.
    digest : str, optional
        Content hash of the measurement file (kept in the meta as ``sha256``: how a re-run recognizes it).

    Returns
    -------
    IngestResult
    """
    mon = _monitor_for(store, machine, monitor)
    baseline_doc = store.baseline(machine)
    baseline = Baseline.from_dict(baseline_doc) if baseline_doc else None
    frf: FRFData | None = None
    if mon.operational:
        analysis = mon.analyse(data, baseline=baseline)
        kind = "operational"
    else:
        with warnings.catch_warnings(record=True) as caught:  # low coherence etc.: kept with the record
            warnings.simplefilter("always")
            frf = mon.prepare(data)
        analysis = mon.analyse(frf, baseline=baseline)
        analysis = replace(analysis, notes=(*(f"pre-processing: {w.message}" for w in caught), *analysis.notes))
        kind = "frf" if isinstance(data, FRFData) else "time"
    names = analysis.estimate.names
    deviation = None
    alarms: list[Alarm] = []
    fit_meta = {"success": analysis.estimate.success, "sigma": analysis.estimate.sigma,
                "iterations": analysis.estimate.iterations}
    given = {str(k): float(v) for k, v in (conditions or {}).items() if not str(k).startswith(RATE_PREFIX)}
    finite = {k: v for k, v in given.items() if np.isfinite(v)}
    # (a timestamp that is not timezone-aware is refused by the record below, with its own message)
    aware = isinstance(timestamp, datetime) and timestamp.utcoffset() is not None
    before = store.measurements(machine, until=timestamp - timedelta(microseconds=1), limit=1) if aware else []
    rates = condition_rates(finite, timestamp, (before[0].timestamp, before[0].conditions) if before else None)
    not_judged, judge_notes = baseline.judge({**given, **rates}) if baseline is not None else ([], [])
    ignored = sorted(str(k) for k in (conditions or {}) if str(k).startswith(RATE_PREFIX))
    if ignored:
        judge_notes.append(f"the condition(s) {ignored} are ignored: '{RATE_PREFIX}' names are cappe's own rates of "
                           "change, taken from the previous measurement")
    meta: dict[str, Any] = {"notes": [*analysis.notes, *judge_notes], "fit": fit_meta}
    if rates:
        meta["rates"] = rates
    # a fit that does not describe the measurement even after its restarts (a local minimum, a sensor mounted the
    # other way round, a fault the model cannot describe): its factors, and a diagnosis from them, may be wrong
    misfit = "" if analysis.estimate.success or baseline is None else (
        f"the stiffness-factor fit did not succeed ({analysis.estimate.message}): its factors and any diagnosis "
        "from them may be wrong")
    if not_judged:
        meta["not_judged"] = not_judged
    if len(finite) < len(given):
        meta["conditions_not_finite"] = {k: str(v) for k, v in given.items() if k not in finite}
    if digest is not None:
        meta["sha256"] = digest
    with store.transaction(machine) as tx:
        state = tx.state()
        mid = tx.add_measurement(timestamp=timestamp, source=source, kind=kind, conditions=finite,
                                 frf=mon._band(frf) if keep_frf and frf is not None else None, meta=meta)
        tx.add_features(mid, analysis.features())
        tx.add_estimates(mid, path="fast", values=dict(zip(names, analysis.estimate.factor.tolist(), strict=True)),
                         std=dict(zip(names, analysis.estimate.std.tolist(), strict=True)))
        if baseline is not None and not not_judged:
            state, deviation, alarms = mon.step(state, analysis, {**given, **rates}, baseline)
            if misfit:  # the alarm itself says it, where `monitor alarms` shows it later
                alarms = [replace(a, message=f"{a.message}; {misfit}") for a in alarms]
            # the change from the healthy expectation at these conditions, for people and the dashboard
            tx.add_estimates(mid, path="deviation", values=dict(zip(names, np.expm1(deviation).tolist(), strict=True)),
                             std=dict(zip(names, baseline.scale.tolist(), strict=True)))
            for alarm in alarms:
                tx.add_alarm(mid, component=alarm.component, statistic=alarm.statistic, value=alarm.value,
                             severity=alarm.severity, diagnosis=alarm.diagnosis.to_dict(), message=alarm.message)
            tx.set_state(state)
        count = int((state or {}).get("count", 0))
    every = mon.config.slow_every
    if frf is not None and (alarms or (every and baseline is not None and not not_judged and count % every == 0)):
        slow = mon.slow_path(frf, analysis.estimate)
        with store.transaction(machine) as tx:
            tx.add_estimates(mid, path="slow", values=dict(zip(slow.names, slow.factor.tolist(), strict=True)),
                             std=dict(zip(slow.names, slow.std.tolist(), strict=True)))
        analysis = replace(analysis, slow=slow)
    return IngestResult(mid, analysis, deviation, tuple(alarms), dict((state or {}).get("active", {})),
                        not_judged=tuple(not_judged), notes=(*judge_notes, *([misfit] if misfit else [])))


def detectable_change(config: MonitorConfig, baseline: Baseline) -> dict[str, Any]:
    """The change of each component the charts are tuned to, and how soon they find it.

    Parameters
    ----------
    config : MonitorConfig
        The machine's configuration (detection method, false-alarm rate, shift).
    baseline : Baseline
        Its healthy baseline (the charts' standard deviations).

    Returns
    -------
    dict
        ``change``: component -> the relative change of ``shift`` chart standard deviations; ``measurements``:
        the average number of measurements to find it; ``resolution``: the baseline's resolution; ``shift``;
        ``size_scale_std``: the relative standard uncertainty of a diagnosed change's size beyond the scatter
        (:attr:`Baseline.size_scale_std`, the largest over the components); ``model_offset``: how far the healthy
        machine is from its model; ``size_scale``: component -> its own size uncertainty measured on the machine's
        twin (:meth:`Baseline.component_scale_std`; None without the twin); ``rate_terms``: component -> the
        conditions whose rate of change its expectation uses (:attr:`Baseline.rate_terms`).
    """
    detector = SequentialDetector(baseline.names, baseline.scale, method=config.detection,
                                  false_alarm_rate=config.false_alarm_rate, shift=config.shift,
                                  lam=config.ewma_lambda)
    design = detector.design()
    return {"change": {n: float(-np.expm1(-config.shift * s)) for n, s in zip(baseline.names, baseline.scale,
                                                                            strict=True)},
            "measurements": float(design["arl_at_shift"]), "resolution": baseline.resolution,
            "shift": config.shift, "size_scale_std": baseline.size_scale_std, "model_offset": baseline.model_offset,
            "size_scale": None if baseline.size_error is None else
            {n: float(v) for n, v in zip(baseline.names, baseline.component_scale_std(), strict=True)},
            "rate_terms": {n: list(v) for n, v in baseline.rate_terms.items()}}


def file_digest(path: str | Path) -> str:
    """SHA-256 of a file's bytes (how a re-run ingest recognizes a file it recorded, whatever its name).

    Parameters
    ----------
    path : str or Path
        The file.

    Returns
    -------
    str
        64 hex digits.

    Raises
    ------
    OSError
        The file cannot be read.
    """
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


class RecordedFiles:
    """The files a machine's measurements were recorded from: by source name and by content hash.

    Parameters
    ----------
    store : HistoryStore
        The history store.
    machine : str
        A registered machine.
    """

    def __init__(self, store: Any, machine: str) -> None:
        self._by_source: dict[str, tuple[int, str | None]] = {}
        self._by_digest: dict[str, tuple[int, str]] = {}
        for r in store.measurements(machine):
            self.add(r.id, r.source, r.meta.get("sha256") if isinstance(r.meta, Mapping) else None)

    def add(self, measurement_id: int, source: str, digest: str | None) -> None:
        """Note a recorded measurement.

        Parameters
        ----------
        measurement_id : int
            Its id in the store.
        source : str
            The file it was recorded from.
        digest : str or None
            The file's content hash (None: not known).
        """
        self._by_source[source] = (measurement_id, digest)
        if digest is not None:
            self._by_digest.setdefault(digest, (measurement_id, source))

    def seen(self, source: str, digest: str) -> str | None:
        """Why a file need not be ingested again (None: it is new).

        Parameters
        ----------
        source : str
            The file's name as it would be recorded.
        digest : str
            Its content hash (:func:`file_digest`).

        Returns
        -------
        str or None

        Raises
        ------
        DataError
            Another file of the same name is recorded already (a source is recorded once per machine).
        """
        if digest in self._by_digest:
            ident, first = self._by_digest[digest]
            return (f"already recorded as measurement {ident}"
                    + ("" if first == source else f" from {first} (the same content)"))
        if source in self._by_source:
            ident, known = self._by_source[source]
            if known is None:
                return f"already recorded as measurement {ident} (recorded before content hashes were kept)"
            msg = (f"a different file of this name is recorded already as measurement {ident} (its content hash "
                   f"differs); rename the new file to record it")
            raise DataError(msg)
        return None


def learn_store_baseline(
    store: Any,
    machine: str,
    *,
    first: int | None = None,
    since: datetime | None = None,
    until: datetime | None = None,
    resolution: float | None = None,
    monitor: Monitor | None = None,
) -> Baseline:
    """Learn the healthy baseline from recorded measurements (the first ``first``, or those in a time range),
    store it, and restart the detector state.

    The rates of change of the conditions are taken from each measurement's predecessor in the store
    (:func:`~cappe.monitor._baseline.with_rates`) and offered to the baseline as terms.

    Parameters
    ----------
    store : HistoryStore
        The history store.
    machine : str
        A registered machine.
    first : int, optional
        Use the first ``first`` measurements in the range.
    since, until : datetime, optional
        Time range of the measurements used (default all).
    resolution : float, optional
        Smallest relative change treated as real (0.005 = 0.5 %; default derived from the healthy data,
        :func:`~cappe.monitor._baseline.derived_resolution`).
    monitor : Monitor, optional
        The machine's monitor (built from the stored config when not given).

    Returns
    -------
    Baseline

    Raises
    ------
    DataError
        No recorded measurement in the range, or their estimates are incomplete.
    """
    mon = _monitor_for(store, machine, monitor)
    records = store.measurements(machine, since=since, until=until)
    if first is not None:
        records = records[:first]
    # a measurement without a condition most others give would drop that condition from the regression: it is
    # left out (and said so), not the condition
    usual = {k for k in {k for r in records for k in r.conditions}
             if 2 * sum(k in r.conditions for r in records) > len(records)}
    left_out = [f"measurement {r.id} ({r.source}) lacks the condition(s) {sorted(usual - set(r.conditions))}"
                for r in records if not usual <= set(r.conditions)]
    records = [r for r in records if usual <= set(r.conditions)]
    if not records:
        msg = f"machine '{machine}' has no recorded measurements in the chosen range to learn a baseline from"
        raise DataError(msg)
    ids = [r.id for r in records]
    table = store.estimates(machine, path="fast")
    table = table[table["measurement_id"].isin(ids)]
    wide = table.pivot(index="measurement_id", columns="parameter", values="value")
    names = list(mon.estimator.names)
    missing = [n for n in names if n not in wide.columns]
    if missing or len(wide) != len(ids):
        msg = f"machine '{machine}': recorded fast-path estimates lack components {missing} or measurements"
        raise DataError(msg)
    log_factors = np.log(wide.loc[ids, names].to_numpy(dtype=float))
    feats = store.features(machine)
    feats = feats[feats["measurement_id"].isin(ids)]
    per_measurement = [dict(zip(g["name"], g["value"], strict=True)) for _, g in feats.groupby("measurement_id")]
    frfs = [f for f in (store.frf(i) for i in ids) if f is not None]
    before = store.measurements(machine, until=records[0].timestamp - timedelta(microseconds=1), limit=1)
    conditions = with_rates([r.conditions for r in records], [r.timestamp for r in records],
                            (before[0].timestamp, before[0].conditions) if before else None)
    baseline = mon._learn(log_factors, features=per_measurement, conditions=conditions,
                          frfs=frfs if len(frfs) == len(ids) else None, resolution=resolution,
                          measurement_ids=ids, sigma=_median_fit_sigma(records))
    baseline = replace(baseline, left_out=tuple(left_out))
    store.set_baseline(machine, baseline.to_dict())
    with store.transaction(machine) as tx:
        tx.set_state({"baseline": baseline.created, "detector": None, "active": {}, "count": 0})
    return baseline


def _median_fit_sigma(records: Sequence[Any]) -> float | None:
    """Median residual of the recorded fast-path fits (kept in each measurement's meta by :func:`ingest`)."""
    values = [float(r.meta["fit"]["sigma"]) for r in records if isinstance(r.meta.get("fit"), Mapping)
              and r.meta["fit"].get("sigma") is not None]
    return float(np.median(values)) if values else None


def forecast_fault(store: Any, machine: str, fault: str, *, level: float = 0.95) -> Any:
    """When an active component fault will reach its intolerable grade, from its trend since it was first alarmed.

    The relative changes from healthy recorded for the component (the ``deviation`` estimates) from the
    measurement of its first unacknowledged alarm on are extrapolated linearly (:func:`forecast_crossing`, a
    Fieller interval widened for the systematic scale error of the component's sizes, the baseline's
    :meth:`~cappe.monitor._baseline.Baseline.component_scale_std`); times are hours from the
    latest of them.

    Parameters
    ----------
    store : HistoryStore
        The history store.
    machine : str
        A registered machine.
    fault : str
        A component with an unacknowledged alarm.
    level : float
        Coverage probability of the interval.

    Returns
    -------
    CrossingForecast or None
        None where the fault is not a component, has no open alarm, or fewer than 3 judged measurements since.
    """
    from cappe.monitor._prognosis import forecast_crossing

    config = MonitorConfig.from_dict(store.machine_config(machine))
    if fault not in config.component_names:
        return None
    opened = [a for a in store.alarms(machine, unacknowledged=True) if a.component == fault]
    if not opened:
        return None
    first = min(a.measurement_id for a in opened)
    table = store.estimates(machine, path="deviation")
    table = table[(table["parameter"] == fault) & (table["measurement_id"] >= first)]
    if len(table) < 3:
        return None
    when = {r.id: r.timestamp for r in store.measurements(machine)}
    stamps = [when[int(i)] for i in table["measurement_id"]]
    latest = max(stamps)
    hours = np.array([(s - latest).total_seconds() / 3600.0 for s in stamps])
    change = table["value"].to_numpy(dtype=float)
    limit = config.thresholds(fault).intolerable
    doc = store.baseline(machine)
    scale_std = SIZE_SCALE_FLOOR
    if doc:
        baseline = Baseline.from_dict(doc)
        scale_std = float(baseline.component_scale_std()[list(baseline.names).index(fault)])
    threshold = -limit if change[-1] < 0 else limit
    if scale_std >= 0.2:  # the twin reads this component's sizes 20 % or more off: no crossing time can be told
        nominal = forecast_crossing(hours, change, threshold, level=level)
        return replace(nominal, lower=-np.inf, upper=np.inf, determined=False,
                       reason=f"the model's twin reads {fault}'s changes {100 * scale_std:.2g} % of themselves off")
    return forecast_crossing(hours, change, threshold, level=level, scale_std=scale_std)
