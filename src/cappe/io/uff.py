"""Universal File Format (UFF) exchange with measurement and modal-test software (encoding by pyuff).

What cappe writes and reads
---------------------------
* **UFF 58** (ASCII ``58`` or binary ``58b``), one dataset per signal:
  function type 1 (time response) for :class:`~cappe.systems.TimeData` channels, function type 4 (frequency
  response function) per (output, input) pair of :class:`~cappe.systems.frf.FRFData` with *reference = input* and
  *response = output*, and function type 6 (coherence) per pair when ``FRFData.coherence`` is set.
  Multiple coherence (type 26) is read as the coherence of every pair of its response; pyuff cannot write it.
* **UFF 55** (one dataset per mode, load case = axis-position set) with **UFF 2411** (double precision) or
  **UFF 15** node coordinates, and **UFF 2467** permanent groups that carry cappe's node and sensor names.

The ID lines of cappe's datasets (cappe.uff/1)
-----------------------------------------------
Standard fields (node, direction, specific data type, axis units) are filled so that other programs see sensible
degrees of freedom; the values cappe needs for exact round trips sit in the five 80-character ID lines:

=============  =================================================================================================
UFF 58 ID 1    description for display (channel, or ``output / input``)
UFF 58 ID 2    ``cappe.uff/1 <time|frf|coherence> x0=<t0> dx=<step>`` (or ``rate=<1/step>``, or ``xn=<last>`` for
               a log-spaced abscissa): the exact abscissa
UFF 58 ID 3    FRF only: ``decay=<window_decay>`` and ``quantity=<output quantity>`` tokens, else ``NONE``
UFF 58 ID 4    channel (time) or output (FRF) name as a JSON string
UFF 58 ID 5    unit (time) or input name (FRF) as a JSON string
UFF 55 ID 1    description for display
UFF 55 ID 2    ``cappe.uff/1 modal set=<k> mode=<j>`` (load case ``k``, mode number ``j``; 1-based)
UFF 55 ID 4    axis position as ``axis=value`` tokens (``NONE`` without axes)
UFF 55 ID 5    ``freq=<Hz> zeta=<ratio>`` at full precision
=============  =================================================================================================

Names are JSON-quoted with ASCII escapes, so any channel name of at most 78 characters (after escaping)
round-trips exactly. Full-precision values from the ID lines are used only when they agree with the standard
fields (to the 6 digits those hold); a file edited by other software falls back to the standard fields with a
:class:`~cappe.exceptions.DataWarning`.

Node numbers
------------
UFF identifies degrees of freedom by integer node number and direction code (1..6 = +x +y +z +rx +ry +rz, negative
for the minus direction, 0 for a scalar). Labels ``"node:direction"`` (directions ``x y z rx ry rz`` with optional
sign) map to that node and direction; a node name that is a plain positive integer (``"12"``) keeps its number,
every other node name (``"tool"``) gets the next free number after the largest integer name, in order of first
appearance. Names without a direction are scalar points with a node number of their own. In UFF 58 files the
exact names come back from the ID lines. In UFF 55 files, one UFF 2467 group per sensor (``"sensor tool:x"``,
in sensor order) and one per coordinate-only node (``"node base"``) map numbers back to names; each group holds that
one node. Group names are limited to 40 characters by the format, so sensor labels to 33 and node names to 35
(printable ASCII, no leading, trailing or repeated blanks).

Reading files written by other programs
---------------------------------------
Without cappe's ID lines, time channels are named from the response node and direction (``"12:+z"``, or ``"12"``
for a scalar point); FRF outputs from the response DOF and inputs from the reference DOF (``"12:+z"`` /
``"1:-x"``); repeated time-channel names get a ``" (dataset k)"`` suffix. Mode-shape sensors are named
``"12:x"``... for each node and direction of the UFF 55 records, leaving out directions that are zero in every
mode (UFF's convention for unmeasured DOFs). Units come from the ordinate axis-units label, output quantities
from the ordinate specific data type (8 displacement, 11 velocity, 12 acceleration).

Incomplete files
----------------
Every dataset lies between two ``    -1`` lines. A file that stops inside its last dataset (a copy cut short, a file
still being written by the acquisition software) is refused with a DataError naming the file and the dataset
(``dataset #12 (UFF 58) of run.uff ends before its data is complete``) rather than read without that dataset.

Precision
---------
Binary UFF 58 stores ordinates and an uneven abscissa as IEEE doubles (exact). ASCII UFF 58 stores ordinates with
12 significant digits (E20.12); an uneven abscissa only with 6 (E13.5), which near a lightly damped peak shifts
the response by percents (a relative shift of 4e-6 is 1 % of the half-power bandwidth of a 0.05 % damped mode).
cappe therefore writes even and log-spaced (``np.geomspace``) grids with ID-line tokens from which its reader
rebuilds them exactly (other programs read the 6 digits); other non-uniform frequency grids should go to binary
UFF, CSV or npz. UFF 55 stores shapes, frequencies and damping with 6 significant digits (E13.5);
cappe's ID 5 line restores frequency and damping exactly. UFF 2411 coordinates are exact, UFF 15 ones have
6 digits.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import re
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyuff
from numpy.typing import NDArray

from cappe.exceptions import DataError, DataWarning
from cappe.io.files import atomic_path
from cappe.io.modal import modal_data_from_mapping
from cappe.systems.frf import FRFData
from cappe.systems.modal import MODAL_FORMAT, ModalData
from cappe.systems.timedata import TimeData

__all__ = [
    "UFF_FORMAT",
    "read_uff_frf",
    "read_uff_modal",
    "read_uff_nodes",
    "read_uff_time_data",
    "write_uff_frf",
    "write_uff_modal",
    "write_uff_nodes",
    "write_uff_time_data",
]

UFF_FORMAT = "cappe.uff/1"

# UFF 58 function types (record 6, field 1).
FUNCTION_TYPES = {
    0: "general", 1: "time response", 2: "auto spectrum", 3: "cross spectrum", 4: "frequency response function",
    5: "transmissibility", 6: "coherence", 7: "auto correlation", 8: "cross correlation", 9: "power spectral density",
    12: "spectrum", 18: "mode indicator function", 26: "multiple coherence",
}
TIME, FRF, COHERENCE, MULTIPLE_COHERENCE = 1, 4, 6, 26
SUPPORTED = (
    "UFF 58 function type 1 (time response), 4 (FRF) with optional 6/26 (coherence); "
    "UFF 55 analysis type 2, 3 or 7 (modes), or UFF 2414 normal modes at nodes (FE results), with UFF 15/2411 "
    "nodes and UFF 2467 groups"
)

_DIRECTIONS = {"x": 1, "y": 2, "z": 3, "rx": 4, "ry": 5, "rz": 6}
_DIRECTION_NAMES = {code: name for name, code in _DIRECTIONS.items()}
_LABEL = re.compile(r"^(?P<node>.+):(?P<sign>[+-]?)(?P<dir>x|y|z|rx|ry|rz)$")
_NODE_NUMBER = re.compile(r"^[1-9][0-9]{0,8}$")  # fits UFF's I10 node fields
_GROUP_NAME = re.compile(r"^\S+( \S+)*$")  # no leading/trailing or repeated blanks (a blank run could fake '    -1')
_GROUP_WIDTH = 40
_ID_WIDTH = 80
_NODE_ENTITY = 7  # UFF 2467 entity type code of a node
_SENSOR_GROUP, _NODE_GROUP = "sensor ", "node "
_DELIMITER = b"    -1"  # the line that opens and closes every dataset

# ordinate "specific data type" codes (UFF 58 record 9) by output quantity and by SI unit
_QUANTITY_TYPES = {"displacement": 8, "elongation": 8, "velocity": 11, "acceleration": 12}
_TYPE_QUANTITIES = {8: "displacement", 11: "velocity", 12: "acceleration"}
_UNIT_TYPES = {"m": 8, "m/s": 11, "m/s^2": 12, "m/s2": 12, "N": 13, "Pa": 15, "kg": 16}
_ABSCISSA_TIME, _ABSCISSA_FREQUENCY, _EXCITATION_FORCE = 17, 18, 13

# Even-spacing headers hold x0 and the step with 6 digits (E13.5): values from the ID lines must agree to this.
_HEADER_RTOL = 1e-5
# An abscissa uniform to this relative tolerance (TimeData's rule for a uniform time grid) is written as even
# spacing ``x0 + k * mean step`` in ASCII files, where an uneven abscissa would keep 6 digits only.
_UNIFORM_RTOL = 1e-6
# A log-spaced abscissa that np.geomspace reproduces to this relative tolerance (4 ulps) is written with the tokens
# from which the reader rebuilds it (an uneven ASCII abscissa keeps only 6 digits).
_GEOMETRIC_RTOL = 4 * float(np.finfo(float).eps)


# ----------------------------------------------------------------------------------------------- file handling


def _write_datasets(path: str | Path, datasets: Sequence[dict[str, Any]]) -> None:
    with atomic_path(path) as tmp:
        # 'add' on the fresh empty file: pyuff's 'overwrite' truncates the header of a first binary 58 dataset
        try:
            with warnings.catch_warnings():
                # pyuff's binary 58 writer reopens the file and never closes the last handle; CPython closes it
                # when the writer returns, which warns ResourceWarning (not the user's concern)
                warnings.simplefilter("ignore", ResourceWarning)
                pyuff.UFF(str(tmp)).write_sets(list(datasets), mode="add")
        except Exception as exc:  # pyuff raises bare Exception
            msg = f"cannot write UFF file {path}: {exc}"
            raise DataError(msg) from exc


def _delimiters(data: bytes) -> list[int]:
    """Offsets of the ``    -1`` lines that open and close datasets, found by pyuff's rule (``UFF.refresh``: the
    six characters followed by a line end, the end of the file or 74 blanks), so that they pair as pyuff's do."""
    found = []
    at = data.find(_DELIMITER)
    while at >= 0:
        end = at + len(_DELIMITER)
        if end == len(data) or data[end] in b"\r\n" or (at + 80 < len(data) and data[end : at + 80] == b" " * 74):
            found.append(at)
        at = data.find(_DELIMITER, at + 1)
    return found


