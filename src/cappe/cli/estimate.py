"""``cappe estimate MODEL --data FILE --method M``: physical parameters from measurements, with uncertainty."""

from __future__ import annotations

import argparse
import inspect
import json
import sys
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from cappe._format import interval_text
from cappe.cli._common import ModelContext, UsageError, add_model_options, emit, names, naming_file, text_pairs


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    from cappe.estimate._registry import METHODS

    p = sub.add_parser("estimate", help="estimate physical parameters from time data, FRFs or modal data")
    add_model_options(p)
    p.add_argument("--data", required=True, metavar="FILE",
                   help="measurements: UFF 58 / CSV / npz time data or FRFs, or cappe.modal/1 JSON")
    p.add_argument("--method", required=True, choices=list(METHODS), help="estimation method")
    p.add_argument("--unknowns", metavar="LIST", help="comma-separated unknowns (default: those marked unknown)")
    p.add_argument("--bounds", metavar="NAME=LO:HI", action="append", default=[],
                   help="bounds of an unknown (repeatable; default from the model file)")
    p.add_argument("--start", metavar="FILE.json", help="start values {name: value}")
    p.add_argument("--seed", type=int, default=0, help="seed for multi-start points and filters (default 0)")
    p.add_argument("--setting", metavar="NAME=VALUE", action="append", default=[],
                   help="method setting, e.g. instruments=model, passes=8, strategy=differential-evolution "
                        "(repeatable; VALUE is JSON or a plain string)")
    p.add_argument("--intersample", choices=["zoh", "foh", "bl"],
                   help="time data: the inputs between samples. Default bl (band-limited), what a DAQ with an "
                        "anti-alias filter records, for one-step and two-step; ekf and ukf: zoh (default) or foh "
                        "(no filter can step a band-limited input); direct needs no assumption")
    p.add_argument("--plot", metavar="FILE.png", help="correlation matrix (EKF/UKF: parameter trajectories)")
    p.add_argument("--plot-landscape", metavar="A,B:FILE.png",
                   help="the method's cost over unknowns A and B around the optimum (least-squares methods)")
    p.add_argument("--plot-residuals", metavar="FILE.png",
                   help="residual analysis as MATLAB's resid: autocorrelation of the output errors and their "
                        "cross-correlation with the inputs, with 99 %% bounds (one-step, time data)")
    p.add_argument("--plot-response", metavar="FILE.png",
                   help="measured vs model response before (start) and after estimation (time data or FRFs)")
    p.set_defaults(func=run)


def load_data(path: str) -> Any:
    """Time data, FRFs or modal data by content."""
    from cappe.io import read_measurements, read_modal_data

    if Path(path).suffix.lower() == ".json":
        return read_modal_data(path)
    return read_measurements(path)


def _bounds(items: list[str]) -> dict[str, tuple[float, float]]:
    out: dict[str, tuple[float, float]] = {}
    for name, rest in text_pairs(items, "--bounds", "NAME=LO:HI").items():
        lo, _, hi = rest.partition(":")
        try:
            out[name] = (float(lo), float(hi))  # a missing ':' leaves hi empty, which float() rejects
        except ValueError as exc:
            msg = f"--bounds must look like NAME=LO:HI; got {name + '=' + rest!r}"
            raise UsageError(msg) from exc
    return out


def settings(items: list[str]) -> dict[str, Any]:
    """``NAME=VALUE`` pairs; VALUE parsed as JSON when it is JSON, else kept as a string."""
    out: dict[str, Any] = {}
    for name, value in text_pairs(items, "--setting", allow_empty=True).items():
        try:
            out[name] = json.loads(value)
        except json.JSONDecodeError:
            out[name] = value
        except (RecursionError, ValueError) as exc:  # nesting or integer digits beyond what Python reads
            msg = f"--setting {name}: the value cannot be read ({type(exc).__name__}: {str(exc)[:80]})"
            raise UsageError(msg) from exc
    return out


def _kind(data: Any) -> str:
    from cappe.systems import FRFData, ModalData, TimeData

    if isinstance(data, TimeData):
        return "time"
    if isinstance(data, FRFData):
        return "frf"
    if isinstance(data, ModalData):
        return "modal"
    return type(data).__name__


def _landscape(option: str) -> tuple[list[str], str]:
    """The two parameters and the file of ``--plot-landscape A,B:FILE.png``."""
    pair, sep, target = option.partition(":")
    axes = names(pair) or []
    if not sep or not target or len(axes) != 2:
        msg = f"--plot-landscape must look like A,B:FILE.png; got {option!r}"
        raise UsageError(msg)
    return axes, target


