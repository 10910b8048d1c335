"""Where the tip can go, and pointing where: the range of tip orientations at each reached cell, and the
dexterous workspace (the reference publication's Section 7, issue 72).

A robot with more inputs than the tip's three coordinates reaches a cell with a family of configurations
(n_u - 3 dimensions of it), and so with a range of tip orientations. For each cell c of the workspace's grid
(step s) two backward problems give the range's ends,

    min / max  angle(axis(q), r)   s.t.  R(q, u) = 0,  u in U,  C q + p_E(0) in cell c

(axis: the tip's axis, :mod:`casadi_ws.fem.frame`; r: a reference direction, by default the axis at rest),
solved in u alone as the reduced backward method is: at a verified equilibrium the objective's gradient
d cos / du = (d cos / dq) K^-1 H^T and the tip's A = C K^-1 H^T give a linear programme for du (the
objective's change over the box U, the cell and a trust region of each input), the equilibrium at u + du is
solved by Newton from the predictor q + K^-1 H^T du, and the step is kept where the verified tip lies in the
cell and the angle improved (else the trust region halves). Every answer is a verified equilibrium whose tip
lies in the cell. Cells are taken nearest-rest first, each started from its own reported configuration and
from the best answer of its neighbours so far (warm-started as forward-backward is); a range is therefore a
lower bound of the true one (local optima), which the tests check against forward clouds.

The **dexterous workspace** for a cone of half-angle c about r is the set of cells whose smallest angle is at
most c: where the tip can be held pointing within c of r.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..solvers.equilibrium import CONVERGED, admissible_guess, solve_equilibrium, tangent_factorization
from ..solvers.sensitivity import input_range, sensitivity
from .states import states_at

__all__ = ["OrientationSettings", "OrientationRanges", "attach", "orientation_ranges", "parse_orientation"]


@dataclass
class OrientationSettings:
    """Settings of :func:`orientation_ranges`."""

    reference: np.ndarray | None = None
    """The direction tilt is measured from (normalised); None: the tip's axis at rest."""
    cone: float | None = None
    """Half-angle (degrees) of the dexterous workspace's cone about ``reference``; None: no dexterous
    workspace."""
    max_iterations: int = 12
    """Steps of one backward problem (each a Newton solve and an LU)."""
    tolerance: float = 0.01
    """Stop when the linear programme promises, or a step gains, less than this many degrees."""
    shrink: float = 0.02
    """The linear programme keeps the tip this share of a step inside the cell's faces: the equilibrium at the
    new inputs lands where the linearisation said up to its curvature. Measured on the coarse 4-cable trunk
    (20 mm cells, a 4096-point forward cloud): at 0.1, 6.6 % of the points lay outside their cell's range (all
    within a tenth of a cell of a face, up to 7.7 deg); at 0.02, 0.5 % (up to 0.8 deg), in the same time."""
    seed_n_d: int = 5
    """Values per input of a coarse forward grid whose points seed the cells they land in: the configurations
    that reach one cell form families apart from each other (on the 4-cable trunk, antagonistic tensions
    reach the cell of a relaxed state tilted 16 deg where the relaxed state's own family tops at 5 deg), and
    a local method from one start finds the family it starts in. 0: no seeds."""
    passes: int = 1
    """Sweeps over the cells: the first solves each cell from the best of its own point, its seeds and its
    neighbours' answers so far (then from its own point where that fails); each further one solves again the
    cells where a neighbour's answer is better than the cell's own, until none is (or ``passes`` ran).
    Measured on the coarse 4-cable trunk: a second pass cost a third more and improved no cell."""


