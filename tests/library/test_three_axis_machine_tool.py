"""The three-axis benchmark ``builtin:three-axis-machine-tool`` (issue 24): a column machine with a flexible bed and
column (Craig-Bampton models of 3-D Timoshenko frames), three ball-screw axes and a spindle head.

Checks the file's promises: 60-100 unknowns in the paper's style with eq. 14 bounds, the 3 x 3 x 3 grid of axis
positions, at least 25 modes in 15-500 Hz at every grid position, every unknown moving some mode somewhere, and
frequencies that vary continuously along the axes. References come from outside cappe's model compiler and modal
engine: an assembly written here with numpy from the model file's raw YAML and the full (unreduced) FE matrices,
``scipy.linalg.eigh``, and first-order damping ratios computed here from the undamped shapes.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse as sps
import yaml

from cappe.library import builtin_path
from cappe.library._three_axis import FRAME_FILES, frames
from cappe.model.loader import load_model
from cappe.model.numeric import NumericModel

MODEL = "builtin:three-axis-machine-tool"
GRID = {"x": (-0.6, 0.0, 0.6), "y": (0.4, 0.8, 1.2), "z": (-0.2, 0.0, 0.2)}
POSITIONS = [dict(zip("xyz", p, strict=True)) for p in itertools.product(*GRID.values())]
CORNERS = [dict(zip("xyz", p, strict=True)) for p in itertools.product(*((v[0], v[-1]) for v in GRID.values()))]
BAND_HZ = (15.0, 500.0)
DIRECTIONS = ("x", "y", "z", "rx", "ry", "rz")


@pytest.fixture(scope="module")
def model() -> NumericModel:
    return NumericModel(load_model(MODEL))


def _modes(model: NumericModel, position: dict[str, float], params: dict[str, float] | None = None,
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Undamped frequencies (Hz) by scipy's eigh on (K, M), and first-order damping ratios computed here from the
    mass-normalized shapes: zeta = phi^T C phi / (2 omega) + phi^T H phi / (2 omega^2)."""
    system = model.system(params, position)
    lam, phi = scipy.linalg.eigh(system.K, system.M)
    omega = np.sqrt(np.clip(lam, 0.0, None))
    zeta = (np.einsum("ij,ik,kj->j", phi, system.C, phi) / (2 * omega)
            + np.einsum("ij,ik,kj->j", phi, system.H, phi) / (2 * omega**2))
    return omega / (2 * np.pi), zeta, phi


def test_the_file_declares_60_to_100_unknowns_in_the_papers_style(model):
    unknown = [p for p in model.structure.parameters if p.unknown]
    assert 60 <= len(unknown) <= 100
    # k: stiffness, b: viscous damping, d: loss factor; mounts, guides, fixed bearings, couplings, screws, spindle
    kinds = {"k": "stiffness", "b": "damping", "d": "loss"}
    groups = {p.name.split("_")[0].rstrip("xyz1234") for p in unknown}
    assert groups == {"me", "lg", "fb", "cpl", "bsd", "spf", "spr"}
    for p in unknown:
        assert p.kind == kinds[p.name.split("_")[1][0]], p.name
        lo, hi = p.bounds
        expected = (0.7, 1.3) if p.kind == "stiffness" else (1 / 3, 3.0)
        # bounds written with six significant digits in the file: at most half a unit of the sixth, 5e-6
        assert lo / p.value == pytest.approx(expected[0], rel=5e-6), p.name
        assert hi / p.value == pytest.approx(expected[1], rel=5e-6), p.name


def test_axes_span_a_3x3x3_grid_and_the_frames_are_flexible(model):
    structure = model.structure
    assert {a.name: a.positions for a in structure.axes} == GRID
    assert [f.name for f in structure.flexible_bodies] == ["bed", "column"]
    labels, rows = model.sensor_matrix(position=POSITIONS[13])
    nodes = {s.name: s.body for s in structure.sensors}
    assert len(nodes) >= 30
    for body in ("bed", "saddle", "column", "head", "spindle", "screwx", "screwy", "screwz", "rotorx", "rotorz"):
        assert body in nodes.values(), body
    # every sensor node sees some motion of the structure
    assert np.all(np.abs(rows).reshape(len(nodes), -1).max(axis=1) > 0)


