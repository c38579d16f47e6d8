"""Validation of an identified model against reference modes at one axis position (paper Tables 2-5, Fig. 7).

Modal criteria, per reference mode r paired with the model mode of largest MACXP (one-to-one assignment):

- ``macxp[r]``: MACXP (paper eq. 4) of the pair, from the model's exact complex modes by default;
- ``nfd[r] = |f_m - f_r| / f_r`` and ``ndd[r] = |zeta_m - zeta_r| / zeta_r`` (eq. 5 without the square;
  :func:`cappe.correlate.nfd`, :func:`cappe.correlate.ndd`).

FRF criteria, per frequency response function (output channel j, input channel k), over ``freq``:

- ``frac[j, k]``: the frequency response assurance criterion of the two FRFs (:func:`cappe.correlate.frac`);
- ``csf[j, k]``: the cross-signature scale factor of the single FRF (:func:`cappe.correlate.csf` with one output),
  ``2 |H_x H_a| / (|H_x|^2 + |H_a|^2)``, averaged over the frequency lines: 1 only where the amplitudes agree.

Outputs and inputs are the reference's sensor channels (``"node:x"``): a unit force at the sensor point along the
channel direction, the displacement response (receptance, m/N) along the output channel. Two definitions of the
two FRF sets, stated in ``frf_source``:

- ``"truth"`` (the reference was simulated from known parameters): both are the full model's receptances, at the
  true and at the identified parameters (all modes, viscous, hysteretic and gyroscopic terms);
- ``"measured FRFs"`` (no truth, measured FRFs at the position given): the measured FRFs at their own channels
  (model sensor channels after a sensor map), output quantities and lines up to 1.25 times the highest reference
  frequency, against the full model's FRFs there (all modes, residual effects included);
- ``"modal synthesis"`` (no truth, no measured FRFs): both are modal sums over the reference modes,
  ``H_jk = sum_r psi_jr psi_kr / (omega_r^2 - omega^2 + 2 i zeta_r omega_r omega)``, with the reference's shapes
  and with the paired model modes (exact complex modes with ``exact``, else the first-order ones), frequency
  ``|lambda| / 2 pi`` and damping ratio ``-Re lambda / |lambda|``. The reference's shapes must be mass-normalized
  (as ``cappe simulate`` writes them); where they are not (an extraction without driving points), each is scaled
  to its model partner's modal mass and ``notes`` says so: the criteria then test poles and shapes only. A modal
  synthesis leaves out the modes outside the reference's band and the residual terms of measured FRFs.

FRFs whose reference power ``sum_f |H|^2`` is below ``1e-10`` of the largest (zero by symmetry: an x force on a
symmetric structure seen in y) are left out (NaN), as FRAC and CSF of numerical noise mean nothing.

Statistics (``statistics()``) follow the paper: worst, the 5 % worst tail (5th percentile of the similarity
criteria FRAC, CSF, MACXP; 95th percentile of the error NDD), mean and median, over modes (MACXP, NDD) or over
FRFs (FRAC, CSF).
"""

from __future__ import annotations

import threading
import weakref
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cappe.correlate import ndd, nfd, pair_modes
from cappe.estimate._frf_refinement import model_frf
from cappe.exceptions import DataError
from cappe.modal import ModalEngine
from cappe.modal._engine import StateEigensystem
from cappe.model import NumericModel, Structure
from cappe.parallel import chunk_slices
from cappe.systems.dynamic_stiffness import frf_lines
from cappe.systems.frf import FRFData
from cappe.systems.mechanical import DERIVATIVE_ORDER
from cappe.systems.modal import ModalData, ModalDataSet

__all__ = ["ValidationResult", "find_set", "model_receptance", "summarize", "validate_identification"]

Array = NDArray[np.float64]
CArray = NDArray[np.complex128]

#: FRFs whose reference power is below this fraction of the largest are numerically zero and left out.
NEGLIGIBLE_POWER = 1e-10
#: Criteria where larger is better (their 5 % tail is the 5th percentile; the others' the 95th).
SIMILARITY = ("frac", "csf", "macxp")


