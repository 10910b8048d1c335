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
from enum import IntEnum

import numpy as np

from ..status import Status
from .linear import SINGLE_PRECISION_PROBE, factorize, solver_of  # noqa: F401  (re-exported)

__all__ = ["CONVERGED", "CONTINUATION_FAILED", "DIVERGED", "Equilibrium", "Factorization", "MAX_ITERATIONS",
           "OUTSIDE_BOUNDS", "Branch", "SAME_STATE", "TRUST_REGION", "VOLUME_KEPT", "admissible_guess",
           "designed_negatives", "factorize", "inside_bounds", "newton_krylov", "quasi_static", "settle",
           "solve_equilibrium",
           "tangent_factorization", "verify"]

CONVERGED, MAX_ITERATIONS, DIVERGED, CONTINUATION_FAILED, OUTSIDE_BOUNDS = (
    Status.CONVERGED, Status.MAX_ITERATIONS, Status.DIVERGED, Status.CONTINUATION_FAILED, Status.OUTSIDE_BOUNDS)


class Branch(IntEnum):
    """How a solve made sure its answer is on the branch of the equilibrium it started from
    (:attr:`Equilibrium.branch`; docs/methods.md "One answer per input")."""

    NEAR = 0
    """Newton converged without shortening a step: it stayed near its first iterate."""
    MIDPOINT = 1
    """Some step was shortened; the midpoint test found the answer on the start's branch."""
    PATH_AGREED = 2
    """The midpoint test failed; the answer re-solved along the path from the start (:func:`quasi_static`)
    is the same state."""
    PATH_REPLACED = 3
    """The path from the start reached another equilibrium, which replaced Newton's answer."""
    PATH_DEPENDENT = 4
    """The answer depends on the path: loaded from the start and from rest the robot comes to different
    stable equilibria (hysteresis: buckling, snap-through, contact that holds); the one from rest is reported,
    so that results do not depend on the method's settings."""
    UNCONFIRMED = 5
    """The midpoint test failed and the path from the start did not converge: Newton's answer is kept."""


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


def tangent_factorization(model, q: np.ndarray, u: np.ndarray, single: bool = True) -> Factorization:
    """A fresh LU of the tangent K at the equilibrium (q, u) (``single``: in single precision where a probe shows
    it accurate, see :func:`casadi_ws.solvers.linear.factorize`)."""
    K = model.tangent(q, u)
    return _factorization(K, q, model, single)


def _factorization(K, q, model=None, single: bool = True) -> Factorization:
    return Factorization(factorize(K, single=single, pivot_threshold=getattr(model, "pivot_threshold", 0.01),
                                   solver=solver_of(model), negatives=designed_negatives(model), inertia=False),
                         q.copy())


def designed_negatives(model) -> int | None:
    """How many negative eigenvalues ``model``'s tangent has where it is stable, by design: those of a
    symmetric saddle point's rows (the continuous pressure's); None where some rows do not keep it symmetric
    (contact, prescribed quantities: the stability test then factorises the stiffness it holds)."""
    saddle = [t.negatives for t in model.terms]
    return None if None in saddle else sum(saddle)


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
    branch: int = 0
    """How the answer was made sure to be on its start's branch: a :class:`Branch` code."""

    @property
    def converged(self) -> bool:
        return self.status == CONVERGED

    @property
    def status_name(self) -> str:
        return Status(self.status).label

    @property
    def path_dependent(self) -> bool:
        return self.branch == Branch.PATH_DEPENDENT

    def to_dict(self) -> dict:
        return {"tip": self.tip.tolist(), "u": self.u.tolist(), "converged": self.converged,
                "status": self.status_name, "iterations": self.iterations,
                "factorizations": self.factorizations, "residual": self.residual,
                "load_steps": self.load_steps, "path_dependent": self.path_dependent}


