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
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from .checkpoint import CHECKPOINT, fingerprint, load_checkpoint, save_checkpoint
from .equilibrium import (CONVERGED, OUTSIDE_BOUNDS, Equilibrium, Factorization, factorize, newton_krylov,
                          solve_equilibrium)
from .model import StaticModel
from .parallel import deferred_interrupt, one_blas_thread, process_pool
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
    checkpoint_every: float = 30.0
    """Seconds between checkpoints when the run has an output directory (see :func:`forward`)."""
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
    # clip: u_min + 1.0 (u_max - u_min) can exceed u_max by an ulp, which the bounds check would refuse
    return np.clip(u_min + axes[idx] * (u_max - u_min), u_min, u_max)


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


@dataclass
class _Sweep:
    """What carries from one point of the sweep to the next."""

    history: list = field(default_factory=list)  # verified (u, q) since the last failure, newest last (<= 3)
    fac: object = None  # the last LU, for the tangent predictor at turns
    start: tuple | None = None  # the last verified (q, u), for continuation after a failure


def _solve_point(model, u, j, settings, tol, sw: _Sweep, counters):
    """Solve one point of the sweep from what ``sw`` carries; updates ``sw`` and ``counters``."""
    if sw.history:
        guess = _predict(model, sw.history, u, sw.fac, settings.predictor)
        u0, q0 = sw.history[-1]
        nk = newton_krylov(model, u, guess, sw.fac, tol) if (settings.krylov and sw.fac is not None) else None
        if nk is not None:
            q_nk, rel, n_kry = nk
            counters["krylov_iterations"] += n_kry
            inside = np.all(u >= model.u_min - 1e-12) and np.all(u <= model.u_max + 1e-12)
            eq = Equilibrium(q_nk, u.copy(), model.tip(q_nk), CONVERGED if inside else OUTSIDE_BOUNDS, 1, 0,
                             rel, 0, sw.fac)
        else:
            eq = solve_equilibrium(model, u, q0=q0, u0=u0, guess=guess,
                                   fac=sw.fac if settings.reuse_factorization else None,
                                   tol=settings.tol, max_iter=settings.max_iter)
    else:
        if j > 0:
            counters["restarts"] += 1
        q0, u0 = (None, None) if sw.start is None else sw.start
        eq = solve_equilibrium(model, u, q0=q0, u0=u0, tol=settings.tol, max_iter=settings.max_iter)
    counters["solves"] += 1
    counters["newton_iterations"] += eq.iterations
    counters["factorizations"] += eq.factorizations
    counters["load_steps"] += eq.load_steps
    if eq.status == CONVERGED:
        sw.history = (sw.history + [(u.copy(), eq.q)])[-3:]
        if eq.factorization is not None:  # a point verified without a Newton step keeps the last LU
            sw.fac = eq.factorization
        sw.start = (eq.q, u.copy())
    else:
        sw.history = []  # next point: continuation from the last verified equilibrium
        sw.fac = None
    return eq


def _sweep(model: StaticModel, us: np.ndarray, settings: ForwardSettings, progress=None,
           resume: dict | None = None, checkpoint=None):
    """Solve the equilibria at ``us`` in order; returns per-point arrays and counters.

    ``checkpoint`` (if given) is called with the sweep's state every ``settings.checkpoint_every`` seconds
    and on Ctrl-C; passing such a state back as ``resume`` continues where it stopped.
    """
    n = len(us)
    tips = np.full((n, 3), np.nan)
    status = np.zeros(n, dtype=int)
    residual = np.zeros(n)
    states = np.zeros((n, model.n_dof)) if settings.store_states else None
    counters = dict(solves=0, newton_iterations=0, factorizations=0, load_steps=0, restarts=0,
                    krylov_iterations=0)
    tol = model.problem.solver.tolerance if settings.tol is None else settings.tol
    sw = _Sweep()
    first = 0
    if resume is not None:
        first = int(resume["next"])
        tips[:first], status[:first], residual[:first] = resume["tips"], resume["status"], resume["residual"]
        if states is not None:
            states[:first] = resume["states"]
        counters.update(resume["counters"])
        sw.history = list(zip(resume["hist_u"], resume["hist_q"]))
        if len(resume["start_q"]):
            sw.start = (resume["start_q"], resume["start_u"])
        if sw.history:  # the LU is not saved: refactorise at the last verified point (tangent predictor)
            u_last, q_last = sw.history[-1]
            _, K, _ = model.residual_and_tangent(q_last, u_last)
            sw.fac = Factorization(factorize(K), q_last.copy())
        if progress is not None:
            progress(first)

    def state(nxt):
        st = dict(next=nxt, tips=tips[:nxt], status=status[:nxt], residual=residual[:nxt],
                  counters=dict(counters),
                  hist_u=np.array([h[0] for h in sw.history]).reshape(len(sw.history), model.n_u),
                  hist_q=np.array([h[1] for h in sw.history]).reshape(len(sw.history), model.n_dof),
                  start_q=np.zeros(0) if sw.start is None else sw.start[0],
                  start_u=np.zeros(0) if sw.start is None else sw.start[1])
        if states is not None:
            st["states"] = states[:nxt]
        return st

    last_save = time.perf_counter()
    done = first  # points whose results, history and counters are all recorded
    try:
        with deferred_interrupt() as ctrl_c:
            for j in range(first, n):
                snapshot = (list(sw.history), sw.fac, sw.start, dict(counters))
                try:
                    eq = _solve_point(model, us[j], j, settings, tol, sw, counters)
                except KeyboardInterrupt:  # a second Ctrl-C mid-point: forget it, it is solved again on resume
                    sw.history, sw.fac, sw.start, counters = snapshot
                    raise
                tips[j], status[j], residual[j] = eq.tip, eq.status, eq.residual
                if states is not None and eq.status == CONVERGED:
                    states[j] = eq.q
                done = j + 1
                if progress is not None:
                    progress(1)
                if checkpoint is not None and time.perf_counter() - last_save > settings.checkpoint_every:
                    checkpoint(state(done))
                    last_save = time.perf_counter()
                ctrl_c.check()  # Ctrl-C stops here, between points, where the state is complete
    except KeyboardInterrupt:
        if checkpoint is not None:
            checkpoint(state(done))
        raise
    return tips, status, residual, states, counters


