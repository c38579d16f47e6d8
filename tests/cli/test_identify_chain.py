"""``cappe identify`` on a test engineer's files: one reference file per position, warnings in the text output,
honest intervals, and extract-modes recording the position and mapping sensors (issue 20)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import pyuff

from cappe.cli import main
from cappe.io import read_modal_data, write_modal_data
from cappe.io.modal import ModalData, ModalDataSet
from cappe.modal import ModalEngine
from cappe.model import NumericModel, load_model

#: The small slide model shared with tests/estimate/test_automated.py (see tests/data/README.md).
MODEL = Path(__file__).parents[1] / "data" / "bench-slide.yaml"
TRUTH = {"me_kx": 7.1e7, "me1_ky": 0.95e8, "me2_ky": 1.2e8, "me3_ky": 1.7e8, "me_kz": 4.1e7, "lgs_kx": 2.3e8,
         "lgs_ky": 3.4e8, "bsd_kz": 0.8e8, "me_by": 1.1e4, "me_dx": 0.025, "lgs_bx": 1.2e3, "lgs_dy": 0.03}
POSITIONS = (-0.2, 0.0, 0.25)
QUICK = ["--n-gsa", "32", "--n-opt", "6", "--seed", "2", "--workers", "1", "--permutations", "0"]


@pytest.fixture(scope="module")
def reference() -> ModalData:
    return ModalEngine(NumericModel(load_model(MODEL))).modal_data([{"z": z} for z in POSITIONS], params=TRUTH)


def _split(reference: ModalData, folder: Path) -> list[str]:
    paths = []
    for k, s in enumerate(reference.sets):
        path = folder / f"z{k}.json"
        write_modal_data(path, ModalData(reference.sensors, (s,)))
        paths.append(str(path))
    return paths


def test_one_file_per_position(reference, tmp_path, capsys):
    paths = _split(reference, tmp_path)
    (tmp_path / "truth.json").write_text(json.dumps(TRUTH))
    code = main(["identify", str(MODEL), "--reference", *paths, "--truth", str(tmp_path / "truth.json"), *QUICK,
                 "-o", str(tmp_path / "r.json")])
    out = capsys.readouterr()
    assert code == 0, out.err
    doc = json.loads((tmp_path / "r.json").read_text())
    # the default validation position is stated in the output
    assert "validation position {'z': -0.2} chosen by default" in out.err
    errors = [abs(doc["parameters"][n] / v - 1) for n, v in TRUTH.items()]
    assert max(errors) < 1e-4  # exact reference (exact complex modes, realized on both sides): exact estimates
    # 95 % intervals of positive parameters stay positive (log scale) and cover the truth here
    for name, (lo, hi) in doc["uncertainty"]["ci95"].items():
        assert 0 < lo <= doc["parameters"][name] <= hi


def test_two_files_at_one_position_are_refused(reference, tmp_path, capsys):
    paths = _split(reference, tmp_path)
    code = main(["identify", str(MODEL), "--reference", paths[0], paths[0], *QUICK])
    assert code == 1
    assert "position {'z': -0.2} is already given by" in capsys.readouterr().err


def test_wrong_shape_spurious_mode_and_scale_are_flagged(reference, tmp_path, capsys):
    """A reference mode with a wrong shape, a spurious mode, and shapes that are not mass-normalized: each is a
    line of the text output (not only the JSON)."""
    rng = np.random.default_rng(4)
    sets = []
    for k, s in enumerate(reference.sets):
        # the 9 lowest modes (a band), not mass-normalized (as extracted without driving points)
        shapes, freq, damping = s.shapes[:, :9] * 7.0, s.frequency[:9], s.damping[:9]
        if k == 1:
            shapes = shapes.copy()
            shapes[:, 2] = rng.standard_normal(shapes.shape[0])  # a wrong shape
            # a spurious mode between modes 3 and 4, with a shape of its own
            f_new = 0.5 * (freq[2] + freq[3])
            order = np.argsort(np.append(freq, f_new))
            freq = np.append(freq, f_new)[order]
            damping = np.append(damping, 0.02)[order]
            shapes = np.column_stack([shapes, rng.standard_normal(shapes.shape[0])])[:, order]
        sets.append(ModalDataSet(s.position, freq, damping, shapes))
    path = tmp_path / "ref.json"
    write_modal_data(path, ModalData(reference.sensors, tuple(sets)))
    code = main(["identify", str(MODEL), "--reference", str(path), "--validation", "z=-0.2", *QUICK])
    out = capsys.readouterr().out
    assert code in (0, 1)
    warnings = [line for line in out.splitlines() if line.startswith("warning:")]
    flagged = [line for line in warnings if "at {'z': 0.0} pairs with model mode" in line and "MACXP" in line]
    assert len(flagged) >= 2, warnings  # the wrong shape and the spurious mode
    assert any("not mass-normalized" in line for line in warnings), warnings
    assert "modal synthesis over the" in out


def _two_dof_uff(path: Path) -> None:
    """FRFs of a 2-DOF chain from numpy, as a foreign UFF 58: integer nodes, node 2 measured in -x."""
    m = np.diag([2.0, 1.0])
    k = np.array([[3e5, -1e5], [-1e5, 1e5]])
    c = 2e-4 * k
    freq = np.arange(1, 2001) * 0.1
    h = np.stack([np.linalg.inv(k + 2j * np.pi * f * c - (2 * np.pi * f) ** 2 * m) for f in freq], axis=-1)
    sets = []
    for out, sign in ((0, 1), (1, -1)):
        sets.append({"type": 58, "binary": 0, "func_type": 4, "id1": "FRF", "id2": "", "id3": "", "id4": "",
                     "id5": "", "rsp_node": out + 1, "rsp_dir": sign, "ref_node": 1, "ref_dir": 1, "x": freq,
                     "data": sign * h[out, 0], "abscissa_spacing": 0.1, "abscissa_spec_data_type": 18,
                     "ordinate_spec_data_type": 8, "orddenom_spec_data_type": 13})
    pyuff.UFF(str(path)).write_sets(sets, mode="add")


def test_extract_modes_records_position_and_flips_negative_channels(tmp_path, capsys):
    uff = tmp_path / "frf.uff"
    _two_dof_uff(uff)
    (tmp_path / "map.csv").write_text("channel,sensor\n1:+x,a:x\n2:-x,b:x\n")
    code = main(["extract-modes", str(uff), "--band", "20:150", "--sensor-map", str(tmp_path / "map.csv"),
                 "--position", "z=0.135", "-o", str(tmp_path / "m.json")])
    out = capsys.readouterr().out
    assert code == 0
    assert "sign flipped" in out
    assert "2:-x" in out
    data = read_modal_data(tmp_path / "m.json")
    assert data.sensors == ("a:x", "b:x")
    assert data.sets[0].position == {"z": 0.135}
    # the first mode of the chain moves both masses in phase: at the model's +x both components share a sign
    first = data.sets[0].shapes[:, 0]
    first = first / first[np.argmax(np.abs(first))]
    assert first.real.min() > 0, first
    assert replace(data.sets[0]).n_modes == 2