def test_stored_matrix_files_are_what_the_frame_generator_builds():
    # the generator module is the only source of the bed and column matrices: the files must not drift from it
    folder = builtin_path("three-axis-machine-tool").parent
    for body, fm in frames().items():
        for name, built in zip(FRAME_FILES[body], (fm.frame.stiffness, fm.frame.mass), strict=True):
            stored = sps.load_npz(folder / name)
            assert stored.shape == built.shape
            assert abs(stored - built).max() == 0.0, name


@pytest.mark.parametrize("position", POSITIONS, ids=lambda p: "x{x}_y{y}_z{z}".format(**p))
def test_at_least_25_modes_between_15_and_500_hz_at_every_grid_position(model, position):
    freq, zeta, _ = _modes(model, position)
    assert freq.min() >= BAND_HZ[0]  # no free rigid-body motion, nothing below the band
    in_band = (freq >= BAND_HZ[0]) & (freq <= BAND_HZ[1])
    assert np.count_nonzero(in_band) >= 25
    # light damping throughout the band (machine-tool modes: a few tenths of a per cent to a few per cent)
    assert np.all((zeta[in_band] > 1e-3) & (zeta[in_band] < 0.08))


@pytest.mark.slow
def test_every_unknown_moves_some_mode_at_some_grid_corner(model):
    # each unknown alone at its upper bound (stiffness x 1.3, damping x 3): a stiffness must shift some in-band
    # frequency by >= 0.3 %, a damping unknown raise some in-band damping ratio by >= 5 % (at nominal values the
    # weakest are about 4 times above these floors: lgz_kry 1.3 %, me1_bx 20 %), at one of the eight grid corners;
    # one batch of matrices per corner, scipy's eigh and first-order damping computed here for each vector
    unknown = [p for p in model.structure.parameters if p.unknown]
    batch = np.repeat(model.vector(None)[None, :], len(unknown) + 1, axis=0)
    for i, p in enumerate(unknown, start=1):
        batch[i, model.parameter_names.index(p.name)] = p.bounds[1]
    best = np.zeros(len(unknown))
    for position in CORNERS:
        mats = model.matrices(batch, position, names=("M", "K", "C", "H"))
        freq, zeta = [], []
        for b in range(batch.shape[0]):
            lam, phi = scipy.linalg.eigh(mats["K"][b], mats["M"][b])
            omega = np.sqrt(np.clip(lam, 0.0, None))
            zeta.append(np.einsum("ij,ik,kj->j", phi, mats["C"][b], phi) / (2 * omega)
                        + np.einsum("ij,ik,kj->j", phi, mats["H"][b], phi) / (2 * omega**2))
            freq.append(omega / (2 * np.pi))
        band = (freq[0] >= BAND_HZ[0]) & (freq[0] <= BAND_HZ[1])
        for i, p in enumerate(unknown, start=1):
            change = np.abs(freq[i] / freq[0] - 1) if p.kind == "stiffness" else np.abs(zeta[i] / zeta[0] - 1)
            best[i - 1] = max(best[i - 1], float(change[band].max()))
    weak = {p.name: round(float(v), 5) for p, v in zip(unknown, best, strict=True)
            if v < (3e-3 if p.kind == "stiffness" else 0.05)}
    assert not weak


def _sweep(model, axis: str, values: np.ndarray, base: dict[str, float], n: int = 30) -> np.ndarray:
    return np.array([_modes(model, {**base, axis: float(v)})[0][:n] for v in values])


