"""SymbolicModel against references derived independently of its closed-form point Jacobians.

Three references:

* :func:`cappe.model.lagrange.lagrange_matrices` (full nonlinear poses, energies, Hessians at q = 0) on the
  built-in models and on structures built here, compared exactly (``sympy.simplify(difference) == 0``);
* ``sympy.physics.mechanics`` models written here from scratch (frames, points, rigid bodies, spring and
  damper forces), linearized about q = 0 and compared exactly after mapping the coordinate order;
* mathematical properties every model must have (hypothesis, random numeric structures in exact rationals):
  M and K symmetric, M positive definite, K positive semi-definite, G skew-symmetric.

No test compares cappe with itself. All comparisons are exact (rational or symbolic arithmetic), so there
are no numerical tolerances.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import pytest
import sympy as sp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from sympy.physics.mechanics import (
    KanesMethod,
    LagrangesMethod,
    Lagrangian,
    Particle,
    Point,
    ReferenceFrame,
    RigidBody,
    dynamicsymbols,
    inertia,
)

from cappe.exceptions import ModelError
from cappe.model import Structure, StructureBuilder, SymbolicModel, load_model
from cappe.model._expressions import symbol
from cappe.model.lagrange import lagrange_matrices
from cappe.model.structure import DIRECTIONS

MATRICES = ("M", "C", "K", "G")
ZERO = sp.Integer(0)


# -- helpers ------------------------------------------------------------------------------------------
def assert_same(actual: sp.MatrixBase, expected: sp.MatrixBase, what: str) -> None:
    """Exact symbolic equality: every entry of ``simplify(actual - expected)`` must be 0."""
    assert actual.shape == expected.shape, f"{what}: shape {actual.shape} != {expected.shape}"
    wrong = {}
    for i in range(actual.rows):
        for j in range(actual.cols):
            difference = sp.expand(actual[i, j] - expected[i, j])
            if difference != 0 and sp.simplify(difference) != 0:
                wrong[(i, j)] = (actual[i, j], expected[i, j])
    assert not wrong, f"{what}: entries differ (cappe, reference): {wrong}"


def assert_matches_lagrange(structure: Structure) -> dict[str, sp.Matrix]:
    """Compare SymbolicModel's M, C, K, G with the energy-based reference; return the reference."""
    model = SymbolicModel(structure)
    reference = lagrange_matrices(structure)
    for name in MATRICES:
        assert_same(getattr(model, name), reference[name], f"{structure.name} {name}")
    return reference


def reorder(matrix: sp.Matrix, labels: Sequence[str], structure: Structure) -> sp.Matrix:
    """Permute a reference matrix whose rows/columns follow ``labels`` into ``structure.dofs`` order."""
    assert sorted(labels) == sorted(structure.dofs)
    index = [list(labels).index(label) for label in structure.dofs]
    return matrix.extract(index, index)


def kane_linear(
    frame: ReferenceFrame,
    q: Sequence[sp.Function],
    bodies: Sequence[RigidBody | Particle],
    loads: Sequence[tuple[Point, object]],
) -> tuple[sp.Matrix, sp.Matrix, sp.Matrix]:
    """Kane's equations with u = q', linearized about q = u = 0.

    ``KanesMethod`` gives ``M(q) u' = f(q, u)``; about rest, ``M(0) q'' - df/du q' - df/dq q = 0``. Returns
    ``(M, D, K)`` with ``D = -df/du`` (viscous damping plus gyroscopic) and ``K = -df/dq``. Setting u = 0
    before differentiating in q (and q = 0 before differentiating in u) is exact at the operating point and
    keeps the expressions small; dynamic symbols are swapped for plain symbols for the same reason.
    """
    t = dynamicsymbols._t
    u = dynamicsymbols(f"u0:{len(q)}")
    kinematics = [qi.diff(t) - ui for qi, ui in zip(q, u, strict=True)]
    method = KanesMethod(frame, q_ind=list(q), u_ind=u, kd_eqs=kinematics)
    method.kanes_equations(list(bodies), list(loads))
    qs = sp.symbols(f"qs0:{len(q)}", real=True)
    us = sp.symbols(f"us0:{len(q)}", real=True)
    plain = {**dict(zip(q, qs, strict=True)), **dict(zip(u, us, strict=True))}
    forcing = method.forcing.xreplace(plain)
    assert not forcing.atoms(sp.Derivative), "forcing still holds time derivatives"
    q_rest = {s: ZERO for s in qs}
    u_rest = {s: ZERO for s in us}
    mass = method.mass_matrix.xreplace(plain).xreplace(q_rest)
    stiffness = -forcing.xreplace(u_rest).jacobian(qs).xreplace(q_rest)
    damping = -forcing.xreplace(q_rest).jacobian(us).xreplace(u_rest)
    return mass, damping, stiffness


