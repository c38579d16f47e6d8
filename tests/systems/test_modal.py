"""Modal results: the DOF that dominates each mode by kinetic energy."""

from __future__ import annotations

import numpy as np
import pytest

from cappe.exceptions import DataError
from cappe.systems import ModalSet, dominant_dofs


def test_dominant_dof_is_the_largest_kinetic_energy_not_the_largest_entry():
    # hand computation: energies m_i phi_i^2 = (1, 0.25) for mode 1 and (1, 25) J for mode 2 (rotation of 100 kg m^2)
    mass = np.diag([1.0, 100.0])
    shapes = np.array([[1.0, 1.0], [0.05, -0.5]])
    assert dominant_dofs(mass, shapes).tolist() == [0, 1]


def test_dominant_dof_is_invariant_to_scaling_and_dof_order():
    rng = np.random.default_rng(7)
    a = rng.normal(size=(5, 5))
    mass = a @ a.T + 5 * np.eye(5)  # symmetric positive definite
    shapes = rng.normal(size=(5, 5)) + 1j * rng.normal(size=(5, 5))
    expected = dominant_dofs(mass, shapes)
    scale = np.exp(1j * rng.uniform(0, 2 * np.pi, 5)) * rng.uniform(0.1, 10, 5)  # any complex scaling per mode
    assert dominant_dofs(mass, shapes * scale[None, :]).tolist() == expected.tolist()
    perm = rng.permutation(5)
    assert dominant_dofs(mass[np.ix_(perm, perm)], shapes[perm]).tolist() == perm.argsort()[expected].tolist()


def test_modal_set_method_agrees_with_the_function():
    mass = np.diag([2.0, 3.0, 50.0])
    shapes = np.array([[1.0, 0.2, 0.0], [0.1, 1.0, 0.3], [0.0, 0.01, 0.2]])
    modes = ModalSet(frequency=np.array([1.0, 2.0, 3.0]), damping=np.zeros(3), shapes=shapes,
                     poles=2j * np.pi * np.array([1.0, 2.0, 3.0]), dofs=("a", "b", "c"), method="undamped")
    assert modes.dominant_dofs(mass).tolist() == dominant_dofs(mass, shapes).tolist() == [0, 1, 2]


def test_dominant_dofs_names_mismatched_shapes():
    with pytest.raises(DataError, match=r"square mass matrix \(n_dof, n_dof\).*got mass \(2, 2\) and shapes \(3, 1\)"):
        dominant_dofs(np.eye(2), np.ones((3, 1)))
