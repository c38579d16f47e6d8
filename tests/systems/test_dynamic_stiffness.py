"""The dynamic-stiffness FRF kernel against closed forms of a 1- and a 2-DOF oscillator and finite differences."""

from __future__ import annotations

import numpy as np
import pytest

from cappe.systems.dynamic_stiffness import dynamic_stiffness, frf_lines


def two_dof(k1: float = 4e4, k2: float = 2.5e4, c1: float = 12.0, c2: float = 3.0, eta: float = 0.01,
            gyro: float = 5.0) -> dict[str, np.ndarray]:
    """Two masses in a chain (ground - k1 - m1 - k2 - m2), viscous and hysteretic damping and a skew G."""
    m = np.diag([2.0, 0.5])
    k = np.array([[k1 + k2, -k2], [-k2, k2]])
    c = np.array([[c1 + c2, -c2], [-c2, c2]])
    return {"M": m, "K": k, "C": c, "G": np.array([[0.0, gyro], [-gyro, 0.0]]), "H": eta * k}


def test_one_dof_closed_form_and_output_orders() -> None:
    # m x'' + c x' + (k + i h) x = F: H = 1 / (k + i h + i w c - w^2 m); velocity and acceleration times (i w)^order
    m, c, k, h = 3.0, 7.0, 2e4, 150.0
    mats = {"M": np.array([[m]]), "C": np.array([[c]]), "K": np.array([[k]]), "G": np.zeros((1, 1)),
            "H": np.array([[h]])}
    w = np.linspace(0.0, 300.0, 41)
    out = frf_lines(mats, w, np.eye(1), np.ones((3, 1)), orders=[0, 1, 2])
    exact = 1.0 / (k + 1j * h + 1j * w * c - w**2 * m)
    # closed form vs one LU per line of a 1 x 1 system: equal to round-off (rtol 1e-13)
    np.testing.assert_allclose(out.H[:, 0, 0], exact, rtol=1e-13)
    np.testing.assert_allclose(out.H[:, 1, 0], 1j * w * exact, rtol=1e-13)
    np.testing.assert_allclose(out.H[:, 2, 0], -(w**2) * exact, rtol=1e-13)
    assert out.L is None
    assert out.dH.shape == (0, *out.H.shape)


def test_two_dof_closed_form() -> None:
    # the 2 x 2 inverse by its adjugate: Z^-1 = [[z22, -z12], [-z21, z11]] / det Z
    mats = two_dof()
    w = np.linspace(1.0, 400.0, 57)
    z11 = mats["K"][0, 0] + 1j * mats["H"][0, 0] + 1j * w * mats["C"][0, 0] - w**2 * mats["M"][0, 0]
    z22 = mats["K"][1, 1] + 1j * mats["H"][1, 1] + 1j * w * mats["C"][1, 1] - w**2 * mats["M"][1, 1]
    z12 = mats["K"][0, 1] + 1j * mats["H"][0, 1] + 1j * w * (mats["C"][0, 1] + mats["G"][0, 1])
    z21 = mats["K"][1, 0] + 1j * mats["H"][1, 0] + 1j * w * (mats["C"][1, 0] + mats["G"][1, 0])
    det = z11 * z22 - z12 * z21
    exact = np.stack([np.stack([z22, -z12], -1), np.stack([-z21, z11], -1)], -2) / det[:, None, None]
    out = frf_lines(mats, w, np.eye(2), np.eye(2))
    # closed form vs LAPACK's LU: round-off amplified by the condition number near resonance (rtol 1e-10)
    np.testing.assert_allclose(out.H, exact, rtol=1e-10, atol=0)
    # only the wanted input column and output row are formed
    one = frf_lines(mats, w, np.eye(2)[:, [1]], np.eye(2)[[0]])
    np.testing.assert_allclose(one.H[:, 0, 0], exact[:, 0, 1], rtol=1e-10)
    np.testing.assert_array_equal(dynamic_stiffness(mats, w)[:, 0, 1], z12)


@pytest.mark.parametrize(("n_in", "n_out"), [(2, 2), (1, 1)])
def test_derivatives_match_central_differences(n_in: int, n_out: int) -> None:
    # dH/dp = -L dZ/dp X against central differences of the closed form in k1, k2, c2, the loss factor and the
    # gyroscopic coefficient; (2, 2) takes the one-inverse path, (1, 1) of 2 DOFs the two-solve path
    base = {"k1": 4e4, "k2": 2.5e4, "c2": 3.0, "eta": 0.01, "gyro": 5.0}
    w = np.linspace(5.0, 350.0, 31)
    b, s = np.eye(2)[:, :n_in], np.eye(2)[:n_out] + 0.3
    derivs: dict[str, list[np.ndarray]] = {name: [] for name in "MCKGH"}
    numeric = []
    for name, value in base.items():
        step = 1e-6 * value
        hi, lo = two_dof(**{**base, name: value + step}), two_dof(**{**base, name: value - step})
        for key in "MCKGH":
            derivs[key].append((hi[key] - lo[key]) / (2 * step))  # exact: every matrix is affine in each value
        numeric.append((frf_lines(hi, w, b, s, orders=[1] * n_out).H - frf_lines(lo, w, b, s, orders=[1] * n_out).H)
                       / (2 * step))
    out = frf_lines(two_dof(**base), w, b, s, orders=[1] * n_out,
                    derivatives={key: np.array(v) for key, v in derivs.items()})
    assert out.L is not None
    np.testing.assert_allclose(out.L, s @ np.linalg.inv(dynamic_stiffness(two_dof(**base), w)), rtol=1e-12)
    # central differences with a relative step of 1e-6: truncation ~1e-12, cancellation ~1e-10 relative (rtol 1e-6)
    for d in range(len(base)):
        scale = np.abs(numeric[d]).max()
        np.testing.assert_allclose(out.dH[d], numeric[d], rtol=1e-6, atol=1e-7 * scale)


def test_singular_line() -> None:
    # an undamped 1-DOF oscillator is singular at its natural frequency: raise, or inf there with the line marked
    mats = {"M": np.array([[1.0]]), "C": np.zeros((1, 1)), "K": np.array([[4.0]]), "G": np.zeros((1, 1)),
            "H": np.zeros((1, 1))}
    w = np.array([1.0, 2.0, 3.0])
    with pytest.raises(np.linalg.LinAlgError):
        frf_lines(mats, w, np.eye(1), np.eye(1))
    out = frf_lines(mats, w, np.eye(1), np.eye(1), singular="inf")
    np.testing.assert_array_equal(out.singular, [False, True, False])
    assert np.isinf(out.H[1, 0, 0])
    np.testing.assert_allclose(out.H[[0, 2], 0, 0], [1 / 3, -1 / 5], rtol=1e-15)  # 1 / (k - w^2 m)
