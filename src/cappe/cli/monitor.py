"""``cappe monitor``: the monitoring chain over a history store (init, simulate, ingest, baseline, status, history,
alarms, serve) and the bearing-preload studies (preload, bearing-test)."""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from cappe.cli._common import ModelContext, UsageError, add_model_options, add_output_options, band, emit, names
from cappe.cli._monitor_chain import register as _register_chain


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    parser = sub.add_parser("monitor", help="condition monitoring: history store, detection, diagnosis, dashboard; "
                                           "preload studies")
    cmds = parser.add_subparsers(dest="monitor_command", metavar="COMMAND", required=True)
    _register_chain(cmds)
    p = cmds.add_parser(
        "preload",
        help="frequency-damping map over preload, FRFs at 75/100/125 %%, which sensor sees which mode",
        description=(
            "Thesis Figs 5.30-5.32 for any model with a preload parameter: exact modes over the preloads (each "
            "mode followed by its shape), their log-sensitivity to the preload, the FRFs of one input at three "
            "preloads, and each output's level at each mode (dB below its strongest)."
        ),
    )
    add_model_options(p)
    p.add_argument("--parameter", default="preload", help="the preload parameter (default preload)")
    p.add_argument("--preloads", metavar="LIST",
                   help="comma-separated preloads (default the thesis's 0.05 ... 1.5 of nominal)")
    p.add_argument("--modes", metavar="LIST", default="1,2,3,4,5", help="modes to follow (default 1,2,3,4,5)")
    p.add_argument("--input", help="input of the FRFs (default the model's first)")
    p.add_argument("--outputs", metavar="LIST", help="outputs of the FRFs (default all)")
    p.add_argument("--bode-preloads", metavar="LIST", default="0.75,1,1.25",
                   help="preloads of the FRFs (default 0.75,1,1.25)")
    p.add_argument("--band", metavar="LO:HI", help="FRF band in Hz (default 0 to 1.5 x the highest mode followed)")
    p.add_argument("--plot-map", metavar="FILE.png", help="write the frequency-damping map")
    p.add_argument("--plot-bode", metavar="FILE.png", help="write the FRFs at the --bode-preloads")
    p.set_defaults(func=preload)

    q = cmds.add_parser(
        "bearing-test",
        help="front and rear bearing stiffness from a quasi-static force/displacement test",
        description=(
            "Thesis 5.4.4 / App. C4: a slow force on the shaft and two displacement probes (shaft relative to "
            "housing) away from the bearings; rigid-shaft kinematics and the lever rule give each bearing's "
            "stiffness sample by sample (coefficients from the geometry), with mean, std and 95 % interval."
        ),
    )
    q.add_argument("data", metavar="DATA", help="time data (UFF 58, CSV or npz)")
    q.add_argument("--force", required=True, help="force channel (N)")
    q.add_argument("--displacements", required=True, metavar="D1,D2", help="the two probe channels (m)")
    q.add_argument("--z-force", type=float, required=True, help="axial position of the force (m)")
    q.add_argument("--z-bearings", required=True, metavar="FRONT,REAR", help="axial positions of the bearings (m)")
    q.add_argument("--z-sensors", required=True, metavar="Z1,Z2", help="axial positions of the probes (m)")
    q.add_argument("--min-force", type=float, default=0.3,
                   help="leave out samples below this fraction of the largest force (default 0.3)")
    add_output_options(q)
    q.set_defaults(func=bearing_test)


def _pair(text: str, option: str) -> tuple[float, float]:
    values = _numbers(text, option) or []
    if len(values) != 2:
        msg = f"{option} must be two comma-separated numbers; got {text!r}"
        raise UsageError(msg)
    return values[0], values[1]


def bearing_test(args: argparse.Namespace) -> int:
    from cappe.io import read_time_data
    from cappe.monitor import static_bearing_stiffness

    data = read_time_data(args.data)
    probes = names(args.displacements) or []
    if len(probes) != 2:
        msg = f"--displacements must name two channels; got {args.displacements!r}"
        raise UsageError(msg)
    z_front, z_rear = _pair(args.z_bearings, "--z-bearings")
    z1, z2 = _pair(args.z_sensors, "--z-sensors")
    result = static_bearing_stiffness(data.channel(args.force), data.channel(probes[0]), data.channel(probes[1]),
                                      z_force=args.z_force, z_front=z_front, z_rear=z_rear, z_sensors=(z1, z2),
                                      min_force=args.min_force)
    summary = result.summary()
    lines = [f"{args.data}: {int(result.used.sum())} of {result.used.size} samples used "
             f"(|{args.force}| >= {args.min_force:g} x its largest)"]
    for name in ("front", "rear"):
        c, a1, a2 = result.coefficients[name]
        s = summary[name]
        lines.append(f"  {name:5s} k = {c:.4g} F / ({a1:+.4g} {probes[0]} {a2:+.4g} {probes[1]}): mean {s['mean']:.4g} "
                     f"N/m, std {100 * s['std'] / s['mean']:.2g} %, 95 % interval [{s['ci95_low']:.4g}, "
                     f"{s['ci95_high']:.4g}]")
    emit(args, {"data": args.data, **result.to_dict()}, "\n".join(lines))
    return 0


