"""``cappe extract-modes FRF --band LO:HI``: poles by (poly-reference) LSCF, automatic selection, LSFD shapes."""

from __future__ import annotations

import argparse
from dataclasses import replace

from cappe.cli._common import (
    UsageError,
    add_output_options,
    band,
    emit,
    names,
    naming_file,
    number_pairs,
    text_pairs,
)


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "extract-modes",
        help="modal parameters from measured FRFs: LSCF stabilization diagram, pole clustering, LSFD mode shapes",
    )
    p.add_argument("frf", metavar="FRF", help="FRF file (UFF 58, CSV with re/im pairs, or .npz)")
    p.add_argument("--band", required=True, metavar="LO:HI", help="frequency band in Hz, e.g. 10:500")
    p.add_argument("--max-order", type=int, default=40, help="highest model order of the diagram (default 40)")
    p.add_argument("--n-modes", type=int, help="keep the N best-supported physical poles (default: all found)")
    p.add_argument("--method", choices=["plscf", "lscf"], default="plscf",
                   help="poly-reference (default) or common-denominator LSCF")
    p.add_argument("--near", metavar="HZ,...", help="select the poles nearest these frequencies instead of clustering")
    p.add_argument("--driving-point", metavar="INPUT=OUTPUT", action="append", default=[],
                   help="driving-point pair for mass-normalized shapes (repeatable)")
    p.add_argument("--sensor", metavar="OUTPUT=NODE:DIR", action="append", default=[],
                   help="label an FRF output as a sensor DOF for the mode shapes, e.g. d1=n1:x (repeatable)")
    p.add_argument("--reference-side", choices=["auto", "inputs", "outputs"], default="auto",
                   help="references of the estimator: the measured inputs, or the outputs by reciprocity (roving "
                        "hammer: shapes at the hammer points); auto (default) takes the side with fewer channels")
    p.add_argument("--bootstrap", type=int, default=10, metavar="N",
                   help="bootstrap replicates for the standard deviations of frequency, damping and shapes, widened "
                        "by t_0.975(N)/1.96 for their number (default 10; 0 skips them)")
    p.add_argument("--sensor-map", metavar="MAP.csv",
                   help="CSV 'channel,sensor' naming the model sensor channel of each measured channel (e.g. "
                        "5:-z,table_fl:z); a negative measured direction is flipped to the model's positive one; "
                        "channels not in the map are left out")
    p.add_argument("--position", metavar="AXIS=VALUE", action="append", default=[],
                   help="axis position of the measurement, recorded in the modal file, e.g. z=0.135 (repeatable "
                        "or comma-separated)")
    p.add_argument("--uff", metavar="FILE.uff", help="also write the modes as UFF 55 (outputs must be NODE:DIR)")
    p.add_argument("--plot", metavar="FILE.png", help="stabilization diagram with the selected poles")
    add_output_options(p)
    p.set_defaults(func=run)


