"""Model text is untrusted: expressions are built from a syntax-tree whitelist, never evaluated as Python.

The canary is an audit hook (PEP 578): evaluating text as Python raises the interpreter's ``exec`` audit event,
and touching files raises ``open`` / ``os.remove``. ``ast.parse`` only raises ``compile`` (it builds a tree).
Before the whitelist builder, every expression went through sympy's ``parse_expr`` (``eval``), and a
full-width ``ｅｖａｌ`` with its code in octal escapes ran that code on ``cappe model show``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import pytest
import sympy as sp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cappe.cli import main
from cappe.exceptions import ModelError
from cappe.model import load_model
from cappe.model._expressions import MAX_EXPRESSION_LENGTH, as_expression

_WATCHED = {"exec", "open", "os.remove", "os.unlink", "os.system", "subprocess.Popen", "os.rename"}
_EVENTS: list[tuple[str, str]] = []
_ACTIVE = [False]


def _audit(event: str, args: tuple[object, ...]) -> None:
    if _ACTIVE[0] and event in _WATCHED:
        _EVENTS.append((event, repr(args)[:120]))


sys.addaudithook(_audit)  # audit hooks cannot be removed; this one records only while _ACTIVE


def _parse_watched(text: object, names: list[str]) -> object:
    """as_expression(text) with the canary armed; returns the expression or the ModelError."""
    _EVENTS.clear()
    _ACTIVE[0] = True
    try:
        return as_expression(text, names, "model.yaml, bodies[0].mass")
    except ModelError as exc:
        return exc
    finally:
        _ACTIVE[0] = False


# warm up sympy's lazy imports (importing a module raises the exec event too)
as_expression("sin(k)*cos(k)/tan(k)+exp(k)*log(k, 2)+sqrt(k)+abs(k)+atan2(k, 1)+acb_radial(k, k, 1, 1, 1, 1)", ["k"], "")


def _octal(code: str) -> str:
    return "".join(f"\\{ord(c):03o}" for c in code)


def _fullwidth(word: str) -> str:
    return "".join(chr(ord(c) - 0x21 + 0xFF01) if "!" <= c <= "~" else c for c in word)


def _mathematical(word: str) -> str:
    """Mathematical bold letters, which NFKC folds to ASCII as Python does for identifiers."""
    out = []
    for c in word:
        if "a" <= c <= "z":
            out.append(chr(0x1D41A + ord(c) - ord("a")))
        elif "A" <= c <= "Z":
            out.append(chr(0x1D400 + ord(c) - ord("A")))
        else:
            out.append(c)
    return "".join(out)


def test_the_reported_exploit_does_not_run(tmp_path):
    canary = tmp_path / "canary.txt"
    code = f"__import__('pathlib').Path({str(canary)!r}).write_text('pwned')"
    model = tmp_path / "model.yaml"
    model.write_text(
        "format: cappe.model/1\nname: evil\n"
        f"bodies:\n  - {{name: b, mass: '{_fullwidth('eval')}(\"{_octal(code)}\")', dofs: [x]}}\n"
        "elements:\n  - {name: e, bodies: [ground, b], stiffness: {x: 1.0e6}}\n",
        encoding="utf-8",
    )
    assert main(["model", "show", str(model)]) == 1
    assert not canary.exists()
    with pytest.raises(ModelError, match=r"U\+FF45.*model\.yaml, bodies\[0\]\.mass"):
        load_model(model)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        (_fullwidth("eval") + '("1")', r"character 'ｅ' \(U\+FF45\) at position 0"),
        (_mathematical("open") + '("x")', r"U\+1D428"),
        ('__import__("os").system("true")', r"not one of the functions.*'__import__\(\"os\"\)\.system'"),
        ("k.__class__.__bases__", r"construct that is not allowed.*: 'k\.__class__\.__bases__'"),
        ("().__class__", r"construct that is not allowed"),
        ("(lambda: 1)()", r"not one of the functions"),
        ("[x for x in ()]", r"construct that is not allowed"),
        ("'1'*10**10", r"literal that is not a real number: \"'1'\""),
        ("9**9**9", r"power with more than 400 digits: '9\*\*9\*\*9'"),
        ("2**10**9", r"power with more than 400 digits"),
        ("10**10**7", r"power with more than 400 digits"),
        ("10**-10**7", r"power with more than 400 digits"),
        ("(k + 1)**100000", r"power larger than 64"),
        ("10**300*10**300", r"outside the floating-point range"),
        ("1" * 400, r"outside the floating-point range"),
        ("1e999", r"outside the floating-point range"),
        ("k^2", r"write powers as \*\*, not \^"),
        ("k // 2", r"integer division"),
        ("(k", r"does not parse: '\(' was never closed"),
        ("k))", r"does not parse: unmatched '\)'"),
        ("k; import os", r"does not parse"),
        ("sin(k, k)", r"calls sin with 2 argument\(s\); it takes 1"),
        ("sin(x=k)", r"keyword arguments"),
        ("sin", r"unknown name 'sin' \(a function"),
        ("k" + "+k" * MAX_EXPRESSION_LENGTH, rf"at most {MAX_EXPRESSION_LENGTH} are allowed"),
        ("-" * 60 + "k", r"nests deeper than 50 levels"),
        ("1j*k", r"not a real number"),
        ("True", r"not a real number"),
        ("k if k else 1", r"construct that is not allowed"),
    ],
)
def test_forbidden_text_is_a_located_model_error(text, match):
    result = _parse_watched(text, ["k"])
    assert isinstance(result, ModelError)
    assert str(result).endswith("(model.yaml, bodies[0].mass)")
    assert not _EVENTS
    with pytest.raises(ModelError, match=match):
        as_expression(text, ["k"], "model.yaml, bodies[0].mass")


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("2*k + 0.5", 2 * sp.Symbol("k", real=True) + sp.Rational(1, 2)),
        ("1.0e5", sp.Integer(100000)),
        ("1e5*k", 100000 * sp.Symbol("k", real=True)),
        ("1E-3", sp.Rational(1, 1000)),
        (".5", sp.Rational(1, 2)),
        ("0.135", sp.Rational(27, 200)),  # the decimal literal exactly, not its binary float
        ("-k**2/4", -sp.Symbol("k", real=True) ** 2 / 4),
        ("2**-3", sp.Rational(1, 8)),
        ("log(k, 10)", sp.log(sp.Symbol("k", real=True)) / sp.log(10)),
        ("k" + "+k" * 900, 901 * sp.Symbol("k", real=True)),  # long sums are built without recursion
        ("(" * 200 + "k" + ")" * 199 + ")", sp.Symbol("k", real=True)),
    ],
)
def test_ordinary_expressions_mean_what_they_say(text, expected):
    result = _parse_watched(text, ["k"])
    assert not isinstance(result, ModelError), result
    assert sp.simplify(result - expected) == 0
    assert not _EVENTS


# -- property tests: whatever the text, a sympy expression or a located ModelError, quickly, and nothing run --

_DANGEROUS_WORDS = [
    "eval",
    "exec",
    "open",
    "compile",
    "__import__",
    "globals",
    "getattr",
    "breakpoint",
    "input",
    "os",
    "system",
    "__class__",
    "__bases__",
    "__subclasses__",
    "__globals__",
    "__builtins__",
    "__dict__",
    "Symbol",
    "Function",
    "Integer",
    "k",
    "sin",
    "pi",
]


def _spelled(word: str) -> st.SearchStrategy[str]:
    return st.sampled_from([word, _fullwidth(word), _mathematical(word), word.upper()])


_word = st.sampled_from(_DANGEROUS_WORDS).flatmap(_spelled)
_unicode_name = st.text(
    alphabet=st.characters(categories=("Lu", "Ll", "Lo", "Nd", "Pc")), min_size=1, max_size=8
)
_escape = st.text(alphabet="abcdefghijklmnopqrstuvwxyz_().'", max_size=20).map(lambda s: f'"{_octal(s)}"')
_atom = st.one_of(
    _word,
    _unicode_name,
    _escape,
    st.integers(-(10**12), 10**12).map(str),
    st.floats(allow_nan=False, allow_infinity=False).map(repr),
    st.sampled_from(["1e5", "1.0e5", ".5", "1E-3", "1_000", "0x1F", "1j", "''", "None", "...", "*", "**"]),
)
_glue = st.sampled_from(
    ["", " ", ".", "(", ")", ",", "[", "]", "+", "-", "*", "/", "**", "^", "//", "%", "@", ":", ";", "=", "==",
     " if ", " else ", " for ", " in ", "lambda ", "\\", "\n", "#", "!", "~", "<<", "{", "}"]
)  # fmt: skip


@st.composite
def _texts(draw: st.DrawFn) -> str:
    parts = draw(st.lists(st.tuples(_atom, _glue), min_size=1, max_size=12))
    return "".join(a + g for a, g in parts)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(text=st.one_of(_texts(), st.text(max_size=60)))
def test_no_text_is_ever_run(text, tmp_path_factory):
    start = time.process_time()  # this process's CPU time: the bound holds on a loaded machine too
    result = _parse_watched(text, ["k"])
    elapsed = time.process_time() - start
    assert not _EVENTS, (text, _EVENTS)
    assert isinstance(result, (sp.Expr, ModelError)), (text, result)
    if isinstance(result, ModelError):
        message = str(result)
        assert message.endswith("(model.yaml, bodies[0].mass)")
        assert "\n" not in message.replace("\\n", "")
    assert elapsed < 2.0, (text, elapsed)  # bounded work: no expression may take CPU seconds


@settings(max_examples=150, deadline=None)
@given(payload=st.sampled_from(["remove", "write_text", "system"]), word=_word, spelling=st.integers(0, 2))
def test_canary_file_is_never_touched(payload, word, spelling, tmp_path_factory):
    canary = Path(tmp_path_factory.getbasetemp()) / "canary.txt"
    canary.write_text("alive")
    code = {
        "remove": f"__import__('os').remove({str(canary)!r})",
        "write_text": f"__import__('pathlib').Path({str(canary)!r}).write_text('x')",
        "system": f"__import__('os').system('rm ' + {str(canary)!r})",
    }[payload]
    wrapper = [_fullwidth, _mathematical, str][spelling]
    for text in (
        f'{wrapper("eval")}("{_octal(code)}")',
        f'{wrapper("exec")}("{_octal(code)}")',
        f"{word}({code})",
        code,
    ):
        result = _parse_watched(text, ["k"])
        assert isinstance(result, ModelError), text
        assert not _EVENTS, (text, _EVENTS)
    assert canary.read_text() == "alive"
