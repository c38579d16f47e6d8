"""Frequency response functions ``H[out, in, freq]``."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cappe.exceptions import DataError

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
        Complex frequency responses (output unit per input unit).
    input_names, output_names : tuple of str
        Channels along the second and first axes of ``H``.
    output_quantities : tuple of str
        ``"displacement"``, ``"velocity"`` or ``"acceleration"`` per output; empty when unknown (read as
        displacement).
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

    def __post_init__(self) -> None:
        # the structure every consumer relies on; value checks (finite H, increasing lines) belong to the
        # consumers that need them (writers, modal extraction): a model FRF may be inf at an undamped resonance
        freq = np.asarray(self.freq, dtype=float)
        H = np.asarray(self.H)
        n_out, n_in = len(self.output_names), len(self.input_names)
        if freq.ndim != 1 or freq.size == 0 or not np.all(np.isfinite(freq)):
            msg = f"FRF freq must be a non-empty 1-D array of finite frequencies in Hz; got shape {freq.shape}"
            raise DataError(msg)
        if H.shape != (n_out, n_in, freq.size):
            msg = f"FRF H must have shape (n_out, n_in, n_freq) = ({n_out}, {n_in}, {freq.size}); got {H.shape}"
            raise DataError(msg)
        for what, names in (("output", self.output_names), ("input", self.input_names)):
            repeated = sorted({n for n in names if list(names).count(n) > 1})
            if repeated:
                msg = f"FRF {what} names must be unique; repeated: {repeated}"
                raise DataError(msg)
        if self.output_quantities and len(self.output_quantities) != n_out:
            msg = (
                f"FRF output_quantities must list one quantity per output ({n_out}); "
                f"got {len(self.output_quantities)}"
            )
            raise DataError(msg)
        if self.coherence is not None:
            coh = np.asarray(self.coherence)
            if coh.shape != H.shape or np.iscomplexobj(coh) or not np.all(np.isfinite(coh)):
                msg = f"FRF coherence must be a finite real array of shape {H.shape}; got shape {coh.shape}"
                raise DataError(msg)
        decay = self.window_decay
        if decay is not None and not (
            isinstance(decay, (int, float, np.floating)) and math.isfinite(decay) and decay > 0
        ):
            msg = f"FRF window_decay must be None or a time constant > 0 in s; got {decay!r}"
            raise DataError(msg)
        object.__setattr__(self, "freq", freq)

    def response(self, output: str, input: str) -> NDArray[np.complex128]:  # noqa: A002
        """The FRF of one output/input pair.

        Parameters
        ----------
        output, input : str
            Output and input channel names.

        Returns
        -------
        ndarray of complex, shape (n_freq,)

        Raises
        ------
        ValueError
            A name is not a channel of the FRFs.
        """
        return np.asarray(self.H[self.output_names.index(output), self.input_names.index(input)], dtype=complex)

    def reciprocal(self) -> FRFData:
        """The same FRFs read by Maxwell-Betti reciprocity, ``H_oi = H_io``: inputs become outputs and back.

        A roving-hammer test (one accelerometer, the hammer moved over N points) measures one output and N inputs;
        read by reciprocity it is N responses to one reference, which is what a poly-reference estimator and the
        mode shapes over the hammer points need. Reciprocity holds for symmetric M, C, K (no gyroscopic or
        circulatory terms) when every input is a force and every output the same response quantity at the matching
        location and direction.

        Returns
        -------
        FRFData
            ``H`` of shape (n_in, n_out, n_freq); every new output carries the original outputs' common quantity.

        Raises
        ------
        DataError
            The outputs measure different quantities (the transposed FRFs would mix them within one output).

        Examples
        --------
        >>> import numpy as np
        >>> frf = FRFData(np.array([1.0, 2.0]), np.ones((1, 3, 2), dtype=complex), ("1:+x", "2:+x", "3:+x"),
        ...               ("1:+x",), ("acceleration",))
        >>> back = frf.reciprocal()
        >>> back.output_names, back.input_names, back.output_quantities
        (('1:+x', '2:+x', '3:+x'), ('1:+x',), ('acceleration', 'acceleration', 'acceleration'))
        """
        kinds = set(self.output_quantities)
        if len(kinds) > 1:
            msg = (
                f"FRFs can be read by reciprocity only when every output measures the same quantity; got "
                f"{dict(zip(self.output_names, self.output_quantities, strict=True))}"
            )
            raise DataError(msg)
        quantities = (kinds.pop(),) * len(self.input_names) if kinds else ()
        coherence = None if self.coherence is None else np.asarray(self.coherence).transpose(1, 0, 2)
        return FRFData(
            freq=self.freq,
            H=np.asarray(self.H).transpose(1, 0, 2),
            input_names=self.output_names,
            output_names=self.input_names,
            output_quantities=quantities,
            coherence=coherence,
            window_decay=self.window_decay,
        )

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
