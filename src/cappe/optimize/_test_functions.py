"""Test functions with known minima for checking the search strategies.

Each function takes points along the FIRST axis, like :func:`scipy.optimize.rosen`: ``x`` of shape (n,) gives a
float, a batch of shape (n, S) gives an array (S,), so a function can be handed to
``minimize(..., vectorized=True)`` as it is. Gradients follow the same layout and return an array shaped like ``x``.

The six-hump camelback function is the robustness test of thesis section 4.3 (Fig. 4.3): two global minima
f = -1.0316 at (0.0898, -0.7126) and (-0.0898, 0.7126), and six local minima in the box [-3, 3] x [-2, 2]. The
other minimizers and values are the standard ones of the global-optimization literature (Jamil & Yang 2013,
"A literature survey of benchmark functions for global optimization problems"; Surjanovic & Bingham, Virtual
Library of Simulation Experiments), refined here by Newton's method in 30-digit arithmetic (mpmath).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cappe.exceptions import DataError

__all__ = ["TEST_FUNCTIONS", "BenchmarkFunction"]

Array = NDArray[np.float64]
_Field = Callable[[Array], Array]


@dataclass(frozen=True, eq=False)
class BenchmarkFunction:
    """A test function for minimizers with its search box and known minima.

    Attributes
    ----------
    name : str
        Registry key.
    lower, upper : ndarray, shape (n,)
        The usual search box.
    f_min : float
        Global minimum value.
    minimizers : ndarray, shape (k, n)
        Every global minimizer.
    func : callable
        ``func(x)`` for points as columns, ``x`` of shape (n, S) -> values (S,).
    grad : callable or None
        ``grad(x)`` -> gradients (n, S), where known analytically.
    local_minima : ndarray, shape (m, n) or None
        Every local minimum inside the box (global ones included) where the function has few; None otherwise.
    scalable : bool
        Defined in any dimension (then :meth:`in_dim` gives the n-dimensional version).

    Examples
    --------
    >>> f = TEST_FUNCTIONS["camelback"]
    >>> round(f(f.minimizers[0]), 4), f.n
    (-1.0316, 2)
    >>> f(np.zeros((2, 3))).shape   # a batch of three points (columns)
    (3,)
    """

    name: str
    lower: Array
    upper: Array
    f_min: float
    minimizers: Array
    func: _Field
    grad: _Field | None = None
    local_minima: Array | None = None
    scalable: bool = False

    @property
    def n(self) -> int:
        """Number of variables."""
        return int(self.lower.size)

    @property
    def bounds(self) -> tuple[Array, Array]:
        """``(lower, upper)``, the form :func:`cappe.optimize.minimize` takes."""
        return self.lower.copy(), self.upper.copy()

    def __call__(self, x: ArrayLike) -> float | Array:
        """Value at ``x`` (n,) -> float, or at a batch (n, S) -> (S,)."""
        arr = self._points(x)
        out = self.func(arr)
        return float(out) if arr.ndim == 1 else np.asarray(out, dtype=float)

    def gradient(self, x: ArrayLike) -> Array:
        """Analytic gradient, shaped like ``x`` ((n,) or (n, S)).

        Parameters
        ----------
        x : array_like, shape (n,) or (n, S)
            One point, or a batch of S points as columns.

        Returns
        -------
        ndarray, shape like ``x``

        Raises
        ------
        DataError
            The function has no analytic gradient.
        """
        if self.grad is None:
            msg = f"test function {self.name!r} has no analytic gradient"
            raise DataError(msg)
        return np.asarray(self.grad(self._points(x)), dtype=float)

    def in_dim(self, n: int) -> BenchmarkFunction:
        """The same function in ``n`` variables (scalable functions only).

        Parameters
        ----------
        n : int
            Number of variables, >= 1.

        Returns
        -------
        BenchmarkFunction

        Raises
        ------
        DataError
            The function is not scalable, or ``n < 1``.
        """
        if not self.scalable:
            msg = f"test function {self.name!r} is defined in {self.n} variables only; got n={n}"
            raise DataError(msg)
        if n < 1:
            msg = f"n must be >= 1; got {n}"
            raise DataError(msg)
        tile = np.full(n, 1.0)
        return replace(self, lower=self.lower[0] * tile, upper=self.upper[0] * tile,
                       minimizers=self.minimizers[:, :1] * tile[None, :], local_minima=None)

    def _points(self, x: ArrayLike) -> Array:
        arr = np.asarray(x, dtype=float)
        if arr.ndim not in (1, 2) or arr.shape[0] != self.n:
            msg = f"x for {self.name!r} must have shape ({self.n},) or ({self.n}, S); got {arr.shape}"
            raise DataError(msg)
        return arr


def _camelback(x: Array) -> Array:
    a, b = x[0], x[1]
    return np.asarray((4.0 - 2.1 * a**2 + a**4 / 3.0) * a**2 + a * b + (-4.0 + 4.0 * b**2) * b**2)


def _camelback_grad(x: Array) -> Array:
    a, b = x[0], x[1]
    return np.stack([8.0 * a - 8.4 * a**3 + 2.0 * a**5 + b, a - 8.0 * b + 16.0 * b**3])


def _rosenbrock(x: Array) -> Array:
    return np.asarray(np.sum(100.0 * (x[1:] - x[:-1] ** 2) ** 2 + (1.0 - x[:-1]) ** 2, axis=0))


def _rosenbrock_grad(x: Array) -> Array:
    g = np.zeros_like(x)
    step = x[1:] - x[:-1] ** 2
    g[:-1] += -400.0 * x[:-1] * step - 2.0 * (1.0 - x[:-1])
    g[1:] += 200.0 * step
    return g


def _rastrigin(x: Array) -> Array:
    return np.asarray(10.0 * x.shape[0] + np.sum(x**2 - 10.0 * np.cos(2.0 * np.pi * x), axis=0))


def _rastrigin_grad(x: Array) -> Array:
    return 2.0 * x + 20.0 * np.pi * np.sin(2.0 * np.pi * x)


_ACKLEY_A, _ACKLEY_B, _ACKLEY_C = 20.0, 0.2, 2.0 * np.pi


def _ackley(x: Array) -> Array:
    n = x.shape[0]
    rho = np.sqrt(np.sum(x**2, axis=0) / n)
    mean_cos = np.sum(np.cos(_ACKLEY_C * x), axis=0) / n
    return np.asarray(-_ACKLEY_A * np.exp(-_ACKLEY_B * rho) - np.exp(mean_cos) + _ACKLEY_A + np.e)


def _ackley_grad(x: Array) -> Array:
    n = x.shape[0]
    rho = np.sqrt(np.sum(x**2, axis=0) / n)
    mean_cos = np.sum(np.cos(_ACKLEY_C * x), axis=0) / n
    # d rho / d x_i = x_i / (n rho); the cone tip at rho = 0 has no gradient, 0 is returned there
    safe = np.where(rho > 0.0, rho, 1.0)
    radial = np.where(rho > 0.0, _ACKLEY_A * _ACKLEY_B * np.exp(-_ACKLEY_B * rho) / (n * safe), 0.0)
    return np.asarray(radial * x + np.exp(mean_cos) * _ACKLEY_C * np.sin(_ACKLEY_C * x) / n, dtype=float)


_BRANIN = (1.0, 5.1 / (4.0 * np.pi**2), 5.0 / np.pi, 6.0, 10.0, 1.0 / (8.0 * np.pi))


def _branin(x: Array) -> Array:
    a, b, c, r, s, t = _BRANIN
    return np.asarray(a * (x[1] - b * x[0] ** 2 + c * x[0] - r) ** 2 + s * (1.0 - t) * np.cos(x[0]) + s)


def _branin_grad(x: Array) -> Array:
    a, b, c, r, s, t = _BRANIN
    g = x[1] - b * x[0] ** 2 + c * x[0] - r
    return np.stack([2.0 * a * g * (c - 2.0 * b * x[0]) - s * (1.0 - t) * np.sin(x[0]), 2.0 * a * g])


def _goldstein_price_parts(x: Array) -> tuple[Array, ...]:
    a, b = x[0], x[1]
    u, v = a + b + 1.0, 2.0 * a - 3.0 * b
    p = 19.0 - 14.0 * a + 3.0 * a**2 - 14.0 * b + 6.0 * a * b + 3.0 * b**2
    q = 18.0 - 32.0 * a + 12.0 * a**2 + 48.0 * b - 36.0 * a * b + 27.0 * b**2
    return u, v, p, q, 1.0 + u**2 * p, 30.0 + v**2 * q


def _goldstein_price(x: Array) -> Array:
    *_, left, right = _goldstein_price_parts(x)
    return np.asarray(left * right)


def _goldstein_price_grad(x: Array) -> Array:
    a, b = x[0], x[1]
    u, v, p, q, left, right = _goldstein_price_parts(x)
    dp = -14.0 + 6.0 * a + 6.0 * b  # dp/da = dp/db
    d_left = 2.0 * u * p + u**2 * dp  # same for a and b since du/da = du/db = 1
    d_right_a = 4.0 * v * q + v**2 * (-32.0 + 24.0 * a - 36.0 * b)
    d_right_b = -6.0 * v * q + v**2 * (48.0 - 36.0 * a + 54.0 * b)
    return np.stack([d_left * right + left * d_right_a, d_left * right + left * d_right_b])


def _himmelblau(x: Array) -> Array:
    a, b = x[0], x[1]
    return np.asarray((a**2 + b - 11.0) ** 2 + (a + b**2 - 7.0) ** 2)


def _himmelblau_grad(x: Array) -> Array:
    a, b = x[0], x[1]
    g1, g2 = a**2 + b - 11.0, a + b**2 - 7.0
    return np.stack([4.0 * a * g1 + 2.0 * g2, 2.0 * g1 + 4.0 * b * g2])


def _make(name: str, lower: list[float], upper: list[float], f_min: float, minimizers: list[list[float]],
          func: _Field, grad: _Field | None, *, local_minima: list[list[float]] | None = None,
          scalable: bool = False) -> BenchmarkFunction:
    return BenchmarkFunction(
        name, np.array(lower), np.array(upper), f_min, np.array(minimizers), func, grad,
        None if local_minima is None else np.array(local_minima), scalable,
    )


_CAMEL_GLOBAL = [[0.089842013100318062, -0.71265640302073963], [-0.089842013100318062, 0.71265640302073963]]
_CAMEL_LOCAL = [
    *_CAMEL_GLOBAL,
    [1.7036067149699808, -0.79608356867262512], [-1.7036067149699808, 0.79608356867262512],  # f = -0.21546
    [1.6071047529201972, 0.56865145488413137], [-1.6071047529201972, -0.56865145488413137],  # f = 2.10425
]
_HIMMELBLAU = [[3.0, 2.0], [-2.8051180869527449, 3.131312518250573], [-3.7793102533777469, -3.2831859912861694],
               [3.5844283403304917, -1.8481265269644036]]

TEST_FUNCTIONS: dict[str, BenchmarkFunction] = {
    f.name: f
    for f in (
        _make("camelback", [-3.0, -2.0], [3.0, 2.0], -1.0316284534898774, _CAMEL_GLOBAL, _camelback,
              _camelback_grad, local_minima=_CAMEL_LOCAL),
        _make("rosenbrock", [-5.0, -5.0], [10.0, 10.0], 0.0, [[1.0, 1.0]], _rosenbrock, _rosenbrock_grad,
              scalable=True),
        _make("rastrigin", [-5.12, -5.12], [5.12, 5.12], 0.0, [[0.0, 0.0]], _rastrigin, _rastrigin_grad,
              scalable=True),
        _make("ackley", [-32.768, -32.768], [32.768, 32.768], 0.0, [[0.0, 0.0]], _ackley, _ackley_grad,
              scalable=True),
        _make("branin", [-5.0, 0.0], [10.0, 15.0], 5.0 / (4.0 * np.pi),
              [[-np.pi, 12.275], [np.pi, 2.275], [3.0 * np.pi, 2.475]], _branin, _branin_grad),
        _make("goldstein-price", [-2.0, -2.0], [2.0, 2.0], 3.0, [[0.0, -1.0]], _goldstein_price,
              _goldstein_price_grad),
        _make("himmelblau", [-5.0, -5.0], [5.0, 5.0], 0.0, _HIMMELBLAU, _himmelblau, _himmelblau_grad,
              local_minima=_HIMMELBLAU),
    )
}
"""Registry of the test functions by name: camelback, rosenbrock, rastrigin, ackley, branin, goldstein-price,
himmelblau."""
