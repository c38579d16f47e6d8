"""cappe.modal/1 files: round trip and validation messages."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cappe.exceptions import DataError
from cappe.io import ModalData, ModalDataSet, modal_data_from_mapping, read_modal_data, write_modal_data


def test_round_trip_keeps_complex_shapes(tmp_path):
    shapes = np.array([[1.0 + 0.1j, 0.2], [-0.5j, 1.0]])
    data = ModalData(("a:x", "b:y"), (ModalDataSet({"z": 0.1}, np.array([10.0, 20.0]), np.array([0.01, 0.02]),
                                                   shapes),))
    path = tmp_path / "modes.json"
    write_modal_data(path, data)
    back = read_modal_data(path)
    assert back.sensors == data.sensors
    assert back.sets[0].position == {"z": 0.1}
    np.testing.assert_array_equal(back.sets[0].shapes, shapes)
    np.testing.assert_array_equal(back.sets[0].frequency, [10.0, 20.0])
    # poles follow the damping convention -zeta omega + i omega sqrt(1 - zeta^2)
    w = 2 * np.pi * 10.0
    assert back.sets[0].poles[0] == pytest.approx(-0.01 * w + 1j * w * np.sqrt(1 - 0.01**2), rel=1e-15)


def good():
    return {"format": "cappe.modal/1", "sensors": ["a:x", "b:x"],
            "sets": [{"position": {"z": 0.1}, "frequency": [10.0], "damping": [0.01], "shape_re": [[1.0, 0.5]]}]}


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda d: d.update(format="cappe.modal/2"), r"modal data must have \"format\": \"cappe.modal/1\"; got 'cappe.modal/2' \(f.json, format\)"),
        (lambda d: d.update(sensors=[]), r"sensors must be a non-empty list"),
        (lambda d: d.update(sensors=["a:x", "a:x"]), r"sensors must be unique"),
        (lambda d: d.update(sets=[]), r"sets must be a non-empty list"),
        (lambda d: d["sets"][0].update(frequency=[-1.0]), r"sets\[0\].frequency must be > 0 Hz"),
        (lambda d: d["sets"][0].update(damping=[1.5]), r"sets\[0\].damping ratios must lie in \[0, 1\)"),
        (lambda d: d["sets"][0].update(damping=[0.1, 0.2]), r"sets\[0\].damping must be 1 numbers; got shape \(2,\)"),
        (lambda d: d["sets"][0].update(shape_re=[[1.0]]), r"sets\[0\].shape_re\[0\] must be 2 numbers"),
        (lambda d: d["sets"][0].update(shape_re=[[1.0, "x"]]), r"sets\[0\].shape_re\[0\] must be a list of numbers"),
        (lambda d: d["sets"][0].update(shape_im=[]), r"sets\[0\].shape_im must list one shape per mode \(1\)"),
        (lambda d: d["sets"][0].update(frequency=[float("nan")]), r"sets\[0\].frequency contains NaN or Inf"),
        (lambda d: d["sets"][0].update(position=[1]), r"sets\[0\].position must be a mapping"),
    ],
)
def test_validation_names_the_entry(change, message):
    data = good()
    change(data)
    with pytest.raises(DataError, match=message):
        modal_data_from_mapping(data, "f.json")


def test_read_errors(tmp_path):
    with pytest.raises(DataError, match="cannot read modal data"):
        read_modal_data(tmp_path / "none.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{")
    with pytest.raises(DataError, match=r"is not valid JSON: .* \(line 1\)"):
        read_modal_data(bad)
    bad.write_text(json.dumps(good()))
    assert read_modal_data(bad).sets[0].n_modes == 1
