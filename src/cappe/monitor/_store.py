"""The history store of the condition-monitoring chain.

Per machine id it records every measurement (with its FRF, operating conditions and metadata), the features
extracted from it, the parameter estimates, the alarms, the machine's configuration, the learned healthy
baseline (with its history) and the detector state, each with a timezone-aware UTC timestamp.

Backends
--------
One SQLAlchemy Core code path serves both:

- **SQLite** (a plain file path or ``sqlite:///path``): one file, WAL journal (readers never block the writer),
  foreign keys on, a busy timeout of 30 s so that concurrent writers wait for each other instead of failing, and
  ``synchronous=FULL``: a committed record survives a killed process *and* a power loss (``NORMAL`` would
  survive only the former; an ingest every few seconds can afford the extra sync).
- **PostgreSQL** (``postgresql+psycopg://user@host:port/db``; ``postgresql://`` means the same): timestamps as
  ``timestamp with time zone``. The tables have plain names (``meta``, ``machines``, ``measurements``, ...),
  so give the store a database of its own.

Ingests and concurrency
-----------------------
Everything one measurement brings (the measurement, its features, estimates, alarms and the new detector state)
is written in one transaction, :meth:`HistoryStore.transaction`: all or nothing, committed when the ``with`` block
ends normally, rolled back when it raises. Ingests into the same machine are serialized across threads and
processes: SQLite takes its write lock (for the whole file) at ``BEGIN IMMEDIATE``, PostgreSQL locks the
machine's row with ``SELECT ... FOR UPDATE`` (other machines ingest in parallel), so the detector state read at
the start of a transaction is never stale. A SQLite writer that cannot get the lock within the busy timeout
raises :class:`~cappe.exceptions.DataError`; PostgreSQL waits for the row as long as it takes. Every other write
(machines, baselines, acknowledgements) is a short transaction of its own; a thread with an open ingest
transaction writes through it (:meth:`IngestTransaction.set_baseline`). A store object may be shared between
threads; each process opens its own.

Timestamps have microsecond resolution; naive ``datetime`` values are refused. JSON documents (configurations,
baselines, states, metadata, diagnoses) are stored as text; NumPy scalars and arrays in them become numbers and
lists, and mapping keys become strings as in any JSON.
"""

from __future__ import annotations

import io
import json
import math
import numbers
import os
import threading
import zipfile
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any

import numpy as np
from sqlalchemy import (
    URL,
    Boolean,
    Column,
    DateTime,
    Float,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    MetaData,
    String,
    Table,
    Text,
    UniqueConstraint,
    create_engine,
    event,
    func,
    insert,
    inspect,
    literal,
    make_url,
    select,
    text,
    update,
)
from sqlalchemy.engine import Connection, Dialect, Engine, RootTransaction
from sqlalchemy.exc import ArgumentError, DBAPIError, IntegrityError, OperationalError
from sqlalchemy.types import TypeDecorator, TypeEngine

from cappe.exceptions import DataError
from cappe.systems.frf import FRFData

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "SCHEMA_VERSION",
    "AlarmRecord",
    "HistoryStore",
    "IngestTransaction",
    "MeasurementRecord",
    "decode_frf",
    "encode_frf",
]

#: Schema version written to (and required in) the ``meta`` table.
SCHEMA_VERSION = "cappe.history/1"

_FRF_FORMAT = "cappe.frf/1"
_BUSY_TIMEOUT_MS = 30_000
_PG_SCHEMA_LOCK = 0x63617070  # advisory-lock key ("capp") serializing schema creation on PostgreSQL
_BEGIN_OPTION = "cappe_sqlite_begin"


# --------------------------------------------------------------------------------------------------------------
# schema


class _UTCTimestamp(TypeDecorator[datetime]):
    """Timezone-aware UTC ``datetime``: ``timestamp with time zone`` on PostgreSQL, fixed-width ISO text elsewhere.

    The text form ``YYYY-MM-DDTHH:MM:SS.ffffff+00:00`` has one width and one offset, so text order is time order.
    """

    impl = String(32)
    cache_ok = True

    def load_dialect_impl(self, dialect: Dialect) -> TypeEngine[Any]:
        if dialect.name == "postgresql":
            return dialect.type_descriptor(DateTime(timezone=True))
        return dialect.type_descriptor(String(32))

    def process_bind_param(self, value: datetime | None, dialect: Dialect) -> Any:
        if value is None:
            return None
        utc = value.astimezone(UTC)
        return utc if dialect.name == "postgresql" else utc.isoformat(timespec="microseconds")

    def process_result_value(self, value: Any, dialect: Dialect) -> datetime | None:
        if value is None:
            return None
        moment = datetime.fromisoformat(value) if isinstance(value, str) else value
        return _pure_utc(moment)


_METADATA = MetaData()

_meta = Table(
    "meta",
    _METADATA,
    Column("key", String(64), primary_key=True),
    Column("value", Text, nullable=False),
)

_machines = Table(
    "machines",
    _METADATA,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("name", Text, nullable=False, unique=True),
    Column("config", Text, nullable=False),
    Column("state", Text, nullable=True),
    Column("created", _UTCTimestamp(), nullable=False),
    Column("config_updated", _UTCTimestamp(), nullable=False),
    Column("state_updated", _UTCTimestamp(), nullable=True),
)

_baselines = Table(
    "baselines",
    _METADATA,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("machine_id", Integer, ForeignKey("machines.id", ondelete="CASCADE"), nullable=False, index=True),
    Column("created", _UTCTimestamp(), nullable=False),
    Column("document", Text, nullable=False),
)

_measurements = Table(
    "measurements",
    _METADATA,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("machine_id", Integer, ForeignKey("machines.id", ondelete="CASCADE"), nullable=False),
    Column("timestamp", _UTCTimestamp(), nullable=False),
    Column("source", Text, nullable=False),
    Column("kind", Text, nullable=False),
    Column("conditions", Text, nullable=False),
    Column("meta", Text, nullable=False),
    Column("frf", LargeBinary, nullable=True),
    UniqueConstraint("machine_id", "source", name="uq_measurements_machine_source"),
    Index("ix_measurements_machine_time", "machine_id", "timestamp", "id"),
)

