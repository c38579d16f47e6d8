"""``cappe simulate``: simulated measurements from a model.

* ``cappe simulate MODEL --excite INPUT=SIGNAL ...``: time data (inputs and responses with seeded noise).
* ``cappe simulate MODEL [--params truth.json] [--positions all|AXIS=V,...] [--modes N] [--noise-frequency ...]
  [--noise-damping ...] [--noise-shape ...] [--sensors LIST] [--seed N] -o ref.json [--uff modes.uff] [--frf frf.uff
  --driving-points IN,... --band LO:HI --lines N --noise-frf REL]``: reference modal data (cappe.modal/1) at the
  model's sensor nodes, the exact modes of the true parameters (nominal values for parameters the file leaves
  out) tracked across axis positions, with seeded noise; optionally as UFF 55 with the sensor nodes' global
  coordinates at the first position (UFF 2411), and FRFs from driving points to every sensor channel (exact, or
  with seeded relative complex noise: a rehearsal of a modal test).

``--modes`` larger than the number of oscillatory modes of the model is an error (exit 1).
"""

from __future__ import annotations

import argparse
import itertools
import math
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from cappe.cli._common import JSON_OUT, TIME_OUT, ModelContext, UsageError, add_model_options, band, emit, names

SIGNALS = ("random", "periodic-random", "chirp", "prbs", "impact", "sine:FREQ", "square:FREQ")
#: Time-simulation options and their defaults (None on the command line means "not given").
TIME_DEFAULTS = {"fs": 2048.0, "duration": 8.0, "amplitude": 10.0, "outputs": None, "noise": 0.0, "input_noise": 0.0,
                 "intersample": "bl"}
