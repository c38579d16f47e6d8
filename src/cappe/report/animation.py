"""Animations of rigid-body vibration: measured vs model-based motion (thesis 4.6) and mode shapes.

Each body is drawn as a wireframe through its points (the minimum spanning tree of the points, so that any
point cloud gives a connected skeleton) moved by the small rigid-body motion ``u + theta x (r - r0)``, magnified
by ``scale``. Files are written by extension: ``.gif`` (Pillow, one image per frame) or ``.html`` (a
self-contained page with the frames embedded and a JavaScript player, matplotlib's ``to_jshtml``).

Figures are :class:`matplotlib.figure.Figure` objects on an Agg canvas: no pyplot state, no backend switch.
"""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.sparse.csgraph import minimum_spanning_tree
from scipy.spatial.distance import pdist, squareform

from cappe._arguments import positive_number
from cappe.exceptions import DataError
from cappe.identify._rigid_body import RIGID_BODY_DOFS, BodyGeometry, RigidBodyMotion, body_geometry
from cappe.io.files import atomic_path, write_text
from cappe.modal._batch import ModalBatch
from cappe.model.numeric import NumericModel, ParamsLike
from cappe.systems.modal import ModalData, ModalDataSet, ModalSet

__all__ = ["animate_mode_shape", "animate_motion"]

Array = NDArray[np.float64]
_EXTENSIONS = (".gif", ".html", ".htm")
_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink", "tab:olive")


@dataclass
class _Track:
    """One body in one panel: nominal points (k, 3), wireframe edges and displacements per frame."""

    label: str
    points: Array
    edges: list[tuple[int, int]]
    motion: Array  # (n_frames, k, 3), m, before magnification
    color: str
    dashed: bool


def _check_path(path: str | Path) -> Path:
    out = Path(path)
    if out.suffix.lower() not in _EXTENSIONS:
        msg = f"animation file must end in .gif or .html; got {str(path)!r}"
        raise DataError(msg)
    return out


def _positive_int(name: str, value: Any, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or int(value) < minimum:
        msg = f"argument {name!r} must be an integer >= {minimum}; got {value!r}"
        raise DataError(msg)
    return int(value)


def _unique_points(points: Array) -> Array:
    """Points with duplicates (closer than 1e-9 m) removed, order kept."""
    keep: list[int] = []
    for i, p in enumerate(points):
        if all(np.linalg.norm(p - points[j]) > 1e-9 for j in keep):
            keep.append(i)
    return points[keep]


def _edges(points: Array) -> list[tuple[int, int]]:
    if points.shape[0] < 2:
        return []
    tree = minimum_spanning_tree(squareform(pdist(points))).tocoo()
    return [(int(i), int(j)) for i, j in zip(tree.row, tree.col, strict=True)]


def _geometry_points(item: BodyGeometry | ArrayLike, body: str) -> Array:
    raw = item.points if isinstance(item, BodyGeometry) else item
    try:
        pts = np.asarray(raw, dtype=float)
    except (TypeError, ValueError):
        msg = f"geometry[{body!r}] must be a BodyGeometry or points of shape (k, 3) in m; got {raw!r}"
        raise DataError(msg) from None
    if pts.ndim == 1 and pts.size == 3:
        pts = pts[None, :]
    if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] == 0 or not np.all(np.isfinite(pts)):
        msg = f"geometry[{body!r}] must be finite points of shape (k, 3) in m; got shape {np.shape(pts)}"
        raise DataError(msg)
    return pts


