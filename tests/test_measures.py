"""Workspace measures (issue: design studies): volume, area, extents and task share, against exact values."""

import json

import numpy as np
import pytest
from conftest import REPO

from casadi_ws import (Cable, ForwardSettings, Material, Problem, StaticModel, Task, WorkspaceResult, box_mesh,
                       forward, measures, solve_equilibrium)
from casadi_ws.io.problem import nodes_on_plane
from casadi_ws.solvers.equilibrium import tangent_factorization
from casadi_ws.solvers.sensitivity import sensitivity


def test_cell_volume_of_a_ball_is_within_a_cell_layer_of_the_exact_one():
    rng = np.random.default_rng(0)
    r, s = 0.02, 0.002
    p = rng.normal(size=(400000, 3))
    p = r * p / np.linalg.norm(p, axis=1, keepdims=True) * rng.uniform(0, 1, (len(p), 1)) ** (1 / 3)
    res = WorkspaceResult("forward", p, np.zeros((len(p), 3)))
    m = measures(res, step=s, origin=np.zeros(3))
    exact = 4 / 3 * np.pi * r**3
    # the occupied cells cover the ball and lie within sqrt(3) s/2 of it
    assert exact * 0.99 < m["cell_volume"] < 4 / 3 * np.pi * (r + np.sqrt(3) * s / 2) ** 3
    assert m["volume"] is None and m["volume_method"] is None  # no boundary surface: no volume, only cells
    np.testing.assert_allclose(m["extents"], [[-r, -r, -r], [r, r, r]], atol=2e-4)
    # a task box half inside the ball: about half of its cells are reached
    t = measures(res, step=s, origin=np.zeros(3), task=Task(box=[[0.0, -0.004, -0.004], [0.04, 0.004, 0.004]]))
    assert t["task_cells"] == 21 * 5 * 5 and 0.45 < t["task_share"] < 0.6


def two_cable_plate():
    """A linear-elastic cantilever plate with two cables: at small tensions the tip moves as A u."""
    L = 0.1
    mesh = box_mesh((0.02, 0.02, L), (3, 3, 12), (-0.01, -0.01, 0.0))
    z = np.linspace(0.01, L, 10)
    cables = [Cable(np.column_stack([np.full_like(z, 0.006), np.zeros_like(z), z]), np.array([0.006, 0, 0]),
                    0.0, 0.005, "x"),
              Cable(np.column_stack([np.zeros_like(z), np.full_like(z, 0.006), z]), np.array([0, 0.006, 0]),
                    0.0, 0.005, "y")]
    return Problem(mesh, Material("linear", 1e6, 0.3), nodes_on_plane(mesh, [0, 0, 0], [0, 0, 1]), cables,
                   np.array([0.0, 0.0, L]), name="plate")


def test_area_of_a_linear_two_cable_workspace_is_the_parallelogram():
    pb = two_cable_plate()
    m = StaticModel(pb)
    fw = forward(pb, settings=ForwardSettings(n_d=6, progress=False), model=m)
    eq = solve_equilibrium(m, [0.0, 0.0])
    A, _ = sensitivity(m, eq.q, tangent_factorization(m, eq.q, eq.u))
    exact = np.linalg.norm(np.cross(A[:, 0], A[:, 1])) * 0.005 * 0.005
    got = measures(fw, step=1e-6)["area"]
    # the tensions soften the plate (geometric stiffness, ~T L^2 / EI = 0.4 %): nearly linear
    assert abs(got - exact) / exact < 0.01


