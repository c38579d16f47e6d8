"""fit_black_box: order selection, pruning and refinement in one call, against a known discrete system."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal as sig

from cappe.exceptions import DataError
from cappe.identify import ARX, OE, fit_black_box, prune, select_order
from cappe.systems import TimeData

FS = 100.0  # Hz
A = [1.0, -1.8, 0.95]  # one lightly damped mode: z = 0.9 +- 0.37j, 6.3 Hz, 6.5 % damping
B = [0.0, 1.0, 0.5]


def truth():
    """The mode of A in closed form: s = fs log z, f = |s| / 2 pi, zeta = -Re s / |s|."""
    s = FS * np.log(np.roots(A)[np.argmax(np.roots(A).imag)])
    return abs(s) / (2 * np.pi), -s.real / abs(s)


def record(*, equation_error: bool, seed: int = 0, n: int = 4000) -> TimeData:
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    e = 0.05 * rng.standard_normal(n)
    y = sig.lfilter(B, A, u) + (sig.lfilter([1.0], A, e) if equation_error else e)
    return TimeData.from_rate(FS, {"u": u, "y": y})


def test_chosen_order_recovers_the_mode():
    fit = fit_black_box(record(equation_error=True), inputs="u", output="y", max_order=5)
    assert fit.orders == {"na": 2, "nb": 2, "nk": 1}  # the ARX structure of the data
    assert fit.order_selection is not None
    assert fit.pruned == ()
    assert fit.refined is None
    f, zeta = truth()
    # seeded: 3e-5 and 5e-3 relative errors observed; 0.1 % and 2 % leave a margin for other BLAS builds
    np.testing.assert_allclose(fit.modes.frequency, [f], rtol=1e-3)
    np.testing.assert_allclose(fit.modes.damping, [zeta], rtol=2e-2)
    assert fit.quality.stable
    assert fit.quality.fit_horizon == "simulation"


def test_pruned_and_refined_equals_the_steps_done_by_hand():
    data = record(equation_error=False, seed=1)
    fit = fit_black_box(data, inputs=["u"], output="y", order=10, prune=1, refine=True)
    model = ARX(10, 10, 1).fit(data, inputs=["u"], output="y")
    pruned = prune(model, input="u", n_modes=1)
    refined = OE(2, 2, 1).fit(data, inputs=["u"], output="y")  # 2 poles of the one pruned mode
    np.testing.assert_array_equal(fit.model.poles(), model.poles())  # same computation: bit for bit
    np.testing.assert_array_equal(fit.pruned[0].modes.frequency, pruned.modes.frequency)
    assert fit.refined is not None
    np.testing.assert_array_equal(fit.refined.poles(), refined.poles())
    np.testing.assert_array_equal(fit.poles, refined.continuous_poles())
    # the output-error refit removes ARX's noise bias: seeded errors 4e-6 and 1e-4; bounds as above
    f, zeta = truth()
    np.testing.assert_allclose(fit.modes.frequency, [f], rtol=1e-3)
    np.testing.assert_allclose(fit.modes.damping, [zeta], rtol=2e-2)
    out = fit.to_dict()
    assert out["refined"]["orders"] == {"nb": 2, "nf": 2, "nk": 1}
    assert set(out["pruning"]) == {"u"}
    assert out["input"] == "u"  # the first transfer function at the top level
    assert out["denominator"] == out["transfer_functions"][0]["denominator"]
    assert len(out["denominator"]) == 3


def test_auto_order_uses_select_order():
    data = record(equation_error=True, seed=2, n=1000)
    fit = fit_black_box(data, inputs="u", output="y", structure="oe", max_order=3, criterion="bic")
    selection = select_order(data, inputs=["u"], output="y", structure="oe", orders=range(1, 4), criterion="bic")
    assert fit.order_selection is not None
    assert fit.order_selection.best_orders == selection.best_orders
    assert fit.to_dict()["order_selection"] == selection.to_dict()


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"structure": "fir"}, r"structure must be one of arx, armax, oe, bj; got 'fir'"),
        ({"order": 0}, r"order must be a positive integer or 'auto'; got 0"),
        ({"order": 2, "prune": "some"}, r"prune must be a positive number of modes, 'auto' or None; got 'some'"),
        ({"order": 2, "refine": True}, r"refine and cutoff act on a pruned model; give prune=N or prune='auto'"),
        ({"order": 2, "cutoff": 30.0}, r"refine and cutoff act on a pruned model"),
    ],
)
def test_bad_settings_are_named(settings, message):
    with pytest.raises(DataError, match=message):
        fit_black_box(record(equation_error=True, n=200), inputs="u", output="y", **settings)
