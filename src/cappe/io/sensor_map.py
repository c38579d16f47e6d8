"""Sensor maps: measured channels to model sensor channels, with the sign of the measured direction.

A sensor map is a CSV file with the header ``channel,sensor``; each row names a channel as the data file gives it
(a UFF ``NODE:±DIR`` label such as ``5:-z``, a CSV column, an ID-line name) and the model's sensor channel
``NODE:DIR`` it measures::

    channel,sensor
    5:-z,table_fl:z
    5:+x,table_fl:x

A channel measured in a negative direction (UFF direction code -3, read as ``5:-z``) maps to the model's positive
direction with its sign flipped. A sign written in the sensor column states the measured direction on the model
and takes precedence (``5:+z,table_fl:-z`` flips; ``5:-z,table_fl:+z`` does not). The same rule applies without a map: a
channel label with a negative direction is never kept as it is (:func:`channel_sign`).
"""

from __future__ import annotations

import csv
import re
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from cappe.exceptions import DataError
from cappe.systems.frf import FRFData
from cappe.systems.modal import ModalData
from cappe.systems.timedata import TimeData

__all__ = ["apply_sensor_map", "channel_sign", "map_channels", "map_modal_data", "map_time_data", "read_sensor_map"]

_SIGNED = re.compile(r"^(?P<node>.+):(?P<sign>[+-]?)(?P<dir>x|y|z|rx|ry|rz)$")


def channel_sign(label: str) -> tuple[str, float]:
    """A channel label without its direction's sign, and the sign: ``"5:-z"`` -> ``("5:z", -1.0)``.

    Parameters
    ----------
    label : str
        A channel label; ``NODE:±DIR`` labels (directions x, y, z, rx, ry, rz) lose their sign, others are kept.

    Returns
    -------
    name : str
        ``NODE:DIR`` (or the label unchanged when it has no direction).
    sign : float
        -1.0 for a negative direction, else 1.0.

    Examples
    --------
    >>> channel_sign("5:-z"), channel_sign("table:x"), channel_sign("Mic 01")
    (('5:z', -1.0), ('table:x', 1.0), ('Mic 01', 1.0))
    """
    m = _SIGNED.match(label.strip())
    if m is None:
        return label.strip(), 1.0
    return f"{m['node']}:{m['dir']}", -1.0 if m["sign"] == "-" else 1.0


