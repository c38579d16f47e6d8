"""The frame generator against analytic beam frequencies, and Craig-Bampton against the full FE model.

References: Euler-Bernoulli free-free and clamped beams, beta_n L from the characteristic equations
cos(bL) cosh(bL) = +1 (free-free) and -1 (clamped-free) (Blevins, Formulas for Natural Frequency and Mode Shape,
table 8-1); the simply supported Timoshenko beam's frequency equation
(kGA k^2 - rho A w^2)(EI k^2 + kGA - rho I w^2) = (kGA k)^2 with k = n pi / L (Timoshenko 1921; Han, Benaroya and
Wei, J. Sound Vib. 225 (1999) eq. 66); axial rods f_n = n c / (2 L).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
import scipy.optimize
import scipy.sparse as sps

from cappe.exceptions import ModelError
from cappe.modal import modal_batch
from cappe.model import NumericModel, StructureBuilder, load_model
from cappe.model.fe import BeamSection, craig_bampton, frame_from_spec, frame_model

E, NU, RHO = 210e9, 0.3, 7850.0


def _line(n_el: int, length: float, section: BeamSection):  # type: ignore[no-untyped-def]
    nodes = np.c_[np.linspace(0, length, n_el + 1), np.zeros(n_el + 1), np.zeros(n_el + 1)]
    return frame_model(nodes, [[i, i + 1] for i in range(n_el)], section)


def _roots(sign: float, count: int) -> np.ndarray:
    """beta L of cos(x) cosh(x) = sign, from scipy's brentq near (n + 1/2) pi."""
    out = []
    for n in range(1, count + 1):
        guess = (n - 0.5 if sign < 0 else n + 0.5) * np.pi
        out.append(scipy.optimize.brentq(lambda x: np.cos(x) * np.cosh(x) - sign, guess - 1.0, guess + 1.0))
    return np.array(out)


def test_free_free_euler_bernoulli_beam_matches_the_analytic_frequencies() -> None:
    # slender (L / h = 250) so rotary inertia, which the element carries, shifts frequencies by < 1e-5
    sec = BeamSection.rectangle(0.004, 0.008, E=E, nu=NU, rho=RHO, timoshenko=False)
    fm = _line(40, 2.0, sec)
    lam = scipy.linalg.eigh(fm.stiffness.toarray(), fm.mass.toarray(), eigvals_only=True)
    f = np.sqrt(np.clip(lam, 0, None)) / (2 * np.pi)
    assert np.all(f[:6] < 1e-3 * f[6])  # six rigid-body modes
    beta = _roots(1.0, 3) / 2.0
    for inertia in (sec.Iz, sec.Iy):  # bending in local x-y (width) and x-z (height)
        ref = beta**2 * np.sqrt(E * inertia / (RHO * sec.A)) / (2 * np.pi)
        found = np.array([f[np.argmin(abs(f - r))] for r in ref])
        np.testing.assert_allclose(found, ref, rtol=2e-4)  # 40 cubic elements: discretization < 1e-4
    c = np.sqrt(E / RHO)
    axial = c / (2 * 2.0)
    assert abs(f[np.argmin(abs(f - axial))] / axial - 1) < 1e-3  # linear elements, h / lambda = 1/40


def test_cantilever_matches_the_analytic_frequencies() -> None:
    sec = BeamSection.rectangle(0.004, 0.004, E=E, nu=NU, rho=RHO, timoshenko=False)
    fm = _line(40, 1.0, sec)
    keep = np.arange(6, fm.n_dof)  # node 0 clamped
    k = fm.stiffness.toarray()[np.ix_(keep, keep)]
    m = fm.mass.toarray()[np.ix_(keep, keep)]
    f = np.sqrt(scipy.linalg.eigh(k, m, eigvals_only=True)) / (2 * np.pi)
    ref = _roots(-1.0, 3) ** 2 * np.sqrt(E * sec.Iy / (RHO * sec.A)) / (2 * np.pi)
    # square section: each bending frequency twice (y and z)
    np.testing.assert_allclose(f[[0, 1]], ref[0], rtol=1e-4)
    np.testing.assert_allclose(f[[2, 3]], ref[1], rtol=1e-4)
    found = np.array([f[np.argmin(abs(f - r))] for r in ref])
    np.testing.assert_allclose(found, ref, rtol=2e-4)


