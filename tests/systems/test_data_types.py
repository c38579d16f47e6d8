"""The data types live in cappe.systems; cappe.io hands the very same objects on under their old names."""

from __future__ import annotations

import cappe.io
import cappe.io.modal
import cappe.io.timedata
import cappe.systems
import cappe.systems.modal
import cappe.systems.timedata


def test_time_data_has_one_home():
    assert cappe.systems.TimeData.__module__ == "cappe.systems.timedata"
    for name in ("TimeData", "check_clipping"):
        home = getattr(cappe.systems.timedata, name)
        assert getattr(cappe.systems, name) is home
        assert getattr(cappe.io, name) is home
        assert getattr(cappe.io.timedata, name) is home


def test_modal_data_has_one_home():
    for name in ("ModalData", "ModalDataSet"):
        home = getattr(cappe.systems.modal, name)
        assert home.__module__ == "cappe.systems.modal"
        assert getattr(cappe.systems, name) is home
        assert getattr(cappe.io, name) is home
        assert getattr(cappe.io.modal, name) is home
    assert cappe.io.MODAL_FORMAT == cappe.io.modal.MODAL_FORMAT == cappe.systems.modal.MODAL_FORMAT == "cappe.modal/1"
