"""Prescribed quantities: displacement-controlled cables (the input is the shortening, the tension an
unknown >= 0 that vanishes when the cable goes slack, as SOFA's CableConstraint) and cavities controlled by
their volume growth (SOFA's volumeGrowth), in the model, every method and the problem format."""

import numpy as np
import pytest
from conftest import small_trunk
from test_cavity import chamber_problem
from test_forward_backward import strict_recall

from casadi_ws import ProblemError, StaticModel, problem_from_dict, solve_equilibrium
from casadi_ws.control.inverse import reach
from casadi_ws.solvers.admissible import admissibility
from casadi_ws.workspace.compare import compare
from casadi_ws.workspace.forward import ForwardSettings, forward
from casadi_ws.workspace.forward_backward import FBSettings, forward_backward


def _trunk(controls=("displacement", "displacement"), u_min=0.0, u_max=0.006):
    pb = small_trunk("corotational", n_cables=2)
    for c, k in zip(pb.actuators, controls):
        c.control = k
        if k == "displacement":
            c.u_min, c.u_max = u_min, u_max
    return pb


@pytest.fixture(scope="module")
def force_model():
    return StaticModel(small_trunk("corotational", n_cables=2))


def test_the_shortening_a_tension_produced_gives_back_that_tension_and_state(force_model):
    mf = force_model
    eq = solve_equilibrium(mf, np.array([30.0, 10.0]))
    s = mf.rest_quantities - mf.actuator_states(eq.q)  # the shortenings those tensions produce
    md = StaticModel(_trunk())
    d = solve_equilibrium(md, s)
    assert d.converged and d.residual < 1e-8
    assert np.abs(md.tip(d.q) - mf.tip(eq.q)).max() < 1e-9
    assert np.allclose(md.intensities(d.q, s), [30.0, 10.0], rtol=1e-6)
    assert np.abs(d.q[: md.n_mech] - eq.q).max() < 1e-9
    assert admissibility(md, d.q, s, d.factorization).admissible


def test_a_slack_cable_carries_no_tension(force_model):
    md = StaticModel(_trunk(u_min=-0.01))
    # cable 2 let out by 2 mm: the body does not follow, the cable goes slack
    d = solve_equilibrium(md, np.array([0.003, -0.002]))
    t = md.intensities(d.q, d.u)
    assert d.converged and t[0] > 1.0 and abs(t[1]) < 1e-6 and md.slack(d.q).tolist() == [False, True]
    shortening = md.rest_quantities - md.actuator_states(d.q)
    assert shortening[1] > -0.002 + 1e-4  # longer than the body needs: slack
    # the same state as the force-controlled trunk with that tension on cable 1 and none on cable 2
    f = solve_equilibrium(force_model, np.array([t[0], 0.0]))
    assert np.abs(md.tip(d.q) - force_model.tip(f.q)).max() < 1e-8


def test_a_mixed_problem_matches_force_control(force_model):
    eq = solve_equilibrium(force_model, np.array([25.0, 40.0]))
    s = force_model.rest_quantities - force_model.actuator_states(eq.q)
    mm = StaticModel(_trunk(("force", "displacement")))
    d = solve_equilibrium(mm, np.array([25.0, s[1]]))
    assert d.converged and np.abs(mm.tip(d.q) - eq.tip).max() < 1e-9
    assert mm.intensities(d.q, d.u)[1] == pytest.approx(40.0, rel=1e-6)


def test_volume_control_of_a_chamber_matches_pressure_control():
    mp = StaticModel(chamber_problem())
    eq = solve_equilibrium(mp, np.array([8000.0]))
    growth = mp.actuator_states(eq.q) - mp.rest_quantities
    pb = chamber_problem()
    pb.actuators[0].control, pb.actuators[0].u_min, pb.actuators[0].u_max = "volume", 0.0, 2 * growth[0]
    mv = StaticModel(pb)
    v = solve_equilibrium(mv, growth)
    assert v.converged and np.abs(mv.tip(v.q) - eq.tip).max() < 1e-10
    assert mv.intensities(v.q, growth)[0] == pytest.approx(8000.0, rel=1e-6)


