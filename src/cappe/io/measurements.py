"""Measured time data and FRFs on disk: UFF 58, CSV and npz, with the format taken from the file extension.

Formats
-------
``.uff`` / ``.unv``
    UFF 58, ASCII by default or binary with ``format="uff-binary"`` (see :mod:`cappe.io.uff`).
``.csv``
    One header row, then one row per sample or frequency line; numbers are written at full precision (shortest
    repr that reads back to the same double), so CSV round trips are exact.

    * Time data: ``time,<channel>,<channel>,...``. A unit follows a name as ``name [unit]`` (one blank, square
      brackets, e.g. ``acc [m/s^2]``); the time column is ``time`` or ``time [s]``. A channel without a unit whose
      name itself ends in ``" [...]"`` is written as ``name []`` so that it reads back unchanged.
    * FRFs: ``frequency,<output>/<input> re,<output>/<input> im,...`` with the real and imaginary part of each
      pair in adjacent columns (outputs major, inputs minor), then ``<output>/<input> coh`` columns when the
      coherence is known. The frequency column is ``frequency`` or ``frequency [Hz]``. A name that contains ``/``
      or starts with ``"`` is written as a JSON string (``"a/b"/F1 re``).
    * Lines before the header that start with ``#`` are comments. cappe writes ``# window_decay: <s>`` and
      ``# output_quantities: ["displacement", ...]`` there (JSON values) when an FRF has them; other programs
      can skip them (pandas: ``comment="#"``).
``.lvm``
    LabVIEW measurement text files (read only, time data; see :mod:`cappe.io.lvm`).
``.npz``
    numpy archive. Time data: ``format = "cappe.timedata/1"``, ``time``, ``values`` (n_channels, n_samples),
    ``channels``, ``units``. FRFs: ``format = "cappe.frf/1"``, ``freq``, ``H`` (n_out, n_in, n_freq),
    ``input_names``, ``output_names``, ``output_quantities``, ``window_decay`` (NaN for None) and, when known,
    ``coherence``. Exact.

Reading is bounded: a CSV file larger than ``MAX_CSV_BYTES`` (1 GiB) is refused (store long recordings as npz or
binary UFF), and every error names the file and the place (line and column, array, comment).
"""

from __future__ import annotations

import csv
import io
import json
import re
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
from numpy.typing import NDArray

from cappe.exceptions import DataError
from cappe.io.files import atomic_path, finite_number, parse_json, read_text_file, shown, write_text
from cappe.io.lvm import read_lvm_time_data
from cappe.io.uff import (
    COHERENCE,
    FRF,
    MULTIPLE_COHERENCE,
    SUPPORTED,
    TIME,
    check_frf,
    read_uff_frf,
    read_uff_time_data,
    uff_function_types,
    write_uff_frf,
    write_uff_time_data,
)
from cappe.systems.frf import FRFData
from cappe.systems.timedata import TimeData

__all__ = [
    "FRF_NPZ_FORMAT",
    "MEASUREMENT_FORMATS",
    "TIME_NPZ_FORMAT",
    "match_channels",
    "read_frf",
    "read_measurements",
    "read_time_data",
    "write_frf",
    "write_time_data",
]

MEASUREMENT_FORMATS = ("uff", "uff-binary", "csv", "npz", "lvm")
TIME_NPZ_FORMAT = "cappe.timedata/1"
FRF_NPZ_FORMAT = "cappe.frf/1"
_EXTENSIONS = {".uff": "uff", ".unv": "uff", ".csv": "csv", ".npz": "npz", ".lvm": "lvm"}
_UNIT = re.compile(r"^(?P<name>.*) \[(?P<unit>[^\[\]]*)\]$")
_TIME_HEADER = re.compile(r"^time( \[s\])?$", re.IGNORECASE)
_FREQ_HEADER = re.compile(r"^freq(uency)?( \[Hz\])?$", re.IGNORECASE)
_PARTS = ("re", "im", "coh")
#: The largest CSV file read (bytes); longer recordings belong in .npz or binary UFF, which read faster and exactly.
MAX_CSV_BYTES = 1024 * 2**20


