"""Prognosis on the spindle: does the forecast of a loosening screw's intolerable crossing cover the truth?

The hammer chain of README step 9 (1 % FRF noise, temperature drift, baseline from one healthy day) watches
``N_SEQUENCES`` sequences in which housing screw 3 loosens linearly by ``RATE`` per measurement (every 15 min) from
a random time of day. At ``AT`` measurements after the first alarm, :func:`cappe.monitor.forecast_crossing`
extrapolates the screw's changes since that alarm to the intolerable grade (-25 %); the truth is the time the
simulated stiffness reaches 75 %. Reported: the coverage of the 95 % intervals (counting "cannot be told" as
covering, and how often that was said), their median width and the median error of the point forecast, and the
coverage of the intervals from the scatter alone (without the scale uncertainty, the baseline's ``size_scale_std``).

The data come from cappe's scenario simulator (``scenario``, the default) or from the independent generator
:class:`benchmarks._spindle_generator.ShopFloor` (numpy physics of its own, cold starts and warm-up) with the exact
model (``exact``) or a machine 3 % heavier and 30 % more damped than its model (``mismatch``).

The scale term is the baseline's :meth:`~cappe.monitor.Baseline.component_scale_std` of the component (from the
machine's twin where the baseline has FRFs: the generator's cases; the offset rule on cappe's scenarios).

``python -m benchmarks.bench_prognosis [N_SEQUENCES] [scenario|exact|mismatch] [COMPONENT]`` writes
``benchmarks/results/prognosis.json`` (scenario) or ``prognosis_<case>.json`` (``_<component>`` appended for a
``COMPONENT`` other than screw 3, the one that then loses ``RATE`` per measurement).
"""

from __future__ import annotations

import sys
import time
import warnings
from datetime import UTC, datetime, timedelta

import numpy as np

from benchmarks._common import write_results
from cappe.model import NumericModel, load_model
from cappe.monitor import Monitor, default_config, forecast_crossing, simulate_scenario
from cappe.parallel import blas_threads

OUTPUTS = ["sx", "sy", "hax", "hay", "haz", "htax"]
START = datetime(2026, 1, 5, 6, 0, tzinfo=UTC)
RATE = 0.01  # stiffness lost per measurement (4 %/h)
AT = 8  # measurements after the first alarm at which the forecast is made


def main() -> None:
    with blas_threads(1):  # as a cappe command runs (cappe.parallel.command_blas_threads)
        _main()


def _main() -> None:
    t0, c0 = time.perf_counter(), time.process_time()
    n_seq = int(sys.argv[1]) if len(sys.argv) > 1 else 200
    case = sys.argv[2] if len(sys.argv) > 2 else "scenario"
    component = sys.argv[3] if len(sys.argv) > 3 else "screw3"
    n = 40  # measurements per sequence: 4 healthy, then the screw loosens by RATE per measurement
    if case == "scenario":
        model = NumericModel(load_model("builtin:spindle-bearing"))
        config = default_config(model, machine="spindle-01", source="builtin:spindle-bearing", outputs=OUTPUTS,
                                band=(150.0, 1000.0))
        monitor = Monitor(config, model)
        day = simulate_scenario(config, "healthy", n=96, model=model, rng=1, start=START)
        baseline = monitor.learn_baseline([monitor.analyse(m.frf, modal=False) for m in day],
                                          conditions=[m.conditions for m in day])

        def sequence(seq: int) -> list:
            start = START + timedelta(days=1, hours=float(np.random.default_rng(900 + seq).uniform(0, 24)))
            return simulate_scenario(config, "loosening-screw", n=n, fault_at=4, component=component,
                                     severity=RATE * (n - 1 - 4), model=model, rng=1000 + seq, start=start)
    else:
        from benchmarks.bench_calibration import setup

        monitor, floor, baseline = setup(case, seed=4)

        def sequence(seq: int) -> list:
            return floor.run(n, fault=component, loss=RATE * np.clip(np.arange(n) - 4, 0, None), fault_at=4)
    scale_std = float(baseline.component_scale_std()[list(baseline.names).index(component)])
    covered, undetermined, widths, errors = [], 0, [], []
    covered_scatter_only, widths_scatter = [], []
    for seq in range(n_seq):
        data = sequence(seq)
        state = None
        first = None
        times, changes = [], []
        for k, m in enumerate(data):
            if baseline.judge(m.conditions)[0]:
                continue
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                analysis = monitor.analyse(m.frf, baseline=baseline, modal=False)
            state, deviation, alarms = monitor.step(state, analysis, m.conditions, baseline)
            if first is None and any(a.component == component for a in alarms):
                first = k
            if first is not None:
                times.append(0.25 * k)
                changes.append(float(np.expm1(deviation[monitor.estimator.names.index(component)])))
            if first is not None and k == first + AT - 1:
                break
        if first is None or len(times) < 3:
            continue
        forecast = forecast_crossing(times, changes, -0.25, scale_std=scale_std)
        truth = 0.25 * (4 + 0.25 / RATE)  # factor 1 - RATE (k - 4) reaches 0.75
        covered.append(forecast.covers(truth))
        scatter_only = forecast_crossing(times, changes, -0.25)
        covered_scatter_only.append(scatter_only.covers(truth))
        if scatter_only.determined:
            widths_scatter.append(scatter_only.upper - scatter_only.lower)
        undetermined += not forecast.determined
        if forecast.determined and forecast.time is not None:
            widths.append(forecast.upper - forecast.lower)
            errors.append(forecast.time - truth)
        if seq % 10 == 0:
            print(f"sequence {seq}: forecast {forecast.text(now=times[-1])}; truth in {truth - times[-1]:.3g} h; "
                  f"coverage so far {sum(covered)}/{len(covered)} (scatter only {sum(covered_scatter_only)})",
                  flush=True)
    rate = float(np.mean(covered))
    row = {"case": case, "component": component, "sequences": len(covered), "coverage_95": rate, "scale_std": scale_std,
           "coverage_95_scatter_only": float(np.mean(covered_scatter_only)),
           "coverage_binomial_se": float(np.sqrt(0.95 * 0.05 / len(covered))),
           "undetermined": undetermined, "median_width_h": float(np.median(widths)),
           "median_error_h": float(np.median(errors)), "rate_per_measurement": RATE, "forecast_after": AT,
           "median_width_scatter_only_h": float(np.median(widths_scatter)),
           "wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0}
    print(f"coverage {100 * rate:.1f} % of {len(covered)} (95 % stated; scatter only "
          f"{100 * row['coverage_95_scatter_only']:.1f} %), {undetermined} undetermined, median width "
          f"{row['median_width_h']:.2f} h (scatter only {row['median_width_scatter_only_h']:.2f} h), median error "
          f"{row['median_error_h']:+.2f} h, scale_std {100 * scale_std:.2g} %, cpu {row['cpu_s']:.0f} s")
    name = "prognosis" if case == "scenario" else f"prognosis_{case}"
    print(f"wrote {write_results(name if component == 'screw3' else f'{name}_{component}', [row])}")


if __name__ == "__main__":
    main()
