"""Structure descriptions: parameters, axes, rigid bodies, stiffness-damping elements, inputs, outputs, sensors.

Every description is a frozen dataclass holding sympy expressions in the model's parameter and axis names.
A :class:`Structure` is immutable; it is built and validated by :class:`StructureBuilder` (which the YAML
loader also uses, so a file and a Python script that say the same thing give the same Structure).

Conventions (SI units throughout)
---------------------------------
* Every body has a reference point (its *origin*) whose nominal position in the global frame is
  ``position``; the body frame is parallel to the global frame in the nominal configuration. Attachment
  points, sensor points and the centre of mass are given in the body frame, relative to the origin.
  Points on ``ground`` are global coordinates. Positions and points may depend on axis coordinates
  (thesis CASE 3: the nominal configuration moves with the axes; small vibrations are superimposed).
* Generalized coordinates per body: translations ``x y z`` of the origin and small rotations
  ``rx ry rz`` about the global axes; a body uses 1-6 of them (``dofs``). Inactive DOFs are held at zero.
* An element joins body ``a`` to body ``b``. Its local axes are the columns of ``axes`` (global frame).
  The elongation in local direction ``x`` is the displacement of b's point minus a's point along the
  local x axis; ``rx`` is the relative rotation about that axis. Each direction may carry a stiffness
  ``k`` (N/m or N m/rad), a viscous damping ``c`` (N s/m or N m s/rad) and a loss factor ``eta``
  (dimensionless): the hysteretic (structural) damping force is ``1j * eta * k * elongation``, so the
  hysteretic matrix is ``H = sum(eta k h^T h)`` and an isolated element has damping ratio ``eta / 2``.
* A spinning body (``spin``) adds the gyroscopic matrix ``G = -Ip * Omega * [n]x`` on its rotational DOFs,
  with ``n`` the unit spin axis, ``Ip`` the polar moment of inertia and ``Omega`` the spin speed (rad/s).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
import sympy as sp

from cappe.exceptions import ModelError
from cappe.model._expressions import NAME_PATTERN, as_expression, shown, symbol
from cappe.model.flexible import (
    FlexibleBody,
    InterfaceNode,
    OffsetPoint,
    checked_matrices,
    frame_node_entries,
    matrix_source,
    modal_damping_matrix,
    needed_rotations,
    parse_damping,
    parse_lines,
    parse_nodes,
    reduced_body,
)

__all__ = [
    "DIRECTIONS",
    "GROUND",
    "PARAMETER_KINDS",
    "QUANTITIES",
    "Axis",
    "Body",
    "FlexibleBody",
    "Input",
    "Output",
    "Parameter",
    "Sensor",
    "Spin",
    "StiffnessDampingElement",
    "Structure",
    "StructureBuilder",
]

GROUND = "ground"
DIRECTIONS = ("x", "y", "z", "rx", "ry", "rz")
PARAMETER_KINDS = ("mass", "inertia", "stiffness", "damping", "loss", "length", "other")
QUANTITIES = ("displacement", "velocity", "acceleration", "elongation")
_UNIT_AXES = {"x": (1, 0, 0), "y": (0, 1, 0), "z": (0, 0, 1)}

Vector3 = tuple[sp.Expr, sp.Expr, sp.Expr]


@dataclass(frozen=True)
class Parameter:
    """A named model parameter (SI value).

    ``unknown`` marks the parameters an identification should estimate; ``disturbable`` marks known
    parameters whose values are uncertain enough to perturb in robustness studies.

    Attributes
    ----------
    name : str
        Name used in expressions (``k11``, ``me1_kx``).
    value : float
        Nominal value in SI units.
    unit : str
        Unit text (``"N/m"``).
    kind : str
        One of :data:`PARAMETER_KINDS` (``"mass"``, ``"stiffness"`` ...); sets the sign rules.
    bounds : (float, float) or None
        Search bounds (SI).
    unknown : bool
        To be estimated.
    disturbable : bool
        Known but uncertain.
    description : str
        Free text.
    """

    name: str
    value: float
    unit: str = ""
    kind: str = "other"
    bounds: tuple[float, float] | None = None
    unknown: bool = False
    disturbable: bool = False
    description: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "value": self.value,
            "unit": self.unit,
            "kind": self.kind,
            "bounds": list(self.bounds) if self.bounds is not None else None,
            "unknown": self.unknown,
            "disturbable": self.disturbable,
        }


@dataclass(frozen=True)
class Axis:
    """A machine axis whose coordinate (m or rad) reconfigures the structure.

    Attributes
    ----------
    name : str
        Name used in expressions (``z``).
    positions : tuple of float
        Positions of interest (m or rad); the first is the default.
    unit : str
        ``"m"`` or ``"rad"``.
    description : str
        Free text.
    """

    name: str
    positions: tuple[float, ...]
    unit: str = "m"
    description: str = ""


@dataclass(frozen=True)
class Spin:
    """Steady spin of a body: unit axis ``axis`` (global), speed ``speed`` (rad/s), polar inertia (kg m^2).

    Attributes
    ----------
    axis : tuple of 3 sympy expressions
        Unit spin axis in global coordinates.
    speed : sympy expression
        Spin speed in rad/s.
    polar_inertia : sympy expression
        Polar moment of inertia about the axis in kg m^2.
    """

    axis: Vector3
    speed: sp.Expr
    polar_inertia: sp.Expr


@dataclass(frozen=True)
class Body:
    """A rigid body: mass (kg), inertia tensor about its centre of mass (kg m^2), nominal origin, DOFs.

    Attributes
    ----------
    name : str
        Body name.
    mass : sympy expression
        Mass in kg.
    inertia : sympy.ImmutableMatrix, shape (3, 3)
        Inertia tensor about the centre of mass in kg m^2 (global axes).
    position : tuple of 3 sympy expressions
        Nominal origin in global coordinates (m; may depend on axes).
    com : tuple of 3 sympy expressions
        Centre of mass relative to the origin (m).
    dofs : tuple of str
        Active directions among ``x y z rx ry rz``.
    spin : Spin or None
        Steady spin (gyroscopic terms).
    description : str
        Free text.
    """

    name: str
    mass: sp.Expr
    inertia: sp.ImmutableMatrix
    position: Vector3
    com: Vector3
    dofs: tuple[str, ...]
    spin: Spin | None = None
    description: str = ""


@dataclass(frozen=True)
class StiffnessDampingElement:
    """A stiffness-damping element (SDE) joining body ``body_a`` to ``body_b`` (either may be ground).

    Attributes
    ----------
    name : str
        Element name.
    body_a, body_b : str
        The joined bodies (``"ground"`` allowed).
    point_a, point_b : tuple of 3 sympy expressions
        Attachment points in each body's frame (m).
    axes : sympy.ImmutableMatrix, shape (3, 3)
        Local axes of the element (columns, global coordinates).
    stiffness : mapping direction -> sympy expression
        Stiffness per local direction (N/m, N m/rad).
    damping : mapping direction -> sympy expression
        Viscous damping per local direction (N s/m, N m s/rad).
    loss : mapping direction -> sympy expression
        Loss factor per local direction (hysteretic damping ``eta k``; dimensionless).
    description : str
        Free text.
    """

    name: str
    body_a: str
    body_b: str
    point_a: Vector3
    point_b: Vector3
    axes: sp.ImmutableMatrix
    stiffness: Mapping[str, sp.Expr]
    damping: Mapping[str, sp.Expr]
    loss: Mapping[str, sp.Expr]
    description: str = ""

    @property
    def directions(self) -> tuple[str, ...]:
        """Directions that carry stiffness, damping or loss, in DIRECTIONS order."""
        used = set(self.stiffness) | set(self.damping) | set(self.loss)
        return tuple(d for d in DIRECTIONS if d in used)


@dataclass(frozen=True)
class Input:
    """A force (N) or moment (N m) acting on ``body`` at ``point`` along unit ``direction`` (global).

    Attributes
    ----------
    name : str
        Input name.
    kind : {"force", "moment"}
        What acts.
    body : str
        The body it acts on.
    point : tuple of 3 sympy expressions
        Point of action in the body frame (m).
    direction : tuple of 3 sympy expressions
        Unit direction (global).
    """

    name: str
    kind: str
    body: str
    point: Vector3
    direction: Vector3


@dataclass(frozen=True)
class Output:
    """A measured quantity: motion of a body point along a direction, or an element elongation.

    For ``quantity == "elongation"``, ``element`` and ``element_direction`` name the element and its
    local direction; otherwise ``body``, ``point`` and ``direction`` (unit, global) are used. A rotational
    motion output is given with ``rotation=True`` (rad, rad/s, rad/s^2).

    Attributes
    ----------
    name : str
        Output name.
    quantity : str
        One of :data:`QUANTITIES`.
    body : str
        The body moving (motion outputs).
    point : tuple of 3 sympy expressions
        The point in the body frame (m).
    direction : tuple of 3 sympy expressions
        Unit direction (global).
    rotation : bool
        The rotation about ``direction`` instead of the translation along it.
    element : str
        The element (elongation outputs).
    element_direction : str
        Its local direction (elongation outputs).
    """

    name: str
    quantity: str
    body: str = ""
    point: Vector3 = (sp.Integer(0), sp.Integer(0), sp.Integer(0))
    direction: Vector3 = (sp.Integer(1), sp.Integer(0), sp.Integer(0))
    rotation: bool = False
    element: str = ""
    element_direction: str = ""


@dataclass(frozen=True)
class Sensor:
    """A named sensor node: a point on a body (body frame).

    Attributes
    ----------
    name : str
        Node name; its channels are ``"name:x"``, ``"name:y"``, ``"name:z"``.
    body : str
        The body it sits on.
    point : tuple of 3 sympy expressions
        The point in the body frame (m).
    """

    name: str
    body: str
    point: Vector3


@dataclass(frozen=True)
class Structure:
    """A validated, immutable description of a lumped-parameter machine structure.

    Made by :class:`StructureBuilder` or :func:`cappe.model.load_model`.

    Attributes
    ----------
    name : str
        Model name.
    parameters : tuple of Parameter
    axes : tuple of Axis
    bodies : tuple of Body
    elements : tuple of StiffnessDampingElement
    inputs : tuple of Input
    outputs : tuple of Output
    sensors : tuple of Sensor
    description : str
        Free text.
    source : str
        The model file, for messages.
    flexible_bodies : tuple of FlexibleBody
        Bodies given by numeric FE matrices; their coordinates follow the rigid bodies'.
    """

    name: str
    parameters: tuple[Parameter, ...]
    axes: tuple[Axis, ...]
    bodies: tuple[Body, ...]
    elements: tuple[StiffnessDampingElement, ...]
    inputs: tuple[Input, ...]
    outputs: tuple[Output, ...]
    sensors: tuple[Sensor, ...] = ()
    description: str = ""
    source: str = ""
    flexible_bodies: tuple[FlexibleBody, ...] = ()
    _index: Mapping[str, Mapping[str, int]] = field(default_factory=dict, repr=False, compare=False)

    # -- look-ups ---------------------------------------------------------------------------------
    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    @property
    def axis_names(self) -> tuple[str, ...]:
        return tuple(a.name for a in self.axes)

    @property
    def dofs(self) -> tuple[str, ...]:
        """Generalized coordinates as ``body.dof`` labels, bodies in order, then x y z rx ry rz; then each flexible
        body's (``bed.node.x``, ``bed.q1``)."""
        return (tuple(f"{b.name}.{d}" for b in self.bodies for d in b.dofs)
                + tuple(f"{f.name}.{d}" for f in self.flexible_bodies for d in f.dofs))

    @property
    def n_dof(self) -> int:
        return sum(len(b.dofs) for b in self.bodies) + sum(f.n_dof for f in self.flexible_bodies)

    def is_flexible(self, name: str) -> bool:
        """Whether ``name`` is a flexible body.

        Parameters
        ----------
        name : str
            Body name.

        Returns
        -------
        bool
        """
        return any(f.name == name for f in self.flexible_bodies)

    def flexible_body(self, name: str) -> FlexibleBody:
        """The flexible body of that name.

        Parameters
        ----------
        name : str
            Body name.

        Returns
        -------
        FlexibleBody

        Raises
        ------
        ModelError
            The model has no such flexible body.
        """
        return self.flexible_bodies[self._lookup("flexible_bodies", name)]

    def parameter(self, name: str) -> Parameter:
        """The parameter of that name.

        Parameters
        ----------
        name : str
            Parameter name.

        Returns
        -------
        Parameter

        Raises
        ------
        ModelError
            The model has no such parameter (the message lists the known ones).
        """
        return self.parameters[self._lookup("parameters", name)]

    def body(self, name: str) -> Body:
        """The body of that name.

        Parameters
        ----------
        name : str
            Body name.

        Returns
        -------
        Body

        Raises
        ------
        ModelError
            The model has no such body.
        """
        return self.bodies[self._lookup("bodies", name)]

    def element(self, name: str) -> StiffnessDampingElement:
        """The element of that name.

        Parameters
        ----------
        name : str
            Element name.

        Returns
        -------
        StiffnessDampingElement

        Raises
        ------
        ModelError
            The model has no such element.
        """
        return self.elements[self._lookup("elements", name)]

    def input(self, name: str) -> Input:
        """The input of that name.

        Parameters
        ----------
        name : str
            Input name.

        Returns
        -------
        Input

        Raises
        ------
        ModelError
            The model has no such input.
        """
        return self.inputs[self._lookup("inputs", name)]

    def output(self, name: str) -> Output:
        """The output of that name.

        Parameters
        ----------
        name : str
            Output name.

        Returns
        -------
        Output

        Raises
        ------
        ModelError
            The model has no such output.
        """
        return self.outputs[self._lookup("outputs", name)]

    def sensor(self, name: str) -> Sensor:
        """The sensor node of that name.

        Parameters
        ----------
        name : str
            Sensor name.

        Returns
        -------
        Sensor

        Raises
        ------
        ModelError
            The model has no such sensor.
        """
        return self.sensors[self._lookup("sensors", name)]

    def _lookup(self, group: str, name: str) -> int:
        index = self._index.get(group)
        if index is None:
            index = {item.name: i for i, item in enumerate(getattr(self, group))}
        if name not in index:
            known = ", ".join(index) or "none"
            what = _singular(group)
            msg = f"model '{self.name}' has no {what} named {name!r}; known: {known}"
            raise ModelError(msg)
        return index[name]

    @property
    def nominal(self) -> dict[str, float]:
        """Nominal parameter values by name."""
        return {p.name: p.value for p in self.parameters}

    def default_position(self) -> dict[str, float]:
        """The first listed position of every axis (0 when an axis lists none)."""
        return {a.name: (a.positions[0] if a.positions else 0.0) for a in self.axes}

    def resolve_parameters(self, values: Mapping[str, float] | None = None) -> dict[str, float]:
        """Nominal values overridden by ``values``.

        Unknown names, non-finite values and values their kind forbids (a mass, inertia or stiffness below
        zero or a mass or inertia of zero, a negative damping or loss factor) are errors naming the parameter's
        entry in the model file. A stiffness of 0 is allowed here (an element taken out).

        Parameters
        ----------
        values : mapping name -> float, optional
            Overrides (SI).

        Returns
        -------
        dict
            ``{name: value}`` of every parameter (SI), in model order.

        Raises
        ------
        ModelError
            A name is unknown or a value breaks its kind's rule.
        """
        out = self.nominal
        for name, value in (values or {}).items():
            if name not in out:
                msg = f"unknown parameter {name!r} for model '{self.name}'; known: {', '.join(out)}"
                raise ModelError(msg)
            where = f"{self.source + ', ' if self.source else ''}parameters[{self._lookup('parameters', name)}]"
            try:
                number = float(value)
            except (TypeError, ValueError) as exc:
                msg = f"parameter {name!r} must be a number; got {value!r} ({where})"
                raise ModelError(msg) from exc
            if not math.isfinite(number):
                msg = f"parameter {name!r} must be finite; got {value!r} ({where})"
                raise ModelError(msg)
            kind = self.parameter(name).kind
            if (kind in ("mass", "inertia") and number <= 0) or (
                    kind in ("stiffness", "damping", "loss") and number < 0):
                rule = "> 0" if kind in ("mass", "inertia") else ">= 0"
                msg = f"parameter {name!r} ({kind}) must be {rule}; got {number!r} ({where})"
                raise ModelError(msg)
            out[name] = number
        return out

    def disturbed(self, fraction: float, rng: np.random.Generator, values: Mapping[str, float] | None = None,
                  ) -> dict[str, float]:
        """Every ``disturbable`` parameter times ``1 + fraction`` or ``1 - fraction`` (random signs from ``rng``).

        The disturbed model of paper 3.3: known parameters deliberately wrong by a fixed relative amount.
        Values are taken from ``values`` where given, else nominal; the result holds the disturbable ones only.

        Parameters
        ----------
        fraction : float
            Relative disturbance, 0 <= fraction < 1 (0.1: +-10 %).
        rng : Generator
            Source of the signs.
        values : mapping name -> float, optional
            Values (SI) to disturb instead of the nominal ones.

        Returns
        -------
        dict
            ``{name: disturbed value}`` of the disturbable parameters (SI).

        Raises
        ------
        ModelError
            ``fraction`` is out of range, or ``values`` breaks a parameter rule.

        Examples
        --------
        >>> from cappe.model import load_model
        >>> s = load_model("builtin:uniaxial-machine-tool")
        >>> d = s.disturbed(0.1, np.random.default_rng(0))
        >>> len(d), sorted({round(float(v / s.nominal[n]), 6) for n, v in d.items()})
        (40, [0.9, 1.1])
        """
        if not (math.isfinite(fraction) and 0 <= fraction < 1):
            msg = f"disturbance fraction must be in [0, 1); got {fraction!r}"
            raise ModelError(msg)
        base = self.resolve_parameters(values)
        names = [p.name for p in self.parameters if p.disturbable]
        signs = rng.choice([-1.0, 1.0], size=len(names))
        return {n: base[n] * (1 + fraction * s) for n, s in zip(names, signs, strict=True)}

    def resolve_position(self, position: Mapping[str, float] | None = None) -> dict[str, float]:
        """Default axis position overridden by ``position``; unknown axes are errors.

        Parameters
        ----------
        position : mapping axis -> float, optional
            Axis values (m or rad).

        Returns
        -------
        dict
            ``{axis: value}`` of every axis.

        Raises
        ------
        ModelError
            An axis is unknown or a value is not a finite number.
        """
        out = self.default_position()
        for name, value in (position or {}).items():
            if name not in out:
                known = ", ".join(out) or "none (this model has no axes)"
                msg = f"unknown axis {name!r} for model '{self.name}'; known axes: {known}"
                raise ModelError(msg)
            try:
                number = float(value)
            except (TypeError, ValueError) as exc:
                msg = f"axis {name!r} position must be a number; got {value!r}"
                raise ModelError(msg) from exc
            if not math.isfinite(number):
                msg = f"axis {name!r} position must be finite; got {value!r}"
                raise ModelError(msg)
            out[name] = number
        return out