@dataclass
class _Newton:
    q: np.ndarray
    status: int
    iterations: int
    factorizations: int
    residual: float
    fac: Factorization | None
    damped: bool = False
    """Some step was shortened by the line search (the full Newton step failed the monotonicity test): the
    iterates may have left the first one's neighbourhood, so :func:`solve_equilibrium` checks the branch."""


TRUST_REGION = 0.25
"""Largest nodal move of a Newton step, as a share of the local element size (the mean edge of the smallest
element at the node), that may be taken on a lowered residual alone (see :func:`_newton`)."""

VOLUME_KEPT = 0.75
"""Within one Newton solve no element may shrink below this share of its volume at the first iterate (of its
rest volume where the first iterate has it swollen): the crushed branches of the trunk's tip cap lie at
det F ~0.45 from ~0.99, while over every Newton solve of the shipped problems' forward sweeps the smallest
ratio was 0.91 (see :func:`_newton`)."""


def admissible_guess(model, q: np.ndarray) -> bool:
    """Whether a first iterate keeps every element above the admissibility floor of det F (Newton never takes
    an iterate below it, :func:`_newton`; a predictor that does mixes branches)."""
    guard = _Guard(model)
    return guard.min_det(q) >= guard.floor and all(t.admits(model, q) for t in model.terms)


class _Guard:
    """What keeps Newton on its branch (docs/methods.md "One answer per input"): the floor of det F, the
    volume each element keeps, and the trust region of the steps taken without the monotonicity test's
    consent."""

    def __init__(self, model, q_first: np.ndarray | None = None):
        self.model = model
        self.floor = float(model.spec.admissibility.min_det_F)
        self.size = model.node_sizes()
        if q_first is not None:
            j = model.jacobians(q_first)
            self.kept = VOLUME_KEPT * np.minimum(j, 1.0)
            self.j_now = float(j.min())

    def min_det(self, q) -> float:
        return float(self.model.jacobians(q).min())

    def crushes(self, q) -> tuple[bool, float]:
        """(whether the state q takes an element below the floor -- or below its present smallest det F,
        where that is lower -- or below the volume it keeps; its smallest det F)."""
        j = self.model.jacobians(q)
        j_min = float(j.min())
        return not (j_min >= min(self.floor, self.j_now) and np.all(j >= self.kept)), j_min

    def reach(self, step_free) -> float:
        """The largest nodal move of a step on the free dofs, in local element sizes."""
        m = self.model
        d = np.zeros(m.n_mech)
        d[m.free_mech] = step_free[: m.n_free_mech]
        return float(np.max(np.linalg.norm(d.reshape(-1, 3), axis=1) / self.size))


def _taken_anyway(alpha: float, alpha0: float, rel_try: float, rel: float, fresh_contact: bool,
                  cut_taken: bool = True) -> bool:
    """Whether :func:`_newton` takes a step the monotonicity test objects to (the caller has checked that it
    stays within the trust region)."""
    if cut_taken and alpha == alpha0 < 1.0:
        # a step cut where a contact point reaches its surface: taken as it is; the Newton step beyond it,
        # which the test judges, crosses the contact's switch and means little (not so a barrier's cut step,
        # Term.cut_judged: taken as it is, it bounced off the barrier and back, 478 iterations on the gripper)
        return True
    if rel_try < 1e-2 * rel:
        # in soft, cable-loaded bodies the correction can stall in a soft mode while the residual, which is
        # what verification reads, falls 100-1000x
        return True
    if fresh_contact:
        # a contact point grazing its surface (gap and force both ~0) makes the smoothed complementarity row
        # all curvature: the increments stop contracting while the residual falls
        return bool(rel_try < (1.0 - alpha / 4.0) * rel)
    return False


