"""Fixtures of the monitoring tests: the compiled spindle and rig models, and a throw-away PostgreSQL server for
the ``postgres``-marked tests."""

from __future__ import annotations

import os
from collections.abc import Iterator
from typing import NoReturn

import pytest
from _postgres import PostgresServer, find_server_binaries

from cappe.model import NumericModel, load_model
from cappe.monitor import MonitorConfig, default_config

_DATABASE = "cappe_test"

#: The output channels of :func:`spindle_config`.
SPINDLE_OUTPUTS = ("sx", "sy", "hax", "hay", "haz", "htax")


@pytest.fixture(scope="session")
def spindle() -> NumericModel:
    """The compiled spindle-bearing model (immutable, shared by the session)."""
    return NumericModel(load_model("builtin:spindle-bearing"))


@pytest.fixture(scope="session")
def spindle_config(spindle: NumericModel) -> MonitorConfig:
    """The spindle as the monitoring tests watch it: machine 'spindle-01', the six accelerometer and probe channels
    sx, sy, hax, hay, haz, htax, 150-1000 Hz (a frozen config, shared by the session)."""
    return default_config(spindle, machine="spindle-01", source="builtin:spindle-bearing", outputs=SPINDLE_OUTPUTS,
                          band=(150.0, 1000.0))


@pytest.fixture(scope="session")
def rig() -> NumericModel:
    """The compiled two-mass rig."""
    return NumericModel(load_model("builtin:two-mass-rig"))


def _unavailable(reason: str) -> NoReturn:
    """Skip, or fail where CI promises the service (CAPPE_REQUIRE_SERVICES=1)."""
    if os.environ.get("CAPPE_REQUIRE_SERVICES") == "1":
        pytest.fail(f"{reason}, and CAPPE_REQUIRE_SERVICES=1 requires it")
    pytest.skip(reason)


@pytest.fixture(scope="session")
def postgres_server() -> Iterator[PostgresServer]:
    """A PostgreSQL server started for this test session (initdb + pg_ctl in a temporary folder), with an
    empty database ``cappe_test``."""
    try:
        import psycopg  # noqa: F401
    except ImportError:
        _unavailable("the PostgreSQL driver psycopg is not installed (pip install 'cappe[postgres]')")
    bindir = find_server_binaries()
    if bindir is None:
        _unavailable("no PostgreSQL server binaries (initdb, pg_ctl, postgres) in /usr/lib/postgresql/*/bin, "
                     "on PATH or in /usr/local/bin")
    server = PostgresServer(bindir)
    try:
        server.execute(f"CREATE DATABASE {_DATABASE}")
        yield server
    finally:
        server.stop()


@pytest.fixture
def postgres_database(postgres_server: PostgresServer) -> str:
    """The SQLAlchemy URL of the session's test database, emptied for this test (a fresh ``public`` schema:
    much faster than a new database per test)."""
    postgres_server.execute("DROP SCHEMA IF EXISTS public CASCADE", database=_DATABASE)
    postgres_server.execute("CREATE SCHEMA public", database=_DATABASE)
    return postgres_server.url(_DATABASE)
