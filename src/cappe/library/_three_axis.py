"""The bed and the column of ``builtin:three-axis-machine-tool`` as 3-D Timoshenko frames (full sparse FE models).

The model file reads the matrices this module writes (``three-axis-machine-tool.<body>-<K|M>.npz`` next to it,
:func:`scipy.sparse.save_npz`) and reduces them itself (``reduction:`` in the file, Craig-Bampton). Rewrite them
with ``python -m cappe.library._three_axis``; tests/library/test_three_axis_machine_tool.py checks that the stored
files equal what :func:`frames` builds, so the numbers below are the only source of the matrices.

Geometry (m; body frames; y vertical up):

* **bed** (origin at the centre of the rail plane): two longitudinal box girders under the X rails, x = -1.2 ..
  1.2 at z = -0.35 and +0.35, joined by five transverse box ribs at x = -1.2, -0.6, 0, 0.6, 1.2; elements of
  0.1 m along the girders and 0.175 m along the ribs. The X motor and its bracket (35 kg) sit as a point mass on
  the node (1.2, 0, 0) that also carries the X fixed bearing.
* **column** (origin at the centre of its base, on the Z shoes): a central box spine 0.6 (x) x 0.5 (z) from
  y = 0 to 1.6; the two front guide-rail girders at x = -0.3, +0.3, z = 0.25; horizontal arms every 0.2 m joining
  spine and rail girders (the side and front walls), arms at the base to the two rear corners (-0.3, 0, -0.25) and
  (0.3, 0, -0.25), and a top cross beam through (0, 1.6, 0.25), the Y fixed bearing, where the Y motor with its
  bracket (25 kg) sits as a point mass.

Materials: grey cast iron EN-GJL-300 (E 120 GPa, nu 0.26, density 7200 kg/m^3) for both (the handbook range of
E is 110-140 GPa). Sections are thin-walled rectangular boxes (torsion constant of a closed thin-walled section,
4 A_m^2 t / perimeter; shear coefficient 5/6): bed girders 0.30 x 0.50 m with 30 mm walls, ribs 0.20 x 0.40 m with
25 mm walls; column spine 0.50 x 0.60 m with 25 mm walls, rail girders 0.15 x 0.15 m with 20 mm walls, arms
0.10 x 0.20 m with 15 mm walls. Masses: bed about 2.3 t, column about 1.0 t (a cast column of this size weighs
1-1.5 t; the walls' mass is in the spine).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sps
from numpy.typing import NDArray

from cappe.model.fe import BeamSection, FrameModel, frame_model

__all__ = ["FRAME_FILES", "MachineFrame", "frames", "write_matrices"]

Array = NDArray[np.float64]
E_CAST, NU_CAST, RHO_CAST = 120e9, 0.26, 7200.0
#: The files the model reads, per body: (stiffness, mass).
FRAME_FILES = {body: (f"three-axis-machine-tool.{body}-K.npz", f"three-axis-machine-tool.{body}-M.npz")
               for body in ("bed", "column")}


def box(width: float, height: float, wall: float) -> BeamSection:
    """A thin-walled rectangular box of cast iron: ``width`` along the element's local y, ``height`` along local z.

    Parameters
    ----------
    width, height : float
        Outer sides (m).
    wall : float
        Wall thickness (m).

    Returns
    -------
    BeamSection

    Examples
    --------
    >>> round(box(0.3, 0.5, 0.03).A, 6)
    0.0444
    """
    bi, hi = width - 2 * wall, height - 2 * wall
    area = width * height - bi * hi
    mid_w, mid_h = width - wall, height - wall
    torsion = 4 * (mid_w * mid_h) ** 2 * wall / (2 * (mid_w + mid_h))
    return BeamSection(E=E_CAST, G=E_CAST / (2 * (1 + NU_CAST)), rho=RHO_CAST, A=area,
                       Iy=(width * height**3 - bi * hi**3) / 12, Iz=(height * width**3 - hi * bi**3) / 12,
                       J=torsion, kappa=5.0 / 6.0)


@dataclass(frozen=True)
class MachineFrame:
    """A full frame model and the node numbers the model file refers to.

    Attributes
    ----------
    frame : FrameModel
        Nodes and sparse K, M (the point masses included in M).
    named : dict of str to int
        Node index of each named point.
    """

    frame: FrameModel
    named: dict[str, int]

    def node(self, name: str) -> int:
        """Index of a named node.

        Parameters
        ----------
        name : str
            Node name.

        Returns
        -------
        int
        """
        return self.named[name]


class _Mesh:
    """Nodes found by their coordinates (0.1 mm), straight members split into equal elements."""

    def __init__(self) -> None:
        self.points: list[tuple[float, float, float]] = []
        self.index: dict[tuple[int, int, int], int] = {}
        self.elements: list[tuple[int, int]] = []
        self.sections: list[BeamSection] = []

    def node(self, point: tuple[float, float, float]) -> int:
        key = tuple(int(round(v * 1e4)) for v in point)
        if key not in self.index:
            self.index[key] = len(self.points)  # type: ignore[index]
            self.points.append(point)
        return self.index[key]  # type: ignore[index]

    def member(self, start: tuple[float, float, float], end: tuple[float, float, float], n_el: int,
               section: BeamSection) -> None:
        a, b = np.asarray(start), np.asarray(end)
        points = [a + (b - a) * k / n_el for k in range(n_el + 1)]
        ids = [self.node((float(p[0]), float(p[1]), float(p[2]))) for p in points]
        for i, j in zip(ids, ids[1:], strict=False):
            self.elements.append((i, j))
            self.sections.append(section)

    def build(self, point_masses: dict[int, float]) -> FrameModel:
        fm = frame_model(np.array(self.points), np.array(self.elements), self.sections, up=(0.0, 1.0, 0.0))
        lumped = np.zeros(fm.n_dof)
        for node, mass in point_masses.items():
            lumped[6 * node:6 * node + 3] = mass
        return FrameModel(fm.nodes, fm.stiffness, sps.csr_array(fm.mass + sps.diags_array(lumped)))


def bed_frame() -> MachineFrame:
    """The bed: two box girders under the X rails and five transverse ribs (see the module text)."""
    mesh = _Mesh()
    girder, rib = box(0.30, 0.50, 0.03), box(0.20, 0.40, 0.025)
    for z in (-0.35, 0.35):
        mesh.member((-1.2, 0.0, z), (1.2, 0.0, z), 24, girder)
    for x in (-1.2, -0.6, 0.0, 0.6, 1.2):
        mesh.member((x, 0.0, -0.35), (x, 0.0, 0.35), 4, rib)
    # rails: br (rear, z = -0.35) and bf (front, z = +0.35), nodes 0, 1, 2 at x = -1.2, 0, 1.2
    named = {f"b{side}{k}": mesh.node((x, 0.0, z)) for side, z in (("r", -0.35), ("f", 0.35))
             for k, x in enumerate((-1.2, 0.0, 1.2))}
    named |= {"xfb": mesh.node((1.2, 0.0, 0.0)), "rib_left": mesh.node((-1.2, 0.0, 0.0)),
              "rib_mid": mesh.node((0.0, 0.0, 0.0)), "br_q1": mesh.node((-0.6, 0.0, -0.35)),
              "bf_q3": mesh.node((0.6, 0.0, 0.35))}
    return MachineFrame(mesh.build({named["xfb"]: 35.0}), named)


def column_frame() -> MachineFrame:
    """The column: box spine, two front rail girders, arms every 0.2 m, base and top beams (see the module text)."""
    mesh = _Mesh()
    spine, rail, arm = box(0.50, 0.60, 0.025), box(0.15, 0.15, 0.02), box(0.10, 0.20, 0.015)
    mesh.member((0.0, 0.0, 0.0), (0.0, 1.6, 0.0), 16, spine)
    for x in (-0.3, 0.3):
        mesh.member((x, 0.0, 0.25), (x, 1.6, 0.25), 16, rail)
    for level in range(9):
        y = 0.2 * level
        for x in (-0.3, 0.3):
            mesh.member((0.0, y, 0.0), (x, y, 0.25), 1, arm)
    for x in (-0.3, 0.3):
        mesh.member((0.0, 0.0, 0.0), (x, 0.0, -0.25), 1, arm)
        mesh.member((0.0, 1.6, 0.25), (x, 1.6, 0.25), 3, arm)
    named = {f"c{side}{k}": mesh.node((x, y, 0.25)) for side, x in (("l", -0.3), ("r", 0.3))
             for k, y in enumerate((0.0, 0.8, 1.6))}
    named |= {"cbl": mesh.node((-0.3, 0.0, -0.25)), "cbr": mesh.node((0.3, 0.0, -0.25)),
              "znut": mesh.node((0.0, 0.0, 0.0)), "yfb": mesh.node((0.0, 1.6, 0.25)),
              "spine_top": mesh.node((0.0, 1.6, 0.0)), "spine_mid": mesh.node((0.0, 0.8, 0.0)),
              "cl_q1": mesh.node((-0.3, 0.4, 0.25)), "cr_q3": mesh.node((0.3, 1.2, 0.25))}
    return MachineFrame(mesh.build({named["yfb"]: 25.0}), named)


def frames() -> dict[str, MachineFrame]:
    """The two frames by body name.

    Returns
    -------
    dict of str to MachineFrame
    """
    return {"bed": bed_frame(), "column": column_frame()}


def write_matrices(folder: Path) -> list[Path]:
    """Write the frames' stiffness and mass matrices (:data:`FRAME_FILES`) into ``folder``.

    Parameters
    ----------
    folder : Path
        Where the model file lives.

    Returns
    -------
    list of Path
        The files written.
    """
    written = []
    for body, fm in frames().items():
        for name, mat in zip(FRAME_FILES[body], (fm.frame.stiffness, fm.frame.mass), strict=True):
            path = Path(folder) / name
            sps.save_npz(path, sps.csr_matrix(mat), compressed=True)
            written.append(path)
    return written


if __name__ == "__main__":  # pragma: no cover - the maintainer's command that rewrites the files
    from cappe.library import builtin_path

    write_matrices(builtin_path("three-axis-machine-tool").parent)
