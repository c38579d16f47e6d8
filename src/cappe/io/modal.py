"""Modal data files (``"format": "cappe.modal/1"``): reference or measured modes at axis positions.

::

    {"format": "cappe.modal/1",
     "sensors": ["tool:x", "tool:y", ...],
     "sets": [{"position": {"z": -0.294}, "frequency": [Hz, ...], "damping": [ratio, ...],
               "shape_re": [[per sensor] per mode], "shape_im": [[...] per mode],
               "frequency_std": [Hz, ...], "damping_std": [ratio, ...], "shape_std": [[per sensor] per mode]},
              ...]}

``shape_im`` may be omitted for real shapes. The standard deviations are optional (written by ``cappe
extract-modes``, estimated from the measured data); each is >= 0; ``cappe identify`` weights its residuals by them.
The data types, :class:`~cappe.systems.ModalData` and :class:`~cappe.systems.ModalDataSet`, live in
:mod:`cappe.systems.modal`; this module reads, validates and writes them (and hands them on under their old names,
``cappe.io.modal.ModalData``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cappe.exceptions import DataError
from cappe.io.files import finite_number, read_json, shown, write_json
from cappe.systems.modal import MODAL_FORMAT, ModalData, ModalDataSet

__all__ = [
    "MODAL_FORMAT",
    "ModalData",
    "ModalDataSet",
    "modal_data_from_mapping",
    "read_modal_data",
    "write_modal_data",
]


def _where(source: str, entry: str) -> str:
    return f"({source}, {entry})" if source else f"({entry})"


def _number(value: object, what: str, source: str) -> float:
    number = finite_number(value)
    if number is None:
        msg = f"{what} must be a finite number; got {shown(value)} {_where(source, what)}"
        raise DataError(msg)
    return number


def _numbers(value: object, what: str, source: str, *, length: int | None = None) -> NDArray[np.float64]:
    if isinstance(value, np.ndarray) and value.ndim == 1:
        value = value.tolist()
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
        msg = f"{what} must be a list of numbers; got {type(value).__name__} {_where(source, what)}"
        raise DataError(msg)
    if length is not None and len(value) != length:
        msg = f"{what} must list {length} number(s); got {len(value)} {_where(source, what)}"
        raise DataError(msg)
    return np.array([_number(v, f"{what}[{k}]", source) for k, v in enumerate(value)], dtype=float)


def _required(raw: Mapping[str, Any], key: str, entry: str, source: str) -> Any:
    if raw.get(key) is None:
        msg = f"{entry}.{key} is missing {_where(source, entry)}"
        raise DataError(msg)
    return raw[key]


def _non_negative(value: object, what: str, source: str, *, length: int) -> NDArray[np.float64]:
    values = _numbers(value, what, source, length=length)
    if np.any(values < 0):
        msg = f"{what} must be >= 0 (standard deviations) {_where(source, what)}"
        raise DataError(msg)
    return values


def _standard_deviations(
    raw: Mapping[str, Any], entry: str, source: str, m: int, n_s: int
) -> tuple[NDArray[np.float64] | None, NDArray[np.float64] | None, NDArray[np.float64] | None]:
    """The optional ``frequency_std``, ``damping_std`` (one per mode) and ``shape_std`` (per mode, per sensor)."""
    freq_std = damping_std = shape_std = None
    if raw.get("frequency_std") is not None:
        freq_std = _non_negative(raw["frequency_std"], f"{entry}.frequency_std", source, length=m)
    if raw.get("damping_std") is not None:
        damping_std = _non_negative(raw["damping_std"], f"{entry}.damping_std", source, length=m)
    rows = raw.get("shape_std")
    if rows is not None:
        if isinstance(rows, (str, bytes)) or not isinstance(rows, Sequence) or len(rows) != m:
            msg = f"{entry}.shape_std must list one row per mode ({m}) {_where(source, entry)}"
            raise DataError(msg)
        shape_std = np.array(
            [_non_negative(row, f"{entry}.shape_std[{r}]", source, length=n_s) for r, row in enumerate(rows)]
        ).T.reshape(n_s, m)
    return freq_std, damping_std, shape_std


def modal_data_from_mapping(data: Mapping[str, Any], source: str = "") -> ModalData:
    """Validate a parsed ``cappe.modal/1`` document; every error names ``source`` and the entry.

    Parameters
    ----------
    data : mapping
        The parsed document (``format``, ``sensors``, ``sets`` with frequencies in Hz, damping ratios and shapes).
    source : str
        Where it came from (a file name), for messages.

    Returns
    -------
    ModalData

    Raises
    ------
    DataError
        The document breaks a rule of the format.
    """
    if not isinstance(data, Mapping) or data.get("format") != MODAL_FORMAT:
        got = data.get("format") if isinstance(data, Mapping) else type(data).__name__
        msg = f"modal data must have \"format\": \"{MODAL_FORMAT}\"; got {shown(got)} {_where(source, 'format')}"
        raise DataError(msg)
    sensors = data.get("sensors")
    if not isinstance(sensors, Sequence) or isinstance(sensors, str) or not sensors or \
            not all(isinstance(s, str) for s in sensors):
        msg = f"sensors must be a non-empty list of channel labels like 'node:x' {_where(source, 'sensors')}"
        raise DataError(msg)
    if len(set(sensors)) != len(sensors):
        msg = f"sensors must be unique {_where(source, 'sensors')}"
        raise DataError(msg)
    raw_sets = data.get("sets")
    if not isinstance(raw_sets, Sequence) or isinstance(raw_sets, str) or not raw_sets:
        msg = f"sets must be a non-empty list {_where(source, 'sets')}"
        raise DataError(msg)
    sets = []
    n_s = len(sensors)
    for k, raw in enumerate(raw_sets):
        entry = f"sets[{k}]"
        if not isinstance(raw, Mapping):
            msg = f"{entry} must be a mapping {_where(source, entry)}"
            raise DataError(msg)
        position = raw.get("position", {})
        if not isinstance(position, Mapping):
            msg = f"{entry}.position must be a mapping axis -> value {_where(source, entry)}"
            raise DataError(msg)
        pos = {str(a): _number(v, f"{entry}.position.{a}", source) for a, v in position.items()}
        freq = _numbers(_required(raw, "frequency", entry, source), f"{entry}.frequency", source)
        m = freq.size
        if m == 0:
            msg = f"{entry}.frequency must list at least one mode {_where(source, entry)}"
            raise DataError(msg)
        if np.any(freq <= 0):
            msg = f"{entry}.frequency must be > 0 Hz {_where(source, entry)}"
            raise DataError(msg)
        damping = _numbers(_required(raw, "damping", entry, source), f"{entry}.damping", source, length=m)
        if np.any(damping < 0) or np.any(damping >= 1):
            msg = f"{entry}.damping ratios must lie in [0, 1) {_where(source, entry)}"
            raise DataError(msg)
        shapes = np.zeros((n_s, m), dtype=complex)
        for part, name in ((1.0, "shape_re"), (1j, "shape_im")):
            rows = raw.get(name)
            if rows is None and name == "shape_im":
                continue
            if isinstance(rows, (str, bytes)) or not isinstance(rows, Sequence) or len(rows) != m:
                msg = f"{entry}.{name} must list one shape per mode ({m}) {_where(source, entry)}"
                raise DataError(msg)
            for r, row in enumerate(rows):
                shapes[:, r] += part * _numbers(row, f"{entry}.{name}[{r}]", source, length=n_s)
        stds = _standard_deviations(raw, entry, source, m, n_s)
        sets.append(ModalDataSet(pos, freq, damping, shapes, *stds))
    return ModalData(tuple(sensors), tuple(sets), source)


def read_modal_data(path: str | Path) -> ModalData:
    """Read and validate a ``cappe.modal/1`` JSON file.

    Parameters
    ----------
    path : str or Path
        The file to read.

    Returns
    -------
    ModalData

    Raises
    ------
    DataError
        When the file cannot be read or parsed (:func:`cappe.io.files.read_json`) or breaks a rule of the format;
        the message names the file and the entry (``sets[2].frequency[0]``).
    """
    p = Path(path)
    return modal_data_from_mapping(read_json(p, "modal data file"), str(p))


def write_modal_data(path: str | Path, data: ModalData) -> None:
    """Write modal data atomically as ``cappe.modal/1`` JSON.

    Parameters
    ----------
    path : str or Path
        The file to write.
    data : ModalData
        The modes.
    """
    write_json(path, data.to_dict())
