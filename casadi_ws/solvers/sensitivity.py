"""Sensitivities of an equilibrium and the bounded linear least-squares step built on them."""

from __future__ import annotations

import numpy as np

__all__ = ["bounded_step", "closest_to_box", "sensitivity"]


def sensitivity(model, q, fac) -> tuple[np.ndarray, np.ndarray]:
    """(A, S): A = C K^-1 H^T (3 x n_u), S = K^-1 H^T = dq/du on the free dofs (n_free x n_u)."""
    H = model.actuation_matrix(q)  # (n_u, n_free), H = -dL/dq
    # one solve with n_u right-hand sides reads the factors once (they do not fit in cache)
    # (C order, as a checkpoint restores it: the products with S then round the same way after a resume)
    S = np.ascontiguousarray(fac.solve(np.ascontiguousarray(H.T))) if model.n_u else np.zeros((model.n_free, 0))
    return model.C_free @ S, S


def bounded_step(A: np.ndarray, r: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """du minimising |A du - r| with lo <= du <= hi (bounded linear least squares).

    An active-set method (Lawson and Hanson's, with both bounds) for the few actuators of a robot: it
    costs ~50 us where scipy's ``lsq_linear`` costs ~0.8 ms, and the method calls it for every target.
    Where the minimiser is not unique (more actuators than 3), the free part is the least-norm one.
    """
    A = np.asarray(A, dtype=float)
    n = A.shape[1]
    lo, hi = np.asarray(lo, dtype=float), np.minimum(np.maximum(hi, lo), np.inf)
    x = np.clip(np.zeros(n), lo, hi)
    if n == 0:
        return x
    free = hi > lo
    tol = 1e-12 * max(1.0, float(np.abs(A.T @ r).max()) if r.size else 1.0)
    for _ in range(10 * n + 10):
        # inner loop: least squares on the free variables, stepping back to the box when it leaves it
        for _ in range(n + 1):
            if not free.any():
                break
            z = x.copy()
            z[free] = np.linalg.lstsq(A[:, free], r - A[:, ~free] @ x[~free], rcond=None)[0]
            if np.all(z[free] >= lo[free]) and np.all(z[free] <= hi[free]):
                x = z
                break
            d = z - x
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.where(d < 0, (lo - x) / d, np.where(d > 0, (hi - x) / d, np.inf))
            t = np.where(free, t, np.inf)
            k = int(np.argmin(t))
            x = np.clip(x + max(0.0, min(1.0, t[k])) * d, lo, hi)
            x[k] = lo[k] if d[k] < 0 else hi[k]
            free[k] = False
        # KKT at the bounds: a fixed variable whose gradient points into the box is freed
        g = A.T @ (A @ x - r)
        want = np.where(~free & (x <= lo) & (hi > lo), -g, 0.0) + np.where(~free & (x >= hi) & (hi > lo), g, 0.0)
        k = int(np.argmax(want))
        if want[k] <= tol:
            return x
        free[k] = True
    return x


def closest_to_box(A: np.ndarray, r: np.ndarray, lo: np.ndarray, hi: np.ndarray, half_width: float):
    """du (lo <= du <= hi) bringing A du as near as possible to the box r +- half_width (a grid cell around
    r), with the distance left: min |A du - (r + w)| over du and |w_i| <= half_width, a bounded linear
    least-squares problem in (du, w). Where A du can enter the box the minimiser is not unique: the
    least-norm one is the smallest input change that does. Returns ``(du, gap)``, gap the infinity-norm
    distance from A du to the box (0 inside it)."""
    A = np.asarray(A, dtype=float)
    n = A.shape[1]
    h = np.full(3, float(half_width))
    x = bounded_step(np.hstack([A, -np.eye(3)]), r, np.concatenate([lo, -h]), np.concatenate([hi, h]))
    du = x[:n]
    gap = max(0.0, float(np.abs(A @ du - r).max()) - half_width)
    return du, gap
