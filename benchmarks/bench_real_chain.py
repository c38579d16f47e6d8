"""A modal test rehearsed end to end on ``builtin:uniaxial-machine-tool``: foreign UFF 58 in, cappe commands only
(issue 20).

Per random truth (the 27 unknowns drawn log-uniform within their bounds):

1. **An independent FRF generator** (numpy, from the physics): at each of the four axis positions the model's
   M, C, G, K, H (what ``cappe model matrices`` prints) and the sensor rows give the accelerance
   ``A(w) = -w^2 S (K + iH + iw (C + G) - w^2 M)^-1 S_ref^T`` (hysteretic damping as ``K + iH``, a force at a sensor
   point in one direction is that sensor row transposed), on 0.25 Hz lines to 400 Hz, for 3 hammer references
   and 20 triaxial accelerometers (60 responses), each line times ``1 + 0.02 (a + ib) / sqrt(2)`` (a, b standard
   normal: 2 % complex noise). The modal machinery of cappe (engine, FRF kernel, extraction) plays no part.
2. **A foreign UFF 58 file** per position written with pyuff directly: integer nodes 1..20 in the order below,
   direction codes 1..3, and the accelerometers on the left side of the bed mounted upside down (code -2, data
   sign flipped, as a test engineer records them), no cappe ID lines. A sensor map ``channel,sensor`` names them.
3. **The chain**, subprocesses of the ``cappe`` command and nothing else: ``cappe extract-modes POS.uff --band
   15:365 --sensor-map map.csv --position z=... -o POS.json`` per position, then ``cappe identify MODEL
   --reference z1.json z2.json z3.json z4.json --validation z=-0.294 --truth truth.json -o result.json`` at its
   defaults (the truth only for the error table; the identification does not use it).

Reported per truth: stiffness and damping errors (worst, median), how many 95 % intervals cover the truth, the
chain's wall time, and the warnings the text output showed. Targets (issue 20): stiffness worst <= 3 %, median
<= 0.5 %, damping worst <= 25 %, coverage >= 90 %, chain <= 3 min.

``python -m benchmarks.bench_real_chain [RUNS] [--quick] [--keep=DIR] [--frf] [--reuse=DIR]`` (default 3 truths;
``--quick``: one truth, the identification at n_gsa 256, n_opt 20; ``--keep``: the files of every truth stay in
DIR/truthN; ``--frf``: ``identify --frf`` with the measured UFF files and without ``--truth``, so that the held-out
position is validated against its measured FRFs, ``results/real_chain_frf.json``; ``--reuse``: the files a
``--keep`` run left in DIR, without generating and extracting again).
``--seed=K --keep=DIR``: truth K alone, its row in DIR/truthK/row.json (truths side by side in separate processes);
``--combine=DIR [--frf]`` then writes the result file from those rows. CPU seconds of every command are reported
beside the wall times (the commands run with one BLAS thread), with the load average at the start and the end.
``--compare=DIR`` then measures realized against complex shapes in the final refinement on those files
(:func:`compare_shapes`, ``results/real_chain_shapes.json``).
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import pyuff

from benchmarks._common import write_results
from cappe.estimate import ParameterSpace
from cappe.model import NumericModel, load_model

MODEL = "builtin:uniaxial-machine-tool"
#: 20 triaxial accelerometers (the carriage shoes, the screw at the nut and two bed-side points left out)
SENSORS = ("bed1_l", "bed1_r", "bed2_r", "bed3_r", "bed4_l", "bed4_r", "me1_node", "me2_node", "me3_node",
           "table_fl", "table_fr", "table_rl", "table_rr", "nut", "screw_lb", "screw_fb", "journal", "rotor",
           "motor_rear", "motor_flange")
#: mounted upside down: their y channel is written with direction code -2 and the sign of its data flipped
FLIPPED = ("bed1_l", "bed4_l")
#: hammer references (sensor, direction)
REFERENCES = (("table_rr", "x"), ("table_rr", "z"), ("bed1_r", "y"))
NOISE = 0.02
LINES = np.arange(1, 1601) * 0.25  # Hz
BAND = "15:365"
HELD_OUT = "z=-0.294"
AXES = ("x", "y", "z")


def draw_truth(machine: NumericModel, seed: int) -> dict[str, float]:
    """The 27 unknowns log-uniform within their bounds (as in bench_automated)."""
    space = ParameterSpace.from_model(machine)
    rng = np.random.default_rng(seed)
    return space.mapping(space.lower * (space.upper / space.lower) ** rng.uniform(size=space.n))


def accelerance(machine: NumericModel, truth: dict[str, float], position: dict[str, float]) -> np.ndarray:
    """``A[out, in, line]`` (m/s^2 per N) at the 60 sensor channels for the 3 references, from the physics."""
    mats = machine.matrices(truth, position)
    labels, rows = machine.sensor_matrix(truth, position, sensors=SENSORS)
    s = np.asarray(rows)
    b = np.stack([s[labels.index(f"{node}:{d}")] for node, d in REFERENCES], axis=1)  # (n_dof, 3)
    stiff = mats["K"] + 1j * mats["H"]
    out = np.empty((s.shape[0], b.shape[1], LINES.size), dtype=complex)
    for k, f in enumerate(LINES):
        w = 2 * np.pi * f
        z = stiff + 1j * w * (mats["C"] + mats["G"]) - w**2 * mats["M"]
        out[:, :, k] = -(w**2) * (s @ np.linalg.solve(z, b))
    return out


def write_foreign_uff(path: Path, acc: np.ndarray, rng: np.random.Generator) -> None:
    """UFF 58 with integer nodes and direction codes, upside-down sensors negative, 2 % complex noise."""
    noisy = acc * (1 + NOISE * (rng.standard_normal(acc.shape) + 1j * rng.standard_normal(acc.shape)) / np.sqrt(2))
    sets = []
    for i, (ref, ref_dir) in enumerate(REFERENCES):
        for n, sensor in enumerate(SENSORS):
            for d, axis in enumerate(AXES):
                sign = -1 if sensor in FLIPPED and axis == "y" else 1
                sets.append({
                    "type": 58, "binary": 0, "func_type": 4, "id1": f"FRF {sensor} {axis}", "id2": "", "id3": "",
                    "id4": "", "id5": "", "rsp_node": n + 1, "rsp_dir": sign * (d + 1),
                    "ref_node": SENSORS.index(ref) + 1, "ref_dir": AXES.index(ref_dir) + 1,
                    "x": LINES, "data": sign * noisy[3 * n + d, i], "abscissa_spacing": 1,
                    "abscissa_spec_data_type": 18, "ordinate_spec_data_type": 12, "orddenom_spec_data_type": 13,
                    "ordinate_axis_units_lab": "m/s^2",
                })
    if path.exists():
        path.unlink()
    pyuff.UFF(str(path)).write_sets(sets, mode="add")


def write_sensor_map(path: Path) -> None:
    """``channel,sensor``: UFF ``NODE:±DIR`` to the model's sensor channel."""
    lines = ["channel,sensor"]
    for n, sensor in enumerate(SENSORS):
        for axis in AXES:
            sign = "-" if sensor in FLIPPED and axis == "y" else "+"
            lines.append(f"{n + 1}:{sign}{axis},{sensor}:{axis}")
    path.write_text("\n".join(lines) + "\n")


