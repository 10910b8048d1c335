"""docs/nlp-library.md, run from the doc itself on a coarser trunk, and the claims its text makes: the wall is
active and the tip is the closest point on it; the least effort is lower than exact tracking's and lands
within 1 mm; the library's solver serves two targets; A from the rootfinder is A from the model."""

import re

import numpy as np
import pytest
from conftest import REPO, coarse_problem_file

from casadi_ws.solvers.equilibrium import tangent_factorization
from casadi_ws.solvers.sensitivity import sensitivity


def doc_blocks(name: str) -> list[str]:
    """The ```python blocks of docs/NAME, in order."""
    return re.findall(r"```python\n(.*?)```", (REPO / "docs" / name).read_text(), flags=re.S)


@pytest.fixture(scope="module")
def doc(tmp_path_factory):
    """The scope left by running every block of the page in order, on the 2-cable trunk at resolution 0.5."""
    coarse = coarse_problem_file(tmp_path_factory.mktemp("nlp"))
    scope: dict = {}
    for i, block in enumerate(doc_blocks("nlp-library.md")):
        code = block.replace('"problems/trunk_2cables.yaml"', repr(str(coarse)))
        exec(compile(code, f"docs/nlp-library.md block {i}", "exec"), scope)
    return scope


def test_wall_is_active_and_the_tip_is_the_closest_point_on_it(doc):
    model, wall, target, wall_y = doc["model"], doc["wall"], doc["target"], doc["wall_y"]
    assert wall.converged  # a verified equilibrium
    assert target[1] > wall_y + 0.005  # the target is well behind the wall ...
    assert abs(wall.tip[1] - wall_y) < 1e-7  # ... so the wall is active, and respected
    # stationary along the wall: a change of u that keeps the tip on the wall (to first order) does not
    # bring it nearer to the target; A from a fresh LU of the verified equilibrium (not from IPOPT)
    A, _ = sensitivity(model, wall.q, tangent_factorization(model, wall.q, wall.u))
    du = np.array([A[1, 1], -A[1, 0]])
    assert np.all((wall.u > model.u_lower + 1) & (wall.u < model.u_upper - 1))  # no bound active
    e = wall.tip - target
    assert abs(e @ (A @ du)) < 1e-5 * np.linalg.norm(e) * np.linalg.norm(A @ du)
    # and the answer is not the unconstrained one: the target itself is reachable
    assert np.linalg.norm(e) > 0.004


def test_least_effort_is_lower_than_exact_tracking_and_within_a_millimetre(doc):
    effort, exact, goal, u_effort = doc["effort"], doc["exact"], doc["goal"], doc["u_effort"]
    assert effort.converged and exact.reachable
    # the constraint is on the squared distance (m^2), met to IPOPT's constr_viol_tol 1e-10 m^2: 50 nm
    assert np.linalg.norm(effort.tip - goal) < 1e-3 + 1e-7
    assert np.linalg.norm(effort.tip - goal) > 0.999e-3  # active: any less effort and it would be farther
    assert np.sum(u_effort ** 2) < np.sum(exact.u ** 2) - 1.0


def test_library_solver_serves_two_targets_with_the_wall(doc):
    first, again, wall = doc["first"], doc["again"], doc["wall"]
    assert first.success and again.success
    np.testing.assert_allclose(first.u, wall.u, rtol=1e-5)  # the same problem as example 1
    assert again.iterations <= first.iterations + 5
    assert doc["nlp"].value(doc["nlp"].point(), again)[1] <= doc["wall_y"] + 1e-9


def test_rootfinder_jacobian_is_the_models_sensitivity(doc):
    model, start = doc["model"], doc["start"]
    A, _ = sensitivity(model, start.q, tangent_factorization(model, start.q, start.u))
    # to 1e-7 of A's largest entry: Newton's LU is single precision, refined twice (its cross terms are
    # 100x smaller than the diagonal ones, so an elementwise 1e-6 would ask them for 1e-8)
    np.testing.assert_allclose(doc["A_here"], A, rtol=1e-6, atol=1e-7 * np.abs(A).max())
