"""The units of work of ``make test`` (tests/conftest.py): a renamed file or test must not fall out of them silently."""

from __future__ import annotations

import ast
import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# tests/conftest.py by its path: ``import conftest`` finds whichever conftest module was imported first (a worker that
# ran tests/monitor first has tests/monitor/conftest.py under that name)
_SPEC = importlib.util.spec_from_file_location("cappe_tests_conftest", ROOT / "tests" / "conftest.py")
assert _SPEC is not None
assert _SPEC.loader is not None
_CONFTEST = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(_CONFTEST)
SPREAD, work_unit = _CONFTEST.SPREAD, _CONFTEST.work_unit


def test_spread_files_and_their_ordered_tests_exist():
    for path, together in SPREAD.items():
        tree = ast.parse((ROOT / path).read_text())
        functions = {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}
        assert set(together) <= functions, (path, together)


def test_work_units():
    assert work_unit("tests/io/test_uff.py::test_a[1]") == "tests/io/test_uff.py"
    assert work_unit("src/cappe/io/uff.py::cappe.io.uff.write_uff_frf") == "src/cappe/io/uff.py"
    audit = "tests/cli/test_option_audit.py::test_option_changes_the_effect[model zpk --plot]"
    assert work_unit(audit) == audit
    readme = "tests/cli/test_model_cli.py::test_readme_command_runs_as_subprocess"
    assert work_unit(readme + "[cappe model show builtin:two-mass-rig]") == readme
    assert work_unit("tests/cli/test_model_cli.py::test_show_json_contract") == (
        "tests/cli/test_model_cli.py::test_show_json_contract")