# -- rendering --------------------------------------------------------------------------------------------------
def _render(
    path: Path,
    panels: list[list[_Track]],
    titles: list[str],
    stamps: list[str],
    *,
    scale: float | None,
    fps: int,
    figsize: tuple[float, float],
    dpi: float,
    suptitle: str,
) -> Path:
    from matplotlib.animation import FuncAnimation, PillowWriter
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    tracks = [t for panel in panels for t in panel]
    nominal = np.vstack([t.points for t in tracks])
    lo, hi = nominal.min(axis=0), nominal.max(axis=0)
    extent = float(np.max(hi - lo)) or 1.0
    peak = max(float(np.abs(t.motion).max()) for t in tracks)
    if scale is None:
        magnify = 0.1 * extent / peak if peak > 0 else 1.0
    else:
        magnify = positive_number("scale", scale)
    centre = (lo + hi) / 2
    half = 0.5 * extent + max(0.15 * extent, magnify * peak)
    n_frames = tracks[0].motion.shape[0]

    fig = Figure(figsize=figsize, dpi=dpi)
    FigureCanvasAgg(fig)
    artists: list[tuple[_Track, Any, Any]] = []
    for k, panel in enumerate(panels):
        ax = fig.add_subplot(1, len(panels), k + 1, projection="3d")
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
        ax.set_zlim(centre[2] - half, centre[2] + half)
        ax.set_box_aspect((1, 1, 1))
        ax.set_xlabel("x (m)", fontsize=7)
        ax.set_ylabel("y (m)", fontsize=7)
        ax.set_zlabel("z (m)", fontsize=7)
        ax.tick_params(labelsize=6)
        if titles[k]:
            ax.set_title(titles[k], fontsize=8)
        handles = []
        for track in panel:
            style: Literal["-", "--"] = "--" if track.dashed else "-"
            (wire,) = ax.plot([], [], [], style, color=track.color, linewidth=1.2)
            (dots,) = ax.plot([], [], [], "o", color=track.color, markersize=3)
            artists.append((track, wire, dots))
            handles.append(Line2D([], [], linestyle=style, color=track.color, label=track.label))
        ax.legend(handles=handles, fontsize=6, loc="upper left")
    stamp = fig.text(0.99, 0.01, "", ha="right", va="bottom", fontsize=7)
    if suptitle:
        fig.suptitle(suptitle, fontsize=9)
    fig.text(0.01, 0.01, f"motion x {magnify:.3g}", ha="left", va="bottom", fontsize=7)

    def update(frame: int) -> list[Any]:
        for track, wire, dots in artists:
            moved = track.points + magnify * track.motion[frame]
            segments: list[Array] = []
            for i, j in track.edges:
                segments.extend([moved[i], moved[j], np.full(3, np.nan)])
            line = np.array(segments) if segments else np.zeros((0, 3))
            wire.set_data_3d(line[:, 0], line[:, 1], line[:, 2])
            dots.set_data_3d(moved[:, 0], moved[:, 1], moved[:, 2])
        stamp.set_text(stamps[frame])
        return [a for _, w, d in artists for a in (w, d)] + [stamp]

    anim = FuncAnimation(fig, update, frames=n_frames, interval=1000.0 / fps, blit=False, repeat=True)
    if path.suffix.lower() == ".gif":
        with atomic_path(path, suffix=".gif") as tmp:  # Pillow picks the format from the suffix
            anim.save(tmp, writer=PillowWriter(fps=fps), dpi=dpi)
    else:
        player = _offline_buttons(anim.to_jshtml(fps=fps, embed_frames=True, default_mode="loop"))
        head = f'<!DOCTYPE html>\n<html><head><meta charset="utf-8"><title>{html.escape(suptitle)}</title></head>'
        write_text(path, f"{head}<body>\n{player}\n</body></html>\n")
    fig.clear()
    return path


#: Inline SVG icons (16 x 16, the button's text colour) for the Font Awesome icons of matplotlib's player: the page
#: is self-contained, and the icon font it links from a CDN does not load offline, which left the buttons blank.
_ICONS = {
    "minus": '<rect x="3" y="7" width="10" height="2"/>',
    "plus": '<rect x="3" y="7" width="10" height="2"/><rect x="7" y="3" width="2" height="10"/>',
    "play": '<polygon points="4,2 14,8 4,14"/>',
    "play fa-flip-horizontal": '<polygon points="12,2 2,8 12,14"/>',
    "pause": '<rect x="3" y="2" width="4" height="12"/><rect x="9" y="2" width="4" height="12"/>',
    "step-forward": '<polygon points="3,2 11,8 3,14"/><rect x="11" y="2" width="2" height="12"/>',
    "step-backward": '<rect x="3" y="2" width="2" height="12"/><polygon points="13,2 5,8 13,14"/>',
    "fast-forward": '<polygon points="1,2 7,8 1,14"/><polygon points="7,2 13,8 7,14"/>'
                    '<rect x="13" y="2" width="2" height="12"/>',
    "fast-backward": '<rect x="1" y="2" width="2" height="12"/><polygon points="9,2 3,8 9,14"/>'
                     '<polygon points="15,2 9,8 15,14"/>',
}


