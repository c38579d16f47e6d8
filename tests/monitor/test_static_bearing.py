"""Bearing stiffness from a quasi-static test (cappe.monitor._static) on the spindle model's static response."""

from __future__ import annotations

from importlib import resources

import numpy as np
import pytest
import yaml

from cappe.exceptions import DataError, ModelError
from cappe.model import NumericModel
from cappe.model.bearing import AngularContactBearing
from cappe.model.loader import structure_from_mapping
from cappe.monitor import static_bearing_stiffness

Z_FORCE, Z_FRONT, Z_REAR = 0.2417, 0.127, -0.162  # spindle-bearing: input Fx, bearing element centres
Z_SENSORS = (0.195, -0.230)  # the shaft proximity probes of the model (shaft_front, shaft_rear)


@pytest.fixture(scope="module")
def spindle() -> NumericModel:
    """The spindle with housing points under the two shaft probes (relative displacement = shaft - housing)."""
    text = resources.files("cappe.library").joinpath("models", "spindle-bearing.yaml").read_text()
    data = yaml.safe_load(text)
    data["sensors"] += [{"name": "h1", "body": "housing", "point": [0, 0, Z_SENSORS[0]]},
                        {"name": "h2", "body": "housing", "point": [0, 0, Z_SENSORS[1]]}]
    return NumericModel(structure_from_mapping(data, "spindle-bearing + probes"))


def _static_test(nm: NumericModel, preload: float, force: np.ndarray, noise: float, seed: int):
    system = nm.system({"preload": preload})
    u = np.linalg.solve(system.K, system.B[:, [system.input_names.index("Fx")]] * force[None, :])  # (n, T)
    labels, rows = nm.sensor_matrix(nm.vector({"preload": preload}), None)
    x = {lab: rows[labels.index(lab)] @ u for lab in ("shaft_front:x", "shaft_rear:x", "h1:x", "h2:x")}
    rel1, rel2 = x["shaft_front:x"] - x["h1:x"], x["shaft_rear:x"] - x["h2:x"]
    rng = np.random.default_rng(seed)
    scale1, scale2 = noise * np.std(rel1), noise * np.std(rel2)
    return rel1 + scale1 * rng.standard_normal(rel1.size), rel2 + scale2 * rng.standard_normal(rel2.size)


def _truth(preload: float) -> tuple[float, float]:
    bearing = AngularContactBearing(18, 0.0079375, 0.065, np.radians(15.0))
    ratio = bearing.state(378.0 * preload).radial_stiffness / bearing.state(378.0).radial_stiffness
    return 60.0e6 * ratio, 60.0e6 * ratio  # kfx, krx of Table 5.8 times the Hertz ratio


@pytest.mark.parametrize("preload", [1.0, 0.6])
def test_noise_free_test_recovers_the_model_bearings_exactly(spindle, preload):
    force = 200.0 * np.sign(np.sin(2 * np.pi * np.arange(400) / 100 + 0.1))  # a slow square wave
    u1, u2 = _static_test(spindle, preload, force, 0.0, 0)
    res = static_bearing_stiffness(force, u1, u2, z_force=Z_FORCE, z_front=Z_FRONT, z_rear=Z_REAR,
                                   z_sensors=Z_SENSORS)
    k_front, k_rear = _truth(preload)
    np.testing.assert_allclose(res.front, k_front, rtol=1e-8)
    np.testing.assert_allclose(res.rear, k_rear, rtol=1e-8)


def test_noisy_test_statistics_cover_the_truth(spindle):
    force = 200.0 * np.sign(np.sin(2 * np.pi * np.arange(2000) / 200 + 0.1))
    covered = 0
    for seed in range(20):
        u1, u2 = _static_test(spindle, 1.0, force, 0.01, seed)
        res = static_bearing_stiffness(force, u1, u2, z_force=Z_FORCE, z_front=Z_FRONT, z_rear=Z_REAR,
                                       z_sensors=Z_SENSORS)
        summary = res.summary()
        for name, truth in zip(("front", "rear"), _truth(1.0), strict=True):
            assert summary[name]["mean"] == pytest.approx(truth, rel=0.01)
            covered += summary[name]["ci95_low"] <= truth <= summary[name]["ci95_high"]
    # 40 intervals of the mean at 95 %: a handful may miss (1/k bias of noisy ratios is below 1e-4 here)
    assert covered >= 34


def test_static_test_errors():
    f = np.array([1.0, 2.0])
    with pytest.raises(DataError, match="same, non-zero length"):
        static_bearing_stiffness(f, [1.0], [1.0, 2.0], z_force=0.2, z_front=0.1, z_rear=-0.1, z_sensors=(0.15, 0.2))
    with pytest.raises(DataError, match="displacement_2 is not finite at sample 1"):
        static_bearing_stiffness(f, [1.0, 1.0], [1.0, np.nan], z_force=0.2, z_front=0.1, z_rear=-0.1,
                                 z_sensors=(0.15, 0.2))
    with pytest.raises(ModelError, match="sensors must be at different z"):
        static_bearing_stiffness(f, f, f, z_force=0.2, z_front=0.1, z_rear=-0.1, z_sensors=(0.15, 0.15))
    with pytest.raises(DataError, match="the force is zero throughout"):
        static_bearing_stiffness([0.0, 0.0], f, f, z_force=0.2, z_front=0.1, z_rear=-0.1, z_sensors=(0.15, 0.2))


def test_cli_bearing_test_reads_a_record_and_reports_statistics(spindle, tmp_path, capsys):
    import json

    from cappe.cli import main
    from cappe.io import TimeData, write_time_data

    force = 200.0 * np.sign(np.sin(2 * np.pi * np.arange(1000) / 200 + 0.1))
    u1, u2 = _static_test(spindle, 0.8, force, 0.01, 3)
    record = tmp_path / "static.csv"
    write_time_data(record, TimeData.from_channels(np.arange(force.size) * 0.01, {"F": force, "d1": u1, "d2": u2}))
    code = main(["monitor", "bearing-test", str(record), "--force", "F", "--displacements", "d1,d2",
                 "--z-force", str(Z_FORCE), "--z-bearings", f"{Z_FRONT},{Z_REAR}",
                 "--z-sensors", f"{Z_SENSORS[0]},{Z_SENSORS[1]}", "--json"])
    out = capsys.readouterr().out
    assert code == 0
    data = json.loads(out)
    for name, truth in zip(("front", "rear"), _truth(0.8), strict=True):
        assert data["summary"][name]["mean"] == pytest.approx(truth, rel=0.01)
    assert data["n_used"] == 1000
    code = main(["monitor", "bearing-test", str(record), "--force", "F", "--displacements", "d1",
                 "--z-force", "0.2", "--z-bearings", "0.1,-0.1", "--z-sensors", "0.15,0.2"])
    assert code == 2
    assert "--displacements must name two channels" in capsys.readouterr().err
