"""Frequency response functions ``H[out, in, freq]``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["FRFData"]

_UNITS = {"displacement": "m/N", "elongation": "m/N", "velocity": "m/s/N", "acceleration": "m/s^2/N"}


@dataclass(frozen=True)
class FRFData:
    """Complex FRFs on a frequency grid.

    Attributes
    ----------
    freq : ndarray, shape (n_freq,)
        Frequencies in Hz.
    H : ndarray, shape (n_out, n_in, n_freq)
        Complex frequency responses.
    coherence : ndarray, shape (n_out, n_in, n_freq), optional
        Ordinary (single input) or multiple coherence of measured FRFs in [0, 1]; None for model FRFs.
    window_decay : float, optional
        Time constant tau (s) of an exponential window ``exp(-t / tau)`` applied to the response before the FRF was
        estimated (impact tests). It shifts every pole by ``-1 / tau``; modal extraction adds ``1 / tau`` back.
    """

    freq: NDArray[np.float64]
    H: NDArray[np.complex128]
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    output_quantities: tuple[str, ...] = ()
    coherence: NDArray[np.float64] | None = None
    window_decay: float | None = None

    def response(self, output: str, input: str) -> NDArray[np.complex128]:  # noqa: A002
        """The FRF of one output/input pair."""
        return np.asarray(self.H[self.output_names.index(output), self.input_names.index(input)], dtype=complex)

    def to_dict(self) -> dict[str, Any]:
        pairs = []
        for o, out in enumerate(self.output_names):
            for i, inp in enumerate(self.input_names):
                quantity = self.output_quantities[o] if self.output_quantities else "displacement"
                pair: dict[str, Any] = {
                    "input": inp,
                    "output": out,
                    "unit": _UNITS.get(quantity, ""),
                    "re": self.H[o, i].real.tolist(),
                    "im": self.H[o, i].imag.tolist(),
                }
                if self.coherence is not None:
                    pair["coherence"] = self.coherence[o, i].tolist()
                pairs.append(pair)
        result: dict[str, Any] = {"frequency": self.freq.tolist(), "frf": pairs}
        if self.window_decay is not None:
            result["window_decay"] = self.window_decay
        return result
