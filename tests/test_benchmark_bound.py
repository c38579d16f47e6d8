"""The eigen-solve bound of the benchmarks counts every solve the identification makes (issue 24)."""

from __future__ import annotations

from collections import Counter

import numpy as np
import scipy.linalg
import scipy.linalg.lapack

from cappe.modal import ModalEngine, exact_mode_derivatives
from cappe.model import NumericModel


def test_the_bound_counts_scipy_eigh_and_the_quadratic_eigenproblem_factorizations(slide, monkeypatch):
    # before issue 24's fix the count wrapped numpy's eigh and eig only: the modal derivatives' scipy eigh (39390 of
    # them in a three-axis identification) and the quadratic-eigenproblem LU factorizations went uncounted
    from benchmarks.bench_pipeline import _count_eigen_solves

    import cappe.modal._engine as engine_module

    for module, name in ((np.linalg, "eigh"), (np.linalg, "eig"), (scipy.linalg, "eigh"),
                         (scipy.linalg.lapack, "zgetrf")):
        monkeypatch.setattr(module, name, getattr(module, name))  # restored after the test
    monkeypatch.setattr(engine_module, "QUADRATIC_FRACTION", 0.5)
    counter: Counter[tuple[str, int, str]] = Counter()
    _count_eigen_solves(counter)
    model = NumericModel(slide)
    engine = ModalEngine(model, n_modes=6, n_workers=1)
    engine.derivatives(None, {"z": 0.1})  # undamped modes by scipy's generalized eigh
    assert counter[("eigh-generalized", 12, "real")] == 1
    poles = engine.evaluate(None, {"z": 0.1}, exact=True).poles[0]  # one eigh, then the quadratic eigenproblem
    assert counter[("eigh", 12, "real")] == 1
    lu_solve = counter[("lu", 12, "complex")]
    assert lu_solve >= 6  # at least one factorization per mode
    exact_mode_derivatives(engine, None, {"z": 0.1}, poles=poles[:2], parameters=["km"])
    assert counter[("lu", 13, "complex")] == 2  # one bordered system per differentiated mode
    assert counter[("eig", 24, "complex")] == 0  # no state-space eig
