"""The CLI through main(argv), and one real subprocess run of each command the README documents."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

from cappe.cli import main
from cappe.model._expressions import symbol

README = Path(__file__).resolve().parents[2] / "README.md"


def run(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_show_json_contract(capsys):
    code, out, _ = run(capsys, "model", "show", "builtin:two-mass-rig", "--json")
    assert code == 0
    data = json.loads(out)
    assert set(data) >= {
        "name",
        "n_dof",
        "dofs",
        "positions",
        "parameters",
        "bodies",
        "elements",
        "inputs",
        "outputs",
        "sensors",
    }
    assert [p["name"] for p in data["parameters"]] == ["m1", "m2", "k11", "k12", "k22", "c11", "c12", "c22"]
    assert set(data["parameters"][0]) == {"name", "value", "unit", "kind", "bounds", "unknown", "disturbable"}
    assert data["n_dof"] == 2


def test_tf_json_contract_matches_closed_form(capsys):
    code, out, _ = run(capsys, "model", "tf", "builtin:two-mass-rig", "--input", "F1", "--output", "d1", "--json")
    assert code == 0
    data = json.loads(out)
    assert data["input"] == "F1"
    assert data["output"] == "d1"
    m1, m2, k11, k12, k22, c11, c12, c22 = 1.39, 1.09, 1.38e6, 0.12e6, 0.24e6, 13.42, 0.0, 0.47
    expected_num = [1 / m1, (c12 + c22) / (m1 * m2), (k12 + k22) / (m1 * m2)]  # thesis eq. 5.8, b2 = 1/m1
    expected_den = [
        1,
        (c12 * m1 + c22 * m1 + c11 * m2 + c12 * m2) / (m1 * m2),
        (c11 * c12 + c11 * c22 + c12 * c22 + k12 * m1 + k22 * m1 + k11 * m2 + k12 * m2) / (m1 * m2),
        (c12 * k11 + c22 * k11 + c11 * k12 + c22 * k12 + c11 * k22 + c12 * k22) / (m1 * m2),
        (k11 * k12 + k11 * k22 + k12 * k22) / (m1 * m2),
    ]
    # float TF from poles/zeros/gain: agreement to ~1e-9 relative (eigenvalue round-off on 1e11-scale coefficients)
    np.testing.assert_allclose(data["numerator"], expected_num, rtol=1e-8)
    np.testing.assert_allclose(data["denominator"], expected_den, rtol=1e-8)


def test_tf_exact_and_symbolic(capsys):
    code, out, _ = run(
        capsys, "model", "tf", "builtin:two-mass-rig", "--input", "F1", "--output", "d2", "--exact", "--json"
    )
    assert code == 0
    data = json.loads(out)
    assert data["numerator"] == [str(sp.Rational(120000, 1) / (sp.Rational(139, 100) * sp.Rational(109, 100)))]
    code, out, _ = run(
        capsys, "model", "tf", "builtin:two-mass-rig", "--input", "F1", "--output", "d2", "--symbolic", "--json"
    )
    data = json.loads(out)
    m1, m2, k12, c12 = (symbol(n) for n in ("m1", "m2", "k12", "c12"))
    parsed = [sp.sympify(c, locals={"m1": m1, "m2": m2, "k12": k12, "c12": c12}) for c in data["numerator"]]
    assert sp.simplify(parsed[0] - c12 / (m1 * m2)) == 0
    assert sp.simplify(parsed[1] - k12 / (m1 * m2)) == 0


def test_modes_json_ascending_and_overrides(capsys, tmp_path):
    params = tmp_path / "p.json"
    params.write_text(json.dumps({"k12": 0.2e6}))
    code, out, _ = run(
        capsys,
        "model",
        "modes",
        "builtin:two-mass-rig",
        "--params",
        str(params),
        "--set",
        "m1=1.5",
        "--json",
        "-o",
        str(tmp_path / "modes.json"),
    )
    assert code == 0
    data = json.loads(out)
    freqs = [m["frequency"] for m in data["modes"]]
    assert freqs == sorted(freqs)
    # independent: undamped frequencies from the 2x2 eigenproblem with the overridden values
    m = np.diag([1.5, 1.09])
    k = np.array([[1.38e6 + 0.2e6, -0.2e6], [-0.2e6, 0.2e6 + 0.24e6]])
    w = np.sqrt(np.sort(np.linalg.eigvals(np.linalg.solve(m, k)).real)) / (2 * np.pi)
    np.testing.assert_allclose(freqs, w, rtol=1e-4)  # light damping shifts |lambda| by < 1e-5
    assert json.loads((tmp_path / "modes.json").read_text())["modes"][0]["frequency"] == freqs[0]


def test_modes_first_order_and_undamped(capsys):
    for damping in ("first-order", "undamped"):
        code, out, _ = run(capsys, "model", "modes", "builtin:spindle-bearing", "--damping", damping, "--json")
        assert code == 0
        assert len(json.loads(out)["modes"]) == 11


def test_check_dynamometer_reports_exact_invertibility(capsys):
    code, out, _ = run(capsys, "model", "check", "builtin:dynamometer-plate", "--json")
    assert code == 0
    data = json.loads(out)
    assert data["invertibility"]["exact"] == {"rank_M_n_minus_1": 60, "rank_M_n": 66, "invertible": True}
    assert data["invertibility"]["float"]["invertible"] is False
    assert data["rigid_body_modes"] == []


def test_check_reports_rigid_body_modes(capsys, tmp_path):
    model = tmp_path / "free.yaml"
    model.write_text(
        "format: cappe.model/1\nname: free\nparameters:\n  - {name: m, value: 1.0, kind: mass}\n"
        "  - {name: k, value: 100.0, kind: stiffness}\nbodies:\n  - {name: a, mass: m, dofs: [x]}\n"
        "  - {name: b, mass: m, dofs: [x]}\nelements:\n  - {name: s, bodies: [a, b], stiffness: {x: k}}\n"
        "inputs:\n  - {name: F, body: a}\noutputs:\n  - {name: d, body: b}\n"
    )
    code, out, _ = run(capsys, "model", "check", str(model), "--json")
    assert code == 0
    modes = json.loads(out)["rigid_body_modes"]
    assert len(modes) == 1
    assert modes[0]["a.x"] == pytest.approx(modes[0]["b.x"])  # both masses translate together


def test_frf_and_zpk_plots(capsys, tmp_path):
    bode = tmp_path / "bode.png"
    code, out, _ = run(
        capsys,
        "model",
        "frf",
        "builtin:two-mass-rig",
        "--inputs",
        "F1",
        "--outputs",
        "d1",
        "--fmin",
        "10",
        "--fmax",
        "400",
        "--lines",
        "50",
        "--plot",
        str(bode),
        "--json",
    )
    assert code == 0
    assert bode.stat().st_size > 1000
    data = json.loads(out)
    assert len(data["frequency"]) == 50
    pz = tmp_path / "pz.png"
    code, out, _ = run(
        capsys, "model", "zpk", "builtin:two-mass-rig", "--input", "F1", "--output", "d1", "--plot", str(pz), "--json"
    )
    assert code == 0
    assert pz.stat().st_size > 1000
    assert len(json.loads(out)["poles"]) == 4


def test_ss_discrete(capsys):
    code, out, _ = run(
        capsys,
        "model",
        "ss",
        "builtin:two-mass-rig",
        "--inputs",
        "F1",
        "--outputs",
        "d1,a1",
        "--dt",
        "1e-4",
        "--method",
        "tustin",
        "--json",
    )
    assert code == 0
    data = json.loads(out)
    assert data["dt"] == 1e-4
    assert np.array(data["A"]).shape == (4, 4)


@pytest.mark.parametrize(
    ("argv", "code", "match"),
    [
        (["model", "modes", "builtin:nope"], 1, r"unknown built-in model 'nope'"),
        (["model", "modes", "builtin:two-mass-rig", "--set", "m9=1"], 1, r"unknown parameter 'm9'"),
        (["model", "modes", "builtin:two-mass-rig", "--set", "m1"], 2, r"--set must look like NAME=VALUE"),
        (["model", "modes", "builtin:two-mass-rig", "--set", "m1=abc"], 2, r"--set 'm1' must be a number"),
        (["model", "modes", "builtin:two-mass-rig", "--position", "z=1"], 1, r"unknown axis 'z'"),
        (["model", "tf", "builtin:two-mass-rig", "--input", "F9", "--output", "d1"], 1, r"no input named 'F9'"),
        (["model", "modes", "builtin:two-mass-rig", "--params", "/nonexistent.json"], 1, r"cannot read parameter file"),
        (["model", "frf", "builtin:two-mass-rig", "--fmin", "100", "--fmax", "10"], 2, r"need 0 < --fmin < --fmax"),
    ],
)
def test_errors_and_exit_codes(capsys, argv, code, match):
    got, _, err = run(capsys, *argv)
    assert got == code
    assert re.search(match, err)


def test_unknown_command_is_usage_error(capsys):
    assert main(["model", "frobnicate"]) == 2


def _readme_commands() -> list[str]:
    return [line[2:].strip() for line in README.read_text().splitlines() if line.startswith("$ cappe ")]


def test_readme_documents_commands():
    assert len(_readme_commands()) >= 6


@pytest.fixture(scope="module")
def readme_dir(tmp_path_factory):
    """One working directory for the README's commands, in order (later ones read files earlier ones wrote)."""
    return tmp_path_factory.mktemp("readme")


