"""The forward method: against the linear model, cold solves, its own files, and honest failures."""

import json
import subprocess
import sys

import numpy as np
import pytest
import pyvista as pv
from conftest import REPO, small_trunk

from casadi_ws import StaticModel, solve_equilibrium
from casadi_ws.solvers.equilibrium import factorize
from casadi_ws.workspace.forward import ForwardSettings, forward, input_grid, snake_order
from casadi_ws.workspace.result import load_result


def test_snake_order_visits_every_grid_point_once_by_unit_steps():
    for n_d, n_u in ((1, 2), (4, 1), (3, 3), (5, 2)):
        idx = snake_order(n_d, n_u)
        assert len({tuple(r) for r in idx}) == n_d**n_u == len(idx)
        if len(idx) > 1:
            assert np.all(np.abs(np.diff(idx, axis=0)).sum(axis=1) == 1)


def _linear_prediction(model):
    """p = p0 + A u with A = C K^-1 (-dR/du) at rest: exact for a linear body under fixed forces.

    A cable is not quite a fixed force: its tension adds a geometric stiffness u d2L/dq2, which bends the
    image of U by ~0.03 of the span per newton on this trunk. The tests keep u tiny (1e-5 N) to make
    that a 3e-7 effect."""
    q0 = np.zeros(model.n_dof)
    _, K, dRdu = model.residual_and_tangent(q0, np.zeros(model.n_u))
    lu = factorize(K)
    A = model.C_free @ np.column_stack([-lu.solve(dRdu[:, i]) for i in range(model.n_u)])
    return model.p0, A


@pytest.mark.parametrize("n_u", [1, 2])
def test_linear_material_forward_cloud_is_the_linear_image_of_U(n_u):
    pb = small_trunk("linear", n_cables=n_u, gravity=False)
    for c in pb.cables:
        c.u_max = 1e-5  # see _linear_prediction
    model = StaticModel(pb)
    res = forward(pb, settings=ForwardSettings(n_d=5, progress=False), model=model)
    assert res.n_points == 5**n_u and res.n_failed == 0
    p0, A = _linear_prediction(model)
    pred = p0 + res.u @ A.T
    span = np.linalg.norm(pred - p0, axis=1).max()
    assert span > 0
    assert np.abs(res.points - pred).max() < 2e-6 * span
    if n_u == 1:  # on the straight segment, evenly spaced
        d = np.diff(res.points, axis=0)
        np.testing.assert_allclose(d, np.repeat(d[:1], len(d), axis=0), atol=2e-6 * span)
    else:  # the corners of the parallelogram and its parallel sides
        corners = {tuple(u): p for u, p in zip(res.u, res.points)}
        a, b = np.array([0, 0]), pb.u_max
        side1 = corners[(b[0], a[1])] - corners[(a[0], a[1])]
        side2 = corners[(b[0], b[1])] - corners[(a[0], b[1])]
        np.testing.assert_allclose(side1, side2, atol=2e-6 * span)


def test_warm_started_grid_matches_cold_solves():
    pb = small_trunk("corotational", n_cables=2)
    model = StaticModel(pb)
    res = forward(pb, settings=ForwardSettings(n_d=6, progress=False), model=model)
    assert res.n_failed == 0
    for k in (0, 7, 20, 35):
        cold = solve_equilibrium(model, res.u[k])
        assert cold.converged
        assert np.linalg.norm(cold.tip - res.points[k]) < 1e-8  # metres
    # the predictor did its job: about one factorisation per point
    assert res.counters["factorizations"] < 2.5 * res.counters["solves"]
    # without maps: the same points and the LU-free maps, no steerability or compliance
    bare = forward(pb, settings=ForwardSettings(n_d=6, progress=False, maps="none"), model=model)
    assert np.abs(bare.points - res.points).max() < 1e-9
    mb, mr = bare.maps(), res.maps()
    assert np.all(np.isnan(mb["steerability"])) and np.all(np.isnan(mb["compliance"]))
    np.testing.assert_allclose(mb["tilt"], mr["tilt"], atol=1e-6)


