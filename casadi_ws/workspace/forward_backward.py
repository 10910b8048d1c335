"""The forward-backward method (publication, Sections 4.2 and 5, Algorithm 1).

Explore a grid in the 3-D end-effector space instead of the n_u-dimensional input space. Starting from the
equilibrium at u = u_min, every iteration j takes the configurations reached in iteration j - 1 and for each:

  Step 1  bounds the end-effector over its remaining input range by Theorem 1's interval box;
  Step 2  keeps the grid points of its eta-neighbourhood that lie in that box (7);
  Step 5  dismisses the points already explored, by this or an earlier iteration (10);
  Step 3  solves the backward problem (8) for each remaining point, warm-started from the configuration it
          came from; the target is reached if the verified equilibrium's tip lies in the target's cell;
  Step 4  the reached configurations carry their input bound (9) into the next iteration.

The run stops when an iteration reaches no new cell. The estimated workspace W_E is the union of the reached
cells; their tips are the reached points (the publication's red points).

"Reached" means: the backward answer is a verified equilibrium (relative residual below tolerance, u in U)
whose tip lies within the target's cell, i.e. at most s/2 from the target in each coordinate (the relative
strategy uses eta/2). A target that is not reached from its first parent is recorded as explored and not
reached; per (10) it is not tried again. Failure codes in ``failed_status`` (:mod:`casadi_ws.status`):
8 not reached (the closest point found lies outside the cell), 9 prefiltered (see ``FBSettings.prefilter``),
6 the backward solve failed.

:func:`algorithm1` is the loop of the publication's Algorithm 1, step by step; the state it works on (the
grid, explored and reached cells, failures, counters, checkpoints) is kept by :class:`Exploration`.
"""

from __future__ import annotations

import sys
import time
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from ..fem.model import StaticModel
from ..runtime.executor import Executor, deferred_interrupt, make_executor, one_blas_thread, small_pages
from ..runtime.run_state import RunState, fingerprint
from ..solvers.admissible import VIOLATIONS, admissibility, decode
from ..solvers.equilibrium import CONVERGED, Branch, solve_equilibrium, tangent_factorization
from ..solvers.sensitivity import (TangentProducts, bounded_step, closest_to_box, curvature, distance_below,
                                   input_range, sensitivity)
from ..status import Status
from .backward import BackwardSettings, backward
from .boundary import BoundarySettings, Seeds, boundary
from .interval import Grid, default_step, interval_box, neighbourhood
from .maps import point_maps, stack
from .result import WorkspaceResult, describe

__all__ = ["Exploration", "FBSettings", "algorithm1", "forward_backward", "prefilter"]


@dataclass
class FBSettings:
    """Settings of the forward-backward method."""

    step: float | None = None
    """Grid step s_Ed of the uniform strategy, metres; None: scaled to the robot
    (:func:`casadi_ws.workspace.interval.default_step`: its reach / 48, rounded; 4 mm on the trunk)."""
    strategy: str = "uniform"
    """``uniform`` (global grid anchored at the initial tip) or ``relative`` (step 5 % of ||p||)."""
    relative_ratio: float = 0.05
    """Step of the relative strategy as a fraction of ||p|| (the publication's 5 %)."""
    backward: BackwardSettings = field(default_factory=BackwardSettings)
    """How the backward problem (8) is solved."""
    prefilter: float | None = 0.1
    """Skip a target when the linearised reachable set (Step 1's A over the remaining inputs) misses its cell
    by more than ``prefilter`` steps in some coordinate (infinity-norm distance from the linearised closest
    point to the cell's box). Over a one-cell move the linearisation errs by ~s^2 x curvature (~0.04 s on
    the trunk at s = 4 mm). Measured (docs/methods.md): on the 2-cable trunk 0.1, 0.05 and 0.02 reach the
    same cells and 0 loses 12 % of them, along the edges; on a linear-material trunk at s = 1.5 mm, 0.05
    already loses 6 % (its cables' geometric stiffness bends the workspace more per cell). Not applied from
    a configuration whose body is within a step of an obstacle (the linearisation does not see contacts
    close or open); a cell wholly inside an obstacle is always dropped (the tip is inside the body, which
    never enters one). Where the configuration has a curvature Q that foretold its own tip, a target the
    linear test keeps by a margin below the threshold is put to the second-order model too, at half the
    threshold (:func:`prefilter`). Recorded as ``prefiltered``. None: off (the paper's rule)."""
    cells_meeting_box: bool = True
    """Step 2 keeps the neighbours whose *cell* meets the Step-1 box (the box grown by half a step), not
    only those whose centre lies in it as (7) states: a cell is reached by any point in it, and along the
    workspace's edges the box often covers part of a cell but not its centre. The prefilter then drops the
    cells the linearised reachable set misses."""
    max_cells: int = 200_000
    """Budget: stop after the iteration in which this many grid points have been explored. The result holds
    what was verified, its summary says it stopped (``stopped_at_max_cells``), and the checkpoint stays, so
    the run resumes with a larger budget (the budget is not part of the run's fingerprint)."""
    store_states: bool = False
    """Keep every reached point's nodal displacements."""
    workers: int = 1
    """Processes running the backward solves of an iteration in parallel, each with its own model. Cells
    are claimed before any solve, so the result does not depend on this number."""
    progress: bool = True
    """Print one line per iteration on stderr."""
    boundary: BoundarySettings = field(default_factory=BoundarySettings)
    """The workspace's boundary surface, built after the exploration (:mod:`.boundary`); its enclosed volume
    is the result's ``measures.volume``."""


