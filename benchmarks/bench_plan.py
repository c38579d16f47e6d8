"""Test planning on the uniaxial machine tool: the D-optimal plan against 10 random plans of the same size.

``cappe plan-test``'s plan (3 of the 4 axis positions, 12 of the 81 sensor channels, 20 modes) chosen at the nominal
values, and 10 random plans of the same size (the plan's own comparison, seed 0), are each judged twice:

* by the expected relative std of the 27 unknowns (the Fisher information, at the nominal values);
* by the identification error of a noisy simulated test: a random truth within the bounds (seed 1, as the README's
  example), exact modes at the plan's positions and channels with frequency / damping / shape noise 0.005 / 0.05 /
  0.02 (seed 2), identified by the automated pipeline (n_gsa 256, n_opt 20, noise-weighted refinement, every plan
  position used for identification). The error is ``|log(estimate / truth)|`` per unknown.

``python -m benchmarks.bench_plan`` (about 3 minutes on two cores).

On ``builtin:three-axis-machine-tool`` (4 of 27 positions, 24 of 117 channels, 25 modes, 61 unknowns):

* ``python -m benchmarks.bench_plan speed``: the search before and after the per-position Fisher cache, in one run
  (the search as it was, on :meth:`PlanCandidates.criterion`, is kept below as the reference); CPU and wall seconds,
  and whether both return the same plan (``results/plan_speed.json``).
* ``python -m benchmarks.bench_plan three-axis``: the plan against the 10 random plans of its own comparison, by
  expected std and by the identification error of noisy simulated tests (``results/plan_three_axis.json``). The
  data come from an independent generator: numpy's ``eig`` of the state-space matrix of M, C, K + iH (what
  ``cappe model matrices`` prints, through ``NumericModel.matrices``) at a random truth within the bounds (seed 1):
  the 25 lowest complex modes, each kept where the plan's channels see it (the plan's visibility rule, 0.05),
  with the noise plan-test assumes (frequency, damping ratio, complex shape noise relative to the largest measured
  component: 0.005 / 0.05 / 0.02) in ``N_DRAWS`` draws per plan. Each test is estimated by a LOCAL fit of all
  61 unknowns: ``least_squares_fit`` (scipy's trust-region least squares in log-parameters, within the model's
  bounds, at most 12 evaluations: converged, a continuation moves nothing) on the residuals of ``cappe
  identify``'s joint refinement (``ExactModalProblem``: exact complex modes, weighted by the same noise), started at
  the truth times ``exp(0.05 e)``. It measures the local error each plan leaves, not the global search's
  (``cappe identify``'s GSA and subproblems are not run). Its empirical error is compared with the expected std at
  the truth (the Cramer-Rao value the data's point has; plan-test reports it at the nominal values).
"""

from __future__ import annotations

import itertools
import os
import sys
import time
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

from benchmarks._common import state_matrix_modes, write_results
from cappe.estimate import AutomatedIdentification, ParameterSpace, least_squares_fit
from cappe.estimate._exact_modal import ExactModalProblem
from cappe.estimate._plan import PlanCandidates, plan_test
from cappe.modal import reference_modes
from cappe.model import NumericModel, load_model
from cappe.systems.modal import ModalData, ModalDataSet

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


def _reference_search(cands: PlanCandidates, n_positions: int, n_sensors: int) -> tuple[list[int], list[int]]:
    """The search as it was before the Fisher cache: every trial plan's Jacobian built anew (greedy, then exchange)."""

    def greedy(score: Callable[[list[int]], float], pool: list[int], size: int) -> list[int]:
        chosen: list[int] = []
        while len(chosen) < size:
            rest = [i for i in pool if i not in chosen]
            chosen.append(rest[int(np.argmax([score([*chosen, i]) for i in rest]))])
        return chosen

    def exchange(score: Callable[[list[int]], float], chosen: list[int], pool: list[int]) -> tuple[list[int], bool]:
        improved, current = False, score(chosen)
        while True:
            best, best_value = None, current
            for k, i in itertools.product(range(len(chosen)), pool):
                if i in chosen:
                    continue
                trial = [*chosen[:k], i, *chosen[k + 1:]]
                value = score(trial)
                if value > best_value + 1e-9 * max(1.0, abs(best_value)):
                    best, best_value = trial, value
            if best is None:
                return chosen, improved
            chosen, current, improved = best, best_value, True

    all_pos, all_ch = list(range(len(cands.positions))), list(range(len(cands.sensors)))
    positions = greedy(lambda p: cands.criterion(p, all_ch), all_pos, n_positions)
    sensors = greedy(lambda s: cands.criterion(positions, s), all_ch, n_sensors)
    for _ in range(10):
        positions, moved_p = exchange(lambda p, s=sensors: cands.criterion(p, s), positions, all_pos)
        sensors, moved_s = exchange(lambda s, p=positions: cands.criterion(p, s), sensors, all_ch)
        if not (moved_p or moved_s):
            break
    return sorted(positions), sorted(sensors)


