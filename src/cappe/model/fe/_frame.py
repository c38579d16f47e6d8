"""A small 3-D frame generator: two-node Timoshenko (or Euler-Bernoulli) beam elements, sparse K and M.

Why written here and not taken from PyPI: cappe needs the assembled sparse stiffness *and consistent mass*
matrices of a 3-D frame as arrays, to reduce and couple them. anaStruct is 2-D and static; PyNite (3-D frames) and
CALFEM's ``beam3e`` give static stiffness without a consistent mass; OpenSeesPy has both but runs as a global
interpreter state in a native binary from which matrices are awkward to take out, a heavy dependency for ~200
lines of textbook element matrices. The element here is Przemieniecki's (Theory of Matrix Structural Analysis,
1968, ch. 5 and 11): Timoshenko stiffness with the shear parameters ``Phi = 12 E I / (kappa G A L^2)`` (``kappa``
None gives Euler-Bernoulli), the consistent translational mass of the cubic interpolation, and rotary and
torsional inertia with linear interpolation of the (independent) section rotations.

DOFs per node: ``x y z rx ry rz`` (global), node ``i`` at rows ``6 i .. 6 i + 5``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sps
from numpy.typing import ArrayLike, NDArray

from cappe.exceptions import ModelError

__all__ = ["BeamSection", "FrameModel", "beam_element_matrices", "frame_from_spec", "frame_model"]

#: Most beam elements a model file's ``frame`` may generate (each adds 6 DOFs): a full mesh this size, about
#: 120 000 DOFs, is still reduced in seconds to minutes; a file cannot make cappe build an unbounded one.
MAX_FRAME_ELEMENTS = 20_000

Array = NDArray[np.float64]
_DIRECTIONS = ("x", "y", "z", "rx", "ry", "rz")


@dataclass(frozen=True)
class BeamSection:
    """Material and cross-section of a beam (SI).

    Attributes
    ----------
    E : float
        Young's modulus (Pa).
    G : float
        Shear modulus (Pa).
    rho : float
        Density (kg/m^3).
    A : float
        Area (m^2).
    Iy, Iz : float
        Second moments of area about the local y and z axes (m^4): Iy governs bending in the local x-z plane.
    J : float
        Torsion constant (m^4).
    kappa : float or None
        Shear coefficient (5/6 for a rectangle); None: Euler-Bernoulli (no shear deformation).
    """

    E: float  # noqa: N815 (the symbols of the literature)
    G: float  # noqa: N815
    rho: float
    A: float  # noqa: N815
    Iy: float  # noqa: N815
    Iz: float  # noqa: N815
    J: float  # noqa: N815
    kappa: float | None = 5.0 / 6.0

    @classmethod
    def rectangle(cls, width: float, height: float, *, E: float, nu: float, rho: float,  # noqa: N803
                  timoshenko: bool = True) -> BeamSection:
        """A solid rectangle ``width`` (local y) by ``height`` (local z).

        Parameters
        ----------
        width, height : float
            Sides along local y and z (m).
        E : float
            Young's modulus (Pa).
        nu : float
            Poisson's ratio.
        rho : float
            Density (kg/m^3).
        timoshenko : bool
            Shear deformation with kappa = 5/6 (else Euler-Bernoulli).

        Returns
        -------
        BeamSection

        Examples
        --------
        >>> s = BeamSection.rectangle(0.1, 0.2, E=210e9, nu=0.3, rho=7850.0)
        >>> round(s.Iy / s.Iz, 6)
        4.0
        """
        a, b = max(width, height), min(width, height)
        torsion = a * b**3 * (1 / 3 - 0.21 * b / a * (1 - b**4 / (12 * a**4)))  # Roark's approximation
        return cls(E=E, G=E / (2 * (1 + nu)), rho=rho, A=width * height, Iy=width * height**3 / 12,
                   Iz=height * width**3 / 12, J=torsion, kappa=5.0 / 6.0 if timoshenko else None)


def beam_element_matrices(section: BeamSection, length: float) -> tuple[Array, Array]:
    """Local 12 x 12 stiffness and mass of one element (DOFs u v w rx ry rz at node 1, then node 2).

    Parameters
    ----------
    section : BeamSection
        Material and section.
    length : float
        Element length (m).

    Returns
    -------
    K, M : ndarray, shape (12, 12)
    """
    s, L = section, length  # noqa: N806
    k = np.zeros((12, 12))
    m = np.zeros((12, 12))
    ax = s.E * s.A / L
    k[np.ix_([0, 6], [0, 6])] = ax * np.array([[1, -1], [-1, 1]])
    k[np.ix_([3, 9], [3, 9])] = s.G * s.J / L * np.array([[1, -1], [-1, 1]])

    def bending(inertia: float, sign: float) -> Array:
        phi = 0.0 if s.kappa is None else 12 * s.E * inertia / (s.kappa * s.G * s.A * L**2)
        c = s.E * inertia / ((1 + phi) * L**3)
        return c * np.array([
            [12, sign * 6 * L, -12, sign * 6 * L],
            [sign * 6 * L, (4 + phi) * L**2, -sign * 6 * L, (2 - phi) * L**2],
            [-12, -sign * 6 * L, 12, -sign * 6 * L],
            [sign * 6 * L, (2 - phi) * L**2, -sign * 6 * L, (4 + phi) * L**2],
        ])

    def translation_mass(sign: float) -> Array:
        return s.rho * s.A * L / 420 * np.array([
            [156, sign * 22 * L, 54, -sign * 13 * L],
            [sign * 22 * L, 4 * L**2, sign * 13 * L, -3 * L**2],
            [54, sign * 13 * L, 156, -sign * 22 * L],
            [-sign * 13 * L, -3 * L**2, -sign * 22 * L, 4 * L**2],
        ])

    xy, xz = [1, 5, 7, 11], [2, 4, 8, 10]  # (v, rz) and (w, ry): rz = dv/dx, ry = -dw/dx
    k[np.ix_(xy, xy)] += bending(s.Iz, 1.0)
    k[np.ix_(xz, xz)] += bending(s.Iy, -1.0)
    m[np.ix_(xy, xy)] += translation_mass(1.0)
    m[np.ix_(xz, xz)] += translation_mass(-1.0)
    linear = L / 6 * np.array([[2.0, 1.0], [1.0, 2.0]])
    m[np.ix_([0, 6], [0, 6])] += s.rho * s.A * linear
    m[np.ix_([3, 9], [3, 9])] += s.rho * (s.Iy + s.Iz) * linear
    m[np.ix_([4, 10], [4, 10])] += s.rho * s.Iy * linear
    m[np.ix_([5, 11], [5, 11])] += s.rho * s.Iz * linear
    return k, m


@dataclass(frozen=True)
class FrameModel:
    """Assembled frame: node coordinates and sparse stiffness and mass (6 DOFs per node).

    Attributes
    ----------
    nodes : ndarray, shape (n_nodes, 3)
        Node coordinates (m).
    stiffness, mass : scipy.sparse.csr_array, shape (6 n_nodes, 6 n_nodes)
        N/m (N m/rad) and kg (kg m^2).
    """

    nodes: Array
    stiffness: sps.csr_array
    mass: sps.csr_array

    @property
    def n_dof(self) -> int:
        return int(self.stiffness.shape[0])

    def dof(self, node: int, direction: str) -> int:
        """Row of a node's DOF.

        Parameters
        ----------
        node : int
            Node index.
        direction : str
            One of ``x y z rx ry rz``.

        Returns
        -------
        int
        """
        return 6 * node + _DIRECTIONS.index(direction)

    def node_at(self, point: ArrayLike) -> int:
        """Index of the node nearest ``point`` (m).

        Parameters
        ----------
        point : array_like, shape (3,)
            Coordinates (m).

        Returns
        -------
        int
        """
        return int(np.argmin(np.linalg.norm(self.nodes - np.asarray(point, dtype=float), axis=1)))


def frame_model(nodes: ArrayLike, elements: ArrayLike, section: BeamSection | Sequence[BeamSection], *,
                up: ArrayLike = (0.0, 0.0, 1.0)) -> FrameModel:
    """Assemble a 3-D frame of two-node beam elements.

    Parameters
    ----------
    nodes : array_like, shape (n_nodes, 3)
        Node coordinates (m).
    elements : array_like of int, shape (n_elements, 2)
        Node indices of each element.
    section : BeamSection or sequence of BeamSection
        One section for all elements or one per element.
    up : array_like, shape (3,)
        A vector fixing each element's local axes: local y = up x (local x), z = x × y (an element along
        ``up`` takes global x instead).

    Returns
    -------
    FrameModel

    Raises
    ------
    ModelError
        Shapes do not fit, an element has zero length or refers to a missing node.

    Examples
    --------
    >>> import numpy as np
    >>> sec = BeamSection.rectangle(0.05, 0.05, E=210e9, nu=0.3, rho=7850.0)
    >>> fm = frame_model(np.c_[np.linspace(0, 1, 5), np.zeros(5), np.zeros(5)], [[i, i + 1] for i in range(4)], sec)
    >>> fm.stiffness.shape
    (30, 30)
    """
    xyz = np.asarray(nodes, dtype=float)
    conn = np.asarray(elements)
    if xyz.ndim != 2 or xyz.shape[1] != 3 or not np.isfinite(xyz).all():
        msg = f"nodes must be finite coordinates of shape (n_nodes, 3); got shape {xyz.shape}"
        raise ModelError(msg)
    if conn.ndim != 2 or conn.shape[1] != 2 or conn.dtype.kind not in "iu" or conn.min(initial=0) < 0 \
            or conn.max(initial=0) >= xyz.shape[0]:
        msg = f"elements must be pairs of node indices in [0, {xyz.shape[0]}); got shape {conn.shape}"
        raise ModelError(msg)
    sections = [section] * conn.shape[0] if isinstance(section, BeamSection) else list(section)
    if len(sections) != conn.shape[0]:
        msg = f"give one section or one per element ({conn.shape[0]}); got {len(sections)}"
        raise ModelError(msg)
    up_vec = np.asarray(up, dtype=float)
    rows: list[NDArray[np.intp]] = []
    k_vals: list[Array] = []
    m_vals: list[Array] = []
    for e, (a, b) in enumerate(conn):
        d = xyz[b] - xyz[a]
        length = float(np.linalg.norm(d))
        if length <= 0:
            msg = f"element {e} joins nodes {a} and {b} at the same place"
            raise ModelError(msg)
        ex = d / length
        ref = up_vec if np.linalg.norm(np.cross(up_vec, ex)) > 1e-6 * np.linalg.norm(up_vec) else np.eye(3)[0]
        ey = np.cross(ref, ex)
        ey /= np.linalg.norm(ey)
        ez = np.cross(ex, ey)
        rot = np.vstack([ex, ey, ez])
        t = np.kron(np.eye(4), rot)
        k_loc, m_loc = beam_element_matrices(sections[e], length)
        dofs = np.r_[6 * a + np.arange(6), 6 * b + np.arange(6)]
        rows.append(dofs)
        k_vals.append(t.T @ k_loc @ t)
        m_vals.append(t.T @ m_loc @ t)
    n = 6 * xyz.shape[0]
    index = np.array(rows).reshape(-1, 12)
    i = np.repeat(index, 12, axis=1).ravel()
    j = np.tile(index, (1, 12)).ravel()

    def assemble(values: list[Array]) -> sps.csr_array:
        mat = sps.csr_array(sps.coo_array((np.array(values).ravel(), (i, j)), shape=(n, n)))
        return sps.csr_array((mat + mat.T) / 2)

    return FrameModel(xyz, assemble(k_vals), assemble(m_vals))


_SECTION_KEYS = ("E", "G", "A", "Iy", "Iz", "J")


def _section_from_spec(name: str, spec: object, where: str) -> BeamSection:
    """A section ``{E, G, A, Iy, Iz, J, rho or line_mass, kappa}`` of a frame spec (SI; ``line_mass`` kg/m gives
    ``rho = line_mass / A``; ``kappa`` null: Euler-Bernoulli, default 5/6)."""
    allowed = {*_SECTION_KEYS, "rho", "line_mass", "kappa"}
    if not isinstance(spec, Mapping) or not set(_SECTION_KEYS) <= set(spec) or not set(spec) <= allowed \
            or ("rho" in spec) == ("line_mass" in spec):
        msg = (f"section {name!r} takes E, G, A, Iy, Iz, J, one of rho (kg/m^3) and line_mass (kg/m), and optionally "
               f"kappa; got {spec!r} ({where})")
        raise ModelError(msg)
    values: dict[str, float] = {}
    for key in (*_SECTION_KEYS, "rho", "line_mass"):
        if key not in spec:
            continue
        v = spec[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v <= 0:
            msg = f"section {name!r} {key} must be a positive number; got {v!r} ({where}.{key})"
            raise ModelError(msg)
        values[key] = float(v)
    kappa = spec.get("kappa", 5.0 / 6.0)
    if kappa is not None and (isinstance(kappa, bool) or not isinstance(kappa, (int, float)) or not 0 < kappa <= 1):
        msg = f"section {name!r} kappa must be in (0, 1] or null (Euler-Bernoulli); got {kappa!r} ({where}.kappa)"
        raise ModelError(msg)
    rho = values["rho"] if "rho" in values else values["line_mass"] / values["A"]
    return BeamSection(E=values["E"], G=values["G"], rho=rho, A=values["A"], Iy=values["Iy"], Iz=values["Iz"],
                       J=values["J"], kappa=None if kappa is None else float(kappa))


def frame_from_spec(spec: object, where: str) -> FrameModel:
    """A frame described in a model file: sections and beams (polylines of points, each span cut into elements).

    ``{sections: {NAME: {E, G, A, Iy, Iz, J, rho | line_mass, kappa}}, beams: [{points: [[x, y, z], ...],
    section: NAME, divide: 1}], up: [0, 1, 0]}``. Points closer than 1 nm are one node, so beams that share a point
    are joined there rigidly. Each element's local y axis is ``up`` x (local x) (:func:`frame_model`).

    Parameters
    ----------
    spec : mapping
        The ``frame`` entry of a flexible body.
    where : str
        The model entry, for messages.

    Returns
    -------
    FrameModel

    Raises
    ------
    ModelError
        An entry breaks a rule; the message names it.

    Examples
    --------
    >>> spec = {"sections": {"s": {"E": 2.1e11, "G": 8.1e10, "A": 1e-3, "Iy": 1e-7, "Iz": 1e-7, "J": 2e-7,
    ...                            "rho": 7850.0}},
    ...         "beams": [{"points": [[0, 0, 0], [1, 0, 0]], "section": "s", "divide": 4}]}
    >>> frame_from_spec(spec, "example").nodes.shape
    (5, 3)
    """
    if not isinstance(spec, Mapping) or not {"sections", "beams"} <= set(spec) \
            or not set(spec) <= {"sections", "beams", "up"}:
        msg = f"frame takes sections, beams and optionally up; got {spec!r} ({where})"
        raise ModelError(msg)
    sections_spec = spec["sections"]
    if not isinstance(sections_spec, Mapping) or not sections_spec:
        msg = f"frame sections must be a mapping NAME: {{...}}; got {sections_spec!r} ({where}.sections)"
        raise ModelError(msg)
    sections = {str(k): _section_from_spec(str(k), v, f"{where}.sections.{k}") for k, v in sections_spec.items()}
    up = spec.get("up", [0.0, 1.0, 0.0])
    if not isinstance(up, (list, tuple)) or len(up) != 3 or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in up) or not any(up):
        msg = f"frame up must be a non-zero 3-vector; got {up!r} ({where}.up)"
        raise ModelError(msg)
    beams = spec["beams"]
    if not isinstance(beams, (list, tuple)) or not beams:
        msg = f"frame beams must be a non-empty list; got {beams!r} ({where}.beams)"
        raise ModelError(msg)
    coords: list[Array] = []
    index: dict[tuple[int, int, int], int] = {}

    def node(point: Array) -> int:
        key = tuple(int(round(v * 1e9)) for v in point)
        if key not in index:
            index[key] = len(coords)  # type: ignore[index]
            coords.append(point)
        return index[key]  # type: ignore[index]

    elements: list[tuple[int, int]] = []
    element_sections: list[BeamSection] = []
    for i, beam in enumerate(beams):
        here = f"{where}.beams[{i}]"
        if not isinstance(beam, Mapping) or not {"points", "section"} <= set(beam) \
                or not set(beam) <= {"points", "section", "divide"}:
            msg = f"a beam is {{points: [[x, y, z], ...], section: NAME, divide: n}}; got {beam!r} ({here})"
            raise ModelError(msg)
        if beam["section"] not in sections:
            msg = f"beam section {beam['section']!r} is not one of {', '.join(sections)} ({here}.section)"
            raise ModelError(msg)
        divide = beam.get("divide", 1)
        if isinstance(divide, bool) or not isinstance(divide, int) or not 1 <= divide <= 1000:
            msg = f"beam divide must be an integer 1..1000; got {divide!r} ({here}.divide)"
            raise ModelError(msg)
        try:
            points = np.array(beam["points"], dtype=float)
        except (TypeError, ValueError):
            points = np.zeros((0, 0))
        if points.ndim != 2 or points.shape[0] < 2 or points.shape[1] != 3 or not np.isfinite(points).all():
            msg = f"beam points must be at least two finite [x, y, z] (m); got {beam['points']!r} ({here}.points)"
            raise ModelError(msg)
        if len(elements) + (points.shape[0] - 1) * divide > MAX_FRAME_ELEMENTS:
            msg = (f"the frame would have more than {MAX_FRAME_ELEMENTS} beam elements (segments x divide over all "
                   f"beams) ({here})")
            raise ModelError(msg)
        for a, b in zip(points[:-1], points[1:], strict=True):
            if np.linalg.norm(b - a) <= 1e-9:
                msg = f"beam points {a.tolist()} and {b.tolist()} coincide ({here}.points)"
                raise ModelError(msg)
            ids = [node(a + (b - a) * t) for t in np.linspace(0.0, 1.0, divide + 1)]
            for p, q in zip(ids[:-1], ids[1:], strict=True):
                elements.append((p, q))
                element_sections.append(sections[str(beam["section"])])
    return frame_model(np.array(coords), np.array(elements, dtype=np.intp), element_sections,
                       up=np.asarray(up, dtype=float))