@dataclass
class _Config:
    """A reached configuration: its cell, tip, state, input, and the sensitivities its expansion needs."""

    cell: tuple
    p: np.ndarray
    q: np.ndarray | None
    u: np.ndarray
    A: np.ndarray | None  # C K^-1 H^T at this configuration (Step 1)
    S: np.ndarray | None  # K^-1 H^T: the first Gauss-Newton step of its backward solves
    Q: np.ndarray | None = None  # d2q/du2: that step's second-order predictor (reduced backward only)
    Q_age: int = 0  # generations since Q was computed (BackwardSettings.curvature_age)
    violations: int = 0  # admissibility violations (bit mask), non-zero only when they are kept
    maps: dict | None = None  # effort, steerability, compliance, tilt, ... (:mod:`.maps`)
    predictor_error: float | None = None  # how far the second-order model put this tip (steps; BackwardResult)


def algorithm1(ex: Exploration, executor: Executor, ctrl_c) -> None:
    """The publication's Algorithm 1, from the frontier of ``ex`` until no new cell is reached."""
    while ex.frontier and ex.counters["explored"] < ex.settings.max_cells:
        ex.counters["iterations"] += 1
        tasks = []
        for cfg in ex.frontier:
            lower, upper = ex.interval_box(cfg)  # Step 1: Theorem 1 over the remaining inputs (9)
            candidates = ex.neighbourhood(cfg, lower, upper)  # Step 2: S_eta in the box (7)
            targets = ex.exclude(cfg, candidates)  # Step 5: not explored before (10)
            if targets:
                tasks.append((cfg, targets))
        answers = ex.backward(tasks, executor, ctrl_c)  # Step 3: problem (8) for each target
        ex.frontier = ex.update(tasks, answers)  # Step 4: the reached carry their bound U - u (9)
        ex.end_iteration()


@dataclass
class ExpandJob:
    """Step 3 for one configuration, or a share of its targets: all a worker needs to solve them."""

    q: np.ndarray
    """The configuration's state and inputs, and its sensitivities A, S and curvature Q (or None)."""
    u: np.ndarray
    A: np.ndarray
    S: np.ndarray
    Q: np.ndarray | None
    targets: list
    """The targets (3,) to solve for."""
    scale: float
    """The configuration's grid step (m)."""
    backward: BackwardSettings
    Q_age: int = 0
    """How many generations the configuration's Q has been passed on (``BackwardSettings.curvature_age``)."""
    grid: Grid | None = None
    reached: frozenset = frozenset()
    """Cells of ``grid`` reached in an earlier iteration, around the configuration's."""
    p: np.ndarray | None = None
    """The configuration's tip; with ``threshold``, the targets are put to the prefilter first."""
    threshold: float | None = None
    predictor_error: float | None = None
    """How far the configuration's own tip lay from its parent's second-order model (in steps), or None."""


@dataclass
class Answer:
    """What Step 4 reads of a target's backward solve."""

    q: np.ndarray | None
    u: np.ndarray | None
    tip: np.ndarray | None
    status: int
    """A :class:`casadi_ws.status.Status` code (``PREFILTERED``: the target was not solved)."""
    ok: bool
    """A new verified equilibrium was found."""
    A: np.ndarray | None = None
    """The answer's sensitivities and curvature (None where Step 4 does not need them)."""
    S: np.ndarray | None = None
    Q: np.ndarray | None = None
    age: int = 0
    """0: Q is the answer's own; k > 0: the configuration's Q is passed on (not sent back), k generations old."""
    equilibrium_solves: int = 0
    factorizations: int = 0
    violations: int = 0
    """The admissibility mask (0: admissible)."""
    maps: dict | None = None
    predictor_error: float | None = None
    branch: int = 0
    """The answer's :class:`casadi_ws.solvers.equilibrium.Branch` code."""


