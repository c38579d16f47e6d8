"""LabVIEW measurement files (``.lvm``, text): time data as LabVIEW's "Write To Measurement File" writes it.

The layout (National Instruments, "Specification for the LabVIEW Measurement File"): a file header of
``key<TAB>value`` lines between ``LabVIEW Measurement`` and ``***End_of_Header***`` (``Separator``: Tab or Comma,
``Decimal_Separator``: ``.`` or ``,``, ``X_Columns``: No, One or Multi), then a segment: a header with one value
per channel (``Channels``, ``Samples``, ``Y_Unit_Label``, ``X0``, ``Delta_X``) closed by ``***End_of_Header***``, a
column-name row (``X_Value``, the channel names, ``Comment``) and one row per sample.

Read here: one segment, uniformly sampled (time from ``X0`` and ``Delta_X``, which must agree over the channels),
with any separator and decimal mark. Not read, each with its own error: files of several segments (separate
acquisitions appended to one file: split them first) and ``X_Columns`` Multi (one time column per channel).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cappe.exceptions import DataError
from cappe.io.files import read_text_file, shown
from cappe.systems.timedata import TimeData

__all__ = ["read_lvm_time_data"]

_END = "***End_of_Header***"
#: The largest LVM file read (bytes), as for CSV.
MAX_LVM_BYTES = 1024 * 2**20


def _fields(line: str, sep: str) -> list[str]:
    return [c.strip() for c in line.rstrip("\r\n").split(sep)]


def _number(text: str, decimal: str, where: str) -> float:
    try:
        value = float(text.replace(decimal, ".") if decimal != "." else text)
    except ValueError as exc:
        msg = f"{where}: {shown(text)} is not a number (decimal separator {decimal!r})"
        raise DataError(msg) from exc
    if not np.isfinite(value):
        msg = f"{where}: {shown(text)} is not a finite number"
        raise DataError(msg)
    return value


def read_lvm_time_data(path: str | Path) -> TimeData:
    """Read the time data of a LabVIEW measurement file (``.lvm``).

    Channel names come from the column-name row, units from ``Y_Unit_Label``, the time axis from ``X0`` and
    ``Delta_X`` (s). Errors name the file and the line.

    Parameters
    ----------
    path : str or Path
        The file to read.

    Returns
    -------
    TimeData

    Raises
    ------
    DataError
        Not an LVM file, several segments, ``X_Columns`` Multi, channels that disagree on ``X0`` or ``Delta_X``,
        a cell that is not a number, or rows of different length.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> text = ("LabVIEW Measurement\\t\\nSeparator\\tTab\\nDecimal_Separator\\t,\\nX_Columns\\tNo\\n"
    ...         "***End_of_Header***\\t\\nChannels\\t1\\t\\nY_Unit_Label\\tg\\t\\nX0\\t0,0E+0\\t\\n"
    ...         "Delta_X\\t2,0E-5\\t\\n***End_of_Header***\\t\\nX_Value\\tAcc\\tComment\\n\\t0,5\\n\\t-0,25\\n")
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     p = pathlib.Path(tmp) / "a.lvm"
    ...     _ = p.write_text(text)
    ...     data = read_lvm_time_data(p)
    >>> data.channels, data.units, data.fs, data.values.tolist()
    (('Acc',), ('g',), 50000.0, [[0.5, -0.25]])
    """
    p = Path(path)
    text = read_text_file(p, "LabVIEW measurement file", "LVM", max_bytes=MAX_LVM_BYTES)
    lines = text.splitlines()
    if not lines or not lines[0].startswith("LabVIEW Measurement"):
        msg = f"{p}, line 1: not a LabVIEW measurement file (it must begin with 'LabVIEW Measurement')"
        raise DataError(msg)
    ends = [k for k, line in enumerate(lines) if line.strip().startswith(_END)]
    if len(ends) < 2:
        msg = f"{p}: a file header and a segment header, each closed by {_END}, are required; found {len(ends)}"
        raise DataError(msg)
    if len(ends) > 2:
        msg = (
            f"{p} holds {len(ends) - 1} segments (headers closed on lines {', '.join(str(k + 1) for k in ends[1:])}); "
            f"cappe reads one: split the acquisitions into separate files"
        )
        raise DataError(msg)
    head = {}
    for line in lines[1 : ends[0]]:
        parts = line.split("\t")
        if parts and parts[0].strip():
            head[parts[0].strip()] = parts[1].strip() if len(parts) > 1 else ""
    sep = {"Tab": "\t", "Comma": ",", "": "\t"}.get(head.get("Separator", ""), None)
    if sep is None:
        msg = f"{p}: Separator must be Tab or Comma; got {shown(head['Separator'])}"
        raise DataError(msg)
    decimal = head.get("Decimal_Separator", ".") or "."
    if decimal not in (".", ","):
        msg = f"{p}: Decimal_Separator must be '.' or ','; got {shown(decimal)}"
        raise DataError(msg)
    x_columns = head.get("X_Columns", "One") or "One"
    if x_columns == "Multi":
        msg = f"{p}: X_Columns Multi (one time column per channel) is not read; export with X_Columns No or One"
        raise DataError(msg)
    segment: dict[str, tuple[int, list[str]]] = {}
    for k in range(ends[0] + 1, ends[1]):
        cells = _fields(lines[k], sep)
        if cells and cells[0]:
            segment[cells[0]] = (k + 1, cells[1:])
    if "Channels" not in segment:
        msg = f"{p}: the segment header (lines {ends[0] + 2}-{ends[1] + 1}) has no Channels line"
        raise DataError(msg)
    line_no, cells = segment["Channels"]
    n_ch = int(_number(cells[0] if cells else "", ".", f"{p}, line {line_no} (Channels)"))
    if n_ch < 1:
        msg = f"{p}, line {line_no}: Channels must be >= 1; got {n_ch}"
        raise DataError(msg)

    def per_channel(key: str) -> list[float]:
        if key not in segment:
            msg = f"{p}: the segment header has no {key} line; the time axis needs X0 and Delta_X"
            raise DataError(msg)
        where, values = segment[key]
        if len([v for v in values[:n_ch] if v]) < n_ch:
            msg = f"{p}, line {where}: {key} must give one value per channel ({n_ch})"
            raise DataError(msg)
        return [_number(v, decimal, f"{p}, line {where} ({key})") for v in values[:n_ch]]

    x0, dx = per_channel("X0"), per_channel("Delta_X")
    if len(set(x0)) > 1 or len(set(dx)) > 1:
        msg = f"{p}: the channels disagree on X0 {x0} or Delta_X {dx} (s); cappe reads channels on one time axis"
        raise DataError(msg)
    if dx[0] <= 0:
        msg = f"{p}, line {segment['Delta_X'][0]}: Delta_X must be > 0 s; got {dx[0]!r}"
        raise DataError(msg)
    units = segment.get("Y_Unit_Label", (0, []))[1][:n_ch]
    names_row = ends[1] + 1
    while names_row < len(lines) and not lines[names_row].strip():
        names_row += 1
    if names_row >= len(lines):
        msg = f"{p}: no column-name row and no data after the segment header (line {ends[1] + 1})"
        raise DataError(msg)
    header = _fields(lines[names_row], sep)
    names = header[1 : 1 + n_ch]
    if len(names) < n_ch or not all(names):
        msg = f"{p}, line {names_row + 1}: the column-name row must name the {n_ch} channel(s) after X_Value"
        raise DataError(msg)
    rows = []
    for k in range(names_row + 1, len(lines)):
        if not lines[k].strip():
            continue
        cells = _fields(lines[k], sep)
        if len(cells) < 1 + n_ch or not all(cells[1 : 1 + n_ch]):
            msg = f"{p}, line {k + 1}: {n_ch} channel value(s) expected after the X_Value cell; got {shown(lines[k])}"
            raise DataError(msg)
        rows.append([_number(c, decimal, f"{p}, line {k + 1}") for c in cells[1 : 1 + n_ch]])
    if not rows:
        msg = f"{p}: no samples after the column-name row (line {names_row + 1})"
        raise DataError(msg)
    values = np.array(rows, dtype=float).T
    time = np.asarray(x0[0] + dx[0] * np.arange(values.shape[1]), dtype=float)
    unit_tuple = tuple(units) if len(units) == n_ch and any(units) else ()
    try:
        return TimeData(time, values, tuple(names), unit_tuple)
    except DataError as exc:
        msg = f"{p}: {exc}"
        raise DataError(msg) from exc