@pytest.mark.parametrize("command", _readme_commands())
def test_readme_command_runs(command, readme_dir, monkeypatch, capsys):
    """Each ``$ cappe ...`` line exits 0, or with the code its shell comment states (``# exits 1: ...``).

    In this process, through the console script's function (cappe.cli.main): a subprocess per line paid cappe's
    imports, ~3 s, 37 times. That the ``cappe`` script starts is tests/cli/test_entry_points.py's."""
    line, _, comment = command.partition("#")
    expected = re.search(r"\bexits (\d+)", comment)
    monkeypatch.chdir(readme_dir)
    code = main(line.split()[1:])
    assert code == (int(expected.group(1)) if expected else 0), capsys.readouterr().err


class _StopDemo(Exception):
    """Raised by the stand-ins below once the demo's identification stage has shown what it was given."""


def test_demo_identification_options_reach_the_identification(monkeypatch, tmp_path, capsys):
    # --n-gsa, --n-opt, --seed and --report go to the identification stage; what each does there is the identify
    # command's (the option audit's identify cases drive them on the small slide). Here: that the demo hands them
    # on, without running the stage (a minute per run), and that --no-identify skips it.
    import cappe.estimate
    import cappe.report

    seen: list[dict[str, object]] = []

    class Recording:
        def __init__(self, machine, **settings):
            seen.append(dict(settings))

        def fit(self, reference, *, truth=None):
            seen[-1]["truth"] = truth
            seen[-1]["reference"] = reference
            self.result_ = None
            return self

    def report(path, **_):
        seen[-1]["report"] = path
        raise _StopDemo

    monkeypatch.setattr(cappe.estimate, "AutomatedIdentification", Recording)
    monkeypatch.setattr(cappe.report, "write_html_report", report)
    monkeypatch.chdir(tmp_path)
    for argv in (["--n-gsa", "32", "--n-opt", "2", "--seed", "1", "--report", "a.html"],
                 ["--n-gsa", "16", "--n-opt", "1", "--seed", "2", "--report", "b.html"], []):
        with pytest.raises(_StopDemo):
            main(["demo", "--no-monitor", *argv])
    capsys.readouterr()
    first, second, default = seen
    assert (first["n_gsa"], first["n_opt"], first["rng"], first["report"]) == (32, 2, 1, "a.html")
    assert (second["n_gsa"], second["n_opt"], second["rng"], second["report"]) == (16, 1, 2, "b.html")
    assert (default["n_gsa"], default["n_opt"], default["rng"], default["report"]) == (
        256, 20, 1, "cappe-demo-report.html")
    # the seed draws the truth: another seed, another truth, and the reference modes simulated at it
    assert first["truth"] != second["truth"]
    assert first["truth"] == default["truth"]
    assert not np.allclose(first["reference"].sets[0].frequency, second["reference"].sets[0].frequency)
    seen.clear()
    assert main(["demo", "--no-monitor", "--no-identify"]) == 0
    assert seen == []  # --no-identify: the stage is not entered


