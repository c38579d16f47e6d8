"""UFF 58 / 55 / 15 / 2411 exchange: round trips, pyuff's and sdypy-EMA's view of cappe's files, foreign files.

Reference: pyuff decodes every file cappe writes independently of cappe's reader; "foreign" files are written here
with pyuff directly (no cappe ID lines), as modal-test software would write them.
Tolerances come from the UFF field formats: ASCII 58 ordinates E20.12 (12 significant digits, relative rounding
<= 5e-12), UFF 55 / UFF 15 / uneven ASCII abscissa E13.5 (6 significant digits, relative rounding <= 5e-6);
binary 58 and UFF 2411 (E25.16, 17 digits) are exact.
"""

from __future__ import annotations

import json
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
import pyuff
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cappe.exceptions import DataError, DataWarning
from cappe.io.modal import ModalData, ModalDataSet
from cappe.io.timedata import TimeData
from cappe.io.uff import (
    read_uff_frf,
    read_uff_modal,
    read_uff_nodes,
    read_uff_time_data,
    uff_function_types,
    write_uff_frf,
    write_uff_modal,
    write_uff_nodes,
    write_uff_time_data,
)
from cappe.model.numeric import compile_model
from cappe.systems.frf import FRFData

ASCII_RTOL = 5e-12  # E20.12: 12 significant digits
E13_RTOL = 5e-6  # E13.5: 6 significant digits


def _pyuff_sets(path):
    sets = pyuff.UFF(str(path)).read_sets()
    return sets if isinstance(sets, list) else [sets]


def _time_data(rng, fs=3000.0, t0=0.25, n=37):
    names = {"F": "N", "3:z": "m/s^2", "tool:-x": "m/s^2", 'odd "name", ä/ü': ""}
    values = {name: rng.standard_normal(n) * 10.0 ** rng.integers(-6, 4) for name in names}
    return TimeData.from_channels(t0 + np.arange(n) / fs, values, units=names)


def _frf_data(rng, freq):
    n_out, n_in = 3, 2
    H = rng.standard_normal((n_out, n_in, freq.size)) + 1j * rng.standard_normal((n_out, n_in, freq.size))
    coherence = rng.uniform(0.0, 1.0, (n_out, n_in, freq.size))
    return FRFData(
        freq=freq,
        H=H * 1e-6,
        input_names=("hammer", "2:-y"),
        output_names=("tool:x", "12:z", "base acc/1"),
        output_quantities=("acceleration", "acceleration", "elongation"),
        coherence=coherence,
        window_decay=0.123456789,
    )


# ----------------------------------------------------------------------------------------------- time data


@pytest.mark.parametrize("binary", [False, True])
def test_time_data_round_trip(tmp_path, binary):
    data = _time_data(np.random.default_rng(1))
    path = write_uff_time_data(tmp_path / "run.uff", data, binary=binary)
    back = read_uff_time_data(path)
    assert back.channels == data.channels
    assert back.units == data.units
    # the time axis is rebuilt from the exact t0 and rate in ID line 2 (the header keeps 6 digits only)
    np.testing.assert_array_equal(back.time, data.time)
    assert back.fs == 3000.0
    if binary:
        np.testing.assert_array_equal(back.values, data.values)
    else:
        np.testing.assert_allclose(back.values, data.values, rtol=ASCII_RTOL, atol=0)


def test_jittered_time_axis(tmp_path):
    """Recorder time stamps uniform to TimeData's 1e-6 rule: exact in binary, re-gridded to x0 + k * mean step in
    ASCII (not stored with the 6 digits of an uneven ASCII abscissa, which would merge samples at t ~ 1000 s)."""
    t = 1000.0 + np.arange(50) * 0.01 + np.random.default_rng(12).uniform(-2e-9, 2e-9, 50)
    data = TimeData.from_channels(t, {"a": np.arange(50.0)})
    binary = read_uff_time_data(write_uff_time_data(tmp_path / "b.uff", data, binary=True))
    np.testing.assert_array_equal(binary.time, t)
    ascii_ = read_uff_time_data(write_uff_time_data(tmp_path / "a.uff", data))
    np.testing.assert_allclose(ascii_.time, t, rtol=0, atol=4e-9)  # |jitter| <= 2e-9 s plus the mean-step error
    np.testing.assert_array_equal(ascii_.values, data.values)  # small integers are exact in E20.12


def test_pyuff_reads_cappe_time_data(tmp_path):
    data = _time_data(np.random.default_rng(2))
    path = write_uff_time_data(tmp_path / "run.uff", data, binary=True)
    sets = _pyuff_sets(path)
    assert [s["func_type"] for s in sets] == [1, 1, 1, 1]
    for s, name, row in zip(sets, data.channels, data.values, strict=True):
        np.testing.assert_array_equal(s["data"], row)  # binary: exact doubles
        # pyuff's abscissa comes from the E13.5 header: 6 digits
        np.testing.assert_allclose(s["x"], data.time, rtol=E13_RTOL, atol=0)
        assert json.loads(s["id4"]) == name
    # DOFs: '3:z' -> node 3 +z; other names are numbered after 3 in order of appearance: 'F' (a scalar
    # point, direction 0) -> 4, 'tool:-x' -> node 5, -x
    assert (sets[1]["rsp_node"], sets[1]["rsp_dir"]) == (3, 3)
    assert (sets[2]["rsp_node"], sets[2]["rsp_dir"]) == (5, -1)
    assert (sets[0]["rsp_node"], sets[0]["rsp_dir"]) == (4, 0)
    assert sets[0]["ordinate_spec_data_type"] == 13  # excitation force, from unit N
    assert sets[1]["ordinate_axis_units_lab"] == "m/s^2"


def _foreign_58(path, records, binary=0):
    """Write UFF 58 datasets as other software does: node/direction only, no cappe ID lines."""
    uff = pyuff.UFF(str(path))
    dsets = []
    for r in records:
        d = {
            "type": 58, "binary": binary, "id1": r.get("id1", "Point"), "abscissa_spacing": 1,
            "abscissa_spec_data_type": 17 if r["func_type"] == 1 else 18,
            "ordinate_spec_data_type": r.get("ord", 12), "orddenom_spec_data_type": r.get("den", 0),
        }
        d.update({k: v for k, v in r.items() if k not in ("ord", "den")})
        dsets.append(d)
    uff.write_sets(dsets, mode="add")
    return path


def test_foreign_time_data_is_named_from_nodes(tmp_path):
    t = np.arange(16) / 512.0
    rng = np.random.default_rng(3)
    rows = rng.standard_normal((4, 16))
    recs = [
        {"func_type": 1, "rsp_node": 12, "rsp_dir": 3, "ref_node": 0, "ref_dir": 0, "x": t, "data": rows[0],
         "ordinate_axis_units_lab": "g"},
        {"func_type": 1, "rsp_node": 5, "rsp_dir": -1, "ref_node": 0, "ref_dir": 0, "x": t, "data": rows[1]},
        {"func_type": 1, "rsp_node": 7, "rsp_dir": 0, "ref_node": 0, "ref_dir": 0, "x": t, "data": rows[2]},
        {"func_type": 1, "rsp_node": 12, "rsp_dir": 3, "ref_node": 1, "ref_dir": 3, "x": t, "data": rows[3]},
    ]
    path = _foreign_58(tmp_path / "foreign.uff", recs)
    back = read_uff_time_data(path)
    assert back.channels == ("12:+z", "5:-x", "7", "12:+z (dataset 4)")
    assert back.units == ("g", "", "", "")
    np.testing.assert_allclose(back.values, rows, rtol=ASCII_RTOL, atol=0)
    np.testing.assert_allclose(back.time, t, rtol=E13_RTOL, atol=0)  # 1/512 s = 1.953125e-3 needs 7 digits
    assert back.fs == pytest.approx(512.0, rel=E13_RTOL)


