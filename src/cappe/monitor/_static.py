"""Bearing stiffness from a quasi-static force/displacement test (thesis 5.4.4 and Appendix C4).

A slowly varying force ``F`` pushes the shaft sideways at ``z_force``; two displacement sensors measure the shaft
relative to the housing at ``z_1`` and ``z_2``, away from the bearings (which cannot be reached). With a rigid
shaft between the front bearing at ``z_front`` and the rear bearing at ``z_rear`` (forces below the first
resonance, so inertia is negligible):

- the shaft's relative displacement is linear in z, ``u(z) = u_1 + (u_2 - u_1) (z - z_1) / (z_2 - z_1)``, so the
  bearing deflections are fixed combinations of the two readings, ``u_b = a_b1 u_1 + a_b2 u_2``;
- force and moment balance share the force by the lever rule, ``F_front = F (z_force - z_rear) / (z_front -
  z_rear)`` and ``F_rear = F (z_front - z_force) / (z_front - z_rear)``;

hence ``k_b = c_b F / (a_b1 u_1 + a_b2 u_2)`` with every coefficient from the geometry (the thesis's eqs C25-C26 have
this form for its set-up). Each sample with a force well away from zero gives one estimate; the result reports
their mean, standard deviation and a 95 % interval of the mean.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import stats

from cappe.exceptions import DataError, ModelError

Array = NDArray[np.float64]

__all__ = ["StaticBearingTest", "static_bearing_stiffness"]


@dataclass(frozen=True)
class StaticBearingTest:
    """Point-by-point bearing stiffness estimates of one test and their statistics (N/m).

    Attributes
    ----------
    front, rear : ndarray
        One estimate per used sample.
    coefficients : dict
        ``{"front": (c, a1, a2), "rear": (c, a1, a2)}`` of ``k = c F / (a1 u1 + a2 u2)`` (from the geometry).
    used : ndarray of bool
        Which samples were used (force magnitude at least ``min_force`` times its largest).
    """

    front: Array
    rear: Array
    coefficients: dict[str, tuple[float, float, float]]
    used: NDArray[np.bool_]

    def summary(self) -> dict[str, dict[str, float]]:
        """Mean, standard deviation, 95 % interval of the mean and the number of points per bearing."""
        out = {}
        for name, values in (("front", self.front), ("rear", self.rear)):
            n = values.size
            mean = float(np.mean(values))
            std = float(np.std(values, ddof=1)) if n > 1 else float("nan")
            half = float(stats.t.ppf(0.975, n - 1) * std / np.sqrt(n)) if n > 1 else float("nan")
            out[name] = {"mean": mean, "std": std, "ci95_low": mean - half, "ci95_high": mean + half, "n": float(n)}
        return out

    def to_dict(self) -> dict[str, Any]:
        return {"summary": self.summary(), "coefficients": {k: list(v) for k, v in self.coefficients.items()},
                "n_samples": int(self.used.size), "n_used": int(self.used.sum())}


def _coefficients(z_force: float, z_front: float, z_rear: float, z_sensors: tuple[float, float],
                  ) -> dict[str, tuple[float, float, float]]:
    z1, z2 = z_sensors
    if z1 == z2:
        msg = f"the two displacement sensors must be at different z; both at {z1}"
        raise ModelError(msg)
    if z_front == z_rear:
        msg = f"the bearings must be at different z; both at {z_front}"
        raise ModelError(msg)
    out = {}
    for name, z_b, share in (("front", z_front, (z_force - z_rear) / (z_front - z_rear)),
                             ("rear", z_rear, (z_front - z_force) / (z_front - z_rear))):
        w2 = (z_b - z1) / (z2 - z1)
        out[name] = (float(share), float(1.0 - w2), float(w2))
    return out


def static_bearing_stiffness(
    force: ArrayLike,
    displacement_1: ArrayLike,
    displacement_2: ArrayLike,
    *,
    z_force: float,
    z_front: float,
    z_rear: float,
    z_sensors: tuple[float, float],
    min_force: float = 0.3,
) -> StaticBearingTest:
    """Front and rear bearing stiffness, sample by sample, from a quasi-static test (see the module).

    Parameters
    ----------
    force : array_like, shape (n,)
        Force on the shaft (N), e.g. a slow square wave.
    displacement_1, displacement_2 : array_like, shape (n,)
        Shaft displacement relative to the housing at ``z_sensors[0]`` and ``z_sensors[1]`` (m), same direction.
    z_force, z_front, z_rear : float
        Axial positions (m) of the force and the bearing centres.
    z_sensors : (float, float)
        Axial positions of the two sensors.
    min_force : float
        Samples whose force magnitude is below this fraction of the largest are left out (near-zero forces
        divide noise by noise).

    Examples
    --------
    >>> f = np.array([100.0, -100.0])
    >>> # front k 2e7 at z 0.1, rear k 1e7 at z -0.1, force at 0.2: F_front = 1.5 F, F_rear = -0.5 F
    >>> u_front, u_rear = 1.5 * f / 2e7, -0.5 * f / 1e7
    >>> u = lambda z: u_rear + (u_front - u_rear) * (z + 0.1) / 0.2
    >>> res = static_bearing_stiffness(f, u(0.15), u(0.25), z_force=0.2, z_front=0.1, z_rear=-0.1,
    ...                                z_sensors=(0.15, 0.25))
    >>> [round(float(v) / 1e6, 6) for v in (res.front[0], res.rear[0])]
    [20.0, 10.0]
    """
    f, u1, u2 = (np.asarray(v, dtype=float).ravel() for v in (force, displacement_1, displacement_2))
    if not (f.size == u1.size == u2.size) or f.size == 0:
        msg = f"force and the two displacements need the same, non-zero length; got {f.size}, {u1.size}, {u2.size}"
        raise DataError(msg)
    for name, v in (("force", f), ("displacement_1", u1), ("displacement_2", u2)):
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            msg = f"{name} is not finite at sample {int(bad[0])}"
            raise DataError(msg)
    if not 0 <= min_force < 1:
        msg = f"min_force must be a fraction in [0, 1); got {min_force}"
        raise ModelError(msg)
    coef = _coefficients(float(z_force), float(z_front), float(z_rear), (float(z_sensors[0]), float(z_sensors[1])))
    peak = float(np.max(np.abs(f)))
    if peak == 0:
        msg = "the force is zero throughout: nothing loads the bearings"
        raise DataError(msg)
    used = np.abs(f) >= min_force * peak
    estimates = {}
    for name, (c, a1, a2) in coef.items():
        deflection = a1 * u1[used] + a2 * u2[used]
        if np.any(deflection == 0):
            msg = f"the {name} bearing does not deflect at some loaded sample: check the sensor signals"
            raise DataError(msg)
        estimates[name] = c * f[used] / deflection
    return StaticBearingTest(front=estimates["front"], rear=estimates["rear"], coefficients=coef, used=used)
