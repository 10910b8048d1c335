"""The forward-backward method: Theorem 1, agreement with the forward method, verified points."""

import json

import numpy as np
import scipy.sparse as sp
import pytest
from conftest import coarse_problem_file, run_cli, small_trunk

from casadi_ws import Cable, StaticModel, solve_equilibrium
from casadi_ws.workspace.backward import BackwardSettings, backward
from casadi_ws.workspace.compare import compare
from casadi_ws.solvers.equilibrium import Factorization, factorize
from casadi_ws.workspace.forward import ForwardSettings, forward
from casadi_ws.workspace.forward_backward import FBSettings, forward_backward, prefilter
from casadi_ws.solvers.equilibrium import tangent_factorization
from casadi_ws.solvers.sensitivity import (TangentProducts, bounded_step, closest_to_box, curvature, distance_below,
                                          second_order, sensitivity)
from casadi_ws.workspace.interval import NEIGHBOURS, Grid, interval_box, neighbourhood


def test_theorem1_box_contains_the_linear_image_and_is_tight(rng):
    for _ in range(20):
        n_u = rng.integers(1, 5)
        A = rng.normal(size=(3, n_u))
        p = rng.normal(size=3)
        lo = -rng.uniform(0, 2, n_u)
        up = rng.uniform(0, 2, n_u)
        lower, upper = interval_box(A, p, lo, up)
        samples = p + rng.uniform(lo, up, size=(2000, n_u)) @ A.T
        assert np.all(samples >= lower - 1e-12) and np.all(samples <= upper + 1e-12)
        for i in range(3):  # each face is touched by a corner of dU
            corner_up = np.where(A[i] > 0, up, lo)
            corner_lo = np.where(A[i] > 0, lo, up)
            assert np.isclose((p + A @ corner_up)[i], upper[i]) and np.isclose((p + A @ corner_lo)[i], lower[i])


def test_theorem1_box_on_the_model_contains_nearby_equilibria():
    pb = small_trunk("corotational", n_cables=2)
    m = StaticModel(pb)
    u = np.array([30.0, 30.0])
    eq = solve_equilibrium(m, u)
    _, K, _ = m.residual_and_tangent(eq.q, u)
    A, _ = sensitivity(m, eq.q, Factorization(factorize(K), eq.q))
    # linearisation against finite differences of the equilibrium map
    for i in range(2):
        du = np.zeros(2)
        du[i] = 0.01
        ep = solve_equilibrium(m, u + du, q0=eq.q, u0=u, tol=1e-11)
        em = solve_equilibrium(m, u - du, q0=eq.q, u0=u, tol=1e-11)
        np.testing.assert_allclose((ep.tip - em.tip) / 0.02, A[:, i], rtol=2e-3, atol=1e-9)


def test_curvature_is_the_second_derivative_of_the_equilibrium_path():
    # q(u + du) = q + S du + Q(du, du)/2 + O(|du|^3): against solved equilibria one to two cells away,
    # the second-order predictor's error is of third order and its residual a small fraction of the
    # linear predictor's (which is what spares Newton its second LU)
    pb = small_trunk("corotational", n_cables=2)
    m = StaticModel(pb)
    u = np.array([30.0, 10.0])
    eq = solve_equilibrium(m, u, tol=1e-11)
    fac = tangent_factorization(m, eq.q, u)
    A, S = sensitivity(m, eq.q, fac)
    Q = curvature(m, eq.q, u, S, fac, 0.004)
    assert Q.shape == (3, m.n_free)
    errors = []
    for du in (np.array([6.0, 0.0]), np.array([0.0, 6.0]), np.array([4.0, -4.0]), np.array([2.0, -2.0])):
        ex = solve_equilibrium(m, u + du, q0=eq.q, u0=u, tol=1e-11)
        lin = eq.q.copy()
        lin[m.free] += S @ du
        quad = quad_predictor(m, eq.q, S, Q, du)
        e_lin, e_quad = np.linalg.norm(ex.q - lin), np.linalg.norm(ex.q - quad)
        assert e_quad < 0.05 * e_lin
        r_lin = np.linalg.norm(m.residual(lin, u + du))
        r_quad = np.linalg.norm(m.residual(quad, u + du))
        assert r_quad < 0.05 * r_lin
        errors.append(e_quad)
    assert errors[3] < errors[2] / 4  # half the step, ~an eighth of the error (third order)
    # FB's LU is the one Newton computed at this predictor; refined with the exact tangent at the answer,
    # it gives the answer's own A (without, A is ~1 % off)
    du = np.array([6.0, 0.0])
    ex = solve_equilibrium(m, u + du, q0=eq.q, u0=u, tol=1e-11)
    guess = quad_predictor(m, eq.q, S, Q, du)
    at_predictor = Factorization(factorize(m.residual_and_tangent(guess, u + du)[1]), guess)  # double precision
    A_exact, _ = sensitivity(m, ex.q, Factorization(factorize(m.residual_and_tangent(ex.q, u + du)[1]), ex.q))
    A_near, _ = sensitivity(m, ex.q, at_predictor)
    A_refined, _ = sensitivity(m, ex.q, at_predictor, m.residual_and_tangent(ex.q, u + du)[1])
    assert np.abs(A_refined - A_exact).max() < 0.1 * np.abs(A_near - A_exact).max()


