"""Flexible bodies from FE matrices: checked against the equivalent rigid body and against the matrices, modes and
FRFs assembled here with numpy from the same FE blocks (independent of cappe's symbolic assembly).

The FE blocks come from cappe's frame generator, which tests/model/test_fe.py checks against analytic beam
frequencies; nothing here depends on its numbers being right, only on them being a valid FE model.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest
import scipy.io
import scipy.linalg
import scipy.sparse as sps

from cappe.exceptions import ModelError
from cappe.modal import modal_batch, modal_derivatives
from cappe.model import NumericModel, StructureBuilder, SymbolicModel, load_model
from cappe.model.fe import BeamSection, frame_model

L_BEAM = 1.2
N_NODES = 7


def _beam(e_factor: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A free-free steel beam along x from 0 to L_BEAM: nodes, dense K and M (6 DOFs per node)."""
    sec = BeamSection.rectangle(0.08, 0.12, E=210e9 * e_factor, nu=0.3, rho=7850.0)
    nodes = np.c_[np.linspace(0, L_BEAM, N_NODES), np.zeros(N_NODES), np.zeros(N_NODES)]
    fm = frame_model(nodes, [[i, i + 1] for i in range(N_NODES - 1)], sec)
    return nodes, fm.stiffness.toarray(), fm.mass.toarray()


def _node_entries(nodes: np.ndarray) -> list[dict[str, object]]:
    return [{"name": f"n{i}", "at": [float(v) for v in p]} for i, p in enumerate(nodes)]


def _rigid_transform(nodes: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """T (6 n_nodes, 6): node DOFs of a rigid motion (translation t, rotation theta about ``centre``)."""
    t = np.zeros((6 * len(nodes), 6))
    for i, p in enumerate(nodes):
        r = p - centre
        t[6 * i:6 * i + 3, :3] = np.eye(3)
        # theta x r = -[r]x theta
        t[6 * i:6 * i + 3, 3:] = -np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])
        t[6 * i + 3:6 * i + 6, 3:] = np.eye(3)
    return t


SUPPORT = {"x": 2.0e6, "y": 3.0e6, "z": 4.0e6}


def _supported(builder: StructureBuilder, body: str, left: object, right: object) -> None:
    builder.element("left", bodies=["ground", body], at=[0.0, 0.0, 0.0], stiffness={**SUPPORT, "rx": 5.0e4})
    builder.element("right", bodies=["ground", body], at=[L_BEAM, 0.0, 0.0], stiffness=SUPPORT)
    builder.sensor("a", body=body, point=left)
    builder.sensor("b", body=body, point=right)


def test_very_stiff_flexible_body_has_the_modes_of_the_equivalent_rigid_body() -> None:
    nodes, k, m = _beam()
    flex = StructureBuilder("flex")
    flex.parameter("s_k", 1.0e4, kind="other")  # 10^4 times steel: elastic modes far above the suspension's
    flex.flexible_body("beam", mass=m, stiffness=k, nodes=_node_entries(nodes), stiffness_scale="s_k")
    _supported(flex, "beam", "n0", f"n{N_NODES - 1}")
    # the equivalent rigid body: the FE mass matrix's rigid-body projection, computed here with numpy
    centre = np.array([L_BEAM / 2, 0.0, 0.0])
    t = _rigid_transform(nodes, centre)
    m_rigid = t.T @ m @ t
    mass = m_rigid[0, 0]
    np.testing.assert_allclose(m_rigid[:3, :3], mass * np.eye(3), rtol=1e-12)
    np.testing.assert_allclose(m_rigid[:3, 3:], 0.0, atol=1e-9 * mass)  # the centre is the centre of mass
    rigid = StructureBuilder("rigid")
    rigid.body("beam", mass=float(mass), inertia=m_rigid[3:, 3:].tolist(), position=centre.tolist())
    _supported(rigid, "beam", [-L_BEAM / 2, 0, 0], [L_BEAM / 2, 0, 0])
    fb = modal_batch(flex.build(), n_modes=6, sensors="dofs")
    rb = modal_batch(rigid.build(), n_modes=6, sensors="dofs")
    # error of a stiff body's elastic compliance: (f_suspension / f_elastic)^2 ~ (20 Hz / 2 kHz)^2 = 1e-4
    np.testing.assert_allclose(fb.frequency, rb.frequency, rtol=2e-4)
    # the flexible shapes' rigid-body part (least squares onto T) against the rigid body's DOFs (about the centre)
    phi_f = np.linalg.lstsq(t, fb.shapes[0], rcond=None)[0]
    phi_r = rb.shapes[0]
    mac = (np.sum(phi_f * phi_r, axis=0) ** 2) / (np.sum(phi_f**2, axis=0) * np.sum(phi_r**2, axis=0))
    assert mac.min() > 0.9999
    # and the flexible body as soft as steel is not rigid: its first elastic mode is in the range
    soft = modal_batch(flex.build(), {"s_k": 1.0}, n_modes=8)
    assert soft.frequency[0, 6] < 0.5 * modal_batch(flex.build(), n_modes=8).frequency[0, 6]


def _coupled(damping: dict[str, object] | None) -> tuple[StructureBuilder, np.ndarray, np.ndarray]:
    nodes, k, m = _beam()
    b = StructureBuilder("coupled")
    b.parameter("kc", 5.0e6, kind="stiffness")
    b.parameter("cc", 300.0, kind="damping")
    b.parameter("s_k", 1.0, kind="other", bounds=[0.5, 2.0], unknown=True)
    b.parameter("s_m", 1.0, kind="other", bounds=[0.5, 2.0], unknown=True)
    b.body("table", mass=25.0, dofs=["z"], position=[L_BEAM / 2, 0, 0.3])
    b.flexible_body("beam", mass=m, stiffness=k, nodes=_node_entries(nodes), stiffness_scale="s_k",
                    mass_scale="s_m", damping=damping)
    _supported(b, "beam", "n0", f"n{N_NODES - 1}")
    mid = N_NODES // 2
    b.element("shoe", bodies=["beam", "table"], points=[f"n{mid}", [0, 0, 0]], stiffness={"z": "kc"},
              damping={"z": "cc"})
    b.input("F", body="table", direction="z")
    b.input("Fb", body="beam", point=f"n{N_NODES - 1}", direction="y")
    b.output("d", body="table", direction="z")
    b.output("dn", body="beam", point="n1", direction="y", quantity="acceleration")
    return b, k, m


