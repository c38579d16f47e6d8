"""The ideal-case ``cappe identify`` on the three-axis machine (issue 24), against its eigen-solve bound.

Settings: ``builtin:three-axis-machine-tool`` (162 DOF, 61 unknowns), a random truth log-uniform within the bounds
(``--seed``), noise-free reference modes at four positions (a half fraction of the grid's corners, every axis
varied) and the centre held out for validation, 25 modes per position, ``--n-gsa 64 --n-opt 10`` and the other
settings at identify's defaults, BLAS and cappe's executor on one thread (the issue's target is one identification
per 2-core machine shared with other jobs).

The reference modes come from an independent generator written here from the physics: scipy's ``eig`` of the state
matrix ``[[0, I], [-M^-1 (K + iH), -M^-1 (C + G)]]`` built from the model's assembled matrices at the truth, the 25
lowest oscillatory poles, the shapes at the model's sensor channels (no cappe modal engine, no tracking).

Every eigen-solve the run makes is counted as in :mod:`benchmarks.bench_pipeline` (numpy's ``eigh`` and ``eig``,
scipy's generalized ``eigh`` of the modal derivatives, and the complex LU factorizations with which the exact modes
are solved and differentiated on the quadratic eigenproblem) and the same number of solves of the same sizes is
timed bare on one thread: ``bound_s``, the time the same solves take bare on one core (the median of
:data:`BOUND_TIMINGS` timings, each the best of five batches per solve kind; every timing is kept). Reported per
truth: wall and CPU seconds, time per stage, peak memory, ``wall / bound`` and ``cpu / bound``, the load average
before and after, and the worst stiffness and damping errors.

    python -m benchmarks.bench_three_axis --seed 1 [--seed 2 ...]    (each truth in its own child process)
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

from benchmarks._common import RESULTS, state_matrix_modes, write_results
from benchmarks.bench_pipeline import _bare_seconds, _count_eigen_solves

SETTINGS = {"n_gsa": 64, "n_opt": 10}
POSITIONS = [{"x": -0.6, "y": 0.4, "z": -0.2}, {"x": 0.6, "y": 1.2, "z": -0.2},
             {"x": 0.6, "y": 0.4, "z": 0.2}, {"x": -0.6, "y": 1.2, "z": 0.2}]
VALIDATION = {"x": 0.0, "y": 0.8, "z": 0.0}
N_MODES = 25


def independent_reference(machine: Any, truth: dict[str, float], positions: list[dict[str, float]]) -> Any:
    """Exact complex modes at ``positions`` by scipy's dense ``eig`` of the state matrix (no cappe modal code)."""
    from cappe.modal import ModalEngine
    from cappe.systems.modal import ModalData, ModalDataSet

    params = machine.vector(machine.structure.resolve_parameters(truth))
    labels, _ = ModalEngine(machine).sensor_rows(machine.structure.default_position())
    sets = []
    for position in positions:
        mats = machine.matrices(params, position)
        rows = machine.sensor_matrix(position=position)[1]
        lam, vec = state_matrix_modes(mats, N_MODES)
        w = np.abs(lam)
        sets.append(ModalDataSet(dict(position), w / (2 * np.pi), -lam.real / w, rows @ vec))
    return ModalData(tuple(labels), tuple(sets), "independent scipy eig")


def _time_stages(cpu: dict[str, float]) -> None:
    """Wrap the identification's steps so that each adds its CPU seconds to ``cpu`` and logs them as it ends (the
    identification's own ``timings_`` are wall seconds, which a loaded host inflates)."""
    import cappe.estimate._automated_steps as steps

    for name in ("sensitivity_step", "subproblem_step", "stiffness_refinement_step", "damping_step",
                 "joint_refinement_step", "validation_step"):
        func = getattr(steps, name)

        def timed(*args: Any, _func: Any = func, _name: str = name, **kwargs: Any) -> Any:
            c0, t0 = time.process_time(), time.perf_counter()
            out = _func(*args, **kwargs)
            cpu[_name] = time.process_time() - c0
            print(f"{_name}: {cpu[_name]:.1f} s CPU, {time.perf_counter() - t0:.1f} s wall, load "
                  f"{os.getloadavg()[0]:.1f}", file=sys.stderr, flush=True)
            return out

        setattr(steps, name, timed)


