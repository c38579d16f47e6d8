"""Compiled numeric model: fast evaluation of M, C, K, G, H for one or many parameter vectors.

Each matrix is ``X(p, r) = sum_j f_j(p, r) * P_j(r)`` (see :mod:`cappe.model.symbolic`). The patterns
``P_j`` are evaluated once per axis position and cached; a batch of parameter vectors then costs one
vectorized evaluation of the coefficients and one matrix product (B, n_terms) @ (n_terms, n*n).
Terms whose pattern itself depends on parameters (for instance an attachment point given by a length
parameter) are evaluated per sample instead; ``is_affine`` tells whether any exist.

A model that evaluates to NaN or inf (``sqrt(z)`` at a negative position, ``1/z`` at 0, a product beyond 1.8e308)
raises a :class:`~cappe.exceptions.ModelError` that names the model file, the entry and the values, e.g.
``model.yaml, elements[0].stiffness.x: evaluates to nan at z = -0.2``. Finding that costs the usual evaluation
only numpy's floating-point traps; the entry is looked for once something is wrong.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
import scipy.sparse as sps
import sympy as sp
from numpy.typing import NDArray
from scipy.sparse.csgraph import connected_components

from cappe.exceptions import ModelError
from cappe.model.structure import Structure
from cappe.model.symbolic import MATRIX_NAMES, SymbolicModel, Term

__all__ = ["DampingSources", "NumericModel", "compile_model"]

Array = NDArray[np.float64]
#: a coefficient in an error message: the terms it stands for, its expression, and what it is of them ("" or
#: "the derivative with respect to k")
_Column = tuple[tuple[str, ...], sp.Expr, str]
ParamsLike = Mapping[str, float] | Sequence[float] | NDArray[np.floating[Any]] | None


@dataclass
class _MatrixPlan:
    affine_coefficients: list[sp.Expr]
    affine_patterns: list[sp.Matrix]
    residual: sp.Matrix | None
    #: per affine coefficient, the terms (``Term.source``) it stands for
    sources: list[tuple[str, ...]]


class _NonFinite(Exception):  # noqa: N818 (internal signal, turned into a ModelError that names the entry)
    """Generated code gave NaN or inf (``values``: the evaluated coefficients where known), or a function of the
    model's expressions could not be evaluated (``cause``: its error, such as a bearing law beyond its range)."""

    def __init__(self, values: Array | None = None, cause: Exception | None = None) -> None:
        super().__init__("non-finite coefficient")
        self.values = values
        self.cause = cause


#: what each matrix is called in messages
_MATRIX_WORDS = {"M": "mass", "C": "viscous damping", "K": "stiffness", "G": "gyroscopic", "H": "hysteretic damping"}


@dataclass(frozen=True)
class DampingSources:
    """The damping sources of a model: one per element direction with viscous or hysteretic damping.

    Source ``j`` adds ``coefficient[j] * h_j^T h_j`` to C (``kind == "viscous"``, coefficient c) or to H
    (``kind == "hysteretic"``, coefficient eta * k), where ``h_j = rows[j]`` maps q to the element's
    elongation in that direction. For a mass-normalized mode ``phi`` of natural frequency ``omega``, source j
    contributes ``coefficient * (h phi)^2 / (2 omega)`` (viscous) or ``/ (2 omega^2)`` (hysteretic) to the
    first-order damping ratio (paper eq. 12).

    Attributes
    ----------
    names : tuple of str
        ``"element.c<dir>"`` or ``"element.eta<dir>"``.
    elements : tuple of str
        Element of each source.
    kinds : tuple of str
        ``"viscous"`` or ``"hysteretic"``.
    coefficients : ndarray, shape (B, n_sources)
        c (N s/m or N m s/rad) or eta * k (N/m or N m/rad) per sample.
    rows : ndarray, shape (n_sources, n_dof) or (B, n_sources, n_dof)
        Elongation rows; per sample only when attachment points depend on parameters.
    jacobian : ndarray, shape (B, n_sources, n_params), or None
        Partial derivatives of the coefficients with respect to every model parameter (None when not requested).
    """

    names: tuple[str, ...]
    elements: tuple[str, ...]
    kinds: tuple[str, ...]
    coefficients: Array
    rows: Array
    jacobian: Array | None

    @property
    def hysteretic(self) -> NDArray[np.bool_]:
        return np.array([k == "hysteretic" for k in self.kinds], dtype=bool)


def _jacobian(expressions: Sequence[sp.Expr], symbols: Sequence[sp.Symbol]) -> tuple[list[tuple[int, int]],
                                                                                  list[sp.Expr]]:
    """Structurally non-zero partial derivatives: their (expression, symbol) indices and the derivatives."""
    entries: list[tuple[int, int]] = []
    derivatives: list[sp.Expr] = []
    for j, expr in enumerate(expressions):
        present = sp.sympify(expr).free_symbols  # differentiate only by the symbols in expr (most are absent)
        for i, sym in enumerate(symbols):
            if sym not in present:
                continue
            d = sp.diff(expr, sym)
            if d != 0:
                entries.append((j, i))
                derivatives.append(d)
    return entries, derivatives


class _Coefficients:
    """Batched evaluation of a list of coefficient expressions in the parameters and axis positions.

    Most coefficients of a lumped-parameter model are a parameter, or a product of two (a loss factor times a
    stiffness), times a factor of the axis positions only (the share of a guide's stiffness a carriage takes at
    ``z``). Those are evaluated as ``p_a * p_b * g(r)`` over the whole batch with ``g`` computed once per
    position: three array operations instead of one generated-code output per coefficient, each copied into
    the result (measured on the 45-DOF machine tool, 158 coefficients and 70 damping sources: 0.19 + 0.18 ms
    fixed per engine call and ~7 us per sample before, with line_profiler on chunks of 4 and 64). The others
    keep generated code (sympy's ``lambdify``).
    """

    def __init__(self, expressions: Sequence[sp.Expr], parameters: Sequence[sp.Symbol],
                 axes: Sequence[sp.Symbol]) -> None:
        self.size = len(expressions)
        index = {sym: i for i, sym in enumerate(parameters)}
        axis_set = set(axes)
        ones = len(parameters)  # the column of ones appended to the batch: a missing second factor
        fast: list[int] = []
        pairs: list[tuple[int, int]] = []
        factors: list[sp.Expr] = []
        slow: list[int] = []
        for j, expr in enumerate(expressions):
            found = _product_form(sp.sympify(expr), index, axis_set)
            if found is None:
                slow.append(j)
                continue
            params, factor = found
            fast.append(j)
            padded = params + [ones, ones]
            pairs.append((padded[0], padded[1]))
            factors.append(factor)
        self._fast = np.array(fast, dtype=np.intp)
        self._first = np.array([a for a, _ in pairs], dtype=np.intp)
        self._second = np.array([b for _, b in pairs], dtype=np.intp)
        self._slow = np.array(slow, dtype=np.intp)
        self._factor_func = sp.lambdify(list(axes), factors, modules="numpy", cse=True)
        self._factor_cache: dict[tuple[float, ...], Array] = {}
        all_symbols = list(parameters) + list(axes)
        self._slow_func = sp.lambdify(all_symbols, [expressions[j] for j in slow], modules="numpy", cse=True)
        # partial derivatives: d(p_a p_b g)/dp_a = p_b g (no symbolic differentiation); the others by sympy
        entries: list[tuple[int, int]] = []
        other: list[int] = []
        factor_of: list[int] = []
        for f, (j, (a, b)) in enumerate(zip(fast, pairs, strict=True)):
            for this, that in ((a, b), (b, a)):
                if this != ones:
                    entries.append((j, this))
                    other.append(that)
                    factor_of.append(f)
        self._n_fast_entries = len(entries)
        self._jac_other = np.array(other, dtype=np.intp)
        self._jac_factor = np.array(factor_of, dtype=np.intp)
        slow_entries, derivatives = _jacobian([expressions[j] for j in slow], parameters)
        entries.extend((slow[k], i) for k, i in slow_entries)
        #: the structurally non-zero partial derivatives, (expression, parameter) index pairs
        self.entries = entries
        self._slow_jac_func = sp.lambdify(all_symbols, derivatives, modules="numpy", cse=True)

    def jacobian(self, pb: Array, pos: tuple[float, ...]) -> Array:
        """The partial derivatives listed in :attr:`entries`, (B, n_entries), for a batch at one position.

        Raises :class:`_NonFinite` where one is NaN or inf (see :meth:`__call__`).
        """
        return _checked(self._jacobian, pb, pos)

    def _jacobian(self, pb: Array, pos: tuple[float, ...]) -> Array:
        out = np.empty((pb.shape[0], len(self.entries)))
        fast = self._n_fast_entries
        if fast:
            out[:, :fast] = np.take(_with_ones(pb), self._jac_other, axis=1) * self._factors(pos)[self._jac_factor]
        if len(self.entries) > fast:
            for k, v in enumerate(self._slow_jac_func(*_arguments(pb, pos))):
                out[:, fast + k] = v
        return out

    def _factors(self, pos: tuple[float, ...]) -> Array:
        cached = self._factor_cache.get(pos)
        if cached is None:
            # numpy scalars: a factor undefined at this position gives inf or NaN as the generated code does for
            # arrays; Python floats would raise ZeroDivisionError or turn complex. Checked once per position.
            try:
                with np.errstate(all="ignore"):
                    cached = np.array(list(self._factor_func(*(np.float64(v) for v in pos))), dtype=float)
            except (ValueError, ArithmeticError) as exc:  # a function of the model's expressions, out of its range
                raise _NonFinite(cause=exc) from exc
            if not np.isfinite(cached).all():
                raise _NonFinite
            cached.setflags(write=False)
            self._factor_cache[pos] = cached
        return cached

    def __call__(self, pb: Array, pos: tuple[float, ...]) -> Array:
        """The coefficients (B, n) for a batch of parameter vectors (B, n_params) at one position.

        Raises :class:`_NonFinite` where a coefficient is NaN or inf. On the usual path this costs only
        numpy's floating-point traps (no pass over the result): finite parameters and axis factors give a
        non-finite coefficient only through an overflow, invalid operation or division by zero, which trap.
        """
        return _checked(self._evaluate, pb, pos)

    def _evaluate(self, pb: Array, pos: tuple[float, ...]) -> Array:
        if self._fast.size:
            ext = _with_ones(pb)
            # np.take lays the result out C-contiguous (ext[:, index] is column-major): consumers' BLAS products
            # then sum in the same order whatever the batch size
            values = np.take(ext, self._first, axis=1)
            values *= np.take(ext, self._second, axis=1)
            values *= self._factors(pos)
            if not self._slow.size:  # every coefficient in product form (the usual case): in order already
                return values
        out = np.empty((pb.shape[0], self.size))
        if self._fast.size:
            out[:, self._fast] = values
        if self._slow.size:
            for j, v in zip(self._slow, self._slow_func(*_arguments(pb, pos)), strict=True):
                out[:, j] = v
        return out


