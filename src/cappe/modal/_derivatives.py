"""Analytic derivatives of natural frequencies, mode shapes and first-order damping ratios.

For ``K phi_r = lambda_r M phi_r`` with mass-normalized ``phi`` and distinct eigenvalues (Fox & Kapoor;
the modal expansion is exact here because all n modes are known):

* ``d lambda_r = phi_r^T (dK - lambda_r dM) phi_r``
* ``d phi_r = sum_{s != r} phi_s^T (dK - lambda_r dM) phi_r / (lambda_r - lambda_s) phi_s
  - 1/2 (phi_r^T dM phi_r) phi_r``
* with ``zeta_r = c_r / (2 omega_r) + h_r / (2 omega_r^2)``, ``c_r = phi_r^T C phi_r``, ``h_r = phi_r^T H phi_r``:
  ``d zeta_r = dc_r / (2 omega) - c_r d omega / (2 omega^2) + dh_r / (2 omega^2) - h_r d omega / omega^3``,
  ``dc_r = phi_r^T dC phi_r + 2 phi_r^T C d phi_r`` (likewise ``dh_r``) and ``d omega = d lambda / (2 omega)``.

Exact complex modes (:func:`exact_mode_derivatives`): with the state matrix ``A V = V Lambda`` and ``W = V^-1``, a
parameter change ``dA`` moves pole r by ``(W dA V)_rr`` and its eigenvector by
``sum_{s != r} (W dA V)_sr / (lambda_r - lambda_s) v_s`` plus a multiple of ``v_r`` (a change of the arbitrary
complex scale, left out). When the engine solved the modes of the same vector on the quadratic eigenproblem
``Q(s) x = (s^2 M + s (C + G) + K + iH) x = 0`` (:class:`~cappe.modal._engine.QuadraticModes`, few modes of a large
model), each mode is differentiated on it instead, by the bordered (Nelson-type) system
``[[Q(s), Q'(s) x], [x^H, 0]] [dx; ds] = -[dQ x; 0]`` (one complex LU of order n + 1 per mode, every parameter a
right-hand side), and ``dx`` is given the state expansion's gauge: no component along the mode, ``w dv = 0`` for the
state vectors ``v = (x, s x)``, ``w = (u^T (s M + C + G), s u^T M)`` with the left eigenvector ``u^T Q(s) = 0``.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
import scipy.linalg
import scipy.sparse as sps
from numpy.typing import ArrayLike, NDArray

from cappe.exceptions import IllConditionedWarning, ModelError
from cappe.modal._engine import ModalEngine, ModeReference, QuadraticModes, StateEigensystem, _track
from cappe.model.numeric import NumericModel, ParamsLike
from cappe.model.structure import Structure
from cappe.systems.mechanical import MechanicalSystem

__all__ = ["ExactModeDerivatives", "ModalDerivatives", "exact_mode_derivatives", "modal_derivatives",
           "mode_derivative_terms"]

Array = NDArray[np.float64]
CArray = NDArray[np.complex128]
#: Eigenvalues closer than this (relative to the largest) are treated as repeated.
REPEATED_TOLERANCE = 1e-9


@dataclass(frozen=True)
class ModalDerivatives:
    """Modes at one parameter vector and their partial derivatives with respect to every parameter.

    Attributes
    ----------
    frequency : ndarray, shape (n_modes,)
        Natural frequencies in Hz.
    damping : ndarray, shape (n_modes,)
        First-order damping ratios.
    shapes : ndarray, shape (n_sensors, n_modes)
        Mass-normalized real shapes at the sensors.
    d_frequency : ndarray, shape (n_modes, n_params)
        ``d f / d p`` in Hz per parameter unit.
    d_damping : ndarray, shape (n_modes, n_params)
        ``d zeta / d p`` per parameter unit.
    d_shapes : ndarray, shape (n_sensors, n_modes, n_params)
        Derivatives of the mass-normalized shapes at the sensors.
    parameters : ndarray, shape (n_params,)
        Values of the differentiated parameters (all of the model's, or those asked for).
    parameter_names, sensors : tuple of str
    """

    frequency: Array
    damping: Array
    shapes: Array
    d_frequency: Array
    d_damping: Array
    d_shapes: Array
    parameters: Array
    parameter_names: tuple[str, ...]
    sensors: tuple[str, ...]

    def relative(self) -> tuple[Array, Array]:
        """Thesis eq. 4.12, ``(1/Q) dQ/dp``, for frequencies and damping ratios: two (n_modes, n_params)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.d_frequency / self.frequency[:, None], self.d_damping / self.damping[:, None]

    def normalized(self) -> tuple[Array, Array]:
        """Dimensionless ``(p/Q) dQ/dp`` (per cent change per per cent) for frequencies and damping ratios."""
        rel_f, rel_z = self.relative()
        return rel_f * self.parameters[None, :], rel_z * self.parameters[None, :]

    def to_dataframe(self) -> pd.DataFrame:
        """Long table of normalized sensitivities: mode, parameter, frequency and damping sensitivity."""
        nf, nz = self.normalized()
        m, n_p = nf.shape
        return pd.DataFrame({
            "mode": np.repeat(np.arange(m), n_p),
            "parameter": np.tile(np.array(self.parameter_names, dtype=object), m),
            "frequency": np.repeat(self.frequency, n_p),
            "frequency_sensitivity": nf.ravel(),
            "damping_sensitivity": nz.ravel(),
        })

    def to_dict(self) -> dict[str, Any]:
        nf, nz = self.normalized()
        return {
            "parameter_names": list(self.parameter_names),
            "frequency": self.frequency.tolist(),
            "damping": self.damping.tolist(),
            "d_frequency": self.d_frequency.tolist(),
            "d_damping": self.d_damping.tolist(),
            "normalized_frequency_sensitivity": nf.tolist(),
            "normalized_damping_sensitivity": nz.tolist(),
        }


def derivatives(
    engine: ModalEngine,
    params: ParamsLike = None,
    position: Mapping[str, float] | None = None,
    *,
    track: ModeReference | bool = False,
    parameters: Sequence[str] | None = None,
    modes: Sequence[int] | NDArray[np.intp] | None = None,
) -> ModalDerivatives:
    """Modal derivatives at one parameter vector (see :meth:`ModalEngine.derivatives`)."""
    model = engine.model
    p = model.vector(params)
    if p.ndim != 1:
        msg = "modal derivatives take a single parameter vector"
        raise ModelError(msg)
    names = tuple(model.parameter_names) if parameters is None else tuple(parameters)
    unknown = [name for name in names if name not in model.parameter_names]
    if unknown:
        msg = f"unknown parameters {unknown} for model '{model.structure.name}'"
        raise ModelError(msg)
    sel = [model.parameter_names.index(name) for name in names]
    mats = model.matrices(p, position, names=("M", "K", "C", "G", "H"))
    n = model.n_dof
    # only the undamped eigen-solution (with its PSD checks) is needed: no inputs or outputs
    system = MechanicalSystem(M=mats["M"], C=mats["C"], K=mats["K"], G=mats["G"], H=mats["H"],
                              B=np.zeros((n, 0)), S=np.zeros((0, n)), dofs=model.dofs, input_names=(),
                              output_names=(), output_quantities=(), name=model.structure.name)
    lam, phi = system.undamped_modes()
    reference = engine._reference_for(track, position)
    if reference is not None:
        index = _track(reference, phi[None, :, :])[0][0]
    else:
        index = np.arange(engine.n_modes)
    if modes is not None:
        chosen = np.asarray(modes, dtype=np.intp).reshape(-1)
        if chosen.size and (chosen.min() < -index.size or chosen.max() >= index.size):
            msg = f"modes must index the engine's {index.size} modes; got {chosen.tolist()}"
            raise ModelError(msg)
        index = index[chosen]
    scale = max(float(np.abs(lam).max()), 1e-300)
    lam_r = lam[index]
    cols = np.arange(index.size)
    denom = lam_r[None, :] - lam[:, None]  # (n, m): lambda_r - lambda_s
    own = np.arange(n)[:, None] == index[None, :]
    repeated = (np.abs(denom) <= REPEATED_TOLERANCE * scale) & ~own
    if np.any(repeated & (lam_r[None, :] > 0)):
        pairs = sorted({tuple(sorted((int(index[r]), int(s))))
                        for s, r in zip(*np.nonzero(repeated & (lam_r[None, :] > 0)), strict=True)})
        hz = np.sqrt(np.maximum(lam, 0.0)) / (2 * np.pi)
        said = "; ".join(f"modes {a + 1} and {b + 1} at {hz[a]:.6g} Hz" for a, b in pairs[:3])
        warnings.warn(
            f"model '{model.structure.name}' has (nearly) equal frequencies ({said}{' ...' if len(pairs) > 3 else ''})"
            ": their shape derivatives, and their frequency and damping derivatives for a parameter that splits the "
            "frequency, depend on which shapes are chosen for it and are not unique (computed without the coupling "
            "between them)",
            IllConditionedWarning,
            stacklevel=3,
        )
    # modal projections of the derivative matrices, (n_p, n, m): phi_s^T dX phi_r (stacked BLAS products; an
    # einsum over the three operands is several times slower here). The subproblems of the automated
    # identification project (dK - lam dM) phi_r at once instead; either order is exact, each keeps the rounding
    # its seeded results were made with (one projection here changes them in the 14th digit, at no measurable
    # gain in speed: 8 ms per call on the machine tool either way).
    # the derivative matrices times the differentiated modes from the model's sparse patterns (no dense (n_p, n, n)
    # stacks: on the three-axis machine's stiffness refinement they were a quarter of each call), (n_p, n, m) each
    # (only for the matrices the parameters move: the stiffness refinement's move no mass, and M's projection is
    # as dear as K's)
    phi_r = phi[:, index]
    moved = _moved_matrices(model, names, ("M", "K", "C", "H")) if index.size else ()
    dx_phi = model.matrix_derivative_products(p, position, phi_r, moved, parameters=names) if moved else {}
    for name in ("M", "K", "C", "H"):
        dx_phi.setdefault(name, np.zeros((len(names), n, index.size)))
    dk = phi.T @ dx_phi["K"]
    dm = phi.T @ dx_phi["M"] if "M" in moved else np.zeros_like(dk)
    coupling = dk - lam_r[None, None, :] * dm if "M" in moved else dk
    # the modes are the rows of the kernel's batch
    d_lam_t, coef = mode_derivative_terms(np.broadcast_to(lam, (index.size, n)), index,
                                          coupling.transpose(2, 0, 1), dm[:, index, cols].T)
    d_lam = d_lam_t.T  # (n_p, m)
    d_phi = phi @ np.ascontiguousarray(coef.transpose(1, 2, 0))  # (n_p, n, m)
    omega = np.sqrt(lam_r)
    rigid = omega == 0
    safe = np.where(rigid, 1.0, omega)
    d_omega = np.where(rigid, 0.0, d_lam / (2 * safe))
    c_r = np.einsum("ir,ir->r", phi_r, mats["C"] @ phi_r)  # (one BLAS product: a three-operand einsum loops)
    h_r = np.einsum("ir,ir->r", phi_r, mats["H"] @ phi_r)
    dc = np.einsum("ir,pir->pr", phi_r, dx_phi["C"]) + 2 * np.einsum("jr,pjr->pr", mats["C"].T @ phi_r, d_phi)
    dh = np.einsum("ir,pir->pr", phi_r, dx_phi["H"]) + 2 * np.einsum("jr,pjr->pr", mats["H"].T @ phi_r, d_phi)
    zeta = np.where(rigid, 0.0, c_r / (2 * safe) + h_r / (2 * safe**2))
    d_zeta = dc / (2 * safe) - c_r * d_omega / (2 * safe**2) + dh / (2 * safe**2) - h_r * d_omega / safe**3
    d_zeta = np.where(rigid, 0.0, d_zeta)
    labels, rows = engine._sensor_rows(position)
    return ModalDerivatives(
        frequency=omega / (2 * np.pi),
        damping=zeta,
        shapes=rows @ phi_r,
        d_frequency=(d_omega / (2 * np.pi)).T,
        d_damping=d_zeta.T,
        d_shapes=np.transpose(rows @ d_phi, (1, 2, 0)),
        parameters=p[sel],
        parameter_names=names,
        sensors=labels,
    )


def _moved_matrices(model: NumericModel, names: Sequence[str], wanted: Sequence[str]) -> tuple[str, ...]:
    """Those of the matrices ``wanted`` that some parameter of ``names`` moves (the others' derivatives are zero)."""
    chosen = set(names)
    return tuple(name for name in wanted if chosen & set(model.matrix_parameters(name)))


def _stack_times(stack: Array, columns: NDArray[Any]) -> CArray:
    """``stack[i] @ columns`` for every i of a real (n_p, n, n) stack and complex (n, m) columns: one sparse product
    of the stacked rows with the real and imaginary parts side by side, (n_p, n, m) (a parameter's derivative
    matrix touches the few DOFs of its element: the dense product was 5 % of the three-axis refinement)."""
    n_p, n, _ = stack.shape
    m = columns.shape[1]
    out = np.asarray(sps.csr_array(stack.reshape(n_p * n, n)) @ np.concatenate([columns.real, columns.imag], axis=1))
    return np.asarray((out[:, :m] + 1j * out[:, m:]).reshape(n_p, n, m), dtype=complex)


def mode_derivative_terms(
    lam: Array, mode: NDArray[np.intp], proj: Array, own: Array
) -> tuple[Array, Array]:
    """Eigenvalue derivatives and eigenvector expansion coefficients of one mode per row of a batch (Fox & Kapoor).

    The one kernel of the real modes' derivatives: :func:`modal_derivatives` (every mode of one vector, the modes
    as rows) and the automated identification's batched subproblems (one paired mode of each of many vectors)
    call it with the modal projections of the derivative matrices, which each forms as its data are laid out.

    Parameters
    ----------
    lam : ndarray, shape (B, m)
        Eigenvalues ``omega^2`` of every row's modes (all of them: the expansion is then exact).
    mode : ndarray of int, shape (B,)
        The mode r differentiated in each row.
    proj : ndarray, shape (B, n_p, m)
        ``phi_s^T (dK_i - lam_r dM_i) phi_r`` for every parameter i and mode s.
    own : ndarray, shape (B, n_p)
        ``phi_r^T dM_i phi_r``.

    Returns
    -------
    d_lam : ndarray, shape (B, n_p)
        ``d lambda_r / d p_i``.
    coef : ndarray, shape (B, n_p, m)
        ``d phi_r / d p_i = phi @ coef[:, i]``: ``proj / (lam_r - lam_s)`` for ``s != r``, ``-own / 2`` for
        ``s = r`` (mass normalization), 0 where ``lam_s`` (nearly) equals ``lam_r``.

    Examples
    --------
    >>> lam = np.array([[1.0, 4.0]])  # K = diag(1, 4), M = I, phi = I; dK = [[0, 1], [1, 0]], dM = 0
    >>> d_lam, coef = mode_derivative_terms(lam, np.array([0]), np.array([[[0.0, 1.0]]]), np.zeros((1, 1)))
    >>> d_lam, coef
    (array([[0.]]), array([[[-0.        , -0.33333333]]]))
    """
    rows = np.arange(lam.shape[0])
    m = lam.shape[1]
    lam_r = lam[rows, mode]
    is_own = np.arange(m)[None, :] == mode[:, None]
    denom = lam_r[:, None] - lam
    scale = np.maximum(lam.max(axis=1, keepdims=True), 1e-300)
    skip = is_own | (np.abs(denom) <= REPEATED_TOLERANCE * scale)
    safe = np.where(skip, 1.0, denom)
    d_lam = proj[rows, :, mode]  # (B, n_p)
    coef = np.where(skip[:, None, :], 0.0, proj / safe[:, None, :])
    coef[rows, :, mode] = -0.5 * own
    return np.asarray(d_lam, dtype=float), np.asarray(coef, dtype=float)

def modal_derivatives(
    model: NumericModel | Structure,
    params: ParamsLike = None,
    position: Mapping[str, float] | None = None,
    *,
    sensors: Sequence[str] | str | None = None,
    n_modes: int | None = None,
) -> ModalDerivatives:
    """Analytic derivatives of frequencies, damping ratios and shapes (function form).

    Parameters
    ----------
    model : NumericModel or Structure
        The model.
    params : array (n_params,), mapping or None
        One parameter vector (SI; a mapping overrides the nominal values).
    position : mapping or None
        Axis position in m or rad.
    sensors : sequence of str, "dofs" or None
        Channels of the shapes, as for :class:`ModalEngine`.
    n_modes : int or None
        Number of modes (lowest first); None: all.

    Returns
    -------
    ModalDerivatives

    Examples
    --------
    >>> from cappe.model import load_model
    >>> d = modal_derivatives(load_model("builtin:two-mass-rig"))
    >>> freq_sens, _ = d.normalized()
    >>> freq_sens[:, d.parameter_names.index("m1")].round(3)   # f ~ m^-1/2 for the mass-1 mode
    array([-0.008, -0.492])
    """
    return derivatives(ModalEngine(model, sensors=sensors, n_modes=n_modes), params, position)


@dataclass(frozen=True)
class ExactModeDerivatives:
    """Exact complex modes at one parameter vector and their first-order derivatives.

    Attributes
    ----------
    poles : ndarray, complex, shape (m,)
        Poles ``lambda_r`` (rad/s) of the state matrix, one per requested mode.
    shapes : ndarray, complex, shape (n_sensors, m)
        Displacement shapes at the sensors (the eigenvectors' arbitrary complex scale).
    d_poles : ndarray, complex, shape (n_params, m)
        ``d lambda / d p`` per parameter unit.
    d_shapes : ndarray, complex, shape (n_params, n_sensors, m)
        Derivatives of the shapes without their component along the shape itself (a change of scale).
    parameter_names, sensors : tuple of str
    """

    poles: CArray
    shapes: CArray
    d_poles: CArray
    d_shapes: CArray
    parameter_names: tuple[str, ...]
    sensors: tuple[str, ...]


def exact_mode_derivatives(
    engine: ModalEngine,
    params: ParamsLike,
    position: Mapping[str, float] | None,
    *,
    poles: ArrayLike,
    parameters: Sequence[str] | None = None,
) -> ExactModeDerivatives:
    """Analytic derivatives of exact complex modes: first-order perturbation of the state matrix's eigensystem.

    One eigen-decomposition of the state matrix (n_dof ``2 n``) for all parameters, instead of one per parameter.

    Parameters
    ----------
    engine : ModalEngine
        Model and sensors.
    params : mapping, sequence or ndarray of shape (n_params,), optional
        Parameter vector (default nominal).
    position : mapping, optional
        Axis position.
    poles : array_like, complex, shape (m,)
        The poles whose modes are differentiated (each picks the state matrix's nearest eigenvalue, e.g. the
        paired ``ModalBatch.poles`` of :meth:`ModalEngine.evaluate` with ``exact=True``).
    parameters : sequence of str, optional
        Parameters differentiated (default all).

    Returns
    -------
    ExactModeDerivatives

    Examples
    --------
    >>> from cappe.model import load_model
    >>> engine = ModalEngine(load_model("builtin:two-mass-rig"))
    >>> batch = engine.evaluate(None, exact=True)
    >>> d = exact_mode_derivatives(engine, None, None, poles=batch.poles[0], parameters=["k11", "m1"])
    >>> d.d_poles.shape, bool(d.d_poles[0, 1].imag > 0)   # the second mode stiffens with k11
    ((2, 2), True)
    """
    model = engine.model
    full = model.vector(params)
    names = tuple(model.parameter_names) if parameters is None else tuple(parameters)
    n = model.n_dof
    quadratic = engine._quadratic_modes(full, position)
    if quadratic is not None:
        requested = np.atleast_1d(np.asarray(poles))
        picked = np.array([int(np.argmin(np.abs(quadratic.poles - pole))) for pole in requested], dtype=np.intp)
        if np.all(np.abs(quadratic.poles[picked] - requested) <= 1e-12 * np.abs(requested)):
            return _quadratic_mode_derivatives(engine, quadratic, picked, full, position, names)
    # the decomposition the engine made for the same vector (the residuals' exact modes), else one here
    system = engine._state_eigensystem(full, position)
    if system is None:
        mats = model.matrices(full[None, :], position)
        system = StateEigensystem.of(mats, np.asarray(np.linalg.inv(mats["M"]), dtype=float)).first()
    mats, minv, lam, vec = system.mats, system.minv, system.lam, system.vec
    dmats = model.matrix_derivatives(full, position, parameters=list(names))
    stiff = mats["K"] + 1j * mats["H"]
    visc = mats["C"] + mats["G"]
    inv = np.linalg.inv(vec)
    # the requested poles are eigenvalues of the same matrix (the engine builds it alike): find their columns
    idx = np.array([int(np.argmin(np.abs(lam - pole))) for pole in np.atleast_1d(np.asarray(poles))])
    lam_r = lam[idx]
    labels, sensors = engine.sensor_rows(position)  # (n_s, n)
    gap = lam_r[None, :] - lam[:, None]  # (2n, m): lambda_r - lambda_s
    own = np.zeros(gap.shape, dtype=bool)
    own[idx, np.arange(idx.size)] = True
    scale = max(float(np.abs(lam).max()), 1e-300)
    near = own | (np.abs(gap) <= REPEATED_TOLERANCE * scale)
    safe_gap = np.where(near, 1.0, gap)
    # dA has only its lower block row, so W dA V = W[:, n:] (dA_low V): with W_low = W[:, n:] M^-1 and
    # d(M^-1 X) = M^-1 (dX - dM M^-1 X), (W dA V) = -W_low (dK~ V_q + dC~ V_v) over the requested columns only;
    # every parameter at once: (n_p n, n) derivative stacks times the requested columns, then one product by W_low
    w_low = inv[:, n:] @ minv  # (2n, n)
    v_q, v_v = vec[:n, idx], vec[n:, idx]  # displacement and velocity parts of the requested eigenvectors
    n_p, m = len(names), idx.size
    d_low = _stack_times(dmats["K"], v_q) + 1j * _stack_times(dmats["H"], v_q)
    d_low += _stack_times(dmats["C"] + dmats["G"] if "G" in dmats else dmats["C"], v_v)  # (n_p, n, m)
    with_mass = np.flatnonzero(np.any(dmats["M"] != 0, axis=(1, 2)))
    if with_mass.size:
        d_low[with_mass] -= _stack_times(dmats["M"][with_mass], minv @ (stiff @ v_q) + minv @ (visc @ v_v))
    g = -(w_low @ np.ascontiguousarray(d_low.transpose(1, 0, 2)).reshape(n, n_p * m)).reshape(2 * n, n_p, m)
    d_poles = g[idx, :, np.arange(m)].T  # (n_p, m): (W dA V)_{r r}
    coef = np.where(near[:, None, :], 0.0, g / safe_gap[:, None, :])
    d_shapes = ((sensors @ vec[:n]) @ coef.reshape(2 * n, n_p * m)).reshape(sensors.shape[0], n_p, m)
    return ExactModeDerivatives(
        poles=lam_r,
        shapes=sensors @ v_q,
        d_poles=np.asarray(d_poles, dtype=complex).reshape(n_p, m),
        d_shapes=np.ascontiguousarray(d_shapes.transpose(1, 0, 2), dtype=complex),
        parameter_names=names,
        sensors=labels,
    )


def _quadratic_mode_derivatives(engine: ModalEngine, modes: QuadraticModes, picked: NDArray[np.intp], full: Array,
                                position: Mapping[str, float] | None, names: tuple[str, ...]) -> ExactModeDerivatives:
    """:func:`exact_mode_derivatives` of the modes ``picked`` of the quadratic-eigenproblem solution ``modes``: per
    mode one LU of the bordered system (module notes), every parameter at once. The bordered matrices and right-hand
    sides of all modes are formed at once, in the Fortran order LAPACK takes without a copy; the per-mode work is the
    ``getrf`` and its two ``getrs`` alone, and the gauge and the sensor rows are one product for all modes."""
    model = engine.model
    mats = modes.mats
    mass, visc = mats["M"], mats["C"] + mats["G"]
    stiff = mats["K"] + 1j * mats["H"]
    labels, sensors = engine.sensor_rows(position)
    n, n_p, m = model.n_dof, len(names), picked.size
    lam_r = modes.poles[picked]
    x_all = modes.shapes[:, picked]
    d_poles = np.zeros((n_p, m), dtype=complex)
    d_shapes = np.zeros((n_p, sensors.shape[0], m), dtype=complex)
    moving = np.flatnonzero(lam_r != 0)  # rigid-body modes keep pole 0 and their real shape: derivatives 0
    if moving.size:
        s, x, k = lam_r[moving], x_all[:, moving], moving.size
        # dX x per parameter for every moving mode, from the model's sparse patterns, for the matrices the parameters
        # move only (the joint refinement's stiffness and damping unknowns move no mass; 62 -> 55 ms per position of
        # the three-axis machine, best of four interleaved runs): (n_p, n, k) each
        moved = _moved_matrices(model, names, ("M", "C", "G", "K", "H"))
        products = model.matrix_derivative_products(full, position, x, moved, parameters=list(names)) if moved else {}
        # -dQ x = -(s^2 dM x + s (dC + dG) x + dK x + i dH x) per parameter and mode, laid out (k, n_p, n + 1):
        # rhs[j].T is mode j's (n + 1, n_p) right-hand side in Fortran order
        rhs = np.zeros((k, n_p, n + 1), dtype=complex)
        body = rhs[:, :, :n]
        ones = np.ones(k)
        for name, factor in (("M", -(s * s)), ("C", -s), ("G", -s), ("K", -ones), ("H", -1j * ones)):
            if name in products:
                body += products[name].transpose(2, 0, 1) * factor[:, None, None]
        # the bordered matrices, transposed (C order): [[Q(s), Q'(s) x], [x^H scaled, 0]]^T per mode
        flat_t = np.stack([mass.T, visc.T, stiff.T]).astype(complex).reshape(3, n * n)  # Q(s)^T = (s^2, s, 1) @ flat_t
        border_t = np.zeros((k, n + 1, n + 1), dtype=complex)
        border_t[:, :n, :n] = (np.stack([s * s, s, np.ones(k)], axis=1) @ flat_t).reshape(k, n, n)
        mx = mass @ x
        border_t[:, n, :n] = (2 * s * mx + visc @ x).T  # Q'(s) x
        # the normalization row x^H dx = 0, scaled to Q's entries (partial pivoting compares rows)
        biggest = (float(np.abs(mass).max()), float(np.abs(visc).max()), float(np.abs(stiff).max()))
        size = np.abs(s) ** 2 * biggest[0] + np.abs(s) * biggest[1] + biggest[2]
        border_t[:, :n, n] = (size / np.sum(np.abs(x) ** 2, axis=0))[:, None] * x.conj().T
        getrf, getrs = scipy.linalg.lapack.zgetrf, scipy.linalg.lapack.zgetrs
        unit = np.zeros(n + 1, dtype=complex)
        unit[n] = 1.0
        left = np.empty((k, n), dtype=complex)
        for j in range(k):
            lu, piv, info = getrf(border_t[j].T, overwrite_a=True)
            if info != 0:
                msg = f"the bordered system of mode {moving[j] + 1} is singular (a repeated pole)"
                raise ModelError(msg)
            left[j] = getrs(lu, piv, unit, trans=1)[0][:n]  # u^T Q(s) = 0, u^T Q'(s) x = 1
            rhs[j] = getrs(lu, piv, rhs[j].T, overwrite_b=True)[0].T
        dx, ds = rhs[:, :, :n], rhs[:, :, n]  # (k, n_p, n), (k, n_p)
        # the state expansion's gauge: w dv = u^T Q'(s) dx + ds u^T M x = 0, a multiple of x added to dx
        left_mv = left @ np.concatenate([mass, visc], axis=1)
        left_mass, left_visc = left_mv[:, :n], left_mv[:, n:]
        gauge = 2 * s[:, None] * left_mass + left_visc  # u^T Q'(s), (k, n)
        along = -(np.einsum("jn,jpn->jp", gauge, dx) + ds * np.einsum("jn,nj->j", left_mass, x)[:, None])
        dx += along[:, :, None] * x.T[:, None, :]
        d_poles[:, moving] = ds.T
        # the sensor rows are sparse (a few DOFs each): one sparse product for every mode and parameter
        at_sensors = sps.csr_array(sensors) @ dx.reshape(k * n_p, n).T  # (n_s, k n_p)
        d_shapes[:, :, moving] = at_sensors.reshape(-1, k, n_p).transpose(2, 0, 1)
    return ExactModeDerivatives(
        poles=lam_r,
        shapes=sensors @ x_all,
        d_poles=d_poles,
        d_shapes=d_shapes,
        parameter_names=names,
        sensors=labels,
    )