def _timed(func: Callable[[], Any]) -> tuple[Any, float, float]:
    wall, cpu = time.perf_counter(), time.process_time()
    out = func()
    return out, time.perf_counter() - wall, time.process_time() - cpu


def speed() -> None:
    """The three-axis plan's search before and after the per-position Fisher cache, in one run."""
    load = os.getloadavg()
    nm = NumericModel(load_model("builtin:three-axis-machine-tool"))
    cands, wall_c, cpu_c = _timed(lambda: PlanCandidates.from_model(nm, n_modes=25, noise=NOISE))
    print(f"derivatives at {len(cands.positions)} positions, {len(cands.sensors)} channels, 25 modes, "
          f"{len(cands.unknowns)} unknowns: {wall_c:.1f} s wall, {cpu_c:.1f} s CPU", flush=True)
    plan, wall_a, cpu_a = _timed(lambda: plan_test(candidates=cands, n_positions=4, n_sensors=24, n_random=0))
    print(f"after (cached blocks): {wall_a:.1f} s wall, {cpu_a:.1f} s CPU, log det {plan.criterion:.2f}", flush=True)
    (pos, sens), wall_b, cpu_b = _timed(lambda: _reference_search(cands, 4, 24))
    before = cands.criterion(pos, sens)
    same = pos == list(plan.position_index) and sens == list(plan.sensor_index)
    print(f"before (a Jacobian per trial): {wall_b:.1f} s wall, {cpu_b:.1f} s CPU, log det {before:.2f}; "
          f"same plan: {same}; CPU speed-up {cpu_b / cpu_a:.1f}x; load {load[0]:.1f} -> {os.getloadavg()[0]:.1f}")
    write_results("plan_speed", [{
        "model": "three-axis-machine-tool", "n_positions": 4, "n_sensors": 24, "n_modes": 25,
        "candidates": [len(cands.positions), len(cands.sensors)], "unknowns": len(cands.unknowns),
        "derivatives_wall_s": wall_c, "derivatives_cpu_s": cpu_c,
        "before_wall_s": wall_b, "before_cpu_s": cpu_b, "before_log_det": before,
        "after_wall_s": wall_a, "after_cpu_s": cpu_a, "after_log_det": plan.criterion, "same_plan": same,
        "positions": pos, "sensors": sens, "load_before": load[0], "load_after": os.getloadavg()[0],
    }])


N_DRAWS = 2
START_SPREAD = 0.05


class _Rehearsal:
    """Noisy simulated tests of one plan from the independent generator, and their local estimates."""

    def __init__(self, nm: NumericModel, truth: dict[str, float], positions: list[dict[str, float]],
                 sensors: list[str], all_sensors: list[str]) -> None:
        self.nm, self.positions, self.sensors = nm, positions, sensors
        self.modes = [_generator_modes(nm, truth, p, all_sensors, sensors) for p in positions]

    def data(self, rng: np.random.Generator) -> ModalData:
        """One noisy test (cappe.modal/1 data at the plan's positions and channels), noise as plan-test assumes."""
        sets = []
        for position, (freq, zeta, shapes) in zip(self.positions, self.modes, strict=True):
            f = freq * (1 + NOISE[0] * rng.standard_normal(freq.size))
            z = zeta * (1 + NOISE[1] * rng.standard_normal(zeta.size))
            e = rng.standard_normal((2, *shapes.shape))
            scale = NOISE[2] * np.max(np.abs(shapes), axis=0) / np.sqrt(2)
            sets.append(ModalDataSet(dict(position), f, z, shapes + scale[None, :] * (e[0] + 1j * e[1])))
        return ModalData(tuple(self.sensors), tuple(sets), self.nm.structure.name)

    def fit(self, space: ParameterSpace, data: ModalData, start: np.ndarray) -> np.ndarray:
        """Local estimate of every unknown: identify's exact-mode residuals, trust-region least squares."""
        problem = ExactModalProblem(self.nm, space, data, (1.0, 1.0, 1.0), noise=NOISE, n_modes=28)
        fitted = least_squares_fit("rehearsal", space, problem.residuals, problem.jacobian, starts=start[None, :],
                                   x_scale=1.0, max_nfev=12)
        return space.vector(fitted.estimate.parameters)


