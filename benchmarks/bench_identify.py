"""Identification from measurements: cappe against the peer tools on the same data, ratios from one run.

* FRF estimation (H1 with coherence) of 4 inputs x 4 outputs, 2**19 samples, 4096-sample Hann segments, 50 %
  overlap: ``cappe.identify.estimate_frf`` (each channel transformed once, batched spectral matrices) against the
  same H1 assembled from ``scipy.signal.csd`` calls per channel pair. The maximum relative difference of H1 is
  recorded.
* Modal extraction from 6 FRFs x 4000 lines of a 3-DOF system with 1 % noise, model orders up to 40 (the same
  polynomial order, 20 in sdypy-EMA's counting): ``cappe.identify.extract_modes`` (LSCF, stabilization, clustering,
  LSFD) against sdypy-EMA's ``get_poles`` + ``select_closest_poles`` + ``get_constants`` (LSCF + LSFD with the
  poles given by hand). The differences of frequencies and damping ratios between the tools are recorded. The
  ratio compares like with like: cappe without its bootstrap standard deviations (``n_bootstrap=0``; EMA gives
  none); the default extraction with its 30 bootstrap replicates (each a further LSCF + LSFD) is timed beside it.
* A 40th-order two-input ARX fit on 10**4 samples (the thesis's high-order fit) and its pruning.
"""

from __future__ import annotations

import contextlib
import io
import warnings
from typing import Any

import numpy as np
import scipy.signal as sig

from benchmarks._common import best, write_results
from cappe.identify import ARX, estimate_frf, extract_modes, prune
from cappe.io import TimeData
from cappe.systems import FRFData


