"""Shared CLI plumbing: model options, JSON output, errors and exit codes."""

from __future__ import annotations

import argparse
import functools
import json
import math
import sys
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, ParamSpec

from cappe.exceptions import DataError, ModelError

if TYPE_CHECKING:
    from cappe.model import NumericModel, Structure

# the library is imported where a command needs it (as in every command module): `cappe --help` and the commands
# that need no model do not pay for sympy and scipy.signal (about 1 s of imports)

EXIT_OK, EXIT_FAILURE, EXIT_USAGE = 0, 1, 2
_P = ParamSpec("_P")


class UsageError(Exception):
    """A command-line argument is malformed (exit code 2)."""


#: What ``-o`` writes, by command: the JSON result (most), or a data file chosen by its extension.
JSON_OUT: dict[str, str] = {".json": "JSON"}
FRF_OUT: dict[str, str] = {".uff": "UFF 58", ".unv": "UFF 58", ".csv": "CSV, re/im pairs", ".npz": "npz"}
TIME_OUT: dict[str, str] = {".uff": "UFF 58", ".unv": "UFF 58", ".csv": "CSV", ".npz": "npz"}


def out_file(kinds: Mapping[str, str]) -> Callable[[str], str]:
    """An argparse ``type`` for ``-o``: the file's extension must be one of ``kinds`` (extension -> what is written).

    A file that does not end in what the command writes is refused at once (exit 2), before any work: ``-o
    frf.csv`` on a command that writes JSON would otherwise leave JSON in a file named .csv. A name without an
    extension is taken where JSON is written.
    """

    def check(value: str) -> str:
        suffix = Path(value).suffix.lower()
        if suffix in kinds or (not suffix and ".json" in kinds):
            return value
        shown = ", ".join(f"{ext} ({what})" for ext, what in kinds.items())
        msg = f"{value!r}: this command writes {shown}; give FILE one of these extensions"
        raise argparse.ArgumentTypeError(msg)

    check.__name__ = "FILE"
    return check


def add_output_options(parser: argparse.ArgumentParser, kinds: Mapping[str, str] = JSON_OUT) -> None:
    parser.add_argument("--json", action="store_true", help="print machine-readable JSON")
    what = " or ".join(dict.fromkeys(kinds.values()))
    ext = ", ".join(kinds)
    parser.add_argument("-o", "--out", metavar="FILE", type=out_file(kinds),
                        help=f"write the result to FILE ({what}, by the extension: {ext})" if len(kinds) > 1
                        else f"write the result to FILE ({what})")


class _Deprecated(argparse.Action):
    """An old spelling of an option: stores into the new option's ``dest`` and says which spelling to use."""

    def __init__(self, option_strings: list[str], dest: str, *, instead: str, join: bool = False,
                 **kwargs: Any) -> None:
        self.instead, self.join = instead, join
        super().__init__(option_strings, dest, **kwargs)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        if self.join and isinstance(values, list):
            values = ",".join(values)
        print(f"cappe: warning: {option_string} is deprecated; use {self.instead}", file=sys.stderr)
        setattr(namespace, self.dest, values)


def add_deprecated(parser: argparse.ArgumentParser | Any, option: str, *, dest: str, instead: str,
                   join: bool = False, **kwargs: Any) -> None:
    """Accept ``option``, an old spelling, as ``instead`` (which stores into ``dest``), with a deprecation message.

    ``join``: the old spelling took space-separated values (``--input A B``); they are stored as the comma list
    the new spelling takes.
    """
    parser.add_argument(option, dest=dest, action=_Deprecated, instead=instead, join=join,
                        help=f"deprecated: use {instead}", **kwargs)


def channels(value: str | None, option: str) -> list[str]:
    """A required comma-separated channel list (``--inputs A,B``), or a usage error naming ``option``."""
    listed = names(value)
    if not listed:
        msg = f"{option} is required (a comma-separated list of channels, e.g. {option} F1,F2)"
        raise UsageError(msg)
    return listed


def add_model_options(parser: argparse.ArgumentParser, out: Mapping[str, str] = JSON_OUT) -> None:
    parser.add_argument("model", metavar="MODEL", help="model YAML file or builtin:NAME")
    parser.add_argument("--params", metavar="FILE.json", help="parameter values {name: value} (SI)")
    parser.add_argument(
        "--set",
        dest="overrides",
        metavar="NAME=VALUE",
        action="append",
        default=[],
        help="override one parameter (repeatable)",
    )
    parser.add_argument(
        "--position", metavar="AXIS=VALUE", action="append", default=[], help="axis position, e.g. z=0.135 (repeatable)"
    )
    add_output_options(parser, out)


