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
reached; per (10) it is not tried again.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field

import numpy as np

from .backward import BackwardSettings, backward
from .equilibrium import CONVERGED, Factorization, factorize, solve_equilibrium
from .forward import describe
from .interval import Grid, interval_box, neighbourhood, sensitivity
from .model import StaticModel
from .result import WorkspaceResult

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
    max_cells: int = 200_000
    """Stop (with a note in the counters) after exploring this many grid points."""
    store_states: bool = False
    """Keep every reached point's nodal displacements."""
    progress: bool = True
    """Print one line per iteration on stderr."""


@dataclass
class _Config:
    cell: tuple
    p: np.ndarray
    q: np.ndarray
    u: np.ndarray
    fac: Factorization | None = None


def forward_backward(problem, settings: FBSettings | None = None, model: StaticModel | None = None,
                     step: float | None = None) -> WorkspaceResult:
    """Estimate the workspace by Algorithm 1; see :class:`FBSettings`."""
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
                    factorizations=0, not_reached=0, backward_failed=0, stopped_at_max_cells=False)

    # initial configuration: the equilibrium at u = u_min (U^(0) = U)
    eq = solve_equilibrium(model, model.u_min.copy())
    if eq.status != CONVERGED:
        raise RuntimeError(f"no equilibrium at u = u_min ({eq.status_name}); cannot start")
    counters["equilibrium_solves"] += 1
    p0 = eq.tip
    uniform = settings.strategy == "uniform"
    grid = Grid(p0, settings.step) if uniform else None
    start = _Config(grid.index(p0) if uniform else (0, 0, 0), p0, eq.q, eq.u.copy())

    reached = [start]  # feasible configurations: W_Es over all iterations
    visited = {start.cell}  # W_E-union: grid points already explored (uniform) ...
    visited_pts = [p0]  # ... or their positions (relative strategy)
    failed_targets, failed_status = [], []
    frontier = [start]
    while frontier and counters["explored"] < settings.max_cells:
        counters["iterations"] += 1
        new_frontier = []
        for cfg in frontier:
            # Step 1: interval over-estimation at cfg, with its input bound (9)
            t = time.perf_counter()
            if cfg.fac is None:
                _, K, _ = model.residual_and_tangent(cfg.q, cfg.u)
                cfg.fac = Factorization(factorize(K), cfg.q.copy())
                counters["factorizations"] += 1
            A, _ = sensitivity(model, cfg.q, cfg.fac)
            lower, upper = interval_box(A, cfg.p, model.u_min - cfg.u, model.u_max - cfg.u)
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
                cell = tuple(np.asarray(cfg.cell) + off) if uniform else None
                if uniform:
                    if cell in visited:
                        continue
                    visited.add(cell)
                else:
                    if np.min(np.max(np.abs(np.asarray(visited_pts) - target), axis=1)) < 0.5 * eta:
                        continue
                    visited_pts.append(target)
                todo.append((cell, target))
            counters["explored"] += len(todo)
            timings["step2_neighbourhood"] += time.perf_counter() - t

            # Step 3: backward problem (8) for each, warm-started from cfg
            t = time.perf_counter()
            for cell, target in todo:
                res = backward(model, target, cfg.q, cfg.u, cfg.fac, eta, settings.backward)
                counters["backward_solves"] += 1
                counters["equilibrium_solves"] += res.equilibrium_solves
                counters["factorizations"] += res.factorizations
                inside = bool(np.all(np.abs(res.tip - target) <= 0.5 * eta * (1 + 1e-9)))
                if res.ok and inside:
                    new = _Config(cell if uniform else (0, 0, 0), res.tip, res.q, res.u, None)
                    new_frontier.append(new)  # Step 4: carries its bound U^(j) = U - u^(j)
                    reached.append(new)
                else:
                    counters["backward_failed" if not res.ok else "not_reached"] += 1
                    failed_targets.append(target)
                    failed_status.append(res.status if not res.ok else -1)
            timings["step3_backward"] += time.perf_counter() - t
            cfg.fac = None  # expanded: its factorisation is no longer needed
        frontier = new_frontier
        if settings.progress:
            import sys

            print(f"forward-backward: iteration {counters['iterations']}: {len(new_frontier)} new cells, "
                  f"{len(reached)} reached, {counters['explored']} explored", file=sys.stderr)
    if settings.backward.formulation == "ipopt":
        from .nlp import release_solvers

        release_solvers()
    counters["stopped_at_max_cells"] = bool(frontier)
    counters["feasible"] = len(reached)
    timings["total"] = time.perf_counter() - t0

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
        counters=counters, timings=timings, settings=_plain(settings), problem=describe(problem, model),
        rest_tip=model.p0, arrays=arrays)


def _plain(settings: FBSettings) -> dict:
    d = asdict(settings)
    return d