@pytest.mark.slow
@pytest.mark.extended(reason="each fault of the demo is detected and diagnosed by the chain's own tests: "
                             "tests/monitor/test_chain.py (preload loss, loosening screw) and "
                             "tests/cli/test_monitor_cli.py (front bearing)")
def test_demo_monitoring_finds_each_fault(capsys):
    code, out, _ = run(capsys, "demo", "--no-identify", "--json")
    assert code == 0
    alarms = json.loads(out)["monitoring_alarms"]
    # the simulated faults: front bearing -10 %, preload -40 %, screw 2 loosening to -50 % (two grades)
    assert [(a["scenario"], a["diagnosis"]["hypothesis"]) for a in alarms] == [
        ("bearing-loss", "front"), ("preload-loss", "preload"), ("loosening-screw", "screw2"),
        ("loosening-screw", "screw2")]
    assert all(a["measurement"] >= 2 for a in alarms)  # none before the fault


def test_readme_python_api_runs(tmp_path, monkeypatch):
    block = README.read_text().split("## Python API", 1)[1].split("```python", 1)[1].split("```", 1)[0]
    monkeypatch.chdir(tmp_path)
    exec(compile(block, "README.md", "exec"), {})  # noqa: S102 (our own documentation)


def _readme_yaml_blocks() -> list[str]:
    """Every ```yaml block of the documentation (```yml marks an excerpt that cannot load alone)."""
    docs = [README, *sorted((README.parent / "docs").glob("*.md"))]
    return [block.split("```", 1)[0] for doc in docs for block in doc.read_text().split("```yaml\n")[1:]]