@naming_file("data")
def run(args: argparse.Namespace) -> int:
    from cappe.estimate._registry import METHODS, estimator_class
    from cappe.io import read_parameters

    if args.plot_landscape:
        _landscape(args.plot_landscape)  # a usage error before the fit, not after it
    ctx = ModelContext(args)
    data = load_data(args.data)
    wanted = METHODS[args.method][2]
    have = _kind(data)
    if have != wanted:
        hint = " (estimate FRFs first with `cappe frf`)" if wanted == "frf" and have == "time" else ""
        msg = f"method {args.method!r} takes {wanted} data; {args.data} holds {have} data{hint}"
        raise UsageError(msg)
    start = read_parameters(args.start) if args.start else None
    cls = estimator_class(args.method)
    options = settings(args.setting)
    takes = inspect.signature(cls.__init__).parameters
    refused: Mapping[str, str] = getattr(cls, "intersample_refused", {})
    if "intersample" in takes and have == "time" and args.intersample in refused:
        msg = f"--intersample {args.intersample} does not apply to method {args.method!r}: {refused[args.intersample]}"
        raise UsageError(msg)
    if "intersample" in takes and have == "time":
        options.setdefault("intersample", args.intersample or getattr(cls, "intersample_default", "bl"))
    elif args.intersample not in (None, "zoh") or (args.intersample and have != "time"):
        msg = (
            f"--intersample {args.intersample} does not apply to method {args.method!r} on {have} data"
            + (" (it models a held input, zoh)" if have == "time" else "")
        )
        raise UsageError(msg)
    if "position" in takes:
        options.setdefault("position", ctx.position)
    elif args.position:  # the modal methods take each set's position from the reference data
        msg = (
            f"--position does not apply to method {args.method!r}: its reference data carry the axis position of "
            "each set"
        )
        raise UsageError(msg)
    try:
        estimator = cls(ctx.numeric, names(args.unknowns), bounds=_bounds(args.bounds) or None, start=start,
                        values=ctx.values, rng=args.seed, **options)
    except TypeError as exc:
        msg = f"--setting: {exc} (method {args.method!r})"
        raise UsageError(msg) from exc
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = estimator.fit(data).estimate_
    shown = set(result.diagnostics.get("warnings", []))  # these print in the text output (and stay in the JSON)
    for w in caught:
        if not any(line in str(w.message) for line in shown):
            print(f"cappe: warning: {w.message}", file=sys.stderr)
    doc = result.to_dict()
    if args.plot_residuals:
        analysis = result.diagnostics.get("residual_analysis")
        if not analysis or "outputs" not in analysis:
            reason = "an exact fit has none" if analysis else f"method {args.method!r} on {have} data has none"
            msg = f"--plot-residuals: no residual analysis to plot ({reason})"
            raise UsageError(msg)
        from cappe.identify import ResidualAnalysis

        ResidualAnalysis.from_dict(analysis).plot(args.plot_residuals, title=f"{result.method}: residual analysis")
        doc["diagnostics"]["plot_residuals"] = args.plot_residuals
    if args.plot:
        _plot(result, args.plot)
        doc["diagnostics"]["plot"] = args.plot
    if args.plot_landscape:
        axes, target = _landscape(args.plot_landscape)
        estimator.cost_slice(axes).plot(target, title=f"{result.method}: cost over {axes[0]} and {axes[1]}")
        doc["diagnostics"]["plot_landscape"] = target
    if args.plot_response:
        _plot_response(ctx, estimator, result, data, args.plot_response)
        doc["diagnostics"]["plot_response"] = args.plot_response
    emit(args, doc, _text(result, args.method))
    return 0 if result.success else 1


def _plot(result: Any, path: str) -> None:
    from cappe.report import correlation_plot, trajectory_plot

    trajectory = result.diagnostics.get("trajectory")
    if trajectory is not None and "time" in trajectory:
        trajectory_plot(np.asarray(trajectory["time"]), np.asarray(trajectory["values"]), list(result.names), path,
                        title=f"{result.method}: parameter trajectories")
    else:
        correlation_plot(result, path)


