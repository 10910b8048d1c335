"""Linear springs that hold nodes softly to anchors (:class:`Springs`, phase ``internal``): SOFA's
``RestShapeSpringsForceField``.

Each selected node is pulled towards its anchor (its rest position, or a given point) by a spring of stiffness
k (N/m, the same in every direction): f = k (x - a) on its three components, K = k I. A part held softly (a
gripper's base clamped in foam, a membrane's rim in a frame) moves a little under load instead of not at all;
springs on every node of the body hold it too, without a support.

A worked example of a term (docs/methods.md "How to add a term"): the problem-file key ``springs`` is read by
:func:`casadi_ws.io.problem.problem_from_dict`, which adds one :class:`Springs` per entry to
``ModelSpec.terms``; the SOFA importer maps ``RestShapeSpringsForceField`` to it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import Term

__all__ = ["Springs"]


@dataclass(eq=False)
class Springs(Term):
    """Springs of stiffness ``stiffness`` (N/m, per node) from ``nodes`` to ``anchors`` (rest positions by
    default)."""

    nodes: np.ndarray
    """Mesh node indices (k,)."""
    stiffness: float | np.ndarray
    """N/m: one value, or one per node (k,)."""
    anchors: np.ndarray | None = None
    """Where each spring is anchored (k, 3), m; None: the node's rest position."""
    name: str = "springs"

    phase = "internal"
    negatives = 0  # k I is symmetric and positive: the tangent stays as symmetric and as definite as it was

    def setup(self, model, pos):
        nodes = np.asarray(self.nodes, dtype=np.int64)
        k = np.broadcast_to(np.asarray(self.stiffness, dtype=float), nodes.shape)
        self._dofs = (3 * nodes[:, None] + np.arange(3)).ravel()
        self._k = np.repeat(k, 3)
        rest = model.X[self._dofs]
        anchors = rest if self.anchors is None else np.asarray(self.anchors, dtype=float).reshape(-1)
        self._offset = rest - anchors  # x - a = offset + q
        p = pos[self._dofs]
        self._free = p >= 0
        self._keys = p[self._free] * model.n_free + p[self._free]

    def forces(self, model, s):
        f = np.zeros(model.n_dof)
        np.add.at(f, self._dofs, self._k * (self._offset + s.q[self._dofs]))
        return f

    def pattern(self, model, pos):
        return self._keys

    def tangent(self, model, cache):
        return self._keys, self._k[self._free]

    @property
    def tangent_from_residual(self):
        return False