#: Reference-data options, by their command-line spelling.
MODAL_OPTIONS = {
    "positions": "--positions", "modes": "--modes", "noise_frequency": "--noise-frequency",
    "noise_damping": "--noise-damping", "noise_shape": "--noise-shape", "uff": "--uff", "frf": "--frf",
    "driving_points": "--driving-points", "frf_outputs": "--frf-outputs", "lines": "--lines",
    "noise_frf": "--noise-frf", "sensors": "--sensors",
}
#: Default number of FRF lines and the default top of the FRF band relative to the highest reference mode.
DEFAULT_LINES, BAND_MARGIN = 801, 1.25


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "simulate",
        help="simulated data: time records (--excite) or reference modes and FRFs at the sensor nodes",
        description=(
            "With --excite: excite model inputs with test signals and record outputs with seeded noise (time data). "
            "Without --excite: reference modal data (cappe.modal/1) of the model at its parameter values "
            "(--params truth.json; parameters it leaves out keep their nominal values) at its sensor nodes, "
            "exact complex modes tracked across axis positions, with seeded noise; optionally UFF 55 (--uff) and "
            "exact FRFs as UFF 58 (--frf)."
        ),
    )
    add_model_options(p, {**JSON_OUT, **TIME_OUT})
    time = p.add_argument_group("time data (with --excite)")
    time.add_argument("--excite", metavar="INPUT=SIGNAL", action="append", default=[],
                      help=f"excite a model input; SIGNAL is one of {', '.join(SIGNALS)} (repeatable)")
    time.add_argument("--fs", type=float, help="sampling rate in Hz (default 2048)")
    time.add_argument("--duration", type=float, help="record length in s (default 8)")
    time.add_argument("--amplitude", type=float,
                      help="force level in N: RMS for random signals, peak otherwise (default 10)")
    time.add_argument("--outputs", metavar="LIST", help="comma-separated model outputs to record (default all)")
    time.add_argument("--noise", type=float, help="output noise, fraction of channel RMS (0.01 = 1 %%)")
    time.add_argument("--input-noise", type=float, help="noise on the recorded inputs, fraction of RMS")
    time.add_argument("--intersample", choices=["zoh", "foh", "bl"],
                      help="the force between samples: bl (default) band-limited, as a DAQ with an anti-alias filter "
                           "records it; foh linear; zoh held (a DAC or PRBS without reconstruction filter)")
    p.add_argument("--band", metavar="LO:HI",
                   help="Hz; time data: excitation band of random and chirp signals (default 0:fs/2.56); "
                        "reference data: FRF band (default 0 to 1.25 x the highest mode)")
    p.add_argument("--seed", type=int, default=0, help="seed for the signals and the noise (default 0)")
    p.add_argument("--disturb", type=float, metavar="FRACTION",
                   help="disturbed model (paper 3.3): every disturbable parameter not given by --params or --set "
                        "times 1 +- FRACTION, random signs from --seed (e.g. 0.1)")
    modal = p.add_argument_group("reference modal data (without --excite)")
    modal.add_argument("--positions", metavar="all|AXIS=V[,V...]", action="append", default=[],
                       help="axis positions: 'all' (every listed position of the model's axes) or values of one "
                            "axis (repeatable; several axes combine; default the model's default position or "
                            "--position)")
    modal.add_argument("--modes", type=int, metavar="N",
                       help="number of modes: the lowest N at the first position, tracked (default all)")
    modal.add_argument("--sensors", metavar="LIST",
                       help="sensor channels NODE:DIR or nodes of the modes, comma-separated (default every channel "
                            "of the model's sensor nodes; e.g. the sensors of a cappe plan-test plan)")
    modal.add_argument("--noise-frequency", type=float, metavar="REL",
                       help="frequency noise: f * (1 + REL * N(0,1)), e.g. 0.005 (default 0)")
    modal.add_argument("--noise-damping", type=float, metavar="REL",
                       help="damping noise: zeta * (1 + REL * N(0,1)), e.g. 0.05 (default 0)")
    modal.add_argument("--noise-shape", type=float, metavar="REL",
                       help="shape noise: complex Gaussian with RMS modulus REL x the mode's largest component, "
                            "e.g. 0.02 (default 0)")
    modal.add_argument("--uff", metavar="FILE.uff",
                       help="also write the modes as UFF 55 with the sensor nodes (UFF 2411, first position)")
    modal.add_argument("--frf", metavar="FILE",
                       help="also write exact FRFs (UFF 58, CSV or npz by extension); several positions give "
                            "one file each, named FILE_AXIS=VALUE")
    modal.add_argument("--driving-points", metavar="LIST",
                       help="FRF inputs: model inputs or sensor channels NODE:DIR (default all model inputs)")
    modal.add_argument("--frf-outputs", metavar="LIST",
                       help="FRF responses: model outputs, sensor channels or nodes (default every sensor channel)")
    modal.add_argument("--lines", type=int, metavar="N",
                       help=f"FRF frequency lines in --band (default {DEFAULT_LINES})")
    modal.add_argument("--noise-frf", type=float, metavar="REL",
                       help="FRF noise: H * (1 + REL * complex N(0,1)) on every line, independent per line and "
                            "channel, e.g. 0.02 (default 0: exact FRFs)")
    p.set_defaults(func=run)


def _signal(
    kind: str, input_name: str, args: argparse.Namespace, lo_hi: tuple[float, float], seed: np.random.Generator
) -> Any:
    from cappe.identify import chirp, impact, prbs, random_noise, sine, square

    fs, duration, amplitude = args.fs, args.duration, args.amplitude
    common = {"fs": fs, "name": input_name}
    head, _, arg = kind.partition(":")
    if head in ("sine", "square"):
        try:
            freq = float(arg)
        except ValueError as exc:
            msg = f"--excite {input_name}={kind}: {head} needs a frequency in Hz, e.g. {head}:120"
            raise UsageError(msg) from exc
        func = sine if head == "sine" else square
        return func(freq=freq, amplitude=amplitude, duration=duration, **common)
    if arg:
        msg = f"--excite {input_name}={kind}: {head!r} takes no argument"
        raise UsageError(msg)
    if head == "random":
        return random_noise(duration=duration, rms=amplitude, band=lo_hi, rng=seed, **common)
    if head == "periodic-random":
        return random_noise(duration=duration, rms=amplitude, band=lo_hi, periodic=True, n_periods=8, rng=seed,
                            **common)
    if head == "chirp":
        return chirp(f0=max(lo_hi[0], 1e-3), f1=lo_hi[1], duration=duration, amplitude=amplitude, **common)
    if head == "prbs":
        n = int(round(duration * fs))
        return prbs(n_samples=n, amplitude=amplitude, rng=seed, **common)
    if head == "impact":
        # a hammer tip whose force spectrum is flat to the top of the band: contact time ~ 1 / (2 f_hi)
        return impact(duration=duration, amplitude=amplitude, contact_time=max(0.5 / lo_hi[1], 2.0 / fs),
                      at=0.01 * duration, **common)
    msg = f"--excite {input_name}={kind}: unknown signal {head!r}; choose from {', '.join(SIGNALS)}"
    raise UsageError(msg)