def _plot_response(ctx: ModelContext, estimator: Any, result: Any, data: Any, path: str) -> None:
    from cappe.report import response_plot
    from cappe.systems import time_response

    kind = _kind(data)
    space = estimator.space_
    before = ctx.numeric.system(space.full(space.start), ctx.position)
    after = ctx.numeric.system(space.full(result.values), ctx.position)
    if kind == "time":
        inputs = [n for n in before.input_names if n in data.channels]
        outputs = [n for n in before.output_names if n in data.channels]
        excitation = data.select(inputs)
        curves = [time_response(system, excitation, outputs=outputs).select(outputs).values
                  for system in (before, after)]
        # the last 400 samples: a whole record of a random test is too dense to compare curves
        window = slice(max(data.n_samples - 400, 0), None)
        response_plot(data.time[window], data.select(outputs).values[:, window], curves[0][:, window],
                      curves[1][:, window], path, labels=outputs,
                      title=f"{result.method}: measured vs model (last {data.time[window].size} samples)")
    elif kind == "frf":
        # one curve per (output, input) pair, outputs major: the row order of H[out, in, freq] flattened
        inputs, outputs = list(data.input_names), list(data.output_names)
        measured, model_before, model_after = (
            np.abs(frf.H).reshape(-1, data.freq.size)
            for frf in (data, before.frf(data.freq, inputs, outputs), after.frf(data.freq, inputs, outputs))
        )
        response_plot(data.freq, measured, model_before, model_after, path,
                      labels=[f"{o}/{i}" for o in outputs for i in inputs],
                      xlabel="frequency (Hz)", log=True, title=f"{result.method}: measured vs model FRFs")
    else:
        msg = "--plot-response needs time data or FRFs; modal data have no response to plot"
        raise UsageError(msg)


def _text(result: Any, method: str) -> str:
    diagnostics = result.diagnostics
    if result.success:
        state = "converged"
    elif diagnostics.get("fit_test") == "failed":
        state = "FAILED (the fit does not explain the data)"
    else:
        state = "NOT converged"
    lines = [f"{method}: {state}{' - ' + result.message if result.message else ''}; cost {result.cost:.4g}"]
    if "intersample" in diagnostics:
        lines.append(f"inputs between samples: {diagnostics['intersample']}")
    lines.append("   parameter          value        std (%)           95 % interval   identifiable")
    for k, name in enumerate(result.names):
        v, s = result.values[k], result.std[k]
        rel = f"{100 * s / abs(v):10.3g}" if np.isfinite(s) and v != 0 else "         -"
        lo, hi = result.ci95[k]
        interval = interval_text(lo, hi, v)
        practical = diagnostics.get("practically_non_identifiable", {})
        flag = "yes" if result.identifiable[k] else f"NO ({practical[name]})" if name in practical else "NO"
        if flag == "yes" and name in diagnostics.get("intersample_dependent", []):
            flag = "depends on intersample"
        lines.append(f"  {name:>10s}  {v:13.6g}  {rel}     {interval:>24s}   {flag}")
    if result.combinations:
        lines.append("undetermined combinations (relative changes): " + "; ".join(result.combinations))
    weakest = diagnostics.get("weakest_direction")
    if isinstance(weakest, dict):
        lines.append(f"practically non-identifiable: the data determine the unknowns except along "
                     f"{weakest['combination']} (relative changes, std {100 * weakest['relative_std']:.3g} %)")
    sensitivity = diagnostics.get("intersample_sensitivity")
    if isinstance(sensitivity, dict) and sensitivity:
        from cappe.estimate._intersample import sensitivity_text

        moves = sensitivity_text(sensitivity, ruled_out=diagnostics.get("intersample_ruled_out"))
        lines.append(f"were the inputs between samples not {diagnostics.get('intersample', '?')}, the estimate would "
                     f"move (largest): {moves}")
    analysis = diagnostics.get("residual_analysis")
    if isinstance(analysis, dict) and "outputs" in analysis:
        white = analysis.get("white", {})
        lines.append(
            f"residual tests ({analysis['samples']} samples, level {analysis['level']:g}): independent of the inputs "
            f"{'yes' if analysis.get('independent') else 'NO'}; white "
            + ", ".join(f"{o} {'yes' if ok else 'NO'}" for o, ok in white.items())
        )
        if isinstance(diagnostics.get("residuals_tested"), str):
            lines.append(f"residuals tested: {diagnostics['residuals_tested']}")
    weighting = diagnostics.get("second_step_weighting")
    if isinstance(weighting, str):
        lines.append(f"second step weighted by: {weighting}")
    second = diagnostics.get("second_step_test")
    if isinstance(second, dict) and second.get("p_value") is not None:
        verdict = "passed" if second["passed"] else "FAILED"
        lines.append(f"second step against step 1's uncertainty: chi2 {second['chi2']:.4g} on {second['dof']} dof, "
                     f"p = {second['p_value']:.3g} (level {second['level']:g}): {verdict}"
                     + ("" if second["passed"] else
                        f"; standard errors scaled by {np.sqrt(second['covariance_scale']):.3g}"))
    covariance = diagnostics.get("covariance")
    if isinstance(covariance, dict) and "kind" in covariance:
        lines.append(f"intervals: {covariance['kind']} over {covariance.get('lags', '?')} lags (the residuals are "
                     "correlated in time; the Gauss-Newton standard errors are in the JSON)")
    lines += [f"WARNING: {line}" for line in diagnostics.get("warnings", [])]
    return "\n".join(lines)
