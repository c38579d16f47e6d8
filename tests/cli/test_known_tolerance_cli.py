"""``cappe identify --known-tolerance``: the option's parsing, its one-line errors, and the lines the text output
gives about the known parameters' uncertainty (the small slide model, its masses tagged disturbable)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from cappe.cli import main as cli
from cappe.cli._common import EXIT_USAGE
from cappe.io import write_modal_data
from cappe.modal import ModalEngine
from cappe.model import NumericModel, load_model

#: The small slide model of tests/cli/test_identify_cli.py and its truth.
MODEL = Path(__file__).parents[1] / "data" / "bench-slide.yaml"
TRUTH = {"me_kx": 7.1e7, "me1_ky": 0.95e8, "me2_ky": 1.2e8, "me3_ky": 1.7e8, "me_kz": 4.1e7, "lgs_kx": 2.3e8,
         "lgs_ky": 3.4e8, "bsd_kz": 0.8e8, "me_by": 1.1e4, "me_dx": 0.025, "lgs_bx": 1.2e3, "lgs_dy": 0.03}

BASE = ["--n-gsa", "8", "--n-opt", "2", "--workers", "1", "--permutations", "0", "--validation", "none"]


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("known")
    text = MODEL.read_text()
    for mass in ("mb", "mt"):
        old = f"{{name: {mass}, value:"
        assert old in text
        line = next(row for row in text.splitlines() if old in row)
        text = text.replace(line, line.replace("kind: mass}", "kind: mass, disturbable: true}"))
    model = folder / "slide-disturbable.yaml"
    model.write_text(text)
    assert sum(p.disturbable for p in load_model(model).parameters) == 2
    reference = ModalEngine(NumericModel(load_model(model))).modal_data([{"z": z} for z in (-0.2, 0.25)],
                                                                        params=TRUTH)
    write_modal_data(folder / "ref.json", reference)
    return {"plain": MODEL, "tagged": model, "ref": folder / "ref.json"}


@pytest.mark.parametrize(("entry", "said"), [
    ("nope=0.1", "'nope' is not a parameter of bench-slide"),
    ("me_kx=0.1", "'me_kx' is an unknown of this identification"),
    ("mb=-0.1", "relative standard deviation >= 0"),
    ("mb=ten", "relative standard deviation >= 0"),
    ("-0.1", "relative standard deviation >= 0"),
    ("0.1", "tags no known parameter disturbable; name them as NAME=REL"),
])
def test_bad_entries_are_one_line_errors_naming_the_entry(files, capsys, entry, said):
    code = cli(["identify", str(files["plain"]), "--reference", str(files["ref"]), *BASE,
                "--known-tolerance", entry])
    err = capsys.readouterr().err.strip()
    assert code == EXIT_USAGE
    assert len(err.splitlines()) == 1, err
    assert f"--known-tolerance {entry!r}" in err or f"--known-tolerance {entry}" in err
    assert said in err


def test_first_order_refinement_refuses_the_option(files, capsys):
    code = cli(["identify", str(files["tagged"]), "--reference", str(files["ref"]), *BASE, "--first-order",
                "--known-tolerance", "0.1"])
    assert code == EXIT_USAGE
    assert "needs the exact-mode refinement" in capsys.readouterr().err


def test_text_says_whether_the_intervals_include_the_known_parameters(files, capsys):
    """Without the option on a model with disturbable parameters: one line that the intervals assume the known
    parameters exact, naming the option. With it: which knowns were considered and how much they widen."""
    ref = ["identify", str(files["tagged"]), "--reference", str(files["ref"]), *BASE]
    assert cli(ref) == 0
    text = capsys.readouterr().out
    note = [row for row in text.splitlines() if "assume the known parameters exact" in row]
    assert len(note) == 1
    assert "--known-tolerance" in note[0]
    assert "(2 tagged disturbable)" in note[0]
    assert "including" not in text

    assert cli([*ref, "--known-tolerance", "0.1", "--known-tolerance", "mt=0.05", "--known-tolerance",
                "bsd_bz=0.2"]) == 0
    text = capsys.readouterr().out
    assert "assume the known parameters exact" not in text
    rows = [row for row in text.splitlines() if "known parameters' uncertainty" in row]
    assert len(rows) == 1
    assert "including 3 known parameters' uncertainty (relative std 5 % or 10 % or 20 %" in rows[0]
    assert "x wider" in rows[0]

    assert cli([*ref, "--known-tolerance", "0.1", "--known-tolerance", "mt=0.05", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    known = doc["diagnostics"]["uncertainty"]["known"]
    assert known["parameters"] == {"mb": 0.1, "mt": 0.05}
    assert known["largest_widening"] >= 1
    assert doc["diagnostics"]["settings"]["known_tolerance"] == {"mb": 0.1, "mt": 0.05}


def test_the_note_is_absent_where_no_parameter_is_tagged(files, capsys):
    assert cli(["identify", str(files["plain"]), "--reference", str(files["ref"]), *BASE]) == 0
    assert "assume the known parameters exact" not in capsys.readouterr().out


def test_a_negligible_scatter_does_not_print_a_factor_of_millions(files, capsys):
    """An exact, noise-free reference leaves the fit almost no scatter: the widening factor (millions) is printed
    as "more than 1000 x", with the standard error before and after, never as a number like 6.47e+06."""
    assert cli(["identify", str(files["tagged"]), "--reference", str(files["ref"]), *BASE,
                "--known-tolerance", "0.1", "--json"]) == 0
    known = json.loads(capsys.readouterr().out)["diagnostics"]["uncertainty"]["known"]
    assert known["largest_widening"] > 1e4  # the case this test is about (the JSON keeps the number)
    assert cli(["identify", str(files["tagged"]), "--reference", str(files["ref"]), *BASE,
                "--known-tolerance", "0.1"]) == 0
    row = next(r for r in capsys.readouterr().out.splitlines() if "known parameters' uncertainty" in r)
    assert "up to more than 1000 x wider" in row
    assert "e+" not in row, row
    assert f"({known['largest_widening_parameter']}: std " in row
    assert " % -> " in row


def test_every_text_output_says_the_intervals_assume_the_known_parameters_exact(files):
    """The note comes with the summary every text output prints (cappe identify, cappe demo, the Python API's
    summary_text), not only with cappe identify's; it names those left out when only some are given a tolerance;
    the JSON lists them."""
    from cappe.cli.identify import summary_text
    from cappe.estimate import AutomatedIdentification
    from cappe.io import read_modal_data

    model = load_model(files["tagged"])
    reference = read_modal_data(files["ref"])
    settings = {"n_gsa": 8, "n_opt": 2, "n_workers": 1, "n_permutations": 0, "validation": None, "rng": 0}
    result = AutomatedIdentification(model, **settings).fit(reference).result_
    text = summary_text(result, None, model.name)
    note = [row for row in text.splitlines() if "assume the known parameters exact" in row]
    assert note == ["note: the intervals assume the known parameters exact (2 tagged disturbable); "
                    "--known-tolerance REL includes their uncertainty"]
    assert result.estimate.diagnostics["known_assumed_exact"] == ["mb", "mt"]

    partial = AutomatedIdentification(model, known_tolerance={"mt": 0.05}, **settings).fit(reference).result_
    text = summary_text(partial, None, model.name)
    assert "assume 1 more known parameter exact that the model tags disturbable (mb)" in text
    assert "including 1 known parameter's uncertainty (relative std 5 %" in text
    assert partial.estimate.diagnostics["known_assumed_exact"] == ["mb"]


def test_first_order_refinement_refuses_the_noise_options_in_the_command_line_terms(files, capsys):
    # a new user (issue 24's trial on a fresh clone) got "noise weighting needs the exact-mode refinement (exact=True)"
    # after the GSA had started: a Python argument they never gave. Now a usage error before any work, naming options
    code = cli(["identify", str(files["tagged"]), "--reference", str(files["ref"]), *BASE, "--first-order",
                "--noise-frequency", "0.005", "--noise-damping", "0.05", "--noise-shape", "0.02"])
    assert code == EXIT_USAGE
    err = capsys.readouterr().err
    assert "--first-order" in err
    assert "exact=True" not in err