def text_pairs(
    items: list[str], option: str, form: str = "NAME=VALUE", *, allow_empty: bool = False
) -> dict[str, str]:
    """Repeatable ``KEY=VALUE`` options as ``{key: value}`` (stripped); ``form`` shapes the usage message."""
    out: dict[str, str] = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name.strip() or not (allow_empty or value.strip()):
            msg = f"{option} must look like {form}; got {item!r}"
            raise UsageError(msg)
        out[name.strip()] = value.strip()
    return out


def number_pairs(items: list[str], what: str) -> dict[str, float]:
    """Repeatable ``NAME=NUMBER`` options as ``{name: finite float}``."""
    out: dict[str, float] = {}
    for name, value in text_pairs(items, what, allow_empty=True).items():
        try:
            number = float(value)
        except ValueError as exc:
            msg = f"{what} {name!r} must be a number; got {value!r}"
            raise UsageError(msg) from exc
        if not math.isfinite(number):
            msg = f"{what} {name!r} must be finite; got {value!r}"
            raise UsageError(msg)
        out[name] = number
    return out


class ModelContext:
    """The model, parameter values and position a command works on."""

    def __init__(self, args: argparse.Namespace) -> None:
        from cappe.model import load_model

        self.structure: Structure = load_model(args.model)
        values: dict[str, float] = {}
        if args.params:
            from cappe.io import read_parameters

            values.update(read_parameters(args.params))
            try:  # the file's values alone first, so that a value breaking a rule names the file it came from
                self.structure.resolve_parameters(values)
            except ModelError as exc:
                msg = f"{args.params}: {exc}"
                raise ModelError(msg) from exc
        values.update(number_pairs(args.overrides, "--set"))
        self.values = self.structure.resolve_parameters(values)
        self.overrides = values
        self.position = self.structure.resolve_position(number_pairs(args.position, "--position"))
        self._numeric: NumericModel | None = None

    @property
    def numeric(self) -> NumericModel:
        from cappe.model import NumericModel

        if self._numeric is None:
            self._numeric = NumericModel(self.structure)
        return self._numeric

    def system(self) -> Any:
        return self.numeric.system(self.values, self.position)


def emit(args: argparse.Namespace, data: Mapping[str, Any], text: str) -> None:
    """Print JSON or text, and write JSON to --out when asked."""
    if getattr(args, "out", None):
        from cappe.io import write_json

        write_json(args.out, data)
    if getattr(args, "json", False):
        print(json.dumps(data, indent=2, default=_default))
    else:
        print(text)


def _default(obj: Any) -> Any:
    if hasattr(obj, "tolist"):
        return obj.tolist()
    return str(obj)


def naming_file(
    attribute: str, errors: tuple[type[Exception], ...] = (DataError,)
) -> Callable[[Callable[_P, int]], Callable[_P, int]]:
    """Make a command's ``errors`` name the data file ``args.<attribute>`` where the message does not already.

    The readers name the file in every error of their own; what the library finds later in the data (a channel
    that is missing, a record too short for the segment length) does not know which file the data came from.
    ModelError belongs in ``errors`` only where the model was loaded before (then it is about this file's data
    against the model, e.g. a reference's sensor the model lacks).
    """

    def decorate(func: Callable[_P, int]) -> Callable[_P, int]:
        @functools.wraps(func)
        def run(*pos: _P.args, **kw: _P.kwargs) -> int:
            try:
                return func(*pos, **kw)
            except errors as exc:
                args = next((a for a in pos if isinstance(a, argparse.Namespace)), None)
                path = getattr(args, attribute, None)
                if not isinstance(path, str) or Path(path).name in str(exc):
                    raise
                msg = f"{path}: {exc}"
                raise type(exc)(msg) from exc

        return run

    return decorate


def run_guarded(func: Any, args: argparse.Namespace) -> int:
    from cappe.parallel import blas_threads, command_blas_threads

    try:
        threads = command_blas_threads()
    except ValueError as exc:
        print(f"cappe: usage error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    try:
        # the whole command on one BLAS thread unless CAPPE_BLAS_THREADS says otherwise (see cappe.parallel)
        with blas_threads(threads):
            return int(func(args) or EXIT_OK)
    except UsageError as exc:
        print(f"cappe: usage error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except (ModelError, DataError) as exc:
        print(f"cappe: error: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    except OSError as exc:
        print(f"cappe: error: {exc}", file=sys.stderr)
        return EXIT_FAILURE


def names(value: str | None) -> list[str] | None:
    if value is None:
        return None
    return [v.strip() for v in value.split(",") if v.strip()]


def band(value: str, option: str = "--band") -> tuple[float, float]:
    """Parse ``LO:HI`` (Hz) into a pair of floats."""
    lo, sep, hi = value.partition(":")
    try:
        pair = (float(lo), float(hi))
    except ValueError:
        pair = (math.nan, math.nan)
    if not sep or not all(math.isfinite(v) for v in pair) or not 0 <= pair[0] < pair[1]:
        msg = f"{option} must look like LO:HI in Hz with 0 <= LO < HI; got {value!r}"
        raise UsageError(msg)
    return pair
