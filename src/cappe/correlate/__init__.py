"""Correlation of model and measurement: mode-shape criteria, FRF criteria and mode pairing."""

from cappe.correlate._frf import csac, csf, frac
from cappe.correlate._modal import mac, macx, macxp, macxp_batch, macxp_paired, ndd, nfd
from cappe.correlate._pairing import ModePairing, pair_modes

__all__ = [
    "ModePairing",
    "csac",
    "csf",
    "frac",
    "mac",
    "macx",
    "macxp",
    "macxp_batch",
    "macxp_paired",
    "ndd",
    "nfd",
    "pair_modes",
]