def _format(path: Path, fmt: str | None) -> str:
    if fmt is not None:
        if fmt not in MEASUREMENT_FORMATS:
            msg = f"format must be one of {list(MEASUREMENT_FORMATS)} or None; got {fmt!r}"
            raise DataError(msg)
        return fmt
    found = _EXTENSIONS.get(path.suffix.lower())
    if found is None:
        msg = (
            f"cannot tell the format of {path} from its extension {path.suffix!r}; use .uff/.unv (UFF 58), .csv, "
            f".npz or .lvm (LabVIEW, read only), or pass format= one of {list(MEASUREMENT_FORMATS)}"
        )
        raise DataError(msg)
    return found


def _read_only(p: Path, fmt: str, what: str) -> None:
    if fmt == "lvm":
        msg = f"cannot write {p}: cappe reads LabVIEW .lvm files but writes {what} as .uff, .csv or .npz"
        raise DataError(msg)


def _prefixed(p: Path, exc: DataError) -> DataError:
    text = str(exc)
    return exc if text.startswith(str(p)) else DataError(f"{p}: {text}")


# ------------------------------------------------------------------------------------------------- public


def write_time_data(path: str | Path, data: TimeData, *, format: str | None = None) -> Path:  # noqa: A002
    """Write time data as UFF 58, CSV or npz (atomically; format from the extension unless given).

    Parameters
    ----------
    path : str or Path
        Target file; ``.uff``/``.unv`` (ASCII UFF), ``.csv`` or ``.npz``.
    data : TimeData
        Channels with their names and units.
    format : {None, "uff", "uff-binary", "csv", "npz"}
        Overrides the extension; ``"uff-binary"`` writes binary UFF 58 (exact doubles).

    Returns
    -------
    Path
        The file written.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> data = TimeData.from_channels([0.0, 0.5], {"F": [1.0, 2.0]}, units={"F": "N"})
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = write_time_data(pathlib.Path(tmp) / "run.csv", data)
    ...     path.read_text().splitlines()
    ['time,F [N]', '0.0,1.0', '0.5,2.0']
    """
    p = Path(path)
    fmt = _format(p, format)
    _read_only(p, fmt, "time data")
    if fmt in ("uff", "uff-binary"):
        return write_uff_time_data(p, data, binary=fmt == "uff-binary")  # validates data itself
    if not isinstance(data, TimeData):
        msg = f"data must be a TimeData; got {type(data).__name__}"
        raise DataError(msg)
    if fmt == "csv":
        units = data.units or ("",) * data.n_channels
        header = ["time"] + [_unit_cell(c, u) for c, u in zip(data.channels, units, strict=True)]
        rows = np.column_stack([data.time, data.values.T]).tolist()
        write_text(p, _csv_text([], header, rows))
        return p
    _save_npz(
        p,
        format=np.array(TIME_NPZ_FORMAT),
        time=data.time,
        values=data.values,
        channels=np.array(data.channels, dtype=str),
        units=np.array(data.units, dtype=str),
    )
    return p


def read_time_data(path: str | Path, *, format: str | None = None) -> TimeData:  # noqa: A002
    """Read time data from UFF 58 (function type 1), CSV or npz (format from the extension unless given).

    Errors name the file and the place: a missing file, an empty file, a non-numeric CSV cell (line and column),
    a missing npz array, non-uniform time stamps (TimeData's rules).

    Parameters
    ----------
    path : str or Path
        The file to read.
    format : {None, "uff", "uff-binary", "csv", "npz"}
        File format; None takes it from the extension (.uff/.unv, .csv, .npz).

    Returns
    -------
    TimeData

    Raises
    ------
    DataError
        The file cannot be read or does not hold valid time data.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> data = TimeData.from_rate(2048.0, {"F": [0.0, 1.0, 0.0], "acc": [0.1, 0.2, 0.3]})
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     back = read_time_data(write_time_data(pathlib.Path(tmp) / "run.npz", data))
    >>> back.channels, back.fs
    (('F', 'acc'), 2048.0)
    """
    p = Path(path)
    fmt = _format(p, format)
    if fmt in ("uff", "uff-binary"):
        return read_uff_time_data(p)
    if fmt == "csv":
        return _time_from_table(_read_table(p))
    if fmt == "lvm":
        return read_lvm_time_data(p)
    return _time_from_npz(p, _load_npz(p))


