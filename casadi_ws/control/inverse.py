"""Inverse control with the workspace method's NLP: reach a target, follow a path of targets.

``reach`` solves  min |p_E(q) - target|^2 (+ rho |u - u_ref|^2)  s.t.  R(q, u) = 0, u in U, from rest or from
a warm start, by one of two methods (``ReachSettings.method``):

``reduced``  (default) Gauss-Newton in u only, as the forward-backward method's backward step: at the current
             equilibrium the points' sensitivity J = W K^-1 H^T (one LU, n_u solves) gives a bounded
             linear least-squares step in u (kept within the state limits, linearised), the equilibrium at
             u + du is solved by Newton from q + K^-1 H^T du, and a step that does not lower the objective
             is halved. Every iterate is a verified equilibrium. A target it does not reach gets a second
             run from the middle of U (a local minimum of the distance is not the closest point), and
             where Gauss-Newton stalls the full-space NLP runs from the same start. On the 2-cable trunk a
             target costs 0.3-1 s where IPOPT took 6-9 s (its exact Hessian of the residual is a third
             derivative of the elements, and its KKT systems are twice the size of K); on the pinch gripper
             11 s against 372 s, and on the PneuNet finger 1.3 s where IPOPT stopped 0.26 mm short.
``ipopt``    the full-space NLP over (q, u) with exact derivatives (:func:`casadi_ws.nlp.formulations.tracking`).
             If the direct solve fails, it follows a homotopy: the target moves from the current tip to
             the goal in steps, each solve warm-started by the previous one. The answer is re-verified by a
             Newton solve at the returned u.

An unreachable target is not an error: the result is the closest tip found (a local minimiser of the
distance), its u and the distance, with ``reachable = False``.

``reachable`` means: the verified tip lies within ``tolerance`` (default 1e-6 m) of the target. Orientation
can be asked for with extra embedded points and their targets (the C in R^{6 x 3n}-style variant of the
publication's Section 7: three points around the tip fix its position and orientation).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from ..solvers.equilibrium import (CONVERGED, Equilibrium, admissible_guess, settle, solve_equilibrium,
                                   tangent_factorization)
from ..solvers.sensitivity import applied_step, bounded_step, input_range, sensitivity
from ..workspace.backward import _within_limits
from ..status import Status
from ..fem.model import StaticModel
from ..nlp.formulations import EquilibriumNLP, tracking
from ..solvers.admissible import Admissibility, admissibility

__all__ = ["FollowResult", "ReachResult", "ReachSettings", "follow", "reach"]


@dataclass
class ReachSettings:
    """Settings of :func:`reach` and :func:`follow`."""

    tolerance: float = 1e-6
    """A target is reachable if the verified tip lies within this distance of it, metres."""
    regularization: float = 0.0
    """rho in m^2/N^2: adds rho |u - u_ref|^2 (u_ref = 0: prefer low tensions; in follow, the previous u)."""
    max_du: float | None = None
    """Largest change of each tension from the warm start (N); None: only U."""
    extra_points: list = field(default_factory=list)
    """Rest positions of further embedded points whose targets are given to reach() (orientation)."""
    homotopy_steps: int = 8
    """Steps of the target homotopy used when a direct solve fails (``ipopt``)."""
    method: str = "reduced"
    """``reduced`` (Gauss-Newton in u on verified equilibria) or ``ipopt`` (the full-space NLP); see the
    module's docstring."""
    max_iterations: int = 50
    """Gauss-Newton iterations (``reduced``); each costs an equilibrium solve and one LU."""


