"""The whole ``cappe identify`` on the benchmark machine tool at the paper's settings, against its eigen-solve bound.

Settings: ``builtin:uniaxial-machine-tool`` (45 DOF, 27 unknowns), a random truth within the bounds, exact reference
modes (20 per position) at z2..z4 for identification and z1 = -0.294 m held out, N = 1024 Saltelli base samples,
N_opt = 100 local searches per subproblem, 10 permuted-damping models, default executor (threads, one per core).

The run happens in a child process so that its peak memory (``ru_maxrss``) is its own. Every eigen-solve the run
makes is counted by wrapping numpy's ``eigh`` and ``eig``, scipy's ``eigh`` (generalized, the modal derivatives')
and LAPACK's complex ``getrf`` (the exact modes' quadratic-eigenproblem factorizations) with the matrices' sizes;
after the run the same
number of solves of the same sizes is timed bare (batched LAPACK, BLAS on one thread): serially
(``eigen_serial_s``), and split over one thread per core running at once (``bound_s``, the time no implementation
of the same algorithm could beat on this machine: two cores of the shared test machine run bare ``eigh`` 1.45-2x
as fast as one, depending on the host's load; the best of three attempts is taken). Reported: wall time (model
compilation included), time per stage, peak memory, ``wall_s / bound_s``, and ``ideal_ratio = wall_s /
(eigen_serial_s / cores)`` against perfect scaling.

The modal engine hands one eigen-solve to the samples of a chunk that share a stiffness (in the GSA, the Saltelli
columns of the damping unknowns repeat their base sample's stiffness): the solves counted, and so the bound, are
those actually made. For comparison with runs before that sharing, the samples the engine evaluated are counted too
(``engine_samples``, ``shared_solves``) and the bound with one solve per sample is reported beside it
(``bound_one_solve_per_sample_s``, ``ratio_one_solve_per_sample``).
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import time
from collections import Counter
from typing import Any

import numpy as np

from benchmarks._common import write_results

SETTINGS = {"n_gsa": 1024, "n_opt": 100, "n_permutations": 10}


def _count_eigen_solves(counter: Counter[tuple[str, int, str]]) -> None:
    """Wrap the eigen-solvers so that every solve adds (kind, n, dtype) to ``counter``: numpy's ``eigh`` and ``eig``,
    scipy's ``eigh`` (``"eigh-generalized"`` with a mass matrix: the modal derivatives' undamped modes, 39390 of
    them in a three-axis identification, uncounted before issue 24's speed work) and LAPACK's complex ``getrf``
    (``"lu"``: the factorizations the exact modes of one vector are solved and differentiated with on the quadratic
    eigenproblem, see :class:`cappe.modal._engine.QuadraticModes`)."""
    import scipy.linalg
    import scipy.linalg.lapack

    originals = {"eigh": np.linalg.eigh, "eig": np.linalg.eig}

    def wrap(kind: str) -> Any:
        func = originals[kind]

        def counted(a: Any, *args: Any, **kwargs: Any) -> Any:
            arr = np.asarray(a)
            batch = int(np.prod(arr.shape[:-2])) if arr.ndim > 2 else 1
            counter[(kind, arr.shape[-1], "complex" if np.iscomplexobj(arr) else "real")] += batch
            return func(a, *args, **kwargs)

        return counted

    np.linalg.eigh = wrap("eigh")
    np.linalg.eig = wrap("eig")
    scipy_eigh, getrf = scipy.linalg.eigh, scipy.linalg.lapack.zgetrf

    def counted_eigh(a: Any, b: Any = None, *args: Any, **kwargs: Any) -> Any:
        arr = np.asarray(a)
        kind = "eigh" if b is None else "eigh-generalized"
        counter[(kind, arr.shape[-1], "complex" if np.iscomplexobj(arr) else "real")] += 1
        return scipy_eigh(a, b, *args, **kwargs)

    def counted_lu(a: Any, *args: Any, **kwargs: Any) -> Any:
        counter[("lu", np.shape(a)[-1], "complex")] += 1
        return getrf(a, *args, **kwargs)

    scipy.linalg.eigh = counted_eigh
    scipy.linalg.lapack.zgetrf = counted_lu


def _count_engine_samples(counter: Counter[str]) -> None:
    """Wrap the modal engine's chunk solver so that every sample it evaluates adds to ``counter["samples"]``."""
    from cappe.modal._engine import ModalEngine

    original = ModalEngine._solve

    def counted(self: Any, pb: Any, *args: Any, **kwargs: Any) -> Any:
        counter["samples"] += int(pb.shape[0])
        return original(self, pb, *args, **kwargs)

    ModalEngine._solve = counted  # type: ignore[method-assign]


