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
reached; per (10) it is not tried again. Failure codes in ``failed_status``: -1 not reached (the closest
point found lies outside the cell), -2 prefiltered (see ``FBSettings.prefilter``), >= 1 the backward
solve failed (see :mod:`casadi_ws.workspace.backward`).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from .backward import BackwardSettings, backward
from ..runtime.run_state import CHECKPOINT, fingerprint, load_checkpoint, save_checkpoint
from ..solvers.equilibrium import CONVERGED, Factorization, factorize, solve_equilibrium
from ..solvers.sensitivity import bounded_step, sensitivity
from .interval import Grid, interval_box, neighbourhood
from ..fem.model import StaticModel
from ..runtime.executor import deferred_interrupt, one_blas_thread, process_pool
from .result import WorkspaceResult, describe

__all__ = ["FBSettings", "forward_backward"]


@dataclass
class FBSettings:
    """Settings of the forward-backward method."""

    step: float = 0.004
    """Grid step s_Ed of the uniform strategy, metres."""
    strategy: str = "uniform"
    """``uniform`` (global grid anchored at the initial tip) or ``relative`` (step 5 % of ||p||)."""
    relative_ratio: float = 0.05
    """Step of the relative strategy as a fraction of ||p|| (the publication's 5 %)."""
    backward: BackwardSettings = field(default_factory=BackwardSettings)
    """How the backward problem (8) is solved."""
    prefilter: float | None = 0.1
    """Skip a target when the linearised closest point (bounded least squares with Step 1's A) lies more
    than (0.5 + prefilter) steps from it in some coordinate, i.e. a tenth of a cell outside the target's
    cell by default. Over a one-cell move the linearisation errs by ~s^2 x curvature (~0.04 s on the trunk
    at s = 4 mm), so such a cell is not reached (0.25 and 0.1 reach the same cells on the 2-, 3- and
    4-cable trunks; BENCHMARKS.md). Recorded as ``prefiltered``. None: off (the paper's rule)."""
    max_cells: int = 200_000
    """Stop (with a note in the counters and a warning in the summary) after the iteration in which this
    many grid points have been explored."""
    store_states: bool = False
    """Keep every reached point's nodal displacements."""
    workers: int = 1
    """Processes running the backward solves of an iteration in parallel, each with its own model. Cells
    are claimed before any solve, so the result does not depend on this number."""
    progress: bool = True
    """Print one line per iteration on stderr."""


@dataclass
class _Config:
    cell: tuple
    p: np.ndarray
    q: np.ndarray
    u: np.ndarray
    A: np.ndarray  # C K^-1 H^T at this configuration (Step 1)
    S: np.ndarray | None  # K^-1 H^T: the first Gauss-Newton step of its backward solves


def _expand(model, q, u, A, S, targets, scale, bsettings):
    """Step 3 for one configuration: backward solves of its targets; returns plain data per target.

    The sensitivities of each new configuration come from the backward's last Newton LU (one iterate
    from the answer: A is ~0.5 % off, far below what the box and the prefilter can notice). They travel
    with the configuration, so expanding it needs no LU, in this process or in a worker, and the result
    does not depend on the number of workers.
    """
    out = []
    for target in targets:
        res = backward(model, target, q, u, None, scale, bsettings, sens=(A, S))
        A_new = S_new = None
        n_fac = res.factorizations
        if res.ok:
            fac = res.fac
            if fac is None:
                _, K, _ = model.residual_and_tangent(res.q, res.u)
                fac = Factorization(factorize(K), res.q.copy())
                n_fac += 1
            A_new, S_new = sensitivity(model, res.q, fac)
        out.append((res.q, res.u, res.tip, res.status, res.ok, A_new, S_new, res.equilibrium_solves, n_fac))
    return out


_WORKER_MODEL = None


def _worker_init(problem):
    global _WORKER_MODEL
    _WORKER_MODEL = StaticModel(problem)


def _worker_expand(args):
    return _expand(_WORKER_MODEL, *args)


def forward_backward(problem, settings: FBSettings | None = None, model: StaticModel | None = None,
                     step: float | None = None, checkpoint_dir=None, resume: bool = False) -> WorkspaceResult:
    """Estimate the workspace by Algorithm 1; see :class:`FBSettings`.

    With ``checkpoint_dir``, a checkpoint is saved there after every iteration; ``resume=True`` continues
    from it and ends with the same result as an uninterrupted run.
    """
    with one_blas_thread():
        return _forward_backward(problem, settings, model, step, checkpoint_dir, resume)


