"""Reading data files safely (bounded, UTF-8, JSON with numbers checked) and writing results atomically (temp file +
rename)."""

from __future__ import annotations

import json
import math
import numbers
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from cappe.exceptions import DataError

__all__ = [
    "MAX_JSON_BYTES",
    "MAX_PARAMETER_BYTES",
    "atomic_path",
    "finite_number",
    "parse_json",
    "read_json",
    "read_parameters",
    "read_text_file",
    "shown",
    "write_json",
    "write_text",
]

#: The largest JSON data file read (modal data, estimates, manifests): far above any real one (a modal file of 1000
#: sensors, 50 modes and 10 positions is about 20 MB); a bound, so that a wrong file fails with a message instead
#: of filling the memory.
MAX_JSON_BYTES = 256 * 2**20
#: The largest parameter file read: tens of thousands of ``"name": value`` pairs.
MAX_PARAMETER_BYTES = 2**20
# ints with more digits than this are not read as ints: Python's int(str) refuses more than 4300 digits
# (sys.get_int_max_str_digits()), and any int beyond 309 digits is outside the float range anyway
_MAX_INT_DIGITS = 4300


def read_parameters(path: str | Path) -> dict[str, float]:
    """Read a parameter file ``{"name": value, ...}`` (SI). Names are checked later against the model.

    Parameters
    ----------
    path : str or Path
        The file to read.

    Returns
    -------
    dict
        ``{name: float}`` in SI units.

    Raises
    ------
    DataError
        When the file cannot be read, is not JSON (see :func:`read_json`), is not an object or holds a value that is
        not a finite number; the message names the file and the parameter.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = pathlib.Path(tmp) / "p.json"
    ...     _ = path.write_text('{"k12": 2e5, "m1": 1}')
    ...     read_parameters(path)
    {'k12': 200000.0, 'm1': 1.0}
    """
    p = Path(path)
    data = read_json(p, "parameter file", max_bytes=MAX_PARAMETER_BYTES)
    if not isinstance(data, dict):
        msg = f'parameter file {p} must hold a JSON object {{"name": value}}; got {type(data).__name__}'
        raise DataError(msg)
    out: dict[str, float] = {}
    for name, value in data.items():
        number = finite_number(value)
        if number is None:
            msg = f"parameter {shown(name)} in {p} must be a finite number; got {shown(value)}"
            raise DataError(msg)
        out[str(name)] = number
    return out


def read_text_file(path: str | Path, what: str, kind: str, *, max_bytes: int) -> str:
    """The text of a UTF-8 file (a leading byte order mark dropped), read up to ``max_bytes``.

    ``what`` names the file in messages ("parameter file"), ``kind`` the expected content ("JSON", "CSV"). Reading
    stops after ``max_bytes`` (an endless device or a wrong multi-gigabyte file is not read into memory).

    Raises
    ------
    DataError
        When the file is missing or unreadable, larger than ``max_bytes`` or not UTF-8.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = pathlib.Path(tmp) / "run.csv"
    ...     _ = path.write_bytes(b"\\xef\\xbb\\xbftime,F\\n")
    ...     read_text_file(path, "CSV measurement file", "CSV", max_bytes=100)
    'time,F\\n'
    """
    p = Path(path)
    try:
        with open(p, "rb") as fh:
            raw = fh.read(max_bytes + 1)
    except FileNotFoundError as exc:
        msg = f"cannot read {what} {p}: no such file"
        raise DataError(msg) from exc
    except OSError as exc:
        msg = f"cannot read {what} {p}: {exc.strerror or exc}"
        raise DataError(msg) from exc
    if len(raw) > max_bytes:
        msg = f"{what} {p} is larger than {_size(max_bytes)}, the most cappe reads as {kind}"
        raise DataError(msg)
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        start = exc.start + 3 if raw.startswith(b"\xef\xbb\xbf") else exc.start  # the offset within the file
        msg = f"{what} {p} is not a UTF-8 text file ({kind} expected): {exc.reason} at byte {start}"
        raise DataError(msg) from exc


def read_json(path: str | Path, what: str, *, max_bytes: int = MAX_JSON_BYTES) -> Any:
    """Read a JSON data file: :func:`read_text_file`, then :func:`parse_json` with ``"{what} {path}"`` as label.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = pathlib.Path(tmp) / "d.json"
    ...     _ = path.write_text('{"a": [1, 1e400]}')
    ...     read_json(path, "data file")
    {'a': [1, 1e400]}
    """
    p = Path(path)
    return parse_json(read_text_file(p, what, "JSON", max_bytes=max_bytes), f"{what} {p}")


