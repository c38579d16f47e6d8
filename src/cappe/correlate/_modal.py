"""Mode-shape and modal-parameter correlation criteria: MAC, MACX, MACXP, NFD and NDD."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cappe.correlate._validate import as_finite_array, as_poles, as_shapes, check_same_sensors, first_index
from cappe.exceptions import DataError

__all__ = ["mac", "macx", "macxp", "macxp_batch", "macxp_paired", "ndd", "nfd"]


def _shape_sets(phi_a: ArrayLike, phi_x: ArrayLike) -> tuple[NDArray[Any], NDArray[Any]]:
    a = as_shapes(phi_a, "phi_a")
    x = as_shapes(phi_x, "phi_x")
    check_same_sensors(a, x)
    return a, x


def _norm2(phi: NDArray[Any]) -> NDArray[np.float64]:
    """``phi_r^H phi_r`` for every column r."""
    return np.asarray(np.sum(np.abs(phi) ** 2, axis=0), dtype=np.float64)


def mac(phi_a: ArrayLike, phi_x: ArrayLike) -> NDArray[np.float64]:
    """Modal assurance criterion between every pair of mode shapes.

    ``MAC[i, j] = |a_i^H x_j|^2 / ((a_i^H a_i) (x_j^H x_j))``.

    Parameters
    ----------
    phi_a : array_like, shape (n_sensors, n_a) or (n_sensors,)
        First set of shapes (e.g. analytical), real or complex, one mode per column. A 1-D array is one shape.
    phi_x : array_like, shape (n_sensors, n_x) or (n_sensors,)
        Second set of shapes (e.g. experimental) at the same sensors.

    Returns
    -------
    ndarray, shape (n_a, n_x)
        MAC values in [0, 1] (dimensionless), always 2-D.

    Raises
    ------
    DataError
        If an array is not numeric, not finite, not 1-D or 2-D, empty, has an all-zero column, or the
        sensor counts differ.

    Examples
    --------
    >>> import numpy as np
    >>> from cappe.correlate import mac
    >>> phi = np.array([[1.0, 1.0], [1.0, -1.0]])
    >>> mac(phi, phi)
    array([[1., 0.],
           [0., 1.]])
    >>> mac([1.0, 0.0], [1.0, 1.0])
    array([[0.5]])
    """
    a, x = _shape_sets(phi_a, phi_x)
    cross = np.abs(a.conj().T @ x) ** 2
    return np.asarray(cross / np.outer(_norm2(a), _norm2(x)), dtype=np.float64)


def macx(phi_a: ArrayLike, phi_x: ArrayLike) -> NDArray[np.float64]:
    """Extended modal assurance criterion MACX for complex shapes (Vacher, Jacquier & Bucharles, ISMA 2010).

    ``MACX[i, j] = (|a_i^H x_j| + |a_i^T x_j|)^2 / ((a_i^H a_i + |a_i^T a_i|) (x_j^H x_j + |x_j^T x_j|))``.
    It is the largest squared correlation of the real responses ``Re(a e^{i t})`` and ``Re(x e^{i s})``
    over the phases ``t`` and ``s``, and it equals the MAC for real shapes.

    Parameters
    ----------
    phi_a : array_like, shape (n_sensors, n_a) or (n_sensors,)
        First set of shapes, real or complex, one mode per column. A 1-D array is one shape.
    phi_x : array_like, shape (n_sensors, n_x) or (n_sensors,)
        Second set of shapes at the same sensors.

    Returns
    -------
    ndarray, shape (n_a, n_x)
        MACX values in [0, 1] (dimensionless), always 2-D.

    Raises
    ------
    DataError
        On the same invalid input as `mac`.

    Examples
    --------
    >>> import numpy as np
    >>> from cappe.correlate import mac, macx
    >>> a = np.array([1.0, 1.0j])  # a circular shape: Re(a e^{it}) passes through x at t = 0
    >>> x = np.array([1.0, 0.0])
    >>> mac(a, x), macx(a, x)
    (array([[0.5]]), array([[1.]]))
    """
    a, x = _shape_sets(phi_a, phi_x)
    num = (np.abs(a.conj().T @ x) + np.abs(a.T @ x)) ** 2
    den_a = _norm2(a) + np.abs(np.sum(a * a, axis=0))
    den_x = _norm2(x) + np.abs(np.sum(x * x, axis=0))
    return np.asarray(num / np.outer(den_a, den_x), dtype=np.float64)


def macxp(phi_a: ArrayLike, lam_a: ArrayLike, phi_x: ArrayLike, lam_x: ArrayLike) -> NDArray[np.float64]:
    """Pole-weighted extended modal assurance criterion MACXP between every pair of modes.

    Vacher, Jacquier & Bucharles (ISMA 2010); eq. (4) of Ellinger & Zaeh (2022). For every pair (i, j),
    with ``s = |Re lam|``::

        num = (|a_i^H x_j| / |conj(lam_a_i) + lam_x_j| + |a_i^T x_j| / |lam_a_i + lam_x_j|)^2
        den = (a_i^H a_i / (2 s_a_i) + |a_i^T a_i| / (2 |lam_a_i|))
              * (x_j^H x_j / (2 s_x_j) + |x_j^T x_j| / (2 |lam_x_j|))
        MACXP[i, j] = num / den

    It is the largest squared correlation over ``t >= 0`` of the free decays of the two modes, so it
    lies in [0, 1] and weighs shape similarity with pole proximity.

    Parameters
    ----------
    phi_a : array_like, shape (n_sensors, n_a) or (n_sensors,)
        First set of complex (or real) shapes, one mode per column. A 1-D array is one shape.
    lam_a : array_like, shape (n_a,) or scalar
        Poles of ``phi_a`` in rad/s, ``lam = -zeta omega + i omega sqrt(1 - zeta^2)``.
    phi_x : array_like, shape (n_sensors, n_x) or (n_sensors,)
        Second set of shapes at the same sensors.
    lam_x : array_like, shape (n_x,) or scalar
        Poles of ``phi_x`` in rad/s.

    Returns
    -------
    ndarray, shape (n_a, n_x)
        MACXP of every mode of ``a`` with every mode of ``x`` (dimensionless, in [0, 1]), always 2-D.

    Raises
    ------
    DataError
        On the invalid shapes listed under `mac`, and if a pole array is not finite, not 1-D, has a
        length other than the number of shape columns, or contains a zero pole.

    Notes
    -----
    Conventions accepted:

    - The sign of ``Re lam`` does not matter: every pole is taken as ``-|Re lam| + i Im lam`` (the paper's
      denominator already uses ``|Re lam|``), so a "positive decay rate" convention gives the same numbers.
    - A mode may be given by either member of its conjugate pair, ``(phi, lam)`` or ``(conj(phi), conj(lam))``:
      the result is the same.

    Undamped poles (``Re lam = 0``) make both numerator and denominator infinite. The value returned is the
    limit as the damping goes to zero; it is computed from the criterion multiplied through by
    ``4 s_a s_x``, which is finite everywhere:

    - an undamped mode against a damped one, or two undamped modes at different poles: 0;
    - two undamped modes at the same pole ``lam_a == lam_x`` (compared exactly): the MAC
      ``|a^H x|^2 / (a^H a x^H x)``; for ``lam_a == conj(lam_x)``, ``|a^T x|^2 / (a^H a x^H x)``.
      This is the limit along equal damping of both modes (``s_a = s_x -> 0``); along
      ``s_a / s_x -> r`` it would be ``4 r / (1 + r)^2`` times that. So MACXP of a set with itself has a
      unit diagonal also for undamped modes, but it jumps from the MAC to 0 as soon as two undamped
      poles differ at all; give a small damping where a graded measure is wanted.

    Examples
    --------
    Real shapes at equal poles give the MAC; separating the poles lowers the MACXP.

    >>> import numpy as np
    >>> from cappe.correlate import macxp
    >>> phi = np.array([1.0, 0.5])
    >>> lam = -1.0 + 100.0j
    >>> macxp(phi, lam, phi, lam)
    array([[1.]])
    >>> macxp(phi, lam, phi, -1.0 + 102.0j).round(3)
    array([[0.504]])
    """
    a, x = _shape_sets(phi_a, phi_x)
    la = as_poles(lam_a, "lam_a", a.shape[1], "phi_a")
    lx = as_poles(lam_x, "lam_x", x.shape[1], "phi_x")
    return _macxp_core(np.abs(a.conj().T @ x), np.abs(a.T @ x), _column_terms(a, la, 1), _column_terms(x, lx, 0))


def macxp_paired(
    phi_a: NDArray[Any], lam_a: NDArray[Any], phi_x: NDArray[Any], lam_x: NDArray[Any]
) -> NDArray[np.float64]:
    """MACXP of paired modes, column r of ``phi_a`` with column r of ``phi_x``, over batches.

    The hot-path form of :func:`macxp` for sensitivity analysis: no input validation, leading axes
    broadcast. Undamped poles follow the same limits as :func:`macxp`.

    Parameters
    ----------
    phi_a : ndarray, shape (..., n_sensors, n_modes)
        Shapes (e.g. of a batch of model evaluations).
    lam_a : ndarray, shape (..., n_modes)
        Their poles in rad/s.
    phi_x : ndarray, shape (..., n_sensors, n_modes)
        Reference shapes, broadcastable against ``phi_a``.
    lam_x : ndarray, shape (..., n_modes)
        Reference poles in rad/s.

    Returns
    -------
    ndarray, shape (..., n_modes)

    Examples
    --------
    >>> import numpy as np
    >>> phi = np.array([[1.0, 1.0], [0.5, -1.0]])
    >>> lam = np.array([-1.0 + 100.0j, -2.0 + 150.0j])
    >>> bool(np.allclose(macxp_paired(phi, lam, phi, lam), np.diag(macxp(phi, lam, phi, lam))))
    True
    """
    a = np.asarray(phi_a)
    x = np.asarray(phi_x)
    cross_h = np.sum(a.conj() * x, axis=-2)
    cross_t = np.sum(a * x, axis=-2)
    return _macxp_core(np.abs(cross_h), np.abs(cross_t), _column_terms(a, np.asarray(lam_a), None),
                       _column_terms(x, np.asarray(lam_x), None))


def macxp_batch(
    phi_a: NDArray[Any], lam_a: NDArray[Any], phi_x: NDArray[Any], lam_x: NDArray[Any]
) -> NDArray[np.float64]:
    """MACXP of every mode of every batch member against every reference mode: shape (B, m_x, m_a).

    The hot-path form of :func:`macxp` for a batch of model evaluations against one reference, as the
    global sensitivity analysis needs it: no input validation; the cross products are two stacked matrix
    products (``a^H x`` and ``a^T x``; one when the shapes are real), which is several times faster than
    broadcasting :func:`macxp_paired` over an extra axis (that forms a (B, m_x, n_s, m_a) temporary).

    Parameters
    ----------
    phi_a : ndarray, shape (B, n_sensors, m_a)
        Shapes of the batch (real or complex).
    lam_a : ndarray, shape (B, m_a)
        Their poles in rad/s.
    phi_x : ndarray, shape (n_sensors, m_x)
        Reference shapes.
    lam_x : ndarray, shape (m_x,)
        Reference poles in rad/s.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> phi = rng.standard_normal((2, 4, 3)) + 1j * rng.standard_normal((2, 4, 3))
    >>> lam = -rng.uniform(1, 5, (2, 3)) + 1j * rng.uniform(50, 90, (2, 3))
    >>> out = macxp_batch(phi, lam, phi[0][:, :2], lam[0][:2])
    >>> bool(np.allclose(out[1], macxp(phi[1], lam[1], phi[0][:, :2], lam[0][:2]).T))
    True
    """
    a = np.asarray(phi_a)
    x = np.asarray(phi_x)
    if not np.iscomplexobj(a):
        return _macxp_real_batch(a, np.asarray(lam_a), x, np.asarray(lam_x))
    at = np.swapaxes(a, -1, -2)
    abs_t = np.abs(np.swapaxes(at @ x, -1, -2))  # (B, m_x, m_a)
    abs_h = np.abs(np.swapaxes(at.conj() @ x, -1, -2))
    s_a, pole_a, den_a, root_a = _column_terms(a, np.asarray(lam_a), None)  # (B, m_a)
    s_x, pole_x, den_x, root_x = _column_terms(x, np.asarray(lam_x), None)  # (m_x,)
    terms_a = (s_a[:, None, :], pole_a[:, None, :], den_a[:, None, :], root_a[:, None, :])
    terms_x = (s_x[:, None], pole_x[:, None], den_x[:, None], root_x[:, None])
    return _macxp_core(abs_h, abs_t, terms_a, terms_x)


def _macxp_real_batch(a: NDArray[np.float64], lam_a: NDArray[Any], x: NDArray[Any],
                      lam_x: NDArray[Any]) -> NDArray[np.float64]:
    """:func:`macxp_batch` for real batch shapes (first-order modes: the GSA's and the subproblems' case).

    With ``a`` real, ``|a^H x| = |a^T x|`` and MACXP is ``(w_h + w_t)^2 |a^T x|^2 / (den_a den_x)`` with the pole
    weights ``w = min(1, 2 sqrt(s_a s_x) / |pole distance|)``. It is evaluated in squares,
    ``(w_h + w_t)^2 = q_h + q_t + 2 sqrt(q_h q_t)`` with ``q = min(1, 4 s_a s_x / distance^2)`` (``min`` only
    replaces the NaN of 0 / 0, coinciding undamped poles, by the limit 1: ``4 s_a s_x <= (s_a + s_x)^2 <=
    distance^2``), so one square root per pair instead of three, and the cross products come out of one real
    product ``[Re x, Im x]^T a`` laid out as the result: 20.4 -> 17.1 us per sample for the GSA's 20 x 45 pairs of 81
    channels (chunks of 64, the allocator tuned as the executor does, a one-off timing; a third of it is that
    product, at the machine's peak). Agrees with :func:`macxp` to rounding (tests).
    """
    a = np.asarray(a, dtype=float)  # integer shapes too (the squares below are computed in place)
    m_x = x.shape[1]
    xs = np.concatenate([x.real, x.imag], axis=1).T if np.iscomplexobj(x) else np.ascontiguousarray(x.T, dtype=float)
    cross = xs @ a  # (B, m_x or 2 m_x, m_a)
    out = np.square(cross[:, :m_x])
    if np.iscomplexobj(x):
        out += np.square(cross[:, m_x:])  # |a^T x|^2
    s_a, _, den_a, _ = _column_terms(a, lam_a, None)  # (B, m_a)
    s_x, _, den_x, _ = _column_terms(x, lam_x, None)  # (m_x,)
    s_a3, s_x3 = s_a[:, None, :], s_x[:, None]
    decay2 = s_a3 + s_x3
    np.square(decay2, out=decay2)  # (B, m_x, m_a)
    prod4 = s_a3 * (4.0 * s_x3)
    im_a, im_x = lam_a.imag[:, None, :], lam_x.imag[:, None]
    q_h = np.subtract(im_x, im_a)
    np.square(q_h, out=q_h)
    q_h += decay2
    q_t = np.add(im_x, im_a)
    np.square(q_t, out=q_t)
    q_t += decay2
    with np.errstate(divide="ignore", invalid="ignore"):
        np.divide(prod4, q_h, out=q_h)
        np.divide(prod4, q_t, out=q_t)
    np.fmin(q_h, 1.0, out=q_h)
    np.fmin(q_t, 1.0, out=q_t)
    both = np.multiply(q_h, q_t, out=decay2)
    np.sqrt(both, out=both)
    both *= 2.0
    both += q_h
    both += q_t  # (w_h + w_t)^2
    out *= both
    out /= den_a[:, None, :] * den_x[:, None]
    return out


def _column_terms(
    phi: NDArray[Any], lam: NDArray[Any], outer: int | None
) -> tuple[NDArray[Any], NDArray[Any], NDArray[Any], NDArray[Any]]:
    """Per-mode s = |Re lam|, the pole with Re = -s, and the denominator term of MACXP.

    ``outer`` = 1 or 0 places the mode axis for an outer product (rows or columns); None keeps it last.
    """
    s = np.abs(lam.real)
    pole = -s + 1j * lam.imag
    if np.iscomplexobj(phi):
        norm = np.sum(np.abs(phi) ** 2, axis=-2)
        den = norm + np.abs(np.sum(phi * phi, axis=-2)) * s / np.abs(pole)
    else:  # phi^T phi = phi^H phi
        norm = np.einsum("...ij,...ij->...j", phi, phi)
        den = norm * (1.0 + s / np.abs(pole))
    if outer == 1:
        return s[:, np.newaxis], pole[:, np.newaxis], den[:, np.newaxis], np.sqrt(s)[:, np.newaxis]
    if outer == 0:
        return s[np.newaxis, :], pole[np.newaxis, :], den[np.newaxis, :], np.sqrt(s)[np.newaxis, :]
    return s, pole, den, np.sqrt(s)


def _macxp_core(
    abs_h: NDArray[np.float64],
    abs_t: NDArray[np.float64],
    terms_a: tuple[NDArray[Any], NDArray[Any], NDArray[Any], NDArray[Any]],
    terms_x: tuple[NDArray[Any], NDArray[Any], NDArray[Any], NDArray[Any]],
) -> NDArray[np.float64]:
    """MACXP multiplied through by 4 s_a s_x, which stays finite for undamped poles.

    ``abs_h`` and ``abs_t`` are ``|a^H x|`` and ``|a^T x|`` (the same array for real shapes).
    """
    s_a, la, den_a, root_a = terms_a
    s_x, lx, den_x, root_x = terms_x
    # 2 sqrt(s_a s_x) / |conj(lam_a) + lam_x| and 2 sqrt(s_a s_x) / |lam_a + lam_x|: both <= 1 because
    # |Re(...)| = s_a + s_x >= 2 sqrt(s_a s_x); a zero distance only occurs for coinciding undamped poles,
    # whose limit (equal damping) is 1. In real arithmetic: Re(...) = -(s_a + s_x), Im = Im lam_x -+ Im lam_a.
    # written in place on three arrays of the result's size (the MACXP core is the GSA's largest step after eigh)
    decay2 = np.square(s_a + s_x)
    shape = np.broadcast_shapes(decay2.shape, np.shape(lx), np.shape(la), abs_h.shape, abs_t.shape)
    weight_h = np.empty(shape)
    np.subtract(lx.imag, la.imag, out=weight_h)
    np.square(weight_h, out=weight_h)
    weight_h += decay2
    np.sqrt(weight_h, out=weight_h)  # the distance to conj(lam_a), then the weight in place
    weight_t = np.empty(shape)
    np.add(lx.imag, la.imag, out=weight_t)
    np.square(weight_t, out=weight_t)
    weight_t += decay2
    np.sqrt(weight_t, out=weight_t)
    root = np.empty(shape)
    np.multiply(root_a, root_x, out=root)
    root *= 2.0
    with np.errstate(divide="ignore", invalid="ignore"):
        np.divide(root, weight_h, out=weight_h)
        np.divide(root, weight_t, out=weight_t)
    # fmin drops the NaN of 0 / 0 (coinciding undamped poles: weight 1) and caps x / 0 = inf at 1
    np.fmin(weight_h, 1.0, out=weight_h)
    np.fmin(weight_t, 1.0, out=weight_t)
    if abs_h is abs_t:
        weight_h += weight_t
        num = weight_h
        num *= abs_h
    else:
        num = weight_h
        num *= abs_h
        weight_t *= abs_t
        num += weight_t
    np.square(num, out=num)
    num /= den_a * den_x
    return num


def _relative_difference(
    value: ArrayLike, reference: ArrayLike, names: tuple[str, str], quantity: str
) -> NDArray[np.float64]:
    val = as_finite_array(value, names[0], allow_complex=False)
    ref = as_finite_array(reference, names[1], allow_complex=False)
    try:
        val, ref = np.broadcast_arrays(val, ref)
    except ValueError as exc:
        msg = f"{names[0]} with shape {val.shape} and {names[1]} with shape {ref.shape} do not broadcast"
        raise DataError(msg) from exc
    index = first_index(ref == 0)
    if index is not None:
        msg = f"{names[1]} (reference {quantity}) must be nonzero; got 0 at index {index}"
        raise DataError(msg)
    return np.asarray(np.abs(val - ref) / np.abs(ref), dtype=np.float64)


def nfd(f_a: ArrayLike, f_x: ArrayLike) -> NDArray[np.float64]:
    """Natural frequency difference ``|f_a - f_x| / |f_x|`` of paired modes.

    Parameters
    ----------
    f_a : array_like of float
        Natural frequencies, e.g. of a model (Hz or rad/s, the same unit as ``f_x``).
    f_x : array_like of float
        Reference natural frequencies, broadcastable against ``f_a``; must be nonzero.

    Returns
    -------
    ndarray, broadcast shape of the inputs
        Relative differences (dimensionless, >= 0).

    Raises
    ------
    DataError
        If an input is not real and finite, the shapes do not broadcast, or a reference is zero.

    Examples
    --------
    >>> from cappe.correlate import nfd
    >>> nfd([105.0, 190.0], [100.0, 200.0])
    array([0.05, 0.05])
    """
    return _relative_difference(f_a, f_x, ("f_a", "f_x"), "frequency")


def ndd(zeta_a: ArrayLike, zeta_x: ArrayLike) -> NDArray[np.float64]:
    """Natural damping difference ``|zeta_a - zeta_x| / |zeta_x|`` of paired modes.

    Ellinger & Zaeh (2022), eq. (5), use its square.

    Parameters
    ----------
    zeta_a : array_like of float
        Damping ratios, e.g. of a model (dimensionless).
    zeta_x : array_like of float
        Reference damping ratios, broadcastable against ``zeta_a``; must be nonzero.

    Returns
    -------
    ndarray, broadcast shape of the inputs
        Relative differences (dimensionless, >= 0).

    Raises
    ------
    DataError
        If an input is not real and finite, the shapes do not broadcast, or a reference is zero.

    Examples
    --------
    >>> from cappe.correlate import ndd
    >>> ndd([0.03, 0.01], [0.02, 0.02])
    array([0.5, 0.5])
    """
    return _relative_difference(zeta_a, zeta_x, ("zeta_a", "zeta_x"), "damping ratio")