_features = Table(
    "features",
    _METADATA,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("measurement_id", Integer, ForeignKey("measurements.id", ondelete="CASCADE"), nullable=False),
    Column("name", Text, nullable=False),
    Column("value", Float, nullable=False),
    Column("std", Float, nullable=True),
    UniqueConstraint("measurement_id", "name", name="uq_features_measurement_name"),
)

_estimates = Table(
    "estimates",
    _METADATA,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("measurement_id", Integer, ForeignKey("measurements.id", ondelete="CASCADE"), nullable=False),
    Column("path", Text, nullable=False),
    Column("parameter", Text, nullable=False),
    Column("value", Float, nullable=False),
    Column("std", Float, nullable=True),
    UniqueConstraint("measurement_id", "path", "parameter", name="uq_estimates_measurement_path_parameter"),
)

_alarms = Table(
    "alarms",
    _METADATA,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("measurement_id", Integer, ForeignKey("measurements.id", ondelete="CASCADE"), nullable=False,
           index=True),
    Column("component", Text, nullable=False),
    Column("statistic", Text, nullable=False),
    Column("value", Float, nullable=False),
    Column("severity", Text, nullable=False),
    Column("diagnosis", Text, nullable=False),
    Column("message", Text, nullable=False),
    Column("acknowledged", Boolean, nullable=False, default=False),
    Column("acknowledged_at", _UTCTimestamp(), nullable=True),
)

_TABLES = frozenset(_METADATA.tables)


# --------------------------------------------------------------------------------------------------------------
# records


@dataclass(frozen=True)
class MeasurementRecord:
    """One stored measurement.

    Attributes
    ----------
    id : int
        Measurement id (unique in the store).
    machine : str
        Machine id.
    timestamp : datetime
        When it was measured (timezone-aware, UTC).
    source : str
        Where it came from (file name, acquisition id); unique per machine.
    kind : str
        What it is (``"impact"``, ``"operational"``, ...).
    conditions : dict of str to float
        Operating conditions (speed, temperature, axis positions, ...).
    meta : dict
        Free metadata (JSON).
    has_frf : bool
        Whether an FRF is stored with it (:meth:`HistoryStore.frf`).
    """

    id: int
    machine: str
    timestamp: datetime
    source: str
    kind: str
    conditions: dict[str, float]
    meta: dict[str, Any]
    has_frf: bool

    def to_dict(self) -> dict[str, Any]:
        """The record as JSON-ready values (timestamp as ISO 8601 text)."""
        result = asdict(self)
        result["timestamp"] = self.timestamp.isoformat()
        return result


@dataclass(frozen=True)
class AlarmRecord:
    """One stored alarm.

    Attributes
    ----------
    id : int
        Alarm id (unique in the store).
    machine : str
        Machine id.
    measurement_id : int
        The measurement that raised it.
    timestamp : datetime
        The measurement's timestamp (timezone-aware, UTC).
    component, statistic : str
        What alarmed and by which test statistic.
    value : float
        The statistic's value.
    severity : str
        Severity grade as the detector names it.
    diagnosis : dict
        The detector's diagnosis (JSON).
    message : str
        Human-readable text.
    acknowledged : bool
        Whether an operator acknowledged it.
    """

    id: int
    machine: str
    measurement_id: int
    timestamp: datetime
    component: str
    statistic: str
    value: float
    severity: str
    diagnosis: dict[str, Any]
    message: str
    acknowledged: bool

    def to_dict(self) -> dict[str, Any]:
        """The record as JSON-ready values (timestamp as ISO 8601 text)."""
        result = asdict(self)
        result["timestamp"] = self.timestamp.isoformat()
        return result


# --------------------------------------------------------------------------------------------------------------
# validation helpers


def _pure_utc(moment: datetime) -> datetime:
    """A plain ``datetime`` in UTC (drops subclasses such as ``pandas.Timestamp`` and sub-microsecond parts)."""
    utc = moment.astimezone(UTC)
    return datetime(utc.year, utc.month, utc.day, utc.hour, utc.minute, utc.second, utc.microsecond,
                    tzinfo=UTC)


def _timestamp(value: object, what: str) -> datetime:
    if not isinstance(value, datetime):
        msg = f"{what} must be a timezone-aware datetime; got {type(value).__name__} {value!r}"
        raise DataError(msg)
    if value.tzinfo is None or value.utcoffset() is None:
        msg = f"{what}: timestamp must be timezone-aware (e.g. datetime(..., tzinfo=UTC)); got {value!r}"
        raise DataError(msg)
    return _pure_utc(value)


def _name(value: object, what: str) -> str:
    if not isinstance(value, str) or not value.strip():
        msg = f"{what} must be a non-empty string; got {value!r}"
        raise DataError(msg)
    return value


