"""Morris elementary-effects screening (SALib's trajectory design and analysis, for many outputs)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray
from SALib.analyze import morris as _salib_morris_analyze
from SALib.sample import morris as _salib_morris_sample

from cappe._rng import RandomLike
from cappe.exceptions import ModelError
from cappe.sensitivity._sobol import (
    SampleFunction,
    _check_bootstrap,
    _check_int,
    _check_problem,
    _derive_seeds,
    _evaluate,
    _long_frame,
    _problem_dict,
    _readonly,
    _top,
)

__all__ = ["MorrisResult", "morris_screening"]


@dataclass(frozen=True, eq=False)
class MorrisResult:
    """Morris screening measures of every output with respect to every parameter.

    Elementary effects follow SALib (``scaled=False``): the output change over one grid step divided by the step as
    a fraction of the parameter's range, so all four measures carry the output's unit and compare across parameters
    with different ranges.

    Attributes
    ----------
    mu : ndarray, shape (n_outputs, n_params)
        Mean elementary effect (output unit); effects of opposite sign cancel.
    mu_star : ndarray, shape (n_outputs, n_params)
        Mean absolute elementary effect (output unit), the ranking measure.
    sigma : ndarray, shape (n_outputs, n_params)
        Standard deviation of the elementary effects (ddof=1, output unit): non-linearity and interactions.
    mu_star_conf : ndarray, shape (n_outputs, n_params)
        Half-width of the ``conf_level`` bootstrap confidence interval of mu_star (output unit).
    names, output_names : tuple of str
        Parameter and output names.
    n_trajectories, num_levels : int
        Design size: the model ran ``n_trajectories * (n_params + 1)`` times on a ``num_levels`` grid.
    n_resamples : int
        Bootstrap resamples behind mu_star_conf.
    conf_level : float
        Confidence level of mu_star_conf.
    sample_seed, bootstrap_seed : int
        Seeds given to ``SALib.sample.morris.sample(seed=)`` and ``SALib.analyze.morris.analyze(seed=)``.
    X : ndarray, shape (n_samples, n_params), or None
        Trajectory samples, kept only with ``keep_samples=True``.
    Y : ndarray, shape (n_samples, n_outputs), or None
        Model outputs for X, kept only with ``keep_samples=True``.
    """

    mu: NDArray[np.float64]
    mu_star: NDArray[np.float64]
    sigma: NDArray[np.float64]
    mu_star_conf: NDArray[np.float64]
    names: tuple[str, ...]
    output_names: tuple[str, ...]
    n_trajectories: int
    num_levels: int
    n_resamples: int
    conf_level: float
    sample_seed: int
    bootstrap_seed: int
    X: NDArray[np.float64] | None = None
    Y: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        _readonly(self.mu, self.mu_star, self.sigma, self.mu_star_conf, self.X, self.Y)

    def top_parameters(self, k: int = 5) -> dict[str, tuple[str, ...]]:
        """The k parameters with the largest mu_star for each output, largest first.

        Parameters
        ----------
        k : int
            Parameters per output.

        Returns
        -------
        dict
            ``{output name: parameter names}``.
        """
        return _top(self.mu_star, self.names, self.output_names, k)

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python dictionary (lists of floats); X and Y are not included."""
        return {
            "method": "morris",
            "names": list(self.names),
            "output_names": list(self.output_names),
            "n_trajectories": self.n_trajectories,
            "num_levels": self.num_levels,
            "n_resamples": self.n_resamples,
            "conf_level": self.conf_level,
            "sample_seed": self.sample_seed,
            "bootstrap_seed": self.bootstrap_seed,
            "mu": self.mu.tolist(),
            "mu_star": self.mu_star.tolist(),
            "sigma": self.sigma.tolist(),
            "mu_star_conf": self.mu_star_conf.tolist(),
        }

    def to_dataframe(self) -> pd.DataFrame:
        """Long table, one row per (output, parameter): columns output, parameter, mu, mu_star, sigma, mu_star_conf."""
        return _long_frame(self.output_names, self.names, {"mu": self.mu, "mu_star": self.mu_star,
                                                           "sigma": self.sigma, "mu_star_conf": self.mu_star_conf})


