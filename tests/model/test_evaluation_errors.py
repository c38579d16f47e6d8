"""A model that evaluates to NaN or inf, or to values double precision cannot hold, is a ModelError naming the model
file and the entry (issue 18): never NaN or inf passed on, never numpy's RuntimeWarning (warnings are errors here).
"""

from __future__ import annotations

import re
import textwrap

import numpy as np
import pytest

from cappe.exceptions import ModelError
from cappe.model import NumericModel, StructureBuilder
from cappe.model.loader import structure_from_yaml

# a table (x and rz) on a spring and a damper to ground, with a sensor; the expressions under test replace the
# placeholders
TEMPLATE = """\
format: cappe.model/1
name: sled
parameters:
  - {{name: m, value: {m}, unit: kg, kind: mass}}
  - {{name: k, value: {k}, unit: N/m, kind: stiffness}}
  - {{name: c, value: 30.0, unit: N s/m, kind: damping}}
  - {{name: eta, value: {eta}, kind: loss}}
axes:
  - {{name: z, positions: [0.1, 0.3]}}
bodies:
  - {{name: table, mass: m, inertia: {{xx: 0.02, yy: 0.02, zz: 0.03}}, dofs: [x, rz]}}
elements:
  - {{name: shoe, bodies: [ground, table], stiffness: {{x: '{kx}', rz: 1.0e5}}, damping: {{x: '{cx}'}},
      loss: {{x: eta}}}}
sensors:
  - {{name: s1, body: table, point: ['{sx}', 0, 0]}}
inputs:
  - {{name: F, body: table, direction: x, point: [0, '{fy}', 0]}}
outputs:
  - {{name: d, quantity: displacement, body: table, direction: x}}
"""


def sled(*, m="3.0", k="2.0e6", eta="0.0", kx="k", cx="c", sx="0.1", fy="0"):
    text = TEMPLATE.format(m=m, k=k, eta=eta, kx=kx, cx=cx, sx=sx, fy=fy)
    return NumericModel(structure_from_yaml(textwrap.dedent(text), "model.yaml"))


@pytest.mark.parametrize(
    ("kx", "z", "value"),
    [
        ("1e6*sqrt(z)", -0.2, "nan"),  # the example
        ("k/z", 0.0, "inf"),
        ("k*(3 + log(z))", 0.0, "-inf"),
        ("k*sqrt(z)", -0.2, "nan"),  # in product form: the axis factor is evaluated once per position
    ],
)
def test_stiffness_undefined_at_a_position_names_the_entry_and_the_position(kx, z, value):
    nm = sled(kx=kx)
    used = ", k = 2e+06" if "k" in kx.replace("sqrt", "") else ""
    match = rf"^model\.yaml, elements\[0\]\.stiffness\.x: evaluates to {value} at z = {z:g}{re.escape(used)}$"
    with pytest.raises(ModelError, match=match):
        nm.matrices(None, {"z": z})
    with pytest.raises(ModelError, match=match):
        nm.system(None, {"z": z})
    with pytest.raises(ModelError, match=match):
        nm.affine_terms(["K"], None, {"z": z})
    if used:  # the derivative with respect to k is undefined there too (1e6 sqrt(z) has none)
        with pytest.raises(ModelError, match=match):
            nm.matrix_derivatives(None, {"z": z})
    nm.matrices(None, {"z": 0.3})  # the model itself is fine elsewhere


def test_an_overflowing_product_names_the_entry_and_the_parameter():
    nm = sled(kx="exp(700)*k")
    with pytest.raises(ModelError, match=r"^model\.yaml, elements\[0\]\.stiffness\.x: evaluates to inf at k = 2e\+06$"):
        nm.matrices()


def test_damping_undefined_at_a_position_is_named_by_the_damping_sources_too():
    nm = sled(cx="c/z")
    match = r"^model\.yaml, elements\[0\]\.damping\.x: evaluates to inf at z = 0, c = 30$"
    with pytest.raises(ModelError, match=match):
        nm.damping_sources(None, {"z": 0.0})
    with pytest.raises(ModelError, match=match):
        nm.matrices(None, {"z": 0.0})


def test_loss_times_stiffness_overflowing_names_the_loss_entry():
    # each value is finite; their product (the hysteretic coefficient) is not
    nm = sled(k="1.0e200", eta="1.0e200")
    match = (r"^model\.yaml, elements\[0\]\.loss\.x: loss factor times stiffness evaluates to inf at k = 1e\+200, "
             r"eta = 1e\+200$")
    with pytest.raises(ModelError, match=match):
        nm.matrices()
    with pytest.raises(ModelError, match=match):
        nm.damping_sources()


