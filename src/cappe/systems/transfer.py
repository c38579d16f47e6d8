"""Transfer functions: float, exact-rational and symbolic coefficients (highest power first, monic denominator)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg as sla
from numpy.typing import NDArray

from cappe.exceptions import ModelError
from cappe.systems.statespace import StateSpaceModel

__all__ = ["TransferFunctionModel", "transfer_function"]


@dataclass(frozen=True)
class TransferFunctionModel:
    """SISO transfer function ``num(s) / den(s)`` with a monic denominator.

    ``kind`` is ``"float"`` (numpy floats), ``"exact"`` (sympy Rationals) or ``"symbolic"`` (sympy
    expressions in the parameter names). ``cancelled`` lists exact pole-zero factors removed (as sympy
    polynomials in s, printed), empty for float models.

    Attributes
    ----------
    numerator, denominator : tuple
        Coefficients in powers of s (rad/s), highest first; the denominator is monic.
    input, output : str
        Channel names.
    kind : {"float", "exact", "symbolic"}
        Type of the coefficients.
    cancelled : tuple of str
        Exact pole-zero factors removed.
    """

    numerator: tuple[Any, ...]
    denominator: tuple[Any, ...]
    input: str
    output: str
    kind: str = "float"
    cancelled: tuple[str, ...] = ()

    @property
    def order(self) -> int:
        return len(self.denominator) - 1

    def float_coefficients(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        if self.kind == "symbolic":
            msg = "symbolic coefficients have no float value; substitute parameters first"
            raise ModelError(msg)
        return (np.array([float(c) for c in self.numerator]), np.array([float(c) for c in self.denominator]))

    def poles(self) -> NDArray[np.complex128]:
        return np.asarray(np.roots(self.float_coefficients()[1]), dtype=complex)

    def zeros(self) -> NDArray[np.complex128]:
        num = np.trim_zeros(self.float_coefficients()[0], "f")
        return np.asarray(np.roots(num), dtype=complex) if num.size > 1 else np.zeros(0, complex)

    def evaluate(self, s: complex | NDArray[np.complexfloating[Any]]) -> Any:
        """Value at complex frequency s (rad/s).

        Parameters
        ----------
        s : complex or ndarray of complex
            Complex frequency in rad/s (``2j pi f`` for the frequency response at f Hz).

        Returns
        -------
        complex or ndarray of complex
            Output unit per input unit, shaped like ``s``.
        """
        num, den = self.float_coefficients()
        return np.polyval(num, s) / np.polyval(den, s)

    def dc_gain(self) -> float:
        num, den = self.float_coefficients()
        if den[-1] == 0:
            return float("inf") if num[-1] != 0 else float("nan")
        return float(num[-1] / den[-1])

    def to_dict(self) -> dict[str, Any]:
        def fmt(c: Any) -> Any:
            if self.kind == "float":
                return float(c)
            return str(c)

        out: dict[str, Any] = {
            "input": self.input,
            "output": self.output,
            "numerator": [fmt(c) for c in self.numerator],
            "denominator": [fmt(c) for c in self.denominator],
        }
        if self.kind != "float":
            out["kind"] = self.kind
        if self.cancelled:
            out["cancelled"] = list(self.cancelled)
        return out

    def to_control(self) -> Any:
        import control

        num, den = self.float_coefficients()
        return control.tf(num, den)


def invariant_zeros(a: NDArray[Any], b: NDArray[Any], c: NDArray[Any], d: NDArray[Any]) -> NDArray[np.complex128]:
    """Finite invariant zeros of a SISO realization from the Rosenbrock pencil."""
    n = a.shape[0]
    big = np.block([[a, b], [c, d]])
    e = np.zeros_like(big)
    e[:n, :n] = np.eye(n)
    vals = sla.eigvals(big, e)
    finite = vals[np.isfinite(vals)]
    keep = np.abs(finite) < 1e12 * max(1.0, float(np.abs(np.linalg.eigvals(a)).max()))
    return np.asarray(finite[keep], dtype=complex)


def transfer_function(
    ss: StateSpaceModel,
    input: str | None = None,  # noqa: A002
    output: str | None = None,
) -> TransferFunctionModel:
    """Float SISO transfer function of a continuous state-space model, from its poles, zeros and gain.

    Poles are eigenvalues of A, zeros the invariant zeros of the pencil, and the gain matches the
    response at a test frequency; this avoids the ill-conditioned characteristic-polynomial route.

    Parameters
    ----------
    ss : StateSpaceModel
        A continuous model.
    input, output : str, optional
        Input and output names (may be omitted where the model has one).

    Returns
    -------
    TransferFunctionModel
        Float coefficients, s in rad/s.

    Raises
    ------
    ModelError
        When a coefficient cannot be computed in double precision (many poles of large magnitude: the constant
        term of the denominator is the product of all of them); never returns NaN or inf.
    """
    if ss.is_discrete:
        msg = "transfer_function takes a continuous model"
        raise ModelError(msg)
    i = _pick(ss.input_names, input, "input")
    o = _pick(ss.output_names, output, "output")
    a, b, c, d = ss.A, ss.B[:, [i]], ss.C[[o], :], ss.D[[o]][:, [i]]
    what = f"transfer function {ss.output_names[o]}/{ss.input_names[i]}"
    if not all(np.isfinite(m).all() for m in (a, b, c, d)):
        msg = f"{what}: the state-space matrices are not finite"
        raise ModelError(msg)
    with np.errstate(all="ignore"):  # an overflow is reported below, not warned about
        try:
            poles = np.linalg.eigvals(a)
            zeros = invariant_zeros(a, b, c, d)
            scale = max(1.0, float(np.abs(poles).max()))
            s0 = 1j * scale * 0.7310 + 0.1234 * scale
            g0 = (c @ np.linalg.solve(s0 * np.eye(a.shape[0]) - a, b) + d)[0, 0]
        except np.linalg.LinAlgError as exc:
            msg = f"{what}: its poles, zeros and gain cannot be computed in double precision ({exc})"
            raise ModelError(msg) from exc
        k = g0 * np.prod(s0 - poles) / np.prod(s0 - zeros) if zeros.size else g0 * np.prod(s0 - poles)
        if not np.isfinite(k):  # products of ~100 factors of 1e4 rad/s overflow: a sum of logarithms does not
            k = g0 * np.exp(np.sum(np.log(s0 - poles)) - np.sum(np.log(s0 - zeros)))
        den = np.real_if_close(np.poly(poles), tol=1e6)
        num = np.real_if_close(k * np.poly(zeros), tol=1e6) if zeros.size else np.array([k])
    # poles and zeros come in conjugate pairs, so the coefficients are real up to round-off
    num_r = np.real(num)
    den_r = np.real(den)
    if not (np.isfinite(num_r).all() and np.isfinite(den_r).all()):
        largest = max(float(np.abs(poles).max()), 1.0)
        msg = (f"{what}: its coefficients cannot be computed in double precision ({poles.size} poles of magnitude "
               f"up to {largest:.3g} rad/s; the constant term of the denominator is the product of all of them): "
               "use the state-space model (cappe model ss) or the exact rational coefficients (--exact)")
        raise ModelError(msg)
    return TransferFunctionModel(
        tuple(float(x) for x in num_r), tuple(float(x) for x in den_r), ss.input_names[i], ss.output_names[o], "float"
    )


def _pick(names: Sequence[str], name: str | None, what: str) -> int:
    if name is None:
        if len(names) != 1:
            msg = f"choose one {what}: {', '.join(names)}"
            raise ModelError(msg)
        return 0
    if name not in names:
        msg = f"unknown {what} {name!r}; known: {', '.join(names)}"
        raise ModelError(msg)
    return list(names).index(name)
