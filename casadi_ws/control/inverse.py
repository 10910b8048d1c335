"""Inverse control with the workspace method's NLP: reach a target, follow a path of targets.

``reach`` solves  min |p_E(q) - target|^2 (+ rho |u - u_ref|^2)  s.t.  R(q, u) = 0, u in U  with IPOPT and
exact derivatives (:func:`casadi_ws.nlp.formulations.tracking`), from rest or from a warm start. If the direct solve
fails, it follows a homotopy: the target moves from the current tip to the goal in steps, each solve
warm-started by the previous one. The answer is always re-verified by a Newton solve at the returned u.

An unreachable target is not an error: the result is the closest tip found (a local minimiser of the
distance), its u and the distance, with ``reachable = False``.

``reachable`` means: the verified tip lies within ``tolerance`` (default 1e-6 m) of the target. Orientation
can be asked for with extra embedded points and their targets (the C in R^{6 x 3n}-style variant of the
publication's Section 7: three points around the tip fix its position and orientation).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from ..solvers.equilibrium import CONVERGED, solve_equilibrium
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
    """Steps of the target homotopy used when a direct solve fails."""


@dataclass
class ReachResult:
    reachable: bool
    u: np.ndarray
    tip: np.ndarray
    error: float
    """Distance from the verified tip to the target, metres."""
    status: int
    """A :class:`casadi_ws.status.Status` code: 0 converged (IPOPT solved, equilibrium verified),
    5 iteration limit (IPOPT stopped before optimality; its last iterate, verified, is returned) or
    6 solve failed (not even that iterate is an equilibrium: the start is returned)."""
    iterations: int
    q: np.ndarray
    homotopy: bool = False
    admissibility: Admissibility | None = None
    """The admissibility checks of the returned equilibrium (None: it failed); a target is reachable only
    by an admissible one."""

    def to_dict(self) -> dict:
        adm = self.admissibility
        return {"reachable": self.reachable, "u": self.u.tolist(), "tip": self.tip.tolist(),
                "error": self.error, "status": Status(self.status).label, "status_code": int(self.status),
                "admissible": bool(adm and adm.admissible), "stable": bool(adm and adm.stable),
                "violations": list(adm.violations) if adm else [], "iterations": self.iterations,
                "homotopy": self.homotopy, "units": {"tip": "m", "u": "N", "error": "m"}}


def _solver(model, settings: ReachSettings) -> EquilibriumNLP:
    # the points themselves are part of the key: two sets of the same size are different problems
    key = (np.asarray(settings.extra_points, dtype=float).tobytes(), settings.regularization)
    cache = model.__dict__.setdefault("_tracking_nlps", {})
    if key not in cache:
        points = None
        if settings.extra_points:
            points = np.vstack([model.p0[None], np.asarray(settings.extra_points, float)])
        cache[key] = tracking(model, points=points, rho=settings.regularization)
    return cache[key]


def reach(problem_or_model, target, q0=None, u0=None, settings: ReachSettings | None = None,
          extra_targets=None, u_ref=None) -> ReachResult:
    """Tensions that bring the end-effector to ``target`` (closest reachable point otherwise)."""
    settings = settings or ReachSettings()
    model = problem_or_model if isinstance(problem_or_model, StaticModel) else StaticModel(problem_or_model)
    target = np.asarray(target, dtype=float).reshape(3)
    if q0 is None:
        start = solve_equilibrium(model, model.u_min.copy())
        q0, u0 = start.q, start.u
    u0 = np.asarray(u0, dtype=float)
    targets = np.vstack([target[None], np.asarray(extra_targets, float).reshape(-1, 3)]) \
        if settings.extra_points else target[None]
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
                           Status.SOLVE_FAILED, its, q0, used_homotopy)
    err = float(np.linalg.norm(eq.tip - target))
    adm = admissibility(model, eq.q, eq.u, eq.factorization)
    return ReachResult(err <= settings.tolerance and adm.admissible, eq.u, eq.tip, err,
                       Status.CONVERGED if ok else Status.ITERATION_LIMIT, its, eq.q, used_homotopy, adm)


@dataclass
class FollowResult:
    targets: np.ndarray
    tips: np.ndarray
    u: np.ndarray
    errors: np.ndarray
    reachable: np.ndarray
    status: list
    settings: dict

    def save_csv(self, path) -> None:
        n_u = self.u.shape[1]
        header = ",".join(["x_target", "y_target", "z_target", "x", "y", "z", "error", "reachable"]
                          + [f"u{i + 1}" for i in range(n_u)])
        data = np.hstack([self.targets, self.tips, self.errors[:, None], self.reachable[:, None], self.u])
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
                        [r.status for r in rows], asdict(settings))