@naming_file("frf")
def run(args: argparse.Namespace) -> int:
    from cappe.identify import extract_modes
    from cappe.io import read_frf, write_modal_data, write_uff_modal
    from cappe.io.sensor_map import apply_sensor_map, map_channels, read_sensor_map

    frf = read_frf(args.frf)
    labels = text_pairs(args.sensor, "--sensor", "OUTPUT=NODE:DIR")
    # by reciprocity (a roving hammer) the shapes are at the inputs: --sensor may label inputs as well
    unknown = sorted(set(labels) - set(frf.output_names) - set(frf.input_names))
    if unknown:
        msg = (f"--sensor names channels {unknown} that {args.frf} lacks; its outputs are "
               f"{list(frf.output_names)}, its inputs {list(frf.input_names)}")
        raise UsageError(msg)
    if args.sensor_map and labels:
        msg = "give either --sensor-map or --sensor, not both"
        raise UsageError(msg)
    if args.bootstrap < 0 or args.bootstrap == 1:
        msg = f"--bootstrap must be 0 (no standard deviations) or at least 2; got {args.bootstrap}"
        raise UsageError(msg)
    position = number_pairs([v for item in args.position for v in item.split(",") if v.strip()], "--position")
    # a sensor map, or the --sensor labels (every other channel as it is): a negative measured direction is
    # flipped to the model's positive direction, never kept (issue 20)
    mapping = read_sensor_map(args.sensor_map) if args.sensor_map else \
        {name: labels.get(name, name) for name in (*frf.output_names, *frf.input_names)}
    original = (*frf.output_names, *frf.input_names)
    renamed = dict(zip(original, (s or n for (s, _), n in zip(map_channels(original, mapping), original,
                                                               strict=True)), strict=True))
    frf, notes = apply_sensor_map(frf, mapping, args.sensor_map or "")
    shape_points = frf.input_names if _reciprocal(frf, args.reference_side) else frf.output_names
    unlabelled = [name for name in shape_points if ":" not in name]
    if args.uff and unlabelled:
        msg = (f"--uff needs every FRF output as a NODE:DIR sensor label; label {unlabelled} with "
               f"--sensor OUTPUT=NODE:DIR (e.g. --sensor {unlabelled[0]}=n1:x)")
        raise UsageError(msg)
    lo_hi = band(args.band)
    near = names(args.near)
    try:
        selection: str | list[float] = [float(v) for v in near] if near else "auto"
    except ValueError as exc:
        msg = f"--near must be a comma-separated list of frequencies in Hz; got {args.near!r}"
        raise UsageError(msg) from exc
    pairs = text_pairs(args.driving_point, "--driving-point", "INPUT=OUTPUT")
    driving = {renamed.get(inp, inp): renamed.get(out, out) for inp, out in pairs.items()}
    result = extract_modes(
        frf, band=lo_hi, max_order=args.max_order, n_modes=args.n_modes, method=args.method,
        selection=selection, driving_points=driving or None, reference_side=args.reference_side,
        n_bootstrap=args.bootstrap,
    )
    modal = result.to_modal_data()
    if position:
        modal = replace(modal, sets=tuple(replace(s, position=dict(position)) for s in modal.sets))
    data = result.to_dict()
    data = {**data, "band": list(lo_hi), "method": args.method, "position": position, "notes": notes}
    if args.out:
        write_modal_data(args.out, modal)
    if args.uff:
        write_uff_modal(args.uff, modal)
        data["uff"] = args.uff
    if args.plot:
        from cappe.report import stabilization_plot

        stabilization_plot(result.diagram, args.plot, frf=frf, selected=result.selection)
        data["plot"] = args.plot
    lines = [*notes, f"{len(result.frequency)} modes in {lo_hi[0]:g}-{lo_hi[1]:g} Hz ({args.method}, orders up to "
             f"{args.max_order}):"]
    if result.reciprocity:
        lines.append(f"read by reciprocity: reference {', '.join(result.fit.input_names)}; shapes at the "
                     f"{len(result.fit.output_names)} excitation points {', '.join(result.fit.output_names)}")
    f_std = result.frequency_std if result.frequency_std is not None else [float("nan")] * result.fit.n_modes
    z_std = result.damping_std if result.damping_std is not None else [float("nan")] * result.fit.n_modes
    lines.append("   mode   frequency (Hz)      std   damping (%)       std   support")
    for k, (f, fs, z, zs, n) in enumerate(
            zip(result.frequency, f_std, result.damping, z_std, result.selection.support, strict=True)):
        lines.append(f"  {k + 1:5d}   {f:14.4f} {_std(fs, 8, 4)}   {100 * z:11.4f} {_std(100 * zs, 9, 4)}   {n:7d}")
    if result.n_bootstrap:
        lines.append(f"std: {result.n_bootstrap} bootstrap replicates over the fit's residuals")
    else:
        lines.append("std: not estimated (--bootstrap 0)")
    lines.extend(f"warning: {w}" for w in result.warnings)
    if args.out:
        lines.append(f"wrote {args.out} (cappe.modal/1{', position ' + str(position) if position else ''})")
    # -o receives the modal data contract (cappe.modal/1), not this summary: print only
    emit(argparse.Namespace(**{**vars(args), "out": None}), data, "\n".join(lines))
    return 0


def _reciprocal(frf: object, side: str) -> bool:
    """Whether extract_modes reads ``frf`` by reciprocity (the same rule, for the checks made before it runs)."""
    from cappe.identify._lsfd import _reference_side

    return _reference_side(frf, side)  # type: ignore[arg-type]


def _std(value: float, width: int, digits: int) -> str:
    return f"{value:{width}.{digits}f}" if value == value else f"{'-':>{width}}"
