"""Preload studies (cappe.monitor._preload, ``cappe monitor preload``) on the spindle model (thesis 5.4.3)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cappe.cli import main
from cappe.exceptions import ModelError
from cappe.modal import ModalEngine
from cappe.monitor import preload_frfs, preload_map, sensor_visibility
from cappe.systems.frf import FRFData


def test_map_columns_are_exact_modes_of_the_system_at_each_preload(spindle):
    result = preload_map(spindle, (0.3, 1.0, 1.4))
    # at the reference preload the columns are modes 1-5 in frequency order
    exact = spindle.system({"preload": 1.0}).modes("exact")
    np.testing.assert_allclose(result.frequency[1], exact.frequency[:5], rtol=1e-9)
    np.testing.assert_allclose(result.damping[1], exact.damping[:5], rtol=1e-7)
    for k, value in enumerate(result.preload):
        modes = spindle.system({"preload": float(value)}).modes("exact")  # MechanicalSystem, not the engine
        for j in range(len(result.modes)):
            r = int(np.argmin(np.abs(modes.frequency - result.frequency[k, j])))
            assert result.frequency[k, j] == pytest.approx(modes.frequency[r], rel=1e-9)
            assert result.damping[k, j] == pytest.approx(modes.damping[r], rel=1e-6)
    assert np.all(result.tracking_mac > 0.5)


def test_map_sensitivity_matches_the_analytic_frequency_derivative(spindle):
    h = 0.01
    result = preload_map(spindle, (1 - h, 1.0, 1 + h))
    d = ModalEngine(spindle, sensors="dofs").derivatives({"preload": 1.0}, parameters=["preload"])
    analytic = d.d_frequency[:5, 0] / d.frequency[:5]  # d ln f / d preload at preload 1 (undamped modes)
    # exact damped modes and a central difference over +-1 %: agreement to a few parts in a thousand
    np.testing.assert_allclose(result.sensitivity(), analytic, rtol=5e-3, atol=2e-4)


def test_frfs_move_their_peaks_up_with_the_preload(spindle):
    freq = np.linspace(150, 320, 1701)
    frfs = preload_frfs(spindle, freq, (0.75, 1.0, 1.25), inputs="Fx", outputs="sx")
    peaks = [float(freq[np.argmax(np.abs(frfs[v].H[0, 0]))]) for v in (0.75, 1.0, 1.25)]
    assert peaks[0] < peaks[1] < peaks[2]
    direct = spindle.system({"preload": 1.25}).frf(freq, inputs="Fx", outputs="sx")
    np.testing.assert_array_equal(frfs[1.25].H, direct.H)


def test_sensor_visibility_in_db_below_the_strongest_mode():
    freq = np.linspace(1.0, 100.0, 991)
    h = np.zeros((2, 1, freq.size), dtype=complex)
    h[0, 0, 190] = 10.0  # 20 Hz
    h[0, 0, 590] = 0.1  # 60 Hz: 40 dB down
    h[1, 0, 190] = 1.0
    h[1, 0, 590] = 2.0
    frf = FRFData(freq=freq, H=h, input_names=("F",), output_names=("a", "b"))
    levels = sensor_visibility(frf, [20.0, 60.0])
    np.testing.assert_allclose(levels[:, 0, :], [[0.0, -40.0], [20 * np.log10(0.5), 0.0]], atol=1e-12)
    with pytest.raises(ModelError, match="no line within 2 % of the mode at 500 Hz"):
        sensor_visibility(frf, [500.0])


def test_map_errors(spindle):
    with pytest.raises(ModelError, match="has no parameter 'bolt'"):
        preload_map(spindle, parameter="bolt")
    with pytest.raises(ModelError, match="preloads must be positive"):
        preload_map(spindle, (0.5, -1.0))
    with pytest.raises(ModelError, match="modes must be numbers from 1 to 11"):
        preload_map(spindle, modes=(0, 2))


def test_cli_prints_the_map_and_writes_plots(capsys, tmp_path):
    map_png, bode_png = tmp_path / "map.png", tmp_path / "bode.png"
    code = main(["monitor", "preload", "builtin:spindle-bearing", "--preloads", "0.5,1,1.5", "--modes", "1,2",
                 "--outputs", "sx,hx", "--plot-map", str(map_png), "--plot-bode", str(bode_png), "--json"])
    out = capsys.readouterr().out
    assert code == 0
    data = json.loads(out)
    assert data["map"]["preload"] == [0.5, 1.0, 1.5]
    assert data["map"]["modes"] == [1, 2]
    assert set(data["visibility_db"]) == {"sx", "hx"}
    assert max(data["visibility_db"]["sx"]) == 0.0
    assert map_png.stat().st_size > 0
    assert bode_png.stat().st_size > 0
    code = main(["monitor", "preload", "builtin:spindle-bearing", "--preloads", "a,b"])
    assert code == 2
    assert "--preloads must be comma-separated numbers" in capsys.readouterr().err
    code = main(["monitor", "preload", "builtin:two-mass-rig"])
    assert code == 1
    assert "has no parameter 'preload'" in capsys.readouterr().err
