"""Parsing of the expressions that model files use for masses, stiffnesses, points and directions.

Expressions are sympy expressions in the model's parameter and axis names. Only those names, numbers, the
operators + - * / ** and a few elementary functions are allowed, so that a typo is an error instead of a new
free symbol.

Model files are shared, downloaded and attached to issues, so their text is untrusted: it is never evaluated.
:func:`ast.parse` builds a syntax tree (it runs nothing), and the sympy expression is assembled node by node
from a whitelist. Non-ASCII characters are refused before parsing (Python folds full-width and mathematical
letters into ASCII names, e.g. a full-width ``eval``), and the work an expression can cause is bounded: its
length, its nesting, the size of exact powers and of exponents of expressions.
"""

from __future__ import annotations

import ast
import math
import re
from collections.abc import Callable, Iterable, Mapping
from functools import cache
from typing import NoReturn

import sympy as sp

from cappe.exceptions import ModelError
from cappe.model.bearing import acb_axial, acb_radial

__all__ = [
    "CONSTANTS",
    "FUNCTIONS",
    "MAX_EXPONENT",
    "MAX_EXPRESSION_DEPTH",
    "MAX_EXPRESSION_LENGTH",
    "MAX_POWER_DIGITS",
    "NAME_PATTERN",
    "as_expression",
    "shown",
    "symbol",
]

#: Names a model may use for parameters, axes, bodies and everything else that is named.
NAME_PATTERN = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")

#: Elementary functions allowed in expressions.
FUNCTIONS: dict[str, Callable[..., object]] = {
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
    "abs": sp.Abs,
    # stiffness of an angular-contact ball bearing relative to a reference preload (cappe.model.bearing)
    "acb_radial": acb_radial,
    "acb_axial": acb_axial,
}
#: Numbers of each function's arguments (log(x) or log(x, base)).
_ARITY: dict[str, tuple[int, ...]] = {
    **{name: (1,) for name in FUNCTIONS},
    "atan2": (2,),
    "log": (1, 2),
    "acb_radial": (6,),
    "acb_axial": (6,),
}
#: Named constants allowed in expressions.
CONSTANTS: dict[str, sp.Expr] = {"pi": sp.pi}

#: Longest expression text accepted (the built-in models' longest is well under 200 characters).
MAX_EXPRESSION_LENGTH = 2000
#: Deepest nesting of parentheses, calls and powers accepted (a sum of many terms counts as one level).
MAX_EXPRESSION_DEPTH = 50
#: Most decimal digits an exact power of numbers may have (a float carries at most 309).
MAX_POWER_DIGITS = 400
#: Largest numeric exponent of an expression that is not a number (k**4 is common, k**100 is not physics).
MAX_EXPONENT = 64

_FLOAT_MAX = sp.Float(1.7976931348623157e308)
# + - and * / chains are flattened into one sympy Add or Mul
_CHAIN_OPERATORS = (ast.Add, ast.Sub, ast.Mult, ast.Div)
_OPERATOR_HINTS: dict[type[ast.operator], str] = {
    ast.BitXor: " (write powers as **, not ^)",
    ast.FloorDiv: " (// is integer division; write /)",
    ast.Mod: " (% is not allowed)",
    ast.MatMult: " (@ is not allowed)",
}


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
        if isinstance(value, int) and abs(value) > _FLOAT_MAX:
            msg = "expected a number within the floating-point range (below 1.8e308); got a larger integer"
            msg += f" ({where})"
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
            f"expression {shown(value)!r} uses unknown name(s) {', '.join(unknown)}; "
            f"only parameters and axes may appear ({where})"
        )
        raise ModelError(msg)
    if expr.has(sp.I) or expr.has(sp.zoo, sp.oo, -sp.oo, sp.nan):
        msg = f"expression {shown(value)!r} is not a finite real value ({where})"
        raise ModelError(msg)
    return sp.sympify(expr)


