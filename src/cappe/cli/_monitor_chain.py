"""The monitoring-chain commands of ``cappe monitor`` (thesis Fig. 1.1 over a history store).

``init`` records a machine (model, channels, components, alarm rules); ``simulate`` writes scenario data;
``ingest`` runs the chain on measurement files; ``watch`` ingests files as they arrive in a folder;
``baseline`` learns the healthy state from recorded measurements; ``status``, ``history`` and ``alarms`` read
the store; ``serve`` starts the dashboard.
"""

from __future__ import annotations

import argparse
import json
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from cappe.cli._common import ModelContext, UsageError, add_output_options, emit, names, number_pairs, text_pairs
from cappe.cli._common import band as parse_band
from cappe.exceptions import DataError, ModelError

__all__ = ["register"]


_SENSOR_MAP_HELP = ("CSV file with the columns channel,sensor: the files' channel names (a third-party UFF's "
                    "'12:+z', '1:-x') to the machine's inputs and outputs; negative directions are sign-flipped")


def _store_options(p: argparse.ArgumentParser, *, machine: bool = True) -> None:
    p.add_argument("store", metavar="STORE", help="history store: an SQLite file or a SQLAlchemy URL "
                                                   "(postgresql+psycopg://user@host/db)")
    if machine:
        p.add_argument("--machine", help="machine id (default: the store's only machine)")
    add_output_options(p)