def test_tangent_products_by_differences_refine_s_and_q_as_the_assembled_tangent_does():
    # FB refines a reached configuration's S and Q (from the LU at its predictor) against the tangent at the
    # answer; the products by residual differences must do what the assembled K does, to the LU's round-off
    pb = small_trunk("corotational", n_cables=2)
    m = StaticModel(pb)
    u = np.array([30.0, 10.0])
    eq = solve_equilibrium(m, u, tol=1e-11)
    K = m.residual_and_tangent(eq.q, u)[1]
    V = np.random.default_rng(1).standard_normal((m.n_free, 3))
    KV = TangentProducts(m, eq.q, u) @ V
    assert np.abs(KV - K @ V).max() < 1e-5 * np.abs(K @ V).max()
    du = np.array([6.0, 0.0])
    fac0 = tangent_factorization(m, eq.q, u)
    S0 = sensitivity(m, eq.q, fac0)[1]
    guess = quad_predictor(m, eq.q, S0, curvature(m, eq.q, u, S0, fac0, 0.004), du)
    ex = solve_equilibrium(m, u + du, q0=eq.q, u0=u, tol=1e-11)
    near = Factorization(factorize(m.residual_and_tangent(guess, u + du)[1]), guess)
    K_ex = m.residual_and_tangent(ex.q, u + du)[1]
    A_k, S_k = sensitivity(m, ex.q, near, K_ex)
    A_d, S_d = sensitivity(m, ex.q, near, TangentProducts(m, ex.q, u + du))
    assert np.abs(A_d - A_k).max() < 1e-6 * np.abs(A_k).max()
    Q_k = curvature(m, ex.q, u + du, S_k, near, 0.004, K_ex)
    Q_d = curvature(m, ex.q, u + du, S_d, near, 0.004, TangentProducts(m, ex.q, u + du))
    assert np.abs(Q_d - Q_k).max() < 1e-4 * np.abs(Q_k).max()


def test_fb_with_tangent_products_by_differences_reaches_the_same_cells():
    pb = small_trunk("corotational", n_cables=2)
    m = StaticModel(pb)
    runs = [forward_backward(pb, FBSettings(step=0.005, progress=False, backward=BackwardSettings(tangent_products=k)),
                             model=m) for k in ("assembled", "differences")]
    a, b = ({tuple(c) for c in r.arrays["cells"]} for r in runs)
    assert a == b
    assert abs(runs[1].counters["factorizations"] - runs[0].counters["factorizations"]) <= 0.02 * len(a)
    # auto: by differences where their residuals cost less than 3/4 of an assembled tangent
    from types import SimpleNamespace

    from casadi_ws.fem.elements import TET4, TET10
    from casadi_ws.workspace.forward_backward import _by_differences
    auto = BackwardSettings()
    assert [_by_differences(SimpleNamespace(n_u=n, element=TET10), auto) for n in (1, 2, 3)] == [True, True, False]
    assert [_by_differences(SimpleNamespace(n_u=n, element=TET4), auto) for n in (1, 2)] == [True, False]
    with pytest.raises(ValueError, match="tangent_products"):
        forward_backward(pb, FBSettings(step=0.005, progress=False, backward=BackwardSettings(tangent_products="x")),
                         model=m)


def test_a_failed_second_order_prediction_falls_back_to_the_linear_one_not_to_continuation():
    # on the 10-node trunk bent double, the second-order predictor can land where K is indefinite and Newton
    # diverges from it; Newton from the linear predictor then costs ~3 LUs, the continuation from q ~8
    from casadi_ws.workspace.backward import _equilibrium

    m = StaticModel(small_trunk("corotational", n_cables=2))
    u, du = np.array([30.0, 10.0]), np.array([6.0, 0.0])
    eq = solve_equilibrium(m, u)
    _, S = sensitivity(m, eq.q, tangent_factorization(m, eq.q, u))
    exact = solve_equilibrium(m, u + du, q0=eq.q, u0=u, tol=1e-11)
    wrong = 0.01 * np.random.default_rng(0).standard_normal(m.n_free)  # a curvature term 1 cm off
    guess = eq.q.copy()
    guess[m.free] += S @ du + wrong
    alone = solve_equilibrium(m, u + du, q0=eq.q, u0=u, guess=guess)
    assert alone.load_steps > 0  # Newton failed from it: the continuation took over
    res = _equilibrium(m, eq.q, u, u + du, S @ du, wrong)
    assert res.converged and res.load_steps == 0 and res.factorizations < alone.factorizations
    assert np.abs(res.q - exact.q).max() < 1e-8


