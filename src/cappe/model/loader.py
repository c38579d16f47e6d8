"""Reading model files (YAML, ``format: cappe.model/1``) and built-in models into a Structure."""

from __future__ import annotations

import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from cappe.exceptions import ModelError
from cappe.model.structure import Structure, StructureBuilder

__all__ = ["FORMAT", "load_model", "structure_from_mapping"]

FORMAT = "cappe.model/1"
BUILTIN_PREFIX = "builtin:"
#: Largest model file read (the built-in machine tool's is 30 kB; FE matrices live in files of their own).
MAX_MODEL_BYTES = 16 * 2**20


def _float_spellings(base: Any) -> Any:
    """A safe loader that also reads 1e5, 1.0e5, 1E-3 and .5 as numbers.

    PyYAML follows YAML 1.1, whose floats need a dot and a signed exponent: ``1.0e5`` would be the string
    '1.0e5'. Engineers write numbers that way, so every spelling of YAML 1.2's core schema is a float here.
    """
    loader: Any = type(f"Cappe{base.__name__}", (base,), {})
    loader.add_constructor("tag:yaml.org,2002:int", _bounded_int)
    loader.add_implicit_resolver(
        "tag:yaml.org,2002:float",
        re.compile(r"^[-+]?(?:\.[0-9]+|[0-9][0-9_]*(?:\.[0-9_]*)?)(?:[eE][-+]?[0-9]+)?$"),
        list("-+0123456789."),
    )
    return loader


def _bounded_int(loader: Any, node: Any) -> Any:
    """YAML's integer, refused with its line where it has more digits than any float (Python itself refuses
    to read more than 4300 without a line)."""
    digits = sum(c.isdigit() for c in str(node.value))
    if digits > _MAX_INT_DIGITS:
        problem = f"an integer of {digits} digits is beyond the floating-point range"
        raise yaml.constructor.ConstructorError(None, None, problem, node.start_mark)
    return yaml.constructor.SafeConstructor.construct_yaml_int(loader, node)


_MAX_INT_DIGITS = 400

#: libyaml's safe loader where PyYAML was built with it (0.05 s less of the machine tool's 1.1 s load and compile);
#: the same documents and types. A document it rejects is parsed again by the pure-Python loader for the message.
_SAFE_LOADER: Any = _float_spellings(getattr(yaml, "CSafeLoader", yaml.SafeLoader))
_PURE_LOADER: Any = _float_spellings(yaml.SafeLoader)

_TOP = {
    "format",
    "name",
    "description",
    "source",
    "parameters",
    "axes",
    "bodies",
    "flexible_bodies",
    "elements",
    "inputs",
    "outputs",
    "sensors",
}
_KEYS = {
    "parameters": ({"name", "value"}, {"unit", "kind", "bounds", "unknown", "disturbable", "description"}),
    "axes": ({"name"}, {"positions", "unit", "description"}),
    "bodies": ({"name", "mass"}, {"inertia", "position", "com", "dofs", "spin", "description"}),
    "flexible_bodies": (
        {"name", "nodes"},
        {"mass", "stiffness", "frame", "position", "mass_scale", "stiffness_scale", "damping", "recovery", "reduction",
         "lines", "description"},
    ),
    "elements": ({"name", "bodies"}, {"points", "at", "axes", "stiffness", "damping", "loss", "description"}),
    "inputs": ({"name", "body"}, {"point", "direction", "kind"}),
    "outputs": ({"name"}, {"quantity", "body", "point", "direction", "rotation", "sensor", "element"}),
    "sensors": ({"name", "body"}, {"point"}),
}
# sensors are declared before outputs so that outputs can refer to them
_ORDER = ("parameters", "axes", "bodies", "flexible_bodies", "elements", "sensors", "inputs", "outputs")


def load_model(source: str | Path) -> Structure:
    """Load a model from a YAML file path or a built-in name ``builtin:NAME``.

    Parameters
    ----------
    source : str or Path
        A ``cappe.model/1`` YAML file or ``"builtin:NAME"`` (:func:`cappe.library.builtin_names`).

    Returns
    -------
    Structure

    Raises
    ------
    ModelError
        If the file cannot be read or parsed, or breaks a rule; the message names the file, the entry
        and the rule.

    Examples
    --------
    >>> load_model("builtin:two-mass-rig").n_dof
    2
    """
    text_source = str(source)
    if text_source.startswith(BUILTIN_PREFIX):
        from cappe.library import builtin_path

        path = builtin_path(text_source[len(BUILTIN_PREFIX) :])
        label = text_source
    else:
        path = Path(source)
        label = str(path)
    try:
        with path.open("rb") as handle:
            raw = handle.read(MAX_MODEL_BYTES + 1)
    except OSError as exc:
        msg = f"cannot read model file {label}: {exc.strerror or exc}"
        raise ModelError(msg) from exc
    if len(raw) > MAX_MODEL_BYTES:
        msg = f"model file {label} is larger than {MAX_MODEL_BYTES // 2**20} MiB; a model description is not that long"
        raise ModelError(msg)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        msg = f"model file {label} is not UTF-8 text: byte 0x{raw[exc.start]:02x} at line {line} cannot be decoded"
        raise ModelError(msg) from exc
    return structure_from_yaml(text, label, base=path.parent)