def test_result_round_trip_and_files(tmp_path):
    pb = small_trunk("corotational", n_cables=2)
    res = forward(pb, settings=ForwardSettings(n_d=4, progress=False, store_states=True))
    res.save(tmp_path)
    back = load_result(tmp_path)
    for name in ("points", "u", "failed_u", "failed_status", "failed_residual", "states", "rest_tip"):
        np.testing.assert_array_equal(getattr(back, name), getattr(res, name))
    assert back.counters == res.counters and back.settings == res.settings and back.method == "forward"
    s = json.loads((tmp_path / "summary.json").read_text())
    assert {"method", "n_points", "n_failed", "time_s", "settings"} <= set(s)
    assert s["n_points"] == 16 and s["settings"]["n_d"] == 4
    csv = np.loadtxt(tmp_path / "points.csv", delimiter=",", skiprows=1)
    assert csv.shape == (16, 21)
    assert (tmp_path / "points.csv").read_text().splitlines()[0] == \
        "x,y,z,u1,u2,stable,admissible,violations,effort,steerability,compliance,tilt,roll,axis_x,axis_y,axis_z," \
        "contact,state1,state2,intensity1,intensity2"
    np.testing.assert_array_equal(csv[:, 19:21], csv[:, 3:5])  # force control: the intensity is the input
    assert np.all(csv[:, 16] == 0.0)  # no obstacles: no contact force
    np.testing.assert_allclose(np.linalg.norm(csv[:, 13:16], axis=1), 1.0, rtol=1e-5)  # the tip's axis: unit
    np.testing.assert_array_equal(csv[:, 5:8], np.column_stack([np.ones(16), np.ones(16), np.zeros(16)]))
    vtu = pv.read(tmp_path / "points.vtu")
    assert vtu.n_points == 16 and "u2" in vtu.point_data
    assert res.states.shape == (16, 3 * pb.mesh.n_nodes)


def test_impossible_settings_produce_reported_failures_not_points():
    pb = small_trunk("corotational", n_cables=2)
    pb.solver.max_load_steps = 2
    model = StaticModel(pb)
    res = forward(pb, settings=ForwardSettings(n_d=4, progress=False, max_iter=1, predictor="none"), model=model)
    assert res.n_failed > 0 and res.n_points + res.n_failed == 16
    grid = {tuple(u) for u in input_grid(pb.u_min, pb.u_max, 4)}
    assert {tuple(u) for u in res.failed_u} <= grid
    assert np.all(res.failed_status != 0)
    for u, p in zip(res.u, res.points):  # whatever is reported reachable is a verified equilibrium
        eq = solve_equilibrium(model, u)
        assert np.linalg.norm(eq.tip - p) < 1e-8
    none = forward(pb, settings=ForwardSettings(n_d=3, progress=False, tol=1e-30), model=model)
    assert none.n_points == 0 and none.n_failed == 9


def test_parallel_workers_give_the_same_points():
    pb = small_trunk("corotational", n_cables=2)
    one = forward(pb, settings=ForwardSettings(n_d=10, progress=False))
    two = forward(pb, settings=ForwardSettings(n_d=10, progress=False, workers=2))
    assert two.settings["workers"] == 2
    np.testing.assert_array_equal(one.u, two.u)
    assert np.abs(one.points - two.points).max() < 1e-8


