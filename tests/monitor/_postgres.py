"""A throw-away PostgreSQL server for the tests: ``initdb`` + ``pg_ctl`` in a temporary folder.

The server listens on a free TCP port of 127.0.0.1 (its unix socket lives in the same temporary folder), accepts
every local connection without a password (``trust``) and runs without fsync: it only has to live as long as the
test session. ``initdb`` refuses to run as root, so under root every server command runs as the unprivileged user
``postgres`` (or ``nobody``) through ``runuser``, and the temporary folder is handed to that user.
"""

from __future__ import annotations

import contextlib
import glob
import os
import pwd
import re
import shutil
import socket
import subprocess
import tempfile
from pathlib import Path

__all__ = ["PostgresServer", "find_server_binaries"]

_SUPERUSER = "cappe"


def _version_key(folder: str) -> tuple[int, ...]:
    return tuple(int(part) for part in re.findall(r"\d+", folder))


def find_server_binaries() -> Path | None:
    """The folder holding ``initdb``, ``pg_ctl`` and ``postgres``, newest version first; None if there is none.

    Searched: ``/usr/lib/postgresql/<version>/bin`` (Debian), the folders of ``initdb`` on PATH and
    ``/usr/local/bin`` (symbolic links are followed to the real installation).
    """
    candidates = sorted(glob.glob("/usr/lib/postgresql/*/bin"), key=_version_key, reverse=True)
    for name in (shutil.which("initdb"), "/usr/local/bin/initdb"):
        if name and os.path.exists(name):
            candidates.append(str(Path(name).resolve().parent))
    for folder in candidates:
        if all(os.access(os.path.join(folder, tool), os.X_OK) for tool in ("initdb", "pg_ctl", "postgres")):
            return Path(folder)
    return None


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


class PostgresServer:
    """A running throw-away server; :meth:`stop` shuts it down and removes its files.

    Parameters
    ----------
    bindir : Path
        Folder with ``initdb`` and ``pg_ctl`` (:func:`find_server_binaries`).
    """

    def __init__(self, bindir: Path) -> None:
        self.bindir = bindir
        self.root = Path(tempfile.mkdtemp(prefix="cappe-pg-"))
        self.data = self.root / "data"
        self.log = self.root / "server.log"
        self.port = 0
        self._prefix: list[str] = []
        if os.geteuid() == 0:
            user = self._unprivileged_user()
            entry = pwd.getpwnam(user)
            os.chown(self.root, entry.pw_uid, entry.pw_gid)
            self._prefix = ["runuser", "-u", user, "--"]
        try:
            self._run("initdb", "-D", str(self.data), "-U", _SUPERUSER, "-A", "trust", "-E", "UTF8",
                      "--no-locale", "--no-sync")
            self._start()
        except BaseException:
            shutil.rmtree(self.root, ignore_errors=True)
            raise

    @staticmethod
    def _unprivileged_user() -> str:
        if shutil.which("runuser") is None:
            msg = "running as root, and 'runuser' is missing: cannot start PostgreSQL as an unprivileged user"
            raise RuntimeError(msg)
        for user in ("postgres", "nobody"):
            with contextlib.suppress(KeyError):
                pwd.getpwnam(user)
                return user
        msg = "running as root, and neither user 'postgres' nor 'nobody' exists to run PostgreSQL"
        raise RuntimeError(msg)

    def _run(self, tool: str, *args: str) -> None:
        command = [*self._prefix, str(self.bindir / tool), *args]
        done = subprocess.run(command, cwd=self.root, capture_output=True, text=True, timeout=120, check=False)
        if done.returncode != 0:
            log = self.log.read_text() if self.log.exists() else ""
            msg = f"{' '.join(command)} failed ({done.returncode}):\n{done.stdout}\n{done.stderr}\n{log}"
            raise RuntimeError(msg)

    def _start(self) -> None:
        # a port found free may be taken before the server binds it: try a few
        for attempt in range(3):
            self.port = _free_port()
            options = (
                f"-p {self.port} -c listen_addresses=127.0.0.1 -c unix_socket_directories={self.root} "
                "-c fsync=off -c synchronous_commit=off -c full_page_writes=off -c max_connections=40"
            )
            try:
                self._run("pg_ctl", "start", "-w", "-t", "60", "-D", str(self.data), "-l", str(self.log),
                          "-o", options)
            except RuntimeError:
                if attempt == 2:
                    raise
            else:
                return

    def url(self, database: str = "postgres", *, password: str | None = None) -> str:
        """SQLAlchemy URL of a database on this server (trust authentication ignores any password)."""
        user = _SUPERUSER if password is None else f"{_SUPERUSER}:{password}"
        return f"postgresql+psycopg://{user}@127.0.0.1:{self.port}/{database}"

    def execute(self, statement: str, database: str = "postgres") -> None:
        """Run one statement in autocommit mode (``CREATE DATABASE`` and the like)."""
        import psycopg

        with psycopg.connect(host="127.0.0.1", port=self.port, user=_SUPERUSER, dbname=database,
                             autocommit=True) as conn:
            conn.execute(statement)

    def stop(self) -> None:
        """Stop the server and remove its folder."""
        try:
            self._run("pg_ctl", "stop", "-D", str(self.data), "-m", "immediate", "-w", "-t", "60")
        finally:
            shutil.rmtree(self.root, ignore_errors=True)