def _frf_row() -> dict[str, Any]:
    rng = np.random.default_rng(0)
    n, n_in, n_out, nperseg = 2**19, 4, 4, 4096
    u = rng.standard_normal((n_in, n))
    mix = rng.standard_normal((n_out, n_in))
    y = np.array([sig.lfilter([1.0, 0.3], [1.0, -1.2 + 0.1 * k, 0.8], mix[k] @ u) for k in range(n_out)])
    y += 0.01 * rng.standard_normal(y.shape)
    names_in = [f"F{k}" for k in range(n_in)]
    names_out = [f"a{k}" for k in range(n_out)]
    data = TimeData.from_rate(1024.0, dict(zip(names_in + names_out, np.vstack([u, y]), strict=True)))

    def ours() -> FRFData:
        return estimate_frf(data, inputs=names_in, outputs=names_out, nperseg=nperseg, noverlap=nperseg // 2)

    def scipy_pairs() -> np.ndarray:
        kw = {"fs": 1024.0, "window": "hann", "nperseg": nperseg, "noverlap": nperseg // 2}
        gxx = np.empty((n_in, n_in, nperseg // 2 + 1), complex)
        gyx = np.empty((n_out, n_in, nperseg // 2 + 1), complex)
        for i in range(n_in):
            for j in range(n_in):
                gxx[i, j] = sig.csd(u[j], u[i], **kw)[1]  # E[conj(X_j) X_i]
            for o in range(n_out):
                gyx[o, i] = sig.csd(u[i], y[o], **kw)[1]
        # H1 = Gyx Gxx^-1 per line (Gxx[i, j] = E[X_i conj(X_j)])
        return np.einsum("oif->foi", gyx) @ np.linalg.inv(np.einsum("ijf->fij", gxx))

    t_ours, t_scipy = best(ours), best(scipy_pairs)
    h_ours = ours().H
    h_ref = np.einsum("foi->oif", scipy_pairs())
    diff = float(np.nanmax(np.abs(h_ours - h_ref)) / np.nanmax(np.abs(h_ref)))
    return {"case": "frf_h1_4x4", "samples": n, "nperseg": nperseg, "cappe_s": t_ours, "scipy_csd_s": t_scipy,
            "speedup": t_scipy / t_ours, "max_rel_difference": diff}


def _three_dof() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    m = np.diag([2.0, 1.5, 1.0])
    k = np.array([[7e5, -3e5, 0.0], [-3e5, 5e5, -2e5], [0.0, -2e5, 2e5]])
    return m, 2e-5 * k + 5.0 * m, k


def _three_dof_truth() -> tuple[np.ndarray, np.ndarray]:
    """Exact frequencies (Hz) and damping ratios from the state-space eigenvalues."""
    m, c, k = _three_dof()
    a = np.block([[np.zeros((3, 3)), np.eye(3)], [-np.linalg.solve(m, k), -np.linalg.solve(m, c)]])
    lam = np.linalg.eigvals(a)
    lam = lam[lam.imag > 0]
    lam = lam[np.argsort(np.abs(lam))]
    return np.abs(lam) / (2 * np.pi), -lam.real / np.abs(lam)


def _three_dof_frf() -> FRFData:
    m, c, k = _three_dof()
    freq = np.linspace(1.0, 200.0, 4000)
    w = 2 * np.pi * freq
    z = k[None] + 1j * w[:, None, None] * c[None] - (w**2)[:, None, None] * m[None]
    h = np.linalg.inv(z)[:, :, :2]  # 3 outputs x 2 inputs
    rng = np.random.default_rng(1)
    h = h * (1 + 0.01 * (rng.standard_normal(h.shape) + 1j * rng.standard_normal(h.shape)))
    return FRFData(freq, np.einsum("foi->oif", h), ("F1", "F2"), ("x1", "x2", "x3"), ("displacement",) * 3)


def _modal_row() -> dict[str, Any]:
    from sdypy import EMA

    frf = _three_dof_frf()
    flat = frf.H.reshape(-1, frf.freq.size)  # 6 FRFs for EMA (it treats them as one reference)
    single = FRFData(frf.freq, flat[:, None, :], ("F",), tuple(f"r{k}" for k in range(6)), ("displacement",) * 6)

    def ours(n_bootstrap: int = 0) -> Any:
        return extract_modes(single, band=(2.0, 190.0), max_order=40, method="lscf", n_bootstrap=n_bootstrap)

    mine = ours()

    def ema() -> Any:
        model = EMA.Model(frf=flat, freq=frf.freq, lower=2.0, upper=190.0, pol_order_high=20, frf_form="receptance")
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()), \
                warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model.get_poles(method="lscf", show_progress=False)
            model.select_closest_poles(list(mine.frequency))
            model.get_constants(method="lsfd", whose_poles="own")
        return model

    t_ours, t_ema = best(ours), best(ema)
    t_bootstrap = best(lambda: ours(30), repeat=1)
    ref = ema()
    truth_f, truth_z = _three_dof_truth()
    return {"case": "lscf_lsfd_6_frfs", "lines": int(frf.freq.size), "cappe_s": t_ours, "sdypy_ema_s": t_ema,
            "speedup": t_ema / t_ours, "cappe_with_30_bootstrap_s": t_bootstrap,
            "max_rel_frequency_difference": float(np.max(np.abs(np.asarray(ref.nat_freq) / mine.frequency - 1))),
            "max_rel_damping_difference": float(np.max(np.abs(np.asarray(ref.nat_xi) / mine.damping - 1))),
            "cappe_max_rel_frequency_error": float(np.max(np.abs(mine.frequency / truth_f - 1))),
            "cappe_max_rel_damping_error": float(np.max(np.abs(mine.damping / truth_z - 1))),
            "ema_max_rel_frequency_error": float(np.max(np.abs(np.asarray(ref.nat_freq) / truth_f - 1))),
            "ema_max_rel_damping_error": float(np.max(np.abs(np.asarray(ref.nat_xi) / truth_z - 1))),
            "note": "cappe selects poles automatically; EMA is given cappe's frequencies to pick its poles"}


def _arx_row() -> dict[str, Any]:
    rng = np.random.default_rng(2)
    n = 10_000
    u = rng.standard_normal((2, n))
    y = sig.lfilter([0, 1.0, 0.4], [1, -1.6, 0.9], u[0]) + sig.lfilter([0, 0.5], [1, -0.5, 0.6], u[1])
    y += 0.01 * np.std(y) * rng.standard_normal(n)
    data = TimeData.from_rate(2000.0, {"u1": u[0], "u2": u[1], "y": y})

    def fit() -> Any:
        return ARX(40, 40).fit(data, inputs=["u1", "u2"], output="y")

    t_fit = best(fit)
    model = fit()
    t_prune = best(lambda: prune(model, input="u1", n_modes=1))
    return {"case": "arx40_two_inputs", "samples": n, "parameters": model.n_parameters_, "fit_s": t_fit,
            "prune_s": t_prune}


def main() -> None:
    rows = [_frf_row(), _modal_row(), _arx_row()]
    for row in rows:
        print({k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()})
    write_results("identify", rows)


if __name__ == "__main__":
    main()