def spring_damper(point_b: Point, point_a: Point, origin: Point, frame: ReferenceFrame, direction: object,
                  k: sp.Expr, c: sp.Expr, q: Sequence[sp.Function]) -> list[tuple[Point, object]]:
    """Forces of a linear spring-damper along a fixed global ``direction`` between two points.

    The elongation is the change of the component of ``point_b - point_a`` along ``direction``
    since the rest configuration (q = 0); tension pulls b back towards a.
    """
    gap = point_b.pos_from(origin) - point_a.pos_from(origin)
    along = gap.dot(direction)
    elongation = along - along.subs({qi: 0 for qi in q})
    rate = (point_b.vel(frame) - point_a.vel(frame)).dot(direction)
    tension = k * elongation + c * rate
    return [(point_b, -tension * direction), (point_a, tension * direction)]


def in_frame(frame: ReferenceFrame, components: Sequence[sp.Expr]) -> object:
    """The vector with ``components`` along ``frame``'s x, y, z."""
    return components[0] * frame.x + components[1] * frame.y + components[2] * frame.z


def moving_frame(name: str, frame: ReferenceFrame, origin: Point, coordinates: Mapping[str, sp.Function],
                 position: Sequence[sp.Expr]) -> tuple[ReferenceFrame, Point]:
    """Frame and origin of a body: body-fixed x-y-z angles, origin translated from ``position``.

    ``coordinates`` maps the body's active DOFs (x y z rx ry rz) to dynamic symbols; the others stay 0.
    """
    angles = [coordinates.get(d, ZERO) for d in ("rx", "ry", "rz")]
    body_frame = frame.orientnew(f"{name}_frame", "Body", angles, "XYZ")
    shift = in_frame(frame, [coordinates.get(d, ZERO) for d in ("x", "y", "z")])
    body_origin = origin.locatenew(f"{name}_origin", in_frame(frame, position) + shift)
    body_origin.set_vel(frame, shift.dt(frame))
    return body_frame, body_origin


def body_point(name: str, body_origin: Point, body_frame: ReferenceFrame, frame: ReferenceFrame,
               r: Sequence[sp.Expr]) -> Point:
    """A point fixed in a body at ``r`` (body frame) from its origin."""
    point = body_origin.locatenew(name, in_frame(body_frame, r))
    point.v2pt_theory(body_origin, frame, body_frame)
    return point


def unit(v: Sequence[object]) -> sp.Matrix:
    w = sp.Matrix([sp.sympify(x) for x in v])
    return w / sp.sqrt(w.dot(w))


def params(builder: StructureBuilder, values: Mapping[str, tuple[float, str]]) -> dict[str, sp.Symbol]:
    for name, (value, kind) in values.items():
        builder.parameter(name, value, kind=kind)
    return {name: symbol(name) for name in values}