def _children_cpu() -> float:
    """CPU seconds (user + system) of the finished child processes so far."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def cappe(*argv: str) -> str:
    """One cappe command as a user runs it (with this checkout's sources first on the path), with one BLAS thread
    (the chain's commands run one after another; its CPU time is what it costs whatever the load)."""
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1] / "src"), "OPENBLAS_NUM_THREADS": "1",
           "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, "-m", "cappe", *argv], capture_output=True, text=True, env=env,
                          check=False)
    if done.returncode not in (0, 1):
        msg = f"cappe {' '.join(argv)} failed ({done.returncode}):\n{done.stderr[-3000:]}"
        raise RuntimeError(msg)
    return done.stdout + done.stderr


def run_truth(seed: int, work: Path, quick: bool, frf: bool = False, reuse: bool = False) -> dict[str, Any]:
    """Generate, write, extract and identify for one random truth; errors against it.

    ``frf``: identify with ``--frf`` (the measured UFF files of every position, the sensor map; no ``--truth``, so
    the held-out position is validated against its measured FRFs). ``reuse``: the UFF and modal files a ``--keep``
    run left in ``work`` (same seed) are used again; generation and extraction are skipped (``extract_s`` None).
    """
    structure = load_model(MODEL)
    machine = NumericModel(structure)
    truth = draw_truth(machine, seed)
    rng = np.random.default_rng(seed + 1000)
    positions = structure.axes[0].positions
    t_gen: float | None = None
    t_extract: float | None = None
    cpu_extract: list[float] = []
    load = [os.getloadavg()[0]]
    t0 = time.perf_counter()
    if not reuse:
        (work / "truth.json").write_text(json.dumps(truth))
        write_sensor_map(work / "map.csv")
        t_gen = time.perf_counter()
        for j, z in enumerate(positions):
            write_foreign_uff(work / f"z{j + 1}.uff", accelerance(machine, truth, {"z": z}), rng)
        t_gen = time.perf_counter() - t_gen
        t0 = time.perf_counter()
        for j, z in enumerate(positions):
            c0 = _children_cpu()
            cappe("extract-modes", str(work / f"z{j + 1}.uff"), "--band", BAND, "--sensor-map",
                  str(work / "map.csv"), "--position", f"z={z}", "-o", str(work / f"z{j + 1}.json"))
            cpu_extract.append(_children_cpu() - c0)
        t_extract = time.perf_counter() - t0
    extra = ["--n-gsa", "256", "--n-opt", "20"] if quick else []
    if frf:
        extra += ["--frf", *(str(work / f"z{j + 1}.uff") for j in range(len(positions))), "--sensor-map",
                  str(work / "map.csv")]
    else:
        extra += ["--truth", str(work / "truth.json")]
    result = work / ("result_frf.json" if frf else "result.json")  # both stay side by side in a kept folder
    t_identify, c0 = time.perf_counter(), _children_cpu()
    text = cappe("identify", MODEL, "--reference", *(str(work / f"z{j + 1}.json") for j in range(len(positions))),
                 "--validation", HELD_OUT, "--permutations", "0", "-o", str(result), *extra)
    t_identify, cpu_identify = time.perf_counter() - t_identify, _children_cpu() - c0
    t_chain = time.perf_counter() - t0
    load.append(os.getloadavg()[0])
    (work / ("identify_frf.txt" if frf else "identify.txt")).write_text(text)
    doc = json.loads(result.read_text())
    kinds = {n: structure.parameter(n).kind for n in truth}
    errors = {n: 100 * (doc["parameters"][n] / truth[n] - 1) for n in truth}
    ci = doc["uncertainty"]["ci95"]
    covered = {n: bool(ci[n][0] <= truth[n] <= ci[n][1]) for n in truth}
    stiff = [abs(errors[n]) for n in truth if kinds[n] == "stiffness"]
    damp = [abs(errors[n]) for n in truth if kinds[n] != "stiffness"]
    n_modes = [len(json.loads((work / f"z{j + 1}.json").read_text())["sets"][0]["frequency"])
               for j in range(len(positions))]
    return {
        "seed": seed, "stiffness_worst_pct": max(stiff), "stiffness_median_pct": float(np.median(stiff)),
        "damping_worst_pct": max(damp), "damping_median_pct": float(np.median(damp)),
        "covered": int(sum(covered.values())), "n_unknowns": len(covered),
        "not_covered": sorted(n for n, c in covered.items() if not c),
        "negative_lower_bounds": sorted(n for n in truth if ci[n][0] < 0),
        "modes_extracted": n_modes, "generate_s": t_gen, "extract_s": t_extract, "identify_s": t_identify,
        "chain_s": t_chain, "frf": frf,
        "cpu_extract_s": cpu_extract, "cpu_identify_s": cpu_identify,
        "cpu_chain_s": (sum(cpu_extract) if cpu_extract else float("nan")) + cpu_identify,
        "cpu_identify_stages_s": doc["diagnostics"].get("cpu_timings"),
        "wall_identify_stages_s": doc["diagnostics"].get("timings"), "load_start_end": load,
        "warnings": [line for line in text.splitlines() if "warning" in line.lower()],
        "validation": doc["diagnostics"]["validation"]["validation"]["statistics"],
        "validation_source": doc["diagnostics"]["validation"]["validation"]["frf_source"],
        "chi2_dof": (doc["diagnostics"].get("frf_refinement") or {}).get("chi2_dof"),
        "errors_pct": errors,
    }


