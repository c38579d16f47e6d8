"""Measurement files: CSV / npz / UFF round trips, format dispatch, error messages and channel matching.

References: numpy's own CSV and npz readers (np.loadtxt, np.load) and the csv module read cappe's files
independently; round trips are exact for CSV (shortest repr of every double) and npz, and within E20.12
(12 significant digits, relative rounding <= 5e-12) for ASCII UFF.
"""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cappe.exceptions import DataError
from cappe.io import measurements
from cappe.io.measurements import (
    match_channels,
    read_frf,
    read_measurements,
    read_time_data,
    write_frf,
    write_time_data,
)
from cappe.io.timedata import TimeData
from cappe.systems.frf import FRFData

ASCII_RTOL = 5e-12  # ASCII UFF 58 ordinates: E20.12


def _time_data(rng, n=40, fs=2560.0):
    units = {"F1": "N", "acc, x": "m/s^2", 'say "hi"': "", "d [m]": "", "v [mm/s]": "m/s"}
    values = {name: rng.standard_normal(n) * 1e-3 for name in units}
    return TimeData.from_channels(0.125 + np.arange(n) / fs, values, units=units)


def _frf(rng, with_extras=True):
    freq = np.linspace(0.0, 400.0, 33)
    shape = (2, 3, freq.size)
    H = rng.standard_normal(shape) + 1j * rng.standard_normal(shape)
    return FRFData(
        freq=freq,
        H=H,
        input_names=("F1", "ham/mer", '"quoted"'),
        output_names=("d1", "tool:x"),
        output_quantities=("displacement", "acceleration") if with_extras else (),
        coherence=rng.uniform(0, 1, shape) if with_extras else None,
        window_decay=0.0625 if with_extras else None,
    )


def _assert_same_frf(back, frf, rtol=0.0):
    assert (back.output_names, back.input_names) == (frf.output_names, frf.input_names)
    assert back.output_quantities == frf.output_quantities
    assert back.window_decay == frf.window_decay
    np.testing.assert_array_equal(back.freq, frf.freq)
    np.testing.assert_allclose(back.H.real, frf.H.real, rtol=rtol, atol=0)
    np.testing.assert_allclose(back.H.imag, frf.H.imag, rtol=rtol, atol=0)
    if frf.coherence is None:
        assert back.coherence is None
    else:
        np.testing.assert_allclose(back.coherence, frf.coherence, rtol=rtol, atol=0)


# ----------------------------------------------------------------------------------------------- round trips


@pytest.mark.parametrize(("name", "fmt", "rtol"), [
    ("run.csv", None, 0.0), ("run.npz", None, 0.0), ("run.uff", None, ASCII_RTOL), ("run.unv", None, ASCII_RTOL),
    ("run.bin", "uff-binary", 0.0), ("run.txt", "csv", 0.0),
])
def test_time_data_round_trips(tmp_path, name, fmt, rtol):
    data = _time_data(np.random.default_rng(1))
    back = read_time_data(write_time_data(tmp_path / name, data, format=fmt), format=fmt)
    assert back.channels == data.channels
    assert back.units == data.units
    np.testing.assert_array_equal(back.time, data.time)
    np.testing.assert_allclose(back.values, data.values, rtol=rtol, atol=0)
    assert isinstance(read_measurements(tmp_path / name, format=fmt), TimeData)


@pytest.mark.parametrize(("name", "fmt", "rtol"), [
    ("h.csv", None, 0.0), ("h.npz", None, 0.0), ("h.uff", None, ASCII_RTOL), ("h.58b", "uff-binary", 0.0),
])
@pytest.mark.parametrize("with_extras", [True, False])
def test_frf_round_trips(tmp_path, name, fmt, rtol, with_extras):
    frf = _frf(np.random.default_rng(2), with_extras)
    path = write_frf(tmp_path / name, frf, format=fmt)
    _assert_same_frf(read_frf(path, format=fmt), frf, rtol)
    _assert_same_frf(read_measurements(path, format=fmt), frf, rtol)