def _expand(model, job: ExpandJob) -> list[Answer]:
    """Step 3 for one configuration: backward solves of its targets; returns an :class:`Answer` per target.

    With the configuration's tip ``job.p`` and a ``job.threshold``, the targets are first put to the prefilter
    (:func:`prefilter`, with the second-order model of Q where ``job.predictor_error``, that model's miss of
    this configuration's own tip, says it can be trusted); a dropped target answers :data:`_PREFILTERED`. It
    runs here, in the worker, rather than in the process handing out the jobs: there, its 2 s on the 4-cable
    trunk held the lock the pool's threads need to feed the workers, and the run took 3-8 s longer
    (docs/methods.md).

    The sensitivities of each new configuration come from the backward's last Newton LU (at the
    second-order predictor, one iterate from the answer), refined with the exact tangent at the answer
    (A ~1 % off without, which the box would not notice but the next predictor would), and so does its
    curvature Q (reduced backward: the second-order predictor of its own targets), unless it takes this
    configuration's Q, of age ``job.Q_age`` (``BackwardSettings.curvature_age``). They travel with the
    configuration, so expanding it needs no LU, in this process or in a worker, and the result does not
    depend on the number of workers. An answer that takes this configuration's Q answers None for it.

    An answer that misses its target's cell and lands in one of ``job.reached`` (cells of ``job.grid``
    reached in an earlier iteration, around this configuration's) gets no sensitivities and no maps: Step 4
    keeps only its tip, status and admissibility (on the 4-cable trunk 59 of 2793 answers).
    """
    out = []
    q, u, Q, bsettings, scale = job.q, job.u, job.Q, job.backward, job.scale
    sens = (job.A, job.S) if Q is None else (job.A, job.S, Q)
    passed_on = Q is not None and job.Q_age < _curvature_age(model, bsettings)
    kept = [True] * len(job.targets)
    if job.p is not None:
        trusted = (job.predictor_error is not None and job.threshold is not None
                   and job.predictor_error <= TRUST * job.threshold)
        kept = prefilter(model, q, u, job.A, job.p, job.targets, scale, job.threshold,
                         bsettings.edge_box is not None, Q if trusted else None)
    for target, keep in zip(job.targets, kept):
        if not keep:
            out.append(_PREFILTERED)
            continue
        res = backward(model, target, q, u, None, scale, bsettings, sens=sens)
        answer = Answer(res.q, res.u, res.tip, res.status, res.ok, equilibrium_solves=res.equilibrium_solves,
                        factorizations=res.factorizations, predictor_error=res.predictor_error, branch=res.branch)
        if res.ok:
            fac = res.fac
            if fac is None:
                fac = tangent_factorization(model, res.q, res.u)
                answer.factorizations += 1
            answer.violations = admissibility(model, res.q, res.u, fac).mask
            landed = job.grid is not None and not _on_target(res.tip, target, scale)
            if landed and job.grid.index(res.tip) in job.reached:
                out.append(answer)
                continue
            answer.A, answer.S, answer.Q, G = _derivatives(model, res.q, res.u, fac, scale, bsettings,
                                                           curved=not passed_on)
            if passed_on:  # the caller has it: not sent back (~0.1 MB an answer on the 4-cable trunk)
                answer.Q, answer.age = None, job.Q_age + 1
            answer.maps = point_maps(model, res.q, res.u, answer.A, fac, G)
        out.append(answer)
    return out


_TWO_RINGS = np.array([(i, j, k) for i in range(-2, 3) for j in range(-2, 3) for k in range(-2, 3)], dtype=np.int64)


def _on_target(tip, target, eta) -> bool:
    """Whether a verified tip lies in its target's cell (Step 4's test, with a relative slack of 1e-9)."""
    return bool(np.all(np.abs(tip - target) <= 0.5 * eta * (1 + 1e-9)))


_PREFILTERED = Answer(None, None, None, int(Status.PREFILTERED), False)
"""A target the prefilter dropped, as :func:`_expand` answers for a target it solved."""


def prefilter(model, q, u, A, p, targets, eta, threshold, whole_cell=True, Q=None) -> list[bool]:
    """Whether each target of the configuration (q, u), of tip p and Step 1's A, is kept by the prefilter
    (``FBSettings.prefilter``: ``threshold``, in steps eta). ``whole_cell``: a target is kept when the
    linearised reachable set comes near any point of its cell, not only its centre (the backward problem's
    ``edge_box`` lets an answer land off the centre).

    With the configuration's curvature ``Q`` (d2q/du2, :func:`casadi_ws.solvers.sensitivity.curvature`), a
    target whose cell the linearised set misses, by less than the threshold, is put to the second-order model
    p + A du + C Q(du, du) / 2 as well, and dropped where that misses the cell by more than
    :data:`SECOND_ORDER` x threshold. Why: over a one-cell move the linearisation errs by up to ~0.25 step on the
    trunks, the second-order model by ~0.06, so the threshold must be wide for the first and need not be for
    the second. Measured (docs/methods.md): every target a backward solve reached lay in the second-order
    model's reach, and a third to a half of the solves that missed were spared. The caller passes Q only
    where the model foretold the configuration's own tip (:data:`TRUST`)."""
    if threshold is None or (model.has_contact and model.min_gap(q) < eta):
        # near a contact the linearisation cannot tell which cells are out of reach: it holds the
        # contacts that releasing an input would open, and misses those a step would close (the tip then
        # slides along the obstacle or the body)
        return [True] * len(targets)
    lo, hi, _ = input_range(model, q, u)
    T = None if Q is None or not Q.size else _tip_curvature(model, Q)
    kept = []
    for target in targets:
        gap = _linear_gap(A, target - p, lo, hi, eta, threshold, whole_cell)
        if T is not None and 0 < gap <= threshold * eta:
            gap = _second_order_gap(A, T, target - p, lo, hi, eta, SECOND_ORDER * threshold, whole_cell) / SECOND_ORDER
        kept.append(gap <= threshold * eta)
    return kept


SECOND_ORDER = 0.5
"""The second-order prefilter's threshold, as a share of ``FBSettings.prefilter`` (see :func:`prefilter`)."""

TRUST = 0.25
"""The second-order model is trusted for a configuration's targets where it put the configuration's own tip
within this share of ``FBSettings.prefilter`` (``BackwardResult.predictor_error``). Why: where Q is poor
(measured on a linear-material trunk at 1.5 mm cells: it missed by a step), its model would drop cells."""


