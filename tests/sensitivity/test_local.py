"""Local sensitivities, percentage tables (thesis Table 5.3), the modal cost and cost landscapes."""

from __future__ import annotations

import numpy as np
import pytest

from cappe.correlate import mac
from cappe.exceptions import DataError, ModelError
from cappe.io import ModalData
from cappe.modal import ModalEngine
from cappe.model import NumericModel
from cappe.sensitivity import ModalCost, cost_landscape, modal_sensitivity, percentage_table


def test_percentage_table_of_a_decoupled_oscillator_is_closed_form(two_mass):
    """With k12 = c12 = 0 the rig is two single oscillators: f ~ m^-1/2 and zeta ~ c m^-1/2 exactly."""
    params = {"k12": 0.0, "c12": 0.0}
    table = percentage_table(two_mass, params, percent=10, parameters=["m1", "c11", "k11", "m2"])
    nm = NumericModel(two_mass)
    # mode 2 is mass 1 (k11/m1 = 1.38e6/1.39 > k22/m2 = 0.24e6/1.09)
    np.testing.assert_allclose(table.frequency[1], np.sqrt(1.38e6 / 1.39) / (2 * np.pi), rtol=1e-12)
    assert table.parameters == ("m1", "m1", "c11", "c11", "k11", "k11", "m2", "m2")
    np.testing.assert_array_equal(table.change_percent, [10, -10] * 4)
    expected_f = 100 * (np.array([1.1, 0.9]) ** -0.5 - 1)  # m1 +-10 % (Table 5.3: -4.7, +5.4)
    np.testing.assert_allclose(table.frequency_change_percent[:2, 1], expected_f, rtol=1e-10)
    np.testing.assert_allclose(table.damping_change_percent[:2, 1], expected_f, rtol=1e-10)
    np.testing.assert_allclose(table.damping_change_percent[2:4, 1], [10.0, -10.0], rtol=1e-10)  # c11 (Table 5.3)
    np.testing.assert_allclose(table.frequency_change_percent[4:6, 1], 100 * (np.array([1.1, 0.9]) ** 0.5 - 1),
                               rtol=1e-10)
    # the other mode does not move at all
    np.testing.assert_allclose(table.frequency_change_percent[:6, 0], 0.0, atol=1e-10)
    assert nm.parameter_names[0] == "m1"


def test_percentage_table_contract_and_small_changes_match_derivatives(spindle):
    table = percentage_table(spindle, percent=0.01)
    data = table.to_dict()
    assert set(data) == {"percent", "position", "modes", "rows"}
    assert [r["parameter"] for r in data["rows"][:2]] == [spindle.parameters[0].name] * 2
    assert set(data["rows"][0]) == {"parameter", "change_percent", "frequency_change_percent", "damping_change_percent"}
    freq = [m["frequency"] for m in data["modes"]]
    assert freq == sorted(freq)
    sens = modal_sensitivity(spindle)
    nf, nz = sens.normalized()
    # a +0.01 % change moves Q by 0.01 * (p/Q dQ/dp) per cent to first order; the second-order remainder is
    # ~1e-4 relative, so compare to 1e-3 of the largest sensitivity
    plus = table.frequency_change_percent[0::2] / 0.01
    np.testing.assert_allclose(plus, nf.T, atol=1e-3 * np.abs(nf).max())
    plus_z = table.damping_change_percent[0::2] / 0.01
    np.testing.assert_allclose(plus_z, nz.T, atol=1e-3 * np.abs(nz).max())
    assert "f1 %" in table.to_dataframe().columns
    assert table.to_text().splitlines()[0].split()[:3] == ["parameter", "change", "f1"]


def test_percentage_table_errors(two_mass):
    with pytest.raises(ModelError, match=r"percent must lie in \(0, 100\); got 150"):
        percentage_table(two_mass, percent=150)
    with pytest.raises(ModelError, match="unknown parameter 'k33' for model 'two-mass-rig'"):
        percentage_table(two_mass, parameters=["k33"])


def reference_for(structure, params=None) -> ModalData:
    return ModalEngine(structure, sensors=["n1:x", "n2:x"]).modal_data(params=params, exact=False)


def test_modal_cost_is_zero_at_the_reference_and_its_gradient_matches_finite_differences(two_mass):
    ref = reference_for(two_mass)
    cost = ModalCost(two_mass, ref)
    nm = NumericModel(two_mass)
    assert cost(nm.nominal) < 1e-12  # same first-order modes: zero up to the round-off of 1 - MAC (~1e-16)
    p = nm.nominal * np.array([1.1, 0.95, 1.05, 0.9, 1.1, 1.2, 1.0, 0.8])
    grad = cost.gradient(p)
    for i in range(p.size):
        if p[i] == 0:
            continue
        h = 1e-6 * p[i]
        dp = np.zeros_like(p)
        dp[i] = h
        fd = (cost(p + dp) - cost(p - dp)) / (2 * h)
        # central differences at relative step 1e-6: ~1e-8 relative agreement for this smooth cost
        np.testing.assert_allclose(grad[i], fd, rtol=1e-5, atol=1e-9 * np.abs(grad).max())
    batch = cost(np.vstack([nm.nominal, p]))
    assert batch.shape == (2,)
    assert batch[1] == pytest.approx(cost(p), rel=1e-12)


def test_modal_cost_pairing_uses_the_mac(two_mass):
    ref = reference_for(two_mass)
    cost = ModalCost(two_mass, ref)
    rng = np.random.default_rng(9)
    shapes = rng.normal(size=(5, 2, 2))
    index, values = cost._pairing(shapes, ref.sets[0].shapes)
    for b in range(5):
        full = mac(ref.sets[0].shapes, shapes[b])  # the public criterion, one sample at a time
        np.testing.assert_array_equal(index[b], np.argmax(full, axis=1))
        np.testing.assert_allclose(values[b], full.max(axis=1), rtol=1e-12)


def test_cost_landscape_has_its_minimum_at_the_true_parameters(two_mass, tmp_path):
    """Thesis Fig. 4.5: the cost over m1 and k11 with the other parameters at their true values."""
    ref = reference_for(two_mass)
    cost = ModalCost(two_mass, ref)
    nm = NumericModel(two_mass)
    land = cost_landscape(cost, nm.parameter_names, nm.nominal, ("m1", "k11"), ((0.7, 2.08), (0.69e6, 2.07e6)),
                          n=(21, 21))
    x, y, value = land.minimum
    assert (x, y) == pytest.approx((1.39, 1.38e6), rel=1e-12)
    assert value < 1e-12  # round-off of 1 - MAC
    assert land.values.shape == (21, 21)
    out = land.plot(tmp_path / "landscape.png")
    assert out.stat().st_size > 1000
    with pytest.raises(ModelError, match=r"range of 'm1' must have lo < hi; got \(2.0, 1.0\)"):
        cost_landscape(cost, nm.parameter_names, nm.nominal, ("m1", "k11"), ((2.0, 1.0), (1.0, 2.0)))
    with pytest.raises(ModelError, match="unknown parameter 'mass'"):
        cost_landscape(cost, nm.parameter_names, nm.nominal, ("mass", "k11"), ((1.0, 2.0), (1.0, 2.0)))


def test_modal_cost_rejects_zero_reference_damping(two_mass):
    ref = reference_for(two_mass, params={"c11": 0.0, "c22": 0.0})
    with pytest.raises(DataError, match="reference set 0 has a zero damping ratio"):
        ModalCost(two_mass, ref)
