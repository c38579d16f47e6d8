"""``cappe monitor serve``: a local web dashboard of one history store.

:func:`make_server` serves a self-contained page (HTML, JavaScript and CSS shipped in ``cappe/monitor/dashboard``;
no external scripts, charts drawn as inline SVG) and a JSON API that reads the store on every request, so a new
ingest shows on the next reload:

==========================================  =========================================================================
``GET /api/machines``                       machine ids with their model, number of measurements and worst active
                                            alarm severity
``GET /api/machine/<id>/status``            latest measurement, the latest fast-path estimate of every component with
                                            its std and the baseline mean/std, number of measurements, active
                                            (unacknowledged) alarms and their worst severity
``GET /api/machine/<id>/trends``            per component: fast-path and slow-path estimates over time with std, the
                                            baseline mean, std and band; the FRF correlation ``csf`` over time
``GET /api/machine/<id>/alarms``            every alarm, newest first, with its diagnosis
``POST /api/alarm/<id>/acknowledge``        acknowledge one alarm
``GET /api/machine/<id>/frf``               ``|H|`` of the latest measurement with an FRF against the baseline's mean
                                            ``|H|``
``GET /api/machine/<id>/map``               the baseline's frequency-damping map and the current point (the latest
                                            ``freq_k`` / ``zeta_k`` features of the map's modes)
==========================================  =========================================================================

Every request must name the server in its ``Host`` header (DNS rebinding: a page of another site whose name
resolves to this computer would otherwise read the store and acknowledge alarms): the address it listens on, on a
loopback or wildcard (``0.0.0.0``) interface also ``localhost``, ``127.0.0.1`` and ``[::1]``, and any name given
in ``allowed_hosts``, each with the served port or without one. Other hosts, and requests without exactly one
``Host`` header, are answered 421 with a short plain-text message, whatever the method and path.
Unknown machines, alarms and paths answer 404, failures inside the server 500, both as ``{"error": message}``.
Numbers that are not finite are sent as ``null``. Store access is serialized by a lock, so a store whose
connection may not be shared between threads is safe behind the threaded server.
"""

from __future__ import annotations

import contextlib
import functools
import ipaddress
import json
import math
import os
import re
import socket
import threading
import urllib.parse
from collections.abc import Callable, Mapping, Sequence
from datetime import datetime
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
from sqlalchemy.engine import make_url
from sqlalchemy.exc import ArgumentError

from cappe._logging import get_logger
from cappe.exceptions import DataError
from cappe.monitor._config import SEVERITY_GRADES, worst_severity

if TYPE_CHECKING:
    from cappe.monitor._store import HistoryStore

__all__ = ["DashboardServer", "make_server"]

_log = get_logger(__name__)

#: Static files of the page: name -> content type.
_ASSETS = {
    "index.html": "text/html; charset=utf-8",
    "app.js": "text/javascript; charset=utf-8",
    "style.css": "text/css; charset=utf-8",
    "favicon.svg": "image/svg+xml",
}
#: Earlier measurements drawn as a trail behind the current point of the frequency-damping map.
_MAP_TRAIL = 20
#: Largest request body read (the API takes no body; anything bigger is refused).
_MAX_BODY = 1 << 16

_MACHINE_ROUTE = re.compile(r"^/api/machine/(?P<machine>[^/]+)/(?P<view>status|trends|alarms|frf|map)$")
_ACK_ROUTE = re.compile(r"^/api/alarm/(?P<alarm>[^/]+)/acknowledge$")
#: Names of this computer's loopback interface, accepted in the Host header of a loopback or wildcard bind.
_LOOPBACK_NAMES = ("localhost", "127.0.0.1", "::1")
#: A DNS host name (labels of letters, digits, '-' and '_', dot-separated, an optional final dot).
_HOST_NAME = re.compile(r"^(?!-)[a-z0-9_-]{1,63}(?<!-)(\.(?!-)[a-z0-9_-]{1,63}(?<!-))*\.?$")


class _NotFound(LookupError):
    """A request names a machine, alarm or path that does not exist (answered with 404)."""


class _MethodNotAllowed(LookupError):
    """A known path asked with the wrong method (answered with 405)."""


class _Forbidden(PermissionError):
    """A state-changing request from another origin (answered with 403)."""


