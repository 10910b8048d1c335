"""The forward method (publication, Section 4.1): grid the input box U, solve the equilibrium at every node.

Each actuator's bound [u_min, u_max] is split into ``n_d`` values, and the n_d^n_u combinations are visited
in serpentine ("snake") order, so consecutive inputs differ by one grid step in one actuator and each
solve is warm-started from an already solved neighbour. The first iterate is predicted by extrapolating
the previous solutions along the current grid line (quadratic from three, linear from two; the tangent
K^-1 dR/du du at a turn), which leaves an error of ~1e-8 m on the trunk: one Newton step then verifies
the point. Measured alternatives (chord steps with a reused factorisation, plain warm start) are slower
on geometrically nonlinear robots; see BENCHMARKS.md.

Every point is checked (relative residual below tolerance, u inside U). A point that fails is kept as a
failure with its u and status, never among the reachable points; the sweep then restarts from the last
verified equilibrium, by continuation if needed.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

from .equilibrium import CONVERGED, OUTSIDE_BOUNDS, Equilibrium, newton_krylov, solve_equilibrium
from .model import StaticModel
from .parallel import one_blas_thread, process_pool
from .result import WorkspaceResult

__all__ = ["ForwardSettings", "forward", "input_grid", "snake_order"]


@dataclass
class ForwardSettings:
    """Settings of the forward method."""

    n_d: int = 11
    """Values per actuator, bounds included: n_d^n_u equilibria (the publication used 100)."""
    predictor: str = "extrapolate"
    """``extrapolate`` (along the grid line, tangent at turns), ``tangent`` (K^-1 dR/du du) or ``none``."""
    reuse_factorization: bool = False
    """Try chord steps with the previous point's LU before refactorising (pays off for linear materials)."""
    krylov: bool = False
    """Newton with the exact tangent solved by GMRES, preconditioned by the last LU; a fresh LU only when
    GMRES needs more than 12 iterations (see :func:`casadi_ws.equilibrium.newton_krylov`). On the 1029-node
    trunk it saves 9 LUs in 10 but costs as much in GMRES work; it may pay on finer meshes."""
    store_states: bool = False
    """Keep every point's nodal displacements in the result (n_points x 3n floats)."""
    workers: int = 1
    """Processes sweeping slices of the grid in parallel, each with its own model."""
    progress: bool = True
    """Show a progress bar on stderr for runs longer than a moment."""
    tol: float | None = None
    """Relative residual tolerance; default: the problem's ``solver.tolerance``."""
    max_iter: int | None = None
    """Newton iterations per point; default: the problem's ``solver.max_iterations``."""


def snake_order(n_d: int, n_u: int) -> np.ndarray:
    """Multi-indices of an n_d^n_u grid, consecutive ones differing by 1 in exactly one coordinate.

    The last coordinate varies fastest; each coordinate sweeps back and forth (boustrophedon).
    """
    idx = np.arange(n_d)[:, None]
    for _ in range(n_u - 1):
        blocks = [np.hstack([np.full((len(idx), 1), i), idx if i % 2 == 0 else idx[::-1]]) for i in range(n_d)]
        idx = np.vstack(blocks)
    return idx


def input_grid(u_min, u_max, n_d: int) -> np.ndarray:
    """The inputs of the forward grid in snake order, (n_d^n_u, n_u)."""
    u_min, u_max = np.asarray(u_min, float), np.asarray(u_max, float)
    axes = np.linspace(0.0, 1.0, n_d) if n_d > 1 else np.zeros(1)
    idx = snake_order(n_d, u_min.size)
    return u_min + axes[idx] * (u_max - u_min)


def _predict(model, history, u, fac, mode):
    """First iterate for u from the previous verified points ``history`` [(u, q), ...] (newest last)."""
    u_prev, q_prev = history[-1]
    if mode == "none":
        return q_prev
    du = u - u_prev
    if mode == "extrapolate" and len(history) >= 2:
        # points on the same grid line, equally spaced, ending at the previous one
        line = [history[-1]]
        for k in range(len(history) - 2, max(len(history) - 4, -1), -1):
            if np.allclose(line[-1][0] - history[k][0], du):
                line.append(history[k])
            else:
                break
        if len(line) >= 3:
            return 3 * line[0][1] - 3 * line[1][1] + line[2][1]
        if len(line) == 2:
            return 2 * line[0][1] - line[1][1]
    if fac is None:
        return q_prev
    _, dL = model.cable_lengths(q_prev)
    q = q_prev.copy()
    q[model.free] -= fac.solve(dL[:, model.free].T @ du)
    return q


