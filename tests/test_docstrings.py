"""Every argument of the public API is documented, as python-control's docstring test checks its own.

The public API: the names in ``__all__`` of every subpackage of cappe and of its public top-level modules
(``cappe.estimate``'s come from its ``__init__.pyi`` through lazy_loader), their classes' ``__init__`` arguments and
public methods. Each argument (``self`` and ``cls`` aside) must be named in the numpydoc ``Parameters`` or
``Other Parameters`` section of its docstring (read with numpydoc's docscrape); ``name1, name2 : type`` documents
both, ``*args`` / ``**kwargs`` may be written with or without their stars; private arguments (``_name``) need no
entry. A class documents its ``__init__`` arguments in its own docstring or its ``__init__``'s; a dataclass may
list its fields under ``Attributes`` (they are its attributes too). Every name a ``Parameters`` section documents
must be an argument, unless the callable takes ``**kwargs``. A malformed section (``Parameter``, a repeated
header) fails too. Units and shapes belong in the type line (STYLE.md); that is read by people, not checked here.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import pkgutil
import warnings
from collections.abc import Callable, Iterator
from typing import Any

import pytest
from numpydoc.docscrape import NumpyDocString

import cappe

_SECTIONS = ("Parameters", "Other Parameters")


# -- the checker ---------------------------------------------------------------------------------------------------
def _arguments(signature: inspect.Signature) -> list[inspect.Parameter]:
    """The arguments a caller passes: not ``self`` / ``cls``, not private (``_index`` of a dataclass)."""
    return [p for p in signature.parameters.values() if p.name not in ("self", "cls") and not p.name.startswith("_")]


def _documented(doc: str | None, sections: tuple[str, ...] = _SECTIONS) -> set[str]:
    """The names the given numpydoc sections of ``doc`` document (``a, b : int`` names both)."""
    if not doc:
        return set()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an unknown or repeated section is a malformed docstring
        parsed = NumpyDocString(inspect.cleandoc(doc))
    return {name.strip().lstrip("*") for section in sections for entry in parsed[section]
            for name in entry.name.split(",") if name.strip()}


def check_arguments(signature: inspect.Signature, *docs: str | None, attributes: bool = False) -> list[str]:
    """What is wrong with how ``docs`` document the arguments of ``signature`` (empty when nothing is).

    ``attributes`` accepts the ``Attributes`` section too (the fields of a dataclass).
    """
    arguments = _arguments(signature)
    if not arguments:
        return []
    sections = (*_SECTIONS, "Attributes") if attributes else _SECTIONS
    documented = set().union(*(_documented(doc, sections) for doc in docs))
    problems = [f"argument {p.name!r} is not documented" for p in arguments if p.name not in documented]
    if not any(p.kind is inspect.Parameter.VAR_KEYWORD for p in arguments):
        listed = set().union(*(_documented(doc) for doc in docs))  # (Attributes may name properties too)
        names = {p.name for p in arguments}
        problems += [f"documents {name!r}, which is not an argument" for name in sorted(listed - names)]
    return problems


def _ours(func: Any, owner: type) -> bool:
    """Whether ``func`` is a Python function of the package that defines ``owner`` (not object's, an exception's
    or a library's)."""
    root = owner.__module__.split(".")[0]
    return inspect.isfunction(func) and (func.__module__ or "").split(".")[0] == root


def check_callable(obj: Any) -> list[str]:
    """Problems of a function, or of a class's ``__init__`` arguments."""
    if not inspect.isclass(obj):
        return check_arguments(inspect.signature(obj), obj.__doc__)
    init = next((k.__dict__["__init__"] for k in obj.__mro__ if "__init__" in k.__dict__), None)
    if not (dataclasses.is_dataclass(obj) or _ours(init, obj)):
        return []
    return check_arguments(inspect.signature(obj), obj.__doc__, getattr(init, "__doc__", None),
                           attributes=dataclasses.is_dataclass(obj))


def public_api() -> dict[str, Any]:
    """``{qualified name: object}`` of every public function and class (each object once, by its first name)."""
    modules = [f"cappe.{m.name}" for m in pkgutil.iter_modules(cappe.__path__) if not m.name.startswith("_")]
    found: dict[int, tuple[str, Any]] = {}
    for name in modules:
        module = importlib.import_module(name)
        for attr in getattr(module, "__all__", ()):
            obj = getattr(module, attr)
            if (inspect.isfunction(obj) or inspect.isclass(obj)) and id(obj) not in found:
                found[id(obj)] = (f"{name}.{attr}", obj)
    return dict(found.values())


def _methods(cls: type) -> Iterator[Callable[..., Any]]:
    """The public methods (static and class methods too) that cappe defines on ``cls`` or its bases."""
    for name in dir(cls):
        if name.startswith("_"):
            continue
        raw = next((k.__dict__[name] for k in cls.__mro__ if name in k.__dict__), None)
        if isinstance(raw, (staticmethod, classmethod)):
            raw = raw.__func__
        if _ours(raw, cls):
            yield raw


def api_callables() -> dict[str, Any]:
    """``{qualified name: function or class}``: the public functions and classes and the classes' methods, each
    method once, named by the class that defines it (``cappe.identify.PolynomialModel.fit``)."""
    out: dict[str, Any] = {}
    for qualified, obj in public_api().items():
        out[qualified] = obj
        if inspect.isclass(obj):
            package = qualified.rsplit(".", 1)[0]
            for method in _methods(obj):
                out.setdefault(f"{package}.{method.__qualname__}", method)
    return out


API = api_callables()

def _cases() -> list[Any]:
    return [pytest.param(name, id=name) for name in sorted(API)]


# -- the checker catches what it should ----------------------------------------------------------------------------
def test_checker_reports_an_undocumented_argument():
    def scale(x, factor):
        """Multiply.

        Parameters
        ----------
        x : float
            Value.
        """
        return x * factor

    assert check_callable(scale) == ["argument 'factor' is not documented"]


def test_checker_reports_a_function_without_parameters_section_and_a_stale_name():
    def bare(x, y):
        """No sections at all."""

    def renamed(freq, H):
        """Renamed argument.

        Parameters
        ----------
        f : ndarray
            Frequencies in Hz.
        H : ndarray
            FRFs.
        """

    assert check_callable(bare) == ["argument 'x' is not documented", "argument 'y' is not documented"]
    assert check_callable(renamed) == ["argument 'freq' is not documented", "documents 'f', which is not an argument"]


def test_checker_accepts_grouped_names_star_arguments_and_dataclass_attributes():
    def grouped(name, unit, *args, rng=None, **kwargs):
        """Grouped.

        Parameters
        ----------
        name, unit : str
            Channel name and unit.
        *args
            Passed on.
        rng : int, Generator or None
            Seed.

        Other Parameters
        ----------------
        **kwargs
            Passed on.
        """

    @dataclasses.dataclass(frozen=True)
    class Point:
        """A point.

        Attributes
        ----------
        x, y : float
            Coordinates in m.
        """

        x: float
        y: float
        _cache: dict = dataclasses.field(default_factory=dict)  # private: not the caller's

    class Plain:
        """A class documents its ``__init__`` in its own docstring.

        Parameters
        ----------
        k : float
            Stiffness in N/m.
        """

        def __init__(self, k, c):
            self.k, self.c = k, c

        def method(self):
            """Takes only self."""

    assert check_callable(grouped) == []
    assert check_callable(Point) == []
    assert check_callable(Plain) == ["argument 'c' is not documented"]
    assert check_callable(Plain.method) == []


def test_checker_refuses_a_malformed_section():
    def misspelled(x):
        """Misspelled section.

        Parameter
        ---------
        x : float
            Value.
        """

    with pytest.raises(UserWarning, match="Unknown section Parameter"):
        check_callable(misspelled)


def test_the_api_is_found():
    # names from a plain __all__, from cappe.estimate's stub, a class and a method inherited from a private base
    for name in ("cappe.systems.FRFData", "cappe.estimate.fit_least_squares", "cappe.estimate.ParameterSpace.full",
                 "cappe.identify.PolynomialModel.fit", "cappe.model.Structure"):
        assert name in API, name
    assert sum(inspect.isfunction(obj) for obj in public_api().values()) > 150  # 156 when this test was written


# -- the public API ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", _cases())
def test_every_argument_is_documented(name):
    problems = check_callable(API[name])
    assert not problems, f"{name}: " + "; ".join(problems)
