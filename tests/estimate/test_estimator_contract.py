"""One contract for every estimator, as scikit-learn's ``check_estimator`` checks its own.

The estimators are every method of the registry (``cappe.estimate.METHODS``: a method added there is checked here
without a line more) and the black-box models of :mod:`cappe.identify` (ARX, ARMAX, OE, Box-Jenkins). Each one:

- ``__init__`` only stores its settings, unchanged and under their names (any object is accepted there;
  validation happens in ``fit``);
- ``get_params`` returns every ``__init__`` argument, ``type(est)(**est.get_params())`` has the same settings,
  ``set_params`` changes them and refuses unknown names;
- every learned value (``estimate_``, ``params_`` ... or ``predict``, ``poles`` ...) raises NotFittedError before
  ``fit``;
- ``fit`` returns ``self``, and two fits with the same seed give identical results;
- data of the wrong type or kind, and NaN in the data, raise DataError with a message naming what was received.

Data: the two-mass rig (builtin) simulated for 0.5 s at 1 kHz with 1 % noise, and a 400-sample second-order ARMAX
record for the black-box models. Settings that keep a method's fit under a second or two on this rig are in
``SETTINGS`` (fewer transfer-function pairs and starts, a small GSA); every method runs with its own defaults for
everything else.
"""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
import scipy.signal as sig

from cappe.estimate import METHODS, Estimator, estimator_class, simulate_data
from cappe.exceptions import DataError, ModelError, NotFittedError
from cappe.identify import ARMAX, ARX, OE, BoxJenkins, PolynomialModel
from cappe.model import NumericModel, load_model
from cappe.systems import FRFData, TimeData
from cappe.systems.modal import ModalData, ModalDataSet

UNKNOWNS = ("k11", "k22")
TRUTH = {"k11": 1.3e6, "k22": 0.25e6}
PAIRS = [("F1", "d1"), ("F1", "d2")]
#: per method, settings that keep the fit short on the two-mass rig (the method's defaults otherwise)
SETTINGS: dict[str, dict[str, Any]] = {
    "two-step-tf": {"pairs": PAIRS, "n_starts": 2},
    # the default root form ("frequency-damping") puts k22 on its bound with 1 % noise on a record this short (it
    # does not on 2 s); the complex form recovers it, so the check below that the fit is a fit holds
    "two-step-zp": {"pairs": PAIRS, "n_starts": 2, "roots": "complex"},
    "hybrid": {"settings": {"two-step-tf": {"pairs": PAIRS, "n_starts": 2}}},
    "automated-gsa": {"n_gsa": 64, "n_opt": 4, "n_permutations": 0, "n_workers": 1},
}
#: the black-box models: class, orders
POLYNOMIAL: dict[str, tuple[type[PolynomialModel], dict[str, Any]]] = {
    "ARX": (ARX, {"na": 2, "nb": 2}),
    "ARMAX": (ARMAX, {"na": 2, "nb": 2, "nc": 1}),
    "OE": (OE, {"nb": 2, "nf": 2}),
    "BoxJenkins": (BoxJenkins, {"nb": 2, "nc": 1, "nd": 1, "nf": 2}),
}
CASES = [*METHODS, *POLYNOMIAL]


# -- the estimators and their data -------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def rig() -> NumericModel:
    return NumericModel(load_model("builtin:two-mass-rig"))


@pytest.fixture(scope="module")
def datasets(rig) -> dict[str, Any]:
    """One data object per kind a method takes (``METHODS[method][2]``), and the black-box record."""
    truth = rig.structure.resolve_parameters(TRUTH)
    out = {kind: simulate_data(rig, kind, truth, noise=0.01, rng=np.random.default_rng(7), duration=0.5)
           for kind in ("time", "frf", "modal")}
    # y = (0.5 q^-1 + 0.2 q^-2) / (1 - 1.2 q^-1 + 0.5 q^-2) u + (1 + 0.4 q^-1) / (1 - 1.2 q^-1 + 0.5 q^-2) e
    rng = np.random.default_rng(8)
    u, e = rng.standard_normal(400), 0.05 * rng.standard_normal(400)
    a = [1.0, -1.2, 0.5]
    y = sig.lfilter([0.0, 0.5, 0.2], a, u) + sig.lfilter([1.0, 0.4], a, e)
    out["polynomial"] = TimeData.from_rate(100.0, {"u": u, "y": y})
    return out


def kind_of(case: str) -> str:
    return METHODS[case][2] if case in METHODS else "polynomial"


def make(case: str, rig: NumericModel, **settings: Any) -> Any:
    """A fresh estimator of ``case`` with the test's settings (``settings`` override them)."""
    if case in METHODS:
        return estimator_class(case)(rig, list(UNKNOWNS), rng=0, **{**SETTINGS.get(case, {}), **settings})
    cls, orders = POLYNOMIAL[case]
    return cls(**{**orders, **settings})


