"""``cappe monitor init|simulate|ingest|baseline|status|history|alarms|serve`` through main(argv)."""

from __future__ import annotations

import json
import re
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from cappe.cli import main
from cappe.monitor import HistoryStore


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture(scope="module")
def monitored(tmp_path_factory) -> Path:
    """A store with one machine, a learned baseline and an ingested front-bearing loss."""
    folder = tmp_path_factory.mktemp("monitor")
    store = folder / "store.db"
    common = ["--machine", "spindle-01"]
    assert main(["monitor", "init", str(store), *common, "--model", "builtin:spindle-bearing", "--outputs",
                 "sx,sy,hax,hay,haz,htax", "--band", "150:1000"]) == 0
    assert main(["monitor", "simulate", "healthy", "--store", str(store), *common, "-n", "30", "--seed", "1",
                 "-o", str(folder / "healthy")]) == 0
    assert main(["monitor", "ingest", str(store), *common, "--manifest", str(folder / "healthy/scenario.json")]) == 0
    assert main(["monitor", "baseline", str(store), *common]) == 0
    assert main(["monitor", "simulate", "bearing-loss", "--store", str(store), *common, "-n", "4", "--fault-at", "1",
                 "--seed", "2", "--start", "2026-01-06T06:00:00+00:00", "-o", str(folder / "fault")]) == 0
    assert main(["monitor", "ingest", str(store), *common, "--manifest", str(folder / "fault/scenario.json")]) == 0
    return folder


def test_chain_records_and_reports_the_fault(monitored: Path, capsys) -> None:
    store = monitored / "store.db"
    code, out, _ = run(capsys, "monitor", "status", store, "--json")
    assert code == 0
    doc = json.loads(out)["machines"][0]
    assert doc["machine"] == "spindle-01"
    assert doc["measurements"] == 34
    assert doc["worst_severity"] == "conditionally tolerable"
    # the latest factors are the store's own last fast-path estimates
    with HistoryStore(store) as history:
        table = history.estimates("spindle-01", path="fast")
        last = table[table["measurement_id"] == table["measurement_id"].max()]
        alarms = history.alarms("spindle-01")
    assert doc["factors"]["front"]["value"] == pytest.approx(float(last[last["parameter"] == "front"]["value"].iloc[0]))
    assert len(alarms) == 1
    assert alarms[0].component == "front"
    assert alarms[0].diagnosis["hypothesis"] == "front"
    assert alarms[0].diagnosis["change"] == pytest.approx(-0.10, abs=0.01)  # the simulated 10 % loss


def test_alarms_and_acknowledge(monitored: Path, capsys) -> None:
    store = monitored / "store.db"
    code, out, _ = run(capsys, "monitor", "alarms", store, "--machine", "spindle-01")
    assert code == 0
    assert "front bearing: -10.0 %" in out
    with HistoryStore(store) as history:
        alarm_id = history.alarms("spindle-01")[0].id
    code, out, _ = run(capsys, "monitor", "alarms", store, "--machine", "spindle-01", "--ack", alarm_id, "--json")
    assert code == 0
    assert json.loads(out)["alarms"] == []  # nothing unacknowledged left
    code, out, _ = run(capsys, "monitor", "alarms", store, "--machine", "spindle-01", "--all")
    assert "acknowledged" in out


def test_history_table_and_csv(monitored: Path, capsys, tmp_path: Path) -> None:
    store = monitored / "store.db"
    csv = tmp_path / "h.csv"
    code, out, _ = run(capsys, "monitor", "history", store, "--machine", "spindle-01", "--last", "3", "--csv", csv,
                       "--json")
    assert code == 0
    rows = json.loads(out)["rows"]
    assert len(rows) == 3
    assert rows[-1]["front"] == pytest.approx(0.9, abs=0.02)  # 10 % lost (the temperature moves it a little)
    assert csv.read_text().splitlines()[0].startswith("measurement_id,timestamp")
    code, out, _ = run(capsys, "monitor", "history", store, "--machine", "spindle-01", "--path", "slow", "--json")
    slow = json.loads(out)["rows"]
    assert len(slow) == 1  # the alarm ran the full estimation once
    assert slow[0]["kfx"] == pytest.approx(0.9, abs=0.02)


