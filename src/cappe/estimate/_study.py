"""Simulation studies (thesis 4.5, Table 4.3): known truth -> simulated data with seeded noise -> estimate,
repeated over noise levels and seeds, tabulated as mean and standard deviation of every estimate."""

from __future__ import annotations

import inspect
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cappe.estimate._registry import METHODS, estimator_class
from cappe.exceptions import ConvergenceWarning, DataWarning, ModelError
from cappe.model import NumericModel, Structure
from cappe.systems.modal import ModalData, ModalDataSet

__all__ = ["StudyResult", "simulation_study", "simulate_data"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class StudyResult:
    """Estimates of every run: ``estimates[level, seed, parameter]`` (nan where a run failed).

    Attributes
    ----------
    method : str
        The estimation method.
    names : tuple of str
        The unknowns.
    truth : ndarray, shape (n,)
        Their true values (SI).
    noise_levels : ndarray, shape (n_levels,)
        Relative noise of each level (0.01 = 1 %).
    seeds : tuple of int
        The seeds of the runs at every level.
    estimates : ndarray, shape (n_levels, n_seeds, n)
        Estimates (SI; nan where a run failed).
    success : ndarray of bool, shape (n_levels, n_seeds)
        Which runs were a success (converged and passed the method's residual tests).
    position : dict
        Axis position (m or rad) the time data and FRFs were simulated and estimated at (empty: the model's
        default position; modal data carry theirs).
    ci95 : ndarray, shape (n_levels, n_seeds, n, 2), optional
        The 95 % interval of every run, successful or not (nan where the run gave none: a parameter it could not
        determine or held at a bound). None for a result made without them.
    """

    method: str
    names: tuple[str, ...]
    truth: Array
    noise_levels: Array
    seeds: tuple[int, ...]
    estimates: Array
    success: NDArray[np.bool_]
    position: dict[str, float] = field(default_factory=dict)
    ci95: Array | None = None

    def covered(self) -> NDArray[np.bool_] | None:
        """Whether each run's 95 % interval covers the truth, shape (n_levels, n_seeds, n); a run without an
        interval for a parameter does not cover it. None without intervals."""
        if self.ci95 is None:
            return None
        lo, hi = self.ci95[..., 0], self.ci95[..., 1]
        with np.errstate(invalid="ignore"):
            return np.asarray(np.isfinite(lo) & np.isfinite(hi) & (lo <= self.truth) & (self.truth <= hi))

    def summary(self) -> list[dict[str, Any]]:
        """One row per noise level and parameter: truth, mean, std, mean error in %, runs used (the successful
        ones), and, with intervals, how many of those and of all runs (``runs_all``) cover the truth
        (``covered``, ``covered_all``)."""
        rows = []
        covered = self.covered()
        for i, level in enumerate(self.noise_levels):
            ok = self.success[i]
            for k, name in enumerate(self.names):
                values = self.estimates[i, ok, k]
                mean = float(values.mean()) if values.size else float("nan")
                std = float(values.std(ddof=1)) if values.size > 1 else float("nan")
                row = {"noise": float(level), "parameter": name, "truth": float(self.truth[k]), "mean": mean,
                       "std": std, "error_percent": 100 * (mean / self.truth[k] - 1), "runs": int(ok.sum())}
                if covered is not None:
                    row |= {"covered": int(covered[i, ok, k].sum()), "covered_all": int(covered[i, :, k].sum()),
                            "runs_all": int(ok.size)}
                rows.append(row)
        return rows

    def to_dict(self) -> dict[str, Any]:
        def clean(v: Any) -> Any:
            return None if isinstance(v, float) and not np.isfinite(v) else v

        return {
            "format": "cappe.study/1",
            "method": self.method,
            "parameters": list(self.names),
            "truth": dict(zip(self.names, self.truth.tolist(), strict=True)),
            "noise_levels": self.noise_levels.tolist(),
            "seeds": list(self.seeds),
            "position": dict(self.position),
            "rows": [{k: clean(v) for k, v in row.items()} for row in self.summary()],
        }

    def to_text(self) -> str:
        """The layout of thesis Table 4.3: per parameter, the truth and mean (std) at every noise level."""
        head = f"{'parameter':>10s} {'truth':>11s}" + "".join(f"   noise {100 * n:g} %: mean (std)".rjust(30)
                                                            for n in self.noise_levels)
        lines = [head]
        rows = self.summary()
        for k, name in enumerate(self.names):
            cells = []
            for i in range(self.noise_levels.size):
                row = rows[i * len(self.names) + k]
                cells.append(f"{row['mean']:.5g} ({row['std']:.2g})".rjust(30))
            lines.append(f"{name:>10s} {self.truth[k]:11.5g}" + "".join(cells))
        failed = int((~self.success).sum())
        if failed:
            per_level = ", ".join(f"{int((~ok).sum())} of {ok.size} at {100 * n:g} %"
                                  for n, ok in zip(self.noise_levels, self.success, strict=True))
            lines.append(f"{failed} of {self.success.size} runs were not a success (did not converge or failed a "
                         f"residual test; {per_level}) and are left out of the mean and std")
        if self.ci95 is None:
            return "\n".join(lines)
        lines.append("95 % intervals covering the truth: of the runs claiming success | of all runs (a run without "
                     "an interval does not cover" + ("; noise-free runs have round-off intervals, not counted)"
                                                    if np.any(self.noise_levels == 0) else ")"))
        for k, name in enumerate(self.names):
            cells = []
            for i in range(self.noise_levels.size):
                row = rows[i * len(self.names) + k]
                cell = ("-" if self.noise_levels[i] == 0 else
                        f"{row['covered']}/{row['runs']} | {row['covered_all']}/{row['runs_all']}")
                cells.append(cell.rjust(30))
            lines.append(f"{name:>10s} {'':11s}" + "".join(cells))
        return "\n".join(lines)


def simulate_data(
    model: NumericModel,
    kind: str,
    truth: Mapping[str, float],
    *,
    noise: float,
    rng: np.random.Generator,
    fs: float = 1000.0,
    duration: float = 4.0,
    band: tuple[float, float] | None = None,
    position: Mapping[str, float] | None = None,
) -> Any:
    """Data of the kind a method takes, simulated at ``truth`` with relative noise ``noise``.

    ``"time"``: band-limited random forces (RMS 10 N) on every model input, every model output recorded with white
    noise of ``noise`` times its RMS. ``"frf"``: H1 FRFs estimated from such data. ``"modal"``: the exact modes
    at the default position with frequency and damping multiplied by ``1 + noise * N(0, 1)``, and complex noise of
    ``noise`` times each shape's largest component on the shapes.

    Parameters
    ----------
    model : NumericModel
        The model.
    kind : {"time", "frf", "modal"}
        The kind of data (``cappe.estimate.METHODS[method][2]``).
    truth : mapping name -> float
        Parameter values (SI) the data are simulated at; the others keep their nominal values.
    noise : float
        Relative noise (0.01 = 1 %).
    rng : Generator
        Source of the forces and the noise.
    fs : float
        Sampling rate in Hz (time and FRF data).
    duration : float
        Record length in s (time and FRF data).
    band : (float, float), optional
        Frequency band of the random forces in Hz (default ``(0, fs / 2.56)``).
    position : mapping axis -> float, optional
        Axis position (m or rad) the data are simulated at (default the model's default position); modal data
        record it in their set.

    Returns
    -------
    TimeData, FRFData or ModalData
    """
    from cappe.identify import estimate_frf, random_noise
    from cappe.systems import TimeData, time_response

    where = model.structure.resolve_position(position or {})
    system = model.system(model.structure.resolve_parameters(truth), where)
    if kind == "modal":
        from cappe.modal import ModalEngine

        modes = ModalEngine(model).modal_data([where], params=model.vector(model.structure.resolve_parameters(truth)))
        sets = []
        for s in modes.sets:
            shapes = s.shapes + noise * np.abs(s.shapes).max(axis=0) * (
                rng.standard_normal(s.shapes.shape) + 1j * rng.standard_normal(s.shapes.shape)) / np.sqrt(2)
            sets.append(ModalDataSet(dict(s.position), s.frequency * (1 + noise * rng.standard_normal(s.n_modes)),
                                     s.damping * (1 + noise * rng.standard_normal(s.n_modes)), shapes))
        return ModalData(modes.sensors, tuple(sets), modes.source)
    lo_hi = band if band is not None else (0.0, fs / 2.56)
    forces = {}
    for name in system.input_names:
        forces[name] = random_noise(fs=fs, duration=duration, rms=10.0, band=lo_hi, rng=rng, name=name).channel(name)
    excitation = TimeData.from_rate(fs, forces)
    data = time_response(system, excitation, noise=noise, rng=rng)
    if kind == "frf":
        outputs = [n for n, q in zip(system.output_names, system.output_quantities, strict=True)
                   if q == "displacement"] or list(system.output_names)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DataWarning)  # low coherence outside the band is expected here
            return estimate_frf(data, inputs=list(system.input_names), outputs=outputs, band=(max(lo_hi[0], 1.0),
                                                                                             lo_hi[1]))
    return data