# -- structures built for the tests -------------------------------------------------------------------
# A block whose centre of mass is off its origin, with a full inertia tensor, on four corner mounts whose
# local axes are rotated (irrational direction cosines), with x/y/z stiffness and damping; one mount also
# has a rotational stiffness about its (rotated) local z axis.
BLOCK_POSITION = (sp.Rational(1, 10), sp.Rational(-1, 5), sp.Rational(1, 2))
BLOCK_CORNERS = (
    ((sp.Rational(3, 10), sp.Rational(1, 5), sp.Rational(-1, 10)), {"x": [1, 1, 0], "y": [-1, 1, 1]}),
    ((sp.Rational(-3, 10), sp.Rational(1, 5), sp.Rational(-1, 10)), {"x": [0, 1, 2], "y": [1, 0, 0]}),
    ((sp.Rational(-3, 10), sp.Rational(-1, 5), sp.Rational(-1, 10)), {"x": [2, -1, 1], "y": [1, 2, 0]}),
    ((sp.Rational(3, 10), sp.Rational(-1, 5), sp.Rational(-1, 10)), {"x": [1, 0, 1], "y": [0, 1, 0]}),
)


def block_structure() -> Structure:
    b = StructureBuilder("offset-block")
    params(b, {
        "m": (4.0, "mass"), "Ixx": (0.05, "inertia"), "Iyy": (0.07, "inertia"), "Izz": (0.09, "inertia"),
        "Ixy": (0.004, "other"), "Ixz": (-0.003, "other"), "Iyz": (0.002, "other"),
        "ex": (0.01, "length"), "ey": (-0.02, "length"), "ez": (0.03, "length"),
        "kx": (1.0e6, "stiffness"), "ky": (2.0e6, "stiffness"), "kz": (3.0e6, "stiffness"),
        "cx": (10.0, "damping"), "cy": (20.0, "damping"), "cz": (30.0, "damping"),
        "kt": (5.0e3, "stiffness"),
    })
    b.body("block", mass="m", inertia={"xx": "Ixx", "yy": "Iyy", "zz": "Izz", "xy": "Ixy", "xz": "Ixz",
                                       "yz": "Iyz"},
           position=list(BLOCK_POSITION), com=["ex", "ey", "ez"])
    for i, (corner, axes) in enumerate(BLOCK_CORNERS):
        extra = {"rz": "kt"} if i == 0 else {}
        on_ground = [BLOCK_POSITION[j] + corner[j] for j in range(3)]
        b.element(f"mount{i}", bodies=("ground", "block"), points=(on_ground, list(corner)),
                  axes=axes, stiffness={"x": "kx", "y": "ky", "z": "kz", **extra},
                  damping={"x": "cx", "y": "cy", "z": "cz"})
    return b.build()


def chain_structure() -> Structure:
    """Two bodies in a chain: ground - lower - upper, with offsets, rotated axes and a rotational joint."""
    b = StructureBuilder("two-body-chain")
    params(b, {
        "m1": (10.0, "mass"), "m2": (2.0, "mass"), "J1": (0.3, "inertia"), "J2x": (0.02, "inertia"),
        "J2y": (0.03, "inertia"), "J2z": (0.01, "inertia"), "J2xy": (0.001, "other"), "h": (0.05, "length"),
        "kg": (5.0e6, "stiffness"), "cg": (50.0, "damping"), "kb": (1.0e6, "stiffness"),
        "cb": (5.0, "damping"), "kr": (2.0e3, "stiffness"), "cr": (0.1, "damping"),
    })
    b.body("lower", mass="m1", inertia={"xx": "J1", "yy": "J1", "zz": "J1"}, dofs=["x", "y", "z", "rz"])
    b.body("upper", mass="m2", inertia={"xx": "J2x", "yy": "J2y", "zz": "J2z", "xy": "J2xy"},
           position=[0, 0, 0.4], com=[0, 0.01, "h"], dofs=["x", "z", "rx", "ry", "rz"])
    b.element("foot_a", bodies=("ground", "lower"), at=[0.2, 0.1, -0.1],
              stiffness={"x": "kg", "y": "kg", "z": "kg"}, damping={"x": "cg", "z": "cg"})
    b.element("foot_b", bodies=("ground", "lower"), at=[-0.2, -0.1, -0.1],
              stiffness={"x": "kg", "y": "kg", "z": "kg"}, damping={"y": "cg"})
    b.element("joint", bodies=("lower", "upper"), at=[0.05, 0.02, 0.25],
              axes={"x": [1, 2, 2], "y": [2, 1, -2]},
              stiffness={"x": "kb", "y": "kb", "z": "kb", "rx": "kr", "ry": "kr", "rz": "kr"},
              damping={"z": "cb", "ry": "cr"})
    b.element("joint_b", bodies=("upper", "lower"), points=([0.1, 0, -0.1], [0.1, 0, 0.3]),
              stiffness={"x": "kb"}, damping={"x": "cb"})
    return b.build()


