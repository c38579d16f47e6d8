"""The history store of the monitoring chain (cappe.monitor._store) on SQLite and on a real PostgreSQL server.

Round trips are exact (the store must give back what it was given: equality, not tolerances). Concurrency and
crash safety are checked with real processes: two writers that would lose updates without the per-machine lock,
and a writer killed with SIGKILL in the middle of a transaction.
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from datetime import UTC, datetime, timedelta, timezone

import numpy as np
import pandas as pd
import pytest
import sqlalchemy

import cappe.monitor._store as store_module
from cappe.exceptions import DataError
from cappe.monitor._store import (
    SCHEMA_VERSION,
    AlarmRecord,
    HistoryStore,
    MeasurementRecord,
    decode_frf,
    encode_frf,
)
from cappe.systems.frf import FRFData

MACHINE = "spindle-01"
CONFIG = {"model": "builtin:spindle-bearing", "components": [{"name": "front", "parameters": ["k11"]}],
          "thresholds": {"warning": 0.99, "alarm": 0.999}}
T0 = datetime(2024, 5, 1, 8, 0, tzinfo=UTC)

BACKENDS = ["sqlite", pytest.param("postgresql", marks=pytest.mark.postgres)]


@pytest.fixture(params=BACKENDS)
def url(request, tmp_path) -> str:
    if request.param == "sqlite":
        return str(tmp_path / "history.db")
    return request.getfixturevalue("postgres_database")


@pytest.fixture
def store(url):
    with HistoryStore(url) as opened:
        opened.add_machine(MACHINE, CONFIG)
        yield opened


@pytest.fixture
def sqlite_store(tmp_path):
    with HistoryStore(tmp_path / "history.db") as opened:
        opened.add_machine(MACHINE, CONFIG)
        yield opened


def _frf(*, coherence: bool = True, decay: float | None = None) -> FRFData:
    rng = np.random.default_rng(7)
    freq = np.linspace(10.0, 500.0, 37)
    H = rng.standard_normal((2, 3, 37)) + 1j * rng.standard_normal((2, 3, 37))
    coh = rng.uniform(0.0, 1.0, (2, 3, 37)) if coherence else None
    return FRFData(freq, H, ("F1", "F2", "Fz"), ("a1", "d2"), ("acceleration", "displacement"), coh, decay)


def _ingest(store: HistoryStore, i: int, *, timestamp: datetime | None = None, frf: FRFData | None = None) -> int:
    """One complete ingest: a measurement with two features, two estimates, an alarm and the new state."""
    with store.transaction(MACHINE) as tx:
        count = (tx.state() or {"count": 0})["count"]
        mid = tx.add_measurement(timestamp=timestamp or T0 + timedelta(hours=i), source=f"run-{i:03d}.uff",
                                 kind="impact", conditions={"speed": 1000.0 + i}, frf=frf, meta={"operator": "ab"})
        tx.add_features(mid, {"f1": (400.0 + i, 0.5), "zeta1": (0.02, None)})
        tx.add_estimates(mid, path="factors", values={"k11": 1.0 + i / 100, "k12": 0.9}, std={"k11": 0.01})
        tx.add_alarm(mid, component="front", statistic="T2", value=10.0 + i, severity="warning",
                     diagnosis={"parameters": {"k11": -0.1}}, message=f"front bearing: T2 = {10 + i}")
        tx.set_state({"count": count + 1})
    return mid


# --------------------------------------------------------------------------------------------------------------
# round trips


def test_machines_config_and_replace(store, url):
    store.add_machine("axis-z", {"model": "slide"})
    assert store.machines() == ["axis-z", MACHINE]
    assert store.machine_config(MACHINE) == CONFIG
    with pytest.raises(DataError, match=r"machine 'axis-z' already exists in history store .*; use replace=True"):
        store.add_machine("axis-z", {"model": "other"})
    store.add_machine("axis-z", {"model": "slide", "version": 2}, replace=True)
    assert store.machine_config("axis-z") == {"model": "slide", "version": 2}
    store.close()
    with HistoryStore(url) as reopened:  # everything is in the database, nothing in the object
        assert reopened.machines() == ["axis-z", MACHINE]
        assert reopened.machine_config(MACHINE) == CONFIG


def test_measurements_are_ordered_by_time_then_id_with_since_until_and_limit(store):
    # inserted out of time order; two share a timestamp (then the id decides)
    hours = [3, 1, 2, 2, 0]
    ids = [_ingest(store, i, timestamp=T0 + timedelta(hours=h)) for i, h in enumerate(hours)]
    records = store.measurements(MACHINE)
    assert [r.id for r in records] == [ids[4], ids[1], ids[2], ids[3], ids[0]]
    assert [r.timestamp for r in records] == [T0 + timedelta(hours=h) for h in (0, 1, 2, 2, 3)]
    assert all(r.timestamp.tzinfo == UTC for r in records)
    # since/until are inclusive
    window = store.measurements(MACHINE, since=T0 + timedelta(hours=1), until=T0 + timedelta(hours=2))
    assert [r.id for r in window] == [ids[1], ids[2], ids[3]]
    # limit keeps the newest, returned oldest first
    assert [r.id for r in store.measurements(MACHINE, limit=2)] == [ids[3], ids[0]]
    assert [r.id for r in store.measurements(MACHINE, until=T0 + timedelta(hours=2), limit=2)] == [ids[2], ids[3]]
    assert store.measurements(MACHINE, limit=0) == []
    assert store.latest_measurement(MACHINE).id == ids[0]


def test_measurement_record_round_trip(store):
    tz = timezone(timedelta(hours=2))
    local = datetime(2024, 5, 1, 10, 30, 15, 123456, tzinfo=tz)
    with store.transaction(MACHINE) as tx:
        mid = tx.add_measurement(timestamp=local, source="a.uff", kind="operational",
                                 conditions={"speed": 12000.0, "temperature": 31.5},
                                 meta={"channels": [1, 2], "note": "ünïcode", "gain": np.float64(2.5)})
    (record,) = store.measurements(MACHINE)
    assert record == MeasurementRecord(
        id=mid, machine=MACHINE, timestamp=datetime(2024, 5, 1, 8, 30, 15, 123456, tzinfo=UTC), source="a.uff",
        kind="operational", conditions={"speed": 12000.0, "temperature": 31.5},
        meta={"channels": [1, 2], "note": "ünïcode", "gain": 2.5}, has_frf=False)
    assert record.to_dict()["timestamp"] == "2024-05-01T08:30:15.123456+00:00"
    assert store.frf(mid) is None
    assert store.latest_measurement(MACHINE) == record


def test_empty_machine(store):
    assert store.measurements(MACHINE) == []
    assert store.latest_measurement(MACHINE) is None
    assert store.alarms(MACHINE) == []
    assert store.baseline(MACHINE) is None
    assert store.counts(MACHINE) == {"measurements": 0, "features": 0, "estimates": 0, "alarms": 0}
    for frame, columns in ((store.features(MACHINE), ["measurement_id", "timestamp", "name", "value", "std"]),
                           (store.estimates(MACHINE),
                            ["measurement_id", "timestamp", "path", "parameter", "value", "std"])):
        assert list(frame.columns) == columns
        assert len(frame) == 0
        assert str(frame["timestamp"].dtype) == "datetime64[us, UTC]"


def test_features_and_estimates_frames(store):
    ids = [_ingest(store, i) for i in range(3)]
    with store.transaction(MACHINE) as tx:
        tx.add_estimates(ids[0], path="modal", values={"k11": 2.0}, std={"k11": math.nan})
    features = store.features(MACHINE)
    assert list(features.columns) == ["measurement_id", "timestamp", "name", "value", "std"]
    assert features["measurement_id"].tolist() == [ids[0], ids[0], ids[1], ids[1], ids[2], ids[2]]
    assert features["name"].tolist() == ["f1", "zeta1"] * 3
    assert features["value"].tolist() == [400.0, 0.02, 401.0, 0.02, 402.0, 0.02]
    assert features["std"].tolist()[0::2] == [0.5, 0.5, 0.5]
    assert features["std"].isna().tolist()[1::2] == [True, True, True]  # None = unknown
    assert features["timestamp"].tolist() == [pd.Timestamp(T0 + timedelta(hours=h)) for h in (0, 0, 1, 1, 2, 2)]
    assert str(features["timestamp"].dtype) == "datetime64[us, UTC]"
    assert features.dtypes["measurement_id"] == np.int64
    only = store.features(MACHINE, names=["f1"])
    assert only["name"].tolist() == ["f1"] * 3

    estimates = store.estimates(MACHINE)
    assert list(estimates.columns) == ["measurement_id", "timestamp", "path", "parameter", "value", "std"]
    assert len(estimates) == 7
    k11 = store.estimates(MACHINE, path="factors", parameters=["k11"])
    assert k11["value"].tolist() == [1.0, 1.01, 1.02]
    assert k11["std"].tolist() == [0.01] * 3
    modal = store.estimates(MACHINE, path="modal")
    assert modal["parameter"].tolist() == ["k11"]
    assert math.isnan(modal["std"].iloc[0])  # NaN std is stored as unknown
    assert store.estimates(MACHINE, parameters=["k12"])["value"].tolist() == [0.9] * 3


def test_alarms_and_acknowledge(store):
    ids = [_ingest(store, i, timestamp=T0 + timedelta(hours=h)) for i, h in enumerate((2, 0, 1))]
    alarms = store.alarms(MACHINE)
    assert [a.measurement_id for a in alarms] == [ids[1], ids[2], ids[0]]  # by the measurement's time
    first = alarms[0]
    assert first == AlarmRecord(id=first.id, machine=MACHINE, measurement_id=ids[1], timestamp=T0,
                                component="front", statistic="T2", value=11.0, severity="warning",
                                diagnosis={"parameters": {"k11": -0.1}}, message="front bearing: T2 = 11",
                                acknowledged=False)
    assert first.to_dict()["timestamp"] == T0.isoformat()
    store.acknowledge(first.id)
    store.acknowledge(first.id)  # again is harmless
    assert [a.id for a in store.alarms(MACHINE, unacknowledged=True)] == [alarms[1].id, alarms[2].id]
    assert [a.acknowledged for a in store.alarms(MACHINE)] == [True, False, False]


def test_baseline_keeps_history_and_returns_the_newest(store):
    assert store.baseline(MACHINE) is None
    store.set_baseline(MACHINE, {"mean": [1.0, 2.0], "n": 10})
    store.set_baseline(MACHINE, {"mean": [1.5, 2.5], "n": 20, "cov": np.eye(2)})
    assert store.baseline(MACHINE) == {"mean": [1.5, 2.5], "n": 20, "cov": [[1.0, 0.0], [0.0, 1.0]]}
    with store.transaction(MACHINE) as tx:
        tx.set_baseline({"n": 30})
    assert store.baseline(MACHINE) == {"n": 30}
    engine = sqlalchemy.create_engine(store.url)
    try:
        with engine.connect() as conn:  # every call added a row
            n_rows = conn.execute(sqlalchemy.text("SELECT count(*) FROM baselines")).scalar_one()
    finally:
        engine.dispose()
    assert n_rows == 3


def test_state_round_trip(store):
    with store.transaction(MACHINE) as tx:
        assert tx.state() is None
        tx.set_state({"count": 1, "ewma": [0.5, math.inf], "nested": {"a": None}})
        assert tx.state() == {"count": 1, "ewma": [0.5, math.inf], "nested": {"a": None}}
    with store.transaction(MACHINE) as tx:
        assert tx.state() == {"count": 1, "ewma": [0.5, math.inf], "nested": {"a": None}}


@pytest.mark.parametrize(("coherence", "decay"), [(True, None), (False, 0.25)])
def test_frf_round_trip_is_lossless(store, coherence, decay):
    frf = _frf(coherence=coherence, decay=decay)
    mid = _ingest(store, 0, frf=frf)
    _ingest(store, 1)
    assert [r.has_frf for r in store.measurements(MACHINE)] == [True, False]
    back = store.frf(mid)
    # lossless: bit-identical arrays, not merely close ones
    assert back.H.dtype == np.complex128
    assert np.array_equal(back.H, frf.H)
    assert np.array_equal(back.freq, frf.freq)
    assert (back.input_names, back.output_names, back.output_quantities) == (
        ("F1", "F2", "Fz"), ("a1", "d2"), ("acceleration", "displacement"))
    assert back.window_decay == decay
    if coherence:
        assert np.array_equal(back.coherence, frf.coherence)
    else:
        assert back.coherence is None


def test_encode_frf_is_compact_and_upcasts_single_precision():
    frf = FRFData(np.arange(1.0, 2001.0), np.ones((1, 1, 2000), dtype=np.complex64) * (1 + 2j), ("F",), ("a",))
    data = encode_frf(frf)
    raw = 2000 * 8 + 2000 * 16  # freq (float64) and H (complex128) as raw bytes: 48 kB
    assert len(data) < raw / 5  # compressed: a regular grid and a constant H pack far below that (~4 kB)
    back = decode_frf(data)
    assert back.H.dtype == np.complex128
    assert np.array_equal(back.H, frf.H)
    assert back.output_quantities == ()


def test_counts(store):
    for i in range(4):
        _ingest(store, i)
    assert store.counts(MACHINE) == {"measurements": 4, "features": 8, "estimates": 8, "alarms": 4}
    store.add_machine("other", {})
    assert store.counts("other") == {"measurements": 0, "features": 0, "estimates": 0, "alarms": 0}


def test_one_machine_does_not_see_another(store):
    store.add_machine("other", {})
    _ingest(store, 0)
    with store.transaction("other") as tx:
        tx.add_measurement(timestamp=T0, source="run-000.uff", kind="impact")  # same source, other machine
    assert [r.source for r in store.measurements("other")] == ["run-000.uff"]
    assert len(store.features("other")) == 0
    assert store.alarms("other") == []


# --------------------------------------------------------------------------------------------------------------
# atomicity


def test_an_exception_inside_the_transaction_leaves_nothing(store):
    _ingest(store, 0)
    before = store.counts(MACHINE)

    class Interrupted(Exception):
        pass

    def interrupted_ingest():
        with store.transaction(MACHINE) as tx:
            mid = tx.add_measurement(timestamp=T0 + timedelta(days=1), source="late.uff", kind="impact",
                                     frf=_frf())
            tx.add_features(mid, {"f1": (1.0, None)})
            tx.add_estimates(mid, path="factors", values={"k11": 1.0})
            tx.add_alarm(mid, component="front", statistic="T2", value=1.0, severity="alarm", diagnosis={},
                         message="x")
            tx.set_state({"count": 99})
            tx.set_baseline({"n": 1})
            raise Interrupted

    with pytest.raises(Interrupted):
        interrupted_ingest()
    assert store.counts(MACHINE) == before
    assert [r.source for r in store.measurements(MACHINE)] == ["run-000.uff"]
    assert store.baseline(MACHINE) is None
    with store.transaction(MACHINE) as tx:
        assert tx.state() == {"count": 1}


def test_duplicate_source_is_refused_and_rolls_the_ingest_back(store):
    first = _ingest(store, 0)
    before = store.counts(MACHINE)

    def ingest_again():
        with store.transaction(MACHINE) as tx:
            tx.set_state({"count": 42})
            other = tx.add_measurement(timestamp=T0, source="new.uff", kind="impact")
            tx.add_features(other, {"f1": (1.0, None)})
            tx.add_measurement(timestamp=T0, source="run-000.uff", kind="impact")

    with pytest.raises(DataError, match=rf"measurement source 'run-000.uff' is already recorded for machine "
                                        rf"'{MACHINE}' \(id {first}\)"):
        ingest_again()
    assert store.counts(MACHINE) == before
    with store.transaction(MACHINE) as tx:
        assert tx.state() == {"count": 1}


# --------------------------------------------------------------------------------------------------------------
# concurrency and crash safety with real processes

# A writer process. Each transaction reads the count from the state, records a measurement whose features and
# estimates carry that count, pauses (widening the window in which a missing lock would lose an update) and
# writes count + 1. It reports "added <source>" inside the transaction and "committed <id>" after the commit,
# then waits `gap` seconds. With `gated`, it also waits inside every transaction, after "added", for a line on
# stdin: a kill then surely lands in the middle of a transaction. With `paced`, it waits for a line on stdin
# before every transaction: the test then starts its own transaction and the writer's at the same moment.
_WRITER = """
import sys, time
from datetime import UTC, datetime, timedelta
from cappe.monitor._store import HistoryStore

