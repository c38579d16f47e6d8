"""Scenario manifests (read_scenario): a bad manifest is a DataError naming the file and the entry."""

from __future__ import annotations

import pytest

from cappe.exceptions import DataError
from cappe.monitor import read_scenario

ENTRY = b'{"file": "m.npz", "timestamp": "2024-01-01T00:00:00+00:00"'


@pytest.mark.parametrize(("content", "pattern"), [
    (b'{"format": "\xff"}', r"scenario manifest .*s\.json is not a UTF-8 text file \(JSON expected\)"),
    (b"[" * 100_000, r"scenario manifest .*s\.json nests arrays or objects too deeply to be read"),
    (b"", r"scenario manifest .*s\.json is empty; expected JSON"),
    (b"[]", r"s\.json: format must be 'cappe\.monitor-scenario/1'; got 'list'"),
    (b'{"format": "cappe.monitor-scenario/1", "measurements": {}}', r"s\.json: measurements must be a list; got dict"),
    (b'{"format": "cappe.monitor-scenario/1", "measurements": [3]}',
     r"s\.json: measurements\[0\] must be an object with 'file' and 'timestamp'; got int"),
    (b'{"format": "cappe.monitor-scenario/1", "measurements": [{"file": "m.npz"}]}',
     r"s\.json: measurements\[0\] needs 'file' and an ISO 'timestamp'"),
    (b'{"format": "cappe.monitor-scenario/1", "measurements": [' + ENTRY + b', "conditions": [1]}]}',
     r"s\.json: measurements\[0\]\.conditions must be an object \{name: number\}; got \[1\]"),
    (b'{"format": "cappe.monitor-scenario/1", "measurements": [' + ENTRY + b', "conditions": {"T": 1' + b"0" * 5000 + b"}}]}",
     r"s\.json: measurements\[0\]\.conditions must be an object \{name: number\}; got \{'T': 100000\.\.\.000 \(5001"),
])
def test_bad_manifests(tmp_path, content, pattern):
    path = tmp_path / "s.json"
    path.write_bytes(content)
    with pytest.raises(DataError, match=pattern):
        read_scenario(path)
