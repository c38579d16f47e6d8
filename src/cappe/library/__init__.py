"""Built-in models, addressed as ``builtin:NAME``; each YAML file documents where its numbers come from."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from cappe.exceptions import ModelError

__all__ = ["builtin_names", "builtin_path"]


def _folder() -> Path:
    return Path(str(resources.files("cappe.library").joinpath("models")))


def builtin_names() -> list[str]:
    """Names of the built-in models."""
    return sorted(p.stem for p in _folder().glob("*.yaml"))


def builtin_path(name: str) -> Path:
    """Path of the YAML file of built-in model ``name``.

    Parameters
    ----------
    name : str
        A built-in model name (``"two-mass-rig"``, ...; :func:`builtin_names` lists them).

    Returns
    -------
    Path

    Raises
    ------
    ModelError
        No built-in model has that name.
    """
    path = _folder() / f"{name}.yaml"
    if not path.is_file():
        msg = f"unknown built-in model {name!r}; available: {', '.join(builtin_names())}"
        raise ModelError(msg)
    return path