def test_time_axes_must_agree(tmp_path):
    t = np.arange(8) / 100.0
    recs = [
        {"func_type": 1, "rsp_node": 1, "rsp_dir": 1, "ref_node": 0, "ref_dir": 0, "x": t, "data": np.ones(8)},
        {"func_type": 1, "rsp_node": 2, "rsp_dir": 1, "ref_node": 0, "ref_dir": 0, "x": t[:6], "data": np.ones(6)},
    ]
    path = _foreign_58(tmp_path / "two.uff", recs)
    with pytest.raises(DataError, match=r"dataset #2 of .*two\.uff has a different time axis \(6 samples .* than dataset #1 \(8 samples"):
        read_uff_time_data(path)


def test_non_uniform_foreign_time_axis_names_the_file(tmp_path):
    t = np.array([0.0, 0.1, 0.2, 0.35])
    recs = [{"func_type": 1, "rsp_node": 1, "rsp_dir": 1, "ref_node": 0, "ref_dir": 0, "x": t, "data": np.ones(4),
             "abscissa_spacing": 0}]
    path = _foreign_58(tmp_path / "uneven.uff", recs)
    with pytest.raises(DataError, match=r"uneven\.uff: time stamps must be uniformly spaced"):
        read_uff_time_data(path)


# ----------------------------------------------------------------------------------------------------- FRFs


@pytest.mark.parametrize("binary", [False, True])
def test_frf_round_trip_uniform_grid(tmp_path, binary):
    freq = np.fft.rfftfreq(64, 1 / 3000.0)  # step 46.875 Hz
    frf = _frf_data(np.random.default_rng(4), freq)
    back = read_uff_frf(write_uff_frf(tmp_path / "h.uff", frf, binary=binary))
    assert (back.output_names, back.input_names) == (frf.output_names, frf.input_names)
    assert back.output_quantities == frf.output_quantities
    assert back.window_decay == frf.window_decay  # exact: repr in ID line 3
    np.testing.assert_array_equal(back.freq, freq)
    if binary:
        np.testing.assert_array_equal(back.H, frf.H)
        np.testing.assert_array_equal(back.coherence, frf.coherence)
    else:
        np.testing.assert_allclose(back.H.real, frf.H.real, rtol=ASCII_RTOL, atol=0)
        np.testing.assert_allclose(back.H.imag, frf.H.imag, rtol=ASCII_RTOL, atol=0)
        np.testing.assert_allclose(back.coherence, frf.coherence, rtol=ASCII_RTOL, atol=0)


def test_frf_uneven_grid_exact_in_binary_six_digits_in_ascii(tmp_path):
    # neither even nor log-spaced: lines from a log grid moved by up to 10 % of their step
    rng = np.random.default_rng(5)
    freq = np.geomspace(1.0, 1000.0, 40) * (1 + 0.01 * rng.uniform(-1, 1, 40))
    frf = _frf_data(rng, freq)
    binary = read_uff_frf(write_uff_frf(tmp_path / "b.uff", frf, binary=True))
    np.testing.assert_array_equal(binary.freq, freq)
    np.testing.assert_array_equal(binary.H, frf.H)
    ascii_ = read_uff_frf(write_uff_frf(tmp_path / "a.uff", frf))
    np.testing.assert_allclose(ascii_.freq, freq, rtol=E13_RTOL, atol=0)  # documented loss: E13.5 abscissa
    assert not np.array_equal(ascii_.freq, freq)


def test_model_frf_round_trip(tmp_path, two_mass):
    system = compile_model(two_mass).system()
    frf = system.frf(np.linspace(0.0, 250.0, 126), ["F1", "F2"], ["d1", "d2"])
    back = read_uff_frf(write_uff_frf(tmp_path / "model.uff", frf, binary=True))
    np.testing.assert_array_equal(back.H, frf.H)
    assert back.output_quantities == ("displacement", "displacement")
    assert back.coherence is None
    assert back.window_decay is None


def test_pyuff_and_sdypy_read_cappe_frfs(tmp_path):
    from sdypy.EMA import Model

    freq = np.linspace(10.0, 500.0, 50)
    frf = _frf_data(np.random.default_rng(6), freq)
    frf = FRFData(freq, frf.H, frf.input_names, frf.output_names, ("acceleration",) * 3, frf.coherence)
    path = write_uff_frf(tmp_path / "h.uff", frf, binary=True)
    sets = _pyuff_sets(path)
    assert [s["func_type"] for s in sets] == [4] * 6 + [6] * 6
    for s, (o, i) in zip(sets[:6], np.ndindex(3, 2), strict=True):
        np.testing.assert_array_equal(s["data"], frf.H[o, i])
        assert (json.loads(s["id4"]), json.loads(s["id5"])) == (frf.output_names[o], frf.input_names[i])
        assert s["ordinate_spec_data_type"] == 12
        assert s["orddenom_spec_data_type"] == 13
    for s, (o, i) in zip(sets[6:], np.ndindex(3, 2), strict=True):
        np.testing.assert_array_equal(s["data"], frf.coherence[o, i])
    # reference = input, response = output: '2:-y' is node 2, direction -2; '12:z' is node 12, +3
    assert (sets[3]["ref_node"], sets[3]["ref_dir"], sets[3]["rsp_node"], sets[3]["rsp_dir"]) == (2, -2, 12, 3)

    model = Model(lower=10.0, upper=400.0, pol_order_high=10)
    model.read_uff(str(path))
    assert model.frf_form == "accelerance"  # from the ordinate data type 12
    n = model.freq.size  # sdypy cuts at the bin closest to `upper`
    np.testing.assert_array_equal(model.freq, freq[:n])
    np.testing.assert_array_equal(model.frf, frf.H.reshape(6, -1)[:, :n])


