"""Inverse control: reach and follow, checked against forward solves."""


import numpy as np
import pytest
from conftest import cantilever, coarse_problem_file, run_cli, small_trunk

from casadi_ws import StaticModel, solve_equilibrium
from casadi_ws.workspace.forward import ForwardSettings, forward
from casadi_ws.control.inverse import ReachSettings, follow, reach


def test_round_trip_random_inputs(rng):
    pb = small_trunk("corotational", n_cables=2)
    m = StaticModel(pb)
    for _ in range(3):
        u = rng.uniform(pb.u_min, pb.u_max)
        tip = solve_equilibrium(m, u).tip
        r = reach(m, tip)
        assert r.reachable and r.error < 1e-6
        eq = solve_equilibrium(m, r.u)  # verified independently, from rest
        assert eq.converged and np.linalg.norm(eq.tip - tip) < 1e-6
        assert np.all(r.u >= pb.u_min - 1e-12) and np.all(r.u <= pb.u_max + 1e-12)


def test_far_target_returns_the_closest_reachable_tip():
    pb = small_trunk("corotational", n_cables=2)
    m = StaticModel(pb)
    target = np.array([0.08, 0.08, 0.15])  # beyond what 100 N per cable can do
    r = reach(m, target)
    assert not r.reachable and np.isfinite(r.error) and r.error > 0.01
    cloud = forward(pb, settings=ForwardSettings(n_d=21, progress=False), model=m)
    d_forward = np.linalg.norm(cloud.points - target, axis=1).min()
    spacing = np.linalg.norm(np.diff(cloud.points[:21], axis=0), axis=1).max()
    assert r.error <= d_forward + 1e-9  # no forward point is closer
    assert r.error >= d_forward - spacing  # and it is on the cloud's boundary, not beyond it
    assert np.any(np.isclose(r.u, pb.u_max)) or np.any(np.isclose(r.u, pb.u_min))


def test_follow_a_circle_inside_the_workspace(tmp_path):
    pb = small_trunk("corotational", n_cables=2)
    m = StaticModel(pb)
    # a circle of tips produced by a circle in U, so every target is reachable
    ang = np.linspace(0, 2 * np.pi, 13)
    us = np.column_stack([50 + 25 * np.cos(ang), 50 + 25 * np.sin(ang)])
    targets = np.array([solve_equilibrium(m, u).tip for u in us])
    res = follow(m, targets)
    assert res.reachable.all() and res.errors.max() < 1e-6
    assert np.abs(np.diff(res.u, axis=0)).max() < 20.0  # continuous: neighbours 13 N apart in U
    res.save_csv(tmp_path / "f.csv")
    assert np.loadtxt(tmp_path / "f.csv", delimiter=",", skiprows=1).shape == (13, 15)  # ..., u1, u2, tilt, roll, axis


def test_change_limit():
    pb = small_trunk("corotational", n_cables=2)
    m = StaticModel(pb)
    tip = solve_equilibrium(m, [40.0, 40.0]).tip
    start = solve_equilibrium(m, [0.0, 0.0])
    r = reach(m, tip, q0=start.q, u0=start.u, settings=ReachSettings(max_du=10.0))
    assert not r.reachable and np.all(r.u <= 10.0 + 1e-9)  # 40 N is out of a 10 N step


def test_regularization_trades_distance_for_lower_tensions():
    """rho |u|^2 pulls the answer towards u = 0: lower tensions, a tip short of the target, both verified."""
    pb = small_trunk("corotational", n_cables=2)
    m = StaticModel(pb)
    tip = solve_equilibrium(m, [60.0, 30.0]).tip
    plain = reach(m, tip)
    assert plain.reachable and np.allclose(plain.u, [60.0, 30.0], atol=1e-3)
    reg = reach(m, tip, settings=ReachSettings(regularization=1e-8))
    assert not reg.reachable and 1e-5 < reg.error < 1e-2  # noticeably off the target, not far
    assert np.linalg.norm(reg.u) < np.linalg.norm(plain.u) - 1.0
    eq = solve_equilibrium(m, reg.u)  # the answer is an equilibrium at its u
    assert eq.converged and np.linalg.norm(eq.tip - reg.tip) < 1e-8


def test_cli_reach_and_follow(tmp_path):
    prob = coarse_problem_file(tmp_path)
    run = run_cli
    import json

    r = run("reach", prob, "--target", "0.5,0.5,0.5", "--compact")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["reachable"] is False and out["error"] > 0.3 and len(out["u"]) == 2
    (tmp_path / "path.csv").write_text("x,y,z\n0.005,0.002,0.1945\n0.006,0.004,0.1944\n")
    r = run("follow", prob, "--targets", tmp_path / "path.csv", "--out", tmp_path / "f")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "f" / "follow.csv").is_file() and (tmp_path / "f" / "three_views.png").is_file()
    r = run("reach", prob, "--target", "1,2")
    assert r.returncode == 2 and "--target" in r.stderr


