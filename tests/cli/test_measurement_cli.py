"""``cappe simulate`` (time data), ``cappe frf`` and ``cappe extract-modes`` through main(argv)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cappe.cli import main
from cappe.io import read_frf, read_modal_data, read_time_data, read_uff_modal
from cappe.model import NumericModel, load_model


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture(scope="module")
def rig_modes():
    return NumericModel(load_model("builtin:two-mass-rig")).system().modes()


@pytest.fixture
def impact_run(capsys, tmp_path):
    data = tmp_path / "hit.uff"
    code, out, _ = run(capsys, "simulate", "builtin:two-mass-rig", "--excite", "F1=impact", "--fs", 2048,
                       "--duration", 4, "--band", "0:500", "--amplitude", 200, "--outputs", "a1,a2",
                       "--noise", 0.01, "--seed", 1, "-o", data)
    assert code == 0, out
    return data


def test_simulate_writes_time_data_with_units(capsys, impact_run):
    data = read_time_data(impact_run)
    assert data.channels == ("F1", "a1", "a2")
    assert data.units == ("N", "m/s^2", "m/s^2")
    assert data.fs == 2048.0
    assert data.n_samples == 4 * 2048
    # the hammer pulse peaks at the requested amplitude (noise-free input channel)
    assert data.channel("F1").max() == pytest.approx(200.0, rel=0.02)


def test_impact_chain_recovers_the_rig_modes(capsys, tmp_path, impact_run, rig_modes):
    frf_file = tmp_path / "frf.uff"
    plot = tmp_path / "frf.png"
    code, out, err = run(capsys, "frf", impact_run, "--inputs", "F1", "--outputs", "a1,a2", "--impact",
                         "-o", frf_file, "--plot", plot, "--json")
    assert code == 0, err
    summary = json.loads(out)
    assert summary["window_decay"] > 0  # the 4 s record has not decayed: exponential window applied
    assert summary["outputs"] == ["a1", "a2"]
    assert plot.stat().st_size > 1000
    frf = read_frf(frf_file)
    assert frf.window_decay == pytest.approx(summary["window_decay"], rel=1e-12)

    modes_file = tmp_path / "modes.json"
    uff = tmp_path / "modes.uff"
    stab = tmp_path / "stab.png"
    code, out, err = run(capsys, "extract-modes", frf_file, "--band", "20:400", "--sensor", "a1=n1:x",
                         "--sensor", "a2=n2:x", "-o", modes_file, "--uff", uff, "--plot", stab, "--json")
    assert code == 0, err
    result = json.loads(out)
    freqs = [m["frequency"] for m in result["modes"]]
    assert freqs == sorted(freqs)
    # issue 4 tolerances: frequency 0.5 %, damping 5 %
    np.testing.assert_allclose(freqs, rig_modes.frequency, rtol=0.005)
    np.testing.assert_allclose([m["damping"] for m in result["modes"]], rig_modes.damping, rtol=0.05)
    modal = read_modal_data(modes_file)
    assert modal.sensors == ("n1:x", "n2:x")
    np.testing.assert_allclose(modal.sets[0].frequency, freqs, rtol=1e-12)
    from_uff = read_uff_modal(uff)
    np.testing.assert_allclose(from_uff.sets[0].frequency, freqs, rtol=1e-12)
    assert stab.stat().st_size > 1000


def test_frf_text_output_and_random_excitation(capsys, tmp_path):
    data = tmp_path / "run.csv"
    code, _, _ = run(capsys, "simulate", "builtin:two-mass-rig", "--excite", "F1=random", "--excite", "F2=random",
                     "--fs", 1024, "--duration", 16, "--band", "0:300", "--outputs", "d1,d2", "--seed", 3, "-o", data)
    assert code == 0
    code, out, err = run(capsys, "frf", data, "--inputs", "F1,F2", "--outputs", "d1,d2", "--band", "20:300",
                         "--nperseg", 4096)
    assert code == 0, err
    assert "H1 FRFs of 2 output(s) x 2 input(s)" in out
    assert "d2/F1:" in out


def test_errors_and_exit_codes(capsys, tmp_path, impact_run):
    code, _, err = run(capsys, "frf", impact_run, "--inputs", "F9", "--outputs", "a1")
    assert code == 1
    assert "F9" in err
    assert "F1" in err  # the available channels are listed
    code, _, err = run(capsys, "frf", impact_run, "--inputs", "F1", "--outputs", "a1", "--band", "400:100")
    assert code == 2
    assert "--band must look like LO:HI" in err
    code, _, err = run(capsys, "frf", impact_run, "--inputs", "F1", "--outputs", "a1", "--exp-window", "soon")
    assert code == 2
    assert "--exp-window must be a time constant" in err
    code, _, err = run(capsys, "simulate", "builtin:two-mass-rig", "--excite", "F3=random")
    assert code == 2
    assert "'F3' is not an input of two-mass-rig" in err
    code, _, err = run(capsys, "simulate", "builtin:two-mass-rig", "--excite", "F1=sine")
    assert code == 2
    assert "sine needs a frequency in Hz" in err
    code, _, err = run(capsys, "simulate", "builtin:two-mass-rig", "--excite", "F1=noise")
    assert code == 2
    assert "unknown signal 'noise'" in err
    frf_file = tmp_path / "f.npz"
    assert run(capsys, "frf", impact_run, "--inputs", "F1", "--outputs", "a1", "--impact", "-o", frf_file)[0] == 0
    code, _, err = run(capsys, "extract-modes", frf_file, "--band", "20:5000")
    assert code == 1
    assert "band" in err
    code, _, err = run(capsys, "extract-modes", frf_file, "--band", "20:400", "--uff", tmp_path / "m.uff")
    assert code == 2
    assert "--sensor OUTPUT=NODE:DIR" in err
    code, _, err = run(capsys, "extract-modes", frf_file, "--band", "20:400", "--sensor", "z=n1:x")
    assert code == 2
    assert "--sensor names channels ['z']" in err
    code, _, err = run(capsys, "extract-modes", tmp_path / "missing.uff", "--band", "20:400")
    assert code == 1
    assert "missing.uff" in err


@pytest.fixture
def random_run(capsys, tmp_path):
    data = tmp_path / "random.npz"
    code, _, _ = run(capsys, "simulate", "builtin:two-mass-rig", "--excite", "F1=random", "--excite", "F2=random",
                     "--fs", 2000, "--duration", 5, "--band", "0:1000", "--outputs", "d1", "--noise", 0.01,
                     "--seed", 1, "-o", data)
    assert code == 0
    return data


def test_fit_arx40_pruned_to_the_physical_order(capsys, tmp_path, random_run, rig_modes):
    plot = tmp_path / "pz.png"
    code, out, err = run(capsys, "fit", random_run, "--inputs", "F1,F2", "--output", "d1", "--structure", "arx",
                         "--order", 40, "--prune", "auto", "--plot", plot, "--json")
    assert code == 0, err
    result = json.loads(out)
    # same shape as `cappe model tf` at the top level (first input), plus poles and modes
    assert result["input"] == "F1"
    assert result["output"] == "d1"
    assert result["denominator"][0] == 1.0
    assert len(result["denominator"]) == 5  # the rig's physical order: 2 modes, 4 poles
    assert [tf["input"] for tf in result["transfer_functions"]] == ["F1", "F2"]
    assert len(result["poles"]) == 2  # one per conjugate pair
    np.testing.assert_allclose([m["frequency"] for m in result["modes"]], rig_modes.frequency, rtol=0.005)
    np.testing.assert_allclose([m["damping"] for m in result["modes"]], rig_modes.damping, rtol=0.05)
    assert result["pruning"]["F1"]["removed_counts"]
    assert plot.stat().st_size > 1000
    # the pruned continuous TF reproduces the model's: compare at the first resonance (within 5 %, noise and
    # pruning; the resonance peak is the most sensitive point to the damping estimate)
    from cappe.model import NumericModel, load_model

    s = 2j * np.pi * rig_modes.frequency[1]
    truth = NumericModel(load_model("builtin:two-mass-rig")).system().frf([rig_modes.frequency[1]], "F1", "d1").H
    fitted = np.polyval(result["numerator"], s) / np.polyval(result["denominator"], s)
    assert abs(fitted / truth[0, 0, 0] - 1) < 0.05


def test_fit_order_selection_and_refinement(capsys, random_run, rig_modes):
    code, out, err = run(capsys, "fit", random_run, "--inputs", "F1,F2", "--output", "d1", "--structure", "oe",
                         "--order", "auto", "--max-order", 5, "--criterion", "bic")
    assert code == 0, err
    assert "OE fit of d1 from F1, F2 (nb=4, nf=4, nk=1)" in out  # BIC picks the physical order 4
    code, out, err = run(capsys, "fit", random_run, "--inputs", "F1", "--output", "d1", "--order", 30, "--prune", 2,
                         "--refine", "--json")
    assert code == 0, err
    result = json.loads(out)
    assert result["refined"]["orders"] == {"nb": 4, "nf": 4, "nk": 1}
    np.testing.assert_allclose([m["frequency"] for m in result["modes"]], rig_modes.frequency, rtol=0.005)


def test_fit_usage_errors(capsys, random_run):
    code, _, err = run(capsys, "fit", random_run, "--inputs", "F1", "--output", "d1", "--order", "forty")
    assert code == 2
    assert "--order must be a positive integer or 'auto'; got 'forty'" in err
    code, _, err = run(capsys, "fit", random_run, "--inputs", "F1", "--output", "d1", "--order", 4, "--prune", "x")
    assert code == 2
    assert "--prune must be a positive number of modes or 'auto'" in err
    code, _, err = run(capsys, "fit", random_run, "--inputs", "F1", "--output", "d1", "--order", 4, "--refine")
    assert code == 2
    assert "add --prune N or --prune auto" in err
    code, _, err = run(capsys, "fit", random_run, "--inputs", "F7", "--output", "d1", "--order", 4)
    assert code == 1
    assert "F7" in err