def test_input_and_sensor_points_undefined_at_a_position():
    nm = sled(fy="1/z")  # the moment arm of the force about z
    with pytest.raises(ModelError, match=r"^model\.yaml, inputs\[0\]\.point\[1\]: evaluates to inf at z = 0$"):
        nm.io_matrices(None, {"z": 0.0})
    nm = sled(sx="log(z)")
    with pytest.raises(ModelError, match=r"^model\.yaml, sensors\[0\]\.point\[0\]: evaluates to -?inf at z = 0$"):
        nm.sensor_matrix(None, {"z": 0.0})
    with pytest.raises(ModelError, match=r"^model\.yaml, sensors\[0\]\.point\[0\]: evaluates to nan"):
        nm.sensor_matrix(None, {"z": -1.0})


def test_geometry_undefined_at_a_position_names_the_element():
    b = StructureBuilder("tilting")
    b.parameter("m", 2.0, kind="mass")
    b.parameter("k", 1.0e6, kind="stiffness")
    b.axis("z", [0.5, 1.0])
    b.body("b1", mass="m", inertia={"xx": 0.1, "yy": 0.1, "zz": 0.1}, dofs=["x", "ry"])
    b.element("e1", bodies=("ground", "b1"), at=["1/z", 0, 0], stiffness={"x": "k", "z": "k"})
    nm = NumericModel(b.build())
    with pytest.raises(ModelError, match=r"^elements\[0\]: its attachment point on 'ground' \(x\) evaluates to inf "
                                         r"at z = 0$"):
        nm.matrices(None, {"z": 0.0})


def test_finite_values_whose_sum_overflows_name_an_entry_and_the_matrix_entry():
    b = StructureBuilder("stiff")
    b.parameter("m", 1.0, kind="mass")
    b.parameter("k", 1.0e308, kind="stiffness")
    b.body("b1", mass="m", dofs=["x"])
    b.element("e1", bodies=("ground", "b1"), stiffness={"x": "k"})
    b.element("e2", bodies=("ground", "b1"), stiffness={"x": "k"})
    nm = NumericModel(b.build())
    with pytest.raises(ModelError, match=r"^elements\[0\]\.stiffness\.x: adds 1e\+308 to the stiffness matrix entry "
                                         r"\[b1\.x, b1\.x\] at k = 1e\+308, which sums to inf"):
        nm.matrices()


def test_a_batch_names_the_values_of_the_sample_that_overflows():
    nm = sled(kx="exp(690)*k")
    pb = np.tile(nm.nominal, (3, 1))
    pb[2, 1] = 1.0e10  # k of the third sample: exp(690) * 1e10 is beyond 1.8e308
    nm.matrices(pb[:2])
    with pytest.raises(ModelError, match=r"evaluates to inf at k = 1e\+10$"):
        nm.matrices(pb)


def test_a_negative_stiffness_where_the_model_is_evaluated_is_an_error():
    # loading checks the listed positions; a system at another position is checked where it is evaluated
    nm = sled(kx="k*(z - 0.05)")
    nm.system(None, {"z": 0.1})
    with pytest.raises(ModelError, match=r"^model\.yaml, elements\[0\]\.stiffness\.x: the stiffness evaluates to "
                                         r"-1e\+06 at z = -0\.45, k = 2e\+06; it must be >= 0$"):
        nm.system(None, {"z": -0.45})


def test_a_mass_negative_at_an_unlisted_position_names_the_body():
    b = StructureBuilder("sliding-mass")
    b.parameter("m", 0.5, kind="mass")
    b.parameter("k", 1.0e4, kind="stiffness")
    b.axis("z", [0.0, 0.2])
    b.body("slide", mass="m - z", dofs=["x"])
    b.element("e1", bodies=("ground", "slide"), stiffness={"x": "k"})
    system = NumericModel(b.build()).system(None, {"z": 1.0})
    for compute in (system.undamped_modes, lambda: system.modes("exact"), lambda: system.state_space()):
        with pytest.raises(ModelError, match=r"^bodies\[0\] \(slide\.x\): the mass matrix is not positive definite on "
                                             r"slide\.x \(eigenvalues -0\.5 in kg and kg m\^2\)"):
            compute()


@pytest.mark.parametrize(
    ("values", "match"),
    [
        ({"m": -1.0}, r"parameter 'm' \(mass\) must be > 0; got -1\.0 \(model\.yaml, parameters\[0\]\)"),
        ({"m": 0.0}, r"parameter 'm' \(mass\) must be > 0; got 0\.0 \(model\.yaml, parameters\[0\]\)"),
        ({"k": -5.0}, r"parameter 'k' \(stiffness\) must be >= 0; got -5\.0 \(model\.yaml, parameters\[1\]\)"),
        ({"c": -1.0}, r"parameter 'c' \(damping\) must be >= 0; got -1\.0 \(model\.yaml, parameters\[2\]\)"),
    ],
)
def test_overrides_follow_the_rules_of_their_kind(values, match):
    nm = sled()
    with pytest.raises(ModelError, match=match):
        nm.structure.resolve_parameters(values)
    with pytest.raises(ModelError, match=match):
        nm.system(values)


def test_an_axis_position_must_be_finite():
    nm = sled()
    with pytest.raises(ModelError, match=re.escape("axis 'z' position must be finite; got nan")):
        nm.matrices(None, {"z": float("nan")})
