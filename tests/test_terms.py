"""The model is the sum of its terms (issue: one assembler): a term written here, outside the package, is seen
by every solver; the two terms of the problem format (``springs``, ``pressure_loads``) against closed forms
and finite differences; the SOFA importer's rules for them and for ``ConstantForceField``."""

from dataclasses import replace

import numpy as np
import pytest
from conftest import cantilever

import casadi as ca
from casadi_ws import (FBSettings, ForwardSettings, Problem, StaticModel, Term, forward, forward_backward,
                       problem_from_dict, reach, residual_function, solve_equilibrium)
from casadi_ws.actuation import Cable
from casadi_ws.fem.surface import boundary_faces
from casadi_ws.fem.terms import PressureLoad, Springs


class GroundSpring(Term):
    """A linear spring of stiffness k (N/m) from one component of one node to the ground: the whole of a term."""

    name = "ground_spring"
    phase = "internal"  # a force of the body's own, summed with the elements'
    negatives = 0  # k > 0 on the diagonal: the tangent stays symmetric and as definite as it was
    tangent_from_residual = False

    def __init__(self, node: int, component: int, k: float):
        self.dof, self.k = 3 * node + component, k

    def setup(self, model, pos):
        self.key = np.array([pos[self.dof] * model.n_free + pos[self.dof]])

    def pattern(self, model, pos):
        return self.key

    def forces(self, model, s):
        f = np.zeros(model.n_dof)
        f[self.dof] = self.k * s.q[self.dof]
        return f

    def tangent(self, model, cache):
        return self.key, np.array([self.k])


def _beam(n_cables=2):
    """A linear 2 x 2 x 20 cantilever along +z, its tip node the end effector, with two straight cables at
    +x and +y (small tensions: a nearly linear response)."""
    pb = cantilever(n=2, model="linear", nu=0.3)
    L, h = 0.2, 0.02
    zs = np.linspace(L / 20, L, 20)
    cables = []
    for k, (dx, dy) in enumerate([(h / 4, 0.0), (0.0, h / 4)][:n_cables]):
        pts = np.column_stack([np.full_like(zs, dx), np.full_like(zs, dy), zs])
        cables.append(Cable(pts, np.array([dx, dy, 0.0]), 0.0, 0.05, f"c{k}"))
    pb.actuators = cables
    tip = int(np.argmin(np.linalg.norm(pb.mesh.nodes - [0.0, 0.0, L], axis=1)))
    return pb, tip


