"""Steps 1 and 2 of the forward-backward method: Theorem 1's interval box and the grid neighbourhood.

Step 1 (Theorem 1). At an equilibrium (p, q, u), the linearised model K dq = H^T du gives the end-effector
displacement A du with A = C K^-1 H^T. Over the remaining input range dU = [u_min - u, u_max - u] (the
update (9)), interval arithmetic with A+ = max(0, A), A- = A - A+ bounds it by the box

    [p + A+ du_low + A- du_up,  p + A+ du_up + A- du_low].

The publication adds C K^-1 F to both corners. Here F (gravity, point loads) is constant and already
balanced in the equilibrium the box is computed at, so that term would count it twice: it is zero.

Step 2. The end-effector space is discretised either by a uniform grid of step s_Ed anchored at the
initial tip position (the default: cells are then shared across iterations, which the exclusion rule
(10) needs) or by the relative strategy, a local grid of step 5 % of ||p|| around each point. The
eta-neighbourhood S_eta(p) is the ring of the 26 grid points at infinity-norm distance eta; those
inside the Step-1 box form W_Es (7).
"""

from __future__ import annotations

import itertools

import numpy as np

__all__ = ["default_step", "Grid", "NEIGHBOURS", "interval_box", "neighbourhood"]

NEIGHBOURS = np.array([d for d in itertools.product((-1, 0, 1), repeat=3) if any(d)], dtype=np.int64)
"""The 26 offsets of the ring at infinity-norm distance 1."""


def interval_box(A: np.ndarray, p: np.ndarray, du_low: np.ndarray, du_up: np.ndarray):
    """Theorem 1: the box (lower, upper) containing p + A du for every du in [du_low, du_up]."""
    Ap = np.maximum(A, 0.0)
    Am = A - Ap
    return p + Ap @ du_low + Am @ du_up, p + Ap @ du_up + Am @ du_low


def neighbourhood(centre: np.ndarray, step, lower: np.ndarray, upper: np.ndarray):
    """Grid points of S_eta(centre) inside the box [lower, upper] (eq. 7), with their offsets."""
    pts = centre + NEIGHBOURS * np.asarray(step)
    inside = np.all((pts >= lower - 1e-12) & (pts <= upper + 1e-12), axis=1)
    return pts[inside], NEIGHBOURS[inside]


STEPS_PER_REACH = 48
"""The default grid step is the robot's reach over this many, rounded (:func:`default_step`)."""


def default_step(model) -> float:
    """The forward-backward grid step a first run uses: the robot's reach (distance from its fixed nodes'
    centroid to the rest tip) / 48, rounded to 1, 2, 2.5, 4, 5 or 8 x 10^k m. The 195 mm trunk gets 4 mm, a
    20 mm finger 0.4 mm, a 1 m arm 20 mm: ~25-50 cells across a workspace that bends the robot by a fraction
    of its length."""
    X = model.mesh.nodes
    base = X[model.fixed_nodes].mean(axis=0) if len(model.fixed_nodes) else X.mean(axis=0)
    reach = float(np.linalg.norm(model.p0 - base)) or float(np.ptp(X, axis=0).max())
    raw = reach / STEPS_PER_REACH
    k = np.floor(np.log10(raw))
    nice = np.array([1, 2, 2.5, 4, 5, 8, 10]) * 10.0**k
    return float(nice[np.argmin(np.abs(np.log(nice / raw)))])


class Grid:
    """Uniform grid of step ``step`` anchored at ``origin``: cell k has centre origin + k * step."""

    def __init__(self, origin: np.ndarray, step: float):
        if not step > 0:
            raise ValueError(f"grid step must be > 0, got {step}")
        self.origin = np.asarray(origin, dtype=float)
        self.step = float(step)

    def index(self, p: np.ndarray) -> tuple:
        return tuple(np.round((np.asarray(p) - self.origin) / self.step).astype(np.int64).tolist())

    def centre(self, k) -> np.ndarray:
        return self.origin + np.asarray(k, dtype=float) * self.step

    def contains(self, k, p, slack: float = 1e-9) -> bool:
        """Does p lie in cell k (half-width step/2, plus a relative slack)?"""
        return bool(np.all(np.abs(np.asarray(p) - self.centre(k)) <= self.step * (0.5 + slack)))
