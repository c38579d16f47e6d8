"""Rigid-body motion from accelerometers, model-based motion and their agreement (thesis 4.6).

Thesis section 4.6 builds a *signal based response* (the six generalized coordinates of each rigid body,
obtained from accelerometers on it) and a *model based response* (the same coordinates simulated by the gray-box
model for the measured excitation) and takes the weighted RMS of their difference as the confidence of both the
model and the visualization. This module provides the pieces:

* :func:`accelerometer_matrix` — the linear map from the six body accelerations at a reference point to the
  readings of accelerometers at given points and directions;
* :func:`nine_accelerometer_layout` and :func:`solve_nine_accelerometers` — the classical 3-2-2-2 arrangement
  of nine accelerometers (Padgaonkar et al. 1975, thesis Fig. 4.7 and eq. 4.15) and its closed-form solution;
* :func:`reconstruct_rigid_body_motion` — weighted least squares for any sensor set (explicit geometry or the
  sensor nodes of a model), with rank and conditioning checks, fit residuals per channel and drift-suppressed
  double integration (:func:`integrate_acceleration`);
* :func:`model_rigid_body_motion` — the model-based motion of the same bodies for the measured inputs;
* :func:`motion_confidence` — the weighted, normalized RMS residual between the two.

Conventions
-----------
Motion of a body is ``(x, y, z, rx, ry, rz)``: translation of its reference point (m) and small rotations about
the global axes (rad), as in :mod:`cappe.model.structure`. A point ``r`` of the body moves by
``u + theta x (r - r0)``; its acceleration is ``a0 + alpha x (r - r0)``. The centripetal term
``omega x (omega x (r - r0))`` is quadratic in the (small) vibration velocity and is omitted by the linear
least-squares fit; the nine-accelerometer formulas cancel it exactly. All quantities are SI.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import scipy.linalg as sla
import sympy as sp
from numpy.typing import ArrayLike, NDArray
from scipy.integrate import cumulative_trapezoid

from cappe._arguments import is_numeric, positive_number, real_number
from cappe.exceptions import DataError, DataWarning, IllConditionedWarning
from cappe.model.numeric import NumericModel, ParamsLike
from cappe.systems.timedata import TimeData

__all__ = [
    "NINE_ACCELEROMETER_LABELS",
    "RIGID_BODY_DOFS",
    "AccelerometerLayout",
    "BodyGeometry",
    "MotionConfidence",
    "RigidBodyMotion",
    "accelerometer_matrix",
    "body_geometry",
    "integrate_acceleration",
    "model_rigid_body_motion",
    "motion_confidence",
    "nine_accelerometer_layout",
    "reconstruct_rigid_body_motion",
    "solve_nine_accelerometers",
]

Array = NDArray[np.float64]
Quantity = Literal["acceleration", "velocity", "displacement"]

#: The six motions of a rigid body, in result column order.
RIGID_BODY_DOFS = ("x", "y", "z", "rx", "ry", "rz")
#: Channel order of the nine-accelerometer arrangement (thesis Fig. 4.7).
NINE_ACCELEROMETER_LABELS = ("a_x", "a_y", "a_z", "a_x1", "a_z1", "a_y2", "a_z2", "a_x3", "a_y3")
_QUANTITIES = ("acceleration", "velocity", "displacement")
# Rank decisions on the column-scaled sensor matrix: singular values below this fraction of the largest count as
# zero (float geometry of a degenerate layout leaves ~1e-16); above _COND_WARN the fit amplifies noise so much
# that a warning is due.
_RANK_RTOL = 1e-10
_COND_WARN = 1e6
# Rotation columns are scaled by the sensors' spread, but by no less than 1 mm (sensors at one point have none).
_MIN_SPREAD = 1e-3
# Trapezoid-rule correction is capped at a factor 2 per integration (reached at about 0.37 fs), where the rule's
# response falls towards its zero at the Nyquist frequency.
_TRAPEZOID_FLOOR = 0.5


# -- small helpers ----------------------------------------------------------------------------------------------
def _vectors(name: str, value: ArrayLike, *, rows: int | None = None) -> Array:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        msg = f"argument {name!r} must be numeric with shape (n, 3); got {value!r}"
        raise DataError(msg) from None
    if arr.ndim == 1 and arr.size == 3:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 3 or (rows is not None and arr.shape[0] != rows):
        want = f"({rows}, 3)" if rows is not None else "(n, 3)"
        msg = f"argument {name!r} must have shape {want}; got {np.shape(value)}"
        raise DataError(msg)
    if not np.all(np.isfinite(arr)):
        msg = f"argument {name!r} contains NaN or Inf"
        raise DataError(msg)
    return arr


def _point(name: str, value: ArrayLike) -> Array:
    arr = np.asarray(value, dtype=float) if is_numeric(value) else None
    if arr is None or arr.shape != (3,) or not np.all(np.isfinite(arr)):
        msg = f"{name} must be a finite 3-vector [x, y, z] in m; got {value!r}"
        raise DataError(msg)
    return arr


def _unit_directions(name: str, directions: Array, labels: Sequence[str] | None = None) -> Array:
    norm = np.linalg.norm(directions, axis=1)
    bad = np.flatnonzero(norm < 1e-12)
    if bad.size:
        which = repr(labels[bad[0]]) if labels is not None else f"row {bad[0]}"
        msg = f"{name}: direction of {which} must be a non-zero 3-vector; got {directions[bad[0]].tolist()}"
        raise DataError(msg)
    return np.asarray(directions / norm[:, None])


def _rms(x: Array, axis: int = -1) -> Array:
    return np.asarray(np.sqrt(np.mean(np.square(x), axis=axis)))


# -- kinematics -------------------------------------------------------------------------------------------------
def accelerometer_matrix(points: ArrayLike, directions: ArrayLike, reference: ArrayLike = (0.0, 0.0, 0.0)) -> Array:
    """Map from the six accelerations of a rigid body to the readings of accelerometers on it.

    Row ``i`` gives ``a_i = d_i . (a0 + alpha x (r_i - r0)) = d_i . a0 + ((r_i - r0) x d_i) . alpha`` for the
    body acceleration ``(a0, alpha)`` = (x, y, z, rx, ry, rz) at the reference point ``r0``. The centripetal
    acceleration ``omega x (omega x (r_i - r0))`` is second order in the vibration amplitude and is omitted.

    Parameters
    ----------
    points : array_like, shape (n, 3)
        Accelerometer locations in m.
    directions : array_like, shape (n, 3)
        Sensitive axes; normalized to unit length.
    reference : array_like, shape (3,)
        Point whose translation the first three columns describe, in m (same frame as ``points``).

    Returns
    -------
    ndarray, shape (n, 6)
        Rows ``[d_i, (r_i - r0) x d_i]``: m/s^2 per m/s^2 and m/s^2 per rad/s^2.

    Examples
    --------
    >>> accelerometer_matrix([[0.0, 0.1, 0.0]], [[1.0, 0.0, 0.0]])
    array([[ 1. ,  0. ,  0. ,  0. ,  0. , -0.1]])
    """
    pts = _vectors("points", points)
    dirs = _unit_directions("accelerometer_matrix", _vectors("directions", directions, rows=pts.shape[0]))
    r0 = _point("reference", reference)
    return np.hstack([dirs, np.cross(pts - r0, dirs)])


@dataclass(frozen=True)
class AccelerometerLayout:
    """Named accelerometers on one rigid body.

    Attributes
    ----------
    labels : tuple of str
        Channel name of each accelerometer.
    points : ndarray, shape (n, 3)
        Locations in m.
    directions : ndarray, shape (n, 3)
        Unit sensitive axes.
    reference : ndarray, shape (3,)
        Reference point of the body motion, m.
    """

    labels: tuple[str, ...]
    points: Array
    directions: Array
    reference: Array

    def matrix(self) -> Array:
        """:func:`accelerometer_matrix` of this layout, shape (n, 6)."""
        return accelerometer_matrix(self.points, self.directions, self.reference)

    def sensors(self) -> dict[str, tuple[Array, Array]]:
        """``{label: (point, direction)}``, the form :func:`reconstruct_rigid_body_motion` takes per body."""
        return {lab: (p, d) for lab, p, d in zip(self.labels, self.points, self.directions, strict=True)}

    def to_dict(self) -> dict[str, Any]:
        return {
            "labels": list(self.labels),
            "points": self.points.tolist(),
            "directions": self.directions.tolist(),
            "reference": self.reference.tolist(),
        }


def nine_accelerometer_layout(
    *, rx: float, ry: float, rz: float, origin: ArrayLike = (0.0, 0.0, 0.0)
) -> AccelerometerLayout:
    """The nine-accelerometer (3-2-2-2) arrangement of Padgaonkar et al. (1975), thesis Fig. 4.7.

    A triaxial group ``a_x, a_y, a_z`` sits at ``origin`` along the body axes; pairs sit on three arms:
    ``a_x1, a_z1`` at ``origin + (0, ry, 0)``, ``a_y2, a_z2`` at ``origin + (rx, 0, 0)`` and ``a_x3, a_y3`` at
    ``origin + (0, 0, rz)``. Each pair measures the two directions perpendicular to its arm, so every angular
    acceleration is seen twice (see :func:`solve_nine_accelerometers`).

    Parameters
    ----------
    rx, ry, rz : float
        Signed arm lengths in m (non-zero).
    origin : array_like, shape (3,)
        Location of the triaxial group, m; also the reference point of the motion.

    Examples
    --------
    >>> lay = nine_accelerometer_layout(rx=0.1, ry=0.2, rz=0.3)
    >>> lay.labels[3], lay.points[3].tolist(), lay.directions[3].tolist()
    ('a_x1', [0.0, 0.2, 0.0], [1.0, 0.0, 0.0])
    """
    arms = [_arm(n, v) for n, v in (("rx", rx), ("ry", ry), ("rz", rz))]
    o = _point("origin", origin)
    ex, ey, ez = np.eye(3)
    on = {0: arms[0] * ex, 1: arms[1] * ey, 2: arms[2] * ez}
    offsets = [np.zeros(3)] * 3 + [on[1], on[1], on[0], on[0], on[2], on[2]]
    directions = [ex, ey, ez, ex, ez, ey, ez, ex, ey]
    return AccelerometerLayout(
        NINE_ACCELEROMETER_LABELS, o + np.array(offsets), np.array(directions, dtype=float), o.copy()
    )


def _arm(name: str, value: Any) -> float:
    out = real_number(name, value)
    if out == 0:
        msg = f"arm length {name!r} must be a non-zero finite number in m; got {value!r}"
        raise DataError(msg)
    return out


def solve_nine_accelerometers(accelerations: ArrayLike, *, rx: float, ry: float, rz: float) -> Array:
    """Body accelerations from the nine-accelerometer arrangement in closed form (thesis eq. 4.15).

    With the readings in :data:`NINE_ACCELEROMETER_LABELS` order (layout of :func:`nine_accelerometer_layout`)::

        alpha_x = (a_z1 - a_z) / (2 ry) - (a_y3 - a_y) / (2 rz)
        alpha_y = (a_x3 - a_x) / (2 rz) - (a_z2 - a_z) / (2 rx)
        alpha_z = (a_y2 - a_y) / (2 rx) - (a_x1 - a_x) / (2 ry)

    and the translational acceleration of the origin is ``(a_x, a_y, a_z)``. Each angular acceleration is the
    mean of its two estimates, in which the centripetal terms (``w_y w_z r`` for alpha_x, and so on) enter with
    opposite signs and cancel, so the result is exact for finite angular velocity too. (The thesis prints
    ``a_z3`` in the second formula; the arrangement has no such sensor and ``a_x3`` is meant.)

    Parameters
    ----------
    accelerations : array_like, shape (..., 9)
        Readings in m/s^2.
    rx, ry, rz : float
        Arm lengths in m.

    Returns
    -------
    ndarray, shape (..., 6)
        ``(a_x, a_y, a_z, alpha_x, alpha_y, alpha_z)`` in m/s^2 and rad/s^2.

    Examples
    --------
    >>> import numpy as np
    >>> lay = nine_accelerometer_layout(rx=0.1, ry=0.1, rz=0.1)
    >>> readings = lay.matrix() @ np.array([1.0, 0.0, 0.0, 0.0, 0.0, 2.0])
    >>> solve_nine_accelerometers(readings, rx=0.1, ry=0.1, rz=0.1).round(12).tolist()
    [1.0, 0.0, 0.0, 0.0, 0.0, 2.0]
    """
    a = np.asarray(accelerations, dtype=float)
    if a.ndim == 0 or a.shape[-1] != 9:
        order = ", ".join(NINE_ACCELEROMETER_LABELS)
        msg = f"accelerations must have shape (..., 9) in the order {order}; got {a.shape}"
        raise DataError(msg)
    if not np.all(np.isfinite(a)):
        msg = "accelerations contain NaN or Inf"
        raise DataError(msg)
    lx, ly, lz = _arm("rx", rx), _arm("ry", ry), _arm("rz", rz)
    ax, ay, az, ax1, az1, ay2, az2, ax3, ay3 = np.moveaxis(a, -1, 0)
    alpha_x = (az1 - az) / (2 * ly) - (ay3 - ay) / (2 * lz)
    alpha_y = (ax3 - ax) / (2 * lz) - (az2 - az) / (2 * lx)
    alpha_z = (ay2 - ay) / (2 * lx) - (ax1 - ax) / (2 * ly)
    return np.stack([ax, ay, az, alpha_x, alpha_y, alpha_z], axis=-1)


# -- integration ------------------------------------------------------------------------------------------------
def integrate_acceleration(
    acceleration: ArrayLike,
    *,
    fs: float,
    f_min: float,
    f_max: float | None = None,
    filter_order: int = 4,
    axis: int = -1,
) -> tuple[Array, Array]:
    """Velocity and displacement from acceleration with drift suppression below ``f_min``.

    Double integration amplifies low-frequency disturbances (offset and thermal drift of accelerometers, thesis
    4.6) as 1/f^2, and the unknown initial velocity and position add a line. The method:

    1. integrate once and twice with the trapezoid rule from zero initial conditions;
    2. remove the least-squares polynomial of degree 2 (velocity) or 3 (displacement) over the record: it holds
       the unknown initial conditions and the integrals of an acceleration offset and linear drift exactly;
    3. extend the remainder evenly (mirror) to make it periodic without a jump, and apply in the frequency
       domain a zero-phase high-pass ``1 / (1 + (f_min / f)^(2 n))`` (the magnitude of an n-th order
       Butterworth filter applied forwards and backwards, n = ``filter_order``), an optional low-pass
       ``1 / (1 + (f / f_max)^(2 n))`` and the inverse of the trapezoid rule's frequency response
       ``(pi f / fs) cot(pi f / fs)`` (capped at a factor 2 per integration near Nyquist).

    In the passband (above about 3 ``f_min``; the high-pass takes 1.5e-4 off the amplitude at 3 ``f_min`` with
    n = 4) the result equals the exact integral of every component there, except within about 2 / ``f_min``
    of either end of the record, where the unknown initial conditions cannot be separated from the filtered
    band. Motion below ``f_min`` is removed, drift or not.

    Parameters
    ----------
    acceleration : array_like
        Samples along ``axis``, m/s^2 (or rad/s^2).
    fs : float
        Sampling rate in Hz.
    f_min : float
        High-pass corner in Hz, ``0 < f_min < fs / 2``.
    f_max : float, optional
        Low-pass corner in Hz, ``f_min < f_max <= fs / 2``.
    filter_order : int
        Butterworth order n of the corners.
    axis : int
        Time axis.

    Returns
    -------
    velocity, displacement : ndarray
        Same shape as ``acceleration``; m/s and m (or rad/s and rad).

    Examples
    --------
    >>> import numpy as np
    >>> fs, f0 = 1000.0, 25.0
    >>> t = np.arange(2000) / fs
    >>> acc = -(2 * np.pi * f0) ** 2 * np.sin(2 * np.pi * f0 * t) + 0.5  # offset
    >>> _, d = integrate_acceleration(acc, fs=fs, f_min=5.0)
    >>> inner = slice(400, 1600)  # 2 / f_min from either end
    >>> bool(np.abs(d[inner] - np.sin(2 * np.pi * f0 * t[inner])).max() < 1e-3)
    True
    """
    a = np.asarray(acceleration, dtype=float)
    if a.ndim == 0:
        msg = "acceleration must be an array with a time axis"
        raise DataError(msg)
    if not np.all(np.isfinite(a)):
        msg = "acceleration contains NaN or Inf"
        raise DataError(msg)
    rate = positive_number("fs", fs, "Hz")
    low, high = _band_limits(f_min, f_max, rate)
    order = _filter_order(filter_order)
    x = np.moveaxis(a, axis, -1)
    n = x.shape[-1]
    if n < 8:
        msg = f"acceleration needs at least 8 samples along the time axis; got {n}"
        raise DataError(msg)
    if n / rate * low < 2.0:
        warnings.warn(
            f"record of {n / rate:.3g} s is shorter than 2 / f_min = {2 / low:.3g} s: the integrated motion is "
            f"dominated by edge effects; use a longer record or a higher f_min",
            DataWarning,
            stacklevel=2,
        )
    dt = 1.0 / rate
    v_raw = cumulative_trapezoid(x, dx=dt, axis=-1, initial=0.0)
    d_raw = cumulative_trapezoid(v_raw, dx=dt, axis=-1, initial=0.0)
    velocity = _band(v_raw, rate, low, high, order, n_integrations=1, degree=2)
    displacement = _band(d_raw, rate, low, high, order, n_integrations=2, degree=3)
    return np.moveaxis(velocity, -1, axis), np.moveaxis(displacement, -1, axis)


def _band_limits(f_min: Any, f_max: Any, fs: float) -> tuple[float, float | None]:
    low = positive_number("f_min", f_min, "Hz")
    if low >= fs / 2:
        msg = f"argument 'f_min' must be below the Nyquist frequency {fs / 2:g} Hz; got {f_min!r}"
        raise DataError(msg)
    if f_max is None:
        return low, None
    high = positive_number("f_max", f_max, "Hz")
    if not low < high <= fs / 2:
        msg = f"argument 'f_max' must satisfy f_min ({low:g} Hz) < f_max <= fs / 2 ({fs / 2:g} Hz); got {f_max!r}"
        raise DataError(msg)
    return low, high


def _filter_order(value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 1 <= int(value) <= 16:
        msg = f"argument 'filter_order' must be an integer from 1 to 16; got {value!r}"
        raise DataError(msg)
    return int(value)


def _band(
    x: Array, fs: float, f_min: float, f_max: float | None, order: int, *, n_integrations: int, degree: int
) -> Array:
    """Remove the LS polynomial, mirror-extend, band-limit and undo the trapezoid response (see above)."""
    n = x.shape[-1]
    tau = np.linspace(-1.0, 1.0, n)
    basis = np.polynomial.legendre.legvander(tau, degree)  # (n, degree + 1), well conditioned on [-1, 1]
    flat = x.reshape(-1, n).T
    coef, *_ = np.linalg.lstsq(basis, flat, rcond=None)
    rest = flat - basis @ coef  # (n, m)
    extended = np.concatenate([rest, rest[-2:0:-1]], axis=0)  # period 2n - 2, continuous at both joins
    m = extended.shape[0]
    f = np.fft.rfftfreq(m, 1.0 / fs)
    gain = np.zeros(f.size)
    pos = f > 0
    with np.errstate(over="ignore", divide="ignore"):
        gain[pos] = 1.0 / (1.0 + (f_min / f[pos]) ** (2 * order))
        if f_max is not None:
            gain[pos] /= 1.0 + (f[pos] / f_max) ** (2 * order)
    half = np.pi * f[pos] / fs
    response = np.maximum(half / np.tan(np.minimum(half, np.pi / 2 - 1e-12)), _TRAPEZOID_FLOOR)
    gain[pos] /= response**n_integrations
    out = np.fft.irfft(np.fft.rfft(extended, axis=0) * gain[:, None], m, axis=0)[:n]
    return np.asarray(out.T.reshape(x.shape))


# -- results ----------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RigidBodyMotion:
    """Six-DOF motion of rigid bodies over time: signal based (from sensors) or model based.

    Attributes
    ----------
    time : ndarray, shape (n_t,)
        Sample times in s.
    bodies : tuple of str
        Body names.
    acceleration, velocity, displacement : ndarray, shape (n_bodies, n_t, 6)
        Motion of each body's reference point, columns :data:`RIGID_BODY_DOFS` (m, rad and their derivatives).
        Inactive DOFs are zero.
    active : ndarray of bool, shape (n_bodies, 6)
        DOFs that were estimated (signal) or simulated (model).
    reference : ndarray, shape (n_bodies, 3)
        Reference point of each body in m (nominal, global frame for model-based geometry).
    points : tuple of ndarray
        Per body, the points (k, 3) in m that locate it for visualization (sensor points, attachment points).
    source : str
        ``"signal"`` or ``"model"``.
    f_min, f_max : float or None
        Pass band of the integration in Hz (None for motion integrated exactly by the model).
    channels : tuple of str
        Sensor channels used (signal based only).
    channel_bodies : tuple of str
        Body of each channel.
    residual : ndarray, shape (n_channels, n_t)
        Measured minus fitted acceleration per channel, m/s^2: what the rigid-body motion does not explain.
    residual_ratio : ndarray, shape (n_channels,)
        RMS of the residual over RMS of the channel (0 for a perfectly rigid motion; NaN for a zero channel).
    condition : ndarray, shape (n_bodies,)
        2-norm condition number of each body's weighted sensor matrix, rotation columns scaled by the sensors'
        RMS distance from their centroid (unit-free); NaN for model-based motion.
    redundancy : ndarray of int, shape (n_bodies,)
        Number of channels minus estimated DOFs per body (residuals are only informative when > 0).
    """

    time: Array
    bodies: tuple[str, ...]
    acceleration: Array
    velocity: Array
    displacement: Array
    active: NDArray[np.bool_]
    reference: Array
    points: tuple[Array, ...]
    source: str
    f_min: float | None = None
    f_max: float | None = None
    channels: tuple[str, ...] = ()
    channel_bodies: tuple[str, ...] = ()
    residual: Array = field(default_factory=lambda: np.zeros((0, 0)))
    residual_ratio: Array = field(default_factory=lambda: np.zeros(0))
    condition: Array = field(default_factory=lambda: np.zeros(0))
    redundancy: NDArray[np.int_] = field(default_factory=lambda: np.zeros(0, dtype=int))

    @property
    def n_samples(self) -> int:
        return int(self.time.size)

    def index(self, body: str) -> int:
        """Row of a body; unknown names raise a DataError listing the known ones.

        Parameters
        ----------
        body : str
            Body name.

        Returns
        -------
        int
            Index into ``bodies`` and the first axis of the motion arrays.
        """
        if body not in self.bodies:
            msg = f"unknown body {body!r}; the motion has {list(self.bodies)}"
            raise DataError(msg)
        return self.bodies.index(body)

    def get(self, body: str, quantity: Quantity = "displacement") -> Array:
        """Motion of one body, shape (n_t, 6), columns :data:`RIGID_BODY_DOFS`.

        Parameters
        ----------
        body : str
            Body name.
        quantity : {"displacement", "velocity", "acceleration"}
            Which motion: m and rad, m/s and rad/s, or m/s^2 and rad/s^2.

        Returns
        -------
        ndarray, shape (n_t, 6)
        """
        if quantity not in _QUANTITIES:
            msg = f"quantity must be one of {', '.join(_QUANTITIES)}; got {quantity!r}"
            raise DataError(msg)
        return np.asarray(getattr(self, quantity)[self.index(body)])

    def point_motion(self, body: str, points: ArrayLike, quantity: Quantity = "displacement") -> Array:
        """Motion ``u + theta x (r - r0)`` of body points (k, 3) in m: shape (n_t, k, 3).

        Parameters
        ----------
        body : str
            Body name.
        points : array_like, shape (k, 3)
            Points of the body in global coordinates (m).
        quantity : {"displacement", "velocity", "acceleration"}
            Which motion (m, m/s or m/s^2).

        Returns
        -------
        ndarray, shape (n_t, k, 3)
            Translation of each point along x, y, z (small rotations).
        """
        q = self.get(body, quantity)
        rel = _vectors("points", points) - self.reference[self.index(body)]
        return np.asarray(q[:, None, :3] + np.cross(q[:, None, 3:], rel[None, :, :]))

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "source": self.source,
            "dofs": list(RIGID_BODY_DOFS),
            "time": self.time.tolist(),
            "bodies": {},
            "f_min": self.f_min,
            "f_max": self.f_max,
        }
        for b, name in enumerate(self.bodies):
            out["bodies"][name] = {
                "active": [d for d, on in zip(RIGID_BODY_DOFS, self.active[b], strict=True) if on],
                "reference": self.reference[b].tolist(),
                "points": self.points[b].tolist(),
                "acceleration": self.acceleration[b].tolist(),
                "velocity": self.velocity[b].tolist(),
                "displacement": self.displacement[b].tolist(),
            }
            if self.condition.size:
                out["bodies"][name]["condition"] = float(self.condition[b])
                out["bodies"][name]["redundancy"] = int(self.redundancy[b])
        if self.channels:
            out["channels"] = {
                c: {"body": b, "residual_ratio": float(r)}
                for c, b, r in zip(self.channels, self.channel_bodies, self.residual_ratio, strict=True)
            }
        return out


@dataclass(frozen=True)
class BodyGeometry:
    """Nominal geometry of one body for visualization (global frame, m).

    Attributes
    ----------
    name : str
    reference : ndarray, shape (3,)
        The body's origin (the point whose motion the model's DOFs describe).
    points : ndarray, shape (k, 3)
        Origin, centre of mass, sensor nodes and element attachment points.
    labels : tuple of str
        What each point is (``"origin"``, ``"com"``, ``"sensor:NAME"``, ``"element:NAME"``).
    """

    name: str
    reference: Array
    points: Array
    labels: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "reference": self.reference.tolist(),
            "points": self.points.tolist(),
            "labels": list(self.labels),
        }


def _substitutions(model: NumericModel, params: ParamsLike, position: Mapping[str, float] | None) -> dict[Any, float]:
    p = model.vector(params)
    if p.ndim != 1:
        msg = "params must be a single parameter vector, not a batch"
        raise DataError(msg)
    pos = model.position_vector(position)
    symbols = model.symbolic.symbols
    subs = {symbols[n]: float(v) for n, v in zip(model.parameter_names, p, strict=True)}
    subs.update({symbols[a]: float(v) for a, v in zip(model.axis_names, pos, strict=True)})
    return subs


def _evaluate(vector: Sequence[Any], subs: Mapping[Any, float]) -> Array:
    return np.array([float(sp.sympify(v).xreplace(dict(subs))) for v in vector], dtype=float)


def body_geometry(
    model: NumericModel, *, params: ParamsLike = None, position: Mapping[str, float] | None = None
) -> dict[str, BodyGeometry]:
    """Nominal points of every body of a model (origin, centre of mass, sensors, attachment points).

    Points are global coordinates at the given parameter values and axis position, the frame in which
    :func:`model_rigid_body_motion` and model-based :func:`reconstruct_rigid_body_motion` report motion.

    Parameters
    ----------
    model : NumericModel
        The model.
    params : mapping name -> float or ndarray, optional
        Parameter values (SI); default the model's.
    position : mapping axis -> float, optional
        Axis position (m or rad); default the model's.

    Returns
    -------
    dict
        ``{body name: BodyGeometry}`` (points in m).

    Examples
    --------
    >>> from cappe.model import load_model
    >>> geo = body_geometry(NumericModel(load_model("builtin:two-mass-rig")))
    >>> sorted(geo)
    ['mass1', 'mass2']
    """
    subs = _substitutions(model, params, position)
    structure = model.structure
    out: dict[str, BodyGeometry] = {}
    for body in structure.bodies:
        origin = _evaluate(body.position, subs)
        pts = [origin, origin + _evaluate(body.com, subs)]
        labels = ["origin", "com"]
        for s in structure.sensors:
            if s.body == body.name:
                pts.append(origin + _evaluate(s.point, subs))
                labels.append(f"sensor:{s.name}")
        for e in structure.elements:
            for b, p in ((e.body_a, e.point_a), (e.body_b, e.point_b)):
                if b == body.name:
                    pts.append(origin + _evaluate(p, subs))
                    labels.append(f"element:{e.name}")
        out[body.name] = BodyGeometry(body.name, origin, np.array(pts), tuple(labels))
    return out


def _sensor_points(geo: BodyGeometry) -> Array:
    """The sensor nodes among a body's points, shape (k, 3) (k may be 0)."""
    rows = [p for p, lab in zip(geo.points, geo.labels, strict=True) if lab.startswith("sensor:")]
    return np.array(rows, dtype=float).reshape(-1, 3)