url, machine, tag = sys.argv[1:4]
n, pause, gap, mode = int(sys.argv[4]), float(sys.argv[5]), float(sys.argv[6]), sys.argv[7]
gated = mode == "gated"
with HistoryStore(url) as store:
    print("ready", flush=True)
    sys.stdin.readline()
    i = 0
    while n < 0 or i < n:
        if mode == "paced":
            sys.stdin.readline()
        with store.transaction(machine) as tx:
            count = (tx.state() or {"count": 0})["count"]
            source = f"{tag}-{i}"
            mid = tx.add_measurement(timestamp=datetime(2024, 1, 1, tzinfo=UTC) + timedelta(seconds=count),
                                     source=source, kind="operational", conditions={"speed": 1000.0 + i})
            print("added", source, flush=True)
            time.sleep(pause)
            if gated:
                sys.stdin.readline()
            tx.add_features(mid, {"count": (float(count), None), "rms": (0.1, 0.01)})
            tx.add_estimates(mid, path="factors", values={"k11": 1.0 + count, "k12": 0.9}, std={"k11": 0.01})
            tx.set_state({"count": count + 1})
        print("committed", mid, flush=True)
        time.sleep(gap)
        i += 1
"""


def _writer(url: str, tag: str, n: int, pause: float, gap: float, *, mode: str = "free") -> subprocess.Popen[str]:
    arguments = [url, MACHINE, tag, str(n), str(pause), str(gap), mode]
    return subprocess.Popen([sys.executable, "-c", _WRITER, *arguments], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _assert_complete(store: HistoryStore) -> list[MeasurementRecord]:
    """Every measurement has all its features and estimates, and the state counts the measurements."""
    records = store.measurements(MACHINE)
    ids = sorted(r.id for r in records)
    features = store.features(MACHINE)
    estimates = store.estimates(MACHINE)
    assert sorted(features["measurement_id"]) == sorted(ids * 2)
    assert sorted(estimates["measurement_id"]) == sorted(ids * 2)
    with store.transaction(MACHINE) as tx:
        assert tx.state() == {"count": len(records)}
    # each transaction saw a different count: 0, 1, ..., n - 1
    seen = features.loc[features["name"] == "count", "value"]
    assert sorted(seen) == [float(c) for c in range(len(records))]
    return records


def test_concurrent_ingests_into_one_machine_are_serialized(store, url):
    # this process and a writer process, 15 ingests each into the same machine, in rounds: in each round both
    # start a transaction at the same moment (the writer on a line from this process), so one of them must wait
    # for the other's lock; each transaction pauses 10 ms between reading the count and writing count + 1, the
    # window in which a missing lock loses an update. The rounds make the interleaving certain whatever the load
    # (free-running writers with fixed gaps once let one of them make all its ingests while the other slept in
    # SQLite's busy handler, on a loaded CI machine).
    n, pause = 15, 0.01  # every round contends for the lock: 15 of them prove what 40 did, in ~40 % of the time
    child = _writer(url, "child", n, pause, 0.0, mode="paced")
    try:
        assert child.stdout.readline() == "ready\n", child.stderr.read()
        child.stdin.write("go\n")
        child.stdin.flush()
        for i in range(n):
            child.stdin.write("round\n")  # the writer starts its transaction now ...
            child.stdin.flush()
            with store.transaction(MACHINE) as tx:  # ... and this process its own
                count = (tx.state() or {"count": 0})["count"]
                mid = tx.add_measurement(timestamp=T0 + timedelta(seconds=count), source=f"parent-{i}",
                                         kind="operational")
                time.sleep(pause)
                tx.add_features(mid, {"count": (float(count), None), "rms": (0.1, 0.01)})
                tx.add_estimates(mid, path="factors", values={"k11": 1.0 + count, "k12": 0.9})
                tx.set_state({"count": count + 1})
            line = child.stdout.readline()
            while line.startswith("added"):
                line = child.stdout.readline()
            assert line.startswith("committed"), line + child.stderr.read()  # the round ends with both done
        out, err = child.communicate(timeout=120)
    finally:
        with contextlib.suppress(ProcessLookupError):
            child.kill()
        child.wait()
    assert child.returncode == 0, err
    records = _assert_complete(store)
    assert len(records) == 2 * n
    assert store.counts(MACHINE) == {"measurements": 2 * n, "features": 4 * n, "estimates": 4 * n, "alarms": 0}
    # in id order, the records come in the rounds' pairs: one of each writer per round
    sources = [r.source for r in sorted(records, key=lambda r: r.id)]
    assert [sorted(sources[2 * i:2 * i + 2]) for i in range(n)] == [[f"child-{i}", f"parent-{i}"] for i in range(n)]


def test_a_writer_killed_mid_transaction_leaves_only_whole_records(store, url):
    writer = _writer(url, "k", -1, 0.01, 0.0, mode="gated")
    watchdog = threading.Timer(60.0, writer.kill)  # never hang the suite on a stuck child
    watchdog.start()
    committed: list[int] = []
    in_flight = None
    try:
        assert writer.stdout.readline() == "ready\n", writer.stderr.read()
        writer.stdin.write("go\n")
        writer.stdin.flush()
        while True:
            line = writer.stdout.readline()
            assert line, f"the writer ended early: {writer.stderr.read()}"
            word, value = line.split()
            if word == "committed":
                committed.append(int(value))
            elif len(committed) < 5:
                writer.stdin.write("go on\n")  # let this transaction finish
                writer.stdin.flush()
            else:
                in_flight = value  # a measurement added, its features not yet: the writer waits; kill it
                os.kill(writer.pid, signal.SIGKILL)
                break
        writer.wait(timeout=30)
        rest, _ = writer.communicate()
    finally:
        watchdog.cancel()
        with contextlib.suppress(ProcessLookupError):
            writer.kill()
        writer.wait()
    assert writer.returncode == -signal.SIGKILL
    assert rest == ""  # nothing after the in-flight "added"
    if url.startswith("sqlite") or "://" not in url:
        with contextlib.closing(sqlite3.connect(url)) as raw:
            assert raw.execute("PRAGMA integrity_check").fetchall() == [("ok",)]
    records = _assert_complete(store)
    sources = [r.source for r in records]
    assert in_flight not in sources  # the half-done transaction left nothing
    assert set(committed) <= {r.id for r in records}
    assert len(records) == len(committed)
    # and the store takes new ingests
    _ingest(store, 0)
    assert store.counts(MACHINE)["measurements"] == len(committed) + 1


def test_a_sqlite_writer_waits_for_the_lock_instead_of_failing(sqlite_store, tmp_path):
    database = tmp_path / "history.db"
    with contextlib.closing(sqlite3.connect(database, isolation_level=None, check_same_thread=False)) as other:
        other.execute("BEGIN IMMEDIATE")  # another process holds the write lock for a while
        releaser = threading.Timer(0.5, other.execute, args=("COMMIT",))
        releaser.start()
        started = time.perf_counter()
        sqlite_store.add_machine("axis-z", {})
        waited = time.perf_counter() - started
        releaser.join()
    assert waited >= 0.4  # it waited for the commit (0.5 s, minus timer slack) instead of failing at once
    assert sqlite_store.machines() == ["axis-z", MACHINE]


def test_a_sqlite_writer_gives_up_after_the_busy_timeout(tmp_path, monkeypatch):
    monkeypatch.setattr(store_module, "_BUSY_TIMEOUT_MS", 200)  # instead of 30 s
    with HistoryStore(tmp_path / "history.db") as opened:
        opened.add_machine(MACHINE, {})
        with contextlib.closing(sqlite3.connect(tmp_path / "history.db", isolation_level=None)) as other:
            other.execute("BEGIN IMMEDIATE")
            for write in (lambda: opened.set_baseline(MACHINE, {}), lambda: opened.transaction(MACHINE).__enter__()):
                with pytest.raises(DataError, match=r"history store sqlite:///.* stayed locked by another writer "
                                                    r"for 0.2 s; try again when its ingest has finished"):
                    write()
            other.execute("ROLLBACK")
        opened.set_baseline(MACHINE, {"n": 1})  # free again
        assert opened.baseline(MACHINE) == {"n": 1}


def test_sqlite_connection_settings(sqlite_store, tmp_path):
    with sqlite_store._engine.connect() as conn:  # the settings every pooled connection gets
        pragma = {name: conn.exec_driver_sql(f"PRAGMA {name}").scalar()
                  for name in ("journal_mode", "synchronous", "foreign_keys", "busy_timeout")}
    assert pragma == {"journal_mode": "wal", "synchronous": 2, "foreign_keys": 1, "busy_timeout": 30000}
    assert sqlite_store.url == f"sqlite:///{tmp_path / 'history.db'}"


def test_relative_sqlite_url_is_made_absolute(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with HistoryStore("sqlite:///rel.db") as opened:
        assert opened.url == f"sqlite:///{tmp_path / 'rel.db'}"
        assert repr(opened) == f"HistoryStore('sqlite:///{tmp_path / 'rel.db'}')"
    assert (tmp_path / "rel.db").exists()


@pytest.mark.postgres
def test_postgres_url_is_normalized_and_the_password_masked(postgres_database):
    plain = postgres_database.replace("postgresql+psycopg://cappe@", "postgresql://cappe:s3cret@")
    with HistoryStore(plain) as opened:
        assert opened.url == postgres_database.replace("cappe@", "cappe:s3cret@")
        assert "s3cret" not in repr(opened)
        assert "cappe:***@" in repr(opened)
        opened.add_machine(MACHINE, {})
        with pytest.raises(DataError, match=r"already exists in history store postgresql\+psycopg://cappe:\*\*\*@"):
            opened.add_machine(MACHINE, {})


# --------------------------------------------------------------------------------------------------------------
# schema


def _set_version(url: str, version: str) -> None:
    engine = sqlalchemy.create_engine(url if "://" in url else f"sqlite:///{url}")
    try:
        with engine.begin() as conn:
            conn.execute(sqlalchemy.text("UPDATE meta SET value = :v WHERE key = 'schema_version'"), {"v": version})
    finally:
        engine.dispose()


def test_another_schema_version_is_refused(url):
    HistoryStore(url).close()
    _set_version(url, SCHEMA_VERSION)
    HistoryStore(url).close()  # the current version opens
    _set_version(url, "cappe.history/0")
    with pytest.raises(DataError, match=r"history store .* has schema version 'cappe.history/0'; "
                                        r"this cappe reads 'cappe.history/1'"):
        HistoryStore(url)


def test_a_damaged_or_foreign_database_is_refused(tmp_path):
    path = tmp_path / "history.db"
    HistoryStore(path).close()
    with contextlib.closing(sqlite3.connect(path)) as raw:
        raw.execute("DROP TABLE alarms")
        raw.commit()
    with pytest.raises(DataError, match=r"lacks the tables \['alarms'\]; it is damaged"):
        HistoryStore(path)
    foreign = tmp_path / "foreign.db"
    with contextlib.closing(sqlite3.connect(foreign)) as raw:
        raw.execute("CREATE TABLE features (x)")
        raw.commit()
    with pytest.raises(DataError, match=r"has the tables \['features'\] but no 'meta' table: it is not a cappe"):
        HistoryStore(foreign)
    junk = tmp_path / "junk.db"
    junk.write_bytes(b"not a database " * 100)
    with pytest.raises(DataError, match=r"cannot open history store sqlite:///.*junk.db: file is not a database"):
        HistoryStore(junk)


# --------------------------------------------------------------------------------------------------------------
# errors


def test_unknown_machine_names_the_known_ones(store):
    with pytest.raises(DataError, match=rf"unknown machine 'nope' in history store .*; known machines: '{MACHINE}'"):
        store.machine_config("nope")
    with pytest.raises(DataError, match=r"unknown machine 'nope'"), store.transaction("nope"):
        pass
    for query in (store.measurements, store.features, store.estimates, store.alarms, store.counts, store.baseline):
        with pytest.raises(DataError, match=r"unknown machine 'nope'"):
            query("nope")
    with pytest.raises(DataError, match=r"unknown machine 'nope'"):
        store.set_baseline("nope", {})


def test_unknown_machine_lists_at_most_twenty(sqlite_store):
    for k in range(21):
        sqlite_store.add_machine(f"m{k:02d}", {})
    with pytest.raises(DataError, match=r"known machines: 'm00', .*'m19' and 2 more"):
        sqlite_store.machine_config("nope")


def test_errors_on_an_empty_store(tmp_path):
    with HistoryStore(tmp_path / "h.db") as empty, pytest.raises(DataError, match=r"known machines: none"):
        empty.counts("m")


def test_a_transaction_cannot_be_used_after_it_ended(store):
    with store.transaction(MACHINE) as tx:
        pass
    for use in (tx.state, lambda: tx.set_state({}), lambda: tx.add_measurement(timestamp=T0, source="x", kind="k")):
        with pytest.raises(DataError, match=rf"the ingest transaction for machine '{MACHINE}' has ended; "
                                            rf"open a new one with store.transaction\('{MACHINE}'\)"):
            use()
    assert "ended" in repr(tx)


def test_a_thread_cannot_nest_transactions_or_write_beside_one(sqlite_store):
    with sqlite_store.transaction(MACHINE) as tx:
        with pytest.raises(DataError, match=rf"an ingest transaction for machine '{MACHINE}' is already open in "
                                            r"this thread"), sqlite_store.transaction(MACHINE):
            pass
        with pytest.raises(DataError, match=r"cannot write to history store .* outside the ingest transaction "
                                            rf"for machine '{MACHINE}'"):
            sqlite_store.set_baseline(MACHINE, {})
        assert sqlite_store.measurements(MACHINE) == []  # reading beside it is fine
        tx.set_state({"count": 0})
    sqlite_store.set_baseline(MACHINE, {"n": 0})  # and writing after it
    assert sqlite_store.baseline(MACHINE) == {"n": 0}


def test_a_closed_store_refuses_work(tmp_path):
    opened = HistoryStore(tmp_path / "h.db")
    opened.close()
    opened.close()
    with pytest.raises(DataError, match=r"history store sqlite:///.*h.db is closed"):
        opened.machines()


INF, NAN = math.inf, math.nan

# (what is done inside a transaction on a measurement `mid` of MACHINE, the expected message)
TRANSACTION_ERRORS = [
    (lambda tx, mid: tx.add_measurement(timestamp=datetime(2024, 1, 1), source="n.uff", kind="impact"),
     r"measurement timestamp of machine 'spindle-01': timestamp must be timezone-aware"),
    (lambda tx, mid: tx.add_measurement(timestamp="2024-01-01", source="n.uff", kind="impact"),
     r"measurement timestamp of machine 'spindle-01' must be a timezone-aware datetime; got str"),
    (lambda tx, mid: tx.add_measurement(timestamp=T0, source="", kind="impact"),
     r"measurement source must be a non-empty string; got ''"),
    (lambda tx, mid: tx.add_measurement(timestamp=T0, source="n.uff", kind=" "),
     r"measurement kind of 'n.uff' must be a non-empty string"),
    (lambda tx, mid: tx.add_measurement(timestamp=T0, source="n.uff", kind="impact", conditions={"speed": INF}),
     r"condition 'speed' of measurement 'n.uff' must be a finite number; got inf"),
    (lambda tx, mid: tx.add_measurement(timestamp=T0, source="n.uff", kind="impact", frf="frf.uff"),
     r"frf must be an FRFData; got str"),
    (lambda tx, mid: tx.add_measurement(timestamp=T0, source="n.uff", kind="impact", meta={"x": object()}),
     r"meta of measurement 'n.uff' must be a JSON document .*object is not JSON-serializable"),
    (lambda tx, mid: tx.add_features(mid, {"f2": (INF, None)}),
     r"feature 'f2' value of measurement \d+ must be a finite number; got inf"),
    (lambda tx, mid: tx.add_features(mid, {"f2": (NAN, None)}),
     r"feature 'f2' value of measurement \d+ must be a finite number; got nan"),
    (lambda tx, mid: tx.add_features(mid, {"f2": (1.0, -0.1)}),
     r"feature 'f2' std of measurement \d+ must be >= 0 \(or None/NaN for unknown\); got -0.1"),
    (lambda tx, mid: tx.add_features(mid, {"f2": (1.0, INF)}),
     r"feature 'f2' std of measurement \d+ must be a finite number; got inf"),
    (lambda tx, mid: tx.add_features(mid, {"": (1.0, None)}),
     r"feature name of measurement \d+ must be a non-empty string; got ''"),
    (lambda tx, mid: tx.add_features(mid, {"f2": 1.0}),
     r"feature 'f2' of measurement \d+ must be a pair \(value, std\); got 1.0"),
    (lambda tx, mid: tx.add_features(mid, {"f1": (1.0, None)}),
     r"features \['f1'\] are already recorded for measurement \d+"),
    (lambda tx, mid: tx.add_features(mid, [("f2", (1.0, None))]),
     r"features must be a mapping; got list"),
    (lambda tx, mid: tx.add_features(10_000, {"f2": (1.0, None)}),
     r"no measurement with id 10000 in history store"),
    (lambda tx, mid: tx.add_features("1", {"f2": (1.0, None)}),
     r"measurement id must be an integer id; got '1'"),
    (lambda tx, mid: tx.add_estimates(mid, path="factors", values={"k13": NAN}),
     r"estimate 'factors'/'k13' of measurement \d+ value must be a finite number; got nan"),
    (lambda tx, mid: tx.add_estimates(mid, path="factors", values={"k13": 1.0}, std={"k14": 0.1}),
     r"std of estimates 'factors' of measurement \d+ names parameters without a value: \['k14'\]"),
    (lambda tx, mid: tx.add_estimates(mid, path="", values={"k13": 1.0}),
     r"estimation path of measurement \d+ must be a non-empty string"),
    (lambda tx, mid: tx.add_estimates(mid, path="factors", values={"k11": 1.0}),
     r"estimates \['k11'\] of path 'factors' are already recorded for measurement \d+"),
    (lambda tx, mid: tx.add_alarm(mid, component="front", statistic="T2", value=INF, severity="alarm",
                                  diagnosis={}, message="m"),
     r"alarm of measurement \d+: value must be a finite number; got inf"),
    (lambda tx, mid: tx.add_alarm(mid, component="", statistic="T2", value=1.0, severity="alarm",
                                  diagnosis={}, message="m"),
     r"alarm of measurement \d+: component must be a non-empty string"),
    (lambda tx, mid: tx.set_state(["count", 1]),
     r"detector state of machine 'spindle-01' must be a mapping; got list"),
]


@pytest.mark.parametrize(("action", "match"), TRANSACTION_ERRORS)
def test_invalid_ingest_input_is_refused_and_nothing_is_kept(sqlite_store, action, match):
    _ingest(sqlite_store, 0)
    before = sqlite_store.counts(MACHINE)
    mid = sqlite_store.latest_measurement(MACHINE).id

    def ingest():
        with sqlite_store.transaction(MACHINE) as tx:
            tx.add_measurement(timestamp=T0, source="partial.uff", kind="impact")  # undone by the error
            action(tx, mid)

    with pytest.raises(DataError, match=match):
        ingest()
    assert sqlite_store.counts(MACHINE) == before


def test_a_measurement_of_another_machine_is_refused(sqlite_store):
    mid = _ingest(sqlite_store, 0)
    sqlite_store.add_machine("other", {})
    with pytest.raises(DataError, match=rf"measurement {mid} belongs to machine '{MACHINE}', not to 'other'"), \
            sqlite_store.transaction("other") as tx:
        tx.add_features(mid, {"f9": (1.0, None)})


STORE_ERRORS = [
    (lambda s: s.add_machine("", {}), r"machine id must be a non-empty string; got ''"),
    (lambda s: s.add_machine("m2", ["a"]), r"configuration of machine 'm2' must be a mapping; got list"),
    (lambda s: s.add_machine("m2", {"f": {1, 2}}),
     r"configuration of machine 'm2' must be a JSON document .*set is not JSON-serializable"),
    (lambda s: s.set_baseline(MACHINE, None), r"baseline of machine 'spindle-01' must be a mapping; got NoneType"),
    (lambda s: s.measurements(MACHINE, since=datetime(2024, 1, 1)), r"since: timestamp must be timezone-aware"),
    (lambda s: s.measurements(MACHINE, until=datetime(2024, 1, 1)), r"until: timestamp must be timezone-aware"),
    (lambda s: s.measurements(MACHINE, limit=-1), r"limit must be an integer >= 0 or None; got -1"),
    (lambda s: s.measurements(MACHINE, limit=2.5), r"limit must be an integer >= 0 or None; got 2.5"),
    (lambda s: s.features(MACHINE, names="f1"),
     r"feature names must be a sequence of names, not a single string; got 'f1' \(write \['f1'\]\)"),
    (lambda s: s.estimates(MACHINE, parameters="k11"), r"parameters must be a sequence of names, not a single"),
    (lambda s: s.estimates(MACHINE, path=""), r"estimation path must be a non-empty string"),
    (lambda s: s.frf(10_000), r"no measurement with id 10000 in history store sqlite:///"),
    (lambda s: s.frf(True), r"measurement id must be an integer id; got True"),
    (lambda s: s.acknowledge(10_000), r"no alarm with id 10000 in history store sqlite:///"),
]


@pytest.mark.parametrize(("action", "match"), STORE_ERRORS)
def test_invalid_store_input_is_refused(sqlite_store, action, match):
    with pytest.raises(DataError, match=match):
        action(sqlite_store)


@pytest.mark.parametrize(("location", "match"), [
    ("", r"history store path must not be empty"),
    ("sqlite://", r"an in-memory SQLite history store is not supported \(database ''\)"),
    ("sqlite:///:memory:", r"an in-memory SQLite history store is not supported \(database ':memory:'\)"),
    ("mysql://u@localhost/db", r"history store URL 'mysql://u@localhost/db' names an unsupported backend 'mysql'"),
    ("post gres://x", r"cannot parse history store URL 'post gres://x'"),
    ("postgresql://u@h:port/db", r"cannot parse history store URL 'postgresql://u@h:port/db'"),
    (5, r"history store URL must be a string or a path; got int"),
])
def test_invalid_locations_are_refused(location, match):
    with pytest.raises(DataError, match=match):
        HistoryStore(location)


def test_a_missing_folder_is_refused(tmp_path):
    with pytest.raises(DataError, match=r"cannot create history store '.*h.db': folder '.*missing' does not exist"):
        HistoryStore(tmp_path / "missing" / "h.db")


def test_a_missing_driver_says_what_to_install(monkeypatch):
    def no_driver(url):
        msg = "No module named 'psycopg'"
        raise ModuleNotFoundError(msg)

    monkeypatch.setattr(store_module, "create_engine", no_driver)
    with pytest.raises(ImportError, match=r"needs the database driver 'psycopg': pip install 'cappe\[postgres\]'"):
        HistoryStore("postgresql://u@localhost/db")


def test_frf_decoding_errors():
    with pytest.raises(DataError, match=r"cannot decode FRF data \(15 bytes\)"):
        decode_frf(b"not an npz file")
    import io

    buffer = io.BytesIO()
    np.savez_compressed(buffer, freq=np.ones(2))
    with pytest.raises(DataError, match=r"encoded FRF has format None; expected 'cappe.frf/1'"):
        decode_frf(buffer.getvalue())