def rotor_structure() -> Structure:
    """An axisymmetric rotor spinning about z on two radial bearings, centre of mass off the origin."""
    b = StructureBuilder("spinning-rotor")
    params(b, {
        "m": (5.0, "mass"), "Id": (0.2, "inertia"), "Ip": (0.01, "inertia"), "lc": (0.02, "length"),
        "a": (0.15, "length"), "bb": (0.25, "length"), "k1": (1.0e7, "stiffness"), "k2": (2.0e7, "stiffness"),
        "c1": (100.0, "damping"), "c2": (200.0, "damping"), "Omega": (300.0, "other"),
    })
    b.body("rotor", mass="m", inertia={"xx": "Id", "yy": "Id", "zz": "Ip"}, com=[0, 0, "lc"],
           dofs=["x", "y", "rx", "ry"], spin={"axis": "z", "speed": "Omega"})
    b.element("front", bodies=("ground", "rotor"), points=([0, 0, "a"], [0, 0, "a"]),
              stiffness={"x": "k1", "y": "k1"}, damping={"x": "c1", "y": "c1"})
    b.element("rear", bodies=("ground", "rotor"), points=([0, 0, "-bb"], [0, 0, "-bb"]),
              stiffness={"x": "k2", "y": "k2"}, damping={"x": "c2", "y": "c2"})
    return b.build()


# -- (a) against the energy-based Lagrange reference --------------------------------------------------
def test_two_mass_rig_matches_lagrange() -> None:
    structure = load_model("builtin:two-mass-rig")
    reference = assert_matches_lagrange(structure)
    k11, k12, k22 = symbol("k11"), symbol("k12"), symbol("k22")
    # and the reference itself is the textbook matrix
    assert reference["K"] == sp.Matrix([[k11 + k12, -k12], [-k12, k12 + k22]])


def test_offset_block_with_rotated_mounts_matches_lagrange() -> None:
    structure = block_structure()
    reference = assert_matches_lagrange(structure)
    # the test really exercises coupling: offset centre of mass couples translation and rotation in M,
    # and the rotated, off-centre mounts fill K
    assert reference["M"][0, 4] != 0
    assert all(reference["K"][i, j] != 0 for i in range(6) for j in range(6))


def test_two_body_chain_matches_lagrange() -> None:
    structure = chain_structure()
    reference = assert_matches_lagrange(structure)
    assert reference["K"][:4, 4:] != sp.zeros(4, 5)  # body-to-body coupling present


def test_dynamometer_plate_matches_lagrange() -> None:
    assert_matches_lagrange(load_model("builtin:dynamometer-plate"))


def test_spinning_rotor_matches_lagrange() -> None:
    structure = rotor_structure()
    assert_matches_lagrange(structure)
    g = SymbolicModel(structure).G
    assert g != sp.zeros(4, 4)
    assert (g + g.T).applyfunc(sp.expand) == sp.zeros(4, 4)
    rx, ry = structure.dofs.index("rotor.rx"), structure.dofs.index("rotor.ry")
    assert sp.expand(g[rx, ry] - symbol("Ip") * symbol("Omega")) == 0