@dataclass
class OrientationRanges:
    """Per reported point whose cell was solved (one point per cell; ``point`` indexes the result's points)."""

    reference: np.ndarray
    step: float
    point: np.ndarray
    """(k,) the result's point that represents each cell."""
    cell: np.ndarray
    """(k, 3) the cells' integer indices on the grid (centre = origin + index * step)."""
    origin: np.ndarray
    tilt_min: np.ndarray
    """(k,) degrees: the smallest angle from ``reference`` reached with the tip in the cell."""
    tilt_max: np.ndarray
    u_at_min: np.ndarray
    """(k, n_u) the inputs attaining ``tilt_min`` (a verified equilibrium whose tip lies in the cell)."""
    u_at_max: np.ndarray
    axis_at_min: np.ndarray
    """(k, 3) the tip's axis there."""
    axis_at_max: np.ndarray
    variation: np.ndarray
    """(k,) degrees: one cell's worth of tilt -- the largest difference between the tilt of the cell's own
    point and those of its 26 neighbours' (points one cell apart): two points of one cell differ by about this
    much even without redundancy (NaN for a cell without neighbours)."""
    cone: float | None = None
    counters: dict = field(default_factory=dict)

    @property
    def cone_axis(self) -> np.ndarray:
        """(k, 3) the axis of the cone through both ends' directions (their bisector)."""
        m = self.axis_at_min + self.axis_at_max
        return m / np.linalg.norm(m, axis=1, keepdims=True)

    @property
    def cone_half_angle(self) -> np.ndarray:
        """(k,) degrees: half the angle between the two ends' directions."""
        c = np.clip(np.sum(self.axis_at_min * self.axis_at_max, axis=1), -1.0, 1.0)
        return np.degrees(np.arccos(c)) / 2

    @property
    def dexterous(self) -> np.ndarray:
        """(k,) bool: the cells where the tip can point within ``cone`` of the reference (all, without a cone)."""
        if self.cone is None:
            return np.ones(len(self.point), dtype=bool)
        return self.tilt_min <= self.cone

    def per_point(self, n_points: int, cells_of_points: np.ndarray) -> dict:
        """``tilt_min``, ``tilt_max``, ``axis_at_min``, ``axis_at_max`` and ``dexterous`` for each of the result's
        points (its cell's; NaN where the cell was not solved)."""
        index = {tuple(c): i for i, c in enumerate(self.cell.tolist())}
        out = {k: np.full(n_points, np.nan) for k in ("tilt_min", "tilt_max")}
        out["dexterous"] = np.zeros(n_points, dtype=bool)
        out["axis_at_min"], out["axis_at_max"] = np.full((n_points, 3), np.nan), np.full((n_points, 3), np.nan)
        for j, c in enumerate(cells_of_points.tolist()):
            i = index.get(tuple(c))
            if i is not None:
                out["tilt_min"][j], out["tilt_max"][j] = self.tilt_min[i], self.tilt_max[i]
                out["axis_at_min"][j], out["axis_at_max"][j] = self.axis_at_min[i], self.axis_at_max[i]
                out["dexterous"][j] = self.dexterous[i]
        return out


def parse_orientation(text: str) -> tuple[np.ndarray | None, float | None]:
    """``axis=[0,0,1],cone=15`` (either part may be left out) -> (axis or None, cone degrees or None); raises
    ValueError with what was expected."""
    import re

    axis = cone = None
    rest = text.strip()
    m = re.search(r"axis\s*=\s*\[([^\]]*)\]", rest)
    if m:
        try:
            axis = np.array([float(x) for x in m.group(1).split(",")])
        except ValueError:
            axis = np.zeros(0)
        if axis.shape != (3,) or not np.all(np.isfinite(axis)) or not np.linalg.norm(axis) > 0:
            raise ValueError(f"axis: expected three numbers, not all zero, e.g. axis=[0,0,1], got [{m.group(1)}]")
        rest = rest[: m.start()] + rest[m.end():]
    m = re.search(r"cone\s*=\s*([^,\s]+)", rest)
    if m:
        try:
            cone = float(m.group(1))
        except ValueError:
            cone = np.nan
        if not 0 <= cone <= 180:
            raise ValueError(f"cone: expected a half-angle in degrees in [0, 180], got {m.group(1)}")
        rest = rest[: m.start()] + rest[m.end():]
    if rest.replace(",", "").strip():
        raise ValueError(f"expected 'axis=[x,y,z],cone=degrees' (either part may be left out), got {text!r}")
    return (None if axis is None else axis / np.linalg.norm(axis)), cone


def cells_of(result, step: float | None = None) -> tuple[np.ndarray, float, np.ndarray]:
    """(origin, step, (n, 3) cell index of every point): a forward-backward result's own grid, or the grid of
    ``step`` (default: the problem's default step) anchored at the first point."""
    from .measures import _grid

    origin, step = _grid(result, step, None)
    return origin, step, np.round((np.asarray(result.points) - origin) / step).astype(np.int64)