def write_frf(path: str | Path, frf: FRFData, *, format: str | None = None) -> Path:  # noqa: A002
    """Write FRFs (with coherence and window decay when set) as UFF 58, CSV or npz, atomically.

    Parameters
    ----------
    path : str or Path
        The file to write.
    frf : FRFData
        The FRFs (finite, increasing lines).
    format : {None, "uff", "uff-binary", "csv", "npz"}
        File format; None takes it from the extension (.uff/.unv, .csv, .npz).

    Returns
    -------
    Path
        ``path``.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import numpy as np
    >>> frf = FRFData(np.array([10.0, 20.0]), np.array([[[1 + 2j, 3 - 1j]]]), ("F1",), ("d1",), window_decay=0.5)
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = write_frf(pathlib.Path(tmp) / "h.csv", frf)
    ...     path.read_text().splitlines()
    ['# window_decay: 0.5', 'frequency,d1/F1 re,d1/F1 im', '10.0,1.0,2.0', '20.0,3.0,-1.0']
    """
    p = Path(path)
    fmt = _format(p, format)
    _read_only(p, fmt, "FRFs")
    if fmt in ("uff", "uff-binary"):
        return write_uff_frf(p, frf, binary=fmt == "uff-binary")  # validates frf itself
    check_frf(frf)
    freq = np.asarray(frf.freq, dtype=float)
    H = np.asarray(frf.H, dtype=complex)
    if fmt == "csv":
        comments = []
        if frf.window_decay is not None:
            comments.append(f"# window_decay: {json.dumps(float(frf.window_decay))}")
        if frf.output_quantities:
            comments.append(f"# output_quantities: {json.dumps(list(frf.output_quantities))}")
        pairs = [f"{_pair_cell(o)}/{_pair_cell(i)}" for o in frf.output_names for i in frf.input_names]
        header = ["frequency"] + [f"{pair} {part}" for pair in pairs for part in ("re", "im")]
        columns = [freq]
        flat = H.reshape(-1, freq.size)
        for row in flat:
            columns += [row.real, row.imag]
        if frf.coherence is not None:
            header += [f"{pair} coh" for pair in pairs]
            columns += list(np.asarray(frf.coherence, dtype=float).reshape(-1, freq.size))
        write_text(p, _csv_text(comments, header, np.column_stack(columns).tolist()))
        return p
    arrays: dict[str, Any] = {
        "format": np.array(FRF_NPZ_FORMAT),
        "freq": freq,
        "H": H,
        "input_names": np.array(frf.input_names, dtype=str),
        "output_names": np.array(frf.output_names, dtype=str),
        "output_quantities": np.array(frf.output_quantities, dtype=str),
        "window_decay": np.array(np.nan if frf.window_decay is None else float(frf.window_decay)),
    }
    if frf.coherence is not None:
        arrays["coherence"] = np.asarray(frf.coherence, dtype=float)
    _save_npz(p, **arrays)
    return p


def read_frf(path: str | Path, *, format: str | None = None) -> FRFData:  # noqa: A002
    """Read FRFs from UFF 58 (function type 4, coherence 6/26), CSV or npz (format from the extension).

    Parameters
    ----------
    path : str or Path
        The file to read.
    format : {None, "uff", "uff-binary", "csv", "npz"}
        File format; None takes it from the extension (.uff/.unv, .csv, .npz).

    Returns
    -------
    FRFData

    Raises
    ------
    DataError
        The file cannot be read or does not hold valid FRFs.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import numpy as np
    >>> frf = FRFData(np.array([1.0, 2.0, 3.0]), np.ones((2, 1, 3), complex), ("F",), ("a", "b"))
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     back = read_frf(write_frf(pathlib.Path(tmp) / "h.csv", frf))
    >>> back.output_names, back.H.shape
    (('a', 'b'), (2, 1, 3))
    """
    p = Path(path)
    fmt = _format(p, format)
    if fmt in ("uff", "uff-binary"):
        return read_uff_frf(p)
    if fmt == "csv":
        return _frf_from_table(_read_table(p))
    if fmt == "lvm":
        msg = f"{p} is a LabVIEW measurement file of time data; estimate FRFs from it with `cappe frf`"
        raise DataError(msg)
    return _frf_from_npz(p, _load_npz(p))