# -- signal-based motion ----------------------------------------------------------------------------------------
@dataclass
class _BodyFit:
    name: str
    channels: list[str]
    rows: Array  # (n_c, 6) sensor rows for all six DOFs
    active: NDArray[np.bool_]
    reference: Array
    points: Array


def _model_bodies(
    model: NumericModel,
    data: TimeData,
    bodies: Sequence[str] | None,
    labels: Mapping[str, str] | None,
    params: ParamsLike,
    position: Mapping[str, float] | None,
) -> list[_BodyFit]:
    structure = model.structure
    label_of = dict(labels) if labels is not None else {}
    for channel in label_of:
        data.index(channel)
    sensor_names = {s.name for s in structure.sensors}
    picked: list[tuple[str, str, str, int]] = []  # channel, node, body, axis
    for channel in data.channels:
        label = label_of.get(channel, channel)
        node, sep, direction = label.rpartition(":")
        if not sep or node not in sensor_names:
            if channel in label_of:
                msg = (
                    f"labels: channel {channel!r} maps to {label!r}, which is not a sensor channel 'node:x|y|z' of "
                    f"model '{structure.name}'; sensor nodes: {sorted(sensor_names)}"
                )
                raise DataError(msg)
            continue
        if direction not in ("x", "y", "z"):
            msg = f"channel {channel!r}: sensor direction must be x, y or z; got {direction!r} in {label!r}"
            raise DataError(msg)
        picked.append((channel, node, structure.sensor(node).body, "xyz".index(direction)))
    known = [b.name for b in structure.bodies]
    wanted = list(bodies) if bodies is not None else [b for b in known if any(p[2] == b for p in picked)]
    for b in wanted:
        if b not in known:
            msg = f"unknown body {b!r} for model '{structure.name}'; known bodies: {known}"
            raise DataError(msg)
    if not wanted:
        msg = (
            f"no data channel names a sensor of model '{structure.name}' as 'node:x|y|z' "
            f"(sensor nodes: {sorted(sensor_names) or 'none'}; channels: {list(data.channels)})"
        )
        raise DataError(msg)
    nodes = sorted({p[1] for p in picked})
    row_labels, rows = model.sensor_matrix(params, position, nodes) if nodes else ([], np.zeros((0, model.n_dof)))
    row_of = {lab: r for lab, r in zip(row_labels, rows, strict=True)}
    geometry = body_geometry(model, params=params, position=position)
    fits = []
    for b in wanted:
        chans = [p for p in picked if p[2] == b]
        if not chans:
            msg = f"body {b!r} has no sensor channel in the data (channels: {list(data.channels)})"
            raise DataError(msg)
        cols = [j for j, d in enumerate(model.dofs) if d.split(".")[0] == b]
        dof_index = [RIGID_BODY_DOFS.index(model.dofs[j].split(".")[1]) for j in cols]
        full = np.zeros((len(chans), 6))
        for i, (_, node, _, ax) in enumerate(chans):
            full[i, dof_index] = row_of[f"{node}:{'xyz'[ax]}"][cols]
        active = np.zeros(6, dtype=bool)
        active[dof_index] = True
        geo = geometry[b]
        fits.append(_BodyFit(b, [c[0] for c in chans], full, active, geo.reference, _sensor_points(geo)))
    return fits