def test_single_precision_lu_gives_double_precision_sensitivities_and_is_refused_when_inaccurate(rng):
    pb = small_trunk("corotational", n_cables=2)
    m = StaticModel(pb)
    u = np.array([30.0, 30.0])
    eq = solve_equilibrium(m, u)
    _, K, _ = m.residual_and_tangent(eq.q, u)
    single, double = Factorization(factorize(K, single=True), eq.q), Factorization(factorize(K), eq.q)
    assert single.K is not None and double.K is None  # Newton's LUs are single, factorize's default double
    A1, _ = sensitivity(m, eq.q, single)
    A2, _ = sensitivity(m, eq.q, double)
    np.testing.assert_allclose(A1, A2, rtol=1e-4, atol=1e-4 * np.abs(A2).max())
    # cond ~1e10: single precision would be meaningless, the probe falls back to double
    U, _ = np.linalg.qr(rng.standard_normal((40, 40)))
    V, _ = np.linalg.qr(rng.standard_normal((40, 40)))
    bad = sp.csc_matrix(U @ np.diag(np.logspace(0, 10, 40)) @ V.T)
    lu = factorize(bad, single=True)
    assert not lu.single and lu.K is None
    x = rng.standard_normal(40)
    np.testing.assert_allclose(lu.solve(bad @ x), x, rtol=1e-4)
    # exactly singular once rounded to single precision: factorised in double
    nearly = sp.csc_matrix(np.array([[1.0, 1.0], [1.0, 1.0 + 1e-10]]))
    lu = factorize(nearly, single=True)
    assert not lu.single
    np.testing.assert_allclose(nearly @ lu.solve(np.array([1.0, 2.0])), [1.0, 2.0], rtol=1e-5)


def quad_predictor(m, q, S, Q, du):
    guess = q.copy()
    guess[m.free] += S @ du + second_order(Q, du)
    return guess


def test_bounded_step_matches_scipy_bvls(rng):
    """The active-set bounded least squares against scipy's BVLS: never a worse fit, always inside the box
    (pinned, one-sided, aligned-column and underdetermined problems included)."""
    from scipy.optimize import lsq_linear

    for _ in range(500):
        n = int(rng.integers(1, 6))
        A = rng.normal(size=(3, n)) * 6e-4
        if n > 1 and rng.random() < 0.2:
            A[:, 1] = A[:, 0]
        r = rng.normal(size=3) * rng.choice([1e-3, 1e-2, 1e-1])
        lo = -rng.uniform(0, 50, n) * (rng.random(n) < 0.8)
        hi = rng.uniform(0, 50, n) * (rng.random(n) < 0.8)
        du = bounded_step(A, r, lo, hi)
        assert np.all(du >= lo) and np.all(du <= hi)
        ref = np.clip(lsq_linear(A, r, bounds=(lo, np.maximum(hi, lo + 1e-300)), method="bvls").x, lo, hi)
        assert np.linalg.norm(A @ du - r) <= np.linalg.norm(A @ ref - r) + 1e-12 * np.linalg.norm(r)


def test_distance_below_bounds_the_prefilter_gap(rng):
    """The prefilter's shortcut: distance_below is a lower bound on the distance to the linearised set for any
    normal, equal to it at bounded_step's residual, and so (/ sqrt 3, less the half cell) on closest_to_box's
    gap, which the shortcut then need not compute."""
    for _ in range(300):
        n = int(rng.integers(1, 6))
        A = rng.normal(size=(3, n)) * 6e-4
        r = rng.normal(size=3) * rng.choice([1e-3, 1e-2, 1e-1])
        lo, hi = -rng.uniform(0, 50, n), rng.uniform(0, 50, n)
        e = A @ bounded_step(A, r, lo, hi) - r
        d = np.linalg.norm(e)
        if d > 1e-6 * np.linalg.norm(r):  # outside the set (inside it, e is rounding and points anywhere)
            assert abs(distance_below(A, r, lo, hi, -e) - d) <= 1e-9 * np.linalg.norm(r)
        assert distance_below(A, r, lo, hi, rng.normal(size=3)) <= d + 1e-12
        h = rng.uniform(0.1, 2) * 1e-3
        assert closest_to_box(A, r, lo, hi, h)[1] >= d / np.sqrt(3) - h - 1e-12


def _flat_patch():
    """The small 2-cable trunk at u = (30, 30) N: model, u, equilibrium, A, and the unit normal of the linearised
    reachable set p + A du, a flat patch (two inputs)."""
    pb = small_trunk("corotational", n_cables=2)
    m = StaticModel(pb)
    u = np.array([30.0, 30.0])
    eq = solve_equilibrium(m, u)
    A, _ = sensitivity(m, eq.q, tangent_factorization(m, eq.q, u))
    n = np.cross(A[:, 0], A[:, 1])
    return m, u, eq, A, n / np.linalg.norm(n)