def read_measurements(path: str | Path, *, format: str | None = None) -> TimeData | FRFData:  # noqa: A002
    """Read a measurement file as TimeData or FRFData, whichever it holds.

    UFF: function type 1 datasets give time data, function type 4 FRFs (a file with both is ambiguous);
    CSV: a first header column ``time`` or ``frequency``; npz: the ``time``/``values`` or ``freq``/``H`` arrays.

    Parameters
    ----------
    path : str or Path
        The file to read.
    format : {None, "uff", "uff-binary", "csv", "npz"}
        File format; None takes it from the extension (.uff/.unv, .csv, .npz).

    Returns
    -------
    TimeData or FRFData

    Examples
    --------
    >>> import pathlib, tempfile
    >>> data = TimeData.from_rate(10.0, {"x": [1.0, 2.0]})
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     type(read_measurements(write_time_data(pathlib.Path(tmp) / "x.uff", data))).__name__
    'TimeData'
    """
    p = Path(path)
    fmt = _format(p, format)
    if fmt in ("uff", "uff-binary"):
        funcs = set(uff_function_types(p))
        if TIME in funcs and FRF in funcs:
            msg = (
                f"{p} holds both time data (UFF 58 function type 1) and FRFs (type 4); "
                "read it with read_time_data or read_frf"
            )
            raise DataError(msg)
        if FRF in funcs:
            return read_uff_frf(p)
        if TIME in funcs:
            return read_uff_time_data(p)
        found = ", ".join(str(f) for f in sorted(funcs))
        extra = " (coherence without FRFs)" if funcs <= {COHERENCE, MULTIPLE_COHERENCE} else ""
        msg = (
            f"{p} holds UFF 58 function type(s) {found}{extra}, none of them time data or FRFs; "
            f"supported: {SUPPORTED}"
        )
        raise DataError(msg)
    if fmt == "lvm":
        return read_lvm_time_data(p)
    if fmt == "csv":
        table = _read_table(p)
        first = table.header[0].strip()
        if _TIME_HEADER.match(first):
            return _time_from_table(table)
        if _FREQ_HEADER.match(first):
            return _frf_from_table(table)
        msg = (
            f"{p}, line {table.header_line}: the first column must be 'time' (time data) or 'frequency' (FRFs); "
            f"got {shown(table.header[0])}"
        )
        raise DataError(msg)
    arrays = _load_npz(p)
    if "time" in arrays and "values" in arrays:
        return _time_from_npz(p, arrays)
    if "freq" in arrays and "H" in arrays:
        return _frf_from_npz(p, arrays)
    msg = f"{p} holds arrays {sorted(arrays)}; expected time and values (time data) or freq and H (FRFs)"
    raise DataError(msg)


def match_channels(data: TimeData, names: Sequence[str], role: str) -> list[int]:
    """Rows of ``data`` holding the named channels, in the order given.

    Parameters
    ----------
    data : TimeData
        Measured channels.
    names : sequence of str
        Channel names the caller needs (e.g. the model's inputs).
    role : str
        What the channels are for (``"input"``, ``"output"``), used in the error message.

    Raises
    ------
    DataError
        When a name is missing (the message lists the missing and the available channels) or repeated.

    Examples
    --------
    >>> data = TimeData.from_rate(100.0, {"F1": [0.0, 1.0], "d1": [0.0, 0.1], "d2": [0.0, 0.2]})
    >>> match_channels(data, ["d2", "d1"], "output")
    [2, 1]
    """
    names = [str(n) for n in names]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        msg = f"{role} channel(s) {repeated} are listed more than once"
        raise DataError(msg)
    missing = [n for n in names if n not in data.channels]
    if missing:
        msg = f"{role} channel(s) {missing} not found in the data; available channels: {list(data.channels)}"
        raise DataError(msg)
    return [data.channels.index(n) for n in names]


# ---------------------------------------------------------------------------------------------------- CSV


def _csv_text(comments: Sequence[str], header: Sequence[str], rows: Sequence[Sequence[float]]) -> str:
    buf = io.StringIO()
    for line in comments:
        buf.write(line + "\n")
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)  # floats are written with repr(): the shortest string that reads back exactly
    return buf.getvalue()


def _unit_cell(name: str, unit: str) -> str:
    if "[" in unit or "]" in unit or "\n" in unit or "\r" in unit:
        msg = f"unit {unit!r} of channel {name!r} cannot go into a CSV header: it must not contain [ ] or newlines"
        raise DataError(msg)
    if unit or _UNIT.match(name):
        return f"{name} [{unit}]"
    return name


def _pair_cell(name: str) -> str:
    return json.dumps(name) if "/" in name or name.startswith('"') or not name else name


