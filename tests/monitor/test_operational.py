"""Output-only monitoring: operational records (no force) through SSI-COV into the same detection and diagnosis.

Truth comes from the operational scenario generator (:func:`cappe.monitor.simulate_operation`: the state-space
resolvent of the model's matrices and an unmeasured coloured force whose spectrum changes with the load), whose
physics is checked here against cappe's own FRF code path, never from the chain itself.
"""

from __future__ import annotations

from dataclasses import replace
from datetime import timedelta

import numpy as np
import pytest

from cappe.cli import main
from cappe.exceptions import DataError
from cappe.model import NumericModel
from cappe.monitor import (
    OUTPUT_ONLY_LIMITATIONS,
    HistoryStore,
    ModalFactorEstimator,
    Monitor,
    MonitorConfig,
    default_config,
    simulate_operation,
    simulate_scenario,
)
from cappe.monitor._operation import _modes

OUTPUTS = ["sx", "sy", "hax", "hay", "haz", "htax"]
BAND = (150.0, 1000.0)


@pytest.fixture(scope="module")
def monitor(spindle: NumericModel) -> Monitor:
    config = default_config(spindle, machine="spindle-oma", source="builtin:spindle-bearing", outputs=OUTPUTS,
                            band=BAND, excitation="operational")
    return Monitor(config, spindle)


@pytest.fixture(scope="module")
def healthy(monitor: Monitor) -> list:
    """A day of operational records every 30 minutes (20 s each): the baseline covers a temperature cycle."""
    return simulate_operation(monitor.config, "healthy", n=48, seconds=20.0, interval=timedelta(minutes=30),
                              model=monitor.model, rng=11)


@pytest.fixture(scope="module")
def baseline(monitor: Monitor, healthy: list):
    return monitor.learn_baseline([monitor.analyse(m.data) for m in healthy],
                                  conditions=[m.conditions for m in healthy])


def test_generator_physics_matches_cappes_frf(spindle: NumericModel) -> None:
    # the generator's resolvent (its own state-space eigen-decomposition) against cappe's FRF of the same
    # parameters: two code paths, one physics
    p = spindle.vector({"kfx": 1.1 * spindle.vector({})[spindle.parameter_names.index("kfx")]})
    system = spindle.system(p, {})
    ii = [system.input_names.index(n) for n in ("Fx", "Fy", "Fz")]
    oo = [system.output_names.index(n) for n in ("sx", "hax")]
    lam, modal_in, modal_out = _modes(system, ii, oo)
    freq = np.array([100.0, 212.0, 480.0, 900.0])
    w = 2 * np.pi * freq
    ours = np.einsum("oj,fj,ij->ofi", modal_out, 1.0 / (1j * w[:, None] - lam[None, :]), modal_in)
    ours[1] *= -(w**2)[:, None]  # hax is an acceleration
    theirs = np.moveaxis(np.asarray(system.frf(freq, inputs=["Fx", "Fy", "Fz"], outputs=["sx", "hax"]).H), -1, 1)
    np.testing.assert_allclose(ours, theirs, rtol=1e-8, atol=1e-12 * np.max(np.abs(theirs)))  # round-off only


def test_records_have_no_force_and_a_load_dependent_colour(monitor: Monitor) -> None:
    records = simulate_operation(monitor.config, "healthy", n=2, seconds=4.0, model=monitor.model, rng=3)
    assert records[0].data.channels == tuple(OUTPUTS)
    assert not set(monitor.config.inputs) & set(records[0].data.channels)
    assert records[0].truth["load"] != records[1].truth["load"]


def test_operational_baseline_and_a_front_bearing_loss(monitor: Monitor, baseline, healthy: list) -> None:
    # the healthy scatter of the output-only factors: below 3 % for every component on 20 s records
    assert np.all(baseline.scale < 0.03), baseline.scale
    faulty = simulate_operation(monitor.config, "bearing-loss", n=5, fault_at=0, component="front", severity=0.10,
                                seconds=20.0, model=monitor.model, rng=12,
                                start=healthy[-1].timestamp + timedelta(hours=13))
    state = None
    first = None
    for k, m in enumerate(faulty):
        analysis = monitor.analyse(m.data, baseline=baseline)
        state, deviation, alarms = monitor.step(state, analysis, m.conditions, baseline)
        if alarms and first is None:
            first = (k, alarms[0].diagnosis.hypothesis, alarms[0].diagnosis.change)
    assert first is not None
    assert first[0] <= 4  # within 5 measurements (the done-means)
    assert first[1] == "front"
    assert first[2] == pytest.approx(-0.10, abs=0.03)  # the size, against the truth of the generator


