"""Every option of every command reaches what it should (issue 22: options parsed and then dropped).

For each command a base command line runs, then the same line with one option added or changed; what the command
printed (JSON where it has it), its exit code and the files it wrote must differ. A dropped option (``cappe estimate
--position`` was one) leaves them equal. ``test_every_option_is_audited`` walks the parser: an option added later
without a case here, or without a stated reason in ``EXEMPT``, fails it.

The data files are made once per module: the README's sled, a carriage of our own whose dynamics depend on the axis
position (the sled's do not: its table and shoe move together), the two-mass rig's modes, time records, FRFs, a
monitoring store, and a static bearing test written from the rigid-shaft lever rule with numpy. A command line
that several cases share (a base) runs once per module. The demo's identification and monitoring stages take
minutes: their options are in ``EXEMPT``, each naming the faster test of the same contract; a case that must run such
a stage is ``extended``.
"""

from __future__ import annotations

import argparse
import fcntl
import hashlib
import json
import os
import re
import shutil
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from cappe.cli import build_parser, main

README = Path(__file__).resolve().parents[2] / "README.md"
SLIDE = Path(__file__).resolve().parents[1] / "data" / "bench-slide.yaml"
SLIDE_TRUTH = {"me_kx": 7.1e7, "me1_ky": 0.95e8, "me2_ky": 1.2e8, "me3_ky": 1.7e8, "me_kz": 4.1e7, "lgs_kx": 2.3e8,
               "lgs_ky": 3.4e8, "bsd_kz": 0.8e8, "me_by": 1.1e4, "me_dx": 0.025, "lgs_bx": 1.2e3, "lgs_dy": 0.03}

#: A table on one shoe at height z: the x spring acts z above the table's centre, so x and ry couple by z (no two
#: frequencies alike: repeated modes would make the local sensitivities warn).
CARRIAGE = """\
format: cappe.model/1
name: carriage
parameters:
  - {name: m, value: 3.0, unit: kg, kind: mass}
  - {name: k, value: 2.0e6, unit: N/m, kind: stiffness, bounds: [1.0e6, 4.0e6], unknown: true}
  - {name: c, value: 30.0, unit: N s/m, kind: damping, bounds: [10.0, 90.0], unknown: true}
  - {name: preload, value: 1.0, unit: '-', kind: other}
axes:
  - {name: z, positions: [0.0, 0.1, 0.2]}
bodies:
  - {name: table, mass: m, inertia: {xx: 0.02, yy: 0.025, zz: 0.03}}
elements:
  - {name: shoe, bodies: [ground, table], at: [0, 0, z], stiffness: {x: k*preload, y: 1.3*k, z: 0.8*k, rx: 1.0e5,
     ry: 1.3e5, rz: 1.6e5}, damping: {x: c, y: c, z: c, rx: 1.0, ry: 1.0, rz: 1.0}}
inputs:
  - {name: F, body: table, direction: x}
  - {name: G, body: table, direction: y}
outputs:
  - {name: d, quantity: displacement, body: table, direction: x}
  - {name: e, quantity: displacement, body: table, direction: y}
sensors:
  - {name: s1, body: table, point: [0, 0, 0.1]}
  - {name: s2, body: table, point: [0.1, 0, 0]}
"""

# the static bearing test: force at Z_FORCE on a rigid shaft in bearings at Z_FRONT and Z_REAR (stiffness K_FRONT,
# K_REAR), displacement probes at Z_SENSORS
Z_FORCE, Z_FRONT, Z_REAR, Z_SENSORS = 0.25, 0.1, -0.1, (0.15, 0.2)
K_FRONT, K_REAR = 2.0e8, 1.0e8


def _bearing_record(path: Path, k_front: float = K_FRONT, k_rear: float = K_REAR) -> None:
    """Force F (and F2 = 2 F, a second force channel) with two noisy probes of a rigid shaft."""
    from cappe.io import TimeData, write_time_data

    rng = np.random.default_rng(5)
    force = 200.0 * np.sign(np.sin(2 * np.pi * np.arange(600) / 200 + 0.1)) * np.linspace(0.2, 1.0, 600)
    # lever rule: F_front + F_rear = F, F_front (Z_FRONT - Z_REAR) = F (Z_FORCE - Z_REAR)
    f_front = force * (Z_FORCE - Z_REAR) / (Z_FRONT - Z_REAR)
    f_rear = force - f_front
    u_front, u_rear = f_front / k_front, f_rear / k_rear
    slope = (u_front - u_rear) / (Z_FRONT - Z_REAR)
    probes = [u_rear + slope * (z - Z_REAR) for z in Z_SENSORS]
    noisy = [u * (1 + 0.01 * rng.standard_normal(u.size)) for u in probes]
    write_time_data(path, TimeData.from_channels(np.arange(force.size) * 0.01,
                                                 {"F": force, "F2": 2 * force, "d1": noisy[0],
                                                                                 "d2": noisy[1]}))


