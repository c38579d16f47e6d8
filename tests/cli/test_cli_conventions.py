"""One CLI, one convention (issue 22): output files, channel lists, option names, progress bars, printed text and
the workflow from a model file of one's own to an identification. Each test here failed on the code before."""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from cappe.cli import build_parser, main

README = Path(__file__).resolve().parents[2] / "README.md"


def run(capsys: pytest.CaptureFixture[str], *argv: object) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def _sled(with_sensors: bool = True) -> str:
    """The README's model (it shows a sensors: list; without it, the same model has none)."""
    text = README.read_text().split("```yaml\n", 1)[1].split("```", 1)[0]
    assert "sensors:" in text
    return text if with_sensors else text.split("sensors:", 1)[0]


# -- -o: what is written matches the file's extension ---------------------------------------------------------------
@pytest.mark.parametrize("argv", [
    ["model", "modes", "builtin:two-mass-rig"],
    ["model", "random-truth", "builtin:two-mass-rig"],
    ["sensitivity", "builtin:two-mass-rig", "--local"],
    ["simulate", "builtin:two-mass-rig"],  # without --excite -o writes modal data (JSON)
])
def test_out_with_another_extension_than_written_is_refused(argv, tmp_path, capsys):
    target = tmp_path / "result.csv"
    code, _, err = run(capsys, *argv, "-o", target)
    assert code == 2
    assert "result.csv" in err
    assert ".json" in err
    assert not target.exists()


def test_model_frf_out_writes_the_format_its_extension_names(tmp_path, capsys):
    from cappe.io import read_frf

    code, out, _ = run(capsys, "model", "frf", "builtin:two-mass-rig", "--lines", "30", "--json")
    assert code == 0
    doc = json.loads(out)
    for name in ("frf.csv", "frf.npz", "frf.uff"):
        code, text, _ = run(capsys, "model", "frf", "builtin:two-mass-rig", "--lines", "30", "-o", tmp_path / name)
        assert code == 0
        assert f"wrote {tmp_path / name}" in text
        frf = read_frf(tmp_path / name)
        # ASCII UFF 58 keeps about 6 significant digits (its fixed-width fields); CSV and npz all 17
        np.testing.assert_allclose(frf.freq, doc["frequency"], rtol=1e-5 if name.endswith(".uff") else 1e-15)
        for pair in doc["frf"]:
            o, i = frf.output_names.index(pair["output"]), frf.input_names.index(pair["input"])
            h = np.asarray(pair["re"]) + 1j * np.asarray(pair["im"])
            if name.endswith(".uff"):  # near the 0.05 %-damped peak a 4e-6 shift of the line moves H by ~1 %
                np.testing.assert_allclose(frf.H[o, i], h, rtol=0.05, atol=1e-4 * np.max(np.abs(h)))
            else:
                np.testing.assert_allclose(frf.H[o, i], h, rtol=1e-15)
    code, _, _ = run(capsys, "model", "frf", "builtin:two-mass-rig", "--lines", "30", "-o", tmp_path / "frf.json")
    assert code == 0
    assert json.loads((tmp_path / "frf.json").read_text()) == doc


def test_simulate_out_with_excite_needs_a_data_extension(tmp_path, capsys):
    code, _, err = run(capsys, "simulate", "builtin:two-mass-rig", "--excite", "F1=random", "--duration", "1",
                       "-o", tmp_path / "t.json")
    assert code == 2
    assert "with --excite, -o writes time data" in err