def test_prefilter_keeps_what_the_linearised_set_reaches_and_drops_what_it_misses():
    """A target the linearised reachable set p + A du (du within the remaining inputs) reaches is kept, one it
    misses by many cells is dropped, a cell whose centre it misses but whose corner it touches is kept as a
    whole cell (the backward may land off the centre), and no threshold keeps everything."""
    m, u, eq, A, n = _flat_patch()
    eta = 0.004
    inside = eq.tip + A @ np.array([10.0, -10.0])
    far = inside + 10 * eta * n
    # the cell's corner nearest the patch lies on it; its centre, in the infinity norm, lies
    # 0.5 eta (|n|_1 |n|_inf - 1) beyond half a cell from it: more than the prefilter's 0.1 eta
    assert 0.5 * (np.abs(n).sum() * np.abs(n).max() - 1) > 0.12
    corner = inside + 0.5 * eta * np.sign(n)
    assert prefilter(m, eq.q, u, A, eq.tip, [inside, far], eta, 0.1) == [True, False]
    assert prefilter(m, eq.q, u, A, eq.tip, [corner], eta, 0.1, whole_cell=True) == [True]
    assert prefilter(m, eq.q, u, A, eq.tip, [corner], eta, 0.1, whole_cell=False) == [False]
    assert prefilter(m, eq.q, u, A, eq.tip, [inside, far, corner], eta, None) == [True] * 3


def test_prefilter_second_order_model_drops_cells_the_curved_set_misses():
    """A target whose cell the linearised set misses by less than the threshold is kept by the linear test
    alone; with the configuration's curvature Q bending the set away from it (by half a cell at the inputs
    that reach nearest) the second-order model drops it, bending it towards it keeps it."""
    m, u, eq, A, n = _flat_patch()
    eta = 0.004
    corner = eq.tip + A @ np.array([10.0, -10.0]) + 0.5 * eta * np.sign(n)  # the cell's corner on the patch
    target = corner + 0.05 * eta * n  # its cell now misses the patch by ~0.05 step
    C = m.C_free
    bent = []
    for kappa in (-0.5 * eta / 100.0, 0.5 * eta / 100.0):  # d2p/du_i^2 = kappa n: half a cell at |du|^2 = 100
        CQ = np.column_stack([kappa * n, np.zeros(3), kappa * n])  # pairs (0, 0), (0, 1), (1, 1)
        Q = (C.T @ np.linalg.solve((C @ C.T).toarray(), CQ)).T.astype(np.float32)  # least-norm, C Q^T = CQ
        bent.append(prefilter(m, eq.q, u, A, eq.tip, [target], eta, 0.1, True, Q))
    assert prefilter(m, eq.q, u, A, eq.tip, [target], eta, 0.1, True) == [True]
    assert bent == [[False], [True]]


def test_backward_gives_up_sooner_near_its_closest_point_for_the_same_cells():
    """BackwardSettings.give_up_short: where the step from an iterate moves the tip less than a tenth of a cell,
    the forward-backward method's backward solves give up 0.02 cell beyond the target's cell instead of 0.05:
    fewer equilibria, the same cells (small 2-cable trunk)."""
    from casadi_ws.workspace.boundary import BoundarySettings

    pb = small_trunk("corotational", n_cables=2)
    m = StaticModel(pb)
    runs = [forward_backward(pb, FBSettings(progress=False, boundary=BoundarySettings(enabled=False),
                                            backward=BackwardSettings(give_up_short=short)), model=m)
            for short in (0.02, 0.05)]
    cells = [set(map(tuple, r.arrays["cells"].tolist())) for r in runs]
    assert cells[0] == cells[1]
    assert runs[0].counters["equilibrium_solves"] < runs[1].counters["equilibrium_solves"]


def test_backward_reports_how_far_the_second_order_model_put_its_first_equilibrium():
    """BackwardResult.predictor_error: with Q, the first equilibrium's tip lies within a few hundredths of a
    step of the second-order model's prediction (a one-cell move on the trunk); without Q, None."""
    pb = small_trunk("corotational", n_cables=2)
    m = StaticModel(pb)
    u = np.array([30.0, 30.0])
    eq = solve_equilibrium(m, u)
    fac = tangent_factorization(m, eq.q, u)
    A, S = sensitivity(m, eq.q, fac)
    eta = 0.004
    Q = curvature(m, eq.q, u, S, fac, eta, m.tangent(eq.q, u))
    target = eq.tip + eta * A[:, 0] / np.linalg.norm(A[:, 0])
    with_q = backward(m, target, eq.q, u, None, eta, BackwardSettings(), sens=(A, S, Q))
    without = backward(m, target, eq.q, u, None, eta, BackwardSettings(), sens=(A, S))
    assert with_q.ok and 0 <= with_q.predictor_error < 0.05
    assert without.ok and without.predictor_error is None


def test_neighbourhood_is_the_ring_filtered_by_the_box():
    assert len(NEIGHBOURS) == 26 and np.all(np.abs(NEIGHBOURS).max(axis=1) == 1)
    c = np.zeros(3)
    pts, off = neighbourhood(c, 0.1, np.array([-1, -1, -1.0]), np.array([1, 1, 1.0]))
    assert len(pts) == 26
    pts, off = neighbourhood(c, 0.1, np.array([0, -1, -1.0]), np.array([1, 1, 0.0]))
    assert len(pts) == 2 * 3 * 2 - 1 and np.all(off[:, 0] >= 0) and np.all(off[:, 2] <= 0)
    g = Grid(np.array([0.1, 0.2, 0.3]), 0.01)
    k = g.index(np.array([0.1249, 0.2, 0.2951]))
    assert k == (2, 0, 0) or k == (2, 0, -0)
    assert g.contains(k, np.array([0.1249, 0.2, 0.3049])) and not g.contains(k, np.array([0.1251, 0.2, 0.3]))


