"""State-space models, continuous and discrete (ZOH, FOH, Tustin), and their time responses.

**Intersample behaviour** (MATLAB's ``iddata.InterSample``): a sampled input says nothing about its values between
the samples; the response of a continuous model depends on what is assumed there. This module is the one place
where cappe turns an assumption into a discretization; :data:`INTERSAMPLE` lists them.

* ``"zoh"``: the input is held constant over each sample (a DAC or a PRBS). Exact discretization
  ``x[k+1] = e^{A h} x[k] + h phi1(A h) B u[k]``.
* ``"foh"``: the input is linear between samples (triangle hold, non-causal). Exact discretization
  ``x[k+1] = e^{A h} x[k] + h (phi1 - phi2)(A h) B u[k] + h phi2(A h) B u[k+1]`` with
  ``phi1(X) = (e^X - I) X^-1`` and ``phi2(X) = (e^X - I - X) X^-2``.
* ``"bl"``: the input is band-limited (no content at or above the Nyquist frequency), as a data-acquisition
  system with an anti-alias filter records it. The response is computed in the frequency domain,
  ``Y(omega) = (C (j omega I - A)^-1 B + D) U(omega)`` (the input is taken as zero before and after the record);
  it is exact for band-limited inputs up to the ringing of that start and end. In modal form
  (:func:`band_limited_modal_response`, the hot path) a sum of first-order terms on the DFT grid of the record
  padded by at most one record length, with the free decay that wraps around the circular grid removed exactly;
  for any transfer function (:func:`band_limited_response`) over a record padded until the slowest mode has
  decayed.

Data from a DAQ are band-limited: ``"bl"`` is the assumption that matches them; the ZOH of such data is wrong by
half a sample of delay, the FOH by a gain error of about ``(omega h)^2 / 12`` at ``omega``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cappe.exceptions import DataError, ModelError

__all__ = ["INTERSAMPLE", "StateSpaceModel", "band_limited_modal_response", "band_limited_response",
           "check_intersample", "hold_matrices", "hold_weights", "simulate"]

Array = NDArray[np.float64]
CArray = NDArray[np.complex128]

#: Intersample behaviours of a sampled input: zero-order hold, first-order hold, band-limited.
INTERSAMPLE = ("zoh", "foh", "bl")
#: Zero padding of a band-limited simulation: until the slowest mode has decayed to exp(-28) ~ 7e-13.
_BL_DECAYS = 28.0
#: Longest zero padding of a band-limited simulation: 4 record lengths or 2^18 samples, whichever is longer (a mode
#: that decays more slowly wraps around with exp(-decay_rate * padding) of its amplitude).
_BL_MAX_PAD = 1 << 18
#: Shortest zero padding of a modal band-limited simulation (samples): it holds the ringing of the record's end
#: (the band-limited interpolation of a step decays like 1 / k) away from its start.
_BL_MIN_PAD = 1024


def check_intersample(intersample: str) -> str:
    """``intersample`` if it is one of :data:`INTERSAMPLE`, else a DataError naming the choices.

    Parameters
    ----------
    intersample : str
        ``"zoh"``, ``"foh"`` or ``"bl"``.

    Returns
    -------
    str
        The same value.
    """
    if intersample not in INTERSAMPLE:
        msg = f"intersample must be one of {', '.join(INTERSAMPLE)} (the input between samples); got {intersample!r}"
        raise DataError(msg)
    return intersample


def _phi12(x: ArrayLike) -> tuple[CArray, CArray]:
    """``phi1(x) = (e^x - 1) / x`` and ``phi2(x) = (e^x - 1 - x) / x^2`` elementwise, without cancellation."""
    x = np.asarray(x, dtype=complex)
    small = np.abs(x) < 0.1
    xs = np.where(small, 1.0, x)
    phi1 = np.where(small, 1.0, np.expm1(xs) / xs)
    phi2 = np.where(small, 0.5, (phi1 - 1.0) / xs)
    if small.any():  # Taylor series: phi_j(x) = sum_k x^k / (k + j)!, 12 terms (error < 1e-20 at |x| = 0.1)
        xk = np.ones_like(x)
        s1, s2 = np.zeros_like(x), np.zeros_like(x)
        fact1, fact2 = 1.0, 2.0
        for k in range(12):
            s1 += xk / fact1
            s2 += xk / fact2
            xk = xk * x
            fact1 *= k + 2
            fact2 *= k + 3
        phi1 = np.where(small, s1, phi1)
        phi2 = np.where(small, s2, phi2)
    return phi1, phi2


def hold_weights(lam: ArrayLike, dt: float, intersample: str) -> tuple[CArray, CArray]:
    """Input weights of a first-order mode ``z' = lam z + u`` over one step of length ``dt``.

    ``z(t + dt) = e^{lam dt} z(t) + w_now u(t) + w_next u(t + dt)`` for an input held (``"zoh"``: ``w_next = 0``)
    or linear (``"foh"``) over the step; the diagonal form of :func:`hold_matrices`.

    Parameters
    ----------
    lam : array_like of complex, shape (m,)
        Eigenvalues (1/s).
    dt : float
        Step length in s (>= 0; 0 gives zero weights).
    intersample : {"zoh", "foh"}
        The input between the samples.

    Returns
    -------
    w_now, w_next : ndarray of complex, shape (m,)
        Weights of the input at the start and at the end of the step (s).

    Examples
    --------
    >>> w0, w1 = hold_weights([-1.0], 0.1, "zoh")
    >>> round(float(w0.real[0]), 6), float(w1.real[0])  # (1 - e^-0.1) / 1
    (0.095163, 0.0)
    """
    lam_arr = np.atleast_1d(np.asarray(lam, dtype=complex))
    phi1, phi2 = _phi12(lam_arr * dt)
    if intersample == "zoh":
        return np.asarray(dt * phi1), np.zeros_like(phi1)
    if intersample == "foh":
        return np.asarray(dt * (phi1 - phi2)), np.asarray(dt * phi2)
    msg = f"hold weights exist for intersample 'zoh' and 'foh'; got {intersample!r}"
    raise DataError(msg)


def hold_matrices(a: ArrayLike, b: ArrayLike, dt: float, intersample: str) -> tuple[Array, Array, Array]:
    """Exact discretization ``x[k+1] = Ad x[k] + B_now u[k] + B_next u[k+1]`` of ``x' = A x + B u``.

    One matrix exponential of ``[[A dt, B dt, 0], [0, 0, I], [0, 0, 0]]``, whose first block row is
    ``[e^{A dt}, dt phi1(A dt) B, dt phi2(A dt) B]`` (the construction of :func:`scipy.signal.cont2discrete`).

    Parameters
    ----------
    a : array_like, shape (n, n)
        State matrix (1/s).
    b : array_like, shape (n, n_in)
        Input matrix.
    dt : float
        Sample time in s.
    intersample : {"zoh", "foh"}
        The input between the samples.

    Returns
    -------
    ad : ndarray, shape (n, n)
    b_now, b_next : ndarray, shape (n, n_in)
        ``B_next`` is zero for a zero-order hold.

    Examples
    --------
    >>> ad, b0, b1 = hold_matrices([[-1.0]], [[1.0]], 0.1, "foh")
    >>> bool(np.isclose(b0[0, 0] + b1[0, 0], 1 - np.exp(-0.1)))  # a constant input: the ZOH weight
    True
    """
    import scipy.linalg as sla

    am, bm = np.atleast_2d(np.asarray(a, dtype=float)), np.atleast_2d(np.asarray(b, dtype=float))
    n, m = bm.shape
    if intersample not in ("zoh", "foh"):
        msg = f"hold matrices exist for intersample 'zoh' and 'foh'; got {intersample!r}"
        raise DataError(msg)
    big = np.zeros((n + 2 * m, n + 2 * m))
    big[:n, :n] = am * dt
    big[:n, n: n + m] = bm * dt
    big[n: n + m, n + m:] = np.eye(m)
    e = sla.expm(big)
    ad, g1, g2 = e[:n, :n], e[:n, n: n + m], e[:n, n + m:]
    if intersample == "zoh":
        return ad, g1, np.zeros_like(g1)
    return ad, g1 - g2, g2


def band_limited_response(
    transfer: Callable[[Array], CArray], u: ArrayLike, dt: float, decay_rate: float
) -> Array:
    """Response to a band-limited input, computed in the frequency domain over the zero-padded record.

    ``Y(omega) = H(omega) U(omega)`` on the DFT grid of the record padded with zeros for ``28 / decay_rate``
    seconds (the slowest mode decays by exp(-28) before the response wraps around), at least one record length and
    at most four or 2^18 samples, whichever is longer.
    At the Nyquist line (even lengths) the real part of ``H`` is used: a band-limited real signal has no
    quadrature component there.

    Parameters
    ----------
    transfer : callable
        ``transfer(omega)`` -> ndarray of complex, shape (n_omega, n_out, n_in): the continuous frequency
        response at ``omega`` (rad/s, >= 0).
    u : array_like, shape (n_samples, n_in)
        Input samples.
    dt : float
        Sample time in s.
    decay_rate : float
        Decay rate ``min(-Re lambda)`` of the slowest mode (1/s, > 0).

    Returns
    -------
    ndarray, shape (n_samples, n_out)
        Output samples.

    Examples
    --------
    >>> t = np.arange(4096) * 1e-3
    >>> u = np.sin(2 * np.pi * 50 * t)[:, None]
    >>> y = band_limited_response(lambda w: (1.0 / (1j * w + 10.0))[:, None, None], u, 1e-3, 10.0)
    >>> bool(abs(np.abs(y[2000:, 0]).max() - 1 / abs(2j * np.pi * 50 + 10)) < 1e-4)  # steady-state amplitude
    True
    """
    import scipy.fft as sfft

    uu = np.asarray(u, dtype=float)
    n = uu.shape[0]
    if not (np.isfinite(decay_rate) and decay_rate > 0):
        msg = (
            f"a band-limited simulation needs every mode to decay (decay rate > 0 1/s); got {decay_rate!r}: "
            "the model has an undamped or rigid mode, use intersample 'zoh' or 'foh'"
        )
        raise DataError(msg)
    pad = int(np.ceil(_BL_DECAYS / (decay_rate * dt)))
    total = sfft.next_fast_len(n + min(max(pad, n), max(_BL_MAX_PAD, 4 * n)), real=True)
    spec = sfft.rfft(uu, n=total, axis=0)  # (n_f, n_in)
    omega = 2 * np.pi * sfft.rfftfreq(total, dt)
    h = np.asarray(transfer(omega))
    if total % 2 == 0:
        h[-1] = h[-1].real
    y = sfft.irfft(np.einsum("foi,fi->fo", h, spec), n=total, axis=0)
    return np.asarray(y[:n], dtype=float)


def band_limited_modal_response(
    lam: ArrayLike, bm: ArrayLike, cm: ArrayLike, d: ArrayLike, u: ArrayLike, dt: float, *, delay: float = 0.0
) -> Array:
    """Response of a model in modal form to a band-limited input, as a sum of first-order terms.

    The model is ``z_i' = lam_i z_i + bm_i u``, ``y = Re(sum_i cm_i z_i) + D u`` (for a real system: every mode,
    or one member of each conjugate pair with its ``cm`` doubled), and the input is delayed by ``delay`` samples
    (a linear phase; fractional delays are exact). Each mode's response ``bm_i U(omega) / (j omega - lam_i)`` is
    evaluated on the DFT grid of the record padded with zeros for ``28 / decay_rate`` seconds (the slowest mode
    decays by exp(-28)), at most one record length and at least 1024 samples. A slower mode's free decay after
    the record wraps around the circular grid; it is a free response ``cm_i mu_i^k z_i(t0)`` of the modes whose
    state ``z_i(t0)`` in the middle of the padding the same spectrum gives, and it is subtracted exactly. The
    padding then only has to hold the band-limited ringing of the record's end and start apart.
    At the Nyquist line (even lengths) the real part of the response is used: a band-limited real signal has no
    quadrature component there. Cost: two real FFTs and O(n_freq x modes x (inputs + outputs)) products.

    Parameters
    ----------
    lam : array_like of complex, shape (m,)
        Eigenvalues (1/s), each with a negative real part.
    bm : array_like of complex, shape (m, n_in)
        Modal input matrix.
    cm : array_like of complex, shape (n_out, m)
        Modal output matrix.
    d : array_like, shape (n_out, n_in)
        Feed-through matrix.
    u : array_like, shape (n_samples, n_in)
        Input samples.
    dt : float
        Sample time in s.
    delay : float
        Input delay in samples (may be negative or fractional).

    Returns
    -------
    ndarray, shape (n_samples, n_out)
        Output samples.

    Examples
    --------
    >>> t = np.arange(4096) * 1e-3
    >>> u = np.sin(2 * np.pi * 50 * t)[:, None]
    >>> y = band_limited_modal_response([-10.0], [[1.0]], [[1.0]], [[0.0]], u, 1e-3)
    >>> bool(abs(np.abs(y[2000:, 0]).max() - 1 / abs(2j * np.pi * 50 + 10)) < 1e-4)  # steady-state amplitude
    True
    """
    import scipy.fft as sfft

    lam_a = np.atleast_1d(np.asarray(lam, dtype=complex))
    bm_a = np.asarray(bm, dtype=complex).reshape(lam_a.size, -1)
    cm_a = np.asarray(cm, dtype=complex).reshape(-1, lam_a.size)
    d_a = np.asarray(d, dtype=float).reshape(cm_a.shape[0], bm_a.shape[1])
    uu = np.asarray(u, dtype=float).reshape(-1, bm_a.shape[1])
    n = uu.shape[0]
    decay = float(np.min(-lam_a.real)) if lam_a.size else 1.0 / dt
    if not (np.isfinite(decay) and decay > 0):
        msg = (
            "a band-limited simulation needs every mode to decay (decay rate > 0 1/s); the model has an undamped "
            "or unstable mode, use intersample 'zoh' or 'foh'"
        )
        raise DataError(msg)
    shift = int(np.ceil(abs(delay)))
    pad = max(min(int(np.ceil(_BL_DECAYS / (decay * dt))), n), _BL_MIN_PAD) + 2 * shift
    total = sfft.next_fast_len(n + pad, real=True)
    spec = sfft.rfft(uu, n=total, axis=0)  # (n_f, n_in)
    omega = 2 * np.pi * sfft.rfftfreq(total, dt)
    jw = 1j * omega[:, None]
    phase = np.exp(-1j * omega * (delay * dt))[:, None]
    # products over the few inputs, modes and outputs by einsum's own loops: a threaded BLAS call on such thin
    # matrices costs more than it computes (7x on two busy cores)
    drive = np.einsum("fi,mi->fm", spec, bm_a) * phase  # (n_f, m): bm_i U(omega), delayed
    drive_conj = np.einsum("fi,mi->fm", spec, bm_a.conj()) * phase  # the conjugate modes' drive
    z = drive / (jw - lam_a[None, :])
    # each mode's conjugate partner (conj lam, conj bm, conj cm) makes the response real: y = (Y + conj Y) / 2
    spec_y = 0.5 * (np.einsum("fm,om->fo", z, cm_a)
                    + np.einsum("fm,om->fo", drive_conj / (jw - lam_a.conj()[None, :]), cm_a.conj()))
    spec_y += np.einsum("fi,oi->fo", spec * phase, d_a)
    if total % 2 == 0:
        spec_y[-1] = spec_y[-1].real
    y = sfft.irfft(spec_y, n=total, axis=0)[:n]
    if lam_a.size == 0:
        return np.asarray(y, dtype=float)
    # the modal states in the middle of the padding (sample s of the circular grid), from the full two-sided
    # spectrum: Z_i(-omega) = bm_i conj(U(omega)) e^{j omega delay dt} / (-j omega - lam_i); at Nyquist the mean
    # of both signs (the real-part convention above)
    s = n + (total - n) // 2
    weight = np.ones(omega.size)
    weight_neg = np.ones(omega.size)
    weight_neg[0] = 0.0
    if total % 2 == 0:
        weight[-1] = weight_neg[-1] = 0.5
    turn = np.exp(2j * np.pi * np.arange(omega.size) * (s / total))
    z_neg = drive_conj.conj() / (-jw - lam_a[None, :])
    state = (np.einsum("f,fm->m", weight * turn, z) + np.einsum("f,fm->m", weight_neg * turn.conj(), z_neg)) / total
    # the free decay from there wraps around to the record's samples k = 0..n-1, (total - s + k) samples later
    free = np.exp(np.outer(np.arange(n) * dt, lam_a)) * (np.exp(lam_a * ((total - s) * dt)) * state)[None, :]
    return np.asarray(y - np.einsum("km,om->ko", free, cm_a).real, dtype=float)


@dataclass(frozen=True)
class StateSpaceModel:
    """``x' = A x + B u, y = C x + D u`` (``dt is None``) or ``x[k+1] = A x[k] + B u[k]`` (sample time dt, s).

    Attributes
    ----------
    A : ndarray, shape (n, n)
        State matrix (1/s for a continuous model).
    B : ndarray, shape (n, n_in)
        Input matrix.
    C : ndarray, shape (n_out, n)
        Output matrix.
    D : ndarray, shape (n_out, n_in)
        Feed-through matrix.
    dt : float or None
        Sample time in s; None for a continuous model.
    state_names, input_names, output_names : tuple of str
        Labels of the states, inputs and outputs (may be empty).
    method : str
        How a discrete model was obtained (``"zoh"``, ``"foh"``, ``"tustin"``); empty otherwise.
    """

    A: Array
    B: Array
    C: Array
    D: Array
    dt: float | None = None
    state_names: tuple[str, ...] = ()
    input_names: tuple[str, ...] = ()
    output_names: tuple[str, ...] = ()
    method: str = ""

    @property
    def n_states(self) -> int:
        return int(self.A.shape[0])

    @property
    def is_discrete(self) -> bool:
        return self.dt is not None

    def poles(self) -> NDArray[np.complex128]:
        """Eigenvalues of A (rad/s for continuous, z-plane for discrete)."""
        return np.asarray(np.linalg.eigvals(self.A), dtype=complex)

    def discretize(self, dt: float, method: str = "zoh") -> StateSpaceModel:
        """Discrete model by zero-order hold (``"zoh"``), first-order hold (``"foh"``) or the bilinear transform
        (``"tustin"``).

        The first-order hold's discrete state is ``x[k] - B_next u[k]`` (:func:`hold_matrices`), so that the
        model is causal in that state: ``Bd = B_now + Ad B_next``, ``Dd = D + C B_next`` (as
        :func:`scipy.signal.cont2discrete` gives it).

        Parameters
        ----------
        dt : float
            Sample time in s, > 0.
        method : {"zoh", "foh", "tustin"}
            Discretization.

        Returns
        -------
        StateSpaceModel
            The discrete model.

        Raises
        ------
        ModelError
            The model is discrete already, ``dt`` is not positive or ``method`` unknown.
        """
        if self.is_discrete:
            msg = "model is already discrete"
            raise ModelError(msg)
        if not dt > 0:
            msg = f"sample time dt must be > 0 s; got {dt!r}"
            raise ModelError(msg)
        if method not in ("zoh", "foh", "tustin"):
            msg = f"discretization method must be 'zoh', 'foh' or 'tustin'; got {method!r}"
            raise ModelError(msg)
        if method == "foh":
            ad, b_now, b_next = hold_matrices(self.A, self.B, dt, method)
            return StateSpaceModel(ad, b_now + ad @ b_next, self.C.copy(), self.D + self.C @ b_next, float(dt),
                                   self.state_names, self.input_names, self.output_names, method)
        import scipy.signal as sig  # here: its import (0.6 s) would otherwise come with every file read (cappe.io)

        scipy_method = "bilinear" if method == "tustin" else "zoh"
        ad, bd, cd, dd, _ = sig.cont2discrete((self.A, self.B, self.C, self.D), dt, method=scipy_method)
        return StateSpaceModel(ad, bd, cd, dd, float(dt), self.state_names, self.input_names, self.output_names, method)

    def to_control(self) -> Any:
        """The equivalent python-control ``StateSpace``."""
        import control

        return control.ss(self.A, self.B, self.C, self.D, self.dt if self.dt is not None else 0)

    def to_dict(self) -> dict[str, Any]:
        return {
            "A": self.A.tolist(),
            "B": self.B.tolist(),
            "C": self.C.tolist(),
            "D": self.D.tolist(),
            "dt": self.dt,
            "method": self.method or None,
            "states": list(self.state_names),
            "inputs": list(self.input_names),
            "outputs": list(self.output_names),
        }

    def simulate(
        self,
        u: NDArray[np.floating[Any]],
        t: NDArray[np.floating[Any]] | None = None,
        x0: NDArray[np.floating[Any]] | None = None,
        intersample: str = "zoh",
    ) -> tuple[Array, Array]:
        """Time response; see :func:`simulate`.

        Parameters
        ----------
        u : ndarray, shape (n_samples, n_in) or (n_samples,)
            Inputs per sample.
        t : ndarray, shape (n_samples,), optional
            Uniform sample times in s (needed for a continuous model).
        x0 : ndarray, shape (n,), optional
            Initial state (default zero).
        intersample : {"zoh", "foh", "bl"}
            The input between the samples (continuous models; see the module notes).

        Returns
        -------
        y : ndarray, shape (n_samples, n_out)
        x : ndarray, shape (n_samples, n)
        """
        return simulate(self, u, t, x0, intersample=intersample)


def simulate(
    model: StateSpaceModel,
    u: NDArray[np.floating[Any]],
    t: NDArray[np.floating[Any]] | None = None,
    x0: NDArray[np.floating[Any]] | None = None,
    *,
    intersample: str = "zoh",
) -> tuple[Array, Array]:
    """Response ``y[k, out]`` and states ``x[k, state]`` to inputs ``u[k, in]``.

    For a continuous model ``t`` (uniform, s) is required and ``intersample`` says what the input does between
    the samples (module notes): held constant (``"zoh"``, the default: the result equals that of
    ``model.discretize(dt, "zoh")`` exactly), linear (``"foh"``) or band-limited (``"bl"``, frequency domain over
    the zero-padded record; the model must be stable). A discrete model ignores ``t`` and ``intersample``.

    Parameters
    ----------
    model : StateSpaceModel
        The model.
    u : ndarray, shape (n_samples, n_in) or (n_samples,)
        Inputs per sample.
    t : ndarray, shape (n_samples,), optional
        Uniform sample times in s (needed for a continuous model).
    x0 : ndarray, shape (n,), optional
        Initial state (default zero).
    intersample : {"zoh", "foh", "bl"}
        The input between the samples (continuous models).

    Returns
    -------
    y : ndarray, shape (n_samples, n_out)
        Outputs.
    x : ndarray, shape (n_samples, n)
        States.

    Examples
    --------
    >>> import numpy as np
    >>> m = StateSpaceModel(np.array([[-1.0]]), np.array([[1.0]]), np.array([[1.0]]), np.array([[0.0]]))
    >>> y, _ = simulate(m, np.ones((3, 1)), np.array([0.0, 0.1, 0.2]))
    >>> np.round(y[:, 0], 4)
    array([0.    , 0.0952, 0.1813])
    """
    uu = np.asarray(u, dtype=float)
    if uu.ndim == 1:
        uu = uu[:, None]
    if uu.ndim != 2 or uu.shape[1] != model.B.shape[1]:
        msg = f"inputs must have shape (n_samples, {model.B.shape[1]}); got {np.shape(u)}"
        raise DataError(msg)
    if not np.all(np.isfinite(uu)):
        bad = sorted({int(j) for j in np.where(~np.isfinite(uu))[1]})
        names = [model.input_names[j] if j < len(model.input_names) else str(j) for j in bad]
        msg = f"inputs contain NaN or Inf in channel(s) {', '.join(names)}"
        raise DataError(msg)
    disc = model
    if not model.is_discrete:
        if t is None:
            msg = "a continuous model needs the time vector t"
            raise DataError(msg)
        tt = np.asarray(t, dtype=float)
        if tt.shape != (uu.shape[0],):
            msg = f"t must have shape ({uu.shape[0]},); got {tt.shape}"
            raise DataError(msg)
        steps = np.diff(tt)
        if steps.size == 0 or np.any(steps <= 0) or not np.allclose(steps, steps.mean(), rtol=1e-6, atol=0):
            msg = "t must be strictly increasing with a uniform step"
            raise DataError(msg)
        check_intersample(intersample)
        dt = float(steps.mean())
        if intersample == "bl":
            return _band_limited(model, uu, dt, x0)
        if intersample == "foh":
            return _first_order_hold(model, uu, dt, x0)
        disc = model.discretize(dt, "zoh")
    x = np.zeros((uu.shape[0], disc.n_states))
    state = np.zeros(disc.n_states) if x0 is None else np.asarray(x0, dtype=float).copy()
    # state recursion in blocks: the loop is over samples but each step is a small BLAS call
    a_t = disc.A.T
    bu = uu @ disc.B.T
    for k in range(uu.shape[0]):
        x[k] = state
        state = state @ a_t + bu[k]
    y = x @ disc.C.T + uu @ disc.D.T
    return y, x


def _first_order_hold(model: StateSpaceModel, u: Array, dt: float, x0: Any) -> tuple[Array, Array]:
    """``x[k+1] = Ad x[k] + B_now u[k] + B_next u[k+1]`` from ``x0`` (the input is linear between samples)."""
    ad, b_now, b_next = hold_matrices(model.A, model.B, dt, "foh")
    x = np.zeros((u.shape[0], model.n_states))
    state = np.zeros(model.n_states) if x0 is None else np.asarray(x0, dtype=float).copy()
    a_t = ad.T
    bu = u @ b_now.T
    bu[:-1] += u[1:] @ b_next.T
    for k in range(u.shape[0]):
        x[k] = state
        state = state @ a_t + bu[k]
    return x @ model.C.T + u @ model.D.T, x


def _band_limited(model: StateSpaceModel, u: Array, dt: float, x0: Any) -> tuple[Array, Array]:
    """States and outputs for a band-limited input (:func:`band_limited_modal_response`, or
    :func:`band_limited_response` for a defective state matrix), plus the free response."""
    n = model.n_states
    x = np.zeros((u.shape[0], n))
    if n:
        lam, vec = np.linalg.eig(model.A)
        if np.any(lam.real >= 0):
            msg = "a band-limited simulation needs a stable model (every pole in the left half-plane)"
            raise DataError(msg)
        if np.linalg.cond(vec) < 1e10:  # modal form: x = V z over every mode (the imaginary parts cancel)
            x = band_limited_modal_response(lam, np.linalg.solve(vec, model.B.astype(complex)), vec,
                                            np.zeros((n, u.shape[1])), u, dt)
        else:  # a defective state matrix: (j omega I - A)^-1 B solved per frequency
            eye = np.eye(n)

            def states(omega: Array) -> CArray:  # (n_f, n, n_in)
                return np.asarray(np.linalg.solve(1j * omega[:, None, None] * eye[None] - model.A[None],
                                                  model.B[None]))

            x = band_limited_response(states, u, dt, float(np.min(-lam.real)))
    if x0 is not None:
        ad = model.discretize(dt, "zoh").A
        free = np.asarray(x0, dtype=float).copy()
        for k in range(u.shape[0]):
            x[k] += free
            free = ad @ free
    return x @ model.C.T + u @ model.D.T, x