# -- channel lists and option names: one spelling, the old ones deprecated -----------------------------------------
def test_channel_lists_are_comma_separated_and_the_old_spelling_still_works(tmp_path, capsys):
    data = tmp_path / "run.npz"
    assert main(["simulate", "builtin:two-mass-rig", "--excite", "F1=random", "--excite", "F2=random", "--fs", "512",
                 "--duration", "2", "--outputs", "d1,d2", "--seed", "1", "-o", str(data)]) == 0
    capsys.readouterr()
    code, new, err = run(capsys, "frf", data, "--inputs", "F1,F2", "--outputs", "d1,d2", "--json")
    assert code == 0
    assert err == ""
    code, old, err = run(capsys, "frf", data, "--input", "F1", "F2", "--output", "d1", "d2", "--json")
    assert code == 0
    assert json.loads(old) == json.loads(new)
    assert "--input is deprecated; use --inputs A,B" in err
    assert "--output is deprecated; use --outputs A,B" in err
    code, new, _ = run(capsys, "fit", data, "--inputs", "F1,F2", "--output", "d1", "--order", "4", "--json")
    code_old, old, err = run(capsys, "fit", data, "--input", "F1", "F2", "--output", "d1", "--order", "4", "--json")
    assert code == code_old == 0
    assert json.loads(old) == json.loads(new)
    assert "--input is deprecated" in err
    code, _, err = run(capsys, "frf", data, "--outputs", "d1")
    assert code == 2
    assert "--inputs is required" in err


def test_n_is_lines_in_model_frf_and_n_gsa_in_sensitivity(tmp_path, capsys):
    code, new, err = run(capsys, "model", "frf", "builtin:two-mass-rig", "--lines", "25", "--json")
    assert (code, err) == (0, "")
    code, old, err = run(capsys, "model", "frf", "builtin:two-mass-rig", "--n", "25", "--json")
    assert code == 0
    assert json.loads(old) == json.loads(new)
    assert len(json.loads(new)["frequency"]) == 25
    assert "--n is deprecated; use --lines" in err
    ref = tmp_path / "ref.json"
    assert main(["model", "modes", "builtin:two-mass-rig", "--modal-out", str(ref)]) == 0
    capsys.readouterr()
    common = ["sensitivity", "builtin:two-mass-rig", "--sobol", "--reference", ref, "--parameters", "k11,k12", "--json"]
    code, new, _ = run(capsys, *common, "--n-gsa", "8")
    code_old, old, err = run(capsys, *common, "--n", "8")
    assert code == code_old == 0
    assert json.loads(old) == json.loads(new)
    assert "--n is deprecated; use --n-gsa" in err


def test_identify_noise_options_are_those_of_simulate():
    from cappe.cli.identify import _noise

    def args(**kw: object) -> argparse.Namespace:
        base = {"noise": None, "noise_frequency": None, "noise_damping": None, "noise_shape": None}
        return argparse.Namespace(**{**base, **kw})

    assert _noise(args()) is None
    assert _noise(args(noise_frequency=0.005, noise_damping=0.05, noise_shape=0.02)) == (0.005, 0.05, 0.02)
    assert _noise(args(noise="0.005,0.05,0.02")) == (0.005, 0.05, 0.02)
    from cappe.cli._common import UsageError

    with pytest.raises(UsageError, match="--noise-shape missing"):
        _noise(args(noise_frequency=0.005, noise_damping=0.05))
    with pytest.raises(UsageError, match="either"):
        _noise(args(noise="0.005,0.05,0.02", noise_shape=0.02))
    identify = dict(_parsers(build_parser()))["cappe identify"]
    assert {"--noise-frequency", "--noise-damping", "--noise-shape"} <= set(identify._option_string_actions)


# -- progress bars: on a terminal, or when asked -------------------------------------------------------------------
def test_sobol_progress_only_when_asked_off_a_terminal(tmp_path, capsys):
    ref = tmp_path / "ref.json"
    assert main(["model", "modes", "builtin:two-mass-rig", "--modal-out", str(ref)]) == 0
    capsys.readouterr()
    common = ["sensitivity", "builtin:two-mass-rig", "--sobol", "--reference", ref, "--n-gsa", "8",
              "--parameters", "k11,k12"]
    code, _, err = run(capsys, *common)
    assert code == 0
    assert err == ""  # stderr is not a terminal under pytest
    code, _, err = run(capsys, *common, "--progress")
    assert code == 0
    assert "Sobol' samples" in err


# -- output text ---------------------------------------------------------------------------------------------------
def _parsers(parser: argparse.ArgumentParser, path: str = "cappe"):
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _parsers(sub, f"{path} {name}")


