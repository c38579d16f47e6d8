"""Fuzzing the files users hand to cappe: every outcome is a success or one clean, located error, quickly.

Hypothesis mutates valid files — a model, a parameter file, a modal reference, time data and FRF data — at
random places (values replaced by huge, tiny, non-finite, wrongly typed, deeply nested or non-ASCII ones, keys
dropped, bytes cut or made non-UTF-8) and runs the command that reads each through ``cappe.cli.main``. Whatever
the mutation, the command must return 0, 1 or 2; on failure it prints ``cappe: error: ...`` (or ``usage
error``) on one line that names the file; nothing escapes as an exception (a traceback); no run takes seconds.
"""

from __future__ import annotations

import contextlib
import io
import json
import tempfile
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cappe.cli import main

#: Longest a single fuzzed command may run (the valid inputs take well under a second).
SECONDS = 8.0

FUZZ = settings(
    max_examples=40,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
)

MODEL = {
    "format": "cappe.model/1",
    "name": "sled",
    "parameters": [
        {"name": "m", "value": 3.0, "unit": "kg", "kind": "mass"},
        {"name": "k", "value": 2.0e6, "unit": "N/m", "kind": "stiffness", "bounds": [1.0e6, 4.0e6], "unknown": True},
        {"name": "c", "value": 30.0, "unit": "N s/m", "kind": "damping"},
    ],
    "axes": [{"name": "z", "positions": [-0.2, 0.0, 0.3]}],
    "bodies": [{"name": "table", "mass": "m", "inertia": {"xx": 0.02, "yy": 0.02, "zz": 0.03}, "position": [0, 0, "z"]}],
    "elements": [
        {
            "name": "shoe",
            "bodies": ["ground", "table"],
            "at": [0.05, 0, "z"],
            "stiffness": {"x": "k", "y": "k", "z": "k", "rx": 1.0e5, "ry": 1.0e5, "rz": "1.0e5*(1 + z)"},
            "damping": {"x": "c"},
        }
    ],
    "inputs": [{"name": "F", "body": "table", "direction": "x"}],
    "outputs": [{"name": "d", "quantity": "displacement", "body": "table", "direction": "x"}],
}

# -- what a mutation puts in place of a value --------------------------------------------------------------

_strange_text = st.sampled_from(
    [
        "",
        "k*",
        "(k",
        "k)",
        "9**9**9",
        "10**10**7",
        "sqrt(-k)",
        "exp(700)*k",
        "exp(800)",
        "1/z",
        "log(z)",
        "1e-300*k",
        "1e300*k",
        "k" + "+k" * 1500,
        "ｅｖａｌ('1')",
        "__import__('os')",
        "k.__class__",
        "1.0e5",
        "nan",
        "inf",
        "-1",
        "0",
        "\x00",
        "é",
        "x" * 5000,
    ]
)
_leaf = st.one_of(
    st.integers(-(10**6), 10**6),
    st.sampled_from([0, -1, 10**400, -(10**400), 2**64]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([1e-300, 1e300, -1e300, 5e-324, 1.7976931348623157e308]),
    _strange_text,
    st.text(max_size=12),
    st.booleans(),
    st.none(),
)
_value = st.recursive(
    _leaf,
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=6), inner, max_size=3)),
    max_leaves=8,
)


