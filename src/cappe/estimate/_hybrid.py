"""Hybrid estimation (thesis 3.6.6): a fast, robust method provides the start, an efficient one refines it.

The default chain is the two-step transfer-function fit (global, multi-start, cheap once the black-box model is
identified) refined by the one-step output error (statistically efficient, but local). Any registered methods can be
chained; each stage may take its own data.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from cappe._rng import RandomLike
from cappe.estimate._base import Estimator, Fitted
from cappe.estimate._registry import estimator_class
from cappe.estimate._result import ParameterEstimate
from cappe.estimate._space import ParameterSpace
from cappe.exceptions import DataError, ModelError
from cappe.model import NumericModel, Structure

__all__ = ["HybridEstimator"]


class HybridEstimator(Estimator):
    """Chain of estimators, each started at the previous one's estimate (clipped into the bounds).

    Parameters
    ----------
    model, unknowns, bounds, start, values, rng
        As for every :class:`Estimator`.
    stages : sequence of str
        Method names, first to last (default ``("two-step-tf", "one-step")``).
    settings : mapping, optional
        ``{method: {keyword: value}}`` passed to each stage's constructor.

    Notes
    -----
    ``fit(data)`` takes one data object used by every stage, or a mapping ``{method: data}``. The result is the
    last stage's estimate; the diagnostics hold every stage's values, cost and success.
    """

    method = "hybrid"

    def __init__(
        self,
        model: NumericModel | Structure,
        unknowns: Sequence[str] | None = None,
        *,
        stages: Sequence[str] = ("two-step-tf", "one-step"),
        settings: Mapping[str, Mapping[str, Any]] | None = None,
        bounds: Mapping[str, Sequence[float]] | None = None,
        start: Mapping[str, float] | None = None,
        values: Mapping[str, float] | None = None,
        rng: RandomLike = None,
    ) -> None:
        super().__init__(model, unknowns, bounds=bounds, start=start, values=values, rng=rng)
        self.stages = stages
        self.settings = settings

    def _fit(
        self, model: NumericModel, space: ParameterSpace, data: Any, rng: np.random.Generator
    ) -> ParameterEstimate | Fitted:
        stages = list(self.stages)
        if len(stages) < 2 or "hybrid" in stages:
            msg = f"a hybrid needs two or more stages of other methods; got {stages}"
            raise ModelError(msg)
        if isinstance(data, Mapping):
            missing = [s for s in stages if s not in data]
            if missing:
                msg = f"hybrid data mapping has no data for stage(s) {missing}; it has {sorted(data)}"
                raise DataError(msg)
        start = space.mapping(space.start)
        history: list[dict[str, Any]] = []
        result: ParameterEstimate | None = None
        for k, stage in enumerate(stages):
            cls = estimator_class(stage)
            options = dict((self.settings or {}).get(stage, {}))
            estimator = cls(
                model, list(space.names), bounds={n: (lo, hi) for n, lo, hi in zip(space.names, space.lower,
                                                                                 space.upper, strict=True)},
                start=start, values=self.values, rng=int(rng.integers(2**31)), **options,
            )
            stage_data = data[stage] if isinstance(data, Mapping) else data
            result = estimator.fit(stage_data).estimate_
            history.append({"method": stage, "parameters": result.parameters, "cost": result.cost,
                            "success": result.success, "message": result.message})
            if k < len(stages) - 1:
                if not np.all(np.isfinite(result.values)):
                    msg = f"hybrid stage {stage!r} returned no usable estimate ({result.message})"
                    return ParameterEstimate.failed(self.method, space.names, msg, {"stages": history})
                start = space.mapping(np.clip(result.values, space.lower, space.upper))
        assert result is not None  # stages is non-empty
        diag = dict(result.diagnostics)
        diag["stages"] = history
        # the hybrid's cost is its last stage's
        return Fitted(replace(result, method=self.method, diagnostics=diag), estimator.cost_function_)