@dataclass
class _Table:
    path: Path
    header: list[str]
    header_line: int
    lines: list[int]
    values: NDArray[np.float64]
    meta: dict[str, tuple[int, str]]


def _read_table(p: Path) -> _Table:
    text = read_text_file(p, "CSV measurement file", "CSV", max_bytes=MAX_CSV_BYTES)
    if not text.strip():
        msg = f"{p} is empty; expected a CSV header row ('time,...' or 'frequency,...') and data rows"
        raise DataError(msg)
    lines = text.splitlines(keepends=True)
    meta: dict[str, tuple[int, str]] = {}
    skip = 0
    while skip < len(lines) and (lines[skip].lstrip().startswith("#") or not lines[skip].strip()):
        body = lines[skip].strip().lstrip("#")
        key, sep, value = body.partition(":")
        if sep:
            meta[key.strip()] = (skip + 1, value.strip())
        skip += 1
    reader = csv.reader(io.StringIO("".join(lines[skip:])))
    header: list[str] | None = None
    header_line = 0
    cells: list[list[str]] = []
    row_lines: list[int] = []
    try:
        for row in reader:
            if not any(c.strip() for c in row):
                continue
            line = skip + reader.line_num
            if header is None:
                header, header_line = row, line
                continue
            if len(row) != len(header):
                msg = f"{p}, line {line}: {len(row)} cell(s); the header (line {header_line}) has {len(header)}"
                raise DataError(msg)
            cells.append(row)
            row_lines.append(line)
    except csv.Error as exc:
        msg = f"{p}, line {skip + reader.line_num}: malformed CSV: {exc}"
        raise DataError(msg) from exc
    if header is None:
        msg = f"{p} holds only comment lines; expected a CSV header row ('time,...' or 'frequency,...') and data rows"
        raise DataError(msg)
    if not cells:
        msg = f"{p} has a header row (line {header_line}) but no data rows"
        raise DataError(msg)
    try:
        values = np.array(cells, dtype=float)
    except ValueError:
        values = None  # a cell that is not a number, found below
    if values is None or not np.all(np.isfinite(values)):
        _bad_cell(p, header, cells, row_lines)
    return _Table(p, header, header_line, row_lines, values, meta)


def _bad_cell(p: Path, header: list[str], cells: list[list[str]], lines: list[int]) -> NoReturn:
    """Raise for the first cell that is not a finite number, naming its line, column and text."""
    for row, line in zip(cells, lines, strict=True):
        for j, cell in enumerate(row):
            try:
                number = float(cell)  # what numpy uses for strings
            except ValueError:
                msg = f"{p}, line {line}, column {j + 1} ({shown(header[j])}): {shown(cell)} is not a number"
                raise DataError(msg) from None
            if not np.isfinite(number):  # 'nan', 'inf', '1e400' or more digits than a float holds
                msg = f"{p}, line {line}, column {j + 1} ({shown(header[j])}): {shown(cell)} is not a finite number"
                raise DataError(msg)
    msg = f"{p}: the data rows hold a cell that is not a finite number"  # pragma: no cover - float() found none
    raise DataError(msg)  # pragma: no cover


def _check_first_column(table: _Table, header: re.Pattern[str], what: str, allowed: str) -> None:
    if not header.match(table.header[0].strip()):
        msg = (
            f"{table.path}, line {table.header_line}: the first column of {what} must be {allowed}; "
            f"got {shown(table.header[0])}"
        )
        raise DataError(msg)


def _time_from_table(table: _Table) -> TimeData:
    p = table.path
    _check_first_column(table, _TIME_HEADER, "time data", "'time' or 'time [s]'")
    names, units = [], []
    for cell in table.header[1:]:
        m = _UNIT.match(cell)
        names.append(m["name"] if m else cell)
        units.append(m["unit"] if m else "")
    try:
        return TimeData(table.values[:, 0], table.values[:, 1:].T, tuple(names), tuple(units) if any(units) else ())
    except DataError as exc:
        raise _prefixed(p, exc) from exc


def _take_name(text: str, *, last: bool) -> tuple[str, str] | None:
    """The first name of ``text`` (a JSON string, or plain text up to '/' or the end) and what follows it."""
    if text.startswith('"'):
        try:
            name, end = json.JSONDecoder().raw_decode(text)
        except json.JSONDecodeError:
            return None
        return (name, text[end:]) if isinstance(name, str) else None
    if last:
        return text, ""
    name, sep, tail = text.partition("/")
    return (name, sep + tail) if sep else None


