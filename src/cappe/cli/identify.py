"""``cappe identify MODEL --reference ref.json``: the automated GSA-guided identification (paper 2022).

Stages (progress bars on stderr when it is a terminal, or with ``--progress``): GSA, stiffness subproblems,
joint refinements, damping least squares, validation. Prints the parameter table (estimate, uncertainty, truth
and error when ``--truth`` is given), the validation statistics and the runtime per stage; ``-o`` writes
cappe.estimate/1, ``--report`` a self-contained HTML report.
"""

from __future__ import annotations

import argparse
import math
import sys
import warnings
from typing import TYPE_CHECKING, Any

import numpy as np

from cappe.cli._common import UsageError, add_deprecated, add_output_options, emit, names, number_pairs

if TYPE_CHECKING:
    from cappe.estimate import AutomatedResult, ParameterEstimate


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "identify",
        help="automated identification of all unknowns from reference modes at axis positions (GSA-guided)",
        description=(
            "GSA over all unknowns, stiffness by repeated local searches per mode-position subproblem, damping by "
            "linear least squares on modal damping contributions, joint refinement, and validation at a held-out "
            "position (Ellinger & Zaeh 2022)."
        ),
    )
    p.add_argument("model", metavar="MODEL", help="model YAML file or builtin:NAME")
    p.add_argument("--reference", required=True, nargs="+", metavar="FILE.json",
                   help="reference modes (cappe.modal/1), one file per axis position or one file with several sets; "
                        "the sets of all files are one reference, told apart by their 'position' (two sets at one "
                        "position are an error), at the sensors the files share")
    p.add_argument("--sensor-map", metavar="MAP.csv",
                   help="CSV 'channel,sensor' naming the model sensor channel of each reference sensor label and --frf "
                        "channel (e.g. 5:-z,table_fl:z); negative measured directions are flipped; reference files "
                        "already at the map's model channels (extract-modes --sensor-map) are kept as they are")
    p.add_argument("--frf", nargs="+", metavar="FILE.uff",
                   help="measured FRFs (UFF 58, CSV or .npz), one file per reference position, in the order of the "
                        "reference sets (or placed by --frf-position); channels mapped by --sensor-map. At "
                        "identification positions every unknown is refined against them after the modal stages "
                        "(complex-log residuals weighted by the data's own noise); at the validation position FRAC "
                        "and CSF compare the model with them (unless --truth is given)")
    p.add_argument("--frf-position", nargs="+", metavar="AXIS=VALUE,...",
                   help="the axis position of each --frf file, in their order (default: the reference sets' order)")
    p.add_argument("--validation", metavar="AXIS=VALUE,...",
                   help="position held out for validation, e.g. z=-0.294; 'none' to identify from every position "
                        "(default: the reference's first position when it has two or more)")
    p.add_argument("--truth", metavar="FILE.json", help="true parameters of a simulated reference {name: value}")
    p.add_argument("--params", metavar="FILE.json", help="values of known parameters {name: value} (SI)")
    p.add_argument("--set", dest="overrides", metavar="NAME=VALUE", action="append", default=[],
                   help="value of a known parameter (repeatable)")
    p.add_argument("--unknowns", metavar="LIST", help="comma-separated unknowns (default: those marked unknown)")
    p.add_argument("--n-gsa", type=int, default=1024, help="Sobol base sample size, a power of two (default 1024)")
    p.add_argument("--n-opt", type=int, default=100, help="local searches per subproblem (default 100)")
    p.add_argument("--threshold", type=float, default=0.01, help="significance threshold on ST (default 0.01)")
    for quantity, example in (("frequency", 0.005), ("damping", 0.05), ("shape", 0.02)):
        p.add_argument(f"--noise-{quantity}", type=float, metavar="REL",
                       help=f"relative noise of the reference's {quantity} values (e.g. {example}; as in cappe "
                            "simulate): with all three, the final refinement is weighted by them")
    add_deprecated(p, "--noise", dest="noise", instead="--noise-frequency F --noise-damping Z --noise-shape S",
                   metavar="F,Z,S")
    p.add_argument("--known-tolerance", dest="known_tolerance", action="append", default=[],
                   metavar="REL|NAME=REL",
                   help="relative standard deviation of known parameters (0.1: 10 %%), which the 95 %% intervals "
                        "then include (consider covariance): REL for every parameter the model tags disturbable, "
                        "NAME=REL for any known one (repeatable; NAME=REL overrides REL). A parameter known to "
                        "+-10 %% (uniform, or +-10 %% with either sign) has a standard deviation of at most 0.1, so "
                        "0.1 is safe; without the option the intervals assume the known parameters exact")
    p.add_argument("--shapes", choices=("real", "complex"), default="real",
                   help="shapes the final refinement compares: realized model and reference shapes (real part at "
                        "their principal phase: blind to mode complexity that an LSCF/LSFD fit of hysteretically "
                        "damped FRFs cannot reproduce; default), or complex shapes as they are")
    p.add_argument("--first-order", action="store_true",
                   help="final refinement on first-order modes (for first-order references) instead of exact ones")
    p.add_argument("--permutations", type=int, default=10,
                   help="random damping reassignments of the permuted-damping comparison (default 10)")
    p.add_argument("--overlay", metavar="OUT,IN",
                   help="sensor channels of the FRF shown in the report, e.g. table:x,table:x (default: the driving "
                        "point with the largest peak)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--workers", type=int, help="threads or processes (default: one per core)")
    p.add_argument("--executor", choices=("serial", "threads", "processes"), default="threads",
                   help="where the GSA, the subproblems and the validations run (default threads; the result is "
                        "the same)")
    p.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                   help="run the GSA, the subproblems and the validations on an existing Dask cluster (overrides "
                        "--executor; the result is the same)")
    p.add_argument("--progress", action="store_true", help="progress bars even when stderr is not a terminal")
    p.add_argument("--report", metavar="FILE.html", help="write a self-contained HTML report")
    add_output_options(p)
    p.set_defaults(func=run)