def test_foreign_frfs_with_multiple_coherence(tmp_path):
    freq = np.linspace(0.0, 200.0, 21)
    rng = np.random.default_rng(7)
    H = rng.standard_normal((2, 2, 21)) + 1j * rng.standard_normal((2, 2, 21))
    coh = rng.uniform(0, 1, (2, 21))
    outs, ins = [(10, 3), (11, -2)], [(1, -1), (2, 3)]
    recs = [
        {"func_type": 4, "rsp_node": on, "rsp_dir": od, "ref_node": inn, "ref_dir": ind, "x": freq,
         "data": H[o, i], "ord": 11, "den": 13}
        for o, (on, od) in enumerate(outs) for i, (inn, ind) in enumerate(ins)
    ]
    recs += [
        {"func_type": 6, "rsp_node": on, "rsp_dir": od, "ref_node": 0, "ref_dir": 0, "x": freq, "data": coh[o],
         "id1": "MULTICOH"}
        for o, (on, od) in enumerate(outs)
    ]
    path = _foreign_58(tmp_path / "foreign.uff", recs)
    # pyuff cannot write function type 26; turn the coherence records into multiple coherence by hand
    lines = path.read_text().splitlines(keepends=True)
    for k, line in enumerate(lines):
        if line.startswith("MULTICOH"):
            assert lines[k + 5].startswith("    6")
            lines[k + 5] = "   26" + lines[k + 5][5:]
    path.write_text("".join(lines))

    back = read_uff_frf(path)
    assert back.output_names == ("10:+z", "11:-y")
    assert back.input_names == ("1:-x", "2:+z")
    assert back.output_quantities == ("velocity", "velocity")
    assert back.window_decay is None
    np.testing.assert_allclose(back.H.real, H.real, rtol=ASCII_RTOL, atol=0)
    np.testing.assert_allclose(back.H.imag, H.imag, rtol=ASCII_RTOL, atol=0)
    # a multiple coherence belongs to its output and applies to every input
    np.testing.assert_allclose(back.coherence, np.repeat(coh[:, None, :], 2, axis=1), rtol=ASCII_RTOL, atol=0)
    assert uff_function_types(path) == [4, 4, 4, 4, 26, 26]


def test_frf_grid_and_duplicate_errors(tmp_path):
    freq = np.linspace(0.0, 10.0, 5)
    rec = {"func_type": 4, "rsp_node": 1, "rsp_dir": 1, "ref_node": 9, "ref_dir": 1, "x": freq, "data": np.ones(5) + 0j}
    incomplete = _foreign_58(tmp_path / "grid.uff", [rec, {**rec, "rsp_node": 2, "ref_node": 8}])
    with pytest.raises(DataError, match=r"grid\.uff lacks the FRF\(s\) \['1:\+x/8:\+x', '2:\+x/9:\+x'\] to complete the 2 x 2"):
        read_uff_frf(incomplete)
    twice = _foreign_58(tmp_path / "twice.uff", [rec, rec])
    with pytest.raises(DataError, match=r"datasets #1 and #2 of .*twice\.uff both hold the FRF '1:\+x'/'9:\+x'"):
        read_uff_frf(twice)
    axis = _foreign_58(tmp_path / "axis.uff", [rec, {**rec, "rsp_node": 2, "x": freq * 2}])
    with pytest.raises(DataError, match=r"dataset #2 of .*axis\.uff has a different frequency axis"):
        read_uff_frf(axis)
    coh = _foreign_58(tmp_path / "coh.uff", [rec, {**rec, "func_type": 6, "rsp_node": 5, "data": np.ones(5)}])
    with pytest.raises(DataError, match=r"dataset #2 of .*coh\.uff holds coherence for '5:\+x'/'9:\+x', which has no FRF"):
        read_uff_frf(coh)
    part = _foreign_58(tmp_path / "part.uff", [rec, {**rec, "rsp_node": 2},
                                               {**rec, "func_type": 6, "data": np.ones(5)}])
    with pytest.raises(DataError, match=r"part\.uff has coherence for some FRFs but not for \['2:\+x/9:\+x'\]"):
        read_uff_frf(part)
    clash = _foreign_58(tmp_path / "clash.uff", [rec, *[{**rec, "func_type": 6, "data": np.ones(5)}] * 2])
    with pytest.raises(DataError, match=r"datasets #2 and #3 of .*clash\.uff both hold coherence for '1:\+x'/'9:\+x'"):
        read_uff_frf(clash)


def test_frf_write_validation(tmp_path):
    freq = np.array([1.0, 2.0])
    good = FRFData(freq, np.ones((1, 1, 2), complex), ("F",), ("a",))
    with pytest.raises(DataError, match=r"UFF 58 needs at least 2 frequency points; got 1"):
        write_uff_frf(tmp_path / "x.uff", FRFData(freq[:1], np.ones((1, 1, 1), complex), ("F",), ("a",)))
    with pytest.raises(DataError, match=r"FRF H must have shape \(n_out, n_in, n_freq\) = \(1, 1, 2\); got \(1, 2, 2\)"):
        write_uff_frf(tmp_path / "x.uff", FRFData(freq, np.ones((1, 2, 2), complex), ("F",), ("a",)))
    nan = np.ones((1, 1, 2), complex)
    nan[0, 0, 1] = np.nan
    with pytest.raises(DataError, match=r"FRF 'a'/'F' has 1 non-finite value\(s\), first at 2 Hz"):
        write_uff_frf(tmp_path / "x.uff", FRFData(freq, nan, ("F",), ("a",)))
    with pytest.raises(DataError, match=r"FRF input names must be unique; repeated: \['F'\]"):
        write_uff_frf(tmp_path / "x.uff", FRFData(freq, np.ones((1, 2, 2), complex), ("F", "F"), ("a",)))
    with pytest.raises(DataError, match=r"output_quantities must list one quantity per output \(1\); got 2"):
        write_uff_frf(tmp_path / "x.uff", FRFData(freq, good.H, ("F",), ("a",), ("velocity", "velocity")))
    with pytest.raises(DataError, match=r"coherence must be a finite real array of shape \(1, 1, 2\); got shape \(2,\)"):
        write_uff_frf(tmp_path / "x.uff", FRFData(freq, good.H, ("F",), ("a",), coherence=np.ones(2)))
    with pytest.raises(DataError, match=r"window_decay must be None or a time constant > 0 in s; got -1.0"):
        write_uff_frf(tmp_path / "x.uff", FRFData(freq, good.H, ("F",), ("a",), window_decay=-1.0))
    with pytest.raises(DataError, match=r"output quantity 'linear velocity' of 'a' must be one word"):
        write_uff_frf(tmp_path / "x.uff", FRFData(freq, good.H, ("F",), ("a",), ("linear velocity",)))
    with pytest.raises(DataError, match=r"frf must be an FRFData; got dict"):
        write_uff_frf(tmp_path / "x.uff", {})  # type: ignore[arg-type]
    with pytest.raises(DataError, match=r"input name 'x{90}' is too long for a UFF ID line: at most 80 characters after JSON quoting; got 92"):
        write_uff_frf(tmp_path / "x.uff", FRFData(freq, good.H, ("x" * 90,), ("a",)))
    assert not (tmp_path / "x.uff").exists()
    assert list(tmp_path.iterdir()) == []  # no temporary files left behind


# --------------------------------------------------------------------------------------------- modal data


def _modal(rng, complex_shapes=True):
    sensors = ("tool:x", "tool:y", "3:-z", "top:z", "3:x")
    sets = []
    for z in (0.1, -0.294):
        m = 3
        shapes = rng.standard_normal((5, m)) + (1j * rng.standard_normal((5, m)) if complex_shapes else 0)
        sets.append(ModalDataSet({"z": z, "x": 0.5}, np.sort(rng.uniform(20, 900, m)), rng.uniform(0, 0.2, m), shapes))
    return ModalData(sensors, tuple(sets))