def test_time_csv_layout_is_readable_by_numpy(tmp_path):
    data = _time_data(np.random.default_rng(3))
    path = write_time_data(tmp_path / "run.csv", data)
    with open(path, newline="") as fh:
        header = next(csv.reader(fh))
    assert header == ["time", "F1 [N]", "acc, x [m/s^2]", 'say "hi"', "d [m] []", "v [mm/s] [m/s]"]
    table = np.loadtxt(path, delimiter=",", skiprows=1, quotechar='"')
    np.testing.assert_array_equal(table[:, 0], data.time)  # shortest repr: exact
    np.testing.assert_array_equal(table[:, 1:].T, data.values)


def test_frf_csv_layout_is_readable_by_numpy(tmp_path):
    frf = _frf(np.random.default_rng(4))
    path = write_frf(tmp_path / "h.csv", frf)
    lines = path.read_text().splitlines()
    assert lines[:2] == ["# window_decay: 0.0625", '# output_quantities: ["displacement", "acceleration"]']
    header = next(csv.reader([lines[2]]))
    assert header[:7] == [
        "frequency", "d1/F1 re", "d1/F1 im", 'd1/"ham/mer" re', 'd1/"ham/mer" im', 'd1/"\\"quoted\\"" re',
        'd1/"\\"quoted\\"" im',
    ]
    assert header[13:15] == ["d1/F1 coh", 'd1/"ham/mer" coh']
    table = np.loadtxt(path, delimiter=",", skiprows=3, comments=None)
    H = table[:, 1:13:2] + 1j * table[:, 2:13:2]
    np.testing.assert_array_equal(H.T.reshape(2, 3, -1), frf.H)
    np.testing.assert_array_equal(table[:, 13:].T.reshape(2, 3, -1), frf.coherence)


def test_npz_layout_is_readable_by_numpy(tmp_path):
    data = _time_data(np.random.default_rng(5))
    with np.load(write_time_data(tmp_path / "t.npz", data), allow_pickle=False) as z:
        assert str(z["format"]) == "cappe.timedata/1"
        np.testing.assert_array_equal(z["values"], data.values)
        assert tuple(z["channels"]) == data.channels
    frf = _frf(np.random.default_rng(6), with_extras=False)
    with np.load(write_frf(tmp_path / "h.npz", frf), allow_pickle=False) as z:
        assert str(z["format"]) == "cappe.frf/1"
        assert np.isnan(z["window_decay"])
        assert "coherence" not in z.files
        np.testing.assert_array_equal(z["H"], frf.H)


def test_foreign_csv_headers_are_accepted(tmp_path):
    path = tmp_path / "logger.csv"
    path.write_text("# exported by a logger\n\nTime [s], a ,b [g]\n0.0,1,2\n0.001,3,4\n")
    data = read_time_data(path)
    assert data.channels == (" a ", "b")  # cells are names verbatim; only a trailing ' [unit]' is split off
    assert data.units == ("", "g")
    np.testing.assert_array_equal(data.values, [[1.0, 3.0], [2.0, 4.0]])
    path.write_text("freq [Hz],out/in re,out/in im\n1,2,3\n")
    frf = read_measurements(path)
    assert isinstance(frf, FRFData)
    assert frf.H[0, 0, 0] == 2 + 3j


@settings(max_examples=30, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])  # too_slow: wall clock
@given(
    names=st.lists(st.text(alphabet=st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00\r\n"),
                           min_size=1, max_size=12), min_size=1, max_size=4, unique=True),
    unit=st.sampled_from(["", "N", "m/s^2", "g"]),
    scale=st.floats(min_value=-1e300, max_value=1e300, allow_nan=False),
)
def test_property_csv_and_npz_round_trips_are_exact(tmp_path, names, unit, scale):
    """Any names (commas, quotes, brackets, unicode) and values come back exactly from CSV and npz."""
    values = {name: scale * np.array([1.0, -1 / 3, 1e-300]) * (k + 1) for k, name in enumerate(names)}
    data = TimeData.from_channels([0.0, 0.1, 0.2], values, units=dict.fromkeys(names, unit))
    for suffix in ("csv", "npz"):
        back = read_time_data(write_time_data(tmp_path / f"p.{suffix}", data))
        assert back.channels == data.channels
        # all-empty units mean "unknown"; CSV cannot tell ('', '') from (), npz keeps them
        assert back.units == (data.units if unit or suffix == "npz" else ())
        np.testing.assert_array_equal(back.values, data.values)