@pytest.mark.parametrize(("width", "height", "timoshenko", "rtol"), [
    (0.004, 0.004, False, 2e-4),  # slender: Euler-Bernoulli
    (0.05, 0.15, True, 1e-3),  # L / h = 6.7: shear and rotary inertia lower the 4th mode by 9 %
])
def test_simply_supported_timoshenko_beam_matches_the_closed_form(width: float, height: float, timoshenko: bool,
                                                                  rtol: float) -> None:
    sec = BeamSection.rectangle(width, height, E=E, nu=NU, rho=RHO, timoshenko=timoshenko)
    n_el, length = 80, 1.0
    fm = _line(n_el, length, sec)
    keep = [fm.dof(i, "z") for i in range(1, n_el)] + [fm.dof(i, "ry") for i in range(n_el + 1)]
    k = fm.stiffness.toarray()[np.ix_(keep, keep)]
    m = fm.mass.toarray()[np.ix_(keep, keep)]
    f = np.sqrt(scipy.linalg.eigh(k, m, eigvals_only=True)[:4]) / (2 * np.pi)
    a, inertia, kga = sec.A, sec.Iy, 5 / 6 * sec.G * sec.A
    ref = []
    for n in range(1, 5):
        kn = n * np.pi / length
        if not timoshenko:  # Rayleigh beam (the element keeps rotary inertia): w2 = EI k^4 / (rho A + rho I k^2)
            ref.append(np.sqrt(E * inertia * kn**4 / (RHO * a + RHO * inertia * kn**2)) / (2 * np.pi))
            continue
        # (kGA k^2 - rho A w2)(EI k^2 + kGA - rho I w2) - (kGA k)^2 = 0, a quadratic in w2: the lower root
        qa = RHO * a * RHO * inertia
        qb = -(kga * kn**2 * RHO * inertia + RHO * a * (E * inertia * kn**2 + kga))
        qc = kga * kn**2 * E * inertia * kn**2
        ref.append(np.sqrt((-qb - np.sqrt(qb * qb - 4 * qa * qc)) / (2 * qa)) / (2 * np.pi))
    np.testing.assert_allclose(f, ref, rtol=rtol)


def _portal(n: int = 10) -> tuple:  # type: ignore[type-arg]
    """A 3-D portal frame: two columns (1 m) and a beam (1.5 m) in the x-z plane, n elements each."""
    sec = BeamSection.rectangle(0.06, 0.06, E=E, nu=NU, rho=RHO)
    col_a = np.c_[np.zeros(n + 1), np.zeros(n + 1), np.linspace(0, 1, n + 1)]
    beam = np.c_[np.linspace(0, 1.5, n + 1)[1:], np.zeros(n), np.ones(n)]
    col_b = np.c_[np.full(n, 1.5), np.zeros(n), np.linspace(1, 0, n + 1)[1:]]
    nodes = np.vstack([col_a, beam, col_b])
    elements = [[i, i + 1] for i in range(len(nodes) - 1)]
    return nodes, frame_model(nodes, elements, sec, up=(0.0, 1.0, 0.0))


def _supported_full(fm, feet: list[int], k_support: float) -> tuple[np.ndarray, np.ndarray]:  # type: ignore[no-untyped-def]
    k = fm.stiffness.toarray()
    for node in feet:
        for d in range(6):
            k[6 * node + d, 6 * node + d] += k_support
    return k, fm.mass.toarray()