def _newton(model, u, q, load, tol, max_iter, fac: Factorization | None, target: float | None = None) -> _Newton:
    """Newton on the free dofs with Deuflhard's natural-monotonicity test, kept on its branch.

    A step dq = -K^-1 R is judged by the simplified correction dq' = -K^-1 R(q + a dq) with the same
    factorisation: it is accepted when ||dq'|| < (1 - a/4) ||dq||, else a is halved. This test is
    affine-invariant; the plain residual norm is not, and it rejects good steps when thin parts rotate.
    The same ratio says whether a factorisation is worth keeping: while it contracts the correction at
    least 4x per step, or the residual 5x (chord iterations, ~20x cheaper than refactorising), it is
    reused, otherwise refreshed. In soft, cable-loaded bodies the correction can stall in a soft mode while
    the residual, which is what verification reads, falls 1000x: a step that cuts the residual 100x is
    therefore taken even when the correction test objects (within the trust region, below). A factorisation
    passed in is tried first.
    With ``solver.newton: rootfinder`` the solve is casadi.rootfinder's instead (:mod:`.rootfinder`).

    Three rules keep the iterates on the branch they start on (docs/methods.md "One answer per input"): no
    trial state takes an element below the admissibility floor of det F (or below its present det F where
    that is already lower), nor below :data:`VOLUME_KEPT` of its volume at the first iterate; and the steps
    taken without the monotonicity test's consent -- a step cut where a contact point reaches its surface, a
    step that only lowers the residual -- must stay within :data:`TRUST_REGION` of the local element size.
    Without them a full 14 mm step from a good guess crushed the trunk's tip onto a non-physical branch
    (det F 0.46) that Newton then converged on.

    With ``target`` (< tol) it iterates on towards that residual while accepted steps still lower it and are
    not round-off (1e-13 of q), but a stop below ``tol`` counts as converged: a point is never a failure once
    its residual passes the check.
    """
    if model.spec.solver.newton == "rootfinder":
        from .rootfinder import rootfinder_newton

        q, rel, its = rootfinder_newton(model, u, q, load, tol if target is None else min(tol, target), max_iter)
        status = CONVERGED if rel < tol else (DIVERGED if not np.isfinite(rel) else MAX_ITERATIONS)
        return _Newton(q, status, its, its, rel, None)
    free = model.free
    if not all(t.admits(model, q) for t in model.terms):
        return _Newton(q.copy(), DIVERGED, 0, 0, np.inf, fac)
    guard = _Guard(model, q)
    contact = getattr(model, "has_contact", False)
    q = q.copy()
    R, scale = model.residual(q, u, load, with_scale=True)
    its = nfac = 0
    need_fresh = fac is None
    dq = None if need_fresh else -fac.solve(R)
    goal = tol if target is None else min(tol, target)

    damped = False
    history = []

    def done(status):
        return _Newton(q, status, its, nfac, rel, fac, damped)

    def stop(status):
        return done(CONVERGED if rel < tol else status)

    while True:
        rel = np.linalg.norm(R) / scale
        if not np.isfinite(rel):
            return done(DIVERGED)
        if rel < goal:
            return done(CONVERGED)
        if not history or rel != history[-1]:  # (a pass whose step was refused leaves rel as it was)
            history.append(rel)
        if its >= max_iter and not (its < 2 * max_iter and _contracting(history)):
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
        alpha, cut_taken = model.contact_step_limit(q, dq) if contact else (1.0, False)
        alpha0 = alpha
        while True:
            q_try = q.copy()
            q_try[free] += alpha * dq
            crushes, j_try = guard.crushes(q_try)
            R_try, scale_try = model.residual(q_try, u, load, with_scale=True)
            rel_try = np.linalg.norm(R_try) / scale_try
            if rel_try < goal and not crushes:  # verified: the simplified correction would judge a step done
                q, rel, damped = q_try, rel_try, damped or alpha < alpha0
                return done(CONVERGED)
            dq_bar = -fac.solve(R_try) if np.all(np.isfinite(R_try)) else None
            theta = np.linalg.norm(dq_bar) / size if dq_bar is not None else np.inf
            ok = bool(theta < 1.0 - alpha / 4.0)
            if not ok and np.isfinite(theta) and guard.reach(alpha * dq) <= TRUST_REGION:
                ok = _taken_anyway(alpha, alpha0, rel_try, rel, fresh and contact, cut_taken)
            ok = ok and not crushes
            if rel < tol and not (ok and rel_try < rel and alpha * size > 1e-13 * np.linalg.norm(q)):
                # polishing towards ``target`` has reached round-off (the residual of trunk_table at rest
                # wandered about 2e-10 for 25 iterations and 17 LUs): the point is verified as it is
                return done(CONVERGED)
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
            damped = damped or alpha < alpha0
            q, R, scale, dq, guard.j_now = q_try, R_try, scale_try, dq_bar, j_try