def test_rotor_spinning_about_a_tilted_axis_matches_lagrange() -> None:
    """G = -Ip Omega [n]x for a spin axis that is not a coordinate axis (sign and orientation of [n]x)."""
    n = sp.Matrix([sp.Rational(3, 5), 0, sp.Rational(4, 5)])
    b = StructureBuilder("tilted-rotor")
    s = params(b, {"m": (2.0, "mass"), "Id": (0.1, "inertia"), "Ip": (0.03, "inertia"),
                   "k": (1.0e6, "stiffness"), "Omega": (100.0, "other")})
    tensor = s["Id"] * sp.eye(3) + (s["Ip"] - s["Id"]) * n * n.T  # axisymmetric about n
    b.body("rotor", mass="m", inertia=tensor.tolist(), dofs=["x", "rx", "ry", "rz"],
           spin={"axis": list(n), "speed": "Omega"})
    b.element("front", bodies=("ground", "rotor"), at=[0, 0.1, 0.2], stiffness={"x": "k", "y": "k", "z": "k"})
    b.element("rear", bodies=("ground", "rotor"), at=[0.1, 0, -0.2], stiffness={"x": "k", "y": "k", "z": "k"})
    structure = b.build()
    reference = assert_matches_lagrange(structure)
    expected = -s["Ip"] * s["Omega"] * sp.Matrix([[0, -n[2], n[1]], [n[2], 0, -n[0]], [-n[1], n[0], 0]])
    assert (reference["G"][1:, 1:] - expected).applyfunc(sp.expand) == sp.zeros(3, 3)


def test_spindle_bearing_matches_lagrange() -> None:
    assert_matches_lagrange(load_model("builtin:spindle-bearing"))


def test_lagrange_rejects_a_rotor_that_is_not_axisymmetric() -> None:
    # the builder already refuses such a body; a hand-made Structure must still be refused by the reference
    import dataclasses

    b = StructureBuilder("lopsided")
    b.body("r", mass=1, inertia={"xx": 1, "yy": 1, "zz": 3}, dofs=["rx", "ry"], spin={"axis": "z", "speed": 10})
    b.element("e", bodies=("ground", "r"), stiffness={"rx": 1, "ry": 1})
    with pytest.raises(ModelError, match="axisymmetric"):
        b.body("q", mass=1, inertia={"xx": 1, "yy": 2, "zz": 3, "xz": sp.Rational(1, 10)}, spin={"axis": "z", "speed": 10})
    good = b.build()
    lopsided = sp.ImmutableMatrix([[1, 0, sp.Rational(1, 10)], [0, 2, 0], [sp.Rational(1, 10), 0, 3]])
    bad = dataclasses.replace(good, bodies=(dataclasses.replace(good.bodies[0], inertia=lopsided),))
    with pytest.raises(ModelError, match="axisymmetric"):
        lagrange_matrices(bad)


# -- (b) against sympy.physics.mechanics models written from scratch -----------------------------------
def test_two_mass_rig_matches_lagranges_method() -> None:
    t = dynamicsymbols._t
    x1, x2 = dynamicsymbols("x1 x2")
    m1, m2, k11, k12, k22, c11, c12, c22 = (symbol(n) for n in "m1 m2 k11 k12 k22 c11 c12 c22".split())
    frame = ReferenceFrame("N")
    p1, p2 = Point("P1"), Point("P2")
    p1.set_vel(frame, x1.diff(t) * frame.x)
    p2.set_vel(frame, x2.diff(t) * frame.x)
    mass1, mass2 = Particle("mass1", p1, m1), Particle("mass2", p2, m2)
    mass1.potential_energy = k11 * x1**2 / 2 + k12 * (x2 - x1) ** 2 / 2
    mass2.potential_energy = k22 * x2**2 / 2
    lagrangian = Lagrangian(frame, mass1, mass2)
    v1, v2 = x1.diff(t), x2.diff(t)
    forces = [(p1, (-c11 * v1 - c12 * (v1 - v2)) * frame.x), (p2, (-c22 * v2 - c12 * (v2 - v1)) * frame.x)]
    method = LagrangesMethod(lagrangian, [x1, x2], forcelist=forces, frame=frame)
    method.form_lagranges_equations()
    qd = [x1.diff(t), x2.diff(t)]
    rest = {x1: 0, x2: 0, **{v: 0 for v in qd}, **{v.diff(t): 0 for v in qd}}
    # M_lin [q', q'']^T = A [q, q']^T, with M_lin = diag(I, M) and A = [[0, I], [-K, -C]]
    m_lin, a_lin, _, inputs = method.linearize(q_ind=[x1, x2], qd_ind=qd, op_point=rest, A_and_B=False)
    assert inputs.shape[0] == 0
    assert m_lin[:2, :2] == sp.eye(2)
    assert a_lin[:2, :] == sp.Matrix([[0, 0, 1, 0], [0, 0, 0, 1]])
    structure = load_model("builtin:two-mass-rig")
    model = SymbolicModel(structure)
    labels = ("mass1.x", "mass2.x")
    assert_same(model.M, reorder(m_lin[2:, 2:], labels, structure), "M")
    assert_same(model.C, reorder(-a_lin[2:, 2:], labels, structure), "C")
    assert_same(model.K, reorder(-a_lin[2:, :2], labels, structure), "K")
    assert model.G == sp.zeros(2, 2)


