"""Meshes: reading, generating, checking, embedding; the real SOFA meshes load and solve."""

import meshio
import numpy as np
import pytest
from conftest import MESHES, SOFA_TRUNK

from casadi_ws import Cable, Material, MeshError, Problem, StaticModel, box_mesh, load_mesh, trunk_mesh
from casadi_ws import solve_equilibrium, trunk_cable
from casadi_ws.fem.mesh import embed
from casadi_ws.io.problem import nodes_in_box, tip_centre



def test_trunk_generator_defaults_match_sofa_trunk():
    m = trunk_mesh()
    assert 700 <= m.n_nodes <= 1500
    assert np.isclose(m.nodes[:, 2].max(), 0.195) and np.isclose(m.nodes[:, 2].min(), 0.0)
    r = np.linalg.norm(m.nodes[:, :2], axis=1)
    assert np.isclose(r[m.nodes[:, 2] == 0].max(), 0.013) and np.isclose(r[np.isclose(m.nodes[:, 2], 0.195)].max(), 0.005)
    # volume of the tapered cylinder, up to the polygonal section
    exact = np.pi * 0.195 * (0.013**2 + 0.013 * 0.005 + 0.005**2) / 3
    assert abs(m.volumes().sum() - exact) < 0.02 * exact
    assert np.all(m.volumes() > 0)
    assert trunk_mesh(resolution=2.0).n_nodes > 4 * m.n_nodes


def test_embedding_reproduces_points_and_measures_outside_distance(rng):
    m = box_mesh((1.0, 2.0, 3.0), (2, 3, 4))
    pts = rng.uniform([0, 0, 0], [1, 2, 3], size=(20, 3))
    e = embed(m, pts)
    W = e.matrix(m)
    np.testing.assert_allclose((W @ m.nodes.ravel()).reshape(-1, 3), pts, atol=1e-12)
    assert np.all(e.outside == 0) and np.all(e.weights > -1e-9)
    out = embed(m, [[1.25, 1.0, 1.5]])  # 0.25 beyond the face x = 1
    assert np.isclose(out.outside[0], 0.25)
    np.testing.assert_allclose(out.matrix(m) @ m.nodes.ravel(), [1.25, 1.0, 1.5], atol=1e-12)  # extrapolated


def test_file_mesh_ignores_other_cells_and_scales(tmp_path):
    m = box_mesh((10.0, 10.0, 10.0), (1, 1, 1))
    cells = [("tetra", m.tets), ("triangle", m.tets[:, :3]), ("vertex", np.arange(3)[:, None])]
    pts = np.vstack([m.nodes, [[99.0, 99.0, 99.0]]])  # a node no tetrahedron uses
    meshio.write(tmp_path / "b.vtk", meshio.Mesh(pts, cells))
    loaded = load_mesh(tmp_path / "b.vtk", scale=0.001)
    assert loaded.n_tets == m.n_tets and loaded.n_nodes == m.n_nodes
    np.testing.assert_allclose(loaded.nodes.max(0), [0.01, 0.01, 0.01])


def test_inverted_and_degenerate_tetrahedra_are_named(tmp_path):
    m = box_mesh((1.0, 1.0, 1.0), (1, 1, 1))
    tets = m.tets.copy()
    tets[3, [1, 2]] = tets[3, [2, 1]]
    meshio.write(tmp_path / "inv.vtu", meshio.Mesh(m.nodes, [("tetra", tets)]))
    with pytest.raises(MeshError, match=r"inv\.vtu: tetrahedron 3 .* inverted"):
        load_mesh(tmp_path / "inv.vtu")
    tets = m.tets.copy()
    tets[5, 3] = tets[5, 2]
    meshio.write(tmp_path / "deg.vtu", meshio.Mesh(m.nodes, [("tetra", tets)]))
    with pytest.raises(MeshError, match=r"tetrahedron 5 .* degenerate"):
        load_mesh(tmp_path / "deg.vtu")
    meshio.write(tmp_path / "tri.vtk", meshio.Mesh(m.nodes, [("triangle", m.tets[:, :3])]))
    with pytest.raises(MeshError, match="no linear tetrahedra"):
        load_mesh(tmp_path / "tri.vtk")


