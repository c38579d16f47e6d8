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


def _daq_csv(path, fs, n, digits, jitter=0.0):
    """A CSV as LabVIEW / DAQ software writes it: the time column with ``digits`` significant digits (``%.{d}g``,
    written here from the exact grid k / fs, not by cappe), one sine channel."""
    rng = np.random.default_rng(0)
    t = np.arange(n) / fs + jitter * rng.standard_normal(n) / fs
    rows = "\n".join(f"{v:.{digits}g},{np.sin(2 * np.pi * 50.0 * v):.6g}" for v in t)
    path.write_text("time,acc\n" + rows + "\n")
    return path


@pytest.mark.parametrize(("fs", "n", "digits"), [(2048.0, 8192, 7), (51200.0, 60000, 7), (51200.0, 60000, 10),
                                                 (2048.0, 8192, 10)])
def test_daq_time_columns_rounded_to_their_digits_are_uniform(tmp_path, fs, n, digits):
    # 7 digits at 51.2 kHz: t = 1.171855 s is written to 1e-6 s, 5 % of the step; such files were rejected as
    # "not uniformly spaced" (the tolerance was 1e-6 of dt); now the rounding of t sets it, and no warning is due
    import warnings

    from cappe.io import read_time_data

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        data = read_time_data(_daq_csv(tmp_path / "daq.csv", fs, n, digits))
    assert data.fs == pytest.approx(fs, rel=1e-6)
    assert data.n_samples == n


def test_real_jitter_warns_and_a_dropped_sample_stays_an_error(tmp_path):
    from cappe.io import read_time_data

    # 1 % rms timing jitter at 2048 Hz (10 digits: rounding is 1e-9 s, jitter ~5e-6 s): a warning naming the sample
    with pytest.warns(DataWarning, match=r"time stamps jitter: sample \d+ .* from the uniform grid, more than the "
                                         r"rounding of its 10 significant digits; .* uniformly sampled at 2048 Hz"):
        read_time_data(_daq_csv(tmp_path / "jitter.csv", 2048.0, 4096, 10, jitter=0.01))
    t = np.delete(np.round(np.arange(4096) / 2048.0, 6), 1000)
    with pytest.raises(DataError, match=r"uniformly spaced \(missing or irregular samples\); the step after sample 999"):
        TimeData.from_channels(t, {"a": np.zeros(t.size)})
