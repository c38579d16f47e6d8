"""``cappe plan-test MODEL``: choose axis positions and sensor channels so that the unknowns are identifiable.

* ``cappe plan-test MODEL --n-positions 3 --n-sensors 12 [--candidate-positions z=...] [--candidate-sensors LIST]
  [--modes 20] [--noise-frequency 0.005 --noise-damping 0.05 --noise-shape 0.02] [--max-std 0.1] -o plan.json``
"""

from __future__ import annotations

import argparse
import itertools
import math
import shlex
from typing import Any

import numpy as np

from cappe.cli._common import UsageError, add_model_options, emit, names, number_pairs

__all__ = ["register", "run"]

NOISE_DEFAULTS = {"frequency": 0.005, "damping": 0.05, "shape": 0.02}


def register(sub: Any) -> None:
    p = sub.add_parser(
        "plan-test",
        help="choose axis positions and sensor channels so the unknowns are identifiable (D-optimal Fisher)",
        description=(
            "Choose N axis positions and M sensor channels from candidates that maximize the Fisher information "
            "(D-optimal) of the modal data cappe identify fits, under the stated noise; report the expected std of "
            "every unknown and the unknowns the plan cannot determine; write a cappe.plan/1 file."
        ),
    )
    add_model_options(p)
    p.add_argument("--n-positions", type=int, required=True, metavar="N", help="axis positions to measure at")
    p.add_argument("--n-sensors", type=int, required=True, metavar="M",
                   help="sensor channels NODE:DIR (the same at every position)")
    p.add_argument("--candidate-positions", metavar="AXIS=V[,V...]", action="append", default=[],
                   help="candidate values of one axis (repeatable; axes combine; default the model's listed "
                        "positions)")
    p.add_argument("--grid", type=int, metavar="K",
                   help="instead: K evenly spaced values per axis between its smallest and largest listed position")
    p.add_argument("--candidate-sensors", metavar="LIST",
                   help="candidate channels or nodes, comma-separated (default every channel of the model's sensors)")
    p.add_argument("--unknowns", metavar="LIST", help="comma-separated unknowns (default: those marked unknown)")
    p.add_argument("--modes", type=int, default=20, metavar="N",
                   help="modes per position, the lowest (as cappe simulate --modes; default 20)")
    for quantity, default in NOISE_DEFAULTS.items():
        p.add_argument(f"--noise-{quantity}", type=float, default=default, metavar="REL",
                       help=f"relative std of the {quantity} values, as cappe simulate / identify (default {default})")
    p.add_argument("--max-std", type=float, default=0.1, metavar="REL",
                   help="an unknown with a larger expected relative std is reported undetermined (default 0.1)")
    p.add_argument("--visibility", type=float, default=0.05, metavar="FRACTION",
                   help="a mode counts where its largest measured component reaches this fraction of its largest "
                        "candidate component (default 0.05)")
    p.add_argument("--random", type=int, default=10, metavar="N", help="random plans to compare with (default 10)")
    p.add_argument("--seed", type=int, default=0, help="seed of the random plans (default 0)")
    p.set_defaults(func=run)


def _candidate_positions(args: argparse.Namespace, structure: Any, base: dict[str, float]) -> list[dict[str, float]]:
    axes = {a.name: a for a in structure.axes}
    if args.grid is not None and args.candidate_positions:
        msg = "give either --grid or --candidate-positions"
        raise UsageError(msg)
    values: dict[str, list[float]] = {}
    if args.grid is not None:
        if args.grid < 1:
            msg = f"--grid must be >= 1; got {args.grid}"
            raise UsageError(msg)
        for name, axis in axes.items():
            if axis.positions:
                values[name] = np.linspace(min(axis.positions), max(axis.positions), args.grid).tolist()
    elif args.candidate_positions:
        for item in args.candidate_positions:
            axis, sep, rest = item.partition("=")
            axis = axis.strip()
            if not sep or axis not in axes:
                msg = (f"--candidate-positions must look like AXIS=V[,V...] with an axis of model "
                       f"'{structure.name}' ({', '.join(axes) or 'none'}); got {item!r}")
                raise UsageError(msg)
            for text in rest.split(","):
                number = number_pairs([f"{axis}={text}"], "--candidate-positions")[axis]
                values.setdefault(axis, []).append(number)
    else:
        values = {name: list(a.positions) for name, a in axes.items() if a.positions}
    chosen = sorted(set(number_pairs(args.position, "--position")) & set(values))
    if chosen:  # the plan picks these axes' values itself: a fixed --position there would be dropped
        msg = (f"--position fixes {', '.join(chosen)}, which the plan chooses among its candidate positions; to "
               f"measure at one value, give it as the only candidate (--candidate-positions {chosen[0]}=V)")
        raise UsageError(msg)
    order = [a for a in structure.axis_names if a in values]
    combos = itertools.product(*(values[a] for a in order))
    return [{**base, **dict(zip(order, combo, strict=True))} for combo in combos]


