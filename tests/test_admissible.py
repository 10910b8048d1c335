"""Admissible equilibria: stability, inversion, self-penetration, state limits, the rest state.

References are closed forms (Euler's buckling load, a cable's compliance on a beam), dense eigenvalues of
the same tangent, or geometry built in the test; never an earlier output of the code under test.
"""

import numpy as np
import pytest
from conftest import REPO, cantilever, nodes_inside_other_tetrahedra, small_trunk

import casadi_ws as cw
from casadi_ws import Cable, Material, Problem, box_mesh
from casadi_ws.fem.mesh import quadratic
from casadi_ws.io.problem import nodes_on_plane
from casadi_ws.solvers.admissible import (AdmissibilitySettings, admissibility, admissible_equilibrium,
                                          penetrating_samples)
from casadi_ws.solvers.equilibrium import solve_equilibrium


E, L, H = 1e6, 0.2, 0.01
P_EULER = np.pi**2 * E * (H**4 / 12) / (4 * L**2)  # cantilever, dead axial load at the tip


def column(load_factor, model="neohookean", width=H):
    """The 10 x 10 x 200 mm cantilever (10-node tets, one element across), axial dead load at its tip.
    ``model`` ``taylor_hood``: a nearly incompressible neo-Hookean (nu = 0.49) with the continuous pressure."""
    mesh = quadratic(box_mesh((width, H, L), (1, 1, 20), (-width / 2, -H / 2, 0.0)))
    mat = Material("mooney_rivlin", E, 0.49, formulation=model) if model == "taylor_hood" else Material(model, E, 0.3)
    return Problem(mesh, mat, nodes_on_plane(mesh, [0, 0, 0], [0, 0, 1]), [],
                   np.array([0.0, 0.0, L]), point_loads=[(np.array([0.0, 0.0, L]),
                                                          np.array([0.0, 0.0, -load_factor * P_EULER]))])


def _stable_straight(factor, model="neohookean"):
    m = cw.StaticModel(column(factor, model))
    eq = solve_equilibrium(m, np.zeros(0))
    assert eq.converged
    return admissibility(m, eq.q, eq.u, eq.factorization).stable


@pytest.mark.parametrize("model", ["neohookean", "corotational", "taylor_hood"])
def test_euler_critical_load_within_2_percent(model):
    """The straight column's stability, decided by the pivots (or, with the pressure unknowns of the
    Taylor-Hood element, on their Schur complement), changes within 2 % of Euler's load."""
    lo, hi = 0.8, 1.2  # bisection on the stability of the straight equilibrium
    assert _stable_straight(lo, model) and not _stable_straight(hi, model)
    for _ in range(6):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _stable_straight(mid, model) else (lo, mid)
    assert abs(0.5 * (lo + hi) - 1.0) < 0.02


@pytest.mark.parametrize("factor", [0.7, 1.5, 3.0])
def test_column_is_never_straight_and_stable_above_euler(factor):
    m = cw.StaticModel(column(factor))
    eq, adm, _ = admissible_equilibrium(m, np.zeros(0))
    lateral = float(np.linalg.norm(eq.tip[:2]))
    if factor < 1:
        assert eq.converged and adm.admissible and adm.stable and lateral < 1e-3 * L
    else:  # buckled and stable, or refused as unstable: never straight and verified
        assert not (adm.admissible and lateral < 0.05 * L)
        if not adm.admissible:
            assert "unstable" in adm.violations and adm.smallest_eigenvalue < 0


@pytest.mark.slow
def test_rectangular_column_above_euler_comes_out_buckled_and_stable():
    # 10 x 15 mm: one weak axis, so the buckled branch is isolated (a square one buckles in any direction)
    m = cw.StaticModel(column_rect())
    eq, adm, branched = admissible_equilibrium(m, np.zeros(0))
    assert branched and eq.converged and adm.admissible and adm.stable
    assert np.linalg.norm(eq.tip[:2]) > 0.25 * L and eq.tip[2] < 0.8 * L


def column_rect():
    b, d = H, 0.015
    mesh = quadratic(box_mesh((b, d, L), (1, 1, 10), (-b / 2, -d / 2, 0.0)))
    P = np.pi**2 * E * (d * b**3 / 12) / (4 * L**2)
    return Problem(mesh, Material("neohookean", E, 0.3), nodes_on_plane(mesh, [0, 0, 0], [0, 0, 1]), [],
                   np.array([0.0, 0.0, L]), point_loads=[(np.array([0.0, 0.0, L]), np.array([0.0, 0.0, -1.5 * P]))])


def _dense_eigenvalues(m, q):
    K = m.residual_and_tangent(q, np.zeros(m.n_u))[1].toarray()
    return np.linalg.eigvals(K).real