def morris_screening(
    *,
    func: SampleFunction,
    bounds: ArrayLike,
    names: Sequence[str],
    n_trajectories: int,
    num_levels: int = 4,
    rng: RandomLike = None,
    n_resamples: int = 100,
    conf_level: float = 0.95,
    chunk_size: int | None = None,
    progress: bool = False,
    output_names: Sequence[str] | None = None,
    keep_samples: bool = False,
) -> MorrisResult:
    """Morris elementary-effects screening of a vectorized model with uniformly distributed parameters.

    Samples ``n_trajectories`` one-at-a-time trajectories on a ``num_levels`` grid with
    ``SALib.sample.morris.sample``, evaluates ``func`` block by block and analyses each output with
    ``SALib.analyze.morris.analyze``.

    Parameters
    ----------
    func : callable
        Maps a (B, D) float array of parameter samples to outputs of shape (B,) or (B, n_outputs); it receives a copy.
    bounds : array_like, shape (D, 2)
        Lower and upper bound of each parameter, in the parameter's unit; lower < upper.
    names : sequence of str, length D
        Unique parameter names.
    n_trajectories : int
        Number of trajectories (>= 2); ``func`` runs on ``n_trajectories * (D + 1)`` samples.
    num_levels : int
        Grid levels per parameter, even and >= 2.
    rng : int, numpy.random.Generator or None
        Randomness source. Two seeds are derived as ``as_generator(rng).integers(1, 2**31, size=2)`` and passed
        to SALib's sampler and analysis (``seed=``); both are stored on the result.
    n_resamples : int
        Bootstrap resamples for mu_star_conf (>= 2).
    conf_level : float
        Confidence level of mu_star_conf, in (0, 1).
    chunk_size : int, optional
        Samples per ``func`` call; default 4096.
    progress : bool
        Show a progress bar (stderr) over the model evaluations.
    output_names : sequence of str, optional
        Names of the outputs; default ``y0, y1, ...``.
    keep_samples : bool
        Keep the samples X and outputs Y on the result.

    Returns
    -------
    MorrisResult
        mu, mu_star, sigma and mu_star_conf of shape (n_outputs, D).

    Raises
    ------
    ModelError
        If bounds, names, n_trajectories, num_levels, n_resamples, conf_level or chunk_size break their rules.
    DataError
        If ``func`` returns a wrong shape, complex or non-finite values, or ``output_names`` does not match.

    Examples
    --------
    >>> res = morris_screening(func=lambda x: 3 * x[:, 0] + 0 * x[:, 1], bounds=[[0, 1], [0, 1]],
    ...                        names=["a", "b"], n_trajectories=10, rng=0)
    >>> res.mu_star.round(6)
    array([[3., 0.]])
    """
    b, names_t = _check_problem(bounds, names)
    n_traj = _check_int(n_trajectories, "n_trajectories", 2)
    levels = _check_int(num_levels, "num_levels", 2)
    if levels % 2:
        msg = f"num_levels must be even so that trajectory steps are balanced; got {levels}"
        raise ModelError(msg)
    r, level = _check_bootstrap(n_resamples, conf_level)
    if chunk_size is not None:
        _check_int(chunk_size, "chunk_size", 1)
    sample_seed, bootstrap_seed = _derive_seeds(rng)
    problem = _problem_dict(b, names_t)
    X = np.asarray(_salib_morris_sample.sample(problem, n_traj, num_levels=levels, seed=sample_seed), dtype=float)
    Y, out_names = _evaluate(func, X, names=names_t, output_names=output_names, chunk_size=chunk_size,
                             progress=progress, desc="Morris samples")
    measures = {key: np.empty((Y.shape[1], len(names_t))) for key in ("mu", "mu_star", "sigma", "mu_star_conf")}
    for o in range(Y.shape[1]):
        si = _salib_morris_analyze.analyze(problem, X, np.ascontiguousarray(Y[:, o]), num_resamples=r,
                                           conf_level=level, num_levels=levels, seed=bootstrap_seed)
        for key, value in measures.items():
            value[o] = np.ma.getdata(si[key])
    return MorrisResult(names=names_t, output_names=out_names, n_trajectories=n_traj, num_levels=levels,
                        n_resamples=r, conf_level=level, sample_seed=sample_seed, bootstrap_seed=bootstrap_seed,
                        X=X if keep_samples else None, Y=Y if keep_samples else None, **measures)