def test_a_term_written_outside_the_package_is_seen_by_every_solver():
    pb, tip = _beam()
    P = 1e-3
    loaded = replace(pb, point_loads=[(pb.mesh.nodes[tip], np.array([P, 0.0, 0.0]))])
    free = solve_equilibrium(StaticModel(loaded), np.zeros(2))
    k_b = P / (free.tip - pb.end_effector)[0]
    k = 2.0 * k_b
    tied = replace(loaded, terms=[GroundSpring(tip, 0, k)])
    eq = solve_equilibrium(StaticModel(tied), np.zeros(2), tol=1e-12)
    assert eq.converged
    # linear elasticity, a load and a spring on one dof: exactly P / (k + k_b)
    assert abs((eq.tip - pb.end_effector)[0] / (P / (k + k_b)) - 1) < 1e-8

    with_spring = replace(pb, terms=[GroundSpring(tip, 0, k)])
    model, plain = StaticModel(with_spring), StaticModel(pb)
    assert model.term("ground_spring").k == k and model.terms[-1] is not with_spring.terms[0]  # a copy each

    # forward: its points are the equilibria with the spring; the spring holds x, not y
    fw = forward(with_spring, 3, ForwardSettings(progress=False), model=model)
    fw0 = forward(pb, 3, ForwardSettings(progress=False), model=plain)
    assert fw.n_points == fw0.n_points == 9
    for u, p, p0 in zip(fw.u, fw.points, fw0.points):
        assert np.linalg.norm(p - solve_equilibrium(model, u).tip) < 1e-9
        d, d0 = p - pb.end_effector, p0 - pb.end_effector
        if abs(d0[0]) > 1e-6:
            assert abs(d[0] / d0[0] - 1 / 3) < 0.03  # k = 2 k_b: a third of the motion along x
        assert abs(d[1] - d0[1]) <= 0.03 * abs(d0[1]) + 1e-9

    # forward-backward: every point it reports is an equilibrium with the spring
    fb = forward_backward(with_spring, FBSettings(progress=False, step=1.5e-5), model=model)
    assert fb.n_points > 10
    for u, p in zip(fb.u[::5], fb.points[::5]):
        assert np.linalg.norm(p - solve_equilibrium(model, u).tip) < 1e-8

    # reach: a target only the tied beam reaches at those inputs
    target = fw.points[4]
    r = reach(model, target)
    assert r.reachable and r.error < 1e-3 * np.ptp(fw.points[:, 0])
    assert np.linalg.norm(solve_equilibrium(model, r.u).tip - target) < 1e-3 * np.ptp(fw.points[:, 0])

    # the CasADi Functions: R and its Jacobian carry the spring
    R = residual_function(model)
    q = model.full(np.random.default_rng(0).standard_normal(model.n_free) * 1e-4)
    u = np.array([0.01, 0.02])
    assert np.allclose(np.asarray(R(q[model.free], u)).ravel(), model.residual(q, u), rtol=0, atol=1e-14)
    j = list(model.free).index(3 * tip)
    assert np.asarray(R(q[model.free], u)).ravel()[j] - plain.residual(q, u)[j] == pytest.approx(k * q[3 * tip])
    qs = ca.MX.sym("q", model.n_free)
    J = ca.Function("J", [qs], [ca.jacobian(R(qs, u), qs)])(q[model.free]).sparse()
    assert abs(J - model.tangent(q, u)).max() < 1e-12 * abs(J).max()
    assert J[j, j] - plain.tangent(q, u)[j, j] == pytest.approx(k)


def test_springs_hold_a_cantilever_tip_as_the_closed_form():
    """10-node cantilever (L/h = 10), its tip face held by springs of total stiffness k = k_b: tip deflection
    P / (k + 3 E I / L^3) (measured 0.14 % off: the beam's own shear and discretisation)."""
    E, L, h, P = 1e6, 0.2, 0.02, 1e-3
    k_b = 3 * E * h**4 / 12 / L**3
    pb = cantilever(n=2, model="linear", nu=0.0, order=2)
    x = pb.mesh.nodes
    tip = np.flatnonzero(x[:, 2] > L - 1e-12)
    pb.point_loads = [(x[i], np.array([P / tip.size, 0.0, 0.0])) for i in tip]
    pb.terms = [Springs(tip, k_b / tip.size)]
    eq = solve_equilibrium(StaticModel(pb), np.zeros(0))
    assert eq.converged
    assert abs((eq.tip - pb.end_effector)[0] / (P / (k_b + k_b)) - 1) < 0.02