def strict_recall(fw, fb) -> float:
    """Share of the FB grid's cells holding a forward point that FB reports, computed here from the point
    set and the grid (not by casadi_ws.compare)."""
    origin, step = np.asarray(fb.arrays["grid_origin"]), float(fb.arrays["cell_step"])
    occupied = {tuple(k) for k in np.round((fw.points - origin) / step).astype(int)}
    reported = {tuple(k) for k in fb.arrays["cells"]}
    return len(occupied & reported) / len(occupied)


def _agreement(model_name, step):
    pb = small_trunk(model_name, n_cables=2)
    model = StaticModel(pb)
    fb = forward_backward(pb, FBSettings(step=step, progress=False), model=model)
    fw = forward(pb, settings=ForwardSettings(n_d=30, progress=False), model=model)
    return pb, model, fb, fw, compare(fw, fb)


def test_linear_material_fb_agrees_with_forward():
    # a linear body has no compressive geometric stiffness to offset the cables' own, so its workspace is
    # only ~8 mm wide: a finer grid
    _, _, fb, fw, cmp = _agreement("linear", 0.0015)
    assert fb.n_points > 10
    assert strict_recall(fw, fb) >= 0.98
    assert cmp["cells_a_in_b"] == strict_recall(fw, fb)
    assert cmp["precision_within_one_cell"] >= 0.99


def test_nonlinear_trunk_fb_agrees_with_forward_and_its_points_are_equilibria(tmp_path):
    pb, model, fb, fw, cmp = _agreement("corotational", 0.005)
    assert fb.counters["iterations"] >= 3 and fb.counters["explored"] >= fb.n_points - 1
    # the second-order predictor: one LU per equilibrium solve, not two (measured: 99 LUs for 99 solves,
    # 1.375 per reached cell, against 2.4 with the linear predictor)
    assert fb.counters["factorizations"] <= 1.05 * fb.counters["equilibrium_solves"]
    assert fb.counters["factorizations_per_cell"] < 1.6
    assert strict_recall(fw, fb) >= 0.98  # every cell a forward point occupies, edges included
    assert cmp["points_a_in_b_cells"] >= 0.98
    assert cmp["precision_within_one_cell"] >= 0.95
    assert cmp["hausdorff"] < 2 * 0.005
    # every FB point, re-solved forward at its u, lands where FB said (and its u is inside U)
    assert np.all(fb.u >= pb.u_min - 1e-12) and np.all(fb.u <= pb.u_max + 1e-12)
    for u, p in zip(fb.u[::3], fb.points[::3]):
        eq = solve_equilibrium(model, u)
        assert eq.converged and np.linalg.norm(eq.tip - p) < 1e-7
    # each reached point lies in its cell
    grid = Grid(fb.arrays["grid_origin"], float(fb.arrays["cell_step"]))
    assert all(grid.contains(tuple(c), p) for c, p in zip(fb.arrays["cells"], fb.points))
    fb.save(tmp_path)
    import pyvista as pv

    assert pv.read(tmp_path / "cells.vtu").n_cells == fb.n_points


def test_the_linear_predictor_reaches_the_same_cells_with_more_lus():
    """``second_order=False`` (no curvature Q per reached cell) changes the cost, not the workspace."""
    pb = small_trunk("corotational", n_cables=2)
    m = StaticModel(pb)
    second = forward_backward(pb, FBSettings(step=0.005, progress=False), model=m)
    first = forward_backward(pb, FBSettings(step=0.005, progress=False, backward=BackwardSettings(second_order=False)),
                             model=m)
    a, b = ({tuple(c) for c in r.arrays["cells"]} for r in (second, first))
    assert len(a ^ b) <= 0.02 * len(a)
    assert first.counters["factorizations_per_cell"] > 1.3 * second.counters["factorizations_per_cell"]


def test_a_curvature_serves_later_generations_for_the_same_cells(monkeypatch):
    """``curvature_age``: a reached configuration takes the Q of the one it was reached from while that Q is
    young enough; fewer Q are computed, the workspace is the same."""
    import importlib

    fbm = importlib.import_module("casadi_ws.workspace.forward_backward")
    calls = []
    monkeypatch.setattr(fbm, "curvature", lambda *a, **k: calls.append(1) or curvature(*a, **k))
    pb = small_trunk("corotational", n_cables=2)
    m = StaticModel(pb)
    runs, computed = {}, {}
    for age in (0, 2):
        calls.clear()
        runs[age] = forward_backward(pb, FBSettings(step=0.005, progress=False,
                                                    backward=BackwardSettings(curvature_age=age)), model=m)
        computed[age] = len(calls)
    a, b = ({tuple(c) for c in r.arrays["cells"]} for r in runs.values())
    assert len(a ^ b) <= 0.02 * len(a)
    assert computed[0] >= runs[0].counters["feasible"]  # every verified answer, and the start
    assert computed[2] < 0.6 * computed[0]
    assert runs[2].counters["factorizations_per_cell"] < 1.3 * runs[0].counters["factorizations_per_cell"]
    with pytest.raises(ValueError, match="curvature_age"):
        forward_backward(pb, FBSettings(step=0.005, progress=False, backward=BackwardSettings(curvature_age=-1)),
                         model=m)
    # auto: passed on with linear tetrahedra, where it was measured to pay, not with 10-node ones
    from types import SimpleNamespace

    from casadi_ws.fem.elements import TET4, TET10
    auto = BackwardSettings()
    assert [fbm._curvature_age(SimpleNamespace(n_u=2, element=e), auto) for e in (TET4, TET10)] == [2, 0]
    assert fbm._curvature_age(m, auto) == 2 and fbm._curvature_age(m, BackwardSettings(curvature_age=0)) == 0


