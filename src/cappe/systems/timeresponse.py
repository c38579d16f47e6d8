"""Time response of a mechanical system to sampled excitation: synthetic measurements with seeded noise."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cappe._rng import RandomLike, as_generator
from cappe.exceptions import DataError
from cappe.systems.statespace import check_intersample
from cappe.systems.timedata import TimeData

__all__ = ["OUTPUT_UNITS", "time_response"]

#: SI unit of each output quantity.
OUTPUT_UNITS = {"displacement": "m", "elongation": "m", "velocity": "m/s", "acceleration": "m/s^2"}


def time_response(
    system: Any,
    excitation: TimeData,
    *,
    inputs: Mapping[str, str] | None = None,
    outputs: Sequence[str] | None = None,
    noise: float = 0.0,
    input_noise: float = 0.0,
    rng: RandomLike = None,
    intersample: str = "zoh",
) -> TimeData:
    """Simulated measurement: the system's outputs to the excitation, plus white noise, with the inputs.

    The continuous system is started at rest and simulated exactly for the input between samples that
    ``intersample`` names (:mod:`cappe.systems.statespace`): held (``"zoh"``, the default here), linear
    (``"foh"``) or band-limited (``"bl"``, as a DAQ with an anti-alias filter records a force). Hysteretic
    damping enters as its equivalent viscous matrix at each mode (see :meth:`MechanicalSystem.state_space`).

    Parameters
    ----------
    system : MechanicalSystem
        ``model.system(params, position)``.
    excitation : TimeData
        Force channels in N (moments in N m).
    inputs : mapping, optional
        Excitation channel -> model input name; by default every channel must be a model input of that name.
    outputs : sequence of str, optional
        Model outputs to record; all by default.
    noise, input_noise : float
        Standard deviation of Gaussian white noise added to each output (input) channel, as a fraction of that
        channel's RMS value (0.01 = "1 % noise"). The recorded inputs carry the input noise; the system is driven
        by the clean excitation.
    rng : int, Generator or None
        Seed for the noise.
    intersample : {"zoh", "foh", "bl"}
        The excitation between samples.

    Returns
    -------
    TimeData
        The input channels (named as in ``excitation``) followed by the outputs, in SI units.

    Examples
    --------
    >>> from cappe.model import NumericModel, load_model
    >>> system = NumericModel(load_model("builtin:two-mass-rig")).system()
    >>> force = TimeData.from_rate(1000.0, {"F1": [1.0] + [0.0] * 99})
    >>> data = time_response(system, force, outputs=["d1"])
    >>> data.channels
    ('F1', 'd1')
    """
    mapping = dict(inputs) if inputs is not None else {c: c for c in excitation.channels}
    for channel, name in mapping.items():
        excitation.index(channel)
        if name not in system.input_names:
            msg = (
                f"excitation channel {channel!r} maps to {name!r}, which is not an input of model "
                f"'{system.name}'; its inputs are {list(system.input_names)}"
            )
            raise DataError(msg)
    for what, value in (("noise", noise), ("input_noise", input_noise)):
        if not (np.isfinite(value) and value >= 0):
            msg = f"{what} must be a finite fraction >= 0 of each channel's RMS; got {value!r}"
            raise DataError(msg)
    out_names = list(system.output_names) if outputs is None else list(outputs)
    for name in out_names:
        if name not in system.output_names:
            msg = f"unknown output {name!r} for model '{system.name}'; its outputs are {list(system.output_names)}"
            raise DataError(msg)
    channels = list(mapping)
    model_inputs = [mapping[c] for c in channels]
    ss = system.state_space(model_inputs, out_names)
    u = excitation.values[[excitation.index(c) for c in channels]].T
    y, _ = ss.simulate(u, excitation.time, intersample=check_intersample(intersample))
    gen = as_generator(rng)
    recorded_u = _with_noise(u, input_noise, gen)
    recorded_y = _with_noise(y, noise, gen)
    units = [excitation.unit(c) or "N" for c in channels]
    quantities = dict(zip(system.output_names, system.output_quantities, strict=True))
    units += [OUTPUT_UNITS.get(quantities[name], "") for name in out_names]
    return TimeData(
        excitation.time,
        np.vstack([recorded_u.T, recorded_y.T]),
        tuple(channels) + tuple(out_names),
        tuple(units),
    )


def _with_noise(values: NDArray[np.float64], level: float, gen: np.random.Generator) -> NDArray[np.float64]:
    if level == 0:
        return values
    rms = np.sqrt(np.mean(values**2, axis=0))
    return np.asarray(values + level * rms * gen.standard_normal(values.shape), dtype=float)
