"""The stiffness subproblems' batched Levenberg-Marquardt against scipy's trust-region reflective least squares.

One subproblem of ``cappe identify`` on ``builtin:uniaxial-machine-tool`` (45 DOF, 27 unknowns): reference mode 7
at z = -0.06 m (exact modes of a seeded random truth), searched over 7 stiffness unknowns from ``n_opt`` random
starts, every other unknown drawn at random in its bounds per run (the paper's brute force), objective
``NFD^2 + (1 - MAC)`` of the MACXP-paired mode with its analytic Jacobian. Timed: the batched projected
Levenberg-Marquardt of :func:`cappe.estimate.solve_subproblem` (every iteration one batched eigen solution of all
active runs) and :func:`cappe.estimate.fit_least_squares` (scipy, one run after the other, the same residuals and
Jacobian, at most 50 evaluations as the batch has at most 50 iterations), BLAS on one thread as in the pipeline.
Reported: seconds of each, their ratio (measured in the same run) and the median final cost of each.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from benchmarks._common import write_results
from cappe.estimate import ParameterSpace, fit_least_squares, solve_subproblem
from cappe.estimate._subproblems import _mode_problem
from cappe.modal import ModalEngine, reference_modes
from cappe.model import NumericModel, load_model
from cappe.parallel import single_threaded_blas

NAMES = ["me1_kx", "me1_ky", "me2_ky", "me3_ky", "lgs_kx", "lgs_ky", "bsd_kz"]
SET_INDEX, MODE = 1, 6  # z = -0.06 m, reference mode 7


def _case(n_opt: int) -> dict[str, Any]:
    nm = NumericModel(load_model("builtin:uniaxial-machine-tool"))
    space = ParameterSpace.from_model(nm)
    rng = np.random.default_rng(5)
    truth = space.mapping(space.lower * (space.upper / space.lower) ** rng.uniform(size=space.n))
    reference = reference_modes(nm, params=nm.structure.resolve_parameters(truth), positions="all", n_modes=20)
    idx = [space.names.index(n) for n in NAMES]
    lo, hi = space.lower[idx], space.upper[idx]
    lo_u, hi_u = space.internal_bounds()
    starts = space.full(space.from_internal(np.random.default_rng(0).uniform(lo_u, hi_u, size=(n_opt, space.n))))
    engine = ModalEngine(nm, sensors=list(reference.sensors))
    position = nm.structure.resolve_position(reference.sets[SET_INDEX].position)
    cols = np.array([nm.parameter_names.index(n) for n in NAMES])
    engine.evaluate(starts[:1], position)  # the per-position caches, as the pipeline warms them
    with single_threaded_blas():
        t = time.perf_counter()
        _, cost, iterations = solve_subproblem(model=nm, reference=reference, set_index=SET_INDEX, mode=MODE,
                                               parameters=NAMES, start=starts, lower=lo, upper=hi, engine=engine)
        batched = time.perf_counter() - t
        problem = _mode_problem(engine, position, reference.sets[SET_INDEX], MODE, cols, (1.0, 1.0))
        t = time.perf_counter()
        costs = []
        for base in starts:
            sub = ParameterSpace.from_model(
                nm, NAMES, bounds={n: (a, b) for n, a, b in zip(NAMES, lo, hi, strict=True)},
                start={n: float(np.clip(base[c], a, b)) for n, c, a, b in zip(NAMES, cols, lo, hi, strict=True)},
                values=dict(zip(nm.parameter_names, base, strict=True)))

            def run(p: np.ndarray, base: np.ndarray = base) -> tuple[np.ndarray, np.ndarray]:
                q = base.copy()
                q[cols] = p
                return problem(q[None, :])

            est = fit_least_squares("subproblem", sub, lambda p, run=run: run(p)[0][0],
                                    lambda p, run=run: run(p)[1][0], max_nfev=50)
            costs.append(est.cost)
        scipy_s = time.perf_counter() - t
    return {"n_opt": n_opt, "batched_lm_s": batched, "batched_iterations": iterations, "scipy_trf_s": scipy_s,
            "ratio": scipy_s / batched, "cost_median_batched": float(np.median(cost)),
            "cost_median_scipy": float(np.median(costs))}


def main() -> None:
    rows = [_case(n) for n in (20, 100)]
    for r in rows:
        print(f"subproblem, n_opt = {r['n_opt']}: batched LM {r['batched_lm_s']:.3f} s ({r['batched_iterations']} "
              f"iterations), scipy trf {r['scipy_trf_s']:.3f} s -> {r['ratio']:.1f}x; median cost "
              f"{r['cost_median_batched']:.4g} / {r['cost_median_scipy']:.4g}")
    write_results("subproblem", rows)


if __name__ == "__main__":
    main()
