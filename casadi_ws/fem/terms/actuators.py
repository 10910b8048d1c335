"""The actuators' forces on the body (:class:`Actuators`, phase ``applied``): each actuator a pushes with its
intensity t_a (a cable's tension, a chamber's pressure) along H_a = sign_a dQ_a/dq, its quantity Q_a (a
cable's length: sign -1, so H = -dL/dq; a chamber's volume: +1). R holds -sign_a t_a dQ_a/dq; K gains the
geometric stiffness -sign_a t_a d2Q_a/dq2; dR/du_a = -H_a. The intensity is the input u_a, or the state's
unknown where the input is the quantity itself (:class:`casadi_ws.fem.terms.prescribed.Prescribed`).

The quantities and their derivatives are one CasADi function of the actuators' embedded points
(:mod:`casadi_ws.actuation`), evaluated for all actuators in one call.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ...actuation.base import quantity_functions, third_function
from ..kernels import ElementBatch
from .base import Evaluation, Term, tangent_data

__all__ = ["ActuatorData", "Actuators"]


@dataclass
class ActuatorData:
    actuator: object
    W: sp.csr_matrix
    """(3k x n_dof) positions of the actuator's points = W @ x."""
    hessian_sparsity: ca.Sparsity
    """Pattern of d2Q/dP2 (3k x 3k) as CasADi derives it."""
    _third: ca.Function | None = None

    @property
    def third(self) -> ca.Function:
        """(P, mu) -> d2(mu . dQ/dP)/dP2, for Lagrangian Hessians; built on first use (costly for a cavity)."""
        if self._third is None:
            self._third = third_function(self.actuator)
        return self._third


