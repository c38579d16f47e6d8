"""Every validation rule of the model language gives a clear error naming file, entry, rule and value."""

from __future__ import annotations

import textwrap

import numpy as np
import pytest

from cappe.exceptions import ModelError
from cappe.model import NumericModel, StructureBuilder, load_model
from cappe.model.loader import structure_from_yaml

BASE = """\
format: cappe.model/1
name: block
parameters:
  - {name: m, value: 2.0, unit: kg, kind: mass}
  - {name: k, value: 1.0e6, unit: N/m, kind: stiffness, bounds: [1.0e5, 1.0e7], unknown: true}
  - {name: c, value: 10.0, unit: N s/m, kind: damping}
bodies:
  - {name: b1, mass: m, inertia: {xx: 0.1, yy: 0.2, zz: 0.3}}
elements:
  - {name: e1, bodies: [ground, b1], at: [0.1, 0.0, 0.0], stiffness: {x: k, y: k, z: k, rx: k, ry: k, rz: k}, damping: {x: c}}
inputs:
  - {name: F, body: b1, direction: x}
outputs:
  - {name: d, quantity: displacement, body: b1, direction: x}
"""


def load(text: str, label: str = "model.yaml"):
    return structure_from_yaml(textwrap.dedent(text), label)


def test_base_model_is_valid():
    s = load(BASE)
    assert s.n_dof == 6
    assert s.parameter("k").unknown


@pytest.mark.parametrize(
    ("old", "new", "match"),
    [
        (
            "stiffness: {x: k, y: k",
            "stiffness: {x: kk, y: k",
            r"unknown name 'kk'.*model\.yaml, elements\[0\]\.stiffness\.x",
        ),
        (
            "{name: c, value: 10.0",
            "{name: k, value: 10.0",
            r"duplicate parameter name 'k' \(model\.yaml, parameters\[2\]\)",
        ),
        (
            "bodies: [ground, b1]",
            "bodies: [ground, b9]",
            r"unknown body 'b9' \(model\.yaml, elements\[0\]\.bodies\[1\]\); known bodies: b1",
        ),
        (
            "{name: F, body: b1, direction: x}",
            "{name: F, body: b1, direction: [0, 0, 0]}",
            r"direction must have non-zero length; got \[0, 0, 0\] \(model\.yaml, inputs\[0\]\.direction\)",
        ),
        (
            "{name: m, value: 2.0",
            "{name: m, value: -2.0",
            r"parameter 'm' \(mass\) must be > 0; got -2\.0 \(model\.yaml, parameters\[0\]\)",
        ),
        ("mass: m,", "mass: -m,", r"body 'b1' mass must be > 0; got -2 \(model\.yaml, bodies\[0\]\.mass\)"),
        (
            "stiffness: {x: k,",
            "stiffness: {x: -k,",
            r"element 'e1' stiffness 'x' must be >= 0; got -1e\+06 \(model\.yaml, elements\[0\]\.stiffness\.x\)",
        ),
        (
            "inertia: {xx: 0.1, yy: 0.2, zz: 0.3}",
            "inertia: {xx: 0.1, yy: 0.2, zz: 0.3, xy: 0.5}",
            r"body 'b1' inertia tensor must be positive definite; eigenvalues .* \(model\.yaml, bodies\[0\]\.inertia\)",
        ),
        (
            "value: 1.0e6, unit: N/m, kind: stiffness, bounds: [1.0e5, 1.0e7]",
            "value: 1.0e6, unit: N/m, kind: stiffness, bounds: [1.0e7, 1.0e5]",
            r"bounds must satisfy lo < hi; got \[10000000\.0, 100000\.0\]",
        ),
        (
            "{name: c, value: 10.0, unit: N s/m, kind: damping}",
            "{name: c, value: 10.0, unit: N s/m, kind: dampin}",
            r"kind must be one of mass, inertia, .*; got 'dampin' \(model\.yaml, parameters\[2\]\)",
        ),
        (
            "{name: d, quantity: displacement",
            "{name: d, quantity: displacment",
            r"quantity must be one of displacement, velocity, acceleration, elongation; got 'displacment'",
        ),
        (
            "{name: F, body: b1, direction: x}",
            "{name: F, body: b1, direction: x, colour: red}",
            r"model\.yaml, inputs\[0\]: unknown key\(s\) colour",
        ),
    ],
)
def test_rule_violations_are_named(old, new, match):
    assert old in BASE
    with pytest.raises(ModelError, match=match):
        load(BASE.replace(old, new))


