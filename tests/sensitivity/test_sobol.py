"""Global sensitivity analysis: Sobol' indices and Morris screening.

References: SALib 1.6 (``SALib.analyze.sobol.analyze`` and ``SALib.analyze.morris.analyze``) run one output at a
time on the very same samples and bootstrap seeds; the Ishigami function's closed-form indices (Ishigami & Homma
1990; Sobol' & Levitan 1999), computed below from the variance decomposition, not copied.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from SALib.analyze import morris as salib_morris_analyze
from SALib.analyze import sobol as salib_sobol_analyze
from SALib.sample import morris as salib_morris_sample
from SALib.sample import sobol as salib_sobol_sample

from cappe.exceptions import DataError, IllConditionedWarning, ModelError
from cappe.sensitivity import MorrisResult, SobolResult, morris_screening, sobol_analyze, sobol_indices

# Same estimators on the same numbers; only the summation order differs (observed differences < 1e-15).
SALIB_ATOL = 1e-10
PI = math.pi
ISHIGAMI_BOUNDS = [[-PI, PI]] * 3
ISHIGAMI_NAMES = ["x1", "x2", "x3"]


# ------------------------------------------------------------------------------------------------ test functions


def ishigami(x: np.ndarray, a: float = 7.0, b: float = 0.1) -> np.ndarray:
    return np.sin(x[:, 0]) + a * np.sin(x[:, 1]) ** 2 + b * x[:, 2] ** 4 * np.sin(x[:, 0])


def ishigami_exact(a: float, b: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Closed-form (S1, ST, S13) of the Ishigami function with x ~ U(-pi, pi)^3.

    f = f1(x1) + f2(x2) + f13(x1, x3) with partial variances V1 = (1 + b pi^4 / 5)^2 / 2, V2 = a^2 / 8,
    V13 = b^2 pi^8 (1/18 - 1/50); V = V1 + V2 + V13.
    """
    v1 = 0.5 * (1 + b * PI**4 / 5) ** 2
    v2 = a**2 / 8
    v13 = b**2 * PI**8 * (1 / 18 - 1 / 50)
    v = v1 + v2 + v13
    return np.array([v1, v2, 0.0]) / v, np.array([v1 + v13, v2, v13]) / v, v13 / v