def _offline_buttons(player: str) -> str:
    """matplotlib's animation player with its Font Awesome icons drawn as inline SVG and the CDN link removed."""
    import re

    def icon(match: re.Match[str]) -> str:
        shapes = _ICONS.get(match.group(1))
        if shapes is None:  # an icon this table does not know: keep matplotlib's markup
            return match.group(0)
        return (f'<svg width="16" height="16" viewBox="0 0 16 16" fill="currentColor" aria-hidden="true" '
                f'style="vertical-align: middle">{shapes}</svg>')

    player = re.sub(r'<i class="fa fa-([a-z -]+?)"></i>', icon, player)
    if "fa fa-" not in player:  # nothing left that needs the icon font
        player = re.sub(r'<link rel="stylesheet"\s+href="[^"]*font-awesome[^"]*">', "", player)
    return player


# -- measured vs model motion -----------------------------------------------------------------------------------
def animate_motion(
    path: str | Path,
    *,
    measured: RigidBodyMotion,
    model: RigidBodyMotion | None = None,
    geometry: Mapping[str, BodyGeometry | ArrayLike] | None = None,
    bodies: Sequence[str] | None = None,
    quantity: Literal["displacement", "velocity", "acceleration"] = "displacement",
    layout: Literal["overlay", "side"] = "overlay",
    n_frames: int = 20,
    window: tuple[float, float] | None = None,
    fps: int = 10,
    scale: float | None = None,
    figsize: tuple[float, float] = (6.0, 4.5),
    dpi: float = 80.0,
    title: str = "",
) -> Path:
    """Animate the rigid-body motion of bodies, measured (signal based) and optionally model based.

    Parameters
    ----------
    path : str or Path
        Output file, ``.gif`` or ``.html`` (self-contained); written atomically.
    measured : RigidBodyMotion
        Motion to show (solid lines).
    model : RigidBodyMotion, optional
        Model-based motion of the same bodies on the same time grid (dashed lines).
    geometry : mapping, optional
        ``{body: BodyGeometry or points (k, 3)}`` in the frame of the motions' reference points (m), e.g.
        :func:`~cappe.identify._rigid_body.body_geometry` of the model; default the measured sensor points and
        reference point of each body.
    bodies : sequence of str, optional
        Bodies to draw (default all measured bodies).
    quantity : {"displacement", "velocity", "acceleration"}
        What moves the points (displacement in m by default).
    layout : {"overlay", "side"}
        Model drawn over the measurement, or in a second panel beside it.
    n_frames : int
        Number of frames, evenly spaced over ``window``.
    window : (float, float), optional
        Time span in s (default the whole record).
    fps : int
        Frames per second of the animation.
    scale : float, optional
        Magnification of the motion; default such that the largest excursion is 10 % of the structure's size.
    figsize, dpi : optional
        Figure size in inches and resolution.
    title : str
        Figure title.

    Returns
    -------
    Path
        The written file.

    Examples
    --------
    >>> import numpy as np, tempfile, pathlib
    >>> t = np.arange(50) / 100.0
    >>> d = np.zeros((1, 50, 6)); d[0, :, 0] = 1e-4 * np.sin(2 * np.pi * 4 * t)
    >>> m = RigidBodyMotion(t, ("b",), d, d, d, np.ones((1, 6), bool), np.zeros((1, 3)),
    ...                     (np.array([[0.0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]]),), "signal")
    >>> out = animate_motion(pathlib.Path(tempfile.mkdtemp()) / "m.gif", measured=m, n_frames=2,
    ...                      figsize=(2, 2), dpi=40)
    >>> out.stat().st_size > 0
    True
    """
    out = _check_path(path)
    if not isinstance(measured, RigidBodyMotion):
        msg = f"measured must be a RigidBodyMotion; got {type(measured).__name__}"
        raise DataError(msg)
    if model is not None:
        if not isinstance(model, RigidBodyMotion):
            msg = f"model must be a RigidBodyMotion or None; got {type(model).__name__}"
            raise DataError(msg)
        if model.time.shape != measured.time.shape or not np.allclose(model.time, measured.time, rtol=0, atol=1e-9):
            msg = "measured and model motion must share the time grid"
            raise DataError(msg)
    if quantity not in ("displacement", "velocity", "acceleration"):
        msg = f"quantity must be displacement, velocity or acceleration; got {quantity!r}"
        raise DataError(msg)
    if layout not in ("overlay", "side"):
        msg = f"layout must be 'overlay' or 'side'; got {layout!r}"
        raise DataError(msg)
    frames = _positive_int("n_frames", n_frames)
    rate = _positive_int("fps", fps)
    names = list(bodies) if bodies is not None else list(measured.bodies)
    for b in names:
        measured.index(b)
    t = measured.time
    start, stop = (float(t[0]), float(t[-1])) if window is None else (float(window[0]), float(window[1]))
    inside = np.flatnonzero((t >= start) & (t <= stop))
    if inside.size == 0:
        msg = f"window ({start:g}, {stop:g}) s holds no sample of the record {t[0]:g} .. {t[-1]:g} s"
        raise DataError(msg)
    picks = inside[np.round(np.linspace(0, inside.size - 1, frames)).astype(int)]
    measured_tracks, model_tracks = [], []
    for k, b in enumerate(names):
        i = measured.index(b)
        if geometry is not None and b in geometry:
            pts = _geometry_points(geometry[b], b)
        else:
            pts = np.vstack([measured.reference[i][None, :], measured.points[i]])
        pts = _unique_points(pts)
        edges = _edges(pts)
        color = _COLORS[k % len(_COLORS)]
        moved = measured.point_motion(b, pts, quantity)[picks]
        measured_tracks.append(_Track(f"{b} (measured)", pts, edges, moved, color, False))
        if model is not None and b in model.bodies:
            sim = model.point_motion(b, pts, quantity)[picks]
            model_tracks.append(_Track(f"{b} (model)", pts, edges, sim, color, True))
    if model is None or not model_tracks:
        panels, titles = [measured_tracks], [""]
    elif layout == "overlay":
        panels, titles = [measured_tracks + model_tracks], ["measured (solid) and model (dashed)"]
    else:
        panels, titles = [measured_tracks, model_tracks], ["measured", "model"]
    stamps = [f"t = {t[p]:.4f} s" for p in picks]
    return _render(
        out, panels, titles, stamps, scale=scale, fps=rate, figsize=figsize, dpi=dpi, suptitle=title or quantity
    )