def _checked(evaluate: Any, pb: Array, pos: tuple[float, ...]) -> Array:
    """``evaluate(pb, pos)`` with floating-point traps; a trap is confirmed on a second, untrapped evaluation
    (generated code may compute a branch it then discards) and raises :class:`_NonFinite` with the values."""
    try:
        with np.errstate(over="raise", invalid="raise", divide="raise"):
            return cast(Array, evaluate(pb, pos))
    except FloatingPointError:
        pass
    except (ValueError, ArithmeticError) as exc:  # a function of the model's expressions, out of its range
        raise _NonFinite(cause=exc) from exc
    try:
        with np.errstate(all="ignore"):
            values = cast(Array, evaluate(pb, pos))
    except (ValueError, ArithmeticError) as exc:
        raise _NonFinite(cause=exc) from exc
    if not np.isfinite(values).all():
        raise _NonFinite(values)
    return values


def _scalars(pos: tuple[float, ...]) -> list[np.float64]:
    """Axis positions as numpy scalars: generated code then follows numpy's rules (1/0 is inf, sqrt(-1) NaN)
    instead of Python's (ZeroDivisionError, complex results)."""
    return [np.float64(v) for v in pos]


def _real(value: object) -> float:
    """``value`` as a float; NaN where it is not a real number (a complex or infinite sympy result)."""
    try:
        number = complex(value)  # type: ignore[call-overload]
    except (TypeError, ValueError, OverflowError):
        return math.nan
    return number.real if number.imag == 0 else math.nan


def _shown(value: object) -> str:
    """A value in a message: ``nan``, ``inf``, ``-inf``, a number, or a complex number said to be one."""
    try:
        number = complex(value)  # type: ignore[call-overload]
    except (TypeError, ValueError, OverflowError):
        return str(value)
    if number.imag != 0:
        return f"{number} (not a real number)"
    return f"{number.real:.6g}"


def _with_ones(pb: Array) -> Array:
    """The batch (B, n_params) with a column of ones appended: the factor a single-parameter product lacks."""
    ext = np.empty((pb.shape[0], pb.shape[1] + 1))
    ext[:, :-1] = pb
    ext[:, -1] = 1.0
    return ext


def _arguments(pb: Array, pos: tuple[float, ...]) -> list[Array]:
    """The arguments of generated code: one array per parameter, then one per axis (the position repeated)."""
    return [pb[:, i] for i in range(pb.shape[1])] + [np.full(pb.shape[0], v) for v in pos]


def _product_form(expr: sp.Expr, index: Mapping[sp.Symbol, int],
                  axes: set[sp.Symbol]) -> tuple[list[int], sp.Expr] | None:
    """``expr`` as (at most two parameter columns, a factor of the axes only), or None if it is not of that form."""
    params: list[int] = []
    rest: list[sp.Expr] = []
    for factor in sp.Mul.make_args(expr):
        if factor in index:
            params.append(index[factor])
        elif factor.free_symbols <= axes:
            rest.append(factor)
        else:
            return None
    if len(params) > 2:
        return None
    return params, sp.Mul(*rest)


def compile_model(model: Structure | SymbolicModel) -> NumericModel:
    """Compile a Structure (or its SymbolicModel) into a NumericModel.

    Parameters
    ----------
    model : Structure or SymbolicModel
        The model description (derived symbolically first when a Structure).

    Returns
    -------
    NumericModel
    """
    return NumericModel(model)