def test_serve_answers(monitored: Path, capsys, monkeypatch) -> None:
    import cappe.monitor as monitor_api

    started = {}
    ready = threading.Event()
    real = monitor_api.make_server

    def capture(*args, **kwargs):
        server = real(*args, **kwargs)
        started["server"] = server
        ready.set()
        return server

    monkeypatch.setattr(monitor_api, "make_server", capture)
    argv = ["monitor", "serve", str(monitored / "store.db"), "--port", "0", "--allowed-host", "spindle-pc",
            "--allowed-host", "spindle-pc.example.org"]
    thread = threading.Thread(target=main, args=(argv,), daemon=True)
    thread.start()
    # a generous bound, not a pace (a fixed 10 s could run out on a loaded CI machine); a command that ends
    # without a server stops the wait at once
    deadline = time.monotonic() + 120
    while not ready.wait(0.05) and thread.is_alive() and time.monotonic() < deadline:
        pass
    assert "server" in started, "cappe monitor serve did not start a server"
    server = started["server"]
    try:
        with urllib.request.urlopen(f"{server.url}api/machines", timeout=120) as response:
            machines = json.loads(response.read())
        for host, status in (("spindle-pc", 200), (f"spindle-pc.example.org:{server.port}", 200),
                             ("attacker.example", 421)):
            request = urllib.request.Request(f"{server.url}api/machines", headers={"Host": host})
            try:
                with urllib.request.urlopen(request, timeout=120) as response:
                    got = response.status
            except urllib.error.HTTPError as err:
                with err:
                    got = err.code
            assert got == status, host
    finally:
        server.shutdown()
        thread.join(timeout=10)
    assert "spindle-01" in json.dumps(machines)
    assert server.allowed_hosts == ("localhost", "127.0.0.1", "::1", "spindle-pc", "spindle-pc.example.org")
    out = capsys.readouterr().out
    assert f"at {server.url} (Ctrl-C stops it); answers to host names localhost, 127.0.0.1, [::1], spindle-pc, " \
           "spindle-pc.example.org" in out


@pytest.mark.parametrize(
    ("argv", "code", "match"),
    [
        (["monitor", "status", "missing.db"], 2, "does not exist"),
        (["monitor", "ingest", "{store}", "--machine", "spindle-01"], 2, "give measurement FILEs or --manifest"),
        (["monitor", "ingest", "{store}", "--machine", "nobody", "--manifest", "{folder}/fault/scenario.json"], 1,
         "nobody"),
        (["monitor", "ingest", "{store}", "a.uff", "b.uff", "--machine", "spindle-01", "--time", "2026-01-01"], 2,
         "--time needs exactly one FILE"),
        (["monitor", "status", "{folder}/two.db"], 0, ""),
        (["monitor", "alarms", "{folder}/two.db"], 2, r"--machine is needed: .* holds machines \['a', 'b'\]"),
        (["monitor", "baseline", "{store}", "--machine", "spindle-01", "--since", "yesterday"], 2, "ISO time"),
        (["monitor", "simulate", "healthy", "-o", "x"], 2, "--store STORE --machine ID or --model MODEL"),
        (["monitor", "init", "{folder}/other.db", "--machine", "m", "--model", "builtin:spindle-bearing",
          "--outputs", "sx,nope"], 1, r"output\(s\) \['nope'\] not in model"),
        (["monitor", "init", "{store}", "--machine", "spindle-01", "--model", "builtin:spindle-bearing"], 1,
         "already exists"),
    ],
)
def test_errors(monitored: Path, capsys, argv, code, match) -> None:
    import re

    two = monitored / "two.db"
    if not two.exists():
        with HistoryStore(two) as store:
            store.add_machine("a", {})
            store.add_machine("b", {})
    filled = [a.format(store=monitored / "store.db", folder=monitored) for a in argv]
    got, _, err = run(capsys, *filled)
    assert got == code
    assert re.search(match, err), err


def test_ingest_without_baseline_says_so(tmp_path: Path, capsys) -> None:
    store = tmp_path / "s.db"
    assert main(["monitor", "init", str(store), "--machine", "m", "--model", "builtin:spindle-bearing", "--outputs",
                 "sx,hax", "--band", "150:1000", "--detection", "ewma", "--severity",
                 "tolerable=0.1,intolerable=0.3"]) == 0
    assert main(["monitor", "simulate", "healthy", "--model", "builtin:spindle-bearing", "--machine", "m", "-n",
                 "1", "--format", "csv", "-o", str(tmp_path / "d")]) == 0
    code, out, _ = run(capsys, "monitor", "ingest", store, tmp_path / "d" / "m00000.csv",
                       "--time", "2026-02-01T10:00:00", "--condition", "temperature=21.5")  # the only machine
    assert code == 0
    assert "no baseline yet" in out
    with HistoryStore(store) as history:
        record = history.latest_measurement("m")
        config = history.machine_config("m")
    assert record.conditions == {"temperature": 21.5}
    assert record.timestamp.isoformat() == "2026-02-01T10:00:00+00:00"  # naive times are read as UTC
    assert config["detection"] == "ewma"
    assert config["severity"] == {"tolerable": 0.1, "intolerable": 0.3}


