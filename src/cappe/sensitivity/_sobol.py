"""Variance-based (Sobol') global sensitivity indices, estimated for all outputs at once.

The sample is SALib's Sobol'-sequence Saltelli design (:func:`SALib.sample.sobol.sample`); the estimators are the
ones of :func:`SALib.analyze.sobol.analyze` (SALib 1.6): Saltelli et al. (2010) for first and total order, Saltelli
(2002) for second order, each output normalized by its mean and standard deviation over the whole sample, and
normal-approximation bootstrap confidence intervals ``z * std(resampled estimates, ddof=1)``. SALib analyses one output
per call and gathers every bootstrap resample explicitly; here each bootstrap resample is a row of a count matrix
``W[k, i]`` (how often base sample ``i`` is drawn in resample ``k``), so every resampled mean over all parameters and
outputs is one matrix product ``W @ F``. With the same resampling indices the numbers equal SALib's to rounding.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray
from SALib.sample import sobol as _salib_sobol_sample
from scipy.stats import norm
from tqdm import tqdm

from cappe._rng import RandomLike, as_generator
from cappe.exceptions import DataError, IllConditionedWarning, ModelError

__all__ = ["SobolResult", "sobol_analyze", "sobol_indices"]

SampleFunction = Callable[[NDArray[np.float64]], ArrayLike]

_SEED_HIGH = 2**31  # derived seeds lie in [1, 2**31): SALib's analyze treats seed 0 as "no seed"
_BLOCK_ELEMENTS = 2**22  # float64 elements per temporary array in the estimators (32 MiB)
_DEFAULT_CHUNK = 4096  # samples per func call when chunk_size is None
_CONSTANT_ULPS = 16  # an output varying by less than this many ulps of its magnitude is constant
_SHOW = 5  # how many indices / names an error message lists


# ---------------------------------------------------------------------------------------------------------------
# validation and evaluation helpers (shared with the Morris module)
# ---------------------------------------------------------------------------------------------------------------


def _listing(items: Sequence[Any]) -> str:
    """``[a, b, c, ...]`` showing at most ``_SHOW`` items."""
    shown = ", ".join(repr(i) for i in items[:_SHOW])
    return f"[{shown}{', ...' if len(items) > _SHOW else ''}]"


def _check_names(names: Sequence[str], what: str = "names") -> tuple[str, ...]:
    if isinstance(names, str):
        msg = f"{what} must be a sequence of strings, one per parameter; got the single string {names!r}"
        raise ModelError(msg)
    result = tuple(names)
    for name in result:
        if not isinstance(name, str) or not name:
            msg = f"{what} must be non-empty strings; got {name!r}"
            raise ModelError(msg)
    seen: set[str] = set()
    for name in result:
        if name in seen:
            msg = f"{what} must be unique; {name!r} appears more than once"
            raise ModelError(msg)
        seen.add(name)
    return result


def _check_problem(bounds: ArrayLike, names: Sequence[str]) -> tuple[NDArray[np.float64], tuple[str, ...]]:
    """Validated ``(bounds (D, 2), names)``."""
    names_t = _check_names(names)
    try:
        b = np.asarray(bounds, dtype=float)
    except (TypeError, ValueError) as exc:
        msg = f"bounds must be a (n_params, 2) array of (lower, upper) floats; got {bounds!r}"
        raise ModelError(msg) from exc
    if b.ndim != 2 or b.shape[1] != 2 or b.shape[0] == 0:
        msg = f"bounds must have shape (n_params, 2) with n_params >= 1; got shape {b.shape}"
        raise ModelError(msg)
    if b.shape[0] != len(names_t):
        msg = (f"names has {len(names_t)} entries but bounds has {b.shape[0]} rows; every parameter needs one name "
               "and one (lower, upper) row")
        raise ModelError(msg)
    for name, (lo, hi) in zip(names_t, b, strict=True):
        if not (np.isfinite(lo) and np.isfinite(hi)):
            msg = f"bounds of parameter {name!r} must be finite; got [{float(lo)!r}, {float(hi)!r}]"
            raise ModelError(msg)
        if not lo < hi:
            msg = f"bounds of parameter {name!r} must satisfy lower < upper; got [{float(lo)!r}, {float(hi)!r}]"
            raise ModelError(msg)
    return b, names_t


def _problem_dict(bounds: NDArray[np.float64], names: tuple[str, ...]) -> dict[str, Any]:
    return {"num_vars": len(names), "names": list(names), "bounds": bounds.tolist()}


def _check_int(value: Any, what: str, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        msg = f"{what} must be an integer >= {minimum}; got {value!r}"
        raise ModelError(msg)
    return int(value)


def _check_bootstrap(n_resamples: Any, conf_level: Any) -> tuple[int, float]:
    r = _check_int(n_resamples, "n_resamples", 2)
    if isinstance(conf_level, bool) or not isinstance(conf_level, (int, float)) or not 0.0 < conf_level < 1.0:
        msg = f"conf_level must be a probability strictly between 0 and 1; got {conf_level!r}"
        raise ModelError(msg)
    return r, float(conf_level)


def _derive_seeds(rng: RandomLike) -> tuple[int, int]:
    """``(sample_seed, bootstrap_seed)``: two draws of ``as_generator(rng).integers(1, 2**31, size=2)``."""
    seeds = as_generator(rng).integers(1, _SEED_HIGH, size=2)
    return int(seeds[0]), int(seeds[1])


def _output_names(output_names: Sequence[str] | None, n_outputs: int) -> tuple[str, ...]:
    if output_names is None:
        return tuple(f"y{i}" for i in range(n_outputs))
    names = _check_names(output_names, "output_names")
    if len(names) != n_outputs:
        msg = f"output_names has {len(names)} entries but there are {n_outputs} outputs"
        raise DataError(msg)
    return names


def _evaluate(
    func: SampleFunction,
    X: NDArray[np.float64],
    *,
    names: tuple[str, ...],
    output_names: Sequence[str] | None,
    chunk_size: int | None,
    progress: bool,
    desc: str,
) -> tuple[NDArray[np.float64], tuple[str, ...]]:
    """Evaluate ``func`` on blocks of ``chunk_size`` rows of X; validated ``(Y (n_rows, n_outputs), output_names)``.

    Stops at the first block with a NaN or Inf output and reports it.
    """
    chunk = _DEFAULT_CHUNK if chunk_size is None else _check_int(chunk_size, "chunk_size", 1)
    n_rows, n_params = X.shape
    Y: NDArray[np.float64] | None = None
    out_names: tuple[str, ...] = ()
    with tqdm(total=n_rows, disable=not progress, unit="sample", desc=desc) as bar:
        for start in range(0, n_rows, chunk):
            stop = min(start + chunk, n_rows)
            raw = np.asarray(func(X[start:stop].copy()))
            if np.iscomplexobj(raw):
                msg = (f"func must return real outputs; got complex values for samples {start}..{stop - 1} "
                       "(return magnitudes or real and imaginary parts as separate outputs)")
                raise DataError(msg)
            try:
                y = raw.astype(float, copy=False)
            except (TypeError, ValueError) as exc:
                msg = f"func must return a float array; got dtype {raw.dtype} for samples {start}..{stop - 1}"
                raise DataError(msg) from exc
            if y.ndim == 1:
                y = y[:, np.newaxis]
            b = stop - start
            if y.ndim != 2 or y.shape[0] != b or y.shape[1] == 0:
                msg = (f"func must return shape ({b},) or ({b}, n_outputs) with n_outputs >= 1 for a ({b}, {n_params}) "
                       f"block of samples; got shape {raw.shape}")
                raise DataError(msg)
            if Y is None:
                out_names = _output_names(output_names, y.shape[1])
                Y = np.empty((n_rows, y.shape[1]))
            elif y.shape[1] != Y.shape[1]:
                msg = (f"func returned {y.shape[1]} outputs for samples {start}..{stop - 1} but {Y.shape[1]} for "
                       "earlier samples; the number of outputs must not change")
                raise DataError(msg)
            bad = ~np.isfinite(y)
            if bad.any():
                rows = np.flatnonzero(bad.any(axis=1))
                cols = np.flatnonzero(bad.any(axis=0))
                first = ", ".join(f"{p}={v:.6g}" for p, v in zip(names, X[start + rows[0]], strict=True))
                msg = (f"func returned NaN or Inf for {rows.size} of the samples {start}..{stop - 1} (sample indices "
                       f"{_listing((rows + start).tolist())}) in {cols.size} outputs "
                       f"{_listing([out_names[c] for c in cols])}; every output must be finite for every sample "
                       f"(first such sample: {first})")
                raise DataError(msg)
            Y[start:stop] = y
            bar.update(b)
    if Y is None:  # pragma: no cover - X always has rows
        msg = "no samples to evaluate"
        raise DataError(msg)
    return Y, out_names


def _top(values: NDArray[np.float64], names: tuple[str, ...], output_names: tuple[str, ...],
         k: int) -> dict[str, tuple[str, ...]]:
    """For each output the names of the (at most) k largest finite values, largest first."""
    k = _check_int(k, "k", 1)
    top: dict[str, tuple[str, ...]] = {}
    for out, row in zip(output_names, values, strict=True):
        order = [j for j in np.argsort(-row, kind="stable") if np.isfinite(row[j])]
        top[out] = tuple(names[j] for j in order[:k])
    return top


def _long_frame(output_names: tuple[str, ...], names: tuple[str, ...],
                columns: dict[str, NDArray[np.float64]]) -> pd.DataFrame:
    n_out, d = len(output_names), len(names)
    data: dict[str, Any] = {
        "output": np.repeat(np.array(output_names, dtype=object), d),
        "parameter": np.tile(np.array(names, dtype=object), n_out),
    }
    data.update({key: value.reshape(-1) for key, value in columns.items()})
    return pd.DataFrame(data)


def _readonly(*arrays: NDArray[Any] | None) -> None:
    for a in arrays:
        if a is not None:
            a.flags.writeable = False


# ---------------------------------------------------------------------------------------------------------------
# result
# ---------------------------------------------------------------------------------------------------------------


#: An ST interval wider than +- this is too noisy to read the value (:meth:`SobolResult.noise`).
NOISY_HALF_WIDTH = 0.1


@dataclass(frozen=True, eq=False)
class SobolResult:
    """Sobol' indices of every output with respect to every parameter, with bootstrap confidence intervals.

    Attributes
    ----------
    S1, ST : ndarray, shape (n_outputs, n_params)
        First-order and total-order indices (dimensionless fractions of the output variance).
    S1_conf, ST_conf : ndarray, shape (n_outputs, n_params)
        Half-widths of the ``conf_level`` bootstrap confidence intervals of S1 and ST (dimensionless).
    S2, S2_conf : ndarray, shape (n_outputs, n_params, n_params), or None
        Second-order indices ``S2[o, j, k]`` and their half-widths for ``j < k``, NaN elsewhere (SALib's layout);
        None unless second-order indices were requested.
    names : tuple of str
        Parameter names, in column order.
    output_names : tuple of str
        Output names, in row order.
    n : int
        Base sample size (rows of the Saltelli matrices A and B); the model ran ``n * (n_params + 2)`` times, or
        ``n * (2 * n_params + 2)`` with second order.
    n_resamples : int
        Bootstrap resamples behind the confidence intervals.
    conf_level : float
        Confidence level of the intervals.
    sample_seed, bootstrap_seed : int or None
        Seeds given to SALib's sampler (``seed=``) and used for the bootstrap indices (SALib's ``analyze(seed=)``),
        None where unknown (``sobol_analyze`` with a Generator).
    X : ndarray, shape (n_samples, n_params), or None
        Parameter samples, kept only when asked for (``keep_samples=True``).
    Y : ndarray, shape (n_samples, n_outputs), or None
        Model outputs for X, kept only when asked for.
    """

    S1: NDArray[np.float64]
    S1_conf: NDArray[np.float64]
    ST: NDArray[np.float64]
    ST_conf: NDArray[np.float64]
    names: tuple[str, ...]
    output_names: tuple[str, ...]
    n: int
    n_resamples: int
    conf_level: float
    S2: NDArray[np.float64] | None = None
    S2_conf: NDArray[np.float64] | None = None
    sample_seed: int | None = None
    bootstrap_seed: int | None = None
    X: NDArray[np.float64] | None = None
    Y: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        _readonly(self.S1, self.S1_conf, self.ST, self.ST_conf, self.S2, self.S2_conf, self.X, self.Y)

    def top_parameters(self, k: int = 5, *, by: Literal["ST", "S1"] = "ST") -> dict[str, tuple[str, ...]]:
        """The k most influential parameters of each output, most influential first.

        Parameters
        ----------
        k : int
            How many parameters to list per output (fewer where indices are NaN).
        by : {"ST", "S1"}
            Rank by total-order (default) or first-order index.

        Returns
        -------
        dict of str to tuple of str
            Output name to parameter names.
        """
        if by not in ("ST", "S1"):
            msg = f"by must be 'ST' or 'S1'; got {by!r}"
            raise ModelError(msg)
        return _top(self.ST if by == "ST" else self.S1, self.names, self.output_names, k)

    def noise(self, *, width: float | None = None) -> dict[str, Any]:
        """Whether the sample size estimates ST well enough to read the values: the count of ST estimates outside
        [0, 1] (by more than 0.05) and of ST intervals wider than +-``width``.

        A total index is a fraction of a variance, so an estimate outside [0, 1] is sampling noise; its error falls
        as ``1 / sqrt(n)``.

        Parameters
        ----------
        width : float, optional
            Largest readable half-width of an ST interval (dimensionless; default :data:`NOISY_HALF_WIDTH`).

        Returns
        -------
        dict
            ``outside`` and ``wide`` (counts), ``count`` (finite ST estimates), ``min`` and ``max`` (of ST),
            ``too_noisy`` (either count nonzero).

        Examples
        --------
        >>> st = np.array([[2.7, 0.1]])
        >>> res = SobolResult(st, st, st, np.full((1, 2), 0.3), ("a", "b"), ("f1",), 16, 100, 0.95)
        >>> res.noise()["outside"], res.noise()["too_noisy"]
        (1, True)
        """
        limit = NOISY_HALF_WIDTH if width is None else float(width)
        st = np.asarray(self.ST, dtype=float)
        conf = np.asarray(self.ST_conf, dtype=float)
        finite = np.isfinite(st)
        outside = int(np.sum(finite & ((st > 1.05) | (st < -0.05))))
        wide = int(np.sum(np.isfinite(conf) & (conf > limit)))
        return {"outside": outside, "wide": wide, "count": int(finite.sum()),
                "min": float(np.min(st[finite])) if finite.any() else float("nan"),
                "max": float(np.max(st[finite])) if finite.any() else float("nan"),
                "too_noisy": bool(outside or wide)}

    def noise_text(self) -> str:
        """One line saying that this sample size is too noisy to read the ST values, or ``""`` when it is not.

        Returns
        -------
        str
            The line (no trailing newline).
        """
        check = self.noise()
        if not check["too_noisy"]:
            return ""
        return (f"too noisy to read at N = {self.n}: {check['outside']} of {check['count']} ST estimates lie "
                f"outside [0, 1] (from {check['min']:.2g} to {check['max']:.2g}) and {check['wide']} have "
                f"intervals wider than +-{NOISY_HALF_WIDTH:g}; run a larger N (the error falls as 1/sqrt(N))")

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python dictionary (lists of floats, NaN where undefined); X and Y are not included."""
        d: dict[str, Any] = {
            "method": "sobol",
            "names": list(self.names),
            "output_names": list(self.output_names),
            "n": self.n,
            "n_resamples": self.n_resamples,
            "conf_level": self.conf_level,
            "sample_seed": self.sample_seed,
            "bootstrap_seed": self.bootstrap_seed,
            "S1": self.S1.tolist(),
            "S1_conf": self.S1_conf.tolist(),
            "ST": self.ST.tolist(),
            "ST_conf": self.ST_conf.tolist(),
        }
        if self.S2 is not None and self.S2_conf is not None:
            d["S2"] = self.S2.tolist()
            d["S2_conf"] = self.S2_conf.tolist()
        return d

    def to_dataframe(self) -> pd.DataFrame:
        """Long table, one row per (output, parameter): columns output, parameter, S1, S1_conf, ST, ST_conf."""
        return _long_frame(self.output_names, self.names,
                           {"S1": self.S1, "S1_conf": self.S1_conf, "ST": self.ST, "ST_conf": self.ST_conf})