def _contracting(history: list) -> bool:
    """Whether the relative residual fell in each of the last three iterations, at least 2x each and 100x over
    the three: a Newton that reaches its iteration limit so is converging and goes on (up to twice the limit).
    Stopped there, the pinch gripper with self-contact at 1 N per cable was at 3e-6 and falling at iteration
    30, and the continuation that followed started again from rest."""
    h = history[-4:]
    return len(h) == 4 and all(b < 0.5 * a for a, b in zip(h[:-1], h[1:])) and h[-1] < 1e-2 * h[0]


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
    """Solve R(q, u) = 0: the equilibrium the robot reaches from the known one (q0, u0), or from rest.

    ``q0`` is a known equilibrium at tensions ``u0`` (default: rest): the warm start, the start of a
    continuation if the direct solve fails, and the neighbour whose branch the answer must be on (a Newton
    whose steps were shortened is checked, :attr:`Equilibrium.branch`). ``guess`` overrides the first iterate
    (e.g. a predictor). ``fac`` is a factorisation to try reusing. ``tol`` and ``max_iter`` default to the
    problem's settings. ``target`` (< tol): iterate on towards this residual, e.g. for points that others are
    interpolated from; the point is accepted at ``tol`` all the same.
    """
    settings = model.spec.solver
    tol = settings.tolerance if tol is None else tol
    max_iter = settings.max_iterations if max_iter is None else max_iter
    u = np.asarray(u, dtype=float).reshape(-1)
    if u.shape != (model.n_u,):
        raise ValueError(f"u must have {model.n_u} entries (one per cable), got {u.size}")
    q = np.zeros(model.n_dof) if q0 is None else np.asarray(q0, dtype=float).copy()
    if guess is not None:
        q = np.asarray(guess, dtype=float).copy()
    if q0 is not None and u0 is not None:
        start = (np.asarray(q0, dtype=float), np.asarray(u0, dtype=float), 1.0)
    else:
        start = (np.zeros(model.n_dof), np.zeros(model.n_u), 0.0)

    res = _newton(model, u, q, 1.0, tol, max_iter, fac, target)
    its, nfac, steps, branch = res.iterations, res.factorizations, 0, 0
    if res.status != CONVERGED and continuation:
        res, s_its, s_fac, steps = _continuation(model, *start, u, tol, max_iter, settings.max_load_steps, res.fac)
        its, nfac = its + s_its, nfac + s_fac
    elif res.status == CONVERGED and res.damped and q0 is not None and u0 is not None and np.any(start[1] != u):
        # (with u0 = u there is no path to check: what changed is not an input, e.g. a load stable_branch moves)
        res, branch, counts = _check_branch(model, res, start, u, tol, max_iter, settings.max_load_steps)
        its, nfac, steps = its + counts[0], nfac + counts[1], counts[2]
    status = res.status
    residual = res.residual
    if status == CONTINUATION_FAILED:  # res.q belongs to a partial load: judge it at the asked u instead
        R, scale = model.residual(res.q, u, 1.0, with_scale=True)
        residual = float(np.linalg.norm(R) / scale)
    if status == CONVERGED and not inside_bounds(model, u):
        status = OUTSIDE_BOUNDS
    return Equilibrium(res.q, u, model.tip(res.q), status, its, nfac, float(residual), steps, res.fac, int(branch))


