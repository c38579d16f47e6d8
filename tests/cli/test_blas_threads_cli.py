"""Every command runs BLAS on one thread by default, and ``CAPPE_BLAS_THREADS`` changes it (cappe.parallel).

A command's work is many small linear-algebra calls, which OpenBLAS's threads slow down: ``cappe monitor ingest`` of
16 measurements took 22 s on two threads and 7 s on one. The thread counts are read with threadpoolctl inside the
command (where it prints its result), with the process's BLAS set to two threads around it, so that a command that
does not pin would be seen at two on any machine.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest
from threadpoolctl import threadpool_info, threadpool_limits

import cappe
from cappe.cli import _monitor_chain, main
from cappe.cli import model as model_cli
from cappe.cli import sensitivity as sensitivity_cli
from cappe.cli import simulate as simulate_cli


def _blas_threads() -> list[int]:
    return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]


def _probe(monkeypatch: pytest.MonkeyPatch, module: ModuleType) -> list[list[int]]:
    """Record the BLAS thread counts each time the command ``module`` prints its result."""
    seen: list[list[int]] = []
    emit = module.emit

    def probe(*args: Any, **kwargs: Any) -> None:
        seen.append(_blas_threads())
        emit(*args, **kwargs)

    monkeypatch.setattr(module, "emit", probe)
    return seen


@pytest.fixture(scope="module")
def measurements(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A monitoring store of the spindle and a manifest of two healthy measurements (not yet ingested)."""
    folder = tmp_path_factory.mktemp("threads")
    assert main(["monitor", "init", str(folder / "store.db"), "--machine", "spindle-01", "--model",
                 "builtin:spindle-bearing", "--outputs", "sx,hax", "--band", "150:1000"]) == 0
    assert main(["monitor", "simulate", "healthy", "--store", str(folder / "store.db"), "-n", "2", "--seed", "1",
                 "-o", str(folder / "day")]) == 0
    return folder


def _command(name: str, folder: Path, tmp_path: Path) -> tuple[ModuleType, list[str]]:
    if name == "monitor ingest":
        store = tmp_path / "store.db"
        store.write_bytes((folder / "store.db").read_bytes())  # a fresh copy: each run ingests the same two
        return _monitor_chain, ["monitor", "ingest", str(store), "--manifest", str(folder / "day/scenario.json")]
    if name == "model modes":
        return model_cli, ["model", "modes", "builtin:spindle-bearing"]
    if name == "sensitivity":
        return sensitivity_cli, ["sensitivity", "builtin:two-mass-rig", "--local", "--percent", "10"]
    return simulate_cli, ["simulate", "builtin:two-mass-rig", "--excite", "F1=random", "--fs", "1000", "--duration",
                          "0.5", "--outputs", "d1", "--seed", "1", "-o", str(tmp_path / "sim.npz")]


def _two_threads() -> Any:
    limits = threadpool_limits(limits=2, user_api="blas")
    if any(n != 2 for n in _blas_threads()):
        limits.restore_original_limits()
        pytest.skip("the BLAS libraries of this process cannot be set to two threads")
    return limits


@pytest.mark.parametrize("name", ["monitor ingest", "model modes", "sensitivity", "simulate"])
def test_commands_run_blas_on_one_thread_by_default(name, measurements, tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("CAPPE_BLAS_THREADS", raising=False)
    module, argv = _command(name, measurements, tmp_path)
    seen = _probe(monkeypatch, module)
    variable = os.environ.get("OPENBLAS_NUM_THREADS")
    with _two_threads():
        assert main(argv) == 0, capsys.readouterr().err
        after = _blas_threads()
    assert seen, "the command printed nothing"
    assert all(n == 1 for n in seen[0]), seen
    assert set(after) == {2}  # the caller's limits come back, and the variable the command set for late loads
    assert os.environ.get("OPENBLAS_NUM_THREADS") == variable


@pytest.mark.parametrize(("value", "outer", "inside"), [("2", 1, 2), ("auto", 2, 2), (" 1 ", 2, 1)])
def test_cappe_blas_threads_overrides_the_default(value, outer, inside, measurements, tmp_path, monkeypatch):
    monkeypatch.setenv("CAPPE_BLAS_THREADS", value)
    module, argv = _command("model modes", measurements, tmp_path)
    seen = _probe(monkeypatch, module)
    with _two_threads():
        with threadpool_limits(limits=outer, user_api="blas"):
            assert main(argv) == 0
    assert all(n == inside for n in seen[0]), seen


@pytest.mark.parametrize("value", ["0", "-1", "1.5", "two", "²"])
def test_bad_cappe_blas_threads_is_a_usage_error(value, monkeypatch, capsys):
    monkeypatch.setenv("CAPPE_BLAS_THREADS", value)
    assert main(["model", "show", "builtin:two-mass-rig"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("cappe: usage error: CAPPE_BLAS_THREADS must be a positive number of threads or 'auto'; "
                          f"got {value!r}")
    assert err.count("\n") == 1


_LATE_LOAD = textwrap.dedent("""
    import json, sys
    from threadpoolctl import threadpool_info
    from cappe.cli import main, model

    def blas():
        return {lib["filepath"]: lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"}

    before, seen, emit = blas(), [], model.emit
    model.emit = lambda *a, **k: (seen.append(blas()), emit(*a, **k))
    loaded = "scipy.linalg" in sys.modules
    code = main(["model", "modes", "builtin:spindle-bearing", "--json"])
    print(json.dumps({"before": before, "seen": seen[0], "loaded": loaded, "code": code}), file=sys.stderr)
""")


def test_blas_loaded_during_the_command_is_pinned_too():
    # a fresh interpreter as the `cappe` script is: scipy (and its own OpenBLAS) loads inside the command, after the
    # limit was set; the user's OPENBLAS_NUM_THREADS=2 is what it would start with otherwise
    env = {k: v for k, v in os.environ.items() if k not in ("CAPPE_BLAS_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS")}
    env["OPENBLAS_NUM_THREADS"] = "2"
    source = str(Path(cappe.__file__).parents[1])  # the cappe under test, not another install
    env["PYTHONPATH"] = os.pathsep.join(p for p in (source, env.get("PYTHONPATH")) if p)
    result = subprocess.run([sys.executable, "-c", _LATE_LOAD], capture_output=True, text=True, env=env, check=False,
                            timeout=120)
    doc = json.loads(result.stderr.strip().splitlines()[-1])
    assert doc["code"] == 0
    if any(n != 2 for n in doc["before"].values()):
        pytest.skip(f"OpenBLAS does not start two threads on this machine: {doc['before']}")
    assert not doc["loaded"], "scipy.linalg was imported before the command: this test no longer sees a late load"
    assert len(doc["seen"]) > len(doc["before"])  # scipy's OpenBLAS loaded during the command
    assert all(n == 1 for n in doc["seen"].values()), doc["seen"]
