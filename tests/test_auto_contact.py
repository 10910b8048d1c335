"""Self-contact found as the body moves (``self_contact: auto``, issue 69): the declared pair's answer and beam
theory on the stacked cantilevers, a finger curled onto its own base checked by an audit independent of the
contact code (every boundary node against every tetrahedron), Newton's third law, finite differences, and
bad input."""

import json

import numpy as np
import pytest
import yaml
from conftest import REPO, nodes_inside_other_tetrahedra
from test_self_contact import EI, GAP, L, T, _beams

import casadi_ws as cw
from casadi_ws import StaticModel, problem_from_dict, solve_equilibrium
from casadi_ws.fem.spec import AutoSelfContact
from casadi_ws.io.problem import ProblemError
from casadi_ws.solvers.admissible import admissibility
from casadi_ws.solvers.equilibrium import SAME_STATE, _apart, settle


def _upper_force(m, q):
    """The vertical force the lower beam pushes the upper one with: the contact forces on the upper beam's
    nodes, summed (read off the residual's pieces, not the term's report)."""
    f = m.contact_forces(q)[: m.n_mech].reshape(-1, 3)
    return float(f[m.mesh.nodes[:, 2] > T + GAP / 2, 2].sum())


def test_auto_self_contact_gives_the_declared_pairs_force_and_beam_theorys(tmp_path):
    d = _beams(tmp_path)
    declared = StaticModel(problem_from_dict(d, str(tmp_path / "beams.yaml"), tmp_path))
    eq_d = solve_equilibrium(declared, np.zeros(1))
    d["self_contact"] = "auto"
    m = StaticModel(problem_from_dict(d, str(tmp_path / "beams.yaml"), tmp_path))
    eq = solve_equilibrium(m, np.zeros(1))
    assert eq_d.converged and eq.converged
    R = 3 * EI * GAP / (2 * L**3)
    F = _upper_force(m, eq.q)
    assert F == pytest.approx(_upper_force(declared, eq_d.q), rel=0.005)  # measured +0.2 %
    assert F == pytest.approx(R, rel=0.02)  # measured +0.5 %
    (c,) = [c for c in m.contacts(eq.q) if c["kind"] == "self"]
    assert c["points"] > 0 and c["force"] == pytest.approx(F, rel=0.005) and 0 < c["gap"] <= c["dhat"]
    f = m.contact_forces(eq.q)[: m.n_mech].reshape(-1, 3)
    assert np.abs(f.sum(axis=0)).max() <= 1e-9 * np.abs(f).sum()
    assert not nodes_inside_other_tetrahedra(m, eq.q)
    assert admissibility(m, eq.q, np.zeros(1), eq.factorization).admissible


@pytest.fixture(scope="module")
def curled_finger():
    """SoftRobots' Finger (problems/sofa/finger) with ``self_contact: auto``, its cable pulled 70 mm: without
    contact it passes through its own base from 55 mm on (tests/test_admissible.py)."""
    p = cw.load_problem(REPO / "problems" / "sofa" / "finger" / "finger.yaml")
    p.actuators[0].u_max = 0.09
    p.self_contact_auto = AutoSelfContact()
    m = StaticModel(p)
    return m, cw.quasi_static(m, [0.07])


def test_a_finger_curled_onto_its_base_presses_on_itself_and_not_through(curled_finger):
    m, eq = curled_finger
    assert eq.converged
    assert not nodes_inside_other_tetrahedra(m, eq.q)
    assert admissibility(m, eq.q, eq.u, eq.factorization).admissible
    (c,) = [c for c in m.contacts(eq.q) if c["kind"] == "self"]
    assert c["points"] > 0 and c["force"] > 1.0  # newtons: the curled end leans on the base
    f = m.contact_forces(eq.q)[: m.n_mech].reshape(-1, 3)
    assert np.abs(f.sum(axis=0)).max() <= 1e-9 * np.abs(f).sum()  # what it pushes, it is pushed back
    # another load path to the same input: beyond it, then back. Frictionless on a faceted base
    # the curled end can rest in more than one way (measured: up to 53 um apart, 5e-3 of an element), so the
    # package reports the state the path from rest in tenths reaches, whichever path found an answer
    beyond = solve_equilibrium(m, [0.08], q0=eq.q, u0=eq.u)
    back = solve_equilibrium(m, [0.07], q0=beyond.q, u0=beyond.u)
    assert beyond.converged and back.converged
    reported = settle(m, back, None)
    assert _apart(m, reported.q, eq.q) <= SAME_STATE
    assert reported.path_dependent == (_apart(m, back.q, eq.q) > SAME_STATE)


