"""Output-only modal analysis: covariance-driven stochastic subspace identification (SSI-COV).

Responses recorded in operation, under an unmeasured broadband excitation, are the output of a linear system
driven by (coloured) noise. Their output correlations ``R_k = E[y_{t+k} y_ref,t^T]`` factor as
``R_k = C A^(k-1) G`` (Peeters and De Roeck 1999), so the block Toeplitz matrix of correlations

    T = [[R_i,      R_(i-1), ..., R_1    ],
         [R_(i+1),  R_i,     ..., R_2    ],
         ...
         [R_(2i-1), ...,          R_i    ]]      (n_out i x n_ref i)

is the product of the observability matrix ``O = [C; C A; ...; C A^(i-1)]`` and the reversed controllability
matrix. A truncated SVD ``T ~ U_n S_n V_n^T`` gives ``O = U_n S_n^(1/2)`` for every model order ``n``; ``C`` is its
first block row and ``A`` follows from the shift structure (``O[:-l] A = O[l:]``, least squares). The discrete
eigenvalues ``mu`` of ``A`` give the continuous poles ``s = fs ln(mu)``, the mode shapes are ``C psi`` at the
output channels (complex, unscaled: without a measured force the modal mass and participation are unknown).

Models of increasing order go into the stabilization diagram of :func:`cappe.identify.stabilization_diagram` (with
the mode shapes as the vectors of its MAC test) and the physical modes are picked by :func:`select_poles`, as for
LSCF. The correlations are estimated with the unbiased estimator; a white-noise force's
spectral colour does not matter as long as it excites every mode of the band (its own poles, of a coloured force,
are outside the band or too damped to stabilize).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg as sla
from numpy.typing import NDArray

from cappe.exceptions import DataError
from cappe.identify._lscf import PoleSelection, StabilizationDiagram, select_poles, stabilization_diagram
from cappe.systems.timedata import TimeData

__all__ = ["OperationalModes", "ssi_cov"]

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]


@dataclass(frozen=True)
class OperationalModes:
    """Modes identified from responses only (no force).

    Attributes
    ----------
    frequency : ndarray, shape (m,)
        Natural frequencies ``|s| / 2 pi`` in Hz, ascending.
    damping : ndarray, shape (m,)
        Damping ratios ``-Re s / |s|``.
    shapes : ndarray of complex, shape (n_out, m)
        Mode shapes at the output channels, unit norm, largest component real and positive. Not mass-normalized:
        without a measured force their scale is unknown.
    output_names : tuple of str
        The channels of the shape rows.
    diagram : StabilizationDiagram
        The stabilization diagram the modes were selected from (vectors: the mode shapes).
    selection : PoleSelection
        The selected poles (order, support in the diagram).
    block_rows : int
        Block rows ``i`` of the Toeplitz matrix.
    singular_values : ndarray
        Singular values of the Toeplitz matrix (their drop shows the model order the data support).
    """

    frequency: FloatArray
    damping: FloatArray
    shapes: ComplexArray
    output_names: tuple[str, ...]
    diagram: StabilizationDiagram
    selection: PoleSelection
    block_rows: int
    singular_values: FloatArray

    @property
    def n_modes(self) -> int:
        return int(self.frequency.size)

    @property
    def poles(self) -> ComplexArray:
        """Continuous poles (rad/s), upper half plane."""
        return np.asarray(self.selection.poles, dtype=complex)

    def to_dict(self) -> dict[str, Any]:
        return {
            "method": "ssi-cov",
            "outputs": list(self.output_names),
            "block_rows": self.block_rows,
            "frequency": self.frequency.tolist(),
            "damping": self.damping.tolist(),
            "shape_re": self.shapes.real.T.tolist(),
            "shape_im": self.shapes.imag.T.tolist(),
            "support": self.selection.support.tolist(),
        }


def _correlations(y: FloatArray, ref: FloatArray, max_lag: int) -> FloatArray:
    """Unbiased correlations ``R[k] = sum_t y[:, t+k] ref[:, t]^T / (N - k)``, k = 0 .. max_lag; (lags, l, r).

    Direct products (a few matrix products per lag) for the short lags SSI needs; the FFT for long ones."""
    n = y.shape[1]
    if max_lag <= 256:
        return np.asarray([y[:, k:] @ ref[:, : n - k].T / (n - k) for k in range(max_lag + 1)], dtype=float)
    size = 1 << int(np.ceil(np.log2(2 * n)))
    fy = np.fft.rfft(y, size, axis=1)
    fr = np.fft.rfft(ref, size, axis=1)
    cross = np.fft.irfft(fy[:, None, :] * fr[None, :, :].conj(), size, axis=2)[:, :, : max_lag + 1]
    return np.asarray(np.moveaxis(cross, 2, 0) / (n - np.arange(max_lag + 1))[:, None, None], dtype=float)


def _normalized(shapes: ComplexArray) -> ComplexArray:
    """Unit-norm columns, each turned so that its largest component is real and positive."""
    out = shapes / np.linalg.norm(shapes, axis=0, keepdims=True)
    big = out[np.argmax(np.abs(out), axis=0), np.arange(out.shape[1])]
    return np.asarray(out * (big.conj() / np.abs(big))[None, :], dtype=complex)


def ssi_cov(
    data: TimeData,
    *,
    outputs: Sequence[str] | None = None,
    references: Sequence[str] | None = None,
    band: Sequence[float] | None = None,
    block_rows: int | None = None,
    orders: Sequence[int] | None = None,
    near: Sequence[float] | None = None,
    min_fraction: float = 0.5,
    freq_tol: float = 0.01,
    damping_tol: float = 0.1,
    mac_tol: float = 0.95,
    max_damping: float = 0.1,
) -> OperationalModes:
    """Modes from output-only time data by covariance-driven stochastic subspace identification (see the notes).

    Parameters
    ----------
    data : TimeData
        Responses recorded under an unmeasured, broadband excitation (SI units).
    outputs : sequence of str, optional
        Response channels (default every channel of ``data``).
    references : sequence of str, optional
        Reference channels of the correlations (default all outputs; fewer references make the Toeplitz
        matrix smaller).
    band : (float, float), optional
        Band in Hz of the modes kept (default 0 to the Nyquist frequency); poles outside are excluded.
    block_rows : int, optional
        Block rows ``i`` of the Toeplitz matrix; ``n_out i`` bounds the model order (default: enough for the
        highest order, and at least a period of the lowest band frequency).
    orders : sequence of int, optional
        Model orders of the stabilization diagram, ascending and even (default 2, 4, ..., 40).
    near : sequence of float, optional
        Frequencies (Hz) of the modes wanted: select the stable poles near them instead of clustering
        (:func:`select_poles`).
    min_fraction : float
        Fraction of the orders a cluster of stable poles must appear in to be a mode (automatic selection).
    freq_tol, damping_tol, mac_tol, max_damping : float
        Stability tolerances of the diagram (:func:`stabilization_diagram`).

    Returns
    -------
    OperationalModes

    Raises
    ------
    DataError
        A channel is missing, the record is too short for the Toeplitz matrix, an order exceeds what the
        block rows allow, or no mode stabilizes.

    Examples
    --------
    >>> import numpy as np
    >>> from scipy import signal
    >>> fs, f0, zeta = 200.0, 12.0, 0.02
    >>> w0 = 2 * np.pi * f0
    >>> sos = signal.zpk2sos([], np.exp(np.array([-zeta * w0 + 1j * w0 * np.sqrt(1 - zeta**2),
    ...                                          -zeta * w0 - 1j * w0 * np.sqrt(1 - zeta**2)]) / fs), 1.0)
    >>> y = signal.sosfilt(sos, np.random.default_rng(1).standard_normal(40000))
    >>> modes = ssi_cov(TimeData.from_rate(fs, {"y": y}), band=(5, 50), orders=range(2, 13, 2), block_rows=20)
    >>> round(float(modes.frequency[0]), 1)
    12.0
    """
    names = tuple(outputs) if outputs is not None else tuple(data.channels)
    refs = tuple(references) if references is not None else names
    for what, group in (("output", names), ("reference", refs)):
        missing = [c for c in group if c not in data.channels]
        if missing or not group:
            msg = (f"ssi_cov: {what} channel(s) {missing or '(none given)'} not in the data; channels: "
                   f"{list(data.channels)}")
            raise DataError(msg)
    order_list = [int(n) for n in (orders if orders is not None else range(2, 41, 2))]
    if not order_list or min(order_list) < 2 or np.any(np.diff(order_list) <= 0):
        msg = f"ssi_cov: orders must be ascending integers >= 2; got {order_list}"
        raise DataError(msg)
    fs = data.fs
    f_band = (0.0, fs / 2) if band is None else (float(band[0]), float(band[1]))
    if not 0 <= f_band[0] < f_band[1]:
        msg = f"ssi_cov: band must be (f_lo, f_hi) Hz with 0 <= f_lo < f_hi; got {band!r}"
        raise DataError(msg)
    n_out, n_ref = len(names), len(refs)
    if block_rows is None:
        period = int(np.ceil(fs / max(f_band[0], fs / 200)))  # a period of the lowest band frequency (<= 200 rows)
        block_rows = max(int(np.ceil(max(order_list) / min(n_out, n_ref))) + 1, min(period, 200))
    i = int(block_rows)
    if i < 2 or max(order_list) > min(n_out, n_ref) * i:
        msg = (f"ssi_cov: block_rows {i} allow model orders up to {min(n_out, n_ref) * i} "
               f"(outputs x block rows); got orders up to {max(order_list)}")
        raise DataError(msg)
    if data.n_samples < 20 * 2 * i:
        msg = (f"ssi_cov: {data.n_samples} samples are too few for {i} block rows (need at least {40 * i}); "
               f"record longer or lower block_rows")
        raise DataError(msg)
    y = np.asarray([data.channel(c) for c in names], dtype=float)
    ref = np.asarray([data.channel(c) for c in refs], dtype=float)
    y = y - y.mean(axis=1, keepdims=True)
    ref = ref - ref.mean(axis=1, keepdims=True)
    if not np.all(np.isfinite(y)) or not np.all(np.isfinite(ref)):
        msg = "ssi_cov: the data contain NaN or Inf"
        raise DataError(msg)
    scale = np.std(y, axis=1)  # channels of different units and size weigh alike; shapes are scaled back
    scale_ref = np.std(ref, axis=1)
    if np.any(scale == 0) or np.any(scale_ref == 0):
        dead = [c for c, s in zip(names, scale, strict=True) if s == 0]
        msg = f"ssi_cov: channel(s) {dead or list(refs)} carry no signal"
        raise DataError(msg)
    corr = _correlations(y / scale[:, None], ref / scale_ref[:, None], 2 * i)
    # T[a, b] = R[i + a - b] for block row a, block column b (a, b = 0 .. i-1)
    lags = i + np.arange(i)[:, None] - np.arange(i)[None, :]
    toeplitz = corr[lags].transpose(0, 2, 1, 3).reshape(n_out * i, n_ref * i)
    u, sv, _ = sla.svd(toeplitz, full_matrices=False)
    all_poles, all_shapes = [], []
    for n in order_list:
        obs = u[:, :n] * np.sqrt(sv[:n])[None, :]
        a_mat = np.linalg.lstsq(obs[:-n_out], obs[n_out:], rcond=None)[0]
        c_mat = obs[:n_out]
        mu, psi = np.linalg.eig(a_mat)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.log(mu.astype(complex)) * fs
        ok = np.isfinite(s) & (np.abs(mu) > 0)
        all_poles.append(s[ok])
        all_shapes.append((c_mat @ psi)[:, ok] * scale[:, None])
    diagram = stabilization_diagram(orders=order_list, poles=all_poles, participation=all_shapes, band=f_band,
                                    input_names=names, freq_tol=freq_tol, damping_tol=damping_tol, mac_tol=mac_tol,
                                    max_damping=max_damping)
    selection = select_poles(diagram, near=near, min_fraction=min_fraction)
    shapes = _normalized(np.asarray(selection.participation, dtype=complex))
    return OperationalModes(np.asarray(selection.frequency, dtype=float), np.asarray(selection.damping, dtype=float),
                            shapes, names, diagram, selection, i, np.asarray(sv, dtype=float))
