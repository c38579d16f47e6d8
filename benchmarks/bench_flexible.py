"""The modal engine on a model with a flexible body, beside a rigid-body model of the same size (issue 23).

Two pairs, each measured in one run. At 30 DOFs: ``rigid`` is the 5-body chain of :mod:`benchmarks.bench_matrices`;
``flexible`` is two 6-DOF rigid bodies on either end of a steel beam reduced by Craig-Bampton to 18 DOFs (both end
nodes' six DOFs and 6 fixed-interface modes), joined by elements whose stiffnesses vary with the beam's stiffness
and mass scales. At machine size: ``rigid-120`` is the 20-body chain (120 DOFs) beside
``builtin:uniaxial-machine-tool-flexible-bed`` (121 DOFs, 100 of them the reduced bed: 94 rank-one damping sources
of its loss factor, 21 sensor rows through the recovery matrix), its 27 unknowns drawn within their bounds at
z = 0.135 with every mode (the GSA's and the subproblems' case: known masses). The bed here carries a mass scale
``s_m`` (nominal 1: the builtin's matrices); the varying-mass case draws it and every mass and inertia within
0.9 .. 1.1 of nominal (an estimator with masses among its unknowns), reported in CPU seconds like the known masses.
Reported per model: ``fraction_of_bound = t_bound / t_engine`` with ``t_bound`` numpy's batched ``eigh`` alone on
the same reduced problems (BLAS on one thread), for a batch of varied parameter vectors; wall seconds, and for the
known masses also CPU seconds (``time.process_time``, best of five: on a loaded shared host the wall times of single
runs vary by a factor of two, the CPU times by a few tenths).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from benchmarks._common import best, best_cpu, write_results
from benchmarks.bench_matrices import chain
from cappe.modal import ModalEngine
from cappe.model import NumericModel, StructureBuilder, load_model
from cappe.model.fe import BeamSection, craig_bampton, frame_model
from cappe.parallel import single_threaded_blas


def flexible_model() -> NumericModel:
    """Two rigid bodies on a Craig-Bampton beam (30 DOFs)."""
    n = 13
    nodes = np.c_[np.linspace(0, 1.2, n), np.zeros(n), np.zeros(n)]
    fm = frame_model(nodes, [[i, i + 1] for i in range(n - 1)],
                     BeamSection.rectangle(0.08, 0.12, E=210e9, nu=0.3, rho=7850.0))
    boundary = [6 * i + d for i in (0, n - 1) for d in range(6)]
    red = craig_bampton(fm.stiffness, fm.mass, boundary, n_modes=6)
    b = StructureBuilder("flexible-30")
    b.parameter("m", 5.0, kind="mass")
    b.parameter("J", 0.05, kind="inertia")
    b.parameter("s_k", 1.0, kind="other")
    b.parameter("s_m", 1.0, kind="other")
    six = ("x", "y", "z", "rx", "ry", "rz")
    for i in range(4):
        b.parameter(f"k{i}", 1.0e7 * (1 + 0.1 * i), kind="stiffness")
        b.parameter(f"c{i}", 100.0, kind="damping")
    b.flexible_body("beam", mass=red.mass, stiffness=red.stiffness, stiffness_scale="s_k", mass_scale="s_m",
                    damping={"loss": 0.002},
                    nodes=[{"name": "left", "at": [0.0, 0, 0]}, {"name": "right", "at": [1.2, 0, 0]}])
    for j, x in enumerate((0.0, 1.2)):
        b.body(f"b{j}", mass="m", inertia={"xx": "J", "yy": "J", "zz": "J", "xy": "J/10"}, position=[x, 0, 0.2],
               com=[0.01, 0.005, 0.02])
        b.element(f"e{2 * j}", bodies=("ground", f"b{j}"), at=[x, 0.02, 0.3],
                  stiffness={d: f"k{2 * j}" if d in "xyz" else f"k{2 * j}/100" for d in six},
                  damping={"x": f"c{2 * j}"})
        b.element(f"e{2 * j + 1}", bodies=(f"b{j}", "beam"), at=[x, 0, 0],
                  stiffness={d: f"k{2 * j + 1}" if d in "xyz" else f"k{2 * j + 1}/100" for d in six},
                  damping={"x": f"c{2 * j + 1}"})
    b.input("F", body="b0", direction="x")
    b.output("d", body="b1", direction="x")
    return NumericModel(b.build())


def bed_with_mass_scale() -> NumericModel:
    """``builtin:uniaxial-machine-tool-flexible-bed`` with a mass scale ``s_m`` (nominal 1) on its bed."""
    from cappe.library import builtin_path

    text = builtin_path("uniaxial-machine-tool-flexible-bed").read_text()
    text = text.replace("parameters:\n", "parameters:\n  - {name: s_m, value: 1.0, kind: other}\n", 1)
    text = text.replace("  - name: bed\n", "  - name: bed\n    mass_scale: s_m\n", 1)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "bed.yaml"
        path.write_text(text)
        return NumericModel(load_model(path))


def varying_masses(model: NumericModel, params: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``params`` with every mass, inertia and ``s_m`` drawn within 0.9 .. 1.1 of nominal."""
    out = params.copy()
    for i, name in enumerate(model.parameter_names):
        if model.structure.parameter(name).kind in ("mass", "inertia") or name == "s_m":
            out[:, i] = model.nominal[i] * rng.uniform(0.9, 1.1, size=len(out))
    return out


