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
from cappe.systems.dynamic_stiffness import dynamic_stiffness, frf_lines
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
    ``source`` (the model file) and ``dof_entries`` (per DOF, the model entry it belongs to, such as
    ``"model.yaml, bodies[1]"``) only serve error messages.

    Every matrix must be finite (checked where a computation fails). A result that double precision cannot
    give (a natural frequency lost next to one many orders of magnitude larger, an overflow) raises
    :class:`~cappe.exceptions.ModelError`; it is never returned as NaN, inf or a wrong rigid-body mode.

    Attributes
    ----------
    M, C, K, G, H : ndarray, shape (n_dof, n_dof)
        Mass (kg, kg m^2), viscous damping (N s/m), stiffness (N/m), gyroscopic (N s/m) and hysteretic
        (N/m, the imaginary part of the complex stiffness) matrices in the generalized coordinates.
    B : ndarray, shape (n_dof, n_in)
        Generalized force per unit input.
    S : ndarray, shape (n_out, n_dof)
        Displacement-level output rows.
    dofs : tuple of str
        Names of the generalized coordinates.
    input_names, output_names : tuple of str
        Inputs and outputs, in the order of the columns of B and the rows of S.
    output_quantities : tuple of str
        ``"displacement"``, ``"elongation"``, ``"velocity"`` or ``"acceleration"`` per output.
    name : str
        Model name, for messages.
    parameters : mapping name -> float
        The parameter values (SI) the system was built at.
    position : mapping axis -> float
        The axis position (m or rad).
    source : str
        The model file, for messages.
    dof_entries : tuple of str
        Per DOF, the model entry it belongs to, for messages.
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
    source: str = ""
    dof_entries: tuple[str, ...] = ()

    def _check_finite(self) -> None:
        """Raise if a matrix has NaN or inf: checked where a computation fails (a NumericModel's systems are finite
        already; a check up front would cost every computation a pass over every matrix)."""
        for label in ("M", "C", "K", "G", "H", "B", "S"):
            value = np.asarray(getattr(self, label))
            if value.size and not np.isfinite(value).all():
                index = tuple(int(i) for i in np.argwhere(~np.isfinite(value))[0])
                msg = f"{self._where()}: matrix {label} has the non-finite entry {value[index]} at {list(index)}"
                raise ModelError(msg)

    @property
    def n_dof(self) -> int:
        return int(self.M.shape[0])

    # -- messages ---------------------------------------------------------------------------------
    def _where(self, dof: int | None = None) -> str:
        """Where an error lies: the model file (or name), and the entry of DOF ``dof`` where given."""
        if dof is not None and len(self.dof_entries) == self.n_dof:
            return f"{self.dof_entries[dof]} ({self.dofs[dof]})"
        label = self.source or f"model '{self.name}'"
        return f"{label} ({self.dofs[dof]})" if dof is not None and dof < len(self.dofs) else label

    def _dominant(self, shape: NDArray[Any]) -> int:
        """The DOF holding most of a mode's kinetic energy."""
        with np.errstate(all="ignore"):
            energy = np.nan_to_num(np.abs(np.real(np.conj(shape) * (self.M @ shape))))
        return int(np.argmax(energy))

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
        except (np.linalg.LinAlgError, ValueError) as exc:
            self._check_finite()
            raise ModelError(self._mass_message()) from exc

    def _mass_message(self) -> str:
        """Which DOFs make M indefinite: the first body (DOF label ``body.dof``) whose diagonal block is not
        positive definite, with its eigenvalues."""
        bodies: dict[str, list[int]] = {}
        for k, dof in enumerate(self.dofs):
            bodies.setdefault(dof.rpartition(".")[0], []).append(k)
        for block in bodies.values():
            eig = np.linalg.eigvalsh(self.M[np.ix_(block, block)])
            if eig.min() <= 0:
                return (f"{self._where(block[0])}: the mass matrix is not positive definite on "
                        f"{', '.join(self.dofs[k] for k in block)} (eigenvalues {', '.join(f'{e:.4g}' for e in eig)} "
                        "in kg and kg m^2): masses and inertias must be > 0")
        return f"{self._where()}: the mass matrix is not positive definite (non-physical masses or inertias)"

    # -- modes ------------------------------------------------------------------------------------
    def undamped_modes(self) -> tuple[Array, Array]:
        """Squared natural frequencies (rad^2/s^2, ascending) and mass-normalized real mode shapes.

        Squared frequencies below 1e-10 of the largest are rigid-body modes (0) where they are ones (K phi = 0 to
        round-off, row by row). An elastic mode down there keeps its value where double precision resolves it (to
        about 1e-4 above 1e-12 of the largest); below, the masses and stiffnesses span more orders of magnitude
        than double precision resolves, and a ModelError says so instead of returning a wrong rigid-body mode.
        """
        self._mass_factor()
        with np.errstate(all="ignore"):
            try:
                lam, phi = sla.eigh(self.K, self.M)
            except (np.linalg.LinAlgError, ValueError) as exc:
                raise ModelError(self._range_message("the generalized eigenproblem K phi = lambda M phi fails")) \
                    from exc
        if not (np.isfinite(lam).all() and np.isfinite(phi).all()):
            raise ModelError(self._range_message("the eigenvalues of K phi = lambda M phi overflow"))
        scale = max(float(np.abs(lam).max()), 1e-300)
        zero = np.abs(lam) < 1e-10 * scale
        if zero.any():
            elastic = np.zeros_like(zero)
            elastic[zero] = self._not_rigid(phi[:, zero])
            lost = np.flatnonzero(elastic & ~(lam >= 1e-12 * scale))
            if lost.size:
                top = np.sqrt(scale) / (2 * np.pi)
                raise ModelError(self._range_message(
                    f"a mode is taken for a rigid-body mode because its natural frequency is below 1e-6 of the "
                    f"highest ({top:.3g} Hz), but it is not one", self._dominant(phi[:, lost[0]])))
            zero &= ~elastic
        lam = np.where(zero, 0.0, lam)
        if lam.min() < 0:
            msg = (
                f"{self._where()}: the stiffness matrix is not positive semi-definite "
                f"(min eigenvalue {lam.min():.3g})"
            )
            raise ModelError(msg)
        return lam, phi

    def _not_rigid(self, shapes: Array) -> NDArray[np.bool_]:
        """Which of the modes ``shapes`` (squared frequency next to zero) are not rigid-body modes.

        A rigid-body mode has ``K phi = 0`` to round-off in every row, relative to ``|K| |phi|`` (a tolerance of
        1e-6 leaves room for mass matrices of condition up to about 1e9); an elastic mode lost next to much
        higher ones has not.
        """
        with np.errstate(all="ignore"):
            residual = np.abs(self.K @ shapes)
            size = np.abs(self.K) @ np.abs(shapes)
            ratio = np.where(size > 0, residual / np.where(size > 0, size, 1.0), 0.0)
        return np.asarray(~(ratio.max(axis=0) <= 1e-6))

    def _range_message(self, what: str, dof: int | None = None) -> str:
        """An error for values beyond double precision: ``what`` happened; the ranges of M's and K's diagonals."""
        self._check_finite()  # a NaN given in a matrix is said as such
        if dof is None:
            with np.errstate(all="ignore"):
                ratio = np.abs(np.diag(self.K)) / np.abs(np.diag(self.M))
            finite = np.where(np.isfinite(ratio), ratio, np.inf)
            dof = int(np.argmax(finite)) if finite.size else None

        def span(values: Array) -> str:
            nonzero = np.abs(values[values != 0])
            return f"{nonzero.min():.3g} to {nonzero.max():.3g}" if nonzero.size else "0"

        return (f"{self._where(dof)}: {what}: the model's masses, stiffnesses, damping or spin span too many orders of "
                f"magnitude for double precision (mass matrix diagonal {span(np.diag(self.M))}, stiffness matrix "
                f"diagonal {span(np.diag(self.K))})")

    def modes(self, damping: str = "exact") -> ModalSet:
        """Modes: ``"undamped"``, ``"first-order"`` (energy damping ratios) or ``"exact"`` (complex).

        Parameters
        ----------
        damping : {"exact", "first-order", "undamped"}
            How damping enters the modes.

        Returns
        -------
        ModalSet
            Frequencies in Hz, damping ratios and shapes at the DOFs, ascending.

        Raises
        ------
        ModelError
            ``damping`` is unknown, or double precision cannot give the modes.
        """
        if damping == "exact":
            return self._exact_modes()
        if damping not in ("undamped", "first-order"):
            msg = f"damping must be 'exact', 'first-order' or 'undamped'; got {damping!r}"
            raise ModelError(msg)
        lam, phi = self.undamped_modes()
        omega = np.sqrt(lam)
        rigid = omega == 0
        with np.errstate(all="ignore"):  # an overflow is reported below, not warned about
            if damping == "undamped":
                zeta = np.zeros_like(omega)
            else:
                safe = np.where(rigid, 1.0, omega)
                cv = np.einsum("ir,ij,jr->r", phi, self.C, phi)
                hv = np.einsum("ir,ij,jr->r", phi, self.H, phi)
                zeta = np.where(rigid, 0.0, cv / (2 * safe) + hv / (2 * safe**2))
            poles = -zeta * omega + 1j * omega * np.sqrt(np.clip(1 - zeta**2, 0, None))
        if not (np.isfinite(zeta).all() and np.isfinite(poles).all()):
            r = int(np.flatnonzero(~(np.isfinite(zeta) & np.isfinite(poles)))[0])
            raise ModelError(self._range_message(f"the damping ratio or pole of mode {r + 1} overflows",
                                                 self._dominant(phi[:, r])))
        return ModalSet(omega / (2 * np.pi), zeta, phi, poles, self.dofs, damping, rigid)

    def _exact_modes(self) -> ModalSet:
        a = self.state_matrix(hysteretic="complex")
        with np.errstate(all="ignore"):
            try:
                lam, vec = np.linalg.eig(a)
            except np.linalg.LinAlgError as exc:
                raise ModelError(self._range_message("the eigenvalues of the state matrix do not converge")) from exc
        if not (np.isfinite(lam).all() and np.isfinite(vec).all()):
            raise ModelError(self._range_message("the eigenvalues of the state matrix overflow"))
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
        if any(rigid):
            self._check_rigid_count(sum(rigid), scale)
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

    def _check_rigid_count(self, n_rigid: int, scale: float) -> None:
        """The exact complex modes' rigid-body modes must be those of the undamped problem: more are elastic modes
        whose poles are too small for the eigen-solver next to the largest (the undamped problem resolves them,
        or says why not)."""
        lam, phi = self.undamped_modes()
        lost = n_rigid - int(np.count_nonzero(lam == 0))
        if lost > 0:  # name the lowest
            r = int(np.flatnonzero(lam > 0)[0])
            low = float(np.sqrt(lam[r])) / (2 * np.pi)
            raise ModelError(self._range_message(
                f"the exact complex modes cannot resolve {lost} elastic mode(s) from {low:.3g} Hz (undamped): their "
                f"poles are below 1e-7 of the largest pole magnitude, {scale:.3g} rad/s (or 1e-7 rad/s)",
                self._dominant(phi[:, r])))

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
        """A of the first-order form with x = [q, q']; H as ``"equivalent"`` viscous or ``"complex"`` stiffness.

        Parameters
        ----------
        hysteretic : {"equivalent", "complex"}
            Hysteretic damping as its equivalent viscous matrix (real A) or as complex stiffness (complex A).

        Returns
        -------
        ndarray, shape (2 n_dof, 2 n_dof)
            In 1/s.
        """
        n = self.n_dof
        fac = self._mass_factor()
        stiff: NDArray[Any] = self.K.astype(complex) + 1j * self.H if hysteretic == "complex" else self.K
        damp = self.C + self.G
        if hysteretic == "equivalent":
            damp = damp + self.equivalent_viscous_hysteretic()
        a = np.zeros((2 * n, 2 * n), dtype=stiff.dtype)
        a[:n, n:] = np.eye(n)
        with np.errstate(all="ignore"):
            a[n:, :n] = -sla.cho_solve(fac, stiff, check_finite=False)
            a[n:, n:] = -sla.cho_solve(fac, damp, check_finite=False)
        if not np.isfinite(a).all():
            row = int(np.argwhere(~np.isfinite(a[n:]))[0][0])
            raise ModelError(self._range_message("the state matrix (M^-1 K, M^-1 C) overflows", row))
        return a

    def state_space(
        self, inputs: Sequence[str] | str | None = None, outputs: Sequence[str] | str | None = None
    ) -> StateSpaceModel:
        """Continuous state space with x = [q, q'] for the chosen inputs and outputs.

        Hysteretic damping enters as its equivalent viscous matrix (it has no exact time-domain form).

        Parameters
        ----------
        inputs, outputs : sequence of str or str, optional
            Input and output names (default all).

        Returns
        -------
        StateSpaceModel
            Continuous, in SI units.
        """
        ii = self._indices(inputs, self.input_names, "input")
        oo = self._indices(outputs, self.output_names, "output")
        n = self.n_dof
        fac = self._mass_factor()
        a = self.state_matrix("equivalent")
        with np.errstate(all="ignore"):
            minv_b = sla.cho_solve(fac, self.B[:, ii], check_finite=False)
        if not np.isfinite(minv_b).all():
            row = int(np.argwhere(~np.isfinite(minv_b))[0][0])
            raise ModelError(self._range_message("the input matrix M^-1 B overflows", row))
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
                with np.errstate(all="ignore"):
                    c[row] = s @ a[n:, :]
                    d[row] = s @ minv_b
        if not (np.isfinite(c).all() and np.isfinite(d).all()):
            raise ModelError(self._range_message("the acceleration outputs' rows S M^-1 (K, C, B) overflow"))
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
        """Exact FRF ``H[out, in, freq]`` with complex stiffness K + 1j H (freq in Hz).

        Parameters
        ----------
        freq : sequence of float
            Frequencies in Hz, >= 0.
        inputs, outputs : sequence of str or str, optional
            Input and output names (default all).

        Returns
        -------
        FRFData
            In output units per input unit (m/N, m/s/N or m/s^2/N); inf (with an IllConditionedWarning) at a line
            where the dynamic stiffness is singular.

        Raises
        ------
        ModelError
            ``freq`` is not 1-D, finite and >= 0, a name is unknown, or the response overflows.
        """
        f = np.atleast_1d(np.asarray(freq, dtype=float))
        if f.ndim != 1 or not np.all(np.isfinite(f)) or np.any(f < 0):
            msg = "frequencies must be a 1-D array of finite values >= 0 Hz"
            raise ModelError(msg)
        ii = self._indices(inputs, self.input_names, "input")
        oo = self._indices(outputs, self.output_names, "output")
        w = 2 * np.pi * f
        mats = {"M": self.M, "C": self.C, "K": self.K, "G": self.G, "H": self.H}
        orders = np.array([DERIVATIVE_ORDER[self.output_quantities[k]] for k in oo])
        with np.errstate(all="ignore"):  # an overflow is reported below, not warned about
            # a frequency so high that w^2 M is beyond double precision (looked for only where it may be)
            top = float(w.max(initial=0.0))
            bound = (float(np.abs(self.K).max() + np.abs(self.H).max()) + top * float(np.abs(self.C + self.G).max())
                     + top * top * float(np.abs(self.M).max()))
            overflow: NDArray[np.bool_] = np.zeros(f.size, dtype=bool)
            if not bound < 1e300:
                overflow = np.asarray(~np.isfinite(dynamic_stiffness(mats, w)).all(axis=(1, 2)))
            lines = frf_lines(mats, w[~overflow], self.B[:, ii], self.S[oo], orders=orders, singular="inf")
            h = np.full((len(oo), len(ii), f.size), np.nan, dtype=complex)
            h[..., ~overflow] = np.moveaxis(lines.H, 0, -1)
            singular = np.zeros(f.size, dtype=bool)
            singular[~overflow] = lines.singular
        for at in f[singular]:
            warnings.warn(
                f"dynamic stiffness singular at {at:g} Hz (rigid-body mode or undamped resonance); FRF set to inf "
                "there",
                IllConditionedWarning,
                stacklevel=2,
            )
        bad = np.flatnonzero((~np.isfinite(h).all(axis=(0, 1)) & ~singular) | overflow)
        if bad.size:
            self._check_finite()
            msg = (f"{self._where()}: the frequency response is not finite at {f[bad[0]]:g} Hz: the dynamic stiffness "
                   "K + 1j H + 1j w (C + G) - w^2 M or the response overflows double precision there")
            raise ModelError(msg)
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

        Parameters
        ----------
        inputs, outputs : sequence of str or str, optional
            Input and output names (default all).

        Returns
        -------
        ndarray, shape (n_out, n_in)
            Output units per input unit (m/N for displacements).
        """
        ii = self._indices(inputs, self.input_names, "input")
        oo = self._indices(outputs, self.output_names, "output")
        out = np.zeros((len(oo), len(ii)))
        k = self.K + 1j * self.H
        lam, phi = self.undamped_modes()  # checks that every matrix is finite
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
