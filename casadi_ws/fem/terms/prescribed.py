"""Prescribed quantities (:class:`Prescribed`, phase ``rows``): a displacement-controlled cable, a chamber
controlled by its volume growth.

The input u_a is then g_a's target, g_a(q) = sign_a (Q_a(q) - Q_a(rest)) (a cable's shortening, a chamber's
growth), and the actuator's intensity t_a (tension, pressure) is an unknown of the state, held as t_a / kappa_a
(the intensity in units of the quantity, so that the state's entries are all lengths for cables and Newton's
norms weigh them alike). Each adds one equation,

    bilateral (a chamber):     kappa_a (g_a(q) - u_a) = 0
    unilateral (a cable):      phi(t_a, kappa_a (g_a(q) - u_a)) = 0,   phi(a, b) = a + b - sqrt(a^2 + b^2 + eps^2)

(the complementarity row contact uses too, :func:`casadi_ws.fem.terms.base.complementarity`): the cable is taut
(shortening = the motor's, tension >= 0) or slack (tension ~0, shortened more than the motor pulled), as SOFA's
CableConstraint with minForce 0. eps (1e-8 of kappa_a Q_a(rest)) keeps phi smooth, so Newton, the sensitivities
and the NLPs' Hessians see one smooth residual. kappa_a = 1 / (H_a K0^-1 H_a^T), the actuator's own stiffness at
rest, gives the row the units and the scale of a force (or pressure). The tangent is bordered by these rows,
dR/du_a is nonzero in its own row only.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..spec import ModelError
from .base import Term, complementarity, held_block, point_pairs, tangent_data

__all__ = ["Prescribed"]


class Prescribed(Term):
    """The rows and unknowns of the actuators whose input is their quantity (see the module)."""

    name = "intensities"
    applied = False
    negatives = None  # bordered (when it has rows): the stability test factorises the stiffness it holds

    def __init__(self, spec):
        self.actuators = list(spec.actuators)
        self.index = np.flatnonzero([getattr(a, "prescribed", False) for a in self.actuators])
        """The actuators whose input is their quantity."""
        self.n_rows = self.index.size
        self.negatives = 0 if not self.n_rows else None
        self.unilateral = np.array([self.actuators[i].unilateral for i in self.index], dtype=bool)
        self.source = spec.source
        self.kappa = np.zeros(self.n_rows)
        self.eps = np.zeros(self.n_rows)

    @property
    def tangent_from_residual(self):
        return self.n_rows > 0

    def setup(self, model, pos):
        acts = model.actuator_data
        self.border_dofs = [np.unique(acts[a].W[:, model.free].tocoo().col).astype(np.int64) for a in self.index]
        """Per prescribed actuator, the free dofs its points move (its row and column of the tangent)."""

    def pattern(self, model, pos):
        # prescribed actuator k borders K: column and row j over the dofs its points move, and the diagonal
        # (the Fischer-Burmeister row's dependence on the intensity)
        keys, n = [], model.n_free
        for k, r in enumerate(self.border_dofs):
            j = self.rows.start + k
            keys += [np.full(r.size, j) * n + r, r * n + j, np.array([j * n + j])]
        return np.concatenate(keys + [np.zeros(0, dtype=np.int64)])

    def attach(self, model, slots):
        self._border_slots = []  # per prescribed actuator: (column slots, row slots, diagonal slot)
        for r in self.border_dofs:
            self._border_slots.append((slots[: r.size], slots[r.size: 2 * r.size], slots[2 * r.size]))
            slots = slots[2 * r.size + 1:]

    def ready(self, model):
        """kappa (the actuator's own stiffness at rest, 1 / H K0^-1 H^T) and eps of each prescribed actuator."""
        if not self.n_rows:
            return
        from scipy.sparse.linalg import splu

        q0 = np.zeros(model.n_dof)
        ke, = model.elements.values(q0, "stiff")
        n = model.n_free_mech
        K0 = model.elements.assemble(model, ke)[:n, :n].tocsc()
        H = model.actuation_rows(q0)[:, :n]
        lu = splu(K0)
        rest = model.rest_quantities
        for k, a in enumerate(self.index):
            c = float(H[a] @ lu.solve(H[a]))
            if not c > 0:
                act = self.actuators[a]
                j = [x for x in self.actuators if x.kind == act.kind].index(act)
                raise ModelError(f"{self.source}: {act.kind}s[{j}].control: {act.name!r} does not move the "
                                      f"body at rest (its points are held: compliance {c:g}), so its "
                                      f"{act.quantity_name} cannot be prescribed")
            self.kappa[k] = 1.0 / c
            self.eps[k] = 1e-8 * self.kappa[k] * abs(rest[a])

    # ---------------------------------------------------------------- at a state
    def intensities(self, q: np.ndarray) -> np.ndarray:
        """The prescribed actuators' intensities (tension N, pressure Pa), from the state."""
        return self.kappa * q[self.state]

    def rows_at(self, model, q, u, Q):
        """(phi, dphi/da, dphi/db, d2phi/da2, d2phi/dadb, d2phi/db2) of each prescribed actuator's equation,
        a = its intensity, b = kappa (g(q) - u); with u None, b from the equilibrium's a b = eps^2/2. (The
        state holds a / kappa: its derivatives carry a factor kappa per a.)"""
        a = self.intensities(q)
        pre = self.index
        if u is None:
            b = self.eps**2 / (2 * np.maximum(a, self.eps))
        else:
            g = model.sign[pre] * (Q[pre] - model.rest_quantities[pre])
            b = self.kappa * (g - np.asarray(u, dtype=float)[pre])
        return complementarity(a, b, self.eps, self.unilateral)

    def slack(self, q: np.ndarray) -> np.ndarray:
        """(n_rows,) bool: the unilateral ones that are slack at the equilibrium q (a cable with no tension,
        shortened more than its motor pulled: tension below eps / sqrt 2, where the Fischer-Burmeister row
        depends more on the tension than on the shortening)."""
        return self.unilateral & (self.intensities(q) < self.eps / np.sqrt(2))

    # ---------------------------------------------------------------- the term
    def residual(self, model, q, u, R):
        if not self.n_rows:
            return None
        Q = model.actuator_states(q)
        R[self.rows] = self.rows_at(model, q, u, Q)[0]
        return None

    def add_tangent(self, model, s, cache, data):
        if not self.n_rows:
            return data
        data = tangent_data(model, data)
        Q, dQ, _ = model.actuators_term._at(s)
        _, pa, pb, *_ = self.rows_at(model, s.q, s.u, Q)
        H = (dQ * model.sign[:, None])[:, model.free]
        for k, (a, r) in enumerate(zip(self.index, self.border_dofs)):
            kap = self.kappa[k]
            cs, rs, ds = self._border_slots[k]
            data[cs], data[rs], data[ds] = -kap * H[a, r], pb[k] * kap * H[a, r], kap * pa[k]
        return data

    def input_jacobian(self, model, s, dRdu):
        if not self.n_rows:
            return
        Q = model.actuator_states(s.q)
        pb = self.rows_at(model, s.q, s.u, Q)[2]
        for k, a in enumerate(self.index):
            dRdu[:, a] = 0.0
            dRdu[self.rows.start + k, a] = -pb[k] * self.kappa[k]

    def held(self, model, q, u):
        """The held quantities: sum_k w_k rho_k H_k H_k^T, rho_k = 1e3 kappa_k (held 1000x stiffer than the body
        holds them at rest), w_k = dphi/db (1 for a taut cable or a chamber, 0 for a slack cable)."""
        if not self.n_rows:
            return None
        pb = self.rows_at(model, q, u, model.actuator_states(q))[2]
        H = model.actuation_rows(q)
        pt = np.concatenate([np.full(r.size, k) for k, r in enumerate(self.border_dofs)])
        fpos = np.concatenate(self.border_dofs)
        val = np.concatenate([H[a, r] for a, r in zip(self.index, self.border_dofs)])
        return held_block(1e3 * self.kappa * pb, pt, fpos, val, point_pairs(pt), model.n_free_mech)

    def add_hessian(self, model, s, lam, Hqq, Hqu):
        """The prescribed actuators' share of d(K^T lam)/d(q, u): the intensity's column of the geometric
        stiffness, and the second derivatives of phi(a, b)."""
        if not self.n_rows:
            return Hqq, Hqu
        q, u = s.q, s.u
        Q, dQ, h = model.actuator_terms(q, hessians=True)
        _, pa, pb, paa, pab, pbb = self.rows_at(model, q, u, Q)
        H = (dQ * model.sign[:, None])[:, model.free]
        n, nm = model.n_free, model.n_free_mech
        extra = sp.lil_matrix((n, n))
        acts = model.actuator_data
        for k, a in enumerate(self.index):
            j, lk, kap = self.rows.start + k, lam[self.rows.start + k], self.kappa[k]
            Wf = acts[a].W[:, model.free]
            d2Q = (Wf.T @ model.actuators_term.point_hessian(a, h) @ Wf).tocsr()
            # lam_k phi(a, b(q)): kappa (phi_b sign d2Q + phi_bb kappa H H^T) in (q, q)
            Hqq = Hqq + (lk * kap * pb[k] * model.sign[a]) * d2Q
            r = self.border_dofs[k]
            rr, cc = np.meshgrid(r, r, indexing="ij")
            Hqq = Hqq + sp.csr_matrix(((lk * pbb[k] * kap * kap * np.outer(H[a, r], H[a, r])).ravel(),
                                       (rr.ravel(), cc.ravel())), shape=(n, n))
            # (q, t_k) and (t_k, q): d(K^T lam)_q / dt_k = -sign d2Q lam_m (the column the actuators gave for
            # u_a), plus lam_k kappa phi_ab H; times kappa, the state holding t_k / kappa
            c = kap * (Hqu[:, a] + lk * kap * pab[k] * H[a])
            c[nm:] = 0.0
            extra[:, j] = c[:, None]
            extra[j, :] = c[None, :]
            extra[j, j] = lk * paa[k] * kap * kap
            # d(dR/du_a^T lam)/dq = d(-kappa phi_b lam_k)/dq
            col = np.zeros(n)
            col[:] = -kap * lk * pbb[k] * kap * H[a]
            col[j] = -kap * lk * pab[k] * kap
            Hqu[:, a] = col
        return (Hqq + extra.tocsr()).tocsc(), Hqu

    def input_pattern(self, model):
        return {int(a): np.array([self.rows.start + k]) for k, a in enumerate(self.index)}

    def hessian_pattern(self, model):
        # lam_k phi(a, b(q)) couples all the actuator's dofs
        rows, cols = [np.zeros(0, dtype=np.int64)], [np.zeros(0, dtype=np.int64)]
        for r in self.border_dofs:
            rr, cc = np.meshgrid(r, r, indexing="ij")
            rows.append(rr.ravel())
            cols.append(cc.ravel())
        return np.concatenate(rows), np.concatenate(cols)
