"""The static model as CasADi Functions: write your own problems over the equilibria in plain CasADi.

    R = residual_function(model)      R(q, u) = f_int(q) - H(q)^T u - F   (q: the free dofs, u: all inputs)
    p = point_function(model)         p(q) = positions of the end-effector (or of any embedded points), 3 x k

``R`` is a :class:`casadi.Callback` that evaluates the model (compiled per-element SX functions, sparse
assembly) and tells CasADi everything it needs to differentiate it exactly:

- its Jacobian ``[K, dR/du]`` with the true sparsity (``get_jac_sparsity``) and as a Function
  (``get_jacobian``), so ``casadi.jacobian``, ``nlpsol``'s constraint Jacobian and ``rootfinder`` see the
  assembled tangent;
- its reverse mode (``get_reverse``): the vector-Jacobian product ``(K^T lam, dR/du^T lam)``, itself a
  Callback whose Jacobian is the Hessian of ``lam . R`` (element Hessian-vector functions and the
  actuators' third derivatives), so IPOPT gets exact Hessians of the Lagrangian.

AD through a mapped whole-mesh graph would give the same numbers at ~1 s per Hessian on the trunk; this
costs about one assembly. The Callbacks live as long as the model (they are cached on it): a CasADi
Function built on ``R`` stays valid while the model object does. ``p`` is linear in q and is an ordinary
SX Function.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.sparse as sp


__all__ = ["point_function", "quantity_function", "residual_function"]


class _Pattern:
    """A CasADi sparsity with the (row, col) of each of its nonzeros, to fill it from numpy."""

    def __init__(self, shape, rows, cols):
        rows, cols = np.asarray(rows, dtype=np.int64), np.asarray(cols, dtype=np.int64)
        order = np.lexsort((rows, cols))
        self.rows, self.cols = rows[order], cols[order]
        self.shape = tuple(shape)
        indptr = np.concatenate([[0], np.cumsum(np.bincount(self.cols, minlength=shape[1]))])
        self.sparsity = ca.Sparsity(shape[0], shape[1], indptr.tolist(), self.rows.tolist())
        self.indptr = indptr

    def transpose(self) -> "_Pattern":
        return _Pattern(self.shape[::-1], self.cols, self.rows)

    def gather(self, M: np.ndarray) -> np.ndarray:
        return M[self.rows, self.cols]

    def stacked(self, n: int) -> tuple[ca.Sparsity, np.ndarray]:
        """The pattern of n copies stacked vertically, and where nonzero e of copy k goes in its data."""
        sizes = np.diff(self.indptr)
        e = np.arange(self.rows.size)
        k = np.arange(n)[:, None]
        where = self.indptr[self.cols][None, :] * n + k * sizes[self.cols][None, :] + (e - self.indptr[self.cols])
        return ca.vertcat(*[self.sparsity] * n), where


class _Callback(ca.Callback):
    """A CasADi Function evaluated by ``fn(args, wanted) -> outputs`` on the nonzeros, numpy in and out.

    ``jacobian`` (a function returning the Jacobian Callback), ``jac_sparsity(oind, iind)`` and
    ``reverse(nadj)`` are optional. Derived Callbacks are kept referenced here: CasADi does not own them.
    """

    def __init__(self, name, ins, outs, fn, jacobian=None, jac_sparsity=None, reverse=None):
        ca.Callback.__init__(self)
        self._ins, self._outs, self._fn = ins, outs, fn
        self._jacobian, self._jac_sparsity, self._reverse = jacobian, jac_sparsity, reverse
        self._children = []
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

    def has_eval_buffer(self):
        return True

    def eval_buffer(self, arg, res):
        args = [np.frombuffer(a, dtype=float) if a is not None else None for a in arg]
        wanted = [r is not None and r.nbytes > 0 for r in res]
        outs = self._fn(args, wanted)
        for r, w, o in zip(res, wanted, outs):
            if w:
                np.frombuffer(r, dtype=float)[:] = o
        return 0

    def has_jacobian(self):
        return self._jacobian is not None

    def get_jacobian(self, name, inames, onames, opts):
        cb = self._jacobian(name)
        self._children.append(cb)
        return cb

    def has_jac_sparsity(self, oind, iind):
        return self._jac_sparsity is not None

    def get_jac_sparsity(self, oind, iind, symmetric):
        return self._jac_sparsity(oind, iind)

    def has_reverse(self, nadj):
        return self._reverse is not None

    def get_reverse(self, nadj, name, inames, onames, opts):
        cb = self._reverse(nadj, name)
        self._children.append(cb)
        return cb


class _ResidualFunctions:
    """Patterns and numeric pieces behind R, its Jacobian, its VJP and the VJP's Jacobian."""

    def __init__(self, model, with_load: bool):
        self.m = m = model
        self.with_load = with_load
        n, nu = m.n_free, m.n_u
        keys = m.pattern_keys()  # sorted column * n + row: K's CSC order
        self.version = m.pattern_version
        rows, cols = keys % n, keys // n
        self.K = _Pattern((n, n), rows, cols)
        # dR/du_a is nonzero where the terms say: the free dofs that move actuator a's points, or a prescribed
        # quantity's own equation
        du = {}
        for t in m.terms:
            du.update(t.input_pattern(m) or {})
        cat = lambda parts: np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)  # noqa: E731
        self.dRdu = _Pattern((n, nu), cat([du[a] for a in sorted(du)]),
                             cat([np.full(du[a].size, a) for a in sorted(du)]))
        # d(K^T lam)/dq: K's pattern and what the terms add beyond it (the actuators' third derivatives, the
        # prescribed quantities' couplings of their dofs)
        hr, hc = [rows], [cols]
        for t in m.terms:
            r, c = t.hessian_pattern(m)
            hr.append(r)
            hc.append(c)
        keys = np.unique(np.concatenate(hc) * n + np.concatenate(hr))
        self.H = _Pattern((n, n), keys % n, keys // n)
        self._h_keys = keys

    # ------------------------------------------------------------------ numeric pieces (free-dof vectors in)
    def full(self, q):
        return self.m.full(q)

    def load(self, args):
        return float(args[2][0]) if self.with_load else 1.0

    def residual(self, args, wanted):
        return [self.m.residual(self.full(args[0]), args[1], self.load(args))]

    def tangent(self, q, u, load):
        _, K, dRdu = self.m.residual_and_tangent(self.full(q), u, load)
        self.current()
        return K, dRdu

    def current(self):
        """Refuses to go on where the model's pattern grew since these Functions declared it (self-contact
        found as the body moves, at a state with pairs it had not met): a Jacobian on the old pattern would
        drop entries."""
        if self.m.pattern_version != self.version:
            from .spec import ModelError

            raise ModelError("the model's sparsity pattern grew since this CasADi Function was built (self_contact: "
                             "auto met new pairs of its boundary): build the Function again at this state")

    def hessian_values(self, q, u, lam):
        """Nonzeros of d(K^T lam)/dq on the pattern H, and d(K^T lam)/du (dense)."""
        Hqq, Hqu = self.m.residual_hessian(self.full(q), u, lam)
        self.current()
        Hqq = Hqq.tocoo()
        vals = np.zeros(self._h_keys.size)
        np.add.at(vals, np.searchsorted(self._h_keys, Hqq.col.astype(np.int64) * self.m.n_free + Hqq.row), Hqq.data)
        return vals, Hqu


def residual_function(model, with_load: bool = False) -> ca.Function:
    """``R(q, u)`` as a CasADi Function with exact first and second derivatives (see the module docstring).

    q: the free degrees of freedom (``model.n_free``, zero at rest), u: all actuator inputs (``model.n_u``).
    ``with_load`` adds a third input, the factor on the external loads F (used by continuation).
    Cached on the model: calling it twice returns the same Function.
    """
    return model.cache.get(("residual_function", bool(with_load)), lambda: _build_residual(model, with_load))


def _build_residual(model, with_load):
    P = _ResidualFunctions(model, with_load)
    n, nu = model.n_free, model.n_u
    dense, empty = ca.Sparsity.dense, (lambda r, c: ca.Sparsity(r, c))
    ins = [("q", dense(n, 1)), ("u", dense(nu, 1))] + ([("load", dense(1, 1))] if with_load else [])
    n_in = len(ins)
    F_free = model.F[model.free]

    def jac_blocks():
        blocks = [P.K.sparsity, P.dRdu.sparsity]
        if with_load:
            blocks.append(_Pattern((n, 1), np.flatnonzero(F_free), np.zeros(np.count_nonzero(F_free))).sparsity)
        return blocks

    def jacobian(name):
        def fn(args, wanted):
            K, dRdu = P.tangent(args[0], args[1], P.load(args)) if any(wanted[:2]) else (None, None)
            out = [K.data if wanted[0] else None, P.dRdu.gather(dRdu) if wanted[1] else None]
            if with_load:
                out.append(-F_free[F_free != 0])
            return out
        return _Callback(name, ins + [("out_R", empty(n, 1))],
                         [(f"jac_R_{nm}", s) for (nm, _), s in zip(ins, jac_blocks())], fn)

    def reverse(nadj, name):
        return _vjp(P, ins, nadj, name, F_free)

    return _Callback("R", ins, [("R", dense(n, 1))], P.residual, jacobian=jacobian,
                     jac_sparsity=lambda o, i: jac_blocks()[i], reverse=reverse)


def _vjp(P, ins, nadj, name, F_free):
    """The reverse-mode Callback: (q, u[, load], out_R, adj_R) -> (adj_q, adj_u[, adj_load]), and its
    Jacobian (the Hessian blocks of lam . R)."""
    m, n, nu = P.m, P.m.n_free, P.m.n_u
    dense, empty = ca.Sparsity.dense, (lambda r, c: ca.Sparsity(r, c))
    with_load = P.with_load
    vjp_ins = ins + [("out_R", empty(n, 1)), ("adj_R", dense(n, nadj))]
    i_adj = len(vjp_ins) - 1
    outs = [("adj_q", dense(n, nadj)), ("adj_u", dense(nu, nadj))] + \
        ([("adj_load", dense(1, nadj))] if with_load else [])

    def fn(args, wanted):
        lam = args[i_adj].reshape(nadj, n)
        K, dRdu = P.tangent(args[0], args[1], P.load(args))
        out = [(K.T @ lam.T).T.ravel(), (dRdu.T @ lam.T).T.ravel()]
        if with_load:
            out.append(-(lam @ F_free))
        return out

    # Jacobian of the VJP. Rows: the outputs, nadj columns stacked. Columns: q, u[, load], out_R, adj_R
    Hq, Hq_where = P.H.stacked(nadj)
    Hu, Hu_where = P.dRdu.stacked(nadj)
    HuT_pattern = P.dRdu.transpose()
    HuT, HuT_where = HuT_pattern.stacked(nadj)
    KT = ca.diagcat(*[P.K.sparsity] * nadj)  # K's pattern is symmetric
    dRduT = ca.diagcat(*[HuT_pattern.sparsity] * nadj)
    n_in = len(ins)
    blocks = {("adj_q", "q"): Hq, ("adj_q", "u"): Hu, ("adj_u", "q"): HuT, ("adj_q", "adj_R"): KT,
              ("adj_u", "adj_R"): dRduT}
    if with_load:
        blocks[("adj_load", "adj_R")] = ca.diagcat(*[_Pattern((1, n), np.zeros(np.count_nonzero(F_free)),
                                                              np.flatnonzero(F_free)).sparsity] * nadj)
    jac_outs = []
    for oname, osp in outs:
        for iname, isp in vjp_ins:
            s = blocks.get((oname, iname), empty(osp.numel(), isp.numel()))
            jac_outs.append((f"jac_{oname}_{iname}", s))
    jac_ins = vjp_ins + [(f"out_{o}", empty(*s.shape)) for o, s in outs]

    def jac_fn(args, wanted):
        q, u = args[0], args[1]
        lam = args[i_adj].reshape(nadj, n)
        named = dict(zip([nm for nm, _ in jac_outs], wanted))
        res = {}
        if named["jac_adj_q_q"] or named["jac_adj_q_u"] or named["jac_adj_u_q"]:
            hq, hu = np.zeros(Hq.nnz()), np.zeros(Hu.nnz())
            huT = np.zeros(HuT.nnz())
            for k in range(nadj):
                vals, Hqu = P.hessian_values(q, u, lam[k])
                hq[Hq_where[k]] = vals
                hu[Hu_where[k]] = P.dRdu.gather(Hqu)
                huT[HuT_where[k]] = HuT_pattern.gather(Hqu.T)
            res.update(jac_adj_q_q=hq, jac_adj_q_u=hu, jac_adj_u_q=huT)
        if named["jac_adj_q_adj_R"] or named["jac_adj_u_adj_R"]:
            K, dRdu = P.tangent(q, u, P.load(args))
            Kt = K.T.tocsc()  # same (symmetric) pattern as K, explicit zeros kept
            Kt.sort_indices()
            res["jac_adj_q_adj_R"] = np.tile(Kt.data, nadj)
            res["jac_adj_u_adj_R"] = np.tile(HuT_pattern.gather(dRdu.T), nadj)
        if with_load and named.get("jac_adj_load_adj_R"):
            res["jac_adj_load_adj_R"] = np.tile(-F_free[F_free != 0], nadj)
        return [res.get(nm) if w else None for (nm, _), w in zip(jac_outs, wanted)]

    def jacobian(jname):
        return _Callback(jname, jac_ins, jac_outs, jac_fn)

    def jac_sparsity(o, i):
        return jac_outs[o * len(vjp_ins) + i][1]

    return _Callback(name, vjp_ins, outs, fn, jacobian=jacobian, jac_sparsity=jac_sparsity)


def point_function(model, points=None) -> ca.Function:
    """``p(q)``: positions (3 x k) of embedded points as a CasADi Function of the free dofs q.

    ``points``: rest positions (k, 3) of points inside the mesh; default the end-effector. Linear in q
    (p = W q + p(0), W the points' interpolation weights), so it is an exact SX expression.
    """
    if points is None:
        W, p0 = model.C_free, model.p0
    else:
        pts = np.atleast_2d(np.asarray(points, dtype=float))
        E = model.embedding(pts)
        W, p0 = E[:, model.free], E @ model.X
    W = sp.csc_matrix(W)
    W.sort_indices()
    k = W.shape[0] // 3
    q = ca.SX.sym("q", model.n_free)
    Wd = ca.DM(ca.Sparsity(W.shape[0], W.shape[1], W.indptr.tolist(), W.indices.tolist()), W.data)
    p = ca.mtimes(Wd, q) + ca.DM(p0)
    return ca.Function("p", [q], [ca.reshape(p, 3, k)], ["q"], ["p"])


def quantity_function(model) -> ca.Function:
    """``Q(q)``: each actuator's quantity (a cable's length in m, a cavity's volume in m^3), (n_u,), as a
    CasADi Function of the free dofs: the actuators' own SX function of their points, which are linear in q,
    so its derivatives are exact (the state limits of :mod:`casadi_ws.solvers.admissible` as constraints)."""
    q = ca.SX.sym("q", model.n_free)
    if not model.n_u:
        return ca.Function("Q", [q], [ca.SX(0, 1)], ["q"], ["Q"])
    act = model.actuators_term
    W = sp.csc_matrix(act.W_all[:, model.free])
    W.sort_indices()
    Wd = ca.DM(ca.Sparsity(W.shape[0], W.shape[1], W.indptr.tolist(), W.indices.tolist()), W.data)
    P = ca.mtimes(Wd, q) + ca.DM(act.W_all @ model.X)
    return ca.Function("Q", [q], [act.quantities_function(P)[0]], ["q"], ["Q"])