@dataclass(frozen=True)
class ValidationResult:
    """Agreement of a model with reference modes (and FRFs) at one axis position.

    Attributes
    ----------
    position : dict
        Axis position.
    reference_frequency : ndarray, shape (m,)
        Reference natural frequencies (Hz).
    model_mode : ndarray of int, shape (m,)
        Model mode (ascending frequency, 0-based) paired with each reference mode.
    model_frequency : ndarray, shape (m,)
        Natural frequency of the paired model mode (Hz).
    reference_damping, model_damping : ndarray, shape (m,)
        Damping ratios of the reference modes and of their paired model modes (dimensionless).
    macxp, nfd, ndd : ndarray, shape (m,)
        MACXP, natural frequency difference and natural damping difference of each pair (dimensionless).
    macxp_matrix : ndarray, shape (n_model, m)
        MACXP of the lowest model modes (rows) with every reference mode (columns).
    freq : ndarray, shape (n_freq,)
        Frequency lines of the FRF criteria (Hz).
    outputs, inputs : tuple of str
        Channels of the FRFs.
    frac, csf : ndarray, shape (n_out, n_in)
        FRF criteria per output and input channel (NaN where the reference FRF is negligible).
    frf_source : str
        ``"truth"``, ``"measured FRFs"`` or ``"modal synthesis"`` (see the module notes).
    overlay : dict
        One FRF for plots: ``output``, ``input`` (the driving point with the largest response) and the arrays
        ``reference`` and ``model`` (complex, shape (n_freq,), m/N).
    notes : tuple of str
        What a user must know to read the FRF criteria (e.g. reference shapes that are not mass-normalized).
    """

    position: dict[str, float]
    reference_frequency: Array
    model_mode: NDArray[np.intp]
    model_frequency: Array
    reference_damping: Array
    model_damping: Array
    macxp: Array
    nfd: Array
    ndd: Array
    macxp_matrix: Array
    freq: Array
    outputs: tuple[str, ...]
    inputs: tuple[str, ...]
    frac: Array
    csf: Array
    frf_source: str
    overlay: Mapping[str, Any]
    notes: tuple[str, ...] = ()

    def values(self, criterion: str) -> Array:
        """The finite values of one criterion (``frac``, ``csf``, ``macxp``, ``ndd``, ``nfd``), flattened.

        Parameters
        ----------
        criterion : {"frac", "csf", "macxp", "ndd", "nfd"}
            The criterion.

        Returns
        -------
        ndarray, shape (n_finite,)
            Its finite values (dimensionless).

        Raises
        ------
        DataError
            ``criterion`` is not one of these.
        """
        if criterion not in ("frac", "csf", "macxp", "ndd", "nfd"):
            msg = f"criterion must be one of frac, csf, macxp, ndd, nfd; got {criterion!r}"
            raise DataError(msg)
        arr = np.asarray(getattr(self, criterion), dtype=float).ravel()
        return np.asarray(arr[np.isfinite(arr)], dtype=float)

    def statistics(self) -> dict[str, dict[str, float]]:
        """``{criterion: {"worst", "p5", "mean", "median"}}`` for FRAC, CSF, MACXP and NDD (fractions, not %).

        ``p5`` is the 5 % worst tail: the 5th percentile of FRAC, CSF and MACXP, the 95th of NDD.
        """
        return {c: summarize(self.values(c), larger_is_better=c in SIMILARITY) for c in ("frac", "csf", "macxp", "ndd")}

    def to_dict(self) -> dict[str, Any]:
        return {
            "position": dict(self.position),
            "statistics": self.statistics(),
            "frf_source": self.frf_source,
            "modes": {
                "reference_frequency": self.reference_frequency.tolist(),
                "model_mode": self.model_mode.tolist(),
                "model_frequency": self.model_frequency.tolist(),
                "reference_damping": self.reference_damping.tolist(),
                "model_damping": self.model_damping.tolist(),
                "macxp": self.macxp.tolist(),
                "nfd": self.nfd.tolist(),
                "ndd": self.ndd.tolist(),
            },
            "frf": {
                "outputs": list(self.outputs),
                "inputs": list(self.inputs),
                "band": [float(self.freq[0]), float(self.freq[-1])],
                "n_freq": int(self.freq.size),
                "frac": [[None if not np.isfinite(v) else float(v) for v in row] for row in self.frac],
                "csf": [[None if not np.isfinite(v) else float(v) for v in row] for row in self.csf],
                "overlay": {"output": self.overlay["output"], "input": self.overlay["input"]},
            },
        }


