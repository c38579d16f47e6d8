"""The unknowns of an estimation: names, bounds, start, and the transformation the optimizers work in.

Bounded positive quantities (masses, stiffnesses, damping coefficients with a lower bound > 0) are searched in
``u = log(p)``: equal steps are equal relative changes, the box ``[log lo, log hi]`` is handled by the optimizers
natively, and a parameter can never cross zero. Others are searched in ``u = p / scale`` with ``scale`` the
larger bound magnitude (or the start), which keeps the internal variables of order one. No penalty functions: they
put walls into the cost that trapped the thesis's minimizer (thesis 4.3).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cappe._rng import RandomLike, as_generator
from cappe.exceptions import ModelError
from cappe.model import NumericModel, Structure

__all__ = ["ParameterSpace"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ParameterSpace:
    """Unknown parameters of a model with bounds, start and the internal (optimizer) coordinates.

    Attributes
    ----------
    names : tuple of str
        Unknown parameter names, in the order of every vector below.
    lower, upper : ndarray, shape (n,)
        Bounds in SI units (``-inf`` / ``inf`` allowed for unbounded parameters).
    start : ndarray, shape (n,)
        Start values (SI), inside the bounds.
    log : ndarray of bool, shape (n,)
        Which parameters are searched in ``log(p)``.
    scale : ndarray, shape (n,)
        Divisor of the linear ones.
    columns : ndarray of int, shape (n,)
        Positions of the unknowns in the model's full parameter vector.
    base : ndarray, shape (n_params,)
        The full parameter vector the unknowns are written into (nominal values of the known parameters).

    Examples
    --------
    >>> from cappe.model import load_model
    >>> space = ParameterSpace.from_model(load_model("builtin:two-mass-rig"), ["k11", "c11"])
    >>> space.names, bool(space.log.all())
    (('k11', 'c11'), True)
    >>> np.allclose(space.from_internal(space.to_internal(space.start)), space.start)
    True
    """

    names: tuple[str, ...]
    lower: Array
    upper: Array
    start: Array
    log: NDArray[np.bool_]
    scale: Array
    columns: NDArray[np.intp]
    base: Array

    @classmethod
    def from_model(
        cls,
        model: NumericModel | Structure,
        unknowns: Sequence[str] | None = None,
        *,
        bounds: Mapping[str, Sequence[float]] | None = None,
        start: Mapping[str, float] | None = None,
        values: Mapping[str, float] | None = None,
        log: bool | Mapping[str, bool] = True,
    ) -> ParameterSpace:
        """Unknowns (default: those marked ``unknown`` in the model), bounds (default: the model's), start
        (default: the model's values) and the known parameters' values (``values`` overrides nominal ones).

        Parameters
        ----------
        model : NumericModel or Structure
            The model whose parameters are estimated.
        unknowns : sequence of str, optional
            Parameters to estimate, in the order of every vector (default: those marked ``unknown``).
        bounds : mapping name -> (lower, upper), optional
            Bounds of some unknowns in SI units, overriding the model's (no bounds: unbounded).
        start : mapping name -> float, optional
            Start values of some unknowns (SI), inside their bounds.
        values : mapping name -> float, optional
            Values of any parameters (SI) for the base vector, overriding the model's nominal values.
        log : bool or mapping name -> bool
            Search in ``log(p)`` where the bounds allow it (``0 < lower``, finite ``upper``); otherwise linearly,
            divided by the largest finite bound (or the start).

        Returns
        -------
        ParameterSpace

        Raises
        ------
        ModelError
            Unknown names, no unknowns, missing or reversed bounds, or a start outside its bounds.
        """
        nm = model if isinstance(model, NumericModel) else NumericModel(model)
        structure = nm.structure
        names = list(unknowns) if unknowns is not None else [p.name for p in structure.parameters if p.unknown]
        if not names:
            msg = f"model '{structure.name}' marks no parameter unknown; name the unknowns to estimate"
            raise ModelError(msg)
        bad = [n for n in names if n not in nm.parameter_names]
        if bad:
            msg = f"unknowns {bad} are not parameters of model '{structure.name}'; its parameters: {nm.parameter_names}"
            raise ModelError(msg)
        repeated = sorted({n for n in names if names.count(n) > 1})
        if repeated:
            msg = f"unknowns must be listed once each; repeated: {repeated}"
            raise ModelError(msg)
        extra = sorted(set(bounds or {}) - set(names)) + sorted(set(start or {}) - set(names))
        if extra:
            msg = f"bounds or start given for {sorted(set(extra))}, which are not among the unknowns {names}"
            raise ModelError(msg)
        base = nm.vector(structure.resolve_parameters(values))
        columns = np.array([nm.parameter_names.index(n) for n in names], dtype=np.intp)
        lower, upper, first = [], [], []
        for name, col in zip(names, columns, strict=True):
            given = (bounds or {}).get(name)
            pair = given if given is not None else structure.parameter(name).bounds
            if pair is None:
                pair = (-np.inf, np.inf)
            lo, hi = (float(v) for v in pair)
            if not lo < hi:
                msg = f"bounds of {name!r} must satisfy lower < upper; got [{lo:g}, {hi:g}]"
                raise ModelError(msg)
            value = float((start or {}).get(name, base[col]))
            if not (np.isfinite(value) and lo <= value <= hi):
                msg = (f"start of {name!r} = {value:g} lies outside its bounds [{lo:g}, {hi:g}]; give a start value "
                       "inside them or bounds that contain it")
                raise ModelError(msg)
            lower.append(lo)
            upper.append(hi)
            first.append(value)
        lo_arr, hi_arr, start_arr = np.array(lower), np.array(upper), np.array(first)
        wants = np.array([log.get(n, True) if isinstance(log, Mapping) else bool(log) for n in names], dtype=bool)
        use_log = wants & (lo_arr > 0) & np.isfinite(hi_arr)
        mags = np.where(np.isfinite(hi_arr), np.abs(hi_arr), 0.0)
        mags = np.maximum(mags, np.where(np.isfinite(lo_arr), np.abs(lo_arr), 0.0))
        scale = np.where(mags > 0, mags, np.where(start_arr != 0, np.abs(start_arr), 1.0))
        return cls(tuple(names), lo_arr, hi_arr, start_arr, use_log, scale, columns, base)

    @property
    def n(self) -> int:
        return len(self.names)

    def to_internal(self, values: ArrayLike) -> Array:
        """Optimizer coordinates of SI values (..., n).

        Parameters
        ----------
        values : array_like, shape (..., n)
            Values of the unknowns in SI units.

        Returns
        -------
        ndarray, shape (..., n)
            ``log(|p|)`` for log-searched unknowns, ``p / scale`` for the others (dimensionless).
        """
        p = np.asarray(values, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.log, np.log(np.abs(p)), p / self.scale)

    def from_internal(self, internal: ArrayLike) -> Array:
        """SI values of optimizer coordinates (..., n).

        Parameters
        ----------
        internal : array_like, shape (..., n)
            Optimizer coordinates (dimensionless).

        Returns
        -------
        ndarray, shape (..., n)
            Values of the unknowns in SI units.
        """
        u = np.asarray(internal, dtype=float)
        return np.where(self.log, np.exp(u), u * self.scale)

    def internal_bounds(self) -> tuple[Array, Array]:
        """Box bounds in optimizer coordinates."""
        return self.to_internal(self.lower), self.to_internal(self.upper)

    def value_jacobian(self, internal: ArrayLike) -> Array:
        """``dp/du`` (..., n): the diagonal of the transformation's Jacobian (chain rule for gradients).

        Parameters
        ----------
        internal : array_like, shape (..., n)
            Optimizer coordinates (dimensionless).

        Returns
        -------
        ndarray, shape (..., n)
            ``p`` for log-searched unknowns, ``scale`` for the others (SI units of each unknown).
        """
        u = np.asarray(internal, dtype=float)
        return np.where(self.log, np.exp(u), self.scale)

    def full(self, values: ArrayLike) -> Array:
        """Full model parameter vectors (..., n_params) with the unknowns set to ``values`` (..., n).

        Parameters
        ----------
        values : array_like, shape (..., n)
            Values of the unknowns in SI units.

        Returns
        -------
        ndarray, shape (..., n_params)
            ``base`` with the unknowns' columns replaced (SI).
        """
        p = np.asarray(values, dtype=float)
        out = np.broadcast_to(self.base, (*p.shape[:-1], self.base.size)).copy()
        out[..., self.columns] = p
        return out

    def sample(self, rng: RandomLike = None) -> Array:
        """A random point within the bounds: log-uniform for log-searched unknowns, uniform for the others.

        The way the paper draws its random truths (Ellinger & Zaeh 2022, eq. 14 bounds); ``cappe model
        random-truth`` writes one as a parameter file.

        Parameters
        ----------
        rng : int, numpy.random.Generator or None
            Seed or generator (one ``uniform(size=n)`` draw is taken from it).

        Returns
        -------
        ndarray, shape (n,)
            Values of the unknowns (SI) in the order of ``names``.

        Raises
        ------
        ModelError
            An unknown without finite bounds (there is no uniform distribution to draw from).

        Examples
        --------
        >>> from cappe.model import load_model
        >>> space = ParameterSpace.from_model(load_model("builtin:two-mass-rig"), ["k11"], bounds={"k11": (1e5, 1e7)})
        >>> bool(1e5 <= space.sample(0)[0] <= 1e7)
        True
        """
        open_ = [n for n, lo, hi in zip(self.names, self.lower, self.upper, strict=True)
                 if not (np.isfinite(lo) and np.isfinite(hi))]
        if open_:
            msg = f"unknowns {open_} have no finite bounds to draw a random value within; give them bounds"
            raise ModelError(msg)
        u = as_generator(rng).uniform(size=self.n)
        with np.errstate(divide="ignore", invalid="ignore"):
            drawn = np.where(self.log, self.lower * (self.upper / self.lower) ** u,
                             self.lower + (self.upper - self.lower) * u)
        return np.asarray(drawn, dtype=float)

    def mapping(self, values: ArrayLike) -> dict[str, float]:
        """``{name: value}`` of one vector.

        Parameters
        ----------
        values : array_like, shape (n,)
            Values of the unknowns (SI).

        Returns
        -------
        dict
            ``{name: float}`` in the order of ``names``.
        """
        return {n: float(v) for n, v in zip(self.names, np.asarray(values, dtype=float), strict=True)}

    def vector(self, values: Mapping[str, float], what: str = "values") -> Array:
        """A vector (n,) from a mapping that names every unknown.

        Parameters
        ----------
        values : mapping name -> float
            A value (SI) for every unknown; other names are ignored.
        what : str
            What the values are, for the message.

        Returns
        -------
        ndarray, shape (n,)

        Raises
        ------
        ModelError
            An unknown is missing from ``values``.
        """
        missing = [n for n in self.names if n not in values]
        if missing:
            msg = f"{what} must give every unknown; missing {missing}"
            raise ModelError(msg)
        return np.array([float(values[n]) for n in self.names])

    def fixing(self, name: str, value: float) -> ParameterSpace:
        """The space without unknown ``name``, which is held at ``value`` (for profiles and staged fits).

        Parameters
        ----------
        name : str
            The unknown to fix.
        value : float
            Its value (SI), written into ``base``.

        Returns
        -------
        ParameterSpace
            The other ``n - 1`` unknowns.

        Raises
        ------
        ModelError
            ``name`` is not an unknown.
        """
        if name not in self.names:
            msg = f"{name!r} is not among the unknowns {list(self.names)}"
            raise ModelError(msg)
        k = self.names.index(name)
        keep = [j for j in range(self.n) if j != k]
        base = self.base.copy()
        base[self.columns[k]] = float(value)
        return ParameterSpace(
            tuple(self.names[j] for j in keep), self.lower[keep], self.upper[keep], self.start[keep], self.log[keep],
            self.scale[keep], self.columns[keep], base,
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            name: {"lower": float(lo), "upper": float(hi), "start": float(s), "log": bool(lg)}
            for name, lo, hi, s, lg in zip(self.names, self.lower, self.upper, self.start, self.log, strict=True)
        }
