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