def summarize(values: ArrayLike, *, larger_is_better: bool) -> dict[str, float]:
    """Worst value, 5 % worst tail, mean and median of a criterion (NaN when there are no values).

    Parameters
    ----------
    values : array_like
        Values of the criterion, any shape; non-finite ones are left out.
    larger_is_better : bool
        True for correlations (FRAC, CSF, MACXP: worst is the minimum), False for errors (NFD, NDD).

    Returns
    -------
    dict
        ``{"worst", "p5", "mean", "median"}``; ``p5`` is the 5th (or 95th) percentile.

    Examples
    --------
    >>> summarize([0.9, 1.0, 0.8], larger_is_better=True)["worst"]
    0.8
    """
    v = np.asarray(values, dtype=float).ravel()
    v = v[np.isfinite(v)]
    if v.size == 0:
        nan = float("nan")
        return {"worst": nan, "p5": nan, "mean": nan, "median": nan}
    worst = float(v.min() if larger_is_better else v.max())
    tail = float(np.percentile(v, 5 if larger_is_better else 95))
    return {"worst": worst, "p5": tail, "mean": float(v.mean()), "median": float(np.median(v))}


def find_set(reference: ModalData, position: Mapping[str, float], model: NumericModel) -> int:
    """Index of the reference set at ``position`` (axis values compared to 1e-9 m); DataError naming the positions.

    Parameters
    ----------
    reference : ModalData
        Reference modes at one or more positions.
    position : mapping axis -> float
        The axis position sought (m or rad); axes not given take the model's defaults.
    model : NumericModel
        The model whose axes resolve the positions.

    Returns
    -------
    int
        Index into ``reference.sets``.

    Raises
    ------
    DataError
        No set is at ``position``.
    """
    wanted = model.position_vector(model.structure.resolve_position(position))
    for k, data_set in enumerate(reference.sets):
        have = model.position_vector(model.structure.resolve_position(data_set.position))
        if np.allclose(have, wanted, rtol=0, atol=1e-9):
            return k
    known = [dict(s.position) for s in reference.sets]
    msg = f"position {dict(position)} is not among the reference's positions {known}"
    raise DataError(msg)


#: Frequency lines per block of the FRF computations: (lines, n_out, n_in) blocks stay in the CPU caches.
_BLOCK_LINES = 24


def model_receptance(
    model: NumericModel,
    params: ArrayLike,
    position: Mapping[str, float] | None,
    freq: ArrayLike,
    outputs: Sequence[str],
    inputs: Sequence[str],
) -> CArray:
    """Receptance (m/N) between sensor channels of the full model: ``H[out, in, freq]``.

    ``H = S_out (K + i H + i omega (C + G) - omega^2 M)^-1 S_in^T``, where ``S`` are the sensor rows of the
    channels (a unit force at the sensor point along the channel's direction).

    Parameters
    ----------
    model : NumericModel
        The model.
    params : array_like, shape (n_params,)
        Full parameter vector (SI).
    position : mapping axis -> float or None
        Axis position (m or rad); None for the default.
    freq : array_like, shape (n_freq,)
        Frequencies in Hz.
    outputs, inputs : sequence of str
        Sensor channels (``"node:x"``) of the response and of the force.

    Returns
    -------
    ndarray of complex, shape (n_out, n_in, n_freq)
        Receptance in m/N (rad/N m for rotational channels).

    Examples
    --------
    >>> from cappe.model import load_model
    >>> nm = NumericModel(load_model("builtin:two-mass-rig"))
    >>> H = model_receptance(nm, nm.nominal, None, [0.0], ["n1:x"], ["n1:x"])
    >>> bool(np.isclose(H[0, 0, 0].real, np.linalg.inv(nm.matrices()["K"])[0, 0]))
    True
    """
    lines = _receptance_lines(model, np.asarray(params, dtype=float), position, freq, outputs, inputs)
    return np.ascontiguousarray(np.moveaxis(lines, 0, -1))


