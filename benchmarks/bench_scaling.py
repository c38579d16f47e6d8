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

``python -m benchmarks.bench_scaling dask``: the GSA stage of ``cappe identify`` on ``builtin:three-axis-machine-tool``
(61 unknowns, Sobol' N = 16 as ``--n-gsa 16``, i.e. 16 x 63 model runs per position, at 2 of the grid's corners, 25
modes, the four criteria) serially, then on a real local Dask cluster started here (``distributed.LocalCluster``:
a scheduler and 1, then 2 worker processes of one thread each): the Sobol' indices must be identical, and the wall
and CPU times give the scaling (``results/scaling_dask.json``). This host has 2 cores shared with other work: 2
workers is its limit, and the load is recorded.
"""

from __future__ import annotations

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


def dask() -> None:
    """The three-axis GSA stage serially and on a local Dask cluster of 1 and 2 workers: identical indices."""
    from distributed import Client, LocalCluster

    from cappe.estimate import ParameterSpace
    from cappe.model import load_model
    from cappe.sensitivity import model_sobol

    nm = NumericModel(load_model("builtin:three-axis-machine-tool"))
    space = ParameterSpace.from_model(nm)
    truth = space.mapping(space.sample(1))
    positions = [{"x": -0.6, "y": 0.4, "z": -0.2}, {"x": 0.6, "y": 1.2, "z": 0.2}]
    reference = reference_modes(nm, params=truth, positions=positions, n_modes=25)

    def gsa(executor: str) -> tuple[Any, float, float, float]:
        load = os.getloadavg()[0]
        wall, cpu = time.perf_counter(), time.process_time()
        result = model_sobol(nm, reference, n=16, rng=0, executor=executor)
        return result, time.perf_counter() - wall, time.process_time() - cpu, load

    serial, wall_s, cpu_s, load_s = gsa("serial")
    rows: list[dict[str, Any]] = [{"executor": "serial", "workers": 1, "wall_s": wall_s, "client_cpu_s": cpu_s,
                                   "load": load_s, "identical": True}]
    print(f"serial: {wall_s:.1f} s wall ({cpu_s:.1f} s CPU), load {load_s:.1f}", flush=True)
    for workers in (1, 2):
        with (LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None) as cluster,
              Client(cluster) as client):
            before = client.run(time.process_time)
            result, wall, cpu, load = gsa(cluster.scheduler_address)
            after = client.run(time.process_time)
        worker_cpu = sum(after[w] - before[w] for w in after)
        same = all(np.array_equal(getattr(result.sobol, k), getattr(serial.sobol, k)) for k in ("S1", "ST"))
        rows.append({"executor": "dask LocalCluster", "workers": workers, "wall_s": wall, "client_cpu_s": cpu,
                     "worker_cpu_s": worker_cpu, "load": load, "identical": same, "speed_up_vs_serial": wall_s / wall})
        print(f"dask, {workers} worker(s): {wall:.1f} s wall (client {cpu:.1f} s CPU, workers {worker_cpu:.1f} s "
              f"CPU), load {load:.1f}; identical to serial: {same}", flush=True)
    rows.append({"model": "three-axis-machine-tool", "stage": "GSA (model_sobol)", "n": 16, "unknowns": space.n,
                 "positions": positions, "n_modes": 25, "model_runs": 16 * (space.n + 2) * len(positions)})
    write_results("scaling_dask", rows)


def main() -> None:
    if sys.argv[1:] == ["dask"]:
        dask()
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
