"""check_model: conditioning and rigid-body modes in closed form, ranks of systems uncontrollable by construction."""

from __future__ import annotations

import numpy as np
import pytest

from cappe.exact import EXACT_STATE_LIMIT, PBHRanks, check_model
from cappe.exceptions import ModelError
from cappe.model import NumericModel, StructureBuilder, load_model


def twin():
    """One body on x and y springs of equal stiffness, one force along (3, 4)/5: only 3 x + 4 y is driven."""
    b = StructureBuilder("twin")
    b.parameter("m", 2.0, kind="mass")
    b.parameter("k", 8.0e3, kind="stiffness")
    b.parameter("c", 3.0, kind="damping")
    b.body("body", mass="m", dofs=["x", "y"])
    b.element("mount", bodies=("ground", "body"), stiffness={"x": "k", "y": "k"}, damping={"x": "c", "y": "c"})
    b.input("F", body="body", direction=[3, 4, 0])
    b.output("dx", quantity="displacement", body="body", direction="x")
    b.output("dy", quantity="displacement", body="body", direction="y")
    b.output("dq", quantity="displacement", body="body", direction=[3, 4, 0])
    return b.build()


def free_pair():
    """Two bodies joined by one spring and tied to nothing: one rigid-body mode, both moving together."""
    b = StructureBuilder("free-pair")
    b.parameter("m1", 1.0, kind="mass")
    b.parameter("m2", 3.0, kind="mass")
    b.parameter("k", 1.0e4, kind="stiffness")
    b.body("a", mass="m1", dofs=["x"])
    b.body("b", mass="m2", dofs=["x"])
    b.element("link", bodies=("a", "b"), stiffness={"x": "k"})
    b.input("F", body="a", direction="x")
    b.output("d", quantity="displacement", body="b", direction="x")
    return b.build()


def test_uncontrollable_twin_by_construction():
    check = check_model(twin(), inputs=["F"], outputs=["dx", "dy"])
    # A = diag(A1, A1) and b = (3 b1, 4 b1) / 5: rank [b, Ab, ...] = 2 of 4; x and y both measured: 4
    assert check.pbh == PBHRanks(2, 4)
    assert (check.controllability_rank, check.observability_rank) == (2, 4)
    assert check.invertibility is not None
    assert check.invertibility.invertible_exact  # one input, two outputs, a nonzero transfer column
    assert check.rigid_body_modes == ()
    # M = 2 I and K = 8e3 I: both perfectly conditioned (to round-off, 1e-12)
    assert check.condition_M == pytest.approx(1.0, rel=1e-12)
    assert check.condition_K == pytest.approx(1.0, rel=1e-12)
    along = check_model(twin(), inputs=["F"], outputs=["dq"])
    assert along.pbh == PBHRanks(2, 2)  # one direction driven, the same one measured
    assert along.outputs == ("dq",)


def test_rigid_body_mode_of_a_free_pair():
    check = check_model(free_pair())
    assert len(check.rigid_body_modes) == 1
    (mode,) = check.rigid_body_modes
    assert set(mode) == {"a.x", "b.x"}
    assert mode["a.x"] == mode["b.x"] == pytest.approx(np.sign(mode["a.x"]), abs=1e-6)  # shape (1, 1) up to sign
    assert check.condition_M == pytest.approx(3.0, rel=1e-12)  # diag(1, 3)
    assert check.condition_K == np.inf  # singular K is reported as such
    assert check.to_dict()["condition"] == {"M": check.condition_M, "K": None}


def test_condition_number_of_the_rig_in_closed_form():
    # K of the two-mass rig as NumericModel prints it: eigenvalues of a symmetric 2x2 matrix in closed form
    k11, k12, k22 = 1.5e6, -1.2e5, 3.6e5
    mean, half = (k11 + k22) / 2, np.hypot((k11 - k22) / 2, k12)
    check = check_model(NumericModel(load_model("builtin:two-mass-rig")))
    assert check.condition_K == pytest.approx((mean + half) / (mean - half), rel=1e-12)
    assert check.n_states == 4
    assert check.exact  # 4 states <= EXACT_STATE_LIMIT
    assert EXACT_STATE_LIMIT == 24


def test_exact_tests_can_be_skipped_and_values_change_the_result():
    rig = load_model("builtin:two-mass-rig")
    check = check_model(rig, exact=False)
    assert not check.exact
    assert check.invertibility is None
    assert "invertibility" not in check.to_dict()
    stiffer = check_model(rig, {"k11": 3.0e6}, exact=False)  # k11 doubled: K's spread grows
    assert stiffer.condition_K > check.condition_K


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"inputs": ["F9"]}, r"model 'two-mass-rig' has no input named 'F9'; known: F1, F2"),
        ({"outputs": ["q"]}, r"model 'two-mass-rig' has no output named 'q'"),
        ({"values": {"k99": 1.0}}, r"unknown parameter 'k99' for model 'two-mass-rig'"),
        ({"position": {"z": 0.1}}, r"unknown axis 'z' for model 'two-mass-rig'"),
    ],
)
def test_unknown_names_are_model_errors(settings, message):
    with pytest.raises(ModelError, match=message):
        check_model(load_model("builtin:two-mass-rig"), exact=False, **settings)
