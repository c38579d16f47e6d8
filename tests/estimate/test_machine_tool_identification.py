"""The automated identification of ``builtin:uniaxial-machine-tool`` meets the issue's done-means (one run each).

The full studies over five truths per case are ``benchmarks/bench_automated.py`` (results in the README); here one
ideal and one disturbed case at the settings of ``make demo`` guard the headline claims on every test run. The truth
is the independent check: it is drawn at random within the bounds and only the reference modes reach the pipeline.
"""

from __future__ import annotations

import numpy as np
import pytest

from cappe.estimate import AutomatedIdentification, ParameterSpace
from cappe.modal import reference_modes
from cappe.model import NumericModel, load_model

pytestmark = [pytest.mark.slow, pytest.mark.extended(reason=(
    "two full identifications of the 45-DOF machine tool; the pipeline's truth-recovery contract is covered on "
    "the bench slide by tests/estimate/test_automated.py::test_ideal_case_recovers_stiffness_and_damping"))]


@pytest.fixture(scope="module")
def machine() -> NumericModel:
    return NumericModel(load_model("builtin:uniaxial-machine-tool"))


def _identify(machine: NumericModel, seed: int, disturb: bool) -> tuple[AutomatedIdentification, dict[str, float]]:
    structure = machine.structure
    space = ParameterSpace.from_model(machine)
    rng = np.random.default_rng(seed)
    truth = space.mapping(space.lower * (space.upper / space.lower) ** rng.uniform(size=space.n))
    # the disturbed model of paper 3.3: the reference comes from known parameters the identification gets wrong
    wrong = structure.disturbed(0.1, rng) if disturb else {}
    reference = reference_modes(machine, params=structure.resolve_parameters({**truth, **wrong}), positions="all",
                                n_modes=20)
    est = AutomatedIdentification(machine, n_gsa=256, n_opt=20, validation={"z": -0.294}, rng=seed,
                                  n_permutations=0)
    return est.fit(reference, truth=truth), truth


def test_ideal_case_all_stiffness_within_1_and_damping_within_5_percent(machine):
    est, truth = _identify(machine, 11, disturb=False)
    errors = est.estimate_.relative_error(truth)
    kinds = {p.name: p.kind for p in machine.structure.parameters}
    stiffness = {n: e for n, e in errors.items() if kinds[n] == "stiffness"}
    damping = {n: e for n, e in errors.items() if kinds[n] != "stiffness"}
    assert len(stiffness) == 16
    assert len(damping) == 11
    assert max(abs(e) for e in stiffness.values()) < 0.01, stiffness
    assert max(abs(e) for e in damping.values()) < 0.05, damping


def test_disturbed_case_stiffness_within_5_percent_and_frac_above_95(machine):
    est, truth = _identify(machine, 12, disturb=True)
    errors = est.estimate_.relative_error(truth)
    kinds = {p.name: p.kind for p in machine.structure.parameters}
    stiffness = {n: e for n, e in errors.items() if kinds[n] == "stiffness"}
    assert max(abs(e) for e in stiffness.values()) < 0.05, stiffness
    frac = est.validation_["validation"].statistics()["frac"]
    assert frac["worst"] >= 0.95
