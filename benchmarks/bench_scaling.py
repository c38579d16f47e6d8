"""How the automated identification's time grows with the model size and the number of unknowns.

A synthetic chain of rigid bodies (6 DOF each, full 6 x 6 mass blocks) between two walls, joined by elements with
a stiffness parameter per direction and a viscous damping parameter per element; a sensor node on every body.
The reference: the chain's own exact modes (10 lowest) at nominal values with the unknowns drawn within their
bounds (stiffness 0.7-1.3 x, damping 1/3-3 x nominal, as paper eq. 14). The pipeline runs with reduced settings
(N = 32, N_opt = 8, one position, no permuted-damping models) so that the largest case stays within minutes; its
stages scale with N and N_opt linearly, so the exponents carry over.

Two sweeps: n_dof = 30 ... 300 with 27 unknowns (20 stiffness, 7 damping), and 27 ... 100 unknowns at n_dof = 120.
Reported: time per stage and in total, and the growth exponents b of t ~ x^b (least squares on log-log), written
to ``benchmarks/results/scaling.json`` with a plot ``scaling.png``.

``python -m benchmarks.bench_scaling dask [--workers 1,2,4,8] [--full] [--seed S]``: a whole ``cappe identify`` on
``builtin:three-axis-machine-tool`` (61 unknowns, 25 modes per position, the reference from the independent scipy
generator of :mod:`benchmarks.bench_three_axis` at a random truth), run as a command in a child process: serially
(``--executor serial``), then with ``--scheduler`` on a real local Dask cluster started here
(``distributed.LocalCluster``: a scheduler and 1, 2, ... worker processes of one thread each, every process on one
BLAS thread, the workers with one malloc arena: ``MALLOC_ARENA_MAX=1``). The result files must be identical except
their timings, and so must the printed text and warnings.
The GSA, the subproblems, the stiffness refinement's starts and the validations run on the cluster, the other steps
in the command's process. Default settings keep one run to minutes on a shared 2-core host: 2 identification
positions, ``--n-gsa 16 --n-opt 4 --permutations 2 --first-order``; ``--full`` takes bench_three_axis's (4
positions, ``--n-gsa 64 --n-opt 10``, exact final refinement). On the first cluster, 200 trivial tasks that read the
engine measure the cost per task (the first map ships the engine and its model, the second finds them on the
workers). Reported (``results/scaling_dask.json``): wall and CPU seconds of the command and of the workers, the
load, the stage times, and the parallel efficiency of the distributed stages against the smallest cluster,
``t_1 w_1 / (t_w w)`` on their wall times: meaningful only on a machine with a free core per worker (this host has
2 cores shared with other work: its load is recorded).
"""

from __future__ import annotations

import json
import os
import sys
import time
from typing import Any

import numpy as np

from benchmarks._common import RESULTS, write_results
from cappe.estimate import AutomatedIdentification
from cappe.modal import reference_modes
from cappe.model import NumericModel, StructureBuilder

SETTINGS = {"n_gsa": 32, "n_opt": 8, "n_permutations": 0}
N_MODES = 10
SIX = ("x", "y", "z", "rx", "ry", "rz")


def sliding_chain(n_bodies: int) -> NumericModel:
    """Bodies b0..b(n-1) along z between two walls; element e_i has k{i}_{x..rz} and c{i}."""
    b = StructureBuilder(f"scaling-chain-{n_bodies}")
    b.parameter("m", 5.0, kind="mass")
    b.parameter("J", 0.05, kind="inertia")
    for i in range(n_bodies + 1):
        for d in SIX:
            nominal = 1.0e7 * (1 + 0.05 * i) * (1.0 if d in "xyz" else 0.01) * (1 + 0.1 * SIX.index(d))
            b.parameter(f"k{i}_{d}", nominal, kind="stiffness", bounds=(0.7 * nominal, 1.3 * nominal))
        b.parameter(f"c{i}", 100.0, kind="damping", bounds=(100.0 / 3, 300.0))
    for i in range(n_bodies):
        b.body(f"b{i}", mass="m", inertia={"xx": "J", "yy": "J", "zz": "J", "xy": "J/10"}, position=[0, 0, 0.2 * i],
               com=[0.01, 0.005, 0.02])
        b.sensor(f"s{i}", body=f"b{i}", point=[0.05, 0.03, 0.0])
    for i in range(n_bodies + 1):
        a = "ground" if i == 0 else f"b{i - 1}"
        c = "ground" if i == n_bodies else f"b{i}"
        b.element(f"e{i}", bodies=(a, c), at=[0.05, 0.02, 0.2 * i - 0.1], stiffness={d: f"k{i}_{d}" for d in SIX},
                  damping={"x": f"c{i}"})
    return NumericModel(b.build())