def test_output_only_fit_recovers_a_screw_loss(monitor: Monitor) -> None:
    data = simulate_operation(monitor.config, "bearing-loss", n=1, fault_at=0, component="screw3", severity=0.2,
                              seconds=30.0, model=monitor.model, rng=5)[0]
    analysis = monitor.analyse(data.data)
    factor = dict(zip(analysis.estimate.names, analysis.estimate.factor, strict=True))
    # a single record against the reference model (no baseline): within 3 % of the truth (healthy scatter ~1 %)
    assert factor["screw3"] == pytest.approx(0.8, abs=0.03)
    assert analysis.estimate.success


def test_output_only_fit_leaves_the_local_minimum_of_a_large_screw_loss(monitor: Monitor) -> None:
    # 50 % off screw 3 shifts the modes so far that the fit from the reference model stops in a local minimum
    # (screws 1-4 at 0.82, 1.37, 0.69, 0.72; RMS scaled residual 13, healthy fits 1.5-1.9); the restarts find it
    data = simulate_operation(monitor.config, "bearing-loss", n=1, fault_at=0, component="screw3", severity=0.5,
                              seconds=30.0, model=monitor.model, rng=103)[0]
    analysis = monitor.analyse(data.data)
    factor = dict(zip(analysis.estimate.names, analysis.estimate.factor, strict=True))
    assert factor["screw3"] == pytest.approx(0.5, abs=0.03)
    assert factor["screw4"] == pytest.approx(1.0, abs=0.05)
    assert analysis.estimate.sigma < 3.0


def test_wrong_data_for_the_excitation(monitor: Monitor, spindle: NumericModel) -> None:
    frf = simulate_scenario(monitor.config, "healthy", n=1, model=spindle, rng=1)[0].frf
    with pytest.raises(DataError, match="monitored output-only: its records are time data of the outputs"):
        monitor.analyse(frf)
    record = simulate_operation(monitor.config, "healthy", n=1, seconds=4.0, model=spindle, rng=1)[0].data
    with pytest.raises(DataError, match=r"lack the output channel\(s\) \['sx'\]"):
        monitor.analyse(record.select(OUTPUTS[1:]))
    measured = Monitor(default_config(spindle, machine="hammer", source="builtin:spindle-bearing", outputs=OUTPUTS,
                                      band=BAND), spindle)
    with pytest.raises(DataError, match=r"time data lack the force channel\(s\) \['Fx', 'Fy', 'Fz'\].*"
                                        r"--excitation operational"):
        measured.analyse(record)


def test_config_round_trip_and_errors(monitor: Monitor) -> None:
    doc = monitor.config.to_dict()
    assert doc["excitation"] == "operational"
    assert MonitorConfig.from_dict(doc).excitation == "operational"
    old = {k: v for k, v in doc.items() if k != "excitation"}  # a store written before output-only monitoring
    assert MonitorConfig.from_dict(old).excitation == "measured"
    with pytest.raises(DataError, match=r"excitation must be one of \['measured', 'operational'\]; got 'shaker'"):
        MonitorConfig.from_dict({**doc, "excitation": "shaker"})
    assert monitor.limitations() == [OUTPUT_ONLY_LIMITATIONS]
    assert "mass change cannot be told from a stiffness change" in OUTPUT_ONLY_LIMITATIONS


def test_modal_estimator_needs_sensor_channels(spindle: NumericModel) -> None:
    config = default_config(spindle, machine="m", source="builtin:spindle-bearing", outputs=["sx", "hax"], band=BAND)
    est = ModalFactorEstimator(Monitor(config, spindle).estimator)
    assert est.sensors == ["shaft_front:x", "housing_front:x"]
    with pytest.raises(DataError, match="no identified mode"):
        est.estimate([], [], np.zeros((2, 0)))


def test_cli_output_only_chain(tmp_path, capsys) -> None:
    store = tmp_path / "oma.db"
    common = ["--machine", "oma"]
    assert main(["monitor", "init", str(store), *common, "--model", "builtin:spindle-bearing", "--outputs",
                 ",".join(OUTPUTS), "--band", "150:1000", "--excitation", "operational"]) == 0
    out = capsys.readouterr().out
    assert "note: output-only (operational) records" in out
    assert main(["monitor", "simulate", "healthy", "--store", str(store), *common, "-n", "3", "--seconds", "8",
                 "--seed", "1", "--format", "npz", "-o", str(tmp_path / "day")]) == 0
    assert "no force channel" in capsys.readouterr().out
    assert main(["monitor", "ingest", str(store), *common, "--manifest", str(tmp_path / "day/scenario.json")]) == 0
    capsys.readouterr()
    with HistoryStore(store) as history:
        kinds = {r.kind for r in history.measurements("oma")}
    assert kinds == {"operational"}  # how the store knows
    assert main(["monitor", "status", str(store)]) == 0
    assert "note: output-only (operational) records" in capsys.readouterr().out