def _explicit_bodies(
    data: TimeData,
    sensors: Mapping[str, Mapping[str, tuple[ArrayLike, ArrayLike]]],
    bodies: Sequence[str] | None,
    reference: Mapping[str, ArrayLike] | None,
    dofs: Mapping[str, Sequence[str]] | None,
) -> list[_BodyFit]:
    if not isinstance(sensors, Mapping) or not sensors:
        msg = f"sensors must map body names to {{channel: (point, direction)}}; got {sensors!r}"
        raise DataError(msg)
    for group, name in ((reference, "reference"), (dofs, "dofs")):
        for b in group or {}:
            if b not in sensors:
                msg = f"{name}: unknown body {b!r}; bodies in sensors: {list(sensors)}"
                raise DataError(msg)
    wanted = list(bodies) if bodies is not None else list(sensors)
    seen: dict[str, str] = {}
    fits = []
    for b in wanted:
        if b not in sensors:
            msg = f"unknown body {b!r}; bodies in sensors: {list(sensors)}"
            raise DataError(msg)
        table = sensors[b]
        if not isinstance(table, Mapping) or not table:
            msg = f"sensors[{b!r}] must map channel names to (point, direction); got {table!r}"
            raise DataError(msg)
        chans = list(table)
        pts, dirs = [], []
        for c in chans:
            data.index(c)
            if c in seen:
                msg = f"channel {c!r} is listed for two bodies ({seen[c]!r} and {b!r})"
                raise DataError(msg)
            seen[c] = b
            entry = table[c]
            if not isinstance(entry, (tuple, list)) or len(entry) != 2:
                msg = f"sensors[{b!r}][{c!r}] must be (point, direction); got {entry!r}"
                raise DataError(msg)
            pts.append(_point(f"sensors[{b!r}][{c!r}] point", entry[0]))
            dirs.append(_point(f"sensors[{b!r}][{c!r}] direction", entry[1]))
        points = np.array(pts)
        directions = _unit_directions(f"sensors[{b!r}]", np.array(dirs), chans)
        r0 = _point(f"reference[{b!r}]", reference[b]) if reference and b in reference else np.zeros(3)
        active = np.ones(6, dtype=bool)
        if dofs and b in dofs:
            chosen = list(dofs[b])
            bad = [d for d in chosen if d not in RIGID_BODY_DOFS]
            if bad or not chosen:
                msg = f"dofs[{b!r}] must list names from {', '.join(RIGID_BODY_DOFS)}; got {chosen!r}"
                raise DataError(msg)
            active = np.array([d in chosen for d in RIGID_BODY_DOFS])
        rows = accelerometer_matrix(points, directions, r0)
        fits.append(_BodyFit(b, chans, rows, active, r0, points))
    return fits