# ------------------------------------------------------------------------------------- a multi-file ingest that fails


@pytest.fixture(scope="module")
def healthy_csv(tmp_path_factory) -> Path:
    """Three healthy measurements of machine 'm' as CSV files, and the store config they fit."""
    folder = tmp_path_factory.mktemp("ingest-failure")
    assert main(["monitor", "init", str(folder / "template.db"), "--machine", "m", "--model", "builtin:spindle-bearing",
                 "--outputs", "sx,hax", "--band", "150:1000"]) == 0
    assert main(["monitor", "simulate", "healthy", "--store", str(folder / "template.db"), "-n", "3", "--format", "csv",
                 "--seed", "5", "-o", str(folder / "sim")]) == 0
    return folder


@pytest.fixture
def ingest_dir(healthy_csv: Path, tmp_path: Path, monkeypatch) -> Path:
    """A fresh store s.db with machine 'm' and the files a1.csv, a2.csv, c.csv (good) and b.csv (not a measurement)
    in the working directory, so that messages show the names as typed."""
    import shutil

    shutil.copyfile(healthy_csv / "template.db", tmp_path / "s.db")
    for k, name in enumerate(("a1.csv", "a2.csv", "c.csv")):
        shutil.copyfile(healthy_csv / "sim" / f"m{k:05d}.csv", tmp_path / name)
    (tmp_path / "b.csv").write_text("time,sx\n0.0,1.0\nnot a number,2.0\n")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _sources(store: Path) -> list[str]:
    with HistoryStore(store) as history:
        return [r.source for r in history.measurements("m")]


def _one_line(err: str) -> str:
    assert err.endswith("\n")
    assert err.count("\n") == 1, err  # one line: no traceback, no progress bar
    assert "Traceback" not in err
    return err[:-1]


def test_ingest_failure_says_which_file_and_what_was_recorded(ingest_dir: Path, capsys) -> None:
    code, _, err = run(capsys, "monitor", "ingest", "s.db", "a1.csv", "a2.csv", "b.csv", "c.csv")
    assert code == 1
    line = _one_line(err)
    assert line.startswith("cappe: error: b.csv: ")
    assert line.endswith("; 2 earlier file(s) (a1.csv, a2.csv) were recorded, b.csv was not recorded, the 1 file(s) "
                         "after it were not ingested")
    assert _sources(ingest_dir / "s.db") == ["a1.csv", "a2.csv"]  # the message is true


def test_ingest_failure_at_the_first_or_last_file(ingest_dir: Path, capsys) -> None:
    code, _, err = run(capsys, "monitor", "ingest", "s.db", "b.csv", "a1.csv", "a2.csv")
    assert code == 1
    line = _one_line(err)
    assert line.startswith("cappe: error: b.csv: ")
    assert line.endswith("; nothing was recorded; the 2 file(s) after it were not ingested")
    assert _sources(ingest_dir / "s.db") == []
    code, _, err = run(capsys, "monitor", "ingest", "s.db", "a1.csv", "b.csv", "--json")
    assert code == 1
    assert _one_line(err).endswith("; 1 earlier file(s) (a1.csv) were recorded, b.csv was not recorded")
    assert _sources(ingest_dir / "s.db") == ["a1.csv"]


def test_ingest_of_a_missing_file_records_nothing(ingest_dir: Path, capsys) -> None:
    code, _, err = run(capsys, "monitor", "ingest", "s.db", "a1.csv", "gone.csv", "a2.csv")
    assert code == 1
    assert _one_line(err) == "cappe: error: gone.csv: No such file or directory; nothing was recorded"
    assert _sources(ingest_dir / "s.db") == []