def test_no_help_text_shows_a_doubled_percent_sign():
    shown = {path: parser.format_help() for path, parser in _parsers(build_parser())}
    assert "cappe monitor bearing-test" in shown
    doubled = [path for path, text in shown.items() if "%%" in text]
    assert not doubled


def test_model_check_says_which_ranks_agree():
    from cappe.cli.model import _float_sain_massey

    def inv(exact: tuple[int, int], fl: tuple[int, int]) -> SimpleNamespace:
        ok = lambda r: r[1] - r[0] == 2  # noqa: E731 (two inputs, two outputs)
        return SimpleNamespace(exact_ranks=exact, float_ranks=fl, invertible_exact=ok(exact), invertible_float=ok(fl))

    same = _float_sain_massey(inv((8, 10), (8, 10)))
    assert "the same as the exact ranks" in same
    assert "wrong" not in same
    wrong = _float_sain_massey(inv((8, 10), (4, 4)))
    assert "wrong verdict" in wrong
    differ = _float_sain_massey(inv((8, 9), (4, 4)))  # both not invertible
    assert "same verdict" in differ
    assert "wrong" not in differ


def test_model_check_on_the_rig_names_the_wrong_double_precision_verdict(capsys):
    code, out, _ = run(capsys, "model", "check", "builtin:two-mass-rig")
    assert code == 0
    assert "float rank is wrong here" not in out
    assert "give the wrong verdict here; the exact test above holds" in out


def test_identify_prints_positions_in_words():
    from cappe.cli.identify import _where, _where_all

    assert _where({"z": -0.294}) == "z = -0.294"
    assert _where(None, "none held out") == "none held out"
    assert _where({}) == "the one configuration (no axes)"
    assert _where_all([{"z": -0.06}, {"z": 0.135}]) == "z = -0.06; z = 0.135"
    assert _where_all([{}]) == "the one configuration (no axes)"


# -- workflow: a truth within the bounds, sensors in the model file ------------------------------------------------
def test_random_truth_is_log_uniform_within_the_bounds(tmp_path, capsys):
    from cappe.estimate import ParameterSpace
    from cappe.io import read_parameters
    from cappe.model import load_model

    model = load_model("builtin:uniaxial-machine-tool")
    space = ParameterSpace.from_model(model)
    out = tmp_path / "truth.json"
    code, text, _ = run(capsys, "model", "random-truth", "builtin:uniaxial-machine-tool", "--seed", "1", "-o", out)
    assert code == 0
    truth = read_parameters(out)
    assert list(truth) == list(space.names)
    assert "random truth of 27 unknowns" in text
    # independent: the paper's draw written out with numpy (as `cappe demo` drew its truth before this command)
    u = np.random.default_rng(1).uniform(size=space.n)
    np.testing.assert_allclose(list(truth.values()), space.lower * (space.upper / space.lower) ** u, rtol=1e-15)
    # log-uniform: log(p / lo) / log(hi / lo) is uniform on [0, 1] (2000 draws, seeded: the KS p-value is fixed)
    rng = np.random.default_rng(7)
    draws = np.array([space.sample(rng) for _ in range(2000)])
    assert np.all((draws >= space.lower) & (draws <= space.upper))
    fractions = np.log(draws[:, 0] / space.lower[0]) / np.log(space.upper[0] / space.lower[0])
    assert stats.kstest(fractions, "uniform").pvalue > 0.01
    # a parameter whose bounds include zero is drawn uniformly
    linear = ParameterSpace.from_model(model, ["me1_kx"], bounds={"me1_kx": (0.0, 4e7)}, start={"me1_kx": 1e7})
    values = np.array([linear.sample(rng)[0] for _ in range(2000)])
    assert stats.kstest(values / 4e7, "uniform").pvalue > 0.01


def test_random_truth_needs_finite_bounds():
    from cappe.estimate import ParameterSpace
    from cappe.exceptions import ModelError
    from cappe.model import load_model

    space = ParameterSpace.from_model(load_model("builtin:two-mass-rig"), ["k11"], bounds={"k11": (1e5, np.inf)},
                                      start={"k11": 1e6})
    with pytest.raises(ModelError, match=r"unknowns \['k11'\] have no finite bounds"):
        space.sample(0)