def _receptance_lines(model: NumericModel, params: Array, position: Mapping[str, float] | None, freq: ArrayLike,
                      outputs: Sequence[str], inputs: Sequence[str]) -> CArray:
    """:func:`model_receptance` laid out line-major, ``H[freq, out, in]`` (the layout the criteria stream)."""
    labels, rows = model.sensor_matrix(params, position)
    index = {lab: i for i, lab in enumerate(labels)}
    missing = [c for c in (*outputs, *inputs) if c not in index]
    if missing:
        msg = f"channels {sorted(set(missing))} are not sensor channels of model '{model.structure.name}'"
        raise DataError(msg)
    s_out = rows[[index[c] for c in outputs]]
    s_in_t = rows[[index[c] for c in inputs]].T  # (n, n_in)
    mats = model.matrices(params, position)
    omega = 2 * np.pi * np.asarray(freq, dtype=float)
    # Exact modal synthesis over all 2n state-space modes replaces a direct solve per line where it agrees with it:
    # on the three-axis machine (162 DOF, 600 lines, 117 x 117 channels, one BLAS thread, interleaved) one call
    # took 1.19-1.40 CPU s by direct solves and 0.81-0.88 s by the synthesis (the state matrix's eig, V^-1 B, the
    # sum over modes and the check), some 21 calls per `cappe identify`. The synthesis is not exact where the state
    # matrix is defective or its eigenvectors nearly so (rigid-body modes: a double zero pole; near-repeated
    # defective poles), nor on a pole; and its error is absolute, some 1e-11 of a line's largest |H|, where the
    # direct solve keeps every entry to ~1e-13 of itself: far above the highest pole, where cross FRFs fall 1e-13
    # below the line's largest, it is noise, and the line's CSF with it. Its own checks (_state_synthesis) and the
    # direct solve at a few lines (_synthesis_agrees) decide; any doubt takes the direct solve at every line.
    out = _state_synthesis(mats, omega, s_in_t, s_out)
    if out is not None and (omega.size == 0 or _synthesis_agrees(out, mats, omega, s_in_t, s_out)):
        return out
    if out is None:
        out = np.empty((omega.size, s_out.shape[0], s_in_t.shape[1]), dtype=complex)
    for s in chunk_slices(omega.size, _BLOCK_LINES):  # blocks of lines small enough for the CPU caches
        out[s] = frf_lines(mats, omega[s], s_in_t, s_out).H
    return out


#: Largest difference between the modal synthesis and the direct solve at a check line, relative to the line's
#: largest ``|H|``, for the synthesis to be taken (FRAC and the plotted FRFs). Measured on the three-axis machine
#: (three parameter vectors and positions, 600 lines to 625 Hz, 117 x 117 channels): 2e-10 at most over every line.
_SYNTHESIS_RTOL = 1e-8

#: Largest difference at a check line relative to the entry itself, over the FRFs the criteria keep (power above
#: ``NEGLIGIBLE_POWER``; the synthesis's power agrees to ~1e-6 of itself at that threshold): a relative error e
#: moves the line's CSF by e^2 / 2, 5e-9 here. Measured on the three-axis machine, 600 lines to 370-385 Hz (its
#: identification's validation band): 1e-6 at most over every line, 1.4e-7 at the check lines; to 1000 Hz 3e-5 at
#: the last line, to 6.4 kHz (all 162 modes) 6e6; the spindle at 200 rad/s, 200 lines to 2 kHz, 5e-5.
_SYNTHESIS_ENTRY_RTOL = 1e-4

#: Poles with ``|lambda|`` at most this fraction of the largest are taken as zero (rigid-body modes): a defective
#: double zero pole splits into two of about ``sqrt(eps |A|)``, some 1e-8 of the largest pole.
_ZERO_POLE = 1e-6