# -- mode shapes ------------------------------------------------------------------------------------------------
def _shape_from(
    mode: ModalSet | ModalBatch | ModalDataSet | ModalData | ArrayLike,
    index: int,
    sample: int,
    set_index: int,
    sensors: Sequence[str] | None,
) -> tuple[NDArray[np.complex128], list[str], float | None, dict[str, float] | None]:
    """Shape vector, its labels (DOF or sensor channel names), frequency (Hz) and axis position, if known."""
    freq: NDArray[Any] | None
    position: dict[str, float] | None
    if isinstance(mode, ModalData):
        if not 0 <= set_index < len(mode.sets):
            msg = f"set_index must be in 0 .. {len(mode.sets) - 1}; got {set_index}"
            raise DataError(msg)
        chosen = mode.sets[set_index]
        shape, labels, f_hz, _ = _shape_from(chosen, index, sample, set_index, list(mode.sensors))
        return shape, labels, f_hz, dict(chosen.position)
    if isinstance(mode, ModalSet):
        shapes, labels, freq = mode.shapes, list(mode.dofs), mode.frequency
        position = None
    elif isinstance(mode, ModalBatch):
        if not 0 <= sample < mode.n_samples:
            msg = f"sample must be in 0 .. {mode.n_samples - 1}; got {sample}"
            raise DataError(msg)
        if mode.full_shapes is not None and mode.dofs:
            shapes, labels = mode.full_shapes[sample], list(mode.dofs)
        else:
            shapes, labels = mode.shapes[sample], list(mode.sensors)
        freq, position = mode.frequency[sample], dict(mode.position)
    elif isinstance(mode, ModalDataSet):
        if sensors is None:
            msg = "a ModalDataSet has no channel labels: pass sensors=[...] ('node:x' labels, one per shape row)"
            raise DataError(msg)
        shapes, labels, freq, position = mode.shapes, list(sensors), mode.frequency, dict(mode.position)
    else:
        arr = np.asarray(mode, dtype=complex)
        if arr.ndim == 1:
            arr = arr[:, None]
        if sensors is None:
            msg = "a bare shape array needs sensors=[...]: one 'node:x' or 'body.dof' label per row"
            raise DataError(msg)
        shapes, labels, freq, position = arr, list(sensors), None, None
    shapes = np.asarray(shapes)
    if shapes.ndim != 2 or shapes.shape[0] != len(labels):
        msg = f"mode shapes must have one row per label ({len(labels)}); got shape {shapes.shape}"
        raise DataError(msg)
    if not 0 <= index < shapes.shape[1]:
        msg = f"mode index must be in 0 .. {shapes.shape[1] - 1}; got {index}"
        raise DataError(msg)
    f = float(np.asarray(freq)[index]) if freq is not None else None
    return np.asarray(shapes[:, index], dtype=complex), labels, f, position


