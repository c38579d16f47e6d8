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
        (lambda d: d["sets"][0].update(damping=[0.1, 0.2]), r"sets\[0\].damping must list 1 number\(s\); got 2 \(f.json, sets\[0\].damping\)"),
        (lambda d: d["sets"][0].update(shape_re=[[1.0]]), r"sets\[0\].shape_re\[0\] must list 2 number\(s\); got 1"),
        (lambda d: d["sets"][0].update(shape_re=[[1.0, "x"]]), r"sets\[0\].shape_re\[0\]\[1\] must be a finite number; got 'x' \(f.json, sets\[0\].shape_re\[0\]\[1\]\)"),
        (lambda d: d["sets"][0].update(shape_im=[]), r"sets\[0\].shape_im must list one shape per mode \(1\)"),
        (lambda d: d["sets"][0].update(frequency=[float("nan")]), r"sets\[0\].frequency\[0\] must be a finite number; got nan"),
        (lambda d: d["sets"][0].update(frequency=["10"]), r"sets\[0\].frequency\[0\] must be a finite number; got '10'"),
        (lambda d: d["sets"][0].update(frequency=[[10.0]]), r"sets\[0\].frequency\[0\] must be a finite number; got \[10.0\]"),
        (lambda d: d["sets"][0].update(frequency={"a": 10.0}), r"sets\[0\].frequency must be a list of numbers; got dict \(f.json, sets\[0\].frequency\)"),
        (lambda d: d["sets"][0].update(frequency=10.0), r"sets\[0\].frequency must be a list of numbers; got float"),
        (lambda d: d["sets"][0].update(frequency="10"), r"sets\[0\].frequency must be a list of numbers; got str"),
        (lambda d: d["sets"][0].update(frequency=[]), r"sets\[0\].frequency must list at least one mode"),
        (lambda d: d["sets"][0].pop("frequency"), r"sets\[0\].frequency is missing \(f.json, sets\[0\]\)"),
        (lambda d: d["sets"][0].pop("damping"), r"sets\[0\].damping is missing"),
        (lambda d: d["sets"][0].update(damping=[True]), r"sets\[0\].damping\[0\] must be a finite number; got True"),
        (lambda d: d["sets"][0].update(position={"z": "0.1"}), r"sets\[0\].position.z must be a finite number; got '0.1'"),
        (lambda d: d["sets"][0].update(position={"z": None}), r"sets\[0\].position.z must be a finite number; got None"),
        (lambda d: d["sets"][0].update(shape_re={"a": 1}), r"sets\[0\].shape_re must list one shape per mode \(1\)"),
        (lambda d: d["sets"][0].update(shape_re=["ab"]), r"sets\[0\].shape_re\[0\] must be a list of numbers; got str"),
        (lambda d: d.update(format="x" * 10_000), r"got 'x+\.\.\. \(f.json, format\)$"),
        (lambda d: d.update(sensors=["a:x", 3]), r"sensors must be a non-empty list of channel labels"),
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
    with pytest.raises(DataError, match=r"modal data file .*bad\.json is not valid JSON: Expecting property name enclosed in double quotes at column 2$"):
        read_modal_data(bad)
    bad.write_text(json.dumps(good()))
    assert read_modal_data(bad).sets[0].n_modes == 1


BIG = "1" + "0" * 400  # 10**400: Python reads the int, float() overflows
HUGE = "1" + "0" * 5000  # more digits than int(str) accepts (sys.get_int_max_str_digits() is 4300)


@pytest.mark.parametrize(("content", "pattern"), [
    (json.dumps(good()).replace("10.0", BIG).encode(),
     r"sets\[0\].frequency\[0\] must be a finite number; got 100000\.\.\.000 \(401 digits\) \(.*m\.json, sets\[0\].frequency\[0\]\)"),
    (json.dumps(good()).replace("10.0", HUGE).encode(), r"sets\[0\].frequency\[0\] must be a finite number; got 100000\.\.\.000 \(5001 digits\)"),
    (json.dumps(good()).replace("0.5", "-" + BIG).encode(), r"sets\[0\].shape_re\[0\]\[1\] must be a finite number; got -100000\.\.\.000"),
    (json.dumps(good()).replace("0.1", HUGE).encode(), r"sets\[0\].position.z must be a finite number; got 100000\.\.\.000 \(5001 digits\)"),
    (json.dumps(good()).replace("0.01", "Infinity").encode(), r"sets\[0\].damping\[0\] must be a finite number; got inf"),
    (json.dumps(good()).replace("a:x", "\\u00e9").encode().replace(b"\\u00e9", b"\xe9"),
     r"modal data file .*m\.json is not a UTF-8 text file \(JSON expected\): invalid continuation byte at byte \d+"),
    (b"[" * 100_000, r"modal data file .*m\.json nests arrays or objects too deeply to be read"),
    (b'{"sets": ' + b"[" * 3000 + b"]" * 3000 + b"}", r"modal data file .*m\.json nests arrays or objects too deeply to be read"),
    (b"", r"modal data file .*m\.json is empty; expected JSON"),
    (b"[]", r"modal data must have \"format\": \"cappe.modal/1\"; got 'list'"),
])
def test_bad_modal_files_name_the_file_and_entry(tmp_path, content, pattern):
    path = tmp_path / "m.json"
    path.write_bytes(content)
    with pytest.raises(DataError, match=pattern) as info:
        read_modal_data(path)
    assert "\n" not in str(info.value)


def test_modal_file_with_byte_order_mark(tmp_path):
    path = tmp_path / "m.json"
    path.write_bytes(b"\xef\xbb\xbf" + json.dumps(good()).encode())
    assert read_modal_data(path).sensors == ("a:x", "b:x")


def test_standard_deviations_round_trip(tmp_path):
    # the optional per-mode std of extract-modes: frequency_std, damping_std (per mode) and shape_std (per mode,
    # per sensor, laid out like shape_re)
    doc = good()
    doc["sets"][0]["frequency_std"] = [0.02]
    doc["sets"][0]["damping_std"] = [0.001]
    doc["sets"][0]["shape_std"] = [[0.01, 0.03]]
    data = modal_data_from_mapping(doc)
    s = data.sets[0]
    np.testing.assert_array_equal(s.frequency_std, [0.02])
    np.testing.assert_array_equal(s.shape_std, [[0.01], [0.03]])
    write_modal_data(tmp_path / "m.json", data)
    back = read_modal_data(tmp_path / "m.json").sets[0]
    np.testing.assert_array_equal(back.damping_std, [0.001])
    np.testing.assert_array_equal(back.shape_std, s.shape_std)
    assert modal_data_from_mapping(good()).sets[0].frequency_std is None  # absent: unknown, not zero


@pytest.mark.parametrize(("key", "value", "pattern"), [
    ("frequency_std", [-0.1], r"sets\[0\].frequency_std must be >= 0 \(standard deviations\) \(m\.json, sets\[0\].frequency_std\)"),
    ("damping_std", [0.1, 0.2], r"sets\[0\].damping_std must list 1 number\(s\); got 2"),
    ("shape_std", [[0.1]], r"sets\[0\].shape_std\[0\] must list 2 number\(s\); got 1"),
    ("shape_std", "x", r"sets\[0\].shape_std must list one row per mode \(1\)"),
])
def test_bad_standard_deviations(key, value, pattern):
    doc = good()
    doc["sets"][0][key] = value
    with pytest.raises(DataError, match=pattern):
        modal_data_from_mapping(doc, "m.json")