def _position(value: str | None, reference: Any) -> dict[str, float] | None:
    if value is None:
        return dict(reference.sets[0].position) if len(reference.sets) >= 2 else None
    if value.strip().lower() == "none":
        return None
    return number_pairs([v for v in value.split(",") if v.strip()], "--validation")


def _noise(args: argparse.Namespace) -> tuple[float, float, float] | None:
    """The reference's relative noise (frequency, damping, shape): the three options, or the deprecated --noise."""
    given = {q: getattr(args, f"noise_{q}") for q in ("frequency", "damping", "shape")}
    if args.noise is not None:
        if any(v is not None for v in given.values()):
            msg = "give either --noise-frequency/--noise-damping/--noise-shape or the deprecated --noise F,Z,S"
            raise UsageError(msg)
        try:
            levels = tuple(float(v) for v in args.noise.split(","))
        except ValueError:
            levels = ()
        if len(levels) != 3 or not all(math.isfinite(v) and v > 0 for v in levels):
            msg = f"--noise must be three numbers > 0 like 0.005,0.05,0.02; got {args.noise!r}"
            raise UsageError(msg)
        return (levels[0], levels[1], levels[2])
    if all(v is None for v in given.values()):
        return None
    missing = [f"--noise-{q}" for q, v in given.items() if v is None]
    if missing:
        msg = f"the refinement is weighted by all three noise levels; {', '.join(missing)} missing"
        raise UsageError(msg)
    bad = {f"--noise-{q}": v for q, v in given.items() if not (math.isfinite(v) and v > 0)}
    if bad:
        msg = f"noise levels must be > 0; got {bad}"
        raise UsageError(msg)
    return (given["frequency"], given["damping"], given["shape"])


def known_tolerance(items: list[str], structure: Any, unknowns: list[str]) -> dict[str, float]:
    """The --known-tolerance entries as ``{known parameter: relative standard deviation}``: a bare REL for every
    known parameter the model tags disturbable, NAME=REL for the one named (overriding the bare value)."""
    bare: float | None = None
    named: dict[str, float] = {}
    for item in items:
        name, sep, value = item.rpartition("=")
        try:
            rel = float(value)
        except ValueError:
            rel = math.nan
        if not (math.isfinite(rel) and rel >= 0):
            msg = (f"--known-tolerance {item!r}: the tolerance must be a relative standard deviation >= 0 like 0.1; "
                   f"got {value!r}")
            raise UsageError(msg)
        if not sep:
            bare = rel
            continue
        name = name.strip()
        if name not in structure.parameter_names:
            msg = f"--known-tolerance {item!r}: {name!r} is not a parameter of {structure.name}"
            raise UsageError(msg)
        if name in unknowns:
            msg = f"--known-tolerance {item!r}: {name!r} is an unknown of this identification, not a known parameter"
            raise UsageError(msg)
        named[name] = rel
    out: dict[str, float] = {}
    if bare is not None:
        tagged = [p.name for p in structure.parameters if p.disturbable and p.name not in unknowns]
        if not tagged:
            msg = (f"--known-tolerance {bare:g}: {structure.name} tags no known parameter disturbable; name them as "
                   "NAME=REL")
            raise UsageError(msg)
        out = dict.fromkeys(tagged, bare)
    out.update(named)
    return out