def _positions_option(positions: list[dict[str, float]], axes: tuple[str, ...]) -> list[str]:
    """``--positions`` options for cappe simulate: one axis' values each (a full grid), or None if not a grid."""
    values = {a: sorted({p[a] for p in positions}) for a in axes}
    if len(positions) != math.prod(len(v) for v in values.values()):
        return []
    return [f"--positions {a}={','.join(f'{v:.12g}' for v in vals)}" for a, vals in values.items()]


def run(args: argparse.Namespace) -> int:
    from cappe.cli._common import ModelContext
    from cappe.estimate._plan import PlanCandidates, plan_test

    levels = {q: getattr(args, f"noise_{q}") for q in NOISE_DEFAULTS}
    bad = {f"--noise-{q}": v for q, v in levels.items() if not (math.isfinite(v) and v > 0)}
    if bad:
        msg = f"noise levels must be > 0; got {bad}"
        raise UsageError(msg)
    for option, value, low in (("--n-positions", args.n_positions, 1), ("--n-sensors", args.n_sensors, 1),
                               ("--modes", args.modes, 1), ("--random", args.random, 0)):
        if value < low:
            msg = f"{option} must be >= {low}; got {value}"
            raise UsageError(msg)
    if not (math.isfinite(args.max_std) and args.max_std > 0):
        msg = f"--max-std must be > 0; got {args.max_std}"
        raise UsageError(msg)
    ctx = ModelContext(args)
    positions = _candidate_positions(args, ctx.structure, ctx.position)
    if args.n_positions > len(positions):
        msg = f"--n-positions {args.n_positions}: only {len(positions)} candidate positions"
        raise UsageError(msg)
    candidates = PlanCandidates.from_model(
        ctx.numeric, unknowns=names(args.unknowns), params=ctx.values, positions=positions,
        sensors=names(args.candidate_sensors), n_modes=args.modes,
        noise=(levels["frequency"], levels["damping"], levels["shape"]), visibility=args.visibility)
    plan = plan_test(candidates=candidates, n_positions=args.n_positions, n_sensors=args.n_sensors,
                     max_relative_std=args.max_std, n_random=args.random, rng=args.seed)
    doc = plan.to_dict()
    doc["commands"] = _commands(args, plan, ctx.structure.axis_names)
    emit(args, doc, _text(plan, doc, args))
    return 0


def _commands(args: argparse.Namespace, plan: Any, axes: tuple[str, ...]) -> dict[str, str]:
    """Command lines that rehearse the plan on simulated data: one cappe simulate where the plan's positions form a
    grid (``--positions`` combines axes as a grid), else one per position (each axis at its value, ``ref1.json``,
    ``ref2.json``, ...; one command per line), and the cappe identify that reads what they write."""
    noise = " ".join(f"--noise-{q} {getattr(args, f'noise_{q}'):g}" for q in NOISE_DEFAULTS)
    model = shlex.quote(args.model)
    sensors = ",".join(plan.sensors)
    common = f"--sensors {sensors} --modes {args.modes} {noise}"
    grid = _positions_option(plan.positions, axes)
    if grid:
        simulate = f"cappe simulate {model} --params truth.json {' '.join(grid)} {common} -o ref.json"
        references = "ref.json"
    else:
        lines = []
        for k, position in enumerate(plan.positions, start=1):
            where = " ".join(f"--positions {a}={position[a]:.12g}" for a in axes)
            lines.append(f"cappe simulate {model} --params truth.json {where} {common} --seed {k} -o ref{k}.json")
        simulate = "\n".join(lines)
        references = " ".join(f"ref{k}.json" for k in range(1, len(plan.positions) + 1))
    validation = "none" if len(plan.positions) < 2 else ",".join(f"{k}={v:.12g}" for k, v in plan.positions[0].items())
    return {
        "simulate": simulate,
        "identify": f"cappe identify {model} --reference {references} --validation none {noise} -o result.json",
        "validation_note": f"the plan's positions are all identification positions (--validation none); hold out "
                           f"another position for validation (e.g. --validation {validation} takes one of them)",
    }


