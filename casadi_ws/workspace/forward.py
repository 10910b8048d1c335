"""The forward method (publication, Section 4.1): grid the input box U, solve the equilibrium at every node.

Each actuator's bound [u_min, u_max] is split into ``n_d`` values, and the n_d^n_u combinations are visited
in serpentine ("snake") order: grid lines along the last actuator, consecutive lines running in opposite
directions, so every solve starts next to an already solved point.

Along a line, Newton solves every ``stride``-th point (default ~10-17 % of the range apart). Its first iterate is
the polynomial through the line's previous Newton points (up to 6; the tangent K^-1 dR/du du at a turn),
so one Newton step with a fresh factorisation finishes it. The points between are the polynomial through
the nearest (up to 8) Newton points of the line, and are accepted on the same check as any other point;
on the trunk they pass with residuals ~1e-10, so most points cost one residual evaluation instead of a
factorisation. Measured alternatives (chord steps or GMRES with an older factorisation, which the soft
modes of a cable-loaded body defeat) are in docs/methods.md and BENCHMARKS.md.

Every point is checked (relative residual below tolerance, u inside U). A point that fails is kept as a
failure with its u and status, never among the reachable points; the sweep then restarts from the last
verified equilibrium, by continuation if needed.
"""

from __future__ import annotations

import functools
import time
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from ..fem.model import StaticModel
from ..fem.spec import ranged_inputs
from ..runtime.executor import Executor, deferred_interrupt, make_executor, one_blas_thread, small_pages
from ..runtime.run_state import RunState, fingerprint
from ..solvers.admissible import VIOLATIONS, admissibility, encode
from ..solvers.equilibrium import (CONVERGED, OUTSIDE_BOUNDS, Branch, Equilibrium, admissible_guess, inside_bounds,
                                   newton_krylov, settle, solve_equilibrium, tangent_factorization, verify)
from ..solvers.sensitivity import sensitivity
from .maps import MAPS, point_maps, state_maps
from .result import WorkspaceResult, describe

__all__ = ["CUBE_STATES", "ForwardSettings", "SweepResult", "across_planes", "across_stride", "forward", "input_grid",
           "lagrange_weights", "line_stride", "new_counters", "snake_order", "sweep"]


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
    GMRES needs more than 12 iterations (see :func:`casadi_ws.solvers.equilibrium.newton_krylov`). On the 1029-node
    trunk it saves 9 LUs in 10 but costs as much in GMRES work; it may pay on finer meshes."""
    store_states: bool = False
    """Keep every point's nodal displacements in the result (n_points x 3n floats)."""
    maps: str = "exact"
    """``exact``: every point's steerability and compliance from a double-precision LU of its own tangent, at its
    state polished by one Newton step (within 1e-5 of central finite differences of independent equilibria on
    trunk_2cables, and within 1e-10 of each other whatever the grid's split among workers). It costs an LU per
    interpolated point: 2.4x the sweep of trunk_2cables at n_d = 100, where most points are interpolated, and
    the double LU with the polish +17 % more there (BENCHMARKS.md "forward"). ``interpolated``: exact maps at
    the Newton points only, linear between them along a line or across lines (an LU less per interpolated
    point; measured up to 8 % off finite differences on trunk_2cables at n_d = 11, and 15 % apart between a
    serial and a 2-worker run, whose Newton points differ). ``none``: no steerability and compliance at all (NaN;
    an LU less per Newton point): for sweeps whose maps nobody reads (the seeds of a fold's union or of the
    orientation ranges)."""
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
    stride: int | None = None
    """Along each grid line, Newton solves every ``stride``-th point (and the last); the points between are
    the polynomial through the nearest (up to 8) solved points of the line, accepted if their residual passes
    the same check, else solved by Newton from there (and interpolated from, for the points after it).
    1: Newton everywhere. Default: line by line, n_d // 6 (wide) or, on a line after one whose
    interpolations failed too often, n_d // 10 (narrow), both clamped to [1, 8] (docs/methods.md): on the
    linear trunks wide pays, on the 10-node trunk narrow."""
    across: int | None = None
    """With three or more actuators, the grid lines of a plane (the last two actuators varying) are solved
    as above only every ``across``-th line (and the last); the points of the lines between are the
    polynomial across lines through the nearest (up to 8) solved lines' points at the same input, accepted
    on the same check, else solved by Newton from there. They inherit stability and self-penetration from
    the solved lines either side when both pass those. The cube of three actuators is swept the same way
    plane by plane (see :func:`_cube`). 1: every line solved. Default with three or more actuators: n_d // 10,
    clamped to [1, 8] and at most ``stride`` (closer than ``stride``'s default: across lines the polynomial
    fails verification more often than along them); 1 with two (their sweep is already ~16 % Newton points
    at n_d = 100)."""


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
    """The inputs of the forward grid in snake order, (n_d^k, n_u) for the k inputs with a range: an input held
    at one value (u_min = u_max, a cable kept at its rest length) is no axis of the grid (n_d copies of every
    point otherwise: the SOFA Trunk with its four short cables held, 11^8 equilibria for 11^4)."""
    u_min, u_max = np.asarray(u_min, float), np.asarray(u_max, float)
    axes = np.linspace(0.0, 1.0, n_d) if n_d > 1 else np.zeros(1)
    active = ranged_inputs(u_min, u_max)
    idx = np.zeros((n_d ** active.size if active.size else 1, u_min.size), dtype=np.int64)
    if active.size:
        idx[:, active] = snake_order(n_d, active.size)
    # clip: u_min + 1.0 (u_max - u_min) can exceed u_max by an ulp, which the bounds check would refuse
    return np.clip(u_min + axes[idx] * (u_max - u_min), u_min, u_max)


def grid_inputs(problem) -> int:
    """How many inputs span the forward grid (those with a range; ``problem`` or a model)."""
    return int(ranged_inputs(problem.u_min, problem.u_max).size)


