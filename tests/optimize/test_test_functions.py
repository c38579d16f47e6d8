"""The test-function registry against literature values, scipy's own Rosenbrock, finite differences and brute force."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import optimize as sopt
from scipy.differentiate import jacobian

from cappe.exceptions import DataError
from cappe.optimize._test_functions import TEST_FUNCTIONS, BenchmarkFunction

# Published global minima (Jamil & Yang 2013; Surjanovic & Bingham, VLSE; thesis Fig. 4.3 for the camelback), with
# the number of decimals they are published to: the registry must agree to one unit in the last published decimal
# (some sources truncate rather than round: 0.71265... is published as 0.7126).
LITERATURE = {
    "camelback": (-1.0316, [(0.0898, -0.7126), (-0.0898, 0.7126)], 4),
    "rosenbrock": (0.0, [(1.0, 1.0)], 12),
    "rastrigin": (0.0, [(0.0, 0.0)], 12),
    "ackley": (0.0, [(0.0, 0.0)], 12),
    "branin": (0.397887, [(-np.pi, 12.275), (np.pi, 2.275), (9.42478, 2.475)], 5),
    "goldstein-price": (3.0, [(0.0, -1.0)], 12),
    "himmelblau": (0.0, [(3.0, 2.0), (-2.805118, 3.131312), (-3.779310, -3.283186), (3.584428, -1.848126)], 6),
}


@pytest.mark.parametrize("name", sorted(TEST_FUNCTIONS))
def test_registry_matches_literature(name):
    f = TEST_FUNCTIONS[name]
    f_lit, x_lit, decimals = LITERATURE[name]
    tol = 10.0**-decimals  # one unit in the last published decimal
    assert abs(f.f_min - f_lit) <= tol
    np.testing.assert_allclose(f.minimizers, np.array(x_lit), atol=tol)
    for x in f.minimizers:
        # the stored minimizers are refined to 17 digits: the value there is f_min to round-off (1e-12 absolute)
        assert f(x) == pytest.approx(f.f_min, abs=1e-12)
        assert np.all((f.lower <= x) & (x <= f.upper))


@pytest.mark.parametrize("name", sorted(TEST_FUNCTIONS))
def test_global_minimum_by_brute_force(name):
    """scipy.optimize.brute (a 201-point grid per axis, then Nelder-Mead) is an independent global search."""
    f = TEST_FUNCTIONS[name]
    ranges = tuple(zip(f.lower, f.upper, strict=True))
    x, fval, *_ = sopt.brute(f, ranges, Ns=201, full_output=True,
                             finish=lambda g, x0, **kw: sopt.fmin(g, x0, xtol=1e-10, ftol=1e-12, full_output=True,
                                                                 disp=False))
    # Nelder-Mead's ftol 1e-12 leaves ~1e-9 in f; Ackley's non-differentiable tip and its exp() leave ~1e-8
    assert fval == pytest.approx(f.f_min, abs=1e-7)
    assert np.min(np.max(np.abs(f.minimizers - x), axis=1)) < 1e-4


@pytest.mark.parametrize("name", sorted(TEST_FUNCTIONS))
def test_gradient_matches_finite_differences(name):
    f = TEST_FUNCTIONS[name]
    points = np.random.default_rng(7).uniform(f.lower, f.upper, size=(20, f.n))
    for x in points:
        numeric = _numeric_jacobian(f, x)
        # scipy.differentiate's adaptive central differences reach ~1e-10 relative; 1e-8 leaves room for the
        # steep corners of Goldstein-Price (|grad| ~ 1e6) and Ackley's exponentials
        np.testing.assert_allclose(f.gradient(x), numeric, rtol=1e-8, atol=1e-8 * (1.0 + abs(f(x))))


@pytest.mark.parametrize("name", sorted(TEST_FUNCTIONS))
def test_batches_match_single_points(name):
    f = TEST_FUNCTIONS[name]
    batch = np.random.default_rng(3).uniform(f.lower, f.upper, size=(7, f.n)).T  # (n, S)
    np.testing.assert_array_equal(f(batch), [f(batch[:, j]) for j in range(7)])
    np.testing.assert_array_equal(f.gradient(batch), np.column_stack([f.gradient(batch[:, j]) for j in range(7)]))


@pytest.mark.parametrize("n", [2, 5])
def test_rosenbrock_matches_scipy(n):
    f = TEST_FUNCTIONS["rosenbrock"].in_dim(n)
    batch = np.random.default_rng(n).uniform(-2.0, 2.0, size=(n, 4))
    # same formula evaluated in a different order: equal to a few ulps of values up to ~1e4
    np.testing.assert_allclose(f(batch), sopt.rosen(batch), rtol=1e-14)
    np.testing.assert_allclose(f.gradient(batch[:, 0]), sopt.rosen_der(batch[:, 0]), rtol=1e-13)
    assert f.n == n
    np.testing.assert_array_equal(f.minimizers, np.ones((1, n)))


@pytest.mark.parametrize("name", ["rastrigin", "ackley"])
def test_scalable_functions_in_five_variables(name):
    f = TEST_FUNCTIONS[name].in_dim(5)
    assert f(np.zeros(5)) == pytest.approx(0.0, abs=1e-14)  # closed form: 0 at the origin
    assert f(np.full(5, 0.5)) > 1.0  # and clearly positive away from it
    assert f.bounds[0].shape == (5,)


def _numeric_jacobian(func, x):
    """scipy.differentiate.jacobian of a function that takes points along the first axis (n, ...)."""
    n = x.size

    def columns(z):
        flat = z.reshape(n, -1)
        out = np.asarray(func(flat))
        return out.reshape(out.shape[:-1] + z.shape[1:])

    res = jacobian(columns, x)
    assert np.all(res.success)
    return res.df


def _hessian(f, x):
    return _numeric_jacobian(f.gradient, x)


def test_camelback_has_six_local_minima():
    """Thesis Fig. 4.3: the gradient vanishes and the Hessian is positive definite at the six listed points, and a
    fine grid (independent of the stored list) has exactly six discrete local minima, each next to one of them."""
    f = TEST_FUNCTIONS["camelback"]
    assert f.local_minima is not None
    assert len(f.local_minima) == 6
    for x in f.local_minima:
        np.testing.assert_allclose(f.gradient(x), 0.0, atol=1e-12)  # 17-digit minimizers: round-off level
        assert np.all(np.linalg.eigvalsh(_hessian(f, x)) > 0.0)
    xs, ys = np.linspace(-3.0, 3.0, 601), np.linspace(-2.0, 2.0, 401)
    grid = f(np.stack(np.meshgrid(xs, ys, indexing="ij")).reshape(2, -1)).reshape(601, 401)
    inner = grid[1:-1, 1:-1]
    lower_than_neighbours = np.ones_like(inner, dtype=bool)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di or dj:
                lower_than_neighbours &= inner < grid[1 + di:600 + di, 1 + dj:400 + dj]
    i, j = np.nonzero(lower_than_neighbours)
    found = np.column_stack([xs[i + 1], ys[j + 1]])
    assert len(found) == 6
    for x in found:  # each grid minimum is within one grid step (0.01) of a listed minimum
        assert np.min(np.max(np.abs(f.local_minima - x), axis=1)) <= 0.01


def test_errors_name_the_problem():
    camel = TEST_FUNCTIONS["camelback"]
    with pytest.raises(DataError, match=r"x for 'camelback' must have shape \(2,\) or \(2, S\); got \(3,\)"):
        camel(np.zeros(3))
    with pytest.raises(DataError, match=r"'camelback' is defined in 2 variables only; got n=3"):
        camel.in_dim(3)
    with pytest.raises(DataError, match=r"n must be >= 1; got 0"):
        TEST_FUNCTIONS["rastrigin"].in_dim(0)
    bare = BenchmarkFunction("bare", np.zeros(1), np.ones(1), 0.0, np.zeros((1, 1)), lambda x: x[0] ** 2)
    with pytest.raises(DataError, match=r"test function 'bare' has no analytic gradient"):
        bare.gradient(np.zeros(1))