def simulation_study(
    *,
    model: NumericModel | Structure,
    method: str,
    truth: Mapping[str, float],
    unknowns: Sequence[str] | None = None,
    noise_levels: Sequence[float] = (0.0, 0.01),
    seeds: Sequence[int] = (0, 1, 2),
    start: Mapping[str, float] | None = None,
    settings: Mapping[str, Any] | None = None,
    fs: float = 1000.0,
    duration: float = 4.0,
    position: Mapping[str, float] | None = None,
) -> StudyResult:
    """Repeat simulate -> estimate for every noise level and seed.

    Parameters
    ----------
    model : NumericModel or Structure
        The model; it simulates the data and is estimated.
    method : str
        A method of :data:`METHODS`.
    truth : mapping name -> float
        Parameter values (SI) the data are simulated at.
    unknowns : sequence of str, optional
        Parameters to estimate (default: those marked ``unknown``).
    noise_levels : sequence of float
        Relative noise levels (0.01 = 1 %).
    seeds : sequence of int
        Seeds of the runs at every level (each run's data and the estimator's ``rng``).
    start : mapping name -> float, optional
        Start values of the estimation (SI; default the model's).
    settings : mapping, optional
        Keyword settings of the estimator.
    fs : float
        Sampling rate in Hz of simulated time and FRF data.
    duration : float
        Record length in s of simulated time and FRF data.
    position : mapping axis -> float, optional
        Axis position (m or rad) of the simulated time data and FRFs, passed to the estimators that take one
        (default the model's default position). Methods whose reference modes carry the position of each set
        (modal, feature map, hybrid, automated) refuse it.

    Returns
    -------
    StudyResult

    Raises
    ------
    ModelError
        ``method`` is not registered, or a ``position`` is given to a method whose reference data carry it.

    Examples
    --------
    >>> from cappe.model import load_model
    >>> res = simulation_study(model=load_model("builtin:two-mass-rig"), method="direct", truth={"k11": 1.2e6},
    ...                        unknowns=["k11"], noise_levels=[0.0], seeds=[0], duration=1.0)
    >>> round(float(res.estimates[0, 0, 0]) / 1.2e6, 6)
    1.0
    """
    if method not in METHODS:
        msg = f"unknown estimation method {method!r}; choose from {', '.join(METHODS)}"
        raise ModelError(msg)
    nm = model if isinstance(model, NumericModel) else NumericModel(model)
    cls = estimator_class(method)
    kind = METHODS[method][2]
    options = dict(settings or {})
    if "position" in inspect.signature(cls.__init__).parameters:
        options.setdefault("position", nm.structure.resolve_position(position or {}))
    elif position:
        msg = f"a position does not apply to method {method!r}: its reference data carry the axis position of each set"
        raise ModelError(msg)
    names = list(unknowns) if unknowns is not None else [p.name for p in nm.structure.parameters if p.unknown]
    truth_full = nm.structure.resolve_parameters(truth)
    levels = np.asarray(noise_levels, dtype=float)
    estimates = np.full((levels.size, len(seeds), len(names)), np.nan)
    intervals = np.full((levels.size, len(seeds), len(names), 2), np.nan)
    success = np.zeros((levels.size, len(seeds)), dtype=bool)
    for i, level in enumerate(levels):
        for j, seed in enumerate(seeds):
            rng = np.random.default_rng([int(seed), i])
            data = simulate_data(nm, kind, truth_full, noise=float(level), rng=rng, fs=fs, duration=duration,
                                 position=options.get("position"))
            estimator = cls(nm, names, start=start, rng=int(seed), **options)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ConvergenceWarning)
                result = estimator.fit(data).estimate_
            intervals[i, j] = result.ci95
            if result.success:
                estimates[i, j] = result.values
                success[i, j] = True
    return StudyResult(method, tuple(names), np.array([truth_full[n] for n in names]), levels,
                       tuple(int(s) for s in seeds), estimates, success, dict(options.get("position") or {}),
                       intervals)
