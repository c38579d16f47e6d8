"""Poles from FRFs: least-squares complex-frequency (LSCF) and poly-reference LSCF (PolyMAX) estimators,
stabilization diagrams and automatic pole selection by clustering.

The estimators fit, for each model order ``n``, a discrete-time rational model in ``z = exp(-1j omega dt)``
(Guillaume et al. 2003; Peeters et al., PolyMAX, 2004):

* ``"common"`` (LSCF): every FRF ``H_k`` (each output/input pair) is ``B_k(z) / a(z)`` with one scalar
  denominator ``a(z) = sum_j a_j z**j`` common to all FRFs;
* ``"poly"`` (poly-reference LSCF, a right matrix-fraction model): every output row
  ``H_o = B_o(z) A(z)**-1`` with a matrix denominator ``A(z) = sum_j A_j z**j`` of size ``n_in x n_in``; its
  poles come with modal participation vectors (one entry per input).

All coefficients are real, so poles come in complex-conjugate pairs as they must for real-valued time
responses. The numerator coefficients are eliminated from the normal equations (reduced normal equations
``M alpha = 0``); the highest denominator coefficient is fixed to the identity. Continuous poles follow from
the roots as ``s = -ln(z) / dt``.

Pruning follows the rules of Nickel (1999, section 4.7): poles above the band (beyond what the data can
show) and poles with unrealistically high damping are excluded, and so are unstable poles (negative damping);
the remaining ones are kept only when they recur across model orders (stabilization).

Frequency scaling: ``dt = 1 / (2 f_hi)`` with ``f_hi`` the upper edge of the band, so that the band
``[f_lo, f_hi]`` maps onto the arc ``omega dt in [pi f_lo / f_hi, pi]`` of the unit circle and every pole below
``f_hi`` has a unique discrete image. Each output row (``"poly"``) or FRF (``"common"``) is scaled to unit RMS over
the band so that outputs of different size or unit weigh alike.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import scipy.cluster.hierarchy as sch
import scipy.linalg as sla
from numpy.typing import ArrayLike, NDArray

from cappe.correlate import mac
from cappe.exceptions import DataError
from cappe.systems.frf import FRFData

__all__ = [
    "PoleSelection",
    "StabilizationDiagram",
    "lscf_poles",
    "select_poles",
    "stabilization_diagram",
]

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]


# -- validation -----------------------------------------------------------------------------------------------
def _check_frf(frf: FRFData) -> tuple[FloatArray, ComplexArray]:
    """Frequency axis and FRF array of ``frf``: at least 2 lines, finite, >= 0 and strictly increasing."""
    freq = np.asarray(frf.freq, dtype=float)
    H = np.asarray(frf.H)
    if freq.ndim != 1 or freq.size < 2:
        msg = f"FRF frequency axis must be 1-D with at least 2 lines; got shape {freq.shape}"
        raise DataError(msg)
    if not np.all(np.isfinite(freq)) or np.any(np.diff(freq) <= 0) or freq[0] < 0:
        msg = (
            f"FRF frequencies must be finite, >= 0 Hz and strictly increasing; got "
            f"{freq[0]:g} .. {freq[-1]:g} Hz with {int(np.sum(np.diff(freq) <= 0))} non-increasing steps"
        )
        raise DataError(msg)
    return freq, H.astype(complex)  # shapes and window_decay are checked by FRFData itself


def _band_lines(freq: FloatArray, band: Sequence[float]) -> tuple[tuple[float, float], NDArray[np.intp]]:
    """Validated band (Hz) and the indices of the frequency lines inside it."""
    try:
        f_lo, f_hi = (float(b) for b in band)
    except (TypeError, ValueError) as exc:
        msg = f"band must be a pair (f_lo, f_hi) in Hz; got {band!r}"
        raise DataError(msg) from exc
    lo, hi = float(freq[0]), float(freq[-1])
    # a band that overshoots the data by less than one line (the same band given to the FRF estimator, whose
    # lines fall inside it) is clipped to the data
    step = float(np.median(np.diff(freq))) if freq.size > 1 else 0.0
    if lo - step <= f_lo < lo:
        f_lo = lo
    if hi < f_hi <= hi + step:
        f_hi = hi
    if not (np.isfinite(f_lo) and np.isfinite(f_hi)) or f_lo >= f_hi or f_lo < lo or f_hi > hi or f_lo < 0:
        msg = (
            f"band ({f_lo:g}, {f_hi:g}) Hz must satisfy 0 <= f_lo < f_hi and lie inside the data's frequency "
            f"range [{lo:g}, {hi:g}] Hz"
        )
        raise DataError(msg)
    idx = np.flatnonzero((freq >= f_lo) & (freq <= f_hi))
    return (f_lo, f_hi), idx


def _check_finite(H: ComplexArray, freq: FloatArray, frf: FRFData) -> None:
    """``H`` (n_out, n_in, n_lines) at the frequencies ``freq`` (Hz) must be finite."""
    bad = ~np.isfinite(H)
    if bad.any():
        o, i, k = (int(v) for v in np.argwhere(bad)[0])
        msg = (
            f"FRF {frf.output_names[o]}/{frf.input_names[i]} contains NaN or Inf in the band "
            f"(first at {float(freq[k]):g} Hz)"
        )
        raise DataError(msg)


def _check_positive(value: float, name: str, *, upper: float | None = None) -> float:
    v = float(value)
    if not np.isfinite(v) or v <= 0 or (upper is not None and v > upper):
        rule = f"in (0, {upper:g}]" if upper is not None else "> 0"
        msg = f"{name} must be {rule}; got {value!r}"
        raise DataError(msg)
    return v


# -- stabilization diagram ------------------------------------------------------------------------------------
def _pole_frequency_damping(poles: ComplexArray) -> tuple[FloatArray, FloatArray]:
    wn = np.abs(poles)
    safe = np.where(wn > 0, wn, 1.0)
    return wn / (2 * np.pi), np.where(wn > 0, -poles.real / safe, 0.0)


def _pair_mac(a: ComplexArray, b: ComplexArray) -> FloatArray:
    """Column-wise MAC of two (n, k) arrays."""
    num = np.abs(np.sum(a.conj() * b, axis=0)) ** 2
    den = np.sum(np.abs(a) ** 2, axis=0) * np.sum(np.abs(b) ** 2, axis=0)
    return np.asarray(np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0), dtype=float)


@dataclass(frozen=True)
class StabilizationDiagram:
    """Poles of a family of models of increasing order, with stability flags.

    All per-pole arrays are flat (one entry per pole, all orders together); ``order`` says which model each
    pole belongs to. Only poles in the upper half plane are kept (one of each conjugate pair); real poles are
    dropped.

    Attributes
    ----------
    orders : tuple of int
        Model orders, ascending.
    order : ndarray of int, shape (n_poles,)
        Model order of each pole.
    poles : ndarray of complex, shape (n_poles,)
        Continuous-time poles in rad/s, corrected for an exponential window when the FRFs had one.
    frequency : ndarray, shape (n_poles,)
        Natural frequencies ``|s| / 2 pi`` in Hz.
    damping : ndarray, shape (n_poles,)
        Damping ratios ``-Re s / |s|``.
    participation : ndarray of complex, shape (n_in, n_poles)
        Modal participation vectors (unit norm) of the poly-reference model; a row of ones for a common
        denominator model (then the vector test always passes).
    flags : ndarray of str, shape (n_poles,)
        ``"o"`` new/unstable, ``"f"`` frequency stable, ``"d"`` frequency and damping stable, ``"v"`` frequency
        and vector stable, ``"s"`` all three stable, ``"x"`` excluded. A pole is compared with the nearest
        non-excluded pole of the previous order.
    excluded : ndarray of str, shape (n_poles,)
        Why a pole was excluded (``"negative damping"``, ``"damping above cap"``, ``"outside band"``), else ``""``.
    band : tuple of float
        Frequency band (Hz).
    reference : str
        ``"poly"`` or ``"common"`` (or ``"external"`` for poles given to :func:`stabilization_diagram`).
    input_names : tuple of str
        Inputs (references) the participation vectors refer to.
    tolerances : dict
        ``freq_tol``, ``damping_tol``, ``mac_tol`` and ``max_damping`` used for the flags.
    """

    orders: tuple[int, ...]
    order: NDArray[np.int64]
    poles: ComplexArray
    frequency: FloatArray
    damping: FloatArray
    participation: ComplexArray
    flags: NDArray[np.str_]
    excluded: NDArray[np.str_]
    band: tuple[float, float]
    reference: str
    input_names: tuple[str, ...]
    tolerances: Mapping[str, float]

    @property
    def n_poles(self) -> int:
        return int(self.poles.size)

    def at_order(self, order: int) -> NDArray[np.intp]:
        """Indices of the poles of one model order.

        Parameters
        ----------
        order : int
            The model order.

        Returns
        -------
        ndarray of int
            Indices into the pole arrays.
        """
        return np.flatnonzero(self.order == order)

    def stable(self, flag: str = "s") -> NDArray[np.intp]:
        """Indices of the poles carrying ``flag``.

        Parameters
        ----------
        flag : {"s", "v", "d", "f", "o", "x"}
            Stability flag (see ``flags``; default all three stable).

        Returns
        -------
        ndarray of int
            Indices into the pole arrays.
        """
        return np.flatnonzero(self.flags == flag)

    def with_tolerances(
        self,
        *,
        freq_tol: float | None = None,
        damping_tol: float | None = None,
        mac_tol: float | None = None,
        max_damping: float | None = None,
    ) -> StabilizationDiagram:
        """The same poles flagged with other tolerances (None keeps the current value).

        Parameters
        ----------
        freq_tol, damping_tol : float, optional
            Largest relative change of frequency and damping ratio to the nearest pole of the previous order.
        mac_tol : float, optional
            Smallest MAC between the participation vectors of the two poles (0..1).
        max_damping : float, optional
            Poles damped more than this damping ratio are excluded.

        Returns
        -------
        StabilizationDiagram

        Raises
        ------
        DataError
            A tolerance is out of range.
        """
        tol = dict(self.tolerances)
        for key, value in (
            ("freq_tol", freq_tol),
            ("damping_tol", damping_tol),
            ("mac_tol", mac_tol),
            ("max_damping", max_damping),
        ):
            if value is not None:
                tol[key] = value
        return _flagged(
            self.orders,
            self.order,
            self.poles,
            self.participation,
            band=self.band,
            reference=self.reference,
            input_names=self.input_names,
            **tol,
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": "cappe.stabilization/1",
            "reference": self.reference,
            "band": [float(b) if np.isfinite(b) else None for b in self.band],
            "inputs": list(self.input_names),
            "tolerances": dict(self.tolerances),
            "orders": list(self.orders),
            "order": self.order.tolist(),
            "frequency": self.frequency.tolist(),
            "damping": self.damping.tolist(),
            "flag": self.flags.tolist(),
            "excluded": self.excluded.tolist(),
        }


def _flagged(
    orders: tuple[int, ...],
    order: NDArray[np.int64],
    poles: ComplexArray,
    participation: ComplexArray,
    *,
    band: tuple[float, float],
    reference: str,
    input_names: tuple[str, ...],
    freq_tol: float,
    damping_tol: float,
    mac_tol: float,
    max_damping: float,
) -> StabilizationDiagram:
    freq_tol = _check_positive(freq_tol, "freq_tol")
    damping_tol = _check_positive(damping_tol, "damping_tol")
    mac_tol = _check_positive(mac_tol, "mac_tol", upper=1.0)
    max_damping = _check_positive(max_damping, "max_damping", upper=1.0)
    frequency, damping = _pole_frequency_damping(poles)
    excluded = np.full(poles.size, "", dtype=object)
    excluded[(frequency < band[0]) | (frequency > band[1])] = "outside band"
    excluded[damping > max_damping] = "damping above cap"
    excluded[damping < 0] = "negative damping"
    valid = excluded == ""
    flags = np.where(valid, "o", "x").astype(object)
    for prev, cur in zip(orders[:-1], orders[1:], strict=True):
        here = np.flatnonzero((order == cur) & valid)
        there = np.flatnonzero((order == prev) & valid)
        if here.size == 0 or there.size == 0:
            continue
        # nearest pole of the previous order (in the complex plane, i.e. mostly by frequency)
        nearest = there[np.argmin(np.abs(poles[here, None] - poles[None, there]), axis=1)]
        f_ok = np.abs(frequency[here] - frequency[nearest]) <= freq_tol * frequency[nearest]
        d_ok = np.abs(damping[here] - damping[nearest]) <= damping_tol * np.abs(damping[nearest])
        v_ok = _pair_mac(participation[:, here], participation[:, nearest]) >= mac_tol
        code = np.where(
            f_ok & d_ok & v_ok, "s", np.where(f_ok & d_ok, "d", np.where(f_ok & v_ok, "v", np.where(f_ok, "f", "o")))
        )
        flags[here] = code
    return StabilizationDiagram(
        orders=orders,
        order=order,
        poles=poles,
        frequency=frequency,
        damping=damping,
        participation=participation,
        flags=flags.astype(str),
        excluded=excluded.astype(str),
        band=band,
        reference=reference,
        input_names=input_names,
        tolerances={"freq_tol": freq_tol, "damping_tol": damping_tol, "mac_tol": mac_tol, "max_damping": max_damping},
    )


def stabilization_diagram(
    *,
    orders: Sequence[int],
    poles: Sequence[ArrayLike],
    participation: Sequence[ArrayLike] | None = None,
    band: Sequence[float] | None = None,
    input_names: Sequence[str] = (),
    freq_tol: float = 0.01,
    damping_tol: float = 0.05,
    mac_tol: float = 0.98,
    max_damping: float = 0.2,
) -> StabilizationDiagram:
    """Stabilization diagram of poles from models of increasing order (from any estimator).

    Parameters
    ----------
    orders : sequence of int, length n_orders
        Model orders, strictly ascending.
    poles : sequence of array_like of complex
        Continuous poles (rad/s) of each model; poles with negative imaginary part and real poles are dropped
        (conjugates).
    participation : sequence of array_like of complex, optional
        Participation (or mode shape) vectors of each model, shape (n_vec, n_poles_k), in the order of the poles.
        Without them the vector test always passes.
    band : (float, float), optional
        Band (Hz); poles outside are excluded. Default: no limit.
    input_names : sequence of str
        Labels of the vector entries.
    freq_tol, damping_tol : float
        Largest relative change of frequency (default 1 %) and damping ratio (5 %) to the nearest pole of the
        previous order for a pole to count as frequency / damping stable.
    mac_tol : float
        Smallest MAC between the vectors of the two poles for a vector-stable pole (default 0.98).
    max_damping : float
        Poles damped more than this (default 0.2) are excluded, as are poles with negative damping.

    Returns
    -------
    StabilizationDiagram

    Raises
    ------
    DataError
        If the orders are not strictly ascending, the list lengths differ, a vector array does not fit its
        poles, the band is reversed, or a tolerance is out of range.

    Examples
    --------
    >>> import numpy as np
    >>> lam = -0.5 + 2j * np.pi * 10.0
    >>> d = stabilization_diagram(orders=[2, 4, 6], poles=[[lam], [lam * 1.001], [lam * 1.0012, -1 + 200j]])
    >>> d.flags.tolist()
    ['o', 's', 's', 'o']
    """
    orders_t = tuple(int(n) for n in orders)
    if len(orders_t) == 0 or any(b <= a for a, b in zip(orders_t[:-1], orders_t[1:], strict=True)):
        msg = f"orders must be a non-empty, strictly ascending list of model orders; got {list(orders_t)}"
        raise DataError(msg)
    if len(poles) != len(orders_t):
        msg = f"poles must hold one array per order ({len(orders_t)}); got {len(poles)}"
        raise DataError(msg)
    if participation is not None and len(participation) != len(orders_t):
        msg = f"participation must hold one array per order ({len(orders_t)}); got {len(participation)}"
        raise DataError(msg)
    all_poles: list[ComplexArray] = []
    all_vec: list[ComplexArray] = []
    all_order: list[NDArray[np.int64]] = []
    n_vec = 1
    for k, n in enumerate(orders_t):
        p = np.atleast_1d(np.asarray(poles[k], dtype=complex))
        if p.ndim != 1 or not np.all(np.isfinite(p)):
            msg = f"poles of order {n} must be a 1-D array of finite complex numbers"
            raise DataError(msg)
        if participation is None:
            v = np.ones((1, p.size), dtype=complex)
        else:
            v = np.asarray(participation[k], dtype=complex)
            if v.ndim != 2 or v.shape[1] != p.size or (k > 0 and v.shape[0] != n_vec):
                msg = (
                    f"participation of order {n} must have shape (n_vec, {p.size}) with the same n_vec for all "
                    f"orders; got {v.shape}"
                )
                raise DataError(msg)
            n_vec = v.shape[0]
        keep = p.imag > 0
        all_poles.append(p[keep])
        all_vec.append(v[:, keep])
        all_order.append(np.full(int(keep.sum()), n, dtype=np.int64))
    vec = np.concatenate(all_vec, axis=1)
    f_band = (0.0, np.inf) if band is None else (float(band[0]), float(band[1]))
    if not f_band[0] < f_band[1]:
        msg = f"band must be (f_lo, f_hi) with f_lo < f_hi in Hz; got {band!r}"
        raise DataError(msg)
    return _flagged(
        orders_t,
        np.concatenate(all_order),
        np.concatenate(all_poles),
        vec,
        band=f_band,
        reference="external",
        input_names=tuple(input_names),
        freq_tol=freq_tol,
        damping_tol=damping_tol,
        mac_tol=mac_tol,
        max_damping=max_damping,
    )


# -- the estimator --------------------------------------------------------------------------------------------
def _lag_sums(z: ComplexArray, data: ComplexArray, max_lag: int) -> ComplexArray:
    """``sum_f z_f**l * data[..., f]`` for l = -max_lag .. max_lag; output shape (2 max_lag + 1, ...)."""
    powers = z[None, :] ** np.arange(-max_lag, max_lag + 1)[:, None]
    return np.asarray(np.tensordot(powers, data, axes=([1], [-1])), dtype=complex)


def _reduced_normal_equations(rows: ComplexArray, z: ComplexArray, p: int) -> tuple[FloatArray, FloatArray]:
    """Build the pieces of the reduced normal equations up to order ``p``.

    ``rows`` has shape (n_rows, n_ref, n_f): output rows of the right matrix-fraction model. For row o the
    equation error is ``X beta_o + Y_o alpha`` with ``X = [z**0 .. z**p]`` and ``Y_o = -kron(X, H_o)``; with
    real coefficients the normal matrices are ``R = Re X^H X``, ``S_o = Re X^H Y_o``, ``T_o = Re Y_o^H Y_o``.
    Eliminating ``beta_o`` leaves ``M = sum_o (T_o - S_o^T R^-1 S_o)``. Returns ``T = sum_o T_o`` (m, m), built
    from lag sums (it is Toeplitz in the power index), and ``C`` (p+1, m, m) where ``C[n]`` is
    ``sum_o S_o^T R^-1 S_o`` for the model of order n, both indexed ``[j * n_ref + a]`` (power j, reference a):
    the reduced matrix of order n is the leading block ``T - C[n]``.

    ``S_o^T R^-1 S_o = G_o^T G_o`` with ``G_o = Q^T Y_o`` and ``Q`` the orthonormal factor of the (real-stacked)
    ``X``. Its columns are nested in the order, so one QR serves every order; unlike a Cholesky factor of R it
    stays usable when the monomials are numerically dependent on a short arc of the unit circle (narrow bands).

    ``G`` is one real product ``[Re W, -Im W] @ [Re H; Im H]`` with ``W[(j, k), f] = conj(Qc[f, j]) z_f**k``,
    which does not depend on the data: half the arithmetic of the complex product ``Qc^H Y`` and without the
    (n_f, p+1, n_rows n_ref) array ``Y`` (measured, 60 rows x 3 references, 1401 lines, order 38, one thread: the
    product 0.25 s -> 0.04 s, the whole build 0.19 s -> 0.09 s; what a bootstrap over the extraction repeats per
    replicate). ``W`` is built for a few powers k
    at a time so that it stays below ~64 MB.
    """
    n_rows, n_ref, n_f = rows.shape
    m = (p + 1) * n_ref
    lag = np.arange(p + 1)[None, :] - np.arange(p + 1)[:, None] + p  # k - j + p, indexed [j, k]
    cross = rows.conj()[:, :, None, :] * rows[:, None, :, :]  # (n_rows, a, b, n_f)
    t_lags = _lag_sums(z, cross.sum(axis=0), p).real  # (2p+1, a, b)
    T = t_lags[lag].transpose(0, 2, 1, 3).reshape(m, m)  # [j*n_ref + a, k*n_ref + b]
    powers = z[:, None] ** np.arange(p + 1)[None, :]  # X, (n_f, p+1)
    q, _ = np.linalg.qr(np.concatenate([powers.real, powers.imag], axis=0))
    qc_h = (q[:n_f] - 1j * q[n_f:]).T  # Qc^H, (p+1, n_f)
    # Y_o[f, k*n_ref + b] = -z_f**k H_ob(f); G_o = Re(Qc^H Y_o), all rows and powers k in real products
    h = rows.transpose(2, 0, 1).reshape(n_f, n_rows * n_ref)
    h_stacked = np.concatenate([h.real, h.imag], axis=0)  # (2 n_f, o*b)
    g4 = np.empty((p + 1, p + 1, n_rows * n_ref))  # [j, k, o*b]
    step = max(1, int(4e6 // ((p + 1) * n_f)))
    for k0 in range(0, p + 1, step):
        w = qc_h[:, None, :] * powers.T[None, k0:k0 + step, :]  # [j, k, f]
        w = np.concatenate([w.real, -w.imag], axis=2).reshape(-1, 2 * n_f)
        g4[:, k0:k0 + step] = -(w @ h_stacked).reshape(p + 1, -1, n_rows * n_ref)
    G = g4.reshape(p + 1, p + 1, n_rows, n_ref).transpose(0, 2, 1, 3).reshape(p + 1, n_rows, m)
    C = np.cumsum(np.matmul(G.transpose(0, 2, 1), G), axis=0)
    return T, C


def _order_poles(T: FloatArray, C_n: FloatArray, n: int, n_ref: int) -> tuple[ComplexArray, ComplexArray]:
    """Roots z (n * n_ref) and left null vectors (n_ref, n * n_ref) of the denominator of order n."""
    m = (n + 1) * n_ref
    k = n * n_ref
    M = T[:m, :m] - C_n[:m, :m]
    M = 0.5 * (M + M.T)
    # over-modelled orders make M nearly singular by construction (extra computational poles): that is expected
    # and harmless for the physical poles, so scipy's ill-conditioning warning is not passed on
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sla.LinAlgWarning)
        try:
            alpha = sla.solve(M[:k, :k], -M[:k, k:], assume_a="sym", check_finite=False)
        except np.linalg.LinAlgError:
            alpha = np.linalg.lstsq(M[:k, :k], -M[:k, k:], rcond=None)[0]
    if not np.all(np.isfinite(alpha)):
        alpha = np.linalg.lstsq(M[:k, :k], -M[:k, k:], rcond=None)[0]
    # A(z) = sum_j z^j A_j with A_n = I; alpha stacks A_0 .. A_{n-1}. Poles: det A(z)^T = 0 via block companion.
    blocks = alpha.reshape(n, n_ref, n_ref).transpose(0, 2, 1)  # A_j^T
    comp = np.zeros((k, k))
    if n > 1:
        comp[: k - n_ref, n_ref:] = np.eye(k - n_ref)
    comp[k - n_ref :, :] = -np.concatenate(list(blocks), axis=1)
    roots, vecs = np.linalg.eig(comp)
    return roots, vecs[:n_ref]


def lscf_poles(
    frf: FRFData,
    *,
    band: Sequence[float],
    max_order: int = 40,
    orders: Iterable[int] | None = None,
    reference: str = "poly",
    freq_tol: float = 0.01,
    damping_tol: float = 0.05,
    mac_tol: float = 0.98,
    max_damping: float = 0.2,
) -> StabilizationDiagram:
    """Poles of LSCF models of increasing order and their stabilization diagram.

    Parameters
    ----------
    frf : FRFData
        FRFs ``H[out, in, freq]`` (any output quantity). If ``frf.window_decay`` (s) is set, every pole is
        corrected for the exponential window: ``s + 1 / window_decay``.
    band : (float, float)
        Frequency band in Hz; only lines inside it are used, ``dt = 1 / (2 f_hi)``.
    max_order : int
        Highest denominator order; used when ``orders`` is None, giving ``orders = range(2, max_order + 1, 2)``.
    orders : iterable of int, optional
        Denominator orders (polynomial degree n: n poles for ``"common"``, n * n_in for ``"poly"``).
    reference : {"poly", "common"}
        Poly-reference (right matrix-fraction, with participation vectors) or common-denominator model.
    freq_tol, damping_tol, mac_tol, max_damping : float
        Stability tolerances and the damping cap, see :func:`stabilization_diagram`.

    Returns
    -------
    StabilizationDiagram

    Raises
    ------
    DataError
        If the band is reversed or outside the data's frequency range, the data are not finite, the band holds
        too few lines for the highest order, an order is < 1, or ``reference`` is unknown.

    Examples
    --------
    >>> import numpy as np
    >>> from cappe.systems.frf import FRFData
    >>> f = np.linspace(0.0, 100.0, 501)
    >>> lam = -0.3 + 2j * np.pi * 40.0
    >>> s = 2j * np.pi * f
    >>> H = (1 / (s - lam) + 1 / (s - lam.conjugate()))[None, None]
    >>> d = lscf_poles(FRFData(f, H, ("F",), ("a",)), band=(5.0, 80.0), max_order=8)
    >>> k = d.stable()[-1]
    >>> round(float(d.frequency[k]), 4), round(float(d.damping[k]), 6)
    (40.0, 0.001194)
    """
    freq, H = _check_frf(frf)
    f_band, idx = _band_lines(freq, band)
    if reference not in ("poly", "common"):
        msg = f"reference must be 'poly' or 'common'; got {reference!r}"
        raise DataError(msg)
    try:
        order_list = sorted({int(n) for n in (range(2, int(max_order) + 1, 2) if orders is None else orders)})
    except (TypeError, ValueError) as exc:
        msg = f"model orders must be integers; got orders={orders!r}, max_order={max_order!r}"
        raise DataError(msg) from exc
    if not order_list or order_list[0] < 1:
        msg = f"model orders must be integers >= 1; got {order_list or 'none'} (max_order={max_order!r})"
        raise DataError(msg)
    p = order_list[-1]
    n_out, n_in, _ = H.shape
    Hb = H[:, :, idx]
    _check_finite(Hb, freq[idx], frf)
    if reference == "poly":
        rows = Hb
    else:
        rows = Hb.reshape(n_out * n_in, 1, idx.size)
    if 2 * idx.size <= p + 1:
        msg = (
            f"band ({f_band[0]:g}, {f_band[1]:g}) Hz holds {idx.size} frequency lines; model order {p} needs "
            f"more than {(p + 1) // 2}"
        )
        raise DataError(msg)
    rms = np.sqrt(np.mean(np.abs(rows) ** 2, axis=(1, 2)))
    used = rms > 0
    if not used.any():
        msg = "all FRFs are zero in the band; no poles can be estimated"
        raise DataError(msg)
    rows = rows[used] / rms[used, None, None]
    n_ref = rows.shape[1]
    dt = 1.0 / (2.0 * f_band[1])
    z = np.exp(-1j * 2 * np.pi * freq[idx] * dt)
    T, C = _reduced_normal_equations(rows, z, p)
    shift = 0.0 if frf.window_decay is None else 1.0 / float(frf.window_decay)
    pole_list: list[ComplexArray] = []
    vec_list: list[ComplexArray] = []
    for n in order_list:
        roots, vecs = _order_poles(T, C[n], n, n_ref)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = -np.log(roots.astype(complex)) / dt + shift
        finite = np.isfinite(s)
        s, vecs = s[finite], vecs[:, finite]
        norm = np.linalg.norm(vecs, axis=0)
        vecs = vecs / np.where(norm > 0, norm, 1.0)
        order_idx = np.argsort(np.abs(s))
        pole_list.append(s[order_idx])
        vec_list.append(vecs[:, order_idx])
    diagram = stabilization_diagram(
        orders=order_list,
        poles=pole_list,
        participation=vec_list if reference == "poly" else None,
        band=f_band,
        freq_tol=freq_tol,
        damping_tol=damping_tol,
        mac_tol=mac_tol,
        max_damping=max_damping,
    )
    return replace(
        diagram, reference=reference, input_names=tuple(frf.input_names) if reference == "poly" else ("common",)
    )


# -- pole selection -------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PoleSelection:
    """Physical poles chosen from a stabilization diagram, ascending in frequency.

    Attributes
    ----------
    poles : ndarray of complex, shape (n_modes,)
        Poles in rad/s (upper half plane).
    frequency : ndarray, shape (n_modes,)
        Natural frequencies in Hz.
    damping : ndarray, shape (n_modes,)
        Damping ratios.
    participation : ndarray of complex, shape (n_in, n_modes)
        Participation vectors of the chosen poles (unit norm).
    order : ndarray of int, shape (n_modes,)
        Model order each representative pole was taken from.
    support : ndarray of int, shape (n_modes,)
        Number of model orders in which the pole's cluster has a stable pole.
    """

    poles: ComplexArray
    frequency: FloatArray
    damping: FloatArray
    participation: ComplexArray
    order: NDArray[np.int64]
    support: NDArray[np.int64]

    @property
    def n_modes(self) -> int:
        return int(self.poles.size)

    def to_dict(self) -> dict[str, Any]:
        return {
            "modes": [
                {"frequency": float(f), "damping": float(d), "order": int(n), "support": int(c)}
                for f, d, n, c in zip(self.frequency, self.damping, self.order, self.support, strict=True)
            ]
        }


def _cluster_distance(diagram: StabilizationDiagram, idx: NDArray[np.intp]) -> FloatArray:
    """Pairwise distance ``|s_i - s_j| / max(|s_i|, |s_j|) + (1 - MAC_ij)`` of the poles ``idx``."""
    p = diagram.poles[idx]
    v = diagram.participation[:, idx]
    rel = np.abs(p[:, None] - p[None, :]) / np.maximum(np.abs(p)[:, None], np.abs(p)[None, :])
    d = rel + (1.0 - mac(v, v))
    np.fill_diagonal(d, 0.0)
    return np.asarray(np.maximum(0.5 * (d + d.T), 0.0), dtype=float)


def _representative(diagram: StabilizationDiagram, members: NDArray[np.intp]) -> int:
    """The member closest to the cluster's median frequency and damping (relative distances)."""
    f, d = diagram.frequency[members], diagram.damping[members]
    f_med, d_med = np.median(f), np.median(d)
    score = np.abs(f - f_med) / f_med + np.abs(d - d_med) / max(abs(float(d_med)), 1e-12)
    return int(members[np.argmin(score)])


