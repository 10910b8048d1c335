"""Pressure cavities (issue: pneumatic cavities): volume, its exact derivatives, invariance, the cavity found
by a point, and the closed form of a pressurised box-shaped chamber's energy (Clapeyron)."""

import numpy as np
import pytest

from casadi_ws import Cavity, Material, Problem, StaticModel, box_mesh, solve_equilibrium
from casadi_ws.actuation.base import quantity_functions
from casadi_ws.actuation.cavity import surface_volume
from casadi_ws.fem.mesh import Mesh, quadratic
from casadi_ws.io.cavities import cavity_enclosing, inner_boundaries
from casadi_ws.io.problem import nodes_on_plane


def icosphere(level: int):
    """Unit sphere triangulated by subdividing an icosahedron (outward normals), vertices on the sphere."""
    t = (1 + 5 ** 0.5) / 2
    X = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
                  [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], float)
    F = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
                  [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5],
                  [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    X = X / np.linalg.norm(X, axis=1, keepdims=True)
    for _ in range(level):
        pts, mid, new = list(X), {}, []

        def m(a, b):
            key = (min(a, b), max(a, b))
            if key not in mid:
                p = (X[a] + X[b]) / 2
                pts.append(p / np.linalg.norm(p))
                mid[key] = len(pts) - 1
            return mid[key]
        for a, b, c in F:
            ab, bc, ca = m(a, b), m(b, c), m(c, a)
            new += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        X, F = np.array(pts), np.array(new)
    return X, F


def sphere6(level: int):
    """The same sphere with 6-node triangles, mid-edge nodes on the sphere."""
    X, F = icosphere(level)
    pts, mid, F6 = list(X), {}, []
    for tri in F:
        ids = []
        for a, b in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])):
            key = (min(a, b), max(a, b))
            if key not in mid:
                p = X[a] + X[b]
                pts.append(p / np.linalg.norm(p))
                mid[key] = len(pts) - 1
            ids.append(mid[key])
        F6.append(list(tri) + ids)
    return np.array(pts), np.array(F6)


def test_sphere_volume_converges_to_the_exact_one():
    exact = 4 * np.pi / 3
    flat = [abs(surface_volume(*icosphere(k)) - exact) / exact for k in (2, 3, 4)]
    curved = [abs(surface_volume(*sphere6(k)) - exact) / exact for k in (1, 2, 3)]
    assert flat[2] < 0.004 and curved[2] < 1e-5
    assert flat[0] / flat[1] > 3.5 and flat[1] / flat[2] > 3.5  # O(h^2) for flat triangles
    assert curved[0] / curved[1] > 10 and curved[1] / curved[2] > 10  # O(h^4) for curved ones


def hollow_box(n=6, order=1):
    """A unit-cube block (metres /10) with a closed cubic chamber in its middle: the centre hexes removed."""
    mesh = box_mesh((0.1, 0.1, 0.1), (n, n, n))
    c = mesh.nodes[mesh.tets].mean(axis=1)
    keep = ~np.all(np.abs(c - 0.05) < 0.05 / 3 * (1 + 1e-9), axis=1)  # the middle third in each direction
    tets = mesh.tets[keep]
    used = np.unique(tets)
    remap = -np.ones(mesh.n_nodes, dtype=np.int64)
    remap[used] = np.arange(used.size)
    out = Mesh(mesh.nodes[used], remap[tets], "<hollow box>")
    return quadratic(out) if order == 2 else out


@pytest.mark.parametrize("order", [1, 2])
def test_box_chamber_is_found_and_has_the_exact_volume(order):
    mesh = hollow_box(order=order)
    assert len(inner_boundaries(mesh)) == 1
    cav = cavity_enclosing(mesh, [0.05, 0.05, 0.05], "chamber", 0.0, 1e4)
    assert np.isclose(cav.rest_volume(), (0.1 / 3) ** 3, rtol=1e-12)
    with pytest.raises(ValueError, match="inside the solid"):
        cavity_enclosing(mesh, [0.01, 0.01, 0.01])
    with pytest.raises(ValueError, match="none of the mesh's 1 closed inner"):
        cavity_enclosing(mesh, [0.5, 0.5, 0.5])


