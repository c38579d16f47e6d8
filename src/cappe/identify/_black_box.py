"""A black-box model from time data in one call: select the order, prune to the physical roots, refine.

The pipeline of ``cappe fit`` (thesis 4.7): an ARX, ARMAX, OE or Box-Jenkins model of a given order or of the
order :func:`~cappe.identify.select_order` chooses; optionally :func:`~cappe.identify.prune` to its physical
poles and zeros (per input), and an output-error model of the pruned order refitted to remove the noise bias of
the over-parameterized fit. The result holds every stage's model and the final continuous transfer functions,
poles and modes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from cappe.exceptions import DataError
from cappe.identify._order import OrderSelection, select_order
from cappe.identify._polynomial import ARMAX, ARX, OE, BoxJenkins, ModalParameters, PolynomialModel
from cappe.identify._prune import PrunedModel
from cappe.identify._prune import prune as prune_model
from cappe.systems.timedata import TimeData
from cappe.systems.transfer import TransferFunctionModel

__all__ = ["BLACK_BOX_STRUCTURES", "BlackBoxFit", "FitQuality", "fit_black_box"]

#: The model structures :func:`fit_black_box` fits.
BLACK_BOX_STRUCTURES = ("arx", "armax", "oe", "bj")


@dataclass(frozen=True)
class FitQuality:
    """How well a fitted model reproduces the measured output.

    Attributes
    ----------
    fit_percent : float
        NRMSE fit in % (100 is exact) of the simulated output, or of the one-step prediction when the model is
        unstable.
    fit_horizon : str
        ``"simulation"`` or ``"one-step"``.
    stable : bool
        Whether every discrete pole lies inside the unit circle.
    """

    fit_percent: float
    fit_horizon: str
    stable: bool

    @classmethod
    def of(cls, model: PolynomialModel, data: TimeData) -> FitQuality:
        """The fit of ``model`` to ``data``: simulated when the model is stable, one step ahead otherwise.

        Parameters
        ----------
        model : PolynomialModel
            A fitted model.
        data : TimeData
            The data to compare with (its input and output channels).

        Returns
        -------
        FitQuality
        """
        stable = bool(np.all(np.abs(model.poles()) < 1.0))
        horizon = float("inf") if stable else 1.0
        return cls(model.fit_percent(data, horizon), "simulation" if stable else "one-step", stable)

    def to_dict(self) -> dict[str, Any]:
        return {"fit_percent": self.fit_percent, "fit_horizon": self.fit_horizon, "stable": self.stable}


@dataclass(frozen=True)
class BlackBoxFit:
    """Result of :func:`fit_black_box`.

    Attributes
    ----------
    structure : str
        ``"arx"``, ``"armax"``, ``"oe"`` or ``"bj"``.
    inputs : tuple of str
        Input channels.
    output : str
        Output channel.
    model : PolynomialModel
        The fitted model of the chosen or given order, before pruning and refinement.
    quality : FitQuality
        Fit of :attr:`model`.
    order_selection : OrderSelection or None
        Every candidate order and its criteria, when the order was chosen (``order="auto"``).
    pruned : tuple of PrunedModel
        :attr:`model` pruned to its physical roots, one per input (empty without pruning).
    refined : PolynomialModel or None
        The output-error model of the pruned order, when refined.
    refined_quality : FitQuality or None
        Fit of :attr:`refined`.
    transfer_functions : tuple of TransferFunctionModel
        The final continuous transfer functions, one per input (of the refined, else the pruned, else the fitted
        model).
    poles : ndarray of complex, shape (n_poles,)
        The final continuous poles in rad/s.
    modes : ModalParameters
        The final modes (natural frequencies in Hz, damping ratios).
    """

    structure: str
    inputs: tuple[str, ...]
    output: str
    model: PolynomialModel
    quality: FitQuality
    order_selection: OrderSelection | None
    pruned: tuple[PrunedModel, ...]
    refined: PolynomialModel | None
    refined_quality: FitQuality | None
    transfer_functions: tuple[TransferFunctionModel, ...]
    poles: NDArray[np.complex128]
    modes: ModalParameters

    @property
    def orders(self) -> dict[str, Any]:
        """The polynomial orders and delays of :attr:`model` (its settings without the iteration limits)."""
        return _orders(self.model)

    def to_dict(self) -> dict[str, Any]:
        """The result as JSON-ready data; the first transfer function's fields at the top level, as in
        ``cappe model tf``."""
        out: dict[str, Any] = {"structure": self.structure}
        if self.order_selection is not None:
            out["order_selection"] = self.order_selection.to_dict()
        out["orders"] = self.orders
        out["success"] = bool(self.model.success_)
        out.update(self.quality.to_dict())
        out["loss"] = float(self.model.loss_)
        if self.pruned:
            out["pruning"] = {name: p.to_dict() for name, p in zip(self.inputs, self.pruned, strict=True)}
        if self.refined is not None and self.refined_quality is not None:
            out["refined"] = {"orders": _orders(self.refined), "success": bool(self.refined.success_),
                              **self.refined_quality.to_dict()}
        out.update(self.transfer_functions[0].to_dict())
        out["transfer_functions"] = [tf.to_dict() for tf in self.transfer_functions]
        out["poles"] = _pairs(self.poles)
        out["modes"] = self.modes.to_dict()["modes"]
        return out


def fit_black_box(
    data: TimeData,
    *,
    inputs: Sequence[str] | str,
    output: str,
    structure: str = "arx",
    order: int | Literal["auto"] = "auto",
    criterion: str = "aic",
    max_order: int = 12,
    nk: int = 1,
    prune: int | Literal["auto"] | None = None,
    cutoff: float | None = None,
    max_damping: float = 0.3,
    refine: bool = False,
) -> BlackBoxFit:
    """Fit a black-box model to time data, choosing its order, pruning it and refining it as asked.

    Parameters
    ----------
    data : TimeData
        Uniformly sampled input and output channels (SI units).
    inputs : str or sequence of str
        Input channel(s).
    output : str
        Output channel.
    structure : {"arx", "armax", "oe", "bj"}
        Model structure; every polynomial of it has the order n.
    order : int or "auto"
        The order n, or ``"auto"`` to choose it among 1 to ``max_order`` by ``criterion``.
    criterion : {"aic", "bic", "fpe"}
        With ``order="auto"``: the information criterion.
    max_order : int
        With ``order="auto"``: the largest candidate order.
    nk : int
        Input delay in samples.
    prune : int or "auto", optional
        Prune to this many modes (the thesis rules, then the most significant), or ``"auto"`` (the rules and a
        1 % peak-significance floor); None does not prune.
    cutoff : float, optional
        With ``prune``: anti-alias cut-off in Hz (default 0.8 x Nyquist).
    max_damping : float
        With ``prune``: the largest credible damping ratio.
    refine : bool
        With ``prune``: refit an output-error model of the pruned order (removes the noise bias of ARX).

    Returns
    -------
    BlackBoxFit

    Raises
    ------
    DataError
        If the structure, order, criterion or pruning settings are not valid, or a channel is missing.

    Warns
    -----
    ConvergenceWarning
        When an iterative fit (ARMAX, OE, BJ) does not converge.

    Examples
    --------
    >>> import numpy as np, scipy.signal as sig
    >>> from cappe.systems import TimeData
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(2000)
    >>> e = 0.1 * rng.standard_normal(2000)
    >>> y = sig.lfilter([0, 1.0, 0.5], [1, -1.5, 0.7], u) + sig.lfilter([1], [1, -1.5, 0.7], e)
    >>> fit = fit_black_box(TimeData.from_rate(1.0, {"u": u, "y": y}), inputs="u", output="y", max_order=5)
    >>> fit.orders
    {'na': 2, 'nb': 2, 'nk': 1}
    >>> fit.modes.n_modes
    1
    """
    if structure not in BLACK_BOX_STRUCTURES:
        msg = f"structure must be one of {', '.join(BLACK_BOX_STRUCTURES)}; got {structure!r}"
        raise DataError(msg)
    if order != "auto" and not (isinstance(order, int | np.integer) and order >= 1):
        msg = f"order must be a positive integer or 'auto'; got {order!r}"
        raise DataError(msg)
    if prune is not None and prune != "auto" and not (isinstance(prune, int | np.integer) and prune >= 1):
        msg = f"prune must be a positive number of modes, 'auto' or None; got {prune!r}"
        raise DataError(msg)
    if (refine or cutoff is not None) and prune is None:
        msg = "refine and cutoff act on a pruned model; give prune=N or prune='auto'"
        raise DataError(msg)
    names = [inputs] if isinstance(inputs, str) else list(inputs)
    selection = None
    if order == "auto":
        selection = select_order(data, inputs=names, output=output, structure=structure,
                                 orders=range(1, max_order + 1), nk=nk, criterion=criterion)
        model = selection.model
    else:
        model = _estimator(structure, int(order), nk).fit(data, inputs=names, output=output)
    quality = FitQuality.of(model, data)
    final, poles, modes = model, model.continuous_poles(), model.modal_parameters()
    pruned: list[PrunedModel] = []
    refined, refined_quality = None, None
    if prune is not None:
        n_modes = None if prune == "auto" else int(prune)
        pruned = [
            prune_model(model, input=name, n_modes=n_modes, min_peak=0.01 if n_modes is None else None,
                        cutoff=cutoff, max_damping=max_damping)
            for name in names
        ]
        poles = np.array([r.value for r in pruned[0].poles], dtype=complex)
        modes = pruned[0].modes
        if refine:
            n = 2 * modes.n_modes + int(np.sum(np.abs(poles.imag) == 0))
            refined = OE(n, n, nk).fit(data, inputs=names, output=output)
            refined_quality = FitQuality.of(refined, data)
            final, modes, poles = refined, refined.modal_parameters(), refined.continuous_poles()
    if pruned and refined is None:
        tfs = [p.transfer_function for p in pruned]
    else:
        tfs = [final.to_transfer_function(name, negative_real="reflect") for name in names]
    return BlackBoxFit(
        structure=structure, inputs=tuple(names), output=output, model=model, quality=quality,
        order_selection=selection, pruned=tuple(pruned), refined=refined, refined_quality=refined_quality,
        transfer_functions=tuple(tfs), poles=poles, modes=modes,
    )


def _estimator(structure: str, n: int, nk: int) -> PolynomialModel:
    if structure == "arx":
        return ARX(n, n, nk)
    if structure == "armax":
        return ARMAX(n, n, n, nk)
    if structure == "oe":
        return OE(n, n, nk)
    return BoxJenkins(n, n, n, n, nk)


def _orders(model: PolynomialModel) -> dict[str, Any]:
    return {k: v for k, v in model.get_params().items() if k not in ("max_iter", "tol")}


def _pairs(values: NDArray[Any]) -> list[list[float]]:
    v = np.asarray(values, dtype=complex)
    v = v[np.lexsort((v.imag, np.abs(v)))]
    return [[float(z.real), float(z.imag)] for z in v]
