"""``cappe model show|matrices|modes|tf|zpk|ss|frf|check``: representations of a structure model."""

from __future__ import annotations

import argparse
import functools
import sys
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from cappe.cli._common import (
    FRF_OUT,
    JSON_OUT,
    ModelContext,
    UsageError,
    add_deprecated,
    add_model_options,
    add_output_options,
    emit,
    names,
)
from cappe.exceptions import ModelError


def _with_model(func: Callable[[argparse.Namespace, ModelContext], int]) -> Callable[[argparse.Namespace], int]:
    """Run a command on the model, parameter values and position of its arguments.

    An error found in the loaded model names the model file where the message does not (a representation or a
    look-up by name does not know it), and, with a ``--params`` file, that file too: its values may be the cause (a
    mass of 1e-300 kg), and the model entry alone does not say where they came from.
    """

    @functools.wraps(func)
    def run(args: argparse.Namespace) -> int:
        ctx = ModelContext(args)
        try:
            return func(args, ctx)
        except ModelError as exc:
            msg = str(exc)
            source = ctx.structure.source
            if source and source not in msg:
                msg = f"{source}: {msg}"
            if args.params and str(args.params) not in msg:
                msg = f"{msg} (parameter values from {args.params})"
            if msg == str(exc):
                raise
            raise ModelError(msg) from exc

    return run


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    parser = sub.add_parser("model", help="model representations: show, matrices, modes, tf, zpk, ss, frf, check; "
                                          "random-truth")
    cmds = parser.add_subparsers(dest="model_command", metavar="COMMAND", required=True)

    p = cmds.add_parser("show", help="parameters, bodies, elements, inputs, outputs, sensors")
    add_model_options(p)
    p.set_defaults(func=show)

    p = cmds.add_parser("matrices", help="M, C, K, G, H (numeric or --symbolic)")
    add_model_options(p)
    p.add_argument("--symbolic", action="store_true", help="expressions in the parameter names")
    p.set_defaults(func=matrices)

    p = cmds.add_parser("modes", help="natural frequencies, damping ratios, mode shapes")
    add_model_options(p)
    p.add_argument("--damping", choices=["exact", "first-order", "undamped"], default="exact")
    p.add_argument("--modal-out", metavar="FILE", help="also write the modes at the sensors as cappe.modal/1 JSON")
    p.add_argument("--sensors", metavar="LIST", help="comma-separated sensor channels or nodes for --modal-out")
    p.add_argument("--all-positions", action="store_true",
                   help="with --modal-out: one set per combination of the model's listed axis positions")
    p.add_argument("--plot", metavar="FILE.html|FILE.gif",
                   help="animate a mode shape (the bodies' wireframes over one cycle; .html plays in a browser)")
    p.add_argument("--mode", type=int, default=1, metavar="N", help="mode animated by --plot (1-based, default 1)")
    p.set_defaults(func=modes)

    for name, func, helptext in (
        ("tf", tf, "transfer function (monic denominator, highest power first)"),
        ("zpk", zpk_cmd, "zeros, poles and gain"),
    ):
        p = cmds.add_parser(name, help=helptext)
        add_model_options(p)
        p.add_argument("--input", required=True, help="input name")
        p.add_argument("--output", required=True, help="output name")
        group = p.add_mutually_exclusive_group()
        group.add_argument("--exact", action="store_true", help="exact rational coefficients")
        group.add_argument("--symbolic", action="store_true", help="coefficients in the parameter names")
        if name == "zpk":
            p.add_argument("--plot", metavar="FILE.png", help="write a pole-zero map")
        p.set_defaults(func=func)

    p = cmds.add_parser("ss", help="state-space matrices, continuous or discrete")
    add_model_options(p)
    p.add_argument("--inputs", help="comma-separated inputs (default all)")
    p.add_argument("--outputs", help="comma-separated outputs (default all)")
    p.add_argument("--dt", type=float, help="sample time (s) for a discrete model")
    p.add_argument("--method", choices=["zoh", "tustin"], default="zoh")
    p.set_defaults(func=ss)

    p = cmds.add_parser("frf", help="frequency response functions",
                        epilog="-o writes the FRFs as UFF 58 (.uff/.unv), CSV (.csv) or npz (.npz) by the extension, "
                               "or this command's JSON (.json).")
    add_model_options(p, {**JSON_OUT, **FRF_OUT})
    p.add_argument("--inputs", help="comma-separated inputs (default all)")
    p.add_argument("--outputs", help="comma-separated outputs (default all)")
    p.add_argument("--fmin", type=float, default=None, help="lowest frequency (Hz)")
    p.add_argument("--fmax", type=float, default=None, help="highest frequency (Hz)")
    p.add_argument("--lines", type=int, default=400, metavar="N",
                   help="number of frequencies, log spaced (default 400)")
    add_deprecated(p, "--n", dest="lines", instead="--lines", type=int, metavar="N")
    p.add_argument("--plot", metavar="FILE.png", help="write a Bode plot")
    p.set_defaults(func=frf)

    p = cmds.add_parser(
        "random-truth", help="a random parameter file within the unknowns' bounds (log-uniform where positive)",
        description="Draws each unknown parameter within its bounds, log-uniformly where both bounds are positive "
                    "(as the paper's random truths), uniformly otherwise, and writes {name: value} with -o: the "
                    "parameter file that `cappe simulate --params` and `cappe identify --truth` read.")
    p.add_argument("model", metavar="MODEL", help="model YAML file or builtin:NAME")
    p.add_argument("--unknowns", metavar="LIST", help="comma-separated parameters to draw (default: those marked "
                                                      "unknown)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    add_output_options(p)
    p.set_defaults(func=random_truth)

    p = cmds.add_parser("check", help="validation, conditioning, rigid-body modes, exact invertibility")
    add_model_options(p)
    p.add_argument("--inputs", help="comma-separated inputs for the invertibility test (default all)")
    p.add_argument("--outputs", help="comma-separated outputs for the invertibility test (default all)")
    p.add_argument("--exact", choices=("auto", "always", "never"), default="auto",
                   help=f"exact rational rank tests (symbolic derivation, Sain-Massey): auto = up to "
                        f"{EXACT_STATE_LIMIT} states; larger models get the numerical PBH test only")
    p.set_defaults(func=check)


# -- show -------------------------------------------------------------------------------------------
@_with_model
def show(args: argparse.Namespace, ctx: ModelContext) -> int:
    s = ctx.structure
    if args.position:  # parsed with the other model options, and nothing here depends on it
        msg = ("model show describes the model at every axis position; --position has no effect here (it applies to "
               "matrices, modes, tf, zpk, ss, frf and check)")
        raise UsageError(msg)
    data = {
        "name": s.name,
        "n_dof": s.n_dof,
        "dofs": list(s.dofs),
        "positions": {a.name: list(a.positions) for a in s.axes},
        "parameters": [{**p.to_dict(), "value": ctx.values[p.name]} for p in s.parameters],
        "bodies": [
            {
                "name": b.name,
                "mass": str(b.mass),
                "dofs": list(b.dofs),
                "position": [str(v) for v in b.position],
                "spin": None
                if b.spin is None
                else {"speed": str(b.spin.speed), "polar_inertia": str(b.spin.polar_inertia)},
            }
            for b in s.bodies
        ],
        "elements": [
            {
                "name": e.name,
                "bodies": [e.body_a, e.body_b],
                "directions": list(e.directions),
                "stiffness": {d: str(v) for d, v in e.stiffness.items()},
                "damping": {d: str(v) for d, v in e.damping.items()},
                "loss": {d: str(v) for d, v in e.loss.items()},
            }
            for e in s.elements
        ],
        "inputs": [
            {
                "name": i.name,
                "kind": i.kind,
                "body": i.body,
                "point": [str(v) for v in i.point],
                "direction": [str(v) for v in i.direction],
            }
            for i in s.inputs
        ],
        "outputs": [
            {
                "name": o.name,
                "quantity": o.quantity,
                **(
                    {"element": o.element, "direction": o.element_direction}
                    if o.element
                    else {
                        "body": o.body,
                        "point": [str(v) for v in o.point],
                        "direction": [str(v) for v in o.direction],
                    }
                ),
            }
            for o in s.outputs
        ],
        "sensors": [{"name": n.name, "body": n.body, "point": [str(v) for v in n.point]} for n in s.sensors],
    }
    flexible = f", {len(s.flexible_bodies)} flexible" if s.flexible_bodies else ""
    lines = [f"model {s.name}: {s.n_dof} DOF, {len(s.bodies)} bodies{flexible}, {len(s.elements)} elements"]
    if s.axes:
        lines.append("axes: " + ", ".join(f"{a.name} at {list(a.positions)} {a.unit}" for a in s.axes))
    lines.append("parameters:")
    for p in s.parameters:
        flags = " unknown" if p.unknown else (" disturbable" if p.disturbable else "")
        bounds = f" [{p.bounds[0]:g}, {p.bounds[1]:g}]" if p.bounds else ""
        lines.append(f"  {p.name:<10} {ctx.values[p.name]:>12.6g} {p.unit:<8} {p.kind:<9}{bounds}{flags}")
    lines.append("dofs: " + " ".join(s.dofs))
    lines.append("inputs: " + ", ".join(f"{i.name} ({i.kind} on {i.body})" for i in s.inputs))
    lines.append("outputs: " + ", ".join(f"{o.name} ({o.quantity})" for o in s.outputs))
    if s.sensors:
        lines.append("sensors: " + ", ".join(n.name for n in s.sensors))
    emit(args, data, "\n".join(lines))
    return 0


# -- matrices ---------------------------------------------------------------------------------------
@_with_model
def matrices(args: argparse.Namespace, ctx: ModelContext) -> int:
    if args.symbolic:
        from cappe.model import derive

        sym = derive(ctx.structure)
        mats = sym.substitute(ctx.position) if ctx.structure.axes and args.position else sym.matrices()
        data: dict[str, Any] = {
            "dofs": list(ctx.structure.dofs),
            "matrices": {k: [[str(v) for v in row] for row in m.tolist()] for k, m in mats.items()},
        }
        text = "\n".join(f"{k} =\n{m}" for k, m in mats.items() if any(v != 0 for v in m))
    else:
        sys_ = ctx.system()
        mats_n = {"M": sys_.M, "C": sys_.C, "K": sys_.K, "G": sys_.G, "H": sys_.H}
        data = {
            "dofs": list(sys_.dofs),
            "position": ctx.position,
            "matrices": {k: m.tolist() for k, m in mats_n.items()},
        }
        with np.printoptions(precision=5, linewidth=160, suppress=False):
            text = (
                "dofs: " + " ".join(sys_.dofs) + "\n" + "\n".join(f"{k} =\n{m}" for k, m in mats_n.items() if np.any(m))
            )
    emit(args, data, text)
    return 0


# -- modes ------------------------------------------------------------------------------------------
@_with_model
def modes(args: argparse.Namespace, ctx: ModelContext) -> int:
    system = ctx.system()
    result = system.modes(args.damping)
    data = result.to_dict()
    data["position"] = ctx.position
    notes = []
    if args.damping == "exact":
        # how far the light-damping (first-order) estimate is from the exact complex modes
        approx = system.modes("first-order")
        if approx.n_modes == result.n_modes:
            safe = np.where(result.frequency > 0, result.frequency, 1.0)
            df = float(np.max(np.abs(approx.frequency - result.frequency) / safe, initial=0.0))
            dz = float(np.max(np.abs(approx.damping - result.damping), initial=0.0))
            data["first_order_difference"] = {"frequency_max_relative": df, "damping_max_absolute": dz}
            notes.append(f"first-order vs exact: frequencies within {100 * df:.3g} %, damping ratios within {dz:.3g}")
    lines = [
        f"{ctx.structure.name}: {result.n_modes} modes ({args.damping} damping)",
        f"{'mode':>4} {'frequency (Hz)':>15} {'damping (%)':>12}  dominant DOF (kinetic energy)",
    ]
    dominant = result.dominant_dofs(system.M)
    for r in range(result.n_modes):
        k = int(dominant[r])
        tag = " (rigid)" if result.rigid.size and result.rigid[r] else ""
        lines.append(f"{r + 1:>4} {_fixed(result.frequency[r], 3):>15} {_fixed(100 * result.damping[r], 4):>12}  "
                     f"{result.dofs[k]}{tag}")
    lines.extend(notes)
    if args.modal_out:
        lines.append(_write_modal(ctx, args))
    if args.plot:
        lines.append(_animate(ctx, args, result))
        data["plot"] = args.plot
    emit(args, data, "\n".join(lines))
    return 0


def _animate(ctx: ModelContext, args: argparse.Namespace, result: Any) -> str:
    from cappe.report import animate_mode_shape

    if not 1 <= args.mode <= result.n_modes:
        msg = f"--mode must be between 1 and {result.n_modes} (the model's modes); got {args.mode}"
        raise UsageError(msg)
    r = args.mode - 1
    title = (f"{ctx.structure.name}: mode {args.mode}, {result.frequency[r]:.4g} Hz, damping "
             f"{100 * result.damping[r]:.3g} % ({args.damping})")
    animate_mode_shape(args.plot, model=ctx.numeric, mode=result, index=r, params=ctx.values,
                       position=ctx.position, title=title)
    return f"wrote {args.plot} (mode {args.mode} animated over one cycle, magnified)"


def _fixed(value: float, decimals: int) -> str:
    """``value`` with ``decimals`` decimals, or in exponent form where that would show no digit or dozens."""
    if value != 0 and not 10.0 ** (-decimals) <= abs(value) < 1e9:
        return f"{value:.{decimals + 1}e}"
    return f"{value:.{decimals}f}"


def _write_modal(ctx: ModelContext, args: argparse.Namespace) -> str:
    import itertools

    from cappe.io import write_modal_data
    from cappe.modal import ModalEngine

    axes = ctx.structure.axes
    if args.all_positions and axes:
        combos = itertools.product(*[axis.positions or (ctx.position[axis.name],) for axis in axes])
        positions = [dict(zip([a.name for a in axes], combo, strict=True)) for combo in combos]
    else:
        positions = [ctx.position]
    engine = ModalEngine(ctx.numeric, sensors=names(args.sensors))
    data = engine.modal_data(positions, ctx.values, exact=args.damping == "exact")
    write_modal_data(args.modal_out, data)
    text = f"wrote {len(data.sets)} modal set(s) at {len(data.sensors)} channels to {args.modal_out}"
    if not ctx.structure.sensors and not args.sensors:
        from cappe.modal._reference import no_sensors_message

        text += (f"\nnote: the channels are the model's DOFs ({', '.join(data.sensors[:3])} ...); cappe simulate, "
                 f"identify and estimate compare modes at sensor nodes: {no_sensors_message(ctx.structure)}")
    return text


# -- tf / zpk ---------------------------------------------------------------------------------------
def _transfer(ctx: ModelContext, args: argparse.Namespace) -> Any:
    from cappe.exact import exact_transfer_function, symbolic_transfer_function
    from cappe.model import derive
    from cappe.systems import transfer_function

    s = ctx.structure
    s.input(args.input)
    s.output(args.output)
    if args.exact or args.symbolic:
        sym = derive(s)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            if args.exact:
                result = exact_transfer_function(sym, args.input, args.output, ctx.values, ctx.position)
            else:
                result = symbolic_transfer_function(
                    sym, args.input, args.output, ctx.overrides, ctx.position if s.axes and args.position else None
                )
        for w in caught:
            print(f"cappe: warning: {w.message}", file=sys.stderr)
        return result
    return transfer_function(ctx.system().state_space(args.input, args.output), args.input, args.output)


def _poly_text(coefs: tuple[Any, ...], kind: str) -> str:
    n = len(coefs) - 1
    terms = []
    for k, c in enumerate(coefs):
        power = n - k
        if c == 0:
            continue
        value = f"{float(c):.6g}" if kind == "float" else f"({c})"
        terms.append(value + ("" if power == 0 else (" s" if power == 1 else f" s^{power}")))
    return " + ".join(terms) if terms else "0"


@_with_model
def tf(args: argparse.Namespace, ctx: ModelContext) -> int:
    result = _transfer(ctx, args)
    num = _poly_text(result.numerator, result.kind)
    den = _poly_text(result.denominator, result.kind)
    text = f"G({args.output}/{args.input})(s) =\n  numerator:   {num}\n  denominator: {den}"
    if result.cancelled:
        text += "\n  exact pole-zero cancellation removed: " + ", ".join(result.cancelled)
    emit(args, result.to_dict(), text)
    return 0


@_with_model
def zpk_cmd(args: argparse.Namespace, ctx: ModelContext) -> int:
    from cappe.systems import zpk

    if args.symbolic:
        msg = "zpk needs numbers; use --exact or plain float"
        raise UsageError(msg)
    model = zpk(_transfer(ctx, args))
    data = model.to_dict()
    if args.plot:
        from cappe.report import pole_zero_plot

        pole_zero_plot(model, args.plot, f"{ctx.structure.name}: {args.output}/{args.input}")
        data["plot"] = args.plot

    def fmt(v: np.ndarray) -> str:  # type: ignore[type-arg]
        return ", ".join(f"{z.real:.6g}{z.imag:+.6g}j" for z in v) or "none"

    text = f"zeros (rad/s): {fmt(model.zeros)}\npoles (rad/s): {fmt(model.poles)}\ngain: {model.gain:.6g}"
    emit(args, data, text)
    return 0


# -- ss ---------------------------------------------------------------------------------------------
@_with_model
def ss(args: argparse.Namespace, ctx: ModelContext) -> int:
    model = ctx.system().state_space(names(args.inputs), names(args.outputs))
    if args.dt is not None:
        model = model.discretize(args.dt, args.method)
    with np.printoptions(precision=5, linewidth=160):
        text = "\n".join(
            [
                f"{'discrete (' + model.method + f', dt = {model.dt:g} s)' if model.is_discrete else 'continuous'}"
                f" state space, {model.n_states} states",
                "states: " + " ".join(model.state_names),
                f"A =\n{model.A}",
                f"B =\n{model.B}",
                f"C =\n{model.C}",
                f"D =\n{model.D}",
            ]
        )
    emit(args, model.to_dict(), text)
    return 0


# -- frf --------------------------------------------------------------------------------------------
@_with_model
def frf(args: argparse.Namespace, ctx: ModelContext) -> int:
    system = ctx.system()
    undamped = system.modes("undamped").frequency
    elastic = undamped[undamped > 0]
    fmin = args.fmin if args.fmin is not None else (max(elastic.min() / 10, 0.1) if elastic.size else 1.0)
    fmax = args.fmax if args.fmax is not None else (elastic.max() * 2 if elastic.size else 1000.0)
    if args.fmin is None and args.fmax is None and elastic.size and fmin >= fmax:
        fmin = elastic.min() / 10  # every mode far below 0.1 Hz: the band around them, not the 0.1 Hz floor
    if not 0 < fmin < fmax:
        msg = f"need 0 < --fmin < --fmax; got {fmin:g} and {fmax:g}"
        raise UsageError(msg)
    if args.lines < 2:
        msg = f"--lines must be at least 2; got {args.lines}"
        raise UsageError(msg)
    freq = np.geomspace(fmin, fmax, args.lines)
    result = system.frf(freq, names(args.inputs), names(args.outputs))
    data = result.to_dict()
    if args.plot:
        from cappe.report import bode_plot

        bode_plot(result, args.plot, ctx.structure.name)
        data["plot"] = args.plot
    peaks = []
    for o, out in enumerate(result.output_names):
        for i, inp in enumerate(result.input_names):
            mag = np.abs(result.H[o, i])
            k = int(np.argmax(mag))
            peaks.append(f"{out}/{inp}: max |H| = {mag[k]:.4g} at {freq[k]:.2f} Hz")
    text = f"FRF on {args.lines} frequencies from {fmin:g} to {fmax:g} Hz\n" + "\n".join(peaks)
    if args.out and Path(args.out).suffix.lower() in FRF_OUT:
        from cappe.io import write_frf

        write_frf(args.out, result)
        text += f"\nwrote {args.out}"
        args = argparse.Namespace(**{**vars(args), "out": None})  # -o got the FRFs, not this summary
    emit(args, data, text)
    return 0


# -- random-truth -----------------------------------------------------------------------------------
def random_truth(args: argparse.Namespace) -> int:
    from cappe.estimate import ParameterSpace
    from cappe.model import load_model

    structure = load_model(args.model)
    space = ParameterSpace.from_model(structure, names(args.unknowns))
    truth = space.mapping(space.sample(args.seed))
    lines = [f"{structure.name}: random truth of {space.n} unknowns within their bounds (seed {args.seed})",
             f"  {'parameter':<12}{'value':>13}  {'bounds':<25} draw"]
    for k, (name, value) in enumerate(truth.items()):
        bounds = f"[{space.lower[k]:.4g}, {space.upper[k]:.4g}]"
        unit = structure.parameter(name).unit
        lines.append(f"  {name:<12}{value:>13.5g}  {bounds:<25} {'log-uniform' if space.log[k] else 'uniform'}"
                     f"{'  ' + unit if unit else ''}")
    if args.out:
        lines.append(f"wrote {args.out} (parameter file: --params / --truth)")
    emit(args, truth, "\n".join(lines))
    return 0


# -- check ------------------------------------------------------------------------------------------
#: Largest state count for which ``model check --exact auto`` runs the exact rational rank tests:
#: cappe.exact.EXACT_STATE_LIMIT, spelled out so that building the parser imports no sympy.
EXACT_STATE_LIMIT = 24


@_with_model
def check(args: argparse.Namespace, ctx: ModelContext) -> int:
    from cappe.exact import check_model

    result = check_model(ctx.numeric, ctx.values, ctx.position, inputs=names(args.inputs),
                         outputs=names(args.outputs), exact={"always": True, "never": False}.get(args.exact))
    cond_m, cond_k = result.condition_M, result.condition_K
    lines = [
        f"model {result.name}: valid, {result.n_dof} DOF",
        f"condition number: M {cond_m:.3g}, K " + (f"{cond_k:.3g}" if np.isfinite(cond_k) else "inf (singular)"),
    ]
    if result.rigid_body_modes:
        lines.append(f"{len(result.rigid_body_modes)} rigid-body mode(s) (unconstrained DOFs):")
        lines.extend("  " + ", ".join(f"{d} {v:+.3f}" for d, v in m.items()) for m in result.rigid_body_modes)
    else:
        lines.append("no rigid-body modes: every DOF is constrained")
    lines.append(f"inputs {', '.join(result.inputs)} -> outputs {', '.join(result.outputs)}: "
                 f"{result.n_states} states")
    pbh = result.pbh
    lines.append(f"  PBH test (double precision, per mode): controllability rank {pbh.controllability_rank}, "
                 f"observability rank {pbh.observability_rank}")
    inv = result.invertibility
    if inv is not None:
        lines.append(f"  controllability rank {result.controllability_rank}, observability rank "
                     f"{result.observability_rank} (exact)")
        lines.append(
            f"  Sain-Massey M_n {inv.matrix_shape[0]}x{inv.matrix_shape[1]}: exact ranks "
            f"{inv.exact_ranks[1]} / {inv.exact_ranks[0]} -> "
            f"{'invertible' if inv.invertible_exact else 'NOT invertible'}"
        )
        lines.append(_float_sain_massey(inv))
    else:
        lines.append(f"  exact rank tests skipped: {result.n_states} states > {EXACT_STATE_LIMIT} (rational Krylov "
                     "and Sain-Massey matrices of this size take minutes to hours); --exact always forces them")
    emit(args, result.to_dict(), "\n".join(lines))
    return 0


def _float_sain_massey(inv: Any) -> str:
    """The double-precision Sain-Massey ranks beside the exact ones, saying whether they agree and which to trust."""
    ranks = f"double precision ranks {inv.float_ranks[1]} / {inv.float_ranks[0]}"
    if tuple(inv.float_ranks) == tuple(inv.exact_ranks):
        return f"  ({ranks}: the same as the exact ranks)"
    if inv.invertible_float != inv.invertible_exact:
        verdict = "invertible" if inv.invertible_float else "not invertible"
        return (f"  ({ranks} -> {verdict}: the SVD ranks of M_n differ from the exact ones and give the wrong "
                "verdict here; the exact test above holds)")
    return f"  ({ranks}: they differ from the exact ranks, but give the same verdict)"


__all__ = ["register"]