@pytest.mark.parametrize(("k_support", "multiple", "n_el"), [
    (1.0e8, 1.5, 10),  # feet stiff against the frame: the usual rule, 1.5 times the band, gives 5e-5
    # soft feet (the frame's free-free modes in the band): 1.5 x band keeps 5 modes and is 12 % off at the band's
    # top, 2 x band 1.5 %, 3 x band 0.35 % (measured on this frame): soft interfaces need a higher multiple
    (1.0e7, 3.0, 10),
    (1.0e7, 3.0, 40),  # 726 DOFs: the fixed-interface modes from eigsh (shift-invert) instead of a dense solve
])
def test_craig_bampton_matches_the_full_model_in_the_band(k_support: float, multiple: float, n_el: int) -> None:
    nodes, fm = _portal(n_el)
    feet = [0, len(nodes) - 1]
    mid = len(nodes) // 2  # the middle of the beam: interior, recovered
    boundary = [6 * n + d for n in feet for d in range(6)]
    band = 150.0
    red = craig_bampton(fm.stiffness, fm.mass, boundary, band=band, multiple=multiple)
    assert np.all(red.fixed_interface_freq <= multiple * band)
    assert red.n_modes >= 3
    # both on the same elastic feet (added at the boundary DOFs, which both models keep physical)
    k_full, m_full = _supported_full(fm, feet, k_support)
    k_red = red.stiffness.copy()
    k_red[np.arange(12), np.arange(12)] += k_support
    lam_f, phi_f = scipy.linalg.eigh(k_full, m_full)
    lam_r, phi_r = scipy.linalg.eigh(k_red, red.mass)
    f_full, f_red = np.sqrt(lam_f) / (2 * np.pi), np.sqrt(lam_r) / (2 * np.pi)
    in_band = np.flatnonzero(f_full <= band)
    assert in_band.size >= 5
    np.testing.assert_allclose(f_red[in_band], f_full[in_band], rtol=5e-3)
    recovered = red.recovery @ phi_r[:, in_band]
    for j, i in enumerate(in_band):
        a, b = recovered[:, j], phi_f[:, i]
        assert (a @ b) ** 2 / ((a @ a) * (b @ b)) >= 0.99
    # the interior node's motion from the recovery rows is the full model's at that node, mode by mode
    rows = [6 * mid + d for d in range(3)]
    for j, i in enumerate(in_band):
        a, b = recovered[rows, j], phi_f[rows, i]
        if np.linalg.norm(b) > 1e-3 * np.abs(phi_f[:, i]).max():  # the modes that move it
            assert (a @ b) ** 2 / ((a @ a) * (b @ b)) > 0.99


def test_craig_bampton_refuses_a_boundary_that_leaves_the_body_free() -> None:
    _, fm = _portal()
    with pytest.raises(ModelError, match=r"K_ii is singular: the boundary DOFs must hold the body's rigid-body"):
        craig_bampton(fm.stiffness, fm.mass, [0, 1, 2], n_modes=4)


def test_model_file_reduces_a_full_sparse_model_and_recovers_an_interior_sensor(tmp_path: Path) -> None:
    nodes, fm = _portal()
    sps.save_npz(tmp_path / "portal_K.npz", fm.stiffness)
    sps.save_npz(tmp_path / "portal_M.npz", fm.mass)
    last = len(nodes) - 1
    (tmp_path / "portal.yaml").write_text(f"""\
format: cappe.model/1
name: portal
flexible_bodies:
  - name: frame
    mass: portal_M.npz
    stiffness: portal_K.npz
    reduction: {{band: 150, multiple: 3}}
    nodes:
      - {{name: foot_a, at: [0.0, 0.0, 0.0], row: 0}}
      - {{name: foot_b, at: [1.5, 0.0, 0.0], row: {6 * last}}}
    recovery:
      nodes:
        - {{name: top, at: {nodes[15].tolist()}, dofs: [x, y, z], row: {6 * 15}}}
elements:
  - {{name: mount_a, bodies: [ground, frame], points: [[0, 0, 0], foot_a], stiffness: {{x: 1.0e7, y: 1.0e7, z: 1.0e7, rx: 1.0e7, ry: 1.0e7, rz: 1.0e7}}}}
  - {{name: mount_b, bodies: [ground, frame], at: [1.5, 0, 0], stiffness: {{x: 1.0e7, y: 1.0e7, z: 1.0e7, rx: 1.0e7, ry: 1.0e7, rz: 1.0e7}}}}
sensors:
  - {{name: top, body: frame, point: top}}
""")
    s = load_model(tmp_path / "portal.yaml")
    assert s.dofs[:2] == ("frame.foot_a.x", "frame.foot_a.y")
    assert s.dofs[12] == "frame.q1"
    k_full, m_full = _supported_full(fm, [0, last], 1.0e7)
    lam_f, phi_f = scipy.linalg.eigh(k_full, m_full)
    f_full = np.sqrt(lam_f) / (2 * np.pi)
    in_band = np.flatnonzero(f_full <= 150.0)
    batch = modal_batch(NumericModel(s), n_modes=in_band.size, sensors=["top"])
    np.testing.assert_allclose(batch.frequency[0], f_full[in_band], rtol=5e-3)
    rows = [6 * 15 + d for d in range(3)]
    for j, i in enumerate(in_band):
        a, b = batch.shapes[0][:, j], phi_f[rows, i]
        if np.linalg.norm(b) > 1e-3 * np.abs(phi_f[:, i]).max():  # modes that move the top node
            assert (a @ b) ** 2 / ((a @ a) * (b @ b)) > 0.99


