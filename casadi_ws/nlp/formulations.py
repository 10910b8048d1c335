"""NLP formulations over the static model, solved by IPOPT with exact derivatives.

The full-space problem has variables x = (q_free, u) and parameters p (here: a target):

    min_x  || C q + p_E(0) - target ||^2      s.t.  R(q, u) = 0,   u_min <= u <= u_max

CasADi's ``nlpsol`` would build the gradient, constraint Jacobian and Lagrangian Hessian by AD through the
whole mesh (about 1 s per Hessian on the trunk). Instead they are supplied as CasADi Callbacks that call the
model, which assembles them from the compiled per-element functions:

    dR/dq      = K (element stiffness - sum_a sign_a u_a d2Q_a)     the Newton tangent
    dR/du_a    = -sign_a dQ_a/dq                                  (a cable: sign -1, Q = its length)
    d2(lam.R)  = sum_e d(K_e^T lam_e)/dq_e  -  sum_a sign_a u_a d2(lam . dQ_a)/dq2      (q, q)
                 -sign_a d2Q_a lam                                                (q, u_a)

the actuators' terms derived by CasADi from each actuator's quantity (:mod:`casadi_ws.actuation`).

The same pieces (:class:`FullSpaceNLP`) serve every formulation. :class:`TrackingNLP` is the one in use:
the backward problem (8) of the forward-backward method is its one-point case, and inverse control
(:mod:`casadi_ws.control.inverse`) adds points, a regularisation and limits on the change of u. Adding an objective
term means adding its value and gradient in ``grad_f`` and its Hessian in ``hess_lag``; adding a constraint
means appending rows to ``g`` and ``jac_g`` and its multiplier's Hessian to ``hess_lag`` (see
docs/nlp-library.md).
"""

from __future__ import annotations

import contextlib
import gc
import os
import sys

import numpy as np
import scipy.sparse as sp

import casadi as ca

from ..fem.kernels import ElementBatch

__all__ = ["FullSpaceNLP", "TrackingNLP", "quiet_stdout", "release_solvers"]

IPOPT_OPTIONS = {
    # measured on the backward problem: gradient scaling quadruples the iterations from a warm start
    "ipopt.nlp_scaling_method": "none",
    "ipopt.mu_strategy": "adaptive",
    "ipopt.warm_start_init_point": "yes",
    "ipopt.mu_init": 1e-6,
    "ipopt.warm_start_bound_push": 1e-9,
    "ipopt.warm_start_mult_bound_push": 1e-9,
    "ipopt.tol": 1e-10,
    "ipopt.constr_viol_tol": 1e-10,
    "ipopt.max_iter": 100,
    "ipopt.print_level": 0,
    "ipopt.sb": "yes",
    "print_time": False,
    "calc_lam_p": False,  # multipliers of the parameters would need AD through the callbacks
    "no_nlp_grad": True,
}


def _pattern(M: sp.spmatrix) -> ca.Sparsity:
    M = M.tocsc()
    M.sort_indices()
    return ca.Sparsity(M.shape[0], M.shape[1], M.indptr.tolist(), M.indices.tolist())


class _Values:
    """Scatter a scipy matrix onto a fixed CSC pattern (entries outside it must be zero)."""

    def __init__(self, pattern: sp.csc_matrix):
        P = pattern.tocsc()
        P.sort_indices()
        self.shape = P.shape
        self.rows = P.indices.copy()
        self.cols = np.repeat(np.arange(P.shape[1]), np.diff(P.indptr))
        self.sparsity = _pattern(P)

    def __call__(self, M) -> ca.DM:
        vals = np.asarray(sp.csr_matrix(M)[self.rows, self.cols]).ravel()
        return ca.DM(self.sparsity, vals)


