"""``cappe model modes --plot FILE.html --mode N``: the mode-shape view from the command line."""

from __future__ import annotations

import json

from cappe.cli import main


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_mode_shape_page_is_written(capsys, tmp_path):
    page = tmp_path / "mode2.html"
    code, out, err = run(capsys, "model", "modes", "builtin:two-mass-rig", "--plot", page, "--mode", 2, "--json")
    assert code == 0, err
    assert json.loads(out)["plot"] == str(page)
    text = page.read_text()
    # the title names the mode and its exact frequency (166.3 Hz: the rig's upper mode, as `model modes` lists it)
    assert "two-mass-rig: mode 2, 166.3 Hz" in text
    assert text.count("data:image/png;base64") >= 8  # one frame per phase step of the cycle
    code, _, err = run(capsys, "model", "modes", "builtin:two-mass-rig", "--plot", page, "--mode", 3)
    assert code == 2
    assert "--mode must be between 1 and 2 (the model's modes); got 3" in err
