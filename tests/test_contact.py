"""Frictionless contact with rigid obstacles, checked against closed forms: a block resting on a table
(reaction = weight), a propped cantilever (beam theory, with and without a gap), the tangent and Hessian
against finite differences, and an obstacle nobody touches changing nothing."""

import numpy as np
import pytest
from conftest import REPO, nodes_in_box, trunk_cable, trunk_mesh

from casadi_ws import StaticModel, problem_from_dict, solve_equilibrium
from casadi_ws.fem.contact import Obstacle
from casadi_ws.io.problem import Material, Problem
from casadi_ws.solvers.admissible import admissibility
from casadi_ws.workspace.compare import compare
from casadi_ws.workspace.forward import forward
from casadi_ws.workspace.forward_backward import FBSettings, forward_backward

L, B, T, E, RHO = 0.2, 0.01, 0.01, 1e6, 1000.0
"""A slender beam (m, Pa, kg/m^3): L/T = 20, so shear adds ~0.5 % to beam theory's deflections."""


def _block(**extra):
    """A 2 x 2 x 1 cm block standing on the table z = 0, held only by two symmetry planes (x, y)."""
    d = {"mesh": {"generate": "box", "size": [0.02, 0.02, 0.01], "divisions": [4, 4, 2], "origin": [-0.01, -0.01, 0.0]},
         "material": {"young_modulus": 1e5, "poisson_ratio": 0.3, "density": 1000.0},
         "fixed": [{"box": [-1e-6, -1, -1, 1e-6, 1, 1], "components": ["x"]},
                   {"box": [-1, -1e-6, -1, 1, 1e-6, 1], "components": ["y"]}],
         "gravity": [0, 0, -9.81],
         "cables": [{"points": [[0.004, 0, 0.002], [0.004, 0, 0.008]], "pull_point": [0.004, 0, 0.01], "u_max": 0.01}],
         "obstacles": [{"name": "table", "plane": {"point": [0, 0, 0], "normal": [0, 0, 1]}}]}
    return problem_from_dict({**d, **extra}, "block.yaml", ".")


def test_a_block_on_a_table_weighs_on_it():
    m = StaticModel(_block())
    eq = solve_equilibrium(m, np.zeros(1))
    assert eq.converged
    weight = m.F[: m.n_mech].reshape(-1, 3).sum(axis=0)
    reaction = m.contact_forces(eq.q)[: m.n_mech].reshape(-1, 3).sum(axis=0)
    assert np.linalg.norm(reaction + weight) <= 1e-8 * np.linalg.norm(weight)
    (c,) = m.contacts(eq.q)
    assert c["name"] == "table" and np.allclose(c["force"], reaction, rtol=1e-12, atol=1e-15)
    assert c["points"] == 25  # the bottom face's 5 x 5 nodes
    g = m.contact_terms()[0].contact_set.gaps(m.positions(eq.q))[0]
    assert g.min() > -1e-9 * 0.01


def _beam(order, gravity, obstacle=True, gap=0.0, radius=0.005, divisions=(20, 2, 2), plane=False):
    """A cantilever clamped at x = 0 under its weight, its tip resting on a cylinder across it (a rounded,
    frictionless support) whose top is ``gap`` below the tip's lower edge."""
    d = {"mesh": {"generate": "box", "size": [L, B, T], "divisions": list(divisions), "origin": [0, -B / 2, -T / 2],
                  "order": order},
         "material": {"young_modulus": E, "poisson_ratio": 0.0, "density": RHO, "model": "linear"},
         "fixed": {"box": [-1e-6, -1, -1, 1e-6, 1, 1]}, "gravity": [0, 0, -gravity],
         "cables": [{"points": [[0.1, 0, 0.002], [0.15, 0, 0.002]], "pull_point": [0, 0, 0.002], "u_max": 0.01}],
         "end_effector": [L, 0, 0]}
    if plane:  # tilted so that only the tip's edge reaches it
        d["obstacles"] = [{"name": "ramp", "plane": {"point": [L, -B / 2, -T / 2 - gap], "normal": [-0.3, 0.1, 1]}}]
    elif obstacle:
        z = -T / 2 - gap - radius
        d["obstacles"] = [{"name": "prop", "cylinder": {"a": [L, -0.02, z], "b": [L, 0.02, z], "radius": radius}}]
    return StaticModel(problem_from_dict(d, "beam.yaml", "."))


EI = E * B * T**3 / 12


def _sag(m, q, x):
    """Vertical displacement of the beam's axis at x."""
    return float((m.embedding(np.array([[x, 0.0, 0.0]])) @ q)[2])