@pytest.mark.parametrize("model", ["corotational", "neohookean"])
@pytest.mark.parametrize("order", [1, 2])
def test_stability_under_rigid_rotation_and_uniform_compression(model, order):
    mesh = box_mesh((0.02, 0.02, 0.04), (2, 2, 4) if order == 1 else (1, 1, 2))
    mesh = quadratic(mesh) if order == 2 else mesh
    pb = Problem(mesh, Material(model, 1e6, 0.3), nodes_on_plane(mesh, [0, 0, 0], [0, 0, 1]), [],
                 np.array([0.01, 0.01, 0.04]))
    m = cw.StaticModel(pb)
    rest = np.sort(_dense_eigenvalues(m, np.zeros(m.n_dof)))
    c, s = np.cos(1.0), np.sin(1.0)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    X = mesh.nodes
    rotated = (X @ R.T - X).ravel()
    dense = np.sort(_dense_eigenvalues(m, rotated))
    np.testing.assert_allclose(dense, rest, rtol=1e-6, atol=1e-9 * rest[-1])  # objectivity: same spectrum
    adm = admissibility(m, rotated, np.zeros(0))
    assert adm.admissible and adm.stable and adm.negative_pivots == 0
    # uniform compression (a prestress, not an equilibrium): 0.1 % keeps K positive definite; at 25 % the
    # compressive stress's geometric stiffness makes it indefinite. The criterion follows the dense spectrum
    for c in (0.001, 0.25):
        dense = np.sort(_dense_eigenvalues(m, (-c * X).ravel()))
        adm = admissibility(m, (-c * X).ravel(), np.zeros(0), settings=AdmissibilitySettings(self_penetration=False))
        assert adm.stable == (dense[0] > 0) == (c < 0.01)
        assert adm.min_det_F == pytest.approx((1 - c) ** 3, rel=1e-9)
        if model == "neohookean":  # symmetric K: the pivots are its inertia
            assert adm.negative_pivots == np.count_nonzero(dense < 0)


def test_pivot_count_equals_negative_eigenvalues_above_euler():
    m = cw.StaticModel(column(3.0))
    eq = solve_equilibrium(m, np.zeros(0))
    adm = admissibility(m, eq.q, eq.u, eq.factorization)
    dense = _dense_eigenvalues(m, eq.q)
    assert adm.negative_pivots == np.count_nonzero(dense < 0) == 2
    assert adm.smallest_eigenvalue == pytest.approx(dense.min(), rel=1e-6)


@pytest.mark.parametrize("model", ["linear", "corotational", "neohookean"])
def test_an_inverted_element_is_refused_for_every_law(model):
    mesh = box_mesh((0.01, 0.01, 0.01), (1, 1, 1))
    pb = Problem(mesh, Material(model, 1e6, 0.3), nodes_on_plane(mesh, [0, 0, 0], [0, 0, 1]), [],
                 np.array([0.005, 0.005, 0.01]))
    m = cw.StaticModel(pb)
    q = np.zeros(m.n_dof)
    top = np.flatnonzero(mesh.nodes[:, 2] > 0.005)
    q.reshape(-1, 3)[top, 2] = -0.02  # the top face pushed through the bottom one
    adm = admissibility(m, q, np.zeros(0))
    assert "inverted" in adm.violations and adm.min_det_F < 0 and not adm.admissible
    q.reshape(-1, 3)[top, 2] = -0.002  # 20 % compression: admissible
    assert "inverted" not in admissibility(m, q, np.zeros(0)).violations



@pytest.mark.parametrize("order", [1, 2])
def test_the_compiled_jacobians_are_the_determinants_of_the_deformation_gradients(order):
    mesh = box_mesh((0.02, 0.02, 0.04), (2, 2, 3) if order == 1 else (1, 1, 2))
    mesh = quadratic(mesh) if order == 2 else mesh
    pb = Problem(mesh, Material("corotational", 1e6, 0.3), nodes_on_plane(mesh, [0, 0, 0], [0, 0, 1]), [],
                 np.array([0.01, 0.01, 0.04]))
    m = cw.StaticModel(pb)
    q = 0.004 * np.random.default_rng(3).standard_normal(m.n_dof)
    np.testing.assert_allclose(m.jacobians(q), np.linalg.det(m.deformation_gradients(q)), rtol=1e-12, atol=1e-14)

def _bent(mesh, angle):
    """The beam along +z bent into a circular arc of the given total angle about the y axis."""
    X = mesh.nodes
    if angle == 0:
        return np.zeros(X.size)
    rho = L / angle
    phi = X[:, 2] / rho
    x = (rho - X[:, 0]) * np.cos(phi) - rho
    z = (rho - X[:, 0]) * np.sin(phi)
    return (np.column_stack([-x, X[:, 1], z]) - X).ravel()


