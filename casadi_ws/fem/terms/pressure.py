"""A pressure continuous across elements: the Taylor-Hood (P2/P1) element for nearly incompressible laws.

The elements of a ``formulation: taylor_hood`` law integrate only the isochoric part of their energy; the
volumetric part is this term's. A pressure p, linear on each 10-node tetrahedron and continuous across them,
has one unknown per corner node, and the model's energy gains (the perturbed Lagrangian, as a hybrid element)

    Pi_p(u, p) = sum_i p_i g_i(u) - sum_i c_i p_i^2 / 2,   g_i(u) = integral of N_i (J - 1),
    c_i = sum_e integral over e of N_i / K_e

(N_i the linear shape function of corner node i, K_e the element's bulk modulus; c_i is the lumped pressure
"mass", which makes the Schur complement below sparse and, as K/mu grows, changes nothing: at nu = 0.499 the
lumped and the consistent pressure mass give the same tip deflection to 0.04 %). Stationarity in p gives
p_i = g_i / c_i, a weighted mean of K (J - 1) over the corner's elements: J is constrained in the mean over
patches, not at each point, so the element does not lock.

The state holds v_i = p_i / kappa (a length; kappa = K / l, l the mean element size), so that the term's rows
are forces like every other: row i is kappa (g_i - c_i kappa v_i), and the nodal rows get sum_i p_i dg_i/du.
The tangent is symmetric: kappa dg_i/du in row and column i, -c_i kappa^2 on the diagonal. The stability test
holds the pressure at its equilibrium value given the displacements (the Schur complement
K_uu + sum_i dg_i dg_i^T / c_i: the stiffness of the displacement-only problem it stands for), so Sylvester's
law of inertia still decides.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ..elements import TET10
from ..kernels import ElementBatch
from .base import Term

__all__ = ["ContinuousPressure", "pressure_functions"]


@lru_cache(maxsize=None)
def pressure_functions() -> dict[str, ca.Function]:
    """Per-element SX functions of g_e = [integral of N_i (J - 1)] over a 10-node tetrahedron's corners i.

    Inputs: u_e (30), G_e (n_qp * 30, as the element kernels'), w (n_qp, m^3), c (4, the corner weights),
    lam (30). ``volume``: g_e (4), dg_e/du_e (4 x 30, row-major). ``stiffness``: vec of sum_i c_i d2g_i/du2
    (900). ``hessian``: vec of d(sum_i c_i d2g_i/du2 lam)/du (900) and the rows d2g_i/du2 lam (4 x 30).
    J is cubic in u, so the last is constant in F at each quadrature point."""
    el = TET10
    nd, nn, nq = el.n_dof, el.n_nodes, el.n_qp
    u, Gv, w = ca.SX.sym("u", nd), ca.SX.sym("G", nq * nd), ca.SX.sym("w", nq)
    c, lam = ca.SX.sym("c", 4), ca.SX.sym("lam", nd)
    L = np.column_stack([1.0 - el.quad_points.sum(axis=1), el.quad_points])  # corner shape functions (nq, 4)
    Fv, Lv = ca.SX.sym("F", 9), ca.SX.sym("Lam", 9)
    J = ca.det(ca.reshape(Fv, 3, 3))
    dJ = ca.gradient(J, Fv)
    fun = ca.Function("dJ", [Fv, Lv], [J, dJ, ca.hessian(J, Fv)[0], ca.hessian(ca.dot(Lv, dJ), Fv)[0]])
    from ..materials import _dF_du

    x = ca.reshape(u, 3, nn).T
    g, dg, H, T, Hl = [0] * 4, [0] * 4, 0, 0, [0] * 4
    for k in range(nq):
        G = ca.reshape(Gv[k * nd:(k + 1) * nd], 3, nn).T
        F = ca.SX.eye(3) + ca.mtimes(x.T, G)
        B = _dF_du(G)
        Jk, dJk, HJk, Tk = fun(ca.vec(F), ca.mtimes(B, lam))
        BHB = ca.mtimes(B.T, ca.mtimes(HJk, B))
        ck = sum(c[i] * L[k, i] for i in range(4))
        H += w[k] * ck * BHB
        T += w[k] * ck * ca.mtimes(B.T, ca.mtimes(Tk, B))
        for i in range(4):
            g[i] += w[k] * L[k, i] * (Jk - 1)
            dg[i] += w[k] * L[k, i] * ca.mtimes(B.T, dJk)
            Hl[i] += w[k] * L[k, i] * ca.mtimes(BHB, lam)
    vec = lambda M: ca.densify(ca.reshape(M, -1, 1))  # noqa: E731
    ins, names = [u, Gv, w], ["u", "G", "w"]
    return {
        "volume": ca.Function("tet10_pressure_volume", ins, [ca.densify(ca.vertcat(*g)), vec(ca.horzcat(*dg))],
                              names, ["g", "dg"]),
        "stiffness": ca.Function("tet10_pressure_stiffness", ins + [c], [vec(H)], names + ["c"], ["H"]),
        "hessian": ca.Function("tet10_pressure_hessian", ins + [c, lam], [vec(T), vec(ca.horzcat(*Hl))],
                               names + ["c", "lam"], ["T", "Hl"]),
    }


class ContinuousPressure(Term):
    """The pressure unknowns of the Taylor-Hood elements and their rows (see the module)."""

    name = "pressure"
    applied = False
    """Its nodal forces are internal: they do not join the applied loads in the residual's scale."""

    def __init__(self, tets: np.ndarray, edofs: np.ndarray, w: np.ndarray, G: np.ndarray, bulk: np.ndarray,
                 n_free_mech: int, backend: str = "auto"):
        self.corners, corner = np.unique(tets[:, :4], return_inverse=True)
        self.corner = corner.reshape(-1, 4)
        """(m, 4) each element's corners, as indices of the term's unknowns."""
        self.n_rows = self.negatives = self.corners.size
        self.edofs, self.w, self.G = edofs, np.ascontiguousarray(w), np.ascontiguousarray(G.reshape(len(w), -1))
        L = np.column_stack([1.0 - TET10.quad_points.sum(axis=1), TET10.quad_points])
        self.c = np.bincount(self.corner.ravel(), weights=((w @ L) / bulk[:, None]).ravel(), minlength=self.n_rows)
        """Lumped pressure mass c_i (m^3 / Pa)."""
        size = float(np.mean(np.abs(w.sum(axis=1)))) ** (1.0 / 3.0)
        self.kappa = float(bulk.max()) / size
        """p_i / v_i (Pa/m)."""
        self.n_free_mech = n_free_mech
        self._backend = backend
        self._kernels = {}

    def _kernel(self, name):
        if name not in self._kernels:
            self._kernels[name] = ElementBatch(pressure_functions()[name], self._backend)
        return self._kernels[name]

    def pressures(self, q) -> np.ndarray:
        """p at the corner nodes (Pa)."""
        return self.kappa * q[self.state]

    def setup(self, model, pos):
        self._ed = pos[self.edofs]

    def pattern(self, model, pos):
        ed = self._ed
        n = model.n_free
        nd = ed.shape[1]
        a, b = np.meshgrid(np.arange(nd), np.arange(nd), indexing="ij")  # vec column-major: entry (a, b) at b nd + a
        rows, cols = ed[:, a.T.ravel()], ed[:, b.T.ravel()]
        self._uu = (rows >= 0) & (cols >= 0)
        j = self.rows.start + np.repeat(self.corner, nd, axis=1)  # (m, 4 nd): corner i, dof a at i nd + a
        e = np.tile(ed, (1, 4))
        self._uv = e >= 0
        jj = self.rows.start + np.arange(self.n_rows)
        self._keys = np.concatenate([cols[self._uu] * n + rows[self._uu], j[self._uv] * n + e[self._uv],
                                     e[self._uv] * n + j[self._uv], jj * n + jj])
        return self._keys

    def residual(self, model, q, u, R):
        ue = q[self.edofs]
        g, dg = self._kernel("volume")(ue, self.G, self.w)
        p = self.pressures(q)
        f = np.einsum("mi,mia->ma", p[self.corner], dg.reshape(-1, 4, self.edofs.shape[1]))
        keep = self._ed >= 0
        R += np.bincount(self._ed[keep], weights=f[keep], minlength=R.size)
        gi = np.bincount(self.corner.ravel(), weights=g.ravel(), minlength=self.n_rows)
        R[self.rows] = self.kappa * (gi - self.c * p)
        return ue, dg, p

    def tangent(self, model, cache):
        ue, dg, p = cache
        H, = self._kernel("stiffness")(ue, self.G, self.w, p[self.corner])
        kdg = self.kappa * dg[self._uv]
        return self._keys, np.concatenate([H[self._uu], kdg, kdg, -self.c * self.kappa**2])

    def volume_gradients(self, model, q) -> sp.csr_matrix:
        """dg_i/du on the nodal free dofs, (n_rows, n_free_mech)."""
        _, dg = self._kernel("volume")(q[self.edofs], self.G, self.w)
        j = np.repeat(self.corner, self.edofs.shape[1], axis=1)
        e = np.tile(self._ed, (1, 4))
        keep = e >= 0
        return sp.csr_matrix((dg[keep], (j[keep], e[keep])), shape=(self.n_rows, self.n_free_mech))

    def held(self, model, q, u):
        """The Schur complement's share: sum_i dg_i dg_i^T / c_i (the pressure follows the displacements)."""
        D = self.volume_gradients(model, q)
        return (D.T @ sp.diags(1.0 / self.c) @ D).tocsc()

    def hessian(self, model, q, u, lam):
        """Second derivatives of lam . R: (u, u) sum_i p_i d(d2g_i lam_u)/du + kappa lam_i d2g_i; (u, v_i)
        kappa d2g_i lam_u; (v, v) none (the rows are linear in v)."""
        n, nd = model.n_free, self.edofs.shape[1]
        ue = q[self.edofs]
        lam_full = np.zeros(model.n_dof)
        lam_full[model.free] = lam
        T, Hl = self._kernel("hessian")(ue, self.G, self.w, self.pressures(q)[self.corner], lam_full[self.edofs])
        H, = self._kernel("stiffness")(ue, self.G, self.w, self.kappa * lam[self.rows][self.corner])
        khl = self.kappa * Hl.reshape(-1, 4, nd).reshape(len(ue), -1)[self._uv]
        vals = np.concatenate([(T + H)[self._uu], khl, khl, np.zeros(self.n_rows)])
        k = self._keys
        return sp.csc_matrix((vals, (k % n, k // n)), shape=(n, n))
