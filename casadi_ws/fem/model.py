"""The static FEM model of a soft robot: residual, tangent stiffness, and their derivatives.

    R(q, u) = f_int(q) - H(q)^T u - F = 0,        H_a = sign_a dQ_a/dq,    p_E = C q + p_E(0)

q is the vector of nodal displacements (3n, node-major; fixed dofs stay 0), u the actuator inputs, Q_a the
quantity of actuator a (a cable's length: sign -1, so H = -dL/dq). The element laws come from
:mod:`casadi_ws.fem.materials` (CasADi SX, one graph per element type) and are evaluated over the mesh by
:class:`casadi_ws.fem.kernels.ElementBatch`; the actuators' quantities and their derivatives are one CasADi
function of the actuators' embedded points (:mod:`casadi_ws.actuation`). Assembly uses index maps fixed
once per mesh. All matrices returned here are restricted to the free dofs.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ..actuation.base import quantity_functions
from .kernels import ElementBatch
from .materials import element_functions
from .mesh import embed

__all__ = ["ROUNDOFF", "StaticModel"]

ROUNDOFF = 20 * np.finfo(float).eps
"""Relative round-off allowed in the assembled internal forces: at rest (zero load) a residual below
ROUNDOFF x the elements' force scale counts as zero (measured at rest: ~3 eps for every law and order)."""


@dataclass
class _ActuatorData:
    actuator: object
    W: sp.csr_matrix
    """(3k x 3n) positions of the actuator's points = W @ x."""
    hessian_sparsity: ca.Sparsity
    """Pattern of d2Q/dP2 (3k x 3k) as CasADi derives it."""
    third: ca.Function
    """(P, mu) -> d2(mu . dQ/dP)/dP2, for Lagrangian Hessians."""


