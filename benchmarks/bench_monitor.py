"""The monitoring chain on the spindle: measurements per second, and the stiffness-factor fit against scipy.

One run measures, on the set-up of README step 9 (3 hammer inputs, 6 outputs, 851 lines from 150 to 1000 Hz,
1 % FRF noise, six component factors):

- the fast-path fit (:class:`cappe.monitor.FactorEstimator`: analytic low-rank Jacobian, start point kept) against
  ``scipy.optimize.least_squares`` (trust-region reflective, 2-point finite-difference Jacobian) on the very same
  residual ``w ln(H_model / H_measured)`` from the same start; both must reach the same factors;
- the cost of one exact model FRF on the same lines (the unit of work of any FRF fit), so that a fit's time reads
  as FRF-evaluation equivalents;
- the whole chain per measurement: analysis (fast fit, LSCF modal features, FRAC/CSF), detection, and the atomic
  ingest into an SQLite history store.

``python -m benchmarks.bench_monitor`` writes ``benchmarks/results/monitor.json``.
"""

from __future__ import annotations

import tempfile
import time
import warnings
from datetime import timedelta
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from benchmarks._common import best, write_results
from cappe.model import NumericModel, load_model
from cappe.monitor import HistoryStore, Monitor, default_config, ingest, register_machine, simulate_scenario

OUTPUTS = ["sx", "sy", "hax", "hay", "haz", "htax"]
N_FITS = 40


def _scipy_fit(monitor: Monitor, frf: Any, start: np.ndarray) -> np.ndarray:
    est = monitor.estimator
    freq, h_meas = est.select(frf)
    weights, _ = est._weights(freq)
    used = weights > 0
    h_meas = np.where(used, h_meas, 1.0)

    def residual(s: np.ndarray) -> np.ndarray:
        h = np.where(used, est.frf(s, freq), 1.0)
        r = (weights * np.log(h / h_meas)).ravel()
        return np.concatenate([r.real, r.imag])

    return np.asarray(least_squares(residual, start, method="trf", x_scale=0.01, xtol=1e-10).x)


def main() -> None:
    model = NumericModel(load_model("builtin:spindle-bearing"))
    config = default_config(model, machine="spindle-01", source="builtin:spindle-bearing", outputs=OUTPUTS,
                            band=(150.0, 1000.0))
    monitor = Monitor(config, model)
    healthy = simulate_scenario(config, "healthy", n=48, model=model, rng=1)
    faulty = simulate_scenario(config, "bearing-loss", n=N_FITS, fault_at=0, component="front", model=model, rng=2,
                               start=healthy[-1].timestamp + timedelta(hours=1))
    freq, _ = monitor.estimator.select(healthy[0].frf)
    start = np.zeros(len(config.components))
    t_frf = best(lambda: monitor.estimator.frf(start, freq), repeat=20)

    # fast path against scipy on the same residual, healthy and faulty measurements
    rows: list[dict[str, Any]] = []
    for label, data in (("healthy", healthy[:N_FITS]), ("front bearing -10 %", faulty)):
        t0 = time.perf_counter()
        ours = [monitor.estimator.estimate(m.frf).log_factor for m in data]
        t_ours = (time.perf_counter() - t0) / len(data)
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            theirs = [_scipy_fit(monitor, m.frf, start) for m in data[:10]]
        t_scipy = (time.perf_counter() - t0) / 10
        diff = float(np.max(np.abs(np.exp(np.array(ours[:10])) - np.exp(np.array(theirs)))))
        rows.append({"case": label, "fit_s": t_ours, "scipy_fit_s": t_scipy, "speedup": t_scipy / t_ours,
                     "fit_in_frf_evaluations": t_ours / t_frf, "max_factor_difference": diff})
        print(f"{label:20s} fit {1e3 * t_ours:6.1f} ms ({t_ours / t_frf:4.1f} FRF evaluations), scipy least_squares "
              f"{1e3 * t_scipy:6.1f} ms: {t_scipy / t_ours:4.1f}x; factors agree to {diff:.1e}")

    # the whole chain per measurement through an SQLite store
    with tempfile.TemporaryDirectory() as tmp:
        with HistoryStore(Path(tmp) / "bench.db") as store:
            register_machine(store, config)
            t0 = time.perf_counter()
            for m in healthy:
                ingest(store, config.machine, m.frf, timestamp=m.timestamp, source=f"h{m.index}",
                       conditions=m.conditions, monitor=monitor)
            t_ingest = (time.perf_counter() - t0) / len(healthy)
    t_analyse = best(lambda: monitor.analyse(healthy[0].frf), repeat=5)
    print(f"chain: analysis with modal features {1e3 * t_analyse:.0f} ms, ingest into SQLite "
          f"{1e3 * t_ingest:.0f} ms per measurement ({1 / t_ingest:.1f} measurements/s); one model FRF on "
          f"{freq.size} lines {1e3 * t_frf:.2f} ms")
    rows.append({"case": "chain", "frf_evaluation_s": t_frf, "analysis_s": t_analyse, "ingest_s": t_ingest,
                 "lines": int(freq.size), "outputs": len(OUTPUTS), "inputs": len(config.inputs)})
    print(f"wrote {write_results('monitor', rows)}")


if __name__ == "__main__":
    main()
