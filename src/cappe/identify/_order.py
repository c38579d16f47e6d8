"""Order selection for the polynomial black-box models by information criteria or validation data (thesis 4.7).

For a model with d estimated parameters fitted to N samples with loss V (mean squared one-step prediction error)
the criteria are, following Ljung (1999, sections 7.4 and 16.4):

- ``FPE = V (1 + d/N) / (1 - d/N)``  (Akaike's final prediction error);
- ``AIC = N log V + 2 d``  (Akaike's information criterion for Gaussian errors with the constant
  ``N (log 2 pi + 1)`` dropped; MATLAB's ``aic(sys)`` adds it back, which does not change the choice);
- ``BIC = N log V + d log N``  (Schwarz / Rissanen MDL, same constant dropped).

All candidates are compared on the same samples: N and V are taken over ``t >= n0`` with n0 the largest lag of
any candidate, so a high-order ARX model does not lose a different number of samples than a low-order one.
With validation data the chosen model is the one with the lowest one-step prediction loss on it (cross
validation, MATLAB ``arxstruc`` / ``selstruc``).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cappe.exceptions import DataError
from cappe.identify._polynomial import ARMAX, ARX, OE, BoxJenkins, PolynomialModel
from cappe.systems.timedata import TimeData

__all__ = ["OrderSelection", "select_order"]

_FIELDS = {
    "arx": ("na", "nb"),
    "armax": ("na", "nb", "nc"),
    "oe": ("nb", "nf"),
    "bj": ("nb", "nc", "nd", "nf"),
}


@dataclass(frozen=True)
class OrderSelection:
    """Result of :func:`select_order`.

    Attributes
    ----------
    structure : str
        ``"arx"``, ``"armax"``, ``"oe"`` or ``"bj"``.
    fields : tuple of str
        Names of the order entries (e.g. ``("na", "nb")``).
    orders : tuple of tuple of int
        The candidates, in the order given.
    n_parameters, loss, aic, bic, fpe : ndarray, shape (n_candidates,)
        d, V (on the common estimation samples) and the three criteria per candidate.
    validation_loss : ndarray or None
        One-step prediction loss on the validation data, when given.
    criterion : str
        What chose the model: ``"aic"``, ``"bic"``, ``"fpe"`` or ``"validation"``.
    best : int
        Index of the chosen candidate.
    model : PolynomialModel
        The chosen, fitted model.
    n_samples : int
        N used in the criteria.

    Examples
    --------
    >>> import numpy as np, scipy.signal as sig
    >>> rng = np.random.default_rng(1)
    >>> u, e = rng.standard_normal(500), 0.1 * rng.standard_normal(500)
    >>> y = sig.lfilter([0, 1.0], [1, -0.5], u) + sig.lfilter([1.0], [1, -0.5], e)  # an ARX(1, 1) system
    >>> data = TimeData.from_rate(1.0, {"u": u, "y": y})
    >>> sel = select_order(data, inputs="u", output="y", orders=[1, 2], criterion="bic")
    >>> sel.best_orders, sel.to_dict()["table"][0]["n_parameters"]
    ({'na': 1, 'nb': 1}, 2)
    """

    structure: str
    fields: tuple[str, ...]
    orders: tuple[tuple[int, ...], ...]
    n_parameters: NDArray[np.int_]
    loss: NDArray[np.float64]
    aic: NDArray[np.float64]
    bic: NDArray[np.float64]
    fpe: NDArray[np.float64]
    validation_loss: NDArray[np.float64] | None
    criterion: str
    best: int
    model: PolynomialModel = field(repr=False)
    n_samples: int = 0

    @property
    def best_orders(self) -> dict[str, int]:
        return dict(zip(self.fields, self.orders[self.best], strict=True))

    def to_dict(self) -> dict[str, Any]:
        rows = []
        for k, o in enumerate(self.orders):
            row: dict[str, Any] = dict(zip(self.fields, o, strict=True))
            row.update(
                n_parameters=int(self.n_parameters[k]),
                loss=float(self.loss[k]),
                aic=float(self.aic[k]),
                bic=float(self.bic[k]),
                fpe=float(self.fpe[k]),
            )
            if self.validation_loss is not None:
                row["validation_loss"] = float(self.validation_loss[k])
            rows.append(row)
        return {
            "structure": self.structure,
            "criterion": self.criterion,
            "n_samples": self.n_samples,
            "best": self.best_orders,
            "table": rows,
        }


def information_criteria(loss: float, n_parameters: int, n_samples: int) -> dict[str, float]:
    """AIC, BIC and FPE of one model (see the module notes for the definitions).

    Examples
    --------
    >>> information_criteria(0.5, 4, 1000)["fpe"] == 0.5 * (1 + 4 / 1000) / (1 - 4 / 1000)
    True
    """
    n, d, v = n_samples, n_parameters, loss
    log_v = math.log(v) if v > 0 else -math.inf
    fpe = v * (1 + d / n) / (1 - d / n) if d < n else math.inf
    return {"aic": n * log_v + 2 * d, "bic": n * log_v + d * math.log(n), "fpe": fpe}


def _candidates(structure: str, orders: Iterable[Any]) -> list[tuple[int, ...]]:
    n_fields = len(_FIELDS[structure])
    out: list[tuple[int, ...]] = []
    for item in orders:
        if isinstance(item, (int, np.integer)) and not isinstance(item, bool):
            out.append((int(item),) * n_fields)
            continue
        if isinstance(item, Sequence) and not isinstance(item, str) and len(item) == n_fields:
            if all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in item):
                out.append(tuple(int(v) for v in item))
                continue
        msg = (
            f"each {structure} candidate order must be an integer n (all orders n) or a tuple "
            f"{_FIELDS[structure]} of integers; got {item!r}"
        )
        raise DataError(msg)
    if not out:
        msg = "orders must list at least one candidate"
        raise DataError(msg)
    return out


def _build(structure: str, o: tuple[int, ...], nk: int | Sequence[int]) -> PolynomialModel:
    if structure == "arx":
        return ARX(o[0], o[1], nk)
    if structure == "armax":
        return ARMAX(o[0], o[1], o[2], nk)
    if structure == "oe":
        return OE(o[0], o[1], nk)
    return BoxJenkins(o[0], o[1], o[2], o[3], nk)


def select_order(
    data: TimeData,
    *,
    inputs: Sequence[str] | str,
    output: str,
    structure: str = "arx",
    orders: Iterable[Any] = range(1, 11),
    nk: int | Sequence[int] = 1,
    criterion: str | None = None,
    validation: TimeData | None = None,
) -> OrderSelection:
    """Fit every candidate order and choose one by AIC, BIC, FPE or validation loss.

    Parameters
    ----------
    data : TimeData
        Estimation data.
    inputs, output : channel names
        As for :meth:`PolynomialModel.fit`.
    structure : {"arx", "armax", "oe", "bj"}
        Model structure.
    orders : iterable
        Candidates: integers n (every order of the structure equal to n) or tuples in the structure's order
        (arx: ``(na, nb)``, armax: ``(na, nb, nc)``, oe: ``(nb, nf)``, bj: ``(nb, nc, nd, nf)``); nb applies to
        every input.
    nk : int or sequence of int
        Input delays, fixed for all candidates.
    criterion : {"aic", "bic", "fpe", "validation"}, optional
        Default ``"validation"`` when validation data are given, else ``"aic"``.
    validation : TimeData, optional
        Independent data for cross validation (one-step prediction loss).

    Returns
    -------
    OrderSelection

    Examples
    --------
    >>> import numpy as np, scipy.signal as sig
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(2000)
    >>> e = 0.1 * rng.standard_normal(2000)
    >>> y = sig.lfilter([0, 1.0, 0.5], [1, -1.5, 0.7], u) + sig.lfilter([1], [1, -1.5, 0.7], e)
    >>> sel = select_order(TimeData.from_rate(1.0, {"u": u, "y": y}), inputs="u", output="y", orders=range(1, 6))
    >>> sel.best_orders
    {'na': 2, 'nb': 2}
    """
    key = structure.lower() if isinstance(structure, str) else structure
    if key not in _FIELDS:
        msg = f"structure must be one of {sorted(_FIELDS)}; got {structure!r}"
        raise DataError(msg)
    crit = criterion if criterion is not None else ("validation" if validation is not None else "aic")
    if crit not in ("aic", "bic", "fpe", "validation"):
        msg = f"criterion must be 'aic', 'bic', 'fpe' or 'validation'; got {criterion!r}"
        raise DataError(msg)
    if crit == "validation" and validation is None:
        msg = "criterion 'validation' needs validation data (validation=TimeData)"
        raise DataError(msg)
    candidates = _candidates(key, orders)
    models = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for o in candidates:
            models.append(_build(key, o, nk).fit(data, inputs=inputs, output=output))
    for w in caught:  # re-issue each fit's warnings (convergence, conditioning) from here
        warnings.warn(w.message, w.category, stacklevel=2)
    n0 = max(m._o.n_lagged for m in models)
    losses = []
    for m in models:
        e = m.residuals(data)[n0:]
        losses.append(float(e @ e) / e.size)
    n = data.n_samples - n0
    d = np.array([m.n_parameters_ for m in models])
    crits = [information_criteria(v, int(k), n) for v, k in zip(losses, d, strict=True)]
    aic = np.array([c["aic"] for c in crits])
    bic = np.array([c["bic"] for c in crits])
    fpe = np.array([c["fpe"] for c in crits])
    val = None
    if validation is not None:
        val_list = []
        for m in models:
            e = m.residuals(validation)[n0:]
            val_list.append(float(e @ e) / max(e.size, 1))
        val = np.array(val_list)
    score = {"aic": aic, "bic": bic, "fpe": fpe, "validation": val}[crit]
    if score is None:  # pragma: no cover - excluded by the argument checks above
        msg = "criterion 'validation' needs validation data"
        raise DataError(msg)
    best = int(np.argmin(score))
    return OrderSelection(
        key,
        _FIELDS[key],
        tuple(candidates),
        d,
        np.array(losses),
        aic,
        bic,
        fpe,
        val,
        crit,
        best,
        models[best],
        n,
    )
