"""Self-contained HTML report of an automated identification (figures inline as base64 PNG).

Sections: parameters (estimate, uncertainty, truth and error when known), per-stage costs and timings, the
sensitivity map (total Sobol' indices of every mode-position output) and Sobol' bar charts (paper Fig. 5), the
subproblem selection, parameter-deviation histograms when the truth is known (paper Figs 6 and 8), validation
statistics (paper Tables 2-5), FRF overlays with the permuted-damping model (paper Figs 7 and 9; the FRF that
``AutomatedIdentification.fit(overlay=...)`` kept) and MACXP matrices.
"""

from __future__ import annotations

import base64
import html
import io
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cappe._format import interval_text
from cappe.io.files import write_text

__all__ = ["in_words", "parameter_legend", "write_html_report"]

_STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1100px; color: #222; }
h1 { font-size: 1.5em; } h2 { font-size: 1.2em; border-bottom: 1px solid #ccc; margin-top: 2em; }
table { border-collapse: collapse; margin: 0.5em 0; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.2em 0.6em; text-align: right; }
th { background: #f2f2f2; } td.name, th.name { text-align: left; }
.bad { color: #b00; } .note { color: #555; font-size: 0.9em; }
img { max-width: 100%; }
"""


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _img(png: bytes, alt: str = "figure") -> str:
    """Inline ``<img>`` tag of PNG bytes (base64)."""
    data = base64.b64encode(png).decode("ascii")
    return f'<img src="data:image/png;base64,{data}" alt="{_e(alt)}">'


def _png(fig: Any, alt: str = "figure", *, tight_layout: bool = True) -> str:
    """``<img>`` tag of a matplotlib figure (base64 PNG); closes the figure.

    ``tight_layout=False`` crops to the drawn content instead (for figures, such as a colorbar shared by several
    axes, that tight_layout cannot handle).
    """
    plt = _pyplot()
    buffer = io.BytesIO()
    if tight_layout:
        fig.tight_layout()
    fig.savefig(buffer, format="png", dpi=100, bbox_inches=None if tight_layout else "tight")
    plt.close(fig)
    return _img(buffer.getvalue(), alt)


def _e(value: Any) -> str:
    return html.escape(str(value))


def _num(value: Any, fmt: str = ".4g") -> str:
    try:
        v = float(value)
    except (TypeError, ValueError):
        return "-"
    return format(v, fmt) if np.isfinite(v) else "-"


def _table(header: Sequence[str], rows: Sequence[Sequence[str]], names: int = 1) -> str:
    head = "".join(f'<th class="name">{_e(h)}</th>' if i < names else f"<th>{_e(h)}</th>"
                   for i, h in enumerate(header))
    body = []
    for row in rows:
        cells = "".join(f'<td class="name">{c}</td>' if i < names else f"<td>{c}</td>" for i, c in enumerate(row))
        body.append(f"<tr>{cells}</tr>")
    return f"<table><tr>{head}</tr>{''.join(body)}</table>"


def _label(position: Mapping[str, float] | None) -> str:
    if not position:
        return "-"
    return ", ".join(f"{k} = {v:g}" for k, v in position.items())


def _unit(unit: str) -> str:
    """A parameter unit as printed (dimensionless for an empty unit or ``1``)."""
    return "-" if unit in ("", "1") else unit


def _parameters(result: Any, truth: Mapping[str, float] | None, units: Mapping[str, str]) -> str:
    header = ["parameter", "unit", "estimate", "std", "std %", "95 % interval", "identifiable"]
    if truth is not None:
        header += ["truth", "error %"]
    rows = []
    for k, name in enumerate(result.names):
        value = float(result.values[k])
        lo, hi = (float(v) for v in result.ci95[k])
        std = float(result.std[k])
        rel = 100 * std / abs(value) if value != 0 and np.isfinite(std) else float("nan")
        row = [_e(name), _e(_unit(units.get(name, ""))), _num(value, ".6g"), _num(std, ".2g"), _num(rel, ".2g"),
               _e(interval_text(lo, hi, value)),
               "yes" if result.identifiable[k] else '<span class="bad">no</span>']
        if truth is not None:
            t = truth.get(name)
            err = 100 * (value / t - 1) if t else float("nan")
            inside = t is not None and lo <= t <= hi
            row += [_num(t, ".6g"), _num(err, "+.2g") + ("" if inside or t is None else
                                                         ' <span class="bad">(outside the interval)</span>')]
        rows.append(row)
    return _table(header, rows, names=1)


def parameter_legend(structure: Any, names: Sequence[str]) -> list[tuple[str, str, str, str]]:
    """What each parameter is, from the model: ``(name, meaning, kind, unit)`` per name.

    The meaning is the parameter's description in the model file, followed by where it enters the model (the
    element, the property and the direction: ``me1: viscous damping in x``), or the body whose mass or inertia
    it sets.

    Parameters
    ----------
    structure : Structure or NumericModel
        The model.
    names : sequence of str
        The parameters to explain.

    Returns
    -------
    list of (str, str, str, str)

    Examples
    --------
    >>> from cappe.model import load_model
    >>> parameter_legend(load_model("builtin:two-mass-rig"), ["c11"])
    [('c11', 'thick beam damping; enters beam1: viscous damping in x', 'damping', 'N s/m')]
    """
    structure = getattr(structure, "structure", structure)
    by_name = {p.name: p for p in structure.parameters}
    uses: dict[str, list[str]] = {n: [] for n in names}
    for element in structure.elements:
        for label, mapping in (("stiffness", element.stiffness), ("viscous damping", element.damping),
                               ("loss factor", element.loss)):
            for direction, expr in mapping.items():
                for symbol in getattr(expr, "free_symbols", ()):
                    if str(symbol) in uses:
                        uses[str(symbol)].append(f"{element.name}: {label} in {direction}")
    for body in structure.bodies:
        for label, expr in (("mass", body.mass), ("inertia", body.inertia)):
            for symbol in getattr(expr, "free_symbols", ()):
                if str(symbol) in uses and f"{body.name}: {label}" not in uses[str(symbol)]:
                    uses[str(symbol)].append(f"{body.name}: {label}")
    out = []
    for name in names:
        parameter = by_name.get(name)
        if parameter is None:
            out.append((name, "", "", ""))
            continue
        parts = [parameter.description] if parameter.description else []
        if uses[name]:
            parts.append("enters " + ", ".join(uses[name]))
        out.append((name, "; ".join(parts), parameter.kind, _unit(parameter.unit)))
    return out


def _legend(structure: Any, names: Sequence[str]) -> str:
    rows = [[_e(n), _e(meaning), _e(kind), _e(unit)] for n, meaning, kind, unit in parameter_legend(structure, names)]
    return ("<h3>What the parameters are</h3>"
            + _table(["parameter", "meaning (model file) and where it enters the model", "kind", "unit"], rows, 2))


#: scipy's termination messages, said in words
_MESSAGES = (
    ("`gtol` termination condition", "the cost stopped decreasing: its gradient vanished (a local minimum)"),
    ("`ftol` termination condition", "the cost stopped decreasing: the last steps changed it by a negligible "
                                     "relative amount"),
    ("`xtol` termination condition", "the parameters stopped changing: the last step was negligible"),
    ("`max_nfev` exceeded", "the search ran out of its evaluation budget before it converged"),
    ("estimate at a bound for", "an estimate ended at its bound"),
)


def in_words(message: str) -> str:
    """An optimizer's termination message in words an engineer reads (unknown messages pass through).

    Parameters
    ----------
    message : str
        The estimate's ``message``.

    Returns
    -------
    str

    Examples
    --------
    >>> in_words("`gtol` termination condition is satisfied.")
    'the cost stopped decreasing: its gradient vanished (a local minimum)'
    """
    said = []
    for part in (p.strip() for p in message.split(";")):
        if not part:
            continue
        for key, words in _MESSAGES:
            if key in part:
                rest = part.split(key, 1)[1].strip() if key == "estimate at a bound for" else ""
                said.append(words + (f" ({rest})" if rest else ""))
                break
        else:
            said.append(part)
    return "; ".join(said)


def _run_info(estimate: Any, identified: Any, run: Mapping[str, Any] | None) -> str:
    """Version, date, seed, input files and settings: what reproduces the page."""
    import datetime

    from cappe import __version__

    rows = [["cappe version", _e(__version__)],
            ["written", _e(datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"))],
            ["method", _e(estimate.method)]]
    for key, value in (run or {}).items():
        rows.append([_e(key), _e(value if not isinstance(value, list | tuple) else ", ".join(map(str, value)))])
    if identified is not None:
        for key, value in identified.settings.to_dict().items():
            shown = ", ".join(map(str, value)) if isinstance(value, list | tuple) else value
            rows.append([_e(f"setting {key.replace('_', ' ')}"), _e("-" if shown is None else shown)])
    return "<h2>Run</h2>" + _table(["", "value"], rows)


def _histograms(result: Any, truth: Mapping[str, float], groups: Mapping[str, Sequence[str]]) -> str:
    """Relative deviations from the truth per group (paper Figs 6 and 8), median and 90 % percentile marked."""
    present = {g: [n for n in names if n in truth and n in result.names] for g, names in groups.items()}
    present = {g: names for g, names in present.items() if names}
    if not present:
        return ""
    plt = _pyplot()
    fig, axes = plt.subplots(1, len(present), figsize=(5 * len(present), 3.2), squeeze=False)
    for ax, (group, names) in zip(axes[0], present.items(), strict=True):
        dev = np.array([100 * (result.parameters[n] / truth[n] - 1) for n in names])
        ax.hist(dev, bins=min(max(len(dev), 5), 20), orientation="horizontal", color="#4477aa")
        ax.axhline(float(np.median(dev)), color="k", ls="--", label="median")
        ax.axhline(float(np.percentile(np.abs(dev), 90)), color="#cc6677", ls=":", label="90 % percentile of |dev|")
        ax.set_xlabel("count")
        ax.set_ylabel("relative deviation in %")
        ax.set_title(f"{group} parameters ({len(names)})", fontsize=10)
        ax.legend(fontsize=8)
    return _png(fig)


def _sensitivity_map(gsa: Any, threshold: float, max_rows: int = 60) -> str:
    """ST of the outputs (rows: criterion, mode, position) over the parameters, significant cells marked: only the
    outputs where some parameter reaches ``threshold``, the ``max_rows`` with the largest ST when there are more,
    so that every row keeps a readable label."""
    plt = _pyplot()
    st = np.clip(np.nan_to_num(np.asarray(gsa.sobol.ST, dtype=float)), 0, 1)
    names = list(gsa.sobol.names)
    outputs = list(gsa.sobol.output_names)
    keep = np.flatnonzero(st.max(axis=1) >= threshold)
    note = f"{keep.size} of {len(outputs)} outputs have a parameter with ST >= {threshold:g}"
    if keep.size > max_rows:
        keep = np.sort(keep[np.argsort(-st[keep].max(axis=1), kind="stable")[:max_rows]])
        note += f"; the {max_rows} with the largest ST are drawn"
    if keep.size == 0:
        return f"<p class=note>{_e(note)}: no sensitivity map.</p>"
    st = st[keep]
    labels = [outputs[i] for i in keep]
    fig, ax = plt.subplots(figsize=(max(6.0, 0.35 * len(names) + 3), max(3.0, 0.22 * len(labels) + 2)))
    image = ax.imshow(st, aspect="auto", cmap="viridis", vmin=0, vmax=1, interpolation="nearest")
    rows, cols = np.nonzero(st >= threshold)
    ax.scatter(cols, rows, s=6, c="w", marker=".")
    ax.set_xticks(range(len(names)), names, rotation=60, ha="right", fontsize=8)
    ax.set_yticks(range(len(labels)), labels, fontsize=8)
    ax.set_xlabel("parameter")
    ax.set_ylabel("output (criterion:mode@position)")
    fig.colorbar(image, ax=ax, label="total Sobol index ST (0-1)", shrink=min(1.0, 12.0 / max(len(labels), 1)))
    ax.set_title(f"sensitivity map (white dots: ST >= {threshold:g})", fontsize=10)
    return f"<p class=note>{_e(note)}.</p>" + _png(fig, "sensitivity map")


def _sobol_note(gsa: Any) -> str:
    """What total Sobol indices are, and whether this sample size estimates them well enough to read."""
    sobol = gsa.sobol
    text = ("<p class=note>The total Sobol index ST of a parameter is the share of an output's variance, over the "
            "parameter bounds, that involves that parameter alone or in interaction with others (dimensionless, "
            "between 0 and 1; the first-order index S1 counts it alone). An output whose ST is near 0 for a "
            "parameter carries no information on it. Estimated from "
            f"N = {sobol.n} base samples ({sobol.n * (len(sobol.names) + 2)} model runs); whiskers: "
            f"{100 * sobol.conf_level:g} % bootstrap intervals.</p>")
    noisy = sobol.noise_text()
    if noisy:
        text += (f"<p class=bad>{_e(noisy[0].upper() + noisy[1:])}. Only a parameter's membership of the significant "
                 "set is used here.</p>")
    return text


def _mode_table(results: Sequence[Any]) -> str:
    """Per position and reference mode: frequencies and damping ratios, measured and model, their differences, and
    MACXP."""
    rows = []
    for res in results:
        for r, f_ref in enumerate(res.reference_frequency):
            f_model = float(res.model_frequency[r])
            z_ref, z_model = 100 * float(res.reference_damping[r]), 100 * float(res.model_damping[r])
            z_diff = _num(100 * (z_model / z_ref - 1), "+.3g") if z_ref > 0 else "-"
            rows.append([_e(_label(res.position)), str(r + 1), str(int(res.model_mode[r]) + 1), _num(f_ref, ".5g"),
                         _num(f_model, ".5g"), _num(100 * (f_model / f_ref - 1), "+.3g"), _num(z_ref, ".4g"),
                         _num(z_model, ".4g"), z_diff, _num(100 * float(res.macxp[r]), ".2f")])
    return ("<h3>Modes</h3><p class=note>Reference (measured or simulated) against the identified model, mode by "
            "mode: natural frequencies in Hz and damping ratios zeta in % of critical damping, each with the "
            "model's difference from the reference in % of the reference value (for the damping ratio this is the "
            "signed NDD, (zeta_model - zeta_ref) / zeta_ref; '-' where the reference mode is undamped); MACXP, "
            "shape agreement weighted by pole proximity (paper eq. 4; 100 % = identical mode).</p>"
            + _table(["position (m)", "mode", "model mode", "f reference (Hz)", "f model (Hz)", "f difference %",
                      "zeta reference %", "zeta model %", "zeta difference %", "MACXP %"], rows))


#: a MACXP below this is explained on the page
_GOOD_MACXP = 0.99


def _worst_macxp(results: Sequence[Any], estimate: Any) -> str:
    """Which mode has the worst MACXP, and what makes it low, next to the parameter uncertainty."""
    worst = None
    for res in results:
        for r, value in enumerate(res.macxp):
            if np.isfinite(value) and (worst is None or value < worst[0]):
                worst = (float(value), res, r)
    if worst is None or worst[0] >= _GOOD_MACXP:
        return ""
    value, res, r = worst
    nfd = 100 * (float(res.model_frequency[r]) / float(res.reference_frequency[r]) - 1)
    ndd = 100 * float(res.ndd[r])
    std = np.asarray(estimate.std, dtype=float) / np.abs(np.asarray(estimate.values, dtype=float))
    largest = float(np.nanmax(100 * std)) if np.any(np.isfinite(std)) else float("nan")
    cause = ("the damping differs more than the frequency: MACXP weights shape agreement by pole proximity, and "
             "the pole of a lightly damped mode moves mostly with its damping" if abs(ndd) > abs(nfd) else
             "the frequencies differ: MACXP weights shape agreement by pole proximity")
    return (f"<p>Worst MACXP: {100 * value:.2f} % for reference mode {r + 1} at {_e(_label(res.position))} (model "
            f"mode {int(res.model_mode[r]) + 1}; frequency {nfd:+.3f} %, NDD {ndd:.3g} %): {cause}. The largest "
            f"parameter standard error is {largest:.3g} %; a damping parameter that the modes determine poorly "
            "leaves such a mode's MACXP low while the stiffnesses agree.</p>")


def _sobol_bars(gsa: Any, top: int, max_panels: int) -> str:
    """Bars of S1 and ST for the most informative outputs (the largest single ST), paper Fig. 5."""
    import tempfile

    from cappe.report.plots import sobol_plot

    st = np.nan_to_num(np.asarray(gsa.sobol.ST, dtype=float))
    order = np.argsort(-st.max(axis=1), kind="stable")
    chosen = [gsa.sobol.output_names[i] for i in order[:max_panels]]
    with tempfile.TemporaryDirectory() as folder:
        target = Path(folder) / "sobol.png"
        sobol_plot(gsa.sobol, target, outputs=chosen, top=top)
        return ("<p class=note>Bars per output (the outputs with the largest single ST); the legend above the "
                "bars says what each is.</p>" + _img(target.read_bytes(), "Sobol indices"))


def _statistics(label: str, stats: Mapping[str, Mapping[str, float]]) -> str:
    if not stats:
        return ""
    rows = []
    for key, title in (("worst", "worst"), ("p5", "5 % worst tail"), ("mean", "mean"), ("median", "median")):
        rows.append([_e(title)] + [_num(100 * stats[c][key], ".2f") for c in ("frac", "csf", "macxp", "ndd")])
    return f"<p>{_e(label)}</p>" + _table(["statistic", "FRAC %", "CSF %", "MACXP %", "NDD %"], rows)


def _overlay(result: Any, permuted: Sequence[Any]) -> str:
    plt = _pyplot()
    ov = result.overlay
    fig, (ax_m, ax_p) = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True)
    curves = [("reference", ov["reference"], "k", "-"), ("model", ov["model"], "#4477aa", "--")]
    if permuted:
        curves.append(("model with permuted damping", permuted[0].overlay["model"], "#cc6677", ":"))
    for label, h, color, style in curves:
        ax_m.semilogy(result.freq, np.abs(h), color=color, ls=style, label=label)
        ax_p.plot(result.freq, np.degrees(np.angle(h)), color=color, ls=style)
    # measured FRFs keep their own quantity (accelerance of an accelerometer and hammer test, ...)
    ax_m.set_ylabel("|FRF| as measured" if result.frf_source == "measured FRFs" else "receptance in m/N")
    ax_p.set_ylabel("phase in deg")
    ax_p.set_xlabel("frequency in Hz")
    ax_m.legend(fontsize=8)
    ax_m.set_title(f"{ov['output']} / {ov['input']} at {_label(result.position)} ({result.frf_source})", fontsize=10)
    for ax in (ax_m, ax_p):
        ax.grid(True, alpha=0.3)
    return _png(fig)


def _macxp_matrices(results: Sequence[Any]) -> str:
    if not results:
        return ""
    plt = _pyplot()
    fig, axes = plt.subplots(1, len(results), figsize=(4.2 * len(results), 4), squeeze=False)
    for ax, res in zip(axes[0], results, strict=True):
        image = ax.imshow(res.macxp_matrix, vmin=0, vmax=1, cmap="Blues", interpolation="nearest", origin="lower")
        ax.set_xlabel("reference mode")
        ax.set_ylabel("model mode")
        ax.set_title(_label(res.position), fontsize=9)
        ax.set_xticks(range(res.macxp_matrix.shape[1]), [str(i + 1) for i in range(res.macxp_matrix.shape[1])],
                      fontsize=6)
        ax.set_yticks(range(res.macxp_matrix.shape[0]), [str(i + 1) for i in range(res.macxp_matrix.shape[0])],
                      fontsize=6)
    fig.colorbar(image, ax=axes[0].tolist(), label="MACXP", shrink=0.8)
    return _png(fig, "MACXP matrices", tight_layout=False)


def write_html_report(
    path: str | Path,
    *,
    result: Any,
    gsa: Any | None = None,
    validation: Any | None = None,
    truth: Mapping[str, float] | None = None,
    title: str | None = None,
    top: int = 10,
    max_sobol_panels: int = 6,
    model: Any | None = None,
    run: Mapping[str, Any] | None = None,
) -> Path:
    """Write a self-contained HTML report of an identification (atomically).

    Parameters
    ----------
    path : str or Path
        Target file.
    result : AutomatedResult or ParameterEstimate
        The identification: ``AutomatedIdentification.result_`` gives the whole report (stages, sensitivity,
        subproblem selection, validation); another estimator's ``ParameterEstimate`` gives the parameter table and
        the sections of ``gsa`` and ``validation`` when given.
    gsa : ModelSobolResult, optional
        Sensitivity map and Sobol' bars (default: the automated identification's).
    validation : IdentificationValidation or mapping, optional
        Validation sections (default: the automated identification's); a mapping as
        ``AutomatedIdentification.validation_`` gives it is accepted: ``{"validation": ValidationResult or None,
        "identification": [ValidationResult], "permuted": [ValidationResult]}``.
    truth : mapping, optional
        True parameter values (simulated reference): errors and deviation histograms.
    title : str, optional
        Page title.
    top, max_sobol_panels : int
        Parameters per Sobol' bar chart and number of charts.
    model : Structure or NumericModel, optional
        The identified model: units of the parameters and a legend saying what each one is (its description
        and the element, property and direction it enters).
    run : mapping, optional
        What reproduces the run, shown with the cappe version, the date and the identification settings: e.g.
        ``{"command": ..., "seed": 0, "input files": [...]}``.

    Returns
    -------
    Path

    Examples
    --------
    >>> import tempfile
    >>> from cappe.estimate import ParameterEstimate
    >>> res = ParameterEstimate("demo", ("k",), np.array([2.0]), np.array([0.1]), np.array([[1.8, 2.2]]),
    ...                         np.eye(1), np.array([True]))
    >>> with tempfile.TemporaryDirectory() as d:
    ...     text = write_html_report(Path(d) / "r.html", result=res, truth={"k": 2.0}).read_text()
    >>> "<table>" in text and "[1.8, 2.2]" in text
    True
    """
    from cappe.estimate import AutomatedResult, IdentificationValidation

    identified = result if isinstance(result, AutomatedResult) else None
    estimate = result.estimate if identified is not None else result
    if identified is not None:
        gsa = identified.gsa.sobol if gsa is None else gsa
        validation = identified.validation if validation is None else validation
    if isinstance(validation, Mapping):  # AutomatedIdentification.validation_
        permuted = tuple(validation.get("permuted") or ())
        validation = IdentificationValidation(validation.get("validation"),
                                              tuple(validation.get("identification") or ()), permuted,
                                              tuple({} for _ in permuted)) if validation else None
    structure = getattr(model, "structure", model)
    units = {p.name: p.unit for p in structure.parameters} if structure is not None else {}
    parts = [f"<h1>{_e(title or 'cappe identification report')}</h1>",
             f"<p>method <b>{_e(estimate.method)}</b>: "
             f"{'converged' if estimate.success else '<span class=bad>did not converge</span>'}"
             f"{' - ' + _e(in_words(estimate.message)) if estimate.message else ''}. Final cost "
             f"{_num(estimate.cost)} (sum of squared weighted relative residuals, dimensionless).</p>"]
    if identified is not None and identified.identification_positions:
        parts.append(f"<p>identification positions: "
                     f"{_e('; '.join(_label(p) for p in identified.identification_positions))}; "
                     f"validation position: {_e(_label(identified.validation_position))}</p>")
    parts.append(_run_info(estimate, identified, run))
    parts.append("<h2>Parameters</h2><p class=note>Estimates in SI units with their standard error and 95 % "
                 "interval (local, from the Jacobian at the optimum); identifiable: the data determine the "
                 "parameter (not part of an undetermined combination).</p>" + _parameters(estimate, truth, units))
    if structure is not None:
        parts.append(_legend(structure, estimate.names))
    elif any("_" in n for n in estimate.names):
        parts.append("<p class=note>Pass the model to name what each parameter is (units and legend).</p>")
    if identified is not None:
        parts.append("<h2>Stages</h2>")
        parts.append(_table(["stage", "cost (dimensionless)"],
                            [[_e(k.replace("_", " ")), _num(v)] for k, v in identified.costs.items()]))
        parts.append(_table(["stage", "time (s)"],
                            [[_e(k.replace("_", " ")), _num(v, ".3g")] for k, v in identified.timings.items()]))
    if truth is not None:
        groups = {"all": list(estimate.names)}
        if identified is not None and (identified.stiffness_unknowns or identified.damping_unknowns):
            groups = {"stiffness": list(identified.stiffness_unknowns), "damping": list(identified.damping_unknowns)}
        figure = _histograms(estimate, truth, groups)
        if figure:
            parts.append("<h2>Deviation from the truth</h2>" + figure)
    if gsa is not None:
        parts.append("<h2>Global sensitivity</h2>")
        parts.append(_sobol_note(gsa))
        parts.append(_sensitivity_map(gsa, identified.gsa.threshold if identified is not None else 0.01))
        parts.append(_sobol_bars(gsa, top, max_sobol_panels))
    if identified is not None and identified.stiffness.selection:
        parts.append(_selection(identified.stiffness.selection, units))
    if validation is not None:
        parts += _validation(validation, estimate)
    page = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{_e(title or 'cappe report')}</title>"
            f"<style>{_STYLE}</style></head><body>{''.join(parts)}</body></html>\n")
    return write_text(path, page)


def _selection(selection: Mapping[str, Any], units: Mapping[str, str]) -> str:
    """The paper's subproblem selection: per modal unknown, the least-spread subproblem's median."""
    rows = [[_e(n), _num(s.value), _e(_unit(units.get(n, ""))), _num(100 * s.spread, ".3g"), str(s.mode),
             _e(_label(s.position)),
             str(s.searched_in)] for n, s in selection.items()]
    return ("<h2>Stiffness subproblems</h2><p class=note>For each parameter the mode-position subproblem "
            "with the least spread of its optimum over the runs (paper section 2.3.2).</p>"
            + _table(["parameter", "median", "unit", "spread %", "mode", "position (m)", "subproblems"], rows))


def _validation(validation: Any, estimate: Any) -> list[str]:
    """Statistics at the held-out and identification positions, the permuted-damping comparison, the FRF overlay
    and the MACXP matrices."""
    parts = ["<h2>Validation</h2>"]
    held, ident, permuted = validation.held, list(validation.identification), list(validation.permuted)
    if held is not None:
        parts.append(_statistics(f"held-out position {_label(held.position)}", held.statistics()))
    pooled = validation.identification_statistics()
    if pooled:
        parts.append(_statistics("identification positions", pooled))
    if permuted:
        rows = [[_e(c)] + [_num(100 * np.mean([p.statistics()[c][k] for p in permuted]), ".2f")
                           for k in ("worst", "mean")] for c in ("frac", "csf", "macxp", "ndd")]
        parts.append(f"<p>permuted damping ({len(permuted)} random reassignments of the identified damping "
                     f"factors, at {_e(_label(permuted[0].position))}; averages)</p>")
        parts.append(_table(["criterion", "worst %", "mean %"], rows))
    target = held if held is not None else (ident[0] if ident else None)
    if target is not None:
        parts.append("<h3>FRF overlay</h3>" + _overlay(target, permuted))
    shown = ([held] if held is not None else []) + ident
    if shown:
        parts.append(_mode_table(shown) + _worst_macxp(shown, estimate))
    if shown:
        parts.append("<h3>MACXP matrices</h3>" + _macxp_matrices(shown))
    return parts
