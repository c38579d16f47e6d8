"""The exact-mode counterpart of modal updating: residuals of a model's exact complex modes against reference
modes, with their analytic Jacobian, for the final joint refinement of the automated identification.

:class:`~cappe.estimate.ModalUpdatingEstimator` compares first-order modes (undamped modes with energy damping
ratios, light damping); :class:`ExactModalProblem` compares the state-space (complex) modes, whose difference from
first-order ones (mode complexity from non-proportional damping) would otherwise bias estimates by up to about 1 %
on closely spaced modes.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cappe.estimate._space import ParameterSpace
from cappe.estimate._validation import _pair
from cappe.modal import ModalEngine, exact_mode_derivatives
from cappe.model import NumericModel
from cappe.parallel import Executor
from cappe.systems.modal import ModalData, ModalDataSet

__all__ = ["ExactModalProblem", "realized"]

Array = NDArray[np.float64]
CArray = NDArray[np.complex128]


def realized(shapes: CArray) -> Array:
    """Real mode shapes of complex ones: each turned by the phase that makes it as real as it can be, real part kept.

    The phase is ``theta = arg(sum_i a_i^2) / 2``, which maximizes ``||Re(a exp(-i theta))||`` (the shape's
    principal direction in the complex plane); the result is the shape's best real (normal-mode) approximation,
    up to its sign. Components are along axis -2 (sensors), modes along the last axis.

    Parameters
    ----------
    shapes : ndarray of complex, shape (..., n_sensors, n_modes)
        Complex mode shapes, any scale.

    Returns
    -------
    ndarray, shape (..., n_sensors, n_modes)
        The realized shapes (same scale).

    Examples
    --------
    >>> a = np.array([[1.0 + 1.0j], [2.0 + 2.0j]])
    >>> np.round(realized(a) / np.sqrt(2), 12).ravel().tolist()
    [1.0, 2.0]
    """
    theta = 0.5 * np.angle(np.sum(shapes * shapes, axis=-2, keepdims=True))
    return np.asarray((shapes * np.exp(-1j * theta)).real, dtype=float)


class ExactModalProblem:
    """Modal residuals of the exact complex modes over all unknowns, for the final joint refinement.

    Per reference set and mode r, paired once per evaluation point with the model mode of largest MACXP
    (one-to-one): ``sqrt(w_f) (f_m - f_r) / f_r``, ``sqrt(w_z) (zeta_m - zeta_r) / zeta_r`` and the real and
    imaginary parts of ``sqrt(w_s) (a (a^H x) / (a^H a) - x)`` (complex model shape ``a``, unit reference shape
    ``x``; its squared norm is ``1 - MAC``, invariant to the arbitrary complex scale of ``a``), with
    ``f_m = |lambda| / 2 pi`` and ``zeta_m = -Re lambda / |lambda|`` as in cappe.modal/1 files. With
    ``noise = (s_f, s_z, s_s)`` (the relative noise of frequencies and damping ratios, and of shape components
    relative to each mode's largest, as ``cappe simulate`` adds it) the residuals are divided by their noise
    standard deviations instead: ``s_f``, ``s_z`` and ``s_s max|x_r| / sqrt(2)``. The Jacobian
    is analytic (first-order perturbation of each set's state-matrix eigen-decomposition, see :meth:`jacobian`),
    with the pairing of the point. The sets are evaluated side by side on a thread ``executor``.

    Parameters
    ----------
    model : NumericModel
        The model whose unknowns are refined.
    space : ParameterSpace
        The unknowns (SI vectors of ``space.n``).
    reference : ModalData
        Reference modes (Hz, damping ratios, complex shapes at the model's sensor channels) at one or more
        positions.
    weights : (float, float, float)
        ``(w_f, w_z, w_s)``: weights of the frequency, damping and shape residuals (used without ``noise``).
    noise : (float, float, float), optional
        ``(s_f, s_z, s_s)``: relative noise of the frequencies, damping ratios and shape components; replaces
        ``weights`` by the noise standard deviations.
    executor : Executor, optional
        A ``"threads"`` executor evaluates the sets side by side; any other (or None) runs them serially.
    shapes : {"complex", "real"}
        ``"real"``: model and reference shapes are each realized (:func:`realized`) before the comparison, and
        only the real shape residuals are kept: mode complexity that a rational LSCF/LSFD fit of measured FRFs
        cannot reproduce (hysteretic damping ``K + iH``, whose mirrored poles are not complex conjugates) then
        does not bias the estimates. Frequencies and damping ratios still come from the exact complex poles.
    reference_std : bool
        Weight by the reference's own standard deviations (``frequency_std``, ``damping_std``, ``shape_std`` of
        every set) where the reference has them and ``noise`` is not given (default); the divisors are then
        ``frequency_std / f``, ``damping_std / zeta`` and, per mode, the RMS over the sensors of ``shape_std /
        sqrt(2)`` (the scatter of a real or imaginary part) over ``||x||`` (the target is scaled to unit norm).
    pairing : {"macxp", "mac"}
        Pairing criterion; MACXP falls back to the MAC in a set whose reference or model damping is zero (MACXP
        degenerates for undamped poles).
    n_modes : int, optional
        Only the lowest ``n_modes`` model modes (by undamped frequency) may be paired (default all).

    Examples
    --------
    >>> from cappe.model import load_model
    >>> nm = NumericModel(load_model("builtin:two-mass-rig"))
    >>> space = ParameterSpace.from_model(nm, ["k11", "c11"])
    >>> ref = ModalEngine(nm).modal_data()
    >>> problem = ExactModalProblem(nm, space, ref, (1.0, 1.0, 1.0))
    >>> float(np.abs(problem.residuals(space.start)).max()) < 1e-9
    True
    """

    def __init__(self, model: NumericModel, space: ParameterSpace, reference: ModalData,
                 weights: tuple[float, float, float], noise: Sequence[float] | None = None,
                 executor: Executor | None = None, *, shapes: str = "complex", reference_std: bool = True,
                 pairing: str = "macxp", n_modes: int | None = None) -> None:
        # the sets (positions) are independent: with a thread executor they are evaluated side by side (LAPACK
        # releases the GIL); elsewhere the problem's closures would be shipped for every evaluation, so serially
        self._runner = executor if executor is not None and executor.kind == "threads" else Executor("serial")
        self.model = model
        self.space = space
        self.reference = reference
        if shapes not in ("complex", "real"):
            msg = f"shapes must be 'complex' or 'real'; got {shapes!r}"
            raise ValueError(msg)
        self.shapes = shapes
        self.sqrt_w = np.sqrt(np.asarray(weights, dtype=float))
        self.pairing = pairing
        self.engine = ModalEngine(model, sensors=list(reference.sensors), n_modes=n_modes, warm_start=True)
        self.positions = [model.structure.resolve_position(s.position) for s in reference.sets]
        raw = [s.shapes if shapes == "complex" else realized(s.shapes).astype(complex) for s in reference.sets]
        norms = [np.linalg.norm(x, axis=0) for x in raw]
        self.targets = [x / n[None, :] for x, n in zip(raw, norms, strict=True)]
        # residual divisors per set and mode: (frequency, damping, shape), relative to the reference's values
        self.divisors: list[tuple[Array, Array, Array]] = []
        self.weighting = "weights" if noise is None else "noise"
        with_std = reference_std and noise is None and all(
            s.frequency_std is not None and s.damping_std is not None and s.shape_std is not None
            and np.all(s.frequency_std > 0) and np.all(s.damping_std > 0) and np.all(s.shape_std > 0)
            for s in reference.sets)
        for data_set, x, n in zip(reference.sets, self.targets, norms, strict=True):
            m = x.shape[1]
            if with_std:
                self.weighting = "reference standard deviations"
                assert data_set.frequency_std is not None
                assert data_set.damping_std is not None
                assert data_set.shape_std is not None
                # shape_std is the modulus of each component's complex deviation: each of its real and imaginary
                # parts scatters by shape_std / sqrt(2); one divisor per mode, their RMS over the sensors
                part_std = np.sqrt(np.mean(data_set.shape_std ** 2, axis=0) / 2)
                div = (data_set.frequency_std / data_set.frequency, data_set.damping_std / data_set.damping,
                       part_std / n)
            elif noise is None:
                w_f, w_z, w_s = self.sqrt_w
                div = (np.full(m, 1 / w_f if w_f > 0 else 0.0), np.full(m, 1 / w_z if w_z > 0 else 0.0),
                       np.full(m, 1 / w_s if w_s > 0 else 0.0))
            else:
                s_f, s_z, s_s = (float(v) for v in noise)
                div = (np.full(m, s_f), np.full(m, s_z), s_s * np.max(np.abs(x), axis=0) / np.sqrt(2))
            self.divisors.append(div)
        self.evaluations = 0
        self._count_lock = threading.Lock()
        self._cache: dict[bytes, tuple[Array, list[NDArray[np.intp]], list[CArray]]] = {}
        self._criteria: dict[bytes, list[tuple[str, Array]]] = {}

    def _modes(self, params: Array, k: int) -> tuple[CArray, CArray]:
        batch = self.engine.evaluate(params, self.positions[k], exact=True)
        with self._count_lock:
            self.evaluations += params.shape[0]
        assert batch.poles is not None  # exact=True
        assert batch.complex_shapes is not None
        return batch.poles, batch.complex_shapes

    def _residual(self, poles: CArray, shapes: CArray, k: int, index: NDArray[np.intp]) -> Array:
        """Residuals (B, n_r) of a batch with a fixed pairing."""
        data_set = self.reference.sets[k]
        lam = poles[:, index]
        w = np.abs(lam)
        f = w / (2 * np.pi)
        zeta = -lam.real / w
        a = shapes[:, :, index]  # (B, n_s, m)
        if self.shapes == "real":
            a = realized(a).astype(complex)
        x = self.targets[k]
        c = np.sum(a.conj() * x[None], axis=1)  # a^H x
        aa = np.sum(np.abs(a) ** 2, axis=1)
        e = a * (c / aa)[:, None, :] - x[None]
        d_f, d_z, d_s = self.divisors[k]
        parts = []
        if np.all(d_f > 0):
            parts.append((f - data_set.frequency) / data_set.frequency / d_f)
        if np.all(d_z > 0):
            parts.append((zeta - data_set.damping) / data_set.damping / d_z)
        if np.all(d_s > 0):
            e = e / d_s[None, None, :]
            parts.append(e.real.reshape(e.shape[0], -1))
            if self.shapes == "complex":
                parts.append(e.imag.reshape(e.shape[0], -1))
        return np.concatenate(parts, axis=1)

    def _evaluate(self, p: Array) -> tuple[Array, list[NDArray[np.intp]], list[CArray]]:
        """Residuals at ``p``, and per set the pairing and the paired model poles (kept for the Jacobian at the
        same point, which needs them and would otherwise solve the same eigenproblem again)."""
        key = np.asarray(p, dtype=float).tobytes()
        hit = self._cache.get(key)
        if hit is not None:
            return hit
        full = self.space.full(p)[None, :]

        def one_set(k: int) -> tuple[Array, NDArray[np.intp], CArray, tuple[str, Array]]:
            poles, shapes = self._modes(full, k)
            data_set = self.reference.sets[k]
            criterion = self.pairing
            finite = poles[0][np.isfinite(poles[0]) & (np.abs(poles[0]) > 0)]
            if criterion == "macxp" and (np.any(data_set.damping <= 0) or np.any(finite.real >= 0)):
                criterion = "mac"
            index, matrix = _pair(shapes[0], poles[0], data_set, criterion)
            values = matrix[index, np.arange(index.size)]
            return self._residual(poles, shapes, k, index)[0], index, poles[0][index], (criterion, values)

        parts = self._runner.map(one_set, range(len(self.reference.sets)))
        out = (np.concatenate([r for r, _, _, _ in parts]), [index for _, index, _, _ in parts],
               [paired for _, _, paired, _ in parts])
        self._cache = {key: out}
        self._criteria = {key: [crit for _, _, _, crit in parts]}
        return out

    def residuals(self, p: Array) -> Array:
        """Residual vector at unknowns ``p`` (SI).

        Parameters
        ----------
        p : ndarray, shape (space.n,)
            The unknowns in SI units.

        Returns
        -------
        ndarray, shape (n_r,)
            Dimensionless residuals (relative frequency and damping errors, shape residuals), weighted.
        """
        return self._evaluate(np.asarray(p, dtype=float))[0]

    def jacobian(self, p: Array, parameters: Sequence[str] | None = None) -> Array:
        """``d r / d p`` (n_r, n), analytic: first-order perturbation of the state matrix's eigen-decomposition, or
        of each mode's quadratic eigenproblem where the engine solved the modes that way
        (:func:`cappe.modal.exact_mode_derivatives`), one per set instead of one per unknown; the residuals are
        invariant to the complex scale of a shape, which the shape derivatives leave out.

        Parameters
        ----------
        p : ndarray, shape (space.n,)
            The unknowns in SI units.
        parameters : sequence of str, optional
            Model parameters to differentiate by instead of the unknowns, e.g. known ones whose uncertainty the
            intervals consider (:func:`~cappe.estimate._automated_steps.robust_uncertainty`); default the unknowns.

        Returns
        -------
        ndarray, shape (n_r, space.n) or (n_r, len(parameters))
            Derivatives of the residuals by the SI parameters (1 / unit of each parameter).
        """
        p = np.asarray(p, dtype=float)
        _, _, paired = self._evaluate(p)
        full = self.space.full(p[None, :])[0]
        wanted = self.space.names if parameters is None else parameters
        columns = [self.model.parameter_names.index(n) for n in wanted]

        def one_set(k: int) -> Array:
            return self._set_jacobian(full, k, paired[k], columns, self.reference.sets[k])

        return np.concatenate(self._runner.map(one_set, range(len(self.reference.sets))), axis=0)

    def _set_jacobian(self, full: Array, k: int, paired: CArray, columns: list[int],
                      data_set: ModalDataSet) -> Array:
        """Jacobian rows of set ``k`` at the full parameter vector ``full`` (paired model poles given)."""
        names = [self.model.parameter_names[c] for c in columns]
        d = exact_mode_derivatives(self.engine, full, self.positions[k], poles=paired, parameters=names)
        lam_r, a = d.poles, d.shapes  # a: (n_s, m) complex sensor shapes (any scale)
        da = d.d_shapes  # (n_unknowns, n_s, m); every unknown at once below
        if self.shapes == "real":  # the realized shape Re(a exp(-i theta)), theta = arg(sum a^2) / 2, and its change
            total = np.sum(a * a, axis=0)
            turn = np.exp(-0.5j * np.angle(total))[None, :]
            d_theta = (np.sum(a[None] * da, axis=1) / total).imag  # (n_unknowns, m)
            # real from here on, as the realized reference shapes are: the products below in real arithmetic
            da = ((da - 1j * d_theta[:, None, :] * a[None]) * turn[None]).real
            a = (a * turn).real
        x = self.targets[k].real if self.shapes == "real" else self.targets[k]
        c = np.sum(a.conj() * x, axis=0)  # a^H x per mode
        aa = np.sum(np.abs(a) ** 2, axis=0)
        w_abs = np.abs(lam_r)
        d_f, d_z, d_s = self.divisors[k]
        d_lam = d.d_poles  # (n_unknowns, m)
        d_abs = (lam_r.conj()[None, :] * d_lam).real / w_abs
        d_zeta = -d_lam.real / w_abs + lam_r.real * d_abs / w_abs**2
        parts = []
        if np.all(d_f > 0):
            parts.append((d_abs / (2 * np.pi) / data_set.frequency).T / d_f[:, None])  # (m, n_unknowns)
        if np.all(d_z > 0):
            parts.append((d_zeta / data_set.damping).T / d_z[:, None])
        if np.all(d_s > 0):
            dc = np.sum(da.conj() * x[None], axis=1)  # (n_unknowns, m)
            daa = 2 * np.sum((a.conj()[None] * da).real, axis=1)
            de = (da * (c / aa)[None, None, :] + a[None] * (dc / aa)[:, None, :]
                  - a[None] * (c * daa / aa**2)[:, None, :]) / d_s[None, None, :]  # (n_unknowns, n_s, m)
            for part in (de.real, de.imag) if self.shapes == "complex" else (de.real,):
                parts.append(part.reshape(len(columns), -1).T)
        return np.concatenate(parts, axis=0)

    def _layout(self) -> tuple[NDArray[np.intp], NDArray[np.intp], Array, Array]:
        """Per residual, in the order of :meth:`residuals`: its mode-position pair (a running index), its kind
        (0 frequency, 1 damping, 2 shape), its divisor and its noise unit (1 for frequency and damping residuals,
        ``max|x_r| / sqrt(2)`` for the components of shape r, the unit of the shape noise level)."""
        groups, kinds, divisors, units = [], [], [], []
        start = 0
        for data_set, x, (d_f, d_z, d_s) in zip(self.reference.sets, self.targets, self.divisors, strict=True):
            m, n_s = data_set.n_modes, len(self.reference.sensors)
            modes = start + np.arange(m)
            unit = np.max(np.abs(x), axis=0) / np.sqrt(2)
            for kind, d in ((0, d_f), (1, d_z)):
                if np.all(d > 0):
                    groups.append(modes)
                    kinds.append(np.full(m, kind))
                    divisors.append(d)
                    units.append(np.ones(m))
            if np.all(d_s > 0):
                for _ in range(2 if self.shapes == "complex" else 1):
                    groups.append(np.tile(modes, n_s))  # (n_s, m) flattened row-major: mode = index % m
                    kinds.append(np.full(m * n_s, 2))
                    divisors.append(np.tile(d_s, n_s))
                    units.append(np.tile(unit, n_s))
            start += m
        return (np.concatenate(groups).astype(np.intp), np.concatenate(kinds).astype(np.intp),
                np.concatenate(divisors), np.concatenate(units))

    def groups(self) -> NDArray[np.intp]:
        """The mode-position pair of every residual (a running index over sets and their modes), in the order of
        :meth:`residuals`: the clusters of a cluster-robust covariance, since one mode's frequency, damping and
        shape errors share their causes (its extraction, its modelling).

        Returns
        -------
        ndarray of int, shape (n_r,)
        """
        return self._layout()[0]

    def scatter(self, p: Array) -> tuple[float, float, float]:
        """The residuals' own noise levels at ``p``: the rms relative frequency and damping errors, and the rms
        shape-component error in units of each mode's largest component over sqrt(2) (the ``noise`` convention).

        Parameters
        ----------
        p : ndarray, shape (space.n,)
            The unknowns in SI units (a fitted estimate).

        Returns
        -------
        (float, float, float)
            ``(s_f, s_z, s_s)``, usable as ``noise``; NaN for a kind without residuals.
        """
        _, kinds, divisors, units = self._layout()
        raw = self.residuals(p) * divisors / units
        return tuple(float(np.sqrt(np.mean(raw[kinds == k] ** 2))) if np.any(kinds == k) else math.nan
                     for k in range(3))  # type: ignore[return-value]

    def reweight(self, p: Array) -> dict[str, float] | None:
        """Divide the residuals by their own scatter at ``p`` (a fitted estimate) from now on: every mode's shape
        components by their rms, and its relative frequency and damping errors by a level per kind times the
        mode's quality ``q_r`` (its shape scatter over the median mode's; one residual per mode cannot give its
        own scatter, and a mode that an extraction got poorly, overlapped, weakly excited or heavily damped, is
        poor in all three). The levels ``c_f``, ``c_z`` make the mean square of ``e_r / (c q_r)`` one per kind.

        Parameters
        ----------
        p : ndarray, shape (space.n,)
            The unknowns in SI units.

        Returns
        -------
        dict or None
            ``frequency``, ``damping`` (the levels ``c_f``, ``c_z``) and ``shape_min``, ``shape_median``,
            ``shape_max`` (the modes' shape scatter, in units of their largest component); None, with the
            divisors unchanged, where a kind is weighted zero or some mode has no scatter (an exact reference).
        """
        groups, kinds, divisors, units = self._layout()
        if not all(np.any(kinds == k) for k in range(3)):
            return None
        raw = self.residuals(p) * divisors / units
        n_modes = [data_set.n_modes for data_set in self.reference.sets]
        total = int(sum(n_modes))
        shape = np.array([np.sqrt(np.mean(raw[(groups == g) & (kinds == 2)] ** 2)) for g in range(total)])
        if not np.all(np.isfinite(shape) & (shape > 1e-12)):
            return None
        quality = shape / np.median(shape)
        e_f = raw[kinds == 0]  # one per mode, in mode order
        e_z = raw[kinds == 1]
        c_f = float(np.sqrt(np.mean((e_f / quality) ** 2)))
        c_z = float(np.sqrt(np.mean((e_z / quality) ** 2)))
        if not (c_f > 0 and c_z > 0):
            return None
        new = []
        start = 0
        for x, m in zip(self.targets, n_modes, strict=True):
            q, s_r = quality[start:start + m], shape[start:start + m]
            new.append((c_f * q, c_z * q, s_r * np.max(np.abs(x), axis=0) / np.sqrt(2)))
            start += m
        self.divisors = new
        self._cache = {}
        return {"frequency": c_f, "damping": c_z, "shape_min": float(shape.min()),
                "shape_median": float(np.median(shape)), "shape_max": float(shape.max())}

    def pairing_report(self, p: Array) -> list[dict[str, Any]]:
        """Per set: the model mode paired with each reference mode at ``p``.

        Parameters
        ----------
        p : ndarray, shape (space.n,)
            The unknowns in SI units.

        Returns
        -------
        list of dict
            Per reference set ``{"position": {...}, "model_mode": [model mode index (0-based) per reference
            mode], "criterion": "macxp" or "mac", "value": [its value per pair]}``.
        """
        p = np.asarray(p, dtype=float)
        _, pairs, _ = self._evaluate(p)
        criteria = self._criteria[p.tobytes()]
        return [{"position": dict(s.position), "model_mode": idx.tolist(), "criterion": crit,
                 "value": values.tolist()}
                for s, idx, (crit, values) in zip(self.reference.sets, pairs, criteria, strict=True)]