# ---------------------------------------------------------------------------------------------------------------
# estimators
# ---------------------------------------------------------------------------------------------------------------


def _estimate(
    Y: NDArray[np.float64], n_params: int, second_order: bool, resample_index: NDArray[np.int64], conf_level: float,
) -> tuple[dict[str, NDArray[np.float64]], NDArray[np.bool_]]:
    """Indices of all outputs of Y (n * step, n_out); ``(arrays, zero_variance mask (n_out,))``.

    ``resample_index`` (n, n_resamples) holds the bootstrap draws, laid out as SALib's ``r``.
    """
    d = n_params
    step = 2 * d + 2 if second_order else d + 2
    n, n_resamples = resample_index.shape
    n_out = Y.shape[1]
    eps = np.finfo(float).eps
    z = float(norm.ppf(0.5 + conf_level / 2))
    # W[k, i] / n: bootstrap resample k as weights on the base samples i, so a resampled mean is a matrix product
    flat = (resample_index + n * np.arange(n_resamples)[np.newaxis, :]).reshape(-1)
    weights = np.bincount(flat, minlength=n * n_resamples).reshape(n_resamples, n) / n
    ju, ku = np.triu_indices(d, 1)
    n_pairs = ju.size

    out = {key: np.full((n_out, d), np.nan) for key in ("S1", "S1_conf", "ST", "ST_conf")}
    if second_order:
        out["S2"] = np.full((n_out, d, d), np.nan)
        out["S2_conf"] = np.full((n_out, d, d), np.nan)
    zero_variance = np.zeros(n_out, dtype=bool)

    per_output = (n + n_resamples) * (step + d + (n_pairs if second_order else 0))
    block = max(1, _BLOCK_ELEMENTS // per_output)
    for c0 in range(0, n_out, block):
        cols = slice(c0, min(c0 + block, n_out))
        yb = Y[:, cols]
        m = yb.shape[1]
        # SALib normalizes each output by its mean and standard deviation over the whole sample
        scale = np.max(np.abs(yb), axis=0)
        const = np.ptp(yb, axis=0) <= _CONSTANT_ULPS * eps * scale
        std = yb.std(axis=0)
        yn = (yb - yb.mean(axis=0)) / np.where(const, 1.0, std)
        yn[:, const] = 0.0  # constant outputs: rounding noise only, reported as NaN below
        y3 = yn.reshape(n, step, m)
        a, b = y3[:, 0], y3[:, step - 1]  # (n, m)
        ab = y3[:, 1 : d + 1]  # (n, d, m)
        var = np.var(np.concatenate([a, b]), axis=0)
        bad = const | (var <= eps)
        zero_variance[cols] = bad
        inv_var = 1.0 / np.where(bad, 1.0, var)

        mean_b = weights @ (a + b) / 2
        var_b = weights @ (a * a + b * b) / 2 - mean_b**2  # (R, m); var of the 2n resampled A and B values
        ok_b = var_b > eps
        inv_var_b = np.where(ok_b, 1.0 / np.where(ok_b, var_b, 1.0), 0.0)  # SALib: 0 where the variance vanishes

        f1 = b[:, np.newaxis] * (ab - a[:, np.newaxis])  # (n, d, m)
        s1 = f1.mean(axis=0) * inv_var  # (d, m)
        s1_b = (weights @ f1.reshape(n, d * m)).reshape(n_resamples, d, m) * inv_var_b[:, np.newaxis]
        del f1
        ft = (a[:, np.newaxis] - ab) ** 2
        st = 0.5 * ft.mean(axis=0) * inv_var
        st_b = 0.5 * (weights @ ft.reshape(n, d * m)).reshape(n_resamples, d, m) * inv_var_b[:, np.newaxis]
        del ft
        out["S1"][cols] = s1.T
        out["ST"][cols] = st.T
        out["S1_conf"][cols] = z * s1_b.std(axis=0, ddof=1).T
        out["ST_conf"][cols] = z * st_b.std(axis=0, ddof=1).T

        if second_order and n_pairs:
            ba = y3[:, d + 1 : 2 * d + 1]  # (n, d, m)
            # V_jk = mean(BA_j AB_k - A B) / var; S2_jk = V_jk - S1_j - S1_k (Saltelli 2002, as SALib)
            g = ba[:, ju] * ab[:, ku]  # (n, n_pairs, m)
            prod = a * b
            v = (g.mean(axis=0) - prod.mean(axis=0)) * inv_var
            s2 = v - s1[ju] - s1[ku]  # (n_pairs, m)
            g_b = (weights @ g.reshape(n, n_pairs * m)).reshape(n_resamples, n_pairs, m)
            del g
            v_b = (g_b - (weights @ prod)[:, np.newaxis]) * inv_var_b[:, np.newaxis]
            s2_b = v_b - s1_b[:, ju] - s1_b[:, ku]
            out["S2"][cols, ju, ku] = s2.T  # basic slice + index arrays: writes into out["S2"]
            out["S2_conf"][cols, ju, ku] = z * s2_b.std(axis=0, ddof=1).T

    for value in out.values():
        value[zero_variance] = np.nan
    return out, zero_variance


def _warn_zero_variance(mask: NDArray[np.bool_], output_names: tuple[str, ...]) -> None:
    if mask.any():
        names = [output_names[i] for i in np.flatnonzero(mask)]
        msg = (f"{len(names)} of {mask.size} outputs have zero variance over the Sobol' sample "
               f"{_listing(names)}; their Sobol' indices are undefined (0/0) and set to NaN")
        warnings.warn(msg, IllConditionedWarning, stacklevel=3)


def _result(arrays: dict[str, NDArray[np.float64]], **fields: Any) -> SobolResult:
    return SobolResult(S1=arrays["S1"], S1_conf=arrays["S1_conf"], ST=arrays["ST"], ST_conf=arrays["ST_conf"],
                       S2=arrays.get("S2"), S2_conf=arrays.get("S2_conf"), **fields)


def _as_outputs(Y: ArrayLike) -> NDArray[np.float64]:
    try:
        y = np.asarray(Y, dtype=float)
    except (TypeError, ValueError) as exc:
        msg = "Y must be a real float array of shape (n_samples,) or (n_samples, n_outputs)"
        raise DataError(msg) from exc
    if y.ndim == 1:
        y = y[:, np.newaxis]
    if y.ndim != 2 or y.shape[1] == 0:
        msg = f"Y must have shape (n_samples,) or (n_samples, n_outputs) with n_outputs >= 1; got shape {y.shape}"
        raise DataError(msg)
    return np.ascontiguousarray(y)


def sobol_analyze(
    Y: ArrayLike,
    *,
    names: Sequence[str],
    second_order: bool = False,
    n_resamples: int = 100,
    conf_level: float = 0.95,
    rng: RandomLike = None,
    output_names: Sequence[str] | None = None,
) -> SobolResult:
    """Sobol' indices from model outputs on a given Sobol'/Saltelli sample (all outputs at once).

    The counterpart of ``SALib.analyze.sobol.analyze`` for many outputs: the same estimators and, for the same
    resampling indices, the same confidence intervals, computed for every output in one pass.

    Parameters
    ----------
    Y : array_like, shape (n_samples,) or (n_samples, n_outputs)
        Outputs on the rows of a sample from ``SALib.sample.sobol.sample`` (or ``saltelli.sample``), in SALib's row
        order; ``n_samples = n * (D + 2)``, or ``n * (2 D + 2)`` with ``second_order``. Any unit.
    names : sequence of str, length D
        Parameter names (the columns of the sample).
    second_order : bool
        Whether the sample was drawn with ``calc_second_order=True``; then S2 is computed.
    n_resamples : int
        Bootstrap resamples (>= 2).
    conf_level : float
        Confidence level of the intervals, in (0, 1).
    rng : int, numpy.random.Generator or None
        Source of the bootstrap indices ``as_generator(rng).integers(n, size=(n, n_resamples))``: for an int seed
        ``s >= 1`` the same draws as ``SALib.analyze.sobol.analyze(..., seed=s)`` (SALib ignores ``seed=0``).
    output_names : sequence of str, optional
        Names of the outputs (columns of Y); default ``y0, y1, ...``.

    Returns
    -------
    SobolResult
        Indices of shape (n_outputs, D); X and Y are not kept.

    Raises
    ------
    DataError
        If Y has the wrong shape, a row count that does not fit the design, or non-finite values.
    ModelError
        If names, n_resamples or conf_level break their rules.

    Warns
    -----
    IllConditionedWarning
        If an output has zero variance; its indices are NaN.

    Examples
    --------
    >>> from SALib.sample import sobol as sobol_sample
    >>> problem = {"num_vars": 2, "names": ["a", "b"], "bounds": [[0.0, 1.0], [0.0, 1.0]]}
    >>> X = sobol_sample.sample(problem, 256, calc_second_order=False, seed=1)
    >>> res = sobol_analyze(X[:, 0] + 2 * X[:, 1], names=["a", "b"], rng=2)
    >>> res.ST.round(1)
    array([[0.2, 0.8]])
    """
    names_t = _check_names(names)
    d = len(names_t)
    r, level = _check_bootstrap(n_resamples, conf_level)
    y = _as_outputs(Y)
    step = 2 * d + 2 if second_order else d + 2
    if y.shape[0] % step or y.shape[0] < 2 * step:
        rule = "2 D + 2" if second_order else "D + 2"
        msg = (f"Y must have n * ({rule}) = n * {step} rows with n >= 2 for D = {d} parameters and "
               f"second_order={second_order}; got {y.shape[0]} rows")
        raise DataError(msg)
    bad_rows = np.flatnonzero(~np.isfinite(y).all(axis=1))
    if bad_rows.size:
        msg = f"Y must be finite; got NaN or Inf in {bad_rows.size} rows {_listing(bad_rows.tolist())}"
        raise DataError(msg)
    out_names = _output_names(output_names, y.shape[1])
    n = y.shape[0] // step
    seed = int(rng) if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool) else None
    resample_index = as_generator(rng).integers(n, size=(n, r))
    arrays, zero_variance = _estimate(y, d, second_order, resample_index, level)
    _warn_zero_variance(zero_variance, out_names)
    return _result(arrays, names=names_t, output_names=out_names, n=n, n_resamples=r, conf_level=level,
                   bootstrap_seed=seed)


