"""``cappe monitor serve``: the dashboard's JSON API against a real SQLite history store, and its page in
headless Chromium.

The store is filled the way the monitoring chain fills it (fast estimates every measurement, slow ones every tenth,
modal features, FRFs, two alarms after the front bearing lost 10 % of its stiffness); every number the API or
the page shows is compared with what the store returns for the same question.
"""

from __future__ import annotations

import http.client
import json
import logging
import os
import shutil
import socket
import struct
import threading
import urllib.error
import urllib.request
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cappe.exceptions import DataError
from cappe.monitor._dashboard import DashboardServer, make_server
from cappe.monitor._store import HistoryStore
from cappe.systems.frf import FRFData

MACHINE = "spindle-01"
OTHER = "spindle-02"  # configured, nothing measured yet
COMPONENTS = {"front": "front bearing", "rear": "rear bearing", "screw1": "housing screw 1",
              "screw2": "housing screw 2"}
N_MEASUREMENTS = 30
#: Seconds a request may take before the test calls the server hung: a guard, not a speed bound (a loaded CI
#: machine answers in seconds what an idle one answers in milliseconds)
HUNG = 120
START = datetime(2024, 5, 1, 8, 0, tzinfo=UTC)
FREQ = np.linspace(50.0, 2000.0, 240)
MODES_HZ = np.array([420.0, 910.0, 1480.0])
ZETA = np.array([0.021, 0.017, 0.025])
PHI = np.array([[1.0, 0.6, -0.4], [0.5, -0.9, 0.7]])  # mode shapes at the two outputs (= the two inputs)
OUTPUTS = ("shaft_x", "housing_y")
INPUTS = ("hammer_x", "hammer_y")
PRELOADS = [0.25, 0.5, 0.75, 1.0, 1.25, 1.5]
XSS = '<img src=x onerror="window.__xss=1"> front bearing lost 10 % of its stiffness'
CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]


# --------------------------------------------------------------------------------------------- the store


def _frf(front: float) -> FRFData:
    """Modal-sum FRFs; the first mode moves with the square root of the front bearing's factor."""
    modes = MODES_HZ * np.array([np.sqrt(front), 1.0, 1.0])
    w = 2 * np.pi * FREQ
    H = np.zeros((2, 2, FREQ.size), dtype=complex)
    for r, f in enumerate(modes):
        wr = 2 * np.pi * f
        H += np.einsum("o,i->oi", PHI[:, r], PHI[:, r])[:, :, None] / (wr**2 - w**2 + 2j * ZETA[r] * wr * w)
    return FRFData(freq=FREQ, H=H, input_names=INPUTS, output_names=OUTPUTS)


