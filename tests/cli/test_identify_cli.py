"""``cappe identify``: end to end on a small position-dependent model, and its error exits."""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from cappe.cli import identify
from cappe.cli._common import EXIT_USAGE, run_guarded
from cappe.io import write_modal_data
from cappe.io.modal import ModalData, ModalDataSet
from cappe.modal import ModalEngine
from cappe.model import NumericModel, load_model

#: The small slide model shared with tests/estimate/test_automated.py (see tests/data/README.md).
MODEL = Path(__file__).parents[1] / "data" / "bench-slide.yaml"

TRUTH = {"me_kx": 7.1e7, "me1_ky": 0.95e8, "me2_ky": 1.2e8, "me3_ky": 1.7e8, "me_kz": 4.1e7, "lgs_kx": 2.3e8,
         "lgs_ky": 3.4e8, "bsd_kz": 0.8e8, "me_by": 1.1e4, "me_dx": 0.025, "lgs_bx": 1.2e3, "lgs_dy": 0.03}


def cli(argv: Sequence[str]) -> int:
    """``cappe identify ...`` through the command's own parser and the CLI's error handling (as ``cappe.cli.main``)."""
    parser = argparse.ArgumentParser(prog="cappe")
    sub = parser.add_subparsers(dest="command", required=True)
    identify.register(sub)
    try:
        args = parser.parse_args(list(argv))
    except SystemExit as exc:
        return int(exc.code) if isinstance(exc.code, int) else EXIT_USAGE
    return run_guarded(args.func, args)


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("identify")
    nm = NumericModel(load_model(MODEL))
    reference = ModalEngine(nm).modal_data([{"z": z} for z in (-0.2, 0.0, 0.25)], params=TRUTH)
    write_modal_data(folder / "ref.json", reference)
    (folder / "truth.json").write_text(json.dumps(TRUTH))
    s = reference.sets[0]
    bad_sensor = ModalData(("bed1:x", "nose:x"), (ModalDataSet(s.position, s.frequency, s.damping, s.shapes[:2]),))
    write_modal_data(folder / "bad_sensor.json", bad_sensor)
    many = ModalData(reference.sensors, (ModalDataSet(s.position, np.tile(s.frequency, 2), np.tile(s.damping, 2),
                                                      np.tile(s.shapes, (1, 2))),))
    write_modal_data(folder / "many.json", many)
    return {"folder": folder, "model": MODEL, "ref": folder / "ref.json", "truth": folder / "truth.json",
            "bad_sensor": folder / "bad_sensor.json", "many": folder / "many.json"}