def test_readme_has_yaml_blocks():
    assert _readme_yaml_blocks()


@pytest.mark.parametrize("block", _readme_yaml_blocks())
def test_every_documented_yaml_model_loads(block, tmp_path, capsys):
    # each model shown in the documentation loads and gives modes as written (the README's sled once failed on
    # its own 1.0e5, which PyYAML reads as a string)
    path = tmp_path / "model.yaml"
    path.write_text(block)
    code, out, err = run(capsys, "model", "modes", str(path), "--json")
    assert code == 0, err
    modes = json.loads(out)["modes"]
    assert modes
    if "name: sled" in block:
        # independent check: the table's x motion is a single oscillator (the shoe's x spring acts through the
        # centre's x line, so no moment): f = sqrt(k/m)/(2 pi), zeta = c/(2 sqrt(k m)) with k 2e6, m 3, c 30
        x_mode = max(modes, key=lambda mode: abs(mode["shape"]["table.x"]))
        assert x_mode["frequency"] == pytest.approx(np.sqrt(2.0e6 / 3.0) / (2 * np.pi), rel=1e-4)  # zeta^2 ~ 4e-5
        assert x_mode["damping"] == pytest.approx(30.0 / (2 * np.sqrt(2.0e6 * 3.0)), rel=1e-6)


