"""Band-limited (``--intersample bl``) simulation and fit: the modal kernel against the per-frequency transfer.

Both timed in the same run, on the two-mass rig (F1 -> d1, d2, 2 kHz):

* **before**: the response ``(sum_i r_i / (j omega - lam_i) + D) U(omega)`` assembled by ``einsum`` per frequency
  on the record zero-padded until the slowest mode has decayed by exp(-28) (at least one record, at most 2^18
  samples or four records): :func:`cappe.systems.statespace.band_limited_response`, which one-step used;
* **after**: :func:`cappe.systems.statespace.band_limited_modal_response`: first-order terms per mode on the
  record's grid padded by at most one record, the wrapped-around free decay removed exactly.

Reported (CPU seconds, BLAS on one thread as a ``cappe`` command runs; the machine is shared and its wall time
measures the neighbours): seconds per simulation
of an 8000-sample record at the truth and at a lightly damped point a search passes through (c22 = 0.05 N s/m:
decay 0.03 1/s, the old padding hits 2^18), their ratio and the largest difference of the two; the seconds of a
complete ``one-step`` fit (seven unknowns, delay and offsets, 1 % noise) of a DAQ record with each kernel and the
change of the estimate in units of its standard error. The independent reference is a 16x oversampled continuous
simulation, anti-alias filtered and decimated (:func:`benchmarks.bench_coverage.simulate`): the distance of both
kernels' simulations to it.
"""

from __future__ import annotations

import time
import warnings
from typing import Any

import numpy as np

from benchmarks import bench_coverage as cov
from benchmarks._common import best_cpu, write_results
from cappe.estimate._one_step import OneStepEstimator, _Modes, _TimeModel
from cappe.model import NumericModel, load_model
from cappe.parallel import blas_threads
from cappe.systems.statespace import band_limited_modal_response, band_limited_response

NAMES = ("m1", "m2", "k11", "k12", "k22", "c11", "c12", "c22")


def _per_frequency(self: _TimeModel, modes: _Modes, u: np.ndarray, delay: float) -> np.ndarray:
    """The kernel one-step used before: the transfer matrix per frequency by einsum over the long padding."""
    res = modes.cm[:, :, None] * modes.bm[None, :, :]
    tau = delay * self.dt

    def transfer(omega: np.ndarray) -> np.ndarray:
        jw = 1j * omega[:, None]
        h = 0.5 * (np.einsum("oml,fm->fol", res, 1.0 / (jw - modes.lam[None, :]))
                   + np.einsum("oml,fm->fol", res.conj(), 1.0 / (jw - modes.lam.conj()[None, :])))
        return np.asarray((h + modes.d[None]) * np.exp(-1j * omega * tau)[:, None, None])

    return band_limited_response(transfer, u, self.dt, float(np.min(-modes.lam.real)))


def _modal(self: _TimeModel, modes: _Modes, u: np.ndarray, delay: float) -> np.ndarray:
    return band_limited_modal_response(modes.lam, modes.bm, modes.cm, modes.d, u, self.dt, delay=delay)


def _simulation_rows(nm: NumericModel) -> list[dict[str, Any]]:
    rows = []
    rng = np.random.default_rng(0)
    f, y = cov.simulate("daq", rng, 1)
    u = np.vstack([f, f[:2000]])[:8000]  # an 8000-sample record (the README's 4 s at 2 kHz)
    sim = _TimeModel(nm, None, ["F1"], ["d1", "d2"], 1 / cov.FS, "bl")
    for label, c22 in (("truth", 2.0), ("lightly damped", 0.05)):
        p = np.array([{**cov.TRUTH, "c22": c22}[n] for n in NAMES])
        modes = sim.modes(p, np.ones(2))
        before = best_cpu(lambda m=modes: _per_frequency(sim, m, u, 0.3), 10)
        after = best_cpu(lambda m=modes: _modal(sim, m, u, 0.3), 10)
        a, b = _per_frequency(sim, modes, u, 0.3), _modal(sim, modes, u, 0.3)
        rows.append({"case": f"simulation, 8000 samples, {label}", "before_s": before, "after_s": after,
                     "speedup": before / after, "max_difference_relative": float(np.abs(a - b).max()
                                                                                / np.abs(b).max())})
    # both against the 16x oversampled, anti-alias filtered, decimated record (noise-free)
    modes = sim.modes(np.array([cov.TRUTH[n] for n in NAMES]), np.ones(2))
    ref = y[:, :2]
    for name, kernel in (("before", _per_frequency), ("after", _modal)):
        err = np.abs(kernel(sim, modes, f, 0.0) - ref).max() / np.abs(ref).max()
        rows.append({"case": f"{name}: distance to the 16x oversampled DAQ record", "max_error_relative": float(err)})
    return rows


def _fit_rows(nm: NumericModel) -> list[dict[str, Any]]:
    data = cov.record("daq", 0.01, 3, 1).select(["F1", "d1", "d2"])
    estimates, seconds = {}, {}
    original = _TimeModel._band_limited
    try:
        for name, kernel in (("before", _per_frequency), ("after", _modal)):
            _TimeModel._band_limited = kernel  # type: ignore[method-assign]
            t0 = time.process_time()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                estimates[name] = OneStepEstimator(nm, cov.UNKNOWNS, values={"c12": 0.0}, rng=0,
                                                   intersample="bl").fit(data).estimate_
            seconds[name] = time.process_time() - t0
    finally:
        _TimeModel._band_limited = original  # type: ignore[method-assign]
    old, new = estimates["before"], estimates["after"]
    shift = np.abs(new.values - old.values) / old.std
    truth = np.array([cov.TRUTH[n] for n in new.names])
    return [{"case": "one-step bl fit, 6000 samples, F1 -> d1, d2, 7 unknowns", "before_s": seconds["before"],
             "after_s": seconds["after"], "speedup": seconds["before"] / seconds["after"],
             "largest_change_in_std": float(shift.max()),
             "largest_error_in_std_before": float(np.max(np.abs(old.values - truth) / old.std)),
             "largest_error_in_std_after": float(np.max(np.abs(new.values - truth) / new.std))}]


def main() -> None:
    nm = NumericModel(load_model("builtin:two-mass-rig"))
    with blas_threads(1):  # as a cappe command runs (cappe.parallel.command_blas_threads)
        rows = _simulation_rows(nm)
        for row in rows:
            print(row, flush=True)
        for row in _fit_rows(nm):
            print(row, flush=True)
            rows.append(row)
    write_results("intersample", rows)


if __name__ == "__main__":
    main()
