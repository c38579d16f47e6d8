"""Result of a batched modal evaluation."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from cappe.systems.modal import ModalDataSet, ModalSet

__all__ = ["ModalBatch"]

Array = NDArray[np.float64]


#: Relative size of the real part that rounding leaves on the exact pole of an undamped mode (|Re| / |lambda|
#: ~ 1e-16 from the eigen solve; 1e-10 leaves room for ill-conditioned models and stays far from any real damping).
ROUNDING_DAMPING = 1e-10


def pole_damping(poles: NDArray[np.complex128]) -> Array:
    """Damping ratios ``-Re(lambda) / |lambda|`` of nonzero poles, with an undamped mode's rounding residue set to 0.

    An undamped mode's exact pole comes out with a real part of either sign at rounding level (-2.6e-17 on a model
    without damping in that direction); a modal data file must hold ratios in [0, 1), so that residue is 0, while a
    really negative ratio (an unstable mode, below -1e-10) is kept for the reader to refuse.
    """
    zeta = -poles.real / np.abs(poles)
    return np.where((zeta < 0) & (zeta > -ROUNDING_DAMPING), 0.0, zeta)


@dataclass(frozen=True)
class ModalBatch:
    """Modes of a model for a batch of parameter vectors at one axis position.

    Modes are ascending in frequency per sample unless they were tracked against a reference, in which
    case mode ``r`` of every sample is the one most similar to reference mode ``r`` (``mode_index`` says
    which ascending-frequency mode it was).

    Attributes
    ----------
    frequency : ndarray, shape (B, n_modes)
        Undamped natural frequencies in Hz.
    damping : ndarray, shape (B, n_modes)
        First-order modal damping ratios, viscous plus hysteretic (``phi^T C phi / 2 omega +
        phi^T H phi / 2 omega^2`` for mass-normalized ``phi``).
    shapes : ndarray, shape (B, n_sensors, n_modes)
        Mass-normalized real mode shapes at the sensor channels.
    sensors : tuple of str
        Channel labels (``"node:x"``) or DOF names.
    position : dict
        Axis position.
    parameters : ndarray, shape (B, n_params)
        The parameter vectors.
    parameter_names : tuple of str
    mode_index : ndarray of int, shape (B, n_modes)
        Ascending-frequency index of each reported mode.
    tracking_mac : ndarray, shape (B, n_modes), optional
        Mass-weighted MAC of each tracked mode with its reference mode.
    contributions : ndarray, shape (B, n_modes, n_sources), optional
        Share of each damping source in the damping ratio (they sum to ``damping``; paper eq. 12).
    damping_gradient : ndarray, shape (B, n_modes, n_params), optional
        ``d zeta / d p`` at fixed mode shapes and frequencies: the matrix Q of paper eq. 13 for damping
        parameters (exact where zeta is linear in the parameter).
    source_names, source_elements : tuple of str
        Names and elements of the damping sources.
    poles : ndarray of complex, shape (B, n_modes), optional
        Exact complex poles in rad/s (upper half plane) of the damped gyroscopic system, paired with the
        real modes; NaN where a real mode has no oscillatory counterpart (overdamped).
    complex_shapes : ndarray of complex, shape (B, n_sensors, n_modes), optional
        Exact complex mode shapes at the sensors, scaled so that ``phi^T M psi = 1`` with the real mode.
    full_shapes : ndarray, shape (B, n_dof, n_modes), optional
        Mass-normalized real shapes at all DOFs.
    dofs : tuple of str
        Names of the DOFs (rows of ``full_shapes``).
    """

    frequency: Array
    damping: Array
    shapes: Array
    sensors: tuple[str, ...]
    position: dict[str, float]
    parameters: Array
    parameter_names: tuple[str, ...]
    mode_index: NDArray[np.intp]
    tracking_mac: Array | None = None
    contributions: Array | None = None
    damping_gradient: Array | None = None
    source_names: tuple[str, ...] = ()
    source_elements: tuple[str, ...] = ()
    poles: NDArray[np.complex128] | None = None
    complex_shapes: NDArray[np.complex128] | None = None
    full_shapes: Array | None = None
    dofs: tuple[str, ...] = field(default=())

    @property
    def n_samples(self) -> int:
        return int(self.frequency.shape[0])

    @property
    def n_modes(self) -> int:
        return int(self.frequency.shape[1])

    @property
    def omega(self) -> Array:
        """Natural frequencies in rad/s."""
        return 2 * np.pi * self.frequency

    @property
    def first_order_poles(self) -> NDArray[np.complex128]:
        """Poles ``-zeta omega + 1j omega sqrt(1 - zeta^2)`` of the first-order damping model (rad/s)."""
        w, z = self.omega, self.damping
        return np.asarray(-z * w + 1j * w * np.sqrt(np.clip(1 - z**2, 0, None)), dtype=complex)

    def element_contributions(self) -> tuple[tuple[str, ...], Array]:
        """Damping contributions summed per element: names and (B, n_modes, n_elements)."""
        if self.contributions is None:
            msg = "damping contributions were not computed; evaluate with contributions=True"
            raise ValueError(msg)
        names = tuple(dict.fromkeys(self.source_elements))
        out = np.zeros((*self.contributions.shape[:2], len(names)))
        for j, element in enumerate(self.source_elements):
            out[:, :, names.index(element)] += self.contributions[:, :, j]
        return names, out

    def modal_set(self, sample: int = 0) -> ModalSet:
        """The modes of one sample as a :class:`ModalSet` (shapes at the sensors).

        Parameters
        ----------
        sample : int
            Row of the batch.

        Returns
        -------
        ModalSet
            Exact modes when they were computed, else the real (first-order) ones.
        """
        if self.poles is not None and self.complex_shapes is not None:
            poles = self.poles[sample]
            freq = np.abs(poles) / (2 * np.pi)
            zeta = -poles.real / np.where(np.abs(poles) > 0, np.abs(poles), 1.0)
            return ModalSet(freq, zeta, self.complex_shapes[sample], poles, self.sensors, "exact",
                            self.frequency[sample] == 0)
        return ModalSet(self.frequency[sample], self.damping[sample], self.shapes[sample],
                        self.first_order_poles[sample], self.sensors, "first-order", self.frequency[sample] == 0)

    def data_set(self, sample: int = 0) -> ModalDataSet:
        """One sample's modes as a :class:`cappe.systems.ModalDataSet` (exact modes when computed).

        Modes without an exact oscillatory counterpart (rigid-body or overdamped) are left out.

        Parameters
        ----------
        sample : int
            Row of the batch.

        Returns
        -------
        ModalDataSet
            Frequencies in Hz, damping ratios and shapes at the sensors, at the batch's position.
        """
        if self.poles is not None and self.complex_shapes is not None:
            poles = self.poles[sample]
            keep = np.isfinite(poles) & (np.abs(poles) > 0)
            w = np.abs(poles[keep])
            return ModalDataSet(dict(self.position), w / (2 * np.pi), pole_damping(poles[keep]),
                                self.complex_shapes[sample][:, keep])
        keep = self.frequency[sample] > 0
        return ModalDataSet(dict(self.position), self.frequency[sample][keep], self.damping[sample][keep],
                            self.shapes[sample][:, keep].astype(complex))

    def to_dataframe(self) -> pd.DataFrame:
        """Long table: one row per sample and mode with frequency, damping and (if computed) exact pole."""
        b, m = self.frequency.shape
        data: dict[str, Any] = {
            "sample": np.repeat(np.arange(b), m),
            "mode": np.tile(np.arange(m), b),
            "frequency": self.frequency.ravel(),
            "damping": self.damping.ravel(),
            "mode_index": self.mode_index.ravel(),
        }
        if self.poles is not None:
            data["pole_real"] = self.poles.real.ravel()
            data["pole_imag"] = self.poles.imag.ravel()
        return pd.DataFrame(data)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "position": dict(self.position),
            "sensors": list(self.sensors),
            "parameter_names": list(self.parameter_names),
            "parameters": self.parameters.tolist(),
            "frequency": self.frequency.tolist(),
            "damping": self.damping.tolist(),
            "shapes": self.shapes.tolist(),
            "mode_index": self.mode_index.tolist(),
        }
        if self.poles is not None and self.complex_shapes is not None:
            out["poles_real"] = self.poles.real.tolist()
            out["poles_imag"] = self.poles.imag.tolist()
            out["shape_re"] = self.complex_shapes.real.tolist()
            out["shape_im"] = self.complex_shapes.imag.tolist()
        if self.contributions is not None:
            out["source_names"] = list(self.source_names)
            out["contributions"] = self.contributions.tolist()
        return out
