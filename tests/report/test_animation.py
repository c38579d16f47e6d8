"""Animations of rigid-body motion and mode shapes: files, frame counts, kinematics of the drawn points."""

from __future__ import annotations

import io
import os
import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from cappe.exceptions import DataError
from cappe.identify._rigid_body import RigidBodyMotion, body_geometry, model_rigid_body_motion
from cappe.io.modal import ModalData, ModalDataSet
from cappe.io.timedata import TimeData
from cappe.model import NumericModel, load_model
from cappe.report.animation import _dof_tracks, _sensor_tracks, animate_mode_shape, animate_motion

SMALL = {"figsize": (2.5, 2.0), "dpi": 40}


@pytest.fixture(scope="module")
def plate():
    return NumericModel(load_model("builtin:dynamometer-plate"))


def _motion(n_t=60, body="b", amplitude=1e-4):
    t = np.arange(n_t) / 200.0
    d = np.zeros((1, n_t, 6))
    d[0, :, 0] = amplitude * np.sin(2 * np.pi * 7 * t)
    d[0, :, 5] = 10 * amplitude * np.cos(2 * np.pi * 7 * t)
    pts = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 0.1]])
    return RigidBodyMotion(t, (body,), d, d, d, np.ones((1, 6), bool), np.zeros((1, 3)), (pts,), "signal")


def test_gif_has_the_requested_frames_and_they_move(tmp_path):
    out = animate_motion(tmp_path / "motion.gif", measured=_motion(), n_frames=5, fps=10, **SMALL)
    assert out == tmp_path / "motion.gif"
    assert out.stat().st_size > 0
    with Image.open(out) as im:
        assert im.n_frames == 5
        assert im.info["duration"] == 100  # 1000 / fps ms (GIF stores centiseconds)
        im.seek(0)
        first = np.asarray(im.convert("RGB"), dtype=int)
        im.seek(2)
        third = np.asarray(im.convert("RGB"), dtype=int)
    assert np.abs(first - third).sum() > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["motion.gif"]  # no temp file left behind
    plain = tmp_path / "plain.txt"
    plain.write_text("x")
    assert out.stat().st_mode & 0o777 == plain.stat().st_mode & 0o777  # the usual mode, not mkstemp's 0600


def test_html_is_self_contained_with_the_animation_script(tmp_path):
    measured = _motion()
    model = _motion(amplitude=2e-4)
    out = animate_motion(
        tmp_path / "motion.html", measured=measured, model=model, layout="side", n_frames=3, title="a<b", **SMALL
    )
    text = out.read_text(encoding="utf-8")
    assert "<script" in text
    assert "<title>a&lt;b</title>" in text
    frames = set(re.findall(r"frames\[(\d+)\] = \"data:image/png;base64,", text))
    assert frames == {"0", "1", "2"}  # every frame embedded, none referenced as a separate file
    assert sorted(p.name for p in tmp_path.iterdir()) == ["motion.html"]


def test_measured_and_model_motion_of_a_model(tmp_path, plate):
    rng = np.random.default_rng(5)
    data = TimeData.from_rate(2000.0, {"Fz": rng.normal(size=200), "Mx": 0.01 * rng.normal(size=200)})
    measured = model_rigid_body_motion(plate, data, inputs={"Fz": "Fz", "Mx": "Mx"})
    model = model_rigid_body_motion(plate, data, inputs={"Fz": "Fz", "Mx": "Mx"}, params={"kn": 6.0e8})
    geometry = body_geometry(plate)
    out = animate_motion(
        tmp_path / "plate.gif",
        measured=measured,
        model=model,
        geometry=geometry,
        n_frames=3,
        window=(0.02, 0.08),
        **SMALL,
    )
    with Image.open(out) as im:
        assert im.n_frames == 3


def test_mode_shape_gif_and_html(tmp_path, plate):
    modes = plate.system().modes()  # exact complex modes: phase is animated
    gif = animate_mode_shape(tmp_path / "mode.gif", model=plate, mode=modes, index=2, n_frames=4, **SMALL)
    with Image.open(gif) as im:
        assert im.n_frames == 4
    labels, rows = plate.sensor_matrix()
    measured = ModalData(tuple(labels), (ModalDataSet({}, modes.frequency, modes.damping, rows @ modes.shapes),))
    page = animate_mode_shape(tmp_path / "mode.html", model=plate, mode=measured, index=0, n_frames=2, **SMALL)
    assert len(re.findall(r"frames\[\d+\] = ", page.read_text(encoding="utf-8"))) == 2


def test_drawn_points_follow_the_mode_shape(plate):
    """The DOF-shape path (np.cross kinematics) and the sensor-shape path (the model's symbolic sensor rows)
    move the sensor nodes identically, and frame k is Re(phi exp(2 pi i k / n))."""
    modes = plate.system().modes()
    phi = modes.shapes[:, 3]
    phases = np.exp(2j * np.pi * np.arange(6) / 6)
    geometry = body_geometry(plate)
    dof_track = _dof_tracks(phi, list(plate.dofs), geometry, phases)[0]
    labels, rows = plate.sensor_matrix()
    sensor_track = _sensor_tracks(rows @ phi, labels, geometry, phases)[0]
    for k, node in enumerate(["centre", "corner1", "corner2", "corner3", "corner4"]):
        point = geometry["plate"].points[geometry["plate"].labels.index(f"sensor:{node}")]
        j = int(np.argmin(np.linalg.norm(dof_track.points - point, axis=1)))
        assert np.allclose(dof_track.points[j], point, atol=1e-12)
        np.testing.assert_allclose(sensor_track.points[k], point, atol=1e-12)
        # same motion from both kinematic paths (round-off, shapes are O(1))
        np.testing.assert_allclose(dof_track.motion[:, j], sensor_track.motion[:, k], atol=1e-12)
        expected = np.real(phases[:, None] * (rows[3 * k : 3 * k + 3] @ phi)[None, :])
        np.testing.assert_allclose(sensor_track.motion[:, k], expected, atol=1e-12)