def child() -> dict[str, Any]:
    """The measured run (in its own process)."""
    counter: Counter[tuple[str, int, str]] = Counter()
    samples: Counter[str] = Counter()
    _count_eigen_solves(counter)
    _count_engine_samples(samples)
    from cappe.estimate import AutomatedIdentification, ParameterSpace
    from cappe.modal import reference_modes
    from cappe.model import NumericModel, load_model

    t0 = time.perf_counter()
    machine = NumericModel(load_model("builtin:uniaxial-machine-tool"))
    compile_s = time.perf_counter() - t0
    space = ParameterSpace.from_model(machine)
    rng = np.random.default_rng(1)
    truth = space.mapping(space.lower * (space.upper / space.lower) ** rng.uniform(size=space.n))
    reference = reference_modes(machine, params=machine.structure.resolve_parameters(truth), positions="all",
                                n_modes=20)
    counter.clear()  # the reference is the user's data, not the identification's work
    samples.clear()
    t1 = time.perf_counter()
    estimator = AutomatedIdentification(machine, validation={"z": -0.294}, rng=1, **SETTINGS)
    result = estimator.fit(reference, truth=truth).estimate_
    fit_s = time.perf_counter() - t1
    errors = result.relative_error(truth)
    return {
        "wall_s": compile_s + fit_s, "compile_s": compile_s, "fit_s": fit_s,
        "stages_s": {k: v for k, v in estimator.timings_.items() if k != "total"},
        "peak_memory_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "worst_relative_error": max(abs(v) for v in errors.values()),
        "eigen_solves": [{"kind": k, "n": n, "dtype": d, "count": c} for (k, n, d), c in sorted(counter.items())],
        "engine_samples": samples["samples"],
    }