def _paths(tree: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    out = [prefix]
    if len(prefix) > 12:  # inside a deep value an earlier mutation made
        return out
    if isinstance(tree, dict):
        for key, value in tree.items():
            out += _paths(value, (*prefix, key))
    elif isinstance(tree, list):
        for i, value in enumerate(tree):
            out += _paths(value, (*prefix, i))
    return out


def _deep(depth: int) -> Any:
    value: Any = 1.0
    for _ in range(depth):
        value = [value]
    return value


@st.composite
def _mutated_tree(draw: st.DrawFn, tree: Any) -> Any:
    """``tree`` with one to three changes at random places."""
    tree = json.loads(json.dumps(tree))
    for _ in range(draw(st.integers(1, 3))):
        paths = [p for p in _paths(tree) if p]
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent = tree
        for key in path[:-1]:
            parent = parent[key]
        action = draw(st.sampled_from(["replace", "replace", "replace", "delete", "deep"]))
        if action == "delete":
            del parent[path[-1]]
        elif action == "deep":
            parent[path[-1]] = _deep(draw(st.sampled_from([50, 5000])))
        else:
            parent[path[-1]] = draw(_value)
    return tree


class _Blob(bytes):
    """File content whose repr stays short in Hypothesis's reports (the full text would be tens of kB)."""

    def __repr__(self) -> str:
        return f"<{len(self)} bytes: {bytes(self[:60])!r}...>"


@st.composite
def _corrupted_bytes(draw: st.DrawFn, data: bytes) -> bytes:
    """``data`` cut, or with bytes changed (non-UTF-8 among them)."""
    action = draw(st.sampled_from(["cut", "flip", "insert"]))
    at = draw(st.integers(0, max(len(data) - 1, 0)))
    if action == "cut":
        return _Blob(data[:at])
    if action == "flip":
        byte = draw(st.sampled_from([0x00, 0xFF, 0xC3, 0x80, ord("-"), ord("\n")]))
        return _Blob(data[:at] + bytes([byte]) + data[at + 1 :])
    return _Blob(data[:at] + draw(st.binary(min_size=1, max_size=8)) + data[at:])


def _dump(tree: Any, kind: str) -> bytes:
    try:
        if kind == "json":
            return _Blob(json.dumps(tree).encode())
        return _Blob(yaml.safe_dump(tree, allow_unicode=True).encode())
    except (RecursionError, ValueError):  # the dumpers' own limits on what they write
        return _Blob(b"[" * 5000)


def _run(argv: list[str], file_name: str) -> None:
    """Run the CLI; fail the test on anything but a success or one clean, located error within SECONDS."""
    out, err = io.StringIO(), io.StringIO()
    start = time.process_time()  # this process's CPU time: the bound holds on a loaded machine too
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # warnings print on stderr in the real CLI; here only outcomes count
        code = main(argv)
    elapsed = time.process_time() - start
    text = err.getvalue()
    assert "Traceback" not in text, text
    assert code in (0, 1, 2), (code, text)
    assert elapsed < SECONDS, (argv, elapsed)
    if code:
        errors = [line for line in text.splitlines() if line.startswith("cappe: ")]
        assert errors, text
        if code == 1:
            assert file_name in errors[-1], errors[-1]


def _fuzz_file(tmp: Path, name: str, content: bytes, argv: Callable[[str], list[str]]) -> None:
    path = tmp / name
    path.write_bytes(content)
    _run(argv(str(path)), name)


# -- the targets -----------------------------------------------------------------------------------------


@pytest.mark.slow
@FUZZ
@given(
    content=st.one_of(
        _mutated_tree(MODEL).map(lambda t: _dump(t, "yaml")),
        _corrupted_bytes(_dump(MODEL, "yaml")),
    ),
    command=st.sampled_from([["show"], ["modes"], ["tf", "--input", "F", "--output", "d"], ["matrices"]]),
    position=st.sampled_from([[], ["--position", "z=-0.2"], ["--position", "z=0.3"]]),
)
def test_fuzzed_model_files(content, command, position):
    with tempfile.TemporaryDirectory() as tmp:
        _fuzz_file(Path(tmp), "model.yaml", content, lambda p: ["model", command[0], p, *command[1:], *position])


@pytest.mark.slow
@FUZZ
@given(
    content=st.one_of(
        _mutated_tree({"k11": 1.2e6, "m1": 1.3, "c12": 5.0}).map(lambda t: _dump(t, "json")),
        _mutated_tree({"k11": 1.2e6, "m1": 1.3}).map(lambda t: _dump(t, "yaml")),
        _corrupted_bytes(b'{"k11": 1.2e6, "m1": 1.3}'),
    ),
    suffix=st.sampled_from([".json", ".yaml"]),
)
def test_fuzzed_parameter_files(content, suffix):
    with tempfile.TemporaryDirectory() as tmp:
        _fuzz_file(
            Path(tmp), "params" + suffix, content, lambda p: ["model", "modes", "builtin:two-mass-rig", "--params", p]
        )


@pytest.fixture(scope="module")
def modal_reference() -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "ref.json"
        assert main(["model", "modes", "builtin:two-mass-rig", "--modal-out", str(path)]) == 0
        return json.loads(path.read_text())


@pytest.mark.slow
@FUZZ
@given(data=st.data())
def test_fuzzed_modal_references(modal_reference, data):
    content = data.draw(
        st.one_of(
            _mutated_tree(modal_reference).map(lambda t: _dump(t, "json")),
            _corrupted_bytes(_dump(modal_reference, "json")),
        )
    )
    with tempfile.TemporaryDirectory() as tmp:
        _fuzz_file(
            Path(tmp),
            "ref.json",
            content,
            lambda p: ["sensitivity", "builtin:two-mass-rig", "--sobol", "--reference", p, "--n-gsa", "4"],
        )


def _time_data_csv() -> bytes:
    fs, n = 512.0, 1024
    t = np.arange(n) / fs
    rng = np.random.default_rng(0)
    force = rng.standard_normal(n)
    response = np.convolve(force, np.exp(-t[:64] * 40) * np.sin(2 * np.pi * 50 * t[:64]))[:n]
    lines = ["time,F,a"] + [f"{a:.12g},{b:.6g},{c:.6g}" for a, b, c in zip(t, force, response, strict=True)]
    return ("\n".join(lines) + "\n").encode()


TIME_CSV = _time_data_csv()


@pytest.mark.slow
@FUZZ
@given(
    content=st.one_of(
        _corrupted_bytes(TIME_CSV),
        st.sampled_from(["nan", "inf", "1e999", "9" * 5000, "x", "", "1,2", "é"]).map(
            lambda v: _Blob(TIME_CSV.replace(b"\n0.0390625,", f"\n{v},".encode(), 1))
        ),
        st.sampled_from(["time,F,F", "F,a", "time", "time,,a", "time,F,a,extra"]).map(
            lambda header: _Blob(TIME_CSV.replace(b"time,F,a", header.encode(), 1))
        ),
    ),
    nperseg=st.sampled_from(["256", "1", "0", "100000"]),
)
def test_fuzzed_time_data(content, nperseg):
    with tempfile.TemporaryDirectory() as tmp:
        _fuzz_file(
            Path(tmp),
            "data.csv",
            content,
            lambda p: ["frf", p, "--inputs", "F", "--outputs", "a", "--nperseg", nperseg],
        )


@pytest.fixture(scope="module")
def frf_file() -> bytes:
    """FRF data as `cappe frf -o` writes it (the format extract-modes reads), from the time data above."""
    with tempfile.TemporaryDirectory() as tmp:
        data, out = Path(tmp) / "data.csv", Path(tmp) / "frf.csv"
        data.write_bytes(TIME_CSV)
        assert main(["frf", str(data), "--inputs", "F", "--outputs", "a", "--nperseg", "256", "-o", str(out)]) == 0
        return _Blob(out.read_bytes())


@pytest.mark.slow
@FUZZ
@given(data=st.data())
def test_fuzzed_frf_data(frf_file, data):
    content = data.draw(
        st.one_of(
            _corrupted_bytes(frf_file),
            st.sampled_from(["nan", "inf", "1e999", "9" * 5000, "x", ""]).flatmap(
                lambda v: st.integers(1, 20).map(lambda row: _replace_field(frf_file, row, v))
            ),
        )
    )
    with tempfile.TemporaryDirectory() as tmp:
        _fuzz_file(Path(tmp), "frf.csv", content, lambda p: ["extract-modes", p, "--band", "20:150", "--max-order", "8"])


def _replace_field(content: bytes, row: int, value: str) -> bytes:
    lines = content.decode().splitlines()
    if row < len(lines):
        fields = lines[row].split(",")
        fields[-1] = value
        lines[row] = ",".join(fields)
    return ("\n".join(lines) + "\n").encode()
