"""Batched evaluation of system matrices against a per-sample loop, and against the eigen-solve cost.

For a chain of n rigid bodies (6 DOF each) the affine NumericModel evaluates M, C, K for a batch of
parameter vectors with one matrix product; the naive route calls the evaluation once per sample. Both are
timed in the same run, together with the batched generalized eigen-solves of the same matrices, so the
ratios are meaningful on any machine.
"""

from __future__ import annotations

import numpy as np

from benchmarks._common import best, write_results
from cappe.model import NumericModel, StructureBuilder


def chain(n_bodies: int) -> NumericModel:
    b = StructureBuilder(f"chain-{n_bodies}")
    b.parameter("m", 5.0, kind="mass")
    b.parameter("J", 0.05, kind="inertia")
    for i in range(n_bodies + 1):
        b.parameter(f"k{i}", 1.0e7 * (1 + 0.1 * i), kind="stiffness")
        b.parameter(f"c{i}", 100.0, kind="damping")
    for i in range(n_bodies):
        # centre of mass off the body origin and a product of inertia: M has full 6 x 6 blocks, as in real machines
        b.body(f"b{i}", mass="m", inertia={"xx": "J", "yy": "J", "zz": "J", "xy": "J/10"}, position=[0, 0, 0.2 * i],
               com=[0.01, 0.005, 0.02])
    six = ("x", "y", "z", "rx", "ry", "rz")
    for i in range(n_bodies + 1):
        a = "ground" if i == 0 else f"b{i - 1}"
        c = "ground" if i == n_bodies else f"b{i}"
        if a == c:
            continue
        b.element(f"e{i}", bodies=(a, c), at=[0.05, 0.02, 0.2 * i - 0.1],
                  stiffness={d: f"k{i}" if d in "xyz" else f"k{i}/100" for d in six}, damping={"x": f"c{i}"})
    b.input("F", body="b0", direction="x")
    b.output("d", body=f"b{n_bodies - 1}", direction="x")
    return NumericModel(b.build())




def _measure(model: NumericModel, params: np.ndarray) -> dict[str, float]:  # type: ignore[type-arg]
    model.matrices(params[:2])  # warm the pattern cache
    t_batched = best(lambda: model.matrices(params, names=("M", "K")))
    t_loop = best(lambda: [model.matrices(p, names=("M", "K")) for p in params])
    mats = model.matrices(params, names=("M", "K"))

    def eig() -> None:
        chol = np.linalg.cholesky(mats["M"])
        inv = np.linalg.inv(chol)
        np.linalg.eigvalsh(inv @ mats["K"] @ np.swapaxes(inv, 1, 2))

    t_eig = best(eig)
    return {"batched_s": t_batched, "loop_s": t_loop, "eigensolve_s": t_eig}


def main() -> None:
    rng = np.random.default_rng(0)
    rows = []
    for n_bodies, batch in ((2, 512), (5, 512), (10, 256), (25, 64)):
        model = chain(n_bodies)
        params = model.nominal * rng.uniform(0.7, 1.3, size=(batch, model.nominal.size))
        t = _measure(model, params)
        rows.append({
            "n_dof": model.n_dof, "batch": batch, **t,
            "speedup_vs_loop": t["loop_s"] / t["batched_s"],
            "matrix_time_over_eigensolve": t["batched_s"] / t["eigensolve_s"],
        })
        print(f"n_dof {model.n_dof:4d}  batch {batch:4d}: batched {t['batched_s'] * 1e3:8.2f} ms, loop "
              f"{t['loop_s'] * 1e3:8.2f} ms ({t['loop_s'] / t['batched_s']:6.1f}x), eigen-solves "
              f"{t['eigensolve_s'] * 1e3:8.2f} ms (matrices cost {100 * t['batched_s'] / t['eigensolve_s']:5.1f} % "
              "of the solves)")
    write_results("matrices", rows)


if __name__ == "__main__":
    main()