def _assert_modal_equal(back, modal):
    assert back.sensors == modal.sensors
    assert len(back.sets) == len(modal.sets)
    for b, s in zip(back.sets, modal.sets, strict=True):
        assert b.position == s.position
        np.testing.assert_array_equal(b.frequency, s.frequency)  # exact: ID line 5
        np.testing.assert_array_equal(b.damping, s.damping)
        np.testing.assert_allclose(b.shapes.real, s.shapes.real, rtol=E13_RTOL, atol=0)
        np.testing.assert_allclose(b.shapes.imag, s.shapes.imag, rtol=E13_RTOL, atol=0)


@pytest.mark.parametrize("complex_shapes", [True, False])
def test_modal_round_trip_with_positions_and_coordinates(tmp_path, complex_shapes):
    modal = _modal(np.random.default_rng(8), complex_shapes)
    coords = {"tool": (0.0, 0.1, 1 / 3), "3": (1e-7, -2.0, 0.0), "top": (0.2, 0.2, 0.1), 40: (5.0, 5.0, 5.0)}
    path = write_uff_modal(tmp_path / "m.uff", modal, coordinates=coords)
    _assert_modal_equal(read_uff_modal(path), modal)
    nodes = read_uff_nodes(path)
    assert nodes == {"tool": (0.0, 0.1, 1 / 3), "3": (1e-7, -2.0, 0.0), "top": (0.2, 0.2, 0.1), "40": (5.0, 5.0, 5.0)}


