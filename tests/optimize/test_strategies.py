"""Search strategies against known minima, scipy's shgo and curve_fit, a brute-force grid, and their own reruns."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import optimize as sopt

from cappe.exceptions import ConvergenceWarning, DataError
from cappe.optimize._minimize import STRATEGIES, OptimizationResult, minimize
from cappe.optimize._test_functions import TEST_FUNCTIONS

CAMEL = TEST_FUNCTIONS["camelback"]
GLOBAL = ["direct", "differential-evolution", "dual-annealing"]
FAST_DA = {"maxiter": 300}  # dual annealing's default 1000 iterations are more than these 2- to 5-variable tests need


def _options(strategy):
    return FAST_DA if strategy == "dual-annealing" else None


@pytest.fixture(scope="module")
def shgo_camelback():
    """scipy.optimize.shgo (simplicial homology global optimization) as an independent global reference."""
    res = sopt.shgo(CAMEL, list(zip(*CAMEL.bounds, strict=True)), n=256, iters=1, sampling_method="sobol",
                    minimizer_kwargs={"method": "SLSQP", "options": {"ftol": 1e-14}})
    assert res.success
    return res


@pytest.mark.parametrize("strategy", ["multistart", *GLOBAL])
@pytest.mark.parametrize("with_gradient", [False, True])
def test_camelback_global_minimum(strategy, with_gradient, shgo_camelback):
    """Thesis Fig. 4.3: every strategy finds f = -1.0316 at (+-0.0898, -+0.7126) from a seeded run."""
    res = minimize(CAMEL, CAMEL.bounds, strategy=strategy, rng=11, jac=CAMEL.gradient if with_gradient else None,
                   options=_options(strategy))
    assert res.success, res.message
    # the local polish (SLSQP, ftol 1e-8) leaves ~1e-10 in f; 1e-6 is the required accuracy
    assert res.fun == pytest.approx(shgo_camelback.fun, abs=1e-6)
    assert res.fun == pytest.approx(CAMEL.f_min, abs=1e-6)
    # f - f_min ~ 0.5 * lambda_min * dx^2 with Hessian eigenvalues ~ 4..16: 1e-6 in f allows ~1e-3 in x
    assert np.min(np.max(np.abs(CAMEL.minimizers - res.x), axis=1)) < 1e-3
    assert (res.n_jacobian_evaluations > 0) == with_gradient
    assert res.n_evaluations > 0
    assert res.n_iterations > 0


def _grid_local_minima(f, n_grid=(601, 401)):
    """Reference local minima: discrete minima of a fine grid refined by Nelder-Mead (no cappe code involved)."""
    xs, ys = (np.linspace(lo, hi, k) for lo, hi, k in zip(f.lower, f.upper, n_grid, strict=True))
    grid = f(np.stack(np.meshgrid(xs, ys, indexing="ij")).reshape(2, -1)).reshape(n_grid)
    inner = grid[1:-1, 1:-1]
    mask = np.ones_like(inner, dtype=bool)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di or dj:
                mask &= inner < grid[1 + di:n_grid[0] - 1 + di, 1 + dj:n_grid[1] - 1 + dj]
    i, j = np.nonzero(mask)
    refined = [sopt.minimize(f, [xs[a + 1], ys[b + 1]], method="Nelder-Mead",
                             options={"xatol": 1e-10, "fatol": 1e-14}) for a, b in zip(i, j, strict=True)]
    return sorted(((r.x, r.fun) for r in refined), key=lambda t: t[1])


def test_multistart_finds_all_six_camelback_minima():
    reference = _grid_local_minima(CAMEL)
    assert len(reference) == 6
    res = minimize(CAMEL, CAMEL.bounds, strategy="multistart", n_starts=64, rng=2, jac=CAMEL.gradient)
    assert res.success
    assert len(res.minima) == 6
    starts = [r for r in res.history if r.stage == "local"]
    checks = [r for r in res.history if r.stage == "check"]
    assert len(starts) == 64
    assert len(checks) >= 6  # one neighbourhood search per distinct end point
    restarts = [r for r in res.history if r.stage == "restart"]
    assert sum(m.hits for m in res.minima) <= 64 + len(restarts)
    assert [m.fun for m in res.minima] == sorted(m.fun for m in res.minima)
    for (_, f_ref), m in zip(reference, res.minima, strict=True):
        # same ordering by value; the two members of each symmetric pair have equal values, so match by position
        dist = min(np.max(np.abs(m.x - x)) for x, _ in reference)
        assert dist < 1e-4  # SLSQP's ftol 1e-8 leaves ~1e-5 in x at these curvatures
        assert m.fun == pytest.approx(f_ref, abs=1e-8)
    # the global minimum is the one reported
    assert res.fun == pytest.approx(CAMEL.f_min, abs=1e-9)
    assert all(r.method == "SLSQP" for r in res.history)


def test_saddle_points_are_not_reported_as_minima():
    """The camelback's origin is a saddle (gradient 0, Hessian [[8, 1], [1, -8]]): SLSQP started there stops at
    once and calls it converged; the check restart descends from it, and it is dropped from the minima."""
    res = minimize(CAMEL, CAMEL.bounds, x0=[0.0, 0.0], n_starts=0, rng=0, jac=CAMEL.gradient)
    first = res.history[0]
    assert first.success
    np.testing.assert_array_equal(first.x, [0.0, 0.0])
    assert all(np.max(np.abs(m.x)) > 0.05 for m in res.minima)
    assert res.fun < -0.2  # the restart reached a true minimum (-1.0316 or -0.2155)
    assert "stationary points but not minima" in res.message
    unchecked = minimize(CAMEL, CAMEL.bounds, x0=[0.0, 0.0], n_starts=0, jac=CAMEL.gradient, check_minima=False)
    assert len(unchecked.minima) == 1
    assert unchecked.fun == 0.0


def test_few_starts_miss_minima_so_the_count_is_informative():
    """Two starts cannot reach six basins: the minima list reflects what the search saw."""
    res = minimize(CAMEL, CAMEL.bounds, strategy="multistart", n_starts=2, rng=2)
    assert 1 <= len(res.minima) <= 2


# asymmetric boxes: the standard ones are centred on the minimizer, which DIRECT samples first
RASTRIGIN_BOX = ([-3.3, -4.1, -2.7, -5.12, -1.9], [5.12, 4.4, 5.12, 3.6, 5.12])
ACKLEY_BOX = ([-20.0, -12.5], [32.768, 27.0])


@pytest.mark.parametrize(("strategy", "n"), [(s, 2) for s in GLOBAL] + [("differential-evolution", 5),
                                                                         ("dual-annealing", 5)])
def test_rastrigin_global_minimum(strategy, n):
    f = TEST_FUNCTIONS["rastrigin"].in_dim(n)
    lower, upper = (np.array(b[:n]) for b in RASTRIGIN_BOX)
    res = minimize(f, (lower, upper), strategy=strategy, rng=5, jac=f.gradient, options=_options(strategy))
    assert res.success, res.message
    # smooth minimum with curvature 2 + 40 pi^2: SLSQP polish reaches ~1e-10 in f; the next local minimum is at f ~ 1
    assert res.fun == pytest.approx(0.0, abs=1e-6)
    np.testing.assert_allclose(res.x, 0.0, atol=1e-4)


@pytest.mark.parametrize("strategy", GLOBAL)
def test_ackley_global_minimum(strategy):
    f = TEST_FUNCTIONS["ackley"]
    res = minimize(f, ACKLEY_BOX, strategy=strategy, rng=5, jac=f.gradient, options=_options(strategy))
    assert res.success, res.message
    # Ackley has a cone tip at 0 (f ~ 4 |x| nearby) that gradient methods approach only to ~1e-7 in x
    assert res.fun == pytest.approx(0.0, abs=1e-5)
    np.testing.assert_allclose(res.x, 0.0, atol=1e-5)


def test_direct_reaches_rastrigin_in_two_variables_only():
    """A known weakness, kept visible: DIRECT (5000 evaluations) ends in a local minimum of Rastrigin in 5-D."""
    f = TEST_FUNCTIONS["rastrigin"].in_dim(5)
    res = minimize(f, RASTRIGIN_BOX, strategy="direct", jac=f.gradient)
    assert res.success  # converged polish: a local minimum, not certified global
    assert res.fun > 0.9  # the next-lowest minima of Rastrigin have f = 0.995 k, k = 1, 2, ...


def _exponential_decay():
    t = np.linspace(0.0, 4.0, 60)
    y = 2.5 * np.exp(-1.3 * t) + 0.4 + 0.01 * np.random.default_rng(3).standard_normal(t.size)

    def residuals(p):
        return p[0] * np.exp(-p[1] * t) + p[2] - y

    def jacobian(p):
        e = np.exp(-p[1] * t)
        return np.column_stack([e, -p[0] * t * e, np.ones_like(t)])

    return t, y, residuals, jacobian


def test_least_squares_analytic_jacobian_same_answer_fewer_evaluations():
    t, y, residuals, jacobian = _exponential_decay()
    bounds = ([0.0, 0.1, -1.0], [10.0, 5.0, 2.0])
    exact = minimize(None, bounds, strategy="least-squares", residuals=residuals, residual_jacobian=jacobian,
                     x0=[1.0, 1.0, 0.0])
    numeric = minimize(None, bounds, strategy="least-squares", residuals=residuals, x0=[1.0, 1.0, 0.0])
    reference, _ = sopt.curve_fit(lambda tt, a, b, c: a * np.exp(-b * tt) + c, t, y, p0=[1.0, 1.0, 0.0])
    assert exact.success
    assert numeric.success
    # TRF with ftol = xtol = 1e-8: both fits agree with each other and with curve_fit (LM) to ~1e-8 relative
    np.testing.assert_allclose(exact.x, numeric.x, rtol=1e-6)
    np.testing.assert_allclose(exact.x, reference, rtol=1e-6)
    assert exact.fun == pytest.approx(float(np.sum(residuals(reference) ** 2)), rel=1e-9)
    assert exact.n_evaluations < numeric.n_evaluations  # no finite-difference columns
    assert exact.n_jacobian_evaluations > 0
    assert numeric.n_jacobian_evaluations == 0
    assert exact.history[0].method == "TRF"


@pytest.mark.parametrize("strategy", ["multistart", *GLOBAL])
def test_residuals_drive_every_strategy(strategy):
    """Without fun, the objective is sum(r**2) and every local search is least squares."""
    t, y, residuals, jacobian = _exponential_decay()
    reference, _ = sopt.curve_fit(lambda tt, a, b, c: a * np.exp(-b * tt) + c, t, y, p0=[1.0, 1.0, 0.0])
    res = minimize(None, ([0.0, 0.1, -1.0], [10.0, 5.0, 2.0]), strategy=strategy, residuals=residuals,
                   residual_jacobian=jacobian, rng=0, n_starts=4, options=_options(strategy))
    assert res.success, res.message
    np.testing.assert_allclose(res.x, reference, rtol=1e-6)  # as above
    assert res.history[-1].method == "TRF"


@pytest.mark.parametrize(("strategy", "extra"), [("multistart", {}), ("multistart", {"sampling": "lhs"}),
                                                 ("differential-evolution", {}), ("dual-annealing", {})])
def test_seeds_reproduce_bit_for_bit(strategy, extra):
    def run(seed):
        return minimize(CAMEL, CAMEL.bounds, strategy=strategy, rng=seed, options=_options(strategy), **extra)

    a, b, c = run(123), run(123), run(np.random.default_rng(124))
    np.testing.assert_array_equal(a.x, b.x)
    assert a.fun == b.fun
    assert a.n_evaluations == b.n_evaluations
    assert a.to_dict() == b.to_dict()
    # a different seed takes a different path (otherwise the check above could not fail)
    assert a.to_dict()["history"] != c.to_dict()["history"] or a.n_evaluations != c.n_evaluations


def test_direct_is_deterministic_without_a_seed():
    a = minimize(CAMEL, CAMEL.bounds, strategy="direct")
    b = minimize(CAMEL, CAMEL.bounds, strategy="direct", rng=99)
    assert a.to_dict() == b.to_dict()


@pytest.mark.parametrize("strategy", STRATEGIES)
def test_budget_exhaustion_fails_with_a_warning(strategy):
    t, y, residuals, _ = _exponential_decay()
    fun = None if strategy == "least-squares" else CAMEL
    bounds = ([0.0, 0.1, -1.0], [10.0, 5.0, 2.0]) if fun is None else CAMEL.bounds
    with pytest.warns(ConvergenceWarning, match=rf"minimize \({strategy}\) did not converge: stopped at "
                                                r"max_evaluations=3"):
        res = minimize(fun, bounds, strategy=strategy, rng=0, max_evaluations=3,
                       residuals=residuals if fun is None else None)
    assert not res.success
    assert res.n_evaluations <= 3
    assert np.all(np.isfinite(res.x))
    assert np.isfinite(res.fun)  # the best point evaluated is returned, with its value


def test_budget_shares_let_a_global_phase_end_normally():
    """With a budget, DE's generations are cut to fit; the polish then converges within the rest."""
    res = minimize(CAMEL, CAMEL.bounds, strategy="differential-evolution", rng=3, max_evaluations=400)
    assert res.success, res.message
    assert res.n_evaluations <= 400
    assert res.fun == pytest.approx(CAMEL.f_min, abs=1e-6)


