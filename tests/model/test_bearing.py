"""Angular-contact bearing stiffness (cappe.model.bearing) against closed forms and an independent ball-by-ball sum."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cappe.exceptions import ModelError
from cappe.model.bearing import AngularContactBearing, contact_constant, ellipticity

E, NU = 2.08e11, 0.3
#: Thesis Table 5.7: Barden 110H, 18 balls, 15 deg, bore 50 mm, outside 80 mm (pitch 65 mm); the ball diameter
#: (5/16 in) is an assumption of this test.
BARDEN = AngularContactBearing(18, 7.9375e-3, 0.065, math.radians(15.0))


def test_sphere_on_flat_is_the_classical_hertz_contact():
    # a ball of radius R on a flat: sum_rho = 2/R, circular contact; delta^3 = 9 Q^2 / (16 E*^2 R),
    # E* = E / (2 (1 - nu^2)) for two bodies of the same material
    radius, load = 0.004, 50.0
    delta = (load / contact_constant(2 / radius, 0.0, E, NU)) ** (2 / 3)
    e_star = E / (2 * (1 - NU**2))
    assert delta == pytest.approx((9 * load**2 / (16 * e_star**2 * radius)) ** (1 / 3), rel=1e-12)


@pytest.mark.parametrize("ratio", [2.0, 5.0, 10.0, 20.0])
def test_ellipticity_agrees_with_the_hamrock_brewe_fit(ratio):
    # a contact with principal relative radii R_y = ratio * R_x: F(rho) = (ratio - 1) / (ratio + 1);
    # Hamrock & Brewe's curve fit kappa = 1.0339 ratio^0.636 is good to about 1.5 % over the range of ball
    # bearings (it drifts to 6 % by ratio 100)
    kappa = ellipticity((ratio - 1) / (ratio + 1))
    assert kappa == pytest.approx(1.0339 * ratio**0.636, rel=0.015)


def test_axial_stiffness_is_the_slope_of_the_load_deflection_curve():
    for preload in (20.0, 378.0, 567.0):
        state = BARDEN.state(preload)
        h = 1e-4 * preload
        up, down = BARDEN.state(preload + h), BARDEN.state(preload - h)
        slope = 2 * h / (up.axial_deflection - down.axial_deflection)
        assert state.axial_stiffness == pytest.approx(slope, rel=2e-5)


def test_radial_stiffness_equals_a_ball_by_ball_sum():
    # displace the inner ring radially by dr at fixed axial position and add up the ball forces from the
    # raceway geometry alone (the curvature centres of ball j move by dr cos psi_j)
    state = BARDEN.state(378.0)
    big_a, a0 = BARDEN.curvature_centre_distance, BARDEN.contact_angle
    k_n = BARDEN.contact_constant(state.contact_angle)
    axial = big_a * math.sin(a0) + state.axial_deflection
    psi = 2 * np.pi * np.arange(BARDEN.n_balls) / BARDEN.n_balls + 0.1
    dr = 1e-9

    def radial_force(shift: float) -> float:
        radial = big_a * math.cos(a0) + shift * np.cos(psi)
        s = np.hypot(axial, radial)
        q = k_n * np.clip(s - big_a, 0.0, None) ** 1.5
        return float(np.sum(q * radial / s * np.cos(psi)))

    # the resultant of the ball loads on the ring grows with the shift: its slope is the radial stiffness
    k_sum = (radial_force(dr) - radial_force(-dr)) / (2 * dr)
    assert state.radial_stiffness == pytest.approx(k_sum, rel=1e-5)


def test_stiffness_grows_with_preload_about_as_its_cube_root():
    curve = BARDEN.stiffness_curve(378.0 * np.array([0.05, 0.5, 0.75, 1.0, 1.25, 1.5]))
    for key in ("axial_stiffness", "radial_stiffness", "contact_angle"):
        assert np.all(np.diff(curve[key]) > 0), key
    ratio = curve["radial_stiffness"][-1] / curve["radial_stiffness"][3]
    # fixed contact angle would give exactly 1.5^(1/3); the growing angle lowers the radial gain slightly
    assert 0.95 * 1.5 ** (1 / 3) < ratio < 1.5 ** (1 / 3)
    assert curve["axial_stiffness"][-1] / curve["axial_stiffness"][3] > 1.5 ** (1 / 3)


def test_bad_geometry_and_loads_are_errors():
    with pytest.raises(ModelError, match="n_balls must be an integer >= 3"):
        AngularContactBearing(2, 0.008, 0.065, 0.26)
    with pytest.raises(ModelError, match="need 0 < ball_diameter < pitch_diameter"):
        AngularContactBearing(18, 0.07, 0.065, 0.26)
    with pytest.raises(ModelError, match="contact_angle must be in"):
        AngularContactBearing(18, 0.008, 0.065, 2.0)
    with pytest.raises(ModelError, match="inner_curvature must be in"):
        AngularContactBearing(18, 0.008, 0.065, 0.26, inner_curvature=0.4)
    with pytest.raises(ModelError, match="axial load must be a positive number"):
        BARDEN.state(-1.0)
    with pytest.raises(ModelError, match="curvature difference"):
        ellipticity(1.2)


def test_spindle_model_scales_its_bearings_by_the_hertz_law():
    # builtin:spindle-bearing multiplies the Table 5.8 stiffnesses by the 110H ratio at 378 N x preload
    from cappe.model import NumericModel, load_model

    nm = NumericModel(load_model("builtin:spindle-bearing"))
    bearing = AngularContactBearing(18, 0.0079375, 0.065, math.radians(15.0))
    k_nominal = nm.matrices(nm.nominal)["K"]
    p = nm.nominal.copy()
    i = nm.parameter_names.index("preload")
    p[i] = 1.5
    k_preloaded = nm.matrices(p)["K"]
    ratio_r = bearing.state(567.0).radial_stiffness / bearing.state(378.0).radial_stiffness
    ratio_a = bearing.state(567.0).axial_stiffness / bearing.state(378.0).axial_stiffness
    # the bearing part of K: K(p) - K(p with all bearing stiffnesses zero)
    zero = {n: 0.0 for n in ("kfx", "kfy", "kfz", "krx", "kry")}
    base = nm.matrices(nm.vector(zero))["K"]
    bearings_nominal = k_nominal - base
    q = nm.vector(zero)
    q[i] = 1.5
    bearings_preloaded = k_preloaded - nm.matrices(q)["K"]
    spindle_z = nm.dofs.index("spindle.z")
    assert bearings_preloaded[spindle_z, spindle_z] == pytest.approx(ratio_a * bearings_nominal[spindle_z, spindle_z],
                                                                       rel=1e-10)
    spindle_x = nm.dofs.index("spindle.x")
    assert bearings_preloaded[spindle_x, spindle_x] == pytest.approx(ratio_r * bearings_nominal[spindle_x, spindle_x],
                                                                       rel=1e-10)
    # the exact derivative with respect to the preload (through the law's slope) against central differences
    d_k = nm.matrix_derivatives(p)["K"][i]
    h = 1e-5
    up, down = p.copy(), p.copy()
    up[i] += h
    down[i] -= h
    fd = (nm.matrices(up)["K"] - nm.matrices(down)["K"]) / (2 * h)
    np.testing.assert_allclose(d_k, fd, rtol=1e-6, atol=1e-9 * np.abs(fd).max())