def run(args: argparse.Namespace) -> int:
    suffix = Path(args.out).suffix.lower() if args.out else None
    if suffix is not None and bool(args.excite) != (suffix in TIME_OUT):
        msg = (f"-o {args.out}: with --excite, -o writes time data (.uff/.unv, .csv or .npz)" if args.excite else
               f"-o {args.out}: without --excite, -o writes reference modal data (cappe.modal/1 JSON, .json)")
        raise UsageError(msg)
    if args.excite:
        given = [flag for dest, flag in MODAL_OPTIONS.items() if getattr(args, dest) not in (None, [])]
        if given:
            verb = "belongs" if len(given) == 1 else "belong"
            msg = f"{', '.join(given)} {verb} to reference modal data (without --excite), not to time simulation"
            raise UsageError(msg)
        for dest, default in TIME_DEFAULTS.items():
            if getattr(args, dest) is None:
                setattr(args, dest, default)
        return _run_time(args)
    given = [f"--{dest.replace('_', '-')}" for dest in TIME_DEFAULTS if getattr(args, dest) is not None]
    if given:
        verb = "belongs" if len(given) == 1 else "belong"
        msg = (
            f"{', '.join(given)} {verb} to time simulation (--excite INPUT=SIGNAL); reference modal data takes "
            "--noise-frequency, --noise-damping and --noise-shape"
        )
        raise UsageError(msg)
    return _run_modal(args)


def _run_time(args: argparse.Namespace) -> int:
    from cappe.io import write_time_data
    from cappe.systems import TimeData, time_response

    ctx = _context(args)
    system = ctx.system()
    lo_hi = band(args.band) if args.band else (0.0, args.fs / 2.56)
    # independent random streams for every signal and for the noise (one seed must not correlate them)
    streams = [np.random.default_rng(child) for child in np.random.SeedSequence(args.seed).spawn(len(args.excite) + 1)]
    channels: dict[str, Any] = {}
    for k, item in enumerate(args.excite):
        input_name, sep, kind = item.partition("=")
        if not sep or not input_name or not kind:
            msg = f"--excite must look like INPUT=SIGNAL; got {item!r}"
            raise UsageError(msg)
        if input_name not in system.input_names:
            known = list(system.input_names)
            msg = f"--excite: {input_name!r} is not an input of {ctx.structure.name}; its inputs: {known}"
            raise UsageError(msg)
        channels[input_name] = _signal(kind, input_name, args, lo_hi, streams[k]).channel(input_name)
    n = min(v.size for v in channels.values())
    excitation = TimeData.from_rate(args.fs, {name: v[:n] for name, v in channels.items()})
    data = time_response(system, excitation, outputs=names(args.outputs), noise=args.noise,
                         input_noise=args.input_noise, rng=streams[-1], intersample=args.intersample)
    summary = {
        "model": ctx.structure.name,
        "fs": data.fs,
        "n_samples": data.n_samples,
        "channels": list(data.channels),
        "units": list(data.units),
        "rms": {c: float(np.sqrt(np.mean(v**2))) for c, v in zip(data.channels, data.values, strict=True)},
        "excitation": dict(item.partition("=")[::2] for item in args.excite),
        "noise": args.noise,
        "intersample": args.intersample,
        "seed": args.seed,
    }
    lines = [f"{ctx.structure.name}: {data.n_samples} samples at {data.fs:g} Hz ({data.duration:g} s), "
             f"force between samples: {args.intersample}"]
    lines += [f"  {c:>10s}  rms {summary['rms'][c]:.4g} {u}" for c, u in zip(data.channels, data.units, strict=True)]
    if args.out:
        write_time_data(args.out, data)
        summary["out"] = args.out
        lines.append(f"wrote {args.out}")
    emit(argparse.Namespace(**{**vars(args), "out": None}), summary, "\n".join(lines))
    return 0


