"""Batched modal engine: many parameter vectors x axis positions -> modes, damping, shapes.

Per chunk of samples: reduce ``K phi = lambda M phi`` with the Cholesky factor ``M = L L^T`` to the symmetric
``L^-1 K L^-T`` (for samples with the model's nominal M, from stiffness patterns reduced once per position; for the
others, from their own assembled M and K), solve all problems with one batched ``eigh``, map back to
mass-normalized shapes, and form the sensor shapes and the first-order damping ratios from the modal elongations
of the damping sources (one sparse product). Chunks run on threads (see :mod:`cappe.parallel`); every sample goes
through the same arithmetic whatever the chunk it lands in (tested bit for bit over chunk sizes).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np
import scipy.linalg
import scipy.sparse as sps
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from cappe.exceptions import ModelError
from cappe.modal._batch import ModalBatch
from cappe.model.numeric import DampingSources, NumericModel, ParamsLike
from cappe.model.structure import Structure
from cappe.model.symbolic import MATRIX_NAMES
from cappe.parallel import Executor, map_chunks
from cappe.systems.modal import ModalData

if TYPE_CHECKING:
    from cappe.modal._derivatives import ModalDerivatives

__all__ = ["ModalEngine", "ModeReference", "modal_batch"]

Array = NDArray[np.float64]
T = TypeVar("T")

#: Eigenvalues below this fraction of the largest are rigid-body (zero-frequency) modes.
RIGID_TOLERANCE = 1e-10
#: Extra candidate modes considered when tracking, so a mode that drops out of the lowest band is found.
TRACKING_MARGIN = 4
#: The exact modes of a single vector are solved mode by mode on the quadratic eigenproblem (about two complex LU
#: factorizations of order n_dof each) when the engine reports at most this fraction of the n_dof modes; else by one
#: eig of the 2 n_dof state matrix (which costs about 200 such factorizations: 168 ms against 0.85 ms at n_dof 162).
QUADRATIC_FRACTION = 0.25
#: A quadratic-eigenproblem mode has converged when its normwise backward error
#: ``||Q(s) x|| / ((|s|^2 ||M|| + |s| ||C + G|| + ||K + iH||) ||x||)`` is below this (a few units of round-off).
QUADRATIC_TOLERANCE = 1e-14


@dataclass(frozen=True)
class ModeReference:
    """Reference modes that tracked evaluations are matched to (by mass-weighted MAC).

    Attributes
    ----------
    shapes : ndarray, shape (n_dof, n_modes)
        Mass-normalized real mode shapes at all DOFs.
    mass : ndarray, shape (n_dof, n_dof)
        Mass matrix of the reference, used to weight the MAC (units of translations and rotations differ).
    frequency : ndarray, shape (n_modes,)
        Reference natural frequencies in Hz.
    """

    shapes: Array
    mass: Array
    frequency: Array

    @property
    def n_modes(self) -> int:
        return int(self.shapes.shape[1])


@dataclass
class _Chunk:
    frequency: Array
    damping: Array
    shapes: Array
    mode_index: NDArray[np.intp]
    tracking_mac: Array | None
    contributions: Array | None
    damping_gradient: Array | None
    poles: NDArray[np.complex128] | None
    complex_shapes: NDArray[np.complex128] | None
    full_shapes: Array | None


class ModalEngine:
    """Fast modal analysis of a NumericModel for batches of parameter vectors at axis positions.

    Parameters
    ----------
    model : NumericModel or Structure
        The model (a Structure is compiled).
    sensors : sequence of str, "dofs" or None
        Channels for the mode shapes: ``"node:x"`` labels or node names (all three directions). ``None``:
        every channel of every sensor node of the model, or the DOFs if it has none. ``"dofs"``: the DOFs.
    n_modes : int or None
        Number of modes reported (lowest first); ``None``: all.
    chunk_size : int
        Samples per chunk; bounds memory (about ``chunk_size * 6 * n_dof**2`` floats in flight per worker).
    n_workers : int or None
        Worker threads; ``None``: one per core. Results are identical for any value.
    executor : Executor, str or None
        Where chunks run instead (``"serial"``, ``"threads"``, ``"processes"`` or a Dask scheduler address; see
        :class:`cappe.parallel.Executor`); results are identical for every choice.
    warm_start : bool
        Start each single-vector exact solve on the quadratic eigenproblem from the exact modes of the previous one
        at the same position (a search's next point) instead of from the undamped modes; a mode that does not
        converge to its undamped mode's partner from there is solved cold. The modes agree with a cold solve to
        their conditioning (backward error below :data:`QUADRATIC_TOLERANCE` either way), but not bit for bit, and
        then depend on the order of the evaluations: off by default.

    Examples
    --------
    >>> from cappe.model import load_model
    >>> engine = ModalEngine(load_model("builtin:two-mass-rig"))
    >>> batch = engine.evaluate([[1.39, 1.09, 1.38e6, 0.12e6, 0.24e6, 13.42, 0.0, 0.47]])
    >>> batch.frequency.round(2)
    array([[ 89.72, 166.29]])
    """

    def __init__(
        self,
        model: NumericModel | Structure,
        *,
        sensors: Sequence[str] | str | None = None,
        n_modes: int | None = None,
        chunk_size: int = 256,
        n_workers: int | None = None,
        executor: Executor | str | None = None,
        warm_start: bool = False,
    ) -> None:
        self.model = model if isinstance(model, NumericModel) else NumericModel(model)
        self.warm_start = warm_start
        n = self.model.n_dof
        if n_modes is None:
            n_modes = n
        if isinstance(n_modes, bool) or not isinstance(n_modes, int) or not 1 <= n_modes <= n:
            msg = f"n_modes must be an integer from 1 to n_dof = {n}; got {n_modes!r}"
            raise ModelError(msg)
        self.n_modes = n_modes
        self.chunk_size = chunk_size
        self.n_workers = n_workers
        self.executor = executor
        if sensors is not None and not isinstance(sensors, str) and not list(sensors):
            msg = f"the list of sensor channels for model '{self.model.structure.name}' is empty; name at least one"
            raise ModelError(msg)
        self._sensor_request = sensors
        self._sensor_cache: dict[tuple[float, ...], tuple[tuple[str, ...], Array]] = {}
        self._group_cache: dict[tuple[float, ...], list[NDArray[np.intp]]] = {}
        self._nominal_cache: dict[tuple[float, ...], _NominalReduction] = {}
        self._stacked_cache: dict[tuple[float, ...], _Projection] = {}
        self._fused_cache: dict[tuple[float, ...], tuple[Array, Array] | None] = {}
        # the state matrix's eigen-decomposition of the last single-sample exact solve at each position, for
        # exact_mode_derivatives at the same vector (a second eig of the 2 n_dof state matrix otherwise)
        self._state_cache: dict[tuple[float, ...], tuple[bytes, StateEigensystem]] = {}
        # likewise the quadratic-eigenproblem modes of the last single-sample exact solve at each position
        self._quadratic_cache: dict[tuple[float, ...], tuple[bytes, QuadraticModes]] = {}
        # how each single-vector exact solve went: "quadratic", or "fallback" (a mode missed: the state eig);
        # appended (atomic under threads) rather than counted
        self._exact_outcomes: list[str] = []
        self._dof_channels = sensors == "dofs" or (sensors is None and not self.model.structure.sensors)
        self.sensors = self._sensor_rows(self.model.structure.default_position())[0]

    # -- sensors ----------------------------------------------------------------------------------
    def sensor_rows(self, position: Mapping[str, float] | None = None) -> tuple[tuple[str, ...], Array]:
        """The engine's sensor channels at ``position``: labels and the rows (n_s, n_dof) mapping DOFs to them.

        Parameters
        ----------
        position : mapping or None
            Axis position in m or rad (sensor rows of bodies that move with an axis depend on it).

        Returns
        -------
        labels : tuple of str
            The channels.
        rows : ndarray, shape (n_s, n_dof)
            Channel motion per DOF (dimensionless for translations; m per rad for rotations).

        Examples
        --------
        >>> from cappe.model import load_model
        >>> labels, rows = ModalEngine(load_model("builtin:two-mass-rig"), sensors="dofs").sensor_rows()
        >>> labels, rows.shape
        (('mass1.x', 'mass2.x'), (2, 2))
        """
        labels, rows = self._sensor_rows(position)
        return labels, rows.copy()

    def _sensor_rows(self, position: Mapping[str, float] | None) -> tuple[tuple[str, ...], Array]:
        pos = self.model.position_vector(position)
        cached = self._sensor_cache.get(pos)
        if cached is not None:
            return cached
        request = self._sensor_request
        structure = self.model.structure
        if self._dof_channels:
            cached = (self.model.dofs, np.eye(self.model.n_dof))
        else:
            labels, rows = self.model.sensor_matrix(position=position)
            if request is not None and not isinstance(request, str):
                wanted: list[int] = []
                for item in request:
                    hits = [i for i, lab in enumerate(labels) if lab == item or lab.split(":")[0] == item]
                    if not hits:
                        msg = (
                            f"sensor {item!r} does not exist in model '{structure.name}'; known channels: "
                            f"{', '.join(labels) or 'none'}"
                        )
                        raise ModelError(msg)
                    wanted.extend(hits)
                labels, rows = [labels[i] for i in wanted], rows[wanted]
            elif isinstance(request, str):
                msg = f"sensors must be a list of channel labels, 'dofs' or None; got {request!r}"
                raise ModelError(msg)
            for sensor in structure.sensors:
                for value in self.model.symbolic.sensor_rows(sensor.name):
                    for expr in value.values():
                        free = {str(s) for s in getattr(expr, "free_symbols", set())}
                        if free & set(self.model.parameter_names):
                            msg = (
                                f"sensor {sensor.name!r} of model '{structure.name}' moves with parameters "
                                f"{sorted(free & set(self.model.parameter_names))}; the modal engine needs "
                                "sensor points that depend on axis positions only"
                            )
                            raise ModelError(msg)
            cached = (tuple(labels), rows)
        self._sensor_cache[pos] = cached
        return cached

    # -- reference and tracking ---------------------------------------------------------------------
    def reference(
        self,
        params: ParamsLike = None,
        position: Mapping[str, float] | None = None,
        *,
        previous: ModeReference | None = None,
    ) -> ModeReference:
        """Reference modes at one parameter vector (default nominal) and position.

        With ``previous`` (the reference of a neighbouring position), the modes are ordered to follow it,
        so that reference mode r is the same physical mode at every position.

        Parameters
        ----------
        params : array (n_params,), mapping or None
            One parameter vector (SI; default nominal).
        position : mapping or None
            Axis position in m or rad.
        previous : ModeReference, optional
            Reference at a neighbouring position to follow.

        Returns
        -------
        ModeReference

        Raises
        ------
        ModelError
            ``params`` is a batch.
        """
        p = self.model.vector(params)
        if p.ndim != 1:
            msg = "reference() takes a single parameter vector"
            raise ModelError(msg)
        mats = self.model.matrices(p, position, names=("M",))
        chunk = self._solve(p[None, :], position, track=previous, exact=False, contributions=False, full=True)
        return ModeReference(np.asarray(chunk.full_shapes)[0], mats["M"], chunk.frequency[0])

    def _state_eigensystem(self, params: Array, position: Mapping[str, float] | None) -> StateEigensystem | None:
        """The state eigen-decomposition kept from the last single-vector exact solve of ``params`` (bit for bit) at
        ``position``, else None."""
        kept = self._state_cache.get(self.model.position_vector(position))
        if kept is None or kept[0] != np.asarray(params, dtype=float).tobytes():
            return None
        return kept[1]

    def _quadratic_modes(self, params: Array, position: Mapping[str, float] | None) -> QuadraticModes | None:
        """The quadratic-eigenproblem modes kept from the last single-vector exact solve of ``params`` (bit for bit)
        at ``position``, else None."""
        kept = self._quadratic_cache.get(self.model.position_vector(position))
        if kept is None or kept[0] != np.asarray(params, dtype=float).tobytes():
            return None
        return kept[1]

    @property
    def exact_solves(self) -> dict[str, int]:
        """How the single-vector exact solves went so far: ``{"quadratic": n, "fallback": k}`` (k of them missed a
        mode on the quadratic eigenproblem and took the state matrix's full eig instead)."""
        outcomes = list(self._exact_outcomes)
        return {"quadratic": outcomes.count("quadratic"), "fallback": outcomes.count("fallback")}

    def _reference_for(self, track: ModeReference | bool, position: Mapping[str, float] | None) -> ModeReference | None:
        """The reference a ``track`` argument stands for: True means the nominal modes at ``position``."""
        if track is True:
            return self.reference(None, position)
        return track or None

    def references(
        self, positions: Sequence[Mapping[str, float]], params: ParamsLike = None
    ) -> list[ModeReference]:
        """Reference modes at several positions, each tracked to the previous one.

        Parameters
        ----------
        positions : sequence of mapping
            Axis positions in m or rad, in the order to track along.
        params : array (n_params,), mapping or None
            One parameter vector (SI; default nominal).

        Returns
        -------
        list of ModeReference
        """
        out: list[ModeReference] = []
        for position in positions:
            out.append(self.reference(params, position, previous=out[-1] if out else None))
        return out

    def modal_data(
        self,
        positions: Sequence[Mapping[str, float]] | None = None,
        params: ParamsLike = None,
        *,
        exact: bool = True,
    ) -> ModalData:
        """Modes at one parameter vector at several positions as :class:`cappe.systems.ModalData`.

        Modes are tracked from position to position, so column r is the same physical mode at each; with
        ``exact`` the poles and complex shapes include all damping and gyroscopic terms.

        Parameters
        ----------
        positions : sequence of mapping, optional
            Axis positions in m or rad (default: the model's default position).
        params : array (n_params,), mapping or None
            One parameter vector (SI; default nominal).
        exact : bool
            Exact complex modes (else first-order damping and real shapes).

        Returns
        -------
        ModalData
            One set per position, at the engine's sensor channels.

        Examples
        --------
        >>> from cappe.model import load_model
        >>> data = ModalEngine(load_model("builtin:two-mass-rig")).modal_data()
        >>> data.sensors, data.sets[0].frequency.round(1)
        (('n1:x', 'n1:y', 'n1:z', 'n2:x', 'n2:y', 'n2:z'), array([ 89.7, 166.3]))
        """
        if positions is None:
            positions = [self.model.structure.default_position()]
        refs = self.references(positions, params)
        sets = tuple(
            self.evaluate(params, position, track=ref, exact=exact).data_set(0)
            for position, ref in zip(positions, refs, strict=True)
        )
        return ModalData(self.sensors, sets, self.model.structure.name)

    # -- evaluation -------------------------------------------------------------------------------
    def derivatives(
        self,
        params: ParamsLike = None,
        position: Mapping[str, float] | None = None,
        *,
        track: ModeReference | bool = False,
        parameters: Sequence[str] | None = None,
        modes: Sequence[int] | NDArray[np.intp] | None = None,
    ) -> ModalDerivatives:
        """Analytic derivatives of frequencies, damping ratios and sensor shapes at one parameter vector.

        Returns a :class:`cappe.modal.ModalDerivatives`, with respect to ``parameters`` (default all; naming
        only the ones needed saves most of the work on models with many parameters), of the ``modes`` asked for
        (default all the engine reports; the derivatives stay exact: the expansion runs over every mode).

        Parameters
        ----------
        params : array (n_params,), mapping or None
            One parameter vector (SI; default nominal).
        position : mapping or None
            Axis position in m or rad.
        track : ModeReference or bool
            Order the modes like a reference (``True``: the nominal modes at this position).
        parameters : sequence of str, optional
            Parameters to differentiate by (default all).
        modes : sequence of int, optional
            The modes returned, in this order: indices (0-based) into the modes the engine reports (after
            ``track``); default all of them.

        Returns
        -------
        ModalDerivatives
        """
        from cappe.modal._derivatives import derivatives

        return derivatives(self, params, position, track=track, parameters=parameters, modes=modes)

    def evaluate(
        self,
        params: ParamsLike = None,
        position: Mapping[str, float] | None = None,
        *,
        track: ModeReference | bool = False,
        exact: bool = False,
        contributions: bool = False,
        full_shapes: bool = False,
        progress: bool = False,
    ) -> ModalBatch:
        """Modes for one parameter vector or a batch (B, n_params) at one axis position.

        Parameters
        ----------
        params : array (n_params,) or (B, n_params), mapping or None
            Parameter vectors in ``model.parameter_names`` order (a mapping overrides the nominal values).
        position : mapping or None
            Axis position (default: each axis at its first position).
        track : ModeReference or bool
            Report, for each reference mode, the most similar mode (mass-weighted MAC, optimal assignment).
            ``True`` tracks against the nominal modes at this position.
        exact : bool
            Also compute the exact complex poles and shapes (viscous, hysteretic and gyroscopic terms).
        contributions : bool
            Also return the damping contribution of each source and ``d zeta / d p``.
        full_shapes : bool
            Also return the shapes at all DOFs.
        progress : bool
            Progress bar.
        """
        p = self.model.vector(params)
        pb = p if p.ndim == 2 else p[None, :]
        reference = self._reference_for(track, position)
        chunks = map_chunks(
            lambda s: self._solve(pb[s], position, track=reference, exact=exact, contributions=contributions,
                                  full=full_shapes, offset=s.start),
            pb.shape[0],
            chunk_size=self.chunk_size,
            n_workers=self.n_workers,
            executor=self.executor,
            progress=progress,
            description="modes",
        )
        return self._combine(chunks, pb, position)

    def map(
        self,
        func: Callable[[ModalBatch], T],
        params: ParamsLike,
        position: Mapping[str, float] | None = None,
        *,
        track: ModeReference | bool = False,
        exact: bool = False,
        contributions: bool = False,
        progress: bool = False,
    ) -> list[T]:
        """Apply ``func`` to the modes of each chunk and return its results in order (memory stays bounded).

        Parameters
        ----------
        func : callable
            ``func(batch)`` -> T for the :class:`ModalBatch` of one chunk of parameter vectors.
        params : array (n_params,) or (B, n_params), mapping or None
            Parameter vectors (SI) in ``model.parameter_names`` order.
        position : mapping or None
            Axis position in m or rad.
        track, exact, contributions, progress
            As for :meth:`evaluate`.

        Returns
        -------
        list
            ``func``'s results, one per chunk, in order.
        """
        p = self.model.vector(params)
        pb = p if p.ndim == 2 else p[None, :]
        reference = self._reference_for(track, position)

        def run(s: slice) -> T:
            chunk = self._solve(pb[s], position, track=reference, exact=exact, contributions=contributions,
                                full=False, offset=s.start)
            return func(self._combine([chunk], pb[s], position))

        return map_chunks(run, pb.shape[0], chunk_size=self.chunk_size, n_workers=self.n_workers,
                          executor=self.executor, progress=progress, description="modes")

    def _combine(self, chunks: list[_Chunk], pb: Array, position: Mapping[str, float] | None) -> ModalBatch:
        sensors = self._sensor_rows(position)[0]

        def cat(name: str) -> Any:
            values = [getattr(c, name) for c in chunks]
            if values[0] is None or len(values) == 1:  # a single chunk's arrays are its own: no copy
                return values[0]
            return np.concatenate(values, axis=0)

        return ModalBatch(
            frequency=cat("frequency"),
            damping=cat("damping"),
            shapes=cat("shapes"),
            sensors=sensors,
            position=dict(zip(self.model.axis_names, self.model.position_vector(position), strict=True)),
            parameters=pb,
            parameter_names=tuple(self.model.parameter_names),
            mode_index=cat("mode_index"),
            tracking_mac=cat("tracking_mac"),
            contributions=cat("contributions"),
            damping_gradient=cat("damping_gradient"),
            source_names=self.model.source_names,
            source_elements=self.model.source_elements,
            poles=cat("poles"),
            complex_shapes=cat("complex_shapes"),
            full_shapes=cat("full_shapes"),
            dofs=self.model.dofs,
        )

    # -- the hot path -----------------------------------------------------------------------------
    def _mass_groups(self, position: Mapping[str, float] | None) -> list[NDArray[np.intp]]:
        """Diagonal blocks of M grouped by size: each entry is (n_blocks, size) DOF indices."""
        pos = self.model.position_vector(position)
        cached = self._group_cache.get(pos)
        if cached is None:
            by_size: dict[int, list[NDArray[np.intp]]] = {}
            for block in self.model.blocks("M", position):
                by_size.setdefault(block.size, []).append(block)
            cached = [np.array(blocks) for _, blocks in sorted(by_size.items())]
            self._group_cache[pos] = cached
        return cached

    def _reduce(self, pb: Array, position: Mapping[str, float] | None, exact: bool,
                offset: int) -> tuple[dict[str, Array], _MassReduction | _Reductions | _ScaledReduction, Array,
                                      NDArray[np.intp] | None]:
        """The matrices the chunk needs (all five with ``exact``, else none or M and K), the reduction of each sample,
        the reduced stiffness ``L^-1 K L^-T`` and, where samples repeat one another's stiffness, the sample each
        row of the reduced stiffness stands for.

        Samples whose mass parameters have their nominal values (known masses, as in the GSA and the stiffness
        subproblems) take :class:`_NominalReduction`; the others factor their own M. Which way a sample goes
        depends on that sample only, so the results do not depend on the chunk it lands in.

        When every sample of the chunk has the nominal M, samples with the same stiffness parameters (bit for bit)
        share one reduced stiffness and so one eigen-solve: the reduced stiffness then has one row per distinct
        stiffness and the returned index maps each sample to its row (else it is None, one row per sample). A
        Saltelli design repeats each base sample's stiffness in the columns of the damping unknowns (11 of the
        machine tool's 27 unknowns: 38 % of the GSA's eigen-solves). The eigen-solve of the same matrix gives the
        same bits wherever it is done, so sharing it changes no result.
        """
        model = self.model
        groups = self._mass_groups(position)
        nominal = self._nominal_reduction(position) if model.is_affine else None
        shared = None if nominal is None else nominal.shares_mass(pb)
        if shared is not None and not shared.all():
            assert nominal is not None  # shared is only set with a nominal reduction
            scaled = _ScaledReduction.of(nominal, pb, shared)
            if scaled is not None:
                mats = model.matrices(pb, position) if exact else {}
                reduced = scaled.reduce(nominal.reduce(model.affine_terms(("K",), pb, position)["K"][0]))
                return mats, scaled, reduced, None
        if shared is None or not shared.any():
            mats = model.matrices(pb, position, names=MATRIX_NAMES if exact else ("M", "K"))
            reduction = _MassReduction(mats["M"], groups, offset)
            return mats, reduction, reduction.reduce(mats["K"]), None
        assert nominal is not None  # shared is only set with a nominal reduction
        mats = model.matrices(pb, position) if exact else {}
        if shared.all():
            first, inverse = nominal.distinct_stiffness(pb)
            repeats = None if first.size == pb.shape[0] else inverse
            rows = pb if repeats is None else pb[first]
            reduced = nominal.reduce(model.affine_terms(("K",), rows, position)["K"][0])
            return mats, _Reductions(shared, nominal, None), reduced, repeats
        reduced = np.empty((pb.shape[0], model.n_dof, model.n_dof))
        reduced[shared] = nominal.reduce(model.affine_terms(("K",), pb[shared], position)["K"][0])
        rest = np.flatnonzero(~shared)
        own = model.matrices(pb[rest], position, names=("M", "K"))
        try:
            other = _MassReduction(own["M"], groups, 0)
        except ModelError:  # name the samples as numbered in the whole batch: factor the chunk's M to raise that
            _MassReduction(model.matrices(pb, position, names=("M",))["M"], groups, offset)
            raise
        reduced[rest] = other.reduce(own["K"])
        return mats, _Reductions(shared, nominal, other), reduced, None

    def _stacked_rows(self, position: Mapping[str, float] | None, sensor_rows: Array,
                      source_rows: Array) -> _Projection:
        """The sensor rows above the damping sources' elongation rows at ``position``, split into sparse and dense
        rows (:class:`_Projection`)."""
        pos = self.model.position_vector(position)
        if pos not in self._stacked_cache:
            self._stacked_cache[pos] = _Projection(np.vstack([sensor_rows, source_rows]))
        return self._stacked_cache[pos]

    def _fused_rows(self, position: Mapping[str, float] | None, sensor_rows: Array,
                    source_rows: Array) -> tuple[Array, Array] | None:
        """The sensor rows and the source rows times the nominal ``L^-T``, dense, where ``L^-T`` has a dense block (a
        flexible body): applied to the eigenvectors ``v`` they give the shapes at the sensors and the elongations
        without forming ``phi = L^-T v``. None for models of rigid bodies only (their ``L^-T`` is sparse and they keep
        the two sparse products)."""
        pos = self.model.position_vector(position)
        if pos not in self._fused_cache:
            projection, linv_t = self._nominal_reduction(position).factor()
            fused = None
            if projection.dense_index.size:
                fused = (np.ascontiguousarray(sensor_rows @ linv_t), np.ascontiguousarray(source_rows @ linv_t))
            self._fused_cache[pos] = fused
        return self._fused_cache[pos]

    def _nominal_reduction(self, position: Mapping[str, float] | None) -> _NominalReduction:
        """The reduction of the nominal mass matrix at ``position`` (made once per position; affine models only)."""
        pos = self.model.position_vector(position)
        if pos not in self._nominal_cache:
            self._nominal_cache[pos] = _NominalReduction(self.model, position, self._mass_groups(position))
        return self._nominal_cache[pos]

    def _solve(
        self,
        pb: Array,
        position: Mapping[str, float] | None,
        *,
        track: ModeReference | None,
        exact: bool,
        contributions: bool,
        full: bool,
        offset: int = 0,
    ) -> _Chunk:
        model = self.model
        n = model.n_dof
        mats, reduction, reduced, repeats = self._reduce(pb, position, exact, offset)
        # with ``repeats``, the modes and everything that depends only on them (shapes, tracking, projections) are
        # worked out once per distinct stiffness and handed to the samples that share it; the damping, which
        # differs between those samples, is then computed per sample
        lam, vec = np.linalg.eigh(reduced)
        scale = np.max(np.abs(lam), axis=1, keepdims=True)
        lam = np.where(np.abs(lam) < RIGID_TOLERANCE * np.maximum(scale, 1e-300), 0.0, lam)
        bad = np.flatnonzero(lam.min(axis=1) < 0)
        if bad.size:
            samples = bad if repeats is None else np.flatnonzero(np.isin(repeats, bad))
            msg = (
                f"stiffness matrix is not positive semi-definite for samples {_first(samples + offset)} "
                f"(min eigenvalue {lam[bad[0]].min():.3g}) in model '{model.structure.name}'"
            )
            raise ModelError(msg)
        m_out = track.n_modes if track is not None else self.n_modes
        n_cand = min(n, m_out + TRACKING_MARGIN) if track is not None else m_out
        vectors = vec[:, :, :n_cand]
        lam = lam[:, :n_cand]
        b = vectors.shape[0]
        # the mass-normalized shapes L^-T v (one per distinct stiffness): with every sample on the nominal reduction
        # and no tracking, kept in the (n, B m) layout that the sparse projections below take (phi (B, n, m) is
        # formed from it only where asked for: the same bits, two layout copies fewer). On a model with a flexible
        # body, whose block of L^-T is dense, the sensor and source rows times L^-T are applied to v instead and
        # L^-T v is not formed at all unless asked for (_fused_rows).
        flat: Array | None = None
        phi: Array | None = None
        sources = model.damping_sources(pb, position, jacobian=contributions)
        # the chunk's reduction where every sample takes the nominal one (or the nominal one after a block-diagonal
        # S of its own: L^-T v = L_nom^-T (S^T v), _ScaledReduction) and nothing is tracked
        nominal: _Reductions | _ScaledReduction | None = None
        if track is None and (isinstance(reduction, _ScaledReduction)
                              or (isinstance(reduction, _Reductions) and reduction.other is None)):
            nominal = reduction
        base = reduction.premultiply(vectors) if isinstance(reduction, _ScaledReduction) else vectors
        fused = None
        if nominal is not None and not (full or exact or self._dof_channels) and sources.rows.ndim == 2:
            fused = self._fused_rows(position, self._sensor_rows(position)[1], sources.rows)
        if nominal is not None and fused is None:
            flat = nominal.nominal.flat_shapes(base)
        elif nominal is None:
            phi = reduction.shapes(vectors)
        if track is not None:
            assert phi is not None  # tracking takes the (B, n, m) shapes
            index, mac = _track(track, phi)
            rows = np.arange(b)[:, None]
            phi = phi[rows[:, :, None], np.arange(n)[None, :, None], index[:, None, :]]
            lam = lam[rows, index]
        else:
            index = np.broadcast_to(np.arange(m_out), (b, m_out)).copy()
            mac = None
        m = lam.shape[1]

        def shapes_of(flat_shapes: Array | None, shapes: Array | None) -> Array:
            if shapes is not None:
                return shapes
            if flat_shapes is None:  # the fused rows' path: L^-T v not formed yet
                assert isinstance(reduction, (_Reductions, _ScaledReduction))
                flat_shapes = reduction.nominal.flat_shapes(base)
            return _unflatten(flat_shapes, m)

        if repeats is not None and sources.rows.ndim == 3:  # elongation rows per sample: hand the modes out first
            lam, index, phi = lam[repeats], index[repeats], shapes_of(flat, phi)[repeats]
            mac = None if mac is None else mac[repeats]
            repeats, b, flat = None, pb.shape[0], None
        sensor_rows = self._sensor_rows(position)[1]
        if self._dof_channels or sources.rows.ndim == 3:
            phi = shapes_of(flat, phi)
            elongation = sources.rows @ phi  # (B, n_src, m)
            shapes = phi.copy() if self._dof_channels else sensor_rows @ phi
        else:
            # sensor channels and element elongations are sparse rows (a few DOFs of one or two bodies): one
            # sparse product over every mode of the chunk (each entry a fixed-order sum, whatever the chunk) instead
            # of two dense batched products, 81 x 45 and 70 x 45 per mode on the machine tool
            if fused is not None:
                # a flexible body: one dense BLAS product per sample each, (n_s, n) @ (n, m) and (n_src, n) @ (n, m)
                # (measured on the flexible-bed machine tool: 0.6 of the time of splitting the rows into sparse and
                # dense ones, gathering the dense ones' columns and scattering the results)
                shapes, elongation = fused[0] @ base, fused[1] @ base
            else:
                if flat is None:
                    flat = _flatten(shapes_of(flat, phi))
                proj = self._stacked_rows(position, sensor_rows, sources.rows).project(flat, m)
                n_s = sensor_rows.shape[0]
                # contiguous (B, rows, m): the per-sample products of _first_order_damping must see the same layout
                # whatever the chunk size (BLAS sums a strided operand in another order)
                shapes, elongation = np.ascontiguousarray(proj[:, :n_s]), np.ascontiguousarray(proj[:, n_s:])
        if full or exact:
            phi = shapes_of(flat, phi)
        if repeats is not None:
            lam, index, shapes, elongation = lam[repeats], index[repeats], shapes[repeats], elongation[repeats]
            mac = None if mac is None else mac[repeats]
            phi = phi[repeats] if phi is not None and (full or exact) else phi
        omega = np.sqrt(lam)
        zeta, contrib, gradient = _first_order_damping(sources, elongation, omega, contributions)
        poles = cshapes = None
        if exact:
            assert phi is not None  # formed above for exact
            found = None
            if pb.shape[0] == 1 and m <= QUADRATIC_FRACTION * n:  # one vector (the exact refinements), few modes
                kept = self._quadratic_cache.get(model.position_vector(position)) if self.warm_start else None
                found = QuadraticModes.solve({k: v[0] for k, v in mats.items()}, phi[0], omega[0], zeta[0],
                                             previous=None if kept is None else kept[1])
                self._exact_outcomes.append("fallback" if found is None else "quadratic")
            if found is not None:
                self._quadratic_cache[model.position_vector(position)] = (pb[0].tobytes(), found)
                poles, psi = found.poles[None, :], found.shapes[None, :, :]
            else:
                minv = reduction.inverse_mass()
                system = StateEigensystem.of(mats, minv)
                if pb.shape[0] == 1:  # one vector (the exact refinements): kept for its derivatives
                    self._state_cache[model.position_vector(position)] = (pb[0].tobytes(), system.first())
                poles, psi = _exact_modes(mats, minv, phi, omega, system)
            cshapes = psi if self._dof_channels else sensor_rows @ psi
        return _Chunk(omega / (2 * np.pi), zeta, shapes, index, mac, contrib, gradient, poles, cshapes,
                      phi if full else None)


def modal_batch(
    model: NumericModel | Structure,
    params: ParamsLike = None,
    position: Mapping[str, float] | None = None,
    *,
    sensors: Sequence[str] | str | None = None,
    n_modes: int | None = None,
    exact: bool = False,
    contributions: bool = False,
    track: ModeReference | bool = False,
) -> ModalBatch:
    """Modes of ``model`` for a batch of parameter vectors (function form of :meth:`ModalEngine.evaluate`).

    Parameters
    ----------
    model : NumericModel or Structure
        The model.
    params : array (n_params,) or (B, n_params), mapping or None
        Parameter vectors (SI) in ``model.parameter_names`` order (a mapping overrides the nominal values).
    position : mapping or None
        Axis position in m or rad (default: each axis at its first position).
    sensors : sequence of str, "dofs" or None
        Channels of the shapes, as for :class:`ModalEngine`.
    n_modes : int or None
        Number of modes (lowest first); None: all.
    exact, contributions, track
        As for :meth:`ModalEngine.evaluate`.

    Returns
    -------
    ModalBatch

    Examples
    --------
    >>> from cappe.model import load_model
    >>> batch = modal_batch(load_model("builtin:two-mass-rig"), exact=True)
    >>> (batch.damping.round(4), (-batch.poles.real / abs(batch.poles)).round(4))
    (array([[0.0005, 0.0045]]), array([[0.0005, 0.0045]]))
    """
    engine = ModalEngine(model, sensors=sensors, n_modes=n_modes)
    return engine.evaluate(params, position, exact=exact, contributions=contributions, track=track)


# -- numerical kernels ------------------------------------------------------------------------------
class _Projection:
    """Rows (n_rows, n) applied to the mode shapes of a chunk: the sensor and damping-source rows, or ``L^-T``.

    Rows of rigid-body elements and sensors (and ``L^-T`` of rigid bodies' 6 x 6 mass blocks) touch a few DOFs:
    they stay one sparse matrix applied to the chunk's shapes in the (n, B m) layout (each entry a fixed-order sum).
    Rows with more than :attr:`DENSE_NNZ` entries (the rank-one damping sources of a flexible body's damping block,
    sensors read through a recovery matrix, ``L^-T`` of its dense mass block) are dense over the flexible body's
    coordinates: scipy's sparse product walks them entry by entry (measured: about 0.7 of the eigen-solves' time on
    the 121-DOF flexible-bed machine tool), so they are one BLAS product per sample over their columns,
    ``(r, n_c) @ (n_c, m)``, the same shapes whatever the chunk and so the same bits.
    """

    #: A row with more stored entries than this is treated as dense (two 6-DOF bodies give at most 12).
    DENSE_NNZ = 16

    def __init__(self, rows: Array) -> None:
        nnz = np.count_nonzero(rows, axis=1)
        dense = nnz > self.DENSE_NNZ
        self.n_rows = rows.shape[0]
        self.sparse_index = np.flatnonzero(~dense)
        self.dense_index = np.flatnonzero(dense)
        self.sparse = sps.csr_array(rows[self.sparse_index])
        self.columns = np.flatnonzero(np.any(rows[self.dense_index] != 0, axis=0))
        self.dense = np.ascontiguousarray(rows[np.ix_(self.dense_index, self.columns)])

    def project(self, flat: Array, m: int) -> Array:
        """``rows @ phi`` per sample, (B, n_rows, m), from the shapes laid out (n, B m) (:func:`_flatten`)."""
        b = flat.shape[1] // m
        if not self.dense_index.size:
            return _unflatten(np.asarray(self.sparse @ flat), m)
        out = np.empty((b, self.n_rows, m))
        if self.sparse_index.size:
            out[:, self.sparse_index] = _unflatten(np.asarray(self.sparse @ flat), m)
        out[:, self.dense_index] = self.dense @ _unflatten(flat[self.columns], m)
        return out


def _flatten(shapes: Array) -> Array:
    """Shapes (B, n, m) laid out (n, B m), column ``k m + j`` holding mode j of sample k: one sparse product then
    maps the shapes of the whole chunk."""
    b, n, m = shapes.shape
    return np.ascontiguousarray(shapes.transpose(1, 0, 2)).reshape(n, b * m)


def _unflatten(flat: Array, m: int) -> Array:
    """The inverse layout of :func:`_flatten`: (rows, B m) -> C-contiguous (B, rows, m)."""
    # the batch size spelled out: a model without damping sources has no rows, and -1 cannot be inferred from 0
    return np.ascontiguousarray(flat.reshape(flat.shape[0], flat.shape[1] // m, m).transpose(1, 0, 2))


def _first(indices: NDArray[np.intp], k: int = 5) -> str:
    shown = ", ".join(str(int(i)) for i in indices[:k])
    return f"[{shown}{', ...' if indices.size > k else ''}] ({indices.size} in all)"


class _MassReduction:
    """Reduction of ``K phi = lambda M phi`` to ``(L^-1 K L^-T) v = lambda v``, ``phi = L^-T v``, using the
    block structure of M (the strategy depends only on the model, so every sample takes the same arithmetic).

    * diagonal M (point masses, principal axes at the centre of mass): scaling by ``1/sqrt(m_i)``, O(n^2);
    * equal contiguous blocks (6-DOF bodies with centre-of-mass offsets), n_dof >= BLOCK_MIN_DOF: block products,
      O(s n^2) instead of O(n^3);
    * otherwise dense products with the block-diagonal ``L^-1``.
    """

    #: Below this size the dense products beat many small block products (measured, benchmarks/bench_modal.py).
    BLOCK_MIN_DOF = 48

    def __init__(self, mass: Array, groups: list[NDArray[np.intp]], offset: int) -> None:
        self.mass = mass
        b, n, _ = mass.shape
        self.linv = _inverse_cholesky(mass, groups, offset)
        self.kind = "dense"
        if len(groups) == 1 and np.array_equal(groups[0].ravel(), np.arange(n)):
            size = groups[0].shape[1]
            if size == 1:
                self.kind = "diagonal"
                self.scale = np.ascontiguousarray(np.diagonal(self.linv, axis1=1, axis2=2))
            elif n >= self.BLOCK_MIN_DOF:
                self.kind = "blocks"
                nb = n // size
                idx = groups[0]
                self.blocks = np.ascontiguousarray(self.linv[:, idx[:, :, None], idx[:, None, :]])  # (B, nb, s, s)
                self.size, self.n_blocks = size, nb
        if self.kind == "dense":
            self.linv_t = np.ascontiguousarray(np.swapaxes(self.linv, 1, 2))

    def reduce(self, stiffness: Array) -> Array:
        b, n, _ = stiffness.shape
        if self.kind == "diagonal":
            return stiffness * self.scale[:, :, None] * self.scale[:, None, :]
        if self.kind == "blocks":
            s, nb = self.size, self.n_blocks
            left = self.blocks @ stiffness.reshape(b, nb, s, n)  # rows: L_I^-1 K_I.  (B, nb, s, n)
            cols = np.ascontiguousarray(left.reshape(b, n, nb, s).transpose(0, 2, 1, 3))  # (B, nb, n, s)
            right = cols @ np.swapaxes(self.blocks, 2, 3)  # columns: (.) L_J^-T
            return np.ascontiguousarray(right.transpose(0, 2, 1, 3).reshape(b, n, n))
        return self.linv @ stiffness @ self.linv_t

    def shapes(self, vectors: Array) -> Array:
        b, n, m = vectors.shape
        if self.kind == "diagonal":
            return vectors * self.scale[:, :, None]
        if self.kind == "blocks":
            s, nb = self.size, self.n_blocks
            out = np.swapaxes(self.blocks, 2, 3) @ np.ascontiguousarray(vectors).reshape(b, nb, s, m)
            return out.reshape(b, n, m)
        return self.linv_t @ np.ascontiguousarray(vectors)

    def inverse_mass(self) -> Array:
        linv_t = np.ascontiguousarray(np.swapaxes(self.linv, 1, 2))
        return linv_t @ self.linv


class _NominalReduction:
    """The reduction of ``K phi = lambda M phi`` for samples whose M is the model's nominal one at a position.

    ``L^-1`` is formed once, and so are the reduced stiffness patterns ``L^-1 P_j L^-T``: a sample's reduced
    stiffness is then the sparse sum ``sum_j f_j(p) L^-1 P_j L^-T`` of its coefficients, with no assembly of M and
    K, no factorization and no dense products per sample: measured 61 -> 21 us per sample on the 45-DOF machine
    tool (chunks of 64, a one-off timing), and the engine at 0.84-0.93 of the bare eigh bound with known masses
    against 0.73-0.84 with varying ones (benchmarks/bench_modal.py, n_dof 30-150; the shared host's load moves
    these by a few hundredths from run to run). The factor is formed on first
    use, so a model whose nominal M is not positive definite fails only when a sample has that M.
    """

    def __init__(self, model: NumericModel, position: Mapping[str, float] | None,
                 groups: list[NDArray[np.intp]]) -> None:
        # snapshots: the caller's position mapping and the model's nominal vector may change after this
        self.model, self.groups = model, groups
        self.position = dict(zip(model.axis_names, model.position_vector(position), strict=True))
        self.nominal = model.nominal.copy()
        self._mass_columns = [model.parameter_names.index(p) for p in model.matrix_parameters("M")]
        self._stiffness_columns = [model.parameter_names.index(p) for p in model.matrix_parameters("K")]
        self._factor: tuple[_Projection, NDArray[np.intp], Any, Array, Array] | None = None
        self._scale_plan: tuple[list[tuple[NDArray[np.intp], str, Any, Any]] | None] | None = None

    def scale_plan(self) -> list[tuple[NDArray[np.intp], str, Any, Any]] | None:
        """How a sample's mass blocks relate to the nominal ones (:class:`_ScaledReduction`), per group of blocks:
        ``(group, "scalar", term per block, its nominal coefficient per block)`` where every block is one term's
        (a flexible body's ``s_m M_fe``), ``(group, "blocks", the terms' patterns on the blocks (n_terms, nb, s, s),
        the nominal ``L_b`` (nb, s, s))`` for rigid bodies' small blocks. None where it does not apply: a model
        without flexible bodies, a large block of several terms, small blocks that are not the first DOFs (a
        lumped-mass flexible body beside another), a nominal M that is not positive definite."""
        if self._scale_plan is None:
            self._scale_plan = (self._make_scale_plan(),)
        return self._scale_plan[0]

    def _make_scale_plan(self) -> list[tuple[NDArray[np.intp], str, Any, Any]] | None:
        model = self.model
        if not model.structure.flexible_bodies:
            return None
        try:
            self._factored()
        except ModelError:
            return None
        coefficients, patterns = model.affine_terms(("M",), self.nominal[None, :], self.position)["M"]
        plan: list[tuple[NDArray[np.intp], str, Any, Any]] = []
        for group in self.groups:
            on_blocks = patterns[:, group[:, :, None], group[:, None, :]]  # (n_terms, nb, s, s)
            if group.shape[1] <= _ScaledReduction.SMALL:
                nominal = np.einsum("t,tkij->kij", coefficients[0], on_blocks)
                plan.append((group, "blocks", on_blocks, np.linalg.cholesky(nominal)))
                continue
            touching = np.any(on_blocks != 0, axis=(2, 3))  # (n_terms, nb)
            if not (touching.sum(axis=0) == 1).all():
                return None
            terms = np.argmax(touching, axis=0)
            plan.append((group, "scalar", terms, coefficients[0, terms]))
        small = [group.ravel() for group, kind, _, _ in plan if kind == "blocks"]
        if small and not np.array_equal(np.sort(np.concatenate(small)), np.arange(sum(g.size for g in small))):
            return None  # the small blocks' DOFs are not the first ones (see _ScaledReduction.reduce)
        return plan

    def shares_mass(self, params: Array) -> NDArray[np.bool_]:
        """Which samples (B, n_params) have the nominal M: their mass parameters equal the nominal values."""
        cols = self._mass_columns
        return np.asarray(np.all(params[:, cols] == self.nominal[cols], axis=1))

    def distinct_stiffness(self, params: Array) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """The first sample of each distinct set of stiffness parameters (bit for bit) among ``params`` (B,
        n_params), and for every sample the position of its set in that list."""
        keys = np.ascontiguousarray(params[:, self._stiffness_columns])
        b = params.shape[0]
        if keys.shape[1] == 0:  # K depends on no parameter: one stiffness for all
            return np.zeros(1, dtype=np.intp), np.zeros(b, dtype=np.intp)
        if np.unique(keys.sum(axis=1)).size == b:  # equal rows have equal sums: all distinct (the usual case)
            every = np.arange(b, dtype=np.intp)
            return every, every
        rows = keys.view(np.dtype((np.void, keys.shape[1] * keys.itemsize))).ravel()
        _, first, inverse = np.unique(rows, return_index=True, return_inverse=True)
        return first.astype(np.intp), inverse.astype(np.intp).ravel()

    def _factored(self) -> tuple[_Projection, NDArray[np.intp], Any, Array, Array]:
        if self._factor is None:
            model = self.model
            mass = model.matrices(self.nominal[None, :], self.position, names=("M",))["M"]
            try:
                linv = _inverse_cholesky(mass, self.groups, 0)[0]
            except ModelError as exc:
                msg = (f"the nominal mass matrix of model '{model.structure.name}' at position "
                       f"{self.position} is not positive definite (non-physical masses or inertias); "
                       "samples with those masses have no modes")
                raise ModelError(msg) from exc
            linv_t = np.ascontiguousarray(linv.T)
            patterns = model.affine_terms(("K",), self.nominal, self.position)["K"][1]
            flat = (linv @ patterns @ linv_t).reshape(patterns.shape[0], -1)
            # the lower triangle only: eigh reads no other (on a flexible body's dense block, half the work)
            n = patterns.shape[1]
            lower = (np.arange(n)[:, None] >= np.arange(n)[None, :]).ravel()
            nz = np.flatnonzero(np.any(flat != 0, axis=0) & lower)
            # L^-T is block-diagonal like M (bodies): sparse
            # (a flexible body's block of it is dense: see _Projection)
            self._factor = (_Projection(linv_t), nz, sps.csr_array(flat[:, nz].T), linv_t @ linv, linv_t)
        return self._factor

    def factor(self) -> tuple[_Projection, Array]:
        """``L^-T`` as :class:`_Projection` and as a dense (n, n) array."""
        factor = self._factored()
        return factor[0], factor[4]

    def reduce(self, stiffness_coefficients: Array) -> Array:
        """The lower triangle of ``L^-1 K L^-T`` (B, n, n), what ``eigh`` reads, from the stiffness coefficients
        (B, n_terms); the upper triangle is zero."""
        _, nz, patterns, _, _ = self._factored()
        n = self.model.n_dof
        out = np.zeros((stiffness_coefficients.shape[0], n * n))
        out[:, nz] = (patterns @ np.ascontiguousarray(stiffness_coefficients.T)).T
        return out.reshape(-1, n, n)

    def shapes(self, vectors: Array) -> Array:
        """``L^-T v`` (B, n, m), C-contiguous like :class:`_MassReduction`'s (consumers' BLAS products then sum in
        the same order whichever reduction a sample took)."""
        return _unflatten(self.flat_shapes(vectors), vectors.shape[2])

    def flat_shapes(self, vectors: Array) -> Array:
        """``L^-T v`` laid out as :func:`_flatten` lays out ``v``."""
        linv_t = self._factored()[0]
        if not linv_t.dense_index.size:
            return np.asarray(linv_t.sparse @ _flatten(vectors))
        return _flatten(linv_t.project(_flatten(vectors), vectors.shape[2]))

    def inverse_mass(self) -> Array:
        return self._factored()[3]


class _Reductions:
    """The reductions of a chunk: the nominal one for the rows ``shared``, the samples' own for the others."""

    def __init__(self, shared: NDArray[np.bool_], nominal: _NominalReduction, other: _MassReduction | None) -> None:
        self.shared, self.nominal, self.other = shared, nominal, other

    def shapes(self, vectors: Array) -> Array:
        if self.other is None:
            return self.nominal.shapes(vectors)
        out = np.empty(vectors.shape)
        out[self.shared] = self.nominal.shapes(vectors[self.shared])
        out[~self.shared] = self.other.shapes(vectors[~self.shared])
        return out

    def inverse_mass(self) -> Array:
        n = self.nominal.model.n_dof
        out = np.empty((self.shared.size, n, n))
        out[self.shared] = self.nominal.inverse_mass()
        if self.other is not None:
            out[~self.shared] = self.other.inverse_mass()
        return out


class _ScaledReduction:
    """The reduction of samples whose M differs from the nominal one by a block-diagonal factor: ``L = L_nom S^-1``.

    A flexible body's mass block is ``s_m M_fe``: with its scale ``s_m`` varying (an unknown), its Cholesky factor is
    the nominal one times ``sqrt(s_m / s_m,nom)``, so ``S`` is a number on that block; a rigid body's 6 x 6 block
    takes ``S_b = L_b^-1 L_b,nom`` (two small factorizations). The sample's reduced stiffness is then
    ``S (L_nom^-1 K L_nom^-T) S^T`` from the nominal reduction's patterns (no assembly of K, no factorization of the
    dense block, O(n^2) per sample instead of the two dense O(n^3) products of :class:`_MassReduction`) and its shapes
    ``L_nom^-T (S^T v)``: the nominal path's fused rows apply. Taken only on models with a flexible body (rigid
    ones keep :class:`_MassReduction`'s block products) where every large mass block of the chunk is a multiple of
    its nominal one (the samples with the nominal M take ``S = I``, exactly).
    """

    #: Blocks larger than this must be multiples of their nominal ones (a rigid body's are at most 6 x 6).
    SMALL = 6

    def __init__(self, nominal: _NominalReduction, scalars: list[tuple[NDArray[np.intp], Array]],
                 blocks: list[tuple[NDArray[np.intp], Array]]) -> None:
        self.nominal = nominal
        self.scalars = scalars  # per group of large blocks: DOFs (n_blocks, s) and each sample's factor (B, n_blocks)
        self.blocks = blocks  # per group of small blocks: DOFs (n_blocks, s) and S_b (B, n_blocks, s, s)

    @classmethod
    def of(cls, nominal: _NominalReduction, params: Array, shared: NDArray[np.bool_]) -> _ScaledReduction | None:
        """The scaled reduction of the samples ``params`` (B, n_params), or None where it does not apply."""
        plan = nominal.scale_plan()
        if plan is None:
            return None
        coefficients = nominal.model.affine_terms(("M",), params, nominal.position)["M"][0]  # (B, n_terms)
        scalars: list[tuple[NDArray[np.intp], Array]] = []
        blocks: list[tuple[NDArray[np.intp], Array]] = []
        for group, kind, data, reference in plan:
            if kind == "scalar":  # each block is c_t P_t of one term t: L = sqrt(c_t / c_t,nom) L_nom
                ratio = coefficients[:, data] / reference
                if (ratio <= 0).any():
                    return None  # not positive definite: the samples' own factorization names them
                factor = 1.0 / np.sqrt(ratio)
                factor[shared] = 1.0
                scalars.append((group, factor))
                continue
            own = np.zeros((params.shape[0], *data.shape[1:]))
            for t in range(data.shape[0]):  # a fixed-order sum: the same bits in any chunk
                if data[t].any():
                    own += coefficients[:, t, None, None, None] * data[t]
            try:
                factor = np.linalg.inv(np.linalg.cholesky(own)) @ reference
            except np.linalg.LinAlgError:
                return None
            factor[shared] = np.eye(group.shape[1])
            blocks.append((group, factor))
        return cls(nominal, scalars, blocks)

    def reduce(self, lower: Array) -> Array:
        """``S A S^T`` (B, n, n) from the lower triangle of ``A = L_nom^-1 K L_nom^-T`` (what
        :meth:`_NominalReduction.reduce` gives; the upper triangle is zero)."""
        out = lower
        b, n, _ = out.shape
        if self.blocks:
            # the small blocks' DOFs come first (rigid bodies; :meth:`_NominalReduction.scale_plan`): their rows in
            # full (the upper part from the lower triangle's columns) are all the row mixing reads, and the column
            # mixing reads the lower triangle only
            r = sum(group.size for group, _ in self.blocks)
            out[:, :r, :] += np.swapaxes(np.tril(lower[:, :, :r], -1), 1, 2)
        if self.scalars:
            d = self._scale(b, n)
            out *= d[:, :, None]
            out *= d[:, None, :]
        for group, factor in self.blocks:
            nb, s = group.shape
            idx = _as_slice(group.ravel())
            out[:, idx, :] = (factor @ out[:, idx, :].reshape(b, nb, s, n)).reshape(b, nb * s, n)
            out[:, :, idx] = (out[:, :, idx].reshape(b, n, nb, s).transpose(0, 2, 1, 3)
                              @ np.swapaxes(factor, 2, 3)).transpose(0, 2, 1, 3).reshape(b, n, nb * s)
        return out

    def _scale(self, b: int, n: int) -> Array:
        """Per sample and DOF the number of the scalar blocks (1 elsewhere), (B, n)."""
        d = np.ones((b, n))
        for group, factor in self.scalars:
            d[:, group] = factor[:, :, None]
        return d

    def premultiply(self, vectors: Array) -> Array:
        """``S^T v`` (B, n, m), C-contiguous."""
        b, n, m = vectors.shape
        out = vectors * self._scale(b, n)[:, :, None] if self.scalars else np.array(vectors, order="C")
        for group, factor in self.blocks:
            nb, s = group.shape
            idx = _as_slice(group.ravel())
            out[:, idx, :] = (np.swapaxes(factor, 2, 3) @ out[:, idx, :].reshape(b, nb, s, m)).reshape(b, nb * s, m)
        return np.ascontiguousarray(out)

    def shapes(self, vectors: Array) -> Array:
        return self.nominal.shapes(self.premultiply(vectors))

    def inverse_mass(self) -> Array:
        """``L^-T L^-1`` (B, n, n)."""
        n = self.nominal.model.n_dof
        b = (self.scalars[0][1] if self.scalars else self.blocks[0][1]).shape[0]
        linv_t = self.shapes(np.broadcast_to(np.eye(n), (b, n, n)))
        return np.asarray(linv_t @ np.swapaxes(linv_t, 1, 2))


def _as_slice(index: NDArray[np.intp]) -> NDArray[np.intp] | slice:
    """A run of consecutive indices as a slice (a view, no gather and scatter: the rigid bodies' DOFs come first)."""
    if index.size and np.array_equal(index, np.arange(index[0], index[0] + index.size)):
        return slice(int(index[0]), int(index[0]) + index.size)
    return index


def _inverse_cholesky(mass: Array, groups: list[NDArray[np.intp]], offset: int) -> Array:
    """``L^-1`` with ``M = L L^T`` for a stack of mass matrices, block by block; names the samples where M is
    not positive definite.

    ``groups`` lists M's diagonal blocks by size, (n_blocks, size) index arrays. Rigid-body mass matrices are
    block-diagonal by body, so factoring and inverting (B * n_bodies) 6 x 6 blocks replaces a dense
    Cholesky plus inverse of (B, n, n): measured 10-30x cheaper at n_dof 30-150 (benchmarks/bench_modal.py).
    """
    b, n, _ = mass.shape
    linv = np.zeros_like(mass)
    for group in groups:
        rows = group[:, :, None]
        cols = group[:, None, :]
        blocks = mass[:, rows, cols]  # (B, n_blocks, s, s)
        try:
            chol = np.linalg.cholesky(blocks)
        except np.linalg.LinAlgError as exc:
            bad = [i for i in range(b) if not all(_is_positive_definite(m) for m in blocks[i])]
            msg = (
                f"mass matrix is not positive definite for samples "
                f"{_first(np.array(bad, dtype=np.intp) + offset)} (non-physical masses or inertias)"
            )
            raise ModelError(msg) from exc
        linv[:, rows, cols] = np.linalg.inv(chol)
    return linv


def _is_positive_definite(mat: Array) -> bool:
    try:
        np.linalg.cholesky(mat)
    except np.linalg.LinAlgError:
        return False
    return True


def _first_order_damping(
    sources: DampingSources, elongation: Array, omega: Array, contributions: bool
) -> tuple[Array, Array | None, Array | None]:
    """zeta = sum_j coef_j (h_j phi)^2 / (2 omega^k), k = 1 viscous, 2 hysteretic; rigid modes get 0.

    ``elongation`` holds the modal elongations ``h_j phi`` of the sources, (B, n_src, m).
    """
    b, _, m = elongation.shape
    if not sources.names:
        zeros = np.zeros((b, m))
        if not contributions:
            return zeros, None, None
        assert sources.jacobian is not None  # the engine asks for it with the contributions
        return zeros, np.zeros((b, m, 0)), np.zeros((b, m, sources.jacobian.shape[2]))
    elong2 = np.square(elongation)
    rigid = omega == 0
    safe = np.where(rigid, 1.0, omega)
    # 1 / (2 omega^k) per kind of source (no power of the (B, n_src, m) array); rigid modes get 0
    per_kind = (np.where(rigid, 0.0, 0.5 / safe), np.where(rigid, 0.0, 0.5 / (safe * safe)))  # (B, m) each
    hysteretic = sources.hysteretic
    if not contributions:
        # zeta = sum over the sources of each kind: one batched (1, n_src) @ (n_src, m) product per kind
        zeta = np.zeros((b, m))
        for kind, factor in zip((~hysteretic, hysteretic), per_kind, strict=True):
            if np.any(kind):
                coef = np.where(kind, sources.coefficients, 0.0)[:, None, :]  # (B, 1, n_src)
                zeta += (coef @ elong2)[:, 0, :] * factor
        return zeta, None, None
    unit = elong2 * np.where(hysteretic[None, :, None], per_kind[1][:, None, :], per_kind[0][:, None, :])
    contrib = unit * sources.coefficients[:, :, None]
    zeta = contrib.sum(axis=1)
    assert sources.jacobian is not None  # the engine asks for it with the contributions
    gradient = np.swapaxes(unit, 1, 2) @ sources.jacobian  # (B, m, n_params)
    return zeta, np.ascontiguousarray(np.swapaxes(contrib, 1, 2)), gradient


def _track(reference: ModeReference, phi: Array) -> tuple[NDArray[np.intp], Array]:
    """Index of the candidate mode matching each reference mode, and its mass-weighted MAC."""
    weighted = reference.shapes.T @ reference.mass  # (m_ref, n)
    cross = weighted @ phi  # (B, m_ref, n_cand)
    norm_ref = np.einsum("ir,ir->r", reference.shapes, reference.mass @ reference.shapes)
    norm = np.einsum("bir,bir->br", phi, reference.mass @ phi)
    mac = cross**2 / (norm_ref[None, :, None] * norm[:, None, :])
    best = np.argmax(mac, axis=2)
    index = best.copy()
    for b in range(phi.shape[0]):
        if np.unique(best[b]).size != best.shape[1]:  # two reference modes claim one mode: assign optimally
            rows, cols = linear_sum_assignment(mac[b], maximize=True)
            index[b, rows] = cols
    chosen = np.take_along_axis(mac, index[:, :, None], axis=2)[:, :, 0]
    return index.astype(np.intp), chosen


@dataclass(frozen=True)
class StateEigensystem:
    """The eigen-decomposition of the first-order state matrix ``A = [[0, I], [-M^-1 (K + iH), -M^-1 (C + G)]]``
    of a batch (or of one vector: no batch axis), with the matrices it was made from.

    Attributes
    ----------
    mats : dict
        ``M, C, G, K, H`` (B, n, n) or (n, n).
    minv : ndarray
        ``M^-1``.
    lam : ndarray of complex, shape (B, 2 n) or (2 n,)
        Eigenvalues of ``A``.
    vec : ndarray, shape (B, 2 n, 2 n) or (2 n, 2 n)
        Right eigenvectors (columns), as LAPACK returns them.
    """

    mats: dict[str, Array]
    minv: Array
    lam: NDArray[Any]
    vec: NDArray[Any]

    @classmethod
    def of(cls, mats: dict[str, Array], minv: Array) -> StateEigensystem:
        """The decomposition of the batch's state matrices (one batched ``eig``)."""
        b, n, _ = mats["M"].shape
        stiff = mats["K"] + 1j * mats["H"] if np.any(mats["H"]) else mats["K"]
        state = np.zeros((b, 2 * n, 2 * n), dtype=stiff.dtype)
        state[:, :n, n:] = np.eye(n)
        state[:, n:, :n] = -(minv @ stiff)
        state[:, n:, n:] = -(minv @ (mats["C"] + mats["G"]))
        lam, vec = np.linalg.eig(state)
        return cls(mats, minv, lam, vec)

    def first(self) -> StateEigensystem:
        """The first vector's decomposition, without the batch axis (copies: the batch's arrays are released)."""
        return StateEigensystem({k: v[0].copy() for k, v in self.mats.items()}, self.minv[0].copy(),
                                self.lam[0].copy(), self.vec[0].copy())


@dataclass(frozen=True)
class QuadraticModes:
    """Exact complex modes of one vector, solved mode by mode on the quadratic eigenproblem
    ``Q(s) x = (s^2 M + s (C + G) + K + iH) x = 0``, each from its undamped mode.

    Each mode starts from its undamped shape ``phi_r`` and first-order pole
    ``omega_r (-zeta_r + i sqrt(1 - zeta_r^2))`` (``sigma``) and runs inverse iteration of the state matrix with that
    shift, written on the quadratic problem: ``z = -Q(sigma)^-1 (M v + (C + G + sigma M) x)`` for the state vector
    ``(x, v)`` (one complex LU of order n_dof; the error shrinks by ``|s - sigma| / |s' - sigma|`` per step, ``s'``
    the next-nearest pole), the pole from the Rayleigh functional ``x^H Q(s) x = 0``. A mode that has not converged
    after a few steps is shifted to its current pole and factored again (Rayleigh-quotient acceleration).
    :meth:`solve` returns None when a mode misses (no convergence, a pole not in the upper half plane, a shape that
    is not its undamped mode's: squared mass-weighted similarity below 0.5, or two modes on one pole): the caller
    then takes the state matrix's full eig, which pairs by optimal assignment.

    Attributes
    ----------
    mats : dict
        ``M, C, G, K, H`` (n, n) of the vector.
    poles : ndarray of complex, shape (m,)
        Poles (rad/s, upper half plane; 0 for rigid-body modes).
    shapes : ndarray of complex, shape (n, m)
        Displacement shapes, scaled so that ``phi_r^T M x_r = 1`` as :func:`_exact_modes` scales them (rigid-body
        modes: their real shape).
    """

    mats: dict[str, Array]
    poles: NDArray[np.complex128]
    shapes: NDArray[np.complex128]

    @classmethod
    def solve(cls, mats: dict[str, Array], phi: Array, omega: Array, zeta: Array, *,
              previous: QuadraticModes | None = None) -> QuadraticModes | None:
        """The exact modes of the undamped modes ``phi`` (n, m) with ``omega`` (m,) rad/s and first-order damping
        ratios ``zeta`` (m,), or None if one misses (see the class notes). With ``previous`` (the exact modes of a
        nearby vector, the same m modes), each mode starts from its previous pole and shape, and all start cold as
        above if one of them misses from there."""
        mass, visc = mats["M"], mats["C"] + mats["G"]
        stiff = mats["K"] + 1j * mats["H"]
        norms = (float(np.abs(mass).sum(axis=0).max()), float(np.abs(visc).sum(axis=0).max()),
                 float(np.abs(stiff).sum(axis=0).max()))
        stack = np.concatenate([mass, visc, stiff]).astype(complex)
        moving = np.flatnonzero(omega > 0)
        w, z = omega[moving], zeta[moving]
        if not np.all((z >= 0.0) & (z < 1.0)):  # overdamped to first order: the full eig judges
            return None
        # a search's next point moves each pole by a fraction of its distance to the next one: from the previous
        # pole as the shift, inverse iteration needs 43 % fewer steps (117 against 205 per position on the
        # three-axis machine's joint refinement); a start that converges elsewhere fails the checks and goes cold
        if (previous is not None and previous.poles.shape == omega.shape
                and np.array_equal(np.flatnonzero(previous.poles != 0), moving)):
            warm = cls._accepted(mats, stack, norms, phi, moving, previous.shapes[:, moving], previous.poles[moving])
            if warm is not None:
                return warm
        return cls._accepted(mats, stack, norms, phi, moving, phi[:, moving], w * (-z + 1j * np.sqrt(1.0 - z * z)))

    @classmethod
    def _accepted(cls, mats: dict[str, Array], stack: NDArray[np.complex128], norms: tuple[float, float, float],
                  phi: Array, moving: NDArray[np.intp], x0: NDArray[Any], s0: NDArray[np.complex128],
                  ) -> QuadraticModes | None:
        """The modes of ``phi`` by inverse iteration of the moving ones from ``(s0, x0)``, or None where one misses
        (no convergence, a pole not in the upper half plane, a shape not its undamped mode's, two modes on one pole).
        """
        mass = mats["M"]
        poles = np.zeros(phi.shape[1], dtype=complex)
        shapes = phi.astype(complex)
        if moving.size:
            found = _quadratic_modes(stack, x0, s0, norms)
            if found is None:
                return None
            lam, x = found  # (k,), (k, n): one mode per row
            overlap = np.einsum("ij,ji->i", x, mass @ phi[:, moving])  # phi_r^T M x_r
            energy = np.einsum("ij,ij->i", x.conj(), x @ mass.T).real  # x_r^H M x_r
            if np.any(lam.imag <= 0) or np.any(np.abs(overlap) ** 2 < 0.5 * energy):
                return None
            poles[moving], shapes[:, moving] = lam, (x / overlap[:, None]).T
        upper = poles[moving]
        if upper.size > 1:
            gap = np.abs(upper[:, None] - upper[None, :]) + np.diag(np.full(upper.size, np.inf))
            if gap.min() <= 1e-8 * np.abs(upper).max():
                return None
        return cls(dict(mats), poles, shapes)


#: Factorizations (shifts) per quadratic-eigenproblem mode, and inverse-iteration steps per factorization.
QUADRATIC_SHIFTS = 4
QUADRATIC_STEPS = 8


def _quadratic_modes(stack: NDArray[np.complex128], x0: Array, s0: NDArray[np.complex128],
                     norms: tuple[float, float, float]) -> tuple[NDArray[np.complex128], NDArray[np.complex128]] | None:
    """The modes of ``(s^2 M + s D + S) x = 0`` by shifted inverse iteration, mode r from ``(s0[r], x0[:, r])`` (see
    :class:`QuadraticModes`; ``stack`` is ``[M; D; S]``, (3 n, n) complex): the poles (k,) and the shapes (k, n), one
    per row with largest component 1; None if a mode does not converge.

    The modes iterate side by side, each with its own shift, LU and convergence as if alone (one LAPACK ``getrf``
    per shift and two triangular solves, :func:`_lu_solve`, per step and mode); the products with ``M, D, S``, the
    Rayleigh functionals and the backward errors of a step are one matrix operation for all modes.
    """
    getrf = scipy.linalg.lapack.zgetrf
    n, k = x0.shape
    # (s^2, s, 1) @ flat_t is Q(s)^T in C order, i.e. Q(s) in the Fortran order getrf takes without a copy
    flat_t = np.ascontiguousarray(stack.reshape(3, n, n).transpose(0, 2, 1)).reshape(3, n * n)
    stack_t = np.ascontiguousarray(stack.T)  # x (rows) @ stack_t = [M x, D x, S x]
    x = np.array(x0.T, dtype=complex)  # (k, n)
    x /= x[np.arange(k), np.argmax(np.abs(x), axis=1)][:, None]
    lam, sigma = np.array(s0, dtype=complex), np.array(s0, dtype=complex)
    prod = x @ stack_t  # (k, 3 n)
    v_mass = lam[:, None] * prod[:, :n]  # M v for the state vectors (x, v = lam x)
    out_lam, out_x = np.zeros(k, dtype=complex), np.zeros((k, n), dtype=complex)
    done = np.zeros(k, dtype=bool)
    for _ in range(QUADRATIC_SHIFTS):
        live = np.flatnonzero(~done)
        if live.size == 0:
            break
        coef = np.stack([sigma[live] ** 2, sigma[live], np.ones(live.size)], axis=1)
        factors: dict[int, tuple[Any, NDArray[np.intp]]] = {}
        for r, q in zip(live, (coef @ flat_t).reshape(live.size, n, n), strict=True):
            lu, piv, info = getrf(q.T, overwrite_a=True)
            if info != 0:  # the shift is a pole to the last bit: no inverse
                return None
            factors[int(r)] = (lu, _row_order(piv))
        best = np.full(k, np.nan)  # backward error of this shift's converged modes (their pole and shape in out_*)
        for _ in range(QUADRATIC_STEPS):
            if live.size == 0:
                break
            rhs = -(v_mass[live] + prod[live, n:2 * n] + sigma[live, None] * prod[live, :n])
            z = np.array([_lu_solve(*factors[int(r)], b) for r, b in zip(live, rhs, strict=True)])
            pivot = z[np.arange(live.size), np.argmax(np.abs(z), axis=1)][:, None]
            previous = prod[live, :n] / pivot  # M x_old, rescaled
            x[live] = z / pivot
            prod[live] = x[live] @ stack_t
            mx, dx, sx = prod[live, :n], prod[live, n:2 * n], prod[live, 2 * n:]
            v_mass[live] = previous + sigma[live, None] * mx  # M (x_old + sigma z), rescaled
            a = np.einsum("ij,ij->i", x[live].conj(), mx)
            b = np.einsum("ij,ij->i", x[live].conj(), dx)
            c = np.einsum("ij,ij->i", x[live].conj(), sx)
            root = np.sqrt(b * b - 4 * a * c)
            plus, minus = (-b + root) / (2 * a), (-b - root) / (2 * a)
            lam[live] = np.where(np.abs(plus - lam[live]) <= np.abs(minus - lam[live]), plus, minus)
            s = lam[live, None]
            residual = s * s * mx + s * dx + sx
            size = np.abs(lam[live]) ** 2 * norms[0] + np.abs(lam[live]) * norms[1] + norms[2]
            error = np.abs(residual).sum(axis=1) / (size * np.abs(x[live]).sum(axis=1))
            # one step past convergence (it polishes the last digits): the better of the two, and the mode is done
            past = ~np.isnan(best[live])
            better = past & (error <= best[live])
            out_lam[live[better]], out_x[live[better]] = lam[live[better]], x[live[better]]
            done[live[past]] = True
            fresh = ~past & (error <= QUADRATIC_TOLERANCE)
            best[live[fresh]] = error[fresh]
            out_lam[live[fresh]], out_x[live[fresh]] = lam[live[fresh]], x[live[fresh]]
            live = live[~past]
        # converged on this shift's last step: its polished value; the others shift to their current pole
        done[~np.isnan(best)] = True
        sigma[~done] = lam[~done]
    if not np.all(done):
        return None
    return out_lam, out_x


def _row_order(piv: NDArray[np.int32]) -> NDArray[np.intp]:
    """The row order that LAPACK's ``getrf`` pivots ``piv`` (0-based, one interchange per row) put a right-hand side
    in: ``b[order]`` is ``P b`` (one ``laswp`` on the row indices)."""
    rows = np.arange(piv.size, dtype=float)[:, None]
    order: NDArray[np.intp] = scipy.linalg.lapack.dlaswp(rows, piv, overwrite_a=True)[:, 0].astype(np.intp)
    return order


def _lu_solve(lu: NDArray[np.complex128], order: NDArray[np.intp],
              b: NDArray[np.complex128]) -> NDArray[np.complex128]:
    """``A^-1 b`` for one column from ``getrf``'s factors of ``A`` (``order``: :func:`_row_order` of its pivots) by
    the two triangular solves (BLAS ``trsv``): what ``getrs`` does, without its matrix-solve (``trsm``) set-up, which
    costs more than the solves themselves for one column of order 162 (0.073 against 0.031 ms, one thread)."""
    trsv = scipy.linalg.blas.ztrsv
    y = trsv(lu, b[order], lower=1, diag=1, overwrite_x=1)
    return trsv(lu, y, lower=0, overwrite_x=1)  # type: ignore[no-any-return]


def _exact_modes(
    mats: dict[str, Array], minv: Array, phi: Array, omega: Array, system: StateEigensystem | None = None
) -> tuple[NDArray[np.complex128], NDArray[np.complex128]]:
    """Complex poles and displacement shapes of the full damped system, paired with the real modes.

    Pairing is by the mass-weighted similarity ``|phi^T M psi|^2 / psi^H M psi`` (optimal assignment);
    rigid-body modes keep pole 0 and their real shape; a real mode without an oscillatory partner (similarity
    below 0.5: overdamped) gets NaN. ``system``: the state matrices' decomposition, if already made.
    """
    b, n, m = phi.shape
    if system is None:
        system = StateEigensystem.of(mats, minv)
    lam, vec = system.lam, system.vec
    poles = np.full((b, m), np.nan + 1j * np.nan)
    shapes = np.full((b, n, m), np.nan + 1j * np.nan)
    mphi = mats["M"] @ phi  # (B, n, m)
    for k in range(b):
        upper = np.flatnonzero(lam[k].imag > 1e-9 * max(float(np.abs(lam[k]).max()), 1.0))
        psi = vec[k, :n, upper]  # (n_up, n)
        if upper.size == 0:
            continue
        overlap = np.abs(mphi[k].T @ psi.T)  # (m, n_up)
        norms = np.sqrt(np.einsum("ij,ij->j", np.conj(psi.T), mats["M"][k] @ psi.T).real)
        sim = overlap / np.where(norms > 0, norms, 1.0)
        rows, cols = linear_sum_assignment(sim, maximize=True)
        for r, c in zip(rows, cols, strict=True):
            if sim[r, c] ** 2 < 0.5 or omega[k, r] == 0:
                continue
            vector = psi[c]
            poles[k, r] = lam[k, upper[c]]
            shapes[k, :, r] = vector / (mphi[k, :, r] @ vector)
    rigid = omega == 0
    poles[rigid] = 0.0
    shapes = np.where(rigid[:, None, :], phi.astype(complex), shapes)
    return poles, shapes
