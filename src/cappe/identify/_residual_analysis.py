"""Residual analysis of a fitted model, as MATLAB's ``resid``: are the residuals white, and independent of the inputs?

For the residuals ``e`` of each output and the inputs ``u`` of one or several records:

* **Autocorrelation** ``r_e(tau) / r_e(0)``, ``tau = 0..max_lag``. White residuals have ``|r| < z / sqrt(N)``
  (per lag, ``z`` the two-sided normal quantile of the level); the test over all lags is Ljung-Box,
  ``Q = N (N + 2) sum_tau r(tau)^2 / (N - tau) ~ chi2(max_lag)``. Coloured residuals mean coloured measurement
  noise or missed dynamics; the Gauss-Newton intervals, which assume white residuals, are then too narrow.
* **Cross-correlation** ``r_eu(tau) = sum_k e[k + tau] u[k] / sqrt(sum e^2 sum u^2)``, ``tau = -max_lag..max_lag``
  (positive lags: the residual after the input). Residuals independent of ``u`` have variance ``P / N`` per lag
  with ``P = sum_k r_e(k) r_u(k)`` (MATLAB's bound, correct for coloured inputs). The test of a pair is a weighted
  Bonferroni over the lags: half its level goes to the largest ``|r_eu| / sqrt(P / N)`` over all ``2 max_lag + 1``
  lags, half to the largest over the ``2 NEAR_LAG + 1`` lags next to zero (``p = min(1, 2 min(p_all, p_near))``,
  each part Bonferroni over its lags); the pairs are Bonferroni again, so the whole test, over all lags and
  output-input pairs, has the level (Ljung-Box likewise over the outputs). The near lags are where a wrong
  intersample behaviour or a sub-sample delay shows: it acts within one sample, so the residual takes a share of
  the input at lag 0. Measured on the issue-21 records (a UKF's FOH fit of band-limited DAQ records, F1 + F2, 5 %
  noise, ``benchmarks/bench_coverage.py``): the largest ``|r_eu| / sqrt(P / N)`` of d1 and F1 lay at lag 0 in 10
  of 10 records, 3.9-7.4, the other lags within noise. The largest over all 51 lags alone needs 4.06 at level
  0.01 over 4 pairs, and missed the two records at 3.9 and 4.0; Ljung's chi-square of all lags
  (``N r_eu^T R^-1 r_eu ~ chi2(51)``, R the covariance of the lags under independence) spreads that one lag over
  51 degrees of freedom (p 0.18 and 0.52 for those two). The near-lag part needs 3.53, the all-lag part 4.22,
  and keeps wrong dynamics, whose correlation spreads over the lags of the impulse response, in view.
  A residual that correlates with an input means the model does not explain the response to that input (wrong
  structure or parameters, intersample behaviour, delay): an output-error fit that fails this test is not valid,
  whatever the optimizer says.

Correlations of several records are summed over the records (each within its own record).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import stats

from cappe.exceptions import DataError

__all__ = ["ResidualAnalysis", "residual_analysis"]

Array = NDArray[np.float64]

#: Default number of lags (MATLAB's resid uses 25).
MAX_LAG = 25
#: Default significance level of each test (MATLAB draws 99 % bounds).
LEVEL = 0.01
#: Lags next to zero that the independence test watches with half its level (module notes): within one sample,
#: where an intersample behaviour or a delay the model does not have shows.
NEAR_LAG = 1


@dataclass(frozen=True)
class ResidualAnalysis:
    """Correlations of residuals with themselves and with the inputs, their bounds and tests.

    Attributes
    ----------
    output_names, input_names : tuple of str
        Residual (output) and input channels.
    lags : ndarray of int, shape (max_lag + 1,)
        Lags of the autocorrelation (samples).
    autocorrelation : ndarray, shape (n_out, max_lag + 1)
        Normalized autocorrelation of each output's residuals (1 at lag 0).
    auto_bound : float
        Per-lag bound ``z / sqrt(N)`` of white residuals.
    whiteness_p : ndarray, shape (n_out,)
        Ljung-Box p-value per output.
    cross_lags : ndarray of int, shape (2 max_lag + 1,)
        Lags of the cross-correlation (samples; positive: residual after input).
    cross_correlation : ndarray, shape (n_out, n_in, 2 max_lag + 1)
        Normalized cross-correlation of residuals and inputs.
    cross_bound : ndarray, shape (n_out, n_in)
        Per-lag bound ``z sqrt(P / N)`` of independent residuals.
    independence_p : ndarray, shape (n_out, n_in)
        p-value of the largest cross-correlation: the weighted Bonferroni of the largest over all lags and over the
        lags within ``near_lag`` of zero (module notes).
    samples : int
        Number of residual samples per output (all records).
    level : float
        Significance level of the tests and bounds.
    near_lag : int or None
        The near lags' reach; None in documents written before the near-lag part (the largest over all lags only).
    """

    output_names: tuple[str, ...]
    input_names: tuple[str, ...]
    lags: NDArray[np.int_]
    autocorrelation: Array
    auto_bound: float
    whiteness_p: Array
    cross_lags: NDArray[np.int_]
    cross_correlation: Array
    cross_bound: Array
    independence_p: Array
    samples: int
    level: float = LEVEL
    near_lag: int | None = NEAR_LAG

    @property
    def white(self) -> NDArray[np.bool_]:
        """Per output: the whiteness test passes (Bonferroni over the outputs: the whole test has ``level``)."""
        return np.asarray(self.whiteness_p * self.whiteness_p.size >= self.level)

    @property
    def independent(self) -> NDArray[np.bool_]:
        """Per output and input: the independence test passes (Bonferroni over the pairs: the whole test has
        ``level``)."""
        return np.asarray(self.independence_p * self.independence_p.size >= self.level)

    @property
    def passed(self) -> bool:
        """Whether the residuals are independent of every input (the test an output-error fit must pass)."""
        return bool(np.all(self.independent))

    def warnings(self) -> list[str]:
        """One line per failed test, saying what it means."""
        lines = []
        for o, name in enumerate(self.output_names):
            for i, inp in enumerate(self.input_names):
                if not self.independent[o, i]:
                    k = int(np.argmax(np.abs(self.cross_correlation[o, i])))
                    lines.append(
                        f"residuals of {name} correlate with input {inp} (|r| = "
                        f"{abs(self.cross_correlation[o, i, k]):.3g} at lag {int(self.cross_lags[k])}, 99 % bound "
                        f"{self.cross_bound[o, i]:.2g}, p = {self.independence_p[o, i]:.1e}): the model does not "
                        "explain the response to it (structure, parameters, intersample behaviour or delay); the "
                        "estimate is not valid"
                    )
        coloured = [n for n, ok in zip(self.output_names, self.white, strict=True) if not ok]
        if coloured:
            worst = float(np.min(self.whiteness_p))
            lines.append(
                f"residuals of {', '.join(coloured)} are not white (Ljung-Box over {self.lags.size - 1} lags, "
                f"p = {worst:.1e}): coloured noise or missed dynamics; intervals that assume white residuals are "
                "too narrow"
            )
        return lines

    def to_dict(self) -> dict[str, Any]:
        return {
            "outputs": list(self.output_names),
            "inputs": list(self.input_names),
            "level": self.level,
            "samples": self.samples,
            "lags": self.lags.tolist(),
            "autocorrelation": self.autocorrelation.tolist(),
            "auto_bound": self.auto_bound,
            "whiteness_p": dict(zip(self.output_names, self.whiteness_p.tolist(), strict=True)),
            "cross_lags": self.cross_lags.tolist(),
            "cross_correlation": self.cross_correlation.tolist(),
            "cross_bound": self.cross_bound.tolist(),
            "independence_p": {o: dict(zip(self.input_names, row, strict=True))
                               for o, row in zip(self.output_names, self.independence_p.tolist(), strict=True)},
            "white": dict(zip(self.output_names, self.white.tolist(), strict=True)),
            "independent": self.passed,
            "near_lag": self.near_lag,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ResidualAnalysis:
        """The inverse of :meth:`to_dict`.

        Parameters
        ----------
        data : dict
            A :meth:`to_dict` document (as in an estimate's ``diagnostics["residual_analysis"]``).

        Returns
        -------
        ResidualAnalysis
        """
        outputs, inputs = tuple(data["outputs"]), tuple(data["inputs"])
        return cls(
            outputs, inputs, np.asarray(data["lags"], dtype=int), np.asarray(data["autocorrelation"], dtype=float),
            float(data["auto_bound"]), np.array([data["whiteness_p"][o] for o in outputs], dtype=float),
            np.asarray(data["cross_lags"], dtype=int), np.asarray(data["cross_correlation"], dtype=float),
            np.asarray(data["cross_bound"], dtype=float),
            np.array([[data["independence_p"][o][i] for i in inputs] for o in outputs], dtype=float),
            int(data["samples"]), float(data["level"]), data.get("near_lag"),
        )

    def plot(self, path: str | Path, *, title: str = "") -> Path:
        """Autocorrelation (first column) and cross-correlations (one column per input) with their bounds.

        Parameters
        ----------
        path : str or Path
            Image file to write (format from the extension).
        title : str
            Figure title.

        Returns
        -------
        Path
            ``path``.
        """
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        n_out, n_in = len(self.output_names), len(self.input_names)
        fig, axes = plt.subplots(n_out, 1 + n_in, figsize=(3.6 * (1 + n_in), 2.4 * n_out), squeeze=False)
        for o, name in enumerate(self.output_names):
            ax = axes[o, 0]
            ok = bool(self.white[o])
            ax.vlines(self.lags, 0, self.autocorrelation[o], color="C0" if ok else "C3")
            ax.axhspan(-self.auto_bound, self.auto_bound, color="0.85", zorder=0)
            ax.set_title(f"autocorrelation of e({name})" + ("" if ok else " - NOT white"), fontsize=9)
            ax.set_xlabel("lag (samples)", fontsize=8)
            ax.set_ylim(-1.05, 1.05)
            for i, inp in enumerate(self.input_names):
                ax = axes[o, 1 + i]
                ok = bool(self.independent[o, i])
                ax.vlines(self.cross_lags, 0, self.cross_correlation[o, i], color="C0" if ok else "C3")
                bound = self.cross_bound[o, i]
                ax.axhspan(-bound, bound, color="0.85", zorder=0)
                ax.set_title(f"e({name}) vs {inp}" + ("" if ok else " - CORRELATED"), fontsize=9)
                ax.set_xlabel("lag (samples)", fontsize=8)
        if title:
            fig.suptitle(title, fontsize=10)
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
        return Path(path)


def _correlate(a: Array, b: Array, max_lag: int) -> Array:
    """``sum_k a[k + tau] b[k]`` for ``tau = -max_lag..max_lag`` (zero outside the record)."""
    import scipy.signal as sig

    full = sig.correlate(a, b, mode="full", method="auto")  # lags -(n-1)..(n-1)
    mid = a.size - 1
    out = np.zeros(2 * max_lag + 1)
    lo, hi = max(mid - max_lag, 0), min(mid + max_lag, full.size - 1)
    out[lo - (mid - max_lag): hi - (mid - max_lag) + 1] = full[lo: hi + 1]
    return out


def residual_analysis(
    *,
    residuals: ArrayLike | Sequence[ArrayLike],
    inputs: ArrayLike | Sequence[ArrayLike],
    output_names: Sequence[str],
    input_names: Sequence[str],
    max_lag: int = MAX_LAG,
    level: float = LEVEL,
) -> ResidualAnalysis:
    """Auto- and cross-correlation tests of residuals (module notes).

    Parameters
    ----------
    residuals : array_like, shape (n_samples, n_out), or a sequence of them (one per record)
        Output errors (any units; each output is normalized).
    inputs : array_like, shape (n_samples, n_in), or a sequence of them
        Inputs of the same records.
    output_names, input_names : sequence of str
        Channel names.
    max_lag : int
        Largest lag in samples (>= 1).
    level : float
        Significance level of the tests, in (0, 1).

    Returns
    -------
    ResidualAnalysis

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal((4000, 1))
    >>> white = residual_analysis(residuals=rng.standard_normal((4000, 1)), inputs=u, output_names=["y"],
    ...                           input_names=["u"])
    >>> bool(white.passed)
    True
    >>> leaky = residual_analysis(residuals=rng.standard_normal((4000, 1)) + 0.2 * u, inputs=u, output_names=["y"],
    ...                           input_names=["u"])
    >>> bool(leaky.passed)
    False
    """
    def records(x: Any, what: str) -> list[Array]:
        items = list(x) if isinstance(x, (list, tuple)) else [x]
        out = [np.asarray(r, dtype=float) for r in items]
        out = [r[:, None] if r.ndim == 1 else r for r in out]
        if not out or any(r.ndim != 2 for r in out):
            msg = f"{what} must be (n_samples, n_channels) arrays, one per record"
            raise DataError(msg)
        return out

    e_recs, u_recs = records(residuals, "residuals"), records(inputs, "inputs")
    if len(e_recs) != len(u_recs) or any(e.shape[0] != u.shape[0] for e, u in zip(e_recs, u_recs, strict=False)):
        msg = "residuals and inputs must come as records of equal lengths"
        raise DataError(msg)
    n_out, n_in = e_recs[0].shape[1], u_recs[0].shape[1]
    if n_out != len(output_names) or n_in != len(input_names):
        msg = f"got {n_out} residual and {n_in} input channels for names {list(output_names)} and {list(input_names)}"
        raise DataError(msg)
    if isinstance(max_lag, bool) or not isinstance(max_lag, (int, np.integer)) or max_lag < 1:
        msg = f"max_lag must be an integer >= 1; got {max_lag!r}"
        raise DataError(msg)
    if not 0 < level < 1:
        msg = f"level must lie in (0, 1); got {level!r}"
        raise DataError(msg)
    n_total = sum(e.shape[0] for e in e_recs)
    lag = int(min(max_lag, max(min(e.shape[0] for e in e_recs) // 4, 1)))
    auto_e = np.zeros((n_out, 2 * lag + 1))
    auto_u = np.zeros((n_in, 2 * lag + 1))
    cross = np.zeros((n_out, n_in, 2 * lag + 1))
    for e, u in zip(e_recs, u_recs, strict=True):
        for o in range(n_out):
            auto_e[o] += _correlate(e[:, o], e[:, o], lag)
            for i in range(n_in):
                cross[o, i] += _correlate(e[:, o], u[:, i], lag)
        for i in range(n_in):
            auto_u[i] += _correlate(u[:, i], u[:, i], lag)
    e0 = np.where(auto_e[:, lag] > 0, auto_e[:, lag], 1.0)
    u0 = np.where(auto_u[:, lag] > 0, auto_u[:, lag], 1.0)
    rho_e = auto_e / e0[:, None]
    rho_u = auto_u / u0[:, None]
    rho_eu = cross / np.sqrt(e0[:, None, None] * u0[None, :, None])
    z = float(stats.norm.ppf(1 - level / 2))
    taus = np.arange(1, lag + 1)
    q = n_total * (n_total + 2) * np.sum(rho_e[:, lag + 1:] ** 2 / (n_total - taus)[None, :], axis=1)
    whiteness_p = np.asarray(stats.chi2.sf(q, lag), dtype=float)
    p_factor = np.maximum(np.einsum("ok,ik->oi", rho_e, rho_u), 1e-12)  # sum_k r_e(k) r_u(k), k = -lag..lag
    sd = np.sqrt(p_factor / n_total)
    near = min(NEAR_LAG, lag)
    scaled = np.abs(rho_eu) / sd[:, :, None]
    p_all = (2 * lag + 1) * 2 * stats.norm.sf(np.max(scaled, axis=2))
    p_near = (2 * near + 1) * 2 * stats.norm.sf(np.max(scaled[:, :, lag - near: lag + near + 1], axis=2))
    independence_p = np.minimum(1.0, 2 * np.minimum(p_all, p_near))
    return ResidualAnalysis(
        tuple(output_names), tuple(input_names), np.arange(lag + 1), rho_e[:, lag:], z / np.sqrt(n_total),
        whiteness_p, np.arange(-lag, lag + 1), rho_eu, z * sd, np.asarray(independence_p, dtype=float), n_total,
        float(level), near,
    )


@dataclass(frozen=True)
class RunsTest:
    """Wald-Wolfowitz runs test of residual signs along frequency: too few sign changes mean a systematic misfit.

    Noise at frequency lines a few lines apart is independent; a model that misses a resonance leaves long runs of
    one sign. The one-sided p-value of
    each series is ``Phi((R - mu) / sigma)`` with ``mu = 2 n+ n- / n + 1`` and
    ``sigma^2 = (mu - 1)(mu - 2) / (n - 1)``; the test over all series is Bonferroni.

    Attributes
    ----------
    names : tuple of str
        The series ("d1/F1 real" ...).
    runs, expected : ndarray, shape (n_series,)
        Observed and expected number of runs.
    p_values : ndarray, shape (n_series,)
        One-sided p-values (too few runs).
    level : float
        Significance level of the whole test.
    """

    names: tuple[str, ...]
    runs: Array
    expected: Array
    p_values: Array
    level: float = LEVEL

    @property
    def passed(self) -> bool:
        """No series has significantly too few runs (Bonferroni over the series)."""
        return bool(np.all(self.p_values * len(self.names) >= self.level))

    def warnings(self) -> list[str]:
        """One line naming the series with systematic misfit, empty when the test passes."""
        if self.passed:
            return []
        bad = [f"{n} ({int(r)} runs, {e:.0f} expected)"
               for n, r, e, p in zip(self.names, self.runs, self.expected, self.p_values, strict=True)
               if p * len(self.names) < self.level]
        return [f"the residuals run in long stretches of one sign along frequency in {', '.join(bad)} (runs test, "
                f"p = {float(np.min(self.p_values)):.1e}): a systematic misfit, not noise; the estimate is not valid"]

    def to_dict(self) -> dict[str, Any]:
        return {"test": "runs", "level": self.level, "passed": self.passed,
                "series": {n: {"runs": int(r), "expected": float(e), "p": float(p)}
                           for n, r, e, p in zip(self.names, self.runs, self.expected, self.p_values, strict=True)}}


def runs_test(*, residuals: Sequence[ArrayLike], names: Sequence[str], level: float = LEVEL,
              stride: int = 3) -> RunsTest:
    """Runs test of the signs of each residual series (in frequency order), see :class:`RunsTest`.

    Each series is tested as ``stride`` interleaved sub-series (every third line by default): the errors of
    Welch-averaged H1 estimates correlate positively between neighbouring lines (about +0.44 under a Hann window),
    which alone would shorten the runs; lines three apart are uncorrelated.

    Parameters
    ----------
    residuals : sequence of array_like, shape (n_lines,)
        One real series per FRF pair and part.
    names : sequence of str
        Their names.
    level : float
        Significance level, in (0, 1).
    stride : int
        Spacing of the lines tested together (>= 1).

    Returns
    -------
    RunsTest

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> runs_test(residuals=[rng.standard_normal(400)], names=["noise"]).passed
    True
    >>> runs_test(residuals=[np.sin(np.linspace(0, 9, 400)) + 0.1 * rng.standard_normal(400)], names=["bias"]).passed
    False
    """
    if len(residuals) != len(names):
        msg = f"got {len(residuals)} residual series for {len(names)} names"
        raise DataError(msg)
    runs, expected, p_values = [], [], []
    subseries = [np.asarray(x, dtype=float)[k::stride] for x in residuals for k in range(stride)]
    for series in subseries:
        s = np.sign(series)
        s = s[s != 0]
        n_pos, n_neg = int(np.sum(s > 0)), int(np.sum(s < 0))
        n = n_pos + n_neg
        r = 1 + int(np.sum(s[1:] != s[:-1])) if n else 0
        mu = 2.0 * n_pos * n_neg / n + 1.0 if n else 0.0
        var = (mu - 1.0) * (mu - 2.0) / (n - 1.0) if n > 1 else 0.0
        runs.append(r)
        expected.append(mu)
        p_values.append(float(stats.norm.cdf((r - mu) / np.sqrt(var))) if var > 0 else 1.0)
    # the sub-series of one residual series: a systematic misfit shows in each, noise in none; keep the worst
    n_s = len(residuals)
    p_arr = np.asarray(p_values).reshape(n_s, stride)
    worst = np.argmin(p_arr, axis=1)
    pick = np.arange(n_s) * stride + worst
    return RunsTest(tuple(names), np.asarray(runs, dtype=float)[pick], np.asarray(expected)[pick],
                    np.minimum(1.0, p_arr.min(axis=1) * stride), float(level))