def fit(estimator: Any, data: Any) -> Any:
    if isinstance(estimator, PolynomialModel):
        return estimator.fit(data, inputs="u", output="y")
    return estimator.fit(data)


def learned(estimator: Any) -> dict[str, Any]:
    """What a fit learned, for comparing two fits."""
    if isinstance(estimator, PolynomialModel):
        return {"parameters": estimator.parameters_, "covariance": estimator.covariance_, "loss": estimator.loss_}
    est = estimator.estimate_
    return {"values": est.values, "std": est.std, "cost": est.cost, "success": est.success,
            "message": est.message}


def setting_names(cls: type) -> list[str]:
    # a ``**deprecated`` catch-all (AutomatedIdentification's old run options) is not a setting
    return [p.name for p in list(inspect.signature(cls.__init__).parameters.values())[1:]
            if p.kind not in (inspect.Parameter.VAR_POSITIONAL, inspect.Parameter.VAR_KEYWORD)]


def test_every_registered_method_and_black_box_model_is_checked():
    # the registry is the list of estimators: each of its classes is an Estimator, and this file runs them all
    assert all(issubclass(estimator_class(m), Estimator) for m in METHODS)
    assert set(SETTINGS) <= set(METHODS)
    # and every black-box structure of cappe.identify
    assert {cls.__name__ for cls in PolynomialModel.__subclasses__()} == set(POLYNOMIAL)


# -- __init__ and the settings -----------------------------------------------------------------------------------
class _Setting:
    """A value no setting could validly take: __init__ must store it as it is."""

    def __init__(self, name: str) -> None:
        self.name = name

    def __repr__(self) -> str:
        return f"<{self.name}>"


@pytest.mark.parametrize("case", CASES)
def test_init_only_stores_settings(case, rig):
    cls = type(make(case, rig))
    given = {name: _Setting(name) for name in setting_names(cls)}
    estimator = cls(**given)  # no validation, no conversion: that happens in fit
    assert sorted(vars(estimator)) == sorted(given), "__init__ must set exactly its arguments, nothing learned"
    for name, value in given.items():
        assert getattr(estimator, name) is value, f"{cls.__name__}.__init__ changed setting {name!r}"


@pytest.mark.parametrize("case", CASES)
def test_get_params_round_trip_and_set_params(case, rig):
    estimator = make(case, rig)
    cls = type(estimator)
    params = estimator.get_params()
    assert list(params) == setting_names(cls)  # every __init__ argument, in signature order
    clone = cls(**params)
    assert clone is not estimator
    assert all(clone.get_params()[k] is v for k, v in params.items())

    name = next(k for k in params if k not in ("model", "unknowns"))
    marker = _Setting(name)
    assert estimator.set_params(**{name: marker}) is estimator
    assert estimator.get_params()[name] is marker
    assert clone.get_params()[name] is params[name]  # the copy keeps its own settings
    with pytest.raises(ModelError, match=rf"{cls.__name__} has no setting\(s\) \['colour'\]; its settings are \["):
        estimator.set_params(colour="red")


@pytest.mark.parametrize(("cls", "iteration"), [(ARMAX, {"max_iter": 7, "tol": 1e-6}), (OE, {"max_iter": 7}),
                                                (BoxJenkins, {"tol": 1e-6})])
def test_black_box_settings_include_the_iteration_limits(cls, iteration):
    # get_params of ARMAX, OE and BJ left max_iter and tol out: a copy silently went back to the defaults
    orders = POLYNOMIAL[cls.__name__][1]
    model = cls(**orders, **iteration)
    assert model.get_params() == {**model.get_params(), **iteration}
    copy = cls(**model.get_params())
    assert (copy.max_iter, copy.tol) == (model.max_iter, model.tol)
    # the repr shows the orders always and an iteration limit only where it is not the default
    assert repr(copy).startswith(f"{cls.__name__}(")
    assert all(f"{k}={v!r}" in repr(copy) for k, v in iteration.items())
    assert "max_iter" not in repr(cls(**orders))


# -- use before fit ------------------------------------------------------------------------------------------------
def before_fit_uses(estimator: Any) -> dict[str, Callable[[], Any]]:
    """Every learned value the estimator offers, as a call."""
    cls = type(estimator)
    if isinstance(estimator, PolynomialModel):
        data = TimeData.from_rate(100.0, {"u": np.ones(10), "y": np.ones(10)})
        return {
            "predict": lambda: estimator.predict(data),
            "residuals": lambda: estimator.residuals(data),
            "fit_percent": lambda: estimator.fit_percent(data),
            **{name: getattr(estimator, name) for name in ("poles", "zeros", "to_discrete_tf", "to_state_space",
                                                           "to_transfer_function", "to_zpk", "continuous_poles",
                                                           "modal_parameters")},
        }
    names = [n for n in dir(cls) if n.endswith("_") and not n.startswith("_")
             and isinstance(inspect.getattr_static(cls, n), property)]
    assert {"estimate_", "params_", "cost_function_"} <= set(names)
    uses: dict[str, Callable[[], Any]] = {name: (lambda name=name: getattr(estimator, name)) for name in names}
    uses["cost_slice"] = lambda: estimator.cost_slice(list(UNKNOWNS))
    return uses


