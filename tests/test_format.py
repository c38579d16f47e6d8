"""Intervals printed so that their width shows (issue 22: '[2.595e+07, 2.595e+07]' in the report and the text)."""

from __future__ import annotations

import numpy as np
import pytest

from cappe._format import interval_text


@pytest.mark.parametrize("relative_width", [1e-1, 1e-3, 2e-5, 1e-9, 1e-13])
def test_printed_ends_recover_the_interval_to_a_tenth_of_its_width(relative_width):
    rng = np.random.default_rng(7)
    for value in 10.0 ** rng.uniform(-8, 9, 20) * rng.choice([-1, 1], 20):
        lo, hi = value - abs(value) * relative_width * 0.4, value + abs(value) * relative_width * 0.6
        text = interval_text(lo, hi, value)
        a, b = (float(x) for x in text.strip("[]").split(","))
        assert a < b
        assert abs(a - lo) <= 0.1 * (hi - lo), text
        assert abs(b - hi) <= 0.1 * (hi - lo), text


def test_undetermined_and_degenerate_intervals():
    assert interval_text(np.nan, 1.0, 0.5) == "not determined"
    assert interval_text(-np.inf, np.inf, 0.5) == "not determined"
    assert interval_text(3.0, 3.0, 3.0) == "[3, 3]"
