"""The model check of ``cappe model check``: conditioning, rigid-body modes, controllability, observability and
invertibility of a structure model at one parameter vector and axis position.

It lives in :mod:`cappe.exact` (not in :mod:`cappe.model`) because its rank tests are this package's exact algebra,
and :mod:`cappe.exact` already builds on :mod:`cappe.model` and :mod:`cappe.systems`.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from cappe.exact.rank import (
    InvertibilityResult,
    PBHRanks,
    controllability_rank,
    observability_rank,
    pbh_ranks,
    sain_massey,
)
from cappe.exact.rational import exact_state_space
from cappe.model.numeric import NumericModel
from cappe.model.structure import Structure

__all__ = ["EXACT_STATE_LIMIT", "ModelCheck", "check_model"]

#: Largest state count for which :func:`check_model` runs the exact rational rank tests unless told otherwise
#: (rational Krylov and Sain-Massey matrices of more states take minutes to hours).
EXACT_STATE_LIMIT = 24


@dataclass(frozen=True)
class ModelCheck:
    """Result of :func:`check_model`.

    Attributes
    ----------
    name : str
        Model name.
    n_dof : int
        Number of generalized coordinates.
    condition_M, condition_K : float
        2-norm condition numbers of the mass and stiffness matrices; inf where beyond double precision, and for
        K when the model has rigid-body modes (K is singular).
    rigid_body_modes : tuple of dict
        One per rigid-body (zero-frequency) mode: its shape scaled to a largest entry of 1, as ``{dof: value}``
        over the DOFs that move (rounded to 6 decimals).
    inputs, outputs : tuple of str
        The inputs and outputs of the rank and invertibility tests.
    n_states : int
        2 n_dof, the order of the state-space realization x = [q, q'].
    pbh : PBHRanks
        Controllability and observability ranks by the PBH test in double precision.
    exact : bool
        Whether the exact rational tests ran.
    invertibility : InvertibilityResult or None
        The Sain-Massey test, when ``exact``.
    controllability_rank, observability_rank : int or None
        Exact ranks of the Krylov matrices, when ``exact``.
    """

    name: str
    n_dof: int
    condition_M: float
    condition_K: float
    rigid_body_modes: tuple[dict[str, float], ...]
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    n_states: int
    pbh: PBHRanks
    exact: bool
    invertibility: InvertibilityResult | None = None
    controllability_rank: int | None = None
    observability_rank: int | None = None

    def to_dict(self) -> dict[str, Any]:
        """The result as JSON-ready data (infinite condition numbers as None), as ``cappe model check --json``."""
        cond_m, cond_k = self.condition_M, self.condition_K
        out: dict[str, Any] = {
            "valid": True,
            "n_dof": self.n_dof,
            "condition": {"M": cond_m if np.isfinite(cond_m) else None, "K": cond_k if np.isfinite(cond_k) else None},
            "rigid_body_modes": [dict(m) for m in self.rigid_body_modes],
            "inputs": list(self.inputs),
            "outputs": list(self.outputs),
            "n_states": self.n_states,
            "pbh": self.pbh.to_dict(),
            "exact": self.exact,
        }
        if self.invertibility is not None:
            out["invertibility"] = self.invertibility.to_dict()
            out["controllability_rank"] = self.controllability_rank
            out["observability_rank"] = self.observability_rank
        return out


def check_model(
    model: Structure | NumericModel,
    values: Mapping[str, float] | None = None,
    position: Mapping[str, float] | None = None,
    *,
    inputs: Sequence[str] | None = None,
    outputs: Sequence[str] | None = None,
    exact: bool | None = None,
) -> ModelCheck:
    """Check a structure model: conditioning, rigid-body modes, PBH ranks and, exactly, ranks and invertibility.

    Parameters
    ----------
    model : Structure or NumericModel
        The model (a compiled :class:`~cappe.model.NumericModel` saves compiling it again).
    values : mapping of str to float, optional
        Parameter values by name (SI), overriding the nominal ones.
    position : mapping of str to float, optional
        Axis positions by axis name (the model's unit), overriding the default.
    inputs, outputs : sequence of str, optional
        Inputs and outputs of the rank and invertibility tests (default all of the model's).
    exact : bool, optional
        Run the exact rational tests (symbolic derivation, Krylov ranks, Sain-Massey); default: up to
        :data:`EXACT_STATE_LIMIT` states.

    Returns
    -------
    ModelCheck

    Raises
    ------
    ModelError
        If a parameter, axis, input or output is unknown or a value is out of range.

    Notes
    -----
    Hysteretic damping has no exact rational form: the exact tests leave it out without a warning (the PBH test
    takes it as its equivalent viscous damping, as :meth:`~cappe.systems.MechanicalSystem.state_space` does).

    Examples
    --------
    >>> from cappe.exact import check_model
    >>> from cappe.model import load_model
    >>> check = check_model(load_model("builtin:two-mass-rig"))
    >>> check.rigid_body_modes, check.pbh.controllability_rank, check.invertibility.invertible_exact
    ((), 4, True)
    """
    numeric = model if isinstance(model, NumericModel) else NumericModel(model)
    structure = numeric.structure
    values = structure.resolve_parameters(values)
    position = structure.resolve_position(position)
    system = numeric.system(values, position)
    lam, phi = system.undamped_modes()
    rigid = [r for r in range(lam.size) if lam[r] == 0]
    rigid_modes = []
    for r in rigid:
        shape = phi[:, r] / np.abs(phi[:, r]).max()
        rigid_modes.append({d: round(float(v), 6) for d, v in zip(system.dofs, shape, strict=True) if abs(v) > 1e-9})
    with np.errstate(all="ignore"):  # a condition number beyond double precision is inf, said as such
        cond_m = float(np.linalg.cond(system.M))
        cond_k = float(np.linalg.cond(system.K)) if not rigid else float("inf")
    ins = list(inputs) if inputs else list(numeric.input_names)
    outs = list(outputs) if outputs else list(numeric.output_names)
    for n in ins:
        structure.input(n)
    for n in outs:
        structure.output(n)
    n_states = 2 * system.n_dof
    run_exact = exact if exact is not None else n_states <= EXACT_STATE_LIMIT
    with np.errstate(all="ignore"):
        pbh = pbh_ranks(system.state_space(ins, outs))
    check = ModelCheck(
        name=structure.name, n_dof=system.n_dof, condition_M=cond_m, condition_K=cond_k,
        rigid_body_modes=tuple(rigid_modes), inputs=tuple(ins), outputs=tuple(outs), n_states=n_states, pbh=pbh,
        exact=run_exact,
    )
    if not run_exact:
        return check
    with warnings.catch_warnings():  # hysteretic damping: the PBH test above covers it; exactly it is left out
        warnings.simplefilter("ignore")
        exact_ss = exact_state_space(numeric.symbolic, values, position, ins, outs)
    return replace(check, invertibility=sain_massey(exact_ss), controllability_rank=controllability_rank(exact_ss),
                   observability_rank=observability_rank(exact_ss))