def test_sofa_trunk_loads_and_bends_towards_pulled_cable():
    mesh = load_mesh(SOFA_TRUNK, scale=0.001)
    assert (mesh.n_nodes, mesh.n_tets) == (709, 1972)
    cables = [trunk_cable(0, "long"), trunk_cable(90, "long")]
    assert embed(mesh, cables[0].points).outside.max() > 0  # grooves: some points lie outside
    pb = Problem(mesh, Material("corotational", 1.8e7, 0.45), nodes_in_box(mesh, [-1, -1, -1], [1, 1, 0.02]),
                 cables, tip_centre(mesh))
    # its grooves are deep necks (radius ~5 mm): at E = 18 MPa a few newtons already bend it by centimetres
    eq = solve_equilibrium(StaticModel(pb), [3.0, 0.0])
    assert eq.converged
    assert eq.tip[0] > 0.01 and abs(eq.tip[1]) < 0.1 * eq.tip[0]


def test_sofa_finger_and_diamond_load_and_solve():
    finger = load_mesh(MESHES / "finger.vtk", scale=0.001)
    xs = np.linspace(-0.015, -0.095, 9)
    cable = Cable(np.column_stack([xs, np.full_like(xs, 0.0035), np.full_like(xs, 0.0075)]),
                  np.array([0.0, 0.0035, 0.0075]), 0.0, 5.0)
    pb = Problem(finger, Material("corotational", 5e5, 0.45, 1100), nodes_in_box(finger, [-0.004, -1, -1], [1, 1, 1]),
                 [cable], np.array([-0.1, 0.0075, 0.0075]), gravity=np.array([0, 0, -9.81]))
    eq = solve_equilibrium(StaticModel(pb), [2.0])
    assert eq.converged and eq.tip[1] < 0.0075 - 1e-3  # the cable on the y = 3.5 mm side curls it that way

    diamond = load_mesh(MESHES / "diamond.vtu", scale=0.001)
    assert diamond.n_tets == 4147
    arms = [np.array([0.09, 0.0, 0.0]), np.array([-0.09, 0.0, 0.0]), np.array([0.0, 0.0, 0.09])]
    cables = [Cable(a[None], np.array([0.0, -0.12, 0.0]), 0.0, 5.0, f"arm{i}") for i, a in enumerate(arms)]
    pb = Problem(diamond, Material("corotational", 1e6, 0.45), nodes_in_box(diamond, [-1, 0.08, -1], [1, 1, 1]),
                 cables, np.array([0.0, -0.06, 0.0]))
    eq = solve_equilibrium(StaticModel(pb), [1.0, 1.0, 0.0])
    assert eq.converged and eq.tip[1] < -0.06


def test_tet10_shape_functions_and_quadratic_meshes():
    from casadi_ws.fem.elements import TET10
    from casadi_ws.fem.mesh import quadratic

    N = TET10.shape(TET10.ref_nodes)
    np.testing.assert_allclose(N, np.eye(10), atol=1e-14)  # Kronecker delta at the nodes
    xi = np.random.default_rng(0).dirichlet(np.ones(4), size=20)[:, 1:]
    np.testing.assert_allclose(TET10.shape(xi).sum(axis=1), 1.0)
    h = 1e-6
    for j in range(3):  # gradients against central differences
        e = np.zeros(3)
        e[j] = h
        fd = (TET10.shape(xi + e) - TET10.shape(xi - e)) / (2 * h)
        np.testing.assert_allclose(TET10.shape_gradients(xi)[:, :, j], fd, atol=1e-8)
    m1 = box_mesh((0.02, 0.03, 0.1), (2, 2, 5))
    m2 = quadratic(m1)
    assert m2.tets.shape == (m1.n_tets, 10) and m2.element is TET10
    np.testing.assert_allclose(m2.nodes[m2.tets[:, 4]], 0.5 * (m2.nodes[m2.tets[:, 0]] + m2.nodes[m2.tets[:, 1]]))
    w, _ = TET10.rest_geometry(m2.nodes[m2.tets])
    np.testing.assert_allclose(w.sum(), 0.02 * 0.03 * 0.1, rtol=1e-12)
    loads = TET10.body_load_weights(m2.nodes[m2.tets])  # consistent: corners -V/20, mid-edges V/5
    V = m1.volumes()[:, None]
    np.testing.assert_allclose(loads[:, :4], np.broadcast_to(-V / 20, (len(V), 4)), rtol=1e-10)
    np.testing.assert_allclose(loads[:, 4:], np.broadcast_to(V / 5, (len(V), 6)), rtol=1e-10)
    # a point embedded in a quadratic mesh moves with an affine field exactly
    p = np.array([[0.011, 0.017, 0.063]])
    W = embed(m2, p).matrix(m2)
    F = np.array([[1.1, 0.2, 0.0], [0.0, 0.9, 0.1], [0.05, 0.0, 1.2]])
    np.testing.assert_allclose(W @ (m2.nodes @ F.T).ravel(), (p @ F.T).ravel(), atol=1e-14)