def test_identify_end_to_end(files, capsys):
    out = files["folder"] / "result.json"
    report = files["folder"] / "report.html"
    code = cli(["identify", str(files["model"]), "--reference", str(files["ref"]), "--truth", str(files["truth"]),
                "--n-gsa", "32", "--n-opt", "6", "--seed", "2", "--workers", "1", "--permutations", "2",
                "--overlay", "tool:x,bed1:y", "-o", str(out), "--report", str(report)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    text = captured.out
    # the held-out position defaults to the reference's first one
    assert "validation position: z = -0.2\n" in text  # a position in words, not a Python dict (issue 22)
    assert "worst |error|" in text
    assert "runtime: gsa" in text
    assert "; CPU: gsa" in text  # CPU seconds per stage: what a stage costs whatever the load
    assert "permuted damping (2 reassignments)" in text
    doc = json.loads(out.read_text())
    assert doc["format"] == "cappe.estimate/1"
    assert doc["method"] == "automated-gsa"
    assert set(doc["parameters"]) == set(TRUTH)
    for name, value in doc["parameters"].items():
        # ideal case (exact modes of the truth, no noise): the 1 % / 5 % criteria, achieved ~1e-9
        assert value == pytest.approx(TRUTH[name], rel=0.01 if name.endswith(("kx", "ky", "kz", "_k")) else 0.05)
    assert doc["diagnostics"]["timings"]["total"] > 0
    held = doc["diagnostics"]["validation"]["validation"]
    assert held["frf"]["overlay"] == {"output": "tool:x", "input": "bed1:y"}
    assert held["statistics"]["frac"]["worst"] == pytest.approx(1.0, abs=1e-6)  # recovered model
    assert doc["diagnostics"]["gsa"]["outputs"]
    page = report.read_text()
    assert page.startswith("<!DOCTYPE html>")
    assert page.count("data:image/png;base64,") >= 5  # histograms, sensitivity map, Sobol bars, FRF, MACXP
    assert "held-out position z = -0.2" in page


def test_identify_json_without_hold_out(files, capsys):
    code = cli(["identify", str(files["model"]), "--reference", str(files["ref"]), "--validation", "none",
                "--unknowns", "me_kx,me_kz,me_by", "--n-gsa", "16", "--n-opt", "3", "--workers", "1",
                "--permutations", "0", "--json"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    doc = json.loads(captured.out)
    assert list(doc["parameters"]) == ["me_kx", "me_kz", "me_by"]
    assert doc["diagnostics"]["validation_position"] is None
    assert len(doc["diagnostics"]["identification_positions"]) == 3


def test_identify_names_sensors_that_do_not_fit(files, capsys):
    code = cli(["identify", str(files["model"]), "--reference", str(files["bad_sensor"]), "--n-gsa", "8"])
    assert code == 1
    assert "reference sensors ['nose:x'] are not sensor channels of model 'bench-slide'" in capsys.readouterr().err


def test_identify_names_a_bad_overlay_before_the_identification(files, capsys, monkeypatch):
    # the overlay channels were checked by the validation step, after the whole identification (28 s on the
    # machine tool at --n-gsa 64); the error now comes first
    import cappe.estimate._automated as automated

    def pipeline_ran(*_args, **_kwargs):
        msg = "the pipeline ran"
        raise AssertionError(msg)

    monkeypatch.setattr(automated, "run_pipeline", pipeline_ran)
    code = cli(["identify", str(files["model"]), "--reference", str(files["ref"]), "--overlay", "nose:x,bed1:y"])
    assert code == 1
    assert "overlay ('nose:x', 'bed1:y') must be (output, input): two reference sensor channels" in (
        capsys.readouterr().err)


def test_identify_names_modes_and_positions_that_do_not_fit(files, capsys):
    code = cli(["identify", str(files["model"]), "--reference", str(files["many"]), "--n-gsa", "8"])
    assert code == 1
    assert "reference set 0 (position {'z': -0.2}) has 24 modes; model 'bench-slide' has only 12" in capsys.readouterr().err
    code = cli(["identify", str(files["model"]), "--reference", str(files["ref"]), "--validation", "z=-0.294"])
    assert code == 1
    assert "position {'z': -0.294} is not among the reference's positions" in capsys.readouterr().err
    code = cli(["identify", str(files["model"]), "--reference", str(files["ref"]), "--validation", "x=0.1"])
    assert code == 1
    assert "unknown axis 'x'" in capsys.readouterr().err


def test_identify_usage_errors(files, capsys):
    code = cli(["identify", str(files["model"]), "--reference", str(files["ref"]), "--noise", "0.1,0.2"])
    assert code == EXIT_USAGE
    assert "--noise must be three numbers > 0" in capsys.readouterr().err
    code = cli(["identify", str(files["model"]), "--reference", str(files["ref"]), "--overlay", "tool:x"])
    assert code == EXIT_USAGE
    assert "--overlay must look like OUT,IN" in capsys.readouterr().err
    code = cli(["identify", str(files["model"]), "--reference", str(files["ref"]), "--n-opt", "0"])
    assert code == EXIT_USAGE
    assert "--n-opt must be >= 1; got 0" in capsys.readouterr().err
    code = cli(["identify", str(files["model"]), "--reference", str(files["ref"]), "--set", "nope=1"])
    assert code == 1
    assert "unknown parameter 'nope'" in capsys.readouterr().err


def test_parameters_the_data_do_not_determine_get_a_warning_line() -> None:
    """A nan std in the table was the only sign that two mounts in parallel were not told apart (three-axis run)."""
    from cappe.cli.identify import _parameter_rows
    from cappe.estimate import ParameterEstimate

    n = 3
    est = ParameterEstimate(
        method="automated", names=("k1", "k2", "k3"), values=np.array([1.0, 2.0, 3.0]),
        std=np.array([0.01, np.nan, np.nan]), ci95=np.full((n, 2), np.nan), correlation=np.eye(n),
        identifiable=np.array([True, False, False]), combinations=("+0.71 k2 +0.71 k3",),
    )
    lines = _parameter_rows(est, None)
    warning = [line for line in lines if line.startswith("warning:")]
    assert len(warning) == 1
    assert "k2, k3" in warning[0]
    assert "+0.71 k2 +0.71 k3" in warning[0]
    assert "k1" not in warning[0]
    fine = replace(est, std=np.array([0.01, 0.02, 0.03]), identifiable=np.ones(n, bool), combinations=())
    assert not [line for line in _parameter_rows(fine, None) if line.startswith("warning:")]