def test_local_iteration_limit_reports_failure():
    rosen = TEST_FUNCTIONS["rosenbrock"]
    with pytest.warns(ConvergenceWarning, match="did not converge: 0 of 1 local searches"):
        res = minimize(rosen, rosen.bounds, x0=[-1.2, 1.0], n_starts=0, options={"local_maxiter": 2})
    assert not res.success
    assert "Iteration limit" in res.history[0].message
    assert res.minima == ()  # a search that did not converge is not a local minimum


def test_vectorized_differential_evolution_calls_with_column_batches():
    seen = []

    def batched(x):
        seen.append(x.shape)
        return CAMEL(x)

    res = minimize(batched, CAMEL.bounds, strategy="differential-evolution", rng=4, vectorized=True)
    assert res.success
    assert res.fun == pytest.approx(CAMEL.f_min, abs=1e-6)  # as in the camelback test
    assert all(s[0] == 2 for s in seen)  # (n, S) columns, scipy's convention
    assert max(s[1] for s in seen) >= 30  # a whole generation (popsize 15 x 2 variables) in one call
    assert len(seen) < res.n_evaluations


@pytest.mark.parametrize("strategy", ["multistart", *GLOBAL])
def test_objective_is_never_evaluated_outside_the_box(strategy):
    lower, upper = np.array([0.5, -1.0]), np.array([1.5, 0.25])
    points = []

    def fun(x):
        points.append(np.array(x, dtype=float))
        return float((x[0] - 2.0) ** 2 + (x[1] + 3.0) ** 2)  # unconstrained minimum (2, -3) lies outside

    res = minimize(fun, (lower, upper), strategy=strategy, rng=0, options=_options(strategy))
    pts = np.array(points)
    assert np.all((pts >= lower) & (pts <= upper))
    # closed form: the constrained minimum is the corner nearest (2, -3)
    np.testing.assert_allclose(res.x, [1.5, -1.0], atol=1e-6)
    assert res.success