def _channel_weights(weights: Mapping[str, float] | None, data: TimeData, used: Sequence[str]) -> dict[str, float]:
    out = dict.fromkeys(used, 1.0)
    for c, w in (weights or {}).items():
        if c not in out:
            msg = f"weights: channel {c!r} is not a sensor channel of the fit; sensor channels: {list(used)}"
            raise DataError(msg)
        out[c] = _weight(f"weight of channel {c!r}", w)
    return out


def _weight(what: str, value: Any) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        msg = f"weights: {what} must be a number >= 0; got {value!r}"
        raise DataError(msg) from None
    if not (math.isfinite(number) and number >= 0):
        msg = f"weights: {what} must be a finite number >= 0; got {value!r}"
        raise DataError(msg)
    return number


def _describe(vector: Array, names: Sequence[str]) -> str:
    big = np.abs(vector) > 1e-6 * np.abs(vector).max()
    text = ""
    for v, n, on in zip(vector, names, big, strict=True):
        if not on:
            continue
        sign = "-" if v < 0 else "+"
        size = "" if math.isclose(abs(v), 1.0, rel_tol=1e-9) else f"{abs(v):.3g}*"
        text += f" {sign} {size}{n}" if text else f"{'-' if v < 0 else ''}{size}{n}"
    return text


