"""Reference derivation of M, C, K and G from energies (Lagrange's equations), for validation only.

:class:`cappe.model.symbolic.SymbolicModel` writes the matrices down in closed form from the point
Jacobians ``[I, -[r]x]``. This module derives them a second, independent way: every body gets its full
nonlinear pose ``R(q) = Rx(rx) Ry(ry) Rz(rz)`` (:mod:`cappe.model.geometry`), and the matrices are the
second derivatives at ``q = 0`` of

* the kinetic energy ``T = 1/2 m |v_com|^2 + 1/2 w^T (R I R^T) w`` with ``[w]x = R' R^T``; a spinning
  body adds its spin ``Omega R n`` to ``w`` (the rotor spins about its own axis, which turns with the body),
* the potential energy ``V = 1/2 sum k_d l_d(q)^2``,
* the Rayleigh dissipation function ``D = 1/2 sum c_d (dl_d/dt)^2``,

where ``l_d`` is an element's elongation in its local direction ``d``: ``e_d . (P_b(q) - P_a(q) -
(P_b(0) - P_a(0)))`` for a translation, ``e_d . vee(skew(R_a^T R_b))`` for a rotation (exact to first order,
and not built on the small-angle formula). Then

``M = d2T/dqd2``, ``K = d2V/dq2``, ``C = d2D/dqd2`` and ``G = N - N^T`` with ``N_ij = d2T/(dqd_i dq_j)``,

all at ``q = qd = 0``. Time derivatives use the chain rule ``d/dt f(q) = sum_i df/dq_i qd_i``. The
derivatives are taken in the cheapest exact order (q or qd set to 0 as soon as the remaining derivatives no
longer need it; K by the product rule ``d2(k l^2 / 2) = k (dl dl^T + l d2l)``, where ``l = 0`` at rest).

For an axisymmetric rotor the spin adds ``Omega Ip w . (R n)`` and the constant ``Omega^2 Ip / 2`` to T:
the first gives ``G = -Ip Omega [n]x``, the second no stiffness (K comes from V alone).

Everything is exact and symbolic, so the cost grows quickly with the number of DOFs: this is for small
models, tests and model checks, not for hot paths. The hysteretic matrix H is not derived here (it is not
an energy term; it is ``sum eta k h^T h`` with the same ``h`` as K).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import sympy as sp

from cappe.exceptions import ModelError
from cappe.model.geometry import rotation_x, rotation_y, rotation_z
from cappe.model.structure import DIRECTIONS, GROUND, Body, StiffnessDampingElement, Structure

__all__ = ["lagrange_matrices"]


@dataclass(frozen=True)
class _Pose:
    """Nonlinear pose of one body (or of ground) as functions of the generalized coordinates."""

    origin: sp.Matrix  # 3x1, global position of the body origin
    rotation: sp.Matrix  # 3x3, body frame -> global frame

    def point(self, p: Sequence[sp.Expr]) -> sp.Matrix:
        """Global position of a point given in the body frame."""
        return self.origin + self.rotation * sp.Matrix(p)


def lagrange_matrices(structure: Structure) -> dict[str, sp.Matrix]:
    """Derive M, C, K and G of ``structure`` from its energies (independent reference).

    Parameters
    ----------
    structure : Structure
        The model. Every spinning body must be axisymmetric about its spin axis, with
        ``inertia @ n == polar_inertia * n`` (the derivation adds the spin to the angular velocity, which
        gives the usual gyroscopic matrix only for such a rotor).

    Returns
    -------
    dict[str, sympy.Matrix]
        ``{"M": ..., "C": ..., "K": ..., "G": ...}``, square in ``structure.n_dof``, rows and columns in
        ``structure.dofs`` order, entries expanded expressions in the parameter and axis symbols.

    Raises
    ------
    ModelError
        If a spinning body is not axisymmetric about its spin axis, or the model has flexible bodies (numeric FE
        matrices have no energy expressions to derive from).

    Examples
    --------
    >>> from cappe.model import load_model
    >>> lagrange_matrices(load_model("builtin:two-mass-rig"))["K"]
    Matrix([
    [k11 + k12,      -k12],
    [     -k12, k12 + k22]])
    """
    if structure.flexible_bodies:
        names = ", ".join(f.name for f in structure.flexible_bodies)
        msg = (f"model '{structure.name}' has flexible bodies ({names}) given by numeric FE matrices: the Lagrange "
               "derivation is for rigid-body models")
        raise ModelError(msg)
    q: list[sp.Symbol] = []
    qd: list[sp.Symbol] = []
    ground = _Pose(sp.zeros(3, 1), sp.eye(3))
    poses: dict[str, _Pose] = {GROUND: ground}
    nominal: dict[str, _Pose] = {GROUND: ground}
    for body in structure.bodies:
        full: list[sp.Expr] = []
        for d in DIRECTIONS:
            if d in body.dofs:
                # Dummy symbols cannot collide with parameter or axis names.
                q.append(sp.Dummy(f"q_{body.name}_{d}", real=True))
                qd.append(sp.Dummy(f"qd_{body.name}_{d}", real=True))
                full.append(q[-1])
            else:
                full.append(sp.Integer(0))
        poses[body.name] = _pose(body, full)
        nominal[body.name] = _pose(body, [sp.Integer(0)] * 6)

    def dt(expr: sp.Matrix) -> sp.Matrix:
        """Time derivative by the chain rule (q depends on time only through q itself)."""
        out = sp.zeros(*expr.shape)
        for qi, qdi in zip(q, qd, strict=True):
            out += expr.diff(qi) * qdi
        return out

    kinetic = [_kinetic_energy(body, poses[body.name], dt) for body in structure.bodies]
    springs: list[tuple[sp.Expr, sp.Expr]] = []  # V = sum 1/2 k l^2 as (k, l) pairs
    dissipation: list[sp.Expr] = []
    for element in structure.elements:
        for d in element.directions:
            stiffness = element.stiffness.get(d, sp.Integer(0))
            damping = element.damping.get(d, sp.Integer(0))
            if stiffness == 0 and damping == 0:
                continue
            elongation = _elongation(element, d, poses, nominal)
            if stiffness != 0:
                springs.append((stiffness, elongation))
            if damping != 0:
                rate = dt(sp.Matrix([elongation]))[0, 0]
                dissipation.append(damping * rate**2 / 2)

    q_rest = {s: sp.Integer(0) for s in q}
    qd_rest = {s: sp.Integer(0) for s in qd}
    # T and D are quadratic in qd, so setting q = 0 before differentiating with respect to qd is exact.
    kinetic_rest = [t.xreplace(q_rest) for t in kinetic]
    dissipation_rest = [d.xreplace(q_rest) for d in dissipation]
    # N_ij = d2T/(dqd_i dq_j) at rest. The partial derivatives commute, so differentiate in qd first and
    # set qd = 0 before differentiating in q: that drops the (large) part of T quadratic in qd early.
    coupling = _second_derivatives(kinetic, qd, q, between=qd_rest, after=q_rest).T
    result = {
        "M": _second_derivatives(kinetic_rest, qd, qd),
        "C": _second_derivatives(dissipation_rest, qd, qd),
        "K": _squares_hessian(springs, q, q_rest),
        "G": coupling - coupling.T,
    }
    return {name: matrix.applyfunc(sp.expand) for name, matrix in result.items()}


def _second_derivatives(
    terms: Sequence[sp.Expr],
    first: Sequence[sp.Symbol],
    second: Sequence[sp.Symbol],
    *,
    between: Mapping[sp.Symbol, sp.Expr] | None = None,
    after: Mapping[sp.Symbol, sp.Expr] | None = None,
) -> sp.Matrix:
    """Matrix ``A[i, j] = sum over terms of d/d second[i] (d term / d first[j])``.

    ``between`` is substituted after the first derivative and ``after`` after the second (both are
    evaluation points, e.g. q = 0). Each term is differentiated only with respect to the symbols it
    contains, which keeps the work proportional to the size of each body's or element's energy.
    """
    out = sp.zeros(len(second), len(first))
    index_first = {s: j for j, s in enumerate(first)}
    index_second = {s: i for i, s in enumerate(second)}
    for term in terms:
        present = term.free_symbols
        for s_first in present & index_first.keys():
            gradient = term.diff(s_first)
            if between:
                gradient = gradient.xreplace(dict(between))
            for s_second in gradient.free_symbols & index_second.keys():
                value = gradient.diff(s_second)
                if after:
                    value = value.xreplace(dict(after))
                out[index_second[s_second], index_first[s_first]] += value
    return out


def _squares_hessian(
    squares: Sequence[tuple[sp.Expr, sp.Expr]],
    variables: Sequence[sp.Symbol],
    rest: Mapping[sp.Symbol, sp.Expr],
) -> sp.Matrix:
    """Hessian at ``rest`` of ``V = sum 1/2 k l(q)^2`` over ``(k, l)`` pairs.

    By the product rule, ``d2(1/2 k l^2)/dq_i dq_j = k (dl/dq_i dl/dq_j + l d2l/dq_i dq_j)``. The second
    derivatives of ``l`` are only needed where ``l`` does not vanish at ``rest``; an elongation is zero in the
    nominal configuration, so usually only the gradient is computed (n derivatives per term instead of n^2).
    """
    n = len(variables)
    out = sp.zeros(n, n)
    rest_map = dict(rest)
    for k, length in squares:
        gradient = sp.Matrix([length.diff(v).xreplace(rest_map) for v in variables])
        out += k * gradient * gradient.T
        value = length.xreplace(rest_map)
        if value != 0:
            out += k * value * sp.hessian(length, variables).xreplace(rest_map)
    return out


def _pose(body: Body, full: Sequence[sp.Expr]) -> _Pose:
    """Pose of ``body`` for ``full = (x, y, z, rx, ry, rz)`` (inactive entries 0)."""
    x, y, z, rx, ry, rz = full
    rotation = (rotation_x(rx) * rotation_y(ry) * rotation_z(rz))[:3, :3]
    origin = sp.Matrix(body.position) + sp.Matrix([x, y, z])
    return _Pose(origin, rotation)


def _vee(w: sp.Matrix) -> sp.Matrix:
    """Vector of the skew-symmetric part of a 3x3 matrix (``vee([a]x) == a``)."""
    return sp.Matrix([w[2, 1] - w[1, 2], w[0, 2] - w[2, 0], w[1, 0] - w[0, 1]]) / 2


def _kinetic_energy(body: Body, pose: _Pose, dt: Callable[[sp.Matrix], sp.Matrix]) -> sp.Expr:
    """Kinetic energy of one body: translation of the centre of mass plus rotation about it."""
    rotation = pose.rotation
    velocity = dt(pose.point(body.com))
    omega = _vee(dt(rotation) * rotation.T)
    if body.spin is not None:
        n = sp.Matrix(body.spin.axis)
        residue = sp.simplify(body.inertia * n - body.spin.polar_inertia * n)
        if residue != sp.zeros(3, 1):
            msg = (
                f"body {body.name!r}: the reference derivation needs a rotor axisymmetric about its spin "
                f"axis (inertia @ n == polar_inertia * n); got inertia @ n - polar_inertia * n = "
                f"{list(residue)}"
            )
            raise ModelError(msg)
        omega = omega + body.spin.speed * rotation * n
    inertia = rotation * sp.Matrix(body.inertia) * rotation.T
    translational = body.mass * (velocity.T * velocity)[0, 0] / 2
    rotational = (omega.T * inertia * omega)[0, 0] / 2
    return translational + rotational


def _elongation(
    element: StiffnessDampingElement, direction: str, poses: Mapping[str, _Pose], nominal: Mapping[str, _Pose]
) -> sp.Expr:
    """Nonlinear elongation of ``element`` in its local ``direction`` (zero at q = 0).

    ``poses`` are the bodies' poses as functions of q, ``nominal`` the same poses at q = 0.
    """
    k = DIRECTIONS.index(direction)
    axis = sp.Matrix(element.axes[:, k % 3])
    pose_a, pose_b = poses[element.body_a], poses[element.body_b]
    if k < 3:
        gap = pose_b.point(element.point_b) - pose_a.point(element.point_a)
        nominal_b = nominal[element.body_b].point(element.point_b)
        nominal_a = nominal[element.body_a].point(element.point_a)
        return (axis.T * (gap - (nominal_b - nominal_a)))[0, 0]
    relative = pose_a.rotation.T * pose_b.rotation
    return (axis.T * _vee(relative))[0, 0]
