"""Sobol' analysis of many outputs: cappe's vectorized estimators against SALib's one-output-at-a-time ``analyze``.

Both analyse the very same outputs on the same Sobol' sample with the same bootstrap seed, so the indices must agree
to rounding; the maximum absolute difference over S1, S1_conf, ST, ST_conf (and S2, S2_conf) is recorded. The
outputs come from a cheap synthetic vectorized model (random linear terms, pairwise interactions and a smooth
non-linearity) with D = 27 parameters, N = 1024 and 160 outputs. SALib is timed on every output when that takes
less than ``SALIB_BUDGET_S``; otherwise on the first outputs only, and its time for all outputs is extrapolated
linearly (labelled so in the printed line and the JSON).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from SALib.analyze import sobol as salib_sobol_analyze
from SALib.sample import sobol as salib_sobol_sample

from benchmarks._common import best, write_results
from cappe.sensitivity import sobol_analyze

D, N, N_OUTPUTS = 27, 1024, 160
SALIB_BUDGET_S = 120.0  # time SALib on all outputs only if its estimated total stays below this
SEED_SAMPLE, SEED_BOOTSTRAP = 20240601, 7


def synthetic_outputs(X: np.ndarray, n_outputs: int, rng: np.random.Generator) -> np.ndarray:
    """(n_samples, n_outputs): random linear terms + 10 random pairwise interactions + a sine of a random mix."""
    u = (X - 0.5) * 2
    linear = u @ (rng.standard_normal((D, n_outputs)) * rng.uniform(0, 1, D)[:, np.newaxis] ** 3)
    i, j = rng.integers(D, size=(2, 10))
    interactions = (u[:, i] * u[:, j]) @ rng.standard_normal((10, n_outputs))
    mix = np.sin(u @ rng.standard_normal((D, n_outputs)) * 0.3)
    return np.asarray(linear + interactions + mix)




def _row(second_order: bool, salib_first: int) -> dict[str, Any]:
    names = [f"x{k}" for k in range(D)]
    problem = {"num_vars": D, "names": names, "bounds": [[0.0, 1.0]] * D}
    X = salib_sobol_sample.sample(problem, N, calc_second_order=second_order, seed=SEED_SAMPLE)
    Y = synthetic_outputs(X, N_OUTPUTS, np.random.default_rng(0))

    def ours() -> Any:
        return sobol_analyze(Y, names=names, second_order=second_order, rng=SEED_BOOTSTRAP)

    t_ours = best(ours)
    res = ours()
    keys = ["S1", "S1_conf", "ST", "ST_conf"] + (["S2", "S2_conf"] if second_order else [])

    def salib(o: int) -> Any:
        return salib_sobol_analyze.analyze(problem, Y[:, o], calc_second_order=second_order, num_resamples=100,
                                           conf_level=0.95, seed=SEED_BOOTSTRAP)

    t0 = time.perf_counter()
    refs = [salib(o) for o in range(salib_first)]
    t_first = time.perf_counter() - t0
    if t_first * N_OUTPUTS / salib_first <= SALIB_BUDGET_S:
        t0 = time.perf_counter()
        refs += [salib(o) for o in range(salib_first, N_OUTPUTS)]
        t_salib = t_first + (time.perf_counter() - t0)
        timing = f"measured on all {N_OUTPUTS} outputs"
    else:
        t_salib = t_first * N_OUTPUTS / salib_first
        timing = f"extrapolated linearly from {salib_first} outputs ({t_first:.2f} s measured)"
    diff = max(float(np.nanmax(np.abs(getattr(res, key)[o] - ref[key]))) for o, ref in enumerate(refs) for key in keys)
    return {
        "second_order": second_order, "D": D, "N": N, "n_outputs": N_OUTPUTS, "n_samples": int(X.shape[0]),
        "vectorized_s": t_ours, "salib_loop_s": t_salib, "salib_timing": timing,
        "salib_outputs_timed": salib_first if timing.startswith("extrapolated") else len(refs),
        "speedup_vs_salib": t_salib / t_ours, "outputs_compared": len(refs), "max_abs_difference": diff,
    }


def main() -> None:
    rows = []
    for second_order, salib_first in ((False, 16), (True, 4)):
        row = _row(second_order, salib_first)
        rows.append(row)
        print(f"Sobol' {'S1+ST+S2' if second_order else 'S1+ST'}  D {D}  N {N}  {N_OUTPUTS} outputs: vectorized "
              f"{row['vectorized_s']:7.3f} s, SALib loop {row['salib_loop_s']:8.2f} s ({row['salib_timing']}), "
              f"{row['speedup_vs_salib']:6.1f}x; max |difference| {row['max_abs_difference']:.1e} over "
              f"{row['outputs_compared']} outputs")
    write_results("sobol", rows)


if __name__ == "__main__":
    main()