def _forward_backward(problem, settings, model, step, checkpoint_dir=None, resume=False) -> WorkspaceResult:
    settings = settings or FBSettings()
    if step is not None:
        settings.step = float(step)
    if settings.strategy not in ("uniform", "relative"):
        raise ValueError(f"strategy must be 'uniform' or 'relative', got {settings.strategy!r}")
    t0 = time.perf_counter()
    model = model or StaticModel(problem)
    timings = {"build_model": time.perf_counter() - t0, "step1_interval": 0.0, "step2_neighbourhood": 0.0,
               "step3_backward": 0.0}
    counters = dict(iterations=0, explored=0, feasible=0, backward_solves=0, equilibrium_solves=0,
                    factorizations=0, not_reached=0, prefiltered=0, backward_failed=0,
                    stopped_at_max_cells=False)

    # initial configuration: the equilibrium at u = u_min (U^(0) = U)
    eq = solve_equilibrium(model, model.u_min.copy())
    if eq.status != CONVERGED:
        raise RuntimeError(f"no equilibrium at u = u_min ({eq.status_name}); cannot start")
    counters["equilibrium_solves"] += 1
    p0 = eq.tip
    uniform = settings.strategy == "uniform"
    grid = Grid(p0, settings.step) if uniform else None
    _, K, _ = model.residual_and_tangent(eq.q, eq.u)
    A0, S0 = sensitivity(model, eq.q, Factorization(factorize(K), eq.q))
    counters["factorizations"] += 1
    start = _Config(grid.index(p0) if uniform else (0, 0, 0), p0, eq.q, eq.u.copy(), A0, S0)

    reached = [start]  # feasible configurations: W_Es over all iterations
    visited = {start.cell}  # W_E-union: grid points already explored (uniform) ...
    visited_pts = [p0]  # ... or their positions (relative strategy)
    failed_targets, failed_status = [], []
    frontier = [start]

    # checkpoints at iteration boundaries, where the state is complete and the run deterministic
    fp = fingerprint("forward-backward", model, asdict(settings) | {"workers": None, "progress": None})
    previous = 0.0
    if resume:
        if checkpoint_dir is None:
            raise ValueError("resume needs the checkpoint directory")
        meta, a = load_checkpoint(checkpoint_dir, fp)
        previous = float(meta["elapsed"])
        counters.update(meta["counters"])
        timings.update({k: v for k, v in meta["timings"].items() if k.startswith("step")})
        fset = set(int(i) for i in a["frontier"])
        reached = []
        for i in range(len(a["cells"])):
            f = i in fset
            k = int(np.searchsorted(a["frontier"], i)) if f else -1
            reached.append(_Config(tuple(int(c) for c in a["cells"][i]), a["p"][i],
                                   a["frontier_q"][k] if f else (a["q"][i] if "q" in a else None), a["u"][i],
                                   a["frontier_A"][k] if f else None, a["frontier_S"][k] if f else None))
        frontier = [reached[i] for i in sorted(fset)]
        visited = {tuple(int(c) for c in v) for v in a["visited"]}
        visited_pts = list(a["visited_pts"])
        failed_targets, failed_status = list(a["failed_targets"]), list(a["failed_status"])

    def checkpoint():
        if checkpoint_dir is None:
            return
        ids = {id(c): i for i, c in enumerate(reached)}
        fr = np.array(sorted(ids[id(c)] for c in frontier), dtype=np.int64)
        arrays = dict(cells=np.array([c.cell for c in reached]), p=np.array([c.p for c in reached]),
                      u=np.array([c.u for c in reached]), frontier=fr,
                      frontier_q=np.array([reached[i].q for i in fr]).reshape(len(fr), model.n_dof),
                      frontier_A=np.array([reached[i].A for i in fr]).reshape(len(fr), 3, model.n_u),
                      frontier_S=np.array([reached[i].S for i in fr]).reshape(len(fr), model.n_free, model.n_u),
                      visited=np.array(sorted(visited)).reshape(-1, 3),
                      visited_pts=np.array(visited_pts).reshape(-1, 3),
                      failed_targets=np.array(failed_targets).reshape(-1, 3),
                      failed_status=np.array(failed_status, dtype=int))
        if settings.store_states:
            arrays["q"] = np.array([c.q for c in reached])
        save_checkpoint(checkpoint_dir, {"fingerprint": fp, "method": "forward-backward", "counters": counters,
                                         "timings": timings,
                                         "elapsed": previous + time.perf_counter() - t0}, arrays)

    bsettings = settings.backward
    if bsettings.give_up is None and bsettings.formulation == "reduced":
        bsettings = replace(bsettings, give_up=0.05)  # see BackwardSettings.give_up
    pool = _pool(problem, settings.workers) if settings.workers > 1 else None
    interrupt = deferred_interrupt()
    ctrl_c = interrupt.__enter__()  # Ctrl-C stops between configurations; the last iteration's checkpoint stays
    try:
        while frontier and counters["explored"] < settings.max_cells:
            counters["iterations"] += 1
            tasks = []
            for cfg in frontier:
                # Step 1: interval over-estimation at cfg, with its input bound (9)
                t = time.perf_counter()
                lower, upper = interval_box(cfg.A, cfg.p, model.u_min - cfg.u, model.u_max - cfg.u)
                timings["step1_interval"] += time.perf_counter() - t

                # Step 2 (7) and Step 5 (10): neighbours in the box, not yet explored
                t = time.perf_counter()
                if uniform:
                    centre, eta = grid.centre(cfg.cell), settings.step
                else:
                    centre, eta = cfg.p, settings.relative_ratio * float(np.linalg.norm(cfg.p))
                targets, offsets = neighbourhood(centre, eta, lower, upper)
                todo = []
                for target, off in zip(targets, offsets):
                    cell = tuple(np.asarray(cfg.cell) + off) if uniform else (0, 0, 0)
                    if uniform:
                        if cell in visited:
                            continue
                        visited.add(cell)
                    else:
                        if np.min(np.max(np.abs(np.asarray(visited_pts) - target), axis=1)) < 0.5 * eta:
                            continue
                        visited_pts.append(target)
                    counters["explored"] += 1
                    if settings.prefilter is not None:
                        gap = np.abs(_linear_closest(cfg.A, cfg.p, cfg.u, model, target) - target).max()
                        if gap > (0.5 + settings.prefilter) * eta:
                            counters["prefiltered"] += 1
                            failed_targets.append(target)
                            failed_status.append(-2)
                            continue
                    todo.append((cell, target))
                timings["step2_neighbourhood"] += time.perf_counter() - t
                if todo:
                    tasks.append((cfg, todo, eta))

            # Step 3: backward problem (8) for each kept target, warm-started from its configuration
            t = time.perf_counter()
            jobs = [(cfg.q, cfg.u, cfg.A, cfg.S, [tg for _, tg in todo], eta, bsettings)
                    for cfg, todo, eta in tasks]
            if pool is None:
                outs = []
                for j in jobs:
                    outs.append(_expand(model, *j))
                    ctrl_c.check()
            else:
                # the configurations with the most targets first, so no worker is left with a long one at
                # the end of the iteration (the results are put back in order: same result as 1 worker)
                order = sorted(range(len(jobs)), key=lambda i: -len(jobs[i][4]))
                outs = [None] * len(jobs)
                for i, out in zip(order, pool.map(_worker_expand, [jobs[i] for i in order])):
                    outs[i] = out
                ctrl_c.check()
            new_frontier = []
            for (cfg, todo, eta), out in zip(tasks, outs):
                for (cell, target), (q, u, tip, status, ok, A, S, n_eq, n_fac) in zip(todo, out):
                    counters["backward_solves"] += 1
                    counters["equilibrium_solves"] += n_eq
                    counters["factorizations"] += n_fac
                    if ok and np.all(np.abs(tip - target) <= 0.5 * eta * (1 + 1e-9)):
                        new = _Config(cell, tip, q, u, A, S)  # Step 4: carries its bound U - u
                        new_frontier.append(new)
                        reached.append(new)
                    else:
                        counters["backward_failed" if not ok else "not_reached"] += 1
                        failed_targets.append(target)
                        failed_status.append(status if not ok else -1)
                cfg.S = None  # expanded: no longer needed
            timings["step3_backward"] += time.perf_counter() - t
            frontier = new_frontier
            if not settings.store_states:
                for c in reached:  # only the frontier's states are needed from here on
                    if c.S is None:
                        c.q = None
            checkpoint()
            if settings.progress:
                import sys

                print(f"forward-backward: iteration {counters['iterations']}: {len(new_frontier)} new cells, "
                      f"{len(reached)} reached, {counters['explored']} explored", file=sys.stderr)
    finally:
        interrupt.__exit__(None, None, None)
        if pool is not None:
            pool.shutdown(cancel_futures=True)
    if settings.backward.formulation == "ipopt":
        from ..nlp.formulations import release_solvers

        release_solvers()
    counters["stopped_at_max_cells"] = bool(frontier)
    counters["feasible"] = len(reached)
    timings["total"] = time.perf_counter() - t0 + previous
    timings["before_resume"] = previous
    if checkpoint_dir is not None:
        (Path(checkpoint_dir) / CHECKPOINT).unlink(missing_ok=True)  # complete: the result files replace it

    pts = np.array([c.p for c in reached])
    arrays = {"cell_step": np.array(settings.step if uniform else np.nan)}
    if uniform:
        arrays["cells"] = np.array([c.cell for c in reached], dtype=np.int64)
        arrays["cells_centres"] = np.array([grid.centre(c.cell) for c in reached])
        arrays["grid_origin"] = grid.origin
    return WorkspaceResult(
        method="forward-backward", points=pts, u=np.array([c.u for c in reached]),
        failed_u=np.array(failed_targets).reshape(-1, 3), failed_status=np.array(failed_status, dtype=int),
        failed_residual=np.full(len(failed_status), np.nan),
        states=np.array([c.q for c in reached]) if settings.store_states else None,
        counters=counters, timings=timings, settings=asdict(settings), problem=describe(problem, model),
        rest_tip=model.p0, arrays=arrays)


def _pool(problem, workers):
    return process_pool(workers, _worker_init, (problem,))


def _linear_closest(A, p, u, model, target):
    """Tip of the linearised model closest to target over the remaining input range."""
    return p + A @ bounded_step(A, target - p, model.u_min - u, model.u_max - u)