def _null_space_text(null: Array, names: Sequence[str]) -> str:
    """Readable basis of a null space (columns of ``null``): reduced row echelon form of its transpose."""
    basis = null.T.copy()
    pivot_row = 0
    for col in range(basis.shape[1]):
        if pivot_row == basis.shape[0]:
            break
        k = pivot_row + int(np.argmax(np.abs(basis[pivot_row:, col])))
        if abs(basis[k, col]) < 1e-9:
            continue
        basis[[pivot_row, k]] = basis[[k, pivot_row]]
        basis[pivot_row] /= basis[pivot_row, col]
        for r in range(basis.shape[0]):
            if r != pivot_row:
                basis[r] -= basis[r, col] * basis[pivot_row]
        pivot_row += 1
    return "; ".join(_describe(v, names) for v in basis)


def _solve_body(fit: _BodyFit, y: Array, w: Array) -> tuple[Array, Array, float]:
    """Weighted LS for one body: accelerations (n_t, 6), fitted channel values (n_c, n_t), condition number."""
    cols = np.flatnonzero(fit.active)
    names = [RIGID_BODY_DOFS[j] for j in cols]
    a = fit.rows[:, cols]
    centroid = fit.points.mean(axis=0) if fit.points.size else fit.reference
    spread = float(np.sqrt(np.mean(np.sum((fit.points - centroid) ** 2, axis=1)))) if fit.points.size else 0.0
    length = max(spread, _MIN_SPREAD)
    scale = np.array([1.0 if RIGID_BODY_DOFS[j] in ("x", "y", "z") else length for j in cols])
    sw = np.sqrt(w)
    aw = (a * sw[:, None]) / scale[None, :]
    used = int(np.count_nonzero(w > 0))
    sv = sla.svdvals(aw) if aw.size else np.zeros(0)
    smax = float(sv[0]) if sv.size else 0.0
    rank = int(np.count_nonzero(sv > _RANK_RTOL * smax)) if smax > 0 else 0
    if rank < cols.size:
        null = sla.null_space(aw, rcond=_RANK_RTOL) if smax > 0 else np.eye(cols.size)
        null = null / scale[:, None]
        msg = (
            f"body {fit.name!r}: the {used} weighted sensor channel(s) determine only {rank} of its {cols.size} "
            f"motions ({', '.join(names)}); not determined: {_null_space_text(null, names)}. Add sensors in other "
            f"directions or at other points, or restrict the body's DOFs"
        )
        raise DataError(msg)
    cond = float(sv[0] / sv[-1])
    if cond > _COND_WARN:
        warnings.warn(
            f"body {fit.name!r}: sensor matrix condition number {cond:.3g} > {_COND_WARN:.0e}; the estimated motion "
            f"amplifies sensor noise strongly (nearly degenerate sensor layout)",
            IllConditionedWarning,
            stacklevel=3,
        )
    sol, *_ = sla.lstsq(aw, y * sw[:, None])
    acc = np.zeros((y.shape[1], 6))
    acc[:, cols] = (sol / scale[:, None]).T
    fitted = a @ acc[:, cols].T
    return acc, fitted, cond