def compare_shapes(work: Path) -> dict[str, Any]:
    """Item 2 of issue 20 measured: the final refinement alone, from the pipeline's after-damping start on the
    same extracted modes, with realized and with complex shapes (reweighted twice, as ``identify`` does)."""
    from cappe.cli.identify import combined_reference
    from cappe.estimate._automated_steps import robust_uncertainty
    from cappe.estimate._base import least_squares_fit
    from cappe.estimate._exact_modal import ExactModalProblem

    machine = NumericModel(load_model(MODEL))
    doc = json.loads((work / "result.json").read_text())
    truth = json.loads((work / "truth.json").read_text())
    ident = [p for p in sorted(work.glob("z*.json")) if json.loads(p.read_text())["sets"][0]["position"]["z"]
             != float(HELD_OUT.split("=")[1])]
    reference, _ = combined_reference([str(p) for p in ident])
    space = ParameterSpace.from_model(machine)
    true = np.array([truth[n] for n in space.names])
    start = np.array([doc["diagnostics"]["stages"]["after_damping_least_squares"][n] for n in space.names])
    kinds = [machine.structure.parameter(n).kind for n in space.names]
    out: dict[str, Any] = {}
    for shapes in ("real", "complex"):
        problem = ExactModalProblem(machine, space, reference, (1.0, 0.01, 1.0), shapes=shapes)
        p = start
        for k in range(3):
            if k:
                problem.reweight(p)
            est = least_squares_fit("t", space, problem.residuals, problem.jacobian,
                                    starts=np.clip(p, space.lower, space.upper)[None, :]).estimate
            p = np.asarray(est.values, dtype=float)
        est = robust_uncertainty(est, problem.jacobian(p), problem.residuals(p), problem.groups())
        err = np.abs(100 * (p / true - 1))
        stiff = [e for e, k in zip(err, kinds, strict=True) if k == "stiffness"]
        damp = [e for e, k in zip(err, kinds, strict=True) if k != "stiffness"]
        out[shapes] = {"stiffness_worst_pct": max(stiff), "stiffness_median_pct": float(np.median(stiff)),
                       "damping_worst_pct": max(damp), "damping_median_pct": float(np.median(damp)),
                       "covered": int(np.sum((est.ci95[:, 0] <= true) & (true <= est.ci95[:, 1])))}
    return out


