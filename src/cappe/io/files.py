"""Reading parameter files and writing results atomically (temp file + rename)."""

from __future__ import annotations

import json
import math
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from cappe.exceptions import DataError

__all__ = ["atomic_path", "read_parameters", "write_json", "write_text"]


def read_parameters(path: str | Path) -> dict[str, float]:
    """Read a parameter file ``{"name": value, ...}`` (SI). Names are checked later against the model."""
    p = Path(path)
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        msg = f"cannot read parameter file {p}: {exc.strerror or exc}"
        raise DataError(msg) from exc
    except json.JSONDecodeError as exc:
        msg = f"parameter file {p} is not valid JSON: {exc.msg} at line {exc.lineno}, column {exc.colno}"
        raise DataError(msg) from exc
    if not isinstance(data, dict):
        msg = f'parameter file {p} must hold a JSON object {{"name": value}}; got {type(data).__name__}'
        raise DataError(msg)
    out: dict[str, float] = {}
    for name, value in data.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            msg = f"parameter {name!r} in {p} must be a finite number; got {value!r}"
            raise DataError(msg)
        out[str(name)] = float(value)
    return out


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
    """Write text atomically (see :func:`atomic_path`)."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_json(path: str | Path, data: Any) -> Path:
    """Write JSON atomically (indent 2)."""
    return write_text(path, json.dumps(data, indent=2) + "\n")