# ---------------------------------------------------------------------------------------------------
class StructureBuilder:
    """Builds a validated :class:`Structure` step by step.

    Parameters and axes must be declared before the expressions that use them. ``where`` arguments are
    locations for error messages (the YAML loader passes ``"file.yaml, bodies[2]"``).

    Parameters
    ----------
    name : str
        Model name.
    description : str
        Free text.
    source : str
        The model file, named in error messages.
    base : Path, optional
        Folder that matrix files of flexible bodies are read relative to (the model file's).

    Examples
    --------
    >>> b = StructureBuilder("spring-mass")
    >>> b.parameter("m", 2.0, unit="kg", kind="mass")
    >>> b.parameter("k", 8.0e3, unit="N/m", kind="stiffness")
    >>> b.body("mass", mass="m", dofs=["x"])
    >>> b.element("spring", bodies=("mass", "ground"), stiffness={"x": "k"})
    >>> b.input("F", body="mass", direction=[1, 0, 0])
    >>> b.output("d", quantity="displacement", body="mass", direction=[1, 0, 0])
    >>> b.build().n_dof
    1
    """

    def __init__(self, name: str, *, description: str = "", source: str = "", base: Path | None = None) -> None:
        self.name = name
        self.base = base
        self._flexible: list[FlexibleBody] = []
        self.description = description
        self.source = source
        self._parameters: list[Parameter] = []
        self._axes: list[Axis] = []
        self._bodies: list[Body] = []
        self._elements: list[StiffnessDampingElement] = []
        self._inputs: list[Input] = []
        self._outputs: list[Output] = []
        self._sensors: list[Sensor] = []
        self._names: dict[str, dict[str, str]] = {}
        self._where_of: dict[tuple[str, str], str] = {}
        self._points_cache: tuple[tuple[int, int], list[dict[sp.Symbol, sp.Float]]] | None = None

    # -- helpers ----------------------------------------------------------------------------------
    def _here(self, where: str | None, group: str, index: int) -> str:
        if where:
            return where
        return f"{self.source + ', ' if self.source else ''}{group}[{index}]"

    def _claim(self, group: str, name: object, where: str) -> str:
        if not isinstance(name, str) or not NAME_PATTERN.match(name):
            msg = f"{_singular(group)} name must be an identifier (letters, digits, _); got {name!r} ({where})"
            raise ModelError(msg)
        taken = self._names.setdefault(group, {})
        if name in taken:
            msg = f"duplicate {_singular(group)} name {name!r} ({where}); first defined at {taken[name]}"
            raise ModelError(msg)
        taken[name] = where
        return name

    @property
    def _symbols(self) -> list[str]:
        return [p.name for p in self._parameters] + [a.name for a in self._axes]

    def _expr(self, value: object, where: str) -> sp.Expr:
        return as_expression(value, self._symbols, where)

    def _vector(self, value: object, where: str, *, unit: bool = False) -> Vector3:
        if isinstance(value, str) and value.lstrip("+-") in _UNIT_AXES:
            sign = -1 if value.startswith("-") else 1
            return tuple(sp.Integer(sign * c) for c in _UNIT_AXES[value.lstrip("+-")])  # type: ignore[return-value]
        if not isinstance(value, (list, tuple)) or len(value) != 3:
            msg = f"expected a 3-vector [x, y, z]; got {value!r} ({where})"
            raise ModelError(msg)
        vec = tuple(self._expr(v, f"{where}[{i}]") for i, v in enumerate(value))
        if unit:
            norm2 = sum(v**2 for v in vec)
            nominal = self._nominal_value(norm2)
            if nominal is not None and nominal <= 1e-24:
                msg = f"direction must have non-zero length; got {list(value)!r} ({where})"
                raise ModelError(msg)
            norm = sp.sqrt(norm2)
            vec = tuple(_simplified(v / norm) for v in vec)
        return vec  # type: ignore[return-value]

    def _evaluation_points(self) -> list[dict[sp.Symbol, sp.Float]]:
        """Substitutions for validation: nominal parameters at every combination of listed axis positions.

        Made once per set of parameters and axes (they are only ever appended; every element's vectors are
        checked against them, which rebuilt them a few hundred times per model)."""
        key = (len(self._parameters), len(self._axes))
        cached = self._points_cache
        if cached is not None and cached[0] == key:
            return cached[1]
        params = {symbol(p.name): sp.Float(p.value) for p in self._parameters}
        grids = [[(symbol(a.name), sp.Float(v)) for v in (a.positions or (0.0,))] for a in self._axes]
        points = [{**params, **dict(combo)} for combo in itertools.product(*grids)]
        self._points_cache = (key, points)
        return points

    def _nominal_value(self, expr: sp.Expr) -> float | None:
        """Smallest value of ``expr`` over :meth:`_evaluation_points`; None if it is not a real number."""
        expr = sp.sympify(expr)
        if not expr.free_symbols:  # a number: the same at every point
            try:
                return float(expr.evalf())
            except (TypeError, ValueError):
                return None
        values = []
        for subs in self._evaluation_points():
            try:
                values.append(float(expr.xreplace(subs).evalf()))
            except (TypeError, ValueError):
                return None
        return min(values) if values else None

    def _relative(self, body: str, location: Vector3) -> Vector3:
        """A global location expressed in ``body``'s frame (ground: unchanged)."""
        if body == GROUND:
            return location
        origin = next(b.position for b in self._all_bodies() if b.name == body)
        return tuple(sp.expand(location[i] - origin[i]) for i in range(3))  # type: ignore[return-value]

    def _all_bodies(self) -> list[Body | FlexibleBody]:
        """Every body declared so far, rigid then flexible (the coordinates' order); one name space (``bodies``)."""
        return [*self._bodies, *self._flexible]

    def _claim_body(self, name: object, where: str) -> str:
        """Claim a rigid or flexible body's name (not ``ground``, not taken by either kind); returns ``where``."""
        if name == GROUND:
            msg = f"'ground' is reserved for the fixed frame and cannot name a body ({where})"
            raise ModelError(msg)
        self._claim("bodies", name, where)
        return where

    def _require_body(self, name: object, where: str, *, allow_ground: bool) -> str:
        known = [b.name for b in self._all_bodies()]
        if allow_ground and name == GROUND:
            return GROUND
        if name not in known:
            extra = " or 'ground'" if allow_ground else ""
            msg = f"unknown body {name!r} ({where}); known bodies: {', '.join(known) or 'none'}{extra}"
            raise ModelError(msg)
        return str(name)

    # -- declarations -----------------------------------------------------------------------------
    def parameter(
        self,
        name: str,
        value: float,
        *,
        unit: str = "",
        kind: str = "other",
        bounds: Sequence[float] | None = None,
        unknown: bool = False,
        disturbable: bool = False,
        description: str = "",
        where: str | None = None,
    ) -> None:
        """Declare a parameter with its nominal SI value.

        Parameters
        ----------
        name : str
            Name used in expressions.
        value : float
            Nominal value (SI): > 0 for mass, inertia and stiffness, >= 0 for damping and loss.
        unit : str
            Unit text (``"N/m"``).
        kind : str
            One of :data:`PARAMETER_KINDS`.
        bounds : (float, float), optional
            Search bounds (SI), lo < hi, holding ``value``.
        unknown : bool
            To be estimated.
        disturbable : bool
            Known but uncertain (robustness studies).
        description : str
            Free text.
        where : str, optional
            Location for error messages.

        Raises
        ------
        ModelError
            The name is taken, the kind unknown, or the value or bounds break a rule.
        """
        where = self._here(where, "parameters", len(self._parameters))
        self._claim("parameters", name, where)
        if name in {a.name for a in self._axes}:
            msg = f"parameter name {name!r} is already an axis name ({where})"
            raise ModelError(msg)
        if kind not in PARAMETER_KINDS:
            msg = f"parameter {name!r} kind must be one of {', '.join(PARAMETER_KINDS)}; got {kind!r} ({where})"
            raise ModelError(msg)
        number = _finite(value, f"parameter {name!r} value", where)
        if kind in ("mass", "inertia", "stiffness") and number <= 0:
            msg = f"parameter {name!r} ({kind}) must be > 0; got {number!r} ({where})"
            raise ModelError(msg)
        if kind in ("damping", "loss") and number < 0:
            msg = f"parameter {name!r} ({kind}) must be >= 0; got {number!r} ({where})"
            raise ModelError(msg)
        lohi: tuple[float, float] | None = None
        if bounds is not None:
            if not isinstance(bounds, (list, tuple)) or len(bounds) != 2:
                msg = f"parameter {name!r} bounds must be [lo, hi]; got {bounds!r} ({where})"
                raise ModelError(msg)
            lo = _finite(bounds[0], f"parameter {name!r} lower bound", where)
            hi = _finite(bounds[1], f"parameter {name!r} upper bound", where)
            if not lo < hi:
                msg = f"parameter {name!r} bounds must satisfy lo < hi; got [{lo!r}, {hi!r}] ({where})"
                raise ModelError(msg)
            if not lo <= number <= hi:
                msg = f"parameter {name!r} value {number!r} lies outside its bounds [{lo!r}, {hi!r}] ({where})"
                raise ModelError(msg)
            lohi = (lo, hi)
        if unknown and lohi is None:
            msg = f"unknown parameter {name!r} needs bounds [lo, hi] ({where})"
            raise ModelError(msg)
        self._parameters.append(
            Parameter(name, number, str(unit), kind, lohi, bool(unknown), bool(disturbable), str(description))
        )

    def axis(
        self,
        name: str,
        positions: Sequence[float] = (),
        *,
        unit: str = "m",
        description: str = "",
        where: str | None = None,
    ) -> None:
        """Declare a machine axis and the positions at which the model is studied.

        Parameters
        ----------
        name : str
            Name used in expressions.
        positions : sequence of float
            Positions of interest (m or rad); the first is the default.
        unit : str
            ``"m"`` or ``"rad"``.
        description : str
            Free text.
        where : str, optional
            Location for error messages.

        Raises
        ------
        ModelError
            The name is taken or a position is not a finite number.
        """
        where = self._here(where, "axes", len(self._axes))
        self._claim("axes", name, where)
        if name in {p.name for p in self._parameters}:
            msg = f"axis name {name!r} is already a parameter name ({where})"
            raise ModelError(msg)
        if not isinstance(positions, (list, tuple)):
            msg = f"axis {name!r} positions must be a list of numbers; got {positions!r} ({where})"
            raise ModelError(msg)
        values = tuple(_finite(v, f"axis {name!r} position", where) for v in positions)
        self._axes.append(Axis(name, values, str(unit), str(description)))

    def body(
        self,
        name: str,
        *,
        mass: object,
        inertia: object = None,
        position: object = (0, 0, 0),
        com: object = (0, 0, 0),
        dofs: Sequence[str] = DIRECTIONS,
        spin: Mapping[str, object] | None = None,
        description: str = "",
        where: str | None = None,
    ) -> None:
        """Declare a rigid body.

        ``inertia`` is the tensor about the centre of mass in the body frame: a 3x3 list, a mapping with
        keys ``xx yy zz xy xz yz`` (missing products are 0), or None for a point mass (only allowed when
        no rotational DOF is active).

        Parameters
        ----------
        name : str
            Body name.
        mass : expression
            Mass in kg (a number or an expression in parameters and axes).
        inertia : list, mapping or None
            Inertia tensor about the centre of mass in kg m^2 (see above).
        position : sequence of 3 expressions
            Nominal origin in global coordinates (m; may use axis coordinates).
        com : sequence of 3 expressions
            Centre of mass relative to the origin (m).
        dofs : sequence of str
            Active directions among ``x y z rx ry rz``.
        spin : mapping, optional
            Steady spin: ``speed`` (rad/s), ``axis`` (default ``"z"``) and ``polar_inertia`` (kg m^2, default from
            ``inertia``).
        description : str
            Free text.
        where : str, optional
            Location for error messages.

        Raises
        ------
        ModelError
            The name is taken or an entry breaks a rule.
        """
        where = self._claim_body(name, self._here(where, "bodies", len(self._bodies)))
        dof_list = list(dofs) if isinstance(dofs, (list, tuple)) else [dofs]
        bad = [d for d in dof_list if d not in DIRECTIONS]
        if bad or not dof_list or len(set(dof_list)) != len(dof_list):
            msg = (
                f"body {name!r} dofs must be 1-6 distinct names from {', '.join(DIRECTIONS)}; "
                f"got {dofs!r} ({where}.dofs)"
            )
            raise ModelError(msg)
        ordered = tuple(d for d in DIRECTIONS if d in dof_list)
        mass_expr = self._expr(mass, f"{where}.mass")
        mass_value = self._nominal_value(mass_expr)
        if mass_value is not None and mass_value <= 0:
            msg = f"body {name!r} mass must be > 0; got {mass_value:.6g} ({where}.mass)"
            raise ModelError(msg)
        rotational = any(d.startswith("r") for d in ordered)
        tensor = self._inertia(name, inertia, where, required=rotational)
        spin_obj = None
        if spin is not None:
            spin_obj = self._spin(name, spin, tensor, f"{where}.spin")
        self._bodies.append(
            Body(
                name=name,
                mass=mass_expr,
                inertia=tensor,
                position=self._vector(position, f"{where}.position"),
                com=self._vector(com, f"{where}.com"),
                dofs=ordered,
                spin=spin_obj,
                description=str(description),
            )
        )

    def _inertia(self, name: str, inertia: object, where: str, *, required: bool) -> sp.ImmutableMatrix:
        if inertia is None:
            if required:
                msg = f"body {name!r} has rotational DOFs and needs an inertia tensor ({where}.inertia)"
                raise ModelError(msg)
            return sp.ImmutableMatrix(sp.zeros(3, 3))
        here = f"{where}.inertia"
        if isinstance(inertia, Mapping):
            unknown = set(inertia) - {"xx", "yy", "zz", "xy", "xz", "yz"}
            if unknown:
                msg = f"inertia keys must be xx yy zz xy xz yz; got {sorted(unknown)} ({here})"
                raise ModelError(msg)
            get = {k: self._expr(inertia.get(k, 0), f"{here}.{k}") for k in ("xx", "yy", "zz", "xy", "xz", "yz")}
            rows = [
                [get["xx"], get["xy"], get["xz"]],
                [get["xy"], get["yy"], get["yz"]],
                [get["xz"], get["yz"], get["zz"]],
            ]
        elif (
            isinstance(inertia, (list, tuple))
            and len(inertia) == 3
            and all(isinstance(r, (list, tuple)) and len(r) == 3 for r in inertia)
        ):
            rows = [[self._expr(v, f"{here}[{i}][{j}]") for j, v in enumerate(r)] for i, r in enumerate(inertia)]
        else:
            msg = f"inertia must be a 3x3 list or a mapping of xx yy zz xy xz yz; got {inertia!r} ({here})"
            raise ModelError(msg)
        tensor = sp.ImmutableMatrix(rows)
        if tensor != tensor.T:
            msg = f"body {name!r} inertia tensor must be symmetric ({here})"
            raise ModelError(msg)
        if required:
            self._check_positive_definite(name, tensor, here)
        return tensor

    def _check_positive_definite(self, name: str, tensor: sp.ImmutableMatrix, where: str) -> None:
        for subs in self._evaluation_points():
            try:
                values = np.array(tensor.xreplace(subs).evalf(), dtype=float)
            except (TypeError, ValueError):
                return
            eig = np.linalg.eigvalsh(values)
            if eig.min() <= 1e-12 * abs(eig).max():
                msg = (
                    f"body {name!r} inertia tensor must be positive definite; eigenvalues "
                    f"{', '.join(f'{e:.4g}' for e in eig)} kg m^2 ({where})"
                )
                raise ModelError(msg)

    def _spin(self, name: str, spin: Mapping[str, object], tensor: sp.ImmutableMatrix, where: str) -> Spin:
        if not isinstance(spin, Mapping) or "speed" not in spin:
            msg = f"body {name!r} spin needs 'speed' (rad/s) and 'axis'; got {spin!r} ({where})"
            raise ModelError(msg)
        axis = self._vector(spin.get("axis", "z"), f"{where}.axis", unit=True)
        speed = self._expr(spin["speed"], f"{where}.speed")
        self._check_axisymmetric(name, tensor, axis, where)
        if "polar_inertia" in spin:
            polar = self._expr(spin["polar_inertia"], f"{where}.polar_inertia")
        else:
            n = sp.Matrix(axis)
            polar = sp.simplify((n.T * tensor * n)[0, 0])
        return Spin(axis=axis, speed=speed, polar_inertia=polar)

    def _check_axisymmetric(self, name: str, tensor: sp.ImmutableMatrix, axis: Vector3, where: str) -> None:
        """A steadily spinning body must be axisymmetric about its spin axis (I n parallel to n).

        Otherwise its inertia seen from the non-rotating frame varies with time and the model is not
        time-invariant; the gyroscopic matrix -Ip Omega [n]x assumes I n = Ip n.
        """
        n = sp.Matrix(axis)
        residual = tensor * n - (n.T * tensor * n)[0, 0] * n
        size = self._nominal_value(sum((tensor * n)[i] ** 2 for i in range(3)))
        worst = self._nominal_value(-sum(residual[i] ** 2 for i in range(3)))
        if size is not None and worst is not None and -worst > 1e-18 * max(size, 1e-300):
            msg = (
                f"spinning body {name!r} must be axisymmetric about its spin axis (inertia tensor times the "
                f"axis must be parallel to the axis); got I n = {[str(v) for v in tensor * n]} ({where})"
            )
            raise ModelError(msg)

    def flexible_body(
        self,
        name: str,
        *,
        mass: object = None,
        stiffness: object = None,
        nodes: Sequence[Mapping[str, object]],
        frame: Mapping[str, object] | None = None,
        position: object = (0, 0, 0),
        mass_scale: object = 1,
        stiffness_scale: object = 1,
        damping: Mapping[str, object] | None = None,
        recovery: Mapping[str, object] | None = None,
        reduction: Mapping[str, object] | None = None,
        lines: Sequence[Mapping[str, object]] | None = None,
        description: str = "",
        where: str | None = None,
    ) -> None:
        """Declare a flexible body: numeric (reduced) FE matrices with named interface nodes.

        See :mod:`cappe.model.flexible` for the conventions (DOF order, damping models, scale factors).

        Parameters
        ----------
        name : str
            Body name.
        mass, stiffness : array_like, sparse matrix, str or mapping
            The matrices (kg, N/m; order n up to :data:`~cappe.model.flexible.MAX_FLEXIBLE_DOF`), or files
            ``"bed_K.mtx"`` / ``{file: "bed.npz", key: "K"}`` (.mtx, .mat, .npz) relative to the model file.
            Leave both out where ``frame`` gives the body.
        nodes : list of mappings
            Interface nodes ``{name, at: [x, y, z] (m, body frame), dofs: [x, y, ...], row: first row}``.
        frame : mapping, optional
            A 3-D beam frame generated at load time instead of matrices (:func:`cappe.model.fe.frame_from_spec`:
            ``{sections: {NAME: {E, G, A, Iy, Iz, J, rho | line_mass}}, beams: [{points, section, divide}]}``);
            nodes (and recovery nodes) sit on frame nodes and take their rows from their coordinates. Usually
            with a ``reduction``.
        position : 3-vector of expressions
            Origin of the body frame in global coordinates (m).
        mass_scale, stiffness_scale : expression
            Factors on the matrices (a parameter makes them identifiable).
        damping : mapping, optional
            ``{modal: ratio or [ratios]}``, ``{rayleigh: [alpha, beta]}`` or ``{loss: eta}``.
        recovery : mapping, optional
            ``{matrix: array or file spec (n_rec, n), nodes: [interior nodes, rows of the matrix]}``; with
            ``reduction``, only ``{nodes: [...]}`` (rows of the full matrices; the recovery matrix is the reduction's).
        reduction : mapping, optional
            ``{band: Hz, multiple: 1.5}`` or ``{modes: n}``: ``mass`` and ``stiffness`` are full (sparse) FE
            matrices, node rows index them, and the body is their Craig-Bampton model with the interface nodes' DOFs
            as boundary (:func:`cappe.model.fe.craig_bampton`).
        lines : list of mappings, optional
            ``[{name, nodes: [n0, n1, ...], interpolation: linear}]``: straight lines of interface nodes along which
            attachment points whose coordinates depend on an axis travel (linear shape functions between the nodes;
            ``hermite``: beam elements, cubic in the nodes' translations and rotations, C1 along the line).
        description : str
            Free text.
        where : str, optional
            Location for error messages.

        Raises
        ------
        ModelError
            The name is taken or an entry breaks a rule (file, size, symmetry, definiteness, nodes).
        """
        where = self._claim_body(name, self._here(where, "flexible_bodies", len(self._flexible)))
        if frame is not None:
            if mass is not None or stiffness is not None:
                msg = f"flexible body {name!r} takes either mass and stiffness or a frame, not both ({where})"
                raise ModelError(msg)
            from cappe.model.fe._frame import frame_from_spec

            generated = frame_from_spec(frame, f"{where}.frame")
            mass, stiffness = generated.mass, generated.stiffness
            nodes = frame_node_entries(name, nodes, generated.nodes, f"{where}.nodes")  # type: ignore[assignment]
            if isinstance(recovery, Mapping) and "nodes" in recovery:
                recovery = {**recovery, "nodes": frame_node_entries(name, recovery["nodes"], generated.nodes,
                                                                   f"{where}.recovery.nodes")}
        elif mass is None or stiffness is None:
            msg = f"flexible body {name!r} needs mass and stiffness matrices, or a frame ({where})"
            raise ModelError(msg)
        interior: tuple[InterfaceNode, ...] = ()
        rec = None
        if reduction is not None:
            if recovery is not None and (not isinstance(recovery, Mapping) or set(recovery) != {"nodes"}):
                msg = (f"with a reduction, recovery gives only 'nodes' (rows of the full matrices); got {recovery!r} "
                       f"({where}.recovery)")
                raise ModelError(msg)
            m_red, k_red, interface, interior, rec = reduced_body(
                name, matrix_source(mass, self.base, f"{where}.mass"),
                matrix_source(stiffness, self.base, f"{where}.stiffness"), nodes,
                None if recovery is None else recovery["nodes"], reduction, where)
            m, k = checked_matrices(m_red, k_red, where)
            recovery = None
        else:
            m, k = checked_matrices(matrix_source(mass, self.base, f"{where}.mass"),
                                    matrix_source(stiffness, self.base, f"{where}.stiffness"), where)
            interface = parse_nodes(name, nodes, m.shape[0], f"{where}.nodes")
        scales = {}
        for label, value in (("mass_scale", mass_scale), ("stiffness_scale", stiffness_scale)):
            expr = self._expr(value, f"{where}.{label}")
            low = self._nominal_value(expr)
            if low is not None and low <= 0:
                msg = f"flexible body {name!r} {label} must be > 0; got {low:.6g} ({where}.{label})"
                raise ModelError(msg)
            scales[label] = expr
        damp = parse_damping(name, damping, self._expr, self._nominal_value, f"{where}.damping")
        if recovery is not None:
            if not isinstance(recovery, Mapping) or set(recovery) != {"matrix", "nodes"}:
                msg = f"recovery must give 'matrix' and 'nodes'; got {recovery!r} ({where}.recovery)"
                raise ModelError(msg)
            raw = matrix_source(recovery["matrix"], self.base, f"{where}.recovery.matrix", square=False)
            rec = np.array(raw.toarray() if hasattr(raw, "toarray") else raw, dtype=float)
            if rec.ndim != 2 or rec.shape[1] != m.shape[0] or not np.isfinite(rec).all():
                msg = (f"recovery matrix must be finite with {m.shape[0]} columns (the body's coordinates); got "
                       f"shape {rec.shape} ({where}.recovery.matrix)")
                raise ModelError(msg)
            rec.setflags(write=False)
            interior = parse_nodes(name, recovery["nodes"], rec.shape[0], f"{where}.recovery.nodes", interior=True)
        if interior:
            clash = {n.name for n in interior} & {n.name for n in interface}
            if clash:
                msg = f"interior node(s) {', '.join(sorted(clash))} already name interface nodes ({where}.recovery)"
                raise ModelError(msg)
        node_lines = parse_lines(name, lines, interface, f"{where}.lines")
        modal = modal_damping_matrix(m, k, damp.ratios) if damp.kind == "modal" else None
        if modal is not None:
            modal.setflags(write=False)
        self._flexible.append(
            FlexibleBody(
                name=name,
                position=self._vector(position, f"{where}.position"),
                mass=m,
                stiffness=k,
                nodes=interface,
                interior=interior,
                recovery=rec,
                mass_scale=scales["mass_scale"],
                stiffness_scale=scales["stiffness_scale"],
                damping=damp,
                modal_damping=modal,
                description=str(description),
                lines=node_lines,
            )
        )

    def _flexible_named(self, body: str) -> FlexibleBody | None:
        return next((f for f in self._flexible if f.name == body), None)

    def _point(self, body: str, value: object, where: str) -> Vector3:
        """A point in ``body``'s frame: a 3-vector, or on a flexible body the name of one of its nodes or a point
        offset from one (``{node: NAME, offset: [dx, dy, dz]}``)."""
        flex = self._flexible_named(body)
        if isinstance(value, Mapping):
            if flex is None:
                msg = (f"a point {{node, offset}} sits on a flexible body; {body!r} is not one: give a 3-vector "
                       f"({where})")
                raise ModelError(msg)
            return self._offset_point(flex, value, where)
        if flex is not None and isinstance(value, str):
            return tuple(sp.Float(v) for v in self._node(flex, value, where).point)  # type: ignore[return-value]
        return self._vector(value, where)

    def _node(self, flex: FlexibleBody, name: object, where: str) -> InterfaceNode:
        node = flex.node(name) if isinstance(name, str) else None
        if node is None:
            known = ", ".join(n.name for n in (*flex.nodes, *flex.interior))
            msg = f"flexible body {flex.name!r} has no node {name!r}; its nodes: {known} ({where})"
            raise ModelError(msg)
        return node

    def _offset_point(self, flex: FlexibleBody, value: Mapping[Any, Any], where: str) -> Vector3:
        """A point rigidly linked to a node of ``flex`` (:class:`OffsetPoint`), recorded on the body; its
        coordinates are the node's plus the offset."""
        if set(value) != {"node", "offset"}:
            msg = (f"a point offset from a node of flexible body {flex.name!r} is {{node: NAME, offset: [dx, dy, dz]}}"
                   f"; got keys {sorted(map(str, value))} ({where})")
            raise ModelError(msg)
        node = self._node(flex, value["node"], f"{where}.node")
        vec = self._vector(value["offset"], f"{where}.offset")
        if any(v.free_symbols for v in vec):
            msg = (f"the offset of a point on flexible body {flex.name!r} must be numbers (m); got "
                   f"{[str(v) for v in vec]} ({where}.offset)")
            raise ModelError(msg)
        offset = tuple(float(v) for v in vec)
        point = tuple(p + d for p, d in zip(node.point, offset, strict=True))
        if not any(offset):
            return tuple(sp.Float(v) for v in node.point)  # type: ignore[return-value]
        missing = [d for d in needed_rotations(offset) if d not in node.dofs]
        if missing:
            msg = (f"node {node.name!r} of flexible body {flex.name!r} has no rotational DOF "
                   f"{', '.join(missing)}: a point offset by {list(offset)} from it moves with its rotation "
                   f"({where})")
            raise ModelError(msg)
        other = flex.node_at(point)
        if other is not None:
            msg = (f"the point offset by {list(offset)} from node {node.name!r} of flexible body {flex.name!r} is "
                   f"node {other.name!r}: name that node, or link the two nodes by an element ({where})")
            raise ModelError(msg)
        found = flex.offset_at(point)
        if found is None:
            entry = OffsetPoint(node.name, offset, point)  # type: ignore[arg-type]
            updated = replace(flex, offsets=(*flex.offsets, entry))
            self._flexible[self._flexible.index(flex)] = updated
        elif found.node != node.name:
            msg = (f"the point offset by {list(offset)} from node {node.name!r} of flexible body {flex.name!r} "
                   f"coincides with the point offset by {list(found.offset)} from node {found.node!r} ({where})")
            raise ModelError(msg)
        return tuple(sp.Float(v) for v in point)  # type: ignore[return-value]

    def _on_node(self, body: str, value: object, where: str, *, interior: bool) -> Vector3:
        point = self._point(body, value, where)
        self._check_on_node(body, point, where, interior=interior)
        return point

    def _check_on_line(self, flex: FlexibleBody, point: Vector3, where: str) -> None:
        """A point on a flexible body that moves with an axis (an element's, an input's, an output's or a
        sensor's) must travel along one of its lines of nodes, inside the line at every listed axis position."""
        shown_point = [str(v) for v in point]
        found = flex.line_through(point, self._evaluation_points())
        if found is None:
            lines = ", ".join(line.name for line in flex.lines) or "none declared"
            msg = (f"a moving point on flexible body {flex.name!r} must travel along one of its lines of nodes "
                   f"({lines}); {shown_point} does not ({where})")
            raise ModelError(msg)
        line, s = found
        tol = 1e-9 * max(line.s[-1], 1.0)
        for subs in self._evaluation_points():
            value = float(s.xreplace(subs))
            if not line.s[0] - tol <= value <= line.s[-1] + tol:
                axes = {a.name for a in self._axes}
                at = ", ".join(f"{k} = {float(v):.6g}" for k, v in subs.items() if str(k) in axes)
                msg = (f"moving point {shown_point} leaves line {line.name!r} of flexible body {flex.name!r} "
                       f"(s = {value:.6g} m, the line spans {line.s[0]:.6g} .. {line.s[-1]:.6g}) at {at} ({where})")
                raise ModelError(msg)

    def _check_on_node(self, body: str, point: Vector3, where: str, *, interior: bool) -> None:
        """On a flexible body a point must be one of its nodes (interface nodes; interior ones for sensing)."""
        flex = self._flexible_named(body)
        if flex is None:
            return
        try:
            coords = [float(v) for v in point]
        except TypeError:
            coords = None
        if coords is None:
            self._check_on_line(flex, point, where)
            return
        linked = flex.offset_at(coords)
        if linked is not None:
            base = flex.node(linked.node)
            if not interior and base not in flex.nodes:
                msg = (f"point {coords} hangs on interior node {linked.node!r} of flexible body {body!r}: elements "
                       f"and inputs attach to interface nodes ({where})")
                raise ModelError(msg)
            return
        if flex.node_at(coords, interior=interior) is None:
            kinds = "nodes" if interior else "interface nodes"
            msg = (f"point {coords} is not at one of flexible body {body!r}'s {kinds} "
                   f"({', '.join(n.name for n in (*flex.nodes, *(flex.interior if interior else ())))}) ({where})")
            raise ModelError(msg)

    def element(
        self,
        name: str,
        *,
        bodies: Sequence[str],
        points: Sequence[object] | None = None,
        at: object = None,
        axes: Mapping[str, object] | None = None,
        stiffness: Mapping[str, object] | None = None,
        damping: Mapping[str, object] | None = None,
        loss: Mapping[str, object] | None = None,
        description: str = "",
        where: str | None = None,
    ) -> None:
        """Declare a stiffness-damping element between two bodies (or a body and ground).

        ``points`` gives the attachment point in each body's frame (default: both origins); alternatively
        ``at`` gives one global location (expressions may use axis coordinates) where the element attaches
        to both bodies, converted to body frames with the bodies' nominal positions.
        ``axes`` optionally gives the local ``x`` and ``y`` axes (global frame); ``z = x × y``.
        ``stiffness``, ``damping`` and ``loss`` map directions (x y z rx ry rz) to expressions.

        Parameters
        ----------
        name : str
            Element name.
        bodies : (str, str)
            The joined bodies (``"ground"`` allowed for one).
        points : sequence of two 3-vectors, optional
            Attachment points in each body's frame (m).
        at : 3-vector of expressions, optional
            One global attachment location (m) instead of ``points``.
        axes : mapping, optional
            Local ``x`` and ``y`` axes (global frame).
        stiffness : mapping direction -> expression, optional
            Stiffness (N/m, N m/rad).
        damping : mapping direction -> expression, optional
            Viscous damping (N s/m, N m s/rad).
        loss : mapping direction -> expression, optional
            Loss factors (dimensionless; hysteretic damping ``eta k``).
        description : str
            Free text.
        where : str, optional
            Location for error messages.

        Raises
        ------
        ModelError
            The name is taken or an entry breaks a rule.
        """
        where = self._here(where, "elements", len(self._elements))
        self._claim("elements", name, where)
        if not isinstance(bodies, (list, tuple)) or len(bodies) != 2:
            msg = f"element {name!r} bodies must be a pair [a, b]; got {bodies!r} ({where}.bodies)"
            raise ModelError(msg)
        a = self._require_body(bodies[0], f"{where}.bodies[0]", allow_ground=True)
        b = self._require_body(bodies[1], f"{where}.bodies[1]", allow_ground=True)
        if a == b:
            msg = f"element {name!r} must join two different bodies; got {a!r} twice ({where}.bodies)"
            raise ModelError(msg)
        if at is not None:
            if points is not None:
                msg = f"element {name!r} takes either 'points' or 'at', not both ({where})"
                raise ModelError(msg)
            location = self._vector(at, f"{where}.at")
            point_a = self._relative(a, location)
            point_b = self._relative(b, location)
        else:
            pts = points if points is not None else ((0, 0, 0), (0, 0, 0))
            if not isinstance(pts, (list, tuple)) or len(pts) != 2:
                msg = f"element {name!r} points must be a pair of 3-vectors; got {points!r} ({where}.points)"
                raise ModelError(msg)
            point_a = self._point(a, pts[0], f"{where}.points[0]")
            point_b = self._point(b, pts[1], f"{where}.points[1]")
        for body_name, pt, k in ((a, point_a, 0), (b, point_b, 1)):
            self._check_on_node(body_name, pt, f"{where}.{'at' if at is not None else f'points[{k}]'}",
                                interior=False)
        frame = self._frame(name, axes, f"{where}.axes")
        groups = {
            label: self._directional(name, label, table or {}, f"{where}.{label}")
            for label, table in (("stiffness", stiffness), ("damping", damping), ("loss", loss))
        }
        if not any(groups.values()):
            msg = f"element {name!r} has no stiffness, damping or loss in any direction ({where})"
            raise ModelError(msg)
        self._elements.append(
            StiffnessDampingElement(
                name=name,
                body_a=a,
                body_b=b,
                point_a=point_a,
                point_b=point_b,
                axes=frame,
                stiffness=groups["stiffness"],
                damping=groups["damping"],
                loss=groups["loss"],
                description=str(description),
            )
        )

    def _frame(self, name: str, axes: Mapping[str, object] | None, where: str) -> sp.ImmutableMatrix:
        if axes is None:
            return sp.ImmutableMatrix(sp.eye(3))
        if not isinstance(axes, Mapping) or set(axes) - {"x", "y"} or "x" not in axes:
            msg = f"element {name!r} axes must give 'x' and optionally 'y' as 3-vectors; got {axes!r} ({where})"
            raise ModelError(msg)
        ex = sp.Matrix(self._vector(axes["x"], f"{where}.x", unit=True))
        if "y" in axes:
            ey_raw = sp.Matrix(self._vector(axes["y"], f"{where}.y", unit=True))
        else:
            # any vector not parallel to x completes the frame
            trial = sp.Matrix([0, 0, 1]) if abs(self._nominal_value(ex[2]) or 0.0) < 0.9 else sp.Matrix([1, 0, 0])
            ey_raw = trial
        ey = ey_raw - (ex.T * ey_raw)[0, 0] * ex
        norm = self._nominal_value(sp.sqrt((ey.T * ey)[0, 0]))
        if norm is not None and norm < 1e-9:
            msg = f"element {name!r} axes x and y must not be parallel ({where})"
            raise ModelError(msg)
        ey = (ey / sp.sqrt((ey.T * ey)[0, 0])).applyfunc(_simplified)
        ez = ex.cross(ey)
        return sp.ImmutableMatrix(sp.Matrix.hstack(ex, ey, ez.applyfunc(_simplified)))

    def _directional(self, name: str, label: str, table: Mapping[str, object], where: str) -> Mapping[str, sp.Expr]:
        if not isinstance(table, Mapping):
            msg = f"element {name!r} {label} must map directions to values; got {table!r} ({where})"
            raise ModelError(msg)
        out: dict[str, sp.Expr] = {}
        for direction, value in table.items():
            if direction not in DIRECTIONS:
                msg = (
                    f"element {name!r} {label} direction must be one of {', '.join(DIRECTIONS)}; "
                    f"got {direction!r} ({where})"
                )
                raise ModelError(msg)
            expr = self._expr(value, f"{where}.{direction}")
            nominal = self._nominal_value(expr)
            if nominal is not None and nominal < 0:
                msg = f"element {name!r} {label} {direction!r} must be >= 0; got {nominal:.6g} ({where}.{direction})"
                raise ModelError(msg)
            out[direction] = expr
        return MappingProxyType({d: out[d] for d in DIRECTIONS if d in out})

    def input(
        self,
        name: str,
        *,
        body: str,
        point: object = (0, 0, 0),
        direction: object = "x",
        kind: str = "force",
        where: str | None = None,
    ) -> None:
        """Declare an input: a force (N) or moment (N m) on a body.

        Parameters
        ----------
        name : str
            Input name.
        body : str
            The body it acts on (not ground).
        point : 3-vector of expressions
            Point of action in the body frame (m).
        direction : str or 3-vector
            ``"x"``, ``"-y"`` ... or a vector (global), normalized.
        kind : {"force", "moment"}
            What acts.
        where : str, optional
            Location for error messages.

        Raises
        ------
        ModelError
            The name is taken, the kind or body unknown, or the direction zero.
        """
        where = self._here(where, "inputs", len(self._inputs))
        self._claim("signals", name, where)
        if kind not in ("force", "moment"):
            msg = f"input {name!r} kind must be 'force' or 'moment'; got {kind!r} ({where}.kind)"
            raise ModelError(msg)
        body_name = self._require_body(body, f"{where}.body", allow_ground=False)
        self._inputs.append(
            Input(
                name=name,
                kind=kind,
                body=body_name,
                point=self._on_node(body_name, point, f"{where}.point", interior=False),
                direction=self._vector(direction, f"{where}.direction", unit=True),
            )
        )

    def output(
        self,
        name: str,
        *,
        quantity: str = "displacement",
        body: str | None = None,
        point: object = (0, 0, 0),
        direction: object = "x",
        rotation: bool = False,
        sensor: str | None = None,
        element: str | None = None,
        where: str | None = None,
    ) -> None:
        """Declare an output: motion of a body point (or sensor) along a direction, or an elongation.

        Parameters
        ----------
        name : str
            Output name.
        quantity : str
            One of :data:`QUANTITIES`.
        body : str, optional
            The moving body (motion outputs without ``sensor``).
        point : 3-vector of expressions
            The point in the body frame (m).
        direction : str or 3-vector
            ``"x"``, ``"-y"`` ... or a vector (global); for an elongation, the element's local direction.
        rotation : bool
            The rotation about ``direction`` (rad) instead of the translation along it.
        sensor : str, optional
            A declared sensor node giving body and point.
        element : str, optional
            The element (elongation outputs).
        where : str, optional
            Location for error messages.

        Raises
        ------
        ModelError
            The name is taken, or the quantity, body, sensor, element or direction is unknown.
        """
        where = self._here(where, "outputs", len(self._outputs))
        self._claim("signals", name, where)
        if quantity not in QUANTITIES:
            msg = (
                f"output {name!r} quantity must be one of {', '.join(QUANTITIES)}; got {quantity!r} ({where}.quantity)"
            )
            raise ModelError(msg)
        if quantity == "elongation":
            names = [e.name for e in self._elements]
            if element not in names:
                msg = (
                    f"output {name!r} refers to unknown element {element!r} ({where}.element); "
                    f"known: {', '.join(names) or 'none'}"
                )
                raise ModelError(msg)
            if direction not in DIRECTIONS:
                msg = (
                    f"output {name!r} elongation direction must be one of {', '.join(DIRECTIONS)}; "
                    f"got {direction!r} ({where}.direction)"
                )
                raise ModelError(msg)
            self._outputs.append(
                Output(name=name, quantity=quantity, element=str(element), element_direction=str(direction))
            )
            return
        if sensor is not None:
            found = [s for s in self._sensors if s.name == sensor]
            if not found:
                msg = f"output {name!r} refers to unknown sensor {sensor!r} ({where}.sensor)"
                raise ModelError(msg)
            body_name, pt = found[0].body, found[0].point
        else:
            body_name = self._require_body(body, f"{where}.body", allow_ground=False)
            pt = self._on_node(body_name, point, f"{where}.point", interior=True)
        self._outputs.append(
            Output(
                name=name,
                quantity=quantity,
                body=body_name,
                point=pt,
                direction=self._vector(direction, f"{where}.direction", unit=True),
                rotation=bool(rotation),
            )
        )

    def sensor(self, name: str, *, body: str, point: object = (0, 0, 0), where: str | None = None) -> None:
        """Declare a named sensor node on a body.

        Parameters
        ----------
        name : str
            Node name; its channels are ``"name:x"``, ``"name:y"``, ``"name:z"``.
        body : str
            The body it sits on (not ground).
        point : 3-vector of expressions
            The point in the body frame (m).
        where : str, optional
            Location for error messages.

        Raises
        ------
        ModelError
            The name is taken or the body unknown.
        """
        where = self._here(where, "sensors", len(self._sensors))
        self._claim("sensors", name, where)
        body_name = self._require_body(body, f"{where}.body", allow_ground=False)
        self._sensors.append(Sensor(name=name, body=body_name,
                                    point=self._on_node(body_name, point, f"{where}.point", interior=True)))

    def build(self) -> Structure:
        """Validate the whole and return the immutable Structure."""
        if not self._bodies and not self._flexible:
            msg = f"model '{self.name}' has no bodies ({self.source or 'builder'})"
            raise ModelError(msg)
        groups = ("parameters", "axes", "bodies", "elements", "inputs", "outputs", "sensors", "flexible_bodies")
        structure = Structure(
            name=self.name,
            parameters=tuple(self._parameters),
            axes=tuple(self._axes),
            bodies=tuple(self._bodies),
            elements=tuple(self._elements),
            inputs=tuple(self._inputs),
            outputs=tuple(self._outputs),
            sensors=tuple(self._sensors),
            description=self.description,
            source=self.source,
            flexible_bodies=tuple(self._flexible),
        )
        index = {g: MappingProxyType({item.name: i for i, item in enumerate(getattr(structure, g))}) for g in groups}
        object.__setattr__(structure, "_index", MappingProxyType(index))
        return structure


def _singular(group: str) -> str:
    """What one entry of a model-file group is called in messages (``bodies`` -> ``body``, not ``bodie``)."""
    return {"bodies": "body", "axes": "axis", "flexible_bodies": "flexible body"}.get(group, group[:-1])


def _simplified(expr: sp.Expr) -> sp.Expr:
    """``sympy.simplify(expr)``, skipped for a rational number (already in its simplest form; the axis-aligned
    directions of most models, where simplify's tries took most of the model loading time)."""
    return expr if expr.is_Rational else sp.simplify(expr)


def _finite(value: object, what: str, where: str) -> float:
    if isinstance(value, bool):
        msg = f"{what} must be a number; got {value!r} ({where})"
        raise ModelError(msg)
    try:
        number = float(value)  # type: ignore[arg-type]
    except OverflowError as exc:
        msg = f"{what} must be within the floating-point range; got an integer beyond it ({where})"
        raise ModelError(msg) from exc
    except (TypeError, ValueError) as exc:
        msg = f"{what} must be a number; got {shown(repr(value))} ({where})"
        raise ModelError(msg) from exc
    if not math.isfinite(number):
        msg = f"{what} must be finite; got {value!r} ({where})"
        raise ModelError(msg)
    return number