class StaticModel:
    """Numeric static model of a :class:`casadi_ws.io.problem.Problem`."""

    def __init__(self, problem, backend: str = "auto"):
        self.problem = problem
        mesh = problem.mesh
        self.mesh = mesh
        self.element = element = mesh.element
        self.n_nodes = mesh.n_nodes
        self.n_dof = 3 * mesh.n_nodes
        fixed = problem.fixed_dofs()  # (n_nodes, 3)
        self.fixed_nodes = np.flatnonzero(fixed.all(axis=1))
        self.free = np.flatnonzero(~fixed.ravel())
        self.n_free = self.free.size
        self.X = mesh.nodes.reshape(-1).copy()

        # --- elements
        mat = problem.material
        Xe = mesh.nodes[mesh.tets]
        w, G = element.rest_geometry(Xe)
        # Lame parameters and density per element: the body's material, overridden in its regions
        mu, lam = np.full(mesh.n_tets, mat.lame[0]), np.full(mesh.n_tets, mat.lame[1])
        rho = np.full(mesh.n_tets, mat.density)
        for tets, region in problem.regions:
            mu[tets], lam[tets] = region.lame
            rho[tets] = region.density
        nd = element.n_dof
        self._Xe = (Xe - Xe[:, :1]).reshape(-1, nd)  # element-local: see materials' note on round-off
        self._Ge = G.reshape(G.shape[0], -1)
        self._Pe = np.column_stack([w, mu, lam])
        funs = element_functions(mat.model, element, hessian=False)
        self.element_functions = funs
        self._force = ElementBatch(funs["force"], backend)
        self._stiff = ElementBatch(funs["stiffness"], backend)
        self.backend = self._force.backend
        self._edofs = (3 * mesh.tets[:, :, None] + np.arange(3)[None, None, :]).reshape(-1, nd)

        # --- loads: consistent gravity loads and point loads on embedded points
        F = np.zeros(self.n_dof)
        g = np.asarray(problem.gravity, dtype=float)
        if np.any(g):
            weights = rho[:, None] * element.body_load_weights(Xe)  # kg per node and element
            for a in range(element.n_nodes):
                np.add.at(F.reshape(-1, 3), mesh.tets[:, a], weights[:, a, None] * g[None, :])
        for point, force in problem.point_loads:
            W = embed(mesh, np.asarray(point)[None]).matrix(mesh)
            F += W.T @ np.asarray(force, dtype=float)
        self.F = F

        # --- actuators
        self.actuators = list(problem.actuators)
        self.n_u = len(self.actuators)
        self.u_min = np.array([a.u_min for a in self.actuators], dtype=float)
        self.u_max = np.array([a.u_max for a in self.actuators], dtype=float)
        self.sign = np.array([a.sign for a in self.actuators], dtype=float)
        self._build_actuators()
        self._build_pattern()
        rest_Q = self.actuator_states(np.zeros(self.n_dof))
        limits = [a.quantity_limits(Q0) for a, Q0 in zip(self.actuators, rest_Q)]
        self.quantity_limits = (np.array([l[0] for l in limits]), np.array([l[1] for l in limits]),
                                [l[2] if np.isfinite(l[0]) or np.isfinite(l[1]) else "" for l in limits])
        """(lower, upper, violation name) of each actuator's quantity Q (a cable's stroke, a chamber's
        volume); the name is empty where it is unlimited."""
        if not any(self.quantity_limits[2]):
            self.quantity_limits = (self.quantity_limits[0], self.quantity_limits[1], [])
        stretch = np.full(mesh.n_tets, np.inf if mat.max_stretch is None else mat.max_stretch)
        for tets, region in problem.regions:
            stretch[tets] = np.inf if region.max_stretch is None else region.max_stretch
        self.max_stretch = stretch
        """Largest principal stretch allowed per element (inf: none)."""

        # --- end-effector: p_E = C q + p_E(0)
        ee = np.atleast_2d(np.asarray(problem.end_effector, dtype=float))
        self.C = embed(mesh, ee).matrix(mesh).tocsr()
        self.p0 = self.C @ self.X
        self.C_free = self.C[:, self.free].tocsc()

        # force scale under which a residual counts as zero. Loads of exactly 0 give q = 0, but the internal
        # forces there are round-off, ~eps of the force each element exerts at unit strain (E V_e^(2/3),
        # the polar decomposition's included); that round-off must pass the tolerance whatever the law
        E_e = np.full(mesh.n_tets, mat.young_modulus)
        for tets, region in problem.regions:
            E_e[tets] = region.young_modulus
        self.element_force_scale = float(np.linalg.norm(E_e * np.abs(w.sum(axis=1)) ** (2.0 / 3.0)))
        """The norm over elements of the force each exerts at unit strain, E_e V_e^(2/3) (N)."""
        self.force_floor = max(1e-12 * mat.young_modulus * mesh.characteristic_length() ** 2,
                               ROUNDOFF * self.element_force_scale / problem.solver.tolerance)
        self._G_qp = G  # (m, n_qp, n_nodes, 3): deformation gradients for the admissibility checks

    # ------------------------------------------------------------------ assembly
    def _build_actuators(self):
        """All actuators in one CasADi call (a call costs ~0.1 ms of overhead, a residual ~1 ms in all)."""
        self._act: list[_ActuatorData] = []
        Ps, Qs, gs, hs = [], [], [], []
        for a in self.actuators:
            pieces = quantity_functions(a)
            W = self._points_matrix(a)
            self._act.append(_ActuatorData(a, W, pieces["hessian_sparsity"], pieces["third"]))
            Ps.append(pieces["P"])
            Qs.append(pieces["Q"])
            gs.append(pieces["dQ"])
            hs.append(pieces["d2Q"])
        sizes = [d.W.shape[0] for d in self._act]
        self._W_all = sp.vstack([d.W for d in self._act]).tocsr() if self._act else None
        self._W_all_T = self._W_all.T.tocsr() if self._act else None
        self._g_rows = np.arange(sum(sizes))
        self._g_cols = np.repeat(np.arange(self.n_u), sizes)
        self._h_offsets = np.cumsum([0] + [d.hessian_sparsity.nnz() for d in self._act])[:-1]
        P = ca.vertcat(*Ps) if Ps else ca.SX(0, 1)
        Q, g = ca.vertcat(*Qs), ca.vertcat(*gs)
        h = ca.vertcat(*hs)
        self._actuators_qg = ca.Function("actuators", [P], [Q, g])
        self._actuators_qgh = ca.Function("actuators_h", [P], [Q, g, h])

    def _points_matrix(self, actuator) -> sp.csr_matrix:
        """W (3k x 3n): the actuator's points from the nodal positions; points that are mesh nodes
        (``actuator.nodes``) follow them exactly, others are embedded in their host elements."""
        nodes = getattr(actuator, "nodes", None)
        if nodes is None:
            return embed(self.mesh, np.asarray(actuator.rest_points(), dtype=float)).matrix(self.mesh)
        cols = (3 * np.asarray(nodes, dtype=np.int64)[:, None] + np.arange(3)).ravel()
        return sp.csr_matrix((np.ones(cols.size), (np.arange(cols.size), cols)), shape=(cols.size, self.n_dof))

    def actuator_terms(self, q: np.ndarray, hessians: bool = False):
        """Q (n_u,), dQ/dq (n_u, 3n) and, if asked, the nonzeros of every d2Q/dP2, stacked."""
        if not self._act:
            return np.zeros(0), np.zeros((0, self.n_dof)), np.zeros(0)
        P = self._W_all @ (self.X + q)
        out = (self._actuators_qgh if hessians else self._actuators_qg)(P)
        G = np.zeros((self._g_rows.size, self.n_u))
        G[self._g_rows, self._g_cols] = np.asarray(out[1]).ravel()
        dQ = (self._W_all_T @ G).T
        return np.asarray(out[0]).ravel(), dQ, (np.asarray(out[2]).ravel() if hessians else None)

    def _build_pattern(self):
        """Index maps from element stiffness entries and actuator Hessian entries to the CSC data of K on
        the free dofs (one pattern for both, so assembling K is a single bincount)."""
        pos = -np.ones(self.n_dof, dtype=np.int64)
        pos[self.free] = np.arange(self.n_free)
        ed = pos[self._edofs]  # (m, n_dof_e), -1 for fixed
        nd = self.element.n_dof
        # element matrix is vec'ed column-major: entry (a, b) at index b * nd + a
        j = np.arange(nd * nd)
        rows, cols = ed[:, j % nd].ravel(), ed[:, j // nd].ravel()
        keep = (rows >= 0) & (cols >= 0)
        keys = [cols[keep] * self.n_free + rows[keep]]
        # actuator i adds -sign_i u_i W^T h_i W (h_i: Hessian of its quantity in its points, 3k x 3k, whose
        # nonzeros are stored after the previous actuators' in the stacked vector of actuator_terms): every
        # pair of nonzeros of W whose rows meet in h_i's pattern adds h_i[r1, r2] w1 w2 to K[i1, i2]
        h_index, h_weight, h_act = [], [], []
        for i, d in enumerate(self._act):
            Wc = d.W[:, self.free].tocsr()
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
            keys.append(Wc.indices[e2].astype(np.int64) * self.n_free + Wc.indices[e1])
        ukey, slot = np.unique(np.concatenate(keys), return_inverse=True)
        # every element entry has a slot; those of fixed dofs go to one past the end, cut off after the
        # bincount (cheaper than gathering the kept ones on every assembly)
        n_el = keys[0].size
        self._k_slot = np.full(keep.size, ukey.size, dtype=np.int64)
        self._k_slot[keep] = slot[:n_el]
        self._act_slots = slot[n_el:]
        self._act_h_index = np.concatenate(h_index + [np.zeros(0, dtype=np.int64)])
        self._act_h_weight = np.concatenate(h_weight + [np.zeros(0)])
        self._act_of_entry = np.concatenate(h_act + [np.zeros(0, dtype=np.int64)])
        self._k_rows = (ukey % self.n_free).astype(np.int32)
        ccount = np.bincount(ukey // self.n_free, minlength=self.n_free)
        self._k_indptr = np.concatenate([[0], np.cumsum(ccount)]).astype(np.int32)
        self._k_nnz = ukey.size

    def hessian_vector_function(self):
        """The element function of d(K_e^T lam_e)/du_e (for the NLPs' Hessians), built on first use."""
        if "hessian_vector" not in self.element_functions:
            self.element_functions.update(element_functions(self.problem.material.model, self.element))
        return self.element_functions["hessian_vector"]

    def _element_inputs(self, q: np.ndarray):
        return q[self._edofs], self._Xe, self._Ge, self._Pe

    def positions(self, q: np.ndarray) -> np.ndarray:
        """Current node positions (n, 3)."""
        return (self.X + q).reshape(-1, 3)

    def deformation_gradients(self, q: np.ndarray) -> np.ndarray:
        """F = I + du/dX at every quadrature point, (m, n_qp, 3, 3)."""
        if "_F_op" not in self.__dict__:
            # F_ij at (element e, point k) = delta_ij + sum_a q[3 node_a + i] G[e, k, a, j]: a sparse map of q
            m, nq, nn, _ = self._G_qp.shape
            e, k, a, i, j = np.meshgrid(np.arange(m), np.arange(nq), np.arange(nn), np.arange(3), np.arange(3),
                                        indexing="ij")
            rows = (((e * nq + k) * 3 + i) * 3 + j).ravel()
            cols = (3 * self.mesh.tets[e, a] + i).ravel()
            self._F_op = sp.csr_matrix((self._G_qp[e, k, a, j].ravel(), (rows, cols)), shape=(m * nq * 9, self.n_dof))
        m, nq = self._G_qp.shape[:2]
        return np.eye(3) + (self._F_op @ q).reshape(m, nq, 3, 3)

    def internal_force(self, q: np.ndarray) -> np.ndarray:
        """f_int(q) on all dofs (3n,)."""
        fe, = self._force(*self._element_inputs(q))
        return np.bincount(self._edofs.ravel(), weights=fe.ravel(), minlength=self.n_dof)

    def element_stiffness(self, q: np.ndarray) -> sp.csc_matrix:
        """df_int/dq on the free dofs."""
        ke, = self._stiff(*self._element_inputs(q))
        return self.assemble(ke)

    def assemble(self, ke: np.ndarray, actuator_weights: np.ndarray | None = None) -> sp.csc_matrix:
        """The free-dof matrix from element matrices ke (m, n_dof_e^2), plus actuator Hessian entries if
        given."""
        data = np.bincount(self._k_slot, weights=ke.ravel(), minlength=self._k_nnz + 1)[: self._k_nnz]
        if actuator_weights is not None and actuator_weights.size:
            data += np.bincount(self._act_slots, weights=actuator_weights, minlength=self._k_nnz)
        return sp.csc_matrix((data, self._k_rows, self._k_indptr), shape=(self.n_free, self.n_free))

    def actuator_states(self, q: np.ndarray) -> np.ndarray:
        """Each actuator's quantity at q (a cable's length in m), (n_u,)."""
        return self.actuator_terms(q)[0]

    def _point_hessian(self, i: int, h: np.ndarray) -> sp.csr_matrix:
        """d2Q_i/dP2 (3k x 3k) of actuator i from the stacked nonzeros ``h`` of actuator_terms."""
        sp_h = self._act[i].hessian_sparsity
        r, c = sp_h.get_triplet()
        return sp.csr_matrix((h[self._h_offsets[i]: self._h_offsets[i] + sp_h.nnz()], (r, c)),
                             shape=(sp_h.size1(), sp_h.size2()))

    def actuator_hessians(self, q: np.ndarray) -> list[sp.csc_matrix]:
        """d2Q_a/dq2 on the free dofs, one sparse matrix per actuator."""
        _, _, h = self.actuator_terms(q, hessians=True)
        return [(d.W[:, self.free].T @ self._point_hessian(i, h) @ d.W[:, self.free]).tocsc()
                for i, d in enumerate(self._act)]

    def actuator_third(self, q: np.ndarray, lam_full: np.ndarray, u: np.ndarray):
        """The actuators' share of the Hessian of lam . R over (q, u) on the free dofs: the (q, q) block
        -sum_a sign_a u_a d2(lam . dQ_a/dq)/dq2 and the (q, u) columns -sign_a d2Q_a/dq2 lam."""
        x = self.X + q
        Hqq = sp.csc_matrix((self.n_free, self.n_free))
        cols = []
        _, _, h = self.actuator_terms(q, hessians=True)
        for i, (d, ua, sa) in enumerate(zip(self._act, u, self.sign)):
            P = d.W @ x
            mu = d.W @ lam_full
            Wf = d.W[:, self.free]
            T = d.third(P, mu).sparse()
            Hqq = Hqq + (-sa * ua) * (Wf.T @ T @ Wf)
            cols.append(-sa * (Wf.T @ (self._point_hessian(i, h) @ mu)))
        return Hqq, cols

    # ------------------------------------------------------------------ the static model
    def residual(self, q: np.ndarray, u: np.ndarray, load: float = 1.0, with_scale: bool = False):
        """R(q, u) = f_int - sum_a u_a sign_a dQ_a/dq - load * F, on the free dofs.

        With ``with_scale`` also returns ||H^T u + load F|| (free dofs), the reference of the relative
        residual (plus a round-off allowance, see below), floored so that a zero load is judged absolutely.
        """
        _, dQ, _ = self.actuator_terms(q)
        ext = (dQ.T @ (-self.sign * np.asarray(u, dtype=float)) - load * self.F)[self.free]
        fe, = self._force(*self._element_inputs(q))
        R = np.bincount(self._edofs.ravel(), weights=fe.ravel(), minlength=self.n_dof)[self.free] + ext
        if with_scale:
            # 1e-6 of the unassembled element forces: the assembly's round-off (~1e-16 of them) then stays
            # far below any tolerance, even when the applied load is tiny
            return R, max(float(np.linalg.norm(ext)) + 1e-6 * float(np.linalg.norm(fe)), self.force_floor)
        return R

    def residual_and_tangent(self, q: np.ndarray, u: np.ndarray, load: float = 1.0):
        """(R, K, dR/du) on the free dofs; K = dR/dq includes the actuators' geometric stiffness."""
        u = np.asarray(u, dtype=float)
        _, dQ, h = self.actuator_terms(q, hessians=True)
        coef = -self.sign * u  # R holds -sign_a u_a dQ_a/dq
        weights = (coef[self._act_of_entry] * self._act_h_weight * h[self._act_h_index]
                   if self._act else np.zeros(0))
        inputs = self._element_inputs(q)
        fe, ke = self._force(*inputs)[0], self._stiff(*inputs)[0]
        R = (np.bincount(self._edofs.ravel(), weights=fe.ravel(), minlength=self.n_dof) + dQ.T @ coef
             - load * self.F)[self.free]
        return R, self.assemble(ke, weights), (dQ * -self.sign[:, None])[:, self.free].T

    def actuation_matrix(self, q: np.ndarray) -> np.ndarray:
        """H(q) = sign dQ/dq on the free dofs, (n_u, n_free) (a cable's row: -dL/dq)."""
        _, dQ, _ = self.actuator_terms(q)
        return (dQ * self.sign[:, None])[:, self.free]

    def residual_hessian(self, q: np.ndarray, u: np.ndarray, lam: np.ndarray):
        """Second derivatives of lam . R (lam on the free dofs): (d(K^T lam)/dq on the free dofs, sparse;
        d(K^T lam)/du = d(dR/du^T lam)/dq, dense (n_free, n_u)). K^T lam, not K lam: the corotational
        tangent is not exactly symmetric, and this is what reverse-mode AD differentiates."""
        if "_hv" not in self.__dict__:
            # "auto", not "c": a kernel too large to compile (kernels.MAX_COMPILED_CODE) runs in CasADi's VM
            # even when the others are compiled
            self._hv = ElementBatch(self.hessian_vector_function(), "casadi" if self.backend == "casadi" else "auto")
        lam_full = np.zeros(self.n_dof)
        lam_full[self.free] = lam
        he, = self._hv(*self._element_inputs(q), lam_full[self._edofs])
        Hact, cols = self.actuator_third(q, lam_full, np.asarray(u, dtype=float))
        Hqu = np.column_stack(cols) if cols else np.zeros((self.n_free, 0))
        return self.assemble(he) + Hact, Hqu

    @property
    def u_lower(self) -> np.ndarray:
        """Lower bounds of u (the box U), (n_u,)."""
        return self.u_min

    @property
    def u_upper(self) -> np.ndarray:
        """Upper bounds of u, (n_u,)."""
        return self.u_max

    @property
    def q_rest(self) -> np.ndarray:
        """The free degrees of freedom at rest (zeros, (n_free,)): a start for an NLP over q."""
        return np.zeros(self.n_free)

    def tip(self, q: np.ndarray) -> np.ndarray:
        """End-effector position p_E = C q + p_E(0)."""
        return self.C @ q + self.p0

    def full(self, q_free: np.ndarray) -> np.ndarray:
        q = np.zeros(self.n_dof)
        q[self.free] = q_free
        return q
