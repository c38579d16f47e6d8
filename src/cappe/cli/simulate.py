"""``cappe simulate MODEL --excite INPUT=SIGNAL``: a simulated measurement (inputs and responses with noise)."""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from cappe.cli._common import ModelContext, UsageError, add_model_options, band, emit, names

SIGNALS = ("random", "periodic-random", "chirp", "prbs", "impact", "sine:FREQ", "square:FREQ")


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "simulate",
        help="simulated measurement: excite model inputs with test signals, record outputs with seeded noise",
    )
    add_model_options(p)
    p.add_argument("--excite", metavar="INPUT=SIGNAL", action="append", default=[], required=True,
                   help=f"excite a model input; SIGNAL is one of {', '.join(SIGNALS)} (repeatable)")
    p.add_argument("--fs", type=float, default=2048.0, help="sampling rate in Hz (default 2048)")
    p.add_argument("--duration", type=float, default=8.0, help="record length in s (default 8)")
    p.add_argument("--band", metavar="LO:HI", help="excitation band in Hz for random and chirp (default 0:fs/2.56)")
    p.add_argument("--amplitude", type=float, default=10.0,
                   help="force level in N: RMS for random signals, peak otherwise (default 10)")
    p.add_argument("--outputs", metavar="LIST", help="comma-separated model outputs to record (default all)")
    p.add_argument("--noise", type=float, default=0.0, help="output noise, fraction of channel RMS (0.01 = 1 %%)")
    p.add_argument("--input-noise", type=float, default=0.0, help="noise on the recorded inputs, fraction of RMS")
    p.add_argument("--seed", type=int, default=0, help="seed for the signals and the noise (default 0)")
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
    from cappe.io import TimeData, write_time_data
    from cappe.systems import time_response

    ctx = ModelContext(args)
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
                         input_noise=args.input_noise, rng=streams[-1])
    summary = {
        "model": ctx.structure.name,
        "fs": data.fs,
        "n_samples": data.n_samples,
        "channels": list(data.channels),
        "units": list(data.units),
        "rms": {c: float(np.sqrt(np.mean(v**2))) for c, v in zip(data.channels, data.values, strict=True)},
        "excitation": dict(item.partition("=")[::2] for item in args.excite),
        "noise": args.noise,
        "seed": args.seed,
    }
    lines = [f"{ctx.structure.name}: {data.n_samples} samples at {data.fs:g} Hz ({data.duration:g} s)"]
    lines += [f"  {c:>10s}  rms {summary['rms'][c]:.4g} {u}" for c, u in zip(data.channels, data.units, strict=True)]
    if args.out:
        write_time_data(args.out, data)
        summary["out"] = args.out
        lines.append(f"wrote {args.out}")
    emit(argparse.Namespace(**{**vars(args), "out": None}), summary, "\n".join(lines))
    return 0
