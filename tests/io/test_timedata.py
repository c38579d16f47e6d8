"""TimeData validation: every bad-data rule names the channel or sample, and clipping detection."""

from __future__ import annotations

import numpy as np
import pytest

from cappe.exceptions import DataError, DataWarning
from cappe.io import TimeData, check_clipping


def _t(n=50, fs=100.0):
    return np.arange(n) / fs


def test_properties_and_selection():
    data = TimeData.from_channels(_t(), {"F": np.ones(50), "a": np.arange(50.0)}, units={"F": "N", "a": "m/s^2"})
    assert (data.fs, data.n_samples, data.n_channels) == (100.0, 50, 2)
    assert data.duration == pytest.approx(0.5, rel=1e-12)
    sub = data.select(["a"])
    assert sub.channels == ("a",)
    assert sub.units == ("m/s^2",)
    np.testing.assert_array_equal(sub.channel("a"), np.arange(50.0))
    assert data.unit("F") == "N"


def test_non_finite_values_name_channel_and_sample():
    a = np.zeros(50)
    a[7] = np.nan
    with pytest.raises(DataError, match=r"channel 'acc' has 1 non-finite value\(s\) \(NaN or Inf\), first at sample 7 \(t = 0.07 s\)"):
        TimeData.from_channels(_t(), {"F": np.zeros(50), "acc": a})
    a[7] = np.inf
    with pytest.raises(DataError, match=r"channel 'acc' has 1 non-finite"):
        TimeData.from_channels(_t(), {"acc": a})


def test_time_stamp_rules():
    t = _t()
    missing = np.delete(t, 20)
    with pytest.raises(DataError, match=r"uniformly spaced \(missing or irregular samples\); the step after sample 19"):
        TimeData.from_channels(missing, {"F": np.zeros(49)})
    backwards = t.copy()
    backwards[10] = backwards[9]
    with pytest.raises(DataError, match=r"must increase strictly; sample 10 .* does not follow sample 9"):
        TimeData.from_channels(backwards, {"F": np.zeros(50)})
    nan_t = t.copy()
    nan_t[3] = np.nan
    with pytest.raises(DataError, match=r"time stamps must be finite; sample 3"):
        TimeData.from_channels(nan_t, {"F": np.zeros(50)})
    with pytest.raises(DataError, match=r"time must be a 1-D array of at least 2 samples"):
        TimeData.from_channels([0.0], {"F": [1.0]})
    # recorder rounding (7 significant digits) is accepted
    TimeData.from_channels(np.round(t + 1000.0, 4), {"F": np.zeros(50)})


def test_length_name_and_unit_rules():
    with pytest.raises(DataError, match=r"channel 'a' has 49 samples but the time vector has 50"):
        TimeData.from_channels(_t(), {"F": np.zeros(50), "a": np.zeros(49)})
    with pytest.raises(DataError, match=r"channels must all have the same length \(50 samples\); different: \{'a': 40\}"):
        TimeData.from_rate(100.0, {"F": np.zeros(50), "a": np.zeros(40)})
    with pytest.raises(DataError, match=r"channel names must be unique; repeated: \['F'\]"):
        TimeData(_t(), np.zeros((2, 50)), ("F", "F"))
    with pytest.raises(DataError, match=r"values must have shape \(n_channels, n_samples\) = \(1, 50\); got \(2, 50\)"):
        TimeData(_t(), np.zeros((2, 50)), ("F",))
    with pytest.raises(DataError, match=r"units must list one unit per channel \(1\); got 2"):
        TimeData(_t(), np.zeros((1, 50)), ("F",), ("N", "m"))
    with pytest.raises(DataError, match=r"argument 'fs' must be > 0 Hz; got -1.0"):
        TimeData.from_rate(-1.0, {"F": np.zeros(5)})
    with pytest.raises(DataError, match=r"argument 'fs' must be finite; got inf"):
        TimeData.from_rate(np.inf, {"F": np.zeros(5)})
    with pytest.raises(DataError, match=r"argument 'fs' must be a real number; got 'fast'"):
        TimeData.from_rate("fast", {"F": np.zeros(5)})
    data = TimeData.from_rate(100.0, {"F": np.zeros(5)})
    with pytest.raises(DataError, match=r"unknown channel 'x'; the data has \['F'\]"):
        data.channel("x")


def test_clipping_detection():
    t = np.arange(2000) / 1000.0
    clean = np.sin(2 * np.pi * 5 * t)
    data = TimeData.from_channels(t, {"ok": clean, "cut": np.clip(1.3 * clean, -1.0, 1.0), "const": np.ones(2000)})
    with pytest.warns(DataWarning, match=r"channel\(s\) look clipped .*'cut' \("):
        found = check_clipping(data)
    assert set(found) == {"cut"}
    # fraction of samples with |1.3 sin| >= 1: 1 - (2/pi) asin(1/1.3), sampled on a 200-sample period
    expected = 1 - 2 / np.pi * np.arcsin(1 / 1.3)
    assert found["cut"] == pytest.approx(expected, abs=0.01)
    assert check_clipping(data.select(["ok", "const"])) == {}
    # signals that sit on their extremes by design are not clipping
    two_level = np.sign(np.sin(2 * np.pi * 7 * t) + 1e-9)
    hammer = np.zeros(2000)
    hammer[100:105] = np.sin(np.pi * np.arange(1, 6) / 6)
    designed = TimeData.from_channels(t, {"prbs_like": two_level, "hammer": hammer})
    assert check_clipping(designed) == {}


def test_written_files_get_the_usual_permissions(tmp_path):
    import os

    from cappe.io import write_json

    path = write_json(tmp_path / "a.json", {"x": 1})
    mask = os.umask(0)
    os.umask(mask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~mask  # not mkstemp's 0600