def test_pyuff_reads_cappe_modal_data(tmp_path):
    modal = _modal(np.random.default_rng(9))
    path = write_uff_modal(tmp_path / "m.uff", modal, coordinates={"tool": (0.0, 0.0, 1.0)})
    sets = _pyuff_sets(path)
    assert [s["type"] for s in sets] == [2467, 2411] + [55] * 6
    # nodes: '3' keeps its number; 'tool' and 'top' follow it in order of first appearance
    groups = {g["group_name"]: int(g["entity_tag"][0]) for g in sets[0]["groups"]}
    assert groups == {"sensor tool:x": 4, "sensor tool:y": 4, "sensor 3:-z": 3, "sensor top:z": 5, "sensor 3:x": 3}
    assert list(sets[1]["node_nums"]) == [4]
    for k, s in enumerate(sets[2:]):
        ref = modal.sets[k // 3]
        j = k % 3
        assert (s["analysis_type"], s["load_case"], s["mode_n"]) == (3, k // 3 + 1, j + 1)
        w = 2 * np.pi * ref.frequency[j]
        pole = -ref.damping[j] * w + 1j * w * np.sqrt(1 - ref.damping[j] ** 2)
        np.testing.assert_allclose(s["eig"], pole, rtol=E13_RTOL)
        assert list(s["node_nums"]) == [4, 3, 5]
        expected = np.zeros((3, 3), complex)  # slots x, y, z by node 4, 3, 5
        expected[0, 0], expected[1, 0], expected[2, 1] = ref.shapes[0, j], ref.shapes[1, j], -ref.shapes[2, j]
        expected[2, 2], expected[0, 1] = ref.shapes[3, j], ref.shapes[4, j]
        got = np.array([s["r1"], s["r2"], s["r3"]])
        np.testing.assert_allclose(got.real, expected.real, rtol=E13_RTOL, atol=0)
        np.testing.assert_allclose(got.imag, expected.imag, rtol=E13_RTOL, atol=0)


def test_real_shapes_with_rotations_use_normal_modes(tmp_path):
    rng = np.random.default_rng(10)
    s = ModalDataSet({}, np.array([15.0, 80.0]), np.array([0.0, 0.05]), rng.standard_normal((3, 2)).astype(complex))
    modal = ModalData(("1:x", "1:ry", "2:rz"), (s,))
    path = write_uff_modal(tmp_path / "rot.uff", modal)
    sets = _pyuff_sets(path)
    assert [(d["analysis_type"], d["data_ch"], d["n_data_per_node"]) for d in sets[1:]] == [(2, 3, 6)] * 2
    np.testing.assert_allclose([d["modal_damp_vis"] for d in sets[1:]], [0.0, 0.05], rtol=E13_RTOL)
    np.testing.assert_allclose(sets[1]["r5"], [s.shapes[1, 0].real, 0.0], rtol=E13_RTOL)
    _assert_modal_equal(read_uff_modal(path), modal)


def test_model_modes_round_trip(tmp_path, two_mass):
    modes = compile_model(two_mass).system().modes()
    modal = ModalData(("1:x", "2:x"), (ModalDataSet({}, modes.frequency, modes.damping, modes.shapes),))
    _assert_modal_equal(read_uff_modal(write_uff_modal(tmp_path / "rig.unv", modal)), modal)


def _foreign_55(path, modes, nodes, analysis_type=3, load_cases=None):
    datasets = [pyuff.prepare_15(node_nums=list(nodes), x=[0.0] * len(nodes), y=[1.0] * len(nodes),
                                 z=[0.5] * len(nodes))]
    for j, (value, r) in enumerate(modes):
        d = {"type": 55, "analysis_type": analysis_type, "data_ch": 2, "spec_data_type": 8,
             "load_case": (load_cases or [1] * len(modes))[j], "mode_n": j + 1, "node_nums": np.array(nodes),
             "r1": r[0], "r2": r[1], "r3": r[2]}
        if analysis_type == 3:
            d["eig"] = value
        else:
            d.update(freq=value[0], modal_damp_vis=value[1])
        datasets.append(d)
    pyuff.UFF(str(path)).write_sets(datasets, mode="add")
    return path


def test_foreign_complex_modes(tmp_path):
    rng = np.random.default_rng(11)
    w, zeta = 2 * np.pi * np.array([31.5, 77.0]), np.array([0.02, 0.1])
    eig = -zeta * w + 1j * w * np.sqrt(1 - zeta**2)
    shapes = [rng.standard_normal((3, 2)) + 1j * rng.standard_normal((3, 2)) for _ in range(2)]
    for sh in shapes:
        sh[1] = 0.0  # y not measured: all zero, as UFF asks for unused DOFs
    # the second mode is given by its conjugate (eigenvalue below the real axis, conjugate shape)
    path = _foreign_55(tmp_path / "f.uff", [(eig[0], shapes[0]), (eig[1].conj(), shapes[1].conj())], [101, 7],
                       load_cases=[1, 1])
    back = read_uff_modal(path)
    assert back.sensors == ("101:x", "101:z", "7:x", "7:z")
    (s,) = back.sets
    assert s.position == {}
    np.testing.assert_allclose(s.frequency, [31.5, 77.0], rtol=E13_RTOL)
    np.testing.assert_allclose(s.damping, zeta, rtol=2 * E13_RTOL)  # zeta = -Re/|eig|: two rounded values
    for j in range(2):
        expected = shapes[j][[0, 2]].T.reshape(-1)  # node 101 x z, node 7 x z
        np.testing.assert_allclose(s.shapes[:, j].real, expected.real, rtol=E13_RTOL, atol=0)
        np.testing.assert_allclose(s.shapes[:, j].imag, expected.imag, rtol=E13_RTOL, atol=0)
    assert read_uff_nodes(path) == {101: (0.0, 1.0, 0.5), 7: (0.0, 1.0, 0.5)}


def test_foreign_normal_modes_in_two_load_cases(tmp_path):
    r = [np.array([1.0, 0.5]), np.array([0.0, 0.0]), np.array([0.25, -1.0])]
    path = _foreign_55(tmp_path / "n.uff", [((10.0, 0.01), r), ((20.0, 0.02), r), ((11.0, 0.03), r)], [1, 2],
                       analysis_type=2, load_cases=[1, 1, 2])
    back = read_uff_modal(path)
    assert [list(s.frequency) for s in back.sets] == [[10.0, 20.0], [11.0]]
    assert [list(s.damping) for s in back.sets] == [[0.01, 0.02], [0.03]]
    assert back.sensors == ("1:x", "1:z", "2:x", "2:z")
    np.testing.assert_array_equal(back.sets[1].shapes[:, 0], [1.0, 0.25, 0.5, -1.0])


def test_stale_id_line_falls_back_to_the_record(tmp_path):
    s = ModalDataSet({}, np.array([50.0]), np.array([0.01]), np.array([[1.0 + 0j]]))
    path = write_uff_modal(tmp_path / "m.uff", ModalData(("1:z",), (s,)))
    path.write_text(path.read_text().replace("freq=50.0 ", "freq=55.0 "))
    with pytest.warns(DataWarning, match=r"dataset #2 of .*m\.uff: ID line 5 \('freq=55.0 zeta=0.01'\) disagrees with the mode record \(50 Hz"):
        back = read_uff_modal(path)
    assert back.sets[0].frequency[0] == pytest.approx(50.0, rel=E13_RTOL)


def test_stale_abscissa_id_line_warns(tmp_path):
    data = TimeData.from_rate(100.0, {"a": [1.0, 2.0, 3.0]})
    path = write_uff_time_data(tmp_path / "t.uff", data)
    path.write_text(path.read_text().replace("dx=0.01", "dx=0.02"))
    with pytest.warns(DataWarning, match=r"dataset #1 of .*t\.uff: ID line 2 .* disagrees with the abscissa header"):
        back = read_uff_time_data(path)
    assert back.fs == pytest.approx(100.0, rel=E13_RTOL)


def test_modal_write_errors(tmp_path):
    one = ModalDataSet({}, np.array([10.0]), np.array([0.01]), np.array([[1.0 + 1j]]))
    with pytest.raises(DataError, match=r"sensor 'acc1' must be 'node:direction' with direction x, y, z, rx, ry or rz"):
        write_uff_modal(tmp_path / "m.uff", ModalData(("acc1",), (one,)))
    two = ModalDataSet({}, np.array([10.0]), np.array([0.01]), np.array([[1.0 + 1j], [2.0]]))
    with pytest.raises(DataError, match=r"sensors '3:z' and '3:-z' measure the same UFF degree of freedom"):
        write_uff_modal(tmp_path / "m.uff", ModalData(("3:z", "3:-z"), (two,)))
    with pytest.raises(DataError, match=r"complex mode shapes with rotational sensors \(e.g. '3:rx'\) cannot be written"):
        write_uff_modal(tmp_path / "m.uff", ModalData(("3:z", "3:rx"), (two,)))
    long_name = "n" * 40
    with pytest.raises(DataError, match=r"sensor name 'n{40}:z' cannot be stored in a UFF 2467 group name"):
        write_uff_modal(tmp_path / "m.uff", ModalData((f"{long_name}:z",), (one,)))
    with pytest.raises(DataError, match=r"sensor name 'a   b:z' cannot be stored .* without leading, trailing or repeated blanks"):
        write_uff_modal(tmp_path / "m.uff", ModalData(("a   b:z",), (one,)))
    with pytest.raises(DataError, match=r"modal data has no sets"):
        write_uff_modal(tmp_path / "m.uff", ModalData(("1:z",), ()))
    empty = ModalDataSet({}, np.array([]), np.array([]), np.zeros((1, 0), complex))
    with pytest.raises(DataError, match=r"set 0 of the modal data has no modes"):
        write_uff_modal(tmp_path / "m.uff", ModalData(("1:z",), (empty,)))
    with pytest.raises(DataError, match=r"set 0: shapes must have shape \(n_sensors, n_modes\) = \(2, 1\)"):
        write_uff_modal(tmp_path / "m.uff", ModalData(("1:z", "2:z"), (one,)))
    bad = ModalDataSet({}, np.array([np.nan]), np.array([0.01]), np.array([[1.0 + 0j]]))
    with pytest.raises(DataError, match=r"set 0 of the modal data holds NaN or Inf"):
        write_uff_modal(tmp_path / "m.uff", ModalData(("1:z",), (bad,)))
    negative = ModalDataSet({}, np.array([10.0]), np.array([-0.01]), np.array([[1.0 + 0j]]))
    with pytest.raises(DataError, match=r"set 0: frequencies must be > 0 Hz and damping ratios in \[0, 1\); got \[10.\] Hz and \[-0.01\]"):
        write_uff_modal(tmp_path / "m.uff", ModalData(("1:z",), (negative,)))
    spaced = ModalDataSet({"axis z": 0.1}, np.array([10.0]), np.array([0.01]), np.array([[1.0 + 0j]]))
    with pytest.raises(DataError, match=r"axis name 'axis z' in set 0 must be one word without '='"):
        write_uff_modal(tmp_path / "m.uff", ModalData(("1:z",), (spaced,)))
    many = ModalDataSet({f"axis{k}": 1 / 3 for k in range(5)}, np.array([10.0]), np.array([0.01]), np.array([[1.0 + 0j]]))
    with pytest.raises(DataError, match=r"the position of set 0 \(axis0=0.3333333333333333 .*\) does not fit UFF ID line 4"):
        write_uff_modal(tmp_path / "m.uff", ModalData(("1:z",), (many,)))
    with pytest.raises(DataError, match=r"coordinates name the same node twice"):
        write_uff_modal(tmp_path / "m.uff", ModalData(("1:z",), (one,)), coordinates={1: (0, 0, 0), "1": (0, 0, 0)})
    with pytest.raises(DataError, match=r"modal must be a ModalData; got list"):
        write_uff_modal(tmp_path / "m.uff", [])  # type: ignore[arg-type]
    assert list(tmp_path.iterdir()) == []


def test_modal_read_errors(tmp_path):
    r = [np.array([1.0, 0.5]), np.array([0.0, 0.0]), np.array([0.25, -1.0])]
    path = _foreign_55(tmp_path / "f.uff", [((10.0, 0.01), r)], [1, 2], analysis_type=2)
    pyuff.UFF(str(path)).write_sets(
        {"type": 55, "analysis_type": 2, "data_ch": 2, "spec_data_type": 8, "load_case": 1, "mode_n": 2,
         "freq": 20.0, "node_nums": np.array([1, 3]), "r1": r[0], "r2": r[1], "r3": r[2]}, mode="add")
    with pytest.raises(DataError, match=r"dataset #3 of .*f\.uff lists other nodes or values per node than dataset #2"):
        read_uff_modal(path)
    response = tmp_path / "fr.uff"
    pyuff.UFF(str(response)).write_sets(
        {"type": 55, "analysis_type": 5, "data_ch": 2, "spec_data_type": 8, "load_case": 1, "freq_step_n": 1,
         "freq": 20.0, "node_nums": np.array([1]), "r1": [1.0], "r2": [0.0], "r3": [0.0]}, mode="add")
    with pytest.raises(DataError, match=r"fr\.uff holds no mode shapes \(UFF 55 analysis type 2, 3 or 7, or UFF 2414 normal modes at nodes\); found UFF 55 \(UFF 55/2414 analysis types \[5\]\)"):
        read_uff_modal(response)
    negative = _foreign_55(tmp_path / "neg.uff", [((10.0, -0.01), r)], [1, 2], analysis_type=2)
    with pytest.raises(DataError, match=r"dataset #2 of .*neg\.uff: mode 1 of load case 1 must have a frequency > 0 Hz and a damping ratio in \[0, 1\); got 10 Hz and -0.01"):
        read_uff_modal(negative)


# -------------------------------------------------------------------------------------------------- nodes


@pytest.mark.parametrize(("dataset", "rtol"), [(2411, 0.0), (15, E13_RTOL)])
def test_nodes_round_trip(tmp_path, dataset, rtol):
    coords = {"base": (0.1, -0.2, 1 / 3), 5: (1.0, 2.0, 3.0), "12": (0.0, 0.0, 1e-9), "spindle nose": (4.0, 5.0, 6.0)}
    path = write_uff_nodes(tmp_path / "geo.uff", coords, dataset=dataset)
    back = read_uff_nodes(path)
    assert list(back) == list(coords)  # names come back as str, numbers as int, in file order
    for key, xyz in coords.items():
        np.testing.assert_allclose(back[key], xyz, rtol=rtol, atol=0)
    sets = _pyuff_sets(path)
    assert [g["group_name"] for g in sets[0]["groups"]] == ["node base", "node 12", "node spindle nose"]
    assert list(sets[1]["node_nums"]) == [13, 5, 12, 14]  # '12' keeps 12; other names follow the largest number


def test_node_errors(tmp_path):
    with pytest.raises(DataError, match=r"node keys '3' \(name\) and 3 \(number\) both map to node 3"):
        write_uff_nodes(tmp_path / "n.uff", {3: (0, 0, 0), "3": (0, 0, 0)})
    with pytest.raises(DataError, match=r"node numbers must be positive integers of at most 9 digits; got 0"):
        write_uff_nodes(tmp_path / "n.uff", {0: (0, 0, 0)})
    with pytest.raises(DataError, match=r"coordinates of node 'a' must be three finite numbers \(x, y, z\) in m; got \(0, 0\)"):
        write_uff_nodes(tmp_path / "n.uff", {"a": (0, 0)})
    with pytest.raises(DataError, match=r"coordinates of node 'a' must be three numbers \(x, y, z\) in m; got 'xyz'"):
        write_uff_nodes(tmp_path / "n.uff", {"a": "xyz"})
    with pytest.raises(DataError, match=r"node keys must be names \(str\) or node numbers \(int\); got 1.5"):
        write_uff_nodes(tmp_path / "n.uff", {1.5: (0, 0, 0)})
    with pytest.raises(DataError, match=r"node dataset must be 15 \(single precision\) or 2411 \(double precision\); got 18"):
        write_uff_nodes(tmp_path / "n.uff", {1: (0, 0, 0)}, dataset=18)
    assert list(tmp_path.iterdir()) == []
    twice = tmp_path / "twice.uff"
    pyuff.UFF(str(twice)).write_sets([pyuff.prepare_15(node_nums=[1], x=[0.0], y=[0.0], z=[0.0])] * 2, mode="add")
    with pytest.raises(DataError, match=r"node 1 is defined twice in .*twice\.uff \(datasets #1 and #2\)"):
        read_uff_nodes(twice)


# ------------------------------------------------------------------------------------- file-level errors


def test_unsupported_and_missing_files(tmp_path):
    header = tmp_path / "header.uff"
    pyuff.UFF(str(header)).write_sets(
        [pyuff.prepare_164(units_code=1, units_description="SI", temp_mode=1, length=1.0, force=1.0,
                           temp=1.0, temp_offset=273.15)], mode="add")
    for reader in (read_uff_time_data, read_uff_frf):
        with pytest.raises(DataError, match=r"header\.uff holds no (time data|FRFs) .*; found UFF 164"):
            reader(header)
    with pytest.raises(DataError, match=r"header\.uff holds no mode shapes .*; found UFF 164; supported: UFF 58 function type 1"):
        read_uff_modal(header)
    with pytest.raises(DataError, match=r"header\.uff holds no node coordinates \(UFF 15 or 2411\); found UFF 164"):
        read_uff_nodes(header)
    with pytest.raises(DataError, match=r"header\.uff holds no time or FRF data; found UFF 164; supported:"):
        uff_function_types(header)
    spectrum = _foreign_58(tmp_path / "psd.uff", [
        {"func_type": 2, "rsp_node": 1, "rsp_dir": 1, "ref_node": 1, "ref_dir": 1, "x": np.arange(4.0),
         "data": np.ones(4)}])
    with pytest.raises(DataError, match=r"psd\.uff holds no FRFs \(UFF 58 function type 4\); found UFF 58 function type 2 \(auto spectrum\)"):
        read_uff_frf(spectrum)
    with pytest.raises(DataError, match=r"cannot read UFF file .*nothere\.uff: no such file"):
        read_uff_frf(tmp_path / "nothere.uff")
    empty = tmp_path / "empty.uff"
    empty.write_text("")
    with pytest.raises(DataError, match=r"empty\.uff holds no UFF datasets \(blocks between '    -1' lines\)"):
        read_uff_time_data(empty)
    broken = tmp_path / "broken.uff"
    broken.write_text("    -1\n    58\nonly two lines\n    -1\n")
    with pytest.raises(DataError, match=r"cannot decode dataset #1 \(UFF 58\) of .*broken\.uff"):
        read_uff_frf(broken)


def test_failed_write_keeps_the_old_file(tmp_path, monkeypatch):
    path = tmp_path / "run.uff"
    path.write_text("old content\n")
    data = TimeData.from_rate(10.0, {"a": [1.0, 2.0]})

    def half_write(self, dsets, mode="add", force_double=True):
        with open(self._filename, "a") as fh:
            fh.write("    -1\n    58\npartial")
        msg = "disk full"
        raise RuntimeError(msg)

    monkeypatch.setattr(pyuff.UFF, "write_sets", half_write)
    with pytest.raises(DataError, match=r"cannot write UFF file .*run\.uff: disk full"):
        write_uff_time_data(path, data)
    assert path.read_text() == "old content\n"
    assert [p.name for p in tmp_path.iterdir()] == ["run.uff"]


@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])  # too_slow: wall clock
@given(
    names=st.lists(st.text(min_size=1, max_size=20).filter(lambda s: len(json.dumps(s)) <= 80), min_size=1, max_size=4, unique=True),
    values=st.lists(st.floats(allow_nan=False, allow_infinity=False, width=64), min_size=2, max_size=12),
    binary=st.booleans(),
)
def test_property_channel_names_round_trip(tmp_path, names, values, binary):
    """Any channel names (unicode, blanks, quotes, control characters) and any doubles come back exactly (binary)."""
    data = TimeData.from_rate(256.0, {name: np.roll(values, k) for k, name in enumerate(names)})
    path = Path(tmp_path) / "p.uff"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        back = read_uff_time_data(write_uff_time_data(path, data, binary=binary))
    assert back.channels == data.channels
    np.testing.assert_array_equal(back.time, data.time)
    if binary:
        np.testing.assert_array_equal(back.values, data.values)
    else:  # E20.12 keeps 12 significant digits; values near the double range limits round to +-inf/0 otherwise
        finite = np.abs(data.values) < 1e300
        np.testing.assert_allclose(back.values[finite], data.values[finite], rtol=ASCII_RTOL, atol=1e-300)