RIGID_BLOCK_POSITION = (sp.Rational(1, 5), sp.Rational(-1, 10), sp.Rational(3, 10))
RIGID_BLOCK_MOUNTS = (  # attachment point (body frame), local x and y axes (rational direction cosines)
    ((sp.Rational(1, 10), sp.Rational(1, 5), sp.Rational(-1, 10)), {"x": [3, 4, 0], "y": [-4, 3, 0]}),
    ((sp.Rational(-1, 10), sp.Rational(1, 5), sp.Rational(-1, 10)), {"x": [1, 0, 0], "y": [0, 1, 0]}),
    ((sp.Rational(0), sp.Rational(-1, 5), sp.Rational(-1, 10)), {"x": [2, 2, 1], "y": [1, -2, 2]}),
)


def rigid_block_structure() -> Structure:
    """A 6-DOF block off the global origin, offset centre of mass, springs at offset points (cappe side)."""
    b = StructureBuilder("rigid-block")
    params(b, {
        "m": (3.0, "mass"), "Ixx": (0.04, "inertia"), "Iyy": (0.05, "inertia"), "Izz": (0.06, "inertia"),
        "Ixy": (0.002, "other"), "Ixz": (0.001, "other"), "Iyz": (-0.003, "other"),
        "ox": (0.01, "length"), "oy": (0.02, "length"), "oz": (-0.03, "length"),
        "k1": (1.0e6, "stiffness"), "k2": (2.0e6, "stiffness"), "k3": (3.0e6, "stiffness"),
        "d1": (1.0, "damping"), "d2": (2.0, "damping"), "d3": (3.0, "damping"),
    })
    b.body("block", mass="m", inertia={"xx": "Ixx", "yy": "Iyy", "zz": "Izz", "xy": "Ixy", "xz": "Ixz",
                                       "yz": "Iyz"}, position=RIGID_BLOCK_POSITION, com=["ox", "oy", "oz"])
    for i, (point, axes) in enumerate(RIGID_BLOCK_MOUNTS):
        at = [RIGID_BLOCK_POSITION[j] + point[j] for j in range(3)]
        b.element(f"mount{i}", bodies=("ground", "block"), at=at, axes=axes,
                  stiffness={"x": "k1", "y": "k2", "z": "k3"}, damping={"x": "d1", "y": "d2", "z": "d3"})
    return b.build()