def main(argv: list[str]) -> dict[str, Any]:
    compare = next((a.split("=", 1)[1] for a in argv if a.startswith("--compare=")), None)
    if compare is not None:  # the shape comparison on the files a --keep run left
        rows = []
        for work in sorted(Path(compare).glob("truth*")):
            rows.append({"truth": work.name, **compare_shapes(work)})
            print(json.dumps(rows[-1]), flush=True)
        write_results("real_chain_shapes", rows)
        return {"runs": rows}
    frf = "--frf" in argv
    combine = next((a.split("=", 1)[1] for a in argv if a.startswith("--combine=")), None)
    if combine is not None:  # the truths that --seed runs left in one folder, as one result file
        results = [json.loads(p.read_text()) for p in sorted(Path(combine).glob("truth*/row.json"))]
        summary = summarize(results)
        print("summary:", json.dumps(summary))
        write_results("real_chain_frf" if frf else "real_chain", [*results, {"summary": summary}])
        return {"runs": results, "summary": summary}
    quick = "--quick" in argv
    numbers = [a for a in argv if not a.startswith("-")]
    runs = 1 if quick and not numbers else int(numbers[0]) if numbers else 3
    keep = next((a.split("=", 1)[1] for a in argv if a.startswith("--keep=")), None)
    reuse = next((a.split("=", 1)[1] for a in argv if a.startswith("--reuse=")), None)
    one = next((int(a.split("=", 1)[1]) for a in argv if a.startswith("--seed=")), None)
    results = []
    for seed in range(runs) if one is None else [one]:
        with tempfile.TemporaryDirectory() as tmp:
            folder = keep if reuse is None else reuse
            work = Path(tmp) if folder is None else Path(folder) / f"truth{seed}"
            work.mkdir(parents=True, exist_ok=True)
            r = run_truth(seed, work, quick, frf=frf, reuse=reuse is not None)
            if one is not None:
                (work / "row.json").write_text(json.dumps(r))
        results.append(r)
        print(f"truth {seed}: stiffness worst {r['stiffness_worst_pct']:.2f} % "
              f"median {r['stiffness_median_pct']:.2f} %,"
              f" damping worst {r['damping_worst_pct']:.1f} % median {r['damping_median_pct']:.1f} %, covered "
              f"{r['covered']}/{r['n_unknowns']} (missed {r['not_covered']}), modes {r['modes_extracted']}, "
              f"identify {r['identify_s']:.0f} s, extract {r['extract_s'] or float('nan'):.0f} s (CPU: identify "
              f"{r['cpu_identify_s']:.0f} s, extract {sum(r['cpu_extract_s']):.0f} s, load {r['load_start_end']}), "
              f"warnings {len(r['warnings'])}, held-out FRAC worst "
              f"{100 * r['validation']['frac']['worst']:.1f} % ({r['validation_source']}), chi2/dof {r['chi2_dof']}")
        for line in r["warnings"]:
            print("   ", line)
    summary = summarize(results)
    print("summary:", json.dumps(summary))
    if not quick and one is None:
        write_results("real_chain_frf" if frf else "real_chain", [*results, {"summary": summary}])
    return {"runs": results, "summary": summary}


def summarize(results: list[dict[str, Any]]) -> dict[str, Any]:
    """Worst and median errors, coverage, and the chain's wall and CPU time over the truths."""
    return {
        "stiffness_worst_pct": max(r["stiffness_worst_pct"] for r in results),
        "stiffness_median_pct": float(np.median([r["stiffness_median_pct"] for r in results])),
        "damping_worst_pct": max(r["damping_worst_pct"] for r in results),
        "coverage": sum(r["covered"] for r in results) / sum(r["n_unknowns"] for r in results),
        "chain_s_max": max(r["chain_s"] for r in results),
        "identify_s_max": max(r["identify_s"] for r in results),
        "cpu_chain_s_max": max(r["cpu_chain_s"] for r in results),
    }


if __name__ == "__main__":
    main(sys.argv[1:])