def _check_complete(p: Path) -> None:
    """Refuse a file that stops inside its last dataset (cut short, or still being written).

    pyuff pairs the ``    -1`` lines and drops a last dataset without its closing one; the reader would return the
    other datasets as if the file held no more.
    """
    try:
        data = p.read_bytes()
    except OSError as exc:
        msg = f"cannot read UFF file {p}: {exc.strerror or exc}"
        raise DataError(msg) from exc
    marks = _delimiters(data)
    if len(marks) % 2 == 0:
        # after the last closing line (and its line end): nothing, more lines, or a next opening line cut short
        rest = data
        if marks:
            end = data.find(b"\n", marks[-1])
            rest = b"" if end < 0 else data[end + 1 :]
        rest = rest.lstrip(b"\r\n")
        if not rest or not _DELIMITER.startswith(rest):
            return
        what = "its opening '    -1' line"
    else:
        rest = data[marks[-1] + len(_DELIMITER) :].lstrip(b"\r\n")
        line, newline, _ = rest.partition(b"\n")
        code = line[:6].strip()
        if newline and code.isdigit():
            kind = f"UFF {int(code)}{'b' if line[6:7].lower() == b'b' else ''}"
            what = "its closing '    -1' line"
        else:
            kind = "UFF type cut off"
            what = "its type line"
        msg = (
            f"dataset #{len(marks) // 2 + 1} ({kind}) of {p} ends before its data is complete: the file stops "
            f"without {what} (cut short, or still being written)"
        )
        raise DataError(msg)
    msg = (
        f"dataset #{len(marks) // 2 + 1} of {p} ends before its data is complete: the file stops inside {what} "
        "(cut short, or still being written)"
    )
    raise DataError(msg)


def _open_uff(path: str | Path) -> tuple[Path, Any, list[int]]:
    p = Path(path)
    if not p.is_file():
        msg = f"cannot read UFF file {p}: no such file"
        raise DataError(msg)
    try:
        uff = pyuff.UFF(str(p))
        types = [int(t) for t in uff.get_set_types()]
    except Exception as exc:  # pyuff raises bare Exception
        msg = f"cannot read UFF file {p}: {exc}"
        raise DataError(msg) from exc
    _check_complete(p)
    if not types:
        msg = f"{p} holds no UFF datasets (blocks between '    -1' lines); supported: {SUPPORTED}"
        raise DataError(msg)
    return p, uff, types


def _read_set(p: Path, uff: Any, k: int, set_type: int, *, header_only: bool = False) -> dict[str, Any]:
    try:
        # pyuff's UFF 2467 reader prints every group it parses; keep that off the user's terminal
        with contextlib.redirect_stdout(io.StringIO()):
            dset = uff.read_sets(k, header_only=header_only)
    except Exception as exc:  # pyuff raises bare Exception
        msg = f"cannot decode dataset #{k + 1} (UFF {set_type}) of {p}: {exc}"
        raise DataError(msg) from exc
    return dict(dset)


def _found(p: Path, uff: Any, types: Sequence[int]) -> str:
    """Describe what a file holds: dataset types, with the function types of UFF 58 datasets."""
    counts: dict[str, int] = {}
    for k, t in enumerate(types):
        key = f"UFF {t}"
        if t == 58:
            func = int(_read_set(p, uff, k, t, header_only=True).get("func_type", -1))
            key = f"UFF 58 function type {func} ({FUNCTION_TYPES.get(func, 'unknown')})"
        counts[key] = counts.get(key, 0) + 1
    return ", ".join(f"{key} x{n}" if n > 1 else key for key, n in counts.items())


def uff_function_types(path: str | Path) -> list[int]:
    """Function types of the UFF 58 datasets in a file (headers only); other datasets are skipped.

    Used to tell time data from FRFs before reading. Raises DataError when the file has no UFF 58 dataset.
    """
    p, uff, types = _open_uff(path)
    funcs = [int(_read_set(p, uff, k, t, header_only=True)["func_type"]) for k, t in enumerate(types) if t == 58]
    if not funcs:
        msg = f"{p} holds no time or FRF data; found {_found(p, uff, types)}; supported: {SUPPORTED}"
        raise DataError(msg)
    return funcs


# ------------------------------------------------------------------------------------------------- names


def _display(text: str) -> str:
    """An ID line for display: blanks collapsed (so it can never look like a '    -1' delimiter), cut to 80."""
    line = " ".join(text.split())[:_ID_WIDTH]
    return line or "NONE"


def _quoted(text: str, what: str) -> str:
    line = json.dumps(text, ensure_ascii=True)
    if len(line) > _ID_WIDTH:
        msg = (
            f"{what} {text!r} is too long for a UFF ID line: at most {_ID_WIDTH} characters after JSON quoting; "
            f"got {len(line)}"
        )
        raise DataError(msg)
    return line


def _unquoted(line: str) -> str | None:
    try:
        value = json.loads(line)
    except json.JSONDecodeError:
        return None
    return value if isinstance(value, str) else None


def _split_label(label: str) -> tuple[str, int]:
    """``"tool:-z"`` -> ``("tool", -3)``; a label without a direction is a scalar point ``(label, 0)``."""
    m = _LABEL.match(label)
    if m is None:
        return label, 0
    code = _DIRECTIONS[m["dir"]]
    return m["node"], -code if m["sign"] == "-" else code


def _dof_name(node: int, direction: int) -> str:
    if direction == 0:
        return str(node)
    name = _DIRECTION_NAMES.get(abs(direction))
    if name is None:
        return f"{node}:{direction}"
    return f"{node}:{'-' if direction < 0 else '+'}{name}"


def _number_nodes(names: Sequence[str], fixed: Mapping[str, int] | None = None) -> dict[str, int]:
    """Node numbers: integer names keep theirs, others follow the largest in order of first appearance."""
    numbers = dict(fixed or {})
    for name in names:
        if name not in numbers and _NODE_NUMBER.match(name):
            numbers[name] = int(name)
    taken = set(numbers.values())
    nxt = max(taken, default=0) + 1
    for name in names:
        if name not in numbers:
            while nxt in taken:
                nxt += 1
            numbers[name] = nxt
            taken.add(nxt)
    return numbers