def test_solve_reports_measures_and_task_share(tmp_path):
    import subprocess
    import sys

    text = (REPO / "problems" / "trunk_2cables.yaml").read_text().replace("resolution: 1.0", "resolution: 0.5")
    text += "task:\n  box: [[0.0, 0.0, 0.15], [0.02, 0.02, 0.2]]\n"
    (tmp_path / "t.yaml").write_text(text)
    r = subprocess.run([sys.executable, "-m", "casadi_ws.cli", "solve", str(tmp_path / "t.yaml"), "--nd", "5",
                        "--out", str(tmp_path / "o"), "--quiet"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    s = json.loads((tmp_path / "o" / "summary.json").read_text())["measures"]
    assert s["cells"] > 0 and s["area"] > 0 and s["task"] == {"box": [[0.0, 0.0, 0.15], [0.02, 0.02, 0.2]]}
    assert 0 < s["task_share"] < 1
    r = subprocess.run([sys.executable, "-m", "casadi_ws.cli", "solve", str(tmp_path / "t.yaml"), "--nd", "2",
                        "--out", str(tmp_path / "p"), "--task-box", "1,2,3"], capture_output=True, text=True)
    assert r.returncode == 2 and "--task-box: expected xmin,ymin,zmin,xmax,ymax,zmax" in r.stderr


def test_fb_measures_count_the_cells_it_reports():
    from casadi_ws import FBSettings, forward_backward

    pb = two_cable_plate()
    m = StaticModel(pb)
    fb = forward_backward(pb, FBSettings(step=2e-6, progress=False), model=m)
    for step in (None, 2e-6):  # the command line passes --step: the same grid, the same cells
        assert measures(fb, step=step)["cells"] == len(fb.arrays["cells"])


def _cube_boundary(lo, size):
    """A closed, outward-oriented triangulated cube as a workspace boundary."""
    from casadi_ws.workspace.boundary import Boundary

    V = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float) * size + lo
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    T = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    return Boundary(V, T, np.zeros((8, 3)), "input-faces", closed=True, volume=size**3, volume_error=0.0)


def test_volume_area_and_length_each_mean_one_thing():
    rng = np.random.default_rng(1)
    # 1 input: a straight curve 3 cm long, its points out of order: a length, no area, no volume
    t = rng.permutation(np.linspace(0.0, 1.0, 31))
    one = WorkspaceResult("forward", np.column_stack([0.03 * t, 0 * t, 0 * t]), t[:, None],
                          problem={"u_min": [0.0], "u_max": [1.0]})
    m = measures(one, step=0.002)
    assert m["length"] == pytest.approx(0.03) and "area" not in m and m["volume"] is None
    # 2 inputs (a third held at one value): an area, no volume
    u = np.stack(np.meshgrid(np.linspace(0, 1, 21), np.linspace(0, 1, 21)), axis=-1).reshape(-1, 2)
    two = WorkspaceResult("forward", np.column_stack([0.01 * u, np.zeros(len(u))]),
                          np.column_stack([u, np.full(len(u), 5.0)]), problem={"u_min": [0, 0, 5], "u_max": [1, 1, 5]})
    m = measures(two, step=0.001)
    assert m["area"] == pytest.approx(1e-4) and "length" not in m and m["volume"] is None
    assert m["cell_volume"] == m["cells"] * 0.001**3
    # 3 inputs with a closed boundary: its enclosed volume
    three = WorkspaceResult("forward", rng.uniform(0, 0.01, (50, 3)), rng.uniform(0, 1, (50, 3)),
                            problem={"u_min": [0, 0, 0], "u_max": [1, 1, 1]})
    three.boundary = _cube_boundary(np.zeros(3), 0.01)
    m = measures(three, step=0.001)
    assert m["volume"] == pytest.approx(1e-6) and m["volume_method"] == "boundary" and "area" not in m
    # 4 inputs: the same; without a boundary no volume at all (the cells' is cell_volume, never volume)
    four = WorkspaceResult("forward", rng.uniform(0, 0.01, (80, 3)), rng.uniform(0, 1, (80, 4)),
                           problem={"u_min": [0, 0, 0, 0], "u_max": [1, 1, 1, 1]})
    m = measures(four, step=0.001)
    assert m["volume"] is None and m["cell_volume"] == m["cells"] * 0.001**3 > 0
    assert "area" not in m and "length" not in m
    four.boundary = _cube_boundary(np.zeros(3), 0.01)
    m = measures(four, step=0.001)
    assert m["volume"] == pytest.approx(1e-6) and m["volume_method"] == "boundary"


def test_compare_reports_both_boundary_volumes_and_their_symmetric_difference():
    from casadi_ws.workspace.compare import compare

    rng = np.random.default_rng(2)
    a = WorkspaceResult("forward", rng.uniform(0, 0.01, (200, 3)), np.zeros((200, 3)))
    b = WorkspaceResult("forward", rng.uniform(0, 0.01, (200, 3)) + [0.005, 0, 0], np.zeros((200, 3)))
    out = compare(a, b)
    assert out["volume_a"] is None and out["volume_b"] is None and "volume_symmetric_difference" not in out
    a.boundary, b.boundary = _cube_boundary(np.zeros(3), 0.01), _cube_boundary(np.array([0.005, 0, 0]), 0.01)
    out = compare(a, b)
    assert out["volume_a"] == pytest.approx(1e-6) and out["volume_b"] == pytest.approx(1e-6)
    # two 1 cm cubes overlapping by half: 0.5 + 0.5 cm^3 inside exactly one
    assert out["volume_symmetric_difference"] == pytest.approx(1e-6, rel=0.02)
    assert out["cell_volume_a"] == out["cells_a"] * out["step"] ** 3