def animate_mode_shape(
    path: str | Path,
    *,
    model: NumericModel,
    mode: ModalSet | ModalBatch | ModalDataSet | ModalData | ArrayLike,
    index: int = 0,
    sample: int = 0,
    set_index: int = 0,
    sensors: Sequence[str] | None = None,
    params: ParamsLike = None,
    position: Mapping[str, float] | None = None,
    n_frames: int = 16,
    fps: int = 12,
    scale: float | None = None,
    figsize: tuple[float, float] = (5.0, 4.5),
    dpi: float = 80.0,
    title: str = "",
) -> Path:
    """Animate one mode shape over a cycle: points move by ``Re(phi exp(i 2 pi k / n_frames))``.

    A complex shape shows its phase (non-proportional damping, gyroscopic modes); a real shape is a standing
    wave. Shapes over generalized coordinates (``"body.dof"`` labels: :class:`ModalSet`, a :class:`ModalBatch`
    with full shapes) move every body's points (:func:`~cappe.identify._rigid_body.body_geometry`) rigidly;
    shapes at sensor channels (``"node:x"`` labels: :class:`ModalDataSet`, :class:`ModalData`, a ModalBatch)
    move the sensor nodes along the measured directions, and each body's wireframe joins its nodes.

    Parameters
    ----------
    path : str or Path
        Output file, ``.gif`` or ``.html``.
    model : NumericModel
        Supplies the geometry (body origins, sensor nodes, attachment points).
    mode : ModalSet, ModalBatch, ModalDataSet, ModalData or array_like
        The modes; an array is one shape (n_labels,) or shapes (n_labels, n_modes).
    index : int
        Mode number (column).
    sample, set_index : int
        Sample of a ModalBatch, set of a ModalData.
    sensors : sequence of str, optional
        Row labels for a ModalDataSet or a bare array.
    params, position : optional
        Parameter values and axis position of the geometry (default the mode set's position when it has one).
    n_frames, fps, scale, figsize, dpi, title : optional
        Frames per cycle, playback rate, magnification (default: largest excursion 10 % of the structure's size),
        figure size (in), resolution and title.

    Returns
    -------
    Path

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from cappe.model import load_model
    >>> nm = NumericModel(load_model("builtin:two-mass-rig"))
    >>> out = animate_mode_shape(pathlib.Path(tempfile.mkdtemp()) / "mode.gif", model=nm,
    ...                          mode=nm.system().modes(), n_frames=2, figsize=(2, 2), dpi=40)
    >>> out.suffix
    '.gif'
    """
    out = _check_path(path)
    if not isinstance(model, NumericModel):
        msg = f"model must be a NumericModel; got {type(model).__name__}"
        raise DataError(msg)
    frames = _positive_int("n_frames", n_frames)
    rate = _positive_int("fps", fps)
    shape, labels, freq, mode_position = _shape_from(mode, int(index), int(sample), int(set_index), sensors)
    geometry = body_geometry(model, params=params, position=position if position is not None else mode_position)
    phases = np.exp(2j * np.pi * np.arange(frames) / frames)
    tracks: list[_Track] = []
    if all("." in lab and ":" not in lab for lab in labels):
        tracks = _dof_tracks(shape, labels, geometry, phases)
    elif all(":" in lab for lab in labels):
        tracks = _sensor_tracks(shape, labels, geometry, phases)
    else:
        msg = f"shape labels must all be 'body.dof' or all 'node:x|y|z'; got {labels}"
        raise DataError(msg)
    what = f"mode {index + 1}" + (f", {freq:.4g} Hz" if freq is not None else "")
    stamps = [f"phase {360 * k / frames:.0f} deg" for k in range(frames)]
    return _render(out, [tracks], [""], stamps, scale=scale, fps=rate, figsize=figsize, dpi=dpi, suptitle=title or what)