@pytest.mark.parametrize("six", [False, True])
def test_the_volume_summed_over_faces_has_the_derivatives_of_the_whole(rng, six):
    """quantity_functions takes a cavity's volume face by face (Cavity.quantity_terms, ~6x faster to build
    than differentiating the whole surface's); the same value, gradient and Hessian, with the same pattern."""
    import casadi as ca

    X, F = sphere6(1) if six else icosphere(1)
    X = X * 0.01 + rng.normal(size=X.shape) * 1e-4
    cav = Cavity(X, F, None, 0.0, 1.0)
    f = quantity_functions(cav)
    P = ca.SX.sym("P", X.size)
    Q = cav.quantity(P)
    H = ca.hessian(Q, P)[0]
    assert f["hessian_sparsity"] == H.sparsity()
    whole = ca.Function("w", [P], [Q, ca.gradient(Q, P), H])
    parts = ca.Function("p", [f["P"]], [f["Q"], f["dQ"], ca.SX(f["hessian_sparsity"], f["d2Q"])])
    for a, b in zip(whole(X.ravel()), parts(X.ravel())):
        a, b = a.full(), b.full()
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-13 * np.abs(a).max())


@pytest.mark.parametrize("level, six", [(1, False), (1, True)])
def test_volume_derivatives_and_invariance(rng, level, six):
    X, F = sphere6(level) if six else icosphere(level)
    X = X * 0.01 + rng.normal(size=X.shape) * 1e-4  # a lumpy centimetre sphere
    cav = Cavity(X, F, None, 0.0, 1.0)
    f = quantity_functions(cav)
    import casadi as ca

    V = ca.Function("V", [f["P"]], [f["Q"], f["dQ"], ca.hessian(f["Q"], f["P"])[0]])
    P = X.ravel()
    out = V(P)
    v, g, H = float(out[0]), out[1].full().ravel(), out[2].full()
    assert np.isclose(v, surface_volume(X, F))
    d = rng.normal(size=P.size) * 1e-5
    h = 1e-3
    fd = (float(V(P + h * d)[0]) - float(V(P - h * d)[0])) / (2 * h)
    assert np.isclose(fd, g @ d, rtol=1e-7)
    fd2 = (np.asarray(V(P + h * d)[1]).ravel() - np.asarray(V(P - h * d)[1]).ravel()) / (2 * h)
    np.testing.assert_allclose(fd2, H @ d, rtol=1e-6, atol=1e-9 * np.abs(fd2).max())
    # rigid motions leave V unchanged
    from scipy.spatial.transform import Rotation

    R = Rotation.from_rotvec([0.3, -1.1, 0.7]).as_matrix()
    Y = X @ R.T + np.array([0.2, -0.4, 1.0])
    assert np.isclose(surface_volume(Y, F), v, rtol=1e-12)


def chamber_problem(order=1, model="linear"):
    mesh = hollow_box(order=order)
    cav = cavity_enclosing(mesh, [0.05, 0.05, 0.05], "chamber", 0.0, 2e4)
    return Problem(mesh, Material(model, 1e6, 0.3), nodes_on_plane(mesh, [0, 0, 0], [0, 0, 1]), [cav],
                   np.array([0.05, 0.05, 0.1]), name="chamber")