def test_the_tangent_with_contact_matches_finite_differences(curled_finger):
    m, eq = curled_finger
    q, u = eq.q.copy(), eq.u
    K = m.tangent(q, u)
    rng = np.random.default_rng(0)
    v = np.zeros(m.n_free)
    v[: m.n_free_mech] = rng.standard_normal(m.n_free_mech)
    errors = []
    for h in (1e-9, 1e-10):  # central differences; contact gaps are ~1 um, so steps must be far below
        qp, qm = q.copy(), q.copy()
        qp[m.free] += h * v
        qm[m.free] -= h * v
        fd = (m.residual(qp, u) - m.residual(qm, u)) / (2 * h)
        errors.append(np.linalg.norm(K @ v - fd) / np.linalg.norm(fd))
    assert errors[1] <= 1e-6 and errors[1] < errors[0], errors


def test_a_casadi_function_built_before_new_pairs_refuses_to_differentiate(curled_finger):
    m0, eq = curled_finger
    m = StaticModel(m0.spec)  # a new model: its pattern has the pairs of the rest state only
    R = cw.residual_function(m)
    J = R.jacobian()
    with pytest.raises(Exception, match="pattern grew"):
        J(eq.q[m.free], eq.u, np.zeros(m.n_free))


@pytest.mark.parametrize("value, message", [
    ("automatic", "expected 'auto'"),
    ({"auto": False}, "self_contact.auto: expected true"),
    ({"auto": True, "distance": 0.5}, "self_contact.distance: the body's boundary at rest has parts"),
])
def test_bad_self_contact_input_is_one_line(tmp_path, value, message):
    d = _beams(tmp_path, order=1, divisions=(10, 1, 1))
    d["self_contact"] = value
    with pytest.raises(ProblemError, match=message) as e:
        problem_from_dict(d, str(tmp_path / "beams.yaml"), tmp_path)
    assert "\n" not in str(e.value)
    (tmp_path / "beams.yaml").write_text(yaml.safe_dump(d))
    from casadi_ws.cli import main

    assert main(["equilibrium", str(tmp_path / "beams.yaml"), "--u", "0"]) == 2


def test_the_sofa_trunk_curls_onto_itself_past_where_it_passed_through():
    """The SoftRobots Trunk as imported (problems/sofa/trunk), one long cable at 40 % of its 70 mm stroke, the
    other seven at rest: without contact its disks met at 34 % and passed through each other; with
    ``self_contact: auto`` they press (docs/methods.md: the path goes on to a fold at 97.8 %)."""
    p = cw.load_problem(REPO / "problems" / "sofa" / "trunk" / "trunk.yaml")
    p.self_contact_auto = AutoSelfContact()
    m = StaticModel(p)
    u = np.zeros(m.n_u)
    u[0] = 0.4 * m.u_max[0]
    eq = cw.quasi_static(m, u)
    assert eq.converged
    (c,) = [c for c in m.contacts(eq.q) if c["kind"] == "self"]
    assert c["points"] > 0 and c["force"] > 0.5
    assert not nodes_inside_other_tetrahedra(m, eq.q)
    assert admissibility(m, eq.q, eq.u, eq.factorization).admissible