def test_ssi_settings_reach_the_modal_analysis(monitor: Monitor, monkeypatch) -> None:
    import cappe.identify

    record = simulate_operation(monitor.config, "healthy", n=1, seconds=20.0, model=monitor.model, rng=3)[0].data
    calls: list[dict] = []
    real = cappe.identify.ssi_cov

    def spy(*args, **kwargs):
        calls.append(kwargs)
        return real(*args, **kwargs)

    monkeypatch.setattr(cappe.identify, "ssi_cov", spy)
    default_freq = monitor.operational_modes(record)[0]
    assert calls[-1]["orders"][0] == 4  # automatic orders
    assert "mac_tol" not in calls[-1]  # ssi_cov's criteria
    config = replace(monitor.config, ssi_orders=(6, 30, 3), ssi_block_rows=12,
                     ssi_stability={"mac_tol": 0.99, "min_fraction": 0.9})
    freq, _, _, notes = Monitor(config, monitor.model).operational_modes(record)
    assert calls[-1]["orders"] == list(range(6, 31, 3))
    assert calls[-1]["block_rows"] == 12
    assert calls[-1]["mac_tol"] == 0.99
    assert calls[-1]["min_fraction"] == 0.9
    assert not np.array_equal(freq, default_freq, equal_nan=True)  # the settings change the modes found
    # block rows without orders: the automatic orders stop at what 6 outputs x 2 block rows allow, and say so
    capped = Monitor(replace(monitor.config, ssi_block_rows=2), monitor.model)
    notes = capped.operational_modes(record)[3]
    assert calls[-1]["orders"] == [4, 8, 12]
    assert "model orders stop at 12, what 2 block rows x 6 outputs allow" in notes[0]


def test_ssi_settings_round_trip_and_errors(monitor: Monitor) -> None:
    config = replace(monitor.config, ssi_orders=(4, 24, 4), ssi_block_rows=8, ssi_stability={"freq_tol": 0.02})
    back = MonitorConfig.from_dict(config.to_dict())
    assert (back.ssi_orders, back.ssi_block_rows, dict(back.ssi_stability)) == ((4, 24, 4), 8, {"freq_tol": 0.02})
    old = {k: v for k, v in monitor.config.to_dict().items() if not k.startswith("ssi_")}  # an older store
    assert MonitorConfig.from_dict(old).ssi_orders is None
    for change, message in (
        ({"ssi_orders": (1, 10, 2)}, r"ssi_orders must be LOWEST >= 2, HIGHEST >= LOWEST, STEP >= 1; got \(1, 10, 2\)"),
        ({"ssi_orders": (4, 60, 4), "ssi_block_rows": 8}, "ssi_block_rows 8 x 6 outputs allow model orders up to 48"),
        ({"ssi_block_rows": 1}, "ssi_block_rows must be >= 2; got 1"),
        ({"ssi_stability": {"mac": 0.9}}, "unknown SSI-COV stabilization criterion 'mac'"),
        ({"ssi_stability": {"mac_tol": 1.5}}, r"SSI-COV mac_tol must be in \(0, 1\]; got 1.5"),
        ({"excitation": "measured", "ssi_block_rows": 8}, "SSI-COV settings apply to excitation 'operational' only"),
    ):
        with pytest.raises(DataError, match=message):
            replace(monitor.config, **change)


def test_cli_ssi_options(tmp_path, capsys) -> None:
    store = str(tmp_path / "oma.db")
    base = ["monitor", "init", store, "--model", "builtin:spindle-bearing", "--outputs", ",".join(OUTPUTS),
            "--band", "150:1000"]
    assert main([*base, "--machine", "a", "--excitation", "operational", "--ssi-orders", "4:24",
                 "--ssi-block-rows", "8", "--ssi-stability", "mac_tol=0.9,min_fraction=0.6"]) == 0
    assert "SSI-COV: model orders 4-24 step 2, block rows 8, stabilization mac_tol=0.9, min_fraction=0.6" in \
        capsys.readouterr().out
    with HistoryStore(store) as history:
        config = MonitorConfig.from_dict(history.machine_config("a"))
    assert (config.ssi_orders, config.ssi_block_rows) == ((4, 24, 2), 8)
    assert main([*base, "--machine", "b", "--excitation", "operational", "--ssi-orders", "4-24"]) == 2
    assert "--ssi-orders must be LO:HI or LO:HI:STEP with integers; got '4-24'" in capsys.readouterr().err
    assert main([*base, "--machine", "c", "--ssi-block-rows", "8"]) == 1  # a measured machine has no SSI
    err = capsys.readouterr().err
    assert "SSI-COV settings apply to excitation 'operational' only" in err
    assert len(err.strip().splitlines()) == 1