def _split_pair(cell: str) -> tuple[str, str] | None:
    """``out/in`` (either name may be a JSON string) -> (out, in), or None when the cell is not a pair."""
    first = _take_name(cell, last=False)
    if first is None or not first[1].startswith("/"):
        return None
    second = _take_name(first[1][1:], last=True)
    if second is None or second[1]:
        return None
    return first[0], second[0]


def _frf_from_table(table: _Table) -> FRFData:
    p = table.path
    _check_first_column(table, _FREQ_HEADER, "FRF data", "'frequency' or 'frequency [Hz]'")
    columns: dict[tuple[str, str], dict[str, int]] = {}
    for j, cell in enumerate(table.header[1:], start=1):
        pair_text, _, part = cell.rpartition(" ")
        pair = _split_pair(pair_text) if part in _PARTS else None
        if pair is None:
            msg = f"{p}, line {table.header_line}, column {j + 1}: {shown(cell)} must read '<output>/<input> re|im|coh'"
            raise DataError(msg)
        parts = columns.setdefault(pair, {})
        if part in parts:
            msg = f"{p}, line {table.header_line}: column {j + 1} repeats {shown(cell)} (column {parts[part] + 1})"
            raise DataError(msg)
        parts[part] = j
    with_coherence = [pair for pair, parts in columns.items() if "coh" in parts]
    for (out, inp), parts in columns.items():
        for have, lack in (("re", "im"), ("im", "re")):
            if have in parts and lack not in parts:
                msg = (
                    f"{p}, line {table.header_line}: column {parts[have] + 1} '{out}/{inp} {have}' has no matching "
                    f"'{out}/{inp} {lack}' column (complex FRFs need re/im column pairs)"
                )
                raise DataError(msg)
        if "re" not in parts:
            msg = (
                f"{p}, line {table.header_line}: coherence column '{out}/{inp} coh' has no FRF columns "
                f"'{out}/{inp} re/im'"
            )
            raise DataError(msg)
    outputs = list(dict.fromkeys(out for out, _ in columns))
    inputs = list(dict.fromkeys(inp for _, inp in columns))
    missing = [f"{o}/{i}" for o in outputs for i in inputs if (o, i) not in columns]
    if missing:
        msg = f"{p}: the FRF columns lack the pair(s) {missing} to complete the {len(outputs)} x {len(inputs)} grid"
        raise DataError(msg)
    if with_coherence and len(with_coherence) != len(columns):
        lacking = [f"{o}/{i}" for (o, i) in columns if (o, i) not in with_coherence]
        msg = f"{p}: coherence columns are given for some FRFs but not for {lacking}"
        raise DataError(msg)
    v = table.values
    n_f = v.shape[0]
    H = np.empty((len(outputs), len(inputs), n_f), dtype=complex)
    coherence = np.empty((len(outputs), len(inputs), n_f)) if with_coherence else None
    for (out, inp), parts in columns.items():
        o, i = outputs.index(out), inputs.index(inp)
        H[o, i] = v[:, parts["re"]] + 1j * v[:, parts["im"]]
        if coherence is not None:
            coherence[o, i] = v[:, parts["coh"]]
    quantities, decay = _meta_quantities(table, len(outputs)), _meta_decay(table)
    try:
        frf = FRFData(freq=v[:, 0].copy(), H=H, input_names=tuple(inputs), output_names=tuple(outputs),
                      output_quantities=quantities, coherence=coherence, window_decay=decay)
        check_frf(frf)
    except DataError as exc:
        raise _prefixed(p, exc) from exc
    return frf


def _meta_json(table: _Table, key: str) -> Any:
    line, raw = table.meta[key]
    return parse_json(raw, f"{table.path}, line {line}: the value of comment '{key}'")


def _meta_decay(table: _Table) -> float | None:
    if "window_decay" not in table.meta:
        return None
    value = _meta_json(table, "window_decay")
    number = finite_number(value)
    if value is not None and number is None:
        line = table.meta["window_decay"][0]
        msg = f"{table.path}, line {line}: window_decay must be a finite number (s) or null; got {shown(value)}"
        raise DataError(msg)
    return number