def combined_reference(paths: list[str], sensor_map: str | None = None) -> tuple[Any, list[str]]:
    """The sets of several cappe.modal/1 files as one reference, and the lines a user should see about it.

    Sets are told apart by their position; the files' sensors are renamed by ``sensor_map`` (negative measured
    directions flipped) and reduced to those every file has.
    """
    from dataclasses import replace

    from cappe.exceptions import DataError
    from cappe.io import read_modal_data
    from cappe.io.sensor_map import channel_sign, map_modal_data, read_sensor_map
    from cappe.systems.modal import ModalData

    mapping = read_sensor_map(sensor_map) if sensor_map else None
    notes: list[str] = []
    parts = []
    targets = {channel_sign(v)[0] for v in mapping.values()} if mapping else set()
    for path in paths:
        data = read_modal_data(path)
        more: list[str] = []
        # a file extract-modes wrote with this map is at the model's channels already (the map is there for --frf)
        if mapping is None or not all(s in targets for s in data.sensors):
            data, more = map_modal_data(data, mapping, sensor_map or "")
        notes += [f"{path}: {line}" for line in more]
        parts.append((path, data))
    common = [s for s in parts[0][1].sensors if all(s in d.sensors for _, d in parts[1:])]
    if not common:
        msg = f"the reference files {paths} share no sensor channel"
        raise DataError(msg)
    sets = []
    seen: dict[tuple[tuple[str, float], ...], str] = {}
    for path, data in parts:
        rows = [data.sensors.index(s) for s in common]
        if len(rows) < len(data.sensors):
            notes.append(f"warning: {path}: {len(data.sensors) - len(rows)} sensor(s) that the other reference "
                         "files lack are left out")
        for k, data_set in enumerate(data.sets):
            key = tuple(sorted(data_set.position.items()))
            if key in seen:
                msg = (f"{path}, sets[{k}]: position {data_set.position} is already given by {seen[key]}; each "
                       "position must come once (record it with cappe extract-modes --position)")
                raise DataError(msg)
            seen[key] = f"{path}"
            sets.append(replace(data_set, shapes=data_set.shapes[rows]))
    source = paths[0] if len(paths) == 1 else ", ".join(paths)
    return ModalData(tuple(common), tuple(sets), source), notes


def measured_frfs(paths: list[str] | None, positions: list[str] | None, reference: Any,
                  sensor_map: str | None = None) -> tuple[list[Any], list[str]]:
    """The --frf files as MeasuredFRF at model sensor channels (the sensor map applied), each at its position: the
    --frf-position given for it, else the position of the reference set of the same rank; and the notes a user
    should see."""
    from cappe.estimate._frf_refinement import MeasuredFRF
    from cappe.exceptions import DataError
    from cappe.io import read_frf
    from cappe.io.sensor_map import apply_sensor_map, read_sensor_map

    if not paths:
        if positions:
            msg = "--frf-position needs --frf files"
            raise UsageError(msg)
        return [], []
    if positions is not None and len(positions) != len(paths):
        msg = f"--frf-position gives {len(positions)} positions for {len(paths)} --frf files; give one per file"
        raise UsageError(msg)
    if positions is None and len(paths) > len(reference.sets):
        msg = (f"--frf gives {len(paths)} files but the reference has {len(reference.sets)} positions; place them "
               "with --frf-position")
        raise UsageError(msg)
    mapping = read_sensor_map(sensor_map) if sensor_map else None
    out, notes = [], []
    for k, path in enumerate(paths):
        where = (number_pairs([v for v in positions[k].split(",") if v.strip()], "--frf-position")
                 if positions is not None else dict(reference.sets[k].position))
        try:
            data, more = apply_sensor_map(read_frf(path), mapping, sensor_map or "")
        except DataError as exc:
            if path in str(exc):  # the reader's message names the file already
                raise
            msg = f"{path}: {exc}"
            raise DataError(msg) from exc
        notes += [f"{path}: {line}" for line in more]
        out.append(MeasuredFRF(dict(where), data, path))
    return out, notes