def child(seed: int) -> dict[str, Any]:
    """The measured run (in its own process)."""
    counter: Counter[tuple[str, int, str]] = Counter()
    _count_eigen_solves(counter)
    stage_cpu: dict[str, float] = {}
    _time_stages(stage_cpu)
    from cappe.estimate import AutomatedIdentification, ParameterSpace
    from cappe.model import NumericModel, load_model

    cpu0, t0 = time.process_time(), time.perf_counter()
    machine = NumericModel(load_model("builtin:three-axis-machine-tool"))
    compile_s = time.perf_counter() - t0
    space = ParameterSpace.from_model(machine)
    rng = np.random.default_rng(seed)
    truth = space.mapping(space.lower * (space.upper / space.lower) ** rng.uniform(size=space.n))
    reference = independent_reference(machine, truth, [*POSITIONS, VALIDATION])
    counter.clear()  # the reference is the user's data, not the identification's work
    cpu1, t1 = time.process_time(), time.perf_counter()
    estimator = AutomatedIdentification(machine, validation=VALIDATION, rng=seed, n_workers=1, **SETTINGS)
    result = estimator.fit(reference, truth=truth).estimate_
    fit_s, fit_cpu = time.perf_counter() - t1, time.process_time() - cpu1
    errors = result.relative_error(truth)
    return {
        "seed": seed, "wall_s": compile_s + fit_s, "compile_s": compile_s, "fit_s": fit_s,
        "cpu_s": time.process_time() - cpu0, "fit_cpu_s": fit_cpu,
        "stages_s": {k: v for k, v in estimator.timings_.items() if k != "total"}, "stages_cpu_s": stage_cpu,
        "peak_memory_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "errors": {k: float(v) for k, v in errors.items()},
        "eigen_solves": [{"kind": k, "n": n, "dtype": d, "count": c} for (k, n, d), c in sorted(counter.items())],
        # the joint refinement's record: its exact solves (quadratic eigenproblem or fallback to the state eig), its
        # pairing candidates, its least-squares evaluations over the fit and the two reweighted refits
        "joint_refinement": {**{k: result.diagnostics.get(k) for k in ("exact_solves", "pairing_candidates",
                                                                        "iterations", "evaluations", "scatter")},
                             "record": result.diagnostics.get("joint_refinement")},
        # how far the joint refinement started from the truth (after the damping least squares)
        "start_errors": {k: float(v / truth[k] - 1.0)
                         for k, v in result.diagnostics["stages"]["after_damping_least_squares"].items()},
    }