class NumericModel:
    """Numeric evaluation of a structure's matrices, inputs and outputs.

    Parameter vectors follow ``parameter_names`` (all model parameters, in file order); a mapping of
    overrides by name is accepted wherever a vector is.

    Parameters
    ----------
    model : Structure or SymbolicModel
        The model description (derived symbolically first when a Structure).

    Examples
    --------
    >>> from cappe.model import load_model
    >>> nm = NumericModel(load_model("builtin:two-mass-rig"))
    >>> nm.matrices()["K"]
    array([[1500000., -120000.],
           [-120000.,  360000.]])
    """

    def __init__(self, model: Structure | SymbolicModel) -> None:
        self.symbolic = model if isinstance(model, SymbolicModel) else SymbolicModel(model)
        self.symbolic.check_signals()
        self.structure = self.symbolic.structure
        self.parameter_names = self.structure.parameter_names
        self.axis_names = self.structure.axis_names
        self.dofs = self.structure.dofs
        self.n_dof = self.structure.n_dof
        self.nominal = np.array([p.value for p in self.structure.parameters], dtype=float)
        self._param_symbols = [self.symbolic.symbols[n] for n in self.parameter_names]
        self._axis_symbols = [self.symbolic.symbols[n] for n in self.axis_names]
        self._plans = {name: self._plan(self.symbolic.terms[name]) for name in MATRIX_NAMES}
        coefficients: list[sp.Expr] = []
        self._slices: dict[str, slice] = {}
        #: per coefficient, the terms it stands for (to name the model entry in an error)
        self._coefficient_sources: list[tuple[str, ...]] = []
        #: per matrix, the numeric blocks of flexible bodies as flat patterns (n_blocks, n*n); their coefficients
        #: follow the matrix's symbolic ones
        self._block_patterns: dict[str, Array] = {}
        for name in MATRIX_NAMES:
            start = len(coefficients)
            coefficients.extend(self._plans[name].affine_coefficients)
            self._coefficient_sources.extend(self._plans[name].sources)
            blocks = self.symbolic.block_terms[name]
            coefficients.extend(term.coefficient for term in blocks)
            self._coefficient_sources.extend((term.source,) for term in blocks)
            self._block_patterns[name] = self._block_flat(blocks)
            self._slices[name] = slice(start, len(coefficients))
        self._coefficient_expressions = coefficients
        #: the coefficients that are an element's stiffness, damping or loss times stiffness: never negative
        self._nonnegative = np.concatenate([np.arange(self._slices[name].start, self._slices[name].stop)
                                            for name in ("K", "C", "H")]).astype(np.intp)
        #: per DOF, the model entry of its body (for messages)
        self._dof_entries = (tuple(self._location(f"bodies[{i}]") for i, b in enumerate(self.structure.bodies)
                                   for _ in b.dofs)
                             + tuple(self._location(f"flexible_bodies[{i}]")
                                     for i, f in enumerate(self.structure.flexible_bodies) for _ in range(f.n_dof)))
        all_symbols = self._param_symbols + self._axis_symbols
        self._n_coef = len(coefficients)
        self._coefficients = _Coefficients(coefficients, self._param_symbols, self._axis_symbols)
        # patterns are mostly zeros: generate code for the structural non-zeros only and scatter them (printing
        # every entry of every dense pattern took most of the compile time of a 45-DOF model)
        self._pattern_funcs: dict[str, tuple[int, NDArray[np.intp], Any]] = {}
        for name, plan in self._plans.items():
            where: list[int] = []
            exprs: list[sp.Expr] = []
            for t, pattern in enumerate(plan.affine_patterns):
                for (i, j), value in sorted(sp.SparseMatrix(pattern).todok().items()):
                    where.append((t * self.n_dof + i) * self.n_dof + j)
                    exprs.append(value)
            func = sp.lambdify(self._axis_symbols, exprs, modules="numpy", cse=True)
            self._pattern_funcs[name] = (len(plan.affine_patterns), np.array(where, dtype=np.intp), func)
        self._residual_funcs = {
            name: sp.lambdify(all_symbols, plan.residual, modules="numpy", cse=True)
            for name, plan in self._plans.items()
            if plan.residual is not None
        }
        self.is_affine = not self._residual_funcs
        self._io = sp.lambdify(
            all_symbols, [self.symbolic.input_matrix(), self.symbolic.output_matrix()], modules="numpy", cse=True
        )
        self.input_names = tuple(i.name for i in self.structure.inputs)
        self.output_names = tuple(o.name for o in self.structure.outputs)
        self.output_quantities = tuple(o.quantity for o in self.structure.outputs)
        self._pattern_cache: dict[tuple[float, ...], dict[str, Array]] = {}
        self._source_row_cache: dict[tuple[float, ...], Array] = {}
        self._sensor_matrix_cache: dict[tuple[tuple[str, ...], tuple[float, ...], bytes], tuple[tuple[str, ...],
                                                                                         Array]] = {}
        self._sensor_moves: dict[str, bool] = {}
        self._entry_values: tuple[list[tuple[str, str, sp.Expr]], Any] | None = None
        self._compile_damping_sources()
        self._sparse_cache: dict[tuple[float, ...], dict[str, tuple[NDArray[np.intp], sps.csr_array]]] = {}
        self._term_cache: dict[tuple[float, ...], dict[str, sps.csr_array]] = {}
        #: per position, the largest coefficient magnitude no assembled entry can overflow with
        self._safe_coefficient: dict[tuple[float, ...], float] = {}
        # derivatives of the affine coefficients (only the structurally non-zero ones) and of residual terms
        self._jacobian_entries = np.array(self._coefficients.entries, dtype=np.intp).reshape(-1, 2)
        self._residual_derivative_funcs = {
            name: sp.lambdify(
                all_symbols, [plan.residual.diff(sym) for sym in self._param_symbols], modules="numpy", cse=True
            )
            for name, plan in self._plans.items()
            if plan.residual is not None
        }

    def _block_flat(self, blocks: Sequence[Any]) -> Array:
        """Flexible bodies' numeric blocks placed in full (n, n) patterns, flattened: (n_blocks, n*n)."""
        n = self.n_dof
        out = np.zeros((len(blocks), n, n))
        for t, term in enumerate(blocks):
            size = term.block.shape[0]
            out[t, term.offset:term.offset + size, term.offset:term.offset + size] = term.block
        flat = out.reshape(len(blocks), n * n)
        flat.setflags(write=False)
        return flat

    def _compile_damping_sources(self) -> None:
        names: list[str] = []
        elements: list[str] = []
        kinds: list[str] = []
        coefficients: list[sp.Expr] = []
        rows: list[list[sp.Expr]] = []
        for e in self.structure.elements:
            for d in e.directions:
                h = self.symbolic.elongation_row(e.name, d)
                if not h:
                    continue
                dense = [h.get(j, sp.Integer(0)) for j in range(self.n_dof)]
                found = []
                if d in e.damping and e.damping[d] != 0:
                    found.append((f"{e.name}.c{d}", "viscous", e.damping[d]))
                if d in e.loss and e.loss[d] != 0 and d in e.stiffness:
                    found.append((f"{e.name}.eta{d}", "hysteretic", e.loss[d] * e.stiffness[d]))
                for name, kind, coefficient in found:
                    names.append(name)
                    kinds.append(kind)
                    coefficients.append(coefficient)
                    elements.append(e.name)
                    rows.append(dense)
        # flexible bodies: each damping block (symmetric, positive semi-definite) as a sum of rank-one sources
        # d_i u_i u_i^T, so the first-order damping ratios and their derivatives treat them as they treat elements
        fixed: list[Array] = []
        for term in self.symbolic.block_terms["C"] + self.symbolic.block_terms["H"]:
            weights, vectors = np.linalg.eigh(term.block)
            keep = np.flatnonzero(weights > 1e-12 * max(float(abs(weights).max()), 1e-300))
            for number, i in enumerate(keep, start=1):
                row = np.zeros(self.n_dof)
                row[term.offset:term.offset + vectors.shape[0]] = np.sqrt(weights[i]) * vectors[:, i]
                fixed.append(row)
                names.append(f"{term.source}{number}")
                kinds.append("viscous" if term in self.symbolic.block_terms["C"] else "hysteretic")
                coefficients.append(term.coefficient)
                elements.append(term.source.rpartition(".")[0])
        self._source_fixed_rows = np.array(fixed).reshape(len(fixed), self.n_dof)
        all_symbols = self._param_symbols + self._axis_symbols
        self.source_names = tuple(names)
        self.source_elements = tuple(elements)
        self._source_kinds = tuple(kinds)
        self._source_expressions = coefficients
        self._source_coef = _Coefficients(coefficients, self._param_symbols, self._axis_symbols)
        # code for the rows' structural non-zeros only (an elongation row touches one or two bodies), scattered
        where = [(j * self.n_dof + k) for j, row in enumerate(rows) for k, v in enumerate(row) if v != 0]
        # numbers evaluated to 17 digits first: an exact square root of a large integer (a tilted axis written with
        # decimals normalizes to one) is a Python int under numpy's sqrt, which fails beyond int64
        entries = [sp.N(sp.sympify(v), 17) for row in rows for v in row if v != 0]
        self._source_row_where = np.array(where, dtype=np.intp)
        self._source_rows = sp.lambdify(all_symbols, entries, modules="numpy", cse=True)
        axis_set = set(self._axis_symbols)
        self._source_rows_per_sample = any(not sp.sympify(v).free_symbols <= axis_set for v in entries)
        self._source_jac_entries = np.array(self._source_coef.entries, dtype=np.intp).reshape(-1, 2)

    def damping_sources(
        self, params: ParamsLike = None, position: Mapping[str, float] | None = None, *, jacobian: bool = True
    ) -> DampingSources:
        """The model's damping sources evaluated at a parameter vector or batch (see :class:`DampingSources`).

        ``jacobian=False`` leaves out the coefficients' derivatives (a (B, n_sources, n_params) array that the
        damping ratios alone do not need).

        Parameters
        ----------
        params : array (n_params,) or (B, n_params), mapping or None
            Parameter vector(s) in ``parameter_names`` order (SI), overrides by name, or None (nominal).
        position : mapping axis -> float, optional
            Axis position (m or rad).
        jacobian : bool
            Also the coefficients' derivatives by the parameters.

        Returns
        -------
        DampingSources

        Examples
        --------
        >>> from cappe.model import load_model
        >>> src = NumericModel(load_model("builtin:two-mass-rig")).damping_sources()
        >>> src.names, src.coefficients
        (('beam1.cx', 'spring12.cx', 'beam2.cx'), array([[13.42,  0.  ,  0.47]]))
        """
        p = self.vector(params)
        pb = p if p.ndim == 2 else p[None, :]
        pos = self.position_vector(position)
        n_b, n_s, n = pb.shape[0], len(self.source_names), self.n_dof
        try:
            coef = self._source_coef(pb, pos)
        except _NonFinite as exc:
            raise self._nonfinite_error(pb, pos, exc.values, self._source_columns(), exc.cause) from None
        jac = np.zeros((n_b, n_s, pb.shape[1])) if jacobian else None
        if jac is not None and self._source_jac_entries.size:
            source, parameter = self._source_jac_entries.T
            try:
                jac[:, source, parameter] = self._source_coef.jacobian(pb, pos)
            except _NonFinite as exc:
                derivatives = self._derivative_columns(self._source_coef.entries, self._source_columns())
                raise self._nonfinite_error(pb, pos, exc.values, derivatives, exc.cause) from None
        rows: Array
        if self._source_rows_per_sample:
            rows = np.empty((n_b, n_s, n))
            for b in range(n_b):
                rows[b] = self._source_row_matrix(pb[b], pos)
        else:
            cached = self._source_row_cache.get(pos)
            if cached is None:
                cached = self._source_row_matrix(pb[0], pos)
                cached.setflags(write=False)
                self._source_row_cache[pos] = cached
            rows = cached
        return DampingSources(self.source_names, self.source_elements, self._source_kinds, coef, rows, jac)

    def _source_row_matrix(self, p: Array, pos: tuple[float, ...]) -> Array:
        """The sources' elongation rows (n_sources, n_dof) at one parameter vector and position."""
        rows = np.zeros(len(self.source_names) * self.n_dof)
        if self._source_row_where.size:
            with np.errstate(all="ignore"):
                rows[self._source_row_where] = np.asarray(self._source_rows(*p, *_scalars(pos)), dtype=float)
            if not np.isfinite(rows).all():
                raise self._nonfinite_error(p[None, :], pos)
        out = rows.reshape(len(self.source_names), self.n_dof)
        n_fixed = self._source_fixed_rows.shape[0]
        if n_fixed:
            out[out.shape[0] - n_fixed:] = self._source_fixed_rows
        return out

    def _plan(self, terms: list[Term]) -> _MatrixPlan:
        axis_set = set(self._axis_symbols)
        grouped: dict[sp.Expr, sp.Matrix] = {}
        sources: dict[sp.Expr, tuple[str, ...]] = {}
        residual = None
        n = self.n_dof
        for term in terms:
            pattern = term.dense(n)
            if pattern.free_symbols <= axis_set:
                key = sp.sympify(term.coefficient)
                grouped[key] = grouped[key] + pattern if key in grouped else pattern
                sources[key] = (*sources.get(key, ()), term.source)
            else:
                part = term.coefficient * pattern
                residual = part if residual is None else residual + part
        return _MatrixPlan(list(grouped), list(grouped.values()), residual, [sources[key] for key in grouped])

    # -- argument handling ------------------------------------------------------------------------
    def vector(self, params: ParamsLike = None) -> Array:
        """Parameter vector(s): ``(n_params,)`` or ``(B, n_params)`` from overrides, a vector or a batch.

        Parameters
        ----------
        params : array (n_params,) or (B, n_params), mapping or None
            A vector or batch in ``parameter_names`` order (SI), overrides of the nominal values by name, or None
            (the nominal vector).

        Returns
        -------
        ndarray, shape (n_params,) or (B, n_params)

        Raises
        ------
        ModelError
            A name or the shape does not fit the model, or a value is not finite.
        """
        if params is None:
            return self.nominal.copy()
        if isinstance(params, Mapping):
            resolved = self.structure.resolve_parameters(params)
            return np.array([resolved[n] for n in self.parameter_names], dtype=float)
        arr = np.asarray(params, dtype=float)
        if arr.shape[-1:] != (len(self.parameter_names),) or arr.ndim > 2:
            msg = (
                f"parameter array must have shape (n_params,) or (B, n_params) with n_params = "
                f"{len(self.parameter_names)}; got {arr.shape}"
            )
            raise ModelError(msg)
        if not np.all(np.isfinite(arr)):
            msg = "parameter array contains NaN or Inf"
            raise ModelError(msg)
        return arr

    def position_vector(self, position: Mapping[str, float] | None = None) -> tuple[float, ...]:
        """The axis coordinates in ``axis_names`` order (axes not given take the model's defaults).

        Parameters
        ----------
        position : mapping axis -> float, optional
            Axis values (m or rad).

        Returns
        -------
        tuple of float

        Raises
        ------
        ModelError
            An axis is unknown or a value is not finite.
        """
        resolved = self.structure.resolve_position(position)
        return tuple(resolved[a] for a in self.axis_names)

    # -- NaN and inf: the slow path that names the model entry ------------------------------------
    def _evaluate_coefficients(self, pb: Array, pos: tuple[float, ...]) -> Array:
        try:
            return self._coefficients(pb, pos)
        except _NonFinite as exc:
            raise self._nonfinite_error(pb, pos, exc.values, self._coefficient_columns(), exc.cause) from None

    def _coefficient_columns(self) -> list[_Column]:
        return [(sources, expr, "") for sources, expr in
                zip(self._coefficient_sources, self._coefficient_expressions, strict=True)]

    def _source_columns(self) -> list[_Column]:
        return [((name,), expr, "") for name, expr in zip(self.source_names, self._source_expressions, strict=True)]

    def _derivative_columns(self, entries: Sequence[tuple[int, int]], columns: Sequence[_Column]) -> list[_Column]:
        """Columns of a coefficient Jacobian (its ``entries``: coefficient and parameter indices) for messages."""
        return [(columns[j][0], sp.diff(columns[j][1], self._param_symbols[i]),
                 f"the derivative with respect to {self.parameter_names[i]}") for j, i in entries]

    def _location(self, where: str) -> str:
        """``model.yaml, elements[0].stiffness.x``: the model file (where known) and the entry."""
        source = self.structure.source
        if not where:
            return source or f"model '{self.structure.name}'"
        return f"{source}, {where}" if source else where

    def _assignments(self, expr: sp.Expr, p: Array, pos: tuple[float, ...]) -> str:
        """`` at z = -0.2, k = 2e+06``: the axes and parameters ``expr`` uses, with their values ('' for none)."""
        used = sp.sympify(expr).free_symbols
        pairs = [(n, v) for n, sym, v in zip(self.axis_names, self._axis_symbols, pos, strict=True) if sym in used]
        pairs += [(n, v) for n, sym, v in zip(self.parameter_names, self._param_symbols, p, strict=True)
                  if sym in used]
        return " at " + ", ".join(f"{n} = {float(v):.6g}" for n, v in pairs) if pairs else ""

    def _term_entry(self, source: str) -> tuple[str, str]:
        """The model entry of a term (``Term.source``, e.g. ``"shoe.kx"``) and what its coefficient is."""
        name, _, tail = source.rpartition(".")
        s = self.structure
        flexible = [f.name for f in s.flexible_bodies]
        if name in flexible:
            here = f"flexible_bodies[{flexible.index(name)}]"
            return {"mass": (f"{here}.mass_scale", "the mass scale"),
                    "stiffness": (f"{here}.stiffness_scale", "the stiffness scale"),
                    "alpha": (f"{here}.damping.rayleigh[0]", "alpha times the mass scale"),
                    "beta": (f"{here}.damping.rayleigh[1]", "beta times the stiffness scale"),
                    "eta": (f"{here}.damping.loss", "the loss factor times the stiffness scale"),
                    }.get(tail.rstrip("0123456789"), (f"{here}.damping.modal", "the scale of its modal damping"))
        if tail == "mass" or tail == "spin" or tail.startswith("I"):
            here = f"bodies[{[b.name for b in s.bodies].index(name)}]"
            if tail == "spin":
                return f"{here}.spin", "polar inertia times spin speed"
            return (f"{here}.mass", "the mass") if tail == "mass" else (f"{here}.inertia.{tail[1:]}", "the inertia")
        here = f"elements[{[e.name for e in s.elements].index(name)}]"
        if tail.startswith("eta"):
            return f"{here}.loss.{tail[3:]}", "loss factor times stiffness"
        label = "stiffness" if tail.startswith("k") else "damping"
        return f"{here}.{label}.{tail[1:]}", f"the {label}"

    def _entries(self) -> tuple[list[tuple[str, str, sp.Expr]], Any]:
        """Every expression of the model, with its entry (``bodies[0].mass``) and a description where the entry
        alone does not say what it is, and generated code evaluating them all (made when an error needs it)."""
        if self._entry_values is None:
            s = self.structure
            found: list[tuple[str, str, sp.Expr]] = []

            def vector(where: str, values: Sequence[sp.Expr], label: str = "") -> None:
                for k, v in enumerate(values):
                    if label:  # an entry without its own key (an attachment point given by 'points' or 'at')
                        found.append((where, f"{label} ({'xyz'[k]})", v))
                    else:
                        found.append((f"{where}[{k}]", "", v))

            for i, b in enumerate(s.bodies):
                here = f"bodies[{i}]"
                found.append((f"{here}.mass", "", b.mass))
                for a, c in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)):
                    found.append((f"{here}.inertia.{'xyz'[a]}{'xyz'[c]}", "", b.inertia[a, c]))
                vector(f"{here}.position", b.position)
                vector(f"{here}.com", b.com)
                if b.spin is not None:
                    found.append((f"{here}.spin.speed", "", b.spin.speed))
                    found.append((f"{here}.spin.polar_inertia", "", b.spin.polar_inertia))
                    vector(f"{here}.spin.axis", b.spin.axis)
            for i, e in enumerate(s.elements):
                here = f"elements[{i}]"
                for label, table in (("stiffness", e.stiffness), ("damping", e.damping), ("loss", e.loss)):
                    found.extend((f"{here}.{label}.{d}", "", v) for d, v in table.items())
                vector(here, e.point_a, f"its attachment point on {e.body_a!r}")
                vector(here, e.point_b, f"its attachment point on {e.body_b!r}")
                found.extend((here, "its local axes", v) for v in e.axes)
            for i, inp in enumerate(s.inputs):
                vector(f"inputs[{i}].point", inp.point)
                vector(f"inputs[{i}].direction", inp.direction)
            for i, out in enumerate(s.outputs):
                if out.quantity != "elongation":
                    vector(f"outputs[{i}].point", out.point)
                    vector(f"outputs[{i}].direction", out.direction)
            for i, sensor in enumerate(s.sensors):
                vector(f"sensors[{i}].point", sensor.point)
            for i, flex in enumerate(s.flexible_bodies):
                here = f"flexible_bodies[{i}]"
                found.append((f"{here}.mass_scale", "", flex.mass_scale))
                found.append((f"{here}.stiffness_scale", "", flex.stiffness_scale))
                found.extend((f"{here}.damping.{label}", "", v) for label, v in (
                    ("rayleigh[0]", flex.damping.alpha), ("rayleigh[1]", flex.damping.beta),
                    ("loss", flex.damping.eta)))
                vector(f"{here}.position", flex.position)
            func = sp.lambdify(self._param_symbols + self._axis_symbols, [expr for *_, expr in found],
                               modules="numpy")
            self._entry_values = (found, func)
        return self._entry_values

    def _first_nonfinite_entry(self, p: Array, pos: tuple[float, ...]) -> str | None:
        """The first entry of the model (file order) that evaluates to NaN or inf, or cannot be evaluated (a
        function of it out of its range), as a message; None if none."""
        found, func = self._entries()
        arguments = [np.float64(v) for v in p] + _scalars(pos)
        try:
            with np.errstate(all="ignore"):
                values = list(func(*arguments))
        except (ValueError, ArithmeticError):  # find the entry: each on its own
            values = []
            symbols = self._param_symbols + self._axis_symbols
            for where, label, expr in found:
                try:
                    with np.errstate(all="ignore"):
                        values.append(sp.lambdify(symbols, expr, modules="numpy")(*arguments))
                except (ValueError, ArithmeticError) as exc:
                    what = f"{label} " if label else ""
                    return (f"{self._location(where)}: {what}cannot be evaluated{self._assignments(expr, p, pos)}: "
                            f"{exc}")
        for (where, label, expr), value in zip(found, values, strict=True):
            if not math.isfinite(_real(value)):
                what = f"{label} " if label else ""
                return f"{self._location(where)}: {what}evaluates to {_shown(value)}{self._assignments(expr, p, pos)}"
        return None

    def _nonfinite_error(
        self,
        pb: Array | None,
        pos: tuple[float, ...],
        values: Array | None = None,
        columns: Sequence[_Column] = (),
        cause: Exception | None = None,
    ) -> ModelError:
        """The error for a NaN or inf in the model's evaluation at a batch ``pb`` (None: nominal) and a position.

        Names the first entry of the model that evaluates to NaN or inf (or cannot be evaluated: ``cause``) at the
        first offending sample, or, where every entry is finite, the coefficient (a product such as loss factor
        times stiffness) that is not: ``values`` are the evaluated coefficients and ``columns`` say, per
        coefficient, its terms and expression.
        """
        rows = np.atleast_2d(self.nominal if pb is None else pb)
        if values is not None:
            bad = np.flatnonzero(~np.isfinite(values).all(axis=1))
            candidates = bad[:1] if bad.size else np.zeros(1, dtype=np.intp)
        else:  # the sample is not known: the first whose entries say
            candidates = np.arange(rows.shape[0])
        message, b = None, int(candidates[0])
        for k in candidates:
            message = self._first_nonfinite_entry(rows[k], pos)
            if message is not None:
                b = int(k)
                break
        p = rows[b]
        if message is None and values is not None and columns:
            j = int(np.flatnonzero(~np.isfinite(values[b]))[0])
            sources, expr, description = columns[j]
            where, what = self._term_entry(sources[0])
            what = f"{description} of {what}" if description else what
            message = (f"{self._location(where)}: {what} evaluates to {_shown(values[b, j])}"
                       f"{self._assignments(expr, p, pos)}")
        if message is None:
            at = ", ".join(f"{n} = {v:.6g}" for n, v in zip(self.axis_names, pos, strict=True))
            what = f"cannot be evaluated: {cause}" if cause is not None else "evaluates to NaN or inf"
            message = f"{self._location('')}: the model {what}{' at ' + at if at else ''}"
        return ModelError(message)

    def _matrix_error(self, name: str, mats: Array, pb: Array, pos: tuple[float, ...]) -> ModelError:
        """The error for a matrix with NaN or inf entries although its coefficients are finite: an entry of the
        model (a parameter-dependent point), or terms whose sum overflows."""
        b = int(np.flatnonzero(~np.isfinite(mats.reshape(mats.shape[0], -1)).all(axis=1))[0])
        p = pb[b]
        message = self._first_nonfinite_entry(p, pos)
        if message is not None:
            return ModelError(message)
        i, j = (int(v) for v in np.argwhere(~np.isfinite(mats[b]))[0])
        symbols = self._param_symbols + self._axis_symbols
        largest: tuple[float, Term] | None = None
        for term in self.symbolic.terms[name]:
            if (i, j) not in term.pattern:
                continue
            with np.errstate(all="ignore"):
                value = _real(sp.lambdify(symbols, term.coefficient * term.pattern[(i, j)], modules="numpy")(
                    *(np.float64(v) for v in p), *_scalars(pos)))
            if largest is None or not abs(value) <= abs(largest[0]):
                largest = (value, term)
        entry = f"{_MATRIX_WORDS[name]} matrix entry [{self.dofs[i]}, {self.dofs[j]}]"
        if largest is None:
            return ModelError(f"{self._location('')}: the {entry} evaluates to {_shown(mats[b, i, j])}")
        value, term = largest
        where, _ = self._term_entry(term.source)
        return ModelError(
            f"{self._location(where)}: adds {value:.6g} to the {entry}{self._assignments(term.coefficient, p, pos)}, "
            f"which sums to {_shown(mats[b, i, j])}: beyond double precision (about 1.8e308)"
        )

    def _patterns(self, pos: tuple[float, ...]) -> dict[str, Array]:
        """Dense patterns (n_terms, n*n) of every matrix at one axis position (cached)."""
        cached = self._pattern_cache.get(pos)
        if cached is None:
            n = self.n_dof
            cached = {}
            for name, (n_terms, where, func) in self._pattern_funcs.items():
                blocks = self._block_patterns[name]
                flat = np.zeros((n_terms + blocks.shape[0]) * n * n)
                if where.size:
                    with np.errstate(all="ignore"):
                        flat[where] = np.asarray(func(*_scalars(pos)), dtype=float)
                    if not np.isfinite(flat).all():  # the geometry is undefined at this position
                        raise self._nonfinite_error(None, pos)
                if blocks.shape[0]:
                    flat[n_terms * n * n:] = blocks.reshape(-1)
                cached[name] = flat.reshape(n_terms + blocks.shape[0], n * n)
            self._pattern_cache[pos] = cached
        return cached

    def _sparse_patterns(self, pos: tuple[float, ...]) -> dict[str, tuple[NDArray[np.intp], sps.csr_array]]:
        """Per matrix: flat indices of its structural non-zeros and the (n_nz, n_terms) map onto them.

        Assembling ``X[:, nz] = (P @ coef.T).T`` with a sparse ``P`` costs one multiply-add per stored
        pattern entry and sample (a dense (n_terms, n*n) product costs n_terms * n*n), and each sample's
        sum runs in the same fixed order whatever the batch size, so results do not depend on batching.
        """
        cached = self._sparse_cache.get(pos)
        if cached is None:
            cached = {}
            for name, dense in self._patterns(pos).items():
                nz = np.flatnonzero(np.any(dense != 0, axis=0))
                cached[name] = (nz, sps.csr_array(dense[:, nz].T))
            self._sparse_cache[pos] = cached
        return cached

    def blocks(self, name: str, position: Mapping[str, float] | None = None) -> list[NDArray[np.intp]]:
        """DOF index sets of the independent diagonal blocks of matrix ``name`` (connected components of its
        structural non-zeros); one block of all DOFs if the matrix has parameter-dependent patterns.

        The mass matrix of a rigid-body model is block-diagonal by body, so its Cholesky factor and inverse
        can be computed on the small blocks.

        Parameters
        ----------
        name : {"M", "C", "K", "G", "H"}
            The matrix.
        position : mapping axis -> float, optional
            Axis position (m or rad); the pattern may depend on it.

        Returns
        -------
        list of ndarray of int
            DOF indices of each block.

        Examples
        --------
        >>> from cappe.model import load_model
        >>> NumericModel(load_model("builtin:two-mass-rig")).blocks("M")
        [array([0]), array([1])]
        """
        n = self.n_dof
        if name in self._residual_funcs:
            return [np.arange(n)]
        nz = self._sparse_patterns(self.position_vector(position))[name][0]
        graph = sps.coo_array((np.ones(nz.size), (nz // n, nz % n)), shape=(n, n))
        count, labels = connected_components(graph, directed=False)
        return [np.flatnonzero(labels == k) for k in range(count)]

    def matrix_parameters(self, name: str) -> tuple[str, ...]:
        """The parameters matrix ``name`` depends on (in ``parameter_names`` order).

        Parameters
        ----------
        name : {"M", "C", "K", "G", "H"}
            The matrix.

        Returns
        -------
        tuple of str

        Raises
        ------
        ModelError
            ``name`` is not a matrix of the model.

        Examples
        --------
        >>> from cappe.model import load_model
        >>> NumericModel(load_model("builtin:two-mass-rig")).matrix_parameters("M")
        ('m1', 'm2')
        """
        if name not in self._slices:
            msg = f"matrix must be one of {MATRIX_NAMES}; got {name!r}"
            raise ModelError(msg)
        rows = self._slices[name]
        j, i = self._jacobian_entries.T
        used = set(i[(j >= rows.start) & (j < rows.stop)].tolist())
        plan = self._plans[name]
        if plan.residual is not None:
            used |= {i for i, sym in enumerate(self._param_symbols) if sym in plan.residual.free_symbols}
        return tuple(self.parameter_names[i] for i in sorted(used))

    def affine_terms(
        self, names: Sequence[str], params: ParamsLike = None, position: Mapping[str, float] | None = None
    ) -> dict[str, tuple[Array, Array]]:
        """The affine form ``X = sum_j f_j P_j`` of each matrix in ``names``: coefficients (B, n_terms) and
        patterns (n_terms, n, n, shared and read-only) at one axis position.

        Only for matrices without parameter-dependent patterns; the modal engine reduces a mass matrix shared by
        a batch with it.

        Parameters
        ----------
        names : sequence of str
            Matrices among ``"M"``, ``"C"``, ``"K"``, ``"G"``, ``"H"``.
        params : array (n_params,) or (B, n_params), mapping or None
            Parameter vector(s) (SI), overrides by name, or None (nominal).
        position : mapping axis -> float, optional
            Axis position (m or rad).

        Returns
        -------
        dict
            ``{name: (coefficients (B, n_terms), patterns (n_terms, n_dof, n_dof))}``.

        Raises
        ------
        ModelError
            A name is not a matrix, or its pattern depends on the parameters.

        Examples
        --------
        >>> from cappe.model import load_model
        >>> nm = NumericModel(load_model("builtin:two-mass-rig"))
        >>> coef, patterns = nm.affine_terms(["K"], nm.nominal[None, :])["K"]
        >>> bool(np.allclose(np.einsum("bt,tij->bij", coef, patterns)[0], nm.matrices()["K"]))
        True
        """
        for name in names:
            if name not in self._slices:
                msg = f"matrix must be one of {MATRIX_NAMES}; got {name!r}"
                raise ModelError(msg)
            if name in self._residual_funcs:
                msg = (f"matrix {name} of model '{self.structure.name}' has parameter-dependent patterns: it has "
                       "no affine form")
                raise ModelError(msg)
        p = self.vector(params)
        pb = p if p.ndim == 2 else p[None, :]
        pos = self.position_vector(position)
        n = self.n_dof
        coef = self._evaluate_coefficients(pb, pos)
        out: dict[str, tuple[Array, Array]] = {}
        for name in names:
            patterns = self._patterns(pos)[name].reshape(-1, n, n)
            patterns.setflags(write=False)
            out[name] = (coef[:, self._slices[name]], patterns)
        return out

    # -- evaluation -------------------------------------------------------------------------------
    def matrices(
        self,
        params: ParamsLike = None,
        position: Mapping[str, float] | None = None,
        names: Sequence[str] = MATRIX_NAMES,
    ) -> dict[str, Array]:
        """M, C, K, G, H at a parameter vector (n, n) or a batch (B, n, n), at one axis position.

        Parameters
        ----------
        params : array (n_params,) or (B, n_params), mapping or None
            Parameter vector(s) (SI), overrides by name, or None (nominal).
        position : mapping axis -> float, optional
            Axis position (m or rad).
        names : sequence of str
            The matrices wanted.

        Returns
        -------
        dict
            ``{name: ndarray (n_dof, n_dof) or (B, n_dof, n_dof)}``: mass (kg, kg m^2), viscous damping (N s/m),
            stiffness (N/m), gyroscopic (N s/m) and hysteretic (N/m) matrices.
        """
        p = self.vector(params)
        return self._assemble(p, self.position_vector(position), names)[1]

    def _assemble(self, p: Array, pos: tuple[float, ...], names: Sequence[str]) -> tuple[Array, dict[str, Array]]:
        """The coefficients (B, n_coef) and the matrices of :meth:`matrices`."""
        batch = p.ndim == 2
        pb = p if batch else p[None, :]
        n = self.n_dof
        coef = self._evaluate_coefficients(pb, pos)
        sparse = self._sparse_patterns(pos)
        safe = batch or self._safe(coef, pos)
        out: dict[str, Array] = {}
        for name in names:
            nz, pattern = sparse[name]
            flat = np.zeros((pb.shape[0], n * n))
            if nz.size:
                flat[:, nz] = (pattern @ np.ascontiguousarray(coef[:, self._slices[name]].T)).T
            mats = flat.reshape(pb.shape[0], n, n)
            func = self._residual_funcs.get(name)
            if func is not None:
                with np.errstate(all="ignore"):
                    for b in range(pb.shape[0]):
                        mats[b] += np.asarray(func(*pb[b], *_scalars(pos)), dtype=float)
            # finite coefficients can still sum past the largest double: checked for a single vector where its
            # largest coefficient could (a batch's sums would cost a pass over B n^2 values; its coefficients are
            # checked, and values near 1e308 that only overflow when added are not what a bounded design samples)
            if (func is not None or (not batch and not safe)) and not np.isfinite(mats).all():
                raise self._matrix_error(name, mats, pb, pos)
            out[name] = mats if batch else mats[0]
        return coef, out

    def _safe(self, coef: Array, pos: tuple[float, ...]) -> bool:
        """Whether no entry of the matrices assembled from one vector's coefficients can overflow: each entry is a
        sum of at most (the largest row sum of |pattern|) times the largest |coefficient|."""
        limit = self._safe_coefficient.get(pos)
        if limit is None:
            bound = max((float(abs(pattern).sum(axis=1).max()) for nz, pattern in self._sparse_patterns(pos).values()
                         if nz.size), default=0.0)
            limit = 1e300 / bound if bound > 0 else math.inf
            self._safe_coefficient[pos] = limit
        return not coef.size or float(np.abs(coef).max()) < limit

    def matrix_derivatives(
        self,
        params: ParamsLike = None,
        position: Mapping[str, float] | None = None,
        names: Sequence[str] = MATRIX_NAMES,
        *,
        parameters: Sequence[str] | None = None,
    ) -> dict[str, Array]:
        """Exact partial derivatives of each matrix with respect to every parameter: (n_params, n, n).

        With ``parameters``, only with respect to those, in that order: (len(parameters), n, n) (on models with
        many parameters most of the work when few are wanted).

        Parameters
        ----------
        params : array (n_params,), mapping or None
            One parameter vector (SI), overrides by name, or None (nominal).
        position : mapping axis -> float, optional
            Axis position (m or rad).
        names : sequence of str
            The matrices wanted.
        parameters : sequence of str, optional
            Parameters to differentiate by (default all).

        Returns
        -------
        dict
            ``{name: ndarray (n_parameters, n_dof, n_dof)}``, per SI unit of each parameter.

        Raises
        ------
        ModelError
            ``params`` is a batch, or a name is unknown.

        Examples
        --------
        >>> from cappe.model import load_model
        >>> nm = NumericModel(load_model("builtin:two-mass-rig"))
        >>> nm.matrix_derivatives()["K"][nm.parameter_names.index("k12")]
        array([[ 1., -1.],
               [-1.,  1.]])
        >>> nm.matrix_derivatives(names=("K",), parameters=["k12"])["K"][0]
        array([[ 1., -1.],
               [-1.,  1.]])
        """
        p, pos = self._single(params, position, "matrix_derivatives")
        n = self.n_dof
        jac, sel = self._coefficient_jacobian(p, pos, parameters)
        patterns = self._patterns(pos)
        out: dict[str, Array] = {}
        for name in names:
            # only the terms whose coefficient moves with a wanted parameter (a few per parameter): the same sum
            # without its zero products (the three-axis machine's patterns have hundreds of terms of 162^2 entries)
            part = jac[self._slices[name]]
            terms = np.flatnonzero(np.any(part != 0, axis=1))
            deriv = (part[terms].T @ patterns[name][terms]).reshape(sel.size, n, n)
            extra = self._residual_derivatives(name, p, pos, sel)
            out[name] = deriv if extra is None else deriv + extra
        return out

    def matrix_derivative_products(
        self,
        params: ParamsLike,
        position: Mapping[str, float] | None,
        vectors: NDArray[Any],
        names: Sequence[str] = MATRIX_NAMES,
        *,
        parameters: Sequence[str] | None = None,
    ) -> dict[str, NDArray[Any]]:
        """The derivative matrices of :meth:`matrix_derivatives` times ``vectors``, without forming them.

        Each derivative is a sum of the model's constant patterns weighted by coefficient derivatives; the patterns
        times ``vectors`` are one sparse product (per position, the patterns are kept sparse), so the cost does not
        grow with ``n_params * n_dof^2`` (the dense derivative stacks of a 162-DOF machine with 61 unknowns are 13 MB
        per matrix).

        Parameters
        ----------
        params : array (n_params,), mapping or None
            One parameter vector (SI), overrides by name, or None (nominal).
        position : mapping axis -> float, optional
            Axis position (m or rad).
        vectors : ndarray, shape (n_dof, m)
            Real or complex columns.
        names : sequence of str
            The matrices wanted.
        parameters : sequence of str, optional
            Parameters to differentiate by (default all).

        Returns
        -------
        dict
            ``{name: ndarray (n_parameters, n_dof, m)}``: ``dX / dp_i @ vectors``.

        Examples
        --------
        >>> from cappe.model import load_model
        >>> nm = NumericModel(load_model("builtin:two-mass-rig"))
        >>> nm.matrix_derivative_products(None, None, np.eye(2), ("K",), parameters=["k12"])["K"][0]
        array([[ 1., -1.],
               [-1.,  1.]])
        """
        p, pos = self._single(params, position, "matrix_derivative_products")
        n = self.n_dof
        cols = np.asarray(vectors)
        if cols.ndim != 2 or cols.shape[0] != n:
            msg = f"vectors must have shape (n_dof, m) = ({n}, m); got {cols.shape}"
            raise ModelError(msg)
        m = cols.shape[1]
        jac, sel = self._coefficient_jacobian(p, pos, parameters)
        out: dict[str, NDArray[Any]] = {}
        for name in names:
            part = jac[self._slices[name]]
            products = np.asarray(self._term_operators(pos)[name] @ cols).reshape(-1, n * m)  # (n_terms, n m)
            # each term moves with one or two parameters: the weighting is a sparse product too (its zero entries,
            # the terms that do not move, are dropped by the sparse matrix: no copy of the products they select)
            result = np.asarray(sps.csr_array(part.T) @ products).reshape(sel.size, n, m)
            extra = self._residual_derivatives(name, p, pos, sel)
            out[name] = result if extra is None else result + extra @ cols
        return out

    def _single(self, params: ParamsLike, position: Mapping[str, float] | None,
                who: str) -> tuple[Array, tuple[float, ...]]:
        """One parameter vector (a batch refused, naming the method ``who``) and the position's key."""
        p = self.vector(params)
        if p.ndim != 1:
            msg = f"{who} takes a single parameter vector"
            raise ModelError(msg)
        return p, self.position_vector(position)

    def _residual_derivatives(self, name: str, p: Array, pos: tuple[float, ...],
                              sel: NDArray[np.intp]) -> Array | None:
        """The derivatives of matrix ``name``'s residual part (the terms its patterns do not hold), (n_sel, n, n),
        or None where it has none."""
        func = self._residual_derivative_funcs.get(name)
        if func is None:
            return None
        with np.errstate(all="ignore"):
            mats = func(*p, *_scalars(pos))
            extra = np.stack([np.asarray(mats[column], dtype=float) for column in sel])
        if not np.isfinite(extra).all():
            raise self._nonfinite_error(p[None, :], pos)
        return extra

    def _term_operators(self, pos: tuple[float, ...]) -> dict[str, sps.csr_array]:
        """Per matrix: its patterns stacked as rows, (n_terms n, n) sparse, so that one product with (n, m) columns
        gives every pattern times them (cached per position)."""
        cached = self._term_cache.get(pos)
        if cached is None:
            n = self.n_dof
            cached = {name: sps.csr_array(dense.reshape(-1, n)) for name, dense in self._patterns(pos).items()}
            self._term_cache[pos] = cached
        return cached

    def _coefficient_jacobian(self, p: Array, pos: tuple[float, ...],
                              parameters: Sequence[str] | None) -> tuple[Array, NDArray[np.intp]]:
        """``d coefficient / d parameter`` (n_coef, n_selected) at one vector, and the selected parameter columns."""
        n_p = len(self.parameter_names)
        if parameters is None:
            sel = np.arange(n_p)
        else:
            unknown = [name for name in parameters if name not in self.parameter_names]
            if unknown:
                msg = f"unknown parameters {unknown} for model '{self.structure.name}'"
                raise ModelError(msg)
            sel = np.array([self.parameter_names.index(name) for name in parameters], dtype=np.intp)
        jac = np.zeros((self._n_coef, n_p))
        if self._jacobian_entries.size:
            coefficient, parameter = self._jacobian_entries.T
            try:
                jac[coefficient, parameter] = self._coefficients.jacobian(p[None, :], pos)[0]
            except _NonFinite as exc:
                columns = self._derivative_columns(self._coefficients.entries, self._coefficient_columns())
                raise self._nonfinite_error(p[None, :], pos, exc.values, columns, exc.cause) from None
        return jac[:, sel], sel

    def io_matrices(
        self, params: ParamsLike = None, position: Mapping[str, float] | None = None
    ) -> tuple[Array, Array]:
        """Input matrix (n_dof, n_inputs) and displacement-level output matrix (n_outputs, n_dof).

        Parameters
        ----------
        params : array (n_params,), mapping or None
            One parameter vector (SI), overrides by name, or None (nominal).
        position : mapping axis -> float, optional
            Axis position (m or rad).

        Returns
        -------
        B : ndarray, shape (n_dof, n_inputs)
            Generalized force per unit input.
        S : ndarray, shape (n_outputs, n_dof)
            Output rows (displacement level; each output's quantity says how to differentiate).

        Raises
        ------
        ModelError
            ``params`` is a batch.
        """
        p = self.vector(params)
        if p.ndim != 1:
            msg = "io_matrices takes a single parameter vector"
            raise ModelError(msg)
        pos = self.position_vector(position)
        with np.errstate(all="ignore"):
            b_mat, s_mat = self._io(*p, *_scalars(pos))
            b_arr = np.asarray(b_mat, dtype=float).reshape(self.n_dof, len(self.structure.inputs))
            s_arr = np.asarray(s_mat, dtype=float).reshape(len(self.structure.outputs), self.n_dof)
        if not (np.isfinite(b_arr).all() and np.isfinite(s_arr).all()):
            raise self._nonfinite_error(p[None, :], pos)
        return b_arr, s_arr

    def system(self, params: ParamsLike = None, position: Mapping[str, float] | None = None) -> Any:
        """The numeric second-order system (:class:`cappe.systems.MechanicalSystem`) at one parameter vector.

        Parameters
        ----------
        params : array (n_params,), mapping or None
            One parameter vector (SI), overrides by name, or None (nominal).
        position : mapping axis -> float, optional
            Axis position (m or rad).

        Returns
        -------
        MechanicalSystem
        """
        from cappe.systems.mechanical import MechanicalSystem

        p = self.vector(params)
        if p.ndim != 1:
            msg = "system() takes a single parameter vector; use matrices() for batches"
            raise ModelError(msg)
        pos = self.position_vector(position)
        coef, mats = self._assemble(p, pos, MATRIX_NAMES)
        if np.any(coef[0, self._nonnegative] < 0):
            self._raise_negative(coef[0], p, pos)
        b_mat, s_mat = self.io_matrices(p, position)
        resolved = dict(zip(self.parameter_names, p.tolist(), strict=True))
        return MechanicalSystem(
            M=mats["M"],
            C=mats["C"],
            K=mats["K"],
            G=mats["G"],
            H=mats["H"],
            B=b_mat,
            S=s_mat,
            dofs=self.dofs,
            input_names=self.input_names,
            output_names=self.output_names,
            output_quantities=self.output_quantities,
            name=self.structure.name,
            parameters=resolved,
            position=dict(zip(self.axis_names, pos, strict=True)),
            source=self.structure.source,
            dof_entries=self._dof_entries,
        )

    def _raise_negative(self, coef: Array, p: Array, pos: tuple[float, ...]) -> None:
        """Element stiffness, damping and loss must be >= 0 wherever they are evaluated (the model's rule, which
        loading checks at the nominal values and listed positions only): name the first negative one."""
        j = int(self._nonnegative[np.flatnonzero(coef[self._nonnegative] < 0)[0]])
        where, what = self._term_entry(self._coefficient_sources[j][0])
        assignments = self._assignments(self._coefficient_expressions[j], p, pos)
        msg = f"{self._location(where)}: {what} evaluates to {coef[j]:.6g}{assignments}; it must be >= 0"
        raise ModelError(msg)

    def sensor_matrix(
        self,
        params: ParamsLike = None,
        position: Mapping[str, float] | None = None,
        sensors: Sequence[str] | None = None,
    ) -> tuple[list[str], Array]:
        """Rows mapping q to x, y, z displacements of sensor nodes: labels ``node:dir`` and (3 n_s, n_dof).

        Parameters
        ----------
        params : array (n_params,), mapping or None
            One parameter vector (SI), overrides by name, or None (nominal); sensor points may depend on it.
        position : mapping axis -> float, optional
            Axis position (m or rad).
        sensors : sequence of str, optional
            Sensor names (default all).

        Returns
        -------
        labels : list of str
            ``"node:x"``, ``"node:y"``, ``"node:z"`` per sensor.
        rows : ndarray, shape (3 n_s, n_dof)
            Sensor displacement per generalized coordinate.
        """
        names = list(sensors) if sensors is not None else [s.name for s in self.structure.sensors]
        p = self.vector(params)
        pos = self.position_vector(position)
        symbols = self._param_symbols + self._axis_symbols
        for name in names:
            if name not in self._sensor_moves:
                self._sensor_moves[name] = any(set(self._param_symbols) & cast(sp.Expr, v).free_symbols
                                               for row in self.symbolic.sensor_rows(name) for v in row.values())
        # the rows are exact substitutions, so a repeat of the same sensors, position (and parameters, where a
        # sensor point moves with them) is served from a small cache
        key = (tuple(names), pos, p.tobytes() if any(self._sensor_moves[name] for name in names) else b"")
        cached = self._sensor_matrix_cache.get(key)
        if cached is None:
            subs = dict(zip(symbols, list(p) + list(pos), strict=True))
            labels: list[str] = []
            rows = np.zeros((3 * len(names), self.n_dof))
            for k, name in enumerate(names):
                for a, row in enumerate(self.symbolic.sensor_rows(name)):
                    labels.append(f"{name}:{'xyz'[a]}")
                    for j, v in row.items():
                        rows[3 * k + a, j] = _real(cast(sp.Expr, v).xreplace(subs))
            if not np.isfinite(rows).all():
                raise self._nonfinite_error(p[None, :] if p.ndim == 1 else p, pos)
            if len(self._sensor_matrix_cache) >= 64:
                self._sensor_matrix_cache.clear()
            cached = (tuple(labels), rows)
            self._sensor_matrix_cache[key] = cached
        return list(cached[0]), cached[1].copy()

    def with_nominal(self, values: ParamsLike) -> NumericModel:
        """The same model with other nominal (default) parameter values; this model is left as it is.

        The new model shares the compiled code and the caches that do not depend on parameter values, so it is
        made at once.

        Parameters
        ----------
        values : mapping, sequence or ndarray of shape (n_params,)
            The new nominal vector, or overrides of the model file's values by name.

        Returns
        -------
        NumericModel

        Examples
        --------
        >>> from cappe.model import load_model
        >>> nm = NumericModel(load_model("builtin:two-mass-rig"))
        >>> stiffer = nm.with_nominal({"k11": 2.0e6})
        >>> float(stiffer.matrices()["K"][0, 0]), float(nm.matrices()["K"][0, 0])
        (2120000.0, 1500000.0)
        """
        import copy

        p = np.array(self.vector(values), dtype=float)
        if p.ndim != 1:
            msg = f"with_nominal takes one parameter vector (n_params,); got shape {p.shape}"
            raise ModelError(msg)
        other = copy.copy(self)
        other.nominal = p
        return other
