"""Exact equations of motion of a Structure, as sympy matrices in the parameters and axis coordinates.

``M q'' + (C + G) q' + (K + 1j H) q = B u`` for harmonic motion (H: hysteretic damping, G: gyroscopic,
skew-symmetric). Each matrix is kept as a sum of *terms* ``coefficient * pattern``: the coefficient is an
expression in the parameters (a stiffness, a mass, ``eta*k``), the pattern a sparse matrix that depends only
on the geometry (and so on the axis coordinates). This is the affine structure that NumericModel exploits.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import sympy as sp
from numpy.typing import NDArray

from cappe.exceptions import ModelError
from cappe.model._expressions import symbol
from cappe.model.flexible import FlexibleBody, OffsetPoint
from cappe.model.geometry import point_jacobian, skew
from cappe.model.structure import DIRECTIONS, GROUND, Output, Structure

__all__ = ["MATRIX_NAMES", "BlockTerm", "SymbolicModel", "Term", "derive"]

MATRIX_NAMES = ("M", "C", "K", "G", "H")
SparseRow = dict[int, sp.Expr]


@dataclass(frozen=True)
class Term:
    """One additive term ``coefficient * pattern`` of a system matrix (pattern sparse: {(i, j): expr})."""

    coefficient: sp.Expr
    pattern: Mapping[tuple[int, int], sp.Expr]
    source: str

    def dense(self, n: int) -> sp.Matrix:
        out = sp.zeros(n, n)
        for (i, j), v in self.pattern.items():
            out[i, j] += v
        return out


@dataclass(frozen=True, eq=False)
class BlockTerm:
    """One additive term ``coefficient * block`` of a system matrix with a numeric block (a flexible body's
    matrix) on the DOFs ``offset .. offset + n``."""

    coefficient: sp.Expr
    block: NDArray[np.float64]
    offset: int
    source: str


def derive(structure: Structure) -> SymbolicModel:
    """Derive the exact symbolic model of ``structure`` (same as ``SymbolicModel(structure)``).

    Parameters
    ----------
    structure : Structure
        The model description.

    Returns
    -------
    SymbolicModel
    """
    return SymbolicModel(structure)


class SymbolicModel:
    """Exact symbolic equations of motion of a Structure.

    Parameters
    ----------
    structure : Structure
        The model description; its parameters and axis coordinates become sympy symbols.

    Examples
    --------
    >>> from cappe.model import load_model
    >>> sym = SymbolicModel(load_model("builtin:two-mass-rig"))
    >>> sym.K
    Matrix([
    [k11 + k12,      -k12],
    [     -k12, k12 + k22]])
    """

    def __init__(self, structure: Structure) -> None:
        self.structure = structure
        self.dofs = structure.dofs
        self.n_dof = structure.n_dof
        self._offset: dict[str, int] = {}
        self._sensor_rows: dict[str, list[SparseRow]] = {}
        i = 0
        for body in structure.bodies:
            self._offset[body.name] = i
            i += len(body.dofs)
        self._flexible: dict[str, FlexibleBody] = {}
        for flex in structure.flexible_bodies:
            self._offset[flex.name] = i
            self._flexible[flex.name] = flex
            i += flex.n_dof

    # -- kinematics -------------------------------------------------------------------------------
    def _columns(self, body: str) -> dict[int, int]:
        """Map of DIRECTIONS index -> global DOF index for the active DOFs of ``body``."""
        if body == GROUND:
            return {}
        b = self.structure.body(body)
        start = self._offset[body]
        return {DIRECTIONS.index(d): start + k for k, d in enumerate(b.dofs)}

    def point_rows(self, body: str, point: Sequence[sp.Expr]) -> list[SparseRow]:
        """Three sparse rows mapping q to the (x, y, z) displacement of a body point.

        Parameters
        ----------
        body : str
            Body name (``"ground"``: no DOFs, empty rows).
        point : sequence of 3 sympy expressions
            The point relative to the body's origin, in m.

        Returns
        -------
        list of dict
            One sparse row ``{DOF index: sympy expression}`` per component.
        """
        if body in self._flexible:
            return self._flexible_rows(body, point, rotation=False)
        cols = self._columns(body)
        jac = point_jacobian(point)
        rows: list[SparseRow] = []
        for a in range(3):
            row = {cols[c]: jac[a, c] for c in cols if jac[a, c] != 0}
            rows.append(row)
        return rows

    def rotation_rows(self, body: str, point: Sequence[sp.Expr] | None = None) -> list[SparseRow]:
        """Three sparse rows mapping q to the small rotation (rx, ry, rz) of a body.

        Parameters
        ----------
        body : str
            Body name.
        point : sequence of 3 sympy expressions, optional
            The point (m, body frame): the node whose rotation it is on a flexible body (unused on a rigid one).

        Returns
        -------
        list of dict
            One sparse row ``{DOF index: sympy expression}`` per component.
        """
        if body in self._flexible:
            if point is None:
                msg = f"the rotation of flexible body {body!r} is a node's: name the point"
                raise ModelError(msg)
            return self._flexible_rows(body, point, rotation=True)
        cols = self._columns(body)
        return [{cols[3 + a]: sp.Integer(1)} if 3 + a in cols else {} for a in range(3)]

    def elongation_row(self, element: str, direction: str) -> SparseRow:
        """Sparse row h with elongation = h q for one local direction of an element.

        Parameters
        ----------
        element : str
            Element name.
        direction : {"x", "y", "z", "rx", "ry", "rz"}
            Local direction of the element (translations in m, rotations in rad).

        Returns
        -------
        dict
            ``{DOF index: sympy expression}``.
        """
        e = self.structure.element(element)
        k = DIRECTIONS.index(direction)
        axis = e.axes[:, k % 3]
        if k < 3:
            rows_b = self.point_rows(e.body_b, e.point_b)
            rows_a = self.point_rows(e.body_a, e.point_a)
        else:
            rows_b = self.rotation_rows(e.body_b, e.point_b)
            rows_a = self.rotation_rows(e.body_a, e.point_a)
        for body, rows in ((e.body_b, rows_b), (e.body_a, rows_a)):
            self._require_components(body, rows, axis, k >= 3, f"element {element!r} direction {direction!r}")
        return _combine([(axis[a], rows_b[a]) for a in range(3)] + [(-axis[a], rows_a[a]) for a in range(3)])

    def direction_row(
        self, body: str, point: Sequence[sp.Expr], direction: Sequence[sp.Expr], rotation: bool = False
    ) -> SparseRow:
        """Row mapping q to the motion of a body point along a unit direction (or rotation about it).

        Parameters
        ----------
        body : str
            Body name.
        point : sequence of 3 sympy expressions
            The point relative to the body's origin, in m (unused for a rotation).
        direction : sequence of 3 sympy expressions
            Unit direction in global coordinates.
        rotation : bool
            The rotation about ``direction`` instead of the translation along it.

        Returns
        -------
        dict
            ``{DOF index: sympy expression}``.
        """
        rows = self.rotation_rows(body, point) if rotation else self.point_rows(body, point)
        return _combine([(direction[a], rows[a]) for a in range(3)])

    def _flexible_rows(self, body: str, point: Sequence[sp.Expr], *, rotation: bool) -> list[SparseRow]:
        """Rows of a flexible body's node at ``point``: its DOFs (interface node; a direction it does not carry
        gives an empty row) or its rows of the recovery matrix (interior node)."""
        flex = self._flexible[body]
        try:
            coords = [float(v) for v in point]
        except TypeError:
            return self._line_rows(body, point, rotation=rotation)
        node = flex.node_at(coords)
        if node is None:
            linked = flex.offset_at(coords)
            if linked is None:
                msg = f"point {coords} is not at a node of flexible body {body!r}"
                raise ModelError(msg)
            return self._offset_rows(body, linked, rotation=rotation)
        start = self._offset[body]
        names = DIRECTIONS[3:] if rotation else DIRECTIONS[:3]
        interface = node in flex.nodes
        rows: list[SparseRow] = []
        for d in names:
            r = node.row(d)
            if r is None:
                rows.append({})
            elif interface:
                rows.append({start + r: sp.Integer(1)})
            else:
                assert flex.recovery is not None  # interior nodes come with their recovery matrix
                rows.append({start + j: sp.Float(float(v)) for j, v in enumerate(flex.recovery[r]) if v != 0})
        return rows

    def _offset_rows(self, body: str, linked: OffsetPoint, *, rotation: bool) -> list[SparseRow]:
        """Rows of a point rigidly linked to a node: ``u + theta x d`` (translations), the node's ``theta``
        (rotations)."""
        node_point = self.structure.flexible_body(body).node(linked.node)
        assert node_point is not None  # the builder checked the node
        point = [sp.Float(v) for v in node_point.point]
        theta = self._flexible_rows(body, point, rotation=True)
        if rotation:
            return theta
        u = self._flexible_rows(body, point, rotation=False)
        d = [sp.Float(v) for v in linked.offset]
        # (theta x d)_a = theta_b d_c - theta_c d_b for (a, b, c) cyclic; a component the node does not carry
        # stays unknown (empty), as at the node itself
        return [_combine([(sp.Integer(1), u[a]), (d[(a + 2) % 3], theta[(a + 1) % 3]),
                          (-d[(a + 1) % 3], theta[(a + 2) % 3])]) if u[a] else {} for a in range(3)]

    def _line_rows(self, body: str, point: Sequence[sp.Expr], *, rotation: bool) -> list[SparseRow]:
        """Rows of a point travelling along a line of a flexible body's nodes: the nodes' DOFs weighted by the
        line's shape functions at the point's line coordinate."""
        flex = self._flexible[body]
        found = flex.line_through(point, self._samples())
        if found is None:
            msg = (f"a moving point on flexible body {body!r} must travel along one of its lines of nodes; got "
                   f"{[str(v) for v in point]}")
            raise ModelError(msg)
        line, s = found
        start = self._offset[body]
        names = DIRECTIONS[3:] if rotation else DIRECTIONS[:3]
        rows: list[SparseRow] = []
        if line.interpolation == "hermite":
            blocks = [block[1 if rotation else 0] for block in line.hermite_weights(s)]
            for a in range(3):
                combined: SparseRow = {}
                for node_name, block in zip(line.nodes, blocks, strict=True):
                    node = flex.node(node_name)
                    assert node is not None  # parse_lines checked the line's nodes (all six DOFs)
                    for c, d in enumerate(DIRECTIONS):
                        if block[a, c] != 0:
                            combined[start + node.rows[node.dofs.index(d)]] = block[a, c]
                rows.append(combined)
            return rows
        weights = line.shape_functions(s)
        for d in names:
            row: SparseRow = {}
            for node_name, weight in zip(line.nodes, weights, strict=True):
                node = flex.node(node_name)
                r = None if node is None else node.row(d)
                if r is not None:
                    row[start + r] = weight
            rows.append(row)
        return rows

    def _samples(self) -> list[dict[sp.Symbol, sp.Expr]]:
        """Nominal parameters at every combination of the listed axis positions (where moving points are checked)."""
        params = {symbol(p.name): sp.Float(p.value) for p in self.structure.parameters}
        grids = [[(symbol(a.name), sp.Float(v)) for v in (a.positions or (0.0,))] for a in self.structure.axes]
        return [{**params, **dict(combo)} for combo in itertools.product(*grids)]

    def _require_components(self, body: str, rows: list[SparseRow], direction: Sequence[sp.Expr], rotation: bool,
                            what: str) -> None:
        """An element or input on a flexible body's node needs the node to carry every component it acts along
        (a reduced model has no coordinate to hold the others at zero)."""
        if body not in self._flexible:
            return
        names = ("rx", "ry", "rz") if rotation else ("x", "y", "z")
        missing = [names[a] for a in range(3) if direction[a] != 0 and not rows[a]]
        if missing:
            msg = (f"{what} acts along {', '.join(missing)} on flexible body {body!r}, at a node without "
                   f"{'those DOFs' if len(missing) > 1 else 'that DOF'}")
            raise ModelError(msg)

    # -- matrices as terms ------------------------------------------------------------------------
    @cached_property
    def terms(self) -> dict[str, list[Term]]:
        """Additive terms of M, C, K, G and H."""
        out: dict[str, list[Term]] = {name: [] for name in MATRIX_NAMES}
        for body in self.structure.bodies:
            out["M"].extend(self._mass_terms(body.name))
            if body.spin is not None:
                out["G"].append(self._gyro_term(body.name))
        for e in self.structure.elements:
            for d in e.directions:
                h = self.elongation_row(e.name, d)
                if not h:
                    continue
                pattern = _outer(h)
                if d in e.stiffness and e.stiffness[d] != 0:
                    out["K"].append(Term(e.stiffness[d], pattern, f"{e.name}.k{d}"))
                if d in e.damping and e.damping[d] != 0:
                    out["C"].append(Term(e.damping[d], pattern, f"{e.name}.c{d}"))
                if d in e.loss and e.loss[d] != 0 and d in e.stiffness:
                    out["H"].append(Term(e.loss[d] * e.stiffness[d], pattern, f"{e.name}.eta{d}"))
        return out

    def _mass_terms(self, name: str) -> list[Term]:
        body = self.structure.body(name)
        cols = self._columns(name)
        c = body.com
        sc = skew(c)
        full = sp.zeros(6, 6)
        full[:3, :3] = sp.eye(3)
        full[:3, 3:] = -sc
        full[3:, :3] = sc
        full[3:, 3:] = -sc * sc
        terms = [Term(body.mass, _restrict(full, cols), f"{name}.mass")]
        for a in range(3):
            for b in range(a, 3):
                value = body.inertia[a, b]
                if value == 0 or (3 + a) not in cols or (3 + b) not in cols:
                    continue
                pattern = {(cols[3 + a], cols[3 + b]): sp.Integer(1)}
                if a != b:
                    pattern[(cols[3 + b], cols[3 + a])] = sp.Integer(1)
                terms.append(Term(value, pattern, f"{name}.I{'xyz'[a]}{'xyz'[b]}"))
        return [t for t in terms if t.pattern]

    def _gyro_term(self, name: str) -> Term:
        spin = self.structure.body(name).spin
        if spin is None:
            msg = f"body {name!r} does not spin"
            raise ModelError(msg)
        block = sp.zeros(6, 6)
        block[3:, 3:] = -skew(spin.axis)
        return Term(spin.polar_inertia * spin.speed, _restrict(block, self._columns(name)), f"{name}.spin")

    @cached_property
    def block_terms(self) -> dict[str, list[BlockTerm]]:
        """Additive terms of M, C, K, G and H with numeric blocks (flexible bodies), by matrix."""
        out: dict[str, list[BlockTerm]] = {name: [] for name in MATRIX_NAMES}
        for flex in self.structure.flexible_bodies:
            for name, coefficient, block, source in flex.matrix_terms():
                out[name].append(BlockTerm(coefficient, block, self._offset[flex.name], source))
        return out

    def _assemble(self, name: str) -> sp.ImmutableMatrix:
        if self.structure.flexible_bodies:
            bodies = ", ".join(f.name for f in self.structure.flexible_bodies)
            msg = (f"model '{self.structure.name}' has flexible bodies ({bodies}) given by numeric FE matrices: "
                   "symbolic and exact matrices, transfer functions and Lagrange checks are for rigid-body models; "
                   "use the numeric model (cappe model matrices/modes/frf)")
            raise ModelError(msg)
        total = sp.zeros(self.n_dof, self.n_dof)
        for term in self.terms[name]:
            for (i, j), v in term.pattern.items():
                total[i, j] += term.coefficient * v
        return sp.ImmutableMatrix(total.applyfunc(sp.expand))

    @cached_property
    def M(self) -> sp.ImmutableMatrix:  # noqa: N802 (matrix names follow the literature)
        """Mass matrix."""
        return self._assemble("M")

    @cached_property
    def C(self) -> sp.ImmutableMatrix:  # noqa: N802
        """Viscous damping matrix."""
        return self._assemble("C")

    @cached_property
    def K(self) -> sp.ImmutableMatrix:  # noqa: N802
        """Stiffness matrix."""
        return self._assemble("K")

    @cached_property
    def G(self) -> sp.ImmutableMatrix:  # noqa: N802
        """Gyroscopic matrix (skew-symmetric, proportional to spin speed)."""
        return self._assemble("G")

    @cached_property
    def H(self) -> sp.ImmutableMatrix:  # noqa: N802
        """Hysteretic damping matrix (imaginary part of the complex stiffness)."""
        return self._assemble("H")

    def matrices(self) -> dict[str, sp.ImmutableMatrix]:
        return {name: getattr(self, name) for name in MATRIX_NAMES}

    # -- inputs and outputs -----------------------------------------------------------------------
    def input_column(self, name: str) -> SparseRow:
        """Generalized force per unit input (sparse column).

        Parameters
        ----------
        name : str
            Input name (a force in N or a moment in N m).

        Returns
        -------
        dict
            ``{DOF index: sympy expression}``.
        """
        inp = self.structure.input(name)
        moment = inp.kind == "moment"
        if inp.body in self._flexible:
            rows = self.rotation_rows(inp.body, inp.point) if moment else self.point_rows(inp.body, inp.point)
            self._require_components(inp.body, rows, inp.direction, moment, f"input {name!r}")
        return self.direction_row(inp.body, inp.point, inp.direction, rotation=moment)

    def output_row(self, name: str) -> tuple[str, SparseRow]:
        """(quantity, row) with the output's displacement-level value = row · q.

        Parameters
        ----------
        name : str
            Output name.

        Returns
        -------
        quantity : str
            ``"displacement"``, ``"velocity"``, ``"acceleration"`` or ``"elongation"``.
        row : dict
            ``{DOF index: sympy expression}``.
        """
        out: Output = self.structure.output(name)
        if out.quantity == "elongation":
            return out.quantity, self.elongation_row(out.element, out.element_direction)
        return out.quantity, self.direction_row(out.body, out.point, out.direction, rotation=out.rotation)

    def sensor_rows(self, name: str) -> list[SparseRow]:
        """Rows for the x, y, z displacement of a sensor node (derived once per sensor; a fresh list each call).

        Parameters
        ----------
        name : str
            Sensor name.

        Returns
        -------
        list of dict
            One sparse row ``{DOF index: sympy expression}`` per component.
        """
        rows = self._sensor_rows.get(name)
        if rows is None:
            s = self.structure.sensor(name)
            rows = self.point_rows(s.body, s.point)
            self._sensor_rows[name] = rows
        return [dict(row) for row in rows]

    def input_matrix(self, inputs: Iterable[str] | None = None) -> sp.ImmutableMatrix:
        """Generalized forces per unit input, one column per input.

        Parameters
        ----------
        inputs : iterable of str, optional
            Input names (default all, in model order).

        Returns
        -------
        sympy.ImmutableMatrix, shape (n_dof, n_in)
        """
        names = list(inputs) if inputs is not None else [i.name for i in self.structure.inputs]
        cols = [_dense_row(self.input_column(n), self.n_dof) for n in names]
        return (
            sp.ImmutableMatrix(sp.Matrix.hstack(*[c.T for c in cols]))
            if cols
            else sp.ImmutableMatrix(sp.zeros(self.n_dof, 0))
        )

    def output_matrix(self, outputs: Iterable[str] | None = None) -> sp.ImmutableMatrix:
        """Displacement-level output rows (the quantity of each output says how to differentiate).

        Parameters
        ----------
        outputs : iterable of str, optional
            Output names (default all, in model order).

        Returns
        -------
        sympy.ImmutableMatrix, shape (n_out, n_dof)
        """
        names = list(outputs) if outputs is not None else [o.name for o in self.structure.outputs]
        rows = [_dense_row(self.output_row(n)[1], self.n_dof) for n in names]
        return sp.ImmutableMatrix(sp.Matrix.vstack(*rows)) if rows else sp.ImmutableMatrix(sp.zeros(0, self.n_dof))

    # -- substitution -----------------------------------------------------------------------------
    def substitute(self, values: Mapping[str, object]) -> dict[str, sp.ImmutableMatrix]:
        """Matrices with the given parameter / axis values substituted (others stay symbolic).

        Parameters
        ----------
        values : mapping name -> number or expression
            Parameter values (SI) and axis coordinates (m or rad) by name.

        Returns
        -------
        dict
            ``{"M", "C", "K", "G", "H": sympy.ImmutableMatrix}`` (mass, viscous damping, stiffness, gyroscopic,
            hysteretic), each (n_dof, n_dof).
        """
        subs = {symbol(k): sp.sympify(v) for k, v in values.items()}
        return {k: sp.ImmutableMatrix(m.xreplace(subs)) for k, m in self.matrices().items()}

    @property
    def symbols(self) -> dict[str, sp.Symbol]:
        """Parameter and axis symbols by name."""
        names = list(self.structure.parameter_names) + list(self.structure.axis_names)
        return {n: symbol(n) for n in names}

    def check_signals(self) -> None:
        """Raise ModelError if an input or output does not touch any active DOF."""
        for inp in self.structure.inputs:
            if not self.input_column(inp.name):
                msg = (
                    f"input {inp.name!r} acts only on inactive DOFs of body {inp.body!r} "
                    f"(active: {', '.join(self.structure.body(inp.body).dofs)})"
                )
                raise ModelError(msg)
        for out in self.structure.outputs:
            if not self.output_row(out.name)[1]:
                target = out.element or out.body
                msg = f"output {out.name!r} sees only inactive DOFs of {target!r}"
                raise ModelError(msg)


def _combine(parts: Iterable[tuple[sp.Expr, SparseRow]]) -> SparseRow:
    row: SparseRow = {}
    for weight, r in parts:
        if weight == 0:
            continue
        for j, v in r.items():
            row[j] = row.get(j, sp.Integer(0)) + weight * v
    return {j: sp.expand(v) for j, v in sorted(row.items()) if sp.expand(v) != 0}


def _outer(h: SparseRow) -> dict[tuple[int, int], sp.Expr]:
    return {(i, j): sp.expand(a * b) for i, a in h.items() for j, b in h.items()}


def _restrict(block: sp.Matrix, cols: Mapping[int, int]) -> dict[tuple[int, int], sp.Expr]:
    out: dict[tuple[int, int], sp.Expr] = {}
    for a, i in cols.items():
        for b, j in cols.items():
            v = sp.expand(block[a, b])
            if v != 0:
                out[(i, j)] = v
    return out


def _dense_row(row: SparseRow, n: int) -> sp.Matrix:
    out = sp.zeros(1, n)
    for j, v in row.items():
        out[0, j] = v
    return out