@pytest.mark.parametrize("order", [1, 2])
def test_clapeyron_pressure_work_is_twice_the_strain_energy(order):
    """Linear elasticity, small pressure: p dV = 2 W (W = 1/2 q^T K q), as the pressure's work is
    p dV/dq . q and the load is proportional."""
    pb = chamber_problem(order)
    m = StaticModel(pb)
    p = 100.0
    eq = solve_equilibrium(m, [p], tol=1e-12)
    assert eq.converged
    dV = m.actuator_states(eq.q)[0] - m.actuator_states(np.zeros(m.n_dof))[0]
    K = m.element_stiffness(np.zeros(m.n_dof))
    qf = eq.q[m.free]
    W = 0.5 * qf @ (K @ qf)
    assert dV > 0
    # linear elements, but the cavity's force follows the geometry: equal to first order in p
    assert np.isclose(p * dV, 2 * W, rtol=1e-3)


def test_cavity_pressure_tangent_and_nlp_hessian_match_finite_differences(rng):
    import casadi as ca

    from casadi_ws import residual_function

    pb = chamber_problem(1, "neohookean")
    m = StaticModel(pb)
    u = np.array([5e3])
    eq = solve_equilibrium(m, u)
    assert eq.converged
    R = residual_function(m)
    nq = m.n_free
    q, uu = ca.MX.sym("q", nq), ca.MX.sym("u", 1)
    lam = rng.normal(size=nq)
    H = ca.Function("H", [q, uu], [ca.hessian(ca.dot(ca.DM(lam), R(q, uu)), ca.vertcat(q, uu))[0]])
    x0 = np.concatenate([eq.q[m.free], u])
    v = rng.normal(size=nq + 1) * np.concatenate([np.full(nq, 1e-4), [100.0]])
    h = 1e-4

    def res(x):
        return m.residual(m.full(x[:nq]), x[nq:])

    def grad(x):
        _, K, dRdu = m.residual_and_tangent(m.full(x[:nq]), x[nq:])
        return np.concatenate([K.T @ lam, dRdu.T @ lam])

    _, K, dRdu = m.residual_and_tangent(eq.q, u)
    J = np.hstack([K.toarray(), dRdu])
    fd = (res(x0 + h * v) - res(x0 - h * v)) / (2 * h)
    assert np.linalg.norm(fd - J @ v) < 1e-6 * np.linalg.norm(fd)
    fd = (grad(x0 + h * v) - grad(x0 - h * v)) / (2 * h)
    Hv = H(x0[:nq], x0[nq:]).sparse() @ v
    assert np.linalg.norm(fd - Hv) < 1e-5 * np.linalg.norm(fd)


def lame_volume_change(p, a, b, E, nu):
    """Thick-walled sphere under internal pressure p (Lame): the cavity's volume change to first order."""
    u_a = p * a**3 / (E * (b**3 - a**3)) * ((1 - 2 * nu) * a + (1 + nu) * b**3 / (2 * a**2))
    return 4 * np.pi * a**2 * u_a


def sphere_problem_file(tmp_path, mesh_name, order=1, model="linear"):
    """A problem file for a shipped hollow sphere: the cavity found by its centre, a statically determinate
    3-2-1 support on the nodes nearest to (-b, 0, 0) (all), (b, 0, 0) (y, z) and (0, b, 0) (z), so that the
    supports take no load and Lame's solution holds."""
    import meshio
    from conftest import MESHES

    b = 0.02
    X = meshio.read(MESHES / mesh_name).points
    boxes = []
    for target in ([-b, 0, 0], [b, 0, 0], [0, b, 0]):
        x = X[np.argmin(np.linalg.norm(X - target, axis=1))]
        boxes.append([(x - 1e-6).tolist(), (x + 1e-6).tolist()])
    text = f"""
mesh: {{file: {MESHES / mesh_name}, order: {order}}}
material: {{model: {model}, young_modulus: 1.0e+6, poisson_ratio: 0.3}}
fixed:
  - box: {boxes[0]}
  - {{box: {boxes[1]}, components: [y, z]}}
  - {{box: {boxes[2]}, components: [z]}}
cavities:
  - {{name: inside, enclosing: [0, 0, 0], u_min: 0, u_max: 1000}}
end_effector: [0, 0, {b - 1e-4}]
"""
    path = tmp_path / "sphere.yaml"
    path.write_text(text)
    return path