def test_an_equilibrium_through_itself_says_how_to_make_it_press(tmp_path, capsys):
    from casadi_ws.cli import main

    (tmp_path / "beams.yaml").write_text(yaml.safe_dump(_beams(tmp_path, contact=False)))
    assert main(["equilibrium", str(tmp_path / "beams.yaml"), "--u", "0"]) == 1
    err = capsys.readouterr().err
    assert "passes through itself" in err and "self_contact: auto" in err


def test_a_candidate_search_that_explodes_is_one_line_and_exit_2(tmp_path, monkeypatch, capsys):
    from casadi_ws.cli import main
    from casadi_ws.fem.terms import auto_contact

    d = _beams(tmp_path)
    d["self_contact"] = "auto"
    (tmp_path / "beams.yaml").write_text(yaml.safe_dump(d))
    monkeypatch.setattr(auto_contact, "MAX_PAIRS", 1e-3)  # the beams press with a few pairs: over the cap
    assert main(["equilibrium", str(tmp_path / "beams.yaml"), "--u", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "candidate search explodes" in err[0] and "self_contact.distance" in err[0]


@pytest.mark.parametrize("tension", [1.0, 1.5])
def test_newton_through_first_contact_takes_at_most_twice_the_contact_free_iterations(tension):
    """The pinch gripper (problems/pinch_gripper.yaml) with ``self_contact: auto`` instead of its declared pair,
    solved from rest at tensions where its jaws press (from ~0.55 N per cable): at most twice the Newton
    iterations of the same solve without contact (its jaws then pass through each other), issue 69's budget.
    A barrier's CCD-cut steps taken as they were made it 478 at 1.5 N (bouncing off the barrier), and cut at 0.8
    of the time of contact each step crept up to it (docs/methods.md "Self-contact found as the body moves");
    at 1.0 N the Newton stopped at its iteration limit while converging and started again from rest."""
    d = yaml.safe_load((REPO / "problems" / "pinch_gripper.yaml").read_text())
    del d["self_contact"]
    path, folder = str(REPO / "problems" / "pinch_gripper.yaml"), REPO / "problems"
    free = solve_equilibrium(StaticModel(problem_from_dict(d, path, folder)), [tension, tension])
    d["self_contact"] = "auto"
    m = StaticModel(problem_from_dict(d, path, folder))
    eq = solve_equilibrium(m, [tension, tension])
    assert free.converged and eq.converged and eq.load_steps == 0
    assert eq.iterations <= 2 * free.iterations, (eq.iterations, free.iterations)
    (c,) = [c for c in m.contacts(eq.q) if c["kind"] == "self"]
    assert c["points"] > 0 and not nodes_inside_other_tetrahedra(m, eq.q)


def test_the_docs_numbers_on_the_trunk_curling_onto_itself_are_the_benchmarks():
    """docs/methods.md and docs/sofa.md state what scripts/bench_self_contact.py measured
    (benchmarks/self_contact_trunk.json): the fold's share of the stroke, the pairs pressing there, how much the
    pattern grew, and the iterations of the step of first contact against the contact-free one before it."""
    b = json.loads((REPO / "benchmarks" / "self_contact_trunk.json").read_text())
    ok = [r for r in b["steps"] if r["status"] == "converged"]
    last = ok[-1]
    first = next(i for i, r in enumerate(ok) if r["pairs"] > 0)
    methods = (REPO / "docs" / "methods.md").read_text()
    sofa = (REPO / "docs" / "sofa.md").read_text()
    assert f"{100 * last['share']:.1f} %" in sofa and f"{last['pairs']} pairs pressing" in sofa
    assert f"{last['pairs']} pairs pressing" in methods
    assert (f"grew {last['pattern_grew']} times, from {b['nnz_without_self_contact']:,} to {last['nnz']:,} entries"
            in methods)
    ratio = ok[first]["iterations"] / ok[first - 1]["iterations"]
    assert f"takes {ratio:.1f}x the iterations of the contact-free one before it" in methods
