"""The hand-written Levenberg-Marquardt loops of the monitor and of the black-box models against the shared one.

Each on its real use, both timed in the same run:

* the monitor's stiffness-factor fit (:class:`cappe.monitor.FactorEstimator`): ``builtin:spindle-bearing``, outputs
  sx, hax, hay, input Fx, band 150-1000 Hz (400 lines), one group per bearing (front, rear), a stream of 20
  measurements with losses of 0-30 % and 1 % complex noise (seeded), each fitted from the reference as the
  monitoring chain does. Its own loop (log-factor trust region, the start point's Jacobian kept for the next
  measurement) against :func:`cappe.optimize.minimize` ``strategy="least-squares"`` (scipy's trust-region
  reflective method, the engine of :func:`cappe.estimate.fit_least_squares`) on the same residual and analytic
  Jacobian, in a box of +-3 in log-factor;
* the prediction-error fit of ARMAX(2, 2, 2), ARMAX(4, 4, 4), OE(2, 2) and OE(4, 4) (``cappe fit``): 4000
  samples of a seeded ARMAX process, the SVD-based loop with stable C, D and F of
  :mod:`cappe.identify._polynomial` against the same shared solver on the same errors and Jacobian (stabilized
  once at the end).

Reported: seconds of each, their ratio and the final costs.
"""

from __future__ import annotations

import time
import warnings
from typing import Any

import numpy as np
import scipy.signal as sig

from benchmarks._common import write_results
from cappe.identify import ARMAX, OE
from cappe.identify import _polynomial as poly
from cappe.model import NumericModel, load_model
from cappe.monitor import FactorEstimator
from cappe.optimize import minimize
from cappe.systems import FRFData, TimeData


class _SharedSolver(FactorEstimator):
    """The monitor's fit with the shared least-squares solver in place of its own loop."""

    def _solve(self, freq: Any, h_meas: Any, weights: Any, start: Any, max_iter: int) -> Any:
        used = weights > 0
        n = len(self.names)

        def residual(s: np.ndarray) -> np.ndarray:
            h = np.where(used, np.moveaxis(self._lines(self.parameters(s), freq).H, 0, -1), 1.0)
            r = (weights * np.log(h / h_meas)).ravel()
            return np.concatenate([r.real, r.imag])

        def jacobian(s: np.ndarray) -> np.ndarray:
            p = self.parameters(s)
            lines = self._lines(p, freq)
            h = np.where(used, np.moveaxis(lines.H, 0, -1), 1.0)
            jac = (weights[None] * self._jacobian(p, freq, lines.X, lines.L) / h[None]).reshape(n, -1)
            return np.concatenate([jac.real, jac.imag], axis=1).T

        res = minimize(None, (np.full(n, -3.0), np.full(n, 3.0)), strategy="least-squares", x0=start,
                       residuals=residual, residual_jacobian=jacobian, max_evaluations=max_iter)
        r = residual(res.x)
        return res.x, 0.5 * float(r @ r), jacobian(res.x), res.n_evaluations, res.success, res.message