# ----------------------------------------------------------------------------------------------- dispatch


def test_format_selection_errors(tmp_path):
    data = TimeData.from_rate(10.0, {"a": [1.0, 2.0]})
    with pytest.raises(DataError, match=r"cannot tell the format of .*run\.dat from its extension '\.dat'; use \.uff/\.unv \(UFF 58\), \.csv, \.npz or \.lvm \(LabVIEW, read only\)"):
        write_time_data(tmp_path / "run.dat", data)
    with pytest.raises(DataError, match=r"format must be one of \['uff', 'uff-binary', 'csv', 'npz', 'lvm'\] or None; got 'xlsx'"):
        read_frf(tmp_path / "run.csv", format="xlsx")
    for name in ("run.csv", "run.npz", "run.uff"):
        with pytest.raises(DataError, match=r"data must be a TimeData; got dict"):
            write_time_data(tmp_path / name, {"a": [1.0]})  # type: ignore[arg-type]
        with pytest.raises(DataError, match=r"frf must be an FRFData; got dict"):
            write_frf(tmp_path / name, {"H": [1.0]})  # type: ignore[arg-type]
    assert list(tmp_path.iterdir()) == []


def test_every_format_is_written_with_the_usual_permissions(tmp_path):
    """Atomic writes go through mkstemp (mode 0600); the finished file must get the mode a plain write gives."""
    data = TimeData.from_rate(10.0, {"a": [1.0, 2.0]})
    plain = tmp_path / "plain.txt"
    plain.write_text("x")
    expected = plain.stat().st_mode & 0o777
    for name, fmt in (("t.csv", None), ("t.npz", None), ("t.uff", None), ("t.bin", "uff-binary")):
        assert write_time_data(tmp_path / name, data, format=fmt).stat().st_mode & 0o777 == expected, name


def test_read_measurements_dispatch_errors(tmp_path):
    data = TimeData.from_rate(10.0, {"a": [1.0, 2.0]})
    frf = FRFData(np.array([1.0, 2.0]), np.ones((1, 1, 2), complex), ("F",), ("a",))
    both = tmp_path / "both.uff"
    write_time_data(both, data)
    mixed = tmp_path / "mixed.uff"
    write_frf(mixed, frf)
    mixed.write_bytes(mixed.read_bytes() + both.read_bytes())
    with pytest.raises(DataError, match=r"mixed\.uff holds both time data \(UFF 58 function type 1\) and FRFs \(type 4\)"):
        read_measurements(mixed)
    coh_only = tmp_path / "coh.uff"
    write_frf(coh_only, FRFData(frf.freq, frf.H, ("F",), ("a",), coherence=np.ones((1, 1, 2))))
    text = coh_only.read_text()
    coh_only.write_text(text[text.index("    -1\n    58", 10):])  # drop the FRF dataset, keep the coherence
    with pytest.raises(DataError, match=r"coh\.uff holds UFF 58 function type\(s\) 6 \(coherence without FRFs\), none of them time data or FRFs; supported: UFF 58 function type 1"):
        read_measurements(coh_only)
    odd = tmp_path / "odd.csv"
    odd.write_text("sample,a\n1,2\n")
    with pytest.raises(DataError, match=r"odd\.csv, line 1: the first column must be 'time' \(time data\) or 'frequency' \(FRFs\); got 'sample'"):
        read_measurements(odd)
    arrays = tmp_path / "arrays.npz"
    np.savez(arrays, x=np.ones(2))
    with pytest.raises(DataError, match=r"arrays\.npz holds arrays \['x'\]; expected time and values \(time data\) or freq and H \(FRFs\)"):
        read_measurements(arrays)


# ------------------------------------------------------------------------------------------------ CSV errors