def lagrange_weights(xs, x) -> np.ndarray:
    """Weights w with sum_i w_i f(xs_i) = the polynomial through (xs_i, f(xs_i)) evaluated at x."""
    xs = np.asarray(xs, dtype=float)
    w = np.ones(xs.size)
    for i in range(xs.size):
        others = np.delete(xs, i)
        w[i] = np.prod((x - others) / (xs[i] - others))
    return w


@functools.lru_cache(maxsize=4096)
def _weights(xs: tuple, x: float) -> np.ndarray:
    """:func:`lagrange_weights`, remembered: the points of a line (plane) between solved ones share them."""
    return lagrange_weights(xs, x)


def _line_axis(u_a, u_b):
    """The one actuator in which u_a and u_b differ, or None."""
    d = np.flatnonzero(u_a != u_b)
    return int(d[0]) if d.size == 1 else None


def _predict(model, history, u, fac, mode):
    """First iterate for u from the previous verified points ``history`` [(u, q), ...] (newest last); the
    newest point itself where the prediction would take an element below the admissibility floor."""
    u_prev, q_prev = history[-1]
    if mode == "none":
        return q_prev
    q = None
    if mode == "extrapolate":
        line = _nearest_on_a_line(model, history, u)
        if line is not None:
            axis, xs, qs = line
            q = polynomial_guess(model, xs, qs, u[axis])
    if q is None and fac is not None:  # tangent predictor: K dq = H^T du
        q = q_prev.copy()
        q[model.free] += fac.solve(model.actuation_matrix(q_prev).T @ (u - u_prev))
    return q if q is not None and admissible_guess(model, q) else q_prev


def polynomial_guess(model, xs, qs, x) -> np.ndarray:
    """The polynomial through the states ``qs`` at inputs ``xs`` (nearest to x first), at x; or the straight
    line through the two nearest where the polynomial strays from that line by more than the line's own step
    from the nearest state. Measured on trunk_table: the polynomial's departure from the line is 3-5 % of that
    step on smooth stretches and 4-55 times it across a contact's switch, where the polynomial through six
    points overshot into the table (relative residual ~800) and Newton from it went to a crushed branch."""
    xs, x = tuple(float(v) for v in xs), float(x)
    poly = sum(w * q for w, q in zip(_weights(xs, x), qs))
    if len(xs) <= 2:
        return poly
    line = sum(w * q for w, q in zip(_weights(xs[:2], x), qs[:2]))
    f = model.free_mech
    return poly if np.linalg.norm((poly - line)[f]) <= np.linalg.norm((line - qs[0])[f]) else line


def _nearest_on_a_line(model, history, u):
    """(axis, xs, qs): the known points nearest to u on one grid line through u, the line with the most
    of them (up to 6) and, among those, the shortest reach. Along the current line they lie a stride apart,
    across lines (the same position on the previous lines) one grid step: that one extrapolates best."""
    hu = np.array([h[0] for h in history])
    width = np.where(model.u_max > model.u_min, model.u_max - model.u_min, 1.0)
    best = None
    for axis in range(u.size):
        others = np.arange(u.size) != axis
        on = np.flatnonzero(np.all(hu[:, others] == u[others], axis=1) & (hu[:, axis] != u[axis]))
        line = {}
        for k in on[::-1]:  # newest first
            line.setdefault(float(hu[k, axis]), history[k][1])
        xs = sorted(line, key=lambda x: abs(x - u[axis]))[:_EXTRAPOLATION_POINTS]
        if len(xs) < 2:
            continue
        key = (-len(xs), max(abs(x - u[axis]) for x in xs) / width[axis])
        if best is None or key < best[0]:
            best = (key, axis, xs, [line[x] for x in xs])
    return None if best is None else best[1:]


# Measured on the trunk (docs/methods.md): from exactly solved points one grid step apart, the polynomial
# through the last 6 leaves a relative residual ~1e-10 (3 points: ~1e-5); through 8 points 8 steps apart,
# interpolation leaves < 1e-9 -- below the tolerance, so the point needs no Newton step at all.
_EXTRAPOLATION_POINTS = 6
_INTERPOLATION_POINTS = 8
_HISTORY = 128  # Newton points kept: several lines' worth, so a line's first point extrapolates across lines
# Newton points are what the others are extrapolated and interpolated from: a residual just under the
# tolerance there would be amplified in those, so Newton goes on to 1 % of it (a quadratic step is cheap).
_POLISH = 1e-2


@dataclass
class _Sweep:
    """What carries from one point of the sweep to the next."""

    history: list = field(default_factory=list)  # verified Newton points (u, q) since the last failure, newest last
    fac: object = None  # the last LU, for the tangent predictor at turns
    start: tuple | None = None  # the last verified (q, u), for continuation after a failure
    narrow: bool = False  # the next line takes the narrow stride (see line_strides)


def new_counters() -> dict:
    """The sweep's counters, all zero: Newton ``solves`` (with their ``newton_iterations``,
    ``factorizations``, ``load_steps`` of continuation, ``krylov_iterations``), ``restarts`` after a failed
    point, points ``interpolated`` and verified, of which ``interpolation_failed`` did not pass and were
    solved by Newton from there (counted among the ``solves`` too); of the solves, ``branch_checks`` whose
    Newton shortened a step and whose branch was therefore checked, ``branch_paths`` of those re-solved along
    the path from their neighbour, ``branch_replaced`` whose answer the path replaced, and ``path_dependent``
    whose answer depends on the path (:class:`casadi_ws.solvers.equilibrium.Branch`)."""
    return dict(solves=0, newton_iterations=0, factorizations=0, load_steps=0, restarts=0, krylov_iterations=0,
                interpolated=0, interpolation_failed=0, branch_checks=0, branch_paths=0, branch_replaced=0,
                path_dependent=0)