def test_nan_values_count_as_infinite():
    def fun(x):
        return float("nan") if x[0] < 0.0 else float((x[0] - 0.5) ** 2 + x[1] ** 2)

    res = minimize(fun, ([-1.0, -1.0], [1.0, 1.0]), strategy="differential-evolution", rng=0)
    np.testing.assert_allclose(res.x, [0.5, 0.0], atol=1e-5)
    assert res.success


@pytest.mark.parametrize("strategy", ["multistart", *GLOBAL])
def test_errors_in_the_objective_propagate(strategy):
    def broken(x):
        msg = "model parameter 'k9' is missing"
        raise KeyError(msg)

    with pytest.raises(KeyError, match="k9"):
        minimize(broken, CAMEL.bounds, strategy=strategy, rng=0)


def test_result_to_dict_is_json():
    res = minimize(CAMEL, CAMEL.bounds, strategy="multistart", n_starts=8, rng=0)
    doc = json.loads(json.dumps(res.to_dict()))
    assert doc["format"] == "cappe.optimize/1"
    assert doc["x"] == [float(v) for v in res.x]
    assert sum(r["stage"] == "local" for r in doc["history"]) == 8
    assert doc["minima"][0]["fun"] == pytest.approx(CAMEL.f_min, abs=1e-6)
    assert isinstance(res, OptimizationResult)
    with pytest.raises(AttributeError):
        res.fun = 0.0  # frozen