# ------------------------------------------------------------------------------------------- files cut short


def _as_values(result):
    """What a reader returned, as comparable plain values (arrays as lists)."""
    if isinstance(result, TimeData):
        return ("time", result.channels, result.units, result.time.tolist(), result.values.tolist())
    if isinstance(result, FRFData):
        coherence = None if result.coherence is None else result.coherence.tolist()
        return ("frf", result.input_names, result.output_names, result.output_quantities, result.window_decay,
                result.freq.tolist(), result.H.tolist(), coherence)
    if isinstance(result, ModalData):
        return ("modal", result.sensors, [(s.position, s.frequency.tolist(), s.damping.tolist(), s.shapes.tolist())
                                          for s in result.sets])
    return result  # nodes: a dict, function types: a list


def _frf_then(path, dataset):
    """A small foreign FRF file (pyuff) with one more dataset of another type at its end."""
    _foreign_58(path, [{"func_type": 4, "rsp_node": 2, "rsp_dir": 3, "ref_node": 1, "ref_dir": 3,
                        "x": np.linspace(0.0, 70.0, 8), "data": np.arange(8.0) * (1 - 2j)}])
    pyuff.UFF(str(path)).write_sets([dataset], mode="add")
    return path


_GROUP = {"group_number": 1, "group_name": "node base", "entity_type_code": np.array([7]),
          "entity_tag": np.array([3]), "entity_node_leaf_id": np.array([0]), "entity_component_id": np.array([0]),
          **dict.fromkeys(("active_constraint_set_no_for_group", "active_restraint_set_no_for_group",
                           "active_load_set_no_for_group", "active_dof_set_no_for_group",
                           "active_temperature_set_no_for_group", "active_contact_set_no_for_group"), 0)}

