"""Simulated measurements (systems.time_response) against python-control's forced response."""

from __future__ import annotations

import control
import numpy as np
import pytest

from cappe.exceptions import DataError
from cappe.io import TimeData
from cappe.model import NumericModel
from cappe.systems import time_response


@pytest.fixture(scope="module")
def rig(two_mass):
    return NumericModel(two_mass).system()


def _excitation(n=2000, fs=2000.0, seed=3):
    rng = np.random.default_rng(seed)
    return TimeData.from_rate(fs, {"F1": rng.standard_normal(n), "F2": 0.5 * rng.standard_normal(n)})


def test_matches_python_control_forced_response(rig):
    exc = _excitation()
    data = time_response(rig, exc, outputs=["d1", "d2", "a2"])
    assert data.channels == ("F1", "F2", "d1", "d2", "a2")
    assert data.units == ("N", "N", "m", "m", "m/s^2")
    # independent reference: python-control on the same continuous system, ZOH discretized by control itself
    ss = rig.state_space(["F1", "F2"], ["d1", "d2", "a2"])
    sysd = control.c2d(control.ss(ss.A, ss.B, ss.C, ss.D), exc.dt, method="zoh")
    ref = control.forced_response(sysd, T=np.arange(exc.n_samples) * exc.dt, U=exc.values).outputs
    got = data.values[2:]
    # both are exact ZOH recursions of the same model; differences are float round-off over 2000 steps
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max(axis=1, keepdims=True).max())


def test_noise_level_and_seed(rig):
    exc = _excitation(n=20000)
    clean = time_response(rig, exc, outputs=["d1"])
    noisy = time_response(rig, exc, outputs=["d1"], noise=0.01, input_noise=0.02, rng=7)
    again = time_response(rig, exc, outputs=["d1"], noise=0.01, input_noise=0.02, rng=7)
    np.testing.assert_array_equal(noisy.values, again.values)
    rel = np.std(noisy.values - clean.values, axis=1) / np.sqrt(np.mean(clean.values**2, axis=1))
    # 20000 Gaussian samples: the sample std is within ~1.5 % of the set level (5 sigma: 5 / sqrt(2 * 20000))
    np.testing.assert_allclose(rel, [0.02, 0.02, 0.01], rtol=0.03)


def test_channel_mapping(rig):
    exc = TimeData.from_rate(1000.0, {"hammer": np.r_[1.0, np.zeros(99)]})
    data = time_response(rig, exc, inputs={"hammer": "F2"}, outputs=["d2"])
    direct = time_response(rig, TimeData.from_rate(1000.0, {"F2": np.r_[1.0, np.zeros(99)]}), outputs=["d2"])
    np.testing.assert_array_equal(data.channel("d2"), direct.channel("d2"))


def test_errors(rig):
    exc = _excitation(n=10)
    with pytest.raises(DataError, match=r"channel 'F1' maps to 'F9', which is not an input of model 'two-mass-rig'"):
        time_response(rig, exc, inputs={"F1": "F9"})
    with pytest.raises(DataError, match=r"unknown channel 'Fx'; the data has \['F1', 'F2'\]"):
        time_response(rig, exc, inputs={"Fx": "F1"})
    with pytest.raises(DataError, match=r"unknown output 'd7'"):
        time_response(rig, exc, outputs=["d7"])
    with pytest.raises(DataError, match=r"noise must be a finite fraction >= 0"):
        time_response(rig, exc, noise=-0.1)