@pytest.mark.parametrize(("text", "pattern"), [
    ("", r"bad\.csv is empty; expected a CSV header row"),
    ("# only a comment\n", r"bad\.csv holds only comment lines"),
    ("time,a\n", r"bad\.csv has a header row \(line 1\) but no data rows"),
    ("time,a\n0,1\n0.1,x1\n", r"bad\.csv, line 3, column 2 \('a'\): 'x1' is not a number"),
    ("# c\ntime,a,b\n0,1,2\n0.1,2\n", r"bad\.csv, line 4: 2 cell\(s\); the header \(line 2\) has 3"),
    ("time,a\n0,1\n0,2\n", r"bad\.csv: time stamps must increase strictly; sample 1"),
    ("time,a\n0,1\n1,nan\n", r"bad\.csv, line 3, column 2 \('a'\): 'nan' is not a finite number"),
    ("time,a\n0,1\n1,1e400\n", r"bad\.csv, line 3, column 2 \('a'\): '1e400' is not a finite number"),
    ("time,a\n0,1\n1," + "9" * 5000 + "\n", r"bad\.csv, line 3, column 2 \('a'\): '9+\.\.\. is not a finite number$"),
    ("time,a\n0,1\n1,x" + "9" * 5000 + "\n", r"bad\.csv, line 3, column 2 \('a'\): 'x9+\.\.\. is not a number$"),
    ("time,a,a\n0,1,2\n1,2,3\n", r"bad\.csv: channel names must be unique; repeated: \['a'\]"),
    ("t,a\n0,1\n", r"bad\.csv, line 1: the first column of time data must be 'time' or 'time \[s\]'; got 't'"),
])
def test_time_csv_errors(tmp_path, text, pattern):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(DataError, match=pattern):
        read_time_data(path)


@pytest.mark.parametrize(("text", "pattern"), [
    ("frequency,a/F re\n1,2\n", r"line 1: column 2 'a/F re' has no matching 'a/F im' column \(complex FRFs need re/im column pairs\)"),
    ("frequency,a/F im\n1,2\n", r"line 1: column 2 'a/F im' has no matching 'a/F re' column"),
    ("frequency,a/F re,a/F im,b/F re,b/F im,a/F coh\n1,2,3,4,5,6\n", r"bad\.csv: coherence columns are given for some FRFs but not for \['b/F'\]"),
    ("frequency,a/F coh\n1,2\n", r"line 1: coherence column 'a/F coh' has no FRF columns 'a/F re/im'"),
    ("frequency,a/F re,a/F im,b/G re,b/G im\n1,2,3,4,5\n", r"bad\.csv: the FRF columns lack the pair\(s\) \['a/G', 'b/F'\] to complete the 2 x 2 grid"),
    ("frequency,aF re\n1,2\n", r"line 1, column 2: 'aF re' must read '<output>/<input> re\|im\|coh'"),
    ("frequency,a/F real\n1,2\n", r"column 2: 'a/F real' must read"),
    ("frequency,a/F re,a/F re\n1,2,3\n", r"line 1: column 3 repeats 'a/F re' \(column 2\)"),
    ("frequency,a/F re,a/F im\n1,2,inf\n", r"bad\.csv, line 2, column 3 \('a/F im'\): 'inf' is not a finite number"),
    ("# window_decay: fast\nfrequency,a/F re,a/F im\n1,2,3\n", r"bad\.csv, line 1: the value of comment 'window_decay' is not valid JSON: Expecting value at column 1$"),
    ("# window_decay: \"1\"\nfrequency,a/F re,a/F im\n1,2,3\n", r"line 1: window_decay must be a finite number \(s\) or null; got '1'"),
    ("# window_decay: -2\nfrequency,a/F re,a/F im\n1,2,3\n", r"bad\.csv: FRF window_decay must be None or a time constant > 0 in s; got -2.0"),
    ("# window_decay: " + "[" * 100_000 + "\nfrequency,a/F re,a/F im\n1,2,3\n", r"bad\.csv, line 1: the value of comment 'window_decay' nests arrays or objects too deeply to be read"),
    ("# window_decay: 1" + "0" * 400 + "\nfrequency,a/F re,a/F im\n1,2,3\n", r"bad\.csv, line 1: window_decay must be a finite number \(s\) or null; got 100000\.\.\.000 \(401 digits\)"),
    ("# window_decay: 1" + "0" * 5000 + "\nfrequency,a/F re,a/F im\n1,2,3\n", r"bad\.csv, line 1: window_decay must be a finite number \(s\) or null; got 100000\.\.\.000 \(5001 digits\)"),
    ("# window_decay: NaN\nfrequency,a/F re,a/F im\n1,2,3\n", r"bad\.csv, line 1: window_decay must be a finite number \(s\) or null; got nan"),
    ("# window_decay:\nfrequency,a/F re,a/F im\n1,2,3\n", r"bad\.csv, line 1: the value of comment 'window_decay' is empty; expected JSON"),
    ("# output_quantities: [\"velocity\"\nfrequency,a/F re,a/F im\n1,2,3\n", r"bad\.csv, line 1: the value of comment 'output_quantities' is not valid JSON"),
    ("# output_quantities: [\"velocity\"]\nfrequency,a/F re,a/F im,b/F re,b/F im\n1,2,3,4,5\n", r"line 1: output_quantities must list 2 strings \(one per output\); got \['velocity'\]"),
    ("frequency,\"\"\"a/F re\"\n1,2\n", r"column 2: '\"a/F re' must read"),
    ("time,a\n0,1\n", r"bad\.csv, line 1: the first column of FRF data must be 'frequency' or 'frequency \[Hz\]'; got 'time'"),
])
def test_frf_csv_errors(tmp_path, text, pattern):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(DataError, match=pattern):
        read_frf(path)