def test_a_propped_cantilever_matches_beam_theory_on_10_node_tets():
    g = 0.01  # small deflections (~1e-4 of the length): the linear theory's setting
    w = RHO * g * B * T
    m = _beam(2, g)
    eq = solve_equilibrium(m, np.zeros(1))
    assert eq.converged
    (c,) = m.contacts(eq.q)
    assert c["force"][2] == pytest.approx(3 * w * L / 8, rel=0.02)  # the prop's reaction
    assert abs(c["force"][0]) < 1e-3 * c["force"][2]
    assert _sag(m, eq.q, L / 2) == pytest.approx(-w * L**4 / (192 * EI), rel=0.02)  # midspan deflection
    # without the prop the tip falls as a cantilever's: wL^4 / 8EI
    free = _beam(2, g, obstacle=False)
    eq0 = solve_equilibrium(free, np.zeros(1))
    assert _sag(free, eq0.q, L) == pytest.approx(-w * L**4 / (8 * EI), rel=0.02)


def test_a_prop_below_a_gap_is_met_at_the_load_beam_theory_says():
    gap = 1e-4
    g_touch = gap * 8 * EI / (RHO * B * T * L**4)  # the gravity at which the free tip falls by the gap
    before = _beam(2, 0.8 * g_touch, gap=gap)
    eq = solve_equilibrium(before, np.zeros(1))
    assert eq.converged and before.contacts(eq.q)[0]["points"] == 0
    weight = RHO * 0.8 * g_touch * B * T * L
    # what remains is the smoothing's lambda g = eps^2 / 2 at a 1e-5 m gap
    assert np.linalg.norm(before.contacts(eq.q)[0]["force"]) < 1e-6 * weight
    after = _beam(2, 2 * g_touch, gap=gap)
    eq = solve_equilibrium(after, np.zeros(1))
    w = RHO * 2 * g_touch * B * T
    # the prop takes what the tip's deflection beyond the gap needs: 3wL/8 - 3 EI gap / L^3
    assert after.contacts(eq.q)[0]["force"][2] == pytest.approx(3 * w * L / 8 - 3 * EI * gap / L**3, rel=0.02)


def test_an_obstacle_nobody_touches_changes_nothing():
    free = _beam(1, 1.0, obstacle=False)
    far = _beam(1, 1.0, gap=0.05)  # 5 cm below a tip that sags ~2.4 cm
    a, b = solve_equilibrium(free, np.zeros(1), target=1e-13), solve_equilibrium(far, np.zeros(1), target=1e-13)
    assert a.converged and b.converged
    assert np.abs(b.q[: far.n_mech] - a.q).max() < 1e-11 * np.abs(a.q).max()
    assert far.contacts(b.q)[0]["points"] == 0


@pytest.mark.parametrize("plane", [False, True])
def test_contact_tangent_and_hessian_match_finite_differences(plane):
    """On the cylinder (curved) the tangent; on a plane also the Hessian, which leaves out the distance's
    third derivatives (zero on a flat obstacle; docs/methods.md)."""
    rng = np.random.default_rng(3)
    m = _beam(2, 3.0, divisions=(8, 1, 1), radius=0.01, plane=plane)
    u = np.zeros(1)
    eq = solve_equilibrium(m, u)
    assert eq.converged and m.contacts(eq.q)[0]["points"] > 0
    q = eq.q + m.full(1e-7 * rng.standard_normal(m.n_free))
    _, K, _ = m.residual_and_tangent(q, u)
    d = 1e-9 * rng.standard_normal(m.n_free)
    qp, qm = q.copy(), q.copy()
    qp[m.free] += d
    qm[m.free] -= d
    fd = (m.residual(qp, u) - m.residual(qm, u)) / 2
    assert np.linalg.norm(K @ d - fd) < 1e-6 * np.linalg.norm(fd)
    if not plane:
        return
    lam = rng.standard_normal(m.n_free)
    Hqq, _ = m.residual_hessian(q, u, lam)

    def vjp(qq):
        return m.residual_and_tangent(qq, u)[1].T @ lam

    fd = (vjp(qp) - vjp(qm)) / 2
    assert np.linalg.norm(Hqq @ d - fd) < 1e-5 * np.linalg.norm(fd)


