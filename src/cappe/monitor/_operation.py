"""Operational (output-only) monitoring data: responses of the machine in production, with no measured force.

An independent simulation from the physics: at each measurement the machine's matrices (``M``, ``C``, ``G``,
``K``, ``H`` at the true parameters of that moment, from :func:`~cappe.monitor._scenario.scenario_states`:
thermal drift and the scenario's fault) give the dynamic stiffness ``Z(w) = K + iH - w^2 M + iw(C + G)``,
inverted with numpy through the eigen-decomposition of its state matrix ``[[0, I], [-M^-1 (K + iH), -M^-1 (C + G)]]``
(the resolvent, mode by mode); the responses are synthesized in the frequency domain,

    y(f) = (i w)^d S Z(w)^-1 B F(f),

(``d`` = 0, 1, 2 for displacement, velocity and acceleration outputs), and brought to the time domain by an
inverse FFT: an exactly periodic record of stationary random response, without start-up transients and exact
also for the hysteretic damping that has no time-domain realization. The force is the process's: random, unmeasured,
at the configured inputs, coloured by a spectrum that changes with the load of the moment,

    PSD_F(f) ~ load^2 / (1 + (f / f_c)^2)^2,   f_c = 200 Hz + 600 Hz x load,

with the three directions correlated by a load-dependent mixing (cutting forces share their cause). The load
wanders between measurements (uniform 0.3 to 1.0). Every output channel gets white sensor noise of ``noise``
times its RMS. The records carry no force channel: what the monitor sees in production.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timedelta

import numpy as np
from numpy.typing import NDArray

from cappe._rng import RandomLike, as_generator
from cappe.exceptions import DataError
from cappe.model import NumericModel, load_model
from cappe.monitor._config import MonitorConfig
from cappe.monitor._scenario import scenario_states
from cappe.systems.mechanical import DERIVATIVE_ORDER, MechanicalSystem
from cappe.systems.timedata import TimeData

__all__ = ["OperationalMeasurement", "operational_response", "simulate_operation"]

Array = NDArray[np.float64]
CArray = NDArray[np.complex128]


@dataclass(frozen=True)
class OperationalMeasurement:
    """One simulated operational record with its truth.

    Attributes
    ----------
    index : int
    timestamp : datetime
    conditions : dict
        ``temperature`` in degC (the load is not a recorded condition: the monitor must not need it).
    truth : dict
        The true relative value of every changed quantity, and ``load``.
    fault : str or None
    data : TimeData
        The output channels only.
    """

    index: int
    timestamp: datetime
    conditions: dict[str, float]
    truth: dict[str, float]
    fault: str | None
    data: TimeData


def _modes(system: MechanicalSystem, ii: list[int], oo: list[int]) -> tuple[CArray, CArray, CArray]:
    """Poles and modal input and output matrices of the state matrix ``[[0, I], [-M^-1 (K + iH), -M^-1 (C + G)]]``:
    ``H(w) = modal_out diag(1 / (i w - lambda)) modal_in`` (displacement-level outputs)."""
    n = system.M.shape[0]
    minv = np.linalg.inv(system.M)
    state = np.zeros((2 * n, 2 * n), dtype=complex)  # x = [q, q'], complex stiffness K + iH
    state[:n, n:] = np.eye(n)
    state[n:, :n] = -minv @ (system.K + 1j * system.H)
    state[n:, n:] = -minv @ (system.C + system.G)
    lam, vec = np.linalg.eig(state)
    modal_in = np.linalg.solve(vec, np.vstack([np.zeros((n, len(ii))), minv @ system.B[:, ii]]))  # (2n, n_in)
    modal_out = system.S[oo] @ vec[:n]  # (n_out, 2n)
    return lam, modal_in.T, modal_out


def operational_response(
    model: NumericModel,
    params: Array,
    *,
    inputs: list[str],
    outputs: list[str],
    position: dict[str, float] | None,
    fs: float,
    n_samples: int,
    load: float,
    noise: float,
    rng: np.random.Generator,
) -> TimeData:
    """Responses at ``outputs`` to the coloured random process force at ``inputs`` (module notes).

    Parameters
    ----------
    model : NumericModel
        The machine's model (its matrices at ``params`` are the physics simulated).
    params : ndarray
        Full parameter vector (SI).
    inputs, outputs : list of str
        Force inputs and response channels.
    position : dict, optional
        Axis position.
    fs : float
        Sampling rate in Hz.
    n_samples : int
        Samples (even).
    load : float
        Process load in (0, 1]; scales and colours the force.
    noise : float
        Sensor noise, a fraction of each channel's RMS.
    rng : Generator

    Returns
    -------
    TimeData
    """
    system = model.system(params, position)
    ii = [system.input_names.index(n) for n in inputs]
    oo = [system.output_names.index(n) for n in outputs]
    freq = np.fft.rfftfreq(n_samples, 1.0 / fs)
    w = 2 * np.pi * freq
    lam, modal_in, modal_out = _modes(system, ii, oo)
    f_c = 200.0 + 600.0 * load
    amplitude = load / (1.0 + (freq / f_c) ** 2)
    mix = np.eye(len(ii)) + (0.3 + 0.5 * load) * (np.ones((len(ii), len(ii))) - np.eye(len(ii))) / max(len(ii), 1)
    white = (rng.standard_normal((freq.size, len(ii))) + 1j * rng.standard_normal((freq.size, len(ii))))
    force = amplitude[:, None] * (white @ mix.T)
    force[0] = 0.0
    # q(w) = sum_j v_j (w_j^T B F) / (i w - lambda_j): the state-space resolvent, mode by mode
    modal = (force @ modal_in) / (1j * w[:, None] - lam[None, :])
    order = np.array([DERIVATIVE_ORDER[system.output_quantities[o]] for o in oo])
    y_f = (modal @ modal_out.T) * (1j * w[:, None]) ** order[None, :]
    y = np.fft.irfft(y_f, n_samples, axis=0).T
    y += noise * np.std(y, axis=1, keepdims=True) * rng.standard_normal(y.shape)
    return TimeData.from_rate(fs, dict(zip(outputs, y, strict=True)))


def simulate_operation(
    config: MonitorConfig,
    scenario: str = "healthy",
    *,
    n: int = 200,
    fault_at: int | None = None,
    component: str | None = None,
    severity: float | None = None,
    fs: float | None = None,
    seconds: float = 60.0,
    noise: float = 0.02,
    interval: timedelta = timedelta(minutes=15),
    start: datetime | None = None,
    temperature: tuple[float, float] = (22.0, 4.0),
    preload_per_kelvin: float = 0.01,
    model: NumericModel | None = None,
    rng: RandomLike = None,
) -> list[OperationalMeasurement]:
    """Simulate ``n`` operational records of a machine (see the module notes).

    Parameters
    ----------
    config : MonitorConfig
        The machine: model, reference parameters, channels (its inputs are where the process force acts) and band.
    scenario : {"healthy", "bearing-loss", "loosening-screw", "preload-loss"}
    n : int
        Number of records.
    fault_at, component, severity : optional
        As :func:`cappe.monitor.simulate_scenario`.
    fs : float, optional
        Sampling rate in Hz (default 2.56 x the band's upper end, as a signal analyser sets it).
    seconds : float
        Record length in s.
    noise : float
        Sensor noise as a fraction of each channel's RMS.
    interval : timedelta
        Time between records.
    start : datetime, optional
        Time of the first record (UTC).
    temperature : (float, float)
        Mean and daily amplitude in degC.
    preload_per_kelvin : float
        Relative preload change per kelvin.
    model : NumericModel, optional
        Compiled ``config.model``.
    rng : int or Generator, optional

    Returns
    -------
    list of OperationalMeasurement

    Raises
    ------
    DataError
        A setting out of range, an unknown scenario or component.

    Examples
    --------
    >>> from cappe.monitor import default_config
    >>> nm = NumericModel(load_model("builtin:spindle-bearing"))
    >>> cfg = default_config(nm, machine="s1", source="builtin:spindle-bearing", outputs=["sx", "hax"])
    >>> rec = simulate_operation(cfg, "bearing-loss", n=2, fault_at=1, seconds=2.0, model=nm, rng=1)
    >>> rec[1].fault, rec[1].data.channels, bool(rec[1].data.fs == 2.56 * cfg.band[1])
    ('front', ('sx', 'hax'), True)
    """
    rate = 2.56 * config.band[1] if fs is None else float(fs)
    n_samples = 2 * int(round(rate * seconds / 2))
    if n < 1 or not (0 <= noise < 1) or not rate > 2 * config.band[1] or n_samples < 64:
        msg = (f"operational scenario needs n >= 1, 0 <= noise < 1, fs above twice the band's upper end and at "
               f"least 64 samples; got n={n}, noise={noise}, fs={rate:g} Hz, {n_samples} samples")
        raise DataError(msg)
    nm = model if model is not None else NumericModel(load_model(config.model))
    gen = as_generator(rng)
    out = []
    for state in scenario_states(config, scenario, nm, gen, n=n, fault_at=fault_at, component=component,
                                 severity=severity, interval=interval, start=start, temperature=temperature,
                                 preload_per_kelvin=preload_per_kelvin):
        load = float(gen.uniform(0.3, 1.0))
        data = operational_response(nm, state.params, inputs=list(config.inputs), outputs=list(config.outputs),
                                    position=dict(config.position), fs=rate, n_samples=n_samples, load=load,
                                    noise=noise, rng=gen)
        out.append(OperationalMeasurement(state.index, state.timestamp, state.conditions,
                                          {**state.truth, "load": round(load, 4)}, state.fault, data))
    return out