def structure_from_yaml(text: str, label: str = "<string>", *, base: Path | None = None) -> Structure:
    """Parse YAML model text; ``label`` names the file in error messages, matrix files are read relative to
    ``base``."""
    try:
        data = yaml.load(text, Loader=_SAFE_LOADER)
    except yaml.YAMLError:
        data = _parse_for_message(text, label)
    except RecursionError as exc:
        msg = f"model file {label} nests its YAML too deeply to be a model description"
        raise ModelError(msg) from exc
    if not isinstance(data, Mapping):
        msg = f"model file {label} must contain a mapping at the top level; got {type(data).__name__}"
        raise ModelError(msg)
    return structure_from_mapping(data, label, base=base)


def _parse_for_message(text: str, label: str) -> Any:
    """Parse with PyYAML's pure-Python loader, whose errors name the offending character or alias (libyaml's
    only say what kind of thing went wrong); raise its error, with line and column, as a ModelError."""
    try:
        return yaml.load(text, Loader=_PURE_LOADER)
    except RecursionError as exc:
        msg = f"model file {label} nests its YAML too deeply to be a model description"
        raise ModelError(msg) from exc
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = f"line {mark.line + 1}, column {mark.column + 1}" if mark is not None else "unknown line"
        problem = getattr(exc, "problem", None) or str(exc)
        msg = f"malformed YAML in {label} at {line}: {problem}"
        raise ModelError(msg) from exc


def structure_from_mapping(data: Mapping[str, Any], label: str = "<mapping>", *, base: Path | None = None,
                           ) -> Structure:
    """Build a Structure from the parsed content of a model file.

    Parameters
    ----------
    data : mapping
        The parsed ``cappe.model/1`` document.
    label : str
        Where it came from (a file name), for messages.
    base : Path, optional
        Folder that the matrix files of flexible bodies are read relative to (the model file's; default: the
        working directory).

    Returns
    -------
    Structure

    Raises
    ------
    ModelError
        The document breaks a rule of the format; the message names ``label`` and the entry.
    """
    fmt = data.get("format", FORMAT)
    if fmt != FORMAT:
        msg = f"{label}: unsupported model format {fmt!r}; expected {FORMAT!r}"
        raise ModelError(msg)
    unknown = sorted(set(data) - _TOP)
    if unknown:
        msg = f"{label}: unknown top-level key(s) {', '.join(map(str, unknown))}; allowed: {', '.join(sorted(_TOP))}"
        raise ModelError(msg)
    name = data.get("name")
    if not isinstance(name, str) or not name:
        msg = f"{label}: 'name' must be a non-empty string; got {name!r}"
        raise ModelError(msg)
    builder = StructureBuilder(name, description=str(data.get("description", "") or ""), source=label, base=base)
    for group in _ORDER:
        entries = data.get(group, []) or []
        if not isinstance(entries, list):
            msg = f"{label}: '{group}' must be a list; got {type(entries).__name__}"
            raise ModelError(msg)
        required, optional = _KEYS[group]
        for i, entry in enumerate(entries):
            where = f"{label}, {group}[{i}]"
            if not isinstance(entry, Mapping):
                msg = f"{where}: entry must be a mapping; got {entry!r}"
                raise ModelError(msg)
            missing = sorted(required - set(entry))
            if missing:
                msg = f"{where}: missing required key(s) {', '.join(missing)}"
                raise ModelError(msg)
            extra = sorted(set(entry) - required - optional)
            if extra:
                msg = (
                    f"{where}: unknown key(s) {', '.join(map(str, extra))}; "
                    f"allowed: {', '.join(sorted(required | optional))}"
                )
                raise ModelError(msg)
            fields = dict(entry)
            item_name = fields.pop("name")
            method = getattr(builder, _METHOD[group])
            if group == "parameters":
                method(item_name, fields.pop("value"), where=where, **fields)
            else:
                method(item_name, where=where, **fields)
    return builder.build()


_METHOD = {
    "parameters": "parameter",
    "axes": "axis",
    "bodies": "body",
    "flexible_bodies": "flexible_body",
    "elements": "element",
    "inputs": "input",
    "outputs": "output",
    "sensors": "sensor",
}
