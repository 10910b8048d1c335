"""Optimisation problems over the static equilibria, written as CasADi expressions and solved by IPOPT.

A problem is built step by step, as with ``casadi.Opti``, on the model's CasADi Functions
(:func:`casadi_ws.fem.functions.residual_function`, :func:`casadi_ws.fem.functions.point_function`):

    nlp = EquilibriumNLP(model)                     # variables q (free dofs), u; constraint R(q, u) = 0
    t = nlp.parameter("target", 3)                  # a parameter: one solver serves many targets
    nlp.minimize(casadi.sumsqr(nlp.point() - t))    # any expression of nlp.q, nlp.u and parameters
    nlp.subject_to(nlp.point()[1], lower=0.02)      # any constraint lower <= expr <= upper
    sol = nlp.solve(q, u, target=[0.01, 0.03, 0.19])

CasADi derives every gradient, Jacobian and Hessian from these expressions; the model's Callbacks supply
the exact derivatives of R (assembled, not AD through the mesh). u's box is passed to IPOPT as simple
bounds, and can be tightened per solve. Each solve is warm-started in the primal and the constraint
multipliers of the previous successful solve, with IPOPT options chosen for warm starts
(:data:`IPOPT_OPTIONS`).

:func:`tracking` is the problem the package itself solves: the backward problem (8) of the
forward-backward method is its one-point case; inverse control (:mod:`casadi_ws.control.inverse`) adds
points, a regularisation and limits on the change of u.
"""

from __future__ import annotations

import gc
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..fem.functions import point_function, quantity_function, residual_function
from ..solvers.rootfinder import quiet_stdout, register_solver

__all__ = ["EquilibriumNLP", "IPOPT_OPTIONS", "NLPSolution", "cached_tracking", "quiet_stdout", "release_solvers",
           "tracking"]

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
    # derivative Functions of the model's Callbacks take many directions at once (CasADi's default: 64)
    "oracle_options": {"max_num_dir": 512},
}


@dataclass
class NLPSolution:
    """What one solve returns."""

    q: np.ndarray
    """Nodal displacements, all dofs (3n): IPOPT's last iterate (re-verify before reporting it)."""
    u: np.ndarray
    """Inputs, clipped to the bounds of the solve."""
    success: bool
    """IPOPT reported success."""
    iterations: int
    stats: dict
    """IPOPT's statistics (``casadi.Function.stats()``)."""
    objective: float
    p: np.ndarray
    """The parameters' values of this solve, stacked."""