def reconstruct_rigid_body_motion(
    data: TimeData,
    *,
    sensors: Mapping[str, Mapping[str, tuple[ArrayLike, ArrayLike]]] | None = None,
    model: NumericModel | None = None,
    bodies: Sequence[str] | None = None,
    labels: Mapping[str, str] | None = None,
    reference: Mapping[str, ArrayLike] | None = None,
    dofs: Mapping[str, Sequence[str]] | None = None,
    params: ParamsLike = None,
    position: Mapping[str, float] | None = None,
    weights: Mapping[str, float] | None = None,
    f_min: float = 5.0,
    f_max: float | None = None,
    filter_order: int = 4,
) -> RigidBodyMotion:
    """Signal-based rigid-body motion: six body accelerations from any accelerometer set, then integrated.

    For each body, the accelerations ``q`` (x y z rx ry rz at the reference point) minimize
    ``sum_i w_i (a_i - row_i . q)^2`` over its channels (rows from :func:`accelerometer_matrix`, or from the
    model's sensor nodes), sample by sample. Velocities and displacements follow from
    :func:`integrate_acceleration` with pass band ``f_min`` .. ``f_max``. The residual of each channel tells how
    far the measured motion is from rigid (sensor noise, body flexibility, a wrong sensor position or
    direction); it is informative only where a body has more channels than DOFs.

    Parameters
    ----------
    data : TimeData
        Accelerometer channels in m/s^2 (other channels are ignored).
    sensors : mapping, optional
        ``{body: {channel: (point, direction)}}`` with points (m) and directions in one frame per body.
        Give either ``sensors`` or ``model``.
    model : NumericModel, optional
        Sensor geometry from the model's sensor nodes: channels named ``"node:x"``, ``"node:y"`` or ``"node:z"``
        (or renamed through ``labels``) are the acceleration of that node along the global axis. Each body's
        estimated DOFs are its active model DOFs; its reference point is its origin.
    bodies : sequence of str, optional
        Bodies to estimate (default: every body with sensor channels).
    labels : mapping, optional
        ``{data channel: "node:x"}`` for data whose channels are named otherwise (model only).
    reference : mapping, optional
        ``{body: (3,) point}``, reference point per body in m (explicit sensors; default the frame origin).
    dofs : mapping, optional
        ``{body: ["x", "y", "rz"]}`` to estimate only some DOFs (explicit sensors; the rest are held at zero).
    params, position : optional
        Model parameter values and axis position (model only).
    weights : mapping, optional
        ``{channel: w >= 0}``, e.g. ``1 / sigma^2`` for channel noise sigma; default 1. A zero weight leaves the
        channel out of the fit (its residual is still reported).
    f_min, f_max : float
        Integration pass band in Hz (see :func:`integrate_acceleration`); 5 Hz by default, the thesis' limit
        for thermal drift of accelerometers.
    filter_order : int
        Butterworth order of the band edges.

    Returns
    -------
    RigidBodyMotion

    Raises
    ------
    DataError
        If a body's channels do not determine all its estimated motions (the message names the body and the
        undetermined motion), or on inconsistent arguments.

    Warns
    -----
    IllConditionedWarning
        If a body's scaled sensor matrix has condition number above 1e6.

    Examples
    --------
    >>> import numpy as np
    >>> from cappe.systems import TimeData
    >>> lay = nine_accelerometer_layout(rx=0.1, ry=0.1, rz=0.1)
    >>> t = np.arange(1000) / 1000.0
    >>> q = np.outer(np.sin(2 * np.pi * 40 * t), [1.0, 0, 0, 0, 0, 5.0])
    >>> data = TimeData.from_channels(t, dict(zip(lay.labels, (q @ lay.matrix().T).T)))
    >>> motion = reconstruct_rigid_body_motion(data, sensors={"plate": lay.sensors()}, f_min=5.0)
    >>> bool(np.allclose(motion.get("plate", "acceleration"), q, atol=1e-12))
    True
    """
    if not isinstance(data, TimeData):
        msg = f"data must be a TimeData; got {type(data).__name__}"
        raise DataError(msg)
    if model is not None and sensors is None:
        if reference is not None or dofs is not None:
            msg = "'reference' and 'dofs' apply to explicit sensors; with a model they follow from the model"
            raise DataError(msg)
        fits = _model_bodies(model, data, bodies, labels, params, position)
    elif sensors is not None and model is None:
        if labels is not None:
            msg = "'labels' applies to model sensor nodes; with explicit sensors name the data channels directly"
            raise DataError(msg)
        fits = _explicit_bodies(data, sensors, bodies, reference, dofs)
    else:
        msg = "give exactly one of 'sensors' (explicit geometry) or 'model' (sensor nodes of a model)"
        raise DataError(msg)
    low, high = _band_limits(f_min, f_max, data.fs)
    order = _filter_order(filter_order)
    used = [c for fit in fits for c in fit.channels]
    w_of = _channel_weights(weights, data, used)
    n_t = data.n_samples
    acc = np.zeros((len(fits), n_t, 6))
    residual = np.zeros((len(used), n_t))
    cond = np.zeros(len(fits))
    row = 0
    for b, fit in enumerate(fits):
        y = data.values[[data.index(c) for c in fit.channels]]
        w = np.array([w_of[c] for c in fit.channels])
        acc[b], fitted, cond[b] = _solve_body(fit, y, w)
        residual[row : row + len(fit.channels)] = y - fitted
        row += len(fit.channels)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)  # re-issued below with the data's context
        vel, disp = integrate_acceleration(acc, fs=data.fs, f_min=low, f_max=high, filter_order=order, axis=1)
    if data.duration * low < 2.0:
        warnings.warn(
            f"record of {data.duration:.3g} s is shorter than 2 / f_min = {2 / low:.3g} s: the integrated motion "
            f"is dominated by edge effects",
            DataWarning,
            stacklevel=2,
        )
    measured_rms = _rms(data.values[[data.index(c) for c in used]]) if used else np.zeros(0)
    res_rms = _rms(residual) if used else np.zeros(0)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(measured_rms > 0, res_rms / np.where(measured_rms > 0, measured_rms, 1.0), np.nan)
    return RigidBodyMotion(
        time=data.time.copy(),
        bodies=tuple(f.name for f in fits),
        acceleration=acc,
        velocity=vel,
        displacement=disp,
        active=np.array([f.active for f in fits]),
        reference=np.array([f.reference for f in fits]),
        points=tuple(f.points for f in fits),
        source="signal",
        f_min=low,
        f_max=high,
        channels=tuple(used),
        channel_bodies=tuple(f.name for f in fits for _ in f.channels),
        residual=residual,
        residual_ratio=np.asarray(ratio, dtype=float),
        condition=cond,
        redundancy=np.array([sum(1 for c in f.channels if w_of[c] > 0) - int(f.active.sum()) for f in fits]),
    )


