"""How many bootstrap replicates the standard deviations of ``extract_modes`` need (issue 20): coverage of the
95 % intervals ``estimate +- 1.96 std`` against exact poles, and the CPU time, for several replicate counts.

Two structures written here from the physics (numpy; the truth is the eigenvalues of the state matrix, cappe's
estimators play no part in it), 2 % complex noise on every line (``1 + 0.02 (a + ib) / sqrt(2)``):

* ``roving``: the 3-DOF chain of ``tests/identify/test_roving_hammer.py``, one accelerometer, the hammer at three
  points (read by reciprocity), 0.25 Hz lines to 200 Hz, band 5-195 Hz, orders up to 20;
* ``poly``: a 6-DOF chain with non-proportional viscous damping, two references, six accelerometers (the
  poly-reference path), 0.25 Hz lines to 250 Hz, band 10-240 Hz, orders up to 20.

Per trial one noisy data set is extracted once per replicate count (each with its own bootstrap seed). For a
replicate count n the standard deviation is a root-mean-square over n replicates: n degrees of freedom, so
``+- 1.96 std`` covers at the rate of a Student t with n degrees of freedom, not 95 % (10 replicates: 93.1 %;
30: 94.0 %). The table gives the coverage of ``+- 1.96 std`` as written by the extraction.

``python -m benchmarks.bench_mode_std [TRIALS] [--counts=5,10,30]`` (default 40 trials;
``results/mode_std.json``). Run it with one BLAS thread (OPENBLAS_NUM_THREADS=1): it reports CPU seconds.
"""

from __future__ import annotations

import json
import sys
import time
from typing import Any

import numpy as np

from benchmarks._common import write_results
from cappe.identify import extract_modes
from cappe.systems.frf import FRFData

NOISE = 0.02


def _modes(M: np.ndarray, C: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact natural frequencies (Hz) and damping ratios, ascending, from the state matrix."""
    n = M.shape[0]
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]])
    lam = np.linalg.eigvals(A)
    lam = lam[lam.imag > 0]
    lam = lam[np.argsort(np.abs(lam))]
    return np.abs(lam) / (2 * np.pi), -lam.real / np.abs(lam)


def _accelerance(M: np.ndarray, C: np.ndarray, K: np.ndarray, freq: np.ndarray, outputs: list[int],
                 inputs: list[int]) -> np.ndarray:
    s = 2j * np.pi * freq
    n = M.shape[0]
    X = np.linalg.solve(K + s[:, None, None] * C + s[:, None, None] ** 2 * M, np.eye(n))  # (f, n, n)
    return np.transpose(s[:, None, None] ** 2 * X[:, outputs][:, :, inputs], (1, 2, 0))  # (out, in, f)


def roving_case() -> dict[str, Any]:
    M = np.diag([2.0, 1.0, 1.5])
    K = 1e5 * np.array([[3.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 1.5]])
    C = 3.0 * M + 4e-5 * K
    freq = np.arange(0.0, 200.0 + 1e-9, 0.25)
    H = _accelerance(M, C, K, freq, [0], [0, 1, 2])
    f, z = _modes(M, C, K)
    return {"freq": freq, "H": H, "inputs": ("p1", "p2", "p3"), "outputs": ("p1",), "band": (5.0, 195.0),
            "max_order": 20, "f": f, "z": z}


def poly_case() -> dict[str, Any]:
    n = 6
    M = np.diag([1.0, 1.4, 0.8, 1.2, 0.9, 1.1])
    k = 2e5 * np.array([1.0, 1.3, 0.7, 1.1, 0.9, 1.2, 0.6])  # springs to ground at both ends and between masses
    K = np.zeros((n, n))
    for i in range(n + 1):
        a, b = i - 1, i
        if a >= 0:
            K[a, a] += k[i]
        if b < n:
            K[b, b] += k[i]
        if a >= 0 and b < n:
            K[a, b] -= k[i]
            K[b, a] -= k[i]
    c = np.array([8.0, 2.0, 12.0, 3.0, 6.0, 1.0, 10.0])  # dampers beside the springs: not proportional
    C = np.zeros((n, n))
    for i in range(n + 1):
        a, b = i - 1, i
        if a >= 0:
            C[a, a] += c[i]
        if b < n:
            C[b, b] += c[i]
        if a >= 0 and b < n:
            C[a, b] -= c[i]
            C[b, a] -= c[i]
    freq = np.arange(0.0, 250.0 + 1e-9, 0.25)
    H = _accelerance(M, C, K, freq, list(range(n)), [0, 3])
    f, z = _modes(M, C, K)
    return {"freq": freq, "H": H, "inputs": ("r1", "r4"), "outputs": tuple(f"a{i + 1}" for i in range(n)),
            "band": (10.0, 240.0), "max_order": 20, "f": f, "z": z}


def run_case(case: dict[str, Any], trials: int, counts: list[int]) -> dict[str, Any]:
    z_f: dict[int, list[np.ndarray]] = {n: [] for n in counts}
    z_d: dict[int, list[np.ndarray]] = {n: [] for n in counts}
    cpu: dict[int, float] = {n: 0.0 for n in [0, *counts]}
    missed = 0
    for trial in range(trials):
        rng = np.random.default_rng(500 + trial)
        H = case["H"] * (1 + NOISE * (rng.standard_normal(case["H"].shape)
                                      + 1j * rng.standard_normal(case["H"].shape)) / np.sqrt(2))
        frf = FRFData(case["freq"], H, case["inputs"], case["outputs"], ("acceleration",) * len(case["outputs"]))
        for n in [0, *counts]:
            t = time.process_time()
            res = extract_modes(frf, band=case["band"], max_order=case["max_order"], n_bootstrap=n, rng=trial)
            cpu[n] += time.process_time() - t
            if n == 0:
                continue
            if res.frequency.size != case["f"].size:
                missed += 1
                continue
            z_f[n].append((res.frequency - case["f"]) / res.frequency_std)
            z_d[n].append((res.damping - case["z"]) / res.damping_std)
    rows = {}
    for n in counts:
        af, ad = np.abs(np.array(z_f[n])), np.abs(np.array(z_d[n]))
        rows[n] = {"frequency_covered": float(np.mean(af < 1.96)), "damping_covered": float(np.mean(ad < 1.96)),
                   "intervals": int(af.size), "cpu_s_per_extraction": cpu[n] / trials}
    return {"modes": int(case["f"].size), "trials": trials, "extractions_missing_a_mode": missed,
            "cpu_s_per_extraction_without_bootstrap": cpu[0] / trials, "by_replicates": rows}


def main(argv: list[str]) -> dict[str, Any]:
    numbers = [a for a in argv if not a.startswith("-")]
    trials = int(numbers[0]) if numbers else 40
    counts_arg = next((a.split("=", 1)[1] for a in argv if a.startswith("--counts=")), "5,10,30")
    counts = [int(v) for v in counts_arg.split(",")]
    out = {}
    for name, make in (("roving", roving_case), ("poly", poly_case)):
        out[name] = run_case(make(), trials, counts)
        print(name, json.dumps(out[name]), flush=True)
    write_results("mode_std", [{"case": k, **v} for k, v in out.items()])
    return out


if __name__ == "__main__":
    main(sys.argv[1:])
