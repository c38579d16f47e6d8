"""Modal engine throughput as a fraction of the LAPACK bound, thread scaling, and against a naive loop.

For chains of 6-DOF rigid bodies (n_dof 12 to 150) and several batch sizes, in one run:

* ``engine_1``: ModalEngine.evaluate with one worker (frequencies, first-order damping, sensor shapes);
* ``engine_2``: the same with two worker threads;
* ``engine_known_mass_1``: one worker, masses and inertias at their nominal values (the GSA's and the stiffness
  subproblems' case: every sample shares the nominal M, whose reduction is made once);
* ``bound_2``: the same eigen-solves split over two threads (what the machine's cores allow);
* ``bound``: numpy's batched ``eigh`` alone on the reduced symmetric matrices of the same problems, BLAS
  pinned to one thread (the cost of the eigen-solves, which no modal engine can beat);
* ``loop``: the naive route, one MechanicalSystem per sample and scipy's generalized ``eigh`` (timed on a
  subset and scaled).

Reported: ``fraction_of_bound = t_bound / t_engine_1`` (target >= 0.7 for n_dof >= 30), ``thread_speedup
= t_engine_1 / t_engine_2`` (target >= 1.8 on 2 cores) and ``speedup_vs_loop``.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from benchmarks._common import best, write_results
from benchmarks.bench_matrices import chain
from cappe.modal import ModalEngine
from cappe.parallel import single_threaded_blas


def main() -> None:
    rng = np.random.default_rng(0)
    rows = []
    for n_bodies, batches in ((2, (256, 2048)), (5, (256, 1024)), (10, (128, 512)), (25, (64, 256))):
        model = chain(n_bodies)
        for batch in batches:
            params = model.nominal * rng.uniform(0.7, 1.3, size=(batch, model.nominal.size))
            chunk = max(1, min(256, batch // 4))
            one = ModalEngine(model, n_workers=1, chunk_size=chunk)
            two = ModalEngine(model, n_workers=2, chunk_size=chunk)
            one.evaluate(params[:2])  # compile caches
            t_one = best(lambda: one.evaluate(params))  # noqa: B023 (called inside the iteration)
            t_two = best(lambda: two.evaluate(params))  # noqa: B023
            known = params.copy()
            masses = [i for i, name in enumerate(model.parameter_names)
                      if model.structure.parameter(name).kind in ("mass", "inertia")]
            known[:, masses] = model.nominal[masses]
            t_known = best(lambda: one.evaluate(known))  # noqa: B023
            mats = model.matrices(params, names=("M", "K"))
            linv = np.linalg.inv(np.linalg.cholesky(mats["M"]))
            reduced = linv @ mats["K"] @ np.swapaxes(linv, 1, 2)
            halves = [reduced[: batch // 2], reduced[batch // 2 :]]
            with single_threaded_blas():
                t_bound = best(lambda: np.linalg.eigh(reduced))  # noqa: B023
                with ThreadPoolExecutor(2) as pool:
                    t_bound_2 = best(lambda: list(pool.map(np.linalg.eigh, halves)))  # noqa: B023
                n_loop = min(batch, 64)
                t_loop = best(
                    lambda: [model.system(p).modes("first-order") for p in params[:n_loop]],  # noqa: B023
                    repeat=2,
                ) * batch / n_loop
            row = {
                "n_dof": model.n_dof,
                "batch": batch,
                "chunk_size": chunk,
                "engine_1_s": t_one,
                "engine_2_s": t_two,
                "engine_known_mass_1_s": t_known,
                "fraction_of_bound_known_mass": t_bound / t_known,
                "bound_s": t_bound,
                "loop_s": t_loop,
                "evaluations_per_s_1": batch / t_one,
                "evaluations_per_s_2": batch / t_two,
                "fraction_of_bound": t_bound / t_one,
                "thread_speedup": t_one / t_two,
                "bound_2_s": t_bound_2,
                "bound_thread_speedup": t_bound / t_bound_2,
                "speedup_vs_loop": t_loop / t_one,
            }
            rows.append(row)
            print(
                f"n_dof {model.n_dof:4d} batch {batch:5d}: {row['evaluations_per_s_1']:9.0f}/s (1 thread) "
                f"{row['evaluations_per_s_2']:9.0f}/s (2 threads, {row['thread_speedup']:4.2f}x; bare eigh "
                f"{row['bound_thread_speedup']:4.2f}x); "
                f"{row['fraction_of_bound']:4.2f} of the eigh bound ({row['fraction_of_bound_known_mass']:4.2f} with "
                f"known masses); {row['speedup_vs_loop']:5.1f}x the loop"
            )
    write_results("modal", rows)


if __name__ == "__main__":
    main()