def _synthesis_agrees(lines: CArray, mats: Mapping[str, Array], omega: Array, s_in_t: Array, s_out: Array) -> bool:
    """Whether a modal synthesis ``lines`` (line-major) agrees with the direct solve within ``_SYNTHESIS_RTOL`` and
    ``_SYNTHESIS_ENTRY_RTOL`` at the first, the middle and the last line and the one of the largest ``|H|`` (nearest
    the sharpest resonance, where near-defective poles' errors show; the last is where FRFs have fallen furthest)."""
    n = lines.shape[0]
    peaks, power = np.empty(n), np.zeros(lines.shape[1:])
    for s in chunk_slices(n, _BLOCK_LINES):  # blocks of lines: no temporary of the FRFs' size
        size = np.abs(lines[s])
        peaks[s] = size.max(axis=(1, 2))
        power += np.square(size).sum(axis=0)
    check = np.unique(np.array([0, n // 2, n - 1, int(np.argmax(peaks))], dtype=np.intp))
    direct = frf_lines(mats, omega[check], s_in_t, s_out).H
    err = np.abs(lines[check] - direct)
    if np.any(err.max(axis=(1, 2)) > _SYNTHESIS_RTOL * np.abs(direct).max(axis=(1, 2))):
        return False
    kept = power > NEGLIGIBLE_POWER * power.max()
    return bool(np.all(err[:, kept] <= _SYNTHESIS_ENTRY_RTOL * np.abs(direct[:, kept])))


def _state_synthesis(mats: Mapping[str, Array], omega: Array, s_in_t: Array, s_out: Array) -> CArray | None:
    """``H[freq, out, in] = S_out V_x diag(1 / (i omega - lambda)) V^-1 [0; M^-1 S_in^T]`` over all 2n modes of the
    state matrix (``V_x``: the displacement rows of its eigenvectors ``V``), or None where it cannot be trusted:
    M or V singular, a pole numerically zero, a line on a pole (a value not finite)."""
    n = s_out.shape[1]
    try:
        minv = np.asarray(np.linalg.inv(mats["M"]), dtype=float)
    except np.linalg.LinAlgError:
        return None
    system = StateEigensystem.of({k: np.asarray(v)[None] for k, v in mats.items()}, minv[None])
    lam, vec = system.lam[0], system.vec[0]
    size = np.abs(lam)
    if not np.all(np.isfinite(lam)) or size.min() <= _ZERO_POLE * size.max():
        return None
    excitation = np.zeros((2 * n, s_in_t.shape[1]), dtype=complex)
    excitation[n:] = minv @ s_in_t
    try:
        modal_in = np.linalg.solve(vec, excitation)  # (2n, n_in)
    except np.linalg.LinAlgError:
        return None
    modal_out = s_out @ vec[:n]  # (n_out, 2n)
    out = np.empty((omega.size, s_out.shape[0], s_in_t.shape[1]), dtype=complex)
    with np.errstate(divide="ignore", invalid="ignore"):
        for s in chunk_slices(omega.size, _BLOCK_LINES):  # blocks of lines small enough for the CPU caches
            weight = 1.0 / (1j * omega[s, None] - lam[None, :])  # (lines, 2n)
            out[s] = (modal_out[None] * weight[:, None, :]) @ modal_in
    return out if np.all(np.isfinite(out)) else None


class _TruthReceptances:
    """The reference FRFs of a simulated reference (line-major), computed once for the validations that share
    them (the held-out position and every permuted-damping model compare against the same truth): the 4 most
    recent per model. The automated identification clears it (:meth:`cache_clear`) when its validations are done.

    The models are held weakly: on a Dask worker the model is the executor's copy (shipped once), which the worker
    drops when the executor closes; a cache that held it (an ``lru_cache`` keyed by the model did) kept the copy
    and its tens of MB of FRFs in the worker for as long as the worker lived.
    """

    KEPT = 4

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._frfs: weakref.WeakKeyDictionary[NumericModel, OrderedDict[tuple[Any, ...], CArray]] = (
            weakref.WeakKeyDictionary())

    def __call__(self, model: NumericModel, truth: bytes, position: tuple[tuple[str, float], ...], grid: bytes,
                 outputs: tuple[str, ...], inputs: tuple[str, ...]) -> CArray:
        key = (truth, position, grid, outputs, inputs)
        with self._lock:
            kept = self._frfs.setdefault(model, OrderedDict())
            out = kept.get(key)
            if out is not None:
                kept.move_to_end(key)
                return out
        out = _receptance_lines(model, np.frombuffer(truth), dict(position), np.frombuffer(grid), outputs, inputs)
        out.setflags(write=False)
        with self._lock:
            kept[key] = out
            while len(kept) > self.KEPT:
                kept.popitem(last=False)
        return out

    def __len__(self) -> int:
        """The FRFs kept, over all models."""
        with self._lock:
            return sum(len(kept) for kept in self._frfs.values())

    def cache_clear(self) -> None:
        """Forget every FRF kept."""
        with self._lock:
            self._frfs.clear()


_truth_receptance = _TruthReceptances()


def _line_criteria(h_mod: CArray, h_ref: CArray) -> tuple[Array, Array]:
    """FRAC and line-averaged CSF of every FRF ``[..., out, in]`` of line-major arrays ``(n_freq, ...)`` (NaN where
    the reference is negligible; FRAC NaN where the model's FRF is zero at every line): the formulas of
    :func:`cappe.correlate.frac` and :func:`cappe.correlate.csf` (one output per FRF), accumulated over blocks of
    lines.

    Per FRF it sums ``|H_a|^2``, ``|H_x|^2``, ``conj(H_x) H_a`` and the line's CSF
    ``2 |H_a| |H_x| / (|H_a|^2 + |H_x|^2)`` (1 where both are zero) over the lines; a block of lines is small
    enough for the CPU caches, so 81 x 81 FRFs of 600 lines need no temporaries of their size.
    """
    shape = h_ref.shape[1:]
    power_a, power_x, csf_sum = np.zeros(shape), np.zeros(shape), np.zeros(shape)
    cross = np.zeros(shape, dtype=complex)
    for s in chunk_slices(h_ref.shape[0], _BLOCK_LINES):
        a, x = h_mod[s], h_ref[s]
        pa = np.square(a.real)
        pa += np.square(a.imag)
        px = np.square(x.real)
        px += np.square(x.imag)
        power_a += pa.sum(axis=0)
        power_x += px.sum(axis=0)
        cross += np.einsum("f...,f...->...", x.conj(), a)
        den = pa + px
        pa *= px
        np.sqrt(pa, out=pa)
        pa *= 2.0
        line = np.ones(den.shape)  # both zero at a line: equal there
        np.divide(pa, den, out=line, where=den > 0)
        csf_sum += line.sum(axis=0)
    keep = power_x > NEGLIGIBLE_POWER * power_x.max()
    frac_v = np.full(shape, np.nan)
    csf_v = np.full(shape, np.nan)
    # a model FRF that is zero at every line (a channel the model cannot move, e.g. y of an x-only model, where the
    # reference holds noise) leaves FRAC undefined, as in correlate.frac: NaN, without a 0/0 RuntimeWarning
    power = power_a[keep] * power_x[keep]
    frac_v[keep] = np.divide(np.abs(cross[keep]) ** 2, power, out=np.full(power.shape, np.nan), where=power > 0)
    csf_v[keep] = csf_sum[keep] / h_ref.shape[0]
    return frac_v, csf_v


def _measured_pair(model: NumericModel, params: Array, position: Mapping[str, float], measured: FRFData,
                   f_max: float) -> tuple[Array, list[str], list[str], CArray, CArray]:
    """Lines, output and input channels, and the measured and model FRFs (line-major) of a validation against
    measured FRFs: the measured channels that are model sensor channels, lines in (0, f_max] (all lines when none
    is below f_max), non-finite measured values set to zero in both."""
    labels = set(model.sensor_matrix(params, position)[0])
    outs = [k for k, n in enumerate(measured.output_names) if n in labels]
    ins = [k for k, n in enumerate(measured.input_names) if n in labels]
    if not outs or not ins:
        msg = (f"measured FRFs at {dict(position)} have no {'output' if not outs else 'input'} at a sensor channel of "
               f"model '{model.structure.name}' (outputs {list(measured.output_names)[:6]}, inputs "
               f"{list(measured.input_names)}); map them with a sensor map")
        raise DataError(msg)
    freq = np.asarray(measured.freq, dtype=float)
    lines = np.flatnonzero((freq > 0) & (freq <= f_max))
    if lines.size == 0:
        lines = np.flatnonzero(freq > 0)
    if lines.size == 0:
        msg = f"measured FRFs at {dict(position)} have no line above 0 Hz"
        raise DataError(msg)
    quantities = measured.output_quantities or ("displacement",) * len(measured.output_names)
    orders = [DERIVATIVE_ORDER[quantities[k]] for k in outs]
    out_names = [measured.output_names[k] for k in outs]
    in_names = [measured.input_names[k] for k in ins]
    h_ref = np.moveaxis(np.asarray(measured.H, dtype=complex)[np.ix_(outs, ins)][..., lines], -1, 0)
    h_mod = model_frf(model, params, position, freq[lines], out_names, in_names, orders)[0]
    bad = ~np.isfinite(h_ref)
    h_ref = np.where(bad, 0.0, h_ref)
    h_mod = np.where(bad, 0.0, h_mod)
    return freq[lines], out_names, in_names, np.ascontiguousarray(h_ref), np.ascontiguousarray(h_mod)


def _synthesis(shapes: ArrayLike, freq_modes: Array, zeta: Array, freq: Array, out_idx: Sequence[int],
               in_idx: Sequence[int]) -> CArray:
    """Modal sum ``sum_r psi_jr psi_kr / (w_r^2 - w^2 + 2 i zeta_r w_r w)``, line-major: (n_freq, n_out, n_in)."""
    psi = np.asarray(shapes)
    wr = 2 * np.pi * freq_modes
    w = 2 * np.pi * freq
    den = wr[None, :] ** 2 - w[:, None] ** 2 + 2j * zeta[None, :] * wr[None, :] * w[:, None]  # (n_f, m)
    a = psi[list(out_idx)]  # (n_out, m)
    b = psi[list(in_idx)]
    return np.asarray(np.einsum("jr,kr,fr->fjk", a, b, 1.0 / den), dtype=complex)


#: Reference shapes whose modal scale factor against the paired mass-normalized model shapes lies outside
#: [1 / MASS_NORMALIZED_FACTOR, MASS_NORMALIZED_FACTOR] are taken as not mass-normalized.
MASS_NORMALIZED_FACTOR = 1.5


def _scaled_reference(data_set: ModalDataSet, model_shapes: CArray) -> tuple[CArray, tuple[str, ...]]:
    """Reference shapes for a modal synthesis: as they are when they are mass-normalized (their modal scale factor
    against the paired model shapes within a factor 1.5 of 1), else each scaled to its model partner's modal mass
    (complex modal scale factor), with a note saying so."""
    x = data_set.shapes
    msf = np.sum(x.conj() * model_shapes, axis=0) / np.sum(np.abs(x) ** 2, axis=0)  # model ~ msf * reference
    size = np.abs(msf)
    off = (size > MASS_NORMALIZED_FACTOR) | (size < 1 / MASS_NORMALIZED_FACTOR)
    if not np.any(off):
        return x, ()
    worst = float(np.max(np.maximum(size, 1 / size)))
    note = (f"reference shapes at {data_set.position} are not mass-normalized ({int(off.sum())} of "
            f"{data_set.n_modes} modes off by a factor up to {worst:.3g}): FRAC and CSF use them scaled to the "
            "model's modal masses, so they test poles and shapes but not modal masses (give driving points to "
            "extract-modes, or validate against measured FRFs)")
    return x * msf[None, :], (note,)


def _pair(model_shapes: CArray, model_poles: CArray, data_set: ModalDataSet,
          criterion: str = "macxp") -> tuple[NDArray[np.intp], Array]:
    """One-to-one pairing by MACXP (or ``criterion="mac"``: shapes alone), maximal total
    (:func:`cappe.correlate.pair_modes`), of the model modes with a finite nonzero pole: the model mode of each
    reference mode, and the criterion matrix (n_model, m; zero rows for the other model modes)."""
    idx = np.flatnonzero(np.isfinite(model_poles) & (np.abs(model_poles) > 0))
    if idx.size < data_set.n_modes:
        msg = (f"only {idx.size} oscillatory model modes at position {data_set.position}; the reference has "
               f"{data_set.n_modes}")
        raise DataError(msg)
    if criterion == "mac":
        pairing = pair_modes(phi_a=model_shapes[:, idx], phi_x=data_set.shapes, criterion="mac", threshold=0.0)
    else:
        pairing = pair_modes(phi_a=model_shapes[:, idx], lam_a=model_poles[idx], phi_x=data_set.shapes,
                             lam_x=data_set.poles, threshold=0.0)
    model_of = np.empty(data_set.n_modes, dtype=np.intp)
    model_of[pairing.index_x] = idx[pairing.index_a]
    full = np.zeros((model_poles.size, data_set.n_modes))
    full[idx] = pairing.matrix
    return model_of, full


def validate_identification(
    *,
    model: NumericModel | Structure,
    params: ArrayLike | Mapping[str, float],
    reference: ModalData,
    position: Mapping[str, float] | None = None,
    truth: ArrayLike | Mapping[str, float] | None = None,
    inputs: Sequence[str] | None = None,
    freq: ArrayLike | None = None,
    n_freq: int = 600,
    exact: bool = True,
    overlay: tuple[str, str] | None = None,
    measured: FRFData | None = None,
) -> ValidationResult:
    """FRAC, CSF, MACXP and NDD of a model against reference modes at one position (see the module notes).

    Parameters
    ----------
    model : NumericModel or Structure
    params : array (n_params,) or mapping
        The identified model's full parameter vector (or overrides of the nominal values).
    reference : ModalData
        Reference modes; the set at ``position`` is used (default: the first set).
    position : mapping, optional
        Axis position of the set to validate against.
    truth : array (n_params,) or mapping, optional
        Parameters the reference was simulated from: the reference FRFs are then the model's at ``truth``.
    inputs : sequence of str, optional
        Input channels of the FRFs (default: every reference channel).
    freq : array_like, optional
        Frequency lines (Hz) of the FRF criteria (default ``n_freq`` lines up to 1.25 times the highest reference
        frequency).
    n_freq : int
        Number of default frequency lines.
    exact : bool
        Compare the model's exact complex modes (default) rather than its first-order ones.
    overlay : (str, str), optional
        Output and input channel of the FRF kept for plots (default: the driving point with the largest peak).
    measured : FRFData, optional
        Measured FRFs at this position, at model sensor channels: without ``truth``, FRAC and CSF compare the
        model's FRFs with them (``inputs``, ``freq`` and ``n_freq`` do not apply).

    Returns
    -------
    ValidationResult

    Examples
    --------
    >>> from cappe.model import load_model
    >>> rig = load_model("builtin:two-mass-rig")
    >>> ref = ModalEngine(rig).modal_data()
    >>> res = validate_identification(model=rig, params={}, reference=ref, truth={})
    >>> res.statistics()["frac"]["worst"] > 0.999999, res.statistics()["ndd"]["worst"] < 1e-9
    (True, True)
    """
    nm = model if isinstance(model, NumericModel) else NumericModel(model)
    k = 0 if position is None else find_set(reference, position, nm)
    data_set = reference.sets[k]
    pos = nm.structure.resolve_position(data_set.position)
    p = nm.vector(params if isinstance(params, Mapping) else np.asarray(params, dtype=float))
    sensors = list(reference.sensors)
    engine = ModalEngine(nm, sensors=sensors)
    batch = engine.evaluate(p, pos, exact=exact)
    if exact and batch.poles is not None and batch.complex_shapes is not None:
        shapes: CArray = batch.complex_shapes[0]
        poles: CArray = batch.poles[0]
    else:
        shapes = batch.shapes[0].astype(complex)
        poles = batch.first_order_poles[0]
    model_of, matrix = _pair(shapes, poles, data_set)
    omega_m = np.abs(poles[model_of])
    f_model = omega_m / (2 * np.pi)
    zeta_model = -poles[model_of].real / omega_m
    values = matrix[model_of, np.arange(data_set.n_modes)]
    nfd_v = nfd(f_model, data_set.frequency)
    damped = data_set.damping > 0  # NDD of an undamped reference mode is undefined: NaN, left out of statistics
    ndd_v = np.full(data_set.n_modes, np.nan)
    ndd_v[damped] = ndd(zeta_model[damped], data_set.damping[damped])
    n_show = min(poles.size, max(data_set.n_modes + 4, int(model_of.max()) + 1))

    notes: tuple[str, ...] = ()
    out_names: list[str] = sensors
    if truth is None and measured is not None:
        f_grid, out_names, channels_in, h_ref, h_mod = _measured_pair(nm, p, pos, measured,
                                                                      1.25 * float(data_set.frequency.max()))
        source = "measured FRFs"
    else:
        f_grid = (np.linspace(0.0, 1.25 * float(data_set.frequency.max()), n_freq + 1)[1:] if freq is None
                  else np.asarray(freq, dtype=float))
        channels_in = list(inputs) if inputs is not None else sensors
        unknown = [c for c in channels_in if c not in sensors]
        if unknown:
            msg = f"FRF input channels {unknown} are not reference sensor channels {sensors}"
            raise DataError(msg)
        in_idx = [sensors.index(c) for c in channels_in]
        if truth is not None:
            t = nm.vector(truth if isinstance(truth, Mapping) else np.asarray(truth, dtype=float))
            h_ref = _truth_receptance(nm, t.tobytes(), tuple(pos.items()), f_grid.tobytes(), tuple(sensors),
                                      tuple(channels_in))
            h_mod = _receptance_lines(nm, p, pos, f_grid, sensors, channels_in)
            source = "truth"
        else:
            ref_shapes, notes = _scaled_reference(data_set, shapes[:, model_of])
            h_ref = _synthesis(ref_shapes, data_set.frequency, data_set.damping, f_grid, range(len(sensors)),
                               in_idx)
            h_mod = _synthesis(shapes[:, model_of], f_model, zeta_model, f_grid, range(len(sensors)), in_idx)
            source = "modal synthesis"
    frac_v, csf_v = _line_criteria(h_mod, h_ref)
    if overlay is not None:
        if overlay[0] not in out_names or overlay[1] not in channels_in:
            msg = f"overlay {overlay} must name a reference channel and an FRF input channel {channels_in}"
            raise DataError(msg)
        o_best, i_best = out_names.index(overlay[0]), channels_in.index(overlay[1])
    else:
        drive = [(out_names.index(c), j) for j, c in enumerate(channels_in) if c in out_names]
        if not drive:  # measured FRFs without a driving point: every FRF is a candidate
            drive = [(o, i) for o in range(len(out_names)) for i in range(len(channels_in))]
        peak = [float(np.max(np.abs(h_ref[:, o, i]))) for o, i in drive]
        o_best, i_best = drive[int(np.argmax(peak))]
    kept = {"output": out_names[o_best], "input": channels_in[i_best], "reference": h_ref[:, o_best, i_best].copy(),
            "model": h_mod[:, o_best, i_best].copy()}
    return ValidationResult(
        position=dict(pos), reference_frequency=data_set.frequency.copy(), model_mode=model_of,
        model_frequency=f_model, reference_damping=data_set.damping.copy(), model_damping=zeta_model, macxp=values,
        nfd=nfd_v, ndd=ndd_v, macxp_matrix=matrix[:n_show], freq=f_grid,
        outputs=tuple(out_names), inputs=tuple(channels_in), frac=frac_v, csf=csf_v, frf_source=source,
        overlay=kept, notes=notes,
    )