def _context(args: argparse.Namespace) -> ModelContext:
    """The model and its values, with --disturb applied to the disturbable parameters not set explicitly."""
    ctx = ModelContext(args)
    if args.disturb is not None:
        if not (np.isfinite(args.disturb) and 0 <= args.disturb < 1):
            msg = f"--disturb must be a fraction in [0, 1), e.g. 0.1; got {args.disturb}"
            raise UsageError(msg)
        # a stream of its own, so that adding --disturb leaves the noise of the same seed unchanged
        changed = ctx.structure.disturbed(args.disturb, np.random.default_rng([args.seed, 3]), ctx.values)
        if not changed:
            msg = f"--disturb: model '{ctx.structure.name}' tags no parameter as disturbable"
            raise UsageError(msg)
        changed = {n: v for n, v in changed.items() if n not in ctx.overrides}
        ctx.values.update(changed)
        ctx.overrides.update(changed)
    return ctx


def _parse_positions(items: list[str], ctx: ModelContext) -> list[dict[str, float]] | str:
    """``--positions`` values: ``"all"`` or one axis' values each; axes combine, unnamed axes keep ``ctx.position``."""
    if not items:
        return [dict(ctx.position)]
    structure = ctx.structure
    if "all" in items:
        if len(items) > 1:
            msg = f"--positions all cannot be combined with other --positions values; got {items}"
            raise UsageError(msg)
        return "all"
    listed = {a.name: a.positions for a in structure.axes}
    known = "; ".join(f"{a} (positions {', '.join(f'{v:g}' for v in pos) or 'none listed'})"
                      for a, pos in listed.items()) or "none (this model has no axes)"
    values: dict[str, list[float]] = {}
    for item in items:
        axis, sep, rest = item.partition("=")
        axis = axis.strip()
        if not sep or not axis or not rest.strip():
            msg = f"--positions must be 'all' or AXIS=VALUE[,VALUE...] (e.g. z=-0.294,0.135); got {item!r}"
            raise UsageError(msg)
        if axis not in listed:
            msg = f"--positions {item!r}: model '{structure.name}' has no axis {axis!r}; its axes: {known}"
            raise UsageError(msg)
        for text in rest.split(","):
            try:
                value = float(text)
            except ValueError:
                value = math.nan
            if not math.isfinite(value):
                msg = f"--positions {item!r}: {text.strip()!r} is not a finite number (m or rad); axis {known}"
                raise UsageError(msg)
            if value in values.get(axis, []):
                msg = f"--positions names {axis}={value:g} twice"
                raise UsageError(msg)
            values.setdefault(axis, []).append(value)
    axes = [a for a in structure.axis_names if a in values]
    return [{**ctx.position, **dict(zip(axes, combo, strict=True))}
            for combo in itertools.product(*(values[a] for a in axes))]


def _label(position: dict[str, float]) -> str:
    return " ".join(f"{a}={v:g}" for a, v in position.items()) or "(no axes)"


def _frf_path(path: str, position: dict[str, float], several: bool) -> Path:
    p = Path(path)
    if not several:
        return p
    tag = "_".join(f"{a}={v:g}" for a, v in position.items())
    return p.with_name(f"{p.stem}_{tag}{p.suffix}")


