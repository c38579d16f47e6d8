"""Sensor maps (``channel,sensor`` CSV): reading, its errors, and the sign of channels measured in a negative
direction, on FRFs and modal data."""

from __future__ import annotations

import numpy as np
import pytest

from cappe.exceptions import DataError
from cappe.io.sensor_map import apply_sensor_map, channel_sign, map_channels, map_modal_data, read_sensor_map
from cappe.systems.frf import FRFData
from cappe.systems.modal import ModalData, ModalDataSet


def test_read_and_map(tmp_path):
    path = tmp_path / "map.csv"
    path.write_text("channel,sensor\n5:-z,table_fl:z\n6:+x,bed:x\n\n7:y,motor:-y\n")
    mapping = read_sensor_map(path)
    assert mapping == {"5:-z": "table_fl:z", "6:+x": "bed:x", "7:y": "motor:-y"}
    # 5:z and 5:+z are one channel; the sensor column's sign, when written, states the measured direction
    assert map_channels(["5:-z", "6:x", "7:+y", "8:z"], mapping) == [
        ("table_fl:z", -1.0), ("bed:x", 1.0), ("motor:y", -1.0), (None, 1.0)]
    assert channel_sign("12:-rz") == ("12:rz", -1.0)


@pytest.mark.parametrize(("text", "message"), [
    ("chan,sens\n1:x,a:x\n", r"map\.csv must start with the header 'channel,sensor'.*line 1"),
    ("channel,sensor\n1:x\n", r"map\.csv, line 2: a row must be CHANNEL,SENSOR"),
    ("channel,sensor\n1:x,a:x\n1:x,b:x\n", r"map\.csv, line 3: channel '1:x' is mapped twice"),
    ("channel,sensor\n1:x,a:x\n2:-x,a:x\n", r"map\.csv, line 3: sensor 'a:x' is already measured by line 2"),
    ("channel,sensor\n", r"map\.csv has no rows"),
])
def test_read_errors(tmp_path, text, message):
    path = tmp_path / "map.csv"
    path.write_text(text)
    with pytest.raises(DataError, match=message):
        read_sensor_map(path)


def test_missing_file(tmp_path):
    with pytest.raises(DataError, match=r"cannot read sensor map .*nope\.csv"):
        read_sensor_map(tmp_path / "nope.csv")


def test_frf_sign_flipped_and_unmapped_left_out():
    h = np.arange(1, 13, dtype=float).reshape(3, 2, 2) * (1 + 1j)
    frf = FRFData(np.array([1.0, 2.0]), h, ("1:+x", "2:-y"), ("1:+x", "2:-y", "3:+z"))
    mapped, notes = apply_sensor_map(frf, {"1:x": "a:x", "2:-y": "b:y"}, "map.csv")
    assert mapped.output_names == ("a:x", "b:y")
    assert mapped.input_names == ("a:x", "b:y")
    # value at the model's positive direction = -(measured in the negative direction), for outputs and inputs
    np.testing.assert_array_equal(mapped.H[0, 0], h[0, 0])
    np.testing.assert_array_equal(mapped.H[1, 0], -h[1, 0])
    np.testing.assert_array_equal(mapped.H[0, 1], -h[0, 1])
    np.testing.assert_array_equal(mapped.H[1, 1], h[1, 1])
    assert any("sign flipped" in n for n in notes)
    assert any("warning: 1 output channel(s) not in the sensor map (map.csv) left out: 3:+z" in n for n in notes)
    with pytest.raises(DataError, match=r"sensor map \(m\.csv\) names none of the FRF outputs"):
        apply_sensor_map(frf, {"9:x": "a:x"}, "m.csv")


def test_without_a_map_a_negative_direction_is_never_kept():
    frf = FRFData(np.array([1.0, 2.0]), np.ones((2, 1, 2), complex), ("1:x",), ("5:-z", "6:+x"))
    mapped, notes = apply_sensor_map(frf, None)
    assert mapped.output_names == ("5:z", "6:x")
    np.testing.assert_array_equal(mapped.H[0, 0], -np.ones(2))
    assert notes


def test_modal_data():
    s = ModalDataSet({"z": 0.1}, np.array([10.0]), np.array([0.01]), np.array([[1.0 + 0j], [2.0 + 0j]]))
    data, notes = map_modal_data(ModalData(("5:-z", "6:x"), (s,)), {"5:-z": "t:z", "6:+x": "b:x"})
    assert data.sensors == ("t:z", "b:x")
    np.testing.assert_array_equal(data.sets[0].shapes[:, 0], [-1.0, 2.0])
    assert notes


def test_modal_data_with_two_sensors_mapped_to_one_channel_is_refused():
    # modal shapes used to keep both rows under one name, which a later pairing then read as one sensor
    s = ModalDataSet({"z": 0.1}, np.array([10.0]), np.array([0.01]), np.array([[1.0 + 0j], [2.0 + 0j]]))
    with pytest.raises(DataError, match=r"sensor map \(m\.csv\): \['t:z'\] are each given by two sensors"):
        map_modal_data(ModalData(("5:z", "6:z"), (s,)), {"5:z": "t:z", "6:z": "t:z"}, "m.csv")
