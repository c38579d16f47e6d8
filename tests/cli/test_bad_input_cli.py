"""Bad data files through the CLI (issue 18): one line on stderr naming the file, exit code 1, never a traceback.

One command per file kind: parameter files (--params, --start), modal reference files (estimate --data, identify
--reference) and measurement files (frf and fit on time data, extract-modes on FRFs, estimate on either).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from cappe.cli import main

BIG = "1" + "0" * 400  # 10**400: Python reads the int, float() overflows
HUGE = "1" + "0" * 5000  # more digits than int(str) accepts

PARAMETERS = {
    "non-UTF-8": b'{"k12": 1.0, "\xff": 2}',
    "deep nesting": b"[" * 100_000,
    "10**400": f'{{"k12": {BIG}}}'.encode(),
    "5001 digits": f'{{"k12": {HUGE}}}'.encode(),
    "NaN": b'{"k12": NaN}',
    "string": b'{"k12": "2e5"}',
    "list": b"[1, 2]",
    "empty": b"",
}
MODAL = {
    "non-UTF-8": b'{"format": "cappe.modal/1", "sensors": ["\xff"]}',
    "deep nesting": b'{"format": "cappe.modal/1", "sets": ' + b"[" * 100_000,
    "10**400": ('{"format": "cappe.modal/1", "sensors": ["d1", "d2"], "sets": [{"frequency": [' + BIG
                + '], "damping": [0.01], "shape_re": [[1, 0.5]]}]}').encode(),
    "5001 digits": ('{"format": "cappe.modal/1", "sensors": ["d1", "d2"], "sets": [{"frequency": [' + HUGE
                    + '], "damping": [0.01], "shape_re": [[1, 0.5]]}]}').encode(),
    "Infinity": (b'{"format": "cappe.modal/1", "sensors": ["d1", "d2"], "sets": [{"frequency": [Infinity], '
                 b'"damping": [0.01], "shape_re": [[1, 0.5]]}]}'),
    "mapping for a list": (b'{"format": "cappe.modal/1", "sensors": ["d1", "d2"], "sets": [{"frequency": {"a": 1}, '
                           b'"damping": [0.01], "shape_re": [[1, 0.5]]}]}'),
    "missing key": b'{"format": "cappe.modal/1", "sensors": ["d1", "d2"], "sets": [{"damping": [0.01]}]}',
    "empty": b"",
}
TIME_CSV = {
    "non-UTF-8": b"time,F1,d1\n0,1,\xff\n",
    "1e400": b"time,F1,d1\n0,1,2\n0.1,1e400,3\n",
    "5001 digits": b"time,F1,d1\n0,1,2\n0.1," + HUGE.encode() + b",3\n",
    "NaN": b"time,F1,d1\n0,1,2\n0.1,nan,3\n",
    "text": b"time,F1,d1\n0,1,2\n0.1,one,3\n",
    "empty": b"",
}
FRF_CSV = {
    "non-UTF-8": b"frequency,d1/F1 re,d1/F1 im\n1,\xff,1\n",
    "deep nesting": b"# window_decay: " + b"[" * 100_000 + b"\nfrequency,d1/F1 re,d1/F1 im\n1,2,3\n",
    "10**400": b"# window_decay: " + BIG.encode() + b"\nfrequency,d1/F1 re,d1/F1 im\n1,2,3\n",
    "5001 digits": b"# window_decay: " + HUGE.encode() + b"\nfrequency,d1/F1 re,d1/F1 im\n1,2,3\n",
    "inf": b"frequency,d1/F1 re,d1/F1 im\n1,2,3\n2,inf,3\n",
    "empty": b"",
}


def _one_line_error(capsys, argv, name):
    code = main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert code == 1, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("cappe: error: ")
    assert name in lines[0]
    assert len(lines[0]) < 400  # values are cut short in messages


@pytest.mark.parametrize("content", PARAMETERS.values(), ids=PARAMETERS)
def test_bad_parameter_file(tmp_path, capsys, content):
    path = tmp_path / "bad-params.json"
    path.write_bytes(content)
    _one_line_error(capsys, ["model", "modes", "builtin:two-mass-rig", "--params", path], "bad-params.json")


@pytest.mark.parametrize("content", PARAMETERS.values(), ids=PARAMETERS)
def test_bad_start_file(tmp_path, capsys, content):
    path = tmp_path / "bad-start.json"
    path.write_bytes(content)
    data = tmp_path / "ref.json"
    data.write_text(json.dumps({"format": "cappe.modal/1", "sensors": ["d1", "d2"],
                                "sets": [{"frequency": [50.0], "damping": [0.01], "shape_re": [[1, 0.5]]}]}))
    argv = ["estimate", "builtin:two-mass-rig", "--data", data, "--method", "modal", "--start", path]
    _one_line_error(capsys, argv, "bad-start.json")


@pytest.mark.parametrize("content", MODAL.values(), ids=MODAL)
def test_bad_modal_data(tmp_path, capsys, content):
    path = tmp_path / "bad-ref.json"
    path.write_bytes(content)
    _one_line_error(capsys, ["estimate", "builtin:two-mass-rig", "--data", path, "--method", "modal"], "bad-ref.json")


def test_bad_modal_reference_for_identify(tmp_path, capsys):
    path = tmp_path / "bad-ref.json"
    path.write_bytes(MODAL["10**400"])
    _one_line_error(capsys, ["identify", "builtin:two-mass-rig", "--reference", path], "bad-ref.json")


@pytest.mark.parametrize("content", TIME_CSV.values(), ids=TIME_CSV)
@pytest.mark.parametrize("command", ["frf", "fit"])
def test_bad_time_data(tmp_path, capsys, content, command):
    path = tmp_path / "bad-run.csv"
    path.write_bytes(content)
    _one_line_error(capsys, [command, path, "--inputs", "F1", "--output" if command == "fit" else "--outputs", "d1"],
                    "bad-run.csv")


@pytest.mark.parametrize("content", FRF_CSV.values(), ids=FRF_CSV)
def test_bad_frf_data(tmp_path, capsys, content):
    path = tmp_path / "bad-frf.csv"
    path.write_bytes(content)
    _one_line_error(capsys, ["extract-modes", path, "--band", "1:100"], "bad-frf.csv")
    _one_line_error(capsys, ["estimate", "builtin:two-mass-rig", "--data", path, "--method", "one-step-frf"],
                    "bad-frf.csv")


def test_bad_frf_npz(tmp_path, capsys):
    path = tmp_path / "bad-frf.npz"
    np.savez(path, freq=np.ones(2), H=np.array([[["a", "b"]]]), input_names=np.array(["F1"]),
             output_names=np.array(["d1"]))
    _one_line_error(capsys, ["extract-modes", path, "--band", "1:100"], "bad-frf.npz")


def test_setting_value_python_cannot_read_is_a_usage_error(tmp_path, capsys):
    # json.loads raised RecursionError / ValueError (digit limit) through the --setting parser
    ref = tmp_path / "ref.json"
    assert main(["model", "modes", "builtin:two-mass-rig", "--modal-out", str(ref)]) == 0
    capsys.readouterr()
    for value in ["[" * 100_000, "9" * 5000]:
        code = main(["estimate", "builtin:two-mass-rig", "--data", str(ref), "--method", "modal",
                     "--setting", f"max_nfev={value}"])
        err = capsys.readouterr().err
        assert code == 2, err
        assert err.startswith("cappe: usage error: --setting max_nfev: the value cannot be read")
        assert "Traceback" not in err


def test_errors_found_in_the_data_name_the_data_file(tmp_path, capsys):
    # the readers name the file in their own errors; what the library finds later (a missing channel, an empty
    # channel name) did not say which file the data came from
    t = np.arange(64) / 64.0
    path = tmp_path / "run.csv"
    path.write_text("time,F,a\n" + "".join(f"{v:.17g},{np.sin(v):.17g},{np.cos(v):.17g}\n" for v in t))
    code = main(["frf", str(path), "--inputs", "G", "--outputs", "a", "--nperseg", "32"])
    err = capsys.readouterr().err
    assert code == 1
    assert err.startswith(f"cappe: error: {path}: input channel(s) ['G'] not found")
    path.write_text("time,,a\n" + "".join(f"{v:.17g},{np.sin(v):.17g},{np.cos(v):.17g}\n" for v in t))
    code = main(["frf", str(path), "--inputs", "F", "--outputs", "a"])
    err = capsys.readouterr().err
    assert code == 1
    assert "channel names must not be empty; channel 0 has none" in err
    assert str(path) in err


def test_reference_not_matching_the_model_names_the_reference(tmp_path, capsys):
    # found by the fuzz test: a sensor the model lacks was a ModelError without the reference file's name
    ref = tmp_path / "ref.json"
    assert main(["model", "modes", "builtin:two-mass-rig", "--modal-out", str(ref)]) == 0
    data = json.loads(ref.read_text())
    data["sensors"][0] = "n7:x"
    ref.write_text(json.dumps(data))
    capsys.readouterr()
    code = main(["sensitivity", "builtin:two-mass-rig", "--sobol", "--reference", str(ref), "--n-gsa", "4"])
    err = capsys.readouterr().err
    assert code == 1
    assert err.startswith(f"cappe: error: {ref}: sensor 'n7:x' does not exist in model 'two-mass-rig'")