def machine_params(model: NumericModel, batch: int, rng: np.random.Generator) -> np.ndarray:
    """The model's nominal values with its unknowns drawn log-uniformly within their bounds."""
    params = np.tile(model.nominal, (batch, 1))
    for i, name in enumerate(model.parameter_names):
        p = model.structure.parameter(name)
        if p.unknown and p.bounds is not None:
            low, high = p.bounds
            params[:, i] = low * (high / low) ** rng.uniform(size=batch)
    return params


def main() -> None:
    rng = np.random.default_rng(0)
    rows = []
    bed = bed_with_mass_scale()
    cases = [("rigid", chain(5), 1024, None), ("flexible", flexible_model(), 1024, None),
             ("rigid-120", chain(20), 256, None), ("flexible-bed", bed, 256, {"z": 0.135})]
    for label, model, batch, position in cases:
        if position is None:
            params = model.nominal * rng.uniform(0.7, 1.3, size=(batch, model.nominal.size))
        else:
            params = machine_params(model, batch, rng)
        engine = ModalEngine(model, n_workers=1, chunk_size=256)
        engine.evaluate(params[:2], position)  # compile caches
        t_engine = best(lambda: engine.evaluate(params, position))  # noqa: B023 (called inside the iteration)
        mats = model.matrices(params, position, names=("M", "K"))
        linv = np.linalg.inv(np.linalg.cholesky(mats["M"]))
        reduced = linv @ mats["K"] @ np.swapaxes(linv, 1, 2)
        with single_threaded_blas():
            t_bound = best(lambda: np.linalg.eigh(reduced))  # noqa: B023
        known = params.copy()  # the GSA's and the stiffness subproblems' case: masses (and s_m) nominal
        fixed = [i for i, name in enumerate(model.parameter_names)
                 if model.structure.parameter(name).kind in ("mass", "inertia") or name == "s_m"]
        known[:, fixed] = model.nominal[fixed]
        t_known = best(lambda: engine.evaluate(known, position))  # noqa: B023
        mats = model.matrices(known, position, names=("M", "K"))
        linv = np.linalg.inv(np.linalg.cholesky(mats["M"]))
        reduced_known = linv @ mats["K"] @ np.swapaxes(linv, 1, 2)
        with single_threaded_blas():
            t_bound_known = best(lambda: np.linalg.eigh(reduced_known))  # noqa: B023
            cpu_engine = best_cpu(lambda: engine.evaluate(known, position))  # noqa: B023
            cpu_bound = best_cpu(lambda: np.linalg.eigh(reduced_known))  # noqa: B023
        varied = varying_masses(model, params, rng)
        mats = model.matrices(varied, position, names=("M", "K"))
        linv = np.linalg.inv(np.linalg.cholesky(mats["M"]))
        reduced_varied = linv @ mats["K"] @ np.swapaxes(linv, 1, 2)
        with single_threaded_blas():
            cpu_varied = best_cpu(lambda: engine.evaluate(varied, position))  # noqa: B023
            cpu_bound_varied = best_cpu(lambda: np.linalg.eigh(reduced_varied))  # noqa: B023
        row = {"model": label, "n_dof": model.n_dof, "batch": batch, "engine_s": t_engine, "bound_s": t_bound,
               "fraction_of_bound": t_bound / t_engine, "evaluations_per_s": batch / t_engine,
               "engine_known_mass_s": t_known, "fraction_of_bound_known_mass": t_bound_known / t_known,
               "engine_known_mass_cpu_s": cpu_engine, "bound_known_mass_cpu_s": cpu_bound,
               "fraction_of_bound_known_mass_cpu": cpu_bound / cpu_engine,
               "engine_varying_mass_cpu_s": cpu_varied, "bound_varying_mass_cpu_s": cpu_bound_varied,
               "fraction_of_bound_varying_mass_cpu": cpu_bound_varied / cpu_varied}
        rows.append(row)
        print(f"{label:12s} n_dof {model.n_dof:3d} batch {batch}: {row['evaluations_per_s']:8.0f}/s, "
              f"{row['fraction_of_bound']:4.2f} of the eigh bound ({row['fraction_of_bound_known_mass']:4.2f} with "
              f"known masses; in CPU time {row['fraction_of_bound_known_mass_cpu']:4.2f}, varying masses "
              f"{row['fraction_of_bound_varying_mass_cpu']:4.2f}: {cpu_varied:.2f} against {cpu_bound_varied:.2f} "
              "CPU-s)")
    write_results("flexible", rows)


if __name__ == "__main__":
    main()