def test_file_level_errors(tmp_path):
    with pytest.raises(DataError, match=r"cannot read .*gone\.csv: no such file"):
        read_time_data(tmp_path / "gone.csv")
    with pytest.raises(DataError, match=r"cannot read .*gone\.npz: no such file"):
        read_frf(tmp_path / "gone.npz")
    binary = tmp_path / "bin.csv"
    binary.write_bytes(b"time,a\n\xff\xfe\n")
    with pytest.raises(DataError, match=r"bin\.csv is not a UTF-8 text file \(CSV expected\): invalid start byte at byte 7"):
        read_time_data(binary)
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(b"PK not really")
    with pytest.raises(DataError, match=r"corrupt\.npz is not a readable \.npz archive"):
        read_time_data(corrupt)
    partial = tmp_path / "partial.npz"
    np.savez(partial, time=np.arange(3.0), values=np.ones((1, 3)))
    with pytest.raises(DataError, match=r"partial\.npz lacks the array 'channels' of time data; it holds \['time', 'values'\]"):
        read_time_data(partial)
    wrong = tmp_path / "wrong.npz"
    np.savez(wrong, format=np.array("cappe.timedata/1"), freq=np.ones(2), H=np.ones((1, 1, 2)))
    with pytest.raises(DataError, match=r"wrong\.npz has format 'cappe\.timedata/1'; expected 'cappe\.frf/1'"):
        read_frf(wrong)
    numbers = tmp_path / "numbers.npz"
    np.savez(numbers, time=np.arange(3.0), values=np.ones((1, 3)), channels=np.array([1]))
    with pytest.raises(DataError, match=r"array 'channels' in .*numbers\.npz must be a 1-D array of strings; got dtype int64"):
        read_time_data(numbers)
    shape = tmp_path / "shape.npz"
    np.savez(shape, time=np.arange(3.0), values=np.ones((2, 3)), channels=np.array(["a"]))
    with pytest.raises(DataError, match=r"shape\.npz: values must have shape \(n_channels, n_samples\) = \(1, 3\); got \(2, 3\)"):
        read_time_data(shape)
    frf_shape = tmp_path / "hshape.npz"
    np.savez(frf_shape, freq=np.ones(2), H=np.ones((1, 1, 3)), input_names=np.array(["F"]), output_names=np.array(["a"]))
    with pytest.raises(DataError, match=r"hshape\.npz: FRF H must have shape \(n_out, n_in, n_freq\) = \(1, 1, 2\); got \(1, 1, 3\)"):
        read_frf(frf_shape)


def test_units_with_brackets_cannot_go_to_csv(tmp_path):
    path = tmp_path / "run.csv"
    path.write_text("keep me\n")
    data = TimeData.from_channels([0.0, 1.0], {"a": [1.0, 2.0]}, units={"a": "m [x]"})
    with pytest.raises(DataError, match=r"unit 'm \[x\]' of channel 'a' cannot go into a CSV header: it must not contain \[ \] or newlines"):
        write_time_data(path, data)
    assert path.read_text() == "keep me\n"