def test_a_run_whose_curvatures_serve_later_generations_resumes_to_the_same_result(tmp_path):
    # the frontier's Q ages are checkpointed: a resumed run passes on the same Q's as an uninterrupted one
    pb = small_trunk("corotational", n_cables=2)
    m = StaticModel(pb)

    def run(max_cells=10**6, checkpoint_dir=None, resume=False):
        return forward_backward(pb, FBSettings(step=0.005, progress=False, max_cells=max_cells,
                                               backward=BackwardSettings(curvature_age=2)), model=m,
                                checkpoint_dir=checkpoint_dir, resume=resume)

    ref = run()
    assert run(15, tmp_path).counters["stopped_at_max_cells"]  # after iteration 2, where the Q's are 2 old
    resumed = run(checkpoint_dir=tmp_path, resume=True)
    for k in ("explored", "feasible", "backward_solves", "factorizations"):
        assert resumed.counters[k] == ref.counters[k], k
    np.testing.assert_array_equal(resumed.arrays["cells"], ref.arrays["cells"])
    np.testing.assert_array_equal(resumed.points, ref.points)  # to the bit: the same predictors


def test_unreachable_target_is_not_reached():
    pb = small_trunk("corotational", n_cables=2)
    m = StaticModel(pb)
    eq = solve_equilibrium(m, [0.0, 0.0])
    target = eq.tip + np.array([-0.01, 0.0, 0.0])  # cables only pull towards +x and +y
    r = backward(m, target, eq.q, eq.u, scale=0.005)
    assert r.ok and np.abs(r.tip - target).max() > 0.005
    np.testing.assert_allclose(r.u[0], 0.0, atol=1e-9)


def test_cli_fb_and_compare(tmp_path):
    prob = coarse_problem_file(tmp_path)
    run = run_cli
    r = run("solve", prob, "--method", "fb", "--step", "0.015", "--out", tmp_path / "fb")
    assert r.returncode == 0, r.stderr
    iterations = [line for line in r.stderr.splitlines() if line.startswith("forward-backward: iteration")]
    assert iterations and all(" s" in line and "reached" in line for line in iterations)
    assert any("cells/s); next: " in line and "at this rate" in line for line in iterations[:-1] or iterations)
    assert (tmp_path / "fb" / "cells.vtu").is_file()
    s = json.loads((tmp_path / "fb" / "summary.json").read_text())
    assert sum(s["failures"].values()) == s["n_failed"]
    r = run("solve", prob, "--method", "forward", "--nd", "4", "--out", tmp_path / "fw", "--quiet")
    assert r.returncode == 0, r.stderr
    r = run("compare", tmp_path / "fw", tmp_path / "fb", "--plot", tmp_path / "cmp.png")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    keys = list(out)
    assert keys[:3] == ["cells_a_in_b", "cells_b_in_a", "points_a_in_b_cells"]  # strict measures first
    assert {"coverage_within_one_cell", "precision_within_one_cell", "hausdorff", "cell_volume_a", "cell_volume_b",
            "volume_a", "volume_b"} <= set(out)
    assert (tmp_path / "cmp.png").is_file()
    r = run("solve", prob, "--method", "fb", "--step", "-1", "--out", tmp_path / "x")
    assert r.returncode == 2 and "--step" in r.stderr


@pytest.mark.parametrize("material, pulled", [("corotational", True), ("linear", True), ("linear", False),
                                              ("neohookean", True)])
