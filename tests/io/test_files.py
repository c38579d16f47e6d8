"""Reading JSON data files (read_json) and parameter files (read_parameters): every bad input is a DataError that
names the file and the entry, never a UnicodeDecodeError, RecursionError, OverflowError or Python's int-digit limit."""

from __future__ import annotations

from pathlib import Path

import pytest

from cappe.exceptions import DataError
from cappe.io import read_parameters
from cappe.io.files import read_json

BIG = "1" + "0" * 400  # 10**400: Python reads the int, float() overflows
HUGE = "1" + "0" * 5000  # more digits than int(str) accepts (sys.get_int_max_str_digits() is 4300)


@pytest.mark.parametrize(("content", "pattern"), [
    (b'{"k": 1.0, "\xff": 2}', r"parameter file .*p\.json is not a UTF-8 text file \(JSON expected\): invalid start byte at byte 12"),
    (b"[" * 100_000, r"parameter file .*p\.json nests arrays or objects too deeply to be read"),
    (b"[" * 5000 + b"]" * 5000, r"parameter file .*p\.json nests arrays or objects too deeply to be read"),
    (b'{"k": {"a": ' * 5000 + b"1" + b"}" * 10000, r"parameter file .*p\.json nests arrays or objects too deeply"),
    (f'{{"k": {BIG}}}'.encode(), r"parameter 'k' in .*p\.json must be a finite number; got 100000\.\.\.000 \(401 digits\)"),
    (f'{{"k": -{HUGE}}}'.encode(), r"parameter 'k' in .*p\.json must be a finite number; got -100000\.\.\.000 \(5001 digits\)"),
    (f'{{"k": {HUGE}.5}}'.encode(), r"parameter 'k' in .*p\.json must be a finite number; got 100000\.\.\.0\.5 \(5003 characters\)"),
    (b'{"k": 1e400}', r"parameter 'k' in .*p\.json must be a finite number; got 1e400"),
    (b'{"k": NaN}', r"parameter 'k' in .*p\.json must be a finite number; got nan"),
    (b'{"k": -Infinity}', r"parameter 'k' in .*p\.json must be a finite number; got -inf"),
    (b'{"k": "1.0"}', r"parameter 'k' in .*p\.json must be a finite number; got '1\.0'"),
    (b'{"k": [1.0]}', r"parameter 'k' in .*p\.json must be a finite number; got \[1\.0\]"),
    (b'{"k": true}', r"parameter 'k' in .*p\.json must be a finite number; got True"),
    (b'{"k": null}', r"parameter 'k' in .*p\.json must be a finite number; got None"),
    (b'{"k": "' + b"x" * 10_000 + b'"}', r"parameter 'k' in .*p\.json must be a finite number; got 'x+\.\.\.$"),
    (b"[1.0]", r"parameter file .*p\.json must hold a JSON object \{\"name\": value\}; got list"),
    (b"", r"parameter file .*p\.json is empty; expected JSON"),
    (b" \n\t", r"parameter file .*p\.json is empty; expected JSON"),
    (b'{"k": 1.0, "k": 2.0}', r"parameter file .*p\.json gives the key 'k' twice in one object"),
    (b'{"k": 1', r"parameter file .*p\.json is not valid JSON: Expecting ',' delimiter at column 8$"),
    (b'{\n"k": 1\n"m": 2}', r"parameter file .*p\.json is not valid JSON: Expecting ',' delimiter at line 3, column 1$"),
    # cut short after its first line (a new user's truncated file read "at column 1", the file's first character)
    (b'{"k":\n', r"parameter file .*p\.json is not valid JSON: Expecting value at line 2, column 1$"),
])
def test_bad_parameter_files_name_the_file_and_entry(tmp_path, content, pattern):
    path = tmp_path / "p.json"
    path.write_bytes(content)
    with pytest.raises(DataError, match=pattern) as info:
        read_parameters(path)
    assert "\n" not in str(info.value)


def test_parameter_files_read_numbers_and_a_byte_order_mark(tmp_path):
    path = tmp_path / "p.json"
    path.write_bytes(b'\xef\xbb\xbf{"k": 2, "m": 1.5e3, "big": ' + b"1" + b"0" * 300 + b"}")
    assert read_parameters(path) == {"k": 2.0, "m": 1500.0, "big": 1e300}


def test_parameter_files_are_bounded(tmp_path):
    path = tmp_path / "p.json"
    path.write_bytes(b'{"k": 1.0}' + b" " * 2**20)
    with pytest.raises(DataError, match=r"parameter file .*p\.json is larger than 1 MiB, the most cappe reads"):
        read_parameters(path)
    with pytest.raises(DataError, match=r"cannot read parameter file .*: Is a directory"):
        read_parameters(tmp_path)
    with pytest.raises(DataError, match=r"cannot read parameter file .*none\.json: no such file"):
        read_parameters(tmp_path / "none.json")


@pytest.mark.skipif(not Path("/dev/zero").exists(), reason="needs /dev/zero")
def test_an_endless_file_stops_at_the_limit():
    with pytest.raises(DataError, match=r"parameter file /dev/zero is larger than 1 MiB"):
        read_parameters("/dev/zero")


def test_read_json_limit_and_numbers(tmp_path):
    path = tmp_path / "d.json"
    path.write_text('{"a": [1, 2.5, NaN]}')
    with pytest.raises(DataError, match=r"data file .*d\.json is larger than 10 bytes, the most cappe reads"):
        read_json(path, "data file", max_bytes=10)
    data = read_json(path, "data file")
    assert data["a"][:2] == [1, 2.5]
    assert type(data["a"][0]) is int
