"""Static equilibrium R(q, u) = 0 for given tensions u: Newton with line search, factor reuse, continuation.

The Jacobian is the exact tangent K evaluated by the model (CasADi element functions) and factorised with
SuperLU. A factorisation can be handed back in to warm-start the next solve ("chord" iterations reuse it as
long as the residual contracts fast; it is refreshed otherwise), which is what makes sweeps over many
nearby inputs cheap. When a direct solve fails, the load is applied in continuation steps from the last
known equilibrium (or from rest).

Status codes (``Equilibrium.status``): 0-4 of :mod:`casadi_ws.status` (0 converged: verified).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..status import Status
from .linear import SINGLE_PRECISION_PROBE, factorize, solver_of  # noqa: F401  (re-exported)

__all__ = ["CONVERGED", "CONTINUATION_FAILED", "DIVERGED", "Equilibrium", "Factorization", "MAX_ITERATIONS",
           "OUTSIDE_BOUNDS", "designed_negatives", "factorize", "inside_bounds", "newton_krylov", "solve_equilibrium",
           "tangent_factorization", "verify"]

CONVERGED, MAX_ITERATIONS, DIVERGED, CONTINUATION_FAILED, OUTSIDE_BOUNDS = (
    Status.CONVERGED, Status.MAX_ITERATIONS, Status.DIVERGED, Status.CONTINUATION_FAILED, Status.OUTSIDE_BOUNDS)


@dataclass
class Factorization:
    """An LU factorisation of K on the free dofs, with the state it was computed at."""

    lu: object
    q: np.ndarray

    def solve(self, b: np.ndarray) -> np.ndarray:
        return self.lu.solve(b)

    def negative_pivots(self) -> int | None:
        """How many pivots of the LU are negative, or None if the count says nothing (SuperLU swapped rows, or
        PARDISO's LU of an unsymmetric K). Without row swaps the LU of a symmetric K is its L D L^T, so this
        is the number of K's negative eigenvalues (Sylvester's law of inertia)."""
        f = getattr(self.lu, "negative_pivots", None)
        return f() if f is not None else None

    @property
    def K(self):
        """The matrix factorised when the LU is in single precision (:func:`factorize`), else None: what
        needs K^-1 to full precision (sensitivities) refines its solves against it."""
        return getattr(self.lu, "K", None)


def tangent_factorization(model, q: np.ndarray, u: np.ndarray) -> Factorization:
    """A fresh LU of the tangent K at the equilibrium (q, u)."""
    K = model.tangent(q, u)
    return _factorization(K, q, model)


def _factorization(K, q, model=None) -> Factorization:
    return Factorization(factorize(K, single=True, pivot_threshold=getattr(model, "pivot_threshold", 0.01),
                                   solver=solver_of(model), negatives=designed_negatives(model), inertia=False),
                         q.copy())


def designed_negatives(model) -> int | None:
    """How many negative eigenvalues ``model``'s tangent has where it is stable, by design: those of a
    symmetric saddle point's rows (the continuous pressure's); None where some rows do not keep it symmetric
    (contact, prescribed quantities: the stability test then factorises the stiffness it holds)."""
    saddle = [getattr(t, "negatives", None) for t in getattr(model, "terms", ())]
    if getattr(model, "n_lam", 0) or None in saddle:
        return None
    return sum(saddle)


@dataclass
class Equilibrium:
    """Result of one equilibrium solve."""

    q: np.ndarray
    """Nodal displacements (3n)."""
    u: np.ndarray
    """Tensions the equilibrium was solved for."""
    tip: np.ndarray
    """End-effector position p_E = C q + p_E(0)."""
    status: int
    """A :class:`casadi_ws.status.Status` code; 0 means verified."""
    iterations: int = 0
    """Newton iterations, all continuation steps included."""
    factorizations: int = 0
    """LU factorisations of K computed."""
    residual: float = float("nan")
    """Relative residual ||R|| / ||H^T u + F|| at q."""
    load_steps: int = 0
    """Continuation steps used (0: direct solve)."""
    factorization: Factorization | None = field(default=None, repr=False)
    """Latest factorisation, reusable to warm-start a nearby solve."""

    @property
    def converged(self) -> bool:
        return self.status == CONVERGED

    @property
    def status_name(self) -> str:
        return Status(self.status).label

    def to_dict(self) -> dict:
        return {"tip": self.tip.tolist(), "u": self.u.tolist(), "converged": self.converged,
                "status": self.status_name, "iterations": self.iterations,
                "factorizations": self.factorizations, "residual": self.residual,
                "load_steps": self.load_steps}


@dataclass
class _Newton:
    q: np.ndarray
    status: int
    iterations: int
    factorizations: int
    residual: float
    fac: Factorization | None


def _newton(model, u, q, load, tol, max_iter, fac: Factorization | None, target: float | None = None) -> _Newton:
    """Newton on the free dofs with Deuflhard's natural-monotonicity test.

    A step dq = -K^-1 R is judged by the simplified correction dq' = -K^-1 R(q + a dq) with the same
    factorisation: it is accepted when ||dq'|| < (1 - a/4) ||dq||, else a is halved. This test is
    affine-invariant; the plain residual norm is not, and it rejects good steps when thin parts rotate.
    The same ratio says whether a factorisation is worth keeping: while it contracts the correction at
    least 4x per step, or the residual 5x (chord iterations, ~20x cheaper than refactorising), it is
    reused, otherwise refreshed. In soft, cable-loaded bodies the correction can stall in a soft mode while
    the residual, which is what verification reads, falls 1000x: a chord step that cuts the residual 100x
    is therefore taken even when the correction test objects. A factorisation passed in is tried first.
    With ``solver.newton: rootfinder`` the solve is casadi.rootfinder's instead (:mod:`.rootfinder`).

    With ``target`` (< tol) it iterates on towards that residual, but a stop below ``tol`` still counts as
    converged: a point is never a failure once its residual passes the check.
    """
    if getattr(model.problem.solver, "newton", "builtin") == "rootfinder":
        from .rootfinder import rootfinder_newton

        q, rel, its = rootfinder_newton(model, u, q, load, tol if target is None else min(tol, target), max_iter)
        status = CONVERGED if rel < tol else (DIVERGED if not np.isfinite(rel) else MAX_ITERATIONS)
        return _Newton(q, status, its, its, rel, None)
    free = model.free
    q = q.copy()
    R, scale = model.residual(q, u, load, with_scale=True)
    its = nfac = 0
    need_fresh = fac is None
    dq = None if need_fresh else -fac.solve(R)
    goal = tol if target is None else min(tol, target)

    def stop(status):
        return _Newton(q, CONVERGED if rel < tol else status, its, nfac, rel, fac)

    while True:
        rel = np.linalg.norm(R) / scale
        if not np.isfinite(rel):
            return _Newton(q, DIVERGED, its, nfac, rel, fac)
        if rel < goal:
            return _Newton(q, CONVERGED, its, nfac, rel, fac)
        if its >= max_iter:
            return stop(MAX_ITERATIONS)
        fresh = need_fresh
        if fresh:
            K = model.tangent(q, u, load)
            try:
                fac = _factorization(K, q, model)
            except RuntimeError:  # exactly singular tangent
                return stop(DIVERGED)
            nfac += 1
            dq = -fac.solve(R)
        its += 1
        size = np.linalg.norm(dq)
        alpha = alpha0 = model.contact_step_limit(q, dq) if getattr(model, "has_contact", False) else 1.0
        while True:
            q_try = q.copy()
            q_try[free] += alpha * dq
            R_try, scale_try = model.residual(q_try, u, load, with_scale=True)
            rel_try = np.linalg.norm(R_try) / scale_try
            if rel_try < goal:  # verified: the simplified correction's solve would judge a step already done
                q, rel = q_try, rel_try
                return _Newton(q, CONVERGED, its, nfac, rel, fac)
            dq_bar = -fac.solve(R_try) if np.all(np.isfinite(R_try)) else None
            theta = np.linalg.norm(dq_bar) / size if dq_bar is not None else np.inf
            ok = bool(theta < 1.0 - alpha / 4.0)
            if not ok and alpha == alpha0 < 1.0 and np.isfinite(theta):
                # a step cut where a contact point reaches its surface: taken as it is (a trust region); the
                # Newton step beyond it, which the test judges, crosses the contact's switch and means little
                ok = True
            if not ok and not fresh and np.isfinite(theta):
                ok = bool(rel_try < 1e-2 * rel)
            if not ok and fresh and getattr(model, "has_contact", False) and np.isfinite(theta):
                # a contact point grazing its surface (gap and force both ~0) makes the smoothed complementarity
                # row all curvature: the Newton increments stop contracting while the residual still falls
                ok = bool(rel_try < (1.0 - alpha / 4.0) * rel)
            if ok or not fresh:
                break
            alpha *= 0.5
            if alpha < alpha0 / 64:
                return stop(DIVERGED)
        # keep the factorisation while it contracts fast, or slowly but enough to finish in 3 cheap steps
        # (near the tolerance theta measures round-off, and a refactorisation would buy nothing)
        rel_next = rel_try if ok else np.inf
        contracts = theta < 0.25 or rel_next < 0.2 * rel or (theta < 0.7 and rel_next * theta**3 < tol)
        need_fresh = not (ok and alpha == 1.0 and contracts)
        if ok:
            q, R, scale, dq = q_try, R_try, scale_try, dq_bar


def newton_krylov(model, u, q, fac: Factorization, tol: float, max_iter: int = 4, max_krylov: int = 12):
    """Newton steps with the exact tangent at each iterate, solved by GMRES preconditioned with an older LU.

    An LU costs ~20x a GMRES iteration on the trunk; the exact K costs half an LU. When consecutive points
    are close, K^-1 of a previous point clusters the spectrum of the new K near 1 and GMRES needs a few
    iterations. Returns ``(q, relative residual, krylov iterations)`` once converged, or None as soon as
    GMRES needs more than ``max_krylov`` iterations or the residual stops falling: then a fresh LU is due.
    """
    from scipy.sparse.linalg import LinearOperator, gmres

    q = q.copy()
    R, scale = model.residual(q, u, 1.0, with_scale=True)
    M = LinearOperator((model.n_free, model.n_free), matvec=fac.solve)
    n_kry = 0
    for _ in range(max_iter):
        rel = np.linalg.norm(R) / scale
        if not np.isfinite(rel):
            return None
        if rel < tol:
            return q, rel, n_kry
        K = model.tangent(q, u)
        count = [0]
        # inexact Newton: 1e-6 of the residual suffices when the first iterate is a good predictor; GMRES's
        # own test reads the unpreconditioned residual, which stalls near 1e-9 on this ill-conditioned K
        dq, info = gmres(K, -R, M=M, rtol=1e-6, atol=0.0, restart=max_krylov, maxiter=1,
                         callback=lambda _: count.__setitem__(0, count[0] + 1), callback_type="pr_norm")
        n_kry += count[0]
        if info != 0 and count[0] >= max_krylov:
            return None
        q[model.free] += dq
        R_new, scale = model.residual(q, u, 1.0, with_scale=True)
        if not np.linalg.norm(R_new) < np.linalg.norm(R):
            return None
        R = R_new
    rel = np.linalg.norm(R) / scale
    return (q, rel, n_kry) if rel < tol else None


def solve_equilibrium(model, u, q0: np.ndarray | None = None, u0: np.ndarray | None = None,
                      fac: Factorization | None = None, tol: float | None = None,
                      max_iter: int | None = None, continuation: bool = True,
                      guess: np.ndarray | None = None, target: float | None = None) -> Equilibrium:
    """Solve R(q, u) = 0.

    ``q0`` is a known equilibrium at tensions ``u0`` (default: rest): the warm start, and the start of a
    continuation if the direct solve fails. ``guess`` overrides the first iterate (e.g. a predictor).
    ``fac`` is a factorisation to try reusing. ``tol`` and ``max_iter`` default to the problem's settings.
    ``target`` (< tol): iterate on towards this residual, e.g. for points that others are interpolated from;
    the point is accepted at ``tol`` all the same.
    """
    settings = model.problem.solver
    tol = settings.tolerance if tol is None else tol
    max_iter = settings.max_iterations if max_iter is None else max_iter
    u = np.asarray(u, dtype=float).reshape(-1)
    if u.shape != (model.n_u,):
        raise ValueError(f"u must have {model.n_u} entries (one per cable), got {u.size}")
    q = np.zeros(model.n_dof) if q0 is None else np.asarray(q0, dtype=float).copy()
    if guess is not None:
        q = np.asarray(guess, dtype=float).copy()

    res = _newton(model, u, q, 1.0, tol, max_iter, fac, target)
    its, nfac, steps = res.iterations, res.factorizations, 0
    if res.status != CONVERGED and continuation:
        if q0 is not None and u0 is not None:
            q_s, u_s, load_s = np.asarray(q0, dtype=float).copy(), np.asarray(u0, dtype=float), 1.0
        else:
            q_s, u_s, load_s = np.zeros(model.n_dof), np.zeros(model.n_u), 0.0
        res, s_its, s_fac, steps = _continuation(model, q_s, u_s, load_s, u, tol, max_iter,
                                                 settings.max_load_steps, res.fac)
        its, nfac = its + s_its, nfac + s_fac
    status = res.status
    residual = res.residual
    if status == CONTINUATION_FAILED:  # res.q belongs to a partial load: judge it at the asked u instead
        R, scale = model.residual(res.q, u, 1.0, with_scale=True)
        residual = float(np.linalg.norm(R) / scale)
    if status == CONVERGED and not inside_bounds(model, u):
        status = OUTSIDE_BOUNDS
    return Equilibrium(res.q, u, model.tip(res.q), status, its, nfac, float(residual), steps, res.fac)


def inside_bounds(model, u) -> bool:
    """u in [u_min, u_max], up to round-off (1e-12 of the bounds)."""
    slack = 1e-12 * np.maximum(1.0, np.abs(model.u_max))
    return bool(np.all(u >= model.u_min - slack) and np.all(u <= model.u_max + slack))


def verify(model, u, q, tol: float) -> Equilibrium:
    """The equilibrium check alone, no Newton step: q is accepted at u (status CONVERGED) if its relative
    residual is below ``tol`` and u lies in U; else the status is OUTSIDE_BOUNDS or MAX_ITERATIONS."""
    u = np.asarray(u, dtype=float)
    R, scale = model.residual(q, u, with_scale=True)
    rel = float(np.linalg.norm(R) / scale)
    status = MAX_ITERATIONS if not rel < tol else (CONVERGED if inside_bounds(model, u) else OUTSIDE_BOUNDS)
    return Equilibrium(q, u.copy(), model.tip(q), status, 0, 0, rel, 0, None)


def _continuation(model, q, u_start, load_start, u_end, tol, max_iter, max_steps, fac):
    """Apply (u, load) from (u_start, load_start) to (u_end, 1) in adaptive steps, predictor = secant."""
    s, ds = 0.0, 0.25
    its = nfac = steps = 0
    prev = None  # (s, q) of the previous converged step, for the secant predictor
    last = _Newton(q, CONTINUATION_FAILED, 0, 0, float("nan"), fac)
    while s < 1.0 and steps < max_steps:
        t = min(1.0, s + ds)
        u_t = u_start + t * (u_end - u_start)
        load_t = load_start + t * (1.0 - load_start)
        guess = q if prev is None else q + (q - prev[1]) * (t - s) / (s - prev[0])
        r = _newton(model, u_t, guess, load_t, tol, max_iter, None)
        its, nfac, steps = its + r.iterations, nfac + r.factorizations, steps + 1
        if r.status == CONVERGED:
            prev, q, s = (s, q), r.q, t
            last = r
            ds = min(2.0 * ds, 1.0)
        else:
            ds *= 0.5
            if ds < 1e-4:
                break
    if s < 1.0:
        return _Newton(q, CONTINUATION_FAILED, 0, 0, last.residual, last.fac), its, nfac, steps
    return last, its, nfac, steps