def _meta(line: str) -> dict[str, str]:
    """``key=value`` tokens of an ID line."""
    return dict(tok.split("=", 1) for tok in line.split() if "=" in tok)


def _cappe_kind(dset: Mapping[str, Any]) -> str | None:
    words = str(dset.get("id2", "")).split()
    return words[1] if len(words) >= 2 and words[0] == UFF_FORMAT else None


def _float_token(meta: Mapping[str, str], key: str) -> float | None:
    try:
        value = float(meta[key])
    except (KeyError, ValueError):
        return None
    return value if math.isfinite(value) else None


# ------------------------------------------------------------------------------------------------ abscissa


def _abscissa(x: NDArray[np.float64], binary: bool) -> tuple[int, str]:
    """Choose even (1) or uneven (0) spacing and the exact ID-line tokens for an even abscissa.

    Even spacing is used when ``x0 + k * dx`` (or ``x0 + k / rate``) reproduces ``x`` bit for bit, and in ASCII
    files also when every step is within 1e-6 of the mean step (an uneven ASCII abscissa would keep only 6 digits;
    the grid is then rebuilt as ``x0 + k * mean step``). Otherwise the abscissa is written point by point (exact in
    binary files); in ASCII files a log-spaced abscissa (``np.geomspace(x0, xn, n)`` to 4 ulps) also gets the
    tokens ``x0=`` and ``xn=``, from which cappe's reader rebuilds it exactly.
    """
    k = np.arange(x.size, dtype=float)
    x0 = float(x[0])
    steps = (float(x[1] - x[0]), float((x[-1] - x[0]) / (x.size - 1)))
    for dx in steps:
        if dx > 0 and np.array_equal(x0 + k * dx, x):
            return 1, f"x0={x0!r} dx={dx!r}"
    dx = steps[1]
    if dx > 0:
        rate = float(np.round(1.0 / dx, 9))
        if np.array_equal(x0 + k / rate, x):
            return 1, f"x0={x0!r} rate={rate!r}"
        if not binary and np.all(np.abs(np.diff(x) - dx) <= _UNIFORM_RTOL * dx):
            return 1, f"x0={x0!r} dx={dx!r}"
    if not binary and x0 > 0 and x.size > 2:
        xn = float(x[-1])
        if xn > x0 and np.allclose(np.geomspace(x0, xn, x.size), x, rtol=_GEOMETRIC_RTOL, atol=0.0):
            return 0, f"x0={x0!r} xn={xn!r}"  # log-spaced: the reader rebuilds np.geomspace(x0, xn, n)
    return 0, ""


def _exact_abscissa(p: Path, k: int, dset: Mapping[str, Any]) -> NDArray[np.float64]:
    """The abscissa of a UFF 58 dataset, from cappe's ID line 2 when it agrees with the header."""
    x = np.asarray(dset["x"], dtype=float)
    if _cappe_kind(dset) is None:
        return x
    meta = _meta(str(dset["id2"]))
    if int(dset.get("abscissa_spacing", 0)) != 1:
        return _geometric_abscissa(p, k, dset, meta, x)
    x0 = _float_token(meta, "x0")
    dx = _float_token(meta, "dx")
    rate = _float_token(meta, "rate")
    if x0 is None or (dx is None and rate is None):
        return x
    step = dx if dx is not None else 1.0 / rate  # type: ignore[operator]
    head_x0, head_dx = float(dset["abscissa_min"]), float(dset["abscissa_inc"])
    if abs(x0 - head_x0) > _HEADER_RTOL * abs(x0) + 1e-300 or abs(step - head_dx) > _HEADER_RTOL * abs(step):
        warnings.warn(
            f"dataset #{k + 1} of {p}: ID line 2 ({dset['id2']!r}) disagrees with the abscissa header "
            f"(x0 = {head_x0:.6g}, step = {head_dx:.6g}); using the header",
            DataWarning,
            stacklevel=3,
        )
        return x
    n = np.arange(x.size, dtype=float)
    return x0 + n * dx if dx is not None else x0 + n / rate  # type: ignore[operator]


def _geometric_abscissa(p: Path, k: int, dset: Mapping[str, Any], meta: Mapping[str, str],
                        x: NDArray[np.float64]) -> NDArray[np.float64]:
    """A log-spaced abscissa rebuilt from cappe's ``x0=`` and ``xn=`` tokens when it agrees with the 6 digits of the
    file's own abscissa (else that abscissa, with a warning)."""
    x0, xn = _float_token(meta, "x0"), _float_token(meta, "xn")
    if x0 is None or xn is None or x.size < 3 or not 0 < x0 < xn:
        return x
    rebuilt = np.geomspace(x0, xn, x.size)
    if not np.allclose(rebuilt, x, rtol=_HEADER_RTOL, atol=0.0):
        warnings.warn(
            f"dataset #{k + 1} of {p}: ID line 2 ({dset['id2']!r}) disagrees with the abscissa it holds "
            f"({x[0]:.6g} to {x[-1]:.6g}); using the abscissa",
            DataWarning,
            stacklevel=4,
        )
        return x
    return np.asarray(rebuilt, dtype=float)


def _record_58(
    *,
    func_type: int,
    x: NDArray[np.float64],
    data: NDArray[Any],
    binary: bool,
    kind: str,
    ids: tuple[str, str, str, str],
    response: tuple[int, int],
    reference: tuple[int, int],
    types: tuple[int, int, int],
    ordinate_units: str = "NONE",
) -> dict[str, Any]:
    spacing, tokens = _abscissa(x, binary)
    return {
        "type": 58,
        "binary": int(binary),
        "func_type": func_type,
        "id1": ids[0],
        "id2": f"{UFF_FORMAT} {kind} {tokens}".strip(),
        "id3": ids[1],
        "id4": ids[2],
        "id5": ids[3],
        "rsp_node": response[0],
        "rsp_dir": response[1],
        "ref_node": reference[0],
        "ref_dir": reference[1],
        "x": np.asarray(x, dtype=float),
        "data": data,
        "abscissa_spacing": spacing,
        "abscissa_spec_data_type": types[0],
        "ordinate_spec_data_type": types[1],
        "orddenom_spec_data_type": types[2],
        "ordinate_axis_units_lab": ordinate_units,
    }


def _check_abscissa(x: NDArray[np.float64], what: str) -> None:
    if x.size < 2:
        msg = f"UFF 58 needs at least 2 {what} points; got {x.size}"
        raise DataError(msg)


# --------------------------------------------------------------------------------------------- time data


def write_uff_time_data(path: str | Path, data: TimeData, *, binary: bool = False) -> Path:
    """Write time data as UFF 58 function type 1 datasets, one per channel (atomically).

    Parameters
    ----------
    path : str or Path
        Target file (``.uff`` or ``.unv`` by convention).
    data : TimeData
        Channels to write; names and units round-trip exactly (see the module notes on ID lines).
    binary : bool
        Write binary ``58b`` datasets (exact doubles) instead of ASCII (12 significant digits).

    Returns
    -------
    Path
        The file written.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import numpy as np
    >>> data = TimeData.from_rate(100.0, {"F": [0.0, 1.0, 0.5], "3:z": [0.0, 0.1, 0.2]})
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = write_uff_time_data(pathlib.Path(tmp) / "run.uff", data, binary=True)
    ...     back = read_uff_time_data(path)
    >>> back.channels, bool(np.array_equal(back.values, data.values))
    (('F', '3:z'), True)
    """
    if not isinstance(data, TimeData):
        msg = f"data must be a TimeData; got {type(data).__name__}"
        raise DataError(msg)
    units = data.units or ("",) * data.n_channels
    nodes = _number_nodes([_split_label(c)[0] for c in data.channels])
    records = []
    for name, unit, row in zip(data.channels, units, data.values, strict=True):
        node, direction = _split_label(name)
        # the 20-character axis-units label, for other programs (the exact unit is in ID line 5)
        plain = len(unit) <= 20 and _GROUP_NAME.match(unit) and unit.isascii() and unit.isprintable()
        label = unit if plain else "NONE"
        records.append(
            _record_58(
                func_type=TIME,
                x=data.time,
                data=np.asarray(row, dtype=float),
                binary=binary,
                kind="time",
                ids=(_display(name), "NONE", _quoted(name, "channel name"), _quoted(unit, f"unit of channel {name!r}")),
                response=(nodes[node], direction),
                reference=(0, 0),
                types=(_ABSCISSA_TIME, _UNIT_TYPES.get(unit, 0), 0),
                ordinate_units=label,
            )
        )
    _write_datasets(path, records)
    return Path(path)


