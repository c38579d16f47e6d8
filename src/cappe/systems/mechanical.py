"""Numeric second-order system ``M q'' + (C + G) q' + (K + 1j H) q = B u``, ``y = S q`` (or its derivatives).

Everything downstream — modes, FRFs, state space, transfer functions — is derived from this value.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg as sla
from numpy.typing import NDArray

from cappe.exceptions import IllConditionedWarning, ModelError
from cappe.systems.frf import FRFData
from cappe.systems.modal import ModalSet
from cappe.systems.statespace import StateSpaceModel

__all__ = ["DERIVATIVE_ORDER", "MechanicalSystem"]

Array = NDArray[np.float64]
#: Time-derivative order of each output quantity with respect to its displacement-level row.
DERIVATIVE_ORDER = {"displacement": 0, "elongation": 0, "velocity": 1, "acceleration": 2}


@dataclass(frozen=True)
class MechanicalSystem:
    """A numeric linear mechanical system at one parameter vector and axis position.

    ``S`` holds displacement-level output rows; ``output_quantities`` says whether each output is the
    displacement (or elongation), velocity or acceleration of that combination of coordinates.
    """

    M: Array
    C: Array
    K: Array
    G: Array
    H: Array
    B: Array
    S: Array
    dofs: tuple[str, ...]
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    output_quantities: tuple[str, ...]
    name: str = ""
    parameters: Mapping[str, float] = field(default_factory=dict)
    position: Mapping[str, float] = field(default_factory=dict)

    @property
    def n_dof(self) -> int:
        return int(self.M.shape[0])

    # -- selection --------------------------------------------------------------------------------
    def _indices(self, names: Sequence[str] | str | None, known: tuple[str, ...], what: str) -> list[int]:
        if names is None:
            return list(range(len(known)))
        if isinstance(names, str):
            names = [names]
        out = []
        for n in names:
            if n not in known:
                msg = f"unknown {what} {n!r} for model '{self.name}'; known: {', '.join(known) or 'none'}"
                raise ModelError(msg)
            out.append(known.index(n))
        return out

    def _mass_factor(self) -> Any:
        try:
            return sla.cho_factor(self.M)
        except np.linalg.LinAlgError as exc:
            msg = f"mass matrix of model '{self.name}' is not positive definite (non-physical masses/inertias)"
            raise ModelError(msg) from exc

    # -- modes ------------------------------------------------------------------------------------
    def undamped_modes(self) -> tuple[Array, Array]:
        """Squared natural frequencies (rad^2/s^2, ascending) and mass-normalized real mode shapes."""
        self._mass_factor()
        lam, phi = sla.eigh(self.K, self.M)
        scale = max(float(np.abs(lam).max()), 1e-300)
        lam = np.where(np.abs(lam) < 1e-10 * scale, 0.0, lam)
        if lam.min() < 0:
            msg = (
                f"stiffness matrix of model '{self.name}' is not positive semi-definite "
                f"(min eigenvalue {lam.min():.3g})"
            )
            raise ModelError(msg)
        return lam, phi

    def modes(self, damping: str = "exact") -> ModalSet:
        """Modes: ``"undamped"``, ``"first-order"`` (energy damping ratios) or ``"exact"`` (complex)."""
        if damping == "exact":
            return self._exact_modes()
        if damping not in ("undamped", "first-order"):
            msg = f"damping must be 'exact', 'first-order' or 'undamped'; got {damping!r}"
            raise ModelError(msg)
        lam, phi = self.undamped_modes()
        omega = np.sqrt(lam)
        rigid = omega == 0
        if damping == "undamped":
            zeta = np.zeros_like(omega)
        else:
            safe = np.where(rigid, 1.0, omega)
            cv = np.einsum("ir,ij,jr->r", phi, self.C, phi)
            hv = np.einsum("ir,ij,jr->r", phi, self.H, phi)
            zeta = np.where(rigid, 0.0, cv / (2 * safe) + hv / (2 * safe**2))
        poles = -zeta * omega + 1j * omega * np.sqrt(np.clip(1 - zeta**2, 0, None))
        return ModalSet(omega / (2 * np.pi), zeta, phi, poles, self.dofs, damping, rigid)

    def _exact_modes(self) -> ModalSet:
        a = self.state_matrix(hysteretic="complex")
        lam, vec = np.linalg.eig(a)
        n = self.n_dof
        scale = max(float(np.abs(lam).max()), 1.0)
        # a defective double zero eigenvalue (undamped rigid-body mode) splits by about sqrt(eps)*|A| in
        # floating point, so "zero" is judged at 1e-7 relative, well above that and well below any real mode
        lam = np.where(np.abs(lam) < 1e-7 * scale, 0.0, lam)
        tol = 1e-9 * scale
        oscill = np.where(lam.imag > tol)[0]
        real_idx = [int(i) for i in np.where(np.abs(lam.imag) <= tol)[0]]
        wn = [float(abs(lam[i])) for i in oscill]
        zeta = [float(-lam[i].real / abs(lam[i])) for i in oscill]
        poles = [complex(lam[i]) for i in oscill]
        shapes = [vec[:n, i] for i in oscill]
        rigid = [False] * len(poles)
        # real poles (overdamped or rigid-body modes) come in pairs belonging to one mode each: pair them by
        # the similarity (MAC) of their displacement shapes; then omega^2 = l1 l2 and 2 zeta omega = -(l1 + l2)
        for i, j in self._pair_real_poles(real_idx, vec[:n]):
            l1, l2 = float(lam[i].real), float(lam[j].real) if j is not None else 0.0
            w = float(np.sqrt(max(l1 * l2, 0.0))) if j is not None else abs(l1)
            is_rigid = w <= tol
            wn.append(0.0 if is_rigid else w)
            zeta.append(0.0 if is_rigid else (-(l1 + l2) / (2 * w) if j is not None else 1.0))
            poles.append(complex(max(l1, l2) if j is not None else l1, 0.0))
            shapes.append(vec[:n, i])
            rigid.append(is_rigid)
        wn_arr = np.array(wn)
        order = np.argsort(wn_arr, kind="stable")
        phi = np.array(shapes, dtype=complex).T[:, order] if shapes else np.zeros((n, 0), complex)
        for r in range(phi.shape[1]):
            k = int(np.argmax(np.abs(phi[:, r])))
            if abs(phi[k, r]) > 0:
                phi[:, r] = phi[:, r] / phi[k, r]
        return ModalSet(
            wn_arr[order] / (2 * np.pi),
            np.array(zeta)[order],
            phi,
            np.array(poles, dtype=complex)[order],
            self.dofs,
            "exact",
            np.array(rigid, dtype=bool)[order],
        )

    @staticmethod
    def _pair_real_poles(indices: list[int], shapes: NDArray[Any]) -> list[tuple[int, int | None]]:
        """Greedy pairing of real eigenvalues by the MAC of their displacement eigenvectors."""
        left = list(indices)
        pairs: list[tuple[int, int | None]] = []
        while len(left) > 1:
            best, best_mac = (left[0], left[1]), -1.0
            for a_pos, i in enumerate(left):
                for j in left[a_pos + 1 :]:
                    u, v = shapes[:, i], shapes[:, j]
                    den = float(np.real(np.vdot(u, u) * np.vdot(v, v)))
                    mac = abs(np.vdot(u, v)) ** 2 / den if den > 0 else 0.0
                    if mac > best_mac:
                        best, best_mac = (i, j), mac
            pairs.append(best)
            left = [k for k in left if k not in best]
        if left:
            pairs.append((left[0], None))
        return pairs

    # -- state space ------------------------------------------------------------------------------
    def equivalent_viscous_hysteretic(self) -> Array:
        """Viscous matrix giving each mode the first-order damping ratio of the hysteretic matrix H.

        ``C_eq = M Phi diag(phi_r^T H phi_r / omega_r) Phi^T M``: at each natural frequency the modal
        hysteretic force ``1j phi^T H phi`` equals the viscous ``1j omega phi^T C_eq phi``.
        """
        if not np.any(self.H):
            return np.zeros_like(self.C)
        lam, phi = self.undamped_modes()
        omega = np.sqrt(lam)
        hv = np.einsum("ir,ij,jr->r", phi, self.H, phi)
        coef = np.where(omega > 0, hv / np.where(omega > 0, omega, 1.0), 0.0)
        mphi = self.M @ phi
        return (mphi * coef) @ mphi.T

    def state_matrix(self, hysteretic: str = "equivalent") -> NDArray[Any]:
        """A of the first-order form with x = [q, q']; H as ``"equivalent"`` viscous or ``"complex"`` stiffness."""
        n = self.n_dof
        fac = self._mass_factor()
        stiff: NDArray[Any] = self.K.astype(complex) + 1j * self.H if hysteretic == "complex" else self.K
        damp = self.C + self.G
        if hysteretic == "equivalent":
            damp = damp + self.equivalent_viscous_hysteretic()
        a = np.zeros((2 * n, 2 * n), dtype=stiff.dtype)
        a[:n, n:] = np.eye(n)
        a[n:, :n] = -sla.cho_solve(fac, stiff)
        a[n:, n:] = -sla.cho_solve(fac, damp)
        return a

    def state_space(
        self, inputs: Sequence[str] | str | None = None, outputs: Sequence[str] | str | None = None
    ) -> StateSpaceModel:
        """Continuous state space with x = [q, q'] for the chosen inputs and outputs.

        Hysteretic damping enters as its equivalent viscous matrix (it has no exact time-domain form).
        """
        ii = self._indices(inputs, self.input_names, "input")
        oo = self._indices(outputs, self.output_names, "output")
        n = self.n_dof
        fac = self._mass_factor()
        a = self.state_matrix("equivalent")
        minv_b = sla.cho_solve(fac, self.B[:, ii])
        b = np.vstack([np.zeros((n, len(ii))), minv_b])
        c = np.zeros((len(oo), 2 * n))
        d = np.zeros((len(oo), len(ii)))
        for row, k in enumerate(oo):
            s = self.S[k]
            order = DERIVATIVE_ORDER[self.output_quantities[k]]
            if order == 0:
                c[row, :n] = s
            elif order == 1:
                c[row, n:] = s
            else:
                c[row] = s @ a[n:, :]
                d[row] = s @ minv_b
        states = tuple(self.dofs) + tuple(f"d({q})/dt" for q in self.dofs)
        return StateSpaceModel(
            a, b, c, d, None, states, tuple(self.input_names[i] for i in ii), tuple(self.output_names[k] for k in oo)
        )

    # -- frequency response -----------------------------------------------------------------------
    def frf(
        self,
        freq: Sequence[float] | NDArray[np.floating[Any]],
        inputs: Sequence[str] | str | None = None,
        outputs: Sequence[str] | str | None = None,
    ) -> FRFData:
        """Exact FRF ``H[out, in, freq]`` with complex stiffness K + 1j H (freq in Hz)."""
        f = np.atleast_1d(np.asarray(freq, dtype=float))
        if f.ndim != 1 or not np.all(np.isfinite(f)) or np.any(f < 0):
            msg = "frequencies must be a 1-D array of finite values >= 0 Hz"
            raise ModelError(msg)
        ii = self._indices(inputs, self.input_names, "input")
        oo = self._indices(outputs, self.output_names, "output")
        w = 2 * np.pi * f
        z = (
            (self.K + 1j * self.H)[None]
            + 1j * w[:, None, None] * (self.C + self.G)[None]
            - (w**2)[:, None, None] * self.M[None]
        )
        rhs = np.broadcast_to(self.B[:, ii].astype(complex), (f.size, self.n_dof, len(ii)))
        try:
            x = np.linalg.solve(z, rhs)
        except np.linalg.LinAlgError:
            x = np.empty_like(rhs)
            for k in range(f.size):
                try:
                    x[k] = np.linalg.solve(z[k], rhs[k])
                except np.linalg.LinAlgError:
                    x[k] = np.inf
                    warnings.warn(
                        f"dynamic stiffness singular at {f[k]:g} Hz (rigid-body mode or undamped "
                        f"resonance); FRF set to inf there",
                        IllConditionedWarning,
                        stacklevel=2,
                    )
        s = self.S[oo]
        h = np.einsum("oi,fij->ojf", s, x)
        orders = np.array([DERIVATIVE_ORDER[self.output_quantities[k]] for k in oo])
        h = h * ((1j * w)[None, None, :] ** orders[:, None, None])
        return FRFData(
            f,
            h,
            tuple(self.input_names[i] for i in ii),
            tuple(self.output_names[k] for k in oo),
            tuple(self.output_quantities[k] for k in oo),
        )

    def dc_gain(self, inputs: Sequence[str] | str | None = None, outputs: Sequence[str] | str | None = None) -> Array:
        """Static gain (outputs x inputs).

        Velocity and acceleration outputs have zero static gain. With rigid-body modes (singular K) the gain
        is finite when the input does no work on the rigid-body motion; when it does, the gain is inf for an
        output that sees the rigid-body motion and nan (undefined without inertia relief) for one that does not.
        """
        ii = self._indices(inputs, self.input_names, "input")
        oo = self._indices(outputs, self.output_names, "output")
        out = np.zeros((len(oo), len(ii)))
        k = self.K + 1j * self.H
        lam, phi = self.undamped_modes()
        rigid = phi[:, lam == 0]
        x, *_ = np.linalg.lstsq(k, self.B[:, ii].astype(complex), rcond=None)
        scale_b = np.abs(self.B[:, ii]).max(axis=0) + 1e-300
        excites = (
            np.abs(rigid.T @ self.B[:, ii]).max(axis=0) > 1e-9 * scale_b if rigid.size else np.zeros(len(ii), bool)
        )
        for row, o in enumerate(oo):
            if DERIVATIVE_ORDER[self.output_quantities[o]] > 0:
                continue
            sees = bool(rigid.size) and np.abs(self.S[o] @ rigid).max() > 1e-9 * (np.abs(self.S[o]).max() + 1e-300)
            values = np.real(self.S[o] @ x)
            out[row] = np.where(excites, np.inf if sees else np.nan, values) if rigid.size else values
        return out
