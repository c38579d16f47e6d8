"""Reading parameter files and writing results atomically (temp file + rename)."""

from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any

from cappe.exceptions import DataError

__all__ = ["read_parameters", "write_json", "write_text"]


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


def write_text(path: str | Path, text: str) -> Path:
    """Write text atomically: a reader sees the old file or the new one, never half of it."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", dir=p.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; a written result gets the usual permissions
        os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return p


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_json(path: str | Path, data: Any) -> Path:
    """Write JSON atomically (indent 2)."""
    return write_text(path, json.dumps(data, indent=2) + "\n")
