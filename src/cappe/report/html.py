"""Self-contained HTML report of an automated identification (figures inline as base64 PNG).

Sections: parameters (estimate, uncertainty, truth and error when known), per-stage costs and timings, the
sensitivity map (total Sobol' indices of every mode-position output) and Sobol' bar charts (paper Fig. 5), the
subproblem selection, parameter-deviation histograms when the truth is known (paper Figs 6 and 8), validation
statistics (paper Tables 2-5), FRF overlays with the permuted-damping model (paper Figs 7 and 9) and MACXP matrices.
"""

from __future__ import annotations

import base64
import html
import io
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cappe.io.files import write_text

__all__ = ["write_html_report"]

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


def _parameters(result: Any, truth: Mapping[str, float] | None) -> str:
    header = ["parameter", "estimate", "std", "95 % interval", "identifiable"]
    if truth is not None:
        header += ["truth", "error %"]
    rows = []
    for k, name in enumerate(result.names):
        value = float(result.values[k])
        lo, hi = result.ci95[k]
        row = [_e(name), _num(value), _num(result.std[k], ".2g"), f"[{_num(lo)}, {_num(hi)}]",
               "yes" if result.identifiable[k] else '<span class="bad">no</span>']
        if truth is not None:
            t = truth.get(name)
            err = 100 * (value / t - 1) if t else float("nan")
            row += [_num(t), _num(err, "+.3f")]
        rows.append(row)
    return _table(header, rows)


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


def _sensitivity_map(gsa: Any, threshold: float) -> str:
    """ST of every output (rows: criterion, mode, position) over the parameters, significant cells outlined."""
    plt = _pyplot()
    st = np.clip(np.nan_to_num(np.asarray(gsa.sobol.ST, dtype=float)), 0, 1)
    names = list(gsa.sobol.names)
    outputs = list(gsa.sobol.output_names)
    height = min(max(3.0, 0.14 * len(outputs) + 1.5), 40.0)
    fig, ax = plt.subplots(figsize=(max(6.0, 0.3 * len(names) + 3), height))
    image = ax.imshow(st, aspect="auto", cmap="viridis", vmin=0, vmax=1, interpolation="nearest")
    rows, cols = np.nonzero(st >= threshold)
    ax.scatter(cols, rows, s=4, c="w", marker=".")
    ax.set_xticks(range(len(names)), names, rotation=60, ha="right", fontsize=7)
    step = max(1, len(outputs) // 60)
    ax.set_yticks(range(0, len(outputs), step), outputs[::step], fontsize=6)
    fig.colorbar(image, ax=ax, label="total Sobol index ST")
    ax.set_title(f"sensitivity map (dots: ST >= {threshold:g})", fontsize=10)
    return _png(fig)


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
        return _img(target.read_bytes(), "Sobol indices")


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
    ax_m.set_ylabel("receptance in m/N")
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
    >>> "<table>" in text and "+0.000" in text
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
    parts = [f"<h1>{_e(title or 'cappe identification report')}</h1>",
             f"<p>method <b>{_e(estimate.method)}</b>, cost {_num(estimate.cost)}, "
             f"{'converged' if estimate.success else '<span class=bad>not converged</span>'}"
             f"{': ' + _e(estimate.message) if estimate.message else ''}</p>"]
    if identified is not None and identified.identification_positions:
        parts.append(f"<p>identification positions: "
                     f"{_e('; '.join(_label(p) for p in identified.identification_positions))}; "
                     f"validation position: {_e(_label(identified.validation_position))}</p>")
    parts.append("<h2>Parameters</h2>" + _parameters(estimate, truth))
    if identified is not None:
        parts.append("<h2>Stages</h2>")
        parts.append(_table(["stage", "cost"], [[_e(k), _num(v)] for k, v in identified.costs.items()]))
        parts.append(_table(["stage", "seconds"], [[_e(k), _num(v, ".3g")] for k, v in identified.timings.items()]))
    if truth is not None:
        groups = {"all": list(estimate.names)}
        if identified is not None and (identified.stiffness_unknowns or identified.damping_unknowns):
            groups = {"stiffness": list(identified.stiffness_unknowns), "damping": list(identified.damping_unknowns)}
        figure = _histograms(estimate, truth, groups)
        if figure:
            parts.append("<h2>Deviation from the truth</h2>" + figure)
    if gsa is not None:
        parts.append("<h2>Global sensitivity</h2>")
        parts.append(_sensitivity_map(gsa, identified.gsa.threshold if identified is not None else 0.01))
        parts.append(_sobol_bars(gsa, top, max_sobol_panels))
    if identified is not None and identified.stiffness.selection:
        parts.append(_selection(identified.stiffness.selection))
    if validation is not None:
        parts += _validation(validation)
    page = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{_e(title or 'cappe report')}</title>"
            f"<style>{_STYLE}</style></head><body>{''.join(parts)}</body></html>\n")
    return write_text(path, page)


def _selection(selection: Mapping[str, Any]) -> str:
    """The paper's subproblem selection: per modal unknown, the least-spread subproblem's median."""
    rows = [[_e(n), _num(s.value), _num(100 * s.spread, ".3g"), str(s.mode), _e(_label(s.position)),
             str(s.searched_in)] for n, s in selection.items()]
    return ("<h2>Stiffness subproblems</h2><p class=note>For each parameter the mode-position subproblem "
            "with the least spread of its optimum over the runs (paper section 2.3.2).</p>"
            + _table(["parameter", "median", "spread %", "mode", "position", "subproblems"], rows))


def _validation(validation: Any) -> list[str]:
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
        parts.append("<h3>MACXP matrices</h3>" + _macxp_matrices(shown))
    return parts
