"""Equilibria by ``casadi.rootfinder`` on the model's residual Function, and their sensitivities.

    q = rootfinder(q_guess, u)          R(q, u) = 0 by CasADi's Newton (line search, MUMPS on K)

Being a CasADi Function, the rootfinder differentiates through the implicit-function theorem: the Jacobian
of p(q(u)) with respect to u is the publication's A = C K^-1 H^T, and :func:`equilibrium_function` returns
exactly that composition. ``solver.newton: rootfinder`` in a problem file makes every equilibrium of the
package use it (with the same continuation on failure); the built-in Newton
(:mod:`casadi_ws.solvers.equilibrium`) stays the default because it reuses factorisations between
iterations and nearby points (BENCHMARKS.md, "nlp": ~3x faster on the trunk).

The linear solver is MUMPS: CasADi's default for rootfinders (CSparse) measured 3x slower on the trunk's K,
its LDL did not converge (no pivoting) and QR was 7x slower.
"""

from __future__ import annotations

import atexit
import gc
import os
import sys
import weakref

import casadi as ca
import numpy as np

from ..fem.cache import quiet_stdout

__all__ = ["equilibrium_function", "quiet_stdout", "register_solver", "release_rootfinders", "rootfinder_newton"]

_LIVE_SOLVERS: "weakref.WeakSet" = weakref.WeakSet()
"""Objects holding IPOPT/MUMPS solvers (``release()`` drops them), released quietly at exit."""


def release_rootfinders() -> None:
    """Destroy the registered NLP solvers now, without MUMPS's farewell (a model's rootfinders go with it)."""
    with quiet_stdout():
        for holder in list(_LIVE_SOLVERS):
            holder.release()
        gc.collect()


def _at_exit() -> None:
    # solvers still alive at shutdown (ours, and those inside a user's Functions) are destroyed after every
    # handler, and their MUMPS writes to the C-level stdout then. Drop ours quietly; then point file
    # descriptor 1 at /dev/null but Python's sys.stdout at the real stdout, so that exit handlers that run
    # after this one still print.
    release_rootfinders()
    sys.stdout.flush()
    saved = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    os.close(devnull)
    sys.stdout = os.fdopen(saved, "w", buffering=1)


atexit.register(_at_exit)


def register_solver(holder) -> None:
    """Release ``holder``'s solvers (its ``release()``) quietly at exit, if it is still alive then."""
    _LIVE_SOLVERS.add(holder)


def _rootfinder(model, max_iter: int, tol: float) -> ca.Function:
    """rootfinder over G(q; u, load, s) = R(q, u, load) / s: s (a force scale) makes one absolute tolerance
    serve every solve."""
    return model.cache.get(("rootfinder", max_iter, tol), lambda: _build_rootfinder(model, max_iter, tol))


def _build_rootfinder(model, max_iter: int, tol: float) -> ca.Function:
    from ..fem.functions import residual_function

    R = residual_function(model, with_load=True)
    n = model.n_free
    q, u, load, s = ca.MX.sym("q", n), ca.MX.sym("u", model.n_u), ca.MX.sym("load"), ca.MX.sym("s")
    G = ca.Function("G", [q, u, load, s], [R(q, u, load) / s], ["q", "u", "load", "s"], ["G"])
    # |R|_inf < tol s / sqrt(n) implies |R|_2 < tol s, the package's test
    return ca.rootfinder("equilibrium", "newton", G, {
        "linear_solver": "mumps", "abstol": tol / np.sqrt(n), "abstolStep": 0.0, "max_iter": max_iter,
        "error_on_fail": False})


def rootfinder_newton(model, u, q, load, tol, max_iter):
    """One Newton solve by casadi.rootfinder from q (all dofs); returns (q, relative residual, iterations).
    The residual is the package's own test, evaluated afterwards."""
    rf = _rootfinder(model, max_iter, tol)
    _, scale = model.residual(q, u, load, with_scale=True)
    q_new = model.full(np.asarray(rf(q[model.free], u, load, scale)).ravel())
    its = int(rf.stats().get("iter_count", 0))
    R, scale = model.residual(q_new, u, load, with_scale=True)
    return q_new, float(np.linalg.norm(R) / scale), its


def equilibrium_function(model, points=None, tol: float | None = None, max_iter: int | None = None) -> ca.Function:
    """``(q_guess, u) -> (q, p)``: the equilibrium at u by Newton from q_guess (free dofs), and the
    positions p (3 x k) of the end-effector (or of embedded ``points``) there.

    A CasADi Function: its Jacobian ``dp/du`` is the sensitivity A = C K^-1 H^T at the equilibrium (by the
    implicit-function theorem, without differentiating the iterations). The tolerance is relative to the
    force of all actuators at their upper bounds plus the loads (the Function has no per-call scale); no
    continuation: from a poor guess, use :func:`casadi_ws.solve_equilibrium` instead.
    """
    from ..fem.functions import point_function

    settings = model.spec.solver
    tol = settings.tolerance if tol is None else tol
    max_iter = settings.max_iterations if max_iter is None else max_iter
    rf = _rootfinder(model, max_iter, tol)
    H = model.actuation_matrix(np.zeros(model.n_dof))
    scale = float(np.linalg.norm(H.T @ model.u_max + model.F[model.free])) or model.force_floor
    q0, u = ca.MX.sym("q_guess", model.n_free), ca.MX.sym("u", model.n_u)
    q = rf(q0, u, 1.0, scale)
    return ca.Function("equilibrium", [q0, u], [q, point_function(model, points)(q)],
                       ["q_guess", "u"], ["q", "p"])