def test_springs_to_given_anchors_and_holding_the_body_alone(tmp_path):
    """A problem file whose body is held by springs only (no ``fixed``), anchored at rest; and springs anchored
    elsewhere pull the nodes there (a stiff spring: within 1e-3 of the offset)."""
    text = """
mesh: {generate: box, size: [0.02, 0.02, 0.1], divisions: [2, 2, 10], origin: [-0.01, -0.01, 0]}
material: {model: linear, young_modulus: 1.0e+6, poisson_ratio: 0.3}
springs:
  - {name: base, nodes: {plane: {point: [0, 0, 0], normal: [0, 0, 1]}}, stiffness: 1.0e+4}
cables:
  - {name: c, points: [[0.005, 0, 0.05], [0.005, 0, 0.1]], pull_point: [0.005, 0, 0], u_min: 0, u_max: 0.1}
end_effector: tip
"""
    pb = problem_from_dict(__import__("yaml").safe_load(text), "springs.yaml")
    assert pb.fixed_nodes.size == 0 and isinstance(pb.terms[0], Springs) and pb.terms[0].name == "base"
    m = StaticModel(pb)
    assert m.n_free == m.n_mech
    eq = solve_equilibrium(m, [0.05])
    assert eq.converged and np.linalg.norm(eq.tip - pb.end_effector) > 1e-5
    # the springs carry the cable's pull towards its pull point (0.05 N, along z but for the bend)
    base = pb.terms[0].nodes
    spring_force = -1e4 * eq.q[: m.n_mech].reshape(-1, 3)[base].sum(axis=0)  # on the body
    assert np.linalg.norm(spring_force) == pytest.approx(0.05, rel=1e-6) and spring_force[2] > 0.999 * 0.05

    d = __import__("yaml").safe_load(text)
    d["fixed"] = {"plane": {"point": [0, 0, 0], "normal": [0, 0, 1]}}
    top = pb.mesh.nodes[pb.mesh.nodes[:, 2] > 0.099]  # in the order of their indices
    d["springs"] = [{"nodes": {"box": [[-1, -1, 0.099], [1, 1, 1]]}, "stiffness": 1e5,
                     "anchors": (top + [0, 0, 1e-3]).tolist()}]
    pb = problem_from_dict(d, "anchored.yaml")
    eq = solve_equilibrium(StaticModel(pb), [0.0])
    assert eq.converged and 0.9e-3 < (eq.tip - pb.end_effector)[2] < 1e-3
    for bad, key in [({"stiffness": -1.0}, "springs[0].stiffness"), ({"anchors": [[0, 0, 0]] * 2}, "springs[0].anchors"),
                     ({"nodes": {"box": [[1, 1, 1], [2, 2, 2]]}}, "springs[0].nodes.box")]:
        d2 = dict(d, springs=[{**d["springs"][0], **bad}])
        with pytest.raises(ValueError, match=rf"anchored.yaml: {key.replace('[', '.').replace(']', '.')}"):
            problem_from_dict(d2, "anchored.yaml")


def _sphere(tmp_path, name, order):
    from test_cavity import sphere_problem_file

    from casadi_ws import load_problem

    pb = load_problem(sphere_problem_file(tmp_path, name, order))
    f = boundary_faces(pb.mesh)
    outer = f[(np.linalg.norm(pb.mesh.nodes[f], axis=2) > 0.015).all(axis=1)]
    return pb, outer


def test_pressure_on_a_thick_sphere_matches_lame(tmp_path):
    """A hollow sphere (a = 10, b = 20 mm, 10-node, 5 mm) under an external pressure: the outer surface's mean
    radial displacement against Lame's -p b^3 / (b^3 - a^3) (b / 3K + a^3 / (4 mu b^2)) (measured 0.12 %)."""
    pb, outer = _sphere(tmp_path, "hollow_sphere_5mm_o2.vtu", 2)
    p, a, b, E, nu = 100.0, 0.01, 0.02, 1e6, 0.3
    pb.terms = [PressureLoad(outer, p)]
    m = StaticModel(pb)
    eq = solve_equilibrium(m, [0.0], tol=1e-11)
    assert eq.converged
    on = np.unique(outer)
    X = pb.mesh.nodes[on]
    u_r = np.mean(np.einsum("ij,ij->i", m.positions(eq.q)[on] - X, X / np.linalg.norm(X, axis=1)[:, None]))
    K, mu = E / (3 * (1 - 2 * nu)), E / (2 * (1 + nu))
    exact = -p * b**3 / (b**3 - a**3) * (b / (3 * K) + a**3 / (4 * mu * b**2))
    assert abs(u_r / exact - 1) < 0.03


