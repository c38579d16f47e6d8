"""Modes as data: natural frequencies, damping ratios and mode shapes.

Two containers, one purpose each (the other modal results hold more and convert into these):

* :class:`ModalSet` - the modes of one system (one parameter vector, one axis position) at its labelled
  coordinates, with the method that computed them and the rigid-body flags: what ``MechanicalSystem.modes``
  returns and ``cappe model modes`` prints.
* :class:`ModalData` of :class:`ModalDataSet` - modes at named sensor channels at one or more axis positions:
  measured, extracted or simulated reference modes, the ``"cappe.modal/1"`` document that :mod:`cappe.io` reads
  and writes (JSON, UFF 55) and that estimators and criteria compare a model with.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cappe.exceptions import DataError

__all__ = ["MODAL_FORMAT", "ModalData", "ModalDataSet", "ModalSet", "dominant_dofs"]

#: Format string of modal data documents (:meth:`ModalData.to_dict`; read and written by :mod:`cappe.io`).
MODAL_FORMAT = "cappe.modal/1"
#: Optional per-mode standard deviations of a cappe.modal/1 set (absolute: Hz, ratio, shape units).
STD_FIELDS = ("frequency_std", "damping_std", "shape_std")


@dataclass(frozen=True)
class ModalSet:
    """Modes of a structure, ascending in natural frequency.

    Attributes
    ----------
    frequency : ndarray, shape (n_modes,)
        Natural frequencies |lambda| / 2 pi in Hz (undamped frequencies for ``method="undamped"``).
    damping : ndarray, shape (n_modes,)
        Damping ratios (-Re lambda / |lambda| for exact modes; first-order energy estimate otherwise).
    shapes : ndarray, shape (n_dof, n_modes)
        Mode shapes at the generalized coordinates: real and mass-normalized for ``undamped`` and
        ``first-order``; complex, scaled so the largest component is 1, for ``exact``.
    poles : ndarray, shape (n_modes,)
        Complex poles in rad/s (upper half plane).
    dofs : tuple of str
        Labels of the generalized coordinates.
    method : str
        ``"undamped"``, ``"first-order"`` or ``"exact"``.
    rigid : ndarray of bool
        True for rigid-body (zero-frequency) modes.
    """

    frequency: NDArray[np.float64]
    damping: NDArray[np.float64]
    shapes: NDArray[Any]
    poles: NDArray[np.complex128]
    dofs: tuple[str, ...]
    method: str
    rigid: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool))

    @property
    def n_modes(self) -> int:
        return int(self.frequency.shape[0])

    @property
    def omega(self) -> NDArray[np.float64]:
        """Natural frequencies in rad/s."""
        return 2 * np.pi * self.frequency

    def dominant_dofs(self, mass: NDArray[np.float64]) -> NDArray[np.intp]:
        """Per mode, the index in :attr:`dofs` of the DOF holding the largest share of its kinetic energy.

        The method form of :func:`dominant_dofs`, on these mode shapes.

        Parameters
        ----------
        mass : ndarray, shape (n_dof, n_dof)
            Mass matrix of the system the modes belong to (kg, kg m^2 on rotations).

        Returns
        -------
        ndarray of int, shape (n_modes,)
        """
        return dominant_dofs(mass, self.shapes)

    def to_dict(self) -> dict[str, Any]:
        modes = []
        for r in range(self.n_modes):
            shape = self.shapes[:, r]
            entry: dict[str, Any] = {
                "frequency": float(self.frequency[r]),
                "damping": float(self.damping[r]),
                "shape": {d: float(np.real(v)) for d, v in zip(self.dofs, shape, strict=True)},
            }
            if np.iscomplexobj(self.shapes):
                entry["shape_imag"] = {d: float(np.imag(v)) for d, v in zip(self.dofs, shape, strict=True)}
            if self.rigid.size and self.rigid[r]:
                entry["rigid"] = True
            modes.append(entry)
        return {"method": self.method, "dofs": list(self.dofs), "modes": modes}


def dominant_dofs(mass: NDArray[np.float64], shapes: NDArray[Any]) -> NDArray[np.intp]:
    """Per mode, the DOF holding the largest share of its kinetic energy, ``Re(conj(phi_i) (M phi)_i)``.

    Unlike the largest shape entry, this compares translations (m) and rotations (rad) in one unit (J), so a
    mode is named after the coordinate that carries it whatever the units and scaling of its shape.

    Parameters
    ----------
    mass : ndarray, shape (n_dof, n_dof)
        Mass matrix (kg on translations, kg m^2 on rotations).
    shapes : ndarray, shape (n_dof, n_modes)
        Mode shapes, one column per mode, real or complex (m or rad per unit modal coordinate; any scaling).

    Returns
    -------
    ndarray of int, shape (n_modes,)
        For each mode, the row of ``shapes`` (index of the DOF) with the largest kinetic energy.

    Raises
    ------
    DataError
        If ``mass`` is not square or its size differs from the number of rows of ``shapes``.

    Examples
    --------
    The second mode's largest entry is the translation, but most of its energy is in the rotation:

    >>> import numpy as np
    >>> from cappe.systems import dominant_dofs
    >>> mass = np.diag([1.0, 100.0])                    # kg and kg m^2
    >>> shapes = np.array([[1.0, 1.0], [0.05, -0.5]])   # m and rad; one column per mode
    >>> dominant_dofs(mass, shapes)
    array([0, 1])
    """
    phi = np.asarray(shapes)
    m = np.asarray(mass)
    if m.ndim != 2 or m.shape[0] != m.shape[1] or phi.ndim != 2 or phi.shape[0] != m.shape[0]:
        msg = (f"dominant_dofs needs a square mass matrix (n_dof, n_dof) and shapes (n_dof, n_modes); "
               f"got mass {m.shape} and shapes {phi.shape}")
        raise DataError(msg)
    energy = np.real(np.conj(phi) * (m @ phi))
    dominant: NDArray[np.intp] = np.argmax(energy, axis=0)
    return dominant


@dataclass(frozen=True)
class ModalDataSet:
    """Modes identified (or simulated) at one axis position.

    Attributes
    ----------
    position : dict
        Axis values, e.g. ``{"z": 0.135}`` (m); empty for a model without axes.
    frequency : ndarray, shape (n_modes,)
        Natural frequencies in Hz.
    damping : ndarray, shape (n_modes,)
        Damping ratios.
    shapes : ndarray of complex, shape (n_sensors, n_modes)
        Mode shapes at the sensors, one mode per column.
    frequency_std, damping_std, shape_std : ndarray, shape (n_modes,), optional
        Standard deviations estimated from the data (``cappe extract-modes``): of each frequency (Hz), each
        damping ratio, and of each component of a mode's shape (real and imaginary part alike, in the units of
        ``shapes``). None where unknown.
    """

    position: dict[str, float]
    frequency: NDArray[np.float64]
    damping: NDArray[np.float64]
    shapes: NDArray[np.complex128]
    frequency_std: NDArray[np.float64] | None = None
    damping_std: NDArray[np.float64] | None = None
    shape_std: NDArray[np.float64] | None = None

    @property
    def n_modes(self) -> int:
        return int(self.frequency.size)

    @property
    def poles(self) -> NDArray[np.complex128]:
        """Poles ``-zeta omega + 1j omega sqrt(1 - zeta^2)`` in rad/s (omega = 2 pi f)."""
        w = 2 * np.pi * self.frequency
        z = self.damping
        return np.asarray(-z * w + 1j * w * np.sqrt(np.clip(1 - z**2, 0, None)), dtype=complex)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "position": dict(self.position),
            "frequency": self.frequency.tolist(),
            "damping": self.damping.tolist(),
            "shape_re": self.shapes.real.T.tolist(),
            "shape_im": self.shapes.imag.T.tolist(),
        }
        for name in STD_FIELDS:
            value = getattr(self, name)
            if value is not None:
                out[name] = np.asarray(value, dtype=float).tolist()
        return out


@dataclass(frozen=True)
class ModalData:
    """Modal data at one or more axis positions, all at the same sensor channels.

    Read and written by :mod:`cappe.io` (``read_modal_data`` / ``write_modal_data``, UFF 55); ``to_dict`` is the
    ``"cappe.modal/1"`` document.

    Attributes
    ----------
    sensors : tuple of str
        Sensor channel labels ``"node:direction"``, one per row of every set's ``shapes``.
    sets : tuple of ModalDataSet
        The modes at each axis position.
    source : str
        Where the data came from (a file name), for messages; empty when built in memory.

    Examples
    --------
    >>> import numpy as np
    >>> data = ModalData(("n1:x",), (ModalDataSet({}, np.array([10.0]), np.array([0.01]), np.ones((1, 1), complex)),))
    >>> data.to_dict()["sets"][0]["frequency"]
    [10.0]
    """

    sensors: tuple[str, ...]
    sets: tuple[ModalDataSet, ...] = field(default=())
    source: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {"format": MODAL_FORMAT, "sensors": list(self.sensors), "sets": [s.to_dict() for s in self.sets]}