# --------------------------------------------------------------------------------------------- host names


def _host_name(text: str) -> str | None:
    """A host name or IP address in the form the Host check compares: lower case, IPv6 without brackets, no final
    dot; None when ``text`` is neither."""
    name = text.strip().lower()
    if name.startswith("[") and name.endswith("]"):
        name = name[1:-1]
    with contextlib.suppress(ValueError):
        return ipaddress.ip_address(name).compressed
    if len(name) > 254 or not _HOST_NAME.match(name):
        return None
    return name.rstrip(".")


def _served_names(host: str, bound: str, allowed: Sequence[str]) -> tuple[str, ...]:
    """Host names a server bound to ``bound`` (asked for as ``host``) answers to, besides ``allowed``.

    Every bind answers to its address and to the name it was asked for by; loopback and wildcard (``0.0.0.0``,
    ``::``) binds also to the loopback names.
    """
    names: list[str] = []
    for text in (host, bound):
        name = _host_name(text)
        if name is None:
            continue
        try:
            address = ipaddress.ip_address(name)
        except ValueError:  # a name such as localhost or the computer's own
            names.append(name)
            continue
        if address.is_loopback or address.is_unspecified:
            names += _LOOPBACK_NAMES
        names.append(name)  # also 0.0.0.0: the server's url, which some browsers take for this computer
    names += allowed
    return tuple(dict.fromkeys(names))


def _split_host(header: str) -> tuple[str | None, int | None]:
    """Host and port of a Host header (``name``, ``name:port``, ``[v6]:port``); host None when malformed, port None
    when absent."""
    host, port_text = header, ""
    if header.startswith("["):
        close = header.find("]")
        if close < 0:
            return None, None
        host, rest = header[: close + 1], header[close + 1 :]
        if rest and not rest.startswith(":"):
            return None, None
        port_text = rest[1:]
    elif header.count(":") == 1:
        host, port_text = header.split(":")
    elif ":" in header:  # an IPv6 address must be bracketed
        return None, None
    if port_text and not (port_text.isascii() and port_text.isdigit() and len(port_text) <= 5):
        return None, None
    if header.endswith(":"):
        return None, None
    return _host_name(host), int(port_text) if port_text else None


def _allowed_hosts(allowed: Sequence[str] | str | None) -> tuple[str, ...]:
    """Checked, normalized ``allowed_hosts`` of :func:`make_server`."""
    if allowed is None:
        return ()
    if isinstance(allowed, str):
        allowed = [allowed]
    names = []
    for text in allowed:
        name = _host_name(text) if isinstance(text, str) else None
        if name is None:
            msg = (
                "dashboard allowed host must be a host name or IP address without port, scheme or path "
                f"(dashboard.example.org, 192.0.2.7, [2001:db8::7]); got {text!r}"
            )
            raise DataError(msg)
        names.append(name)
    return tuple(names)


# --------------------------------------------------------------------------------------------- JSON helpers


def _jsonable(obj: Any) -> Any:
    """Plain JSON types of ``obj``: numpy scalars and arrays unpacked, NaN/inf as None, datetimes in ISO 8601."""
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        value = float(obj)
        return value if math.isfinite(value) else None
    if obj is pd.NaT:
        return None
    if isinstance(obj, datetime):
        return obj.isoformat()
    if isinstance(obj, Mapping):
        return {str(key): _jsonable(value) for key, value in obj.items()}
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (list, tuple)):
        return [_jsonable(value) for value in obj]
    return str(obj)


def _number(value: Any) -> float | None:
    """A finite float, or None for missing / NaN / non-numeric values."""
    if value is None:
        return None
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    return number if math.isfinite(number) else None


def _format(value: float | None, digits: int) -> str:
    """``value`` to ``digits`` significant digits, trailing zeros kept (``0.9000``); an en dash when missing."""
    return "\u2013" if value is None else f"{value:#.{digits}g}"


def _sorted_frame(frame: pd.DataFrame) -> pd.DataFrame:
    """Rows in time order (measurement id breaks ties), a fresh index."""
    if frame.empty:
        return frame
    return frame.sort_values(["timestamp", "measurement_id"], kind="stable").reset_index(drop=True)