# name: (write the file at a path, read it); every last dataset type cappe's readers meet, written by cappe's
# writers and, as an independent reference, by pyuff directly
CUT_FILES = {
    "time 58": (lambda p: write_uff_time_data(p, _time_data(np.random.default_rng(1), n=9)), read_uff_time_data),
    "time 58b": (lambda p: write_uff_time_data(p, _time_data(np.random.default_rng(1), n=9), binary=True),
                 read_uff_time_data),
    "frf 58 with coherence": (lambda p: write_uff_frf(p, _frf_data(np.random.default_rng(2), np.linspace(0, 90, 7))),
                              read_uff_frf),
    "frf 58b": (lambda p: write_uff_frf(p, _frf_data(np.random.default_rng(2), np.linspace(0, 90, 7)), binary=True),
                read_uff_frf),
    "function types 58": (lambda p: write_uff_frf(p, _frf_data(np.random.default_rng(2), np.linspace(0, 90, 7))),
                          uff_function_types),
    "modal 55 after 2411": (lambda p: write_uff_modal(p, _modal(np.random.default_rng(3)),
                                                      coordinates={"tool": (0, 0, 0.1), "base": (1, 2, 3)}),
                            read_uff_modal),
    "modal 55 real after 15": (lambda p: write_uff_modal(p, _modal(np.random.default_rng(3), complex_shapes=False),
                                                         coordinates={"tool": (0, 0, 0.1)}, node_dataset=15),
                               read_uff_modal),
    "nodes 2411 after 2467": (lambda p: write_uff_nodes(p, {"base": (0.1, -0.2, 1 / 3), 5: (1.0, 2.0, 3.0)}),
                              read_uff_nodes),
    "nodes 15 after 2467": (lambda p: write_uff_nodes(p, {"base": (0.1, -0.2, 0.3), 5: (1.0, 2.0, 3.0)},
                                                      dataset=15), read_uff_nodes),
    "nodes 2411 only": (lambda p: write_uff_nodes(p, {5: (1.0, 2.0, 3.0)}), read_uff_nodes),
    "pyuff time 58": (lambda p: _foreign_58(p, [
        {"func_type": 1, "rsp_node": n, "rsp_dir": 3, "ref_node": 0, "ref_dir": 0, "x": np.arange(6) / 100.0,
         "data": np.arange(6.0) * n} for n in (1, 2)]), read_uff_time_data),
    "pyuff frf 58b": (lambda p: _foreign_58(p, [
        {"func_type": 4, "rsp_node": n, "rsp_dir": 3, "ref_node": 1, "ref_dir": 3, "x": np.linspace(0.0, 70.0, 8),
         "data": np.arange(8.0) * (n - 2j)} for n in (1, 2)], binary=1), read_uff_frf),
    "pyuff modes 55 after 15": (lambda p: _foreign_55(p, [((20.0, 0.01), np.eye(3)[:, :2]),
                                                          ((50.0, 0.02), np.eye(3)[:, 1:])], [1, 2],
                                                      analysis_type=2), read_uff_modal),
    "pyuff nodes 2411": (lambda p: pyuff.UFF(str(p)).write_sets(
        [pyuff.prepare_2411(node_nums=[1, 2], def_cs=[0, 0], disp_cs=[0, 0], color=[0, 0], x=[0.0, 1.0],
                            y=[0.5, 0.25], z=[1 / 3, 2.0])], mode="add") or p, read_uff_nodes),
    "pyuff frf then 151": (lambda p: _frf_then(p, pyuff.prepare_151(
        model_name="rig", description="impact test", db_app="cappe", date_db_created="01-Jan-26",
        time_db_created="06:00:00", version_db1=1, version_db2=0, file_type=0, date_db_saved="01-Jan-26",
        time_db_saved="06:00:00", program="pyuff", date_db_written="01-Jan-26", time_db_written="06:00:00")),
        read_uff_frf),
    "pyuff frf then 164": (lambda p: _frf_then(p, pyuff.prepare_164(
        units_code=1, units_description="SI", temp_mode=1, length=1.0, force=1.0, temp=1.0, temp_offset=273.15)),
        read_uff_frf),
    "pyuff frf then 82": (lambda p: _frf_then(p, pyuff.prepare_82(trace_num=1, n_nodes=3, color=8, id="line",
                                                                   nodes=np.array([1, 2, 1]))), read_uff_frf),
    "pyuff frf then 2467": (lambda p: _frf_then(p, {"type": 2467, "groups": [_GROUP]}), read_uff_frf),
}


def _cuts(opening, end, edge=120, stride=7):
    """Offsets from just inside the last dataset's opening line to just before its closing line ends: every one
    within ``edge`` bytes of either end (header, type line, last values, closing line), every ``stride``-th between."""
    inside = range(opening + 1, end)
    return sorted({*inside[:edge], *inside[-edge:], *inside[::stride]})