class FullSpaceNLP:
    """Derivative pieces of the static model over x = (q_free, u) (see the module docstring)."""

    def __init__(self, model):
        self.model = model
        m = model
        self.nq, self.nu = m.n_free, m.n_u
        self.nx = self.nq + self.nu
        self._hv = ElementBatch(m.hessian_vector_function(), m.backend)
        rng = np.random.default_rng(0)
        q = m.full(rng.normal(size=self.nq) * 1e-6)
        u = np.ones(self.nu)
        lam = rng.normal(size=self.nq)
        _, K, dRdu = m.residual_and_tangent(q, u)
        self.jac_pattern = sp.hstack([abs(K) + 1.0 * (K != 0), sp.csc_matrix(np.ones_like(dRdu))]).tocsc()
        H = self.hessian(q, u, lam, 1.0)
        H = abs(H) + (H != 0) + sp.csc_matrix(([1.0] * self.nx, (range(self.nx), range(self.nx))),
                                              shape=(self.nx, self.nx))
        self.hess_pattern = sp.triu(H).tocsc()
        self.jac_values = _Values(self.jac_pattern)
        self.hess_values = _Values(self.hess_pattern)

    def split(self, x):
        x = np.asarray(x, dtype=float).ravel()
        return self.model.full(x[:self.nq]), x[self.nq:]

    def jacobian(self, q, u) -> sp.csc_matrix:
        _, K, dRdu = self.model.residual_and_tangent(q, u)
        return sp.hstack([K, sp.csc_matrix(dRdu)]).tocsc()

    def hessian(self, q, u, lam_g, lam_f, objective_hessian=None) -> sp.csc_matrix:
        """Hessian of lam_f * f + lam_g . R over x (full, symmetric)."""
        m = self.model
        lam = np.zeros(m.n_dof)
        lam[m.free] = lam_g
        ue, Xe, Ge, Pe = m._element_inputs(q)
        he, = self._hv(ue, Xe, Ge, Pe, lam[m._edofs])
        Hqq = m.assemble(he)
        Hqq = 0.5 * (Hqq + Hqq.T)
        Hact, cols = m.actuator_third(q, lam, u)
        Hqq = Hqq + Hact
        if objective_hessian is not None:
            Hqq = Hqq + lam_f * objective_hessian
        Hqu = sp.csc_matrix(np.column_stack(cols)) if cols else sp.csc_matrix((self.nq, 0))
        return sp.bmat([[Hqq, Hqu], [Hqu.T, None]], format="csc") if self.nu else Hqq.tocsc()


class _Fn(ca.Callback):
    """A CasADi Callback around a Python function of numpy arrays with fixed output sparsities."""

    def __init__(self, name, ins, outs, fn):
        ca.Callback.__init__(self)
        self._ins, self._outs, self._fn = ins, outs, fn
        self.construct(name, {})

    def get_n_in(self):
        return len(self._ins)

    def get_n_out(self):
        return len(self._outs)

    def get_name_in(self, i):
        return self._ins[i][0]

    def get_name_out(self, i):
        return self._outs[i][0]

    def get_sparsity_in(self, i):
        return self._ins[i][1]

    def get_sparsity_out(self, i):
        return self._outs[i][1]

    def eval(self, arg):
        return self._fn(*[np.asarray(a.full()) for a in arg])