@dataclass
class ReachResult:
    reachable: bool
    u: np.ndarray
    tip: np.ndarray
    error: float
    """Distance from the verified tip to the target, metres."""
    status: int
    """A :class:`casadi_ws.status.Status` code: 0 converged (the method's optimality test passed,
    equilibrium verified), 5 iteration limit (the method stopped before; its last iterate, verified, is
    returned) or 6 solve failed (no step from the start gave a verified equilibrium: the start is
    returned)."""
    iterations: int
    """Gauss-Newton (``reduced``) or IPOPT iterations."""
    q: np.ndarray
    homotopy: bool = False
    admissibility: Admissibility | None = None
    """The admissibility checks of the returned equilibrium (None: it failed); a target is reachable only
    by an admissible one."""
    method: str = "reduced"
    """The method whose answer this is: ``reduced``, or ``ipopt`` (asked for, or where Gauss-Newton
    stalled)."""
    orientation: dict | None = None
    """The tip's orientation at the answer: ``tilt``, ``roll`` (deg) and ``axis`` (:mod:`casadi_ws.fem.frame`)."""

    def to_dict(self) -> dict:
        adm = self.admissibility
        return {"reachable": self.reachable, "u": self.u.tolist(), "tip": self.tip.tolist(),
                "error": self.error, "status": Status(self.status).label, "status_code": int(self.status),
                "admissible": bool(adm and adm.admissible), "stable": bool(adm and adm.stable),
                "violations": list(adm.violations) if adm else [], "iterations": self.iterations,
                "homotopy": self.homotopy, "method": self.method, "orientation": self.orientation,
                "units": {"tip": "m", "u": "N", "error": "m", "tilt": "deg", "roll": "deg"}}


def _solver(model, settings: ReachSettings) -> EquilibriumNLP:
    # the points themselves are part of the key: two sets of the same size are different problems
    key = (np.asarray(settings.extra_points, dtype=float).tobytes(), settings.regularization)
    cache = model.__dict__.setdefault("_tracking_nlps", {})
    if key not in cache:
        cache[key] = tracking(model, points=_rest_points(model, settings), rho=settings.regularization)
    return cache[key]


def _rest_points(model, settings):
    """Rest positions (k, 3) of the tip and the extra points, in the order of ``targets``; None: the tip."""
    if not settings.extra_points:
        return None
    return np.vstack([model.p0[None], np.asarray(settings.extra_points, float)])


def reach(problem_or_model, target, q0=None, u0=None, settings: ReachSettings | None = None,
          extra_targets=None, u_ref=None) -> ReachResult:
    """Tensions that bring the end-effector to ``target`` (closest reachable point otherwise), with the tip's
    orientation there (``orientation``: tilt and roll in degrees, the axis)."""
    model = problem_or_model if isinstance(problem_or_model, StaticModel) else StaticModel(problem_or_model)
    r = _reach(model, target, q0, u0, settings or ReachSettings(), extra_targets, u_ref)
    o = model.tip_frame.orientation(r.q)
    r.orientation = {"tilt": o["tilt"], "roll": o["roll"], "axis": o["direction"].tolist()}
    return r


def _reach(model, target, q0, u0, settings, extra_targets, u_ref) -> ReachResult:
    target = np.asarray(target, dtype=float).reshape(3)
    if q0 is None:
        start = solve_equilibrium(model, model.u_min.copy())
        q0, u0 = start.q, start.u
    u0 = np.asarray(u0, dtype=float)
    targets = np.vstack([target[None], np.asarray(extra_targets, float).reshape(-1, 3)]) \
        if settings.extra_points else target[None]
    if settings.method not in ("reduced", "ipopt"):
        raise ValueError(f"unknown reach method {settings.method!r}; expected 'reduced' or 'ipopt'")
    if settings.method == "reduced":
        pts = _rest_points(model, settings)
        W = model.C if pts is None else model.embedding(pts)  # positions W (X + q)
        r = _reduced(model, W, targets, q0, u0, settings, u_ref)
        if r.status == Status.CONVERGED and not r.reachable:
            r = _restart_from_the_middle(model, W, targets, q0, u0, settings, u_ref, r)
        if r.status == Status.CONVERGED:
            return r
        # Gauss-Newton stalled (a cable that the others' pull keeps slack turns its steps aside): the
        # full-space NLP from the same start
        r_ipopt = _ipopt(model, targets, q0, u0, settings, u_ref)
        return r_ipopt if r_ipopt.status != Status.SOLVE_FAILED else r
    return _ipopt(model, targets, q0, u0, settings, u_ref)


