"""Preload studies on a model with a ``preload`` parameter (thesis 5.4.3, Figs 5.30-5.32).

- :func:`preload_map`: natural frequency and damping ratio of chosen modes over a range of preloads, each mode
  followed by its shape (mass-weighted MAC against the modes at the reference preload): the frequency-damping
  "maps" a monitoring system inverts, with the log-sensitivity ``d ln f / d ln preload`` of every mode;
- :func:`preload_frfs`: exact FRFs at several preloads (the Bode plots at 75 %, 100 % and 125 %);
- :func:`sensor_visibility`: how strongly each mode shows in each output's FRF, in dB below that output's
  strongest resonance: which sensor (shaft or housing, displacement or acceleration) sees which mode.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cappe.exceptions import ModelError
from cappe.modal import ModalEngine
from cappe.model import NumericModel, Structure
from cappe.systems.frf import FRFData

Array = NDArray[np.float64]

__all__ = ["THESIS_PRELOADS", "PreloadMap", "preload_frfs", "preload_map", "sensor_visibility"]

#: The preloads of thesis Fig. 5.30, as fractions of nominal.
THESIS_PRELOADS = (0.05, 0.15, 0.25, 0.40, 0.55, 0.70, 0.85, 1.00, 1.15, 1.30, 1.50)


@dataclass(frozen=True)
class PreloadMap:
    """Modes of a model over preloads (frequency in Hz, damping as a ratio).

    Attributes
    ----------
    preload : ndarray, shape (P,)
        Preload values (the model parameter's unit, e.g. a fraction of nominal).
    modes : tuple of int
        The modes followed (1-based numbers at the reference preload).
    frequency, damping : ndarray, shape (P, m)
        Each column is one physical mode, followed by its shape.
    tracking_mac : ndarray, shape (P, m)
        Mass-weighted MAC of each mode with its reference shape (how sure the following is).
    reference : float
        The preload whose modes define the columns.
    """

    preload: Array
    modes: tuple[int, ...]
    frequency: Array
    damping: Array
    tracking_mac: Array
    reference: float

    def sensitivity(self) -> Array:
        """``d ln f / d ln preload`` of each mode at the reference preload (central differences on the map)."""
        k = int(np.argmin(np.abs(self.preload - self.reference)))
        if self.preload.size < 3 or k in (0, self.preload.size - 1):
            msg = "the map needs preloads on both sides of the reference for a sensitivity"
            raise ModelError(msg)
        lp = np.log(self.preload)
        lf = np.log(self.frequency)
        return np.asarray((lf[k + 1] - lf[k - 1]) / (lp[k + 1] - lp[k - 1]), dtype=float)

    def to_dict(self) -> dict[str, Any]:
        return {"preload": self.preload.tolist(), "modes": list(self.modes), "reference": self.reference,
                "frequency": self.frequency.tolist(), "damping": self.damping.tolist(),
                "tracking_mac": self.tracking_mac.tolist(), "sensitivity": self.sensitivity().tolist()
                if self.preload.size >= 3 else None}


def _numeric(model: NumericModel | Structure, parameter: str) -> tuple[NumericModel, int]:
    nm = model if isinstance(model, NumericModel) else NumericModel(model)
    if parameter not in nm.parameter_names:
        msg = f"model '{nm.structure.name}' has no parameter {parameter!r} to vary; its parameters: " + \
            ", ".join(nm.parameter_names)
        raise ModelError(msg)
    return nm, nm.parameter_names.index(parameter)


def preload_map(
    model: NumericModel | Structure,
    preloads: Sequence[float] = THESIS_PRELOADS,
    modes: Sequence[int] = (1, 2, 3, 4, 5),
    *,
    parameter: str = "preload",
    reference: float = 1.0,
    params: Mapping[str, float] | None = None,
    position: Mapping[str, float] | None = None,
) -> PreloadMap:
    """Exact complex modes at every preload, the chosen modes followed by shape (thesis Fig. 5.30).

    Parameters
    ----------
    model : NumericModel or Structure
        The model; it must have the parameter ``parameter``.
    preloads : sequence of float
        Values of ``parameter`` (its unit, e.g. a fraction of nominal), > 0.
    modes : sequence of int
        Modes to follow (1-based, at the reference preload).
    parameter : str
        The model parameter varied.
    reference : float
        The preload whose modes define the columns.
    params : mapping name -> float, optional
        Other parameter values (SI).
    position : mapping axis -> float, optional
        Axis position (m or rad).

    Returns
    -------
    PreloadMap

    Raises
    ------
    ModelError
        The model has no such parameter, or the preloads or modes are invalid.

    Examples
    --------
    >>> from cappe.model import load_model
    >>> m = preload_map(load_model("builtin:spindle-bearing"), modes=(1, 2))
    >>> bool(np.all(np.diff(m.frequency, axis=0) > 0))   # stiffer bearings, higher frequencies
    True
    """
    nm, col = _numeric(model, parameter)
    values = np.asarray(preloads, dtype=float)
    if values.ndim != 1 or values.size == 0 or not np.all(np.isfinite(values) & (values > 0)):
        msg = f"preloads must be positive numbers; got {list(np.atleast_1d(preloads))}"
        raise ModelError(msg)
    chosen = [int(r) for r in modes]
    if not chosen or min(chosen) < 1 or max(chosen) > nm.n_dof:
        msg = f"modes must be numbers from 1 to {nm.n_dof}; got {chosen}"
        raise ModelError(msg)
    base = nm.vector(dict(params or {}))
    engine = ModalEngine(nm)
    ref_params = base.copy()
    ref_params[col] = reference
    track = engine.reference(ref_params, position)
    batch = np.tile(base, (values.size, 1))
    batch[:, col] = values
    result = engine.evaluate(batch, position, track=track, exact=True)
    idx = np.array(chosen) - 1
    assert result.poles is not None  # exact=True
    omega = np.abs(result.poles[:, idx])
    mac = result.tracking_mac if result.tracking_mac is not None else np.ones_like(omega)
    return PreloadMap(preload=values, modes=tuple(chosen), frequency=omega / (2 * np.pi),
                      damping=-result.poles[:, idx].real / omega, tracking_mac=np.asarray(mac)[:, idx],
                      reference=float(reference))


def preload_frfs(
    model: NumericModel | Structure,
    freq: Sequence[float] | NDArray[np.float64],
    preloads: Sequence[float] = (0.75, 1.0, 1.25),
    *,
    inputs: Sequence[str] | str | None = None,
    outputs: Sequence[str] | str | None = None,
    parameter: str = "preload",
    params: Mapping[str, float] | None = None,
    position: Mapping[str, float] | None = None,
) -> dict[float, FRFData]:
    """Exact FRFs of the model at each preload (thesis Fig. 5.31: nominal, 75 % and 125 %).

    Parameters
    ----------
    model : NumericModel or Structure
        The model; it must have the parameter ``parameter``.
    freq : sequence of float
        Frequencies in Hz.
    preloads : sequence of float
        Values of ``parameter``.
    inputs, outputs : sequence of str or str, optional
        Model inputs and outputs (default all).
    parameter : str
        The model parameter varied.
    params : mapping name -> float, optional
        Other parameter values (SI).
    position : mapping axis -> float, optional
        Axis position (m or rad).

    Returns
    -------
    dict
        ``{preload: FRFData}``.

    Raises
    ------
    ModelError
        The model has no such parameter.
    """
    nm, _ = _numeric(model, parameter)
    out = {}
    for value in preloads:
        system = nm.system({**dict(params or {}), parameter: float(value)}, position)
        out[float(value)] = system.frf(freq, inputs=inputs, outputs=outputs)
    return out


def sensor_visibility(frf: FRFData, mode_frequencies: Sequence[float], *, bandwidth: float = 0.02) -> Array:
    """Level (dB) of each mode in each output's FRF relative to that output's strongest mode: (n_out, n_in, m).

    A mode's level is the largest FRF magnitude within ``bandwidth`` (relative) of its natural frequency;
    0 dB marks the output's strongest mode, -40 dB a mode hard to see next to it (thesis 5.4.3: the third
    resonance 45 dB below the first is "not suitable for detection" with that sensor).

    Parameters
    ----------
    frf : FRFData
        FRFs (model or measured).
    mode_frequencies : sequence of float
        Natural frequencies of the modes in Hz.
    bandwidth : float
        Relative half-width of the window around each natural frequency (0.02 = +-2 %).

    Returns
    -------
    ndarray, shape (n_out, n_in, m)
        Levels in dB (<= 0; -inf where the output does not respond at the mode at all).
    """
    f = np.asarray(frf.freq, dtype=float)
    levels = []
    for fn in np.asarray(mode_frequencies, dtype=float):
        near = np.abs(f - fn) <= bandwidth * fn
        if not np.any(near):
            msg = f"the FRF has no line within {100 * bandwidth:g} % of the mode at {fn:.4g} Hz"
            raise ModelError(msg)
        levels.append(np.max(np.abs(frf.H[:, :, near]), axis=-1))
    peak = np.stack(levels, axis=-1)  # (n_out, n_in, m)
    strongest = np.max(peak, axis=-1, keepdims=True)
    with np.errstate(divide="ignore"):  # an output that does not see a mode at all: -inf dB, not a warning
        return np.asarray(20 * np.log10(peak / np.where(strongest > 0, strongest, 1.0)), dtype=float)