@pytest.fixture(scope="module")
def world(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Every data file the cases read, in one folder (the cases run there).

    Under pytest-xdist (``make test`` spreads this file's cases over the workers) the workers share one build
    (~15 s): the first to come makes it under a lock in the run's common temporary folder, and each worker copies
    it into a folder of its own, which only its cases change (a case's outputs are told apart by what appears in
    its folder).
    """
    own = tmp_path_factory.mktemp("audit")
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        _build_world(own)
        return own
    shared = tmp_path_factory.getbasetemp().parent / "audit-world"
    with shared.with_suffix(".lock").open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if not (shared / ".built").is_file():
            shutil.rmtree(shared, ignore_errors=True)
            shared.mkdir()
            _build_world(shared)
            (shared / ".built").touch()
    shutil.copytree(shared, own, dirs_exist_ok=True)
    (own / ".built").unlink()
    return own


def _build_world(w: Path) -> None:
    """Write :func:`world`'s files into ``w``."""
    sled = README.read_text().split("```yaml\n", 1)[1].split("```", 1)[0]
    (w / "sled.yaml").write_text(sled)
    (w / "carriage.yaml").write_text(CARRIAGE)
    # the same models with another nominal mass: a different MODEL argument with the same channels
    (w / "carriage2.yaml").write_text(CARRIAGE.replace("value: 3.0, unit: kg", "value: 3.5, unit: kg"))
    rig = (Path(__file__).resolve().parents[2] / "src/cappe/library/models/two-mass-rig.yaml").read_text()
    assert "{name: m1, value: 1.39," in rig
    (w / "rig2.yaml").write_text(rig.replace("{name: m1, value: 1.39,", "{name: m1, value: 1.5,"))
    (w / "spindle.json").write_text(json.dumps({"ms": 11.0}))
    (w / "carriage_params.json").write_text(json.dumps({"m": 4.0}))
    (w / "rig_params.json").write_text(json.dumps({"m1": 2.0}))
    (w / "rig_start.json").write_text(json.dumps({"k11": 1.3e6}))
    (w / "rig_truth.json").write_text(json.dumps({"k11": 1.1e6}))
    (w / "slide_truth.json").write_text(json.dumps(SLIDE_TRUTH))
    w_ = str(w)
    steps = [
        ["model", "modes", "builtin:two-mass-rig", "--modal-out", f"{w_}/rig_ref.json"],
        ["model", "modes", "builtin:two-mass-rig", "--set", "k12=2e5", "--modal-out", f"{w_}/rig_ref2.json"],
        ["simulate", f"{w_}/carriage.yaml", "--excite", "F=random", "--excite", "G=random", "--fs", "1000",
         "--duration", "2", "--noise", "0.01", "--seed", "1", "-o", f"{w_}/car.npz"],
        ["simulate", "builtin:two-mass-rig", "--excite", "F1=random", "--excite", "F2=random", "--fs", "1024",
         "--duration", "2", "--outputs", "d1,d2", "--noise", "0.01", "--seed", "1", "-o", f"{w_}/run.npz"],
        ["simulate", "builtin:two-mass-rig", "--set", "c11=20", "--set", "c22=4", "--excite", "F1=random", "--excite",
         "F2=random", "--fs", "1000", "--duration", "2", "--noise", "0.01", "--seed", "1", "--intersample", "zoh",
         "-o", f"{w_}/est.npz"],  # a held input: what the EKF models (its residual tests refuse anything else)
        ["simulate", "builtin:two-mass-rig", "--excite", "F1=impact", "--fs", "2048", "--duration", "2", "--band",
         "0:500", "--amplitude", "200", "--outputs", "a1,a2", "--noise", "0.01", "--seed", "1", "-o",
         f"{w_}/hit.npz"],
        ["frf", f"{w_}/hit.npz", "--inputs", "F1", "--outputs", "a1,a2", "--impact", "-o", f"{w_}/frf.uff"],
        ["simulate", str(SLIDE), "--params", f"{w_}/slide_truth.json", "--positions", "all", "-o",
         f"{w_}/slide_ref.json"],
        ["simulate", str(SLIDE), "--params", f"{w_}/slide_truth.json", "--positions", "all", "--noise-frequency",
         "0.01", "--seed", "1", "-o", f"{w_}/slide_ref2.json"],
        ["monitor", "init", f"{w_}/store.db", "--machine", "m1", "--model", "builtin:spindle-bearing", "--outputs",
         "sx,sy,hax,hay,haz,htax", "--band", "150:1000"],
        ["monitor", "simulate", "healthy", "--store", f"{w_}/store.db", "--machine", "m1", "-n", "12", "--seed", "1",
         "-o",
         f"{w_}/day1"],
        ["monitor", "init", f"{w_}/store.db", "--machine", "m2", "--model", "builtin:spindle-bearing", "--outputs",
         "sx,sy,hax,hay,haz,htax", "--band", "150:900"],
        ["monitor", "ingest", f"{w_}/store.db", "--machine", "m1", "--manifest", f"{w_}/day1/scenario.json"],
        ["monitor", "ingest", f"{w_}/store.db", "--machine", "m2", "--manifest", f"{w_}/day1/scenario.json"],
        ["monitor", "baseline", f"{w_}/store.db", "--machine", "m1"],
        ["monitor", "baseline", f"{w_}/store.db", "--machine", "m2"],
        ["monitor", "simulate", "bearing-loss", "--store", f"{w_}/store.db", "--machine", "m1", "-n", "3",
         "--fault-at", "1", "--seed", "2", "--start", "2026-01-06T06:00:00+00:00", "-o", f"{w_}/day2"],
        ["monitor", "ingest", f"{w_}/store.db", "--machine", "m1", "--manifest", f"{w_}/day2/scenario.json"],
        ["monitor", "simulate", "healthy", "--store", f"{w_}/store.db", "--machine", "m1", "-n", "2", "--seed", "3",
         "--start", "2026-01-07T06:00:00+00:00", "-o", f"{w_}/day3"],
        ["monitor", "simulate", "bearing-loss", "--store", f"{w_}/store.db", "--machine", "m1", "-n", "2",
         "--fault-at", "0", "--seed", "4", "--start", "2026-01-08T06:00:00+00:00", "-o", f"{w_}/day4"],
    ]
    for argv in steps:
        assert main(argv) == 0, argv
    _bearing_record(w / "static.csv")
    _bearing_record(w / "static2.csv", k_front=1.5e8)
    _sensor_maps(w)


def _sensor_maps(w: Path) -> None:
    """Sensor maps that change what a command reads: the FRF's accelerometers named as the rig's nodes, the slide
    reference without its last channel, and the spindle's probes as another program names them (node numbers, one
    mounted in -y: ``foreign/m.npz``, which only the map makes readable); a folder without a scenario.json."""
    from dataclasses import replace

    from cappe.io import read_measurements, read_modal_data, write_frf

    (w / "frf_map.csv").write_text("channel,sensor\na1,n1:x\na2,n2:x\n")
    sensors = read_modal_data(w / "slide_ref.json").sensors
    (w / "slide_map.csv").write_text("channel,sensor\n" + "".join(f"{s},{s}\n" for s in sensors[:-1]))
    first = sorted(p for p in (w / "day3").iterdir() if p.name != "scenario.json")[0]
    frf = read_measurements(first)
    foreign = {"sx": "11:+x", "sy": "12:-y"}
    sign = np.array([-1.0 if foreign.get(c, "").endswith("-y") else 1.0 for c in frf.output_names])
    (w / "foreign").mkdir()
    write_frf(w / "foreign" / "m.npz", replace(frf, output_names=tuple(foreign.get(c, c) for c in frf.output_names),
                                               H=frf.H * sign[:, None, None]))
    (w / "spindle_map.csv").write_text("channel,sensor\n" + "".join(
        f"{foreign.get(c, c)},{c}\n" for c in (*frf.input_names, *frf.output_names)))
    (w / "loose").mkdir()
    shutil.copyfile(first, w / "loose" / first.name)


def _scrub(value: object) -> object:
    """Drop what changes from run to run by itself: wall-clock times."""
    if isinstance(value, dict):
        return {k: _scrub(v) for k, v in value.items() if not re.fullmatch(r"(cpu_)?timings?|runtime(_s)?|elapsed(_s)?", k)}
    if isinstance(value, list):
        return [_scrub(v) for v in value]
    return value


#: Observed runs by command line: cases that share a base run it once (every run leaves the folder as it found it,
#: and a store it changes is a fresh copy, so a command line's effect is the same each time).
_RUNS: dict[tuple[str, ...], tuple[object, ...]] = {}


def _observe(folder: Path, capsys: pytest.CaptureFixture[str], argv: list[str]) -> tuple[object, ...]:
    """Exit code, printed output (scrubbed), stderr's words and the files written, for one run in ``folder``."""
    key = tuple(argv)
    if key not in _RUNS:
        _RUNS[key] = _run(folder, capsys, argv)
    return _RUNS[key]


def _run(folder: Path, capsys: pytest.CaptureFixture[str], argv: list[str]) -> tuple[object, ...]:
    """:func:`_observe` without the memory."""
    for arg in argv:  # a run that changes a store works on a fresh copy
        if re.fullmatch(r".*/work\d?\.db", arg):
            shutil.copyfile(folder / "store.db", arg)
    before = {p for p in folder.rglob("*")}
    code = main(argv)
    captured = capsys.readouterr()
    out = captured.out
    err = re.sub(r"[\d.]+", "#", captured.err)  # progress bars and deprecation messages, without their numbers
    try:
        printed: object = _scrub(json.loads(out))
    except ValueError:  # text: without its wall-clock times ("runtime: ...", the demo's "done in 3.79 s")
        printed = "\n".join(re.sub(r"\bin \d+(\.\d+)? s\b", "in # s", line) for line in out.splitlines()
                            if not line.startswith("runtime:"))
    written = {}
    for path in sorted(set(folder.rglob("*")) - before, reverse=True):
        if path.is_file():
            data = path.read_bytes()
            if path.suffix == ".json":
                data = json.dumps(_scrub(json.loads(data)), sort_keys=True).encode()
            written[path.relative_to(folder).as_posix()] = hashlib.sha256(data).hexdigest()
            path.unlink()
        else:
            path.rmdir()
    for arg in argv:
        if re.fullmatch(r".*/work\d?\.db", arg):
            Path(arg).unlink(missing_ok=True)
    return code, printed, err, tuple(sorted(written.items()))


def _case(command: str, option: str, base: list[str], extra: list[str] | None = None,
          variant: list[str] | None = None, *, slow: bool = False, fails: bool = False,
          extended: str | None = None) -> object:
    """One audit case: ``base`` and ``base + extra`` (or ``variant``) must differ in their effect (``fails``: the
    base run is refused, the option is what makes the command go through; ``extended``: the reason a case that
    takes minutes is left out of ``make test``, naming the faster test of the same contract)."""
    marks = [pytest.mark.slow] if slow or extended else []
    if extended:
        marks.append(pytest.mark.extended(reason=extended))
    return pytest.param(command, option, base, variant if variant is not None else base + (extra or []), fails,
                        id=f"{command} {option}", marks=marks)


def _model_cases(command: str, base: list[str], *, position: list[str] | None = None,
                 out: str = "{w}/out.json") -> list[object]:
    """The options every command on a MODEL shares; ``position`` is the base on the carriage (None: ``base``)."""
    plain = [a for a in base if a != "--json"]
    other = {RIG: "{w}/rig2.yaml", CAR: "{w}/carriage2.yaml"}
    cases = [
        _case(command, "model", base, variant=[other.get(v, v) for v in base]),
        _case(command, "--params", base, ["--params", "{w}/rig_params.json" if "builtin:two-mass-rig" in base
                                          else "{w}/carriage_params.json"]),
        _case(command, "--set", base, ["--set", "m1=2.0" if "builtin:two-mass-rig" in base else "m=4.0"]),
        _case(command, "--json", plain, ["--json"]),
        _case(command, "--out", base, ["-o", out]),
    ]
    carriage = position if position is not None else base
    cases.append(_case(command, "--position", carriage, ["--position", "z=0.2"]))
    return cases


RIG = "builtin:two-mass-rig"
CAR = "{w}/carriage.yaml"

CASES = [
    # -- model --------------------------------------------------------------------------------------------------
    *[c for c in _model_cases("model show", ["model", "show", CAR]) if c.values[1] != "--position"],
    *_model_cases("model matrices", ["model", "matrices", CAR]),
    _case("model matrices", "--symbolic", ["model", "matrices", CAR], ["--symbolic"]),
    *_model_cases("model modes", ["model", "modes", CAR]),
    _case("model modes", "--damping", ["model", "modes", CAR], ["--damping", "undamped"]),
    _case("model modes", "--modal-out", ["model", "modes", CAR], ["--modal-out", "{w}/m.json"]),
    _case("model modes", "--sensors", ["model", "modes", CAR, "--modal-out", "{w}/m.json"], ["--sensors", "s1"]),
    _case("model modes", "--all-positions", ["model", "modes", CAR, "--modal-out", "{w}/m.json"],
          ["--all-positions"]),
    _case("model modes", "--plot", ["model", "modes", RIG], ["--plot", "{w}/mode.html"]),
    _case("model modes", "--mode", ["model", "modes", RIG, "--plot", "{w}/mode.html"], ["--mode", "2"]),
    *_model_cases("model tf", ["model", "tf", CAR, "--input", "F", "--output", "d"]),
    _case("model tf", "--input", ["model", "tf", RIG, "--input", "F1", "--output", "d1"],
          variant=["model", "tf", RIG, "--input", "F2", "--output", "d1"]),
    _case("model tf", "--output", ["model", "tf", RIG, "--input", "F1", "--output", "d1"],
          variant=["model", "tf", RIG, "--input", "F1", "--output", "d2"]),
    _case("model tf", "--exact", ["model", "tf", RIG, "--input", "F1", "--output", "d1"], ["--exact"]),
    _case("model tf", "--symbolic", ["model", "tf", RIG, "--input", "F1", "--output", "d1"], ["--symbolic"]),
    *_model_cases("model zpk", ["model", "zpk", CAR, "--input", "F", "--output", "d"]),
    _case("model zpk", "--input", ["model", "zpk", RIG, "--input", "F1", "--output", "d1"],
          variant=["model", "zpk", RIG, "--input", "F2", "--output", "d1"]),
    _case("model zpk", "--output", ["model", "zpk", RIG, "--input", "F1", "--output", "d1"],
          variant=["model", "zpk", RIG, "--input", "F1", "--output", "d2"]),
    _case("model zpk", "--exact", ["model", "zpk", RIG, "--input", "F1", "--output", "d1", "--json"], ["--exact"]),
    _case("model zpk", "--plot", ["model", "zpk", RIG, "--input", "F1", "--output", "d1"], ["--plot", "{w}/pz.png"]),
    *_model_cases("model ss", ["model", "ss", CAR]),
    _case("model ss", "--inputs", ["model", "ss", RIG], ["--inputs", "F1"]),
    _case("model ss", "--outputs", ["model", "ss", RIG], ["--outputs", "d1"]),
    _case("model ss", "--dt", ["model", "ss", RIG], ["--dt", "1e-3"]),
    _case("model ss", "--method", ["model", "ss", RIG, "--dt", "1e-3"], ["--method", "tustin"]),
    *_model_cases("model frf", ["model", "frf", CAR, "--lines", "40"]),
    _case("model frf", "--inputs", ["model", "frf", RIG, "--lines", "40"], ["--inputs", "F1"]),
    _case("model frf", "--outputs", ["model", "frf", RIG, "--lines", "40"], ["--outputs", "d1"]),
    _case("model frf", "--fmin", ["model", "frf", RIG, "--lines", "40"], ["--fmin", "50"]),
    _case("model frf", "--fmax", ["model", "frf", RIG, "--lines", "40"], ["--fmax", "250"]),
    _case("model frf", "--lines", ["model", "frf", RIG, "--lines", "40"], variant=["model", "frf", RIG, "--lines",
                                                                                    "41"]),
    _case("model frf", "--n", ["model", "frf", RIG, "--lines", "40"], variant=["model", "frf", RIG, "--n", "41"]),
    _case("model frf", "--plot", ["model", "frf", RIG, "--lines", "40"], ["--plot", "{w}/bode.png"]),
    _case("model random-truth", "model", ["model", "random-truth", CAR], variant=["model", "random-truth",
                                                                                   str(SLIDE)]),
    _case("model random-truth", "--unknowns", ["model", "random-truth", CAR], ["--unknowns", "k"]),
    _case("model random-truth", "--seed", ["model", "random-truth", CAR], ["--seed", "1"]),
    _case("model random-truth", "--json", ["model", "random-truth", CAR], ["--json"]),
    _case("model random-truth", "--out", ["model", "random-truth", CAR], ["-o", "{w}/truth.json"]),
    *_model_cases("model check", ["model", "check", CAR]),
    _case("model check", "--inputs", ["model", "check", RIG], ["--inputs", "F1"]),
    _case("model check", "--outputs", ["model", "check", RIG], ["--outputs", "d1"]),
    _case("model check", "--exact", ["model", "check", RIG], ["--exact", "never"]),
    # -- sensitivity ----------------------------------------------------------------------------------------------
    *_model_cases("sensitivity", ["sensitivity", CAR, "--local"]),
    _case("sensitivity", "--local", ["sensitivity", RIG, "--sobol", "--reference", "{w}/rig_ref.json", "--n-gsa",
                                     "8", "--parameters", "k11,k12"],
          variant=["sensitivity", RIG, "--local", "--parameters", "k11,k12"]),
    _case("sensitivity", "--sobol", ["sensitivity", RIG, "--local", "--parameters", "k11,k12"],
          variant=["sensitivity", RIG, "--sobol", "--reference", "{w}/rig_ref.json", "--n-gsa", "8",
                   "--parameters", "k11,k12"]),
    _case("sensitivity", "--percent", ["sensitivity", RIG, "--local"], ["--percent", "5"]),
    *[_case("sensitivity", option, ["sensitivity", RIG, "--sobol", "--reference", "{w}/rig_ref.json", "--n-gsa",
                                    "8", "--parameters", "k11,k12"], extra)
      for option, extra in (("--seed", ["--seed", "3"]), ("--threshold", ["--threshold", "0.5"]),
                            ("--criteria", ["--criteria", "frequency"]), ("--plot", ["--plot", "{w}/sobol.png"]),
                            ("--progress", ["--progress"]))],
    _case("sensitivity", "--reference", ["sensitivity", RIG, "--sobol", "--reference", "{w}/rig_ref.json",
                                         "--n-gsa", "8", "--parameters", "k11,k12"],
          variant=["sensitivity", RIG, "--sobol", "--reference", "{w}/rig_ref2.json", "--n-gsa", "8",
                   "--parameters", "k11,k12"]),
    _case("sensitivity", "--parameters", ["sensitivity", RIG, "--local"], ["--parameters", "k11"]),
    _case("sensitivity", "--n-gsa", ["sensitivity", RIG, "--sobol", "--reference", "{w}/rig_ref.json", "--n-gsa",
                                     "8", "--parameters", "k11,k12"],
          variant=["sensitivity", RIG, "--sobol", "--reference", "{w}/rig_ref.json", "--n-gsa", "16",
                   "--parameters", "k11,k12"]),
    _case("sensitivity", "--n", ["sensitivity", RIG, "--sobol", "--reference", "{w}/rig_ref.json", "--n-gsa",
                                 "8", "--parameters", "k11,k12"],
          variant=["sensitivity", RIG, "--sobol", "--reference", "{w}/rig_ref.json", "--n", "16",
                   "--parameters", "k11,k12"]),
    # -- simulate -------------------------------------------------------------------------------------------------
    *_model_cases("simulate", ["simulate", CAR, "--excite", "F=random", "--fs", "512", "--duration", "1", "--json"],
                  out="{w}/out.npz"),
    *[_case("simulate", option, ["simulate", RIG, "--excite", "F1=random", "--fs", "512", "--duration", "1",
                                 "--json"], extra)
      for option, extra in (("--excite", ["--excite", "F2=random"]), ("--fs", ["--fs", "1024"]),
                            ("--duration", ["--duration", "2"]), ("--amplitude", ["--amplitude", "3"]),
                            ("--outputs", ["--outputs", "d1"]), ("--noise", ["--noise", "0.05"]),
                            ("--input-noise", ["--input-noise", "0.05"]), ("--band", ["--band", "0:100"]),
                            ("--seed", ["--seed", "4"]), ("--intersample", ["--intersample", "zoh"]))],
    *[_case("simulate", option, ["simulate", CAR, "--json"], extra)
      for option, extra in (("--positions", ["--positions", "all"]),
                            ("--modes", ["--modes", "2"]), ("--noise-frequency", ["--noise-frequency", "0.01"]),
                            ("--noise-damping", ["--noise-damping", "0.01"]),
                            ("--noise-shape", ["--noise-shape", "0.01"]), ("--uff", ["--uff", "{w}/modes.uff"]),
                            ("--sensors", ["--sensors", "s1"]),
                            ("--frf", ["--frf", "{w}/ref_frf.uff"]))],
    *[_case("simulate", option, ["simulate", CAR, "--json", "--frf", "{w}/ref_frf.uff"], extra)
      for option, extra in (("--driving-points", ["--driving-points", "s2:x"]),
                            ("--frf-outputs", ["--frf-outputs", "s1:x"]), ("--lines", ["--lines", "11"]),
                            ("--noise-frf", ["--noise-frf", "0.02"]))],
    _case("simulate", "--disturb", ["simulate", "builtin:spindle-bearing", "--modes", "3", "--json"],
          ["--disturb", "0.1"]),
    # -- frf, fit, extract-modes ----------------------------------------------------------------------------------
    *[_case("frf", option, ["frf", "{w}/run.npz", "--inputs", "F1", "--outputs", "d1", "--json"], extra)
      for option, extra in (("--estimator", ["--estimator", "H2"]), ("--nperseg", ["--nperseg", "256"]),
                            ("--window", ["--window", "boxcar"]),
                            ("--band", ["--band", "20:300"]), ("--coherence-threshold", ["--coherence-threshold",
                                                                                         "0.99"]),
                            ("--plot", ["--plot", "{w}/frf.png"]), ("--out", ["-o", "{w}/f.npz"]))],
    _case("frf", "--overlap", ["frf", "{w}/run.npz", "--inputs", "F1", "--outputs", "d1", "--nperseg", "256",
                               "--json"], ["--overlap", "0.25"]),
    _case("frf", "data", ["frf", "{w}/run.npz", "--inputs", "F1", "--outputs", "d1", "--json"],
          variant=["frf", "{w}/est.npz", "--inputs", "F1", "--outputs", "d1", "--json"]),
    _case("frf", "--json", ["frf", "{w}/run.npz", "--inputs", "F1", "--outputs", "d1"], ["--json"]),
    _case("frf", "--inputs", ["frf", "{w}/run.npz", "--inputs", "F1", "--outputs", "d1", "--json"],
          variant=["frf", "{w}/run.npz", "--inputs", "F1,F2", "--outputs", "d1", "--json"]),
    _case("frf", "--outputs", ["frf", "{w}/run.npz", "--inputs", "F1", "--outputs", "d1", "--json"],
          variant=["frf", "{w}/run.npz", "--inputs", "F1", "--outputs", "d1,d2", "--json"]),
    _case("frf", "--input", ["frf", "{w}/run.npz", "--inputs", "F1", "--outputs", "d1", "--json"],
          variant=["frf", "{w}/run.npz", "--input", "F1", "F2", "--outputs", "d1", "--json"]),
    _case("frf", "--output", ["frf", "{w}/run.npz", "--inputs", "F1", "--outputs", "d1", "--json"],
          variant=["frf", "{w}/run.npz", "--inputs", "F1", "--output", "d1", "d2", "--json"]),
    _case("frf", "--impact", ["frf", "{w}/hit.npz", "--inputs", "F1", "--outputs", "a1", "--json"], ["--impact"]),
    _case("frf", "--exp-window", ["frf", "{w}/hit.npz", "--inputs", "F1", "--outputs", "a1", "--impact", "--json"],
          ["--exp-window", "0.5"]),
    *[_case("fit", option, ["fit", "{w}/run.npz", "--inputs", "F1", "--output", "d1", "--order", "4", "--json"],
            extra)
      for option, extra in (("--structure", ["--structure", "oe"]), ("--nk", ["--nk", "0"]),
                            ("--prune", ["--prune", "1"]), ("--out", ["-o", "{w}/fit.json"]))],
    _case("fit", "data", ["fit", "{w}/run.npz", "--inputs", "F1", "--output", "d1", "--order", "4", "--json"],
          variant=["fit", "{w}/est.npz", "--inputs", "F1", "--output", "d1", "--order", "4", "--json"]),
    _case("fit", "--json", ["fit", "{w}/run.npz", "--inputs", "F1", "--output", "d1", "--order", "4"], ["--json"]),
    _case("fit", "--inputs", ["fit", "{w}/run.npz", "--inputs", "F1", "--output", "d1", "--order", "4", "--json"],
          variant=["fit", "{w}/run.npz", "--inputs", "F1,F2", "--output", "d1", "--order", "4", "--json"]),
    _case("fit", "--input", ["fit", "{w}/run.npz", "--inputs", "F1", "--output", "d1", "--order", "4", "--json"],
          variant=["fit", "{w}/run.npz", "--input", "F1", "F2", "--output", "d1", "--order", "4", "--json"]),
    _case("fit", "--output", ["fit", "{w}/run.npz", "--inputs", "F1", "--output", "d1", "--order", "4", "--json"],
          variant=["fit", "{w}/run.npz", "--inputs", "F1", "--output", "d2", "--order", "4", "--json"]),
    _case("fit", "--order", ["fit", "{w}/run.npz", "--inputs", "F1", "--output", "d1", "--order", "4", "--json"],
          variant=["fit", "{w}/run.npz", "--inputs", "F1", "--output", "d1", "--order", "6", "--json"]),
    _case("fit", "--criterion", ["fit", "{w}/run.npz", "--inputs", "F1", "--output", "d1", "--max-order", "6",
                                 "--json"], ["--criterion", "bic"]),
    _case("fit", "--max-order", ["fit", "{w}/run.npz", "--inputs", "F1", "--output", "d1", "--max-order", "4",
                                 "--json"],
          variant=["fit", "{w}/run.npz", "--inputs", "F1", "--output", "d1", "--max-order", "6", "--json"]),
    *[_case("fit", option, ["fit", "{w}/run.npz", "--inputs", "F1", "--output", "d1", "--order", "8", "--prune",
                            "2", "--json"], extra)
      for option, extra in (("--cutoff", ["--cutoff", "120"]), ("--max-damping", ["--max-damping", "0.02"]),
                            ("--refine", ["--refine"]), ("--plot", ["--plot", "{w}/pz.png"]))],
    *[_case("extract-modes", option, ["extract-modes", "{w}/frf.uff", "--band", "20:400", "--max-order", "12",
                                      "--json"], extra)
      for option, extra in (("--n-modes", ["--n-modes", "1"]), ("--method", ["--method", "lscf"]),
                            ("--near", ["--near", "90"]), ("--driving-point", ["--driving-point", "F1=a1"]),
                            ("--sensor", ["--sensor", "a1=n1:x"]), ("--plot", ["--plot", "{w}/stab.png"]),
                            ("--out", ["-o", "{w}/modes.json"]), ("--bootstrap", ["--bootstrap", "0"]),
                            ("--position", ["--position", "z=0.1"]),
                            ("--reference-side", ["--reference-side", "outputs"]),
                            ("--sensor-map", ["--sensor-map", "{w}/frf_map.csv"]))],
    _case("extract-modes", "frf", ["extract-modes", "{w}/frf.uff", "--band", "20:400", "--max-order", "12"],
          variant=["extract-modes", "{w}/frf.uff", "--band", "20:400", "--max-order", "12", "--json"]),
    _case("extract-modes", "--json", ["extract-modes", "{w}/frf.uff", "--band", "20:400", "--max-order", "12"],
          ["--json"]),
    _case("extract-modes", "--band", ["extract-modes", "{w}/frf.uff", "--band", "20:400", "--max-order", "12"],
          variant=["extract-modes", "{w}/frf.uff", "--band", "20:300", "--max-order", "12"]),
    _case("extract-modes", "--max-order", ["extract-modes", "{w}/frf.uff", "--band", "20:400", "--max-order", "12"],
          variant=["extract-modes", "{w}/frf.uff", "--band", "20:400", "--max-order", "16"]),
    _case("extract-modes", "--uff", ["extract-modes", "{w}/frf.uff", "--band", "20:400", "--max-order", "12",
                                     "--sensor", "a1=n1:x", "--sensor", "a2=n2:x"], ["--uff", "{w}/m.uff"]),
    # -- estimate, study ------------------------------------------------------------------------------------------
    *[c for c in _model_cases("estimate", ["estimate", RIG, "--data", "{w}/rig_ref.json", "--method", "modal",
                                           "--json"]) if c.values[1] != "--position"],
    *[_case("estimate", option, ["estimate", RIG, "--data", "{w}/est.npz", "--method", "direct", "--setting",
                                 "instruments=model", "--json"], extra)
      for option, extra in (("--unknowns", ["--unknowns", "k11,k12"]), 
                            ("--start", ["--start", "{w}/rig_start.json"]), ("--setting", ["--setting", "instruments=delayed"]),
                            ("--plot", ["--plot", "{w}/corr.png"]),
                            ("--plot-response", ["--plot-response", "{w}/resp.png"]))],
    _case("estimate", "--bounds", ["estimate", RIG, "--data", "{w}/rig_ref2.json", "--method", "modal", "--json"],
          ["--bounds", "k12=1e5:1.5e5"]),  # the fit of k12 = 2e5 ends on the bound
    _case("estimate", "--plot-landscape", ["estimate", RIG, "--data", "{w}/rig_ref.json", "--method", "modal",
                                           "--json"], ["--plot-landscape", "k11,k12:{w}/land.png"]),
    _case("estimate", "--data", ["estimate", RIG, "--data", "{w}/rig_ref.json", "--method", "modal", "--json"],
          variant=["estimate", RIG, "--data", "{w}/rig_ref2.json", "--method", "modal", "--json"]),
    _case("estimate", "--method", ["estimate", RIG, "--data", "{w}/est.npz", "--method", "direct", "--intersample",
                                   "zoh", "--json"],
          variant=["estimate", RIG, "--data", "{w}/est.npz", "--method", "ekf", "--intersample", "zoh", "--json"]),
    # the EKF is deterministic: the seed reaches the two-step method's Sobol start points
    _case("estimate", "--seed", ["estimate", RIG, "--data", "{w}/est.npz", "--method", "two-step-tf",
                                 "--intersample", "zoh", "--json"], ["--seed", "3"]),
    # est.npz holds its force between samples: the default (band-limited) assumption biases step 1 and the
    # weighted second step's chi-square test fails (exit 1); --intersample zoh is what makes the fit go through
    _case("estimate", "--intersample", ["estimate", RIG, "--data", "{w}/est.npz", "--method", "two-step-tf",
                                        "--json"], ["--intersample", "zoh"], fails=True),
    _case("estimate", "--plot-residuals", ["estimate", RIG, "--data", "{w}/run.npz", "--method", "one-step",
                                           "--unknowns", "k11,k12", "--json"], ["--plot-residuals", "{w}/res.png"]),
    *_model_cases("study", ["study", RIG, "--method", "direct", "--noise", "0.01", "--seeds", "1", "--duration", "1",
                            "--json"],
                  position=["study", CAR, "--method", "two-step-tf", "--noise", "0.01", "--seeds", "1", "--duration",
                            "1", "--json"]),
    *[_case("study", option, ["study", RIG, "--method", "direct", "--noise", "0.01", "--seeds", "1", "--duration",
                              "1", "--json"], extra)
      for option, extra in (("--method", ["--method", "two-step-tf"]), ("--truth", ["--truth", "{w}/rig_truth.json"]),
                            ("--unknowns", ["--unknowns", "k11,k12"]), ("--noise", ["--noise", "0.05"]),
                            ("--seeds", ["--seeds", "2"]), ("--start", ["--start", "{w}/rig_start.json"]),
                            ("--setting", ["--setting", "instruments=none"]), ("--fs", ["--fs", "800"]),
                            ("--duration", ["--duration", "2"]))],
    # -- identify (the small slide model, tiny samples) ------------------------------------------------------------
    *[_case("identify", option, ["identify", str(SLIDE), "--reference", "{w}/slide_ref.json", "--n-gsa", "8",
                                 "--n-opt", "2", "--permutations", "1", "--workers", "1", "--json"], extra, slow=True)
      for option, extra in (
          ("--validation", ["--validation", "none"]), ("--truth", ["--truth", "{w}/slide_truth.json"]),
          ("--params", ["--params", "{w}/slide_truth.json", "--unknowns", "me_kx,lgs_kx"]),
          ("--set", ["--set", "me_dx=0.05"]), ("--unknowns", ["--unknowns", "me_kx,lgs_kx"]),
          ("--n-gsa", ["--n-gsa", "16"]), ("--n-opt", ["--n-opt", "3"]), ("--threshold", ["--threshold", "0.5"]),
          ("--noise-frequency", ["--noise-frequency", "0.01", "--noise-damping", "0.1", "--noise-shape", "0.05"]),
          ("--noise-damping", ["--noise-frequency", "0.01", "--noise-damping", "0.1", "--noise-shape", "0.05"]),
          ("--noise-shape", ["--noise-frequency", "0.01", "--noise-damping", "0.1", "--noise-shape", "0.05"]),
          ("--noise", ["--noise", "0.01,0.1,0.05"]), ("--first-order", ["--first-order"]),
          ("--permutations", ["--permutations", "2"]), ("--overlay", ["--overlay", "tool:x,bed1:y", "--report",
                                                                      "{w}/r.html"]),
          ("--seed", ["--seed", "5"]), ("--report", ["--report", "{w}/r.html"]), ("--out", ["-o", "{w}/r.json"]),
          ("--progress", ["--progress"]), ("--shapes", ["--shapes", "complex"]),
          ("--sensor-map", ["--sensor-map", "{w}/slide_map.csv"]),
          ("--known-tolerance", ["--known-tolerance", "mb=0.1"]))],
    _case("identify", "--json", ["identify", str(SLIDE), "--reference", "{w}/slide_ref.json", "--n-gsa", "8",
                                 "--n-opt", "2", "--permutations", "1", "--workers", "1"], ["--json"], slow=True),
    _case("identify", "--reference", ["identify", str(SLIDE), "--reference", "{w}/slide_ref.json", "--n-gsa", "8",
                                      "--n-opt", "2", "--permutations", "1", "--workers", "1", "--json"],
          variant=["identify", str(SLIDE), "--reference", "{w}/slide_ref2.json", "--n-gsa", "8", "--n-opt", "2",
                   "--permutations", "1", "--workers", "1", "--json"], slow=True),
    # -- monitor (each run on a fresh copy of the store: {w}/work.db) --------------------------------------------
    *[_case("monitor init", option, ["monitor", "init", "{w}/new.db", "--machine", "x", "--model",
                                     "builtin:spindle-bearing", "--json"], extra)
      for option, extra in (
          ("--out", ["-o", "{w}/init.json"]), ("--params", ["--params", "{w}/spindle.json"]),
          ("--set", ["--set", "preload=0.9"]), ("--inputs", ["--inputs", "Fy"]),
          ("--outputs", ["--outputs", "sx,sy"]), ("--band", ["--band", "150:900"]),
          ("--component", ["--component", "front=kfx,kfy"]),
          ("--fault-parameter", ["--fault-parameter", "preload"]),
          ("--detection", ["--detection", "ewma"]), ("--false-alarm-rate", ["--false-alarm-rate", "0.01"]),
          ("--shift", ["--shift", "3"]), ("--severity", ["--severity", "tolerable=0.02,intolerable=0.2"]),
          ("--slow-every", ["--slow-every", "5"]), ("--excitation", ["--excitation", "operational"]))],
    # the SSI-COV settings of an operational machine: what the stored config holds (their effect on the modes
    # found: tests/monitor/test_operational.py::test_ssi_settings_reach_the_modal_analysis)
    *[_case("monitor init", option, ["monitor", "init", "{w}/new.db", "--machine", "x", "--model",
                                     "builtin:spindle-bearing", "--excitation", "operational", "--json"], extra)
      for option, extra in (
          ("--ssi-orders", ["--ssi-orders", "4:24:4"]), ("--ssi-block-rows", ["--ssi-block-rows", "40"]),
          ("--ssi-stability", ["--ssi-stability", "mac_tol=0.9"]))],
    _case("monitor init", "store", ["monitor", "init", "{w}/new.db", "--machine", "x", "--model", CAR],
          variant=["monitor", "init", "{w}/new2.db", "--machine", "x", "--model", CAR]),
    _case("monitor init", "--json", ["monitor", "init", "{w}/new.db", "--machine", "x", "--model", CAR], ["--json"]),
    _case("monitor init", "--machine", ["monitor", "init", "{w}/new.db", "--machine", "x", "--model", CAR],
          variant=["monitor", "init", "{w}/new.db", "--machine", "y", "--model", CAR]),
    _case("monitor init", "--model", ["monitor", "init", "{w}/new.db", "--machine", "x", "--model", CAR, "--json"],
          variant=["monitor", "init", "{w}/new.db", "--machine", "x", "--model", RIG, "--json"]),
    _case("monitor init", "--position", ["monitor", "init", "{w}/new.db", "--machine", "x", "--model", CAR,
                                         "--json"], ["--position", "z=0.2"]),
    _case("monitor init", "--replace", ["monitor", "init", "{w}/work.db", "--machine", "m1", "--model", CAR,
                                        "--json"], ["--replace"], fails=True),
    *[_case("monitor simulate", option, ["monitor", "simulate", "bearing-loss", "--model", "builtin:spindle-bearing",
                                         "-n", "3", "-o", "{w}/sim", "--json"], extra)
      for option, extra in (
          ("--count", ["--count", "4"]), ("--fault-at", ["--fault-at", "1"]), ("--component", ["--component", "rear"]),
          ("--severity", ["--severity", "0.3"]), ("--noise", ["--noise", "0.05"]), ("--interval", ["--interval", "5"]),
          ("--start", ["--start", "2026-02-01T00:00:00+00:00"]), ("--format", ["--format", "csv"]),
          ("--seed", ["--seed", "9"]), ("--machine", ["--machine", "other"]))],
    _case("monitor simulate", "--operational", ["monitor", "simulate", "healthy", "--model", "builtin:spindle-bearing",
                                                "-n", "2", "-o", "{w}/sim", "--json"], ["--operational"]),
    _case("monitor simulate", "--seconds", ["monitor", "simulate", "healthy", "--model", "builtin:spindle-bearing",
                                            "-n", "2", "--operational", "-o", "{w}/sim", "--json"], ["--seconds", "2"]),
    _case("monitor simulate", "scenario", ["monitor", "simulate", "bearing-loss", "--model", "builtin:spindle-bearing",
                                           "-n", "3", "-o", "{w}/sim"],
          variant=["monitor", "simulate", "healthy", "--model", "builtin:spindle-bearing", "-n", "3", "-o", "{w}/sim"]),
    _case("monitor simulate", "--store", ["monitor", "simulate", "healthy", "--model", "builtin:spindle-bearing",
                                          "-n", "2", "-o", "{w}/sim"],
          variant=["monitor", "simulate", "healthy", "--store", "{w}/work.db", "--machine", "m2", "-n", "2", "-o",
                   "{w}/sim"]),
    _case("monitor simulate", "--model", ["monitor", "simulate", "healthy", "--model", "builtin:spindle-bearing",
                                          "-n", "2", "-o", "{w}/sim"],
          variant=["monitor", "simulate", "healthy", "--model", CAR, "-n", "2", "-o", "{w}/sim"]),
    _case("monitor simulate", "--out", ["monitor", "simulate", "healthy", "--model", "builtin:spindle-bearing",
                                        "-n", "2", "-o", "{w}/sim"],
          variant=["monitor", "simulate", "healthy", "--model", "builtin:spindle-bearing", "-n", "2", "-o",
                   "{w}/sim2"]),
    _case("monitor simulate", "--json", ["monitor", "simulate", "healthy", "--model", "builtin:spindle-bearing",
                                         "-n", "2", "-o", "{w}/sim"], ["--json"]),
    *[_case("monitor ingest", option, ["monitor", "ingest", "{w}/work.db", "--machine", "m1", "--manifest",
                                       "{w}/day3/scenario.json"], extra)
      for option, extra in (("--json", ["--json"]), ("--out", ["-o", "{w}/ingest.json"]),
                            ("--progress", ["--progress"]), ("--condition", ["--condition", "temperature=30"]))],
    _case("monitor ingest", "--sensor-map", ["monitor", "ingest", "{w}/work.db", "{w}/foreign/m.npz", "--machine",
                                             "m1", "--time", "2026-01-07T06:00:00+00:00", "--condition",
                                             "temperature=22", "--json"],
          ["--sensor-map", "{w}/spindle_map.csv"], fails=True),
    _case("monitor ingest", "--machine", ["monitor", "ingest", "{w}/work.db", "--machine", "m1", "--manifest",
                                          "{w}/day3/scenario.json", "--json"],
          variant=["monitor", "ingest", "{w}/work.db", "--machine", "m2", "--manifest", "{w}/day3/scenario.json",
                   "--json"]),
    _case("monitor ingest", "--manifest", ["monitor", "ingest", "{w}/work.db", "--machine", "m1", "--manifest",
                                           "{w}/day3/scenario.json", "--json"],
          variant=["monitor", "ingest", "{w}/work.db", "--machine", "m1", "--manifest", "{w}/day4/scenario.json",
                   "--json"]),
    _case("monitor ingest", "files", ["monitor", "ingest", "{w}/work.db", "{w}/day3/FIRST", "--machine", "m1",
                                      "--time", "2026-01-07T06:00:00+00:00", "--condition", "temperature=22",
                                      "--json"],
          variant=["monitor", "ingest", "{w}/work.db", "{w}/day3/LAST", "--machine", "m1", "--time",
                   "2026-01-07T06:00:00+00:00", "--condition", "temperature=22", "--json"]),
    _case("monitor ingest", "--time", ["monitor", "ingest", "{w}/work.db", "{w}/day3/FIRST", "--machine", "m1",
                                       "--time", "2026-01-07T06:00:00+00:00", "--condition", "temperature=22",
                                       "--json"],
          variant=["monitor", "ingest", "{w}/work.db", "{w}/day3/FIRST", "--machine", "m1", "--time",
                   "2026-01-07T07:00:00+00:00", "--condition", "temperature=22", "--json"]),
    *[_case("monitor watch", option, ["monitor", "watch", "{w}/work.db", "{w}/day3", "--machine", "m1", "--once",
                                      "--settle", "0"], extra)
      for option, extra in (("--interval", ["--interval", "5"]),)],
    _case("monitor watch", "--sensor-map", ["monitor", "watch", "{w}/work.db", "{w}/foreign", "--machine", "m1",
                                            "--once", "--settle", "0", "--condition", "temperature=22"],
          ["--sensor-map", "{w}/spindle_map.csv"], fails=True),
    _case("monitor watch", "directory", ["monitor", "watch", "{w}/work.db", "{w}/day3", "--machine", "m1", "--once",
                                   "--settle", "0"],
          variant=["monitor", "watch", "{w}/work.db", "{w}/day4", "--machine", "m1", "--once", "--settle", "0"]),
    _case("monitor watch", "--machine", ["monitor", "watch", "{w}/work.db", "{w}/day3", "--machine", "m1", "--once",
                                         "--settle", "0"],
          variant=["monitor", "watch", "{w}/work.db", "{w}/day3", "--machine", "m2", "--once", "--settle", "0"]),
    # a file is read once its size and time have stayed put for --settle s: a watch that looks once reads none
    _case("monitor watch", "--settle", ["monitor", "watch", "{w}/work.db", "{w}/day3", "--machine", "m1", "--once",
                                        "--settle", "0"],
          variant=["monitor", "watch", "{w}/work.db", "{w}/day3", "--machine", "m1", "--once", "--settle", "1"]),
    # a folder without a scenario.json: the file's conditions are the option's
    _case("monitor watch", "--condition", ["monitor", "watch", "{w}/work.db", "{w}/loose", "--machine", "m1",
                                           "--once", "--settle", "0"], ["--condition", "temperature=77"]),
    *[_case("monitor baseline", option, ["monitor", "baseline", "{w}/work.db", "--machine", "m1", "--json"], extra)
      for option, extra in (("--out", ["-o", "{w}/b.json"]), ("--first", ["--first", "10"]),
                            ("--since", ["--since", "2026-01-05T06:20:00+00:00"]),
                            ("--until", ["--until", "2026-01-05T08:40:00+00:00"]),
                            ("--resolution", ["--resolution", "0.05"]))],
    _case("monitor baseline", "--machine", ["monitor", "baseline", "{w}/work.db", "--machine", "m1", "--json"],
          variant=["monitor", "baseline", "{w}/work.db", "--machine", "m2", "--json"]),
    _case("monitor baseline", "--json", ["monitor", "baseline", "{w}/work.db", "--machine", "m1"], ["--json"]),
    _case("monitor status", "--machine", ["monitor", "status", "{w}/work.db", "--json"], ["--machine", "m2"]),
    _case("monitor status", "--json", ["monitor", "status", "{w}/work.db"], ["--json"]),
    _case("monitor status", "--out", ["monitor", "status", "{w}/work.db"], ["-o", "{w}/s.json"]),
    *[_case("monitor history", option, ["monitor", "history", "{w}/work.db", "--machine", "m1", "--json"], extra)
      for option, extra in (("--out", ["-o", "{w}/h.json"]), ("--path", ["--path", "slow"]),
                            ("--parameter", ["--parameter", "front"]), ("--last", ["--last", "2"]),
                            ("--csv", ["--csv", "{w}/h.csv"]))],
    _case("monitor history", "--machine", ["monitor", "history", "{w}/work.db", "--machine", "m1", "--json"],
          variant=["monitor", "history", "{w}/work.db", "--machine", "m2", "--json"]),
    _case("monitor history", "--json", ["monitor", "history", "{w}/work.db", "--machine", "m1"], ["--json"]),
    _case("monitor alarms", "--machine", ["monitor", "alarms", "{w}/work.db", "--machine", "m1", "--json"],
          variant=["monitor", "alarms", "{w}/work.db", "--machine", "m2", "--json"]),
    _case("monitor alarms", "--json", ["monitor", "alarms", "{w}/work.db", "--machine", "m1"], ["--json"]),
    _case("monitor alarms", "--out", ["monitor", "alarms", "{w}/work.db", "--machine", "m1"], ["-o", "{w}/a.json"]),
    _case("monitor alarms", "--ack", ["monitor", "alarms", "{w}/work.db", "--machine", "m1", "--json"],
          ["--ack", "1"]),
    _case("monitor alarms", "--all", ["monitor", "alarms", "{w}/work.db", "--machine", "m1", "--ack", "1", "--json"],
          ["--all"]),
    *[_case("monitor preload", option, ["monitor", "preload", CAR, "--preloads", "0.5,1", "--modes", "1,2", "--json"],
            extra)
      for option, extra in (
          ("--params", ["--params", "{w}/carriage_params.json"]), ("--set", ["--set", "m=4.0"]),
          ("--position", ["--position", "z=0.2"]), ("--out", ["-o", "{w}/p.json"]),
          ("--parameter", ["--parameter", "c"]), ("--preloads", ["--preloads", "0.5,2"]),
          ("--modes", ["--modes", "1,3"]), ("--input", ["--input", "G"]), ("--outputs", ["--outputs", "e"]),
          ("--bode-preloads", ["--bode-preloads", "0.9,1.1"]), ("--band", ["--band", "0:400"]),
          ("--plot-map", ["--plot-map", "{w}/map.png"]), ("--plot-bode", ["--plot-bode", "{w}/pb.png"]))],
    _case("monitor preload", "model", ["monitor", "preload", CAR, "--preloads", "0.5,1", "--modes", "1,2", "--json"],
          variant=["monitor", "preload", "builtin:spindle-bearing", "--preloads", "0.5,1", "--modes", "1,2",
                   "--json"]),
    _case("monitor preload", "--json", ["monitor", "preload", CAR, "--preloads", "0.5,1", "--modes", "1,2"],
          ["--json"]),
    *[_case("monitor bearing-test", option, ["monitor", "bearing-test", "{w}/static.csv", "--force", "F",
                                             "--displacements", "d1,d2", "--z-force", "0.25", "--z-bearings",
                                             "0.1,-0.1", "--z-sensors", "0.15,0.2", "--json"], extra)
      for option, extra in (("--out", ["-o", "{w}/bt.json"]), ("--min-force", ["--min-force", "0.6"]),
                            ("--force", ["--force", "F2"]), ("--displacements", ["--displacements", "d2,d1"]),
                            ("--z-force", ["--z-force", "0.3"]), ("--z-bearings", ["--z-bearings", "0.1,-0.2"]),
                            ("--z-sensors", ["--z-sensors", "0.15,0.22"]))],
    _case("monitor bearing-test", "data", ["monitor", "bearing-test", "{w}/static.csv", "--force", "F",
                                           "--displacements", "d1,d2", "--z-force", "0.25", "--z-bearings",
                                           "0.1,-0.1", "--z-sensors", "0.15,0.2", "--json"],
          variant=["monitor", "bearing-test", "{w}/static2.csv", "--force", "F", "--displacements", "d1,d2",
                   "--z-force", "0.25", "--z-bearings", "0.1,-0.1", "--z-sensors", "0.15,0.2", "--json"]),
    _case("monitor bearing-test", "--json", ["monitor", "bearing-test", "{w}/static.csv", "--force", "F",
                                             "--displacements", "d1,d2", "--z-force", "0.25", "--z-bearings",
                                             "0.1,-0.1", "--z-sensors", "0.15,0.2"], ["--json"]),
    # -- plan-test (the carriage: one axis, two sensors) ----------------------------------------------------------
    *[c for c in _model_cases("plan-test", ["plan-test", CAR, "--n-positions", "1", "--n-sensors", "2", "--modes",
                                            "4", "--random", "2", "--json"]) if c.values[1] != "--position"],
    *[_case("plan-test", option, ["plan-test", CAR, "--n-positions", "1", "--n-sensors", "2", "--modes", "4",
                                  "--random", "2", "--json"], extra)
      for option, extra in (
          ("--candidate-positions", ["--candidate-positions", "z=0.0,0.2"]), ("--grid", ["--grid", "5"]),
          ("--candidate-sensors", ["--candidate-sensors", "s1"]), ("--unknowns", ["--unknowns", "k"]),
          ("--noise-frequency", ["--noise-frequency", "0.01"]), ("--noise-damping", ["--noise-damping", "0.1"]),
          ("--noise-shape", ["--noise-shape", "0.05"]), ("--max-std", ["--max-std", "0.01"]),
          ("--visibility", ["--visibility", "0.5"]), ("--random", ["--random", "3"]), ("--seed", ["--seed", "2"]),
          # given twice, the last counts
          ("--n-positions", ["--n-positions", "2"]), ("--n-sensors", ["--n-sensors", "3"]),
          ("--modes", ["--modes", "3"]))],
    # -- demo (the identification and monitoring stages take tens of seconds) --------------------------------------
    _case("demo", "--json", ["demo", "--no-identify", "--no-monitor"], ["--json"]),
    _case("demo", "--out", ["demo", "--no-identify", "--no-monitor"], ["-o", "{w}/demo.json"]),
]

#: Options the difference test does not drive, each with the reason and where its effect is tested.
EXEMPT = {
    # its difference test would run the demo's monitoring stage (about a minute) once more for nothing: the two
    # runs exist already, with and without it
    ("demo", "--no-monitor"): "tests/cli/test_model_cli.py: test_demo_monitoring_finds_each_fault (without it: the "
                              "alarms of every scenario) and test_demo_prints_modes_and_tfs (with it: no monitoring)",
    # each would run the demo's identification stage (about a minute) twice; what the options do there is the
    # identify command's (the identify cases of this audit drive them on the small slide in seconds)
    **{("demo", option): "tests/cli/test_model_cli.py::test_demo_identification_options_reach_the_identification "
                         "(the demo hands the option to the identification stage; --no-identify skips it)"
       for option in ("--no-identify", "--n-gsa", "--n-opt", "--seed", "--report")},
    ("model show", "--position"): "refused: show describes every position (test_cli_conventions)",
    ("model zpk", "--symbolic"): "refused: zpk needs numbers (a usage error with the way out, --exact)",
    ("estimate", "--position"): "tests/cli/test_estimate_cli.py::test_position_reaches_the_estimator (c792c4b)",
    ("identify", "model"): "the model being identified: every identify case drives it (tests/cli/test_identify_cli)",
    ("identify", "--workers"): "same result by design on any worker count (tests/test_parallel.py checks that)",
    ("identify", "--executor"): "same result by design on every executor (tests/test_parallel.py checks that)",
    ("identify", "--frf"): "needs measured FRFs of a model with its own generator: tests/estimate/"
                           "test_frf_refinement.py::test_frf_refinement_brings_damping_within_target (damping 25 % -> "
                           "5 % with the option)",
    ("identify", "--frf-position"): "places the --frf files: tests/estimate/test_frf_refinement.py::"
                                    "test_bad_frf_input_names_the_file (a position no reference has is refused, so "
                                    "the option is read)",
    ("identify", "--scheduler"): "needs a running Dask cluster (tests/test_parallel.py with the distributed extra)",
    ("monitor history", "store"): "the store is the data every monitor case reads",
    ("monitor ingest", "store"): "the store is the data every monitor case reads",
    ("monitor baseline", "store"): "the store is the data every monitor case reads",
    ("monitor status", "store"): "the store is the data every monitor case reads",
    ("monitor alarms", "store"): "the store is the data every monitor case reads",
    ("monitor watch", "store"): "the store is the data every monitor case reads",
    ("monitor watch", "--once"): "without it the watch runs until it is stopped: tests/cli/test_monitor_cli.py::"
                                 "test_watch_survives_a_kill_and_a_restart_mid_folder kills such a watch",
    ("plan-test", "--position"): "fixes only axes the plan does not choose, and is refused on an axis it chooses: "
                                 "tests/cli/test_plan_test_cli.py::test_plan_test_bad_input (the carriage has one "
                                 "axis, which the plan chooses)",
    ("monitor serve", "store"): "serve blocks; tests/cli/test_monitor_cli.py::test_serve_answers serves a store",
    ("monitor serve", "--port"): "test_serve_answers asks for port 0 and reads the port it got",
    ("monitor serve", "--allowed-host"): "test_serve_answers checks the hosts it answers and the one it refuses",
    ("monitor serve", "--host"): "binding another interface needs one; the address is printed (test_cli_conventions)",
    ("monitor serve", "--json"): "tests/cli/test_cli_conventions.py::test_serve_json_prints_its_address",
    ("monitor serve", "--out"): "tests/cli/test_cli_conventions.py::test_serve_json_prints_its_address",
}


@pytest.fixture(scope="module")
def scratch(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An empty folder for the cases that read none of :func:`world`'s files (the demo: it writes its outputs
    there), so that a worker running only those does not build the world (~15 s)."""
    return tmp_path_factory.mktemp("audit-scratch")


def _expand(argv: list[str], folder: Path) -> list[str]:
    argv = [a.replace("{w}", str(folder)) for a in argv]
    if any("FIRST" in a or "LAST" in a for a in argv):
        day3 = sorted(p.name for p in (folder / "day3").iterdir() if p.name != "scenario.json")
        argv = [a.replace("FIRST", day3[0]).replace("LAST", day3[-1]) for a in argv]
    return argv


@pytest.mark.slow  # about 500 command runs (shared bases run once within a worker): ~200 s of worker time
@pytest.mark.parametrize(("command", "option", "base", "variant", "fails"), CASES)
def test_option_changes_the_effect(request: pytest.FixtureRequest, capsys: pytest.CaptureFixture[str],
                                   monkeypatch: pytest.MonkeyPatch, command: str, option: str, base: list[str],
                                   variant: list[str], fails: bool) -> None:
    # the demo reads no data file: its cases run in an empty folder (the world is built only where needed)
    folder: Path = request.getfixturevalue("scratch" if command == "demo" else "world")
    monkeypatch.chdir(folder)
    first = _observe(folder, capsys, _expand(base, folder))
    assert (first[0] != 0) == fails, f"base run of {command}: exit {first[0]} ({' '.join(base)}): {first[1:3]}"
    second = _observe(folder, capsys, _expand(variant, folder))
    assert second[0] == 0, f"{command} with {option} failed: {' '.join(variant)}: {second[1:3]}"
    assert second != first, f"{command}: {option} was parsed and changed nothing ({' '.join(variant)})"


def _options(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()) -> Iterator[tuple[str, str]]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _options(sub, (*path, name))
            return
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction) or not path:
            continue
        yield " ".join(path), (action.option_strings[-1] if action.option_strings else action.dest)


def test_every_option_is_audited() -> None:
    audited = {(p.values[0], p.values[1]) for p in CASES}
    missing = sorted(set(_options(build_parser())) - audited - set(EXEMPT))
    assert not missing, f"options without an audit case or a reason in EXEMPT: {missing}"
