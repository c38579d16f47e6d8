"""Output-only monitoring against the hammer-based chain on the spindle: detection, location, false alarms.

Both chains watch the same machine (README step 9: the spindle, outputs sx, sy, hax, hay, haz, htax, band
150-1000 Hz, six component factors, CUSUM at 0.001 false alarms per measurement) through the same drift
(temperature cycling 22 +- 4 degC, preload following at 1 %/K):

- **operational**: 30 s output-only records at 2560 Hz, 2 % sensor noise, responses to an unmeasured process force
  whose spectrum changes with the load (:func:`cappe.monitor.simulate_operation`, an independent state-space
  simulation from the model's matrices); features by SSI-COV, factors from frequencies and unscaled shapes;
- **hammer**: FRFs of the three tool-tip inputs with 1 % noise (:func:`cappe.monitor.simulate_scenario`), factors
  by the FRF fit.

Per chain: a baseline from one healthy day (96 measurements); ``N_TRIALS`` trials of 5 healthy measurements
followed by 5 with a 10 % front-bearing loss (each from a fresh chart, at its own time of day), counting the
measurements to the first alarm and whether it names the front bearing; and a continuous healthy stream of
``N_HEALTHY`` measurements over the following days, counting the measurements at which any chart signals (the
false-alarm rate per measurement) and the alarms raised. Because 1000 measurements can bound a rate of 0.1 % only
loosely, the healthy stream's deviations are also replayed through the charts in a moving-block bootstrap
(blocks of 20 keep the serial correlation of the drift; 200 000 measurements) for the rate itself.

``python -m benchmarks.bench_operational CHAIN [N_HEALTHY N_TRIALS N_BASELINE FAULTS]`` (CHAIN ``operational`` or
``hammer``; defaults 1000, 20, 96, ``front``) writes ``benchmarks/results/operational_CHAIN.json`` (about 0.5 s per
operational measurement, BLAS on one thread as a ``cappe`` command runs). FAULTS, comma-separated from
:data:`FAULTS` (``front`` 10 %, ``screw3`` 50 %, ``preload`` 30 %, each a step), runs the trials of each against the
one baseline and healthy stream (N_HEALTHY 0: none); other than ``front`` alone it writes
``operational_CHAIN_FAULT1_FAULT2.json``, one row per fault, with what the first alarm named (``diagnosed_as``).
"""

from __future__ import annotations

import sys
import time
import warnings
from datetime import UTC, datetime, timedelta
from typing import Any

import numpy as np

from benchmarks._common import write_results
from cappe.model import NumericModel, load_model
from cappe.monitor import Monitor, default_config, simulate_operation, simulate_scenario
from cappe.parallel import blas_threads

OUTPUTS = ["sx", "sy", "hax", "hay", "haz", "htax"]
BAND = (150.0, 1000.0)
N_BASELINE = 96
START = datetime(2026, 1, 5, 6, 0, tzinfo=UTC)


def _records(kind: str, config: Any, model: NumericModel, scenario: str, **kwargs: Any) -> list[Any]:
    if kind == "operational":
        return [(m.data, m.conditions, m.fault) for m in simulate_operation(config, scenario, seconds=30.0,
                                                                            model=model, **kwargs)]
    return [(m.frf, m.conditions, m.fault) for m in simulate_scenario(config, scenario, model=model, **kwargs)]


def _analyse(monitor: Monitor, data: Any, baseline: Any = None) -> Any:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # fit notes are kept with a record in the chain; counted here
        return monitor.analyse(data, baseline=baseline, modal=False)


