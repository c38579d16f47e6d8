"""YAML and builder agree; numeric model agrees with the symbolic one; CASE 3 position dependence; spindle K."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from cappe.exceptions import ModelError
from cappe.model import NumericModel, StructureBuilder, derive
from cappe.model._expressions import symbol
from cappe.model.loader import structure_from_yaml

YAML = """\
format: cappe.model/1
name: sled
parameters:
  - {name: m, value: 3.0, unit: kg, kind: mass}
  - {name: J, value: 0.02, unit: kg m^2, kind: inertia}
  - {name: kg, value: 2.0e6, unit: N/m, kind: stiffness}
  - {name: kt, value: 5.0e5, unit: N m/rad, kind: stiffness}
  - {name: c, value: 30.0, unit: N s/m, kind: damping}
  - {name: eta, value: 0.02, unit: '1', kind: loss}
axes:
  - {name: z, positions: [-0.2, 0.0, 0.3]}
bodies:
  - {name: base, mass: 4*m, inertia: {xx: 4*J, yy: 4*J, zz: 2*J}}
  - {name: table, mass: m, inertia: {xx: J, yy: J, zz: J, xy: J/10}, position: [0, 0, z], com: [0.01, 0, 0]}
elements:
  - {name: mount, bodies: [ground, base], at: [0, -0.1, 0], stiffness: {x: kg, y: kg, z: kg, rx: kt, ry: kt, rz: kt}, damping: {x: c, y: c}}
  - {name: shoe, bodies: [base, table], at: [0.05, 0, z], axes: {x: [1, 1, 0], y: [0, 0, 1]}, stiffness: {x: kg, y: kg, z: kg, rx: kt, ry: kt, rz: kt}, loss: {x: eta, y: eta}}
inputs:
  - {name: F, body: table, point: [0, 0, 0.02], direction: [1, 0, 0]}
outputs:
  - {name: d, quantity: displacement, body: table, point: [0, 0, 0.02], direction: x}
  - {name: a, quantity: acceleration, body: base, direction: y}
  - {name: e, quantity: elongation, element: shoe, direction: x}
