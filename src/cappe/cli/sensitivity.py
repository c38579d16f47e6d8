"""``cappe sensitivity MODEL --local | --sobol``: local percentage tables and global Sobol indices."""

from __future__ import annotations

import argparse
import sys
import warnings

import numpy as np

from cappe.cli._common import ModelContext, UsageError, add_deprecated, add_model_options, emit, names, naming_file
from cappe.exceptions import DataError, IllConditionedWarning, ModelError


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "sensitivity",
        help="local sensitivities (+-x %% table, normalized derivatives) or Sobol indices against reference modes",
    )
    add_model_options(p)
    mode = p.add_mutually_exclusive_group(required=True)
    mode.add_argument("--local", action="store_true", help="percentage table and normalized derivatives")
    mode.add_argument("--sobol", action="store_true", help="Sobol indices per reference mode, position, criterion")
    p.add_argument("--percent", type=float, help="--local: size of the parameter changes (default 10)")
    p.add_argument("--reference", metavar="FILE.json", help="--sobol: reference modes (cappe.modal/1)")
    p.add_argument("--n-gsa", type=int, metavar="N",
                   help="--sobol: Sobol base sample size, a power of two (default 1024; as in cappe identify)")
    add_deprecated(p, "--n", dest="n_gsa", instead="--n-gsa", type=int, metavar="N")
    p.add_argument("--progress", action="store_true", help="--sobol: progress bar even when stderr is not a terminal")
    p.add_argument("--seed", type=int, help="--sobol: random seed (default 0)")
    p.add_argument("--parameters", metavar="LIST",
                   help="comma-separated parameters (default: all for --local, the unknown ones for --sobol)")
    p.add_argument("--criteria", metavar="LIST",
                   help="--sobol: outputs per mode (default macxp,ndd2,frequency,damping)")
    p.add_argument("--threshold", type=float, help="--sobol: significance threshold on ST (default 0.01)")
    p.add_argument("--plot", metavar="FILE.png", help="--sobol: S1/ST bar plot of the first outputs")
    p.set_defaults(func=run)


#: The options of one mode, with their defaults (None on the command line: not given).
LOCAL_OPTIONS = {"percent": 10.0}
SOBOL_OPTIONS = {"reference": None, "n_gsa": 1024, "seed": 0, "criteria": "macxp,ndd2,frequency,damping",
                 "threshold": 0.01, "plot": None, "progress": False}


def run(args: argparse.Namespace) -> int:
    own, other, mode = (LOCAL_OPTIONS, SOBOL_OPTIONS, "--sobol") if args.local else (SOBOL_OPTIONS, LOCAL_OPTIONS,
                                                                                       "--local")
    foreign = [f"--{dest.replace('_', '-')}" for dest in other if getattr(args, dest) not in (None, False)]
    if foreign:  # parsed and then ignored before: say so instead
        msg = f"{', '.join(foreign)} {'applies' if len(foreign) == 1 else 'apply'} to {mode} only"
        raise UsageError(msg)
    for dest, default in own.items():
        if getattr(args, dest) is None:
            setattr(args, dest, default)
    ctx = ModelContext(args)
    if args.local:
        return _local(ctx, args)
    return _sobol(ctx, args)


def _local(ctx: ModelContext, args: argparse.Namespace) -> int:
    from cappe.sensitivity import modal_sensitivity, percentage_table

    table = percentage_table(ctx.numeric, ctx.values, ctx.position, percent=args.percent,
                             parameters=names(args.parameters))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", IllConditionedWarning)
        derivs = modal_sensitivity(ctx.numeric, ctx.values, ctx.position)
    for w in caught:
        if issubclass(w.category, IllConditionedWarning):
            print(f"cappe: warning: {w.message}. The table re-solves the modes and is not affected; the normalized "
                  "derivatives of --json are.", file=sys.stderr)
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    nf, nz = derivs.normalized()
    data = table.to_dict()
    data["normalized"] = {
        "parameter_names": list(derivs.parameter_names),
        "frequency": np.nan_to_num(nf).tolist(),
        "damping": np.nan_to_num(nz).tolist(),
    }
    modes = ", ".join(f"f{r + 1} = {f:.2f} Hz (zeta {100 * z:.3g} %)"
                      for r, (f, z) in enumerate(zip(table.frequency, table.damping, strict=True)))
    text = f"{ctx.structure.name}: changes in % for +-{args.percent:g} % parameter changes\n{modes}\n" + table.to_text()
    emit(args, data, text)
    return 0


@naming_file("reference", (DataError, ModelError))
def _sobol(ctx: ModelContext, args: argparse.Namespace) -> int:
    from cappe.io import read_modal_data
    from cappe.sensitivity import model_sobol

    if not args.reference:
        msg = "--sobol needs --reference FILE.json (modal data, format cappe.modal/1)"
        raise UsageError(msg)
    reference = read_modal_data(args.reference)
    progress = args.progress or (not args.json and sys.stderr.isatty())
    result = model_sobol(ctx.numeric, reference, parameters=names(args.parameters), n=args.n_gsa, rng=args.seed,
                         criteria=names(args.criteria) or [], progress=progress)
    if args.plot:
        result.plot(args.plot)
    data = result.to_dict()
    significant = result.significant(args.threshold)
    data["significant"] = {k: list(v) for k, v in significant.items()}
    lines = [f"{ctx.structure.name}: Sobol indices of {len(result.sobol.output_names)} outputs, "
             f"{len(result.names)} parameters, N = {args.n_gsa} ({args.n_gsa * (len(result.names) + 2)} model runs "
             f"per position); parameters with ST > {args.threshold:g}:"]
    for output, params in significant.items():
        lines.append(f"  {output:<28} {', '.join(params) if params else '-'}")
    noisy = result.sobol.noise_text()
    if noisy:
        data["noise"] = result.sobol.noise()
        lines.append(f"WARNING: the ST values are {noisy}")
    if args.plot:
        lines.append(f"plot written to {args.plot}")
    emit(args, data, "\n".join(lines))
    return 0