def _lame_error(tmp_path, mesh_name, order):
    from casadi_ws import load_problem

    pb = load_problem(sphere_problem_file(tmp_path, mesh_name, order))
    assert [a.kind for a in pb.actuators] == ["cavity"] and len(pb.partial_fixed) == 2
    m = StaticModel(pb)
    assert m.n_free == 3 * m.n_nodes - 6  # 3-2-1: six components fixed
    p = 100.0
    eq = solve_equilibrium(m, [p], tol=1e-11)
    assert eq.converged
    dV = m.actuator_states(eq.q)[0] - m.actuator_states(np.zeros(m.n_dof))[0]
    exact = lame_volume_change(p, 0.01, 0.02, 1e6, 0.3)
    return abs(dV - exact) / exact


@pytest.mark.slow
@pytest.mark.parametrize("order, meshes, tol", [(1, ("hollow_sphere_4mm.vtu", "hollow_sphere_2.5mm.vtu"), 0.12),
                                                (2, ("hollow_sphere_5mm_o2.vtu", "hollow_sphere_3mm_o2.vtu"), 0.01)])
def test_hollow_sphere_volume_change_matches_lame_and_converges(tmp_path, order, meshes, tol):
    """Measured: order 1 29 % then 11 % (4, 2.5 mm), order 2 0.95 % then 0.21 % (5, 3 mm); 2 to 4
    elements through the 10 mm wall."""
    coarse, fine = (_lame_error(tmp_path, name, order) for name in meshes)
    assert fine < coarse / 2
    assert fine < tol and (order == 1 or coarse < 0.03)


def test_surface_file_turned_around_and_mixed_with_cables(tmp_path):
    """A closed surface file oriented into the cavity is turned around (same volume as 'enclosing'); cables
    and cavities mix, u lists the cables first."""
    from conftest import MESHES

    from casadi_ws import load_problem

    text = f"""
mesh: {{file: {MESHES / 'hollow_sphere_4mm.vtu'}}}
material: {{model: corotational, young_modulus: 1.0e+6, poisson_ratio: 0.3}}
fixed: {{box: [[-0.021, -0.021, -0.021], [0.021, 0.021, -0.017]]}}
end_effector: [0, 0, 0.0199]
cavities:
  - {{name: by_file, surface: {MESHES / 'hollow_sphere_4mm_cavity_inverted.vtk'}, u_min: -500, u_max: 1000}}
  - {{name: by_point, enclosing: [0, 0, 0], u_max: 1000}}
cables:
  - {{name: c, points: [[0.015, 0, -0.01], [0.015, 0, 0.01]], pull_point: [0.015, 0, -0.03], u_max: 1}}
"""
    (tmp_path / "mixed.yaml").write_text(text)
    pb = load_problem(tmp_path / "mixed.yaml")
    assert [a.name for a in pb.actuators] == ["c", "by_file", "by_point"]
    v1, v2 = pb.actuators[1].rest_volume(), pb.actuators[2].rest_volume()
    assert v1 > 0 and np.isclose(v1, v2, rtol=1e-12)
    m = StaticModel(pb)
    eq = solve_equilibrium(m, [0.5, 300.0, 0.0])
    assert eq.converged
    states = m.actuator_states(eq.q)
    assert states[1] > v1 and states[2] > v2  # the pressure inflates it, whoever names it


def test_reach_and_follow_with_a_cavity():
    """Inverse control drives a pressure: the tip of a chamber block, reached at a pressure, is found again."""
    from casadi_ws import follow, reach

    pb = chamber_problem(1, "neohookean")
    m = StaticModel(pb)
    goal = solve_equilibrium(m, [8e3])
    r = reach(m, goal.tip)
    # the tip moves ~9 nm per Pa here: the equilibria's tolerance (1e-8 of the force) allows a few Pa
    assert r.reachable and abs(r.u[0] - 8e3) < 8.0  # Pa
    path = [solve_equilibrium(m, [p]).tip for p in (2e3, 4e3)]
    f = follow(m, path)
    assert f.reachable.all()