def read_uff_time_data(path: str | Path) -> TimeData:
    """Read the UFF 58 function type 1 (time response) datasets of a file as one TimeData.

    Channels written by cappe keep their exact names and units. Channels of other programs are named by their ID
    line 1 (``"Mic 01"``) when it gives every such channel a different name, else from the response node and
    direction, e.g. ``"12:+z"`` (``"12"`` for a scalar point); a repeated name gets a ``" (dataset k)"`` suffix.
    Their units come from the ordinate axis-units label (empty when ``NONE``).
    All channels must share one time axis. Other datasets in the file are ignored.

    Parameters
    ----------
    path : str or Path
        The file to read.

    Returns
    -------
    TimeData

    Examples
    --------
    >>> import pathlib, tempfile
    >>> data = TimeData.from_rate(1000.0, {"acc": [0.0, 0.5, -0.25]})
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     back = read_uff_time_data(write_uff_time_data(pathlib.Path(tmp) / "a.uff", data))
    >>> back.channels, back.fs
    (('acc',), 1000.0)
    """
    p, uff, types = _open_uff(path)
    names: list[str] = []
    units: list[str] = []
    rows: list[NDArray[np.float64]] = []
    id_names: dict[int, str] = {}  # channel -> ID line 1, for channels of other programs
    time: NDArray[np.float64] | None = None
    first = 0
    for k, t in enumerate(types):
        if t != 58:
            continue
        head = _read_set(p, uff, k, t, header_only=True)
        if int(head["func_type"]) != TIME:
            continue
        dset = _read_set(p, uff, k, t)
        x = _exact_abscissa(p, k, dset)
        values = np.asarray(dset["data"])
        if np.iscomplexobj(values):
            msg = f"dataset #{k + 1} of {p} is a time response with complex values; expected real samples"
            raise DataError(msg)
        if time is None:
            time, first = x, k
        elif x.shape != time.shape or not np.allclose(x, time, rtol=1e-9, atol=0.0):
            msg = (
                f"dataset #{k + 1} of {p} has a different time axis ({x.size} samples from {x[0]:.9g} s) than "
                f"dataset #{first + 1} ({time.size} samples from {time[0]:.9g} s); all channels must share one"
            )
            raise DataError(msg)
        name, unit = _time_channel_name(dset)
        if name is None:
            id_names[len(names)] = str(dset.get("id1", "")).strip()
            name = _dof_name(int(dset["rsp_node"]), int(dset["rsp_dir"]))
            if name in names:
                name = f"{name} (dataset {k + 1})"
        names.append(name)
        units.append(unit)
        rows.append(np.asarray(values, dtype=float))
    if time is None:
        msg = f"{p} holds no time data (UFF 58 function type 1); found {_found(p, uff, types)}"
        raise DataError(msg)
    # other programs name their channels in ID line 1 ("Mic 01"): used when it names every such channel, each
    # differently (a line common to all datasets, like "Point" or "NONE", names none of them)
    labels = list(id_names.values())
    exact = {name for c, name in enumerate(names) if c not in id_names}
    named = all(lab and lab.upper() != "NONE" for lab in labels)
    if labels and named and len(set(labels)) == len(labels) and not set(labels) & exact:
        names = [id_names.get(c, name) for c, name in enumerate(names)]
    try:
        return TimeData(time, np.array(rows), tuple(names), tuple(units) if any(units) else ())
    except DataError as exc:
        msg = f"{p}: {exc}"
        raise DataError(msg) from exc


def _time_channel_name(dset: Mapping[str, Any]) -> tuple[str | None, str]:
    """Name and unit of a time channel: cappe's ID lines 4/5, else None and the axis-units label."""
    label = str(dset.get("ordinate_axis_units_lab", "")).strip()
    unit = "" if label.upper() in ("", "NONE") else label
    if _cappe_kind(dset) == "time":
        name = _unquoted(str(dset.get("id4", "")))
        exact_unit = _unquoted(str(dset.get("id5", "")))
        if name is not None:
            return name, exact_unit if exact_unit is not None else unit
    return None, unit


# --------------------------------------------------------------------------------------------------- FRFs


def check_frf(frf: FRFData) -> None:
    """Check an FRFData for writing: its structure is checked on construction, here the values must be finite."""
    if not isinstance(frf, FRFData):
        msg = f"frf must be an FRFData; got {type(frf).__name__}"
        raise DataError(msg)
    bad = np.argwhere(~np.isfinite(np.asarray(frf.H)))
    if bad.size:
        o, i, f = bad[0]
        msg = (
            f"FRF {frf.output_names[o]!r}/{frf.input_names[i]!r} has {len(bad)} non-finite value(s), first at "
            f"{frf.freq[f]:.6g} Hz"
        )
        raise DataError(msg)


def write_uff_frf(path: str | Path, frf: FRFData, *, binary: bool = False) -> Path:
    """Write FRFs as UFF 58 function type 4 datasets, one per (output, input) pair (atomically).

    The reference DOF is the input, the response DOF the output (see the module notes on node numbers).
    Coherence, when set, follows as function type 6 datasets in the same pair order. ``window_decay`` and the
    output quantities are kept in ID line 3; the quantity also sets the ordinate data type (8 displacement,
    11 velocity, 12 acceleration) that modal software such as sdypy-EMA uses to pick the FRF form.

    Parameters
    ----------
    path : str or Path
        The file to write.
    frf : FRFData
        The FRFs.
    binary : bool
        Binary UFF 58b instead of ASCII.

    Returns
    -------
    Path
        ``path``.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import numpy as np
    >>> frf = FRFData(np.array([1.0, 2.0]), np.ones((1, 1, 2)) * (1 - 1j), ("F",), ("tool:x",))
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     back = read_uff_frf(write_uff_frf(pathlib.Path(tmp) / "h.uff", frf))
    >>> back.output_names, back.input_names, back.H[0, 0, 1]
    (('tool:x',), ('F',), np.complex128(1-1j))
    """
    check_frf(frf)
    freq = np.asarray(frf.freq, dtype=float)
    _check_abscissa(freq, "frequency")
    quantities = frf.output_quantities or ("",) * len(frf.output_names)
    nodes = _number_nodes([_split_label(n)[0] for n in (*frf.output_names, *frf.input_names)])
    decay = "" if frf.window_decay is None else f"decay={float(frf.window_decay)!r}"
    records = []
    for func, kind, values in ((FRF, "frf", frf.H), (COHERENCE, "coherence", frf.coherence)):
        if values is None:
            continue
        for o, out in enumerate(frf.output_names):
            quantity = quantities[o]
            if quantity and not re.fullmatch(r"\S+", quantity):
                msg = f"output quantity {quantity!r} of {out!r} must be one word to fit UFF ID line 3"
                raise DataError(msg)
            meta = " ".join(t for t in (decay, f"quantity={quantity}" if quantity else "") if t) or "NONE"
            rsp_node, rsp_dir = _split_label(out)
            for i, inp in enumerate(frf.input_names):
                ref_node, ref_dir = _split_label(inp)
                is_frf = func == FRF
                records.append(
                    _record_58(
                        func_type=func,
                        x=freq,
                        data=np.asarray(values[o, i], dtype=complex if is_frf else float),
                        binary=binary,
                        kind=kind,
                        ids=(
                            _display(f"{'H' if is_frf else 'coherence'} {out} / {inp}"),
                            meta,
                            _quoted(out, "output name"),
                            _quoted(inp, "input name"),
                        ),
                        response=(nodes[rsp_node], rsp_dir),
                        reference=(nodes[ref_node], ref_dir),
                        types=(
                            _ABSCISSA_FREQUENCY,
                            _QUANTITY_TYPES.get(quantity, 0) if is_frf else 0,
                            _EXCITATION_FORCE if is_frf else 0,
                        ),
                    )
                )
    _write_datasets(path, records)
    return Path(path)


