"""What a designer reads off a workspace: its size, extents and how much of a task region it covers.

Conventions (all on a uniform grid of step s; a forward-backward result uses its own grid and the cells it
reports, any other result the cells its points occupy on a grid of step s through its first point, or
through ``origin``):

``volume``              the volume enclosed by the boundary surface (:mod:`casadi_ws.workspace.boundary`),
                        m^3, with ``volume_error`` (its difference from the surface through every other
                        node) and ``volume_method`` (``boundary``); None where there is no closed surface
                        (1 or 2 inputs: a curve or a surface has no volume; 6+ inputs, or faces that do not
                        close): never a count of cells (``cell_volume`` is that).
``folded``, ``volume_upper``, ``volume_lower``  where det dp/du changes sign over U (the map folds; the
                        volume is then the union of the images of U's grid cells, :mod:`.images`): the
                        integral of |det dp/du| over U (each point counted once per preimage: an upper bound)
                        and the cells whose 26 neighbours are all reached x s^3 (a lower bound, given the
                        cells hold verified points), m^3
``cells``, ``cell_volume``  number of cells, and cells x s^3 (m^3): what the cells cover, not the robot's
                        volume (it overestimates by a layer of boundary cells, first order in s: ~2.5x on
                        the 3-cable trunk at 4 mm).
``area``                two inputs with a range: the area of the surface u -> p(u), m^2: the boundary's
                        patch where it was built, else summed over the triangles of a Delaunay triangulation
                        of the points' inputs u (scaled to the unit square), mapped to their tips; triangles
                        spanning more than 3 cells (across a hole where solves failed) are left out.
``length``              one input with a range: the length of the curve u -> p(u), m, through the points in
                        the order of u (a step longer than 3 cells, across a gap, is left out).
``extents``             the bounding box of the points, [[xmin, ymin, zmin], [xmax, ymax, zmax]] (m).
``task_share``          with a task: the share of the task's cells that the workspace reaches (a task box:
                        the grid cells whose centre lies in the box; task points: the cells holding them),
                        within the grid's resolution.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..fem.spec import ranged_inputs
from .compare import _index, cell_set

__all__ = ["Task", "measures", "read_task"]


class Task:
    """A region the robot should reach: an axis-aligned box, or a set of points."""

    def __init__(self, box=None, points=None, source: str = "task"):
        if (box is None) == (points is None):
            raise ValueError("a task is a box or a set of points")
        self.box = None if box is None else np.asarray(box, dtype=float).reshape(2, 3)
        self.points = None if points is None else np.atleast_2d(np.asarray(points, dtype=float))
        self.source = source

    def cells(self, origin, step) -> set[tuple]:
        if self.points is not None:
            return {tuple(k) for k in _index(self.points, origin, step)}
        # cells whose centre (origin + k s) lies in the box
        lo = np.ceil((self.box[0] - origin) / step).astype(np.int64)
        hi = np.floor((self.box[1] - origin) / step).astype(np.int64)
        if np.any(hi < lo):
            return set()
        axes = [np.arange(a, b + 1) for a, b in zip(lo, hi)]
        return {tuple(k) for k in np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)}

    def describe(self) -> dict:
        if self.box is not None:
            return {"box": self.box.tolist()}
        return {"points": len(self.points), "source": self.source}


def read_task(box=None, csv: str | Path | None = None) -> Task:
    """A task from a box ([[x0, y0, z0], [x1, y1, z1]]) or a CSV of x, y, z points (a header is allowed)."""
    if csv is not None:
        try:
            pts = np.loadtxt(csv, delimiter=",", ndmin=2)
        except ValueError:
            pts = np.loadtxt(csv, delimiter=",", ndmin=2, skiprows=1)
        if pts.shape[1] < 3 or not np.all(np.isfinite(pts[:, :3])):
            raise ValueError(f"{csv}: expected rows of x, y, z")
        return Task(points=pts[:, :3], source=str(csv))
    try:
        b = np.asarray(box, dtype=float)
    except (ValueError, TypeError):
        b = np.zeros(0)
    if b.shape != (2, 3) or not np.all(np.isfinite(b)) or np.any(b[0] > b[1]):
        raise ValueError(f"expected [[xmin, ymin, zmin], [xmax, ymax, zmax]] with min <= max, got {box!r}")
    return Task(box=b)


def _grid(result, step, origin):
    if "cell_step" in result.arrays and (step is None or np.isclose(step, float(result.arrays["cell_step"]))):
        return np.asarray(result.arrays["grid_origin"], float), float(result.arrays["cell_step"])
    step = float(result.problem.get("default_step", 0.004)) if step is None else float(step)
    origin = result.points[0] if origin is None and result.n_points else (np.zeros(3) if origin is None else origin)
    return np.asarray(origin, float), step


def surface_area(points, u, lower, upper, max_edge: float) -> float:
    """Area of the tip surface over a 2-input box, by a Delaunay triangulation of the scaled inputs."""
    from scipy.spatial import Delaunay

    span = np.where(np.asarray(upper) > np.asarray(lower), np.asarray(upper) - np.asarray(lower), 1.0)
    s = (np.asarray(u) - lower) / span
    if len(s) < 3 or np.linalg.matrix_rank(s - s.mean(0)) < 2:
        return 0.0
    tri = Delaunay(s).simplices
    P = np.asarray(points)[tri]
    e = np.stack([P[:, 1] - P[:, 0], P[:, 2] - P[:, 1], P[:, 0] - P[:, 2]], axis=1)
    keep = np.linalg.norm(e, axis=2).max(axis=1) <= max_edge
    a = 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)
    return float(a[keep].sum())


def curve_length(points, u, max_step: float) -> float:
    """Length of the tip curve over one input: the points in the order of u, steps longer than ``max_step``
    (across a gap where solves failed) left out."""
    P = np.asarray(points)[np.argsort(u, kind="stable")]
    d = np.linalg.norm(np.diff(P, axis=0), axis=1)
    return float(d[d <= max_step].sum())


def _interior(cells: set) -> set:
    """The cells whose 26 neighbours are all in ``cells``."""
    around = [d for d in np.ndindex(3, 3, 3) if d != (1, 1, 1)]
    return {c for c in cells if all((c[0] + a - 1, c[1] + b - 1, c[2] + e - 1) in cells for a, b, e in around)}


def measures(result, step: float | None = None, task: Task | None = None, origin=None) -> dict:
    """The measures of the module's docstring, as plain data (SI units)."""
    origin, step = _grid(result, step, origin)
    cells = cell_set(result, origin, step) if result.n_points else set()
    out = {"cells": len(cells), "cell_step": step, "cell_volume": len(cells) * step**3,
           "volume": None, "volume_error": None, "volume_method": None,
           "extents": ([result.points.min(0).tolist(), result.points.max(0).tolist()] if result.n_points else None)}
    u = np.asarray(result.u)
    b = getattr(result, "boundary", None)
    if b is not None and b.encloses:
        out.update(volume=abs(b.volume), volume_error=b.volume_error, volume_method="boundary",
                   boundary_area=b.area)
    if b is not None and b.fold:
        out["folded"] = True
        if b.fold.get("jacobian_integral") is not None:
            out["volume_upper"] = b.fold["jacobian_integral"]
        if "cells_centres" in result.arrays:  # the exploration's own cells (a forward grid's points are sparser)
            out["volume_lower"] = len(_interior(cells)) * step**3
    if u.ndim == 2 and result.n_points:
        lo, hi = np.asarray(result.problem.get("u_min", u.min(0))), np.asarray(result.problem.get("u_max", u.max(0)))
        free = ranged_inputs(lo, hi) if lo.shape == (u.shape[1],) else np.arange(u.shape[1])
        if free.size == 2:
            out["area"] = surface_area(result.points, u[:, free], lo[free], hi[free], 3 * step)
            if b is not None and b.method == "input-patch":
                out["area"] = b.area
        elif free.size == 1:
            out["length"] = curve_length(result.points, u[:, free[0]], 3 * step)
    if task is not None:
        want = task.cells(origin, step)
        out["task"] = task.describe()
        out["task_cells"] = len(want)
        out["task_share"] = (len(want & cells) / len(want)) if want else None
    return out