@pytest.mark.parametrize("name", list(CUT_FILES))
def test_file_cut_inside_its_last_dataset_is_refused(tmp_path, name):
    """A file cut anywhere inside its last dataset (a copy cut short, a file still being written) is refused
    with a DataError naming the file and the dataset; cut after the last closing line it reads in full."""
    write, read = CUT_FILES[name]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ResourceWarning)  # pyuff's binary writer leaves its last handle to CPython
        path = write(tmp_path / "full.uff")
    whole = _as_values(read(path))
    full = path.read_bytes()
    types = [int(t) for t in pyuff.UFF(str(path)).get_set_types()]
    body = full.rstrip(b"\r\n")
    assert body.endswith(b"    -1")  # after a line end, or straight after the bytes of a binary 58b dataset
    closing = len(body) - 6
    opening = full.rfind(b"    -1\n", 0, closing)  # the writers' opening line
    assert opening == 0 or full[opening - 1 : opening] == b"\n"
    last = full[opening:closing].split(b"\n")[1]
    code = f"{types[-1]}{'b' if last[6:7] == b'b' else ''}"
    assert code in name.split()
    cut = tmp_path / "cut.uff"
    message = re.compile(rf"dataset #{len(types)} (\(UFF ({code}|type cut off)\) )?of {re.escape(str(cut))} ends "
                         r"before its data is complete: the file stops (without|inside) its (type|opening '    -1'"
                         r"|closing '    -1') line \(cut short, or still being written\)$")
    for offset in _cuts(opening, closing + 6):
        cut.write_bytes(full[:offset])
        with pytest.raises(DataError) as caught:
            read(cut)
        assert message.match(str(caught.value)), (offset, str(caught.value))
    for offset in range(closing + 6, len(full) + 1):  # the closing line complete, its line end cut or not
        cut.write_bytes(full[:offset])
        assert _as_values(read(cut)) == whole, offset


@pytest.mark.parametrize(("name", "kind"), [("time 58", "58"), ("frf 58b", "58b"), ("modal 55 after 2411", "55"),
                                            ("pyuff frf then 151", "151"), ("nodes 2411 only", "2411")])
def test_missing_closing_line_is_refused(tmp_path, name, kind):
    write, read = CUT_FILES[name]
    path = write(tmp_path / "full.uff")
    n = len(pyuff.UFF(str(path)).get_set_types())
    text = path.read_bytes()
    assert text.endswith(b"    -1\n")
    path.write_bytes(text[: -len(b"    -1\n")])
    with pytest.raises(DataError, match=rf"^dataset #{n} \(UFF {kind}\) of {re.escape(str(path))} ends before "
                                        r"its data is complete: the file stops without its closing '    -1' line"):
        read(path)


def test_foreign_time_channels_named_in_id_line_1(tmp_path):
    # microphone arrays and DAQ exports name each channel in ID line 1; those names are used when they name every
    # channel differently, and ignored when one line is common to all datasets (then the DOF names stay)
    t = np.arange(16) / 512.0
    recs = [{"func_type": 1, "rsp_node": n, "rsp_dir": 0, "ref_node": 0, "ref_dir": 0, "x": t, "data": np.ones(16),
             "id1": f"Mic {n:02d}"} for n in (1, 2, 3)]
    back = read_uff_time_data(_foreign_58(tmp_path / "mics.uff", recs))
    assert back.channels == ("Mic 01", "Mic 02", "Mic 03")
    for r in recs:
        r["id1"] = "NONE"
    assert read_uff_time_data(_foreign_58(tmp_path / "none.uff", recs)).channels == ("1", "2", "3")
    recs[2]["id1"] = "Mic 01"
    recs[1]["id1"] = "Mic 01"
    recs[0]["id1"] = "Mic 00"
    assert read_uff_time_data(_foreign_58(tmp_path / "same.uff", recs)).channels == ("1", "2", "3")


def _uff_2414_normal_modes(path, freq, zeta, shapes):
    """UFF 2414 normal modes at nodes written by hand from the format's record layout (as FE solvers write them):
    records 1-13 per mode, then node number / six values per node (real, 6E13.5)."""
    e = lambda *v: "".join(f"{x:13.5E}" for x in v)  # noqa: E731
    lines = []
    for r, (f, z) in enumerate(zip(freq, zeta, strict=True)):
        lines += ["    -1", "  2414", f"{r + 1:10d}", f"Mode {r + 1}", f"{1:10d}"] + ["NONE"] * 5
        lines += ["".join(f"{v:10d}" for v in (1, 2, 3, 8, 4, 6)),
                  "".join(f"{v:10d}" for v in (1, 0, 1, 0, 1, r + 1, 0, 0)), f"{0:10d}{0:10d}",
                  e(0.0, f, (2 * np.pi * f) ** 2, 1.0, z, 0.0), e(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)]
        for node, value in enumerate(shapes[:, r], start=1):
            lines += [f"{node:10d}", e(value, 0.0, 0.0, 0.0, 0.0, 0.0)]
        lines.append("    -1")
    path.write_text("\n".join(lines) + "\n")
    return path


def test_fe_normal_modes_from_uff_2414(tmp_path):
    # an FE model's modes (the 3-DOF chain solved with scipy.linalg.eigh) as UFF 2414: read as modal data to
    # compare with measured modes; frequencies and shapes to the 6 digits of E13.5
    import scipy.linalg as sla

    m = np.diag([2.0, 1.0, 1.5])
    k = 1e5 * np.array([[3.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 1.5]])
    w2, phi = sla.eigh(k, m)
    freq = np.sqrt(w2) / (2 * np.pi)
    data = read_uff_modal(_uff_2414_normal_modes(tmp_path / "fe.unv", freq, [0.01, 0.02, 0.0], phi))
    assert data.sensors == ("1:x", "2:x", "3:x")
    np.testing.assert_allclose(data.sets[0].frequency, freq, rtol=1e-5)
    np.testing.assert_allclose(data.sets[0].damping, [0.01, 0.02, 0.0], atol=1e-7)
    np.testing.assert_allclose(data.sets[0].shapes.real, phi, rtol=1e-5, atol=1e-6)


def test_ascii_log_spaced_frequencies_round_trip_exactly(tmp_path):
    # `cappe model frf -o h.uff` writes np.geomspace lines; ASCII UFF 58 kept them to 6 digits (E13.5), a relative
    # shift up to 5e-6: near a 0.01 % damped peak (half-power bandwidth 2e-4 f) that is a few % of |H|
    freq = np.geomspace(7.3, 913.0, 257)
    f_n, zeta = 123.456789, 1e-4  # a single mode written with numpy: H = 1 / (k (1 - r^2 + 2 i zeta r))
    r = freq / f_n
    h = (1.0 / (2.0e6 * (1 - r**2 + 2j * zeta * r)))[None, None, :]
    path = write_uff_frf(tmp_path / "h.uff", FRFData(freq, h, ("F",), ("tool:x",)))
    back = read_uff_frf(path)
    # rebuilt from the ID line's x0 and xn: equal to a few ulps (rtol 4 eps, the writer's own test)
    np.testing.assert_allclose(back.freq, freq, rtol=4 * np.finfo(float).eps, atol=0)
    # the ordinates keep 12 digits at the lines they belong to
    np.testing.assert_allclose(back.H, h, rtol=1e-11, atol=0)
    # other programs read the file's own abscissa (6 digits), and a pyuff reader sees an uneven abscissa
    dset = pyuff.UFF(str(path)).read_sets(0)
    assert dset["abscissa_spacing"] == 0
    np.testing.assert_allclose(dset["x"], freq, rtol=1e-5)