def test_multiple_x0_rows_are_all_started():
    starts = np.array([[1.7, -0.8], [-1.6, -0.57]])
    res = minimize(CAMEL, CAMEL.bounds, x0=starts, n_starts=0)
    np.testing.assert_array_equal(np.array([r.start for r in res.history if r.stage == "local"]), starts)
    assert res.fun == pytest.approx(-0.21546382438371764, abs=1e-8)  # the lower of the two nearby local minima


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"strategy": "annealing"}, r"strategy must be one of \['multistart', .*\]; got 'annealing'"),
        ({"bounds": ([0.0, 0.0], [1.0])}, r"bounds must be \(lower, upper\), two arrays of shape \(n,\); got shapes \(2,\) and \(1,\)"),
        ({"bounds": [(0.0, 1.0), (0.0, 1.0), (0.0, 1.0)]}, r"bounds must be \(lower, upper\).*numpy.transpose"),
        ({"bounds": ([0.0, 1.0], [1.0, 1.0])}, r"bounds must satisfy lower < upper; got lower\[1\]=1 >= upper\[1\]=1"),
        ({"bounds": ([0.0, 0.0], [1.0, np.inf])}, r"bounds must be finite"),
        ({"x0": [0.5, 3.0]}, r"x0 must lie inside the bounds; got x0\[0\]\[1\]=3 outside \[-2, 2\]"),
        ({"x0": [0.5]}, r"x0 must have shape \(2,\) or \(k, 2\) to match the bounds; got \(1,\)"),
        ({"x0": [0.5, np.nan]}, r"x0 must be finite"),
        ({"fun": None}, r"fun is None and no residuals are given"),
        ({"fun": 3.0}, r"fun must be callable or None; got float"),
        ({"strategy": "least-squares"}, r"strategy 'least-squares' needs residuals"),
        ({"residual_jacobian": np.ones}, r"residual_jacobian is given without residuals"),
        ({"n_starts": -1}, r"n_starts must be an integer >= 0; got -1"),
        ({"n_starts": 0}, r"multistart needs at least one start: give x0 or n_starts >= 1"),
        ({"max_evaluations": 0}, r"max_evaluations must be an integer >= 1; got 0"),
        ({"tol": -1e-3}, r"tol must be a finite number > 0; got -0.001"),
        ({"sampling": "halton"}, r"sampling must be 'sobol' or 'lhs'; got 'halton'"),
        ({"cluster_tol": 2.0}, r"cluster_tol must lie in \(0, 1\)"),
        ({"strategy": "direct", "options": {"popsize": 5}}, r"options for strategy 'direct' may be .*; got unknown \['popsize'\]"),
        ({"options": {"local_maxiter": 0}}, r"options\['local_maxiter'\] must be an integer >= 1; got 0"),
        ({"options": {"local_maxiter": True}}, r"options\['local_maxiter'\] must be an integer >= 1; got True"),
        ({"vectorized": True, "fun": None, "residuals": np.sin}, r"vectorized=True applies to fun, but fun is None"),
    ],
)
def test_argument_errors_name_the_argument(kwargs, match):
    args = {"fun": CAMEL, "bounds": CAMEL.bounds, **kwargs}
    fun, bounds = args.pop("fun"), args.pop("bounds")
    with pytest.raises(DataError, match=match):
        minimize(fun, bounds, **args)