def run(args: argparse.Namespace) -> int:
    from cappe.estimate._automated import AutomatedIdentification
    from cappe.io import read_parameters
    from cappe.model import NumericModel, load_model

    for option, value, low in (("--n-gsa", args.n_gsa, 2), ("--n-opt", args.n_opt, 1),
                               ("--permutations", args.permutations, 0)):
        if value < low:
            msg = f"{option} must be >= {low}; got {value}"
            raise UsageError(msg)
    if args.scheduler is not None and "://" not in args.scheduler:
        msg = f"--scheduler must be a Dask scheduler address like tcp://HOST:PORT; got {args.scheduler!r}"
        raise UsageError(msg)
    if args.workers is not None and args.workers < 1:
        msg = f"--workers must be >= 1; got {args.workers}"
        raise UsageError(msg)
    structure = load_model(args.model)
    values: dict[str, float] = {}
    if args.params:
        values.update(read_parameters(args.params))
    values.update(number_pairs(args.overrides, "--set"))
    structure.resolve_parameters(values)  # unknown names are an error here
    truth = read_parameters(args.truth) if args.truth else None
    if truth is not None:
        structure.resolve_parameters(truth)
    unknowns = names(args.unknowns) or [p.name for p in structure.parameters if p.unknown]
    tolerance = known_tolerance(args.known_tolerance, structure, unknowns)
    if tolerance and args.first_order:
        msg = "--known-tolerance needs the exact-mode refinement (leave out --first-order)"
        raise UsageError(msg)
    if args.first_order and _noise(args) is not None:
        msg = ("--noise-frequency/--noise-damping/--noise-shape (or --noise) weight the exact-mode refinement: leave "
               "out --first-order, or the noise options")
        raise UsageError(msg)
    reference, notes = combined_reference(args.reference, args.sensor_map)
    measured, frf_notes = measured_frfs(args.frf, args.frf_position, reference, args.sensor_map)
    notes += frf_notes
    validation = _position(args.validation, reference)
    if args.validation is None and validation is not None:
        notes.append(f"validation position {validation} chosen by default (the reference's first set); "
                     "choose it with --validation")
    progress = bool(args.progress or sys.stderr.isatty())
    overlay = None
    if args.overlay:
        pair = names(args.overlay) or []
        if len(pair) != 2:
            msg = f"--overlay must look like OUT,IN (two sensor channels); got {args.overlay!r}"
            raise UsageError(msg)
        overlay = (pair[0], pair[1])
    estimator = AutomatedIdentification(
        NumericModel(structure), names(args.unknowns), values=values or None, rng=args.seed, n_gsa=args.n_gsa,
        n_opt=args.n_opt, threshold=args.threshold, validation=validation, n_permutations=args.permutations,
        exact=not args.first_order, noise=_noise(args), n_workers=args.workers,
        executor=args.scheduler or args.executor, shapes=args.shapes, frf=measured or None,
        known_tolerance=tolerance or None,
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        estimator.fit(reference, truth=truth, overlay=overlay, progress=progress)
    for line in notes:
        print(f"cappe: {line}", file=sys.stderr)
    for w in caught:
        print(f"cappe: warning: {w.message}", file=sys.stderr)
    result = estimator.result_
    doc = result.to_dict()
    if args.report:
        from cappe.report.html import write_html_report

        write_html_report(args.report, result=result, truth=truth, title=f"{structure.name}: automated identification",
                          model=structure, run=_run_record(args))
        doc["diagnostics"]["report"] = args.report
    text = summary_text(result, truth, structure.name)
    if args.report:
        text += f"\nreport written to {args.report}"
    if args.out:
        text += f"\nresult (cappe.estimate/1) written to {args.out}"
    emit(args, doc, text)
    return 0 if result.estimate.success else 1


def _row_stats(label: str, stats: dict[str, dict[str, float]]) -> list[str]:
    lines = [f"{label}:", f"  {'':<16}{'FRAC %':>10}{'CSF %':>10}{'MACXP %':>10}{'NDD %':>10}"]
    for key, title in (("worst", "worst"), ("p5", "5 % tail"), ("mean", "mean"), ("median", "median")):
        cells = "".join(f"{100 * v:>10.2f}" if v is not None and np.isfinite(v) else f"{'-':>10}"
                        for v in (stats[c][key] for c in ("frac", "csf", "macxp", "ndd")))
        lines.append(f"  {title:<16}{cells}")
    return lines


def summary_text(result: AutomatedResult, truth: dict[str, float] | None, model_name: str) -> str:
    """The printed summary of an automated identification (also used by ``cappe demo``)."""
    estimate, settings = result.estimate, result.settings
    lines = [f"{model_name}: automated identification of {len(estimate.names)} unknowns "
             f"(n_gsa {settings.n_gsa}, n_opt {settings.n_opt}, threshold {settings.threshold})",
             f"identification positions: {_where_all(result.identification_positions)}; "
             f"validation position: {_where(result.validation_position, 'none held out')}"]
    lines += _parameter_rows(estimate, truth)
    lines.append("costs: " + ", ".join(f"{k} {v:.4g}" for k, v in result.costs.items() if v is not None))
    frf = result.frf
    if frf is not None:
        lines.append(f"refined against measured FRFs at {_where_all(p['position'] for p in frf.positions)}: "
                     f"{frf.n_residuals} residuals (complex log: log-magnitude and phase) on "
                     f"{', '.join(str(p['lines']) for p in frf.positions)} lines, weighted by {frf.noise}")
        lines.append(f"  FRF residual / data noise: chi2/dof {frf.chi2_dof:.3g} (1: a fit down to the noise); "
                     f"cost {frf.cost_before:.4g} at the modal estimate -> {frf.cost_after:.4g}")
    joint = result.joint
    if frf is not None:
        lines.append(f"uncertainty: {frf.uncertainty}; 95 % intervals on a log scale; FRF residuals weighted by the "
                     "data's own noise")
    elif joint.uncertainty is not None:
        lines.append(f"uncertainty: {joint.uncertainty}; 95 % intervals on a log scale; residuals "
                     f"weighted by {joint.weighting or 'the weights'}, {joint.shapes or 'complex'} shapes")
    known = estimate.diagnostics.get("uncertainty", {}).get("known")
    if known:
        lines.append(_known_line(estimate, known))
    lines += _assumed_exact_note(result)
    val = result.validation
    if val.held is not None:
        lines += _row_stats(f"validation at {_where(val.held.position)}", val.held.statistics())
        if val.held.frf_source == "measured FRFs":
            lines.append(f"  (FRAC and CSF against the measured FRFs: {len(val.held.outputs)} outputs x "
                         f"{len(val.held.inputs)} references, {val.held.freq.size} lines "
                         f"{val.held.freq[0]:.4g}-{val.held.freq[-1]:.4g} Hz)")
        elif val.held.frf_source != "truth":
            lines.append(f"  (FRAC and CSF from a modal synthesis over the {val.held.reference_frequency.size} "
                         "reference modes, not from measured FRFs: modes outside the reference band and residual "
                         "terms are left out)")
    pooled = val.identification_statistics()
    if pooled:
        lines += _row_stats("identification positions", pooled)
    if val.permuted:
        means = {c: float(np.mean([p.statistics()[c]["mean"] for p in val.permuted])) for c in
                 ("frac", "csf", "macxp", "ndd")}
        lines.append(f"permuted damping ({len(val.permuted)} reassignments), mean: "
                     + ", ".join(f"{c.upper()} {100 * v:.2f} %" for c, v in means.items()))
    cpu = f"; CPU: {', '.join(f'{k} {v:.2f} s' for k, v in result.cpu_timings.items())}" if result.cpu_timings else ""
    lines.append("runtime: " + ", ".join(f"{k} {v:.2f} s" for k, v in result.timings.items()) + cpu)
    if not estimate.success:
        lines.append(f"not converged: {estimate.message}")
    lines += [f"warning: {w.partition(': ')[2] or w}" for w in result.warnings]
    return "\n".join(lines)


#: A widening beyond this is printed as "more than" it: the fit's own scatter is then negligible (an exact,
#: noise-free reference gives factors of millions that mean nothing to a reader).
WIDENING_SHOWN = 1000.0


def _known_line(estimate: ParameterEstimate, known: dict[str, Any]) -> str:
    """The line saying which known parameters' uncertainty the intervals include and how much it widens them."""
    tol = sorted(set(known["parameters"].values()))
    level = " or ".join(f"{100 * v:.3g} %" for v in tol[:3]) + (" ..." if len(tol) > 3 else "")
    factor = float(known["largest_widening"])
    if factor <= WIDENING_SHOWN:
        wider = f"intervals up to {factor:.3g} x wider"
    else:
        wider = f"intervals up to more than {WIDENING_SHOWN:g} x wider: the fit's own scatter is negligible beside it"
    count = len(known["parameters"])
    whose = "parameters'" if count > 1 else "parameter's"
    return (f"  including {count} known {whose} uncertainty (relative std {level}, "
            f"consider covariance): {wider} ({_widest(estimate, known)})")


def _widest(estimate: ParameterEstimate, known: dict[str, Any]) -> str:
    """The unknown whose interval the known parameters widen most, with its relative std without and with them."""
    name = known["largest_widening_parameter"]
    k = list(estimate.names).index(name)
    value = abs(float(estimate.values[k]))
    return f"{name}: std {100 * known['std_without'][k] / value:.2g} % -> {100 * float(estimate.std[k]) / value:.3g} %"


def _assumed_exact_note(result: AutomatedResult) -> list[str]:
    """A note where the intervals take known parameters as exact that the model tags disturbable."""
    exact = list(result.known_assumed_exact)
    if not exact:
        return []
    if not result.settings.known_tolerance:
        return [f"note: the intervals assume the known parameters exact ({len(exact)} tagged disturbable); "
                "--known-tolerance REL includes their uncertainty"]
    listed = ", ".join(exact[:6]) + (" ..." if len(exact) > 6 else "")
    more = f"{len(exact)} more known parameter{'s' if len(exact) > 1 else ''}"
    return [f"note: the intervals assume {more} exact that the model tags disturbable ({listed}); "
            "--known-tolerance REL or NAME=REL includes that uncertainty too"]


def _run_record(args: argparse.Namespace) -> dict[str, Any]:
    """What the report's run section names: the command, the seed and every file the run read."""
    run: dict[str, Any] = {"command": "cappe " + " ".join(sys.argv[1:]), "seed": args.seed,
                           "input files": [args.model, *args.reference]}
    for key, value in (("measured FRFs", args.frf), ("sensor map", args.sensor_map), ("truth", args.truth),
                       ("known parameters", args.params)):
        if value:
            run[key] = value
    return run


def _where(position: Any, missing: str = "-") -> str:
    """An axis position as ``z = -0.294`` (``missing`` for None, 'the one configuration' for a model without axes)."""
    if position is None:
        return missing
    if not position:
        return "the one configuration (no axes)"
    return ", ".join(f"{axis} = {float(value):g}" for axis, value in dict(position).items())


def _where_all(positions: Any) -> str:
    listed = [_where(p) for p in positions]
    return "; ".join(listed) if listed else "none"


def _parameter_rows(estimate: ParameterEstimate, truth: dict[str, float] | None) -> list[str]:
    """The parameter table: estimate and relative standard error, with the truth and the error when known."""
    header = f"  {'parameter':<12}{'estimate':>13}{'std %':>9}"
    if truth is not None:
        header += f"{'truth':>13}{'error %':>10}"
    lines = [header]
    errors = []
    for k, name in enumerate(estimate.names):
        value = float(estimate.values[k])
        std = float(estimate.std[k])
        row = f"  {name:<12}{value:>13.5g}{(100 * std / abs(value) if np.isfinite(std) and value else math.nan):>9.3g}"
        if truth is not None and name in truth:
            err = 100 * (value / truth[name] - 1)
            errors.append(abs(err))
            row += f"{truth[name]:>13.5g}{err:>+10.3f}"
        lines.append(row)
    if errors:
        lines.append(f"  worst |error| {max(errors):.3g} %")
    undetermined = [n for k, n in enumerate(estimate.names)
                    if not (np.isfinite(estimate.std[k]) and estimate.identifiable[k])]
    if undetermined:  # a nan in the std column alone was the only sign of it (issue 24's three-axis run)
        said = f"; least determined: {'; '.join(estimate.combinations)}" if estimate.combinations else ""
        lines.append(f"warning: the data do not determine {', '.join(undetermined)} (no finite or usable standard "
                     f"error): their values are one of many that fit as well{said}")
    return lines