def orientation_ranges(model, result, settings: OrientationSettings | None = None,
                       step: float | None = None) -> OrientationRanges:
    """The range of tip orientations at each cell of ``result`` (see the module)."""
    settings = settings or OrientationSettings()
    t0 = time.perf_counter()
    frame = model.tip_frame
    ref = frame.axis0 if settings.reference is None else np.asarray(settings.reference, float)
    ref = ref / np.linalg.norm(ref)
    origin, step, cells = cells_of(result, step)
    first = {}
    for j, c in enumerate(map(tuple, cells.tolist())):
        first.setdefault(c, j)
    reps = np.array(sorted(first.values()), dtype=int)
    found, Q = states_at(model, result, reps)
    state = dict(zip(found.tolist(), Q))
    seeds = _seeds(model, settings.seed_n_d, origin, step, ref, set(first))
    k = len(reps)
    out = {name: np.full(k, np.nan) for name in ("tilt_min", "tilt_max", "variation")}
    u_at = {s: np.full((k, model.n_u), np.nan) for s in (1, -1)}
    ax_at = {s: np.full((k, 3), np.nan) for s in (1, -1)}
    best: dict = {1: {}, -1: {}}  # sense -> cell -> (cos, q, u)
    counters = {"problems": 0, "steps": 0, "factorizations": 0, "passes": 0}
    half = step / 2
    order = [i for i in sorted(range(k), key=lambda i: np.abs(result.points[reps[i]] - model.p0).max())
             if reps[i] in state]
    own_tilt = {tuple(cells[reps[i]].tolist()): _angle(frame.axis(state[reps[i]]) @ ref) for i in order}
    for i in order:
        c = tuple(cells[reps[i]].tolist())
        near = [abs(own_tilt[c] - own_tilt[n]) for n in _neighbours(c) if n in own_tilt]
        out["variation"][i] = max(near) if near else np.nan
    for sweep in range(max(1, settings.passes)):
        counters["passes"] += 1
        changed = 0
        for i in order:
            j = reps[i]
            cell = tuple(cells[j].tolist())
            lo, hi = origin + cells[j] * step - half, origin + cells[j] * step + half
            own = (frame.axis(state[j]) @ ref, state[j], np.asarray(result.u[j], float))
            for sense in (1, -1):  # 1: the smallest angle (the largest cosine), -1: the largest
                mine = best[sense].get(cell)
                near = [best[sense][n] for n in _neighbours(cell) if n in best[sense]]
                if sweep == 0:
                    # from the best of the cell's own point, its seeds and its neighbours' answers; from its own
                    # point too where that one fails (a neighbour's answer may not reach into the cell)
                    cands = sorted([own] + seeds.get((cell, sense), []) + near, key=lambda b: -sense * b[0])
                    starts = cands[:1] + ([own] if cands[0] is not own else [])
                else:
                    # later passes: from a neighbour's answer better than this cell's (it may lead further)
                    ahead = [b for b in near if mine is None or sense * (b[0] - mine[0]) > 1e-9]
                    starts = sorted(ahead, key=lambda b: -sense * b[0])[:1]
                for _, q, u in starts:
                    a = _extreme(model, frame, ref, q, u, lo, hi, sense, settings, counters)
                    if a is not None and (mine is None or sense * (a[0] - mine[0]) > 1e-12):
                        mine = best[sense][cell] = a
                        changed += sweep > 0
                        break
        if sweep > 0 and not changed:
            break
    for i in order:
        for sense, name in ((1, "tilt_min"), (-1, "tilt_max")):
            a = best[sense].get(tuple(cells[reps[i]].tolist()))
            if a is not None:
                out[name][i] = float(np.degrees(np.arccos(np.clip(a[0], -1.0, 1.0))))
                u_at[sense][i], ax_at[sense][i] = a[2], frame.axis(a[1])
    counters["time_s"] = time.perf_counter() - t0
    return OrientationRanges(ref, step, reps, cells[reps], origin, out["tilt_min"], out["tilt_max"], u_at[1],
                             u_at[-1], ax_at[1], ax_at[-1], out["variation"], settings.cone, counters)


