"""docs/nlp-library.md's worked example, read from the doc itself: an extra objective term, checked against
finite differences."""

import re

import numpy as np
from conftest import REPO, small_trunk

from casadi_ws import StaticModel, solve_equilibrium
from casadi_ws.nlp.formulations import TrackingNLP


def doc_blocks(name: str) -> list[str]:
    """The ```python blocks of docs/NAME, in order."""
    return re.findall(r"```python\n(.*?)```", (REPO / "docs" / name).read_text(), flags=re.S)


def test_extra_objective_term_is_differentiated_exactly_and_changes_the_answer(rng):
    scope: dict = {}
    exec(compile(doc_blocks("nlp-library.md")[0], "docs/nlp-library.md", "exec"), scope)
    ShortCablesNLP = scope["ShortCablesNLP"]
    pb = small_trunk("corotational", n_cables=2)
    m = StaticModel(pb)
    nlp = ShortCablesNLP(m, gamma=1e-3)
    eq = solve_equilibrium(m, [30.0, 40.0])
    x = np.concatenate([eq.q[m.free], eq.u])
    v = rng.normal(size=nlp.pieces.nx)
    h = 1e-7
    f = lambda x: nlp.extra_value(m.full(x[: nlp.pieces.nq]), x[nlp.pieces.nq:])  # noqa: E731
    g = lambda x: nlp.extra_gradient(m.full(x[: nlp.pieces.nq]), x[nlp.pieces.nq:])  # noqa: E731
    assert np.isclose((f(x + h * v) - f(x - h * v)) / (2 * h), g(x) @ v, rtol=1e-6)
    H = nlp.extra_hessian(m.full(x[: nlp.pieces.nq]), x[nlp.pieces.nq:])
    np.testing.assert_allclose((g(x + h * v) - g(x - h * v)) / (2 * h), H @ v, rtol=1e-4, atol=1e-9)
    # an unreachable target: the plain problem and the one preferring short cables stop at different places
    target = eq.tip + np.array([0.0, 0.0, 0.05])
    q1, u1, s1 = TrackingNLP(m).solve(target[None], eq.q, eq.u)
    q2, u2, s2 = nlp.solve(target[None], eq.q, eq.u)
    assert s1["success"] and s2["success"]
    assert m.actuator_states(q2).sum() < m.actuator_states(q1).sum() - 1e-9