@dataclass
class _Curve:
    k: int
    output: str
    input: str
    multiple: bool  # a multiple coherence: applies to every input of the output
    x: NDArray[np.float64]
    values: NDArray[Any]
    meta: dict[str, str]
    quantity_code: int


def read_uff_frf(path: str | Path) -> FRFData:
    """Read the UFF 58 FRF datasets (function type 4) of a file, with coherence (6 or 26) when present.

    FRFs written by cappe keep exact names, window decay and output quantities. For other files, outputs are
    named from the response DOF and inputs from the reference DOF (``"12:+z"``), quantities come from the
    ordinate data type (all known or none), and the window decay is unknown (None). The datasets must form a
    complete output x input grid on one frequency axis; coherence, when present, must cover every pair.
    Other datasets in the file are ignored.

    Parameters
    ----------
    path : str or Path
        The file to read.

    Returns
    -------
    FRFData

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import numpy as np
    >>> H = np.arange(8.0).reshape(2, 1, 4) * (1 + 2j)
    >>> frf = FRFData(np.linspace(0.0, 30.0, 4), H, ("F1",), ("d1", "d2"), ("velocity", "velocity"))
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     back = read_uff_frf(write_uff_frf(pathlib.Path(tmp) / "h.uff", frf, binary=True))
    >>> bool(np.array_equal(back.H, H)), back.output_quantities
    (True, ('velocity', 'velocity'))
    """
    p, uff, types = _open_uff(path)
    frfs: list[_Curve] = []
    cohs: list[_Curve] = []
    for k, t in enumerate(types):
        if t != 58:
            continue
        func = int(_read_set(p, uff, k, t, header_only=True)["func_type"])
        if func not in (FRF, COHERENCE, MULTIPLE_COHERENCE):
            continue
        dset = _read_set(p, uff, k, t)
        curve = _frf_curve(k, dset, func, _exact_abscissa(p, k, dset))
        (frfs if func == FRF else cohs).append(curve)
    if not frfs:
        msg = f"{p} holds no FRFs (UFF 58 function type 4); found {_found(p, uff, types)}"
        raise DataError(msg)
    outputs = list(dict.fromkeys(c.output for c in frfs))
    inputs = list(dict.fromkeys(c.input for c in frfs))
    H, missing = _grid(p, frfs, frfs[0], outputs, inputs, "the FRF", complex)
    if missing:
        msg = f"{p} lacks the FRF(s) {missing} to complete the {len(outputs)} x {len(inputs)} output x input grid"
        raise DataError(msg)
    coherence = _assemble_coherence(p, cohs, frfs[0], outputs, inputs) if cohs else None
    return FRFData(
        freq=frfs[0].x,
        H=H,
        input_names=tuple(inputs),
        output_names=tuple(outputs),
        output_quantities=_quantities(frfs, outputs),
        coherence=coherence,
        window_decay=_decay(p, frfs),
    )


def _frf_curve(k: int, dset: Mapping[str, Any], func: int, x: NDArray[np.float64]) -> _Curve:
    out = inp = None
    if _cappe_kind(dset) in ("frf", "coherence"):
        out = _unquoted(str(dset.get("id4", "")))
        inp = _unquoted(str(dset.get("id5", "")))
    if out is None or inp is None:
        out = _dof_name(int(dset["rsp_node"]), int(dset["rsp_dir"]))
        inp = _dof_name(int(dset["ref_node"]), int(dset["ref_dir"]))
    values = np.asarray(dset["data"])
    if func != FRF:
        values = np.asarray(values.real, dtype=float)
    return _Curve(
        k=k,
        output=out,
        input=inp,
        multiple=func == MULTIPLE_COHERENCE,
        x=x,
        values=values,
        meta=_meta(str(dset.get("id3", ""))) if _cappe_kind(dset) else {},
        quantity_code=int(dset.get("ordinate_spec_data_type", 0)),
    )


def _check_same_axis(p: Path, curve: _Curve, ref: _Curve) -> None:
    if curve.x.shape != ref.x.shape or not np.allclose(curve.x, ref.x, rtol=1e-9, atol=0.0):
        msg = (
            f"dataset #{curve.k + 1} of {p} has a different frequency axis ({curve.x.size} points from "
            f"{curve.x[0]:.9g} Hz) than dataset #{ref.k + 1} ({ref.x.size} points from {ref.x[0]:.9g} Hz)"
        )
        raise DataError(msg)


def _grid(
    p: Path, curves: Sequence[_Curve], ref: _Curve, outputs: Sequence[str], inputs: Sequence[str], what: str,
    dtype: type,
) -> tuple[NDArray[Any], list[str]]:
    """Curves placed on the output x input grid (a multiple coherence on every input of its output), and the
    ``"out/in"`` pairs no curve covers."""
    grid: NDArray[Any] = np.full((len(outputs), len(inputs), ref.x.size), np.nan, dtype=dtype)
    where: dict[tuple[int, int], int] = {}
    for c in curves:
        _check_same_axis(p, c, ref)
        o = outputs.index(c.output)
        for i in range(len(inputs)) if c.multiple else [inputs.index(c.input)]:
            if (o, i) in where:
                msg = f"datasets #{where[o, i] + 1} and #{c.k + 1} of {p} both hold {what} {c.output!r}/{inputs[i]!r}"
                raise DataError(msg)
            where[o, i] = c.k
            grid[o, i] = c.values
    missing = [f"{out}/{inp}" for o, out in enumerate(outputs) for i, inp in enumerate(inputs) if (o, i) not in where]
    return grid, missing


def _assemble_coherence(
    p: Path, cohs: Sequence[_Curve], ref: _Curve, outputs: Sequence[str], inputs: Sequence[str]
) -> NDArray[np.float64]:
    for c in cohs:
        if c.output not in outputs or (not c.multiple and c.input not in inputs):
            pair = f"{c.output!r} (multiple)" if c.multiple else f"{c.output!r}/{c.input!r}"
            msg = f"dataset #{c.k + 1} of {p} holds coherence for {pair}, which has no FRF"
            raise DataError(msg)
    coherence, missing = _grid(p, cohs, ref, outputs, inputs, "coherence for", float)
    if missing:
        msg = f"{p} has coherence for some FRFs but not for {missing}"
        raise DataError(msg)
    return coherence


def _quantities(frfs: Sequence[_Curve], outputs: Sequence[str]) -> tuple[str, ...]:
    found: dict[str, str] = {}
    for c in frfs:
        q = c.meta.get("quantity") or _TYPE_QUANTITIES.get(c.quantity_code, "")
        found.setdefault(c.output, q)
    quantities = tuple(found[o] for o in outputs)
    return quantities if all(quantities) else ()


def _decay(p: Path, frfs: Sequence[_Curve]) -> float | None:
    values = {_float_token(c.meta, "decay") for c in frfs}
    if len(values) > 1:
        msg = f"the FRF datasets of {p} disagree on the window decay (ID line 3): {sorted(map(str, values))}"
        raise DataError(msg)
    return values.pop()


# -------------------------------------------------------------------------------------------------- nodes


def _group(number: int, name: str, node: int) -> dict[str, Any]:
    if len(name) > _GROUP_WIDTH or not _GROUP_NAME.match(name) or not name.isascii() or not name.isprintable():
        what = name[len(_SENSOR_GROUP):] if name.startswith(_SENSOR_GROUP) else name[len(_NODE_GROUP):]
        msg = (
            f"{'sensor' if name.startswith(_SENSOR_GROUP) else 'node'} name {what!r} cannot be stored in a UFF "
            f"2467 group name {name!r}: at most {_GROUP_WIDTH} printable ASCII characters including the prefix, "
            "without leading, trailing or repeated blanks"
        )
        raise DataError(msg)
    zero = np.zeros(1, dtype=int)
    return {
        "group_number": number,
        "group_name": name,
        "entity_type_code": np.array([_NODE_ENTITY]),
        "entity_tag": np.array([node]),
        "entity_node_leaf_id": zero,
        "entity_component_id": zero,
        "active_constraint_set_no_for_group": 0,
        "active_restraint_set_no_for_group": 0,
        "active_load_set_no_for_group": 0,
        "active_dof_set_no_for_group": 0,
        "active_temperature_set_no_for_group": 0,
        "active_contact_set_no_for_group": 0,
    }