def _seeds(model, n_d, origin, step, ref, cells) -> dict:
    """(cell, sense) -> [(cos, q, u)]: the best point of a coarse forward grid in each of ``cells``, for each end
    of the range, with its state."""
    if n_d < 2:
        return {}
    from types import SimpleNamespace

    from .forward import ForwardSettings, forward

    fw = forward(model.spec, settings=ForwardSettings(n_d=n_d, progress=False, maps="none"), model=model)
    if not fw.n_points:
        return {}
    maps = fw.maps()
    cos = np.column_stack([maps["axis_x"], maps["axis_y"], maps["axis_z"]]) @ ref
    where = np.round((fw.points - origin) / step).astype(np.int64)
    pick = {}
    for j, c in enumerate(map(tuple, where.tolist())):
        if c not in cells or not np.isfinite(cos[j]):
            continue
        for sense in (1, -1):
            if (c, sense) not in pick or sense * cos[j] > sense * cos[pick[c, sense]]:
                pick[c, sense] = j
    chosen = sorted(set(pick.values()))
    found, Q = states_at(model, SimpleNamespace(u=fw.u, points=fw.points), chosen)
    state = dict(zip(found.tolist(), Q))
    return {key: [(float(cos[j]), state[j], np.asarray(fw.u[j], float))] for key, j in pick.items() if j in state}


def attach(result, ranges: OrientationRanges, task=None) -> None:
    """Give ``result`` its orientation ranges, in place: per point its cell's ``tilt_min``, ``tilt_max`` and
    ``dexterous`` (``result.maps()``, points.csv, points.vtu, cells.vtu), the dexterous cells
    (``dexterous.vtu``) and the measures ``orientation`` and, with a cone, ``dexterous`` (its cells, their
    volume cells x s^3, its share of the workspace's cells and, with a ``task``, of the task's cells)."""
    cells = np.round((np.asarray(result.points) - ranges.origin) / ranges.step).astype(np.int64)
    per = ranges.per_point(result.n_points, cells)
    solved = np.isfinite(ranges.tilt_min) & np.isfinite(ranges.tilt_max)
    result.arrays.update(map_tilt_min=per["tilt_min"], map_tilt_max=per["tilt_max"],
                         map_dexterous=np.where(np.isfinite(per["tilt_min"]), per["dexterous"], np.nan),
                         orientation_cells=ranges.cell, orientation_tilt_min=ranges.tilt_min,
                         orientation_tilt_max=ranges.tilt_max, orientation_u_at_min=ranges.u_at_min,
                         orientation_u_at_max=ranges.u_at_max, orientation_axis_at_min=ranges.axis_at_min,
                         orientation_axis_at_max=ranges.axis_at_max, orientation_variation=ranges.variation,
                         orientation_reference=ranges.reference, point_axis_at_min=per["axis_at_min"],
                         point_axis_at_max=per["axis_at_max"])
    m = {"reference": ranges.reference.tolist(), "cells": int(len(ranges.point)), "solved": int(solved.sum()),
         "tilt_min_deg": float(np.nanmin(ranges.tilt_min)) if solved.any() else None,
         "tilt_max_deg": float(np.nanmax(ranges.tilt_max)) if solved.any() else None,
         "widest_range_deg": float(np.nanmax(ranges.tilt_max - ranges.tilt_min)) if solved.any() else None,
         "median_variation_deg": float(np.nanmedian(ranges.variation)) if solved.any() else None,
         "time_s": ranges.counters.get("time_s"), "cell_step": ranges.step}
    result.measures["orientation"] = m
    if ranges.cone is not None:
        dex = solved & ranges.dexterous
        result.arrays["dexterous_centres"] = ranges.origin + ranges.cell[dex] * ranges.step
        d = {"axis": ranges.reference.tolist(), "cone_deg": ranges.cone, "cells": int(dex.sum()),
             "cell_volume": float(dex.sum() * ranges.step**3), "share": float(dex.sum() / max(solved.sum(), 1))}
        if task is not None:
            want = task.cells(ranges.origin, ranges.step)
            have = {tuple(c) for c in ranges.cell[dex].tolist()}
            d["task_share"] = (len(want & have) / len(want)) if want else None
        result.measures["dexterous"] = d


def _neighbours(c):
    return [(c[0] + a - 1, c[1] + b - 1, c[2] + e - 1) for a, b, e in np.ndindex(3, 3, 3) if (a, b, e) != (1, 1, 1)]