def test_bad_return_values_are_data_errors():
    with pytest.raises(DataError, match=r"fun must return a scalar; got an array of shape \(2,\)"):
        minimize(lambda x: x, CAMEL.bounds, n_starts=1, rng=0)
    with pytest.raises(DataError, match=r"vectorized fun must map a batch \(n, S\) = \(2, 30\) to shape \(30,\)"):
        minimize(lambda x: x, CAMEL.bounds, strategy="differential-evolution", vectorized=True, rng=0)
    with pytest.raises(DataError, match=r"jac must return the gradient, shape \(2,\); got \(3,\)"):
        minimize(CAMEL, CAMEL.bounds, jac=lambda x: np.ones(3), n_starts=1, rng=0)
    with pytest.raises(DataError, match=r"residual_jacobian must return shape \(n_residuals, 2\); got \(4, 3\)"):
        minimize(None, CAMEL.bounds, strategy="least-squares", residuals=lambda x: np.ones(4) * x[0],
                 residual_jacobian=lambda x: np.ones((4, 3)))
    with pytest.raises(DataError, match=r"residuals must return a 1-D array; got shape \(\)"):
        minimize(None, CAMEL.bounds, strategy="least-squares", residuals=lambda x: x[0])
    with pytest.raises(TypeError, match="rng must be an int seed"):
        minimize(CAMEL, CAMEL.bounds, rng="seed")