# -- model-based motion -----------------------------------------------------------------------------------------
def model_rigid_body_motion(
    model: NumericModel,
    data: TimeData,
    *,
    inputs: Mapping[str, str],
    params: ParamsLike = None,
    position: Mapping[str, float] | None = None,
    bodies: Sequence[str] | None = None,
    f_min: float | None = None,
    f_max: float | None = None,
    filter_order: int = 4,
) -> RigidBodyMotion:
    """Model-based rigid-body motion: the model's response to the measured inputs, body by body.

    The model's generalized coordinates are body motions (``"housing.x"`` ...). The state-space model
    ``x = [q, q']`` of :meth:`MechanicalSystem.state_space` (hysteretic damping as its equivalent viscous
    matrix) is simulated from rest with the input channels held over each sample (zero-order hold, exact for
    such inputs). Accelerations at the samples are ``q'' = A[n:] x + M^-1 B u``. Inactive DOFs are zero.

    With ``f_min`` (and ``f_max``) given, velocity and displacement are obtained from the simulated acceleration
    by :func:`integrate_acceleration`, exactly as the signal-based path does, so that both carry the same band
    limits and edge effects; otherwise they are the exact simulated states.

    Parameters
    ----------
    model : NumericModel
    data : TimeData
        Holds the input channels (N or N m).
    inputs : mapping
        ``{data channel: model input name}``; model inputs not listed are zero.
    params, position : optional
        Parameter values and axis position of the simulation.
    bodies : sequence of str, optional
        Bodies to report (default all).
    f_min, f_max, filter_order : optional
        Integration pass band (see above).

    Returns
    -------
    RigidBodyMotion
        Reference points are the body origins (global, nominal); points are each body's sensor nodes, or its
        origin when it has none.

    Examples
    --------
    >>> import numpy as np
    >>> from cappe.model import load_model
    >>> from cappe.systems import TimeData
    >>> nm = NumericModel(load_model("builtin:two-mass-rig"))
    >>> data = TimeData.from_rate(1000.0, {"F": np.ones(200)})
    >>> m = model_rigid_body_motion(nm, data, inputs={"F": "F1"})
    >>> m.bodies, m.get("mass1").shape
    (('mass1', 'mass2'), (200, 6))
    """
    if not isinstance(model, NumericModel):
        msg = f"model must be a NumericModel; got {type(model).__name__}"
        raise DataError(msg)
    if not isinstance(data, TimeData):
        msg = f"data must be a TimeData; got {type(data).__name__}"
        raise DataError(msg)
    if not isinstance(inputs, Mapping) or not inputs:
        msg = f"inputs must map data channels to model inputs ({list(model.input_names)}); got {inputs!r}"
        raise DataError(msg)
    for channel, name in inputs.items():
        data.index(channel)
        if name not in model.input_names:
            msg = f"inputs: channel {channel!r} maps to unknown model input {name!r}; known: {list(model.input_names)}"
            raise DataError(msg)
    names = list(inputs.values())
    if len(set(names)) != len(names):
        msg = f"inputs: each model input may be fed by one channel only; got {dict(inputs)}"
        raise DataError(msg)
    known = [b.name for b in model.structure.bodies]
    wanted = list(bodies) if bodies is not None else known
    for b in wanted:
        if b not in known:
            msg = f"unknown body {b!r} for model '{model.structure.name}'; known bodies: {known}"
            raise DataError(msg)
    system = model.system(params, position)
    ss = system.state_space(names, [])
    n = model.n_dof
    u = np.stack([data.channel(c) for c in inputs], axis=1)
    _, x = ss.simulate(u, data.time)
    qdd = x @ ss.A[n:].T + u @ ss.B[n:].T
    geometry = body_geometry(model, params=params, position=position)
    n_t = data.n_samples
    acc = np.zeros((len(wanted), n_t, 6))
    vel = np.zeros_like(acc)
    disp = np.zeros_like(acc)
    active = np.zeros((len(wanted), 6), dtype=bool)
    points = []
    for i, name in enumerate(wanted):
        for j, label in enumerate(model.dofs):
            body, dof = label.split(".")
            if body == name:
                k = RIGID_BODY_DOFS.index(dof)
                active[i, k] = True
                acc[i, :, k] = qdd[:, j]
                vel[i, :, k] = x[:, n + j]
                disp[i, :, k] = x[:, j]
        geo = geometry[name]
        sensor_pts = _sensor_points(geo)
        points.append(sensor_pts if sensor_pts.size else geo.reference[None, :].copy())
    low: float | None = None
    high: float | None = None
    if f_min is not None:
        low, high = _band_limits(f_min, f_max, data.fs)
        vel, disp = integrate_acceleration(acc, fs=data.fs, f_min=low, f_max=high, filter_order=filter_order, axis=1)
    elif f_max is not None:
        msg = "f_max needs f_min: band-limited integration is used only when f_min is given"
        raise DataError(msg)
    return RigidBodyMotion(
        time=data.time.copy(),
        bodies=tuple(wanted),
        acceleration=acc,
        velocity=vel,
        displacement=disp,
        active=active,
        reference=np.array([geometry[b].reference for b in wanted]),
        points=tuple(points),
        source="model",
        f_min=low,
        f_max=high,
        condition=np.full(len(wanted), np.nan),
    )