def test_builder_takes_arrays_and_a_reduction() -> None:
    nodes, fm = _portal()
    b = StructureBuilder("portal")
    with pytest.raises(ModelError, match=r"reduction takes \{band: Hz, multiple: 1.5\} or \{modes: n\}"):
        b.flexible_body("f", mass=fm.mass, stiffness=fm.stiffness, nodes=[{"name": "a", "at": [0, 0, 0]}],
                        reduction={"band": 100, "modes": 3})


def _portal_spec(n: int = 10) -> dict:  # type: ignore[type-arg]
    """The portal of :func:`_portal` as a model file's frame entry."""
    sec = BeamSection.rectangle(0.06, 0.06, E=E, nu=NU, rho=RHO)
    section = {"E": sec.E, "G": sec.G, "A": sec.A, "Iy": sec.Iy, "Iz": sec.Iz, "J": sec.J, "rho": sec.rho}
    return {"sections": {"col": section},
            "beams": [{"points": [[0, 0, 0], [0, 0, 1], [1.5, 0, 1], [1.5, 0, 0]], "section": "col", "divide": n}]}


def test_frame_spec_gives_the_frame_generators_matrices() -> None:
    nodes, fm = _portal()
    spec = frame_from_spec(_portal_spec(), "test")
    np.testing.assert_allclose(spec.nodes, nodes, atol=1e-15)
    np.testing.assert_allclose(spec.stiffness.toarray(), fm.stiffness.toarray(), rtol=1e-12, atol=1e-6)
    np.testing.assert_allclose(spec.mass.toarray(), fm.mass.toarray(), rtol=1e-12, atol=1e-15)
    # line_mass in place of rho: rho = line_mass / A
    sec = dict(_portal_spec()["sections"]["col"])
    sec["line_mass"] = sec.pop("rho") * sec["A"]
    by_line_mass = frame_from_spec({**_portal_spec(), "sections": {"col": sec}}, "test")
    np.testing.assert_allclose(by_line_mass.mass.toarray(), fm.mass.toarray(), rtol=1e-12, atol=1e-15)


def test_a_frame_body_in_the_builder_equals_the_same_matrices_given_as_arrays() -> None:
    nodes, fm = _portal()
    last = len(nodes) - 1
    interface = [{"name": "foot_a", "at": [0.0, 0.0, 0.0]}, {"name": "foot_b", "at": [1.5, 0.0, 0.0]}]
    models = []
    for frame in (True, False):
        b = StructureBuilder("portal")
        if frame:
            b.flexible_body("f", frame=_portal_spec(), nodes=interface, reduction={"band": 150, "multiple": 3},
                            recovery={"nodes": [{"name": "top", "at": nodes[15].tolist(), "dofs": ["x", "y", "z"]}]})
        else:
            b.flexible_body("f", mass=fm.mass, stiffness=fm.stiffness, reduction={"band": 150, "multiple": 3},
                            nodes=[{**interface[0], "row": 0}, {**interface[1], "row": 6 * last}],
                            recovery={"nodes": [{"name": "top", "at": nodes[15].tolist(), "dofs": ["x", "y", "z"],
                                                 "row": 6 * 15}]})
        for name, x in (("a", 0.0), ("b", 1.5)):
            b.element(name, bodies=["ground", "f"], at=[x, 0, 0], stiffness=dict.fromkeys(
                ("x", "y", "z", "rx", "ry", "rz"), 1.0e7))
        b.sensor("top", body="f", point="top")
        models.append(NumericModel(b.build()))
    one, two = (modal_batch(m, n_modes=8, sensors=["top"]) for m in models)
    np.testing.assert_allclose(one.frequency, two.frequency, rtol=1e-10)
    np.testing.assert_allclose(np.abs(one.shapes), np.abs(two.shapes), rtol=1e-8, atol=1e-12)


