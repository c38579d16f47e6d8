"""``cappe demo``: the two-mass rig and the spindle-bearing model end to end."""

from __future__ import annotations

import argparse
import time

import numpy as np

from cappe.cli._common import emit
from cappe.exact import symbolic_transfer_function
from cappe.model import NumericModel, derive, load_model
from cappe.systems import transfer_function


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser("demo", help="run the built-in demonstration")
    p.add_argument("--json", action="store_true", help="print machine-readable JSON")
    p.add_argument("-o", "--out", metavar="FILE", help="write the result to FILE (JSON)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
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
    for r in range(sm.n_modes):
        k = int(np.argmax(np.abs(sm.shapes[:, r])))
        lines.append(
            f"  mode {r + 1:>2}: {sm.frequency[r]:9.2f} Hz, damping {100 * sm.damping[r]:6.3f} %, dominant {sm.dofs[k]}"
        )
    data["spindle_modes"] = [{"frequency": m["frequency"], "damping": m["damping"]} for m in sm.to_dict()["modes"]]
    elapsed = time.perf_counter() - start
    lines.append(f"\ndone in {elapsed:.2f} s")
    data["runtime_s"] = elapsed
    emit(args, data, "\n".join(lines))
    return 0


__all__ = ["register"]
