"""Compiled numeric model: fast evaluation of M, C, K, G, H for one or many parameter vectors.

Each matrix is ``X(p, r) = sum_j f_j(p, r) * P_j(r)`` (see :mod:`cappe.model.symbolic`). The patterns
``P_j`` are evaluated once per axis position and cached; a batch of parameter vectors then costs one
vectorized evaluation of the coefficients and one matrix product (B, n_terms) @ (n_terms, n*n).
Terms whose pattern itself depends on parameters (for instance an attachment point given by a length
parameter) are evaluated per sample instead; ``is_affine`` tells whether any exist.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
import sympy as sp
from numpy.typing import NDArray

from cappe.exceptions import ModelError
from cappe.model.structure import Structure
from cappe.model.symbolic import MATRIX_NAMES, SymbolicModel, Term

__all__ = ["NumericModel", "compile_model"]

Array = NDArray[np.float64]
ParamsLike = Mapping[str, float] | Sequence[float] | NDArray[np.floating[Any]] | None


@dataclass
class _MatrixPlan:
    affine_coefficients: list[sp.Expr]
    affine_patterns: list[sp.Matrix]
    residual: sp.Matrix | None


def compile_model(model: Structure | SymbolicModel) -> NumericModel:
    """Compile a Structure (or its SymbolicModel) into a NumericModel."""
    return NumericModel(model)


class NumericModel:
    """Numeric evaluation of a structure's matrices, inputs and outputs.

    Parameter vectors follow ``parameter_names`` (all model parameters, in file order); a mapping of
    overrides by name is accepted wherever a vector is.

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
        for name in MATRIX_NAMES:
            start = len(coefficients)
            coefficients.extend(self._plans[name].affine_coefficients)
            self._slices[name] = slice(start, len(coefficients))
        all_symbols = self._param_symbols + self._axis_symbols
        self._n_coef = len(coefficients)
        self._coefficients = sp.lambdify(all_symbols, coefficients, modules="numpy", cse=True)
        self._pattern_funcs = {
            name: sp.lambdify(self._axis_symbols, plan.affine_patterns, modules="numpy", cse=True)
            for name, plan in self._plans.items()
        }
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

    def _plan(self, terms: list[Term]) -> _MatrixPlan:
        axis_set = set(self._axis_symbols)
        grouped: dict[sp.Expr, sp.Matrix] = {}
        residual = None
        n = self.n_dof
        for term in terms:
            pattern = term.dense(n)
            if pattern.free_symbols <= axis_set:
                key = sp.sympify(term.coefficient)
                grouped[key] = grouped[key] + pattern if key in grouped else pattern
            else:
                part = term.coefficient * pattern
                residual = part if residual is None else residual + part
        return _MatrixPlan(list(grouped), list(grouped.values()), residual)

    # -- argument handling ------------------------------------------------------------------------
    def vector(self, params: ParamsLike = None) -> Array:
        """Parameter vector(s): ``(n_params,)`` or ``(B, n_params)`` from overrides, a vector or a batch."""
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
        resolved = self.structure.resolve_position(position)
        return tuple(resolved[a] for a in self.axis_names)

    def _patterns(self, pos: tuple[float, ...]) -> dict[str, Array]:
        cached = self._pattern_cache.get(pos)
        if cached is None:
            n = self.n_dof
            cached = {}
            for name, func in self._pattern_funcs.items():
                mats = func(*pos)
                cached[name] = (
                    np.array([np.broadcast_to(np.asarray(m, dtype=float), (n, n)) for m in mats]).reshape(
                        len(mats), n * n
                    )
                    if mats
                    else np.zeros((0, n * n))
                )
            self._pattern_cache[pos] = cached
        return cached

    # -- evaluation -------------------------------------------------------------------------------
    def matrices(
        self,
        params: ParamsLike = None,
        position: Mapping[str, float] | None = None,
        names: Sequence[str] = MATRIX_NAMES,
    ) -> dict[str, Array]:
        """M, C, K, G, H at a parameter vector (n, n) or a batch (B, n, n), at one axis position."""
        p = self.vector(params)
        batch = p.ndim == 2
        pb = p if batch else p[None, :]
        pos = self.position_vector(position)
        n = self.n_dof
        args = [pb[:, i] for i in range(pb.shape[1])] + [np.full(pb.shape[0], v) for v in pos]
        coef = np.empty((pb.shape[0], self._n_coef))
        if self._n_coef:
            values = self._coefficients(*args)
            for j, v in enumerate(values):
                coef[:, j] = v
        patterns = self._patterns(pos)
        out: dict[str, Array] = {}
        for name in names:
            mats = (coef[:, self._slices[name]] @ patterns[name]).reshape(pb.shape[0], n, n)
            func = self._residual_funcs.get(name)
            if func is not None:
                for b in range(pb.shape[0]):
                    mats[b] += np.asarray(func(*pb[b], *pos), dtype=float)
            out[name] = mats if batch else mats[0]
        return out

    def io_matrices(
        self, params: ParamsLike = None, position: Mapping[str, float] | None = None
    ) -> tuple[Array, Array]:
        """Input matrix (n_dof, n_inputs) and displacement-level output matrix (n_outputs, n_dof)."""
        p = self.vector(params)
        if p.ndim != 1:
            msg = "io_matrices takes a single parameter vector"
            raise ModelError(msg)
        pos = self.position_vector(position)
        b_mat, s_mat = self._io(*p, *pos)
        b_arr = np.asarray(b_mat, dtype=float).reshape(self.n_dof, len(self.structure.inputs))
        s_arr = np.asarray(s_mat, dtype=float).reshape(len(self.structure.outputs), self.n_dof)
        return b_arr, s_arr

    def system(self, params: ParamsLike = None, position: Mapping[str, float] | None = None) -> Any:
        """The numeric second-order system (:class:`cappe.systems.MechanicalSystem`) at one parameter vector."""
        from cappe.systems.mechanical import MechanicalSystem

        p = self.vector(params)
        if p.ndim != 1:
            msg = "system() takes a single parameter vector; use matrices() for batches"
            raise ModelError(msg)
        mats = self.matrices(p, position)
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
            position=dict(zip(self.axis_names, self.position_vector(position), strict=True)),
        )

    def sensor_matrix(
        self,
        params: ParamsLike = None,
        position: Mapping[str, float] | None = None,
        sensors: Sequence[str] | None = None,
    ) -> tuple[list[str], Array]:
        """Rows mapping q to x, y, z displacements of sensor nodes: labels ``node:dir`` and (3 n_s, n_dof)."""
        names = list(sensors) if sensors is not None else [s.name for s in self.structure.sensors]
        p = self.vector(params)
        pos = self.position_vector(position)
        subs = dict(zip(self._param_symbols + self._axis_symbols, list(p) + list(pos), strict=True))
        labels: list[str] = []
        rows = np.zeros((3 * len(names), self.n_dof))
        for k, name in enumerate(names):
            for a, row in enumerate(self.symbolic.sensor_rows(name)):
                labels.append(f"{name}:{'xyz'[a]}")
                for j, v in row.items():
                    rows[3 * k + a, j] = float(cast(sp.Expr, v).xreplace(subs))
        return labels, rows