def _numpy_assembly(k: np.ndarray, m: np.ndarray, s_k: float, s_m: float, c_fe: np.ndarray,
                    h_fe: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """M, C, K, H of the coupled model written out by hand: DOF 0 the table's z, then the beam's 6 N DOFs."""
    n = 1 + k.shape[0]
    big_m, big_k, big_c, big_h = (np.zeros((n, n)) for _ in range(4))
    big_m[0, 0] = 25.0
    big_m[1:, 1:] = s_m * m
    big_k[1:, 1:] = s_k * k
    big_c[1:, 1:] = c_fe
    big_h[1:, 1:] = h_fe
    for node in (0, N_NODES - 1):
        for a, d in enumerate("xyz"):
            i = 1 + 6 * node + a
            big_k[i, i] += SUPPORT[d]
    big_k[1 + 3, 1 + 3] += 5.0e4  # the left support's rx
    zb = 1 + 6 * (N_NODES // 2) + 2
    for mat, value in ((big_k, 5.0e6), (big_c, 300.0)):
        mat[np.ix_([0, zb], [0, zb])] += value * np.array([[1.0, -1.0], [-1.0, 1.0]])
    return big_m, big_c, big_k, big_h


@pytest.mark.parametrize("kind", ["rayleigh", "loss", "modal"])
def test_matrices_modes_and_frf_match_a_numpy_assembly(kind: str) -> None:
    spec = {"rayleigh": {"rayleigh": [2.0, 1.0e-5]}, "loss": {"loss": 0.004}, "modal": {"modal": [0.01, 0.02]}}
    b, k, m = _coupled(spec[kind])
    s_k, s_m = 1.3, 0.8
    if kind == "rayleigh":
        c_fe, h_fe = 2.0 * s_m * m + 1.0e-5 * s_k * k, np.zeros_like(k)
    elif kind == "loss":
        c_fe, h_fe = np.zeros_like(k), 0.004 * s_k * k
    else:  # modal damping of the scaled body's own free modes, with numpy: lowest elastic modes 1 % and 2 %, rest 2 %
        lam, phi = scipy.linalg.eigh(s_k * k, s_m * m)
        elastic = lam > 1e-6 * lam.max()
        zeta = np.where(np.cumsum(elastic) == 1, 0.01, 0.02)[elastic]
        mp = s_m * m @ phi[:, elastic]
        c_fe, h_fe = (mp * 2 * zeta * np.sqrt(lam[elastic])) @ mp.T, np.zeros_like(k)
    big_m, big_c, big_k, big_h = _numpy_assembly(k, m, s_k, s_m, c_fe, h_fe)
    nm = NumericModel(b.build())
    params = {"s_k": s_k, "s_m": s_m}
    mats = nm.matrices(params)
    scale = {"M": big_m, "C": big_c, "K": big_k, "H": big_h}
    for name, ref in scale.items():
        np.testing.assert_allclose(mats[name], ref, rtol=0, atol=1e-9 * abs(ref).max(initial=1.0))
    # FRF: (K + 1j H + 1j w C - w^2 M)^-1 by numpy, input table z and beam end y; outputs table z, accel n1 y
    freq = np.linspace(5.0, 800.0, 60)
    frf = nm.system(params).frf(freq).H
    bvec = np.zeros((big_m.shape[0], 2))
    bvec[0, 0] = 1.0
    bvec[1 + 6 * (N_NODES - 1) + 1, 1] = 1.0
    svec = np.zeros((2, big_m.shape[0]))
    svec[0, 0] = 1.0
    svec[1, 1 + 6 + 1] = 1.0
    for j, f in enumerate(freq):
        w = 2 * np.pi * f
        x = np.linalg.solve(big_k + 1j * big_h + 1j * w * big_c - w**2 * big_m, bvec)
        ref = svec @ x
        ref[1] *= -(w**2)  # the second output is an acceleration
        np.testing.assert_allclose(frf[:, :, j], ref, rtol=1e-8, atol=1e-12 * abs(ref).max())
    # modes: frequencies from scipy on the numpy matrices, first-order damping ratios from the numpy C and H
    batch = modal_batch(nm, params, sensors="dofs")
    lam, phi = scipy.linalg.eigh(big_k, big_m)
    np.testing.assert_allclose(batch.frequency[0], np.sqrt(lam) / (2 * np.pi), rtol=1e-8)
    w = np.sqrt(lam)
    zeta = (np.einsum("im,ij,jm->m", phi, big_c, phi) / (2 * w) + np.einsum("im,ij,jm->m", phi, big_h, phi)
            / (2 * w**2))
    np.testing.assert_allclose(batch.damping[0], zeta, rtol=1e-7, atol=1e-12)


def test_scale_factor_derivatives_match_finite_differences_and_the_matrices() -> None:
    b, k, m = _coupled({"loss": 0.004})
    nm = NumericModel(b.build())
    p0 = {"s_k": 1.2, "s_m": 0.9}
    deriv = nm.matrix_derivatives(p0, names=("M", "K", "H"), parameters=["s_k", "s_m"])
    n = k.shape[0]
    np.testing.assert_array_equal(deriv["K"][0][-n:, -n:], k)  # exact: the block itself
    np.testing.assert_array_equal(deriv["M"][1][-n:, -n:], m)
    np.testing.assert_allclose(deriv["H"][0][-n:, -n:], 0.004 * k, rtol=1e-15)
    # modal derivatives (analytic, the modal engine's) against central differences of the modal engine
    md = modal_derivatives(nm, p0, n_modes=10, sensors=["a", "b"])
    names = list(nm.parameter_names)
    for pname in ("s_k", "s_m"):
        # the step: the damping ratios' rounding (about 4e-14 absolute on the 1.1e-3 of mode 2, whether from the
        # reduced patterns' sums or from scipy's eigh(K, M), which misses this derivative by 5e-5 at 1e-6) is 1e-3 of
        # the change over a 1e-6 step, 1e-4 over 1e-5; the truncation error there is O(h^2) ~ 1e-10
        h = 1e-5
        up = modal_batch(nm, {**p0, pname: p0[pname] + h}, n_modes=10)
        down = modal_batch(nm, {**p0, pname: p0[pname] - h}, n_modes=10)
        fd_f = (up.frequency[0] - down.frequency[0]) / (2 * h)
        fd_z = (up.damping[0] - down.damping[0]) / (2 * h)
        col = names.index(pname)
        np.testing.assert_allclose(md.d_frequency[:, col], fd_f, rtol=1e-5, atol=1e-6 * abs(fd_f).max())
        np.testing.assert_allclose(md.d_damping[:, col], fd_z, rtol=1e-4, atol=1e-6 * abs(fd_z).max())
    # a pure stiffness scale: f ~ sqrt(s_k) for the modes of the free body... here coupled, so only the sign
    assert (md.d_frequency[:, names.index("s_m")] < 0).all()


def _write_model(tmp_path: Path, extra: str = "", *, mass: str = "beam_M.mtx", stiffness: str = "stiff: {file: beam.npz, key: K}") -> Path:
    nodes, k, m = _beam()
    scipy.io.mmwrite(str(tmp_path / "beam_M.mtx"), sps.coo_matrix(m))
    np.savez(tmp_path / "beam.npz", K=k, M=m)
    scipy.io.savemat(str(tmp_path / "beam.mat"), {"K": k, "M": m})
    node_lines = "\n".join(f"      - {{name: n{i}, at: [{float(p[0])!r}, 0.0, 0.0]}}" for i, p in enumerate(nodes))
    text = textwrap.dedent(f"""\
        format: cappe.model/1
        name: beam-on-mounts
        parameters:
          - {{name: s_k, value: 1.0, kind: other, bounds: [0.5, 2.0], unknown: true}}
        flexible_bodies:
          - name: beam
            mass: {mass}
            stiffness: STIFF
            stiffness_scale: s_k
            damping: {{loss: 0.002}}
            nodes:
        NODES
        elements:
          - {{name: left, bodies: [ground, beam], points: [[0, 0, 0], n0], stiffness: {{x: 2.0e6, y: 3.0e6, z: 4.0e6, rx: 5.0e4}}}}
          - {{name: right, bodies: [ground, beam], at: [{L_BEAM!r}, 0, 0], stiffness: {{x: 2.0e6, y: 3.0e6, z: 4.0e6}}}}
        sensors:
          - {{name: mid, body: beam, point: n3}}
        {extra}
        """).replace("NODES", node_lines).replace("STIFF", stiffness.split(": ", 1)[1])
    path = tmp_path / "model.yaml"
    path.write_text(text)
    return path


def test_yaml_reads_mtx_npz_and_mat_relative_to_the_model_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    nodes, k, m = _beam()
    monkeypatch.chdir(Path("/"))  # paths are relative to the model file, not the working directory
    ref = None
    for mass, stiffness in (("beam_M.mtx", "stiff: {file: beam.npz, key: K}"),
                            ("{file: beam.mat, key: M}", "stiff: {file: beam.mat, key: K}")):
        s = load_model(_write_model(tmp_path, mass=mass, stiffness=stiffness))
        assert s.n_dof == 6 * N_NODES
        assert s.dofs[:2] == ("beam.n0.x", "beam.n0.y")
        mats = NumericModel(s).matrices()
        np.testing.assert_allclose(mats["M"], m, rtol=1e-12, atol=1e-12 * abs(m).max())
        f = modal_batch(s, n_modes=8).frequency
        ref = f if ref is None else ref
        np.testing.assert_allclose(f, ref, rtol=1e-9)


def test_symbolic_and_exact_paths_refuse_flexible_models_with_a_clear_message() -> None:
    b, _, _ = _coupled(None)
    sym = SymbolicModel(b.build())
    with pytest.raises(ModelError, match=r"flexible bodies \(beam\) given by numeric FE matrices: symbolic and exact"):
        _ = sym.K


@pytest.mark.parametrize(("change", "match"), [
    (lambda k, m: (k, m[:-1, :-1]), r"same order; got 41 and 42"),
    (lambda k, m: (k + np.triu(1e-6 * abs(k).max() * np.ones_like(k), 1), m),
     r"stiffness matrix must be symmetric; entries \[0, 1\] and \[1, 0\] differ by"),
    (lambda k, m: (k, -m), r"mass matrix must be positive definite; its smallest eigenvalue"),
    (lambda k, m: (k - 1e3 * m, m), r"stiffness matrix must be positive semi-definite"),
    (lambda k, m: (k * np.nan, m), r"stiffness matrix has NaN or inf entries"),
])
def test_bad_matrices_are_one_line_errors_naming_the_entry(change: object, match: str) -> None:
    nodes, k, m = _beam()
    k2, m2 = change(k, m)  # type: ignore[operator]
    b = StructureBuilder("bad", source="model.yaml")
    with pytest.raises(ModelError, match=match + r".*\(model.yaml, flexible_bodies\[0\]"):
        b.flexible_body("beam", mass=m2, stiffness=k2, nodes=_node_entries(nodes))


def test_bad_files_and_nodes_are_one_line_errors(tmp_path: Path) -> None:
    nodes, k, m = _beam()
    np.save(tmp_path / "obj.npy", np.array([1], dtype=object), allow_pickle=True)
    np.savez(tmp_path / "objs.npz", K=np.array([{"a": 1}], dtype=object))
    (tmp_path / "junk.mtx").write_text("not a matrix market file\n")
    np.savez(tmp_path / "two.npz", K=k, M=m)
    (tmp_path / "empty.mat").write_bytes(b"")
    scipy.io.savemat(tmp_path / "whole.mat", {"K": k})
    (tmp_path / "cut.mat").write_bytes((tmp_path / "whole.mat").read_bytes()[:150])
    # a MATLAB v7.3 header (116 bytes of text, 8 of subsystem offset, version 0x0200, endian 'IM'), then HDF5
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, HDF5 schema 1.00 .".ljust(116) + bytes(8) + b"\x00\x02IM"
    (tmp_path / "v73.mat").write_bytes(header + b"\x89HDF\r\n\x1a\n" + bytes(64))
    b = StructureBuilder("bad", source="m.yaml", base=tmp_path)
    cases = [
        ("empty.mat", r"cannot read matrix file .*empty.mat: .*\(m.yaml, flexible_bodies\[0\].mass\)"),
        ("cut.mat", r"cannot read matrix file .*cut.mat: .*\(m.yaml, flexible_bodies\[0\].mass\)"),
        ("v73.mat", r"v73.mat is a MATLAB v7.3 \(HDF5\) file: save it with .*-v7.*\(m.yaml, flexible_bodies\[0\].mass\)"),
        ("objs.npz", r"cannot read matrix file .*objs.npz: .*pickle.*\(m.yaml, flexible_bodies\[0\].mass\)"),
        ("junk.mtx", r"cannot read matrix file .*junk.mtx.*\(m.yaml, flexible_bodies\[0\].mass\)"),
        ("two.npz", r"holds K, M: name one with 'key' \(m.yaml, flexible_bodies\[0\].mass\)"),
        ({"file": "two.npz", "key": "X"}, r"has no entry 'X'; it holds K, M \(m.yaml, flexible_bodies\[0\].mass.key\)"),
        ("missing.mtx", r"cannot read matrix file .*missing.mtx: No such file"),
        ("obj.npy", r"must end in .mtx, .mat, .npz; got '.npy'"),
    ]
    for i, (spec, match) in enumerate(cases):
        with pytest.raises(ModelError, match=match):
            b.flexible_body(f"beam{i}", mass=spec, stiffness=k, nodes=_node_entries(nodes),
                            where="m.yaml, flexible_bodies[0]")
    with pytest.raises(ModelError, match=r"node 'n2' row 6 is already node 'n1''s \(m.yaml, flexible_bodies\[0\].nodes\[2\].row\)"):
        b.flexible_body("beam_r", mass=m, stiffness=k, where="m.yaml, flexible_bodies[0]",
                        nodes=[{"name": "n0", "at": [0, 0, 0]}, {"name": "n1", "at": [1, 0, 0], "row": 6},
                               {"name": "n2", "at": [2, 0, 0], "row": 6}])
    b.flexible_body("beam", mass=m, stiffness=k, nodes=_node_entries(nodes))
    with pytest.raises(ModelError, match=r"point \[0.5, 0.0, 0.0\] is not at one of flexible body 'beam''s interface nodes"):
        b.element("e", bodies=["ground", "beam"], at=[0.5, 0, 0], stiffness={"x": 1.0})
    with pytest.raises(ModelError, match=r"flexible body 'beam' has no node 'n99'"):
        b.sensor("s", body="beam", point="n99")
    # rigid and flexible bodies share one name space, and 'ground' names neither
    with pytest.raises(ModelError, match=r"'ground' is reserved .* \(m.yaml, flexible_bodies\[1\]\)"):
        b.flexible_body("ground", mass=m, stiffness=k, nodes=_node_entries(nodes))
    with pytest.raises(ModelError, match=r"duplicate body name 'beam' \(m.yaml, bodies\[0\]\); first defined at "
                                         r"m.yaml, flexible_bodies\[0\]"):
        b.body("beam", mass=1.0)


def test_a_node_without_the_dof_an_element_needs_is_an_error() -> None:
    nodes, k, m = _beam()
    entries = _node_entries(nodes)
    b = StructureBuilder("partial")
    # only the translations of n0 are interface DOFs named here; its rotations become q1..q3
    entries[0] = {**entries[0], "dofs": ["x", "y", "z"]}
    entries[1] = {**entries[1], "row": 6}
    b.flexible_body("beam", mass=m, stiffness=k, nodes=entries)
    b.element("torsion", bodies=["ground", "beam"], points=[[0, 0, 0], "n0"], stiffness={"rx": 1.0e4})
    with pytest.raises(ModelError, match=r"element 'torsion' direction 'rx' acts along rx on flexible body 'beam', at a node without that DOF"):
        NumericModel(b.build())


def test_interior_sensor_uses_the_recovery_matrix() -> None:
    nodes, k, m = _beam()
    rec = np.zeros((3, k.shape[0]))
    rec[:, 6 * 3:6 * 3 + 3] = 0.5 * np.eye(3)
    rec[:, 6 * 4:6 * 4 + 3] = 0.5 * np.eye(3)  # halfway between n3 and n4
    b = StructureBuilder("rec")
    b.flexible_body("beam", mass=m, stiffness=k, nodes=_node_entries(nodes),
                    recovery={"matrix": rec, "nodes": [{"name": "h", "at": [0.5 * (nodes[3, 0] + nodes[4, 0]), 0, 0],
                                                        "dofs": ["x", "y", "z"]}]})
    b.element("left", bodies=["ground", "beam"], at=[0, 0, 0], stiffness={**SUPPORT, "rx": 5.0e4})
    b.sensor("h", body="beam", point="h")
    b.output("hz", body="beam", point="h", direction="z")
    nm = NumericModel(b.build())
    labels, rows = nm.sensor_matrix()
    assert labels == ["h:x", "h:y", "h:z"]
    np.testing.assert_array_equal(rows, rec)
    np.testing.assert_array_equal(nm.io_matrices()[1][0], rec[2])


def _carriage_on_rail(position: object, point: object, interpolation: str = "linear") -> StructureBuilder:
    """A 30 kg carriage (y, z) on a guide shoe riding the beam at ``point``, the carriage at ``position``."""
    nodes, k, m = _beam()
    b = StructureBuilder("rail")
    b.axis("p", [0.0, 0.3, 0.6, 1.2])
    b.flexible_body("beam", mass=m, stiffness=k, nodes=_node_entries(nodes),
                    lines=[{"name": "rail", "nodes": [f"n{i}" for i in range(N_NODES)],
                            "interpolation": interpolation}])
    _supported(b, "beam", "n0", f"n{N_NODES - 1}")
    b.body("carriage", mass=30.0, dofs=["y", "z"], position=position)
    b.element("shoe", bodies=["beam", "carriage"], points=[point, [0, 0, -0.1]],
              stiffness={"y": 4.0e7, "z": 6.0e7})
    return b


def test_moving_interface_is_exact_at_nodes_and_continuous_in_between() -> None:
    moving = NumericModel(_carriage_on_rail(["p", 0, 0.1], ["p", 0, 0]).build())
    step = L_BEAM / (N_NODES - 1)
    for node in (0, 2, 5):
        fixed = NumericModel(_carriage_on_rail([node * step, 0, 0.1], f"n{node}").build())
        # at a node: the model with the shoe fixed on that node; the shape functions there are 1 and 0 up to the
        # rounding of the knots (1e-16), which a pair of close modes (33.47 / 33.49 Hz) amplifies to 1e-11
        np.testing.assert_allclose(modal_batch(moving, position={"p": node * step}, n_modes=12).frequency,
                                   modal_batch(fixed, n_modes=12).frequency, rtol=1e-9)
    # continuity: the frequency change over a position step shrinks with the step (at a node and mid-element)
    for centre in (2 * step, 2.5 * step):
        jumps = []
        for eps in (1e-3, 1e-5):
            lo = modal_batch(moving, position={"p": centre - eps}, n_modes=12).frequency[0]
            hi = modal_batch(moving, position={"p": centre + eps}, n_modes=12).frequency[0]
            jumps.append(np.abs(hi - lo).max())
        assert jumps[1] < 2e-2 * jumps[0] + 1e-9  # Lipschitz: 100 times smaller step, about 100 times smaller change
    # over the whole travel, neighbouring positions 1 mm apart differ by little (no jumps between elements)
    sweep = np.linspace(0.0, L_BEAM, 241)
    freq = np.array([modal_batch(moving, position={"p": v}, n_modes=12).frequency[0] for v in sweep])
    assert np.max(np.abs(np.diff(freq, axis=0)) / freq[:-1]) < 0.02
    # the carriage's weight moves the frequencies: the position matters
    assert np.ptp(freq[:, 6]) > 0.01 * freq[:, 6].mean()


def test_hermite_line_is_exact_at_nodes_and_c1_in_between() -> None:
    hermite = NumericModel(_carriage_on_rail(["p", 0, 0.1], ["p", 0, 0], "hermite").build())
    linear = NumericModel(_carriage_on_rail(["p", 0, 0.1], ["p", 0, 0]).build())
    step = L_BEAM / (N_NODES - 1)
    for node in (0, 2, 5):
        fixed = NumericModel(_carriage_on_rail([node * step, 0, 0.1], f"n{node}").build())
        # the close pair 33.47 / 33.49 Hz amplifies the rounding of the cubic weights at a node (1e-16) to 2e-9
        np.testing.assert_allclose(modal_batch(hermite, position={"p": node * step}, n_modes=12).frequency,
                                   modal_batch(fixed, n_modes=12).frequency, rtol=1e-8)

    def freq(model: NumericModel, p: float) -> np.ndarray:
        return modal_batch(model, position={"p": p}, n_modes=12).frequency[0]

    # the derivative of the frequencies over the position, from the left and from the right of node 2: linear
    # shape functions put a kink there (their slope jumps), the beam element's cubic does not (C1)
    h = 1e-4
    jumps = {}
    for label, model in (("linear", linear), ("hermite", hermite)):
        at = freq(model, 2 * step)
        left = (at - freq(model, 2 * step - h)) / h
        right = (freq(model, 2 * step + h) - at) / h
        jumps[label] = (np.abs(right - left).max(), np.abs(right).max())
    # the carriage's weight moves the frequencies: the slopes are not zero
    assert jumps["hermite"][1] > 1.0  # Hz/m
    # C1: the one-sided slopes differ by O(h) (second derivative times h); linear: by O(1)
    assert jumps["hermite"][0] < 2e-2 * jumps["hermite"][1], jumps
    assert jumps["linear"][0] > 30 * jumps["hermite"][0], jumps
    # continuous: a sweep over the travel has no jumps between elements
    sweep = np.linspace(0.0, L_BEAM, 121)
    values = np.array([freq(hermite, v) for v in sweep])
    assert np.max(np.abs(np.diff(values, axis=0)) / values[:-1]) < 0.02


def test_hermite_interpolation_needs_six_dof_nodes_and_a_known_name() -> None:
    nodes, k, m = _beam()
    entries = _node_entries(nodes)
    with pytest.raises(ModelError, match=r"line 'rail' interpolation must be 'linear' or 'hermite' \(beam elements: "
                                         r"cubic with the rotations\); got 'cubic' \(flexible_bodies\[0\].lines\[0\]"
                                         r".interpolation\)"):
        StructureBuilder("b").flexible_body("beam", mass=m, stiffness=k, nodes=entries,
                                            lines=[{"name": "rail", "nodes": ["n0", "n1"], "interpolation": "cubic"}])


def test_moving_point_must_follow_a_line_of_nodes() -> None:
    with pytest.raises(ModelError, match=r"a moving point on flexible body 'beam' must travel along one of its lines of nodes \(rail\); \['p', '0', '1/20'\] does not \(elements\[2\].points\[0\]\)"):
        _carriage_on_rail(["p", 0, 0.1], ["p", 0, 0.05])
    with pytest.raises(ModelError, match=r"moving point \['2\*p', '0', '0'\] leaves line 'rail' of flexible body 'beam' \(s = 2.4 m, the line spans 0 .. 1.2\) at p = 1.2 \(elements\[2\].points\[0\]\)"):
        _carriage_on_rail(["2*p", 0, 0.1], ["2*p", 0, 0])


def test_recovery_matrix_from_a_file_is_rectangular(tmp_path: Path) -> None:
    nodes, k, m = _beam()
    rec = np.zeros((3, k.shape[0]))
    rec[:, 6 * 3:6 * 3 + 3] = np.eye(3)
    np.savez(tmp_path / "rec.npz", T=rec)
    b = StructureBuilder("rec", base=tmp_path)
    b.flexible_body("beam", mass=m, stiffness=k, nodes=_node_entries(nodes),
                    recovery={"matrix": {"file": "rec.npz", "key": "T"},
                              "nodes": [{"name": "c", "at": [0.0, 0.1, 0.0], "dofs": ["x", "y", "z"]}]})
    b.sensor("c", body="beam", point="c")
    np.testing.assert_array_equal(NumericModel(b.build()).sensor_matrix()[1], rec)


def test_lagrange_derivation_refuses_flexible_models() -> None:
    from cappe.model.lagrange import lagrange_matrices

    b, _, _ = _coupled(None)
    with pytest.raises(ModelError, match=r"model 'coupled' has flexible bodies \(beam\) given by numeric FE matrices: the Lagrange derivation is for rigid-body models"):
        lagrange_matrices(b.build())


def test_sensor_coordinates_on_a_flexible_body_are_its_nodes() -> None:
    from cappe.modal import sensor_coordinates

    nodes, k, m = _beam()
    b = StructureBuilder("placed")
    b.flexible_body("beam", mass=m, stiffness=k, nodes=_node_entries(nodes), position=[0.0, 0.5, 1.0])
    b.element("left", bodies=["ground", "beam"], points=[[0.0, 0.5, 1.0], "n0"], stiffness={**SUPPORT, "rx": 5.0e4})
    b.element("right", bodies=["ground", "beam"], at=[L_BEAM, 0.5, 1.0], stiffness=SUPPORT)
    b.sensor("a", body="beam", point="n0")
    b.sensor("b", body="beam", point="n2")
    # the node's coordinates in the body frame plus the body's position
    assert sensor_coordinates(b.build()) == {"a": (0.0, 0.5, 1.0), "b": (float(nodes[2, 0]), 0.5, 1.0)}


# -- points offset from a node (a massless rigid link) ---------------------------------------------------------------
OFFSET = [0.05, -0.08, 0.15]  # from node n3 (beam's middle) to the shoe; every rotation takes part in theta x d


def _offset_shoe(point: object, *, e_factor: float = 1.0) -> StructureBuilder:
    """The free-free beam on its supports, a 30 kg carriage (x, y, z) on a shoe at ``point`` of the beam, a force on
    the beam at ``point`` and a sensor there."""
    nodes, k, m = _beam(e_factor)
    b = StructureBuilder("offset")
    b.flexible_body("beam", mass=m, stiffness=k, nodes=_node_entries(nodes))
    _supported(b, "beam", "n0", f"n{N_NODES - 1}")
    b.body("carriage", mass=30.0, dofs=["x", "y", "z"], position=[L_BEAM / 2 + OFFSET[0], OFFSET[1], OFFSET[2]])
    b.element("shoe", bodies=["beam", "carriage"], points=[point, [0, 0, 0]],
              stiffness={"x": 2.0e7, "y": 4.0e7, "z": 6.0e7})
    b.input("F", body="beam", point=point, direction=[0.0, 0.6, 0.8])
    b.sensor("s", body="beam", point=point)
    b.output("sz", body="beam", point=point, direction="z")
    return b


def _offset_by_hand() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """K, M (the carriage's x y z, then the beam's 6 N DOFs), the offset point's displacement rows R (3, n) and the
    force's column, written out with numpy from u_P = u_n3 + theta_n3 x d."""
    nodes, k, m = _beam()
    n_beam = k.shape[0]
    n = n_beam + 3
    big_k, big_m = np.zeros((n, n)), np.zeros((n, n))
    big_k[:n_beam, :n_beam], big_m[:n_beam, :n_beam] = k, m
    big_m[n_beam:, n_beam:] = 30.0 * np.eye(3)
    for node, extra in ((0, {"rx": 5.0e4}), (N_NODES - 1, {})):
        for a, d in enumerate(("x", "y", "z", "rx")):
            value = {**SUPPORT, **extra}.get(d)
            if value is not None:
                big_k[6 * node + a, 6 * node + a] += value
    d = np.array(OFFSET)
    skew = np.array([[0, -d[2], d[1]], [d[2], 0, -d[0]], [-d[1], d[0], 0]])  # [d]x: theta x d = -[d]x theta
    rows = np.zeros((3, n))
    rows[:, 6 * 3:6 * 3 + 3] = np.eye(3)
    rows[:, 6 * 3 + 3:6 * 3 + 6] = -skew
    for a, kd in enumerate((2.0e7, 4.0e7, 6.0e7)):
        h = -rows[a].copy()
        h[n_beam + a] += 1.0
        big_k += kd * np.outer(h, h)
    force = rows.T @ np.array([0.0, 0.6, 0.8])
    order = np.r_[n_beam:n, 0:n_beam]  # cappe's order: rigid bodies' DOFs first, then flexible bodies'
    return big_k[np.ix_(order, order)], big_m[np.ix_(order, order)], rows[:, order], force[order]


def test_point_offset_from_a_node_moves_with_the_nodes_rotation_as_numpy_assembles_it() -> None:
    point = {"node": "n3", "offset": OFFSET}
    nm = NumericModel(_offset_shoe(point).build())
    big_k, big_m, rows, force = _offset_by_hand()
    mats = nm.matrices()
    np.testing.assert_allclose(mats["K"], big_k, rtol=0, atol=1e-9 * abs(big_k).max())
    np.testing.assert_allclose(mats["M"], big_m, rtol=0, atol=1e-12 * abs(big_m).max())
    labels, sensor_rows = nm.sensor_matrix()
    assert labels[-3:] == ["s:x", "s:y", "s:z"]
    np.testing.assert_allclose(sensor_rows[-3:], rows, rtol=0, atol=1e-15)
    # modes from scipy on the numpy matrices; the shapes at the offset sensor
    lam, phi = scipy.linalg.eigh(big_k, big_m)
    batch = modal_batch(nm, n_modes=12)
    np.testing.assert_allclose(batch.frequency[0], np.sqrt(lam[:12]) / (2 * np.pi), rtol=1e-8)
    ref = rows @ phi[:, :12]
    got = batch.shapes[0][-3:]
    mac = np.sum(got * ref, axis=0) ** 2 / (np.sum(got**2, axis=0) * np.sum(ref**2, axis=0))
    assert mac.min() > 1 - 1e-8
    # the force at the offset point: its moment about the node reaches the node's rotations
    frf = nm.system().frf([37.0]).H
    w = 2 * np.pi * 37.0
    x = np.linalg.solve(big_k - w**2 * big_m, force)
    np.testing.assert_allclose(frf[0, 0, 0], rows[2] @ x, rtol=1e-9)


def test_point_offset_from_a_very_stiff_body_is_the_rigid_bodys_point() -> None:
    nodes, k, m = _beam()
    flex = NumericModel(_offset_shoe({"node": "n3", "offset": OFFSET}, e_factor=1.0e4).build())
    # the rigid equivalent (numpy projection of the FE mass, as above), the shoe at the same point of the rigid body
    centre = np.array([L_BEAM / 2, 0.0, 0.0])
    t = _rigid_transform(nodes, centre)
    m_rigid = t.T @ m @ t
    rigid = StructureBuilder("rigid")
    rigid.body("beam", mass=float(m_rigid[0, 0]), inertia=m_rigid[3:, 3:].tolist(), position=centre.tolist())
    _supported(rigid, "beam", [-L_BEAM / 2, 0, 0], [L_BEAM / 2, 0, 0])
    rigid.body("carriage", mass=30.0, dofs=["x", "y", "z"], position=[L_BEAM / 2 + OFFSET[0], OFFSET[1], OFFSET[2]])
    rigid.element("shoe", bodies=["beam", "carriage"], points=[OFFSET, [0, 0, 0]],
                  stiffness={"x": 2.0e7, "y": 4.0e7, "z": 6.0e7})
    fb = modal_batch(flex, n_modes=9)
    rb = modal_batch(rigid.build(), n_modes=9)
    # the stiff beam's compliance against the shoe's and supports': (f / f_elastic)^2 with f_elastic ~ 20 kHz
    # (measured 1.5e-5; 0.49 with the shoe on the node itself, below)
    np.testing.assert_allclose(fb.frequency, rb.frequency, rtol=5e-5)
    # the same frequencies from a node-only point differ: the offset matters (rotations of the beam take part)
    at_node = modal_batch(NumericModel(_offset_shoe("n3", e_factor=1.0e4).build()), n_modes=9)
    assert np.max(np.abs(at_node.frequency / rb.frequency - 1)) > 1e-2


def test_offset_points_in_a_model_file_and_their_errors(tmp_path: Path) -> None:
    nodes, k, m = _beam()
    np.savez(tmp_path / "beam.npz", K=k, M=m)
    node_lines = "\n".join(f"      - {{name: n{i}, at: [{float(p[0])!r}, 0, 0]}}" for i, p in enumerate(nodes))
    text = textwrap.dedent("""\
        name: offset
        flexible_bodies:
          - name: beam
            mass: {file: beam.npz, key: M}
            stiffness: {file: beam.npz, key: K}
            nodes:
        NODES
        bodies:
          - {name: carriage, mass: 30.0, dofs: [x, y, z], position: [0.65, -0.08, 0.15]}
        elements:
          - {name: left, bodies: [ground, beam], points: [[0, 0, 0], n0], stiffness: {x: 2.0e6, y: 3.0e6, z: 4.0e6, rx: 5.0e4}}
          - {name: right, bodies: [ground, beam], points: [[1.2, 0, 0], n6], stiffness: {x: 2.0e6, y: 3.0e6, z: 4.0e6}}
          - {name: shoe, bodies: [beam, carriage], points: [POINT, [0, 0, 0]], stiffness: {x: 2.0e7, y: 4.0e7, z: 6.0e7}}
        inputs:
          - {name: F, body: beam, point: POINT, direction: [0, 0.6, 0.8]}
        sensors:
          - {name: s, body: beam, point: POINT}
        """).replace("NODES", node_lines)
    path = tmp_path / "offset.yml"
    path.write_text(text.replace("POINT", "{node: n3, offset: [0.05, -0.08, 0.15]}"))
    nm = NumericModel(load_model(path))
    big_k, big_m, rows, _ = _offset_by_hand()
    np.testing.assert_allclose(nm.matrices()["K"], big_k, rtol=0, atol=1e-9 * abs(big_k).max())
    np.testing.assert_allclose(nm.sensor_matrix()[1], rows, rtol=0, atol=1e-15)
    # the node's rotations: q1..q3 (its translations only are named interface DOFs)
    n3 = f"{{name: n3, at: [{float(nodes[3, 0])!r}, 0, 0]}}"
    assert n3 in text
    # a node without the rotations an offset needs
    path.write_text(text.replace("POINT", "{node: n3, offset: [0.05, -0.08, 0.15]}")
                    .replace(n3, n3[:-1] + ", dofs: [x, y, z], row: 18}")
                    .replace("- {name: n4, at:", "- {name: n4, row: 24, at:"))
    with pytest.raises(ModelError, match=r"^node 'n3' of flexible body 'beam' has no rotational DOF rx, ry, rz: a "
                                         r"point offset by \[0.05, -0.08, 0.15\] from it moves with its rotation "
                                         r"\(.*offset.yml, elements\[2\].points\[0\]\)$"):
        load_model(path)
    for point, match in (
        ("{node: n9, offset: [0, 0, 0.1]}", r"flexible body 'beam' has no node 'n9'; its nodes: n0, .* \(.*offset.yml, "
                                            r"elements\[2\].points\[0\].node\)"),
        ("{node: n3, offset: [0.2, 0, 0]}", r"the point offset by \[0.2, 0.0, 0.0\] from node 'n3' of flexible body "
                                            r"'beam' is node 'n4': name that node"),
        ("{node: n3, offset: [a, 0, 0]}", r"unknown name 'a'|'a'"),
        ("{node: n3, at: [0, 0, 1]}", r"a point offset from a node of flexible body 'beam' is \{node: NAME, offset: "
                                      r"\[dx, dy, dz\]\}; got keys \['at', 'node'\] \(.*elements\[2\].points\[0\]\)"),
    ):
        path.write_text(text.replace("POINT", point))
        with pytest.raises(ModelError, match=match):
            load_model(path)
    # on a rigid body, and two offsets landing on one point
    b = _offset_shoe({"node": "n3", "offset": OFFSET})
    with pytest.raises(ModelError, match=r"a point \{node, offset\} sits on a flexible body; 'carriage' is not one: "
                                         r"give a 3-vector \(inputs\[1\].point\)"):
        b.input("G", body="carriage", point={"node": "n3", "offset": OFFSET})
    with pytest.raises(ModelError, match=r"the point offset by \[-0.15, -0.08, 0.15\] from node 'n4' of flexible body "
                                         r"'beam' coincides with the point offset by \[0.05, -0.08, 0.15\] from node "
                                         r"'n3' \(sensors\[3\].point\)"):
        b.sensor("t", body="beam", point={"node": "n4", "offset": [-0.15, -0.08, 0.15]})
    b.sensor("u", body="beam", point={"node": "n3", "offset": [0.0, 0.0, 0.0]})  # the node itself
    assert NumericModel(b.build()).sensor_matrix()[0][-3:] == ["u:x", "u:y", "u:z"]


# -- sensors and outputs moving along a line of nodes -----------------------------------------------------------------
def _rail_with_moving_sensor(interpolation: str, fixed_node: int | None = None) -> NumericModel:
    """The beam on its supports (nothing on it moves with p), a sensor and an output riding the rail at x = p, or
    fixed on node ``fixed_node``."""
    nodes, k, m = _beam()
    b = StructureBuilder("scan")
    b.axis("p", [0.0, 0.3, 0.6, 1.2])
    b.flexible_body("beam", mass=m, stiffness=k, nodes=_node_entries(nodes),
                    lines=[{"name": "rail", "nodes": [f"n{i}" for i in range(N_NODES)],
                            "interpolation": interpolation}])
    _supported(b, "beam", "n0", f"n{N_NODES - 1}")
    b.input("F", body="beam", point="n1", direction="z")
    point: object = ["p", 0, 0] if fixed_node is None else f"n{fixed_node}"
    b.sensor("m", body="beam", point=point)
    b.output("mz", body="beam", point=point, direction="z")
    return NumericModel(b.build())


def _interpolation_rows(p: float, interpolation: str) -> np.ndarray:
    """(3, 6 N) rows of the point x = p on the beam along x, written out here: hat functions of the translations, or
    the beam element's cubics (w = H1 w_i + L H2 w'_i + H3 w_j + L H4 w'_j, slopes y' = rz, z' = -ry)."""
    step = L_BEAM / (N_NODES - 1)
    i = min(int(p // step), N_NODES - 2)
    xi = (p - i * step) / step
    rows = np.zeros((3, 6 * N_NODES))
    linear = ((i, 1 - xi), (i + 1, xi))
    if interpolation == "linear":
        for node, weight in linear:
            rows[:, 6 * node:6 * node + 3] += weight * np.eye(3)
        return rows
    h1, h2, h3, h4 = 1 - 3 * xi**2 + 2 * xi**3, xi - 2 * xi**2 + xi**3, 3 * xi**2 - 2 * xi**3, -(xi**2) + xi**3
    for node, weight in linear:
        rows[0, 6 * node] += weight  # axial: linear
    for node, hw, hs in ((i, h1, h2), (i + 1, h3, h4)):
        rows[1, 6 * node + 1] += hw
        rows[1, 6 * node + 5] += step * hs  # y' = rz
        rows[2, 6 * node + 2] += hw
        rows[2, 6 * node + 4] -= step * hs  # z' = -ry
    return rows


@pytest.mark.parametrize("interpolation", ["linear", "hermite"])
def test_sensor_and_output_moving_along_a_line_interpolate_the_nodes(interpolation: str) -> None:
    moving = _rail_with_moving_sensor(interpolation)
    mats = moving.matrices()
    lam, phi = scipy.linalg.eigh(mats["K"], mats["M"])
    step = L_BEAM / (N_NODES - 1)
    # at a node: the sensor fixed on that node (rows, shapes and FRF)
    for node in (0, 2, 5):
        fixed = _rail_with_moving_sensor(interpolation, node)
        at = {"p": node * step}
        np.testing.assert_allclose(moving.sensor_matrix(position=at)[1][-3:], fixed.sensor_matrix()[1][-3:],
                                   rtol=0, atol=1e-12)  # the cubics at a knot: 1 and 0 up to rounding
        np.testing.assert_allclose(modal_batch(moving, position=at, n_modes=10).shapes[0][-3:],
                                   modal_batch(fixed, n_modes=10).shapes[0][-3:], rtol=0, atol=1e-9)
        np.testing.assert_allclose(moving.system(position=at).frf([40.0, 400.0]).H,
                                   fixed.system().frf([40.0, 400.0]).H, rtol=1e-10)
    # in between: the rows are the shape functions written out with numpy, and so are the mode shapes there
    sweep = np.linspace(0.0, L_BEAM, 25)
    for p in sweep:
        ref_rows = _interpolation_rows(p, interpolation)
        got_rows = moving.sensor_matrix(position={"p": p})[1][-3:]
        np.testing.assert_allclose(got_rows, ref_rows, rtol=0, atol=1e-12)
        shapes = modal_batch(moving, position={"p": p}, n_modes=10).shapes[0][-3:]
        ref = ref_rows @ phi[:, :10]
        sign = np.sign(np.sum(shapes * ref, axis=0))
        np.testing.assert_allclose(shapes * sign, ref, rtol=0, atol=1e-8 * abs(ref).max())
        w = 2 * np.pi * 40.0
        x = np.linalg.solve(mats["K"] - w**2 * mats["M"], _input_column(moving))
        np.testing.assert_allclose(moving.system(position={"p": p}).frf([40.0]).H[0, 0, 0], ref_rows[2] @ x,
                                   rtol=1e-9, atol=1e-15)
    from cappe.modal import sensor_coordinates

    np.testing.assert_allclose(sensor_coordinates(moving, position={"p": 0.45})["m"], [0.45, 0.0, 0.0], atol=1e-15)
    # continuous: the change of the shapes at the sensor over a position step shrinks with the step (at a node and
    # mid-element; Lipschitz: 100 times smaller step, about 100 times smaller change)
    def shape_at(p: float) -> np.ndarray:
        return np.abs(modal_batch(moving, position={"p": p}, n_modes=10).shapes[0][-3:])

    for centre in (2 * step, 2.5 * step):
        jumps = [np.abs(shape_at(centre + eps) - shape_at(centre - eps)).max() for eps in (1e-3, 1e-5)]
        assert 0 < jumps[1] < 2e-2 * jumps[0], jumps


def _input_column(model: NumericModel) -> np.ndarray:
    """The force F (z at node n1) as a column of generalized forces, written out here."""
    column = np.zeros(model.n_dof)
    column[6 * 1 + 2] = 1.0
    return column