def test_animation_errors(tmp_path, plate):
    motion = _motion()
    with pytest.raises(DataError, match=r"animation file must end in \.gif or \.html; got '.*motion\.mp4'"):
        animate_motion(tmp_path / "motion.mp4", measured=motion)
    with pytest.raises(DataError, match="argument 'n_frames' must be an integer >= 1; got 0"):
        animate_motion(tmp_path / "m.gif", measured=motion, n_frames=0)
    with pytest.raises(DataError, match=r"window \(5, 6\) s holds no sample"):
        animate_motion(tmp_path / "m.gif", measured=motion, window=(5.0, 6.0))
    with pytest.raises(DataError, match="layout must be 'overlay' or 'side'; got 'stacked'"):
        animate_motion(tmp_path / "m.gif", measured=motion, layout="stacked")  # type: ignore[arg-type]
    with pytest.raises(DataError, match="measured and model motion must share the time grid"):
        animate_motion(tmp_path / "m.gif", measured=motion, model=_motion(n_t=30))
    with pytest.raises(DataError, match=r"geometry\['b'\] must be finite points of shape \(k, 3\)"):
        animate_motion(tmp_path / "m.gif", measured=motion, geometry={"b": [[0.0, 1.0]]})
    with pytest.raises(DataError, match="unknown body 'c'"):
        animate_motion(tmp_path / "m.gif", measured=motion, bodies=["c"])
    with pytest.raises(DataError, match="argument 'scale' must be > 0; got -1"):
        animate_motion(tmp_path / "m.gif", measured=motion, scale=-1.0, n_frames=1, **SMALL)
    modes = plate.system().modes()
    with pytest.raises(DataError, match=r"mode index must be in 0 \.\. 5; got 6"):
        animate_mode_shape(tmp_path / "m.gif", model=plate, mode=modes, index=6)
    data_set = ModalDataSet({}, modes.frequency, modes.damping, modes.shapes)
    with pytest.raises(DataError, match="a ModalDataSet has no channel labels: pass sensors"):
        animate_mode_shape(tmp_path / "m.gif", model=plate, mode=data_set)
    with pytest.raises(DataError, match="shape label 'tip:x' is not a sensor channel 'node:x|y|z' of the model"):
        animate_mode_shape(tmp_path / "m.gif", model=plate, mode=np.ones(1), sensors=["tip:x"])
    with pytest.raises(DataError, match=r"shape labels must all be 'body.dof' or all 'node:x\|y\|z'"):
        animate_mode_shape(tmp_path / "m.gif", model=plate, mode=np.ones(2), sensors=["plate.x", "centre:x"])
    with pytest.raises(DataError, match=r"mode shapes must have one row per label \(2\); got shape \(3, 1\)"):
        animate_mode_shape(tmp_path / "m.gif", model=plate, mode=np.ones(3), sensors=["plate.x", "plate.y"])
    assert list(tmp_path.iterdir()) == []


def test_html_player_buttons_show_their_icons_offline(tmp_path, plate):
    # the player linked Font Awesome from a CDN: offline (and in a self-contained page) its nine buttons were blank
    chromium = Path("/usr/bin/chromium")
    if not chromium.exists():
        if os.environ.get("CAPPE_REQUIRE_SERVICES") == "1":
            pytest.fail(f"headless Chromium not installed at {chromium}")
        pytest.skip(f"headless Chromium not installed at {chromium}")
    playwright = pytest.importorskip("playwright.sync_api")
    page_file = animate_mode_shape(tmp_path / "mode.html", model=plate, mode=plate.system().modes(), index=0,
                                   n_frames=2, **SMALL)
    assert "font-awesome" not in page_file.read_text(encoding="utf-8")  # nothing fetched from the network
    requests: list[str] = []
    with playwright.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(chromium), args=["--headless", "--no-sandbox",
                                                                           "--disable-gpu"], timeout=120_000)
        try:
            page = browser.new_page()
            page.set_default_timeout(120_000)  # ms; playwright's 30 s could run out on a loaded CI machine
            page.route(re.compile(r"^https?://"), lambda route: (requests.append(route.request.url), route.abort()))
            page.goto(page_file.resolve().as_uri())
            buttons = page.locator(".anim-buttons button")
            shots = [buttons.nth(k).screenshot() for k in range(buttons.count())]
        finally:
            browser.close()
    assert requests == []
    assert len(shots) == 9
    for shot in shots:
        with Image.open(io.BytesIO(shot)) as im:
            gray = np.asarray(im.convert("L"), dtype=float)
        h, w = gray.shape
        inner = gray[h // 4 : 3 * h // 4, w // 4 : 3 * w // 4]  # inside the border: the icon or nothing
        assert inner.min() < 128, "a button without a visible icon"  # dark ink on the light button face
