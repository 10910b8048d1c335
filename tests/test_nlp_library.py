"""docs/nlp-library.md's worked example: an extra objective term, checked against finite differences."""

import numpy as np
import scipy.sparse as sp
from conftest import small_trunk

from casadi_ws import StaticModel, solve_equilibrium
from casadi_ws.nlp.formulations import TrackingNLP


class ShortCablesNLP(TrackingNLP):
    """TrackingNLP + gamma * sum of cable lengths (the example of docs/nlp-library.md)."""

    def __init__(self, model, gamma, **kw):
        self.gamma = gamma
        super().__init__(model, **kw)

    def extra_value(self, q, u):
        L, _ = self.model.cable_lengths(q)
        return self.gamma * L.sum()

    def extra_gradient(self, q, u):
        _, dL = self.model.cable_lengths(q)
        g = np.zeros(self.pieces.nx)
        g[: self.pieces.nq] = self.gamma * dL[:, self.model.free].sum(axis=0)
        return g

    def extra_hessian(self, q, u):
        _, _, H2 = self.model.cable_lengths(q, hessians=True)
        Hqq = self.gamma * sum(H2)
        return sp.block_diag([Hqq, sp.csc_matrix((self.pieces.nu, self.pieces.nu))]).tocsc()


def test_extra_objective_term_is_differentiated_exactly_and_changes_the_answer(rng):
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
    assert m.cable_lengths(q2)[0].sum() < m.cable_lengths(q1)[0].sum() + 1e-12
