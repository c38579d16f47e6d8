"""Exact rational conversion and exact state-space realizations of a symbolic model."""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import sympy as sp
from sympy.polys.matrices import DomainMatrix

from cappe.exceptions import ModelError
from cappe.model._expressions import symbol
from cappe.model.symbolic import SymbolicModel
from cappe.systems.mechanical import DERIVATIVE_ORDER

__all__ = ["ExactStateSpace", "exact_state_space", "rational_values", "to_rational"]


def to_rational(value: object) -> sp.Rational:
    """The exact rational a decimal number denotes (1.39 -> 139/100, not the binary float).

    Parameters
    ----------
    value : float, int, str or sympy number
        The number (a float by its shortest decimal repr).

    Returns
    -------
    sympy.Rational

    Examples
    --------
    >>> to_rational(1.39)
    139/100
    """
    if isinstance(value, sp.Rational):
        return value
    if isinstance(value, float):
        return sp.Rational(repr(value))
    if isinstance(value, int):
        return sp.Integer(value)
    out = sp.nsimplify(sp.sympify(value), rational=True)
    if not isinstance(out, sp.Rational):
        msg = f"value {value!r} is not a rational number"
        raise ModelError(msg)
    return out


def rational_values(
    model: SymbolicModel, values: Mapping[str, float] | None, position: Mapping[str, float] | None
) -> dict[sp.Symbol, sp.Rational]:
    """Substitution map with every parameter and axis coordinate as an exact rational."""
    params = model.structure.resolve_parameters(values)
    pos = model.structure.resolve_position(position)
    return {symbol(k): to_rational(v) for k, v in {**params, **pos}.items()}


def warn_hysteretic(model: SymbolicModel) -> None:
    if any(model.terms["H"]):
        warnings.warn(
            f"model '{model.structure.name}' has hysteretic damping, which has no exact rational "
            "transfer-function form; it is left out of exact and symbolic transfer functions",
            UserWarning,
            stacklevel=3,
        )


@dataclass(frozen=True)
class ExactStateSpace:
    """Exact (rational or symbolic) realization with x = [q, q'].

    Attributes
    ----------
    A : sympy.Matrix, shape (2 n_dof, 2 n_dof)
        State matrix (1/s).
    B : sympy.Matrix, shape (2 n_dof, n_in)
        Input matrix.
    C : sympy.Matrix, shape (n_out, 2 n_dof)
        Output matrix.
    D : sympy.Matrix, shape (n_out, n_in)
        Feed-through matrix.
    input_names, output_names : tuple of str
        The model's inputs and outputs in the order of the columns of B and the rows of C.
    """

    A: sp.Matrix
    B: sp.Matrix
    C: sp.Matrix
    D: sp.Matrix
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]


def exact_state_space(
    model: SymbolicModel,
    values: Mapping[str, float] | None = None,
    position: Mapping[str, float] | None = None,
    inputs: Sequence[str] | None = None,
    outputs: Sequence[str] | None = None,
    *,
    symbolic: bool = False,
) -> ExactStateSpace:
    """Exact state-space matrices; with ``symbolic=True`` parameters stay symbols (small models only).

    Parameters
    ----------
    model : SymbolicModel
        The derived model.
    values : mapping name -> float, optional
        Parameter values (SI, read as exact decimals); default the model's.
    position : mapping axis -> float, optional
        Axis position (m or rad); default the model's.
    inputs, outputs : sequence of str, optional
        Model inputs and outputs (default all).
    symbolic : bool
        Keep the parameters as symbols instead of substituting ``values`` and ``position``.

    Returns
    -------
    ExactStateSpace
    """
    warn_hysteretic(model)
    ins = list(inputs) if inputs is not None else [i.name for i in model.structure.inputs]
    outs = list(outputs) if outputs is not None else [o.name for o in model.structure.outputs]
    subs = {} if symbolic else rational_values(model, values, position)
    m = model.M.xreplace(subs)
    c = (model.C + model.G).xreplace(subs)
    k = model.K.xreplace(subs)
    bq = model.input_matrix(ins).xreplace(subs)
    s_rows = model.output_matrix(outs).xreplace(subs)
    n = model.n_dof
    if symbolic:
        minv = m.inv()
    else:
        dm = DomainMatrix.from_Matrix(sp.Matrix(m)).convert_to(sp.QQ)
        if dm.rank() < n:
            msg = f"mass matrix of model '{model.structure.name}' is singular"
            raise ModelError(msg)
        minv = dm.inv().to_Matrix()
    a = sp.zeros(2 * n, 2 * n)
    a[:n, n:] = sp.eye(n)
    a[n:, :n] = -(minv * k)
    a[n:, n:] = -(minv * c)
    b = sp.zeros(2 * n, len(ins))
    b[n:, :] = minv * bq
    cc = sp.zeros(len(outs), 2 * n)
    dd = sp.zeros(len(outs), len(ins))
    for r, name in enumerate(outs):
        order = DERIVATIVE_ORDER[model.structure.output(name).quantity]
        row = s_rows[r, :]
        if order == 0:
            cc[r, :n] = row
        elif order == 1:
            cc[r, n:] = row
        else:
            cc[r, :] = row * a[n:, :]
            dd[r, :] = row * b[n:, :]
    if symbolic:
        a, b, cc, dd = (x.applyfunc(sp.cancel) for x in (a, b, cc, dd))
    return ExactStateSpace(a, b, cc, dd, tuple(ins), tuple(outs))