def test_rigid_block_matches_kanes_method() -> None:
    structure = rigid_block_structure()
    s = {n: symbol(n) for n in structure.parameter_names}
    labels = [f"block.{d}" for d in DIRECTIONS]
    q = dynamicsymbols("x y z rx ry rz")
    frame = ReferenceFrame("N")
    origin = Point("O")
    origin.set_vel(frame, 0)
    body_frame, body_origin = moving_frame("block", frame, origin, dict(zip(DIRECTIONS, q, strict=True)),
                                           RIGID_BLOCK_POSITION)
    centre = body_point("block_com", body_origin, body_frame, frame, (s["ox"], s["oy"], s["oz"]))
    central = inertia(body_frame, s["Ixx"], s["Iyy"], s["Izz"], s["Ixy"], s["Iyz"], s["Ixz"])
    body = RigidBody("block", centre, body_frame, s["m"], (central, centre))
    loads: list[tuple[Point, object]] = []
    for i, (point, axes) in enumerate(RIGID_BLOCK_MOUNTS):
        on_body = body_point(f"mount{i}", body_origin, body_frame, frame, point)
        on_ground = origin.locatenew(f"ground{i}", in_frame(frame, [RIGID_BLOCK_POSITION[j] + point[j]
                                                                    for j in range(3)]))
        on_ground.set_vel(frame, 0)
        ex, ey = unit(axes["x"]), unit(axes["y"])
        for e, k, c in ((ex, "k1", "d1"), (ey, "k2", "d2"), (ex.cross(ey), "k3", "d3")):
            direction = in_frame(frame, e)
            loads += spring_damper(on_body, on_ground, origin, frame, direction, s[k], s[c], q)
    mass, damping, stiffness = kane_linear(frame, q, [body], loads)
    model = SymbolicModel(structure)
    assert_same(model.M, reorder(mass, labels, structure), "M")
    assert_same(model.C, reorder(damping, labels, structure), "C")
    assert_same(model.K, reorder(stiffness, labels, structure), "K")
    assert model.G == sp.zeros(6, 6)


def test_spinning_rotor_matches_kanes_method() -> None:
    structure = rotor_structure()
    s = {n: symbol(n) for n in structure.parameter_names}
    t = dynamicsymbols._t
    labels = ["rotor.x", "rotor.y", "rotor.rx", "rotor.ry"]
    q = dynamicsymbols("x y rx ry")
    frame = ReferenceFrame("N")
    origin = Point("O")
    origin.set_vel(frame, 0)
    coordinates = dict(zip(("x", "y", "rx", "ry"), q, strict=True))
    # The shaft frame tilts with (rx, ry); the rotor frame spins in it about the shaft axis at Omega.
    shaft_frame, shaft_origin = moving_frame("shaft", frame, origin, coordinates, (0, 0, 0))
    rotor_frame = shaft_frame.orientnew("rotor_frame", "Axis", (s["Omega"] * t, shaft_frame.z))
    centre = body_point("rotor_com", shaft_origin, shaft_frame, frame, (0, 0, s["lc"]))
    # axisymmetric, so the central inertia dyadic reads the same in the shaft and rotor bases
    rotor = RigidBody("rotor", centre, rotor_frame, s["m"],
                      (inertia(shaft_frame, s["Id"], s["Id"], s["Ip"]), centre))
    loads: list[tuple[Point, object]] = []
    for name, z, k, c in (("front", s["a"], "k1", "c1"), ("rear", -s["bb"], "k2", "c2")):
        on_rotor = body_point(name, shaft_origin, shaft_frame, frame, (0, 0, z))
        on_ground = origin.locatenew(f"{name}_ground", z * frame.z)
        on_ground.set_vel(frame, 0)
        for direction in (frame.x, frame.y):
            loads += spring_damper(on_rotor, on_ground, origin, frame, direction, s[k], s[c], q)
    mass, velocity, stiffness = kane_linear(frame, q, [rotor], loads)
    no_damping = {s["c1"]: 0, s["c2"]: 0}
    no_spin = {s["Omega"]: 0}
    model = SymbolicModel(structure)
    assert_same(model.M, reorder(mass, labels, structure), "M")
    assert_same(model.K, reorder(stiffness, labels, structure), "K")
    assert_same(model.C, reorder(velocity.xreplace(no_spin), labels, structure), "C")
    assert_same(model.G, reorder(velocity.xreplace(no_damping), labels, structure), "G")
    assert model.G != sp.zeros(4, 4)


# -- properties on random numeric structures ----------------------------------------------------------
def small_rational(lo: int, hi: int, denominator: int) -> st.SearchStrategy[sp.Rational]:
    return st.integers(lo, hi).map(lambda n: sp.Rational(n, denominator))


def vectors(lo: int, hi: int, denominator: int) -> st.SearchStrategy[list[sp.Rational]]:
    return st.lists(small_rational(lo, hi, denominator), min_size=3, max_size=3)


