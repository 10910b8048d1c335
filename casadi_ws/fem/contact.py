"""Rigid, fixed obstacles: a plane, a box, a sphere, a capped cylinder, or a closed triangle surface.

Each gives the signed distance of points to it (m; positive on the free side, negative inside the
obstacle). Contact forces are not modelled yet: an equilibrium whose boundary passes into an obstacle is
inadmissible (violation ``obstacle``, :mod:`casadi_ws.solvers.admissible`), so a reported workspace never
enters one, and the states in which the robot would press on it are missing (docs/methods.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Obstacle", "boundary_nodes"]


@dataclass
class Obstacle:
    """One obstacle: ``kind`` is ``plane``, ``box``, ``sphere``, ``cylinder`` or ``surface``."""

    kind: str
    name: str
    params: dict = field(default_factory=dict)
    """plane: point, normal (unit); box: lower, upper; sphere: center, radius; cylinder: a, b (axis end
    points), radius; surface: vertices, triangles (closed, outward normals)."""

    def distance(self, x: np.ndarray) -> np.ndarray:
        """Signed distance (k,) of the points x (k, 3): positive outside the obstacle."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        p = self.params
        if self.kind == "plane":
            return (x - p["point"]) @ p["normal"]
        if self.kind == "sphere":
            return np.linalg.norm(x - p["center"], axis=1) - p["radius"]
        if self.kind == "box":
            c, h = 0.5 * (p["lower"] + p["upper"]), 0.5 * (p["upper"] - p["lower"])
            d = np.abs(x - c) - h
            return np.linalg.norm(np.maximum(d, 0.0), axis=1) + np.minimum(d.max(axis=1), 0.0)
        if self.kind == "cylinder":
            a, b, r = p["a"], p["b"], p["radius"]
            axis = b - a
            length = np.linalg.norm(axis)
            t = (x - a) @ (axis / length)  # along the axis from a
            radial = np.linalg.norm((x - a) - np.outer(t, axis / length), axis=1) - r
            along = np.abs(t - 0.5 * length) - 0.5 * length
            d = np.column_stack([radial, along])
            return np.linalg.norm(np.maximum(d, 0.0), axis=1) + np.minimum(d.max(axis=1), 0.0)
        if self.kind == "surface":
            import pyvista as pv

            tris = p["triangles"]
            surf = pv.PolyData(p["vertices"], np.hstack([np.full((len(tris), 1), 3), tris]).ravel())
            # VTK's implicit distance is negative inside a closed surface with outward normals
            return np.asarray(pv.PolyData(x).compute_implicit_distance(surf)["implicit_distance"], dtype=float)
        raise ValueError(f"unknown obstacle kind {self.kind!r}")

    def describe(self) -> dict:
        return {"kind": self.kind, "name": self.name,
                **{k: np.asarray(v).tolist() if isinstance(v, np.ndarray) else v for k, v in self.params.items()}}


def boundary_nodes(mesh) -> np.ndarray:
    """The nodes on the body's boundary (mid-edge nodes of 10-node faces included): what an obstacle is
    checked against."""
    from .surface import boundary_faces

    return np.unique(boundary_faces(mesh))
