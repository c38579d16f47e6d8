"""Model GSA: outputs per reference mode x position x criterion, one evaluation per sample and position."""

from __future__ import annotations

import numpy as np
import pytest

from cappe.exceptions import DataError, ModelError
from cappe.io import ModalData, ModalDataSet
from cappe.modal import ModalEngine
from cappe.sensitivity import CRITERIA, model_sobol
from cappe.sensitivity._gsa import _outputs_for


@pytest.fixture(scope="module")
def slide_reference(slide):
    engine = ModalEngine(slide, sensors=["tool", "top"], n_modes=6)
    return engine.modal_data([{"z": 0.1}, {"z": 0.4}])


def test_outputs_cover_every_mode_position_and_criterion(slide, slide_reference, monkeypatch, tmp_path):
    calls: list[int] = []
    original = ModalEngine._solve

    def counting(self, params, position, **kwargs):
        calls.append(params.shape[0])
        return original(self, params, position, **kwargs)

    monkeypatch.setattr(ModalEngine, "_solve", counting)
    names = ["km", "kg0", "cm", "cg", "eta"]
    bounds = [[4e6, 1.6e7], [1.5e7, 6e7], [300, 2000], [100, 600], [0.01, 0.06]]
    res = model_sobol(slide, slide_reference, parameters=names, bounds=bounds, n=64, rng=3)
    n_out = 2 * 6 * 4
    assert res.sobol.S1.shape == (n_out, 5)
    assert res.sobol.output_names[:4] == ("macxp:mode1@z=0.1", "ndd2:mode1@z=0.1", "frequency:mode1@z=0.1",
                                          "damping:mode1@z=0.1")
    assert res.modes[4] == 2
    assert res.positions[-1] == {"z": 0.4}
    assert res.criteria[-1] == "damping"
    # one modal evaluation per sample and position serves all 48 outputs
    assert sum(calls) == 64 * (5 + 2) * 2
    # frequencies are independent of damping parameters (A1), so for modes well apart from their neighbours
    # (72 and 134 Hz at z = 0.1; the 97.5/97.6 Hz pair can swap which one MACXP picks as damping changes)
    # the total indices of damping parameters vanish
    freq_rows = [i for i, (c, m, p) in enumerate(zip(res.criteria, res.modes, res.positions, strict=True))
                 if c == "frequency" and m in (1, 4) and p == {"z": 0.1}]
    damping_cols = [names.index(n) for n in ("cm", "cg", "eta")]
    np.testing.assert_allclose(res.sobol.ST[np.ix_(freq_rows, damping_cols)], 0.0, atol=1e-12)
    assert all(set(res.significant(0.01)[res.sobol.output_names[i]]) <= {"km", "kg0"} for i in freq_rows)
    frame = res.to_dataframe()
    assert {"criterion", "mode", "position", "S1", "ST"} <= set(frame.columns)
    assert res.to_dict()["outputs"][0]["criterion"] == "macxp"
    out = res.plot(tmp_path / "sobol.png", outputs=["macxp:mode2@z=0.4", "ndd2:mode2@z=0.4"])
    assert out.stat().st_size > 1000


def test_outputs_at_the_reference_parameters(slide):
    """At the parameters behind a first-order reference, MACXP = 1 and NDD^2 = 0 for every mode."""
    engine = ModalEngine(slide, sensors=["tool", "top"], n_modes=6)
    ref = engine.modal_data([{"z": 0.25}], exact=False).sets[0]
    batch = ModalEngine(slide, sensors=["tool", "top"]).evaluate(position={"z": 0.25})
    values = _outputs_for(batch, ref, CRITERIA).reshape(6, 4)
    np.testing.assert_allclose(values[:, 0], 1.0, rtol=1e-12)  # round-off of the MACXP quotient
    np.testing.assert_allclose(values[:, 1], 0.0, atol=1e-20)
    np.testing.assert_allclose(values[:, 2], ref.frequency, rtol=1e-12)
    # a model with different stiffness moves the frequencies and lowers the MACXP
    moved = ModalEngine(slide, sensors=["tool", "top"]).evaluate({"kg0": 4.0e7}, position={"z": 0.25})
    assert np.all(_outputs_for(moved, ref, CRITERIA).reshape(6, 4)[:, 0] < 1.0)


def test_single_mode_sensitivity_of_the_two_mass_rig(two_mass):
    """With k12 = 0 fixed the masses decouple: the mass-1 mode frequency depends only on m1 and k11."""
    engine = ModalEngine(two_mass, sensors=["n1:x", "n2:x"])
    ref = engine.modal_data(params={"k12": 0.0, "c12": 0.0})
    res = model_sobol(two_mass, ref, parameters=["m1", "m2", "k11", "k22"], n=256, rng=1, criteria=["frequency"])
    row = res.sobol.output_names.index("frequency:mode2@-")
    st = dict(zip(res.names, res.sobol.ST[row], strict=True))
    # k12 stays at its nominal 0.12e6 here, so m2 and k22 matter a little; m1 and k11 dominate
    assert st["m1"] > 0.3
    assert st["k11"] > 0.3
    assert st["m2"] < 0.05
    assert st["k22"] < 0.05


def test_errors_name_the_problem(two_mass, slide, slide_reference):
    bad_sensors = ModalData(("nowhere:x",), slide_reference.sets[:1])
    with pytest.raises(ModelError, match=r"sensor 'nowhere:x' does not exist in model 'slide'"):
        model_sobol(slide, bad_sensors, parameters=["km"], bounds=[[1e6, 2e6]], n=8)
    with pytest.raises(ModelError, match="lo"):
        model_sobol(slide, slide_reference, parameters=["km"], bounds=[[2e6, 1e6]], n=8)
    with pytest.raises(ModelError, match=r"parameters \['km'\] of model 'slide' have no bounds"):
        model_sobol(slide, slide_reference, parameters=["km"], n=8)
    with pytest.raises(ModelError, match="model 'slide' marks no parameter unknown"):
        model_sobol(slide, slide_reference, n=8)
    with pytest.raises(ModelError, match="criteria must be a non-empty subset"):
        model_sobol(two_mass, slide_reference, criteria=["mac"], n=8)
    zero = ModalData(("n1:x",), (ModalDataSet({}, np.array([90.0]), np.array([0.0]), np.ones((1, 1), complex)),))
    with pytest.raises(DataError, match="reference set 0 has a zero damping ratio"):
        model_sobol(two_mass, zero, n=8)
    with pytest.raises(ModelError, match="unknown parameter 'k99'"):
        model_sobol(two_mass, zero, parameters=["k99"], n=8)
