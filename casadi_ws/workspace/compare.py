"""Agreement of two workspace estimates (e.g. forward vs forward-backward).

All measures work on a uniform grid of step ``s`` (default: the forward-backward result's cell step, else
2 % of the larger cloud's extent). A cloud's *cell set* is the set of grid cells holding at least one of its
points (a forward-backward result uses its own reached cells).

``coverage``   share of A's points lying within one cell of B's cell set (infinity-norm index distance
               <= 1): how much of A is found by B. With A = forward and B = forward-backward this is the
               publication's "the two workspaces coincide".
``precision``  the same with the roles swapped: share of B's points within one cell of A's cell set.
``hausdorff``  symmetric Hausdorff distance between the two point clouds, metres.
``volume``     cell count x s^3 of each cell set, m^3 (for a 2-actuator robot the workspace is a surface,
               and this is its area times one cell of thickness).
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy.spatial.distance import directed_hausdorff

__all__ = ["compare"]

_RING = np.array(list(itertools.product((-1, 0, 1), repeat=3)), dtype=np.int64)


def _cells(points, origin, step):
    return {tuple(k) for k in np.round((points - origin) / step).astype(np.int64)}


def _near(points, cells, origin, step) -> np.ndarray:
    idx = np.round((points - origin) / step).astype(np.int64)
    return np.array([any(tuple(k + d) in cells for d in _RING) for k in idx], dtype=bool)


def _cell_set(result, origin, step):
    if "cells" in result.arrays and np.isclose(float(result.arrays.get("cell_step", np.nan)), step) \
            and np.allclose(result.arrays.get("grid_origin", origin), origin):
        return {tuple(k) for k in result.arrays["cells"]}
    return _cells(result.points, origin, step)


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
    ca, cb = _cell_set(a, origin, step), _cell_set(b, origin, step)
    h = max(directed_hausdorff(a.points, b.points)[0], directed_hausdorff(b.points, a.points)[0])
    return {
        "step": step,
        "coverage": float(_near(a.points, cb, origin, step).mean()),
        "precision": float(_near(b.points, ca, origin, step).mean()),
        "hausdorff": float(h),
        "volume_a": len(ca) * step**3,
        "volume_b": len(cb) * step**3,
        "cells_a": len(ca),
        "cells_b": len(cb),
        "n_points_a": a.n_points,
        "n_points_b": b.n_points,
        "methods": [a.method, b.method],
    }
