"""A measurement the stiffness-factor fit cannot describe (issue 25, "probability 100 %" on a misfit).

The misfit is made by the test, so the truth is known without the chain: one accelerometer's FRF with its sign
flipped (a sensor mounted the other way round), which no stiffness factor can produce.
"""

from __future__ import annotations

from dataclasses import replace
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest

from cappe.model import NumericModel
from cappe.monitor import HistoryStore, Monitor, MonitorConfig, ingest, simulate_scenario


@pytest.fixture(scope="module")
def learned(spindle: NumericModel, spindle_config: MonitorConfig):
    config = spindle_config
    monitor = Monitor(config, spindle)
    healthy = simulate_scenario(config, "healthy", n=16, model=spindle, rng=11)
    baseline = monitor.learn_baseline([monitor.analyse(m.frf, modal=False) for m in healthy],
                                      conditions=[m.conditions for m in healthy])
    return monitor, healthy, baseline


def test_a_fit_that_does_not_describe_the_measurement_is_said(learned, tmp_path: Path) -> None:
    # before, the fit's failure stayed in the record's meta: the ingest's text and `monitor alarms` showed the alarm
    # alone (here "rear bearing: +7.1 %, probability 100 % (no single fault explains the change well)", the fit's
    # residual 67 times the healthy fits')
    monitor, healthy, baseline = learned
    m = simulate_scenario(monitor.config, "healthy", n=1, model=monitor.model, rng=12,
                          start=healthy[-1].timestamp + timedelta(minutes=15))[0]
    flipped = np.array(m.frf.H, copy=True)
    flipped[list(m.frf.output_names).index("hax")] *= -1.0
    with HistoryStore(tmp_path / "s.db") as store:
        store.add_machine("spindle-01", monitor.config.to_dict())
        store.set_baseline("spindle-01", baseline.to_dict())
        good = ingest(store, "spindle-01", m.frf, timestamp=m.timestamp, source="good.csv",
                      conditions=m.conditions, monitor=monitor, keep_frf=False)
        assert good.analysis.estimate.success
        assert not any("fit did not succeed" in n for n in good.notes)
        bad = ingest(store, "spindle-01", replace(m.frf, H=flipped), timestamp=m.timestamp + timedelta(minutes=1),
                     source="flipped.csv", conditions=m.conditions, monitor=monitor, keep_frf=False)
        assert not bad.analysis.estimate.success, bad.analysis.estimate.sigma / baseline.sigma
        assert any("the stiffness-factor fit did not succeed" in n and "may be wrong" in n for n in bad.notes), \
            bad.notes
        for alarm in bad.alarms:
            assert "fit did not succeed" in alarm.message
        for record in store.alarms("spindle-01"):
            assert "fit did not succeed" in record.message