def _worker(args):
    problem, us, settings = args
    model = StaticModel(problem)
    return _sweep(model, us, settings)


def forward(problem, n_d: int | None = None, settings: ForwardSettings | None = None,
            model: StaticModel | None = None, checkpoint_dir=None, resume: bool = False) -> WorkspaceResult:
    """Estimate the workspace by the forward method; see :class:`ForwardSettings`.

    With ``checkpoint_dir``, the run saves a checkpoint there every ``settings.checkpoint_every`` seconds
    and when interrupted (Ctrl-C); ``resume=True`` continues from it (see :mod:`casadi_ws.checkpoint`).
    """
    with one_blas_thread():
        return _forward(problem, n_d, settings, model, checkpoint_dir, resume)


def _forward(problem, n_d, settings, model, checkpoint_dir=None, resume=False) -> WorkspaceResult:
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
    fp = fingerprint("forward", model, {k: getattr(settings, k) for k in
                                        ("n_d", "predictor", "reuse_factorization", "krylov", "tol", "max_iter",
                                         "store_states")} | {"workers": workers})
    saved_meta, saved = ({}, None)
    if resume:
        if checkpoint_dir is None:
            raise ValueError("resume needs the checkpoint directory")
        saved_meta, saved = load_checkpoint(checkpoint_dir, fp)
    previous = float(saved_meta.get("elapsed", 0.0))

    def save(meta, arrays):
        if checkpoint_dir is not None:
            save_checkpoint(checkpoint_dir, {"fingerprint": fp, "method": "forward",
                                             "elapsed": previous + time.perf_counter() - t0, **meta}, arrays)

    try:
        if workers == 1:
            resume_state = None
            if saved is not None:
                resume_state = dict(saved, next=saved_meta["next"], counters=saved_meta["counters"])

            def checkpoint(st):
                save({"next": st["next"], "counters": st["counters"]},
                     {k: v for k, v in st.items() if k not in ("next", "counters")})

            tips, status, residual, states, counters = _sweep(
                model, us, settings, progress=bar.update if bar else None, resume=resume_state,
                checkpoint=checkpoint if checkpoint_dir is not None else None)
        else:
            tips, status, residual, states, counters = _parallel(problem, us, settings, workers, bar,
                                                                 saved_meta, saved, save)
    finally:
        if bar is not None:
            bar.close()
    t_sweep = time.perf_counter() - t1
    if checkpoint_dir is not None:
        (Path(checkpoint_dir) / CHECKPOINT).unlink(missing_ok=True)  # complete: the result files replace it

    ok = status == CONVERGED
    rest = model.p0
    counters["points"] = n
    result = WorkspaceResult(
        method="forward", points=tips[ok], u=us[ok], failed_u=us[~ok], failed_status=status[~ok],
        failed_residual=residual[~ok], states=states[ok] if states is not None else None, counters=counters,
        timings={"build_model": t_model, "sweep": t_sweep, "total": time.perf_counter() - t0 + previous,
                 "per_point": t_sweep / n, "before_resume": previous},
        settings={**asdict(settings), "workers": workers}, problem=describe(problem, model), rest_tip=rest)
    return result


def _parallel(problem, us, settings, workers, bar, saved_meta, saved, save):
    """Slices of whole grid lines, several per worker; each completed slice is checkpointed."""
    from concurrent.futures import as_completed

    n_lines = max(1, len(us) // settings.n_d)
    pieces = np.array_split(np.arange(len(us)), min(n_lines, 4 * workers))
    results = [None] * len(pieces)
    piece_counters = {int(k): v for k, v in saved_meta.get("pieces", {}).items()}
    for i in piece_counters:
        results[i] = (saved[f"tips_{i}"], saved[f"status_{i}"], saved[f"residual_{i}"],
                      saved.get(f"states_{i}"), piece_counters[i])
        if bar is not None:
            bar.update(len(pieces[i]))

    def checkpoint():
        arrays = {}
        for i, r in enumerate(results):
            if r is not None:
                arrays.update({f"tips_{i}": r[0], f"status_{i}": r[1], f"residual_{i}": r[2]})
                if r[3] is not None:
                    arrays[f"states_{i}"] = r[3]
        save({"pieces": {i: r[4] for i, r in enumerate(results) if r is not None}}, arrays)

    with process_pool(workers) as ex:
        futs = {ex.submit(_worker, (problem, us[p], settings)): i for i, p in enumerate(pieces)
                if results[i] is None}
        try:
            for f in as_completed(futs):
                results[futs[f]] = f.result()
                checkpoint()
                if bar is not None:
                    bar.update(len(pieces[futs[f]]))
        except KeyboardInterrupt:
            for f in futs:
                f.cancel()
            raise
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