def _tip_curvature(model, Q) -> np.ndarray:
    """(3, n_u, n_u): the tip's second derivatives d2p/du_i du_j from Q (rows i <= j, as
    :func:`casadi_ws.solvers.sensitivity.curvature` returns them)."""
    n = model.n_u
    T = np.zeros((3, n, n))
    i, j = np.triu_indices(n)
    T[:, i, j] = T[:, j, i] = np.asarray(model.C_free @ Q.astype(float).T)
    return T


def _second_order_gap(A, T, r, lo, hi, eta, threshold, whole_cell, iterations: int = 3) -> float:
    """:func:`_linear_gap` for the second-order model r(du) = A du + T(du, du) / 2: its closest point to the
    target by Gauss-Newton from the linear one, and the linear gap of the model linearised there."""
    du = bounded_step(A, r, lo, hi)
    for _ in range(iterations):
        J = A + T @ du
        du = np.clip(du + bounded_step(J, r - (A + 0.5 * T @ du) @ du, lo - du, hi - du), lo, hi)
    J = A + T @ du
    reached = (A + 0.5 * T @ du) @ du
    return _linear_gap(J, r - reached + J @ du, lo, hi, eta, threshold, whole_cell)


def _linear_gap(A, r, lo, hi, eta, threshold, whole_cell) -> float:
    """Infinity-norm distance from the cell of centre p + r to the linearised reachable set {A du, du in
    [lo, hi]}."""
    e = A @ bounded_step(A, r, lo, hi) - r
    gap = np.abs(e).max() - 0.5 * eta
    if gap > 0 and whole_cell:  # the centre is out of reach: any point of the cell?
        # no point of the cell is nearer than the linearised set's distance to r in the infinity norm (at
        # least the Euclidean one / sqrt 3), less the half cell: where that bound already drops the target
        # (two thirds of these on the 4-cable trunk), closest_to_box could not keep it
        far = distance_below(A, r, lo, hi, -e) / np.sqrt(r.size) - 0.5 * eta
        if not far > (threshold + 1e-9) * eta:
            gap = min(gap, closest_to_box(A, r, lo, hi, 0.5 * eta)[1])
    return gap


def _derivatives(model, q, u, fac, eta, bsettings, curved: bool = True):
    """(A, S, Q, G) of a reached configuration from an LU near it, G the tip's compliance for its maps; Q (and
    the refinement by the exact tangent at q, when the LU was computed elsewhere: at the predictor, one iterate
    away) only for the reduced backward, whose predictor they feed (IPOPT's has none), Q only if it predicts
    to second order and ``curved`` (not passed on from the configuration it was reached from)."""
    reduced = bsettings.formulation == "reduced"
    if np.array_equal(fac.q, q) or not reduced:
        K = None
    elif _by_differences(model, bsettings):
        K = TangentProducts(model, q, u)
    else:
        K = model.tangent(q, u)
    A, S, G = sensitivity(model, q, fac, K, compliance=True)
    Q = curvature(model, q, u, S, fac, eta, K) if reduced and bsettings.second_order and curved else None
    return A, S, Q, G


def _curvature_age(model, bsettings) -> int:
    """How many generations a computed Q serves (``BackwardSettings.curvature_age``, ``auto`` resolved)."""
    if bsettings.curvature_age != "auto":
        return int(bsettings.curvature_age)
    return 2 if model.element.order == 1 else 0