"""


def build_with_api():
    b = StructureBuilder("sled", source="model.yaml")
    b.parameter("m", 3.0, unit="kg", kind="mass")
    b.parameter("J", 0.02, unit="kg m^2", kind="inertia")
    b.parameter("kg", 2.0e6, unit="N/m", kind="stiffness")
    b.parameter("kt", 5.0e5, unit="N m/rad", kind="stiffness")
    b.parameter("c", 30.0, unit="N s/m", kind="damping")
    b.parameter("eta", 0.02, unit="1", kind="loss")
    b.axis("z", [-0.2, 0.0, 0.3])
    b.body("base", mass="4*m", inertia={"xx": "4*J", "yy": "4*J", "zz": "2*J"})
    b.body(
        "table",
        mass="m",
        inertia={"xx": "J", "yy": "J", "zz": "J", "xy": "J/10"},
        position=[0, 0, "z"],
        com=[0.01, 0, 0],
    )
    six = {d: "kg" if d in "xyz" else "kt" for d in ("x", "y", "z", "rx", "ry", "rz")}
    b.element("mount", bodies=("ground", "base"), at=[0, -0.1, 0], stiffness=six, damping={"x": "c", "y": "c"})
    b.element(
        "shoe",
        bodies=("base", "table"),
        at=[0.05, 0, "z"],
        axes={"x": [1, 1, 0], "y": [0, 0, 1]},
        stiffness=six,
        loss={"x": "eta", "y": "eta"},
    )
    b.input("F", body="table", point=[0, 0, 0.02], direction=[1, 0, 0])
    b.output("d", quantity="displacement", body="table", point=[0, 0, 0.02], direction="x")
    b.output("a", quantity="acceleration", body="base", direction="y")
    b.output("e", quantity="elongation", element="shoe", direction="x")
    return b.build()


def test_yaml_and_api_give_identical_matrices():
    from_yaml = derive(structure_from_yaml(YAML, "model.yaml"))
    from_api = derive(build_with_api())
    for name in ("M", "C", "K", "G", "H"):
        assert getattr(from_yaml, name) == getattr(from_api, name), name
    assert from_yaml.input_matrix() == from_api.input_matrix()
    assert from_yaml.output_matrix() == from_api.output_matrix()


def test_numeric_equals_symbolic_substitution_at_every_position():
    s = structure_from_yaml(YAML, "model.yaml")
    sym = derive(s)
    nm = NumericModel(sym)
    for z in (-0.2, 0.0, 0.3, 0.17):
        values = {**s.nominal, "z": z}
        num = nm.matrices(position={"z": z})
        for name, mat in sym.substitute(values).items():
            # float evaluation of exact rationals: agreement to round-off (relative 1e-12)
            np.testing.assert_allclose(num[name], np.array(mat, dtype=float), rtol=1e-12, atol=1e-9)


def test_batch_equals_single_evaluations():
    s = structure_from_yaml(YAML, "model.yaml")
    nm = NumericModel(s)
    rng = np.random.default_rng(3)
    batch = nm.nominal * rng.uniform(0.7, 1.3, size=(7, nm.nominal.size))
    out = nm.matrices(batch, {"z": 0.3})
    for b in range(batch.shape[0]):
        single = nm.matrices(batch[b], {"z": 0.3})
        for name in out:
            np.testing.assert_allclose(out[name][b], single[name], rtol=1e-13, atol=0)


def test_case3_stiffness_changes_with_axis_position():
    # the shoe moves with the table along z: its lever arm about the base origin changes the coupling
    nm = NumericModel(structure_from_yaml(YAML, "model.yaml"))
    k_a = nm.matrices(position={"z": -0.2})["K"]
    k_b = nm.matrices(position={"z": 0.3})["K"]
    assert not np.allclose(k_a, k_b)
    # hand check of the base.x - base.ry entry. Shoe local axes: x = (1,1,0)/sqrt2, y = (0,0,1),
    # z = x cross y = (1,-1,0)/sqrt2; lever from the base origin r = (0.05, 0, z). For a local axis e the base
    # side of the elongation row is -(e . u + e . (theta x r)); with theta = theta_y * (0,1,0):
    # (0,1,0) x r = (z, 0, -0.05). Local x: h_x = -1/sqrt2, h_ry = -z/sqrt2; local z: the same; local y: h_x = 0.
    # The mount (r = (0,-0.1,0)) has (0,1,0) x r = 0. So K[x, ry] = 2 * kg * (1/sqrt2)(z/sqrt2) = kg * z.
    sym = derive(structure_from_yaml(YAML, "model.yaml"))
    i, j = sym.dofs.index("base.x"), sym.dofs.index("base.ry")
    for z, k in ((-0.2, k_a), (0.3, k_b)):
        assert k[i, j] == pytest.approx(2.0e6 * z, rel=1e-12)


def test_hysteretic_matrix_is_loss_times_stiffness_pattern():
    sym = derive(structure_from_yaml(YAML, "model.yaml"))
    eta, kg = symbol("eta"), symbol("kg")
    # only the shoe carries loss, in x and y: H = eta * (K contribution of the shoe's x and y springs)
    shoe_terms = [t for t in sym.terms["K"] if t.source in ("shoe.kx", "shoe.ky")]
    expected = sum((t.coefficient * t.dense(sym.n_dof) for t in shoe_terms), sp.zeros(sym.n_dof, sym.n_dof))
    assert sp.simplify(sym.H - eta * expected) == sp.zeros(sym.n_dof, sym.n_dof)
    assert kg in sym.H.free_symbols


# -- spindle: thesis Appendix C stiffness matrix, corrected where the appendix is wrong --------------
def thesis_k(corrected: bool) -> sp.Matrix:
    """Appendix C11-C13 transcribed (order xs ys zs xh yh zh rxs rys rxh ryh rzh), optionally corrected."""
    kfx, kfy, kfz, k1x, k1y, k1z = sp.symbols("kFX kFY kFZ kH1X kH1Y kH1Z")
    z0, z2 = sp.Rational(127, 1000), sp.Rational(162, 1000)
    xh0, yh0, zh0 = sp.Rational(48, 1000), sp.Rational(64, 1000), sp.Rational(60, 1000)
    a = kfx * (z0 - z2)
    b = kfy * (z0 - z2)
    s = -1 if corrected else 1  # the four upper-triangle x/rotation signs are wrong in the appendix
    k = sp.zeros(11, 11)
    k[0, 0] = 2 * kfx
    k[0, 3] = -2 * kfx
    k[0, 7] = -s * a
    k[0, 9] = s * a  # noqa: E702
    k[1, 1] = 2 * kfy
    k[1, 4] = -2 * kfy
    k[1, 6] = -b
    k[1, 8] = b  # noqa: E702
    k[2, 2] = kfz
    k[2, 5] = -kfz  # noqa: E702
    k[3, 0] = -2 * kfx
    k[3, 3] = 2 * kfx + 4 * k1x
    k[3, 7] = s * a
    k[3, 9] = -s * a
    k[3, 10] = 4 * k1x * yh0  # noqa: E702
    k[4, 1] = -2 * kfy
    k[4, 4] = 2 * kfy + 4 * k1y
    k[4, 6] = b
    k[4, 8] = -b  # noqa: E702
    k[5, 2] = -kfz
    k[5, 5] = kfz + 4 * k1z
    k[5, 8] = -4 * k1z * yh0  # noqa: E702
    k[6, 1] = -b
    k[6, 4] = b
    k[6, 6] = kfy * (z0**2 + z2**2)
    k[6, 8] = -kfy * (z0**2 + z2**2)  # noqa: E702
    k[7, 0] = a
    k[7, 3] = -a
    k[7, 7] = kfx * (z0**2 + z2**2)
    k[7, 9] = -kfx * (z0**2 + z2**2)  # noqa: E702
    k[8, 1] = b
    k[8, 4] = -b
    k[8, 5] = -4 * k1z * yh0
    k[8, 6] = -kfy * (z0**2 + z2**2)  # noqa: E702
    k[8, 8] = (
        4 * k1z * yh0**2 + (4 if corrected else 2) * k1y * zh0**2 + (1 if corrected else 2) * kfy * (z0**2 + z2**2)
    )
    k[9, 0] = -a
    k[9, 3] = a
    k[9, 7] = -kfx * (z0**2 + z2**2)  # noqa: E702
    k[9, 9] = 4 * k1z * xh0**2 + 4 * k1x * zh0**2 + kfx * z0**2 + (1 if corrected else 2) * kfx * z2**2
    k[10, 3] = 4 * k1x * yh0
    k[10, 10] = 4 * k1y * xh0**2 + 4 * k1x * yh0**2  # noqa: E702
    return k


def spindle_k_in_thesis_symbols(spindle) -> sp.Matrix:
    sym = derive(spindle)
    kfx, kfy, kfz, k1x, k1y, k1z = sp.symbols("kFX kFY kFZ kH1X kH1Y kH1Z")
    subs = {
        symbol("preload"): 1,
        symbol("kfx"): kfx,
        symbol("krx"): kfx,
        symbol("kfy"): kfy,
        symbol("kry"): kfy,
        symbol("kfz"): kfz,
    }
    for j in range(1, 5):
        subs.update({symbol(f"kh{j}x"): k1x, symbol(f"kh{j}y"): k1y, symbol(f"kh{j}z"): k1z})
    # cappe orders spindle dofs first (x y z rx ry), then housing (x y z rx ry rz); the thesis interleaves
    order = [
        "spindle.x",
        "spindle.y",
        "spindle.z",
        "housing.x",
        "housing.y",
        "housing.z",
        "spindle.rx",
        "spindle.ry",
        "housing.rx",
        "housing.ry",
        "housing.rz",
    ]
    idx = [sym.dofs.index(d) for d in order]
    return sym.K.xreplace(subs).extract(idx, idx)


def test_spindle_k_matches_corrected_appendix(spindle):
    assert sp.simplify(spindle_k_in_thesis_symbols(spindle) - thesis_k(corrected=True)) == sp.zeros(11, 11)


def test_spindle_k_differs_from_printed_appendix_exactly_in_six_entries(spindle):
    diff = sp.simplify(spindle_k_in_thesis_symbols(spindle) - thesis_k(corrected=False))
    wrong = {(i, j) for i in range(11) for j in range(11) if diff[i, j] != 0}
    assert wrong == {(0, 7), (0, 9), (3, 7), (3, 9), (8, 8), (9, 9)}


def test_affine_terms_rebuild_the_matrices_and_name_a_wrong_matrix():
    nm = NumericModel(structure_from_yaml(YAML, "model.yaml"))
    batch = nm.nominal * np.random.default_rng(5).uniform(0.7, 1.3, size=(4, nm.nominal.size))
    terms = nm.affine_terms(("M", "K", "C"), batch, {"z": 0.3})
    mats = nm.matrices(batch, {"z": 0.3})
    for name, (coef, patterns) in terms.items():
        assert not patterns.flags.writeable  # shared with the model's cache
        np.testing.assert_allclose(np.einsum("bt,tij->bij", coef, patterns), mats[name], rtol=1e-13, atol=1e-9)
    with pytest.raises(ModelError, match=r"matrix must be one of \('M', 'C', 'K', 'G', 'H'\); got 'D'"):
        nm.affine_terms(("K", "D"), batch)
    with pytest.raises(ModelError, match=r"matrix must be one of \('M', 'C', 'K', 'G', 'H'\); got 'D'"):
        nm.matrix_parameters("D")


def test_matrix_parameters_are_those_that_move_the_matrix():
    # independent check: perturbing a parameter changes the matrix exactly when it is listed
    nm = NumericModel(structure_from_yaml(YAML, "model.yaml"))
    for name in ("M", "K", "C"):
        listed = set(nm.matrix_parameters(name))
        base = nm.matrices(nm.nominal, {"z": 0.3})[name]
        for i, p in enumerate(nm.parameter_names):
            moved = nm.nominal.copy()
            moved[i] *= 1.5
            changed = not np.array_equal(nm.matrices(moved, {"z": 0.3})[name], base)
            assert changed == (p in listed), (name, p)


def test_coefficients_in_product_form_and_generated_code_agree_with_sympy():
    # the batched evaluator takes p_a * p_b * g(axes) itself and leaves everything else to generated code;
    # both must give what sympy's own evaluation of each expression gives, in every batch layout
    from cappe.model.numeric import _Coefficients

    a, b, c, z = sp.symbols("a b c z")
    expressions = [a, 3 * b, a * b * sp.Abs(z - sp.Rational(1, 3)), sp.Integer(0), a**2, b * sp.sin(a),
                   sp.Rational(7, 2) * z + 1, c * (z + 2), a * b * c]
    evaluator = _Coefficients(expressions, [a, b, c], [z])
    assert evaluator._slow.tolist() == [4, 5, 8]  # a**2, b sin(a) and a b c are not products of two parameters
    rng = np.random.default_rng(3)
    pb = rng.uniform(0.5, 2.0, size=(5, 3))
    got = evaluator(pb, (0.25,))
    want = np.array([[float(e.subs({a: row[0], b: row[1], c: row[2], z: 0.25})) for e in expressions] for row in pb])
    np.testing.assert_allclose(got, want, rtol=1e-15, atol=0)
    assert got.flags.c_contiguous
    for k in range(5):  # one sample at a time: the same bits
        np.testing.assert_array_equal(evaluator(pb[k:k + 1], (0.25,)), got[k:k + 1])
    # partial derivatives: product forms by rule, the others by sympy; every structurally non-zero one listed
    symbols = [a, b, c]
    want_entries = {(j, i) for j, e in enumerate(expressions) for i, sym in enumerate(symbols) if sp.diff(e, sym) != 0}
    assert set(evaluator.entries) == want_entries
    derivatives = evaluator.jacobian(pb, (0.25,))
    for k, (j, i) in enumerate(evaluator.entries):
        d = sp.diff(expressions[j], symbols[i])
        np.testing.assert_allclose(derivatives[:, k], [float(d.subs({a: r[0], b: r[1], c: r[2], z: 0.25})) for r in pb],
                                   rtol=1e-14, err_msg=f"d expression {j} / d {symbols[i]}")
    only_fast = _Coefficients(expressions[:4], [a, b, c], [z])
    assert only_fast(pb, (0.25,)).flags.c_contiguous
    np.testing.assert_allclose(only_fast(pb, (-1.0,))[:, 2], pb[:, 0] * pb[:, 1] * (4 / 3), rtol=1e-15)


def test_a_position_factor_undefined_at_a_position_is_an_error_naming_the_entry():
    # product-form coefficients compute their axis factor once per position: with numpy's rules (inf, NaN), not
    # Python's (ZeroDivisionError, complex results), like the generated code for arrays; a NaN or inf is an error
    # that names the entry and the position (issue 18), without numpy's RuntimeWarning
    b = StructureBuilder("undefined-factor")
    b.parameter("m", 1.0, kind="mass")
    b.parameter("k", 1.0e4, kind="stiffness")
    b.axis("z", [0.1, 0.4])
    b.body("a", mass="m", dofs=("x",))
    b.element("e1", bodies=("ground", "a"), at=[0, 0, 0], stiffness={"x": "k/(z + 2)"})
    b.element("e2", bodies=("ground", "a"), at=[0, 0, 0], stiffness={"x": "k*(z + 3)**(1/3)"})
    nm = NumericModel(b.build())
    np.testing.assert_allclose(nm.matrices(None, {"z": 0.0})["K"], [[1.0e4 / 2 + 1.0e4 * 3 ** (1 / 3)]], rtol=1e-14)
    with pytest.raises(ModelError, match=r"^elements\[0\]\.stiffness\.x: evaluates to inf at z = -2, k = 10000$"):
        nm.matrices(None, {"z": -2.0})
    with pytest.raises(ModelError, match=r"^elements\[1\]\.stiffness\.x: evaluates to nan at z = -4, k = 10000$"):
        nm.matrices(None, {"z": -4.0})


def test_matrix_derivative_products_equal_the_derivative_matrices_times_the_vectors(slide):
    # issue 24: the products are formed from the sparse patterns without the dense (n_p, n, n) stacks; against
    # matrix_derivatives @ V (a coefficient non-linear in its parameters, kg0 (Fp / 1000)^(1/3), included)
    nm = NumericModel(slide)
    rng = np.random.default_rng(2)
    p = nm.nominal * rng.uniform(0.8, 1.2, nm.nominal.size)
    vectors = rng.standard_normal((nm.n_dof, 3)) + 1j * rng.standard_normal((nm.n_dof, 3))
    names = ["kg0", "Fp", "eta", "ms", "cm"]
    products = nm.matrix_derivative_products(p, {"z": 0.25}, vectors, parameters=names)
    dense = nm.matrix_derivatives(p, {"z": 0.25}, parameters=names)
    for name, stack in dense.items():
        # the same sums in another order: round-off of the largest term
        np.testing.assert_allclose(products[name], stack @ vectors, rtol=0,
                                   atol=1e-13 * max(np.abs(stack).max(), 1e-300) * np.abs(vectors).max())
    with pytest.raises(ModelError, match=r"vectors must have shape \(n_dof, m\) = \(12, m\); got \(3,\)"):
        nm.matrix_derivative_products(p, {"z": 0.25}, vectors[:3, 0])