def _finite(value: object, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(float(value)):
        msg = f"{what} must be a finite number; got {value!r}"
        raise DataError(msg)
    return float(value)


def _std(value: object, what: str) -> float | None:
    """A standard deviation: None or NaN mean unknown (stored as NULL); otherwise finite and >= 0."""
    if value is None or (isinstance(value, numbers.Real) and math.isnan(float(value))):
        return None
    std = _finite(value, what)
    if std < 0:
        msg = f"{what} must be >= 0 (or None/NaN for unknown); got {std!r}"
        raise DataError(msg)
    return std


def _mapping(value: object, what: str) -> Mapping[Any, Any]:
    if not isinstance(value, Mapping):
        msg = f"{what} must be a mapping; got {type(value).__name__}"
        raise DataError(msg)
    return value


def _json_default(value: object) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    msg = f"{type(value).__name__} is not JSON-serializable"
    raise TypeError(msg)


def _dump_json(value: object, what: str) -> str:
    document = dict(_mapping(value, what))
    try:
        return json.dumps(document, default=_json_default, separators=(",", ":"))
    except (TypeError, ValueError) as exc:
        msg = f"{what} must be a JSON document (mapping of strings, numbers, lists, mappings); {exc}"
        raise DataError(msg) from exc


def _load_json(value: str) -> dict[str, Any]:
    document: dict[str, Any] = json.loads(value)
    return document


def _names(value: Sequence[str] | None, what: str) -> list[str] | None:
    if value is None:
        return None
    if isinstance(value, str):
        msg = f"{what} must be a sequence of names, not a single string; got {value!r} (write [{value!r}])"
        raise DataError(msg)
    return [_name(v, f"{what} entry") for v in value]


def _id(value: object, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        msg = f"{what} must be an integer id; got {value!r}"
        raise DataError(msg)
    return int(value)


# --------------------------------------------------------------------------------------------------------------
# FRF encoding


def encode_frf(frf: FRFData) -> bytes:
    """Encode an FRF as compact binary (a compressed NumPy ``.npz`` archive); :func:`decode_frf` inverts it.

    Parameters
    ----------
    frf : FRFData
        Frequencies, complex ``H[out, in, freq]``, channel names and quantities, coherence and window decay
        if present.

    Returns
    -------
    bytes
        Lossless: ``decode_frf(encode_frf(frf))`` has bit-identical arrays (``H`` as complex128).

    Examples
    --------
    >>> import numpy as np
    >>> from cappe.systems.frf import FRFData
    >>> frf = FRFData(np.array([10.0, 20.0]), np.array([[[1 + 2j, 3 - 4j]]]), ("F1",), ("a1",))
    >>> back = decode_frf(encode_frf(frf))
    >>> np.array_equal(back.H, frf.H), back.input_names, back.output_names
    (True, ('F1',), ('a1',))
    """
    if not isinstance(frf, FRFData):
        msg = f"frf must be an FRFData; got {type(frf).__name__}"
        raise DataError(msg)
    arrays: dict[str, Any] = {
        "format": np.array(_FRF_FORMAT),
        "freq": np.asarray(frf.freq, dtype=np.float64),
        "H": np.asarray(frf.H, dtype=np.complex128),
        "input_names": np.array(frf.input_names, dtype=str),
        "output_names": np.array(frf.output_names, dtype=str),
        "output_quantities": np.array(frf.output_quantities, dtype=str),
    }
    if frf.coherence is not None:
        arrays["coherence"] = np.asarray(frf.coherence, dtype=np.float64)
    if frf.window_decay is not None:
        arrays["window_decay"] = np.array(float(frf.window_decay))
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    return buffer.getvalue()


def decode_frf(data: bytes) -> FRFData:
    """Decode bytes written by :func:`encode_frf`.

    Parameters
    ----------
    data : bytes
        The encoded FRF.

    Returns
    -------
    FRFData

    Examples
    --------
    >>> import numpy as np
    >>> from cappe.systems.frf import FRFData
    >>> frf = FRFData(np.array([5.0]), np.array([[[2j]]]), ("F1",), ("d1",), ("displacement",))
    >>> decode_frf(encode_frf(frf)).output_quantities
    ('displacement',)
    """
    try:
        with np.load(io.BytesIO(bytes(data)), allow_pickle=False) as archive:
            arrays = {key: archive[key] for key in archive.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        msg = f"cannot decode FRF data ({len(data)} bytes): {exc}"
        raise DataError(msg) from exc
    found = str(arrays["format"]) if "format" in arrays else None
    if found != _FRF_FORMAT:
        msg = f"encoded FRF has format {found!r}; expected {_FRF_FORMAT!r}"
        raise DataError(msg)
    return FRFData(
        freq=arrays["freq"],
        H=arrays["H"],
        input_names=tuple(str(n) for n in arrays["input_names"]),
        output_names=tuple(str(n) for n in arrays["output_names"]),
        output_quantities=tuple(str(q) for q in arrays["output_quantities"]),
        coherence=arrays.get("coherence"),
        window_decay=float(arrays["window_decay"]) if "window_decay" in arrays else None,
    )


# --------------------------------------------------------------------------------------------------------------
# engine set-up


def _normalize_url(url: str | os.PathLike[str]) -> URL:
    """A plain path means SQLite; relative SQLite paths become absolute; ``postgresql://`` gets psycopg."""
    if isinstance(url, os.PathLike) or (isinstance(url, str) and "://" not in url):
        raw = os.fspath(url)
        if not raw:
            msg = "history store path must not be empty"
            raise DataError(msg)
        return _sqlite_url(URL.create("sqlite", database=raw))
    if not isinstance(url, str):
        msg = f"history store URL must be a string or a path; got {type(url).__name__}"
        raise DataError(msg)
    try:
        parsed = make_url(url)
    except (ArgumentError, ValueError) as exc:
        msg = f"cannot parse history store URL {url!r}: {exc}"
        raise DataError(msg) from exc
    if parsed.drivername in ("sqlite", "sqlite+pysqlite"):
        return _sqlite_url(parsed)
    if parsed.drivername in ("postgresql", "postgres"):
        return parsed.set(drivername="postgresql+psycopg")
    if parsed.get_backend_name() == "postgresql":
        return parsed
    msg = (
        f"history store URL {parsed.render_as_string(hide_password=True)!r} names an unsupported backend "
        f"{parsed.drivername!r}; use a file path, sqlite:///path or postgresql+psycopg://..."
    )
    raise DataError(msg)


def _sqlite_url(parsed: URL) -> URL:
    database = parsed.database
    if not database or database == ":memory:" or database.startswith("file:") or parsed.query.get("mode") == "memory":
        msg = (
            f"an in-memory SQLite history store is not supported (database {database or ''!r}): "
            "its connections would not share it; give a file path"
        )
        raise DataError(msg)
    path = Path(database).expanduser().resolve()
    if not path.parent.is_dir():
        msg = f"cannot create history store {str(path)!r}: folder {str(path.parent)!r} does not exist"
        raise DataError(msg)
    return parsed.set(drivername="sqlite", database=str(path))


def _on_sqlite_connect(dbapi_connection: Any, connection_record: Any) -> None:
    # SQLAlchemy's recipe: stop the sqlite3 module from issuing BEGIN itself (legacy transaction control) so
    # that _on_sqlite_begin decides between a deferred BEGIN (reads) and BEGIN IMMEDIATE (writes)
    dbapi_connection.isolation_level = None
    cursor = dbapi_connection.cursor()
    try:
        cursor.execute(f"PRAGMA busy_timeout = {_BUSY_TIMEOUT_MS}")
        cursor.execute("PRAGMA journal_mode = WAL")
        cursor.execute("PRAGMA synchronous = FULL")
        cursor.execute("PRAGMA foreign_keys = ON")
    finally:
        cursor.close()


def _on_sqlite_begin(conn: Connection) -> None:
    conn.exec_driver_sql(conn.get_execution_options().get(_BEGIN_OPTION, "BEGIN"))


def _create_engine(url: URL) -> Engine:
    try:
        engine = create_engine(url)
    except ImportError as exc:
        msg = (
            f"the history store {url.render_as_string(hide_password=True)!r} needs the database driver "
            f"'{url.get_driver_name()}': pip install 'cappe[postgres]'"
        )
        raise ImportError(msg) from exc
    if engine.dialect.name == "sqlite":
        event.listen(engine, "connect", _on_sqlite_connect)
        event.listen(engine, "begin", _on_sqlite_begin)
    return engine


# --------------------------------------------------------------------------------------------------------------
# the store


class HistoryStore:
    """Condition-monitoring history of machines in SQLite (default) or PostgreSQL.

    Parameters
    ----------
    url : str or path-like
        A file path or ``sqlite:///path`` (SQLite), or a SQLAlchemy URL ``postgresql+psycopg://user@host/db``.
        The schema is created on first open; a database written by another schema version is refused.

    Attributes
    ----------
    url : str
        The normalized SQLAlchemy URL (absolute path for SQLite). ``repr`` and error messages mask the password.

    Examples
    --------
    >>> import tempfile
    >>> from datetime import UTC, datetime
    >>> from cappe.monitor._store import HistoryStore
    >>> folder = tempfile.TemporaryDirectory()
    >>> with HistoryStore(f"{folder.name}/history.db") as store:
    ...     store.add_machine("spindle-01", {"model": "builtin:spindle-bearing"})
    ...     with store.transaction("spindle-01") as tx:
    ...         mid = tx.add_measurement(timestamp=datetime(2024, 5, 1, 8, 0, tzinfo=UTC),
    ...                                  source="run-001.uff", kind="impact")
    ...         tx.add_features(mid, {"f1": (412.5, 0.8)})
    ...         tx.set_state({"count": 1})
    ...     store.counts("spindle-01")
    {'measurements': 1, 'features': 1, 'estimates': 0, 'alarms': 0}
    >>> folder.cleanup()
    """

    url: str

    def __init__(self, url: str | os.PathLike[str]) -> None:
        parsed = _normalize_url(url)
        self.url = parsed.render_as_string(hide_password=False)
        self._display = parsed.render_as_string(hide_password=True)
        self._engine: Engine | None = _create_engine(parsed)
        self._local = threading.local()
        try:
            self._prepare_schema()
        except DBAPIError as exc:
            self.close()
            msg = f"cannot open history store {self._display}: {exc.orig}"
            raise DataError(msg) from exc
        except BaseException:
            self.close()
            raise

    def __repr__(self) -> str:
        return f"HistoryStore({self._display!r})"

    def __enter__(self) -> HistoryStore:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def close(self) -> None:
        """Close every pooled connection; later calls raise :class:`DataError`. Closing twice is harmless."""
        if self._engine is not None:
            self._engine.dispose()
            self._engine = None

    # -- connections -------------------------------------------------------------------------------------------

    def _live_engine(self) -> Engine:
        if self._engine is None:
            msg = f"history store {self._display} is closed"
            raise DataError(msg)
        return self._engine

    @contextmanager
    def _read(self) -> Iterator[Connection]:
        """A read transaction (a consistent snapshot; never blocks writers on SQLite's WAL)."""
        with self._live_engine().connect() as conn, conn.begin():
            yield conn

    @contextmanager
    def _write(self) -> Iterator[Connection]:
        """A write transaction: SQLite takes its write lock at BEGIN (waiting up to the busy timeout)."""
        engine = self._live_engine()
        active = getattr(self._local, "machine", None)
        if active is not None:
            msg = (
                f"cannot write to history store {self._display} outside the ingest transaction for machine "
                f"{active!r} that is open in this thread (it holds the write lock); use the transaction's methods"
            )
            raise DataError(msg)
        with engine.connect() as conn, self._begin_write(conn):
            yield conn

    def _begin_write(self, conn: Connection) -> RootTransaction:
        conn.execution_options(**{_BEGIN_OPTION: "BEGIN IMMEDIATE"})
        try:
            return conn.begin()
        except OperationalError as exc:
            if "locked" not in str(exc.orig):
                raise
            msg = (
                f"history store {self._display} stayed locked by another writer for "
                f"{_BUSY_TIMEOUT_MS / 1000:g} s; try again when its ingest has finished"
            )
            raise DataError(msg) from exc

    def _prepare_schema(self) -> None:
        with self._write() as conn:
            if conn.dialect.name == "postgresql":
                conn.execute(text("SELECT pg_advisory_xact_lock(:key)"), {"key": _PG_SCHEMA_LOCK})
            present = set(inspect(conn).get_table_names())
            if "meta" in present:
                found = conn.execute(select(_meta.c.value).where(_meta.c.key == "schema_version")).scalar()
                if found != SCHEMA_VERSION:
                    msg = (
                        f"history store {self._display} has schema version {found!r}; "
                        f"this cappe reads {SCHEMA_VERSION!r}"
                    )
                    raise DataError(msg)
                missing = sorted(_TABLES - present)
                if missing:
                    msg = f"history store {self._display} lacks the tables {missing}; it is damaged"
                    raise DataError(msg)
                return
            clash = sorted(_TABLES & present)
            if clash:
                msg = (
                    f"database {self._display} has the tables {clash} but no 'meta' table: "
                    "it is not a cappe history store"
                )
                raise DataError(msg)
            _METADATA.create_all(conn)
            conn.execute(insert(_meta).values(key="schema_version", value=SCHEMA_VERSION))

    def _machine_id(self, conn: Connection, machine: str, *, lock: bool = False) -> int:
        query = select(_machines.c.id).where(_machines.c.name == machine)
        if lock:
            query = query.with_for_update()
        machine_id = conn.execute(query).scalar()
        if machine_id is None:
            known = list(conn.execute(select(_machines.c.name).order_by(_machines.c.name)).scalars())
            shown = ", ".join(repr(k) for k in known[:20]) + (f" and {len(known) - 20} more" if len(known) > 20 else "")
            msg = f"unknown machine {machine!r} in history store {self._display}; known machines: {shown or 'none'}"
            raise DataError(msg)
        return int(machine_id)

    # -- machines ----------------------------------------------------------------------------------------------

    def add_machine(self, machine: str, config: Mapping[str, Any], *, replace: bool = False) -> None:
        """Register a machine with its configuration.

        Parameters
        ----------
        machine : str
            Machine id.
        config : mapping
            The machine's monitoring configuration (JSON document).
        replace : bool
            Replace the configuration of an existing machine (its history, baseline and state are kept).
        """
        name = _name(machine, "machine id")
        document = _dump_json(config, f"configuration of machine {name!r}")
        now = datetime.now(UTC)
        exists = (
            f"machine {name!r} already exists in history store {self._display}; "
            "use replace=True to replace its configuration"
        )
        try:
            with self._write() as conn:
                machine_id = conn.execute(select(_machines.c.id).where(_machines.c.name == name)).scalar()
                if machine_id is None:
                    conn.execute(insert(_machines).values(name=name, config=document, created=now,
                                                          config_updated=now))
                elif replace:
                    conn.execute(update(_machines).where(_machines.c.id == machine_id)
                                 .values(config=document, config_updated=now))
                else:
                    raise DataError(exists)
        except IntegrityError as exc:  # another process added it between our check and insert (PostgreSQL)
            raise DataError(exists) from exc

    def machines(self) -> list[str]:
        """Machine ids in alphabetical order."""
        with self._read() as conn:
            return list(conn.execute(select(_machines.c.name).order_by(_machines.c.name)).scalars())

    def machine_config(self, machine: str) -> dict[str, Any]:
        """The configuration stored for a machine.

        Parameters
        ----------
        machine : str
            A registered machine id.

        Returns
        -------
        dict
            The ``cappe.monitor-config/1`` document.

        Raises
        ------
        DataError
            The machine is not registered.
        """
        with self._read() as conn:
            machine_id = self._machine_id(conn, _name(machine, "machine id"))
            document = conn.execute(select(_machines.c.config).where(_machines.c.id == machine_id)).scalar_one()
        return _load_json(document)

    # -- baseline ----------------------------------------------------------------------------------------------

    def set_baseline(self, machine: str, baseline: Mapping[str, Any]) -> None:
        """Store a new healthy baseline for a machine; earlier ones stay in the history.

        Inside an ingest transaction use :meth:`IngestTransaction.set_baseline` instead.

        Parameters
        ----------
        machine : str
            A registered machine id.
        baseline : mapping
            The ``cappe.monitor-baseline/1`` document (JSON-serializable).

        Raises
        ------
        DataError
            The machine is not registered.
        """
        name = _name(machine, "machine id")
        document = _dump_json(baseline, f"baseline of machine {name!r}")
        with self._write() as conn:
            _insert_baseline(conn, self._machine_id(conn, name), document)

    def baseline(self, machine: str) -> dict[str, Any] | None:
        """The newest baseline of a machine, or None if none was stored.

        Parameters
        ----------
        machine : str
            A registered machine id.

        Returns
        -------
        dict or None
            The ``cappe.monitor-baseline/1`` document.

        Raises
        ------
        DataError
            The machine is not registered.
        """
        with self._read() as conn:
            machine_id = self._machine_id(conn, _name(machine, "machine id"))
            document = conn.execute(
                select(_baselines.c.document).where(_baselines.c.machine_id == machine_id)
                .order_by(_baselines.c.id.desc()).limit(1)
            ).scalar()
        return None if document is None else _load_json(document)

    # -- ingest ------------------------------------------------------------------------------------------------

    @contextmanager
    def transaction(self, machine: str) -> Iterator[IngestTransaction]:
        """One atomic ingest into a machine's history, serialized with every other ingest into that machine.

        Commits when the ``with`` block ends normally; rolls back (and re-raises) when it raises, leaving nothing
        of the ingest behind. The transaction holds the write lock (SQLite: of the whole file) until it ends, so
        keep slow computations outside it. One transaction per thread at a time.

        Parameters
        ----------
        machine : str
            Machine id (must exist).

        Yields
        ------
        IngestTransaction
        """
        name = _name(machine, "machine id")
        engine = self._live_engine()
        active = getattr(self._local, "machine", None)
        if active is not None:
            msg = (
                f"an ingest transaction for machine {active!r} is already open in this thread on history store "
                f"{self._display}; finish it before opening one for {name!r}"
            )
            raise DataError(msg)
        with engine.connect() as conn, self._begin_write(conn):
            machine_id = self._machine_id(conn, name, lock=True)
            tx = IngestTransaction(self, conn, name, machine_id)
            self._local.machine = name
            try:
                yield tx
            finally:
                tx._active = False
                self._local.machine = None

    # -- queries -----------------------------------------------------------------------------------------------

    def measurements(self, machine: str, *, since: datetime | None = None, until: datetime | None = None,
                     limit: int | None = None) -> list[MeasurementRecord]:
        """A machine's measurements in time order (then by id).

        Parameters
        ----------
        machine : str
            Machine id.
        since, until : datetime, optional
            Only those measured at or after ``since`` and at or before ``until`` (timezone-aware).
        limit : int, optional
            Only the newest ``limit`` of them (still returned oldest first).
        """
        name = _name(machine, "machine id")
        m = _measurements
        with self._read() as conn:
            query = select(m.c.id, m.c.timestamp, m.c.source, m.c.kind, m.c.conditions, m.c.meta,
                           m.c.frf.is_not(None)).where(m.c.machine_id == self._machine_id(conn, name))
            if since is not None:
                query = query.where(m.c.timestamp >= _timestamp(since, "since"))
            if until is not None:
                query = query.where(m.c.timestamp <= _timestamp(until, "until"))
            if limit is not None:
                if isinstance(limit, bool) or not isinstance(limit, numbers.Integral) or limit < 0:
                    msg = f"limit must be an integer >= 0 or None; got {limit!r}"
                    raise DataError(msg)
                query = query.order_by(m.c.timestamp.desc(), m.c.id.desc()).limit(int(limit))
            else:
                query = query.order_by(m.c.timestamp, m.c.id)
            rows = list(conn.execute(query))
        if limit is not None:
            rows.reverse()
        return [
            MeasurementRecord(id=row[0], machine=name, timestamp=row[1], source=row[2], kind=row[3],
                              conditions=_load_json(row[4]), meta=_load_json(row[5]), has_frf=bool(row[6]))
            for row in rows
        ]

    def latest_measurement(self, machine: str) -> MeasurementRecord | None:
        """A machine's newest measurement, or None if it has none.

        Parameters
        ----------
        machine : str
            A registered machine id.

        Returns
        -------
        MeasurementRecord or None

        Raises
        ------
        DataError
            The machine is not registered.
        """
        newest = self.measurements(machine, limit=1)
        return newest[0] if newest else None

    def features(self, machine: str, *, names: Sequence[str] | None = None) -> pd.DataFrame:
        """A machine's features, one row per (measurement, feature), in time order.

        Parameters
        ----------
        machine : str
            Machine id.
        names : sequence of str, optional
            Only these features.

        Returns
        -------
        pandas.DataFrame
            Columns ``measurement_id``, ``timestamp`` (UTC), ``name``, ``value``, ``std`` (NaN when unknown).
        """
        name = _name(machine, "machine id")
        wanted = _names(names, "feature names")
        f, m = _features, _measurements
        with self._read() as conn:
            query = (
                select(f.c.measurement_id, m.c.timestamp, f.c.name, f.c.value, f.c.std)
                .join(m, m.c.id == f.c.measurement_id)
                .where(m.c.machine_id == self._machine_id(conn, name))
                .order_by(m.c.timestamp, m.c.id, f.c.id)
            )
            if wanted is not None:
                query = query.where(f.c.name.in_(wanted))
            rows = list(conn.execute(query))
        return _frame(rows, ["measurement_id", "timestamp", "name", "value", "std"])

    def estimates(self, machine: str, *, path: str | None = None,
                  parameters: Sequence[str] | None = None) -> pd.DataFrame:
        """A machine's parameter estimates, one row per (measurement, path, parameter), in time order.

        Parameters
        ----------
        machine : str
            Machine id.
        path : str, optional
            Only those of this estimation path.
        parameters : sequence of str, optional
            Only these parameters.

        Returns
        -------
        pandas.DataFrame
            Columns ``measurement_id``, ``timestamp`` (UTC), ``path``, ``parameter``, ``value``, ``std`` (NaN when
            unknown).
        """
        name = _name(machine, "machine id")
        wanted = _names(parameters, "parameters")
        e, m = _estimates, _measurements
        with self._read() as conn:
            query = (
                select(e.c.measurement_id, m.c.timestamp, e.c.path, e.c.parameter, e.c.value, e.c.std)
                .join(m, m.c.id == e.c.measurement_id)
                .where(m.c.machine_id == self._machine_id(conn, name))
                .order_by(m.c.timestamp, m.c.id, e.c.id)
            )
            if path is not None:
                query = query.where(e.c.path == _name(path, "estimation path"))
            if wanted is not None:
                query = query.where(e.c.parameter.in_(wanted))
            rows = list(conn.execute(query))
        return _frame(rows, ["measurement_id", "timestamp", "path", "parameter", "value", "std"])

    def alarms(self, machine: str, *, unacknowledged: bool = False) -> list[AlarmRecord]:
        """A machine's alarms in time order (then by id); only the unacknowledged ones if asked.

        Parameters
        ----------
        machine : str
            A registered machine id.
        unacknowledged : bool
            Only the alarms not acknowledged yet.

        Returns
        -------
        list of AlarmRecord

        Raises
        ------
        DataError
            The machine is not registered.
        """
        name = _name(machine, "machine id")
        a, m = _alarms, _measurements
        with self._read() as conn:
            query = (
                select(a.c.id, a.c.measurement_id, m.c.timestamp, a.c.component, a.c.statistic, a.c.value,
                       a.c.severity, a.c.diagnosis, a.c.message, a.c.acknowledged)
                .join(m, m.c.id == a.c.measurement_id)
                .where(m.c.machine_id == self._machine_id(conn, name))
                .order_by(m.c.timestamp, a.c.id)
            )
            if unacknowledged:
                query = query.where(a.c.acknowledged.is_(False))
            rows = list(conn.execute(query))
        return [
            AlarmRecord(id=row[0], machine=name, measurement_id=row[1], timestamp=row[2], component=row[3],
                        statistic=row[4], value=row[5], severity=row[6], diagnosis=_load_json(row[7]),
                        message=row[8], acknowledged=bool(row[9]))
            for row in rows
        ]

    def acknowledge(self, alarm_id: int) -> None:
        """Mark an alarm as acknowledged (again is harmless).

        Parameters
        ----------
        alarm_id : int
            The alarm's id.

        Raises
        ------
        DataError
            No alarm has that id.
        """
        ident = _id(alarm_id, "alarm id")
        with self._write() as conn:
            done = conn.execute(
                update(_alarms).where(_alarms.c.id == ident)
                .values(acknowledged=True, acknowledged_at=func.coalesce(
                    _alarms.c.acknowledged_at, literal(datetime.now(UTC), _UTCTimestamp())))
            ).rowcount
            if done == 0:
                msg = f"no alarm with id {ident} in history store {self._display}"
                raise DataError(msg)

    def frf(self, measurement_id: int) -> FRFData | None:
        """The FRF stored with a measurement, or None if it has none.

        Parameters
        ----------
        measurement_id : int
            The measurement's id.

        Returns
        -------
        FRFData or None

        Raises
        ------
        DataError
            No measurement has that id.
        """
        ident = _id(measurement_id, "measurement id")
        with self._read() as conn:
            row = conn.execute(select(_measurements.c.frf).where(_measurements.c.id == ident)).first()
        if row is None:
            msg = f"no measurement with id {ident} in history store {self._display}"
            raise DataError(msg)
        return None if row[0] is None else decode_frf(row[0])

    def counts(self, machine: str) -> dict[str, int]:
        """How many measurements, features, estimates and alarms a machine has.

        Parameters
        ----------
        machine : str
            A registered machine id.

        Returns
        -------
        dict
            ``{"measurements", "features", "estimates", "alarms": count}``.

        Raises
        ------
        DataError
            The machine is not registered.
        """
        name = _name(machine, "machine id")
        m = _measurements
        with self._read() as conn:
            mine = select(m.c.id).where(m.c.machine_id == self._machine_id(conn, name)).scalar_subquery()
            result = {"measurements": conn.execute(select(func.count()).where(m.c.id.in_(mine))).scalar_one()}
            for key, table in (("features", _features), ("estimates", _estimates), ("alarms", _alarms)):
                query = select(func.count()).select_from(table).where(table.c.measurement_id.in_(mine))
                result[key] = conn.execute(query).scalar_one()
        return {key: int(value) for key, value in result.items()}


def _insert_baseline(conn: Connection, machine_id: int, document: str) -> None:
    conn.execute(insert(_baselines).values(machine_id=machine_id, created=datetime.now(UTC),
                                           document=document))


def _frame(rows: Sequence[Any], columns: list[str]) -> pd.DataFrame:
    import pandas as pd

    data: dict[str, Any] = {}
    for k, column in enumerate(columns):
        values = [row[k] for row in rows]
        if column == "measurement_id":
            data[column] = np.array(values, dtype=np.int64)
        elif column == "timestamp":
            data[column] = pd.to_datetime(pd.Series(values, dtype=object), utc=True).astype("datetime64[us, UTC]")
        elif column in ("value", "std"):
            data[column] = np.array([math.nan if v is None else v for v in values], dtype=np.float64)
        else:
            data[column] = pd.Series(values, dtype=object)
    return pd.DataFrame(data, columns=columns)


class IngestTransaction:
    """Writes of one ingest into one machine; only valid inside ``with store.transaction(machine) as tx:``.

    Made by :meth:`HistoryStore.transaction`, not directly. Every method raises :class:`DataError` once the
    ``with`` block has ended.

    Parameters
    ----------
    store : HistoryStore
        The store.
    conn : sqlalchemy.engine.Connection
        The open connection of the transaction (holding the machine's lock).
    machine : str
        The machine id.
    machine_id : int
        Its row id in the store.

    Attributes
    ----------
    machine : str
        The machine id.
    """

    def __init__(self, store: HistoryStore, conn: Connection, machine: str, machine_id: int) -> None:
        self._store = store
        self._conn = conn
        self.machine = machine
        self._machine_id = machine_id
        self._active = True

    def __repr__(self) -> str:
        status = "open" if self._active else "ended"
        return f"<IngestTransaction machine={self.machine!r} on {self._store._display} ({status})>"

    def _connection(self) -> Connection:
        if not self._active:
            msg = (
                f"the ingest transaction for machine {self.machine!r} has ended; "
                f"open a new one with store.transaction({self.machine!r})"
            )
            raise DataError(msg)
        return self._conn

    def _own_measurement(self, conn: Connection, measurement_id: int) -> int:
        ident = _id(measurement_id, "measurement id")
        owner = conn.execute(
            select(_machines.c.name).join(_measurements, _measurements.c.machine_id == _machines.c.id)
            .where(_measurements.c.id == ident)
        ).scalar()
        if owner is None:
            msg = f"no measurement with id {ident} in history store {self._store._display}"
            raise DataError(msg)
        if owner != self.machine:
            msg = f"measurement {ident} belongs to machine {owner!r}, not to {self.machine!r} of this transaction"
            raise DataError(msg)
        return ident

    def state(self) -> dict[str, Any] | None:
        """The machine's detector state (None before the first :meth:`set_state`), read under the ingest lock."""
        conn = self._connection()
        document = conn.execute(select(_machines.c.state).where(_machines.c.id == self._machine_id)).scalar()
        return None if document is None else _load_json(document)

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Replace the machine's detector state (JSON document).

        Parameters
        ----------
        state : mapping
            The state (JSON-serializable), as :meth:`Monitor.step` returns it.
        """
        conn = self._connection()
        document = _dump_json(state, f"detector state of machine {self.machine!r}")
        conn.execute(update(_machines).where(_machines.c.id == self._machine_id)
                     .values(state=document, state_updated=datetime.now(UTC)))

    def set_baseline(self, baseline: Mapping[str, Any]) -> None:
        """Store a new baseline for the machine as part of this ingest (see :meth:`HistoryStore.set_baseline`).

        Parameters
        ----------
        baseline : mapping
            The ``cappe.monitor-baseline/1`` document (JSON-serializable).
        """
        conn = self._connection()
        _insert_baseline(conn, self._machine_id, _dump_json(baseline, f"baseline of machine {self.machine!r}"))

    def add_measurement(self, *, timestamp: datetime, source: str, kind: str,
                        conditions: Mapping[str, float] | None = None, frf: FRFData | None = None,
                        meta: Mapping[str, Any] | None = None) -> int:
        """Record a measurement; returns its id.

        Parameters
        ----------
        timestamp : datetime
            When it was measured (timezone-aware).
        source : str
            Where it came from; recording the same source twice for one machine is an error.
        kind : str
            What it is (``"impact"``, ``"operational"``, ...).
        conditions : mapping of str to float, optional
            Operating conditions (finite numbers).
        frf : FRFData, optional
            The measured FRF, stored losslessly (:func:`encode_frf`).
        meta : mapping, optional
            Free metadata (JSON document).
        """
        conn = self._connection()
        when = _timestamp(timestamp, f"measurement timestamp of machine {self.machine!r}")
        source = _name(source, "measurement source")
        kind = _name(kind, f"measurement kind of {source!r}")
        values = {
            _name(key, f"condition name of measurement {source!r}"):
                _finite(value, f"condition {key!r} of measurement {source!r}")
            for key, value in _mapping(conditions or {}, f"conditions of measurement {source!r}").items()
        }
        blob = None if frf is None else encode_frf(frf)
        meta_document = _dump_json(meta or {}, f"meta of measurement {source!r}")
        existing = conn.execute(
            select(_measurements.c.id)
            .where(_measurements.c.machine_id == self._machine_id, _measurements.c.source == source)
        ).scalar()
        if existing is not None:
            msg = f"measurement source {source!r} is already recorded for machine {self.machine!r} (id {existing})"
            raise DataError(msg)
        result = conn.execute(insert(_measurements).values(
            machine_id=self._machine_id, timestamp=when, source=source, kind=kind,
            conditions=json.dumps(values), meta=meta_document, frf=blob,
        ).returning(_measurements.c.id))
        return int(result.scalar_one())

    def add_features(self, measurement_id: int, features: Mapping[str, tuple[float, float | None]]) -> None:
        """Record features of a measurement.

        Parameters
        ----------
        measurement_id : int
            A measurement of this machine.
        features : mapping of str to (float, float or None)
            ``name -> (value, std)``; the value must be finite, the std is >= 0 or None/NaN (unknown).
        """
        conn = self._connection()
        ident = self._own_measurement(conn, measurement_id)
        rows = []
        for key, pair in _mapping(features, "features").items():
            name = _name(key, f"feature name of measurement {ident}")
            if isinstance(pair, (str, bytes)) or not isinstance(pair, Sequence) or len(pair) != 2:
                msg = f"feature {name!r} of measurement {ident} must be a pair (value, std); got {pair!r}"
                raise DataError(msg)
            rows.append({"measurement_id": ident, "name": name,
                         "value": _finite(pair[0], f"feature {name!r} value of measurement {ident}"),
                         "std": _std(pair[1], f"feature {name!r} std of measurement {ident}")})
        if not rows:
            return
        repeated = list(conn.execute(
            select(_features.c.name)
            .where(_features.c.measurement_id == ident, _features.c.name.in_([r["name"] for r in rows]))
        ).scalars())
        if repeated:
            msg = f"features {sorted(repeated)} are already recorded for measurement {ident}"
            raise DataError(msg)
        conn.execute(insert(_features), rows)

    def add_estimates(self, measurement_id: int, *, path: str, values: Mapping[str, float],
                      std: Mapping[str, float] | None = None) -> None:
        """Record parameter estimates of a measurement.

        Parameters
        ----------
        measurement_id : int
            A measurement of this machine.
        path : str
            The estimation path (e.g. ``"factors"``, ``"modal"``).
        values : mapping of str to float
            ``parameter -> estimate`` (finite).
        std : mapping of str to float, optional
            ``parameter -> standard deviation`` for some or all of ``values`` (>= 0, or NaN for unknown).
        """
        conn = self._connection()
        ident = self._own_measurement(conn, measurement_id)
        path = _name(path, f"estimation path of measurement {ident}")
        spreads = dict(_mapping(std or {}, f"std of estimates {path!r}"))
        values = _mapping(values, f"values of estimates {path!r}")
        extra = sorted(set(spreads) - set(values))
        if extra:
            msg = f"std of estimates {path!r} of measurement {ident} names parameters without a value: {extra}"
            raise DataError(msg)
        rows = []
        for key, value in values.items():
            parameter = _name(key, f"parameter name of estimates {path!r}")
            where = f"estimate {path!r}/{parameter!r} of measurement {ident}"
            rows.append({"measurement_id": ident, "path": path, "parameter": parameter,
                         "value": _finite(value, f"{where} value"), "std": _std(spreads.get(key), f"{where} std")})
        if not rows:
            return
        repeated = list(conn.execute(
            select(_estimates.c.parameter)
            .where(_estimates.c.measurement_id == ident, _estimates.c.path == path,
                   _estimates.c.parameter.in_([r["parameter"] for r in rows]))
        ).scalars())
        if repeated:
            msg = f"estimates {sorted(repeated)} of path {path!r} are already recorded for measurement {ident}"
            raise DataError(msg)
        conn.execute(insert(_estimates), rows)

    def add_alarm(self, measurement_id: int, *, component: str, statistic: str, value: float, severity: str,
                  diagnosis: Mapping[str, Any], message: str) -> int:
        """Record an alarm raised by a measurement; returns its id.

        Parameters
        ----------
        measurement_id : int
            A measurement of this machine.
        component, statistic : str
            What alarmed and by which test statistic.
        value : float
            The statistic's value (finite).
        severity : str
            Severity grade.
        diagnosis : mapping
            The detector's diagnosis (JSON document).
        message : str
            Human-readable text.
        """
        conn = self._connection()
        ident = self._own_measurement(conn, measurement_id)
        where = f"alarm of measurement {ident}"
        row = {
            "measurement_id": ident,
            "component": _name(component, f"{where}: component"),
            "statistic": _name(statistic, f"{where}: statistic"),
            "value": _finite(value, f"{where}: value"),
            "severity": _name(severity, f"{where}: severity"),
            "diagnosis": _dump_json(diagnosis, f"{where}: diagnosis"),
            "message": _name(message, f"{where}: message"),
            "acknowledged": False,
        }
        return int(conn.execute(insert(_alarms).values(**row).returning(_alarms.c.id)).scalar_one())