@pytest.mark.parametrize(("axis", "node_crossing"), [("x", 0.3), ("y", 0.6), ("z", 0.1)])
def test_frequencies_are_continuous_along_each_axis(model, axis, node_crossing):
    # a guide shoe crosses an interface node of the bed (x = 0.3: the rear and front shoes at x - 0.3 = 0) or of the
    # column (y = 0.6: the lower head shoes at y - 0.2 = 0.4 ... the upper ones at 0.8); z moves no point along a
    # line (the column rides on fixed nodes) but changes the Z screw's free length
    base = {"x": 0.0, "y": 0.8, "z": 0.0}
    jumps = []
    for eps in (1e-3, 1e-5):
        lo, hi = _sweep(model, axis, np.array([node_crossing - eps, node_crossing + eps]), base)
        jumps.append(np.abs(hi / lo - 1).max())
    # Lipschitz across the node: a 100 times smaller step gives about a 100 times smaller change
    assert jumps[1] < 2e-2 * jumps[0] + 1e-12
    # over the whole travel, steps of 1/40 of it change no tracked-by-rank frequency by more than 5 %
    travel = np.linspace(GRID[axis][0], GRID[axis][-1], 41)
    freq = _sweep(model, axis, travel, base)
    assert np.max(np.abs(np.diff(freq, axis=0)) / freq[:-1]) < 0.05
    # and the axis matters: some of the lowest 30 frequencies move by more than 2 % over the travel
    assert np.max(np.ptp(freq, axis=0) / freq.mean(axis=0)) > 0.02


# --- an independent assembly: numpy, the raw YAML, the full FE matrices (no Craig-Bampton) ---------------------

def _evaluator(doc: dict, position: dict[str, float]):  # type: ignore[no-untyped-def]
    names = {p["name"]: float(p["value"]) for p in doc["parameters"]} | position | {"pi": math.pi}

    def value(expr: object) -> float:
        # the test's own evaluation of the file's arithmetic (a trusted file; cappe parses it with sympy)
        return float(eval(str(expr), {"__builtins__": {}}, names))  # noqa: S307

    return value