def test_residual_function_derivatives_match_finite_differences(rng, material, pulled):
    """CasADi's Jacobian of R and Hessian of lam . R (from the model's Callbacks) against finite
    differences of the model's residual; also for cables without a pull point, whose Lagrangian Hessian
    once had a false segment from the origin (relative error 2e-4 with a linear material, whose elements add
    nothing to the Hessian)."""
    import casadi as ca
    from dataclasses import replace

    from casadi_ws import residual_function

    pb = small_trunk(material, n_cables=2)
    if not pulled:
        pb.actuators = [replace(c, pull_point=None) for c in pb.actuators]
    m = StaticModel(pb)
    u = np.array([30.0, 40.0])
    eq = solve_equilibrium(m, u)
    R = residual_function(m)
    nq = m.n_free
    q, uu = ca.MX.sym("q", nq), ca.MX.sym("u", m.n_u)
    x = ca.vertcat(q, uu)
    lam = rng.normal(size=nq)
    L = ca.dot(ca.DM(lam), R(q, uu))
    J = ca.Function("J", [q, uu], [ca.jacobian(R(q, uu), x)])
    H = ca.Function("H", [q, uu], [ca.hessian(L, x)[0]])
    x0 = np.concatenate([eq.q[m.free], u])
    v = rng.normal(size=nq + m.n_u)
    v[-2:] *= 10
    h = 1e-7

    def res(x):
        return m.residual(m.full(x[:nq]), x[nq:])

    def grad(x):  # gradient of lam . R, from the model's own tangent
        _, K, dRdu = m.residual_and_tangent(m.full(x[:nq]), x[nq:])
        return np.concatenate([K.T @ lam, dRdu.T @ lam])

    Jv = J(x0[:nq], x0[nq:]).sparse()
    # CasADi's Jacobian and Hessian are the model's own assembly, not an approximation of it
    _, K, dRdu = m.residual_and_tangent(eq.q, u)
    assert abs(Jv - sp.hstack([K, sp.csc_matrix(dRdu)])).max() == 0.0
    Hqq, Hqu = m.residual_hessian(eq.q, u, lam)
    Hx = H(x0[:nq], x0[nq:]).sparse()
    scale = abs(Hqq).max()
    assert abs(Hx[:nq, :nq] - 0.5 * (Hqq + Hqq.T)).max() < 1e-9 * scale
    assert np.abs(Hx[:nq, nq:].toarray() - Hqu).max() < 1e-12 * scale
    fd = (res(x0 + h * v) - res(x0 - h * v)) / (2 * h)
    assert np.linalg.norm(fd - Jv @ v) < 1e-6 * np.linalg.norm(fd)
    Hv = H(x0[:nq], x0[nq:]).sparse()
    fd = (grad(x0 + h * v) - grad(x0 - h * v)) / (2 * h)
    assert np.linalg.norm(fd - Hv @ v) < 1e-6 * np.linalg.norm(fd)


def test_ipopt_and_reduced_backward_agree():
    pb = small_trunk("corotational", n_cables=2)
    m = StaticModel(pb)
    u = np.array([30.0, 40.0])
    eq = solve_equilibrium(m, u)
    for d in ([0.002, 0.001, 0.0], [-0.003, 0.002, 0.001], [0.004, -0.002, -0.001]):
        target = eq.tip + np.array(d)
        tight = BackwardSettings(formulation="reduced", step_tolerance=1e-6, max_iterations=30, stop_inside=None)
        r = backward(m, target, eq.q, u, None, 0.005, tight)
        i = backward(m, target, eq.q, u, None, 0.005, BackwardSettings(formulation="ipopt"))
        assert r.ok and i.ok
        assert np.linalg.norm(r.tip - i.tip) < 2e-6  # metres
        # both are verified equilibria at their u
        for res in (r, i):
            assert np.linalg.norm(solve_equilibrium(m, res.u).tip - res.tip) < 1e-8


def test_fb_with_ipopt_backward_runs_and_stays_quiet(capfd):
    pb = small_trunk("corotational", n_cables=2)
    s = FBSettings(step=0.012, progress=False, backward=BackwardSettings(formulation="ipopt"))
    res = forward_backward(pb, s)
    out = capfd.readouterr().out
    assert "DMUMPS" not in out
    assert res.n_points >= 4 and res.counters["backward_solves"] >= res.n_points - 1
    # cell for cell against the reduced backward on the same grid (measured: 18 of its 20 cells, all of them
    # among its cells; the 2 others are edge cells whose closest point to the centre lies outside, which
    # IPOPT's problem (8) aims at and the reduced backward's edge_box rule does not)
    reduced = forward_backward(pb, FBSettings(step=0.012, progress=False))
    ipopt_cells = {tuple(c) for c in res.arrays["cells"]}
    reduced_cells = {tuple(c) for c in reduced.arrays["cells"]}
    assert ipopt_cells <= reduced_cells and len(ipopt_cells) >= 0.9 * len(reduced_cells)


def test_fb_result_does_not_depend_on_the_number_of_workers():
    pb = small_trunk("corotational", n_cables=2)
    one = forward_backward(pb, FBSettings(step=0.008, progress=False))
    two = forward_backward(pb, FBSettings(step=0.008, progress=False, workers=2))
    assert one.counters == two.counters
    np.testing.assert_array_equal(one.arrays["cells"], two.arrays["cells"])
    assert np.abs(one.points - two.points).max() < 1e-12


def test_answers_landing_in_reached_cells_skip_only_what_step_4_throws_away(monkeypatch):
    """Their sensitivities, Q and maps are not computed (see _expand): the run is the same without the skip."""
    import importlib

    fbm = importlib.import_module("casadi_ws.workspace.forward_backward")  # (the package's name is the function)
    pb = small_trunk("corotational", n_cables=4)  # two answers land in reached cells (3 cables at 6 mm: none)
    calls, derivatives = [], fbm._derivatives
    monkeypatch.setattr(fbm, "_derivatives", lambda *a, **k: calls.append(1) or derivatives(*a, **k))
    skip = forward_backward(pb, FBSettings(step=0.008, progress=False))
    with_skip = len(calls)
    monkeypatch.setattr(fbm.Exploration, "_reached_near", lambda self, cfg: (None, frozenset()))
    full = forward_backward(pb, FBSettings(step=0.008, progress=False))
    assert len(calls) - with_skip > with_skip and skip.counters == full.counters  # fewer, nothing else changed
    np.testing.assert_array_equal(skip.arrays["cells"], full.arrays["cells"])
    np.testing.assert_array_equal(skip.points, full.points)
    np.testing.assert_array_equal(skip.failed_u, full.failed_u)