def g_function(x: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Sobol' G-function on [0, 1]^D."""
    return np.prod((np.abs(4 * x - 2) + a) / (1 + a), axis=1)


def ishigami_outputs(x: np.ndarray) -> np.ndarray:
    return np.column_stack([ishigami(x, a, b) for a, b in ((7.0, 0.1), (5.0, 0.05), (2.0, 0.3))])


def g_outputs(x: np.ndarray) -> np.ndarray:
    a_sets = ([0, 1, 4.5, 9, 99, 99], [0, 0, 0, 0, 0, 0], [1, 2, 5, 10, 20, 50])
    return np.column_stack([g_function(x, np.array(a, dtype=float)) for a in a_sets])


LINEAR_W = np.array([[1.0e-3, 0.0, 2.0e-3], [3.0, -1.0, 0.5], [0.2, 0.2, -0.1], [500.0, 0.0, 100.0]])


def linear_outputs(x: np.ndarray) -> np.ndarray:
    return 1.0e4 + x @ LINEAR_W  # a large offset: SALib's estimators depend on centring


PROBLEMS = {
    "ishigami": (ISHIGAMI_BOUNDS, ishigami_outputs),
    "g_function": ([[0.0, 1.0]] * 6, g_outputs),
    "linear": ([[1.0e3, 2.0e3], [0.0, 1.0], [-5.0, 5.0], [1.0e-3, 2.0e-3]], linear_outputs),
}


def salib_problem(bounds: list[list[float]]) -> dict:
    return {"num_vars": len(bounds), "names": [f"p{i}" for i in range(len(bounds))], "bounds": bounds}


def assert_matches_salib(res: SobolResult, Y: np.ndarray, problem: dict, second_order: bool, seed: int) -> None:
    keys = ["S1", "S1_conf", "ST", "ST_conf"] + (["S2", "S2_conf"] if second_order else [])
    for o in range(Y.shape[1]):
        ref = salib_sobol_analyze.analyze(problem, Y[:, o], calc_second_order=second_order, num_resamples=100,
                                          conf_level=0.95, seed=seed)
        for key in keys:
            np.testing.assert_allclose(getattr(res, key)[o], ref[key], rtol=0, atol=SALIB_ATOL, err_msg=key)


# ------------------------------------------------------------------------------------------------ (a) vs SALib


@pytest.mark.parametrize("second_order", [False, True])
@pytest.mark.parametrize("problem_name", list(PROBLEMS))
def test_sobol_analyze_matches_salib_on_identical_samples(problem_name: str, second_order: bool) -> None:
    bounds, func = PROBLEMS[problem_name]
    problem = salib_problem(bounds)
    X = salib_sobol_sample.sample(problem, 256, calc_second_order=second_order, seed=5)
    Y = func(X)
    res = sobol_analyze(Y, names=problem["names"], second_order=second_order, rng=11)
    assert res.S1.shape == (Y.shape[1], len(bounds))
    assert (res.S2 is not None) == second_order
    assert_matches_salib(res, Y, problem, second_order, seed=11)


def test_sobol_indices_reproducible_in_salib_from_stored_seeds() -> None:
    res = sobol_indices(func=g_outputs, bounds=[[0.0, 1.0]] * 6, names=[f"p{i}" for i in range(6)], n=128, rng=42,
                        second_order=True, keep_samples=True)
    # the documented seed derivation
    assert (res.sample_seed, res.bootstrap_seed) == tuple(np.random.default_rng(42).integers(1, 2**31, size=2))
    problem = salib_problem([[0.0, 1.0]] * 6)
    X = salib_sobol_sample.sample(problem, 128, calc_second_order=True, scramble=True, seed=res.sample_seed)
    assert res.X is not None
    assert res.Y is not None
    np.testing.assert_array_equal(res.X, X)
    np.testing.assert_array_equal(res.Y, g_outputs(X))
    assert_matches_salib(res, res.Y, problem, second_order=True, seed=res.bootstrap_seed)


def test_one_dimensional_output_gives_one_row() -> None:
    res = sobol_indices(func=ishigami, bounds=ISHIGAMI_BOUNDS, names=ISHIGAMI_NAMES, n=64, rng=1)
    assert res.S1.shape == (1, 3)
    assert res.output_names == ("y0",)
    assert res.X is None
    assert res.Y is None


# ------------------------------------------------------------------------------------------------ (b) closed form


def test_ishigami_matches_closed_form() -> None:
    s1, st, s13 = ishigami_exact(7.0, 0.1)
    # the numbers quoted in the literature (Saltelli et al. 2008, Table 4.1) as a check of the formulas above
    np.testing.assert_allclose(s1, [0.3139, 0.4424, 0.0], atol=5e-5)  # 4-digit rounding of the published values
    np.testing.assert_allclose(st, [0.5576, 0.4424, 0.2437], atol=5e-5)  # 4-digit rounding of the published values
    res = sobol_indices(func=ishigami, bounds=ISHIGAMI_BOUNDS, names=ISHIGAMI_NAMES, n=2**13, rng=3,
                        second_order=True)
    assert res.S2 is not None
    assert res.S2_conf is not None
    # Tolerance: each index's own 95 % bootstrap half-width at N = 2^13 (about 0.01-0.04). The bootstrap treats
    # the sample as i.i.d. Monte Carlo; scrambled Sobol' points converge at least as fast (observed errors are
    # <= 0.003 for seeds 0..4), so the half-width bounds the error. The bound must also be tight enough to matter:
    assert np.all(res.S1_conf < 0.05)
    assert np.all(res.ST_conf < 0.05)
    assert np.all(np.abs(res.S1[0] - s1) <= res.S1_conf[0])
    assert np.all(np.abs(res.ST[0] - st) <= res.ST_conf[0])
    s2_exact = {(0, 1): 0.0, (0, 2): s13, (1, 2): 0.0}
    for (j, k), value in s2_exact.items():
        assert res.S2_conf[0, j, k] < 0.06  # the S2 estimator is noisier; keep the bound meaningful
        assert abs(res.S2[0, j, k] - value) <= res.S2_conf[0, j, k]
    assert np.isnan(res.S2[0, 1, 0])  # SALib's layout: upper triangle only
    assert res.top_parameters(3) == {"y0": ("x1", "x2", "x3")}
    assert res.top_parameters(2, by="S1") == {"y0": ("x2", "x1")}


# ------------------------------------------------------------------------------------------------ (c) reproducibility


def test_same_rng_same_result_and_chunking_does_not_matter() -> None:
    kwargs = {"func": ishigami_outputs, "bounds": ISHIGAMI_BOUNDS, "names": ISHIGAMI_NAMES, "n": 128,
              "second_order": True}
    ref = sobol_indices(rng=7, **kwargs)
    # exact equality: the same seeds give the same sample, and ishigami is evaluated row by row
    for other in (sobol_indices(rng=7, **kwargs), sobol_indices(rng=np.random.default_rng(7), **kwargs),
                  sobol_indices(rng=7, chunk_size=7, **kwargs), sobol_indices(rng=7, chunk_size=10**6, **kwargs),
                  sobol_indices(rng=7, progress=True, **kwargs)):
        for key in ("S1", "S1_conf", "ST", "ST_conf", "S2", "S2_conf"):
            np.testing.assert_array_equal(getattr(other, key), getattr(ref, key))
    different = sobol_indices(rng=8, **kwargs)
    assert not np.array_equal(different.S1, ref.S1)


def test_output_blocks_do_not_change_results(monkeypatch: pytest.MonkeyPatch) -> None:
    import cappe.sensitivity._sobol as sobol_module

    problem = salib_problem([[0.0, 1.0]] * 6)
    X = salib_sobol_sample.sample(problem, 64, calc_second_order=True, seed=2)
    Y = g_outputs(X)
    ref = sobol_analyze(Y, names=problem["names"], second_order=True, rng=4)
    monkeypatch.setattr(sobol_module, "_BLOCK_ELEMENTS", 1)  # one output per block
    blocked = sobol_analyze(Y, names=problem["names"], second_order=True, rng=4)
    for key in ("S1", "S1_conf", "ST", "ST_conf", "S2", "S2_conf"):
        # per-output arithmetic is the same; BLAS may sum the bootstrap products in another order
        np.testing.assert_allclose(getattr(blocked, key), getattr(ref, key), rtol=0, atol=1e-13)


# ------------------------------------------------------------------------------------------------ zero variance


def test_zero_variance_outputs_are_nan_with_warning() -> None:
    def func(x: np.ndarray) -> np.ndarray:
        return np.column_stack([ishigami(x), np.full(len(x), 0.1 * 3), np.zeros(len(x))])

    with pytest.warns(IllConditionedWarning, match=r"2 of 3 outputs have zero variance .*\['const', 'zero'\].*NaN"):
        res = sobol_indices(func=func, bounds=ISHIGAMI_BOUNDS, names=ISHIGAMI_NAMES, n=1024, rng=0,
                            output_names=["ishigami", "const", "zero"], second_order=True)
    assert np.all(np.isfinite(res.S1[0]))
    assert res.S2 is not None
    for key in ("S1", "S1_conf", "ST", "ST_conf", "S2", "S2_conf"):
        assert np.all(np.isnan(getattr(res, key)[1:]))
    assert res.top_parameters(2) == {"ishigami": ("x1", "x2"), "const": (), "zero": ()}

    Y = np.column_stack([np.arange(5 * 8, dtype=float), np.full(40, 1.0e6)])
    with pytest.warns(IllConditionedWarning, match=r"1 of 2 outputs have zero variance .*\['y1'\]"):
        res2 = sobol_analyze(Y, names=["a", "b", "c"], rng=1)
    assert np.all(np.isnan(res2.ST[1]))


# ------------------------------------------------------------------------------------------------ result object


def test_result_conversions_and_immutability() -> None:
    res = sobol_indices(func=ishigami_outputs, bounds=ISHIGAMI_BOUNDS, names=ISHIGAMI_NAMES, n=64, rng=2,
                        output_names=["a7", "a5", "a2"])
    df = res.to_dataframe()
    assert list(df.columns) == ["output", "parameter", "S1", "S1_conf", "ST", "ST_conf"]
    assert len(df) == 9
    row = df[(df["output"] == "a5") & (df["parameter"] == "x3")].iloc[0]
    assert row["ST"] == res.ST[1, 2]
    assert row["S1_conf"] == res.S1_conf[1, 2]
    d = json.loads(json.dumps(res.to_dict()))
    assert d["names"] == ISHIGAMI_NAMES
    assert d["output_names"] == ["a7", "a5", "a2"]
    assert d["ST"] == res.ST.tolist()
    assert (d["n"], d["n_resamples"], d["conf_level"]) == (64, 100, 0.95)
    assert "S2" not in d
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.n = 3  # type: ignore[misc]
    with pytest.raises(ValueError, match="read-only"):
        res.S1[0, 0] = 1.0


def test_second_order_in_to_dict() -> None:
    res = sobol_indices(func=ishigami, bounds=ISHIGAMI_BOUNDS, names=ISHIGAMI_NAMES, n=32, rng=2, second_order=True)
    d = res.to_dict()
    assert np.array_equal(np.array(d["S2"]), res.S2, equal_nan=True)
    assert np.array_equal(np.array(d["S2_conf"]), res.S2_conf, equal_nan=True)


# ------------------------------------------------------------------------------------------------ (d) errors


def run_sobol(**overrides: object) -> SobolResult:
    kwargs: dict[str, object] = {"func": ishigami, "bounds": ISHIGAMI_BOUNDS, "names": ISHIGAMI_NAMES, "n": 16,
                                 "rng": 0}
    kwargs.update(overrides)
    return sobol_indices(**kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("overrides", "match"),
    [
        ({"bounds": [[0, 1], [2, 1], [0, 1]]}, r"bounds of parameter 'x2' must satisfy lower < upper; got \[2\.0, 1\.0\]"),
        ({"bounds": [[0, 1], [0, 1], [3, 3]]}, r"bounds of parameter 'x3' must satisfy lower < upper; got \[3\.0, 3\.0\]"),
        ({"bounds": [[0, 1], [0, np.inf], [0, 1]]}, r"bounds of parameter 'x2' must be finite; got \[0\.0, inf\]"),
        ({"bounds": [0, 1, 2]}, r"bounds must have shape \(n_params, 2\) with n_params >= 1; got shape \(3,\)"),
        ({"bounds": [[0, 1], [0]]}, r"bounds must be a \(n_params, 2\) array of \(lower, upper\) floats; got"),
        ({"names": ["x1", "x2"]}, r"names has 2 entries but bounds has 3 rows"),
        ({"names": ["x1", "x2", "x1"]}, r"names must be unique; 'x1' appears more than once"),
        ({"names": "abc"}, r"names must be a sequence of strings, one per parameter; got the single string 'abc'"),
        ({"names": ["x1", 2, "x3"]}, r"names must be non-empty strings; got 2"),
        ({"n": 1000}, r"n must be a power of 2 .*; got 1000 \(nearest: 512 or 1024\)"),
        ({"n": 1}, r"n must be an integer >= 2; got 1"),
        ({"n": 16.0}, r"n must be an integer >= 2; got 16\.0"),
        ({"n_resamples": 1}, r"n_resamples must be an integer >= 2; got 1"),
        ({"conf_level": 1.0}, r"conf_level must be a probability strictly between 0 and 1; got 1\.0"),
        ({"conf_level": True}, r"conf_level must be a probability strictly between 0 and 1; got True"),
        ({"chunk_size": 0}, r"chunk_size must be an integer >= 1; got 0"),
        ({"output_names": ["a", "a"]}, r"output_names must be unique; 'a' appears more than once"),
    ],
)
def test_sobol_indices_rejects_bad_problem(overrides: dict[str, object], match: str) -> None:
    with pytest.raises(ModelError, match=match):
        run_sobol(**overrides)


def _calls(*outputs: object):  # type: ignore[no-untyped-def]
    """A func returning the given outputs on successive calls (as arrays sized to the block where callable)."""
    it = iter(outputs)

    def func(x: np.ndarray) -> object:
        out = next(it)
        return out(x) if callable(out) else out

    return func


@pytest.mark.parametrize(
    ("func", "overrides", "match"),
    [
        (lambda x: np.zeros((len(x), 2, 2)), {},
         r"func must return shape \(80,\) or \(80, n_outputs\) with n_outputs >= 1 for a \(80, 3\) block of samples; got shape \(80, 2, 2\)"),
        (lambda x: np.zeros(len(x) - 1), {}, r"func must return shape \(80,\) or \(80, n_outputs\) .*; got shape \(79,\)"),
        (lambda x: np.zeros((len(x), 0)), {}, r"got shape \(80, 0\)"),
        (lambda x: np.zeros(len(x), dtype=complex), {}, r"func must return real outputs; got complex values for samples 0\.\.79"),
        (lambda x: np.full(len(x), "a"), {}, r"func must return a float array; got dtype <U1 for samples 0\.\.79"),
        (lambda x: np.zeros((len(x), 3)), {"output_names": ["a", "b"]}, r"output_names has 2 entries but there are 3 outputs"),
        (_calls(lambda x: np.zeros((len(x), 2)), lambda x: np.zeros((len(x), 3))), {"chunk_size": 50},
         r"func returned 3 outputs for samples 50\.\.79 but 2 for earlier samples; the number of outputs must not change"),
    ],
)
def test_sobol_indices_rejects_bad_func_output(func: object, overrides: dict[str, object], match: str) -> None:
    with pytest.raises(DataError, match=match):
        run_sobol(func=func, **overrides)


def test_non_finite_outputs_are_reported_with_samples_and_outputs() -> None:
    def func(x: np.ndarray) -> np.ndarray:
        y = np.column_stack([ishigami(x), ishigami(x), ishigami(x)])
        y[[3, 17], 1] = np.nan
        y[5, 2] = np.inf
        return y

    with pytest.raises(DataError, match=(r"func returned NaN or Inf for 3 of the samples 0\.\.79 \(sample indices \[3, 5, 17\]\) "
                                         r"in 2 outputs \['b', 'c'\]; every output must be finite for every sample "
                                         r"\(first such sample: x1=-?\d.*, x2=.*, x3=.*\)")):
        run_sobol(func=func, output_names=["a", "b", "c"])

    bad_second_block = _calls(lambda x: ishigami(x), lambda x: np.full(len(x), np.nan))
    with pytest.raises(DataError, match=r"for 10 of the samples 10\.\.19 \(sample indices \[10, 11, 12, 13, 14, \.\.\.\]\) in 1 outputs \['y0'\]"):
        run_sobol(func=bad_second_block, chunk_size=10)


@pytest.mark.parametrize(
    ("Y", "kwargs", "match"),
    [
        (np.zeros(39), {}, r"Y must have n \* \(D \+ 2\) = n \* 5 rows with n >= 2 for D = 3 parameters and second_order=False; got 39 rows"),
        (np.zeros(5), {}, r"Y must have n \* \(D \+ 2\) = n \* 5 rows with n >= 2 .*; got 5 rows"),
        (np.zeros(44), {"second_order": True}, r"Y must have n \* \(2 D \+ 2\) = n \* 8 rows .*second_order=True; got 44 rows"),
        (np.zeros((40, 2, 2)), {}, r"Y must have shape \(n_samples,\) or \(n_samples, n_outputs\) with n_outputs >= 1; got shape \(40, 2, 2\)"),
        (np.array(["a"] * 40), {}, r"Y must be a real float array of shape \(n_samples,\) or \(n_samples, n_outputs\)"),
        (np.where(np.arange(40) % 7 == 3, np.nan, 1.0), {}, r"Y must be finite; got NaN or Inf in 6 rows \[3, 10, 17, 24, 31, \.\.\.\]"),
        (np.zeros((40, 2)), {"output_names": ["a"]}, r"output_names has 1 entries but there are 2 outputs"),
    ],
)
def test_sobol_analyze_rejects_bad_outputs(Y: np.ndarray, kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(DataError, match=match):
        sobol_analyze(Y, names=["a", "b", "c"], **kwargs)  # type: ignore[arg-type]


def test_top_parameters_rejects_bad_arguments() -> None:
    res = run_sobol()
    with pytest.raises(ModelError, match=r"k must be an integer >= 1; got 0"):
        res.top_parameters(0)
    with pytest.raises(ModelError, match=r"by must be 'ST' or 'S1'; got 'S2'"):
        res.top_parameters(2, by="S2")  # type: ignore[arg-type]


# ------------------------------------------------------------------------------------------------ Morris


MORRIS_BOUNDS = [[2.0, 4.0], [0.0, 1.0], [-1.0, 1.0], [10.0, 20.0]]
MORRIS_NAMES = ["lin", "quad", "inert", "only_y1"]


def morris_func(x: np.ndarray) -> np.ndarray:
    """y0 = 5 lin + 2 quad^2 (inert and only_y1 have no effect); y1 = only_y1 (a pure function of one input)."""
    return np.column_stack([5 * x[:, 0] + 2 * x[:, 1] ** 2, x[:, 3]])


def test_morris_finds_inert_parameters_and_ranks_influential_ones() -> None:
    res = morris_screening(func=morris_func, bounds=MORRIS_BOUNDS, names=MORRIS_NAMES, n_trajectories=20, rng=5,
                           keep_samples=True)
    assert isinstance(res, MorrisResult)
    assert res.mu_star.shape == (2, 4)
    # an inert parameter leaves the output bitwise unchanged, so its elementary effects are exactly 0
    np.testing.assert_array_equal(res.mu_star[0, 2:], 0.0)
    np.testing.assert_array_equal(res.mu_star[1, :3], 0.0)
    # a linear term's elementary effect is slope * range (SALib divides by the step as a fraction of the range);
    # rtol: a few roundings in (y(x + d) - y(x)) / delta
    np.testing.assert_allclose(res.mu_star[0, 0], 5 * 2.0, rtol=1e-12)
    np.testing.assert_allclose(res.mu_star[1, 3], 10.0, rtol=1e-12)
    np.testing.assert_allclose(res.sigma[0, 0], 0.0, atol=1e-12)  # linear: every effect equal, up to rounding
    assert res.sigma[0, 1] > 0  # quadratic: effects depend on where the step is taken
    assert res.top_parameters(2)["y0"] == ("lin", "quad")
    assert res.top_parameters(1)["y1"] == ("only_y1",)

    problem = salib_problem(MORRIS_BOUNDS)
    X = salib_morris_sample.sample(problem, 20, num_levels=4, seed=res.sample_seed)
    assert res.X is not None
    assert res.Y is not None
    np.testing.assert_array_equal(res.X, X)
    for o in range(2):
        ref = salib_morris_analyze.analyze(problem, X, np.ascontiguousarray(res.Y[:, o]), num_resamples=100,
                                           conf_level=0.95, num_levels=4, seed=res.bootstrap_seed)
        for key in ("mu", "mu_star", "sigma", "mu_star_conf"):
            # the same SALib call on the same numbers: identical
            np.testing.assert_array_equal(getattr(res, key)[o], np.ma.getdata(ref[key]), err_msg=key)


def test_morris_conversions_and_reproducibility() -> None:
    kwargs = {"func": morris_func, "bounds": MORRIS_BOUNDS, "names": MORRIS_NAMES, "n_trajectories": 6}
    res = morris_screening(rng=1, output_names=["y", "z"], **kwargs)  # type: ignore[arg-type]
    again = morris_screening(rng=1, chunk_size=3, output_names=["y", "z"], **kwargs)  # type: ignore[arg-type]
    for key in ("mu", "mu_star", "sigma", "mu_star_conf"):
        np.testing.assert_array_equal(getattr(again, key), getattr(res, key))  # same seeds, row-wise func
    df = res.to_dataframe()
    assert list(df.columns) == ["output", "parameter", "mu", "mu_star", "sigma", "mu_star_conf"]
    assert len(df) == 8
    assert df.iloc[5]["output"] == "z"
    assert df.iloc[5]["parameter"] == "quad"
    d = json.loads(json.dumps(res.to_dict()))
    assert d["mu_star"] == res.mu_star.tolist()
    assert (d["n_trajectories"], d["num_levels"], d["sample_seed"]) == (6, 4, res.sample_seed)
    assert res.X is None


@pytest.mark.parametrize(
    ("overrides", "match"),
    [
        ({"num_levels": 5}, r"num_levels must be even so that trajectory steps are balanced; got 5"),
        ({"num_levels": 0}, r"num_levels must be an integer >= 2; got 0"),
        ({"n_trajectories": 1}, r"n_trajectories must be an integer >= 2; got 1"),
        ({"bounds": [[0, 1], [0, 1], [1, 0], [0, 1]]}, r"bounds of parameter 'inert' must satisfy lower < upper; got \[1\.0, 0\.0\]"),
        ({"conf_level": 0.0}, r"conf_level must be a probability strictly between 0 and 1; got 0\.0"),
        ({"chunk_size": -1}, r"chunk_size must be an integer >= 1; got -1"),
    ],
)
def test_morris_rejects_bad_problem(overrides: dict[str, object], match: str) -> None:
    kwargs: dict[str, object] = {"func": morris_func, "bounds": MORRIS_BOUNDS, "names": MORRIS_NAMES,
                                 "n_trajectories": 4, "rng": 0}
    kwargs.update(overrides)
    with pytest.raises(ModelError, match=match):
        morris_screening(**kwargs)  # type: ignore[arg-type]


def test_morris_rejects_non_finite_outputs() -> None:
    with pytest.raises(DataError, match=r"func returned NaN or Inf for 20 of the samples 0\.\.19 .* in 1 outputs \['y0'\]"):
        morris_screening(func=lambda x: np.full(len(x), np.nan), bounds=MORRIS_BOUNDS, names=MORRIS_NAMES,
                         n_trajectories=4, rng=0)