def test_fun_and_residuals_together_report_fun():
    """fun = 0.5 sum(r**2) drives the evolution and is what is reported; the residuals drive the TRF polish."""
    t, y, residuals, jacobian = _exponential_decay()
    reference, _ = sopt.curve_fit(lambda tt, a, b, c: a * np.exp(-b * tt) + c, t, y, p0=[1.0, 1.0, 0.0])

    def half(x):
        return 0.5 * float(np.sum(residuals(x) ** 2))

    res = minimize(half, ([0.0, 0.1, -1.0], [10.0, 5.0, 2.0]), strategy="differential-evolution", rng=1,
                   residuals=residuals, residual_jacobian=jacobian)
    assert res.success
    np.testing.assert_allclose(res.x, reference, rtol=1e-6)  # TRF ftol = xtol = 1e-8, as above
    assert res.fun == half(res.x)
    assert res.history[-1].fun == half(res.history[-1].x)


def test_least_squares_strategy_runs_no_check_restarts():
    _, _, residuals, jacobian = _exponential_decay()
    res = minimize(None, ([0.0, 0.1, -1.0], [10.0, 5.0, 2.0]), strategy="least-squares", residuals=residuals,
                   residual_jacobian=jacobian)
    assert [r.stage for r in res.history] == ["local"]
    np.testing.assert_array_equal(res.history[0].start, [5.0, 2.55, 0.5])  # the box centre without x0


def test_vectorized_fun_works_with_every_strategy():
    shapes = set()

    def batched(x):
        shapes.add(x.shape)
        return CAMEL(x)

    for strategy in ("multistart", "direct", "dual-annealing"):
        res = minimize(batched, CAMEL.bounds, strategy=strategy, rng=0, vectorized=True, options=_options(strategy))
        assert res.fun == pytest.approx(CAMEL.f_min, abs=1e-6)  # as in the camelback test
    assert shapes == {(2, 1)}  # single points arrive as one-column batches


def test_solver_errors_become_failed_searches():
    """least_squares refuses non-finite residuals at its start; that is a failed search, not an exception."""
    with pytest.warns(ConvergenceWarning, match=r"did not converge: every search failed: TRF failed: .*not finite"):
        res = minimize(None, CAMEL.bounds, strategy="least-squares", residuals=lambda x: np.full(3, np.nan))
    assert not res.success
    assert res.history[0].fun == np.inf
    assert res.minima == ()