class EquilibriumNLP:
    """min f(q, u; p)  s.t.  R(q, u) = 0,  lower <= g(q, u; p) <= upper,  u in U (see the module docstring);
    the problem's state limits on the actuators' quantities (``stroke_max``, ``volume_max``) are constraints
    from the start.

    ``q`` (MX, the free dofs) and ``u`` (MX) are the variables; ``R`` is the model's residual Function.
    """

    def __init__(self, model, options: dict | None = None):
        self.model = model
        self.q = ca.MX.sym("q", model.n_free)
        self.u = ca.MX.sym("u", model.n_u)
        self.R = residual_function(model)
        self.options = dict(IPOPT_OPTIONS, **(options or {}))
        self._objective = ca.MX(0)
        self._g, self._lbg, self._ubg = [self.R(self.q, self.u)], [np.zeros(model.n_free)], [np.zeros(model.n_free)]
        self._params: dict[str, tuple[ca.MX, np.ndarray]] = {}
        self._solver = None
        self._lam_g = None
        register_solver(self)
        lo, hi, names = model.quantity_limits
        if names:  # the state limits (a cable's stroke, a chamber's volume), as IPOPT constraints
            limited = [a for a, n in enumerate(names) if n]
            self.subject_to(self.quantities()[limited], lower=lo[limited], upper=hi[limited])

    def release(self) -> None:
        """Drop the IPOPT solver (rebuilt on the next solve), quietly."""
        self._reset()

    # ------------------------------------------------------------------ building
    def parameter(self, name: str, rows: int, cols: int = 1, value=0.0) -> ca.MX:
        """A parameter (set at each solve by name, default ``value``)."""
        self._reset()
        p = ca.MX.sym(name, rows, cols)
        self._params[name] = (p, np.broadcast_to(np.asarray(value, dtype=float), (rows, cols)).copy())
        return p

    def point(self, points=None) -> ca.MX:
        """Positions (3 x k) of embedded points at q; default the end-effector (3 x 1)."""
        return point_function(self.model, points)(self.q)

    def quantities(self) -> ca.MX:
        """The actuators' quantities Q(q) (n_u,): cable lengths (m), cavity volumes (m^3)."""
        return quantity_function(self.model)(self.q)

    def minimize(self, expr) -> None:
        """Add a term to the objective."""
        self._reset()
        self._objective = self._objective + expr

    def subject_to(self, expr, lower=-np.inf, upper=np.inf) -> None:
        """Add constraints lower <= expr <= upper (broadcast to expr's entries)."""
        self._reset()
        expr = ca.vec(ca.MX(expr))
        n = expr.numel()
        self._g.append(expr)
        self._lbg.append(np.broadcast_to(np.asarray(lower, dtype=float), (n,)).ravel())
        self._ubg.append(np.broadcast_to(np.asarray(upper, dtype=float), (n,)).ravel())

    def _reset(self):
        with quiet_stdout():  # a destroyed solver's MUMPS says goodbye on stdout
            self._solver, self._lam_g = None, None

    @property
    def solver(self) -> ca.Function:
        """The IPOPT Function (built on first use)."""
        if self._solver is None:
            p = ca.vertcat(*[ca.vec(s) for s, _ in self._params.values()]) if self._params else ca.MX(0, 1)
            nlp = {"x": ca.vertcat(self.q, self.u), "p": p, "f": self._objective, "g": ca.vertcat(*self._g)}
            self._solver = ca.nlpsol("equilibrium_nlp", "ipopt", nlp, self.options)
        return self._solver

    # ------------------------------------------------------------------ solving
    def _p(self, values: dict) -> np.ndarray:
        unknown = set(values) - set(self._params)
        if unknown:
            raise KeyError(f"unknown parameter(s) {sorted(unknown)}; this problem has {sorted(self._params)}")
        out = []
        for name, (sym, default) in self._params.items():
            v = np.asarray(default if values.get(name) is None else values[name], dtype=float)
            if v.ndim == 2 and v.shape != sym.shape:
                raise ValueError(f"parameter {name!r}: expected shape {sym.shape}, got {v.shape}")
            if v.size == sym.numel():  # a vector for a column, or the matrix itself
                out.append(v.reshape(sym.shape, order="F").ravel(order="F"))
            else:
                out.append(np.broadcast_to(v, sym.shape).ravel(order="F"))
        return np.concatenate(out) if out else np.zeros(0)

    def solve(self, q, u, u_lower=None, u_upper=None, **parameters) -> NLPSolution:
        """Warm-started solve from (q, u) (q: all dofs); bounds on u may be tightened for this solve."""
        m = self.model
        nq = m.n_free
        lbu = m.u_min if u_lower is None else np.maximum(m.u_min, u_lower)
        ubu = m.u_max if u_upper is None else np.minimum(m.u_max, u_upper)
        u0 = np.clip(np.asarray(u, dtype=float), lbu, ubu)
        solver = self.solver
        args = dict(x0=np.concatenate([np.asarray(q, dtype=float)[m.free], u0]), p=self._p(parameters),
                    lbx=np.concatenate([np.full(nq, -np.inf), lbu]), ubx=np.concatenate([np.full(nq, np.inf), ubu]),
                    lbg=np.concatenate(self._lbg), ubg=np.concatenate(self._ubg))
        if self._lam_g is not None:
            args["lam_g0"] = self._lam_g
        with quiet_stdout():
            sol = solver(**args)
        stats = solver.stats()
        x = np.asarray(sol["x"]).ravel()
        ok = bool(stats.get("success"))
        if ok:
            self._lam_g = np.asarray(sol["lam_g"]).ravel()
        return NLPSolution(m.full(x[:nq]), np.clip(x[nq:], lbu, ubu), ok, int(stats.get("iter_count", 0)),
                           stats, float(sol["f"]), args["p"])

    def value(self, expr, sol: NLPSolution) -> np.ndarray:
        """Evaluate an expression of q, u and the parameters at ``sol``."""
        syms = [self.q, self.u] + [s for s, _ in self._params.values()]
        f = ca.Function("value", syms, [ca.MX(expr)])
        p = sol.p
        vals, k = [], 0
        for s, _ in self._params.values():
            vals.append(p[k:k + s.numel()].reshape(s.shape, order="F"))
            k += s.numel()
        return np.asarray(f(sol.q[self.model.free], sol.u, *vals)).squeeze()


def tracking(model, points=None, weights=None, rho: float = 0.0) -> EquilibriumNLP:
    """min sum_i w_i |p_i(q) - t_i|^2 + rho |u - u_ref|^2   s.t.  R(q, u) = 0,  u in U.

    ``points``: rest positions (k, 3) of embedded points (default: the end-effector). Parameters:
    ``targets`` (3 x k, one column per point) and ``u_ref`` (default 0). ``rho`` (m^2/N^2) is a small
    regularisation preferring low inputs (u_ref = 0) or small changes (u_ref = the previous u).
    """
    nlp = EquilibriumNLP(model)
    p = nlp.point(points)
    k = p.shape[1]
    w = np.ones(k) if weights is None else np.asarray(weights, dtype=float)
    targets = nlp.parameter("targets", 3, k)
    u_ref = nlp.parameter("u_ref", model.n_u)
    for i in range(k):
        nlp.minimize(w[i] * ca.sumsqr(p[:, i] - targets[:, i]))
    if rho:
        nlp.minimize(rho * ca.sumsqr(nlp.u - u_ref))
    return nlp


def cached_tracking(model) -> EquilibriumNLP:
    """The tracking NLP of the end-effector (:func:`tracking`), built once per model and kept with it."""
    return model.cache.get("tracking", lambda: tracking(model))


def release_solvers(model) -> None:
    """Destroy ``model``'s cached IPOPT solver now, without MUMPS's farewell on stdout."""
    model.cache.pop("tracking")
    gc.collect()

