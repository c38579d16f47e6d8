"""Are the monitoring chain's stated probabilities and size intervals what they claim, on an independent generator?

The hammer chain of README step 9 (3 hammer inputs, 6 outputs, 150-1000 Hz) learns its baseline from one healthy
day of :class:`benchmarks._spindle_generator.ShopFloor` (numpy physics of its own: cold starts, warm-up, a lagging
temperature sensor, log-normal FRF errors; optionally a machine 3 % heavier and 30 % more damped than the model).
Then, per trial, a fault of random kind (each component, or the preload) and random size (log-uniform from
``SMALLEST`` to ``LARGEST``) appears after two healthy measurements; at the first alarm (within 6 faulty
measurements) the diagnosis's stated numbers are compared with the truth:

- **size intervals**: the fraction of the 95 % intervals (``change +- 1.96 change_std``) that cover the true relative
  change, over the trials whose diagnosis named the true fault (target 95 % +- the binomial 2-sigma of the count);
- **probabilities**: every hypothesis's stated posterior against whether it is the truth, in bins (a reliability
  diagram: in each bin the mean stated probability and the observed frequency, with its binomial standard error).

The constants of the size term (``SIZE_SCALE_FLOOR``, ``MODEL_OFFSET_FACTOR`` in cappe/monitor/_baseline.py) were
chosen on a run with seed 1; the default seed 2 checks them on fresh data.

Small faults are where the diagnosis is least sure of itself: ``LARGEST`` (default 0.4) fills the reliability
diagram's middle bins, which the full range leaves at 1 to 3 cases each.

``python -m benchmarks.bench_calibration [exact|mismatch] [TRIALS] [SEED] [LARGEST]`` writes
``benchmarks/results/calibration_<case>.json`` (``calibration_<case>_upto<LARGEST>.json`` for another largest size).
"""

from __future__ import annotations

import sys
import time
from typing import Any

import numpy as np

from benchmarks._common import write_results
from benchmarks._spindle_generator import ShopFloor
from cappe.model import NumericModel, load_model
from cappe.monitor import Monitor, default_config
from cappe.parallel import blas_threads

OUTPUTS = ["sx", "sy", "hax", "hay", "haz", "htax"]
FAULTS = ("front", "rear", "screw1", "screw2", "screw3", "screw4", "preload")
SMALLEST, LARGEST = 0.002, 0.4
BINS = (0.0, 0.05, 0.2, 0.4, 0.6, 0.8, 0.95, 1.0001)
CASES = {"exact": {"mass_error": 0.0, "damping_factor": 1.0}, "mismatch": {"mass_error": 0.03, "damping_factor": 1.3}}


def setup(case: str, seed: int = 1, sensor_lag: float = 0.5, rates: bool = False) -> tuple[Monitor, ShopFloor, Any]:
    """The chain, the generator and a baseline learned from one healthy day of it (with ``rates``: the
    conditions' rates of change from the measurements' times are candidate terms)."""
    model = NumericModel(load_model("builtin:spindle-bearing"))
    config = default_config(model, machine="spindle-01", source="builtin:spindle-bearing", outputs=OUTPUTS,
                            band=(150.0, 1000.0))
    monitor = Monitor(config, model)
    floor = ShopFloor(config, model, rng=np.random.default_rng(seed), sensor_lag=sensor_lag, **CASES[case])
    day = floor.run(96)
    baseline = monitor.learn_baseline([monitor.analyse(m.frf, modal=False) for m in day],
                                      conditions=[m.conditions for m in day], frfs=[m.frf for m in day],
                                      timestamps=[m.timestamp for m in day] if rates else None)
    return monitor, floor, baseline


def first_alarm(monitor: Monitor, baseline: Any, data: list[Any]) -> tuple[int, Any] | None:
    """Index and alarm of the first alarm over ``data`` (a fresh chart), None without one."""
    state = None
    for k, m in enumerate(data):
        if baseline.judge(m.conditions)[0]:
            continue
        analysis = monitor.analyse(m.frf, baseline=baseline, modal=False)
        state, _, alarms = monitor.step(state, analysis, m.conditions, baseline)
        if alarms:
            return k, alarms[0]
    return None