def _pct(value: float) -> str:
    return f"{100 * value:9.3g}" if np.isfinite(value) else f"{'-':>9s}"


def _range(values: list[float]) -> str:
    finite = [v for v in values if np.isfinite(v)]
    return f"{100 * min(finite):.3g} to {100 * max(finite):.3g}" if finite else "-"


def _text(plan: Any, doc: dict[str, Any], args: argparse.Namespace) -> str:
    c = plan.candidates
    label = "; ".join(" ".join(f"{k}={v:g}" for k, v in p.items()) or "(no axes)" for p in plan.positions)
    lines = [
        f"{c.model_name}: test plan for {len(c.unknowns)} unknowns: {len(plan.positions)} of {len(c.positions)} "
        f"candidate positions, {len(plan.sensors)} of {len(c.sensors)} sensor channels, {c.frequency.shape[1]} modes "
        "per position (D-optimal Fisher information, greedy with exchange)",
        f"noise (relative std, as cappe simulate / identify): frequency {c.noise[0]:g}, damping {c.noise[1]:g}, "
        f"shape {c.noise[2]:g}",
        f"positions: {label}",
        f"sensors: {', '.join(plan.sensors)}",
        f"  {'parameter':<14}{'value':>12}{'std % plan':>12}{'std % all':>11}  determined",
    ]
    for n, v, r, b in zip(c.unknowns, c.values, plan.relative_std, plan.best_relative_std, strict=True):
        lines.append(f"  {n:<14}{v:>12.4g}{_pct(r):>12}{_pct(b):>11}  {'yes' if r <= plan.max_relative_std else 'NO'}")
    lines.append("(std % all: every candidate position and channel measured)")
    level = f"{100 * plan.max_relative_std:g} %"
    if plan.undetermined:
        lines.append(f"not determined by this plan (expected std above {level} or unidentifiable): "
                     f"{', '.join(plan.undetermined)}")
    else:
        lines.append(f"every unknown determined within {level} (expected std)")
    if plan.undetermined_with_all:
        lines.append(f"not determined even with every candidate position and channel measured: "
                     f"{', '.join(plan.undetermined_with_all)}")
    for combo in plan.uncertainty.combinations:
        lines.append(f"undetermined combination (relative): {combo}")
    rnd = plan.random
    if rnd:
        n_det = len(c.unknowns) - len(plan.undetermined_with_all)
        det = rnd["median_relative_std_determinable"]
        lines.append(
            f"{rnd['n']} random plans of the same size: log det {min(rnd['criterion']):.1f} to "
            f"{max(rnd['criterion']):.1f} (this plan {plan.criterion:.1f}); median std over the {n_det} unknowns "
            f"every candidate together determines {_range(det)} % (this plan "
            f"{100 * plan.median_relative_std_determinable:.3g} %), over all {len(c.unknowns)} "
            f"{_range(rnd['median_relative_std'])} % (this plan {100 * float(np.median(plan.relative_std)):.3g} %); "
            f"undetermined {min(rnd['n_undetermined'])} to {max(rnd['n_undetermined'])} (this plan "
            f"{len(plan.undetermined)})")
        if n_det < len(c.unknowns):
            lines.append("(the median over all unknowns also counts those that even every candidate together leaves "
                         "undetermined; the D-criterion does not aim at it)")
    lines.append("rehearse it on simulated data:")
    lines.extend(f"  {line}" for line in doc["commands"]["simulate"].splitlines())
    lines.append(f"  {doc['commands']['identify']}")
    if args.out:
        lines.append(f"plan ({doc['format']}) written to {args.out}")
    return "\n".join(lines)