def register(cmds: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = cmds.add_parser("init", help="record a machine: model, channels, components and alarm rules",
                        description="Record a machine in a history store (created if missing). Components default "
                                    "to the model's element groups (front_x/front_y/front_z -> front).")
    _store_options(p, machine=False)
    p.add_argument("--machine", required=True, help="machine id")
    p.add_argument("--model", required=True, help="model YAML file or builtin:NAME")
    p.add_argument("--params", metavar="FILE.json", help="parameter values of the healthy reference")
    p.add_argument("--set", dest="overrides", metavar="NAME=VALUE", action="append", default=[],
                   help="override one reference parameter (repeatable)")
    p.add_argument("--position", metavar="AXIS=VALUE", action="append", default=[], help="axis position")
    p.add_argument("--inputs", metavar="LIST", help="measured inputs (default all)")
    p.add_argument("--outputs", metavar="LIST", help="measured outputs (default all)")
    p.add_argument("--band", metavar="LO:HI", help="analysis band in Hz (default 0.7 f1 to 1.1 f_last)")
    p.add_argument("--component", metavar="NAME=P1,P2", action="append", default=[],
                   help="a component and its stiffness parameters (repeatable; replaces the defaults)")
    p.add_argument("--fault-parameter", metavar="NAME", action="append",
                   help="a model parameter whose change is a diagnosis of its own (default: preload if present)")
    p.add_argument("--detection", choices=("cusum", "ewma"), default="cusum")
    p.add_argument("--false-alarm-rate", type=float, default=1e-3,
                   help="expected false alarms per healthy measurement (default 0.001)")
    p.add_argument("--shift", type=float, default=2.0, help="change in standard deviations to detect fastest")
    p.add_argument("--severity", metavar="tolerable=F,intolerable=F",
                   help="relative-change thresholds of the grades (default tolerable=0.05,intolerable=0.25)")
    p.add_argument("--slow-every", type=int, default=0, help="run the full estimation every N measurements")
    p.add_argument("--excitation", choices=("measured", "operational"), default="measured",
                   help="measured: FRFs or time data with the force (default); operational: time data of the "
                        "outputs only, recorded in production (output-only modal analysis; --inputs: where the "
                        "process force acts)")
    p.add_argument("--ssi-orders", metavar="LO:HI[:STEP]",
                   help="model orders of the SSI-COV stabilization diagram of an operational machine, STEP default 2 "
                        "(default 4, 8, ... up to twice the modes in the band plus 8)")
    p.add_argument("--ssi-block-rows", type=int, metavar="N",
                   help="block rows of the SSI-COV Toeplitz matrix; outputs x N bound the model order (default: a "
                        "period of the band's lowest frequency)")
    p.add_argument("--ssi-stability", metavar="NAME=F,...",
                   help="SSI-COV stabilization criteria: freq_tol (default 0.01), damping_tol (0.1), mac_tol "
                        "(0.95), min_fraction of the orders a mode must be stable in (0.5), max_damping (0.1)")
    p.add_argument("--replace", action="store_true", help="replace an existing machine's config")
    p.set_defaults(func=init)

    p = cmds.add_parser("simulate", help="write realistic monitoring data: healthy drift or a fault",
                        description="FRF files of a machine's channels with temperature-driven preload drift and "
                                    "a fault (bearing-loss, loosening-screw, preload-loss), plus scenario.json.")
    p.add_argument("scenario", choices=("healthy", "bearing-loss", "loosening-screw", "preload-loss"))
    p.add_argument("--store", help="take the machine config from this store (with --machine)")
    p.add_argument("--machine", help="machine id (default: the store's only machine; 'machine' with --model)")
    p.add_argument("--model", help="model for a default config (without --store)")
    p.add_argument("-n", "--count", type=int, default=200, help="measurements (default 200)")
    p.add_argument("--fault-at", type=int, help="first faulty measurement (default count / 2)")
    p.add_argument("--component", help="faulty component (default front / screw2)")
    p.add_argument("--severity", type=float, help="fraction lost (default 0.1 / 0.5 / 0.4)")
    p.add_argument("--noise", type=float,
                   help="relative FRF noise (default 0.01); with --operational the sensor noise (default 0.02)")
    p.add_argument("--interval", type=float, default=15.0, help="minutes between measurements (default 15)")
    p.add_argument("--start", help="ISO time of the first measurement (default 2026-01-05T06:00Z)")
    p.add_argument("--format", choices=("uff", "csv", "npz"), default="uff", help="file format (default uff)")
    p.add_argument("--operational", action="store_true",
                   help="output-only records in production instead of FRFs: responses to an unmeasured process "
                        "force whose spectrum changes with the load (default for a machine with excitation "
                        "'operational')")
    p.add_argument("--seconds", type=float, default=30.0, help="record length of --operational (default 30 s)")
    p.add_argument("--seed", type=int, help="random seed")
    p.add_argument("-o", "--out", dest="directory", required=True, metavar="DIR", help="output directory")
    p.add_argument("--json", action="store_true", help="print machine-readable JSON")
    p.set_defaults(func=simulate)

    p = cmds.add_parser("ingest", help="run the chain on measurements and record everything",
                        usage="cappe monitor ingest STORE [FILE ...] [--machine ID] [--manifest M] [options]",
                        description="FRF or time-data files (UFF 58, CSV, npz): features, stiffness factors, "
                                    "detection, diagnosis and severity, recorded in the store. The files follow "
                                    "STORE directly.")
    p.add_argument("store", metavar="STORE", help="history store: an SQLite file or a SQLAlchemy URL")
    p.add_argument("files", metavar="FILE", nargs="*", help="measurement files")
    p.add_argument("--machine", help="machine id (default: the store's only machine)")
    add_output_options(p)
    p.add_argument("--progress", action="store_true", help="a progress bar even when stderr is not a terminal")
    p.add_argument("--manifest", help="scenario.json from `cappe monitor simulate` (files, times, conditions)")
    p.add_argument("--time", help="ISO time of a single FILE (default: the file's modification time)")
    p.add_argument("--condition", metavar="NAME=VALUE", action="append", default=[],
                   help="operating condition of the measurement, e.g. temperature=24.5 (repeatable)")
    p.add_argument("--sensor-map", metavar="MAP.csv", help=_SENSOR_MAP_HELP)
    p.set_defaults(func=ingest)

    p = cmds.add_parser("watch", help="ingest measurement files as they arrive in a folder",
                        usage="cappe monitor watch STORE DIR [--machine ID] [options]",
                        description="Poll DIR and run the chain on every new measurement file (UFF 58, CSV, npz) "
                                    "in this one process, oldest first, once its size has stopped changing. A "
                                    "file recorded already (by its content) is skipped, so a watch that was killed "
                                    "or restarted goes on without losing or repeating a file. Times and "
                                    "conditions come from a scenario.json in DIR where it lists the file, else "
                                    "the file's modification time and --condition.")
    p.add_argument("store", metavar="STORE", help="history store: an SQLite file or a SQLAlchemy URL")
    p.add_argument("directory", metavar="DIR", help="the folder the measurement files arrive in")
    p.add_argument("--machine", help="machine id (default: the store's only machine)")
    p.add_argument("--condition", metavar="NAME=VALUE", action="append", default=[],
                   help="operating condition of files the folder's scenario.json does not list (repeatable)")
    p.add_argument("--interval", type=float, default=2.0, help="seconds between looks at DIR (default 2)")
    p.add_argument("--settle", type=float, default=1.0,
                   help="seconds a file's size and time must stay unchanged before it is read (default 1)")
    p.add_argument("--once", action="store_true", help="ingest what DIR holds now, then stop")
    p.add_argument("--sensor-map", metavar="MAP.csv", help=_SENSOR_MAP_HELP)
    p.set_defaults(func=watch)

    p = cmds.add_parser("baseline", help="learn the healthy state from recorded measurements",
                        description="Healthy expectation (quadratic in the recorded operating conditions) and "
                                    "scatter of the component factors; restarts the detector.")
    _store_options(p)
    p.add_argument("--first", type=int, help="use the first N recorded measurements")
    p.add_argument("--since", help="ISO time: from")
    p.add_argument("--until", help="ISO time: to")
    p.add_argument("--resolution", type=float,
                   help="smallest relative change treated as real, e.g. 0.005 (default: derived from the healthy "
                        "data's own scatter)")
    p.set_defaults(func=baseline)

    p = cmds.add_parser("status", help="latest factors, active alarms and worst severity per machine")
    _store_options(p, machine=False)
    p.add_argument("--machine", help="one machine (default all)")
    p.set_defaults(func=status)

    p = cmds.add_parser("history", help="estimates over time")
    _store_options(p)
    p.add_argument("--path", choices=("fast", "slow"), default="fast")
    p.add_argument("--parameter", metavar="LIST", help="components or parameters (default all)")
    p.add_argument("--last", type=int, help="only the last N measurements")
    p.add_argument("--csv", metavar="FILE", help="write the table as CSV")
    p.set_defaults(func=history)

    p = cmds.add_parser("alarms", help="alarms with diagnosis and severity; acknowledge one")
    _store_options(p)
    p.add_argument("--all", action="store_true", help="also acknowledged alarms")
    p.add_argument("--ack", type=int, metavar="ID", help="acknowledge alarm ID")
    p.set_defaults(func=alarms)

    p = cmds.add_parser("serve", help="the dashboard on a local web page")
    _store_options(p, machine=False)
    p.add_argument("--host", default="127.0.0.1", help="interface (default 127.0.0.1: this computer only)")
    p.add_argument("--port", type=int, default=8050, help="port (default 8050; 0 picks a free one)")
    p.add_argument("--allowed-host", metavar="NAME", action="append", default=[],
                   help="a further host name the dashboard answers to, e.g. this computer's network name with "
                        "--host 0.0.0.0 (repeatable); requests naming other hosts are refused (DNS rebinding)")
    p.set_defaults(func=serve)


def _open(path: str, *, create: bool = False) -> Any:
    from cappe.monitor import HistoryStore

    if not create and "://" not in path and not Path(path).exists():
        msg = f"history store {path} does not exist; create it with `cappe monitor init`"
        raise UsageError(msg)
    return HistoryStore(path)


def _machine(args: argparse.Namespace, store: Any) -> str:
    """``--machine``, or the store's only machine."""
    if args.machine:
        return str(args.machine)
    known = store.machines()
    if len(known) != 1:
        msg = f"--machine is needed: {args.store} holds machines {known}"
        raise UsageError(msg)
    return str(known[0])


def _when(text: str, option: str) -> datetime:
    try:
        value = datetime.fromisoformat(text)
    except ValueError as exc:
        msg = f"{option} must be an ISO time like 2026-01-05T06:00:00+00:00; got {text!r}"
        raise UsageError(msg) from exc
    return value if value.tzinfo is not None else value.replace(tzinfo=UTC)


def init(args: argparse.Namespace) -> int:
    from cappe.monitor import Component, SeverityThresholds, default_config, register_machine

    ns = argparse.Namespace(model=args.model, params=args.params, overrides=args.overrides, position=args.position)
    ctx = ModelContext(ns)
    components = None
    if args.component:
        pairs = text_pairs(args.component, "--component", "NAME=P1,P2")
        components = [Component(k, k.replace("_", " "), tuple(names(v) or [])) for k, v in pairs.items()]
    severity = SeverityThresholds(**number_pairs(names(args.severity) or [], "--severity")) if args.severity else None
    settings: dict[str, Any] = {"detection": args.detection, "false_alarm_rate": args.false_alarm_rate,
                                "shift": args.shift, "slow_every": args.slow_every, "excitation": args.excitation}
    if severity is not None:
        settings["severity"] = severity
    settings.update(_ssi_settings(args))
    config = default_config(ctx.numeric, machine=args.machine, source=args.model, params=ctx.overrides,
                            position=ctx.position if args.position else None, inputs=names(args.inputs),
                            outputs=names(args.outputs), band=parse_band(args.band) if args.band else None,
                            components=components, fault_parameters=args.fault_parameter, **settings)
    with _open(args.store, create=True) as store:
        register_machine(store, config, replace=args.replace)
    lines = [f"machine '{config.machine}' recorded in {args.store}: model {config.model}, "
             f"{len(config.inputs)} inputs x {len(config.outputs)} outputs, band {config.band[0]:g}-"
             f"{config.band[1]:g} Hz, {config.detection} at {config.false_alarm_rate:g} false alarms per measurement",
             "components:"]
    lines += [f"  {c.name:10s} {c.label:20s} {', '.join(c.parameters)}" for c in config.components]
    if config.fault_parameters:
        lines.append(f"fault parameters: {', '.join(config.fault_parameters)}")
    if config.excitation == "operational":
        orders = ("automatic" if config.ssi_orders is None
                  else "{}-{} step {}".format(*config.ssi_orders))
        rows = "automatic" if config.ssi_block_rows is None else str(config.ssi_block_rows)
        criteria = ", ".join(f"{k}={v:g}" for k, v in config.ssi_stability.items()) or "ssi_cov defaults"
        lines.append(f"SSI-COV: model orders {orders}, block rows {rows}, stabilization {criteria}")
    lines += [f"note: {text}" for text in _limitations(config)]
    emit(args, config.to_dict(), "\n".join(lines))
    return 0


def _ssi_settings(args: argparse.Namespace) -> dict[str, Any]:
    """The SSI-COV options of ``monitor init`` as :class:`~cappe.monitor.MonitorConfig` fields."""
    settings: dict[str, Any] = {}
    if args.ssi_orders:
        parts = args.ssi_orders.split(":")
        try:
            numbers = [int(p) for p in parts]
        except ValueError:
            numbers = []
        if len(numbers) not in (2, 3):
            msg = f"--ssi-orders must be LO:HI or LO:HI:STEP with integers; got {args.ssi_orders!r}"
            raise UsageError(msg)
        settings["ssi_orders"] = (numbers[0], numbers[1], numbers[2] if len(numbers) == 3 else 2)
    if args.ssi_block_rows is not None:
        settings["ssi_block_rows"] = args.ssi_block_rows
    if args.ssi_stability:
        settings["ssi_stability"] = number_pairs(names(args.ssi_stability) or [], "--ssi-stability")
    return settings


def _limitations(config: Any) -> list[str]:
    """What the machine's measurements cannot tell (:meth:`cappe.monitor.Monitor.limitations`, without compiling
    the model)."""
    from cappe.monitor import OUTPUT_ONLY_LIMITATIONS

    return [OUTPUT_ONLY_LIMITATIONS] if config.excitation == "operational" else []


def simulate(args: argparse.Namespace) -> int:
    from datetime import timedelta

    from cappe.model import NumericModel, load_model
    from cappe.monitor import MonitorConfig, default_config, simulate_scenario, write_scenario

    if args.store:
        with _open(args.store) as store:
            config = MonitorConfig.from_dict(store.machine_config(_machine(args, store)))
        model = NumericModel(load_model(config.model))
    elif args.model:
        model = NumericModel(load_model(args.model))
        config = default_config(model, machine=args.machine or "machine", source=args.model)
    else:
        msg = "give --store STORE --machine ID or --model MODEL"
        raise UsageError(msg)
    start = _when(args.start, "--start") if args.start else None
    if args.operational or config.excitation == "operational":
        from cappe.monitor import simulate_operation

        noise = 0.02 if args.noise is None else args.noise
        records = simulate_operation(config, args.scenario, n=args.count, fault_at=args.fault_at,
                                     component=args.component, severity=args.severity, seconds=args.seconds,
                                     noise=noise, interval=timedelta(minutes=args.interval), start=start,
                                     model=model, rng=args.seed)
        manifest = write_scenario(records, args.directory, machine=config.machine, scenario=args.scenario,
                                  extension=args.format)
        faulty = [m.index for m in records if m.fault]
        first = records[0].data
        text = (f"{config.machine}: {len(records)} operational records ({args.scenario}"
                + (f", fault {records[faulty[0]].fault} from record {faulty[0]}" if faulty else "")
                + f"), {first.duration:.3g} s at {first.fs:g} Hz x {len(config.outputs)} outputs, no force "
                f"channel, {100 * noise:g} % sensor noise; wrote {manifest}")
        emit(args, {"manifest": str(manifest), "count": len(records), "first_fault": faulty[0] if faulty else None},
             text)
        return 0
    noise = 0.01 if args.noise is None else args.noise
    data = simulate_scenario(config, args.scenario, n=args.count, fault_at=args.fault_at, component=args.component,
                             severity=args.severity, noise=noise, interval=timedelta(minutes=args.interval),
                             start=start, model=model, rng=args.seed)
    manifest = write_scenario(data, args.directory, machine=config.machine, scenario=args.scenario,
                              extension=args.format)
    faulty = [m.index for m in data if m.fault]
    text = (f"{config.machine}: {len(data)} measurements ({args.scenario}"
            + (f", fault {data[faulty[0]].fault} from measurement {faulty[0]}" if faulty else "")
            + f"), {data[0].frf.freq.size} lines x {len(config.outputs)} outputs x {len(config.inputs)} inputs, "
            f"{100 * noise:g} % noise; wrote {manifest}")
    emit(args, {"manifest": str(manifest), "count": len(data), "first_fault": faulty[0] if faulty else None}, text)
    return 0


def ingest(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from cappe.monitor import Monitor, MonitorConfig, RecordedFiles, file_digest, read_scenario
    from cappe.monitor import ingest as run_ingest

    conditions = number_pairs(args.condition, "--condition")
    read = _reader(args.sensor_map)
    jobs: list[tuple[Path, datetime, dict[str, float]]] = []
    if args.manifest:
        _, entries = read_scenario(args.manifest)
        jobs += [(e["file"], e["timestamp"], {**e.get("conditions", {}), **conditions}) for e in entries]
    if args.time and len(args.files) != 1:
        msg = "--time needs exactly one FILE"
        raise UsageError(msg)
    for name in args.files:
        path = Path(name)
        if args.time:
            when = _when(args.time, "--time")
        else:
            try:
                when = datetime.fromtimestamp(path.stat().st_mtime, UTC)
            except OSError as exc:
                msg = f"{path}: {exc.strerror or exc}; nothing was recorded"
                raise DataError(msg) from exc
        jobs.append((path, when, conditions))
    if not jobs:
        msg = "give measurement FILEs or --manifest"
        raise UsageError(msg)
    results: list[dict[str, Any]] = []
    skipped: list[dict[str, str]] = []
    lines: list[str] = []
    with _open(args.store) as store:
        machine = _machine(args, store)
        monitor = Monitor(MonitorConfig.from_dict(store.machine_config(machine)))
        known = RecordedFiles(store, machine)
        # a progress bar on a terminal only (None: tqdm's test) unless asked: never in a log or a pipe by default
        quiet = len(jobs) < 3 or args.json
        progress = tqdm(jobs, desc="ingest", unit="meas", disable=False if args.progress else (quiet or None),
                        leave=False)
        for index, (path, when, conds) in enumerate(progress):
            before: set[int] | None = None
            try:
                digest = file_digest(path)
                why = known.seen(str(path), digest)
                if why is not None:  # a re-run batch continues where it stopped
                    skipped.append({"file": str(path), "why": why})
                    continue
                before = _recorded(store, machine, path, when)
                data, notes = read(path)
                lines += [f"note {path.name}: {n}" for n in notes]
                result = run_ingest(store, machine, data, timestamp=when, source=str(path),
                                    conditions=conds, monitor=monitor, digest=digest)
                known.add(result.measurement_id, str(path), digest)
                results.append({"file": str(path), "timestamp": when.isoformat(), **result.to_dict()})
            except BaseException as exc:
                progress.close()
                after = None if before is None else _recorded(store, machine, path, when, failed=True)
                itself = False if before is None else None if after is None else bool(after - before)
                done = [Path(r["file"]) for r in results]
                what = _ingest_stopped(path, done, itself, len(jobs) - index - 1)
                if isinstance(exc, OSError) and exc.strerror:
                    msg = f"{path}: {exc.strerror}; {what}"
                    raise DataError(msg) from exc
                if isinstance(exc, (DataError, ModelError, OSError)):
                    text = " ".join(str(exc).split()) or type(exc).__name__
                    msg = f"{path}: {text}; {what}"
                    raise DataError(msg) from exc
                exc.add_note(f"cappe monitor ingest stopped at {path}: {what}")
                raise
            lines += _judgement_lines(result, path, when)
        counts = store.counts(machine)
        has_baseline = store.baseline(machine) is not None
    lines += [f"skipped {s['file']}: {s['why']}" for s in skipped]
    unjudged = sum(1 for r in results if r["not_judged"])
    lines.append(f"{machine}: ingested {len(results)} measurement(s)"
                 + (f" ({unjudged} not judged)" if unjudged else "")
                 + (f", skipped {len(skipped)} recorded already" if skipped else "")
                 + f"; {counts['measurements']} recorded, {counts['alarms']} alarm(s) in total")
    if results:
        last = results[-1]
        lines.append("latest factors: " + ", ".join(f"{k} {v:.4f}" for k, v in last["factors"].items()))
        if not has_baseline:
            lines.append("no baseline yet: learn one with `cappe monitor baseline` to start detection")
        elif last["active"]:
            lines.append("active faults: " + ", ".join(f"{k} ({v})" for k, v in last["active"].items()))
    emit(args, {"machine": machine, "measurements": results, "skipped": skipped, "counts": counts},
         "\n".join(lines))
    return 0


def _reader(sensor_map: str | None) -> Any:
    """A function path -> (measurement, notes): read the file, its channels renamed by the sensor map."""
    from cappe.io import read_measurements
    from cappe.io.sensor_map import apply_sensor_map, map_time_data, read_sensor_map
    from cappe.systems.frf import FRFData

    mapping = read_sensor_map(sensor_map) if sensor_map else None

    def read(path: Path) -> tuple[Any, list[str]]:
        data = read_measurements(path)
        if mapping is None:
            return data, []
        if isinstance(data, FRFData):
            return apply_sensor_map(data, mapping, sensor_map or "")
        return map_time_data(data, mapping, sensor_map or "")

    return read


def _judgement_lines(result: Any, path: Path, when: datetime) -> list[str]:
    """The lines a person must see about one ingested measurement: its alarms, why it was not judged, notes."""
    lines = [f"ALARM {when.isoformat()} {path.name}: {alarm.message}" for alarm in result.alarms]
    if result.not_judged:
        lines.append(f"NOT JUDGED {when.isoformat()} {path.name} (recorded as measurement "
                     f"{result.measurement_id}): {'; '.join(result.not_judged)}")
    lines += [f"note {when.isoformat()} {path.name}: {n}" for n in result.notes]
    return lines


#: File endings ``monitor watch`` reads as measurements.
_MEASUREMENT_SUFFIXES = (".uff", ".unv", ".csv", ".npz")


def watch(args: argparse.Namespace) -> int:
    import time

    from cappe.monitor import Monitor, MonitorConfig, RecordedFiles, file_digest, read_scenario
    from cappe.monitor import ingest as run_ingest

    folder = Path(args.directory)
    if not folder.is_dir():
        msg = f"{folder}: not a folder"
        raise UsageError(msg)
    conditions = number_pairs(args.condition, "--condition")
    read = _reader(args.sensor_map)
    looked: dict[Path, tuple[int, float]] = {}  # size and time at the last look: a file still written changes
    done: dict[Path, tuple[int, float]] = {}  # files dealt with in this process: their size and time then
    counts = {"ingested": 0, "skipped": 0, "failed": 0}
    with _open(args.store) as store:
        machine = _machine(args, store)
        monitor = Monitor(MonitorConfig.from_dict(store.machine_config(machine)))
        print(f"{machine}: watching {folder} (every {args.interval:g} s; Ctrl-C stops)", flush=True)
        try:
            while True:
                known = RecordedFiles(store, machine)  # the store is the memory: a restart starts from it
                listed: dict[Path, tuple[datetime, dict[str, float]]] = {}
                manifest = folder / "scenario.json"
                if manifest.is_file():
                    try:
                        _, entries = read_scenario(manifest)
                        listed = {Path(e["file"]).resolve(): (e["timestamp"], {**e.get("conditions", {}),
                                                                                 **conditions}) for e in entries}
                    except DataError as exc:
                        print(f"error: {exc}; its files are read with their modification times", flush=True)
                now = time.time()
                ready = []
                for path in sorted(p for p in folder.iterdir() if p.suffix.lower() in _MEASUREMENT_SUFFIXES
                                   and p.is_file()):
                    try:
                        stat = path.stat()
                    except OSError:
                        continue  # gone since the listing
                    seen, looked[path] = looked.get(path), (stat.st_size, stat.st_mtime)
                    if done.get(path) == looked[path]:
                        continue
                    if seen != (stat.st_size, stat.st_mtime) and (seen is not None or args.settle > 0):
                        continue  # new or still changing: look again next time
                    if now - stat.st_mtime < args.settle:
                        continue
                    ready.append((stat.st_mtime, path))
                for _, path in sorted(ready):
                    when, conds = listed.get(path.resolve(),
                                             (datetime.fromtimestamp(path.stat().st_mtime, UTC), conditions))
                    try:
                        digest = file_digest(path)
                        why = known.seen(str(path), digest)
                        if why is None:
                            data, notes = read(path)
                            result = run_ingest(store, machine, data, timestamp=when, source=str(path),
                                                conditions=conds, monitor=monitor, digest=digest)
                            known.add(result.measurement_id, str(path), digest)
                            counts["ingested"] += 1
                            lines = [f"{when.isoformat()} {path.name}: recorded as measurement "
                                     f"{result.measurement_id}", *(f"note {path.name}: {n}" for n in notes),
                                     *_judgement_lines(result, path, when)]
                        else:
                            counts["skipped"] += 1
                            lines = [f"skipped {path}: {why}"]
                    except (DataError, ModelError, OSError) as exc:
                        counts["failed"] += 1
                        lines = [f"error: {path}: {' '.join(str(exc).split())}; not retried until the file changes"]
                    done[path] = looked[path]
                    print("\n".join(lines), flush=True)
                if args.once:
                    break
                time.sleep(args.interval)
        except KeyboardInterrupt:
            pass
    print(f"{machine}: {counts['ingested']} ingested, {counts['skipped']} skipped (recorded already), "
          f"{counts['failed']} failed", flush=True)
    return 1 if counts["failed"] else 0


def _recorded(store: Any, machine: str, path: Path, when: datetime, *, failed: bool = False) -> set[int] | None:
    """Ids of the measurements recorded from ``path`` at ``when`` (a source is recorded once per machine); None
    when the store cannot tell after a failure."""
    try:
        return {r.id for r in store.measurements(machine, since=when, until=when) if r.source == str(path)}
    except Exception:
        if not failed:
            raise
        return None


def _file_list(paths: list[Path]) -> str:
    shown = [str(p) for p in paths]
    return ", ".join(shown if len(shown) <= 4 else [*shown[:2], "...", shown[-1]])


def _ingest_stopped(path: Path, done: list[Path], itself: bool | None, later: int) -> str:
    """What a multi-file ingest that failed at ``path`` left recorded: the files before it (each recorded in its
    own transactions), ``path`` itself (None: unknown), and the ``later`` files not attempted."""
    after = f"the {later} file(s) after it were not ingested" if later else ""
    if itself is None:
        own = f"whether {path} was recorded is unknown"
    elif itself:
        own = f"{path} itself was recorded before the failure"
    else:
        own = f"{path} was not recorded"
    if not done and itself is False:
        return "nothing was recorded" + (f"; the {later} file(s) after it were not ingested" if later else "")
    earlier = f"{len(done)} earlier file(s) ({_file_list(done)}) were recorded" if done else ""
    return ", ".join(part for part in (earlier, own, after) if part)


def baseline(args: argparse.Namespace) -> int:
    from cappe.monitor import learn_store_baseline

    with _open(args.store) as store:
        machine = _machine(args, store)
        result = learn_store_baseline(store, machine, first=args.first,
                                      since=_when(args.since, "--since") if args.since else None,
                                      until=_when(args.until, "--until") if args.until else None,
                                      resolution=args.resolution)
    doc = result.to_dict()
    lines = [f"{machine}: baseline from {result.n_measurements} measurement(s)"
             + (f", depending on {', '.join(result.conditions)}" if result.conditions else "")]
    lines.append(f"  {'component':10s} {'factor':>8s} {'std %':>8s}")
    for name in result.names:
        lines.append(f"  {name:10s} {doc['mean'][name]:8.4f} {100 * doc['std'][name] / doc['mean'][name]:8.4f}")
    lines.append(f"resolution {100 * result.resolution:.2g} % "
                 + ("(given)" if args.resolution is not None else "(derived from the healthy data's own scatter)"))
    lines += _rate_lines(result.rate_terms)
    lines += [f"left out: {why}" for why in result.left_out]
    doc.pop("frf", None)  # the mean FRF is for the dashboard, not the terminal
    emit(args, doc, "\n".join(lines))
    return 0


def _rate_lines(terms: dict[str, Any]) -> list[str]:
    """What the baseline takes from the conditions' rates of change, for people."""
    from cappe.monitor import RATE_GAP

    by_condition: dict[str, list[str]] = {}
    for name, conditions in terms.items():
        for condition in conditions:
            by_condition.setdefault(condition, []).append(name)
    lines = [f"rate term in use: the expectation of {', '.join(names)} follows the rate of change of {condition} "
             "(per minute, from the previous measurement: a condition sensor that lags); a measurement without a "
             f"previous one within {RATE_GAP.total_seconds() / 60:g} min is judged at the learned mean rate, with "
             "wider uncertainty"
             for condition, names in by_condition.items()]
    return lines


def _status_of(store: Any, machine: str) -> dict[str, Any]:
    from cappe.monitor import (
        Baseline,
        MonitorConfig,
        detectable_change,
        forecast_fault,
        severity_rank,
        worst_severity,
    )

    latest = store.latest_measurement(machine)
    table = store.estimates(machine, path="fast")
    factors: dict[str, Any] = {}
    if latest is not None and len(table):
        rows = table[table["measurement_id"] == latest.id]
        changes = store.estimates(machine, path="deviation")
        changes = changes[changes["measurement_id"] == latest.id]
        change = dict(zip(changes["parameter"], changes["value"], strict=True))
        factors = {r.parameter: {"value": float(r.value), "std": None if r.std is None else float(r.std),
                                 "change": None if r.parameter not in change else float(change[r.parameter])}
                   for r in rows.itertuples()}
    active = store.alarms(machine, unacknowledged=True)
    worst = worst_severity([a.severity for a in active])
    forecasts: dict[str, Any] = {}
    for fault in sorted({a.component for a in active}):
        try:
            forecast = forecast_fault(store, machine, fault)
        except DataError:  # a config another program wrote: the status stands without it
            forecast = None
        if forecast is not None and severity_rank(worst_severity([a.severity for a in active
                                                                   if a.component == fault])) < 3:
            forecasts[fault] = {**forecast.to_dict(), "text": forecast.text()}
    doc = store.baseline(machine)
    detectable = None
    try:
        limitations = _limitations(MonitorConfig.from_dict(store.machine_config(machine)))
    except DataError:
        limitations = []
    if doc is not None:
        try:
            detectable = detectable_change(MonitorConfig.from_dict(store.machine_config(machine)),
                                           Baseline.from_dict(doc))
        except DataError:  # a config or baseline another program wrote: the status stands without it
            detectable = None
    return {"machine": machine, "measurements": store.counts(machine)["measurements"],
            "latest": None if latest is None else latest.to_dict(), "factors": factors,
            "baseline": doc is not None, "detectable": detectable, "limitations": limitations,
            "forecasts": forecasts,
            "unacknowledged_alarms": [a.to_dict() for a in active], "worst_severity": worst}


def status(args: argparse.Namespace) -> int:
    with _open(args.store) as store:
        machines = [args.machine] if args.machine else store.machines()
        docs = [_status_of(store, m) for m in machines]
    lines = []
    for d in docs:
        when = d["latest"]["timestamp"] if d["latest"] else "never"
        lines.append(f"{d['machine']}: {d['measurements']} measurement(s), latest {when}, "
                     f"{'baseline learned' if d['baseline'] else 'no baseline'}, "
                     f"{len(d['unacknowledged_alarms'])} unacknowledged alarm(s), worst: {d['worst_severity'] or '-'}")
        for name, f in d["factors"].items():
            std = f"+- {f['std']:.2g}" if f["std"] is not None else ""
            change = f"  {100 * f['change']:+6.2f} % from healthy" if f.get("change") is not None else ""
            lines.append(f"  {name:10s} {f['value']:.4f} {std:10s}{change}")
        if d["detectable"]:
            det = d["detectable"]
            sizes = ", ".join(f"{name} {100 * v:.2g} %" for name, v in det["change"].items())
            lines.append(f"  detectable: a change of {sizes} is found after about {det['measurements']:.2g} "
                         f"measurement(s) ({det['shift']:g} standard deviations of the healthy scatter, resolution "
                         f"{100 * det['resolution']:.2g} %); smaller changes take longer")
            if det.get("size_scale"):
                per = ", ".join(f"{name} {100 * v:.2g} %" for name, v in det["size_scale"].items())
                lines.append(f"  sizes: a diagnosed change's size is uncertain beyond the scatter by +- {per} of "
                             "itself (read back on the machine's twin: the model with its damping fitted to the "
                             f"healthy FRFs; the healthy machine is {100 * det['model_offset']:.2g} % from its model)")
            elif det.get("size_scale_std") is not None:
                lines.append(f"  sizes: a diagnosed change's size is uncertain by +- "
                             f"{100 * det['size_scale_std']:.2g} % of itself beyond the scatter (the healthy machine "
                             f"is {100 * det['model_offset']:.2g} % from its model, RMS over the components: its "
                             "sensitivities are about that far off)")
            lines += [f"  {line}" for line in _rate_lines(det.get("rate_terms") or {})]
        lines += [f"  forecast {name}: {f['text']}" for name, f in d["forecasts"].items()]
        lines += [f"  note: {text}" for text in d["limitations"]]
        if d["latest"] and d["latest"].get("meta", {}).get("not_judged"):
            lines.append("  latest measurement NOT JUDGED: " + "; ".join(d["latest"]["meta"]["not_judged"]))
    emit(args, {"machines": docs}, "\n".join(lines) if lines else f"{args.store}: no machines")
    return 0


def history(args: argparse.Namespace) -> int:
    with _open(args.store) as store:
        machine = _machine(args, store)
        table = store.estimates(machine, path=args.path, parameters=names(args.parameter))
    if table.empty:
        emit(args, {"machine": machine, "rows": []}, f"{machine}: no {args.path} estimates recorded")
        return 0
    wide = table.pivot_table(index=["measurement_id", "timestamp"], columns="parameter", values="value")
    if args.last:
        wide = wide.tail(args.last)
    if args.csv:
        from cappe.io import write_text

        write_text(args.csv, wide.to_csv())
    text = wide.to_string(float_format=lambda v: f"{v:.4f}")
    rows = [{"measurement_id": int(i), "timestamp": _iso(t), **row.to_dict()} for (i, t), row in wide.iterrows()]
    emit(args, {"machine": machine, "path": args.path, "rows": rows}, text)
    return 0


def _iso(when: Any) -> str:
    """A stored time as ISO 8601 with the 'T' separator (the form --since, --until and --start take)."""
    return str(when.isoformat()) if hasattr(when, "isoformat") else str(when)


def alarms(args: argparse.Namespace) -> int:
    with _open(args.store) as store:
        machine = _machine(args, store)
        if args.ack is not None:
            store.acknowledge(args.ack)
        records = store.alarms(machine, unacknowledged=not args.all)
    lines = [f"{machine}: {len(records)} {'' if args.all else 'unacknowledged '}alarm(s)"
             + (f"; acknowledged {args.ack}" if args.ack is not None else "")]
    for a in records:
        mark = "acknowledged" if a.acknowledged else "open"
        lines.append(f"  #{a.id} {a.timestamp.isoformat()} [{a.severity}, {mark}] {a.message}")
    emit(args, {"machine": machine, "alarms": [a.to_dict() for a in records]}, "\n".join(lines))
    return 0


def serve(args: argparse.Namespace) -> int:
    from cappe.monitor import make_server

    with _open(args.store) as store:
        server = make_server(store, host=args.host, port=args.port, allowed_hosts=args.allowed_host)
        started = {"store": args.store, "url": server.url, "allowed_hosts": list(server.allowed_hosts)}
        if args.out:
            from cappe.io import write_json

            write_json(args.out, started)
        if args.json:  # one line: a script that asked for a free port (--port 0) reads the address from it
            print(json.dumps(started), flush=True)
        else:
            print(f"cappe dashboard of {args.store} at {server.url} (Ctrl-C stops it); answers to host names "
                  + ", ".join(f"[{n}]" if ":" in n else n for n in server.allowed_hosts), flush=True)
        try:
            server.serve_forever()
        except KeyboardInterrupt:
            pass
        finally:
            server.shutdown()
    return 0
