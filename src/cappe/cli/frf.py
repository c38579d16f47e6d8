"""``cappe frf DATA --input CH --output CH...``: FRF estimation (H1, H2, Hv) with coherence from time data."""

from __future__ import annotations

import argparse
import sys
import warnings
from typing import Literal

import numpy as np

from cappe.cli._common import FRF_OUT, UsageError, add_deprecated, add_output_options, band, channels, emit, naming_file


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser("frf", help="estimate FRFs with coherence from measured time data (UFF 58, CSV, npz)")
    p.add_argument("data", metavar="DATA", help="time data file (UFF 58, CSV with a time column, or .npz)")
    p.add_argument("--inputs", metavar="LIST", help="input (force) channels, comma-separated (required)")
    p.add_argument("--outputs", metavar="LIST", help="output (response) channels, comma-separated (required)")
    add_deprecated(p, "--input", dest="inputs", instead="--inputs A,B", join=True, nargs="+", metavar="CH")
    add_deprecated(p, "--output", dest="outputs", instead="--outputs A,B", join=True, nargs="+", metavar="CH")
    p.add_argument("--estimator", choices=["H1", "H2", "Hv"], default="H1", help="FRF estimator (default H1)")
    p.add_argument("--nperseg", type=int, help="samples per segment (line spacing fs/nperseg); default 8 averages")
    p.add_argument("--overlap", type=float,
                   help="with --nperseg: segment overlap fraction (default 0.5; without --nperseg, 8 averages at 0.5)")
    p.add_argument("--window", default=None, help="segment window, e.g. hann, hamming, boxcar (default hann)")
    p.add_argument("--impact", action="store_true", help="impact test: one record per hit, force window")
    p.add_argument("--exp-window", metavar="TAU", help="impact: exponential window time constant in s, or auto/none")
    p.add_argument("--band", metavar="LO:HI", help="keep and check only this band in Hz")
    p.add_argument("--coherence-threshold", type=float, default=0.8, help="coherence warning level (default 0.8)")
    p.add_argument("--plot", metavar="FILE.png", help="plot magnitude, phase and coherence")
    add_output_options(p, FRF_OUT)
    p.set_defaults(func=run)
    p.epilog = "-o writes the FRFs: .uff/.unv (UFF 58), .csv (re/im pairs) or .npz, by extension."


@naming_file("data")
def run(args: argparse.Namespace) -> int:
    from cappe.identify import coherence_summary, estimate_frf
    from cappe.io import read_time_data, write_frf

    inputs, outputs = channels(args.inputs, "--inputs"), channels(args.outputs, "--outputs")
    data = read_time_data(args.data)
    exp_window: float | Literal["auto"] | None = "auto"
    if args.exp_window is not None:
        if args.exp_window in ("auto", "none"):
            exp_window = None if args.exp_window == "none" else "auto"
        else:
            try:
                exp_window = float(args.exp_window)
            except ValueError as exc:
                msg = f"--exp-window must be a time constant in s, 'auto' or 'none'; got {args.exp_window!r}"
                raise UsageError(msg) from exc
    if args.overlap is not None and (args.impact or not args.nperseg):
        # the default segmentation (8 averages at 50 %) and the impact records (one per hit) take no overlap
        msg = ("--overlap does not apply to --impact (one record per hit)" if args.impact else
               "--overlap needs --nperseg (without it the record is cut into 8 averages at 50 % overlap)")
        raise UsageError(msg)
    noverlap = int(args.overlap * args.nperseg) if args.overlap is not None else None
    lo_hi = band(args.band) if args.band else None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        frf = estimate_frf(
            data, inputs=inputs, outputs=outputs, estimator=args.estimator, nperseg=args.nperseg,
            noverlap=noverlap, window=args.window, impact=args.impact, exponential_window=exp_window,
            band=lo_hi, coherence_threshold=args.coherence_threshold,
        )
    for w in caught:
        print(f"cappe: warning: {w.message}", file=sys.stderr)
    summary = coherence_summary(frf, threshold=args.coherence_threshold, band=lo_hi)
    df = float(frf.freq[1] - frf.freq[0]) if frf.freq.size > 1 else 0.0
    result = {
        "data": args.data,
        "estimator": args.estimator,
        "inputs": list(frf.input_names),
        "outputs": list(frf.output_names),
        "n_lines": int(frf.freq.size),
        "resolution": df,
        "frequency_range": [float(frf.freq[0]), float(frf.freq[-1])],
        "window_decay": frf.window_decay,
        "coherence": summary.to_dict(),
        "warnings": [str(w.message) for w in caught],
    }
    lines = [
        f"{args.estimator} FRFs of {len(frf.output_names)} output(s) x {len(frf.input_names)} input(s): "
        f"{frf.freq.size} lines, {frf.freq[0]:g}-{frf.freq[-1]:g} Hz, resolution {df:.4g} Hz",
    ]
    single = frf.coherence is not None and bool(np.all(np.abs(frf.coherence - 1.0) < 1e-9))
    result["single_record"] = single
    if single:
        lines.append("coherence is 1 on every line: one record (one hit) has no averaging to judge noise by")
    else:
        lines.append(f"coherence below {args.coherence_threshold:g} (fraction of lines, minimum at):")
    for o, out in enumerate(frf.output_names if not single else ()):
        for i, inp in enumerate(frf.input_names):
            lines.append(
                f"  {out}/{inp}: {100 * summary.fraction_below[o, i]:.1f} %, min {summary.minimum[o, i]:.3f} "
                f"at {summary.freq_of_minimum[o, i]:.4g} Hz"
            )
    if frf.window_decay is not None:
        lines.append(f"exponential window tau = {frf.window_decay:.4g} s (extract-modes removes its damping)")
    if args.out:
        write_frf(args.out, frf)
        result["out"] = args.out
        lines.append(f"wrote {args.out}")
    if args.plot:
        from cappe.report import frf_plot

        frf_plot(frf, args.plot, coherence_threshold=args.coherence_threshold)
        result["plot"] = args.plot
    emit(argparse.Namespace(**{**vars(args), "out": None}), result, "\n".join(lines))
    return 0