def test_the_trunk_above_a_table_slides_on_it_and_fb_finds_the_forward_cells():
    """The 2-cable trunk (coarse mesh) with a cable that pulls it down onto a table cutting its free
    workspace: FB's strict recall against a forward cloud with the table, no point below it."""
    mesh = trunk_mesh(resolution=0.5)
    pb = Problem(mesh, Material("corotational", 1.8e7, 0.45, 1100.0), nodes_in_box(mesh, [-1, -1, -1], [1, 1, 0.02]),
                 [trunk_cable(0, "long"), trunk_cable(270, "long")], np.array([0.0, 0.0, 0.195]),
                 gravity=np.array([0.0, -9.81, 0.0]), name="trunk_table")
    # free, the tip reaches y = -31 mm; the table 22 mm below the axis stops its lower side at y = -17 mm
    pb.obstacles = [Obstacle("plane", "table", {"point": np.array([0, -0.022, 0]), "normal": np.array([0, 1.0, 0])})]
    model = StaticModel(pb)
    fb = forward_backward(pb, FBSettings(step=0.005, progress=False), model=model)
    fw = forward(pb, 15, model=model)
    assert compare(fw, fb)["cells_a_in_b"] >= 0.98
    for r in (fb, fw):
        assert r.points[:, 1].min() > -0.022 + 0.004  # the tip's centre stays about its radius above
    pressing = 0
    for u in fb.u[::4]:  # every reported state is an equilibrium on its side of the table
        eq = solve_equilibrium(model, u)
        assert eq.converged
        assert "obstacle" not in admissibility(model, eq.q, u, eq.factorization).violations
        assert model.positions(eq.q)[:, 1].min() >= -0.022 - 1e-9
        pressing += model.contacts(eq.q)[0]["points"] > 0
    assert pressing > 0


def test_the_finger_closes_on_an_egg_harder_as_its_cable_shortens():
    """problems/finger_object.yaml: SoftRobots' finger (displacement-controlled cable) under an egg (a closed
    STL): the egg's push grows with the shortening, nothing of the finger enters it, and before the finger
    reaches it the answer is the one without the egg."""
    from casadi_ws import load_problem
    from casadi_ws.fem.surface import boundary_faces

    pb = load_problem(REPO / "problems" / "finger_object.yaml")
    model = StaticModel(pb)
    bare = load_problem(REPO / "problems" / "finger_object.yaml")
    bare.obstacles = []
    free = StaticModel(bare)
    egg = pb.obstacles[0]
    faces = boundary_faces(pb.mesh)
    pushes, q, u0 = [], None, None
    for s in np.linspace(0.0, 0.0175, 8):
        u = np.array([s])
        eq = solve_equilibrium(model, u, q0=q, u0=u0)
        assert eq.converged
        q, u0 = eq.q, u
        x = model.positions(eq.q)
        # nodes and face centroids all outside the egg (to round-off)
        assert egg.gap(np.vstack([x, x[faces].mean(axis=1)]))[0].min() > -1e-9
        (c,) = model.contacts(eq.q)
        pushes.append(np.linalg.norm(c["force"]))
        if c["points"] == 0:
            ref = solve_equilibrium(free, u)
            assert np.abs(eq.q[: free.n_dof] - ref.q).max() < 1e-7 * np.abs(ref.q).max()
    pushes = np.array(pushes)
    assert pushes[0] < 1e-9 and pushes[-1] > 0.1  # N
    touching = pushes > 1e-6
    assert np.all(np.diff(pushes[touching]) > 0)  # harder as it shortens


def test_an_obstacles_position_is_a_design_variable():
    """A study varies where the table stands through the key path of its point (docs/studies.md)."""
    from casadi_ws.io.problem import read_yaml
    from casadi_ws.study.spec import apply, study_from_dict

    path = REPO / "problems" / "trunk_table.yaml"
    study = study_from_dict({"problem": str(path), "variables": [
        {"path": "obstacles[0].plane.point[1]", "range": [-0.03, -0.02], "n": 2}],
        "workspace": {"method": "forward", "n_d": 3}, "objectives": [{"maximize": "volume"}], "method": "grid"},
        REPO / "study.yaml")
    (var,) = study.variables
    assert var.grid() == [-0.03, -0.02]
    data = apply(read_yaml(path), {var.path: -0.025})
    pb = problem_from_dict(data, str(path), path.parent)
    assert pb.obstacles[0].params["point"][1] == -0.025


def test_obstacles_are_in_the_paraview_scene_and_the_report(tmp_path):
    import meshio

    from casadi_ws.io.report import write_report
    from casadi_ws.io.scene import write_scene

    pb = _block(obstacles=[{"name": "table", "plane": {"point": [0, 0, 0], "normal": [0, 0, 1]}},
                           {"name": "ball", "sphere": {"center": [0.03, 0, 0.005], "radius": 0.005}}])
    assert "obstacles.vtu" in write_scene(pb, tmp_path)
    m = meshio.read(tmp_path / "obstacles.vtu")
    owner = m.cell_data["obstacle"][0]
    assert set(owner) == {0, 1}
    table = m.points[m.cells[0].data[owner == 0].ravel()]
    assert np.allclose(table[:, 2], 0.0)  # the plane's square lies in the plane
    res = forward(pb, 2, model=StaticModel(pb))
    assert np.all(res.maps()["contact"] > 0)  # it stands on the table at every input
    page = write_report(res, tmp_path / "report.html", pb.mesh, pb.obstacles).read_text()
    assert "obstacle table" in page and "obstacle ball" in page