def _bootstrap_rate(detector: Any, deviations: np.ndarray, stds: np.ndarray, n: int, rng: int) -> float:
    """Signals per measurement of the charts fed a moving-block bootstrap of healthy deviations."""
    gen = np.random.default_rng(rng)
    block = min(20, deviations.shape[0] // 2)
    state = None
    signals = 0
    count = 0
    while count < n:
        start = int(gen.integers(0, deviations.shape[0] - block + 1))
        for k in range(start, start + block):
            state, found = detector.update(state, deviations[k], stds[k])
            signals += bool(found)
            count += 1
            if found:  # after an alarm the chart restarts (the machine is inspected)
                state = None
    return signals / count


#: The faults of the trials: name -> (scenario, component, severity). Each is a step from the 6th measurement on.
FAULTS = {"front": ("bearing-loss", "front", 0.10), "screw3": ("bearing-loss", "screw3", 0.50),
          "preload": ("preload-loss", None, 0.30)}


def _trials(kind: str, config: Any, model: NumericModel, monitor: Monitor, baseline: Any, fault: str,
            n_trials: int) -> dict[str, Any]:
    """Trials of 5 healthy measurements, then 5 with the fault: delay to the first alarm and what it names."""
    scenario, component, severity = FAULTS[fault]
    expected = component or "preload"
    delays: list[int | None] = []
    named: list[str | None] = []
    early = 0
    for trial in range(n_trials):
        when = START + timedelta(days=1, hours=float(np.random.default_rng(50 + trial).uniform(0, 24)))
        records = _records(kind, config, model, scenario, n=10, fault_at=5, component=component,
                           severity=severity, rng=100 + trial, start=when)
        state = None
        first: tuple[int, str] | None = None
        for k, (data, cond, truth) in enumerate(records):
            if baseline.judge(cond)[0]:
                continue
            state, _, alarms = monitor.step(state, _analyse(monitor, data, baseline), cond, baseline)
            if alarms and truth is None:
                early += 1
            if alarms and truth is not None and first is None:
                first = (k - 5 + 1, alarms[0].component)
        delays.append(None if first is None else first[0])
        named.append(first[1] if first else None)
        print(f"{kind} {fault}: trial {trial}: alarm at faulty measurement {delays[-1]}, {named[-1] or '-'}",
              flush=True)
    found = [d for d in delays if d is not None]
    located = sum(n == expected for n in named)
    return {
        "fault": {"scenario": scenario, "component": expected, "severity": severity},
        "trials": n_trials,
        "detected_within_5": int(sum(d is not None and d <= 5 for d in delays)),
        "median_delay": float(np.median(found)) if found else None,
        "max_delay": max(found) if found else None,
        "located_front" if fault == "front" else "located": located,
        "diagnosed_as": {str(n): named.count(n) for n in sorted(set(named), key=str)},
        "alarms_before_fault": early,
    }


def run_chain(kind: str, n_healthy: int, n_trials: int, n_baseline: int = N_BASELINE,
              faults: tuple[str, ...] = ("front",)) -> list[dict[str, Any]]:
    model = NumericModel(load_model("builtin:spindle-bearing"))
    config = default_config(model, machine=f"spindle-{kind}", source="builtin:spindle-bearing", outputs=OUTPUTS,
                            band=BAND, excitation="operational" if kind == "operational" else "measured")
    monitor = Monitor(config, model)
    t0 = time.perf_counter()
    day = _records(kind, config, model, "healthy", n=n_baseline, rng=1, start=START)
    t_sim = (time.perf_counter() - t0) / len(day)
    t0 = time.perf_counter()
    analyses = [_analyse(monitor, d) for d, _, _ in day]
    t_analyse = (time.perf_counter() - t0) / len(day)
    baseline = monitor.learn_baseline(analyses, conditions=[c for _, c, _ in day])
    print(f"{kind}: baseline scale % " + ", ".join(f"{n} {100 * s:.2f}" for n, s in
                                                   zip(baseline.names, baseline.scale, strict=True)), flush=True)

    trials = {fault: _trials(kind, config, model, monitor, baseline, fault, n_trials) for fault in faults}

    # a continuous healthy stream over the following days
    stream = (_records(kind, config, model, "healthy", n=n_healthy, rng=7, start=START + timedelta(days=2))
              if n_healthy else [])
    detector = monitor.detector(baseline)
    state = None
    chart_state = None
    signal_count = alarm_count = judged = 0
    deviations, stds = [], []
    for data, cond, _ in stream:
        if baseline.judge(cond)[0]:
            continue
        judged += 1
        analysis = _analyse(monitor, data, baseline)
        state, deviation, alarms = monitor.step(state, analysis, cond, baseline)
        log_std = np.sqrt(np.clip(np.diag(analysis.estimate.covariance), 0.0, None))
        chart_state, signals = detector.update(chart_state, deviation, log_std)
        signal_count += bool(signals)
        alarm_count += len(alarms)
        deviations.append(deviation)
        stds.append(log_std)
    dev = np.array(deviations)
    rate = _bootstrap_rate(detector, dev, np.array(stds), 200_000, rng=3) if len(dev) else None
    common = {
        "chain": kind,
        "baseline_measurements": n_baseline,
        "baseline_scale_percent": {n: 100 * float(s) for n, s in zip(baseline.names, baseline.scale, strict=True)},
        "healthy_measurements": len(stream),
        "healthy_judged": judged,
        "healthy_signal_measurements": signal_count,
        "healthy_alarms": alarm_count,
        "healthy_z_std": (dev.std(axis=0) / baseline.scale).tolist() if len(dev) else None,
        "bootstrap_false_alarm_rate": rate,
        "simulation_s": t_sim,
        "analysis_s": t_analyse,
    }
    rows = []
    for fault, trial in trials.items():
        rows.append({**common, **trial})
        print(f"{kind} {fault}: detected within 5 in {trial['detected_within_5']}/{n_trials} (median delay "
              f"{trial['median_delay']}), named {trial['diagnosed_as']}; {trial['alarms_before_fault']} alarm(s) "
              f"before the fault; healthy: {signal_count} signalling measurement(s) and {alarm_count} alarm(s) in "
              f"{judged} judged of {len(stream)}; bootstrap rate {rate}; analysis {t_analyse:.2f} s per "
              f"measurement", flush=True)
    return rows


def main() -> None:
    kind = sys.argv[1] if len(sys.argv) > 1 else "operational"
    n_healthy = int(sys.argv[2]) if len(sys.argv) > 2 else 1000
    n_trials = int(sys.argv[3]) if len(sys.argv) > 3 else 20
    n_baseline = int(sys.argv[4]) if len(sys.argv) > 4 else N_BASELINE
    faults = tuple(sys.argv[5].split(",")) if len(sys.argv) > 5 else ("front",)
    if kind not in ("operational", "hammer"):
        msg = f"chain must be 'operational' or 'hammer'; got {kind!r}"
        raise SystemExit(msg)
    unknown = [f for f in faults if f not in FAULTS]
    if unknown:
        msg = f"faults must be among {sorted(FAULTS)}; got {unknown}"
        raise SystemExit(msg)
    t0 = time.process_time()
    with blas_threads(1):  # as a cappe command runs (cappe.parallel.command_blas_threads): ~10x on 2 cores
        rows = run_chain(kind, n_healthy, n_trials, n_baseline, faults)
    cpu = time.process_time() - t0
    for row in rows:
        row["cpu_s"] = cpu
    name = f"operational_{kind}" if faults == ("front",) else f"operational_{kind}_{'_'.join(faults)}"
    print(f"wrote {write_results(name, rows)} ({cpu:.0f} CPU s)")


if __name__ == "__main__":
    main()
