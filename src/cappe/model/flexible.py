"""Flexible bodies: reduced FE matrices (numbers, dense blocks) with named interface nodes.

A flexible body brings its own generalized coordinates: the DOFs of its interface nodes (rows of the matrices in
the order the nodes are listed, unless a node names its first ``row``) and, after them, whatever else the
reduction kept (the fixed-interface modal coordinates of a Craig-Bampton model), labelled ``q1, q2, ...``.
Elements, inputs, outputs and sensors attach to an interface node as to a point of a rigid body: the point is the
node's coordinates (body frame, relative to the body's ``position``) and the motion there is the node's DOFs.
Sensors and outputs may also sit on *interior* nodes that a recovery matrix maps from the body's coordinates.
A point that moves with an axis (an element's, an input's, an output's or a sensor's) travels along a line of
interface nodes (:class:`NodeLine`).
A point *offset* from a node (``{node: NAME, offset: [dx, dy, dz]}`` in a model file) hangs on it by a massless
rigid link: its displacement is ``u + theta x d`` from the node's translations ``u`` and rotations ``theta``, its
rotation the node's (the node needs the rotational DOFs the cross product takes).

Matrices stay numbers: a flexible body adds ``s_m * M_fe`` to M and ``s_k * K_fe`` to K with scale factors
``s_m``, ``s_k`` that may be parameters (exact derivatives: the matrices themselves). Damping is one of

* ``modal``: damping ratios of the body's own free (unconstrained) elastic modes, ``C = M Phi diag(2 zeta omega)
  Phi^T M`` (a list gives the ratios of the lowest elastic modes in order; modes beyond it take its last value;
  rigid-body modes are undamped); with scale factors ``C = sqrt(s_k s_m) C_0`` keeps the ratios;
* ``rayleigh``: ``C = alpha s_m M_fe + beta s_k K_fe`` (alpha 1/s, beta s);
* ``loss``: hysteretic ``H = eta s_k K_fe`` (damping ratio eta / 2 in every elastic mode).

The symbolic and exact paths (``SymbolicModel.K``, exact transfer functions, Lagrange) refuse models with
flexible bodies with a ModelError: their matrices are numeric blocks, not expressions.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import scipy.linalg
import scipy.sparse as sps
import sympy as sp
from numpy.typing import NDArray

from cappe.exceptions import ModelError

__all__ = ["DAMPING_KINDS", "MAX_FLEXIBLE_DOF", "FlexibleBody", "FlexibleDamping", "InterfaceNode", "NodeLine",
           "OffsetPoint", "frame_node_entries"]

Array = NDArray[np.float64]
_DIRECTIONS = ("x", "y", "z", "rx", "ry", "rz")
DAMPING_KINDS = ("none", "modal", "rayleigh", "loss")
#: Largest order of a flexible body's (dense) matrices: a reduced model, not a full FE mesh.
MAX_FLEXIBLE_DOF = 3000
#: Relative asymmetry accepted in a matrix read from a file (written with limited digits).
SYMMETRY_RTOL = 1e-8


@dataclass(frozen=True)
class InterfaceNode:
    """A named node of a flexible body.

    Attributes
    ----------
    name : str
        Node name.
    point : tuple of 3 float
        Coordinates in the body frame, relative to the body's position (m).
    dofs : tuple of str
        Directions among ``x y z rx ry rz`` the node carries.
    rows : tuple of int
        Per direction, the row of the body's matrices (interface node) or of its recovery matrix (interior node).
    """

    name: str
    point: tuple[float, float, float]
    dofs: tuple[str, ...]
    rows: tuple[int, ...]

    def row(self, direction: str) -> int | None:
        """The row of ``direction`` (None where the node does not carry it).

        Parameters
        ----------
        direction : str
            One of ``x y z rx ry rz``.

        Returns
        -------
        int or None
        """
        return self.rows[self.dofs.index(direction)] if direction in self.dofs else None


@dataclass(frozen=True)
class OffsetPoint:
    """A point rigidly linked to a node of a flexible body (a massless rigid link).

    Attributes
    ----------
    node : str
        The node it hangs on.
    offset : tuple of 3 float
        From the node to the point, body frame (m).
    point : tuple of 3 float
        Its coordinates, body frame, relative to the body's position (m): the node's plus the offset.
    """

    node: str
    offset: tuple[float, float, float]
    point: tuple[float, float, float]


def needed_rotations(offset: Sequence[float]) -> tuple[str, ...]:
    """The rotations of a node that ``theta x d`` takes for the offset ``d``: ``rx`` where ``d`` has a y or z
    component, and so on.

    Parameters
    ----------
    offset : sequence of 3 float
        The offset ``d`` (m).

    Returns
    -------
    tuple of str
        Among ``rx ry rz``.
    """
    return tuple(f"r{axis}" for a, axis in enumerate("xyz") if any(offset[b] != 0 for b in range(3) if b != a))


@dataclass(frozen=True)
class FlexibleDamping:
    """Damping of a flexible body (see the module text).

    Attributes
    ----------
    kind : {"none", "modal", "rayleigh", "loss"}
        The damping model.
    ratios : tuple of float
        Modal damping ratios of the lowest elastic modes (``modal``).
    alpha, beta : sympy expression
        Rayleigh coefficients, 1/s and s (``rayleigh``).
    eta : sympy expression
        Loss factor (``loss``).
    """

    kind: str = "none"
    ratios: tuple[float, ...] = ()
    alpha: sp.Expr = sp.Integer(0)
    beta: sp.Expr = sp.Integer(0)
    eta: sp.Expr = sp.Integer(0)


@dataclass(frozen=True, eq=False)
class FlexibleBody:
    """A flexible body given by numeric (reduced) FE matrices and its interface nodes.

    Attributes
    ----------
    name : str
        Body name.
    position : tuple of 3 sympy expressions
        Origin of the body frame in global coordinates (m); node coordinates are relative to it.
    mass, stiffness : ndarray, shape (n, n)
        The body's mass (kg, kg m^2) and stiffness (N/m, N m/rad) matrices, read-only.
    nodes : tuple of InterfaceNode
        Interface nodes (their rows index the matrices).
    interior : tuple of InterfaceNode
        Interior nodes (their rows index ``recovery``).
    recovery : ndarray, shape (n_rec, n), or None
        Maps the body's coordinates to the interior DOFs.
    mass_scale, stiffness_scale : sympy expression
        Factors on the mass and stiffness matrices (parameters or numbers).
    damping : FlexibleDamping
        The damping model.
    modal_damping : ndarray, shape (n, n), or None
        ``C_0`` of modal damping at unit scales.
    description : str
        Free text.
    lines : tuple of NodeLine
        Lines of interface nodes that attachment points may travel along (their coordinates depend on an axis).
    offsets : tuple of OffsetPoint
        Points rigidly linked to nodes (the model's ``{node, offset}`` points).
    """

    name: str
    position: tuple[sp.Expr, sp.Expr, sp.Expr]
    mass: Array
    stiffness: Array
    nodes: tuple[InterfaceNode, ...]
    interior: tuple[InterfaceNode, ...] = ()
    recovery: Array | None = None
    mass_scale: sp.Expr = sp.Integer(1)
    stiffness_scale: sp.Expr = sp.Integer(1)
    damping: FlexibleDamping = field(default_factory=FlexibleDamping)
    modal_damping: Array | None = None
    description: str = ""
    lines: tuple[NodeLine, ...] = ()
    offsets: tuple[OffsetPoint, ...] = ()

    @property
    def n_dof(self) -> int:
        return int(self.mass.shape[0])

    @property
    def dofs(self) -> tuple[str, ...]:
        """Coordinate labels: ``node.dir`` for interface DOFs, ``q1, q2, ...`` for the others, in row order."""
        labels = [""] * self.n_dof
        for node in self.nodes:
            for d, r in zip(node.dofs, node.rows, strict=True):
                labels[r] = f"{node.name}.{d}"
        k = 0
        for i, label in enumerate(labels):
            if not label:
                k += 1
                labels[i] = f"q{k}"
        return tuple(labels)

    def node(self, name: str) -> InterfaceNode | None:
        """The interface or interior node of that name (None if there is none).

        Parameters
        ----------
        name : str
            Node name.

        Returns
        -------
        InterfaceNode or None
        """
        return next((n for n in (*self.nodes, *self.interior) if n.name == name), None)

    def node_at(self, point: Sequence[float], *, interior: bool = True) -> InterfaceNode | None:
        """The node at ``point`` (body frame, m; within 1e-9 of the body's size), interface nodes first.

        Parameters
        ----------
        point : sequence of 3 float
            Body-frame coordinates (m).
        interior : bool
            Also look among the interior nodes.

        Returns
        -------
        InterfaceNode or None
        """
        candidates = (*self.nodes, *self.interior) if interior else self.nodes
        coords = np.array([n.point for n in candidates]).reshape(-1, 3)
        if not coords.size:
            return None
        size = max(float(np.ptp(coords, axis=0).max()), 1.0)
        dist = np.linalg.norm(coords - np.asarray(point, dtype=float), axis=1)
        k = int(np.argmin(dist))
        return candidates[k] if dist[k] <= 1e-9 * size else None

    def offset_at(self, point: Sequence[float]) -> OffsetPoint | None:
        """The offset point at ``point`` (body frame, m; within 1e-9 of the body's size), or None.

        Parameters
        ----------
        point : sequence of 3 float
            Body-frame coordinates (m).

        Returns
        -------
        OffsetPoint or None
        """
        if not self.offsets:
            return None
        coords = np.array([n.point for n in (*self.nodes, *self.interior)]).reshape(-1, 3)
        size = max(float(np.ptp(coords, axis=0).max()), 1.0) if coords.size else 1.0
        dist = np.linalg.norm(np.array([o.point for o in self.offsets]) - np.asarray(point, dtype=float), axis=1)
        k = int(np.argmin(dist))
        return self.offsets[k] if dist[k] <= 1e-9 * size else None

    def line_through(self, point: Sequence[sp.Expr], samples: Sequence[Mapping[sp.Symbol, sp.Expr]],
                     ) -> tuple[NodeLine, sp.Expr] | None:
        """The line a moving point travels along and its line coordinate ``s`` as an expression, or None.

        The point must lie on the line at every sample (parameter and axis values, typically the nominal
        parameters at each listed axis position).

        Parameters
        ----------
        point : sequence of 3 sympy expressions
            Body-frame coordinates (m), depending on axis coordinates.
        samples : sequence of mappings symbol -> value
            Substitutions at which the point is checked.

        Returns
        -------
        (NodeLine, sympy expression) or None
        """
        coords = np.array([n.point for n in self.nodes])
        size = max(float(np.ptp(coords, axis=0).max()), 1.0)
        for line in self.lines:
            ok = True
            for subs in samples:
                try:
                    values = [float(sp.sympify(v).xreplace(subs)) for v in point]
                except (TypeError, ValueError):
                    return None
                if line.locate(values, size) is None:
                    ok = False
                    break
            if ok:
                s = sum(((point[a] - line.origin[a]) * line.direction[a] for a in range(3)), sp.Integer(0))
                return line, sp.expand(s)
        return None

    def matrix_terms(self) -> list[tuple[str, sp.Expr, Array, str]]:
        """The body's additive terms: (matrix name, coefficient, numeric block (n, n), label).

        Returns
        -------
        list of tuple
            ``("M", s_m, M_fe, "bed.mass")``, ``("K", s_k, K_fe, "bed.stiffness")`` and the damping terms.
        """
        s_m, s_k = self.mass_scale, self.stiffness_scale
        out = [("M", s_m, self.mass, f"{self.name}.mass"), ("K", s_k, self.stiffness, f"{self.name}.stiffness")]
        damp = self.damping
        if damp.kind == "rayleigh":
            if damp.alpha != 0:
                out.append(("C", damp.alpha * s_m, self.mass, f"{self.name}.alpha"))
            if damp.beta != 0:
                out.append(("C", damp.beta * s_k, self.stiffness, f"{self.name}.beta"))
        elif damp.kind == "loss" and damp.eta != 0:
            out.append(("H", damp.eta * s_k, self.stiffness, f"{self.name}.eta"))
        elif damp.kind == "modal" and self.modal_damping is not None:
            out.append(("C", sp.sqrt(s_k * s_m), self.modal_damping, f"{self.name}.modal"))
        return out


def free_modes(mass: Array, stiffness: Array) -> tuple[Array, Array]:
    """Undamped free modes of a body: omega^2 (ascending, negatives from round-off set to 0) and mass-normalized
    shapes (columns)."""
    lam, phi = scipy.linalg.eigh(stiffness, mass)
    scale = max(abs(lam).max(), 1e-300)
    lam = np.where(lam < 1e-10 * scale, 0.0, lam)
    return lam, phi


def modal_damping_matrix(mass: Array, stiffness: Array, ratios: Sequence[float]) -> Array:
    """``M Phi diag(2 zeta omega) Phi^T M`` over the elastic free modes (rigid-body modes undamped)."""
    lam, phi = free_modes(mass, stiffness)
    elastic = np.flatnonzero(lam > 0)
    zeta = np.full(elastic.size, ratios[-1] if ratios else 0.0)
    zeta[: min(len(ratios), elastic.size)] = ratios[: elastic.size]
    mphi = mass @ phi[:, elastic]
    c = (mphi * (2 * zeta * np.sqrt(lam[elastic]))) @ mphi.T
    return np.asarray(0.5 * (c + c.T))


def _dense(matrix: Any, what: str, where: str) -> Array:
    if sps.issparse(matrix):
        if matrix.shape[0] > MAX_FLEXIBLE_DOF:
            msg = (f"{what} matrix has order {matrix.shape[0]}; a flexible body takes reduced matrices up to "
                   f"{MAX_FLEXIBLE_DOF} (give a 'reduction' to reduce the full model) ({where})")
            raise ModelError(msg)
        matrix = matrix.toarray()
    arr = np.asarray(matrix)
    if arr.dtype == object or arr.dtype.kind not in "biuf":
        msg = f"{what} matrix must hold real numbers; got {arr.dtype} ({where})"
        raise ModelError(msg)
    arr = np.array(arr, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[0] != arr.shape[1] or arr.shape[0] == 0:
        msg = f"{what} matrix must be square and not empty; got shape {arr.shape} ({where})"
        raise ModelError(msg)
    if arr.shape[0] > MAX_FLEXIBLE_DOF:
        msg = (f"{what} matrix has order {arr.shape[0]}; a flexible body takes reduced matrices up to "
               f"{MAX_FLEXIBLE_DOF} (give a 'reduction' to reduce the full model) ({where})")
        raise ModelError(msg)
    if not np.isfinite(arr).all():
        msg = f"{what} matrix has NaN or inf entries ({where})"
        raise ModelError(msg)
    scale = float(abs(arr).max())
    asym = float(abs(arr - arr.T).max())
    if asym > SYMMETRY_RTOL * scale:
        i, j = np.unravel_index(int(np.argmax(abs(arr - arr.T))), arr.shape)
        msg = (f"{what} matrix must be symmetric; entries [{i}, {j}] and [{j}, {i}] differ by {asym:.3g} "
               f"(largest entry {scale:.3g}) ({where})")
        raise ModelError(msg)
    return np.asarray(0.5 * (arr + arr.T))


def checked_matrices(mass: Any, stiffness: Any, where: str) -> tuple[Array, Array]:
    """Dense, symmetric copies of a body's mass and stiffness, checked: M positive definite, K positive
    semi-definite, both the same order (read-only arrays).

    Parameters
    ----------
    mass, stiffness : array_like or sparse, shape (n, n)
        The matrices.
    where : str
        The model entry, for messages.

    Returns
    -------
    mass, stiffness : ndarray, shape (n, n)

    Raises
    ------
    ModelError
        A rule is broken; the message names the entry and the rule.
    """
    m = _dense(mass, "mass", f"{where}.mass")
    k = _dense(stiffness, "stiffness", f"{where}.stiffness")
    if m.shape != k.shape:
        msg = f"mass and stiffness matrices must have the same order; got {m.shape[0]} and {k.shape[0]} ({where})"
        raise ModelError(msg)
    try:
        np.linalg.cholesky(m)
    except np.linalg.LinAlgError as exc:
        low = float(np.linalg.eigvalsh(m).min())
        msg = f"mass matrix must be positive definite; its smallest eigenvalue is {low:.3g} ({where}.mass)"
        raise ModelError(msg) from exc
    lam = scipy.linalg.eigh(k, m, eigvals_only=True)
    scale = max(float(abs(lam).max()), 1e-300)
    if lam.min() < -1e-8 * scale:
        msg = (f"stiffness matrix must be positive semi-definite; it has omega^2 = {lam.min():.3g} "
               f"(largest {scale:.3g}) ({where}.stiffness)")
        raise ModelError(msg)
    m.setflags(write=False)
    k.setflags(write=False)
    return m, k


def parse_nodes(body: str, entries: object, n: int, where: str, *, interior: bool = False,
                ) -> tuple[InterfaceNode, ...]:
    """Interface (or interior) nodes from their file entries ``{name, at, dofs, row}``.

    Parameters
    ----------
    body : str
        The body, for messages.
    entries : list of mappings
        ``name`` (identifier), ``at`` (3 numbers, m, body frame), ``dofs`` (default all six) and ``row`` (first
        row; default: after the previous node's).
    n : int
        Number of rows the node rows index (the body's order, or the recovery matrix's rows).
    where : str
        The model entry, for messages.
    interior : bool
        Interior nodes (rows of the recovery matrix).

    Returns
    -------
    tuple of InterfaceNode

    Raises
    ------
    ModelError
        An entry breaks a rule (duplicate name or row, row out of range, unknown direction, bad coordinates).
    """
    label = "interior" if interior else "nodes"
    if not isinstance(entries, (list, tuple)) or (not entries and not interior):
        msg = f"flexible body {body!r} {label} must be a non-empty list; got {entries!r} ({where})"
        raise ModelError(msg)
    nodes: list[InterfaceNode] = []
    used: dict[int, str] = {}
    next_row = 0
    for i, entry in enumerate(entries):
        here = f"{where}[{i}]"
        if not isinstance(entry, Mapping) or "name" not in entry or "at" not in entry:
            msg = f"a node needs 'name' and 'at' (and optionally 'dofs', 'row'); got {entry!r} ({here})"
            raise ModelError(msg)
        extra = sorted(set(entry) - {"name", "at", "dofs", "row"})
        if extra:
            msg = f"unknown node key(s) {', '.join(map(str, extra))}; allowed: at, dofs, name, row ({here})"
            raise ModelError(msg)
        name = entry["name"]
        if not isinstance(name, str) or not name.isidentifier():
            msg = f"node name must be an identifier; got {name!r} ({here}.name)"
            raise ModelError(msg)
        if any(node.name == name for node in nodes):
            msg = f"duplicate node name {name!r} on flexible body {body!r} ({here}.name)"
            raise ModelError(msg)
        at = entry["at"]
        if (not isinstance(at, (list, tuple)) or len(at) != 3
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) for v in at)):
            msg = f"node {name!r} 'at' must be 3 finite numbers (m, body frame); got {at!r} ({here}.at)"
            raise ModelError(msg)
        dofs = entry.get("dofs", list(_DIRECTIONS))
        dof_list = list(dofs) if isinstance(dofs, (list, tuple)) else [dofs]
        if not dof_list or any(d not in _DIRECTIONS for d in dof_list) or len(set(dof_list)) != len(dof_list):
            msg = (f"node {name!r} dofs must be 1-6 distinct names from {', '.join(_DIRECTIONS)}; got {dofs!r} "
                   f"({here}.dofs)")
            raise ModelError(msg)
        row = entry.get("row", next_row)
        if isinstance(row, bool) or not isinstance(row, int) or row < 0 or row + len(dof_list) > n:
            msg = (f"node {name!r} row must be an integer with row + {len(dof_list)} DOFs <= {n} "
                   f"(the {'recovery' if interior else 'body'} matrix's rows); got {row!r} ({here}.row)")
            raise ModelError(msg)
        rows = tuple(range(row, row + len(dof_list)))
        for r in rows:
            if r in used:
                msg = f"node {name!r} row {r} is already node {used[r]!r}'s ({here}.row)"
                raise ModelError(msg)
            used[r] = name
        next_row = row + len(dof_list)
        point = (float(at[0]), float(at[1]), float(at[2]))
        nodes.append(InterfaceNode(name, point, tuple(dof_list), rows))
    return tuple(nodes)


def parse_damping(body: str, spec: object, expr: Callable[[object, str], sp.Expr],
                  nominal: Callable[[sp.Expr], float | None], where: str) -> FlexibleDamping:
    """The damping entry of a flexible body: ``{modal: ratio or [ratios]}``, ``{rayleigh: [alpha, beta]}`` or
    ``{loss: eta}`` (None: undamped).

    Parameters
    ----------
    body : str
        The body, for messages.
    spec : mapping or None
        The entry.
    expr : callable
        Parses an expression (value, location).
    nominal : callable
        The smallest value of an expression at the model's evaluation points (None if not a number).
    where : str
        The model entry, for messages.

    Returns
    -------
    FlexibleDamping

    Raises
    ------
    ModelError
        The entry is malformed or a value is negative.
    """
    if spec is None:
        return FlexibleDamping()
    if not isinstance(spec, Mapping) or len(spec) != 1 or next(iter(spec)) not in DAMPING_KINDS[1:]:
        msg = (f"flexible body {body!r} damping must be one of {{modal: ratios}}, {{rayleigh: [alpha, beta]}}, "
               f"{{loss: eta}}; got {spec!r} ({where})")
        raise ModelError(msg)
    kind, value = next(iter(spec.items()))
    if kind == "modal":
        values = value if isinstance(value, (list, tuple)) else [value]
        ratios: list[float] = []
        for i, v in enumerate(values):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (0 <= v < 1):
                msg = f"modal damping ratios must be numbers in [0, 1); got {v!r} ({where}.modal[{i}])"
                raise ModelError(msg)
            ratios.append(float(v))
        if not ratios:
            msg = f"modal damping needs at least one ratio ({where}.modal)"
            raise ModelError(msg)
        return FlexibleDamping("modal", ratios=tuple(ratios))
    if kind == "rayleigh":
        if not isinstance(value, (list, tuple)) or len(value) != 2:
            msg = f"rayleigh damping takes [alpha (1/s), beta (s)]; got {value!r} ({where}.rayleigh)"
            raise ModelError(msg)
        alpha, beta = (expr(v, f"{where}.rayleigh[{i}]") for i, v in enumerate(value))
        for i, e in enumerate((alpha, beta)):
            low = nominal(e)
            if low is not None and low < 0:
                msg = f"rayleigh coefficients must be >= 0; got {low:.6g} ({where}.rayleigh[{i}])"
                raise ModelError(msg)
        return FlexibleDamping("rayleigh", alpha=alpha, beta=beta)
    eta = expr(value, f"{where}.loss")
    low = nominal(eta)
    if low is not None and low < 0:
        msg = f"loss factor must be >= 0; got {low:.6g} ({where}.loss)"
        raise ModelError(msg)
    return FlexibleDamping("loss", eta=eta)


def matrix_source(value: object, base: Path | None, where: str, *, square: bool = True) -> Any:
    """A matrix given in a model: an array (Python API), a sparse matrix, or a file spec read relative to
    ``base``."""
    if isinstance(value, (str, Mapping)):
        from cappe.model.fe._files import read_matrix

        return read_matrix(value, base, where, square=square)
    return value


def reduced_body(body: str, mass: Any, stiffness: Any, nodes: object, interior_nodes: object, spec: object,
                 where: str) -> tuple[Array, Array, tuple[InterfaceNode, ...], tuple[InterfaceNode, ...], Array | None]:
    """A flexible body's Craig-Bampton model from its full matrices (the ``reduction`` entry of a model file).

    Parameters
    ----------
    body : str
        The body, for messages.
    mass, stiffness : sparse or dense matrix, shape (n, n)
        Full FE matrices; node rows index them.
    nodes : list of mappings
        Interface nodes (rows of the full matrices): their DOFs are the boundary DOFs.
    interior_nodes : list of mappings or None
        Nodes to recover (rows of the full matrices).
    spec : mapping
        ``{band: Hz, multiple: 1.5}`` or ``{modes: n}``.
    where : str
        The model entry, for messages.

    Returns
    -------
    mass, stiffness : ndarray
        Reduced matrices (boundary DOFs in node order, then the fixed-interface modal amplitudes).
    nodes, interior : tuple of InterfaceNode
        Nodes renumbered into the reduced coordinates and the recovery rows.
    recovery : ndarray or None
        Rows of the Craig-Bampton recovery matrix for the interior nodes.

    Raises
    ------
    ModelError
        The entry is malformed or the reduction impossible (the boundary does not hold the rigid-body motions).
    """
    from cappe.model.fe._reduction import craig_bampton

    if not isinstance(spec, Mapping) or not set(spec) <= {"band", "multiple", "modes"} or (
            ("band" in spec) == ("modes" in spec)):
        msg = f"reduction takes {{band: Hz, multiple: 1.5}} or {{modes: n}}; got {spec!r} ({where}.reduction)"
        raise ModelError(msg)
    k_full = sps.csr_array(stiffness, dtype=float) if not sps.issparse(stiffness) else sps.csr_array(stiffness)
    m_full = sps.csr_array(mass, dtype=float) if not sps.issparse(mass) else sps.csr_array(mass)
    n = k_full.shape[0]
    if k_full.shape != (n, n) or m_full.shape != (n, n):
        msg = f"mass and stiffness must be square of the same order; got {m_full.shape} and {k_full.shape} ({where})"
        raise ModelError(msg)
    for label, mat in (("mass", m_full), ("stiffness", k_full)):
        scale = float(abs(mat).max()) if mat.nnz else 0.0
        if not np.isfinite(mat.data).all() or (mat.nnz and float(abs(mat - mat.T).max()) > SYMMETRY_RTOL * scale):
            msg = f"{label} matrix must be finite and symmetric ({where}.{label})"
            raise ModelError(msg)
    interface = parse_nodes(body, nodes, n, f"{where}.nodes")
    boundary = [r for node in interface for r in node.rows]
    numbers = {key: spec[key] for key in ("band", "multiple", "modes") if key in spec}
    for key, value in numbers.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value <= 0:
            msg = f"reduction {key} must be a positive number; got {value!r} ({where}.reduction.{key})"
            raise ModelError(msg)
    try:
        red = craig_bampton(k_full, m_full, boundary, band=numbers.get("band"),
                            multiple=float(numbers.get("multiple", 1.5)),
                            n_modes=int(numbers["modes"]) if "modes" in numbers else None)
    except ModelError as exc:
        msg = f"{exc} ({where}.reduction)"
        raise ModelError(msg) from exc
    renumbered: list[InterfaceNode] = []
    start = 0
    for node in interface:
        renumbered.append(InterfaceNode(node.name, node.point, node.dofs, tuple(range(start, start + len(node.dofs)))))
        start += len(node.dofs)
    interior: tuple[InterfaceNode, ...] = ()
    recovery = None
    if interior_nodes is not None:
        found = parse_nodes(body, interior_nodes, n, f"{where}.recovery.nodes", interior=True)
        rows = [r for node in found for r in node.rows]
        recovery = np.array(red.recovery[rows], dtype=float)
        recovery.setflags(write=False)
        out: list[InterfaceNode] = []
        start = 0
        for node in found:
            out.append(InterfaceNode(node.name, node.point, node.dofs, tuple(range(start, start + len(node.dofs)))))
            start += len(node.dofs)
        interior = tuple(out)
    return red.mass, red.stiffness, tuple(renumbered), interior, recovery


@dataclass(frozen=True)
class NodeLine:
    """A straight line of interface nodes along which an attachment point may travel (a guide rail).

    A point on the line at distance ``s`` from its first node moves with the nodes' DOFs weighted by linear shape
    functions (hat functions of ``s``): exactly the node's motion where the point sits on a node, continuous in
    between; beyond the ends the end element's functions extrapolate. With ``interpolation = "hermite"`` the nodes
    are those of beam elements and the point moves as :meth:`hermite_weights` says (C1 along the line).

    Attributes
    ----------
    name : str
        Line name.
    nodes : tuple of str
        Interface nodes in order along the line.
    origin : tuple of 3 float
        The first node's coordinates (m, body frame).
    direction : tuple of 3 float
        Unit vector from the first node to the last.
    s : tuple of float
        Each node's distance from the first (m), increasing.
    interpolation : {"linear", "hermite"}
        Linear shape functions, or beam elements' cubics in the nodes' translations and rotations.
    """

    name: str
    nodes: tuple[str, ...]
    origin: tuple[float, float, float]
    direction: tuple[float, float, float]
    s: tuple[float, ...]
    interpolation: str = "linear"

    def hermite_weights(self, s: sp.Expr) -> list[tuple[sp.Matrix, sp.Matrix]]:
        """Beam-element (cubic Hermite) interpolation of the nodes' six DOFs at line coordinate ``s`` (m).

        Within the element of nodes ``i``, ``i + 1`` (length ``L``, ``xi = (s - s_i) / L``, line direction ``e``,
        ``E = e e^T``, ``P = I - E``, ``[e]x`` the cross-product matrix): the axial translation and the torsion are
        linear (``N1 = 1 - xi``, ``N2 = xi``), the transverse translation is the cubic of the end translations and
        slopes ``theta x e``, and the bending rotation is ``e x dw/ds``::

            u     = sum_j (N_j E + H_j P) u_j - L H'_j [e]x theta_j
            theta = sum_j N_j E theta_j + P theta_j dH'_j/dxi + [e]x u_j dH_j/dxi / L

        (``H`` the Hermite cubics of the translations, ``H'`` those of the slopes). At a node the point moves
        exactly as the node; in between, the motion and its derivative along the line are continuous (C1 in ``s``).
        Beyond the ends the end elements extrapolate.

        Parameters
        ----------
        s : sympy expression
            Distance along the line from the first node (m).

        Returns
        -------
        list of (sympy Matrix (3, 6), sympy Matrix (3, 6))
            Per node, the weights of its ``x y z rx ry rz`` on the point's translation and on its rotation.
        """
        e = sp.Matrix([sp.Float(v) for v in self.direction])
        big_e = e * e.T
        perp = sp.eye(3) - big_e
        cross = sp.Matrix([[0, -e[2], e[1]], [e[2], 0, -e[0]], [-e[1], e[0], 0]])
        knots = [sp.Float(v) for v in self.s]
        k = len(knots)
        # per element: the (translation, rotation) weight blocks of its two nodes as functions of s
        pieces: list[list[tuple[sp.Matrix, sp.Matrix]]] = []
        for i in range(k - 1):
            length = knots[i + 1] - knots[i]
            xi = (s - knots[i]) / length
            n1, n2 = 1 - xi, xi
            h = [1 - 3 * xi**2 + 2 * xi**3, xi - 2 * xi**2 + xi**3, 3 * xi**2 - 2 * xi**3, -xi**2 + xi**3]
            dh = [(-6 * xi + 6 * xi**2) / length, (1 - 4 * xi + 3 * xi**2) / length,
                  (6 * xi - 6 * xi**2) / length, (-2 * xi + 3 * xi**2) / length]  # d/ds of the four
            ends = []
            for n_lin, h_u, h_t, dh_u, dh_t in ((n1, h[0], h[1], dh[0], dh[1]), (n2, h[2], h[3], dh[2], dh[3])):
                trans = (n_lin * big_e + h_u * perp).row_join(-length * h_t * cross)
                rot = (dh_u * cross).row_join(n_lin * big_e + length * dh_t * perp)
                ends.append((trans, rot))
            pieces.append(ends)

        def select(node: int, part: int) -> sp.Matrix:
            """The node's weight block ``part`` (0 translation, 1 rotation), piecewise over the elements."""
            out = sp.zeros(3, 6)
            for r in range(3):
                for c in range(6):
                    branches: list[tuple[sp.Expr, Any]] = []
                    for el in range(k - 1):
                        if node not in (el, el + 1):
                            value: sp.Expr = sp.Integer(0)
                        else:
                            value = sp.expand(pieces[el][node - el][part][r, c])
                        condition = True if el == k - 2 else s < knots[el + 1]
                        branches.append((value, condition))
                    out[r, c] = sp.Piecewise(*branches) if len(branches) > 1 else branches[0][0]
            return out

        return [(select(j, 0), select(j, 1)) for j in range(k)]

    def shape_functions(self, s: sp.Expr) -> list[sp.Expr]:
        """Linear shape functions of the nodes at line coordinate ``s`` (m).

        Parameters
        ----------
        s : sympy expression
            Distance along the line from the first node (m).

        Returns
        -------
        list of sympy expressions
            One per node; they sum to 1.
        """
        knots = [sp.Float(v) for v in self.s]
        k = len(knots)
        out: list[sp.Expr] = []
        for i in range(k):
            pieces: list[tuple[sp.Expr, Any]] = []
            if i > 1:
                pieces.append((sp.Integer(0), s <= knots[i - 1]))
            if i > 0:  # rising from the previous node (before the first segment: extrapolated from it)
                pieces.append(((s - knots[i - 1]) / (knots[i] - knots[i - 1]), s <= knots[i] if i < k - 1 else True))
            if i < k - 1:  # falling to the next node (after the last segment: extrapolated)
                falling = (knots[i + 1] - s) / (knots[i + 1] - knots[i])
                if i < k - 2:
                    pieces.extend([(falling, s < knots[i + 1]), (sp.Integer(0), True)])
                else:
                    pieces.append((falling, True))
            out.append(sp.Piecewise(*pieces))
        return out

    def locate(self, point: Sequence[float], size: float) -> float | None:
        """The line coordinate of ``point`` (m), or None if it is off the line (more than 1e-9 ``size`` away).

        Parameters
        ----------
        point : sequence of 3 float
            Body-frame coordinates (m).
        size : float
            Length scale of the body (m).

        Returns
        -------
        float or None
        """
        rel = np.asarray(point, dtype=float) - np.asarray(self.origin)
        s = float(rel @ np.asarray(self.direction))
        off = float(np.linalg.norm(rel - s * np.asarray(self.direction)))
        return s if off <= 1e-9 * size else None


def parse_lines(body: str, entries: object, nodes: Sequence[InterfaceNode], where: str) -> tuple[NodeLine, ...]:
    """Lines of interface nodes ``[{name, nodes: [n0, n1, ...], interpolation}]`` (straight, at least two nodes, same
    DOFs; ``interpolation`` ``linear`` (default) or ``hermite``: beam elements, all six DOFs).

    Parameters
    ----------
    body : str
        The body, for messages.
    entries : list of mappings or None
        The ``lines`` entry.
    nodes : sequence of InterfaceNode
        The body's interface nodes.
    where : str
        The model entry, for messages.

    Returns
    -------
    tuple of NodeLine

    Raises
    ------
    ModelError
        An entry breaks a rule.
    """
    if entries is None:
        return ()
    if not isinstance(entries, (list, tuple)):
        msg = f"flexible body {body!r} lines must be a list; got {entries!r} ({where})"
        raise ModelError(msg)
    by_name = {n.name: n for n in nodes}
    coords = np.array([n.point for n in nodes])
    size = max(float(np.ptp(coords, axis=0).max()), 1.0)
    out: list[NodeLine] = []
    for i, entry in enumerate(entries):
        here = f"{where}[{i}]"
        if (not isinstance(entry, Mapping) or not {"name", "nodes"} <= set(entry)
                or not set(entry) <= {"name", "nodes", "interpolation"} or not isinstance(entry["name"], str)
                or not isinstance(entry["nodes"], (list, tuple)) or len(entry["nodes"]) < 2):
            msg = (f"a line is {{name: NAME, nodes: [at least two interface nodes], interpolation: linear | hermite}}; "
                   f"got {entry!r} ({here})")
            raise ModelError(msg)
        interpolation = entry.get("interpolation", "linear")
        if interpolation not in ("linear", "hermite"):
            msg = (f"line {entry['name']!r} interpolation must be 'linear' or 'hermite' (beam elements: cubic with "
                   f"the rotations); got {interpolation!r} ({here}.interpolation)")
            raise ModelError(msg)
        missing = [n for n in entry["nodes"] if n not in by_name]
        if missing:
            msg = f"line {entry['name']!r} names unknown interface node(s) {missing} ({here}.nodes)"
            raise ModelError(msg)
        members = [by_name[n] for n in entry["nodes"]]
        if len({m.dofs for m in members}) != 1:
            msg = f"the nodes of line {entry['name']!r} must carry the same DOFs ({here}.nodes)"
            raise ModelError(msg)
        if interpolation == "hermite" and set(members[0].dofs) != set(_DIRECTIONS):
            msg = (f"hermite interpolation along line {entry['name']!r} needs nodes with all six DOFs; they carry "
                   f"{', '.join(members[0].dofs)} ({here}.nodes)")
            raise ModelError(msg)
        first, last = np.array(members[0].point), np.array(members[-1].point)
        span = float(np.linalg.norm(last - first))
        if span <= 0:
            msg = f"line {entry['name']!r} has no length ({here}.nodes)"
            raise ModelError(msg)
        direction = (last - first) / span
        line = NodeLine(str(entry["name"]), tuple(entry["nodes"]), (float(first[0]), float(first[1]), float(first[2])),
                        (float(direction[0]), float(direction[1]), float(direction[2])), ())
        s = [line.locate(m.point, size) for m in members]
        if any(v is None for v in s) or any(b <= a for a, b in zip(s, s[1:], strict=False)):  # type: ignore[operator]
            msg = (f"the nodes of line {entry['name']!r} must lie on a straight line in the order given "
                   f"({here}.nodes)")
            raise ModelError(msg)
        out.append(NodeLine(line.name, line.nodes, line.origin, line.direction, tuple(float(v) for v in s),  # type: ignore[arg-type]
                            str(interpolation)))
    return tuple(out)


def frame_node_entries(body: str, entries: object, coordinates: Array, where: str) -> object:
    """Node entries of a body built from a frame, with each node's ``row`` set from its coordinates.

    A node sits on a frame node (within 1 nm) and its ``dofs`` are a run of ``x y z rx ry rz`` in that order
    (the frame's rows ``6 i .. 6 i + 5``); it gives no ``row`` of its own.

    Parameters
    ----------
    body : str
        The body, for messages.
    entries : list of mappings or None
        The ``nodes`` (or ``recovery.nodes``) entries.
    coordinates : ndarray, shape (n_nodes, 3)
        The frame's node coordinates (m, body frame).
    where : str
        The model entry, for messages.

    Returns
    -------
    list of mappings or the entries unchanged where they are not a list (parse_nodes reports those)

    Raises
    ------
    ModelError
        A node is off the frame's nodes, gives a row, or its DOFs are not a run.
    """
    if not isinstance(entries, (list, tuple)):
        return entries
    out: list[object] = []
    for i, entry in enumerate(entries):
        here = f"{where}[{i}]"
        if not isinstance(entry, Mapping) or "at" not in entry:
            out.append(entry)
            continue
        if "row" in entry:
            msg = f"a node of a frame takes its rows from its coordinates; remove 'row' ({here}.row)"
            raise ModelError(msg)
        try:
            at = np.array(entry["at"], dtype=float).reshape(3)
        except (TypeError, ValueError):
            out.append(entry)
            continue
        dist = np.linalg.norm(coordinates - at, axis=1)
        k = int(np.argmin(dist))
        if dist[k] > 1e-9:
            msg = (f"node {entry.get('name')!r} at {at.tolist()} is not a node of flexible body {body!r}'s frame "
                   f"(nearest {coordinates[k].tolist()}) ({here}.at)")
            raise ModelError(msg)
        dofs = entry.get("dofs", list(_DIRECTIONS))
        dof_list = list(dofs) if isinstance(dofs, (list, tuple)) else [dofs]
        index = [_DIRECTIONS.index(d) for d in dof_list if d in _DIRECTIONS]
        if len(index) == len(dof_list) and index and index != list(range(index[0], index[0] + len(index))):
            msg = (f"node {entry.get('name')!r} dofs on a frame must be a run of x y z rx ry rz in that order; got "
                   f"{dofs!r} ({here}.dofs)")
            raise ModelError(msg)
        out.append({**entry, "row": 6 * k + (index[0] if index else 0)})
    return out