class Actuators(Term):
    """Every actuator's force, geometric stiffness and input derivative (see the module)."""

    name = "actuators"
    phase = "applied"
    negatives = 0

    def __init__(self, spec):
        self.actuators = list(spec.actuators)
        self.n_u = len(self.actuators)
        self.sign = np.array([a.sign for a in self.actuators], dtype=float)
        self._memo = None

    def setup(self, model, pos):
        """All actuators in one CasADi call (a call costs ~0.1 ms of overhead, a residual ~1 ms in all)."""
        self.data: list[ActuatorData] = []
        self._free = model.free
        self._n_dof, self._X = model.n_dof, model.X
        Ps, Qs, gs, hs = [], [], [], []
        for a in self.actuators:
            pieces = quantity_functions(a)
            self.data.append(ActuatorData(a, self._points_matrix(model, a), pieces["hessian_sparsity"]))
            Ps.append(pieces["P"])
            Qs.append(pieces["Q"])
            gs.append(pieces["dQ"])
            hs.append(pieces["d2Q"])
        sizes = [d.W.shape[0] for d in self.data]
        self.W_all = sp.vstack([d.W for d in self.data]).tocsr() if self.data else None
        """(3k x n_dof) every actuator's points, stacked in actuator order."""
        self._W_all_T = self.W_all.T.tocsr() if self.data else None
        self._g_rows = np.arange(sum(sizes))
        self._g_cols = np.repeat(np.arange(self.n_u), sizes)
        self._h_offsets = np.cumsum([0] + [d.hessian_sparsity.nnz() for d in self.data])[:-1]
        P = ca.vertcat(*Ps) if Ps else ca.SX(0, 1)
        Q, g = ca.vertcat(*Qs), ca.vertcat(*gs)
        h = ca.vertcat(*hs)
        self.quantities_function = ca.Function("actuators", [P], [Q, g])
        """P (stacked points) -> (Q, dQ/dP of each actuator's points)."""
        self._qgh = ca.Function("actuators_h", [P], [Q, g, h])
        # compiled like the element kernels: a CasADi call and its DM conversions cost ~50-90 us, 5-9 % of a
        # forward or forward-backward run on the linear trunk, whose element forces take ~130 us. Not a
        # cavity's: its volume's Hessian over the whole wall is megabytes of C, minutes of compiling
        small = max(self.quantities_function.n_instructions(), self._qgh.n_instructions()) < 50_000
        self._kernels = (ElementBatch(self.quantities_function, "c"), ElementBatch(self._qgh, "c")) \
            if self.data and model.elements.backend == "c" and small else None
        self.rest_quantities = self.terms(np.zeros(model.n_dof))[0]
        """Each actuator's quantity at rest (a cable's length, a chamber's volume)."""
        limits = [a.quantity_limits(Q0) for a, Q0 in zip(self.actuators, self.rest_quantities)]
        names = [l[2] if np.isfinite(l[0]) or np.isfinite(l[1]) else "" for l in limits]
        self.quantity_limits = (np.array([l[0] for l in limits]), np.array([l[1] for l in limits]),
                                names if any(names) else [])
        """(lower, upper, violation name) of each actuator's quantity Q (a cable's stroke, a chamber's
        volume); the names are empty where none is limited."""

    @staticmethod
    def _points_matrix(model, actuator) -> sp.csr_matrix:
        """W (3k x n_dof): the actuator's points from the nodal positions; points that are mesh nodes
        (``actuator.nodes``) follow them exactly, others are embedded in their host elements."""
        nodes = getattr(actuator, "nodes", None)
        if getattr(actuator, "spread", None):
            return spread_matrix(model, actuator.rest_points(), actuator.spread)
        if nodes is None:
            return model.embedding(np.asarray(actuator.rest_points(), dtype=float))
        cols = (3 * np.asarray(nodes, dtype=np.int64)[:, None] + np.arange(3)).ravel()
        return sp.csr_matrix((np.ones(cols.size), (np.arange(cols.size), cols)), shape=(cols.size, model.n_dof))

    def pattern(self, model, pos):
        # actuator i adds -sign_i u_i W^T h_i W (h_i: Hessian of its quantity in its points, 3k x 3k, whose
        # nonzeros are stored after the previous actuators' in the stacked vector of terms()): every pair of
        # nonzeros of W whose rows meet in h_i's pattern adds h_i[r1, r2] w1 w2 to K[i1, i2]
        h_index, h_weight, h_act, keys = [], [], [], []
        for i, d in enumerate(self.data):
            Wc = d.W[:, model.free].tocsr()
            Wc.sort_indices()
            hr, hc = (np.asarray(x, dtype=np.int64) for x in d.hessian_sparsity.get_triplet())
            # nonzero s = (r1, r2) of h_i pairs every entry of W's row r1 with every entry of its row r2
            count = np.diff(Wc.indptr)
            n1, n2 = count[hr], count[hc]
            tot = n1 * n2
            slot = np.repeat(np.arange(hr.size), tot)
            k = np.arange(tot.sum()) - np.repeat(np.cumsum(tot) - tot, tot)
            e1 = np.repeat(Wc.indptr[hr], tot) + k // np.repeat(n2, tot)
            e2 = np.repeat(Wc.indptr[hc], tot) + k % np.repeat(n2, tot)
            h_index.append(self._h_offsets[i] + slot)
            h_weight.append(Wc.data[e1] * Wc.data[e2])
            h_act.append(np.full(e1.size, i))
            keys.append(Wc.indices[e2].astype(np.int64) * model.n_free + Wc.indices[e1])
        self._h_index = np.concatenate(h_index + [np.zeros(0, dtype=np.int64)])
        self._h_weight = np.concatenate(h_weight + [np.zeros(0)])
        self._act_of_entry = np.concatenate(h_act + [np.zeros(0, dtype=np.int64)])
        return np.concatenate(keys + [np.zeros(0, dtype=np.int64)])

    def attach(self, model, slots):
        self._slots = slots

    # ---------------------------------------------------------------- what the actuators are at a state
    def terms(self, q: np.ndarray, hessians: bool = False):
        """Q (n_u,), dQ/dq (n_u, n_dof) and, if asked, the nonzeros of every d2Q/dP2, stacked."""
        if not self.data:
            return np.zeros(0), np.zeros((0, self._n_dof)), np.zeros(0)
        # a verified point asks for them two or three times at the same q (its residual, its state limits, its
        # maps): ~0.1 ms each, 5-7 % of an interpolated point of the forward sweep. The last answer is kept,
        # read-only, and returned while q is the same
        memo = self._memo
        if not hessians and memo is not None and memo[0].shape == np.shape(q) and np.array_equal(memo[0], q):
            return memo[1]
        P = self.W_all @ (self._X + q)
        if self._kernels is not None:
            out = [v[0] for v in self._kernels[hessians](P[None])]
        else:
            out = [np.asarray(v).ravel() for v in (self._qgh if hessians else self.quantities_function)(P)]
        G = np.zeros((self._g_rows.size, self.n_u))
        G[self._g_rows, self._g_cols] = out[1]
        dQ = (self._W_all_T @ G).T
        values = out[0]
        if hessians:
            return values, dQ, out[2]
        values.flags.writeable = dQ.flags.writeable = False
        self._memo = (np.array(q, dtype=float, copy=True), (values, dQ, None))
        return values, dQ, None

    def _at(self, s: Evaluation):
        """(Q, dQ, h) at s, computed once for its residual and tangent."""
        if self not in s.memo:
            s.memo[self] = self.terms(s.q, hessians=s.tangent)
        return s.memo[self]

    def rows(self, q: np.ndarray) -> np.ndarray:
        """H(q) = sign dQ/dq on the free dofs, (n_u, n_free) (a cable's row: -dL/dq): where each actuator's
        intensity pushes the body."""
        _, dQ, _ = self.terms(q)
        return (dQ * self.sign[:, None])[:, self._free]

    def point_hessian(self, i: int, h: np.ndarray) -> sp.csr_matrix:
        """d2Q_i/dP2 (3k x 3k) of actuator i from the stacked nonzeros ``h`` of :meth:`terms`."""
        sp_h = self.data[i].hessian_sparsity
        r, c = sp_h.get_triplet()
        return sp.csr_matrix((h[self._h_offsets[i]: self._h_offsets[i] + sp_h.nnz()], (r, c)),
                             shape=(sp_h.size1(), sp_h.size2()))

    def hessians(self, q: np.ndarray) -> list[sp.csc_matrix]:
        """d2Q_a/dq2 on the free dofs, one sparse matrix per actuator."""
        _, _, h = self.terms(q, hessians=True)
        return [(d.W[:, self._free].T @ self.point_hessian(i, h) @ d.W[:, self._free]).tocsc()
                for i, d in enumerate(self.data)]

    def third(self, q: np.ndarray, lam_full: np.ndarray, t: np.ndarray):
        """The actuators' share of the Hessian of lam . R over (q, u) on the free dofs: the (q, q) block
        -sum_a sign_a t_a d2(lam . dQ_a/dq)/dq2 and the (q, u) columns -sign_a d2Q_a/dq2 lam."""
        x = self._X + q
        Hqq = sp.csc_matrix((self._free.size, self._free.size))
        cols = []
        _, _, h = self.terms(q, hessians=True)
        for i, (d, ta, sa) in enumerate(zip(self.data, t, self.sign)):
            P = d.W @ x
            mu = d.W @ lam_full
            Wf = d.W[:, self._free]
            T = d.third(P, mu).sparse()
            Hqq = Hqq + (-sa * ta) * (Wf.T @ T @ Wf)
            cols.append(-sa * (Wf.T @ (self.point_hessian(i, h) @ mu)))
        return Hqq, cols

    # ---------------------------------------------------------------- the term
    def forces(self, model, s):
        _, dQ, _ = self._at(s)
        return dQ.T @ (-self.sign * model.intensities(s.q, s.u))

    def add_tangent(self, model, s, cache, data):
        if not self.data:
            return data
        h = self._at(s)[2] if s.tangent else self.terms(s.q, hessians=True)[2]
        coef = -self.sign * model.intensities(s.q, s.u)  # R holds -sign_a t_a dQ_a/dq
        weights = coef[self._act_of_entry] * self._h_weight * h[self._h_index]
        if weights.size:
            data = tangent_data(model, data)
            data[: model.nnz] += np.bincount(self._slots, weights=weights, minlength=model.nnz)
        return data

    def input_jacobian(self, model, s, dRdu):
        _, dQ, _ = self._at(s)
        dRdu[:] = (dQ * -self.sign[:, None])[:, model.free].T

    def add_hessian(self, model, s, lam, Hqq, Hqu):
        lam_full = np.zeros(model.n_dof)
        lam_full[model.free] = lam
        Hact, cols = self.third(s.q, lam_full, model.intensities(s.q, s.u))
        return Hqq + Hact, (np.column_stack(cols) if cols else np.zeros((model.n_free, 0)))

    def input_pattern(self, model):
        return {a: np.unique(d.W[:, model.free].tocoo().col) for a, d in enumerate(self.data)}

    def hessian_pattern(self, model):
        hr, hc = [], []
        for d in self.data:
            Wf = d.W[:, model.free].tocsr()
            T = d.third.sparsity_out(0)
            tr, tc = (np.asarray(x, dtype=np.int64) for x in T.get_triplet())
            S = sp.csr_matrix((np.ones(tr.size), (tr, tc)), shape=(Wf.shape[0], Wf.shape[0]))
            P = (abs(Wf).T @ S @ abs(Wf)).tocoo()
            hr.append(P.row)
            hc.append(P.col)
        cat = lambda parts: np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)  # noqa: E731
        return cat(hr), cat(hc)


def spread_matrix(model, points: np.ndarray, radius: float) -> sp.csr_matrix:
    """W (3k x n_dof) of points each standing for the weighted mean of the body's boundary nodes within
    ``radius`` of it, weights (radius - distance) normalised: a force on the point is spread over that patch
    as SOFA's cable ``radii`` spread it (its geodesic distance taken as the straight one)."""
    from ..contact import boundary_nodes

    b = boundary_nodes(model.mesh)
    rows, cols, vals = [], [], []
    for i, p in enumerate(np.asarray(points, dtype=float)):
        d = np.linalg.norm(model.mesh.nodes[b] - p, axis=1)
        near = d < radius
        if not near.any():
            raise ValueError(f"no boundary node of the body within {radius:g} m of the point {p.tolist()}")
        w = (radius - d[near]) / (radius - d[near]).sum()
        for c in range(3):
            rows.append(np.full(near.sum(), 3 * i + c))
            cols.append(3 * b[near] + c)
            vals.append(w)
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(3 * len(points), model.n_dof))