def _independent_matrices(position: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
    path = builtin_path("three-axis-machine-tool")
    doc = yaml.safe_load(path.read_text())
    value = _evaluator(doc, position)
    offsets: dict[str, int] = {}
    n = 0
    flexible = {}
    for fb in doc["flexible_bodies"]:
        k_full = sps.load_npz(path.parent / fb["stiffness"]).toarray()
        m_full = sps.load_npz(path.parent / fb["mass"]).toarray()
        nodes = {nd["name"]: (np.array(nd["at"], float), nd.get("dofs", list(DIRECTIONS)), nd["row"])
                 for nd in fb["nodes"]}
        lines = [[nodes[name] for name in line["nodes"]] for line in fb["lines"]]
        flexible[fb["name"]] = (k_full, m_full, nodes, lines)
        offsets[fb["name"]] = n
        n += k_full.shape[0]
    rigid = {}
    for body in doc["bodies"]:
        dofs = body.get("dofs", list(DIRECTIONS))
        rigid[body["name"]] = (np.array([value(v) for v in body["position"]]), dofs, body)
        offsets[body["name"]] = n
        n += len(dofs)
    big_m = np.zeros((n, n))
    big_k = np.zeros((n, n))
    for name, (k_full, m_full, _, _) in flexible.items():
        sl = slice(offsets[name], offsets[name] + k_full.shape[0])
        big_k[sl, sl] += k_full
        big_m[sl, sl] += m_full
    for name, (_, dofs, body) in rigid.items():
        m = value(body["mass"])
        inertia = np.diag([value(body["inertia"][a]) for a in ("xx", "yy", "zz")])
        c = np.array([value(v) for v in body.get("com", [0, 0, 0])])
        cx = np.array([[0, -c[2], c[1]], [c[2], 0, -c[0]], [-c[1], c[0], 0]])
        # kinetic energy of u + theta x c: M = [[m I, -m [c]x], [m [c]x, J_c + m [c]x^T [c]x]]
        full = np.block([[m * np.eye(3), -m * cx], [m * cx, inertia + m * cx.T @ cx]])
        keep = [DIRECTIONS.index(d) for d in dofs]
        sl = slice(offsets[name], offsets[name] + len(dofs))
        big_m[sl, sl] += full[np.ix_(keep, keep)]

    def motion(body: str, point: object, lever: np.ndarray | None, direction: np.ndarray, rotational: bool,
               ) -> np.ndarray:
        """Row h with h q = the motion of ``point`` on ``body`` along ``direction`` (translation or rotation)."""
        row = np.zeros(n)
        if body == "ground":
            return row
        if body in rigid:
            _, dofs, _ = rigid[body]
            six = np.r_[np.zeros(3), direction] if rotational else np.r_[direction, np.cross(lever, direction)]
            for j, d in enumerate(dofs):
                row[offsets[body] + j] = six[DIRECTIONS.index(d)]
            return row
        _, _, nodes, lines = flexible[body]
        if isinstance(point, str):
            weights = [(nodes[point], 1.0)]
        else:  # a moving point: linear shape functions of the two nodes of the line around it
            xyz = np.array([value(v) for v in point])
            weights = []
            for line in lines:
                start, end = line[0][0], line[-1][0]
                axis = (end - start) / np.linalg.norm(end - start)
                s = (xyz - start) @ axis
                if np.linalg.norm(xyz - start - s * axis) > 1e-9:
                    continue
                knots = [(nd[0] - start) @ axis for nd in line]
                i = min(int(np.searchsorted(knots, s, side="right")) - 1, len(knots) - 2)
                t = (s - knots[i]) / (knots[i + 1] - knots[i])
                weights = [(line[i], 1 - t), (line[i + 1], t)]
                break
            assert weights, (body, point)
        six = np.r_[np.zeros(3), direction] if rotational else np.r_[direction, np.zeros(3)]
        for (_, dofs, first), w in weights:
            for j, d in enumerate(dofs):  # a node's DOFs are consecutive rows from its first
                row[offsets[body] + first + j] += w * six[DIRECTIONS.index(d)]
        return row

    for element in doc["elements"]:
        a, b = element["bodies"]
        if "at" in element:
            where = np.array([value(v) for v in element["at"]])
            pa, pb = where, where
            levers = [where - rigid[x][0] if x in rigid else None for x in (a, b)]
        else:
            pa, pb = element["points"]
            levers = [np.array([value(v) for v in p]) if x in rigid else None for x, p in ((a, pa), (b, pb))]
        frame = np.eye(3)
        if "axes" in element:
            ex = np.array([value(v) for v in element["axes"]["x"]])
            ex /= np.linalg.norm(ex)
            ey = np.array([value(v) for v in element["axes"]["y"]])
            ey -= (ey @ ex) * ex
            ey /= np.linalg.norm(ey)
            frame = np.c_[ex, ey, np.cross(ex, ey)]
        for d, k in element.get("stiffness", {}).items():
            e = frame[:, DIRECTIONS.index(d) % 3]
            rot = d.startswith("r")
            h = motion(b, pb, levers[1], e, rot) - motion(a, pa, levers[0], e, rot)
            big_k += value(k) * np.outer(h, h)
    return big_k, big_m


def test_frequencies_match_an_independent_numpy_assembly_of_the_full_fe_model(model, tmp_path):
    position = {"x": 0.6, "y": 1.2, "z": 0.2}  # shoes mid-element on both lines (x 0.3, 0.9; y 1.0, 1.4)
    big_k, big_m = _independent_matrices(position)
    assert big_k.shape[0] > 700  # the full frames: 390 + 348 DOFs, and the rigid bodies
    full = np.sqrt(np.clip(scipy.linalg.eigh(big_k, big_m, eigvals_only=True), 0, None)) / (2 * np.pi)
    # the same file with fixed-interface modes kept up to 8 x 500 Hz instead of 3 x: the assembly itself agrees to
    # the reduction's error, measured 2.1e-4 at 480 Hz (a wrong lever arm, weight or frame shows at 1e-3 .. 1e-1)
    source = builtin_path("three-axis-machine-tool")
    for f in source.parent.glob("three-axis-machine-tool*"):
        (tmp_path / f.name).write_bytes(f.read_bytes())
    text = source.read_text()
    assert text.count("reduction: {band: 500, multiple: 3}") == 2
    (tmp_path / source.name).write_text(text.replace("multiple: 3}", "multiple: 8}"))
    fine = _modes(NumericModel(load_model(tmp_path / source.name)), position)[0]
    in_band = fine <= BAND_HZ[1]
    np.testing.assert_allclose(fine[in_band], full[: in_band.sum()], rtol=5e-4)
    # the model as shipped (3 x band, 162 DOFs): the price of the smaller model, measured 0.98 % worst (335 Hz),
    # 3e-4 median; the file's text states it
    shipped = _modes(model, position)[0]
    in_band = shipped <= BAND_HZ[1]
    error = np.abs(shipped[in_band] / full[: in_band.sum()] - 1)
    assert error.max() < 1.2e-2
    assert np.median(error) < 1e-3
