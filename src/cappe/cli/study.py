"""``cappe study MODEL --method M --truth FILE.json``: simulate -> estimate over noise levels and seeds."""

from __future__ import annotations

import argparse
import inspect
import sys
import warnings

from cappe.cli._common import ModelContext, UsageError, add_model_options, emit, names


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    from cappe.estimate._registry import METHODS

    p = sub.add_parser("study", help="simulation study: estimates' mean and std over noise levels and seeds")
    add_model_options(p)
    p.add_argument("--method", required=True, choices=list(METHODS), help="estimation method")
    p.add_argument("--truth", metavar="FILE.json", help="true parameter values (default: the model's, with --set)")
    p.add_argument("--unknowns", metavar="LIST", help="comma-separated unknowns (default: those marked unknown)")
    p.add_argument("--noise", metavar="LIST", default="0,0.01",
                   help="relative noise levels, comma-separated (default 0,0.01)")
    p.add_argument("--seeds", type=int, default=3, help="runs per noise level (default 3)")
    p.add_argument("--start", metavar="FILE.json", help="start values {name: value} (default: the model's)")
    p.add_argument("--setting", metavar="NAME=VALUE", action="append", default=[],
                   help="method setting passed to every run (repeatable), as for cappe estimate")
    p.add_argument("--fs", type=float, default=1000.0, help="sampling rate of simulated time data in Hz")
    p.add_argument("--duration", type=float, default=4.0, help="record length of simulated time data in s")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from cappe.cli.estimate import settings
    from cappe.estimate._study import simulation_study
    from cappe.io import read_parameters

    ctx = ModelContext(args)
    truth = dict(ctx.values)
    if args.truth:
        truth.update(read_parameters(args.truth))
    try:
        levels = [float(v) for v in names(args.noise) or []]
    except ValueError as exc:
        msg = f"--noise must be comma-separated fractions, e.g. 0,0.01; got {args.noise!r}"
        raise UsageError(msg) from exc
    if not levels or any(v < 0 for v in levels) or args.seeds < 1:
        msg = f"--noise needs levels >= 0 and --seeds >= 1; got {args.noise!r} and {args.seeds}"
        raise UsageError(msg)
    start = read_parameters(args.start) if args.start else None
    from cappe.estimate._registry import estimator_class

    if args.position and "position" not in inspect.signature(estimator_class(args.method).__init__).parameters:
        msg = (
            f"--position does not apply to method {args.method!r}: its reference data carry the axis position of "
            "each set"
        )
        raise UsageError(msg)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = simulation_study(model=ctx.numeric, method=args.method, truth=truth, unknowns=names(args.unknowns),
                                  noise_levels=levels, seeds=range(args.seeds), start=start,
                                  settings=settings(args.setting), fs=args.fs, duration=args.duration,
                                  position=ctx.position if args.position else None)
    for message in dict.fromkeys(str(w.message) for w in caught):
        print(f"cappe: warning: {message}", file=sys.stderr)
    where = ", ".join(f"{axis}={value:g}" for axis, value in ctx.position.items())
    emit(args, result.to_dict(), f"{ctx.structure.name}, {args.method}: {args.seeds} runs per noise level"
         + (f" at {where}" if where else "") + "\n"
         + result.to_text())
    return 0