def _ipopt(model, targets, q0, u0, settings: ReachSettings, u_ref) -> ReachResult:
    """The full-space NLP from (q0, u0), with the target homotopy if needed; see the module's docstring."""
    target = targets[0]
    nlp = _solver(model, settings)
    lo = hi = None
    if settings.max_du is not None:
        lo, hi = u0 - settings.max_du, u0 + settings.max_du

    sol = nlp.solve(q0, u0, u_lower=lo, u_upper=hi, targets=targets.T, u_ref=u_ref)
    q, u, its, ok = sol.q, sol.u, sol.iterations, sol.success
    used_homotopy = False
    # IPOPT can also stop "successfully" short of a reachable target (a tracking optimum 0.04 mm off on a
    # Dragon Skin trunk, where another start reached it to 1e-9): the homotopy gets its chance then too
    if not ok or np.linalg.norm(model.tip(q) - target) > settings.tolerance:
        # move the target from where the tip is, in steps, warm-starting each solve
        used_homotopy = True
        tip0 = model.tip(q0)
        q, u = q0, u0
        for k in range(1, settings.homotopy_steps + 1):
            t_k = targets.copy()
            t_k[0] = tip0 + (target - tip0) * k / settings.homotopy_steps
            sol = nlp.solve(q, u, u_lower=lo, u_upper=hi, targets=t_k.T, u_ref=u_ref)
            q, u, its, ok = sol.q, sol.u, its + sol.iterations, sol.success
    eq = solve_equilibrium(model, u, q0=q0, u0=u0, guess=q)
    if eq.status != CONVERGED:
        return ReachResult(False, u0, model.tip(q0), float(np.linalg.norm(model.tip(q0) - target)),
                           Status.SOLVE_FAILED, its, q0, used_homotopy, method="ipopt")
    err = float(np.linalg.norm(eq.tip - target))
    adm = admissibility(model, eq.q, eq.u, eq.factorization)
    return ReachResult(err <= settings.tolerance and adm.admissible, eq.u, eq.tip, err,
                       Status.CONVERGED if ok else Status.ITERATION_LIMIT, its, eq.q, used_homotopy, adm,
                       method="ipopt")


def _restart_from_the_middle(model, W, targets, q0, u0, settings, u_ref, r: ReachResult) -> ReachResult:
    """Gauss-Newton once more, from the middle of the inputs allowed; the better of the two answers.

    A target Gauss-Newton did not reach may lie beyond a local minimum of the distance: the pinch gripper's
    upper jaw, its lower jaw's cable at 0, stopped 0.12 mm short of a tip that only the lower jaw pushing it
    reaches; from the middle of U it reached it (IPOPT took 372 s there). A target outside the workspace
    costs this second run and keeps the first answer unless the second is closer."""
    lo, hi = model.u_min, model.u_max
    if settings.max_du is not None:
        lo, hi = np.maximum(lo, u0 - settings.max_du), np.minimum(hi, u0 + settings.max_du)
    mid = solve_equilibrium(model, (lo + hi) / 2, q0=q0, u0=u0)
    if mid.status != CONVERGED:
        return r
    r2 = _reduced(model, W, targets, mid.q, mid.u, settings, u_ref, u_box=u0)
    r2.iterations += r.iterations
    r.iterations = r2.iterations
    better = _objective(model, W, settings, targets, r2.q, r2.u, u_ref) < \
        (1 - 1e-9) * _objective(model, W, settings, targets, r.q, r.u, u_ref)
    return r2 if r2.status == Status.CONVERGED and better else r


def _objective(model, W, settings, targets, q, u, u_ref) -> float:
    """sum_i |p_i(q) - t_i|^2 + rho |u - u_ref|^2 (u_ref None: 0), the points' positions W (X + q)."""
    ref = np.zeros(model.n_u) if u_ref is None else np.asarray(u_ref, float)
    return float(np.sum((W @ (model.X + q) - targets.ravel()) ** 2)
                 + settings.regularization * np.sum((u - ref) ** 2))