def unknowns(model: NumericModel, n: int) -> list[str]:
    """About three stiffnesses per damping parameter, spread along the chain."""
    stiff = [p for p in model.parameter_names if p.startswith("k")]
    damp = [p for p in model.parameter_names if p.startswith("c")]
    n_damp = min(max(1, round(n * 7 / 27)), len(damp))
    pick_s = np.linspace(0, len(stiff) - 1, n - n_damp).round().astype(int)
    pick_d = np.linspace(0, len(damp) - 1, n_damp).round().astype(int)
    return [stiff[i] for i in pick_s] + [damp[i] for i in pick_d]


def run(n_bodies: int, n_unknowns: int) -> dict[str, Any]:
    t0 = time.perf_counter()
    model = sliding_chain(n_bodies)
    compile_s = time.perf_counter() - t0
    names = unknowns(model, n_unknowns)
    rng = np.random.default_rng(n_bodies * 1000 + n_unknowns)
    truth = {}
    for name in names:
        lo, hi = model.structure.parameter(name).bounds
        truth[name] = float(lo * (hi / lo) ** rng.uniform())
    reference = reference_modes(model, params=truth, n_modes=N_MODES)
    t1 = time.perf_counter()
    est = AutomatedIdentification(model, names, rng=1, **SETTINGS).fit(reference)
    fit_s = time.perf_counter() - t1
    errors = est.estimate_.relative_error(truth)
    return {"n_dof": model.n_dof, "n_unknowns": len(names), "compile_s": compile_s, "fit_s": fit_s,
            "stages_s": {k: v for k, v in est.timings_.items() if k != "total"},
            "worst_stiffness_error": max(abs(errors[n]) for n in names if n.startswith("k"))}


def exponent(x: list[float], t: list[float]) -> float:
    """Least-squares slope of log t against log x."""
    return float(np.polyfit(np.log(x), np.log(t), 1)[0])


#: wall and CPU seconds (of the stages, of each subproblem): the only entries allowed to differ
DASK_IGNORED = ("timings", "cpu_timings", "seconds")


def _without_times(doc: Any) -> Any:
    """``doc`` (a result file's JSON) without its timings."""
    if isinstance(doc, dict):
        return {k: _without_times(v) for k, v in doc.items() if k not in DASK_IGNORED}
    if isinstance(doc, list):
        return [_without_times(v) for v in doc]
    return doc