@pytest.mark.parametrize("order", [1, 2])
def test_a_body_passing_through_itself_is_refused_a_gently_bent_one_is_not(order):
    pb = cantilever(n=2, slender=10, model="corotational", order=order)
    m = cw.StaticModel(pb)
    for angle, penetrates in ((0.5, False), (np.pi, False), (2.4 * np.pi, True)):
        q = _bent(pb.mesh, angle)
        found = penetrating_samples(m, q)
        assert bool(found.size) == penetrates, (angle, found.size)
        adm = admissibility(m, q, np.zeros(m.n_u), settings=AdmissibilitySettings(stability=False))
        assert ("self_penetration" in adm.violations) == penetrates


def test_a_coarse_finger_curled_through_its_own_base_is_refused():
    # SoftRobots' Finger (about ten elements long, shipped in problems/sofa/finger), its cable pulled 55 mm:
    # the curled end passes through the finger near its base, parts a few element sizes apart at rest that
    # the audit once did not compare (issue 69); 50 mm curls it without touching
    p = cw.load_problem(REPO / "problems" / "sofa" / "finger" / "finger.yaml")
    p.actuators[0].u_max = 0.06
    m = cw.StaticModel(p)
    for u, through in ((0.05, False), (0.055, True)):
        eq = cw.quasi_static(m, [u])
        assert eq.converged
        inside = nodes_inside_other_tetrahedra(m, eq.q)
        assert (len(inside) >= 5) if through else not inside
        adm = admissibility(m, eq.q, eq.u, eq.factorization)
        assert ("self_penetration" in adm.violations) == through, (u, adm.penetrating, inside)
        assert adm.penetrating >= len(inside)  # every node inside is among the samples it reports


def test_stroke_limit_maps_to_the_tension_of_the_cable_compliance():
    # a cable along a 10-node cantilever, linear law: the shortening is (nearly) linear in the tension, so
    # a stroke s is reached at T = s / (dL/dT), the compliance measured at a small tension
    d, Lb, Eb = 0.004, 0.2, 1e6
    pb = cantilever(n=1, slender=10, model="linear", nu=0.0, E=Eb, L=Lb, cable_offset=d, order=2)
    m0 = cw.StaticModel(pb)
    L0 = m0.actuator_states(np.zeros(m0.n_dof))[0]
    compliance = (L0 - m0.actuator_states(solve_equilibrium(m0, [0.01]).q)[0]) / 0.01
    stroke = 0.0002  # small: the linear law stays accurate (rotations ~0.02 rad)
    pb.actuators[0].stroke_max = stroke
    pb.actuators[0].u_max = 2.0 * stroke / compliance
    m = cw.StaticModel(pb)
    res = cw.forward(pb, n_d=41, model=m, settings=cw.ForwardSettings(progress=False))
    t_limit = stroke / compliance
    reported = res.u[:, 0]
    excluded = res.arrays["excluded_u"][:, 0]
    assert res.counters["excluded"]["stroke"] == excluded.size > 0
    # the boundary lies between the largest reported and the smallest excluded tension
    assert reported.max() < excluded.min()
    assert abs(0.5 * (reported.max() + excluded.min()) / t_limit - 1) < 0.08


def test_stretch_limit_cuts_where_the_state_crosses_it():
    pb = small_trunk("corotational", n_cables=1, gravity=False)
    m = cw.StaticModel(pb)
    us = np.linspace(0, 60, 7)
    stretch = []
    for u in us:
        eq = solve_equilibrium(m, [u])
        F = m.deformation_gradients(eq.q)
        stretch.append(np.sqrt(np.linalg.eigvalsh(np.swapaxes(F, -1, -2) @ F)[..., -1].max()))
    limit = 0.5 * (stretch[3] + stretch[4])
    pb2 = small_trunk("corotational", n_cables=1, gravity=False)
    pb2.material = Material("corotational", 1.8e7, 0.45, 1100.0, max_stretch=limit)
    pb2.actuators[0].u_max = 60.0
    res = cw.forward(pb2, n_d=7, settings=cw.ForwardSettings(progress=False))
    np.testing.assert_allclose(np.sort(res.u[:, 0]), us[:4])
    assert res.counters["excluded"]["stretch"] == 3