def sobol_indices(
    *,
    func: SampleFunction,
    bounds: ArrayLike,
    names: Sequence[str],
    n: int,
    rng: RandomLike = None,
    second_order: bool = False,
    n_resamples: int = 100,
    conf_level: float = 0.95,
    chunk_size: int | None = None,
    progress: bool = False,
    output_names: Sequence[str] | None = None,
    keep_samples: bool = False,
) -> SobolResult:
    """Sobol' sensitivity indices of a vectorized model with uniformly distributed parameters.

    Draws SALib's scrambled Sobol'-sequence Saltelli sample, evaluates ``func`` on it block by block and estimates
    first-order, total-order (and optionally second-order) indices with bootstrap confidence intervals for all
    outputs at once (see :func:`sobol_analyze`).

    Parameters
    ----------
    func : callable
        Maps a (B, D) float array of parameter samples (columns in the order of ``names``, units of ``bounds``)
        to outputs of shape (B,) or (B, n_outputs). It receives a copy, so it may modify it.
    bounds : array_like, shape (D, 2)
        Lower and upper bound of each uniformly distributed parameter, in the parameter's unit; lower < upper.
    names : sequence of str, length D
        Unique parameter names.
    n : int
        Base sample size, a power of 2 (>= 2) so that the Sobol' sequence keeps its balance properties. ``func``
        runs on ``n * (D + 2)`` samples, ``n * (2 D + 2)`` with ``second_order``.
    rng : int, numpy.random.Generator or None
        Randomness source. Two seeds are derived as ``as_generator(rng).integers(1, 2**31, size=2)``: the first
        scrambles the Sobol' sequence (``SALib.sample.sobol.sample(..., scramble=True, seed=sample_seed)``), the
        second seeds the bootstrap (``SALib.analyze.sobol.analyze(..., seed=bootstrap_seed)``). Both are stored
        on the result, so the same rng gives the same numbers here and in SALib.
    second_order : bool
        Also estimate second-order indices (almost doubles the model runs).
    n_resamples : int
        Bootstrap resamples (>= 2).
    conf_level : float
        Confidence level of the intervals, in (0, 1).
    chunk_size : int, optional
        Samples per ``func`` call, bounding the model's working memory; default 4096. Does not change results for a
        row-wise ``func``.
    progress : bool
        Show a progress bar (stderr) over the model evaluations.
    output_names : sequence of str, optional
        Names of the outputs; default ``y0, y1, ...``.
    keep_samples : bool
        Keep the samples X (n_samples, D) and outputs Y (n_samples, n_outputs) on the result. Off by default: Y can
        be large (8 bytes per sample and output) and the indices do not need it.

    Returns
    -------
    SobolResult
        Indices of shape (n_outputs, D), with the seeds used.

    Raises
    ------
    ModelError
        If bounds, names, n, n_resamples, conf_level or chunk_size break their rules.
    DataError
        If ``func`` returns a wrong shape, complex or non-finite values, or ``output_names`` does not match.

    Warns
    -----
    IllConditionedWarning
        If an output has zero variance over the sample; its indices are NaN (0/0) rather than SALib's zeros,
        so that "no variance" is not read as "no influence".

    Examples
    --------
    >>> res = sobol_indices(func=lambda x: x[:, 0] + 2 * x[:, 1], bounds=[[0, 1], [0, 1]], names=["a", "b"],
    ...                     n=256, rng=0)
    >>> res.S1.round(1), res.top_parameters(1)
    (array([[0.2, 0.8]]), {'y0': ('b',)})
    """
    b, names_t = _check_problem(bounds, names)
    n_base = _check_int(n, "n", 2)
    if n_base & (n_base - 1):
        lower = 1 << (n_base.bit_length() - 1)
        msg = (f"n must be a power of 2 for the Sobol' sequence to keep its balance properties; got {n_base} "
               f"(nearest: {lower} or {2 * lower})")
        raise ModelError(msg)
    r, level = _check_bootstrap(n_resamples, conf_level)
    if chunk_size is not None:
        _check_int(chunk_size, "chunk_size", 1)
    sample_seed, bootstrap_seed = _derive_seeds(rng)
    X = np.asarray(_salib_sobol_sample.sample(_problem_dict(b, names_t), n_base, calc_second_order=second_order,
                                              scramble=True, seed=sample_seed), dtype=float)
    Y, out_names = _evaluate(func, X, names=names_t, output_names=output_names, chunk_size=chunk_size,
                             progress=progress, desc="Sobol' samples")
    resample_index = np.random.default_rng(bootstrap_seed).integers(n_base, size=(n_base, r))
    arrays, zero_variance = _estimate(Y, len(names_t), second_order, resample_index, level)
    _warn_zero_variance(zero_variance, out_names)
    return _result(arrays, names=names_t, output_names=out_names, n=n_base, n_resamples=r, conf_level=level,
                   sample_seed=sample_seed, bootstrap_seed=bootstrap_seed,
                   X=X if keep_samples else None, Y=Y if keep_samples else None)