@pytest.mark.parametrize("order", [1, 2])
def test_pressure_load_tangent_and_hessian_match_finite_differences(order, rng):
    """On an open surface (a cantilever's side, bent and twisted) the follower load's tangent is not symmetric:
    K (not K^T) is the derivative of R, and the Hessian of lam . R is that of K^T lam."""
    pb = cantilever(n=2, model="linear", order=order)
    f = boundary_faces(pb.mesh)
    side = f[(pb.mesh.nodes[f][:, :, 0] > 0.01 - 1e-12).all(axis=1)]
    with_p = replace(pb, terms=[PressureLoad(side, 2e4)])
    m, m0 = StaticModel(with_p), StaticModel(pb)
    q = m.full(rng.standard_normal(m.n_free) * 2e-3)
    u = np.zeros(0)
    K = (m.tangent(q, u) - m0.tangent(q, u)).tocsc()
    assert abs(K - K.T).max() > 1e-3 * abs(K).max()
    v = rng.standard_normal(m.n_free)
    h = 1e-6

    def R(x):
        return m.residual(m.full(x), u) - m0.residual(m.full(x), u)

    fd = (R(q[m.free] + h * v) - R(q[m.free] - h * v)) / (2 * h)
    assert np.linalg.norm(fd - K @ v) < 1e-7 * np.linalg.norm(fd)
    assert np.linalg.norm(fd - K.T @ v) > 1e-3 * np.linalg.norm(fd)
    lam = rng.standard_normal(m.n_free)
    H = (m.residual_hessian(q, u, lam)[0] - m0.residual_hessian(q, u, lam)[0]).tocsc()

    def KTlam(x):
        return (m.tangent(m.full(x), u) - m0.tangent(m.full(x), u)).T @ lam

    fd = (KTlam(q[m.free] + h * v) - KTlam(q[m.free] - h * v)) / (2 * h)
    assert np.linalg.norm(fd - H @ v) < 1e-7 * np.linalg.norm(fd)


def test_problem_file_pressure_loads_and_bad_input():
    base = {"mesh": {"generate": "box", "size": [0.02, 0.02, 0.1], "divisions": [2, 2, 10],
                     "origin": [-0.01, -0.01, 0]},
            "material": {"model": "linear", "young_modulus": 1e6, "poisson_ratio": 0.3},
            "fixed": {"plane": {"point": [0, 0, 0], "normal": [0, 0, 1]}},
            "cables": [{"points": [[0.005, 0, 0.05], [0.005, 0, 0.1]], "pull_point": [0.005, 0, 0], "u_max": 0.1}],
            "pressure_loads": [{"name": "push", "surface": {"plane": {"point": [0.01, 0, 0], "normal": [-1, 0, 0]}},
                                "pressure": 100.0}]}
    pb = problem_from_dict(base, "push.yaml")
    load = pb.terms[0]
    assert isinstance(load, PressureLoad) and load.name == "push" and len(load.faces) == 2 * 2 * 10
    eq = solve_equilibrium(StaticModel(pb), [0.0])
    # 100 Pa on the +x side (2 cm x 10 cm): the tip moves towards -x
    assert eq.converged and (eq.tip - pb.end_effector)[0] < -1e-5
    for bad, key in [({"pressure": "high"}, "pressure_loads[0].pressure"),
                     ({"surface": {"box": [[0, 0, 0], [0.001, 0.001, 0.001]]}}, "pressure_loads[0].surface"),
                     ({"push": 1}, "pressure_loads[0].push")]:
        d = dict(base, pressure_loads=[{**base["pressure_loads"][0], **bad}])
        with pytest.raises(ValueError, match=rf"push.yaml: {key.replace('[', '.').replace(']', '.')}"):
            problem_from_dict(d, "push.yaml")
    spring = {"name": "push", "nodes": {"indices": [0]}, "stiffness": 1.0}
    with pytest.raises(ValueError, match=r"push.yaml: pressure_loads.0.\.name: 'push' is already the name of springs"):
        problem_from_dict(dict(base, springs=[spring]), "push.yaml")
    with pytest.raises(ValueError, match=r"push.yaml: springs.0.\.name: 'loads' is the name of one of the model's"):
        problem_from_dict(dict(base, springs=[{**spring, "name": "loads"}]), "push.yaml")


def test_a_term_named_as_another_is_refused():
    pb, tip = _beam(1)

    class Loads(GroundSpring):
        name = "loads"

    with pytest.raises(ValueError, match="<python>: terms: two terms named 'loads'"):
        StaticModel(replace(pb, terms=[Loads(tip, 0, 1.0)]))
    springs = [Springs(np.array([tip]), 1.0), Springs(np.array([tip]), 2.0)]
    with pytest.raises(ValueError, match="two terms named 'springs'"):
        StaticModel(replace(pb, terms=springs))
    assert isinstance(pb, Problem)