def _sweep(model: StaticModel, us: np.ndarray, settings: ForwardSettings, start=None, progress=None):
    """Solve the equilibria at ``us`` in order; returns per-point arrays and counters."""
    n = len(us)
    tips = np.full((n, 3), np.nan)
    status = np.zeros(n, dtype=int)
    residual = np.zeros(n)
    states = np.zeros((n, model.n_dof)) if settings.store_states else None
    counters = dict(solves=0, newton_iterations=0, factorizations=0, load_steps=0, restarts=0,
                    krylov_iterations=0)
    tol = model.problem.solver.tolerance if settings.tol is None else settings.tol
    history = []  # verified (u, q) since the last failure, newest last (at most 3 kept)
    fac = None
    for j, u in enumerate(us):
        if history:
            guess = _predict(model, history, u, fac, settings.predictor)
            u0, q0 = history[-1]
            nk = None
            if settings.krylov and fac is not None:
                nk = newton_krylov(model, u, guess, fac, tol)
            if nk is not None:
                q_nk, rel, n_kry = nk
                counters["krylov_iterations"] += n_kry
                eq = Equilibrium(q_nk, u.copy(), model.tip(q_nk), CONVERGED, 1, 0, rel, 0, fac)
                if np.any(u < model.u_min - 1e-12) or np.any(u > model.u_max + 1e-12):
                    eq.status = OUTSIDE_BOUNDS
            else:
                eq = solve_equilibrium(model, u, q0=q0, u0=u0, guess=guess,
                                       fac=fac if settings.reuse_factorization else None,
                                       tol=settings.tol, max_iter=settings.max_iter)
        else:
            if j > 0:
                counters["restarts"] += 1
            q0, u0 = (None, None) if start is None else start
            eq = solve_equilibrium(model, u, q0=q0, u0=u0, tol=settings.tol, max_iter=settings.max_iter)
        counters["solves"] += 1
        counters["newton_iterations"] += eq.iterations
        counters["factorizations"] += eq.factorizations
        counters["load_steps"] += eq.load_steps
        tips[j], status[j], residual[j] = eq.tip, eq.status, eq.residual
        if eq.status == CONVERGED:
            history = (history + [(u.copy(), eq.q)])[-3:]
            fac = eq.factorization
            start = (eq.q, u.copy())
            if states is not None:
                states[j] = eq.q
        else:
            history = []  # next point: continuation from the last verified equilibrium
            fac = None
        if progress is not None:
            progress(1)
    return tips, status, residual, states, counters


def _worker(args):
    problem, us, settings = args
    model = StaticModel(problem)
    return _sweep(model, us, settings)


def forward(problem, n_d: int | None = None, settings: ForwardSettings | None = None,
            model: StaticModel | None = None) -> WorkspaceResult:
    """Estimate the workspace by the forward method; see :class:`ForwardSettings`."""
    with one_blas_thread():
        return _forward(problem, n_d, settings, model)


def _forward(problem, n_d, settings, model) -> WorkspaceResult:
    settings = settings or ForwardSettings()
    if n_d is not None:
        settings.n_d = int(n_d)
    if settings.n_d < 1:
        raise ValueError(f"n_d must be >= 1, got {settings.n_d}")
    t0 = time.perf_counter()
    model = model or StaticModel(problem)
    t_model = time.perf_counter() - t0
    us = input_grid(model.u_min, model.u_max, settings.n_d)
    n = len(us)

    bar = None
    if settings.progress and n > 20:
        from tqdm import tqdm

        bar = tqdm(total=n, desc="forward", unit="pt", mininterval=0.5, leave=False)
    t1 = time.perf_counter()
    workers = max(1, min(int(settings.workers), n // 50 or 1))
    if workers == 1:
        tips, status, residual, states, counters = _sweep(model, us, settings,
                                                          progress=bar.update if bar else None)
    else:
        tips, status, residual, states, counters = _parallel(problem, us, settings, workers, bar)
    t_sweep = time.perf_counter() - t1
    if bar is not None:
        bar.close()

    ok = status == CONVERGED
    rest = model.p0
    counters["points"] = n
    result = WorkspaceResult(
        method="forward", points=tips[ok], u=us[ok], failed_u=us[~ok], failed_status=status[~ok],
        failed_residual=residual[~ok], states=states[ok] if states is not None else None, counters=counters,
        timings={"build_model": t_model, "sweep": t_sweep, "total": time.perf_counter() - t0,
                 "per_point": t_sweep / n},
        settings={**asdict(settings), "workers": workers}, problem=describe(problem, model), rest_tip=rest)
    return result


def _parallel(problem, us, settings, workers, bar):
    # slices of whole grid lines, several per worker so the progress bar moves
    n_line = settings.n_d
    n_lines = max(1, len(us) // n_line)
    pieces = np.array_split(np.arange(len(us)), min(n_lines, 4 * workers))
    results = [None] * len(pieces)
    with process_pool(workers) as ex:
        futs = {ex.submit(_worker, (problem, us[p], settings)): i for i, p in enumerate(pieces)}
        from concurrent.futures import as_completed

        for f in as_completed(futs):
            results[futs[f]] = f.result()
            if bar is not None:
                bar.update(len(pieces[futs[f]]))
    tips = np.vstack([r[0] for r in results])
    status = np.concatenate([r[1] for r in results])
    residual = np.concatenate([r[2] for r in results])
    states = np.vstack([r[3] for r in results]) if settings.store_states else None
    counters = {k: sum(r[4][k] for r in results) for k in results[0][4]}
    return tips, status, residual, states, counters


def describe(problem, model) -> dict:
    """Plain-data description of what was solved, for result files."""
    return {
        "name": problem.name, "source": problem.source, "n_nodes": problem.mesh.n_nodes,
        "n_tets": problem.mesh.n_tets, "n_free_dofs": model.n_free, "material": asdict(problem.material),
        "n_u": model.n_u, "cables": [c.name for c in problem.cables], "u_min": model.u_min.tolist(),
        "u_max": model.u_max.tolist(), "end_effector": np.asarray(problem.end_effector).tolist(),
        "tolerance": problem.solver.tolerance,
    }
