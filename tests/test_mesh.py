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