def test_orientation_with_extra_points_round_trip(rng):
    """Three points around the tip fix its position and orientation (the publication's Section 7)."""
    from casadi_ws.fem.mesh import embed

    pb = small_trunk("corotational", n_cables=2)
    m = StaticModel(pb)
    extra = np.array([[0.002, 0.0, 0.19], [0.0, 0.002, 0.19]])
    W = embed(m.mesh, extra).matrix(m.mesh)
    u = rng.uniform(pb.u_min, pb.u_max)
    eq = solve_equilibrium(m, u)
    goals = (W @ (m.X + eq.q)).reshape(-1, 3)
    r = reach(m, eq.tip, settings=ReachSettings(extra_points=list(extra)), extra_targets=goals)
    assert r.reachable
    np.testing.assert_allclose((W @ (m.X + r.q)).reshape(-1, 3), goals, atol=1e-6)
    np.testing.assert_allclose(r.u, u, rtol=1e-4, atol=1e-3)  # with orientation, u is determined here


def test_reach_with_different_extra_points_of_the_same_count(rng):
    """Each set of extra points is its own problem (NLPs were once cached by the number of points)."""
    from casadi_ws.fem.mesh import embed

    pb = small_trunk("corotational", n_cables=2)
    m = StaticModel(pb)
    eq = solve_equilibrium(m, rng.uniform(pb.u_min, pb.u_max))
    for extra in ([[0.002, 0.0, 0.19]], [[0.0, -0.002, 0.17]]):
        W = embed(m.mesh, np.array(extra)).matrix(m.mesh)
        goal = (W @ (m.X + eq.q)).reshape(-1, 3)
        r = reach(m, eq.tip, settings=ReachSettings(extra_points=extra), extra_targets=goal)
        assert r.reachable
        np.testing.assert_allclose((W @ (m.X + r.q)).reshape(-1, 3), goal, atol=1e-6)


@pytest.mark.parametrize("method", ["reduced", "ipopt"])
@pytest.mark.parametrize("model", ["corotational", "neohookean"])
def test_reach_on_ten_node_elements(model, method):
    """IPOPT needs the element Hessians: on 10-node elements they are built per quadrature point (the
    corotational one was once too large to compile, and then failed to run at all)."""
    pb = cantilever(n=1, slender=5, model=model, nu=0.3, cable_offset=0.01, order=2)
    target = solve_equilibrium(StaticModel(pb), np.array([2.0])).tip
    r = reach(pb, target, settings=ReachSettings(method=method))
    assert r.reachable and r.status == 0 and r.u[0] == pytest.approx(2.0, rel=1e-5) and r.method == method


def test_the_reduced_and_the_full_space_methods_find_the_same_answers():
    """Gauss-Newton in u (the default) against IPOPT over (q, u), each verified: a far target (the closest
    tip, on U's bound), a regularised one (a compromise inside U) and one out of a change limit."""
    pb = small_trunk("corotational", n_cables=2)
    m = StaticModel(pb)
    near = solve_equilibrium(m, [60.0, 30.0]).tip
    start = solve_equilibrium(m, [0.0, 0.0])
    cases = [(np.array([0.08, 0.08, 0.15]), {}, {}), (near, dict(regularization=1e-8), {}),
             (near, dict(max_du=10.0), dict(q0=start.q, u0=start.u))]
    for target, kw, start_at in cases:
        a = reach(m, target, settings=ReachSettings(**kw), **start_at)
        b = reach(m, target, settings=ReachSettings(method="ipopt", **kw), **start_at)
        assert a.method == "reduced" and a.status == 0 and b.method == "ipopt"
        assert a.error == pytest.approx(b.error, rel=1e-5, abs=1e-9)
        np.testing.assert_allclose(a.u, b.u, rtol=1e-4, atol=1e-4)
        np.testing.assert_allclose(a.tip, b.tip, atol=1e-7)


def test_reach_gets_past_a_local_minimum_where_the_jaws_must_touch():
    """The pinch gripper's upper-jaw tip at a state where the lower jaw pushes it up: from rest, Gauss-Newton
    stops 0.12 mm short with the lower jaw's cable at 0 (a local minimum of the distance: that cable moves
    the tip only once the jaws touch); the restart from the middle of U reaches the tip and its inputs."""
    from conftest import REPO

    import casadi_ws as cw

    pb = cw.load_problem(REPO / "problems" / "pinch_gripper.yaml")
    m = StaticModel(pb)
    u = np.array([0.777721, 0.50234])
    goal = solve_equilibrium(m, u)
    r = reach(m, goal.tip)
    assert r.reachable and r.method == "reduced" and r.error < 1e-6
    np.testing.assert_allclose(r.u, u, atol=1e-4)
    jaws, = m.contacts(r.q)  # the jaws press on each other (~7 mN on 3 points)
    assert jaws["points"] > 0 and np.linalg.norm(jaws["force"]) > 1e-3
