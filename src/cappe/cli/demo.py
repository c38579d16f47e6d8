"""``cappe demo``: the two-mass rig and the spindle-bearing model end to end."""

from __future__ import annotations

import argparse
import time

import numpy as np

from cappe.cli._common import emit


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser("demo", help="run the built-in demonstration")
    p.add_argument("--json", action="store_true", help="print machine-readable JSON")
    p.add_argument("-o", "--out", metavar="FILE", help="write the result to FILE (JSON)")
    p.add_argument("--no-identify", dest="identify", action="store_false",
                   help="skip the automated identification of the uniaxial machine tool (about 20 s)")
    p.add_argument("--no-monitor", dest="monitor", action="store_false",
                   help="skip the spindle monitoring scenarios (about 10 s)")
    p.add_argument("--report", metavar="FILE.html", default="cappe-demo-report.html",
                   help="HTML report of the identification (default cappe-demo-report.html)")
    p.add_argument("--n-gsa", type=int, default=256, help="identification: Sobol base sample (default 256)")
    p.add_argument("--n-opt", type=int, default=20, help="identification: local searches per subproblem (default 20)")
    p.add_argument("--seed", type=int, default=1, help="seed of the random truth and the searches (default 1)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from cappe.exact import symbolic_transfer_function
    from cappe.model import NumericModel, derive, load_model
    from cappe.systems import transfer_function

    start = time.perf_counter()
    lines: list[str] = []
    data: dict[str, object] = {}

    rig = load_model("builtin:two-mass-rig")
    sym = derive(rig)
    system = NumericModel(sym).system()
    modes = system.modes("exact")
    lines.append("== two-mass rig (Nickel 1999, 5.3; Table 5.1 most likely values) ==")
    lines.append("modes (exact complex):")
    for r in range(modes.n_modes):
        lines.append(f"  mode {r + 1}: {modes.frequency[r]:8.3f} Hz, damping {100 * modes.damping[r]:.4f} %")
    data["two_mass_modes"] = modes.to_dict()["modes"]
    for out in ("d1", "d2"):
        g = symbolic_transfer_function(sym, "F1", out)
        lines.append(f"G{out[1]}1(s) = {out}/F1, symbolic (thesis eqs 5.7-5.11):")
        lines.append("  numerator:   " + "  |  ".join(str(c) for c in g.numerator))
        lines.append("  denominator: " + "  |  ".join(str(c) for c in g.denominator))
        num = transfer_function(system.state_space("F1", out), "F1", out)
        lines.append(
            "  numeric:     num "
            + " ".join(f"{c:.6g}" for c in num.numerator)
            + " ; den "
            + " ".join(f"{c:.6g}" for c in num.denominator)
        )
        data[f"G{out[1]}1"] = {"symbolic": g.to_dict(), "numeric": num.to_dict()}

    spindle = NumericModel(load_model("builtin:spindle-bearing")).system()
    sm = spindle.modes("exact")
    lines.append("")
    lines.append("== spindle-bearing (Nickel 1999, 3.5 and 5.4; Table 5.8 values) ==")
    lines.append(f"{sm.n_modes} modes (exact complex):")
    dominant = sm.dominant_dofs(spindle.M)
    for r in range(sm.n_modes):
        k = int(dominant[r])
        lines.append(
            f"  mode {r + 1:>2}: {sm.frequency[r]:9.2f} Hz, damping {100 * sm.damping[r]:6.3f} %, dominant {sm.dofs[k]}"
        )
    data["spindle_modes"] = [{"frequency": m["frequency"], "damping": m["damping"]} for m in sm.to_dict()["modes"]]
    if args.monitor:
        lines.append("")
        lines += _monitoring(args, data)
    if args.identify:
        lines.append("")
        lines += _identification(args, data)
    elapsed = time.perf_counter() - start
    lines.append(f"\ndone in {elapsed:.2f} s")
    data["runtime_s"] = elapsed
    emit(args, data, "\n".join(lines))
    return 0


def _identification(args: argparse.Namespace, data: dict[str, object]) -> list[str]:
    """The paper's ideal case: a random truth within the bounds, noise-free reference modes at the four axis
    positions, the automated GSA-guided identification, validation at the held-out position z = -0.294 m."""
    from cappe.cli.identify import summary_text
    from cappe.estimate import AutomatedIdentification, ParameterSpace
    from cappe.modal import reference_modes
    from cappe.model import NumericModel, load_model
    from cappe.report import write_html_report

    t0 = time.perf_counter()
    machine = NumericModel(load_model("builtin:uniaxial-machine-tool"))
    space = ParameterSpace.from_model(machine)
    truth = space.mapping(space.sample(args.seed))
    reference = reference_modes(machine, params=machine.structure.resolve_parameters(truth), positions="all",
                                n_modes=20)
    estimator = AutomatedIdentification(machine, n_gsa=args.n_gsa, n_opt=args.n_opt, validation={"z": -0.294},
                                        rng=args.seed)
    estimator.fit(reference, truth=truth)
    identified = estimator.result_
    write_html_report(args.report, result=identified, truth=truth,
                      title="uniaxial machine tool: automated identification (ideal case)", model=machine,
                      run={"command": "cappe demo", "seed": args.seed,
                           "input files": ["builtin:uniaxial-machine-tool (reference modes simulated at a random "
                                           "truth within the bounds)"]})
    elapsed = time.perf_counter() - t0
    result = identified.estimate
    errors = result.relative_error(truth)
    data["identification"] = {"truth": truth, "estimate": result.parameters, "relative_error": errors,
                              "runtime_s": elapsed, "report": args.report}
    return [
        "== uniaxial machine tool (Ellinger & Zaeh 2022, 3.1): automated identification, ideal case ==",
        f"random truth within the bounds (seed {args.seed}), noise-free reference: 20 modes at 4 positions",
        summary_text(identified, truth, "uniaxial-machine-tool"),
        f"identification done in {elapsed:.1f} s; report written to {args.report}",
    ]


__all__ = ["register"]


def _monitoring(args: argparse.Namespace, data: dict[str, object]) -> list[str]:
    """Thesis Fig. 1.1 on the spindle: a day of healthy data teaches the baseline, then three faults."""
    from datetime import timedelta

    from cappe.model import NumericModel, load_model
    from cappe.monitor import Monitor, default_config, simulate_scenario

    t0 = time.perf_counter()
    model = NumericModel(load_model("builtin:spindle-bearing"))
    config = default_config(model, machine="spindle", source="builtin:spindle-bearing",
                            outputs=["sx", "sy", "hax", "hay", "haz", "htax"], band=(150.0, 1000.0))
    monitor = Monitor(config, model)
    healthy = simulate_scenario(config, "healthy", n=96, model=model, rng=args.seed)
    analyses = [monitor.analyse(m.frf, modal=False) for m in healthy]
    baseline = monitor.learn_baseline(analyses, conditions=[m.conditions for m in healthy])
    raw = np.ptp([a.estimate.factor[0] for a in analyses])
    lines = ["== spindle monitoring (Nickel 1999, Fig. 1.1): hammer FRFs every 15 min, 1 % noise ==",
             f"baseline from {len(healthy)} healthy measurements (one day, 22 +- 4 degC): the front-bearing factor "
             f"swings {100 * raw:.1f} % with the temperature, {100 * baseline.std[0]:.4f} % once compensated"]
    cases = [("bearing-loss", "front", 0.10, "front bearing loses 10 %"),
             ("preload-loss", None, 0.40, "bearing preload drops 40 %"),
             ("loosening-screw", "screw2", 0.50, "housing screw 2 loosens to 50 %")]
    found = []
    for k, (scenario, component, severity, words) in enumerate(cases):
        measurements = simulate_scenario(config, scenario, n=12, fault_at=2, component=component, severity=severity,
                                         model=model, rng=args.seed + 1 + k,
                                         start=healthy[-1].timestamp + timedelta(days=1 + k))
        lines.append(f"{words} from measurement 2:")
        state = None
        for m in measurements:
            analysis = monitor.analyse(m.frf, baseline=baseline, modal=False)
            state, _, alarms = monitor.step(state, analysis, m.conditions, baseline)
            for alarm in alarms:
                lines.append(f"  measurement {m.index:2d}: {alarm.message}")
                found.append({"scenario": scenario, "measurement": m.index, **alarm.to_dict()})
    lines.append(f"monitoring: {len(healthy) + 12 * len(cases)} measurements in {time.perf_counter() - t0:.1f} s")
    data["monitoring_alarms"] = found
    return lines