def test_failed_npz_write_leaves_no_file(tmp_path, monkeypatch):
    def broken(fh, **arrays):
        fh.write(b"PK partial")
        msg = "disk full"
        raise OSError(msg)

    monkeypatch.setattr(np, "savez", broken)
    with pytest.raises(OSError, match="disk full"):
        write_time_data(tmp_path / "run.npz", TimeData.from_rate(10.0, {"a": [1.0, 2.0]}))
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(("arrays", "pattern"), [
    ({"freq": np.array(["1", "2"]), "H": np.ones((1, 1, 2))}, r"array 'freq' in .*bad\.npz must hold numbers; got dtype <U1"),
    ({"freq": np.ones(2), "H": np.array([[["a", "b"]]])}, r"array 'H' in .*bad\.npz must hold numbers; got dtype <U1"),
    ({"freq": np.ones(2), "H": np.ones((1, 1, 2)), "window_decay": np.ones(2)},
     r"array 'window_decay' in .*bad\.npz must be one number \(s, NaN for none\); got shape \(2,\)"),
    ({"freq": np.ones(2), "H": np.ones((1, 1, 2)), "window_decay": np.array("x")},
     r"array 'window_decay' in .*bad\.npz must hold numbers; got dtype <U1"),
    ({"freq": np.ones(2), "H": np.ones((1, 1, 2)), "coherence": np.array([[["a", "b"]]])},
     r"array 'coherence' in .*bad\.npz must hold numbers; got dtype <U1"),
])
def test_frf_npz_with_wrong_types(tmp_path, arrays, pattern):
    path = tmp_path / "bad.npz"
    np.savez(path, input_names=np.array(["F"]), output_names=np.array(["a"]), **arrays)
    with pytest.raises(DataError, match=pattern):
        read_frf(path)


def test_time_npz_with_wrong_types(tmp_path):
    path = tmp_path / "bad.npz"
    np.savez(path, time=np.arange(3.0), values=np.array([["a", "b", "c"]]), channels=np.array(["a"]))
    with pytest.raises(DataError, match=r"array 'values' in .*bad\.npz must hold numbers; got dtype <U1"):
        read_time_data(path)


def test_csv_size_limit_and_byte_order_mark(tmp_path, monkeypatch):
    path = tmp_path / "run.csv"
    path.write_bytes(b"\xef\xbb\xbftime,a\n0,1\n1,2\n")
    assert read_time_data(path).channels == ("a",)  # a spreadsheet's UTF-8 byte order mark is not part of the header
    monkeypatch.setattr(measurements, "MAX_CSV_BYTES", 16)
    with pytest.raises(DataError, match=r"CSV measurement file .*run\.csv is larger than 16 bytes, the most cappe reads"):
        read_time_data(path)


# --------------------------------------------------------------------------------------------- channel match


def test_match_channels():
    data = TimeData.from_rate(100.0, {"F1": [0.0, 1.0], "d1": [0.0, 0.1], "d2": [0.0, 0.2]})
    assert match_channels(data, ("d2", "F1"), "output") == [2, 0]
    assert match_channels(data, [], "input") == []
    with pytest.raises(DataError, match=r"input channel\(s\) \['F2', 'F3'\] not found in the data; available channels: \['F1', 'd1', 'd2'\]"):
        match_channels(data, ["F1", "F2", "F3"], "input")
    with pytest.raises(DataError, match=r"output channel\(s\) \['d1'\] are listed more than once"):
        match_channels(data, ["d1", "d1"], "output")


def test_json_header_names_round_trip(tmp_path):
    """Names that need JSON quoting in FRF headers: slashes, leading quotes, empty names."""
    frf = FRFData(np.array([1.0, 2.0]), np.arange(4.0).reshape(2, 1, 2) + 0j, ("",), ("a/b/c", '"x'))
    back = read_frf(write_frf(tmp_path / "h.csv", frf))
    assert (back.output_names, back.input_names) == (("a/b/c", '"x'), ("",))
    assert json.loads(next(csv.reader([(tmp_path / "h.csv").read_text().splitlines()[0]]))[1][:7]) == "a/b/c"
