"""One robot, one answer (docs/methods.md "One answer per input"): a reported point is the equilibrium the robot
reaches by quasi-static loading from rest; Newton stays on its branch; forward's points do not depend on the
stride or on how the grid is split among workers; forward-backward's points equal the path from rest.

The full grids of every shipped problem, with two worker processes, are `scripts/branch_consistency.py`'s
(BENCHMARKS.md "One answer per input"); here coarse grids of every shipped problem but the two whose equilibria
take seconds (`pinch_gripper`, `trunk_2cables_fine`: the script covers them)."""

import importlib

import numpy as np
import pytest

import casadi_ws as cw
from casadi_ws import FBSettings, ForwardSettings, StaticModel, forward, forward_backward
from casadi_ws.solvers.equilibrium import Branch

from conftest import REPO, small_trunk

E = importlib.import_module("casadi_ws.solvers.equilibrium")
F = importlib.import_module("casadi_ws.workspace.forward")  # (the package's name is the function)
GUESS = REPO / "tests" / "data" / "trunk_table_crushing_guess.npz"
"""The first iterate the forward sweep of trunk_table (n_d = 21, Newton at every point) handed Newton at u = (10,
50) N before this issue's fix, recorded then: det F 0.986 everywhere, yet Newton went on to a crushed tip."""


@pytest.fixture(scope="module")
def table():
    return StaticModel(cw.load_problem(REPO / "problems" / "trunk_table.yaml"))


def test_newton_from_the_crushing_guess_reaches_the_equilibrium_of_the_path_from_rest(table):
    d = np.load(GUESS)
    assert table.jacobians(d["guess"]).min() > 0.98 and table.jacobians(d["crushed"]).min() < 0.5
    eq = cw.solve_equilibrium(table, d["u"], guess=d["guess"])
    ref = cw.quasi_static(table, d["u"])
    assert eq.converged and ref.converged
    assert table.jacobians(eq.q).min() > 0.95
    assert np.linalg.norm(eq.tip - ref.tip) < 1e-6


@pytest.mark.parametrize("guards", ["none", "trust region", "volume kept", "both"])
def test_each_guard_keeps_newton_off_the_crushed_branch(table, monkeypatch, guards):
    """Newton alone from the same guess: without the guards it converges on the crushed branch (as it did), though
    no trial state goes below det F 0.1; with the trust region it reaches the intact state directly, with the
    volume each element keeps it stops short (the continuation from rest then finds the intact state)."""
    if guards in ("none", "volume kept"):
        monkeypatch.setattr(E, "TRUST_REGION", np.inf)
    if guards in ("none", "trust region"):
        monkeypatch.setattr(E, "VOLUME_KEPT", 0.0)
    d = np.load(GUESS)
    eq = cw.solve_equilibrium(table, d["u"], guess=d["guess"], continuation=False)
    if guards == "none":
        assert eq.converged and table.jacobians(eq.q).min() < 0.5
    else:
        assert not eq.converged or table.jacobians(eq.q).min() > 0.95


def test_polishing_stops_at_round_off(table):
    """At rest trunk_table's residual cannot go below ~1e-10: asked for 1e-10, Newton stops where it stalls
    (it took 30 iterations and 18 LUs)."""
    eq = cw.solve_equilibrium(table, [0.0, 0.0], target=1e-10)
    assert eq.converged and eq.iterations <= 8 and eq.factorizations <= 3


def _in_pieces(model, settings, pieces):
    """The grid swept in ``pieces`` slices of whole lines (planes where lines are interpolated across), each
    from rest, as worker processes sweep them (two pieces per worker), here in this process: the tips and the
    number of points interpolated."""
    us = F.input_grid(model.u_min, model.u_max, settings.n_d)
    L = settings.n_d
    unit = L * L if model.n_u >= 2 and F.across_stride(settings, model.n_u, L) > 1 else L
    tips, interpolated = [], 0
    n_units = len(us) // unit
    for units in np.array_split(np.arange(n_units), min(pieces, n_units)):
        rows = np.arange(units[0] * unit, (units[-1] + 1) * unit)
        swept = F.sweep(model, us[rows], settings)
        assert np.all(swept.status == E.CONVERGED)
        tips.append(swept.tips)
        interpolated += swept.counters["interpolated"]
    return np.vstack(tips), interpolated