SAME_STATE = 1e-3
"""Two equilibria are the same state when no node is farther apart than this share of its element size."""


def _apart(model, qa, qb) -> float:
    """The largest nodal distance between two states, in local element sizes."""
    d = (np.asarray(qa)[: model.n_mech] - np.asarray(qb)[: model.n_mech]).reshape(-1, 3)
    return float(np.max(np.linalg.norm(d, axis=1) / model.node_sizes()))


def _check_branch(model, res, start, u, tol, max_iter, max_steps):
    """After a Newton whose steps were shortened: is its answer on the branch of ``start`` = (q, u, load)?

    The midpoint test (cheap: one Newton solve): halfway between the start and the answer, the mean of the
    two states must lie within a quarter of their distance of the equilibrium there; two states of one branch
    pass (the branch is smooth between them: 0.5-3 % of the distance on the contact-free trunks), a crushed
    and an intact one do not. Where it
    fails, the answer is re-solved along the path from the start (:func:`_continuation`), and where that
    reaches another equilibrium and the start was not rest, along the path from rest too (a
    :class:`Branch` code says which). Returns (result, branch code, (iterations, factorisations, load steps))."""
    q_s, u_s, load_s = start
    q_mid = (q_s + res.q) / 2
    mid = _newton(model, (u_s + u) / 2, q_mid, (load_s + 1.0) / 2, tol, max_iter, None)
    its, nfac = mid.iterations, mid.factorizations
    if mid.status == CONVERGED and _apart(model, mid.q, q_mid) <= 0.25 * max(_apart(model, res.q, q_s), 4 * SAME_STATE):
        return res, Branch.MIDPOINT, (its, nfac, 0)
    path, p_its, p_fac, steps = _continuation(model, q_s, u_s, load_s, u, tol, max_iter, max_steps, None)
    its, nfac = its + p_its, nfac + p_fac
    if path.status != CONVERGED:
        return res, Branch.UNCONFIRMED, (its, nfac, steps)
    if _apart(model, path.q, res.q) <= SAME_STATE:
        return res, Branch.PATH_AGREED, (its, nfac, steps)
    if load_s == 0.0:  # the start was rest: the path's answer is the definition's
        return path, Branch.PATH_REPLACED, (its, nfac, steps)
    rest, r_its, r_fac, r_steps = _continuation(model, np.zeros(model.n_dof), np.zeros(model.n_u), 0.0, u, tol,
                                                max_iter, max_steps, None)
    its, nfac, steps = its + r_its, nfac + r_fac, steps + r_steps
    if rest.status != CONVERGED or _apart(model, path.q, rest.q) <= SAME_STATE:
        return path, Branch.PATH_REPLACED, (its, nfac, steps)
    return rest, Branch.PATH_DEPENDENT, (its, nfac, steps)


def settle(model, eq: Equilibrium, q_ref: np.ndarray | None) -> Equilibrium:
    """A method's answer ``eq``, reached from its neighbour ``q_ref``, made the path from rest's where the two
    may differ: where the contact points that press at the answer are not those that press at the neighbour,
    among the points whose contact can hold the body in one of several equilibria (against a curved or
    faceted obstacle or the body itself, :attr:`casadi_ws.fem.terms.ContactTerm.multistable`), the answer is
    compared with :func:`quasi_static` from rest, which replaces it (:attr:`Branch.PATH_DEPENDENT`) where it
    is another state. Measured on the finger pressing the egg (n_d = 41): at a shortening of 17.5 mm the tip
    rests against the egg at one point or at two, 0.8 mm apart, both stable, depending on the steps by which
    it was loaded; the forward sweep's strides and quasi_static disagreed there without this.

    With ``q_ref`` None every answer where such points press is compared: forward-backward's chains of
    configurations can carry one arrangement on to inputs where the path from rest takes the other without
    any change of the pressing points along the chain (seen on the finger: 0.6 mm)."""
    if not eq.converged or not getattr(model, "has_contact", False):
        return eq
    terms = [t for t in model.terms if hasattr(t, "multistable")]
    pressing = [t.in_contact(model, eq.q) & t.multistable for t in terms]
    if q_ref is None:
        if not any(p.any() for p in pressing):
            return eq
    elif all(np.array_equal(p, t.in_contact(model, q_ref) & t.multistable) for p, t in zip(pressing, terms)):
        return eq
    ref = quasi_static(model, eq.u)
    if not ref.converged or _apart(model, ref.q, eq.q) <= SAME_STATE:
        eq.iterations += ref.iterations
        eq.factorizations += ref.factorizations
        return eq
    ref.iterations += eq.iterations
    ref.factorizations += eq.factorizations
    ref.branch = int(Branch.PATH_DEPENDENT)
    return ref