def test_tet10_files_are_read_and_folded_or_mixed_cells_are_refused(tmp_path):
    from casadi_ws.fem.mesh import quadratic

    m2 = quadratic(box_mesh((1.0, 1.0, 1.0), (2, 2, 2)))
    meshio.write(tmp_path / "q.vtu", meshio.Mesh(m2.nodes, [("tetra10", m2.tets)]))
    back = load_mesh(tmp_path / "q.vtu")
    assert back.element.name == "tet10" and back.n_tets == m2.n_tets
    nodes = m2.nodes.copy()
    nodes[m2.tets[5, 4]] = m2.nodes[m2.tets[5, 0]] + 0.95 * (m2.nodes[m2.tets[5, 1]] - m2.nodes[m2.tets[5, 0]])
    meshio.write(tmp_path / "folded.vtu", meshio.Mesh(nodes, [("tetra10", m2.tets)]))
    with pytest.raises(MeshError, match=r"tetrahedron \d+ .* folded"):
        load_mesh(tmp_path / "folded.vtu")
    meshio.write(tmp_path / "mixed.vtu", meshio.Mesh(m2.nodes, [("tetra10", m2.tets[:3]), ("tetra", m2.tets[3:, :4])]))
    with pytest.raises(MeshError, match="mixes"):
        load_mesh(tmp_path / "mixed.vtu")


def test_order_2_in_problem_files_and_every_method_runs_on_it(tmp_path):
    import yaml

    from casadi_ws import FBSettings, ForwardSettings, ProblemError, forward, forward_backward, problem_from_dict
    from casadi_ws.control import reach

    d = yaml.safe_load((MESHES.parents[1] / "problems" / "trunk_2cables.yaml").read_text())
    d["mesh"].update(resolution=0.25, order=2)
    pb = problem_from_dict(d, "order2.yaml")
    assert pb.mesh.element.name == "tet10" and pb.mesh.tets.shape[1] == 10
    fixed_z = pb.mesh.nodes[pb.fixed_nodes, 2]
    assert fixed_z.max() <= 0.02 and np.any(np.isin(pb.fixed_nodes, pb.mesh.tets[:, 4:]))  # mid-edge nodes too
    m = StaticModel(pb)
    eq = solve_equilibrium(m, [40.0, 20.0])
    assert eq.converged and eq.tip[0] > 0.005
    fw = forward(pb, settings=ForwardSettings(n_d=3, progress=False), model=m)
    assert fw.n_points == 9
    fb = forward_backward(pb, FBSettings(step=0.02, progress=False), model=m)
    assert fb.n_points >= 3
    # reach (IPOPT) on a linear material: the corotational 10-node element's Hessian kernel is large (open)
    d["material"]["model"] = "linear"
    lin = StaticModel(problem_from_dict(d, "order2_linear.yaml"))
    target = solve_equilibrium(lin, [40.0, 20.0]).tip
    r = reach(lin, target)
    assert r.reachable and np.allclose(r.u, [40.0, 20.0], atol=1e-3)
    for bad in (3, 0, "two", True):
        d["mesh"]["order"] = bad
        with pytest.raises(ProblemError, match="mesh.order"):
            problem_from_dict(d, "order.yaml")