def test_ingest_failure_after_the_file_was_recorded(ingest_dir: Path, capsys, monkeypatch) -> None:
    """A failure after the measurement's own record (in the slow path, say) says that file was recorded too."""
    import cappe.monitor as monitor_api
    from cappe.exceptions import DataError

    real = monitor_api.ingest

    def failing_after(store, machine, data, **kwargs):
        result = real(store, machine, data, **kwargs)
        if kwargs["source"] == "a2.csv":
            msg = "slow path failed\nin two lines"
            raise DataError(msg)
        if kwargs["source"] == "c.csv":
            msg = "not a cappe error"
            raise RuntimeError(msg)
        return result

    monkeypatch.setattr(monitor_api, "ingest", failing_after)
    code, _, err = run(capsys, "monitor", "ingest", "s.db", "a1.csv", "a2.csv", "c.csv")
    assert code == 1
    assert _one_line(err) == ("cappe: error: a2.csv: slow path failed in two lines; 1 earlier file(s) (a1.csv) were "
                              "recorded, a2.csv itself was recorded before the failure, the 1 file(s) after it were "
                              "not ingested")
    assert _sources(ingest_dir / "s.db") == ["a1.csv", "a2.csv"]
    with pytest.raises(RuntimeError, match="not a cappe error") as caught:  # a bug keeps its traceback, with a note
        main(["monitor", "ingest", "s.db", "c.csv"])
    assert caught.value.__notes__ == ["cappe monitor ingest stopped at c.csv: c.csv itself was recorded before the "
                                      "failure"]


# ----------------------------------------------------------------- re-running a batch; conditions it cannot judge


def test_a_manifest_batch_is_rerun_to_completion(monitored: Path, capsys, tmp_path: Path) -> None:
    """The issue: re-running a manifest failed at once with "already recorded"; now recorded files are skipped."""
    import shutil

    store = tmp_path / "s.db"
    shutil.copyfile(monitored / "store.db", store)
    code, out, _ = run(capsys, "monitor", "ingest", store, "--manifest", monitored / "fault/scenario.json")
    assert code == 0, out
    assert "ingested 0 measurement(s), skipped 4 recorded already; 34 recorded" in out
    assert out.count("already recorded as measurement") == 4
    shutil.copyfile(monitored / "fault/m00000.uff", tmp_path / "renamed.uff")  # the same content, another name
    code, out, _ = run(capsys, "monitor", "ingest", store, tmp_path / "renamed.uff", "--json")
    assert code == 0
    doc = json.loads(out)
    assert doc["measurements"] == []
    assert doc["skipped"][0]["why"].endswith(f"from {monitored / 'fault/m00000.uff'} (the same content)")


def test_a_failed_batch_resumes_where_it_stopped(ingest_dir: Path, capsys) -> None:
    code, _, _ = run(capsys, "monitor", "ingest", "s.db", "a1.csv", "a2.csv", "b.csv", "c.csv")
    assert code == 1
    assert _sources(ingest_dir / "s.db") == ["a1.csv", "a2.csv"]
    (ingest_dir / "b.csv").unlink()  # the bad file is taken out of the batch; the batch is run again
    code, out, _ = run(capsys, "monitor", "ingest", "s.db", "a1.csv", "a2.csv", "c.csv")
    assert code == 0
    assert "ingested 1 measurement(s), skipped 2 recorded already" in out
    assert _sources(ingest_dir / "s.db") == ["a1.csv", "a2.csv", "c.csv"]  # each once
    (ingest_dir / "a1.csv").write_text((ingest_dir / "a1.csv").read_text().replace("0", "1", 1))
    code, _, err = run(capsys, "monitor", "ingest", "s.db", "a1.csv")  # another file under a recorded name
    assert code == 1
    assert "a different file of this name is recorded already as measurement 1" in err


def test_conditions_it_cannot_judge_are_said_and_recorded(monitored: Path, capsys, tmp_path: Path) -> None:
    import shutil

    store = tmp_path / "s.db"
    shutil.copyfile(monitored / "store.db", store)
    assert main(["monitor", "simulate", "healthy", "--store", str(store), "-n", "2", "--seed", "9", "--start",
                 "2026-01-07T06:00:00+00:00", "-o", str(tmp_path / "d")]) == 0
    code, out, _ = run(capsys, "monitor", "ingest", store, tmp_path / "d/m00000.uff", "--time", "2026-01-07T06:00",
                       "--condition", "temp=22")
    assert code == 0
    assert re.search(r"NOT JUDGED 2026-01-07T06:00:00\+00:00 m00000.uff \(recorded as measurement 35\): the baseline "
                     r"depends on the condition 'temperature', which the measurement does not give \(it gives temp\)",
                     out), out
    assert "ingested 1 measurement(s) (1 not judged)" in out
    code, out, _ = run(capsys, "monitor", "ingest", store, tmp_path / "d/m00001.uff", "--time", "2026-01-07T06:15",
                       "--condition", "temperature=77")
    assert code == 0
    assert "ALARM" not in out
    assert "temperature 77 is implausible for this machine" in out