def _bare_seconds(kind: str, n: int, dtype: str, count: int, threads: int = 1) -> float:
    """Batched LAPACK time of ``count`` solves of size ``n`` (BLAS on one thread: its CPU seconds), from a timed
    sample; with ``threads``, the sample is solved by that many threads at once and the time is the wall time of the
    whole count split over them."""
    from concurrent.futures import ThreadPoolExecutor

    from cappe.parallel import single_threaded_blas

    rng = np.random.default_rng(0)
    sample = min(count, max(64, 2_000_000 // (n * n)))
    a = rng.standard_normal((sample, n, n))
    if kind in ("eigh", "eigh-generalized"):
        a = a @ np.swapaxes(a, -1, -2) + n * np.eye(n)
    if dtype == "complex":
        a = a + 1j * rng.standard_normal((sample, n, n))
        if kind == "eigh":
            a = (a + np.conj(np.swapaxes(a, -1, -2))) / 2
    func: Any = np.linalg.eigh if kind == "eigh" else np.linalg.eig
    if kind == "eigh-generalized":  # scipy's K phi = lambda M phi, one at a time as the run solves them
        import scipy.linalg

        mass = a[::-1].copy()  # symmetric positive definite too

        def func(stack: Any) -> Any:
            return [scipy.linalg.eigh(k, m) for k, m in zip(stack, mass, strict=False)]
    elif kind == "lu":  # LAPACK's complex getrf, one at a time
        import scipy.linalg.lapack

        def func(stack: Any) -> Any:
            return [scipy.linalg.lapack.zgetrf(x) for x in stack]
    with single_threaded_blas(), ThreadPoolExecutor(threads) as pool:
        func(a[:2])
        list(pool.map(func, [a[:2]] * threads))  # threads started
        # one thread: its CPU time, which other jobs on a shared machine do not stretch as they stretch the wall
        # clock (a bound timed at load 11 came out 2.6x the quiet one: bench_three_axis, issue 24); several: the
        # wall clock, since their joint throughput is what is measured
        clock = time.process_time if threads == 1 else time.perf_counter
        seconds = float("inf")
        for _ in range(5):  # the best of five: the machine's load varies (the bound is the least time possible)
            t0 = clock()
            list(pool.map(func, [a] * threads))
            seconds = min(seconds, clock() - t0)
    return seconds * count / (sample * threads)


def main() -> None:
    out = subprocess.run([sys.executable, "-m", "benchmarks.bench_pipeline", "--child"], capture_output=True,
                         text=True, check=True, env={**os.environ, "PYTHONWARNINGS": "ignore"})
    row = json.loads(out.stdout.strip().splitlines()[-1])
    cores = len(os.sched_getaffinity(0))
    serial = sum(_bare_seconds(e["kind"], e["n"], e["dtype"], e["count"]) for e in row["eigen_solves"])
    # the cores' joint throughput varies on a shared machine: the best of three attempts a second apart
    attempts = []
    for _ in range(3):
        attempts.append([_bare_seconds(e["kind"], e["n"], e["dtype"], e["count"], cores) for e in row["eigen_solves"]])
        time.sleep(1.0)
    parts = min(attempts, key=sum)
    bound = sum(parts)
    # the engine hands one eigen-solve to the samples of a chunk that share a stiffness (the GSA's damping
    # columns); for comparison with runs before that sharing: the bound with one eigh per evaluated sample
    eigh_solves = sum(e["count"] for e in row["eigen_solves"] if e["kind"] == "eigh")
    eigh_bound = sum(t for t, e in zip(parts, row["eigen_solves"], strict=True) if e["kind"] == "eigh")
    shared = max(row["engine_samples"] - eigh_solves, 0)
    per_sample = bound + eigh_bound * shared / max(eigh_solves, 1)
    row.update({"cores": cores, "eigen_serial_s": serial, "bound_s": bound, "ratio_to_bound": row["wall_s"] / bound,
                "ideal_ratio": row["wall_s"] / (serial / cores), "shared_solves": shared,
                "bound_one_solve_per_sample_s": per_sample, "ratio_one_solve_per_sample": row["wall_s"] / per_sample,
                "settings": SETTINGS})
    stages = ", ".join(f"{k} {v:.1f}" for k, v in row["stages_s"].items())
    solves = ", ".join(f"{e['count']} {e['kind']} {e['n']}x{e['n']} {e['dtype']}" for e in row["eigen_solves"])
    print(f"cappe identify, machine tool, N = 1024, N_opt = 100: {row['wall_s']:.1f} s wall (compile "
          f"{row['compile_s']:.1f} s; {stages} s), peak memory {row['peak_memory_mib']:.0f} MiB, worst error "
          f"{100 * row['worst_relative_error']:.1e} %")
    print(f"  eigen-solves done: {solves}; bare LAPACK {serial:.1f} s serial, bound {row['bound_s']:.1f} s on "
          f"{cores} cores at once -> wall / bound = {row['ratio_to_bound']:.2f} (against perfect scaling, "
          f"{serial / cores:.1f} s: {row['ideal_ratio']:.2f})")
    print(f"  {row['engine_samples']} samples evaluated, {shared} of them on a solve shared with a sample of the same "
          f"stiffness; with one solve per sample the bound would be {per_sample:.1f} s -> "
          f"{row['ratio_one_solve_per_sample']:.2f}")
    write_results("pipeline", [row])


if __name__ == "__main__":
    if "--child" in sys.argv:
        print(json.dumps(child()))
    else:
        main()
