"""``cappe fit DATA --structure arx|armax|oe|bj --order N|auto [--prune N|auto]``: black-box models from time data."""

from __future__ import annotations

import argparse
import sys
import warnings
from typing import Any

from cappe.cli._common import UsageError, add_deprecated, add_output_options, channels, emit, naming_file

#: cappe.identify.BLACK_BOX_STRUCTURES, spelled out so that building the parser imports no numerical library
STRUCTURES = ("arx", "armax", "oe", "bj")


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "fit",
        help="black-box model (ARX, ARMAX, OE, BJ) from time data: continuous TF, poles, modes; pruning",
    )
    p.add_argument("data", metavar="DATA", help="time data file (UFF 58, CSV with a time column, or .npz)")
    p.add_argument("--inputs", metavar="LIST", help="input channels, comma-separated (required)")
    add_deprecated(p, "--input", dest="inputs", instead="--inputs A,B", join=True, nargs="+", metavar="CH")
    p.add_argument("--output", required=True, metavar="CH", help="output channel")
    p.add_argument("--structure", choices=STRUCTURES, default="arx", help="model structure (default arx)")
    p.add_argument("--order", default="auto",
                   help="model order n (every polynomial of the structure has order n), or 'auto' (default)")
    p.add_argument("--criterion", choices=["aic", "bic", "fpe"], help="--order auto: criterion (default aic)")
    p.add_argument("--max-order", type=int, help="--order auto: largest candidate order (default 12)")
    p.add_argument("--nk", type=int, default=1, help="input delay in samples (default 1)")
    p.add_argument("--prune", metavar="N|auto",
                   help="prune to N modes (thesis rules, then the N most significant), or 'auto' (rules and a 1 %% "
                        "peak-significance floor)")
    p.add_argument("--cutoff", type=float, help="--prune: anti-alias cut-off in Hz (default 0.8 x Nyquist)")
    p.add_argument("--max-damping", type=float, default=0.3, help="--prune: largest credible damping ratio (0.3)")
    p.add_argument("--refine", action="store_true",
                   help="--prune: refit an output-error model of the pruned order (removes ARX noise bias)")
    p.add_argument("--plot", metavar="FILE.png", help="--prune: pole-zero map of the pruned vs unpruned model")
    add_output_options(p)
    p.set_defaults(func=run)


def _count_or_auto(text: str | None, option: str, what: str) -> int | None:
    """``auto`` (or the option not given) -> None, else an integer >= 1."""
    if text is None or text == "auto":
        return None
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        msg = f"{option} must be {what} or 'auto'; got {text!r}"
        raise UsageError(msg)
    return n


@naming_file("data")
def run(args: argparse.Namespace) -> int:
    from cappe.identify import fit_black_box
    from cappe.io import read_time_data

    inputs = channels(args.inputs, "--inputs")
    n = _count_or_auto(args.order, "--order", "a positive integer")
    if n is not None and (args.criterion is not None or args.max_order is not None):
        msg = "--criterion and --max-order choose the order with --order auto; with --order N they do nothing"
        raise UsageError(msg)
    prune_to = _count_or_auto(args.prune, "--prune", "a positive number of modes")
    if (args.refine or args.plot or args.cutoff is not None) and args.prune is None:
        msg = "--refine, --plot and --cutoff act on a pruned model; add --prune N or --prune auto"
        raise UsageError(msg)
    data = read_time_data(args.data)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fit = fit_black_box(
            data, inputs=inputs, output=args.output, structure=args.structure,
            order="auto" if n is None else n, criterion=args.criterion or "aic",
            max_order=12 if args.max_order is None else args.max_order, nk=args.nk,
            prune=None if args.prune is None else ("auto" if prune_to is None else prune_to),
            cutoff=args.cutoff, max_damping=args.max_damping, refine=args.refine,
        )
        result: dict[str, Any] = {"format": "cappe.fit/1", "data": args.data, **fit.to_dict()}
        if args.plot:
            from cappe.report import pruning_plot

            orders = ", ".join(f"{k}={v}" for k, v in fit.orders.items())
            pruned = fit.pruned[0]
            pruning_plot(pruned, args.plot, f"{args.output}/{inputs[0]}: {args.structure.upper()} "
                         f"({orders}) pruned to {pruned.modes.n_modes} mode(s)")
            items = list(result.items())  # "plot" right after "pruning", as ever
            items.insert(list(result).index("pruning") + 1, ("plot", args.plot))
            result = dict(items)
    warned = [str(w.message) for w in caught]
    for message in warned:
        print(f"cappe: warning: {message}", file=sys.stderr)
    result["warnings"] = warned
    emit(args, result, _text(args, inputs, result, fit.modes))
    return 0


def _text(args: argparse.Namespace, inputs: list[str], result: dict[str, Any], modes: Any) -> str:
    orders = ", ".join(f"{k}={v}" for k, v in result["orders"].items())
    lines = [f"{args.structure.upper()} fit of {args.output} from {', '.join(inputs)} ({orders}): "
             f"{result['fit_percent']:.2f} % fit ({result['fit_horizon']}"
             f"{'' if result['stable'] else ', the model is unstable'})"]
    if "pruning" in result:
        first = result["pruning"][inputs[0]]
        removed = ", ".join(f"{rule} {count}" for rule, count in first["removed_counts"].items()) or "none"
        lines.append(f"pruned to {modes.n_modes} mode(s); removed poles and zeros by rule: {removed}")
    if "refined" in result:
        refined = result["refined"]
        lines.append(
            f"refined by OE {refined['orders']}: {refined['fit_percent']:.2f} % fit ({refined['fit_horizon']})"
        )
    lines.append("   mode   frequency (Hz)   damping (%)")
    for k, (f, z) in enumerate(zip(modes.frequency, modes.damping, strict=True)):
        lines.append(f"  {k + 1:5d}   {f:14.4f}   {100 * z:11.4f}")
    lines.append(f"continuous TF {result['output']}/{result['input']}: order {len(result['denominator']) - 1}")
    return "\n".join(lines)