# ------------------------------------------------------------------------------------------------- monitor watch


def test_watch_survives_a_kill_and_a_restart_mid_folder(healthy_csv: Path, tmp_path: Path) -> None:
    """A real process is killed (SIGKILL) while it works through a folder; the restarted one finishes it: every
    file recorded once, none lost, none repeated."""
    import os
    import shutil
    import signal
    import subprocess
    import sys

    import cappe

    shutil.copyfile(healthy_csv / "template.db", tmp_path / "s.db")
    assert main(["monitor", "simulate", "healthy", "--store", str(tmp_path / "s.db"), "-n", "10", "--format", "csv",
                 "--seed", "6", "-o", str(tmp_path / "in")]) == 0
    files = sorted((tmp_path / "in").glob("*.csv"))
    # the last three files carry a modification time an hour ahead: the watcher leaves them until they settle, so
    # the kill surely lands before the folder is done, however slowly this process gets to send it on a loaded
    # machine (it lands while the watcher works on the files before them, or waits)
    later, written = time.time() + 3600, {held: held.stat().st_mtime for held in files[-3:]}
    for held in written:
        os.utime(held, (later, later))
    env = {**os.environ, "PYTHONPATH": str(Path(cappe.__file__).parents[1])}
    argv = [sys.executable, "-m", "cappe", "monitor", "watch", str(tmp_path / "s.db"), str(tmp_path / "in"),
            "--interval", "0.2", "--settle", "0"]
    with open(tmp_path / "first.log", "w") as log:
        first = subprocess.Popen(argv, env=env, stdout=log, stderr=subprocess.STDOUT)
        try:
            deadline = time.monotonic() + 300
            while len(_sources(tmp_path / "s.db")) < 3:  # killed mid-folder, after a few files
                assert first.poll() is None, (tmp_path / "first.log").read_text()
                assert time.monotonic() < deadline
                time.sleep(0.05)
            first.send_signal(signal.SIGKILL)
        finally:
            first.kill()
            first.wait()
    recorded = _sources(tmp_path / "s.db")
    assert 3 <= len(recorded) <= len(files) - 3
    for held, mtime in written.items():  # settled now
        os.utime(held, (mtime, mtime))
    second = subprocess.run([*argv, "--once"], env=env, capture_output=True, text=True, timeout=300, check=False)
    assert second.returncode == 0, second.stdout + second.stderr
    assert f"{len(files) - len(recorded)} ingested, {len(recorded)} skipped (recorded already), 0 failed" \
        in second.stdout
    sources = _sources(tmp_path / "s.db")
    assert sorted(sources) == sorted(str(f) for f in files)  # each once: none lost, none repeated
    with HistoryStore(tmp_path / "s.db") as history:  # times and conditions from the folder's scenario.json
        manifest = json.loads((tmp_path / "in/scenario.json").read_text())["measurements"]
        by_source = {r.source: r for r in history.measurements("m")}
        for entry in manifest:
            record = by_source[str(tmp_path / "in" / entry["file"])]
            assert record.conditions == pytest.approx(entry["conditions"])
            assert record.timestamp.isoformat().startswith(entry["timestamp"][:19])


def test_watch_reports_a_bad_file_and_goes_on(ingest_dir: Path, capsys) -> None:
    folder = ingest_dir / "in"
    folder.mkdir()
    for name in ("a1.csv", "b.csv", "c.csv"):
        (folder / name).write_bytes((ingest_dir / name).read_bytes())
    code, out, _ = run(capsys, "monitor", "watch", "s.db", folder, "--once", "--settle", "0")
    assert code == 1
    assert re.search(r"error: .*b.csv: .*; not retried until the file changes", out)
    assert "2 ingested, 0 skipped (recorded already), 1 failed" in out
    assert sorted(_sources(ingest_dir / "s.db")) == [str(folder / "a1.csv"), str(folder / "c.csv")]


# --------------------------------------------------------------------------------------- third-party UFF 58 files