def _generator_modes(nm: NumericModel, truth: dict[str, float], position: dict[str, float], all_sensors: list[str],
                     sensors: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The 25 lowest complex modes of the state matrix (benchmarks._common.state_matrix_modes), those the
    plan's channels see (largest component at least 0.05 of the largest over every candidate channel)."""
    lam, vec = state_matrix_modes(nm.matrices(truth, position), 25)
    labels, rows = nm.sensor_matrix(truth, position)
    every = np.asarray(rows)[[labels.index(s) for s in all_sensors]] @ vec
    mine = np.asarray(rows)[[labels.index(s) for s in sensors]] @ vec
    seen = np.max(np.abs(mine), axis=0) >= 0.05 * np.max(np.abs(every), axis=0)
    lam = lam[seen]
    return np.abs(lam) / (2 * np.pi), -lam.real / np.abs(lam), mine[:, seen]


def three_axis() -> None:
    """The three-axis plan against 10 random plans: expected std and local identification error of noisy tests."""
    load = os.getloadavg()
    nm = NumericModel(load_model("builtin:three-axis-machine-tool"))
    space = ParameterSpace.from_model(nm)
    truth = space.mapping(space.sample(1))
    t_true = space.vector(truth)
    cands = PlanCandidates.from_model(nm, n_modes=25, noise=NOISE)
    plan = plan_test(candidates=cands, n_positions=4, n_sensors=24, n_random=10, rng=0)
    at_truth = PlanCandidates.from_model(nm, params=truth, n_modes=25, noise=NOISE)
    determinable = np.array([n not in plan.undetermined_with_all for n in cands.unknowns])
    plans = [("chosen", list(plan.position_index), list(plan.sensor_index))]
    gen = np.random.default_rng(0)  # the same draws as plan_test's comparison
    for k in range(10):
        rp = sorted(gen.choice(len(cands.positions), 4, replace=False).tolist())
        rs = sorted(gen.choice(len(cands.sensors), 24, replace=False).tolist())
        plans.append((f"random {k}", rp, rs))
    rows: list[dict[str, Any]] = []
    for label, pos, sens in plans:
        wall, cpu = time.perf_counter(), time.process_time()
        unc = cands.uncertainty(pos, sens)
        std = np.where(unc.identifiable, unc.std / unc.values, np.inf)
        unc_t = at_truth.uncertainty(pos, sens)
        std_t = np.where(unc_t.identifiable, unc_t.std / unc_t.values, np.inf)
        own = std <= 0.1
        rehearsal = _Rehearsal(nm, truth, [dict(cands.positions[i]) for i in pos],
                               [cands.sensors[i] for i in sens], list(cands.sensors))
        errors = []
        for draw in range(N_DRAWS):
            rng = np.random.default_rng([2, draw])
            start = t_true * np.exp(START_SPREAD * rng.standard_normal(t_true.size))
            errors.append(np.log(rehearsal.fit(space, rehearsal.data(rng), start) / t_true))
        err = np.array(errors)  # (draws, n_p)
        z = err[:, own & np.isfinite(std_t)] / std_t[own & np.isfinite(std_t)]
        rows.append({
            "plan": label, "positions": [cands.positions[i] for i in pos], "sensors": [cands.sensors[i] for i in sens],
            "criterion": cands.criterion(pos, sens),
            "median_std_pct": 100 * float(np.median(std)),
            "median_std_determinable_pct": 100 * float(np.median(std[determinable])),
            "median_std_determinable_at_truth_pct": 100 * float(np.median(std_t[determinable])),
            "n_determined": int(np.sum(own)),
            "median_error_determinable_pct": 100 * float(np.median(np.abs(err[:, determinable]))),
            "worst_error_determinable_pct": 100 * float(np.max(np.abs(err[:, determinable]))),
            "median_error_own_pct": 100 * float(np.median(np.abs(err[:, own]))),
            "worst_error_own_pct": 100 * float(np.max(np.abs(err[:, own]))),
            "rms_error_over_expected_std": float(np.sqrt(np.mean(z**2))),
            "median_abs_error_over_expected_std": float(np.median(np.abs(z))),
            "cpu_s": time.process_time() - cpu, "wall_s": time.perf_counter() - wall,
        })
        r = rows[-1]
        print(f"{label:>10}: log det {r['criterion']:6.1f}  median std {r['median_std_pct']:5.2f} % (determinable "
              f"{r['median_std_determinable_pct']:5.2f} %)  determined {r['n_determined']:2d}  error median/worst "
              f"{r['median_error_determinable_pct']:5.2f}/{r['worst_error_determinable_pct']:6.1f} % (own "
              f"{r['median_error_own_pct']:5.2f}/{r['worst_error_own_pct']:6.1f} %)  rms error/std "
              f"{r['rms_error_over_expected_std']:4.2f}  ({r['cpu_s']:.0f} s CPU)", flush=True)
    rows.append({"truth_seed": 1, "draws": N_DRAWS, "start_spread": START_SPREAD,
                 "determinable": [n for n, d in zip(cands.unknowns, determinable, strict=True) if d],
                 "load_before": load[0], "load_after": os.getloadavg()[0]})
    write_results("plan_three_axis", rows)


def main() -> None:
    if sys.argv[1:] == ["speed"]:
        speed()
        return
    if sys.argv[1:] == ["three-axis"]:
        three_axis()
        return
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