COARSE = {  # problem: (n_d, settings that interpolate)
    "finger_object": (9, dict(stride=2)),
    "trunk_2cables": (7, dict(stride=3)),
    "trunk_table": (5, dict(stride=2)),
    "trunk_2cables_order2": (4, dict(stride=2)),
    "sofa_trunk_2cables": (5, dict(stride=2)),
    "pneunet_finger": (4, dict(stride=2)),
    "trunk_3cables": (4, dict(stride=2, across=2)),
}
"""(trunk_4cables, 3^4 points twice, is left out: trunk_3cables sweeps planes across the same way, in a
third of the time)"""


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(COARSE))
def test_forward_points_do_not_depend_on_the_stride_or_the_workers(name):
    problem = cw.load_problem(REPO / "problems" / f"{name}.yaml")
    model = StaticModel(problem)
    nd, interpolating = COARSE[name]
    # (the points, not the maps, are compared: an LU per point for exact maps would cost a third more here)
    newton = ForwardSettings(n_d=nd, stride=1, across=1, progress=False, maps="interpolated")
    ref = forward(problem, settings=newton, model=model)
    assert ref.n_failed == 0 and not len(ref.arrays["excluded_violations"]) and ref.n_points == nd**problem.n_u
    # interpolating, and in the two slices one worker of two sweeps, each from rest
    sliced, interpolated = _in_pieces(model, ForwardSettings(n_d=nd, progress=False, maps="interpolated",
                                                             **interpolating), 2)
    assert interpolated > 0  # the second sweep does interpolate
    assert np.abs(sliced - ref.points).max() < 1e-6
    # and the equilibrium the robot reaches from rest, at the grid's far corner
    rest = cw.quasi_static(model, ref.u[-1])
    assert rest.converged and np.linalg.norm(ref.points[-1] - rest.tip) < 1e-6


def test_forward_on_trunk_table_with_newton_everywhere_takes_few_lus_and_excludes_nothing(table):
    """The issue's case on a coarser grid (n_d = 11): Newton at every point took 11.1 LUs per point (17.9 at
    n_d = 21, with points on a crushed branch); now 3.0, none excluded, every tip the path from rest's."""
    r = forward(table.problem, settings=ForwardSettings(n_d=11, stride=1, progress=False, maps="interpolated"),
                model=table)
    assert r.n_failed == 0 and not len(r.arrays["excluded_violations"])
    assert r.counters["factorizations"] / r.counters["points"] < 4
    for i in range(0, len(r.u), 30):
        ref = cw.quasi_static(table, r.u[i])
        assert np.linalg.norm(r.points[i] - ref.tip) < 1e-6


def test_forward_backward_points_equal_the_path_from_rest():
    pb = small_trunk("corotational", n_cables=2)
    model = StaticModel(pb)
    fb = forward_backward(pb, FBSettings(step=0.008, progress=False), model=model)
    assert fb.counters["path_dependent"] == 0
    for i in np.linspace(0, fb.n_points - 1, 8).round().astype(int):
        ref = cw.quasi_static(model, fb.u[i])
        assert ref.converged and np.linalg.norm(fb.points[i] - ref.tip) < 1e-6


def test_a_jump_to_another_branch_is_caught_and_the_path_from_rest_reported(table):
    """Newton from the crushing guess, as if the guess came from a neighbour at u = (10, 45) and the guards were
    off: the answer is on a crushed branch, the midpoint test fails, the path from the neighbour and the path
    from rest reach the intact state, which is reported (Branch.PATH_REPLACED)."""
    d = np.load(GUESS)
    start = cw.quasi_static(table, [10.0, 45.0])
    orig = E.TRUST_REGION, E.VOLUME_KEPT
    E.TRUST_REGION, E.VOLUME_KEPT = np.inf, 0.0
    try:
        res = E._newton(table, d["u"], d["guess"], 1.0, 1e-8, 30, None)
    finally:
        E.TRUST_REGION, E.VOLUME_KEPT = orig
    assert res.status == E.CONVERGED and table.jacobians(res.q).min() < 0.5
    checked, code, _ = E._check_branch(table, res, (start.q, start.u, 1.0), d["u"], 1e-8, 30, 64)
    assert code == Branch.PATH_REPLACED
    ref = cw.quasi_static(table, d["u"])
    assert np.linalg.norm(table.tip(checked.q) - ref.tip) < 1e-6


def test_where_the_finger_can_rest_on_the_egg_in_two_ways_the_path_from_rest_decides():
    """At a shortening of 17.5 mm the finger's tip rests against the (faceted) egg at one point or at two, 0.8 mm
    apart, both stable, depending on the steps it was loaded by. A method's answer whose pressing points differ
    from its neighbour's is compared with quasi_static from rest, which it becomes, counted path-dependent."""
    from casadi_ws.solvers.admissible import admissibility
    from casadi_ws.solvers.equilibrium import settle

    m = StaticModel(cw.load_problem(REPO / "problems" / "finger_object.yaml"))
    u = np.array([0.0175])
    rest_path = cw.quasi_static(m, u)
    others = (cw.quasi_static(m, u, max_step=s) for s in (0.02, 0.04, 0.01, 0.05, 0.03))
    other = next(o for o in others if o.converged and E._apart(m, o.q, rest_path.q) > 0.01)
    for eq in (rest_path, other):
        assert eq.converged and admissibility(m, eq.q, u).admissible
    assert np.linalg.norm(other.tip - rest_path.tip) > 1e-4
    rest = np.zeros(m.n_dof)  # nothing presses at rest: both answers are checked
    settled = settle(m, other, rest)
    assert settled.branch == Branch.PATH_DEPENDENT and np.linalg.norm(settled.tip - rest_path.tip) < 1e-9
    assert settle(m, rest_path, rest) is rest_path