def test_modes_of_a_model_without_sensors_read_back_and_say_what_to_add(tmp_path, capsys):
    from cappe.io import read_modal_data

    model = tmp_path / "sled.yaml"
    model.write_text(_sled(with_sensors=False))
    ref = tmp_path / "modes.json"
    code, out, _ = run(capsys, "model", "modes", model, "--modal-out", ref)
    assert code == 0
    assert "add one to the model file, e.g. 'sensors: [{name: s1, body: table}]'" in out
    data = read_modal_data(ref)  # refused before: undamped modes came out at -2.6e-17
    assert np.all(data.sets[0].damping >= 0)
    # the sled's only damper acts in x: the x mode has c / (2 sqrt(k m)), every other mode exactly 0
    zeta = np.sort(data.sets[0].damping)
    assert zeta[-1] == pytest.approx(30.0 / (2 * np.sqrt(2.0e6 * 3.0)), rel=1e-6)
    assert np.all(zeta[:-1] < 1e-15)  # rounding residue of an undamped pole, never below 0
    code, _, err = run(capsys, "identify", model, "--reference", ref, "--n-gsa", "4", "--n-opt", "1")
    assert code == 1
    assert "'sensors: [{name: s1, body: table}]'" in err
    code, _, err = run(capsys, "simulate", model, "-o", tmp_path / "ref.json")
    assert code == 1
    assert "'sensors: [{name: s1, body: table}]'" in err


def test_the_readme_model_with_its_sensors_goes_through_simulate(tmp_path, capsys):
    from cappe.io import read_modal_data

    model = tmp_path / "sled.yaml"
    model.write_text(_sled())
    truth = tmp_path / "truth.json"
    assert run(capsys, "model", "random-truth", model, "--seed", "2", "-o", truth)[0] == 0
    code, _, err = run(capsys, "simulate", model, "--params", truth, "--positions", "all", "-o", tmp_path / "ref.json")
    assert code == 0, err
    data = read_modal_data(tmp_path / "ref.json")
    assert data.sensors == ("s1:x", "s1:y", "s1:z")
    assert len(data.sets) == 3


# -- monitor: -o everywhere, ISO times, serve --json, ingest --progress -------------------------------------------
@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("conventions")
    db = folder / "s.db"
    assert main(["monitor", "init", str(db), "--machine", "m", "--model", "builtin:spindle-bearing", "--outputs",
                 "sx,sy,hax", "--band", "150:1000"]) == 0
    assert main(["monitor", "simulate", "healthy", "--store", str(db), "-n", "3", "--seed", "1", "-o",
                 str(folder / "day")]) == 0
    return db