def _fill(path: Path | str) -> None:
    rng = np.random.default_rng(7)
    config = {"machine": MACHINE, "model": "builtin:spindle-bearing",
              "components": [{"name": n, "label": label, "parameters": [f"k_{n}"]} for n, label in COMPONENTS.items()]}
    healthy = np.abs(_frf(1.0).H)
    preload = np.array(PRELOADS)
    baseline = {
        "format": "cappe.monitor-baseline/1", "created": START.isoformat(), "n_measurements": 10,
        "mean": dict.fromkeys(COMPONENTS, 1.0), "std": {n: 0.004 for n in COMPONENTS},
        "limits": {"front": [0.985, 1.015]},
        "frf": {"freq": FREQ.tolist(), "input_names": list(INPUTS), "output_names": list(OUTPUTS),
                "magnitude": healthy.tolist()},
        "map": {"parameter": "preload", "preload": PRELOADS, "modes": [1, 2, 3],
                "frequency": (MODES_HZ[None, :] * preload[:, None] ** 0.08).tolist(),
                "damping": (ZETA[None, :] * (1 + 0.4 * (1 - preload[:, None]))).tolist()},
    }
    with HistoryStore(path) as store:
        store.add_machine(MACHINE, config)
        store.add_machine(OTHER, {"machine": OTHER, "model": "builtin:spindle-bearing", "components": []})
        store.set_baseline(MACHINE, baseline)
        for i in range(N_MEASUREMENTS):
            front = 1.0 if i < 20 else 0.9
            with store.transaction(MACHINE) as tx:
                mid = tx.add_measurement(timestamp=START + timedelta(hours=6 * i), source=f"run-{i:03d}.uff",
                                         kind="impact", conditions={"temperature": 24.0 + 0.1 * i}, frf=_frf(front))
                modes = MODES_HZ * np.array([np.sqrt(front), 1.0, 1.0]) + rng.normal(0.0, 0.3, 3)
                features = {f"freq_{k + 1}": (float(modes[k]), 0.3) for k in range(3)}
                features |= {f"zeta_{k + 1}": (float(ZETA[k] * rng.uniform(0.95, 1.05)), 5e-4) for k in range(3)}
                features |= {"csf": (0.999 if front == 1.0 else 0.93 + 0.001 * i, None), "frac": (0.98, None)}
                tx.add_features(mid, features)
                values = {n: (front if n == "front" else 1.0) + float(rng.normal(0.0, 0.004)) for n in COMPONENTS}
                tx.add_estimates(mid, path="fast", values=values,
                                 std={n: 0.004 + 0.0001 * k for k, n in enumerate(COMPONENTS)})
                if i % 10 == 9:  # the slow path; the rear bearing's std unknown (NaN in the store)
                    tx.add_estimates(mid, path="slow", values={n: v + 0.001 for n, v in values.items()},
                                     std={n: 0.002 for n in COMPONENTS if n != "rear"})
                if i in (22, 28):
                    severe = i == 28
                    tx.add_alarm(mid, component="front", statistic="cusum-", value=14.8 if severe else 6.2,
                                 severity="intolerable" if severe else "conditionally tolerable",
                                 diagnosis={"hypothesis": "front", "label": "front bearing",
                                            "probability": 0.98 if severe else 0.81, "change": -0.1,
                                            "candidates": {"front": 0.98, "rear": 0.01, "screw1": 0.01}},
                                 message=XSS if severe else "front bearing stiffness drifting down")


