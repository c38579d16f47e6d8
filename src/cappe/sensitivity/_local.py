"""Local sensitivities: normalized derivatives (thesis eq. 4.12), percentage tables (Table 5.3), modal cost
with analytic gradient, and two-parameter cost landscapes (Fig. 4.5)."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from cappe.exceptions import DataError, ModelError
from cappe.modal import ModalDerivatives, ModalEngine
from cappe.model.numeric import NumericModel, ParamsLike
from cappe.model.structure import Structure
from cappe.sensitivity._plots import landscape_plot
from cappe.systems.modal import ModalData

__all__ = [
    "CostLandscape",
    "ModalCost",
    "PercentageTable",
    "cost_landscape",
    "modal_sensitivity",
    "percentage_table",
]

Array = NDArray[np.float64]


def _engine(model: NumericModel | Structure | ModalEngine, **kwargs: Any) -> ModalEngine:
    return model if isinstance(model, ModalEngine) else ModalEngine(model, **kwargs)


def modal_sensitivity(
    model: NumericModel | Structure | ModalEngine,
    params: ParamsLike = None,
    position: Mapping[str, float] | None = None,
    *,
    n_modes: int | None = None,
) -> ModalDerivatives:
    """Analytic sensitivities of natural frequencies and damping ratios to every parameter.

    ``result.relative()`` gives thesis eq. 4.12, ``(1/Q) dQ/dp``; ``result.normalized()`` the dimensionless
    ``(p/Q) dQ/dp`` (per cent change of Q per per cent change of p).

    Parameters
    ----------
    model : NumericModel, Structure or ModalEngine
        The model (an engine's model is used with the DOFs as sensors).
    params : array (n_params,), mapping or None
        One parameter vector (SI; default nominal).
    position : mapping or None
        Axis position in m or rad.
    n_modes : int, optional
        Number of modes (lowest first; default all).

    Returns
    -------
    ModalDerivatives

    Examples
    --------
    >>> from cappe.model import load_model
    >>> s = modal_sensitivity(load_model("builtin:two-mass-rig"))
    >>> freq, damp = s.normalized()
    >>> float(damp[1, s.parameter_names.index("c11")].round(3))  # mass-1 mode damped by its own beam
    0.999
    """
    engine = _engine(model, n_modes=n_modes, sensors="dofs")
    return engine.derivatives(params, position)


@dataclass(frozen=True)
class PercentageTable:
    """Per cent changes of natural frequencies and damping ratios for +-x % parameter changes (Table 5.3).

    Attributes
    ----------
    percent : float
        Size of the parameter changes in per cent.
    frequency, damping : ndarray, shape (n_modes,)
        Nominal modes (Hz, ratio), ascending in frequency.
    parameters : tuple of str
        Parameter of each row.
    change_percent : ndarray, shape (n_rows,)
        Signed change of the row's parameter (+x, -x).
    frequency_change_percent, damping_change_percent : ndarray, shape (n_rows, n_modes)
        Changes of each mode (tracked by MAC, so a mode keeps its identity even if the order changes).
    position : dict
    """

    percent: float
    frequency: Array
    damping: Array
    parameters: tuple[str, ...]
    change_percent: Array
    frequency_change_percent: Array
    damping_change_percent: Array
    position: dict[str, float]

    def to_dict(self) -> dict[str, Any]:
        return {
            "percent": self.percent,
            "position": dict(self.position),
            "modes": [{"frequency": float(f), "damping": float(z)} for f, z in
                      zip(self.frequency, self.damping, strict=True)],
            "rows": [
                {
                    "parameter": name,
                    "change_percent": float(change),
                    "frequency_change_percent": self.frequency_change_percent[i].tolist(),
                    "damping_change_percent": self.damping_change_percent[i].tolist(),
                }
                for i, (name, change) in enumerate(zip(self.parameters, self.change_percent, strict=True))
            ],
        }

    def to_dataframe(self) -> pd.DataFrame:
        """Wide table: parameter, change, then ``f1 %`` ... and ``zeta1 %`` ... columns."""
        data: dict[str, Any] = {"parameter": list(self.parameters), "change_percent": self.change_percent}
        for r in range(self.frequency.size):
            data[f"f{r + 1} %"] = self.frequency_change_percent[:, r]
        for r in range(self.frequency.size):
            data[f"zeta{r + 1} %"] = self.damping_change_percent[:, r]
        return pd.DataFrame(data)

    def to_text(self, decimals: int = 1) -> str:
        """The table as text, in the layout of thesis Table 5.3.

        Parameters
        ----------
        decimals : int
            Decimals of the per cent changes.

        Returns
        -------
        str
        """
        m = self.frequency.size
        head = ["parameter", "change"] + [f"f{r + 1} %" for r in range(m)] + [f"zeta{r + 1} %" for r in range(m)]
        lines = ["  ".join(f"{h:>9}" for h in head)]
        for i, name in enumerate(self.parameters):
            cells = [f"{name:>9}", f"{self.change_percent[i]:>+8.0f}%"]
            cells += [f"{v:>+9.{decimals}f}" for v in self.frequency_change_percent[i]]
            cells += [f"{v:>+9.{decimals}f}" for v in self.damping_change_percent[i]]
            lines.append("  ".join(cells))
        return "\n".join(lines)


def percentage_table(
    model: NumericModel | Structure | ModalEngine,
    params: ParamsLike = None,
    position: Mapping[str, float] | None = None,
    *,
    percent: float = 10.0,
    parameters: Sequence[str] | None = None,
    n_modes: int | None = None,
) -> PercentageTable:
    """Per cent changes of frequencies and damping ratios for +percent and -percent parameter changes.

    All ``2 * n_parameters`` perturbed models are evaluated in one batch; each perturbed mode is tracked to
    the nominal mode it came from (mass-weighted MAC).

    Parameters
    ----------
    model : NumericModel, Structure or ModalEngine
        The model (an engine's model is used with the DOFs as sensors).
    params : array (n_params,), mapping or None
        One parameter vector (SI; default nominal).
    position : mapping or None
        Axis position in m or rad.
    percent : float
        Parameter change in per cent, 0 < percent < 100.
    parameters : sequence of str, optional
        Parameters to change (default all).
    n_modes : int, optional
        Number of modes (lowest first; default all).

    Returns
    -------
    PercentageTable

    Raises
    ------
    ModelError
        ``percent`` is out of range, ``params`` is a batch or a parameter is unknown.

    Examples
    --------
    >>> from cappe.model import load_model
    >>> table = percentage_table(load_model("builtin:two-mass-rig"), parameters=["m1"])
    >>> table.frequency_change_percent.round(1)   # the mass-1 mode is mode 2
    array([[-0.1, -4.6],
           [ 0.1,  5.3]])
    """
    if not np.isfinite(percent) or not 0 < percent < 100:
        msg = f"percent must lie in (0, 100); got {percent!r}"
        raise ModelError(msg)
    engine = _engine(model, n_modes=n_modes, sensors="dofs")
    nm = engine.model
    base = nm.vector(params)
    if base.ndim != 1:
        msg = "percentage_table takes a single parameter vector"
        raise ModelError(msg)
    names = list(parameters) if parameters is not None else list(nm.parameter_names)
    for name in names:
        if name not in nm.parameter_names:
            msg = f"unknown parameter {name!r} for model '{nm.structure.name}'; known: {', '.join(nm.parameter_names)}"
            raise ModelError(msg)
    reference = engine.reference(base, position)
    nominal = engine.evaluate(base, position, track=reference)
    batch = np.tile(base, (2 * len(names), 1))
    changes = np.tile([percent, -percent], len(names))
    for i, name in enumerate(names):
        j = nm.parameter_names.index(name)
        batch[2 * i, j] *= 1 + percent / 100
        batch[2 * i + 1, j] *= 1 - percent / 100
    moved = engine.evaluate(batch, position, track=reference)
    f0, z0 = nominal.frequency[0], nominal.damping[0]
    with np.errstate(divide="ignore", invalid="ignore"):
        df = np.where(f0 > 0, 100 * (moved.frequency - f0) / f0, 0.0)
        dz = np.where(z0 > 0, 100 * (moved.damping - z0) / z0, 0.0)
    return PercentageTable(float(percent), f0, z0, tuple(np.repeat(names, 2).tolist()), changes, df, dz,
                           nominal.position)


class ModalCost:
    """Modal residual cost against reference modes, batched, with an analytic gradient.

    ``Q(p) = sum over positions and reference modes r of
    w_f ((f_r - f_ref,r) / f_ref,r)^2 + w_z ((zeta_r - zeta_ref,r) / zeta_ref,r)^2 + w_s (1 - MAC_r)``,
    where model mode r is the one with the largest MAC with reference mode r (at the sensors of the
    reference data). The cost behind thesis Fig. 4.5-style landscapes and modal updating.

    Parameters
    ----------
    model : NumericModel, Structure or ModalEngine
    reference : ModalData
        Reference modes; its sensor labels must exist in the model.
    weights : (float, float, float)
        ``w_f, w_z, w_s``.
    """

    def __init__(
        self,
        model: NumericModel | Structure | ModalEngine,
        reference: ModalData,
        *,
        weights: tuple[float, float, float] = (1.0, 1.0, 1.0),
    ) -> None:
        nm = model.model if isinstance(model, ModalEngine) else model
        self.engine = ModalEngine(nm, sensors=list(reference.sensors))
        self.reference = reference
        self.weights = weights
        for k, data_set in enumerate(reference.sets):
            if np.any(data_set.damping <= 0) and weights[1]:
                msg = f"reference set {k} has a zero damping ratio; the damping residual needs damping > 0"
                raise DataError(msg)

    def _pairing(self, shapes: Array, ref_shapes: NDArray[Any]) -> tuple[NDArray[np.intp], Array]:
        """Best-MAC model mode for each reference mode, per sample: indices and MAC (B, m_ref).

        The MAC of :func:`cappe.correlate.mac`, batched; a model mode invisible at the sensors gets MAC 0.
        """
        cross = np.abs(np.conj(ref_shapes).T @ shapes) ** 2  # (B, m_ref, m_model)
        norms = np.sum(np.abs(ref_shapes) ** 2, axis=0)[:, None] * np.sum(shapes**2, axis=1)[:, None, :]
        macs = np.divide(cross, norms, out=np.zeros_like(cross), where=norms > 0)
        index = np.argmax(macs, axis=2)
        return index, np.take_along_axis(macs, index[:, :, None], axis=2)[:, :, 0]

    def __call__(self, params: ParamsLike) -> Array:
        """Cost of one parameter vector (shape ()) or a batch (B,)."""
        p = self.engine.model.vector(params)
        pb = p if p.ndim == 2 else p[None, :]
        total = np.zeros(pb.shape[0])
        w_f, w_z, w_s = self.weights
        for data_set in self.reference.sets:
            batch = self.engine.evaluate(pb, data_set.position)
            index, values = self._pairing(batch.shapes, data_set.shapes)
            f = np.take_along_axis(batch.frequency, index, axis=1)
            z = np.take_along_axis(batch.damping, index, axis=1)
            total += w_f * np.sum(((f - data_set.frequency) / data_set.frequency) ** 2, axis=1)
            if w_z:
                total += w_z * np.sum(((z - data_set.damping) / data_set.damping) ** 2, axis=1)
            total += w_s * np.sum(1 - values, axis=1)
        return total if p.ndim == 2 else total[0]

    def gradient(self, params: ParamsLike = None) -> Array:
        """Analytic gradient ``dQ/dp`` (n_params,) from the modal derivatives.

        Parameters
        ----------
        params : array (n_params,), mapping or None
            One parameter vector (SI; default nominal).

        Returns
        -------
        ndarray, shape (n_params,)
            ``dQ/dp`` per SI unit of each parameter.
        """
        p = self.engine.model.vector(params)
        grad = np.zeros(p.size)
        w_f, w_z, w_s = self.weights
        for data_set in self.reference.sets:
            d = self.engine.derivatives(p, data_set.position)
            index, _ = self._pairing(d.shapes[None], data_set.shapes)
            idx = index[0]
            f, z = d.frequency[idx], d.damping[idx]
            grad += w_f * 2 * ((f - data_set.frequency) / data_set.frequency**2) @ d.d_frequency[idx]
            if w_z:
                grad += w_z * 2 * ((z - data_set.damping) / data_set.damping**2) @ d.d_damping[idx]
            a = d.shapes[:, idx]  # (n_s, m_ref) real model shapes
            x = data_set.shapes
            c = np.sum(np.conj(x) * a, axis=0)  # x^H a
            aa = np.sum(a * a, axis=0)
            xx = np.sum(np.abs(x) ** 2, axis=0)
            # dMAC/da = 2 Re(conj(c) conj(x)) / (aa xx) - 2 |c|^2 a / (aa^2 xx)
            dmac_da = 2 * np.real(np.conj(c) * np.conj(x)) / (aa * xx) - 2 * np.abs(c) ** 2 * a / (aa**2 * xx)
            grad -= w_s * np.einsum("sr,srp->p", dmac_da, d.d_shapes[:, idx, :])
        return grad


@dataclass(frozen=True)
class CostLandscape:
    """A cost evaluated on a grid of two parameters, the others fixed (thesis Fig. 4.5).

    Attributes
    ----------
    names : (str, str)
        The two parameters (x axis, y axis).
    x, y : ndarray
        Grid values of the two parameters.
    values : ndarray, shape (len(y), len(x))
        Cost at each grid point.
    base : ndarray, shape (n_params,)
        The parameter vector the other parameters are taken from.
    """

    names: tuple[str, str]
    x: Array
    y: Array
    values: Array
    base: Array

    @property
    def minimum(self) -> tuple[float, float, float]:
        """(x, y, cost) of the smallest grid value."""
        i, j = np.unravel_index(int(np.argmin(self.values)), self.values.shape)
        return float(self.x[j]), float(self.y[i]), float(self.values[i, j])

    def to_dict(self) -> dict[str, Any]:
        return {"names": list(self.names), "x": self.x.tolist(), "y": self.y.tolist(),
                "values": self.values.tolist(), "minimum": list(self.minimum)}

    def plot(self, path: str | Path, *, title: str = "", log: bool = True, levels: int = 30) -> Path:
        """Write a filled contour plot of the landscape (log10 of the cost by default) to ``path``.

        Parameters
        ----------
        path : str or Path
            Image file to write (format from the extension: .png, .svg, .pdf ...).
        title : str
            Figure title.
        log : bool
            Contour ``log10`` of the cost.
        levels : int
            Number of contour levels.

        Returns
        -------
        Path
            ``path``.
        """
        return landscape_plot(self, path, title, log=log, levels=levels)


def cost_landscape(
    func: Callable[[Array], Array],
    parameter_names: Sequence[str],
    base: Array,
    names: tuple[str, str],
    ranges: tuple[tuple[float, float], tuple[float, float]],
    *,
    n: tuple[int, int] = (41, 41),
) -> CostLandscape:
    """Evaluate a batched cost on a two-parameter grid.

    Parameters
    ----------
    func : callable
        Maps a batch of full parameter vectors (B, n_params) to costs (B,), e.g. a :class:`ModalCost`.
    parameter_names : sequence of str
        Names of the vector entries.
    base : ndarray, shape (n_params,)
        Values of the parameters not on the grid.
    names : (str, str)
        Parameters on the x and y axes.
    ranges : ((lo, hi), (lo, hi))
        Grid ranges.
    n : (int, int)
        Grid points along x and y.

    Examples
    --------
    >>> import numpy as np
    >>> land = cost_landscape(lambda p: (p[:, 0] - 1) ** 2 + (p[:, 1] - 2) ** 2, ["a", "b"], np.zeros(2),
    ...                       ("a", "b"), ((0, 2), (1, 3)), n=(5, 5))
    >>> land.minimum
    (1.0, 2.0, 0.0)
    """
    names_list = list(parameter_names)
    for name in names:
        if name not in names_list:
            msg = f"unknown parameter {name!r}; known: {', '.join(names_list)}"
            raise ModelError(msg)
    for name, (lo, hi) in zip(names, ranges, strict=True):
        if not lo < hi:
            msg = f"range of {name!r} must have lo < hi; got ({lo}, {hi})"
            raise ModelError(msg)
    x = np.linspace(*ranges[0], n[0])
    y = np.linspace(*ranges[1], n[1])
    xx, yy = np.meshgrid(x, y)
    batch = np.tile(np.asarray(base, dtype=float), (xx.size, 1))
    batch[:, names_list.index(names[0])] = xx.ravel()
    batch[:, names_list.index(names[1])] = yy.ravel()
    values = np.asarray(func(batch), dtype=float).reshape(yy.shape)
    return CostLandscape((names[0], names[1]), x, y, values, np.asarray(base, dtype=float))