def _by_differences(model, bsettings) -> bool:
    """Whether the tangent at a reached configuration is applied by differences of residuals (see
    ``BackwardSettings.tangent_products``)."""
    if bsettings.tangent_products != "auto":
        return bsettings.tangent_products == "differences"
    n = model.n_u
    products = 2 * n + 1 + (n * (n + 1) // 2 if bsettings.second_order else 0)
    return products <= 0.75 * model.element.tangent_cost


class Exploration:
    """The state of Algorithm 1 and its bookkeeping.

    ``frontier`` holds the configurations reached in the last iteration; ``reached`` all of them (W_Es over
    all iterations); ``visited`` the grid cells explored (W_E-union: uniform strategy) or ``visited_pts``
    the explored points (relative strategy); ``failed_targets``/``failed_status`` the explored targets not
    reached, with their :class:`casadi_ws.status.Status` codes.
    """

    def __init__(self, problem, model: StaticModel, settings: FBSettings, run: RunState, start: _Config,
                 grid: Grid | None):
        self.problem, self.model, self.settings, self.run, self.grid = problem, model, settings, run, grid
        self.uniform = grid is not None
        self.counters = dict(iterations=0, explored=0, feasible=0, backward_solves=0, equilibrium_solves=0,
                             factorizations=0, not_reached=0, prefiltered=0, backward_failed=0, adopted=0,
                             inadmissible=0, path_dependent=0, excluded={n: 0 for n in VIOLATIONS},
                             stopped_at_max_cells=False)
        self.timings = {"step1_interval": 0.0, "step2_neighbourhood": 0.0, "step3_backward": 0.0}
        # when the last iteration ended, the cells reached by then, the cells it left to expand
        self._clock = (time.perf_counter(), 1, 1)
        self.bsettings = settings.backward
        if self.bsettings.give_up is None and self.bsettings.formulation == "reduced":
            self.bsettings = replace(self.bsettings, give_up=0.05)  # see BackwardSettings.give_up
        self.reached = [start]
        self.reached_cells = {start.cell}
        self.visited = {start.cell}
        self.visited_pts = [start.p]
        self.failed_targets, self.failed_status, self.failed_closest = [], [], []
        self.excluded = []  # (tip, u, violation mask) of the verified answers that are not admissible
        self.frontier = [start]
        # the boundary surface's face nodes start from the reached configurations nearest to them
        self.seeds = Seeds(model, settings.boundary) if settings.boundary.enabled else None
        self._seed(start)

    # ------------------------------------------------------------------ the steps
    def eta(self, cfg) -> float:
        """The neighbourhood's step at cfg: the grid step, or 5 % of ||p|| (relative strategy)."""
        return self.settings.step if self.uniform else self.settings.relative_ratio * float(np.linalg.norm(cfg.p))

    def interval_box(self, cfg):
        t = time.perf_counter()
        lo, hi, _ = input_range(self.model, cfg.q, cfg.u)  # (9), slack cables counted from where they pull
        box = interval_box(cfg.A, cfg.p, lo, hi)
        self.timings["step1_interval"] += time.perf_counter() - t
        return box

    def neighbourhood(self, cfg, lower, upper) -> list[tuple[tuple, np.ndarray]]:
        """(cell, target) of the grid points of S_eta(cfg) inside the box."""
        t = time.perf_counter()
        centre = self.grid.centre(cfg.cell) if self.uniform else cfg.p
        eta = self.eta(cfg)
        if self.settings.cells_meeting_box:
            lower, upper = lower - 0.5 * eta, upper + 0.5 * eta
        targets, offsets = neighbourhood(centre, eta, lower, upper)
        if self.uniform:
            cells = list(map(tuple, (np.asarray(cfg.cell) + offsets).tolist()))  # Python ints, as Grid.index's
        else:
            cells = [(0, 0, 0)] * len(offsets)
        self.timings["step2_neighbourhood"] += time.perf_counter() - t
        return list(zip(cells, targets))

    def exclude(self, cfg, candidates) -> list[tuple[tuple, np.ndarray]]:
        """Rule (10): drop the points explored before (and claim the others), and the cells inside an
        obstacle. (The prefilter is applied by Step 3's jobs: :func:`_expand`.)"""
        t = time.perf_counter()
        eta = self.eta(cfg)
        todo = []
        obstacles = self.problem.obstacles if self.model.contact is not None else []
        for cell, target in candidates:
            if self.uniform:
                if cell in self.visited:
                    continue
                self.visited.add(cell)
            else:
                if np.min(np.max(np.abs(np.asarray(self.visited_pts) - target), axis=1)) < 0.5 * eta:
                    continue
                self.visited_pts.append(target)
            self.counters["explored"] += 1
            # the whole cell is in an obstacle (gap: the contact's cached distance; distance() rebuilds a
            # triangle surface on every call)
            if any(o.gap(target[None])[0][0] < -0.87 * eta for o in obstacles):
                self._fail(target, Status.PREFILTERED)
                continue
            todo.append((cell, target))
        self.timings["step2_neighbourhood"] += time.perf_counter() - t
        return todo

    def backward(self, tasks, executor: Executor, ctrl_c) -> list:
        """Step 3: the backward solves of every task, warm-started from its configuration, in task order.
        Each job first puts its targets to the prefilter (in the worker: see :func:`_expand`)."""
        t = time.perf_counter()
        order = list(range(len(tasks)))
        if executor.workers > 1:
            # the configurations with the most targets first, so no worker is left with a long one at the
            # end of the iteration (the results are put back in order: same result as 1 worker)
            order.sort(key=lambda i: -len(tasks[i][1]))
        # fewer configurations than workers (the first iteration has one): their targets are shared out, each
        # target's answer depending only on its configuration
        pieces = max(1, executor.workers // max(1, len(tasks)))
        sent = []

        def jobs():
            for i in order:
                cfg, todo = tasks[i]
                targets = [tg for _, tg in todo]
                for part in np.array_split(np.arange(len(targets)), min(pieces, len(targets))):
                    sent.append((i, int(part[0])))
                    grid, reached = self._reached_near(cfg)
                    yield (ExpandJob(cfg.q, cfg.u, cfg.A, cfg.S, cfg.Q, [targets[m] for m in part], self.eta(cfg),
                                     self.bsettings, cfg.Q_age, grid, reached, cfg.p, self.settings.prefilter,
                                     cfg.predictor_error),)

        parts = {}
        for k, out in executor.map_unordered(_expand, self.problem, jobs()):
            parts[sent[k]] = out
            if executor.workers == 1:
                ctrl_c.check()
        ctrl_c.check()
        answers = [[] for _ in tasks]
        for (i, _), out in sorted(parts.items()):
            answers[i] += out
        self.timings["step3_backward"] += time.perf_counter() - t
        return answers

    def _reached_near(self, cfg) -> tuple:
        """(grid, the cells reached so far within two cells of cfg's): where an answer that misses its target
        lands, in the cell next to it or one further, when its sensitivities are not needed (see _expand)."""
        if not self.uniform:
            return None, frozenset()
        near = map(tuple, (np.asarray(cfg.cell) + _TWO_RINGS).tolist())
        return self.grid, frozenset(c for c in near if c in self.reached_cells)

    def update(self, tasks, answers) -> list:
        """Step 4: returns the new frontier. A cell is reached when a verified answer lies in it, whichever
        target that solve aimed at: an answer that misses its target's cell but lands in a cell not reached
        yet is adopted there (uniform grid), so no verified equilibrium is thrown away."""
        new_frontier = []
        keep_inadmissible = self.problem.admissibility.keep
        for (cfg, todo), out in zip(tasks, answers):
            eta = self.eta(cfg)
            for (cell, target), a in zip(todo, out):
                q, u, tip, status, ok, viol = a.q, a.u, a.tip, a.status, a.ok, a.violations
                if status == Status.PREFILTERED:
                    self._fail(target, Status.PREFILTERED)
                    continue
                self.counters["backward_solves"] += 1
                self.counters["equilibrium_solves"] += a.equilibrium_solves
                self.counters["factorizations"] += a.factorizations
                self.counters["path_dependent"] += a.branch == Branch.PATH_DEPENDENT
                if ok and viol and not keep_inadmissible:
                    # verified but not a state the robot can take: kept apart, never a reached cell; its
                    # neighbours are still explored from the configurations that are admissible
                    self._exclude(tip, u, viol)
                    self._fail(target, Status.INADMISSIBLE, tip)
                    continue
                on_target = ok and _on_target(tip, target, eta)
                hit = on_target
                if not hit:
                    self._fail(target, Status(status) if not ok else Status.NOT_REACHED, tip if ok else None)
                    if ok and self.uniform:
                        cell = self.grid.index(tip)
                        hit = self.grid.contains(cell, tip)
                if hit and not (self.uniform and cell in self.reached_cells):
                    if cell not in self.visited:  # adopted: explored by the answer that landed in it
                        self.visited.add(cell)
                        self.counters["explored"] += 1
                    if not on_target:
                        self.counters["adopted"] += 1
                    new = _Config(cell, tip, q, u, a.A, a.S, cfg.Q if a.age else a.Q, a.age, viol, a.maps,
                                  a.predictor_error)
                    self._seed(new)
                    new_frontier.append(new)
                    self.reached.append(new)
                    self.reached_cells.add(cell)
            cfg.S = cfg.Q = None  # expanded: no longer needed
        return new_frontier

    def _seed(self, cfg) -> None:
        if self.seeds is not None and not cfg.violations:
            self.seeds.offer(cfg.u, cfg.q, cfg.S, cfg.Q)

    def _exclude(self, tip, u, violations: int) -> None:
        self.excluded.append((tip, u, violations))
        for name in decode(violations):
            self.counters["excluded"][name] += 1

    def _fail(self, target, status: Status, closest=None) -> None:
        """A target not reached; ``closest``: the verified answer's tip (the closest point the backward
        solve found), if it had one."""
        key = {Status.PREFILTERED: "prefiltered", Status.NOT_REACHED: "not_reached",
               Status.INADMISSIBLE: "inadmissible"}.get(status, "backward_failed")
        self.counters[key] += 1
        self.failed_targets.append(target)
        self.failed_status.append(int(status))
        self.failed_closest.append(np.full(3, np.nan) if closest is None else np.asarray(closest, float))

    def end_iteration(self) -> None:
        if not self.settings.store_states:
            for c in self.reached:  # only the frontier's states are needed from here on
                if c.S is None:
                    c.q = None
        self.save()
        if self.settings.progress:
            print(self.progress_line(), file=sys.stderr)

    def progress_line(self) -> str:
        """One line per iteration: cells reached and explored, the iteration's time and rate, and what the next
        iteration will take at that rate (the flood fill's total is not known before it ends: a workspace
        is as large as it turns out to be)."""
        now, (t0, reached0, expanded) = time.perf_counter(), self._clock
        dt, gained = now - t0, len(self.reached) - reached0
        self._clock = (now, len(self.reached), max(len(self.frontier), 1))
        line = (f"forward-backward: iteration {self.counters['iterations']}: {len(self.frontier)} new cells, "
                f"{len(self.reached)} reached, {self.counters['explored']} explored; {dt:.1f} s")
        if gained > 0 and self.frontier:
            line += (f" ({gained / dt:.3g} cells/s); next: {len(self.frontier)} cells to expand, ~"
                     f"{dt * len(self.frontier) / expanded:.0f} s at this rate")
        return line

    # ------------------------------------------------------------------ checkpoints and the result
    def save(self) -> None:
        """A checkpoint at an iteration boundary, where the state is complete and the run deterministic."""
        if self.run.directory is None:
            return
        m = self.model
        ids = {id(c): i for i, c in enumerate(self.reached)}
        fr = np.array(sorted(ids[id(c)] for c in self.frontier), dtype=np.int64)
        reached = self.reached
        arrays = dict(cells=np.array([c.cell for c in reached]), p=np.array([c.p for c in reached]),
                      u=np.array([c.u for c in reached]), frontier=fr,
                      frontier_q=np.array([reached[i].q for i in fr]).reshape(len(fr), m.n_dof),
                      frontier_A=np.array([reached[i].A for i in fr]).reshape(len(fr), 3, m.n_u),
                      frontier_S=np.array([reached[i].S for i in fr]).reshape(len(fr), m.n_free, m.n_u),
                      visited=np.array(sorted(self.visited)).reshape(-1, 3),
                      visited_pts=np.array(self.visited_pts).reshape(-1, 3),
                      failed_targets=np.array(self.failed_targets).reshape(-1, 3),
                      failed_status=np.array(self.failed_status, dtype=int),
                      failed_closest=np.array(self.failed_closest).reshape(-1, 3),
                      **{f"map_{k}": v for k, v in stack([c.maps for c in reached], m.n_u).items()},
                      violations=np.array([c.violations for c in reached], dtype=np.int64),
                      excluded_p=np.array([e[0] for e in self.excluded]).reshape(-1, 3),
                      excluded_u=np.array([e[1] for e in self.excluded]).reshape(-1, m.n_u),
                      excluded_violations=np.array([e[2] for e in self.excluded], dtype=np.int64))
        if self.settings.store_states:
            arrays["q"] = np.array([c.q for c in reached])
        if self.seeds is not None:
            arrays.update(self.seeds.arrays())
        if all(reached[i].Q is not None for i in fr):  # reduced backward
            arrays["frontier_Q"] = np.array([reached[i].Q for i in fr], dtype=np.float32).reshape(
                len(fr), m.n_u * (m.n_u + 1) // 2, m.n_free)
            arrays["frontier_Q_age"] = np.array([reached[i].Q_age for i in fr], dtype=np.int64)
            arrays["frontier_predictor_error"] = np.array(
                [np.nan if reached[i].predictor_error is None else reached[i].predictor_error for i in fr])
        self.run.save({"counters": self.counters, "timings": self.timings}, arrays)

    def restore(self, meta: dict, a: dict) -> None:
        self.counters.update(meta["counters"])
        self.timings.update({k: v for k, v in meta["timings"].items() if k.startswith("step")})
        fset = set(int(i) for i in a["frontier"])
        self.reached = []
        for i in range(len(a["cells"])):
            f = i in fset
            k = int(np.searchsorted(a["frontier"], i)) if f else -1
            self.reached.append(_Config(tuple(int(c) for c in a["cells"][i]), a["p"][i],
                                        a["frontier_q"][k] if f else (a["q"][i] if "q" in a else None), a["u"][i],
                                        a["frontier_A"][k] if f else None, a["frontier_S"][k] if f else None,
                                        a["frontier_Q"][k] if f and "frontier_Q" in a else None,
                                        int(a["frontier_Q_age"][k]) if f and "frontier_Q" in a else 0,
                                        int(a["violations"][i])))
        self.frontier = [self.reached[i] for i in sorted(fset)]
        for c, e in zip(self.frontier, a.get("frontier_predictor_error", ())):
            c.predictor_error = None if np.isnan(e) else float(e)
        self.reached_cells = {c.cell for c in self.reached}
        self.visited = {tuple(int(c) for c in v) for v in a["visited"]}
        self.visited_pts = list(a["visited_pts"])
        self.failed_targets, self.failed_status = list(a["failed_targets"]), list(a["failed_status"])
        self.failed_closest = list(a["failed_closest"])
        for i, c in enumerate(self.reached):
            c.maps = {k[4:]: a[k][i] for k in a if k.startswith("map_")}
        self.excluded = list(zip(a["excluded_p"], a["excluded_u"], (int(v) for v in a["excluded_violations"])))
        if self.seeds is not None:
            self.seeds.restore(a)

    def result(self, build_model: float) -> WorkspaceResult:
        self.counters["stopped_at_max_cells"] = bool(self.frontier)
        self.counters["feasible"] = len(self.reached)
        self.counters["factorizations_per_cell"] = self.counters["factorizations"] / len(self.reached)
        timings = {"build_model": build_model, **self.timings, "total": self.run.elapsed(),
                   "before_resume": self.run.previous}
        reached, settings = self.reached, self.settings
        failed_targets, failed_status, closest = self.failed_targets, self.failed_status, self.failed_closest
        if self.uniform:  # a target missed by one solve whose cell another answer landed in is reached
            keep = [self.grid.index(tg) not in self.reached_cells for tg in failed_targets]
            failed_targets = [tg for tg, k in zip(failed_targets, keep) if k]
            failed_status = [s for s, k in zip(failed_status, keep) if k]
            closest = [c for c, k in zip(closest, keep) if k]
        arrays = {"cell_step": np.array(settings.step if self.uniform else np.nan)}
        if self.uniform:
            arrays["cells"] = np.array([c.cell for c in reached], dtype=np.int64)
            arrays["cells_centres"] = np.array([self.grid.centre(c.cell) for c in reached])
            arrays["grid_origin"] = self.grid.origin
        arrays["failed_closest"] = np.array(closest).reshape(-1, 3)
        arrays.update({f"map_{k}": v for k, v in stack([c.maps for c in reached], self.model.n_u).items()})
        arrays.update(excluded_points=np.array([e[0] for e in self.excluded]).reshape(-1, 3),
                      excluded_u=np.array([e[1] for e in self.excluded]).reshape(-1, self.model.n_u),
                      excluded_violations=np.array([e[2] for e in self.excluded], dtype=np.int64))
        return WorkspaceResult(
            method="forward-backward", points=np.array([c.p for c in reached]), u=np.array([c.u for c in reached]),
            failed_u=np.array(failed_targets).reshape(-1, 3), failed_status=np.array(failed_status, dtype=int),
            failed_residual=np.full(len(failed_status), np.nan),
            states=np.array([c.q for c in reached]) if settings.store_states else None,
            violations=np.array([c.violations for c in reached], dtype=np.int64), counters=self.counters, timings=timings, settings=asdict(settings),
            problem=describe(self.problem, self.model), rest_tip=self.model.p0, arrays=arrays)


def forward_backward(problem, settings: FBSettings | None = None, model: StaticModel | None = None,
                     step: float | None = None, checkpoint_dir=None, resume: bool = False,
                     executor: Executor | None = None) -> WorkspaceResult:
    """Estimate the workspace by Algorithm 1; see :class:`FBSettings`.

    With ``checkpoint_dir``, a checkpoint is saved there after every iteration; ``resume=True`` continues
    from it and ends with the same result as an uninterrupted run. ``executor`` runs the backward solves
    (default: ``settings.workers`` processes, or this process).
    """
    settings = settings or FBSettings()
    if step is not None:
        settings.step = float(step)
    if settings.strategy not in ("uniform", "relative"):
        raise ValueError(f"strategy must be 'uniform' or 'relative', got {settings.strategy!r}")
    if settings.backward.tangent_products not in ("auto", "assembled", "differences"):
        raise ValueError(f"backward.tangent_products must be 'auto', 'assembled' or 'differences', "
                         f"got {settings.backward.tangent_products!r}")
    age = settings.backward.curvature_age
    if age != "auto" and (isinstance(age, bool) or not isinstance(age, (int, np.integer)) or age < 0):
        raise ValueError(f"backward.curvature_age must be 'auto' or an integer >= 0, got {age!r}")
    with one_blas_thread(), small_pages():
        t0 = time.perf_counter()
        model = model or StaticModel(problem)
        build_model = time.perf_counter() - t0
        if settings.step is None:
            settings.step = default_step(model)
        # the budget is not part of the answer: a run stopped by it resumes with a larger one
        # checkpoint format 11: the maps with the tip's roll and axis (10: solves checked for their branch, counted
        # path_dependent; 9: the seeds' Q; 8: the
        # frontier's Q ages; 7: the boundary surface's seeds; 6: the
        # contact map; 5: maps with the actuators' intensities; 4: reached points carry their maps, failures their
        # closest points; 2: frontiers carry Q);
        # an older checkpoint would resume without them and so end with another result than an uninterrupted run
        fp = fingerprint("forward-backward", model, asdict(settings) | {"workers": None, "progress": None,
                                                                         "max_cells": None, "format": 11})
        run = RunState(checkpoint_dir, "forward-backward", fp, resume, t0)

        own = executor is None
        executor = executor or make_executor(settings.workers, model, problem)  # workers start meanwhile
        try:
            # initial configuration: the equilibrium at u = u_min (U^(0) = U)
            eq = solve_equilibrium(model, model.u_min.copy())
            if eq.status != CONVERGED:
                raise RuntimeError(f"no equilibrium at u = u_min ({eq.status_name}); cannot start")
            start_check = admissibility(model, eq.q, eq.u, eq.factorization)
            if not start_check.admissible and not problem.admissibility.keep:
                raise RuntimeError(f"the equilibrium at u = u_min is not admissible "
                                   f"({', '.join(start_check.violations)}); cannot start")
            grid = Grid(eq.tip, settings.step) if settings.strategy == "uniform" else None
            fac0 = tangent_factorization(model, eq.q, eq.u)
            A0, S0, Q0, G0 = _derivatives(model, eq.q, eq.u, fac0, settings.step, settings.backward)
            start = _Config(grid.index(eq.tip) if grid else (0, 0, 0), eq.tip, eq.q, eq.u.copy(), A0, S0, Q0, 0,
                            start_check.mask, point_maps(model, eq.q, eq.u, A0, fac0, G0))
            ex = Exploration(problem, model, settings, run, start, grid)
            ex.counters["equilibrium_solves"] += 1
            ex.counters["factorizations"] += 1
            if run.saved is not None:
                ex.restore(*run.saved)
            with deferred_interrupt() as ctrl_c:  # Ctrl-C stops between solves; the last checkpoint stays
                algorithm1(ex, executor, ctrl_c)
            surface = None
            if settings.boundary.enabled and not ex.frontier:
                t = time.perf_counter()
                dets = [(c.u, c.maps.get("det_A", np.nan)) for c in ex.reached if c.maps]
                surface = boundary(model, settings.boundary, executor=executor, problem=problem, seeds=ex.seeds,
                                   samples=(np.array([d[0] for d in dets]), np.array([d[1] for d in dets])))
                surface.check_points(np.array([c.p for c in ex.reached]))
                ex.timings["boundary"] = time.perf_counter() - t
        finally:
            if own:
                executor.close()
        if settings.backward.formulation == "ipopt":
            from ..nlp.formulations import release_solvers

            release_solvers(model)
        result = ex.result(build_model)
        result.boundary = surface
        if not result.counters["stopped_at_max_cells"]:
            run.finish()  # complete: the result files replace the checkpoint, which a budget stop keeps
        return result

