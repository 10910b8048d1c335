"""Agreement of two workspace estimates (e.g. forward vs forward-backward), strict measures first.

All measures work on a uniform grid of step ``s`` (default: the forward-backward result's cell step and
origin, else 2 % of the larger cloud's extent). A result's *cells* are the grid cells holding at least one of
its points; a forward-backward result on the same grid uses the cells it reports.

Strict (what a sceptical user computes):

``cells_a_in_b``          share of A's cells that B reports (with A = forward, B = forward-backward: the
                          share of the forward-occupied cells the forward-backward method found)
``cells_b_in_a``          share of B's cells that A occupies (a forward cloud coarser than the grid leaves
                          cells between its points empty, so this understates agreement unless A is dense)
``points_a_in_b_cells``   share of A's points lying in one of B's cells

Lenient, labelled as such (they forgive a miss next to a hit, and so hide the cells along the edges):

``coverage_within_one_cell``   share of A's points within one cell of B's cells (infinity-norm index
                               distance <= 1)
``precision_within_one_cell``  the same with the roles swapped

Also ``hausdorff`` (symmetric, metres, between the point clouds) and ``volume_a``/``volume_b`` (cells x s^3,
m^3; for a 2-actuator robot the workspace is a surface, and this is its area times one cell of thickness).
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy.spatial.distance import directed_hausdorff

__all__ = ["cell_set", "compare"]

_RING = np.array(list(itertools.product((-1, 0, 1), repeat=3)), dtype=np.int64)


def _index(points, origin, step) -> np.ndarray:
    return np.round((np.asarray(points) - origin) / step).astype(np.int64)


def _near(points, cells, origin, step) -> np.ndarray:
    return np.array([any(tuple(k + d) in cells for d in _RING) for k in _index(points, origin, step)], dtype=bool)


def cell_set(result, origin, step) -> set[tuple]:
    """The cells of ``result`` on the grid (origin, step): the ones it reports if it is a forward-backward
    result on that grid, else those its points occupy."""
    if "cells" in result.arrays and np.isclose(float(result.arrays.get("cell_step", np.nan)), step) \
            and np.allclose(result.arrays.get("grid_origin", origin), origin):
        return {tuple(k) for k in np.asarray(result.arrays["cells"]).reshape(-1, 3)}
    return {tuple(k) for k in _index(result.points, origin, step)}


def compare(a, b, step: float | None = None) -> dict:
    """Agreement measures of results ``a`` and ``b`` (see the module's docstring)."""
    if a.n_points == 0 or b.n_points == 0:
        raise ValueError("cannot compare an empty workspace")
    origin = None
    for r in (b, a):
        if "grid_origin" in r.arrays:
            origin = np.asarray(r.arrays["grid_origin"], float)
            step = step or float(r.arrays["cell_step"])
            break
    if step is None:
        ext = max(np.ptp(a.points, axis=0).max(), np.ptp(b.points, axis=0).max())
        step = 0.02 * ext if ext > 0 else 1e-3
    if origin is None:
        origin = a.points[0]
    ca, cb = cell_set(a, origin, step), cell_set(b, origin, step)
    h = max(directed_hausdorff(a.points, b.points)[0], directed_hausdorff(b.points, a.points)[0])
    in_b = np.array([tuple(k) in cb for k in _index(a.points, origin, step)], dtype=bool)
    return {
        "cells_a_in_b": len(ca & cb) / len(ca),
        "cells_b_in_a": len(ca & cb) / len(cb),
        "points_a_in_b_cells": float(in_b.mean()),
        "cells_a": len(ca),
        "cells_b": len(cb),
        "cells_both": len(ca & cb),
        "coverage_within_one_cell": float(_near(a.points, cb, origin, step).mean()),
        "precision_within_one_cell": float(_near(b.points, ca, origin, step).mean()),
        "hausdorff": float(h),
        "volume_a": len(ca) * step**3,
        "volume_b": len(cb) * step**3,
        "n_points_a": a.n_points,
        "n_points_b": b.n_points,
        "step": step,
        "methods": [a.method, b.method],
    }