def _oscillators(omegas, zeta=0.02):
    """State space of uncoupled unit-mass oscillators, x = [q, q'] (a stand-in with a .A/.B/.C interface)."""
    from types import SimpleNamespace

    n = len(omegas)
    w = np.diag(np.asarray(omegas, dtype=float))
    a = np.block([[np.zeros((n, n)), np.eye(n)], [-w**2, -2 * zeta * w]])
    return SimpleNamespace(A=a, B=None, C=None)


def _krylov_ranks(a, b, c):
    n = a.shape[0]
    ctrb = np.hstack([np.linalg.matrix_power(a, k) @ b for k in range(n)])
    obsv = np.vstack([c @ np.linalg.matrix_power(a, k) for k in range(n)])
    return np.linalg.matrix_rank(ctrb), np.linalg.matrix_rank(obsv)


def test_pbh_ranks_agree_with_krylov_ranks_on_small_systems():
    from cappe.exact import pbh_ranks

    ss = _oscillators([1.0, 2.0, 3.0])
    # force on oscillators 1 and 2 only, displacement of oscillator 3 only
    ss.B = np.array([[0, 0, 0, 1, 1, 0]], dtype=float).T
    ss.C = np.array([[0, 0, 1, 0, 0, 0]], dtype=float)
    assert pbh_ranks(ss).to_dict() == {"controllability_rank": 4, "observability_rank": 2}
    assert _krylov_ranks(ss.A, ss.B, ss.C) == (4, 2)
    # two identical oscillators driven by one force: a repeated pole pair, rank 1 per eigenvalue
    ss = _oscillators([2.0, 2.0])
    ss.B = np.array([[0, 0, 1, 1]], dtype=float).T
    ss.C = np.array([[1, 0, 0, 0], [0, 1, 0, 0]], dtype=float)
    assert pbh_ranks(ss).to_dict() == {"controllability_rank": 2, "observability_rank": 4}
    assert _krylov_ranks(ss.A, ss.B, ss.C) == (2, 4)


@pytest.mark.parametrize("name", ["two-mass-rig", "spindle-bearing"])
def test_check_pbh_ranks_equal_the_exact_ones(capsys, name):
    code, out, _ = run(capsys, "model", "check", f"builtin:{name}", "--json")
    assert code == 0
    data = json.loads(out)
    assert data["exact"] is True
    assert data["pbh"] == {"controllability_rank": data["controllability_rank"],
                           "observability_rank": data["observability_rank"]}


def test_check_skips_exact_tests_on_large_models(capsys):
    code, out, _ = run(capsys, "model", "check", "builtin:uniaxial-machine-tool")
    assert code == 0
    assert "exact rank tests skipped: 90 states > 24" in out
    assert "controllability rank 90, observability rank 90" in out
    code, out, _ = run(capsys, "model", "check", "builtin:two-mass-rig", "--exact", "never", "--json")
    data = json.loads(out)
    assert data["exact"] is False
    assert "invertibility" not in data