def _monitor() -> dict[str, Any]:
    nm = NumericModel(load_model("builtin:spindle-bearing"))
    groups = {"front": ["kfx", "kfy", "kfz"], "rear": ["krx", "kry"]}
    kw: dict[str, Any] = {"inputs": ["Fx"], "outputs": ["sx", "hax", "hay"], "band": (150.0, 1000.0)}
    freq = np.linspace(150.0, 1000.0, 400)
    rng = np.random.default_rng(1)
    stream = []
    ref = FactorEstimator(nm, groups, **kw)
    for loss in np.linspace(0.0, 0.3, 20):
        p = ref.parameters(np.log([1 - loss, 1 - 0.5 * loss]))
        h = nm.system(dict(zip(nm.parameter_names, p, strict=True))).frf(freq, ["Fx"], kw["outputs"]).H
        noise = 0.01 * (rng.standard_normal(h.shape) + 1j * rng.standard_normal(h.shape)) / np.sqrt(2)
        stream.append(FRFData(freq, h * (1 + noise), ("Fx",), tuple(kw["outputs"])))
    row: dict[str, Any] = {"case": "monitor factor fit, spindle, 2 groups, 400 lines, 20 measurements"}
    for label, cls in (("own", FactorEstimator), ("shared", _SharedSolver)):
        est = cls(nm, groups, **kw)
        est.estimate(stream[0])  # the weights of the line grid, as a running monitor has them
        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fits = [est.estimate(d) for d in stream]
        row[f"{label}_s"] = time.perf_counter() - t
        row[f"{label}_cost_sum"] = float(sum(f.cost for f in fits))
        row[f"{label}_factors_last"] = fits[-1].factor.tolist()
    row["ratio"] = row["shared_s"] / row["own_s"]
    return row


def _shared_pem(theta0: np.ndarray, o: Any, y: np.ndarray, u: np.ndarray, *, max_iter: int, tol: float) -> Any:
    """:func:`poly._pem` with the shared least-squares solver (stabilized at the start and at the end)."""
    theta = poly._pack(poly._stabilize(poly._unpack(theta0, o)), o)

    def residual(t: np.ndarray) -> np.ndarray:
        return poly._errors(poly._unpack(t, o), y, u)[0]

    def jacobian(t: np.ndarray) -> np.ndarray:
        p = poly._unpack(t, o)
        e, v, w = poly._errors(p, y, u)
        return poly._jacobian(p, o, y, u, e, v, w)

    span = 10.0 * (np.abs(theta) + 1.0)
    res = minimize(None, (theta - span, theta + span), strategy="least-squares", x0=theta, residuals=residual,
                   residual_jacobian=jacobian, max_evaluations=max_iter, tol=tol)
    p = poly._stabilize(poly._unpack(res.x, o))
    e, v, w = poly._errors(p, y, u)
    return poly._PemResult(poly._pack(p, o), e, poly._jacobian(p, o, y, u, e, v, w), res.success, res.message,
                           res.n_evaluations)


def _black_box() -> list[dict[str, Any]]:
    rng = np.random.default_rng(3)
    n = 4000
    u = rng.standard_normal(n)
    e = 0.1 * rng.standard_normal(n)
    a, b, c = [1.0, -1.5, 0.7], [0.0, 1.0, 0.5], [1.0, -0.2, 0.3]
    y = sig.lfilter(b, a, u) + sig.lfilter(c, a, e)
    data = TimeData.from_channels(np.arange(n) * 0.01, {"u": u, "y": y})
    rows = []
    for model in (ARMAX(2, 2, 2, 1), ARMAX(4, 4, 4, 1), OE(2, 2, 1), OE(4, 4, 1)):
        row: dict[str, Any] = {"case": f"{model!r} on 4000 samples"}
        own = poly._pem
        for label, pem in (("own", own), ("shared", _shared_pem)):
            poly._pem = pem
            try:
                t = time.perf_counter()
                for _ in range(5):
                    fitted = model.fit(data, inputs="u", output="y")
                row[f"{label}_s"] = (time.perf_counter() - t) / 5
                row[f"{label}_loss"] = float(fitted.loss_)
            finally:
                poly._pem = own
        row["ratio"] = row["shared_s"] / row["own_s"]
        rows.append(row)
    return rows


def main() -> None:
    rows = [_monitor(), *_black_box()]
    for r in rows:
        print(f"{r['case']}: own LM {r['own_s']:.3f} s, shared (scipy trf) {r['shared_s']:.3f} s -> "
              f"{r['ratio']:.1f}x; cost {r.get('own_cost_sum', r.get('own_loss')):.6g} / "
              f"{r.get('shared_cost_sum', r.get('shared_loss')):.6g}")
    write_results("lm", rows)


if __name__ == "__main__":
    main()