def _differences(a: Any, b: Any, path: str = "") -> list[str]:
    """Where two JSON documents differ (their paths)."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = [f"{path}/{k}: only in one" for k in sorted(set(a) ^ set(b))]
        for k in sorted(set(a) & set(b)):
            out += _differences(a[k], b[k], f"{path}/{k}")
        return out
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return [d for k, (x, y) in enumerate(zip(a, b, strict=True)) for d in _differences(x, y, f"{path}[{k}]")]
    return [] if a == b or (a != a and b != b) else [f"{path}: {a!r} != {b!r}"]


def _identify_cli(args: list[str], out: Any) -> dict[str, Any]:
    """``cappe identify ARGS -o OUT`` in a child process: its wall and CPU seconds, result file and text."""
    import resource
    import subprocess

    load = os.getloadavg()[0]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    wall = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "cappe.cli", "identify", *args, "-o", str(out)], capture_output=True,
                          text=True, check=False)
    wall = time.perf_counter() - wall
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode not in (0, 1):
        msg = f"cappe identify failed (exit {done.returncode}):\n{done.stderr[-3000:]}"
        raise SystemExit(msg)
    text = [line for line in done.stdout.splitlines() if not line.startswith(("runtime:", "result (cappe."))]
    return {"wall_s": wall, "cpu_s": (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime),
            "load": load, "doc": json.loads(out.read_text()), "text": text,
            "warnings": [line for line in done.stderr.splitlines() if line.startswith("cappe: warning:")]}


def _task_overhead(address: str, engine: Any, n_tasks: int) -> dict[str, float]:
    """Wall seconds per task of maps of trivial tasks that read the three-axis engine: the first map ships the engine
    and its model; the second finds them on the workers."""
    import cloudpickle

    from cappe.parallel import Executor, shared_loads

    items = [slice(k, k + 1) for k in range(n_tasks)]

    def touch(s: slice) -> int:
        return engine.model.n_dof + s.start

    out: dict[str, float] = {"engine_bytes_with_caches": len(cloudpickle.dumps(engine)),
                             "model_bytes": len(cloudpickle.dumps(engine.model))}
    with Executor(address) as ex:
        for label in ("first_map", "second_map"):
            wall = time.perf_counter()
            ex.map(touch, items)
            out[f"{label}_s_per_task"] = (time.perf_counter() - wall) / n_tasks
        out["loads_per_worker"] = max(sum(c.values()) for c in ex.client.run(shared_loads).values())
    wall = time.perf_counter()
    with Executor("serial") as ex:
        ex.map(touch, items)
    out["serial_s_per_task"] = (time.perf_counter() - wall) / n_tasks
    return out


def dask(argv: list[str]) -> None:
    """A whole ``cappe identify`` on the three-axis machine, serially and on local Dask clusters (see the module)."""
    import argparse
    import tempfile
    from pathlib import Path

    from distributed import Client, LocalCluster

    from benchmarks.bench_three_axis import N_MODES, POSITIONS, VALIDATION, independent_reference
    from cappe.estimate import ParameterSpace
    from cappe.io.modal import write_modal_data
    from cappe.modal import ModalEngine
    from cappe.model import load_model

    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_scaling dask")
    parser.add_argument("--workers", default="1,2", help="worker processes of the clusters, e.g. 1,2,4,8 (default 1,2)")
    parser.add_argument("--full", action="store_true",
                        help="bench_three_axis's settings: 4 positions, --n-gsa 64 --n-opt 10, exact final refinement")
    parser.add_argument("--seed", type=int, default=1, help="the truth's seed (default 1)")
    opts = parser.parse_args(argv)
    workers = [int(w) for w in opts.workers.split(",")]
    positions = POSITIONS if opts.full else POSITIONS[:2]
    settings = ["--n-gsa", "64", "--n-opt", "10"] if opts.full else [
        "--n-gsa", "16", "--n-opt", "4", "--permutations", "2", "--first-order"]
    # one BLAS thread in every process: the client, the CLI and the workers (they inherit it)
    os.environ.update({"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"})
    # one malloc arena in each (single-threaded) worker, set before it starts: a task runs on the worker's executor
    # thread, whose own arena unmaps its heaps as they empty (see cappe.parallel: 1.3x the CPU of the same work in
    # a plain process without it)
    import dask

    dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_ARENA_MAX": 1})
    machine = NumericModel(load_model("builtin:three-axis-machine-tool"))
    space = ParameterSpace.from_model(machine)
    rng = np.random.default_rng(opts.seed)
    truth = space.mapping(space.lower * (space.upper / space.lower) ** rng.uniform(size=space.n))
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        write_modal_data(folder / "reference.json", independent_reference(machine, truth, [*positions, VALIDATION]))
        (folder / "truth.json").write_text(json.dumps(truth))
        where = ",".join(f"{k}={v}" for k, v in VALIDATION.items())
        args = ["builtin:three-axis-machine-tool", "--reference", str(folder / "reference.json"), "--truth",
                str(folder / "truth.json"), "--validation", where, "--seed", "0", *settings]
        serial = _identify_cli([*args, "--executor", "serial"], folder / "serial.json")
        reference_doc = _without_times(serial["doc"])
        diag = serial["doc"]["diagnostics"]
        rows.append({"executor": "serial", "workers": 1, "wall_s": serial["wall_s"], "cpu_s": serial["cpu_s"],
                     "warnings": len(serial["warnings"]),
                     "load": serial["load"], "stages_s": diag["timings"], "stages_cpu_s": diag["cpu_timings"]})
        print(f"serial: {serial['wall_s']:.1f} s wall, {serial['cpu_s']:.1f} s CPU, load {serial['load']:.1f}; "
              f"stages (wall s): {', '.join(f'{k} {v:.1f}' for k, v in diag['timings'].items())}", flush=True)
        for n in workers:
            # the scheduler's HTTP server on a free port (its default 8787 may be taken by another cluster)
            with (LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                               scheduler_kwargs={"dashboard_address": ":0"}) as cluster,
                  Client(cluster) as client):
                address = cluster.scheduler_address
                overhead = _task_overhead(address, ModalEngine(machine, sensors=None), 200) if n == workers[0] else None
                cpu_before = client.run(time.process_time)
                run = _identify_cli([*args, "--scheduler", address], folder / f"dask{n}.json")
                cpu_after = client.run(time.process_time)
            worker_cpu = sum(cpu_after[w] - cpu_before[w] for w in cpu_after)
            diffs = _differences(_without_times(run["doc"]), reference_doc)
            same_text = run["text"] == serial["text"] and run["warnings"] == serial["warnings"]
            diag = run["doc"]["diagnostics"]
            row = {"executor": "dask LocalCluster", "workers": n, "wall_s": run["wall_s"], "client_cpu_s": run["cpu_s"],
                   "worker_cpu_s": worker_cpu, "load": run["load"], "identical": not diffs, "differences": diffs[:20],
                   "identical_text": same_text, "warnings": len(run["warnings"]), "stages_s": diag["timings"],
                   "stages_cpu_s": diag["cpu_timings"]}
            if overhead is not None:
                row["task_overhead"] = overhead
                print(f"per task on {n} worker(s): {1e3 * overhead['first_map_s_per_task']:.2f} ms (first map, ships "
                      f"the engine), {1e3 * overhead['second_map_s_per_task']:.2f} ms (second), serial "
                      f"{1e3 * overhead['serial_s_per_task']:.3f} ms; loads per worker {overhead['loads_per_worker']}",
                      flush=True)
            rows.append(row)
            print(f"dask, {n} worker(s): {run['wall_s']:.1f} s wall, CPU client {run['cpu_s']:.1f} s + workers "
                  f"{worker_cpu:.1f} s, load {run['load']:.1f}; result file identical to serial: {not diffs} "
                  f"{diffs[:3]}, text and warnings identical: {same_text}; stages (wall s): "
                  f"{', '.join(f'{k} {v:.1f}' for k, v in diag['timings'].items())}", flush=True)
    distributed_stages = ("gsa", "stiffness_subproblems", "stiffness_refinement", "validation")
    base = next((r for r in rows if r.get("workers") == workers[0] and r["executor"] != "serial"), None)
    for row in rows:
        if row["executor"] != "serial" and base is not None:
            t1 = sum(base["stages_s"][k] for k in distributed_stages)
            tw = sum(row["stages_s"][k] for k in distributed_stages)
            row["distributed_stages_wall_s"] = tw
            row["parallel_efficiency_vs_first"] = t1 * base["workers"] / (tw * row["workers"])
    rows.append({"model": "three-axis-machine-tool", "unknowns": space.n, "positions": positions,
                 "validation": VALIDATION, "n_modes": N_MODES, "settings": settings, "truth_seed": opts.seed,
                 "reference": "scipy eig of the state matrix (benchmarks.bench_three_axis.independent_reference)",
                 "distributed_stages": distributed_stages, "blas_threads": 1, "threads_per_worker": 1})
    write_results("scaling_dask", rows)


def main() -> None:
    if sys.argv[1:2] == ["dask"]:
        dask(sys.argv[2:])
        return
    rows = []
    for n_bodies in (5, 10, 20, 30, 50):
        rows.append({"sweep": "n_dof", **run(n_bodies, 27)})
        print(f"n_dof {rows[-1]['n_dof']:4d}, 27 unknowns: fit {rows[-1]['fit_s']:6.1f} s", flush=True)
    for n_unknowns in (27, 50, 75, 100):
        rows.append({"sweep": "unknowns", **run(20, n_unknowns)})
        print(f"n_dof  120, {n_unknowns:3d} unknowns: fit {rows[-1]['fit_s']:6.1f} s", flush=True)
    dof = [r for r in rows if r["sweep"] == "n_dof"]
    unk = [r for r in rows if r["sweep"] == "unknowns"]
    exponents = {
        "n_dof": exponent([r["n_dof"] for r in dof], [r["fit_s"] for r in dof]),
        "unknowns": exponent([r["n_unknowns"] for r in unk], [r["fit_s"] for r in unk]),
    }
    for stage in dof[0]["stages_s"]:
        exponents[f"n_dof:{stage}"] = exponent([r["n_dof"] for r in dof], [r["stages_s"][stage] + 1e-9 for r in dof])
        exponents[f"unknowns:{stage}"] = exponent([r["n_unknowns"] for r in unk],
                                                  [r["stages_s"][stage] + 1e-9 for r in unk])
    print(f"growth exponents: t ~ n_dof^{exponents['n_dof']:.2f} (27 unknowns), "
          f"t ~ n_unknowns^{exponents['unknowns']:.2f} (n_dof = 120)")
    write_results("scaling", [*rows, {"exponents": exponents}])
    _plot(dof, unk, exponents)


def _plot(dof: list[dict[str, Any]], unk: list[dict[str, Any]], exponents: dict[str, float]) -> None:
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.6))
    for ax, rows, key, label in ((axes[0], dof, "n_dof", "degrees of freedom"),
                                 (axes[1], unk, "n_unknowns", "unknown parameters")):
        x = [r[key] for r in rows]
        ax.loglog(x, [r["fit_s"] for r in rows], "o-", color="k", label="total")
        for stage in ("gsa", "stiffness_subproblems", "stiffness_refinement", "joint_refinement"):
            ax.loglog(x, [r["stages_s"][stage] for r in rows], ".--", label=stage.replace("_", " "))
        ax.set_xticks(x, [str(v) for v in x])
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xlabel(label)
        ax.set_ylabel("time (s)")
        ax.set_title(f"t ~ {key.replace('n_', '')}^{exponents['n_dof' if key == 'n_dof' else 'unknowns']:.2f}")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle("automated identification, synthetic chain (N = 32, N_opt = 8, 10 modes)", fontsize=9)
    fig.tight_layout()
    fig.savefig(RESULTS / "scaling.png", dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