def _series(frame: pd.DataFrame) -> dict[str, list[Any]]:
    """Columns of an estimates/features frame as JSON lists."""
    return {
        "measurement_id": [int(v) for v in frame["measurement_id"]],
        "timestamp": [_jsonable(v) for v in frame["timestamp"]],
        "value": [_number(v) for v in frame["value"]],
        "std": [_number(v) for v in frame["std"]],
    }


# --------------------------------------------------------------------------------------------- the API


class _Api:
    """Answers of the JSON API, read from the store on every call (callers hold the store lock)."""

    def __init__(self, store: HistoryStore) -> None:
        self.store = store

    # -- lookups

    def _machine(self, machine: str) -> dict[str, Any]:
        if machine not in self.store.machines():
            msg = f"machine {machine!r} is not in the history store"
            raise _NotFound(msg)
        return dict(self.store.machine_config(machine))

    def _components(self, config: Mapping[str, Any], names: Sequence[str]) -> list[dict[str, str]]:
        """The configured components in their order, then any other estimated parameter, with labels."""
        components: list[dict[str, str]] = []
        for component in config.get("components") or []:
            if isinstance(component, Mapping) and "name" in component:
                name = str(component["name"])
                components.append({"name": name, "label": str(component.get("label") or name)})
        known = {c["name"] for c in components}
        components += [{"name": str(n), "label": str(n)} for n in sorted(set(names) - known)]
        return components

    @staticmethod
    def _baseline_of(baseline: Mapping[str, Any] | None, name: str) -> dict[str, Any]:
        """Baseline mean, std and band of one component; the band is the stored limits or mean +- 2 std."""
        baseline = baseline or {}
        mean = _number((baseline.get("mean") or {}).get(name))
        std = _number((baseline.get("std") or {}).get(name))
        limits = (baseline.get("limits") or {}).get(name)
        band: list[float | None] | None = None
        source = None
        if isinstance(limits, Sequence) and len(limits) == 2:
            band, source = [_number(limits[0]), _number(limits[1])], "limits"
        elif mean is not None and std is not None:
            band, source = [mean - 2.0 * std, mean + 2.0 * std], "2 std"
        return {"mean": mean, "std": std, "band": band, "band_source": source}

    @staticmethod
    def _alarm(alarm: Any, labels: Mapping[str, str]) -> dict[str, Any]:
        diagnosis = alarm.diagnosis if isinstance(alarm.diagnosis, Mapping) else {}
        probability = _number(diagnosis.get("probability"))
        return {
            "id": int(alarm.id),
            "machine": alarm.machine,
            "measurement_id": _jsonable(alarm.measurement_id),
            "timestamp": _jsonable(alarm.timestamp),
            "component": alarm.component,
            "component_label": labels.get(alarm.component, alarm.component),
            "statistic": alarm.statistic,
            "value": _number(alarm.value),
            "severity": alarm.severity,
            "diagnosis": _jsonable(diagnosis),
            "probability": probability,
            "probability_text": "\u2013" if probability is None else f"{100.0 * probability:.1f} %",
            "message": alarm.message,
            "acknowledged": bool(alarm.acknowledged),
        }

    @staticmethod
    def _measurement(record: Any) -> dict[str, Any] | None:
        if record is None:
            return None
        return {
            "id": int(record.id),
            "timestamp": _jsonable(record.timestamp),
            "source": record.source,
            "kind": record.kind,
            "conditions": _jsonable(record.conditions or {}),
            "has_frf": bool(record.has_frf),
        }

    # -- endpoints

    def machines(self) -> dict[str, Any]:
        rows = []
        for machine in self.store.machines():
            config = self.store.machine_config(machine)
            active = self.store.alarms(machine, unacknowledged=True)
            rows.append({
                "id": machine,
                "model": _jsonable(config.get("model")),
                "n_measurements": len(self.store.measurements(machine)),
                "active_alarms": len(active),
                "worst_severity": worst_severity([a.severity for a in active]),
            })
        return {"machines": rows}

    def status(self, machine: str) -> dict[str, Any]:
        config = self._machine(machine)
        baseline = self.store.baseline(machine)
        fast = _sorted_frame(self.store.estimates(machine, path="fast"))
        # the chain records each measurement's change from the healthy expectation at its own operating
        # conditions (temperature-compensated) as path "deviation", with the charts' standard deviation
        deviation = _sorted_frame(self.store.estimates(machine, path="deviation"))
        names = [str(n) for n in fast["parameter"].unique()] if not fast.empty else []
        components = []
        for component in self._components(config, names):
            rows = fast[fast["parameter"] == component["name"]] if not fast.empty else fast
            last = rows.iloc[-1] if len(rows) else None
            value = None if last is None else _number(last["value"])
            std = None if last is None else _number(last["std"])
            base = self._baseline_of(baseline, component["name"])
            mean, base_std = base["mean"], base["std"]
            change = None if value is None or mean in (None, 0.0) else value / mean - 1.0
            z = None if value is None or mean is None or not base_std else (value - mean) / base_std
            if last is not None and not deviation.empty:
                dev = deviation[(deviation["parameter"] == component["name"])
                                & (deviation["measurement_id"] == last["measurement_id"])]
                dev_value = _number(dev.iloc[-1]["value"]) if len(dev) else None
                dev_std = _number(dev.iloc[-1]["std"]) if len(dev) else None
                if dev_value is not None and dev_value > -1.0:
                    change = dev_value
                    z = float(np.log1p(dev_value)) / dev_std if dev_std else None
            components.append({
                **component,
                "measurement_id": None if last is None else int(last["measurement_id"]),
                "timestamp": None if last is None else _jsonable(last["timestamp"]),
                "value": value,
                "std": std,
                "value_text": _format(value, 4),
                "std_text": _format(std, 2),
                "baseline_mean": mean,
                "baseline_std": base_std,
                "baseline_band": base["band"],
                "change": change,
                "z": z,
            })
        active = self.store.alarms(machine, unacknowledged=True)
        features = _sorted_frame(self.store.features(machine, names=["csf", "frac"]))
        latest_features = {}
        for name in ("csf", "frac"):
            rows = features[features["name"] == name] if not features.empty else features
            latest_features[name] = _number(rows.iloc[-1]["value"]) if len(rows) else None
        return {
            "machine": machine,
            "model": _jsonable(config.get("model")),
            "n_measurements": len(self.store.measurements(machine)),
            "latest_measurement": self._measurement(self.store.latest_measurement(machine)),
            "has_baseline": baseline is not None,
            "baseline_created": None if baseline is None else _jsonable(baseline.get("created")),
            "components": components,
            "features": latest_features,
            "active_alarms": len(active),
            "worst_severity": worst_severity([a.severity for a in active]),
            "severity_grades": list(SEVERITY_GRADES),
        }

    def trends(self, machine: str) -> dict[str, Any]:
        config = self._machine(machine)
        baseline = self.store.baseline(machine)
        estimates = _sorted_frame(self.store.estimates(machine))
        names = [str(n) for n in estimates["parameter"].unique()] if not estimates.empty else []
        empty: dict[str, list[Any]] = {"measurement_id": [], "timestamp": [], "value": [], "std": []}
        components = []
        for component in self._components(config, names):
            out: dict[str, Any] = {**component, "baseline": self._baseline_of(baseline, component["name"])}
            for path in ("fast", "slow"):
                if estimates.empty:
                    out[path] = empty
                    continue
                rows = estimates[(estimates["parameter"] == component["name"]) & (estimates["path"] == path)]
                out[path] = _series(rows)
            components.append(out)
        features = _sorted_frame(self.store.features(machine, names=["csf"]))
        csf = empty if features.empty else _series(features[features["name"] == "csf"])
        return {"machine": machine, "components": components, "csf": csf}

    def alarms(self, machine: str) -> dict[str, Any]:
        config = self._machine(machine)
        labels = {c["name"]: c["label"] for c in self._components(config, [])}
        alarms = sorted(self.store.alarms(machine), key=lambda a: (a.timestamp, a.id), reverse=True)
        return {"machine": machine, "alarms": [self._alarm(a, labels) for a in alarms]}

    def frf(self, machine: str) -> dict[str, Any]:
        self._machine(machine)
        baseline = self.store.baseline(machine)
        reference = None
        stored = (baseline or {}).get("frf")
        if isinstance(stored, Mapping):
            reference = {
                "freq": _jsonable(stored.get("freq")),
                "input_names": _jsonable(stored.get("input_names")),
                "output_names": _jsonable(stored.get("output_names")),
                "magnitude": _jsonable(stored.get("magnitude")),
            }
        answer: dict[str, Any] = {"machine": machine, "measurement": None, "baseline": reference}
        for record in reversed(self.store.measurements(machine)):
            if not record.has_frf:
                continue
            data = self.store.frf(int(record.id))
            if data is None:
                continue
            answer["measurement"] = {
                "id": int(record.id),
                "timestamp": _jsonable(record.timestamp),
                "freq": _jsonable(data.freq),
                "input_names": list(data.input_names),
                "output_names": list(data.output_names),
                "magnitude": _jsonable(np.abs(data.H)),
            }
            break
        return answer

    def map(self, machine: str) -> dict[str, Any]:
        self._machine(machine)
        stored = (self.store.baseline(machine) or {}).get("map")
        preload_map = _jsonable(stored) if isinstance(stored, Mapping) else None
        features = self.store.features(machine)
        if preload_map is not None and preload_map.get("modes"):
            modes = [int(m) for m in preload_map["modes"]]
        else:  # no map: every mode with a frequency feature
            names = features["name"].unique() if not features.empty else []
            modes = sorted(int(n[5:]) for n in names if re.fullmatch(r"freq_\d+", str(n)))
        wanted = [f"freq_{m}" for m in modes] + [f"zeta_{m}" for m in modes]
        rows = _sorted_frame(features[features["name"].isin(wanted)]) if not features.empty else features
        by_measurement: dict[int, tuple[Any, dict[str, Any]]] = {}  # in time order (rows are sorted)
        for mid, timestamp, name, value in rows[["measurement_id", "timestamp", "name", "value"]].itertuples(
            index=False
        ):
            by_measurement.setdefault(int(mid), (timestamp, {}))[1][str(name)] = value
        points = [
            {
                "measurement_id": mid,
                "timestamp": _jsonable(timestamp),
                "frequency": [_number(values.get(f"freq_{m}")) for m in modes],
                "damping": [_number(values.get(f"zeta_{m}")) for m in modes],
            }
            for mid, (timestamp, values) in by_measurement.items()
        ]
        return {
            "machine": machine,
            "map": preload_map,
            "modes": modes,
            "current": points[-1] if points else None,
            "trail": points[-_MAP_TRAIL - 1 : -1],
        }

    def acknowledge(self, alarm_id: str) -> dict[str, Any]:
        try:
            wanted = int(alarm_id)
        except ValueError:
            msg = f"alarm id must be an integer; got {alarm_id!r}"
            raise _NotFound(msg) from None
        for machine in self.store.machines():
            if any(a.id == wanted for a in self.store.alarms(machine)):
                self.store.acknowledge(wanted)
                config = self.store.machine_config(machine)
                labels = {c["name"]: c["label"] for c in self._components(config, [])}
                alarm = next(a for a in self.store.alarms(machine) if a.id == wanted)
                return {"alarm": self._alarm(alarm, labels)}
        msg = f"alarm {wanted} is not in the history store"
        raise _NotFound(msg)


