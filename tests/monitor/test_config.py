"""The machine description (cappe.monitor._config): components derived from the models, the default config,
serialization, and every validation message."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import scipy.linalg

from cappe.exceptions import DataError
from cappe.monitor import (
    CONFIG_FORMAT,
    Component,
    MonitorConfig,
    SeverityThresholds,
    default_components,
    default_config,
)


def minimal(**changes) -> MonitorConfig:
    base = MonitorConfig(machine="m1", model="builtin:two-mass-rig", inputs=("F1",), outputs=("d1", "d2"),
                         band=(50.0, 250.0), components=(Component("coupling", "coupling spring", ("k12",)),
                                                         Component("base", "base spring", ("k11",))))
    return replace(base, **changes)


def test_default_components_of_the_spindle(spindle):
    comps = default_components(spindle.structure)
    # the model file: front_x/_y/_z and rear_x/_y are direction-suffixed bearing elements, screw1..4 carry
    # three stiffnesses each (kh{i}x, kh{i}y, kh{i}z); dampings and the preload are not stiffness parameters
    expected = {"front": ("kfx", "kfy", "kfz"), "rear": ("krx", "kry")}
    expected |= {f"screw{i}": (f"kh{i}x", f"kh{i}y", f"kh{i}z") for i in range(1, 5)}
    assert {c.name: c.parameters for c in comps} == expected
    assert [c.name for c in comps] == ["front", "rear", "screw1", "screw2", "screw3", "screw4"]
    assert [c.label for c in comps] == ["front bearing", "rear bearing", "housing screw 1", "housing screw 2",
                                        "housing screw 3", "housing screw 4"]
    stiffness = [p.name for p in spindle.structure.parameters if p.kind == "stiffness"]
    assert sorted(p for c in comps for p in c.parameters) == sorted(stiffness)  # each exactly once


def test_default_components_of_the_rig(rig):
    comps = default_components(rig.structure)
    assert {c.name: c.parameters for c in comps} == {"beam1": ("k11",), "spring12": ("k12",), "beam2": ("k22",)}
    assert [c.label for c in comps] == ["beam1", "spring12", "beam2"]


def test_default_config_of_the_spindle(spindle):
    config = default_config(spindle, machine="s1", source="builtin:spindle-bearing")
    # band: 0.7 x the first and 1.1 x the last natural frequency, |lambda| / 2 pi of the state matrix
    mats = spindle.matrices(spindle.vector({}), {})
    n = mats["M"].shape[0]
    a = np.block([[np.zeros((n, n)), np.eye(n)],
                  [-np.linalg.solve(mats["M"], mats["K"]), -np.linalg.solve(mats["M"], mats["C"] + mats["G"])]])
    lam = scipy.linalg.eigvals(a)
    f = np.sort(np.abs(lam[lam.imag > 0])) / (2 * np.pi)
    assert config.band == (round(0.7 * f[0], 1), round(1.1 * f[-1], 1)) == (148.5, 1213.3)
    assert config.fault_parameters == ("preload",)
    assert config.inputs == spindle.input_names
    assert config.outputs == spindle.output_names
    assert config.component_names == ("front", "rear", "screw1", "screw2", "screw3", "screw4")
    assert (config.detection, config.false_alarm_rate, config.shift, config.ewma_lambda) == ("cusum", 1e-3, 2.0, 0.2)
    assert config.model == "builtin:spindle-bearing"
    assert config.machine == "s1"


def test_default_config_options(rig, spindle):
    config = default_config(rig, machine="r1", source="builtin:two-mass-rig", outputs=["d1", "d2"], inputs=["F1"],
                            detection="ewma", ewma_lambda=0.1, params={"k12": 1.0e5})
    assert config.fault_parameters == ()  # no preload parameter in the rig
    assert config.inputs == ("F1",)
    assert config.outputs == ("d1", "d2")
    assert config.detection == "ewma"
    assert config.ewma_lambda == 0.1
    # the band follows the reference model with the overrides
    f = rig.system({"k12": 1.0e5}).modes("exact").frequency
    assert config.band == (round(0.7 * f[0], 1), round(1.1 * f[-1], 1))
    explicit = default_config(spindle, machine="s2", source="x", band=(100.0, 900.0), fault_parameters=[])
    assert explicit.band == (100.0, 900.0)
    assert explicit.fault_parameters == ()
    with pytest.raises(DataError, match=r"monitor config 's3': output\(s\) \['bogus'\] not in model x"):
        default_config(spindle, machine="s3", source="x", outputs=["sx", "bogus"])


def test_dict_round_trip_through_json(spindle):
    config = default_config(spindle, machine="s1", source="builtin:spindle-bearing", params={"kfx": 7e7},
                            detection="ewma", false_alarm_rate=0.002, shift=1.5, ewma_lambda=0.15,
                            severity=SeverityThresholds(0.03, 0.2),
                            severity_overrides={"preload": SeverityThresholds(0.1, 0.4)}, noise_floor=0.02,
                            max_order=30, slow_every=5)
    d = json.loads(json.dumps(config.to_dict()))
    assert d["format"] == CONFIG_FORMAT
    again = MonitorConfig.from_dict(d)
    assert again == config
    assert again.thresholds("preload") == SeverityThresholds(0.1, 0.4)
    assert again.thresholds("front") == SeverityThresholds(0.03, 0.2)
    assert again.component("rear").parameters == ("krx", "kry")


def test_from_dict_defaults_for_optional_keys():
    d = minimal().to_dict()
    for key in ("params", "position", "fault_parameters", "detection", "false_alarm_rate", "shift", "ewma_lambda",
                "severity", "severity_overrides", "noise_floor", "max_order", "slow_every"):
        del d[key]
    d["components"] = [{"name": "coupling", "parameters": ["k12"]}]  # the label defaults to the name
    config = MonitorConfig.from_dict(d)
    assert config.components == (Component("coupling", "coupling", ("k12",)),)
    assert config == replace(minimal(), components=config.components)


def test_component_lookup_error():
    with pytest.raises(DataError, match=r"machine 'm1' has no component 'tip'; components: \['coupling', 'base'\]"):
        minimal().component("tip")


@pytest.mark.parametrize(("changes", "message"), [
    ({"machine": ""}, r"monitor config: machine id must not be empty"),
    ({"detection": "shewhart"}, r"monitor config 'm1': detection must be 'cusum' or 'ewma'; got 'shewhart'"),
    ({"false_alarm_rate": 0.0}, r"monitor config 'm1': false_alarm_rate must be in \(0, 0.5\]; got 0.0"),
    ({"false_alarm_rate": 0.6}, r"monitor config 'm1': false_alarm_rate must be in \(0, 0.5\]; got 0.6"),
    ({"false_alarm_rate": float("nan")}, r"monitor config 'm1': false_alarm_rate must be in \(0, 0.5\]; got nan"),
    ({"shift": 0.0}, r"monitor config 'm1': shift must be in \(0, 50\]; got 0.0"),
    ({"shift": 51.0}, r"monitor config 'm1': shift must be in \(0, 50\]; got 51.0"),
    ({"ewma_lambda": 0.0}, r"monitor config 'm1': ewma_lambda must be in \(0, 1\]; got 0.0"),
    ({"ewma_lambda": 1.5}, r"monitor config 'm1': ewma_lambda must be in \(0, 1\]; got 1.5"),
    ({"noise_floor": 0.0}, r"monitor config 'm1': noise_floor must be in \(0, 1\]; got 0.0"),
    ({"noise_floor": float("inf")}, r"monitor config 'm1': noise_floor must be in \(0, 1\]; got inf"),
    ({"band": (250.0, 50.0)}, r"monitor config 'm1': band must be 0 <= LO < HI Hz; got \(250.0, 50.0\)"),
    ({"band": (-1.0, 50.0)}, r"monitor config 'm1': band must be 0 <= LO < HI Hz; got \(-1.0, 50.0\)"),
    ({"band": (0.0, float("inf"))}, r"monitor config 'm1': band must be 0 <= LO < HI Hz; got \(0.0, inf\)"),
    ({"components": ()}, r"monitor config 'm1': at least one component is needed"),
    ({"components": (Component("a", "a", ()),)}, r"monitor config 'm1': component 'a' has no parameters"),
    ({"components": (Component("a", "a", ("k11", "k12")), Component("b", "b", ("k22", "k12")))},
     r"monitor config 'm1': parameter 'k12' is in components 'a' and 'b'; each parameter belongs to one component"),
    ({"components": (Component("a", "a", ("k11",)), Component("a", "a2", ("k12",)))},
     r"monitor config 'm1': component and fault-parameter names must be unique; got \['a', 'a'\]"),
    ({"fault_parameters": ("coupling",)},
     r"monitor config 'm1': component and fault-parameter names must be unique; got \['coupling', 'base', "
     r"'coupling'\]"),
    ({"max_order": 1}, r"monitor config 'm1': max_order must be >= 2 and slow_every >= 0; got 1, 0"),
    ({"slow_every": -1}, r"monitor config 'm1': max_order must be >= 2 and slow_every >= 0; got 24, -1"),
])
def test_validation_messages(changes, message):
    with pytest.raises(DataError, match=message):
        minimal(**changes)


def test_boundaries_that_are_allowed():
    # the intervals are open below and closed above
    config = minimal(false_alarm_rate=0.5, shift=50.0, ewma_lambda=1.0, noise_floor=1.0, band=(0.0, 1.0),
                     max_order=2, slow_every=0)
    assert config.false_alarm_rate == 0.5


def test_severity_threshold_messages():
    for tolerable, intolerable in ((0.0, 0.2), (0.3, 0.2), (0.2, 0.2), (-0.1, 0.2)):
        with pytest.raises(DataError, match=rf"severity thresholds must satisfy 0 < tolerable < intolerable; got "
                                            rf"tolerable {tolerable!r}, intolerable {intolerable!r}"):
            SeverityThresholds(tolerable, intolerable)


def test_check_model_names_every_unknown_name(rig):
    minimal().check_model(rig)  # all known
    cases = [
        ({"inputs": ("F1", "F9")}, r"input\(s\) \['F9'\] not in model builtin:two-mass-rig; known: \['F1', 'F2'\]"),
        ({"outputs": ("d1", "x2")}, r"output\(s\) \['x2'\] not in model builtin:two-mass-rig; known: \['a1', 'a2', "),
        ({"components": (Component("c", "c", ("k99",)),)}, r"parameter\(s\) \['k99'\] not in model"),
        ({"fault_parameters": ("preload",)}, r"parameter\(s\) \['preload'\] not in model"),
        ({"params": {"m9": 1.0}}, r"parameter\(s\) \['m9'\] not in model"),
        ({"position": {"z": 0.1}}, r"axis\(s\) \['z'\] not in model builtin:two-mass-rig; known: \[\]"),
    ]
    for changes, message in cases:
        with pytest.raises(DataError, match=r"monitor config 'm1': " + message):
            minimal(**changes).check_model(rig)


def test_malformed_dicts():
    good = minimal().to_dict()
    with pytest.raises(DataError, match=r"monitor config format must be 'cappe.monitor-config/1'; got None"):
        MonitorConfig.from_dict({k: v for k, v in good.items() if k != "format"})
    with pytest.raises(DataError, match=r"monitor config is malformed: KeyError 'machine'"):
        MonitorConfig.from_dict({k: v for k, v in good.items() if k != "machine"})
    with pytest.raises(DataError, match=r"monitor config is malformed: KeyError 'parameters'"):
        MonitorConfig.from_dict({**good, "components": [{"name": "c"}]})
    with pytest.raises(DataError, match=r"monitor config is malformed: IndexError"):
        MonitorConfig.from_dict({**good, "band": [50.0]})
    with pytest.raises(DataError, match=r"monitor config is malformed: ValueError"):
        MonitorConfig.from_dict({**good, "false_alarm_rate": "often"})
    with pytest.raises(DataError, match=r"monitor config is malformed: TypeError"):
        MonitorConfig.from_dict({**good, "severity": {"harmless": 0.1}})
    # a validation error inside is passed on as it is, not re-labelled as malformed
    with pytest.raises(DataError, match=r"^severity thresholds must satisfy 0 < tolerable < intolerable"):
        MonitorConfig.from_dict({**good, "severity_overrides": {"base": {"tolerable": 0.5, "intolerable": 0.1}}})
    with pytest.raises(DataError, match=r"^monitor config 'm1': detection must be 'cusum' or 'ewma'; got 'x'"):
        MonitorConfig.from_dict({**good, "detection": "x"})
