"""Test planning on the uniaxial machine tool: the D-optimal plan against 10 random plans of the same size.

``cappe plan-test``'s plan (3 of the 4 axis positions, 12 of the 81 sensor channels, 20 modes) chosen at the nominal
values, and 10 random plans of the same size (the plan's own comparison, seed 0), are each judged twice:

* by the expected relative std of the 27 unknowns (the Fisher information, at the nominal values);
* by the identification error of a noisy simulated test: a random truth within the bounds (seed 1, as the README's
  example), exact modes at the plan's positions and channels with frequency / damping / shape noise 0.005 / 0.05 /
  0.02 (seed 2), identified by the automated pipeline (n_gsa 256, n_opt 20, noise-weighted refinement, every plan
  position used for identification). The error is ``|log(estimate / truth)|`` per unknown.

``python -m benchmarks.bench_plan`` (about 3 minutes on two cores).
"""

from __future__ import annotations

import time
import warnings
from typing import Any

import numpy as np

from benchmarks._common import write_results
from cappe.estimate import AutomatedIdentification, ParameterSpace
from cappe.estimate._plan import PlanCandidates, plan_test
from cappe.modal import reference_modes
from cappe.model import NumericModel, load_model

NOISE = (0.005, 0.05, 0.02)


def _identify(nm: NumericModel, truth: dict[str, float], positions: list[dict[str, float]],
              sensors: list[str]) -> np.ndarray:
    ref = reference_modes(nm, params=truth, positions=positions, sensors=sensors, n_modes=20,
                          noise_frequency=NOISE[0], noise_damping=NOISE[1], noise_shape=NOISE[2], rng=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est = AutomatedIdentification(nm, rng=0, n_gsa=256, n_opt=20, validation=None, noise=NOISE,
                                      n_permutations=0).fit(ref)
    return np.array([abs(np.log(est.params_[n] / truth[n])) for n in truth])


def main() -> None:
    nm = NumericModel(load_model("builtin:uniaxial-machine-tool"))
    space = ParameterSpace.from_model(nm)
    truth = space.mapping(space.sample(1))
    t0 = time.perf_counter()
    cands = PlanCandidates.from_model(nm, n_modes=20, noise=NOISE)
    plan = plan_test(candidates=cands, n_positions=3, n_sensors=12, n_random=10, rng=0)
    t_plan = time.perf_counter() - t0
    rows: list[dict[str, Any]] = []
    plans = [("chosen", list(plan.position_index), list(plan.sensor_index))]
    gen = np.random.default_rng(0)  # the same draws as plan_test's comparison
    for k in range(10):
        rp = sorted(gen.choice(len(cands.positions), 3, replace=False).tolist())
        rs = sorted(gen.choice(len(cands.sensors), 12, replace=False).tolist())
        plans.append((f"random {k}", rp, rs))
    for label, pos, sens in plans:
        rel = cands.uncertainty(pos, sens)
        std = np.where(rel.identifiable, rel.std / rel.values, np.inf)
        t1 = time.perf_counter()
        err = _identify(nm, truth, [dict(cands.positions[i]) for i in pos], [cands.sensors[i] for i in sens])
        rows.append({
            "plan": label, "positions": [cands.positions[i]["z"] for i in pos],
            "sensors": [cands.sensors[i] for i in sens], "criterion": cands.criterion(pos, sens),
            "median_std_pct": 100 * float(np.median(std)), "n_std_above_10pct": int(np.sum(~(std <= 0.1))),
            "median_error_pct": 100 * float(np.median(err)), "worst_error_pct": 100 * float(np.max(err)),
            "n_error_above_10pct": int(np.sum(err > 0.1)), "identify_s": time.perf_counter() - t1,
        })
        r = rows[-1]
        print(f"{label:>10}: log det {r['criterion']:7.1f}  median std {r['median_std_pct']:6.2f} %  "
              f"std > 10 %: {r['n_std_above_10pct']:2d}  median error {r['median_error_pct']:6.2f} %  "
              f"worst {r['worst_error_pct']:7.1f} %  error > 10 %: {r['n_error_above_10pct']:2d}")
    rows.append({"plan_s": t_plan})
    write_results("plan", rows)


if __name__ == "__main__":
    main()