@dataclass
class SweepResult:
    """The points of a sweep (or of a piece of the grid), in the order of its inputs."""

    tips: np.ndarray
    """(n, 3) end-effector positions (NaN where a point failed)."""
    status: np.ndarray
    """(n,) :class:`casadi_ws.status.Status` codes (0: verified)."""
    residual: np.ndarray
    """(n,) relative residuals."""
    violations: np.ndarray
    """(n,) admissibility masks (0: admissible)."""
    maps: np.ndarray
    """(n, len(MAPS) + 2 n_u): the point maps, then each actuator's state and intensity."""
    states: np.ndarray | None
    """(n, n_dof) nodal displacements where kept (``ForwardSettings.store_states``), else None."""
    counters: dict
    """:func:`new_counters`' counters of the points' solves."""

    ARRAYS = ("tips", "status", "residual", "violations", "maps", "states")
    """The per-point arrays, by name (checkpoints store them so)."""

    def __len__(self) -> int:
        return len(self.tips)

    @classmethod
    def concatenate(cls, parts: list["SweepResult"]) -> "SweepResult":
        """The pieces one after the other; their counters summed."""
        states = [p.states for p in parts]
        return cls(np.vstack([p.tips for p in parts]), np.concatenate([p.status for p in parts]),
                   np.concatenate([p.residual for p in parts]), np.concatenate([p.violations for p in parts]),
                   np.vstack([p.maps for p in parts]), None if any(x is None for x in states) else np.vstack(states),
                   {k: sum(p.counters[k] for p in parts) for k in parts[0].counters})


def _count(counters, eq):
    counters["solves"] += 1
    counters["newton_iterations"] += eq.iterations
    counters["factorizations"] += eq.factorizations
    counters["load_steps"] += eq.load_steps
    counters["branch_checks"] += eq.branch != Branch.NEAR
    counters["branch_paths"] += eq.branch >= Branch.PATH_AGREED
    counters["branch_replaced"] += eq.branch == Branch.PATH_REPLACED
    counters["path_dependent"] += eq.branch == Branch.PATH_DEPENDENT


def _solve_point(model, u, j, settings, tol, sw: _Sweep, counters):
    """Solve one point of the sweep from what ``sw`` carries; updates ``sw`` and ``counters``."""
    if sw.history:
        guess = _predict(model, sw.history, u, sw.fac, settings.predictor)
        u0, q0 = sw.history[-1]
        nk = newton_krylov(model, u, guess, sw.fac, tol) if (settings.krylov and sw.fac is not None) else None
        if nk is not None:
            q_nk, rel, n_kry = nk
            counters["krylov_iterations"] += n_kry
            status = CONVERGED if inside_bounds(model, u) else OUTSIDE_BOUNDS
            eq = Equilibrium(q_nk, u.copy(), model.tip(q_nk), status, 1, 0, rel, 0, sw.fac)
        else:
            eq = solve_equilibrium(model, u, q0=q0, u0=u0, guess=guess,
                                   fac=sw.fac if settings.reuse_factorization else None,
                                   tol=tol, max_iter=settings.max_iter, target=_POLISH * tol)
    else:
        if j > 0:
            counters["restarts"] += 1
        q0, u0 = (None, None) if sw.start is None else sw.start
        eq = solve_equilibrium(model, u, q0=q0, u0=u0, tol=tol, max_iter=settings.max_iter,
                               target=_POLISH * tol)
    eq = settle(model, eq, np.zeros(model.n_dof) if q0 is None else q0)
    _count(counters, eq)
    if eq.status == CONVERGED:
        sw.history = (sw.history + [(u.copy(), eq.q)])[-_HISTORY:]
        if eq.factorization is not None:  # a point verified without a Newton step keeps the last LU
            sw.fac = eq.factorization
        sw.start = (eq.q, u.copy())
    else:
        sw.history = []  # next point: continuation from the last verified equilibrium
        sw.fac = None
    return eq


def line_stride(settings, line_length: int) -> int:
    """Grid steps between the Newton-solved points of a line (the wide one of :func:`line_strides`)."""
    return line_strides(settings, line_length)[0]