class TrackingNLP:
    """IPOPT over (q, u): min sum_i w_i |p_i(q) - t_i|^2 + rho |u - u_ref|^2 s.t. R(q, u) = 0, u in bounds.

    ``points`` are rest positions of embedded points (default: the end-effector alone); their targets t_i
    and the reference u_ref are parameters, so one solver serves a whole sequence of targets with warm
    starts. ``rho`` (m^2/N^2) is a small regularisation preferring low tensions (u_ref = 0) or small
    changes (u_ref = previous u). Bounds on u can be tightened per solve (e.g. a limit on the change of u).
    Built once per model: building costs about one Hessian evaluation.
    """

    def __init__(self, model, points=None, weights=None, rho: float = 0.0):
        from ..fem.mesh import embed

        self.model = model
        self.pieces = pieces = FullSpaceNLP(model)
        nx, nq, nu = pieces.nx, pieces.nq, pieces.nu
        if points is None:
            Cs = [model.C_free]
            p0s = [model.p0]
        else:
            pts = np.atleast_2d(np.asarray(points, dtype=float))
            Cs, p0s = [], []
            for pt in pts:
                W = embed(model.mesh, pt[None]).matrix(model.mesh).tocsr()
                Cs.append(W[:, model.free].tocsc())
                p0s.append(W @ model.X)
        w = np.ones(len(Cs)) if weights is None else np.asarray(weights, dtype=float)
        self.n_points = len(Cs)
        C = sp.vstack(Cs).tocsc()
        p0 = np.concatenate(p0s)
        W = np.repeat(w, 3)
        self._objective_hessian = (2.0 * C.T @ sp.diags(W) @ C).tocsc()
        self.rho = float(rho)
        dense = ca.Sparsity.dense
        n_p = 3 * self.n_points + nu

        def parts(x, p):
            x = np.asarray(x, float).ravel()
            p = np.asarray(p, float).ravel()
            qf, u = x[:nq], x[nq:]
            e = C @ qf + p0 - p[:3 * self.n_points]
            du = u - p[3 * self.n_points:]
            return qf, u, e, du

        def f_and_g(x, p):
            qf, u, e, du = parts(x, p)
            q = model.full(qf)
            f = float(e @ (W * e)) + self.rho * float(du @ du) + float(self.extra_value(q, u))
            return [ca.DM(f), ca.DM(model.residual(q, u))]

        def grad_f(x, p):
            qf, u, e, du = parts(x, p)
            q = model.full(qf)
            f = float(e @ (W * e)) + self.rho * float(du @ du) + float(self.extra_value(q, u))
            g = np.concatenate([2.0 * (C.T @ (W * e)), 2.0 * self.rho * du]) + self.extra_gradient(q, u)
            return [ca.DM(f), ca.DM(g)]

        def jac_g(x, p):
            q, u = pieces.split(x)
            return [ca.DM(model.residual(q, u)), pieces.jac_values(pieces.jacobian(q, u))]

        def hess_lag(x, p, lam_f, lam_g):
            q, u = pieces.split(x)
            lf = float(np.asarray(lam_f).ravel()[0])
            H = pieces.hessian(q, u, np.asarray(lam_g).ravel(), lf, self._objective_hessian)
            if self.rho and nu:
                H = H + sp.diags(np.concatenate([np.zeros(nq), np.full(nu, 2.0 * self.rho * lf)]))
            extra = self.extra_hessian(q, u)
            if extra is not None:
                H = H + lf * extra
            return [self.hess_values(sp.triu(H))]

        # the Hessian's sparsity is fixed before the first solve: include the extra term's pattern
        rng = np.random.default_rng(1)
        q_probe = model.full(rng.normal(size=nq) * 1e-6)
        extra = self.extra_hessian(q_probe, np.ones(nu))
        pattern = pieces.hess_pattern
        if extra is not None:
            pattern = (abs(pattern) + sp.triu(abs(extra) + (extra != 0))).tocsc()
        self.hess_values = _Values(pattern)

        xs, ps = ("x", dense(nx, 1)), ("p", dense(n_p, 1))
        self._cbs = [
            _Fn("nlp", [xs, ps], [("f", dense(1, 1)), ("g", dense(nq, 1))], f_and_g),
            _Fn("grad_f", [xs, ps], [("f", dense(1, 1)), ("grad_f_x", dense(nx, 1))], grad_f),
            _Fn("jac_g", [xs, ps], [("g", dense(nq, 1)), ("jac_g_x", pieces.jac_values.sparsity)], jac_g),
            _Fn("hess_lag", [xs, ps, ("lam_f", dense(1, 1)), ("lam_g", dense(nq, 1))],
                [("hess_gamma_x_x", self.hess_values.sparsity)], hess_lag),
        ]
        opts = dict(IPOPT_OPTIONS, grad_f=self._cbs[1], jac_g=self._cbs[2], hess_lag=self._cbs[3])
        self.solver = ca.nlpsol("tracking", "ipopt", self._cbs[0], opts)
        self.lam_g = np.zeros(nq)

    # hooks for further objective terms (see docs/nlp-library.md); q is the full displacement vector
    def extra_value(self, q, u) -> float:
        return 0.0

    def extra_gradient(self, q, u) -> np.ndarray:
        return np.zeros(self.pieces.nx)

    def extra_hessian(self, q, u):
        """Hessian over x = (q_free, u) of the extra term (sparse), or None."""
        return None

    def solve(self, targets, q, u, u_ref=None, u_lower=None, u_upper=None):
        """Warm-started solve; returns (q_full, u, IPOPT stats). ``targets``: (n_points, 3)."""
        m = self.model
        nq = self.pieces.nq
        lbu = m.u_min if u_lower is None else np.maximum(m.u_min, u_lower)
        ubu = m.u_max if u_upper is None else np.minimum(m.u_max, u_upper)
        u0 = np.clip(u, lbu, ubu)
        p = np.concatenate([np.asarray(targets, float).ravel(),
                            np.zeros(m.n_u) if u_ref is None else np.asarray(u_ref, float)])
        with quiet_stdout():
            sol = self.solver(x0=np.concatenate([q[m.free], u0]), p=p,
                              lbx=np.concatenate([np.full(nq, -np.inf), lbu]),
                              ubx=np.concatenate([np.full(nq, np.inf), ubu]), lbg=0, ubg=0, lam_g0=self.lam_g)
        stats = self.solver.stats()
        x = np.asarray(sol["x"]).ravel()
        if stats.get("success"):
            self.lam_g = np.asarray(sol["lam_g"]).ravel()
        q_new, u_new = self.pieces.split(x)
        return q_new, np.clip(u_new, lbu, ubu), stats


_SOLVERS: dict[int, TrackingNLP] = {}


@contextlib.contextmanager
def quiet_stdout():
    """Silence the C-level stdout (MUMPS prints 'Entering DMUMPS ... JOB=-2' when a solver is destroyed)."""
    sys.stdout.flush()
    saved = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)


def release_solvers() -> None:
    """Destroy the cached IPOPT solvers now, without MUMPS's farewell on stdout."""
    with quiet_stdout():
        _SOLVERS.clear()
        gc.collect()