def _coordinates(coords: Mapping[Any, Any]) -> dict[Any, tuple[float, float, float]]:
    out: dict[Any, tuple[float, float, float]] = {}
    for key, xyz in coords.items():
        if isinstance(key, bool) or not isinstance(key, (int, np.integer, str)):
            msg = f"node keys must be names (str) or node numbers (int); got {key!r}"
            raise DataError(msg)
        try:
            arr = np.asarray(xyz, dtype=float)
        except (TypeError, ValueError) as exc:
            msg = f"coordinates of node {key!r} must be three numbers (x, y, z) in m; got {xyz!r}"
            raise DataError(msg) from exc
        if arr.shape != (3,) or not np.all(np.isfinite(arr)):
            msg = f"coordinates of node {key!r} must be three finite numbers (x, y, z) in m; got {xyz!r}"
            raise DataError(msg)
        out[int(key) if isinstance(key, (int, np.integer)) else key] = (float(arr[0]), float(arr[1]), float(arr[2]))
    return out


def _node_dataset(dataset: int, numbers: Sequence[int], xyz: Sequence[tuple[float, float, float]]) -> dict[str, Any]:
    if dataset not in (15, 2411):
        msg = f"node dataset must be 15 (single precision) or 2411 (double precision); got {dataset!r}"
        raise DataError(msg)
    arr = np.array(xyz, dtype=float).reshape(-1, 3)
    zeros = np.zeros(len(numbers), dtype=int)
    return {
        "type": dataset,
        "node_nums": np.array(numbers, dtype=int),
        "def_cs": zeros,
        "disp_cs": zeros,
        "color": zeros,
        "x": arr[:, 0],
        "y": arr[:, 1],
        "z": arr[:, 2],
    }


def write_uff_nodes(
    path: str | Path, coords: Mapping[str | int, Sequence[float]], *, dataset: int = 2411
) -> Path:
    """Write node coordinates (m) as UFF 2411 (double precision, default) or UFF 15 (6 digits), atomically.

    Integer keys are node numbers. String keys are node names: each gets a UFF 2467 group ``"node <name>"`` so
    that :func:`read_uff_nodes` returns the same keys; a name that is a positive integer keeps that number.

    Parameters
    ----------
    path : str or Path
        The file to write.
    coords : mapping name or number -> (x, y, z)
        Node coordinates in m.
    dataset : {2411, 15}
        UFF dataset type.

    Returns
    -------
    Path
        ``path``.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = write_uff_nodes(pathlib.Path(tmp) / "geo.uff", {"tool": (0.0, 0.1, 0.2), 7: (1.0, 0.0, 0.0)})
    ...     read_uff_nodes(path)
    {'tool': (0.0, 0.1, 0.2), 7: (1.0, 0.0, 0.0)}
    """
    points = _coordinates(coords)
    fixed = {str(k): k for k in points if isinstance(k, int)}
    names = [k for k in points if isinstance(k, str)]
    clash = sorted(set(fixed) & set(names))
    if clash:
        msg = f"node keys {clash[0]!r} (name) and {int(clash[0])} (number) both map to node {clash[0]}"
        raise DataError(msg)
    bad = [k for k in fixed.values() if not _NODE_NUMBER.match(str(k))]
    if bad:
        msg = f"node numbers must be positive integers of at most 9 digits; got {bad[0]}"
        raise DataError(msg)
    numbers = _number_nodes(names, fixed)
    groups = [_group(g + 1, f"{_NODE_GROUP}{name}", numbers[name]) for g, name in enumerate(names)]
    datasets: list[dict[str, Any]] = [{"type": 2467, "groups": groups}] if groups else []
    datasets.append(_node_dataset(dataset, [numbers[str(k)] for k in points], list(points.values())))
    _write_datasets(path, datasets)
    return Path(path)


def _groups(p: Path, uff: Any, types: Sequence[int]) -> tuple[dict[int, str], list[tuple[int, str, int]]]:
    """cappe's name groups: node number -> name, and sensors as (group number, label, node number)."""
    names: dict[int, str] = {}
    sensors: list[tuple[int, str, int]] = []
    for k, t in enumerate(types):
        if t != 2467:
            continue
        for g in _read_set(p, uff, k, t).get("groups", []):
            codes, tags = np.atleast_1d(g["entity_type_code"]), np.atleast_1d(g["entity_tag"])
            if codes.size != 1 or int(codes[0]) != _NODE_ENTITY:
                continue
            name, node = str(g["group_name"]), int(tags[0])
            if name.startswith(_SENSOR_GROUP):
                label = name[len(_SENSOR_GROUP):]
                sensors.append((int(g["group_number"]), label, node))
                names.setdefault(node, _split_label(label)[0])
            elif name.startswith(_NODE_GROUP):
                names[node] = name[len(_NODE_GROUP):]
    sensors.sort()
    return names, sensors


def read_uff_nodes(path: str | Path) -> dict[str | int, tuple[float, float, float]]:
    """Read node coordinates (UFF 15 and 2411) in file order: ``{name or number: (x, y, z)}``.

    Nodes named by cappe's UFF 2467 groups come back under their names (str), other nodes under their
    numbers (int).

    Parameters
    ----------
    path : str or Path
        The file to read.

    Returns
    -------
    dict
        ``{name or number: (x, y, z)}`` in m.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     read_uff_nodes(write_uff_nodes(pathlib.Path(tmp) / "g.uff", {3: (0.5, 0.0, 0.25)}, dataset=15))
    {3: (0.5, 0.0, 0.25)}
    """
    p, uff, types = _open_uff(path)
    names, _ = _groups(p, uff, types)
    out: dict[str | int, tuple[float, float, float]] = {}
    seen: dict[int, int] = {}
    for k, t in enumerate(types):
        if t not in (15, 2411):
            continue
        dset = _read_set(p, uff, k, t)
        for num, x, y, z in zip(dset["node_nums"], dset["x"], dset["y"], dset["z"], strict=True):
            node = int(num)
            if node in seen:
                msg = f"node {node} is defined twice in {p} (datasets #{seen[node] + 1} and #{k + 1})"
                raise DataError(msg)
            seen[node] = k
            out[names.get(node, node)] = (float(x), float(y), float(z))
    if not seen:
        msg = f"{p} holds no node coordinates (UFF 15 or 2411); found {_found(p, uff, types)}"
        raise DataError(msg)
    return out


# ---------------------------------------------------------------------------------------------- modal data


def _check_modal(modal: ModalData) -> list[tuple[str, int]]:
    if not isinstance(modal, ModalData):
        msg = f"modal must be a ModalData; got {type(modal).__name__}"
        raise DataError(msg)
    if not modal.sets:
        msg = "modal data has no sets; UFF 55 stores one dataset per mode"
        raise DataError(msg)
    dofs = []
    for label in modal.sensors:
        node, direction = _split_label(label)
        if direction == 0:
            msg = f"sensor {label!r} must be 'node:direction' with direction x, y, z, rx, ry or rz for UFF 55"
            raise DataError(msg)
        dofs.append((node, direction))
    taken: dict[tuple[str, int], str] = {}
    for label, (node, direction) in zip(modal.sensors, dofs, strict=True):
        other = taken.setdefault((node, abs(direction)), label)
        if other != label:
            msg = f"sensors {other!r} and {label!r} measure the same UFF degree of freedom"
            raise DataError(msg)
    n_s = len(modal.sensors)
    for k, s in enumerate(modal.sets):
        m = np.asarray(s.frequency).size
        shapes = np.asarray(s.shapes)
        if m == 0:
            msg = f"set {k} of the modal data has no modes; UFF 55 stores one dataset per mode"
            raise DataError(msg)
        if shapes.shape != (n_s, m) or np.asarray(s.damping).shape != (m,):
            msg = (
                f"set {k}: shapes must have shape (n_sensors, n_modes) = ({n_s}, {m}) and damping ({m},); "
                f"got {shapes.shape} and {np.asarray(s.damping).shape}"
            )
            raise DataError(msg)
        if not (np.all(np.isfinite(shapes)) and np.all(np.isfinite(s.frequency)) and np.all(np.isfinite(s.damping))):
            msg = f"set {k} of the modal data holds NaN or Inf"
            raise DataError(msg)
        freq, damping = np.asarray(s.frequency), np.asarray(s.damping)
        if np.any(freq <= 0) or np.any(damping < 0) or np.any(damping >= 1):
            msg = f"set {k}: frequencies must be > 0 Hz and damping ratios in [0, 1); got {freq} Hz and {damping}"
            raise DataError(msg)
        for axis in s.position:
            if not re.fullmatch(r"[^\s=]+", str(axis)):
                msg = f"axis name {axis!r} in set {k} must be one word without '=' to fit UFF ID line 4"
                raise DataError(msg)
    return dofs


