"""Constant external loads (:class:`Loads`, phase ``applied``): gravity and a body force, as consistent nodal
loads of the elements' mass and volume, and forces on embedded points. Scaled by the load factor of a continuation (0 at rest)."""

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
        self.body_force = np.asarray(getattr(spec, "body_force", np.zeros(3)), dtype=float)
        self.point_loads = list(spec.point_loads)

    def setup(self, model, pos):
        mesh, element, el = model.mesh, model.element, model.elements
        F = np.zeros(model.n_dof)
        if np.any(self.gravity) or np.any(self.body_force):
            volumes = element.body_load_weights(el.Xe)  # m^3 per node and element: the shape functions' integrals
            for a in range(element.n_nodes):
                load = (el.rho * volumes[:, a])[:, None] * self.gravity[None, :] + volumes[:, a, None] * self.body_force
                np.add.at(F[: model.n_mech].reshape(-1, 3), mesh.tets[:, a], load)
        for point, force in self.point_loads:
            W = model.embedding(np.asarray(point)[None])
            F += W.T @ np.asarray(force, dtype=float)
        self.F = F
        """The loads on all dofs (n_dof,), N."""

    def forces(self, model, s):
        return -(s.load * self.F)