def line_strides(settings, line_length: int) -> tuple[int, int]:
    """(wide, narrow): the grid steps between the Newton-solved points of a line, and those of a line after
    one whose interpolations failed too often (see :attr:`ForwardSettings.stride`); both ``stride`` if given."""
    if settings.stride is not None:
        return max(1, int(settings.stride)), max(1, int(settings.stride))
    return int(np.clip(line_length // 6, 1, 8)), int(np.clip(line_length // 10, 1, 8))


# A line whose interpolations failed more often than this sends the next line to the narrow stride; a narrow
# line failing at most _NARROW_OK of them sends the next one back to the wide stride. Measured at n_d = 30
# (docs/methods.md): on the linear trunks ~10 % fail at the wide stride, on the 10-node trunk ~70 %.
_TOO_MANY_FAILED = 0.25
_NARROW_OK = 0.05


def across_stride(settings, n_u: int, n_lines: int) -> int:
    """Lines between the Newton-solved lines of a plane, and planes between the swept planes of a cube
    (see :attr:`ForwardSettings.across`)."""
    if settings.across is not None:
        return max(1, int(settings.across))
    return min(line_stride(settings, n_lines), int(np.clip(n_lines // 10, 1, 8))) if n_u >= 3 else 1


def _grid_positions(n: int, stride: int, reverse: bool) -> list[int]:
    """Every stride-th of n positions and the last (and half a stride in from each end where the stride is 3
    or more: there the stencil is one-sided, which interpolates less well), mirrored when the sweep runs
    backwards, so that the solved positions are the same inputs whichever way it runs."""
    grid = set(range(0, n, stride)) | {n - 1}
    if stride >= 3:
        grid |= {stride // 2, n - 1 - stride // 2}
    return sorted(n - 1 - g for g in grid) if reverse else sorted(grid)


def _solve_line(model, us, first, settings, tol, sw: _Sweep, counters):
    """Solve the points of one grid line (in sweep order, the line's actuator varying): every stride-th by
    Newton, the others by interpolating those and verifying the residual (Newton where that fails)."""
    n = len(us)
    wide, narrow = line_strides(settings, n) if n > 2 else (1, 1)
    stride = narrow if sw.narrow else wide
    # Newton at the same grid positions on every line (whichever way it runs), so their first iterates can
    # be extrapolated across the previous lines, one grid step apart
    newton = _grid_positions(n, stride, n > 1 and bool(np.any(us[-1] < us[0])))
    out = [None] * n
    for j in newton:
        out[j] = _solve_point(model, us[j], first + j, settings, tol, sw, counters)
        out[j].newton = True
    if stride == 1:
        return out
    axis = _line_axis(us[0], us[-1])
    x = us[:, axis]
    solved = np.array([j for j in newton if out[j].status == CONVERGED])
    failed_before = counters["interpolation_failed"]
    for j in range(n):
        if out[j] is not None:
            continue
        if solved.size == 0:
            out[j] = _solve_point(model, us[j], first + j, settings, tol, sw, counters)
            out[j].newton = True
            continue
        near = solved[np.argsort(np.abs(x[solved] - x[j]), kind="stable")[:_INTERPOLATION_POINTS]]
        guess = polynomial_guess(model, x[near], [out[k].q for k in near], x[j])
        eq = verify(model, us[j], guess, tol)
        counters["interpolated"] += 1
        k = near[0]
        if eq.status != CONVERGED:  # interpolation not good enough here: Newton from it
            counters["interpolation_failed"] += 1
            # polished like a Newton point: it becomes one of the nodes of the points after it
            eq = solve_equilibrium(model, us[j], q0=out[k].q, u0=us[k], guess=guess, tol=tol,
                                   max_iter=settings.max_iter, target=_POLISH * tol)
            eq = settle(model, eq, out[k].q)
            eq.newton = True
            _count(counters, eq)
            if eq.status == CONVERGED:  # failures cluster: the points after it interpolate from it too
                solved = np.append(solved, j)
        else:
            settled = settle(model, eq, out[k].q)
            if settled is not eq:  # the path from rest's, checked like a Newton point (and counted)
                eq = settled
                eq.newton = True
                _count(counters, eq)
        out[j] = eq
    tried = n - len(newton)
    failed = counters["interpolation_failed"] - failed_before
    if wide != narrow:
        sw.narrow = failed > _TOO_MANY_FAILED * tried if stride == wide else failed > _NARROW_OK * tried
    return out


def _check_line(model, line, mode: str = "exact") -> tuple[np.ndarray, np.ndarray]:
    """Admissibility masks of a line's points (0 for points that did not converge), and their maps. Newton
    points get every check, with the pivots of their own LU; a point between two Newton points of the line
    inherits stability and self-penetration from them when both pass those, and gets the cheap checks
    itself. The maps (:mod:`.maps`) come from each point's own LU (``exact``: the Newton points' LU where it was
    taken at the point, else a fresh one); with ``exact`` False, between Newton points steerability and
    compliance are interpolated linearly from them, the others computed at the point; ``none``: neither."""
    exact = mode == "exact"
    masks = np.zeros(len(line), dtype=np.int64)
    maps = np.full((len(line), len(MAPS) + 2 * model.n_u), np.nan)
    costly = encode(("unstable", "self_penetration"))
    done = np.zeros(len(line), dtype=bool)
    for j, eq in enumerate(line):
        if eq.status == CONVERGED and getattr(eq, "newton", False):
            masks[j] = admissibility(model, eq.q, eq.u, eq.factorization).mask
            done[j] = True
    anchors = np.flatnonzero(done)
    for j, eq in enumerate(line):
        if done[j] or eq.status != CONVERGED:
            continue
        left, right = anchors[anchors < j], anchors[anchors > j]
        inherit = left.size and right.size and not (masks[left[-1]] | masks[right[0]]) & costly
        masks[j] = admissibility(model, eq.q, eq.u, eq.factorization, inherited=bool(inherit)).mask
    # the maps: from each point's own LU; or (not exact) between Newton points steerability and compliance
    # (which need an LU) linearly interpolated along the line, the others at the point
    lu_maps = [MAPS.index("steerability"), MAPS.index("compliance")]
    for j, eq in enumerate(line):
        if eq.status != CONVERGED:
            continue
        if (done[j] or exact) and mode != "none":
            fac = eq.factorization if done[j] and eq.factorization is not None else None
            m = _lu_maps(model, eq, fac)
        else:
            m = state_maps(model, eq.q, eq.u) | {"steerability": np.nan, "compliance": np.nan}
        maps[j] = [m[name] for name in MAPS] + list(m["states"]) + list(m["intensities"])
    for j in np.flatnonzero(~done):
        if mode != "interpolated" or line[j].status != CONVERGED or not anchors.size:
            continue
        left, right = anchors[anchors < j], anchors[anchors > j]
        a, b = (left[-1] if left.size else right[0]), (right[0] if right.size else left[-1])
        w = 0.0 if a == b else (j - a) / (b - a)
        maps[j, lu_maps] = (1 - w) * maps[a, lu_maps] + w * maps[b, lu_maps]
    return masks, maps


def _solve_plane(model, us, first, settings, tol, sw: _Sweep, counters, L: int):
    """A plane of grid lines (the last two actuators varying; ``L`` points per line, in sweep order): every
    ``across``-th line solved by :func:`_solve_line`, the lines between interpolated across lines and
    verified. Returns the equilibria, admissibility masks and maps of its points."""
    lines = [np.arange(a, min(a + L, len(us))) for a in range(0, len(us), L)]
    ax, lax = ranged_inputs(model.u_min, model.u_max)[-2:]
    x = np.array([us[idx[0], ax] for idx in lines])
    newton = _grid_positions(len(lines), across_stride(settings, grid_inputs(model), len(lines)),
                             len(lines) > 1 and bool(x[-1] < x[0]))
    eqs = [None] * len(us)
    masks = np.zeros(len(us), dtype=np.int64)
    maps = np.full((len(us), len(MAPS) + 2 * model.n_u), np.nan)
    at = {}  # (Newton line, input of the line's actuator) -> index of the point
    for i in newton:
        idx = lines[i]
        line = _solve_line(model, us[idx], first + idx[0], settings, tol, sw, counters)
        masks[idx], maps[idx] = _check_line(model, line, settings.maps)
        for eq in line:
            # checked: the lines between need only its states; a plane's ~250 LUs kept to its end took 12 GB
            # per worker on the 3-cable trunk at n_d = 30
            eq.factorization = None
        for j, eq in zip(idx, line):
            eqs[j] = eq
            if eq.status == CONVERGED:
                at[i, float(us[j, lax])] = j
    for i in sorted(set(range(len(lines))) - set(newton)):
        for j in lines[i]:
            nodes = [(k, at[k, float(us[j, lax])]) for k in newton if (k, float(us[j, lax])) in at]
            eqs[j], masks[j], maps[j] = _across(model, us[j], x[i], [(x[k], n) for k, n in nodes], eqs, masks, maps,
                                                settings, tol, counters)
    return eqs, masks, maps


def _across(model, u, x, nodes, eqs, masks, maps, settings, tol, counters):
    """One point between Newton lines, at ``x`` on the across axis: the polynomial through the nearest
    ``nodes`` [(x_k, point index)], verified (Newton from it otherwise); then its checks and maps."""
    if not nodes:
        eq = settle(model, solve_equilibrium(model, u, tol=tol, max_iter=settings.max_iter), np.zeros(model.n_dof))
        _count(counters, eq)
        eq.newton = True
        return eq, *_own_checks(model, eq, settings.maps)
    nodes = sorted(nodes, key=lambda n: abs(n[0] - x))[:_INTERPOLATION_POINTS]
    xs = np.array([n[0] for n in nodes])
    guess = polynomial_guess(model, xs, [eqs[k].q for _, k in nodes], x)
    eq = verify(model, u, guess, tol)
    counters["interpolated"] += 1
    k, solved = nodes[0][1], False
    if eq.status != CONVERGED:
        counters["interpolation_failed"] += 1
        eq = solve_equilibrium(model, u, q0=eqs[k].q, u0=eqs[k].u, guess=guess, tol=tol, max_iter=settings.max_iter)
        solved = True
    settled = settle(model, eq, eqs[k].q)
    if solved or settled is not eq:
        eq = settled
        _count(counters, eq)
        eq.newton = True
        return eq, *_own_checks(model, eq, settings.maps)
    # the solved lines either side (or the nearest one, at the plane's edge) stand in for its costly checks
    lo = [n for n in nodes if n[0] < x]
    hi = [n for n in nodes if n[0] > x]
    a = min(lo, key=lambda n: x - n[0]) if lo else None
    b = min(hi, key=lambda n: n[0] - x) if hi else None
    costly = encode(("unstable", "self_penetration"))
    inherit = a is not None and b is not None and not (masks[a[1]] | masks[b[1]]) & costly
    mask = admissibility(model, eq.q, eq.u, None, inherited=bool(inherit)).mask
    m = _lu_maps(model, eq) if settings.maps == "exact" else state_maps(model, eq.q, eq.u)
    row = np.array([m.get(name, np.nan) for name in MAPS] + list(m["states"]) + list(m["intensities"]))
    if settings.maps == "interpolated":
        a, b = a or b, b or a
        w = 0.0 if a[0] == b[0] else (x - a[0]) / (b[0] - a[0])
        lu_maps = [MAPS.index("steerability"), MAPS.index("compliance")]
        row[lu_maps] = (1 - w) * maps[a[1], lu_maps] + w * maps[b[1], lu_maps]
    return eq, mask, row


def _lu_maps(model, eq, fac=None) -> dict:
    """The maps at a verified equilibrium from ``fac`` or, without one, a fresh LU of its own tangent: the LU a
    Newton solve ends with may be a chord LU of an earlier iterate or of the point before."""
    # A double-precision LU, and the maps at the state one Newton step further, refined against its own
    # tangent. Why: from a single-precision LU refined once the compliance was ~1e-4 off, and a serial and a
    # 2-worker run of one grid (whose states of a point differ within the tolerance, ~1e-9) 7.8e-5 apart;
    # refined to round-off, 2.4e-8 apart; at the polished state, 7e-11, whichever path reached the point. The
    # double LU costs about what the single one and its refinement did (trunk_2cables: 6.4 against 4.8 + 3 ms).
    if fac is None or not np.array_equal(fac.q, eq.q) or getattr(fac, "K", None) is not None:
        fac = tangent_factorization(model, eq.q, eq.u, single=False)
    q = eq.q + model.full(fac.solve(-model.residual(eq.q, eq.u)))
    A, _, G = sensitivity(model, q, fac, K=model.tangent(q, eq.u), compliance=True, joint=True)
    return point_maps(model, eq.q, eq.u, A, fac, G)


def _own_checks(model, eq, mode: str = "exact"):
    """Admissibility mask and maps of a Newton-solved point, from its own LU (then dropped: the point is
    kept to the end of its plane, and where the interpolation across lines fails often, a plane's LUs
    took 12 GB per worker)."""
    row = np.full(len(MAPS) + 2 * model.n_u, np.nan)
    if eq.status != CONVERGED:
        return 0, row
    fac = eq.factorization if eq.factorization is not None else tangent_factorization(model, eq.q, eq.u)
    eq.factorization = None
    mask = admissibility(model, eq.q, eq.u, fac).mask
    m = _lu_maps(model, eq, fac) if mode != "none" else state_maps(model, eq.q, eq.u)
    return mask, np.array([m.get(name, np.nan) for name in MAPS] + list(m["states"]) + list(m["intensities"]))


def sweep(model: StaticModel, us: np.ndarray, settings: ForwardSettings, progress=None,
           resume: dict | None = None, checkpoint=None, line_length: int | None = None) -> SweepResult:
    """Solve the equilibria at ``us`` (whole grid lines of ``line_length`` points, default n_d, in sweep
    order); returns their :class:`SweepResult`.

    ``checkpoint`` (if given) is called with the sweep's state every ``settings.checkpoint_every`` seconds
    (at the end of a line) and on Ctrl-C; passing such a state back as ``resume`` continues where it stopped.
    """
    n = len(us)
    L = max(1, min(int(line_length or settings.n_d), n))
    tips = np.full((n, 3), np.nan)
    status = np.zeros(n, dtype=int)
    residual = np.zeros(n)
    violations = np.zeros(n, dtype=np.int64)
    maps = np.full((n, len(MAPS) + 2 * model.n_u), np.nan)
    states = np.zeros((n, model.n_dof)) if settings.store_states else None
    counters = new_counters()
    tol = model.spec.solver.tolerance if settings.tol is None else settings.tol
    sw = _Sweep()
    first = 0
    if resume is not None:
        first = int(resume["next"])
        tips[:first], status[:first], residual[:first] = resume["tips"], resume["status"], resume["residual"]
        violations[:first] = resume["violations"]
        maps[:first] = resume["maps"]
        if states is not None:
            states[:first] = resume["states"]
        counters.update(resume["counters"])
        sw.history = list(zip(resume["hist_u"], resume["hist_q"]))
        if len(resume["start_q"]):
            sw.start = (resume["start_q"], resume["start_u"])
        sw.narrow = bool(resume.get("narrow", False))
        if sw.history:  # the LU is not saved: refactorise at the last verified point (tangent predictor)
            u_last, q_last = sw.history[-1]
            sw.fac = tangent_factorization(model, q_last, u_last)
        if progress is not None:
            progress(first)

    def state(nxt):
        st = dict(next=nxt, tips=tips[:nxt], status=status[:nxt], residual=residual[:nxt], violations=violations[:nxt],
                  maps=maps[:nxt],
                  counters=dict(counters),
                  hist_u=np.array([h[0] for h in sw.history]).reshape(len(sw.history), model.n_u),
                  hist_q=np.array([h[1] for h in sw.history]).reshape(len(sw.history), model.n_dof),
                  start_q=np.zeros(0) if sw.start is None else sw.start[0],
                  start_u=np.zeros(0) if sw.start is None else sw.start[1], narrow=np.array(sw.narrow))
        if states is not None:
            st["states"] = states[:nxt]
        return st

    last_save = time.perf_counter()
    done = first  # points whose results, history and counters are all recorded
    # the unit of work (and of checkpoints): a plane of lines where lines are interpolated across, else a line
    k = grid_inputs(model)
    P = L * L if k >= 2 and across_stride(settings, k, L) > 1 else L
    try:
        with deferred_interrupt() as ctrl_c:
            for a in range(first, n, P):
                b = min(a + P, n)
                snapshot = (list(sw.history), sw.fac, sw.start, dict(counters))
                try:
                    if P > L:
                        line, violations[a:b], maps[a:b] = _solve_plane(model, us[a:b], a, settings, tol, sw,
                                                                         counters, L)
                    else:
                        line = _solve_line(model, us[a:b], a, settings, tol, sw, counters)
                except KeyboardInterrupt:  # a second Ctrl-C mid-line: forget it, it is solved again on resume
                    sw.history, sw.fac, sw.start, counters = snapshot
                    raise
                if P == L:
                    violations[a:b], maps[a:b] = _check_line(model, line, settings.maps)
                for j, eq in enumerate(line, start=a):
                    tips[j], status[j], residual[j] = eq.tip, eq.status, eq.residual
                    if states is not None and eq.status == CONVERGED:
                        states[j] = eq.q
                done = b
                if progress is not None:
                    progress(b - a)
                if checkpoint is not None and time.perf_counter() - last_save > settings.checkpoint_every:
                    checkpoint(state(done))
                    last_save = time.perf_counter()
                ctrl_c.check()  # Ctrl-C stops here, between lines, where the state is complete
    except KeyboardInterrupt:
        if checkpoint is not None:
            checkpoint(state(done))
        raise
    return SweepResult(tips, status, residual, violations, maps, states, counters)


def _sweep_job(model, us, settings):
    return sweep(model, us, settings)


def forward(problem, n_d: int | None = None, settings: ForwardSettings | None = None,
            model: StaticModel | None = None, checkpoint_dir=None, resume: bool = False,
            executor: Executor | None = None) -> WorkspaceResult:
    """Estimate the workspace by the forward method; see :class:`ForwardSettings`.

    With ``checkpoint_dir``, the run saves a checkpoint there every ``settings.checkpoint_every`` seconds
    and when interrupted (Ctrl-C); ``resume=True`` continues from it (see :mod:`casadi_ws.runtime.run_state`).
    ``executor`` runs slices of the grid (default: ``settings.workers`` processes, or this process).
    """
    with one_blas_thread(), small_pages():
        return _forward(problem, n_d, settings, model, checkpoint_dir, resume, executor)


def _forward(problem, n_d, settings, model, checkpoint_dir, resume, executor) -> WorkspaceResult:
    settings = settings or ForwardSettings()
    if n_d is not None:
        settings.n_d = int(n_d)
    if settings.n_d < 1:
        raise ValueError(f"n_d must be >= 1, got {settings.n_d}")
    if settings.maps not in ("exact", "interpolated", "none"):
        raise ValueError(f"maps must be 'exact', 'interpolated' or 'none', got {settings.maps!r}")
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
    workers = executor.workers if executor is not None else settings.workers
    workers = max(1, min(int(workers), n // 50 or 1))
    # format 11: the tip's roll and axis among the maps (10: exact maps from a double-precision LU at the polished
    # state; a checkpoint of an older format would mix them)
    fp = fingerprint("forward", model, {k: getattr(settings, k) for k in
                                        ("n_d", "predictor", "reuse_factorization", "krylov", "tol", "max_iter",
                                         "store_states", "stride", "across", "maps")} | {"workers": workers, "format": 11})
    run = RunState(checkpoint_dir, "forward", fp, resume, t0)
    try:
        cube = grid_inputs(problem) == problem.n_u and across_planes(problem.n_u, model.n_dof, settings)
        if workers == 1 and not cube:
            resume_state = None
            if run.saved is not None:
                meta, arrays = run.saved
                resume_state = dict(arrays, next=meta["next"], counters=meta["counters"])

            def checkpoint(st):
                run.save({"next": st["next"], "counters": st["counters"]},
                         {k: v for k, v in st.items() if k not in ("next", "counters")})

            swept = sweep(model, us, settings, progress=bar.update if bar else None, resume=resume_state,
                          checkpoint=checkpoint if checkpoint_dir is not None else None)
        else:  # pieces of the grid run by the executor (this process's for the cube on one worker)
            own = executor is None
            executor = executor or make_executor(workers, model, problem)
            try:
                swept = (_cube if cube else _parallel)(problem, us, settings, workers, bar, run, executor)
            finally:
                if own:
                    executor.close()
    finally:
        if bar is not None:
            bar.close()
    t_sweep = time.perf_counter() - t1
    run.finish()

    tips, status, residual, violations, maps, states = (swept.tips, swept.status, swept.residual, swept.violations,
                                                        swept.maps, swept.states)
    counters = swept.counters
    converged = status == CONVERGED
    excluded = converged & (violations != 0) & (not problem.admissibility.keep)
    ok = converged & ~excluded
    counters["points"] = n
    counters["excluded"] = {v: int(np.count_nonzero(excluded & (violations >> i & 1 == 1)))
                            for i, v in enumerate(VIOLATIONS)}
    arrays = dict(excluded_points=tips[excluded], excluded_u=us[excluded], excluded_violations=violations[excluded])
    for i, name in enumerate(MAPS):
        arrays[f"map_{name}"] = maps[ok, i]
    arrays["map_states"] = maps[ok, len(MAPS):len(MAPS) + model.n_u]
    arrays["map_intensities"] = maps[ok, len(MAPS) + model.n_u:]
    return WorkspaceResult(
        method="forward", points=tips[ok], u=us[ok], failed_u=us[~converged], failed_status=status[~converged],
        failed_residual=residual[~converged], states=states[ok] if states is not None else None,
        violations=violations[ok], arrays=arrays, counters=counters,
        timings={"build_model": t_model, "sweep": t_sweep, "total": run.elapsed(),
                 "per_point": t_sweep / n, "before_resume": run.previous},
        settings={**asdict(settings), "workers": workers}, problem=describe(problem, model), rest_tip=model.p0)


def _parallel(problem, us, settings, workers, bar, run: RunState, executor: Executor) -> SweepResult:
    """Slices of whole grid lines, several per worker; each completed slice is checkpointed."""
    L = settings.n_d
    # whole planes where lines are interpolated across them (see sweep), else whole lines
    k = grid_inputs(problem)
    unit = L * L if k >= 2 and across_stride(settings, k, L) > 1 else L
    n_units = max(1, len(us) // unit)
    # two pieces per worker: each starts cold (~1 s of continuation from rest), so more cost more
    pieces = [np.arange(units[0] * unit, (units[-1] + 1) * unit)
              for units in np.array_split(np.arange(n_units), min(n_units, 2 * workers))]
    results: list[SweepResult | None] = [None] * len(pieces)
    if run.saved is not None:
        saved_meta, saved = run.saved
        for i, c in saved_meta.get("pieces", {}).items():
            i = int(i)
            results[i] = SweepResult(*(saved.get(f"{name}_{i}") for name in SweepResult.ARRAYS), c)
            if bar is not None:
                bar.update(len(pieces[i]))

    def checkpoint():
        arrays = {f"{name}_{i}": getattr(r, name) for i, r in enumerate(results) if r is not None
                  for name in SweepResult.ARRAYS if getattr(r, name) is not None}
        run.save({"pieces": {i: r.counters for i, r in enumerate(results) if r is not None}}, arrays)

    todo = [i for i in range(len(pieces)) if results[i] is None]
    for k, r in executor.map_unordered(_sweep_job, problem, [(us[pieces[i]], settings) for i in todo]):
        results[todo[k]] = r
        checkpoint()
        if bar is not None:
            bar.update(len(pieces[todo[k]]))
    out = SweepResult.concatenate(results)
    if not settings.store_states:
        out.states = None
    return out


CUBE_STATES = 1 << 30
"""Bytes of the solved planes' states that interpolating across planes may hold (n_solved_planes x n_d^2 x
n_dof doubles: 245 MB on the 3-cable trunk at n_d = 30); a larger cube is swept plane by plane, lines
interpolated across lines only."""


def across_planes(n_u: int, n_dof: int, settings: ForwardSettings) -> bool:
    """Whether the forward sweep interpolates across planes (:func:`_cube`): three actuators, planes solved
    only every ``across``-th, and their states within :data:`CUBE_STATES`."""
    L = settings.n_d
    across = across_stride(settings, n_u, L)
    if n_u != 3 or across <= 1 or L < 3:
        return False
    return len(_grid_positions(L, across, False)) * L * L * n_dof * 8 <= CUBE_STATES


def _plane_rows(planes, P: int) -> np.ndarray:
    return np.concatenate([np.arange(i * P, (i + 1) * P) for i in planes])


def _cube(problem, us, settings, workers, bar, run: RunState, executor: Executor) -> SweepResult:
    """Three actuators: the grid is one cube of n_d planes (the first actuator fixed in each). Phase 1
    sweeps every ``across``-th plane (and the last) as planes are swept elsewhere (lines solved and
    interpolated across lines), keeping their states; phase 2 interpolates the planes between across the
    nearest (up to 8) solved planes, point by point at the same inputs of the other two actuators, and
    verifies them (Newton from there where that fails). Interpolating along one axis needs its solved
    points from all along it (six solved planes of fifteen left residuals ~1e-7 against eight of thirty's
    ~1e-9), so the cube is not cut into slabs: each phase is split over the workers (two pieces per
    worker). Each finished piece is checkpointed, the solved planes with their states, so a resumed run
    interpolates from the same planes. Returns the points in grid order."""
    L = settings.n_d
    P = L * L
    x = us[::P, 0]
    newton = _grid_positions(L, across_stride(settings, 3, L), False)
    between = [i for i in range(L) if i not in set(newton)]
    # solved planes: two runs of consecutive ones per worker (each starts cold, from rest); the planes between:
    # one piece per worker, every workers-th plane (the interpolation fails more often near u = u_min: a
    # contiguous split would leave one worker most of the Newton solves), each sent the solved planes' states
    split = [list(g) for g in np.array_split(newton, min(len(newton), 2 * workers))]
    pieces = [("n", g) for g in split] + [("b", between[k::workers]) for k in range(min(workers, len(between)))]
    results: dict[int, SweepResult] = {}
    if run.saved is not None:
        meta, saved = run.saved
        for k, c in meta.get("pieces", {}).items():
            k = int(k)
            results[k] = SweepResult(*(saved.get(f"{name}_{k}") for name in SweepResult.ARRAYS), c)
            if bar is not None:
                bar.update(len(pieces[k][1]) * P)

    def checkpoint():
        arrays = {f"{name}_{k}": getattr(r, name) for k, r in results.items() for name in SweepResult.ARRAYS
                  if getattr(r, name) is not None}
        run.save({"pieces": {k: r.counters for k, r in results.items()}}, arrays)

    def run_phase(kind, make_job, fn):
        todo = [k for k, (kd, _) in enumerate(pieces) if kd == kind and k not in results]
        for i, r in executor.map_unordered(fn, problem, [make_job(pieces[k][1]) for k in todo]):
            results[todo[i]] = r
            checkpoint()
            if bar is not None:
                bar.update(len(r))

    solve = replace(settings, store_states=True)  # phase 2 interpolates from the solved planes' states
    run_phase("n", lambda g: (us[_plane_rows(g, P)], solve), _sweep_job)
    solved = [k for k, (kd, _) in enumerate(pieces) if kd == "n"]
    node_planes = [i for k in solved for i in pieces[k][1]]
    node = SweepResult.concatenate([results[k] for k in solved])
    node_of = {i: n for n, i in enumerate(node_planes)}
    at = 0
    for k in solved:  # one copy of the states: the checkpoint's pieces view the nodes' array
        m = len(results[k])
        results[k] = replace(results[k], states=node.states[at:at + m])
        at += m

    def between_job(g):
        # the solved planes the pieces' planes interpolate from (the eight nearest of each), and only those
        nearest = (sorted(node_planes, key=lambda j: abs(x[j] - x[i]))[:_INTERPOLATION_POINTS] for i in g)
        near = sorted(set().union(*nearest), key=node_of.get)
        rows = slice(None) if len(near) == len(node_planes) else \
            np.concatenate([np.arange(node_of[j] * P, (node_of[j] + 1) * P) for j in near])  # (usually all: no copy)
        return (_Between(us[_plane_rows(g, P)], x[g], x[near], us[_plane_rows(near, P)], node.states[rows],
                         node.status[rows], node.violations[rows], node.maps[rows], settings),)

    run_phase("b", between_job, _between_job)
    n = len(us)
    out = SweepResult(np.full((n, 3), np.nan), np.zeros(n, dtype=int), np.zeros(n), np.zeros(n, dtype=np.int64),
                      np.full((n, len(MAPS) + 2 * problem.n_u), np.nan),
                      np.zeros((n, node.states.shape[1])) if settings.store_states else None,
                      {c: sum(r.counters[c] for r in results.values()) for c in results[0].counters})
    for k, (_, g) in enumerate(pieces):
        rows = _plane_rows(g, P)
        for name in SweepResult.ARRAYS:
            if getattr(out, name) is not None:
                getattr(out, name)[rows] = getattr(results[k], name)
    return out


@dataclass
class _Between:
    """Phase 2 of :func:`_cube` for some planes: their inputs, and the solved planes they interpolate from."""

    us: np.ndarray
    x_planes: np.ndarray
    """The first actuator's input of each plane to interpolate."""
    x_nodes: np.ndarray
    """... of each solved plane sent."""
    us_nodes: np.ndarray
    q_nodes: np.ndarray
    status_nodes: np.ndarray
    masks_nodes: np.ndarray
    maps_nodes: np.ndarray
    settings: ForwardSettings


class _Nodes:
    """The solved planes' points as :func:`_across` reads them: ``nodes[i].q``, ``nodes[i].u``."""

    def __init__(self, q, u):
        self.q, self.u = q, u

    def __getitem__(self, i):
        from types import SimpleNamespace

        return SimpleNamespace(q=self.q[i], u=self.u[i])


def _between_job(model, job: _Between) -> SweepResult:
    """Phase 2 of :func:`_cube` for some planes between solved ones: every point the polynomial across the
    solved planes at the same inputs of the other two actuators, verified, checked (:func:`_across`)."""
    settings, us = job.settings, job.us
    tol = model.spec.solver.tolerance if settings.tol is None else settings.tol
    counters = new_counters()
    P = len(us) // len(job.x_planes)
    at: dict[bytes, list] = {}
    for n in np.flatnonzero(job.status_nodes == CONVERGED):
        at.setdefault(job.us_nodes[n, 1:].tobytes(), []).append((job.x_nodes[n // P], int(n)))
    nodes = _Nodes(job.q_nodes, job.us_nodes)
    n = len(us)
    tips, status, residual = np.full((n, 3), np.nan), np.zeros(n, dtype=int), np.zeros(n)
    violations = np.zeros(n, dtype=np.int64)
    maps = np.full((n, job.maps_nodes.shape[1]), np.nan)
    states = np.zeros((n, model.n_dof)) if settings.store_states else None
    for j in range(n):
        eq, violations[j], maps[j] = _across(model, us[j], job.x_planes[j // P], at.get(us[j, 1:].tobytes(), []),
                                             nodes, job.masks_nodes, job.maps_nodes, settings, tol, counters)
        tips[j], status[j], residual[j] = eq.tip, eq.status, eq.residual
        if states is not None and eq.status == CONVERGED:
            states[j] = eq.q
    return SweepResult(tips, status, residual, violations, maps, states, counters)
