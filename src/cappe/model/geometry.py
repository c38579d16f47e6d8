"""Homogeneous transforms and the small-motion Jacobian of a point on a rigid body.

A body's pose is ``TM(q) = Trans(x, y, z) · Rx(rx) · Ry(ry) · Rz(rz)`` (thesis 3.4.2, Appendix A).
Linearizing the motion of a body point about the nominal pose (q = 0) gives the Jacobian
``J(r) = [I3, -[r]x]``: the point moves by ``u + theta × r``. :func:`point_jacobian` returns that closed
form; :func:`point_jacobian_from_transform` differentiates the full transform and is its independent check.
"""

from __future__ import annotations

from collections.abc import Sequence

import sympy as sp

__all__ = [
    "homogeneous_transform",
    "point_jacobian",
    "point_jacobian_from_transform",
    "rotation_x",
    "rotation_y",
    "rotation_z",
    "skew",
    "translation",
]


def translation(x: sp.Expr, y: sp.Expr, z: sp.Expr) -> sp.Matrix:
    """4x4 homogeneous translation."""
    return sp.Matrix([[1, 0, 0, x], [0, 1, 0, y], [0, 0, 1, z], [0, 0, 0, 1]])


def rotation_x(a: sp.Expr) -> sp.Matrix:
    """4x4 homogeneous rotation by angle ``a`` (rad) about x."""
    c, s = sp.cos(a), sp.sin(a)
    return sp.Matrix([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1]])


def rotation_y(a: sp.Expr) -> sp.Matrix:
    """4x4 homogeneous rotation by angle ``a`` (rad) about y."""
    c, s = sp.cos(a), sp.sin(a)
    return sp.Matrix([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1]])


def rotation_z(a: sp.Expr) -> sp.Matrix:
    """4x4 homogeneous rotation by angle ``a`` (rad) about z."""
    c, s = sp.cos(a), sp.sin(a)
    return sp.Matrix([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])


def homogeneous_transform(q: Sequence[sp.Expr]) -> sp.Matrix:
    """Pose ``Trans(x, y, z) Rx(rx) Ry(ry) Rz(rz)`` for ``q = (x, y, z, rx, ry, rz)``."""
    x, y, z, rx, ry, rz = q
    return translation(x, y, z) * rotation_x(rx) * rotation_y(ry) * rotation_z(rz)


def skew(v: Sequence[sp.Expr]) -> sp.Matrix:
    """Cross-product matrix: ``skew(a) @ b == a × b``."""
    return sp.Matrix([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def point_jacobian(r: Sequence[sp.Expr]) -> sp.Matrix:
    """3x6 Jacobian of the displacement of body point ``r`` (body frame) w.r.t. (x, y, z, rx, ry, rz)."""
    return sp.Matrix.hstack(sp.eye(3), -skew(r))


def point_jacobian_from_transform(r: Sequence[sp.Expr]) -> sp.Matrix:
    """The same Jacobian, by differentiating the full homogeneous transform at q = 0 (reference)."""
    q = sp.symbols("q0:6", real=True)
    moved = homogeneous_transform(q) * sp.Matrix([r[0], r[1], r[2], 1])
    jac = moved[:3, 0].jacobian(sp.Matrix(q))
    return sp.simplify(jac.subs({qi: 0 for qi in q}))