def _parse(text: str, allowed: frozenset[str], where: str) -> sp.Expr:
    """Build the sympy expression of ``text`` from its syntax tree, node by node from a whitelist.

    Nothing of the text is ever evaluated as Python: :func:`ast.parse` only builds the tree, and only numbers,
    the allowed names, + - * / **, unary signs and calls of :data:`FUNCTIONS` become sympy objects.
    """
    if len(text) > MAX_EXPRESSION_LENGTH:
        _reject(text, f"is {len(text)} characters long; at most {MAX_EXPRESSION_LENGTH} are allowed", where)
    for position, char in enumerate(text):
        if not (char.isascii() and (char.isprintable() or char in " \t\n\r")):
            _reject(
                text,
                f"contains the character {char!r} (U+{ord(char):04X}) at position {position}; "
                "only ASCII names, numbers, + - * / ** and parentheses may appear",
                where,
            )
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except (SyntaxError, ValueError, RecursionError, MemoryError) as exc:
        reason = getattr(exc, "msg", None) or str(exc) or type(exc).__name__
        _reject(text, f"does not parse: {reason}", where)
    return _Builder(text.strip(), allowed, where).build(tree.body, 0)


class _Builder:
    """Turns whitelisted syntax-tree nodes into sympy objects; everything else is a ModelError."""

    def __init__(self, text: str, allowed: frozenset[str], where: str) -> None:
        self.text = text
        self.allowed = allowed
        self.where = where

    def fail(self, node: ast.AST, reason: str) -> NoReturn:
        token = ast.get_source_segment(self.text, node) or type(node).__name__
        if len(token) > 40:
            token = token[:37] + "..."
        _reject(self.text, f"{reason}: {token!r}", self.where)

    def build(self, node: ast.AST, depth: int) -> sp.Expr:
        if depth > MAX_EXPRESSION_DEPTH:
            self.fail(node, f"nests deeper than {MAX_EXPRESSION_DEPTH} levels")
        if isinstance(node, ast.Constant):
            return self.number(node)
        if isinstance(node, ast.Name):
            return self.name(node)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.UAdd, ast.USub)):
            operand = self.build(node.operand, depth + 1)
            return -operand if isinstance(node.op, ast.USub) else operand
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow):
            return self.power(node, self.build(node.left, depth + 1), self.build(node.right, depth + 1))
        if isinstance(node, ast.BinOp) and isinstance(node.op, _CHAIN_OPERATORS):
            return self.chain(node, depth)
        if isinstance(node, ast.Call):
            return self.call(node, depth)
        if isinstance(node, ast.BinOp):
            symbol_text = _OPERATOR_HINTS.get(type(node.op), "")
            self.fail(node, f"uses an operator that is not allowed{symbol_text}")
        self.fail(node, "uses a construct that is not allowed (only numbers, names, + - * / ** and function calls)")

    def chain(self, node: ast.BinOp, depth: int) -> sp.Expr:
        """A left-leaning run of + - (or * /) as one sympy Add (Mul), walked without recursion, so that a long
        sum does not exhaust the stack."""
        additive = isinstance(node.op, (ast.Add, ast.Sub))
        family = (ast.Add, ast.Sub) if additive else (ast.Mult, ast.Div)
        terms: list[tuple[ast.operator, ast.AST]] = []
        current: ast.AST = node
        while isinstance(current, ast.BinOp) and isinstance(current.op, family):
            terms.append((current.op, current.right))
            current = current.left
        parts = [self.build(current, depth + 1)]
        for op, right in reversed(terms):
            value = self.build(right, depth + 1)
            if isinstance(op, ast.Sub):
                value = -value
            elif isinstance(op, ast.Div):
                value = sp.Integer(1) / value
            parts.append(value)
        result = sp.Add(*parts) if additive else sp.Mul(*parts)
        return self.bounded(node, result)

    def number(self, node: ast.Constant) -> sp.Expr:
        value = node.value
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(node, "uses a literal that is not a real number")
        if isinstance(value, float):
            if not math.isfinite(value):
                self.fail(node, "uses a number outside the floating-point range")
            # the literal's text as an exact rational (0.135 -> 27/200), not the binary float
            literal = (ast.get_source_segment(self.text, node) or repr(value)).replace("_", "")
            return sp.Rational(literal)
        if abs(value) > _FLOAT_MAX:
            self.fail(node, "uses a number outside the floating-point range")
        return sp.Integer(value)

    def name(self, node: ast.Name) -> sp.Expr:
        if node.id in self.allowed:
            return symbol(node.id)
        if node.id in CONSTANTS:
            return CONSTANTS[node.id]
        hint = " (a function: call it with arguments)" if node.id in FUNCTIONS else ""
        allowed = ", ".join(sorted(self.allowed)) or "none"
        _reject(
            self.text,
            f"uses unknown name {node.id!r}{hint}; only the parameters and axes ({allowed}), the constants "
            f"{', '.join(sorted(CONSTANTS))} and the functions {', '.join(sorted(FUNCTIONS))} may appear",
            self.where,
        )

    def call(self, node: ast.Call, depth: int) -> sp.Expr:
        if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
            self.fail(node.func, f"calls something that is not one of the functions {', '.join(sorted(FUNCTIONS))}")
        name = node.func.id
        if node.keywords:
            self.fail(node, f"passes keyword arguments to {name}, which takes positional arguments only")
        arities = _ARITY[name]
        if len(node.args) not in arities:
            expected = " or ".join(str(a) for a in arities)
            self.fail(node, f"calls {name} with {len(node.args)} argument(s); it takes {expected}")
        args = [self.build(arg, depth + 1) for arg in node.args]
        try:
            result = FUNCTIONS[name](*args)
        except (TypeError, ValueError, ArithmeticError) as exc:
            self.fail(node, f"cannot be evaluated ({exc})")
        return self.bounded(node, sp.sympify(result))

    def power(self, node: ast.BinOp, base: sp.Expr, exponent: sp.Expr) -> sp.Expr:
        """``base**exponent`` where its exact value stays small: an exact power of numbers may have at most
        :data:`MAX_POWER_DIGITS` digits (9**9**9 would have 369 million), and a numeric exponent of an
        expression at most :data:`MAX_EXPONENT` in size ((k + 1)**10**6 would expand into a million terms)."""
        if exponent.is_Number:
            size = abs(float(exponent))
            if base.is_Number:
                magnitude = abs(float(base)) if base.is_finite else math.inf
                if magnitude not in (0.0, 1.0) and size * abs(math.log10(magnitude)) > MAX_POWER_DIGITS:
                    self.fail(node, f"is a power with more than {MAX_POWER_DIGITS} digits")
            elif size > MAX_EXPONENT:
                self.fail(node, f"raises an expression to a power larger than {MAX_EXPONENT}")
        return self.bounded(node, base**exponent)

    def bounded(self, node: ast.AST, value: sp.Expr) -> sp.Expr:
        """``value`` unless it is a number beyond the floating-point range (a product of large literals)."""
        if value.is_Number and value.is_finite and abs(value) > _FLOAT_MAX:
            self.fail(node, "evaluates to a number outside the floating-point range")
        return value


def _reject(text: str, reason: str, where: str) -> NoReturn:
    msg = f"expression {shown(text)!r} {reason} ({where})"
    raise ModelError(msg)


def shown(value: object, limit: int = 80) -> str:
    """``value`` as text for a message, cut to ``limit`` characters."""
    text = value if isinstance(value, str) else str(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def substitute(expr: sp.Expr, values: Mapping[str, object]) -> sp.Expr:
    """Replace names by values (numbers or expressions)."""
    return expr.xreplace({symbol(k): sp.sympify(v) for k, v in values.items()})