def write_uff_modal(
    path: str | Path,
    modal: ModalData,
    *,
    coordinates: Mapping[str | int, Sequence[float]] | None = None,
    node_dataset: int = 2411,
) -> Path:
    """Write modal data as UFF 55 (one dataset per mode) with optional node coordinates, atomically.

    Each set (axis position) is one load case (``load_case = set index + 1``), with its position in ID line 4.
    Real shapes are written as normal modes (analysis type 2: frequency in Hz and viscous damping ratio), complex
    shapes as complex modes (analysis type 3) with the eigenvalue ``-zeta omega + 1j omega sqrt(1 - zeta^2)``
    in rad/s; both read back with frequency and damping exact (ID line 5) and shapes to 6 significant digits.
    Rotational sensors need real shapes (pyuff writes complex data with 3 values per node only).

    Parameters
    ----------
    path : str or Path
        Target file.
    modal : ModalData
        Sensors ``"node:direction"``; see the module notes on node numbers and names.
    coordinates : mapping, optional
        ``{node name: (x, y, z)}`` in m, written as UFF 2411 (or 15) nodes. Integer keys are taken as names
        (``3`` is node ``"3"``); nodes without sensors are allowed (geometry).
    node_dataset : {2411, 15}
        Node dataset type.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import numpy as np
    >>> from cappe.systems import ModalDataSet
    >>> s = ModalDataSet({"z": 0.1}, np.array([50.0]), np.array([0.02]), np.array([[1.0], [0.5 - 0.1j]]))
    >>> modal = ModalData(("tool:x", "tool:y"), (s,))
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     back = read_uff_modal(write_uff_modal(pathlib.Path(tmp) / "m.uff", modal))
    >>> back.sensors, back.sets[0].position, back.sets[0].frequency
    (('tool:x', 'tool:y'), {'z': 0.1}, array([50.]))
    """
    dofs = _check_modal(modal)
    points = {str(k): v for k, v in _coordinates(coordinates or {}).items()}
    if coordinates is not None and len(points) != len(coordinates):
        msg = "coordinates name the same node twice (as a number and as a string)"
        raise DataError(msg)
    sensor_nodes = list(dict.fromkeys(node for node, _ in dofs))
    numbers = _number_nodes([*sensor_nodes, *points])
    groups = [_group(g + 1, f"{_SENSOR_GROUP}{label}", numbers[dofs[g][0]]) for g, label in enumerate(modal.sensors)]
    extra = [name for name in points if name not in sensor_nodes]
    groups += [_group(len(groups) + g + 1, f"{_NODE_GROUP}{name}", numbers[name]) for g, name in enumerate(extra)]
    datasets: list[dict[str, Any]] = [{"type": 2467, "groups": groups}]
    if points:
        datasets.append(_node_dataset(node_dataset, [numbers[n] for n in points], list(points.values())))

    rotations = any(abs(d) > 3 for _, d in dofs)
    complex_shapes = any(np.any(np.asarray(s.shapes).imag != 0) for s in modal.sets)
    if rotations and complex_shapes:
        rot = next(label for label, (_, d) in zip(modal.sensors, dofs, strict=True) if abs(d) > 3)
        msg = (
            f"complex mode shapes with rotational sensors (e.g. {rot!r}) cannot be written to UFF 55: pyuff writes "
            "complex data with 3 values per node only; use real shapes or the cappe.modal/1 JSON format"
        )
        raise DataError(msg)
    n_slots = 6 if rotations else 3
    node_index = {node: j for j, node in enumerate(sensor_nodes)}
    for k, s in enumerate(modal.sets):
        position = " ".join(f"{axis}={float(v)!r}" for axis, v in s.position.items()) or "NONE"
        if len(position) > _ID_WIDTH:
            msg = f"the position of set {k} ({position}) does not fit UFF ID line 4 ({_ID_WIDTH} characters)"
            raise DataError(msg)
        shapes = np.asarray(s.shapes)
        for j in range(shapes.shape[1]):
            f, zeta = float(s.frequency[j]), float(s.damping[j])
            r = np.zeros((n_slots, len(sensor_nodes)), dtype=complex if complex_shapes else float)
            for row, (node, direction) in enumerate(dofs):
                value = shapes[row, j] if complex_shapes else shapes[row, j].real
                r[abs(direction) - 1, node_index[node]] = -value if direction < 0 else value
            dset: dict[str, Any] = {
                "type": 55,
                "id1": _display(f"mode {j + 1} of set {k + 1}: {f:.6g} Hz, damping {zeta:.4g}"),
                "id2": f"{UFF_FORMAT} modal set={k + 1} mode={j + 1}",
                "id3": "NONE",
                "id4": position,
                "id5": f"freq={f!r} zeta={zeta!r}",
                "model_type": 1,
                "data_ch": 3 if rotations else 2,
                "spec_data_type": 8,
                "load_case": k + 1,
                "mode_n": j + 1,
                "node_nums": np.array([numbers[n] for n in sensor_nodes], dtype=int),
            }
            dset.update({f"r{slot + 1}": r[slot] for slot in range(n_slots)})
            if complex_shapes:
                w = 2 * np.pi * f
                dset.update(analysis_type=3, eig=complex(-zeta * w, w * math.sqrt(max(1.0 - zeta**2, 0.0))))
            else:
                dset.update(analysis_type=2, freq=f, modal_m=0.0, modal_damp_vis=zeta, modal_damp_his=0.0)
            datasets.append(dset)
    _write_datasets(path, datasets)
    return Path(path)


def _mode_values(p: Path, k: int, dset: Mapping[str, Any]) -> tuple[float, float, bool]:
    """Frequency (Hz), damping ratio and whether the shape must be conjugated (eigenvalue below the axis)."""
    conj = False
    if int(dset["analysis_type"]) == 2:
        f, zeta = float(dset["freq"]), float(dset.get("modal_damp_vis", 0.0))
    else:
        eig = complex(dset["eig"])
        conj = eig.imag < 0
        w = abs(eig)
        f, zeta = w / (2 * np.pi), (-eig.real / w if w > 0 else 0.0)
    if _cappe_kind(dset) == "modal":
        meta = _meta(str(dset.get("id5", "")))
        f_id, z_id = _float_token(meta, "freq"), _float_token(meta, "zeta")
        if f_id is not None and z_id is not None:
            # E13.5 record values carry 6 digits; zeta from an eigenvalue loses a few more near zero damping
            tol = 2 * _HEADER_RTOL
            if abs(f_id - f) <= tol * abs(f_id) and abs(z_id - zeta) <= tol * (abs(z_id) + 1e-6):
                return f_id, z_id, conj
            warnings.warn(
                f"dataset #{k + 1} of {p}: ID line 5 ({dset['id5']!r}) disagrees with the mode record "
                f"({f:.6g} Hz, damping {zeta:.6g}); using the record",
                DataWarning,
                stacklevel=3,
            )
    return f, zeta, conj