def test_the_parser_is_built_without_the_numerical_libraries():
    """`cappe --help` and the parser of every command need none of sympy, scipy or the estimators (their imports
    take about 1.5 s): the commands import what they use when they run."""
    code = ("import sys; from cappe.cli import build_parser; build_parser(); "
            "print(sorted(m for m in ('sympy', 'scipy', 'cappe.model', 'cappe.io', 'cappe.estimate._base') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


# -- bad values: one located error or a finite answer, never a traceback or NaN (issue 18) ---------------------------
CHAIN = """\
format: cappe.model/1
name: chain
parameters:
  - {{name: m1, value: {m1}, unit: kg, kind: mass}}
  - {{name: m2, value: {m2}, unit: kg, kind: mass}}
  - {{name: k, value: {k}, unit: N/m, kind: stiffness}}
  - {{name: c, value: 30.0, unit: N s/m, kind: damping}}
axes:
  - {{name: z, positions: [0.1, 0.3]}}
bodies:
  - {{name: table, mass: m1, dofs: [x]}}
  - {{name: slide, mass: m2, dofs: [x]}}
elements:
  - {{name: shoe, bodies: [ground, table], stiffness: {{x: '{kx}'}}, damping: {{x: c}}}}
  - {{name: link, bodies: [table, slide], stiffness: {{x: k}}, damping: {{x: c}}}}
inputs:
  - {{name: F, body: table, direction: x}}
outputs:
  - {{name: d, quantity: displacement, body: table, direction: x}}
"""

MODEL_COMMANDS = {"matrices": [], "modes": [], "tf": ["--input", "F", "--output", "d"], "frf": ["--lines", "20"]}


def chain_file(tmp_path, *, m1="3.0", m2="3.0", k="2.0e6", kx="k"):
    path = tmp_path / "model.yaml"
    path.write_text(CHAIN.format(m1=m1, m2=m2, k=k, kx=kx))
    return str(path)


def _no_constant(token):
    msg = f"{token} in the JSON output"
    raise AssertionError(msg)


@pytest.mark.parametrize("command", MODEL_COMMANDS)
@pytest.mark.parametrize(
    ("kx", "z", "value"),
    [
        ("1e6*sqrt(z)", "-0.2", "nan at z = -0.2"),
        ("exp(700)*k", "0.1", "inf at k = 2e+06"),
        ("k/z", "0", "inf at z = 0, k = 2e+06"),
        ("k*(3 + log(z))", "0", "-inf at z = 0, k = 2e+06"),
    ],
)
def test_an_expression_undefined_at_the_position_is_one_located_error(capsys, tmp_path, command, kx, z, value):
    path = chain_file(tmp_path, kx=kx)
    code, out, err = run(capsys, "model", command, path, "--position", f"z={z}", *MODEL_COMMANDS[command])
    assert code == 1
    assert out == ""
    assert err == f"cappe: error: {path}, elements[0].stiffness.x: evaluates to {value}\n"


#: exit codes of matrices, modes, tf and frf: 0 where double precision holds the answer (M of 1e-300 kg is exact;
#: at 1e-300 kg the FRF is a direct solve, at 1e300 kg the poles' real parts are at round-off as for any lightly
#: damped model), 1 where it does not (exact complex modes spread over 1e297, K's sum beyond 1.8e308, ...)
EXTREMES = {
    "mass-1e-300": ({"m1": "1e-300", "m2": "1e-300"}, (0, 1, 1, 0)),
    "mass-1e300": ({"m1": "1e300", "m2": "1e300"}, (0, 1, 0, 0)),
    "stiffness-1e308": ({"k": "1e308"}, (1, 1, 1, 1)),
    "masses-1e-200-1e200": ({"m1": "1e-200", "m2": "1e200"}, (0, 1, 1, 1)),
}


@pytest.mark.parametrize("command", MODEL_COMMANDS)
@pytest.mark.parametrize("case", EXTREMES)
def test_extreme_values_give_finite_numbers_or_one_located_error(capsys, tmp_path, command, case):
    values, codes = EXTREMES[case]
    path = chain_file(tmp_path, **values)
    code, out, err = run(capsys, "model", command, path, "--json", *MODEL_COMMANDS[command])
    assert code == codes[list(MODEL_COMMANDS).index(command)]
    if code == 0:
        assert err == ""
        json.loads(out, parse_constant=_no_constant)  # no NaN, Infinity or -Infinity
    else:
        assert out == ""
        # the file, and the entry: a body (with its DOF), an element's value, or the transfer function
        entry = r"(, bodies\[\d\] \(\w+\.x\)|, elements\[\d\]\.stiffness\.x|: transfer function d/F)"
        assert re.fullmatch(rf"cappe: error: {re.escape(path)}{entry}: [^\n]+\n", err), err


@pytest.mark.parametrize(
    ("values", "command", "message"),
    [
        ({"k": "1e308"}, "matrices", "elements[0].stiffness.x: adds 1e+308 to the stiffness matrix entry [table.x, "
                                     "table.x] at k = 1e+308, which sums to inf"),
        ({"m1": "1e-200", "m2": "1e200"}, "modes", "bodies[1] (slide.x): a mode is taken for a rigid-body mode"),
        ({"m1": "1e300", "m2": "1e300"}, "modes", "the exact complex modes cannot resolve 2 elastic mode(s)"),
        ({"m1": "1e-300", "m2": "1e-300"}, "tf", "transfer function d/F: its coefficients cannot be computed in double "
                                                 "precision"),
    ],
)
def test_what_double_precision_cannot_hold_is_named(capsys, tmp_path, values, command, message):
    path = chain_file(tmp_path, **values)
    code, _, err = run(capsys, "model", command, path, *MODEL_COMMANDS[command])
    assert code == 1
    assert err.startswith(f"cappe: error: {path}")
    assert message in err


def test_extreme_masses_that_double_precision_holds_give_the_right_numbers(capsys, tmp_path):
    # 1e300 kg: natural frequencies of 1e-148 Hz, the FRF's default band around them (not below the 0.1 Hz floor)
    path = chain_file(tmp_path, m1="1e300", m2="1e300")
    code, out, _ = run(capsys, "model", "modes", path, "--damping", "undamped", "--json")
    assert code == 0
    freqs = [mode["frequency"] for mode in json.loads(out)["modes"]]
    want = np.sqrt(2e6 / 1e300 * (3 + np.array([-1.0, 1.0]) * np.sqrt(5)) / 2) / (2 * np.pi)  # equal masses, springs
    np.testing.assert_allclose(freqs, want, rtol=1e-12)  # LAPACK's eigh on a 2 x 2 problem
    code, out, _ = run(capsys, "model", "modes", path, "--damping", "undamped")
    assert f"{want[0]:.4e}" in out  # not 0.000
    code, out, _ = run(capsys, "model", "frf", path, "--json", "--lines", "5")
    assert code == 0
    data = json.loads(out)
    assert data["frequency"][0] == pytest.approx(want[0] / 10, rel=1e-9)


def test_an_override_breaking_its_kind_names_the_parameter_entry(capsys, tmp_path):
    code, out, err = run(capsys, "model", "matrices", "builtin:two-mass-rig", "--set", "m1=-1")
    assert (code, out) == (1, "")
    assert err == ("cappe: error: parameter 'm1' (mass) must be > 0; got -1.0 (builtin:two-mass-rig, parameters[0])\n")
    params = tmp_path / "p.json"
    params.write_text('{"c11": -2.0}')
    code, out, err = run(capsys, "model", "modes", "builtin:two-mass-rig", "--params", str(params))
    assert (code, out) == (1, "")
    assert err == (f"cappe: error: {params}: parameter 'c11' (damping) must be >= 0; got -2.0 "
                   "(builtin:two-mass-rig, parameters[5])\n")
    # a value the rules allow but double precision cannot resolve: the body's entry, and where the value came from
    params.write_text('{"m1": 1e300}')
    code, out, err = run(capsys, "model", "modes", "builtin:two-mass-rig", "--params", str(params))
    assert (code, out) == (1, "")
    assert err.startswith("cappe: error: builtin:two-mass-rig, bodies[0] (mass1.x): a mode is taken for a rigid-body "
                          "mode")
    assert err.endswith(f" (parameter values from {params})\n")


@pytest.mark.slow
def test_tf_of_the_90_state_machine_tool_has_finite_coefficients(capsys):
    # its numerator used to print as NaN with exit 0 (an overflowing product of 90 pole distances)
    code, out, err = run(capsys, "model", "tf", "builtin:uniaxial-machine-tool", "--input", "Ftx", "--output", "atx",
                         "--json")
    assert (code, err) == (0, "")
    data = json.loads(out, parse_constant=_no_constant)
    assert len(data["denominator"]) == 91
    assert data["numerator"][0] > 0