@st.composite
def rotations(draw: st.DrawFn) -> sp.Matrix:
    """A rational rotation matrix (Cayley transform of a rational skew matrix)."""
    a, b, c = draw(st.lists(small_rational(-3, 3, 2), min_size=3, max_size=3))
    skew = sp.Matrix([[0, -c, b], [c, 0, -a], [-b, a, 0]])
    return (sp.eye(3) - skew).inv() * (sp.eye(3) + skew)


@st.composite
def random_structures(draw: st.DrawFn) -> Structure:
    """1-2 bodies with random DOFs, masses, inertias, offsets; 1-4 random elements; maybe a spinning body."""
    b = StructureBuilder("random")
    names = []
    for i in range(draw(st.integers(1, 2))):
        dofs = draw(st.lists(st.sampled_from(DIRECTIONS), min_size=1, max_size=6, unique=True))
        spin = None
        if draw(st.booleans()):
            # axisymmetric about a coordinate axis so that the spin axis is a principal axis
            axis = draw(st.sampled_from((0, 1, 2)))
            transverse, polar = draw(small_rational(1, 20, 100)), draw(small_rational(1, 20, 100))
            tensor = sp.diag(*[polar if j == axis else transverse for j in range(3)])
            spin = {"axis": ["x", "y", "z"][axis], "speed": draw(small_rational(-500, 500, 1))}
        else:
            root = sp.Matrix(3, 3, draw(st.lists(small_rational(-5, 5, 10), min_size=9, max_size=9)))
            tensor = root * root.T + sp.eye(3) / 100
        name = f"body{i}"
        b.body(name, mass=draw(small_rational(1, 100, 10)), inertia=tensor.tolist(),
               position=draw(vectors(-5, 5, 10)), com=draw(vectors(-5, 5, 100)), dofs=dofs, spin=spin)
        names.append(name)
    targets = ["ground", *names]
    for i in range(draw(st.integers(1, 4))):
        a = draw(st.sampled_from(targets))
        b_name = draw(st.sampled_from([n for n in targets if n != a]))
        frame = draw(rotations())
        stiff = draw(st.lists(st.sampled_from(DIRECTIONS), min_size=1, max_size=6, unique=True))
        damp = draw(st.lists(st.sampled_from(DIRECTIONS), max_size=6, unique=True))
        b.element(f"e{i}", bodies=(a, b_name), points=(draw(vectors(-5, 5, 10)), draw(vectors(-5, 5, 10))),
                  axes={"x": list(frame[:, 0]), "y": list(frame[:, 1])},
                  stiffness={d: draw(small_rational(1, 1000, 1)) for d in stiff},
                  damping={d: draw(small_rational(0, 100, 10)) for d in damp})
    return b.build()


PROPERTY_SETTINGS = settings(max_examples=20, deadline=None, database=None,
                             suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@PROPERTY_SETTINGS
@given(random_structures())
def test_random_structure_matrices_have_the_right_symmetry_and_definiteness(structure: Structure) -> None:
    """M, K, C symmetric; M positive definite; K, C positive semi-definite; G skew (zero without spin)."""
    model = SymbolicModel(structure)
    m, c, k, g = (sp.Matrix(getattr(model, name)) for name in MATRICES)
    # entries are exact rationals, so every check below is exact
    assert all(x.is_Rational for mat in (m, c, k, g) for x in mat)
    assert m == m.T
    assert k == k.T
    assert c == c.T
    assert g == -g.T
    assert m.is_positive_definite
    assert k.is_positive_semidefinite
    assert c.is_positive_semidefinite
    spinning = any(body.spin is not None and body.spin.speed != 0 and
                   sum(d.startswith("r") for d in body.dofs) >= 2 for body in structure.bodies)
    if not spinning:
        assert g == sp.zeros(*g.shape)


@pytest.mark.slow
@settings(max_examples=6, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(random_structures())
def test_random_structures_match_lagrange(structure: Structure) -> None:
    """The same random structures, compared entry by entry with the energy-based reference."""
    assert_matches_lagrange(structure)