def _selection(diagram: StabilizationDiagram, chosen: list[int], support: list[int]) -> PoleSelection:
    ids = np.asarray(chosen, dtype=np.intp)
    sort = np.argsort(diagram.frequency[ids], kind="stable")
    ids = ids[sort]
    return PoleSelection(
        poles=diagram.poles[ids],
        frequency=diagram.frequency[ids],
        damping=diagram.damping[ids],
        participation=diagram.participation[:, ids],
        order=diagram.order[ids],
        support=np.asarray(support, dtype=np.int64)[sort],
    )


def select_poles(
    diagram: StabilizationDiagram,
    *,
    near: Sequence[float] | None = None,
    n_modes: int | None = None,
    min_fraction: float = 0.3,
    distance: float = 0.02,
    window: float = 0.05,
) -> PoleSelection:
    """Physical poles from a stabilization diagram: automatic by clustering, or near given frequencies.

    Automatic (``near=None``): the stable poles (flag ``"s"``) of all orders are clustered hierarchically
    (average linkage) with the distance ``|s_i - s_j| / max(|s_i|, |s_j|) + (1 - MAC_ij)`` cut at ``distance``;
    a cluster is a physical mode when it has stable poles in at least ``min_fraction`` of the model orders after
    the first (which has nothing to be stable against); with ``n_modes``, the ``n_modes`` clusters present in most
    orders are kept instead. Each cluster is represented
    by the member pole closest to its median frequency and damping.

    Manual (``near=[f1, f2, ...]`` Hz): for each frequency, the stable poles within the relative ``window``
    (default 5 %) of it form the cluster, represented as above.

    Parameters
    ----------
    diagram : StabilizationDiagram
    near : sequence of float, optional
        Approximate natural frequencies (Hz) for manual selection.
    n_modes : int, optional
        Number of modes to keep in automatic selection.
    min_fraction : float
        Fraction of model orders a cluster must appear in (automatic selection without ``n_modes``).
    distance : float
        Cut-off of the cluster distance (dimensionless).
    window : float
        Relative frequency window for manual selection.

    Returns
    -------
    PoleSelection
        Ascending in frequency.

    Raises
    ------
    DataError
        If no stable pole is near a requested frequency, fewer clusters than ``n_modes`` exist, no cluster
        qualifies, or an argument is out of range.

    Examples
    --------
    >>> import numpy as np
    >>> lam = -0.5 + 2j * np.pi * 10.0
    >>> d = stabilization_diagram(orders=[2, 4, 6, 8], poles=[[lam]] * 4)
    >>> sel = select_poles(d)
    >>> round(float(sel.frequency[0]), 6), sel.support.tolist()
    (10.000317, [3])
    """
    stable = diagram.stable("s")
    if near is not None:
        window = _check_positive(window, "window", upper=1.0)
        targets = np.atleast_1d(np.asarray(near, dtype=float))
        if targets.ndim != 1 or targets.size == 0 or not np.all(np.isfinite(targets)) or np.any(targets <= 0):
            msg = f"near must be a non-empty list of frequencies > 0 Hz; got {near!r}"
            raise DataError(msg)
        chosen, support = [], []
        for f0 in targets:
            members = stable[np.abs(diagram.frequency[stable] - f0) <= window * f0]
            if members.size == 0:
                msg = (
                    f"no stable pole within {100 * window:g} % of {f0:g} Hz in the stabilization diagram "
                    f"(band {diagram.band[0]:g} .. {diagram.band[1]:g} Hz); raise the model order or widen window"
                )
                raise DataError(msg)
            chosen.append(_representative(diagram, members))
            support.append(int(np.unique(diagram.order[members]).size))
        return _selection(diagram, chosen, support)

    min_fraction = _check_positive(min_fraction, "min_fraction", upper=1.0)
    distance = _check_positive(distance, "distance")
    if n_modes is not None and (int(n_modes) != n_modes or n_modes < 1):
        msg = f"n_modes must be a positive integer; got {n_modes!r}"
        raise DataError(msg)
    if stable.size == 0:
        msg = "the stabilization diagram has no stable poles; raise the model order or check the band"
        raise DataError(msg)
    if stable.size == 1:
        labels = np.ones(1, dtype=int)
    else:
        dist = _cluster_distance(diagram, stable)
        tree = sch.linkage(dist[np.triu_indices(stable.size, 1)], method="average")
        labels = sch.fcluster(tree, t=distance, criterion="distance")
    clusters = [stable[labels == lab] for lab in np.unique(labels)]
    counts = np.array([np.unique(diagram.order[c]).size for c in clusters])
    n_orders = len(diagram.orders)
    if n_modes is not None:
        if len(clusters) < n_modes:
            msg = f"n_modes={n_modes} requested but the stable poles form only {len(clusters)} clusters"
            raise DataError(msg)
        keep = np.argsort(-counts, kind="stable")[: int(n_modes)]
    else:
        keep = np.flatnonzero(counts >= min_fraction * (n_orders - 1))
        if keep.size == 0:
            msg = (
                f"no pole cluster is stable in at least {100 * min_fraction:g} % of the {n_orders} model orders "
                f"(best: {int(counts.max())}); raise the model order or lower min_fraction"
            )
            raise DataError(msg)
    chosen = [_representative(diagram, clusters[k]) for k in keep]
    return _selection(diagram, chosen, [int(counts[k]) for k in keep])
