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

Also ``hausdorff`` (symmetric, metres, between the point clouds); ``cell_volume_a``/``cell_volume_b`` (cells x
s^3, m^3: what the cells cover, not a volume of the workspace; for a 2-actuator robot the workspace is a
surface, and this is its area times one cell of thickness); and where a result has a closed boundary surface
(:mod:`.boundary`) its enclosed ``volume_a``/``volume_b`` (else None), and where both have one
``volume_symmetric_difference``: the volume inside exactly one of the two surfaces (m^3), counted on a grid of
:data:`SAMPLES` points a side over their common bounding box (error about the surfaces' area times the grid's
spacing, ``volume_symmetric_difference_spacing``).
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy.spatial.distance import directed_hausdorff

__all__ = ["cell_set", "compare"]

SAMPLES = 64
"""Grid points per side on which the volume inside exactly one of two boundary surfaces is counted."""

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
        "cell_volume_a": len(ca) * step**3,
        "cell_volume_b": len(cb) * step**3,
        **_volumes(a, b),
        "n_points_a": a.n_points,
        "n_points_b": b.n_points,
        "step": step,
        "methods": [a.method, b.method],
    }


def _closed(r):
    b = getattr(r, "boundary", None)
    return b if b is not None and b.encloses else None


def _volumes(a, b) -> dict:
    """The boundary volumes of two results and the volume inside exactly one of their surfaces (see the
    module)."""
    from ..fem.surface import signed_distance

    ba, bb = _closed(a), _closed(b)
    out = {"volume_a": abs(ba.volume) if ba else None, "volume_b": abs(bb.volume) if bb else None}
    if ba is None or bb is None:
        return out
    lo = np.minimum(ba.vertices.min(0), bb.vertices.min(0))
    hi = np.maximum(ba.vertices.max(0), bb.vertices.max(0))
    h = (hi - lo) / SAMPLES
    axes = [lo[i] + h[i] * (np.arange(SAMPLES) + 0.5) for i in range(3)]
    P = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    inside_a = signed_distance(ba.vertices, ba.triangles, P) < 0
    inside_b = signed_distance(bb.vertices, bb.triangles, P) < 0
    out["volume_symmetric_difference"] = float(np.count_nonzero(inside_a != inside_b) * np.prod(h))
    out["volume_symmetric_difference_spacing"] = float(h.max())
    return out
