"""Modal models: natural frequencies, damping ratios and mode shapes."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["ModalSet"]


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