def _reduced(model, W, targets, q, u, settings: ReachSettings, u_ref, u_box=None) -> ReachResult:
    """Gauss-Newton in u from the verified equilibrium (q, u), the points' positions W (X + q); see the
    module's docstring. ``u_box``: the centre of the ``max_du`` box (default u)."""
    Wf = W[:, model.free].tocsr()
    goal = targets.ravel()
    root = np.sqrt(settings.regularization)
    u_start = u.copy() if u_box is None else np.asarray(u_box, float)
    u_ref = np.zeros(model.n_u) if u_ref is None else np.asarray(u_ref, float)

    def cost(q, u):
        return _objective(model, W, settings, targets, q, u, u_ref)

    start_q, start_u = q, u
    fac = tangent_factorization(model, q, u)
    f = cost(q, u)
    status, its, moved_once = Status.ITERATION_LIMIT, 0, False
    for its in range(1, settings.max_iterations + 1):
        _, S = sensitivity(model, q, fac)
        J, r = Wf @ S, goal - W @ (model.X + q)
        if root:
            J, r = np.vstack([J, root * np.eye(model.n_u)]), np.concatenate([r, root * (u_ref - u)])
        lo, hi, offset = input_range(model, q, u)
        if settings.max_du is not None:
            lo = np.maximum(lo, u_start - settings.max_du - u)
            hi = np.minimum(hi, u_start + settings.max_du - u - offset)
        du = _within_limits(model, q, J, S, r, bounded_step(J, r, lo, np.maximum(hi, lo)), lo, hi)
        # converged: the step would move no point by a hundredth of the tolerance
        if np.abs(Wf @ (S @ du)).max(initial=0.0) < 1e-2 * settings.tolerance:
            status = Status.CONVERGED
            break
        for _ in range(6):  # a step that does not lower the objective (or fails to solve) is halved
            u_new = np.clip(u + applied_step(du, offset), model.u_min, model.u_max)
            guess = q.copy()
            guess[model.free] += S @ du
            eq = solve_equilibrium(model, u_new, q0=q, u0=u, guess=guess if admissible_guess(model, guess) else q)
            f_new = cost(eq.q, u_new) if eq.status == CONVERGED else np.inf
            if f_new < f:
                break
            du = du / 2
        else:
            status = Status.SOLVE_FAILED if not moved_once else Status.ITERATION_LIMIT
            break
        moved_once = True
        q, u, f = eq.q, u_new, f_new
        fac = eq.factorization if eq.factorization is not None else tangent_factorization(model, q, u)
    if not moved_once and status == Status.SOLVE_FAILED:
        q, u = start_q, start_u
    elif q is not start_q:  # contact that can hold the body in more than one way: the path from rest decides
        settled = settle(model, Equilibrium(q, u, model.tip(q), CONVERGED, 0, 0, 0.0, 0, fac), start_q)
        q, fac = settled.q, settled.factorization
    tip = model.tip(q)
    err = float(np.linalg.norm(tip - targets[0]))
    adm = admissibility(model, q, u, fac)
    return ReachResult(err <= settings.tolerance and adm.admissible, u, tip, err, status, its, q, False, adm)


@dataclass
class FollowResult:
    targets: np.ndarray
    tips: np.ndarray
    u: np.ndarray
    errors: np.ndarray
    reachable: np.ndarray
    status: list
    settings: dict
    orientation: np.ndarray | None = None
    """(k, 5): tilt, roll (deg) and the tip's axis at each answer."""

    def save_csv(self, path) -> None:
        n_u = self.u.shape[1]
        header = ",".join(["x_target", "y_target", "z_target", "x", "y", "z", "error", "reachable"]
                          + [f"u{i + 1}" for i in range(n_u)] + ["tilt", "roll", "axis_x", "axis_y", "axis_z"])
        data = np.hstack([self.targets, self.tips, self.errors[:, None], self.reachable[:, None], self.u,
                          self.orientation])
        np.savetxt(path, data, delimiter=",", header=header, comments="", fmt="%.10g")


def follow(problem_or_model, targets, settings: ReachSettings | None = None) -> FollowResult:
    """Reach ``targets`` (k, 3) in order, each warm-started from the previous answer."""
    settings = settings or ReachSettings()
    model = problem_or_model if isinstance(problem_or_model, StaticModel) else StaticModel(problem_or_model)
    targets = np.atleast_2d(np.asarray(targets, dtype=float))
    q = u = None
    rows = []
    for t in targets:
        r = reach(model, t, q0=q, u0=u, settings=settings,
                  u_ref=u if (settings.regularization and u is not None) else None)
        rows.append(r)
        q, u = r.q, r.u  # the verified equilibrium (or, if verification failed, the previous one)
    return FollowResult(targets, np.array([r.tip for r in rows]), np.array([r.u for r in rows]),
                        np.array([r.error for r in rows]), np.array([r.reachable for r in rows]),
                        [r.status for r in rows], asdict(settings),
                        np.array([[r.orientation["tilt"], r.orientation["roll"], *r.orientation["axis"]]
                                  for r in rows]).reshape(-1, 5))