def _numbers(text: str | None, option: str) -> list[float] | None:
    if text is None:
        return None
    try:
        return [float(v) for v in names(text) or []]
    except ValueError as exc:
        msg = f"{option} must be comma-separated numbers; got {text!r}"
        raise UsageError(msg) from exc


def preload(args: argparse.Namespace) -> int:
    from cappe.monitor import THESIS_PRELOADS, preload_frfs, preload_map, sensor_visibility
    from cappe.report import bode_plot, preload_map_plot
    from cappe.systems.frf import FRFData

    ctx = ModelContext(args)
    preloads = _numbers(args.preloads, "--preloads") or list(THESIS_PRELOADS)
    modes_text = _numbers(args.modes, "--modes") or []
    if any(m != int(m) for m in modes_text):
        msg = f"--modes must be whole mode numbers; got {args.modes!r}"
        raise UsageError(msg)
    bode_at = _numbers(args.bode_preloads, "--bode-preloads") or [1.0]
    given = {n: v for n, v in ctx.overrides.items() if n != args.parameter}
    result = preload_map(ctx.numeric, preloads, [int(m) for m in modes_text], parameter=args.parameter,
                         params=given, position=ctx.position)
    sens = result.sensitivity() if len(preloads) >= 3 else np.full(len(result.modes), np.nan)
    inputs = [args.input] if args.input else list(ctx.numeric.input_names[:1])
    outputs = names(args.outputs) or list(ctx.numeric.output_names)
    lo, hi = band(args.band) if args.band else (0.0, 1.5 * float(result.frequency.max()))
    freq = np.linspace(max(lo, 1e-3 * hi), hi, 1500)
    frfs = preload_frfs(ctx.numeric, freq, bode_at, inputs=inputs, outputs=outputs, parameter=args.parameter,
                        params=given, position=ctx.position)
    nominal = frfs[min(frfs, key=lambda v: abs(v - result.reference))]
    k_ref = int(np.argmin(np.abs(result.preload - result.reference)))
    levels = sensor_visibility(nominal, result.frequency[k_ref])[:, 0, :]  # (n_out, m)

    lines = [f"{ctx.structure.name}: modes {', '.join(map(str, result.modes))} over {args.parameter} "
             f"(followed by shape from {args.parameter} = {result.reference:g})"]
    head = f"  {args.parameter:>8} " + " ".join(f"{'mode ' + str(m) + ' Hz / %':>18}" for m in result.modes)
    lines.append(head)
    for k, value in enumerate(result.preload):
        cells = " ".join(f"{result.frequency[k, j]:10.2f} /{100 * result.damping[k, j]:5.2f}"
                         for j in range(len(result.modes)))
        lines.append(f"  {value:8.3g} {cells}")
    lines.append("  d ln f / d ln preload: " + ", ".join(f"mode {m} {s:.3f}" for m, s in zip(result.modes, sens,
                                                                                              strict=True)))
    lines.append(f"level of each mode in the FRFs from {inputs[0]} (dB below the output's strongest mode):")
    for o, out in enumerate(nominal.output_names):
        lines.append(f"  {out:>8} " + " ".join(f"{levels[o, j]:7.1f}" for j in range(len(result.modes))))
    files: dict[str, Any] = {}
    if args.plot_map:
        preload_map_plot(result, args.plot_map, title=f"{ctx.structure.name}: frequency-damping map")
        files["map"] = args.plot_map
        lines.append(f"wrote {args.plot_map}")
    if args.plot_bode:
        # one FRF set with an output per (output, preload), so that the Bode plot overlays them
        stacked = np.concatenate([frfs[v].H for v in bode_at], axis=0)
        labels = tuple(f"{out} @ {100 * v:g} %" for v in bode_at for out in outputs)
        overlay = FRFData(freq=freq, H=stacked, input_names=tuple(inputs), output_names=labels)
        bode_plot(overlay, args.plot_bode, title=f"{ctx.structure.name}: FRFs from {inputs[0]} over preload")
        files["bode"] = args.plot_bode
        lines.append(f"wrote {args.plot_bode}")
    data = {"model": ctx.structure.name, "map": result.to_dict(), "input": inputs[0], "outputs": outputs,
            "visibility_db": {out: levels[o].tolist() for o, out in enumerate(nominal.output_names)},
            "files": files}
    emit(args, data, "\n".join(lines))
    return 0


__all__ = ["register"]