def _third_party_uff(frf, path: Path) -> dict[str, str]:
    """The FRFs written with pyuff as another program writes them: no cappe ID lines, numbered nodes, some
    sensors mounted in a negative direction (their data negated); returns the sensor map that undoes it."""
    import pyuff

    mapping = {}
    sets = []
    for o, out in enumerate(frf.output_names):
        node, direction = 11 + o, (-1) ** o * (1 + o % 3)  # 11:+x, 12:-y, 13:+z, 14:-x ...
        for i, inp in enumerate(frf.input_names):
            sets.append({"type": 58, "binary": 0, "func_type": 4, "id1": "Acme DAQ", "id2": "run 7", "id3": "NONE",
                         "id4": "NONE", "id5": "NONE", "rsp_node": node, "rsp_dir": direction, "ref_node": 1,
                         "ref_dir": 1 + i, "x": frf.freq, "data": np.sign(direction) * frf.H[o, i],
                         "abscissa_spacing": 1, "abscissa_spec_data_type": 18, "ordinate_spec_data_type": 12,
                         "orddenom_spec_data_type": 13})
            mapping[f"1:+{'xyz'[i]}"] = inp
        mapping[f"{node}:{'-' if direction < 0 else '+'}{'xyz'[abs(direction) - 1]}"] = out
    pyuff.UFF(str(path)).write_sets(sets, mode="overwrite")
    return mapping


def test_a_third_party_uff_is_ingested_through_a_sensor_map(monitored: Path, capsys, tmp_path: Path) -> None:
    """The issue: a UFF 58 without cappe's ID lines failed with "FRF data lack channels"."""
    import shutil

    from cappe.io import read_measurements

    store = tmp_path / "s.db"
    shutil.copyfile(monitored / "store.db", store)
    own = read_measurements(monitored / "fault/m00002.uff")
    mapping = _third_party_uff(own, tmp_path / "acme.uff")
    (tmp_path / "map.csv").write_text("channel,sensor\n" + "".join(f"{k},{v}\n" for k, v in mapping.items()))
    code, _, err = run(capsys, "monitor", "ingest", store, tmp_path / "acme.uff", "--time", "2026-01-08T06:00",
                       "--condition", "temperature=22")
    assert code == 1
    assert "FRF data lack channels" in err  # without the map the channels are the file's node numbers
    code, out, _ = run(capsys, "monitor", "ingest", store, tmp_path / "acme.uff", "--time", "2026-01-08T06:00",
                       "--condition", "temperature=22", "--sensor-map", tmp_path / "map.csv", "--json")
    assert code == 0, out
    doc = json.loads(out)["measurements"][0]
    with HistoryStore(store) as history:  # the same factors as cappe's own file of the same FRFs gave
        table = history.estimates("spindle-01", path="fast")
        sources = {r.id: r.source for r in history.measurements("spindle-01")}
    mine = table[table["measurement_id"].map(sources) == str(monitored / "fault/m00002.uff")]
    for name, value in zip(mine["parameter"], mine["value"], strict=True):
        assert doc["factors"][name] == pytest.approx(value, rel=1e-6)


def test_status_states_the_detectable_change(monitored: Path, capsys) -> None:
    code, out, _ = run(capsys, "monitor", "status", monitored / "store.db")
    assert code == 0
    line = next(x for x in out.splitlines() if "detectable:" in x)
    assert re.search(r"detectable: a change of front [0-9.e-]+ %, rear .* is found after about [0-9.]+ "
                     r"measurement\(s\) \(2 standard deviations of the healthy scatter, resolution [0-9.e-]+ %\)", line)
    # and how uncertain a diagnosed size is beyond the scatter (issue 25: no fixed 0.5 % floor)
    # per component, read back on the machine's twin (the store keeps the healthy FRFs)
    assert re.search(r"sizes: a diagnosed change's size is uncertain beyond the scatter by \+- front [0-9.]+ %, rear "
                     r"[0-9.]+ %, .*screw4 [0-9.]+ % of itself \(read back on the machine's twin: .* the healthy machine "
                     r"is [0-9.e-]+ % from its model\)", out)
    code, out, _ = run(capsys, "monitor", "status", monitored / "store.db", "--json")
    det = json.loads(out)["machines"][0]["detectable"]
    with HistoryStore(monitored / "store.db") as history:
        from cappe.monitor import Baseline

        baseline = Baseline.from_dict(history.baseline("spindle-01"))
    # two chart standard deviations of the baseline: sqrt(std^2 + resolution^2), as a relative loss
    assert det["change"]["front"] == pytest.approx(-np.expm1(-2 * baseline.scale[0]))
    assert det["resolution"] == baseline.resolution < 0.005  # derived, below the old fixed 0.5 %
    assert det["size_scale_std"] == pytest.approx(baseline.size_scale_std)
    assert det["size_scale"]["screw1"] == pytest.approx(baseline.component_scale_std()[2])