def read_sensor_map(path: str | Path) -> dict[str, str]:
    """Read a ``channel,sensor`` CSV file.

    Parameters
    ----------
    path : str or Path
        The CSV file (header ``channel,sensor``, one row per measured channel).

    Returns
    -------
    dict
        ``{channel: sensor}`` as written (signs kept; :func:`map_channels` applies them).

    Raises
    ------
    DataError
        The file is missing, lacks the header, or a row is empty, repeats a channel or maps two channels to one
        sensor; the message names the file and the line.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except OSError as exc:
        msg = f"cannot read sensor map {p}: {exc.strerror or exc}"
        raise DataError(msg) from exc
    rows = list(csv.reader(text.splitlines()))
    if not rows or [c.strip().lower() for c in rows[0]] != ["channel", "sensor"]:
        got = ",".join(rows[0]) if rows else ""
        msg = f"sensor map {p} must start with the header 'channel,sensor'; got {got!r} (line 1)"
        raise DataError(msg)
    out: dict[str, str] = {}
    seen: dict[str, int] = {}
    for line, row in enumerate(rows[1:], start=2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != 2 or not row[0].strip() or not row[1].strip():
            msg = (f"sensor map {p}, line {line}: a row must be CHANNEL,SENSOR (e.g. 5:-z,table_fl:z); "
                   f"got {','.join(row)!r}")
            raise DataError(msg)
        channel, sensor = row[0].strip(), row[1].strip()
        if channel in out:
            msg = f"sensor map {p}, line {line}: channel {channel!r} is mapped twice"
            raise DataError(msg)
        target = channel_sign(sensor)[0]
        if target in seen:
            msg = f"sensor map {p}, line {line}: sensor {target!r} is already measured by line {seen[target]}"
            raise DataError(msg)
        seen[target] = line
        out[channel] = sensor
    if not out:
        msg = f"sensor map {p} has no rows under its header"
        raise DataError(msg)
    return out


def map_channels(names: Sequence[str], mapping: Mapping[str, str] | None) -> list[tuple[str | None, float]]:
    """Per channel: the model sensor channel it measures (None when the map leaves it out) and the sign to apply.

    A channel matches a map entry by its exact label or by its label with the direction's sign normalized
    (``5:z`` and ``5:+z`` are one channel). The sign is the sensor column's when it has one, else the channel's.
    Without a map every channel is kept, a negative direction flipped.

    Parameters
    ----------
    names : sequence of str
        Channel labels as the data file gives them.
    mapping : mapping channel -> sensor, optional
        A sensor map (:func:`read_sensor_map`).

    Returns
    -------
    list of (str or None, float)
        ``(sensor, sign)`` per channel: ``value_at_sensor = sign * measured_value``.

    Examples
    --------
    >>> map_channels(["5:-z", "6:+x", "7:y"], {"5:-z": "table:z", "6:x": "bed:x"})
    [('table:z', -1.0), ('bed:x', 1.0), (None, 1.0)]
    """
    if mapping is None:
        return [channel_sign(n) for n in names]
    keyed: dict[tuple[str, float], str] = {}
    for channel, mapped in mapping.items():
        keyed[channel_sign(channel)] = mapped
    out: list[tuple[str | None, float]] = []
    for name in names:
        sensor = mapping.get(name)
        key = channel_sign(name)
        if sensor is None:
            sensor = keyed.get(key)
        if sensor is None:
            out.append((None, 1.0))
            continue
        target, target_sign = channel_sign(sensor)
        explicit = (m := _SIGNED.match(sensor.strip())) is not None and bool(m["sign"])
        out.append((target, target_sign if explicit else key[1]))
    return out


def apply_sensor_map(frf: FRFData, mapping: Mapping[str, str] | None,
                     source: str = "") -> tuple[FRFData, list[str]]:
    """FRFs at model sensor channels: outputs and inputs renamed by the map, negative directions sign-flipped.

    Parameters
    ----------
    frf : FRFData
        Measured FRFs with the data file's channel labels.
    mapping : mapping channel -> sensor, optional
        A sensor map; None only normalizes negative directions (``5:-z`` -> ``5:z``, sign flipped).
    source : str
        The map's file name, for messages.

    Returns
    -------
    frf : FRFData
        The outputs the map names (all without a map), renamed; inputs it names are renamed too.
    notes : list of str
        One line per change a user should see (flipped channels, channels left out).

    Raises
    ------
    DataError
        No output of the FRFs is in the map, or two outputs map to one sensor.
    """
    where = f" ({source})" if source else ""
    outs = map_channels(frf.output_names, mapping)
    ins = map_channels(frf.input_names, mapping)
    keep = [k for k, (s, _) in enumerate(outs) if s is not None]
    if not keep:
        msg = (f"sensor map{where} names none of the FRF outputs {list(frf.output_names)[:6]}"
               f"{' ...' if len(frf.output_names) > 6 else ''}")
        raise DataError(msg)
    names = [outs[k][0] for k in keep]
    doubled = sorted({n for n in names if names.count(n) > 1 and n is not None})
    if doubled:
        msg = f"sensor map{where}: outputs {doubled} are each measured by two channels"
        raise DataError(msg)
    out_sign = np.array([outs[k][1] for k in keep])
    in_sign = np.array([s for _, s in ins])
    in_names = tuple(s if s is not None else n for (s, _), n in zip(ins, frf.input_names, strict=True))
    H = frf.H[keep] * out_sign[:, None, None] * in_sign[None, :, None]
    coherence = frf.coherence[keep] if frf.coherence is not None else None
    quantities = tuple(frf.output_quantities[k] for k in keep) if frf.output_quantities else ()
    notes = []
    flipped = [frf.output_names[k] for k in keep if outs[k][1] < 0]
    flipped += [n for n, (_, s) in zip(frf.input_names, ins, strict=True) if s < 0]
    if flipped:
        notes.append(f"{len(flipped)} channel(s) measured in a negative direction, sign flipped to the model's "
                     f"positive direction: {', '.join(flipped[:8])}{' ...' if len(flipped) > 8 else ''}")
    dropped = [frf.output_names[k] for k, (s, _) in enumerate(outs) if s is None]
    if dropped:
        notes.append(f"warning: {len(dropped)} output channel(s) not in the sensor map{where} left out: "
                     f"{', '.join(dropped[:8])}{' ...' if len(dropped) > 8 else ''}")
    mapped = replace(frf, H=H, output_names=tuple(n for n in names if n is not None), input_names=in_names,
                     coherence=coherence, output_quantities=quantities)
    return mapped, notes


def map_modal_data(data: ModalData, mapping: Mapping[str, str] | None,
                   source: str = "") -> tuple[ModalData, list[str]]:
    """Modal data at model sensor channels: sensors renamed by the map, negative directions sign-flipped.

    Parameters
    ----------
    data : ModalData
        Modes at the data file's channel labels.
    mapping : mapping channel -> sensor, optional
        A sensor map; None only normalizes negative directions.
    source : str
        The map's file name, for messages.

    Returns
    -------
    data : ModalData
        The modes at the sensors the map names (all without a map).
    notes : list of str
        One line per change a user should see.

    Raises
    ------
    DataError
        No sensor of the data is in the map.
    """
    keep, names, sign, notes = _selection(data.sensors, mapping, source, "sensor")
    sets = [replace(s, shapes=s.shapes[keep] * sign[:, None]) for s in data.sets]
    return ModalData(tuple(names), tuple(sets), data.source), notes


def map_time_data(data: TimeData, mapping: Mapping[str, str] | None,
                  source: str = "") -> tuple[TimeData, list[str]]:
    """Time data at model channels: channels renamed by the map, negative directions sign-flipped.

    Parameters
    ----------
    data : TimeData
        Measured time data with the data file's channel labels.
    mapping : mapping channel -> sensor, optional
        A sensor map (forces and responses alike); None only normalizes negative directions.
    source : str
        The map's file name, for messages.

    Returns
    -------
    data : TimeData
        The channels the map names (all without a map), renamed.
    notes : list of str
        One line per change a user should see.

    Raises
    ------
    DataError
        No channel of the data is in the map, or two channels map to one.

    Examples
    --------
    >>> data = TimeData.from_channels([0.0, 0.1], {"1:-x": [1.0, 2.0], "7:y": [3.0, 4.0], "9:z": [0.0, 0.0]})
    >>> mapped, notes = map_time_data(data, {"1:-x": "fx", "7:y": "sy"})
    >>> mapped.channels, mapped.values[0].tolist()
    (('fx', 'sy'), [-1.0, -2.0])
    """
    keep, names, sign, notes = _selection(data.channels, mapping, source, "channel")
    units = tuple(data.units[k] for k in keep) if data.units else ()
    return replace(data, values=data.values[keep] * sign[:, None], channels=tuple(names), units=units), notes


def _selection(labels: Sequence[str], mapping: Mapping[str, str] | None, source: str,
               noun: str) -> tuple[list[int], list[str], NDArray[np.float64], list[str]]:
    """The rows a sensor map keeps: their indices, model names and signs, and the notes a user should see.

    One rule for every data type: no row kept, or two rows mapped to one model channel, is an error; a negative
    direction is flipped and said; rows not in the map are left out with a warning."""
    where = f" ({source})" if source else ""
    rows = map_channels(labels, mapping)
    keep = [k for k, (s, _) in enumerate(rows) if s is not None]
    if not keep:
        msg = f"sensor map{where} names none of the {noun}s {list(labels)[:6]}"
        raise DataError(msg)
    names = [str(rows[k][0]) for k in keep]
    doubled = sorted({n for n in names if names.count(n) > 1})
    if doubled:
        msg = f"sensor map{where}: {doubled} are each given by two {noun}s of the data"
        raise DataError(msg)
    notes = []
    flipped = [labels[k] for k in keep if rows[k][1] < 0]
    if flipped:
        notes.append(f"{len(flipped)} {noun}(s) measured in a negative direction, sign flipped: "
                     f"{', '.join(flipped[:8])}{' ...' if len(flipped) > 8 else ''}")
    dropped = [labels[k] for k, (s, _) in enumerate(rows) if s is None]
    if dropped:
        notes.append(f"warning: {len(dropped)} {noun}(s) not in the sensor map{where} left out: "
                     f"{', '.join(dropped[:8])}{' ...' if len(dropped) > 8 else ''}")
    return keep, names, np.array([rows[k][1] for k in keep], dtype=float), notes