def quasi_static(model, u, q0: np.ndarray | None = None, u0: np.ndarray | None = None,
                 tol: float | None = None, max_step: float = 0.1) -> Equilibrium:
    """The equilibrium the robot reaches when its inputs move along the straight path from ``u0`` (at the
    equilibrium ``q0``; default: rest, gravity and loads applied with the inputs) to ``u``, in steps of at
    most ``max_step`` of the way (smaller where a step fails). The definition of a reported point
    (docs/methods.md "One answer per input"), and the reference the tests compare every method's points
    with."""
    settings = model.spec.solver
    tol = settings.tolerance if tol is None else tol
    u = np.asarray(u, dtype=float).reshape(-1)
    if q0 is not None and u0 is not None:
        q_s, u_s, load_s = np.asarray(q0, dtype=float), np.asarray(u0, dtype=float), 1.0
    else:
        q_s, u_s, load_s = np.zeros(model.n_dof), np.zeros(model.n_u), 0.0
    res, its, nfac, steps = _continuation(model, q_s, u_s, load_s, u, tol, settings.max_iterations,
                                          max(settings.max_load_steps, int(np.ceil(4 / max_step))), None, max_step)
    status = res.status
    if status == CONVERGED and not inside_bounds(model, u):
        status = OUTSIDE_BOUNDS
    return Equilibrium(res.q, u, model.tip(res.q), status, its, nfac, float(res.residual), steps, res.fac)


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


def _continuation(model, q, u_start, load_start, u_end, tol, max_iter, max_steps, fac, max_step: float = 1.0):
    """Apply (u, load) from (u_start, load_start) to (u_end, 1) in adaptive steps (the first a quarter of the
    way, at most ``max_step``), predictor = secant."""
    s, ds = 0.0, min(0.25, max_step)
    its = nfac = steps = 0
    prev = None  # (s, q) of the previous converged step, for the secant predictor
    last = _Newton(q, CONTINUATION_FAILED, 0, 0, float("nan"), fac)
    while s < 1.0 and steps < max_steps:
        t = min(1.0, s + ds)
        u_t = u_start + t * (u_end - u_start)
        load_t = load_start + t * (1.0 - load_start)
        guess = q if prev is None else q + (q - prev[1]) * (t - s) / (s - prev[0])
        if prev is not None and not all(term.admits(model, guess) for term in model.terms):
            guess = q  # a secant through contact can carry the boundary through itself
        r = _newton(model, u_t, guess, load_t, tol, max_iter, None)
        its, nfac, steps = its + r.iterations, nfac + r.factorizations, steps + 1
        if r.status == CONVERGED:
            prev, q, s = (s, q), r.q, t
            last = r
            ds = min(2.0 * ds, max_step)
        else:
            ds *= 0.5
            if ds < 1e-4:
                break
    if s < 1.0:
        return _Newton(q, CONTINUATION_FAILED, 0, 0, last.residual, last.fac), its, nfac, steps
    return last, its, nfac, steps
