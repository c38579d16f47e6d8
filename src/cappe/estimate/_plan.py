"""Test planning: which axis positions and sensor channels make the unknowns identifiable, before the test is run.

The criterion is the Fisher information of the modal data that ``cappe identify`` fits, under the noise model
that ``cappe simulate`` adds and ``cappe identify --noise-*`` weights by (independent Gaussian errors):

* each frequency ``f (1 + s_f e)``: one observation ``(d f / d theta) / (f s_f)`` per mode and position;
* each damping ratio ``zeta (1 + s_z e)``: ``(d zeta / d theta) / (zeta s_z)``;
* each shape, compared as the unit vector ``x = phi_S / |phi_S|`` over the measured channels ``S`` with complex
  noise of RMS modulus ``s_s max|phi_S|`` per component (its real part has std ``s_s max|x| / sqrt 2``, the
  divisor of :class:`ExactModalProblem`): ``(I - x x^T) (d phi_S / d theta) / |phi_S| / (s_s max|x| / sqrt 2)``
  (the projection removes the arbitrary scale, to which the MAC-type shape residual is blind).

``theta = log p`` for every unknown p, so the inverse Fisher matrix's diagonal is the squared relative std. The
derivatives are the exact first-order ones of :meth:`cappe.modal.ModalEngine.derivatives` (undamped modes and
energy damping ratios; for light damping they equal the exact complex modes' to first order in the damping).
A mode enters a plan only where the measured channels see it: where its largest measured component is at least
``visibility`` times its largest component over all candidate channels (else a test would not find the mode).

Why D-optimality (``log det`` of the Fisher matrix) with greedy selection and exchange: it is invariant to the
scaling of the unknowns, so stiffnesses, dampings and masses of very different sizes compete fairly; it rewards
determining every unknown (one undetermined direction costs a factor ``delta`` in the determinant) rather than
piling information on the best-determined ones, which the trace of the Fisher matrix (T-optimality) rewards; and on
the modal sensitivities it selects positions and sensors together, which effective independence (a sensor criterion
on a fixed mode-shape matrix, Kammer 1991) does not: here the unknowns are the target, not the mode shapes. A weak
prior ``delta I`` (relative std 1000, ``delta = 1e-6``) keeps the criterion finite while a plan is still rank
deficient, so the greedy steps can rank candidates. Greedy selection with pairwise exchange (Fedorov's exchange on
the discrete candidates) is not guaranteed to reach the exhaustive optimum, but every plan it returns has no single
improving swap. Plans are compared by the median expected std over the unknowns that every candidate together
determines (:attr:`MeasurementPlan.median_relative_std_determinable`): on the three-axis machine the D-optimal plan
is best there (2.3 % against 3.5-4.4 % for 10 random plans) but not by the median over all 61 unknowns (6.5 %
against 6.1-20 %), which also counts the 17 that even every candidate together leaves undetermined. An A-optimal
search (the sum of the determinable unknowns' log-variances) reached 5.6 % over all 61 but 3.2 % over the
determinable ones and a smaller determinant: neither criterion aims at the median over all; D-optimality is kept.

The search never builds a trial plan's Jacobian: at a position the Fisher matrix of a channel set is a sum over the
seen modes of terms built from statistics that add over channels (``sum dphi dphi^T``, ``sum phi dphi``,
``sum phi^2``, ``max |phi|``; see :class:`_FisherCache`), and a plan's matrix is the sum over its positions. Every
channel added to (or swapped into) a set is then one batch of matrix products from sensitivities computed once
per candidate position, and a position swap only sums cached blocks (the three-axis machine's 4-of-27-position,
24-of-117-channel plan: 36 s of CPU before, 7.6 s after, the same plan; ``benchmarks/bench_plan.py speed``).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cappe.estimate._uncertainty import LocalUncertainty, jacobian_uncertainty
from cappe.exceptions import ModelError
from cappe.modal import ModalEngine
from cappe.model.numeric import NumericModel, ParamsLike

__all__ = ["PLAN_FORMAT", "MeasurementPlan", "PlanCandidates", "plan_fisher", "plan_test"]

Array = NDArray[np.float64]
PLAN_FORMAT = "cappe.plan/1"
#: Weak prior information on every log-parameter (relative std 1000): keeps log det finite while rank deficient.
PRIOR = 1e-6
#: Exchange passes (positions, then sensors) at most.
MAX_PASSES = 10


@dataclass(frozen=True)
class PlanCandidates:
    """Modal derivatives at every candidate position, at every candidate sensor channel, for the unknowns.

    Built once by :meth:`from_model`; every plan (a subset of positions and of channels) is evaluated from it.

    Attributes
    ----------
    model_name : str
        The model.
    unknowns : tuple of str
        The parameters whose std is planned for.
    values : ndarray, shape (n_p,)
        Their values (SI) at which the derivatives are taken.
    positions : tuple of dict
        Candidate axis positions (m or rad).
    sensors : tuple of str
        Candidate sensor channels ``NODE:DIR``.
    frequency, damping : ndarray, shape (n_pos, n_modes)
        Frequencies (Hz) and first-order damping ratios.
    d_frequency, d_damping : ndarray, shape (n_pos, n_modes, n_p)
        ``d f / d log p`` and ``d zeta / d log p``.
    shapes : ndarray, shape (n_pos, n_sensors, n_modes)
        Real mass-normalized shapes at the channels.
    d_shapes : ndarray, shape (n_pos, n_sensors, n_modes, n_p)
        ``d phi / d log p``.
    noise : (float, float, float)
        Relative noise of frequencies, damping ratios and shape components.
    visibility : float
        A mode enters a plan where its largest measured component is at least this fraction of its largest.
    """

    model_name: str
    unknowns: tuple[str, ...]
    values: Array
    positions: tuple[dict[str, float], ...]
    sensors: tuple[str, ...]
    frequency: Array
    damping: Array
    d_frequency: Array
    d_damping: Array
    shapes: Array
    d_shapes: Array
    noise: tuple[float, float, float]
    visibility: float

    @classmethod
    def from_model(
        cls,
        model: NumericModel,
        *,
        unknowns: Sequence[str] | None = None,
        params: ParamsLike = None,
        positions: Sequence[Mapping[str, float]] | None = None,
        sensors: Sequence[str] | None = None,
        n_modes: int = 20,
        noise: Sequence[float] = (0.005, 0.05, 0.02),
        visibility: float = 0.05,
    ) -> PlanCandidates:
        """Derivatives of the lowest ``n_modes`` modes at every candidate position and channel.

        Parameters
        ----------
        model : NumericModel
            The model.
        unknowns : sequence of str, optional
            Parameters to plan for (default: those marked ``unknown`` in the model).
        params : mapping, array or None
            Parameter values (SI) at which to plan (default nominal).
        positions : sequence of mapping, optional
            Candidate axis positions (default: every combination of the model's listed positions).
        sensors : sequence of str, optional
            Candidate channels ``NODE:DIR`` or node names (default: every channel of the model's sensor nodes).
        n_modes : int
            Modes per position (the lowest), as ``cappe simulate --modes``.
        noise : (float, float, float)
            Relative std of frequencies, damping ratios and shape components (as ``cappe simulate --noise-*``).
        visibility : float
            Fraction of a mode's largest candidate component its measured channels must reach (0 to 1).

        Returns
        -------
        PlanCandidates
        """
        structure = model.structure
        names = [p.name for p in structure.parameters if p.unknown] if unknowns is None else list(unknowns)
        if not names:
            msg = f"model '{structure.name}' has no unknowns to plan for; mark some 'unknown: true' or name them"
            raise ModelError(msg)
        levels = tuple(float(v) for v in noise)
        if len(levels) != 3 or not all(np.isfinite(v) and v > 0 for v in levels):
            msg = f"noise must be three numbers > 0 (frequency, damping, shape); got {tuple(noise)!r}"
            raise ModelError(msg)
        if not 0.0 <= visibility < 1.0:
            msg = f"visibility must be in [0, 1); got {visibility!r}"
            raise ModelError(msg)
        if positions is None:
            axes = structure.axes
            combos = itertools.product(*[a.positions or (0.0,) for a in axes])
            positions = [dict(zip([a.name for a in axes], c, strict=True)) for c in combos]
        resolved = tuple(structure.resolve_position(p) for p in positions)
        if not resolved:
            msg = f"no candidate positions for model '{structure.name}'"
            raise ModelError(msg)
        if sensors is None and not structure.sensors:
            msg = f"model '{structure.name}' has no sensor nodes to plan with; add a 'sensors:' list or name channels"
            raise ModelError(msg)
        if not 1 <= n_modes <= model.n_dof:
            msg = f"n_modes must be from 1 to {model.n_dof} for model '{structure.name}'; got {n_modes}"
            raise ModelError(msg)
        engine = ModalEngine(model, sensors=None if sensors is None else list(sensors), n_modes=n_modes)
        derivs = [engine.derivatives(params, p, parameters=names) for p in resolved]
        rel = derivs[0].parameters  # d/d log p = p d/dp
        if np.any(rel <= 0):
            bad = [n for n, v in zip(names, rel, strict=True) if v <= 0]
            msg = f"unknowns must be positive to plan in relative terms; {bad} are not"
            raise ModelError(msg)
        return cls(
            model_name=structure.name,
            unknowns=tuple(names),
            values=rel,
            positions=resolved,
            sensors=tuple(engine.sensors),
            frequency=np.array([d.frequency for d in derivs]),
            damping=np.array([d.damping for d in derivs]),
            d_frequency=np.array([d.d_frequency * rel for d in derivs]),
            d_damping=np.array([d.d_damping * rel for d in derivs]),
            shapes=np.array([d.shapes for d in derivs]),
            d_shapes=np.array([d.d_shapes * rel for d in derivs]),
            noise=(levels[0], levels[1], levels[2]),
            visibility=float(visibility),
        )

    def jacobian(self, positions: Sequence[int], sensors: Sequence[int]) -> Array:
        """Noise-normalized sensitivities (n_obs, n_p) of a plan's observations to the log-unknowns.

        Parameters
        ----------
        positions : sequence of int
            Indices into :attr:`positions`.
        sensors : sequence of int
            Indices into :attr:`sensors`.

        Returns
        -------
        ndarray, shape (n_obs, n_p)
            One row per frequency, damping ratio and shape component the plan measures.
        """
        s_f, s_z, s_s = self.noise
        chans = np.asarray(sensors, dtype=np.intp)
        rows: list[Array] = []
        for j in positions:
            phi = self.shapes[j][chans]  # (n_s, m)
            top = np.max(np.abs(self.shapes[j]), axis=0)
            seen = (np.max(np.abs(phi), axis=0) >= self.visibility * top) & (top > 0)
            rows.append(self.d_frequency[j, seen] / (self.frequency[j, seen] * s_f)[:, None])
            damped = seen & (self.damping[j] > 0)
            rows.append(self.d_damping[j, damped] / (self.damping[j, damped] * s_z)[:, None])
            norm = np.linalg.norm(phi, axis=0)
            shaped = seen & (norm > 0)
            if chans.size < 2 or not np.any(shaped):
                continue  # one channel: its unit shape is a constant, no information
            x = phi[:, shaped] / norm[shaped]  # (n_s, m')
            dphi = self.d_shapes[j][chans][:, shaped, :]  # (n_s, m', n_p)
            dx = (dphi - x[:, :, None] * np.einsum("sm,smp->mp", x, dphi)[None]) / norm[shaped][None, :, None]
            dx = dx / (s_s * np.max(np.abs(x), axis=0) / np.sqrt(2.0))[None, :, None]
            rows.append(dx.transpose(1, 0, 2).reshape(-1, dx.shape[2]))
        n_p = len(self.unknowns)
        return np.concatenate(rows, axis=0) if rows else np.zeros((0, n_p))

    def fisher(self, positions: Sequence[int], sensors: Sequence[int]) -> Array:
        """Fisher information (n_p, n_p) of a plan in log-unknowns (see :meth:`jacobian`).

        Parameters
        ----------
        positions : sequence of int
            Indices into :attr:`positions`.
        sensors : sequence of int
            Indices into :attr:`sensors`.

        Returns
        -------
        ndarray, shape (n_p, n_p)
        """
        jac = self.jacobian(positions, sensors)
        return jac.T @ jac

    def criterion(self, positions: Sequence[int], sensors: Sequence[int]) -> float:
        """D-criterion ``log det(F + PRIOR I)`` of a plan (larger is better).

        Parameters
        ----------
        positions : sequence of int
            Indices into :attr:`positions`.
        sensors : sequence of int
            Indices into :attr:`sensors`.

        Returns
        -------
        float
        """
        fisher = self.fisher(positions, sensors)
        return float(np.linalg.slogdet(fisher + PRIOR * np.eye(fisher.shape[0]))[1])

    def uncertainty(self, positions: Sequence[int], sensors: Sequence[int]) -> LocalUncertainty:
        """Expected std, rank and undetermined combinations of a plan (Cramer-Rao, unit noise variance).

        Parameters
        ----------
        positions : sequence of int
            Indices into :attr:`positions`.
        sensors : sequence of int
            Indices into :attr:`sensors`.

        Returns
        -------
        LocalUncertainty
            In SI units of the unknowns (std nan where a direction is undetermined).
        """
        jac = self.jacobian(positions, sensors)
        return jacobian_uncertainty(names=self.unknowns, values=self.values, jacobian=jac / self.values[None, :],
                                    residuals=np.zeros(jac.shape[0]), noise_variance=1.0)


@dataclass(frozen=True)
class MeasurementPlan:
    """A chosen test plan and what it is expected to determine.

    Attributes
    ----------
    candidates : PlanCandidates
        What the plan was chosen from.
    position_index, sensor_index : tuple of int
        The chosen positions and channels (indices into the candidates).
    criterion : float
        ``log det(F + PRIOR I)`` of the plan.
    uncertainty : LocalUncertainty
        Expected std (SI) of every unknown under the plan.
    relative_std : ndarray, shape (n_p,)
        std over value (inf where undetermined).
    best_relative_std : ndarray, shape (n_p,)
        The same with every candidate position and channel measured (not a strict bound, see
        :attr:`undetermined_with_all`).
    max_relative_std : float
        Above this relative std an unknown counts as not determined.
    random : dict
        Random plans of the same size for comparison: their criteria and median relative std.
    """

    candidates: PlanCandidates
    position_index: tuple[int, ...]
    sensor_index: tuple[int, ...]
    criterion: float
    uncertainty: LocalUncertainty
    relative_std: Array
    best_relative_std: Array
    max_relative_std: float
    random: dict[str, Any] = field(default_factory=dict)

    @property
    def positions(self) -> list[dict[str, float]]:
        """The chosen axis positions."""
        return [dict(self.candidates.positions[i]) for i in self.position_index]

    @property
    def sensors(self) -> list[str]:
        """The chosen sensor channels."""
        return [self.candidates.sensors[i] for i in self.sensor_index]

    @property
    def undetermined(self) -> list[str]:
        """Unknowns whose expected relative std exceeds :attr:`max_relative_std` (or that are not identifiable)."""
        return [n for n, s in zip(self.candidates.unknowns, self.relative_std, strict=True)
                if not s <= self.max_relative_std]

    @property
    def undetermined_with_all(self) -> list[str]:
        """Unknowns left above :attr:`max_relative_std` even with every candidate measured.

        Not a proof over all plans: a channel with a large component raises the shape noise of the others (it is
        relative to the largest measured component), so a subset can determine a shape-borne unknown better.
        """
        return [n for n, s in zip(self.candidates.unknowns, self.best_relative_std, strict=True)
                if not s <= self.max_relative_std]

    @property
    def median_relative_std_determinable(self) -> float:
        """Median expected relative std over the unknowns that every candidate together determines (nan if none).

        The summary to compare plans by: the median over all unknowns also counts those no plan determines, whose
        std (large or infinite) pushes the median onto whichever weakly determined unknowns a plan happens to
        reach, not onto how well it determines what can be determined.
        """
        keep = self.best_relative_std <= self.max_relative_std
        return float(np.median(self.relative_std[keep])) if np.any(keep) else math.nan

    def to_dict(self) -> dict[str, Any]:
        c = self.candidates
        std = self.uncertainty.std

        def num(v: float) -> float | None:
            return float(v) if np.isfinite(v) else None

        return {
            "format": PLAN_FORMAT,
            "model": c.model_name,
            "criterion": {"name": "D-optimal Fisher information", "log_det": self.criterion, "prior": PRIOR},
            "noise": dict(zip(("frequency", "damping", "shape"), c.noise, strict=True)),
            "n_modes": int(c.frequency.shape[1]),
            "visibility": c.visibility,
            "positions": self.positions,
            "sensors": self.sensors,
            "unknowns": {
                n: {"value": float(v), "std": num(s), "relative_std": num(r), "relative_std_all_candidates": num(b),
                    "determined": bool(r <= self.max_relative_std)}
                for n, v, s, r, b in zip(c.unknowns, c.values, std, self.relative_std, self.best_relative_std,
                                         strict=True)
            },
            "max_relative_std": self.max_relative_std,
            "undetermined": self.undetermined,
            "undetermined_with_all_candidates": self.undetermined_with_all,
            "median_relative_std": float(np.median(self.relative_std)),
            "median_relative_std_determinable": num(self.median_relative_std_determinable),
            "combinations": list(self.uncertainty.combinations),
            "rank": self.uncertainty.rank,
            "candidates": {"positions": [dict(p) for p in c.positions], "sensors": list(c.sensors)},
            "random_plans": self.random,
        }


def plan_fisher(candidates: PlanCandidates, positions: Sequence[int], sensors: Sequence[int]) -> Array:
    """Fisher information of a plan in log-unknowns (function form of :meth:`PlanCandidates.fisher`).

    Parameters
    ----------
    candidates : PlanCandidates
        The candidates' derivatives.
    positions, sensors : sequence of int
        Indices of the plan's positions and channels.

    Returns
    -------
    ndarray, shape (n_p, n_p)
    """
    return candidates.fisher(positions, sensors)


def _relative(unc: LocalUncertainty) -> Array:
    rel = unc.std / np.abs(unc.values)
    return np.where(unc.identifiable & np.isfinite(rel), rel, np.inf)


class _FisherCache:
    """Per-position Fisher blocks of channel sets, from statistics computed once per candidate position.

    At one position the Fisher information of a channel set ``S`` is a sum over the modes the set sees of the
    frequency and damping rows' outer products and the shape term (see :meth:`PlanCandidates.jacobian`)

        ``2 / (s_s^2 M_m^2) (A_m(S) - b_m(S) b_m(S)^T / n_m(S))``, with ``A_m = sum_S dphi dphi^T``,
        ``b_m = sum_S phi dphi``, ``n_m = sum_S phi^2`` and ``M_m = max_S |phi|``,

    (the projection of the unit shape written out), so every statistic adds over channels and a plan's Fisher
    matrix adds over positions. A search step then evaluates every candidate channel added to a base set in one
    batch of matrix products, and a position step only sums cached blocks; :meth:`PlanCandidates.fisher` is the
    reference it equals (to rounding).
    """

    def __init__(self, candidates: PlanCandidates) -> None:
        c = candidates
        s_f, s_z, s_s = c.noise
        self.c = c
        self.n_p = len(c.unknowns)
        self.top = np.max(np.abs(c.shapes), axis=1)  # (n_pos, m)
        freq = c.d_frequency / (c.frequency * s_f)[..., None]
        damped = c.damping > 0
        damp = np.where(damped[..., None], c.d_damping / np.where(damped, c.damping * s_z, 1.0)[..., None], 0.0)
        self.damped = damped
        # outer products of the frequency and damping rows, (n_pos, m, n_p * n_p)
        self.freq_outer = np.einsum("jmp,jmq->jmpq", freq, freq).reshape(*freq.shape[:2], -1)
        self.damp_outer = np.einsum("jmp,jmq->jmpq", damp, damp).reshape(*damp.shape[:2], -1)
        self.shape_weight = 2.0 / s_s**2
        self._blocks: dict[tuple[int, tuple[int, ...]], Array] = {}

    def added(self, position: int, base: Sequence[int], adds: Sequence[int]) -> Array:
        """Fisher blocks (n_add, n_p, n_p) at one position of ``base`` plus each channel of ``adds`` in turn.

        Parameters
        ----------
        position : int
            Index of the candidate position.
        base : sequence of int
            Channels measured in every set (may be empty).
        adds : sequence of int
            Channels, each added to ``base`` alone.

        Returns
        -------
        ndarray, shape (n_add, n_p, n_p)
        """
        c, j, n_p = self.c, position, self.n_p
        base_idx = np.asarray(base, dtype=np.intp)
        add_idx = np.asarray(adds, dtype=np.intp)
        phi_b = c.shapes[j][base_idx]  # (n_b, m)
        d_b = c.d_shapes[j][base_idx]  # (n_b, m, n_p)
        d_m = d_b.transpose(1, 0, 2)  # (m, n_b, n_p)
        a_sum = np.matmul(d_m.transpose(0, 2, 1), d_m).reshape(phi_b.shape[1], -1)  # (m, n_p^2)
        b_sum = np.matmul(phi_b.T[:, None, :], d_m)[:, 0, :]  # (m, n_p)
        n_sum = np.sum(phi_b**2, axis=0)  # (m,)
        top_b = np.max(np.abs(phi_b), axis=0) if base_idx.size else np.zeros(phi_b.shape[1])
        phi_a = c.shapes[j][add_idx]  # (n_a, m)
        d_a = c.d_shapes[j][add_idx]  # (n_a, m, n_p)
        top = np.maximum(top_b[None, :], np.abs(phi_a))
        seen = (top >= c.visibility * self.top[j][None, :]) & (self.top[j] > 0)[None, :]
        fisher = seen.astype(float) @ self.freq_outer[j] + (seen & self.damped[j][None, :]).astype(float) @ \
            self.damp_outer[j]
        n_new = n_sum[None, :] + phi_a**2
        if base_idx.size + 1 >= 2:  # one channel: its unit shape is a constant, no information
            shaped = seen & (n_new > 0)
            weight = np.where(shaped, self.shape_weight / np.where(shaped, top, 1.0) ** 2, 0.0)  # (n_a, m)
            fisher = fisher + weight @ a_sum
            root = np.sqrt(weight)[..., None]
            scaled = root * d_a  # (n_a, m, n_p)
            fisher = fisher + np.matmul(scaled.transpose(0, 2, 1), scaled).reshape(len(add_idx), -1)
            b_new = (b_sum[None] + phi_a[..., None] * d_a) * (root / np.sqrt(np.where(shaped, n_new, 1.0))[..., None])
            fisher = fisher - np.matmul(b_new.transpose(0, 2, 1), b_new).reshape(len(add_idx), -1)
        return np.asarray(fisher, dtype=float).reshape(len(add_idx), n_p, n_p)

    def block(self, position: int, sensors: Sequence[int]) -> Array:
        """The Fisher block (n_p, n_p) of one channel set at one position (cached).

        Parameters
        ----------
        position : int
            Index of the candidate position.
        sensors : sequence of int
            The channels (at least one).

        Returns
        -------
        ndarray, shape (n_p, n_p)
        """
        key = (position, tuple(sorted(sensors)))
        if key not in self._blocks:
            self._blocks[key] = self.added(position, key[1][:-1], key[1][-1:])[0]
        return self._blocks[key]


def _log_det(fisher: Array) -> Array:
    """``log det(F + PRIOR I)`` of one matrix or a stack of them."""
    eye = PRIOR * np.eye(fisher.shape[-1])
    return np.asarray(np.linalg.slogdet(fisher + eye)[1], dtype=float)


def _improves(value: float, best: float) -> bool:
    return value > best + 1e-9 * max(1.0, abs(best))


def _greedy_positions(cache: _FisherCache, pool: Sequence[int], sensors: Sequence[int], size: int) -> list[int]:
    blocks = np.array([cache.block(j, sensors) for j in pool])
    chosen: list[int] = []
    total = np.zeros((cache.n_p, cache.n_p))
    while len(chosen) < size:
        rest = [k for k in range(len(pool)) if pool[k] not in chosen]
        values = _log_det(total[None] + blocks[rest])
        pick = rest[int(np.argmax(values))]
        chosen.append(pool[pick])
        total = total + blocks[pick]
    return chosen


def _greedy_sensors(cache: _FisherCache, positions: Sequence[int], pool: Sequence[int], size: int) -> list[int]:
    chosen: list[int] = []
    while len(chosen) < size:
        rest = [i for i in pool if i not in chosen]
        total = sum(cache.added(j, chosen, rest) for j in positions)
        chosen.append(rest[int(np.argmax(_log_det(np.asarray(total))))])
    return chosen


def _exchange_positions(cache: _FisherCache, chosen: list[int], pool: Sequence[int],
                        sensors: Sequence[int]) -> tuple[list[int], bool]:
    """Best improving swap of a chosen position for an unchosen one, repeated (the sensors' blocks are cached)."""
    blocks = {j: cache.block(j, sensors) for j in pool}
    improved = False
    current = float(_log_det(sum((blocks[j] for j in chosen), np.zeros((cache.n_p, cache.n_p)))))
    while True:
        best, best_value = None, current
        for k, i in itertools.product(range(len(chosen)), pool):
            if i in chosen:
                continue
            trial = [*chosen[:k], i, *chosen[k + 1:]]
            value = float(_log_det(sum((blocks[j] for j in trial), np.zeros((cache.n_p, cache.n_p)))))
            if _improves(value, best_value):
                best, best_value = trial, value
        if best is None:
            return chosen, improved
        chosen, current, improved = best, best_value, True


def _exchange_sensors(cache: _FisherCache, positions: Sequence[int], chosen: list[int],
                      pool: Sequence[int]) -> tuple[list[int], bool]:
    """Best improving swap of a chosen channel for an unchosen one, repeated; each removal's swaps in one batch."""
    improved = False
    current = float(_log_det(np.asarray(sum(cache.block(j, chosen) for j in positions))))
    while True:
        best, best_value = None, current
        rest = [i for i in pool if i not in chosen]
        for k in range(len(chosen)):
            base = [*chosen[:k], *chosen[k + 1:]]
            values = _log_det(np.asarray(sum(cache.added(j, base, rest) for j in positions)))
            for i, value in zip(rest, values, strict=True):
                if _improves(float(value), best_value):
                    best, best_value = [*chosen[:k], i, *chosen[k + 1:]], float(value)
        if best is None:
            return chosen, improved
        chosen, current, improved = best, best_value, True


def plan_test(
    *,
    candidates: PlanCandidates,
    n_positions: int,
    n_sensors: int,
    max_relative_std: float = 0.1,
    n_random: int = 10,
    rng: int | np.random.Generator | None = 0,
) -> MeasurementPlan:
    """Choose ``n_positions`` positions and ``n_sensors`` channels that maximize the D-criterion.

    Positions are chosen greedily with every candidate channel, then channels greedily at those positions, then
    pairwise exchanges of positions and of channels alternate until neither improves the criterion.

    Parameters
    ----------
    candidates : PlanCandidates
        The candidates' derivatives (:meth:`PlanCandidates.from_model`).
    n_positions : int
        Number of axis positions to measure at.
    n_sensors : int
        Number of sensor channels (the same channels at every position).
    max_relative_std : float
        An unknown whose expected relative std exceeds this counts as not determined.
    n_random : int
        Random plans of the same size to compare with (0: none).
    rng : int, Generator or None
        Seed of the random plans.

    Returns
    -------
    MeasurementPlan

    Examples
    --------
    >>> from cappe.model import load_model
    >>> nm = NumericModel(load_model("builtin:two-mass-rig"))
    >>> cands = PlanCandidates.from_model(nm, unknowns=["k11", "k12"], n_modes=2)
    >>> plan = plan_test(candidates=cands, n_positions=1, n_sensors=2, n_random=0)
    >>> plan.sensors, plan.undetermined
    (['n1:x', 'n2:x'], [])
    """
    n_pos, n_ch = len(candidates.positions), len(candidates.sensors)
    if not 1 <= n_positions <= n_pos:
        msg = f"the number of positions must be from 1 to the {n_pos} candidates; got {n_positions}"
        raise ModelError(msg)
    if not 1 <= n_sensors <= n_ch:
        msg = f"the number of sensor channels must be from 1 to the {n_ch} candidates; got {n_sensors}"
        raise ModelError(msg)
    if not max_relative_std > 0:
        msg = f"max_relative_std must be > 0; got {max_relative_std!r}"
        raise ModelError(msg)
    all_ch = list(range(n_ch))
    all_pos = list(range(n_pos))
    cache = _FisherCache(candidates)
    positions = _greedy_positions(cache, all_pos, all_ch, n_positions)
    sensors = _greedy_sensors(cache, positions, all_ch, n_sensors)
    for _ in range(MAX_PASSES):
        positions, moved_p = _exchange_positions(cache, positions, all_pos, sensors)
        sensors, moved_s = _exchange_sensors(cache, positions, sensors, all_ch)
        if not (moved_p or moved_s):
            break
    positions, sensors = sorted(positions), sorted(sensors)
    unc = candidates.uncertainty(positions, sensors)
    best = _relative(candidates.uncertainty(all_pos, all_ch))
    random: dict[str, Any] = {}
    if n_random > 0:
        gen = np.random.default_rng(rng)
        determinable = best <= max_relative_std
        crits, medians, medians_det, counts = [], [], [], []
        for _ in range(n_random):
            rp = sorted(gen.choice(n_pos, n_positions, replace=False).tolist())
            rs = sorted(gen.choice(n_ch, n_sensors, replace=False).tolist())
            rel = _relative(candidates.uncertainty(rp, rs))
            crits.append(candidates.criterion(rp, rs))
            medians.append(float(np.median(rel)))
            medians_det.append(float(np.median(rel[determinable])) if np.any(determinable) else math.nan)
            counts.append(int(np.sum(~(rel <= max_relative_std))))
        random = {"n": n_random, "seed": rng if isinstance(rng, int) else None, "criterion": crits,
                  "median_relative_std": medians, "median_relative_std_determinable": medians_det,
                  "n_undetermined": counts}
    return MeasurementPlan(
        candidates=candidates,
        position_index=tuple(positions),
        sensor_index=tuple(sensors),
        criterion=candidates.criterion(positions, sensors),
        uncertainty=unc,
        relative_std=_relative(unc),
        best_relative_std=best,
        max_relative_std=float(max_relative_std),
        random=random,
    )
