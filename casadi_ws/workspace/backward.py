"""Step 3 of the forward-backward method: the backward problem (8).

    min_{q, u} || C q + p_E(0) - target ||^2   s.t.  R(q, u) = 0,  u in U

solved from a nearby equilibrium (the neighbour the target came from). Formulations behind one interface,
:func:`backward`:

``reduced``  Gauss-Newton in u only. At the current equilibrium, A = C K^-1 H^T (one LU, n_u solves) maps
             du to the tip; a bounded linear least-squares problem gives du; the equilibrium at u + du is
             corrected by Newton from the predictor q + K^-1 H^T du. Repeated until the step is small. Each
             iterate is a verified equilibrium, so the answer always is one. A step is kept within the
             problem's state limits (stroke, volume), linearised at the iterate.
``ipopt``    the full-space NLP over (q, u) (:func:`casadi_ws.nlp.formulations.tracking`), with exact derivatives
             from the model's CasADi Functions and a primal-dual warm start; the answer is then re-verified.

Status codes (``BackwardResult.status``, :mod:`casadi_ws.status`): 0 converged (a verified equilibrium,
closest point found), 5 iteration limit (the last verified equilibrium is returned), 6 solve failed (an
equilibrium solve or the NLP failed), 7 gave up (reduced with ``give_up``: from the last verified
equilibrium, which is returned, the linearised closest point lies outside the target's cell).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..solvers.equilibrium import (CONVERGED, Equilibrium, Factorization, admissible_guess, settle, solve_equilibrium,
                                   tangent_factorization)
from ..solvers.sensitivity import (applied_step, bounded_step, closest_to_box, input_range, limited_step, second_order,
                                   sensitivity)
from ..status import Status

__all__ = ["BackwardResult", "BackwardSettings", "backward"]

SOLVED, ITERATION_LIMIT, FAILED, GAVE_UP = Status.CONVERGED, Status.ITERATION_LIMIT, Status.SOLVE_FAILED, Status.GAVE_UP


@dataclass
class BackwardSettings:
    """Settings of the backward problem (8)."""

    formulation: str = "reduced"
    """``reduced`` (Gauss-Newton in u) or ``ipopt`` (full-space NLP)."""
    max_iterations: int = 6
    """Gauss-Newton iterations (reduced)."""
    step_tolerance: float = 0.01
    """Stop when the tip moves less than this fraction of the grid step (reduced): whether a cell is
    reached is decided at the scale of the cell, and each further iteration costs an equilibrium."""
    stop_inside: float | None = 0.499
    """Reduced: stop as soon as a verified tip lies within this fraction of the step from the target in
    every coordinate (inside its cell): the workspace needs a point of the cell, not the one closest to
    its centre (0.45 cost 6 % more LUs on the 2-cable trunk for the same cells). None: always converge to
    the closest point."""
    edge_box: float | None = 0.4
    """Reduced: where the linearised closest point to the target lies outside the target's cell (a cell on
    the edge of the workspace, only partly reachable), aim instead at the nearest point of the box of
    half-width ``edge_box`` steps around the target (:func:`casadi_ws.solvers.sensitivity.closest_to_box`):
    the workspace needs a point of the cell, and the part of the cell that is reachable is not near its
    centre. 0.4 leaves a tenth of a cell for the linearisation's error. None: the centre only (problem (8)
    as the publication states it)."""
    second_order: bool = True
    """Reduced, in the forward-backward method: predict each backward solve's first equilibrium to second order,
    with the curvature Q = d2q/du2 of the configuration it starts from
    (:func:`casadi_ws.solvers.sensitivity.curvature`: n_u(n_u + 1) residuals and a solve with n_u(n_u + 1)/2
    right-hand sides per reached cell), so that its Newton solve needs one LU. False: the linear predictor
    q + S du, whose Newton solve then needs a second LU where the body rotates (BENCHMARKS.md, "second-order")."""
    curvature_age: int | str = "auto"
    """Reduced, in the forward-backward method, with ``second_order``: how many generations a computed Q serves. A
    configuration reached from one whose Q is younger than this takes that Q (its age plus one) instead of
    computing its own; 0: every reached configuration computes its own. Why: Q changes little over a cell, and a
    Q a few cells old still predicts well enough for one LU in most solves; the Q's saved (n_u(n_u + 1)
    residuals and two solves each) then cost less than the second LUs they leave. ``auto``: 2 with linear
    (4-node) tetrahedra, 0 with 10-node ones, as measured in one process, 0 against 2 (docs/methods.md,
    "Second-order predictor"): the linear trunks took 15.3 / 49.4 / 132.7 s against 14.2 / 46.6 / 111.6 s
    at 2 / 3 / 4 cables, the same cells; the 10-node trunk 46.7 against 49.7 s at 2 cables and 222.6
    against 261.4 s at 3 (its Q changes more over a cell: 1.91 LUs per cell became 2.59)."""
    tangent_products: str = "auto"
    """Reduced, in the forward-backward method: how a reached configuration's S and Q (computed with the LU
    at its last predictor, one Newton iterate away) are refined against the tangent K at the answer.
    ``assembled``: K assembled there. ``differences``: the products K v by forward differences of the
    residual (:class:`casadi_ws.solvers.sensitivity.TangentProducts`; 2 n_u + n_u(n_u + 1)/2 + 1 residuals,
    relative error ~1e-7). ``auto``: differences where they cost at most 3/4 of an assembled tangent by the
    element's ``tangent_cost``: 10-node tetrahedra with up to two inputs, 4-node ones with one. Measured
    (BENCHMARKS.md "tangent-products"): the 10-node 2-cable trunk took 0.89 of the time for the same
    cells; on the linear trunk differences cost the same at 2 inputs and 6 % more at 3."""
    give_up: float | None = None
    """Reduced: stop (status 7) when, from the second iterate on, the linearised closest point (the bounded
    least-squares step's prediction) lies more than (0.5 + give_up) steps from the target in some
    coordinate: the target's cell will not be reached, and converging to the closest point would cost
    equilibria for nothing. From an iterate less than a cell away the linearisation errs by ~0.02 step on
    the trunk. The forward-backward method sets 0.05 (its prefilter makes the same test, with a wider
    margin, before the first iterate). None: always converge."""
    give_up_short: float = 0.02
    """Reduced, with ``give_up``: its margin instead where the step moves the tip less than a tenth of a step
    (the iterate is already near the closest point). There the linearisation at a verified equilibrium errs by
    less than 0.008 step (measured at the 182 such iterates of a 4-cable run; it is the equilibria's own
    tolerance, not the body's curvature), so the margin need not cover a cell's curvature. Before it, 92 of the
    4-cable trunk's 231 missed targets took two to four equilibria to converge 0.50-0.55 step from them."""


@dataclass
class BackwardResult:
    """Answer of the backward problem (8): always a verified equilibrium (the start if nothing better)."""

    q: np.ndarray
    """Nodal displacements of the answer (3n)."""
    u: np.ndarray
    """Its inputs."""
    tip: np.ndarray
    """Its end-effector position."""
    status: int
    """A :class:`casadi_ws.status.Status` code (see the module's docstring)."""
    iterations: int = 0
    """Gauss-Newton (reduced) or IPOPT iterations."""
    equilibrium_solves: int = 0
    factorizations: int = 0
    fac: Factorization | None = None
    """The last LU of K near the answer, reusable for its sensitivities."""
    predictor_error: float | None = None
    """Reduced, started with a curvature Q: how far (infinity norm, in steps ``scale``) the first equilibrium's
    tip lies from where the second-order model p + A du + C Q(du, du) / 2 put it; None without Q. What the
    forward-backward method reads to trust that model for the answer's own targets
    (:func:`casadi_ws.workspace.forward_backward.prefilter`)."""

    branch: int = 0
    """The answer's :class:`casadi_ws.solvers.equilibrium.Branch` code (``PATH_DEPENDENT``: the equilibrium
    from rest is the answer, another one is reached from the start)."""

    @property
    def ok(self) -> bool:
        """A new verified equilibrium was found (the status is not ``solve_failed``)."""
        return self.status != FAILED


def backward(model, target, q, u, fac: Factorization | None = None, scale: float = 1e-3,
             settings: BackwardSettings | None = None, sens=None) -> BackwardResult:
    """Solve (8) for ``target`` from the equilibrium (q, u); ``scale`` is a length (the grid step).

    ``sens`` = (A, S) or (A, S, Q) at (q, u), if known (:func:`casadi_ws.solvers.sensitivity.sensitivity`,
    :func:`~casadi_ws.solvers.sensitivity.curvature`), spares an LU; with Q the first equilibrium is
    predicted to second order, which spares the second LU of its Newton solve.
    """
    settings = settings or BackwardSettings()
    if settings.formulation == "reduced":
        res = _reduced(model, np.asarray(target, float), q, np.asarray(u, float), fac, scale, settings, sens)
    elif settings.formulation == "ipopt":
        res = backward_ipopt(model, np.asarray(target, float), q, np.asarray(u, float), settings)
    else:
        raise ValueError(f"unknown backward formulation {settings.formulation!r}; expected 'reduced' or 'ipopt'")
    return _settled(model, res, q)


def _settled(model, res: BackwardResult, q_start) -> BackwardResult:
    """The answer made the path from rest's wherever its contact could hold it in another equilibrium
    (:func:`casadi_ws.solvers.equilibrium.settle`, every answer where such points press)."""
    if not res.ok or res.q is q_start:
        return res
    eq = Equilibrium(res.q, res.u, res.tip, CONVERGED, 0, 0, 0.0, 0, res.fac, res.branch)
    out = settle(model, eq, None)
    res.factorizations += out.factorizations - (0 if out is eq else eq.factorizations)
    if out is not eq:
        res.q, res.tip, res.fac, res.branch = out.q, out.tip, out.factorization, out.branch
        res.equilibrium_solves += 1
    return res


def _reduced(model, target, q, u, fac, scale, settings, sens=None) -> BackwardResult:
    n_eq = n_fac = 0
    if fac is None and sens is None:
        fac = tangent_factorization(model, q, u)
        n_fac += 1
    tip = model.tip(q)
    Q = sens[2] if sens is not None and len(sens) > 2 else None
    error, branch = None, 0
    for it in range(1, settings.max_iterations + 1):
        A, S = sens[:2] if (it == 1 and sens is not None) else sensitivity(model, q, fac)
        # bounded linear least squares for du: min |tip + A du - target|^2, u_min <= u + du <= u_max (steps
        # of a slack cable counted from where it pulls again: input_range)
        lo, hi, offset = input_range(model, q, u)
        du = bounded_step(A, target - tip, lo, hi)
        miss = np.abs(tip + A @ du - target).max()
        if settings.edge_box is not None and miss > 0.5 * scale:
            du_box, _ = closest_to_box(A, target - tip, lo, hi, settings.edge_box * scale)
            if np.abs(tip + A @ du_box - target).max() < miss:
                du = du_box
        du = _within_limits(model, q, A, S, target - tip, du, lo, hi)
        if not np.any(du):
            return BackwardResult(q, u, tip, SOLVED, it - 1, n_eq, n_fac, fac, error, branch)
        if settings.give_up is not None and it > 1:
            move = A @ du
            margin = settings.give_up if np.linalg.norm(move) >= 0.1 * scale else \
                min(settings.give_up, settings.give_up_short)
            if np.abs(tip + move - target).max() > (0.5 + margin) * scale:
                return BackwardResult(q, u, tip, GAVE_UP, it - 1, n_eq, n_fac, fac, error, branch)
        u_new = np.clip(u + applied_step(du, offset), model.u_min, model.u_max)
        curved = second_order(Q, du) if (it == 1 and Q is not None) else None
        eq = _equilibrium(model, q, u, u_new, S @ du, curved)
        n_eq += 1
        n_fac += eq.factorizations
        if eq.status != CONVERGED:
            return BackwardResult(q, u, tip, FAILED, it, n_eq, n_fac, fac, error, branch)
        if curved is not None:
            error = float(np.abs(eq.tip - tip - A @ du - model.C_free @ curved).max()) / scale
        moved = np.linalg.norm(eq.tip - tip)
        q, u, tip, branch = eq.q, u_new, eq.tip, eq.branch
        if eq.factorization is not None:
            fac = eq.factorization
        elif fac is None:  # Newton needed no step and there was no LU yet
            fac = tangent_factorization(model, q, u)
            n_fac += 1
        if moved < settings.step_tolerance * scale:
            return BackwardResult(q, u, tip, SOLVED, it, n_eq, n_fac, fac, error, branch)
        if settings.stop_inside is not None and np.all(np.abs(tip - target) <= settings.stop_inside * scale):
            return BackwardResult(q, u, tip, SOLVED, it, n_eq, n_fac, fac, error, branch)
    return BackwardResult(q, u, tip, ITERATION_LIMIT, settings.max_iterations, n_eq, n_fac, fac, error, branch)


def _equilibrium(model, q, u, u_new, linear, curved=None):
    """The equilibrium at u_new by Newton from the predictor q + ``linear`` (+ ``curved``, the second-order
    term), warm-started from the equilibrium (q, u).

    Where the second-order predictor lands in a region where K is indefinite (seen on the 10-node trunk at
    large tensions, where the body is bent double: two negative pivots at the predictor, none at q or at the
    answer), Newton from it diverges after 1-6 LUs, and the continuation from q that follows costs ~8 more
    (11-14 in all). Newton from the linear predictor, though its residual is ~10x larger, then converges
    with ~3 LUs: it is tried next, and the continuation only if it fails too."""
    guess = q.copy()
    guess[model.free] += linear
    if not admissible_guess(model, guess):  # a predictor through an inverted element mixes branches
        guess, curved = q, None
    if curved is None:
        return solve_equilibrium(model, u_new, q0=q, u0=u, guess=guess)
    curved_guess = guess.copy()
    curved_guess[model.free] += curved
    if not admissible_guess(model, curved_guess):
        return solve_equilibrium(model, u_new, q0=q, u0=u, guess=guess)
    eq = solve_equilibrium(model, u_new, q0=q, u0=u, guess=curved_guess, continuation=False)
    if eq.status == CONVERGED:
        return eq
    again = solve_equilibrium(model, u_new, q0=q, u0=u, guess=guess)
    again.factorizations += eq.factorizations
    again.iterations += eq.iterations
    return again


LIMIT_MARGIN = 0.02
"""Share of the distance to a state limit that a reduced backward step leaves (see :func:`_within_limits`)."""


def _within_limits(model, q, A, S, r, du, lo, hi):
    """The step kept within the problem's state limits (a cable's stroke, a chamber's volume), linearised at
    q: Q(u + du) ~ Q + dQ/dq S du (:func:`casadi_ws.solvers.sensitivity.limited_step`)."""
    q_lo, q_hi, names = model.quantity_limits  # (not lo, hi: those are the step's box)
    rows = [a for a, n in enumerate(names) if n]
    if not rows:
        return du
    Q, dQ, _ = model.actuator_terms(q)
    G = dQ[rows][:, model.free] @ S
    # 98 % of the way to a limit: the linearisation would otherwise land the equilibrium a hair beyond it
    g_lo, g_hi = q_lo[rows] - Q[rows], q_hi[rows] - Q[rows]
    with np.errstate(invalid="ignore"):  # unlimited sides stay infinite
        g_lo = np.where(np.isfinite(g_lo), g_lo + LIMIT_MARGIN * np.abs(g_lo), g_lo)
        g_hi = np.where(np.isfinite(g_hi), g_hi - LIMIT_MARGIN * np.abs(g_hi), g_hi)
    return limited_step(A, r, lo, hi, G, g_lo, g_hi, du)


def backward_ipopt(model, target, q, u, settings):
    """Backward problem (8) by the full-space NLP; the answer is re-verified by a Newton solve."""
    from ..nlp.formulations import cached_tracking

    nlp = cached_tracking(model)
    sol = nlp.solve(q, u, targets=target)
    # verify: the same equilibrium test as everywhere else, from IPOPT's answer
    eq = solve_equilibrium(model, sol.u, q0=q, u0=u, guess=sol.q)
    if eq.status != CONVERGED:
        return BackwardResult(q, u, model.tip(q), FAILED, sol.iterations, 1, eq.factorizations)
    status = SOLVED if sol.success else ITERATION_LIMIT
    return BackwardResult(eq.q, sol.u, eq.tip, status, sol.iterations, 1, eq.factorizations, eq.factorization,
                          branch=eq.branch)