def trials(monitor: Monitor, floor: ShopFloor, baseline: Any, n: int, rng: np.random.Generator,
           largest: float = LARGEST) -> list[dict]:
    """``n`` fault trials (see the module notes; sizes up to ``largest``); one row each."""
    rows = []
    for t in range(n):
        fault = FAULTS[t % len(FAULTS)]
        loss = float(np.exp(rng.uniform(np.log(SMALLEST), np.log(largest))))
        data = floor.run(8, fault=fault, loss=loss, fault_at=2)
        found = first_alarm(monitor, baseline, data)
        if found is None or found[0] < 2:
            rows.append({"fault": fault, "loss": loss, "detected_at": None if found is None else found[0] - 2})
            continue
        k, alarm = found
        d = alarm.diagnosis
        rows.append({"fault": fault, "loss": loss, "detected_at": k - 2, "hypothesis": d.hypothesis,
                     "change": d.change, "change_std": d.change_std, "candidates": d.candidates,
                     "covered": bool(abs(d.change + loss) <= 1.96 * d.change_std) if d.hypothesis == fault else None})
    return rows


def summarize(rows: list[dict]) -> dict[str, Any]:
    """Coverage of the size intervals and the reliability diagram of the probabilities."""
    named = [r for r in rows if r.get("covered") is not None]
    covered = sum(r["covered"] for r in named)
    stated, truth = [], []
    for r in rows:
        for name, p in r.get("candidates", {}).items():
            stated.append(p)
            truth.append(name == r["fault"])
    p, y = np.array(stated), np.array(truth, dtype=float)
    diagram = []
    for lo, hi in zip(BINS[:-1], BINS[1:], strict=True):
        inside = (p >= lo) & (p < hi)
        if inside.any():
            mean, freq, count = float(p[inside].mean()), float(y[inside].mean()), int(inside.sum())
            diagram.append({"bin": [lo, min(hi, 1.0)], "stated": mean, "observed": freq, "count": count,
                            "se": float(np.sqrt(max(mean * (1 - mean), 1e-12) / count))})
    errors = [abs(r["change"] + r["loss"]) / r["change_std"] for r in named]
    return {"trials": len(rows), "detected": sum(r["detected_at"] is not None for r in rows),
            "named_true_fault": len(named), "covered_95": covered,
            "coverage_95": covered / max(len(named), 1),
            "tolerance_95": 2 * np.sqrt(0.95 * 0.05 / max(len(named), 1)),
            "median_abs_error_in_std": float(np.median(errors)) if errors else None,
            "reliability": diagram}


def main() -> None:
    with blas_threads(1):
        case = sys.argv[1] if len(sys.argv) > 1 else "exact"
        n = int(sys.argv[2]) if len(sys.argv) > 2 else 140
        seed = int(sys.argv[3]) if len(sys.argv) > 3 else 2
        largest = float(sys.argv[4]) if len(sys.argv) > 4 else LARGEST
        t0, c0 = time.perf_counter(), time.process_time()
        monitor, floor, baseline = setup(case, seed=seed)
        rows = trials(monitor, floor, baseline, n, np.random.default_rng(100 + seed), largest)
        summary = summarize(rows)
        summary.update({"case": case, **CASES[case], "seed": seed, "largest": largest,
                        "size_scale_std": baseline.size_scale_std,
                        "wall_s": time.perf_counter() - t0,
                        "cpu_s": time.process_time() - c0})
        print(f"{case}: {summary['detected']}/{summary['trials']} detected, true fault named "
              f"{summary['named_true_fault']}, 95 % size intervals cover {summary['covered_95']} "
              f"({100 * summary['coverage_95']:.1f} % +- {100 * summary['tolerance_95']:.1f} %), median |error| "
              f"{summary['median_abs_error_in_std']:.2g} std")
        for b in summary["reliability"]:
            print(f"  stated {b['bin'][0]:.2f}-{b['bin'][1]:.2f}: mean {b['stated']:.3f}, observed "
                  f"{b['observed']:.3f} +- {b['se']:.3f} ({b['count']})")
        print(f"wall {summary['wall_s']:.0f} s, cpu {summary['cpu_s']:.0f} s")
        name = f"calibration_{case}" if largest == LARGEST else f"calibration_{case}_upto{largest:g}"
        print(f"wrote {write_results(name, [summary, *rows])}")


if __name__ == "__main__":
    main()
