"""Reference data simulated from a model: exact modes at axis positions (with seeded noise) and FRFs.

This is what ``cappe simulate MODEL --params truth.json`` writes (cappe.modal/1, UFF 55, UFF 58) so that an
identification can be tested against a known truth (paper 3.1: the reference is simulated from the model).

Modes
-----
:func:`reference_modes` computes the exact complex modes (viscous, hysteretic and gyroscopic terms) at the
model's sensor channels at every requested position. Modes are tracked from position to position by
mass-weighted MAC (:meth:`ModalEngine.references`), so column ``r`` of every set is the same physical mode:
the ``r``-th lowest undamped mode at the *first* position. Rigid-body modes and modes that are not oscillatory
(overdamped) at some position are left out at every position; ``n_modes`` counts the remaining ones.

Noise
-----
Each quantity has its own random stream (spawned from ``rng``), so changing one noise level leaves the other
quantities' noise unchanged, and the same seed gives the same data:

* frequency ``f * (1 + noise_frequency * e)`` with ``e ~ N(0, 1)``;
* damping ratio ``zeta * (1 + noise_damping * e)``, ``e ~ N(0, 1)``;
* each shape component ``phi_i + noise_shape * max_j |phi_j| * (e1 + 1j e2) / sqrt(2)`` with ``e1, e2 ~ N(0, 1)``:
  circular complex noise whose RMS modulus is ``noise_shape`` times the mode's largest component.

A factor that would make a frequency or damping ratio non-positive (or a damping ratio >= 1) is redrawn
(rejection sampling, i.e. a normal distribution truncated there). At the intended levels (a few per cent) this never
happens in practice (``1 + 0.05 e <= 0`` needs ``e <= -20``), so the relative standard deviation is the setting.

FRFs
----
:func:`reference_frf` gives the exact receptances ``(K + 1j H + 1j omega (C + G) - omega^2 M)^-1`` from chosen
driving points (model inputs, or unit forces at sensor channels) to the sensor channels or to model outputs.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import sympy as sp
from numpy.typing import ArrayLike, NDArray

from cappe._rng import RandomLike, as_generator
from cappe.exceptions import DataError
from cappe.modal._batch import pole_damping
from cappe.modal._engine import ModalEngine
from cappe.model.numeric import NumericModel, ParamsLike
from cappe.model.structure import Structure
from cappe.systems.frf import FRFData
from cappe.systems.modal import ModalData, ModalDataSet

__all__ = ["axis_positions", "reference_frf", "reference_modes", "sensor_coordinates"]

Array = NDArray[np.float64]
#: Rounds of redrawing a noise factor that left the admissible range before giving up.
MAX_REDRAWS = 100


def _numeric(model: NumericModel | Structure) -> NumericModel:
    if isinstance(model, NumericModel):
        return model
    if isinstance(model, Structure):
        return NumericModel(model)
    msg = f"model must be a NumericModel or a Structure; got {type(model).__name__}"
    raise DataError(msg)


def axis_positions(model: NumericModel | Structure) -> list[dict[str, float]]:
    """Every combination of the axis positions listed in a model (one empty position for a model without axes).

    An axis that lists no positions stays at 0.

    Parameters
    ----------
    model : NumericModel or Structure
        The model.

    Returns
    -------
    list of dict
        ``{axis: value}`` (m or rad) for every combination.

    Examples
    --------
    >>> from cappe.model import load_model
    >>> axis_positions(load_model("builtin:two-mass-rig"))
    [{}]
    """
    structure = model.structure if isinstance(model, NumericModel) else model
    names = [a.name for a in structure.axes]
    values = [a.positions or (0.0,) for a in structure.axes]
    return [dict(zip(names, (float(v) for v in combo), strict=True)) for combo in itertools.product(*values)]


def _positions(
    nm: NumericModel, positions: Sequence[Mapping[str, float]] | Mapping[str, float] | str | None
) -> list[dict[str, float]]:
    if positions is None:
        return [nm.structure.default_position()]
    if isinstance(positions, str):
        if positions != "all":
            msg = f"positions must be 'all', a list of axis positions or None; got {positions!r}"
            raise DataError(msg)
        return axis_positions(nm)
    if isinstance(positions, Mapping):
        positions = [positions]
    out = [nm.structure.resolve_position(p) for p in positions]
    if not out:
        msg = "positions must list at least one axis position; got an empty list"
        raise DataError(msg)
    return out


def _level(value: float, name: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError) as exc:
        msg = f"{name} must be a number >= 0 (relative standard deviation); got {value!r}"
        raise DataError(msg) from exc
    if not math.isfinite(number) or number < 0:
        msg = f"{name} must be a finite number >= 0 (relative standard deviation); got {value!r}"
        raise DataError(msg)
    return number


def _factors(
    gen: np.random.Generator, base: Array, level: float, upper: float, what: str
) -> Array:
    """Factors ``1 + level * e`` with ``factor > 0`` and ``base * factor < upper``; inadmissible ones are redrawn."""
    factor = 1.0 + level * gen.standard_normal(base.shape)
    for _ in range(MAX_REDRAWS):
        value = base * factor
        bad = (factor <= 0) | (value >= upper)
        if not np.any(bad):
            return factor
        factor[bad] = 1.0 + level * gen.standard_normal(int(bad.sum()))
    msg = f"{what} noise level {level:g} keeps drawing non-physical values; use a smaller level"
    raise DataError(msg)


def _mode_count(n_modes: int | None, available: int, nm: NumericModel) -> int:
    if n_modes is None:
        return available
    if isinstance(n_modes, bool) or not isinstance(n_modes, (int, np.integer)) or n_modes < 1:
        msg = f"n_modes must be a positive integer or None (all modes); got {n_modes!r}"
        raise DataError(msg)
    if n_modes > available:
        msg = (
            f"n_modes = {n_modes} exceeds the {available} oscillatory modes that model '{nm.structure.name}' has at "
            f"every requested position ({nm.n_dof} DOFs; rigid-body and overdamped modes are left out)"
        )
        raise DataError(msg)
    return int(n_modes)


def no_sensors_message(structure: Structure) -> str:
    """What to do about a model without sensor nodes, where modes are compared at sensor channels ``NODE:DIR``."""
    body = structure.bodies[0].name if structure.bodies else "BODY"
    return (f"model '{structure.name}' has no sensor nodes (no 'sensors:' list); add one to the model file, e.g. "
            f"'sensors: [{{name: s1, body: {body}}}]' (a node at the body's origin, channels s1:x s1:y s1:z)")


def reference_modes(
    model: NumericModel | Structure,
    *,
    params: ParamsLike = None,
    positions: Sequence[Mapping[str, float]] | Mapping[str, float] | str | None = None,
    n_modes: int | None = None,
    sensors: Sequence[str] | str | None = None,
    noise_frequency: float = 0.0,
    noise_damping: float = 0.0,
    noise_shape: float = 0.0,
    rng: RandomLike = None,
) -> ModalData:
    """Exact modes of a model at its sensor channels at axis positions, optionally with seeded noise.

    Parameters
    ----------
    model : NumericModel or Structure
        The model (a Structure is compiled).
    params : mapping, array (n_params,) or None
        The true parameter values: a mapping overrides the nominal values by name (parameters it leaves out keep
        theirs; unknown names raise :class:`~cappe.exceptions.ModelError`), an array gives them all in
        ``model.parameter_names`` order.
    positions : sequence of mappings, mapping, "all" or None
        Axis positions, e.g. ``[{"z": -0.294}, {"z": 0.135}]`` (axes left out stay at their default);
        ``"all"``: every combination of the model's listed axis positions; ``None``: the default position.
    n_modes : int or None
        Number of modes per position: the lowest ``n_modes`` at the first position, tracked to the others
        (default all oscillatory modes).
    sensors : sequence of str, "dofs" or None
        Channels: ``"node:x"`` labels or node names (all three directions); ``None``: every channel of every sensor
        node of the model; ``"dofs"``: the generalized coordinates.
    noise_frequency, noise_damping, noise_shape : float
        Relative noise levels (standard deviations, e.g. 0.005, 0.05, 0.02); see the module notes.
    rng : int, numpy Generator or None
        Seed of the noise.

    Returns
    -------
    ModalData
        One set per position, frequencies in Hz (``|lambda| / 2 pi``), damping ratios ``-Re(lambda) / |lambda|``
        and complex shapes (sensors x modes) scaled so that ``phi^T M psi = 1`` with the mass-normalized real mode.

    Examples
    --------
    >>> from cappe.model import load_model
    >>> ref = reference_modes(load_model("builtin:two-mass-rig"), params={"k12": 0.2e6})
    >>> ref.sensors[:3], ref.sets[0].frequency.round(1)
    (('n1:x', 'n1:y', 'n1:z'), array([ 96.7, 172.2]))
    """
    nm = _numeric(model)
    level_f = _level(noise_frequency, "noise_frequency")
    level_d = _level(noise_damping, "noise_damping")
    level_s = _level(noise_shape, "noise_shape")
    if sensors is None and not nm.structure.sensors:
        msg = f"{no_sensors_message(nm.structure)} (in Python, sensors='dofs' gives the shapes at the DOFs)"
        raise DataError(msg)
    pos = _positions(nm, positions)
    engine = ModalEngine(nm, sensors=sensors)
    references = engine.references(pos, params)
    batches = [engine.evaluate(params, p, track=ref, exact=True) for p, ref in zip(pos, references, strict=True)]
    poles = np.array([np.asarray(b.poles)[0] for b in batches])  # (n_sets, n_dof)
    columns = np.flatnonzero(np.all(np.isfinite(poles) & (np.abs(poles) > 0), axis=0))
    columns = columns[: _mode_count(n_modes, columns.size, nm)]

    streams = as_generator(rng).spawn(3)
    sets = []
    for p, batch, lam in zip(pos, batches, poles, strict=True):
        w = np.abs(lam[columns])
        freq = w / (2 * np.pi)
        zeta = pole_damping(lam[columns])
        shapes = np.asarray(batch.complex_shapes)[0][:, columns]
        freq = freq * _factors(streams[0], freq, level_f, math.inf, "noise_frequency")
        zeta = zeta * _factors(streams[1], zeta, level_d, 1.0, "noise_damping")
        e = streams[2].standard_normal((2, *shapes.shape))
        scale = level_s * np.max(np.abs(shapes), axis=0) / math.sqrt(2.0)
        shapes = shapes + scale[None, :] * (e[0] + 1j * e[1])
        sets.append(ModalDataSet(dict(p), freq, zeta, shapes))
    return ModalData(engine.sensors, tuple(sets), nm.structure.name)


def sensor_coordinates(
    model: NumericModel | Structure, *, params: ParamsLike = None, position: Mapping[str, float] | None = None
) -> dict[str, tuple[float, float, float]]:
    """Global coordinates (m) of the model's sensor nodes at a parameter vector and axis position.

    A sensor's point is given in its body's frame relative to the body's origin, whose nominal global position may
    depend on the axes; the sum is the node's location in the global frame.

    Parameters
    ----------
    model : NumericModel or Structure
        The model.
    params : array (n_params,), mapping or None
        One parameter vector (SI; default nominal).
    position : mapping or None
        Axis position in m or rad.

    Returns
    -------
    dict
        ``{sensor name: (x, y, z)}`` in m.

    Raises
    ------
    DataError
        ``params`` is a batch.

    Examples
    --------
    >>> from cappe.model import load_model
    >>> sensor_coordinates(load_model("builtin:two-mass-rig"))
    {'n1': (0.0, 0.0, 0.0), 'n2': (0.0, 0.0, 0.0)}
    """
    nm = _numeric(model)
    p = nm.vector(params)
    if p.ndim != 1:
        msg = f"params must be a single parameter vector; got shape {p.shape}"
        raise DataError(msg)
    symbols = nm.symbolic.symbols
    subs: dict[Any, float] = {symbols[n]: float(v) for n, v in zip(nm.parameter_names, p, strict=True)}
    subs.update({symbols[a]: v for a, v in zip(nm.axis_names, nm.position_vector(position), strict=True)})
    out: dict[str, tuple[float, float, float]] = {}
    for sensor in nm.structure.sensors:
        s = nm.structure
        origin = s.flexible_body(sensor.body).position if s.is_flexible(sensor.body) else s.body(sensor.body).position
        xyz = [float(sp.sympify(o + q).xreplace(subs)) for o, q in zip(origin, sensor.point, strict=True)]
        out[sensor.name] = (xyz[0], xyz[1], xyz[2])
    return out


def _names(items: Sequence[str] | str | None, what: str) -> list[str] | None:
    if items is None:
        return None
    names = [items] if isinstance(items, str) else list(items)
    if not names:
        msg = f"{what} must name at least one channel; got an empty list"
        raise DataError(msg)
    seen = [n for k, n in enumerate(names) if n in names[:k]]
    if seen:
        msg = f"{what} name {seen[0]!r} twice"
        raise DataError(msg)
    return names


def reference_frf(
    model: NumericModel | Structure,
    *,
    freq: ArrayLike,
    params: ParamsLike = None,
    position: Mapping[str, float] | None = None,
    inputs: Sequence[str] | str | None = None,
    outputs: Sequence[str] | str | None = None,
) -> FRFData:
    """Exact FRFs of a model from driving points to its sensor channels (or to model outputs).

    Parameters
    ----------
    model : NumericModel or Structure
        The model.
    freq : array_like, shape (n_freq,)
        Frequencies in Hz (>= 0).
    params : mapping, array or None
        Parameter values (mapping: overrides of the nominal values by name).
    position : mapping or None
        Axis position (default: the model's default position).
    inputs : sequence of str or None
        Driving points: model input names (their force or moment), or sensor channel labels ``"node:x"`` (a unit
        force at that sensor node along the global direction: the driving point of an impact test). Default: all
        model inputs.
    outputs : sequence of str or None
        Responses: model output names (with their quantity: displacement, velocity, acceleration or elongation),
        sensor channel labels ``"node:x"`` or sensor node names (x, y and z), tried in that order. Default: every
        sensor channel (displacement), or every model output when the model has no sensors.

    Returns
    -------
    FRFData
        ``H[out, in, freq]`` in m/N (displacement; velocity and acceleration outputs in m/s/N and m/s^2/N).

    Examples
    --------
    >>> from cappe.model import load_model
    >>> frf = reference_frf(load_model("builtin:two-mass-rig"), freq=[0.0], inputs=["n1:x"], outputs=["n1:x", "d1"])
    >>> frf.output_names, bool(abs(frf.H[0, 0, 0] - frf.H[1, 0, 0]) < 1e-18)
    (('n1:x', 'd1'), True)
    """
    nm = _numeric(model)
    f = np.atleast_1d(np.asarray(freq, dtype=float))
    if f.ndim != 1 or f.size == 0 or not np.all(np.isfinite(f)) or np.any(f < 0):
        msg = f"freq must be a non-empty 1-D array of finite frequencies >= 0 Hz; got shape {f.shape}"
        raise DataError(msg)
    system = nm.system(params, position)
    if nm.structure.sensors:
        labels, rows = nm.sensor_matrix(params, position)
    else:
        labels, rows = [], np.zeros((0, nm.n_dof))
    index = {label: k for k, label in enumerate(labels)}
    nodes = [s.name for s in nm.structure.sensors]

    in_names = _names(inputs, "inputs") or list(system.input_names)
    if not in_names:
        msg = (
            f"model '{nm.structure.name}' has no inputs; name the driving points as sensor channels "
            f"({', '.join(labels[:3]) or 'none'}, ...)"
        )
        raise DataError(msg)
    columns = []
    for name in in_names:
        if name in system.input_names:
            columns.append(system.B[:, system.input_names.index(name)])
        elif name in index:
            columns.append(rows[index[name]])  # unit force along the sensor direction: generalized force R^T e
        else:
            msg = (
                f"driving point {name!r} is neither an input of model '{nm.structure.name}' "
                f"({', '.join(system.input_names) or 'none'}) nor a sensor channel ({', '.join(labels) or 'none'})"
            )
            raise DataError(msg)

    out_items = _names(outputs, "outputs")
    if out_items is None:
        out_items = labels or list(system.output_names)
    out_names: list[str] = []
    out_rows: list[Array] = []
    quantities: list[str] = []
    for name in out_items:
        if name in system.output_names:
            k = system.output_names.index(name)
            out_names.append(name)
            out_rows.append(system.S[k])
            quantities.append(system.output_quantities[k])
        elif name in index or name in nodes:
            picked = [name] if name in index else [f"{name}:{d}" for d in "xyz"]
            out_names.extend(picked)
            out_rows.extend(rows[index[label]] for label in picked)
            quantities.extend("displacement" for _ in picked)
        else:
            msg = (
                f"output {name!r} is neither an output of model '{nm.structure.name}' "
                f"({', '.join(system.output_names) or 'none'}) nor a sensor channel or node "
                f"({', '.join(labels) or 'none'})"
            )
            raise DataError(msg)
    if len(set(out_names)) != len(out_names):
        msg = f"outputs name the same channel twice: {out_names}"
        raise DataError(msg)
    driven = dataclasses.replace(
        system,
        B=np.column_stack(columns),
        S=np.vstack(out_rows),
        input_names=tuple(in_names),
        output_names=tuple(out_names),
        output_quantities=tuple(quantities),
    )
    result: FRFData = driven.frf(f)
    return result