def test_cli_solve_writes_files_and_refuses_to_overwrite(tmp_path):
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "casadi_ws.cli", "solve", str(REPO / "problems" / "trunk_2cables.yaml"),
           "--nd", "2", "--out", str(out), "--quiet"]
    r = subprocess.run(cmd, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stdout == ""  # quiet, and no solver chatter
    for f in ("summary.json", "points.csv", "result.npz", "points.vtu", "three_views.png", "workspace_3d.png",
              "robot.vtu", "actuators.vtu", "report.html", "boundary.vtu", "boundary.stl"):
        assert (out / f).is_file(), f
    import meshio

    robot, act = meshio.read(out / "robot.vtu"), meshio.read(out / "actuators.vtu")
    assert robot.cells[0].type == "tetra" and robot.point_data["fixed"].any()
    assert {c.type for c in act.cells} == {"line"}  # the two cables' segments
    assert set(np.concatenate(act.cell_data["actuator"]).tolist()) == {0, 1}
    r = subprocess.run(cmd, capture_output=True, text=True)
    assert r.returncode == 2 and "--overwrite" in r.stderr
    r = subprocess.run(cmd[:-3] + ["--stride", "0", "--out", str(tmp_path / "s0")], capture_output=True, text=True)
    assert r.returncode == 2 and "--stride: expected an integer >= 1, got 0" in r.stderr


def test_checkpoints_survive_failed_points_and_resume_to_the_same_sweep():
    from casadi_ws.workspace.forward import sweep

    pb = small_trunk("corotational", n_cables=2)
    pb.solver.max_load_steps = 2
    m = StaticModel(pb)
    s = ForwardSettings(n_d=4, progress=False, max_iter=1, predictor="none", checkpoint_every=0.0)
    us = input_grid(pb.u_min, pb.u_max, 4)
    saved = []
    ref = sweep(m, us, s, checkpoint=lambda st: saved.append(st))  # a checkpoint after every grid line
    assert (ref.status != 0).any() and len(saved) == len(us) // 4
    assert any(len(st["hist_u"]) == 0 for st in saved)  # states right after a failure are saved too
    mid = saved[len(saved) // 2 - 1]
    again = sweep(m, us, s, resume=dict(mid))
    np.testing.assert_array_equal(again.status, ref.status)
    assert np.nanmax(np.abs(again.tips - ref.tips)) < 1e-8


@pytest.mark.parametrize("n_u, n_d, stride", [(1, 41, 4), (2, 21, 4), (1, 9, 8)])
def test_points_between_newton_points_match_cold_solves(n_u, n_d, stride):
    """Interpolated points are accepted only on the residual check: they must be the equilibria that Newton
    finds from rest. (1, 9, 8): a stride far too coarse, where interpolation fails and Newton takes over."""
    pb = small_trunk("corotational", n_cables=n_u)
    model = StaticModel(pb)
    res = forward(pb, settings=ForwardSettings(n_d=n_d, stride=stride, progress=False), model=model)
    c = res.counters
    assert res.n_failed == 0 and res.n_points == n_d**n_u
    assert c["interpolated"] > 0
    if n_d == 9:
        assert c["interpolation_failed"] > 0
    else:
        assert c["solves"] < 0.6 * n_d**n_u  # most points needed no Newton step
    ref = forward(pb, settings=ForwardSettings(n_d=n_d, stride=1, progress=False), model=model)
    np.testing.assert_array_equal(ref.u, res.u)
    assert np.abs(ref.points - res.points).max() < 1e-8  # metres
    rng = np.random.default_rng(0)
    for k in rng.choice(res.n_points, 4, replace=False):
        cold = solve_equilibrium(model, res.u[k])
        assert cold.converged and np.linalg.norm(cold.tip - res.points[k]) < 1e-8


def test_a_failed_interpolation_becomes_a_node_and_narrows_the_next_line(monkeypatch):
    """A point whose interpolant fails verification is solved by Newton and interpolated from by the points
    after it on its line; a line where more than a quarter failed sends the next line to the narrow stride,
    and a narrow line where (almost) none failed sends the next one back to the wide stride."""
    import importlib

    from casadi_ws.solvers.equilibrium import DIVERGED

    fw = importlib.import_module("casadi_ws.workspace.forward")
    pb = small_trunk("corotational", n_cables=2)
    m = StaticModel(pb)
    n_d = 31
    us = input_grid(pb.u_min, pb.u_max, n_d)
    settings = ForwardSettings(n_d=n_d, progress=False)
    assert fw.line_strides(settings, n_d) == (5, 3)
    real_verify, real_weights = fw.verify, fw.lagrange_weights
    fail = {"first": False, "all": False, "calls": 0}
    nodes = []

    def verify(model, u, q, tol):
        eq = real_verify(model, u, q, tol)
        fail["calls"] += 1
        if fail["all"] or (fail["first"] and fail["calls"] == 1):
            eq.status = DIVERGED
        return eq

    def weights(xs, x):
        nodes.append(set(np.round(xs, 9)))
        return real_weights(xs, x)

    monkeypatch.setattr(fw, "verify", verify)
    monkeypatch.setattr(fw, "lagrange_weights", weights)
    sw, counters = fw._Sweep(), fw.new_counters()
    interpolated = []
    for line, mode in enumerate(["first", "all", "all", "none", "none"]):
        fail.update(first=mode == "first", all=mode == "all", calls=0)
        nodes.clear()
        idx = np.arange(line * n_d, (line + 1) * n_d)
        before = counters["interpolated"]
        out = fw._solve_line(m, us[idx], idx[0], settings, 1e-8, sw, counters)
        assert all(eq.converged for eq in out)
        interpolated.append(counters["interpolated"] - before)
        if mode == "first":  # the failed point (solved by Newton) is a node of the next one's polynomial
            x = us[idx, 1]
            failed = [j for j, eq in enumerate(out) if getattr(eq, "newton", False)
                      and j not in fw._grid_positions(n_d, 5, bool(x[-1] < x[0]))]
            assert len(failed) == 1 and any(round(x[failed[0]], 9) in n for n in nodes)
    # wide (9 Newton points of 31), wide (1 failure of 22 is few), narrow (13) twice (all failed), wide again
    assert interpolated == [22, 22, 18, 18, 22]
    assert counters["interpolation_failed"] == 1 + 22 + 18


def _three_cable_trunk(u_max=10.0):
    pb = small_trunk("corotational", n_cables=3)
    for c in pb.actuators:
        c.u_max = u_max  # a gentle range: the across-line polynomials pass verification at this coarse grid
    return pb


def test_a_plane_holds_no_lu_of_its_checked_lines():
    """Regression: a plane kept every Newton point's LU until the plane was done (~250 LUs: 12 GB per worker
    on the 3-cable trunk at n_d = 30, killed by the OOM killer). Once a solved line is checked, its LUs go."""
    from casadi_ws.workspace.forward import _solve_plane, _Sweep, new_counters

    pb = _three_cable_trunk()
    m = StaticModel(pb)
    n_d = 7
    us = input_grid(pb.u_min, pb.u_max, n_d)[:n_d * n_d]
    counters = new_counters()
    settings = ForwardSettings(n_d=n_d, stride=1, across=2, progress=False)
    eqs, masks, _ = _solve_plane(m, us, 0, settings, 1e-8, _Sweep(), counters, n_d)
    assert all(eq.converged for eq in eqs) and counters["factorizations"] >= n_d
    # only points Newton-solved between the lines (their interpolation failed) may still hold their own LU
    assert sum(eq.factorization is not None for eq in eqs) <= counters["interpolation_failed"]


@pytest.mark.slow
def test_lines_and_planes_interpolated_across_match_the_lines_solved_one_by_one(tmp_path):
    """With three actuators, only every ``across``-th plane of the cube is swept, and in it every
    ``across``-th line solved; the points between are interpolated across lines, the planes between across
    the swept planes (reading their states, in a second phase), and verified. Same points and checks as
    solving every line, far fewer Newton solves; the same from two workers, and after a resume: a run
    stopped after its first piece resumes from the checkpoint (the swept planes' states with it) to the
    same points, checks and maps. A sweep of planes one by one checkpoints per plane and resumes too."""
    from casadi_ws.runtime.executor import SerialExecutor
    from casadi_ws.workspace.forward import across_planes, sweep

    pb = _three_cable_trunk()
    m = StaticModel(pb)

    def settings(across=2, **kw):
        return ForwardSettings(n_d=9, stride=1, across=across, progress=False, **kw)

    assert across_planes(3, m.n_dof, settings()) and not across_planes(3, m.n_dof, settings(1))
    ref = forward(pb, settings=settings(1), model=m)
    res = forward(pb, settings=settings(), model=m)
    c = res.counters
    assert res.n_failed == 0 and res.n_points == ref.n_points == 9**3
    # 5 of 9 planes swept, 5 of 9 lines of those solved: Newton solves ~(5/9)^2 of the points
    assert c["interpolated"] > 0.6 * 9**3 and c["interpolation_failed"] < 0.05 * c["interpolated"]
    assert c["solves"] < 0.4 * ref.counters["solves"]
    np.testing.assert_array_equal(ref.u, res.u)
    assert np.abs(ref.points - res.points).max() < 1e-8
    np.testing.assert_array_equal(ref.violations, res.violations)
    two = forward(pb, settings=ForwardSettings(n_d=9, stride=1, across=2, workers=2, progress=False))
    np.testing.assert_array_equal(two.u, res.u)
    assert np.abs(two.points - res.points).max() < 1e-8

    class StopAfterOne(SerialExecutor):
        def map_unordered(self, fn, problem, jobs):
            yield from super().map_unordered(fn, problem, jobs[:1])
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        forward(pb, settings=settings(), model=m, checkpoint_dir=tmp_path, executor=StopAfterOne(m))
    again = forward(pb, settings=settings(), model=m, checkpoint_dir=tmp_path, resume=True)
    np.testing.assert_array_equal(again.points, res.points)
    np.testing.assert_array_equal(again.violations, res.violations)
    np.testing.assert_array_equal(again.arrays["map_effort"], res.arrays["map_effort"])
    assert again.counters["solves"] == c["solves"]

    s = settings(checkpoint_every=0.0)
    us = input_grid(pb.u_min, pb.u_max, 9)
    saved = []
    full = sweep(m, us, s, checkpoint=lambda st: saved.append(st))
    assert len(saved) == 9 and all(st["next"] % 81 == 0 for st in saved)  # a checkpoint per plane
    again = sweep(m, us, s, resume=dict(saved[2]))
    np.testing.assert_array_equal(again.status, full.status)
    assert np.nanmax(np.abs(again.tips - full.tips)) < 1e-8


def test_an_input_held_at_one_value_is_no_axis_of_the_grid():
    assert input_grid([0.0, 1.0, 0.0], [2.0, 1.0, 4.0], 3).tolist() == [
        [0, 1, 0], [0, 1, 2], [0, 1, 4], [1, 1, 4], [1, 1, 2], [1, 1, 0], [2, 1, 0], [2, 1, 2], [2, 1, 4]]
    # the 3-cable trunk with its middle cable held at its lower bound: the plane u2 = 0 of the full grid, the
    # same points (interpolated across lines, planes and workers as each grid is)
    pb = small_trunk("corotational", n_cables=3)
    full = forward(pb, settings=ForwardSettings(n_d=7, progress=False))
    pb.actuators[1].u_max = pb.actuators[1].u_min
    for workers in (1, 2):
        held = forward(pb, settings=ForwardSettings(n_d=7, progress=False, workers=workers))
        assert len(held.u) == 49 and np.all(held.u[:, 1] == pb.actuators[1].u_min)
        for u, p in zip(held.u, held.points):
            (k,) = np.flatnonzero(np.all(full.u == u, axis=1))
            assert np.abs(full.points[k] - p).max() < 1e-8


def test_the_3d_picture_has_round_ticks_spanning_the_data():
    from casadi_ws.io.plots import _nice_axis

    for lo, hi in ((-13.0, 60.87), (0.0, 195.0), (0.31, 0.38), (5.0, 5.0)):
        a, b, n = _nice_axis(lo, hi)
        step = (b - a) / (n - 1)
        assert a <= lo and b >= hi and 3 <= n <= 7
        assert any(np.isclose(step / 10.0 ** np.floor(np.log10(step)), k) for k in (1, 2, 2.5, 5))
        assert np.isclose(a / step, round(a / step))  # ticks on multiples of the step: 0, 50, 100