def test_ingest_progress_when_asked_and_history_times_in_iso_8601(store, capsys, tmp_path):
    code, _, err = run(capsys, "monitor", "ingest", store, "--manifest", store.parent / "day" / "scenario.json",
                       "--progress", "-o", tmp_path / "ingest.json")
    assert code == 0
    assert "ingest" in err  # the bar, though stderr is no terminal here
    assert json.loads((tmp_path / "ingest.json").read_text())["counts"]["measurements"] == 3
    code, out, _ = run(capsys, "monitor", "history", store, "--json", "-o", tmp_path / "history.json")
    assert code == 0
    rows = json.loads(out)["rows"]
    assert len(rows) == 3
    assert rows[0]["timestamp"] == "2026-01-05T06:00:00+00:00"  # the scenario's default start
    assert all(re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\+00:00", r["timestamp"]) for r in rows)
    assert json.loads((tmp_path / "history.json").read_text()) == json.loads(out)


@pytest.mark.parametrize("command", ["status", "alarms", "history"])
def test_every_store_command_writes_its_json_with_out(store, capsys, tmp_path, command):
    target = tmp_path / f"{command}.json"
    code, out, _ = run(capsys, "monitor", command, store, "--json", "-o", target)
    assert code == 0
    assert json.loads(target.read_text()) == json.loads(out)


def test_serve_json_prints_its_address(store, capsys, monkeypatch, tmp_path):
    import cappe.monitor as monitor_api

    class Server:
        url = "http://127.0.0.1:8765/"
        allowed_hosts = ("127.0.0.1", "localhost")

        def serve_forever(self) -> None:
            raise KeyboardInterrupt

        def shutdown(self) -> None:
            pass

    monkeypatch.setattr(monitor_api, "make_server", lambda *a, **k: Server())
    code, out, _ = run(capsys, "monitor", "serve", store, "--json", "-o", tmp_path / "serve.json")
    assert code == 0
    started = json.loads(out)
    assert started["url"] == "http://127.0.0.1:8765/"
    assert started["allowed_hosts"] == ["127.0.0.1", "localhost"]
    assert json.loads((tmp_path / "serve.json").read_text()) == started


# -- options that were parsed and dropped (found by tests/cli/test_option_audit.py) ---------------------------------
def test_frf_overlap_is_used_or_refused(tmp_path, capsys):
    data = tmp_path / "run.npz"
    hit = tmp_path / "hit.npz"
    assert main(["simulate", "builtin:two-mass-rig", "--excite", "F1=random", "--fs", "512", "--duration", "2",
                 "--outputs", "d1", "--seed", "1", "-o", str(data)]) == 0
    assert main(["simulate", "builtin:two-mass-rig", "--excite", "F1=impact", "--fs", "1024", "--duration", "1",
                 "--band", "0:300", "--outputs", "a1", "--seed", "1", "-o", str(hit)]) == 0
    capsys.readouterr()
    common = ["frf", data, "--inputs", "F1", "--outputs", "d1", "--json"]
    code, _, err = run(capsys, *common, "--overlap", "0.25")  # ignored before: 8 averages at 50 % regardless
    assert code == 2
    assert "--overlap needs --nperseg" in err
    half = json.loads(run(capsys, *common, "--nperseg", "128")[1])
    quarter = json.loads(run(capsys, *common, "--nperseg", "128", "--overlap", "0.25")[1])
    assert half["coherence"] != quarter["coherence"]
    # an impact record of a given length (the overlap default made this an error before)
    code, out, err = run(capsys, "frf", hit, "--inputs", "F1", "--outputs", "a1", "--impact", "--nperseg", "512",
                         "--json")
    assert code == 0, err
    assert json.loads(out)["n_lines"] == 257
    code, _, err = run(capsys, "frf", hit, "--inputs", "F1", "--outputs", "a1", "--impact", "--overlap", "0.5")
    assert code == 2
    assert "--overlap does not apply to --impact" in err


def test_model_show_refuses_a_position_it_would_ignore(tmp_path, capsys):
    model = tmp_path / "sled.yaml"
    model.write_text(_sled())
    code, _, err = run(capsys, "model", "show", model, "--position", "z=0.3")
    assert code == 2
    assert "--position has no effect here" in err
    assert run(capsys, "model", "modes", model, "--position", "z=0.3")[0] == 0


def test_options_of_the_other_mode_are_refused_not_ignored(tmp_path, capsys):
    code, _, err = run(capsys, "sensitivity", "builtin:two-mass-rig", "--local", "--seed", "3", "--threshold", "0.1")
    assert code == 2
    assert "--seed, --threshold apply to --sobol only" in err
    code, _, err = run(capsys, "sensitivity", "builtin:two-mass-rig", "--sobol", "--reference", "x.json",
                       "--percent", "5")
    assert code == 2
    assert "--percent applies to --local only" in err
    data = tmp_path / "run.npz"
    assert main(["simulate", "builtin:two-mass-rig", "--excite", "F1=random", "--fs", "512", "--duration", "1",
                 "--outputs", "d1", "--seed", "1", "-o", str(data)]) == 0
    capsys.readouterr()
    code, _, err = run(capsys, "fit", data, "--inputs", "F1", "--output", "d1", "--order", "4", "--criterion", "bic")
    assert code == 2
    assert "--criterion and --max-order choose the order with --order auto" in err
