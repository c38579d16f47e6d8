"""Parsing of the expressions that model files use for masses, stiffnesses, points and directions.

Expressions are sympy expressions in the model's parameter and axis names. Only those names, numbers
and a few elementary functions are allowed, so that a typo is an error instead of a new free symbol.
"""

from __future__ import annotations

import keyword
import re
from collections.abc import Iterable, Mapping
from functools import cache

import sympy as sp
from sympy.parsing.sympy_parser import (
    auto_number,
    factorial_notation,
    parse_expr,
    rationalize,
)

from cappe.exceptions import ModelError
from cappe.model.bearing import acb_axial, acb_radial

__all__ = ["FUNCTIONS", "NAME_PATTERN", "as_expression", "symbol"]

#: Names a model may use for parameters, axes, bodies and everything else that is named.
NAME_PATTERN = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")

#: Elementary functions and constants allowed in expressions.
FUNCTIONS: dict[str, object] = {
    "sin": sp.sin,
    "cos": sp.cos,
    "tan": sp.tan,
    "asin": sp.asin,
    "acos": sp.acos,
    "atan": sp.atan,
    "atan2": sp.atan2,
    "sqrt": sp.sqrt,
    "exp": sp.exp,
    "log": sp.log,
    "pi": sp.pi,
    "abs": sp.Abs,
    # stiffness of an angular-contact ball bearing relative to a reference preload (cappe.model.bearing)
    "acb_radial": acb_radial,
    "acb_axial": acb_axial,
}

# Decimal literals become exact rationals (0.135 -> 27/200) so that exact algebra sees exactly what the
# file says; floats would carry binary round-off into exact ranks and cancellations.
_TRANSFORMS = (auto_number, factorial_notation, rationalize)


@cache
def symbol(name: str) -> sp.Symbol:
    """The sympy symbol cappe uses for a parameter or axis name (real-valued)."""
    return sp.Symbol(name, real=True)


def as_expression(value: object, names: Iterable[str], where: str) -> sp.Expr:
    """Turn a number, string or sympy expression into an expression in the allowed ``names``.

    Parameters
    ----------
    value : float | int | str | sympy.Expr
        What the file or builder call gave.
    names : iterable of str
        Parameter and axis names the expression may use.
    where : str
        Location for error messages, e.g. ``"model.yaml, bodies[0].mass"``.

    Returns
    -------
    sympy.Expr
        The expression with numbers as exact rationals.

    Raises
    ------
    ModelError
        If the text does not parse, uses an unknown name, or is not a finite real value.

    Examples
    --------
    >>> as_expression("2*k + 0.5", ["k"], "demo")
    2*k + 1/2
    """
    allowed = set(names)
    if isinstance(value, bool):
        msg = f"expected a number or an expression; got the boolean {value!r} ({where})"
        raise ModelError(msg)
    if isinstance(value, sp.Basic):
        expr = sp.sympify(value)
    elif isinstance(value, (int, float)):
        if value != value or value in (float("inf"), float("-inf")):
            msg = f"expected a finite number; got {value!r} ({where})"
            raise ModelError(msg)
        expr = sp.nsimplify(value, rational=True) if isinstance(value, float) else sp.Integer(value)
    elif isinstance(value, str):
        expr = _parse(value, frozenset(allowed), where)
    else:
        msg = f"expected a number or an expression string; got {type(value).__name__} {value!r} ({where})"
        raise ModelError(msg)
    unknown = sorted(s.name for s in expr.free_symbols if s.name not in allowed)
    if unknown:
        msg = (
            f"expression {value!r} uses unknown name(s) {', '.join(unknown)}; "
            f"only parameters and axes may appear ({where})"
        )
        raise ModelError(msg)
    if expr.has(sp.I) or expr.has(sp.zoo, sp.oo, -sp.oo, sp.nan):
        msg = f"expression {value!r} is not a finite real value ({where})"
        raise ModelError(msg)
    return sp.sympify(expr)


def _parse(text: str, allowed: frozenset[str], where: str) -> sp.Expr:
    local: dict[str, object] = {name: symbol(name) for name in allowed}
    for name, func in FUNCTIONS.items():
        local.setdefault(name, func)
    for word in re.findall(r"[A-Za-z_][A-Za-z0-9_]*", text):
        if keyword.iskeyword(word) or (word not in local and word not in allowed):
            msg = (
                f"expression {text!r} uses unknown name {word!r}; only parameters, axes and "
                f"{', '.join(sorted(FUNCTIONS))} may appear ({where})"
            )
            raise ModelError(msg)
    try:
        expr = parse_expr(
            text,
            local_dict=local,
            global_dict={"Integer": sp.Integer, "Float": sp.Float, "Rational": sp.Rational, "Symbol": sp.Symbol},
            transformations=_TRANSFORMS,
            evaluate=True,
        )
    except (SyntaxError, TypeError, ValueError, AttributeError, NameError, ZeroDivisionError) as exc:
        msg = f"cannot parse expression {text!r}: {exc} ({where})"
        raise ModelError(msg) from exc
    if not isinstance(expr, sp.Expr):
        msg = f"expression {text!r} is not a scalar value ({where})"
        raise ModelError(msg)
    return expr


def substitute(expr: sp.Expr, values: Mapping[str, object]) -> sp.Expr:
    """Replace names by values (numbers or expressions)."""
    return expr.xreplace({symbol(k): sp.sympify(v) for k, v in values.items()})
