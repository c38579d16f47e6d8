"""SSI-COV (output-only modal analysis) against a 3-DOF chain simulated here from its physics.

The reference is independent of cappe: the chain's matrices are written out, its exact complex modes come from
numpy's eigen-solver of the state matrix, and its responses to an unmeasured force are simulated mode by mode
(exact zero-order-hold discretization of each complex first-order mode, scipy.signal.lfilter), with a force
coloured by a low-pass filter and 5 % sensor noise.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from cappe.exceptions import DataError
from cappe.identify import ssi_cov
from cappe.systems.timedata import TimeData

FS = 1000.0


def _chain() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """M, C, K of a 3-mass chain fixed at one end, with non-proportional damping."""
    m = np.diag([1.0, 1.5, 2.0])
    k1, k2, k3 = 4.0e5, 3.0e5, 2.0e5
    k = np.array([[k1 + k2, -k2, 0.0], [-k2, k2 + k3, -k3], [0.0, -k3, k3]])
    c = np.array([[30.0, -10.0, 0.0], [-10.0, 25.0, -5.0], [0.0, -5.0, 12.0]])
    return m, c, k


def _truth() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Exact modes (frequency Hz, damping ratio, displacement shapes), and the state eigenvectors and poles."""
    m, c, k = _chain()
    n = 3
    minv = np.linalg.inv(m)
    a = np.block([[np.zeros((n, n)), np.eye(n)], [-minv @ k, -minv @ c]])
    lam, vec = np.linalg.eig(a)
    up = np.flatnonzero(lam.imag > 0)
    up = up[np.argsort(np.abs(lam[up]))]
    w = np.abs(lam[up])
    return w / (2 * np.pi), -lam[up].real / w, vec[:n, up], lam, vec


def _simulate(seconds: float, rng: int, *, noise: float = 0.05) -> TimeData:
    """Displacements of the chain under a low-pass coloured random force at every mass (unmeasured)."""
    m, _, _ = _chain()
    gen = np.random.default_rng(rng)
    n_samples = int(seconds * FS)
    sos = signal.butter(2, 300.0, fs=FS, output="sos")  # the force's colour
    force = signal.sosfilt(sos, gen.standard_normal((3, n_samples)), axis=1)
    _, _, _, lam, vec = _truth()
    b = np.vstack([np.zeros((3, 3)), np.linalg.inv(m)])
    gamma = np.linalg.solve(vec, b)  # modal inputs
    dt = 1.0 / FS
    mu = np.exp(lam * dt)
    y = np.zeros((3, n_samples))
    for j in range(6):  # each complex mode: x[t+1] = mu x[t] + (mu - 1) / lam gamma u[t] (zero-order hold)
        u = ((mu[j] - 1) / lam[j]) * (gamma[j] @ force)
        x = signal.lfilter([0.0, 1.0], [1.0, -mu[j]], u)
        y += np.real(vec[:3, j][:, None] * x[None, :])
    y += noise * np.std(y, axis=1, keepdims=True) * gen.standard_normal(y.shape)
    return TimeData.from_rate(FS, {"d1": y[0], "d2": y[1], "d3": y[2]})


def test_ssi_cov_recovers_the_exact_modes_of_a_simulated_chain() -> None:
    freq, zeta, shapes, _, _ = _truth()
    modes = ssi_cov(_simulate(300.0, 1), band=(5.0, 400.0), orders=range(2, 31, 2), block_rows=30)
    assert modes.n_modes == 3
    # tolerances: over seeds 0-3 of this 300 s record the errors were at most 0.1 % in frequency, 4 % in damping
    # and 5e-6 in 1 - MAC; the bounds leave a factor 2-3 (frequency, damping) and 20 (MAC)
    np.testing.assert_allclose(modes.frequency, freq, rtol=3e-3)
    np.testing.assert_allclose(modes.damping, zeta, rtol=0.1)
    macs = [abs(np.vdot(shapes[:, r], modes.shapes[:, r])) ** 2
            / (np.vdot(shapes[:, r], shapes[:, r]).real * np.vdot(modes.shapes[:, r], modes.shapes[:, r]).real)
            for r in range(3)]
    assert min(macs) > 0.9999
    assert modes.output_names == ("d1", "d2", "d3")
    assert modes.diagram.n_poles > 0
    assert modes.to_dict()["method"] == "ssi-cov"


def test_ssi_cov_scatter_over_seeds_is_small_and_unbiased() -> None:
    freq, _, _, _, _ = _truth()
    found = np.array([ssi_cov(_simulate(120.0, seed), band=(5.0, 400.0), orders=range(2, 25, 2),
                              block_rows=25, near=freq).frequency for seed in range(6)])
    bias = np.mean(found, axis=0) / freq - 1
    spread = np.std(found, axis=0, ddof=1) / freq
    # a bias of more than 3 standard errors of the mean (plus 0.05 % for the order choice) would be a defect
    assert np.all(np.abs(bias) <= 3 * spread / np.sqrt(6) + 5e-4), (bias, spread)


def test_ssi_cov_single_reference_channel() -> None:
    freq, _, _, _, _ = _truth()
    modes = ssi_cov(_simulate(300.0, 2), references=["d3"], band=(5.0, 400.0), orders=range(2, 25, 2),
                    block_rows=40, near=freq)
    np.testing.assert_allclose(modes.frequency, freq, rtol=5e-3)


def test_ssi_cov_errors() -> None:
    data = _simulate(2.0, 3)
    with pytest.raises(DataError, match=r"output channel\(s\) \['F1'\] not in the data"):
        ssi_cov(data, outputs=["F1"])
    with pytest.raises(DataError, match="allow model orders up to 30"):
        ssi_cov(data, orders=[2, 40], block_rows=10)
    with pytest.raises(DataError, match="too few for 60 block rows"):
        ssi_cov(data, block_rows=60, orders=[2, 4])
    with pytest.raises(DataError, match="orders must be ascending"):
        ssi_cov(data, orders=[4, 2])


def test_correlations_direct_and_fft_agree() -> None:
    from cappe.identify._ssi import _correlations

    y = np.random.default_rng(4).standard_normal((2, 3000))
    direct = _correlations(y, y[:1], 40)
    by_fft = _correlations(y, y[:1], 300)[:41]
    np.testing.assert_allclose(direct, by_fft, atol=1e-12)  # two exact evaluations of the same sums