@pytest.mark.parametrize(("change", "match"), [
    ({"beams": []}, r"frame beams must be a non-empty list; got \[\] \(t.beams\)"),
    ({"up": [0, 0, 0]}, r"frame up must be a non-zero 3-vector; got \[0, 0, 0\] \(t.up\)"),
    ({"sections": {"col": {"E": 1.0}}}, r"section 'col' takes E, G, A, Iy, Iz, J, one of rho .* \(t.sections.col\)"),
    ({"sections": {"col": {"E": -1.0, "G": 1.0, "A": 1.0, "Iy": 1.0, "Iz": 1.0, "J": 1.0, "rho": 1.0}}},
     r"section 'col' E must be a positive number; got -1.0 \(t.sections.col.E\)"),
    ({"sections": {"col": {"E": 1.0, "G": 1.0, "A": 1.0, "Iy": 1.0, "Iz": 1.0, "J": 1.0, "rho": 1.0, "kappa": 2}}},
     r"section 'col' kappa must be in \(0, 1\] or null \(Euler-Bernoulli\); got 2 \(t.sections.col.kappa\)"),
    ({"beams": [{"points": [[0, 0, 0], [1, 0, 0]], "section": "web"}]},
     r"beam section 'web' is not one of col \(t.beams\[0\].section\)"),
    ({"beams": [{"points": [[0, 0, 0], [1, 0, 0]], "section": "col", "divide": 0}]},
     r"beam divide must be an integer 1..1000; got 0 \(t.beams\[0\].divide\)"),
    ({"beams": [{"points": [[0, 0, 0]], "section": "col"}]},
     r"beam points must be at least two finite \[x, y, z\] \(m\); got \[\[0, 0, 0\]\] \(t.beams\[0\].points\)"),
    ({"beams": [{"points": [[0, 0, 0], [0, 0, 0]], "section": "col"}]},
     r"beam points \[0.0, 0.0, 0.0\] and \[0.0, 0.0, 0.0\] coincide \(t.beams\[0\].points\)"),
    ({"beams": [{"points": [[k, 0, 0] for k in range(30)], "section": "col", "divide": 1000}]},
     r"the frame would have more than 20000 beam elements .* \(t.beams\[0\]\)"),
    ({"beams": [{"points": [[0, 0, 0], [1, 0, 0]], "sect": "col"}]},
     r"a beam is \{points: \[\[x, y, z\], ...\], section: NAME, divide: n\}; got .* \(t.beams\[0\]\)"),
])
def test_bad_frame_specs_are_one_line_errors_naming_the_entry(change: dict, match: str) -> None:  # type: ignore[type-arg]
    with pytest.raises(ModelError, match=match):
        frame_from_spec({**_portal_spec(), **change}, "t")


def test_frame_nodes_take_their_rows_from_the_frame() -> None:
    cases = [
        ({"nodes": [{"name": "a", "at": [0.0, 0.0, 0.55]}]},
         r"node 'a' at \[0.0, 0.0, 0.55\] is not a node of flexible body 'f''s frame \(nearest \[0.0, 0.0, 0.[56]\]\) "
         r"\(flexible_bodies\[0\].nodes\[0\].at\)"),
        ({"nodes": [{"name": "a", "at": [0.0, 0.0, 0.0], "row": 0}]},
         r"a node of a frame takes its rows from its coordinates; remove 'row' \(flexible_bodies\[0\].nodes\[0\].row\)"),
        ({"nodes": [{"name": "a", "at": [0.0, 0.0, 0.0], "dofs": ["x", "rz"]}]},
         r"node 'a' dofs on a frame must be a run of x y z rx ry rz in that order; got \['x', 'rz'\]"),
        ({"mass": np.eye(6), "stiffness": np.eye(6), "nodes": [{"name": "a", "at": [0.0, 0.0, 0.0]}]},
         r"flexible body 'f' takes either mass and stiffness or a frame, not both \(flexible_bodies\[0\]\)"),
    ]
    for kwargs, match in cases:
        with pytest.raises(ModelError, match=match):
            StructureBuilder("portal").flexible_body("f", frame=_portal_spec(), **kwargs)
    with pytest.raises(ModelError, match=r"flexible body 'f' needs mass and stiffness matrices, or a frame"):
        StructureBuilder("portal").flexible_body("f", nodes=[{"name": "a", "at": [0.0, 0.0, 0.0]}])


def test_craig_bampton_gives_the_same_matrices_every_time() -> None:
    # eigsh (interior > 200 DOFs) started from ARPACK's random vector: the fixed-interface modes came out with other
    # signs from call to call, and so did a model's reduced matrices and every result computed from them
    nodes, fm = _portal(40)
    boundary = [6 * n + d for n in (0, len(nodes) - 1) for d in range(6)]
    first = craig_bampton(fm.stiffness, fm.mass, boundary, band=150.0, multiple=3.0)
    again = craig_bampton(fm.stiffness, fm.mass, boundary, band=150.0, multiple=3.0)
    np.testing.assert_array_equal(again.mass, first.mass)
    np.testing.assert_array_equal(again.stiffness, first.stiffness)
    np.testing.assert_array_equal(again.recovery, first.recovery)
    # the sign convention: each fixed-interface mode's largest entry is positive (the dense solver's too)
    modes = first.recovery[:, len(boundary):]
    assert np.all(modes[np.argmax(np.abs(modes), axis=0), np.arange(modes.shape[1])] > 0)
