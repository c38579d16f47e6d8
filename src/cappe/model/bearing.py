"""Angular-contact ball bearings: Hertzian contact stiffness and the stiffness of a preloaded bearing.

The model (Jones; Harris & Kotzalas, *Rolling Bearing Analysis*, ch. 6-7), for steel balls and rings:

- **Contact.** Each ball touches the inner and the outer raceway in an elliptical Hertz contact. With the curvature
  sum ``sum_rho`` and curvature difference ``F(rho)`` of a contact (from the ball diameter ``D``, the groove
  curvature ratio ``f = r_groove / D`` and ``gamma = D cos(alpha) / d_m``), the ellipticity ``kappa = a / b``
  solves ``F(rho) = ((kappa^2 + 1) E(e) - 2 K(e)) / ((kappa^2 - 1) E(e))`` with ``e^2 = 1 - 1 / kappa^2`` and the
  complete elliptic integrals ``K``, ``E``. The approach of the two bodies under the normal load ``Q`` is
  ``delta = delta* (3 Q / (2 sum_rho) * 2 (1 - nu^2) / E_Y)^(2/3) * sum_rho / 2`` with
  ``delta* = (2 K / pi) (pi / (2 kappa^2 E))^(1/3)``, i.e. ``Q = K_c delta^(3/2)``. Inner and outer contact act in
  series: ``K_n = (K_i^(-2/3) + K_o^(-2/3))^(-3/2)``.
- **Preloaded bearing.** The groove curvature centres are ``A = (f_i + f_o - 1) D`` apart. An axial load ``F_a``
  shared by all ``Z`` balls turns the contact angle from ``alpha_0`` to ``alpha`` with
  ``F_a / (Z K_n A^(3/2)) = sin(alpha) (cos(alpha_0) / cos(alpha) - 1)^(3/2)``; the ball load is
  ``Q = F_a / (Z sin alpha)`` and the contact deflection ``delta_n = A (cos alpha_0 / cos alpha - 1)``.
- **Stiffness.** With the contact stiffness ``k_n = dQ / d delta_n = 1.5 K_n delta_n^(1/2)`` and the geometric term
  ``Q / (A + delta_n)`` of the turning load line, one bearing has the axial and radial stiffness
  ``k_a = Z (k_n sin^2 alpha + Q / (A + delta_n) cos^2 alpha)`` and
  ``k_r = Z / 2 (k_n cos^2 alpha + Q / (A + delta_n) sin^2 alpha)`` (all balls loaded; the radial value is the
  average over the azimuth, ``sum cos^2 psi_j = Z / 2``). A rigidly preloaded duplex pair has twice each.

Every coefficient follows from the geometry and the material; no catalogue constant is carried over.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import sympy as sp
from scipy.optimize import brentq
from scipy.special import ellipe, ellipk

from cappe.exceptions import ModelError

__all__ = ["AngularContactBearing", "BearingState", "acb_axial", "acb_radial", "contact_constant", "ellipticity"]


def ellipticity(curvature_difference: float) -> float:
    """Ellipticity ``kappa = a / b >= 1`` of a Hertz contact with curvature difference ``F(rho)`` in [0, 1).

    >>> round(ellipticity(0.0), 12)   # equal principal curvatures: a circular contact
    1.0
    """
    f_rho = float(curvature_difference)
    if not 0.0 <= f_rho < 1.0:
        msg = f"curvature difference F(rho) must be in [0, 1); got {f_rho}"
        raise ModelError(msg)
    if f_rho < 1e-12:
        return 1.0

    def residual(kappa: float) -> float:
        m = 1.0 - 1.0 / kappa**2
        big_e = ellipe(m)
        return float(((kappa**2 + 1) * big_e - 2 * ellipk(m)) / ((kappa**2 - 1) * big_e) - f_rho)

    return float(brentq(residual, 1.0 + 1e-9, 1e4, xtol=1e-14, rtol=1e-14))


def contact_constant(curvature_sum: float, curvature_difference: float, youngs_modulus: float,
                     poisson: float) -> float:
    """``K_c`` of ``Q = K_c delta^(3/2)`` for one Hertz point contact of two bodies of the same material (SI).

    Two equal spheres of radius R (``sum_rho = 4 / R``) give the classical ``delta^3 = 4.5 Q^2 (1 - nu^2)^2 /
    (E^2 R)``:

    >>> R, E, nu, Q = 0.01, 2.0e11, 0.3, 100.0
    >>> delta = (Q / contact_constant(4 / R, 0.0, E, nu)) ** (2 / 3)
    >>> round(delta / (4.5 * Q**2 * (1 - nu**2) ** 2 / (E**2 * R)) ** (1 / 3), 12)
    1.0
    """
    if curvature_sum <= 0 or youngs_modulus <= 0 or not 0 <= poisson < 0.5:
        msg = (f"contact needs curvature_sum > 0, youngs_modulus > 0 and 0 <= poisson < 0.5; got "
               f"{curvature_sum}, {youngs_modulus}, {poisson}")
        raise ModelError(msg)
    kappa = ellipticity(curvature_difference)
    m = 1.0 - 1.0 / kappa**2
    big_k, big_e = ellipk(m), ellipe(m)
    delta_star = (2 * big_k / math.pi) * (math.pi / (2 * kappa**2 * big_e)) ** (1 / 3)
    # delta = c Q^(2/3)
    c = delta_star * (3 / (2 * curvature_sum) * 2 * (1 - poisson**2) / youngs_modulus) ** (2 / 3) * curvature_sum / 2
    return float(c ** (-1.5))


@dataclass(frozen=True)
class BearingState:
    """A preloaded angular-contact bearing at one axial load (all SI; angles in rad).

    ``axial_stiffness`` and ``radial_stiffness`` are those of one bearing (N/m); ``ball_load`` is ``Q`` (N),
    ``contact_deflection`` ``delta_n`` (m), ``axial_deflection`` the inner ring's axial displacement (m).

    Attributes
    ----------
    axial_load : float
        Axial (pre)load of the bearing in N.
    contact_angle : float
        Loaded contact angle in rad.
    ball_load : float
        Normal load ``Q`` of one ball in N.
    contact_deflection : float
        Normal approach ``delta_n`` of the raceways at one ball in m.
    axial_deflection : float
        Axial displacement of the inner ring from the unloaded contact in m.
    contact_stiffness : float
        ``dQ / d delta_n`` of one ball in N/m.
    axial_stiffness, radial_stiffness : float
        Axial and radial stiffness of the bearing in N/m.
    """

    axial_load: float
    contact_angle: float
    ball_load: float
    contact_deflection: float
    axial_deflection: float
    contact_stiffness: float
    axial_stiffness: float
    radial_stiffness: float


@dataclass(frozen=True)
class AngularContactBearing:
    """Geometry and material of an angular-contact ball bearing (SI; the contact angle in rad).

    Parameters
    ----------
    n_balls : int
    ball_diameter, pitch_diameter : float
        ``D`` and ``d_m`` in m.
    contact_angle : float
        Free (unloaded) contact angle ``alpha_0`` in rad.
    inner_curvature, outer_curvature : float
        Groove curvature ratios ``f = r / D`` (just above 0.5).
    youngs_modulus, poisson : float
        Of balls and rings (bearing steel by default).

    Examples
    --------
    >>> b = AngularContactBearing(18, 7.938e-3, 0.065, math.radians(15))
    >>> s100, s50 = b.state(378.0), b.state(189.0)
    >>> 1.2 < s100.radial_stiffness / s50.radial_stiffness < 1.27   # about the 1/3 power of the preload ratio
    True
    """

    n_balls: int
    ball_diameter: float
    pitch_diameter: float
    contact_angle: float
    inner_curvature: float = 0.52
    outer_curvature: float = 0.53
    youngs_modulus: float = 2.08e11
    poisson: float = 0.3

    def __post_init__(self) -> None:
        problems = []
        if isinstance(self.n_balls, bool) or not isinstance(self.n_balls, int) or self.n_balls < 3:
            problems.append(f"n_balls must be an integer >= 3; got {self.n_balls!r}")
        if not 0 < self.ball_diameter < self.pitch_diameter:
            problems.append(f"need 0 < ball_diameter < pitch_diameter; got {self.ball_diameter}, {self.pitch_diameter}")
        if not 0 < self.contact_angle < math.pi / 2:
            problems.append(f"contact_angle must be in (0, pi/2) rad; got {self.contact_angle}")
        for name in ("inner_curvature", "outer_curvature"):
            if not 0.5 < getattr(self, name) < 1.0:
                problems.append(f"{name} must be in (0.5, 1); got {getattr(self, name)}")
        if problems:
            raise ModelError("; ".join(problems))

    @property
    def curvature_centre_distance(self) -> float:
        """``A = (f_i + f_o - 1) D`` (m)."""
        return (self.inner_curvature + self.outer_curvature - 1.0) * self.ball_diameter

    def _contacts(self, alpha: float) -> tuple[tuple[float, float], tuple[float, float]]:
        """(sum_rho, F(rho)) of the inner and the outer contact at contact angle ``alpha``."""
        d = self.ball_diameter
        gamma = d * math.cos(alpha) / self.pitch_diameter
        fi, fo = self.inner_curvature, self.outer_curvature
        inner_sum = (4 - 1 / fi + 2 * gamma / (1 - gamma)) / d
        inner_diff = (1 / fi + 2 * gamma / (1 - gamma)) / (4 - 1 / fi + 2 * gamma / (1 - gamma))
        outer_sum = (4 - 1 / fo - 2 * gamma / (1 + gamma)) / d
        outer_diff = (1 / fo - 2 * gamma / (1 + gamma)) / (4 - 1 / fo - 2 * gamma / (1 + gamma))
        return (inner_sum, inner_diff), (outer_sum, outer_diff)

    def contact_constant(self, alpha: float | None = None) -> float:
        """``K_n`` of ``Q = K_n delta_n^(3/2)`` for one ball between both raceways (N/m^1.5) at ``alpha``.

        Parameters
        ----------
        alpha : float, optional
            Contact angle in rad (default the unloaded one).

        Returns
        -------
        float
            In N/m^1.5.
        """
        angle = self.contact_angle if alpha is None else float(alpha)
        (si, fi), (so, fo) = self._contacts(angle)
        k_in = contact_constant(si, fi, self.youngs_modulus, self.poisson)
        k_out = contact_constant(so, fo, self.youngs_modulus, self.poisson)
        return float((k_in ** (-2 / 3) + k_out ** (-2 / 3)) ** (-1.5))

    def state(self, axial_load: float) -> BearingState:
        """The bearing under the axial (pre)load ``axial_load`` (N), shared by all balls.

        Parameters
        ----------
        axial_load : float
            Axial load in N, > 0.

        Returns
        -------
        BearingState

        Raises
        ------
        ModelError
            ``axial_load`` is not a positive finite number.
        """
        fa = float(axial_load)
        if not (math.isfinite(fa) and fa > 0):
            msg = f"axial load must be a positive number of newtons; got {axial_load!r}"
            raise ModelError(msg)
        a0, big_a, z = self.contact_angle, self.curvature_centre_distance, self.n_balls
        # K_n depends on alpha only through gamma (weakly): fix point on it, the load equation by bracketing
        k_n = self.contact_constant(a0)
        alpha = a0
        for _ in range(50):
            def load(angle: float, k_n: float = k_n) -> float:
                stretch = max(math.cos(a0) / math.cos(angle) - 1.0, 0.0)
                return float(z * k_n * big_a**1.5 * math.sin(angle) * stretch**1.5 - fa)

            alpha_new = float(brentq(load, a0, math.pi / 2 - 1e-9, xtol=1e-15, rtol=1e-15))
            k_new = self.contact_constant(alpha_new)
            done = abs(alpha_new - alpha) < 1e-14 and abs(k_new - k_n) <= 1e-13 * k_n
            alpha, k_n = alpha_new, k_new
            if done:
                break
        delta_n = big_a * (math.cos(a0) / math.cos(alpha) - 1.0)
        q = fa / (z * math.sin(alpha))
        k_c = 1.5 * k_n * math.sqrt(delta_n)
        geometric = q / (big_a + delta_n)
        return BearingState(
            axial_load=fa,
            contact_angle=alpha,
            ball_load=q,
            contact_deflection=delta_n,
            axial_deflection=(big_a + delta_n) * math.sin(alpha) - big_a * math.sin(a0),
            contact_stiffness=k_c,
            axial_stiffness=z * (k_c * math.sin(alpha) ** 2 + geometric * math.cos(alpha) ** 2),
            radial_stiffness=z / 2 * (k_c * math.cos(alpha) ** 2 + geometric * math.sin(alpha) ** 2),
        )

    def stiffness_curve(self, axial_loads: np.ndarray) -> dict[str, np.ndarray]:
        """Axial and radial stiffness of one bearing and its contact angle over axial loads (N).

        Parameters
        ----------
        axial_loads : array_like, shape (n,)
            Axial loads in N, > 0.

        Returns
        -------
        dict
            ``axial_load`` (N), ``contact_angle`` (rad), ``axial_stiffness`` and ``radial_stiffness`` (N/m), each an
            ndarray of shape (n,).
        """
        states = [self.state(float(f)) for f in np.atleast_1d(axial_loads)]
        return {
            "axial_load": np.array([s.axial_load for s in states]),
            "contact_angle": np.array([s.contact_angle for s in states]),
            "axial_stiffness": np.array([s.axial_stiffness for s in states]),
            "radial_stiffness": np.array([s.radial_stiffness for s in states]),
        }


# -- expression functions for model files ------------------------------------------------------------------------
# ``acb_radial(F, F_ref, Z, D, d_m, alpha0_deg)`` and ``acb_axial(...)``: the radial / axial stiffness of an
# angular-contact ball bearing (default groove curvatures and steel) at the axial preload F relative to that at
# F_ref. A model file multiplies its identified stiffness at the reference preload by them, e.g.
# ``kfx*acb_radial(378*preload, 378, 18, 0.0079375, 0.065, 15)``. Only the load F may depend on parameters.


@functools.lru_cache(maxsize=4096)
def _stiffness(kind: str, load: float, n_balls: int, ball: float, pitch: float, angle_deg: float) -> float:
    bearing = AngularContactBearing(n_balls, ball, pitch, math.radians(angle_deg))
    state = bearing.state(load)
    return state.radial_stiffness if kind == "radial" else state.axial_stiffness


def _ratio(kind: str, load: float, reference: float, n_balls: float, ball: float, pitch: float,
           angle_deg: float) -> float:
    args = (int(round(n_balls)), float(ball), float(pitch), float(angle_deg))
    return _stiffness(kind, float(load), *args) / _stiffness(kind, float(reference), *args)


def _slope(kind: str, load: float, reference: float, n_balls: float, ball: float, pitch: float,
           angle_deg: float) -> float:
    # d ratio / d load by a central difference of the smooth scalar law (relative step 1e-5: error ~1e-10)
    h = 1e-5 * float(load)
    return (_ratio(kind, load + h, reference, n_balls, ball, pitch, angle_deg)
            - _ratio(kind, load - h, reference, n_balls, ball, pitch, angle_deg)) / (2 * h)


def _numeric(func: Callable[..., float], kind: str) -> Callable[..., np.ndarray]:
    """Elementwise over broadcast arrays (lambdify passes batches of parameter values)."""
    vectorized = np.vectorize(lambda *args: func(kind, *args), otypes=[float])

    def call(*args: object) -> np.ndarray:
        return np.asarray(vectorized(*args))

    return call


def _numbers(*args: sp.Expr) -> list[float] | None:
    """The arguments as floats when all are numbers (then sympy evaluates the function), else None."""
    return [float(a) for a in args] if all(a.is_Number for a in args) else None


class _BearingRatio(sp.Function):  # type: ignore[misc]
    """Base of the model-file functions ``acb_radial`` and ``acb_axial`` (see above)."""

    nargs = 6
    kind = "radial"

    @classmethod
    def eval(cls, load: sp.Expr, reference: sp.Expr, *geometry: sp.Expr) -> sp.Expr | None:
        values = _numbers(load, reference, *geometry)
        if values is None:
            return None
        if load == reference:
            return sp.Integer(1)  # keeps exact algebra exact at the reference preload
        return sp.Float(_ratio(cls.kind, *values))

    def fdiff(self, argindex: int = 1) -> sp.Expr:
        if argindex != 1:
            raise sp.core.function.ArgumentIndexError(self, argindex)
        return (_RadialSlope if self.kind == "radial" else _AxialSlope)(*self.args)


class _BearingSlope(sp.Function):  # type: ignore[misc]
    nargs = 6
    kind = "radial"

    @classmethod
    def eval(cls, load: sp.Expr, reference: sp.Expr, *geometry: sp.Expr) -> sp.Expr | None:
        values = _numbers(load, reference, *geometry)
        return None if values is None else sp.Float(_slope(cls.kind, *values))


class acb_radial(_BearingRatio):  # noqa: N801 - the name model files use
    kind = "radial"
    _imp_ = staticmethod(_numeric(_ratio, "radial"))


class acb_axial(_BearingRatio):  # noqa: N801 - the name model files use
    kind = "axial"
    _imp_ = staticmethod(_numeric(_ratio, "axial"))


class _RadialSlope(_BearingSlope):
    kind = "radial"
    _imp_ = staticmethod(_numeric(_slope, "radial"))


class _AxialSlope(_BearingSlope):
    kind = "axial"
    _imp_ = staticmethod(_numeric(_slope, "axial"))
