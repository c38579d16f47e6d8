"""Zero-pole-gain models."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cappe.systems.transfer import TransferFunctionModel

__all__ = ["ZeroPoleGainModel", "zpk"]


@dataclass(frozen=True)
class ZeroPoleGainModel:
    """``G(s) = gain * prod(s - zeros) / prod(s - poles)`` (rad/s).

    Attributes
    ----------
    zeros, poles : ndarray of complex
        Zeros and poles in rad/s.
    gain : float
        Leading coefficient ratio (output unit per input unit times s^(n_poles - n_zeros)).
    input, output : str
        Channel names (may be empty).
    """

    zeros: NDArray[np.complex128]
    poles: NDArray[np.complex128]
    gain: float
    input: str = ""
    output: str = ""

    def to_dict(self) -> dict[str, Any]:
        def pairs(v: NDArray[np.complex128]) -> list[list[float]]:
            return [[float(x.real), float(x.imag)] for x in _sorted(v)]

        return {
            "input": self.input,
            "output": self.output,
            "zeros": pairs(self.zeros),
            "poles": pairs(self.poles),
            "gain": float(self.gain),
        }

    def dc_gain(self) -> float:
        if np.any(np.abs(self.poles) == 0):
            return float("inf")
        return float(np.real(self.gain * np.prod(-self.zeros) / np.prod(-self.poles)))


def zpk(tf: TransferFunctionModel) -> ZeroPoleGainModel:
    """Zero-pole-gain form of a (float or exact) transfer function.

    Parameters
    ----------
    tf : TransferFunctionModel
        The transfer function (s in rad/s).

    Returns
    -------
    ZeroPoleGainModel
    """
    num, den = tf.float_coefficients()
    num = np.trim_zeros(num, "f")
    zeros = np.roots(num) if num.size > 1 else np.zeros(0, complex)
    poles = np.roots(den)
    gain = float(num[0] / den[0]) if num.size else 0.0
    return ZeroPoleGainModel(np.asarray(zeros, complex), np.asarray(poles, complex), gain, tf.input, tf.output)


def _sorted(v: NDArray[np.complex128]) -> NDArray[np.complex128]:
    return v[np.lexsort((v.imag, np.abs(v)))]