def _meta_quantities(table: _Table, n_out: int) -> tuple[str, ...]:
    if "output_quantities" not in table.meta:
        return ()
    value = _meta_json(table, "output_quantities")
    if not isinstance(value, list) or len(value) != n_out or not all(isinstance(q, str) for q in value):
        line = table.meta["output_quantities"][0]
        msg = (
            f"{table.path}, line {line}: output_quantities must list {n_out} strings (one per output); "
            f"got {shown(value)}"
        )
        raise DataError(msg)
    return tuple(value)


# ---------------------------------------------------------------------------------------------------- npz


def _save_npz(p: Path, **arrays: Any) -> None:
    with atomic_path(p) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **arrays)


def _load_npz(p: Path) -> dict[str, NDArray[Any]]:
    if not p.is_file():
        msg = f"cannot read {p}: no such file"
        raise DataError(msg)
    try:
        with np.load(p, allow_pickle=False) as archive:
            return {key: archive[key] for key in archive.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        msg = f"{p} is not a readable .npz archive (numpy.savez without pickled objects): {exc}"
        raise DataError(msg) from exc


def _npz_array(p: Path, arrays: dict[str, NDArray[Any]], key: str, kind: str) -> NDArray[Any]:
    if key not in arrays:
        msg = f"{p} lacks the array {key!r} of {kind}; it holds {sorted(arrays)}"
        raise DataError(msg)
    return arrays[key]


def _npz_names(p: Path, arrays: dict[str, NDArray[Any]], key: str, kind: str) -> tuple[str, ...]:
    value = _npz_array(p, arrays, key, kind)
    if value.dtype.kind != "U" or value.ndim != 1:
        msg = f"array {key!r} in {p} must be a 1-D array of strings; got dtype {value.dtype} and shape {value.shape}"
        raise DataError(msg)
    return tuple(str(v) for v in value)


def _npz_numbers(p: Path, arrays: dict[str, NDArray[Any]], key: str, kind: str, dtype: type) -> NDArray[Any]:
    value = _npz_array(p, arrays, key, kind)
    allowed = "biufc" if dtype is complex else "biuf"
    if value.dtype.kind not in allowed:
        msg = f"array {key!r} in {p} must hold numbers; got dtype {value.dtype}"
        raise DataError(msg)
    return np.asarray(value, dtype=dtype)


def _check_npz_format(p: Path, arrays: dict[str, NDArray[Any]], expected: str) -> None:
    if "format" in arrays and str(arrays["format"]) != expected:
        msg = f"{p} has format {str(arrays['format'])!r}; expected {expected!r}"
        raise DataError(msg)


def _time_from_npz(p: Path, arrays: dict[str, NDArray[Any]]) -> TimeData:
    kind = "time data"
    _check_npz_format(p, arrays, TIME_NPZ_FORMAT)
    time = _npz_numbers(p, arrays, "time", kind, float)
    values = _npz_numbers(p, arrays, "values", kind, float)
    channels = _npz_names(p, arrays, "channels", kind)
    units = _npz_names(p, arrays, "units", kind) if "units" in arrays else ()
    try:
        return TimeData(time, values, channels, units)
    except (DataError, ValueError, TypeError) as exc:
        raise _prefixed(p, DataError(str(exc))) from exc


def _frf_from_npz(p: Path, arrays: dict[str, NDArray[Any]]) -> FRFData:
    kind = "FRF data"
    _check_npz_format(p, arrays, FRF_NPZ_FORMAT)
    decay = _npz_numbers(p, arrays, "window_decay", kind, float) if "window_decay" in arrays else np.array(np.nan)
    if decay.size != 1:
        msg = f"array 'window_decay' in {p} must be one number (s, NaN for none); got shape {decay.shape}"
        raise DataError(msg)
    fields: dict[str, Any] = {
        "freq": _npz_numbers(p, arrays, "freq", kind, float),
        "H": _npz_numbers(p, arrays, "H", kind, complex),
        "input_names": _npz_names(p, arrays, "input_names", kind),
        "output_names": _npz_names(p, arrays, "output_names", kind),
        "output_quantities": _npz_names(p, arrays, "output_quantities", kind) if "output_quantities" in arrays else (),
        "coherence": _npz_numbers(p, arrays, "coherence", kind, float) if "coherence" in arrays else None,
        "window_decay": None if np.isnan(decay.item()) else float(decay.item()),
    }
    try:
        frf = FRFData(**fields)
        check_frf(frf)
    except DataError as exc:
        raise _prefixed(p, exc) from exc
    return frf