# --------------------------------------------------------------------------------------------- HTTP


class _HTTPServer(ThreadingHTTPServer):
    daemon_threads = True
    dashboard: DashboardServer


class _IPv6HTTPServer(_HTTPServer):
    address_family = socket.AF_INET6


class _Handler(BaseHTTPRequestHandler):
    server: _HTTPServer
    server_version = "cappe-dashboard"
    timeout = 30.0  # a client that stalls mid-request does not hold a thread for ever

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 (the base class's name)
        _log.debug("%s - " + format, self.address_string(), *args)

    # -- responses

    def _send(self, status: int, body: bytes, content_type: str) -> None:
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.send_header("X-Content-Type-Options", "nosniff")
        if content_type.startswith("text/html"):
            self.send_header(
                "Content-Security-Policy",
                "default-src 'self'; img-src 'self' data:; style-src 'self'; script-src 'self'; "
                "connect-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'",
            )
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def _send_json(self, status: int, payload: Any) -> None:
        body = json.dumps(_jsonable(payload), allow_nan=False, separators=(",", ":")).encode()
        self._send(status, body, "application/json; charset=utf-8")

    def _send_error_json(self, status: HTTPStatus, message: str) -> None:
        self._send_json(status, {"error": message, "status": int(status)})

    # -- dispatch

    def do_GET(self) -> None:
        self._dispatch("GET")

    def do_HEAD(self) -> None:
        self._dispatch("HEAD")

    def do_POST(self) -> None:
        self._dispatch("POST")

    def _dispatch(self, method: str) -> None:
        path = urllib.parse.urlsplit(self.path).path
        refusal = self._host_refusal()
        if refusal is not None:
            _log.info("dashboard refused %s %s: %s", method, self.path, refusal)
            self.close_connection = True  # the request body, if any, is not read
            with contextlib.suppress(ConnectionError):
                self._send(HTTPStatus.MISDIRECTED_REQUEST, f"{refusal}\n".encode(), "text/plain; charset=utf-8")
            return
        try:
            if method == "POST":
                self._read_body()
            handled = self._route(method, path)
        except ConnectionError:  # the client went away (closed tab, reload): nobody to answer
            _log.debug("dashboard client left during %s %s", method, self.path)
        except _NotFound as exc:
            self._send_error_json(HTTPStatus.NOT_FOUND, str(exc))
        except _MethodNotAllowed as exc:
            self._send_error_json(HTTPStatus.METHOD_NOT_ALLOWED, str(exc))
        except _Forbidden as exc:
            self._send_error_json(HTTPStatus.FORBIDDEN, str(exc))
        except Exception as exc:  # every failure gets an answer, never a hanging request
            _log.exception("dashboard request %s %s failed", method, self.path)
            with contextlib.suppress(ConnectionError):
                self._send_error_json(HTTPStatus.INTERNAL_SERVER_ERROR, f"{type(exc).__name__}: {exc}")
        else:
            if not handled:
                self._send_error_json(HTTPStatus.NOT_FOUND, f"no such page: {path!r}")

    def _read_body(self) -> None:
        try:
            length = int(self.headers.get("Content-Length") or 0)
        except ValueError:
            length = -1
        if not 0 <= length <= _MAX_BODY:
            msg = f"request body length must be 0 to {_MAX_BODY} bytes; got {self.headers.get('Content-Length')!r}"
            raise _Forbidden(msg)
        if length:
            self.rfile.read(length)

    def _host_refusal(self) -> str | None:
        """Why the request's Host header is not one this server answers to (DNS rebinding); None when it is."""
        dashboard = self.server.dashboard
        hosts = self.headers.get_all("Host") or []
        if len(hosts) != 1:
            return f"a request needs exactly one Host header; got {len(hosts)}"
        name, port = _split_host(hosts[0])
        if name in dashboard.allowed_hosts and port in (None, dashboard.port):
            return None
        served = ", ".join(f"[{n}]" if ":" in n else n for n in dashboard.allowed_hosts)
        return (
            f"host {hosts[0][:100]!r} is not served here; this dashboard answers to {served} (port "
            f"{dashboard.port} or none); name others with --allowed-host (allowed_hosts)"
        )

    def _check_origin(self) -> None:
        """Refuse state changes asked by a page from another origin (a cross-site form post)."""
        origin = self.headers.get("Origin")
        if origin is None:
            return
        host = self.headers.get("Host", "")
        if urllib.parse.urlsplit(origin).netloc != host:
            msg = f"acknowledging from another origin is not allowed; got origin {origin!r} for host {host!r}"
            raise _Forbidden(msg)

    def _route(self, method: str, path: str) -> bool:
        dashboard = self.server.dashboard
        if path == "/" or path.lstrip("/") in _ASSETS:
            if method == "POST":
                msg = f"{path} is a page; use GET"
                raise _MethodNotAllowed(msg)
            name = "index.html" if path == "/" else path.lstrip("/")
            self._send(HTTPStatus.OK, dashboard._asset(name), _ASSETS[name])
            return True
        found = self._endpoint(path)
        if found is None:
            return False
        call, methods = found
        if method not in methods:
            msg = f"{path} answers {' and '.join(methods)} only; got {method}"
            raise _MethodNotAllowed(msg)
        if method == "POST":
            self._check_origin()
        with dashboard._lock:
            payload = call()
        self._send_json(HTTPStatus.OK, payload)
        return True

    def _endpoint(self, path: str) -> tuple[Callable[[], dict[str, Any]], tuple[str, ...]] | None:
        """The API call a path names and the methods it answers; None for an unknown path."""
        api = self.server.dashboard._api
        if path == "/api/machines":
            return api.machines, ("GET", "HEAD")
        if match := _MACHINE_ROUTE.match(path):
            view: Callable[[str], dict[str, Any]] = getattr(api, match["view"])
            return functools.partial(view, urllib.parse.unquote(match["machine"])), ("GET", "HEAD")
        if match := _ACK_ROUTE.match(path):
            return functools.partial(api.acknowledge, urllib.parse.unquote(match["alarm"])), ("POST",)
        return None


# --------------------------------------------------------------------------------------------- the server


class DashboardServer:
    """The dashboard's HTTP server over one history store.

    Made by :func:`make_server`. Run it in the foreground with :meth:`serve_forever` or in a background thread
    with :meth:`start`; :meth:`shutdown` (or leaving the ``with`` block) stops it, closes the socket and closes the
    store when the server opened it from a path.

    Parameters
    ----------
    store : HistoryStore
        The store the pages read.
    httpd : ThreadingHTTPServer
        The bound HTTP server (made by :func:`make_server` with the dashboard's request handler).
    owns_store : bool
        Close ``store`` on shutdown (it was opened from a path).
    asked_host : str
        The host the server was asked to bind to (a name, an address or a wildcard).
    allowed_hosts : sequence of str
        Further names accepted in the ``Host`` header.

    Attributes
    ----------
    url : str
        Address of the page, e.g. ``http://127.0.0.1:43127/``.
    host : str
        Interface the server listens on.
    port : int
        Port the server listens on (the one the system chose when asked for port 0).
    allowed_hosts : tuple of str
        Host names and addresses accepted in a request's ``Host`` header (lower case, IPv6 without brackets),
        with ``port`` or without a port.
    store : HistoryStore
        The store read on every request.
    """

    def __init__(
        self, store: HistoryStore, httpd: _HTTPServer, *, owns_store: bool, asked_host: str,
        allowed_hosts: Sequence[str],
    ) -> None:
        self.store = store
        self._httpd = httpd
        self._owns_store = owns_store
        self._api = _Api(store)
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._serving = False
        self._closed = False
        self._assets: dict[str, bytes] = {}
        httpd.dashboard = self
        host, port = httpd.server_address[:2]
        self.host = str(host)
        self.port = int(port)
        shown = f"[{self.host}]" if ":" in self.host else self.host
        self.url = f"http://{shown}:{self.port}/"
        self.allowed_hosts = _served_names(asked_host, self.host, allowed_hosts)

    def __repr__(self) -> str:
        state = "closed" if self._closed else ("serving" if self._serving else "ready")
        return f"DashboardServer(url={self.url!r}, {state})"

    def _asset(self, name: str) -> bytes:
        if name not in self._assets:
            self._assets[name] = resources.files("cappe.monitor").joinpath("dashboard", name).read_bytes()
        return self._assets[name]

    def _check_open(self) -> None:
        if self._closed:
            msg = f"dashboard server at {self.url} is shut down; make a new one with make_server()"
            raise RuntimeError(msg)
        if self._serving:
            msg = f"dashboard server at {self.url} is already serving"
            raise RuntimeError(msg)

    def serve_forever(self) -> None:
        """Serve requests in this thread until :meth:`shutdown` is called from another thread (or Ctrl-C).

        Examples
        --------
        >>> from cappe.monitor._dashboard import make_server
        >>> with make_server("history.sqlite") as server:  # doctest: +SKIP
        ...     print(f"dashboard at {server.url}")
        ...     server.serve_forever()
        """
        self._check_open()
        self._serving = True
        self._httpd.serve_forever(poll_interval=0.2)

    def start(self) -> None:
        """Serve requests in a background (daemon) thread; returns at once.

        Examples
        --------
        >>> from cappe.monitor._dashboard import make_server
        >>> server = make_server("history.sqlite")  # doctest: +SKIP
        >>> server.start()  # doctest: +SKIP
        >>> server.shutdown()  # doctest: +SKIP
        """
        self._check_open()
        self._serving = True
        self._thread = threading.Thread(
            target=self._httpd.serve_forever, kwargs={"poll_interval": 0.2}, name="cappe-dashboard", daemon=True
        )
        self._thread.start()

    def shutdown(self) -> None:
        """Stop serving, close the listening socket and, if the server opened the store, the store.

        Safe to call more than once and on a server that never served.
        """
        if self._closed:
            return
        self._closed = True
        try:
            if self._serving:
                self._httpd.shutdown()  # returns once serve_forever has left its loop
            if self._thread is not None:
                self._thread.join()
        finally:
            self._httpd.server_close()
            if self._owns_store:
                with self._lock:
                    self.store.close()

    def __enter__(self) -> DashboardServer:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.shutdown()


def make_server(
    store: HistoryStore | str | os.PathLike[str],
    *,
    host: str = "127.0.0.1",
    port: int = 0,
    allowed_hosts: Sequence[str] | None = None,
) -> DashboardServer:
    """Make the dashboard server of a history store (listening, not yet serving).

    Parameters
    ----------
    store : HistoryStore or str or path-like
        An open store (left open on shutdown) or its URL / SQLite file (opened here, closed on shutdown). A file
        path must exist: the dashboard does not create an empty store.
    host : str, optional
        Interface to listen on; the default serves this computer only. ``0.0.0.0`` serves the network (the API
        can acknowledge alarms and has no authentication).
    port : int, optional
        TCP port in 0 ... 65535; 0 lets the system choose a free one (see ``DashboardServer.url``).
    allowed_hosts : sequence of str, optional
        Further names (or addresses) the server answers to in a request's ``Host`` header, e.g. the computer's
        network name for a deliberate bind to ``0.0.0.0``. Without them it answers to the address it listens
        on and, on a loopback or wildcard interface, to ``localhost``, ``127.0.0.1`` and ``[::1]``; requests
        naming another host (a DNS-rebinding page) are refused with 421.

    Returns
    -------
    DashboardServer
        Call ``serve_forever()`` or ``start()``; ``shutdown()`` or a ``with`` block stops it.

    Raises
    ------
    DataError
        A store path that does not exist, a port outside 0 ... 65535, or an allowed host that is not a host name
        or IP address.
    OSError
        The address cannot be bound (port in use, unknown host).

    Examples
    --------
    >>> import urllib.request, json
    >>> from cappe.monitor._dashboard import make_server
    >>> with make_server("history.sqlite") as server:  # doctest: +SKIP
    ...     server.start()
    ...     with urllib.request.urlopen(server.url + "api/machines") as response:
    ...         print(json.load(response))
    {'machines': [{'id': 'spindle-01', 'model': 'builtin:spindle-bearing', ...}]}
    """
    if isinstance(port, bool) or not isinstance(port, (int, np.integer)) or not 0 <= int(port) <= 65535:
        msg = f"dashboard port must be an integer in 0 ... 65535; got {port!r}"
        raise DataError(msg)
    if not isinstance(host, str) or not host:
        msg = f"dashboard host must be a non-empty string; got {host!r}"
        raise DataError(msg)
    allowed = _allowed_hosts(allowed_hosts)
    owns_store = False
    if isinstance(store, (str, os.PathLike)):
        from cappe.monitor._store import HistoryStore

        location = os.fspath(store)
        if location.startswith("sqlite:"):  # sqlite:///relative or sqlite:////absolute
            with contextlib.suppress(ArgumentError):  # a malformed URL: the store's own check words it
                location = make_url(location).database or location
        if "://" not in location and not Path(location).is_file():
            msg = f"history store file {location!r} does not exist"
            raise DataError(msg)
        store = HistoryStore(store)
        owns_store = True
    server_class = _IPv6HTTPServer if ":" in host else _HTTPServer
    try:
        httpd = server_class((host, int(port)), _Handler)
    except OSError as exc:
        if owns_store:
            store.close()
        msg = f"cannot serve the dashboard on {host}:{port}: {exc.strerror or exc}"
        raise OSError(exc.errno, msg) from exc
    except BaseException:
        if owns_store:
            store.close()
        raise
    return DashboardServer(store, httpd, owns_store=owns_store, asked_host=host, allowed_hosts=allowed)