def _run_modal(args: argparse.Namespace) -> int:
    from cappe.io import write_frf, write_modal_data, write_uff_modal
    from cappe.modal import reference_frf, reference_modes, sensor_coordinates

    if args.frf is None:
        stray = [flag for dest, flag in (("driving_points", "--driving-points"), ("frf_outputs", "--frf-outputs"),
                                         ("lines", "--lines"), ("band", "--band"), ("noise_frf", "--noise-frf"))
                 if getattr(args, dest) is not None]
        if stray:
            verb = "sets" if len(stray) == 1 else "set"
            msg = f"{', '.join(stray)} {verb} up the simulated FRFs; give --frf FILE as well"
            raise UsageError(msg)
    if args.lines is not None and args.lines < 2:
        msg = f"--lines must be an integer >= 2; got {args.lines}"
        raise UsageError(msg)
    if args.noise_frf is not None and not (np.isfinite(args.noise_frf) and 0.0 <= args.noise_frf <= 1.0):
        msg = f"--noise-frf must be a relative level in [0, 1] (0.02 = 2 %); got {args.noise_frf:g}"
        raise UsageError(msg)
    ctx = _context(args)
    model = ctx.numeric
    positions = _parse_positions(args.positions, ctx)
    levels = {key: getattr(args, f"noise_{key}") or 0.0 for key in ("frequency", "damping", "shape")}
    ref = reference_modes(model, params=ctx.values, positions=positions, n_modes=args.modes,
                          sensors=names(args.sensors), noise_frequency=levels["frequency"],
                          noise_damping=levels["damping"], noise_shape=levels["shape"], rng=args.seed)
    sets = [dict(s.position) for s in ref.sets]

    frfs = []
    if args.frf is not None:
        top = BAND_MARGIN * max(float(np.max(s.frequency)) for s in ref.sets)
        lo, hi = band(args.band) if args.band else (0.0, float(f"{top:.3g}"))
        freq = np.linspace(lo, hi, args.lines or DEFAULT_LINES)
        # a stream of its own: adding --noise-frf leaves the modal noise and --disturb of the same seed unchanged
        frf_rng = np.random.default_rng([args.seed, 5])
        for position in sets:
            frf = reference_frf(model, freq=freq, params=ctx.values, position=position,
                                inputs=names(args.driving_points), outputs=names(args.frf_outputs))
            if args.noise_frf:
                relative = frf_rng.standard_normal(frf.H.shape) + 1j * frf_rng.standard_normal(frf.H.shape)
                frf = replace(frf, H=frf.H * (1.0 + args.noise_frf * relative / np.sqrt(2.0)))
            frfs.append((_frf_path(args.frf, position, len(sets) > 1), position, frf))

    files: dict[str, Any] = {}
    lines = [
        f"{ctx.structure.name}: {ref.sets[0].n_modes} modes at {len(ref.sets)} position(s), "
        f"{len(ref.sensors)} sensor channels ({len(dict.fromkeys(s.split(':')[0] for s in ref.sensors))} nodes)"
    ]
    lines += [f"  {_label(s.position):>14s}  {s.frequency.min():.4g} - {s.frequency.max():.4g} Hz" for s in ref.sets]
    lines.append(
        f"noise: frequency {levels['frequency']:g}, damping {levels['damping']:g}, shape {levels['shape']:g} "
        f"(relative std; seed {args.seed})"
    )
    if args.disturb:
        n = sum(p.disturbable for p in ctx.structure.parameters)
        lines.append(f"disturbed: the {n} disturbable parameters by +-{args.disturb:g} (their values: --json)")
    if args.out:
        write_modal_data(args.out, ref)
        files["modal"] = args.out
        lines.append(f"wrote {args.out} (cappe.modal/1)")
    if args.uff:
        nodes = sensor_coordinates(model, params=ctx.values, position=sets[0])
        coordinates: dict[str | int, Sequence[float]] = {name: xyz for name, xyz in nodes.items()}
        write_uff_modal(args.uff, ref, coordinates=coordinates)
        files["uff"] = args.uff
        lines.append(f"wrote {args.uff} (UFF 55 modes, UFF 2411 sensor nodes at {_label(sets[0])})")
    if frfs:
        files["frf"] = []
        for path, position, frf in frfs:
            write_frf(path, frf)
            files["frf"].append({"path": str(path), "position": position, "noise": args.noise_frf or 0.0})
            lines.append(
                f"wrote {path} ({len(frf.output_names)} responses x {len(frf.input_names)} driving points "
                f"({', '.join(frf.input_names)}), {frf.freq.size} lines {frf.freq[0]:g}-{frf.freq[-1]:g} Hz, "
                f"{_label(position)}, " + (f"relative complex noise {args.noise_frf:g})" if args.noise_frf
                                           else "exact)")
            )
    summary = {
        "model": ctx.structure.name,
        "parameters": dict(ctx.overrides),
        "n_sets": len(ref.sets),
        "n_modes": ref.sets[0].n_modes,
        "n_sensors": len(ref.sensors),
        "sensors": list(ref.sensors),
        "sets": [
            {"position": s.position, "frequency_range": [float(s.frequency.min()), float(s.frequency.max())]}
            for s in ref.sets
        ],
        "noise": levels,
        "seed": args.seed,
        "files": files,
    }
    emit(argparse.Namespace(**{**vars(args), "out": None}), summary, "\n".join(lines))
    return 0
