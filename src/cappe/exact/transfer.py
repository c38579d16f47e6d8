"""Exact transfer functions from the second-order equations, with exact pole-zero cancellation.

``G(s) = s^k * c^T adj(Z(s)) b / det Z(s)`` with ``Z(s) = M s^2 + (C + G) s + K``; the numerator is the
bordered determinant ``-det([[Z, b], [c^T, 0]])``. Both are computed with fraction-free elimination in a
polynomial ring, over the rationals (exact numbers) or over the parameters (symbolic coefficients).
Common factors of numerator and denominator are removed exactly (gcd) and reported.
"""

from __future__ import annotations

from collections.abc import Mapping

import sympy as sp
from sympy.polys.matrices import DomainMatrix

from cappe.exact.rational import rational_values, to_rational, warn_hysteretic
from cappe.model._expressions import symbol
from cappe.model.symbolic import SymbolicModel
from cappe.systems.mechanical import DERIVATIVE_ORDER
from cappe.systems.transfer import TransferFunctionModel

__all__ = ["S", "exact_transfer_function", "symbolic_transfer_function"]

S = sp.Symbol("s")


def _polynomials(
    model: SymbolicModel,
    input: str,
    output: str,  # noqa: A002
    subs: Mapping[sp.Symbol, sp.Expr],
) -> tuple[sp.Poly, sp.Poly]:
    warn_hysteretic(model)
    n = model.n_dof
    z = (model.M * S**2 + (model.C + model.G) * S + model.K).xreplace(subs)
    col = model.input_matrix([input]).xreplace(subs)
    quantity, _ = model.output_row(output)
    row = model.output_matrix([output]).xreplace(subs)
    bordered = sp.zeros(n + 1, n + 1)
    bordered[:n, :n] = z
    bordered[:n, n] = col
    bordered[n, :n] = row
    gens = [S, *sorted((z.free_symbols | row.free_symbols | col.free_symbols) - {S}, key=lambda x: x.name)]
    den = _det(z, gens)
    num = -_det(bordered, gens)
    num = num * sp.Poly(S ** DERIVATIVE_ORDER[quantity], *gens)
    return num, den


def _det(matrix: sp.Matrix, gens: list[sp.Symbol]) -> sp.Poly:
    dm = DomainMatrix.from_Matrix(matrix)
    ring = sp.QQ[tuple(gens)] if len(gens) > 1 else sp.QQ[gens[0]]
    value = dm.convert_to(ring).det()
    return sp.Poly(ring.to_sympy(value), *gens, domain=sp.QQ)


def _finish(num: sp.Poly, den: sp.Poly, input: str, output: str, kind: str) -> TransferFunctionModel:  # noqa: A002
    cancelled: list[str] = []
    g = sp.gcd(num, den)
    if not num.is_zero and sp.Poly(g.as_expr(), S).degree() > 0:
        num = sp.div(num, g)[0]
        den = sp.div(den, g)[0]
        for factor, mult in sp.factor_list(g.as_expr())[1]:
            if factor.has(S):
                cancelled.extend([str(factor)] * mult)
    num_s = sp.Poly(num.as_expr(), S)
    den_s = sp.Poly(den.as_expr(), S)
    lead = den_s.LC()
    simplify = sp.cancel if kind == "symbolic" else sp.nsimplify
    num_c = tuple(simplify(c / lead) for c in num_s.all_coeffs()) if not num_s.is_zero else (sp.Integer(0),)
    den_c = tuple(simplify(c / lead) for c in den_s.all_coeffs())
    return TransferFunctionModel(num_c, den_c, input, output, kind, tuple(cancelled))


def exact_transfer_function(
    model: SymbolicModel,
    input: str,
    output: str,  # noqa: A002
    values: Mapping[str, float] | None = None,
    position: Mapping[str, float] | None = None,
) -> TransferFunctionModel:
    """Transfer function with exact rational coefficients (parameters read as exact decimals).

    Parameters
    ----------
    model : SymbolicModel
        The derived model.
    input, output : str
        Model input and output names.
    values : mapping name -> float, optional
        Parameter values (SI); default the model's.
    position : mapping axis -> float, optional
        Axis position (m or rad); default the model's.

    Returns
    -------
    TransferFunctionModel
        Coefficients as sympy rationals, s in rad/s.

    Examples
    --------
    >>> from cappe.model import load_model, derive
    >>> tf = exact_transfer_function(derive(load_model("builtin:two-mass-rig")), "F1", "d2")
    >>> tf.numerator
    (1200000000/15151,)
    """
    num, den = _polynomials(model, input, output, rational_values(model, values, position))
    return _finish(num, den, input, output, "exact")


def symbolic_transfer_function(
    model: SymbolicModel,
    input: str,
    output: str,  # noqa: A002
    values: Mapping[str, float] | None = None,
    position: Mapping[str, float] | None = None,
) -> TransferFunctionModel:
    """Transfer function with coefficients as expressions in the parameters (monic denominator).

    ``values`` may fix some parameters (exact rationals); ``position`` fixes axis coordinates (default: the
    symbols stay). Intended for small models: the cost grows quickly with the number of DOFs.

    Parameters
    ----------
    model : SymbolicModel
        The derived model.
    input, output : str
        Model input and output names.
    values : mapping name -> float, optional
        Parameters to fix (SI); the others stay symbols.
    position : mapping axis -> float, optional
        Axis coordinates to fix (m or rad).

    Returns
    -------
    TransferFunctionModel
        Coefficients as sympy expressions, s in rad/s.
    """
    subs = {symbol(k): to_rational(v) for k, v in (values or {}).items()}
    subs.update({symbol(k): to_rational(v) for k, v in (position or {}).items()})
    num, den = _polynomials(model, input, output, subs)
    return _finish(num, den, input, output, "symbolic")