# -- confidence -------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MotionConfidence:
    """Agreement of signal-based and model-based motion (thesis 4.6, Fig. 4.6 block 6).

    For each compared body and DOF, ``ratio = RMS(measured - model) / RMS(measured)`` over the compared
    samples (unit-free, so translations and rotations can be combined). The overall residual is
    ``r = sqrt(sum w ratio^2 / sum w)`` over the compared components and ``confidence = max(0, 1 - r)``:
    1 for identical motion, 0 when the residual is as large as the measured motion.

    Attributes
    ----------
    bodies : tuple of str
    dofs : tuple of str
        :data:`RIGID_BODY_DOFS`.
    ratio : ndarray, shape (n_bodies, 6)
        Normalized RMS residual per body and DOF; NaN where a DOF is not compared (inactive, or zero weight).
    weights : ndarray, shape (n_bodies, 6)
        Weight of each component (0 where not compared).
    residual : float
        Weighted normalized RMS residual r.
    confidence : float
        ``max(0, 1 - r)``.
    quantity : str
        Compared quantity.
    window : tuple of float
        Compared time span (s).
    """

    bodies: tuple[str, ...]
    dofs: tuple[str, ...]
    ratio: Array
    weights: Array
    residual: float
    confidence: float
    quantity: str
    window: tuple[float, float]

    def to_dict(self) -> dict[str, Any]:
        return {
            "quantity": self.quantity,
            "window": list(self.window),
            "residual": self.residual,
            "confidence": self.confidence,
            "ratio": {
                b: {d: float(v) for d, v in zip(self.dofs, self.ratio[i], strict=True) if np.isfinite(v)}
                for i, b in enumerate(self.bodies)
            },
        }


def _component_weights(weights: Mapping[str, float] | None, bodies: Sequence[str]) -> Array:
    w = np.ones((len(bodies), 6))
    for key, value in (weights or {}).items():
        body, _, dof = str(key).partition(".")
        if body not in bodies or (dof and dof not in RIGID_BODY_DOFS):
            msg = (
                f"weights: key {key!r} must be a compared body or 'body.dof' with dof in "
                f"{', '.join(RIGID_BODY_DOFS)}; compared bodies: {list(bodies)}"
            )
            raise DataError(msg)
        number = _weight(f"weight {key!r}", value)
        i = list(bodies).index(body)
        if dof:
            w[i, RIGID_BODY_DOFS.index(dof)] = number
        else:
            w[i, :] = number
    return w


def motion_confidence(
    measured: RigidBodyMotion,
    model: RigidBodyMotion,
    *,
    quantity: Quantity = "acceleration",
    weights: Mapping[str, float] | None = None,
    window: tuple[float, float] | None = None,
) -> MotionConfidence:
    """Weighted RMS residual between signal-based and model-based motion, as a confidence indicator.

    See :class:`MotionConfidence` for the definition. Components are compared where both motions have the DOF
    active and the weight is positive. Acceleration (the default) needs no integration; for velocity or
    displacement, obtain the model motion with the same ``f_min`` as the measured one and exclude about
    2 / ``f_min`` at each end through ``window``.

    Parameters
    ----------
    measured, model : RigidBodyMotion
        On the same time grid; bodies present in both are compared.
    quantity : {"acceleration", "velocity", "displacement"}
    weights : mapping, optional
        ``{"body": w}`` or ``{"body.dof": w}`` (w >= 0; default 1 for every component).
    window : (float, float), optional
        Start and end time (s) of the compared samples; default the whole record.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(100) / 100.0
    >>> acc = np.zeros((1, 100, 6)); acc[0, :, 0] = np.sin(2 * np.pi * 5 * t)
    >>> motion = RigidBodyMotion(t, ("b",), acc, acc, acc, np.ones((1, 6), bool), np.zeros((1, 3)),
    ...                          (np.zeros((1, 3)),), "signal")
    >>> motion_confidence(motion, motion).confidence
    1.0
    """
    if not isinstance(measured, RigidBodyMotion) or not isinstance(model, RigidBodyMotion):
        msg = "measured and model must be RigidBodyMotion results"
        raise DataError(msg)
    if quantity not in _QUANTITIES:
        msg = f"quantity must be one of {', '.join(_QUANTITIES)}; got {quantity!r}"
        raise DataError(msg)
    if measured.time.shape != model.time.shape or not np.allclose(
        measured.time, model.time, rtol=0, atol=1e-9 * max(1.0, float(np.abs(measured.time).max()))
    ):
        msg = (
            f"measured and model motion must share the time grid; got {measured.n_samples} and {model.n_samples} "
            f"samples"
        )
        raise DataError(msg)
    common = [b for b in measured.bodies if b in model.bodies]
    if not common:
        msg = f"measured bodies {list(measured.bodies)} and model bodies {list(model.bodies)} have none in common"
        raise DataError(msg)
    t = measured.time
    if window is None:
        mask = np.ones(t.size, dtype=bool)
        span = (float(t[0]), float(t[-1]))
    else:
        try:
            start, stop = (float(v) for v in window)
        except (TypeError, ValueError):
            msg = f"window must be (start, stop) in s; got {window!r}"
            raise DataError(msg) from None
        mask = (t >= start) & (t <= stop)
        if np.count_nonzero(mask) < 2:
            msg = f"window ({start:g}, {stop:g}) s holds fewer than 2 samples of the record {t[0]:g} .. {t[-1]:g} s"
            raise DataError(msg)
        span = (start, stop)
    w = _component_weights(weights, common)
    ratio = np.full((len(common), 6), np.nan)
    for i, b in enumerate(common):
        mi, ki = measured.index(b), model.index(b)
        on = measured.active[mi] & model.active[ki] & (w[i] > 0)
        meas = getattr(measured, quantity)[mi][mask]
        sim = getattr(model, quantity)[ki][mask]
        rms_meas = _rms(meas, axis=0)
        rms_res = _rms(meas - sim, axis=0)
        for k in np.flatnonzero(on):
            if rms_meas[k] > 0:
                ratio[i, k] = rms_res[k] / rms_meas[k]
            else:
                ratio[i, k] = 0.0 if rms_res[k] == 0 else np.inf
    used = np.isfinite(ratio) | np.isinf(ratio)
    w = np.where(used, w, 0.0)
    if not np.any(w > 0):
        msg = "no body DOF is active in both motions with a positive weight; nothing to compare"
        raise DataError(msg)
    r = float(np.sqrt(np.sum(w[used] * ratio[used] ** 2) / np.sum(w[used])))
    return MotionConfidence(
        bodies=tuple(common),
        dofs=RIGID_BODY_DOFS,
        ratio=ratio,
        weights=w,
        residual=r,
        confidence=max(0.0, 1.0 - r),
        quantity=quantity,
        window=span,
    )
