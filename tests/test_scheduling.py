"""The units of work of ``make test`` (tests/conftest.py): a renamed file or test must not fall out of them silently."""

from __future__ import annotations

import ast
import importlib.util
from collections import OrderedDict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# tests/conftest.py by its path: ``import conftest`` finds whichever conftest module was imported first (a worker that
# ran tests/monitor first has tests/monitor/conftest.py under that name)
_SPEC = importlib.util.spec_from_file_location("cappe_tests_conftest", ROOT / "tests" / "conftest.py")
assert _SPEC is not None
assert _SPEC.loader is not None
_CONFTEST = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(_CONFTEST)
SPREAD, FIRST, work_unit, first_to_front = _CONFTEST.SPREAD, _CONFTEST.FIRST, _CONFTEST.work_unit, _CONFTEST.first_to_front


def test_spread_files_and_their_ordered_tests_exist():
    for path, together in SPREAD.items():
        tree = ast.parse((ROOT / path).read_text())
        functions = {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}
        assert set(together) <= functions, (path, together)


def test_first_units_exist():
    """A unit of FIRST renamed away would silently lose its place at the front of the queue."""
    assert len(set(FIRST)) == len(FIRST)
    for unit in FIRST:
        path, _, name = unit.partition("::")
        assert (ROOT / path).is_file(), unit
        # a file's test, a test kept together in a SPREAD file (any of its cases), or a lone test of a SPREAD file
        nodeid = f"{unit}[case]" if name in SPREAD.get(path, ()) else unit if name else f"{unit}::test_x"
        assert work_unit(nodeid) == unit, unit
        if name:
            tree = ast.parse((ROOT / path).read_text())
            assert name in {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}, unit


def test_the_longest_waiting_first_unit_goes_out_next():
    queue = OrderedDict.fromkeys(["tests/test_docstrings.py", FIRST[2], "tests/io/test_uff.py", FIRST[1]])
    first_to_front(queue)
    assert list(queue) == [FIRST[1], "tests/test_docstrings.py", FIRST[2], "tests/io/test_uff.py"]
    queue.popitem(last=False)
    first_to_front(queue)
    assert next(iter(queue)) == FIRST[2]
    rest = OrderedDict.fromkeys(["tests/io/test_uff.py", "tests/test_docstrings.py"])
    first_to_front(rest)  # none of FIRST waiting: xdist's order stands
    assert list(rest) == ["tests/io/test_uff.py", "tests/test_docstrings.py"]


def test_work_units():
    assert work_unit("tests/io/test_uff.py::test_a[1]") == "tests/io/test_uff.py"
    assert work_unit("src/cappe/io/uff.py::cappe.io.uff.write_uff_frf") == "src/cappe/io/uff.py"
    audit = "tests/cli/test_option_audit.py::test_option_changes_the_effect[model zpk --plot]"
    assert work_unit(audit) == audit
    readme = "tests/cli/test_model_cli.py::test_readme_command_runs"
    assert work_unit(readme + "[cappe model show builtin:two-mass-rig]") == readme
    assert work_unit("tests/cli/test_model_cli.py::test_show_json_contract") == (
        "tests/cli/test_model_cli.py::test_show_json_contract")
