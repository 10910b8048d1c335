"""Constant external loads (:class:`Loads`, phase ``applied``): gravity, as consistent nodal loads of the
elements' mass, and forces on embedded points. Scaled by the load factor of a continuation (0 at rest)."""

from __future__ import annotations

import numpy as np

from .base import Term

__all__ = ["Loads"]


class Loads(Term):
    """F: the body's weight and the point loads; R holds -load F."""

    name = "loads"
    phase = "applied"
    negatives = 0

    def __init__(self, spec):
        self.gravity = np.asarray(spec.gravity, dtype=float)
        self.point_loads = list(spec.point_loads)

    def setup(self, model, pos):
        mesh, element, el = model.mesh, model.element, model.elements
        F = np.zeros(model.n_dof)
        if np.any(self.gravity):
            weights = el.rho[:, None] * element.body_load_weights(el.Xe)  # kg per node and element
            for a in range(element.n_nodes):
                np.add.at(F[: model.n_mech].reshape(-1, 3), mesh.tets[:, a], weights[:, a, None] * self.gravity[None, :])
        for point, force in self.point_loads:
            W = model.embedding(np.asarray(point)[None])
            F += W.T @ np.asarray(force, dtype=float)
        self.F = F
        """The loads on all dofs (n_dof,), N."""

    def forces(self, model, s):
        return -(s.load * self.F)
