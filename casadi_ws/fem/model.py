"""The static FEM model of a cable-driven soft robot: residual, tangent stiffness, and their derivatives.

    R(q, u) = f_int(q) - H(q)^T u - F = 0,        H = -dL/dq,    p_E = C q + p_E(0)

q is the vector of nodal displacements (3n, node-major; fixed dofs stay 0), u the cable tensions. The
element laws come from :mod:`casadi_ws.fem.materials` (CasADi SX, one graph per element) and are evaluated over
the mesh by :class:`casadi_ws.fem.kernels.ElementBatch`; assembly uses index maps fixed once per mesh. All matrices
returned here are restricted to the free dofs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..actuation.cable import cable_length_function
from .kernels import ElementBatch
from .materials import element_functions, rest_geometry
from .mesh import embed

__all__ = ["StaticModel"]


@dataclass
class _CableData:
    W: sp.csr_matrix  # (3k x 3n) passage point positions = W @ x
    pull: np.ndarray
    fun: object


class StaticModel:
    """Numeric static model of a :class:`casadi_ws.io.problem.Problem`."""

    def __init__(self, problem, backend: str = "auto"):
        self.problem = problem
        mesh = problem.mesh
        self.mesh = mesh
        self.n_nodes = mesh.n_nodes
        self.n_dof = 3 * mesh.n_nodes
        fixed = np.zeros(mesh.n_nodes, dtype=bool)
        fixed[np.asarray(problem.fixed_nodes, dtype=np.int64)] = True
        self.fixed_nodes = np.flatnonzero(fixed)
        self.free = np.flatnonzero(np.repeat(~fixed, 3))
        self.n_free = self.free.size
        self.X = mesh.nodes.reshape(-1).copy()

        # --- elements
        mat = problem.material
        Xe = mesh.nodes[mesh.tets]
        V0, G = rest_geometry(Xe)
        mu, lam = mat.lame
        self._Xe = (Xe - Xe[:, :1]).reshape(-1, 12)  # element-local: see material's note on round-off
        self._Ge = G.reshape(-1, 12)
        self._Pe = np.column_stack([V0, np.full(V0.size, mu), np.full(V0.size, lam)])
        funs = element_functions(mat.model)
        self.element_functions = funs
        self._force = ElementBatch(funs["force"], backend)
        self._stiff = ElementBatch(funs["stiffness"], backend)
        self.backend = self._force.backend
        self._edofs = (3 * mesh.tets[:, :, None] + np.arange(3)[None, None, :]).reshape(-1, 12)

        # --- loads: lumped gravity and point loads on embedded points
        F = np.zeros(self.n_dof)
        g = np.asarray(problem.gravity, dtype=float)
        if np.any(g):
            nodal = (mat.density * V0 / 4.0)[:, None] * g[None, :]
            for a in range(4):
                np.add.at(F.reshape(-1, 3), mesh.tets[:, a], nodal)
        for point, force in problem.point_loads:
            W = embed(mesh, np.asarray(point)[None]).matrix(mesh)
            F += W.T @ np.asarray(force, dtype=float)
        self.F = F

        # --- cables
        self.cables: list[_CableData] = []
        for c in problem.cables:
            emb = embed(mesh, np.asarray(c.points, dtype=float))
            pull = np.zeros(3) if c.pull_point is None else np.asarray(c.pull_point, dtype=float)
            fun = cable_length_function(len(c.points), c.pull_point is not None)
            self.cables.append(_CableData(emb.matrix(mesh), pull, fun))
        self.n_u = len(self.cables)
        self.u_min = np.array([c.u_min for c in problem.cables], dtype=float)
        self.u_max = np.array([c.u_max for c in problem.cables], dtype=float)
        self._build_cables()
        self._build_pattern()

        # --- end-effector: p_E = C q + p_E(0)
        ee = np.atleast_2d(np.asarray(problem.end_effector, dtype=float))
        self.C = embed(mesh, ee).matrix(mesh).tocsr()
        self.p0 = self.C @ self.X
        self.C_free = self.C[:, self.free].tocsc()

        # force scale under which a residual counts as zero (loads of exactly 0 give q = 0 exactly)
        self.force_floor = 1e-12 * mat.young_modulus * mesh.characteristic_length() ** 2

    # ------------------------------------------------------------------ assembly
    def _build_cables(self):
        """All cables in one CasADi call (a call costs ~0.1 ms of overhead, a residual ~1 ms in all)."""
        import casadi as ca

        sizes = [c.W.shape[0] for c in self.cables]
        self._W_all = sp.vstack([c.W for c in self.cables]).tocsr() if self.cables else None
        self._W_all_T = self._W_all.T.tocsr() if self.cables else None
        self._g_rows = np.arange(sum(sizes))
        self._g_cols = np.repeat(np.arange(self.n_u), sizes)
        self._h_offsets = np.cumsum([0] + [k * k for k in sizes])[:-1]
        Ps = [ca.SX.sym(f"P{i}", k) for i, k in enumerate(sizes)]
        outs = [c.fun(P, ca.DM(c.pull)) for P, c in zip(Ps, self.cables)]
        P = ca.vertcat(*Ps) if Ps else ca.SX(0, 1)
        L, g = ca.vertcat(*[o[0] for o in outs]), ca.vertcat(*[o[1] for o in outs])
        h = ca.vertcat(*[ca.vec(o[2]) for o in outs])  # symmetric: column-major = row-major
        self._cables_lg = ca.Function("cables", [P], [L, g])
        self._cables_lgh = ca.Function("cables_h", [P], [L, g, h])

    def _cable_terms(self, q: np.ndarray, hessians: bool = False):
        """L (n_u,), dL/dq (n_u, 3n) and, if asked, the stacked Hessians of all cables (vec'd)."""
        if not self.cables:
            return np.zeros(0), np.zeros((0, self.n_dof)), np.zeros(0)
        P = self._W_all @ (self.X + q)
        out = (self._cables_lgh if hessians else self._cables_lg)(P)
        G = np.zeros((self._g_rows.size, self.n_u))
        G[self._g_rows, self._g_cols] = np.asarray(out[1]).ravel()
        dL = (self._W_all_T @ G).T
        return np.asarray(out[0]).ravel(), dL, (np.asarray(out[2]).ravel() if hessians else None)

    def _build_pattern(self):
        """Index maps from element stiffness entries and cable-length Hessian entries to the CSC data of K
        on the free dofs (one pattern for both, so assembling K is a single bincount)."""
        pos = -np.ones(self.n_dof, dtype=np.int64)
        pos[self.free] = np.arange(self.n_free)
        ed = pos[self._edofs]  # (m, 12), -1 for fixed
        # element matrix is vec'ed column-major: entry (a, b) at index b * 12 + a
        j = np.arange(144)
        rows, cols = ed[:, j % 12].ravel(), ed[:, j // 12].ravel()
        keep = (rows >= 0) & (cols >= 0)
        keys = [cols[keep] * self.n_free + rows[keep]]
        # cable c adds u_c W^T h_c W (h_c: Hessian of its length in its passage points, 3k x 3k, stored
        # after the previous cables' in the stacked vector of _cable_terms): every pair of nonzeros of W
        # contributes h_c[a1, a2] w1 w2 to K[i1, i2]
        h_index, h_weight, h_cable = [], [], []
        for i, c in enumerate(self.cables):
            Wf = c.W[:, self.free].tocoo()
            e1, e2 = np.meshgrid(np.arange(Wf.nnz), np.arange(Wf.nnz), indexing="ij")
            e1, e2 = e1.ravel(), e2.ravel()
            near = np.abs(Wf.row[e1] // 3 - Wf.row[e2] // 3) <= 1  # a chain's length couples neighbours only
            e1, e2 = e1[near], e2[near]
            h_index.append(self._h_offsets[i] + Wf.row[e1] * c.W.shape[0] + Wf.row[e2])
            h_weight.append(Wf.data[e1] * Wf.data[e2])
            h_cable.append(np.full(e1.size, i))
            keys.append(Wf.col[e2].astype(np.int64) * self.n_free + Wf.col[e1])
        ukey, slot = np.unique(np.concatenate(keys), return_inverse=True)
        # every element entry has a slot; those of fixed dofs go to one past the end, cut off after the
        # bincount (cheaper than gathering the kept ones on every assembly)
        n_el = keys[0].size
        self._k_slot = np.full(keep.size, ukey.size, dtype=np.int64)
        self._k_slot[keep] = slot[:n_el]
        self._cable_slots = slot[n_el:]
        self._cable_h_index = np.concatenate(h_index + [np.zeros(0, dtype=np.int64)])
        self._cable_h_weight = np.concatenate(h_weight + [np.zeros(0)])
        self._cable_of_entry = np.concatenate(h_cable + [np.zeros(0, dtype=np.int64)])
        self._k_rows = (ukey % self.n_free).astype(np.int32)
        ccount = np.bincount(ukey // self.n_free, minlength=self.n_free)
        self._k_indptr = np.concatenate([[0], np.cumsum(ccount)]).astype(np.int32)
        self._k_nnz = ukey.size

    def _element_inputs(self, q: np.ndarray):
        return q[self._edofs], self._Xe, self._Ge, self._Pe

    def positions(self, q: np.ndarray) -> np.ndarray:
        """Current node positions (n, 3)."""
        return (self.X + q).reshape(-1, 3)

    def internal_force(self, q: np.ndarray) -> np.ndarray:
        """f_int(q) on all dofs (3n,)."""
        fe, = self._force(*self._element_inputs(q))
        return np.bincount(self._edofs.ravel(), weights=fe.ravel(), minlength=self.n_dof)

    def element_stiffness(self, q: np.ndarray) -> sp.csc_matrix:
        """df_int/dq on the free dofs."""
        ke, = self._stiff(*self._element_inputs(q))
        return self.assemble(ke)

    def assemble(self, ke: np.ndarray, cable_weights: np.ndarray | None = None) -> sp.csc_matrix:
        """The free-dof matrix from element matrices ke (m, 144), plus cable Hessian entries if given."""
        data = np.bincount(self._k_slot, weights=ke.ravel(), minlength=self._k_nnz + 1)[: self._k_nnz]
        if cable_weights is not None and cable_weights.size:
            data += np.bincount(self._cable_slots, weights=cable_weights, minlength=self._k_nnz)
        return sp.csc_matrix((data, self._k_rows, self._k_indptr), shape=(self.n_free, self.n_free))

    def cable_lengths(self, q: np.ndarray, hessians: bool = False):
        """L (n_u,), dL/dq (n_u, 3n) and, if asked, the list of d2L/dq2 on the free dofs."""
        L, dL, h = self._cable_terms(q, hessians)
        if not hessians:
            return L, dL
        H2 = []
        for i, c in enumerate(self.cables):
            k = c.W.shape[0]
            hi = h[self._h_offsets[i]: self._h_offsets[i] + k * k].reshape(k, k)
            Wf = c.W[:, self.free]
            H2.append((Wf.T @ sp.csr_matrix(hi) @ Wf).tocsc())
        return L, dL, H2

    # ------------------------------------------------------------------ the static model
    def residual(self, q: np.ndarray, u: np.ndarray, load: float = 1.0, with_scale: bool = False):
        """R(q, u) = f_int + sum_c u_c dL_c/dq - load * F, on the free dofs.

        With ``with_scale`` also returns ||H^T u + load F|| (free dofs), the reference of the relative
        residual (plus a round-off allowance, see below), floored so that a zero load is judged absolutely.
        """
        _, dL = self.cable_lengths(q)
        ext = (dL.T @ np.asarray(u, dtype=float) - load * self.F)[self.free]
        fe, = self._force(*self._element_inputs(q))
        R = np.bincount(self._edofs.ravel(), weights=fe.ravel(), minlength=self.n_dof)[self.free] + ext
        if with_scale:
            # 1e-6 of the unassembled element forces: the assembly's round-off (~1e-16 of them) then stays
            # far below any tolerance, even when the applied load is tiny
            return R, max(float(np.linalg.norm(ext)) + 1e-6 * float(np.linalg.norm(fe)), self.force_floor)
        return R

    def residual_and_tangent(self, q: np.ndarray, u: np.ndarray, load: float = 1.0):
        """(R, K, dR/du) on the free dofs; K = dR/dq includes the cables' geometric stiffness."""
        u = np.asarray(u, dtype=float)
        _, dL, h = self._cable_terms(q, hessians=True)
        weights = (u[self._cable_of_entry] * self._cable_h_weight * h[self._cable_h_index]
                   if self.cables else np.zeros(0))
        inputs = self._element_inputs(q)
        fe, ke = self._force(*inputs)[0], self._stiff(*inputs)[0]
        R = (np.bincount(self._edofs.ravel(), weights=fe.ravel(), minlength=self.n_dof) + dL.T @ u
             - load * self.F)[self.free]
        return R, self.assemble(ke, weights), dL[:, self.free].T

    def actuation_matrix(self, q: np.ndarray) -> np.ndarray:
        """H(q) = -dL/dq on the free dofs, (n_u, n_free)."""
        _, dL = self.cable_lengths(q)
        return -dL[:, self.free]

    def tip(self, q: np.ndarray) -> np.ndarray:
        """End-effector position p_E = C q + p_E(0)."""
        return self.C @ q + self.p0

    def full(self, q_free: np.ndarray) -> np.ndarray:
        q = np.zeros(self.n_dof)
        q[self.free] = q_free
        return q