def test_surface_files_that_are_not_a_chamber_wall_are_refused(tmp_path):
    """Found by review: the faces of an interior tetrahedron, and two chambers oriented differently, were
    accepted (pressure on interior nodes; one chamber deflated)."""
    import meshio

    from casadi_ws.fem.surface import reverse
    from casadi_ws.io.cavities import cavity_from_surface

    mesh = hollow_box(n=6)
    t = mesh.tets[np.argmin(np.linalg.norm(mesh.nodes[mesh.tets].mean(1) - 0.02, axis=1))]
    faces = np.array([[t[0], t[2], t[1]], [t[0], t[1], t[3]], [t[1], t[2], t[3]], [t[0], t[3], t[2]]])
    meshio.write(tmp_path / "tet.vtk", meshio.Mesh(mesh.nodes, [("triangle", faces)]))
    with pytest.raises(ValueError, match="4 of its 4 triangles are not on the mesh's boundary"):
        cavity_from_surface(mesh, tmp_path / "tet.vtk")
    big = box_mesh((0.2, 0.1, 0.1), (12, 6, 6))
    c = big.nodes[big.tets].mean(1)
    holes = np.all(np.abs(c - [0.05, 0.05, 0.05]) < 0.0251, axis=1) | \
        np.all(np.abs(c - [0.15, 0.05, 0.05]) < 0.0168, axis=1)
    tets = big.tets[~holes]
    used = np.unique(tets)
    remap = -np.ones(big.n_nodes, dtype=np.int64)
    remap[used] = np.arange(used.size)
    two = Mesh(big.nodes[used], remap[tets], "<two chambers>")
    a, b = inner_boundaries(two)
    meshio.write(tmp_path / "two.vtk", meshio.Mesh(two.nodes, [("triangle", np.vstack([a, reverse(b)]))]))
    with pytest.raises(ValueError, match="2 closed pieces are oriented differently"):
        cavity_from_surface(two, tmp_path / "two.vtk")
    meshio.write(tmp_path / "both.vtk", meshio.Mesh(two.nodes, [("triangle", np.vstack([a, b]))]))
    cav = cavity_from_surface(two, tmp_path / "both.vtk")
    assert np.isclose(cav.rest_volume(), surface_volume(two.nodes, a) + surface_volume(two.nodes, b))


def test_checkpoint_fingerprint_sees_material_regions():
    from dataclasses import replace

    from casadi_ws.runtime.run_state import fingerprint

    pb = chamber_problem(1, "linear")
    tets = np.flatnonzero(pb.mesh.nodes[pb.mesh.tets].mean(1)[:, 2] < 0.02)
    a = StaticModel(replace(pb, regions=[(tets, Material("linear", 1e7, 0.3))]))
    b = StaticModel(replace(pb, regions=[(tets, Material("linear", 5e7, 0.3))]))
    assert fingerprint("fb", a, {}) != fingerprint("fb", b, {})


def test_no_solver_output_at_exit_and_other_exit_handlers_keep_stdout():
    import subprocess
    import sys

    code = ("import atexit; atexit.register(lambda: print('report')); import numpy as np, casadi_ws as cw\n"
            "from conftest import small_trunk\n"
            "m = cw.StaticModel(small_trunk()); r = cw.reach(m, m.p0 + [0.004, 0, -0.001])\n"
            "q = cw.equilibrium_function(m)\n")
    from conftest import REPO

    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO / "tests")
    assert r.returncode == 0, r.stderr
    assert r.stdout == "report\n"  # MUMPS's 'JOB = -2' farewell is not there, the user's report is
