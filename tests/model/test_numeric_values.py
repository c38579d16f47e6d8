"""NumericModel.with_nominal: a model with other parameter values, without changing the original."""

from __future__ import annotations

import numpy as np
import pytest

from cappe.exceptions import ModelError
from cappe.model import NumericModel


def test_with_nominal_gives_a_new_model_and_leaves_the_original(two_mass):
    nm = NumericModel(two_mass)
    before = nm.nominal.copy()
    values = nm.vector({"k11": 2.0e6, "m2": 1.5})
    other = nm.with_nominal(values)
    assert other is not nm
    np.testing.assert_array_equal(nm.nominal, before)  # unchanged
    np.testing.assert_array_equal(other.nominal, values)
    values[0] = -1.0  # the new model holds its own copy
    assert other.nominal[0] != -1.0
    # its matrices at its defaults are the original's at those values (the same compiled code)
    np.testing.assert_array_equal(other.matrices()["K"], nm.matrices({"k11": 2.0e6, "m2": 1.5})["K"])
    np.testing.assert_array_equal(other.matrices()["M"], nm.matrices({"k11": 2.0e6, "m2": 1.5})["M"])
    assert other.structure is nm.structure
    # overrides by name are relative to the model file's values
    np.testing.assert_array_equal(nm.with_nominal({"k11": 2.0e6}).nominal, nm.vector({"k11": 2.0e6}))


def test_with_nominal_refuses_a_batch_and_bad_names(two_mass):
    nm = NumericModel(two_mass)
    with pytest.raises(ModelError, match=r"with_nominal takes one parameter vector \(n_params,\); got shape \(2, 8\)"):
        nm.with_nominal(np.tile(nm.nominal, (2, 1)))
    with pytest.raises(ModelError, match="parameter array must have shape"):
        nm.with_nominal([1.0, 2.0])
    with pytest.raises(ModelError, match="nope"):
        nm.with_nominal({"nope": 1.0})


def test_damping_rows_of_an_element_with_decimal_axes_evaluate():
    # decimals stay exact, so a tilted axis [1, 0.127323954474, 0] normalizes to sqrt of a 24-digit integer; numpy
    # cannot take the square root of a Python integer beyond int64, and the damping sources (the elongation rows of
    # the damped elements, not squared) failed with "loop of ufunc does not support argument 0 of type int"
    from cappe.model import StructureBuilder

    b = StructureBuilder("tilted")
    b.body("a", mass=2.0, dofs=["x", "y"])
    b.element("e", bodies=["ground", "a"], axes={"x": [1, 0.127323954474, 0], "y": [0, 0, 1]},
              stiffness={"x": 1.0e6, "y": 2.0e6}, loss={"x": 0.05})
    nm = NumericModel(b.build())
    sources = nm.damping_sources()
    tilt = np.array([1.0, 0.127323954474]) / np.hypot(1.0, 0.127323954474)
    # the source's row is the unit elongation direction, its coefficient eta k; 1e-12: round-off
    np.testing.assert_allclose(sources.rows[0], tilt, rtol=1e-12)
    np.testing.assert_allclose(sources.coefficients, [[0.05 * 1.0e6]], rtol=1e-12)
