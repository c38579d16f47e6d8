"""State-space models, continuous and discrete (ZOH, Tustin), and their time responses."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cappe.exceptions import DataError, ModelError

__all__ = ["StateSpaceModel", "simulate"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class StateSpaceModel:
    """``x' = A x + B u, y = C x + D u`` (``dt is None``) or ``x[k+1] = A x[k] + B u[k]`` (sample time dt, s).

    Attributes
    ----------
    A : ndarray, shape (n, n)
        State matrix (1/s for a continuous model).
    B : ndarray, shape (n, n_in)
        Input matrix.
    C : ndarray, shape (n_out, n)
        Output matrix.
    D : ndarray, shape (n_out, n_in)
        Feed-through matrix.
    dt : float or None
        Sample time in s; None for a continuous model.
    state_names, input_names, output_names : tuple of str
        Labels of the states, inputs and outputs (may be empty).
    method : str
        How a discrete model was obtained (``"zoh"``, ``"tustin"``); empty otherwise.
    """

    A: Array
    B: Array
    C: Array
    D: Array
    dt: float | None = None
    state_names: tuple[str, ...] = ()
    input_names: tuple[str, ...] = ()
    output_names: tuple[str, ...] = ()
    method: str = ""

    @property
    def n_states(self) -> int:
        return int(self.A.shape[0])

    @property
    def is_discrete(self) -> bool:
        return self.dt is not None

    def poles(self) -> NDArray[np.complex128]:
        """Eigenvalues of A (rad/s for continuous, z-plane for discrete)."""
        return np.asarray(np.linalg.eigvals(self.A), dtype=complex)

    def discretize(self, dt: float, method: str = "zoh") -> StateSpaceModel:
        """Discrete model by zero-order hold (``"zoh"``) or the bilinear transform (``"tustin"``).

        Parameters
        ----------
        dt : float
            Sample time in s, > 0.
        method : {"zoh", "tustin"}
            Discretization.

        Returns
        -------
        StateSpaceModel
            The discrete model.

        Raises
        ------
        ModelError
            The model is discrete already, ``dt`` is not positive or ``method`` unknown.
        """
        if self.is_discrete:
            msg = "model is already discrete"
            raise ModelError(msg)
        if not dt > 0:
            msg = f"sample time dt must be > 0 s; got {dt!r}"
            raise ModelError(msg)
        if method not in ("zoh", "tustin"):
            msg = f"discretization method must be 'zoh' or 'tustin'; got {method!r}"
            raise ModelError(msg)
        import scipy.signal as sig  # here: its import (0.6 s) would otherwise come with every file read (cappe.io)

        scipy_method = "bilinear" if method == "tustin" else "zoh"
        ad, bd, cd, dd, _ = sig.cont2discrete((self.A, self.B, self.C, self.D), dt, method=scipy_method)
        return StateSpaceModel(ad, bd, cd, dd, float(dt), self.state_names, self.input_names, self.output_names, method)

    def to_control(self) -> Any:
        """The equivalent python-control ``StateSpace``."""
        import control

        return control.ss(self.A, self.B, self.C, self.D, self.dt if self.dt is not None else 0)

    def to_dict(self) -> dict[str, Any]:
        return {
            "A": self.A.tolist(),
            "B": self.B.tolist(),
            "C": self.C.tolist(),
            "D": self.D.tolist(),
            "dt": self.dt,
            "method": self.method or None,
            "states": list(self.state_names),
            "inputs": list(self.input_names),
            "outputs": list(self.output_names),
        }

    def simulate(
        self,
        u: NDArray[np.floating[Any]],
        t: NDArray[np.floating[Any]] | None = None,
        x0: NDArray[np.floating[Any]] | None = None,
    ) -> tuple[Array, Array]:
        """Time response; see :func:`simulate`.

        Parameters
        ----------
        u : ndarray, shape (n_samples, n_in) or (n_samples,)
            Inputs per sample.
        t : ndarray, shape (n_samples,), optional
            Uniform sample times in s (needed for a continuous model).
        x0 : ndarray, shape (n,), optional
            Initial state (default zero).

        Returns
        -------
        y : ndarray, shape (n_samples, n_out)
        x : ndarray, shape (n_samples, n)
        """
        return simulate(self, u, t, x0)


def simulate(
    model: StateSpaceModel,
    u: NDArray[np.floating[Any]],
    t: NDArray[np.floating[Any]] | None = None,
    x0: NDArray[np.floating[Any]] | None = None,
) -> tuple[Array, Array]:
    """Response ``y[k, out]`` and states ``x[k, state]`` to inputs ``u[k, in]``.

    For a continuous model ``t`` (uniform, s) is required and the input is held constant over each sample
    (zero-order hold), so the result equals that of ``model.discretize(dt, "zoh")`` exactly. A discrete
    model ignores ``t``.

    Parameters
    ----------
    model : StateSpaceModel
        The model.
    u : ndarray, shape (n_samples, n_in) or (n_samples,)
        Inputs per sample.
    t : ndarray, shape (n_samples,), optional
        Uniform sample times in s (needed for a continuous model).
    x0 : ndarray, shape (n,), optional
        Initial state (default zero).

    Returns
    -------
    y : ndarray, shape (n_samples, n_out)
        Outputs.
    x : ndarray, shape (n_samples, n)
        States.

    Examples
    --------
    >>> import numpy as np
    >>> m = StateSpaceModel(np.array([[-1.0]]), np.array([[1.0]]), np.array([[1.0]]), np.array([[0.0]]))
    >>> y, _ = simulate(m, np.ones((3, 1)), np.array([0.0, 0.1, 0.2]))
    >>> np.round(y[:, 0], 4)
    array([0.    , 0.0952, 0.1813])
    """
    uu = np.asarray(u, dtype=float)
    if uu.ndim == 1:
        uu = uu[:, None]
    if uu.ndim != 2 or uu.shape[1] != model.B.shape[1]:
        msg = f"inputs must have shape (n_samples, {model.B.shape[1]}); got {np.shape(u)}"
        raise DataError(msg)
    if not np.all(np.isfinite(uu)):
        bad = sorted({int(j) for j in np.where(~np.isfinite(uu))[1]})
        names = [model.input_names[j] if j < len(model.input_names) else str(j) for j in bad]
        msg = f"inputs contain NaN or Inf in channel(s) {', '.join(names)}"
        raise DataError(msg)
    disc = model
    if not model.is_discrete:
        if t is None:
            msg = "a continuous model needs the time vector t"
            raise DataError(msg)
        tt = np.asarray(t, dtype=float)
        if tt.shape != (uu.shape[0],):
            msg = f"t must have shape ({uu.shape[0]},); got {tt.shape}"
            raise DataError(msg)
        steps = np.diff(tt)
        if steps.size == 0 or np.any(steps <= 0) or not np.allclose(steps, steps.mean(), rtol=1e-6, atol=0):
            msg = "t must be strictly increasing with a uniform step"
            raise DataError(msg)
        disc = model.discretize(float(steps.mean()), "zoh")
    x = np.zeros((uu.shape[0], disc.n_states))
    state = np.zeros(disc.n_states) if x0 is None else np.asarray(x0, dtype=float).copy()
    # state recursion in blocks: the loop is over samples but each step is a small BLAS call
    a_t = disc.A.T
    bu = uu @ disc.B.T
    for k in range(uu.shape[0]):
        x[k] = state
        state = state @ a_t + bu[k]
    y = x @ disc.C.T + uu @ disc.D.T
    return y, x
