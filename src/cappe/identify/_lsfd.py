"""Residues and mode shapes from FRFs at known poles (least-squares frequency domain, LSFD), and the complete
modal extraction ``FRFs -> stabilization diagram -> selected poles -> modal model``.

Model of every FRF (output o, input i) at ``s = 1j omega``, for displacement-level outputs::

    H_oi(s) = sum_r [ R_oir / (s - lambda_r) + conj(R_oir) / (s - conj(lambda_r)) ] + LR_oi / s**2 + UR_oi

with real lower (``LR``, modes below the band: mass-like) and upper (``UR``, modes above: stiffness-like)
residual coefficients, so that the time response is real. Velocity and acceleration outputs are the same
model times ``s`` and ``s**2``; the residues ``R`` are therefore always displacement-level (receptance)
residues, whatever the measured quantity.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cappe._rng import RandomLike, as_generator
from cappe.exceptions import DataError
from cappe.identify._lscf import (
    PoleSelection,
    StabilizationDiagram,
    _band_lines,
    _check_finite,
    _check_frf,
    _pole_frequency_damping,
    lscf_poles,
    select_poles,
)
from cappe.systems.frf import FRFData
from cappe.systems.modal import ModalData, ModalDataSet

__all__ = ["ModalExtraction", "ModalFit", "extract_modes", "lsfd"]

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

#: Time-derivative order of each output quantity (others are fitted as given, like displacement).
_DERIVATIVE = {"displacement": 0, "elongation": 0, "velocity": 1, "acceleration": 2}


def _derivative_orders(quantities: Sequence[str], n_out: int) -> NDArray[np.intp]:
    """Time-derivative order of each of ``n_out`` outputs (all 0 when no quantities are given; FRFData checks that
    a given list has one per output)."""
    if not quantities:
        return np.zeros(n_out, dtype=np.intp)
    return np.array([_DERIVATIVE.get(q, 0) for q in quantities], dtype=np.intp)


def _basis(s: ComplexArray, poles: ComplexArray, lower: bool, upper: bool) -> ComplexArray:
    """Columns (n_f, 2 m + residuals): real and imaginary part of each residue, then LR and UR."""
    a = 1.0 / (s[:, None] - poles[None, :])
    b = 1.0 / (s[:, None] - poles.conj()[None, :])
    cols = [a + b, 1j * (a - b)]
    if lower:
        cols.append((1.0 / s**2)[:, None])
    if upper:
        cols.append(np.ones((s.size, 1), dtype=complex))
    return np.concatenate(cols, axis=1)


@dataclass(frozen=True)
class ModalFit:
    """Modal model fitted to FRFs: poles, residues, mode shapes, participation and residual terms.

    Attributes
    ----------
    poles : ndarray of complex, shape (n_modes,)
        Physical poles in rad/s (upper half plane, corrected for an exponential window), ascending in frequency.
    frequency : ndarray, shape (n_modes,)
        Natural frequencies ``|lambda| / 2 pi`` in Hz.
    damping : ndarray, shape (n_modes,)
        Damping ratios ``-Re lambda / |lambda|``.
    residues : ndarray of complex, shape (n_out, n_in, n_modes)
        Displacement-level residues ``R[out, in, mode]`` (m/N/s for force inputs and displacement outputs).
    shapes : ndarray of complex, shape (n_out, n_modes)
        Mode shapes at the outputs, the best rank-one factor of each mode's residue matrix
        ``R[:, :, r] ~ shapes[:, r] participation[:, r]^T``. Scaling: with driving points, the residue of a
        driving point is ``psi_o**2 / (2j omega_d)`` (``omega_d = Im lambda``), which makes the shapes
        mass-normalized for proportionally damped structures (``scaling = "driving point"``); otherwise the
        largest component of each shape is 1 (``scaling = "unit max"``).
    participation : ndarray of complex, shape (n_in, n_modes)
        Modal participation factors per input.
    lower_residual, upper_residual : ndarray, shape (n_out, n_in)
        Real coefficients of the ``1 / s**2`` and constant residual terms (displacement level).
    fit_error : ndarray, shape (n_out, n_in)
        Relative misfit ``||H - H_fit|| / ||H||`` of each FRF over the band.
    input_names, output_names, output_quantities : tuple of str
        As in the FRFs.
    band : tuple of float
        Fitted band (Hz).
    window_decay : float or None
        Exponential window time constant (s) the poles were corrected for.
    scaling : str
        ``"driving point"`` or ``"unit max"``.
    """

    poles: ComplexArray
    frequency: FloatArray
    damping: FloatArray
    residues: ComplexArray
    shapes: ComplexArray
    participation: ComplexArray
    lower_residual: FloatArray
    upper_residual: FloatArray
    fit_error: FloatArray
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    output_quantities: tuple[str, ...]
    band: tuple[float, float]
    window_decay: float | None
    scaling: str

    @property
    def n_modes(self) -> int:
        return int(self.poles.size)

    def synthesize(self, freq: ArrayLike, *, windowed: bool = False) -> FRFData:
        """FRFs of the modal model (with its residual terms) at ``freq`` (Hz, > 0).

        ``windowed=True`` gives the FRFs as measured through the exponential window (poles shifted by
        ``-1 / window_decay``), for comparison with the data the model was fitted to.

        Parameters
        ----------
        freq : array_like, shape (n_freq,)
            Frequencies in Hz, > 0.
        windowed : bool
            Synthesize as seen through the exponential window of the fitted data.

        Returns
        -------
        FRFData
            ``H[out, in, freq]`` in the units of the fitted FRFs.

        Raises
        ------
        DataError
            ``freq`` is not 1-D, finite and > 0.

        Examples
        --------
        >>> import numpy as np
        >>> from cappe.systems.frf import FRFData
        >>> f = np.linspace(1.0, 20.0, 200)
        >>> lam = np.array([-0.5 + 60j])
        >>> H = (1 / (2j * np.pi * f - lam) + 1 / (2j * np.pi * f - lam.conj()))[None, None]
        >>> fit = lsfd(FRFData(f, H, ("F",), ("x",)), poles=lam, band=(1.0, 20.0))
        >>> bool(np.allclose(fit.synthesize(f).H, H, rtol=1e-9))
        True
        """
        f = np.atleast_1d(np.asarray(freq, dtype=float))
        if f.ndim != 1 or not np.all(np.isfinite(f)) or np.any(f <= 0):
            msg = "synthesis frequencies must be a 1-D array of finite values > 0 Hz"
            raise DataError(msg)
        s = 2j * np.pi * f
        poles = self.poles - (1.0 / self.window_decay if windowed and self.window_decay else 0.0)
        a = 1.0 / (s[None, :] - poles[:, None])  # (m, n_f)
        b = 1.0 / (s[None, :] - poles.conj()[:, None])
        H = np.einsum("oir,rf->oif", self.residues, a) + np.einsum("oir,rf->oif", self.residues.conj(), b)
        H = H + self.lower_residual[..., None] / s**2 + self.upper_residual[..., None]
        d = _derivative_orders(self.output_quantities, len(self.output_names))
        H = H * s[None, None, :] ** d[:, None, None]
        return FRFData(f, H, self.input_names, self.output_names, self.output_quantities)

    def to_modal_data(self, position: Mapping[str, float] | None = None) -> ModalData:
        """The modes as :class:`cappe.systems.ModalData`, one set at ``position``; sensors are the output names.

        Parameters
        ----------
        position : mapping axis -> float, optional
            Axis position of the set (m or rad); empty by default.

        Returns
        -------
        ModalData
        """
        data_set = ModalDataSet(
            dict(position or {}), self.frequency.copy(), self.damping.copy(), self.shapes.astype(complex)
        )
        return ModalData(tuple(self.output_names), (data_set,))

    def to_dict(self) -> dict[str, Any]:
        modes = []
        for r in range(self.n_modes):
            modes.append(
                {
                    "frequency": float(self.frequency[r]),
                    "damping": float(self.damping[r]),
                    "pole": [float(self.poles[r].real), float(self.poles[r].imag)],
                    "shape_re": {o: float(v.real) for o, v in zip(self.output_names, self.shapes[:, r], strict=True)},
                    "shape_im": {o: float(v.imag) for o, v in zip(self.output_names, self.shapes[:, r], strict=True)},
                    "participation_re": {
                        i: float(v.real) for i, v in zip(self.input_names, self.participation[:, r], strict=True)
                    },
                    "participation_im": {
                        i: float(v.imag) for i, v in zip(self.input_names, self.participation[:, r], strict=True)
                    },
                }
            )
        return {
            "format": "cappe.modal_fit/1",
            "band": list(self.band),
            "inputs": list(self.input_names),
            "outputs": list(self.output_names),
            "window_decay": self.window_decay,
            "scaling": self.scaling,
            "modes": modes,
            "fit_error": {
                f"{o}/{i}": float(self.fit_error[a, b])
                for a, o in enumerate(self.output_names)
                for b, i in enumerate(self.input_names)
            },
        }


def _as_poles(poles: PoleSelection | ArrayLike) -> ComplexArray:
    values = poles.poles if isinstance(poles, PoleSelection) else poles
    try:
        lam = np.atleast_1d(np.asarray(values, dtype=complex))
    except (TypeError, ValueError) as exc:
        msg = f"poles must be complex numbers in rad/s; got {values!r}"
        raise DataError(msg) from exc
    if lam.ndim != 1 or lam.size == 0 or not np.all(np.isfinite(lam)) or np.any(lam.imag <= 0):
        msg = (
            f"poles must be a non-empty 1-D array of finite poles in the upper half plane (Im > 0, rad/s); "
            f"got {np.array2string(lam, precision=4)}"
        )
        raise DataError(msg)
    return np.asarray(lam[np.argsort(np.abs(lam), kind="stable")], dtype=complex)


def _driving_pairs(frf: FRFData, driving_points: Mapping[str, str] | None) -> list[tuple[int, int]]:
    if not driving_points:
        return []
    pairs = []
    for inp, out in driving_points.items():
        if inp not in frf.input_names:
            msg = f"driving_points: unknown input {inp!r}; FRF inputs: {', '.join(frf.input_names)}"
            raise DataError(msg)
        if out not in frf.output_names:
            msg = (
                f"driving_points: unknown output {out!r} for input {inp!r}; FRF outputs: {', '.join(frf.output_names)}"
            )
            raise DataError(msg)
        pairs.append((frf.output_names.index(out), frf.input_names.index(inp)))
    return pairs


def _shapes(
    residues: ComplexArray, poles: ComplexArray, driving: list[tuple[int, int]]
) -> tuple[ComplexArray, ComplexArray]:
    """Rank-one factors ``R[:, :, r] ~ psi_r l_r^T`` of each mode, scaled (see :class:`ModalFit`)."""
    n_out, n_in, m = residues.shape
    shapes = np.zeros((n_out, m), dtype=complex)
    part = np.zeros((n_in, m), dtype=complex)
    for r in range(m):
        u_all, sv, _ = np.linalg.svd(residues[:, :, r], full_matrices=False)
        if sv[0] == 0:
            continue
        u = u_all[:, 0]
        proj = u.conj() @ residues[:, :, r]  # u^H R[:, i] for every input i
        if driving:
            o_idx = np.array([o for o, _ in driving])
            i_idx = np.array([i for _, i in driving])
            weight = float(np.sum(np.abs(u[o_idx]) ** 2))
            c2 = 2j * poles[r].imag * np.sum(u[o_idx].conj() * proj[i_idx]) / weight if weight > 0 else 0.0
            c = np.sqrt(complex(c2))
            if c == 0:
                continue
            psi = c * u
            k = int(np.argmax(np.abs(psi)))
            if psi[k].real < 0:
                psi, c = -psi, -c
            shapes[:, r] = psi
            part[:, r] = proj / c
        else:
            k = int(np.argmax(np.abs(u)))
            shapes[:, r] = u / u[k]
            part[:, r] = u[k] * proj
    return shapes, part


def lsfd(
    frf: FRFData,
    *,
    poles: PoleSelection | ArrayLike,
    band: Sequence[float],
    lower_residual: bool = True,
    upper_residual: bool = True,
    driving_points: Mapping[str, str] | None = None,
) -> ModalFit:
    """Residues, mode shapes and participation factors at known poles by linear least squares (LSFD).

    Parameters
    ----------
    frf : FRFData
        FRFs ``H[out, in, freq]``; ``output_quantities`` (displacement, velocity, acceleration) select the
        model form, and ``window_decay`` (s) says the poles were shifted by ``-1 / window_decay`` in the data.
    poles : PoleSelection or array_like of complex, shape (n_modes,)
        Physical poles in rad/s (upper half plane), e.g. from :func:`select_poles`.
    band : (float, float)
        Band in Hz; lines at 0 Hz are skipped.
    lower_residual, upper_residual : bool
        Include the ``1 / s**2`` and constant residual terms (displacement level).
    driving_points : mapping input -> output, optional
        Output measured at each input's location and direction; selects driving-point scaling of the shapes.

    Returns
    -------
    ModalFit
        Modes ascending in frequency.

    Raises
    ------
    DataError
        If the band is reversed or outside the data's frequency range, holds too few lines for the unknowns,
        the poles are not in the upper half plane, or a driving point names an unknown input or output.

    Examples
    --------
    >>> import numpy as np
    >>> from cappe.systems.frf import FRFData
    >>> f = np.linspace(1.0, 50.0, 400)
    >>> lam = np.array([-0.6 + 2j * np.pi * 20.0])
    >>> s = 2j * np.pi * f
    >>> H = (3j / (s - lam) - 3j / (s - lam.conj()))[None, None]
    >>> fit = lsfd(FRFData(f, H, ("F",), ("x",)), poles=lam, band=(1.0, 50.0))
    >>> complex(np.round(fit.residues[0, 0, 0], 9))
    3j
    """
    freq, H = _check_frf(frf)
    f_band, idx = _band_lines(freq, band)
    idx = idx[freq[idx] > 0]
    lam = _as_poles(poles)
    driving = _driving_pairs(frf, driving_points)
    deriv = _derivative_orders(frf.output_quantities, len(frf.output_names))
    Hb = H[:, :, idx]
    _check_finite(Hb, freq[idx], frf)
    n_out, n_in, n_f = Hb.shape
    m = lam.size
    n_unknown = 2 * m + int(lower_residual) + int(upper_residual)
    if 2 * n_f < n_unknown:
        msg = (
            f"band ({f_band[0]:g}, {f_band[1]:g}) Hz holds {n_f} usable frequency lines; {m} modes with residual "
            f"terms need at least {(n_unknown + 1) // 2}"
        )
        raise DataError(msg)
    shift = 0.0 if frf.window_decay is None else 1.0 / float(frf.window_decay)
    s: ComplexArray = np.asarray(2j * np.pi * freq[idx], dtype=complex)
    base = _basis(s, np.asarray(lam - shift, dtype=complex), lower_residual, upper_residual)
    coef = np.zeros((n_out, n_in, n_unknown))
    fitted = np.zeros_like(Hb)
    for d in np.unique(deriv):
        outs = np.flatnonzero(deriv == d)
        A = base * (s**d)[:, None]
        A_real = np.concatenate([A.real, A.imag], axis=0)
        scale = np.linalg.norm(A_real, axis=0)
        scale = np.where(scale > 0, scale, 1.0)
        rhs = Hb[outs].reshape(-1, n_f).T  # (n_f, n_outs * n_in)
        b_real = np.concatenate([rhs.real, rhs.imag], axis=0)
        x = np.linalg.lstsq(A_real / scale, b_real, rcond=None)[0] / scale[:, None]
        coef[outs] = x.T.reshape(outs.size, n_in, n_unknown)
        fitted[outs] = (A @ x).T.reshape(outs.size, n_in, n_f)
    residues = coef[..., :m] + 1j * coef[..., m : 2 * m]
    k = 2 * m
    lower = coef[..., k] if lower_residual else np.zeros((n_out, n_in))
    upper = coef[..., k + int(lower_residual)] if upper_residual else np.zeros((n_out, n_in))
    norm = np.linalg.norm(Hb, axis=2)
    error = np.linalg.norm(Hb - fitted, axis=2) / np.where(norm > 0, norm, 1.0)
    shapes, part = _shapes(residues, lam, driving)
    frequency, damping = _pole_frequency_damping(lam)
    return ModalFit(
        poles=lam,
        frequency=frequency,
        damping=damping,
        residues=residues,
        shapes=shapes,
        participation=part,
        lower_residual=lower,
        upper_residual=upper,
        fit_error=error,
        input_names=tuple(frf.input_names),
        output_names=tuple(frf.output_names),
        output_quantities=tuple(frf.output_quantities),
        band=f_band,
        window_decay=None if frf.window_decay is None else float(frf.window_decay),
        scaling="driving point" if driving else "unit max",
    )


@dataclass(frozen=True)
class ModalExtraction:
    """Result of :func:`extract_modes`: the stabilization diagram, the selected poles and the LSFD fit.

    Attributes
    ----------
    diagram : StabilizationDiagram
    selection : PoleSelection
    fit : ModalFit
    method : str
        ``"plscf"`` or ``"lscf"``.
    reciprocity : bool
        True when the FRFs were read by reciprocity (:meth:`FRFData.reciprocal`): the measured inputs (hammer
        points) are the fit's outputs, and the shapes are given at them.
    frequency_std, damping_std : ndarray, shape (n_modes,), optional
        Standard deviations of the frequencies (Hz) and damping ratios from a wild bootstrap over the fit's
        residuals (see :func:`extract_modes`); None without a bootstrap.
    shape_std : ndarray, shape (n_out, n_modes), optional
        Standard deviation (modulus of the complex deviation) of each shape component, in the shapes' scaling.
    found : ndarray of int, shape (n_modes,), optional
        In how many bootstrap replicates each mode was found again.
    n_bootstrap : int
        Number of bootstrap replicates (0: none).
    warnings : tuple of str
        What the data could not determine (modes not reproducible under their own noise), one line each.
    """

    diagram: StabilizationDiagram
    selection: PoleSelection
    fit: ModalFit
    method: str
    reciprocity: bool = False
    frequency_std: FloatArray | None = None
    damping_std: FloatArray | None = None
    shape_std: FloatArray | None = None
    found: NDArray[np.int64] | None = None
    n_bootstrap: int = 0
    warnings: tuple[str, ...] = ()

    @property
    def frequency(self) -> FloatArray:
        """Natural frequencies in Hz, ascending."""
        return self.fit.frequency

    @property
    def damping(self) -> FloatArray:
        """Damping ratios."""
        return self.fit.damping

    @property
    def shapes(self) -> ComplexArray:
        """Mode shapes at the outputs, shape (n_out, n_modes)."""
        return self.fit.shapes

    def to_modal_data(self, position: Mapping[str, float] | None = None) -> ModalData:
        """The extracted modes as :class:`cappe.systems.ModalData` (:meth:`ModalFit.to_modal_data`).

        Parameters
        ----------
        position : mapping axis -> float, optional
            Axis position of the set (m or rad); empty by default.

        Returns
        -------
        ModalData
            With the standard deviations of the bootstrap when there was one.
        """
        data = self.fit.to_modal_data(position)
        data_set = replace(
            data.sets[0], frequency_std=self.frequency_std, damping_std=self.damping_std, shape_std=self.shape_std
        )
        return replace(data, sets=(data_set,))

    def to_dict(self) -> dict[str, Any]:
        fit = self.fit.to_dict()
        modes = fit["modes"]
        if self.frequency_std is not None and self.damping_std is not None and self.shape_std is not None:
            found = self.found if self.found is not None else np.zeros(self.fit.n_modes, dtype=np.int64)
            modes = [
                {
                    **mode,
                    "frequency_std": _finite_or_none(self.frequency_std[r]),
                    "damping_std": _finite_or_none(self.damping_std[r]),
                    "shape_std": {
                        o: _finite_or_none(v) for o, v in zip(self.fit.output_names, self.shape_std[:, r], strict=True)
                    },
                    "bootstrap_found": int(found[r]),
                }
                for r, mode in enumerate(modes)
            ]
        return {
            "format": "cappe.modal_extraction/1",
            "method": self.method,
            "band": list(self.fit.band),
            "reciprocity": self.reciprocity,
            "n_bootstrap": self.n_bootstrap,
            "modes": modes,
            "selection": self.selection.to_dict()["modes"],
            "fit": fit,
            "diagram": self.diagram.to_dict(),
            "warnings": list(self.warnings),
        }


def _finite_or_none(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def _reference_side(frf: FRFData, reference_side: str) -> bool:
    """Whether to read ``frf`` by reciprocity (see :func:`extract_modes`)."""
    if reference_side not in ("auto", "inputs", "outputs"):
        msg = f"reference_side must be 'auto', 'inputs' or 'outputs'; got {reference_side!r}"
        raise DataError(msg)
    if reference_side == "auto":
        return len(frf.input_names) > len(frf.output_names) and len(set(frf.output_quantities)) <= 1
    return reference_side == "outputs"


def _matched_poles(diagram: StabilizationDiagram, selection: PoleSelection, tol: float) -> ComplexArray:
    """For each selected pole, the pole of the same model order in ``diagram`` nearest to it (relative distance
    ``|s - s0| / |s0|``); NaN where none is within ``tol``."""
    valid = diagram.excluded == ""
    out = np.full(selection.n_modes, np.nan + 0j, dtype=complex)
    for r, (pole, order) in enumerate(zip(selection.poles, selection.order, strict=True)):
        cand = np.flatnonzero((diagram.order == order) & valid)
        if cand.size == 0:
            continue
        dist = np.abs(diagram.poles[cand] - pole) / abs(pole)
        k = int(np.argmin(dist))
        if dist[k] <= tol:
            out[r] = diagram.poles[cand[k]]
    return out


def _bootstrap(
    frf: FRFData,
    extraction: ModalExtraction,
    *,
    band: Sequence[float],
    driving_points: Mapping[str, str] | None,
    n_bootstrap: int,
    rng: RandomLike,
    tolerances: Mapping[str, float],
) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.int64]]:
    """Standard deviations of frequency, damping and shapes by a wild bootstrap over the LSFD residuals.

    Each replicate is the fitted modal model (as measured, through the window) plus the residual of every line
    turned by a random phase ``exp(2j pi u)``: heteroscedastic noise keeps its size at each line. The poles are
    estimated again at the model order each mode was taken from and matched to the selected ones, the shapes by
    LSFD at the matched poles, each aligned to the original shape by the least-squares complex factor.
    """
    gen = as_generator(rng)
    fit = extraction.fit
    freq = np.asarray(frf.freq, dtype=float)
    _, idx = _band_lines(freq, band)
    idx = idx[freq[idx] > 0]
    f = freq[idx]
    model = fit.synthesize(f, windowed=True).H
    data = np.asarray(frf.H, dtype=complex)[:, :, idx]
    resid = data - model
    n_unknown = 2 * fit.n_modes + 2
    dof = max(2 * f.size - n_unknown, 1)
    resid = resid * np.sqrt(2 * f.size / dof)
    orders = sorted({int(n) for n in extraction.selection.order})
    reference = "poly" if extraction.method == "plscf" else "common"
    m = fit.n_modes
    poles = np.full((n_bootstrap, m), np.nan + 0j)
    shapes = np.full((n_bootstrap, fit.shapes.shape[0], m), np.nan + 0j)
    # a replicate pole further than five frequency tolerances from the selected one is another pole: the mode was
    # not found in that replicate
    tol = 5 * float(tolerances["freq_tol"])
    for b in range(n_bootstrap):
        phase = np.exp(2j * np.pi * gen.random(resid.shape))
        rep = replace(frf, freq=f, H=model + resid * phase, coherence=None)
        diagram = lscf_poles(
            rep, band=(f[0], f[-1]), orders=orders, reference=reference, freq_tol=tolerances["freq_tol"],
            damping_tol=tolerances["damping_tol"], mac_tol=tolerances["mac_tol"], max_damping=tolerances["max_damping"],
        )
        lam = _matched_poles(diagram, extraction.selection, tol)
        ok = np.isfinite(lam)
        poles[b] = lam
        if not ok.any():
            continue
        lam_fit = np.where(ok, lam, fit.poles)  # missing modes keep the original pole so the basis stays whole
        rep_fit = lsfd(rep, poles=lam_fit, band=(f[0], f[-1]), driving_points=driving_points)
        order = np.argsort(np.abs(lam_fit), kind="stable")  # lsfd sorts its poles; undo it
        psi = np.empty_like(rep_fit.shapes)
        psi[:, order] = rep_fit.shapes
        for r in np.flatnonzero(ok):
            ref = fit.shapes[:, r]
            den = np.vdot(psi[:, r], psi[:, r])
            if den == 0:
                continue
            shapes[b, :, r] = psi[:, r] * (np.vdot(psi[:, r], ref) / den)
    found = np.sum(np.isfinite(poles), axis=0).astype(np.int64)
    rep_freq, rep_damp = _pole_frequency_damping(np.where(np.isfinite(poles), poles, 1j))
    rep_freq[~np.isfinite(poles)] = np.nan
    rep_damp[~np.isfinite(poles)] = np.nan
    # root-mean-square deviation of the replicates from the estimate: their spread and the estimator's bias under
    # this noise (mean replicate - estimate), which for LSCF grows with the noise and would otherwise leave the
    # truth outside the interval (measured: 4 standard deviations on a 3-DOF chain with 2 % noise)
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a mode found in no replicate: NaN
        freq_std = np.sqrt(np.nanmean((rep_freq - fit.frequency) ** 2, axis=0))
        damp_std = np.sqrt(np.nanmean((rep_damp - fit.damping) ** 2, axis=0))
        shape_std = np.sqrt(np.nanmean(np.abs(shapes - fit.shapes) ** 2, axis=0))
    usable = found >= 2
    # a root-mean-square over n replicates has n degrees of freedom: +-1.96 of it covers at the rate of Student's
    # t with n degrees of freedom (93.1 % at n = 10), so it is widened by t_0.975(n) / 1.96 (1.14 at n = 10, 1.04
    # at 30) and +-1.96 std is a 95 % interval whatever the number of replicates
    widen = _student_widening(np.maximum(found, 2))
    freq_std, damp_std = np.where(usable, freq_std * widen, np.nan), np.where(usable, damp_std * widen, np.nan)
    shape_std = np.where(usable[None, :], shape_std * widen[None, :], np.nan)
    return freq_std, damp_std, shape_std, found


def _student_widening(dof: NDArray[np.int64]) -> FloatArray:
    """``t_0.975(dof) / z_0.975``: how much wider a 95 % interval is when its scale is estimated from ``dof``
    degrees of freedom."""
    from scipy import stats

    return np.asarray(stats.t.ppf(0.975, dof) / stats.norm.ppf(0.975), dtype=float)


def extract_modes(
    frf: FRFData,
    *,
    band: Sequence[float],
    max_order: int = 40,
    n_modes: int | None = None,
    method: str = "plscf",
    selection: str | Sequence[float] = "auto",
    driving_points: Mapping[str, str] | None = None,
    freq_tol: float = 0.01,
    damping_tol: float = 0.05,
    mac_tol: float = 0.98,
    max_damping: float = 0.2,
    min_fraction: float = 0.3,
    reference_side: str = "auto",
    n_bootstrap: int = 10,
    rng: RandomLike = 0,
) -> ModalExtraction:
    """Modal parameters from FRFs: (poly-reference) LSCF poles, stabilization, pole selection, LSFD, and the
    standard deviation of each mode's frequency, damping and shape estimated from the data.

    The references of the poly-reference estimator are the side with fewer channels: a roving-hammer test (one
    accelerometer, the hammer moved over N points: 1 output, N inputs) is read by reciprocity
    (:meth:`FRFData.reciprocal`) as N responses to one reference, so that the poles are fitted from N rows and the
    mode shapes are given at the hammer points (``result.reciprocity``).

    Standard deviations: a wild bootstrap over the residuals of the LSFD fit. Each of ``n_bootstrap`` replicates
    adds to the fitted model the residual of every line turned by a random phase (noise that varies over the band
    keeps its size at each line), estimates the poles again at the order each mode was taken from and the shapes by
    LSFD; the root-mean-square deviation of the replicates from the estimate is the standard deviation (it holds the
    estimator's bias under this noise as well as its spread), widened by ``t_0.975(n) / 1.96`` for the n
    replicates it rests on (a scale estimated from n deviations: without it +-1.96 std covers at Student's rate,
    93.1 % at n = 10), so that +-1.96 std is a 95 % interval. Model error left in the residual counts as noise
    (the estimate errs on the wide side). A mode that the replicates find in fewer than half of them is not
    determined by the data, nor is a damping ratio whose standard deviation exceeds half its value: both are named
    in ``result.warnings``.

    Parameters
    ----------
    frf : FRFData
        Measured or simulated FRFs ``H[out, in, freq]``; with ``window_decay`` set, poles are corrected for
        the exponential window (``+1 / window_decay`` on the real part) before damping is computed.
    band : (float, float)
        Frequency band in Hz.
    max_order : int
        Highest denominator order; orders ``2, 4, ..., max_order`` are estimated.
    n_modes : int, optional
        Number of modes to keep (automatic selection); default: every cluster stable in ``min_fraction`` of
        the orders.
    method : {"plscf", "lscf"}
        Poly-reference LSCF (PolyMAX) or common-denominator LSCF.
    selection : "auto" or sequence of float
        Automatic selection by clustering, or approximate natural frequencies (Hz) to pick poles near.
    driving_points : mapping input -> output, optional
        Driving-point FRFs for mode-shape scaling (see :class:`ModalFit`).
    freq_tol, damping_tol, mac_tol, max_damping : float
        Stabilization tolerances, see :func:`stabilization_diagram`.
    min_fraction : float
        See :func:`select_poles`.
    reference_side : {"auto", "inputs", "outputs"}
        The references of the estimator: the measured inputs (``"inputs"``), or, by reciprocity, the measured
        outputs (``"outputs"``, the hammer points become the shapes' points). ``"auto"`` (default) reads by
        reciprocity when there are more inputs than outputs and the outputs measure one quantity.
    n_bootstrap : int
        Bootstrap replicates for the standard deviations (default 10: the std to about 22 %, widened for it; 0
        skips them). Measured on numpy-generated FRFs with 2 % noise (``benchmarks/bench_mode_std.py``): 10
        replicates cover the truth as often as 30 at a third of the cost.
    rng : int, numpy Generator or None
        Seed of the bootstrap (default 0: the same data give the same standard deviations).

    Returns
    -------
    ModalExtraction

    Raises
    ------
    DataError
        From the steps (band, orders, no stable poles, ...) or for an unknown ``method`` / ``selection``.

    Examples
    --------
    >>> import numpy as np
    >>> from cappe.systems.frf import FRFData
    >>> f = np.linspace(0.0, 100.0, 1001)
    >>> lam = np.array([-0.4 + 2j * np.pi * 30.0, -0.9 + 2j * np.pi * 62.0])
    >>> s = 2j * np.pi * f[:, None]
    >>> H = np.stack([(v / (s - lam) + np.conj(v) / (s - lam.conj())).sum(1) for v in ([1j, 1j], [0.5j, -1j])])
    >>> res = extract_modes(FRFData(f, H[:, None], ("F",), ("p1", "p2")), band=(5.0, 95.0), max_order=12)
    >>> [round(float(x), 3) for x in res.frequency], [round(float(z), 5) for z in res.damping]
    ([30.0, 62.0], [0.00212, 0.00231])
    """
    if method not in ("plscf", "lscf"):
        msg = f"method must be 'plscf' (poly-reference LSCF) or 'lscf' (common denominator); got {method!r}"
        raise DataError(msg)
    if isinstance(selection, str) and selection != "auto":
        msg = f"selection must be 'auto' or a list of approximate natural frequencies (Hz); got {selection!r}"
        raise DataError(msg)
    if int(n_bootstrap) != n_bootstrap or n_bootstrap < 0 or n_bootstrap == 1:
        msg = f"n_bootstrap must be 0 (no standard deviations) or an integer >= 2; got {n_bootstrap!r}"
        raise DataError(msg)
    reciprocity = _reference_side(frf, reference_side)
    if reciprocity:
        frf = frf.reciprocal()
        if driving_points:
            # the pair (input i, output o) of the measurement is (input o, output i) of the reciprocal FRFs
            pairs = {}
            for inp, out in driving_points.items():
                if out not in frf.input_names or inp not in frf.output_names:
                    msg = (
                        f"driving_points: {inp!r}={out!r} must pair a measured input with a measured output; inputs: "
                        f"{', '.join(frf.output_names)}, outputs: {', '.join(frf.input_names)}"
                    )
                    raise DataError(msg)
                pairs[out] = inp
            driving_points = pairs
    tolerances = {"freq_tol": freq_tol, "damping_tol": damping_tol, "mac_tol": mac_tol, "max_damping": max_damping}
    diagram = lscf_poles(
        frf, band=band, max_order=max_order, reference="poly" if method == "plscf" else "common", freq_tol=freq_tol,
        damping_tol=damping_tol, mac_tol=mac_tol, max_damping=max_damping,
    )
    if isinstance(selection, str):
        chosen = select_poles(diagram, n_modes=n_modes, min_fraction=min_fraction)
    else:
        chosen = select_poles(diagram, near=selection)
    fit = lsfd(frf, poles=chosen, band=band, driving_points=driving_points)
    result = ModalExtraction(diagram=diagram, selection=chosen, fit=fit, method=method, reciprocity=reciprocity)
    if n_bootstrap == 0:
        return result
    freq_std, damp_std, shape_std, found = _bootstrap(
        frf, result, band=band, driving_points=driving_points, n_bootstrap=int(n_bootstrap), rng=rng,
        tolerances=tolerances,
    )
    notes = tuple(
        f"mode {r + 1} at {fit.frequency[r]:.4g} Hz was found again in only {found[r]} of {n_bootstrap} bootstrap "
        f"replicates of the data's own noise: the data do not determine it (a spurious or weakly excited mode?)"
        for r in range(fit.n_modes)
        if found[r] < n_bootstrap / 2
    ) + tuple(
        f"mode {r + 1} at {fit.frequency[r]:.4g} Hz: its damping ratio {100 * fit.damping[r]:.3g} % has a standard "
        f"deviation of {100 * damp_std[r]:.2g} %: the data hardly determine it"
        for r in range(fit.n_modes)
        if found[r] >= n_bootstrap / 2 and np.isfinite(damp_std[r]) and damp_std[r] > 0.5 * fit.damping[r]
    )
    return replace(
        result, frequency_std=freq_std, damping_std=damp_std, shape_std=shape_std, found=found,
        n_bootstrap=int(n_bootstrap), warnings=notes,
    )