def main(seeds: list[int]) -> None:
    from cappe.estimate import ParameterSpace  # noqa: F401  (import check before the long runs)

    rows = []
    # the truths run side by side, one process and one BLAS thread each; each logs its stages to RESULTS/*.log
    env = {**os.environ, "PYTHONWARNINGS": "ignore", "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
           "MKL_NUM_THREADS": "1"}
    load_before = os.getloadavg()
    RESULTS.mkdir(exist_ok=True)
    runs = []
    for seed in seeds:
        with (RESULTS / f"three_axis_{seed}.log").open("w") as log:
            runs.append(subprocess.Popen([sys.executable, "-m", "benchmarks.bench_three_axis", "--child", str(seed)],
                                         stdout=subprocess.PIPE, stderr=log, text=True, env=env))
    for seed, run in zip(seeds, runs, strict=True):
        stdout, _ = run.communicate()
        if run.returncode:
            print(f"truth {seed}: failed (exit {run.returncode}); see {RESULTS / f'three_axis_{seed}.log'}")
            continue
        row = json.loads(stdout.strip().splitlines()[-1])
        row["load_before"], row["load_after"] = load_before, os.getloadavg()
        bound, attempts = _bound(row["eigen_solves"])
        damping = _damping_names()
        stiff_err = [abs(v) for k, v in row["errors"].items() if k not in damping]
        damp_err = [abs(v) for k, v in row["errors"].items() if k in damping]
        row.update({"bound_s": bound, "bound_attempts_s": attempts, "ratio_to_bound": row["wall_s"] / bound,
                    "cpu_ratio_to_bound_range": [row["cpu_s"] / max(attempts), row["cpu_s"] / min(attempts)],
                    "cpu_ratio_to_bound": row["cpu_s"] / bound, "fit_cpu_ratio_to_bound": row["fit_cpu_s"] / bound,
                    "stiffness_worst": max(stiff_err), "damping_worst": max(damp_err), "settings": SETTINGS})
        stages = ", ".join(f"{k} {v:.1f}" for k, v in row["stages_s"].items())
        solves = ", ".join(f"{e['count']} {e['kind']} {e['n']}x{e['n']} {e['dtype']}" for e in row["eigen_solves"])
        cpu_stages = ", ".join(f"{k} {v:.1f}" for k, v in row["stages_cpu_s"].items())
        print(f"truth {seed}: {row['wall_s']:.0f} s wall, {row['cpu_s']:.0f} s CPU (compile {row['compile_s']:.1f} "
              f"s; wall {stages} s; CPU {cpu_stages} s), load {row['load_before'][0]:.1f} -> "
              f"{row['load_after'][0]:.1f}, peak memory {row['peak_memory_mib']:.0f} MiB; stiffness worst "
              f"{100 * row['stiffness_worst']:.2g} %, damping worst {100 * row['damping_worst']:.2g} %", flush=True)
        low, high = row["cpu_ratio_to_bound_range"]
        print(f"  eigen-solves: {solves}; bound {bound:.1f} s on one core (median of {len(attempts)} timings, "
              f"{min(attempts):.1f}-{max(attempts):.1f} s) -> wall / bound {row['ratio_to_bound']:.2f}, CPU / bound "
              f"{row['cpu_ratio_to_bound']:.2f} ({low:.2f}-{high:.2f} over the timings)", flush=True)
        rows.append(row)
        write_results("three_axis", rows)


#: Timings of the bound after each run, a few seconds apart; the bound is their median. One timing (the best of five
#: batches of each solve kind) varied by 10-35 % from one to the next on this quiet host (eigh of order 162: 2.1-2.9
#: ms per matrix; truth 3's bound 113-149 s in five timings), more than the margin the ratio is judged by.
BOUND_TIMINGS = 5


def _bound(solves: list[dict[str, Any]]) -> tuple[float, list[float]]:
    """The eigen-solve bound of a run's ``solves`` on one core (median of :data:`BOUND_TIMINGS` timings, seconds),
    and every timing."""
    attempts = []
    for k in range(BOUND_TIMINGS):
        if k:
            time.sleep(2.0)
        attempts.append(sum(_bare_seconds(e["kind"], e["n"], e["dtype"], e["count"]) for e in solves))
    return float(np.median(attempts)), attempts


def _damping_names() -> set[str]:
    """The damping unknowns of the three-axis machine (those the model's damping matrices depend on)."""
    from cappe.estimate import ParameterSpace
    from cappe.model import NumericModel, load_model

    machine = NumericModel(load_model("builtin:three-axis-machine-tool"))
    space = ParameterSpace.from_model(machine)
    damping = set(machine.matrix_parameters("C")) | set(machine.matrix_parameters("H"))
    return {n for n in space.names if n in damping and n not in set(machine.matrix_parameters("K"))}


if __name__ == "__main__":
    if "--child" in sys.argv:
        found = json.dumps(child(int(sys.argv[sys.argv.index("--child") + 1])), default=str)
        print(found)
        print(found, file=sys.stderr)  # kept in the log too
    else:
        args = sys.argv[1:]
        main([int(args[i + 1]) for i, a in enumerate(args) if a == "--seed"] or [1])