@pytest.mark.parametrize("u", [[0.003, 0.002], [0.003, -0.002]], ids=["taut", "one slack"])
def test_tangent_and_hessian_match_finite_differences(u, rng):
    m = StaticModel(_trunk(u_min=-0.01))
    u = np.array(u)
    q = solve_equilibrium(m, u).q + m.full(1e-5 * rng.standard_normal(m.n_free))  # off the equilibrium too
    _, K, dRdu = m.residual_and_tangent(q, u)
    d = 1e-7 * rng.standard_normal(m.n_free)
    qp, qm = q.copy(), q.copy()
    qp[m.free] += d
    qm[m.free] -= d
    fd = (m.residual(qp, u) - m.residual(qm, u)) / 2
    assert np.linalg.norm(K @ d - fd) < 1e-6 * np.linalg.norm(fd)
    du = np.array([1e-8, -2e-8])
    fd = (m.residual(q, u + du) - m.residual(q, u - du)) / 2
    assert np.linalg.norm(dRdu @ du - fd) < 1e-6 * np.linalg.norm(fd)
    lam = rng.standard_normal(m.n_free)
    Hqq, Hqu = m.residual_hessian(q, u, lam)

    def vjp(qq, uu):
        _, Kk, D = m.residual_and_tangent(qq, uu)
        return Kk.T @ lam

    fd = (vjp(qp, u) - vjp(qm, u)) / 2
    assert np.linalg.norm(Hqq @ d - fd) < 1e-5 * np.linalg.norm(fd)
    fd = (vjp(q, u + du) - vjp(q, u - du)) / 2
    assert np.linalg.norm(Hqu @ du - fd) < 1e-5 * np.linalg.norm(fd)


def test_reach_finds_the_shortenings_of_a_reachable_tip(force_model):
    eq = solve_equilibrium(force_model, np.array([30.0, 10.0]))
    s = force_model.rest_quantities - force_model.actuator_states(eq.q)
    r = reach(StaticModel(_trunk()), eq.tip)  # IPOPT on the CasADi Functions, then verified
    assert r.error < 1e-6 and np.allclose(r.u, s, atol=1e-7)


def test_fb_in_shortenings_agrees_with_the_forward_cloud():
    pb = _trunk()
    model = StaticModel(pb)
    fb = forward_backward(pb, FBSettings(step=0.005, progress=False), model=model)
    fw = forward(pb, settings=ForwardSettings(n_d=30, progress=False), model=model)
    # a slack region exists in this box (cable 1 slackens while cable 2 bends the trunk): its cells too
    slack = [model.slack(solve_equilibrium(model, u).q)[0] for u in fw.u[::97]]
    assert any(slack)
    assert strict_recall(fw, fb) >= 0.98
    t = fb.maps()["intensities"]  # the tensions each point needs, as points.csv reports them
    assert np.all(t > -1e-6) and t.max() > 10 and np.all(np.isfinite(fw.maps()["intensities"]))
    assert compare(fw, fb)["precision_within_one_cell"] >= 0.95
    for u, p in zip(fb.u[::5], fb.points[::5]):  # every FB point is an equilibrium at its shortenings
        eq = solve_equilibrium(model, u)
        assert eq.converged and np.linalg.norm(eq.tip - p) < 1e-7


def test_problem_format_control(tmp_path):
    base = {"mesh": {"generate": "box", "size": [0.01, 0.01, 0.06], "divisions": [2, 2, 6]},
            "material": {"young_modulus": 1e6, "poisson_ratio": 0.3},
            "fixed": {"box": [-1, -1, -1, 1, 1, 0.0001]}, "end_effector": "tip"}
    cable = {"points": [[0.004, 0.005, 0.01], [0.004, 0.005, 0.06]], "pull_point": [0.004, 0.005, 0]}
    p = problem_from_dict({**base, "cables": [{**cable, "control": "displacement", "u_max": 0.002}]})
    assert p.cables[0].control == "displacement" and p.cables[0].input_unit == "m"
    with pytest.raises(ProblemError, match=r"cables\[0\].u_max: missing"):
        problem_from_dict({**base, "cables": [{**cable, "control": "displacement"}]})
    with pytest.raises(ProblemError, match=r"cables\[0\].control: expected force \(u is the tension\) or "
                                           r"displacement \(u is the shortening, m\), got 'position'"):
        problem_from_dict({**base, "cables": [{**cable, "control": "position"}]})


def test_a_prescribed_cable_that_cannot_move_the_body_is_one_line(tmp_path):
    import subprocess
    import sys

    import yaml

    problem = {"mesh": {"generate": "box", "size": [0.01, 0.01, 0.06], "divisions": [2, 2, 6]},
               "material": {"young_modulus": 1e6, "poisson_ratio": 0.3},
               "fixed": {"box": [-1, -1, -1, 1, 1, 0.0001]}, "end_effector": "tip",
               # its points are all fixed nodes: pulling it cannot move anything
               "cables": [{"points": [[0.0, 0.0, 0.0], [0.01, 0.0, 0.0]], "control": "displacement", "u_max": 0.001}]}
    path = tmp_path / "held.yaml"
    path.write_text(yaml.safe_dump(problem))
    r = subprocess.run([sys.executable, "-m", "casadi_ws.cli", "equilibrium", str(path), "--u", "0.0005"],
                       capture_output=True, text=True)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "held.yaml: cables[0].control: 'cable1' does not move the body at rest" in r.stderr