def parse_json(text: str, label: str) -> Any:
    """Parse JSON text from a file; ``label`` names it in messages ("parameter file p.json").

    Numbers outside the float range (``1e400``, an integer of 400 or 5000 digits) are read as infinite floats
    that print as written, so that the checks for finite numbers reject them by their text; ``NaN`` and
    ``Infinity`` are read as Python reads them. A repeated key in one object is an error (JSON would keep the last).

    Raises
    ------
    DataError
        When the text is empty, not JSON, nested too deeply for the parser, or repeats a key.

    Examples
    --------
    >>> data = parse_json('{"k": 1e400, "n": 2}', "parameter file p.json")
    >>> data, data["k"] == float("inf")
    ({'k': 1e400, 'n': 2}, True)
    """
    if not text.strip():
        msg = f"{label} is empty; expected JSON"
        raise DataError(msg)
    try:
        return json.loads(text, parse_int=_parse_int, parse_float=_parse_float,
                          object_pairs_hook=lambda pairs: _unique_keys(pairs, label))
    except json.JSONDecodeError as exc:
        # a one-line text gives its column alone, unless the error sits past a trailing line break (a file cut
        # short after its first line ends there: "column 1" alone pointed at the file's first character)
        one_line = "\n" not in text.rstrip() and exc.lineno == 1
        where = f"column {exc.colno}" if one_line else f"line {exc.lineno}, column {exc.colno}"
        msg = f"{label} is not valid JSON: {exc.msg} at {where}"
        raise DataError(msg) from exc
    except RecursionError as exc:  # the C parser counts nesting against the recursion limit and unwinds cleanly
        msg = f"{label} nests arrays or objects too deeply to be read"
        raise DataError(msg) from exc


def finite_number(value: object) -> float | None:
    """``value`` as a float when it is a finite real number (int or float, numpy's too, not bool); else None.

    Examples
    --------
    >>> finite_number(3), finite_number(float("nan")), finite_number("3"), finite_number(True), finite_number(10**400)
    (3.0, None, None, None, None)
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return None
    try:
        number = float(value)
    except OverflowError:  # an int beyond the float range
        return None
    return number if math.isfinite(number) else None


def shown(value: object, limit: int = 60) -> str:
    """``repr(value)`` for a message, cut to about ``limit`` characters (a message stays one readable line).

    Examples
    --------
    >>> shown("x" * 100, limit=10)
    "'xxxxxx..."
    """
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


class _OutOfRange(float):
    """A JSON number beyond the float range: ``+-inf`` that prints as written (shortened), for messages."""

    text: str

    def __new__(cls, text: str) -> _OutOfRange:
        self = super().__new__(cls, -math.inf if text.startswith("-") else math.inf)
        self.text = text
        return self

    def __repr__(self) -> str:
        if len(self.text) <= 20:
            return self.text
        sign = "-" if self.text.startswith("-") else ""
        body = self.text.lstrip("-")
        unit = "digits" if body.isdigit() else "characters"
        return f"{sign}{body[:6]}...{body[-3:]} ({len(body)} {unit})"

    __str__ = __repr__


def _parse_int(text: str) -> int | float:
    if len(text) > _MAX_INT_DIGITS:
        return _OutOfRange(text)
    value = int(text)
    try:
        float(value)
    except OverflowError:
        return _OutOfRange(text)
    return value


def _parse_float(text: str) -> float:
    value = float(text)
    return _OutOfRange(text) if math.isinf(value) else value


def _unique_keys(pairs: list[tuple[str, Any]], label: str) -> dict[str, Any]:
    out = dict(pairs)
    if len(out) == len(pairs):
        return out
    seen: set[str] = set()
    for key, _ in pairs:
        if key in seen:
            msg = f"{label} gives the key {shown(key)} twice in one object"
            raise DataError(msg)
        seen.add(key)
    return out  # pragma: no cover - a shorter dict means a repeated key


def _size(n_bytes: int) -> str:
    return f"{n_bytes // 2**20} MiB" if n_bytes >= 2**20 and n_bytes % 2**20 == 0 else f"{n_bytes} bytes"


@contextmanager
def atomic_path(path: str | Path, suffix: str = ".tmp") -> Iterator[Path]:
    """Yield an empty temporary file next to ``path``; rename it to ``path`` when the block succeeds.

    Readers see the old file or the new one, never half of it; a failed write removes the temporary file and leaves
    an existing ``path`` untouched. ``suffix`` lets writers that pick a format by extension (Pillow) use it. The
    file gets the usual (umask) permissions, not mkstemp's 0600.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=suffix, dir=target.parent)
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_text(path: str | Path, text: str) -> Path:
    """Write text atomically (see :func:`atomic_path`).

    Parameters
    ----------
    path : str or Path
        The file to write (replaced only once the text is complete).
    text : str
        The content, written as UTF-8.

    Returns
    -------
    Path
        ``path``.
    """
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_json(path: str | Path, data: Any) -> Path:
    """Write JSON atomically (indent 2).

    Parameters
    ----------
    path : str or Path
        The file to write.
    data : object
        A JSON-serializable value (dicts, lists, str, numbers, bool, None).

    Returns
    -------
    Path
        ``path``.
    """
    return write_text(path, json.dumps(data, indent=2) + "\n")
