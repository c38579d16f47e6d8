"""The package keeps its layers: import-linter checks the contracts in pyproject.toml ([tool.importlinter]).

* ``model``, ``systems`` and ``modal`` never import ``io``, ``estimate`` or ``monitor`` (not even through another
  package, nor inside a function);
* no library package imports ``cli``;
* no package cycles among the subpackages and modules of ``cappe``.

The second test copies the package, breaks one rule at a time and checks that the linter reports exactly that
contract (a layer test that cannot fail would be a defect).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = ROOT / "pyproject.toml"
PACKAGE = ROOT / "src" / "cappe"
LINT = "import sys; from importlinter.cli import lint_imports_command; sys.exit(lint_imports_command())"
RULES = ("core-below-files", "cli-on-top", "no-package-cycles")


def _contract_names() -> dict[str, str]:
    contracts = tomllib.loads(PYPROJECT.read_text(encoding="utf-8"))["tool"]["importlinter"]["contracts"]
    return {c["id"]: c["name"] for c in contracts}


def _lint(cwd: Path, pythonpath: Path | None = None) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ)
    if pythonpath is not None:
        env["PYTHONPATH"] = str(pythonpath)  # ahead of the installed package on sys.path
    return subprocess.run(
        [sys.executable, "-c", LINT, str(PYPROJECT), "--no-cache"],
        cwd=cwd, env=env, capture_output=True, text=True, timeout=300, check=False,
    )


def _verdicts(output: str, names: dict[str, str]) -> dict[str, str]:
    verdicts = {}
    for rule, name in names.items():
        for verdict in ("KEPT", "BROKEN"):
            if f"{name} {verdict}" in output:
                verdicts[rule] = verdict
    return verdicts


def test_pyproject_states_the_layer_rules():
    assert set(RULES) <= set(_contract_names())


def test_the_package_keeps_its_layers():
    run = _lint(ROOT)
    assert run.returncode == 0, run.stdout + run.stderr
    assert _verdicts(run.stdout, _contract_names()) == dict.fromkeys(RULES, "KEPT"), run.stdout


# one violation per rule: (file in the copy, code appended to it, rules it must break, the line the report shows)
VIOLATIONS = {
    "modal imports io inside a function": (
        "modal/_batch.py",
        "\n\ndef _leak():\n    from cappe.io import read_modal_data\n\n    return read_modal_data\n",
        {"core-below-files"},
        "cappe.modal._batch -> cappe.io",
    ),
    "systems reaches io through identify": (
        "systems/zpk.py",
        "\nimport cappe.identify._frf\n",
        {"core-below-files", "no-package-cycles"},  # identify imports systems: also a cycle
        "cappe.identify._frf -> cappe.io.measurements",
    ),
    "a library package imports cli": (
        "correlate/_pairing.py",
        "\nimport cappe.cli\n",
        {"cli-on-top", "no-package-cycles"},  # cli imports everything, so any import of it from below closes a cycle
        "cappe.correlate._pairing -> cappe.cli",
    ),
    "optimize imports estimate, which imports optimize": (
        "optimize/_minimize.py",
        "\nfrom cappe.estimate import _space\n",
        {"no-package-cycles"},
        ".optimize -> .estimate",
    ),
}


@pytest.mark.parametrize("case", list(VIOLATIONS))
def test_a_deliberate_violation_breaks_its_contract(tmp_path, case):
    path, code, broken, shown = VIOLATIONS[case]
    copy = tmp_path / "cappe"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    with (copy / path).open("a", encoding="utf-8") as f:
        f.write(code)
    run = _lint(tmp_path, pythonpath=tmp_path)
    verdicts = _verdicts(run.stdout, _contract_names())
    assert run.returncode == 1, run.stdout + run.stderr
    assert verdicts == {rule: "BROKEN" if rule in broken else "KEPT" for rule in RULES}, run.stdout
    assert shown in run.stdout
