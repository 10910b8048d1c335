"""The tip's orientation: a frame carried by the body, its rotation from rest, the axis and the roll about it.

The reference publication (Section 7) proposes three points at the tip that define a plane: C then gives
the tip's position and orientation, and the same methods give the workspace of both. Here a frame is read
from nine numbers P(q), linear in the state:

- ``frame`` points given (``end_effector.frame``, three points embedded in the body): P = the three
  points. Their orthonormal frame E (e1 along p2 - p1, e3 normal to the plane, e2 = e3 x e1) turns by
  R = E(q) E(0)^T; the tip's axis at rest is the plane's normal, pointing away from the supports.
- otherwise: P = the tip elements' mean deformation gradient F (the elements holding the end effector),
  R its rotation (polar decomposition F = R U); the axis at rest runs from the supports' centroid to the tip.

The axis now is R a0; ``tilt`` is its angle from a0 (or from a reference direction), ``roll`` the angle of
R's twist about a0 (the swing-twist split R = R_swing R_twist, R_twist about a0). Derivatives of a scalar
of R with respect to q go through the nine numbers (central differences in P, exact in P's linear map).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["TipFrame"]


def _frame_of_points(P: np.ndarray) -> np.ndarray:
    p1, p2, p3 = P.reshape(3, 3)
    e1 = p2 - p1
    e1 = e1 / np.linalg.norm(e1)
    e3 = np.cross(p2 - p1, p3 - p1)
    e3 = e3 / np.linalg.norm(e3)
    return np.column_stack([e1, np.cross(e3, e1), e3])


def _polar_rotation(P: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(P.reshape(3, 3))
    R = U @ Vt
    if np.linalg.det(R) < 0:  # an inverted tip element: the nearest rotation
        U[:, -1] *= -1
        R = U @ Vt
    return R


class TipFrame:
    """The tip frame of a model (see the module). ``points``: three points (3, 3) at the tip, or None."""

    def __init__(self, model, points: np.ndarray | None = None):
        base = model.mesh.nodes[model.fixed_nodes].mean(axis=0) if len(model.fixed_nodes) else model.mesh.nodes.mean(axis=0)
        outward = model.p0 - base
        if points is not None:
            points = np.asarray(points, dtype=float).reshape(3, 3)
            self.kind = "points"
            self.L = model.embedding(points)  # (9, n_dof): P = L (X + q)
            self.P0 = self.L @ model.X
            self.E0 = _frame_of_points(self.P0)
            a0 = self.E0[:, 2]
            self.axis0 = a0 if a0 @ outward >= 0 else -a0
        else:
            self.kind = "deformation"
            self.L, self.P0 = _tip_deformation_operator(model)
            self.axis0 = outward / max(np.linalg.norm(outward), 1e-300)

    def numbers(self, q: np.ndarray) -> np.ndarray:
        """P(q), the nine numbers the frame is read from."""
        return self.P0 + self.L @ q

    def rotation_of(self, P: np.ndarray) -> np.ndarray:
        if self.kind == "points":
            return _frame_of_points(P) @ self.E0.T
        return _polar_rotation(P)

    def rotation(self, q: np.ndarray) -> np.ndarray:
        """R (3 x 3): the tip frame's rotation from rest."""
        return self.rotation_of(self.numbers(q))

    def axis(self, q: np.ndarray) -> np.ndarray:
        """The tip's axis now (unit vector), R a0."""
        return self.rotation(q) @ self.axis0

    def orientation(self, q: np.ndarray, reference: np.ndarray | None = None) -> dict:
        """``direction`` (the axis now), ``tilt`` (deg, from ``reference`` or from the axis at rest), ``roll``
        (deg, the twist about the rest axis) and ``rotation`` (R)."""
        R = self.rotation(q)
        d = R @ self.axis0
        ref = self.axis0 if reference is None else np.asarray(reference, float) / np.linalg.norm(reference)
        return {"direction": d, "tilt": float(np.degrees(np.arccos(np.clip(d @ ref, -1.0, 1.0)))),
                "roll": roll(R, self.axis0), "rotation": R}

    def gradient(self, q: np.ndarray, f) -> np.ndarray:
        """d f(R(q)) / dq (n_dof,) of a scalar function ``f`` of the rotation: central differences in the nine
        numbers (step 1e-7 of their scale), chained with their linear map."""
        P = self.numbers(q)
        h = 1e-7 * max(np.abs(P).max(), 1e-12)
        g = np.empty(9)
        for i in range(9):
            dp = np.zeros(9)
            dp[i] = h
            g[i] = (f(self.rotation_of(P + dp)) - f(self.rotation_of(P - dp))) / (2 * h)
        return np.asarray(self.L.T @ g).ravel()


def roll(R: np.ndarray, axis: np.ndarray) -> float:
    """The twist angle (deg) of the rotation R about ``axis`` (swing-twist split)."""
    w = np.sqrt(max(0.0, 1.0 + np.trace(R))) / 2
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    v = v / (4 * w) if w > 1e-12 else _axis_of_half_turn(R)
    return float(np.degrees(2 * np.arctan2(v @ axis, w)))


def _axis_of_half_turn(R):
    # a rotation by pi: R = 2 n n^T - I; the quaternion's vector part is n
    M = (R + np.eye(3)) / 2
    n = M[:, int(np.argmax(np.diag(M)))]
    return n / np.linalg.norm(n)


def _tip_deformation_operator(model):
    """(9 x n_dof operator, its value at rest): the mean F over the quadrature points of the elements holding
    the end effector (those with the most of its embedding nodes)."""
    nodes = np.unique(model.C.indices // 3)
    tets = model.mesh.tets
    count = np.isin(tets, nodes).sum(axis=1)
    elems = np.flatnonzero(count == count.max())
    nq = model.quadrature_points
    rows = ((elems[:, None] * nq + np.arange(nq)[None]) * 9)[..., None] + np.arange(9)
    op = model.deformation_operator()[rows.reshape(-1, 9).ravel()]
    m = len(elems) * nq
    mean = sp.csr_matrix((np.full(9 * m, 1.0 / m), (np.tile(np.arange(9), m), np.arange(9 * m))), shape=(9, 9 * m))
    return (mean @ op).tocsr(), np.eye(3).ravel()