def test_malformed_yaml_reports_line():
    broken = BASE.replace("  - {name: F, body: b1, direction: x}", "  - {name: F, body: b1, direction: x")
    with pytest.raises(ModelError, match=r"malformed YAML in model\.yaml at line 1[0-9], column"):
        load(broken)


@pytest.mark.parametrize(("text", "match"), [
    ("format: cappe.model/1\n\tname: x\n", r"at line 2, column 1: found character '\\t' that cannot start any token"),
    ("format: cappe.model/1\nname: *nowhere\n", r"at line 2, column 7: found undefined alias 'nowhere'"),
])
def test_malformed_yaml_names_the_offending_character_or_alias(text, match):
    # the fast (libyaml) parser only says what kind of thing went wrong; the message comes from the detailed one
    with pytest.raises(ModelError, match=match):
        structure_from_yaml(text, "model.yaml")


def test_unknown_name_in_expression_string():
    with pytest.raises(ModelError, match=r"unknown name 'q'"):
        load(BASE.replace("mass: m,", "mass: m*q,"))


def test_unconstrained_dofs_reported_as_rigid_body_modes():
    # the element only restrains x: y, z and the rotations are free -> 5 rigid-body modes, no crash
    s = load(BASE.replace("stiffness: {x: k, y: k, z: k, rx: k, ry: k, rz: k}", "stiffness: {x: k}"))
    system = NumericModel(s).system()
    modes = system.modes("undamped")
    assert int(np.sum(modes.frequency == 0)) == 5
    assert int(np.sum(system.modes("exact").rigid)) == 5


def test_builder_reports_missing_file():
    with pytest.raises(ModelError, match=r"cannot read model file nowhere\.yaml"):
        load_model("nowhere.yaml")


def test_unknown_builtin_lists_available():
    with pytest.raises(ModelError, match=r"unknown built-in model 'nope'; available: .*two-mass-rig"):
        load_model("builtin:nope")


def test_signal_on_inactive_dof_is_an_error():
    b = StructureBuilder("one")
    b.parameter("m", 1.0, kind="mass")
    b.parameter("k", 1.0, kind="stiffness")
    b.body("mass", mass="m", dofs=["x"])
    b.element("spring", bodies=("ground", "mass"), stiffness={"x": "k"})
    b.input("F", body="mass", direction="y")
    with pytest.raises(ModelError, match=r"input 'F' acts only on inactive DOFs of body 'mass' \(active: x\)"):
        NumericModel(b.build())


def test_ground_is_reserved_and_elements_need_two_bodies():
    b = StructureBuilder("x")
    b.parameter("m", 1.0, kind="mass")
    with pytest.raises(ModelError, match=r"'ground' is reserved"):
        b.body("ground", mass="m", dofs=["x"])
    b.body("a", mass="m", dofs=["x"])
    with pytest.raises(ModelError, match=r"element 'e' must join two different bodies; got 'a' twice"):
        b.element("e", bodies=("a", "a"), stiffness={"x": 1})


def test_name_errors_call_a_body_a_body_and_an_axis_an_axis(two_mass):
    # the messages took the group name minus its last letter: "duplicate bodie name", "no bodie named", "axe name"
    b = StructureBuilder("x", source="x.yaml")
    b.body("a", mass=1.0, dofs=["x"])
    with pytest.raises(ModelError, match=r"^duplicate body name 'a' \(x.yaml, bodies\[1\]\); first defined at "):
        b.body("a", mass=1.0, dofs=["x"])
    with pytest.raises(ModelError, match=r"^axis name must be an identifier \(letters, digits, _\); got '1z'"):
        b.axis("1z", [0.0])
    with pytest.raises(ModelError, match=r"^model 'two-mass-rig' has no body named 'm3'; known: "):
        two_mass.body("m3")