def test_relative_strategy_explores_with_steps_relative_to_the_distance():
    pb = small_trunk("corotational", n_cables=2)
    model = StaticModel(pb)
    fb = forward_backward(pb, FBSettings(strategy="relative", relative_ratio=0.03, progress=False), model=model)
    assert fb.n_points > 5 and "cells" not in fb.arrays
    # targets are at least eta/2 apart (exclusion applies to targets, so two reached tips may land close);
    # every point is a verified equilibrium inside U
    from scipy.spatial.distance import pdist

    eta = 0.03 * np.linalg.norm(fb.points[0])
    assert pdist(fb.points).min() > 0
    for u, p in zip(fb.u[::4], fb.points[::4]):
        assert np.linalg.norm(solve_equilibrium(model, u).tip - p) < 1e-7
    fw = forward(pb, settings=ForwardSettings(n_d=11, progress=False), model=model)
    # strict: the share of the forward cloud's cells (grid of step eta) that hold a forward-backward point
    # (measured 0.979: 47 of 48)
    assert compare(fw, fb, step=eta)["cells_a_in_b"] >= 0.97


def test_every_cell_of_a_known_flat_workspace_is_reported():
    """Linear material, no gravity, two cables pulled from 100 m away (forces of a fixed direction): the
    workspace is the flat parallelogram p0 + A u, u in U. Every cell it enters by more than 5 % of a cell
    (sampled densely from the closed form) must be reported, and nothing else."""
    from conftest import cantilever

    pb = cantilever(n=2, slender=10, model="linear", E=1e6)
    tip = np.array([0.0, 0.0, 0.2])
    d1, d2 = np.array([1.0, 0.3, 0.0]), np.array([-0.4, 1.0, 0.0])  # a skewed parallelogram
    pb.actuators = [Cable(tip[None], tip + 100 * d1 / np.linalg.norm(d1), 0.0, 0.08, "a"),
                    Cable(tip[None], tip + 100 * d2 / np.linalg.norm(d2), 0.0, 0.05, "b")]
    m = StaticModel(pb)
    eq0 = solve_equilibrium(m, [0.0, 0.0])
    _, K, _ = m.residual_and_tangent(eq0.q, [0.0, 0.0])
    A, _ = sensitivity(m, eq0.q, Factorization(factorize(K), eq0.q))
    step = 0.001
    fb = forward_backward(pb, FBSettings(step=step, progress=False), model=m)
    # the closed form is the workspace: check it on a few FB points first
    for u, p in zip(fb.u[::7], fb.points[::7]):
        np.testing.assert_allclose(p, eq0.tip + A @ u, atol=1e-3 * step)
    grid = Grid(fb.arrays["grid_origin"], step)
    s = np.linspace(0, 1, 300)
    us = np.stack(np.meshgrid(s * 0.08, s * 0.05), axis=-1).reshape(-1, 2)
    patch = eq0.tip + us @ A.T
    k = np.round((patch - grid.origin) / step)
    deep = np.all(np.abs((patch - grid.origin) / step - k) <= 0.45, axis=1)
    crossed = {tuple(c) for c in k[deep].astype(int)}
    touched = {tuple(c) for c in k.astype(int)}
    reported = {tuple(c) for c in fb.arrays["cells"]}
    assert len(crossed) > 50
    assert crossed <= reported, f"missed {len(crossed - reported)} of {len(crossed)} cells"
    assert reported <= touched


def test_failures_say_which_were_prefiltered_not_reached_or_failed():
    from casadi_ws.status import Status
    from casadi_ws.workspace.result import WorkspaceResult

    codes = [Status.PREFILTERED] * 3 + [Status.NOT_REACHED, Status.GAVE_UP, Status.SOLVE_FAILED]
    fb = WorkspaceResult("forward-backward", np.zeros((0, 3)), np.zeros((0, 2)), failed_u=np.zeros((6, 3)),
                         failed_status=np.array(codes), failed_residual=np.zeros(6))
    assert fb.failures() == {"prefiltered": 3, "not_reached": 2, "failed": 1}
    assert fb.failures_line() == "3 prefiltered, 2 not reached, 1 failed"
    fw = WorkspaceResult("forward", np.zeros((0, 3)), np.zeros((0, 2)), failed_u=np.zeros((2, 2)),
                         failed_status=np.array([Status.MAX_ITERATIONS, Status.CONTINUATION_FAILED]),
                         failed_residual=np.zeros(2))
    assert fw.failures_line() == "2 failed" and fw.summary()["failures"]["failed"] == 2
