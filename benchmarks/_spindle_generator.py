"""An independent generator of spindle monitoring data, written from the physics in numpy (not cappe's scenario path).

What it shares with cappe is the model's matrices (:meth:`NumericModel.matrices`, :meth:`io_matrices`: the
physics of the machine); what it does on its own:

- **Shop-floor temperature.** A cold start every morning at 06:00 from the hall's temperature (18 degC at night),
  a first-order warm-up toward the running temperature (27 degC, time constant 1.2 h) and a cool-down after
  22:00 (3 h), a slowly wandering part (AR(1) per 5 minutes, 0.3 degC), and a housing sensor that follows the
  bearing with a first-order lag (``sensor_lag`` minutes) and reads with 0.02 degC noise. cappe's scenarios use a
  sine; here the recorded temperature is not the bearing's.
- **Preload.** Thermal growth raises the preload by 1 %/K plus a small quadratic term (the bearing stiffness follows
  through the model's Hertzian law).
- **FRF.** The receptance ``S (K + iH + i w (C + G) - w^2 M)^-1 B`` solved line by line with ``numpy.linalg.solve``
  (cappe solves modally), differentiated to each output's quantity, on 1.25 Hz lines (cappe's scenarios: 1 Hz).
- **Noise.** Log-normal magnitude (``noise``) and Gaussian phase (``noise`` rad) errors per line, plus a floor of
  1e-4 of each output's RMS level (cappe's: complex Gaussian).
- **Model mismatch.** ``mass_error`` scales the simulated machine's mass matrix, ``damping_factor`` its damping,
  against the model the chain uses.

A fault multiplies the parameters of a component (or the preload) by ``1 - loss`` from a given measurement on.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta

import numpy as np

from cappe.model import NumericModel
from cappe.monitor import MonitorConfig
from cappe.systems.frf import FRFData

ORDERS = {"displacement": 0, "velocity": 1, "acceleration": 2}


@dataclass
class Measurement:
    """One generated measurement: its time, recorded conditions, the truth and the FRF."""

    index: int
    timestamp: datetime
    conditions: dict[str, float]
    truth: dict[str, float]
    fault: str | None
    frf: FRFData


@dataclass
class ShopFloor:
    """The independent spindle generator (see the module notes).

    Attributes
    ----------
    config, model : the machine as the chain knows it
    noise : relative FRF error
    sensor_lag : minutes the housing sensor lags the bearing temperature
    mass_error, damping_factor : the simulated machine against the model
    interval : time between measurements
    """

    config: MonitorConfig
    model: NumericModel
    noise: float = 0.01
    sensor_lag: float = 2.0
    mass_error: float = 0.0
    damping_factor: float = 1.0
    interval: timedelta = timedelta(minutes=15)
    df: float = 1.25
    rng: np.random.Generator = field(default_factory=lambda: np.random.default_rng(0))

    def __post_init__(self) -> None:
        nm = self.model
        self.base = nm.vector(dict(self.config.params))
        self.freq = np.arange(self.df, 1.25 * self.config.band[1], self.df)
        system = nm.system(self.base, self.config.position)
        self.ii = [system.input_names.index(n) for n in self.config.inputs]
        self.oo = [system.output_names.index(n) for n in self.config.outputs]
        self.orders = np.array([ORDERS[system.output_quantities[k]] for k in self.oo])
        self.quantities = tuple(system.output_quantities[k] for k in self.oo)
        self.bearing = 22.0  # true bearing temperature, degC
        self.sensor = 22.0
        self.wander = 0.0
        self.clock = datetime(2026, 3, 2, 0, 0, tzinfo=UTC)

    # -- temperature --------------------------------------------------------------------------------------
    def _target(self, when: datetime) -> tuple[float, float]:
        hour = when.hour + when.minute / 60
        running = 6.0 <= hour < 22.0
        return (27.0, 1.2) if running else (18.0, 3.0)

    def advance(self, until: datetime) -> None:
        """Integrate the temperatures in 1-minute steps up to ``until``."""
        step = timedelta(minutes=1)
        while self.clock < until:
            target, tau = self._target(self.clock)
            self.bearing += (target - self.bearing) * (1 - np.exp(-1 / (60 * tau)))
            if self.clock.minute % 5 == 0:
                self.wander = 0.97 * self.wander + 0.3 * np.sqrt(1 - 0.97**2) * self.rng.standard_normal()
            true = self.bearing + self.wander
            lag = max(self.sensor_lag, 1e-9)
            self.sensor += (true - self.sensor) * (1 - np.exp(-1 / lag))
            self.clock += step

    # -- physics --------------------------------------------------------------------------------------------
    def params(self, fault: str | None, loss: float) -> tuple[np.ndarray, float]:
        nm = self.model
        p = self.base.copy()
        dt = self.bearing + self.wander - 22.0
        k_pre = nm.parameter_names.index("preload")
        thermal = 1.0 + 0.01 * dt + 2e-4 * dt**2
        p[k_pre] *= thermal
        if fault == "preload":
            p[k_pre] *= 1.0 - loss
        elif fault is not None:
            for name in self.config.component(fault).parameters:
                p[nm.parameter_names.index(name)] *= 1.0 - loss
        return p, float(p[k_pre] / self.base[k_pre])

    def frf(self, p: np.ndarray) -> np.ndarray:
        """Exact FRF (outputs, inputs, lines) of the simulated machine at parameters ``p``."""
        mats = self.model.matrices(p, self.config.position)
        b_mat, s_mat = self.model.io_matrices(p, self.config.position)
        m = (1.0 + self.mass_error) * mats["M"]
        c = self.damping_factor * mats["C"] + mats["G"]
        k = mats["K"] + 1j * self.damping_factor * mats["H"]
        w = 2 * np.pi * self.freq
        dyn = k[None] + 1j * w[:, None, None] * c[None] - w[:, None, None] ** 2 * m[None]
        x = np.linalg.solve(dyn, np.broadcast_to(b_mat[:, self.ii], (w.size, *b_mat[:, self.ii].shape)))
        h = np.einsum("od,ldi->oil", s_mat[self.oo], x)
        return np.asarray(h * (1j * w)[None, None, :] ** self.orders[:, None, None])

    def _noisy(self, h: np.ndarray) -> np.ndarray:
        if self.noise == 0:
            return h
        rms = np.sqrt(np.mean(np.abs(h) ** 2, axis=(1, 2)))
        mag = np.exp(self.noise * self.rng.standard_normal(h.shape))
        phase = np.exp(1j * self.noise * self.rng.standard_normal(h.shape))
        floor = 1e-4 * rms[:, None, None] * (self.rng.standard_normal(h.shape)
                                             + 1j * self.rng.standard_normal(h.shape)) / np.sqrt(2)
        return h * mag * phase + floor

    def run(self, n: int, *, fault: str | None = None, loss: float | Sequence[float] = 0.0,
            fault_at: int = 0) -> list[Measurement]:
        """The next ``n`` measurements; ``fault`` from measurement ``fault_at`` on (``loss``: one or per one)."""
        losses = np.broadcast_to(np.asarray(loss, dtype=float), (n,))
        out = []
        for k in range(n):
            self.advance(self.clock + self.interval)
            faulty = fault is not None and k >= fault_at
            p, preload = self.params(fault if faulty else None, float(losses[k]))
            h = self._noisy(self.frf(p))
            truth = {"preload": preload}
            if faulty:
                truth[str(fault)] = 1.0 - float(losses[k])
            temp = round(float(self.sensor + 0.02 * self.rng.standard_normal()), 2)
            out.append(Measurement(k, self.clock, {"temperature": temp}, truth, fault if faulty else None,
                                   FRFData(self.freq, h, tuple(self.config.inputs), tuple(self.config.outputs),
                                           self.quantities)))
        return out
