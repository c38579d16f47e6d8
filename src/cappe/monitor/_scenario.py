"""Realistic monitoring data from a model: healthy operation and three kinds of fault, with measurement noise.

Every measurement is an FRF set of the machine's configured channels (an impact or shaker test repeated at a
fixed interval, by default every 15 minutes) at the parameters of that moment:

- **Healthy operation.** The spindle temperature follows a daily cycle (22 +- 4 degC by default) plus a slowly
  wandering part (an AR(1) process, 0.25 degC standard deviation), and the bearing preload follows it: thermal
  growth of the shaft against the housing raises the preload, here by ``preload_per_kelvin`` = 1 % per kelvin of
  the nominal (so +-4 % over the day, +-1.4 % of bearing stiffness through the Hertzian law of the model).
- **bearing-loss**: from measurement ``fault_at`` on, one component (default ``front``) keeps
  ``1 - severity`` of its stiffness (default 10 % lost).
- **loosening-screw**: from ``fault_at`` on, one component (default ``screw2``) loses stiffness linearly until
  ``1 - severity`` at the last measurement (default 50 %).
- **preload-loss**: from ``fault_at`` on, the preload drops to ``1 - severity`` of its value (default 40 %).

Noise: every FRF line gets complex Gaussian noise of standard deviation ``noise |H|`` (the relative error of an
averaged H1 estimate; 0.01 = 1 %) plus ``noise / 100`` of the output's RMS FRF level (the sensor's noise floor,
which keeps responses that vanish by symmetry from being noise-free).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from cappe._rng import RandomLike, as_generator
from cappe.exceptions import DataError
from cappe.io import write_frf, write_json, write_time_data
from cappe.io.files import finite_number, read_json, shown
from cappe.model import NumericModel, load_model
from cappe.monitor._config import MonitorConfig
from cappe.systems.frf import FRFData

if TYPE_CHECKING:
    from cappe.monitor._operation import OperationalMeasurement

__all__ = ["SCENARIOS", "SCENARIO_FORMAT", "ScenarioMeasurement", "ScenarioState", "read_scenario",
           "scenario_states", "simulate_scenario", "write_scenario"]

SCENARIO_FORMAT = "cappe.monitor-scenario/1"

#: Scenario name -> (default component, default severity).
SCENARIOS: dict[str, tuple[str | None, float]] = {
    "healthy": (None, 0.0),
    "bearing-loss": ("front", 0.10),
    "loosening-screw": ("screw2", 0.50),
    "preload-loss": ("preload", 0.40),
}


@dataclass(frozen=True)
class ScenarioMeasurement:
    """One simulated measurement with its truth.

    Attributes
    ----------
    index : int
    timestamp : datetime
        UTC.
    conditions : dict
        Operating conditions recorded with it (``temperature`` in degC).
    truth : dict
        The true relative value of every changed quantity: the faulty component's factor and ``preload``.
    fault : str or None
        The fault present (component or ``preload``), None while healthy.
    frf : FRFData
    """

    index: int
    timestamp: datetime
    conditions: dict[str, float]
    truth: dict[str, float]
    fault: str | None
    frf: FRFData


def simulate_scenario(
    config: MonitorConfig,
    scenario: str = "healthy",
    *,
    n: int = 200,
    fault_at: int | None = None,
    component: str | None = None,
    severity: float | None = None,
    noise: float = 0.01,
    interval: timedelta = timedelta(minutes=15),
    start: datetime | None = None,
    df: float = 1.0,
    temperature: tuple[float, float] = (22.0, 4.0),
    preload_per_kelvin: float = 0.01,
    model: NumericModel | None = None,
    rng: RandomLike = None,
) -> list[ScenarioMeasurement]:
    """Simulate ``n`` measurements of a machine (see the module notes).

    Parameters
    ----------
    config : MonitorConfig
        The machine: model, reference parameters, channels and band.
    scenario : {"healthy", "bearing-loss", "loosening-screw", "preload-loss"}
    n : int
        Number of measurements.
    fault_at : int, optional
        Index of the first faulty measurement (default ``n // 2``).
    component : str, optional
        The faulty component (bearing-loss, loosening-screw).
    severity : float, optional
        Fraction lost (default per scenario, see :data:`SCENARIOS`).
    noise : float
        Relative FRF noise.
    interval : timedelta
        Time between measurements.
    start : datetime, optional
        Time of the first measurement (UTC; default 2026-01-05 06:00).
    df : float
        Line spacing in Hz (lines from ``df`` to 1.2 x the band's upper end).
    temperature : (float, float)
        Mean and daily amplitude in degC.
    preload_per_kelvin : float
        Relative preload change per kelvin (needs a ``preload`` parameter; ignored without one).
    model : NumericModel, optional
        Compiled ``config.model``.
    rng : int or Generator, optional

    Examples
    --------
    >>> from cappe.model import load_model
    >>> from cappe.monitor import default_config
    >>> nm = NumericModel(load_model("builtin:spindle-bearing"))
    >>> cfg = default_config(nm, machine="s1", source="builtin:spindle-bearing", outputs=["sx", "hax"])
    >>> data = simulate_scenario(cfg, "bearing-loss", n=4, fault_at=2, model=nm, rng=1)
    >>> [(m.fault, m.truth.get("front")) for m in data]
    [(None, 1.0), (None, 1.0), ('front', 0.9), ('front', 0.9)]
    """
    if n < 1 or not (0 <= noise < 1) or df <= 0:
        msg = f"scenario needs n >= 1, 0 <= noise < 1 and df > 0; got n={n}, noise={noise}, df={df}"
        raise DataError(msg)
    nm = model if model is not None else NumericModel(load_model(config.model))
    gen = as_generator(rng)
    freq = np.arange(df, 1.2 * config.band[1] + df / 2, df)
    out = []
    for state in scenario_states(config, scenario, nm, gen, n=n, fault_at=fault_at, component=component,
                                 severity=severity, interval=interval, start=start, temperature=temperature,
                                 preload_per_kelvin=preload_per_kelvin):
        frf = nm.system(state.params, config.position).frf(freq, inputs=list(config.inputs),
                                                           outputs=list(config.outputs))
        out.append(ScenarioMeasurement(state.index, state.timestamp, state.conditions, state.truth, state.fault,
                                       _noisy(frf, noise, gen)))
    return out


@dataclass(frozen=True)
class ScenarioState:
    """The machine at one measurement of a scenario: when, its conditions, its true parameters.

    Attributes
    ----------
    index : int
    timestamp : datetime
    conditions : dict
        ``temperature`` in degC, rounded as a sensor would report it.
    truth : dict
        The true relative value of every changed quantity.
    fault : str or None
        The fault present, None while healthy.
    params : ndarray
        The model's full parameter vector (SI).
    """

    index: int
    timestamp: datetime
    conditions: dict[str, float]
    truth: dict[str, float]
    fault: str | None
    params: NDArray[np.float64]


def scenario_states(
    config: MonitorConfig,
    scenario: str,
    model: NumericModel,
    rng: np.random.Generator,
    *,
    n: int,
    fault_at: int | None = None,
    component: str | None = None,
    severity: float | None = None,
    interval: timedelta = timedelta(minutes=15),
    start: datetime | None = None,
    temperature: tuple[float, float] = (22.0, 4.0),
    preload_per_kelvin: float = 0.01,
) -> Iterator[ScenarioState]:
    """The machine's state at each of ``n`` measurements: thermal drift and the scenario's fault (module notes).

    One standard normal draw of ``rng`` per measurement (the wandering temperature), taken when the state is
    produced, so a caller may draw its noise in between.

    Parameters
    ----------
    config : MonitorConfig
        The machine.
    scenario : {"healthy", "bearing-loss", "loosening-screw", "preload-loss"}
    model : NumericModel
        Compiled ``config.model``.
    rng : Generator
    n : int
        Number of measurements.
    fault_at, component, severity, interval, start, temperature, preload_per_kelvin
        As :func:`simulate_scenario`.

    Yields
    ------
    ScenarioState

    Raises
    ------
    DataError
        An unknown scenario or component, or a severity outside (0, 1).
    """
    if scenario not in SCENARIOS:
        msg = f"unknown scenario {scenario!r}; choose one of {sorted(SCENARIOS)}"
        raise DataError(msg)
    nm = model
    gen = rng
    default_component, default_severity = SCENARIOS[scenario]
    target = component or default_component
    loss = default_severity if severity is None else float(severity)
    first_fault = n // 2 if fault_at is None else int(fault_at)
    if scenario != "healthy":
        if not 0 < loss < 1:
            msg = f"scenario severity must be a fraction in (0, 1); got {loss!r}"
            raise DataError(msg)
        if scenario == "preload-loss":
            target = "preload"
            if "preload" not in nm.parameter_names:
                msg = f"model {config.model} has no 'preload' parameter for a preload-loss scenario"
                raise DataError(msg)
        else:
            config.component(str(target))  # raises for an unknown component
    base = nm.vector(dict(config.params))
    has_preload = "preload" in nm.parameter_names
    k_preload = nm.parameter_names.index("preload") if has_preload else -1
    t0 = start if start is not None else datetime(2026, 1, 5, 6, 0, tzinfo=UTC)
    wander = 0.0
    for k in range(n):
        when = t0 + k * interval
        hours = (when - t0).total_seconds() / 3600.0
        wander = 0.95 * wander + 0.25 * np.sqrt(1 - 0.95**2) * gen.standard_normal()
        temp = temperature[0] + temperature[1] * np.sin(2 * np.pi * (hours - 9.0) / 24.0) + wander
        p = base.copy()
        truth: dict[str, float] = {}
        if has_preload:
            p[k_preload] *= 1.0 + preload_per_kelvin * (temp - temperature[0])
        faulty = scenario != "healthy" and k >= first_fault
        factor = 1.0
        if faulty:
            if scenario == "loosening-screw":
                span = max(n - 1 - first_fault, 1)
                factor = 1.0 - loss * (k - first_fault) / span
            else:
                factor = 1.0 - loss
        if target == "preload" and scenario != "healthy":
            p[k_preload] *= factor
        elif target is not None:
            for name in config.component(target).parameters:
                p[nm.parameter_names.index(name)] *= factor
        if target is not None:
            truth[target] = factor
        if has_preload:
            truth["preload"] = float(p[k_preload] / base[k_preload])
        yield ScenarioState(k, when, {"temperature": round(float(temp), 3)}, truth, target if faulty else None, p)


def _noisy(frf: FRFData, noise: float, gen: np.random.Generator) -> FRFData:
    H = np.asarray(frf.H)
    if noise == 0:
        return frf
    rms = np.sqrt(np.mean(np.abs(H) ** 2, axis=(1, 2)))
    sigma = noise * np.abs(H) + 0.01 * noise * rms[:, None, None]
    eps = (gen.standard_normal(H.shape) + 1j * gen.standard_normal(H.shape)) / np.sqrt(2)
    return FRFData(frf.freq, H + sigma * eps, frf.input_names, frf.output_names, frf.output_quantities)


def write_scenario(
    measurements: Sequence[ScenarioMeasurement | OperationalMeasurement],
    directory: str | Path,
    *,
    machine: str,
    scenario: str,
    extension: str = "uff",
) -> Path:
    """Write one FRF file (time data for operational records) per measurement and a manifest ``scenario.json``
    (the ingest order, times, conditions and truth); return the manifest's path.

    Parameters
    ----------
    measurements : sequence of ScenarioMeasurement or OperationalMeasurement
        The simulated measurements, in ingest order.
    directory : str or Path
        Folder to write into (created if needed).
    machine : str
        Machine id recorded in the manifest.
    scenario : str
        Scenario name recorded in the manifest.
    extension : {"uff", "csv", "npz"}
        Format of the FRF files.

    Returns
    -------
    Path
        The manifest.

    Raises
    ------
    DataError
        ``extension`` is not one of these.
    """
    folder = Path(directory)
    if extension not in ("uff", "csv", "npz"):
        msg = f"scenario files must be uff, csv or npz; got {extension!r}"
        raise DataError(msg)
    folder.mkdir(parents=True, exist_ok=True)
    entries = []
    for m in measurements:
        name = f"m{m.index:05d}.{extension}"
        if isinstance(m, ScenarioMeasurement):
            write_frf(folder / name, m.frf)
        else:  # an operational record: time data of the outputs
            write_time_data(folder / name, m.data)
        entries.append({"file": name, "timestamp": m.timestamp.isoformat(), "conditions": m.conditions,
                        "truth": m.truth, "fault": m.fault})
    doc = {"format": SCENARIO_FORMAT, "machine": machine, "scenario": scenario, "measurements": entries}
    path = folder / "scenario.json"
    write_json(path, doc)
    return path


def read_scenario(path: str | Path) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Read a manifest: the document and its entries with ``file`` resolved and ``timestamp`` parsed.

    Parameters
    ----------
    path : str or Path
        The ``scenario.json`` manifest.

    Returns
    -------
    document : dict
        The manifest.
    entries : list of dict
        One per measurement, ``file`` as a Path next to the manifest and ``timestamp`` as a datetime.

    Raises
    ------
    DataError
        The file cannot be read or breaks a rule of the manifest format (the message names the file).
    """
    p = Path(path)
    doc = read_json(p, "scenario manifest")
    got = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
    if got != SCENARIO_FORMAT:
        msg = f"{p}: format must be {SCENARIO_FORMAT!r}; got {shown(got)}"
        raise DataError(msg)
    measurements = doc.get("measurements", [])
    if not isinstance(measurements, list):
        msg = f"{p}: measurements must be a list; got {type(measurements).__name__}"
        raise DataError(msg)
    entries = []
    for k, entry in enumerate(measurements):
        if not isinstance(entry, dict):
            msg = f"{p}: measurements[{k}] must be an object with 'file' and 'timestamp'; got {type(entry).__name__}"
            raise DataError(msg)
        try:
            when = datetime.fromisoformat(entry["timestamp"])
            entries.append({**entry, "file": p.parent / entry["file"], "timestamp": when})
        except (KeyError, TypeError, ValueError) as exc:
            msg = f"{p}: measurements[{k}] needs 'file' and an ISO 'timestamp': {shown(str(exc))}"
            raise DataError(msg) from exc
        conditions = entry.get("conditions", {})
        if not isinstance(conditions, dict) or any(finite_number(v) is None for v in conditions.values()):
            msg = f"{p}: measurements[{k}].conditions must be an object {{name: number}}; got {shown(conditions)}"
            raise DataError(msg)
    return doc, entries