def test_unknown_parameter_override_is_an_error(two_mass):
    with pytest.raises(ModelError, match=r"unknown parameter 'm3' for model 'two-mass-rig'"):
        NumericModel(two_mass).vector({"m3": 1.0})


def test_unknown_axis_is_an_error(two_mass):
    with pytest.raises(ModelError, match=r"unknown axis 'z' for model 'two-mass-rig'"):
        two_mass.resolve_position({"z": 0.1})


def test_spinning_body_must_be_axisymmetric():
    b = StructureBuilder("rotor")
    b.parameter("m", 1.0, kind="mass")
    b.parameter("W", 100.0, kind="other")
    with pytest.raises(ModelError, match=r"spinning body 'r' must be axisymmetric about its spin axis"):
        b.body("r", mass="m", inertia={"xx": 0.1, "yy": 0.2, "zz": 0.05, "yz": 0.01}, spin={"axis": "z", "speed": "W"})
    b.body("s", mass="m", inertia={"xx": 0.1, "yy": 0.1, "zz": 0.05}, spin={"axis": "z", "speed": "W"})


def test_checks_cover_every_combination_of_axis_positions():
    # the mass is negative only where both axes are at 1: each combination of positions must be checked
    b = StructureBuilder("two-axes")
    b.parameter("m", 0.5, kind="mass")
    b.axis("a", [0.0, 1.0])
    b.axis("b", [0.0, 1.0])
    with pytest.raises(ModelError, match=r"body 'slide' mass must be > 0; got -0\.5"):
        b.body("slide", mass="m - a*b", dofs=["x"])


# -- numbers as engineers write them, and files that are not model text ------------------------------------


@pytest.mark.parametrize("spelling", ["1e6", "1.0e6", "1E6", "1.e6", "+1e6", "1_000_000", "1000000.", "10e5"])
def test_every_ordinary_float_spelling_is_a_number(spelling):
    # PyYAML (YAML 1.1) reads 1.0e6 and 1e6 as strings; cappe reads them as numbers wherever a number goes,
    # including places that take only numbers (inertia, bounds, axis positions)
    text = (
        BASE.replace("value: 1.0e6", f"value: {spelling}")
        .replace("xx: 0.1", "xx: 1e-1")
        .replace("bounds: [1.0e5, 1.0e7]", "bounds: [1e5, 1E7]")
    )
    structure = load(text)
    assert structure.parameter("k").value == 1e6
    assert structure.parameter("k").bounds == (1e5, 1e7)


def test_non_utf8_model_file_is_a_located_error(tmp_path):
    path = tmp_path / "latin1.yaml"
    path.write_bytes(BASE.replace("name: block", "name: block\ndescription: Bohrmaschine Gro\xdfe").encode("latin-1"))
    with pytest.raises(ModelError, match=r"latin1\.yaml is not UTF-8 text: byte 0xdf at line 3"):
        load_model(path)


@pytest.mark.parametrize(
    "text",
    ["a:\n" + "".join("  " * i + "- \n" for i in range(1, 3000)), "[" * 100_000, "{a: " * 50_000],
)
def test_deeply_nested_yaml_is_a_clean_error(text):
    with pytest.raises(ModelError, match=r"model\.yaml"):
        load(text)


def test_oversized_model_file_is_refused_before_parsing(tmp_path):
    path = tmp_path / "huge.yaml"
    path.write_bytes(b"# " + b"x" * (17 * 2**20))
    with pytest.raises(ModelError, match=r"huge\.yaml is larger than 16 MiB"):
        load_model(path)


def test_integer_beyond_float_range_is_a_located_error():
    text = BASE.replace("value: 2.0", "value: " + "9" * 400)
    with pytest.raises(ModelError, match=r"parameter.*model\.yaml, parameters\[0\]"):
        load(text)
    text = BASE.replace("mass: m", "mass: " + "9" * 400)
    with pytest.raises(ModelError, match=r"below 1\.8e308\); got a larger integer \(model\.yaml, bodies\[0\]\.mass\)"):
        load(text)


def test_integer_with_more_digits_than_python_reads_names_its_line():
    text = BASE.replace("value: 2.0", "value: " + "9" * 5000)
    with pytest.raises(ModelError, match=r"model\.yaml at line 4, column .*integer of 5000 digits"):
        load(text)