def read_uff_modal(path: str | Path) -> ModalData:
    """Read the UFF 55 mode datasets of a file (analysis type 2 normal or 3/7 complex modes) as ModalData; UFF 2414
    normal modes at nodes (an FE solver's results: frequency and viscous damping ratio of record 12, node values of
    records 14/15) are read the same way as one set, for comparison with measured modes.

    Files written by :func:`write_uff_modal` come back with their sensors, positions, frequencies and damping
    exactly and shapes to 6 significant digits. For other files, each load case becomes a set (position ``{}``),
    frequencies are undamped natural frequencies ``|lambda| / 2 pi`` of complex eigenvalues ``lambda`` (rad/s)
    with damping ``-Re(lambda) / |lambda|``, or the frequency and viscous damping ratio of normal modes; sensors
    are ``"node:x"`` ... (named nodes from cappe's groups keep their names), leaving out directions that are zero
    in every mode. All modes must list the same nodes. Node coordinates: :func:`read_uff_nodes`.

    Parameters
    ----------
    path : str or Path
        The file to read.

    Returns
    -------
    ModalData

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import numpy as np
    >>> from cappe.systems import ModalDataSet
    >>> s = ModalDataSet({}, np.array([12.5, 40.0]), np.array([0.01, 0.03]), np.array([[1.0, 0.2], [-0.4, 1.0]]))
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     back = read_uff_modal(write_uff_modal(pathlib.Path(tmp) / "m.uff", ModalData(("1:z", "2:z"), (s,))))
    >>> back.sensors, back.sets[0].damping
    (('1:z', '2:z'), array([0.01, 0.03]))
    """
    p, uff, types = _open_uff(path)
    modes = []
    other = []
    for k, t in enumerate(types):
        if t not in (55, 2414):
            continue
        dset = _read_set(p, uff, k, t)
        if t == 2414:
            if int(dset.get("analysis_type", 0)) == 2 and int(dset.get("dataset_location", 0)) == 1:
                modes.append((k, _normal_mode_2414(p, k, dset)))
            else:
                other.append(int(dset.get("analysis_type", 0)))
        elif int(dset.get("analysis_type", 0)) in (2, 3, 7):
            modes.append((k, dset))
        else:
            other.append(int(dset.get("analysis_type", 0)))
    if not modes:
        found = _found(p, uff, types) + (f" (UFF 55/2414 analysis types {sorted(set(other))})" if other else "")
        msg = (
            f"{p} holds no mode shapes (UFF 55 analysis type 2, 3 or 7, or UFF 2414 normal modes at nodes); found "
            f"{found}; supported: {SUPPORTED}"
        )
        raise DataError(msg)
    names, sensor_groups = _groups(p, uff, types)
    cappe = bool(sensor_groups) and all(_cappe_kind(d) == "modal" for _, d in modes)
    columns = [_columns(p, k, d) for k, d in modes]
    if cappe:
        sensors = [label for _, label, _ in sensor_groups]
        picks = []
        for _, label, node in sensor_groups:
            direction = _split_label(label)[1]
            picks.append((node, abs(direction) - 1, -1.0 if direction < 0 else 1.0))
    else:
        first_nodes = columns[0][0]
        n_slots = columns[0][1].shape[0]
        used = np.zeros((n_slots, first_nodes.size), dtype=bool)
        for (k, _), (nodes, r) in zip(modes, columns, strict=True):
            if not np.array_equal(nodes, first_nodes) or r.shape[0] != n_slots:
                msg = (
                    f"dataset #{k + 1} of {p} lists other nodes or values per node than dataset #{modes[0][0] + 1}; "
                    "all modes must share one set of degrees of freedom"
                )
                raise DataError(msg)
            used |= r != 0
        picks = [
            (int(node), slot, 1.0) for j, node in enumerate(first_nodes) for slot in range(n_slots) if used[slot, j]
        ]
        sensors = [f"{names.get(node, str(node))}:{_DIRECTION_NAMES[slot + 1]}" for node, slot, _ in picks]
    sets: dict[int, dict[str, Any]] = {}
    for (k, dset), (nodes, r) in zip(modes, columns, strict=True):
        f, zeta, conj = _mode_values(p, k, dset)
        if not (f > 0 and 0 <= zeta < 1):
            msg = (
                f"dataset #{k + 1} of {p}: mode {dset.get('mode_n')} of load case {dset.get('load_case')} must have "
                f"a frequency > 0 Hz and a damping ratio in [0, 1); got {f:.6g} Hz and {zeta:.6g}"
            )
            raise DataError(msg)
        shape = np.zeros(len(picks), dtype=complex)
        for s, (node, slot, sign) in enumerate(picks):
            hit = np.flatnonzero(nodes == node)
            if hit.size == 0 or slot >= r.shape[0]:
                msg = f"dataset #{k + 1} of {p} has no value for sensor {sensors[s]!r} (node {node})"
                raise DataError(msg)
            shape[s] = sign * r[slot, hit[0]]
        if conj:
            shape = shape.conj()
        entry = sets.setdefault(
            int(dset.get("load_case", 0)),
            {"position": _position(p, k, dset) if cappe else {}, "frequency": [], "damping": [], "shape_re": [],
             "shape_im": []},
        )
        entry["frequency"].append(f)
        entry["damping"].append(zeta)
        entry["shape_re"].append(shape.real.tolist())
        entry["shape_im"].append(shape.imag.tolist())
    document = {"format": MODAL_FORMAT, "sensors": sensors, "sets": list(sets.values())}
    return modal_data_from_mapping(document, str(p))


def _normal_mode_2414(p: Path, k: int, dset: Mapping[str, Any]) -> dict[str, Any]:
    """A UFF 2414 normal mode (analysis type 2, data at nodes: an FE solver's modes) in the fields of a UFF 55 one.

    UFF 2414 record 10 field 6 is the mode number, record 12 holds time, frequency (Hz), eigenvalue, modal mass,
    viscous and hysteretic damping ratio; records 14/15 give each node and its values (x, y, z[, rx, ry, rz]).
    """
    try:
        freq = float(dset["record12_field2"])
        zeta = float(dset.get("record12_field5", 0.0) or 0.0)
        nodes = np.asarray(dset["node_nums"], dtype=np.int64)
        values = [np.asarray(v, dtype=float) for v in dset["data_at_node"]]
    except (KeyError, TypeError, ValueError) as exc:
        msg = f"dataset #{k + 1} of {p} (UFF 2414 normal mode) lacks its frequency or its values at nodes"
        raise DataError(msg) from exc
    sizes = {v.size for v in values}
    if len(sizes) != 1 or not 1 <= sizes.pop() <= 6 or len(values) != nodes.size:
        msg = f"dataset #{k + 1} of {p} (UFF 2414 normal mode) must give 1 to 6 values for every node alike"
        raise DataError(msg)
    table = np.array(values)  # (n_nodes, n_values)
    mode: dict[str, Any] = {
        "analysis_type": 2, "freq": freq, "modal_damp_vis": zeta, "node_nums": nodes,
        "load_case": 0, "mode_n": dset.get("record10_field6"),  # all modes of the file form one set
    }
    for slot in range(table.shape[1]):
        mode[f"r{slot + 1}"] = table[:, slot]
    return mode


def _columns(p: Path, k: int, dset: Mapping[str, Any]) -> tuple[NDArray[np.int64], NDArray[np.complex128]]:
    nodes = np.asarray(dset.get("node_nums", []), dtype=np.int64)
    slots = [dset[f"r{s}"] for s in range(1, 7) if f"r{s}" in dset]
    if not slots:
        msg = f"dataset #{k + 1} of {p} holds no shape values"
        raise DataError(msg)
    return nodes, np.array(slots, dtype=complex).reshape(len(slots), nodes.size)


def _position(p: Path, k: int, dset: Mapping[str, Any]) -> dict[str, float]:
    line = str(dset.get("id4", ""))
    if line.strip().upper() == "NONE":
        return {}
    meta = _meta(line)
    position = {axis: _float_token(meta, axis) for axis in meta}
    bad = [axis for axis, v in position.items() if v is None]
    if bad or len(meta) != len(line.split()):
        msg = f"dataset #{k + 1} of {p}: ID line 4 must hold the position as 'axis=value' tokens; got {line!r}"
        raise DataError(msg)
    return {axis: float(v) for axis, v in position.items() if v is not None}