@pytest.mark.parametrize("case", CASES)
def test_use_before_fit_raises_not_fitted(case, rig):
    estimator = make(case, rig)
    expected = f"{type(estimator).__name__} is not fitted yet; call fit("
    wrong = {}
    for name, use in before_fit_uses(estimator).items():
        try:
            use()
        except NotFittedError as exc:
            if expected not in str(exc):
                wrong[name] = str(exc)
        except Exception as exc:  # noqa: BLE001 - any other error is a failure of the contract, reported by name
            wrong[name] = f"{type(exc).__name__}: {exc}"
        else:
            wrong[name] = "no error"
    assert not wrong, f"used before fit, these do not raise NotFittedError ({expected!r}): {wrong}"


# -- fit -----------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("case", CASES)
def test_fit_returns_self_and_seeded_fits_are_identical(case, rig, datasets):
    data = datasets[kind_of(case)]
    first, second = make(case, rig), make(case, rig)
    assert fit(first, data) is first
    assert fit(second, data) is second
    a, b = learned(first), learned(second)
    assert a.keys() == b.keys()
    for key in a:
        # the same seed (rng=0) and the same data: equal to the last bit, not just close
        np.testing.assert_array_equal(a[key], b[key], err_msg=f"{case}: {key} differs between two seeded fits")
    if case in METHODS:
        assert first.estimate_.success, first.estimate_.message
        assert first.estimate_.names == UNKNOWNS
        # the truth within 25 %: the contract fits are short, not accurate, but they must be fits
        values = np.array([TRUTH[n] for n in UNKNOWNS])
        np.testing.assert_allclose(first.estimate_.values, values, rtol=0.25)
    else:
        assert first.success_


# -- bad input -------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize(("bad", "received"), [("data.csv", "str"), (np.zeros((2, 100)), "ndarray")])
def test_wrong_data_type_raises_data_error(case, rig, bad, received):
    with pytest.raises(DataError, match=rf"needs? .*; got {received}|takes .*; got {received}"):
        fit(make(case, rig), bad)


@pytest.mark.parametrize("case", CASES)
def test_data_of_another_kind_raises_data_error(case, rig, datasets):
    other = datasets["modal"] if kind_of(case) in ("time", "frf", "polynomial") else datasets["time"]
    with pytest.raises(DataError, match=rf"got {type(other).__name__}"):
        fit(make(case, rig), other)


def with_nan(data_set: ModalDataSet, field: str) -> ModalDataSet:
    value = np.array(getattr(data_set, field))
    value[..., -1] = np.nan  # the last mode
    return dataclasses.replace(data_set, **{field: value})


# (the feature map compares frequencies and damping ratios only; it does not read shapes)
@pytest.mark.parametrize(("case", "field"), [(m, f) for m in METHODS if METHODS[m][2] == "modal"
                                             for f in ("frequency", "damping", "shapes")
                                             if (m, f) != ("feature-map", "shapes")])
def test_nan_in_modal_data_raises_data_error(case, rig, datasets, field):
    reference = datasets["modal"]
    bad = ModalData(reference.sensors, (with_nan(reference.sets[0], field), *reference.sets[1:]), reference.source)
    last = reference.sets[0].n_modes
    what = {"frequency": "frequencies", "damping": "damping ratios", "shapes": "shapes"}[field]
    with pytest.raises(DataError, match=rf"set 0 \(position \{{\}}\): modes \[{last}\] have non-finite {what}"):
        fit(make(case, rig), bad)


def test_nan_in_time_data_cannot_reach_an_estimator(datasets):
    # every time-data method and the black-box models take TimeData, which refuses NaN when it is built
    record = datasets["time"]
    values = record.values.copy()
    values[1, 5] = np.nan
    with pytest.raises(DataError, match=rf"channel '{record.channels[1]}' has 1 non-finite value\(s\) \(NaN or Inf\)"):
        TimeData(record.time, values, record.channels, record.units)


@pytest.mark.parametrize("case", [m for m in METHODS if METHODS[m][2] == "frf"])
def test_frf_data_without_a_finite_line_raise_data_error(case, rig, datasets):
    # FRFData may hold non-finite lines (a model FRF is inf at an undamped resonance); the FRF methods skip them,
    # and data with no finite line at all are refused
    frf: FRFData = datasets["frf"]
    bad = dataclasses.replace(frf, H=np.full(frf.H.shape, np.nan + 0j))
    with pytest.raises(DataError, match="FRF data have no line with a finite, non-zero response"):
        fit(make(case, rig), bad)