@pytest.mark.parametrize("model", ["linear", "corotational", "neohookean"])
@pytest.mark.parametrize("order", [1, 2])
def test_the_rest_state_converges_for_every_law_and_order(model, order):
    pb = small_trunk(model, gravity=False)
    if order == 2:
        pb.mesh = quadratic(pb.mesh)
    m = cw.StaticModel(pb)
    eq, adm, _ = admissible_equilibrium(m, np.zeros(m.n_u))
    assert eq.converged and eq.residual < 1e-8 and adm.admissible and adm.stable
    assert np.abs(eq.q).max() == 0.0


def test_equilibrium_command_reports_the_checks(tmp_path):
    from conftest import coarse_problem_file, run_cli
    import json

    r = run_cli("equilibrium", coarse_problem_file(tmp_path), "--u", "40,20")
    out = json.loads(r.stdout)
    assert r.returncode == 0 and out["admissible"] and out["stable"] and out["violations"] == []
    assert 0.9 < out["min_det_F"] < 1.0


def test_reach_keeps_a_cable_within_its_stroke():
    # IPOPT gets the stroke as a constraint: a target beyond it returns the closest point at the limit
    d = 0.004
    pb = cantilever(n=1, slender=10, model="linear", nu=0.0, cable_offset=d, order=2)
    m = cw.StaticModel(pb)
    L0 = m.actuator_states(np.zeros(m.n_dof))[0]
    far = solve_equilibrium(m, [1.0])
    stroke = 0.5 * (L0 - m.actuator_states(far.q)[0])
    pb.actuators[0].stroke_max = stroke
    m = cw.StaticModel(pb)
    r = cw.reach(m, far.tip)
    assert not r.reachable and r.admissibility.admissible
    assert L0 - m.actuator_states(r.q)[0] == pytest.approx(stroke, rel=1e-5)
    assert 0.4 < r.u[0] < 0.6  # about half the tension, the law being (nearly) linear
    free = cw.reach(cw.StaticModel(cantilever(n=1, slender=10, model="linear", nu=0.0, cable_offset=d, order=2)),
                    far.tip)
    assert free.reachable and free.u[0] == pytest.approx(1.0, rel=1e-4)


def test_volume_limit_maps_to_lames_pressure(tmp_path):
    # a thick hollow sphere (a = 10, b = 20 mm, 10-node tets, within 1 % of Lame): a chamber allowed to
    # grow by Lame's volume change at 500 Pa is cut at 500 Pa
    from test_cavity import lame_volume_change, sphere_problem_file

    text = sphere_problem_file(tmp_path, "hollow_sphere_5mm_o2.vtu", 2).read_text()
    pb0 = cw.load_problem(sphere_problem_file(tmp_path, "hollow_sphere_5mm_o2.vtu", 2))
    V0 = pb0.actuators[0].rest_volume()
    limit = V0 + lame_volume_change(500.0, 0.01, 0.02, 1e6, 0.3)
    path = tmp_path / "limited.yaml"
    path.write_text(text.replace("u_max: 1000}", f"u_max: 1000, volume_max: {limit!r}}}"))
    pb = cw.load_problem(path)
    assert pb.actuators[0].volume_max == pytest.approx(limit)
    res = cw.forward(pb, n_d=21, settings=cw.ForwardSettings(progress=False))
    top, cut = res.u[:, 0].max(), res.arrays["excluded_u"][:, 0].min()
    assert res.counters["excluded"]["volume"] == res.arrays["excluded_u"].shape[0] > 0
    assert top < cut and top <= 500 * 1.01 + 1e-9 and cut >= 500 * 0.99


def test_forward_backward_reaches_the_cells_up_to_a_stroke_limit():
    # the reduced backward keeps its steps within the linearised stroke, so the cells along the limit are
    # reached (measured: all 11 of the forward cloud's cells; without the limit in the step, 9) and no
    # reported point is beyond it
    pb = small_trunk("corotational", n_cables=2)
    m = cw.StaticModel(pb)
    L0 = m.actuator_states(np.zeros(m.n_dof))[0]
    stroke = L0 - m.actuator_states(solve_equilibrium(m, [50.0, 0.0]).q)[0]
    pb.actuators[0].stroke_max = stroke
    fb = cw.forward_backward(pb, cw.FBSettings(step=0.008, progress=False))
    fw = cw.forward(pb, n_d=31, settings=cw.ForwardSettings(progress=False))
    assert fw.counters["excluded"]["stroke"] > 0
    assert cw.compare(fw, fb)["cells_a_in_b"] >= 0.95
    m = cw.StaticModel(pb)
    for u, p in zip(fb.u, fb.points):
        eq = solve_equilibrium(m, u)
        assert np.allclose(eq.tip, p, atol=1e-7) and L0 - m.actuator_states(eq.q)[0] <= stroke * (1 + 1e-9)
