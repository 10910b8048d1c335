"""The model as CasADi Functions (issue: CasADi-native model): casadi.rootfinder's equilibria equal the
built-in Newton's, and the implicit-function theorem's sensitivity equals finite differences of solves.
(Derivatives of R against finite differences: tests/test_forward_backward.py; Opti examples:
tests/test_nlp_library.py.)"""

from dataclasses import replace

import numpy as np
import pytest
from conftest import small_trunk

import casadi as ca
from casadi_ws import StaticModel, equilibrium_function, point_function, solve_equilibrium


@pytest.fixture(scope="module")
def models():
    pb = small_trunk("corotational", n_cables=2)
    rf = replace(pb, solver=replace(pb.solver, newton="rootfinder"))
    return StaticModel(pb), StaticModel(rf)


@pytest.mark.parametrize("u", [[30.0, 40.0], [100.0, 0.0], [100.0, 100.0]])
def test_rootfinder_equilibria_equal_the_builtin_newton(models, u):
    builtin, rootfinder = models
    a = solve_equilibrium(builtin, u)
    b = solve_equilibrium(rootfinder, u)
    assert a.converged and b.converged
    assert b.factorization is None and b.iterations > 0  # really the rootfinder's Newton
    # both meet the relative residual 1e-8: their tips agree far below a micron (tip moves ~3e-4 m/N)
    assert np.linalg.norm(a.tip - b.tip) < 1e-8


def test_rootfinder_keeps_the_continuation(models):
    """From rest straight to a large input the rootfinder's Newton fails; continuation, as for the
    built-in Newton, finishes the job."""
    _, rootfinder = models
    strict = replace(rootfinder.problem, solver=replace(rootfinder.problem.solver, max_iterations=4))
    m = StaticModel(strict)
    e = solve_equilibrium(m, [100.0, 100.0])
    assert e.converged and e.load_steps > 0
    assert np.linalg.norm(e.tip - solve_equilibrium(models[0], [100.0, 100.0]).tip) < 1e-8


def test_implicit_function_sensitivity_equals_finite_differences(models):
    builtin, _ = models
    F = equilibrium_function(builtin)
    q0, u = ca.MX.sym("q0", builtin.n_free), ca.MX.sym("u", builtin.n_u)
    A_fun = ca.Function("A", [q0, u], [ca.jacobian(F(q0, u)[1], u)])
    u0 = np.array([40.0, 20.0])
    eq = solve_equilibrium(builtin, u0)
    A = A_fun(eq.q[builtin.free], u0).full()
    h = 1e-2  # N; the tip is smooth in u, central differences err O(h^2)
    fd = np.column_stack([(solve_equilibrium(builtin, u0 + h * e, tol=1e-12).tip
                           - solve_equilibrium(builtin, u0 - h * e, tol=1e-12).tip) / (2 * h) for e in np.eye(2)])
    np.testing.assert_allclose(A, fd, rtol=1e-4, atol=1e-4 * np.abs(fd).max())
    # the Function's own equilibrium is the package's
    q, p = F(eq.q[builtin.free] * 0.9, u0)
    np.testing.assert_allclose(np.asarray(p).ravel(), eq.tip, atol=1e-9)


def test_point_function_is_the_tip_and_embeds_points(models):
    m, _ = models
    eq = solve_equilibrium(m, [30.0, 40.0])
    p = point_function(m)
    np.testing.assert_allclose(np.asarray(p(eq.q[m.free])).ravel(), eq.tip, atol=1e-15)
    pts = np.array([[0.0, 0.0, 0.1], [0.002, 0.0, 0.15]])
    P = np.asarray(point_function(m, pts)(eq.q[m.free]))
    assert P.shape == (3, 2)
    np.testing.assert_allclose(P[:, 0], pts[0], atol=2e-3)  # moved, but not far, from its rest position
    assert m.q_rest.shape == (m.n_free,) and np.all(m.u_lower == m.u_min) and np.all(m.u_upper == m.u_max)


def test_forward_and_fb_run_on_the_rootfinder(models):
    """solver.newton: rootfinder reaches every method (no LU is handed back: each user refactorises)."""
    from casadi_ws import FBSettings, ForwardSettings, forward, forward_backward

    builtin, rootfinder = models
    a = forward(builtin.problem, settings=ForwardSettings(n_d=3, progress=False), model=builtin)
    b = forward(rootfinder.problem, settings=ForwardSettings(n_d=3, progress=False), model=rootfinder)
    assert len(a.points) == len(b.points) == 9
    np.testing.assert_allclose(a.points, b.points, atol=1e-8)
    fb = forward_backward(rootfinder.problem, settings=FBSettings(step=0.01, progress=False), model=rootfinder)
    assert len(fb.points) > 5
