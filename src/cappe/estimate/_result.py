"""``ParameterEstimate``: the result every estimator returns, saved as ``cappe.estimate/1`` JSON.

::

    {"format": "cappe.estimate/1", "method": "one-step",
     "parameters": {"k11": 1.38e6, ...},
     "uncertainty": {"std": {...}, "ci95": {"k11": [lo, hi], ...}, "correlation": {"names": [...], "matrix": [...]}},
     "identifiable": {"k11": true, ..., "combinations": ["+0.71 m1 -0.71 m2"]},
     "cost": 1.2e-3, "success": true,
     "diagnostics": {"message": ..., "iterations": ..., "evaluations": ..., "rank": ..., "condition_number": ...,
                     "start": {...}, "bounds": {...}, ...}}

Unknown or non-identifiable values are ``null`` in the uncertainty, never a bare number.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cappe.estimate._uncertainty import LocalUncertainty
from cappe.exceptions import DataError
from cappe.io.files import read_json, write_json

__all__ = ["ESTIMATE_FORMAT", "ParameterEstimate", "read_estimate", "write_estimate"]

ESTIMATE_FORMAT = "cappe.estimate/1"
Array = NDArray[np.float64]


@dataclass(frozen=True)
class ParameterEstimate:
    """Estimated physical parameters with their uncertainty.

    Attributes
    ----------
    method : str
        Estimator name (``"direct"``, ``"two-step-tf"``, ``"one-step"``, ``"ekf"``, ``"modal"`` ...).
    names : tuple of str
        Unknowns, in the order of the arrays.
    values : ndarray, shape (n,)
        Estimates in SI units.
    std : ndarray, shape (n,)
        Standard errors (``nan`` where the data do not determine the parameter).
    ci95 : ndarray, shape (n, 2)
        95 % confidence intervals.
    correlation : ndarray, shape (n, n)
        Correlation matrix of the estimates.
    identifiable : ndarray of bool, shape (n,)
        False for parameters the data cannot determine (alone).
    combinations : tuple of str
        Undetermined directions, e.g. ``"+0.71 m1 -0.71 m2"`` (relative changes; only their sum is known).
    cost : float
        Final value of the method's cost.
    success : bool
        Whether the method converged; False always comes with ``message``.
    message : str
        Why it stopped.
    diagnostics : dict
        Method-specific details (iterations, evaluations, rank, condition number, start, bounds, histories ...).
    """

    method: str
    names: tuple[str, ...]
    values: Array
    std: Array
    ci95: Array
    correlation: Array
    identifiable: NDArray[np.bool_]
    combinations: tuple[str, ...] = ()
    cost: float = float("nan")
    success: bool = True
    message: str = ""
    diagnostics: Mapping[str, Any] = field(default_factory=dict)

    @classmethod
    def from_uncertainty(
        cls,
        method: str,
        uncertainty: LocalUncertainty,
        *,
        cost: float,
        success: bool,
        message: str = "",
        diagnostics: Mapping[str, Any] | None = None,
    ) -> ParameterEstimate:
        """Assemble from :func:`jacobian_uncertainty` output; rank and condition go to the diagnostics.

        Parameters
        ----------
        method : str
            Estimator name.
        uncertainty : LocalUncertainty
            Values, standard errors, intervals and correlation of the unknowns (SI).
        cost : float
            Final value of the method's cost.
        success : bool
            Whether the method converged.
        message : str
            Why it stopped.
        diagnostics : mapping, optional
            Method-specific details, added after rank, condition number and degrees of freedom.

        Returns
        -------
        ParameterEstimate
        """
        diag = {"rank": uncertainty.rank, "condition_number": uncertainty.condition_number,
                "degrees_of_freedom": uncertainty.dof, **(diagnostics or {})}
        return cls(
            method, uncertainty.names, uncertainty.values, uncertainty.std, uncertainty.ci95,
            uncertainty.correlation, uncertainty.identifiable, uncertainty.combinations, float(cost), bool(success),
            message, diag,
        )

    @classmethod
    def failed(
        cls, method: str, names: Sequence[str], message: str, diagnostics: Mapping[str, Any] | None = None
    ) -> ParameterEstimate:
        """A result without usable values: everything ``nan``, nothing identifiable, ``success`` False.

        Parameters
        ----------
        method : str
            Estimator name.
        names : sequence of str
            The unknowns.
        message : str
            Why the method failed.
        diagnostics : mapping, optional
            Method-specific details.

        Returns
        -------
        ParameterEstimate
        """
        n = len(names)
        nan = np.full(n, np.nan)
        return cls(method, tuple(names), nan, nan, np.column_stack([nan, nan]), np.full((n, n), np.nan),
                   np.zeros(n, dtype=bool), (), float("nan"), False, message, dict(diagnostics or {}))

    @property
    def parameters(self) -> dict[str, float]:
        """``{name: value}``."""
        return {n: float(v) for n, v in zip(self.names, self.values, strict=True)}

    def relative_error(self, truth: Mapping[str, float]) -> dict[str, float]:
        """``(estimate - truth) / truth`` per unknown (for studies and tests).

        Parameters
        ----------
        truth : mapping name -> float
            True value of every unknown (SI).

        Returns
        -------
        dict
            ``{name: relative error}`` (dimensionless; 0.01 is 1 % high).
        """
        return {n: float(v / truth[n] - 1.0) for n, v in zip(self.names, self.values, strict=True)}

    def to_dict(self) -> dict[str, Any]:
        def num(v: float) -> float | None:
            return float(v) if np.isfinite(v) else None

        identifiable: dict[str, Any] = {n: bool(f) for n, f in zip(self.names, self.identifiable, strict=True)}
        identifiable["combinations"] = list(self.combinations)
        return {
            "format": ESTIMATE_FORMAT,
            "method": self.method,
            "parameters": self.parameters,
            "uncertainty": {
                "std": {n: num(v) for n, v in zip(self.names, self.std, strict=True)},
                "ci95": {n: [num(lo), num(hi)] for n, (lo, hi) in zip(self.names, self.ci95, strict=True)},
                "correlation": {
                    "names": list(self.names),
                    "matrix": [[num(v) for v in row] for row in self.correlation],
                },
            },
            "identifiable": identifiable,
            "cost": num(self.cost),
            "success": self.success,
            "diagnostics": {"message": self.message, **_plain(dict(self.diagnostics))},
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2)

    def to_dataframe(self) -> Any:
        """One row per unknown: value, std, ci95_low, ci95_high, identifiable."""
        import pandas as pd

        return pd.DataFrame(
            {
                "value": self.values,
                "std": self.std,
                "ci95_low": self.ci95[:, 0],
                "ci95_high": self.ci95[:, 1],
                "identifiable": self.identifiable,
            },
            index=pd.Index(self.names, name="parameter"),
        )

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str = "<dict>") -> ParameterEstimate:
        """Validate a parsed ``cappe.estimate/1`` document (the inverse of :meth:`to_dict`).

        Parameters
        ----------
        data : mapping
            The document.
        source : str
            Where it came from (a file name), for messages.

        Returns
        -------
        ParameterEstimate

        Raises
        ------
        DataError
            The format is not ``cappe.estimate/1`` or an entry is missing or malformed.
        """
        if data.get("format") != ESTIMATE_FORMAT:
            msg = f"{source}: format must be {ESTIMATE_FORMAT!r}; got {data.get('format')!r}"
            raise DataError(msg)
        try:
            params = dict(data["parameters"])
            names = tuple(params)
            unc = data.get("uncertainty", {})

            def arr(values: Mapping[str, Any]) -> Array:
                return np.array([np.nan if values.get(n) is None else float(values[n]) for n in names])

            std = arr(unc.get("std", {}))
            ci = unc.get("ci95", {})
            ci95 = np.array([[np.nan if v is None else float(v) for v in ci.get(n, [None, None])] for n in names])
            matrix = unc.get("correlation", {}).get("matrix")
            corr = (
                np.array([[np.nan if v is None else float(v) for v in row] for row in matrix])
                if matrix is not None
                else np.eye(len(names))
            )
            ident = data.get("identifiable", {})
            diagnostics = dict(data.get("diagnostics", {}))
            message = str(diagnostics.pop("message", ""))
            return cls(
                str(data["method"]), names, np.array([float(params[n]) for n in names]), std,
                ci95.reshape(len(names), 2), corr, np.array([bool(ident.get(n, True)) for n in names]),
                tuple(ident.get("combinations", [])), np.nan if data.get("cost") is None else float(data["cost"]),
                bool(data.get("success", True)), message, diagnostics,
            )
        except (KeyError, TypeError, ValueError) as exc:
            msg = f"{source}: not a valid {ESTIMATE_FORMAT} document ({exc})"
            raise DataError(msg) from exc


def _plain(value: Any) -> Any:
    """JSON-ready copy: arrays to lists, non-finite floats to None."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, (np.floating, float)):
        return float(value) if np.isfinite(value) else None
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def write_estimate(path: str | Path, estimate: ParameterEstimate) -> Path:
    """Write ``cappe.estimate/1`` JSON atomically.

    Parameters
    ----------
    path : str or Path
        The file to write.
    estimate : ParameterEstimate
        The estimate.

    Returns
    -------
    Path
        The file written.
    """
    return write_json(path, estimate.to_dict())


def read_estimate(path: str | Path) -> ParameterEstimate:
    """Read ``cappe.estimate/1`` JSON.

    Parameters
    ----------
    path : str or Path
        The file to read.

    Returns
    -------
    ParameterEstimate

    Raises
    ------
    DataError
        The file cannot be read or is not a valid ``cappe.estimate/1`` document (the message names the file).
    """
    p = Path(path)
    data = read_json(p, "estimate file")
    if not isinstance(data, Mapping):
        msg = f"{p}: an estimate file must hold a JSON object; got {type(data).__name__}"
        raise DataError(msg)
    return ParameterEstimate.from_dict(data, str(p))