@pytest.fixture(scope="module")
def template(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("dashboard") / "history.db"
    _fill(path)
    return path


@pytest.fixture
def store(template: Path, tmp_path: Path) -> Any:
    path = tmp_path / "history.db"
    shutil.copyfile(template, path)  # every test gets its own copy: some acknowledge alarms or ingest
    with HistoryStore(path) as opened:
        yield opened


@pytest.fixture
def server(store: HistoryStore) -> Any:
    with make_server(store) as running:
        running.start()
        yield running


# --------------------------------------------------------------------------------------------- HTTP helpers


def _strict(constant: str) -> Any:
    msg = f"the API sent the non-JSON constant {constant}"
    raise AssertionError(msg)


def _request(url: str, method: str = "GET", headers: dict[str, str] | None = None) -> tuple[int, str, bytes]:
    data = b"" if method == "POST" else None
    req = urllib.request.Request(url, method=method, headers=headers or {}, data=data)
    try:
        with urllib.request.urlopen(req, timeout=HUNG) as response:
            return response.status, response.headers.get("Content-Type", ""), response.read()
    except urllib.error.HTTPError as err:
        with err:
            return err.code, err.headers.get("Content-Type", ""), err.read()


def _json(server: DashboardServer, path: str, method: str = "GET", status: int = 200, **kw: Any) -> Any:
    code, content_type, body = _request(server.url + path, method, **kw)
    assert code == status, body
    assert content_type.startswith("application/json")
    return json.loads(body, parse_constant=_strict)  # NaN / Infinity would fail here


# --------------------------------------------------------------------------------------------- API


def test_machines(server: DashboardServer, store: HistoryStore) -> None:
    machines = _json(server, "api/machines")["machines"]
    assert [m["id"] for m in machines] == store.machines() == [MACHINE, OTHER]
    assert machines[0]["n_measurements"] == len(store.measurements(MACHINE)) == N_MEASUREMENTS
    assert machines[0]["active_alarms"] == 2
    assert machines[0]["worst_severity"] == "intolerable"
    assert machines[1] == {"id": OTHER, "model": "builtin:spindle-bearing", "n_measurements": 0,
                           "active_alarms": 0, "worst_severity": None}


def test_status_matches_store(server: DashboardServer, store: HistoryStore) -> None:
    status = _json(server, f"api/machine/{MACHINE}/status")
    assert status["n_measurements"] == N_MEASUREMENTS
    latest = store.latest_measurement(MACHINE)
    assert latest is not None
    assert status["latest_measurement"]["id"] == latest.id
    assert datetime.fromisoformat(status["latest_measurement"]["timestamp"]) == latest.timestamp
    assert status["latest_measurement"]["conditions"] == latest.conditions
    assert status["active_alarms"] == len(store.alarms(MACHINE, unacknowledged=True)) == 2
    assert status["worst_severity"] == "intolerable"
    assert [c["name"] for c in status["components"]] == list(COMPONENTS)
    fast = store.estimates(MACHINE, path="fast")
    baseline = store.baseline(MACHINE)
    assert baseline is not None
    for component in status["components"]:
        rows = fast[fast["parameter"] == component["name"]]
        last = rows.iloc[-1]
        assert component["label"] == COMPONENTS[component["name"]]
        assert component["measurement_id"] == last["measurement_id"] == latest.id
        # JSON carries float64 exactly (shortest repr round trip): equality, not a tolerance
        assert component["value"] == last["value"]
        assert component["std"] == last["std"]
        assert component["value_text"] == f"{last['value']:#.4g}"
        assert component["baseline_mean"] == baseline["mean"][component["name"]]
        assert component["baseline_std"] == baseline["std"][component["name"]]
        # change and z are derived here: relative tolerance of a few float64 roundings
        np.testing.assert_allclose(component["change"], last["value"] / 1.0 - 1.0, rtol=1e-12)
        np.testing.assert_allclose(component["z"], (last["value"] - 1.0) / 0.004, rtol=1e-12)
    front = status["components"][0]
    assert front["baseline_band"] == [0.985, 1.015]  # the stored limits
    assert status["components"][1]["baseline_band"] == pytest.approx([0.992, 1.008], rel=1e-12)  # mean +- 2 std
    csf = store.features(MACHINE, names=["csf"])
    assert status["features"]["csf"] == csf["value"].iloc[-1]


def test_status_of_machine_without_data(server: DashboardServer) -> None:
    status = _json(server, f"api/machine/{OTHER}/status")
    assert status["n_measurements"] == 0
    assert status["latest_measurement"] is None
    assert status["components"] == []
    assert status["worst_severity"] is None
    assert status["has_baseline"] is False
    for view in ("trends", "alarms", "frf", "map"):
        assert _json(server, f"api/machine/{OTHER}/{view}")["machine"] == OTHER
    assert _json(server, f"api/machine/{OTHER}/frf")["measurement"] is None
    assert _json(server, f"api/machine/{OTHER}/map")["current"] is None


def test_trends_match_store(server: DashboardServer, store: HistoryStore) -> None:
    trends = _json(server, f"api/machine/{MACHINE}/trends")
    estimates = store.estimates(MACHINE)
    for component in trends["components"]:
        for path, expected_n in (("fast", N_MEASUREMENTS), ("slow", N_MEASUREMENTS // 10)):
            rows = estimates[(estimates["parameter"] == component["name"]) & (estimates["path"] == path)]
            series = component[path]
            assert len(series["value"]) == expected_n
            assert series["measurement_id"] == rows["measurement_id"].tolist()
            np.testing.assert_array_equal(series["value"], rows["value"].to_numpy())  # exact: JSON round trip
            times = [datetime.fromisoformat(t) for t in series["timestamp"]]
            assert times == list(rows["timestamp"])
            if component["name"] == "rear" and path == "slow":
                assert series["std"] == [None] * expected_n  # NaN in the store -> null
            else:
                np.testing.assert_array_equal(series["std"], rows["std"].to_numpy())
        assert component["baseline"]["mean"] == 1.0
    assert trends["components"][0]["baseline"]["band_source"] == "limits"
    assert trends["components"][2]["baseline"]["band_source"] == "2 std"
    csf = store.features(MACHINE, names=["csf"])
    np.testing.assert_array_equal(trends["csf"]["value"], csf["value"].to_numpy())


def test_alarms_match_store(server: DashboardServer, store: HistoryStore) -> None:
    alarms = _json(server, f"api/machine/{MACHINE}/alarms")["alarms"]
    stored = store.alarms(MACHINE)
    assert [a["id"] for a in alarms] == [a.id for a in reversed(stored)]  # newest first
    for shown, record in zip(alarms, reversed(stored), strict=True):
        assert shown["severity"] == record.severity
        assert shown["diagnosis"] == record.diagnosis
        assert shown["message"] == record.message
        assert shown["value"] == record.value
        assert shown["probability"] == record.diagnosis["probability"]
        assert shown["component_label"] == "front bearing"
        assert shown["acknowledged"] is False
    assert alarms[0]["message"] == XSS
    assert alarms[0]["probability_text"] == "98.0 %"


def test_acknowledge(server: DashboardServer, store: HistoryStore) -> None:
    severe = store.alarms(MACHINE)[-1]
    answer = _json(server, f"api/alarm/{severe.id}/acknowledge", method="POST")
    assert answer["alarm"]["id"] == severe.id
    assert answer["alarm"]["acknowledged"] is True
    assert [a.acknowledged for a in store.alarms(MACHINE)] == [False, True]
    status = _json(server, f"api/machine/{MACHINE}/status")
    assert status["active_alarms"] == 1
    assert status["worst_severity"] == "conditionally tolerable"
    again = _json(server, f"api/alarm/{severe.id}/acknowledge", method="POST")  # harmless twice
    assert again["alarm"]["acknowledged"] is True


def test_acknowledge_refuses_other_origins_and_get(server: DashboardServer, store: HistoryStore) -> None:
    alarm = store.alarms(MACHINE)[0]
    error = _json(server, f"api/alarm/{alarm.id}/acknowledge", method="POST", status=403,
                  headers={"Origin": "http://evil.example"})
    assert "another origin" in error["error"]
    error = _json(server, f"api/alarm/{alarm.id}/acknowledge", status=405)
    assert "POST" in error["error"]
    same = server.url.rstrip("/")
    _json(server, f"api/alarm/{alarm.id}/acknowledge", method="POST", headers={"Origin": same})
    assert store.alarms(MACHINE)[0].acknowledged


def _raw(server: DashboardServer, method: str, path: str, hosts: list[str]) -> tuple[int, str, bytes]:
    """A request with exactly these Host headers (none, one or several), which urllib cannot send."""
    connection = http.client.HTTPConnection(server.host, server.port, timeout=HUNG)
    try:
        connection.putrequest(method, path, skip_host=True, skip_accept_encoding=True)
        for host in hosts:
            connection.putheader("Host", host)
        if method == "POST":
            connection.putheader("Content-Length", "0")
        connection.endheaders()
        response = connection.getresponse()
        return response.status, response.getheader("Content-Type") or "", response.read()
    finally:
        connection.close()


FOREIGN_HOSTS = ["attacker.example", "attacker.example:{port}", "localhost.attacker.example", "127.0.0.1.nip.io",
                 "localhost:1", "[::2]", "127.0.0.2", "", "localhost:", "local host", "::1"]


@pytest.mark.parametrize("host", FOREIGN_HOSTS)
@pytest.mark.parametrize(("method", "path"), [
    ("GET", "/api/machines"), ("GET", f"/api/machine/{MACHINE}/status"), ("GET", "/"), ("GET", "/app.js"),
    ("HEAD", "/api/machines"), ("GET", "/nothing/here"), ("POST", "/api/alarm/{alarm}/acknowledge"),
])
def test_foreign_host_refused(server: DashboardServer, store: HistoryStore, host: str, method: str, path: str) -> None:
    """DNS rebinding: a page of another site whose name resolves to 127.0.0.1 gets nothing and changes nothing."""
    alarm = store.alarms(MACHINE)[0]
    code, content_type, body = _raw(server, method, path.format(alarm=alarm.id), [host.format(port=server.port)])
    assert code == 421
    assert content_type == "text/plain; charset=utf-8"
    if method != "HEAD":
        text = body.decode()
        assert text.startswith(f"host {host.format(port=server.port)!r} is not served here; this dashboard answers "
                               f"to localhost, 127.0.0.1, [::1] (port {server.port} or none)")
        assert text.count("\n") == 1
        assert MACHINE not in text
    assert not store.alarms(MACHINE)[0].acknowledged


@pytest.mark.parametrize("hosts", [[], ["127.0.0.1", "attacker.example"], ["127.0.0.1", "127.0.0.1"]])
def test_missing_or_repeated_host_refused(server: DashboardServer, store: HistoryStore, hosts: list[str]) -> None:
    alarm = store.alarms(MACHINE)[0]
    for method, path in (("GET", "/api/machines"), ("POST", f"/api/alarm/{alarm.id}/acknowledge"), ("GET", "/")):
        code, content_type, body = _raw(server, method, path, hosts)
        assert (code, content_type) == (421, "text/plain; charset=utf-8")
        assert body.decode() == f"a request needs exactly one Host header; got {len(hosts)}\n"
    assert not store.alarms(MACHINE)[0].acknowledged


@pytest.mark.parametrize("host", ["localhost", "localhost:{port}", "LocalHost.:{port}", "127.0.0.1",
                                  "127.0.0.1:{port}", "[::1]", "[::1]:{port}", "[0:0::1]:{port}"])
def test_served_host_names_accepted(server: DashboardServer, store: HistoryStore, host: str) -> None:
    named = host.format(port=server.port)
    code, _, body = _raw(server, "GET", "/api/machines", [named])
    assert code == 200
    assert [m["id"] for m in json.loads(body)["machines"]] == [MACHINE, OTHER]
    assert _raw(server, "GET", "/", [named])[0] == 200
    alarm = store.alarms(MACHINE)[0]
    code, _, body = _raw(server, "POST", f"/api/alarm/{alarm.id}/acknowledge", [named])
    assert code == 200
    assert store.alarms(MACHINE)[0].acknowledged


def test_configured_host_names_accepted(store: HistoryStore) -> None:
    with make_server(store, allowed_hosts=["Dashboard.Example.ORG", "[2001:db8::7]", "192.0.2.7"]) as server:
        server.start()
        assert server.allowed_hosts == ("localhost", "127.0.0.1", "::1", "dashboard.example.org", "2001:db8::7",
                                        "192.0.2.7")
        for host in ("dashboard.example.org", f"dashboard.example.org:{server.port}", "DASHBOARD.example.org.",
                     f"[2001:db8::7]:{server.port}", "192.0.2.7", "localhost"):
            assert _raw(server, "GET", "/api/machines", [host])[0] == 200, host
        alarm = store.alarms(MACHINE)[0]
        code, _, _ = _raw(server, "POST", f"/api/alarm/{alarm.id}/acknowledge", ["dashboard.example.org"])
        assert code == 200
        assert store.alarms(MACHINE)[0].acknowledged
        for host in ("example.org", "dashboard.example.org:1", "evil.dashboard.example.org", "2001:db8::7"):
            code, _, body = _raw(server, "GET", "/api/machines", [host])
            assert code == 421, host
            assert b"answers to localhost, 127.0.0.1, [::1], dashboard.example.org, [2001:db8::7], 192.0.2.7" in body


def test_non_loopback_bind_answers_to_its_address_only(store: HistoryStore) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:  # this computer's address on its default route
        try:
            probe.connect(("192.0.2.1", 9))  # a UDP connect only picks the route; no packet is sent
            address = probe.getsockname()[0]
        except OSError:
            address = ""
    if address in ("0.0.0.0", "") or address.startswith("127."):
        pytest.skip("this computer has no non-loopback IPv4 address")
    with make_server(store, host=address) as server:
        server.start()
        assert server.allowed_hosts == (address,)
        assert _raw(server, "GET", "/api/machines", [f"{address}:{server.port}"])[0] == 200
        assert _raw(server, "GET", "/api/machines", ["localhost"])[0] == 421
        assert _raw(server, "GET", "/api/machines", ["attacker.example"])[0] == 421


def test_wildcard_bind_answers_to_loopback_and_configured_names(store: HistoryStore) -> None:
    with make_server(store, host="0.0.0.0", allowed_hosts=["spindle-pc"]) as server:
        server.start()
        assert server.allowed_hosts == ("localhost", "127.0.0.1", "::1", "0.0.0.0", "spindle-pc")
        for host in ("spindle-pc", f"localhost:{server.port}", f"0.0.0.0:{server.port}"):  # 0.0.0.0: its url
            assert _raw(server, "GET", "/api/machines", [host])[0] == 200, host
        assert _raw(server, "GET", "/api/machines", ["attacker.example"])[0] == 421


@pytest.mark.parametrize("bad", ["", "http://dashboard.example.org", "dashboard.example.org:8050", "a/b", "a b",
                                 "-a.example", "a..b", 7])
def test_allowed_hosts_checked(store: HistoryStore, bad: Any) -> None:
    with pytest.raises(DataError, match=r"dashboard allowed host must be a host name or IP address without port, "
                                        r"scheme or path .*; got "):
        make_server(store, allowed_hosts=[bad])


def test_frf_matches_store(server: DashboardServer, store: HistoryStore) -> None:
    answer = _json(server, f"api/machine/{MACHINE}/frf")
    latest = store.latest_measurement(MACHINE)
    assert latest is not None
    frf = store.frf(latest.id)
    assert frf is not None
    measurement = answer["measurement"]
    assert measurement["id"] == latest.id
    assert measurement["output_names"] == list(OUTPUTS)
    assert measurement["input_names"] == list(INPUTS)
    np.testing.assert_array_equal(measurement["freq"], frf.freq)
    np.testing.assert_array_equal(measurement["magnitude"], np.abs(frf.H))  # exact: JSON round trip of |H|
    baseline = store.baseline(MACHINE)
    assert baseline is not None
    assert answer["baseline"]["magnitude"] == baseline["frf"]["magnitude"]
    assert answer["baseline"]["output_names"] == list(OUTPUTS)


def test_map_matches_store(server: DashboardServer, store: HistoryStore) -> None:
    answer = _json(server, f"api/machine/{MACHINE}/map")
    baseline = store.baseline(MACHINE)
    assert baseline is not None
    assert answer["map"] == baseline["map"]
    assert answer["modes"] == [1, 2, 3]
    latest = store.latest_measurement(MACHINE)
    assert latest is not None
    features = store.features(MACHINE)
    last = features[features["measurement_id"] == latest.id].set_index("name")["value"]
    current = answer["current"]
    assert current["measurement_id"] == latest.id
    assert current["frequency"] == [last[f"freq_{k}"] for k in (1, 2, 3)]
    assert current["damping"] == [last[f"zeta_{k}"] for k in (1, 2, 3)]
    assert len(answer["trail"]) == 20  # the 20 measurements before the current one
    assert answer["trail"][-1]["measurement_id"] == store.measurements(MACHINE)[-2].id


def test_new_ingest_shows_on_next_request(server: DashboardServer, store: HistoryStore) -> None:
    with store.transaction(MACHINE) as tx:
        mid = tx.add_measurement(timestamp=START + timedelta(days=30), source="late.uff", kind="impact")
        tx.add_estimates(mid, path="fast", values={"front": 0.8125}, std={"front": 0.005})
    status = _json(server, f"api/machine/{MACHINE}/status")
    assert status["n_measurements"] == N_MEASUREMENTS + 1
    assert status["latest_measurement"]["id"] == mid
    front = status["components"][0]
    assert (front["value"], front["std"], front["value_text"]) == (0.8125, 0.005, "0.8125")
    assert _json(server, f"api/machine/{MACHINE}/frf")["measurement"]["id"] == mid - 1  # newest with an FRF


@pytest.mark.parametrize(
    ("path", "method", "status", "match"),
    [
        ("api/machine/nope/status", "GET", 404, "machine 'nope' is not in the history store"),
        ("api/machine/nope/frf", "GET", 404, "machine 'nope'"),
        ("api/machine/spindle%2001/map", "GET", 404, "machine 'spindle 01'"),
        ("api/machine/spindle-01/bogus", "GET", 404, "no such page"),
        ("api/alarm/999/acknowledge", "POST", 404, "alarm 999 is not in the history store"),
        ("api/alarm/abc/acknowledge", "POST", 404, "alarm id must be an integer; got 'abc'"),
        ("nothing/here", "GET", 404, "no such page: '/nothing/here'"),
        ("api/machines", "POST", 405, "answers GET and HEAD only"),
        ("", "POST", 405, "is a page"),
    ],
)
def test_errors_answer_json(server: DashboardServer, path: str, method: str, status: int, match: str) -> None:
    error = _json(server, path, method=method, status=status)
    assert match in error["error"]
    assert error["status"] == status


def test_server_error_answers_500_and_keeps_serving(
    server: DashboardServer, store: HistoryStore, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    def broken(*args: Any, **kwargs: Any) -> Any:
        msg = "disk on fire"
        raise RuntimeError(msg)

    monkeypatch.setattr(store, "features", broken)
    with caplog.at_level(logging.ERROR, logger="cappe.monitor._dashboard"):
        error = _json(server, f"api/machine/{MACHINE}/map", status=500)
    assert error["error"] == "RuntimeError: disk on fire"
    assert "dashboard request GET /api/machine/spindle-01/map failed" in caplog.text  # with its traceback
    assert "disk on fire" in caplog.text
    monkeypatch.undo()
    assert _json(server, "api/machines")["machines"][0]["id"] == MACHINE


def test_concurrent_requests(server: DashboardServer) -> None:
    results: list[int] = []

    def fetch() -> None:
        code, _, _ = _request(server.url + f"api/machine/{MACHINE}/status")
        results.append(code)

    threads = [threading.Thread(target=fetch) for _ in range(8)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=2 * HUNG)  # each request gives up after HUNG s
    assert results == [200] * 8


def test_page_assets_are_local(server: DashboardServer) -> None:
    code, content_type, page = _request(server.url)
    assert (code, content_type) == (200, "text/html; charset=utf-8")
    html = page.decode()
    assert 'src="app.js"' in html
    assert 'href="style.css"' in html
    assert "http://" not in html  # nothing fetched from elsewhere
    assert "https://" not in html
    for name, kind in (("app.js", "text/javascript"), ("style.css", "text/css")):
        code, content_type, body = _request(server.url + name)
        assert code == 200
        assert content_type.startswith(kind)
        assert b"https://" not in body
    script = _request(server.url + "app.js")[2].decode()
    for sink in ("innerHTML", "outerHTML", "insertAdjacentHTML", "document.write", "eval("):  # store text stays text
        assert sink not in script


def test_make_server_from_path_owns_the_store(template: Path, tmp_path: Path) -> None:
    path = tmp_path / "copy.db"
    shutil.copyfile(template, path)
    server = make_server(path, port=0)
    assert server.url == f"http://127.0.0.1:{server.port}/"
    assert server.port > 0
    background = threading.Thread(target=server.serve_forever)
    background.start()
    try:
        assert _json(server, "api/machines")["machines"][0]["n_measurements"] == N_MEASUREMENTS
    finally:
        server.shutdown()
        background.join(timeout=10)
    assert not background.is_alive()
    with pytest.raises(DataError, match="is closed"):
        server.store.machines()
    server.shutdown()  # twice is harmless
    with pytest.raises(RuntimeError, match="is shut down"):
        server.start()


def test_shutdown_without_serving_and_borrowed_store_stays_open(store: HistoryStore) -> None:
    with make_server(store):
        pass
    assert store.machines() == [MACHINE, OTHER]


def test_make_server_errors(store: HistoryStore, tmp_path: Path) -> None:
    missing = tmp_path / "missing.db"
    with pytest.raises(DataError, match=r"history store file '.*missing\.db' does not exist"):
        make_server(missing)
    with pytest.raises(DataError, match=r"history store file '.*missing\.db' does not exist"):
        make_server(f"sqlite:///{missing}")
    assert not missing.exists()
    with pytest.raises(DataError, match=r"dashboard port must be an integer in 0 \.\.\. 65535; got 70000"):
        make_server(store, port=70000)
    with pytest.raises(DataError, match=r"dashboard host must be a non-empty string; got ''"):
        make_server(store, host="")
    with make_server(store) as first, pytest.raises(OSError, match=f"cannot serve the dashboard on 127.0.0.1:{first.port}"):
        make_server(store, port=first.port)


@pytest.mark.postgres
def test_make_server_from_postgres_url(postgres_database: str) -> None:
    _fill(postgres_database)
    with make_server(postgres_database) as server, HistoryStore(postgres_database) as store:
        server.start()
        status = _json(server, f"api/machine/{MACHINE}/status")
        fast = store.estimates(MACHINE, path="fast")
        for component in status["components"]:
            assert component["value"] == fast[fast["parameter"] == component["name"]]["value"].iloc[-1]
        assert status["n_measurements"] == N_MEASUREMENTS
        assert status["worst_severity"] == "intolerable"


# --------------------------------------------------------------------------------------------- the page


def _chromium() -> Any:
    if not CHROMIUM.exists():
        msg = f"headless Chromium not installed at {CHROMIUM}"
        if os.environ.get("CAPPE_REQUIRE_SERVICES") == "1":
            pytest.fail(msg + " and CAPPE_REQUIRE_SERVICES=1")
        pytest.skip(msg)
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        if os.environ.get("CAPPE_REQUIRE_SERVICES") == "1":
            pytest.fail("the playwright package is missing and CAPPE_REQUIRE_SERVICES=1")
        pytest.skip("the playwright package is not installed")
    return sync_playwright


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", data[16:24])
    return width, height


@pytest.mark.browser
def test_page_in_chromium(server: DashboardServer, store: HistoryStore, tmp_path: Path) -> None:
    sync_playwright = _chromium()
    errors: list[str] = []
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS, timeout=HUNG * 1000)
        try:
            page = browser.new_page(viewport={"width": 1320, "height": 900})
            page.set_default_timeout(HUNG * 1000)  # playwright's 30 s: a guard, not a speed bound
            page.on("pageerror", lambda exc: errors.append(f"page error: {exc}"))
            page.on("console", lambda m: errors.append(f"console {m.type}: {m.text}") if m.type == "error" else None)
            page.on("response", lambda r: errors.append(f"HTTP {r.status}: {r.url}") if r.status >= 400 else None)
            page.goto(server.url)
            page.wait_for_selector("body[data-state='ready'][data-generation='1']")

            # two machines: a selector; the empty one first, then back to the monitored spindle
            select = page.get_by_test_id("machine-select")
            assert select.is_visible()
            select.select_option(OTHER)
            page.wait_for_selector("body[data-state='ready'][data-generation='2']")
            assert page.get_by_test_id("n-measurements").text_content() == "0"
            assert page.get_by_test_id("alarm-row").count() == 0
            assert page.get_by_test_id("status-header").get_attribute("data-severity") == "none"
            select.select_option(MACHINE)
            page.wait_for_selector("body[data-state='ready'][data-generation='3']")

            # the numbers against the store
            assert page.get_by_test_id("n-measurements").text_content() == str(len(store.measurements(MACHINE)))
            fast = store.estimates(MACHINE, path="fast")
            for name in COMPONENTS:
                value = fast[fast["parameter"] == name]["value"].iloc[-1]
                assert page.get_by_test_id(f"latest-{name}").text_content() == f"{value:#.4g}"
                assert page.get_by_test_id(f"trend-{name}").count() == 1
            header = page.get_by_test_id("status-header")
            assert header.get_attribute("data-severity") == "bad"
            assert page.get_by_test_id("worst-severity").text_content().lower() == "intolerable"
            assert page.get_by_test_id("active-alarms").text_content() == "2"
            rows = page.get_by_test_id("alarm-row")
            assert rows.count() == len(store.alarms(MACHINE)) == 2
            severe = store.alarms(MACHINE)[-1]
            row = page.locator(f"[data-testid='alarm-row'][data-alarm-id='{severe.id}']")
            assert row.get_by_test_id("alarm-severity").text_content() == "intolerable"
            assert row.get_by_test_id("alarm-probability").text_content() == "98.0 %"
            # a message with markup is shown as text, never parsed
            assert XSS in row.text_content()
            assert page.locator("#alarm-body img").count() == 0
            assert page.evaluate("window.__xss === undefined")

            # FRF: two curves (latest and baseline mean); switch the output
            frf = page.get_by_test_id("frf-plot")
            assert frf.locator("polyline").count() == 2
            page.get_by_test_id("frf-output").select_option(OUTPUTS[1])
            assert f"output {OUTPUTS[1]} / input {INPUTS[0]}" in page.get_by_test_id("frf-caption").text_content()
            assert page.get_by_test_id("frf-plot").locator("polyline").count() == 2

            # the map: one current point per mode
            assert page.get_by_test_id("map-current").count() == 3

            # acknowledge the intolerable alarm
            row.get_by_test_id("ack-button").click()
            page.wait_for_selector("body[data-state='ready'][data-generation='4']")
            assert row.get_attribute("data-acknowledged") == "true"
            assert row.get_by_test_id("ack-button").count() == 0
            assert [a.acknowledged for a in store.alarms(MACHINE)] == [False, True]
            assert header.get_attribute("data-severity") == "warn"
            assert page.get_by_test_id("worst-severity").text_content().lower() == "conditionally tolerable"
            assert page.get_by_test_id("active-alarms").text_content() == "1"

            shot = tmp_path / "dashboard.png"
            page.screenshot(path=str(shot), full_page=True)
        finally:
            browser.close()
    width, height = _png_size(shot)
    assert width == 1320
    assert height > 1200  # the full page: status, trends, alarms, FRF and map
    assert shot.stat().st_size > 50_000  # drawn charts, not a blank page
    assert errors == []
    if os.environ.get("CAPPE_DASHBOARD_SCREENSHOT"):  # for a person to look at the page
        shutil.copyfile(shot, os.environ["CAPPE_DASHBOARD_SCREENSHOT"])
