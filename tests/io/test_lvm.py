"""LabVIEW measurement files (.lvm): the real impact-test file of ladisk's tutorial (shared/realdata), read against
the lvm_read package (ladisk's own reader), and the rules of the format, each with its error."""

from __future__ import annotations

import numpy as np
import pytest

from cappe.exceptions import DataError
from cappe.io import read_lvm_time_data, read_measurements, read_time_data, write_time_data

HEAD = ("LabVIEW Measurement\t\nWriter_Version\t2\nSeparator\tTab\nDecimal_Separator\t{dec}\nX_Columns\t{xcol}\n"
        "***End_of_Header***\t\n\t\n")
SEGMENT = ("Channels\t2\t\t\nSamples\t3\t3\t\nY_Unit_Label\tg\tN\t\nX0\t0{d}0E+0\t0{d}0E+0\t\n"
           "Delta_X\t{dx}\t{dx}\t\n***End_of_Header***\t\t\t\nX_Value\tacc\tforce\tComment\n")


def _lvm(tmp_path, *, dec=",", xcol="No", dx="1,0E-3", rows=("\t0,5\t1,0", "\t-0,25\t2,0", "\t0,0\t3,5"), segments=1):
    d = "," if dec == "," else "."
    body = HEAD.format(dec=dec, xcol=xcol) + (SEGMENT.format(d=d, dx=dx) + "\n".join(rows) + "\n") * segments
    path = tmp_path / "m.lvm"
    path.write_text(body)
    return path


def test_real_labview_file_matches_lvm_read(realdata):
    # the ladisk tutorial's hit: 2 channels, 50 kHz, 50 030 samples, decimal comma; every value as lvm_read gives it
    lvm_read = pytest.importorskip("lvm_read")
    path = realdata / "acceleration.lvm"
    data = read_time_data(path)
    ref = lvm_read.read(str(path), read_from_pickle=False, dump_file=False)[0]
    assert data.channels == ("Acceleration (Trigger)", "Force (Trigger)")
    assert data.units == ("g", "Newtons")
    assert data.fs == 50000.0
    assert data.n_samples == 50030
    np.testing.assert_array_equal(data.values, ref["data"][:, :2].T)
    assert data.values[:, 0].tolist() == [-0.007387, 0.232147]  # the first data row of the file, as written


def test_small_files_with_either_decimal_mark(tmp_path):
    comma = read_measurements(_lvm(tmp_path))
    assert comma.channels == ("acc", "force")
    assert comma.units == ("g", "N")
    np.testing.assert_array_equal(comma.values, [[0.5, -0.25, 0.0], [1.0, 2.0, 3.5]])
    np.testing.assert_allclose(comma.time, [0.0, 1e-3, 2e-3], rtol=0, atol=1e-15)
    dot = read_time_data(_lvm(tmp_path, dec=".", dx="1.0E-3", rows=("\t0.5\t1.0", "\t-0.25\t2.0", "\t0\t3.5")))
    np.testing.assert_array_equal(dot.values, comma.values)
    # X_Columns One: the x cells are there, the time still comes from X0 and Delta_X
    one = read_time_data(_lvm(tmp_path, xcol="One", rows=("0\t0,5\t1,0", "0,001\t-0,25\t2,0", "0,002\t0\t3,5")))
    np.testing.assert_array_equal(one.values, comma.values)


@pytest.mark.parametrize(("kwargs", "pattern"), [
    ({"segments": 2}, r"m\.lvm holds 2 segments \(headers closed on lines \d+, \d+\); cappe reads one: split"),
    ({"xcol": "Multi"}, r"m\.lvm: X_Columns Multi \(one time column per channel\) is not read"),
    ({"rows": ("\t0,5\t1,0", "\tabc\t2,0")}, r"m\.lvm, line 16: 'abc' is not a number \(decimal separator ','\)"),
    ({"rows": ("\t0,5\t1,0", "\t0,5")}, r"m\.lvm, line 16: 2 channel value\(s\) expected after the X_Value cell"),
    ({"dx": "0"}, r"m\.lvm, line \d+: Delta_X must be > 0 s; got 0\.0"),
])
def test_bad_lvm_files_name_file_and_line(tmp_path, kwargs, pattern):
    with pytest.raises(DataError, match=pattern):
        read_lvm_time_data(_lvm(tmp_path, **kwargs))


def test_lvm_is_read_only_and_holds_no_frfs(tmp_path):
    from cappe.io import read_frf

    data = read_time_data(_lvm(tmp_path))
    with pytest.raises(DataError, match=r"cannot write .*out\.lvm: cappe reads LabVIEW \.lvm files but writes time"):
        write_time_data(tmp_path / "out.lvm", data)
    with pytest.raises(DataError, match=r"m\.lvm is a LabVIEW measurement file of time data; estimate FRFs"):
        read_frf(tmp_path / "m.lvm")
    (tmp_path / "x.lvm").write_text("time,a\n0,1\n")
    with pytest.raises(DataError, match=r"x\.lvm, line 1: not a LabVIEW measurement file"):
        read_time_data(tmp_path / "x.lvm")