def _dof_tracks(
    shape: NDArray[np.complex128], labels: list[str], geometry: Mapping[str, BodyGeometry], phases: NDArray[Any]
) -> list[_Track]:
    per_body: dict[str, NDArray[np.complex128]] = {}
    for value, label in zip(shape, labels, strict=True):
        body, _, dof = label.partition(".")
        if body not in geometry or dof not in RIGID_BODY_DOFS:
            msg = f"shape label {label!r} is not a DOF 'body.dof' of the model (bodies: {sorted(geometry)})"
            raise DataError(msg)
        per_body.setdefault(body, np.zeros(6, dtype=complex))[RIGID_BODY_DOFS.index(dof)] = value
    tracks = []
    for k, (body, q) in enumerate(per_body.items()):
        geo = geometry[body]
        pts = _unique_points(geo.points)
        rel = pts - geo.reference
        point_shape = q[None, :3] + np.cross(q[None, 3:], rel)  # (k, 3) complex
        motion = np.real(phases[:, None, None] * point_shape[None])
        tracks.append(_Track(body, pts, _edges(pts), motion, _COLORS[k % len(_COLORS)], False))
    return tracks


def _sensor_tracks(
    shape: NDArray[np.complex128], labels: list[str], geometry: Mapping[str, BodyGeometry], phases: NDArray[Any]
) -> list[_Track]:
    where: dict[str, tuple[str, NDArray[np.float64]]] = {}
    for body, geo in geometry.items():
        for p, lab in zip(geo.points, geo.labels, strict=True):
            if lab.startswith("sensor:"):
                where[lab.removeprefix("sensor:")] = (body, p)
    nodes: dict[str, NDArray[np.complex128]] = {}
    for value, label in zip(shape, labels, strict=True):
        node, _, axis = label.rpartition(":")
        if node not in where or axis not in ("x", "y", "z"):
            msg = f"shape label {label!r} is not a sensor channel 'node:x|y|z' of the model (nodes: {sorted(where)})"
            raise DataError(msg)
        nodes.setdefault(node, np.zeros(3, dtype=complex))["xyz".index(axis)] = value
    bodies: dict[str, list[str]] = {}
    for node in nodes:
        bodies.setdefault(where[node][0], []).append(node)
    tracks = []
    for k, (body, members) in enumerate(bodies.items()):
        pts = np.array([where[n][1] for n in members])
        point_shape = np.array([nodes[n] for n in members])
        motion = np.real(phases[:, None, None] * point_shape[None])
        tracks.append(_Track(body, pts, _edges(pts), motion, _COLORS[k % len(_COLORS)], False))
    return tracks