def _cosine(frame, ref):
    a0 = frame.axis0
    return lambda R: float((R @ a0) @ ref)


def _extreme(model, frame, ref, q, u, lo, hi, sense, settings, counters):
    """(cos, q, u) of the best verified equilibrium found with the tip in [lo, hi] (None: none found): the
    sequential linear programme of the module, from the equilibrium (q, u). A step is taken where it improves
    the angle with the tip in the cell (or, from outside, brings the tip nearer the cell); otherwise the trust
    region halves."""
    from scipy.optimize import linprog

    counters["problems"] += 1
    cosine = _cosine(frame, ref)
    span = np.where(model.u_max > model.u_min, model.u_max - model.u_min, 0.0)
    radius = 0.25 * span
    margin = settings.shrink * (hi - lo)

    def outside(tip):
        return float(np.maximum(np.maximum(lo - tip, tip - hi), 0.0).max())

    tip, c = model.tip(q), frame.axis(q) @ ref
    fac = None
    for _ in range(settings.max_iterations):
        if radius.max() < 1e-3 * span.max():
            break
        if fac is None:
            fac = tangent_factorization(model, q, u)
            counters["factorizations"] += 1
        A, S = sensitivity(model, q, fac)
        g = frame.gradient(q, cosine)[model.free] @ S
        d_lo, d_hi, _ = input_range(model, q, u)
        d_lo, d_hi = np.maximum(d_lo, -radius), np.minimum(d_hi, radius)
        # the tip kept within the cell shrunk by the margin, or no farther out than it is (a step may stay put);
        # where it is outside the cell, brought back in first
        t_lo, t_hi = lo + margin - tip, hi - margin - tip
        if outside(tip) == 0:
            t_lo, t_hi = np.minimum(t_lo, 0.0), np.maximum(t_hi, 0.0)
        res = linprog(-sense * g, A_ub=np.vstack([A, -A]), b_ub=np.concatenate([t_hi, -t_lo]),
                      bounds=list(zip(d_lo, d_hi)), method="highs")
        if res.status == 0:
            du = res.x
            promised = np.degrees(abs(g @ du)) / max(np.sqrt(max(1 - c * c, 0.0)), 1e-6)
            if outside(tip) == 0 and promised < settings.tolerance:
                break
        else:
            du = _into_cell(A, t_lo, t_hi, d_lo, d_hi)
            if du is None:
                break
        guess = q.copy()
        guess[model.free] += S @ du
        u_new = np.clip(u + du, model.u_min, model.u_max)
        eq = solve_equilibrium(model, u_new, q0=q, u0=u, guess=guess if admissible_guess(model, guess) else None)
        counters["steps"] += 1
        counters["factorizations"] += eq.factorizations
        if eq.status == CONVERGED:
            c_new, out_new, out_now = frame.axis(eq.q) @ ref, outside(eq.tip), outside(tip)
            better = out_new == 0 and (out_now > 0 or sense * c_new > sense * c)
            if better or (out_now > 0 and out_new < out_now):
                gain = abs(_angle(c_new) - _angle(c)) if out_now == 0 else np.inf
                q, u, tip, c, fac = eq.q, u_new, eq.tip, c_new, eq.factorization
                if gain < settings.tolerance:  # the last step bought less than the tolerance
                    break
                radius = np.minimum(1.5 * radius, 0.25 * span)
                continue
        radius = radius / 2
    return (c, q, u) if outside(tip) == 0 else None


def _angle(c) -> float:
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def _into_cell(A, t_lo, t_hi, d_lo, d_hi):
    """The smallest-violation step into the cell (a linear programme with slack), or None."""
    from scipy.optimize import linprog

    n = A.shape[1]
    c = np.concatenate([np.zeros(n), np.ones(6)])
    A_ub = np.vstack([np.hstack([A, -np.eye(3), np.zeros((3, 3))]), np.hstack([-A, np.zeros((3, 3)), -np.eye(3)])])
    res = linprog(c, A_ub=A_ub, b_ub=np.concatenate([t_hi, -t_lo]),
                  bounds=list(zip(d_lo, d_hi)) + [(0, None)] * 6, method="highs")
    return res.x[:n] if res.status == 0 else None
