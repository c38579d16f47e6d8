"""A model without any damping source (no viscous or hysteretic term) has modes at its sensors like any other."""

from __future__ import annotations

import numpy as np

from cappe.modal import modal_batch
from cappe.model import StructureBuilder


def test_modes_of_an_undamped_model_at_sensors() -> None:
    b = StructureBuilder("undamped")
    b.body("m", mass=2.0, dofs=["x"])
    b.element("k", bodies=["ground", "m"], stiffness={"x": 8.0e3})
    b.sensor("s", body="m")
    batch = modal_batch(b.build(), sensors=["s"])
    # closed form: sqrt(k / m) / (2 pi), undamped
    np.testing.assert_allclose(batch.frequency, [[np.sqrt(8.0e3 / 2.0) / (2 * np.pi)]], rtol=1e-12)
    np.testing.assert_array_equal(batch.damping, [[0.0]])
