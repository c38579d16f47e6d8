"""Global sensitivity of a model's agreement with reference modes (paper section 2.2-2.3.1).

One output per reference mode x axis position x criterion: the MACXP between the reference mode and the
best-matching model mode (the MACXP both measures the agreement and finds the mode, paper eq. 4), the
squared natural damping difference NDD^2 of that pair (eq. 5), and the model mode's frequency and damping
ratio. Each parameter sample is evaluated once per position by the batched modal engine and serves every
output; the Sobol indices of all outputs come from one vectorized analysis.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from cappe._rng import RandomLike
from cappe.correlate import macxp_batch
from cappe.exceptions import DataError, ModelError
from cappe.modal import ModalBatch, ModalEngine
from cappe.model.numeric import NumericModel
from cappe.model.structure import Structure
from cappe.parallel import Executor
from cappe.sensitivity._plots import sobol_plot
from cappe.sensitivity._sobol import SobolResult, sobol_indices
from cappe.systems.modal import ModalData, ModalDataSet

__all__ = ["CRITERIA", "ModelSobolResult", "model_sobol"]

Array = NDArray[np.float64]
#: Outputs computed per reference mode and position.
CRITERIA = ("macxp", "ndd2", "frequency", "damping")


@dataclass(frozen=True)
class ModelSobolResult:
    """Sobol indices of model outputs per reference mode, axis position and criterion.

    Attributes
    ----------
    sobol : SobolResult
        Indices, one row per output (``output_names`` like ``"macxp:mode3@z=0.06"``).
    criteria : tuple of str
        Criterion of each output (``macxp``, ``ndd2``, ``frequency``, ``damping``).
    modes : tuple of int
        Reference mode of each output (1-based, as in the paper's figures).
    positions : tuple of dict
        Axis position of each output.
    reference_frequency : ndarray, shape (n_outputs,)
        Frequency (Hz) of the output's reference mode.
    """

    sobol: SobolResult
    criteria: tuple[str, ...]
    modes: tuple[int, ...]
    positions: tuple[dict[str, float], ...]
    reference_frequency: Array

    @property
    def names(self) -> tuple[str, ...]:
        return self.sobol.names

    def significant(self, threshold: float = 0.01, *, by: str = "ST") -> dict[str, tuple[str, ...]]:
        """Parameters whose index exceeds ``threshold`` for each output (the paper uses ST > 1 %).

        Parameters
        ----------
        threshold : float
            Sobol' index above which a parameter is significant (dimensionless, 0.01 = 1 %).
        by : {"ST", "S1"}
            Total or first-order index.

        Returns
        -------
        dict
            ``{output name: parameter names}``, largest index first.
        """
        values = self.sobol.ST if by == "ST" else self.sobol.S1
        out = {}
        for o, name in enumerate(self.sobol.output_names):
            order = np.argsort(-np.nan_to_num(values[o], nan=-np.inf), kind="stable")
            out[name] = tuple(self.sobol.names[j] for j in order if values[o, j] > threshold)
        return out

    def to_dataframe(self) -> pd.DataFrame:
        """Long table (output, parameter, S1, S1_conf, ST, ST_conf) with criterion, mode and position columns."""
        frame = self.sobol.to_dataframe()
        index = {name: i for i, name in enumerate(self.sobol.output_names)}
        rows = frame["output"].map(index).to_numpy()
        frame["criterion"] = np.array(self.criteria, dtype=object)[rows]
        frame["mode"] = np.array(self.modes)[rows]
        frame["position"] = [self.positions[i] for i in rows]
        return frame

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": "cappe.sensitivity/1",
            "method": "sobol",
            "outputs": [
                {"name": name, "criterion": c, "mode": m, "position": dict(p), "reference_frequency": float(f)}
                for name, c, m, p, f in zip(self.sobol.output_names, self.criteria, self.modes, self.positions,
                                            self.reference_frequency, strict=True)
            ],
            "sobol": self.sobol.to_dict(),
        }

    def plot(self, path: str | Path, *, outputs: Sequence[str] | None = None, top: int = 10) -> Path:
        """S1 and ST bars with confidence whiskers, ``top`` parameters per output (paper Fig. 5).

        Parameters
        ----------
        path : str or Path
            Image file to write (format from the extension: .png, .svg, .pdf ...).
        outputs : sequence of str, optional
            Output names, one panel each (default the first six).
        top : int
            Parameters per panel, largest ST first.

        Returns
        -------
        Path
            ``path``.
        """
        return sobol_plot(self.sobol, path, outputs=outputs, top=top)


def _position_label(position: Mapping[str, float]) -> str:
    return ",".join(f"{k}={v:g}" for k, v in position.items()) or "-"


def _outputs_for(batch: ModalBatch, data_set: ModalDataSet, criteria: Sequence[str]) -> Array:
    """(B, n_criteria * m_ref) outputs of one position, criterion-major per reference mode."""
    freq, zeta = batch.frequency, batch.damping
    poles = batch.first_order_poles if batch.poles is None else batch.poles
    shapes = batch.shapes if batch.complex_shapes is None else batch.complex_shapes
    valid = (freq > 0) & np.isfinite(poles)
    safe_poles = np.where(valid, poles, 1j)
    # every model mode against every reference mode: (B, m_ref, m)
    values = macxp_batch(shapes, safe_poles, data_set.shapes, data_set.poles)
    values = np.where(valid[:, None, :], values, -1.0)
    best = np.argmax(values, axis=2)  # (B, m_ref)
    chosen = np.maximum(np.take_along_axis(values, best[:, :, None], axis=2)[:, :, 0], 0.0)
    f = np.take_along_axis(freq, best, axis=1)
    z = np.take_along_axis(zeta, best, axis=1)
    columns = {
        "macxp": chosen,
        "ndd2": ((z - data_set.damping) / data_set.damping) ** 2,
        "frequency": f,
        "damping": z,
    }
    # order: mode-major, criteria within each mode
    return np.stack([columns[c] for c in criteria], axis=2).reshape(freq.shape[0], -1)


def model_sobol(
    model: NumericModel | Structure,
    reference: ModalData,
    *,
    parameters: Sequence[str] | None = None,
    bounds: ArrayLike | None = None,
    n: int = 1024,
    rng: RandomLike = None,
    criteria: Sequence[str] = CRITERIA,
    exact: bool = False,
    n_workers: int | None = None,
    chunk_size: int = 64,
    n_resamples: int = 100,
    executor: Executor | str | None = None,
    progress: bool = False,
) -> ModelSobolResult:
    """Sobol indices of MACXP, NDD^2, frequency and damping for every reference mode at every position.

    Parameters
    ----------
    model : NumericModel or Structure
    reference : ModalData
        Reference modes at one or more positions (e.g. from an experimental modal analysis or a simulation).
    parameters : sequence of str, optional
        Parameters varied (default: those marked ``unknown`` in the model); the others stay at nominal.
    bounds : array (D, 2), optional
        Ranges of the varied parameters (default: their bounds in the model).
    n : int
        Base sample size (power of two); the model runs ``n * (D + 2)`` times per position.
    rng : int, Generator or None
        Seed of the Sobol sequence scrambling and the bootstrap.
    criteria : sequence of str
        Subset of ``("macxp", "ndd2", "frequency", "damping")``.
    exact : bool
        Use exact complex modes of the model (default: undamped real shapes with first-order poles, which
        is the light-damping assumption A1 of the paper and several times faster).
    n_workers, chunk_size : int
        Parallelism and memory bound of the modal engine. Results do not depend on them. The default chunk of
        64 samples keeps a chunk's (chunk, n_dof, n_dof) temporaries small (better cache reuse, far fewer fresh
        pages mapped per chunk): measured 5-10 % faster than 256 on the 45-DOF machine tool.
    n_resamples : int
        Bootstrap resamples for the confidence intervals.
    executor : Executor, str or None
        Where the model evaluations run (see :class:`cappe.parallel.Executor`; default threads).
    progress : bool
        Progress bar.

    Examples
    --------
    >>> from cappe.model import load_model
    >>> from cappe.modal import ModalEngine
    >>> rig = load_model("builtin:two-mass-rig")
    >>> ref = ModalEngine(rig, sensors=["n1:x", "n2:x"]).modal_data()
    >>> res = model_sobol(rig, ref, parameters=["m1", "k11", "c11"], n=64, rng=0, criteria=["frequency"])
    >>> res.significant(0.1)["frequency:mode2@-"]    # the mass-1 mode
    ('m1', 'k11')
    """
    criteria = tuple(criteria)
    unknown_criteria = [c for c in criteria if c not in CRITERIA]
    if unknown_criteria or not criteria:
        msg = f"criteria must be a non-empty subset of {CRITERIA}; got {list(criteria)}"
        raise ModelError(msg)
    nm = model if isinstance(model, NumericModel) else NumericModel(model)
    structure = nm.structure
    names = list(parameters) if parameters is not None else [p.name for p in structure.parameters if p.unknown]
    if not names:
        msg = f"model '{structure.name}' marks no parameter unknown; name the parameters to vary"
        raise ModelError(msg)
    for name in names:
        if name not in nm.parameter_names:
            msg = f"unknown parameter {name!r} for model '{structure.name}'; known: {', '.join(nm.parameter_names)}"
            raise ModelError(msg)
    if bounds is None:
        missing = [name for name in names if structure.parameter(name).bounds is None]
        if missing:
            msg = f"parameters {missing} of model '{structure.name}' have no bounds; give bounds explicitly"
            raise ModelError(msg)
        bounds = np.array([structure.parameter(name).bounds for name in names], dtype=float)
    if "ndd2" in criteria:
        for k, data_set in enumerate(reference.sets):
            if np.any(data_set.damping <= 0):
                msg = f"reference set {k} has a zero damping ratio; NDD^2 divides by the reference damping"
                raise DataError(msg)
    engine = ModalEngine(nm, sensors=list(reference.sensors), chunk_size=chunk_size, n_workers=n_workers,
                         executor=executor)
    positions = [structure.resolve_position(s.position) for s in reference.sets]
    columns = [nm.parameter_names.index(name) for name in names]

    output_names: list[str] = []
    out_criteria: list[str] = []
    out_modes: list[int] = []
    out_positions: list[dict[str, float]] = []
    ref_freq: list[float] = []
    for data_set, position in zip(reference.sets, positions, strict=True):
        for r in range(data_set.n_modes):
            for c in criteria:
                output_names.append(f"{c}:mode{r + 1}@{_position_label(data_set.position)}")
                out_criteria.append(c)
                out_modes.append(r + 1)
                out_positions.append(dict(position))
                ref_freq.append(float(data_set.frequency[r]))

    def func(x: Array) -> Array:
        full = np.tile(nm.nominal, (x.shape[0], 1))
        full[:, columns] = x
        # the criteria are computed inside each chunk, on the executor's workers (not after it, serially)
        parts = [np.concatenate(engine.map(functools.partial(_outputs_for, data_set=data_set, criteria=criteria),
                                           full, position, exact=exact), axis=0)
                 for data_set, position in zip(reference.sets, positions, strict=True)]
        return np.concatenate(parts, axis=1)

    result = sobol_indices(func=func, bounds=bounds, names=names, n=n, rng=rng, n_resamples=n_resamples,
                           output_names=output_names, progress=progress, chunk_size=max(chunk_size * 128, 8192))
    return ModelSobolResult(result, tuple(out_criteria), tuple(out_modes), tuple(out_positions), np.array(ref_freq))
