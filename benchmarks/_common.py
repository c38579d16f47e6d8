"""Timing and result-file helpers shared by the benchmarks."""

from __future__ import annotations

import json
import os
import platform
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"


def best(func: Callable[[], Any], repeat: int = 3, clock: Callable[[], float] = time.perf_counter) -> float:
    """Shortest time of ``repeat`` calls (s) by ``clock``: the least disturbed measurement."""
    times = []
    for _ in range(repeat):
        t0 = clock()
        func()
        times.append(clock() - t0)
    return min(times)


def best_cpu(func: Callable[[], Any], repeat: int = 5) -> float:
    """Shortest CPU time of this process over ``repeat`` calls (s): on a shared, loaded machine wall time measures
    the neighbours (run with one BLAS thread)."""
    return best(func, repeat, time.process_time)


def write_results(name: str, rows: list[dict[str, Any]]) -> Path:
    """Write ``benchmarks/results/NAME.json`` with the machine description and the rows."""
    RESULTS.mkdir(exist_ok=True)
    out = {
        "benchmark": name,
        "machine": platform.processor() or platform.machine(),
        "cores": len(os.sched_getaffinity(0)),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "rows": rows,
    }
    path = RESULTS / f"{name}.json"
    path.write_text(json.dumps(out, indent=2) + "\n")
    return path


def state_matrix_modes(mats: dict[str, Any], n_modes: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``n_modes`` lowest oscillatory poles and their displacement vectors, by scipy's dense ``eig`` of the state
    matrix ``[[0, I], [-M^-1 (K + iH), -M^-1 (C + G)]]`` built from assembled matrices: the benchmarks' independent
    generator of exact complex modes (no cappe modal code)."""
    import scipy.linalg

    n = mats["M"].shape[0]
    minv = np.linalg.inv(mats["M"])
    state = np.zeros((2 * n, 2 * n), dtype=complex)
    state[:n, n:] = np.eye(n)
    state[n:, :n] = -minv @ (mats["K"] + 1j * mats["H"])
    state[n:, n:] = -minv @ (mats["C"] + mats["G"])
    lam, vec = scipy.linalg.eig(state)
    upper = np.flatnonzero(lam.imag > 1e-6 * np.abs(lam).max())
    keep = upper[np.argsort(np.abs(lam[upper]))][:n_modes]
    return lam[keep], vec[:n, keep]
